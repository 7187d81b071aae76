"""Report: ``results.md``, ``results.csv`` (long), ``loops.csv`` (per loop), ``config.yaml``; atomic writes."""
from __future__ import annotations

import math
from pathlib import Path

from valve_gym._io import write_atomic

from .config import bench_config_to_dict
from .pipeline import BenchmarkResult
from .scenarios import PARTS
from .scores import BAND_GROUPS, REFERENCE_FRICTIONLESS, REFERENCE_PI, Estimate, loop_table

__all__ = ["write_report", "results_markdown", "headline_table", "summary_frame"]


def _write_text(path: Path, text: str) -> Path:
    data = text.encode("utf-8")
    write_atomic(path, lambda f: f.write(data))
    return path


def summary_frame(res: BenchmarkResult):
    """``results.csv`` as a DataFrame: ``part, controller, band, metric, stat, value, ci_lo, ci_hi, n, unit``."""
    import pandas as pd

    gen = res.generalisation.summary if res.generalisation is not None else ()
    return pd.DataFrame([{"part": r.part, "controller": r.controller, "band": r.band, "metric": r.metric,
                          "stat": r.stat, "value": r.estimate.value, "ci_lo": r.estimate.lo,
                          "ci_hi": r.estimate.hi, "n": r.estimate.n, "unit": r.unit} for r in (*res.summary, *gen)])


def _index(res: BenchmarkResult) -> dict[tuple[str, str, str, str], Estimate]:
    return {(r.part, r.controller, r.band, r.metric): r.estimate for r in res.summary}


def _fmt(e: Estimate, scale: float = 1.0, digits: int = 2, ci: bool = True) -> str:
    if e.n == 0 or not math.isfinite(e.value):
        return "n/a"
    v = f"{e.value * scale:.{digits}f}"
    return f"{v} [{e.lo * scale:.{digits}f}, {e.hi * scale:.{digits}f}]" if ci else v


def headline_table(res: BenchmarkResult) -> str:
    """The README table: regulation sticky + severe, healthy IAE vs PI, servo; medians [95 % CI]."""
    ix = _index(res)
    head = ("| controller | LC share | LC amplitude of cycling loops [mm] | R | travel / frictionless PI "
            "| abs. offset [mm] | healthy IAE / PI | servo IAE / PI | servo travel / frictionless PI |")
    lines = [head, "|" + "---|" * 9]
    for s in res.specs:
        def g(part, band, metric):
            return ix.get((part, s.label, band, metric), Estimate(math.nan, math.nan, math.nan, 0))
        lines.append("| " + " | ".join([
            s.label,
            _fmt(g("regulation", "sticky+severe", "lc_share")),
            _fmt(g("regulation", "sticky+severe", "lc_amplitude_cycling"), 1000.0, 1),
            _fmt(g("regulation", "sticky+severe", "R")),
            _fmt(g("regulation", "sticky+severe", "travel_vs_frictionless")),
            _fmt(g("regulation", "sticky+severe", "abs_offset"), 1000.0, 2),
            _fmt(g("regulation", "healthy", "iae_vs_pi")),
            _fmt(g("servo", "sticky+severe", "iae_vs_pi")),
            _fmt(g("servo", "sticky+severe", "travel_vs_frictionless")),
        ]) + " |")
    return "\n".join(lines)


def _part_table(res: BenchmarkResult, part: str, band: str) -> str:
    ix = _index(res)
    cols = [("lc_share", 1.0, 2, "LC share"), ("lc_amplitude_cycling", 1000.0, 1, "LC amp., cycling [mm]"),
            ("lc_period", 1.0, 0, "LC period [s]"),
            ("iae_per_h", 1.0, 2, "IAE [m s/h]"), ("R", 1.0, 2, "R"), ("travel_per_h", 1.0, 1, "travel [strokes/h]"),
            ("reversals_per_h", 1.0, 0, "reversals [1/h]"), ("abs_offset", 1000.0, 2, "abs. offset [mm]")]
    lines = ["| controller | " + " | ".join(c[3] for c in cols) + " |", "|" + "---|" * (len(cols) + 1)]
    for s in res.specs:
        cells = []
        for metric, scale, dg, _ in cols:
            e = ix.get((part, s.label, band, metric))
            cells.append("n/a" if e is None else _fmt(e, scale, dg))
        lines.append(f"| {s.label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _comparison_text(res: BenchmarkResult) -> str:
    c = res.comparison
    if c is None:
        return "No learned compensator ran, so there is no learned-vs-classical comparison."
    if not c.best_classical:
        return (f"No classical block has a median stem travel within the learned block's "
                f"{c.travel_budget:.2f} strokes/h (sticky + severe regulation loops).")
    d = c.difference
    return (f"Travel budget (learned block's median stem travel, sticky + severe regulation): "
            f"{c.travel_budget:.2f} strokes/h. Classical blocks within it: {', '.join(c.within_budget)}. "
            f"Best of them by median R: **{c.best_classical}**. median R_learned - median R_best = "
            f"{d.value:.3f}, paired bootstrap 95 % CI [{d.lo:.3f}, {d.hi:.3f}] over {d.n} loops.")


def results_markdown(res: BenchmarkResult, command: str = "") -> str:
    """The text of ``results.md``."""
    cfg = res.config
    reg = res.scenarios.regulation
    counts = ", ".join(f"{b} {int((reg.band == b).sum())}" for b in ("healthy", "sticky", "severe"))
    out = ["# Compensator benchmark", ""]
    if command:
        out += [f"Command: `{command}`", ""]
    cpu = sum(r.cpu_seconds for r in res.scores)
    out += [f"Run time {res.seconds:.0f} s with {res.jobs_text('worker process(es)')}; CPU time of the runs "
            f"{cpu:.0f} s "
            f"(on {res.jobs} free core(s) about {cpu / max(res.jobs, 1):.0f} s). Seed {cfg.seed}. "
            f"Loops per part: {reg.n} ({counts}); friction models: {', '.join(cfg.models)}. "
            f"Regulation: {cfg.regulation.duration_s:g} s per loop; servo: {res.scenarios.servo.duration_s:g} s.",
            "", "Medians with percentile-bootstrap 95 % confidence intervals (LC share: the mean). "
            f"R = (IAE_PI - IAE_c) / max(IAE_PI - IAE_PI,frictionless, {cfg.scores.r_floor:g} IAE_PI,frictionless), "
            f"per loop against '{REFERENCE_PI}' and '{REFERENCE_FRICTIONLESS}' on the same loop.", ""]
    if res.notes:
        out += ["Notes:", ""] + [f"- {n}" for n in res.notes] + [""]
    out += ["## Headline (regulation: sticky + severe valves)", "", headline_table(res), "",
            "## Learned vs classical at the same valve travel", "", _comparison_text(res), ""]
    for part in PARTS:
        for band in BAND_GROUPS:
            out += [f"## {part.capitalize()}: {band}", "", _part_table(res, part, band), ""]
    if res.generalisation is not None:
        from .generalisation import generalisation_markdown

        out += [generalisation_markdown(res.generalisation, cfg)]
    out += ["## Settings of each block", ""]
    set_by = {r.spec.label: r for r in res.scores}
    out += [f"- {s.label}: `{s.name}`" + (f", S = {s.estimate:g} x true S" if s.estimate else "")
            + (", frictionless valve" if s.frictionless else "") + (f", {dict(s.settings)}" if s.settings else "")
            for s in res.specs if s.label in set_by]
    return "\n".join(out) + "\n"


def write_report(res: BenchmarkResult, out: Path, command: str = "") -> tuple[Path, ...]:
    """Write ``results.md``, ``results.csv``, ``loops.csv`` and ``config.yaml`` into ``out`` (atomically)."""
    import pandas as pd
    import yaml

    out = Path(out)
    loops = pd.concat([loop_table(res.part_scores(p), res.scenarios.part(p), res.config) for p in PARTS],
                      ignore_index=True)
    return (
        _write_text(out / "results.csv", summary_frame(res).to_csv(index=False)),
        _write_text(out / "loops.csv", loops.to_csv(index=False)),
        _write_text(out / "config.yaml", yaml.safe_dump(bench_config_to_dict(res.config), sort_keys=False)),
        _write_text(out / "results.md", results_markdown(res, command)),
    )

