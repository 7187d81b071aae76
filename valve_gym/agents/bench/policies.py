"""Bring your own policy: an agent trained on ``ValveTankRegulation-v0`` as a DCS block in the benchmark.

A policy of the regulation env maps the block's observation to the action ``(gate, correction)`` of
:class:`valve_gym.envs.regulation.BlockLaw`; :class:`PolicyBlock` wraps such a policy in that law, so
it runs as every other DCS block (``reset(sp, pv, op)``, ``step(sp, pv)``) on the benchmark's loops.

What :func:`as_block` accepts (and :func:`evaluate`, :func:`run_with_policies`, ``valve-gym benchmark
--policy``):

* a DCS block (anything with ``reset`` and ``step``), used as it is;
* a Stable-Baselines3 model in memory (PPO, A2C, SAC, TD3, DDPG with an MLP policy), with its
  ``VecNormalize`` if it was trained behind one;
* a safe export (:func:`export_policy`): ``NAME.safetensors`` (the actor's layers) + ``NAME.json``
  (the layer list, the observation normaliser, the block settings, the task, versions), or a
  learned-block file (:func:`valve_gym.agents.learned.load_learned`);
* an SB3 ``.zip`` only after ``valve-gym convert-policy --trust-pickle IN.zip OUT`` (a ``.zip`` or any
  pickle given directly is refused in one line: loading it would run any code inside it).

The forward pass is numpy (no torch, nothing unpickled): the deterministic action of SB3's actor
(the Gaussian mean, clipped to [-1, 1], for PPO/A2C; ``tanh`` of the mean for SAC; the
deterministic actor for TD3/DDPG).
"""
from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from valve_gym.agents.controllers.block import check_inputs, check_op_limits, check_step_inputs, not_reset_error
from valve_gym.envs.regulation import N_ACT, BlockLaw, BlockSettings, RegulationTaskConfig, obs_names

__all__ = ["FORMAT", "NumpyMLP", "ObsNormaliser", "PolicyBlock", "export_policy", "load_policy_block", "as_block",
           "as_blocks", "evaluate", "PolicyShapeError"]

#: Format tag of a safe export's JSON.
FORMAT = "valve_gym.sb3_block/1"
_ACTS = ("tanh", "relu", "clip", "identity")


class PolicyShapeError(ValueError):
    """A policy whose observation or action size does not fit the regulation block."""


class NumpyMLP:
    """A layer list ``[('linear', W, b) | ('tanh',) | ('relu',) | ('clip',), ...]`` evaluated in numpy.

    ``clip`` limits to [-1, 1] (SB3's clipping of an unsquashed action to the action space).
    """

    def __init__(self, layers: Sequence[tuple]):
        self.layers = [tuple(x) for x in layers]
        lin = [x for x in self.layers if x[0] == "linear"]
        if not lin:
            raise ValueError("a policy network needs at least one linear layer")
        self.n_in = int(lin[0][1].shape[1])
        self.n_out = int(lin[-1][1].shape[0])

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Actions ``(n, n_out)`` of inputs ``(n, n_in)`` (float64)."""
        h = np.asarray(x, dtype=np.float64)
        for layer in self.layers:
            kind = layer[0]
            if kind == "linear":
                h = h @ layer[1].T + layer[2]
            elif kind == "tanh":
                h = np.tanh(h)
            elif kind == "relu":
                h = np.maximum(h, 0.0)
            elif kind == "clip":
                h = np.clip(h, -1.0, 1.0)
        return h


class ObsNormaliser:
    """SB3 ``VecNormalize``'s observation transform ``clip((obs - mean) / sqrt(var + eps), -clip, clip)``."""

    def __init__(self, mean, var, clip_obs: float = 10.0, epsilon: float = 1e-8):
        self.mean = np.asarray(mean, float)
        self.var = np.asarray(var, float)
        self.clip_obs = float(clip_obs)
        self.epsilon = float(epsilon)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Normalised observations ``(n, n_obs)``."""
        return np.clip((obs - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip_obs, self.clip_obs)

    @classmethod
    def from_vecnormalize(cls, venv) -> ObsNormaliser | None:
        """The normaliser of an SB3 ``VecNormalize`` (``None`` if it does not normalise observations)."""
        if venv is None or not getattr(venv, "norm_obs", False):
            return None
        rms = venv.obs_rms
        return cls(rms.mean, rms.var, venv.clip_obs, venv.epsilon)


class PolicyBlock:
    """A regulation-env policy as a DCS block: :class:`BlockLaw` driven by ``actor`` (numpy).

    Parameters
    ----------
    actor : callable
        ``(n, n_obs) -> (n, 2)`` actions in [-1, 1] (e.g. :class:`NumpyMLP`).
    settings : BlockSettings
        The block law the policy was trained in (the env's ``config.block``).
    normaliser : ObsNormaliser, optional
        Applied to the observation before the actor (the training ``VecNormalize``'s statistics).
    name : str
    meta : dict, optional
        Shown in the benchmark's settings column (``algorithm``, ``policy_path``).
    """

    def __init__(self, actor, settings: BlockSettings, normaliser: ObsNormaliser | None = None,
                 name: str = "policy", meta: dict | None = None):
        self.actor = actor
        self.block_settings = settings
        self.normaliser = normaliser
        self.name = name
        self.scan_s = float(settings.scan_s)
        self.meta = dict(meta or {})
        self.n_obs = len(obs_names(settings))
        self._law: BlockLaw | None = None
        self._scalar = True

    @property
    def settings(self) -> dict:
        """JSON-able settings (the block law's, the algorithm and the file)."""
        return {**asdict(self.block_settings), "algorithm": self.meta.get("algorithm"),
                "policy": self.meta.get("policy_path")}

    def for_loop(self, Kc: float, Ti: float, scan_s: float) -> PolicyBlock:
        """The policy as the block of a loop with PI gain ``Kc`` [1/pv], integral time ``Ti`` [s], scan ``scan_s`` [s].

        A policy trained on the family (``valve_gym/ValveFamilyRegulation-v0``; its export stores ``e_stroke``)
        also takes the loop's error scale ``e_ref = e_stroke / Kc``, as in training; a policy of the regulation
        env keeps its stored ``e_ref`` (it was trained on the benchmark tank only).
        """
        kw: dict = {"Kc": float(Kc), "Ti": float(Ti), "scan_s": float(scan_s)}
        es = self.meta.get("e_stroke")
        if es is not None:
            kw["e_ref"] = float(es) / float(Kc)
        return PolicyBlock(self.actor, replace(self.block_settings, **kw), self.normaliser, self.name, self.meta)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The policy's action ``(n, 2)`` for block observations ``(n, n_obs)`` (as the env gives them)."""
        x = np.asarray(obs, np.float32).astype(np.float64)
        if self.normaliser is not None:
            x = self.normaliser(x)
        return np.asarray(self.actor(x), float).reshape(-1, N_ACT)

    def reset(self, sp, pv, op) -> None:
        """Bumpless start from the current output ``op`` (fraction of stroke); ``sp``, ``pv`` in m."""
        (sp_a, pv_a, op_a), n, scalar = check_inputs(self.name, sp=sp, pv=pv, op=op)
        check_op_limits(self.name, op_a, self.block_settings.op_lo, self.block_settings.op_hi)
        self._scalar = scalar
        self._law = BlockLaw(self.block_settings, n)
        self._law.reset(sp_a, pv_a, op_a)

    def step(self, sp, pv):
        """One scan: measurement ``pv`` [m] at set point ``sp`` [m]; returns the output (float or (n,))."""
        law = self._law
        if law is None:
            raise not_reset_error(self.name)
        sp_a, pv_a, _ = check_step_inputs(self.name, law.n, sp, pv)
        u = law.act(self.act(law.observe(sp_a, pv_a)))
        return float(u[0]) if self._scalar else u

    def __repr__(self) -> str:
        return f"PolicyBlock(name={self.name!r}, algorithm={self.meta.get('algorithm')!r})"


# --------------------------------------------------------------------------- SB3 models
def _torch_layers(seq) -> list:
    """Layer list of a torch module (``Sequential``, ``Linear`` or activation)."""
    import torch.nn as nn

    mods = list(seq) if isinstance(seq, nn.Sequential) else [seq]
    out = []
    for m in mods:
        if isinstance(m, nn.Linear):
            out.append(("linear", m.weight.detach().cpu().numpy().astype(np.float64),
                        m.bias.detach().cpu().numpy().astype(np.float64)))
        elif isinstance(m, nn.Tanh):
            out.append(("tanh",))
        elif isinstance(m, nn.ReLU):
            out.append(("relu",))
        elif isinstance(m, (nn.Identity, nn.Flatten)):
            continue
        else:
            raise ValueError(f"cannot export a policy layer of type {type(m).__name__}: valve-gym exports MLP "
                             "policies with Linear, Tanh and ReLU layers (SB3's MlpPolicy)")
    return out


def sb3_layers(model) -> tuple[list, str]:
    """The deterministic actor of an SB3 model as a layer list, and the algorithm's name.

    Raises
    ------
    ValueError
        For a policy that is not an MLP on a flat observation (CNN, dict observations, recurrent).
    """
    pol = model.policy
    algo = type(model).__name__.lower()
    fe = getattr(pol, "features_extractor", None) or getattr(getattr(pol, "actor", None), "features_extractor", None)
    if fe is not None and type(fe).__name__ != "FlattenExtractor":
        raise ValueError(f"{type(model).__name__}'s features extractor {type(fe).__name__} is not supported; "
                         "use an MlpPolicy (FlattenExtractor)")
    if hasattr(pol, "mlp_extractor") and hasattr(pol, "action_net"):       # PPO, A2C
        if getattr(pol, "squash_output", False):
            raise ValueError("gSDE with squashed output is not supported; train with use_sde=False")
        return _torch_layers(pol.mlp_extractor.policy_net) + _torch_layers(pol.action_net) + [("clip",)], algo
    actor = getattr(pol, "actor", None)
    if actor is not None and hasattr(actor, "latent_pi") and hasattr(actor, "mu"):   # SAC
        if getattr(actor, "use_sde", False):
            raise ValueError("SAC with gSDE is not supported; train with use_sde=False")
        return _torch_layers(actor.latent_pi) + _torch_layers(actor.mu) + [("tanh",)], algo
    if actor is not None and hasattr(actor, "mu"):                          # TD3, DDPG
        return _torch_layers(actor.mu) + [("clip",)], algo
    raise ValueError(f"cannot read the actor of {type(model).__name__} (supported: PPO, A2C, SAC, TD3, DDPG "
                     "with an MlpPolicy)")


def _check_shapes(n_in: int, n_out: int, settings: BlockSettings, what: str) -> None:
    n_obs = len(obs_names(settings))
    if n_in != n_obs or n_out != N_ACT:
        hint = ("; was it trained on valve_gym/ValveTank-v0 (a direct valve input)? The benchmark runs policies of "
                "valve_gym/ValveTankRegulation-v0" if n_out != N_ACT else
                "; train it on valve_gym/ValveTankRegulation-v0 with the same block settings (block.stick_features "
                "switches 11 / 14 observations)")
        raise PolicyShapeError(f"{what} maps {n_in} observations to {n_out} actions, but the regulation block gives "
                               f"{n_obs} observations and takes {N_ACT} actions (gate, correction){hint}")


def _task_of(model=None, task=None):
    """The training task: a ``RegulationTaskConfig`` or (``ValveFamilyRegulation-v0``) a ``FamilyConfig``."""
    from valve_gym.envs.family_env import FamilyConfig
    from valve_gym.envs.regulation_env import make_regulation_config

    if isinstance(task, FamilyConfig):
        return task
    if task is not None:
        return make_regulation_config(task)
    env = getattr(model, "env", None)
    if env is not None:
        try:
            cfgs = env.get_attr("config")
            if cfgs and isinstance(cfgs[0], (RegulationTaskConfig, FamilyConfig)):
                return cfgs[0]
        except (AttributeError, TypeError, ValueError):
            pass
    return RegulationTaskConfig()


def _find_vecnormalize(model):
    """The ``VecNormalize`` wrapper of ``model``'s env, if any."""
    env = getattr(model, "env", None)
    while env is not None:
        if type(env).__name__ == "VecNormalize":
            return env
        env = getattr(env, "venv", None)
    return None


def block_from_model(model, vecnormalize=None, task=None, name: str | None = None) -> PolicyBlock:
    """A :class:`PolicyBlock` of an SB3 model in memory (weights copied; no torch at run time).

    Parameters
    ----------
    model : stable_baselines3 model
    vecnormalize : VecNormalize, optional
        Its observation statistics are used (default: the ``VecNormalize`` the model's env is wrapped in,
        if any).
    task : RegulationTaskConfig, mapping or YAML path, optional
        The training task (default: the model's env's, else the registered default).
    name : str, optional
    """
    cfg = _task_of(model, task)
    shape = tuple(getattr(model.observation_space, "shape", ()) or ())
    ashape = tuple(getattr(model.action_space, "shape", ()) or ())
    _check_shapes(shape[0] if len(shape) == 1 else -1, ashape[0] if len(ashape) == 1 else -1, cfg.block,
                  f"the {type(model).__name__} model")
    layers, algo = sb3_layers(model)
    vn = vecnormalize if vecnormalize is not None else _find_vecnormalize(model)
    norm = ObsNormaliser.from_vecnormalize(vn)
    e_stroke = getattr(cfg, "e_stroke", None)        # a policy of the family env (FamilyConfig)
    meta = {"algorithm": algo, **({"e_stroke": float(e_stroke)} if e_stroke is not None else {})}
    return PolicyBlock(NumpyMLP(layers), cfg.block, norm, name=name or algo, meta=meta)


def export_policy(model, path, vecnormalize=None, task=None, meta: Mapping | None = None) -> str:
    """Write an SB3 model's deterministic actor as ``path.safetensors`` + ``path.json`` (no pickle); returns the JSON.

    Parameters
    ----------
    model : stable_baselines3 model (PPO, A2C, SAC, TD3, DDPG; MlpPolicy) trained on the regulation env
    path : str or path
        Output stem (``.json``/``.safetensors``/``.zip`` suffixes are dropped).
    vecnormalize : VecNormalize, optional
        Observation statistics to store (default: the model env's ``VecNormalize``, if any).
    task : RegulationTaskConfig, mapping or YAML path, optional
        The training task (default: the model's env's).
    meta : mapping, optional
        More JSON (training command, seed, budget, ...).
    """
    from valve_gym import __version__

    from ..safe_files import save_model_file

    blk = block_from_model(model, vecnormalize, task)
    cfg = _task_of(model, task)
    stem = str(path)
    for ext in (".zip", ".json", ".safetensors"):
        if stem.endswith(ext):
            stem = stem[: -len(ext)]
    tensors, kinds = {}, []
    for i, layer in enumerate(blk.actor.layers):
        kinds.append(layer[0])
        if layer[0] == "linear":
            tensors[f"layer{i}.weight"] = layer[1].astype(np.float32)
            tensors[f"layer{i}.bias"] = layer[2].astype(np.float32)
    norm = blk.normaliser
    if norm is not None:
        tensors["obs_mean"] = norm.mean
        tensors["obs_var"] = norm.var
    from valve_gym.config import config_to_dict

    doc = {"format": FORMAT, "algorithm": blk.meta["algorithm"], "layers": kinds,
           "n_obs": blk.actor.n_in, "n_act": blk.actor.n_out, "obs_names": list(obs_names(cfg.block)),
           "normaliser": None if norm is None else {"clip_obs": norm.clip_obs, "epsilon": norm.epsilon},
           "block": asdict(cfg.block), "task": config_to_dict(cfg),
           "versions": {"valve_gym": __version__, "numpy": np.__version__},
           **({"e_stroke": blk.meta["e_stroke"]} if "e_stroke" in blk.meta else {}), **dict(meta or {})}
    _, jpath = save_model_file(stem, tensors, doc)
    return jpath


def load_policy_block(path, name: str | None = None) -> PolicyBlock:
    """Load a safe export (:func:`export_policy`) as a :class:`PolicyBlock` (never unpickles).

    Raises
    ------
    valve_gym.agents.safe_files.UnsafeFileError
        For an SB3 ``.zip`` or any pickle (one line, with the conversion command).
    PolicyShapeError
        When the network's sizes do not fit the block settings stored with it.
    ValueError
        Another format, or a corrupt file.
    """
    from ..safe_files import load_model_file

    mf = load_model_file(path)
    meta = mf.meta
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path} is not a regulation policy export (format {meta.get('format')!r}, expected "
                         f"{FORMAT!r})")
    kinds = meta.get("layers")
    if not isinstance(kinds, list) or any(k not in ("linear",) + _ACTS for k in kinds):
        raise ValueError(f"{path}: 'layers' must list {', '.join(('linear',) + _ACTS)}")
    layers = []
    for i, k in enumerate(kinds):
        if k == "linear":
            W, b = mf.tensors.get(f"layer{i}.weight"), mf.tensors.get(f"layer{i}.bias")
            if W is None or b is None or W.ndim != 2 or b.shape != (W.shape[0],):
                raise ValueError(f"{path}: weights of layer {i} missing or of the wrong shape")
            layers.append(("linear", W.astype(np.float64), b.astype(np.float64)))
        else:
            layers.append((k,))
    actor = NumpyMLP(layers)
    for a, b in zip([x for x in layers if x[0] == "linear"], [x for x in layers if x[0] == "linear"][1:]):
        if a[1].shape[0] != b[1].shape[1]:
            raise ValueError(f"{path}: layer sizes do not chain ({a[1].shape} then {b[1].shape})")
    try:
        settings = BlockSettings(**meta.get("block", {}))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: bad block settings ({exc})") from None
    _check_shapes(actor.n_in, actor.n_out, settings, f"the policy in {path}")
    norm = None
    if meta.get("normaliser") is not None:
        mean, var = mf.tensors.get("obs_mean"), mf.tensors.get("obs_var")
        if mean is None or var is None or mean.shape != (actor.n_in,) or var.shape != (actor.n_in,) \
                or np.any(var < 0):
            raise ValueError(f"{path}: observation normaliser (obs_mean, obs_var of shape ({actor.n_in},)) missing")
        norm = ObsNormaliser(mean, var, **meta["normaliser"])
    nm = name or meta.get("name") or Path(str(path)).stem
    return PolicyBlock(actor, settings, norm, name=nm, meta={**meta, "policy_path": str(path)})


def _load_file(path, name: str | None):
    from ..adaptive import FORMAT as ADAPTIVE_FORMAT
    from ..adaptive import load_adaptive
    from ..learned import FORMAT as LEARNED_FORMAT
    from ..learned import load_learned
    from ..safe_files import load_model_file, refuse_unsafe

    p = Path(path)
    if not p.exists() and not Path(str(p) + ".json").exists():
        raise FileNotFoundError(f"policy file not found: {p}")
    if p.is_file() and p.suffix not in (".json", ".safetensors"):
        refuse_unsafe(p)
        raise ValueError(f"{p} is not a policy file; give NAME.json (+ NAME.safetensors) written by "
                         "valve_gym.agents.bench.policies.export_policy or `valve-gym convert-policy`")
    fmt = load_model_file(p).meta.get("format")
    if fmt == LEARNED_FORMAT:
        return load_learned(p, **({"name": name} if name else {}))
    if fmt == ADAPTIVE_FORMAT:       # a trained adaptive compensator: each loop gets its own tuning (for_loop)
        return load_adaptive(p, **({"name": name} if name else {}))
    if fmt == "valve_gym.ppo_policy/1":
        raise PolicyShapeError(f"{p} is a policy of valve_gym/ValveTank-v0 (a direct valve input from 5 "
                               "observations), not of the regulation block; the benchmark runs policies trained on "
                               "valve_gym/ValveTankRegulation-v0")
    return load_policy_block(p, name)


def as_block(policy, name: str | None = None, vecnormalize=None, task=None):
    """Any accepted policy (see the module docstring) as a DCS block, its shapes checked.

    Raises
    ------
    UnsafeFileError, PolicyShapeError, ValueError, FileNotFoundError
        One line each, before any loop runs.
    """
    if isinstance(policy, (str, os.PathLike)):
        return _load_file(policy, name)
    if hasattr(policy, "policy") and hasattr(policy, "predict") and hasattr(policy, "observation_space"):
        return block_from_model(policy, vecnormalize, task, name)
    if hasattr(policy, "reset") and hasattr(policy, "step"):
        if name:
            try:
                policy.name = name
            except AttributeError:
                pass
        return policy
    raise TypeError(f"cannot use a {type(policy).__name__} as a policy: give a DCS block (reset/step), a "
                    "Stable-Baselines3 model, or a policy file (.json + .safetensors)")


def as_blocks(policies, names: Sequence[str] | None = None) -> dict[str, list]:
    """``{row label: [block, ...]}`` from policies (one each, a list = the seeds of one row, or a mapping).

    A folder stands for every ``*.json`` policy file in it (the seeds of one row named after the folder).
    """
    if isinstance(policies, Mapping):
        items = list(policies.items())
    else:
        pol = list(policies) if isinstance(policies, (list, tuple)) else [policies]
        names = list(names or [])
        items = []
        for i, p in enumerate(pol):
            nm = names[i] if i < len(names) else None
            if isinstance(p, (str, os.PathLike)) and Path(p).is_dir():
                files = sorted(str(f) for f in Path(p).glob("*.json"))
                if not files:
                    raise FileNotFoundError(f"no policy files (*.json) in the folder {p}")
                items.append((nm or Path(p).name, files))
            else:
                label = nm or (Path(str(p)).stem if isinstance(p, (str, os.PathLike)) else
                               getattr(p, "name", None) if hasattr(p, "step") else type(p).__name__)
                items.append((str(label or f"policy {i + 1}"), p))
    out: dict[str, list] = {}
    for label, p in items:
        seeds = list(p) if isinstance(p, (list, tuple)) else [p]
        out.setdefault(str(label), []).extend(as_block(s, name=str(label)) for s in seeds)
    return out


def evaluate(policy, *, name: str | None = None, config=None, quick: bool = False, jobs: int = 1,
             progress=None, vecnormalize=None):
    """Run the benchmark with ``policy`` beside the classical controllers; the benchmark's typed results.

    Parameters
    ----------
    policy : any accepted policy, a list of them (the seeds of one row) or a mapping ``{label: policy or list}``
    name : str, optional
        Row label (default: the file stem, the block's name or the algorithm).
    config : BenchConfig or YAML path, optional
        The benchmark (default ``configs/benchmark.yaml``'s built-in values).
    quick : bool
        The ``--quick`` benchmark (a few short loops).
    jobs : int
        Worker processes.
    progress : callable, optional
        Called with one line per finished task.
    vecnormalize : VecNormalize, optional
        For an SB3 model in memory trained behind one (default: found on the model's env).

    Returns
    -------
    valve_gym.agents.bench.pipeline.BenchmarkResult
        With one row per policy label (several seeds: per-loop medians over the seeds; the spread of
        the seeds' median ``R`` in ``notes``).
    """
    from .config import BenchConfig, load_bench_config
    from .pipeline import run_benchmark

    if isinstance(config, BenchConfig):
        cfg = config
    else:
        cfg = load_bench_config(config) if config is not None else BenchConfig()
    if quick:
        cfg = cfg.quick_version()
    if vecnormalize is not None and not isinstance(policy, (list, tuple, Mapping)):
        blocks = {name or type(policy).__name__.lower(): [as_block(policy, name, vecnormalize)]}
    else:
        blocks = as_blocks(policy if isinstance(policy, Mapping) or name is None else {name: policy})
    return run_benchmark(cfg, jobs=jobs, progress=progress, policies=blocks)
