"""The recording loader: sniff, map columns, parse, validate, repair, condition."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import replace
from datetime import datetime, timezone

import numpy as np

from ._base import MIN_SAMPLES, RecordingError
from .columns import ColumnMap, as_column_mapping
from .data import data_path  # noqa: F401  (used in the docstring's example)
from .decimate import DEFAULT_MAX_SAMPLES, condition
from .mode import automatic_stretch
from .parse import Parsed, parse_raw
from .read import CHUNK_ROWS, RawColumns, read_columns
from .record import Recording
from .repair import Grid, drop_duplicates, fill_gaps, regrid
from .sniff import Sniffed, sniff
from .units import infer_op_range
from .validate import LoadOptions, check_constant, check_options, check_time_order, mark_absurd, normalise

__all__ = ["load_recording"]

#: Least travel of the controller output over a record (fraction of the range that maps to 0..1) that
#: the loader accepts: an output that moves less is effectively constant, or its range is wrong.
MIN_OP_TRAVEL = 1e-4

#: Largest share of a given output range (``--op-range``, ``--mv-range``) that 0..1 may be when every value
#: lies in 0..1, before the loader refuses the range: the values are a fraction already (0..1 of 0..100 is
#: 1 %; of 0..50, 2 %).
FRACTION_SHARE = 0.02


def load_recording(
    path: str | os.PathLike,
    columns: Mapping[str, str | None] | str | None = None,
    op_range: tuple[float, float] | None = None,
    name: str | None = None,
    max_gap: int = 5,
    resample: bool | str = "auto",
    gaps: str = "longest",
    mv_range: tuple[float, float] | None = None,
    *,
    max_samples: int | None = DEFAULT_MAX_SAMPLES,
    engine: str = "auto",
    dt: float | None = None,
    dayfirst: bool | None = None,
    time_unit: str | None = None,
) -> Recording:
    """Read a control-loop recording from a CSV or Parquet file.

    The steps, each in its own module: :func:`~.sniff.sniff` (format),
    :func:`~.read.read_columns` with :func:`~.columns.resolve_columns`
    (column mapping), :func:`~.parse.parse_raw` (cells to numbers),
    :mod:`~.validate` (time order, absurd values, ranges), :mod:`~.repair`
    (duplicates, uniform grid, gaps) and :func:`~.decimate.condition`
    (long records).

    Parameters
    ----------
    path : str or path-like
        The file's path (not an open file).  CSV file with a header row;
        comma, semicolon or tab separated, UTF-8 (a byte-order mark is fine).  Blank cells and ``nan``, ``NA``,
        ``null`` count as missing values.  Or a Parquet file (recognised by
        its content, any extension): numeric, time-stamp or text columns;
        nulls are missing values; messages count rows instead of lines.
        Numbers that are not finite (``inf``, ``1e309``) or absurd (beyond
        +-1e15, or a spike of at most 3 samples a million times the column's
        typical size away from its median, or more than 20 times the span of
        the column's other values outside their range: a historian's bad-value
        code such as -9999 in a few rows, see :func:`~.validate.mark_absurd`)
        count as missing values too, each stated in `repairs`.
    columns : dict or str, optional
        Role to column name for the roles ``t`` (time), ``op`` (controller
        output), ``pv`` (process variable), ``sp`` (set point), ``mv`` (valve
        stem position), ``mode`` (loop mode), or the CLI's string form
        ``"op=OP,pv=PV,sp="`` (:func:`~.columns.parse_columns`).  One column
        serves one role only.  Names match exactly, else case-insensitively.  A
        role left out is looked up among :data:`DEFAULT_COLUMN_NAMES`
        (case-insensitive; ``t``, ``op``, ``pv`` are required, ``sp`` and
        ``mv`` optional); map a role to None to ignore it.
        The time column holds seconds (since the start, or epoch seconds,
        milliseconds or microseconds, or spreadsheet serial days: read from
        their magnitude and step, :func:`~.units.numeric_time_unit`), or date
        strings (ISO 8601 ``2024-11-21 00:01:00``, ``D/M/Y`` or ``M/D/Y`` with
        a 24- or 12-hour clock, ``18-Jul-2024 00:35``: :func:`~.units.parse_stamps`;
        converted to seconds since the first sample, naive stamps taken as
        UTC).  How they were read is stated in ``notes``.
    op_range : (float, float), optional
        Raw controller-output values ``(lo, hi)`` that map to 0..1, e.g.
        ``(0, 100)`` for percent.  Left out, it is read from the values
        (:func:`~.units.infer_op_range`: 0..1 a fraction, up to 100 percent,
        else the observed range: unknown span) and the choice is stated in
        ``notes``.  Values outside the range
        by up to 5 % of its span are clipped (recorded as a repair); further
        out is an error.  A range of which 0..1 is at most 2 % (e.g.
        ``(0, 100)``) while every op value lies in 0..1 is an error too: the
        output is a fraction already.  A string ``"LO,HI"`` is read as the
        CLI's ``--op-range``.
    name : str, optional
        Label of the record; default the file name without extension.
    max_gap : int, default 5
        Longest run of missing samples (per column, on the uniform grid)
        filled by linear interpolation.  Missing values at the start or end of
        the record are dropped instead (all columns), at any length.
    resample : {'auto', True, False}, default 'auto'
        What to do when the time stamps are not uniformly spaced.  Jitter
        below 10 % of the median step is always resampled onto a uniform grid
        with the median step (pv, sp, mv linearly interpolated; op by
        zero-order hold, as a controller output is held between updates).
        Larger irregularity is resampled the same way with 'auto'/True, and
        raises RecordingError with False.  A step longer than 1.5 median steps
        counts as missing samples (handled like missing values, see
        `max_gap`).
    gaps : {'longest', 'error'}, default 'longest'
        What to do with a run of missing samples longer than `max_gap`:
        'longest' keeps the longest stretch of the record free of such gaps
        (recorded as a repair); 'error' raises RecordingError naming its time
        span.
    mv_range : (float, float), optional
        Raw stem-position values that map to 0..1; default the same as the
        controller output's range (`op_range`, or (0, 1)).
    max_samples : int or None, default 12000
        A longer record is decimated to the sample time its dynamics need and,
        if still longer, windowed to its most informative `max_samples`
        samples (see :func:`~.decimate.condition`); both stated in
        `repairs`.  None keeps every sample.
    engine : {'auto', 'rows', 'columns'}, default 'auto'
        CSV reader: 'rows' parses every row with the csv module (exact line
        numbers; rows with a wrong number of fields are an error), 'columns'
        reads only the mapped columns in chunks with pandas (a row with too
        few fields reads as missing values); 'auto' uses 'columns' above
        8 MB.
    dt : float, optional
        Sample time [s] of a file without a time column (a laboratory or
        MATLAB export: the samples are ``dt`` apart, row after row); the time
        column is then not looked for (naming one as well is an error).
    dayfirst : bool or None
        Dates written ``D/M/Y`` (True) or ``M/D/Y`` (False); None (default)
        reads it from the data and asks for it only when both readings fit.
    time_unit : {None, 's', 'ms', 'us', 'days'}
        Unit of a numeric time column; None (default) reads it from the data.

    Returns
    -------
    Recording
        float64 arrays of shape (n,), finite, on a uniform grid of step
        ``dt`` seconds, 50 <= n <= `max_samples`; every repair listed in
        ``repairs``, how the file was read in ``notes``.

    Raises
    ------
    RecordingError
        Missing, unreadable or non-CSV file; a named column absent (the
        message lists the available ones); non-numeric cells (first line
        numbers given); missing time stamps; decreasing time stamps or
        duplicate time stamps with different values (exact duplicate rows
        are dropped as a repair); non-finite time stamps, or jumps of the
        time stamps that would leave the record mostly gaps; a gap longer than `max_gap` (with
        ``gaps='error'``); irregular sampling with ``resample=False``;
        op values outside [0, 1] without `op_range`, or far outside it
        (the first time named), or all in 0..1 with a percent-like range;
        a loop-mode column that leaves fewer than 50 rows in automatic;
        one column mapped to two roles; a `path` that is not a path;
        constant op or pv (nothing to identify); fewer than 50 samples.

    Examples
    --------
    >>> rec = load_recording(data_path("stictiongpt_plant_loops/csv/"
    ...                                "stiction__2411AIC90201_1002_0004.csv"),
    ...                      columns={"t": "t_s", "op": "OP", "pv": "PV", "sp": "SP"},
    ...                      op_range=(0, 100))
    >>> len(rec), rec.dt, rec.columns["op"]
    (751, 10.0, 'OP')
    """
    if not isinstance(path, (str, bytes, os.PathLike)):
        what = "an open file" if hasattr(path, "read") else f"a {type(path).__name__}"
        named = f" ({path.name!r})" if isinstance(getattr(path, "name", None), str) else ""
        raise RecordingError(
            f"load_recording: pass the file's path (a str or pathlib.Path), not {what}{named}; "
            f"load_recording opens and reads the file itself"
        )
    src = os.fsdecode(path)
    opts = check_options(src, max_gap, resample, gaps, op_range, mv_range, max_samples, engine)
    columns = _time_by_dt(as_column_mapping(columns, src), dt, src)
    sn = sniff(src, opts.engine)
    raw = read_columns(sn, columns)
    if dt is not None:
        raw = _with_sample_times(raw, float(dt))
    raw, said = _automatic_rows(raw, src)
    dc = _decimal_comma_file(sn, raw)
    p = parse_raw(raw, src, decimal_comma=dc, dayfirst=dayfirst, time_unit=time_unit)
    repairs: list[str] = said
    notes = _reader_notes(sn, raw)
    if p.time_note:
        notes.append(p.time_note)
    if dt is not None:
        notes.append(f"time: the row number x {float(dt):g} s (dt given; no time column read)")
    if dc:
        notes.append(f"numbers with a decimal comma read as decimal points (columns separated by "
                     f"{sn.dialect.delimiter!r})")
    check_time_order(p)
    p = drop_duplicates(p, repairs)
    op_valid = opts.op_range if opts.op_range is not None else (0.0, 1.0)
    p = mark_absurd(p, repairs, {"op": op_valid, "mv": opts.mv_range if opts.mv_range is not None else op_valid})
    p, grid = regrid(p, opts, repairs)
    grid = fill_gaps(grid, opts, p.columns.names, src, repairs, _time_formatter(p.start, p.epoch0))
    signals, op_range_used = _normalised(grid, p, opts, repairs, notes)
    t, signals, cond = condition(grid.t, signals, grid.dt, opts.max_samples)
    dt = grid.dt
    if cond is not None:
        repairs.extend(cond.statements(float(t[0])))
        notes.append(f"dominant time scale of the record: {cond.time_scale:.4g} s (autocorrelation of op "
                     f"and pv); {cond.n_out} samples of dt={cond.dt_out:g} s kept of {cond.n_in}")
        dt = cond.dt_out
    return Recording(
        t=t, op=signals["op"], pv=signals["pv"], sp=signals.get("sp"), mv=signals.get("mv"), dt=dt,
        name=name if name is not None else sn.path.stem, op_range=op_range_used,
        repairs=tuple(repairs), columns=dict(p.columns.names), start=p.start, notes=tuple(notes),
    )


def _automatic_rows(raw: RawColumns, src: str) -> tuple[RawColumns, list[str]]:
    """``raw`` without its loop-mode column, cut to the longest automatic stretch, and what was done.

    The mode is a state: a blank cell holds the mode above it (:func:`~.mode.automatic`).
    """
    if "mode" not in raw.columns.index:
        return raw, []
    name = raw.columns.names["mode"]
    data = dict(raw.data)
    mode = data.pop("mode")
    cmap = ColumnMap({r: j for r, j in raw.columns.index.items() if r != "mode"},
                     {r: c for r, c in raw.columns.names.items() if r != "mode"})
    try:
        a, b, said = automatic_stretch(
            mode, lambda a, b: f"{raw.unit}s {raw.lines[a]}-{raw.lines[b - 1]} of the file")
    except RecordingError as e:
        raise RecordingError(f"{src}: column {name!r}: {e}, or pass --columns mode= to read the record "
                             f"as it is") from None
    if b - a < MIN_SAMPLES <= len(mode):
        raise RecordingError(
            f"{src}: column {name!r} (mode): the loop mode leaves only {b - a} of the {len(mode)} data rows: "
            f"the longest automatic stretch is {raw.unit}s {raw.lines[a]}-{raw.lines[b - 1]}, and a recording "
            f"needs at least {MIN_SAMPLES} samples; export a longer stretch in automatic, or pass --columns "
            f"mode= (columns={{'mode': None}} in Python) to read the whole record, manual stretches included"
        )
    raw = replace(raw, data={r: v[a:b] for r, v in data.items()}, lines=raw.lines[a:b], columns=cmap)
    return raw, [f"column {name!r}: {s}" for s in said]


def _decimal_comma_file(sn: Sniffed, raw: RawColumns) -> bool:
    """Whether a CSV file writes its numbers with a decimal comma (``;``- or tab-separated, commas in cells)."""
    if sn.kind != "csv" or sn.dialect is None or sn.dialect.delimiter == ",":
        return False
    for a in raw.data.values():
        if a.dtype == object and any(isinstance(c, str) and "," in c for c in a[:200]):
            return True
    return False


def _reader_notes(sn: Sniffed, raw: RawColumns) -> list[str]:
    n = len(raw.lines)
    if sn.kind == "parquet":
        return [f"read {n} rows of the Parquet columns {', '.join(map(repr, raw.columns.names.values()))}"]
    if sn.engine == "columns":
        return [f"read {n} lines of the CSV columns {', '.join(map(repr, raw.columns.names.values()))} "
                f"column-wise (pandas C parser, chunks of {CHUNK_ROWS} rows)"]
    return []


def _time_formatter(start: str | None, epoch0: float | None):
    """A function formatting a time for messages: seconds, plus the date for date-stamped files."""

    def fmt_t(x: float) -> str:
        s = f"t={x:g} s"
        if start is not None and epoch0 is not None and math.isfinite(epoch0):
            try:
                s += " (" + datetime.fromtimestamp(epoch0 + x, timezone.utc).strftime("%Y-%m-%d %H:%M:%S") + ")"
            except (OverflowError, OSError, ValueError):
                pass
        return s

    return fmt_t


def _check_not_fraction(x: np.ndarray, rng: tuple[float, float], where: str, label: str, noun: str,
                        given: str, fix: str) -> None:
    """Refuse a range `rng` of which 0..1 is at most :data:`FRACTION_SHARE` when all values `x` lie in 0..1.

    An output logged as a fraction 0..1 but read with ``--op-range 0,100`` would move a hundredth of
    what it does, and a stiction size read from it would be as much too small.
    """
    lo, hi = rng
    share = 1.0 / (hi - lo)
    if lo <= 0.0 and hi >= 1.0 and share <= FRACTION_SHARE and float(x.min()) >= 0.0 and float(x.max()) <= 1.0:
        raise RecordingError(
            f"{where}: all {label} values lie in 0..1 ({float(x.min()):g}..{float(x.max()):g}), at most "
            f"{100 * share:.2g} % of {given}: the {noun} looks like a fraction already; {fix}"
        )


def _normalised(grid: Grid, p: Parsed, opts: LoadOptions, repairs: list[str],
                notes: list[str] | None = None) -> tuple[dict[str, np.ndarray], tuple[float, float]]:
    """Map op and mv to 0..1 (range read from the data when not given, errors, clipping); refuse a constant op or pv."""
    names = p.columns.names
    op_raw = grid.values["op"]
    op_range = opts.op_range
    if op_range is None:
        op_range, said = infer_op_range(op_raw)
        if notes is not None:
            notes.append(said)
    else:
        _check_not_fraction(op_raw, op_range, p.where("op"), "OP", "output",
                            f"--op-range {op_range[0]:g},{op_range[1]:g}",
                            "leave out --op-range (or give --op-range 0,1; op_range=None in Python)")
    out = dict(grid.values)
    out["op"] = normalise(op_raw, op_range, "op", p.where("op"), "--op-range", repairs, names["op"], grid.t)
    if "mv" in out:
        mvr = opts.mv_range if opts.mv_range is not None else op_range
        if mvr != (0.0, 1.0):
            given = (f"--mv-range {mvr[0]:g},{mvr[1]:g}" if opts.mv_range is not None else
                     f"--op-range {mvr[0]:g},{mvr[1]:g} (the stem position's range when --mv-range is left out)")
            _check_not_fraction(grid.values["mv"], mvr, p.where("mv"), "MV", "stem position", given,
                                "give --mv-range 0,1 (mv_range=(0, 1) in Python)")
        out["mv"] = normalise(grid.values["mv"], mvr, "mv", p.where("mv"), "--mv-range", repairs,
                              names["mv"], grid.t)
    for r in ("op", "pv"):
        check_constant(grid.values[r], r, p.where(r))
    moved = float(np.ptp(out["op"]))
    if moved < MIN_OP_TRAVEL:
        raise RecordingError(
            f"{p.where('op')}: the controller output moves over only {100 * moved:.2g} % of its range "
            f"{op_range[0]:g}..{op_range[1]:g}, too little to identify anything; check the range "
            f"(--op-range LO,HI: the output's full scale, e.g. 0,100 for percent)"
        )
    return out, op_range


def _time_by_dt(columns, dt, src: str):
    """The column mapping with the time column switched off where ``dt`` gives the sample time."""
    t_off = columns is not None and "t" in columns and not (columns["t"] and str(columns["t"]).strip())
    if dt is None:
        if t_off:
            raise RecordingError(f"{src}: the time column (t) is switched off; give the sample time instead: "
                                 f"dt=SECONDS (CLI: --dt SECONDS) for a file whose rows are equally spaced")
        return columns
    if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not math.isfinite(dt) or dt <= 0:
        raise RecordingError(f"{src}: dt must be the sample time in seconds, a finite number > 0, got {dt!r}")
    if columns is not None and columns.get("t") and str(columns["t"]).strip():
        raise RecordingError(f"{src}: both a time column (t={columns['t']}) and a sample time (dt={dt:g}) are "
                             f"given; give one: the time column, or dt for a file without one")
    return {**dict(columns or {}), "t": None}


def _with_sample_times(raw: RawColumns, dt: float) -> RawColumns:
    """``raw`` with the time of each row: ``k dt`` for row ``k`` (a file without a time column)."""
    n = len(raw.data["op"])
    cmap = ColumnMap(index={**raw.columns.index, "t": -1}, names={**raw.columns.names, "t": f"row x {dt:g} s"})
    return replace(raw, columns=cmap, data={**raw.data, "t": np.arange(n, dtype=np.float64) * dt})

