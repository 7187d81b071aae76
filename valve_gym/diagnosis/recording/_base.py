"""Names, constants and the error type shared by the recording loader's parts."""

from __future__ import annotations

__all__ = [
    "DEFAULT_COLUMN_NAMES",
    "MIN_SAMPLES",
    "MISSING_TOKENS",
    "REQUIRED",
    "ROLES",
    "ROLE_WORDS",
    "RecordingError",
    "fmt_lines",
]

#: Shortest record (samples, after repairs) that :func:`load_recording` accepts.
MIN_SAMPLES = 50

#: Signal roles, in order: time, controller output, process variable,
#: set point, valve stem position, loop mode (automatic or manual; read to keep
#: the longest automatic stretch, :mod:`.mode`, not kept as a signal).
ROLES = ("t", "op", "pv", "sp", "mv", "mode")

#: Roles every recording must have.
REQUIRED = ("t", "op", "pv")

#: Role to the words used for it in messages.
ROLE_WORDS = {
    "t": "time",
    "op": "controller output",
    "pv": "process variable",
    "sp": "set point",
    "mv": "valve stem position",
    "mode": "loop mode",
}

#: Column names tried (case-insensitively, first match wins) for each role
#: when ``columns`` does not name one.  ``MV`` is deliberately *not* a default
#: for any role: in DCS exports it usually means the controller output, in the
#: stiction literature the valve position.
DEFAULT_COLUMN_NAMES: dict[str, tuple[str, ...]] = {
    "t": ("t", "t_s", "time", "time_s", "timestamp"),
    "op": ("op", "u", "u_v", "co", "out", "output", "controller_output"),
    "pv": ("pv", "y", "y_v", "level"),
    "sp": ("sp", "sv", "setpoint", "set_point"),
    "mv": ("stem", "valve_position", "pos"),
    "mode": ("mode", "loop_mode"),
}

#: Cells read as "missing" (case-insensitive, after stripping blanks).
MISSING_TOKENS = frozenset({"", "nan", "na", "n/a", "#n/a", "null", "none", "-"})


class RecordingError(ValueError):
    """A recording file, a column mapping or a range cannot be used.

    The message names the file (where there is one), the column, the problem
    and what to do about it.
    """


def fmt_lines(lines: list[int], limit: int = 5) -> str:
    """Up to `limit` line numbers, comma-separated, with the total if there are more.

    Parameters
    ----------
    lines : list of int
        Line (or row) numbers, 1-based.
    limit : int
        How many to show.

    Returns
    -------
    str
        E.g. ``"5, 9"`` or ``"1, 2, 3, 4, 5, ... (12 in all)"``.
    """
    s = ", ".join(str(x) for x in lines[:limit])
    if len(lines) > limit:
        s += f", ... ({len(lines)} in all)"
    return s
