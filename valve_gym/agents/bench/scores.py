"""Scores: per-loop metrics of each run, the compensation ratio, medians with bootstrap CIs.

Per loop and controller (:class:`LoopScores`): limit cycle present /
amplitude / period (:func:`valve_gym.oscillation.detect_oscillation`, benchmark rule, on the measured
error), IAE per hour, mean offset, stem travel and reversals per hour. Against
the same loop under the SIMC PI and under the SIMC PI on a frictionless valve
(same noise and load): the compensation ratio :func:`compensation_ratio`.
Per part, band and controller (:class:`SummaryRow`): medians (LC share: the
mean) with seeded percentile-bootstrap confidence intervals.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from valve_gym.metrics import reversal_counts
from valve_gym.oscillation import detect_oscillation

from .config import BAND_NAMES, BenchConfig
from .runner import Runs
from .scenarios import Scenarios

__all__ = ["LoopScores", "score_runs", "compensation_ratio", "Estimate", "bootstrap_median", "bootstrap_mean",
           "SummaryRow", "summarise", "Comparison", "compare_learned", "BAND_GROUPS", "METRICS",
           "REFERENCE_PI", "REFERENCE_FRICTIONLESS", "loop_table", "loop_iae", "valve_motion", "limit_cycles"]

#: Band groups of the summary: each band, and the sticky and severe valves together.
BAND_GROUPS = (*BAND_NAMES, "sticky+severe")

#: Row labels of the two references of the compensation ratio.
REFERENCE_PI = "PI (SIMC)"
REFERENCE_FRICTIONLESS = "PI frictionless"

#: Summary metrics: name -> (statistic, unit, description).
METRICS = {
    "lc_share": ("mean", "-", "share of loops with a limit cycle"),
    "lc_amplitude": ("median", "m", "limit-cycle amplitude of the error (0 where none)"),
    "lc_amplitude_cycling": ("median", "m", "limit-cycle amplitude of the loops that cycle"),
    "lc_period": ("median", "s", "limit-cycle period of the loops that cycle"),
    "iae_per_h": ("median", "m s/h", "IAE per hour of record"),
    "iae_vs_pi": ("median", "-", "IAE / IAE of the SIMC PI on the same loop"),
    "R": ("median", "-", "compensation ratio (see compensation_ratio)"),
    "travel_per_h": ("median", "stroke/h", "stem travel per hour, full strokes"),
    "travel_vs_frictionless": ("median", "-", "stem travel / the frictionless PI's on the same loop"),
    "reversals_per_h": ("median", "1/h", "stem reversals per hour"),
    "abs_offset": ("median", "m", "|mean error| over the record"),
}


@dataclass(frozen=True, eq=False)
class LoopScores:
    """Per-loop scores of one controller on one part, each an ``(n,)`` array.

    Attributes
    ----------
    label, part : str
    lc_present : (n,) bool
    lc_amplitude : (n,) m (0 where no limit cycle)
    lc_period : (n,) s (inf where no limit cycle)
    iae_per_h : (n,) m s per hour of record
    offset : (n,) m, mean of ``sp - pv``
    travel_per_h : (n,) full strokes per hour (stem)
    reversals_per_h : (n,) 1/h (stem, with the configured dead band)
    """

    label: str
    part: str
    lc_present: np.ndarray
    lc_amplitude: np.ndarray
    lc_period: np.ndarray
    iae_per_h: np.ndarray
    offset: np.ndarray
    travel_per_h: np.ndarray
    reversals_per_h: np.ndarray


def loop_iae(e, scan_s: float) -> np.ndarray:
    """IAE of each loop: ``sum_k |e_k| scan_s`` over the time axis [m s], ``e = sp - pv`` measured, (T, n) -> (n,).

    The one loop score of IAE: the benchmark (:func:`score_runs`) and the learned compensator's trainer
    (:func:`valve_gym.agents.es.rollout_scores`) both score the measured error with it.

    Examples
    --------
    >>> loop_iae(np.array([[0.1, -0.2], [0.3, 0.0]]), 2.0).round(6).tolist()
    [0.8, 0.4]
    """
    return np.abs(np.asarray(e, float)).sum(axis=0) * scan_s


def valve_motion(stem, deadband: float) -> tuple[np.ndarray, np.ndarray]:
    """Stem travel [full strokes] and stem reversals (moves under ``deadband`` not counted) of each loop.

    The one valve-wear score: the benchmark (:func:`score_runs`) and the learned compensator's trainer
    (:func:`valve_gym.agents.es.rollout_scores`) both use it. ``stem`` (T, n), fraction of stroke ->
    ``(travel (n,), reversals (n,))``.

    Examples
    --------
    >>> x = np.array([[0.0, 0.5, 0.4, 0.6]]).T
    >>> travel, rev = valve_motion(x, 0.05)
    >>> round(float(travel[0]), 6), int(rev[0])
    (0.8, 2)
    """
    stem = np.asarray(stem, float)
    return np.abs(np.diff(stem, axis=0)).sum(axis=0), reversal_counts(stem, deadband)


def limit_cycles(e, scan_s: float) -> list:
    """The benchmark's limit-cycle reading of each loop's measured error ``e`` (T, n).

    One :class:`~valve_gym.oscillation.Oscillation` per loop (benchmark rule); the benchmark and the learned
    compensator's trainer both read limit cycles with it.
    """
    e = np.asarray(e, float)
    return [detect_oscillation(e[:, i], scan_s, "benchmark") for i in range(e.shape[1])]


def score_runs(runs: Runs, config: BenchConfig) -> LoopScores:
    """Score every loop of ``runs`` (metrics on the measured error ``sp - pv``, the stem as the valve)."""
    e = runs.sp - runs.pv
    hours = e.shape[0] * runs.scan_s / 3600.0
    lc = limit_cycles(e, runs.scan_s)
    travel, rev = valve_motion(runs.stem, config.scores.reversal_deadband)
    return LoopScores(
        label=runs.label, part=runs.part,
        lc_present=np.array([x.present for x in lc]),
        lc_amplitude=np.array([x.amplitude for x in lc]),
        lc_period=np.array([x.period_s if x.present else np.inf for x in lc]),
        iae_per_h=loop_iae(e, runs.scan_s) / hours,
        offset=e.mean(axis=0),
        travel_per_h=travel / hours,
        reversals_per_h=rev / hours)


def compensation_ratio(iae_pi, iae_c, iae_0, floor: float = 0.1) -> np.ndarray:
    r"""Share of stiction's IAE cost that a compensator removes, per loop.

    Parameters
    ----------
    iae_pi : (n,) array_like
        IAE of the SIMC PI on the sticky valve.
    iae_c : (n,) array_like
        IAE of the compensator on the same loop (same noise and load).
    iae_0 : (n,) array_like
        IAE of the SIMC PI on the loop's frictionless valve.
    floor : float, optional
        Floor of the denominator as a fraction of ``iae_0`` (> 0, default 0.1).

    Returns
    -------
    (n,) ndarray
        ``R``: 1 = all of stiction's cost removed, 0 = no better than the PI, < 0 worse.

    Notes
    -----
    .. math:: R = \frac{IAE_{PI} - IAE_c}{\max(IAE_{PI} - IAE_0,\; f\,IAE_0)}

    Where stiction costs the PI less than ``f`` (10 %) of the frictionless
    IAE (healthy valves, or a load that keeps the valve moving), the ratio is
    taken against ``f IAE_0`` instead of a near-zero difference: it stays
    bounded and near zero for any controller that is about as good as the PI.

    Examples
    --------
    >>> compensation_ratio([2.0, 2.0, 1.01], [1.5, 1.0, 1.0], [1.0, 1.0, 1.0]).round(3).tolist()
    [0.5, 1.0, 0.1]
    """
    pi, c, z = (np.asarray(a, float) for a in (iae_pi, iae_c, iae_0))
    if floor <= 0.0:
        raise ValueError(f"floor must be > 0, got {floor!r}")
    return (pi - c) / np.maximum(pi - z, floor * z)


@dataclass(frozen=True)
class Estimate:
    """A statistic with its bootstrap confidence interval.

    Attributes
    ----------
    value : float
        The statistic on the sample (NaN-free sample; ``nan`` when empty).
    lo, hi : float
        Percentile-bootstrap interval at the configured level.
    n : int
        Sample size.
    """

    value: float
    lo: float
    hi: float
    n: int


def _bootstrap(x: np.ndarray, stat, n_boot: int, ci: float, rng: np.random.Generator) -> Estimate:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return Estimate(float("nan"), float("nan"), float("nan"), 0)
    idx = rng.integers(0, x.size, size=(n_boot, x.size))
    boots = stat(x[idx], axis=1)
    a = 100.0 * (1.0 - ci) / 2.0
    lo, hi = np.percentile(boots, [a, 100.0 - a])
    return Estimate(float(stat(x)), float(lo), float(hi), int(x.size))


def bootstrap_median(x, n_boot: int = 2000, ci: float = 0.95, seed: int = 0) -> Estimate:
    """Median of ``x`` with a percentile-bootstrap CI (``n_boot`` resamples, ``numpy`` generator ``seed``).

    Non-finite values are left out (``n`` counts the rest).

    Examples
    --------
    >>> e = bootstrap_median(np.arange(101.0), seed=1)
    >>> e.value, e.lo < 50.0 < e.hi, e.n
    (50.0, True, 101)
    """
    return _bootstrap(np.asarray(x, float), np.median, n_boot, ci, np.random.default_rng(seed))


def bootstrap_mean(x, n_boot: int = 2000, ci: float = 0.95, seed: int = 0) -> Estimate:
    """Mean of ``x`` with a percentile-bootstrap CI (see :func:`bootstrap_median`)."""
    return _bootstrap(np.asarray(x, float), np.mean, n_boot, ci, np.random.default_rng(seed))


@dataclass(frozen=True)
class SummaryRow:
    """One row of ``results.csv``: a statistic of one metric, controller, part and band group.

    Attributes
    ----------
    part, controller, band, metric : str
    stat : str
        ``median`` or ``mean``.
    estimate : Estimate
    unit : str
    """

    part: str
    controller: str
    band: str
    metric: str
    stat: str
    estimate: Estimate
    unit: str


def _band_mask(scen: Scenarios, group: str) -> np.ndarray:
    if group == "sticky+severe":
        return (scen.band == "sticky") | (scen.band == "severe")
    return scen.band == group


def _derived(scores: dict[str, LoopScores], label: str, floor: float) -> dict[str, np.ndarray]:
    """Per-loop metric arrays of ``label`` by :data:`METRICS` name (relative ones against the references)."""
    s = scores[label]
    out = {"lc_share": s.lc_present.astype(float), "lc_amplitude": s.lc_amplitude,
           "lc_amplitude_cycling": np.where(s.lc_present, s.lc_amplitude, np.nan),
           "lc_period": np.where(s.lc_present, s.lc_period, np.nan), "iae_per_h": s.iae_per_h,
           "travel_per_h": s.travel_per_h, "reversals_per_h": s.reversals_per_h,
           "abs_offset": np.abs(s.offset)}
    pi, fr = scores.get(REFERENCE_PI), scores.get(REFERENCE_FRICTIONLESS)
    if pi is not None:
        out["iae_vs_pi"] = s.iae_per_h / np.maximum(pi.iae_per_h, 1e-12)
    if pi is not None and fr is not None:
        out["R"] = compensation_ratio(pi.iae_per_h, s.iae_per_h, fr.iae_per_h, floor)
        out["travel_vs_frictionless"] = s.travel_per_h / np.maximum(fr.travel_per_h, 1e-12)
    return out


def summarise(scores: dict[str, LoopScores], scen: Scenarios, config: BenchConfig) -> tuple[SummaryRow, ...]:
    """Every metric of every controller of one part, per band group, with bootstrap CIs.

    The bootstrap generator is seeded from ``config.seed`` and the row's position, so a rerun gives the same
    intervals.
    """
    sc = config.scores
    rows = []
    for ci_, label in enumerate(scores):
        per_loop = _derived(scores, label, sc.r_floor)
        for gi, group in enumerate(BAND_GROUPS):
            m = _band_mask(scen, group)
            for mi, (metric, (stat, unit, _)) in enumerate(METRICS.items()):
                if metric not in per_loop:
                    continue
                seed = int(config.seed) * 7919 + ci_ * 1000 + gi * 100 + mi
                fn = bootstrap_mean if stat == "mean" else bootstrap_median
                est = fn(per_loop[metric][m], sc.n_boot, sc.ci, seed)
                rows.append(SummaryRow(scen.part, label, group, metric, stat, est, unit))
    return tuple(rows)


@dataclass(frozen=True)
class Comparison:
    """The learned block against the best classical one within its valve-travel budget.

    Attributes
    ----------
    learned : str
        Row label of the learned block.
    best_classical : str
        The classical row (PI, detuned PI or a compensator at the true estimate) with the highest median
        ``R`` among those whose median travel is at most the learned block's (``""`` when none).
    travel_budget : float, stroke/h
        The learned block's median stem travel (sticky + severe regulation loops).
    within_budget : tuple of str
        The classical rows that were eligible.
    difference : Estimate
        ``median(R_learned) - median(R_best)`` with a paired bootstrap CI (the same loops resampled).
    """

    learned: str
    best_classical: str
    travel_budget: float
    within_budget: tuple[str, ...]
    difference: Estimate


def compare_learned(scores: dict[str, LoopScores], scen: Scenarios, config: BenchConfig,
                    classical: Sequence[str], learned: str = "learned") -> Comparison | None:
    """:class:`Comparison` on the sticky + severe loops of ``scen`` (None when ``learned`` did not run)."""
    if learned not in scores or REFERENCE_PI not in scores or REFERENCE_FRICTIONLESS not in scores:
        return None
    m = _band_mask(scen, "sticky+severe")
    if not m.any():
        return None
    floor = config.scores.r_floor
    r_l = _derived(scores, learned, floor)["R"][m]
    budget = float(np.median(scores[learned].travel_per_h[m]))
    ok = [c for c in classical if c in scores and float(np.median(scores[c].travel_per_h[m])) <= budget]
    if not ok:
        return Comparison(learned, "", budget, (), Estimate(float("nan"), float("nan"), float("nan"), 0))
    r = {c: _derived(scores, c, floor)["R"][m] for c in ok}
    best = max(ok, key=lambda c: float(np.median(r[c])))
    rng = np.random.default_rng([int(config.seed), 99])
    idx = rng.integers(0, r_l.size, size=(config.scores.n_boot, r_l.size))
    boots = np.median(r_l[idx], axis=1) - np.median(r[best][idx], axis=1)
    a = 100.0 * (1.0 - config.scores.ci) / 2.0
    lo, hi = np.percentile(boots, [a, 100.0 - a])
    diff = Estimate(float(np.median(r_l) - np.median(r[best])), float(lo), float(hi), int(r_l.size))
    return Comparison(learned, best, budget, tuple(ok), diff)


def loop_table(scores: dict[str, LoopScores], scen: Scenarios, config: BenchConfig):
    """Per-loop scores of every controller of one part as a long :class:`pandas.DataFrame`.

    Columns: ``part, loop, band, model, S, J, sp0, controller``, then the raw scores (``lc_present,
    lc_amplitude_m, lc_period_s, iae_per_h, offset_m, travel_per_h, reversals_per_h``) and the relative
    ones (``iae_vs_pi, R, travel_vs_frictionless``); periods without a limit cycle are left empty.
    """
    import pandas as pd

    frames = []
    for label, s in scores.items():
        d = _derived(scores, label, config.scores.r_floor)
        frames.append(pd.DataFrame({
            "part": scen.part, "loop": np.arange(scen.n), "band": scen.band, "model": scen.model,
            "S": scen.S, "J": scen.J, "sp0": scen.sp[0], "controller": label,
            "lc_present": s.lc_present.astype(int), "lc_amplitude_m": s.lc_amplitude,
            "lc_period_s": np.where(np.isfinite(s.lc_period), s.lc_period, np.nan),
            "iae_per_h": s.iae_per_h, "offset_m": s.offset, "travel_per_h": s.travel_per_h,
            "reversals_per_h": s.reversals_per_h,
            "iae_vs_pi": d.get("iae_vs_pi", np.full(scen.n, np.nan)),
            "R": d.get("R", np.full(scen.n, np.nan)),
            "travel_vs_frictionless": d.get("travel_vs_frictionless", np.full(scen.n, np.nan))}))
    return pd.concat(frames, ignore_index=True)
