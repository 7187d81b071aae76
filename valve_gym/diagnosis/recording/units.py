"""Units of a recording as a historian gives them: the output's scale and the time stamps.

Plant data come without flags: the controller output in percent, as a fraction 0..1, or in
engineering or deviation units; time stamps as day-first or month-first dates, with a 12- or
24-hour clock, or as epoch seconds or milliseconds.  This module reads each from the data
and says what it read (one sentence each, for the recording's notes):

* :func:`infer_op_range` -- the output's scale: every value in 0..1 is a fraction; values in
  -5..105 that reach above 1 are percent (a few negative values only where the output also reaches
  20 %: a deviation variable swings around 0); anything else (a deviation or an engineering unit)
  has an unknown span, and the output's own observed range is read as its span (sizes such as the
  stick band S are then fractions of the travel seen).
* :func:`parse_stamps` -- date strings: ISO 8601, ``D/M/Y`` or ``M/D/Y`` (``/``, ``-`` or ``.``
  between the fields, two- or four-digit years), month names (``18-Jul-2024``), an optional
  ``AM``/``PM``.  Day-first or month-first is read from the data: a first field above 12 means
  day-first, a second field above 12 month-first; when every date could be either, the reading
  whose sample interval is regular is taken; when both are, and the dates differ between them, a
  :class:`~._base.RecordingError` asks in one line for ``--dayfirst`` or ``--monthfirst``.
* :func:`numeric_time_unit` -- numbers in the time column: seconds since the start, epoch seconds,
  epoch milliseconds or microseconds (from their magnitude and sample interval), or spreadsheet
  serial days (Excel: 25569 is 1970-01-01).
"""

from __future__ import annotations

import re
from datetime import datetime, timedelta, timezone

import numpy as np

from ._base import RecordingError

__all__ = ["PERCENT_SLACK", "TIME_UNITS", "infer_op_range", "numeric_time_unit", "parse_stamps"]

#: How far beyond 0..100 (percentage points) a percent output may read (a controller's output limits of
#: -5..105 % are common); an output within 0..1 throughout is a fraction.
PERCENT_SLACK = 5.0

#: Time units a numeric time column can be given in (``time_unit=``, ``--time-unit``): factor to seconds.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "days": 86400.0}

_EXCEL_EPOCH_DAYS = 25569.0        # 1970-01-01 as a spreadsheet serial day (1900 date system)


def infer_op_range(op: np.ndarray) -> tuple[tuple[float, float], str]:
    """The raw range of the controller output that maps to 0..1, read from its values, and why.

    Parameters
    ----------
    op : ndarray, shape (n,)
        The output as recorded (finite values; NaN ignored).

    Returns
    -------
    (lo, hi) : tuple of float
        ``(0, 1)`` for a fraction, ``(0, 100)`` for percent, else the output's observed
        ``(min, max)`` (unknown span).
    note : str
        The choice in words.

    Examples
    --------
    >>> infer_op_range(np.array([48.5, 54.2]))[0]
    (0.0, 100.0)
    >>> infer_op_range(np.array([0.2, 0.7]))[0]
    (0.0, 1.0)
    >>> infer_op_range(np.array([-3.0, 2.5]))[0]
    (-3.0, 2.5)
    """
    x = np.asarray(op, dtype=np.float64)
    x = x[np.isfinite(x)]
    lo, hi = float(x.min()), float(x.max())
    if lo >= 0.0 and hi <= 1.0:
        return (0.0, 1.0), f"OP read as a fraction of the stroke (values {lo:.4g}..{hi:.4g} lie in 0..1)"
    if lo >= -PERCENT_SLACK and hi <= 100.0 + PERCENT_SLACK and (lo >= 0.0 or hi >= 20.0):
        return (0.0, 100.0), (f"OP read in percent (values {lo:.4g}..{hi:.4g} lie in 0..100 and reach above 1); "
                              f"--op-range LO,HI says otherwise")
    if hi - lo <= 0.0:
        return (lo - 0.5, lo + 0.5), f"OP constant at {lo:.4g}; its span is unknown"
    return (lo, hi), (f"OP span unknown (values {lo:.4g}..{hi:.4g}: deviation or engineering units, not percent "
                      f"or 0..1): its observed range is read as 0..1, so sizes such as the stick band are "
                      f"fractions of the travel seen, not of the stroke, and an output at a limit cannot be "
                      f"told; give --op-range LO,HI for sizes in stroke")


def numeric_time_unit(t: np.ndarray, unit: str | None = None) -> tuple[float, float | None, str | None]:
    """How to read a numeric time column: factor to seconds, epoch offset, and a note.

    Parameters
    ----------
    t : ndarray, shape (n,)
        The time column's numbers (NaN where missing).
    unit : {None, 's', 'ms', 'us', 'days'}
        Given by the user (``--time-unit``): no inference.  ``'days'`` are spreadsheet serial days.

    Returns
    -------
    factor : float
        Seconds per unit of `t`.
    epoch0 : float or None
        POSIX seconds of the first stamp when the numbers are dates (epoch or serial days), else None.
    note : str or None
        What was read, when it is not plain seconds since the start.
    """
    ok = t[np.isfinite(t)]
    if ok.size < 2:
        return 1.0, None, None
    t0 = float(ok[0])
    steps = np.diff(ok)
    steps = steps[steps > 0]
    step = float(np.median(steps)) if steps.size else 0.0
    if unit is None:
        unit = _guess_unit(t0, step, ok)
        guessed = True
    else:
        guessed = False
    if unit not in TIME_UNITS:
        raise RecordingError(f"time_unit must be one of {', '.join(TIME_UNITS)}, got {unit!r}")
    f = TIME_UNITS[unit]
    if unit == "days":
        epoch0 = (t0 - _EXCEL_EPOCH_DAYS) * 86400.0
    elif 1e8 <= t0 * f <= 1e10:
        epoch0 = t0 * f
    else:
        epoch0 = None
    if unit == "s" and epoch0 is None:
        return 1.0, None, None
    words = {"s": "epoch seconds", "ms": "epoch milliseconds", "us": "epoch microseconds",
             "days": "spreadsheet serial days (Excel, 1900 date system)"}[unit]
    if epoch0 is None:
        words = {"ms": "milliseconds", "us": "microseconds"}.get(unit, words)
    when = ""
    if epoch0 is not None:
        try:
            when = f", starting {datetime.fromtimestamp(epoch0, timezone.utc):%Y-%m-%d %H:%M:%S} UTC"
        except (OverflowError, OSError, ValueError):
            when = ""
    why = (f" (first value {t0:.10g}, median step {step:g}); --time-unit says otherwise" if guessed else
           " (--time-unit)")
    return f, epoch0, f"time column read as {words}{when}, sample interval {step * f:g} s{why}"


def _guess_unit(t0: float, step: float, t: np.ndarray) -> str:
    """The unit of a numeric time column from the first value's magnitude and the sample interval."""
    integral = bool(np.all(np.abs(t[:200] - np.round(t[:200])) < 1e-6))
    if 1e11 <= t0 <= 1e14 and step >= 1.0:
        return "ms"                                  # epoch ms (1973..5138); a step of at least 1 ms
    if 1e14 < t0 <= 1e17 and step >= 1.0:
        return "us"
    if 2e4 <= t0 <= 8e4 and 0.0 < step < 0.05 and not integral:
        return "days"                                # serial days 1954..2119, steps below 72 minutes
    return "s"


# --------------------------------------------------------------------------- date strings
_MONTHS = {m: i + 1 for i, m in enumerate(("jan", "feb", "mar", "apr", "may", "jun", "jul", "aug", "sep", "oct",
                                           "nov", "dec"))}
_NUMERIC = re.compile(
    r"^\s*(\d{1,4})[/.\-](\d{1,2})[/.\-](\d{2,4})(?:[ T,]+(\d{1,2}):(\d{2})(?::(\d{2})(?:[.,](\d+))?)?"
    r"\s*([AaPp]\.?[Mm]\.?)?)?\s*$")
_NAMED = re.compile(
    r"^\s*(\d{1,2})[ /.\-]([A-Za-z]{3})[A-Za-z]*[ /.\-](\d{2,4})(?:[ T,:]+(\d{1,2}):(\d{2})(?::(\d{2})"
    r"(?:[.,](\d+))?)?\s*([AaPp]\.?[Mm]\.?)?)?\s*$")


def _year(y: str) -> int:
    v = int(y)
    return v + 2000 if len(y) <= 2 and v < 70 else (v + 1900 if len(y) <= 2 else v)


def _clock(h, mi, s, frac, ampm) -> float:
    hh = int(h or 0)
    if ampm:
        pm = ampm[0] in "pP"
        if not 1 <= hh <= 12:
            raise ValueError
        hh = hh % 12 + (12 if pm else 0)
    sec = int(s or 0) + (float("0." + frac) if frac else 0.0)
    if hh > 23 or int(mi or 0) > 59 or sec >= 61:
        raise ValueError
    return hh * 3600.0 + int(mi or 0) * 60.0 + sec


def _posix(y: int, m: int, d: int, clock: float) -> float:
    return (datetime(y, m, d, tzinfo=timezone.utc) + timedelta(seconds=clock)).timestamp()


def _iso(s: str) -> tuple[float, bool] | None:
    """POSIX seconds of an ISO 8601 stamp (naive as UTC) and whether it had a zone; None if it is not one."""
    if len(s) < 8 or not s[:4].isdigit():
        return None
    try:
        d = datetime.fromisoformat(s.replace("/", "-"))
    except ValueError:
        return None
    aware = d.tzinfo is not None
    if not aware:
        d = d.replace(tzinfo=timezone.utc)
    return d.timestamp(), aware


def _regularity(sec: np.ndarray) -> float:
    """Share of the steps between consecutive stamps that equal the median step (within 10 %); 0 if any is < 0."""
    d = np.diff(sec[np.isfinite(sec)])
    if d.size == 0:
        return 1.0
    if np.any(d < 0):
        return 0.0
    med = float(np.median(d))
    if med <= 0:
        return 0.0
    share = float(np.mean(np.abs(d - med) <= 0.1 * med))
    # a jump of more than 1.5 steps (a day or a month skipped by the wrong reading) counts against it
    return share - (0.5 if float(np.max(d)) > 1.5 * med else 0.0)


def parse_stamps(cells, idx, dayfirst: bool | None = None) -> tuple[np.ndarray, list[int], str | None]:
    """POSIX seconds of the date strings ``cells[idx]`` (naive stamps as UTC), the bad ones, and a note.

    Parameters
    ----------
    cells : sequence of str
        The time cells.
    idx : sequence of int
        Positions to read (the others stay NaN).
    dayfirst : bool or None
        ``True``: ``D/M/Y``; ``False``: ``M/D/Y``; None: read from the data (module docstring).

    Returns
    -------
    seconds : ndarray, shape (n,), float64
    bad : list of int
        Positions that are no date of any format read here; ``-1`` appended when naive and
        time-zone-aware ISO stamps are mixed.
    note : str or None
        How the dates were read, when not ISO 8601.

    Raises
    ------
    RecordingError
        Day-first and month-first both fit and give different times (ask for ``--dayfirst``
        or ``--monthfirst``), or a field contradicts the order given.
    """
    out = np.full(len(cells), np.nan)
    bad: list[int] = []
    aware: set[bool] = set()
    pending: list[tuple[int, int, int, int, float]] = []      # i, a, b, year, clock
    named = 0
    ampm = False
    for i in idx:
        s = str(cells[i]).strip()
        v = _iso(s)
        if v is not None:
            out[i] = v[0]
            aware.add(v[1])
            continue
        m = _NAMED.match(s)
        try:
            if m is not None and m.group(2).lower() in _MONTHS:
                out[i] = _posix(_year(m.group(3)), _MONTHS[m.group(2).lower()], int(m.group(1)),
                                _clock(*m.group(4, 5, 6, 7, 8)))
                named += 1
                ampm |= bool(m.group(8))
                continue
            m = _NUMERIC.match(s)
            if m is None:
                bad.append(i)
                continue
            a, b, y = m.group(1), m.group(2), m.group(3)
            clock = _clock(*m.group(4, 5, 6, 7, 8))
            ampm |= bool(m.group(8))
            if len(a) == 4:                          # Y/M/D with a four-digit year first
                out[i] = _posix(int(a), int(b), int(y), clock)
                continue
            pending.append((i, int(a), int(b), _year(y), clock))
        except ValueError:
            bad.append(i)
    if len(aware) > 1:
        bad.append(-1)
    note = None
    if pending:
        note = _day_month(pending, out, bad, dayfirst, cells)
    elif named:
        note = "dates with month names read (e.g. 18-Jul-2024)"
    if ampm:
        note = (note + "; " if note else "") + "12-hour clock (AM/PM) read"
    return out, bad, note


def _day_month(pending, out: np.ndarray, bad: list[int], dayfirst: bool | None, cells) -> str:
    """Fill ``out`` for the ``A/B/Y`` stamps ``pending``: day-first or month-first, as given or read."""
    arr = np.array([(a, b) for _, a, b, _, _ in pending])
    a_big, b_big = bool((arr[:, 0] > 12).any()), bool((arr[:, 1] > 12).any())

    def read(df: bool) -> tuple[np.ndarray, list[int]]:
        sec = np.full(len(pending), np.nan)
        no: list[int] = []
        for k, (i, a, b, y, clock) in enumerate(pending):
            d, m = (a, b) if df else (b, a)
            try:
                sec[k] = _posix(y, m, d, clock)
            except ValueError:
                no.append(i)
        return sec, no

    ex = str(cells[pending[0][0]]).strip()
    if dayfirst is None:
        if a_big and b_big:
            raise RecordingError(f"time stamps such as {ex!r}: both the first and the second field of the dates "
                                 f"exceed 12 in some rows, so they are neither day-first nor month-first throughout; "
                                 f"write them one way (ISO 8601: 2024-07-18 00:35:00)")
        if a_big or b_big:
            dayfirst = a_big
            why = f"a {'first' if a_big else 'second'} field above 12"
        else:
            s_d, _ = read(True)
            s_m, _ = read(False)
            r_d, r_m = _regularity(s_d), _regularity(s_m)
            if np.array_equal(s_d, s_m, equal_nan=True):
                dayfirst, why = True, "day and month are the same in every date"
            elif np.allclose(s_d - s_d[0], s_m - s_m[0], equal_nan=True):
                dayfirst = True
                why = ("every field is up to 12, but the times between samples are the same either way (all on one "
                       "date), so only the date named in messages depends on it; --monthfirst reads M/D/Y")
            elif r_d > r_m + 0.05 or r_m > r_d + 0.05:
                dayfirst = r_d > r_m
                why = "only that reading gives a regular sample interval (no jump between the samples)"
            else:
                raise RecordingError(
                    f"time stamps such as {ex!r} read as well day-first as month-first (every field up to 12, "
                    f"both readings regular): say which with --dayfirst or --monthfirst (dayfirst=True/False)")
    else:
        why = "as given"
        if (dayfirst and b_big) or (not dayfirst and a_big):
            raise RecordingError(f"time stamps such as {ex!r}: the {'month' if dayfirst else 'day'} field exceeds "
                                 f"12 in some rows, which contradicts "
                                 f"{'--dayfirst' if dayfirst else '--monthfirst'}; give the other one or none")
    sec, no = read(dayfirst)
    for k, (i, *_rest) in enumerate(pending):
        out[i] = sec[k]
    bad.extend(no)
    order = "day-first (D/M/Y)" if dayfirst else "month-first (M/D/Y)"
    return f"dates read {order}: {why}"

