"""Stiction verdict and size (S, J with 90 % intervals) on the benchmark's regulation loops.

The benchmark (``configs/benchmark.yaml``, :mod:`valve_gym.agents.bench`) draws valves with Riihilahti,
Choudhury or Kano friction of known stick band ``S`` and slip jump ``J`` (fractions of stroke) on a
level tank, with an Ornstein-Uhlenbeck load inflow and 2 mm measurement noise.  Here every loop
runs under the benchmark's PI (SIMC tuning) at its constant set point, its OP and PV become a
:class:`valve_gym.diagnosis.Recording`, and the public diagnosis (``diagnose(rec, 'tank',
candidates=())``) gives the verdict (``stiction.present``) and ``S``, ``S_interval``, ``J``,
``J_interval``, ``sizes_agree`` and each method's ``sizes``.

Scores: verdict accuracy (a healthy valve, S < 0.5 %, should be cleared; a sticky or severe one
found), and on the sticky loops called stiction (and on all sticky loops with an estimate) the
coverage of the true S and J by the 90 % intervals, the median relative errors, each method's own
coverage and how often the two methods' intervals overlap.

``--calibrate`` chooses the size constants instead (the scale and model discrepancy of the
ellipse, the model discrepancies of the fitted slip-jump block) on sticky textbook loops of
:mod:`valve_gym.diagnosis.stiction.loops` drawn with seeds ``90000 + i``: seeds that neither
``benchmarks/validate_stiction.py`` (``50000 + i``) nor this benchmark use.  The rule: the
ellipse's scale is the median of ``S / apparent stiction``; each discrepancy ``c`` is the smallest
on a 0.05 grid whose widened intervals (``lo e^-c``, ``hi e^c``) hold the true value in at least
90 % of the loops; both on the loops called stiction (where the size is read).  With ``--n 60`` this
gave ``ELLIPSE_SCALE`` 2.21, ``DISCREPANCY_ELLIPSE`` 0.9, ``DISCREPANCY_HAMMERSTEIN`` 1.1 and
``DISCREPANCY_HAMMERSTEIN_J`` 1.5, the values shipped.

Usage::

    nice -n 10 python benchmarks/sizes_on_benchmark_loops.py [--n 36] [--jobs 2] [--seed 20261123]
    nice -n 10 python benchmarks/sizes_on_benchmark_loops.py --calibrate [--n 60] [--jobs 2]
"""
from __future__ import annotations

import argparse
import json
import os
import time
from collections import defaultdict

import numpy as np

from valve_gym.diagnosis import Recording, diagnose
from valve_gym.diagnosis.cli import OP_LAG_CHOICES, op_lag_value
from valve_gym.diagnosis.model import process_pool
from valve_gym.diagnosis.stiction import oscillation

CAL_SEED = 90_000
GRID = np.round(np.arange(0.0, 3.0001, 0.05), 2)


def benchmark_loops(n: int, seed: int | None) -> list[dict]:
    """``n`` regulation loops of the benchmark under its SIMC PI: OP, PV, the stem and the true valve."""
    from valve_gym.agents.bench.config import load_bench_config
    from valve_gym.agents.bench.runner import ControllerSpec, run_spec
    from valve_gym.agents.bench.scenarios import regulation_scenarios

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    cfg = load_bench_config(os.path.join(root, "configs", "benchmark.yaml"))
    sc = regulation_scenarios(cfg, n=n, seed=seed)
    runs = run_spec(ControllerSpec("PI (SIMC)", "pi", "pi"), sc)
    t = np.arange(sc.n_steps) * sc.scan_s
    return [{"name": f"{sc.model[i]}_{sc.band[i]}_{i}", "model": str(sc.model[i]), "band": str(sc.band[i]),
             "label": int(sc.band[i] != "healthy"), "S_true": float(sc.S[i]), "J_true": float(sc.J[i]),
             "plant": "tank", "dt": sc.scan_s, "t": t, "op": runs.op[:, i], "pv": runs.pv[:, i],
             "sp": runs.sp[:, i], "stem": runs.stem[:, i]} for i in range(sc.n)]


def calibration_loops(n: int) -> list[dict]:
    """``n`` sticky textbook loops of :mod:`valve_gym.diagnosis.stiction.loops` (seeds ``CAL_SEED + i``)."""
    from valve_gym.diagnosis.stiction.loops import random_spec, simulate_loop

    plant_of = {"foptd": "first_order", "integrating": "integrating", "tank": "tank"}
    out = []
    for i in range(n):
        spec = random_spec(np.random.default_rng(CAL_SEED + i), True)
        rec = simulate_loop(spec, seed=CAL_SEED + i, name=f"cal{i}")
        out.append({"name": f"{spec.process}_{spec.valve}_{i}", "model": spec.valve, "band": "sticky",
                    "label": 1, "S_true": spec.S, "J_true": spec.J, "plant": plant_of[spec.process],
                    "dt": rec.dt, "t": rec.t, "op": rec.op, "pv": rec.pv, "sp": rec.sp})
    return out


def _neutral_sizes() -> None:
    """Size constants at their neutral values: raw profile and apparent-stiction intervals."""
    from valve_gym.diagnosis.stiction import ellipse, hammerstein

    hammerstein.DISCREPANCY_HAMMERSTEIN = hammerstein.DISCREPANCY_HAMMERSTEIN_J = 0.0
    ellipse.ELLIPSE_SCALE, ellipse.DISCREPANCY_ELLIPSE = 1.0, 0.0


def _run_one(args) -> dict:
    loop, neutral, op_lag = args
    if neutral:
        _neutral_sizes()
    t0 = time.perf_counter()
    rec = Recording(t=loop["t"], op=loop["op"], pv=loop["pv"], sp=loop["sp"], dt=loop["dt"], name=loop["name"])
    s = diagnose(rec, plant=loop["plant"], candidates=(), jobs=1, op_lag=op_lag).stiction
    out = {k: v for k, v in loop.items() if k not in ("t", "op", "pv", "sp")}
    out.update({"present": bool(s["present"]), "verdict": s.get("verdict"), "S": s.get("S"),
                "S_interval": s.get("S_interval"), "J": s.get("J"), "J_interval": s.get("J_interval"),
                "sizes_agree": s.get("sizes_agree"), "sizes": s.get("sizes") or [],
                "cycles": bool(oscillation(rec.pv).present), "seconds": time.perf_counter() - t0})
    return out


def run(loops: list[dict], jobs: int, neutral: bool = False, op_lag="auto") -> list[dict]:
    """Diagnose every loop (``jobs`` processes; ``op_lag`` of :func:`~valve_gym.diagnosis.diagnose`)."""
    args = [(lp, neutral, op_lag) for lp in loops]
    if jobs <= 1:
        return [_run_one(a) for a in args]
    with process_pool(jobs) as ex:
        return list(ex.map(_run_one, args))


def _f(x) -> float:
    return float("nan") if x is None else float(x)


def _inside(iv, truth) -> bool | None:
    if iv is None or not np.all(np.isfinite([_f(iv[0]), _f(iv[1])])):
        return None
    return bool(_f(iv[0]) <= truth <= _f(iv[1]))


def _rate(xs) -> tuple[float, int]:
    xs = [x for x in xs if x is not None]
    return (float(np.mean(xs)) if xs else float("nan")), len(xs)


def size_scores(rows: list[dict]) -> dict:
    """Coverage, median relative errors and agreement of the size estimates of ``rows`` (sticky loops)."""
    rows = [r for r in rows if np.isfinite(_f(r["S"]))]
    if not rows:
        return {"n": 0}
    out = {"n": len(rows),
           "S_cover": _rate([_inside(r["S_interval"], r["S_true"]) for r in rows]),
           "J_cover": _rate([_inside(r["J_interval"], r["J_true"]) for r in rows]),
           "S_median_rel_err": float(np.median([abs(_f(r["S"]) - r["S_true"]) / r["S_true"] for r in rows])),
           "J_median_rel_err": float(np.nanmedian([abs(_f(r["J"]) - r["J_true"]) / max(r["J_true"], 1e-4)
                                                   for r in rows])),
           "agree": _rate([r["sizes_agree"] for r in rows]), "methods": {}}
    for m in ("hammerstein", "ellipse"):
        est = [(s, r) for r in rows for s in r["sizes"] if s["method"] == m and np.isfinite(_f(s["S"]))]
        if est:
            out["methods"][m] = {"n": len(est),
                                 "S_cover": float(np.mean([_f(s["S_lo"]) <= r["S_true"] <= _f(s["S_hi"])
                                                           for s, r in est])),
                                 "S_median_rel_err": float(np.median([abs(_f(s["S"]) - r["S_true"]) / r["S_true"]
                                                                      for s, r in est]))}
    return out


def verdict_scores(rows: list[dict]) -> dict:
    """Confusion counts and balanced accuracy of ``stiction.present`` (undecided is not 'present')."""
    tp = sum(r["present"] for r in rows if r["label"])
    fn = sum(not r["present"] for r in rows if r["label"])
    tn = sum(not r["present"] for r in rows if not r["label"])
    fp = sum(r["present"] for r in rows if not r["label"])
    tpr = tp / max(tp + fn, 1)
    tnr = tn / max(tn + fp, 1) if tn + fp else float("nan")
    return {"tp": tp, "fn": fn, "tn": tn, "fp": fp, "sensitivity": tpr, "specificity": tnr,
            "balanced_accuracy": float(np.nanmean([tpr, tnr]))}


def _smallest_c(lo, hi, truth) -> float:
    """Smallest grid ``c`` with ``lo e^-c <= truth <= hi e^c`` for at least 90 % of the loops."""
    lo, hi, truth = (np.asarray(x, float) for x in (lo, hi, truth))
    for c in GRID:
        if np.mean((lo * np.exp(-c) <= truth) & (truth <= hi * np.exp(c))) >= 0.9:
            return float(c)
    return float(GRID[-1])


def calibrate(rows: list[dict]) -> dict:
    """The size constants by the rule of the module notes, from loops diagnosed with neutral constants.

    Only the loops called stiction (``stiction.present``) count: the size is read, and scored, on those.
    """
    rows = [r for r in rows if r["present"]]
    ham = [(s, r) for r in rows for s in r["sizes"] if s["method"] == "hammerstein" and np.isfinite(_f(s["S"]))]
    ell = [(s, r) for r in rows for s in r["sizes"] if s["method"] == "ellipse" and _f(s["S"]) > 0]
    out: dict[str, float] = {"n_hammerstein": len(ham), "n_ellipse": len(ell)}
    if ell:
        k = float(np.exp(np.median([np.log(r["S_true"] / _f(s["S"])) for s, r in ell])))
        out["ELLIPSE_SCALE"] = k
        out["DISCREPANCY_ELLIPSE"] = _smallest_c([k * _f(s["S_lo"]) for s, _ in ell],
                                                 [k * _f(s["S_hi"]) for s, _ in ell], [r["S_true"] for _, r in ell])
    if ham:
        out["DISCREPANCY_HAMMERSTEIN"] = _smallest_c([_f(s["S_lo"]) for s, _ in ham], [_f(s["S_hi"]) for s, _ in ham],
                                                     [r["S_true"] for _, r in ham])
        out["DISCREPANCY_HAMMERSTEIN_J"] = _smallest_c([_f(s["J_lo"]) for s, _ in ham],
                                                       [_f(s["J_hi"]) for s, _ in ham], [r["J_true"] for _, r in ham])
    return out


def _size_line(title: str, sz: dict) -> str:
    if not sz.get("n"):
        return f"{title}: no size estimate\n"
    t = (f"{title}: n={sz['n']}; S inside its 90 % interval {sz['S_cover'][0]:.0%} ({sz['S_cover'][1]}), "
         f"J {sz['J_cover'][0]:.0%} ({sz['J_cover'][1]}); median |S_hat - S|/S {sz['S_median_rel_err']:.0%}, "
         f"J {sz['J_median_rel_err']:.0%}; methods agree {sz['agree'][0]:.0%} ({sz['agree'][1]})\n")
    for m, d in sz["methods"].items():
        t += f"    {m}: n={d['n']}, S cover {d['S_cover']:.0%}, median rel err {d['S_median_rel_err']:.0%}\n"
    return t


def report(rows: list[dict]) -> str:
    """Plain-text report: verdicts overall and per friction model, sizes on sticky loops."""
    v = verdict_scores(rows)
    out = [f"{len(rows)} loops: verdict balanced accuracy {v['balanced_accuracy']:.0%} (sticky found "
           f"{v['tp']}/{v['tp'] + v['fn']}, healthy cleared {v['tn']}/{v['tn'] + v['fp']})\n"]
    by = defaultdict(list)
    for r in rows:
        by[r["model"]].append(r)
    for m, rs in sorted(by.items()):
        vm = verdict_scores(rs)
        out.append(f"  {m}: sticky found {vm['tp']}/{vm['tp'] + vm['fn']}, healthy cleared "
                   f"{vm['tn']}/{vm['tn'] + vm['fp']}\n")
    for cyc, what in ((True, "cycles regularly"), (False, "does not cycle regularly")):
        rs = [r for r in rows if r.get("cycles") is cyc]
        if rs:
            vc = verdict_scores(rs)
            out.append(f"  PV {what} (Thornhill's regularity r > 1, at least 3 cycles): {len(rs)} loops, sticky "
                       f"found {vc['tp']}/{vc['tp'] + vc['fn']}, healthy cleared {vc['tn']}/{vc['tn'] + vc['fp']}\n")
    sticky = [r for r in rows if r["label"]]
    out.append(_size_line("sizes, sticky loops called stiction", size_scores([r for r in sticky if r["present"]])))
    out.append(_size_line("sizes, all sticky loops with an estimate", size_scores(sticky)))
    for m, rs in sorted(by.items()):
        out.append(_size_line(f"  {m}", size_scores([r for r in rs if r["label"]])))
    return "".join(out)


def main(argv=None) -> None:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--n", type=int, default=36, help="loops (benchmark band proportions; --calibrate: sticky)")
    ap.add_argument("--seed", type=int, default=None, help="benchmark draw seed (default: the config's)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--calibrate", action="store_true",
                    help="choose the size constants on textbook loops (seeds 90000+i) instead")
    ap.add_argument("--json", default="", help="write the per-loop results here")
    ap.add_argument("--op-lag", default="auto", choices=OP_LAG_CHOICES, help="diagnose(op_lag=...)")
    a = ap.parse_args(argv)
    if a.n < 1 or a.jobs < 1:
        ap.error("--n and --jobs must be >= 1")
    t0 = time.perf_counter()
    if a.calibrate:
        rows = run(calibration_loops(a.n), a.jobs, neutral=True, op_lag=op_lag_value(a.op_lag))
        text = json.dumps(calibrate(rows), indent=1) + "\n" + report(rows)
    else:
        rows = run(benchmark_loops(a.n, a.seed), a.jobs, op_lag=op_lag_value(a.op_lag))
        text = report(rows)
    print(text + f"({time.perf_counter() - t0:.0f} s)")
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            json.dump(rows, f, indent=1, default=float)


if __name__ == "__main__":
    main()
