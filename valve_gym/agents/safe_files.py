"""Model files without code execution: safetensors weights plus a JSON of everything else.

Every policy and checkpoint ``valve-gym`` writes is a pair ``<stem>.safetensors`` (named float
arrays) + ``<stem>.json`` (architecture, observation transform, normaliser statistics, settings,
versions). Loading reads the safetensors header and raw bytes and ``json.loads`` the metadata:
nothing is ever unpickled. :func:`refuse_unsafe` identifies the formats that would need
unpickling (SB3 ``.zip`` policies, torch ``.pt`` zips, raw pickles) and refuses them with one line
saying what the file is and how to convert a trusted one.
"""
from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import NamedTuple

import numpy as np

from valve_gym._io import write_atomic

__all__ = ["UnsafeFileError", "ModelFile", "save_model_file", "load_model_file", "refuse_unsafe",
           "model_file_paths", "describe_file"]


class UnsafeFileError(ValueError):
    """A file that could only be loaded by unpickling it (refused)."""


class ModelFile(NamedTuple):
    """A loaded model file: ``tensors`` (name -> float/int numpy array) and ``meta`` (JSON object)."""

    tensors: dict
    meta: dict


def model_file_paths(path) -> tuple[Path, Path]:
    """``(weights, json)`` paths of a model file given either one, or their common stem."""
    p = Path(path)
    if p.suffix in (".safetensors", ".json"):
        p = p.with_suffix("")
    return p.with_suffix(".safetensors"), p.with_suffix(".json")


_CONVERT = ("If you trust its origin (only then), convert it once with "
            "`valve-gym convert-policy --trust-pickle {path} OUT`")


def describe_file(path) -> str:
    """What kind of file ``path`` is, from its first bytes (``'pickle'``, ``'sb3-zip'``, ...)."""
    p = Path(path)
    with open(p, "rb") as fh:
        head = fh.read(9)
    size = p.stat().st_size
    if len(head) == 9 and head[8:9] == b"{" and 8 + int.from_bytes(head[:8], "little") <= size:
        return "safetensors"
    if head[:2] == b"PK":
        try:
            with zipfile.ZipFile(p) as z:
                names = z.namelist()
        except zipfile.BadZipFile:
            return "zip"
        if "policy.pth" in names or "data" in names:
            return "sb3-zip"
        if any(n.endswith("data.pkl") for n in names):
            return "torch-zip"
        return "zip"
    if head[:1] == b"\x80" or head[:1] in (b"(", b"]", b"}", b"c"):
        return "pickle"
    return "unknown"


def refuse_unsafe(path) -> None:
    """Raise :class:`UnsafeFileError` if ``path`` is a pickle-based model file (SB3 zip, torch zip, pickle).

    Examples
    --------
    >>> import pickle, tempfile, os
    >>> f = os.path.join(tempfile.mkdtemp(), "p.pkl")
    >>> with open(f, "wb") as fh:
    ...     pickle.dump({"a": 1}, fh)
    >>> refuse_unsafe(f)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    valve_gym.agents.safe_files.UnsafeFileError: ... is a Python pickle; valve-gym never unpickles ...
    """
    kind = describe_file(path)
    what = {"sb3-zip": "a stable-baselines3 .zip (its model data is pickled)",
            "torch-zip": "a torch.save zip (pickled)", "pickle": "a Python pickle"}.get(kind)
    if what:
        raise UnsafeFileError(f"{path} is {what}; valve-gym never unpickles model files (loading one can run "
                              f"any code). {_CONVERT.format(path=path)}")


def save_model_file(path, tensors: Mapping[str, np.ndarray], meta: Mapping) -> tuple[str, str]:
    """Write ``tensors`` (safetensors) and ``meta`` (JSON) atomically; returns both paths.

    The weights are written first and the JSON last, so a model file whose JSON exists is complete.
    """
    from safetensors.numpy import save

    wpath, jpath = model_file_paths(path)
    arrays = {k: np.array(v, order="C") for k, v in tensors.items()}   # (keeps 0-d arrays 0-d)
    data = save(arrays)
    write_atomic(wpath, lambda f: f.write(data))
    text = json.dumps(dict(meta), indent=1, default=_json_default, allow_nan=False)
    write_atomic(jpath, lambda f: f.write(text.encode("utf-8")))
    return str(wpath), str(jpath)


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (set, tuple)):
        return list(o)
    if isinstance(o, os.PathLike):
        return os.fspath(o)
    raise TypeError(f"cannot write {type(o).__name__} to a model file's JSON")


def load_model_file(path) -> ModelFile:
    """Read a model file written by :func:`save_model_file` (never unpickles).

    Parameters
    ----------
    path : str or path
        The ``.safetensors`` file, the ``.json`` file or their common stem.

    Raises
    ------
    FileNotFoundError
        If either part is missing (naming it).
    UnsafeFileError
        If ``path`` is a pickle-based file.
    ValueError
        If the JSON or the weights are corrupt.
    """
    p = Path(path)
    if p.is_file() and p.suffix not in (".safetensors", ".json"):
        refuse_unsafe(p)
        raise ValueError(f"{p} is not a valve-gym model file; expected NAME.safetensors with NAME.json")
    wpath, jpath = model_file_paths(p)
    for q in (wpath, jpath):
        if not q.is_file():
            raise FileNotFoundError(f"model file part missing: {q} (a model file is NAME.safetensors + NAME.json)")
    refuse_unsafe(wpath)
    try:
        meta = json.loads(jpath.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"{jpath} is not valid JSON ({exc}); the model file is corrupt") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{jpath} must hold a JSON object, got {type(meta).__name__}")
    from safetensors import SafetensorError
    from safetensors.numpy import load_file

    try:
        tensors = load_file(str(wpath))
    except (SafetensorError, OSError, ValueError) as exc:
        raise ValueError(f"{wpath} is not a valid safetensors file ({exc}); the model file is corrupt") from None
    return ModelFile(tensors=dict(tensors), meta=meta)
