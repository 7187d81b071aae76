"""SB3 baselines on ``valve_gym/ValveTankRegulation-v0``: PPO, A2C, SAC, TD3 from rl-zoo3-style YAML.

A config may instead name ``env_id: valve_gym/ValveFamilyRegulation-v0`` (the randomised family of
``learned``, :mod:`valve_gym.envs.family_env`; ``configs/rl/ppo_family.yaml``, ``sac_family.yaml``).

``valve-gym train --config configs/rl/sac.yaml --seed 0 --out runs/sac_0`` (``algorithm: sac``; also
``ppo``, ``a2c``, ``td3``; a config with ``algorithm: ppo`` and ``env_id`` trains here, the older PPO
configs of ``ValveTank-v0`` in :mod:`valve_gym.agents.train`).

A config::

    algorithm: sac
    env_id: valve_gym/ValveTankRegulation-v0
    eval: {every_steps: 20000, n_loops: 24, seed: 900001, duration_s: 1800}
    valve_gym/ValveTankRegulation-v0:        # rl-zoo3's hyperparameter format (its -conf file)
      n_timesteps: 200000
      policy: MlpPolicy
      n_envs: 1
      normalize: true
      learning_rate: 0.0003
      ...

The env section is what ``python -m rl_zoo3.train --algo sac --env valve_gym/ValveTankRegulation-v0
--gym-packages valve_gym -conf configs/rl/sac.yaml`` reads (rl-zoo3 ignores the other keys). A run
writes ``curve.csv`` (median ``R``, travel / frictionless PI and LC share of the policy on fixed
benchmark loops against env steps), the policy as a safe export (``policy.safetensors`` +
``policy.json``, the ``VecNormalize`` statistics included) and ``summary.json``. Same config and seed,
same machine and library versions: the same weights (one torch thread, seeded SB3).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from valve_gym.config import ConfigError, read_yaml

__all__ = ["ALGORITHMS", "load_baseline_config", "make_model", "train_baseline", "EvalLoops", "main"]

ALGORITHMS = ("ppo", "a2c", "sac", "td3")
REGULATION_ID = "valve_gym/ValveTankRegulation-v0"
#: The regulation task on the randomised family of ``learned`` (:mod:`valve_gym.envs.family_env`).
FAMILY_ID = "valve_gym/ValveFamilyRegulation-v0"
#: The env ids a baseline config may name.
ENV_IDS = (REGULATION_ID, FAMILY_ID)

_COMMON = {"n_timesteps", "policy", "n_envs", "normalize", "policy_kwargs", "learning_rate", "gamma", "env_kwargs"}
_KEYS = {
    "ppo": _COMMON | {"n_steps", "batch_size", "n_epochs", "gae_lambda", "clip_range", "ent_coef", "vf_coef",
                      "max_grad_norm", "use_sde", "sde_sample_freq"},
    "a2c": _COMMON | {"n_steps", "gae_lambda", "ent_coef", "vf_coef", "max_grad_norm", "use_rms_prop"},
    "sac": _COMMON | {"buffer_size", "batch_size", "tau", "train_freq", "gradient_steps", "learning_starts",
                      "ent_coef", "target_entropy"},
    "td3": _COMMON | {"buffer_size", "batch_size", "tau", "train_freq", "gradient_steps", "learning_starts",
                      "noise_type", "noise_std", "policy_delay", "target_policy_noise", "target_noise_clip"},
}
_TOP = {"algorithm", "env_id", "name", "eval", "budget"}
_EVAL = {"every_steps": 20000, "n_loops": 24, "seed": 900001, "duration_s": 1800.0}


def load_baseline_config(path_or_dict) -> dict:
    """Read and check a baseline config; returns ``{algorithm, env_id, name, eval, hyper}``.

    Raises
    ------
    ConfigError
        Naming an unknown key (and the known ones), an unknown algorithm or env id.
    """
    data = path_or_dict if isinstance(path_or_dict, dict) else read_yaml(Path(path_or_dict), "training config")
    if not isinstance(data, dict):
        raise ConfigError("a baseline config must be a mapping (algorithm, env_id and the env's hyperparameters)")
    algo = str(data.get("algorithm", "")).lower()
    if algo not in ALGORITHMS:
        raise ConfigError(f"algorithm must be one of {', '.join(ALGORITHMS)}, got {data.get('algorithm')!r}")
    env_id = str(data.get("env_id", REGULATION_ID))
    if env_id not in ENV_IDS:
        raise ConfigError(f"env_id: the baselines train on {' or '.join(ENV_IDS)}, got {env_id!r}")
    extra = [k for k in data if k not in _TOP and k != env_id]
    if extra:
        raise ConfigError(f"unknown key(s) {extra}; the keys are {sorted(_TOP)} and {env_id!r} "
                          "(the rl-zoo3 hyperparameters)")
    hyper = data.get(env_id)
    if not isinstance(hyper, dict) or "n_timesteps" not in hyper:
        raise ConfigError(f"the config needs a section {env_id!r} with at least n_timesteps (rl-zoo3's format)")
    bad = [k for k in hyper if k not in _KEYS[algo]]
    if bad:
        raise ConfigError(f"unknown key(s) {bad} in {env_id!r} for {algo}; known: {', '.join(sorted(_KEYS[algo]))}")
    ev = dict(_EVAL)
    for k, v in (data.get("eval") or {}).items():
        if k not in _EVAL:
            raise ConfigError(f"unknown key 'eval.{k}'; the keys of 'eval' are {', '.join(_EVAL)}")
        ev[k] = v
    return {"algorithm": algo, "env_id": env_id, "name": str(data.get("name", algo)), "eval": ev,
            "hyper": dict(hyper), "raw": data}


def _policy_kwargs(pk) -> dict:
    if pk is None:
        return {}
    if isinstance(pk, str):            # rl-zoo3 writes "dict(net_arch=[64, 64])": only literals are read
        import ast

        node = ast.parse(pk, mode="eval").body
        if not (isinstance(node, ast.Call) and getattr(node.func, "id", "") == "dict" and not node.args):
            raise ConfigError(f"policy_kwargs must be a mapping or 'dict(key=literal, ...)', got {pk!r}")
        return {kw.arg: ast.literal_eval(kw.value) for kw in node.keywords if kw.arg}
    if not isinstance(pk, dict):
        raise ConfigError(f"policy_kwargs must be a mapping, got {pk!r}")
    return dict(pk)


def make_model(cfg: dict, seed: int, tb_dir: str | None = None):
    """The SB3 model and its (normalised) training env for ``cfg`` and ``seed``."""
    import stable_baselines3 as sb3
    import torch
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.noise import NormalActionNoise
    from stable_baselines3.common.vec_env import VecNormalize

    import valve_gym  # noqa: F401  (registers the ids)

    torch.set_num_threads(1)
    h = dict(cfg["hyper"])
    h.pop("n_timesteps")
    policy = h.pop("policy", "MlpPolicy")
    n_envs = int(h.pop("n_envs", 1))
    normalize = h.pop("normalize", False)
    env_kwargs = h.pop("env_kwargs", None) or {}
    venv = make_vec_env(cfg["env_id"], n_envs=n_envs, seed=seed, env_kwargs=env_kwargs)
    if normalize:
        nk: dict = {"gamma": float(h.get("gamma", 0.99))}
        if isinstance(normalize, str):
            import ast

            nk.update(ast.literal_eval(normalize))
        venv = VecNormalize(venv, **nk)
    h["policy_kwargs"] = _policy_kwargs(h.get("policy_kwargs"))
    if cfg["algorithm"] == "td3":
        nt, ns = h.pop("noise_type", None), h.pop("noise_std", 0.1)
        if nt == "normal":
            h["action_noise"] = NormalActionNoise(np.zeros(2), float(ns) * np.ones(2))
        elif nt is not None:
            raise ConfigError(f"noise_type must be 'normal', got {nt!r}")
    cls = getattr(sb3, cfg["algorithm"].upper())
    model = cls(policy, venv, seed=seed, device="cpu", verbose=0, tensorboard_log=tb_dir, **h)
    return model, venv


class EvalLoops:
    """Fixed benchmark loops (sticky + severe, regulation part) on which a policy's median ``R`` is tracked.

    The loops are :func:`~valve_gym.agents.bench.scenarios.regulation_scenarios` of the benchmark config
    drawn with ``seed`` (not the benchmark's) and ``duration_s``; the SIMC PI, the frictionless PI and the
    knocker run once on them.
    """

    def __init__(self, n_loops: int = 24, seed: int = 900001, duration_s: float = 1800.0):
        from valve_gym.agents.bench.config import BenchConfig
        from valve_gym.agents.bench.runner import lineup, run_spec
        from valve_gym.agents.bench.scenarios import regulation_scenarios
        from valve_gym.agents.bench.scores import score_runs

        cfg = BenchConfig()
        cfg = replace(cfg, regulation=replace(cfg.regulation, duration_s=float(duration_s)))
        sc = regulation_scenarios(cfg, n=int(n_loops), seed=int(seed))
        self.scen = sc.subset(np.flatnonzero(sc.band != "healthy"))
        self.cfg = cfg
        specs = {s.label: s for s in lineup(cfg)}
        self.ref = {k: score_runs(run_spec(specs[k], self.scen), cfg)
                    for k in ("PI frictionless", "PI (SIMC)", "knocker")}

    def score(self, block, label: str = "policy") -> dict:
        """``{R, travel_vs_frictionless, lc_share, iae_per_h}`` medians (LC: share) of ``block`` on the loops."""
        from dataclasses import replace as dreplace

        from valve_gym.agents.bench.runner import run_loops
        from valve_gym.agents.bench.scores import score_runs

        s = score_runs(dreplace(run_loops(block, self.scen), label=label), self.cfg)
        return self._summary(s)

    def _summary(self, s) -> dict:
        from valve_gym.agents.bench.scores import compensation_ratio

        pi, fr = self.ref["PI (SIMC)"], self.ref["PI frictionless"]
        r = compensation_ratio(pi.iae_per_h, s.iae_per_h, fr.iae_per_h, self.cfg.scores.r_floor)
        return {"R": float(np.median(r)), "travel_vs_frictionless":
                float(np.median(s.travel_per_h / np.maximum(fr.travel_per_h, 1e-12))),
                "lc_share": float(np.mean(s.lc_present)), "iae_per_h": float(np.median(s.iae_per_h))}

    def references(self) -> dict:
        """The scores of the references (``PI (SIMC)``, ``knocker``, ``PI frictionless``)."""
        return {k: self._summary(v) for k, v in self.ref.items()}


def train_baseline(cfg: dict, out, seed: int = 0, timesteps: int | None = None, progress: bool = True,
                   command: str = "", max_wall_s: float | None = None) -> dict:
    """Train one seed of a baseline; writes ``curve.csv``, ``policy.{safetensors,json}``, ``summary.json``.

    ``max_wall_s`` stops the training early (at the next env step after that many seconds; the summary's
    ``env_steps`` and ``stopped_early`` say so): a run cut by the clock is not reproducible step for step.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from valve_gym._io import write_atomic

    from .bench.policies import block_from_model, export_policy

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    total = int(float(timesteps if timesteps is not None else cfg["hyper"]["n_timesteps"]))
    if total < 1:
        raise ConfigError(f"n_timesteps must be >= 1, got {total}")
    ev = cfg["eval"]
    every = int(ev["every_steps"])
    loops = EvalLoops(int(ev["n_loops"]), int(ev["seed"]), float(ev["duration_s"]))
    model, venv = make_model(cfg, seed)
    rows: list[dict] = []
    stopped = {"early": False}
    t0 = time.perf_counter()

    def evaluate(steps: int) -> None:
        blk = block_from_model(model, venv, name=cfg["name"])
        row = {"env_steps": steps, **loops.score(blk), "wall_s": time.perf_counter() - t0}
        rows.append(row)
        if progress:
            print(f"[{cfg['name']} seed {seed}] {steps:>8} steps  median R {row['R']:6.2f}  travel/frictionless "
                  f"{row['travel_vs_frictionless']:5.2f}  LC {row['lc_share']:.2f}  ({row['wall_s']:.0f} s)",
                  file=sys.stderr, flush=True)

    class _Eval(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next = every

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next:
                evaluate(int(self.num_timesteps))
                self.next += every
            if max_wall_s is not None and time.perf_counter() - t0 > max_wall_s:
                stopped["early"] = True
                return False
            return True

    evaluate(0)
    model.learn(total_timesteps=total, callback=_Eval(), progress_bar=False)
    if not rows or rows[-1]["env_steps"] != model.num_timesteps:
        evaluate(int(model.num_timesteps))
    wall = time.perf_counter() - t0
    import pandas as pd

    csv = pd.DataFrame(rows).to_csv(index=False)
    write_atomic(out / "curve.csv", lambda f: f.write(csv.encode()))
    import stable_baselines3
    import torch

    meta = {"name": cfg["name"], "seed": int(seed), "env_steps": int(model.num_timesteps), "budget_steps": total,
            "stopped_early": stopped["early"], "train_wall_s": wall, "train_command": command, "config": cfg["raw"],
            "train_versions": {"stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__,
                               "python": sys.version.split()[0]}}
    export_policy(model, out / "policy", vecnormalize=venv if type(venv).__name__ == "VecNormalize" else None,
                  meta=meta)
    summary = {**meta, "final": rows[-1], "references": loops.references()}
    text = json.dumps(summary, indent=1, default=str, allow_nan=False) if all(
        math.isfinite(v) for v in rows[-1].values()) else json.dumps(summary, indent=1, default=str)
    write_atomic(out / "summary.json", lambda f: f.write(text.encode()))
    return summary


def main(argv=None, command: str | None = None) -> int:
    """``python -m valve_gym.agents.baselines --config FILE [--seed S] [--out DIR] [--timesteps N]``."""
    p = argparse.ArgumentParser(prog="valve-gym train", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--config", required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None)
    p.add_argument("--timesteps", type=int, default=None)
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--max-wall-s", type=float, default=None, help="stop training after this many seconds")
    a, _ = p.parse_known_args(argv)
    try:
        cfg = load_baseline_config(a.config)
    except (ConfigError, OSError) as exc:
        print(f"valve-gym train: {exc}", file=sys.stderr)
        return 2
    out = a.out or str(Path("runs") / f"{cfg['name']}_{a.seed}")
    s = train_baseline(cfg, out, a.seed, a.timesteps, not a.no_progress,
                       command or "valve-gym train " + " ".join(argv if argv is not None else sys.argv[1:]),
                       max_wall_s=a.max_wall_s)
    f = s["final"]
    print(f"{cfg['name']} seed {a.seed}: {s['env_steps']} env steps in {s['train_wall_s']:.0f} s; median R "
          f"{f['R']:.2f}, travel / frictionless PI {f['travel_vs_frictionless']:.2f}, LC share {f['lc_share']:.2f}; "
          f"policy {Path(out) / 'policy.json'}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
