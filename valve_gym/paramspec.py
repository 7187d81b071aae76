"""Parameter declarations shared by the friction models, the effects and the fitter.

:class:`ParamSpec` declares a physical parameter of a block (name, unit, range,
default, prior for fitting); :class:`FreeParam` is one coordinate of the
fitter's search, mapped from the unit interval to a range scaled from the data;
:class:`Registry` keeps named specs of one kind.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["ParamSpec", "FreeParam", "Registry"]


@dataclass(frozen=True)
class ParamSpec:
    """One physical parameter of a friction model or an effect block.

    Attributes
    ----------
    name : str
        Field name in the model's parameter block.
    unit : str
        Unit (``"-"`` for fractions of the stroke).
    lo, hi : float
        Physical range accepted by the model.
    default : float
        Value used when the model is built without it.
    prior : str
        Prior for fitting: ``"lin"`` uniform on [lo, hi], ``"log"`` uniform in
        log, ``"sq"`` uniform in the square root (dense near ``lo``), or
        ``"fixed"`` (not fitted; set by the S/J mapping or left at the default).
    doc : str
        One line: what the parameter is.
    """

    name: str
    unit: str
    lo: float
    hi: float
    default: float
    prior: str
    doc: str

    def __post_init__(self):
        if self.prior not in ("lin", "log", "sq", "fixed"):
            raise ValueError(f"ParamSpec {self.name!r}: prior must be 'lin', 'log', 'sq' or 'fixed', "
                             f"got {self.prior!r}")
        if self.prior == "log" and not self.lo > 0:
            raise ValueError(f"ParamSpec {self.name!r}: a log prior needs lo > 0, got {self.lo}")
        if not self.lo <= self.default <= self.hi:
            raise ValueError(f"ParamSpec {self.name!r}: default {self.default} outside [{self.lo}, {self.hi}]")



@dataclass(frozen=True)
class FreeParam:
    """One free coordinate of the search.

    Parameters
    ----------
    name : str
        Internal name (e.g. ``"tau1"``, ``"z_max"``).
    lo, hi : float
        Bounds in the parameter's own units.
    scale : {'lin', 'log', 'sq'}
        Map from the unit coordinate ``w`` in 0..1: ``lo + (hi-lo) w``,
        ``lo (hi/lo)**w`` or ``lo + (hi-lo) w**2`` (fine resolution near
        ``lo``, e.g. friction near zero).
    unit : str
        Unit, for reports.
    doc : str
        One-line meaning.
    discrete : bool
        Held fixed by gradient-based refinement (e.g. a sign).
    """

    name: str
    lo: float
    hi: float
    scale: str = "lin"
    unit: str = ""
    doc: str = ""
    discrete: bool = False

    def value(self, w):
        """Parameter value(s) for unit coordinate(s) ``w``."""
        return unit_value(self.scale, self.lo, self.hi, np.clip(np.asarray(w, float), 0.0, 1.0))

    def coord(self, v):
        """Unit coordinate(s) of value(s) ``v`` (clipped to the bounds)."""
        v = np.clip(np.asarray(v, float), min(self.lo, self.hi), max(self.lo, self.hi))
        span = self.hi - self.lo
        if span == 0:
            return np.zeros_like(v)
        if self.scale == "log":
            return np.log(v / self.lo) / np.log(self.hi / self.lo)
        if self.scale == "sq":
            return np.sqrt(np.clip((v - self.lo) / span, 0, 1))
        return (v - self.lo) / span




def unit_value(scale: str, lo, hi, w):
    """Values at unit coordinates ``w`` (already within 0..1) of a ``scale`` from ``lo`` to ``hi``.

    ``lo`` and ``hi`` are numbers or arrays that broadcast against ``w`` (one row per parameter:
    :class:`valve_gym.diagnosis.model.ModelStructure` decodes a batch of coordinates at once).
    """
    if scale == "log":
        return lo * (hi / lo) ** w
    if scale == "sq":
        return lo + (hi - lo) * w * w
    return lo + (hi - lo) * w


class Registry:
    """Named specs of one kind (friction models, effects), in registration order.

    Parameters
    ----------
    kind : str
        What the specs are, for messages (``"friction model"``, ``"effect"``).
    spec_type : type
        The class every registered spec must be.
    """

    def __init__(self, kind: str, spec_type: type):
        self.kind = kind
        self.spec_type = spec_type
        self._specs: dict[str, Any] = {}

    def add(self, spec):
        """Add ``spec`` (a name can be registered once); returns it."""
        if not isinstance(spec, self.spec_type):
            raise TypeError(f"registering a {self.kind} takes a {self.spec_type.__name__}, got {type(spec).__name__}")
        if spec.name in self._specs and self._specs[spec.name] is not spec:
            raise ValueError(f"a {self.kind} called {spec.name!r} is already registered")
        self._specs[spec.name] = spec
        return spec

    def get(self, name: str):
        """The spec called ``name``; ``ValueError`` listing the known names otherwise."""
        try:
            return self._specs[name]
        except (KeyError, TypeError):
            raise ValueError(f"unknown {self.kind} {name!r}; known {self.kind.split()[-1]}s: "
                             f"{', '.join(self._specs)}") from None

    def remove(self, name: str) -> None:
        """Forget ``name`` (no error when it is not registered)."""
        self._specs.pop(name, None)

    def names(self) -> tuple[str, ...]:
        """Registered names, in registration order."""
        return tuple(self._specs)
