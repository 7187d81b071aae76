"""Validation of a recording's values: options, time axis, absurd values, ranges.

Every check either passes, or raises :class:`RecordingError` with a message
naming the file, the column, the lines or times and what to do; the only
changes made here are listed repairs (absurd values made missing, op values a
hair outside the range clipped).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ._base import MIN_SAMPLES, ROLE_WORDS, RecordingError
from .parse import Parsed

__all__ = [
    "ABSURD_ABS",
    "ABSURD_REL",
    "LoadOptions",
    "RANGE_TOLERANCE",
    "SPIKE_SAMPLES",
    "check_constant",
    "check_options",
    "check_range",
    "check_time_order",
    "mark_absurd",
    "normalise",
    "parse_range",
]

#: Relative out-of-range tolerance (fraction of the span) clipped as a repair;
#: beyond it a value is an error.
RANGE_TOLERANCE = 0.05

#: A value of larger magnitude is absurd for any process signal (historian
#: error codes such as 1e30 or 3.4e38, overflowed conversions).
ABSURD_ABS = 1e15

#: An isolated spike (at most :data:`SPIKE_SAMPLES` samples in a row) further
#: from the column's median than this many times the column's typical size
#: (the larger of its interquartile range and its median's magnitude, when
#: that is not zero) is absurd.
ABSURD_REL = 1e6

#: Longest run of samples counted as a spike by the relative rule.
SPIKE_SAMPLES = 3


@dataclass(frozen=True)
class LoadOptions:
    """Checked options of :func:`load_recording` (see there for their meaning)."""

    max_gap: int
    resample: bool | str
    gaps: str
    op_range: tuple[float, float] | None
    mv_range: tuple[float, float] | None
    max_samples: int | None
    engine: str


def parse_range(text: str, flag: str = "--op-range") -> tuple[float, float]:
    """Parse a range ``"LO,HI"`` such as ``"0,100"``.

    Parameters
    ----------
    text : str
        Two finite numbers separated by a comma, ``LO < HI``.
    flag : str
        The option it came from, for the message.

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
    usage = f"expected LO,HI with two numbers and LO < HI, e.g. {flag} 0,100"
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
    if not math.isfinite(hi - lo):
        raise RecordingError(f"range {text!r} is too wide to compute with: {usage}")
    return (lo, hi)


def check_range(rng: Any, what: str, flag: str, src: str) -> tuple[float, float]:
    """A ``(lo, hi)`` range given as a pair of numbers or as ``"LO,HI"``.

    Parameters
    ----------
    rng : str or pair of float
    what, flag : str
        Option name and CLI flag, for messages.
    src : str
        The file, for messages.

    Returns
    -------
    tuple of float

    Raises
    ------
    RecordingError
        Not two finite numbers with ``LO < HI``.
    """
    if isinstance(rng, str):
        return parse_range(rng)
    try:
        lo, hi = (float(v) for v in rng)
    except (TypeError, ValueError):
        raise RecordingError(
            f"{src}: {what} must be two numbers (LO, HI), got {rng!r}; e.g. {flag} 0,100"
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi and math.isfinite(hi - lo)):
        raise RecordingError(f"{src}: {what} must be finite with LO < HI, got {rng!r}; e.g. {flag} 0,100")
    return (lo, hi)


def check_options(src: str, max_gap: Any, resample: Any, gaps: Any, op_range: Any, mv_range: Any,
                  max_samples: Any, engine: Any) -> LoadOptions:
    """Check the options of :func:`load_recording`.

    Returns
    -------
    LoadOptions

    Raises
    ------
    RecordingError
        An option of the wrong type or outside its values.
    """
    from .sniff import ENGINES

    if isinstance(max_gap, bool) or not isinstance(max_gap, (int, np.integer)) or max_gap < 0:
        raise RecordingError(f"{src}: max_gap must be a whole number of samples >= 0, got {max_gap!r}")
    if resample not in ("auto", True, False):
        raise RecordingError(f"{src}: resample must be 'auto', True or False, got {resample!r}")
    if gaps not in ("error", "longest"):
        raise RecordingError(f"{src}: gaps must be 'error' or 'longest', got {gaps!r}")
    if max_samples is not None and (isinstance(max_samples, bool) or not isinstance(max_samples, (int, np.integer))
                                    or max_samples < 10 * MIN_SAMPLES):
        raise RecordingError(
            f"{src}: max_samples must be None or a whole number >= {10 * MIN_SAMPLES}, got {max_samples!r}"
        )
    if engine not in ENGINES:
        raise RecordingError(f"{src}: engine must be one of {', '.join(map(repr, ENGINES))}, got {engine!r}")
    return LoadOptions(
        max_gap=int(max_gap), resample=resample, gaps=gaps,
        op_range=None if op_range is None else check_range(op_range, "op_range", "--op-range", src),
        mv_range=None if mv_range is None else check_range(mv_range, "mv_range", "--mv-range", src),
        max_samples=None if max_samples is None else int(max_samples), engine=engine,
    )


def _t_text(p: Parsed, i: int) -> str:
    if p.t_text is not None:
        return str(p.t_text[i]).strip()
    return f"{p.t[i]:.10g}"


def check_time_order(p: Parsed) -> None:
    """Time stamps present, finite, at least :data:`MIN_SAMPLES` rows, never decreasing.

    Parameters
    ----------
    p : Parsed

    Raises
    ------
    RecordingError
        Missing or non-finite time stamps (lines named), too few rows,
        decreasing time stamps (first lines named; a file in descending
        order is told to be sorted).
    """
    where = p.where("t")
    if p.t_nonfinite.size:
        raise RecordingError(
            f"{where}: {p.t_nonfinite.size} non-finite time stamp(s) (inf or beyond the float range) at "
            f"{p.at(p.t_nonfinite)}; fix those cells or delete those rows"
        )
    miss_t = np.flatnonzero(np.isnan(p.t))
    if miss_t.size:
        raise RecordingError(
            f"{where}: {miss_t.size} missing time stamp(s) at {p.at(miss_t)}; fill them in or delete those rows"
        )
    if len(p.t) < MIN_SAMPLES:
        raise RecordingError(
            f"{p.src}: only {len(p.t)} data rows; a recording needs at least {MIN_SAMPLES} samples "
            f"to identify anything; use a longer record"
        )
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.diff(p.t)
    dec = np.flatnonzero(d < 0)
    if dec.size:
        hint = (
            "the file is in descending time order; sort it by time, oldest first"
            if dec.size == d.size
            else "sort the file by time or remove the out-of-order rows"
        )
        if p.start is not None and dec.size < d.size:
            hint += " (with local-time stamps this can be a daylight-saving change)"
        ex = [f"{p.unit} {p.lines[i + 1]} ({_t_text(p, i)} -> {_t_text(p, i + 1)})" for i in dec[:3]]
        raise RecordingError(
            f"{where}: time stamps decrease {dec.size} time(s), first at {'; '.join(ex)}; {hint}"
        )
    if not np.isfinite(d).all():
        raise RecordingError(
            f"{where}: time stamps {p.t[0]:g} to {p.t[-1]:g} span more than the float range; "
            f"check the time column (seconds or ISO dates expected)"
        )


def _absurd_mask(v: np.ndarray) -> tuple[np.ndarray, float]:
    """Absurd values of one column and the threshold distance used."""
    ok = v[np.isfinite(v)]
    if ok.size == 0:
        return np.zeros(v.shape, dtype=bool), math.inf
    mag = np.abs(ok) <= ABSURD_ABS
    base = ok[mag] if mag.any() else ok
    med = float(np.median(base))
    q25, q75 = (float(x) for x in np.percentile(base, [25.0, 75.0]))
    size = max(q75 - q25, abs(med))
    lim = ABSURD_REL * size if size > 0 else math.inf
    with np.errstate(invalid="ignore", over="ignore"):
        far = np.isfinite(v) & (np.abs(v - med) > lim)
        bad = np.isfinite(v) & (np.abs(v) > ABSURD_ABS)
    if far.any():
        d = np.diff(np.concatenate(([0], far.astype(np.int8), [0])))
        for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
            if b - a <= SPIKE_SAMPLES:
                bad[a:b] = True
    return bad, min(lim, ABSURD_ABS)


def mark_absurd(p: Parsed, repairs: list[str]) -> Parsed:
    """Non-finite and absurd values made missing, each stated in `repairs`.

    A value is absurd when its magnitude exceeds :data:`ABSURD_ABS`, or when
    it is part of a spike of at most :data:`SPIKE_SAMPLES` samples further
    than :data:`ABSURD_REL` times the column's typical size from the column's
    median.  Missing values are then filled or reported by the
    gap rules (see :func:`load_recording`'s ``max_gap``).

    Parameters
    ----------
    p : Parsed
    repairs : list of str
        Appended to.

    Returns
    -------
    Parsed
        With those values NaN.
    """
    values = dict(p.values)
    for r, v in p.values.items():
        col = p.columns.names[r]
        nf = p.nonfinite.get(r, np.empty(0, dtype=np.int64))
        if nf.size:
            repairs.append(
                f"treated {nf.size} non-finite value(s) (inf or beyond the float range) of {col!r} ({r}) "
                f"at {p.at(nf)} as missing"
            )
        bad, lim = _absurd_mask(v)
        if bad.any():
            idx = np.flatnonzero(bad)
            v = v.copy()
            ex = v[idx[0]]
            v[idx] = np.nan
            values[r] = v
            repairs.append(
                f"treated {idx.size} absurd value(s) of {col!r} ({r}) at {p.at(idx)} (e.g. {ex:g}; beyond "
                f"+-{ABSURD_ABS:g}, or a spike more than {lim:.3g} from the column's median) as missing"
            )
    return replace(p, values=values)


def normalise(x: np.ndarray, rng: tuple[float, float], role: str, where: str, flag: str,
              repairs: list[str], col: str, t: np.ndarray | None = None) -> np.ndarray:
    """Raw values mapped to 0..1 by ``(x - lo) / (hi - lo)``.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Raw values (finite).
    rng : (float, float)
        ``(lo, hi)``.
    role, where, flag, col : str
        For messages.
    repairs : list of str
        Appended to when values a hair outside the range are clipped.
    t : ndarray, shape (n,), optional
        Sample times [s], to name where values are far outside.

    Returns
    -------
    ndarray, shape (n,)
        In [0, 1].

    Raises
    ------
    RecordingError
        Values more than :data:`RANGE_TOLERANCE` of the span outside the range.
    """
    lo, hi = rng
    span = hi - lo
    tol = RANGE_TOLERANCE * span
    below, above = x < lo, x > hi
    far = (x < lo - tol) | (x > hi + tol)
    if far.any():
        idx = np.flatnonzero(far)
        at = "" if t is None else f" ({idx.size} sample(s), first at t={t[idx[0]]:g} s: {x[idx[0]]:g})"
        raise RecordingError(
            f"{where}: values span {x.min():g}..{x.max():g}, more than 5 % of the span outside "
            f"the range {lo:g}..{hi:g}{at}; pass the right range with {flag} LO,HI, or check that "
            f"the column holds the {ROLE_WORDS[role]}"
        )
    if below.any() or above.any():
        repairs.append(
            f"clipped {int(below.sum() + above.sum())} value(s) of {col!r} ({role}) slightly outside "
            f"{lo:g}..{hi:g} (min {x.min():g}, max {x.max():g}) to the range"
        )
        x = np.clip(x, lo, hi)
    with np.errstate(over="ignore", invalid="ignore"):
        return np.clip((x - lo) / span, 0.0, 1.0)


def check_constant(x: np.ndarray, role: str, where: str) -> None:
    """Raise if a signal does not move over the whole record.

    Parameters
    ----------
    x : ndarray, shape (n,)
    role, where : str
        For the message.

    Raises
    ------
    RecordingError
        If ``max(x) - min(x)`` is zero or below 1e-12 of its magnitude.
    """
    with np.errstate(over="ignore"):
        span = float(np.ptp(x))
    if span <= 1e-12 * max(float(np.max(np.abs(x))), 1e-300):
        raise RecordingError(
            f"{where}: the {ROLE_WORDS[role]} is constant ({float(x[0]):g}) over the whole "
            f"record, so there is nothing to identify; use a stretch where it moves or check "
            f"the column mapping"
        )
