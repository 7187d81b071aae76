"""Learning curves and shipped policies of the SB3 baselines (from ``benchmarks/train_rl_baselines.py``'s runs).

    python benchmarks/rl_baselines_report.py RUNS [--figures docs/figures/rl] [--ship valve_gym/agents/policies/rl]

Writes ``learning_curves.png`` (per algorithm: the median compensation ratio ``R`` and the stem travel /
frictionless PI of the policy on the fixed evaluation loops against env steps, mean and 95 % t-interval over
the seeds; the SIMC PI, the knocker, the frictionless PI and the shipped ES-trained block as lines) and
``curves.csv`` (every seed's curve) into ``--figures``; copies each run's policy (safetensors + JSON) to
``--ship`` as ``<algo>_seed<s>``; prints a markdown table of the final points.
"""
from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np

ALGOS = ("ppo", "sac", "td3")


def _t95(n: int) -> float:
    from scipy.stats import t

    return float(t.ppf(0.975, n - 1)) if n > 1 else float("nan")


def load_runs(runs: Path) -> dict:
    import pandas as pd

    out: dict = {}
    for d in sorted(runs.iterdir()):
        if not (d / "summary.json").is_file():
            continue
        s = json.loads((d / "summary.json").read_text())
        algo = str(s["config"]["algorithm"])
        out.setdefault(algo, []).append({"dir": d, "summary": s, "curve": pd.read_csv(d / "curve.csv")})
    return out


def references(runs: dict) -> dict:
    """The reference rows (same evaluation loops in every run) and the ES-trained block on those loops."""
    first = next(iter(runs.values()))[0]["summary"]
    ref = dict(first["references"])
    try:
        from valve_gym.agents.baselines import EvalLoops
        from valve_gym.agents.learned import load_learned

        ev = first["config"].get("eval", {})
        loops = EvalLoops(int(ev.get("n_loops", 24)), int(ev.get("seed", 900001)),
                          float(ev.get("duration_s", 1800)))
        ref["learned (ES)"] = loops.score(load_learned(), "learned")
    except Exception as exc:  # noqa: BLE001 - the figure is still made without this line
        print(f"note: the ES block's line is left out ({exc})")
    return ref


def figure(runs: dict, ref: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker  # noqa: F401

    algos = [a for a in ALGOS if a in runs]
    fig, axes = plt.subplots(2, len(algos), figsize=(4.6 * len(algos), 6.4), squeeze=False)
    styles = {"PI (SIMC)": ("k", "--"), "knocker": ("tab:red", "-."), "PI frictionless": ("tab:grey", ":"),
              "learned (ES)": ("tab:purple", (0, (5, 2)))}
    for j, algo in enumerate(algos):
        rs = runs[algo]
        common = sorted(set.intersection(*(set(r["curve"]["env_steps"]) for r in rs)))
        for i, metric in enumerate(("R", "travel_vs_frictionless")):
            ax = axes[i, j]
            Y = np.array([[float(r["curve"].set_index("env_steps").loc[s, metric]) for s in common] for r in rs])
            m, sd = Y.mean(0), Y.std(0, ddof=1) if len(rs) > 1 else np.zeros(len(common))
            h = _t95(len(rs)) * sd / np.sqrt(len(rs))
            ax.plot(common, m, color="tab:blue", label=f"{algo.upper()} (mean of {len(rs)} seeds)")
            ax.fill_between(common, m - h, m + h, color="tab:blue", alpha=0.25, label="95 % CI over seeds")
            for r in rs:
                c = r["curve"]
                ax.plot(c["env_steps"], c[metric], color="tab:blue", lw=0.5, alpha=0.35)
            for k, (col, ls) in styles.items():
                if k in ref:
                    ax.axhline(ref[k][metric], color=col, ls=ls, lw=1.2, label=k)
            if metric == "travel_vs_frictionless":
                ax.axhline(1.5, color="tab:orange", lw=0.8, label="travel budget (1.5x)")
            ax.set_xlabel("env steps")
            ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda x, _: f"{x / 1000:g}k"))
            if metric == "R":
                ax.set_ylim(-4.0, 3.0)     # early dips of some seeds go lower (curves.csv has them)
            ax.grid(alpha=0.3)
            if j == 0:
                ax.set_ylabel("median R (sticky + severe; axis at -4..3)" if metric == "R"
                              else "travel / frictionless PI")
            if i == 0:
                ax.set_title(f"{algo.upper()} on ValveTankRegulation-v0")
        if j == len(algos) - 1:
            axes[0, j].legend(fontsize=7, loc="lower right")
            axes[1, j].legend(fontsize=7, loc="upper right")
    fig.suptitle("SB3 baselines: the policy on fixed benchmark loops (19 sticky + severe, 1800 s) during training",
                 fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def ship(runs: dict, dest: Path) -> list:
    dest.mkdir(parents=True, exist_ok=True)
    out = []
    for algo, rs in runs.items():
        for r in rs:
            s = r["summary"]
            stem = dest / f"{algo}_seed{s['seed']}"
            shutil.copyfile(r["dir"] / "policy.safetensors", str(stem) + ".safetensors")
            meta = json.loads((r["dir"] / "policy.json").read_text())
            meta["train_command"] = (f"valve-gym train --config configs/rl/{algo}.yaml --seed {s['seed']} "
                                     f"--out runs/rl/{algo}_{s['seed']}"
                                     + (f" --max-wall-s {s['train_wall_s']:.0f}" if s.get("stopped_early") else ""))
            meta["name"] = f"{algo.upper()}"
            (Path(str(stem) + ".json")).write_text(json.dumps(meta, indent=1))
            out.append(stem)
    return out


def table(runs: dict, ref: dict) -> str:
    lines = ["| row | seeds | env steps (per seed) | median R at the end: mean [min, max] over seeds | "
             "travel / frictionless PI | LC share |", "|---|---|---|---|---|---|"]
    for algo in ALGOS:
        if algo not in runs:
            continue
        f = [r["summary"]["final"] for r in runs[algo]]
        R = np.array([x["R"] for x in f])
        T = np.array([x["travel_vs_frictionless"] for x in f])
        L = np.array([x["lc_share"] for x in f])
        steps = [int(x["env_steps"]) for x in f]
        lines.append(f"| {algo.upper()} | {len(f)} | {min(steps)}-{max(steps)} | {R.mean():.2f} [{R.min():.2f}, "
                     f"{R.max():.2f}] | {T.mean():.2f} [{T.min():.2f}, {T.max():.2f}] | {L.mean():.2f} |")
    for k, v in ref.items():
        lines.append(f"| {k} | - | - | {v['R']:.2f} | {v['travel_vs_frictionless']:.2f} | {v['lc_share']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    import pandas as pd

    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("runs")
    p.add_argument("--figures", default="docs/figures/rl")
    p.add_argument("--ship", default=None)
    a = p.parse_args(argv)
    runs = load_runs(Path(a.runs))
    ref = references(runs)
    fig_dir = Path(a.figures)
    figure(runs, ref, fig_dir / "learning_curves.png")
    rows = [c["curve"].assign(algorithm=algo, seed=c["summary"]["seed"]) for algo, rs in runs.items() for c in rs]
    pd.concat(rows).to_csv(fig_dir / "curves.csv", index=False, float_format="%.5g")
    print(table(runs, ref))
    if a.ship:
        print("shipped:", ", ".join(str(s) for s in ship(runs, Path(a.ship))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
