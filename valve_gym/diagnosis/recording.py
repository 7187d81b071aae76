"""Load a control-loop recording (CSV) for the diagnosis tool.

A *recording* is a sampled control loop: the controller output ``op``, the
process variable ``pv``, optionally the set point ``sp`` and the valve stem
position ``mv``, on a uniform time grid.  :func:`load_recording` reads a CSV
file, finds the columns, checks every value, repairs what can be repaired
safely (short gaps, small time-stamp jitter, exact duplicate rows, values a
hair outside the stated range) and records each repair in
:attr:`Recording.repairs`.  Anything it cannot repair safely raises
:class:`RecordingError` with a message that names the file, the column, the
problem and what to do about it.

Real recordings shipped with the package (see ``valve_gym/data/README.md``)
are located with :func:`data_path`.

Examples
--------
>>> from valve_gym.diagnosis.recording import data_path, load_recording
>>> rec = load_recording(data_path("cascaded_tanks/estimation.csv"),
...                      columns={"t": "t_s", "op": "u_V", "pv": "y_V"},
...                      op_range=(0, 10))
>>> len(rec), rec.dt, rec.op_range
(1024, 4.0, (0.0, 10.0))
>>> round(float(rec.op.max()), 4)   # pump voltage 6.4712 V of 0..10 V
0.6471
>>> rec.sp is None, rec.repairs
(True, ())
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

import numpy as np

__all__ = [
    "MIN_SAMPLES",
    "ROLES",
    "DEFAULT_COLUMN_NAMES",
    "Recording",
    "RecordingError",
    "data_path",
    "load_recording",
    "parse_columns",
    "parse_range",
]

#: Shortest record (samples, after repairs) that :func:`load_recording` accepts.
MIN_SAMPLES = 50

#: Signal roles, in order: time, controller output, process variable,
#: set point, valve stem position.
ROLES = ("t", "op", "pv", "sp", "mv")

_REQUIRED = ("t", "op", "pv")

_ROLE_WORDS = {
    "t": "time",
    "op": "controller output",
    "pv": "process variable",
    "sp": "set point",
    "mv": "valve stem position",
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
}

# Cells read as "missing" (case-insensitive, after stripping blanks).
_MISSING_TOKENS = frozenset({"", "nan", "na", "n/a", "#n/a", "null", "none", "-"})

# Relative out-of-range tolerance (fraction of span) that is clipped silently-
# but-recorded; beyond it the value is an error.
_RANGE_TOLERANCE = 0.05

# Time-stamp jitter (fraction of the median step) below which resampling is
# always done; a step longer than _GAP_FACTOR * dt counts as missing samples.
_SMALL_JITTER = 0.10
_GAP_FACTOR = 1.5
_UNIFORM_RTOL = 1e-6

_DATA_DIR = Path(__file__).resolve().parent.parent / "data"


class RecordingError(ValueError):
    """A recording file, a column mapping or a range cannot be used.

    The message names the file (where there is one), the column, the problem
    and what to do about it.
    """


# --------------------------------------------------------------------------
# Recording
# --------------------------------------------------------------------------


def _as_signal(x: Any, what: str, n: int | None = None) -> np.ndarray:
    a = np.array(x, dtype=np.float64, copy=True)
    if a.ndim != 1:
        raise ValueError(f"Recording.{what} must be 1-D, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"Recording.{what} has {a.shape[0]} samples, t has {n}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"Recording.{what} contains NaN or infinite values")
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False, repr=False)
class Recording:
    """A validated control-loop recording on a uniform time grid.

    Attributes
    ----------
    t : ndarray, shape (n,), float64
        Sample times in seconds, uniformly spaced by `dt`.  For files whose
        time column holds date strings, seconds since the first sample
        (see `start`).
    op : ndarray, shape (n,), float64
        Controller output normalised to 0..1 with `op_range`
        (``(op_raw - lo) / (hi - lo)``).
    pv : ndarray, shape (n,), float64
        Process variable in its own engineering units.
    sp : ndarray, shape (n,), float64, or None
        Set point in the units of `pv`, if recorded.
    mv : ndarray, shape (n,), float64, or None
        Valve stem position normalised to 0..1, if recorded.
    dt : float
        Uniform sample time in seconds.  If None at construction, taken from
        `t`.
    name : str
        Label of the record (by default the file name without extension).
    op_range : tuple of float
        ``(lo, hi)`` of the raw controller output that maps to 0..1.
    repairs : tuple of str
        One human-readable line per repair done while loading (empty if the
        file was used as it is).
    columns : dict of str to str
        Role (``"t"``, ``"op"``, ``"pv"``, ``"sp"``, ``"mv"``) to the column
        name used in the file; only the roles present.
    start : str or None
        First time stamp as written in the file when the time column held
        date strings, else None.

    Notes
    -----
    The arrays are read-only copies.  Equality is identity (arrays do not
    compare to a single bool).
    """

    t: np.ndarray
    op: np.ndarray
    pv: np.ndarray
    sp: np.ndarray | None = None
    mv: np.ndarray | None = None
    dt: float | None = None
    name: str = "recording"
    op_range: tuple[float, float] = (0.0, 1.0)
    repairs: tuple[str, ...] = ()
    columns: dict[str, str] = field(default_factory=dict)
    start: str | None = None

    def __post_init__(self) -> None:
        t = _as_signal(self.t, "t")
        n = t.shape[0]
        if n < 1:
            raise ValueError("Recording needs at least one sample")
        set_ = object.__setattr__
        set_(self, "t", t)
        set_(self, "op", _as_signal(self.op, "op", n))
        set_(self, "pv", _as_signal(self.pv, "pv", n))
        set_(self, "sp", None if self.sp is None else _as_signal(self.sp, "sp", n))
        set_(self, "mv", None if self.mv is None else _as_signal(self.mv, "mv", n))

        dt = self.dt
        if dt is None:
            if n < 2:
                raise ValueError("Recording.dt must be given for a single sample")
            dt = float(np.median(np.diff(t)))
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"Recording.dt must be a positive number of seconds, got {dt!r}")
        if n >= 2:
            tol = _UNIFORM_RTOL * dt + 8 * np.finfo(float).eps * float(np.max(np.abs(t)))
            dev = float(np.max(np.abs(np.diff(t) - dt)))
            if dev > tol:
                raise ValueError(
                    f"Recording.t is not uniformly spaced by dt={dt:g} s "
                    f"(steps deviate by up to {dev:g} s); use load_recording to resample"
                )
        set_(self, "dt", dt)

        for what in ("op", "mv"):
            a = getattr(self, what)
            if a is not None and (a.min() < 0.0 or a.max() > 1.0):
                raise ValueError(
                    f"Recording.{what} must be normalised to 0..1, "
                    f"got values {a.min():g}..{a.max():g}"
                )
        lo, hi = (float(v) for v in self.op_range)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"Recording.op_range must be (lo, hi) with lo < hi, got {self.op_range!r}")
        set_(self, "op_range", (lo, hi))
        set_(self, "name", str(self.name))
        set_(self, "repairs", tuple(str(r) for r in self.repairs))
        set_(self, "columns", dict(self.columns))

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def __repr__(self) -> str:
        roles = ", ".join(r for r in ROLES[1:] if getattr(self, r) is not None)
        return (
            f"Recording(name={self.name!r}, n={len(self)}, dt={self.dt:g} s, "
            f"signals=[{roles}], op_range={self.op_range}, repairs={len(self.repairs)})"
        )

    @property
    def duration(self) -> float:
        """Length of the record in seconds, ``n * dt``."""
        return len(self) * self.dt

    def slice(self, i0: int | None = None, i1: int | None = None) -> "Recording":
        """Samples ``i0`` to ``i1 - 1`` as a new Recording.

        Parameters
        ----------
        i0, i1 : int or None
            Start (inclusive) and stop (exclusive) sample indices with Python
            slice semantics (negative counts from the end, None = open).

        Returns
        -------
        Recording
            Same `dt`, `op_range`, `repairs` and `columns`; `t` keeps the
            original times; `name` gets ``[i0:i1]`` appended.

        Raises
        ------
        ValueError
            If the slice is empty.
        """
        s = slice(i0, i1)
        a, b, _ = s.indices(len(self))
        if b <= a:
            raise ValueError(
                f"Recording.slice({i0}, {i1}) of {self.name!r} (n={len(self)}) is empty"
            )

        def cut(x: np.ndarray | None) -> np.ndarray | None:
            return None if x is None else x[a:b]

        return Recording(
            t=self.t[a:b], op=self.op[a:b], pv=self.pv[a:b], sp=cut(self.sp), mv=cut(self.mv),
            dt=self.dt, name=f"{self.name}[{a}:{b}]", op_range=self.op_range,
            repairs=self.repairs, columns=self.columns, start=self.start if a == 0 else None,
        )

    def to_dataframe(self):
        """The signals as a :class:`pandas.DataFrame`.

        Returns
        -------
        pandas.DataFrame
            Columns ``t``, ``op``, ``pv`` and, when present, ``sp``, ``mv``
            (n rows; op and mv normalised 0..1).  ``df.attrs`` holds
            ``name``, ``dt``, ``op_range``, ``repairs``, ``columns``, ``start``.
        """
        import pandas as pd

        data = {"t": self.t, "op": self.op, "pv": self.pv}
        if self.sp is not None:
            data["sp"] = self.sp
        if self.mv is not None:
            data["mv"] = self.mv
        df = pd.DataFrame({k: np.array(v) for k, v in data.items()})
        df.attrs.update(
            name=self.name, dt=self.dt, op_range=self.op_range, repairs=list(self.repairs),
            columns=dict(self.columns), start=self.start,
        )
        return df


# --------------------------------------------------------------------------
# Package data
# --------------------------------------------------------------------------


def data_path(name: str) -> Path:
    """Path of a data file or folder shipped in ``valve_gym/data``.

    Parameters
    ----------
    name : str
        Relative path inside the data folder, e.g.
        ``"cascaded_tanks/estimation.csv"`` or ``"stictiongpt_plant_loops"``.

    Returns
    -------
    pathlib.Path
        Existing path.

    Raises
    ------
    FileNotFoundError
        If nothing of that name is shipped; the message lists what is.

    Examples
    --------
    >>> data_path("cascaded_tanks/estimation.csv").name
    'estimation.csv'
    """
    rel = Path(str(name))
    if rel.is_absolute() or ".." in rel.parts:
        raise FileNotFoundError(
            f"data_path({name!r}): give a path relative to the package data folder {_DATA_DIR}"
        )
    p = _DATA_DIR / rel
    if not p.exists():
        parent = p.parent if p.parent.is_dir() else _DATA_DIR
        try:
            avail = sorted(c.name + ("/" if c.is_dir() else "") for c in parent.iterdir())
        except OSError:
            avail = []
        shown = ", ".join(avail[:20]) + (", ..." if len(avail) > 20 else "")
        raise FileNotFoundError(
            f"data_path({name!r}): no shipped data file {p}; "
            f"{parent} holds: {shown or '(nothing - is the package data installed?)'}"
        )
    return p


# --------------------------------------------------------------------------
# CLI helpers
# --------------------------------------------------------------------------


def parse_columns(text: str) -> dict[str, str | None]:
    """Parse a column mapping such as ``"t=t_s,op=OP,pv=PV,sp=SP"``.

    Parameters
    ----------
    text : str
        Comma-separated ``role=COLUMN`` items; roles are ``t, op, pv, sp, mv``.
        An empty column (``sp=``) means "do not use this role".  Column names
        cannot contain commas.

    Returns
    -------
    dict
        Role to column name (or None), suitable for ``load_recording(columns=...)``.

    Raises
    ------
    RecordingError
        For an item without ``=``, an unknown or repeated role, or an empty
        column for ``t``, ``op`` or ``pv``.

    Examples
    --------
    >>> parse_columns("t=t_s, op=OP, pv=PV, sp=")
    {'t': 't_s', 'op': 'OP', 'pv': 'PV', 'sp': None}
    """
    usage = "expected --columns role=COLUMN[,role=COLUMN...] with roles t, op, pv, sp, mv, e.g. t=t_s,op=OP,pv=PV"
    if text is None or not str(text).strip():
        raise RecordingError(f"empty column mapping: {usage}")
    out: dict[str, str | None] = {}
    for item in str(text).split(","):
        item = item.strip()
        if not item:
            continue
        if "=" not in item:
            raise RecordingError(f"column mapping item {item!r} has no '=': {usage}")
        role, col = (s.strip() for s in item.split("=", 1))
        role = role.lower()
        if role not in ROLES:
            raise RecordingError(f"unknown role {role!r} in column mapping {text!r}: {usage}")
        if role in out:
            raise RecordingError(f"role {role!r} given twice in column mapping {text!r}: {usage}")
        if not col and role in _REQUIRED:
            raise RecordingError(
                f"role {role!r} ({_ROLE_WORDS[role]}) needs a column name in {text!r}: {usage}"
            )
        out[role] = col or None
    if not out:
        raise RecordingError(f"empty column mapping {text!r}: {usage}")
    return out


def parse_range(text: str) -> tuple[float, float]:
    """Parse a range ``"LO,HI"`` such as ``"0,100"``.

    Parameters
    ----------
    text : str
        Two finite numbers separated by a comma, ``LO < HI``.

    Returns
    -------
    tuple of float
        ``(lo, hi)``.

    Raises
    ------
    RecordingError
        If the text is not two finite numbers with ``LO < HI``.

    Examples
    --------
    >>> parse_range("0,100")
    (0.0, 100.0)
    """
    usage = "expected LO,HI with two numbers and LO < HI, e.g. --op-range 0,100"
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 2 or not all(parts):
        raise RecordingError(f"range {text!r} is not two comma-separated numbers: {usage}")
    try:
        lo, hi = float(parts[0]), float(parts[1])
    except ValueError:
        raise RecordingError(f"range {text!r} contains a non-number: {usage}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise RecordingError(f"range {text!r} must be finite: {usage}")
    if not lo < hi:
        raise RecordingError(f"range {text!r} has LO >= HI: {usage}")
    return (lo, hi)


# --------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------


def _fmt_lines(lines: list[int], limit: int = 5) -> str:
    s = ", ".join(str(x) for x in lines[:limit])
    if len(lines) > limit:
        s += f", ... ({len(lines)} in all)"
    return s


def _read_table(path: Path) -> tuple[list[str], list[list[str]], list[int]]:
    """Header, data rows (as strings) and their file line numbers."""
    src = str(path)
    if not path.exists():
        raise RecordingError(f"{src}: file not found; check the path (relative paths start at {os.getcwd()})")
    if path.is_dir():
        raise RecordingError(f"{src}: is a folder, not a CSV file; give the path of a .csv file in it")
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise RecordingError(f"{src}: cannot be read ({e.strerror or e}); check the file's permissions") from None
    if not raw.strip():
        raise RecordingError(f"{src}: file is empty; expected a CSV file with a header row and data rows")
    if b"\x00" in raw[:65536]:
        raise RecordingError(
            f"{src}: not a text CSV file (binary content); if it is a spreadsheet, export it as CSV"
        )
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")

    sample = text[:8192]
    try:
        dialect: Any = csv.Sniffer().sniff(sample, delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    reader = csv.reader(io.StringIO(text, newline=""), dialect)
    header: list[str] | None = None
    rows: list[list[str]] = []
    lines: list[int] = []
    try:
        for rec in reader:
            if not rec or all(not c.strip() for c in rec):
                continue
            if header is None:
                header = [c.strip() for c in rec]
                continue
            rows.append(rec)
            lines.append(reader.line_num)
    except csv.Error as e:
        raise RecordingError(
            f"{src}: not a valid CSV file near line {reader.line_num} ({e}); check quoting and separators"
        ) from None
    if header is None:
        raise RecordingError(f"{src}: file has no header row; the first line must name the columns")
    if len(header) < 2:
        raise RecordingError(
            f"{src}: only one column ({header[0]!r}) found; expected a CSV file with a header row and "
            f"comma-, semicolon- or tab-separated columns for time, controller output and process variable"
        )
    ncol = len(header)
    bad = []
    for i, (rec, ln) in enumerate(zip(rows, lines)):
        if len(rec) < ncol:
            bad.append(ln)
        elif len(rec) > ncol:
            if any(c.strip() for c in rec[ncol:]):
                bad.append(ln)
            else:
                rows[i] = rec[:ncol]
    if bad:
        raise RecordingError(
            f"{src}: the header has {ncol} columns but lines {_fmt_lines(bad)} have a different number "
            f"of fields; fix or delete those lines"
        )
    if not rows:
        raise RecordingError(f"{src}: no data rows under the header; the file holds no samples")
    return header, rows, lines


def _resolve_columns(
    header: list[str], columns: Mapping[str, str | None] | None, src: str
) -> dict[str, int]:
    """Role -> column index."""
    columns = dict(columns or {})
    avail = ", ".join(repr(h) for h in header)
    for role in columns:
        if role not in ROLES:
            raise RecordingError(
                f"{src}: unknown role {role!r} in columns; roles are {', '.join(ROLES)}"
            )
    lower: dict[str, list[int]] = {}
    for j, h in enumerate(header):
        lower.setdefault(h.lower(), []).append(j)

    out: dict[str, int] = {}
    for role in ROLES:
        if role in columns:
            name = columns[role]
            if name is None or str(name).strip() == "":
                if role in _REQUIRED:
                    raise RecordingError(
                        f"{src}: the {_ROLE_WORDS[role]} ({role}) cannot be switched off; "
                        f"name its column (available: {avail})"
                    )
                continue
            name = str(name).strip()
            exact = [j for j, h in enumerate(header) if h == name]
            hits = exact or lower.get(name.lower(), [])
            if not hits:
                raise RecordingError(
                    f"{src}: column {name!r} given for the {_ROLE_WORDS[role]} ({role}) is not in the "
                    f"file; available columns: {avail}"
                )
            if len(hits) > 1:
                raise RecordingError(
                    f"{src}: column name {name!r} ({role}) appears {len(hits)} times in the header; "
                    f"rename the duplicates in the file"
                )
            out[role] = hits[0]
        else:
            for cand in DEFAULT_COLUMN_NAMES[role]:
                hits = lower.get(cand, [])
                if len(hits) == 1 and hits[0] not in out.values():
                    out[role] = hits[0]
                    break
            else:
                if role in _REQUIRED:
                    raise RecordingError(
                        f"{src}: no column for the {_ROLE_WORDS[role]} ({role}): none of the default "
                        f"names {', '.join(DEFAULT_COLUMN_NAMES[role])} is among the columns {avail}; "
                        f"pass columns={{'{role}': NAME}} (CLI: --columns {role}=NAME)"
                    )
    seen: dict[int, str] = {}
    for role, j in out.items():
        if j in seen:
            raise RecordingError(
                f"{src}: column {header[j]!r} is used for both {seen[j]} and {role}; "
                f"map each role to its own column"
            )
        seen[j] = role
    return out


def _parse_numbers(cells: list[str]) -> tuple[np.ndarray, list[int]]:
    """Float array (NaN = missing) and indices of non-numeric cells."""
    out = np.empty(len(cells), dtype=np.float64)
    bad: list[int] = []
    for i, c in enumerate(cells):
        s = c.strip()
        if s.lower() in _MISSING_TOKENS:
            out[i] = np.nan
            continue
        try:
            v = float(s)
        except ValueError:
            bad.append(i)
            out[i] = np.nan
            continue
        out[i] = v if math.isfinite(v) else np.nan
    return out, bad


def _parse_datetimes(cells: list[str], idx: list[int]) -> tuple[np.ndarray, list[int]]:
    """Seconds (UTC for naive stamps) at positions idx; bad positions."""
    out = np.full(len(cells), np.nan)
    bad: list[int] = []
    aware = set()
    for i in idx:
        s = cells[i].strip()
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


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of the runs of True in a boolean array."""
    if not mask.any():
        return []
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def _resample(
    t: np.ndarray, x: np.ndarray, grid: np.ndarray, dt: float, hold: bool
) -> np.ndarray:
    """Values of x on grid (NaN where unknown): linear or zero-order hold.

    Grid points within a tiny tolerance of a sample take its value exactly; a
    grid point inside a step longer than _GAP_FACTOR * dt is unknown.
    """
    tol = _UNIFORM_RTOL * dt
    j = np.searchsorted(t, grid + tol, side="right") - 1
    j = np.clip(j, 0, len(t) - 1)
    exact = np.abs(grid - t[j]) <= tol
    jn = np.minimum(j + 1, len(t) - 1)
    step = t[jn] - t[j]
    in_gap = ~exact & (step > _GAP_FACTOR * dt)
    if hold:
        y = x[j].copy()
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(step > 0, (grid - t[j]) / np.where(step > 0, step, 1.0), 0.0)
            y = np.where(exact, x[j], x[j] + w * (x[jn] - x[j]))
    y[in_gap] = np.nan
    return y


def load_recording(
    path: str | os.PathLike,
    columns: Mapping[str, str | None] | None = None,
    op_range: tuple[float, float] | None = None,
    name: str | None = None,
    max_gap: int = 5,
    resample: bool | str = "auto",
    gaps: str = "error",
    mv_range: tuple[float, float] | None = None,
) -> Recording:
    """Read a control-loop recording from a CSV file.

    Parameters
    ----------
    path : str or path-like
        CSV file with a header row; comma, semicolon or tab separated, UTF-8
        (a byte-order mark is fine).  Blank cells and ``nan``, ``NA``,
        ``null`` count as missing values.
    columns : dict, optional
        Role to column name for the roles ``t`` (time), ``op`` (controller
        output), ``pv`` (process variable), ``sp`` (set point), ``mv`` (valve
        stem position).  Names match exactly, else case-insensitively.  A
        role left out is looked up among :data:`DEFAULT_COLUMN_NAMES`
        (case-insensitive; ``t``, ``op``, ``pv`` are required, ``sp`` and
        ``mv`` optional); map a role to None to ignore it.
        The time column holds seconds, or ISO 8601 date strings
        (``2024-11-21 00:01:00``; converted to seconds since the first
        sample, naive stamps taken as UTC).
    op_range : (float, float), optional
        Raw controller-output values ``(lo, hi)`` that map to 0..1, e.g.
        ``(0, 100)`` for percent.  May be omitted only when all op values lie
        in [0, 1]; otherwise an error asks for it.  Values outside the range
        by up to 5 % of its span are clipped (recorded as a repair); further
        out is an error.
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
    gaps : {'error', 'longest'}, default 'error'
        What to do with a run of missing samples longer than `max_gap`:
        'error' raises RecordingError naming its time span; 'longest' keeps
        the longest stretch of the record free of such gaps (recorded as a
        repair).
    mv_range : (float, float), optional
        Raw stem-position values that map to 0..1; default the same as the
        controller output's range (`op_range`, or (0, 1)).

    Returns
    -------
    Recording
        float64 arrays of shape (n,), finite, on a uniform grid of step
        ``dt`` seconds, n >= 50; every repair listed in ``repairs``.

    Raises
    ------
    RecordingError
        Missing, unreadable or non-CSV file; a named column absent (the
        message lists the available ones); non-numeric cells (first line
        numbers given); missing time stamps; decreasing time stamps or
        duplicate time stamps with different values (exact duplicate rows
        are dropped as a repair); a gap longer than `max_gap` (with
        ``gaps='error'``); irregular sampling with ``resample=False``;
        op values outside [0, 1] without `op_range`, or far outside it;
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
    src = os.fspath(path)
    p = Path(src)
    if isinstance(max_gap, bool) or not isinstance(max_gap, (int, np.integer)) or max_gap < 0:
        raise RecordingError(f"{src}: max_gap must be a whole number of samples >= 0, got {max_gap!r}")
    if resample not in ("auto", True, False):
        raise RecordingError(f"{src}: resample must be 'auto', True or False, got {resample!r}")
    if gaps not in ("error", "longest"):
        raise RecordingError(f"{src}: gaps must be 'error' or 'longest', got {gaps!r}")
    if op_range is not None:
        op_range = _check_range(op_range, "op_range", "--op-range", src)
    if mv_range is not None:
        mv_range = _check_range(mv_range, "mv_range", "--mv-range", src)

    header, rows, lines_list = _read_table(p)
    col_idx = _resolve_columns(header, columns, src)
    colname = {role: header[j] for role, j in col_idx.items()}
    roles = [r for r in ROLES if r in col_idx]
    sig_roles = [r for r in roles if r != "t"]
    lines = np.asarray(lines_list)
    repairs: list[str] = []

    def where(role: str) -> str:
        return f"{src}: column {colname[role]!r} ({role})"

    # ---- parse cells ---------------------------------------------------
    cells = {r: [row[col_idx[r]] for row in rows] for r in roles}
    vals: dict[str, np.ndarray] = {}
    for r in sig_roles:
        v, bad = _parse_numbers(cells[r])
        if bad:
            ex = cells[r][bad[0]].strip()
            raise RecordingError(
                f"{where(r)}: {len(bad)} non-numeric cell(s) at line(s) "
                f"{_fmt_lines(lines[bad].tolist())} (e.g. {ex!r}); fix or blank those cells "
                f"(blank cells count as missing values; use '.' as the decimal point)"
            )
        if np.isnan(v).all():
            raise RecordingError(
                f"{where(r)}: has no numeric values at all; map the {_ROLE_WORDS[r]} to another column"
                + (f" or switch it off with columns={{'{r}': None}}" if r not in _REQUIRED else "")
            )
        vals[r] = v

    t, bad = _parse_numbers(cells["t"])
    start: str | None = None
    if bad:
        present = [i for i, c in enumerate(cells["t"]) if c.strip().lower() not in _MISSING_TOKENS]
        if len(bad) == len(present):
            t, bad_dt = _parse_datetimes(cells["t"], present)
            if -1 in bad_dt:
                raise RecordingError(
                    f"{where('t')}: mixes time stamps with and without a time zone; "
                    f"write all of them the same way"
                )
            if bad_dt:
                ex = cells["t"][bad_dt[0]].strip()
                raise RecordingError(
                    f"{where('t')}: {len(bad_dt)} cell(s) are neither numbers (seconds) nor ISO date "
                    f"strings, at line(s) {_fmt_lines(lines[bad_dt].tolist())} (e.g. {ex!r}); "
                    f"fix those cells (e.g. 2024-11-21 00:01:00)"
                )
            start = cells["t"][present[0]].strip()
            t = t - t[present[0]]
        else:
            ex = cells["t"][bad[0]].strip()
            raise RecordingError(
                f"{where('t')}: {len(bad)} non-numeric cell(s) at line(s) "
                f"{_fmt_lines(lines[bad].tolist())} (e.g. {ex!r}); the time column must hold "
                f"seconds or ISO date strings throughout; fix those cells"
            )
    is_dates = start is not None
    epoch0 = None
    if is_dates:
        _e, _ = _parse_datetimes([start], [0])
        epoch0 = float(_e[0])

    def fmt_t(x: float) -> str:
        """A time for messages: seconds, plus the date for date-stamped files."""
        s_ = f"t={x:g} s"
        if epoch0 is not None and math.isfinite(epoch0):
            s_ += " (" + datetime.fromtimestamp(epoch0 + x, timezone.utc).strftime("%Y-%m-%d %H:%M:%S") + ")"
        return s_
    miss_t = np.flatnonzero(np.isnan(t))
    if miss_t.size:
        raise RecordingError(
            f"{where('t')}: {miss_t.size} missing time stamp(s) at line(s) "
            f"{_fmt_lines(lines[miss_t].tolist())}; fill them in or delete those rows"
        )
    if len(t) < MIN_SAMPLES:
        raise RecordingError(
            f"{src}: only {len(t)} data rows; a recording needs at least {MIN_SAMPLES} samples "
            f"to identify anything; use a longer record"
        )

    # ---- time order and duplicates ------------------------------------
    d = np.diff(t)
    dec = np.flatnonzero(d < 0)
    if dec.size:
        hint = (
            "the file is in descending time order; sort it by time, oldest first"
            if dec.size == d.size
            else "sort the file by time or remove the out-of-order rows"
        )
        if is_dates and dec.size < d.size:
            hint += " (with local-time stamps this can be a daylight-saving change)"
        ex = [f"line {lines[i + 1]} ({cells['t'][i].strip()} -> {cells['t'][i + 1].strip()})" for i in dec[:3]]
        raise RecordingError(
            f"{where('t')}: time stamps decrease {dec.size} time(s), first at {'; '.join(ex)}; {hint}"
        )
    dup = np.flatnonzero(d == 0)
    if dup.size:
        same = np.ones(dup.size, dtype=bool)
        for r in sig_roles:
            a, b = vals[r][dup], vals[r][dup + 1]
            same &= (a == b) | (np.isnan(a) & np.isnan(b))
        if not same.all():
            k = dup[~same]
            ex = ", ".join(f"lines {lines[i]} and {lines[i + 1]}" for i in k[:3])
            raise RecordingError(
                f"{where('t')}: {k.size} duplicate time stamp(s) with different values ({ex}); "
                f"remove one row of each pair"
            )
        keep = np.ones(len(t), dtype=bool)
        keep[dup + 1] = False
        repairs.append(
            f"dropped {dup.size} exact duplicate row(s) (same time stamp and values) at line(s) "
            f"{_fmt_lines(lines[dup + 1].tolist())}"
        )
        t, lines = t[keep], lines[keep]
        vals = {r: v[keep] for r, v in vals.items()}
        d = np.diff(t)
        if len(t) < MIN_SAMPLES:
            raise RecordingError(
                f"{src}: only {len(t)} samples after dropping duplicate rows; a recording needs at "
                f"least {MIN_SAMPLES}; use a longer record"
            )

    # ---- uniform grid -------------------------------------------------
    dt = float(np.median(d))
    step_gap = d > _GAP_FACTOR * dt
    normal = d[~step_gap]
    jitter = float(np.max(np.abs(normal - dt)) / dt) if normal.size else 0.0
    t0 = float(t[0])
    m = int(math.floor((t[-1] - t0) / dt + 1e-6)) + 1
    grid = t0 + dt * np.arange(m)
    uniform = (not step_gap.any()) and jitter <= _UNIFORM_RTOL
    if uniform:
        dt_fit = (float(t[-1]) - t0) / (len(t) - 1)
        dev = float(np.max(np.abs(t - (t0 + dt_fit * np.arange(len(t))))))
        uniform = dev <= _UNIFORM_RTOL * dt_fit
        if uniform:
            dt = dt_fit
            grid = t0 + dt * np.arange(len(t))
    row_missing = np.zeros(len(grid), dtype=bool)
    if not uniform:
        if jitter >= _SMALL_JITTER and resample is False:
            rng = f"{normal.min():g} to {normal.max():g} s" if normal.size else "-"
            raise RecordingError(
                f"{where('t')}: irregular sampling (steps {rng}, median {dt:g} s, jitter "
                f"{100 * jitter:.0f} % of the median step); pass resample='auto' to resample onto "
                f"a uniform {dt:g} s grid, or give a uniformly sampled file"
            )
        off_grid = np.abs(d[step_gap] / dt - np.round(d[step_gap] / dt)) > _UNIFORM_RTOL
        if jitter > _UNIFORM_RTOL or off_grid.any() or not step_gap.any():
            kind = "small time-stamp jitter" if jitter < _SMALL_JITTER else "irregular sampling"
            repairs.append(
                f"resampled onto a uniform grid dt={dt:g} s ({kind}: steps deviate up to "
                f"{100 * jitter:.3g} % of dt); pv/sp/mv linearly interpolated, op zero-order hold"
            )
        for i in np.flatnonzero(step_gap):
            k = int(round(d[i] / dt)) - 1
            repairs.append(
                f"time stamps jump from t={t[i]:g} s to t={t[i + 1]:g} s (line {lines[i + 1]}): "
                f"{k} missing sample(s) inserted as missing values"
            )
        resampled = {
            r: _resample(t, v, grid, dt, hold=(r == "op")) for r, v in vals.items()
        }
        row_missing = np.isnan(_resample(t, np.zeros_like(t), grid, dt, hold=True))
        vals = resampled
        t = grid

    # ---- missing values --------------------------------------------------
    miss = {r: np.isnan(v) for r, v in vals.items()}

    def trim_edges(t, vals, miss, row_missing, note_prefix=""):
        any_miss = np.zeros(len(t), dtype=bool)
        for mk in miss.values():
            any_miss |= mk
        ok = np.flatnonzero(~any_miss)
        if ok.size == 0:
            raise RecordingError(
                f"{src}: no sample has all of {', '.join(colname[r] for r in sig_roles)} present; "
                f"check the column mapping"
            )
        a, b = int(ok[0]), int(ok[-1]) + 1
        for lo_, hi_, label in ((0, a, "leading"), (b, len(t), "trailing")):
            if hi_ > lo_:
                which = [colname[r] for r in sig_roles if miss[r][lo_:hi_].any()]
                repairs.append(
                    f"{note_prefix}dropped {hi_ - lo_} {label} sample(s) (t={t[lo_]:g} to "
                    f"{t[hi_ - 1]:g} s) with missing values in {', '.join(which)}"
                )
        sl = slice(a, b)
        return (t[sl], {r: v[sl] for r, v in vals.items()},
                {r: mk[sl] for r, mk in miss.items()}, row_missing[sl])

    t, vals, miss, row_missing = trim_edges(t, vals, miss, row_missing)

    long_rows = np.zeros(len(t), dtype=bool)
    long_desc: dict[tuple[int, int], list[str]] = {}
    for r in sig_roles:
        for s0, s1 in _runs(miss[r]):
            if s1 - s0 > max_gap:
                long_rows[s0:s1] = True
                long_desc.setdefault((s0, s1), []).append(r)
    if long_desc:
        if gaps == "error":
            parts = []
            for (s0, s1), rs in sorted(long_desc.items())[:3]:
                span = f"{s1 - s0} missing samples between {fmt_t(t[s0 - 1])} and {fmt_t(t[s1])}"
                if row_missing[s0:s1].all():
                    parts.append(f"{span}: no rows in the file")
                else:
                    parts.append(f"{span} in " + ", ".join(f"{colname[r]!r} ({r})" for r in rs))
            more = f" and {len(long_desc) - 3} more" if len(long_desc) > 3 else ""
            raise RecordingError(
                f"{src}: gap of missing values longer than max_gap={max_gap} samples: "
                f"{'; '.join(parts)}{more}; fill or cut it in the file, raise max_gap "
                f"(--max-gap), or pass gaps='longest' (--gaps longest) to keep the longest "
                f"stretch without such gaps"
            )
        segs = _runs(~long_rows)
        s0, s1 = max(segs, key=lambda s: s[1] - s[0])
        repairs.append(
            f"kept the longest stretch without long gaps: samples {s0}..{s1 - 1} "
            f"(t={t[s0]:g} to {t[s1 - 1]:g} s) of {len(t)}; {len(long_desc)} gap(s) longer than "
            f"max_gap={max_gap} samples cut off"
        )
        sl = slice(s0, s1)
        t, vals, miss, row_missing = trim_edges(
            t[sl], {r: v[sl] for r, v in vals.items()}, {r: mk[sl] for r, mk in miss.items()},
            row_missing[sl], note_prefix="then ",
        )
    idx = np.arange(len(t), dtype=float)
    for r in sig_roles:
        runs = _runs(miss[r])
        if not runs:
            continue
        good = ~miss[r]
        v = vals[r].copy()
        v[miss[r]] = np.interp(idx[miss[r]], idx[good], v[good])
        vals[r] = v
        nmiss = int(miss[r].sum())
        spans = ", ".join(f"t={t[s0]:g}" + (f"-{t[s1 - 1]:g}" if s1 - s0 > 1 else "") for s0, s1 in runs[:5])
        if len(runs) > 5:
            spans += f", ... ({len(runs)} gaps)"
        repairs.append(
            f"filled {nmiss} missing value(s) in {colname[r]!r} ({r}) by linear interpolation "
            f"(gaps <= {max_gap} samples at {spans} s)"
        )

    if len(t) < MIN_SAMPLES:
        raise RecordingError(
            f"{src}: only {len(t)} usable samples after repairs ({'; '.join(repairs) or 'none'}); "
            f"a recording needs at least {MIN_SAMPLES}; use a longer record"
        )

    # ---- ranges and normalisation --------------------------------------
    op_raw = vals["op"]
    if op_range is None:
        lo_v, hi_v = float(op_raw.min()), float(op_raw.max())
        if lo_v < 0.0 or hi_v > 1.0:
            raise RecordingError(
                f"{where('op')}: values span {lo_v:g}..{hi_v:g}, outside 0..1, so the controller "
                f"output's range must be given: pass --op-range LO,HI (op_range=(LO, HI)), "
                f"e.g. --op-range 0,100 for percent"
            )
        op_range = (0.0, 1.0)
    op = _normalise(op_raw, op_range, "op", where("op"), "--op-range", repairs, colname["op"])
    mv = None
    if "mv" in vals:
        mvr = mv_range if mv_range is not None else op_range
        mv = _normalise(vals["mv"], mvr, "mv", where("mv"), "--mv-range", repairs, colname["mv"])

    for r in ("op", "pv"):
        x = vals[r]
        span = float(np.ptp(x))
        if span <= 1e-12 * max(float(np.max(np.abs(x))), 1e-300):
            raise RecordingError(
                f"{where(r)}: the {_ROLE_WORDS[r]} is constant ({float(x[0]):g}) over the whole "
                f"record, so there is nothing to identify; use a stretch where it moves or check "
                f"the column mapping"
            )

    return Recording(
        t=t,
        op=op,
        pv=vals["pv"],
        sp=vals.get("sp"),
        mv=mv,
        dt=dt,
        name=name if name is not None else p.stem,
        op_range=op_range,
        repairs=tuple(repairs),
        columns=colname,
        start=start,
    )


def _check_range(rng: Any, what: str, flag: str, src: str) -> tuple[float, float]:
    if isinstance(rng, str):
        return parse_range(rng)
    try:
        lo, hi = (float(v) for v in rng)
    except (TypeError, ValueError):
        raise RecordingError(
            f"{src}: {what} must be two numbers (LO, HI), got {rng!r}; e.g. {flag} 0,100"
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise RecordingError(f"{src}: {what} must be finite with LO < HI, got {rng!r}; e.g. {flag} 0,100")
    return (lo, hi)


def _normalise(
    x: np.ndarray, rng: tuple[float, float], role: str, where: str, flag: str,
    repairs: list[str], col: str,
) -> np.ndarray:
    lo, hi = rng
    span = hi - lo
    tol = _RANGE_TOLERANCE * span
    below, above = x < lo, x > hi
    if (x < lo - tol).any() or (x > hi + tol).any():
        raise RecordingError(
            f"{where}: values span {x.min():g}..{x.max():g}, more than 5 % of the span outside "
            f"the range {lo:g}..{hi:g}; pass the right range with {flag} LO,HI, or check that "
            f"the column holds the {_ROLE_WORDS[role]}"
        )
    if below.any() or above.any():
        repairs.append(
            f"clipped {int(below.sum() + above.sum())} value(s) of {col!r} ({role}) slightly outside "
            f"{lo:g}..{hi:g} (min {x.min():g}, max {x.max():g}) to the range"
        )
        x = np.clip(x, lo, hi)
    return np.clip((x - lo) / span, 0.0, 1.0)
