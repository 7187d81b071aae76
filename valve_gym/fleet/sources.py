"""Where a fleet's loops come from: one CSV per loop, or a historian's wide export split by tag.

A *loop source* (:class:`LoopSource`) is a small, picklable description of
one loop: the file, the tag and the columns.  :func:`discover_loops` lists the
loops of a file or a folder without loading their data; :func:`load_loop`
reads one loop (in a worker) and returns a :class:`LoadedLoop` with a
:class:`~valve_gym.diagnosis.recording.Recording` on a uniform grid and the
gaps found on the way.

The files are read by the recording pipeline of the diagnosis
(:mod:`valve_gym.diagnosis.recording`), never here:

* **one recording per file** (``*.csv``, ``*.txt`` DCS exports): read by
  :func:`~valve_gym.diagnosis.recording.load_recording` (same columns and
  ranges as ``valve-gym diagnose FILE``; a gap longer than five samples keeps
  the longest stretch without one, reported);
* **a historian's wide export** (``*.csv`` or ``*.parquet``): one time-stamp
  column and, per loop, columns ``TAG.PV``, ``TAG.OP``, optionally ``TAG.SP``
  and ``TAG.MODE``.  Each tag becomes a loop, read by
  :func:`~valve_gym.diagnosis.recording.wide.load_wide_tag` (each tag resampled
  onto a uniform grid at its own scan, :func:`resample_loop`).

What is the fleet's own: the names of the loops (unique, file-safe), the
fingerprint of each file (the resume key), and the outputs of an earlier
fleet run that a folder may hold (skipped).
"""
from __future__ import annotations

import hashlib
import math
import os
import re
from dataclasses import dataclass

from ..diagnosis.recording import RecordingError, load_recording
from ..diagnosis.recording.sniff import recording_files
from ..diagnosis.recording.wide import (
    TEXT_FRACTION,
    TIME_COLUMN_NAMES,
    WIDE_SUFFIXES,
    Gap,
    WideLoop,
    WideTag,
    file_header,
    load_wide_tag,
    resample_loop,
    wide_sources,
)
from .result import TABLE_COLUMNS

__all__ = ["LoopSource", "LoadedLoop", "Gap", "discover_loops", "load_loop", "resample_loop",
           "file_fingerprint", "safe_name", "fleet_outputs", "is_fleet_output", "FLEET_OUTPUT_FILES",
           "WIDE_SUFFIXES", "TIME_COLUMN_NAMES", "TEXT_FRACTION"]


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


#: A loop's recording and what reading it found (recording, gaps, notes): the recording pipeline's own type,
#: for a wide export's tag and a single-loop file alike.
LoadedLoop = WideLoop


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
def _file_sources(path: str, fp: str) -> list[LoopSource]:
    stem = os.path.splitext(os.path.basename(path))[0]
    try:
        header, form = file_header(path)
    except (RecordingError, OSError) as e:
        return [LoopSource(stem, "bad", path, fingerprint=fp, problem=str(e))]
    tags = wide_sources(path, header) if form != "dcs-export" else []
    if not tags:
        if form == "parquet":
            return [LoopSource(stem, "bad", path, fingerprint=fp,
                               problem=f"{path}: a Parquet file must be a wide export with columns TAG.PV, "
                                       f"TAG.OP (found {', '.join(header[:6])}); write single loops as CSV")]
        return [LoopSource(stem, "csv", path, fingerprint=fp)]
    return [LoopSource(w.tag, "bad" if w.problem else "wide", path, tag=w.tag, time_column=w.time_column,
                       columns=w.columns, fingerprint=fp, problem=w.problem) for w in tags]


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
        header, _ = file_header(path)
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
def load_loop(src: LoopSource, columns=None, op_range=None, max_gap: int = 5, mv_range=None,
              dayfirst: bool | None = None, time_unit: str | None = None, dt: float | None = None,
              gaps: str = "longest") -> LoadedLoop:
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
    dt : float, optional, sample time [s] of one-recording files without a time column (``--dt``)
    gaps : {'longest', 'error'}, a gap longer than ``max_gap``: keep the longest stretch without one,
        or fail the loop (``--gaps``)

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
        if dt is not None:
            raise RecordingError(f"{src.path}: tag {src.tag!r}: a wide export carries its time stamps; leave out "
                                 f"--dt (it gives the sample time of a file without a time column)")
        off = tuple(r for r, c in (columns or {}).items() if r in ("sp", "mode") and not (c and str(c).strip()))
        w = load_wide_tag(WideTag(src.path, src.tag, src.time_column, src.columns), name=src.name,
                          op_range=op_range, max_gap=max_gap, off=off, dayfirst=dayfirst, time_unit=time_unit,
                          gaps=gaps)
        return w
    rec = load_recording(src.path, columns=columns, op_range=op_range, name=src.name, max_gap=max_gap,
                         gaps=gaps, mv_range=mv_range, dayfirst=dayfirst, time_unit=time_unit, dt=dt)
    n_gaps = sum(int(m) for r in rec.repairs for m in re.findall(r"(\d+) gap\(s\)", r))
    found = tuple(Gap("pv", math.nan, math.nan) for _ in range(n_gaps))     # times are in the notes
    return WideLoop(rec, found, tuple(rec.repairs) + tuple(rec.notes))
