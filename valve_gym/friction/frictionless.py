"""``none``: a frictionless valve (the lower bound of every stiction comparison).

The seed valve of :class:`valve_gym.params.ValveParams` with ``e_dead = z_max = 0``:
a first-order positioner with the same time constant ``tau`` (and speed limit
``v_max``) as the sticky valves, no dead band, no stick band, no jump.
"""
from __future__ import annotations

from ..params import ModelParams
from .spec import FrictionSpec, ParamSpec, frictionless, register

__all__ = ["SPEC", "build"]


def build(base: ModelParams, S, J) -> ModelParams:
    """``base`` without friction; ``S`` and ``J`` are ignored (checked by the caller).

    Notes
    -----
    ``dh/dt = sign(e) min(|e|/tau, v_max)`` with ``e = u - h``: the stem follows
    the input with the positioner lag only.
    """
    return frictionless(base)


SPEC = register(FrictionSpec(
    name="none",
    title="frictionless valve",
    params=(ParamSpec("tau", "s", 1e-3, 10.0, 0.1, "fixed", "positioner time constant (kept from the base valve)"),
            ParamSpec("v_max", "1/s", 1e-3, float("inf"), 0.5, "fixed",
                      "stem speed limit, strokes per second (kept from the base valve)")),
    kernel="Riihilahti block of the core with e_dead = z_max = 0: dh/dt = sign(e) min(|e|/tau, v_max), "
           "every Euler step.",
    signature="The stem follows the controller output with a first-order lag; no flat stem segments, no "
              "jumps, no offset while moving.",
    report="Frictionless valve (S = 0, J = 0): the stem follows the controller output with the positioner lag.",
    citation="No friction model; the positioner lag is that of K. Yamé, L. El Bahir, \"Teaching control valve "
             "friction using modeling and simulation\", after M. Riihilahti, \"Modeling and simulation of "
             "control valve nonlinearities\", Helsinki University of Technology, 1997.",
    build=build,
))
