"""Controller blocks on a sticky valve at a constant set point, and their cost per scan.

Part 1 (behaviour): the default tank (SIMC PI tuning), a Choudhury valve
(``slip_jump``) with band ``S`` and slip ``J``, no noise and no load, the
level started 5 cm below the set point; after the first third of the record,
per controller: half peak-to-peak of the level (the limit-cycle amplitude),
mean ``|sp - level|``, stem travel and stem reversals. Every compensator gets
the true ``S`` (and ``J`` where it takes one).

Part 2 (speed): seconds per scan of each block for ``n`` loops, as a ratio to
the PI block measured in the same run.

Run::

    .venv/bin/python benchmarks/bench_controllers.py [--T 3000] [--n 100]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from valve_gym import core
from valve_gym.agents import load_controller
from valve_gym.params import ModelParams, SlipJump

NAMES = ("pi", "knocker", "constant_reinforcement", "two_move", "integral_freeze")
CASES = ((0.01, 0.005), (0.02, 0.01), (0.04, 0.02), (0.05, 0.05), (0.02, 0.0))


def _settings(name: str, S: float, J: float) -> dict:
    if name == "pi":
        return {}
    if name in ("constant_reinforcement", "two_move"):
        return {"S": S, "J": J}
    return {"S": S}


def closed_loop(S: float, J: float, T: int) -> list:
    """One row per controller: (name, amplitude m, mean |e| m, stem travel, stem reversals)."""
    p = ModelParams().with_effect("slip_jump", SlipJump(S=S, J=J))
    n = len(NAMES)
    st = core.initial_state(p, n=n, level=0.95)
    ctrls = [load_controller(name, **_settings(name, S, J)) for name in NAMES]
    y = st.y.copy()
    for i, c in enumerate(ctrls):
        c.reset(1.0, y[i], st.h[i])
    ys, hs = np.empty((T, n)), np.empty((T, n))
    for k in range(T):
        u = np.array([c.step(1.0, y[i]) for i, c in enumerate(ctrls)])
        st, y = core.step(st, u, p, n_sub=50)
        ys[k], hs[k] = y, st.h
    ys, hs = ys[T // 3:], hs[T // 3:]
    rows = []
    for i, name in enumerate(NAMES):
        dh = np.diff(hs[:, i])
        moves = np.sign(dh[np.abs(dh) > 1e-6])
        rows.append((name, (ys[:, i].max() - ys[:, i].min()) / 2, np.abs(1.0 - ys[:, i]).mean(),
                     np.abs(dh).sum(), int(np.sum(moves[1:] != moves[:-1]))))
    return rows


def speed(n: int, scans: int = 2000) -> dict:
    """Seconds per scan of each block for ``n`` loops."""
    rng = np.random.default_rng(0)
    pv = 1.0 + 0.002 * rng.standard_normal((scans, n))
    out = {}
    for name in NAMES:
        c = load_controller(name)
        c.reset(1.0, np.ones(n), np.full(n, 0.5))
        t0 = time.perf_counter()
        for k in range(scans):
            c.step(1.0, pv[k])
        out[name] = (time.perf_counter() - t0) / scans
    return out


def main(argv=None) -> None:
    """Print both tables."""
    ap = argparse.ArgumentParser(description="Controller blocks on a sticky valve, and their cost per scan.")
    ap.add_argument("--T", type=int, default=3000, help="scans per closed-loop run (1 s each)")
    ap.add_argument("--n", type=int, default=100, help="loops per block in the speed part")
    args = ap.parse_args(argv)
    print(f"Constant set point, default tank, Choudhury valve; last {args.T - args.T // 3} of {args.T} s")
    print(f"{'S':>5} {'J':>6} {'controller':24s} {'amp [mm]':>9} {'mean|e| [mm]':>13} {'travel':>8} {'rev':>5}")
    for S, J in CASES:
        for name, amp, mae, travel, rev in closed_loop(S, J, args.T):
            print(f"{S:5.3f} {J:6.3f} {name:24s} {amp * 1e3:9.2f} {mae * 1e3:13.2f} {travel:8.3f} {rev:5d}")
    sp = speed(args.n)
    print(f"\nSeconds per scan for {args.n} loops (ratio to the PI block in this run)")
    for name, s in sp.items():
        print(f"{name:24s} {s * 1e6:8.1f} us  x{s / sp['pi']:.2f}")


if __name__ == "__main__":
    main()
