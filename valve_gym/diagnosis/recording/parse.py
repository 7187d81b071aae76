"""Cells to numbers: signal values and time stamps of a recording, as read.

:func:`parse_columns_raw` turns :class:`RawColumns` into :class:`Parsed`:
float64 signals (NaN where a value is missing or not finite), time in seconds
(numbers, ISO 8601 strings or Parquet time stamps) and the line numbers.
Cells that are neither numbers nor missing-value tokens are an error naming
the column, the lines and an example.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np

from ._base import MISSING_TOKENS, REQUIRED, ROLE_WORDS, RecordingError, fmt_lines
from .columns import ColumnMap
from .read import RawColumns
from .units import numeric_time_unit, parse_stamps

__all__ = ["Parsed", "parse_datetimes", "parse_numbers", "parse_raw"]


@dataclass(frozen=True)
class Parsed:
    """A recording's columns as numbers, before any check of the time axis.

    Attributes
    ----------
    src : str
        The file, for messages.
    columns : ColumnMap
    t : ndarray, shape (n,), float64
        Time in seconds (since the first stamp for date strings); NaN missing.
    values : dict of str to ndarray, shape (n,), float64
        Signal role to its values; NaN where missing or not finite.
    lines : ndarray, shape (n,), int64
        Line (CSV) or row (Parquet) number of each sample.
    unit : {'line', 'row'}
        What `lines` counts.
    t_text : ndarray of object, shape (n,), or None
        The time cells as written (text files with date strings or text
        cells), for messages.
    start : str or None
        First time stamp as written when the time column held dates.
    epoch0 : float or None
        POSIX seconds of `start`.
    nonfinite : dict of str to ndarray of int
        Signal role to the positions of cells that were numbers but not
        finite (``inf``, ``1e309``); they are missing in `values`.
    t_nonfinite : ndarray of int
        Positions of non-finite time stamps (NaN in `t`).
    time_note : str or None
        How the time stamps were read when that was inferred (day-first dates, epoch
        milliseconds, ...: :mod:`~.units`).
    """

    src: str
    columns: ColumnMap
    t: np.ndarray
    values: dict[str, np.ndarray]
    lines: np.ndarray
    unit: str
    t_text: np.ndarray | None
    start: str | None
    epoch0: float | None
    nonfinite: dict[str, np.ndarray]
    t_nonfinite: np.ndarray
    time_note: str | None = None

    def where(self, role: str) -> str:
        """``"FILE: column 'NAME' (role)"``, the start of a message about a column."""
        return f"{self.src}: column {self.columns.names[role]!r} ({role})"

    def at(self, idx) -> str:
        """``"line(s) 5, 9"`` for sample positions `idx`."""
        return f"{self.unit}(s) {fmt_lines(self.lines[np.asarray(idx, dtype=np.int64)].tolist())}"


def parse_numbers(cells: np.ndarray, decimal_comma: bool = False) -> tuple[np.ndarray, list[int], list[int]]:
    """Numbers of a column of cells.

    Parameters
    ----------
    cells : ndarray, shape (n,)
        float64, or object holding str or float.
    decimal_comma : bool
        Also read a cell with one comma and no point as a number with a decimal comma
        (``'0,53'``, European exports); only for files whose columns are not separated by commas.

    Returns
    -------
    values : ndarray, shape (n,), float64
        NaN for missing-value tokens, bad cells and non-finite numbers.
    bad : list of int
        Positions of cells that are neither numbers nor missing-value tokens.
    nonfinite : list of int
        Positions of numbers that are not finite (``inf``, ``1e309``).
    """
    if cells.dtype.kind == "f":
        v = np.array(cells, dtype=np.float64)
        inf = np.flatnonzero(np.isinf(v))
        v[inf] = np.nan
        return v, [], inf.tolist()
    out = np.empty(len(cells), dtype=np.float64)
    bad: list[int] = []
    nonfin: list[int] = []
    for i, c in enumerate(cells):
        if isinstance(c, float):
            v = c
        else:
            s = str(c).strip()
            if s.lower() in MISSING_TOKENS:
                out[i] = np.nan
                continue
            try:
                v = float(s)
            except ValueError:
                v = _decimal_comma(s) if decimal_comma else None
                if v is None:
                    bad.append(i)
                    out[i] = np.nan
                    continue
        if math.isinf(v):
            nonfin.append(i)
        out[i] = v if math.isfinite(v) else np.nan
    return out, bad, nonfin


def parse_datetimes(cells, idx) -> tuple[np.ndarray, list[int]]:
    """POSIX seconds (naive stamps taken as UTC) of ISO 8601 strings.

    Parameters
    ----------
    cells : sequence of str
        Time cells.
    idx : sequence of int
        Positions to parse (the others stay NaN).

    Returns
    -------
    seconds : ndarray, shape (n,), float64
    bad : list of int
        Positions that are not ISO date strings; ``-1`` appended when naive
        and time-zone-aware stamps are mixed.
    """
    out = np.full(len(cells), np.nan)
    bad: list[int] = []
    aware = set()
    for i in idx:
        s = str(cells[i]).strip()
        try:
            d = datetime.fromisoformat(s.replace("/", "-"))
        except ValueError:
            bad.append(i)
            continue
        aware.add(d.tzinfo is not None)
        if d.tzinfo is None:
            d = d.replace(tzinfo=timezone.utc)
        out[i] = d.timestamp()
    if len(aware) > 1:
        bad.append(-1)  # marker: mixed naive / aware
    return out, bad


def _decimal_comma(s: str) -> float | None:
    """``s`` read with a decimal comma (one comma, no point), or None."""
    if s.count(",") != 1 or "." in s:
        return None
    try:
        return float(s.replace(",", "."))
    except ValueError:
        return None


def _signal(raw: RawColumns, r: str, src: str, decimal_comma: bool = False) -> tuple[np.ndarray, list[int]]:
    where = f"{src}: column {raw.columns.names[r]!r} ({r})"
    cells = raw.data[r]
    v, bad, nonfin = parse_numbers(cells, decimal_comma)
    if bad:
        ex = str(cells[bad[0]]).strip()
        raise RecordingError(
            f"{where}: {len(bad)} non-numeric cell(s) at {raw.unit}(s) "
            f"{fmt_lines(raw.lines[bad].tolist())} (e.g. {ex!r}); fix or blank those cells "
            f"(blank cells count as missing values; use '.' as the decimal point: a decimal comma is read "
            f"only where the columns are separated by ';' or tabs)"
        )
    if np.isnan(v).all():
        what = (f"has no finite values ({len(nonfin)} non-finite, such as inf)" if nonfin
                else "has no numeric values at all")
        raise RecordingError(
            f"{where}: {what}; map the {ROLE_WORDS[r]} to another column"
            + (f" or switch it off with columns={{'{r}': None}} (CLI: --columns {r}=)" if r not in REQUIRED
               else "")
        )
    return v, nonfin


def _text_time(raw: RawColumns, src: str, decimal_comma: bool = False,
               dayfirst: bool | None = None) -> tuple[np.ndarray, str | None, list[int], str | None]:
    """Seconds from a text time column: numbers, or date strings throughout (:func:`~.units.parse_stamps`)."""
    where = f"{src}: column {raw.columns.names['t']!r} (t)"
    cells = raw.data["t"]
    t, bad, nonfin = parse_numbers(cells, decimal_comma)
    if not bad:
        return t, None, nonfin, None
    present = [i for i, c in enumerate(cells)
               if not (isinstance(c, float) and math.isnan(c)) and str(c).strip().lower() not in MISSING_TOKENS]
    if len(bad) != len(present):
        ex = str(cells[bad[0]]).strip()
        raise RecordingError(
            f"{where}: {len(bad)} non-numeric cell(s) at {raw.unit}(s) "
            f"{fmt_lines(raw.lines[bad].tolist())} (e.g. {ex!r}); the time column must hold "
            f"seconds or date strings throughout; fix those cells"
        )
    try:
        t, bad_dt, note = parse_stamps(cells, present, dayfirst)
    except RecordingError as e:
        raise RecordingError(f"{where}: {e}") from None
    if -1 in bad_dt:
        raise RecordingError(
            f"{where}: mixes time stamps with and without a time zone; write all of them the same way"
        )
    if bad_dt:
        ex = str(cells[bad_dt[0]]).strip()
        raise RecordingError(
            f"{where}: {len(bad_dt)} cell(s) are neither numbers (seconds) nor dates, at "
            f"{raw.unit}(s) {fmt_lines(raw.lines[bad_dt].tolist())} (e.g. {ex!r}); fix those cells "
            f"(e.g. 2024-11-21 00:01:00; D/M/Y, M/D/Y with or without AM/PM and 18-Jul-2024 are read too)"
        )
    return t, str(cells[present[0]]).strip(), [], note


def _numeric_time(t: np.ndarray, time_unit: str | None, src: str, name: str):
    """Seconds, first stamp, its POSIX seconds, a note: a numeric time column (:func:`~.units.numeric_time_unit`)."""
    try:
        f, epoch0, note = numeric_time_unit(t, time_unit)
    except RecordingError as e:
        raise RecordingError(f"{src}: column {name!r} (t): {e}") from None
    if epoch0 is None:
        return (t * f if f != 1.0 else t), None, None, note
    ok = np.flatnonzero(np.isfinite(t))
    rel = (t - t[ok[0]]) * f
    start = datetime.fromtimestamp(epoch0, timezone.utc).strftime("%Y-%m-%d %H:%M:%S")
    return rel, start, epoch0, note


def _time(raw: RawColumns, src: str, decimal_comma: bool = False, dayfirst: bool | None = None,
          time_unit: str | None = None) -> tuple[np.ndarray, str | None, float | None, list[int], str | None]:
    """Time in seconds, the first stamp as written (dates), its POSIX seconds, non-finite stamps, a note."""
    cells = raw.data["t"]
    name = raw.columns.names["t"]
    if cells.dtype.kind == "M":
        ns = cells.astype("datetime64[ns]")
        ok = np.flatnonzero(~np.isnat(ns))
        if ok.size == 0:
            return np.full(len(ns), np.nan), None, None, [], None
        sec = np.where(np.isnat(ns), np.nan, ns.astype(np.int64) / 1e9)
        epoch0 = float(sec[ok[0]])
        start = str(ns[ok[0]].astype("datetime64[s]")).replace("T", " ")
        return sec - epoch0, start, epoch0, [], None
    if cells.dtype.kind == "f":
        t, _, nonfin = parse_numbers(cells)
        t, start, epoch0, note = _numeric_time(t, time_unit, src, name)
        return t, start, epoch0, nonfin, note
    t, start, nonfin, note = _text_time(raw, src, decimal_comma, dayfirst)
    if start is None:
        t, start, epoch0, note = _numeric_time(t, time_unit, src, name)
        return t, start, epoch0, nonfin, note
    ok = np.flatnonzero(np.isfinite(t))
    epoch0 = float(t[ok[0]])
    return t - epoch0, start, epoch0, [], note


def parse_raw(raw: RawColumns, src: str, decimal_comma: bool = False, dayfirst: bool | None = None,
              time_unit: str | None = None) -> Parsed:
    """Numbers of every mapped column.

    Parameters
    ----------
    raw : RawColumns
        From one of the readers.
    src : str
        The file, for messages.
    decimal_comma : bool
        Read ``'0,53'`` as 0.53 (a file whose columns are separated by ``;`` or tabs).
    dayfirst : bool or None
        Dates ``D/M/Y`` (True), ``M/D/Y`` (False) or read from the data (None).
    time_unit : {None, 's', 'ms', 'us', 'days'}
        Unit of a numeric time column; None reads it from the data (:func:`~.units.numeric_time_unit`).

    Returns
    -------
    Parsed

    Raises
    ------
    RecordingError
        Non-numeric cells in a signal column, a signal column without any
        number, time cells that are neither seconds nor ISO dates throughout,
        mixed naive and time-zone-aware stamps.
    """
    sig = raw.columns.signal_roles
    values: dict[str, np.ndarray] = {}
    nonfinite: dict[str, np.ndarray] = {}
    for r in sig:
        v, nf = _signal(raw, r, src, decimal_comma)
        values[r] = v
        nonfinite[r] = np.asarray(nf, dtype=np.int64)
    t, start, epoch0, t_nf, time_note = _time(raw, src, decimal_comma, dayfirst, time_unit)
    lines = raw.lines
    t_text = raw.data["t"] if raw.data["t"].dtype == object else None
    if raw.drop_blank:
        keep = ~np.isnan(t)
        for v in values.values():
            keep |= ~np.isnan(v)
        for r, idx in nonfinite.items():
            keep[idx] = True
        keep[np.asarray(t_nf, dtype=np.int64)] = True
        if not keep.all():
            pos = np.cumsum(keep) - 1
            nonfinite = {r: pos[idx] for r, idx in nonfinite.items()}
            t_nf = pos[np.asarray(t_nf, dtype=np.int64)].tolist()
            t, lines = t[keep], lines[keep]
            values = {r: v[keep] for r, v in values.items()}
            t_text = None if t_text is None else t_text[keep]
    return Parsed(src, raw.columns, t, values, lines, raw.unit, t_text, start, epoch0, nonfinite,
                  np.asarray(t_nf, dtype=np.int64), time_note)
