"""The process model a loop's tag stands for: ``plant='auto'``.

Plant historians name loops by their ISA-5.1 tag: the first letter is the measured variable
(``F`` flow, ``L`` level, ``P`` pressure, ``T`` temperature, ``A`` analysis), followed by
``IC`` (indicating controller), ``RC`` or ``C`` and the loop number (``FIC31102``,
``2411LIC10201``, ``LIC-106``).  A level in a vessel whose outflow is pumped or set
downstream integrates its inflow (``'integrating'``); flow, pressure, temperature and
analysis loops settle (``'first_order'``).  This is the choice the held-out stiction
validation of ``docs/diagnosis.md`` was made with (level loops integrating, all others first
order).  A name without such a code keeps the package's level-tank model (``'tank'``), and a
name with codes of both kinds is ambiguous: ``'tank'`` too, with the reason.  The choice and
its reason are reported; ``plant=`` names the model outright.
"""
from __future__ import annotations

import re

__all__ = ["AUTO", "DEFAULT_PLANT", "plant_from_name", "resolve_plant"]

#: The value of ``plant`` that asks for the choice from the name.
AUTO = "auto"
#: The model of a recording whose name carries no loop tag: the package's level tank.
DEFAULT_PLANT = "tank"

_LETTER = {"F": ("first_order", "flow"), "P": ("first_order", "pressure"),
           "T": ("first_order", "temperature"), "A": ("first_order", "analysis"),
           "L": ("integrating", "level")}
# first letter, optional I or R, C, optional separator, a digit; not inside a word ("STICTION")
_TAG = re.compile(r"(?<![A-Z])([FPTAL])[IR]?C[-_. ]?\d")


def plant_from_name(name: str) -> tuple[str, str]:
    """Process model for a recording called ``name`` and the reason (a sentence).

    Examples
    --------
    >>> plant_from_name("2411FIC20102_0609_0957")[0]
    'first_order'
    >>> plant_from_name("no_stiction__2111LIC23001_1110_0008")[0]
    'integrating'
    >>> plant_from_name("leak_100")[0]
    'tank'
    """
    found = [(m.group(0).rstrip("0123456789-_. "), m.group(1)) for m in _TAG.finditer(str(name).upper())]
    kinds = {_LETTER[letter] for _, letter in found}
    plants = {p for p, _ in kinds}
    if not found:
        return DEFAULT_PLANT, (f"no loop tag (FIC, LIC, PIC, TIC, AIC ...) in the name {name!r}: the level-tank "
                               f"model '{DEFAULT_PLANT}' (name another with plant=/--plant)")
    codes = ", ".join(sorted({c for c, _ in found}))
    if len(plants) > 1:
        return DEFAULT_PLANT, (f"the name {name!r} carries loop tags of both kinds ({codes}): the level-tank model "
                               f"'{DEFAULT_PLANT}' (name another with plant=/--plant)")
    plant = plants.pop()
    what = "/".join(sorted(v for _, v in kinds))
    why = "integrates its inflow" if plant == "integrating" else "settles (self-regulating)"
    return plant, (f"loop tag {codes} in the name: a {what} loop, which {why}: '{plant}' "
                   f"(name another with plant=/--plant)")


def resolve_plant(plant: str, name: str) -> tuple[str, dict]:
    """The process model ``plant`` stands for on a recording called ``name``, and the choice (JSON-ready)."""
    if plant != AUTO:
        return plant, {"asked": plant, "chosen": plant}
    chosen, why = plant_from_name(name)
    return chosen, {"asked": AUTO, "chosen": chosen, "reason": why}
