"""Teaching figures of control valve friction (``valve-gym figures``).

Compute and plot live apart. The compute functions return named results of
plain numpy arrays, so the numbers can be checked without plotting:

* :func:`valve_response` -- the valve alone (input ``i`` -> stem ``h`` and the
  friction state ``z``), sample by sample through the one physics core;
* :func:`valve_io_data`, :func:`valve_steps_data`, :func:`stick_slip_data` --
  the three open-loop experiments (slow sine, staircase, multi-ramp) for the
  paper's healthy valve and a sticky one;
* :func:`closed_loop_pi` -- the tank level loop under the batched PI law of
  :mod:`valve_gym.control`;
* :func:`limit_cycle_data` -- that loop for low, medium and high friction, and
  the limit cycle measured on each by :func:`valve_gym.oscillation.detect_oscillation`.

The ``plot_*`` functions draw one figure each (matplotlib is imported only
there, with the non-interactive Agg backend) and :func:`main` writes them all.
Every file is written atomically (a temporary name in the same folder, then
:func:`os.replace`), so a reader never sees half a PNG.

Example
-------
>>> from valve_gym.figures import valve_io_data
>>> data = valve_io_data(seconds=20.0)
>>> [r.label for r in data]  # doctest: +NORMALIZE_WHITESPACE
['healthy valve (z_max = 0.005, e_dead = 0.005)',
 'sticky valve (z_max = 0.2, e_dead = 0.02)']

References
----------
.. [1] K. Yamé, L. El Bahir, "Teaching control valve friction using modeling
   and simulation".
.. [2] M. Riihilahti, "Modeling and simulation of control valve
   nonlinearities", Helsinki University of Technology, 1997.
"""
from __future__ import annotations

import argparse
import csv
import io
import os
import sys
from collections.abc import Sequence
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ._io import folder_problem
from .control import PIParams
from .core import array_to_state, initial_state, pack, run_packed, state_to_array
from .loop import run_pi_loop
from .params import ModelParams, ValveParams
from .plant import Plant, PlantOutput

__all__ = [
    "HEALTHY", "STICKY", "FRICTION_LEVELS",
    "ValveResponse", "valve_response", "staircase", "multi_ramp",
    "valve_io_data", "valve_steps_data", "stick_slip_data",
    "ClosedLoopResult", "closed_loop_pi", "LimitCycleCase", "limit_cycle_data",
    "limit_cycle_rows", "limit_cycle_markdown", "write_limit_cycle_csv",
    "plot_valve_io", "plot_valve_steps", "plot_stick_slip", "plot_limit_cycles", "main",
]

#: The paper's healthy valve: tau = 0.1 s, z_max = 0.005 s, backlash about 1 %.
HEALTHY = ValveParams(tau=0.1, v_max=0.5, e_dead=0.005, z_max=0.005)
#: A valve with strong stiction and a 4 % dead band.
STICKY = ValveParams(tau=0.1, v_max=0.5, e_dead=0.02, z_max=0.2)

#: Friction levels of the closed-loop figure: (name, z_max [s], e_dead [-]).
#: ``'none'`` (no friction, no dead band) is the reference without a limit cycle.
FRICTION_LEVELS = (
    ("none", 0.0, 0.0),
    ("low", 0.005, 0.002),
    ("medium", 0.05, 0.005),
    ("high", 0.3, 0.01),
)


def _valve_label(name: str, v: ValveParams) -> str:
    return f"{name} valve (z_max = {v.z_max:g}, e_dead = {v.e_dead:g})"


# --------------------------------------------------------------------------- #
# The valve alone
# --------------------------------------------------------------------------- #
class ValveResponse(NamedTuple):
    """Response of the valve alone to an input sequence.

    Attributes
    ----------
    label : str
        Which valve (for legends).
    t : (T,) array, s
        Time at the end of each input sample.
    u : (T,) array, -
        Valve input ``i`` (0..1) held over each sample.
    h : (T,) array, -
        Stem position (0..1) at the end of each sample.
    z : (T,) array, s
        Friction / time-delay state at the end of each sample; the stem can
        move only while ``|z| > z_max``.
    z_max : float, s
        Half width of the friction band of this valve.
    stuck : (T,) array or None
        1.0 while the slip-jump friction block holds the stem stuck, else 0.0
        (``None`` for a valve without that block).
    """

    label: str
    t: np.ndarray
    u: np.ndarray
    h: np.ndarray
    z: np.ndarray
    z_max: float
    stuck: np.ndarray | None = None


def valve_response(valve: ValveParams | ModelParams, u, sample_time: float, dt: float = 1e-3,
                   h0: float | None = None, label: str = "") -> ValveResponse:
    """Drive the valve alone with the input ``u`` and record stem and friction state.

    The valve is the physics core's (:mod:`valve_gym.core`) with the default
    tank attached; only the stem position and ``z`` are read, so the tank plays
    no part. The state starts at rest (``z = 0``, stuck) with the stem at
    ``h0``.

    Parameters
    ----------
    valve : ValveParams or ModelParams
        Scalar valve parameters (the paper's valve), or a whole scalar model
        (e.g. from :func:`valve_gym.friction.valve_model`, any friction
        model); its ``dt`` is replaced by ``dt``.
    u : (T,) array_like, -
        Valve input (0..1), held over each sample of ``sample_time`` seconds.
    sample_time : float, s
        Duration of one input sample; must be a whole number of Euler steps.
    dt : float, s
        Euler step (<= ``valve.tau``). The default 1 ms is far below the
        valve's time constant, so the curves show the model and not the
        integration (with a coarse step the friction state overshoots its band
        edge by up to ``dt * e`` and the stem slips a little on reversals).
    h0 : float, optional
        Initial stem position; default ``u[0]``.
    label : str
        Stored in the result for legends.

    Returns
    -------
    ValveResponse
    """
    u = np.asarray(u, dtype=float).reshape(-1)
    if u.size == 0 or not np.isfinite(u).all():
        raise ValueError("u must be a non-empty array of finite valve inputs (0..1)")
    n_sub = _n_sub(sample_time, dt)
    params = replace(valve, dt=dt) if isinstance(valve, ModelParams) else ModelParams(valve=valve, dt=dt)
    pk = pack(params, 1)
    st = initial_state(params, 1, h=float(u[0] if h0 is None else h0), buf_len=pk.buf_len)
    S = state_to_array(st)
    buf = np.array(st.delay_buf, dtype=float)
    view = array_to_state(S, buf)
    T = u.size
    U = np.ascontiguousarray(u.reshape(T, 1))
    D = np.zeros((1, 1))
    Y, H, LV = (np.empty((1, 1)) for _ in range(3))
    h = np.empty(T)
    z = np.empty(T)
    stuck = np.empty(T)
    for k in range(T):
        run_packed(pk, S, buf, U[k:k + 1], D, n_sub, Y, H, LV)
        h[k] = H[0, 0]
        z[k] = view.z[0]
        stuck[k] = view.stuck[0]
    t = np.arange(1, T + 1) * sample_time
    return ValveResponse(label=label, t=t, u=np.clip(u, 0.0, 1.0), h=h, z=z,
                         z_max=float(np.asarray(params.valve.z_max)),
                         stuck=stuck if params.slip_jump is not None else None)


def _n_sub(sample_time: float, dt: float) -> int:
    if not (np.isfinite(sample_time) and sample_time > 0):
        raise ValueError(
            f"the sample time must be a positive number of seconds, got {sample_time!r}")
    n_sub = int(round(sample_time / dt))
    if n_sub < 1 or abs(n_sub * dt - sample_time) > 1e-9 * max(1.0, sample_time):
        raise ValueError(
            f"the sample time {sample_time} s must be a whole number of Euler steps dt = {dt} s; "
            f"choose a sample time that is a multiple of dt")
    return n_sub


def valve_io_data(seconds: float = 200.0, period: float = 100.0, amplitude: float = 0.3,
                  sample_time: float = 0.05) -> list[ValveResponse]:
    """Slow sine input for the healthy and the sticky valve (input-output plot).

    ``i(t) = 0.5 - amplitude * cos(2 pi t / period)``, starting at rest at its
    minimum.

    Parameters
    ----------
    seconds : float, s
        Length of the experiment.
    period : float, s
        Period of the sine.
    amplitude : float, -
        Amplitude of the sine (fraction of the stroke).
    sample_time : float, s
        Input sample.

    Returns
    -------
    list of ValveResponse
        ``[healthy, sticky]``.
    """
    t = np.arange(int(round(seconds / sample_time))) * sample_time
    u = 0.5 - amplitude * np.cos(2 * np.pi * t / period)
    return [valve_response(v, u, sample_time, label=_valve_label(name, v))
            for name, v in (("healthy", HEALTHY), ("sticky", STICKY))]


def staircase(levels: Sequence[float] | np.ndarray, hold: float, sample_time: float) -> np.ndarray:
    """Piecewise-constant input: each value of ``levels`` held ``hold`` seconds.

    Returns
    -------
    (len(levels) * hold / sample_time,) array
    """
    m = int(round(hold / sample_time))
    return np.repeat(np.asarray(levels, dtype=float), m)


def valve_steps_data(step: float = 0.05, n_steps: int = 4, hold: float = 15.0,
                     sample_time: float = 0.05) -> list[ValveResponse]:
    """Staircase up then down (``n_steps`` steps of ``step`` each way) for both valves.

    Starts at 0.4, climbs to ``0.4 + n_steps*step`` and comes back.

    Returns
    -------
    list of ValveResponse
        ``[healthy, sticky]``.
    """
    up = 0.4 + step * np.arange(n_steps + 1)
    levels = np.concatenate([up, up[-2::-1]])
    u = staircase(levels, hold, sample_time)
    return [valve_response(v, u, sample_time, label=_valve_label(name, v))
            for name, v in (("healthy", HEALTHY), ("sticky", STICKY))]


def multi_ramp(points: Sequence[float], slopes: Sequence[float], sample_time: float,
               start: float = 0.5, hold: float = 5.0) -> np.ndarray:
    """Input made of ramps from ``start`` through ``points`` at the given slopes.

    Parameters
    ----------
    points : sequence of float, -
        Successive end points of the ramps.
    slopes : sequence of float, 1/s
        Speed of each ramp (> 0), same length as ``points``.
    sample_time : float, s
    start : float, -
        Initial input, held ``hold`` seconds first.

    Returns
    -------
    (T,) array
    """
    parts = [np.full(int(round(hold / sample_time)), start)]
    x = start
    for p, s in zip(points, slopes):
        n = max(1, int(round(abs(p - x) / (s * sample_time))))
        parts.append(np.linspace(x, p, n + 1)[1:])
        x = p
    return np.concatenate(parts)


def stick_slip_data(sample_time: float = 0.05) -> list[ValveResponse]:
    """Multi-ramp input (up, down, up, down at different speeds) for both valves.

    On every reversal the sticky valve stays stuck while ``z`` crosses its band
    ``[-z_max, z_max]``, then slips: the stem jumps to catch up with the input.

    Returns
    -------
    list of ValveResponse
        ``[healthy, sticky]``.
    """
    u = multi_ramp([0.7, 0.45, 0.65, 0.35, 0.6], [0.01, 0.01, 0.005, 0.02, 0.01], sample_time)
    return [valve_response(v, u, sample_time, label=_valve_label(name, v))
            for name, v in (("healthy", HEALTHY), ("sticky", STICKY))]


# --------------------------------------------------------------------------- #
# Closed loop
# --------------------------------------------------------------------------- #
class ClosedLoopResult(NamedTuple):
    """A closed-loop run, sampled at the controller instants (time axis first).

    Attributes
    ----------
    t : (T,) array, s
        Sample instants ``k * control_period``.
    sp : (T, n) array, m
        Set point.
    pv : (T, n) array, m
        Measured level (with measurement noise if any) seen by the controller.
    op : (T, n) array, -
        Controller output (valve input, 0..1) applied from ``t[k]`` to ``t[k+1]``.
    stem : (T, n) array, -
        Stem position at ``t[k]``.
    level : (T, n) array, m
        Noise-free level of the measured tank at ``t[k]``.
    """

    t: np.ndarray
    sp: np.ndarray
    pv: np.ndarray
    op: np.ndarray
    stem: np.ndarray
    level: np.ndarray


def closed_loop_pi(params: ModelParams, sp, Kc, Ti, control_period: float = 1.0,
                   seconds: float = 1000.0, noise_std: float = 0.0,
                   seed: int | None = None, state=None, load=None) -> ClosedLoopResult:
    """Level loop: the PI law of :mod:`valve_gym.control` driving the model.

    :func:`valve_gym.loop.run_pi_loop` on a :class:`~valve_gym.plant.Plant`: every
    ``control_period`` seconds the controller reads the level (plus white measurement noise of
    std ``noise_std``), computes its output with :func:`valve_gym.control.pi_step` and the plant
    integrates ``control_period / params.dt`` Euler steps with that output held.

    Parameters
    ----------
    params : ModelParams
        Model; floats or ``(n,)`` arrays (a batch of loops run side by side).
    sp : float, (T,) or (T, n) array_like, m
        Set point: constant, or one value per control sample ``T =
        round(seconds / control_period)`` (a 1-D array is a time profile).
    Kc : float or (n,) array_like, 1/m
        Controller gain (> 0: more level error opens the inflow valve).
    Ti : float or (n,) array_like, s
        Integral time.
    control_period : float, s
        Controller sample time; a whole number of ``params.dt``.
    seconds : float, s
        Length of the run.
    noise_std : float, m
        Standard deviation of the measurement noise (0: none).
    seed : int, optional
        Seed of :func:`numpy.random.default_rng` for the noise.
    state : State, optional
        Initial state (default :func:`valve_gym.core.initial_state`: at rest,
        at ``params.process.level0``, stem at the steady opening).
    load : float or (T,) array_like, m^3/s, optional
        Extra inflow held over each control sample (negative: an offtake;
        process units for ``first_order``); default none.

    Returns
    -------
    ClosedLoopResult

    Raises
    ------
    ValueError
        For a control period that is not a whole number of Euler steps, a
        negative ``noise_std``, a set point of the wrong shape or a run shorter
        than one sample.

    Examples
    --------
    >>> from valve_gym.params import ModelParams
    >>> r = closed_loop_pi(ModelParams(), sp=1.2, Kc=1.0, Ti=30.0, seconds=300.0)
    >>> r.pv.shape
    (300, 1)
    >>> abs(float(r.pv[-1, 0]) - 1.2) < 0.01  # the level has reached the set point
    True
    """
    _n_sub(control_period, params.dt)          # a whole number of Euler steps, or a clear error
    T = int(round(seconds / control_period))
    if T < 1:
        raise ValueError(
            f"seconds = {seconds} is shorter than one control period ({control_period} s)")
    if not (np.isfinite(noise_std) and noise_std >= 0):
        raise ValueError(f"noise_std must be a number >= 0 (metres), got {noise_std!r}")
    n = params.batch_size()
    for v in (Kc, Ti):
        if np.ndim(v) == 1:
            n = max(n, np.shape(v)[0])
    pk = pack(params, n)
    if state is not None and state.n != n:
        raise ValueError(f"state has batch size {state.n}, expected {n}")
    spa = np.asarray(sp, dtype=float)
    if spa.ndim == 0:
        spa = np.full((T, n), float(spa))
    elif spa.ndim == 1 and spa.shape[0] == T:
        spa = np.repeat(spa[:, None], n, axis=1)
    elif spa.ndim == 2 and spa.shape[0] == T and spa.shape[1] in (1, n):
        spa = np.broadcast_to(spa, (T, n)).copy()
    else:
        raise ValueError(f"sp must be a float, a ({T},) profile or a ({T}, {n}) array, "
                         f"got shape {spa.shape}")
    if not np.isfinite(spa).all():
        raise ValueError("sp contains NaN or inf values")
    pi = PIParams(Kc=np.broadcast_to(np.asarray(Kc, float), (n,)).copy(),
                  Ti=np.broadcast_to(np.asarray(Ti, float), (n,)).copy(), Ts=float(control_period))
    plant = Plant(params, n, scan_s=float(control_period))
    start = plant.reset()
    if state is not None:
        buf = np.asarray(state.delay_buf, dtype=float)
        if buf.shape != (n, pk.buf_len):
            raise ValueError("state.delay_buf does not match the model's dead time")
        plant.set_state(state)
        st = plant.state
        start = PlantOutput(pv=(st.level2 if params.process_kind == "cascade" else st.level).copy(),
                            stem=np.clip(st.h, 0.0, 1.0), op=st.u_prev.copy(), y=st.y.copy())
    da = np.zeros(T) if load is None else np.asarray(load, dtype=float)
    if da.ndim == 0:
        da = np.full(T, float(da))
    if da.shape != (T,) or not np.isfinite(da).all():
        raise ValueError(f"load must be a finite number or a ({T},) profile of inflows (m^3/s), "
                         f"got shape {da.shape}")
    run = run_pi_loop(plant, start, spa, pi, noise_std, np.random.default_rng(seed),
                      d=None if load is None else da)
    t = np.arange(T) * control_period
    return ClosedLoopResult(t=t, sp=spa, pv=run.pv[:T], op=run.op, stem=run.stem[:T], level=run.level[:T])


class LimitCycleCase(NamedTuple):
    """Closed-loop run and measured limit cycle for one friction level.

    Attributes
    ----------
    name : str
        Friction level (``'low'``, ``'medium'``, ``'high'``).
    valve : ValveParams
    run : ClosedLoopResult
        With ``n = 1``.
    present : bool
        A regular oscillation was found in the level error (last part of the run).
    amplitude : float, m
        Half peak-to-peak of the level oscillation, median over windows one period long
        (0 when not present).
    period : float, s
        Oscillation period (``inf`` when not present).
    n_cycles : int
        Whole periods in the measured part of the record (0 when not present).
    Kc : float, 1/m
        Controller gain used.
    Ti : float, s
        Integral time used.
    """

    name: str
    valve: ValveParams
    run: ClosedLoopResult
    present: bool
    amplitude: float
    period: float
    n_cycles: int
    Kc: float
    Ti: float


def limit_cycle_data(levels=FRICTION_LEVELS, Kc: float = 1.0, Ti: float = 30.0,
                     control_period: float = 1.0, seconds: float = 3000.0, sp: float = 1.2,
                     settle: float = 1000.0, dt: float = 0.002) -> list[LimitCycleCase]:
    """Run the level loop for each friction level and measure its limit cycle.

    The default tank (:class:`~valve_gym.params.TankParams`) starts at rest at
    1 m with the stem at its steady opening; the set point ``sp`` is applied at
    t = 0 (a set-point step, which is what sets the sticky loop cycling: with
    ``sp = 1`` the loop would stay at rest). The oscillation is measured with
    :func:`valve_gym.oscillation.detect_oscillation` (benchmark rule) on the
    error ``sp - pv`` after the first ``settle`` seconds.

    Parameters
    ----------
    levels : sequence of (name, z_max, e_dead)
    Kc : float, 1/m
    Ti : float, s
    control_period : float, s
    seconds : float, s
        Length of each run.
    sp : float, m
    settle : float, s
        Transient left out of the measurement.
    dt : float, s
        Euler step. The default 2 ms (500 steps per control period) gives
        amplitudes and periods within about 1 % of the limit ``dt -> 0``; the
        environment's 20 ms shifts them by a few per cent (the friction state
        overshoots its band edge by up to ``dt * e`` in one step).

    Returns
    -------
    list of LimitCycleCase
    """
    from .oscillation import detect_oscillation

    valve = ValveParams(tau=HEALTHY.tau, v_max=HEALTHY.v_max,
                        z_max=np.array([lv[1] for lv in levels], float),
                        e_dead=np.array([lv[2] for lv in levels], float))
    params = ModelParams(valve=valve, dt=dt)
    run = closed_loop_pi(params, sp, Kc, Ti, control_period, seconds)
    k0 = int(round(settle / control_period))
    out = []
    for j, (name, zm, ed) in enumerate(levels):
        one = ClosedLoopResult(*(a if a.ndim == 1 else a[:, j:j + 1] for a in run))
        lc = detect_oscillation(one.sp[k0:, 0] - one.pv[k0:, 0], control_period, "benchmark")
        out.append(LimitCycleCase(name=name, valve=replace(HEALTHY, z_max=zm, e_dead=ed), run=one,
                                  present=bool(lc.present), amplitude=float(lc.amplitude),
                                  period=float(lc.period_s) if lc.present else float("inf"),
                                  n_cycles=int(lc.n_cycles) if lc.present else 0,
                                  Kc=float(Kc), Ti=float(Ti)))
    return out


# --------------------------------------------------------------------------- #
# The limit-cycle table
# --------------------------------------------------------------------------- #
_TABLE_HEADER = ("friction", "z_max [s]", "e_dead [-]", "limit cycle", "amplitude [m]",
                 "period [s]", "cycles")


def limit_cycle_rows(cases: Sequence[LimitCycleCase]) -> list[tuple]:
    """Rows ``(friction, z_max, e_dead, present, amplitude_m, period_s, n_cycles)``."""
    return [(c.name, float(c.valve.z_max), float(c.valve.e_dead), c.present, c.amplitude,
             c.period, c.n_cycles) for c in cases]


def _fmt_row(r) -> list[str]:
    name, zm, ed, present, amp, per, nc = r
    return [name, f"{zm:g}", f"{ed:g}", "yes" if present else "no",
            f"{amp:.4f}" if present else "-", f"{per:.0f}" if present else "-", str(nc)]


def limit_cycle_markdown(cases: Sequence[LimitCycleCase]) -> str:
    """The limit-cycle table as GitHub-flavoured Markdown (level oscillation per friction level)."""
    lines = ["| " + " | ".join(_TABLE_HEADER) + " |",
             "|" + "|".join(["---"] + ["---:"] * (len(_TABLE_HEADER) - 1)) + "|"]
    lines += ["| " + " | ".join(_fmt_row(r)) + " |" for r in limit_cycle_rows(cases)]
    return "\n".join(lines) + "\n"


def write_limit_cycle_csv(cases: Sequence[LimitCycleCase], f) -> None:
    """Write the table as CSV to the text stream ``f`` (no limit cycle: amplitude 0, period inf)."""
    w = csv.writer(f, lineterminator="\n")
    w.writerow(["friction", "z_max_s", "e_dead", "limit_cycle", "amplitude_m", "period_s",
                "n_cycles"])
    for name, zm, ed, present, amp, per, nc in limit_cycle_rows(cases):
        w.writerow([name, f"{zm:g}", f"{ed:g}", int(present), f"{amp:.6g}", f"{per:.6g}", nc])


# --------------------------------------------------------------------------- #
# Plotting (matplotlib imported here only)
# --------------------------------------------------------------------------- #
_COLORS = {"input": "0.25", "healthy": "tab:blue", "sticky": "tab:red"}


def _figure(w: float, h: float):
    """A stand-alone Agg figure (no pyplot, no global backend switch)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - matplotlib is a dependency
        raise ImportError("the figures need matplotlib: pip install matplotlib") from exc
    fig = Figure(figsize=(w, h), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _color(r: ValveResponse) -> str:
    return _COLORS["sticky"] if r.label.startswith("sticky") else _COLORS["healthy"]


def plot_valve_io(data: Sequence[ValveResponse], zoom: float = 0.06):
    """Input-output (``i`` vs ``h``) plot of each valve; returns the Figure.

    Each panel has an inset magnifying the top reversal (``zoom`` wide, in
    fractions of the stroke), where the healthy valve's small loop shows.
    """
    fig = _figure(12, 5.8)
    axes = np.atleast_1d(fig.subplots(1, len(data), sharex=True, sharey=True))
    for ax, r in zip(axes, data):
        lo, hi = float(r.u.min()), float(r.u.max())
        ax.plot([lo, hi], [lo, hi], ls=":", color="0.4", lw=1, label="ideal valve (h = i)")
        ax.plot(r.u, r.h, color=_color(r), lw=1.6, label="stem position h")
        ax.set_title(r.label)
        ax.set_xlabel("valve input i (controller output) [fraction of stroke]")
        ax.set_aspect("equal", adjustable="box")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=9)
        ins = ax.inset_axes([0.56, 0.06, 0.41, 0.41])
        ins.plot([lo, hi], [lo, hi], ls=":", color="0.4", lw=1)
        ins.plot(r.u, r.h, color=_color(r), lw=1.4)
        ins.set_xlim(hi - zoom, hi + 0.1 * zoom)
        ins.set_ylim(hi - zoom, hi + 0.1 * zoom)
        ins.set_aspect("equal", adjustable="box")
        ins.tick_params(labelsize=7)
        ins.grid(alpha=0.3)
        ins.set_title("top reversal, magnified", fontsize=8)
        ax.indicate_inset_zoom(ins, edgecolor="0.5")
    axes[0].set_ylabel("stem position h [fraction of stroke]")
    fig.suptitle("Valve input vs stem position under a slow sine input: the width of the loop "
                 "is the dead band plus the stiction")
    return fig


def _plot_time_and_z(data: Sequence[ValveResponse], title: str, input_label: str):
    fig = _figure(11, 7)
    ax1, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=[2, 1])
    t = data[0].t
    ax1.plot(t, data[0].u, color=_COLORS["input"], ls="--", lw=1.2, label=input_label)
    for r in data:
        ax1.plot(r.t, r.h, color=_color(r), lw=1.6, label="stem: " + r.label)
        zn = r.z / r.z_max if r.z_max > 0 else np.sign(r.z)
        ax2.plot(r.t, zn, color=_color(r), lw=1.3, label=r.label)
    ax1.set_ylabel("input i, stem position h\n[fraction of stroke]")
    ax1.legend(loc="best", fontsize=9)
    ax1.grid(alpha=0.3)
    ax1.set_title(title)
    ax2.axhspan(-1, 1, color="0.88", zorder=0,
                label="|z| <= z_max: stem stuck (it moves only outside this band)")
    ax2.set_ylabel("friction state z / z_max [-]")
    ax2.set_xlabel("time [s]")
    ax2.grid(alpha=0.3)
    ax2.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncols=2, fontsize=9,
               frameon=False)
    return fig


def plot_valve_steps(data: Sequence[ValveResponse]):
    """Staircase response of each valve (stem and ``z``); returns the Figure."""
    return _plot_time_and_z(
        data, "Staircase input: after a reversal the sticky valve waits until z has crossed "
              "its band\n(dead time 2 z_max / (D - 2 e_dead) for a step D), longer here than "
              "the first step down lasts", "input i (staircase)")


def plot_stick_slip(data: Sequence[ValveResponse]):
    """Multi-ramp response: stick-slip of the sticky valve; returns the Figure."""
    return _plot_time_and_z(
        data, "Ramps: after each reversal the sticky valve sticks, then slips (jumps) "
              "to catch up with the input", "input i (ramps)")


def plot_limit_cycles(cases: Sequence[LimitCycleCase], window: float = 800.0):
    """Closed-loop level control for each friction level (PV, OP, stem); returns the Figure.

    Shows the last ``window`` seconds of each run.
    """
    fig = _figure(4.2 * len(cases), 7.5)
    axes = fig.subplots(2, len(cases), sharex=True, squeeze=False)
    for j, c in enumerate(cases):
        r = c.run
        k = r.t >= r.t[-1] - window
        a1, a2 = axes[0, j], axes[1, j]
        a1.plot(r.t[k], r.sp[k, 0], color="0.3", ls="--", lw=1, label="set point SP")
        a1.plot(r.t[k], r.pv[k, 0], color="tab:blue", lw=1.5, label="level PV")
        head = ("no friction" if c.name == "none" else f"{c.name} friction") + \
            f": z_max = {c.valve.z_max:g} s, e_dead = {c.valve.e_dead:g}"
        if c.present:
            head += f"\nlimit cycle: amplitude {c.amplitude * 1000:.1f} mm, period {c.period:.0f} s"
        else:
            head += "\nno limit cycle"
        a1.set_title(head, fontsize=10)
        a2.plot(r.t[k], r.op[k, 0], color="tab:orange", lw=1.5, label="controller output OP")
        a2.plot(r.t[k], r.stem[k, 0], color="tab:red", lw=1.5, label="stem position")
        a2.set_xlabel("time [s]")
        for a in (a1, a2):
            a.grid(alpha=0.3)
            if j == 0:  # one legend per row, on the first (quietest) panel
                a.legend(loc="upper right", fontsize=8)
        _pad_ylim(a1, r.pv[k, 0], r.sp[k, 0], floor=0.01)
        _pad_ylim(a2, r.op[k, 0], r.stem[k, 0], floor=0.01)
    axes[0, 0].set_ylabel("level [m]")
    axes[1, 0].set_ylabel("OP, stem position [fraction of stroke]")
    fig.suptitle(
        f"PI level control (Kc = {cases[0].Kc:g} /m, Ti = {cases[0].Ti:g} s, "
        f"sampled every {float(cases[0].run.t[1] - cases[0].run.t[0]):g} s) after a set-point step, "
        f"last {window:g} s:\nwith friction the loop cycles -- triangular level and controller output, "
        "stem moving in jumps")
    return fig


def _pad_ylim(ax, *ys, floor: float):
    lo = min(float(np.min(y)) for y in ys)
    hi = max(float(np.max(y)) for y in ys)
    mid, half = 0.5 * (lo + hi), max(0.5 * (hi - lo), 0.5 * floor)
    ax.set_ylim(mid - 1.25 * half, mid + 1.25 * half)


# --------------------------------------------------------------------------- #
# Writing files
# --------------------------------------------------------------------------- #
def _write_atomic(path, write) -> str:
    """Write atomically (see :func:`valve_gym._io.write_atomic`)."""
    from ._io import write_atomic

    return write_atomic(path, write)


def _save_figure(fig, path: str, dpi: int) -> str:
    return _write_atomic(path, lambda f: fig.savefig(f, format="png", dpi=dpi))


def _save_text(text: str, path: str) -> str:
    return _write_atomic(path, lambda f: f.write(text.encode("utf-8")))


def main(argv: Sequence[str] | None = None) -> int:
    """``valve-gym figures --out DIR [--dpi N]``: write the teaching figures.

    Writes ``valve_io.png``, ``valve_steps.png``, ``stick_slip_ramps.png``,
    ``limit_cycles.png``, ``limit_cycles.md`` and ``limit_cycles.csv`` into
    ``DIR`` (created if missing), printing each path, and prints the
    limit-cycle table.

    Returns
    -------
    int
        Exit status (0 on success, 2 on bad arguments).
    """
    ap = argparse.ArgumentParser(
        prog="valve-gym figures",
        description="Write the teaching figures of control valve friction (PNG) and the "
                    "closed-loop limit-cycle table (Markdown and CSV).")
    ap.add_argument("--out", required=True, metavar="DIR",
                    help="output folder (created if missing)")
    ap.add_argument("--dpi", type=int, default=120, metavar="N",
                    help="resolution of the PNG files in dots per inch (default 120)")
    args = ap.parse_args(None if argv is None else list(argv))
    if not 20 <= args.dpi <= 600:
        ap.error(f"--dpi must be between 20 and 600, got {args.dpi}")
    out = args.out
    why = folder_problem(out) if out.strip() else "empty; give an output folder"
    if not why:
        try:
            os.makedirs(out, exist_ok=True)
        except OSError as exc:
            why = f"cannot create the output folder ({exc.strerror or exc})"
    if why:
        print(f"valve-gym figures: --out {out}: {why}", file=sys.stderr)
        return 2

    jobs = [
        ("valve input vs stem position (slow sine)", "valve_io.png", valve_io_data, plot_valve_io),
        ("staircase step responses", "valve_steps.png", valve_steps_data, plot_valve_steps),
        ("stick-slip under ramps", "stick_slip_ramps.png", stick_slip_data, plot_stick_slip),
    ]
    n_jobs = len(jobs) + 1
    for i, (what, name, compute, plot) in enumerate(jobs, 1):
        print(f"[{i}/{n_jobs}] {what} ...", flush=True)
        print(_save_figure(plot(compute()), os.path.join(out, name), args.dpi), flush=True)

    print(f"[{n_jobs}/{n_jobs}] closed-loop PI level control, friction levels "
          f"{', '.join(lv[0] for lv in FRICTION_LEVELS)} ...", flush=True)
    cases = limit_cycle_data()
    print(_save_figure(plot_limit_cycles(cases), os.path.join(out, "limit_cycles.png"), args.dpi))
    md = limit_cycle_markdown(cases)
    print(_save_text(md, os.path.join(out, "limit_cycles.md")))
    buf = io.StringIO()
    write_limit_cycle_csv(cases, buf)
    print(_save_text(buf.getvalue(), os.path.join(out, "limit_cycles.csv")))
    print("\nLimit cycle of the level per friction level (amplitude = half peak-to-peak):\n")
    print(md, flush=True)
    return 0
