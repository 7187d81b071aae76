"""``slip_jump``: stick-slip valve friction sized by a stick band ``S`` and a slip jump ``J``.

In the diagnosis this effect replaces the paper's integral friction (``z_max``,
``e_dead``) by the two-parameter model of Choudhury, Thornhill & Shah (2005),
applied once per sample, with a positioner lag of one Euler step. The block is
:class:`valve_gym.params.SlipJump`; its kernel laws are the friction models of
:mod:`valve_gym.friction`.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..params import SlipJump
from ..paramspec import FreeParam, ParamSpec
from .spec import EffectSpec, FitContext, register_effect
from .text import cond, pct

__all__ = ["SPEC"]


def _applies(plant: str, actuator: str) -> str:
    return "" if actuator == "valve" else f"slip_jump acts on a valve; the actuator is a {actuator}"


def _free(ctx: FitContext) -> list[FreeParam]:
    s_hi = float(np.clip(ctx.scales.u_range, 0.008, 0.3))
    return [FreeParam("S", 0.0, s_hi, "sq", "-", "stick band + dead band, fraction of stroke"),
            FreeParam("J_rel", 0.0, 2.0, "lin", "-", "slip jump relative to S, J/S")]


def _build(ctx: FitContext, v: dict, dte: float, part: Any) -> SlipJump:
    return SlipJump(S=v["S"], J=np.minimum(v["S"] * v["J_rel"], 1.0), tau_p=dte)


def _physical(ctx: FitContext, v: dict, mp: Any, sign, offset) -> dict:
    if mp.slip_jump is None:
        return {}
    return {"slip_jump.S": mp.slip_jump.S, "slip_jump.J": mp.slip_jump.J}


def _units(plant: str) -> dict:
    return {"slip_jump.S": "fraction of stroke", "slip_jump.J": "fraction of stroke"}


def _seed(prev: dict, structure: Any, seeds: np.ndarray) -> np.ndarray:
    """Start the stick band where the dead band of the paper's valve was (S = 2 e_dead)."""
    if "e_dead" not in prev:
        return seeds
    i = structure.index("S")
    seeds = seeds.copy()
    seeds[0, i] = float(structure.params[i].coord(2.0 * float(prev["e_dead"][0])))
    return seeds


def _explain(before: Any, after: Any, mm: Any, pv_unit: str, imp: str, where: str) -> str:
    p = after.physical
    S, J = p.get("slip_jump.S", float("nan")), p.get("slip_jump.J", float("nan"))
    if J > 1.1 * S:
        kind = "J > S: the stem overshoots the controller output after it breaks free"
    elif J < 0.9 * S:
        kind = "J < S: the stem stops short of the controller output (undershoot)"
    else:
        kind = "J ~ S: the stem jumps to the controller output"
    ev = cond(mm, "near_op_reversal")
    return (f"Slip-jump valve friction. Evidence: {ev or 'the base model misses after reversals'}; "
            f"the stem sticks when the controller output reverses and then jumps, which the "
            f"paper's integral friction model cannot reproduce. Fitted stick band S = "
            f"{pct(S)} and slip jump J = {pct(J)} of the stroke ({kind}). {imp}.{where}")


SPEC = register_effect(EffectSpec(
    name="slip_jump", title="Slip-jump valve friction",
    params=(ParamSpec("S", "-", 0.0, 1.0, 0.02, "sq", "stick band + dead band, fraction of stroke"),
            ParamSpec("J", "-", 0.0, 1.0, 0.01, "lin", "slip jump, fraction of stroke"),
            ParamSpec("tau_p", "s", 1e-6, 100.0, 0.1, "fixed", "positioner time constant (one Euler step)")),
    kernel="the slip_jump block of the core: the friction law once per sample, then the positioner lag",
    signature="the base model misses right after the controller output reverses (the stem sticks, then jumps)",
    conditions=("near_op_reversal",),
    citation="M.A.A.S. Choudhury, N.F. Thornhill, S.L. Shah, Control Engineering Practice 13 (2005) 641-658.",
    applies=_applies, free=_free, neutral={"S": 0.3, "J_rel": 0.5}, build=_build, physical=_physical,
    units=_units, explain=_explain, seed=_seed, rugged=True))
