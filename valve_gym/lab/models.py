"""The lab's three experiments as :class:`param.Parameterized` objects (no browser, no plotting).

Each class holds the settings of one page as parameters (units in their
``doc``) and a ``simulate()`` method that returns the traces as plain numpy
arrays in a :class:`Traces` (columns with units), computed by the existing
simulation code: the valve alone by :func:`valve_gym.figures.valve_response`,
the level or flow loop under the PI law by :func:`valve_gym.figures.closed_loop_pi`
(figure 10 by :func:`valve_gym.figures.limit_cycle_data`), the compensators by
the benchmark's own runner (:func:`valve_gym.agents.bench.runner.run_loops`,
controllers from :func:`valve_gym.agents.load_controller`, scores from
:func:`valve_gym.agents.bench.scores.score_runs`). The limit cycle is read by
the benchmark's detector :func:`valve_gym.oscillation.detect_oscillation` (rule ``"benchmark"``). Nothing
here integrates an equation.

The ``param`` package (installed with Panel) is the only extra dependency.

>>> lab = ValveLab(preset="fig7")
>>> tr = lab.simulate()
>>> list(tr.columns)
['input', 'stem', 'healthy_h', 'friction']
>>> tr.summary["stem_jumps"] > 0          # the sticky valve's stick-slip under the ramps
True
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
import param

from .. import figures
from ..friction import remove_friction, valve_model
from ..params import FirstOrderParams, ModelParams, ValveParams

__all__ = ["Traces", "ValveLab", "LoopLab", "CompensatorLab", "VALVE_MODELS", "COMPENSATORS",
           "valve_params", "valve_input"]

#: Friction models of the lab (names of :func:`valve_gym.friction.valve_model`).
VALVE_MODELS = ("riihilahti", "choudhury", "kano", "karnopp")
#: Compensators of the compensator page (names of :func:`valve_gym.agents.load_controller`).
COMPENSATORS = ("knocker", "constant_reinforcement", "two_move", "integral_freeze", "learned")
#: Euler step of the valve page [s] (far below tau, so the curves show the model, not the integration).
VALVE_DT = 1e-3
#: Input sample of the valve page [s].
VALVE_SAMPLE = 0.05
#: Euler step of the loop page [s] (the environments' step).
LOOP_DT = 0.02


@dataclass
class Traces:
    """Traces of one view: a time axis and named columns, with units, plus a summary.

    Attributes
    ----------
    t : (T,) array, s
    columns : dict of str -> (T,) array
    units : dict of str -> str
        Unit of each column.
    summary : dict of str -> float or str or bool
        Scalars shown beside the plot (limit cycle, scores).
    extra : dict
        Further traces of the view (e.g. figure 10's second loop), each a :class:`Traces`.
    """

    t: np.ndarray
    columns: dict[str, np.ndarray]
    units: dict[str, str]
    summary: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    def csv(self) -> str:
        """The traces as CSV text: ``t_s`` then one column per trace, units in the header."""
        names = list(self.columns)
        head = ["t_s"] + [f"{n}_{self.units.get(n, '')}".rstrip("_") for n in names]
        rows = np.column_stack([self.t] + [self.columns[n] for n in names])
        lines = [",".join(head)] + [",".join(f"{v:.6g}" for v in r) for r in rows]
        for key, tr in self.extra.items():
            sub = tr.csv().splitlines()
            lines += [""] + [f"# {key}"] + sub
        return "\n".join(lines) + "\n"


def valve_params(model: str, tau: float, v_max: float, e_dead: float, z_max: float, S: float, J: float,
                 dt: float = VALVE_DT, base: ModelParams | None = None) -> ModelParams:
    """Model parameters of one valve of the lab.

    ``riihilahti`` is the paper's valve (``tau``, ``v_max``, ``e_dead``,
    ``z_max``); the other models are sized by the stick band ``S`` and slip
    jump ``J`` (:func:`valve_gym.friction.valve_model`) on a valve of the same
    ``tau`` (their positioner lag) and ``v_max``; ``"none"`` is the
    frictionless valve.

    Raises
    ------
    valve_gym.params.ParameterError
        For a value out of its range (the message names it).
    """
    base = ModelParams(dt=dt) if base is None else replace(base, dt=dt)
    base = replace(base, valve=ValveParams(tau=tau, v_max=v_max, e_dead=e_dead, z_max=z_max))
    if model == "riihilahti":
        return base
    if model == "none":
        return remove_friction(base)
    return valve_model(model, S=S, J=min(J, S), base=base)


def valve_input(kind: str, seconds: float, sample_time: float, *, step: float = 0.05, hold: float = 15.0,
                ramp_speed: float = 1.0, amplitude: float = 0.3, period: float = 100.0) -> np.ndarray:
    """The valve page's input signal (fraction of stroke), one value per ``sample_time``.

    Parameters
    ----------
    kind : {'steps', 'ramps', 'sine'}
        ``steps``: a staircase from 0.4 up four steps of ``step`` and back, each held
        ``hold`` s (:func:`valve_gym.figures.staircase`); ``ramps``: the multi-ramp of
        the stick-slip figure with its slopes times ``ramp_speed``
        (:func:`valve_gym.figures.multi_ramp`), then held; ``sine``:
        ``0.5 - amplitude cos(2 pi t / period)``.
    seconds : float, s
        Length (the staircase and the ramps are cut or held to it).

    Returns
    -------
    (round(seconds / sample_time),) array
    """
    T = max(2, int(round(seconds / sample_time)))
    if kind == "sine":
        t = np.arange(T) * sample_time
        return 0.5 - amplitude * np.cos(2 * np.pi * t / period)
    if kind == "steps":
        up = 0.4 + step * np.arange(5)
        u = figures.staircase(np.concatenate([up, up[-2::-1]]), hold, sample_time)
    elif kind == "ramps":
        slopes = [s * ramp_speed for s in (0.01, 0.01, 0.005, 0.02, 0.01)]
        u = figures.multi_ramp([0.7, 0.45, 0.65, 0.35, 0.6], slopes, sample_time)
    else:
        raise ValueError(f"unknown input {kind!r}; use 'steps', 'ramps' or 'sine'")
    if u.size >= T:
        return np.clip(u[:T], 0.0, 1.0)
    return np.clip(np.concatenate([u, np.full(T - u.size, u[-1])]), 0.0, 1.0)


# --------------------------------------------------------------------------- the valve
#: Presets of the valve page, after the paper's figures 6 (slow sine: input vs stem), 7 (ramps:
#: stick-slip) and 8 (staircase: multi-step response), all on its sticky valve.
VALVE_PRESETS: Mapping[str, dict] = {
    "fig6": dict(model="riihilahti", input="sine", seconds=200.0, amplitude=0.3, period=100.0),
    "fig7": dict(model="riihilahti", input="ramps", seconds=130.0, ramp_speed=1.0),
    "fig8": dict(model="riihilahti", input="steps", seconds=135.0, step=0.05, hold=15.0),
}
_STICKY = dict(tau=figures.STICKY.tau, v_max=figures.STICKY.v_max, e_dead=figures.STICKY.e_dead,
               z_max=figures.STICKY.z_max)


class ValveLab(param.Parameterized):
    """The valve alone (the paper's GUI): four valve parameters, a friction model, an input signal.

    ``simulate()`` runs the valve and, as a ghost, the paper's healthy valve on
    the same input.
    """

    preset = param.Selector(default="custom", objects=["custom", "fig6", "fig7", "fig8"],
                            doc="load the settings of the paper's figure 6, 7 or 8", label="preset")
    model = param.Selector(default="riihilahti", objects=list(VALVE_MODELS),
                           doc="friction model", label="friction model")
    tau = param.Number(0.1, bounds=(0.01, 2.0), step=0.01, doc="stem time constant tau [s]", label="tau [s]")
    v_max = param.Number(0.5, bounds=(0.01, 2.0), step=0.01,
                         doc="stem speed limit v_max [stroke/s]", label="v_max [stroke/s]")
    e_dead = param.Number(0.02, bounds=(0.0, 0.1), step=0.001,
                          doc="half dead band e_dead [fraction of stroke]", label="e_dead [fraction of stroke]")
    z_max = param.Number(0.2, bounds=(0.0, 1.0), step=0.005, doc="half friction band z_max [s]", label="z_max [s]")
    S = param.Number(0.04, bounds=(0.0, 0.3), step=0.005,
                     doc="stick band + dead band S [fraction of stroke]", label="S [fraction of stroke]")
    J = param.Number(0.02, bounds=(0.0, 0.3), step=0.005,
                     doc="slip jump J <= S [fraction of stroke]", label="J [fraction of stroke]")
    input = param.Selector(default="ramps", objects=["steps", "ramps", "sine"],
                           doc="input signal i(t)", label="input signal")
    seconds = param.Number(130.0, bounds=(10.0, 600.0), step=5.0,
                           doc="length of the experiment [s]", label="length [s]")
    step = param.Number(0.05, bounds=(0.005, 0.2), step=0.005,
                        doc="staircase step [fraction of stroke]", label="step [fraction of stroke]")
    hold = param.Number(15.0, bounds=(1.0, 60.0), step=1.0, doc="time each step is held [s]", label="hold [s]")
    ramp_speed = param.Number(1.0, bounds=(0.1, 5.0), step=0.1,
                              doc="ramp speed factor (1: 0.5 to 2 %/s) [-]", label="ramp speed factor [-]")
    amplitude = param.Number(0.3, bounds=(0.01, 0.5), step=0.01,
                             doc="sine amplitude [fraction of stroke]", label="amplitude [fraction of stroke]")
    period = param.Number(100.0, bounds=(5.0, 400.0), step=5.0, doc="sine period [s]", label="period [s]")

    def __init__(self, **params):
        preset = params.pop("preset", "custom")
        super().__init__(**params)
        if preset != "custom":
            self.preset = preset

    @param.depends("preset", watch=True)
    def _apply_preset(self):
        if self.preset in VALVE_PRESETS:
            self.param.update(**_STICKY, **VALVE_PRESETS[self.preset])

    @param.depends("model", "tau", "v_max", "e_dead", "z_max", "input", "seconds", "step", "hold", "ramp_speed",
                   "amplitude", "period", watch=True)
    def _leave_preset(self):
        """A setting moved away from the preset's: the view is no longer the preset (back to ``custom``)."""
        want = {**_STICKY, **VALVE_PRESETS.get(self.preset, {})}
        if self.preset in VALVE_PRESETS and any(getattr(self, k) != v for k, v in want.items()):
            self.preset = "custom"

    def params(self) -> ModelParams:
        """The valve's model (:func:`valve_params`)."""
        return valve_params(self.model, self.tau, self.v_max, self.e_dead, self.z_max, self.S, self.J)

    def signal(self) -> np.ndarray:
        """The input ``i`` (fraction of stroke), one value per 50 ms."""
        return valve_input(self.input, self.seconds, VALVE_SAMPLE, step=self.step, hold=self.hold,
                           ramp_speed=self.ramp_speed, amplitude=self.amplitude, period=self.period)

    def simulate(self) -> Traces:
        """Run this valve and the healthy one on the input; columns ``input``, ``stem``, ``healthy_h``, ...

        ``friction`` is the model's friction state: ``z / z_max`` for
        Riihilahti (the stem moves only outside ``[-1, 1]``), ``1`` while stuck
        for Choudhury and Kano, the stem velocity [stroke/s] for Karnopp.
        """
        u = self.signal()
        r = figures.valve_response(self.params(), u, VALVE_SAMPLE, dt=VALVE_DT, label="valve")
        g = _healthy_response(u.tobytes())
        if self.model == "riihilahti":
            fr, fu = (r.z / r.z_max if r.z_max > 0 else np.sign(r.z)), "z/z_max"
        elif self.model == "karnopp":
            fr, fu = r.z, "stroke/s"
        else:
            fr, fu = (r.stuck if r.stuck is not None else np.zeros_like(r.h)), "stuck"
        steps = _stem_jumps(r.h, u)
        return Traces(r.t, {"input": r.u, "stem": r.h, "healthy_h": g.h, "friction": fr},
                      {"input": "-", "stem": "-", "healthy_h": "-", "friction": fu},
                      {"friction_unit": fu, "stem_jumps": steps,
                       "stem_travel": float(np.abs(np.diff(r.h)).sum())})


@lru_cache(maxsize=8)
def _healthy_response(u_bytes: bytes) -> figures.ValveResponse:
    u = np.frombuffer(u_bytes, dtype=float)
    return figures.valve_response(figures.HEALTHY, u, VALVE_SAMPLE, dt=VALVE_DT, label="healthy")


def _stem_jumps(h: np.ndarray, u: np.ndarray) -> int:
    """Stick-slip count: samples where the stem moves more than 4 times its median moving speed.

    A stem that follows a ramp moves by about the same amount every sample; a
    sticky one stands still and then jumps. Returns the number of jumps.
    """
    dh = np.abs(np.diff(h))
    moving = dh[dh > 1e-6]
    if moving.size < 3:
        return 0
    big = dh > 4.0 * float(np.median(moving)) + 1e-4
    return int(np.sum(big[1:] & ~big[:-1]) + (1 if big[0] else 0))


# --------------------------------------------------------------------------- the loop
class LoopLab(param.Parameterized):
    """A PI loop (the paper's level tank, or a flow loop) with a sticky valve and its frictionless ghost."""

    process = param.Selector(default="level tank", objects=["level tank", "flow loop"],
                             doc="the process: the paper's tank (level, m) or a first-order flow loop (T = 10 s)",
                             label="process")
    model = param.Selector(default="riihilahti", objects=list(VALVE_MODELS),
                           doc="friction model", label="friction model")
    e_dead = param.Number(0.01, bounds=(0.0, 0.1), step=0.001,
                          doc="half dead band e_dead [fraction of stroke]", label="e_dead [fraction of stroke]")
    z_max = param.Number(0.3, bounds=(0.0, 1.0), step=0.005, doc="half friction band z_max [s]", label="z_max [s]")
    S = param.Number(0.04, bounds=(0.0, 0.3), step=0.005,
                     doc="stick band + dead band S [fraction of stroke]", label="S [fraction of stroke]")
    J = param.Number(0.02, bounds=(0.0, 0.3), step=0.005,
                     doc="slip jump J <= S [fraction of stroke]", label="J [fraction of stroke]")
    Kc = param.Number(1.0, bounds=(0.05, 20.0), step=0.05, doc="PI gain Kc [1/m] (flow: [-])", label="Kc [1/m]")
    Ti = param.Number(30.0, bounds=(1.0, 600.0), step=1.0, doc="PI integral time Ti [s]", label="Ti [s]")
    sp_step = param.Number(0.2, bounds=(-0.5, 0.5), step=0.01,
                           doc="set-point step [m] (flow: fraction)", label="set-point step [m]")
    sp_at = param.Number(60.0, bounds=(0.0, 3600.0), step=10.0,
                         doc="time of the set-point step [s]", label="set-point step at [s]")
    load = param.Number(0.0, bounds=(-0.3, 0.3), step=0.01,
                        doc="load step: extra inflow, fraction of the valve's full-open flow [-]",
                        label="load step [-]")
    load_at = param.Number(1800.0, bounds=(0.0, 3600.0), step=10.0,
                           doc="time of the load step [s]", label="load step at [s]")
    seconds = param.Number(3600.0, bounds=(300.0, 7200.0), step=100.0,
                           doc="length of the run [s] (scan 1 s)", label="length [s]")
    settle = param.Number(900.0, bounds=(0.0, 3000.0), step=50.0,
                          doc="transient left out of the limit-cycle detection [s]", label="detect after [s]")
    fig10 = param.Boolean(False,
                          doc="figure 10: the tank with low and high friction side by side",
                          label="fig10: low and high friction")

    scan_s = 1.0

    @param.depends("fig10", watch=True)
    def _fig10(self):
        if self.fig10:
            _, zm, ed = figures.FRICTION_LEVELS[-1]
            self.param.update(process="level tank", model="riihilahti", z_max=zm, e_dead=ed, Kc=1.0, Ti=30.0)

    def base(self) -> tuple[ModelParams, float]:
        """The process model (without its valve) and the starting set point."""
        if self.process == "flow loop":
            return ModelParams(process_kind="first_order", process=FirstOrderParams(K=1.0, T=10.0), dt=LOOP_DT), 0.5
        return ModelParams(dt=LOOP_DT), 1.0

    def params(self) -> ModelParams:
        """The loop's model with its sticky valve."""
        base, _ = self.base()
        v = figures.HEALTHY
        return valve_params(self.model, float(v.tau), float(v.v_max), self.e_dead, self.z_max, self.S, self.J,
                            dt=LOOP_DT, base=base)

    def _profiles(self) -> tuple[int, np.ndarray, np.ndarray, float]:
        T = int(round(self.seconds / self.scan_s))
        t = np.arange(T) * self.scan_s
        _, sp0 = self.base()
        sp = sp0 + np.where(t >= self.sp_at, self.sp_step, 0.0)
        base, _ = self.base()
        q_full = float(getattr(base.process, "K" if self.process == "flow loop" else "q_max"))
        load = np.where(t >= self.load_at, self.load * q_full, 0.0)
        return T, sp, load, sp0

    def _run(self, params: ModelParams) -> figures.ClosedLoopResult:
        from ..core import initial_state

        T, sp, load, sp0 = self._profiles()
        st = initial_state(params, 1, level=sp0)
        return figures.closed_loop_pi(params, sp, self.Kc, self.Ti, self.scan_s, T * self.scan_s, state=st,
                                      load=load)

    def read_cycle(self, r: figures.ClosedLoopResult):
        """The benchmark's detector (:func:`valve_gym.oscillation.detect_oscillation`) on the error after ``settle``."""
        from ..oscillation import detect_oscillation

        k0 = min(int(round(self.settle / self.scan_s)), r.t.size - 64)
        return detect_oscillation(r.sp[k0:, 0] - r.pv[k0:, 0], self.scan_s, "benchmark")

    def simulate(self, ghost: bool = True) -> Traces:
        """Run the loop (and its frictionless ghost); columns ``sp``, ``pv``, ``op``, ``stem`` (+ ``*_ghost``).

        ``summary`` holds the limit cycle found by the benchmark's detector:
        ``lc`` (bool), ``lc_amplitude`` (m, half peak-to-peak of the error),
        ``lc_period`` (s). With ``fig10`` the low- and high-friction loops of
        :func:`valve_gym.figures.limit_cycle_data` are run instead, in
        ``extra['low']`` and ``extra['high']``.
        """
        if self.fig10:
            return self._simulate_fig10()
        r = self._run(self.params())
        lc = self.read_cycle(r)
        unit = "m" if self.process == "level tank" else "-"
        cols = {"sp": r.sp[:, 0], "pv": r.pv[:, 0], "op": r.op[:, 0], "stem": r.stem[:, 0]}
        units = {"sp": unit, "pv": unit, "op": "-", "stem": "-"}
        if ghost:
            g = self._ghost()
            cols.update(pv_ghost=g.pv[:, 0], op_ghost=g.op[:, 0])
            units.update(pv_ghost=unit, op_ghost="-")
        return Traces(r.t, cols, units, _lc_summary(lc))

    def _ghost(self) -> figures.ClosedLoopResult:
        T, sp, load, sp0 = self._profiles()
        key = (self.process, self.Kc, self.Ti, T, self.sp_at, self.sp_step, self.load_at, self.load)
        return _ghost_run(key, self)

    def _simulate_fig10(self) -> Traces:
        levels = tuple(lv for lv in figures.FRICTION_LEVELS if lv[0] in ("low", "high"))
        cases = figures.limit_cycle_data(levels=levels, Kc=self.Kc, Ti=self.Ti, seconds=self.seconds,
                                         settle=self.settle, dt=LOOP_DT)
        extra = {}
        for c in cases:
            r = c.run
            extra[c.name] = Traces(r.t, {"sp": r.sp[:, 0], "pv": r.pv[:, 0], "op": r.op[:, 0],
                                         "stem": r.stem[:, 0]}, {"sp": "m", "pv": "m", "op": "-", "stem": "-"},
                                   {"lc": c.present, "lc_amplitude": c.amplitude, "lc_period": c.period,
                                    "z_max": float(c.valve.z_max), "e_dead": float(c.valve.e_dead)})
        hi = extra["high"]
        return Traces(hi.t, dict(hi.columns), dict(hi.units), dict(hi.summary), extra)


_GHOSTS: dict = {}


def _ghost_run(key, lab: LoopLab) -> figures.ClosedLoopResult:
    """The frictionless loop for ``key`` (cached: a friction slider does not re-run it)."""
    if key not in _GHOSTS:
        if len(_GHOSTS) > 16:
            _GHOSTS.clear()
        _GHOSTS[key] = lab._run(remove_friction(lab.params()))
    return _GHOSTS[key]


def _lc_summary(lc) -> dict:
    return {"lc": bool(lc.present), "lc_amplitude": float(lc.amplitude), "lc_period": float(lc.period_s)}


# --------------------------------------------------------------------------- the compensators
class CompensatorLab(param.Parameterized):
    """A compensator against the PI on the same sticky level loops (the benchmark's regulation task).

    ``n_loops`` loops of the benchmark's regulation part (each its own set
    point, load and noise draw, seeded) all get the valve set here; the PI,
    the PI on the frictionless valve and the compensator run on them, and the
    benchmark's scores are read: LC share, amplitude, R, travel.

    In exercise mode the valve's ``S`` and ``J`` are drawn from
    ``exercise_seed`` and hidden until ``reveal``.
    """

    controller = param.Selector(default="knocker", objects=list(COMPENSATORS), doc="compensator", label="compensator")
    model = param.Selector(default="choudhury", objects=["choudhury", "kano", "karnopp"],
                           doc="friction model", label="friction model")
    S = param.Number(0.04, bounds=(0.0, 0.2), step=0.005,
                     doc="valve stick band S [fraction of stroke]", label="S [fraction of stroke]")
    J = param.Number(0.02, bounds=(0.0, 0.2), step=0.005,
                     doc="valve slip jump J <= S [fraction of stroke]", label="J [fraction of stroke]")
    S_est = param.Number(0.04, bounds=(0.001, 0.2), step=0.001,
                         doc="the compensator's stiction estimate S [fraction of stroke]",
                         label="S_est [fraction of stroke]")
    a = param.Number(None, allow_None=True, bounds=(0.0, 0.5),
                     doc="knocker pulse / reinforcement amplitude a [fraction of stroke] (empty: its rule)",
                     label="a [fraction of stroke]")
    h_k = param.Number(None, allow_None=True, bounds=(1.0, 600.0),
                       doc="knocker: time between pulses h_k [s]", label="h_k [s]")
    tau_k = param.Number(None, allow_None=True, bounds=(1.0, 60.0),
                         doc="knocker: pulse width tau_k [s]", label="tau_k [s]")
    band = param.Number(None, allow_None=True, bounds=(0.0, 1.0),
                        doc="integral freeze: error band without integration [m]", label="band [m]")
    release = param.Number(None, allow_None=True, bounds=(0.001, 1.0),
                           doc="two-move: error that ends the hold [m]", label="release [m]")
    n_loops = param.Integer(4, bounds=(1, 24), doc="loops (benchmark regulation draws) [-]", label="loops")
    seed = param.Integer(0, bounds=(0, 10_000), doc="seed of the loops' load and noise", label="seed")
    exercise = param.Boolean(False,
                             doc="exercise: a valve of hidden S; tune the compensator, then reveal S",
                             label="exercise mode")
    exercise_seed = param.Integer(1, bounds=(0, 10_000), doc="which hidden valve", label="hidden valve no.")
    reveal = param.Boolean(False, doc="show the hidden valve's S and J", label="reveal S")

    _OWN = {"knocker": ("a", "h_k", "tau_k"), "constant_reinforcement": ("a",), "two_move": ("release",),
            "integral_freeze": ("band",), "learned": ()}

    def own_settings(self) -> tuple[str, ...]:
        """Names of this compensator's settings shown on the page (besides ``S_est``)."""
        return self._OWN[self.controller]

    def valve(self) -> tuple[float, float]:
        """The valve's ``(S, J)``: the sliders', or in exercise mode the hidden draw."""
        if not self.exercise:
            return float(self.S), float(min(self.J, self.S))
        rng = np.random.default_rng([int(self.exercise_seed), 39])
        S = float(0.01 * 8.0 ** rng.random())        # log-uniform in the benchmark's sticky band, 1 to 8 %
        return round(S, 4), round(S * float(rng.uniform(0.2, 0.9)), 4)

    def scenarios(self):
        """The loops: the benchmark's regulation draws with this page's valve (a ``Scenarios``)."""
        S, J = self.valve()
        sc = _regulation(int(self.n_loops), int(self.seed))
        n = sc.n
        return replace(sc, model=np.full(n, self.model), S=np.full(n, S), J=np.full(n, J))

    def block(self):
        """The compensator block (:func:`valve_gym.agents.load_controller`) with this page's settings."""
        from ..agents import load_controller

        if self.controller == "learned":
            return load_controller("learned")
        kw = {k: getattr(self, k) for k in self.own_settings() if getattr(self, k) is not None}
        return load_controller(self.controller, S=float(self.S_est), **kw)

    def simulate(self) -> Traces:
        """Run PI, frictionless PI and the compensator; traces of loop 0 and the benchmark's scores.

        ``summary``: ``lc_share_pi``, ``lc_share`` (share of loops with a limit
        cycle), ``lc_amplitude_pi``, ``lc_amplitude`` (median, m, 0 where none),
        ``R`` (median compensation ratio), ``travel_pi``, ``travel`` (median
        stem travel, strokes per hour), ``S``, ``J`` (the valve; hidden in
        exercise mode until revealed).
        """
        from ..agents.bench.config import BenchConfig
        from ..agents.bench.runner import run_loops
        from ..agents.bench.scores import compensation_ratio, score_runs

        sc = self.scenarios()
        cfg = BenchConfig()
        pi, free = _references(sc, self.model)
        comp = run_loops(self.block(), sc, label=self.controller)
        s_pi, s_0, s_c = (score_runs(r, cfg) for r in (pi, free, comp))
        R = compensation_ratio(s_pi.iae_per_h, s_c.iae_per_h, s_0.iae_per_h)
        S, J = self.valve()
        summ = {"lc_share_pi": float(s_pi.lc_present.mean()), "lc_share": float(s_c.lc_present.mean()),
                "lc_amplitude_pi": float(np.median(s_pi.lc_amplitude)),
                "lc_amplitude": float(np.median(s_c.lc_amplitude)), "R": float(np.median(R)),
                "travel_pi": float(np.median(s_pi.travel_per_h)), "travel": float(np.median(s_c.travel_per_h)),
                "iae_pi": float(np.median(s_pi.iae_per_h)), "iae": float(np.median(s_c.iae_per_h)),
                "S": S, "J": J, "settings": comp.settings}
        t = np.arange(sc.n_steps) * sc.scan_s
        cols = {"sp": comp.sp[:, 0], "pv": comp.pv[:, 0], "op": comp.op[:, 0], "stem": comp.stem[:, 0],
                "pv_pi": pi.pv[:, 0], "op_pi": pi.op[:, 0], "stem_pi": pi.stem[:, 0]}
        units = {k: ("m" if k.startswith(("sp", "pv")) else "-") for k in cols}
        return Traces(t, cols, units, summ)


@lru_cache(maxsize=4)
def _regulation(n: int, seed: int):
    from ..agents.bench.config import BenchConfig
    from ..agents.bench.scenarios import regulation_scenarios

    return regulation_scenarios(BenchConfig(), n=n, seed=seed)


_REFS: dict = {}


def _references(sc, model: str):
    """PI and frictionless-PI runs on ``sc`` (cached on the loops and the valve)."""
    from ..agents import load_controller
    from ..agents.bench.runner import run_loops

    key = (sc.n, sc.seed, model, float(sc.S[0]), float(sc.J[0]))
    if key not in _REFS:
        if len(_REFS) > 8:
            _REFS.clear()
        pi = run_loops(load_controller("pi", scan_s=sc.scan_s), sc, label="PI (SIMC)")
        free = run_loops(load_controller("pi", scan_s=sc.scan_s), sc, frictionless=True, label="PI frictionless")
        _REFS[key] = (pi, free)
    return _REFS[key]


def fmt_lc(summary: Mapping, unit: str = "m") -> str:
    """One line on the limit cycle of a :class:`Traces` summary."""
    if not summary.get("lc"):
        return "no limit cycle"
    amp = summary["lc_amplitude"]
    a = f"{amp * 1000:.1f} mm" if unit == "m" else f"{amp:.4f}"
    return f"limit cycle: amplitude {a}, period {summary['lc_period']:.0f} s"

