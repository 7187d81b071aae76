"""The learned compensator against the PI on a healthy valve at a constant set point.

The learned block adds a reinforcement and pulses, sized by its estimate of the stick band, to its PI; it
was trained on loops with measurement noise and sticky valves. On a healthy valve it keeps correcting:
this script measures how much, on the default tank (Choudhury valve with S = J = 0, 3000 s at 1 s scans, the
set point at the starting level), for three measurement-noise levels: the IAE of the level over
the last half, the level's peak-to-peak there, the stem travel and the output's first moves.

Usage::

    python benchmarks/learned_on_healthy_valves.py [--policy PATH]

``--policy`` measures another trained file of the learned block (its ``.json``; default the shipped one).
"""
from __future__ import annotations

import argparse

import numpy as np

from valve_gym.agents import load_controller
from valve_gym.friction import valve_model
from valve_gym.params import ModelParams, TankParams
from valve_gym.plant import Plant

NOISE_M = (0.0, 0.0005, 0.002)
SECONDS = 3000


def close_loop(name: str, noise: float, seed: int = 0, policy: str | None = None) -> dict:
    """One healthy loop under controller ``name``: the level, output and stem per scan."""
    params = valve_model("choudhury", np.zeros(1), np.zeros(1), base=ModelParams(process=TankParams()))
    plant = Plant(params, 1, scan_s=1.0)
    out = plant.reset(level=1.0)
    ctrl = load_controller(name, path=policy) if policy and name == "learned" else load_controller(name)
    sp = np.full(1, 1.0)
    op = out.op.copy()
    ctrl.reset(sp, out.y, op)
    rng = np.random.default_rng(seed)
    level, ops, stem = (np.empty(SECONDS) for _ in range(3))
    for k in range(SECONDS):
        op = np.asarray(ctrl.step(sp, out.y + noise * rng.standard_normal(1)), float) * np.ones(1)
        out = plant.step(op)
        level[k], ops[k], stem[k] = out.pv[0], op[0], out.stem[0]
    return {"level": level, "op": ops, "stem": stem}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--policy", default=None, help="learned block to measure (.json; default the shipped one)")
    a = ap.parse_args(argv)
    print("| noise [mm] | controller | IAE, last half [m s] | level peak-to-peak, last half [mm] | "
          "stem travel [strokes] | output, first 4 scans |")
    print("|---|---|---:|---:|---:|---|")
    for noise in NOISE_M:
        for name in ("pi", "learned"):
            r = close_loop(name, noise, policy=a.policy)
            tail = r["level"][SECONDS // 2:]
            print(f"| {1000 * noise:g} | {name} | {np.abs(1.0 - tail).sum():.2f} | {1000 * np.ptp(tail):.1f} | "
                  f"{np.abs(np.diff(r['stem'])).sum():.2f} | {', '.join(f'{v:.3f}' for v in r['op'][:4])} |")


if __name__ == "__main__":
    main()
