"""Stiction verdict on textbook level loops that cycle: constant set point, sticky or healthy valve.

The classic case for a stiction detector: a PI controller at a constant set point on a
Torricelli level tank (cylinder, cone, sphere or horizontal cylinder), the valve with
Choudhury's, Kano's or force-balance friction (S log-uniform 0.5-10 % of the stroke, J 0.1-1.2 S),
or a healthy (linear) valve, made by the independently written textbook simulator
:mod:`valve_gym.diagnosis.stiction.loops` (not :mod:`valve_gym.core`).  Loops are drawn by
:func:`~valve_gym.diagnosis.stiction.loops.random_spec` (SIMC-like tuning with random detuning,
sample time 0.5-5 s, positioner lag, white or coloured noise, slow load drift) but with a wider
noise range than the verdict's training loops: measurement noise of 0.03-1 % of the stroke after
the PI gain (log-uniform).  A sticky loop counts only when its PV oscillates regularly (a clear
limit cycle: Thornhill's regularity test, :func:`valve_gym.diagnosis.stiction.oscillation`); sticky
loops that do not cycle are drawn again.  Healthy loops have no oscillating load and a detuned PI.

Each loop is diagnosed as a user would (``diagnose(rec, plant='tank', actuator='valve')``, every
candidate effect, default rule); "called" is ``stiction.present``.  Reports the balanced accuracy,
the calls by friction model and by size of S, and whether the true S lies inside the reported
90 % interval.  Seeds from ``130_000`` on: no other script (training, calibration, validation) draws them.

Usage::

    nice -n 10 python benchmarks/textbook_limit_cycles.py [--sticky 22] [--healthy 6] [--jobs 2] [--op-lag 0|1|auto]
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np

from valve_gym.diagnosis import Recording, diagnose
from valve_gym.diagnosis.cli import OP_LAG_CHOICES, op_lag_value
from valve_gym.diagnosis.model import process_pool
from valve_gym.diagnosis.stiction import oscillation
from valve_gym.diagnosis.stiction.loops import LoopSpec, random_spec, simulate_loop

SEED0 = 130_000


def draw(i: int, sticky: bool, n: int = 1800) -> tuple[LoopSpec, Recording]:
    """Loop ``i`` of its class: the spec and its recording (redrawn until a sticky loop cycles)."""
    name = f"{'sticky' if sticky else 'healthy'}_{i}"
    for attempt in range(50):
        seed = SEED0 + 1000 * attempt + 2 * i + int(sticky)
        rng = np.random.default_rng(seed)
        spec = random_spec(rng, sticky, process="tank", n=n, disturbance="none")
        if sticky:
            S = float(np.exp(rng.uniform(np.log(0.005), np.log(0.10))))
            spec = replace(spec, S=S, J=float(S * rng.uniform(0.1, 1.2)))
        op_noise = float(np.exp(rng.uniform(np.log(3e-4), np.log(1e-2))))
        spec = replace(spec, noise=op_noise / spec.Kc)
        rec = simulate_loop(spec, seed=seed, name=name)
        if not sticky or oscillation(rec.pv).present:
            return spec, rec
    raise RuntimeError(f"no cycling sticky loop found for case {i}")


def run_case(args):
    """Diagnose one loop; returns a row of the results."""
    i, sticky, op_lag = args
    spec, rec = draw(i, sticky)
    t0 = time.perf_counter()
    res = diagnose(rec, plant="tank", actuator="valve", jobs=1, op_lag=op_lag)
    s = res.stiction
    lo, hi = (s.get("S_interval") or (float("nan"), float("nan")))
    inside = bool(sticky and np.isfinite(lo) and lo <= spec.S <= hi)
    return {"case": rec.name, "sticky": sticky, "valve": spec.valve, "S": spec.S, "J": spec.J,
            "shape": spec.shape, "Ts": spec.Ts, "present": bool(s["present"]),
            "probability": float(s.get("probability", float("nan"))), "S_est": float(s.get("S", float("nan"))),
            "inside": inside, "effects": list(res.effects), "op_lag": res.settings["op_lag"],
            "seconds": time.perf_counter() - t0}


def report(rows: list[dict], seconds: float, argv_note: str) -> None:
    """Print the markdown tables."""
    st = [r for r in rows if r["sticky"]]
    he = [r for r in rows if not r["sticky"]]
    tpr = sum(r["present"] for r in st) / max(len(st), 1)
    tnr = sum(not r["present"] for r in he) / max(len(he), 1)
    print("| friction model | cycling sticky loops | called stiction | true S inside 90 % interval |")
    print("|---|---|---|---|")
    for v in ("choudhury", "kano", "force_balance"):
        rv = [r for r in st if r["valve"] == v]
        if rv:
            print(f"| {v} | {len(rv)} | {sum(r['present'] for r in rv)} | "
                  f"{sum(r['inside'] for r in rv if r['present'])} of {sum(r['present'] for r in rv)} called |")
    print("\n| S band | cycling sticky loops | called stiction |\n|---|---|---|")
    for lo, hi in ((0.005, 0.01), (0.01, 0.03), (0.03, 0.10001)):
        rv = [r for r in st if lo <= r["S"] < hi]
        print(f"| {100 * lo:g}-{100 * min(hi, 0.1):g} % | {len(rv)} | {sum(r['present'] for r in rv)} |")
    print(f"\nHealthy loops cleared: {sum(not r['present'] for r in he)} of {len(he)}.")
    print(f"\n**Balanced accuracy {100 * (tpr + tnr) / 2:.0f} %** (sticky found {sum(r['present'] for r in st)} "
          f"of {len(st)}, healthy cleared {sum(not r['present'] for r in he)} of {len(he)}; "
          f"{seconds:.0f} s). Command: `nice -n 10 python benchmarks/textbook_limit_cycles.py{argv_note}`.")
    missed = [f"{r['case']} ({r['valve']}, S {100 * r['S']:.2g} %)" for r in st if not r["present"]]
    if missed:
        print(f"\nMissed: {', '.join(missed)}.")


def main(argv=None):
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--sticky", type=int, default=22)
    ap.add_argument("--healthy", type=int, default=6)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--op-lag", default="auto", choices=OP_LAG_CHOICES,
                    help="diagnose(op_lag=...): this simulator logs op[k] computed from pv[k] (pairing 1)")
    a = ap.parse_args(argv)
    if a.sticky < 1 or a.healthy < 1 or a.jobs < 1:
        raise SystemExit("--sticky, --healthy and --jobs must be at least 1")
    lag = op_lag_value(a.op_lag)
    tasks = [(i, True, lag) for i in range(a.sticky)] + [(i, False, lag) for i in range(a.healthy)]
    t0 = time.perf_counter()
    rows = []
    with process_pool(a.jobs) as ex:
        for r in ex.map(run_case, tasks):
            rows.append(r)
            print(f"[{len(rows)}/{len(tasks)}] {r['case']} ({r['valve']}, S {100 * r['S']:.2g} %, {r['shape']}, "
                  f"Ts {r['Ts']:g} s): present {r['present']}, p {r['probability']:.2f}, "
                  f"S_est {100 * r['S_est']:.2g} % ({r['seconds']:.0f} s)", file=sys.stderr, flush=True)
    note = "" if (a.sticky, a.healthy) == (22, 6) else f" --sticky {a.sticky} --healthy {a.healthy}"
    note += f" --op-lag {a.op_lag}" if a.op_lag != "auto" else ""
    report(rows, time.perf_counter() - t0, note)
    if a.op_lag == "auto":
        print(f"\nPairing 1 chosen on {sum(r['op_lag'] == 1 for r in rows)} of {len(rows)} loops.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
