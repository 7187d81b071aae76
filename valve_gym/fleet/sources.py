"""Where a fleet's loops come from: one CSV per loop, or a historian's wide export split by tag.

A *loop source* (:class:`LoopSource`) is a small, picklable description of
one loop: the file, the tag and the columns.  :func:`discover_loops` lists the
loops of a file or a folder without loading their data; :func:`load_loop`
reads one loop (in a worker) and returns a :class:`LoadedLoop` with a
:class:`~valve_gym.diagnosis.recording.Recording` on a uniform grid and the
gaps found on the way.

Two layouts are read:

* **one recording per file** (``*.csv``): read by
  :func:`~valve_gym.diagnosis.recording.load_recording` (same columns and
  ranges as ``valve-gym diagnose FILE``; a gap longer than five samples keeps
  the longest stretch without one, reported);
* **a historian's wide export** (``*.csv`` or ``*.parquet``): one time-stamp
  column and, per loop, columns ``TAG.PV``, ``TAG.OP``, optionally ``TAG.SP``
  and ``TAG.MODE``.  Each tag becomes a loop.  Historians store each tag on its
  own (irregular, exception-based) time stamps; every tag's samples are
  resampled onto a uniform grid at the loop's scan (:func:`resample_loop`).
  A tag whose role is given by two columns cannot be read; a few cells of
  status text (``Bad Input``) are missing samples, stated in the notes; time
  stamps that go back (a daylight-saving fall-back in local time) are refused
  as by the single-file loader.

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

import csv
import hashlib
import math
import os
import re
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import NamedTuple

import numpy as np

from ..diagnosis.recording import MIN_SAMPLES, Recording, RecordingError, load_recording
from ..diagnosis.recording._base import MISSING_TOKENS
from ..diagnosis.recording.columns import WIDE_SUFFIXES, duplicate_problem, wide_duplicates, wide_tags
from ..diagnosis.recording.mode import MANUAL_MODES, automatic, automatic_stretch, longest_run
from ..diagnosis.recording.parse import parse_numbers
from ..diagnosis.recording.read import arrow_to_numpy
from ..diagnosis.recording.sniff import recording_files
from ..diagnosis.recording.units import infer_op_range, numeric_time_unit, parse_stamps
from ..diagnosis.recording.validate import check_increasing
from .result import TABLE_COLUMNS

__all__ = ["LoopSource", "LoadedLoop", "Gap", "discover_loops", "load_loop", "resample_loop",
           "file_fingerprint", "safe_name", "fleet_outputs", "is_fleet_output", "FLEET_OUTPUT_FILES",
           "WIDE_SUFFIXES", "TIME_COLUMN_NAMES", "TEXT_FRACTION"]

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
class LoopSource:
    """One loop of a fleet, before its data are read.

    Attributes
    ----------
    name : str, unique loop name (the tag, or the file name without extension)
    kind : {'csv', 'wide', 'bad'}, one recording per file, a tag of a wide export,
        or a file that cannot be used (``problem`` says why)
    path : str, the file
    tag : str, the tag of a wide export ('' otherwise)
    time_column : str, the time-stamp column of a wide export
    columns : tuple of (role, column) pairs of a wide export
    fingerprint : str, SHA-256 of the file's bytes (hex)
    problem : str, why a ``'bad'`` source cannot be read
    """

    name: str
    kind: str
    path: str
    tag: str = ""
    time_column: str = ""
    columns: tuple[tuple[str, str], ...] = ()
    fingerprint: str = ""
    problem: str = ""


@dataclass(frozen=True)
class LoadedLoop:
    """A loop's recording and what loading it found.

    Attributes
    ----------
    recording : Recording, uniform grid, OP normalised to 0..1
    gaps : tuple of Gap, stretches without samples longer than ``max_gap`` scans
    notes : tuple of str, every resampling or repair done (also in ``recording.repairs``)
    """

    recording: Recording
    gaps: tuple[Gap, ...]
    notes: tuple[str, ...]


def safe_name(name: str) -> str:
    """``name`` made safe as a file name: anything but letters, digits, ``._-`` becomes ``_``."""
    s = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "loop"
    return s[:150]


def file_fingerprint(path: str, chunk: int = 1 << 20) -> str:
    """SHA-256 (hex) of a file's bytes, read in chunks of ``chunk`` bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while True:
            b = f.read(chunk)
            if not b:
                break
            h.update(b)
    return h.hexdigest()


# --------------------------------------------------------------------------- discovery
def _header(path: str) -> list[str]:
    """Column names of a CSV or Parquet file (raises RecordingError if unreadable)."""
    if path.lower().endswith(".parquet"):
        import pyarrow.parquet as pq
        try:
            return list(pq.read_schema(path).names)
        except Exception as e:  # pyarrow raises several types for a bad file
            raise RecordingError(f"{path}: not a readable Parquet file ({e}); export it again") from None
    with open(path, newline="", encoding="utf-8-sig", errors="replace") as f:
        head = f.read(65536)
    line = next((ln for ln in head.splitlines() if ln.strip()), "")
    if not line:
        raise RecordingError(f"{path}: file is empty; expected a header row and data rows")
    try:
        dialect = csv.Sniffer().sniff(line, delimiters=",;\t")
        delim = dialect.delimiter
    except csv.Error:
        delim = ","
    return [c.strip() for c in next(csv.reader([line], delimiter=delim))]


def _time_column(header: list[str], tags: dict[str, dict[str, str]]) -> str:
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


def _file_sources(path: str, fp: str) -> list[LoopSource]:
    stem = os.path.splitext(os.path.basename(path))[0]
    try:
        header = _header(path)
    except (RecordingError, OSError) as e:
        return [LoopSource(stem, "bad", path, fingerprint=fp, problem=str(e))]
    tags = wide_tags(header)
    if not tags:
        if path.lower().endswith(".parquet"):
            return [LoopSource(stem, "bad", path, fingerprint=fp,
                               problem=f"{path}: a Parquet file must be a wide export with columns TAG.PV, "
                                       f"TAG.OP (found {', '.join(header[:6])}); write single loops as CSV")]
        return [LoopSource(stem, "csv", path, fingerprint=fp)]
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
        out.append(LoopSource(tag, "bad" if problem else "wide", path, tag=tag, time_column=tcol,
                              columns=tuple(sorted(roles.items())), fingerprint=fp, problem=problem))
    return out


#: The files a fleet run writes next to its ``loops/`` folder (:func:`~valve_gym.fleet.table.write_table`,
#: :func:`~valve_gym.fleet.worklist.write_worklist`).
FLEET_OUTPUT_FILES = ("loops.csv", "loops.parquet", "worklist.md", "worklist.html")


def is_fleet_output(path: str) -> bool:
    """True when ``path`` is recognisably an output of a fleet run, not a recording.

    A file named as one of :data:`FLEET_OUTPUT_FILES` that lies next to a ``loops/`` folder (of
    per-loop results), or a ``loops.csv``/``loops.parquet`` whose header is the fleet table's
    (``loop, status, message, ...``).  A recording that happens to be called ``loops.csv`` has
    neither, and is read as a recording.
    """
    name = os.path.basename(path).lower()
    if name not in FLEET_OUTPUT_FILES:
        return False
    if os.path.isdir(os.path.join(os.path.dirname(path), "loops")):
        return True
    if name.startswith("worklist."):
        return False
    try:
        header = _header(path)
    except (RecordingError, OSError):
        return False
    return tuple(header[:3]) == TABLE_COLUMNS[:3]


def fleet_outputs(folder: str) -> list[str]:
    """The files of ``folder`` that :func:`discover_loops` skips as outputs of a fleet run (sorted)."""
    if not os.path.isdir(folder):
        return []
    return [f for f in recording_files(folder, extra=(".parquet",)) if is_fleet_output(f)]


def _no_recordings(folder: str) -> str:
    """Why ``folder`` holds no loops, naming its subfolders (not read) when it has any."""
    msg = f"folder {folder!r} holds no .csv or .parquet files (nor .txt DCS exports)"
    try:
        subs = sorted(e.name for e in os.scandir(folder) if e.is_dir() and not e.name.startswith("."))
        with_recs = next((d for d in subs[:20] if recording_files(os.path.join(folder, d), extra=(".parquet",))),
                         "")
    except OSError:
        subs, with_recs = [], ""
    if not subs:
        return msg
    named = ", ".join(subs[:5]) + (f", ... ({len(subs)} in all)" if len(subs) > 5 else "")
    eg = os.path.join(folder, with_recs or subs[0])
    return (f"{msg} directly in it; it holds {len(subs)} subfolder(s) ({named}), and fleet mode reads only the "
            f"files directly in the folder given, not its subfolders: give one subfolder (e.g. {eg!r}"
            f"{', which holds recordings' if with_recs else ''}) and run once per subfolder, or put the recordings "
            f"in one folder")


def discover_loops(path: str) -> list[LoopSource]:
    """The loops of a file or a folder (``*.csv``, ``*.parquet``, ``*.txt`` DCS exports, sorted; not recursive).

    Parameters
    ----------
    path : str, a folder, a wide export, or one recording

    Returns
    -------
    list of LoopSource, names unique and file-safe (a name seen twice gets ``@file`` appended).
    A file that cannot be read becomes a source of kind ``'bad'`` (a failed row later), never an
    exception, so one bad file does not stop a fleet.  The outputs of an earlier fleet run
    written into the folder (``loops.csv``, ``loops.parquet`` next to ``loops/``:
    :func:`is_fleet_output`) are not loops and are skipped (:func:`fleet_outputs` lists them).

    Raises
    ------
    RecordingError
        ``path`` does not exist, a folder holds no ``.csv``/``.parquet`` file (or only a fleet
        run's outputs; subfolders are named, not read), or ``path`` is itself a fleet run's table.
    """
    if os.path.isdir(path):
        found = recording_files(path, extra=(".parquet",))
        files = [f for f in found if not is_fleet_output(f)]
        if not files:
            if found:
                names = ", ".join(os.path.basename(f) for f in found)
                raise RecordingError(f"folder {path!r} holds only the outputs of a fleet run ({names}), no "
                                     f"recordings; give the folder of the recordings, and a separate --out folder")
            raise RecordingError(_no_recordings(path))
    elif os.path.isfile(path):
        if is_fleet_output(path):
            raise RecordingError(f"{path}: this is the table of a fleet run (one row per loop's result), not a "
                                 f"recording; give the folder of the recordings or a historian's export")
        files = [path]
    else:
        raise RecordingError(f"{path}: no such file or folder")
    out: list[LoopSource] = []
    seen: set[str] = set()
    for f in files:
        try:
            fp = file_fingerprint(f)
        except OSError as e:
            fp = ""
            srcs = [LoopSource(os.path.basename(f), "bad", f, problem=f"{f}: cannot be read ({e})")]
        else:
            srcs = _file_sources(f, fp)
        for s in srcs:
            name = safe_name(s.name)
            if name in seen:
                name = safe_name(f"{s.name}@{os.path.splitext(os.path.basename(f))[0]}")
            k = 2
            base = name
            while name in seen:
                name, k = f"{base}-{k}", k + 1
            seen.add(name)
            out.append(s if name == s.name else LoopSource(name, s.kind, s.path, s.tag, s.time_column,
                                                           s.columns, s.fingerprint, s.problem))
    return out


# --------------------------------------------------------------------------- loading
def _read_table(src: LoopSource, names: list[str], numbers: bool):
    """The columns ``names`` of a wide export (a CSV file's signal columns as numbers, or as text)."""
    if src.path.lower().endswith(".parquet"):
        import pyarrow.parquet as pq
        return pq.read_table(src.path, columns=names)
    import pyarrow as pa
    import pyarrow.csv as pcsv
    types = {c: (pa.float64() if numbers and r != "mode" else pa.string()) for r, c in src.columns}
    types[src.time_column] = pa.string()
    return pcsv.read_csv(src.path, parse_options=pcsv.ParseOptions(delimiter=_delimiter(src.path)),
                         convert_options=pcsv.ConvertOptions(include_columns=names, column_types=types))


def _read_wide_columns(src: LoopSource, roles: dict[str, str]) -> tuple[dict[str, np.ndarray], dict[str, tuple]]:
    """The time column (as read) and the columns ``roles`` (role -> column) of a tag of a wide export.

    Returns the columns (signals as float, NaN where a cell is missing or not a number; the mode as
    read) and, per signal role with cells that are neither numbers nor blank, ``(positions, cells)``.
    """
    names = [src.time_column] + list(roles.values())
    try:
        table = _read_table(src, names, numbers=True)
    except Exception as e:  # pyarrow: ArrowInvalid, OSError, ...
        msg = str(e).splitlines()[0][:300]
        try:        # a status text (``Bad Input``) in a number column: read the cells as text
            table = _read_table(src, names, numbers=False)
        except Exception:
            raise RecordingError(f"{src.path}: cannot read the columns of tag {src.tag!r} ({msg}); "
                                 f"check that they hold numbers") from None
    out = {"t": table.column(src.time_column).to_numpy(zero_copy_only=False)}
    text: dict[str, tuple] = {}
    comma = not src.path.lower().endswith(".parquet") and _delimiter(src.path) == ";"    # '0,53' is 0.53
    for role, c in roles.items():
        if role == "mode":
            out[role] = table.column(c).to_numpy(zero_copy_only=False)
            continue
        cells = arrow_to_numpy(table.column(c), c, src.path)
        out[role], bad, _ = parse_numbers(cells, decimal_comma=comma)
        if bad:
            text[role] = (np.asarray(bad), cells)
    return out, text


def _delimiter(path: str) -> str:
    """The delimiter of a wide export in CSV: ``;`` when the first line holds one, else ``,``."""
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        return ";" if ";" in f.readline() else ","


def _stamp(t_raw: np.ndarray, i: int) -> str:
    """Row ``i``'s time stamp as written (seconds, or the date to the second)."""
    v = t_raw[i]
    if t_raw.dtype.kind == "M":
        return str(v)[:19].replace("T", " ")
    return f"{v:g}" if isinstance(v, (float, np.floating)) else str(v).strip()


def _text_cells(src: LoopSource, t_raw: np.ndarray, column: str, bad: np.ndarray, cells: np.ndarray, filled: int,
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


def _numeric_seconds(t: np.ndarray, src: LoopSource, notes: list[str],
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


def _seconds(t_raw: np.ndarray, src: LoopSource, notes: list[str], dayfirst: bool | None = None,
             time_unit: str | None = None) -> tuple[np.ndarray, str | None]:
    """Time stamps as float seconds (and the first stamp as ISO text when they are dates).

    Numbers are seconds, epoch seconds, milliseconds or spreadsheet days, and text dates are ISO,
    day-first or month-first, as :mod:`~valve_gym.diagnosis.recording.units` reads them (the
    choice in ``notes``).  A few cells of a text column that are neither numbers nor dates are rows
    without a time stamp (:func:`_text_cells`).
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


def _role_on_grid(t: np.ndarray, x: np.ndarray, grid: np.ndarray, hold: bool) -> np.ndarray:
    if hold:
        j = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 1)
        return x[j]
    return np.interp(grid, t, x)


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
        a, b = _longest_run(known)
        notes.append(f"{len(gaps)} gap(s) longer than {max_gap} scans (longest {max(g.seconds for g in gaps):g} s); "
                     f"kept the longest stretch without one: {grid[a] - lo:g}-{grid[b - 1] - lo:g} s")
        grid = grid[a:b]
        values = {r: v[a:b] for r, v in values.items()}
    return grid, values, gaps, notes


def _present(x: np.ndarray) -> np.ndarray:
    if x.dtype.kind == "f":
        return np.isfinite(x)
    return np.array([v is not None and str(v).strip() not in ("", "nan", "None") for v in x], bool)


def _longest_run(mask: np.ndarray) -> tuple[int, int]:
    if not mask.any():
        raise RecordingError("no stretch of the record is free of gaps")
    return longest_run(mask)


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


def _normalise_op(op: np.ndarray, op_range, where: str, notes: list[str]) -> tuple[np.ndarray, tuple]:
    if op_range is None:            # read from the values: fraction, percent or unknown span (never a failure)
        op_range, said = infer_op_range(op)
        notes.append(said)
    lo, hi = (float(v) for v in op_range)
    tol = 0.05 * (hi - lo)
    if op.min() < lo - tol or op.max() > hi + tol:
        raise RecordingError(f"{where}: OP values {op.min():g}..{op.max():g} lie more than 5 % outside the range "
                             f"{lo:g}..{hi:g}; pass the right range with --op-range LO,HI")
    if op.min() < lo or op.max() > hi:
        notes.append(f"clipped OP values slightly outside {lo:g}..{hi:g}")
    return np.clip((op - lo) / (hi - lo), 0.0, 1.0), (lo, hi)


def _ordered(t: np.ndarray, t_raw: np.ndarray, src: LoopSource, dated: bool) -> None:
    """Refuse time stamps that decrease in the order of the rows (a daylight-saving fall-back named)."""
    ok = np.flatnonzero(np.isfinite(t))
    check_increasing(t[ok], f"{src.path}: column {src.time_column!r} (t)", lambda i: f"row {ok[i] + 1}",
                     lambda i: _stamp(t_raw, int(ok[i])), dated)


def _load_wide(src: LoopSource, op_range, max_gap: int, off: tuple[str, ...] = (), dayfirst: bool | None = None,
               time_unit: str | None = None) -> LoadedLoop:
    where = f"{src.path}: tag {src.tag!r}"
    roles = {r: c for r, c in src.columns if r not in off}
    cols, text = _read_wide_columns(src, roles)
    t_raw = cols.pop("t")
    notes: list[str] = []
    t, start = _seconds(t_raw, src, notes, dayfirst, time_unit)
    _ordered(t, t_raw, src, start is not None)
    for role, (bad, cells) in text.items():
        filled = int(np.isfinite(cols[role]).sum()) + bad.size
        _text_cells(src, t_raw, roles[role], bad, cells, filled, notes)
    try:
        grid, values, gaps, said = resample_loop(t, cols, max_gap=max_gap)
    except RecordingError as e:
        raise RecordingError(f"{where}: {e}") from None
    notes.extend(said)
    grid, values = _automatic_stretch(values, grid, notes, where, roles.get("mode", ""))
    if len(grid) < MIN_SAMPLES:
        raise RecordingError(f"{where}: only {len(grid)} usable samples after resampling (need {MIN_SAMPLES}); "
                             f"export a longer stretch")
    op, rng = _normalise_op(values["op"], op_range, where, notes)
    for role in ("op", "pv"):
        x = values[role]
        if np.ptp(x) <= 1e-12 * max(1.0, float(np.abs(x).max())):
            raise RecordingError(f"{where}: the {role.upper()} is constant; nothing to diagnose")
    cols_used = {"t": src.time_column, **roles}
    cols_used.pop("mode", None)
    rec = Recording(t=grid - grid[0], op=op, pv=values["pv"], sp=values.get("sp"), dt=float(grid[1] - grid[0]),
                    name=src.name, op_range=rng, repairs=tuple(notes), columns=cols_used, start=start)
    return LoadedLoop(rec, tuple(gaps), tuple(notes))


def load_loop(src: LoopSource, columns=None, op_range=None, max_gap: int = 5, mv_range=None,
              dayfirst: bool | None = None, time_unit: str | None = None) -> LoadedLoop:
    """Read one loop.

    Parameters
    ----------
    src : LoopSource, from :func:`discover_loops`
    columns : dict, optional, role -> column name for one-recording CSV files (as ``--columns``); of a
        wide export's tag only the optional roles switched off are used (``{'mode': None}``: the
        ``TAG.MODE`` column is not read, the whole record is; ``{'sp': None}`` likewise)
    op_range : (lo, hi), optional, raw controller-output range that maps to 0..1 (default: read from the
        values, :func:`~valve_gym.diagnosis.recording.units.infer_op_range`, the choice in the notes)
    max_gap : int, longest stretch without samples bridged by interpolation, in scans
    mv_range : (lo, hi), optional, raw valve-position range (one-recording files; default ``op_range``)
    dayfirst : bool or None, dates ``D/M/Y`` (True) or ``M/D/Y`` (False); None reads it from the data
    time_unit : str or None, unit of a numeric time column; None reads it from the data

    Returns
    -------
    LoadedLoop

    Raises
    ------
    RecordingError
        The file, the tag or its data cannot be used; the message names the file, the tag or
        column, and what to do.
    """
    if src.kind == "bad":
        raise RecordingError(src.problem)
    if src.kind == "wide":
        off = tuple(r for r, c in (columns or {}).items() if r in ("sp", "mode") and not (c and str(c).strip()))
        return _load_wide(src, op_range, max_gap, off, dayfirst, time_unit)
    rec = load_recording(src.path, columns=columns, op_range=op_range, name=src.name, max_gap=max_gap,
                         gaps="longest", mv_range=mv_range, dayfirst=dayfirst, time_unit=time_unit)
    n_gaps = sum(int(m) for r in rec.repairs for m in re.findall(r"(\d+) gap\(s\)", r))
    gaps = tuple(Gap("pv", math.nan, math.nan) for _ in range(n_gaps))     # times are in the notes
    return LoadedLoop(rec, gaps, tuple(rec.repairs) + tuple(rec.notes))
