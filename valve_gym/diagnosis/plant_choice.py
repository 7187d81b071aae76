"""The process model a loop's tag stands for: ``plant='auto'``.

Plant historians name loops by their ISA-5.1 tag: the first letter is the measured variable
(``F`` flow, ``L`` level, ``P`` pressure, ``T`` temperature, ``A`` analysis), followed by
``IC`` (indicating controller), ``RC`` or ``C`` and the loop number (``FIC31102``,
``2411LIC10201``, ``LIC-106``).  A level in a vessel whose outflow is pumped or set
downstream integrates its inflow (``'integrating'``); flow, pressure, temperature and
analysis loops settle (``'first_order'``).  This is the choice the held-out stiction
validation of ``docs/diagnosis.md`` was made with (level loops integrating, all others first
order).  What the model maps the controller output to is the recorded PV, so the PV column's
own name is read first: a transmitter tag (``FT115``, ``LT-101``), a loop tag (``LIC101.PV``)
or a word (``flow``, ``pressure``, ``temperature``; ``level`` alone decides nothing, a column so
called is as often a tank rig's); a level-loop file whose PV column
is the flow through its valve (``flow_FT115``) is a flow-to-valve relation, first order.  Then
the recording's name.  Neither: the package's level-tank model (``'tank'``); codes of both kinds
are ambiguous: ``'tank'`` too, with the reason.  The choice and its reason are reported;
``plant=`` names the model outright.
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
# in a column name also a transmitter (FT115, LT-101), and the measured variable in words
_COLUMN_TAG = re.compile(r"(?<![A-Z])([FPTAL])(?:[IR]?C|T)[-_. ]?\d")
# ("level" alone decides nothing: a column so called is as often a tank rig's as a plant loop's)
_WORDS = {"FLOW": "F", "PRESS": "P", "TEMP": "T"}


def _codes(text: str, column: bool) -> list[tuple[str, str]]:
    """(code, first letter) of every loop tag in ``text``; in a column name also transmitters and words."""
    up = str(text).upper()
    found = [(m.group(0).rstrip("0123456789-_. "), m.group(1)) for m in (_COLUMN_TAG if column else _TAG).finditer(up)]
    if column:
        found += [(w.lower(), letter) for w, letter in _WORDS.items() if w in up]
    return found


def _choose(found: list[tuple[str, str]], where: str) -> tuple[str, str] | None:
    """The model the codes ``found`` in ``where`` stand for, and the reason; None without codes."""
    if not found:
        return None
    kinds = {_LETTER[letter] for _, letter in found}
    plants = {p for p, _ in kinds}
    codes = ", ".join(sorted({c for c, _ in found}))
    if len(plants) > 1:
        return DEFAULT_PLANT, (f"{where} carries codes of both kinds ({codes}): the level-tank model "
                               f"'{DEFAULT_PLANT}' (name another with plant=/--plant)")
    plant = plants.pop()
    what = "/".join(sorted(v for _, v in kinds))
    why = "integrates its inflow" if plant == "integrating" else "settles (self-regulating)"
    return plant, f"{codes} in {where}: a {what} loop, which {why}: '{plant}' (name another with plant=/--plant)"


def plant_from_name(name: str, pv_column: str | None = None) -> tuple[str, str]:
    """Process model for a recording called ``name`` whose PV column is ``pv_column``, and the reason.

    Examples
    --------
    >>> plant_from_name("2411FIC20102_0609_0957")[0]
    'first_order'
    >>> plant_from_name("no_stiction__2111LIC23001_1110_0008", pv_column="PV")[0]
    'integrating'
    >>> plant_from_name("LIC-106_sorted", pv_column="flow_FT115")[0]     # the flow through the level valve
    'first_order'
    >>> plant_from_name("leak_100")[0]
    'tank'
    """
    for text, where, column in ((pv_column, f"the PV column {pv_column!r}", True),
                                (name, f"the name {name!r}", False)):
        if text:
            got = _choose(_codes(text, column), where)
            if got is not None:
                return got
    return DEFAULT_PLANT, (f"no loop tag (FIC, LIC, PIC, TIC, AIC ...) in the name {name!r}"
                           + (f" or the PV column {pv_column!r}" if pv_column else "")
                           + f": the level-tank model '{DEFAULT_PLANT}' (name another with plant=/--plant)")


def resolve_plant(plant: str, name: str, pv_column: str | None = None) -> tuple[str, dict]:
    """The process model ``plant`` stands for, and the choice (JSON-ready).

    ``name``: the recording's name; ``pv_column``: the name of its PV column, if known.
    """
    if plant != AUTO:
        return plant, {"asked": plant, "chosen": plant}
    chosen, why = plant_from_name(name, pv_column)
    return chosen, {"asked": AUTO, "chosen": chosen, "reason": why}
