"""Training of the learned compensator by evolution strategies on the regulation task.

``valve-gym train --config configs/learned.yaml --out runs/learned --seed S``

The policy is the network inside the learned block (:mod:`valve_gym.agents.learned`); it is trained by
natural evolution strategies with antithetic sampling, centred-rank fitness shaping and Adam
(Salimans et al. 2017), a policy-search reinforcement-learning method that optimises the
episode's return directly, with deterministic policies, common random numbers for the whole
population (every perturbation meets the same loops), and no value function. Each generation
runs ``2 * pairs`` perturbed networks, the current network and the plain PI on
``scenarios`` regulation loops of the native vector env
(:class:`valve_gym.envs.ValveTankRegulationVectorEnv`, all in one batch).

Fitness of a network on a batch of loops (higher is better)::

    f = -mean_b l_b - travel_penalty * mean_b travel_b / hours
        - reversal_weight * mean_b r_b - lc_weight * mean_b (lc_b - lc_PI,b)
        - lc_amp_weight * mean_b (A_b - A_PI,b) / 0.01 m
    l_b = log(IAE_b / IAE_PI,b)             (max(., 0) on healthy valves)
    r_b = log((rev_b + 1) / (rev_PI,b + 1))  (0 on healthy valves)

with the IAE of the measured level (``sp - pv`` after each scan, the benchmark's own score,
:func:`valve_gym.agents.bench.scores.loop_iae`), the stem travel (strokes) and the stem reversals
(:func:`~valve_gym.agents.bench.scores.valve_motion`, the benchmark's reversal dead band; privileged
signals: only the policy's inputs are restricted), each against the plain PI on the same loop.
The log ratios weigh a healthy valve as much as a severe one; on healthy valves only a loss
against the PI counts (the block is not rewarded for out-tuning the PI where there is no
stiction), and on sticky valves fewer stem reversals than the PI's (fewer stick-slip cycles)
are rewarded beside a lower IAE; with ``lc_weight > 0`` so are fewer detections of the benchmark's
limit-cycle detector (``lc_b`` = 1 where it fires on the measured error, sticky valves only), and with
``lc_amp_weight > 0`` smaller cycles (``A_b`` its amplitude [m], 0 where it does not fire).

References
----------
.. [1] T. Salimans, J. Ho, X. Chen, S. Sidor, I. Sutskever, "Evolution strategies as a scalable
   alternative to reinforcement learning", arXiv:1703.03864, 2017.
.. [2] D. Wierstra et al., "Natural evolution strategies", JMLR 15 (2014) 949-980.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from valve_gym.config import ConfigError, check_count, config_to_dict, load_config
from valve_gym.envs.regulation import N_ACT, RegulationTaskConfig, obs_names, pi_action

from .learned import MAX_LAYER, MLPSpec, mlp_forward, normalise, save_learned, unflatten
from .lifecycle import STOP, stop_on_signals
from .safe_files import load_model_file, save_model_file

#: Upper limits of the ES counts, checked when the config is read (before anything is allocated):
#: the perturbations of a generation are one ``(pairs, n_params)`` array, every pair and scenario
#: one closed-loop run per generation.
MAX_ES_COUNTS = {"generations": 1_000_000, "pairs": 4096, "scenarios": 4096}
_ES_COST = {"generations": "each runs every pair on every scenario",
            "pairs": "each pair is two closed-loop runs per scenario and generation, its perturbation held in memory",
            "scenarios": "each is two closed-loop runs per pair and generation"}

__all__ = ["ESHyper", "ESEvalConfig", "LearnedTrainConfig", "load_learned_train_config", "train_learned",
           "rollout_scores", "RolloutScores", "Interrupted"]


@dataclass(frozen=True)
class ESHyper:
    """Evolution-strategies settings.

    Parameters
    ----------
    generations : int
        Updates of the network.
    pairs : int
        Antithetic perturbation pairs per generation.
    scenarios : int
        Loops each network runs per generation (the same for all, common random numbers).
    sigma : float
        Standard deviation of the parameter perturbations.
    learning_rate : float
        Adam step size.
    weight_decay : float
        L2 decay of the parameters per update (times the learning rate).
    hidden : list of int
        Hidden layer sizes of the tanh network.
    travel_penalty : float
        Fitness cost per stroke per hour of stem travel (in log-IAE units).
    reversal_weight : float
        Fitness weight of ``log((reversals + 1) / (reversals_PI + 1))`` of the stem on sticky valves
        (each reversal is half a stick-slip cycle).
    lc_weight : float
        Fitness weight of the limit-cycle detections on sticky valves (the benchmark's ACF detector
        on the measured error) against the PI's; 0 = not run.
    lc_amp_weight : float
        Fitness weight of the detected limit cycle's amplitude against the PI's, per cm, on sticky
        valves (0 where none is detected); the detector runs when this or ``lc_weight`` is > 0.
    healthy_symmetric : bool
        On healthy valves count any departure from the PI's IAE (``|log ratio|``), not only a loss:
        the block must then behave as the PI where there is no stiction.
    episode_s : float, s
        Episode length used in training (the task's ``episode_s`` is used for validation).
    """

    generations: int = 300
    pairs: int = 16
    scenarios: int = 12
    sigma: float = 0.05
    learning_rate: float = 0.01
    weight_decay: float = 0.005
    hidden: tuple[int, ...] = (32, 32)
    travel_penalty: float = 0.01
    reversal_weight: float = 0.25
    healthy_symmetric: bool = False
    lc_weight: float = 0.0
    lc_amp_weight: float = 0.0
    episode_s: float = 1200.0

    def __post_init__(self):
        for nm in ("generations", "pairs", "scenarios"):
            v = getattr(self, nm)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"es.{nm} must be an integer >= 1, got {v!r}")
            check_count(f"es.{nm}", v, MAX_ES_COUNTS[nm], _ES_COST[nm])
        for nm in ("sigma", "learning_rate", "episode_s"):
            if not getattr(self, nm) > 0:
                raise ConfigError(f"es.{nm} must be > 0, got {getattr(self, nm)!r}")
        if min(self.weight_decay, self.travel_penalty, self.reversal_weight, self.lc_weight, self.lc_amp_weight) < 0:
            raise ConfigError("es.weight_decay, es.travel_penalty, es.reversal_weight, es.lc_weight and "
                              "es.lc_amp_weight must be >= 0")
        if not self.hidden or any((not isinstance(h, int)) or not 1 <= h <= MAX_LAYER for h in self.hidden):
            raise ConfigError(f"es.hidden must be a list of layer sizes from 1 to {MAX_LAYER} (a compensator's "
                              f"network needs tens; each layer's weights are held per population member), "
                              f"got {self.hidden!r}")


@dataclass(frozen=True)
class ESEvalConfig:
    """Validation: every ``every`` generations on ``n_loops`` fixed loops with seeds ``seed + i``.

    The seeds are disjoint from the training seeds (drawn from the run's seed) and from the
    benchmark's; the best network on validation is kept as ``best``.
    """

    every: int = 10
    n_loops: int = 48
    seed: int = 700_000

    def __post_init__(self):
        if self.every < 1 or self.n_loops < 1:
            raise ConfigError("eval.every and eval.n_loops must be >= 1")


@dataclass(frozen=True)
class LearnedTrainConfig:
    """A training run of the learned compensator (YAML: ``configs/learned.yaml``).

    Parameters
    ----------
    algorithm : 'es'
    name : str
    seed : int
    checkpoint_every : int
        Generations between checkpoints (also written on SIGINT/SIGTERM and at the end).
    task : RegulationTaskConfig
    es : ESHyper
    eval : ESEvalConfig
    """

    algorithm: str = "es"
    name: str = "learned"
    seed: int = 0
    checkpoint_every: int = 10
    task: RegulationTaskConfig = field(default_factory=RegulationTaskConfig)
    es: ESHyper = field(default_factory=ESHyper)
    eval: ESEvalConfig = field(default_factory=ESEvalConfig)

    def __post_init__(self):
        if self.algorithm != "es":
            raise ConfigError(f"algorithm must be 'es' for the learned compensator, got {self.algorithm!r}")
        if self.checkpoint_every < 1:
            raise ConfigError("checkpoint_every must be >= 1")
        if not self.name or any(c in self.name for c in "/\\ "):
            raise ConfigError(f"name must be a word without slashes or spaces, got {self.name!r}")


def load_learned_train_config(path_or_dict) -> LearnedTrainConfig:
    """Load a :class:`LearnedTrainConfig` (unknown keys and bad values name the key path)."""
    return load_config(path_or_dict, cls=LearnedTrainConfig)


# --------------------------------------------------------------------------- rollouts
class Interrupted(Exception):
    """Raised inside a rollout when SIGINT/SIGTERM asked the run to stop."""


class RolloutScores(NamedTuple):
    """Scores of ``P`` policies on ``B`` loops.

    Fields
    ------
    iae : (P, B) IAE of the measured level, :func:`valve_gym.agents.bench.scores.loop_iae` [m s]
    travel : (P, B) stem travel [strokes]
    reversals : (P, B) stem reversals (:func:`valve_gym.agents.bench.scores.valve_motion`, the benchmark's dead band)
    lc : (P, B) 1 where the limit-cycle detector fired (0 everywhere unless asked for)
    obs : (n_obs,) mean and (n_obs,) std of the observations (of the last policy)
    S : (B,) stick band of each loop [fraction of stroke]
    lc_amp : (P, B) amplitude of the detected limit cycle [m] (0 where none), or None
    """

    iae: np.ndarray
    travel: np.ndarray
    reversals: np.ndarray
    lc: np.ndarray
    obs_mean: np.ndarray
    obs_std: np.ndarray
    S: np.ndarray
    lc_amp: np.ndarray | None = None


class _TaskPlants:
    """The regulation task's plants of a draw as a :class:`~valve_gym.loop.LoopPlant` of the runner."""

    def __init__(self, plants, scan_s: float):
        self.plants, self.n, self.scan_s = plants, plants.level.size, scan_s

    def scan(self, u: np.ndarray, d: np.ndarray) -> tuple:
        """One scan at input ``u`` (n,) and load ``d`` (n,): ``(y, stem, level)``."""
        self.plants.step(u, d)
        level = self.plants.level.copy()
        return level, self.plants.stem.copy(), level


class _NetworkBank:
    """``P`` policies on ``B`` loops each, as one DCS block of ``P * B`` loops.

    The regulation block law (:class:`~valve_gym.envs.regulation.BlockLaw`) acts on the networks' outputs
    (the plain PI's action for a ``None`` policy). It also sums the observations of the last policy's loops
    (the normaliser's statistics).
    """

    def __init__(self, policies, task: RegulationTaskConfig, B: int, obs_norm):
        from valve_gym.envs.regulation import BlockLaw

        self.P, self.B = len(policies), B
        self.law = BlockLaw(task.block, self.P * B)
        self.n_obs = len(obs_names(task.block))
        self.nets = [i for i, w in enumerate(policies) if w is not None]
        self.stacked = None
        if self.nets:
            self.stacked = {k: np.stack([policies[i][k] for i in self.nets]) for k in policies[self.nets[0]]}
        self.mean, self.std = (np.zeros(self.n_obs), np.ones(self.n_obs)) if obs_norm is None else obs_norm
        self.act = np.tile(pi_action(1), (self.P * B, 1)).reshape(self.P, B, N_ACT)
        self.s1, self.s2, self.k = np.zeros(self.n_obs), np.zeros(self.n_obs), 0

    def reset(self, sp, pv, op) -> None:
        """Bumpless start of every loop."""
        self.law.reset(sp, pv, op)

    def step(self, sp, pv) -> np.ndarray:
        """Measure, run the networks, act: the outputs (P * B,)."""
        if STOP["flag"]:
            raise Interrupted()
        o = self.law.observe(sp, pv).astype(np.float32).reshape(self.P, self.B, self.n_obs).astype(np.float64)
        self.s1 += o[-1].sum(0)
        self.s2 += (o[-1] ** 2).sum(0)
        self.k += 1
        if self.stacked is not None:
            self.act[self.nets] = mlp_forward(self.stacked, normalise(o[self.nets], self.mean, self.std))
        return self.law.act(self.act.reshape(self.P * self.B, N_ACT))


def rollout_scores(policies, task: RegulationTaskConfig, seeds, obs_norm=None, lc: bool = False) -> RolloutScores:
    """Run ``P`` policies on the loops of ``seeds`` (B,): one closed-loop run of ``P * B`` loops.

    The loops are the regulation task's episodes of ``seeds`` (the draws of
    ``ValveTankRegulationVectorEnv.reset(seed=...)``), run by the closed-loop runner
    (:func:`valve_gym.loop.run_closed_loop`) with the policies as one block (:class:`_NetworkBank`), and
    scored with the benchmark's loop scores.

    Parameters
    ----------
    policies : list
        Each ``None`` (the plain PI) or a weights dict of :func:`valve_gym.agents.learned.mlp_forward`.
    task : RegulationTaskConfig
    seeds : sequence of int
    obs_norm : (mean, std), optional
        Observation normaliser of the networks.
    lc : bool
        Run the limit-cycle detector of the benchmark (:func:`valve_gym.oscillation.detect_oscillation`, benchmark rule)
        on each loop's measured error.
    """
    from gymnasium.utils import seeding

    from valve_gym.agents.bench.config import ScoresConfig
    from valve_gym.agents.bench.scores import limit_cycles, loop_iae, valve_motion
    from valve_gym.envs.regulation import LoopPlants, draw_scenarios
    from valve_gym.loop import Scenario, run_closed_loop
    from valve_gym.plant import PlantOutput

    P, B = len(policies), len(seeds)
    n, T, scan = P * B, task.steps, task.block.scan_s
    d = draw_scenarios([seeding.np_random(int(s))[0] for _ in range(P) for s in seeds], task)
    plants = LoopPlants(task, d)
    start = PlantOutput(pv=plants.level.copy(), stem=plants.stem.copy(), op=plants.op0.copy(), y=plants.level.copy())
    bank = _NetworkBank(policies, task, B, obs_norm)
    sc = Scenario(sp=np.broadcast_to(d.sp, (T, n)), scan_s=scan, load=d.load[:, :T].T, noise=d.noise.T)
    run = run_closed_loop(_TaskPlants(plants, scan), bank, sc, start=start)
    err = d.sp - run.pv[1:]                      # the measured error after each scan
    m = bank.s1 / (B * T)
    sd = np.sqrt(np.maximum(bank.s2 / (B * T) - m * m, 0.0))
    trav, rev = valve_motion(run.stem[1:], ScoresConfig().reversal_deadband)
    lc_present, lc_amp = np.zeros(n), np.zeros(n)
    if lc:
        res = limit_cycles(err, scan)
        lc_present = np.array([float(r.present) for r in res])
        lc_amp = np.array([float(r.amplitude) if r.present else 0.0 for r in res])
    return RolloutScores(iae=loop_iae(err, scan).reshape(P, B), travel=trav.reshape(P, B),
                         reversals=rev.reshape(P, B).astype(float), lc=lc_present.reshape(P, B), obs_mean=m,
                         obs_std=sd, S=d.S.reshape(P, B)[0], lc_amp=lc_amp.reshape(P, B))


def fitness(sc: RolloutScores, ref_iae: np.ndarray, ref_rev: np.ndarray, hyper: ESHyper, hours: float,
            healthy_max: float = 0.005, ref_lc: np.ndarray | None = None,
            ref_lc_amp: np.ndarray | None = None) -> np.ndarray:  # noqa: D417
    """Fitness (P,) of scored policies against the PI's IAE ``ref_iae`` (B,) (see the module docstring).

    On healthy valves (``S <= healthy_max``) only a loss against the PI counts (``max(log ratio, 0)``),
    and stem reversals count on the sticky valves only, against the PI's (``ref_rev``, (B,)).
    """
    lr = np.log(np.maximum(sc.iae, 1e-9) / np.maximum(ref_iae, 1e-9)[None, :])
    healthy = (sc.S <= healthy_max)[None, :]
    lr = np.where(healthy, np.abs(lr) if hyper.healthy_symmetric else np.maximum(lr, 0.0), lr)
    rr = np.where(healthy, 0.0, np.log((sc.reversals + 1.0) / (ref_rev[None, :] + 1.0)))
    f = -lr.mean(1) - hyper.travel_penalty * sc.travel.mean(1) / hours - hyper.reversal_weight * rr.mean(1)
    if hyper.lc_weight > 0 and ref_lc is not None:
        f = f - hyper.lc_weight * np.where(healthy, 0.0, sc.lc - ref_lc[None, :]).mean(1)
    if hyper.lc_amp_weight > 0 and ref_lc_amp is not None and sc.lc_amp is not None:
        f = f - hyper.lc_amp_weight * np.where(healthy, 0.0, sc.lc_amp - ref_lc_amp[None, :]).mean(1) / 0.01
    return f


def centered_ranks(f: np.ndarray) -> np.ndarray:
    """Ranks of ``f`` mapped to [-0.5, 0.5] (fitness shaping)."""
    r = np.empty(len(f))
    r[np.argsort(f, kind="stable")] = np.arange(len(f))
    return r / max(len(f) - 1, 1) - 0.5


# --------------------------------------------------------------------------- state
@dataclass
class ESState:
    """Everything a resume needs (written to the checkpoint)."""

    theta: np.ndarray
    m: np.ndarray
    v: np.ndarray
    best_theta: np.ndarray
    obs_mean: np.ndarray
    obs_std: np.ndarray
    gen: int = 0
    env_steps: int = 0
    best_score: float = -math.inf
    wall_s: float = 0.0
    rng_state: dict = field(default_factory=dict)
    curve: list = field(default_factory=list)
    finished: bool = False

    def save(self, path: Path, meta: dict) -> None:
        """Write the checkpoint atomically (safetensors + JSON; the JSON last)."""
        t = {"theta": self.theta, "adam_m": self.m, "adam_v": self.v, "best_theta": self.best_theta,
             "obs_mean": self.obs_mean, "obs_std": self.obs_std}
        j = {"format": "valve_gym.es_checkpoint/1", "gen": self.gen, "env_steps": self.env_steps,
             "best_score": self.best_score if math.isfinite(self.best_score) else None, "wall_s": self.wall_s,
             "rng_state": self.rng_state, "curve": self.curve, "finished": self.finished, **meta}
        save_model_file(path, t, j)

    @classmethod
    def load(cls, path: Path) -> tuple[ESState, dict]:
        """Read a checkpoint written by :meth:`save` (never unpickles)."""
        mf = load_model_file(path)
        j, t = mf.meta, mf.tensors
        if j.get("format") != "valve_gym.es_checkpoint/1":
            raise ValueError(f"{path} is not a learned-compensator training checkpoint")
        bs = j.get("best_score")
        st = cls(theta=t["theta"], m=t["adam_m"], v=t["adam_v"], best_theta=t["best_theta"],
                 obs_mean=t["obs_mean"], obs_std=t["obs_std"], gen=int(j["gen"]), env_steps=int(j["env_steps"]),
                 best_score=-math.inf if bs is None else float(bs), wall_s=float(j["wall_s"]),
                 rng_state=dict(j["rng_state"]), curve=list(j["curve"]), finished=bool(j["finished"]))
        return st, j


def init_state(cfg: LearnedTrainConfig, seed: int) -> ESState:
    """A fresh run: Xavier-initialised hidden layers, output layer 0 with gate bias 3 (the plain PI)."""
    spec = MLPSpec(cfg.es.hidden, len(obs_names(cfg.task.block)))
    rng = np.random.default_rng([seed, 1])
    theta = np.zeros(spec.n_params)
    w = unflatten(spec, theta)
    last = len(spec.sizes) - 2
    for i, (a, b) in enumerate(zip(spec.sizes[:-1], spec.sizes[1:])):
        if i < last:
            w[f"W{i}"][...] = rng.standard_normal((a, b)) / math.sqrt(a)
    w[f"b{last}"][0] = 3.0
    # observation normaliser from PI loops on their own seeds
    seeds = [int(s) for s in np.random.default_rng([seed, 2]).integers(0, 2**31, 16)]
    sc = rollout_scores([None], _train_task(cfg), seeds)
    std = np.maximum(sc.obs_std, 0.25)
    rng_state = dict(np.random.default_rng([seed, 3]).bit_generator.state)
    return ESState(theta=theta, m=np.zeros_like(theta), v=np.zeros_like(theta), best_theta=theta.copy(),
                   obs_mean=sc.obs_mean, obs_std=std, rng_state=rng_state)


def _train_task(cfg: LearnedTrainConfig) -> RegulationTaskConfig:
    from dataclasses import replace

    return replace(cfg.task, episode_s=cfg.es.episode_s)


# --------------------------------------------------------------------------- one generation
def es_generation(st: ESState, cfg: LearnedTrainConfig) -> dict:
    """One update of ``st`` in place; returns the curve row of the training batch."""
    h = cfg.es
    spec = MLPSpec(h.hidden, len(obs_names(cfg.task.block)))
    rng = np.random.default_rng()
    rng.bit_generator.state = st.rng_state
    eps = rng.standard_normal((h.pairs, spec.n_params))
    seeds = rng.integers(0, 2**31, h.scenarios)
    pop = np.concatenate([st.theta + h.sigma * eps, st.theta - h.sigma * eps, st.theta[None]])
    task = _train_task(cfg)
    pols = [unflatten(spec, p) for p in pop] + [None]
    sc = rollout_scores(pols, task, seeds, (st.obs_mean, st.obs_std), lc=h.lc_weight > 0 or h.lc_amp_weight > 0)
    hours = task.episode_s / 3600.0
    f = fitness(sc, sc.iae[-1], sc.reversals[-1], h, hours, cfg.task.S_bands[1], sc.lc[-1],
                None if sc.lc_amp is None else sc.lc_amp[-1])
    r = centered_ranks(f[:2 * h.pairs])
    grad = ((r[:h.pairs] - r[h.pairs:]) @ eps) / (2 * h.pairs * h.sigma)
    g = -grad + h.weight_decay * st.theta          # minimise -f
    t = st.gen + 1
    st.m = 0.9 * st.m + 0.1 * g
    st.v = 0.999 * st.v + 0.001 * g * g
    mh = st.m / (1 - 0.9 ** t)
    vh = st.v / (1 - 0.999 ** t)
    st.theta = st.theta - h.learning_rate * mh / (np.sqrt(vh) + 1e-8)
    st.rng_state = rng.bit_generator.state
    st.gen = t
    st.env_steps += int(pop.shape[0] + 1) * h.scenarios * task.steps
    return {"gen": t, "env_steps": st.env_steps, "train_fitness_center": float(f[-2]),
            "train_fitness_pop_mean": float(f[:-2].mean())}


def validate(st: ESState, cfg: LearnedTrainConfig, theta: np.ndarray, ref: RolloutScores | None):
    """Score ``theta`` against the PI on the validation loops; returns ``(row, ref)``."""
    spec = MLPSpec(cfg.es.hidden, len(obs_names(cfg.task.block)))
    seeds = [cfg.eval.seed + i for i in range(cfg.eval.n_loops)]
    lc = cfg.es.lc_weight > 0 or cfg.es.lc_amp_weight > 0
    if ref is None:
        ref = rollout_scores([None], cfg.task, seeds, lc=lc)
    sc = rollout_scores([unflatten(spec, theta)], cfg.task, seeds, (st.obs_mean, st.obs_std), lc=lc)
    hours = cfg.task.episode_s / 3600.0
    f = float(fitness(sc, ref.iae[0], ref.reversals[0], cfg.es, hours, cfg.task.S_bands[1], ref.lc[0],
                        None if ref.lc_amp is None else ref.lc_amp[0])[0])
    ratio = sc.iae[0] / ref.iae[0]
    stick = ref.S > 0.005
    row = {"val_fitness": f, "val_iae_ratio_sticky_severe": float(np.median(ratio[stick])) if stick.any() else None,
           "val_iae_ratio_healthy": float(np.median(ratio[~stick])) if (~stick).any() else None,
           "val_travel_per_h": float(np.median(sc.travel[0]) / hours),
           "val_pi_travel_per_h": float(np.median(ref.travel[0]) / hours)}
    if lc and stick.any():
        row["val_lc_share_sticky_severe"] = float(sc.lc[0][stick].mean())
        row["val_pi_lc_share_sticky_severe"] = float(ref.lc[0][stick].mean())
    return row, ref


# --------------------------------------------------------------------------- the run
def _block_meta(cfg: LearnedTrainConfig, st: ESState, command: str, seed: int, which: str) -> dict:
    import sys

    import valve_gym

    return {"name": cfg.name, "which": which, "algorithm": "evolution strategies (Salimans et al. 2017)",
            "train_command": command, "seed": seed, "generations": st.gen, "env_steps": st.env_steps,
            "train_wall_s": st.wall_s, "task": config_to_dict(cfg.task), "es": config_to_dict(cfg.es),
            "versions": {"valve_gym": getattr(valve_gym, "__version__", "unknown"), "numpy": np.__version__,
                         "python": sys.version.split()[0]}}


def _write_outputs(out: Path, cfg: LearnedTrainConfig, st: ESState, command: str, seed: int) -> None:
    spec = MLPSpec(cfg.es.hidden, len(obs_names(cfg.task.block)))
    bs = cfg.task.block
    save_learned(out / "final", st.theta, spec, st.obs_mean, st.obs_std, bs,
                 _block_meta(cfg, st, command, seed, "final"))
    save_learned(out / "best", st.best_theta, spec, st.obs_mean, st.obs_std, bs,
                 _block_meta(cfg, st, command, seed, "best (highest validation fitness)"))
    _write_curve(out, st.curve)


def _write_curve(out: Path, curve: list) -> None:
    from valve_gym._io import write_atomic

    keys = []
    for row in curve:
        keys += [k for k in row if k not in keys]
    lines = [",".join(keys)] + [",".join("" if row.get(k) is None else f"{row[k]:.6g}" if isinstance(row.get(k), float)
                                         else str(row.get(k)) for k in keys) for row in curve]
    text = "\n".join(lines) + "\n"
    write_atomic(out / "curve.csv", lambda f: f.write(text.encode()))


def train_learned(cfg: LearnedTrainConfig, out: Path, resume: Path | None = None, seed: int | None = None,
                  generations: int | None = None, command: str = "", progress: bool = True) -> dict:
    """Train (or resume) the learned compensator; returns the summary (also ``summary.json``).

    Returns a summary with ``status``: ``'finished'``, ``'already finished'`` (a resumed finished
    run: nothing changed) or ``'interrupted'`` (SIGINT/SIGTERM: the checkpoint of the last
    completed generation was written).
    """
    from dataclasses import replace

    if seed is not None:
        cfg = replace(cfg, seed=int(seed))
    if generations is not None:
        cfg = replace(cfg, es=replace(cfg.es, generations=int(generations)))
    ck = out / "checkpoints" / "latest"
    meta = {"config": config_to_dict(cfg), "command": command}
    if resume is not None:
        st, j = ESState.load(resume)
        if j.get("config", {}).get("task") != config_to_dict(cfg.task) or \
                j.get("config", {}).get("es", {}).get("hidden") != list(cfg.es.hidden):
            raise ValueError(f"checkpoint {resume} was trained on another task or network; resume with the "
                             f"config of that run")
        if st.finished and st.gen >= cfg.es.generations:
            return {"status": "already finished", "gen": st.gen, "out": str(out)}
        st.finished = False
        if j.get("command") and command:
            command = f"{j['command']} (continued by: {command})"
        meta["command"] = command
    else:
        st = init_state(cfg, cfg.seed)
    ref = None
    t_start = time.perf_counter() - st.wall_s
    with stop_on_signals():
        while st.gen < cfg.es.generations:
            snap = _copy_state(st)
            try:
                row = es_generation(st, cfg)
                if st.gen % cfg.eval.every == 0 or st.gen == cfg.es.generations:
                    vrow, ref = validate(st, cfg, st.theta, ref)
                    row.update(vrow)
                    if vrow["val_fitness"] > st.best_score:
                        st.best_score = vrow["val_fitness"]
                        st.best_theta = st.theta.copy()
            except Interrupted:
                st = snap
                st.wall_s = time.perf_counter() - t_start
                st.save(ck, meta)
                _write_outputs(out, cfg, st, command, cfg.seed)
                return {"status": "interrupted", "gen": st.gen, "signal": STOP["signal"], "out": str(out)}
            st.wall_s = time.perf_counter() - t_start
            row["wall_s"] = st.wall_s
            st.curve.append(row)
            if progress:
                _print_row(row, cfg.es.generations)
            if st.gen % cfg.checkpoint_every == 0:
                st.save(ck, meta)
        st.finished = True
        st.save(ck, meta)
        _write_outputs(out, cfg, st, command, cfg.seed)
    return {"status": "finished", "gen": st.gen, "env_steps": st.env_steps, "train_wall_s": st.wall_s,
            "best_val_fitness": st.best_score, "out": str(out), "curve": st.curve[-1] if st.curve else None}


def _copy_state(st: ESState) -> ESState:
    import copy

    return copy.deepcopy(st)


def _fmt(x, spec: str) -> str:
    return "n/a" if x is None else format(x, spec)


def _print_row(row: dict, total: int) -> None:
    msg = (f"gen {row['gen']}/{total}  steps {row['env_steps']:.3g}  wall {row['wall_s']:.0f} s  "
           f"fitness {row['train_fitness_center']:+.3f}")
    if "val_fitness" in row:
        msg += (f"  | val fitness {_fmt(row['val_fitness'], '+.3f')}, IAE/PI sticky+severe "
                f"{_fmt(row['val_iae_ratio_sticky_severe'], '.3f')}, "
                f"healthy {_fmt(row['val_iae_ratio_healthy'], '.3f')}, "
                f"travel {_fmt(row['val_travel_per_h'], '.2f')}/h (PI {_fmt(row['val_pi_travel_per_h'], '.2f')}/h)")
    print(msg, flush=True)


def summary_json(summary: dict) -> str:
    """The summary as JSON text."""
    return json.dumps(summary, indent=1, default=str)
