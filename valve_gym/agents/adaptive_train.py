"""Training of the adaptive stiction compensator over a randomised family of plants (evolution strategies).

``python -m valve_gym.agents.adaptive_train --config configs/learned_adaptive.yaml --out runs/adaptive``

The block (:class:`~valve_gym.agents.controllers.adaptive.AdaptiveStiction`) has ten numbers; they are
found by evolution strategies (antithetic pairs, centred ranks, Adam; as :mod:`valve_gym.agents.es`)
in an unbounded space ``z`` mapped into each number's range by a logistic function. Every generation
draws fresh loops (common to the whole population) from the training family, simulated by the package's
physics core (:class:`valve_gym.plant.Plant`):

* processes: the Torricelli tank (area 0.1-1 m^2, full flow 5-30 L/s, level 0.5-1.5 m, steady opening
  0.3-0.7), the integrating (pumped-outlet) tank (area 0.3-2 m^2) and the first-order process
  (``K`` 1-3, ``T`` 3-30 s);
* valves: Riihilahti's, Choudhury's and Kano's friction models (Karnopp's is held out), S in the healthy
  (0-0.5 %), sticky (0.5-5 %, log-uniform) and severe (5-10 %) bands, J uniform in [0, S]; stem time
  constant 0.1-1.5 s;
* scans of 0.5, 1 and 2 s; a constant load of 0.2-3 % of full flow (either sign) plus an Ornstein-Uhlenbeck
  load, small (0.05-0.3 % of full flow) or large (0.5-2 %), correlation time 60-300 s; measurement noise
  0.5-3 mm;
* each loop's PI tuned by SIMC from its linear model (``tau_c = max(T/8, 4 theta)``; integrating:
  ``20 s + 4 theta``).

Fitness of a parameter vector (higher is better), against the plain PI on the same loops::

    f = -mean_sticky log(IAE / IAE_PI) - w_h mean_healthy max(0, log(IAE / IAE_PI))
        - w_lc mean_sticky (lc - lc_PI) - w_t mean max(0, log(travel / (L travel_frictionless PI)))

with ``L = travel_limit``, for ``travel_rule: per_loop`` (the first objective, ``L`` = 1.3). With
``travel_rule: median`` (the default, ``L`` = 1.5) the last term is::

    w_t [max(0, median_sticky log(travel / (L travel_frictionless PI)))
         + mean_healthy max(0, log(travel / (L travel_frictionless PI)))]

(``lc``: the benchmark's ACF limit-cycle detector on the measured error). Bit-reproducible from the
configuration and the seed (numpy only, one thread).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from valve_gym.config import ConfigError, load_config
from valve_gym.signals import ou_sequence

from .controllers.adaptive import PARAM_NAMES, PARAMS, SWITCH_RANGES

__all__ = ["AdaptiveTrainConfig", "TrainLoops", "draw_loops", "draw_loop", "train_adaptive", "to_params", "to_z",
           "score_columns", "fitness", "PI_COLUMN",
           "main"]

_LO = np.array([p[2] for p in PARAMS])
_HI = np.array([p[3] for p in PARAMS])
FRICTION = ("riihilahti", "choudhury", "kano")
#: The block's numbers that make it the plain PI (no reinforcement, no pulses): the reference column.
PI_COLUMN = np.array([0.0, 0.0, 0.3, 0.9, 0.05, 0.01, 3.0, 1.0, 0.1, 3.0])
KINDS = ("tank", "integrating", "first_order")
#: The training families and their scan times [s].
FAMILIES = {"core": (0.5, 1.0, 2.0), "broad": (0.5, 1.0, 2.0, 4.0)}
#: Kinds of load of the broad family (each on top of a constant part).
BROAD_LOADS = ("ou", "walk", "sine", "step")


@dataclass(frozen=True)
class AdaptiveTrainConfig:
    """A training run (YAML: ``configs/learned_adaptive.yaml``).

    Parameters
    ----------
    seed : int
    generations, pairs, loops : int
        Updates; antithetic pairs per update; training loops per update.
    episode_s : float, s
    sigma, learning_rate : float
        Perturbation scale and Adam step in ``z`` space.
    w_healthy, w_lc, w_travel : float
        Fitness weights (module docstring).
    travel_rule : {"per_loop", "median"}
        How travel is charged: ``"per_loop"``, every loop's excess over ``travel_limit`` times the
        frictionless PI's travel; ``"median"``, the sticky loops' median ratio over ``travel_limit`` (the
        benchmark's travel target) plus each healthy loop's excess (wear on a sound valve).
    travel_limit : float
        The travel allowed, over the frictionless PI's (> 0).
    init : tuple of float
        Starting values of the ten numbers (in their ranges).
    family : {"core", "broad"}
        The training family: ``"core"`` (the module docstring's list; the shipped file's) or ``"broad"``,
        the same plants and valves with dead time, a sensor lag, coloured noise, more kinds of load, scans
        of 0.5-4 s and the PI tuned anywhere from tight to sluggish (:func:`draw_loop`).
    answer : {"turn", "reversal"}
        The block's answer test (its ``answer`` setting, 0 or 1), written into the trained file's JSON.
    confirm : float
        How long an answer must hold (the block's ``confirm`` setting, 0-5; 0: off), written into the JSON.
    """

    seed: int = 38
    generations: int = 80
    pairs: int = 6
    loops: int = 30
    episode_s: float = 1800.0
    sigma: float = 0.3
    learning_rate: float = 0.1
    w_healthy: float = 2.0
    w_lc: float = 1.0
    w_travel: float = 1.0
    travel_rule: str = "median"
    travel_limit: float = 1.5
    init: tuple[float, ...] = (0.5, 0.25, 0.3, 0.9, 0.05, 0.01, 3.0, 1.0, 0.1, 3.0)
    family: str = "core"
    answer: str = "turn"
    confirm: float = 0.0

    def __post_init__(self):
        for nm in ("generations", "pairs", "loops"):
            if not (isinstance(getattr(self, nm), int) and getattr(self, nm) >= 1):
                raise ConfigError(f"{nm} must be an integer >= 1, got {getattr(self, nm)!r}")
        if not (self.episode_s >= 60 and self.sigma > 0 and self.learning_rate > 0):
            raise ConfigError("episode_s must be >= 60 s, sigma and learning_rate > 0")
        if min(self.w_healthy, self.w_lc, self.w_travel) < 0:
            raise ConfigError("w_healthy, w_lc and w_travel must be >= 0")
        if self.travel_rule not in ("per_loop", "median"):
            raise ConfigError(f"travel_rule must be 'per_loop' or 'median', got {self.travel_rule!r}")
        if not (isinstance(self.travel_limit, (int, float)) and math.isfinite(self.travel_limit)
                and self.travel_limit > 0):
            raise ConfigError(f"travel_limit must be a number > 0, got {self.travel_limit!r}")
        if self.family not in FAMILIES:
            raise ConfigError(f"family must be one of {list(FAMILIES)}, got {self.family!r}")
        if self.answer not in ("turn", "reversal"):
            raise ConfigError(f"answer must be 'turn' or 'reversal', got {self.answer!r}")
        lo, hi = SWITCH_RANGES["confirm"]
        if isinstance(self.confirm, bool) or not isinstance(self.confirm, (int, float)) \
                or not lo <= self.confirm <= hi:
            raise ConfigError(f"confirm must be a number in [{lo:g}, {hi:g}], got {self.confirm!r}")
        v = np.asarray(self.init, float)
        if v.shape != (len(PARAMS),) or np.any(v <= _LO) or np.any(v >= _HI):
            raise ConfigError(f"init must be {len(PARAMS)} numbers strictly inside their ranges "
                              f"{[(p[0], p[2], p[3]) for p in PARAMS]}, got {list(self.init)!r}")


def to_params(z: np.ndarray) -> np.ndarray:
    """Numbers in their ranges from ``z`` (..., 7)."""
    return _LO + (_HI - _LO) / (1.0 + np.exp(-np.asarray(z, float)))


def to_z(params) -> np.ndarray:
    """Inverse of :func:`to_params`."""
    u = (np.asarray(params, float) - _LO) / (_HI - _LO)
    return np.log(u / (1.0 - u))


@dataclass(frozen=True, eq=False)
class TrainLoops:
    """Training loops of one generation (each a dict of scalars) and their exogenous signals."""

    rows: tuple
    load: tuple
    noise: tuple


def _loop(rng: np.random.Generator) -> dict:
    kind = KINDS[int(rng.integers(3))]
    band = ("healthy", "sticky", "sticky", "severe", "severe")[int(rng.integers(5))]
    u = rng.random(2)
    S = {"healthy": 0.005 * u[0], "sticky": 0.005 * 10.0 ** u[0], "severe": 0.05 + 0.05 * u[0]}[band]
    x0 = rng.uniform(0.3, 0.7)
    row: dict[str, Any] = dict(kind=kind, band=band, model=FRICTION[int(rng.integers(3))], S=S, J=S * u[1], x0=x0,
               tau=rng.uniform(0.1, 1.5), scan=(0.5, 1.0, 2.0)[int(rng.integers(3))],
               level=rng.uniform(0.5, 1.5), area=rng.uniform(0.1, 1.0), q_max=rng.uniform(0.005, 0.03),
               K=rng.uniform(1.0, 3.0), T=rng.uniform(3.0, 30.0), noise=rng.uniform(0.0005, 0.003),
               load=(rng.uniform(0.0005, 0.003) if rng.random() < 0.5 else rng.uniform(0.005, 0.02)),
               load_tau=rng.uniform(60.0, 300.0))
    if kind == "integrating":
        row["area"] = rng.uniform(0.3, 2.0)
    if kind == "first_order":
        row["level"] = row["K"] * x0
    row["Kc"], row["Ti"] = _tuning(row)
    return row


def _broaden(rng: np.random.Generator, row: dict) -> dict:
    """The broad family's extras on a core loop ``row`` (drawn after it, from the same ``rng``).

    A scan of 0.5-4 s; a transport delay on half the loops (first-order: 0.1-3 times ``T``, dead-time
    dominant at the top; tanks: 1-30 s); a sensor lag of 0.05-8 s (log-uniform); coloured measurement noise
    on half the loops (AR(1), correlation time 1-10 s); a load that is an OU process (as the core family's),
    a random walk, a slow sine or a step; and the PI's ``tau_c`` scaled by 0.25-2.5 (log-uniform) around the
    core rule, from tight to sluggish.
    """
    r = dict(row)
    r["scan"] = FAMILIES["broad"][int(rng.integers(len(FAMILIES["broad"])))]
    u = rng.random(8)
    if u[0] < 0.5:
        r["theta"] = 0.0
    elif r["kind"] == "first_order":
        r["theta"] = r["T"] * (0.1 + 2.9 * u[1])
    else:
        r["theta"] = 1.0 + 29.0 * u[1]
    r["tau_s"] = 0.05 * 160.0 ** u[2]
    r["noise_tau"] = 0.0 if u[3] < 0.5 else 1.0 + 9.0 * u[4]
    r["load_kind"] = BROAD_LOADS[int(rng.integers(len(BROAD_LOADS)))]
    r["tc_factor"] = 0.25 * 10.0 ** u[5]
    r["Kc"], r["Ti"] = _tuning(r)
    return r


def _tuning(r: dict) -> tuple[float, float]:
    from .controllers.tuning import simc_pi

    theta = r["tau"] + r["scan"] / 2.0 + r.get("theta", 0.0) + r.get("tau_s", 0.0)
    f = r.get("tc_factor", 1.0)
    if r["kind"] == "integrating":
        tc = (20.0 + 4.0 * theta) * f
        return 1.0 / (r["q_max"] / r["area"] * (tc + theta)), 4.0 * (tc + theta)
    if r["kind"] == "tank":
        k_out = r["x0"] * r["q_max"] / math.sqrt(r["level"])
        K, T = 2.0 * r["q_max"] * math.sqrt(r["level"]) / k_out, 2.0 * r["area"] * math.sqrt(r["level"]) / k_out
    else:
        K, T = r["K"], r["T"]
    return simc_pi(K, T, theta, max(T / 8.0, 4.0 * theta) * f)


def draw_loops(cfg: AdaptiveTrainConfig, generation: int) -> TrainLoops:
    """The loops of one generation: loop ``i`` from ``default_rng([seed, generation, i])``."""
    rows, loads, noises = [], [], []
    for i in range(cfg.loops):
        r, load, noise = draw_loop(np.random.default_rng([cfg.seed, generation, i]), episode_s=cfg.episode_s,
                                   family=cfg.family)
        loads.append(load)
        noises.append(noise)
        rows.append(r)
    return TrainLoops(tuple(rows), tuple(loads), tuple(noises))


def draw_loop(rng: np.random.Generator, episode_s: float = 1800.0, steps: int | None = None, family: str = "core"):
    """One loop of the training family and its signals, from ``rng`` alone.

    Parameters
    ----------
    rng : numpy Generator
    episode_s : float, s
        Record length (``round(episode_s / scan)`` scans) unless ``steps`` is given.
    steps : int, optional
        Record length in scans, whatever the loop's scan.
    family : {"core", "broad"}
        ``"broad"`` adds :func:`_broaden`'s extras (its loops are the core draw's, then more draws).

    Returns
    -------
    row : dict of the loop's scalars (``kind``, ``band``, ``model``, ``S``, ``J``, ``scan``, ``Kc``, ``Ti``, ...)
    load : (T,) extra inflow per scan [m^3/s; process input units for ``first_order``]
    noise : (T,) measurement noise [m or pv units]
    """
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {list(FAMILIES)}, got {family!r}")
    r = _loop(rng)
    if family == "broad":
        r = _broaden(rng, r)
    T = int(steps) if steps is not None else int(round(episode_s / r["scan"]))
    a = math.exp(-r["scan"] / r["load_tau"])
    w = rng.standard_normal(T)
    flow = r["q_max"] if r["kind"] != "first_order" else r["K"]
    offset = (1.0 if rng.random() < 0.5 else -1.0) * rng.uniform(0.002, 0.03)
    ou = ou_sequence(np.concatenate([[0.0], w[:-1]]), a, r["load"])   # x_k = a x_(k-1) + g w_(k-1)
    if family == "core":
        return r, (offset + ou) * flow, rng.standard_normal(T) * r["noise"]
    load = _broad_load(rng, r, w, T, ou)
    v = rng.standard_normal(T)
    noise = v if r["noise_tau"] == 0.0 else ou_sequence(v, math.exp(-r["scan"] / r["noise_tau"]), 1.0)
    return r, (offset + load) * flow, noise * r["noise"]


def _broad_load(rng: np.random.Generator, r: dict, w: np.ndarray, T: int, ou: np.ndarray) -> np.ndarray:
    """The broad family's varying load (fraction of full flow): OU, random walk, slow sine or step.

    The walk, the sine and the step ride on a small OU load (a fifth of the loop's ``load``).
    """
    t = np.arange(T) * r["scan"]
    u = rng.random(4)
    kind = r["load_kind"]
    if kind == "ou":
        return ou
    small = 0.2 * ou
    if kind == "walk":                                  # 2e-5 - 1e-4 per sqrt(s)
        return small + (2e-5 + 8e-5 * u[0]) * math.sqrt(r["scan"]) * np.cumsum(w)
    if kind == "sine":                                  # 0.3-1.5 % of full flow, period 5-20 min
        return small + (0.003 + 0.012 * u[0]) * np.sin(2.0 * math.pi * t / (300.0 + 900.0 * u[1])
                                                         + 2.0 * math.pi * u[2])
    size = (0.01 + 0.02 * u[0]) * (1.0 if u[1] < 0.5 else -1.0)   # step of 1-3 % at 20-60 % of the record
    return small + np.where(t >= (0.2 + 0.4 * u[2]) * T * r["scan"], size, 0.0)


def _base(kind: str, rows: list):
    from valve_gym.params import FirstOrderParams, IntegratingParams, ModelParams, TankParams, ValveParams

    col = {k: np.array([r[k] for r in rows], float) for k in ("area", "q_max", "level", "x0", "K", "T", "tau")}
    valve = ValveParams(tau=col["tau"])
    if kind == "tank":
        proc = TankParams(area=col["area"], q_max=col["q_max"], k_out=col["x0"] * col["q_max"] / np.sqrt(col["level"]))
    elif kind == "integrating":
        proc = IntegratingParams(area=col["area"], q_max=col["q_max"], q_out=col["x0"] * col["q_max"])
    else:
        proc = FirstOrderParams(K=col["K"], T=col["T"])
    if "theta" not in rows[0]:                          # the core family
        return ModelParams(valve=valve, process=proc, process_kind=kind)
    from valve_gym.params import DeadTime, SensorLag

    return ModelParams(valve=valve, process=proc, process_kind=kind,
                       dead_time=DeadTime(theta=np.array([r["theta"] for r in rows], float)),
                       sensor_lag=SensorLag(tau_s=np.array([r["tau_s"] for r in rows], float)))


def _plants(loops: TrainLoops, idx: np.ndarray, reps: int, frictionless: np.ndarray, scan: float):
    """``[(cols, plant)]``: batched core plants over (loop, column) pairs, one per kind x model x friction."""
    from valve_gym.friction import valve_model
    from valve_gym.plant import Plant

    out = []
    n = idx.size
    for kind in KINDS:
        for model in FRICTION:
            for fr in (False, True):
                sel = [(j, c) for c in range(reps) if bool(frictionless[c]) == fr for j in range(n)
                       if loops.rows[idx[j]]["kind"] == kind and loops.rows[idx[j]]["model"] == model]
                if not sel:
                    continue
                rows = [loops.rows[idx[j]] for j, _ in sel]
                S = np.array([r["S"] for r in rows])
                params = valve_model("none" if fr else model, S, np.array([r["J"] for r in rows]),
                                     base=_base(kind, rows))
                cols = np.array([c * n + j for j, c in sel])
                out.append((cols, Plant(params, len(sel), scan_s=scan), np.array([r["level"] for r in rows])))
    return out


def _block(P: np.ndarray, rows: list, scan: float, fixed: np.ndarray | None = None):
    from .controllers.adaptive import SWITCHES, AdaptiveStiction

    reps, n = P.shape[0], len(rows)
    kw = {name: np.repeat(P[:, k], n) for k, name in enumerate(PARAM_NAMES)}
    F = np.zeros((reps, len(SWITCHES))) if fixed is None else np.asarray(fixed, float).reshape(reps, len(SWITCHES))
    kw.update({name: np.repeat(F[:, j], n) for j, name in enumerate(SWITCHES)})
    Kc = np.tile(np.array([r["Kc"] for r in rows]), reps)
    Ti = np.tile(np.array([r["Ti"] for r in rows]), reps)
    return AdaptiveStiction(Kc=Kc, Ti=Ti, scan_s=scan, **kw)


def rollout(loops: TrainLoops, P: np.ndarray, frictionless: np.ndarray, scan: float,
            fixed: np.ndarray | None = None) -> dict:
    """Run columns ``P`` (reps, 10) on the loops of scan ``scan``: per (column, loop) IAE, travel, error.

    ``fixed`` (reps, len(SWITCHES)): each column's untrained settings (:data:`~.controllers.adaptive.SWITCHES`;
    default all 0).

    Returns
    -------
    dict with ``idx`` (n,) loop indices and ``iae``, ``travel`` (reps, n) and ``e`` (T, reps, n) measured errors.
    """
    idx = np.array([i for i, r in enumerate(loops.rows) if r["scan"] == scan], int)
    reps, n = P.shape[0], idx.size
    if n == 0:
        return {"idx": idx}
    from valve_gym.agents.bench.scores import loop_iae
    from valve_gym.loop import Scenario, run_closed_loop
    from valve_gym.plant import PlantOutput

    plants = _plants(loops, idx, reps, frictionless, scan)
    N = reps * n
    start = PlantOutput(*(np.empty(N) for _ in range(4)))
    for cols, p, lv in plants:
        for a, b in zip(start, p.reset(level=lv)):
            a[cols] = b
    sp = start.pv.copy()
    T = loops.noise[idx[0]].size
    noise = np.tile(np.stack([loops.noise[i] for i in idx], axis=1), (1, reps))
    load = np.tile(np.stack([loops.load[i] for i in idx], axis=1), (1, reps))
    blk = _block(P, [loops.rows[i] for i in idx], scan, fixed)
    run = run_closed_loop([(cols, p) for cols, p, _ in plants], blk,
                          Scenario(sp=np.broadcast_to(sp, (T, N)), scan_s=scan, load=load, noise=noise), start=start)
    # the measured error (the core family has no sensor lag: the level plus the noise, as always computed)
    e = sp - run.level[:T] - noise if "theta" not in loops.rows[idx[0]] else sp - run.pv[:T]
    travel = np.zeros(N)
    for k in range(T):
        travel += np.abs(run.stem[k + 1] - run.stem[k])
    return {"idx": idx, "iae": loop_iae(e, scan).reshape(reps, n), "travel": travel.reshape(reps, n),
            "e": e.reshape(T, reps, n)}


def score_columns(loops: TrainLoops, P: np.ndarray, fixed=None) -> dict:
    """Per-loop scores of the columns ``P`` (m, 10), then the plain PI and the frictionless PI beside them.

    ``fixed``: the columns' untrained settings as the block takes them (``{"answer": 0.0 or 1.0, "k_i": ...}``,
    :data:`~.controllers.adaptive.SWITCHES`; one dict for all columns or a list, one per column; a switch left
    out is 0).

    Returns
    -------
    dict with ``iae``, ``travel``, ``lc``, ``amplitude`` and ``offset`` (m + 2, n): rows ``0..m-1`` the columns,
    ``m`` the plain PI (:data:`PI_COLUMN`), ``m + 1`` the PI on the frictionless valve; ``lc`` 1.0 where the
    benchmark's detector finds a limit cycle in the measured error (sticky loops only, 0 on healthy ones),
    ``amplitude`` its amplitude (0 where none), ``offset`` the mean measured error [pv]; and ``healthy`` (n,)
    bool.
    """
    from valve_gym.oscillation import detect_oscillation

    from .controllers.adaptive import SWITCHES

    per = [{}] * len(P) if fixed is None else [fixed] * len(P) if isinstance(fixed, dict) else list(fixed)
    F = np.array([[float(f.get(k, 0.0)) for k in SWITCHES] for f in [*per, {}, {}]])     # the two PIs: all off
    cols = np.vstack([P, PI_COLUMN, PI_COLUMN])
    fr = np.zeros(len(cols), bool)
    fr[-1] = True
    c, n = len(cols), len(loops.rows)
    iae, trav, lc = np.zeros((c, n)), np.zeros((c, n)), np.zeros((c, n))
    offset, amp = np.zeros((c, n)), np.zeros((c, n))
    healthy = np.array([r["band"] == "healthy" for r in loops.rows])
    for scan in sorted({float(r["scan"]) for r in loops.rows}):
        r = rollout(loops, cols, fr, scan, F)
        if r["idx"].size == 0:
            continue
        iae[:, r["idx"]], trav[:, r["idx"]] = r["iae"], r["travel"]
        offset[:, r["idx"]] = r["e"].mean(axis=0)
        for j, i in enumerate(r["idx"]):
            if not healthy[i]:
                osc = [detect_oscillation(r["e"][:, k, j], scan, "benchmark") for k in range(c)]
                lc[:, i] = [o.present for o in osc]
                amp[:, i] = [o.amplitude for o in osc]
    return {"iae": iae, "travel": trav, "lc": lc, "offset": offset, "amplitude": amp, "healthy": healthy}


def evaluate(loops: TrainLoops, P: np.ndarray, cfg: AdaptiveTrainConfig) -> np.ndarray:
    """Fitness of each row of ``P`` (m, 10) on ``loops`` (module docstring), against the PI run beside them."""
    from .adaptive import ANSWERS

    return fitness(score_columns(loops, P, {"answer": ANSWERS[cfg.answer], "confirm": float(cfg.confirm)}),
                   P.shape[0], cfg)


def fitness(sc: dict, m: int, cfg: AdaptiveTrainConfig) -> np.ndarray:
    """Fitness (m,) of the first ``m`` columns of the scores ``sc`` (:func:`score_columns`) under ``cfg``."""
    iae, trav, lc, healthy = sc["iae"], sc["travel"], sc["lc"], sc["healthy"]
    lr = np.log(iae[:m] / iae[m])
    f = -np.where(healthy, 0.0, lr).sum(1) / max((~healthy).sum(), 1)
    f -= cfg.w_healthy * np.where(healthy, np.maximum(lr, 0.0), 0.0).sum(1) / max(healthy.sum(), 1)
    f -= cfg.w_lc * np.where(healthy, 0.0, lc[:m] - lc[m]).sum(1) / max((~healthy).sum(), 1)
    excess = np.log(np.maximum(trav[:m], 1e-12) / (cfg.travel_limit * np.maximum(trav[m + 1], 1e-9)))
    if cfg.travel_rule == "per_loop":
        f -= cfg.w_travel * np.maximum(excess, 0.0).mean(1)
    else:
        sticky = ~healthy
        med = np.median(excess[:, sticky], axis=1) if sticky.any() else np.zeros(m)
        f -= cfg.w_travel * (np.maximum(med, 0.0)
                             + np.where(healthy, np.maximum(excess, 0.0), 0.0).sum(1) / max(healthy.sum(), 1))
    return f


def train_adaptive(cfg: AdaptiveTrainConfig, out: Path | None = None, progress=None) -> tuple[np.ndarray, list]:
    """Run the evolution strategies of ``cfg``; returns the final numbers (7,) and the learning curve.

    With ``out``, writes ``adaptive.safetensors`` + ``adaptive.json`` and ``curve.csv`` there.
    """
    from .es import centered_ranks

    t0 = time.perf_counter()
    z = to_z(cfg.init)
    mom, vel = np.zeros_like(z), np.zeros_like(z)
    curve = []
    for g in range(cfg.generations):
        eps = np.random.default_rng([cfg.seed, g, 1_000_000]).standard_normal((cfg.pairs, z.size))
        Z = np.vstack([z[None, :], z + cfg.sigma * eps, z - cfg.sigma * eps])
        f = evaluate(draw_loops(cfg, g), to_params(Z), cfg)
        r = centered_ranks(f[1:])
        grad = ((r[:cfg.pairs] - r[cfg.pairs:])[:, None] * eps).sum(0) / (2 * cfg.pairs * cfg.sigma)
        mom = 0.9 * mom + 0.1 * grad
        vel = 0.999 * vel + 0.001 * grad * grad
        z = z + cfg.learning_rate * (mom / (1 - 0.9 ** (g + 1))) / (np.sqrt(vel / (1 - 0.999 ** (g + 1))) + 1e-8)
        row = {"generation": g + 1, "fitness_centre": float(f[0]), "wall_s": time.perf_counter() - t0,
               **dict(zip(PARAM_NAMES, to_params(z).tolist()))}
        curve.append(row)
        if progress:
            progress(f"gen {g + 1:>3}/{cfg.generations} fitness {f[0]:+.3f} "
                     + " ".join(f"{k}={v:.3g}" for k, v in zip(PARAM_NAMES, to_params(z)))
                     + f" ({row['wall_s']:.0f} s)")
    params = to_params(z)
    if out is not None:
        _write(Path(out), cfg, params, curve, time.perf_counter() - t0)
    return params, curve


def _write(out: Path, cfg: AdaptiveTrainConfig, params: np.ndarray, curve: list, wall: float) -> None:
    import platform

    from valve_gym._io import write_atomic

    from .adaptive import save_adaptive

    out.mkdir(parents=True, exist_ok=True)
    meta = {"config": asdict(cfg), "answer": cfg.answer, "confirm": float(cfg.confirm), "seed": cfg.seed,
            "train_wall_s": round(wall, 1),
            "command": "python -m valve_gym.agents.adaptive_train " + " ".join(sys.argv[1:]),
            "versions": {"python": platform.python_version(), "numpy": np.__version__}}
    save_adaptive(out / "adaptive", params, meta)
    head = list(curve[0]) if curve else ["generation"]
    text = ",".join(head) + "\n" + "".join(",".join(f"{r[h]:.6g}" for h in head) + "\n" for r in curve)
    write_atomic(out / "curve.csv", lambda f: f.write(text.encode("utf-8")))


def load_train_config(source) -> AdaptiveTrainConfig:
    """An :class:`AdaptiveTrainConfig` from a YAML file or a mapping (keys left out keep the defaults)."""
    cfg = load_config(source, cls=AdaptiveTrainConfig, base=AdaptiveTrainConfig())  # pyright: ignore[reportArgumentType]
    if not isinstance(cfg, AdaptiveTrainConfig):  # pragma: no cover
        raise ConfigError(f"could not build a training config from {source!r}")
    return cfg


def main(argv=None) -> int:
    """Command line: train and write the block; 0 on success, 2 on a bad config."""
    ap = argparse.ArgumentParser(prog="python -m valve_gym.agents.adaptive_train",
                                 description="Train the adaptive stiction compensator (docs/learned.md).")
    ap.add_argument("--config", default=None, help="training YAML (default: the built-in defaults)")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--seed", type=int, default=None, help="override the config's seed")
    a = ap.parse_args(argv)
    try:
        cfg = load_train_config(a.config) if a.config else AdaptiveTrainConfig()
        if a.seed is not None:
            from dataclasses import replace

            cfg = replace(cfg, seed=int(a.seed))
    except (ConfigError, OSError) as exc:
        print(f"adaptive_train: {exc}", file=sys.stderr)
        return 2
    params, _ = train_adaptive(cfg, Path(a.out), progress=lambda s: print(s, file=sys.stderr, flush=True))
    print(json.dumps(dict(zip(PARAM_NAMES, params.tolist()))))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
