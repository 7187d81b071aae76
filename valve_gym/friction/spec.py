"""Specs and registry of the valve friction models.

A friction model is one module of :mod:`valve_gym.friction` that declares a
:class:`FrictionSpec`: its parameters (name, unit, range, default, prior for
fitting), how it enters the physics core, its diagnostic signature, its report
text, the full citation, and ``build``, the rule that sizes it from the two
numbers every model shares, the stick band ``S`` and the slip jump ``J``
(fractions of the stroke). The registry maps names to specs; nothing outside a
model's module names its parameters.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..params import ModelParams, ParameterError, SlipJump, register_sample_law
from ..paramspec import ParamSpec, Registry

__all__ = ["ParamSpec", "FrictionSpec", "register", "friction_spec", "registered", "as_band", "frictionless",
           "SampleLaw", "MEM_ROWS"]

Band = float | np.ndarray
#: ``sample_law(u, mem, block) -> x``: see :class:`FrictionSpec`.
SampleLaw = Callable[[np.ndarray, np.ndarray, SlipJump], np.ndarray]
#: Rows of the per-loop memory a sample law gets.
MEM_ROWS = 4


@dataclass(frozen=True)
class FrictionSpec:
    """Declaration of one friction model.

    Attributes
    ----------
    name : str
        Registry name (``valve_model(name, S, J)``).
    title : str
        Short human name.
    params : tuple of ParamSpec
        The model's own parameters.
    kernel : str
        How the model enters the physics core (which block, when it runs).
    signature : str
        What the model looks like in operating data (for the diagnosis text).
    report : str
        Report template; ``{S}`` and ``{J}`` are replaced by the band and the
        jump in % of stroke.
    citation : str
        Full reference of the paper the model implements.
    build : callable ``(base, S, J) -> ModelParams``
        Sizes the model from ``S`` and ``J`` (fractions of stroke, floats or
        ``(n,)`` arrays, already checked) on ``base``, whose friction has been
        removed.
    sample_law : callable ``(u, mem, block) -> x``, optional
        For a model that is not compiled into the kernel: its law, applied by
        :class:`valve_gym.plant.Plant` once per scan. ``u`` is the saturated
        input ``(n,)``, ``block`` the model's
        :class:`~valve_gym.params.SlipJump` (``law = name``), ``mem`` a
        ``(MEM_ROWS, n)`` float array the law keeps its state in (the plant
        sets row 0 to the stem's rest position and row 1 to the input at a
        reset, the other rows to 0). It returns ``x`` ``(n,)``, the target of
        the positioner lag ``dh/dt = (x - h)/tau_p``. Registering the spec
        makes ``name`` a valid ``SlipJump.law``.
    """

    name: str
    title: str
    params: tuple[ParamSpec, ...]
    kernel: str
    signature: str
    report: str
    citation: str
    build: Callable[[ModelParams, Band, Band], ModelParams]
    sample_law: SampleLaw | None = None

    def describe(self, S, J) -> str:
        """Report text for stick band ``S`` and slip jump ``J`` (fractions of stroke, scalars)."""
        s = float(np.mean(S)) * 100.0
        j = float(np.mean(J)) * 100.0
        return self.report.format(S=f"{s:.3g}", J=f"{j:.3g}")

    def param(self, name: str) -> ParamSpec:
        """The :class:`ParamSpec` called ``name`` (``KeyError`` listing the names otherwise)."""
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(f"{self.name} has no parameter {name!r}; it has {[p.name for p in self.params]}")


_REGISTRY = Registry("friction model", FrictionSpec)


def register(spec: FrictionSpec) -> FrictionSpec:
    """Add ``spec`` to the registry (a name can be registered once); returns it."""
    _REGISTRY.add(spec)
    if spec.sample_law is not None:
        register_sample_law(spec.name)
    return spec


def registered() -> tuple[str, ...]:
    """Names of the registered friction models, in registration order."""
    return _REGISTRY.names()


def friction_spec(name: str) -> FrictionSpec:
    """The :class:`FrictionSpec` of model ``name``.

    Raises
    ------
    ValueError
        For an unknown name; the message lists the known models.
    """
    return _REGISTRY.get(name)


def as_band(S, J) -> tuple[Band, Band]:
    """Check and broadcast a stick band ``S`` and slip jump ``J`` (fractions of stroke).

    Returns floats when both are scalars, else two ``(n,)`` float arrays.

    Raises
    ------
    ParameterError
        When a value is not finite, negative, ``S >= 1``, ``J > S``, or the
        shapes do not broadcast to one ``(n,)`` batch.
    """
    try:
        s = np.asarray(S, dtype=float)
        j = np.asarray(J, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"S and J must be numbers or (n,) arrays (fraction of stroke), got "
                             f"{S!r} and {J!r}") from None
    if s.ndim > 1 or j.ndim > 1:
        raise ParameterError(f"S and J must be scalars or (n,) arrays, got shapes {s.shape} and {j.shape}")
    try:
        s, j = np.broadcast_arrays(s, j)
    except ValueError:
        raise ParameterError(f"S has {s.size} values and J has {j.size}: give one value or the same "
                             f"number (n,) for both") from None
    if not (np.isfinite(s).all() and np.isfinite(j).all()):
        raise ParameterError("S and J must be finite numbers (fraction of stroke)")
    if (s < 0).any() or (j < 0).any():
        raise ParameterError(f"S and J must be >= 0 (fraction of stroke), got min S {s.min()}, min J {j.min()}")
    if (s >= 1).any():
        raise ParameterError(f"S must be a fraction of the stroke below 1 (0.02 = 2 %), got {s.max()}")
    if (j > s * (1 + 1e-12)).any():
        k = int(np.argmax(j - s))
        raise ParameterError(f"J <= S is required (a slip jump larger than the stick band is not supported "
                             f"by every model), got S = {float(s.reshape(-1)[k])}, J = {float(j.reshape(-1)[k])}")
    if s.ndim == 0:
        return float(s), float(j)
    return s.astype(float).copy(), j.astype(float).copy()


def frictionless(base: ModelParams) -> ModelParams:
    """``base`` with every friction removed: no slip-jump block, ``e_dead = z_max = 0``.

    The valve keeps its positioner lag ``tau`` and speed limit ``v_max``, and
    the plant and every other block are unchanged.
    """
    if not isinstance(base, ModelParams):
        raise ParameterError(f"base must be a valve_gym.params.ModelParams, got {type(base).__name__}")
    return replace(base, valve=replace(base.valve, e_dead=0.0, z_max=0.0), slip_jump=None)
