"""Valve friction models, each one module with its spec, and the one way to build a sticky valve.

>>> from valve_gym.friction import FRICTION_MODELS, friction_spec, valve_model
>>> FRICTION_MODELS[:3]
('none', 'riihilahti', 'choudhury')
>>> p = valve_model("choudhury", S=0.03, J=0.01)
>>> p.slip_jump.S, p.slip_jump.J
(0.03, 0.01)
>>> print(friction_spec("choudhury").describe(0.03, 0.01))  # doctest: +ELLIPSIS
Stiction (Choudhury, Thornhill & Shah 2005): stick band + dead band S = 3 % of stroke, slip jump J = 1 %; ...

Every model is sized by the same two numbers, fractions of the stroke: the
stick band ``S`` (input travel after a reversal before the stem moves) and the
slip jump ``J`` (the stem's jump when it breaks away). How a model honours them
is in its module (``S``, ``J`` are exact for the data-driven models, mapped at a
reference input speed for the seed model).
"""
from __future__ import annotations

from ..params import ModelParams, ParameterError
from . import choudhury, frictionless, kano, karnopp, riihilahti  # noqa: F401  (register the models)
from .spec import FrictionSpec, ParamSpec, as_band, friction_spec, registered
from .spec import frictionless as remove_friction

__all__ = ["FRICTION_MODELS", "FrictionSpec", "ParamSpec", "friction_spec", "valve_model", "remove_friction"]

_ORDER = ("none", "riihilahti", "choudhury", "kano", "karnopp")

#: Names of the built-in friction models (:func:`~valve_gym.friction.spec.registered` lists
#: every registered one, models added later included).
FRICTION_MODELS: tuple[str, ...] = tuple(sorted(registered(), key=lambda m: _ORDER.index(m)
                                                if m in _ORDER else len(_ORDER)))


def valve_model(model: str, S, J, base: ModelParams | None = None) -> ModelParams:
    """Model parameters of a valve with friction ``model`` sized by stick band ``S`` and slip jump ``J``.

    Parameters
    ----------
    model : str
        One of :data:`FRICTION_MODELS`.
    S : float or (n,) array, fraction of stroke
        Stick band + dead band: input travel after a reversal before the stem
        moves (0 <= S < 1).
    J : float or (n,) array, fraction of stroke
        Slip jump (0 <= J <= S). ``"none"`` ignores ``S`` and ``J``.
    base : ModelParams, optional
        Plant, valve positioner and other blocks (default: the default tank,
        :class:`~valve_gym.params.ModelParams`). Its own friction is removed
        first.

    Returns
    -------
    ModelParams
        Batched (``(n,)`` fields) when ``S`` or ``J`` is an array.

    Raises
    ------
    ValueError
        Unknown ``model`` (the message lists the models).
    valve_gym.params.ParameterError
        ``S``, ``J`` out of range (negative, ``S >= 1``, ``J > S``), not finite,
        or of different lengths.

    Examples
    --------
    >>> import numpy as np
    >>> p = valve_model("riihilahti", np.array([0.01, 0.04]), np.array([0.005, 0.02]))
    >>> p.batch_size()
    2
    """
    spec = friction_spec(model)
    if base is None:
        base = ModelParams()
    if not isinstance(base, ModelParams):
        raise ParameterError(f"base must be a valve_gym.params.ModelParams, got {type(base).__name__}")
    s, j = as_band(S, J)
    return spec.build(remove_friction(base), s, j)
