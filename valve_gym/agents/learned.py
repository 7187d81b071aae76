"""The learned stiction compensator as a DCS function block (numpy inference, safetensors weights).

:func:`load_learned` returns a :class:`LearnedBlock`: the PI block of the regulation task
(:class:`valve_gym.envs.regulation.BlockLaw`, SIMC PI with a gated integrator and a bounded
additive correction) whose gate and correction come from a small tanh network. The block sees
what a DCS block sees: set point, measurement and its own past output; never the stem or the
friction parameters. Its integral action is structural (the gate never goes below ``g_min``),
so it has no steady offset.

The weights are a safetensors file and everything else (architecture, observation normaliser,
block settings, training command, seed, versions) a JSON file beside it; the forward pass is
plain numpy, torch is not needed, nothing is unpickled.
"""
from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from valve_gym.envs.regulation import N_ACT, N_OBS, BlockLaw, BlockSettings, obs_names

from .controllers.block import (
    PV_RANGE,
    GuardedBlock,
    PVGuard,
    check_inputs,
    check_op_limits,
    check_step_inputs,
    not_reset_error,
)
from .controllers.pi import check_action
from .safe_files import load_model_file, save_model_file

__all__ = ["MLPSpec", "LearnedBlock", "load_learned", "save_learned", "mlp_forward", "mlp_shapes", "normalise",
           "DEFAULT_POLICY", "FORMAT"]

#: Largest layer of a learned policy's network (``es.hidden``, PPO's ``net_arch``): a compensator needs
#: tens of units; far larger layers only exhaust memory.
MAX_LAYER = 4096

#: The shipped learned compensator.
DEFAULT_POLICY = Path(__file__).resolve().parent / "policies" / "learned.json"
#: Format tag in the JSON of a learned-block file.
FORMAT = "valve_gym.learned_block/1"


class MLPSpec:
    """Layer sizes of the tanh network ``n_obs -> hidden... -> N_ACT`` (tanh on every layer).

    ``n_obs`` is the block's observation length (``len(obs_names(settings))``; ``N_OBS`` by default).
    """

    def __init__(self, hidden: Sequence[int] = (32, 32), n_obs: int = N_OBS):
        self.hidden = tuple(int(h) for h in hidden)
        if not self.hidden or any(h < 1 for h in self.hidden):
            raise ValueError(f"hidden layer sizes must be positive integers, got {list(hidden)!r}")
        self.n_obs = int(n_obs)
        self.sizes = (self.n_obs,) + self.hidden + (N_ACT,)

    @property
    def n_params(self) -> int:
        """Number of weights and biases."""
        return sum(a * b + b for a, b in zip(self.sizes[:-1], self.sizes[1:]))


def mlp_shapes(spec: MLPSpec) -> list:
    """``[(name, shape), ...]`` of the weights in flat-vector order (``W0, b0, W1, b1, ...``)."""
    out = []
    for i, (a, b) in enumerate(zip(spec.sizes[:-1], spec.sizes[1:])):
        out += [(f"W{i}", (a, b)), (f"b{i}", (b,))]
    return out


def unflatten(spec: MLPSpec, theta: np.ndarray) -> dict:
    """Named weight arrays from a flat parameter vector ``theta`` (..., n_params) (views, leading dims kept)."""
    out, i = {}, 0
    lead = theta.shape[:-1]
    for name, shape in mlp_shapes(spec):
        size = int(np.prod(shape))
        out[name] = theta[..., i:i + size].reshape(lead + shape)
        i += size
    return out


def mlp_forward(weights: dict, x: np.ndarray) -> np.ndarray:
    """Forward pass ``tanh(... tanh(x W0 + b0) ... W_L + b_L)``.

    Parameters
    ----------
    weights : dict
        ``W{i}`` (in, out) and ``b{i}`` (out,), or with a leading population axis ``(P, in, out)``,
        ``(P, out)`` when ``x`` is ``(P, B, in)``.
    x : (B, in) or (P, B, in) array

    Returns
    -------
    (B, out) or (P, B, out) array in (-1, 1)
    """
    h = x
    i = 0
    while f"W{i}" in weights:
        W, b = weights[f"W{i}"], weights[f"b{i}"]
        h = np.tanh(np.matmul(h, W) + (b[:, None, :] if b.ndim == 2 else b))
        i += 1
    return h


def normalise(obs: np.ndarray, mean: np.ndarray, std: np.ndarray) -> np.ndarray:
    """The network's input: ``clip((obs - mean) / std, -5, 5)``."""
    return np.clip((obs - mean) / std, -5.0, 5.0)


class LearnedBlock(GuardedBlock):
    """The learned compensator: :class:`BlockLaw` driven by a numpy network (a DCS block).

    Parameters
    ----------
    weights : dict
        Network weights (see :func:`mlp_forward`).
    obs_mean, obs_std : (n_obs,) arrays
        Normaliser of the observation: the network sees ``(obs - mean) / std``.
    settings : BlockSettings
    name : str
    action : float, +1 reverse acting (opening the valve raises pv: the loops the network was trained on) or
        -1 direct acting; the network sees ``action * sp``, ``action * pv``

    Examples
    --------
    >>> blk = load_learned()
    >>> blk.reset(sp=1.0, pv=1.0, op=0.5)
    >>> round(blk.step(1.0, 1.0), 3)
    0.5
    """

    def __init__(self, weights: dict, obs_mean: np.ndarray, obs_std: np.ndarray,
                 settings: BlockSettings = BlockSettings(), name: str = "learned", meta: dict | None = None,
                 pv_range=PV_RANGE, action: float = 1.0):
        self.guard = PVGuard(name, pv_range)
        self.action = float(action)
        self.weights = weights
        self.obs_mean = np.asarray(obs_mean, float)
        self.obs_std = np.asarray(obs_std, float)
        self.block_settings = settings
        self.name = name
        self.scan_s = float(settings.scan_s)
        self.meta = meta or {}
        self._law: BlockLaw | None = None
        self._scalar = True

    @property
    def settings(self) -> dict:
        """The resolved settings (JSON-able)."""
        return {**asdict(self.block_settings), "action": self.action, "policy": self.meta.get("policy_path")}

    def reset(self, sp, pv, op) -> None:
        """Bumpless start from the current output ``op`` (fraction of stroke); ``sp``, ``pv`` in m.

        The signals are checked as every block's (:func:`~valve_gym.agents.controllers.block.check_inputs`).
        """
        (sp_a, pv_a, op_a), n, scalar = check_inputs(self.name, sp=sp, pv=pv, op=op)
        if np.any((op_a < 0) | (op_a > 1)):
            raise ValueError(f"{self.name}: op must be the valve input as a fraction 0..1, got {op!r}")
        check_op_limits(self.name, op_a, self.block_settings.op_lo, self.block_settings.op_hi)
        self._scalar = scalar
        self._law = BlockLaw(self.block_settings, n)
        self._law.reset(self.action * sp_a, self.action * pv_a, op_a)
        self.guard.start(op_a)

    def step(self, sp, pv):
        """One scan: measurement ``pv`` [m] at set point ``sp`` [m]; returns the output (float or (n,)).

        ``sp`` and ``pv`` are checked as every block's
        (:func:`~valve_gym.agents.controllers.block.check_step_inputs`): as many loops as
        :meth:`reset` was given (or scalars, shared by all loops); a loop with a bad measurement
        (NaN, inf, outside ``pv_range``) holds its output and memory on this scan (``PVGuard``).
        """
        law = self._law
        if law is None:
            raise not_reset_error(self.name)
        sp_a, pv_a, _ = check_step_inputs(self.name, law.n, sp, pv, allow_bad=True)
        sp_a, pv_a, bad = self.guard.screen(sp_a, pv_a)
        kept = {k: v.copy() for k, v in vars(law).items()
                if isinstance(v, np.ndarray) and v.shape[:1] == (law.n,)} if bad.any() else {}
        first = law._first
        obs = law.observe(self.action * sp_a, self.action * pv_a)
        a = mlp_forward(self.weights, normalise(obs, self.obs_mean, self.obs_std))
        u = law.act(a)
        for k, v in kept.items():          # the held loops' memory stays as it was (see PVGuard)
            cur = getattr(law, k)
            setattr(law, k, np.where(bad.reshape((-1,) + (1,) * (v.ndim - 1)), v, cur))
        if bad.all():
            law._first = first
        u = self.guard.finish(u, bad)
        return float(u[0]) if self._scalar else u

    def __repr__(self) -> str:
        return f"LearnedBlock(name={self.name!r}, hidden={self.meta.get('hidden')})"


def save_learned(path, theta: np.ndarray, spec: MLPSpec, obs_mean, obs_std, settings: BlockSettings,
                 meta: dict) -> tuple[str, str]:
    """Write a learned block as ``path.safetensors`` + ``path.json``; returns both paths."""
    w = {k: np.asarray(v, dtype=np.float64).copy() for k, v in unflatten(spec, np.asarray(theta, float)).items()}
    w["obs_mean"] = np.asarray(obs_mean, float)
    w["obs_std"] = np.asarray(obs_std, float)
    m = {"format": FORMAT, "hidden": list(spec.hidden), "activation": "tanh", "n_obs": spec.n_obs, "n_act": N_ACT,
         "block": asdict(settings), **meta}
    return save_model_file(path, w, m)


def _resolve(path) -> Path:
    if path is None:
        return DEFAULT_POLICY
    p = Path(path)
    if p.is_dir():
        for cand in (p / "learned.json", p / "best.json", p / "final.json"):
            if cand.is_file():
                return cand
        raise FileNotFoundError(f"no learned block in {p}: expected learned.json, best.json or final.json "
                                f"(the output folder of `valve-gym train --config configs/learned.yaml`)")
    return p


def _number(name: str, v, block: str = "learned_network"):
    """A setting of the network block as a float (numpy numbers included), or a ValueError saying why not."""
    if isinstance(v, (np.integer, np.floating)):
        return float(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        raise ValueError(f"{block}: setting {name} must be one number for all loops (the network block "
                         f"takes no per-loop settings), got {type(v).__name__} of shape {np.shape(v)}; run one "
                         "block per setting, or use load_controller('learned'), which does")
    return v


#: Settings whose change from the stored ones puts the network outside what it was trained on.
TRAINED_SETTINGS = ("Kc", "Ti", "scan_s")


def _warn_untrained(bs: BlockSettings, trained: dict, path, block: str = "learned_network") -> None:
    """Warn when ``Kc``, ``Ti`` or ``scan_s`` differ from the values the network was trained with."""
    off = [f"{k} = {getattr(bs, k):g} (trained: {float(trained[k]):g})" for k in TRAINED_SETTINGS
           if k in trained and not np.isclose(float(getattr(bs, k)), float(trained[k]), rtol=1e-6, atol=0.0)]
    if off:
        warnings.warn(f"{block}: {', '.join(off)}: the network of {path} was trained with the stored settings "
                      "only, so its gate and correction now act on inputs it has not seen and may do much worse "
                      "than the PI (e.g. about 8x the PI's error and travel at scan_s = 10 s on the default tank); "
                      "compare with load_controller('pi') on this loop before use, or use load_controller('learned'), "
                      "trained over a family of loops and tunings", UserWarning, stacklevel=3)


def load_learned(path=None, **settings) -> LearnedBlock:
    """Load a learned compensator (the shipped one by default) as a DCS block.

    Parameters
    ----------
    path : str or path, optional
        A ``.json``/``.safetensors`` learned-block file or a training output folder
        (``best`` is used); default the shipped ``valve_gym/agents/policies/learned.json``.
    **settings
        Overrides of :class:`~valve_gym.envs.regulation.BlockSettings` (``Kc``, ``Ti``, ``scan_s``,
        ``op_lo``, ``op_hi``: numbers, one for all loops; the network was trained with the stored ones),
        ``name`` and ``pv_range`` (the plausible PV range [m]; see
        :class:`~valve_gym.agents.controllers.block.PVGuard`).

    Returns
    -------
    LearnedBlock

    Raises
    ------
    ValueError
        Unknown setting (listing the known ones), a pickle-based or corrupt file.
    FileNotFoundError
        Missing file.

    Warns
    -----
    UserWarning
        ``Kc``, ``Ti`` or ``scan_s`` other than the stored ones: the network never saw such a loop.
    """
    p = _resolve(path)
    mf = load_model_file(p)
    meta = mf.meta
    if meta.get("format") != FORMAT:
        raise ValueError(f"{p} is not a learned-block file (format {meta.get('format')!r}, expected {FORMAT!r})")
    name = settings.pop("name", "learned_network")
    pv_range = settings.pop("pv_range", PV_RANGE)
    action = _number("action", settings.pop("action", 1.0), name)
    check_action(name, action)
    allowed = ("Kc", "Ti", "scan_s", "op_lo", "op_hi")
    bad = [k for k in settings if k not in allowed]
    if bad:
        raise ValueError(f"unknown setting(s) {bad} for the learned compensator; known: {', '.join(allowed)}, "
                         "action, name")
    settings = {k: _number(k, v, name) for k, v in settings.items()}
    try:
        bs = replace(BlockSettings(**meta["block"]), **settings)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"bad settings for the learned compensator: {exc}") from None
    _warn_untrained(bs, meta["block"], p, name)
    n_obs = len(obs_names(bs))
    spec = MLPSpec(meta["hidden"], n_obs)
    w = {nm: _checked_tensor(p, nm, mf.tensors.get(nm), shape) for nm, shape in mlp_shapes(spec)}
    mean = _checked_tensor(p, "obs_mean", mf.tensors.get("obs_mean"), (n_obs,))
    std = _checked_tensor(p, "obs_std", mf.tensors.get("obs_std"), (n_obs,))
    if np.any(std <= 0):
        raise ValueError(f"{p}: obs_std must be > 0 in every entry (it divides the observation), got min "
                         f"{float(std.min()):g}; the file is corrupt: retrain or restore it")
    return LearnedBlock(w, mean, std, bs, name=name, meta={**meta, "policy_path": str(p)}, pv_range=pv_range,
                        action=float(action))


def _checked_tensor(p, name: str, a, shape: tuple) -> np.ndarray:
    """Tensor ``name`` of the file ``p`` as float64 after checking it: present, float dtype, ``shape``, finite.

    A bool or integer tensor, a wrong shape or a NaN/inf entry would make the block act with NaN or
    as another controller; each raises a one-line ``ValueError`` naming the tensor instead.
    """
    if a is None:
        raise ValueError(f"{p}: tensor {name} missing (expected shape {shape}); the file is not a complete "
                         f"learned block")
    if not np.issubdtype(a.dtype, np.floating):
        raise ValueError(f"{p}: tensor {name} has dtype {a.dtype}, expected a float dtype; the file is corrupt")
    if a.shape != shape:
        raise ValueError(f"{p}: tensor {name} has shape {a.shape}, expected {shape}; the file does not match "
                         f"its JSON's network")
    a = a.astype(np.float64)
    if not np.isfinite(a).all():
        raise ValueError(f"{p}: tensor {name} holds {int((~np.isfinite(a)).sum())} NaN or inf value(s); the file "
                         f"is corrupt: retrain or restore it")
    return a
