"""Figures, JSON and markdown report of a diagnosis (matplotlib imported lazily).

Every file is written atomically: to a temporary file in the target folder,
then renamed over the target, so a reader never sees a half-written file.

Examples
--------
>>> from valve_gym.diagnosis import diagnose
>>> from valve_gym.diagnosis.synthetic import make_recording
>>> res = diagnose(make_recording("none", seed=4, n=300), candidates=(), effort="fast")
>>> import tempfile, os
>>> d = tempfile.mkdtemp()
>>> paths = write_report(res, d)
>>> sorted(os.path.basename(p) for p in paths)[:3]
['acf.png', 'diagnosis.json', 'overlay.png']
"""
from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from .._markdown import md_cell
from ..effects import effect_spec

__all__ = ["write_json", "write_text", "write_report", "plot_overlay", "plot_residuals",
           "plot_acf", "plot_validation", "render_markdown", "summary_table"]


# --------------------------------------------------------------------------- atomic IO
def _atomic(path, write) -> str:
    """Write atomically (see :func:`valve_gym._io.write_atomic`)."""
    from .._io import write_atomic

    return write_atomic(path, write)


def write_text(text: str, path) -> str:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    return _atomic(path, lambda f: f.write(text.encode("utf-8")))


def write_json(obj, path) -> str:
    """Write a JSON-ready object (or a result with ``to_dict``) atomically."""
    if hasattr(obj, "to_dict"):
        obj = obj.to_dict()
    return write_text(json.dumps(obj, indent=2, allow_nan=False) + "\n", path)


def _savefig(fig, path) -> str:
    def w(f):
        fig.savefig(f, format="png", dpi=110, bbox_inches="tight")
    out = _atomic(path, w)
    import matplotlib.pyplot as plt
    plt.close(fig)
    return out


def _plt():
    try:
        import matplotlib
        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover
        raise ImportError("the report figures need matplotlib: pip install matplotlib") from e
    return plt


# --------------------------------------------------------------------------- figures
def _shade(ax, res, color="tab:red"):
    for r in res.mismatch.regions:
        ax.axvspan(r.t_start, r.t_end, color=color, alpha=0.12, lw=0)
    n_fit = res.base_split.n_fit
    if n_fit < len(res.recording):
        ax.axvline(res.recording.t[n_fit], color="k", ls=":", lw=1)


def plot_overlay(res, path=None):
    """Measured vs simulated PV, before (base) and after (final); controller output below.

    Shaded: mismatch regions of the base model; dotted line: start of the
    held-out part.  Returns the figure (or the path when ``path`` is given).
    """
    plt = _plt()
    rec = res.recording
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True,
                                 gridspec_kw={"height_ratios": [3, 1.3]})
    a1.plot(rec.t, rec.pv, color="0.3", lw=0.8, label="measured PV")
    a1.plot(rec.t, res.base.y_sim, color="tab:red", lw=1.2,
            label=f"base: RMSE {res.base.rmse_all:.3g}, fit {res.base.fit_percent_all:.1f} %")
    if res.effects:
        a1.plot(rec.t, res.final.y_sim, color="tab:blue", lw=1.2,
                label=f"+ {', '.join(res.effects)}: RMSE {res.final.rmse_all:.3g}, "
                      f"fit {res.final.fit_percent_all:.1f} %")
    if rec.sp is not None:
        a1.plot(rec.t, rec.sp, color="k", lw=0.8, ls="--", label="set point")
    _shade(a1, res)
    a1.set_ylabel("PV")
    a1.legend(loc="best", fontsize=8)
    a1.set_title(f"{rec.name}: measured vs free-run simulated "
                 f"(shaded: mismatch regions of the base model)")
    lo, hi = rec.op_range
    a2.plot(rec.t, lo + rec.op * (hi - lo), color="tab:green", lw=0.9, label="controller output")
    if res.actuator == "valve":
        try:
            h = res.final.structure.stem(res.final.w, rec.op, n_sub=res.final.n_sub)
            a2.plot(rec.t, lo + h * (hi - lo), color="tab:purple", lw=0.9,
                    label="simulated stem (final model)")
        except Exception:  # pragma: no cover - plotting aid only
            pass
    _shade(a2, res)
    a2.set_ylabel("OP")
    a2.set_xlabel("time [s]")
    a2.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return _savefig(fig, path) if path else fig


def plot_residuals(res, path=None):
    """Residuals before and after, with the noise band and the mismatch threshold."""
    plt = _plt()
    rec = res.recording
    fig, axs = plt.subplots(2, 1, figsize=(11, 5.5), sharex=True, sharey=True)
    for ax, fit, mm, title in ((axs[0], res.base, res.mismatch, "base model"),
                               (axs[1], res.final, res.mismatch_final,
                                "final model" + (f" (+ {', '.join(res.effects)})"
                                                 if res.effects else " (= base)"))):
        r = fit.residual
        ax.plot(rec.t, r, color="0.4", lw=0.6, label="residual")
        if mm.moving_rms is not None:
            ax.plot(rec.t, mm.moving_rms, color="tab:orange", lw=1.2,
                    label=f"moving RMS ({mm.window} samples)")
        ax.axhline(mm.threshold, color="tab:red", ls="--", lw=0.8, label="region threshold")
        s = 2 * mm.tests.noise_std
        ax.axhspan(-s, s, color="tab:green", alpha=0.12, lw=0, label="+-2 x noise level")
        _shade(ax, res)
        ax.set_title(f"{title}: residual RMS {mm.rms:.3g}, Ljung-Box p = "
                     f"{mm.tests.ljung_box_p:.2g}", fontsize=10)
        ax.set_ylabel("PV - simulated")
        ax.legend(loc="upper right", fontsize=7)
    axs[1].set_xlabel("time [s]")
    fig.tight_layout()
    return _savefig(fig, path) if path else fig


def plot_acf(res, path=None):
    """Residual autocorrelation and residual-input cross-correlation, 95 % bands."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 3.8))
    for mm, c, lab in ((res.mismatch, "tab:red", "base"),
                       (res.mismatch_final, "tab:blue", "final")):
        t = mm.tests
        a1.plot(t.lags, t.acf, "o-", ms=2.5, lw=0.8, color=c, label=lab)
        a2.plot(t.ccf_lags, t.ccf, "o-", ms=2.5, lw=0.8, color=c, label=lab)
    for ax, b in ((a1, res.mismatch.tests.acf_bound), (a2, res.mismatch.tests.ccf_bound)):
        ax.axhspan(-b, b, color="0.8", alpha=0.6, lw=0, label="95 % band")
        ax.axhline(0, color="k", lw=0.5)
        ax.legend(fontsize=8)
    a1.set_title("residual autocorrelation")
    a1.set_xlabel("lag [samples]")
    a2.set_title("cross-correlation residual vs controller output")
    a2.set_xlabel("lag [samples] (> 0: output leads)")
    fig.tight_layout()
    return _savefig(fig, path) if path else fig


def plot_stem(res, path=None):
    """The recorded valve position against the output, with the stem test's fitted stiction law.

    None where the recording holds no position or the stem test did not apply.
    """
    from .stiction.stem import _stem

    ev = res.stiction.evidence_of("stem")
    rec = res.recording
    if ev is None or not ev.applicable or rec.mv is None:
        return None
    d = ev.details
    lag = float(d["lag_s"]) / float(rec.dt or 1.0)
    x = _stem(rec.op, d["S"], d["J"], float(np.exp(-1.0 / lag)) if lag > 0 else 0.0, int(d["law"]))
    fits = [d["offset"] + d["span"] * (x if j == 0 else np.r_[x[0], x[:-1]]) for j in (0, 1)]
    fit = min(fits, key=lambda f: float(np.sum((rec.mv - f) ** 2)))
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 3.8), gridspec_kw={"width_ratios": [2, 1]})
    t = rec.t - rec.t[0]
    a1.plot(t, 100 * rec.op, lw=0.8, color="0.5", label="controller output")
    a1.plot(t, 100 * rec.mv, lw=0.9, color="tab:blue", label="recorded position")
    a1.plot(t, 100 * fit, lw=0.9, ls="--", color="tab:red", label=f"fitted law (S {100 * d['S']:.2g} %, "
                                                                  f"J {100 * d['J']:.2g} %)")
    a1.set_xlabel("t [s]")
    a1.set_ylabel("% of stroke")
    a1.set_title(f"stem test: {ev.verdict}")
    a1.legend(fontsize=8)
    a2.plot(100 * rec.op, 100 * rec.mv, ".", ms=2, color="tab:blue", label="recorded")
    a2.plot(100 * rec.op, 100 * fit, lw=0.6, color="tab:red", alpha=0.7, label="fitted")
    a2.set_xlabel("controller output [%]")
    a2.set_ylabel("position [%]")
    a2.set_title("position against output")
    a2.legend(fontsize=8)
    fig.tight_layout()
    return _savefig(fig, path) if path else fig


def plot_validation(res, path=None):
    """The fitted models on the validation recording (initial state refitted)."""
    ser = getattr(res, "_validation_series", None)
    if ser is None:
        return None
    plt = _plt()
    yb, yf, other = ser
    fig, ax = plt.subplots(figsize=(11, 3.8))
    v = res.validation
    ax.plot(other.t, other.pv, color="0.3", lw=0.8, label="measured PV")
    ax.plot(other.t, yb, color="tab:red", lw=1.1, label=f"base: RMSE {v['base_rmse']:.3g}")
    ax.plot(other.t, yf, color="tab:blue", lw=1.1, label=f"final: RMSE {v['final_rmse']:.3g}")
    ax.set_title(f"validation on {other.name} (models fitted on {res.recording.name})")
    ax.set_xlabel("time [s]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _savefig(fig, path) if path else fig


# --------------------------------------------------------------------------- markdown
def _g(x, nd=4):
    if x is None:
        return "–"
    try:
        x = float(x)
    except (TypeError, ValueError):
        return str(x)
    if not np.isfinite(x):
        return "–"
    return f"{x:.{nd}g}"


def render_markdown(res, figures: dict | None = None) -> str:
    """Short markdown report of a :class:`DiagnosisResult`."""
    d = res.to_dict()
    L: list[str] = []
    L += _md_summary(res, d)
    L += _md_fit(d)
    L += _md_parameters(d)
    L += _md_mismatch(d)
    L += _md_candidates(d)
    L += _md_end(d, figures)
    return "\n".join(L) + "\n"


def _verdict_basis(s: dict) -> str:
    """What the stiction verdict rests on: the methods combined and the model-based test."""
    if s.get("probability") is None:
        return ""
    if s.get("verdict_source") == "stem":
        return " (read from the recorded valve position: the stem test, figure `stem.png`)"
    if s.get("verdict_source") == "stem+model":
        return " (the recorded valve position never moved, and the process model needs a band that wide)"
    k = s.get("kstep_delta_ic")
    kstep = "" if k is None else (f"; on {s.get('kstep_horizon')}-sample-ahead predictions friction "
                                  f"{'lowers' if k < 0 else 'does not lower'} the criterion ({k:+.1f})")
    return (f" (methods combined: {s.get('verdict')}, probability of stiction {s['probability']:.2f}; "
            f"free-run model-based test: {'friction' if s.get('model_based_present') else 'no friction'}{kstep})")


def _md_op_lag(settings: dict) -> list[str]:
    """How the controller output was paired with the PV (only when it is not the model's own pairing or was tested)."""
    lag, test = settings.get("op_lag", 0), settings.get("op_lag_test") or {}
    if lag == 0 and not test.get("tested"):
        return []
    how = ("each controller output paired with the PV of the next sample (op[k-1] with pv[k]): the PV of a row "
           "was measured before that row's output acted (an output logged beside the PV it was computed from, or "
           "an input sampled with the output and held until the next sample)" if lag == 1 else
           "each controller output paired with the PV of its own row (pv[k] measured after op[k] acted)")
    margin = settings.get("rule", {}).get("ic_margin", 2.0)
    reaction = test.get("controller_reaction") or {}
    if not test.get("tested"):
        why = "as asked (--op-lag 1)"
    elif test.get("method") == "controller reaction":
        why = f"read from the controller's reaction to the PV: {reaction.get('reason', '')}"
    else:
        why = (f"{reaction.get('reason', 'no clear controller reaction')}, so chosen by fitting the base model "
               f"both ways (information criterion {test['delta_ic']:+.1f} for the next-sample pairing; it needs "
               f"below {-margin:g})")
    return [f"**Pairing of OP and PV:** {how}; {why}.", ""]


def _md_summary(res, d: dict) -> list[str]:
    """Title, record, named effects, friction verdict and the explanations."""
    L: list[str] = []
    rec = d["recording"]
    L.append(f"# Diagnosis of `{rec['name']}`")
    L.append("")
    L.append(f"{rec['n']} samples, dt = {_g(rec['dt'])} s, plant `{res.plant}`, actuator "
             f"`{res.actuator}`; held-out end: {_g(100 * d['holdout']['fraction'], 3)} % of the "
             f"record.")
    if rec.get("notes"):
        L.append("How the file was read: " + "; ".join(rec["notes"]) + ".")
    choice = d.get("settings", {}).get("plant_choice", {})
    if choice.get("reason"):
        L.append(f"Plant model (`--plant auto`): {choice['reason']}.")
    L.append("")
    if rec.get("repairs"):
        L.append("**What was done to the data before fitting** (repairs, resampling, decimation):")
        L.append("")
        L.extend(f"- {r}" for r in rec["repairs"])
        L.append("")
    L += _md_op_lag(d["settings"])
    eff = ", ".join(f"`{e}`" for e in d["effects"]) or "none"
    L.append(f"**Missing physics:** {eff}.  **Valve friction:** "
             + ("present" if d["stiction"].get("present") else
                ("not found" if d["stiction"].get("tested") else "not tested (no valve)"))
             + _verdict_basis(d["stiction"]) + ".")
    L.append("")
    for p in d["explanation"]:
        L.append(f"- {p}")
    if d["stiction"].get("explanation"):
        L.append(f"- {d['stiction']['explanation']}")
    h = d["stiction"].get("horch")
    if h:
        pi = "" if h["phase_index"] is None else f", phase index {h['phase_index']:.2f}"
        L.append(f"- Second opinion, without a model (Horch's cross-correlation test, not part of "
                 f"the verdict): {h['verdict']}{pi}: {h['reason']}.")
    L.append("")
    L += _md_cause(d.get("cause"))
    return L


def _md_cause(c: dict | None) -> list[str]:
    """The cause of the oscillation: probabilities, evidence in words, action (docs/causes.md)."""
    if not c:
        return []
    L = ["## Why the loop oscillates", ""]
    if not c.get("oscillating"):
        return L + [c.get("summary", ""), ""]
    L.append(c["summary"])
    L.append("")
    L.append("| cause | probability |")
    L.append("|---|---:|")
    for k, v in c["probabilities"].items():
        L.append(f"| {k} | {_g(v, 3)} |")
    L.append("")
    L.extend(f"- ({e['cause']}, {e['pull']:+.1f}) {e['statement']}" for e in c["evidence"])
    L.append("")
    L.append(f"**Action:** {c['action']}.")
    L.append("")
    return L


def _md_fit(d: dict) -> list[str]:
    """Fit of the base and final models, whole record, held-out end and validation."""
    L: list[str] = []
    L.append("## Fit before and after")
    L.append("")
    L.append("| model | RMSE (whole record) | fit % | held-out RMSE | held-out fit % | parameters |")
    L.append("|---|---|---|---|---|---|")
    h = d["holdout"]
    for key, hr, hf in (("base", h["base_rmse"], h["base_fit_percent"]),
                        ("final", h["final_rmse"], h["final_fit_percent"])):
        m = d[key]
        L.append(f"| {m['model']} | {_g(m['rmse'])} | {_g(m['fit_percent'], 3)} | {_g(hr)} | "
                 f"{_g(hf, 3)} | {m['n_params']} |")
    if d.get("validation"):
        v = d["validation"]
        L.append("")
        L.append(f"Validation on `{v['recording']}` (initial state refitted): RMSE base "
                 f"{_g(v['base_rmse'])}, final {_g(v['final_rmse'])}; fit % base "
                 f"{_g(v['base_fit_percent'], 3)}, final {_g(v['final_fit_percent'], 3)}. "
                 f"Starting from the fitted recording's initial state instead (a record known to "
                 f"start at the same point): RMSE base {_g(v['base_rmse_same_state'])}, final "
                 f"{_g(v['final_rmse_same_state'])}.")
    L.append("")
    return L


def _md_parameters(d: dict) -> list[str]:
    """Table of the fitted parameters of the base and final models, with units."""
    L: list[str] = []
    L.append("## Fitted parameters")
    L.append("")
    L.append("| parameter | base | final | unit |")
    L.append("|---|---|---|---|")
    keys = list(dict.fromkeys(list(d["base"]["params"]) + list(d["final"]["params"])))
    units = {**d["base"]["units"], **d["final"]["units"]}
    for k in keys:
        L.append(f"| `{k}` | {_g(d['base']['params'].get(k))} | {_g(d['final']['params'].get(k))} "
                 f"| {units.get(k, '')} |")
    L.append("")
    return L


def _md_mismatch(d: dict) -> list[str]:
    """Regions and conditions where the base model misses; residual tests."""
    L: list[str] = []
    L.append("## Where the base model misses")
    L.append("")
    if d["mismatch"]:
        L.append("| t_start [s] | t_end [s] | RMS | mean | share of squared error | main conditions |")
        L.append("|---|---|---|---|---|---|")
        for r in d["mismatch"]:
            main = sorted(((v, k) for k, v in r["conditions"].items()), reverse=True)[:3]
            mc = ", ".join(f"{k} {100 * v:.0f} %" for v, k in main)
            L.append(f"| {_g(r['t_start'])} | {_g(r['t_end'])} | {_g(r['rms'])} | {_g(r['mean'])} | "
                     f"{_g(100 * r['share_sse'], 3)} % | {mc} |")
    else:
        L.append("No region stands out above the threshold.")
    L.append("")
    L.append("| condition | fraction | RMS in | RMS out | ratio | z | significant |")
    L.append("|---|---|---|---|---|---|---|")
    for c in d["mismatch_conditions"]:
        L.append(f"| {md_cell(c['description'])} | {_g(100 * c['fraction'], 3)} % | {_g(c['rms_in'])} | "
                 f"{_g(c['rms_out'])} | {_g(c['ratio'], 3)} | {_g(c['z'], 3)} | "
                 f"{'yes' if c['significant'] else 'no'} |")
    L.append("")
    rt = d["residual_tests"]
    L.append("Residual tests (base -> final): Ljung-Box p "
             f"{_g(rt['base']['ljung_box_p'], 3)} -> {_g(rt['final']['ljung_box_p'], 3)}; "
             f"autocorrelations outside the 95 % band {_g(100 * rt['base']['acf_outside'], 3)} % -> "
             f"{_g(100 * rt['final']['acf_outside'], 3)} %; input cross-correlations outside "
             f"{_g(100 * rt['base']['ccf_outside'], 3)} % -> {_g(100 * rt['final']['ccf_outside'], 3)} %.")
    L.append("")
    return L


def _md_candidates(d: dict) -> list[str]:
    """Table of the candidate effects tried and skipped."""
    L: list[str] = []
    L.append("## Candidates tried")
    L.append("")
    L.append("| round | effect | its signature in the base residual | criterion change | held-out change | verdict |")
    L.append("|---|---|---|---|---|---|")
    for c in d["candidates"]:
        name = c["effect"] + (f" ({c['variant']})" if c["variant"] else "")
        hc = "–" if c["holdout_change"] is None else f"{100 * c['holdout_change']:+.1f} %"
        L.append(f"| {c['round']} | {md_cell(name)} | {md_cell(_signature_seen(c['effect'], d))} | "
                 f"{_g(c['delta_ic'], 3)} | {hc} | "
                 f"{'**added**' if c['accepted'] else ('pays' if c['pays'] else 'no')} |")
    for e, why in d["skipped"].items():
        L.append(f"| – | {md_cell(e)} | – | – | – | {md_cell('skipped: ' + str(why))} |")
    L += _md_evidence(d["holdout"])
    return L


def _md_evidence(hold: dict) -> list[str]:
    """How many independent samples the criterion changes above rest on."""
    n_eff, n_fit = hold.get("n_eff"), hold.get("n_fit")
    if n_eff is None or not n_fit:
        return []
    share = 100.0 * n_eff / n_fit
    pct = f"{share:.0f}" if share >= 10 else f"{share:.2g}"
    return ["", f"The criterion counts {n_eff:.0f} effective samples in the {n_fit} fitted ({pct} %): the base "
                f"model's free-run residual, whose consecutive errors that move together count as one. A residual "
                f"that drifts slowly (an unmeasured load or drift the model cannot reproduce from the controller "
                f"output) has few, and every criterion change above is measured in them: with few, an effect "
                f"must lower the error by more to pass the margin, and a small change is weak evidence either "
                f"way."]


def _signature_seen(effect: str, d: dict) -> str:
    """The located conditions an effect's spec names as its signature, and whether the base residual shows them."""
    try:
        names = effect_spec(effect).conditions
    except ValueError:
        return "–"
    stats = {c["condition"]: c for c in d["mismatch_conditions"]}
    seen = [f"{stats[n]['description']}: {'yes' if stats[n]['significant'] else 'no'} "
            f"(x{_g(stats[n]['ratio'], 2)})" for n in names if n in stats]
    return "; ".join(seen) if seen else "– (in the residual tests)"


def _md_end(d: dict, figures: dict | None) -> list[str]:
    """Figures (file names) and the computing time."""
    L: list[str] = []
    if figures:
        L.append("")
        L.append("## Figures")
        L.append("")
        for k, p in figures.items():
            if p:
                L.append(f"![{k}]({os.path.basename(p)})")
    L.append("")
    t = d["timing"]
    L.append(f"Computed in {_g(t.get('total'), 3)} s ({t.get('candidate_fits')} candidate fits).")
    return L


def write_report(res, folder) -> list[str]:
    """Write ``diagnosis.json``, ``report.md`` and the PNG figures into ``folder``, as one unit.

    The files are staged beside ``folder`` and published together, ``report.md`` last
    (:func:`valve_gym._io.staged_folder`): an interrupted report leaves the folder as it was.
    Returns the written paths.
    """
    from .._io import staged_folder

    with staged_folder(folder, last=("diagnosis.json", "report.md")) as stage:
        figs: dict[str, Any] = {"overlay": plot_overlay(res, os.path.join(stage, "overlay.png")),
                                "residuals": plot_residuals(res, os.path.join(stage, "residuals.png")),
                                "acf": plot_acf(res, os.path.join(stage, "acf.png"))}
        if getattr(res, "_validation_series", None) is not None:
            figs["validation"] = plot_validation(res, os.path.join(stage, "validation.png"))
        stem = plot_stem(res, os.path.join(stage, "stem.png"))
        if stem is not None:
            figs["stem"] = stem
        written = [p for p in figs.values() if p]
        written.append(write_json(res, os.path.join(stage, "diagnosis.json")))
        written.append(write_text(render_markdown(res, figs), os.path.join(stage, "report.md")))
    return [os.path.join(os.fspath(folder), os.path.basename(p)) for p in written]


def summary_table(rows: list[dict]) -> str:
    """Markdown table of :meth:`DiagnosisResult.summary_row` rows (or error rows)."""
    L = ["| recording | plant | effects | stiction | RMSE base | RMSE final | fit % base | "
         "fit % final | held-out RMSE base -> final | s |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            L.append(f"| {md_cell(r.get('recording', r.get('path')))} | – | {md_cell('ERROR: ' + str(r['error']))} "
                     f"| | | | | | | |")
            continue
        L.append(f"| {md_cell(r['recording'])} | {md_cell(r['plant'])} | {md_cell(r['effects'])} | "
                 f"{'yes' if r['stiction'] else 'no'} | {_g(r['base_rmse'])} | "
                 f"{_g(r['final_rmse'])} | {_g(r['base_fit_percent'], 3)} | "
                 f"{_g(r['final_fit_percent'], 3)} | {_g(r['holdout_base_rmse'])} -> "
                 f"{_g(r['holdout_final_rmse'])} | {_g(r['seconds'], 3)} |")
    return "\n".join(L) + "\n"
