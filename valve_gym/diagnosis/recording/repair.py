"""Repairs of a recording's time axis and missing values, each stated in ``repairs``.

* :func:`drop_duplicates` drops exact duplicate rows (duplicate time stamps
  with different values are an error);
* :func:`regrid` puts the samples on a uniform grid of the median step:
  small jitter (and, with ``resample='auto'``, larger irregularity) is
  resampled (op by zero-order hold, the other signals linearly); a step
  longer than :data:`GAP_FACTOR` median steps counts as missing samples;
* :func:`fill_gaps` drops missing values at the start and end, fills runs of
  at most ``max_gap`` missing samples by linear interpolation, and either
  reports longer runs or keeps the longest stretch without them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ._base import MIN_SAMPLES, RecordingError, fmt_lines
from .parse import Parsed
from .validate import LoadOptions

__all__ = ["GAP_FACTOR", "SMALL_JITTER", "Grid", "drop_duplicates", "fill_gaps", "regrid", "runs"]

#: Jitter (fraction of the median step) below which resampling is always done.
SMALL_JITTER = 0.10

#: A step longer than this many median steps counts as missing samples.
GAP_FACTOR = 1.5

_UNIFORM_RTOL = 1e-6

# A grid more than this many times longer than the number of rows (plus a
# margin) is made of gaps: the time axis is cut before the grid is built.
_GRID_BLOWUP = 4


@dataclass(frozen=True)
class Grid:
    """Samples on a uniform time grid, possibly with missing values.

    Attributes
    ----------
    t : ndarray, shape (m,), float64
        Grid times [s].
    dt : float
        Grid step [s].
    values : dict of str to ndarray, shape (m,), float64
        Signal role to values, NaN where missing.
    row_missing : ndarray, shape (m,), bool
        True where the file has no row for the grid point.
    """

    t: np.ndarray
    dt: float
    values: dict[str, np.ndarray]
    row_missing: np.ndarray


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of the runs of True in a boolean array."""
    if not mask.any():
        return []
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def drop_duplicates(p: Parsed, repairs: list[str]) -> Parsed:
    """Drop rows that repeat the previous row's time stamp and values.

    Parameters
    ----------
    p : Parsed
        Time stamps present and non-decreasing.
    repairs : list of str
        Appended to.

    Returns
    -------
    Parsed

    Raises
    ------
    RecordingError
        Duplicate time stamps with different values; too few rows left.
    """
    d = np.diff(p.t)
    dup = np.flatnonzero(d == 0)
    if not dup.size:
        return p
    same = np.ones(dup.size, dtype=bool)
    for v in p.values.values():
        a, b = v[dup], v[dup + 1]
        same &= (a == b) | (np.isnan(a) & np.isnan(b))
    if not same.all():
        k = dup[~same]
        ex = ", ".join(f"{p.unit}s {p.lines[i]} and {p.lines[i + 1]}" for i in k[:3])
        raise RecordingError(
            f"{p.where('t')}: {k.size} duplicate time stamp(s) with different values ({ex}); "
            f"remove one row of each pair"
        )
    keep = np.ones(len(p.t), dtype=bool)
    keep[dup + 1] = False
    repairs.append(
        f"dropped {dup.size} exact duplicate row(s) (same time stamp and values) at {p.unit}(s) "
        f"{fmt_lines(p.lines[dup + 1].tolist())}"
    )
    pos = np.cumsum(keep) - 1
    out = replace(
        p, t=p.t[keep], lines=p.lines[keep], values={r: v[keep] for r, v in p.values.items()},
        t_text=None if p.t_text is None else p.t_text[keep],
        nonfinite={r: np.unique(pos[i]) for r, i in p.nonfinite.items()},
    )
    if len(out.t) < MIN_SAMPLES:
        raise RecordingError(
            f"{p.src}: only {len(out.t)} samples after dropping duplicate rows; a recording needs at "
            f"least {MIN_SAMPLES}; use a longer record"
        )
    return out


def _resample(t: np.ndarray, x: np.ndarray, grid: np.ndarray, dt: float, hold: bool) -> np.ndarray:
    """Values of x on grid (NaN where unknown): linear or zero-order hold.

    Grid points within a tiny tolerance of a sample take its value exactly; a
    grid point inside a step longer than GAP_FACTOR * dt is unknown.
    """
    tol = _UNIFORM_RTOL * dt
    j = np.searchsorted(t, grid + tol, side="right") - 1
    j = np.clip(j, 0, len(t) - 1)
    exact = np.abs(grid - t[j]) <= tol
    jn = np.minimum(j + 1, len(t) - 1)
    step = t[jn] - t[j]
    in_gap = ~exact & (step > GAP_FACTOR * dt)
    if hold:
        y = x[j].copy()
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(step > 0, (grid - t[j]) / np.where(step > 0, step, 1.0), 0.0)
            y = np.where(exact, x[j], x[j] + w * (x[jn] - x[j]))
    y[in_gap] = np.nan
    return y


def _cut_blowup(p: Parsed, opts: LoadOptions, dt: float, repairs: list[str]) -> Parsed:
    """Cut the rows at jumps of the time stamps that would make a grid mostly of gaps."""
    d = np.diff(p.t)
    m = (p.t[-1] - p.t[0]) / dt + 1
    if m <= _GRID_BLOWUP * len(p.t) + 10_000:
        return p
    jumps = np.flatnonzero(d > (opts.max_gap + GAP_FACTOR) * dt)
    if opts.gaps == "error":
        parts = [f"{p.unit} {p.lines[i + 1]}: t={p.t[i]:g} s to t={p.t[i + 1]:g} s, {d[i] / dt - 1:.4g} "
                 f"missing samples of dt={dt:g} s" for i in jumps[np.argsort(d[jumps])[::-1][:3]]]
        raise RecordingError(
            f"{p.where('t')}: the time stamps jump so far that the record would be mostly gaps "
            f"({len(p.t)} rows over {m:.4g} samples of dt={dt:g} s); largest jump(s) at {'; '.join(parts)}; "
            f"check the time column, cut the file, or pass gaps='longest' (--gaps longest)"
        )
    bounds = np.concatenate(([0], jumps + 1, [len(p.t)]))
    k = int(np.argmax(np.diff(bounds)))
    a, b = int(bounds[k]), int(bounds[k + 1])
    repairs.append(
        f"kept the longest stretch without long gaps: {p.unit}s {p.lines[a]}..{p.lines[b - 1]} "
        f"(t={p.t[a]:g} to {p.t[b - 1]:g} s) of {len(p.t)} rows; {jumps.size} jump(s) of the time "
        f"stamps longer than max_gap={opts.max_gap} samples cut off"
    )
    sl = slice(a, b)
    return replace(p, t=p.t[sl], lines=p.lines[sl], values={r: v[sl] for r, v in p.values.items()},
                   t_text=None if p.t_text is None else p.t_text[sl])


def regrid(p: Parsed, opts: LoadOptions, repairs: list[str]) -> tuple[Parsed, Grid]:
    """Put the samples on a uniform grid of the median time step.

    Parameters
    ----------
    p : Parsed
        Time stamps present, increasing (after :func:`drop_duplicates`).
    opts : LoadOptions
    repairs : list of str
        Appended to.

    Returns
    -------
    Parsed
        The rows used (cut at huge jumps with ``gaps='longest'``).
    Grid

    Raises
    ------
    RecordingError
        Irregular sampling with ``resample=False``; jumps of the time stamps
        so large that the grid would be mostly gaps (with ``gaps='error'``).
    """
    dt = float(np.median(np.diff(p.t)))
    if not (math.isfinite(dt) and dt > 0):
        raise RecordingError(f"{p.where('t')}: the median time step is {dt:g} s; time stamps must increase")
    p = _cut_blowup(p, opts, dt, repairs)
    t, vals = p.t, p.values
    if len(t) < MIN_SAMPLES:
        raise RecordingError(f"{p.src}: only {len(t)} rows in the longest stretch; a recording needs at "
                             f"least {MIN_SAMPLES}; use a longer record")
    d = np.diff(t)
    dt = float(np.median(d))
    step_gap = d > GAP_FACTOR * dt
    normal = d[~step_gap]
    jitter = float(np.max(np.abs(normal - dt)) / dt) if normal.size else 0.0
    t0 = float(t[0])
    if (not step_gap.any()) and jitter <= _UNIFORM_RTOL:
        dt_fit = (float(t[-1]) - t0) / (len(t) - 1)
        dev = float(np.max(np.abs(t - (t0 + dt_fit * np.arange(len(t))))))
        if dev <= _UNIFORM_RTOL * dt_fit:
            grid = t0 + dt_fit * np.arange(len(t))
            return p, Grid(grid, dt_fit, dict(vals), np.zeros(len(t), dtype=bool))
    if jitter >= SMALL_JITTER and opts.resample is False:
        rng = f"{normal.min():g} to {normal.max():g} s" if normal.size else "-"
        raise RecordingError(
            f"{p.where('t')}: irregular sampling (steps {rng}, median {dt:g} s, jitter "
            f"{100 * jitter:.0f} % of the median step); pass resample='auto' to resample onto "
            f"a uniform {dt:g} s grid, or give a uniformly sampled file"
        )
    m = int(math.floor((t[-1] - t0) / dt + 1e-6)) + 1
    grid = t0 + dt * np.arange(m)
    off_grid = np.abs(d[step_gap] / dt - np.round(d[step_gap] / dt)) > _UNIFORM_RTOL
    if jitter > _UNIFORM_RTOL or off_grid.any() or not step_gap.any():
        kind = "small time-stamp jitter" if jitter < SMALL_JITTER else "irregular sampling"
        repairs.append(
            f"resampled onto a uniform grid dt={dt:g} s ({kind}: steps deviate up to "
            f"{100 * jitter:.3g} % of dt); pv/sp/mv linearly interpolated, op zero-order hold"
        )
    for i in np.flatnonzero(step_gap)[:20]:
        k = int(np.round(d[i] / dt)) - 1
        repairs.append(
            f"time stamps jump from t={t[i]:g} s to t={t[i + 1]:g} s ({p.unit} {p.lines[i + 1]}): "
            f"{k} missing sample(s) inserted as missing values"
        )
    if step_gap.sum() > 20:
        repairs.append(f"... {int(step_gap.sum()) - 20} more jump(s) of the time stamps treated the same way")
    values = {r: _resample(t, v, grid, dt, hold=(r == "op")) for r, v in vals.items()}
    row_missing = np.isnan(_resample(t, np.zeros_like(t), grid, dt, hold=True))
    return p, Grid(grid, dt, values, row_missing)


def _trim_edges(g: Grid, names: dict[str, str], src: str, repairs: list[str], prefix: str = "") -> Grid:
    """Drop leading and trailing samples with a missing value in any signal."""
    any_miss = np.zeros(len(g.t), dtype=bool)
    for v in g.values.values():
        any_miss |= np.isnan(v)
    ok = np.flatnonzero(~any_miss)
    if ok.size == 0:
        empty = [f"{names[r]!r} ({r})" for r, v in g.values.items() if np.isnan(v).all()]
        if empty:
            raise RecordingError(
                f"{src}: {', '.join(empty)} {'have' if len(empty) > 1 else 'has'} no usable value: every one "
                f"is missing, non-finite or absurd "
                f"(a magnitude beyond 1e15 is read as a historian's error code); check the column and its units"
            )
        raise RecordingError(
            f"{src}: no sample has all of {', '.join(names[r] for r in g.values)} present; "
            f"check the column mapping"
        )
    a, b = int(ok[0]), int(ok[-1]) + 1
    for lo, hi, label in ((0, a, "leading"), (b, len(g.t), "trailing")):
        if hi > lo:
            which = [names[r] for r, v in g.values.items() if np.isnan(v[lo:hi]).any()]
            repairs.append(
                f"{prefix}dropped {hi - lo} {label} sample(s) (t={g.t[lo]:g} to "
                f"{g.t[hi - 1]:g} s) with missing values in {', '.join(which)}"
            )
    return _cut(g, a, b)


def _cut(g: Grid, a: int, b: int) -> Grid:
    return Grid(g.t[a:b], g.dt, {r: v[a:b] for r, v in g.values.items()}, g.row_missing[a:b])


def _long_gaps(g: Grid, max_gap: int) -> dict[tuple[int, int], list[str]]:
    """(start, stop) of each run of more than max_gap missing samples -> the roles missing there."""
    out: dict[tuple[int, int], list[str]] = {}
    for r, v in g.values.items():
        for s0, s1 in runs(np.isnan(v)):
            if s1 - s0 > max_gap:
                out.setdefault((s0, s1), []).append(r)
    return out


def _gap_error(g: Grid, long: dict[tuple[int, int], list[str]], names: dict[str, str], src: str,
               max_gap: int, fmt_t: Callable[[float], str]) -> RecordingError:
    parts = []
    for (s0, s1), rs in sorted(long.items())[:3]:
        span = f"{s1 - s0} missing samples between {fmt_t(g.t[s0 - 1])} and {fmt_t(g.t[s1])}"
        if g.row_missing[s0:s1].all():
            parts.append(f"{span}: no rows in the file")
        else:
            parts.append(f"{span} in " + ", ".join(f"{names[r]!r} ({r})" for r in rs))
    more = f" and {len(long) - 3} more" if len(long) > 3 else ""
    return RecordingError(
        f"{src}: gap of missing values longer than max_gap={max_gap} samples: "
        f"{'; '.join(parts)}{more}; fill or cut it in the file, raise max_gap "
        f"(--max-gap), or pass gaps='longest' (--gaps longest) to keep the longest "
        f"stretch without such gaps"
    )


def fill_gaps(g: Grid, opts: LoadOptions, names: dict[str, str], src: str, repairs: list[str],
              fmt_t: Callable[[float], str]) -> Grid:
    """Trim missing edges, handle long gaps, interpolate short ones.

    Parameters
    ----------
    g : Grid
    opts : LoadOptions
        ``max_gap`` and ``gaps``.
    names : dict of str to str
        Role to column name, for messages.
    src : str
        The file, for messages.
    repairs : list of str
        Appended to.
    fmt_t : callable(float) -> str
        A time for messages.

    Returns
    -------
    Grid
        No missing values.

    Raises
    ------
    RecordingError
        No complete sample; a gap longer than ``max_gap`` with
        ``gaps='error'``; fewer than :data:`MIN_SAMPLES` samples left.
    """
    g = _trim_edges(g, names, src, repairs)
    long = _long_gaps(g, opts.max_gap)
    if long:
        if opts.gaps == "error":
            raise _gap_error(g, long, names, src, opts.max_gap, fmt_t)
        long_rows = np.zeros(len(g.t), dtype=bool)
        for s0, s1 in long:
            long_rows[s0:s1] = True
        s0, s1 = max(runs(~long_rows), key=lambda s: s[1] - s[0])
        repairs.append(
            f"kept the longest stretch without long gaps: samples {s0}..{s1 - 1} "
            f"(t={g.t[s0]:g} to {g.t[s1 - 1]:g} s) of {len(g.t)}; {len(long)} gap(s) longer than "
            f"max_gap={opts.max_gap} samples cut off"
        )
        g = _trim_edges(_cut(g, s0, s1), names, src, repairs, prefix="then ")
    idx = np.arange(len(g.t), dtype=float)
    values = dict(g.values)
    for r, v in g.values.items():
        miss = np.isnan(v)
        rr = runs(miss)
        if not rr:
            continue
        v = v.copy()
        v[miss] = np.interp(idx[miss], idx[~miss], v[~miss])
        values[r] = v
        spans = ", ".join(f"t={g.t[s0]:g}" + (f"-{g.t[s1 - 1]:g}" if s1 - s0 > 1 else "") for s0, s1 in rr[:5])
        if len(rr) > 5:
            spans += f", ... ({len(rr)} gaps)"
        repairs.append(
            f"filled {int(miss.sum())} missing value(s) in {names[r]!r} ({r}) by linear interpolation "
            f"(gaps <= {opts.max_gap} samples at {spans} s)"
        )
    if len(g.t) < MIN_SAMPLES:
        raise RecordingError(
            f"{src}: only {len(g.t)} usable samples after repairs ({'; '.join(repairs) or 'none'}); "
            f"a recording needs at least {MIN_SAMPLES}; use a longer record"
        )
    return Grid(g.t, g.dt, values, g.row_missing)
