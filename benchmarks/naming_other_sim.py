"""Effect naming on recordings of a simulator other than the package's own.

The textbook-loop simulator :mod:`valve_gym.diagnosis.stiction.loops` (written
independently of :mod:`valve_gym.core`) makes level loops on tanks with a PI controller,
set-point moves, white or coloured noise, a slowly drifting load and a positioner lag, with
one concealed effect: ``none`` (healthy valve), ``slip_jump`` (Kano's or Choudhury's
two-parameter stiction, S 1.5-4 % of the stroke) or ``leak`` (extra constant outflow,
10-25 % of the mean inflow). The plant varies from case to case: the sample time (0.5, 1
or 2 s) and the tank's shape (cylinder, cone, sphere, horizontal cylinder; the diagnosis
fits a cylinder); ``--fixed-plant`` gives every case a cylinder sampled at 1 s, the set of
earlier releases. No dead time (it would be a second effect; a first run with 0-3 s of dead
time in every loop had the tool name ``dead_time`` in 3 of 6 healthy loops). Each is
diagnosed with every candidate effect (``plant='tank'``, ``actuator='valve'``, default
rule); "named right" means the first effect named is the concealed one (none for ``none``), where
``tank_shape`` is set aside on the tanks that are not cylinders (there the shape is a second, true
difference from the base model, reported in its own column; on a cylinder it counts as a wrong name).
Case ``i`` uses seed ``70_000 + i``; nothing here was tuned on these cases.

``--all-effects`` adds five more concealed effects, made by the same simulator's optional plant
effects (seeds ``70_100`` on, so the three cases above keep theirs): ``dead_time`` (transport delay
of 3-8 samples between the valve and the flow), ``sensor_lag`` (first-order level sensor,
4-12 samples), ``overflow`` (the tank spills at a rim 40-70 % of the way from the median level to
the highest level the same loop reaches without one, so that it does spill in the record),
``valve_characteristic`` (equal percentage, R 15-50, or quick opening; the maximum flow scaled so
that half opening gives the same flow) and ``oscillating_disturbance`` (a sinusoidal load of
6-12 % of the mean inflow, period 60-200 samples).

``--no-load`` diagnoses the same loops without their slowly drifting unmeasured load (the load's
draw is kept, so every other value of a case stays the same): the difference is what that load
costs the naming and the verdict.

Sampling convention: the textbook simulator logs ``op[k]`` computed from the ``pv[k]`` logged
with it, so ``op[k]`` acts only after ``pv[k]``; the diagnosis (like the package's own loop
generator) reads ``pv[k]`` as measured after ``op[k]`` has acted for one sample. Taken as they
are, these recordings look one sample early to the model. ``--pv-after-op`` re-aligns each
recording to the diagnosis' convention first (pairs ``op[k-1]``, ``pv[k]``; one sample shorter).

Usage::

    nice -n 10 python benchmarks/naming_other_sim.py [--per-effect 6] [--jobs 2] [--fixed-plant] [--pv-after-op]
        [--op-lag 0|1|auto] [--all-effects] [--first 0] [--no-load] [--slip-trace] [--json FILE]

``--slip-trace`` also lists every slip-jump candidate fit of every case (round, confirmed or not, the
criterion's and the held-out RMSE's change, whether it pays, the fitted S and J against the true ones, and
how often the fitted valve slips: :func:`valve_gym.diagnosis.diagnose.valve_slips`); ``--json FILE`` writes
every case's names, verdict, final RMSE and slip-jump candidates, to compare two runs case by case.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace

import numpy as np

from valve_gym._io import write_atomic
from valve_gym.diagnosis import diagnose
from valve_gym.diagnosis.cli import OP_LAG_CHOICES, op_lag_value
from valve_gym.diagnosis.diagnose import valve_slips
from valve_gym.diagnosis.model import process_pool
from valve_gym.diagnosis.recording import Recording
from valve_gym.diagnosis.stiction.loops import TANK_SHAPES, LoopSpec, _tuning, simulate_loop

EFFECTS = ("none", "slip_jump", "leak")
#: Effects of ``--all-effects`` beyond :data:`EFFECTS` (the simulator's optional plant effects).
MORE_EFFECTS = ("dead_time", "sensor_lag", "overflow", "valve_characteristic", "oscillating_disturbance")


def make_spec(effect: str, seed: int, vary: bool = True) -> LoopSpec:
    """A random tank loop with ``effect`` concealed in it (``vary``: random sample time and tank shape)."""
    rng = np.random.default_rng(70_000 + seed)
    p = {"Ts": 1.0, "theta": 0.0, "tau_v": float(rng.uniform(0.05, 0.4)),
         "K": 1.0, "tau": 50.0, "k_i": 0.01, "area": float(rng.uniform(0.15, 0.4)),
         "q_max": float(rng.uniform(0.008, 0.014)), "c_out": float(rng.uniform(0.004, 0.006))}
    Kc, Ti = _tuning(rng, p, "tank", False)
    valve, S, J, leak = "linear", 0.0, 0.0, 0.0
    if effect == "slip_jump":
        valve = str(rng.choice(["kano", "choudhury"]))
        S = float(rng.uniform(0.015, 0.04))
        J = float(S * rng.uniform(0.6, 1.4))
    elif effect == "leak":
        leak = float(rng.uniform(0.10, 0.25) * 0.5 * p["q_max"])
    y0 = (max(p["q_max"] * 0.5 - leak, 1e-9) / p["c_out"]) ** 2
    noise = float(rng.uniform(0.001, 0.004) * y0)
    noise_pole = float(rng.choice([0.0, rng.uniform(0.5, 0.9)]))
    load = float(rng.uniform(0.0, 0.005))
    if vary:         # drawn after the rest, so a case keeps its other values with or without --fixed-plant
        p["Ts"] = float(rng.choice([0.5, 1.0, 2.0]))
        shape = str(rng.choice(TANK_SHAPES))
    else:
        shape = "cylinder"
    extra = _more_effect(effect, rng, p, y0)     # drawn last: the cases of EFFECTS keep their values
    return LoopSpec(process="tank", valve=valve, S=S, J=J, Kc=Kc, Ti=Ti, n=1800, leak=leak, noise=noise,
                    noise_pole=noise_pole, load=load, sp_moves=float(0.25 * y0), shape=shape, **p, **extra)


def make_case(effect: str, seed: int, vary: bool = True, load: bool = True) -> tuple[LoopSpec, Recording]:
    """The spec of case ``seed`` and its recording; an overflow rim is placed where the level reaches it.

    ``load=False``: the same loop without its drifting load (every other drawn value kept).
    """
    spec = make_spec(effect, seed, vary)
    if not load:
        spec = replace(spec, load=0.0)
    name = f"{effect}_{seed}"
    if effect == "overflow":
        free = simulate_loop(replace(spec, level_max=0.0), seed=seed, name=name).pv
        lo, hi = float(np.median(free)), float(np.quantile(free, 0.99))
        spec = replace(spec, level_max=lo + spec.level_max * (hi - lo))
    return spec, simulate_loop(spec, seed=seed, name=name)


def _more_effect(effect: str, rng, p: dict, y0: float) -> dict:
    """Parameters of an effect of :data:`MORE_EFFECTS` (``p`` is changed in place where the plant changes)."""
    extra: dict = {}
    if effect == "dead_time":
        p["theta"] = float(rng.uniform(3.0, 8.0) * p["Ts"])
    elif effect == "sensor_lag":
        extra["sensor_tau"] = float(rng.uniform(4.0, 12.0) * p["Ts"])
    elif effect == "overflow":
        # a fraction of the way from the median level to the highest level the loop reaches without a rim;
        # :func:`make_case` turns it into the rim's height (so that the tank does spill in the record)
        extra["level_max"] = float(rng.uniform(0.4, 0.7))
    elif effect == "valve_characteristic":
        if rng.random() < 0.6:
            R = float(rng.uniform(15.0, 50.0))
            extra.update(characteristic="equal_percentage", rangeability=R)
            f0 = R ** -0.5
        else:
            extra["characteristic"] = "quick_opening"
            f0 = 0.5 ** 0.5
        p["q_max"] = p["q_max"] * 0.5 / f0        # the same flow (and level) at half opening
    elif effect == "oscillating_disturbance":
        extra.update(dist_amp=float(rng.uniform(0.03, 0.06)), dist_period=float(rng.uniform(60.0, 200.0) * p["Ts"]))
    return extra


def run_case(args):
    """Diagnose one case; returns (effect, seed, effects named, seconds, stiction present, probability)."""
    effect, seed, vary, align, op_lag, load = args
    spec, rec = make_case(effect, seed, vary, load)
    if align:
        rec = rec.with_op_lag(1)                 # op[k-1] with pv[k], before the diagnosis sees it
    t0 = time.perf_counter()
    res = diagnose(rec, plant="tank", actuator="valve", jobs=1, op_lag=op_lag)
    s = res.stiction
    u = res.recording.op                         # as the diagnosis paired it
    slips = [{"round": c.round, "confirmed": c.confirmed, "delta_ic": c.delta_ic, "holdout_change": c.holdout_change,
              "pays": c.pays, "accepted": c.accepted, "S": c.fit.physical["slip_jump.S"],
              "J": c.fit.physical["slip_jump.J"], "slips": valve_slips(c.fit, u)}
             for c in res.selection.candidates if c.effect == "slip_jump"]
    detail = {"S_true": float(spec.S) if effect == "slip_jump" else 0.0,
              "J_true": float(spec.J) if effect == "slip_jump" else 0.0,
              "final_rmse": float(res.final.rmse_all), "slip_jump_candidates": slips}
    return (effect, seed, list(res.effects), time.perf_counter() - t0, bool(s["present"]),
            float(s.get("probability", float("nan"))), f"{spec.shape}, Ts {spec.Ts:g} s", spec.shape, detail)


def slip_trace(out: list) -> str:
    """Markdown table of every slip-jump candidate fit of every case (``--slip-trace``)."""
    lines = ["| case | tank | named | true S / J [%] | round | confirmed | ΔBIC | held-out change | pays | "
             "fitted S / J [%] | slips |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in out:
        d = r[8]
        for c in d["slip_jump_candidates"]:
            lines.append(f"| {r[0]}_{r[1]} | {r[6]} | {','.join(r[2]) or 'none'} | "
                         f"{100 * d['S_true']:.2f} / {100 * d['J_true']:.2f} | {c['round']} | "
                         f"{'yes' if c['confirmed'] else 'no'} | {c['delta_ic']:.1f} | "
                         f"{100 * c['holdout_change']:+.1f} % | "
                         f"{'yes' if c['pays'] else 'no'} | {100 * c['S']:.2f} / {100 * c['J']:.2f} | {c['slips']} |")
    return "\n".join(lines)


def concealed_named(effects: list[str], shape: str) -> list[str]:
    """The effects named, less ``tank_shape`` where the tank is not a cylinder (there the shape is a true
    difference from the base model, not a concealed effect; on a cylinder it stays and counts as wrong)."""
    return [e for e in effects if not (e == "tank_shape" and shape != "cylinder")]


def main(argv=None):
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--per-effect", type=int, default=6)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--fixed-plant", action="store_true",
                    help="every loop a cylindrical tank sampled at 1 s (the set of earlier releases)")
    ap.add_argument("--pv-after-op", action="store_true",
                    help="re-align each recording to the diagnosis' sampling convention (op[k-1], pv[k])")
    ap.add_argument("--op-lag", default="auto", choices=OP_LAG_CHOICES,
                    help="diagnose(op_lag=...): 1 pairs op[k-1] with pv[k] inside the diagnosis (this simulator's "
                         "convention), auto lets the diagnosis test it")
    ap.add_argument("--no-load", action="store_true",
                    help="the same loops without their slowly drifting unmeasured load (every other drawn value kept): "
                         "what the load costs the naming and the verdict")
    ap.add_argument("--all-effects", action="store_true",
                    help=f"also conceal {', '.join(MORE_EFFECTS)} (seeds 70100 on)")
    ap.add_argument("--first", type=int, default=0,
                    help="index of the first case (seed 70000 + index; e.g. 1000 for a fresh draw of loops "
                         "no earlier run has diagnosed)")
    ap.add_argument("--slip-trace", action="store_true",
                    help="also list every slip-jump candidate fit: its criterion and held-out changes, fitted S and J "
                         "against the truth, and how often the fitted valve slips")
    ap.add_argument("--json", metavar="FILE", help="write every case's names, verdict, final RMSE and slip-jump "
                                                   "candidates to FILE (to compare runs case by case)")
    a = ap.parse_args(argv)
    if a.first < 0:
        raise SystemExit("--first must be 0 or more")
    if a.per_effect < 1:
        raise SystemExit("--per-effect must be at least 1")
    op_lag = op_lag_value(a.op_lag)
    tasks = [(e, a.first + i, not a.fixed_plant, a.pv_after_op, op_lag, not a.no_load)
             for i, e in enumerate(EFFECTS * a.per_effect)]
    effects = EFFECTS + (MORE_EFFECTS if a.all_effects else ())
    if a.all_effects:
        tasks += [(e, a.first + 100 + i, not a.fixed_plant, a.pv_after_op, op_lag, not a.no_load)
                  for i, e in enumerate(MORE_EFFECTS * a.per_effect)]
    t0 = time.perf_counter()
    with process_pool(a.jobs) as ex:
        out = []
        for r in ex.map(run_case, tasks):
            out.append(r)
            print(f"[{len(out)}/{len(tasks)}] {r[0]}_{r[1]} ({r[6]}): named {r[2] or 'none'} ({r[3]:.0f} s)",
                  file=sys.stderr, flush=True)
    print("| concealed | cases | named right | what was named | `tank_shape` named (not cylinder) | "
          "`stiction.present` | combined probability |\n|---|---|---|---|---|---|---|")
    right = 0
    for e in effects:
        rows = [r for r in out if r[0] == e]
        seen = [concealed_named(r[2], r[7]) for r in rows]
        ok = [(n[:1] == [e]) if e != "none" else (not n) for n in seen]
        right += sum(ok)
        named = ", ".join(",".join(r[2]) or "none" for r in rows)
        pres = sum(r[4] for r in rows)
        probs = ", ".join(f"{r[5]:.2f}" for r in rows)
        shaped = [r for r in rows if r[7] != "cylinder"]
        sh = sum("tank_shape" in r[2] for r in shaped)
        print(f"| {e} | {len(rows)} | {sum(ok)} | {named} | {sh} of {len(shaped)} | {pres} of {len(rows)} | {probs} |")
    print(f"\n**{right} of {len(out)} named right** ({time.perf_counter() - t0:.0f} s, {a.jobs} workers). "
          f"Command: `nice -n 10 python benchmarks/naming_other_sim.py --per-effect {a.per_effect}"
          f"{' --fixed-plant' if a.fixed_plant else ''}{' --pv-after-op' if a.pv_after_op else ''}"
          f"{' --no-load' if a.no_load else ''}"
          f"{' --op-lag ' + a.op_lag if a.op_lag != 'auto' else ''}{' --all-effects' if a.all_effects else ''}"
          f"{f' --first {a.first}' if a.first else ''}{' --slip-trace' if a.slip_trace else ''}`.")
    if a.slip_trace:
        print("\n" + slip_trace(out))
    if a.json:
        cases = [{"case": f"{r[0]}_{r[1]}", "effect": r[0], "seed": r[1], "named": r[2], "present": r[4],
                  "probability": r[5], "plant": r[6], **r[8]} for r in out]
        data = json.dumps({"command": sys.argv, "cases": cases}, indent=1).encode()
        write_atomic(a.json, lambda f: f.write(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())
