"""The compensators on the generalisation part with the stiction size a plant would have: valve_gym's diagnosis.

The generalisation part runs every block at its defaults (no stiction estimate) and, apart, with the loop's
true ``S`` ("S known"). A plant has neither: it records the loop under its PI and diagnoses it. This script
does that for every loop of the part: one record of the SIMC PI's run (SP, PV, OP; the part's 40 minutes,
noise and load), :func:`valve_gym.diagnosis.diagnose` with the process kind an engineer knows from the tag
(``tank``, ``integrating``, ``first_order``), then the knocker and ``learned_adaptive`` given the diagnosed
``S`` where the verdict is stiction (and nothing, i.e. the smallest estimate, where it is not).

    python benchmarks/diagnosed_s_check.py [--jobs 2]       # about 3 min on 2 cores
"""
from __future__ import annotations

import argparse
import sys
from multiprocessing import get_context
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

KIND = {"tank": "tank", "integrating": "integrating", "fopdt": "first_order"}
S_EST: dict = {}
ROWS = ("knocker (S diagnosed)", "learned_adaptive (S diagnosed, frozen)", "learned_adaptive (S diagnosed, adapts)")


def _diagnose(args) -> tuple[int, bool, float]:
    i, t, op, pv, sp, kind = args
    from valve_gym.diagnosis import diagnose
    from valve_gym.diagnosis.recording import Recording

    rec = Recording(t=t, op=op, pv=pv, sp=sp, name=f"gen{i}")
    res = diagnose(rec, plant=kind, candidates=(), effort="fast")
    v = res.stiction
    S = float(v["S"]) if v["present"] and v["S"] is not None and np.isfinite(v["S"]) else 0.0
    return i, bool(v["present"]), S


def main(argv=None) -> int:
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
            tasks.append((int(i), t, np.clip(run.op[:, j], 0.0, 1.0), run.pv[:, j], run.sp[:, j],
                          KIND[str(loops.process[i])]))
    with get_context("fork").Pool(max(1, a.jobs)) as pool:
        found = sorted(pool.imap_unordered(_diagnose, tasks))
    called = np.array([f[1] for f in found])
    S_hat = np.array([f[2] for f in found])
    S_EST["S"] = np.maximum(S_hat, ESTIMATE_MIN)
    sticky = loops.band != "healthy"
    ok = called & sticky & (S_hat > 0)
    err = np.abs(S_hat[ok] / loops.S[ok] - 1.0)
    print(f"diagnosis of the PI's records: stiction called on {int((called & sticky).sum())} of {int(sticky.sum())} "
          f"sticky + severe loops and on {int((called & ~sticky).sum())} of {int((~sticky).sum())} healthy ones; "
          f"median |S_est / S - 1| = {np.median(err):.2f} over the {int(ok.sum())} called sticky loops")

    base_controller, base_lineup = gen._controller, gen.gen_lineup

    def controller(spec, lp, idx, scan_s):
        S = S_EST["S"][idx]
        if spec.label == ROWS[0]:
            return load_controller("knocker", Kc=lp.Kc[idx], Ti=lp.Ti[idx], scan_s=scan_s, S=S)
        if spec.label in ROWS[1:]:
            kw = {"S0": np.clip(S, 0.001, 0.06)}
            if "frozen" in spec.label:
                kw["eta"] = 0.01
            return load_controller("learned_adaptive", Kc=lp.Kc[idx], Ti=lp.Ti[idx], scan_s=scan_s, **kw)
        return base_controller(spec, lp, idx, scan_s)

    def lineup(config, learned=("learned",)):
        return base_lineup(config, learned) + tuple(gen.GenSpec(r, "knocker", "learned") for r in ROWS)

    gen._controller, gen.gen_lineup = controller, lineup      # this process only (jobs=1 below)
    cfg = BenchConfig()
    res = gen.run_generalisation(cfg, gen.GenFamily(), jobs=1, learned=("learned_adaptive",))
    keep = ("| controller", "|---", "| PI (SIMC)", "| knocker", "| learned_adaptive")
    for line in gen.generalisation_markdown(res, cfg).split("Breakdown")[0].splitlines():
        if line.startswith(keep) or (line.startswith("- ") and ("diagnosed" in line or "learned_adaptive:" in line)):
            print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
