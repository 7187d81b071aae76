"""Validation of trained `learned_adaptive` numbers on fresh loops of their own training family.

The loops are drawn as training draws them (:func:`valve_gym.agents.adaptive_train.draw_loops`), from
generations 5000 onwards of seed 38, which no training run reaches (a run draws generations 0 .. ``generations - 1``).
This is the measure a trained file is chosen by: the training fitness (the weights and travel rule of
``--config``, default ``configs/learned_adaptive.yaml``) and, on the sticky + severe loops, the median
compensation ratio ``R``, the limit-cycle share, the travel over the frictionless PI's, and the healthy loops'
IAE over the PI's. It is not a held-out check: the family is
the training family. The held-out checks are the benchmark's generalisation part and
``benchmarks/learned_unseen_check.py`` / ``learned_third_check.py``.

    python benchmarks/adaptive_validation.py [FILE.json ...] [--vary NAME=V1,V2 ...] [--config YAML]
        [--generations 5] [--loops 60]

Each FILE is a trained ``adaptive.json`` (its ``.safetensors`` beside it); with none, the shipped file.
``--vary beta=0.8,1.0`` adds rows of the first file with one number changed to each value.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

FIRST = 5000
#: The validation draws are generations FIRST, FIRST + 1, ... of this seed, whatever the configuration's.
VALIDATION_SEED = 38


def scores(P: np.ndarray, loops) -> dict:
    """Per-loop IAE, travel and limit cycle of the columns ``P`` (m, 10), the PI and the frictionless PI."""
    from valve_gym.agents.adaptive_train import rollout
    from valve_gym.oscillation import detect_oscillation

    pi = np.array([[0.0, 0.0, 0.3, 0.9, 0.05, 0.01, 3.0, 1.0, 0.1, 3.0]])
    cols = np.vstack([P, pi, pi])
    fr = np.zeros(len(cols), bool)
    fr[-1] = True
    m, n = len(cols), len(loops.rows)
    iae, trav, lc = np.zeros((m, n)), np.zeros((m, n)), np.zeros((m, n), bool)
    for scan in (0.5, 1.0, 2.0):
        r = rollout(loops, cols, fr, scan)
        if r["idx"].size == 0:
            continue
        iae[:, r["idx"]], trav[:, r["idx"]] = r["iae"], r["travel"]
        for j, i in enumerate(r["idx"]):
            lc[:, i] = [detect_oscillation(r["e"][:, c, j], scan, "benchmark").present for c in range(m)]
    return {"iae": iae, "travel": trav, "lc": lc}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("files", nargs="*", help="trained adaptive.json files (default: the shipped one)")
    ap.add_argument("--generations", type=int, default=5, help="validation draws (generations 5000, 5001, ...)")
    ap.add_argument("--loops", type=int, default=60, help="loops per draw")
    ap.add_argument("--config", default=str(ROOT / "configs" / "learned_adaptive.yaml"),
                    help="training YAML whose fitness weights and travel rule score the files")
    ap.add_argument("--vary", action="append", default=[], metavar="NAME=V1,V2",
                    help="rows of the first file with the number NAME set to each value (repeatable)")
    a = ap.parse_args(argv)
    if a.generations < 1 or a.loops < 1:
        ap.error("--generations and --loops must be >= 1")
    from valve_gym.agents.adaptive import DEFAULT_ADAPTIVE, load_adaptive
    from valve_gym.agents.adaptive_train import AdaptiveTrainConfig, draw_loops, evaluate, load_train_config
    from valve_gym.agents.bench.scores import compensation_ratio
    from valve_gym.agents.controllers.adaptive import PARAM_NAMES, PARAMS

    files = [Path(f) for f in a.files] or [DEFAULT_ADAPTIVE]
    labels: list = [str(f) for f in files]
    try:
        P = [[float(np.asarray(load_adaptive(f).p[k]).reshape(-1)[0]) for k in PARAM_NAMES] for f in files]
    except (OSError, ValueError) as exc:
        ap.error(str(exc))
    for item in a.vary:
        name, sep, values = item.partition("=")
        if not sep or name not in PARAM_NAMES:
            ap.error(f"--vary takes NAME=V1,V2 with NAME one of {', '.join(PARAM_NAMES)}, got {item!r}")
        lo, hi = next((p[2], p[3]) for p in PARAMS if p[0] == name)
        for v in values.split(","):
            try:
                x = float(v)
            except ValueError:
                ap.error(f"--vary {name}: {v!r} is not a number")
            if not (np.isfinite(x) and lo <= x <= hi):
                ap.error(f"--vary {name}: {v} is outside the number's range [{lo:g}, {hi:g}]")
            P.append(list(P[0]))
            P[-1][PARAM_NAMES.index(name)] = x
            labels.append(f"{labels[0]} with {name} = {x:g}")
    P = np.array(P)
    from dataclasses import replace

    from valve_gym.config import ConfigError

    try:
        base = load_train_config(a.config) if Path(a.config).is_file() else AdaptiveTrainConfig()
    except ConfigError as exc:
        ap.error(str(exc))
    cfg = replace(base, loops=a.loops, seed=VALIDATION_SEED)
    fit, per = [], []
    for g in range(FIRST, FIRST + a.generations):
        loops = draw_loops(cfg, g)
        fit.append(evaluate(loops, P, cfg))
        s = scores(P, loops)
        s["sticky"] = np.array([r["band"] != "healthy" for r in loops.rows])
        per.append(s)
        print(f"draw {g}: fitness " + " ".join(f"{x:+.3f}" for x in fit[-1]), file=sys.stderr, flush=True)
    iae = np.concatenate([s["iae"] for s in per], axis=1)
    trav = np.concatenate([s["travel"] for s in per], axis=1)
    lc = np.concatenate([s["lc"] for s in per], axis=1)
    sticky = np.concatenate([s["sticky"] for s in per])
    m = len(labels)
    print(f"{a.generations} draws x {a.loops} loops of the training family ({int(sticky.sum())} sticky + severe)")
    print("| file | fitness | median R (sticky) | LC share (PI) | travel / frictionless PI | healthy IAE / PI |")
    print("|---|---|---|---|---|---|")
    for c, f in enumerate(labels):
        R = compensation_ratio(iae[m, sticky], iae[c, sticky], iae[m + 1, sticky])
        print(f"| {f} | {np.mean([x[c] for x in fit]):+.3f} | {np.median(R):.2f} | {lc[c, sticky].mean():.2f} "
              f"({lc[m, sticky].mean():.2f}) | {np.median(trav[c, sticky] / trav[m + 1, sticky]):.2f} | "
              f"{np.median(iae[c, ~sticky] / iae[m, ~sticky]):.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
