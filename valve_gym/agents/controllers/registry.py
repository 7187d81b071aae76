"""Controllers by name: :func:`load_controller` and :func:`available_controllers`.

One table maps each name to the block that implements it; the benchmark, the
environment wrappers and the training evaluation build controllers only
through :func:`load_controller`, so a controller added here is available to all
of them. ``"learned"`` is the trained adaptive compensator
(:func:`valve_gym.agents.adaptive.load_adaptive`: a PI with reinforcement and knocker pulses sized by an
online stick-band estimate, trained over a randomised family of plants); ``"learned_network"`` is the
network block trained on the benchmark's tank (``valve_gym.agents.learned.load_learned``, loaded lazily).
``"learned_adaptive"``, the adaptive compensator's earlier name, is still accepted (:data:`ALIASES`).
"""
from __future__ import annotations

import importlib
from collections.abc import Callable

from .block import FunctionBlock
from .constant_reinforcement import ConstantReinforcement
from .integral_freeze import IntegralFreeze
from .knocker import Knocker
from .pi import PIBlock
from .two_move import TwoMove

__all__ = ["load_controller", "available_controllers", "ControllerLoadError", "ALIASES"]


class ControllerLoadError(ValueError):
    """A named controller exists but could not be built (e.g. the learned weights are missing)."""


def _load_learned(**settings):
    try:
        mod = importlib.import_module("valve_gym.agents.learned")
    except ImportError as exc:
        raise ControllerLoadError(
            "the learned network could not be loaded: module valve_gym.agents.learned is not available "
            f"({exc}); install valve_gym with its agents package, or use another controller: "
            f"{', '.join(available_controllers())}") from exc
    loader = getattr(mod, "load_learned", None)
    if loader is None:
        raise ControllerLoadError("the learned network could not be loaded: valve_gym.agents.learned has no "
                                  "load_learned(path=None, **settings)")
    try:
        return loader(**{"name": "learned_network", **settings})
    except ValueError:
        raise
    except Exception as exc:  # noqa: BLE001 - any failure of the loader is reported with its cause
        raise ControllerLoadError(f"the learned network could not be loaded: {type(exc).__name__}: {exc}") \
            from exc


def _load_adaptive(**settings):
    from valve_gym.agents.adaptive import load_adaptive

    try:
        return load_adaptive(**{"name": "learned", **settings})
    except (ValueError, TypeError):
        raise
    except Exception as exc:  # noqa: BLE001 - a missing or unreadable file is reported with its cause
        raise ControllerLoadError(f"the learned compensator could not be loaded: {type(exc).__name__}: {exc}") \
            from exc


_BLOCKS: dict[str, type] = {cls.name: cls for cls in (PIBlock, Knocker, ConstantReinforcement, TwoMove,
                                                       IntegralFreeze)}
_LOADERS: dict[str, Callable[..., object]] = {**_BLOCKS, "learned": _load_adaptive,
                                              "learned_network": _load_learned}
#: Earlier names still accepted by :func:`load_controller`: name -> the name it stands for now.
ALIASES = {"learned_adaptive": "learned"}


def available_controllers() -> tuple[str, ...]:
    """Names :func:`load_controller` accepts.

    Examples
    --------
    >>> available_controllers()
    ('pi', 'knocker', 'constant_reinforcement', 'two_move', 'integral_freeze', 'learned', 'learned_network')
    """
    return tuple(_LOADERS)


def load_controller(name: str, **settings) -> FunctionBlock:
    """Build the controller ``name`` with ``settings`` (defaults: module docs of each block).

    Parameters
    ----------
    name : str, one of :func:`available_controllers`
    **settings
        The block's settings (``Kc`` [1/m], ``Ti`` [s], ``scan_s`` [s], ``op_lo``,
        ``op_hi``, and for compensators the stiction estimate ``S`` [fraction
        of stroke] and their own); ``"learned"`` and ``"learned_network"``
        take ``path`` (None: the shipped file). Gains and stiction settings
        may be ``(n,)`` arrays, one value per loop.

    Returns
    -------
    FunctionBlock
        ``reset(sp, pv, op)``, ``step(sp, pv)``, ``name``, ``scan_s``, ``settings``.

    Raises
    ------
    ValueError
        Unknown name (listing the names), unknown setting, wrong type or value
        out of range (listing the allowed ones); :class:`ControllerLoadError`
        (a ValueError) when a learned block cannot be loaded, saying why.

    Examples
    --------
    >>> ctrl = load_controller("knocker", S=0.03)
    >>> ctrl.settings["a"], ctrl.settings["h_k"]
    (0.015, 3.0)
    >>> load_controller("pid")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: unknown controller 'pid'; available: pi, knocker, constant_reinforcement, two_move, ...
    """
    if not isinstance(name, str) or (name not in _LOADERS and name not in ALIASES):
        raise ValueError(f"unknown controller {name!r}; available: {', '.join(available_controllers())}")
    name = ALIASES.get(name, name)
    unset = sorted(k for k, v in settings.items()
                   if v is None and not (name in ("learned", "learned_network") and k == "path"))
    if unset:
        raise ValueError(f"{name}: setting(s) {unset} given as None; leave a setting out to use its default, "
                         "or give a number")
    return _LOADERS[name](**settings)  # type: ignore[return-value]
