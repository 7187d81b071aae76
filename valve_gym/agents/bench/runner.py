"""Runs: every loop of a part under one controller, batched, one scan at a time.

A controller is a DCS block from :func:`valve_gym.agents.load_controller` driving all
``n`` loops of a :class:`~valve_gym.agents.bench.scenarios.Scenarios` at once (one
``step`` call per scan over ``(n,)`` arrays). Valves come from
:func:`valve_gym.friction.valve_model` and the plant from
:class:`valve_gym.plant.Plant`, one batched plant per friction model.

Per scan ``k`` (``t = k scan_s``), in :func:`valve_gym.loop.run_closed_loop`::

    pv_k  = level_k + noise_k                  (measured level)
    op_k  = ctrl.step(sp_k, pv_k)
    plant.advance(op_k, load_k)  ->  level_{k+1}, stem_{k+1}

The loop starts at steady state at ``sp_0`` (``plant.reset(level=sp_0)``)
and the controller bumplessly at the plant's steady input.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .config import BenchConfig
from .scenarios import Scenarios

__all__ = ["ControllerSpec", "Runs", "run_loops", "run_spec", "lineup", "make_controller", "ControllerBank",
           "valve_model", "make_plant", "controller_loader", "ESTIMATE_GRID", "ESTIMATE_MIN"]

#: Only for blocks that take scalar settings: relative spacing of the log grid the per-loop stiction estimates
#: are rounded to (one block per grid value, at most +-10 % off). And the smallest estimate handed to any
#: block (fraction of stroke).
ESTIMATE_GRID = 0.20
ESTIMATE_MIN = 0.001


@dataclass(frozen=True)
class ControllerSpec:
    """One row of the line-up: which block, with which settings, on which valves.

    Attributes
    ----------
    label : str
        Row name in the results (e.g. ``"knocker"``, ``"knocker S x0.5"``, ``"PI Kc x0.5"``).
    name : str
        Name for :func:`valve_gym.agents.load_controller`.
    family : str
        ``"frictionless"``, ``"pi"``, ``"detuned"``, ``"compensator"`` or ``"learned"``.
    settings : tuple of (str, float)
        Settings passed to ``load_controller`` as they are.
    estimate : float
        When > 0 the block gets ``S = estimate * S_true`` of each loop (the stiction estimate); 0: none.
    frictionless : bool
        Run on the loop's frictionless valve (``valve_model("none", ...)``) instead of its sticky one.
    """

    label: str
    name: str
    family: str
    settings: tuple[tuple[str, float], ...] = ()
    estimate: float = 0.0
    frictionless: bool = False


def lineup(config: BenchConfig) -> tuple[ControllerSpec, ...]:
    """The controllers of a run, in report order (the learned block last; it may be skipped later)."""
    cc = config.controllers
    specs = [ControllerSpec("PI frictionless", "pi", "frictionless", frictionless=True),
             ControllerSpec("PI (SIMC)", "pi", "pi")]
    specs += [ControllerSpec(f"PI Kc x{k:g}", "pi", "detuned", (("detune", float(k)),)) for k in cc.detune]
    for comp in cc.compensators:
        for f in cc.estimate_factors:
            label = comp if f == 1.0 else f"{comp} S x{f:g}"
            specs.append(ControllerSpec(label, comp, "compensator", estimate=float(f)))
    if cc.learned:
        from valve_gym.agents import available_controllers

        specs += [ControllerSpec(n, n, "learned") for n in available_controllers()
                  if n == "learned" or n.startswith("learned_")]
    return tuple(specs)


@dataclass(frozen=True, eq=False)
class Runs:
    """Trajectories of ``n`` loops over ``T`` scans under one controller.

    Attributes
    ----------
    label : str
        The controller's row name.
    part : str
        ``"regulation"`` or ``"servo"``.
    scan_s : float, s
    sp : (T, n) ndarray, m
        Set point.
    pv : (T, n) ndarray, m
        Measured level (with noise), what the controller saw.
    level : (T, n) ndarray, m
        True level.
    op : (T, n) ndarray, fraction of stroke
        Controller output.
    stem : (T, n) ndarray, fraction of stroke
        Valve stem position at the start of each scan.
    settings : str
        The block's resolved settings (as text, for the report).
    """

    label: str
    part: str
    scan_s: float
    sp: np.ndarray
    pv: np.ndarray
    level: np.ndarray
    op: np.ndarray
    stem: np.ndarray
    settings: str = ""


# --------------------------------------------------------------------------- contracts 1-3
def valve_model(model: str, S, J):
    """Default tank with a ``model`` valve of stick band ``S`` and slip jump ``J`` (fractions of stroke, (n,))."""
    from valve_gym.friction import valve_model as vm

    return vm(model, S, J)


def make_plant(params, n: int, scan_s: float):
    """The batched plant stepper of ``n`` loops (:class:`valve_gym.plant.Plant`)."""
    from valve_gym.plant import Plant

    return Plant(params, n, scan_s=scan_s)


def controller_loader() -> Callable:
    """:func:`valve_gym.agents.load_controller`."""
    from valve_gym.agents import load_controller

    return load_controller


# --------------------------------------------------------------------------- controllers
class ControllerBank:
    """Several blocks of one kind, each driving its own subset of the loops, behind one block interface.

    Used when a setting differs per loop (the stiction estimate) and the block takes scalar settings.

    Parameters
    ----------
    blocks : list of blocks
    groups : list of (m_i,) int arrays
        Loops driven by each block (a partition of ``0..n-1``).
    n : int
    """

    def __init__(self, blocks: list, groups: list, n: int):
        self.blocks, self.groups, self.n = blocks, groups, n
        self.name = blocks[0].name
        self.scan_s = blocks[0].scan_s
        self.settings = blocks[0].settings

    def reset(self, sp, pv, op) -> None:
        """Reset each block on its loops."""
        for b, g in zip(self.blocks, self.groups):
            b.reset(sp[g], pv[g], op[g])

    def step(self, sp, pv) -> np.ndarray:
        """One scan of every block; ``(n,)`` outputs."""
        out = np.empty(self.n)
        for b, g in zip(self.blocks, self.groups):
            out[g] = b.step(sp[g], pv[g])
        return out


def _grid(x: np.ndarray) -> np.ndarray:
    """``x`` (> 0) rounded to the log grid of spacing :data:`ESTIMATE_GRID`."""
    step = math.log1p(ESTIMATE_GRID)
    return np.exp(np.round(np.log(x) / step) * step)


def make_controller(spec: ControllerSpec, scenarios: Scenarios, load: Callable | None = None):
    """The block of ``spec`` for the loops of ``scenarios``.

    A compensator gets the per-loop estimate ``S = max(estimate * S_true, ESTIMATE_MIN)`` as an ``(n,)``
    setting; a block that only takes scalar settings is served by a :class:`ControllerBank` instead, one
    block per value of the estimate rounded to the :data:`ESTIMATE_GRID` log grid.

    Raises
    ------
    ValueError
        When ``load_controller`` rejects the name or a setting.
    """
    load = controller_loader() if load is None else load
    kw = dict(spec.settings)
    kw["scan_s"] = scenarios.scan_s
    if spec.estimate <= 0.0:
        return load(spec.name, **kw)
    est = np.maximum(spec.estimate * scenarios.S, ESTIMATE_MIN)
    try:
        return load(spec.name, S=est, **kw)
    except (ValueError, TypeError):
        pass  # scalar settings only: one block per distinct (gridded) estimate
    g = _grid(est)
    values, inv = np.unique(g, return_inverse=True)
    blocks = [load(spec.name, S=float(v), **kw) for v in values]
    return ControllerBank(blocks, [np.flatnonzero(inv == i) for i in range(values.size)], scenarios.n)


# --------------------------------------------------------------------------- running
def _plants(scenarios: Scenarios, frictionless: bool) -> list:
    """``[(idx, plant)]``, one batched plant per friction model."""
    out = []
    for model in dict.fromkeys(scenarios.model.tolist()):
        idx = np.flatnonzero(scenarios.model == model)
        params = valve_model("none" if frictionless else model, scenarios.S[idx], scenarios.J[idx])
        out.append((idx, make_plant(params, idx.size, scenarios.scan_s)))
    return out


def run_loops(ctrl, scenarios: Scenarios, *, frictionless: bool = False, label: str = "") -> Runs:
    """Run every loop of ``scenarios`` under the block ``ctrl`` (one ``step`` per scan over all loops).

    The loop is :func:`valve_gym.loop.run_closed_loop` (the one closed-loop runner), with one batched
    plant per friction model over its columns, started at rest at ``sp_0``.

    Parameters
    ----------
    ctrl : block
        A controller from :func:`valve_gym.agents.load_controller` (``reset(sp, pv, op)``, ``step(sp, pv)``).
    scenarios : Scenarios
    frictionless : bool, optional
        Use each loop's frictionless valve instead of its sticky one.
    label : str, optional
        Row name (default ``ctrl.name``).

    Returns
    -------
    Runs
    """
    from valve_gym.loop import Scenario, run_closed_loop

    T = scenarios.n_steps
    sc = Scenario(sp=scenarios.sp, scan_s=scenarios.scan_s, load=scenarios.load, noise=scenarios.noise)
    run = run_closed_loop(_plants(scenarios, frictionless), ctrl, sc)
    return Runs(label or str(ctrl.name), scenarios.part, scenarios.scan_s, scenarios.sp, run.pv[:T], run.level[:T],
                run.op, run.stem[:T], _settings_text(ctrl))


def _settings_text(ctrl) -> str:
    s = getattr(ctrl, "settings", {}) or {}
    return ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in s.items())


def run_spec(spec: ControllerSpec, scenarios: Scenarios, load: Callable | None = None) -> Runs:
    """Build the block of ``spec`` and run it on ``scenarios`` (see :func:`run_loops`)."""
    ctrl = make_controller(spec, scenarios, load)
    return run_loops(ctrl, scenarios, frictionless=spec.frictionless, label=spec.label)
