"""Cost of one scan of each controller block, this checkout against another revision in the same run.

Each block is built by ``load_controller`` with the SIMC defaults (the compensators with ``S`` = 0.02), reset,
and stepped ``--steps`` scans with a measurement that wanders around the set point, for one loop (scalars in,
scalars out) and for ``--n`` loops (arrays). Every measurement runs in a fresh subprocess. The revisions take
turns (``--repeats`` rounds), so that both see the same machine load. The table gives the time per scan (the
fastest of the rounds: the machine's load only ever adds time) and the ratio now / before. Use it to check
what a change to the blocks' common path costs (the ``action`` sign, for example: ``--before 6fa8e8a``, the
revision before it).

    python benchmarks/bench_block_step.py --before REV [--steps 5000] [--n 100] [--repeats 7]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_diagnosis import _export  # noqa: E402

NAMES = ("pi", "knocker", "constant_reinforcement", "two_move", "integral_freeze", "learned")

#: One measurement, in a subprocess whose sys.path starts with the package's folder: JSON {name: [us_1, us_n]}.
_SCRIPT = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
import valve_gym
from valve_gym.agents import load_controller
steps, n = int(sys.argv[2]), int(sys.argv[3])
out = {"module": valve_gym.__file__}
pv = 1.0 + 0.01 * np.sin(np.arange(steps + 50) / 30.0)
for name in sys.argv[4].split(","):
    kw = {} if name in ("pi", "learned") else {"S": 0.02}
    row = []
    for loops in (1, n):
        blk = load_controller(name, **kw)
        sp = 1.0 if loops == 1 else np.ones(loops)
        blk.reset(sp, sp, 0.5 if loops == 1 else np.full(loops, 0.5))
        p = pv if loops == 1 else np.repeat(pv[:, None], loops, axis=1)
        for k in range(50):
            blk.step(sp, p[k])
        t0 = time.perf_counter()
        for k in range(50, 50 + steps):
            blk.step(sp, p[k])
        row.append(1e6 * (time.perf_counter() - t0) / steps)
    out[name] = row
print(json.dumps(out))
"""


def _measure(tree: str, steps: int, n: int) -> dict:
    res = subprocess.run([sys.executable, "-c", _SCRIPT, tree, str(steps), str(n), ",".join(NAMES)],
                         capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"the measurement on {tree} failed:\n{res.stderr[-2000:]}")
    out = json.loads(res.stdout.strip().splitlines()[-1])
    if not out.pop("module").startswith(tree):
        raise SystemExit(f"the measurement imported another valve_gym than the one in {tree}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--before", required=True, metavar="REV", help="git revision to compare with")
    ap.add_argument("--steps", type=int, default=5000, help="timed scans per block")
    ap.add_argument("--n", type=int, default=100, help="loops of the batched measurement")
    ap.add_argument("--repeats", type=int, default=7, help="rounds, each revision once per round")
    a = ap.parse_args(argv)
    if min(a.steps, a.n, a.repeats) < 1:
        ap.error("--steps, --n and --repeats must be >= 1")
    now_tree = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        old_tree = _export(a.before, tempfile.mkdtemp(prefix="valve_gym_before_"))
    except subprocess.CalledProcessError as exc:
        ap.error(f"--before {a.before!r}: git could not export that revision ({exc})")
    runs: dict[str, list] = {"now": [], "before": []}
    for r in range(a.repeats):
        for label, tree in (("now", now_tree), ("before", old_tree)) if r % 2 == 0 else (("before", old_tree),
                                                                                         ("now", now_tree)):
            runs[label].append(_measure(tree, a.steps, a.n))
        print(f"round {r + 1}/{a.repeats}", file=sys.stderr, flush=True)
    print(f"{a.steps} scans per block, fastest of {a.repeats} rounds, revisions taking turns; before = {a.before}")
    print(f"| block | 1 loop: now [us/scan] | before | ratio | {a.n} loops: now [us/scan] | before | ratio |")
    print("|---|---|---|---|---|---|---|")
    for name in NAMES:
        now = np.min([x[name] for x in runs["now"]], axis=0)
        old = np.min([x[name] for x in runs["before"]], axis=0)
        print(f"| {name} | {now[0]:.1f} | {old[0]:.1f} | {now[0] / old[0]:.2f} | {now[1]:.1f} | {old[1]:.1f} | "
              f"{now[1] / old[1]:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
