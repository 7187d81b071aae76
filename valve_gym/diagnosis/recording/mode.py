"""The loop's mode (automatic or manual) and the longest automatic stretch of a record.

A historian logs a loop's mode as a state tag (``FIC101.MODE``: ``AUTO``, ``MAN``, ``CAS``, ...),
usually only when it changes.  The diagnosis reads a closed loop: in manual the controller output
is the operator's, and the stiction tests that read the controller's reaction (Horch's
cross-correlation, the PV-OP shape) would read the operator instead.  Both a single recording
(:func:`~valve_gym.diagnosis.recording.load_recording`) and fleet mode keep the longest stretch in
automatic and say so in the recording's repairs.

A value is read as manual only when it is one of :data:`MANUAL_MODES`; automatic ones are
:data:`AUTO_MODES`; any other value (a code this table does not know) is kept as automatic and
named by :func:`unknown_modes`, so that no data is dropped on a guess.

>>> import numpy as np
>>> automatic(np.array(["AUTO", "", "MAN", "", "CAS"], dtype=object)).tolist()
[True, True, False, False, True]
>>> unknown_modes(np.array(["1", "0", "2", "2"], dtype=object))
['2']
>>> longest_run(np.array([True, False, True, True, False]))
(2, 4)
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ._base import RecordingError

__all__ = ["AUTO_MODES", "MANUAL_MODES", "automatic", "automatic_stretch", "longest_run", "unknown_modes"]

#: MODE values (upper-cased) that mean the loop is in automatic (closed loop: AUTO, cascade).
AUTO_MODES = frozenset({"AUTO", "AUT", "A", "CAS", "CASCADE", "RCAS", "1", "1.0", "TRUE"})

#: MODE values (upper-cased) that mean the loop is in manual or out of service.
MANUAL_MODES = frozenset({"MAN", "MANUAL", "M", "LO", "IMAN", "OOS", "0", "0.0", "FALSE"})

_MISSING = frozenset({"", "NAN", "NONE", "NA", "N/A", "NULL"})


def automatic(mode: np.ndarray) -> np.ndarray:
    """Per sample, whether the loop is in automatic: not in :data:`MANUAL_MODES`.

    A missing cell holds the mode logged before it (a state tag is stored on change); missing
    cells before the first logged mode take that first mode.  A column without any mode logged is
    read as automatic throughout.
    """
    text = [str(v).strip().upper() for v in mode]
    known = np.array([s not in _MISSING for s in text], bool)
    auto = np.array([s not in MANUAL_MODES for s in text], bool)
    if not known.any():
        return np.ones(len(text), bool)
    last = np.maximum.accumulate(np.where(known, np.arange(len(text)), -1))
    last[last < 0] = int(np.flatnonzero(known)[0])
    return auto[last]


def longest_run(mask: np.ndarray) -> tuple[int, int]:
    """``(start, stop)`` of the longest run of True in ``mask`` (the first of equal ones); ``mask`` has a True."""
    d = np.diff(np.concatenate(([0], np.asarray(mask, bool).astype(np.int8), [0])))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    i = int(np.argmax(stops - starts))
    return int(starts[i]), int(stops[i])


def unknown_modes(mode: np.ndarray) -> list[str]:
    """The logged MODE values, sorted, that are neither automatic nor manual (read as automatic)."""
    text = {str(v).strip().upper() for v in mode}
    return sorted(text - AUTO_MODES - MANUAL_MODES - _MISSING)


def automatic_stretch(mode: np.ndarray, span: Callable[[int, int], str]) -> tuple[int, int, list[str]]:
    """``(start, stop, statements)``: the longest stretch in automatic of the samples with ``mode``.

    ``span(start, stop)`` words the stretch kept for the statement (times or file lines).

    Raises
    ------
    RecordingError
        The loop is in manual throughout.
    """
    auto = automatic(mode)
    said: list[str] = []
    unknown = unknown_modes(mode)
    if unknown:
        said.append(f"MODE value(s) {', '.join(unknown[:5])} not among the manual modes "
                    f"({', '.join(sorted(MANUAL_MODES))}): read as automatic")
    if auto.all():
        return 0, len(auto), said
    if not auto.any():
        raise RecordingError("the loop is in manual throughout (MODE never automatic): nothing closed-loop to "
                             "diagnose; export a stretch in automatic")
    a, b = longest_run(auto)
    said.append(f"MODE manual in {int((~auto).sum())} of {len(auto)} samples: kept the longest automatic "
                f"stretch, {span(a, b)}")
    return a, b, said
