"""Model structures for fitting: the core simulator with a small free-parameter set.

A :class:`ModelStructure` turns a matrix of candidate parameter vectors
``W`` (``(n, k)``, each coordinate in 0..1) into one batched
:class:`~valve_gym.params.ModelParams` plus initial state, runs the one
physics core (:func:`valve_gym.core.run_packed`) once for the whole batch and
returns the simulated process variable ``(T, n)`` in the recording's units
(through :class:`valve_gym.plant.Plant`, the stepper the envs and the benchmark
share: one kernel call for the batch).
Nothing here re-implements physics: it chooses which parameters are free,
their ranges and units, and the measurement map from the core's output to
the recorded PV.

Plants (``plant``) and their free parameters (recording units; ``u`` is the
controller output normalised to 0..1, ``f(u)`` the flow fraction after the
valve, ``PV`` the process variable):

``first_order``
    ``T dy/dt = K f + b - y``; free ``K`` [PV/1], ``T`` [s], ``b`` [PV] and
    the initial output ``y(0)`` [PV].
``integrating``
    ``dy/dt = s (q_max f - q_out)``, ``A = 1``; free ``q_max`` [PV/s],
    ``q_out`` [PV/s], ``y(0)`` [PV] and the sign ``s`` (+1: more output
    raises the PV, -1: the valve drains the vessel).
``tank``
    ``dL/dt = q_max f - k_out sqrt(L)``, ``A = 1``, level ``L = PV`` (> 0);
    free ``q_max`` [PV/s], ``k_out`` [PV^0.5/s], ``L(0)`` [PV].
``cascade``
    the two-tank model of Schoukens et al.
    ``dx1/dt = -k1 sqrt(x1) + k4 u``, ``dx2/dt = k2 sqrt(x1) - k3 sqrt(x2)``,
    ``PV = x2 + c``, written in the core's terms ``A1 = 1``, ``q_max = k4``,
    ``k_out = k1``, ``area2 = k1/k2``, ``k_out2 = k3 k1/k2``; the unmeasured
    upper level is scaled so that it equals the mean PV at the mean input
    (one of ``k1, k2, k4`` is redundant); free ``k1, k3, k4, k1/k2`` (via two
    time constants and a steady level), the offset ``c`` and ``x1(0)``,
    ``x2(0)``.

Internally the search runs on decorrelated coordinates (time constants,
steady-state gains and levels at the mean input) scaled from the data; the
fitted values are reported as the core's parameters.

Actuators (``actuator``)

``valve``
    the paper's valve (Riihilahti / Yamé & El Bahir) with friction ``z_max``
    [s] and dead band ``e_dead`` [-] free.  The stem's own dynamics are much
    faster than a 1-10 s controller sample, so the valve is *quasi-static*:
    ``tau`` equals the Euler step ``dt/n_sub`` and ``v_max = inf``, i.e. once
    the friction state breaks away the stem reaches its target within one
    Euler step.  ``z_max`` keeps the paper's meaning (seconds of integrated
    error), resolved to ``dt/n_sub``.
``pump``
    ``q_in = q_max u`` (no valve, no friction).

Effects (the diagnosis' candidate physics, see :data:`CANDIDATE_EFFECTS`)
switch the corresponding block of :mod:`valve_gym.params` on and free its
parameters.  ``slip_jump`` replaces the paper's friction by the
Choudhury-Thornhill-Shah model (``S``, ``J`` free, positioner lag
``tau_p = dt/n_sub``).

Measurement map: ``PV_model = s * y_core + c``, then clipped to the sensor
range when the recording shows the PV pinned at its maximum or minimum
(``saturation='auto'``): a transmitter that reads exactly the same extreme
value for several samples is saturated, and the model must see the same
clipping.
"""
from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..core import check_dt, initial_state
from ..effects import CANDIDATE_EFFECTS, candidate_effects, effect_spec
from ..params import (
    Cascade,
    FirstOrderParams,
    IntegratingParams,
    ModelParams,
    ParameterError,
    TankParams,
    ValveParams,
    unchecked,
)
from ..paramspec import FreeParam, unit_value
from ..plant import Plant

__all__ = ["PLANTS", "ACTUATORS", "CANDIDATE_EFFECTS", "FreeParam", "DataScales",
           "ModelStructure", "effect_applicability", "kernel_threads", "set_kernel_threads",
           "process_pool", "POSITIVE_GAIN_PLANTS", "process_gain_sign"]

# batched simulations of at least this many Euler steps run in kernel threads
_MIN_THREADED_STEPS = 100_000
_THREADS = [min(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                else (os.cpu_count() or 1), 8)]


def kernel_threads() -> int:
    """Threads the fitter's batched simulations use (default: the cores this process may use, at most 8)."""
    return _THREADS[0]


def set_kernel_threads(n: int) -> None:
    """Set the threads of the fitter's batched simulations (1 = none).

    Results do not depend on it: the systems of a batch are independent.
    """
    n = int(n)
    if n < 1:
        raise ValueError(f"kernel threads must be at least 1, got {n}")
    _THREADS[0] = n


def process_gain_sign(physical) -> float:
    """Sign of a fitted model's process gain from its ``physical`` values: +1 when more output raises the PV."""
    k = float(physical.get("process.K", 1.0)) * float(physical.get("measurement.sign", 1.0))
    return 1.0 if k >= 0 else -1.0


def process_pool(jobs: int):
    """Worker processes for ``jobs`` fits or recordings at once, the kernel threads shared out.

    Each worker runs its batched simulations in ``kernel_threads() // jobs``
    threads (at least 1), so workers and threads together do not oversubscribe
    the cores.
    """
    from concurrent.futures import ProcessPoolExecutor
    return ProcessPoolExecutor(max_workers=jobs, initializer=set_kernel_threads,
                               initargs=(max(1, kernel_threads() // max(1, int(jobs))),))

def pool_map(executor, fn, items: list, cost: Sequence[float] | None = None) -> list:
    """``fn`` over ``items`` on the process pool ``executor`` (in this process without one, or for one item).

    Results come in the order of ``items``.  With ``cost`` (an estimate of each item's work),
    the costliest items are handed out first, so the last to finish is a short one (the results
    are the same: each item is independent).
    """
    if executor is None or len(items) <= 1:
        return [fn(a) for a in items]
    order = list(range(len(items))) if cost is None else sorted(range(len(items)), key=lambda i: -cost[i])
    out: list = [None] * len(items)
    for i, r in zip(order, executor.map(fn, [items[i] for i in order])):
        out[i] = r
    return out


#: Process models the fitter knows.
PLANTS = ("tank", "integrating", "first_order", "cascade")
#: Plants whose process gain is positive by construction (more output, higher PV); the others fit
#: its sign (``first_order``: the sign of ``K``; ``integrating``: ``sign``).
POSITIVE_GAIN_PLANTS = ("tank", "cascade")
#: Actuators the fitter knows.
ACTUATORS = ("valve", "pump")
# CANDIDATE_EFFECTS (the built-in effects, in the order they are tried) comes from valve_gym.effects

_BIG = 1e300


# --------------------------------------------------------------------------- params
@dataclass(frozen=True)
class DataScales:
    """Scales of a recording that set the search ranges (never fitted values).

    Attributes
    ----------
    dt : float, s (controller sample)
    n : int, samples used for fitting
    duration : float, s
    u_mean, u_std, u_min, u_max, u0 : float, controller output 0..1
    y_mean, y_std, y_min, y_max, y0, y_q50 : float, PV units
    sat_hi, sat_lo : float or None, PV value where the sensor saturates
    """

    dt: float
    n: int
    duration: float
    u_mean: float
    u_std: float
    u_min: float
    u_max: float
    u0: float
    y_mean: float
    y_std: float
    y_min: float
    y_max: float
    y0: float
    y_q50: float
    sat_hi: float | None = None
    sat_lo: float | None = None

    @property
    def u_range(self) -> float:
        """Span of the controller output, at least 1e-6 [0..1]."""
        return max(self.u_max - self.u_min, 1e-6)

    @property
    def y_range(self) -> float:
        """Span of the PV, kept above zero [PV]."""
        return max(self.y_max - self.y_min, 1e-12 + 1e-9 * abs(self.y_mean))

    @staticmethod
    def from_signals(u, y, dt, saturation="auto") -> DataScales:
        """Scales of ``u`` (0..1) and ``y`` (PV units) sampled every ``dt`` s.

        ``saturation='auto'`` detects a sensor range end: at least 3
        consecutive samples and 0.5 % of the record exactly at the maximum
        (or minimum) of ``y``.  ``None`` disables it; a pair ``(lo, hi)``
        (either may be None) sets it.
        """
        u = np.asarray(u, float)
        y = np.asarray(y, float)
        k = max(3, min(5, len(y) // 20))
        y0 = float(np.median(y[:k]))
        lo = hi = None
        if saturation == "auto":
            hi = _plateau(y, +1)
            lo = _plateau(y, -1)
        elif saturation is not None:
            lo, hi = saturation
        return DataScales(dt=float(dt), n=len(y), duration=float(len(y) * dt),
                          u_mean=float(u.mean()), u_std=float(max(u.std(), 1e-6)),
                          u_min=float(u.min()), u_max=float(u.max()), u0=float(u[0]),
                          y_mean=float(y.mean()), y_std=float(max(y.std(), 1e-12)),
                          y_min=float(y.min()), y_max=float(y.max()), y0=y0,
                          y_q50=float(np.median(y)),
                          sat_hi=None if hi is None else float(hi),
                          sat_lo=None if lo is None else float(lo))


def _plateau(y, side):
    """Value of a saturated reading at the max (side=+1) or min (-1), else None."""
    ext = y.max() if side > 0 else y.min()
    tol = 1e-9 * max(abs(ext), 1.0)
    at = np.abs(y - ext) <= tol
    if at.sum() < max(3, 0.005 * len(y)):
        return None
    # longest run of consecutive samples at the extreme
    run = best = 0
    for a in at:
        run = run + 1 if a else 0
        best = max(best, run)
    return float(ext) if best >= 3 else None


def effect_applicability(effect: str, plant: str, actuator: str) -> tuple[bool, str]:
    """Whether ``effect`` can be identified for ``plant``/``actuator``, and why not.

    The rule is the effect's own (:class:`valve_gym.effects.EffectSpec`).

    Returns
    -------
    (bool, str)
        ``True, ""`` when it is a candidate; else ``False`` and the reason.
    """
    if effect not in candidate_effects():
        return False, f"unknown effect {effect!r}"
    return effect_spec(effect).applicable(plant, actuator)


# --------------------------------------------------------------------------- structure
class ModelStructure:
    """A plant, an actuator and a set of effects with their free parameters.

    Parameters
    ----------
    plant : {'tank', 'integrating', 'first_order', 'cascade'}
    actuator : {'valve', 'pump'}
    effects : sequence of str
        Candidate effects switched on (see :data:`CANDIDATE_EFFECTS`).
    scales : DataScales
        Scales of the recording (fit part) that set the search ranges.
    n_sub : int
        Euler steps per controller sample (``dt_euler = scales.dt / n_sub``).
    friction : bool
        Valve friction free (``True``) or a frictionless valve (``False``:
        ``z_max = e_dead = 0``, used for the stiction verdict).
    variants : dict, optional
        ``{'valve_characteristic': 'equal_percentage' | 'quick_opening'}``.
    period_hint : float, optional
        Period [s] of the strongest oscillation of the base residual; the
        oscillating disturbance searches periods within a factor 1.5 of it.
    output_offset : bool, optional
        Free offset ``c`` of the measurement (default: only for ``cascade``).

    Examples
    --------
    >>> import numpy as np
    >>> sc = DataScales.from_signals(np.linspace(0.3, 0.6, 200), np.linspace(1.0, 2.0, 200), 1.0)
    >>> ms = ModelStructure("first_order", "valve", (), sc, n_sub=2)
    >>> ms.names
    ['K', 'T', 'b_offset', 'y0', 'e_dead', 'z_max', 'dh0']
    """

    def __init__(self, plant: str, actuator: str, effects: Sequence[str], scales: DataScales,
                 n_sub: int = 2, friction: bool = True, variants: dict | None = None,
                 period_hint: float | None = None, output_offset: bool | None = None):
        if plant not in PLANTS:
            raise ValueError(f"unknown plant {plant!r}; choose one of {', '.join(PLANTS)}")
        if actuator not in ACTUATORS:
            raise ValueError(f"unknown actuator {actuator!r}; choose 'valve' or 'pump'")
        effects = tuple(effects)
        for e in effects:
            ok, why = effect_applicability(e, plant, actuator)
            if not ok:
                raise ValueError(f"effect {e!r} cannot be used here: {why}")
        if len(set(effects)) != len(effects):
            raise ValueError(f"effects listed twice: {effects}")
        if plant == "tank" and scales.y_min <= 0:
            raise ValueError(
                "plant 'tank' needs a positive level (PV > 0, measured above the outlet); the PV "
                f"goes down to {scales.y_min:g}; use --plant first_order or integrating")
        self.plant = plant
        self.actuator = actuator
        self.effects = effects
        self.scales = scales
        self.n_sub = int(n_sub)
        self.friction = bool(friction) and actuator == "valve"
        self.variants = dict(variants or {})
        for e in effects:
            first = effect_spec(e).variants[0]
            if first is not None:
                self.variants.setdefault(e, first)
        self.period_hint = period_hint
        self.output_offset = (plant == "cascade") if output_offset is None else bool(output_offset)
        self.params: list[FreeParam] = self._free_params()
        self.names = [p.name for p in self.params]
        self._index = {p.name: i for i, p in enumerate(self.params)}
        self._decoder = _Decoder(self.params)

    # ---------------------------------------------------------------- description
    @property
    def k(self) -> int:
        """Number of free parameters (a choice of form, e.g. the valve characteristic's, may count as one)."""
        extra = sum(effect_spec(e).variant_k.get(self.variants.get(e) or "", 0) for e in self.effects)
        return len(self.params) + extra

    @property
    def pv_is_simulated_level(self) -> bool:
        """Whether the PV is the core's level through ``sign`` and ``offset`` only.

        True when no measurement effect maps it outside the core: then a measured PV can
        restart the level (``simulate(reset=...)``).
        """
        return all(effect_spec(e).measure is None for e in self.effects)

    @property
    def dt_euler(self) -> float:
        """Euler step of the simulation: sample time over ``n_sub`` [s]."""
        return self.scales.dt / self.n_sub

    @property
    def t_min(self) -> float:
        """Smallest time constant searched [s]: the Euler step, at least half a sample."""
        return max(self.scales.dt / 2.0, self.dt_euler)

    def label(self) -> str:
        """Short description, e.g. ``first_order + valve + dead_time``."""
        parts = [self.plant, self.actuator if self.friction or self.actuator == "pump"
                 else "frictionless valve"]
        for e in self.effects:
            v = self.variants.get(e)
            parts.append(f"{e} ({v})" if v else e)
        return " + ".join(parts)

    #: Attributes holding the kernel's scratch arrays (rebuilt on first use; not pickled, not kept).
    _SCRATCH = ("_scratch", "_scratch_out")

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in self._SCRATCH}

    def release_scratch(self) -> None:
        """Drop the kernel's scratch arrays (a search's buffers, not kept with a fitted result)."""
        for name in self._SCRATCH:
            self.__dict__.pop(name, None)

    def with_effects(self, effects: Sequence[str], **kw) -> ModelStructure:
        """Same plant/actuator/scales with other effects (keyword overrides allowed)."""
        args: dict[str, Any] = dict(plant=self.plant, actuator=self.actuator, effects=tuple(effects),
                    scales=self.scales, n_sub=self.n_sub, friction=self.friction,
                    variants=self.variants, period_hint=self.period_hint,
                    output_offset=self.output_offset)
        args.update(kw)
        args["variants"] = {e: v for e, v in dict(args["variants"] or {}).items() if e in args["effects"]}
        return ModelStructure(**args)

    # ---------------------------------------------------------------- parameters
    def _free_params(self) -> list[FreeParam]:
        sc = self.scales
        dt, D = sc.dt, sc.duration
        yr = sc.y_range
        P: list[FreeParam] = []
        # fastest time constant resolvable by the Euler step (and by the sampling)
        tlo = self.t_min
        if self.plant == "first_order":
            P += [FreeParam("K", -6.0, 6.0, "lin", "PV/1",
                            "steady-state gain, asinh-scaled by std(PV)/std(OP)"),
                  FreeParam("T", tlo, max(D / 2, dt), "log", "s", "time constant"),
                  FreeParam("b_offset", -1.5 * yr, 1.5 * yr, "lin", "PV",
                            "bias b relative to mean(PV) - K f(mean OP)"),
                  FreeParam("y0", -0.5 * yr, 0.5 * yr, "lin", "PV", "initial output - PV(0)")]
        elif self.plant == "integrating":
            g = sc.y_std / sc.u_std
            P += [FreeParam("sign", -1.0, 1.0, "lin", "-", "output sign (>=0: +1)", discrete=True),
                  FreeParam("q_max", 0.05 * g / D, 20.0 * g / dt, "log", "PV/s",
                            "rate of change of the PV per unit flow fraction"),
                  FreeParam("f_bal", sc.u_min - 0.25 * sc.u_range, sc.u_max + 0.25 * sc.u_range,
                            "lin", "-", "flow fraction that balances the outflow, q_out/q_max"),
                  FreeParam("y0", -0.5 * yr, 0.5 * yr, "lin", "PV", "initial output - PV(0)")]
        elif self.plant == "tank":
            P += [FreeParam("tau", tlo, 2 * D, "log", "s",
                            "linearised outflow time constant at the mean level"),
                  FreeParam("gain", 0.2, 5.0, "log", "-",
                            "q_max f(mean OP) / (k_out sqrt(mean PV)): 1 = mean PV is steady"),
                  FreeParam("y0", -0.5 * yr, 0.5 * yr, "lin", "PV", "initial level - PV(0)")]
        else:  # cascade
            P += [FreeParam("tau1", tlo, 2 * D, "log", "s", "upper-tank time constant"),
                  FreeParam("tau2", tlo, 2 * D, "log", "s", "lower-tank time constant"),
                  FreeParam("x2s", 0.2 * max(sc.y_mean, yr), 5.0 * max(sc.y_mean, yr), "log",
                            "PV", "lower level at the mean input, steady state"),
                  FreeParam("x1_0", 0.0, 3.0, "lin", "-",
                            "initial upper level / upper level at the mean input"),
                  FreeParam("y0", -0.5 * yr, 0.5 * yr, "lin", "PV", "initial lower level - PV(0)")]
        if self.output_offset:
            if self.plant == "cascade":
                P.append(FreeParam("c", sc.y_min - 2 * yr, sc.y_min - 0.01 * yr, "lin", "PV",
                                   "measurement offset, PV = x2 + c"))
            else:
                P.append(FreeParam("c", -yr, yr, "lin", "PV", "measurement offset"))
        if self.actuator == "valve" and self.friction and "slip_jump" not in self.effects:
            ur = sc.u_range
            P += [FreeParam("e_dead", 0.0, float(np.clip(ur, 0.004, 0.2)), "sq", "-",
                            "half dead band, fraction of stroke"),
                  FreeParam("z_max", 0.0, float(np.clip(20.0 * ur, 0.01, 2.0)) * dt, "sq", "s",
                            "half width of the friction band (integrated error)")]
        for e in self.effects:
            P += self._effect_params(e)
        if self.actuator == "valve" and self.friction:
            # the stem's position at t = 0 is part of the unknown initial state: a sticky
            # valve can rest anywhere within its band around the first controller output
            band = max(p.hi for p in P if p.name in ("e_dead", "S"))
            P.append(FreeParam("dh0", -band, band, "lin", "-",
                               "initial stem position - first controller output"))
        return P

    def _effect_params(self, e: str) -> list[FreeParam]:
        """Free coordinates of effect ``e``: its spec's rule, ranges scaled from the data."""
        return list(effect_spec(e).free(self))

    # ---------------------------------------------------------------- coordinates
    def decode(self, W) -> dict[str, np.ndarray]:
        """Internal parameter values ``{name: (n,)}`` of unit coordinates ``W`` (n, k)."""
        W = np.atleast_2d(np.asarray(W, float))
        if W.ndim != 2 or W.shape[1] != len(self.names):
            raise ValueError(f"coordinates must have shape (n, {len(self.names)}), one column per free parameter "
                             f"({', '.join(self.names)}); got {W.shape}")
        V = self._decoder(W)
        return {name: V[i] for i, name in enumerate(self.names)}

    def encode(self, values: dict[str, float]) -> np.ndarray:
        """Unit coordinates ``(k,)`` of internal values (missing names -> 0.5... or neutral)."""
        w = np.empty(len(self.params))
        for i, p in enumerate(self.params):
            v = values.get(p.name)
            w[i] = self.neutral_coord(p) if v is None else float(p.coord(np.asarray(v, float)))
        return w

    def neutral_coord(self, p: FreeParam) -> float:
        """Unit coordinate at which an effect parameter leaves the base model unchanged."""
        for e in self.effects:
            neutral = effect_spec(e).neutral
            if p.name in neutral:
                return float(neutral[p.name])
        return 0.5

    def index(self, name: str) -> int:
        """Column of the free parameter ``name`` in the coordinate vectors."""
        return self._index[name]

    # ---------------------------------------------------------------- build
    def _fbar(self, v, n):
        """Flow fraction at the mean controller output, per row."""
        f = np.full(n, self.scales.u_mean)
        if self.actuator == "valve":
            for e in self.effects:
                rule = effect_spec(e).flow_fraction
                if rule is not None:
                    f = rule(self, v, f)
        return np.maximum(f, 1e-3)

    def build(self, values: dict[str, np.ndarray], n_sub: int | None = None, fresh: bool = False):
        """Core parameters, initial state and measurement map for ``values``.

        ``fresh``: the values are ``(n,)`` float arrays of their own (:meth:`decode`'s), used as they
        are; otherwise each is broadcast and copied.

        Returns
        -------
        params : ModelParams (fields are ``(n,)`` arrays)
        init : dict of ``level``, ``level2``, ``h`` for :func:`initial_state`
        sign, offset : (n,) arrays, measurement ``PV = sign * y_core + offset``
        """
        sc = self.scales
        n = len(next(iter(values.values()))) if values else 1
        v = values if fresh else {k: np.broadcast_to(np.asarray(a, float), (n,)).copy() for k, a in values.items()}
        ns = self.n_sub if n_sub is None else int(n_sub)
        dte = sc.dt / ns
        kind = "cascade" if self.plant == "cascade" else self.plant
        with unchecked():           # decoded coordinates are inside the ranges by construction
            pp = self._build_process(v, n)
            blocks = self._build_blocks(v, dte, pp)
            mp = ModelParams(valve=self._build_valve(v, dte), process=pp.process, process_kind=kind, dt=dte,
                             cascade=pp.cascade, actuator=None if self.actuator == "valve" else _pump(),
                             **blocks)
        h0 = np.clip(sc.u0 + (v["dh0"] if "dh0" in v else 0.0), 0.0, 1.0) * np.ones(n)
        init = dict(level=pp.level, h=h0)
        if pp.level2 is not None:
            init["level2"] = pp.level2
        return mp, init, pp.sign, pp.offset

    def _build_process(self, v: dict[str, np.ndarray], n: int) -> _ProcessPart:
        """Process block, initial levels and measurement map of the plant for values ``v`` (n,)."""
        sc = self.scales
        fbar = self._fbar(v, n)
        sign = np.ones(n)
        offset = v["c"] if "c" in v else np.zeros(n)
        for e in self.effects:
            shift = effect_spec(e).map_offset          # e.g. sensor_curve: the reading's zero above the outlet
            if shift is not None:
                offset = offset - shift(self, v)
        cas = None
        level2 = None
        proc: FirstOrderParams | IntegratingParams | TankParams
        if self.plant == "first_order":
            # internal shift so that the core's output stays positive (overflow needs L_max > 0)
            offset = offset + (sc.y_min - sc.y_range)
            ks = sc.y_std / sc.u_std
            K = ks * np.sinh(v["K"])
            b = sc.y_mean - K * fbar + v["b_offset"] - offset
            proc = FirstOrderParams(K=K, T=v["T"], b=b, level0=0.0)
            level = sc.y0 + v["y0"] - offset
            flow_scale = np.maximum(np.abs(K), 1e-12)
        elif self.plant == "integrating":
            sign = np.where(v["sign"] >= 0, 1.0, -1.0)
            offset = offset + np.where(sign > 0, sc.y_min - sc.y_range, sc.y_max + sc.y_range)
            proc = IntegratingParams(area=1.0, q_max=v["q_max"], q_out=v["q_max"] * v["f_bal"],
                                     level0=0.0)
            level = sign * (sc.y0 + v["y0"] - offset)
            flow_scale = v["q_max"]
        elif self.plant == "tank":
            ym = max(sc.y_mean, 1e-9)
            k_out = 2.0 * np.sqrt(ym) / v["tau"]
            q_max = v["gain"] * k_out * np.sqrt(ym) / fbar
            proc = TankParams(area=1.0, q_max=q_max, k_out=k_out, level0=1.0)
            level = np.maximum(sc.y0 + v["y0"] - offset, 0.0)
            flow_scale = q_max * fbar
        else:  # cascade
            X1 = max(sc.y_mean, 1e-9)
            qs = 2.0 * X1 / v["tau1"]
            q_max = qs / fbar
            k_out = qs / np.sqrt(X1)
            x2s = v["x2s"]
            area2 = v["tau2"] * qs / (2.0 * x2s)
            k_out2 = qs / np.sqrt(x2s)
            proc = TankParams(area=1.0, q_max=q_max, k_out=k_out, level0=1.0)
            cas = Cascade(area2=area2, k_out2=k_out2, level2_0=1.0)
            level = v["x1_0"] * X1
            level2 = np.maximum(sc.y0 + v["y0"] - offset, 0.0)
            flow_scale = qs
        return _ProcessPart(proc, cas, level, level2, sign, offset, flow_scale)

    def _build_valve(self, v: dict[str, np.ndarray], dte: float) -> ValveParams:
        """Valve block: fitted friction, or an ideal valve (pump, frictionless, slip-jump)."""
        if self.actuator == "valve" and self.friction and "slip_jump" not in self.effects:
            return ValveParams(tau=dte, v_max=np.inf, e_dead=v["e_dead"], z_max=v["z_max"])
        return ValveParams(tau=dte, v_max=np.inf, e_dead=0.0, z_max=0.0)

    def _build_blocks(self, v: dict[str, np.ndarray], dte: float, pp: _ProcessPart) -> dict[str, Any]:
        """Kernel blocks ``{effect: block}`` of the structure's effects (each spec's ``build``)."""
        blocks: dict[str, Any] = {}
        for e in self.effects:
            build = effect_spec(e).build
            if build is not None:
                blocks[e] = build(self, v, dte, pp)
        return blocks

    def _measure(self, values: dict[str, np.ndarray], Y: np.ndarray) -> np.ndarray:
        """Apply the measurement effects (those outside the core) to the simulated PV ``Y`` (T, n)."""
        for e in self.effects:
            measure = effect_spec(e).measure
            if measure is not None:
                n = Y.shape[1]
                v = {k: np.broadcast_to(np.asarray(a, float), (n,)) for k, a in values.items()}
                Y = measure(self, v, self.scales.dt * np.arange(Y.shape[0]), Y)
        return Y

    def _read(self, values: dict[str, np.ndarray], Y: np.ndarray, sign, offset) -> np.ndarray:
        """The recorded PV from the simulated level ``Y`` (T, n): map, measurement effects, sensor range."""
        if np.any(sign != 1.0):
            Y *= sign[None, :]
        if np.any(offset != 0.0):
            Y += offset[None, :]
        Y = self._measure(values, Y)
        sc = self.scales
        if sc.sat_hi is not None:
            np.minimum(Y, sc.sat_hi, out=Y)
        if sc.sat_lo is not None:
            np.maximum(Y, sc.sat_lo, out=Y)
        return Y

    # ---------------------------------------------------------------- simulate
    def simulate(self, W, u, n_sub: int | None = None, coords: bool = True, reset=None) -> np.ndarray:
        """Simulated PV ``(T, n)`` for unit coordinates ``W`` (n, k) over input ``u`` (T,).

        ``coords=False`` takes internal values ``{name: (n,)}`` instead of ``W``.
        Unstable or invalid parameter rows give ``nan`` columns.  ``reset = (y, N)``:
        an ``N``-step-ahead prediction instead of a free run: every ``N`` samples the
        measured level restarts from the recorded PV ``y`` (T,) of the sample before
        (:func:`valve_gym.core.run_packed_reset`; only without measurement effects).
        """
        return self._simulate(W, u, n_sub, coords, reset)[0]

    def bounded_costs(self, W, u, y, bound, reset=None) -> np.ndarray:
        """Sum of squared errors ``(n,)`` of each row's simulated PV to ``y`` (T,), stopped early.

        The kernel sums each row's squared error as it runs and stops the row once the sum
        exceeds its ``bound`` (n,) by a relative ``1e-9``; such a row costs ``inf`` (its whole
        cost can only be larger: :class:`valve_gym.core.Bound`).  Every other row costs
        ``sum((y - simulate(W, u)) ** 2)``: the kernel's running sum, which adds the squares sample
        after sample as numpy's ``einsum`` sums a column of a batch of two or more, the same number
        bit for bit (``tests/test_diagnosis.py`` checks it on every plant; a batch of one row is
        summed from its PV); ``nan`` where the simulation is not finite.  Every row runs to the end
        where the PV is read through a measurement effect or the friction model runs a per-scan law
        outside the core; an infinite bound stops nothing (the row's whole cost).
        """
        return self._simulate(W, u, None, True, reset, (np.asarray(y, float), bound))[1]

    def _simulate(self, W, u, n_sub, coords: bool, reset, bounded=None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`simulate` or :meth:`bounded_costs`.

        ``bounded`` None: returns ``(Y, empty)``, ``Y`` a new array; ``bounded = (y, bound)``: returns
        ``(Y, costs)``, ``Y`` a scratch array of the structure (overwritten by the next call; the
        columns of stopped rows not fully written).
        """
        values = self.decode(W) if coords else W
        mp, init, sign, offset = self.build(values, n_sub=n_sub, fresh=coords)
        ns = self.n_sub if n_sub is None else int(n_sub)
        n = max(mp.batch_size(), len(sign))
        T = len(u)
        H, LV, Dz = self._work(T, n)
        Y = np.empty((T, n)) if bounded is None else self._out(T, n)
        threads = kernel_threads() if T * n * ns >= _MIN_THREADED_STEPS else 1
        plant = self._plant(mp, init, n, threads)
        bd = None if bounded is None else self._bound(plant, bounded, sign, offset, n, T)
        if reset is not None and int(reset[1]) < T:
            self._run_reset(plant, u, Dz, (Y, H, LV), reset, sign, offset, bd)
        elif bd is not None:
            from ..core import run_packed

            U = np.ascontiguousarray(np.asarray(u, float)).reshape(T, 1)
            pk, S, buf = plant.scan_args(U[:1], Dz[:1], (Y[:1], H[:1], LV[:1]))[:3]
            run_packed(pk, S, buf, U, Dz, ns, Y, H, LV, threads=threads, bound=bd)
        else:
            plant.run(u, Dz, out=(Y, H, LV))
        if bd is not None and n > 1:
            # the kernel's running sums: the sum below in the same order (each column sample after
            # sample), so the same costs bit for bit without another pass over the PV; a single
            # column numpy sums in another order, so one row takes the sum below
            cost = bd.acc.copy()
            cost[~np.isfinite(cost)] = np.nan
            cost[bd.acc > bd.limit] = np.inf
            return Y, cost
        Y = self._read(values, Y, sign, offset)
        if bounded is None:
            return _nan_bad(Y), np.empty(0)
        with np.errstate(over="ignore", invalid="ignore"):
            Y -= bounded[0][:T, None]
            cost = np.einsum("ij,ij->j", Y, Y)      # a stopped row's column: partly unwritten, costs inf below
        cost[~np.isfinite(cost)] = np.nan
        if bd is not None:
            cost[bd.acc > bd.limit] = np.inf
        return Y, cost

    def _bound(self, plant: Plant, bounded, sign, offset, n: int, T: int):
        """The kernel's early stop (:class:`valve_gym.core.Bound`) for ``bounded = (y, bound)``, or None.

        None where the reading is not the core's level through sign, offset and sensor range
        (a measurement effect) or the friction runs outside the kernel.  Infinite bounds stop
        nothing: the kernel then only sums each row's whole cost.
        """
        from ..core import Bound

        y, bound = bounded
        lim = np.broadcast_to(np.asarray(bound, float), (n,)) * (1.0 + 1e-9)
        if plant.sample_law is not None or not self.pv_is_simulated_level:
            return None
        sc = self.scales
        read = np.empty((4, n))
        read[0], read[1] = sign, offset
        read[2] = np.inf if sc.sat_hi is None else sc.sat_hi
        read[3] = -np.inf if sc.sat_lo is None else sc.sat_lo
        return Bound(np.ascontiguousarray(y[:T], dtype=float), read, np.ascontiguousarray(lim), np.zeros(n))

    def _run_reset(self, plant: Plant, u, D, out, reset, sign, offset, bound=None) -> None:
        """Run ``plant`` over ``u`` with the measured level reset from the recorded PV (see :meth:`simulate`)."""
        from ..core import run_packed_reset

        if not self.pv_is_simulated_level or plant.sample_law is not None:
            raise ValueError("a k-step prediction needs the PV to be the simulated level (no measurement "
                             "effect, no per-scan friction law)")
        T, n = len(u), plant.n
        y, every = np.asarray(reset[0], float), int(reset[1])
        sign = np.broadcast_to(np.asarray(sign, float), (n,))
        offset = np.broadcast_to(np.asarray(offset, float), (n,))
        L = np.ascontiguousarray((y[:T, None] - offset[None, :]) / sign[None, :])
        U = np.ascontiguousarray(np.asarray(u, float)).reshape(T, 1)
        pk, S, buf = plant.scan_args(U[:1], D[:1], tuple(a[:1] for a in out))[:3]
        Y, H, LV = out
        run_packed_reset(pk, S, buf, U, D, plant.n_sub, Y, H, LV, L, every, bound=bound)

    def _work(self, T: int, n: int):
        """Scratch arrays of the kernel (stem, level, zero load), reused between calls."""
        w = self.__dict__.get("_scratch")
        if w is None or w[0].shape[0] != T or w[0].shape[1] < n:
            w = (np.empty((T, n)), np.empty((T, n)), np.zeros((T, 1)))
            self.__dict__["_scratch"] = w
        return w[0][:, :n], w[1][:, :n], w[2]

    def _out(self, T: int, n: int) -> np.ndarray:
        """A C-contiguous scratch PV array ``(T, n)``, reused between calls of the same shape.

        The two shapes used last are kept (a search alternates its population's batch with a grid's).
        """
        cache = self.__dict__.setdefault("_scratch_out", {})
        Y = cache.pop((T, n), None)
        if Y is None:
            Y = np.empty((T, n))
            while len(cache) >= 2:
                del cache[next(iter(cache))]
        cache[(T, n)] = Y                   # the most recent last
        return Y

    def stem(self, W, u, n_sub: int | None = None) -> np.ndarray:
        """Simulated stem position ``(T,)`` of the first row of ``W`` (0..1)."""
        values = self.decode(np.atleast_2d(W)[:1])
        mp, init, sign, offset = self.build(values, n_sub=n_sub)
        return self._plant(mp, init, 1).run(u)[1][:, 0]

    def _plant(self, mp: ModelParams, init: dict, n: int, threads: int = 1) -> Plant:
        """The shared plant stepper for ``n`` candidate rows, started from ``init``.

        No parameter checks: invalid rows give NaN columns, which the fitter drops.
        """
        plant = Plant(mp, n, scan_s=self.scales.dt, threads=threads, check=False)
        plant.set_state(initial_state(mp, n, buf_len=plant.packed.buf_len, **init))
        return plant

    # ---------------------------------------------------------------- reporting
    def model_params(self, w, n_sub: int | None = None) -> ModelParams:
        """Scalar :class:`ModelParams` of one coordinate vector ``w`` (k,)."""
        values = {k: float(a[0]) for k, a in self.decode(np.atleast_2d(w)[:1]).items()}
        mp, init, sign, offset = self.build({k: np.array([a]) for k, a in values.items()},
                                            n_sub=n_sub)
        return _scalarise(mp)

    def initial_values(self, w) -> dict:
        """Initial state of one coordinate vector: ``level``, ``level2``, ``h``."""
        values = self.decode(np.atleast_2d(w)[:1])
        _, init, sign, offset = self.build(values)
        return {k: float(np.asarray(a).reshape(-1)[0]) for k, a in init.items()}

    def physical(self, w, n_sub: int | None = None) -> dict[str, float]:
        """Fitted parameters of one coordinate vector, named after the core's fields.

        Keys are ``block.field`` (e.g. ``process.K``, ``valve.z_max``,
        ``dead_time.theta``), ``init.*`` for the initial state and
        ``measurement.*`` for the measurement map ``PV = sign * y_core +
        offset`` between the core's output and the PV.  ``process.b`` and the
        initial output/level of the measured vessel are given as read on the
        PV; the other levels (``overflow.L_max``, the cascade's upper tank)
        in the core's units (``overflow.L_max_pv`` as read on the PV).  Units:
        see :meth:`units`.
        """
        values = self.decode(np.atleast_2d(w)[:1])
        mp, init, sign, offset = self.build(values, n_sub=n_sub)
        mp = _scalarise(mp)
        out: dict[str, float | np.ndarray] = {}
        out.update(self._physical_process(mp, offset))
        out.update(self._physical_effects(mp, sign, offset, values))
        for k, a in init.items():
            if k == "h":
                if "dh0" in self.names:
                    out["init.stem"] = float(np.asarray(a).reshape(-1)[0])
                continue
            a0 = float(np.asarray(a).reshape(-1)[0])
            if (k == "level" and self.plant in ("first_order", "integrating")) or k == "level2":
                a0 = sign[0] * a0 + offset[0]          # as read on the PV
            out[f"init.{k}"] = a0
        out["measurement.sign"] = float(sign[0])
        out["measurement.offset"] = float(offset[0])
        return {k: float(np.asarray(a).reshape(-1)[0]) for k, a in out.items()}

    def _physical_process(self, mp: ModelParams, offset: np.ndarray) -> dict[str, float | np.ndarray]:
        """``process.*``, ``cascade.*`` and ``schoukens.*`` entries of :meth:`physical`."""
        out: dict[str, float | np.ndarray] = {}
        pr = mp.process
        if self.plant == "first_order":
            assert isinstance(pr, FirstOrderParams)
            # b in PV units: the core runs on y_core = PV - offset
            out.update({"process.K": pr.K, "process.T": pr.T, "process.b": pr.b + offset[0]})
        elif self.plant == "integrating":
            assert isinstance(pr, IntegratingParams)
            out.update({"process.q_max": pr.q_max, "process.q_out": pr.q_out})
        else:
            assert isinstance(pr, TankParams)
            out.update({"process.area": pr.area, "process.q_max": pr.q_max,
                        "process.k_out": pr.k_out})
        if mp.cascade is not None:
            assert isinstance(pr, TankParams)
            out.update({"cascade.area2": mp.cascade.area2, "cascade.k_out2": mp.cascade.k_out2})
            a2 = mp.cascade.area2
            out.update({"schoukens.k1": pr.k_out, "schoukens.k2": pr.k_out / a2,
                        "schoukens.k3": mp.cascade.k_out2 / a2, "schoukens.k4": pr.q_max})
        return out

    def _physical_effects(self, mp: ModelParams, sign: np.ndarray, offset: np.ndarray,
                          values: dict[str, np.ndarray]) -> dict[str, float | np.ndarray]:
        """Valve friction and effect entries of :meth:`physical` (each effect's spec names its own)."""
        out: dict[str, float | np.ndarray] = {}
        if self.actuator == "valve" and mp.slip_jump is None:
            out.update({"valve.e_dead": mp.valve.e_dead, "valve.z_max": mp.valve.z_max})
        v = {k: np.asarray(a, float).reshape(-1)[:1] for k, a in values.items()}
        for e in self.effects:
            out.update(effect_spec(e).physical(self, v, mp, sign, offset))
        return out

    def units(self) -> dict[str, str]:
        """Units of the keys of :meth:`physical` (PV = units of the recording's PV)."""
        u = {"process.K": "PV per unit OP (0..1)", "process.T": "s", "process.b": "PV",
             "process.q_max": "PV/s", "process.q_out": "PV/s", "process.area": "-",
             "process.k_out": "PV^0.5/s", "cascade.area2": "-", "cascade.k_out2": "PV^0.5/s",
             "schoukens.k1": "PV^0.5/s", "schoukens.k2": "PV^0.5/s", "schoukens.k3": "PV^0.5/s",
             "schoukens.k4": "PV/s per unit input",
             "valve.e_dead": "fraction of stroke", "valve.z_max": "s (integrated error)",
             "init.level": "PV", "init.level2": "PV", "init.stem": "fraction of stroke",
             "measurement.sign": "-",
             "measurement.offset": "PV"}
        for e in candidate_effects():
            u.update(effect_spec(e).units(self.plant))
        if self.plant == "cascade":
            u["init.level"] = "upper-tank level units (scaled to PV)"
        return u

    def stable_n_sub(self, w, start: int | None = None, cap: int = 400) -> int:
        """Smallest ``n_sub >= start`` for which :func:`check_dt` accepts ``w``'s model."""
        ns = self.n_sub if start is None else int(start)
        while ns <= cap:
            try:
                check_dt(self.model_params(w, n_sub=ns))
                return ns
            except ParameterError:
                ns = int(math.ceil(ns * 1.5))
        return cap


class _Decoder:
    """:meth:`FreeParam.value <valve_gym.paramspec.FreeParam.value>` of every coordinate at once.

    Called with unit coordinates ``W`` (n, k), returns the values ``(k, n)`` (one contiguous row per
    parameter): :func:`~valve_gym.paramspec.unit_value` on the rows of each scale, so element for
    element the numbers ``params[i].value(W[:, i])`` gives.
    """

    def __init__(self, params: Sequence[FreeParam]):
        lo = np.array([p.lo for p in params], float)[:, None]
        hi = np.array([p.hi for p in params], float)[:, None]
        scales = [p.scale for p in params]
        self.groups = []
        for scale in dict.fromkeys(scales):
            rows = np.array([i for i, sc in enumerate(scales) if sc == scale], int)
            self.groups.append((scale, rows, lo[rows], hi[rows]))

    def __call__(self, W: np.ndarray) -> np.ndarray:
        Wt = np.minimum(np.maximum(W.T, 0.0), 1.0)
        V = np.empty_like(Wt)
        for scale, rows, lo, hi in self.groups:
            V[rows] = unit_value(scale, lo, hi, Wt[rows])
        return V


class _ProcessPart(NamedTuple):
    """Process side of a built model, per row (n,): what :meth:`ModelStructure.build` assembles."""

    process: FirstOrderParams | IntegratingParams | TankParams
    cascade: Cascade | None
    level: np.ndarray            # initial level of the core's (upper) vessel [core units]
    level2: np.ndarray | None    # initial level of the cascade's lower tank [core units]
    sign: np.ndarray             # measurement map PV = sign * y_core + offset [-]
    offset: np.ndarray           # [PV]
    flow_scale: np.ndarray       # typical inflow, scales leak and disturbance [core units]


def _pump():
    from ..params import Actuator
    return Actuator(kind="pump")


def _scalarise(mp: ModelParams) -> ModelParams:
    """Copy of a batch-of-one ModelParams with plain floats."""
    from dataclasses import fields, is_dataclass, replace

    def sc(obj: Any) -> Any:
        if obj is None or not is_dataclass(obj) or isinstance(obj, type):
            return obj
        kw = {}
        for f in fields(obj):
            a = getattr(obj, f.name)
            if isinstance(a, np.ndarray):
                kw[f.name] = float(a.reshape(-1)[0])
            elif is_dataclass(a):
                kw[f.name] = sc(a)
        return replace(obj, **kw) if kw else obj

    return sc(mp)


def _nan_bad(Y: np.ndarray) -> np.ndarray:
    """``Y`` (T, n) with every column that holds a non-finite value set to NaN (in place)."""
    bad = ~np.isfinite(Y).all(axis=0)
    if bad.any():
        Y[:, bad] = np.nan
    return Y
