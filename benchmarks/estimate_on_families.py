"""Where the learned compensator's online stick-band estimate lands on the held-out families.

``load_controller("learned")`` sizes its reinforcement and pulses by an estimate ``S_hat`` of the stick band that
it measures from SP, PV and its own output. Given the true band instead, it removes far more of stiction's cost
on every held-out family (``--known`` rows of the family scripts), so this script looks at the estimate itself:
each family's loops are run as its script runs them (the shared harness's SIMC tuning from a step test, the
family's own noise and load, one hour), and for every sticky loop the median of ``S_hat`` over the second half
of the record is set against the loop's true ``S``.

    python benchmarks/estimate_on_families.py [--families second ... eighth] [--duration 3600] [--answers]

Prints, per family and per decade of ``S`` (0.5-1.5 %, 1.5-4 %, 4-10 %), the number of sticky loops and the
median and quartiles of ``S_hat / S``; and, over the healthy loops, the median ``S_hat`` (fraction of stroke).
A ratio well below 1 means the block under-compensates there; above 1, that it over-compensates.

``--answers`` prints instead, per family, how far the block's output had travelled since a reversal of the
integral when the block took the valve's answer (the error's trend turning), over the loop's true band: an
answer after much less than ``S`` came before the stem could have crossed the band.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
for _p in (_HERE.parent, _HERE):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

from learned_unseen_check import tune  # noqa: E402

from valve_gym.agents import load_controller  # noqa: E402

#: family -> (module, simulator class, default size, seed, step-test length [s])
FAMILIES = {"second": ("learned_unseen_check", "Loops", 36, 913, 1200.0),
            "third": ("learned_third_check", "ThirdLoops", 48, 2718, 1800.0),
            "fourth": ("learned_fourth_check", "FourthLoops", 48, 4242, 1800.0),
            "fifth": ("learned_fifth_check", "FifthLoops", 48, 5151, 600.0),
            "sixth": ("learned_sixth_check", "SixthLoops", 48, 6161, 1200.0),
            "seventh": ("learned_seventh_check", "SeventhLoops", 48, 7171, 1200.0),
            "eighth": ("learned_eighth_check", "EighthLoops", 48, 8181, 1800.0)}
BANDS = ((0.005, 0.015), (0.015, 0.04), (0.04, 0.1001))
HEALTHY_S = 0.005


def _run(family: str, duration: float, n: int | None) -> dict:
    """Run ``learned`` on the family's loops as its script does; per loop: ``S``, the median ``S_hat`` over the
    second half, the integral's reversals (``flips``), the answers the block took, and the median output travel
    from a reversal to its answer (``travel``; NaN where none)."""
    mod_name, cls_name, n0, seed, test_s = FAMILIES[family]
    mod = __import__(mod_name)
    sim_cls = getattr(mod, cls_name)
    rows = mod.draw(n0 if n is None else n, seed)
    scans = np.array([r["scan"] for r in rows])
    N = len(rows)
    out = {"S": np.array([r["S"] for r in rows]), "S_hat": np.empty(N), "flips": np.zeros(N),
           "answers": np.zeros(N), "travel": np.full(N, np.nan)}
    for scan in np.unique(scans):
        idx = np.flatnonzero(scans == scan)
        sub = [rows[i] for i in idx]
        Kc, Ti = tune(sim_cls, sub, float(scan), test_s)
        sim = sim_cls(sub, float(scan), False)
        y, _, u0 = sim.reset()
        T = int(round(duration / scan))
        noise, load = sim_cls.disturbances(sub, float(scan), T, duration)
        ctrl = load_controller("learned", Kc=Kc, Ti=Ti, scan_s=float(scan))
        sp = y.copy()
        ctrl.reset(sp, sim.measure(y, noise[0]), u0)
        hist = np.empty((T, len(idx)))
        travels: list[list[float]] = [[] for _ in idx]
        prev = ctrl.state
        for k in range(T):
            op = ctrl.step(sp, sim.measure(y, noise[k]))
            y, _ = sim.step(op, load[k])
            st = ctrl.state
            hist[k] = st.s_hat
            flip = (st.d != prev.d) & (st.d != 0)
            answer = (prev.armed > 0) & (st.armed == 0) & ~flip
            out["flips"][idx] += flip
            out["answers"][idx] += answer
            for j in np.flatnonzero(answer):
                travels[j].append(abs(float(st.o_prev[j] - st.o_flip[j])))
            prev = st
        out["S_hat"][idx] = np.median(hist[T // 2:], axis=0)
        out["travel"][idx] = [np.median(t) if t else np.nan for t in travels]
    return out


def estimates(family: str, duration: float = 3600.0, n: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(S, S_hat)`` per loop of ``family``: the true band and the median estimate over the record's second half."""
    r = _run(family, duration, n)
    return r["S"], r["S_hat"]


def answers_table(family: str, duration: float = 3600.0, n: int | None = None) -> str:
    """One markdown row: on the sticky loops, how far the output had travelled (over ``S``) when the block took
    the valve's answer, and how often the integral reversed and an answer came."""
    r = _run(family, duration, n)
    m = r["S"] >= HEALTHY_S
    t = r["travel"][m] / r["S"][m]
    ok = np.isfinite(t)
    return (f"| {family} | {int(m.sum())} | {np.median(t[ok]):.2f} | {int(np.sum(t[ok] < 0.5))} | "
            f"{np.median(r['flips'][m]):.0f} | {np.median(r['answers'][m]):.0f} | "
            f"{np.median(r['S_hat'][m] / r['S'][m]):.2f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--families", nargs="+", default=["second", "third", "fourth", "fifth"], choices=list(FAMILIES))
    ap.add_argument("--duration", type=float, default=3600.0, help="record length [s]")
    ap.add_argument("--answers", action="store_true",
                    help="instead: the output travel at each answer the block took, over the true band")
    a = ap.parse_args(argv)
    if a.duration <= 0:
        ap.error(f"--duration must be > 0 s, got {a.duration}")
    if a.answers:
        print("| family | sticky loops | median travel at an answer / S | loops under 0.5 | reversals per record "
              "(median) | answers per record (median) | median S_hat / S |")
        print("|---|---|---|---|---|---|---|")
        for fam in a.families:
            print(answers_table(fam, a.duration), flush=True)
        return 0
    print("| family | S band | sticky loops | median S_hat / S | quartiles | healthy loops: median S_hat [%] |")
    print("|---|---|---|---|---|---|")
    for fam in a.families:
        t0 = time.perf_counter()
        S, S_hat = estimates(fam, a.duration)
        healthy = S < HEALTHY_S
        for lo, hi in BANDS:
            m = (S >= lo) & (S < hi)
            r = S_hat[m] / S[m]
            q = np.percentile(r, [25, 75]) if m.any() else (np.nan, np.nan)
            print(f"| {fam} | {100 * lo:g}-{100 * min(hi, 0.1):g} % | {int(m.sum())} | "
                  f"{np.median(r) if m.any() else float('nan'):.2f} | {q[0]:.2f}-{q[1]:.2f} | "
                  f"{100 * np.median(S_hat[healthy]):.2f} |")
        print(f"{fam}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
