"""The compensators on the generalisation part with the stiction size a plant would have: valve_gym's diagnosis.

The generalisation part runs every block at its defaults (no stiction estimate) and, apart, with the loop's
true ``S`` ("S known"). A plant has neither: it records the loop under its PI and diagnoses it. This script
does that for every loop of the part: one record of the SIMC PI's run (SP, PV, OP; the part's 40 minutes,
noise and load), :func:`valve_gym.diagnosis.diagnose` with the process kind an engineer knows from the tag
(``tank``, ``integrating``, ``first_order``), then the knocker and ``learned`` given the diagnosed
``S`` where the verdict is stiction (and nothing, i.e. the smallest estimate, where it is not).

    python benchmarks/diagnosed_s_check.py [--jobs 2]       # about 3 min on 2 cores
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for _p in (ROOT, ROOT / "benchmarks"):            # this checkout's package, and the sibling scripts' helpers
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

KIND = {"tank": "tank", "integrating": "integrating", "fopdt": "first_order"}
ROWS = ("knocker (S diagnosed)", "learned (S diagnosed, frozen)", "learned (S diagnosed, adapts)")


def main(argv=None) -> int:
    from multiprocessing import get_context

    from adaptive_estimate_check import LoopRows, adaptive_row, print_rows
    from learned_unseen_check import diagnosed_band

    import valve_gym.agents.bench.generalisation as gen
    from valve_gym.agents import load_controller
    from valve_gym.agents.bench.config import BenchConfig
    from valve_gym.agents.bench.runner import ESTIMATE_MIN

    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--jobs", type=int, default=2)
    a = p.parse_args(argv)
    loops = gen.gen_loops(gen.GenFamily())
    tasks = []
    for scan in np.unique(loops.scan_s):
        idx = np.flatnonzero(loops.scan_s == scan)
        run = gen._run_group(gen.GenSpec("PI (SIMC)", "pi", "pi"), loops, idx, float(scan))
        t = np.arange(run.pv.shape[0]) * float(scan)
        for j, i in enumerate(idx):
            tasks.append((t, np.clip(run.op[:, j], 0.0, 1.0), run.pv[:, j], run.sp[:, j], KIND[str(loops.process[i])]))
    order = [int(i) for scan in np.unique(loops.scan_s) for i in np.flatnonzero(loops.scan_s == scan)]
    with get_context("fork").Pool(max(1, a.jobs)) as pool:
        found = pool.map(diagnosed_band, tasks)
    called, S_hat = np.zeros(loops.n, bool), np.zeros(loops.n)
    for i, (c, S) in zip(order, found):
        called[i], S_hat[i] = c, S
    sticky = loops.band != "healthy"
    ok = called & sticky & (S_hat > 0)
    err = np.abs(S_hat[ok] / loops.S[ok] - 1.0)
    print(f"diagnosis of the PI's records: stiction called on {int((called & sticky).sum())} of {int(sticky.sum())} "
          f"sticky + severe loops and on {int((called & ~sticky).sum())} of {int((~sticky).sum())} healthy ones; "
          f"median |S_est / S - 1| = {np.median(err):.2f} over the {int(ok.sum())} called sticky loops")
    S_est = np.maximum(S_hat, ESTIMATE_MIN)

    def diagnosed(loops, idx):
        return S_est[idx]

    rows = {ROWS[0]: LoopRows(lambda lp, idx, scan_s: load_controller("knocker", Kc=lp.Kc[idx], Ti=lp.Ti[idx],
                                                                      scan_s=scan_s, S=S_est[idx])),
            ROWS[1]: adaptive_row(diagnosed, frozen=True), ROWS[2]: adaptive_row(diagnosed, frozen=False)}
    cfg = BenchConfig()
    res = gen.run_generalisation(cfg, gen.GenFamily(), jobs=1, learned=("learned",), policies=rows)
    print_rows(res, cfg, ROWS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
