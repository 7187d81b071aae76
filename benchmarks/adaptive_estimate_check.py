"""Where `learned` breaks on the generalisation part: its online stick-band estimate.

Runs the benchmark's generalisation part (PI, default knocker, `learned` at its defaults, the
knocker with the true ``S``) and two diagnostic rows of `learned` that start its estimate
``S_hat`` at each loop's true ``S`` (clipped to the block's ``S0`` range, 0.1-6 % of stroke): one with the
estimate frozen there (``eta`` at its minimum, 0.01) and one with the trained ``eta``, so that the estimate
moves away as it measures. The gap between the default row and the frozen row is what a perfect estimate
of ``S`` would add; these rows use the true ``S``, as the "(S known)" rows do, and are not a block a plant
could run.

    python benchmarks/adaptive_estimate_check.py       # about 45 s on 2 cores
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

FROZEN = "learned, S_hat from the true S (frozen)"
ADAPTS = "learned, S_hat from the true S (adapts)"


class LoopRows:
    """A row of the generalisation part whose block is built per group of loops: ``make(loops, idx, scan_s)``
    (the part's ``for_loops`` hook, so a row may read each loop's settings)."""

    def __init__(self, make):
        self.make = make

    def for_loops(self, loops, idx, scan_s):
        """The block of loops ``idx``."""
        return self.make(loops, idx, scan_s)


def adaptive_row(S_of, frozen: bool) -> LoopRows:
    """``learned`` with its estimate starting at ``S_of(loops, idx)`` (clipped to ``S0``'s range),
    frozen there (``eta`` at its minimum) or adapting at the trained rate."""
    from valve_gym.agents import load_controller

    def make(loops, idx, scan_s):
        kw = {"S0": np.clip(S_of(loops, idx), 0.001, 0.06), **({"eta": 0.01} if frozen else {})}
        return load_controller("learned", Kc=loops.Kc[idx], Ti=loops.Ti[idx], scan_s=scan_s, **kw)
    return LoopRows(make)


def print_rows(res, cfg, labels) -> None:
    """The part's table and comparisons, for the default rows and ``labels``."""
    from valve_gym.agents.bench.generalisation import generalisation_markdown

    keep = ("| controller", "|---", "| PI (SIMC)", "| knocker", "| learned", *(f"| {x}" for x in labels))
    for line in generalisation_markdown(res, cfg).split("Breakdown")[0].splitlines():
        if line.startswith(keep) or (line.startswith("- ") and any(x in line for x in ("learned", *labels))):
            print(line)


def main() -> int:
    from valve_gym.agents.bench.config import BenchConfig
    from valve_gym.agents.bench.generalisation import GenFamily, run_generalisation

    def true_S(loops, idx):
        return loops.S[idx]

    rows = {FROZEN: adaptive_row(true_S, frozen=True), ADAPTS: adaptive_row(true_S, frozen=False)}
    cfg = BenchConfig()
    res = run_generalisation(cfg, GenFamily(), jobs=1, learned=("learned",), policies=rows)
    print_rows(res, cfg, tuple(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
