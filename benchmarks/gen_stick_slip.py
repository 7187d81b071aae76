"""Does the PI stick-slip on the generalisation part's sticky valves, and what does the limit-cycle rule see?

The benchmark's limit-cycle share counts *regular* oscillations (Thornhill's regularity > 1, weakly damped,
significant ACF lobes, :mod:`valve_gym.oscillation`, rule ``"benchmark"``). This script runs the SIMC PI
on every sticky and severe loop of the generalisation part and counts, from the simulated stem, the loops
whose valve still stick-slips in the second half of the record (at least ``--min-slips`` separate slip
episodes: runs of scans where the stem moves by more than 1e-4 of stroke), beside the rule's reading of
each loop's measured error (a regular cycle, or why not).

    python benchmarks/gen_stick_slip.py                 # 40 loops, 40 min each; about 10 s
    python benchmarks/gen_stick_slip.py --duration 3600 # the same loops, one hour
"""
from __future__ import annotations

import argparse
import collections
import re
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def slip_episodes(stem: np.ndarray, eps: float = 1e-4) -> int:
    """Number of separate runs of scans in which the stem moves by more than ``eps``."""
    moving = np.abs(np.diff(stem)) > eps
    return int(np.sum(moving[1:] & ~moving[:-1]) + bool(moving[0])) if moving.size else 0


def main(argv=None) -> int:
    from valve_gym.agents.bench.generalisation import GenFamily, GenSpec, _run_group, gen_loops
    from valve_gym.oscillation import detect_oscillation

    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--duration", type=float, default=None, help="record length [s] (default: the part's)")
    p.add_argument("--min-slips", type=int, default=4, help="slip episodes in the second half that count")
    a = p.parse_args(argv)
    fam = GenFamily() if a.duration is None else replace(GenFamily(), duration_s=a.duration)
    loops = gen_loops(fam)
    spec = GenSpec("PI (SIMC)", "pi", "pi")
    slipping, regular, n = 0, 0, 0
    why: collections.Counter = collections.Counter()
    for scan in np.unique(loops.scan_s):
        idx = np.flatnonzero(loops.scan_s == scan)
        run = _run_group(spec, loops, idx, float(scan))
        for j, i in enumerate(idx):
            if loops.band[i] == "healthy":
                continue
            n += 1
            stem = run.stem[:, j]
            slipping += slip_episodes(stem[stem.size // 2:]) >= a.min_slips
            osc = detect_oscillation((run.sp - run.pv)[:, j], float(scan), "benchmark")
            regular += bool(osc.present)
            if not osc.present:
                why[re.sub(r" \d+ times.*", " too few times", re.sub(r" \(.*|: .*", "", osc.reason))] += 1
    print(f"generalisation part, PI (SIMC), {n} sticky + severe loops, {fam.duration_s:g} s each")
    print(f"  stem still stick-slips in the second half (>= {a.min_slips} slip episodes): {slipping} of {n}")
    print(f"  regular limit cycle by the benchmark's rule: {regular} of {n}")
    for k, v in why.most_common():
        print(f"    not regular, {v:2d} loops: {k}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
