"""Validation of a recording's values: options, time axis, absurd values, ranges.

Every check either passes, or raises :class:`RecordingError` with a message
naming the file, the column, the lines or times and what to do; the only
changes made here are listed repairs (absurd values made missing, op values a
hair outside the range clipped).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ._base import MIN_SAMPLES, ROLE_WORDS, RecordingError
from .parse import Parsed

__all__ = [
    "ABSURD_ABS",
    "ABSURD_REL",
    "DST_BACK",
    "LoadOptions",
    "RANGE_TOLERANCE",
    "KNOWN_CODES",
    "SENTINEL_FRACTION",
    "SENTINEL_MIN_SPAN",
    "SENTINEL_PERCENTILES",
    "SENTINEL_REL",
    "SPIKE_SAMPLES",
    "check_constant",
    "check_increasing",
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

#: Longest run of samples counted as a spike by the relative rules.
SPIKE_SAMPLES = 3

#: An isolated spike (at most :data:`SPIKE_SAMPLES` samples in a row) lying further outside the range of
#: the column's other values than this many times their span is a historian's bad-value code (-9999,
#: 9999, -999, -1e30 in a signal of a few units); see :data:`SENTINEL_FRACTION`.  A real excursion of a
#: process signal is a few times its normal span at most.
SENTINEL_REL = 20.0

#: The bad-value rule of :data:`SENTINEL_REL` reads at most this fraction of a column's values (at least
#: one) at either end of its value range as bad-value codes; the range of the other values is taken
#: between their 0.1 and 99.9 percentiles (:data:`SENTINEL_PERCENTILES`).  A code in more rows than
#: that is part of the column's range and is not repaired.
SENTINEL_FRACTION = 0.01

#: Percentiles of the other values that bound their range for :data:`SENTINEL_REL`.
SENTINEL_PERCENTILES = (0.1, 99.9)

#: Bad-value codes historians write in place of a value (an outage, a failed transmitter, an unset
#: point): read as missing in runs of any length, wherever the column's other values lie more than
#: :data:`SENTINEL_REL` times their span away from the code (never inside an output's declared range).
#: A run longer than ``max_gap`` is then a gap the loader refuses or, with ``gaps='longest'``, avoids.
KNOWN_CODES = (-9999.0, 9999.0, -99999.0, 99999.0, -999999.0, 999999.0, -999.0, -32768.0, 32767.0, 65535.0)

#: A step back of the time stamps within these bounds [s] is named a daylight-saving fall-back (a local
#: clock repeats an hour, or half an hour in a few zones), less the scan.
DST_BACK = (1200.0, 3700.0)

#: The span of the other values is taken as at least this fraction of their magnitude, so that a
#: column that is nearly constant (a set point) keeps its rare real steps.
SENTINEL_MIN_SPAN = 0.01


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
        return parse_range(rng, flag)
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


def check_increasing(t: np.ndarray, where: str, row: Callable[[int], str], text: Callable[[int], str],
                     dated: bool) -> None:
    """Refuse time stamps that decrease (in the order of the file).

    A file of local-time stamps goes back an hour at the daylight-saving fall-back (the clock repeats
    an hour); sorting it would interleave the two hours, so the message asks for stamps in UTC or with
    their UTC offset instead.  Used by :func:`check_time_order` and by fleet mode's wide exports.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Time stamps [s], finite, in the order of the file.
    where : str
        The file and column, the start of the message.
    row, text : callable(int) -> str
        Sample ``i``'s place in the file (``"line 7"``, ``"row 5"``) and its time stamp as written.
    dated : bool
        The stamps are dates (possibly local time), not seconds.

    Raises
    ------
    RecordingError
        A stamp earlier than the one before it: the first three places named, with the stamps.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.diff(t)
    dec = np.flatnonzero(d < 0)
    if not dec.size:
        return
    hint = (
        "the file is in descending time order; sort it by time, oldest first"
        if dec.size == d.size
        else "sort the file by time or remove the out-of-order rows"
    )
    back = float(-d[dec[0]])
    if dated and dec.size < d.size and DST_BACK[0] <= back <= DST_BACK[1]:
        hint = (f"the clock goes back {back:g} s: with local-time stamps that is most likely the daylight-saving "
                f"fall-back (the clock repeats an hour); export the time stamps in UTC or with their UTC offset (e.g. "
                f"2024-10-27 02:30:00+01:00), since sorting would interleave the repeated stretch; otherwise "
                f"{hint}")
    elif dated and dec.size < d.size:
        hint += " (with local-time stamps this can be a daylight-saving change)"
    ex = [f"{row(i + 1)} ({text(i)} -> {text(i + 1)})" for i in dec[:3]]
    raise RecordingError(f"{where}: time stamps decrease {dec.size} time(s), first at {'; '.join(ex)}; {hint}")


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
    check_increasing(p.t, where, lambda i: f"{p.unit} {p.lines[i]}", lambda i: _t_text(p, i), p.start is not None)
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.diff(p.t)
    if not np.isfinite(d).all():
        raise RecordingError(
            f"{where}: time stamps {p.t[0]:g} to {p.t[-1]:g} span more than the float range; "
            f"check the time column (seconds or ISO dates expected)"
        )


def _spikes(far: np.ndarray) -> np.ndarray:
    """The samples of `far` in runs of at most :data:`SPIKE_SAMPLES` samples."""
    out = np.zeros(far.shape, dtype=bool)
    d = np.diff(np.concatenate(([0], far.astype(np.int8), [0])))
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        if b - a <= SPIKE_SAMPLES:
            out[a:b] = True
    return out


def _absurd_mask(v: np.ndarray, valid: tuple[float, float] | None = None) -> tuple[np.ndarray, str]:
    """Absurd values of one column, and the rules that found them, in words (empty when none).

    ``valid``: the column's declared range (the controller output's ``op_range``); a value inside
    it is never read as a bad-value code (an output that saturates for a sample or two is data).
    """
    ok = v[np.isfinite(v)]
    bad = np.zeros(v.shape, dtype=bool)
    if ok.size == 0:
        return bad, ""
    fin = np.isfinite(v)
    with np.errstate(invalid="ignore", over="ignore"):
        huge = fin & (np.abs(v) > ABSURD_ABS)
    mag = (np.abs(ok) <= ABSURD_ABS) & ~np.isin(ok, KNOWN_CODES)
    base = ok[mag] if mag.any() else ok
    # relative rule: a spike a million times the column's typical size from its median
    med = float(np.median(base))
    q25, q75 = (float(x) for x in np.percentile(base, [25.0, 75.0]))
    size = max(q75 - q25, abs(med))
    lim = ABSURD_REL * size if size > 0 else math.inf
    with np.errstate(invalid="ignore", over="ignore"):
        spike = _spikes(fin & (np.abs(v - med) > lim))
    # bad-value codes: values far outside the range of the others (never inside a declared range)
    far = np.zeros(v.shape, dtype=bool)
    few = False
    k = max(1, int(SENTINEL_FRACTION * base.size))
    rest = np.sort(base)[k:base.size - k]
    rng = ""
    if rest.size >= 10:
        lo, hi = (float(x) for x in np.percentile(rest, SENTINEL_PERCENTILES))
        span = max(hi - lo, SENTINEL_MIN_SPAN * max(abs(lo), abs(hi)))
        if span > 0 and math.isfinite(span):
            with np.errstate(invalid="ignore", over="ignore"):
                far = fin & ~huge & ((v < lo - SENTINEL_REL * span) | (v > hi + SENTINEL_REL * span))
            if valid is not None:
                far &= ~((v >= valid[0]) & (v <= valid[1]))
            few = (far & (v < lo)).sum() <= k and (far & (v > hi)).sum() <= k
            rng = f"{lo:.4g}..{hi:.4g}"
    known = far & np.isin(v, KNOWN_CODES)          # the common codes: in runs of any length
    code = _spikes(far & ~known) if few else np.zeros(v.shape, dtype=bool)   # others: a few, isolated
    rules = []
    if huge.any():
        rules.append(f"beyond +-{ABSURD_ABS:g}")
    if (spike & ~huge).any():
        rules.append(f"an isolated spike more than {lim:.3g} from the column's median")
    if (code & ~huge & ~spike).any():
        rules.append(f"an isolated spike of at most {SPIKE_SAMPLES} samples more than {SENTINEL_REL:g} times "
                     f"the span of the other values ({rng}) outside their range")
    if (known & ~huge & ~spike & ~code).any():
        rules.append(f"a known bad-value code more than {SENTINEL_REL:g} times the span of the other values "
                     f"({rng}) outside their range")
    bad = huge | spike | code | known
    return bad, "; ".join(rules)


def mark_absurd(p: Parsed, repairs: list[str], ranges: dict[str, tuple[float, float]] | None = None) -> Parsed:
    """Non-finite and absurd values made missing, each stated in `repairs`.

    A value is absurd when its magnitude exceeds :data:`ABSURD_ABS`, or when
    it is part of a spike of at most :data:`SPIKE_SAMPLES` samples either
    further than :data:`ABSURD_REL` times the column's typical size from the
    column's median, or further outside the range of the column's other
    values than :data:`SENTINEL_REL` times their span (a historian's
    bad-value code such as -9999 in a signal of a few units; at most
    :data:`SENTINEL_FRACTION` of the values at either end).  Missing values
    are then filled or reported by the gap rules (see
    :func:`load_recording`'s ``max_gap``).

    Parameters
    ----------
    p : Parsed
    repairs : list of str
        Appended to.
    ranges : dict of role to (lo, hi), optional
        Declared ranges (``op``, ``mv``): values inside them are never read as bad-value codes.

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
        bad, why = _absurd_mask(v, (ranges or {}).get(r))
        if bad.any():
            idx = np.flatnonzero(bad)
            v = v.copy()
            seen = list(dict.fromkeys(float(x) for x in v[idx]))
            vals = ", ".join(f"{x:g}" for x in seen[:5]) + (", ..." if len(seen) > 5 else "")
            v[idx] = np.nan
            values[r] = v
            repairs.append(
                f"treated {idx.size} absurd value(s) of {col!r} ({r}) at {p.at(idx)} ({vals}) as missing, "
                f"read as a historian's bad-value code: {why}"
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
