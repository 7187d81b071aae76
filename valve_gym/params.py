"""Parameters of the valve, the process and the optional physics blocks.

Every parameter set is a frozen dataclass in engineering units. A field may hold
a float or a ``(n,)`` array: arrays broadcast over the batch, which is how
domain randomisation (sampling a batch of valves) and fitting (searching a batch
of candidate parameter sets) become array operations on the one physics core.

Variants come from :func:`dataclasses.replace`::

    >>> from dataclasses import replace
    >>> from valve_gym.params import ModelParams, ValveParams
    >>> sticky = replace(ModelParams(), valve=ValveParams(z_max=0.2, e_dead=0.01))
    >>> sticky.valve.z_max
    0.2

Optional physics blocks are ``None`` when off. Their names (the keys of
:data:`EFFECTS`) are the candidate effects of the diagnosis tool.
"""
from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field, fields, replace

import numpy as np

Number = float | np.ndarray

__all__ = [
    "ValveParams", "SlipJump", "ValveCharacteristic", "DeadTime", "Overflow", "Leak",
    "SensorLag", "OscillatingDisturbance", "TankShape", "Cascade", "Actuator", "TankParams",
    "IntegratingParams", "FirstOrderParams", "ModelParams", "EFFECTS", "PROCESSES",
    "ParameterError", "AREA_FLOOR", "SLIP_JUMP_LAWS", "slip_jump_laws", "register_sample_law",
]


class ParameterError(ValueError):
    """A parameter value is out of its physical range (the message names it)."""


def _check(obj, name, lo=None, hi=None, lo_open=False, allow_inf=False):
    v = np.asarray(getattr(obj, name), dtype=float)
    where = f"{type(obj).__name__}.{name}"
    if np.isnan(v).any() or (not allow_inf and np.isinf(v).any()):
        raise ParameterError(f"{where} must be a finite number, got {getattr(obj, name)!r}")
    if lo is not None:
        bad = (v <= lo) if lo_open else (v < lo)
        if bad.any():
            rel = ">" if lo_open else ">="
            raise ParameterError(
                f"{where} must be {rel} {lo}, got {np.min(v)!r}; "
                f"a negative time constant or friction band has no physical meaning")
    if hi is not None and (v > hi).any():
        raise ParameterError(f"{where} must be <= {hi}, got {np.max(v)!r}")


#: False inside :func:`unchecked`: blocks skip their range checks on construction.
_CHECKED: ContextVar[bool] = ContextVar("valve_gym_params_checked", default=True)


@contextmanager
def unchecked():
    """Build parameter blocks without their range checks, in this context (thread- and task-local).

    For callers that construct many batches from values already inside the ranges (the
    fitter decodes bounded coordinates thousands of times per fit); a value out of range is
    then not caught here but gives a non-finite simulation.  Everything else checks.
    """
    token = _CHECKED.set(False)
    try:
        yield
    finally:
        _CHECKED.reset(token)


class _Block:
    """Mixin: validate on construction (except inside :func:`unchecked`)."""

    def __post_init__(self):  # noqa: D105
        if _CHECKED.get():
            self.validate()

    def validate(self):  # pragma: no cover - overridden
        pass


@dataclass(frozen=True)
class ValveParams(_Block):
    """Control valve of Riihilahti (1997) as implemented by Yamé & El Bahir.

    Parameters
    ----------
    tau : float or (n,) array, s
        Time constant of the stem's first-order motion (> 0).
    v_max : float or (n,) array, 1/s
        Stem speed limit, in full strokes per second (> 0).
    e_dead : float or (n,) array, -
        Half the dead band, as a fraction of the stroke (>= 0).
    z_max : float or (n,) array, s
        Half width of the friction / time-delay band of the state ``z`` (>= 0).

    Notes
    -----
    With input ``i`` and stem position ``h`` (both 0..1)::

        e   = i - h
        e  <- e - e_dead*sign(e)  if |e| > e_dead  else 0          (dead band)
        dz/dt = max(e,0) if z < -z_max; min(e,0) if z > z_max; e otherwise
        dh/dt = sign(e)*min(|e|/tau, v_max) if |z| > z_max  else 0

    The state starts at ``z = 0`` (stuck) and only the output ``h`` is clipped
    to [0, 1] (the integrator state is not).

    Discretisation: in continuous time ``z`` stays on the edge of its band
    while the stem moves (``dz/dt = 0`` once ``|z| > z_max`` and ``e`` pushes
    outwards). The Euler core keeps exactly that: ``z`` is held at
    ``+-z_max`` and the stem moves while ``z`` is on an edge and ``e`` pushes
    outwards. A plain Euler step would let ``z`` overshoot the edge by
    ``dt*e`` and turn that overshoot into a spurious free stem travel of about
    ``dt*e/tau`` at the next reversal (a whole dead band at dt = 0.02 s). The "healthy" valve of the paper
    is ``tau = 0.1 s, z_max = 0.005 s`` and a backlash of about 1 %
    (``e_dead = 0.005``).

    References
    ----------
    .. [1] K. Yamé, L. El Bahir, "Teaching control valve friction using modeling
       and simulation", after
    .. [2] M. Riihilahti, "Modeling and simulation of control valve
       nonlinearities", Helsinki University of Technology, 1997.
    """

    tau: Number = 0.1
    v_max: Number = 0.5
    e_dead: Number = 0.005
    z_max: Number = 0.005

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "tau", 0.0, lo_open=True)
        _check(self, "v_max", 0.0, lo_open=True, allow_inf=True)
        _check(self, "e_dead", 0.0, 0.5)
        _check(self, "z_max", 0.0)


#: Friction laws of the ``slip_jump`` block compiled into the core's kernel (see :mod:`valve_gym.friction`).
SLIP_JUMP_LAWS = ("choudhury", "kano", "karnopp")
# per-sample laws added by friction-model modules (run by valve_gym.plant.Plant, outside the kernel)
_SAMPLE_LAWS: list[str] = []


def register_sample_law(name: str) -> None:
    """Accept ``name`` as a ``SlipJump.law`` run once per scan outside the kernel (see :mod:`valve_gym.friction`)."""
    if name in SLIP_JUMP_LAWS:
        raise ParameterError(f"{name!r} is a kernel law of the slip_jump block; pick another name")
    if name not in _SAMPLE_LAWS:
        _SAMPLE_LAWS.append(name)


def slip_jump_laws() -> tuple[str, ...]:
    """Every accepted ``SlipJump.law``: the kernel laws, then the registered per-sample laws."""
    return SLIP_JUMP_LAWS + tuple(_SAMPLE_LAWS)


@dataclass(frozen=True)
class SlipJump(_Block):
    """``slip_jump``: stick-slip friction sized by a stick band ``S`` and a slip jump ``J``.

    Replaces the paper's friction model. By default (``law='choudhury'``) the
    two-parameter stiction of Choudhury, Thornhill & Shah (2005), applied once
    per controller sample to the input ``u`` (0..1); its output ``x`` drives a
    positioner lag ``dh/dt = (x - h)/tau_p``. ``law='kano'`` is the model of
    Kano et al. (2004) in the same place; ``law='karnopp'`` a force balance on
    the stem with Karnopp's stick-velocity window, integrated every Euler step
    (``omega_n``, ``zeta``, ``dv`` are its own). Each law is documented in its
    module of :mod:`valve_gym.friction`.

    Parameters
    ----------
    S : float or (n,) array, -
        Stick band plus dead band, fraction of the stroke (>= 0).
    J : float or (n,) array, -
        Slip jump, fraction of the stroke (>= 0). ``J = 0`` pure dead band,
        ``J < S`` undershoot, ``J = S`` no offset, ``J > S`` overshoot
        (``choudhury`` and ``kano`` only).
    tau_p : float or (n,) array, s
        Positioner time constant (> 0); for ``karnopp`` the lag of the
        actuator force behind the input.
    law : {'choudhury', 'kano', 'karnopp'}
        Friction law.
    omega_n : float or (n,) array, rad/s
        ``karnopp``: natural frequency ``sqrt(k/m)`` of stem mass and spring (> 0).
    zeta : float or (n,) array, -
        ``karnopp``: damping ratio of the viscous friction, ``Fv / (2 sqrt(k m))`` (>= 0).
    dv : float or (n,) array, 1/s
        ``karnopp``: half width of the stick-velocity window, strokes per second (> 0).

    Notes
    -----
    ``choudhury``: the valve sticks when the input stops or reverses (stuck
    input ``u_s``). It slips when ``|u - u_s| > S`` after a reversal or
    ``> J`` when the input goes on in the same direction; while moving
    ``x = u - sign(du)*(S - J)/2``.

    References
    ----------
    .. [1] M.A.A.S. Choudhury, N.F. Thornhill, S.L. Shah, "Modelling valve
       stiction", Control Engineering Practice 13 (2005) 641-658.
    .. [2] M. Kano, H. Maruta, H. Kugemoto, K. Shimizu, "Practical model and
       detection algorithm for valve stiction", IFAC DYCOPS 2004.
    .. [3] D. Karnopp, "Computer simulation of stick-slip friction in mechanical
       dynamic systems", J. Dyn. Syst. Meas. Control 107 (1985) 100-103.
    """

    S: Number = 0.02
    J: Number = 0.01
    tau_p: Number = 0.1
    law: str = "choudhury"
    omega_n: Number = 196.5
    zeta: Number = 1.146
    dv: Number = 1e-5

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "S", 0.0, 1.0)
        _check(self, "J", 0.0, 1.0)
        _check(self, "tau_p", 0.0, lo_open=True)
        if self.law not in slip_jump_laws():
            raise ParameterError(f"SlipJump.law must be one of {list(slip_jump_laws())}, got {self.law!r} "
                                 f"(a friction-model module registers its law when it is imported)")
        _check(self, "omega_n", 0.0, lo_open=True)
        _check(self, "zeta", 0.0)
        _check(self, "dv", 0.0, lo_open=True)
        if self.law == "karnopp" and (np.asarray(self.J, float) > np.asarray(self.S, float) * (1 + 1e-12)).any():
            raise ParameterError("SlipJump.J must be <= S for law='karnopp' (the Coulomb friction "
                                 "(S - J)/2 cannot be negative); use law='choudhury' or 'kano' for overshoot")


_CHAR_KINDS = {"linear": 0, "equal_percentage": 1, "quick_opening": 2}


@dataclass(frozen=True)
class ValveCharacteristic(_Block):
    """``valve_characteristic``: installed flow characteristic ``f(h)``.

    Parameters
    ----------
    kind : {'linear', 'equal_percentage', 'quick_opening'}
        ``f = h``; ``f = R**(h - 1)``; ``f = sqrt(h)``.
    R : float or (n,) array, -
        Rangeability of the equal-percentage characteristic (> 1).
    h0 : float or (n,) array, -
        Opening threshold: no flow below stem position ``h0``; above it the
        characteristic acts on ``(h - h0)/(1 - h0)`` (0 <= h0 < 1).

    References
    ----------
    .. [1] ISA-75.11.01, "Flow characteristic and rangeability of control
       valves"; W.L. Luyben, "Process modeling, simulation and control for
       chemical engineers", 2nd ed., McGraw-Hill, 1990, ch. 8.
    """

    kind: str = "equal_percentage"
    R: Number = 30.0
    h0: Number = 0.0

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        if self.kind not in _CHAR_KINDS:
            raise ParameterError(
                f"ValveCharacteristic.kind must be one of {sorted(_CHAR_KINDS)}, got {self.kind!r}")
        _check(self, "R", 1.0, lo_open=True)
        _check(self, "h0", 0.0, 0.99)

    @property
    def code(self) -> int:
        """Kernel code of ``kind``."""
        return _CHAR_KINDS[self.kind]


@dataclass(frozen=True)
class DeadTime(_Block):
    """``dead_time``: transport delay ``theta`` between the valve and the inflow.

    ``q_in(t) = q_max * f(h(t - theta))``, rounded to the Euler step.

    Parameters
    ----------
    theta : float or (n,) array, s (>= 0)

    References
    ----------
    .. [1] D.E. Seborg, T.F. Edgar, D.A. Mellichamp, "Process dynamics and
       control", Wiley, ch. 6 (time delays).
    """

    theta: Number = 2.0

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "theta", 0.0)


@dataclass(frozen=True)
class Overflow(_Block):
    """``overflow``: the tank has a top ``L_max``; above it the level is held.

    Excess inflow spills: ``L = min(L, L_max)`` after each Euler step. With
    ``cascade``, the upper tank's spill goes into the lower tank with the
    fraction ``spill_to_lower`` (the rest leaves), and the lower tank has its
    own top ``L2_max``.

    Parameters
    ----------
    L_max : float or (n,) array, m (> 0)
    L2_max : float or (n,) array, m (> 0), cascade only (``inf`` = no top)
    spill_to_lower : float or (n,) array, - (0..1), cascade only

    References
    ----------
    .. [1] M. Schoukens, P. Mattsson, T. Wigren, J.-P. Noël, "Cascaded tanks
       benchmark combining soft and hard nonlinearities", 2016, DOI
       10.4121/12960104.
    """

    L_max: Number = 2.0
    L2_max: Number = float("inf")
    spill_to_lower: Number = 0.5

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "L_max", 0.0, lo_open=True)
        _check(self, "L2_max", 0.0, lo_open=True, allow_inf=True)
        _check(self, "spill_to_lower", 0.0, 1.0)


@dataclass(frozen=True)
class Leak(_Block):
    """``leak``: constant extra outflow (offtake) independent of the level.

    ``A dL/dt = q_in - q_out - q_leak`` (the level cannot go below zero).

    Parameters
    ----------
    q_leak : float or (n,) array, m^3/s (>= 0; for ``first_order`` it is a
        bias in output units/s)
    """

    q_leak: Number = 0.0005

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "q_leak", 0.0)


@dataclass(frozen=True)
class SensorLag(_Block):
    """``sensor_lag``: first-order lag of the level measurement.

    ``tau_s dy/dt = L - y``.

    Parameters
    ----------
    tau_s : float or (n,) array, s (> 0)
    """

    tau_s: Number = 5.0

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "tau_s", 0.0, lo_open=True)


@dataclass(frozen=True)
class OscillatingDisturbance(_Block):
    """``oscillating_disturbance``: sinusoidal inflow disturbance.

    ``q_d(t) = amplitude * sin(2 pi t / period + phase)`` added to the inflow.

    Parameters
    ----------
    amplitude : float or (n,) array, m^3/s (>= 0)
    period : float or (n,) array, s (> 0)
    phase : float or (n,) array, rad
    """

    amplitude: Number = 0.0005
    period: Number = 60.0
    phase: Number = 0.0

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "amplitude", 0.0)
        _check(self, "period", 0.0, lo_open=True)
        _check(self, "phase")


@dataclass(frozen=True)
class TankShape(_Block):
    """``tank_shape``: the tank's cross-section changes with the level.

    ``A(L) = area * max(1 + taper x + curvature x^2, AREA_FLOOR)`` with
    ``x = L / L_ref - 1``: the vertical cylinder (``taper = curvature = 0``,
    the block off) is nested in it. A quadratic cross-section is exact for the
    common vessels: an upright cone, apex down (``A ~ L^2``: ``taper 2,
    curvature 1`` at any ``L_ref``), a sphere (``A ~ L (D - L)``: ``taper 0,
    curvature -1`` with ``L_ref`` half full), a trough or wedge (``A ~ L``:
    ``taper 1``), and close to a horizontal cylinder (``curvature -1/2`` half
    full). The floor :data:`AREA_FLOOR` keeps the area positive (the apex of a
    cone) and the Euler step stable. Acts on the tank whose area is
    ``process.area`` (the upper tank of ``cascade``). The kernel evaluates the
    cross-section once per controller sample, at the level at its start, and
    holds it over that sample's Euler sub-steps (the area changes little within a
    sample; evaluated every sub-step, the branch cost the vector envs, which do
    not use the block, 3-8 % of their speed in ``benchmarks/bench_kernel.py``).

    Parameters
    ----------
    taper : float or (n,) array, - (relative change of the area per relative
        change of the level at ``L_ref``)
    curvature : float or (n,) array, -
    L_ref : float or (n,) array, m (> 0), the level at which the area is ``area``
    """

    taper: Number = 0.0
    curvature: Number = 0.0
    L_ref: Number = 1.0

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "taper", -10.0, 10.0)
        _check(self, "curvature", -10.0, 10.0)
        _check(self, "L_ref", 0.0, lo_open=True)


#: Smallest cross-section of :class:`TankShape`, relative to ``area``.
AREA_FLOOR = 0.1


@dataclass(frozen=True)
class Cascade(_Block):
    """``cascade``: a second tank below the first, whose level is measured.

    ``A1 dL1/dt = q_in - k1 sqrt(L1)``, ``A2 dL2/dt = k1 sqrt(L1) - k2 sqrt(L2)``
    with ``A1, k1`` of :class:`TankParams` and ``A2, k2`` here.

    Parameters
    ----------
    area2 : float or (n,) array, m^2 (> 0)
    k_out2 : float or (n,) array, m^2.5/s (>= 0)
    level2_0 : float, m, initial level of the lower tank (>= 0)

    References
    ----------
    .. [1] Schoukens et al., cascaded tanks benchmark (see :class:`Overflow`).
    """

    area2: Number = 0.2
    k_out2: Number = 0.005
    level2_0: Number = 1.0

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "area2", 0.0, lo_open=True)
        _check(self, "k_out2", 0.0)
        _check(self, "level2_0", 0.0)


@dataclass(frozen=True)
class Actuator(_Block):
    """``actuator``: the valve (default) or a pump.

    With ``kind='pump'`` the inflow is ``q_in = q_max * u`` directly (no
    valve, no friction), for recordings that have no valve.
    """

    kind: str = "pump"

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        if self.kind not in ("valve", "pump"):
            raise ParameterError(f"Actuator.kind must be 'valve' or 'pump', got {self.kind!r}")


@dataclass(frozen=True)
class TankParams(_Block):
    """Level tank with Torricelli outflow (the environment's plant).

    ``A dL/dt = q_max f(h) - k_out sqrt(L)``, level ``L`` in m (never below 0).

    Parameters
    ----------
    area : float or (n,) array, m^2 (> 0)
    q_max : float or (n,) array, m^3/s, inflow at full opening (> 0)
    k_out : float or (n,) array, m^2.5/s, outflow coefficient (>= 0)
    level0 : float, m, initial level (>= 0)
    """

    area: Number = 0.2
    q_max: Number = 0.01
    k_out: Number = 0.005
    level0: Number = 1.0

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "area", 0.0, lo_open=True)
        _check(self, "q_max", 0.0, lo_open=True)
        _check(self, "k_out", 0.0)
        _check(self, "level0", 0.0)


@dataclass(frozen=True)
class IntegratingParams(_Block):
    """Integrating level with unknown constant outflow.

    ``A dL/dt = q_max f(h) - q_out``.
    """

    area: Number = 1.0
    q_max: Number = 1.0
    q_out: Number = 0.5
    level0: Number = 0.0

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "area", 0.0, lo_open=True)
        _check(self, "q_max", 0.0, lo_open=True)
        _check(self, "q_out", allow_inf=False)
        _check(self, "level0")


@dataclass(frozen=True)
class FirstOrderParams(_Block):
    """Self-regulating first-order process (flow, pressure loops).

    ``T dy/dt = K f(h) + b - y``; add ``dead_time`` for the delay.
    """

    K: Number = 1.0
    T: Number = 10.0
    b: Number = 0.0
    level0: Number = 0.0

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        _check(self, "K")
        _check(self, "T", 0.0, lo_open=True)
        _check(self, "b")
        _check(self, "level0")


PROCESSES = {"tank": TankParams, "integrating": IntegratingParams,
             "first_order": FirstOrderParams, "cascade": TankParams}

#: The optional physics blocks by name (the diagnosis tool's candidate effects).
EFFECTS = {
    "slip_jump": SlipJump,
    "valve_characteristic": ValveCharacteristic,
    "dead_time": DeadTime,
    "overflow": Overflow,
    "leak": Leak,
    "sensor_lag": SensorLag,
    "oscillating_disturbance": OscillatingDisturbance,
    "tank_shape": TankShape,
    "cascade": Cascade,
    "actuator": Actuator,
}


@dataclass(frozen=True)
class ModelParams(_Block):
    """The whole model: valve, process, optional blocks, integration step.

    Parameters
    ----------
    valve : ValveParams
    process : TankParams | IntegratingParams | FirstOrderParams
    process_kind : {'tank', 'integrating', 'first_order', 'cascade'}
        ``cascade`` needs ``cascade`` set (a :class:`Cascade`).
    dt : float, s
        Fixed explicit-Euler step (checked for stability by
        :func:`valve_gym.core.check_dt`).
    slip_jump, valve_characteristic, dead_time, overflow, leak, sensor_lag,
    oscillating_disturbance, tank_shape, cascade, actuator : block or None
        Optional physics, off when ``None``.
    """

    valve: ValveParams = field(default_factory=ValveParams)
    process: TankParams | IntegratingParams | FirstOrderParams = field(
        default_factory=TankParams)
    process_kind: str = "tank"
    dt: float = 0.02
    slip_jump: SlipJump | None = None
    valve_characteristic: ValveCharacteristic | None = None
    dead_time: DeadTime | None = None
    overflow: Overflow | None = None
    leak: Leak | None = None
    sensor_lag: SensorLag | None = None
    oscillating_disturbance: OscillatingDisturbance | None = None
    tank_shape: TankShape | None = None
    cascade: Cascade | None = None
    actuator: Actuator | None = None

    def validate(self):
        """Raise :class:`ParameterError` for a field out of its range."""
        if self.process_kind not in PROCESSES:
            raise ParameterError(
                f"process_kind must be one of {sorted(PROCESSES)}, got {self.process_kind!r}")
        want = PROCESSES[self.process_kind]
        if not isinstance(self.process, want):
            raise ParameterError(
                f"process_kind={self.process_kind!r} needs process={want.__name__}(...), "
                f"got {type(self.process).__name__}")
        if (self.process_kind == "cascade") != (self.cascade is not None):
            raise ParameterError(
                "process_kind='cascade' and the 'cascade' block go together: set both or neither")
        if not (isinstance(self.dt, (int, float)) and np.isfinite(self.dt) and self.dt > 0):
            raise ParameterError(f"ModelParams.dt must be a positive number of seconds, got {self.dt!r}")
        for name, cls in EFFECTS.items():
            v = getattr(self, name)
            if v is not None and not isinstance(v, cls):
                raise ParameterError(f"ModelParams.{name} must be a {cls.__name__} or None, "
                                     f"got {type(v).__name__}")

    @property
    def effects(self) -> tuple:
        """Names of the optional blocks that are on."""
        return tuple(n for n in EFFECTS if getattr(self, n) is not None)

    @property
    def friction_model(self) -> str:
        """Name of the valve's friction model (a name of :data:`valve_gym.friction.FRICTION_MODELS`).

        ``slip_jump.law`` when that block is on; else ``'riihilahti'``, or
        ``'none'`` when its bands are all zero or the actuator is a pump.
        """
        if self.actuator is not None and self.actuator.kind == "pump":
            return "none"
        if self.slip_jump is not None:
            return self.slip_jump.law
        v = self.valve
        if np.all(np.asarray(v.e_dead) == 0) and np.all(np.asarray(v.z_max) == 0):
            return "none"
        return "riihilahti"

    def with_effect(self, name: str, block=None) -> ModelParams:
        """Return a copy with effect ``name`` switched on (default parameters if ``block`` is None)."""
        if name not in EFFECTS:
            raise ParameterError(f"unknown effect {name!r}; known effects: {sorted(EFFECTS)}")
        return replace(self, **{name: block if block is not None else EFFECTS[name]()})

    def batch_size(self) -> int:
        """Length of the batch implied by array-valued fields (1 if all scalar)."""
        n = 1
        for blk in [self.valve, self.process] + [getattr(self, e) for e in EFFECTS]:
            if blk is None:
                continue
            for f in fields(blk):
                v = getattr(blk, f.name)
                if isinstance(v, np.ndarray) and v.ndim > 0:
                    if n not in (1, v.shape[0]) and v.shape[0] != 1:
                        raise ParameterError(
                            f"{type(blk).__name__}.{f.name} has batch size {v.shape[0]} but "
                            f"another parameter has {n}; all arrays must share one length")
                    n = max(n, v.shape[0])
        return n
