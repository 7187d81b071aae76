"""Optional physics blocks as specs: what the diagnosis tool tries, fits and explains.

>>> from valve_gym.effects import CANDIDATE_EFFECTS, effect_spec
>>> CANDIDATE_EFFECTS[:3]
('slip_jump', 'valve_characteristic', 'dead_time')
>>> effect_spec("leak").applicable("integrating", "valve")[0]
False
>>> [p.name for p in effect_spec("dead_time").params]
['theta']

Each built-in effect is one module here that declares an
:class:`~valve_gym.effects.spec.EffectSpec`; importing the package registers
them in the order the diagnosis tries them. A new effect that acts on the
measurement is a single file (``docs/extending.md``).
"""
from __future__ import annotations

from . import (  # noqa: F401
    dead_time,
    leak,
    oscillating_disturbance,
    overflow,
    sensor_curve,
    sensor_lag,
    slip_jump,
    tank_shape,
    valve_characteristic,
)
from .spec import EffectSpec, effect_spec, register_effect, registered_effects

__all__ = ["CANDIDATE_EFFECTS", "EffectSpec", "effect_spec", "register_effect", "candidate_effects"]

_ORDER = ("slip_jump", "valve_characteristic", "dead_time", "overflow", "leak", "sensor_lag",
          "sensor_curve", "oscillating_disturbance", "tank_shape")


def candidate_effects() -> tuple[str, ...]:
    """Every registered effect in the order the diagnosis tries them: the built-ins, then those added later."""
    names = registered_effects()
    return tuple(sorted(names, key=lambda e: _ORDER.index(e) if e in _ORDER else len(_ORDER) + names.index(e)))


#: The built-in effects, in the order they are tried (:func:`candidate_effects` adds the
#: effects registered later).
CANDIDATE_EFFECTS: tuple[str, ...] = tuple(e for e in candidate_effects() if e in _ORDER)
