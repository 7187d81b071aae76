"""The benchmark run: scenarios -> runs -> scores, every controller on both parts.

:func:`run_benchmark` draws the scenarios once, runs each (controller, part)
as one task (in ``jobs`` worker processes), scores it at once and keeps only
the per-loop scores and the trend of one example loop, then summarises.
Progress goes to ``progress`` (one line per finished task).
"""
from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any

import numpy as np

from valve_gym.config import ConfigError

from .config import BenchConfig
from .runner import ControllerSpec, lineup, make_controller, run_loops, run_spec, valve_model
from .scenarios import PARTS, BenchScenarios, Scenarios, benchmark_scenarios
from .scores import Comparison, LoopScores, SummaryRow, compare_learned, score_runs, summarise

__all__ = ["Trend", "TaskResult", "BenchmarkResult", "run_benchmark", "example_loop", "jobs_used", "jobs_text"]


@dataclass(frozen=True, eq=False)
class Trend:
    """Trajectory of the example loop under one controller, each ``(T,)``.

    Attributes
    ----------
    label : str
    t : s; sp, pv : m (pv measured); op, stem : fraction of stroke
    """

    label: str
    t: np.ndarray
    sp: np.ndarray
    pv: np.ndarray
    op: np.ndarray
    stem: np.ndarray


@dataclass(frozen=True, eq=False)
class TaskResult:
    """One controller on one part: per-loop scores, the example trend (regulation), wall and CPU time [s]."""

    spec: ControllerSpec
    part: str
    scores: LoopScores
    trend: Trend | None
    seconds: float
    cpu_seconds: float


@dataclass(frozen=True, eq=False)
class BenchmarkResult:
    """Everything the report and the figures need.

    Attributes
    ----------
    config : BenchConfig
    scenarios : BenchScenarios
    specs : tuple of ControllerSpec
        The controllers that ran, in report order.
    scores : tuple of TaskResult
    summary : tuple of SummaryRow
        Both parts.
    comparison : Comparison or None
        Learned vs the best classical block within its travel budget (regulation).
    example : int
        Index of the example (sticky) loop of the regulation part.
    notes : tuple of str
        Controllers skipped and why.
    seconds : float
        Wall time of the run [s].
    jobs : int
        Worker processes used: the number asked, but at most one per task (:func:`jobs_used`).
    jobs_asked : int
        Worker processes asked for (``--jobs``); 0: not known (taken as ``jobs``).
    n_tasks : int
        Tasks run (controllers x parts).
    generalisation : GenResult or None
        The generalisation part (:mod:`~valve_gym.agents.bench.generalisation`), None when not run.
    """

    config: BenchConfig
    scenarios: BenchScenarios
    specs: tuple[ControllerSpec, ...]
    scores: tuple[TaskResult, ...]
    summary: tuple[SummaryRow, ...]
    comparison: Comparison | None
    example: int
    notes: tuple[str, ...]
    seconds: float
    jobs: int
    jobs_asked: int = 0
    n_tasks: int = 0
    generalisation: Any = None

    def jobs_text(self, unit: str = "job(s)") -> str:
        """The workers used, and the number asked when fewer were used (:func:`jobs_text`)."""
        return jobs_text(self.jobs, self.jobs_asked or self.jobs, self.n_tasks, unit)

    def part_scores(self, part: str) -> dict[str, LoopScores]:
        """``{label: LoopScores}`` of one part, in report order."""
        by = {(r.spec.label, r.part): r.scores for r in self.scores}
        return {s.label: by[(s.label, part)] for s in self.specs if (s.label, part) in by}

    def trends(self) -> tuple[Trend, ...]:
        """Example-loop trends in report order."""
        by = {r.spec.label: r.trend for r in self.scores if r.trend is not None}
        return tuple(by[s.label] for s in self.specs if s.label in by)


def example_loop(scen: Scenarios) -> int:
    """The sticky loop of the first friction model whose ``S`` is nearest the sticky loops' median."""
    m = (scen.band == "sticky") & (scen.model == scen.model[0])
    if not m.any():
        m = scen.band != "healthy" if (scen.band != "healthy").any() else np.ones(scen.n, bool)
    idx = np.flatnonzero(m)
    return int(idx[np.argmin(np.abs(scen.S[idx] - np.median(scen.S[idx])))])


# Set in the parent before the workers fork, so that they inherit the scenarios instead of receiving them.
_STATE: dict = {}


def _task(spec: ControllerSpec, part: str) -> TaskResult:
    t0, c0 = time.perf_counter(), time.process_time()
    cfg: BenchConfig = _STATE["config"]
    scen: Scenarios = _STATE["scenarios"].part(part)
    if spec.family == "policy":      # a user's policy (valve_gym.agents.bench.policies): the block itself
        runs = run_loops(_STATE["policies"][spec.label], scen, label=spec.label)
    else:
        runs = run_spec(spec, scen)
    trend = None
    if part == "regulation":
        i = _STATE["example"]
        trend = Trend(spec.label, np.arange(scen.n_steps) * scen.scan_s, runs.sp[:, i].copy(),
                      runs.pv[:, i].copy(), runs.op[:, i].copy(), runs.stem[:, i].copy())
    scores = score_runs(runs, cfg)
    return TaskResult(spec, part, scores, trend, time.perf_counter() - t0, time.process_time() - c0)


def _available(specs, scen: Scenarios) -> tuple[tuple[ControllerSpec, ...], tuple[str, ...]]:
    """The specs whose block can be made, and a note for each one that cannot."""
    ok, notes = [], []
    for s in specs:
        sub = scen.subset(np.arange(min(2, scen.n)))
        try:
            c = make_controller(s, sub)
            c.reset(sub.sp[0], sub.sp[0], np.full(sub.n, 0.5))
            c.step(sub.sp[1], sub.sp[1] - 0.01)
        except Exception as exc:  # noqa: BLE001 - any failure to load a block skips it with its reason
            notes.append(f"{s.label}: skipped ({type(exc).__name__}: {exc})")
            continue
        ok.append(s)
    return tuple(ok), tuple(notes)


def _check_models(config: BenchConfig) -> None:
    """A :class:`ConfigError` naming ``models`` when a friction model cannot be built."""
    for m in config.models:
        try:
            valve_model(m, np.array([0.02]), np.array([0.01]))
        except (ValueError, KeyError) as exc:
            raise ConfigError(f"models: friction model {m!r} cannot be built ({exc})") from None


def _progress_line(done: int, total: int, r: TaskResult, t0: float) -> str:
    el = time.perf_counter() - t0
    eta = el / done * (total - done)
    return (f"[{done:>3}/{total}] {r.part:<10} {r.spec.label:<32} {r.seconds:6.1f} s (cpu {r.cpu_seconds:5.1f} s)  "
            f"(elapsed {el:5.0f} s, left ~{eta:4.0f} s)")


def jobs_used(jobs: int, n_tasks: int) -> int:
    """Worker processes a run of ``n_tasks`` tasks uses when ``jobs`` are asked: at most one per task."""
    return max(1, min(int(jobs), int(n_tasks)))


def jobs_text(used: int, asked: int, n_tasks: int, unit: str = "job(s)") -> str:
    """``'8 job(s)'``, or ``'8 job(s) (1000 asked; only 8 tasks)'`` when fewer were used than asked.

    Examples
    --------
    >>> jobs_text(2, 2, 22)
    '2 job(s)'
    >>> jobs_text(8, 1000, 8, "worker process(es)")
    '8 worker process(es) (1000 asked; only 8 tasks)'
    """
    if used == asked:
        return f"{used} {unit}"
    return f"{used} {unit} ({asked} asked; only {n_tasks} tasks)"


def _execute(tasks, jobs: int, progress: Callable[[str], None] | None) -> list:
    t0 = time.perf_counter()
    out = []
    if jobs <= 1:
        for spec, part in tasks:
            out.append(_task(spec, part))
            if progress:
                progress(_progress_line(len(out), len(tasks), out[-1], t0))
        return out
    import multiprocessing as mp

    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as ex:
        futs = [ex.submit(_task, spec, part) for spec, part in tasks]
        for f in as_completed(futs):
            out.append(f.result())
            if progress:
                progress(_progress_line(len(out), len(tasks), out[-1], t0))
    return out


def _policy_specs(policies) -> tuple[list, dict, dict]:
    """Specs of the policy rows: one task per seed (``label [i]``), and ``{label: [seed labels]}``."""
    specs, blocks, groups = [], {}, {}
    for label, seeds in (policies or {}).items():
        names = [label] if len(seeds) == 1 else [f"{label} [seed {i}]" for i in range(len(seeds))]
        for nm, blk in zip(names, seeds):
            specs.append(ControllerSpec(nm, "policy", "policy"))
            blocks[nm] = blk
        groups[label] = names
    return specs, blocks, groups


def _median_over_seeds(label: str, part: str, runs: list[TaskResult]) -> TaskResult:
    """One row from the seeds of a policy: per-loop medians of each score (LC: present on most seeds)."""
    from dataclasses import fields

    arrays = {}
    for f in fields(LoopScores):
        if f.name in ("label", "part"):
            continue
        stack = np.stack([np.asarray(getattr(r.scores, f.name), float) for r in runs])
        arrays[f.name] = (stack.mean(axis=0) > 0.5) if f.name == "lc_present" else np.median(stack, axis=0)
    sc = LoopScores(label=label, part=part, **arrays)
    r0 = runs[0]
    trend = None if r0.trend is None else Trend(label, r0.trend.t, r0.trend.sp, r0.trend.pv, r0.trend.op,
                                                r0.trend.stem)
    return TaskResult(ControllerSpec(label, "policy", "policy"), part, sc, trend,
                      sum(r.seconds for r in runs), sum(r.cpu_seconds for r in runs))


def _seed_spread(label: str, names: list, results, scen: Scenarios, config: BenchConfig) -> str:
    """Note: each seed's median R on the sticky + severe regulation loops."""
    from .scores import REFERENCE_FRICTIONLESS, REFERENCE_PI, compensation_ratio

    by = {r.spec.label: r.scores for r in results if r.part == "regulation"}
    if REFERENCE_PI not in by or REFERENCE_FRICTIONLESS not in by:
        return f"{label}: median over {len(names)} seeds"
    m = scen.band != "healthy"
    rs = [float(np.median(compensation_ratio(by[REFERENCE_PI].iae_per_h[m], by[n].iae_per_h[m],
                                             by[REFERENCE_FRICTIONLESS].iae_per_h[m], config.scores.r_floor)))
          for n in names]
    tr = [float(np.median(by[n].travel_per_h[m] / np.maximum(by[REFERENCE_FRICTIONLESS].travel_per_h[m], 1e-12)))
          for n in names]
    return (f"{label}: per-loop medians over {len(names)} seeds; seed spread on the sticky + severe regulation loops: "
            f"median R {min(rs):.2f} .. {max(rs):.2f} ({', '.join(f'{x:.2f}' for x in rs)}), travel / frictionless "
            f"PI {min(tr):.2f} .. {max(tr):.2f}")


def run_benchmark(config: BenchConfig, jobs: int = 1, progress: Callable[[str], None] | None = None,
                  policies=None) -> BenchmarkResult:
    """Run every controller of ``config`` on both parts and score them.

    Parameters
    ----------
    config : BenchConfig
        Use :meth:`BenchConfig.quick_version` for ``--quick``.
    jobs : int, optional
        Worker processes (default 1: in this process); at most one per task is started
        (``BenchmarkResult.jobs``: the number used, ``jobs_asked``: this number).
    progress : callable, optional
        Called with one line of text per finished task.
    policies : mapping of str to list of blocks, optional
        Rows of one's own policies (:func:`valve_gym.agents.bench.policies.as_blocks`): each label runs
        on both parts beside the classical rows; a label with several blocks (seeds) becomes one row of
        per-loop medians over them, its seed spread in ``notes``.

    Returns
    -------
    BenchmarkResult
    """
    if int(jobs) < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs!r}")
    t0 = time.perf_counter()
    _check_models(config)
    scen = benchmark_scenarios(config)
    specs, notes = _available(lineup(config), scen.regulation)
    pspecs, pblocks, groups = _policy_specs(policies)
    _STATE.update(config=config, scenarios=scen, example=example_loop(scen.regulation), policies=pblocks)
    tasks = [(s, p) for p in PARTS for s in specs + tuple(pspecs)]
    # the slowest tasks (banks of compensators) first, so that the workers finish together
    tasks.sort(key=lambda sp: sp[0].estimate <= 0.0)
    used = jobs_used(jobs, len(tasks))
    results = list(_execute(tasks, used, progress))
    for label, names in groups.items():
        if names == [label]:
            specs = specs + (ControllerSpec(label, "policy", "policy"),)
            continue
        notes = notes + (_seed_spread(label, names, results, scen.regulation, config),)
        for p in PARTS:
            results.append(_median_over_seeds(label, p, [r for r in results if r.part == p and r.spec.label in names]))
        specs = specs + (ControllerSpec(label, "policy", "policy"),)
    results = tuple(results)
    res = BenchmarkResult(config, scen, specs, results, (), None, _STATE["example"], notes, 0.0, used,
                          int(jobs), len(tasks))
    summary = tuple(row for p in PARTS for row in summarise(res.part_scores(p), scen.part(p), config))
    classical = tuple(s.label for s in specs if s.family in ("pi", "detuned")
                      or (s.family == "compensator" and s.estimate == 1.0))
    comp = compare_learned(res.part_scores("regulation"), scen.regulation, config, classical)
    gen = _generalisation(config, used, progress, pblocks)
    return BenchmarkResult(config, scen, specs, results, summary, comp, res.example, notes,
                           time.perf_counter() - t0, used, int(jobs), len(tasks), gen)


def _generalisation(config: BenchConfig, jobs: int, progress: Callable[[str], None] | None, policies=None):
    """The generalisation part (its own fixed family, made smaller for a smaller run such as ``--quick``).

    ``policies`` (``{row label: block}``, one per seed) run there too, each with the loop's tuning and scan.
    """
    from .generalisation import GenFamily, run_generalisation

    return run_generalisation(config, GenFamily.for_config(config), jobs=jobs, progress=progress, policies=policies)


def default_jobs() -> int:
    """Worker processes by default: the cores this process may use (at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def print_progress(line: str) -> None:
    """Progress to stderr."""
    print(line, file=sys.stderr, flush=True)
