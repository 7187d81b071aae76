"""A historian's wide export: one time-stamp column and, per loop, ``TAG.PV``, ``TAG.OP`` (``TAG.SP``, ``TAG.MODE``).

Each tag is one loop.  The file is found and read by the same steps as a
single recording (:func:`~.sniff.sniff`, :func:`~.read.read_columns` with the
tag's columns, :func:`~.parse.parse_numbers`, :mod:`~.units`,
:func:`~.validate.check_increasing`, :func:`~.validate.normalise`,
:mod:`~.mode`); what differs is the grid: historians store each tag on its own
(irregular, exception-based) time stamps, so every tag's samples are put on a
uniform grid at the loop's scan by :func:`resample_loop` (PV linearly
interpolated; OP, SP and MODE held), and a stretch without a PV or OP sample
longer than ``max_gap`` scans is a :class:`Gap` (the longest stretch free of
gaps is kept).  A few cells of status text (``Bad Input``) are missing
samples, stated in the notes; time stamps that go back (a daylight-saving
fall-back in local time) are refused as for a single recording.

Examples
--------
>>> import numpy as np
>>> t = np.array([0.0, 1.0, 2.1, 2.9, 4.0, 5.0, 13.0, 14.0, 15.0])
>>> x = np.arange(9.0)
>>> grid, out, gaps, notes = resample_loop(t, {"pv": x, "op": x / 10}, max_gap=5)
>>> float(grid[1] - grid[0]), [g.role for g in gaps], round(gaps[0].seconds, 1)   # an 8 s hole in both
(1.0, ['pv', 'op'], 8.0)
>>> float(grid[0]), len(grid)       # the hole 5-13 s is cut; the longer stretch left, 0-5 s, is kept
(0.0, 6)
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import NamedTuple

import numpy as np

from ._base import MIN_SAMPLES, MISSING_TOKENS, RecordingError
from .columns import WIDE_SUFFIXES, duplicate_problem, wide_duplicates, wide_tags
from .mode import MANUAL_MODES, automatic, automatic_stretch, longest_run
from .parse import parse_numbers
from .read import read_columns, read_header
from .record import Recording
from .sniff import sniff
from .units import infer_op_range, numeric_time_unit, parse_stamps
from .validate import check_constant, check_increasing, normalise

__all__ = ["Gap", "WideTag", "WideLoop", "TIME_COLUMN_NAMES", "TEXT_FRACTION", "WIDE_SUFFIXES", "file_header",
           "wide_sources", "load_wide_tag", "resample_loop"]

#: Names recognised (case-insensitively) as the time-stamp column of a wide export.
TIME_COLUMN_NAMES = ("timestamp", "time", "t", "t_s", "datetime", "date", "ts")

#: A wide export's signal column (``TAG.PV``, ``TAG.OP``, ``TAG.SP``) whose cells that are neither numbers nor
#: blank (a historian's status text such as ``Bad Input``) are more than this fraction of its filled cells
#: is refused; fewer such cells are read as missing samples, bridged or cut by the gap rules.
TEXT_FRACTION = 0.5

_GAP_FACTOR = 1.5


class Gap(NamedTuple):
    """A stretch of a loop's record without samples.

    Attributes
    ----------
    role : str, the signal (``'pv'``, ``'op'``)
    t_start : float, seconds from the first sample of the loop (NaN for a one-recording CSV: the
        loader's note gives the times)
    seconds : float, length of the stretch without a sample [s] (NaN likewise)
    """

    role: str
    t_start: float
    seconds: float


@dataclass(frozen=True)
class WideTag:
    """One tag (loop) of a wide export, before its data are read.

    Attributes
    ----------
    path : str, the file
    tag : str, the tag
    time_column : str, the time-stamp column ('' when the file has none)
    columns : tuple of (role, column) pairs, the tag's columns (``pv``, ``op``, ``sp``, ``mode``)
    problem : str, why the tag cannot be read ('' when it can)
    """

    path: str
    tag: str
    time_column: str
    columns: tuple[tuple[str, str], ...]
    problem: str = ""


@dataclass(frozen=True)
class WideLoop:
    """A tag's recording and what reading it found.

    Attributes
    ----------
    recording : Recording, uniform grid, OP normalised to 0..1
    gaps : tuple of Gap, stretches without samples longer than ``max_gap`` scans
    notes : tuple of str, every resampling or repair done (also in ``recording.repairs``)
    """

    recording: Recording
    gaps: tuple[Gap, ...]
    notes: tuple[str, ...]


# --------------------------------------------------------------------------- the file's tags
def file_header(path: str) -> tuple[tuple[str, ...], str]:
    """Column names of a recording file and its form (``'csv'``, ``'parquet'``, ``'dcs-export'``).

    Raises
    ------
    RecordingError
        The file is missing, unreadable, empty, binary and not Parquet, or a Parquet file that cannot
        be read (or pyarrow is not installed: the message names the extra).
    """
    sn = sniff(path)
    return read_header(sn), sn.form


def _time_column(header: Sequence[str], tags: dict[str, dict[str, str]]) -> str:
    used = {c for roles in tags.values() for c in roles.values()}
    low = {c.lower(): c for c in header}
    for n in TIME_COLUMN_NAMES:
        if n in low and low[n] not in used:
            return low[n]
    rest = [c for c in header if c not in used]
    return rest[0] if rest else ""


def _duplicated(path: str, header: list[str], tcol: str) -> tuple[str, dict[str, str]]:
    """Columns of a wide export that cannot be told apart: ``(problem of the file, {tag: problem})``.

    A time column named twice makes the whole file unusable; a tag's role (``PV``, ``OP``, ``SP``,
    ``MODE``) given by two columns (the same name twice, or two spellings such as ``FIC1.PV`` and
    ``FIC1.pv``) makes that tag unusable: a reader would take one of them without a word.
    """
    def where(js: list[int]) -> str:
        return f"columns {', '.join(str(j + 1) for j in js)} of the header"

    if tcol and header.count(tcol) > 1:
        js = [j for j, h in enumerate(header) if h == tcol]
        return (f"{path}: the time-stamp column {tcol!r} appears {len(js)} times ({where(js)}); give each "
                f"column its own name (delete or rename the duplicates) and export again"), {}
    out: dict[str, str] = {}
    for (tag, role), js in wide_duplicates(header).items():
        if tag not in out:
            out[tag] = f"{path}: {duplicate_problem(header, tag, role, js)}; the tag is not read"
    return "", out


def wide_sources(path: str, header: Sequence[str]) -> list[WideTag]:
    """The tags of a wide export with header ``header``, sorted (empty: the file is not a wide export).

    A tag that cannot be read (no time-stamp column, no ``TAG.PV`` or ``TAG.OP``, a role given by two
    columns) comes with its ``problem``.
    """
    header = list(header)
    tags = wide_tags(header)
    if not tags:
        return []
    tcol = _time_column(header, tags)
    file_problem, tag_problems = _duplicated(path, header, tcol)
    out = []
    for tag, roles in sorted(tags.items()):
        problem = file_problem or tag_problems.get(tag, "")
        if not problem and not tcol:
            problem = f"{path}: no time-stamp column (name one of {', '.join(TIME_COLUMN_NAMES)})"
        elif not problem and ("pv" not in roles or "op" not in roles):
            miss = " and ".join(f"{tag}.{r.upper()}" for r in ("pv", "op") if r not in roles)
            problem = f"{path}: tag {tag!r} has no column {miss}; a loop needs TAG.PV and TAG.OP"
        out.append(WideTag(path, tag, tcol, tuple(sorted(roles.items())), problem))
    return out


# --------------------------------------------------------------------------- reading a tag
def _missing(x: np.ndarray) -> np.ndarray:
    if x.dtype.kind == "f":
        return ~np.isfinite(x)
    return np.array([v is None or str(v).strip().lower() in MISSING_TOKENS for v in x], bool)


def _read_tag_columns(src: WideTag, roles: dict[str, str]) -> tuple[dict[str, np.ndarray], dict[str, tuple]]:
    """The time column (as read) and the columns ``roles`` (role -> column) of a tag of a wide export.

    Read by the recording readers (:func:`~.read.read_columns`: only these columns). Returns the columns
    (signals as float, NaN where a cell is missing or not a number; the mode as read) and, per signal
    role with cells that are neither numbers nor blank, ``(positions, cells)``.
    """
    sn = sniff(src.path)
    mapping: dict[str, str | None] = {"t": src.time_column, "op": roles["op"], "pv": roles["pv"],
                                      "sp": roles.get("sp"), "mv": None, "mode": roles.get("mode")}
    try:
        raw = read_columns(sn, mapping)
    except RecordingError as e:
        raise RecordingError(f"tag {src.tag!r}: {e}") from None
    data = dict(raw.data)
    if raw.drop_blank:                 # the column-wise reader keeps blank lines: rows without any cell
        keep = ~np.logical_and.reduce([_missing(a) for a in data.values()])
        if not keep.all():
            data = {r: a[keep] for r, a in data.items()}
    out = {"t": data["t"]}
    text: dict[str, tuple] = {}
    comma = sn.kind == "csv" and sn.dialect is not None and sn.dialect.delimiter == ";"     # '0,53' is 0.53
    for role in roles:
        if role == "mode":
            out[role] = data["mode"]
            continue
        cells = data[role]
        out[role], bad, _ = parse_numbers(cells, decimal_comma=comma)
        if bad:
            text[role] = (np.asarray(bad), cells)
    return out, text


def _stamp(t_raw: np.ndarray, i: int) -> str:
    """Row ``i``'s time stamp as written (seconds, or the date to the second)."""
    v = t_raw[i]
    if t_raw.dtype.kind == "M":
        return str(v)[:19].replace("T", " ")
    return f"{v:g}" if isinstance(v, (float, np.floating)) else str(v).strip()


def _text_cells(src: WideTag, t_raw: np.ndarray, column: str, bad: np.ndarray, cells: np.ndarray, filled: int,
                notes: list[str]) -> None:
    """State the cells of ``column`` at positions ``bad`` that are not numbers (or dates), or refuse them.

    A signal's such cells are missing samples; a time column's are rows without a time stamp, not read.

    Raises
    ------
    RecordingError
        They are more than :data:`TEXT_FRACTION` of the column's ``filled`` cells.
    """
    if not bad.size:
        return
    i = int(bad[0])
    time = column == src.time_column
    first = f"first {str(cells[i]).strip()!r} at row {i + 1}" + ("" if time else
                                                                 f", {src.time_column} {_stamp(t_raw, i)}")
    what = "neither numbers nor dates" if time else "not numbers"
    if bad.size > TEXT_FRACTION * filled:
        held = "time stamps: export them as seconds or dates" if time else "values: export them as numbers"
        raise RecordingError(
            f"{src.path}: column {column!r} of tag {src.tag!r}: {bad.size} of its {filled} filled cells are {what} "
            f"({first}); the column holds text, not {held} (the values, not status texts)")
    done = "the rows without a time stamp are not read" if time else "read as missing samples"
    notes.append(f"column {column!r}: {bad.size} cell(s) that are {what} ({first}): {done} "
                 f"(rows count the data rows after the header)")


def _numeric_seconds(t: np.ndarray, src: WideTag, notes: list[str],
                     time_unit: str | None) -> tuple[np.ndarray, str | None]:
    """Numbers of a time column as seconds: since the start, or epoch (s, ms, us) or serial days, as read."""
    try:
        f, epoch0, note = numeric_time_unit(t, time_unit)
    except RecordingError as e:
        raise RecordingError(f"{src.path}: column {src.time_column!r}: {e}") from None
    if note:
        notes.append(note)
    if epoch0 is None:
        return t * f, None
    ok = np.flatnonzero(np.isfinite(t))
    start = datetime.fromtimestamp(epoch0, timezone.utc).strftime("%Y-%m-%d %H:%M:%S")
    return (t - t[ok[0]]) * f, start


def _seconds(t_raw: np.ndarray, src: WideTag, notes: list[str], dayfirst: bool | None = None,
             time_unit: str | None = None) -> tuple[np.ndarray, str | None]:
    """Time stamps as float seconds (and the first stamp as ISO text when they are dates).

    Numbers are seconds, epoch seconds, milliseconds or spreadsheet days, and text dates are ISO,
    day-first or month-first, as :mod:`~.units` reads them (the choice in ``notes``).  A few cells of a
    text column that are neither numbers nor dates are rows without a time stamp (:func:`_text_cells`).
    """
    if t_raw.dtype.kind in "fiu":
        return _numeric_seconds(np.asarray(t_raw, float), src, notes, time_unit)
    if t_raw.dtype.kind == "M":
        ns = t_raw.astype("datetime64[ns]")
    else:
        try:
            return _numeric_seconds(np.asarray(t_raw, dtype=float), src, notes, time_unit)
        except (TypeError, ValueError):
            pass
        cells = np.asarray(t_raw, dtype=object)
        head, bad, _ = parse_numbers(cells[:200])
        if np.isfinite(head).sum() > len(bad):               # seconds, with a few cells of text
            num, bad, nonfin = parse_numbers(cells)
            _text_cells(src, t_raw, src.time_column, np.asarray(bad, int), cells,
                        int(np.isfinite(num).sum()) + len(bad) + len(nonfin), notes)
            return _numeric_seconds(num, src, notes, time_unit)
        present = [i for i, c in enumerate(cells) if c is not None and str(c).strip().lower() not in MISSING_TOKENS]
        try:
            sec, bad_i, note = parse_stamps(cells, present, dayfirst)
        except RecordingError as e:
            raise RecordingError(f"{src.path}: column {src.time_column!r}: {e}") from None
        if -1 in bad_i:
            raise RecordingError(f"{src.path}: column {src.time_column!r}: mixes time stamps with and without a "
                                 f"time zone; write all of them the same way")
        _text_cells(src, t_raw, src.time_column, np.asarray(bad_i, int), cells, len(present), notes)
        if note:
            notes.append(note)
        ns = np.full(len(cells), np.datetime64("NaT"), dtype="datetime64[ns]")
        okp = np.isfinite(sec)
        ns[okp] = (np.round(sec[okp] * 1e9)).astype(np.int64).astype("datetime64[ns]")
    ok = ~np.isnat(ns)
    if not ok.any():
        raise RecordingError(f"{src.path}: tag {src.tag!r}: the time column holds neither numbers nor dates")
    t0 = ns[ok][0]
    sec = np.full(len(ns), np.nan)
    sec[ok] = (ns[ok] - t0) / np.timedelta64(1, "s")
    return sec, str(t0)[:19].replace("T", " ")


# --------------------------------------------------------------------------- the grid
def _role_on_grid(t: np.ndarray, x: np.ndarray, grid: np.ndarray, hold: bool) -> np.ndarray:
    if hold:
        j = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 1)
        return x[j]
    return np.interp(grid, t, x)


def _present(x: np.ndarray) -> np.ndarray:
    if x.dtype.kind == "f":
        return np.isfinite(x)
    return np.array([v is not None and str(v).strip() not in ("", "nan", "None") for v in x], bool)


def resample_loop(t: np.ndarray, signals: dict[str, np.ndarray], max_gap: int = 5,
                  scan: float | None = None):
    """Put one loop's signals, each on its own irregular time stamps, on a uniform grid.

    Parameters
    ----------
    t : (N,) float array, time stamps [s] of the export's rows (sorted or not)
    signals : dict role -> (N,) array, NaN (float) or None/'' (mode) where a tag has no
        sample in a row.  Roles ``'pv'`` and ``'op'`` are required; ``'sp'``, ``'mode'`` optional.
    max_gap : int, longest stretch without a sample that is bridged, in scans
    scan : float, optional, the grid step [s]; default the median step between the PV's samples

    Returns
    -------
    grid : (n,) float array [s], uniform with step ``scan``
    values : dict role -> (n,) array, PV linearly interpolated, OP, SP and MODE held
        (a controller output and a set point are held between updates)
    gaps : list of Gap, stretches longer than ``max_gap`` scans; the grid is cut to the
        longest stretch of the record free of them
    notes : list of str, what was done, in words

    Notes
    -----
    A grid point inside a gap is unknown; the longest run of known grid points is kept.
    """
    t = np.asarray(t, float)
    order = np.argsort(t, kind="stable")
    per = {}
    notes: list[str] = []
    for role, x in signals.items():
        x = np.asarray(x)[order]
        ts = t[order]
        ok = np.isfinite(ts) & (_present(x))
        ts, x = ts[ok], x[ok]
        keep = np.concatenate(([True], np.diff(ts) > 0)) if len(ts) else np.zeros(0, bool)
        if not keep.all():    # rows that repeat a time stamp: the first kept; say so where a value differs
            rep = np.flatnonzero(~keep)
            other = rep[x[rep] != x[rep - 1]]
            if other.size:
                notes.append(f"{role.upper()}: {other.size} row(s) repeat the time stamp of the row before with "
                             f"another value (first at {ts[other[0]] - ts[0]:g} s); the first value of each "
                             f"time stamp kept")
        per[role] = (ts[keep], x[keep])
    for role in ("pv", "op"):
        if len(per[role][0]) < 2:
            raise RecordingError(f"the {role.upper()} has fewer than 2 samples")
    tp = per["pv"][0]
    steps = np.diff(tp)
    dt = float(scan) if scan else float(np.median(steps))
    if not (math.isfinite(dt) and dt > 0):
        raise RecordingError("the PV's time stamps do not advance; check the time column")
    lo = max(v[0][0] for r, v in per.items() if r in ("pv", "op"))
    hi = min(v[0][-1] for r, v in per.items() if r in ("pv", "op"))
    if hi <= lo:
        raise RecordingError("the PV and OP samples do not overlap in time")
    grid = lo + dt * np.arange(int(np.floor((hi - lo) / dt + 1e-9)) + 1)
    known = np.ones(len(grid), bool)
    gaps: list[Gap] = []
    irregular = float(np.max(np.abs(steps - dt))) > 1e-6 * dt
    values = {}
    for role, (ts, x) in per.items():
        if len(ts) == 0:
            continue
        values[role] = _role_on_grid(ts, x, grid, hold=role != "pv")
        if role not in ("pv", "op"):
            continue        # set point and mode are stored on change: a long step is no gap
        d = np.diff(ts)
        for i in np.flatnonzero(d > max(max_gap, _GAP_FACTOR) * dt):
            gaps.append(Gap(role, float(ts[i] - lo), float(d[i])))
            known &= ~((grid > ts[i]) & (grid < ts[i + 1]))
    if irregular:
        notes.append(f"time stamps irregular (steps {steps.min():g}..{steps.max():g} s): resampled to the "
                     f"scan {dt:g} s (PV linear; OP, SP, MODE held)")
    if gaps:
        if not known.any():
            raise RecordingError("no stretch of the record is free of gaps")
        a, b = longest_run(known)
        notes.append(f"{len(gaps)} gap(s) longer than {max_gap} scans (longest {max(g.seconds for g in gaps):g} s); "
                     f"kept the longest stretch without one: {grid[a] - lo:g}-{grid[b - 1] - lo:g} s")
        grid = grid[a:b]
        values = {r: v[a:b] for r, v in values.items()}
    return grid, values, gaps, notes


def _automatic_stretch(values: dict[str, np.ndarray], grid: np.ndarray, notes: list[str], where: str,
                       column: str):
    """The grid and values cut to the longest stretch in automatic (the ``mode`` role, if any, removed).

    Raises
    ------
    RecordingError
        The loop is in manual throughout, or its longest automatic stretch is shorter than
        :data:`MIN_SAMPLES` samples of a grid that has them (the mode's changes counted).
    """
    mode = values.pop("mode", None)
    if mode is None:
        return grid, values
    off = "pass --columns mode= (columns={'mode': None} in Python) to read the whole record, manual included"

    def span(a: int, b: int) -> str:
        return f"{grid[a] - grid[0]:g}-{grid[b - 1] - grid[0]:g} s"

    try:
        a, b, said = automatic_stretch(mode, span)
    except RecordingError as e:
        raise RecordingError(f"{where}: column {column!r}: {e}, or {off}") from None
    if b - a < MIN_SAMPLES <= len(grid):
        changes = int(np.count_nonzero(np.diff(automatic(mode))))
        raise RecordingError(
            f"{where}: column {column!r} (mode): the mode changes between automatic and manual {changes} times in "
            f"{len(grid)} samples, and the longest automatic stretch is {b - a} sample(s) ({span(a, b)}), fewer than "
            f"the {MIN_SAMPLES} a diagnosis needs; check the mode column and its coding (manual: "
            f"{', '.join(sorted(MANUAL_MODES))}), export a longer stretch in automatic, or {off}")
    notes.extend(said)
    return grid[a:b], {r: v[a:b] for r, v in values.items()}


def _ordered(t: np.ndarray, t_raw: np.ndarray, src: WideTag, dated: bool) -> None:
    """Refuse time stamps that decrease in the order of the rows (a daylight-saving fall-back named)."""
    ok = np.flatnonzero(np.isfinite(t))
    check_increasing(t[ok], f"{src.path}: column {src.time_column!r} (t)", lambda i: f"row {ok[i] + 1}",
                     lambda i: _stamp(t_raw, int(ok[i])), dated)


def load_wide_tag(src: WideTag, name: str | None = None, op_range: tuple[float, float] | None = None,
                  max_gap: int = 5, off: tuple[str, ...] = (), dayfirst: bool | None = None,
                  time_unit: str | None = None, gaps: str = "longest") -> WideLoop:
    """Read one tag of a wide export onto a uniform grid at its own scan.

    Parameters
    ----------
    src : WideTag, from :func:`wide_sources`
    name : str, optional, the recording's name (default the tag)
    op_range : (lo, hi), optional, raw controller-output range that maps to 0..1 (default: read from the
        values, :func:`~.units.infer_op_range`, the choice in the notes)
    max_gap : int, longest stretch without a PV or OP sample bridged, in scans
    off : tuple of str, optional roles (``'sp'``, ``'mode'``) not read
    dayfirst : bool or None, dates ``D/M/Y`` (True) or ``M/D/Y`` (False); None reads it from the data
    time_unit : str or None, unit of a numeric time column; None reads it from the data
    gaps : {'longest', 'error'}, a gap longer than ``max_gap`` scans: keep the longest stretch without
        one (stated in the notes), or raise RecordingError naming it

    Returns
    -------
    WideLoop

    Raises
    ------
    RecordingError
        The tag or its data cannot be used; the message names the file, the tag or column, and what
        to do.
    """
    if src.problem:
        raise RecordingError(src.problem)
    where = f"{src.path}: tag {src.tag!r}"
    roles = {r: c for r, c in src.columns if r not in off}
    cols, text = _read_tag_columns(src, roles)
    t_raw = cols.pop("t")
    notes: list[str] = []
    t, start = _seconds(t_raw, src, notes, dayfirst, time_unit)
    _ordered(t, t_raw, src, start is not None)
    for role, (bad, cells) in text.items():
        filled = int(np.isfinite(cols[role]).sum()) + bad.size
        _text_cells(src, t_raw, roles[role], bad, cells, filled, notes)
    try:
        grid, values, found, said = resample_loop(t, cols, max_gap=max_gap)
    except RecordingError as e:
        raise RecordingError(f"{where}: {e}") from None
    if found and gaps == "error":
        g = max(found, key=lambda g: g.seconds)
        raise RecordingError(f"{where}: {len(found)} gap(s) longer than {max_gap} scans (the longest "
                             f"{g.seconds:g} s without a {g.role.upper()} sample, at {g.t_start:g} s); export the "
                             f"stretch without them, raise --max-gap, or leave out --gaps error to keep the longest "
                             f"stretch without one")
    notes.extend(said)
    grid, values = _automatic_stretch(values, grid, notes, where, roles.get("mode", ""))
    if len(grid) < MIN_SAMPLES:
        raise RecordingError(f"{where}: only {len(grid)} usable samples after resampling (need {MIN_SAMPLES}); "
                             f"export a longer stretch")
    for role in ("op", "pv"):
        check_constant(values[role], role, f"{where}: column {roles[role]!r}")
    rng = op_range
    if rng is None:                 # read from the values: fraction, percent or unknown span (never a failure)
        rng, said_range = infer_op_range(values["op"])
        notes.append(said_range)
    rng = (float(rng[0]), float(rng[1]))
    op = normalise(values["op"], rng, "op", f"{where}: column {roles['op']!r}", "--op-range", notes, roles["op"],
                   grid - grid[0])
    cols_used = {"t": src.time_column, **roles}
    cols_used.pop("mode", None)
    rec = Recording(t=grid - grid[0], op=op, pv=values["pv"], sp=values.get("sp"), dt=float(grid[1] - grid[0]),
                    name=name if name is not None else src.tag, op_range=rng, repairs=tuple(notes),
                    columns=cols_used, start=start)
    return WideLoop(rec, tuple(found), tuple(notes))
