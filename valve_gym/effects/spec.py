"""Specs and registry of the optional physics blocks (the diagnosis tool's candidate effects).

An effect is one module of :mod:`valve_gym.effects` that declares an
:class:`EffectSpec`: its physical parameters (name, unit, range, default, prior),
how it enters the simulation, its diagnostic signature (what it looks like in the
residual of a model without it, and which located conditions point at it), and the
rules the fitter and the report need: its free coordinates scaled from the data,
the block it builds, its fitted parameters as reported, their units and the
paragraph that explains it. The registry maps names to specs; the fitter
(:mod:`valve_gym.diagnosis.model`), the candidate search
(:mod:`valve_gym.diagnosis.select`) and the report (:mod:`valve_gym.diagnosis.explain`)
iterate it and name no effect themselves.

Two kinds of effect:

* a **kernel effect** (``dead_time``, ``leak``, ...) is a block of
  :class:`valve_gym.params.ModelParams` (a frozen dataclass in
  :mod:`valve_gym.params`, compiled into the core); its ``build`` returns that
  block;
* a **measurement effect** acts on the simulated process variable after the
  core (``measure``), so it needs no change to the core: a new one is a single
  file (``docs/extending.md`` shows one).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ..paramspec import FreeParam, ParamSpec, Registry

__all__ = ["EffectSpec", "FitContext", "register_effect", "effect_spec", "registered_effects",
           "unregister_effect", "always_applies"]


class FitContext(Protocol):
    """What an effect's rules may read of the model structure being fitted.

    Attributes
    ----------
    plant : str, ``'tank'``, ``'integrating'``, ``'first_order'`` or ``'cascade'``
    actuator : str, ``'valve'`` or ``'pump'``
    scales : DataScales of the recording (``dt``, ``duration``, ``y_range``, ...)
    variants : dict, the chosen variant per effect
    period_hint : float or None, period [s] of the base residual's strongest oscillation
    t_min : float, smallest time constant searched [s]
    """

    plant: str
    actuator: str
    scales: Any
    variants: dict
    period_hint: float | None

    @property
    def t_min(self) -> float:
        """Smallest time constant searched [s]."""
        ...


def always_applies(plant: str, actuator: str) -> str:
    """Applicability rule of an effect that fits every plant and actuator: no reason against."""
    return ""


def _no_params(ctx: FitContext) -> list[FreeParam]:
    return []


def _no_physical(ctx: FitContext, v: dict, mp: Any, sign: np.ndarray, offset: np.ndarray) -> dict:
    return {}


def _no_units(plant: str) -> dict:
    return {}


@dataclass(frozen=True)
class EffectSpec:
    """Declaration of one optional physics block.

    Attributes
    ----------
    name : str
        Registry name, the effect's name in the diagnosis JSON and the CLI
        (``--effects``); for a kernel effect also the field of
        :class:`~valve_gym.params.ModelParams` that holds its block.
    title : str
        Short human name.
    params : tuple of ParamSpec
        The block's physical parameters (name, unit, range, default, prior).
    kernel : str
        How the block enters the simulation.
    signature : str
        What a model without the effect leaves in its residual.
    conditions : tuple of str
        Located operating conditions (:func:`valve_gym.diagnosis.locate.condition_masks`)
        whose residual points at the effect.
    citation : str
        Where the physics comes from.
    applies : callable ``(plant, actuator) -> str``
        ``""`` when the effect can be identified for that plant and actuator, else
        the reason why not.
    free : callable ``(ctx) -> list[FreeParam]``
        The fitter's free coordinates, ranges scaled from ``ctx.scales``.
    neutral : mapping
        Unit coordinate of each free coordinate at which the effect leaves the base
        model unchanged (the start of a candidate fit); missing names start at 0.5.
    build : callable ``(ctx, v, dte, part) -> block``, optional
        The :class:`~valve_gym.params.ModelParams` block for decoded values ``v``
        (``{name: (n,) array}``), Euler step ``dte`` [s] and the plant's part
        ``part`` (``sign``, ``offset``: measurement map, ``flow_scale``: typical
        inflow per row). ``None`` for a measurement effect.
    measure : callable ``(ctx, v, t, Y) -> Y``, optional
        For a measurement effect: the measured PV ``(T, n)`` from the simulated
        one ``Y`` (recording units) at times ``t`` ``(T,)`` [s].
    physical : callable ``(ctx, v, mp, sign, offset) -> dict``
        Reported fitted parameters ``{"<name>.<field>": value}`` of one row
        (``v`` decoded values, ``mp`` the scalar ModelParams).
    units : callable ``(plant) -> dict``
        Units of the keys of ``physical``.
    explain : callable ``(before, after, mm, pv_unit, imp, where) -> str``
        The report paragraph: evidence from the mismatch report ``mm`` of the fit
        ``before`` (without the effect), fitted values of ``after``, ``imp`` the
        improvement sentence, ``where`` the region sentence.
    variants : tuple
        Variants tried as separate candidates (``(None,)``: one).
    variant_k : mapping
        Extra parameters a variant counts for (a choice between forms counts as one).
    flow_fraction : callable ``(ctx, v, u) -> f``, optional
        Flow fraction of a valve opening ``u`` (for an effect that changes the
        installed characteristic; the fitter scales the plant at the mean opening).
    seed : callable ``(prev_values, structure, seeds) -> seeds``, optional
        Starting coordinates of a candidate fit from the values of the model without it.
    map_offset : callable ``(ctx, v) -> (n,) array``, optional
        For a measurement effect that reads the core's level from another zero than the
        plant's map: the amount subtracted from the map's offset (``PV_lin = sign * y_core +
        offset``), so that the levels the plant sets in PV terms (initial level, a tank's top)
        follow it (``sensor_curve``: the curve's zero above the outlet).
    rivals_friction : bool
        The effect delays the response as valve friction does; the stiction
        verdict pits friction against a frictionless valve with this effect.
    rugged : bool
        The fit's cost surface is rugged (stick-slip: the error jumps as a stick
        band crosses an output move), so a screening search can miss the gain the
        full search finds; the selection confirms it whenever it is shortlisted,
        whatever its screening result (:data:`valve_gym.diagnosis.select.CONFIRM_BELOW`).
    """

    name: str
    title: str
    params: tuple[ParamSpec, ...]
    kernel: str
    signature: str
    explain: Callable[..., str]
    conditions: tuple[str, ...] = ()
    citation: str = ""
    applies: Callable[[str, str], str] = always_applies
    free: Callable[[FitContext], list[FreeParam]] = _no_params
    neutral: Mapping[str, float] = field(default_factory=dict)
    build: Callable[..., Any] | None = None
    measure: Callable[..., np.ndarray] | None = None
    physical: Callable[..., dict] = _no_physical
    units: Callable[[str], dict] = _no_units
    variants: tuple[str | None, ...] = (None,)
    variant_k: Mapping[str, int] = field(default_factory=dict)
    flow_fraction: Callable[..., np.ndarray] | None = None
    seed: Callable[..., np.ndarray] | None = None
    rivals_friction: bool = False
    rugged: bool = False
    map_offset: Callable[..., np.ndarray] | None = None

    def __post_init__(self):
        if not self.name.isidentifier():
            raise ValueError(f"effect name {self.name!r} must be a Python identifier (it names JSON keys)")
        if (self.build is None) == (self.measure is None):
            raise ValueError(f"effect {self.name!r}: give exactly one of build (a kernel block) or measure "
                             f"(an effect on the measured PV)")
        if not self.variants:
            raise ValueError(f"effect {self.name!r}: variants must list at least one (None for a single form)")

    def param(self, name: str) -> ParamSpec:
        """The :class:`ParamSpec` called ``name`` (``KeyError`` listing the names otherwise)."""
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(f"{self.name} has no parameter {name!r}; it has {[p.name for p in self.params]}")

    def applicable(self, plant: str, actuator: str) -> tuple[bool, str]:
        """``(True, "")`` when the effect can be identified here, else ``(False, reason)``."""
        why = self.applies(plant, actuator)
        return (not why), why


_REGISTRY = Registry("effect", EffectSpec)


def register_effect(spec: EffectSpec) -> EffectSpec:
    """Add ``spec`` to the registry (a name can be registered once); returns it.

    A kernel effect's name must be a block of :class:`valve_gym.params.ModelParams`.
    """
    if spec.build is not None:
        from ..params import EFFECTS
        if spec.name not in EFFECTS:
            raise ValueError(f"kernel effect {spec.name!r} has no block in valve_gym.params.EFFECTS "
                             f"({', '.join(EFFECTS)}); an effect outside the core must use measure=")
    return _REGISTRY.add(spec)


def unregister_effect(name: str) -> None:
    """Remove a registered effect (for tests and plug-ins that replace one)."""
    _REGISTRY.remove(name)


def registered_effects() -> tuple[str, ...]:
    """Names of the registered effects, in registration order."""
    return _REGISTRY.names()


def effect_spec(name: str) -> EffectSpec:
    """The :class:`EffectSpec` of effect ``name``.

    Raises
    ------
    ValueError
        For an unknown name; the message lists the known effects.
    """
    return _REGISTRY.get(name)
