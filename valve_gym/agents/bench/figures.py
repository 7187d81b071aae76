"""Figures of a benchmark run (matplotlib imported here only, Agg backend, PNGs written atomically).

``trends.png``
    SP/PV, OP and stem of the example sticky loop under each controller (regulation).
``bands.png``
    LC share and median R per band with 95 % CIs (regulation), per controller.
``pareto.png``
    Median IAE vs median stem travel on the sticky + severe regulation loops: the PI detuning
    front over Kc, the compensators and the learned block.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from valve_gym._io import write_atomic

from .config import BAND_NAMES
from .pipeline import BenchmarkResult

__all__ = ["write_figures"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    data = buf.getvalue()
    write_atomic(path, lambda f: f.write(data))
    return path


def _trends(res: BenchmarkResult, path: Path) -> Path:
    plt = _plt()
    trends = [t for t in res.trends() if " S x" not in t.label]
    reg = res.scenarios.regulation
    i = res.example
    fig, axes = plt.subplots(3, len(trends), figsize=(2.6 * len(trends), 6.5), sharex=True, sharey="row",
                             squeeze=False)
    for j, tr in enumerate(trends):
        ax = axes[:, j]
        ax[0].plot(tr.t, tr.pv * 1000, lw=0.5, color="0.5", label="PV")
        ax[0].plot(tr.t, tr.sp * 1000, lw=1.0, color="k", label="SP")
        ax[1].plot(tr.t, tr.op * 100, lw=0.6, color="C0")
        ax[2].plot(tr.t, tr.stem * 100, lw=0.8, color="C3")
        ax[0].set_title(tr.label, fontsize=8)
        ax[2].set_xlabel("t [s]")
    axes[0, 0].set_ylabel("level [mm]")
    axes[1, 0].set_ylabel("OP [%]")
    axes[2, 0].set_ylabel("stem [%]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Regulation loop {i}: {reg.model[i]} valve, S = {100 * reg.S[i]:.2f} %, J = {100 * reg.J[i]:.2f} %",
                 fontsize=10)
    out = _save(fig, path)
    plt.close(fig)
    return out


def _bands(res: BenchmarkResult, path: Path) -> Path:
    plt = _plt()
    rows = {(r.controller, r.band, r.metric): r.estimate for r in res.summary if r.part == "regulation"}
    labels = [s.label for s in res.specs if " S x" not in s.label]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    w = 0.8 / max(1, len(labels))
    x = np.arange(len(BAND_NAMES))
    colours = plt.get_cmap("tab20")
    for k, lab in enumerate(labels):
        for ax, metric in zip(axes, ("lc_share", "R")):
            est = [rows.get((lab, b, metric)) for b in BAND_NAMES]
            v = np.array([e.value if e else np.nan for e in est])
            lo = np.array([e.value - e.lo if e else 0.0 for e in est])
            hi = np.array([e.hi - e.value if e else 0.0 for e in est])
            ax.bar(x + k * w, v, w, yerr=[lo, hi], capsize=2, label=lab, color=colours(k % 20))
    axes[0].set_ylabel("share of loops with a limit cycle")
    axes[1].set_ylabel("median compensation ratio R")
    r_max = max((e.hi for (_, _, m), e in rows.items() if m == "R" and np.isfinite(e.hi)), default=1.0)
    axes[1].set_ylim(-2.0, min(3.0, max(1.2, r_max + 0.1)))
    for ax in axes:
        ax.set_xticks(x + 0.4 - w / 2, BAND_NAMES)
    axes[1].axhline(0.0, color="k", lw=0.5)
    axes[1].axhline(1.0, color="k", lw=0.5, ls=":")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=6, fontsize=7,
               bbox_to_anchor=(0.5, -0.08))
    fig.suptitle("Regulation: limit cycles and compensation by stiction band (95 % bootstrap CIs)", fontsize=10)
    out = _save(fig, path)
    plt.close(fig)
    return out


def _pareto(res: BenchmarkResult, path: Path) -> Path:
    plt = _plt()
    rows = {(r.controller, r.metric): r.estimate for r in res.summary
            if r.part == "regulation" and r.band == "sticky+severe"}
    fig, ax = plt.subplots(figsize=(7, 5))
    pis = [s.label for s in res.specs if s.family in ("pi", "detuned")]
    pts = np.array([[rows[(p, "travel_per_h")].value, rows[(p, "iae_per_h")].value] for p in pis])
    pts = pts[np.argsort(pts[:, 0])]  # the front over Kc, from the most detuned to the tightest PI
    ax.plot(pts[:, 0], pts[:, 1], "o-", color="k", label="PI over Kc (SIMC, tighter, detuned)")
    others = [s for s in res.specs if (s.label, "iae_per_h") in rows and s.family not in ("pi", "detuned")]
    colours = plt.get_cmap("tab20")
    for k, s in enumerate(others):
        t, e = rows[(s.label, "travel_per_h")], rows[(s.label, "iae_per_h")]
        mk = {"frictionless": "s", "learned": "*", "policy": "P",
              "compensator": "^" if s.estimate == 1.0 else "o"}[s.family]
        ax.errorbar(t.value, e.value, xerr=[[t.value - t.lo], [t.hi - t.value]],
                    yerr=[[e.value - e.lo], [e.hi - e.value]], fmt=mk, ms=12 if mk == "*" else 6,
                    color="k" if s.family == "learned" else colours(k % 20), label=s.label)
    ax.set_xlabel("median stem travel [full strokes / h]")
    ax.set_ylabel("median IAE [m s / h]")
    ax.set_xscale("log")
    ax.legend(fontsize=6, ncol=2)
    ax.set_title("Regulation, sticky + severe valves: IAE vs valve travel", fontsize=10)
    out = _save(fig, path)
    plt.close(fig)
    return out


def write_figures(res: BenchmarkResult, out: Path) -> tuple[Path, ...]:
    """Write ``trends.png``, ``bands.png`` and ``pareto.png`` into ``out``."""
    out = Path(out)
    return (_trends(res, out / "trends.png"), _bands(res, out / "bands.png"), _pareto(res, out / "pareto.png"))
