"""Validation of trained `learned` numbers on fresh loops of their own training family.

The loops are drawn as training draws them (:func:`valve_gym.agents.adaptive_train.draw_loops`), from
generations 5000 onwards of seed 38, which no training run reaches (a run draws generations 0 .. ``generations - 1``).
This is the measure a trained file is chosen by: the training fitness (the weights and travel rule of
``--config``, default ``configs/learned_adaptive.yaml``) and, on the sticky + severe loops, the median
compensation ratio ``R``, the limit-cycle share, the travel over the frictionless PI's, and the healthy loops'
IAE over the PI's. It is not a held-out check: the family is the training family. The held-out checks are
the benchmark's generalisation part and ``benchmarks/learned_unseen_check.py`` / ``learned_third_check.py``.

    python benchmarks/adaptive_validation.py [FILE.json ...] [--vary NAME=V1,V2 ...] [--config YAML]
        [--generations 5] [--loops 60]

Each FILE is a trained ``adaptive.json`` (its ``.safetensors`` beside it); with none, the shipped file.
``--vary beta=0.8,1.0`` adds rows of the first file with one number changed to each value (also the untrained
switches ``k_i``, the integral boost, ``k_z``, the integral dead zone, and ``confirm``, answers that must hold).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

FIRST = 5000
#: The validation draws are generations FIRST, FIRST + 1, ... of this seed, whatever the configuration's.
VALIDATION_SEED = 38


def _median(x) -> str:
    return f"{np.median(x):.2f}" if np.size(x) else "n/a (no such loops in these draws)"


def _mean(x) -> str:
    return f"{np.mean(x):.2f}" if np.size(x) else "n/a"


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
    from valve_gym.agents import adaptive_train as at
    from valve_gym.agents.adaptive import DEFAULT_ADAPTIVE, load_adaptive
    from valve_gym.agents.bench.scores import compensation_ratio
    from valve_gym.agents.controllers.adaptive import PARAM_NAMES, PARAMS, SWITCH_RANGES, SWITCHES
    from valve_gym.config import ConfigError

    files = [Path(f) for f in a.files] or [DEFAULT_ADAPTIVE]
    labels: list = [str(f) for f in files]
    try:
        blocks = [load_adaptive(f) for f in files]
        P = [[float(np.ravel(b.p[k])[0]) for k in PARAM_NAMES] for b in blocks]
        answers = [{k: float(np.ravel(b.p[k])[0]) for k in SWITCHES} for b in blocks]   # each file's own switches
    except (OSError, ValueError) as exc:
        ap.error(str(exc))
    for item in a.vary:
        name, sep, values = item.partition("=")
        names = (*PARAM_NAMES, *SWITCH_RANGES)
        if not sep or name not in names:
            ap.error(f"--vary takes NAME=V1,V2 with NAME one of {', '.join(names)}; got {item!r}")
        lo, hi = SWITCH_RANGES[name] if name in SWITCH_RANGES else next((p[2], p[3]) for p in PARAMS if p[0] == name)
        for v in values.split(","):
            try:
                x = float(v)
            except ValueError:
                ap.error(f"--vary {name}: {v!r} is not a number")
            if not (np.isfinite(x) and lo <= x <= hi):
                ap.error(f"--vary {name}: {v} is outside the number's range [{lo:g}, {hi:g}]")
            P.append(list(P[0]))
            answers.append(dict(answers[0]))
            if name in SWITCH_RANGES:                  # an untrained setting, not one of the ten
                answers[-1][name] = x
            else:
                P[-1][PARAM_NAMES.index(name)] = x
            labels.append(f"{labels[0]} with {name} = {x:g}")
    P = np.array(P)
    try:
        base = at.load_train_config(a.config) if Path(a.config).is_file() else at.AdaptiveTrainConfig()
    except ConfigError as exc:
        ap.error(str(exc))
    cfg = replace(base, loops=a.loops, seed=VALIDATION_SEED)
    fit, per = [], []
    for g in range(FIRST, FIRST + a.generations):
        loops = at.draw_loops(cfg, g)
        s = at.score_columns(loops, P, answers)
        fit.append(at.fitness(s, len(P), cfg))
        s["sticky"] = ~s["healthy"]
        per.append(s)
        print(f"draw {g}: fitness " + " ".join(f"{x:+.3f}" for x in fit[-1]), file=sys.stderr, flush=True)
    iae = np.concatenate([s["iae"] for s in per], axis=1)
    trav = np.concatenate([s["travel"] for s in per], axis=1)
    lc = np.concatenate([s["lc"] for s in per], axis=1)
    amp = np.concatenate([s["amplitude"] for s in per], axis=1)
    off = np.abs(np.concatenate([s["offset"] for s in per], axis=1))
    sticky = np.concatenate([s["sticky"] for s in per])
    m = len(labels)
    print(f"{a.generations} draws x {a.loops} loops of the training family ({int(sticky.sum())} sticky + severe)")
    print("| file | fitness | median R (sticky) | LC share (PI) | mean LC amp. x1000 (PI) | median abs. offset x1000 "
          "| travel / frictionless PI | healthy IAE / PI |")
    print("|---|---|---|---|---|---|---|---|")
    for c, f in enumerate(labels):
        R = compensation_ratio(iae[m, sticky], iae[c, sticky], iae[m + 1, sticky])
        print(f"| {f} | {np.mean([x[c] for x in fit]):+.3f} | {_median(R)} | {_mean(lc[c, sticky])} "
              f"({_mean(lc[m, sticky])}) | {_mean(1000 * amp[c, sticky])} ({_mean(1000 * amp[m, sticky])}) | "
              f"{_median(1000 * off[c, sticky])} | {_median(trav[c, sticky] / trav[m + 1, sticky])} | "
              f"{_median(iae[c, ~sticky] / iae[m, ~sticky])} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
