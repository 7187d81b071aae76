"""How often the controller's reaction reads a recorder's pairing of OP and PV right, on records of known logging.

No fitting: :func:`valve_gym.diagnosis.pairing.controller_reaction` alone, with the process sign +1 (every
process below has a positive gain), on

* the package's own generator (:mod:`valve_gym.diagnosis.synthetic`, logs ``pv[k]`` after ``op[k]`` acted:
  pairing 0): every effect of the concealed suite and ``none``, seeds 0-5 at 600/1800/3600 samples and
  seeds 10-29 at 1200 samples;
* the independent textbook simulator (:mod:`valve_gym.diagnosis.stiction.loops`, logs ``op[k]`` computed
  from ``pv[k]``: pairing 1): the 160 loops of ``validate_stiction.py --n-sim 160``, 400 more random loops
  (``random_spec``, seeds 300000-300399), and the 33 cases of ``naming_other_sim.py --per-effect 6``
  and ``--per-effect 3 --all-effects``.

Each line counts the readings 0, 1 and undecided (None), and how many were decided by the second,
partial-regression reading.  Usage: ``python benchmarks/pairing_readings.py`` (about 20 s).
"""
from __future__ import annotations

import os
import sys
import time
from collections import Counter

import numpy as np

from valve_gym.diagnosis.pairing import controller_reaction
from valve_gym.diagnosis.stiction.loops import LoopSpec, random_spec, simulate_loop
from valve_gym.diagnosis.synthetic import SUITE_EFFECTS, make_case

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import naming_other_sim as nos  # noqa: E402
import validate_stiction as vs  # noqa: E402


def _count(records, truth: int, label: str) -> None:
    readings, partial = Counter(), 0
    for op, pv in records:
        r = controller_reaction(op, pv, 1.0)
        readings[r["op_lag"]] += 1
        partial += r.get("method") == "partial regression" and r["op_lag"] is not None
    wrong = sum(v for k, v in readings.items() if k is not None and k != truth)
    print(f"| {label} | {truth} | {sum(readings.values())} | {readings[truth]} | {readings[None]} | {wrong} | "
          f"{partial} |")


def _package():
    for eff in ("none",) + SUITE_EFFECTS:
        for seed in range(6):
            for n in (600, 1800, 3600):
                rec = make_case(eff, seed=seed, n=n).recording
                yield rec.op, rec.pv
        for seed in range(10, 30):
            rec = make_case(eff, seed=seed, n=1200).recording
            yield rec.op, rec.pv


def _validation_loops():
    for it in vs._sim_items(160):
        rec = simulate_loop(LoopSpec(**it["spec"]), seed=it["seed"], name=it["name"])
        yield rec.op, rec.pv


def _random_loops():
    for seed in range(400):
        spec = random_spec(np.random.default_rng(300_000 + seed), bool(seed % 2))
        rec = simulate_loop(spec, seed=seed)
        yield rec.op, rec.pv


def _naming_cases():
    cases = list(enumerate(nos.EFFECTS * 6)) + [(100 + i, e) for i, e in enumerate(nos.MORE_EFFECTS * 3)]
    for seed, eff in cases:
        rec = nos.make_case(eff, seed)[1]
        yield rec.op, rec.pv


def main() -> int:
    t0 = time.perf_counter()
    print("| records | true pairing | n | read right | undecided | read wrong | decided by the partial regression |")
    print("|---|---|---|---|---|---|---|")
    _count(_package(), 0, f"package generator, {len(SUITE_EFFECTS) + 1} effects")
    _count(_validation_loops(), 1, "textbook loops of validate_stiction.py --n-sim 160")
    _count(_random_loops(), 1, "400 random textbook loops (seeds 300000-300399)")
    _count(_naming_cases(), 1, "naming_other_sim.py cases (--per-effect 6; --per-effect 3 --all-effects)")
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
