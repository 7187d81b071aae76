"""The names of the quantities, written down once.

valve_gym speaks two vocabularies, each used by one layer, and maps them here:

* the **physics** (:mod:`valve_gym.core`, :mod:`valve_gym.params`,
  :mod:`valve_gym.friction`, the environments' ``info``) uses the paper's symbols:
  level ``L``, valve input ``u``, stem ``h``, friction target ``x``;
* the **control system** (the DCS blocks of :mod:`valve_gym.agents.controllers`, the
  benchmark, the recordings the diagnosis reads, :class:`valve_gym.plant.Plant`'s
  output) uses the plant's tag words: set point ``sp``, process variable ``pv``,
  controller output ``op``.

One quantity has one name in each layer, and the table says which is which.

>>> from valve_gym.quantities import name_of
>>> name_of("op")
'valve input, fraction of stroke (physics: u, control: op)'
>>> name_of("L")
'level of the measured tank, m (physics: L, control: pv)'
"""
from __future__ import annotations

from typing import NamedTuple

__all__ = ["Quantity", "QUANTITIES", "name_of"]


class Quantity(NamedTuple):
    """One quantity: its name in the physics layer, in the control layer, its unit and meaning."""

    physics: str
    control: str
    unit: str
    meaning: str


#: Every quantity with a name in the public API.
QUANTITIES: tuple[Quantity, ...] = (
    Quantity("L", "pv", "m", "level of the measured tank (pv: as the transmitter reads it, with noise)"),
    Quantity("L_sp", "sp", "m", "set point of the level"),
    Quantity("u", "op", "fraction of stroke", "valve input (controller output), 0..1"),
    Quantity("h", "stem", "fraction of stroke", "valve stem position, 0..1"),
    Quantity("x", "x", "fraction of stroke", "target of the positioner lag after a slip-jump friction law"),
    Quantity("S", "S", "fraction of stroke", "stick band (+ dead band): input travel after a reversal before "
             "the stem moves"),
    Quantity("J", "J", "fraction of stroke", "slip jump: the stem's jump when it breaks away"),
    Quantity("z_max", "z_max", "s", "half width of the paper's friction band (integrated error)"),
    Quantity("e_dead", "e_dead", "fraction of stroke", "half dead band of the paper's valve"),
    Quantity("tau", "tau", "s", "valve (positioner) time constant"),
    Quantity("v_max", "v_max", "1/s", "stem speed limit, strokes per second"),
    Quantity("q_in", "q_in", "m^3/s", "inflow through the valve"),
    Quantity("d", "load", "m^3/s", "load: extra inflow (negative: offtake)"),
    Quantity("dt", "dt", "s", "Euler step of the core"),
    Quantity("scan_s", "scan_s", "s", "control period (scan) of a DCS block and of the plant stepper"),
    Quantity("Kc", "Kc", "1/m", "PI gain (fraction of stroke per metre of error)"),
    Quantity("Ti", "Ti", "s", "PI integral time"),
    Quantity("e", "error", "m", "control error sp - pv"),
    Quantity("theta", "theta", "s", "dead time"),
    Quantity("R", "R", "-", "rangeability of an equal-percentage valve"),
)


def name_of(name: str) -> str:
    """Meaning, unit and both names of the quantity called ``name`` in either layer.

    Raises
    ------
    KeyError
        For a name the table does not have (the message lists the names).
    """
    for q in QUANTITIES:
        if name in (q.physics, q.control):
            return f"{q.meaning.split(' (')[0].split(',')[0]}, {q.unit} (physics: {q.physics}, control: {q.control})"
    names = sorted({n for q in QUANTITIES for n in (q.physics, q.control)})
    raise KeyError(f"no quantity called {name!r}; the names are {', '.join(names)}")
