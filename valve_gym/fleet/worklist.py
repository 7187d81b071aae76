"""The worklist: which valve to fix first, as ``worklist.md`` and a static ``worklist.html``.

Loops are ranked by the score of :mod:`valve_gym.fleet.actions` (cost of
stiction: evidence weight x controller-output oscillation amplitude); each row
gives the evidence in one line, ``S`` and ``J``, and the recommended action.
The HTML page embeds, for the top loops, a PV-OP plot and a trend plot (PNG,
base64; matplotlib imported only here, Agg backend), so it can be mailed or
opened from a share without a server.
"""
from __future__ import annotations

import base64
import html
import io
import math
import os
from collections import Counter
from collections.abc import Sequence

from .._io import write_atomic
from .._markdown import md_cells, md_row
from .actions import RULES, S_SEVERE, W_HIGH, W_LOW
from .result import FleetSettings, LoopResult
from .sources import LoopSource, load_loop

__all__ = ["rank", "write_worklist", "loop_plots"]


def rank(results: Sequence[LoopResult]) -> list[LoopResult]:
    """Loops with status ok, highest score first (ties: larger PV oscillation, then name)."""
    ok = [r for r in results if r.status == "ok"]
    return sorted(ok, key=lambda r: (-(r.score if math.isfinite(r.score) else 0.0),
                                     -(r.oscillation if math.isfinite(r.oscillation) else 0.0), r.loop))


def _pct(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{100 * x:.1f} %"


def _g(x: float, fmt: str = ".3g") -> str:
    return "n/a" if not math.isfinite(x) else format(x, fmt)


def _summary(results: Sequence[LoopResult], pending: int = 0) -> list[str]:
    n = len(results)
    ok = [r for r in results if r.status == "ok"]
    osc = sum(r.oscillating for r in ok)
    full = sum(r.stage == "full" for r in ok)
    acts = Counter(r.action.split(" (")[0].split(":")[0] for r in ok if r.oscillating)
    lines = [f"- partial run: {pending} of {n + pending} loops not analysed yet; run the same command again "
             f"to continue them"] if pending else []
    lines += [f"- loops: {n + pending}; analysed: {len(ok)}; failed: {n - len(ok)}"
              + (f"; not analysed yet: {pending}" if pending else ""),
             f"- oscillating: {osc} ({100 * osc / max(len(ok), 1):.0f} % of those analysed); fully diagnosed: {full}"]
    lines += [f"- {k}: {v}" for k, v in acts.most_common()]
    return lines


def _cause_cell(r: LoopResult) -> str:
    """``cause (0.71 / 0.10 / ...)`` of a loop, or ``n/a`` where no cause was read."""
    if not r.cause or r.cause == "none":
        return "n/a"
    ps = (r.p_valve, r.p_tuning, r.p_disturbance, r.p_sensor, r.p_saturation)
    return f"{r.cause} (" + " / ".join(_g(p, ".2f") for p in ps) + ")"


def _rules_md() -> list[str]:
    out = [md_row(("rule", "when", "action")), "|---|---|---|"]
    out += [md_row((r.name, r.when, r.action.format(S="S", message="the message",
                                                    cause_action="the cause's action: repair the valve / retune "
                                                                 "with the suggested Kc / find the upstream source / "
                                                                 "check the transmitter / check the output limits")))
            for r in RULES]
    return out


def _md(results: Sequence[LoopResult], settings: FleetSettings, max_rows: int, pending: int = 0) -> str:
    ranked = [r for r in rank(results) if r.oscillating or r.stiction == "yes"]
    lines = ["# Worklist: which valve to fix first", "", *_summary(results, pending), "",
             f"Ranked by score = w x OP oscillation amplitude [% of stroke] (w: stiction evidence weight; "
             f"see 'How the ranking works'). Plant model {_plant_words(settings.plant)}, "
             f"actuator {settings.actuator}.", "",
             md_row(("#", "loop", "score", "action", "cause (p valve / tuning / disturbance / sensor / saturation)",
                     "S", "J", "w", "PV amplitude", "period [s]", "evidence")),
             "|---:|---|---:|---|---|---:|---:|---:|---:|---:|---|"]
    for i, r in enumerate(ranked[:max_rows], 1):
        lines.append(md_row((i, r.loop, _g(r.score, ".2f"), r.action, _cause_cell(r), _pct(r.S), _pct(r.J),
                             _g(r.weight, ".2f"), _g(r.oscillation), _g(r.period_s, ".0f"),
                             (r.cause_evidence + " " if r.cause_evidence else "") + r.message)))
    if len(ranked) > max_rows:
        lines.append(f"\n{len(ranked) - max_rows} more oscillating loops in loops.csv.")
    if not ranked:
        lines.append(md_row(("", "no loop oscillates", "", "nothing", "", "", "", "", "", "", "")))
    bad = [r for r in results if r.status != "ok"]
    if bad:
        lines += ["", "## Loops that could not be analysed", "", md_row(("loop", "status", "message")), "|---|---|---|"]
        lines += [md_row((r.loop, r.status, r.message)) for r in bad]
    lines += ["", "## How the ranking works", "",
              "score = w x 100 A_OP, with A_OP the controller output's oscillation amplitude (fraction of stroke; "
              "0 when the loop does not oscillate, by Thornhill's regularity of the ACF zero crossings) and w the "
              "stiction evidence weight: the probability that the valve causes the oscillation "
              "(valve_gym.diagnosis.causes, docs/causes.md) where the loop was diagnosed in full, else the diagnosis' "
              "calibrated stiction probability when it reports one, else the mean of "
              "the model verdict (yes 1, no 0) and Horch's phase index. "
              f"w >= {W_HIGH}: the valve is the cause; w <= {W_LOW}: it is not. A stick band S >= {S_SEVERE:.0%} "
              "of stroke is severe. First matching rule:", "", *_rules_md(), ""]
    return "\n".join(lines)


def loop_plots(src: LoopSource, settings: FleetSettings, period_s: float) -> tuple[bytes, bytes]:
    """PNG bytes of the PV-OP plot and the trend plot of one loop (last ~4 periods, at most 600 samples)."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    rec = load_loop(src, **settings.load_kw()).recording
    dt = float(rec.dt or 1.0)
    m = int(min(len(rec), 600, 4 * period_s / dt if math.isfinite(period_s) and period_s > 0 else 600))
    sl = slice(len(rec) - m, len(rec))
    out = []
    fig, ax = plt.subplots(figsize=(3.2, 2.6), dpi=80)
    ax.plot(100 * rec.op[sl], rec.pv[sl], lw=0.8)
    ax.set_xlabel("OP [% of stroke]")
    ax.set_ylabel("PV")
    ax.set_title(f"{src.name}: PV-OP", fontsize=9)
    fig.tight_layout()
    out.append(_png(fig))
    fig, ax = plt.subplots(figsize=(5.0, 2.6), dpi=80)
    t = rec.t[sl]
    ax.plot(t, rec.pv[sl], lw=0.8, label="PV")
    if rec.sp is not None:
        ax.plot(t, rec.sp[sl], lw=0.8, ls="--", label="SP")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("PV, SP")
    ax2 = ax.twinx()
    ax2.plot(t, 100 * rec.op[sl], lw=0.8, color="C3", label="OP")
    ax2.set_ylabel("OP [%]", color="C3")
    ax.legend(loc="upper left", fontsize=7)
    ax.set_title(f"{src.name}: trend", fontsize=9)
    fig.tight_layout()
    out.append(_png(fig))
    plt.close("all")
    return out[0], out[1]


def _png(fig) -> bytes:
    b = io.BytesIO()
    fig.savefig(b, format="png")
    return b.getvalue()


def _html(md_text: str, results: Sequence[LoopResult], sources: Sequence[LoopSource],
          settings: FleetSettings, top: int) -> str:
    by_name = {s.name: s for s in sources}
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>valve_gym worklist</title><style>"
             "body{font-family:sans-serif;margin:1.5em;max-width:75em}table{border-collapse:collapse;font-size:90%}"
             "td,th{border:1px solid #bbb;padding:2px 6px;vertical-align:top}h2{margin-top:1.5em}"
             "img{margin:2px}</style></head><body>"]
    table: list[str] = []
    for line in md_text.splitlines():
        if line.startswith("|"):
            cells = md_cells(line)
            if set("".join(cells)) <= set("-: "):
                continue
            tag = "th" if not table else "td"
            table.append("<tr>" + "".join(f"<{tag}>{html.escape(c)}</{tag}>" for c in cells) + "</tr>")
            continue
        if table:
            parts.append("<table>" + "".join(table) + "</table>")
            table = []
        if line.startswith("# "):
            parts.append(f"<h1>{html.escape(line[2:])}</h1>")
        elif line.startswith("## "):
            parts.append(f"<h2>{html.escape(line[3:])}</h2>")
        elif line.startswith("- "):
            parts.append(f"<div>&bull; {html.escape(line[2:])}</div>")
        elif line.strip():
            parts.append(f"<p>{html.escape(line)}</p>")
    if table:
        parts.append("<table>" + "".join(table) + "</table>")
    ranked = [r for r in rank(results) if r.oscillating][:top]
    if ranked:
        parts.append(f"<h2>Plots of the top {len(ranked)} loops</h2>")
    for i, r in enumerate(ranked, 1):
        parts.append(f"<h3>{i}. {html.escape(r.loop)}: {html.escape(r.action)}</h3>"
                     f"<p>{html.escape(r.message)}</p>")
        try:
            imgs = loop_plots(by_name[r.loop], settings, r.period_s)
        except Exception as e:  # a plot must not lose the worklist
            parts.append(f"<p>(no plot: {html.escape(str(e))})</p>")
            continue
        for b in imgs:
            parts.append(f"<img alt='{html.escape(r.loop)}' src='data:image/png;base64,"
                         f"{base64.b64encode(b).decode()}'>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_worklist(results: Sequence[LoopResult], sources: Sequence[LoopSource], out_dir: str,
                   settings: FleetSettings = FleetSettings(), top: int = 10, max_rows: int = 200,
                   pending: int = 0) -> tuple[str, str]:
    """Write ``out_dir/worklist.md`` and ``out_dir/worklist.html`` (atomic).

    Parameters
    ----------
    results : sequence of LoopResult, one per loop
    sources : sequence of LoopSource, to re-read the top loops for their plots
    out_dir : str
    settings : FleetSettings, as used for the results (columns, ranges)
    top : int, loops with plots in the HTML page
    max_rows : int, ranked rows listed
    pending : int, loops without a result yet (a partial run: ``max_loops`` or interrupted); said at the top

    Returns
    -------
    (md path, html path)
    """
    md_text = _md(results, settings, max_rows, pending)
    page = _html(md_text, results, sources, settings, top)
    md = write_atomic(os.path.join(out_dir, "worklist.md"), lambda f: f.write(md_text.encode("utf-8")))
    ht = write_atomic(os.path.join(out_dir, "worklist.html"), lambda f: f.write(page.encode("utf-8")))
    return md, ht


def _plant_words(plant: str) -> str:
    """The plant setting in words (``auto``: chosen per loop from its tag)."""
    return ("chosen per loop from its tag (LIC... integrating; FIC, PIC, TIC, AIC... first_order; no tag: tank)"
            if plant == "auto" else plant)
