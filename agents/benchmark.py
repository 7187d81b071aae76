"""The compensator benchmark: PI, PI + knocker and PPO on the same sticky valves.

``valve-gym benchmark [--quick] [--out DIR] [--config FILE] [--policy ZIP ...]``

Every controller runs one episode on each valve of a fixed, seeded set
(default 120 valves from healthy to severe stiction, ``tau`` and ``v_max``
randomised too, a quarter of them outside the friction range the policies
were trained on), all valves at once in one vector environment, with the
environment's set-point steps, load disturbances and measurement noise; valve
``i`` gets the same scenario (seed ``seed + i``) under every controller.

Bands (by the valve parameters, see :class:`BandRule`):

``healthy``
    ``z_max <= 0.01 s`` and ``e_dead <= 0.005`` (the "healthy" valve of
    Yamé & El Bahir has ``z_max = 0.005 s``, ``e_dead = 0.005``).
``sticky``
    Not healthy, and every parameter inside the training range of the
    policies (``z_max`` 0.002-0.5 s, ``e_dead`` 0-0.02, ``tau`` 0.05-0.2 s,
    ``v_max`` 0.2-1 /s: the environment's default randomisation).
``outside_training``
    Any parameter outside that training range (here: severe friction).
``all``
    Every valve.

Outputs in ``--out`` (default ``benchmark_results``), each written atomically:
``results.md`` (tables, targets, where controllers lose), ``results.csv``
(long format: ``controller, band, metric, median, q25, q75, n``),
``episodes.csv`` (raw per-episode metrics), ``valves.csv``, ``config.yaml``
(the exact configuration used), and the figures ``boxplots.png`` (IAE and
valve travel per band and controller), ``trajectories.png`` (level, OP and
stem of every controller on the same sticky valve) and ``op_vs_stem.png``.
"""
from __future__ import annotations

import argparse
import glob
import io
import math
import os
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from valve_gym.config import read_yaml, ConfigError, EnvConfig, config_to_dict, load_config

from .evaluate import VALVE_KEYS, episode_metrics, make_eval_env, rollout
from .knocker import KNOCKER_DEFAULTS, KnockerController
from .pi import PIController, default_tuning

__all__ = ["BenchmarkConfig", "ValveGroup", "ValveSet", "BandRule", "PIConfig", "KnockerConfig",
           "load_benchmark_config", "make_valve_set", "assign_bands", "summarise", "paired_ratios",
           "run_benchmark", "BenchmarkResult", "main", "BANDS", "METRICS", "POLICY_DIR"]

Range = Tuple[float, float]

#: Band names, in table order.
BANDS = ("healthy", "sticky", "outside_training", "all")

#: Metrics summarised per controller and band (keys of the per-episode table).
METRICS = ("iae", "ise", "error_std", "lc_present", "lc_amplitude", "lc_period", "crest_factor",
           "hagglund_alarms", "valve_travel", "valve_reversals_per_hour", "op_travel",
           "op_reversals_per_hour", "return")

#: Metrics whose statistics use only the episodes with a limit cycle.
_LC_ONLY = ("lc_amplitude", "lc_period")

#: Where the shipped policies live.
POLICY_DIR = Path(__file__).resolve().parent / "policies"

_TUNING = default_tuning()


# --------------------------------------------------------------------------- config
def _rng_check(name, r, lo=0.0):
    if not (isinstance(r, tuple) and len(r) == 2 and r[0] <= r[1] and r[0] >= lo):
        raise ConfigError(f"{name} must be [low, high] with {lo} <= low <= high, got {list(r)!r}")


@dataclass(frozen=True)
class ValveGroup:
    """One group of benchmark valves, drawn from the given ranges.

    ``z_max`` is drawn log-uniformly, the others uniformly.

    Parameters
    ----------
    n : int, number of valves (>= 0)
    z_max : (2,) s (low > 0)
    e_dead : (2,) fraction of stroke
    tau : (2,) s (low > 0)
    v_max : (2,) 1/s (low > 0)
    """

    n: int = 0
    z_max: Range = (0.002, 0.01)
    e_dead: Range = (0.0, 0.005)
    tau: Range = (0.05, 0.2)
    v_max: Range = (0.2, 1.0)

    def __post_init__(self):
        if self.n < 0:
            raise ConfigError(f"n must be >= 0, got {self.n}")
        _rng_check("z_max", self.z_max)
        if self.z_max[0] <= 0:
            raise ConfigError(f"z_max is drawn log-uniformly and needs low > 0, got {list(self.z_max)!r}")
        _rng_check("e_dead", self.e_dead)
        if self.e_dead[1] > 0.5:
            raise ConfigError(f"e_dead must be <= 0.5, got {list(self.e_dead)!r}")
        _rng_check("tau", self.tau)
        _rng_check("v_max", self.v_max)
        if self.tau[0] <= 0 or self.v_max[0] <= 0:
            raise ConfigError("tau and v_max ranges need low > 0")


@dataclass(frozen=True)
class ValveSet:
    """The three groups the benchmark valves are drawn from (see the module docstring)."""

    healthy: ValveGroup = field(default_factory=lambda: ValveGroup(n=30, z_max=(0.002, 0.01),
                                                                   e_dead=(0.0, 0.005)))
    sticky: ValveGroup = field(default_factory=lambda: ValveGroup(n=60, z_max=(0.01, 0.5),
                                                                  e_dead=(0.0, 0.02)))
    severe: ValveGroup = field(default_factory=lambda: ValveGroup(n=30, z_max=(0.5, 1.5),
                                                                  e_dead=(0.02, 0.04)))


@dataclass(frozen=True)
class BandRule:
    """How valves are put into bands (by their parameters).

    Parameters
    ----------
    healthy_z_max : float, s; healthy_e_dead : float
        A valve is healthy when ``z_max <= healthy_z_max`` and ``e_dead <= healthy_e_dead``.
    train_z_max, train_e_dead, train_tau, train_v_max : (2,) ranges
        The friction range the policies were trained on (the environment's
        default randomisation); a valve with any parameter outside is
        ``outside_training``.
    """

    healthy_z_max: float = 0.01
    healthy_e_dead: float = 0.005
    train_z_max: Range = (0.002, 0.5)
    train_e_dead: Range = (0.0, 0.02)
    train_tau: Range = (0.05, 0.2)
    train_v_max: Range = (0.2, 1.0)


@dataclass(frozen=True)
class PIConfig:
    """PI tuning of the ``pi`` and ``knocker`` controllers (default: SIMC, see :mod:`agents.pi`)."""

    Kc: float = round(_TUNING.Kc, 4)
    Ti: float = round(_TUNING.Ti, 2)


@dataclass(frozen=True)
class KnockerConfig:
    """Knocker parameters (see :mod:`agents.knocker`)."""

    a: float = KNOCKER_DEFAULTS["a"]
    tau_k: float = KNOCKER_DEFAULTS["tau_k"]
    h_k: float = KNOCKER_DEFAULTS["h_k"]


@dataclass(frozen=True)
class QuickConfig:
    """Settings of ``--quick`` (a smoke run for tests)."""

    n_healthy: int = 2
    n_sticky: int = 3
    n_severe: int = 1
    episode_seconds: float = 120.0


@dataclass(frozen=True)
class BenchmarkConfig:
    """Everything that defines a benchmark run (YAML: ``configs/benchmark.yaml``).

    Parameters
    ----------
    seed : int
        Seed of the valve draw; valve ``i`` runs its episode with env seed ``seed + i``.
    env : EnvConfig
        The scenario (set points, load, noise, tank, episode length). Its
        ``randomise`` block is not used: every valve is pinned.
    valves : ValveSet
    bands : BandRule
    pi : PIConfig
    knocker : KnockerConfig
    reversal_deadband : float
        Dead band (fraction of stroke) below which a direction change of OP
        or stem does not count as a reversal.
    quick : QuickConfig
    policies : tuple of str
        Policy zips (default: every ``.zip`` shipped in ``agents/policies``);
        relative paths are taken from the config file's folder.
    """

    seed: int = 12345
    env: EnvConfig = field(default_factory=lambda: _default_scenario())
    valves: ValveSet = field(default_factory=ValveSet)
    bands: BandRule = field(default_factory=BandRule)
    pi: PIConfig = field(default_factory=PIConfig)
    knocker: KnockerConfig = field(default_factory=KnockerConfig)
    reversal_deadband: float = 0.001
    quick: QuickConfig = field(default_factory=QuickConfig)
    policies: Tuple[str, ...] = ()


def _default_scenario() -> EnvConfig:
    """The benchmark's scenario, pinned here (not taken from the env's defaults).

    600 s episodes; the set point starts at 0.7-1.3 m (the tank starts at
    1.0 m) and steps by 0.1-0.3 m every 120-240 s within 0.5-1.5 m; the load
    (extra inflow) jumps to +-0.5-2 L/s every 60-240 s; 2 mm white
    measurement noise.
    """
    from valve_gym.config import LoadSchedule, SetpointSchedule

    return EnvConfig(episode_seconds=600.0,
                     setpoint=SetpointSchedule(initial=(0.7, 1.3), interval=(120.0, 240.0),
                                               step=(0.1, 0.3), limits=(0.5, 1.5)),
                     load=LoadSchedule(interval=(60.0, 240.0), magnitude=(0.0005, 0.002)),
                     noise_std=0.002)


def load_benchmark_config(path_or_dict=None) -> BenchmarkConfig:
    """Load a :class:`BenchmarkConfig` from YAML/mapping over the embedded default.

    Unknown keys, strings where numbers belong and out-of-range values raise
    :class:`valve_gym.config.ConfigError` naming the key path (e.g.
    ``valves.sticky.z_max``).

    Examples
    --------
    >>> cfg = load_benchmark_config({"valves": {"sticky": {"n": 10}}})
    >>> cfg.valves.sticky.n, cfg.valves.healthy.n
    (10, 30)
    >>> load_benchmark_config({"valves": {"stiky": {}}})
    Traceback (most recent call last):
    ...
    valve_gym.config.ConfigError: unknown key 'valves.stiky' (did you mean 'sticky'?); the keys of 'valves' are: healthy, sticky, severe
    """
    base_dir = None
    if isinstance(path_or_dict, (str, os.PathLike)):
        p = Path(path_or_dict)
        data = read_yaml(p, "benchmark config")
        base_dir = p.resolve().parent
        src = f" in {p}"
    else:
        data = dict(path_or_dict or {})
        src = ""
    if not isinstance(data, Mapping):
        raise ConfigError(f"a benchmark config must be a mapping{src}, got {type(data).__name__}")
    data = dict(data)
    pols = data.pop("policies", None)
    if pols is None:
        pols = []
    if isinstance(pols, str) or not isinstance(pols, (list, tuple)) \
            or not all(isinstance(x, str) for x in pols):
        raise ConfigError(f"policies must be a list of .zip paths{src}, got {pols!r}")
    if base_dir is not None:
        pols = [str(base_dir / x) if not os.path.isabs(x) else x for x in pols]
    try:
        cfg = load_config(data, cls=BenchmarkConfig, base=BenchmarkConfig())
    except ConfigError as exc:
        raise ConfigError(f"{exc}{src}") from None
    return replace(cfg, policies=tuple(pols))


def benchmark_config_to_dict(cfg: BenchmarkConfig) -> dict:
    d = config_to_dict(cfg)
    d["policies"] = list(cfg.policies)
    return d


# --------------------------------------------------------------------------- valves
def make_valve_set(cfg: BenchmarkConfig, quick: bool = False):
    """The benchmark valves as a :class:`pandas.DataFrame` (one row per valve).

    Columns ``valve`` (index), ``group``, ``z_max``, ``e_dead``, ``tau``,
    ``v_max``, ``band`` and ``seed`` (the env seed of its episode). The draw
    depends only on ``cfg.seed`` and the group settings.
    """
    import pandas as pd

    rng = np.random.default_rng(cfg.seed)
    rows = []
    ns = {"healthy": cfg.valves.healthy.n, "sticky": cfg.valves.sticky.n, "severe": cfg.valves.severe.n}
    if quick:
        q = cfg.quick
        ns = {"healthy": q.n_healthy, "sticky": q.n_sticky, "severe": q.n_severe}
    for name in ("healthy", "sticky", "severe"):
        g: ValveGroup = getattr(cfg.valves, name)
        n = ns[name]
        # always draw the full group so that --quick takes a prefix of the same valves
        nd = max(n, g.n)
        u = rng.random((nd, 4))
        z = g.z_max[0] * np.exp(u[:, 0] * math.log(g.z_max[1] / g.z_max[0]))
        ed = g.e_dead[0] + u[:, 1] * (g.e_dead[1] - g.e_dead[0])
        tau = g.tau[0] + u[:, 2] * (g.tau[1] - g.tau[0])
        vm = g.v_max[0] + u[:, 3] * (g.v_max[1] - g.v_max[0])
        for i in range(n):
            rows.append({"group": name, "z_max": z[i], "e_dead": ed[i], "tau": tau[i], "v_max": vm[i]})
    df = pd.DataFrame(rows, columns=["group", *VALVE_KEYS])
    if df.empty:
        raise ConfigError("the benchmark has no valves: set valves.<group>.n > 0")
    df.insert(0, "valve", np.arange(len(df)))
    df["band"] = assign_bands(df, cfg.bands)
    df["seed"] = cfg.seed + df["valve"]
    return df


def assign_bands(valves, rule: BandRule) -> np.ndarray:
    """Band of each valve (``healthy``, ``sticky`` or ``outside_training``) from its parameters."""
    z, ed = np.asarray(valves["z_max"], float), np.asarray(valves["e_dead"], float)
    tau, vm = np.asarray(valves["tau"], float), np.asarray(valves["v_max"], float)
    eps = 1e-12

    def out(x, r):
        return (x < r[0] - eps) | (x > r[1] + eps)

    outside = out(z, rule.train_z_max) | out(ed, rule.train_e_dead) | out(tau, rule.train_tau) \
        | out(vm, rule.train_v_max)
    healthy = (z <= rule.healthy_z_max + eps) & (ed <= rule.healthy_e_dead + eps) & ~outside
    return np.where(outside, "outside_training", np.where(healthy, "healthy", "sticky"))


# --------------------------------------------------------------------------- controllers
def make_controllers(cfg: BenchmarkConfig, policies: Sequence[str] = ()) -> list:
    """``pi``, ``knocker`` and one :class:`~agents.ppo.PPOController` per policy file."""
    Ts = float(cfg.env.control_period)
    pi = PIController(Kc=cfg.pi.Kc, Ti=cfg.pi.Ti, Ts=Ts, name="pi")
    kn = KnockerController(PIController(Kc=cfg.pi.Kc, Ti=cfg.pi.Ti, Ts=Ts), a=cfg.knocker.a,
                           tau_k=cfg.knocker.tau_k, h_k=cfg.knocker.h_k, name="knocker")
    ctrls = [pi, kn]
    names = {"pi", "knocker"}
    for path in policies:
        from .ppo import load_policy

        c = load_policy(path, name=Path(path).stem)  # label = file name (ppo.zip -> ppo)
        base, k = c.name, 2
        while c.name in names:
            c.name = f"{base}_{k}"
            k += 1
        names.add(c.name)
        ctrls.append(c)
    return ctrls


def default_policies() -> List[str]:
    """The policy zips shipped in :data:`POLICY_DIR` (sorted)."""
    return sorted(glob.glob(str(POLICY_DIR / "*.zip")))


# --------------------------------------------------------------------------- statistics
def _stats(x: np.ndarray):
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), float("nan"), float("nan"), 0
    q25, med, q75 = np.percentile(x, [25, 50, 75])
    return float(med), float(q25), float(q75), int(x.size)


def _band_masks(episodes) -> Dict[str, np.ndarray]:
    b = episodes["band"].to_numpy()
    return {name: (b == name) if name != "all" else np.ones(len(b), bool) for name in BANDS}


def summarise(episodes, metrics: Sequence[str] = METRICS):
    """Long-format summary: one row per ``controller, band, metric``.

    Columns ``controller, band, metric, median, q25, q75, n``. ``lc_amplitude``
    and ``lc_period`` are summarised over the episodes with a limit cycle
    (``n`` says how many); ``lc_present`` is 0/1 per episode, its median
    and quartiles are those of that indicator (its mean is in ``results.md``).
    """
    import pandas as pd

    rows = []
    for ctrl, df in episodes.groupby("controller", sort=False):
        masks = _band_masks(df)
        for band in BANDS:
            m = masks[band]
            for metric in metrics:
                x = df[metric].to_numpy()[m]
                if metric in _LC_ONLY:
                    x = x[df["lc_present"].to_numpy()[m] > 0.5]
                med, q25, q75, n = _stats(x)
                rows.append({"controller": ctrl, "band": band, "metric": metric, "median": med,
                             "q25": q25, "q75": q75, "n": n})
    return pd.DataFrame(rows, columns=["controller", "band", "metric", "median", "q25", "q75", "n"])


def paired_ratios(episodes, metric: str, ref: str = "pi"):
    """Per-valve ratio ``metric(controller) / metric(ref)`` as a DataFrame (valve x controller)."""
    piv = episodes.pivot(index="valve", columns="controller", values=metric)
    den = piv[ref].to_numpy()
    out = piv.div(np.where(den > 0, den, np.nan), axis=0)
    return out


def paired_summary(episodes, ref: str = "pi"):
    """Long-format rows of the paired ratios ``iae_ratio_vs_pi`` and ``valve_travel_ratio_vs_pi``."""
    import pandas as pd

    rows = []
    bands = episodes.drop_duplicates("valve").set_index("valve")["band"]
    for metric in ("iae", "valve_travel", "error_std"):
        r = paired_ratios(episodes, metric, ref)
        band_of = bands.reindex(r.index).to_numpy()
        for ctrl in r.columns:
            if ctrl == ref:
                continue
            for band in BANDS:
                m = np.ones(len(r), bool) if band == "all" else band_of == band
                med, q25, q75, n = _stats(r[ctrl].to_numpy()[m])
                rows.append({"controller": ctrl, "band": band, "metric": f"{metric}_ratio_vs_{ref}",
                             "median": med, "q25": q25, "q75": q75, "n": n})
    return pd.DataFrame(rows, columns=["controller", "band", "metric", "median", "q25", "q75", "n"])


# --------------------------------------------------------------------------- atomic writes
def _atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (:func:`valve_gym._io.write_atomic`)."""
    from valve_gym._io import write_atomic

    write_atomic(path, lambda f: f.write(data))
    _readable(str(path))


def _readable(path: str) -> None:
    """Give a written file the usual permissions under the umask (temporary files are 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(path, 0o666 & ~mask)


def _atomic_write_text(path: Path, text: str) -> None:
    _atomic_write_bytes(path, text.encode("utf-8"))


def _save_fig(fig, path: Path) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    _atomic_write_bytes(path, buf.getvalue())


# --------------------------------------------------------------------------- running
@dataclass
class BenchmarkResult:
    """What :func:`run_benchmark` returns.

    Attributes
    ----------
    valves : DataFrame, one row per valve
    episodes : DataFrame, per-episode metrics (one row per controller and valve)
    summary : DataFrame, long format ``controller, band, metric, median, q25, q75, n``
    rollouts : dict controller -> Rollout
    controllers : list of controller names, in run order
    example_valve : int, the sticky valve of the trajectory figures
    targets : dict, the PPO targets (see :func:`ppo_targets`)
    seconds : float, wall time of the simulations
    config : BenchmarkConfig (as run, quick settings applied)
    """

    valves: object
    episodes: object
    summary: object
    rollouts: dict
    controllers: list
    example_valve: int
    targets: dict
    seconds: float
    config: BenchmarkConfig


def run_benchmark(cfg: BenchmarkConfig = None, quick: bool = False, policies: Optional[Sequence[str]] = None,
                  progress: bool = True) -> BenchmarkResult:
    """Run every controller on every benchmark valve; returns the tables (no files).

    Parameters
    ----------
    cfg : BenchmarkConfig (default: the embedded default)
    quick : bool, few valves and short episodes (``cfg.quick``)
    policies : sequence of str, policy zips (default ``cfg.policies`` or the shipped ones)
    progress : bool, show a tqdm bar
    """
    import pandas as pd

    cfg = BenchmarkConfig() if cfg is None else cfg
    if quick:
        cfg = replace(cfg, env=replace(cfg.env, episode_seconds=cfg.quick.episode_seconds))
    if policies is None:
        policies = list(cfg.policies) or default_policies()
    valves = make_valve_set(cfg, quick=quick)
    n = len(valves)
    ctrls = make_controllers(cfg, policies)
    pins = {k: valves[k].to_numpy() for k in VALVE_KEYS}
    seeds = [int(s) for s in valves["seed"]]
    T = cfg.env.episode_steps
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=T * len(ctrls), desc="benchmark", unit="step", file=sys.stderr,
                   dynamic_ncols=True)
    t0 = time.perf_counter()
    frames, rollouts = [], {}
    try:
        for c in ctrls:
            if bar is not None:
                bar.set_postfix_str(f"{c.name} on {n} valves")
            env = make_eval_env(c, n, cfg.env)
            try:
                ro = rollout(c, env, seeds, pins, deterministic=True, progress=bar)
            finally:
                env.close()
            df = episode_metrics(ro, deadband=cfg.reversal_deadband)
            df.insert(0, "controller", c.name)
            df["band"] = valves["band"].to_numpy()
            df["group"] = valves["group"].to_numpy()
            frames.append(df)
            rollouts[c.name] = ro
    finally:
        if bar is not None:
            bar.close()
    seconds = time.perf_counter() - t0
    episodes = pd.concat(frames, ignore_index=True)
    summary = pd.concat([summarise(episodes), paired_summary(episodes)], ignore_index=True)
    ex = pick_example_valve(episodes, valves, cfg.bands)
    targets = ppo_targets(episodes, [c.name for c in ctrls])
    return BenchmarkResult(valves=valves, episodes=episodes, summary=summary, rollouts=rollouts,
                           controllers=[c.name for c in ctrls], example_valve=ex, targets=targets,
                           seconds=seconds, config=cfg)


def pick_example_valve(episodes, valves, rule: BandRule = BandRule()) -> int:
    """The sticky valve shown in the trajectory figures.

    The stickiest valve inside the training range: the sticky-band valve
    with the largest ``z_max / train_z_max[1] + e_dead / train_e_dead[1]``;
    without a sticky valve, the valve with the largest ``z_max``.
    """
    sticky = valves[valves["band"] == "sticky"]
    if len(sticky):
        sev = sticky["z_max"].to_numpy() / rule.train_z_max[1] \
            + sticky["e_dead"].to_numpy() / max(rule.train_e_dead[1], 1e-12)
        return int(sticky["valve"].to_numpy()[int(np.argmax(sev))])
    return int(valves["valve"].to_numpy()[int(np.argmax(valves["z_max"].to_numpy()))])


#: The targets a PPO policy is held to (median over the band, paired per valve).
TARGET_IAE_REDUCTION = 0.30
TARGET_TRAVEL_RATIO = 1.5


def ppo_targets(episodes, controllers: Sequence[str]) -> dict:
    """Paired comparison of each non-PI controller with PI, per band.

    For controller ``c`` and band ``b``: ``iae_reduction`` = 1 - median over
    the band's valves of ``IAE_c / IAE_pi``; ``travel_ratio`` = median of
    ``valve_travel_c / valve_travel_pi``; ``iae_median`` and
    ``iae_median_pi``. The PPO targets are ``iae_reduction >= 0.30`` and
    ``travel_ratio <= 1.5`` on the sticky band.
    """
    out = {}
    r_iae = paired_ratios(episodes, "iae")
    r_tr = paired_ratios(episodes, "valve_travel")
    band_of = episodes.drop_duplicates("valve").set_index("valve")["band"].reindex(r_iae.index).to_numpy()
    for c in controllers:
        if c == "pi":
            continue
        res = {}
        for band in BANDS:
            m = np.ones(len(band_of), bool) if band == "all" else band_of == band
            if not m.any():
                continue
            ri = r_iae[c].to_numpy()[m]
            rt = r_tr[c].to_numpy()[m]
            e = episodes[(episodes["controller"] == c)]
            p = episodes[(episodes["controller"] == "pi")]
            em = e.set_index("valve").reindex(r_iae.index)["iae"].to_numpy()[m]
            pm = p.set_index("valve").reindex(r_iae.index)["iae"].to_numpy()[m]
            res[band] = {"iae_reduction": float(1.0 - np.nanmedian(ri)),
                         "travel_ratio": float(np.nanmedian(rt)),
                         "iae_median": float(np.median(em)), "iae_median_pi": float(np.median(pm)),
                         "n": int(m.sum()), "n_iae_worse": int(np.sum(ri > 1.0)),
                         "n_travel_worse": int(np.sum(rt > 1.0))}
        s = res.get("sticky")
        if s is not None:
            res["meets_iae_target"] = bool(s["iae_reduction"] >= TARGET_IAE_REDUCTION)
            res["meets_travel_target"] = bool(s["travel_ratio"] <= TARGET_TRAVEL_RATIO)
        out[c] = res
    return out


# --------------------------------------------------------------------------- reporting
_MD_METRICS = ("iae", "ise", "error_std", "lc_present", "lc_amplitude", "lc_period", "valve_travel",
               "valve_reversals_per_hour", "op_travel", "op_reversals_per_hour", "return")
_UNITS = {"iae": "m s", "ise": "m² s", "error_std": "m", "lc_present": "share", "lc_amplitude": "m",
          "lc_period": "s", "valve_travel": "strokes", "valve_reversals_per_hour": "1/h",
          "op_travel": "strokes", "op_reversals_per_hour": "1/h", "return": "-",
          "crest_factor": "-", "hagglund_alarms": "-"}


def _fmt(x: float) -> str:
    if x is None or not np.isfinite(x):
        return "–"
    a = abs(x)
    if a == 0:
        return "0"
    if a >= 1000:
        return f"{x:.0f}"
    if a >= 10:
        return f"{x:.1f}"
    if a >= 0.1:
        return f"{x:.3f}"
    return f"{x:.2e}" if a < 1e-3 else f"{x:.4f}"


def markdown_tables(res: BenchmarkResult) -> str:
    """Per band: metrics x controllers, cells ``median [q25, q75]``."""
    s = res.summary
    ep = res.episodes
    lines = []
    counts = res.valves["band"].value_counts()
    for band in BANDS:
        nb = len(res.valves) if band == "all" else int(counts.get(band, 0))
        if nb == 0:
            continue
        lines.append(f"### Band `{band}` ({nb} valves)\n")
        lines.append("| metric | " + " | ".join(res.controllers) + " |")
        lines.append("|---|" + "---|" * len(res.controllers))
        for metric in _MD_METRICS:
            cells = []
            for c in res.controllers:
                row = s[(s.controller == c) & (s.band == band) & (s.metric == metric)]
                if row.empty:
                    cells.append("–")
                    continue
                r = row.iloc[0]
                if metric == "lc_present":
                    m = ep[(ep.controller == c)]
                    if band != "all":
                        m = m[m.band == band]
                    cells.append(f"{100 * m['lc_present'].mean():.0f} %")
                elif r["n"] == 0:
                    cells.append("–")
                else:
                    extra = f" (n={r['n']})" if metric in _LC_ONLY else ""
                    cells.append(f"{_fmt(r['median'])} [{_fmt(r['q25'])}, {_fmt(r['q75'])}]{extra}")
            name = f"{metric} [{_UNITS.get(metric, '-')}]"
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def _targets_md(res: BenchmarkResult) -> str:
    lines = ["## Against PI (paired per valve)\n",
             "Median over the band's valves of the per-valve ratio to PI. IAE reduction = "
             "1 - median(IAE / IAE_PI); travel ratio = median(valve travel / valve travel of PI). "
             f"PPO targets on the sticky band: IAE reduction >= {100 * TARGET_IAE_REDUCTION:.0f} %, "
             f"travel ratio <= {TARGET_TRAVEL_RATIO:g}.\n",
             "| controller | band | IAE reduction | valve travel ratio | median IAE | median IAE of PI "
             "| valves with higher IAE than PI |",
             "|---|---|---|---|---|---|---|"]
    for c, r in res.targets.items():
        for band in BANDS:
            if band not in r:
                continue
            b = r[band]
            lines.append(f"| {c} | {band} | {100 * b['iae_reduction']:+.1f} % | {b['travel_ratio']:.2f}x | "
                         f"{_fmt(b['iae_median'])} | {_fmt(b['iae_median_pi'])} | "
                         f"{b['n_iae_worse']} of {b['n']} |")
    lines.append("")
    for c, r in res.targets.items():
        if not c.startswith("ppo") or "sticky" not in r:
            continue
        s = r["sticky"]
        ok_i = "met" if r["meets_iae_target"] else "NOT met"
        ok_t = "met" if r["meets_travel_target"] else "NOT met"
        lines.append(f"* **{c}**: sticky-band IAE reduction {100 * s['iae_reduction']:+.1f} % "
                     f"(target >= {100 * TARGET_IAE_REDUCTION:.0f} %: {ok_i}); valve travel "
                     f"{s['travel_ratio']:.2f}x PI (target <= {TARGET_TRAVEL_RATIO:g}x: {ok_t}).")
        if "healthy" in r:
            h = r["healthy"]
            lines.append(f"  Healthy band: IAE reduction {100 * h['iae_reduction']:+.1f} %, valve travel "
                         f"{h['travel_ratio']:.2f}x PI.")
        if "outside_training" in r:
            o = r["outside_training"]
            lines.append(f"  Outside the training range: IAE reduction {100 * o['iae_reduction']:+.1f} %, "
                         f"valve travel {o['travel_ratio']:.2f}x PI.")
    lines.append("")
    return "\n".join(lines)


def losses(res: BenchmarkResult) -> List[str]:
    """Plain statements of where a controller does worse than PI (paired medians)."""
    out = []
    for c, r in res.targets.items():
        for band in BANDS:
            if band not in r or band == "all":
                continue
            b = r[band]
            if b["iae_reduction"] < -0.01:
                out.append(f"{c} has a higher IAE than PI on the {band} band "
                           f"({-100 * b['iae_reduction']:.1f} % worse, median of paired ratios).")
            if b["travel_ratio"] > 1.1:
                gain = b["iae_reduction"]
                out.append(f"{c} moves the valve {b['travel_ratio']:.2f}x as much as PI on the {band} band "
                           f"(valve wear) for an IAE change of {100 * gain:+.1f} %.")
        for band in ("sticky", "outside_training"):
            b = r.get(band)
            if b and b["n_iae_worse"] > 0 and b["iae_reduction"] >= -0.01:
                out.append(f"{c} has a higher IAE than PI on {b['n_iae_worse']} of the {b['n']} {band} valves "
                           f"(see ratio_vs_friction.png).")
    if not out:
        out.append("No controller is worse than PI by more than 1 % IAE or 10 % valve travel on any band.")
    return out


def write_report(res: BenchmarkResult, out: Path, command: str = "") -> Dict[str, Path]:
    """Write tables, raw metrics, config and figures into ``out`` (atomically)."""
    import yaml

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = {}
    cols = ["controller", "band", "metric", "median", "q25", "q75", "n"]
    files["results.csv"] = out / "results.csv"
    _atomic_write_text(files["results.csv"], res.summary[cols].to_csv(index=False))
    files["episodes.csv"] = out / "episodes.csv"
    _atomic_write_text(files["episodes.csv"], res.episodes.to_csv(index=False))
    files["valves.csv"] = out / "valves.csv"
    _atomic_write_text(files["valves.csv"], res.valves.to_csv(index=False))
    files["config.yaml"] = out / "config.yaml"
    _atomic_write_text(files["config.yaml"], yaml.safe_dump(benchmark_config_to_dict(res.config),
                                                            sort_keys=False))
    files.update(write_figures(res, out))
    files["results.md"] = out / "results.md"
    _atomic_write_text(files["results.md"], report_markdown(res, command))
    return files


def report_markdown(res: BenchmarkResult, command: str = "") -> str:
    cfg = res.config
    v = res.valves
    ex = v.set_index("valve").loc[res.example_valve]
    counts = v["band"].value_counts()
    lines = ["# Compensator benchmark\n"]
    if command:
        lines.append(f"Command: `{command}`\n")
    lines.append(
        f"{len(v)} valves ({', '.join(f'{b}: {int(counts.get(b, 0))}' for b in BANDS[:-1])}), one "
        f"{cfg.env.episode_seconds:g} s episode each with set-point steps "
        f"({cfg.env.setpoint.step[0]:g}-{cfg.env.setpoint.step[1]:g} m every "
        f"{cfg.env.setpoint.interval[0]:g}-{cfg.env.setpoint.interval[1]:g} s), load steps "
        f"({1000 * cfg.env.load.magnitude[0]:g}-{1000 * cfg.env.load.magnitude[1]:g} L/s every "
        f"{cfg.env.load.interval[0]:g}-{cfg.env.load.interval[1]:g} s) and {1000 * cfg.env.noise_std:g} mm "
        f"measurement noise; valve seed {cfg.seed}. Controllers: {', '.join(res.controllers)}. "
        f"Simulation and scoring took {res.seconds:.1f} s.\n")
    lines.append(
        f"Bands: `healthy` = z_max <= {cfg.bands.healthy_z_max:g} s and e_dead <= "
        f"{cfg.bands.healthy_e_dead:g}; `outside_training` = any of z_max, e_dead, tau, v_max outside "
        f"the policies' training range (z_max {list(cfg.bands.train_z_max)} s, e_dead "
        f"{list(cfg.bands.train_e_dead)}, tau {list(cfg.bands.train_tau)} s, v_max "
        f"{list(cfg.bands.train_v_max)} 1/s); `sticky` = the rest; `all` = every valve. Scores on the true "
        f"level, the applied valve input (OP) and the stem position (MV); cells are median [q25, q75]; "
        f"lc_amplitude and lc_period over the episodes with a limit cycle only (n of them), lc_present as "
        f"the share of episodes with one.\n")
    lines.append(markdown_tables(res))
    lines.append(_targets_md(res))
    lines.append("## Where controllers lose\n")
    lines += [f"* {s}" for s in losses(res)]
    lines.append("")
    lines.append(f"Example valve (figures): #{res.example_valve}, band {ex['band']}, z_max "
                 f"{ex['z_max']:.3g} s, e_dead {ex['e_dead']:.3g}, tau {ex['tau']:.3g} s, v_max "
                 f"{ex['v_max']:.3g} 1/s.\n")
    lines.append("Files: results.csv (long format), episodes.csv (per episode), valves.csv, config.yaml, "
                 "boxplots.png, ratio_vs_friction.png, trajectories.png, op_vs_stem.png.\n")
    return "\n".join(lines)


def write_figures(res: BenchmarkResult, out: Path) -> Dict[str, Path]:
    """Box plots, example trajectories and OP-vs-stem plots (PNG, atomic)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    files = {}
    ep = res.episodes
    ctrls = res.controllers
    colors = {c: plt.get_cmap("tab10")(i % 10) for i, c in enumerate(ctrls)}
    bands = [b for b in BANDS if b == "all" or (res.valves["band"] == b).any()]
    # ---- box plots
    fig, axes = plt.subplots(2, len(bands), figsize=(3.2 * len(bands), 6.4), squeeze=False)
    for j, band in enumerate(bands):
        sub = ep if band == "all" else ep[ep.band == band]
        for i, (metric, label) in enumerate((("iae", "IAE [m s]"), ("valve_travel", "valve travel [strokes]"))):
            ax = axes[i, j]
            data = [sub[sub.controller == c][metric].to_numpy() for c in ctrls]
            bp = ax.boxplot(data, patch_artist=True, showfliers=True, widths=0.6)
            for patch, c in zip(bp["boxes"], ctrls):
                patch.set_facecolor(colors[c])
                patch.set_alpha(0.6)
            ax.set_xticks(range(1, len(ctrls) + 1))
            ax.set_xticklabels(ctrls, rotation=30, ha="right", fontsize=8)
            if i == 0:
                ax.set_title(f"{band} ({sub.valve.nunique()} valves)", fontsize=10)
            if j == 0:
                ax.set_ylabel(label)
            ax.grid(axis="y", alpha=0.3)
    fig.suptitle("Distribution over valves per band")
    fig.tight_layout()
    files["boxplots.png"] = out / "boxplots.png"
    _save_fig(fig, files["boxplots.png"])
    plt.close(fig)
    # ---- paired ratios against the friction
    others = [c for c in ctrls if c != "pi"]
    if others:
        fig, axes = plt.subplots(2, len(others), figsize=(3.6 * len(others), 6.2), squeeze=False,
                                 sharex=True)
        z_of = res.valves.set_index("valve")
        for j, c in enumerate(others):
            for i2, metric in enumerate(("iae", "valve_travel")):
                r = paired_ratios(ep, metric)[c]
                zz = z_of.loc[r.index, "z_max"].to_numpy()
                ed = z_of.loc[r.index, "e_dead"].to_numpy()
                ax = axes[i2, j]
                sc = ax.scatter(zz, r.to_numpy(), c=ed, cmap="viridis", s=14, vmin=0.0,
                                vmax=max(float(res.valves["e_dead"].max()), 1e-6))
                ax.axhline(1.0, color="k", lw=0.8, ls=":")
                ax.axvline(res.config.bands.train_z_max[1], color="r", lw=0.8, ls="--")
                ax.set_xscale("log")
                ax.grid(alpha=0.3)
                if i2 == 0:
                    ax.set_title(c, fontsize=10)
                else:
                    ax.set_xlabel("z_max [s]")
                if j == 0:
                    ax.set_ylabel(("IAE" if metric == "iae" else "valve travel") + " / PI's")
        fig.colorbar(sc, ax=axes.ravel().tolist(), label="e_dead", shrink=0.8)
        fig.suptitle("Per-valve ratio to PI against the friction (red: end of the training range)",
                     fontsize=10)
        files["ratio_vs_friction.png"] = out / "ratio_vs_friction.png"
        _save_fig(fig, files["ratio_vs_friction.png"])
        plt.close(fig)
    # ---- trajectories on the example valve
    i = res.example_valve
    vrow = res.valves.set_index("valve").loc[i]
    fig, axes = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True)
    first = res.rollouts[ctrls[0]]
    axes[0].plot(first.t, first.setpoint[:, i], "k--", lw=1.2, label="set point")
    for c in ctrls:
        ro = res.rollouts[c]
        axes[0].plot(ro.t, ro.level[:, i], color=colors[c], lw=1.0, label=c)
        axes[1].plot(ro.t, ro.u[:, i], color=colors[c], lw=0.8, label=c)
        axes[2].plot(ro.t, ro.stem[:, i], color=colors[c], lw=1.0, label=c)
    axes[0].set_ylabel("level [m]")
    axes[1].set_ylabel("controller output OP [-]")
    axes[2].set_ylabel("stem position MV [-]")
    axes[2].set_xlabel("time [s]")
    axes[0].legend(fontsize=8, ncol=min(4, len(ctrls) + 1))
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle(f"Valve #{i} ({vrow['band']}): z_max {vrow['z_max']:.3g} s, e_dead {vrow['e_dead']:.3g}, "
                 f"tau {vrow['tau']:.3g} s, v_max {vrow['v_max']:.3g} 1/s")
    fig.tight_layout()
    files["trajectories.png"] = out / "trajectories.png"
    _save_fig(fig, files["trajectories.png"])
    plt.close(fig)
    # ---- OP vs stem
    fig, axes = plt.subplots(1, len(ctrls), figsize=(3.3 * len(ctrls), 3.4), squeeze=False)
    for ax, c in zip(axes[0], ctrls):
        ro = res.rollouts[c]
        ax.plot(ro.u[:, i], ro.stem[:, i], color=colors[c], lw=0.7)
        lo = min(ro.u[:, i].min(), ro.stem[:, i].min())
        hi = max(ro.u[:, i].max(), ro.stem[:, i].max())
        ax.plot([lo, hi], [lo, hi], "k:", lw=0.8)
        ax.set_title(c, fontsize=10)
        ax.set_xlabel("OP (valve input) [-]")
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("stem position MV [-]")
    fig.suptitle(f"OP vs stem on valve #{i}")
    fig.tight_layout()
    files["op_vs_stem.png"] = out / "op_vs_stem.png"
    _save_fig(fig, files["op_vs_stem.png"])
    plt.close(fig)
    return files


# --------------------------------------------------------------------------- CLI
def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="valve-gym benchmark",
        description="Compare PI, PI + knocker and PPO policies on a fixed, seeded set of randomised "
                    "sticky valves; write tables (markdown, CSV) and figures.")
    p.add_argument("--quick", action="store_true",
                   help="a few valves and short episodes (smoke test, seconds)")
    p.add_argument("--out", default="benchmark_results", help="output folder (default: %(default)s)")
    p.add_argument("--config", default=None,
                   help="benchmark YAML (default: the embedded default, as configs/benchmark.yaml)")
    p.add_argument("--policy", action="append", default=None, metavar="ZIP",
                   help="policy .zip to include (repeatable; default: the policies shipped in "
                        "agents/policies)")
    p.add_argument("--no-policy", action="store_true", help="PI and knocker only")
    p.add_argument("--seed", type=int, default=None, help="override the valve seed of the config")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv=None) -> int:
    """``valve-gym benchmark``: run, print the markdown table, write the files."""
    args = _parser().parse_args(argv)
    import torch

    torch.set_num_threads(1)
    try:
        cfg = load_benchmark_config(args.config)
    except ConfigError as exc:
        print(f"valve-gym benchmark: bad config: {exc}", file=sys.stderr)
        return 2
    if args.seed is not None:
        cfg = replace(cfg, seed=int(args.seed))
    policies = [] if args.no_policy else args.policy
    if policies:
        missing = [p for p in policies if not os.path.isfile(p)]
        if missing:
            print(f"valve-gym benchmark: policy file(s) not found: {', '.join(missing)}", file=sys.stderr)
            return 2
    t0 = time.perf_counter()
    res = run_benchmark(cfg, quick=args.quick, policies=policies, progress=not args.no_progress)
    command = "valve-gym benchmark " + " ".join(argv if argv is not None else sys.argv[1:])
    files = write_report(res, Path(args.out), command=command.strip())
    wall = time.perf_counter() - t0
    print(markdown_tables(res))
    print(_targets_md(res))
    print("Where controllers lose:")
    for s in losses(res):
        print(f"  - {s}")
    print(f"\n{len(res.valves)} valves x {len(res.controllers)} controllers; simulation {res.seconds:.1f} s, "
          f"total {wall:.1f} s. Results in {Path(args.out).resolve()}: "
          f"{', '.join(sorted(files))}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
