"""Check a learned compensator against the targets of the regulation benchmark, on seeds of one's own.

``python -m valve_gym.agents.learned_eval [--policy PATH] [--n 90] [--seed 424242] [--noise 0.002]``

Runs the benchmark's regulation part (:mod:`valve_gym.agents.bench`: same scenario generator, same runner,
same scores) on ``n`` loops drawn with ``--seed`` (pick one that is not the benchmark's), for the
frictionless PI, the SIMC PI, a PI with twice its gain (is the gain compensation or just a faster
controller?), the classical compensators with the true stiction estimate, and the learned block;
prints per band group the limit-cycle share and amplitude, IAE, compensation ratio ``R``, stem
travel, reversals and offset, and the targets of the learned block; then, for the sticky and severe
valves, the learned block's median ``R`` and limit-cycle share (and the SIMC PI's) by friction model.
``--noise`` sets the measurement noise of the loops (standard deviation, m; the benchmark's is 0.002),
to check a block at noise levels it was not trained on.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

__all__ = ["evaluate_learned", "main"]


def _groups(scen) -> dict:
    band = np.asarray(scen.band).astype(str)
    return {"sticky+severe": band != "healthy", "healthy": band == "healthy"}


def evaluate_learned(path=None, n: int = 90, seed: int = 424242, compensators: bool = True,
                     noise_std: float | None = None) -> dict:
    """Scores (``valve_gym.agents.bench.scores.LoopScores`` by label) and the scenarios; see the module docstring.

    ``noise_std`` (m) replaces the benchmark's measurement noise of the regulation loops.
    """
    from valve_gym.agents.bench.config import load_bench_config
    from valve_gym.agents.bench.runner import ControllerSpec, lineup, run_loops, run_spec
    from valve_gym.agents.bench.scenarios import regulation_scenarios
    from valve_gym.agents.bench.scores import score_runs

    from .learned import load_learned

    cfg = load_bench_config(None)
    if noise_std is not None:
        cfg = replace(cfg, regulation=replace(cfg.regulation, noise_std=float(noise_std)))
    scen = regulation_scenarios(cfg, n=n, seed=seed)
    specs = [s for s in lineup(cfg) if s.family in ("frictionless", "pi")]
    specs.append(ControllerSpec("PI Kc x2", "pi", "detuned", (("detune", 2.0),)))
    if compensators:
        specs += [s for s in lineup(cfg) if s.family == "compensator" and s.estimate == 1.0]
    scores = {}
    for s in specs:
        scores[s.label] = score_runs(run_spec(s, scen), cfg)
        print(f"  ran {s.label}", file=sys.stderr, flush=True)
    blk = load_learned(path)
    scores["learned"] = score_runs(replace(run_loops(blk, scen), label="learned"), cfg)
    return {"scores": scores, "scenarios": scen, "config": cfg}


def _table(res: dict) -> str:
    from valve_gym.agents.bench.scores import compensation_ratio

    sc, scen = res["scores"], res["scenarios"]
    floor = res["config"].scores.r_floor
    lines = []
    for g, m in _groups(scen).items():
        if not m.any():
            continue
        lines += [f"\n{g} ({int(m.sum())} loops; medians)",
                  "| controller | LC share | LC amplitude [mm] | IAE [m s/h] | R | travel [strokes/h] | "
                  "reversals/h | abs offset [mm] |", "|---|---|---|---|---|---|---|---|"]
        pi, z = sc["PI (SIMC)"].iae_per_h[m], sc["PI frictionless"].iae_per_h[m]
        for label, s in sc.items():
            lc = s.lc_present[m]
            amp = s.lc_amplitude[m][lc]
            amp_txt = f"{1000 * np.nanmedian(amp):.1f}" if amp.size else "-"
            r = compensation_ratio(pi, s.iae_per_h[m], z, floor)
            lines.append(f"| {label} | {lc.mean():.2f} | {amp_txt} | {np.median(s.iae_per_h[m]):.2f} | "
                         f"{np.median(r):.2f} | {np.median(s.travel_per_h[m]):.2f} | "
                         f"{np.median(s.reversals_per_h[m]):.0f} | {1000 * np.median(np.abs(s.offset[m])):.2f} |")
    return "\n".join(lines)


def _by_model(res: dict) -> str:
    """Sticky + severe loops by friction model: median R and LC share of the learned block against the SIMC PI."""
    from valve_gym.agents.bench.scores import compensation_ratio

    sc, scen = res["scores"], res["scenarios"]
    if "learned" not in sc:
        return ""
    floor = res["config"].scores.r_floor
    sticky = _groups(scen)["sticky+severe"]
    models = np.asarray(scen.model).astype(str)
    lines = ["\nsticky+severe by friction model (medians)",
             "| friction model | loops | R learned | LC share learned | LC share PI (SIMC) |", "|---|---|---|---|---|"]
    for name in sorted(set(models[sticky])):
        m = sticky & (models == name)
        pi, z = sc["PI (SIMC)"].iae_per_h[m], sc["PI frictionless"].iae_per_h[m]
        r = compensation_ratio(pi, sc["learned"].iae_per_h[m], z, floor)
        lines.append(f"| {name} | {int(m.sum())} | {np.median(r):.2f} | {sc['learned'].lc_present[m].mean():.2f} | "
                     f"{sc['PI (SIMC)'].lc_present[m].mean():.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    """Command line; exit 0 done, 1 failed, 2 bad usage."""
    p = argparse.ArgumentParser(prog="python -m valve_gym.agents.learned_eval",
                                description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--policy", default=None, help="learned block (.json or training folder); default the shipped")
    p.add_argument("--n", type=int, default=90, help="loops (default 90)")
    p.add_argument("--seed", type=int, default=424242, help="scenario seed (not the benchmark's)")
    p.add_argument("--no-compensators", action="store_true", help="skip the classical compensators")
    p.add_argument("--noise", type=float, default=None, metavar="M",
                   help="measurement noise of the loops, standard deviation in m (default: the benchmark's)")
    a = p.parse_args(argv)
    if a.n < 3:
        p.error("--n must be >= 3")
    if a.noise is not None and not (0.0 <= a.noise < 1.0):
        p.error(f"--noise must be a standard deviation in m, 0 <= noise < 1 (got {a.noise})")
    try:
        res = evaluate_learned(a.policy, a.n, a.seed, not a.no_compensators, a.noise)
    except (OSError, ValueError) as exc:
        print(f"learned_eval: {exc}", file=sys.stderr)
        return 1
    print(_table(res))
    print(_by_model(res))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
