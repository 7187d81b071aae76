"""Stiction verdict and size from a recorded valve position (the stem test), against the verdict without it.

Where a loop's historian also logs the valve's position (``mv``), the diagnosis reads the stem
against the controller output (:mod:`valve_gym.diagnosis.stiction.stem`) instead of inferring
friction through the process.  This script measures that reading:

* **textbook loops** (:mod:`valve_gym.diagnosis.stiction.loops`, the independently written
  simulator: FOPTD, integrating and tank processes, Choudhury, Kano or force-balance friction with
  S 0.5-10 % of the stroke, healthy valves with external oscillating loads or aggressive tuning;
  cycling or not), each stem read through a position transmitter with noise (0.02-0.3 % of the
  stroke, log-uniform), an offset (+-2 %) and a span error (+-5 %): the stem test's own verdict
  (sensitivity, specificity) and whether the true S and J lie inside the 90 % intervals.  Seeds
  ``160_000`` on; no other script draws them.
* **positions that never move**: the sticky textbook loops above whose stem stays put (a seized
  valve) and the healthy ones with the position signal frozen at its median (a transmitter that
  stopped updating), through ``diagnose``: the public verdict, and how often the process model
  calls the valve seized (``verdict_source`` ``'stem+model'``).
* **the compensator benchmark's regulation loops** (``--bench-n``; the package's simulator under
  its SIMC PI and drifting load, Riihilahti, Choudhury and Kano friction), the public verdict
  ``stiction.present`` of ``diagnose(rec, plant='tank', candidates=())`` with and without the
  stem (with the same transmitter).

``--calibrate`` prints instead the 90 % quantile of the stem test's relative S and J errors
(``|log(estimate / true)|``) on sticky textbook loops of seeds ``150_000`` on (used by no score),
the model-discrepancy factors :data:`valve_gym.diagnosis.stiction.stem.DISCREPANCY_S` and
``DISCREPANCY_J`` widen the profile intervals by.

Usage::

    nice -n 10 python benchmarks/stem_verdict.py [--n 60] [--bench-n 36] [--jobs 2] [--calibrate] [--seed-score 160000]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from validate_stiction import PLANT_OF  # noqa: E402

from valve_gym.diagnosis import Recording, diagnose  # noqa: E402
from valve_gym.diagnosis.model import process_pool  # noqa: E402
from valve_gym.diagnosis.stiction.loops import random_spec, simulate_loop  # noqa: E402
from valve_gym.diagnosis.stiction.stem import stem_evidence  # noqa: E402

SEED_SCORE = 160_000
SEED_CAL = 150_000


def transmitter(x: np.ndarray, rng) -> np.ndarray:
    """The stem ``x`` (0..1) as a position transmitter reads it: noise, offset, span error, 0..1."""
    sd = float(np.exp(rng.uniform(np.log(2e-4), np.log(3e-3))))
    y = rng.uniform(-0.02, 0.02) + rng.uniform(0.95, 1.05) * x + rng.normal(0.0, sd, len(x))
    return np.clip(y, 0.0, 1.0)


def textbook(i: int, sticky: bool, seed0: int) -> tuple[dict, Recording]:
    """Textbook loop ``i`` with its stem read by a transmitter."""
    seed = seed0 + 2 * i + int(sticky)
    rng = np.random.default_rng(seed)
    spec = random_spec(rng, sticky, n=1800)
    rec = simulate_loop(spec, seed=seed, name=f"{'sticky' if sticky else 'healthy'}_{i}", stem=True)
    assert rec.mv is not None
    rec = replace(rec, mv=transmitter(rec.mv, rng))
    return {"S": spec.S, "J": spec.J, "valve": spec.valve, "process": spec.process, "label": int(sticky)}, rec


def read_stem(args) -> dict:
    i, sticky, seed0 = args
    truth, rec = textbook(i, sticky, seed0)
    e = stem_evidence(rec.op, rec.mv, float(rec.dt or 1.0))
    return {**truth, "verdict": e.verdict, "applicable": e.applicable, **{k: e.details.get(k, np.nan)
            for k in ("S_lo", "S_hi", "J_lo", "J_hi")}, "S_est": e.details.get("S", np.nan),
            "J_est": e.details.get("J", np.nan), "reason": e.reason}


def calibrate(n: int, jobs: int) -> None:
    with process_pool(jobs) as ex:
        rows = list(ex.map(read_stem, [(i, True, SEED_CAL) for i in range(n)]))
    ok = [r for r in rows if r["verdict"] == "stiction"]
    eS = np.abs(np.log([r["S_est"] / r["S"] for r in ok]))
    eJ = np.abs(np.log([max(r["J_est"], 1e-4) / r["J"] for r in ok]))
    print(f"{len(ok)} of {n} sticky calibration loops called stiction; 90 % quantile of |log(S_est/S)| "
          f"{np.quantile(eS, 0.9):.3f}, of |log(J_est/J)| {np.quantile(eJ, 0.9):.3f} "
          f"(median {np.median(eS):.3f} / {np.median(eJ):.3f})")


def score_textbook(n: int, jobs: int) -> None:
    tasks = [(i, True, SEED_SCORE) for i in range(n)] + [(i, False, SEED_SCORE) for i in range(n // 2)]
    t0 = time.perf_counter()
    with process_pool(jobs) as ex:
        rows = list(ex.map(read_stem, tasks))
    sticky = [r for r in rows if r["label"]]
    healthy = [r for r in rows if not r["label"]]
    tp = sum(r["verdict"] == "stiction" for r in sticky)
    tn = sum(r["verdict"] == "no stiction" for r in healthy)
    print(f"## Textbook loops, stem test alone ({len(rows)} loops, {time.perf_counter() - t0:.0f} s)\n")
    print("| friction model | sticky loops | called stiction | S inside interval | J inside interval | "
          "median S error | median J error |\n|---|---|---|---|---|---|---|")
    for v in sorted({r["valve"] for r in sticky}):
        rs = [r for r in sticky if r["valve"] == v]
        called = [r for r in rs if r["verdict"] == "stiction"]
        sin = sum(r["S_lo"] <= r["S"] <= r["S_hi"] for r in called)
        jin = sum(r["J_lo"] <= r["J"] <= r["J_hi"] for r in called)
        es = np.median([abs(r["S_est"] / r["S"] - 1) for r in called]) if called else np.nan
        ej = np.median([abs(r["J_est"] / r["J"] - 1) for r in called]) if called else np.nan
        print(f"| {v} | {len(rs)} | {len(called)} | {sin} of {len(called)} | {jin} of {len(called)} | "
              f"{100 * es:.0f} % | {100 * ej:.0f} % |")
    missed = [r for r in sticky if r["verdict"] != "stiction"]
    print(f"\nSticky called: **{tp} of {len(sticky)}**; healthy cleared: **{tn} of {len(healthy)}** "
          f"(balanced accuracy {50 * (tp / len(sticky) + tn / len(healthy)):.0f} %).")
    for r in missed:
        print(f"- missed: {r['valve']} S = {100 * r['S']:.2g} %, {r['process']}: {r['verdict']}, {r['reason']}")
    for r in healthy:
        if r["verdict"] != "no stiction":
            print(f"- healthy not cleared: {r['process']}: {r['verdict']}, {r['reason']}")


def frozen_task(args) -> dict | None:
    """Textbook loop ``i``: a sticky one whose stem never moves, or a healthy one with a frozen position signal."""
    i, sticky = args
    truth, rec = textbook(i, sticky, SEED_SCORE)
    assert rec.mv is not None
    if sticky:
        if stem_evidence(rec.op, rec.mv, float(rec.dt or 1.0)).details.get("frozen") != 1.0:
            return None
    else:           # the transmitter stops updating: its last value, with its noise
        rng = np.random.default_rng(SEED_SCORE + 7 + i)
        rec = replace(rec, mv=np.clip(np.median(rec.mv) + rng.normal(0.0, 3e-4, len(rec.mv)), 0.0, 1.0))
    s = diagnose(rec, plant=PLANT_OF[truth["process"]], candidates=(), effort="fast").stiction
    return {"label": int(sticky), "present": bool(s["present"]), "source": s["verdict_source"]}


def score_frozen(n: int, jobs: int) -> None:
    t0 = time.perf_counter()
    with process_pool(jobs) as ex:
        rows = [r for r in ex.map(frozen_task, [(i, True) for i in range(n)] + [(i, False) for i in range(n // 2)])
                if r is not None]
    st = [r for r in rows if r["label"]]
    he = [r for r in rows if not r["label"]]
    print(f"\n## Positions that never move: seized valve or frozen signal (public verdict, "
          f"{time.perf_counter() - t0:.0f} s)\n")
    print(f"- sticky textbook loops whose stem never moves: **{sum(r['present'] for r in st)} of {len(st)}** "
          f"called ({sum(r['source'] == 'stem+model' for r in st)} as seized by the position and the process "
          f"model together)")
    print(f"- healthy textbook loops with a frozen position signal: **{sum(not r['present'] for r in he)} of "
          f"{len(he)}** cleared ({sum(r['source'] == 'stem+model' for r in he)} wrongly called seized)")


def bench_task(args) -> dict:
    loop, with_stem = args
    mv = loop["mv"] if with_stem else None
    rec = Recording(t=loop["t"], op=loop["op"], pv=loop["pv"], sp=loop["sp"], mv=mv, dt=loop["dt"],
                    name=loop["name"])
    s = diagnose(rec, plant="tank", candidates=(), effort="fast").stiction
    return {"name": loop["name"], "label": loop["label"], "with_stem": with_stem, "present": bool(s["present"]),
            "source": s.get("verdict_source"), "S": s["S"], "S_interval": s["S_interval"], "S_true": loop["S_true"]}


def bench_loops(n: int) -> list[dict]:
    """The benchmark's regulation loops under its SIMC PI, with each stem read by a transmitter."""
    from sizes_on_benchmark_loops import benchmark_loops

    rng = np.random.default_rng(SEED_SCORE - 1)
    return [{**lp, "mv": transmitter(np.clip(lp["stem"], 0.0, 1.0), rng)} for lp in benchmark_loops(n, None)]


def score_bench(n: int, jobs: int) -> None:
    loops = bench_loops(n)
    t0 = time.perf_counter()
    with process_pool(jobs) as ex:
        rows = list(ex.map(bench_task, [(lp, w) for w in (False, True) for lp in loops]))
    print(f"\n## Benchmark regulation loops, public verdict ({len(loops)} loops, {time.perf_counter() - t0:.0f} s)\n")
    print("| recorded | sticky called | healthy cleared | true S inside `S_interval` (called) |\n|---|---|---|---|")
    for w in (False, True):
        rs = [r for r in rows if r["with_stem"] == w]
        st = [r for r in rs if r["label"]]
        he = [r for r in rs if not r["label"]]
        called = [r for r in st if r["present"]]
        cov = sum(r["S_interval"][0] is not None and r["S_interval"][0] <= r["S_true"] <= r["S_interval"][1]
                  for r in called)
        print(f"| {'OP, PV and the valve position' if w else 'OP and PV'} | {len(called)} of {len(st)} | "
              f"{sum(not r['present'] for r in he)} of {len(he)} | {cov} of {len(called)} |")


def main(argv=None) -> int:
    global SEED_SCORE
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--n", type=int, default=60, help="sticky textbook loops (and half as many healthy)")
    ap.add_argument("--bench-n", type=int, default=36, help="benchmark regulation loops (0: skip)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--calibrate", action="store_true")
    ap.add_argument("--seed-score", type=int, default=SEED_SCORE,
                    help="first seed of the scored textbook loops (another value: a fresh draw)")
    a = ap.parse_args(argv)
    SEED_SCORE = a.seed_score
    if a.n < 2 or a.bench_n < 0:
        raise SystemExit("--n must be at least 2 and --bench-n at least 0")
    if a.calibrate:
        calibrate(a.n, a.jobs)
        return 0
    score_textbook(a.n, a.jobs)
    score_frozen(a.n, a.jobs)
    if a.bench_n:
        score_bench(a.bench_n, a.jobs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
