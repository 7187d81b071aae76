"""The trained adaptive stiction compensator: its file (safetensors + JSON) and its loader.

:func:`load_adaptive` builds :class:`~valve_gym.agents.controllers.adaptive.AdaptiveStiction` with the
seven numbers of a trained file (default: the shipped ``policies/adaptive.*``). The safetensors part
holds one float64 vector ``params`` of shape ``(7,)`` in the order of
:data:`~valve_gym.agents.controllers.adaptive.PARAM_NAMES`; the JSON the format tag, the names, the
training configuration, seed, command and versions. Loading checks the format, the names, the shape,
the dtype, that every number is finite and inside its range; nothing is unpickled, torch is not needed.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .controllers.adaptive import PARAM_NAMES, PARAMS, SWITCH_RANGES, AdaptiveStiction
from .safe_files import load_model_file, save_model_file

__all__ = ["load_adaptive", "save_adaptive", "read_params", "fixed_settings", "ANSWERS", "DEFAULT_ADAPTIVE", "FORMAT"]

#: The shipped trained file.
DEFAULT_ADAPTIVE = Path(__file__).resolve().parent / "policies" / "adaptive.json"
#: Format tag of the JSON.
FORMAT = "valve_gym.adaptive_stiction/1"


def save_adaptive(path, params: np.ndarray, meta: dict) -> tuple[str, str]:
    """Write ``params`` (7,) as ``path.safetensors`` + ``path.json`` (atomically); returns both paths."""
    v = np.asarray(params, dtype=np.float64).reshape(-1)
    read_params({"params": v}, {"format": FORMAT, "names": list(PARAM_NAMES)}, path)   # refuse a bad vector
    return save_model_file(path, {"params": v}, {"format": FORMAT, "names": list(PARAM_NAMES), **meta})


def read_params(tensors: dict, meta: dict, path) -> dict:
    """The checked settings ``{name: float}`` of a trained file's parts, or a ValueError naming the problem."""
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path}: not an adaptive-compensator file (format {meta.get('format')!r}, "
                         f"expected {FORMAT!r})")
    if list(meta.get("names", [])) != list(PARAM_NAMES):
        raise ValueError(f"{path}: parameter names {meta.get('names')!r} differ from {list(PARAM_NAMES)!r}; "
                         "the file was written for another version of the block")
    v = tensors.get("params")
    if v is None or v.dtype != np.float64 or v.shape != (len(PARAM_NAMES),):
        got = None if v is None else f"{v.dtype} {v.shape}"
        raise ValueError(f"{path}: tensor 'params' must be float64 of shape ({len(PARAM_NAMES)},), got {got}")
    out = {}
    for x, (name, _, lo, hi, _doc) in zip(v, PARAMS):
        if not (np.isfinite(x) and lo <= x <= hi):
            raise ValueError(f"{path}: parameter {name} = {x!r} is not finite or outside [{lo:g}, {hi:g}]")
        out[name] = float(x)
    return out


#: The answer tests a trained file may name (its JSON's ``"answer"``; files without one: ``"turn"``).
ANSWERS = {"turn": 0.0, "reversal": 1.0}


def fixed_settings(meta: dict, path) -> dict:
    """The block's untrained settings named by a trained file's JSON ``meta``.

    ``{"answer": 0.0 or 1.0, "k_i": float, "k_z": float, "confirm": float}`` (:data:`ANSWERS`; files without
    them: ``"turn"``, no integral boost, no integral dead zone, answers taken unconfirmed), or a ValueError
    naming a bad one.
    """
    a = meta.get("answer", "turn")
    if a not in ANSWERS:
        raise ValueError(f"{path}: answer {a!r} is not one of {sorted(ANSWERS)}; the file was written for another "
                         "version of the block")
    out = {"answer": ANSWERS[a]}
    for name, (lo, hi) in SWITCH_RANGES.items():
        v = meta.get(name, 0.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo <= v <= hi):
            raise ValueError(f"{path}: {name} must be a number in [{lo:g}, {hi:g}], got {v!r}")
        out[name] = float(v)
    return out


def load_adaptive(path=None, **settings) -> AdaptiveStiction:
    """The trained adaptive compensator as a DCS block.

    Parameters
    ----------
    path : str or path, optional
        A trained file (``.json``/``.safetensors`` or their stem); default the shipped one.
    **settings
        PI settings of the loop (``Kc``, ``Ti``, ``detune``, ``scan_s``, ``op_lo``, ``op_hi``); a
        trained number given here overrides the file's. ``name`` sets the block's name.

    Returns
    -------
    AdaptiveStiction

    Raises
    ------
    ValueError
        A file of another format, a bad tensor (shape, dtype, NaN, out of range), an unknown setting.
    FileNotFoundError
        A missing part of the file.

    Examples
    --------
    >>> blk = load_adaptive(scan_s=1.0)
    >>> blk.reset(1.0, 1.0, 0.5)
    >>> blk.step(1.0, 1.0)
    0.5
    """
    p = DEFAULT_ADAPTIVE if path is None else Path(path)
    mf = load_model_file(p)
    trained = read_params(mf.tensors, mf.meta, p)
    trained.update(fixed_settings(mf.meta, p))
    name = settings.pop("name", None)
    # a named block names itself in every message (settings, bad measurements, loop counts)
    cls = AdaptiveStiction if name is None else type("AdaptiveStiction", (AdaptiveStiction,), {"name": str(name)})
    return cls(**{**trained, **settings})
