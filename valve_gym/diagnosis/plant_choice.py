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
the recording's name.  Neither (or codes of both kinds): the process model is chosen from the data
(:func:`plant_from_data`: self-regulating or integrating, with or without dead time, fitted and
compared); without data, the package's level-tank model (``'tank'``).  The choice and its reason
are reported; ``plant=`` names the model outright.
"""
from __future__ import annotations

import math
import re

import numpy as np

__all__ = ["AUTO", "DEFAULT_PLANT", "plant_from_data", "plant_from_name", "resolve_plant"]

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


def _tag_choice(name: str, pv_column: str | None) -> tuple[str, str] | None:
    """The model a loop tag in the PV column or the name stands for (None without one, or with codes of both kinds)."""
    for text, where, column in ((pv_column, f"the PV column {pv_column!r}", True),
                                (name, f"the name {name!r}", False)):
        if text:
            found = _codes(text, column)
            if found:
                if len({_LETTER[letter][0] for _, letter in found}) > 1:
                    return None
                return _choose(found, where)
    return None


#: Longest dead time tried by :func:`plant_from_data` [samples].
MAX_DEAD_TIME = 20
#: Least fall of the information criterion (BIC) for a dead time to count.
DEAD_TIME_MARGIN = 6.0


def _arx(y: np.ndarray, u: np.ndarray, d: int, integrating: bool) -> tuple[float, np.ndarray, int]:
    """One-step least-squares fit; (residual variance, coefficients, n).

    Self-regulating: ``y[k] = a1 y[k-1] + a2 y[k-2] + b u[k-1-d] + c``; integrating, the same with a pole
    at 1 (``a1 + a2 = 1``): ``dy[k] = a dy[k-1] + b u[k-1-d] + c``.
    """
    k0 = 2 + d + 1
    yk = y[k0:]
    if integrating:
        dy = np.diff(y)
        X = np.column_stack([dy[k0 - 2:-1], u[k0 - 1 - d:len(y) - 1 - d], np.ones(len(yk))])
        target = dy[k0 - 1:]
    else:
        X = np.column_stack([y[k0 - 1:-1], y[k0 - 2:-2], u[k0 - 1 - d:len(y) - 1 - d], np.ones(len(yk))])
        target = yk
    coef, *_ = np.linalg.lstsq(X, target, rcond=None)
    r = target - X @ coef
    return float(np.mean(r * r)), coef, len(target)


def plant_from_data(op, pv, dt: float = 1.0) -> tuple[str, str, dict]:
    """Self-regulating (``'first_order'``) or integrating process, and its dead time, fitted from the record.

    Two second-order ARX models of the PV from the controller output are fitted by least squares
    for every dead time of 0..:data:`MAX_DEAD_TIME` samples: one free (self-regulating: its poles
    inside the unit circle), one with a pole at 1 (integrating).  They are nested, so the Bayesian
    information criterion decides (the integrating model has one parameter less; it is chosen when
    the free model's extra parameter does not pay), as does the dead time (kept when it lowers the
    criterion by more than :data:`DEAD_TIME_MARGIN`).  Both ARX fits read the PV in its own units;
    the choice does not change when the PV or the output is scaled or offset.

    Parameters
    ----------
    op, pv : array_like, shape (n,)
        Controller output and process variable, any units.
    dt : float
        Sample time [s] (for the reason's words).

    Returns
    -------
    plant : {'first_order', 'integrating'}
    reason : str
    fit : dict
        ``bic`` per model, ``dead_time_samples``, ``pole`` (the free model's slowest pole).
    """
    u = np.asarray(op, dtype=np.float64)
    y = np.asarray(pv, dtype=np.float64)
    ys = float(np.std(y)) or 1.0
    us = float(np.std(u)) or 1.0
    y = (y - y.mean()) / ys
    u = (u - u.mean()) / us
    n = len(y)
    dmax = int(min(MAX_DEAD_TIME, max(0, n // 20)))
    best: dict[str, tuple[float, int, np.ndarray]] = {}
    for integ, key, npar in ((False, "first_order", 4), (True, "integrating", 3)):
        for d in range(dmax + 1):
            var, coef, m = _arx(y, u, d, integ)
            bic = m * math.log(max(var, 1e-300)) + npar * math.log(m)
            if key not in best or bic < best[key][0]:
                best[key] = (bic, d, coef)
    b_sr, b_int = best["first_order"][0], best["integrating"][0]
    plant = "integrating" if b_int <= b_sr else "first_order"
    d = best[plant][1]
    var0, _, m0 = _arx(y, u, 0, plant == "integrating")
    bic0 = m0 * math.log(max(var0, 1e-300)) + (3 if plant == "integrating" else 4) * math.log(m0)
    if bic0 - best[plant][0] < DEAD_TIME_MARGIN:
        d = 0
    coef = best["first_order"][2]
    roots = np.roots([1.0, -coef[0], -coef[1]])
    pole = float(np.max(np.abs(roots)))
    why = (f"a pole at 1 explains the record as well as a free one (BIC {b_int:.1f} against {b_sr:.1f}; "
           f"free model's slowest pole {pole:.4f}): the process integrates" if plant == "integrating" else
           f"the free model's poles lie inside the unit circle (slowest {pole:.4f}) and beat one at 1 (BIC {b_sr:.1f} "
           f"against {b_int:.1f}): the process settles")
    dead = (f"dead time about {d} sample(s) ({d * dt:g} s), found as the dead_time effect where it pays" if d else
            "no dead time beyond a sample")
    reason = (f"no loop tag in the name or the PV column: second-order ARX models of the PV from the output "
              f"(self-regulating and integrating, dead time 0..{dmax} samples) fitted and compared: {why}; {dead}: "
              f"'{plant}' (name another with plant=/--plant)")
    return plant, reason, {"bic": {"first_order": b_sr, "integrating": b_int}, "dead_time_samples": d,
                           "pole": pole}


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


def resolve_plant(plant: str, name: str, pv_column: str | None = None, op=None, pv=None,
                  dt: float = 1.0) -> tuple[str, dict]:
    """The process model ``plant`` stands for, and the choice (JSON-ready).

    ``name``: the recording's name; ``pv_column``: the name of its PV column, if known; ``op``,
    ``pv``, ``dt``: the record, read (:func:`plant_from_data`) when no tag says the model.
    """
    if plant != AUTO:
        return plant, {"asked": plant, "chosen": plant}
    if op is not None and pv is not None and _tag_choice(name, pv_column) is None:
        chosen, why, fit = plant_from_data(op, pv, dt)
        return chosen, {"asked": AUTO, "chosen": chosen, "reason": why, "source": "data", "fit": fit}
    chosen, why = plant_from_name(name, pv_column)
    return chosen, {"asked": AUTO, "chosen": chosen, "reason": why, "source": "tag"}
