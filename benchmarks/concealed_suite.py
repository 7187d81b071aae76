"""Concealed-effect suite: does the diagnosis name the effect hidden in a closed-loop recording?

Recordings come from :mod:`valve_gym.diagnosis.synthetic`: a PI level loop
around the simulator, with randomised tank, valve friction, tuning, set points
and measurement noise, and at most ONE optional effect switched on at a
magnitude the loop mostly hides.  Every case is diagnosed with all candidate
effects (``plant='tank'``, ``actuator='valve'``, default rule and holdout) in
parallel worker processes, and the result is compared with the truth.

"Named correctly": for an effect case the first effect named is the true one
(``strict``: it is the only one); for a ``none`` case no effect is named.

Usage::

    python benchmarks/concealed_suite.py [--quick] [--per-effect 6] [--none 12]
        [--samples 1800] [--jobs 2] [--seed 0] [--effort auto] [--search full|fast]
        [--json OUT.json]

Prints markdown tables: the confusion matrix, the accuracy and the fit
improvement.  Case ``i`` uses seed ``seed * 1000 + i``.  The selection rule's
thresholds (information-criterion margin, held-out gain) were set on the cases
of ``--seed 1``; the default ``--seed 0`` scores other recordings.
"""
from __future__ import annotations

import argparse
import sys
import time
from collections import Counter, defaultdict
from concurrent.futures import as_completed

import numpy as np

from valve_gym.diagnosis import diagnose
from valve_gym.diagnosis.cli import OP_LAG_CHOICES, op_lag_value
from valve_gym.diagnosis.model import process_pool
from valve_gym.diagnosis.synthetic import SUITE_EFFECTS, make_case

# truth parameter checked per effect: (truth key, fitted key)
_PARAM = {"dead_time": ("dead_time.theta", "dead_time.theta"),
          "sensor_lag": ("sensor_lag.tau_s", "sensor_lag.tau_s"),
          "overflow": ("overflow.L_max", "overflow.L_max_pv"),
          "slip_jump": ("slip_jump.S", "slip_jump.S"),
          "oscillating_disturbance": ("oscillating_disturbance.period",
                                      "oscillating_disturbance.period"),
          "tank_shape": ("tank_shape.taper", "tank_shape.taper")}


def run_case(args):
    effect, seed, n, effort, search, op_lag = args
    t0 = time.perf_counter()
    case = make_case(effect, seed=seed, n=n)
    res = diagnose(case.recording, plant="tank", actuator="valve", effort=effort, seed=seed, search=search,
                   op_lag=op_lag)
    d = res.to_dict()
    param = None
    if effect in _PARAM and effect in d["effects"]:
        tk, fk = _PARAM[effect]
        fitted = d["final"]["params"].get(fk)
        if effect == "dead_time" and fitted is not None:
            # this generator logs pv[k] after op[k] acted (op lag 0): a chosen lag of 1 is a sample of dead time
            fitted += d["settings"]["op_lag"] * case.recording.dt
        param = (case.truth.get(tk), fitted)
    return {"effect": effect, "seed": seed, "named": d["effects"], "op_lag": d["settings"]["op_lag"],
            "base_rmse": d["base"]["rmse"], "final_rmse": d["final"]["rmse"],
            "base_fit": d["base"]["fit_percent"], "final_fit": d["final"]["fit_percent"],
            "hold_base": d["holdout"]["base_rmse"], "hold_final": d["holdout"]["final_rmse"],
            "stiction": d["stiction"].get("present"), "param": param,
            "candidates": [(c["effect"], c["round"], c["delta_ic"], c["holdout_change"])
                           for c in d["candidates"]],
            "seconds": time.perf_counter() - t0}


def main(argv=None):
    a = _parse_args(argv)
    tasks = []
    i = 0
    for e in ("none",) + SUITE_EFFECTS:
        for _ in range(a.none if e == "none" else a.per_effect):
            tasks.append((e, a.seed * 1000 + i, a.samples, a.effort, a.search,
                          op_lag_value(a.op_lag)))
            i += 1
    t0 = time.perf_counter()
    out = _run_all(tasks, a.jobs)
    elapsed = time.perf_counter() - t0
    out.sort(key=lambda r: (r["effect"], r["seed"]))
    _print_confusion(out, a)
    _print_fit_table(out)
    secs = [r["seconds"] for r in out]
    print(f"\n{len(out)} diagnoses (search {a.search}, op lag {a.op_lag}) in {elapsed:.0f} s with {a.jobs} workers "
          f"(median {np.median(secs):.1f} s per recording, kernel threads shared out between the workers).\n")
    if a.op_lag == "auto":
        lag1 = Counter(r["effect"] for r in out if r["op_lag"] == 1)
        print("OP paired with the next PV (op lag 1) by the automatic test: "
              + (", ".join(f"{e} {k}" for e, k in sorted(lag1.items())) or "none") + " (this generator: 0).\n")
    if a.json:
        from valve_gym.diagnosis.report import write_json
        write_json({"cases": out, "settings": vars(a)}, a.json)
    return 0


def _parse_args(argv):
    """Command-line options (``--quick`` sets the case counts and the record length)."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="3 cases per effect, 6 none cases, 900 samples")
    ap.add_argument("--per-effect", type=int, default=6)
    ap.add_argument("--none", type=int, default=12)
    ap.add_argument("--samples", type=int, default=1800)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--effort", default="auto", choices=("auto", "fast", "normal", "thorough"))
    ap.add_argument("--search", default="full", choices=("fast", "full"),
                    help="search of the diagnosis (diagnose(search=...)): 'full' (default) or the opt-in 'fast'")
    ap.add_argument("--op-lag", default="auto", choices=OP_LAG_CHOICES,
                    help="diagnose(op_lag=...): how the recordings pair OP and PV (this generator: 0)")
    ap.add_argument("--json", help="write every case's outcome as JSON")
    a = ap.parse_args(argv)
    if a.quick:
        a.per_effect, a.none, a.samples = 3, 6, 900
    return a


def _run_all(tasks, jobs: int) -> list[dict]:
    """Outcomes of :func:`run_case` for ``tasks`` in ``jobs`` worker processes (order of completion)."""
    out = []
    with process_pool(jobs) as ex:
        futs = [ex.submit(run_case, t) for t in tasks]
        for k, fu in enumerate(as_completed(futs), 1):
            r = fu.result()
            out.append(r)
            print(f"[{k}/{len(tasks)}] {r['effect']} seed {r['seed']}: named "
                  f"{','.join(r['named']) or 'none'} ({r['seconds']:.1f} s)", file=sys.stderr,
                  flush=True)
    return out


def _print_confusion(out: list[dict], a) -> None:
    """Confusion matrix (truth vs first effect named) and the accuracy."""
    labels = ("none",) + SUITE_EFFECTS
    cols = labels + ("other",)
    conf = defaultdict(Counter)
    right = strict = 0
    none_ok = n_none = 0
    for r in out:
        first = r["named"][0] if r["named"] else "none"
        conf[r["effect"]][first if first in labels else "other"] += 1
        if r["effect"] == "none":
            n_none += 1
            none_ok += not r["named"]
        else:
            right += first == r["effect"]
            strict += r["named"] == [r["effect"]]
    n_eff = len(out) - n_none
    print(f"## Concealed-effect suite ({len(out)} recordings of {a.samples} samples, "
          f"dt = 1 s; {a.per_effect} per effect, {a.none} without effect)\n")
    print("Rows: the effect hidden in the recording; columns: the first effect named.\n")
    short = {"none": "none", "slip_jump": "slip", "valve_characteristic": "char",
             "dead_time": "dead", "overflow": "overfl", "leak": "leak", "sensor_lag": "s.lag",
             "oscillating_disturbance": "osc", "tank_shape": "shape", "other": "other"}
    print("| truth \\ named | " + " | ".join(short[c] for c in cols) + " |")
    print("|---|" + "---|" * len(cols))
    for lab in labels:
        print(f"| {lab} | " + " | ".join(str(conf[lab][c]) for c in cols) + " |")
    print(f"\nEffect cases named correctly (first effect named): {right}/{n_eff} = "
          f"{100 * right / max(n_eff, 1):.0f} %; the true effect alone: {strict}/{n_eff} = "
          f"{100 * strict / max(n_eff, 1):.0f} %.  No effect claimed on {none_ok}/{n_none} = "
          f"{100 * none_ok / max(n_none, 1):.0f} % of the 'none' cases.  All cases right "
          f"(first named, or none for none): {right + none_ok}/{len(out)} = "
          f"{100 * (right + none_ok) / len(out):.0f} %.\n")


def _print_fit_table(out: list[dict]) -> None:
    """Median fit before and after, and the error of the fitted effect parameter, per effect."""
    labels = ("none",) + SUITE_EFFECTS
    print("| effect | median RMSE base | median RMSE final | median held-out RMSE base -> final | "
          "median fit % base -> final | true vs fitted parameter (median abs. rel. error) |")
    print("|---|---|---|---|---|---|")
    for lab in labels:
        rs = [r for r in out if r["effect"] == lab]
        if not rs:
            continue
        med = lambda k: float(np.median([r[k] for r in rs if r[k] is not None]))  # noqa: E731
        pe = [abs(p[1] - p[0]) / abs(p[0]) for p in (r["param"] for r in rs)
              if p and p[0] and p[1] is not None]
        pk = _PARAM.get(lab, ("", ""))[0]
        ptxt = f"{pk}: {100 * np.median(pe):.0f} % (n = {len(pe)})" if pe else "–"
        print(f"| {lab} | {med('base_rmse'):.4f} | {med('final_rmse'):.4f} | "
              f"{med('hold_base'):.4f} -> {med('hold_final'):.4f} | "
              f"{med('base_fit'):.1f} -> {med('final_fit'):.1f} | {ptxt} |")


if __name__ == "__main__":
    sys.exit(main())
