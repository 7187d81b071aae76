"""The benchmark's generalisation part: plants no compensator was trained or tuned on, default settings.

The loops run on :mod:`~valve_gym.agents.bench.unseen_plants` (coded apart from the physics core):
self-regulating tanks of other sizes and outlets, integrating (pumped-outlet) level loops and
first-order-plus-dead-time flow loops; scans of 0.5, 1 and 2 s; positioner lags of 0.2-2 s; the
two-parameter stick-slip band coded from its paper and a force-balance stem with Karnopp's stick
condition and a stroke-dependent band (no core friction model has either); small loads (the classic
case where a PI on a sticky valve cycles) and large ones; 1-3 mm of measurement noise; 40 minutes at a
constant set point from rest, with a constant load (0.5-2 % of full flow, either sign) on top of the varying
one, so that every valve has to move off the opening it rests at.

Every controller comes from :func:`valve_gym.agents.load_controller` with its **default settings and no
stiction estimate**; it gets only what belongs to the loop: the loop's PI tuning (``Kc``, ``Ti``, SIMC
from the loop's model, :func:`~valve_gym.agents.bench.unseen_plants.pi_tuning`) and its scan
``scan_s``. Beside them, the compensators with the loop's true ``S`` ("S known" rows). Scores are the
benchmark's own (:func:`~valve_gym.agents.bench.scores.score_runs`, :func:`~.scores.summarise`,
:func:`~.scores.compare_learned`), reported apart from the regulation and servo parts.

The family and its seeds were fixed before any compensator was trained for it; no training reads it.
"""
from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np

from valve_gym.loop import Scenario, run_closed_loop
from valve_gym.plant import PlantOutput
from valve_gym.signals import ou_sequence

from .config import BAND_NAMES, BenchConfig
from .runner import ESTIMATE_MIN, ControllerBank, Runs
from .scenarios import Scenarios
from .scores import (
    REFERENCE_FRICTIONLESS,
    REFERENCE_PI,
    Comparison,
    Estimate,
    LoopScores,
    SummaryRow,
    bootstrap_mean,
    compare_learned,
    score_runs,
    summarise,
)
from .unseen_plants import PROCESSES, VALVES, PlantSpec, UnseenPlants, pi_tuning

__all__ = ["GenFamily", "GenLoops", "GenSpec", "GenResult", "gen_loops", "gen_lineup", "run_generalisation",
           "generalisation_markdown", "PART", "LOAD_LEVELS"]

#: Part name in ``results.csv``.
PART = "generalisation"
#: Load levels: name -> stationary standard deviation of the load, as a fraction of full valve flow.
LOAD_LEVELS = {"small": 0.0015, "large": 0.012}
#: Range of the constant part of every load (random sign), fraction of full valve flow: the valve must move
#: off the opening it rests at, as after any change of the operating point.
OFFSET = (0.005, 0.02)


@dataclass(frozen=True)
class GenFamily:
    """The generalisation family (fixed; its seed is not the benchmark's).

    Attributes
    ----------
    seed : int
    n_healthy, n_sticky, n_severe : int, loops per band
    duration_s : float, s, record length
    scans : tuple of float, s, scan times drawn per loop
    noise : (2,) m, measurement noise standard deviation range
    """

    seed: int = 38_2026
    n_healthy: int = 8
    n_sticky: int = 20
    n_severe: int = 20
    duration_s: float = 2400.0
    scans: tuple[float, ...] = (0.5, 1.0, 2.0)
    noise: tuple[float, float] = (0.001, 0.003)

    @classmethod
    def for_config(cls, config: BenchConfig) -> GenFamily:
        """The family for a benchmark run of ``config``.

        The full family for the default size or larger; for a smaller run (``--quick``, a test's tiny
        configuration) as many times fewer loops and as much shorter records as that run has against the
        default (at least one loop per band; loop ``i`` is the same loop in every size).
        """
        full, ref = cls(), BenchConfig()
        count = sum(getattr(config.bands, b).n for b in BAND_NAMES)
        r_n = min(1.0, count / sum(getattr(ref.bands, b).n for b in BAND_NAMES))
        r_t = min(1.0, config.regulation.duration_s / ref.regulation.duration_s)
        if r_n >= 1.0 and r_t >= 1.0:
            return full
        return replace(full, n_healthy=max(1, round(full.n_healthy * r_n)),
                       n_sticky=max(1, round(full.n_sticky * r_n)), n_severe=max(1, round(full.n_severe * r_n)),
                       duration_s=full.duration_s * r_t)


@dataclass(frozen=True, eq=False)
class GenLoops:
    """The drawn loops: plant, band, load level, scan, tuning and signals of each.

    Attributes
    ----------
    part : str, ``"generalisation"``
    specs : tuple of PlantSpec
    band, load_level : (n,) str arrays
    scan_s, Kc, Ti, noise_std, S : (n,) float arrays
    load, noise : tuple of (T_i,) arrays (extra inflow [m^3/s or pv units], measurement noise [pv])
    duration_s : float, s
    """

    part: str
    specs: tuple[PlantSpec, ...]
    band: np.ndarray
    load_level: np.ndarray
    scan_s: np.ndarray
    Kc: np.ndarray
    Ti: np.ndarray
    noise_std: np.ndarray
    S: np.ndarray
    load: tuple
    noise: tuple
    duration_s: float

    @property
    def n(self) -> int:
        """Number of loops."""
        return len(self.specs)

    @property
    def model(self) -> np.ndarray:
        """Valve model of each loop."""
        return np.array([s.valve for s in self.specs])

    @property
    def process(self) -> np.ndarray:
        """Process kind of each loop."""
        return np.array([s.process for s in self.specs])


def _plant(rng: np.random.Generator, process: str, valve: str, S: float, J: float) -> PlantSpec:
    x0 = rng.uniform(0.3, 0.7)
    tau_p, tau_s = rng.uniform(0.2, 2.0), rng.uniform(0.3, 1.0)
    if process == "tank":
        area, q_max, level = rng.uniform(0.1, 0.8), rng.uniform(0.005, 0.03), rng.uniform(0.5, 1.5)
        return PlantSpec(process, valve, S, J, tau_p, tau_s, area, q_max, x0 * q_max / math.sqrt(level), 0.0,
                         level)
    if process == "integrating":
        return PlantSpec(process, valve, S, J, tau_p, tau_s, rng.uniform(0.3, 2.0), rng.uniform(0.005, 0.03), 0.0,
                         0.0, rng.uniform(0.5, 1.5))
    K, T, theta = rng.uniform(1.0, 3.0), rng.uniform(3.0, 30.0), rng.uniform(0.0, 5.0)
    return PlantSpec(process, valve, S, J, tau_p, tau_s, 1.0, K, T, theta, K * x0)


def _ou(rng: np.random.Generator, sigma: float, tau: float, n: int, dt: float) -> np.ndarray:
    """``n`` scans of an Ornstein-Uhlenbeck load (std ``sigma``, correlation time ``tau`` [s]), starting at 0."""
    w = rng.standard_normal(n)
    return ou_sequence(np.concatenate([[0.0], w[:-1]]), math.exp(-dt / tau), sigma)


def gen_loops(family: GenFamily = GenFamily()) -> GenLoops:
    """Draw the family's loops.

    Loop ``i`` draws from ``default_rng([seed, i])``; the combinations of process x valve x load level
    cycle within each band.

    Examples
    --------
    >>> g = gen_loops(GenFamily(n_healthy=2, n_sticky=2, n_severe=2, duration_s=600.0))
    >>> g.n, sorted(set(g.band.tolist()))
    (6, ['healthy', 'severe', 'sticky'])
    """
    bands = np.repeat(np.array(["healthy", "sticky", "severe"]),
                      [family.n_healthy, family.n_sticky, family.n_severe])
    combos = [(p, v, ld) for p in PROCESSES for v in VALVES for ld in LOAD_LEVELS]
    rows = []
    for i, band in enumerate(bands):
        rng = np.random.default_rng([family.seed, i])
        j = int(np.sum(bands[:i] == band))
        b = ("healthy", "sticky", "severe").index(str(band))
        process, valve, level = combos[(j + 5 * b) % len(combos)]
        u = rng.random(2)
        S = {"healthy": 0.005 * u[0], "sticky": 0.005 * 10.0 ** u[0], "severe": 0.05 + 0.05 * u[0]}[str(band)]
        spec = _plant(rng, process, valve, float(S), float(S * u[1]))
        scan = float(family.scans[int(rng.integers(len(family.scans)))])
        T = int(round(family.duration_s / scan))
        sigma = LOAD_LEVELS[level] * spec.q_max
        step = rng.choice([-1.0, 1.0]) * rng.uniform(*OFFSET) * spec.q_max
        d = step + _ou(rng, sigma, rng.uniform(60.0, 300.0), T, scan)
        nstd = rng.uniform(*family.noise)
        Kc, Ti = pi_tuning(spec, scan)
        rows.append((spec, level, scan, Kc, Ti, nstd, d, rng.standard_normal(T) * nstd))
    specs, lv, scans, Kc, Ti, nstd, d, v = zip(*rows)
    return GenLoops(PART, tuple(specs), bands, np.array(lv), np.array(scans), np.array(Kc), np.array(Ti),
                    np.array(nstd), np.array([s.S for s in specs]), tuple(d), tuple(v), family.duration_s)


@dataclass(frozen=True)
class GenSpec:
    """One row of the generalisation part.

    Attributes
    ----------
    label : str
    name : str, for ``load_controller``
    family : str, ``frictionless``, ``pi``, ``detuned``, ``default`` (compensator, default settings),
        ``known`` (compensator with the true ``S``), ``learned`` or ``policy`` (one's own block, ``--policy``)
    settings : tuple of (str, float)
    frictionless : bool
    """

    label: str
    name: str
    family: str
    settings: tuple[tuple[str, float], ...] = ()
    frictionless: bool = False


def gen_lineup(config: BenchConfig, learned: tuple[str, ...] = ("learned",)) -> tuple[GenSpec, ...]:
    """The rows of the part.

    Frictionless PI, PI, the detuned PIs of ``config.controllers.detune``, its compensators at default
    settings, the learned blocks, then the same compensators with the true ``S``.
    """
    rows = [GenSpec(REFERENCE_FRICTIONLESS, "pi", "frictionless", frictionless=True), GenSpec(REFERENCE_PI, "pi", "pi")]
    rows += [GenSpec(f"PI Kc x{k:g}", "pi", "detuned", (("detune", float(k)),)) for k in config.controllers.detune]
    comps = config.controllers.compensators
    rows += [GenSpec(c, c, "default") for c in comps]
    rows += [GenSpec(n, n, "learned") for n in learned]
    rows += [GenSpec(f"{c} (S known)", c, "known") for c in comps]
    return tuple(rows)


def _controller(spec: GenSpec, loops: GenLoops, idx: np.ndarray, scan_s: float):
    """The block of ``spec`` for loops ``idx`` (one scan time): per-loop tuning, else one block per loop."""
    from valve_gym.agents import load_controller

    if spec.family == "policy":
        return _policy_controller(_GEN["policies"][spec.label], loops, idx, scan_s)
    kw: dict[str, Any] = dict(spec.settings, scan_s=scan_s)
    if spec.family == "known":
        kw["S"] = np.maximum(loops.S[idx], ESTIMATE_MIN)
    try:
        return load_controller(spec.name, Kc=loops.Kc[idx], Ti=loops.Ti[idx], **kw)
    except (ValueError, TypeError):
        pass                                   # scalar settings only: one block per loop
    per = {k: v for k, v in kw.items() if k != "S"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)   # a learned block warns for a tuning it was not trained on
        blocks = [load_controller(spec.name, Kc=float(loops.Kc[i]), Ti=float(loops.Ti[i]), **per) for i in idx]
    return ControllerBank(blocks, [np.array([j]) for j in range(idx.size)], idx.size)


class _UnseenLoopPlant:
    """:class:`~.unseen_plants.UnseenPlants` as a :class:`valve_gym.loop.LoopPlant` (the sensor reads the level)."""

    def __init__(self, plants: UnseenPlants):
        self.plants, self.n, self.scan_s = plants, plants.n, plants.scan_s

    def rest(self) -> PlantOutput:
        """Reset at the operating point; the state the loops start in."""
        y, x, u0 = self.plants.reset()
        return PlantOutput(pv=y, stem=x, op=u0, y=y.copy())

    def scan(self, u: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One scan: ``(y, stem, level)`` after it."""
        y, x = self.plants.step(u, d)
        return y, x, y


def _policy_controller(block, loops: GenLoops, idx: np.ndarray, scan_s: float):
    """One's own block on loops ``idx``.

    An object with ``for_loops(loops, idx, scan_s)`` builds the block of those loops itself (it may read
    each loop's settings, e.g. a per-loop stiction estimate); a policy block runs one copy per loop with
    the loop's ``Kc``, ``Ti`` and scan (:meth:`~valve_gym.agents.bench.policies.PolicyBlock.for_loop`);
    any other block as it is.
    """
    if hasattr(block, "for_loops"):
        return block.for_loops(loops, idx, scan_s)
    if not hasattr(block, "for_loop"):
        return block
    blocks = [block.for_loop(float(loops.Kc[i]), float(loops.Ti[i]), scan_s) for i in idx]
    return ControllerBank(blocks, [np.array([j]) for j in range(idx.size)], idx.size)


def _run_group(spec: GenSpec, loops: GenLoops, idx: np.ndarray, scan_s: float) -> Runs:
    T = loops.load[idx[0]].size
    plant = _UnseenLoopPlant(UnseenPlants([loops.specs[i] for i in idx], scan_s, frictionless=spec.frictionless))
    start = plant.rest()
    spT = np.broadcast_to(start.pv.copy(), (T, idx.size))
    load = np.stack([loops.load[i] for i in idx], axis=1)
    noise = np.stack([loops.noise[i] for i in idx], axis=1)
    ctrl = _controller(spec, loops, idx, scan_s)
    run = run_closed_loop(plant, ctrl, Scenario(sp=spT, scan_s=scan_s, load=load, noise=noise), start=start)
    return Runs(spec.label, PART, scan_s, spT, run.pv[:T], run.level[:T], run.op, run.stem[:T])


def _concat(parts: list[tuple[np.ndarray, LoopScores]], n: int, label: str) -> LoopScores:
    fields = ("lc_present", "lc_amplitude", "lc_period", "iae_per_h", "offset", "travel_per_h", "reversals_per_h")
    out = {}
    for f in fields:
        a = np.empty(n, dtype=bool if f == "lc_present" else float)
        for idx, s in parts:
            a[idx] = getattr(s, f)
        out[f] = a
    return LoopScores(label=label, part=PART, **out)


def run_row(spec: GenSpec, loops: GenLoops, config: BenchConfig) -> LoopScores:
    """Every loop under one row's block, one batch per scan time; per-loop scores in loop order."""
    parts = []
    for scan in np.unique(loops.scan_s):
        idx = np.flatnonzero(loops.scan_s == scan)
        parts.append((idx, score_runs(_run_group(spec, loops, idx, float(scan)), config)))
    return _concat(parts, loops.n, spec.label)


@dataclass(frozen=True, eq=False)
class GenResult:
    """The generalisation part's result.

    Attributes
    ----------
    loops : GenLoops
    specs : tuple of GenSpec, the rows that ran
    scores : dict label -> LoopScores
    summary : tuple of SummaryRow (part ``"generalisation"``)
    comparisons : dict learned label -> Comparison (against the classical rows at default settings)
    notes : tuple of str
    seconds : float
    """

    loops: GenLoops
    specs: tuple[GenSpec, ...]
    scores: dict
    summary: tuple[SummaryRow, ...]
    comparisons: dict
    notes: tuple[str, ...]
    seconds: float


@dataclass(frozen=True, eq=False)
class _View:
    part: str
    band: np.ndarray


_GEN: dict = {}


def _row_task(i: int) -> tuple[int, LoopScores, float]:
    t0 = time.perf_counter()
    s = run_row(_GEN["specs"][i], _GEN["loops"], _GEN["config"])
    return i, s, time.perf_counter() - t0


def _available(specs, loops: GenLoops) -> tuple[list, list]:
    ok, notes = [], []
    idx = np.array([0])
    for s in specs:
        try:
            c = _controller(s, loops, idx, float(loops.scan_s[0]))
            c.reset(np.ones(1), np.ones(1), np.full(1, 0.5))
            c.step(np.ones(1), np.full(1, 0.99))
        except Exception as exc:  # noqa: BLE001 - a block that cannot be built is skipped with its reason
            notes.append(f"{s.label}: skipped ({type(exc).__name__}: {exc})")
            continue
        ok.append(s)
    return ok, notes


def _execute(n_rows: int, jobs: int, progress: Callable[[str], None] | None) -> list:
    t0, out = time.perf_counter(), []
    if jobs <= 1:
        it = (_row_task(i) for i in range(n_rows))
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
        ex = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx)
        it = (f.result() for f in as_completed([ex.submit(_row_task, i) for i in range(n_rows)]))
    for r in it:
        out.append(r)
        if progress:
            progress(f"[{len(out):>3}/{n_rows}] {PART:<14} {_GEN['specs'][r[0]].label:<32} {r[2]:6.1f} s "
                     f"(elapsed {time.perf_counter() - t0:5.0f} s)")
    return out


def learned_names() -> tuple[str, ...]:
    """The registered learned blocks (``learned`` and every ``learned_*`` name)."""
    from valve_gym.agents import available_controllers

    return tuple(n for n in available_controllers() if n == "learned" or n.startswith("learned_"))


def run_generalisation(config: BenchConfig, family: GenFamily = GenFamily(), jobs: int = 1,
                       progress: Callable[[str], None] | None = None,
                       learned: tuple[str, ...] | None = None, policies: dict | None = None) -> GenResult:
    """Run every row of :func:`gen_lineup` on the family's loops and score them with the benchmark's scores.

    Parameters
    ----------
    config : BenchConfig
        Detune factors, scoring rules and bootstrap (``scores``); its seed seeds the bootstrap only.
    family : GenFamily
    jobs : int
        Worker processes (one row per task).
    progress : callable, optional
    learned : tuple of str, optional
        Learned blocks to run (default: :func:`learned_names` when ``config.controllers.learned``, else none).
    policies : dict of str to block, optional
        One's own rows (``valve-gym benchmark --policy``; one block per row label, or an object with
        ``for_loops(loops, idx, scan_s)`` that builds the block of loops ``idx``), after the learned rows.

    Returns
    -------
    GenResult
    """
    t0 = time.perf_counter()
    loops = gen_loops(family)
    if learned is None:
        learned = learned_names() if config.controllers.learned else ()
    _GEN.update(loops=loops, config=config, policies=dict(policies or {}))
    specs, notes = _available(gen_lineup(config, learned) + tuple(GenSpec(str(k), str(k), "policy")
                                                                   for k in _GEN["policies"]), loops)
    _GEN.update(specs=specs)
    res = _execute(len(specs), max(1, min(int(jobs), len(specs))), progress)
    by = {i: s for i, s, _ in res}
    scores = {specs[i].label: by[i] for i in range(len(specs))}
    view = cast(Scenarios, _View(PART, loops.band))
    summary = summarise(scores, view, config)
    classical = tuple(s.label for s in specs if s.family in ("pi", "detuned", "default"))
    comps = {s.label: compare_learned(scores, view, config, classical, s.label) for s in specs
             if s.family in ("learned", "policy")}
    return GenResult(loops, tuple(specs), scores, summary, comps, tuple(notes), time.perf_counter() - t0)


# --------------------------------------------------------------------------- report
def _cell(e: Estimate | None, scale: float = 1.0, digits: int = 2) -> str:
    if e is None or e.n == 0 or not math.isfinite(e.value):
        return "n/a"
    return f"{e.value * scale:.{digits}f} [{e.lo * scale:.{digits}f}, {e.hi * scale:.{digits}f}]"


def mean_amplitude(res: GenResult, label: str, mask: np.ndarray, config: BenchConfig) -> Estimate:
    """Mean limit-cycle amplitude over the loops of ``mask`` (0 where none) [pv units], with a bootstrap CI."""
    return bootstrap_mean(res.scores[label].lc_amplitude[mask], config.scores.n_boot, config.scores.ci,
                          int(config.seed) + 38)


def _table(res: GenResult, config: BenchConfig) -> list[str]:
    ix = {(r.controller, r.band, r.metric): r.estimate for r in res.summary}
    ss = (res.loops.band == "sticky") | (res.loops.band == "severe")
    head = ("| controller | LC share | LC amp. cycling [mm] | mean LC amp. [mm] | LC period [s] | R | "
            "travel / frictionless PI | abs. offset [mm] | healthy IAE / PI |")
    out = [head, "|" + "---|" * 9]
    for s in res.specs:
        def g(metric, band="sticky+severe"):
            return ix.get((s.label, band, metric))
        out.append("| " + " | ".join([
            s.label, _cell(g("lc_share")), _cell(g("lc_amplitude_cycling"), 1000.0, 1),
            _cell(mean_amplitude(res, s.label, ss, config), 1000.0, 2), _cell(g("lc_period"), 1.0, 0),
            _cell(g("R")), _cell(g("travel_vs_frictionless")), _cell(g("abs_offset"), 1000.0, 2),
            _cell(g("iae_vs_pi", "healthy"))]) + " |")
    return out


def _comparison_lines(res: GenResult) -> list[str]:
    out = []
    for label, c in res.comparisons.items():
        c = cast("Comparison | None", c)
        if c is None:
            continue
        if not c.best_classical:
            out.append(f"- {label}: no classical block (default settings) within its median travel of "
                       f"{c.travel_budget:.2f} strokes/h.")
            continue
        d = c.difference
        out.append(f"- {label}: travel budget {c.travel_budget:.2f} strokes/h; best classical within it "
                   f"(default settings): **{c.best_classical}**; median R_learned - median R_best = {d.value:.3f}, "
                   f"paired bootstrap 95 % CI [{d.lo:.3f}, {d.hi:.3f}] over {d.n} loops.")
    return out


def breakdown(res: GenResult, labels: tuple[str, ...]) -> list[str]:
    """Sticky + severe loops by process, valve, load level and slip: LC share and median R of ``labels``.

    The slip groups split the loops by ``J / S``: a valve that jumps by ``J`` each time it breaks away cannot be
    placed closer than that, so a loop with integral action keeps a cycle of about the slip's size there.
    """
    lp = res.loops
    ss = (lp.band == "sticky") | (lp.band == "severe")
    pi, fr = res.scores[REFERENCE_PI], res.scores[REFERENCE_FRICTIONLESS]
    from .scores import compensation_ratio

    groups = [("process", v, lp.process == v) for v in PROCESSES] + [("valve", v, lp.model == v) for v in VALVES]
    groups += [("load", v, lp.load_level == v) for v in LOAD_LEVELS]
    slip = np.array([sp.J / sp.S if sp.S > 0 else 0.0 for sp in lp.specs])
    groups += [("slip J/S", "< 1/3", slip < 1 / 3), ("slip J/S", "1/3 to 2/3", (slip >= 1 / 3) & (slip < 2 / 3)),
               ("slip J/S", ">= 2/3", slip >= 2 / 3)]
    labels = tuple(x for x in labels if x in res.scores)
    out = ["| group | loops | " + " | ".join(f"{x}: LC share / median R" for x in (REFERENCE_PI,) + labels) + " |",
           "|" + "---|" * (3 + len(labels))]
    for kind, val, m in groups:
        m = m & ss
        cells = []
        for x in (REFERENCE_PI,) + labels:
            s = res.scores[x]
            r = compensation_ratio(pi.iae_per_h[m], s.iae_per_h[m], fr.iae_per_h[m])
            cells.append(f"{s.lc_present[m].mean():.2f} / {np.median(r):.2f}" if m.any() else "n/a")
        out.append(f"| {kind} {val} | {int(m.sum())} | " + " | ".join(cells) + " |")
    return out


def generalisation_markdown(res: GenResult, config: BenchConfig) -> str:
    """The ``results.md`` section of the generalisation part."""
    lp = res.loops
    out = ["## Generalisation (plants outside the training family, default settings, no stiction estimate)", "",
           f"{lp.n} loops ({', '.join(f'{b} {int((lp.band == b).sum())}' for b in ('healthy', 'sticky', 'severe'))})"
           f" of `valve_gym.agents.bench.unseen_plants` (processes {', '.join(PROCESSES)}; valves "
           f"{', '.join(VALVES)}; loads {', '.join(LOAD_LEVELS)}; scans {sorted(set(lp.scan_s.tolist()))} s), "
           f"{lp.duration_s:g} s each, run in {res.seconds:.0f} s. Every block through `load_controller(name)` "
           "with the loop's PI tuning and scan only; '(S known)' rows get the true S. Sticky + severe loops, "
           "medians [95 % CI] (LC share and mean amplitude: means); healthy IAE / PI on the healthy loops.", ""]
    if res.notes:
        out += [f"- {n}" for n in res.notes] + [""]
    out += _table(res, config) + [""] + _comparison_lines(res) + [""]
    out += ["Breakdown, sticky + severe loops:", ""] + breakdown(res, tuple(s.label for s in res.specs
                                                                            if s.family in ("learned", "policy")
                                                                            or s.label == "knocker")) + [""]
    return "\n".join(out)

