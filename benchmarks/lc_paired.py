"""Limit cycles of the learned block against the SIMC PI, loop by loop, from a benchmark's loops.csv.

The headline's "LC amplitude" is a median over the loops that cycle, so a controller that stops the
small cycles and leaves only the severe valves cycling shows a *larger* median. This script reads the
per-loop file and prints the paired view: on the loops where the learned block still cycles, the PI's
amplitude on the same loops, and the mean amplitude per loop counting a loop without a cycle as 0.

    valve-gym benchmark --out results && python benchmarks/lc_paired.py results/loops.csv
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("loops_csv", help="loops.csv written by valve-gym benchmark")
    p.add_argument("--controller", default="learned")
    p.add_argument("--reference", default="PI (SIMC)")
    a = p.parse_args(argv)
    d = pd.read_csv(a.loops_csv)
    r = d[(d.part == "regulation") & d.band.isin(["sticky", "severe"])]
    names = set(r.controller)
    for c in (a.controller, a.reference):
        if c not in names:
            print(f"lc_paired: controller {c!r} not in {a.loops_csv}; there are: {sorted(names)}", file=sys.stderr)
            return 2
    c, ref = (r[r.controller == n].set_index("loop").sort_index() for n in (a.controller, a.reference))
    cyc = c.index[c.lc_present == 1]
    print(f"{a.controller}: cycles on {len(cyc)} of {len(c)} sticky + severe loops "
          f"(S = {', '.join(f'{100 * s:.1f}' for s in c.loc[cyc, 'S'])} % of stroke)")
    smaller = int(np.sum(c.loc[cyc, "lc_amplitude_m"].values < ref.loc[cyc, "lc_amplitude_m"].values))
    both = int(np.sum(ref.loc[cyc, "lc_present"].values == 1))
    print(f"on those loops {a.reference} cycles on {both}; {a.controller}'s cycle is smaller on {smaller}")
    for name, x in ((a.reference, ref), (a.controller, c)):
        amp = np.where(x.lc_present == 1, x.lc_amplitude_m, 0.0) * 1000.0
        print(f"{name}: LC share {x.lc_present.mean():.3f}, mean amplitude per loop (0 without a cycle) "
              f"{amp.mean():.2f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
