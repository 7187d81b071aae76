"""Speed of the compensator benchmark's runs against the bare plant, in one run.

Measures, on the regulation loops of the shipped configuration (135 loops, 3600 scans each):

(a) the plant alone: the batched :class:`valve_gym.plant.Plant` of each friction model stepped with the
    steady input held (the reference: what the physics costs);
(b) :func:`valve_gym.agents.bench.runner.run_loops` with the SIMC PI (plant + one block over all loops per scan);
(c) the same with the knocker at the loops' stiction estimates, and with the learned block;
(d) scoring one run (:func:`valve_gym.agents.bench.scores.score_runs`: the ACF detector per loop, travel, reversals).

Loop-scans/s and the ratio to (a); best of ``--repeat`` after a warm-up; CPU time of this process. Prints a
markdown table.

Usage::

    python benchmarks/bench_benchmark.py [--loops N] [--repeat R]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from valve_gym.agents import load_controller
from valve_gym.agents.bench.config import BenchConfig
from valve_gym.agents.bench.runner import ControllerSpec, make_controller, make_plant, run_loops, valve_model
from valve_gym.agents.bench.scenarios import regulation_scenarios
from valve_gym.agents.bench.scores import score_runs


def _plant_only(sc) -> None:
    for model in dict.fromkeys(sc.model.tolist()):
        idx = np.flatnonzero(sc.model == model)
        p = make_plant(valve_model(model, sc.S[idx], sc.J[idx]), idx.size, sc.scan_s)
        u = p.reset(level=sc.sp[0, idx]).op
        for k in range(sc.n_steps):
            p.step(u, sc.load[k, idx])


def _best(fn, repeat: int) -> float:
    fn()  # warm-up (numba compilation, imports)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def main(argv=None) -> int:
    """Print the table; 0 on success."""
    ap = argparse.ArgumentParser(description="Speed of the benchmark runs against the bare plant.")
    ap.add_argument("--loops", type=int, default=None, help="loops (default: the configured 135)")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args(argv)
    cfg = BenchConfig()
    sc = regulation_scenarios(cfg, n=a.loops)
    knock = ControllerSpec("knocker", "knocker", "compensator", estimate=1.0)
    runs = run_loops(load_controller("pi"), sc)
    rows = [("plant alone (reference)", lambda: _plant_only(sc)),
            ("run_loops, SIMC PI", lambda: run_loops(load_controller("pi"), sc)),
            ("run_loops, knocker (per-loop S)", lambda: run_loops(make_controller(knock, sc), sc)),
            ("run_loops, learned", lambda: run_loops(load_controller("learned"), sc)),
            ("score_runs (one controller)", lambda: score_runs(runs, cfg))]
    scans = sc.n * sc.n_steps
    ref = None
    print(f"{sc.n} loops x {sc.n_steps} scans, CPU seconds (best of {a.repeat})\n")
    print("| step | CPU [s] | loop-scans/s | ratio to the plant alone |")
    print("|---|---|---|---|")
    for name, fn in rows:
        t = _best(fn, a.repeat)
        ref = t if ref is None else ref
        print(f"| {name} | {t:.2f} | {scans / t:,.0f} | {t / ref:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
