"""Where `learned_adaptive` breaks on the generalisation part: its online stick-band estimate.

Runs the benchmark's generalisation part (PI, default knocker, `learned_adaptive` at its defaults, the
knocker with the true ``S``) and two diagnostic rows of `learned_adaptive` that start its estimate
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

FROZEN = "learned_adaptive, S_hat from the true S (frozen)"
ADAPTS = "learned_adaptive, S_hat from the true S (adapts)"


def main() -> int:
    import valve_gym.agents.bench.generalisation as gen
    from valve_gym.agents import load_controller
    from valve_gym.agents.bench.config import BenchConfig

    base_controller, base_lineup = gen._controller, gen.gen_lineup

    def controller(spec, loops, idx, scan_s):
        if spec.label in (FROZEN, ADAPTS):
            kw = {"S0": np.clip(loops.S[idx], 0.001, 0.06)}
            if spec.label == FROZEN:
                kw["eta"] = 0.01
            return load_controller("learned_adaptive", Kc=loops.Kc[idx], Ti=loops.Ti[idx], scan_s=scan_s, **kw)
        return base_controller(spec, loops, idx, scan_s)

    def lineup(config, learned=("learned",)):
        return base_lineup(config, learned) + (gen.GenSpec(FROZEN, "learned_adaptive", "learned"),
                                               gen.GenSpec(ADAPTS, "learned_adaptive", "learned"))

    gen._controller, gen.gen_lineup = controller, lineup      # this process only (jobs=1)
    cfg = BenchConfig()
    res = gen.run_generalisation(cfg, gen.GenFamily(), jobs=1, learned=("learned_adaptive",))
    keep = ("| controller", "|---", "| PI (SIMC)", "| knocker |", "| knocker (S known)", "| learned_adaptive")
    for line in gen.generalisation_markdown(res, cfg).split("Breakdown")[0].splitlines():
        if line.startswith(keep) or (line.startswith("- ") and "learned_adaptive" in line):
            print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
