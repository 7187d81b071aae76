"""The closed-loop runner of valve_gym: any DCS block on one plant or on several plants over column groups.

:func:`run_closed_loop` runs ``n`` loops for ``T`` scans. One scan ``k`` is::

    pv_k  = y_k + noise_k                      measured level (sensor output plus pre-drawn noise)
    op_k  = block.step(sp_k, pv_k)             the controller, one call over all n loops
    plant.advance(sat(op_k), load_k)  ->  y_{k+1}, stem_{k+1}, level_{k+1}

The block starts bumplessly, ``block.reset(sp_0, pv_0, op_0)`` with the plant's input at rest. The
block is anything with ``reset(sp, pv, op)`` and ``step(sp, pv) -> (n,)`` (the controllers of
:func:`valve_gym.agents.load_controller`, the learned blocks, :class:`PILaw` for the PI law of
:mod:`valve_gym.control`). The plant is a :class:`~valve_gym.plant.Plant`, any object with
``n``, ``scan_s`` and ``scan(u, d) -> (y, stem, level)`` (:class:`LoopPlant`), or a list of
``(columns, plant)`` pairs, one plant per column group (the benchmark runs one batched plant per
friction model). The inputs are checked once, up front; the block's outputs every scan (finite).

Users: the benchmark (:func:`valve_gym.agents.bench.runner.run_loops`) and its generalisation part,
the trainers' rollouts (:func:`valve_gym.agents.es.rollout_scores`, the adaptive trainer), the
synthetic recordings (:mod:`valve_gym.diagnosis.synthetic`, and through them the fleet simulator)
and the teaching figures (:func:`valve_gym.figures.closed_loop_pi`), the last two through
:func:`run_pi_loop`.

Example
-------
>>> import numpy as np
>>> from valve_gym.control import PIParams
>>> from valve_gym.params import ModelParams
>>> from valve_gym.plant import Plant
>>> plant = Plant(ModelParams(), 1)
>>> sc = Scenario(sp=np.full((300, 1), 1.2), scan_s=1.0)
>>> run = run_closed_loop(plant, PILaw(PIParams(Kc=1.0, Ti=30.0)), sc, start=plant.reset(level=1.0))
>>> run.op.shape, run.pv.shape, abs(float(run.level[-1, 0]) - 1.2) < 0.01
((300, 1), (301, 1), True)
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np

from .control import PIParams, pi_init, pi_step
from .plant import Plant, PlantOutput

__all__ = ["LoopRun", "Scenario", "LoopPlant", "PILaw", "run_closed_loop", "run_pi_loop"]


class LoopRun(NamedTuple):
    """The signals of a closed-loop run of ``T`` scans of ``n`` loops.

    op : (T, n), block output over scan ``k`` (before the valve's 0..1 saturation)
    pv : (T + 1, n), measured level at the start of scan ``k`` (row ``T``: after the last scan) [m]
    level : (T + 1, n), true level of the measured tank at the same instants [m]
    stem : (T + 1, n), stem position at the same instants (0..1)
    """

    op: np.ndarray
    pv: np.ndarray
    level: np.ndarray
    stem: np.ndarray


@dataclass(frozen=True, eq=False)
class Scenario:
    """What the loops are asked to do: set points, loads and measurement noise, all drawn beforehand.

    Parameters
    ----------
    sp : (T, n) array, set point of each scan [m]
    scan_s : float, scan time [s] (must equal the plants'; a block runs at the scan it is given, whatever
        ``scan_s`` it was set up for, as a DCS block scheduled at another rate would)
    load : (T, n) array, optional, extra inflow of each scan [m^3/s] (default none)
    noise : (T + 1, n) or (T, n) array, optional, measurement noise of measurement ``k`` [m]; with ``T``
        rows the last measurement (after the last scan) is noise-free (default: no noise)
    """

    sp: np.ndarray
    scan_s: float
    load: np.ndarray | None = None
    noise: np.ndarray | None = None

    def checked(self) -> Scenario:
        """The scenario as finite float arrays of consistent shapes (ValueError naming the problem)."""
        sp = np.asarray(self.sp, float)
        if sp.ndim != 2 or not np.isfinite(sp).all():
            raise ValueError(f"scenario.sp must be a finite (T, n) array of set points, got shape {sp.shape}")
        T, n = sp.shape
        if not (np.isfinite(self.scan_s) and self.scan_s > 0):
            raise ValueError(f"scenario.scan_s must be > 0 s, got {self.scan_s!r}")
        load = None if self.load is None else np.asarray(self.load, float)
        if load is not None and (load.shape != (T, n) or not np.isfinite(load).all()):
            raise ValueError(f"scenario.load must be a finite (T, n) = ({T}, {n}) array of inflows, "
                             f"got shape {load.shape}")
        noise = None if self.noise is None else np.asarray(self.noise, float)
        if noise is not None and (noise.shape not in ((T, n), (T + 1, n)) or not np.isfinite(noise).all()):
            raise ValueError(f"scenario.noise must be a finite (T + 1, n) or (T, n) array with T, n = {T}, {n}, "
                             f"got shape {noise.shape}")
        return Scenario(sp=sp, scan_s=float(self.scan_s), load=load, noise=noise)


@runtime_checkable
class LoopPlant(Protocol):
    """A plant the runner can drive besides :class:`~valve_gym.plant.Plant` (e.g. one coded apart)."""

    n: int
    scan_s: float

    def scan(self, u: np.ndarray, d: np.ndarray) -> tuple[Any, Any, Any]:
        """One scan with input ``u`` (n,) in 0..1 and inflow ``d`` (n,) held: ``(y, stem, level)`` (n,) after it."""
        ...


class PILaw:
    """The PI law of :mod:`valve_gym.control` (velocity form, :func:`~valve_gym.control.pi_step`) as a block.

    Parameters
    ----------
    pi : PIParams, the settings (gains scalars or ``(n,)``)
    """

    name = "pi"

    def __init__(self, pi: PIParams):
        self.pi = pi
        self.scan_s = pi.Ts
        self._state = pi_init(0.0, 0.0)

    def reset(self, sp, pv, op) -> None:
        """Bumpless start from the output ``op`` (n,) at error ``sp - pv``."""
        self._state = pi_init(op, np.asarray(sp, float) - pv)

    def step(self, sp, pv) -> np.ndarray:
        """One scan: the output (n,) for set point ``sp`` and measurement ``pv``."""
        self._state, u = pi_step(self._state, np.asarray(sp, float) - pv, self.pi)
        return u


class _Cols:
    """One column group: the plant, its columns and its one-scan input rows."""

    def __init__(self, cols, plant, n_all: int):
        self.cols = slice(None) if cols is None else np.asarray(cols)
        self.plant = plant
        self.native = isinstance(plant, Plant)
        m = n_all if cols is None else self.cols.size  # type: ignore[union-attr]
        self.U, self.D = np.empty((1, m)), np.zeros((1, m))

    def scan(self, u: np.ndarray, load_k) -> tuple:
        np.clip(u[self.cols], 0.0, 1.0, out=self.U[0])
        if load_k is not None:
            self.D[0] = load_k[self.cols]
        if self.native:
            Y, H, LV = self.plant.advance(self.U, self.D)
            return Y[0], H[0], LV[0]
        return self.plant.scan(self.U[0], self.D[0])


def _groups(plant, n: int) -> list[_Cols]:
    """The plant argument as column groups covering the ``n`` columns once (ValueError otherwise)."""
    if isinstance(plant, (Plant, LoopPlant)):
        if plant.n != n:
            raise ValueError(f"scenario.sp has {n} column(s) but the plant runs {plant.n} loop(s)")
        return [_Cols(None, plant, n)]
    if not isinstance(plant, Sequence) or not plant:
        raise ValueError("plant must be a Plant, a LoopPlant or a list of (columns, plant) pairs")
    seen = np.zeros(n, int)
    groups = []
    for cols, p in plant:
        cols = np.asarray(cols)
        if cols.ndim != 1 or cols.dtype.kind not in "iu" or cols.size != getattr(p, "n", -1) \
                or (cols.size and (cols.min() < 0 or cols.max() >= n)):
            raise ValueError(f"each (columns, plant) pair needs integer columns in 0..{n - 1}, as many as the "
                             f"plant's loops")
        seen[cols] += 1
        groups.append(_Cols(cols, p, n))
    if not (seen == 1).all():
        raise ValueError(f"the column groups must cover each of the {n} columns exactly once")
    return groups


def _start(groups: list[_Cols], sp0: np.ndarray) -> PlantOutput:
    """Reset every :class:`~valve_gym.plant.Plant` at rest at the first set point; the joint start state."""
    n = sp0.size
    out = PlantOutput(*(np.empty(n) for _ in range(4)))
    for g in groups:
        if not g.native:
            raise ValueError("a LoopPlant needs start=: the state it is in (pv, stem, op, y)")
        s = g.plant.reset(level=sp0[g.cols])
        for a, b in zip(out, s):
            a[g.cols] = b
    return out


def run_closed_loop(plant, block, scenario: Scenario, start: PlantOutput | None = None) -> LoopRun:
    """Run ``block`` in closed loop with ``plant`` over ``scenario``: the one closed-loop runner of valve_gym.

    Parameters
    ----------
    plant : Plant, LoopPlant, or list of (columns (m,) int array, Plant or LoopPlant)
        The loops' plant(s); a list gives one plant per column group (the groups partition ``0..n-1``).
    block : object with ``reset(sp, pv, op)`` and ``step(sp, pv) -> (n,)`` (see the module docstring)
    scenario : Scenario, set points (T, n), loads, noise and scan time
    start : PlantOutput, optional
        The state the plants are in (each ``(n,)``); default: every :class:`~valve_gym.plant.Plant`
        is reset at rest at ``scenario.sp[0]``. The block starts from ``start.op``.

    Returns
    -------
    LoopRun

    Raises
    ------
    ValueError
        For inconsistent shapes or scan times, non-finite inputs, or a block output that is not finite.
    """
    sc = scenario.checked()
    T, n = sc.sp.shape
    groups = _groups(plant, n)
    for g in groups:
        if abs(g.plant.scan_s - sc.scan_s) > 1e-9 * sc.scan_s:
            raise ValueError(f"the plant's scan_s = {g.plant.scan_s} s differs from scenario.scan_s = {sc.scan_s} s")
    if start is None:
        start = _start(groups, sc.sp[0])
    noise, load, sp = sc.noise, sc.load, sc.sp
    op = np.empty((T, n))
    pv, level, stem = (np.empty((T + 1, n)) for _ in range(3))
    level[0], stem[0] = start.pv, start.stem
    pv[0] = start.y if noise is None else start.y + noise[0]
    block.reset(sp[0], pv[0], np.asarray(start.op, float))
    for k in range(T):
        u = np.asarray(block.step(sp[k], pv[k]), float)
        if not np.isfinite(u).all():
            raise ValueError(f"the block {getattr(block, 'name', type(block).__name__)!r} returned a non-finite "
                             f"output at scan {k}")
        op[k] = u
        lk = None if load is None else load[k]
        for g in groups:
            y, h, lv = g.scan(op[k], lk)
            pv[k + 1, g.cols], stem[k + 1, g.cols], level[k + 1, g.cols] = y, h, lv
        if noise is not None and k + 1 < noise.shape[0]:
            pv[k + 1] += noise[k + 1]
    return LoopRun(op=op, pv=pv, level=level, stem=stem)


def run_pi_loop(plant: Plant, start: PlantOutput, sp, pi: PIParams, noise_std: float = 0.0,
                rng: np.random.Generator | None = None, d=None) -> LoopRun:
    """The PI law (:class:`PILaw`) on ``plant`` for ``T`` scans from the state ``start`` it is in.

    :func:`run_closed_loop` with white measurement noise drawn from ``rng`` and the PI starting
    bumplessly from the stem at rest.

    Parameters
    ----------
    plant : Plant, reset (and its ``scan_s`` equal to ``pi.Ts``)
    start : PlantOutput, what the plant shows now (e.g. the return of :meth:`Plant.reset`)
    sp : (T, n) array, set point of each scan [m]
    pi : PIParams, the controller (gains scalars or ``(n,)``)
    noise_std : float, std of the white measurement noise [m] (>= 0)
    rng : numpy Generator, the noise's (``standard_normal((T + 1, n))``, row 0 for the first
        measurement); needed when ``noise_std > 0``
    d : (T, n) or (T,) array, optional, extra inflow of each scan [m^3/s]

    Returns
    -------
    LoopRun
    """
    sp = np.asarray(sp, float)
    if sp.ndim != 2:
        raise ValueError(f"sp must be a (T, n) array of set points, got shape {sp.shape}")
    T, n = sp.shape
    if abs(pi.Ts - plant.scan_s) > 1e-9 * plant.scan_s:
        raise ValueError(f"the PI's Ts = {pi.Ts} s differs from the plant's scan_s = {plant.scan_s} s")
    if noise_std > 0 and rng is None:
        raise ValueError("noise_std > 0 needs a random generator rng (np.random.default_rng(seed))")
    dd = None if d is None else np.asarray(d, float)
    if dd is not None and dd.shape not in ((T,), (T, n)):
        raise ValueError(f"d must be a finite (T,) or (T, n) = ({T}, {n}) array of inflows, got shape {dd.shape}")
    load = None if dd is None else np.broadcast_to(dd if dd.ndim == 2 else dd[:, None], (T, n))
    noise = noise_std * rng.standard_normal((T + 1, n)) if noise_std > 0 else None  # type: ignore[union-attr]
    sc = Scenario(sp=sp, scan_s=plant.scan_s, load=load, noise=noise)
    return run_closed_loop(plant, PILaw(pi), sc, start=start._replace(op=start.stem))
