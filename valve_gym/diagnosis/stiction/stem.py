"""Stiction read from a recorded valve position: the stem against the controller output.

Where the historian logs the valve's position (``mv``: a smart positioner's
travel feedback), the valve's friction need not be inferred through the
process: the stem either follows the controller output or it does not.
Kano et al. (2004) look for sections where the output moves while the
position stays; here the same reading is made quantitative by fitting the
two-parameter stiction models of Choudhury, Thornhill & Shah (2005) and of
Kano et al. (2004) (:func:`valve_gym.friction.choudhury.choudhury_sample`,
:func:`valve_gym.friction.kano.kano_sample`, the laws of the package's core)
from the recorded output to the recorded position, on a grid:

* the law, stick band ``S`` (0 and 40 values from 0.1 % to 30 % of the stroke),
  slip jump ``J = r S`` (``r`` 0, 0.25, 0.5, 0.75, 1), a first-order positioner
  lag (0 and ten from 0.19 to 4 samples) and the pairing of position and output
  (the position logged after the output of its row has acted, or before), with
  finer grids around the three best basins (stick-slip makes the cost rugged);
* each candidate's stem is mapped to the recorded position by least squares
  ``mv = c + b x`` (a transmitter's offset and span; ``b`` negative for a
  position read the other way round).

The verdict compares the best sticky valve with the best frictionless one
(``S = 0``, its positioner pole searched continuously): ``dBIC = n_eff ln(RSS_S / RSS_0) + 2 ln(n_eff)`` on the
effective number of samples of the residual (:func:`~valve_gym.diagnosis.fit.effective_n`).
The valve sticks when ``dBIC`` is below ``-ic_margin`` and the fitted band
reaches the band that matters in the loop (the friction verdict's rule,
``band_needed``).  90 % intervals of ``S`` and ``J`` are profile-likelihood
intervals over the grid (``n_eff ln(RSS / RSS_min) <= 2.706``), widened by
half a grid step and by the calibrated model discrepancy (:data:`DISCREPANCY_S`,
:data:`DISCREPANCY_J`).

Limits: a position sensor on the actuator reads the actuator, not the plug;
a rotary valve's shaft can wind up while the plug sticks, and the stem test
then sees less stiction than the process does.  A ``mv`` column that equals
the output (a readback of the output, common in DCS tags named like a
position) is refused; so is one that does not follow the output at all.

References
----------
.. [1] M. Kano, H. Maruta, H. Kugemoto, K. Shimizu, "Practical model and
   detection algorithm for valve stiction", IFAC DYCOPS, 2004.
.. [2] M.A.A.S. Choudhury, N.F. Thornhill, S.L. Shah, "Modelling valve
   stiction", Control Engineering Practice 13 (2005) 641-658.
"""
from __future__ import annotations

import numpy as np

from ..._numba import njit
from ...friction.choudhury import choudhury_sample
from ...friction.kano import kano_sample
from ._base import Evidence, not_applicable
from .hammerstein import NAN_SIZE, SizeEstimate

__all__ = ["stem_evidence", "stem_size", "STEM_S_GRID"]

CITE = ("Kano et al. 2004 (IFAC DYCOPS, output against position); Choudhury, Thornhill & Shah 2005, "
        "Control Engineering Practice 13, 641-658 (the stiction model fitted)")
DOC = ("stick band S (fraction of stroke) of the two-parameter stiction model fitted from the output to the "
       "recorded valve position; stiction when it beats a frictionless valve (dBIC < -margin) and S reaches "
       "the band that matters")

#: Stick bands of the grid (fractions of stroke), besides 0.
STEM_S_GRID = np.geomspace(0.001, 0.3, 40)
_J_RATIO = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
#: Positioner lags of the grid [samples]: 0 and the lags of the discrete poles 0.005 ... 0.78.
_LAG_SAMPLES = np.concatenate([[0.0], -1.0 / np.log([0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.37, 0.6, 0.78])])
_LAWS = (0, 1)                      # Choudhury's and Kano's law
_LAW_NAMES = ("Choudhury", "Kano")
_CHI2_90 = 2.706
#: Model-discrepancy factors (log scale) the profile intervals of S and J are widened by: the 90 %
#: quantiles of ``|log(estimate / true)|`` on sticky textbook loops of Choudhury, Kano and
#: force-balance valves read through a noisy transmitter, none of them scored
#: (``benchmarks/stem_verdict.py --calibrate --n 160``).  The grid fits Choudhury's and Kano's laws;
#: a force-balance stem, which slides on after it breaks away, reads through them as a smaller band.
DISCREPANCY_S = 0.86
DISCREPANCY_J = 2.77


@njit(cache=True)
def _law_step(law, u, uprev, x, us, stuck, sdir, du_old, S, J):  # pragma: no cover - compiled
    """One sample of Choudhury's (``law`` 0) or Kano's (1) stiction law; the state and the new ``x``."""
    if law == 0:
        x, us, stuck, sdir = choudhury_sample(u, uprev, x, us, stuck, sdir, S, J)
        return x, us, stuck, sdir, du_old
    return kano_sample(u, uprev, x, us, stuck, sdir, du_old, S, J)


@njit(cache=True)
def _grid_rss(op, mv, S, J, a, law):  # pragma: no cover - compiled
    """Residual sum of squares of ``mv ~ c + b x`` for each row's stem ``x``, at both pairings.

    Row ``i`` runs the stiction law ``law[i]`` (0 Choudhury, 1 Kano) with ``S[i], J[i]`` over ``op``
    and a first-order positioner with pole ``a[i]`` (:func:`_stem_into`).  Returns ``(m, 2, 3)``: for
    pairing 0 (``mv[k]`` against ``x[k]``) and 1 (``mv[k]`` against ``x[k-1]``), the RSS, ``b`` and
    ``c``, both over samples ``1..T-1``.
    """
    T = op.shape[0]
    m = S.shape[0]
    out = np.empty((m, 2, 3))
    buf = np.empty(T)
    n = T - 1.0
    sm = 0.0
    smm = 0.0
    for k in range(1, T):
        sm += mv[k]
        smm += mv[k] * mv[k]
    vm = smm - sm * sm / n
    for i in range(m):
        _stem_into(op, S[i], J[i], a[i], law[i], buf)
        for j in range(2):
            sx = 0.0
            sxx = 0.0
            sxm = 0.0
            for k in range(1, T):
                x = buf[k - j]
                sx += x
                sxx += x * x
                sxm += x * mv[k]
            vx = sxx - sx * sx / n
            cxm = sxm - sx * sm / n
            b = cxm / vx if vx > 1e-18 else 0.0
            out[i, j, 0] = max(vm - cxm * b, 0.0)
            out[i, j, 1] = b
            out[i, j, 2] = (sm - b * sx) / n
    return out


@njit(cache=True)
def _stem_into(op, S, J, a, law, y):  # pragma: no cover - compiled
    """The stem (T,) into ``y``: stiction law ``law`` with ``S, J`` over ``op``, then ``x <- a x + (1 - a) target``."""
    x = op[0]
    us = op[0]
    stuck = 0.0
    sdir = 0.0
    du_old = 0.0
    stem = op[0]
    uprev = op[0]
    for k in range(op.shape[0]):
        x, us, stuck, sdir, du_old = _law_step(law, op[k], uprev, x, us, stuck, sdir, du_old, S, J)
        uprev = op[k]
        stem = a * stem + (1.0 - a) * x
        y[k] = stem


def _stem(op, S: float, J: float, a: float, law: int = 0) -> np.ndarray:
    """The stem ``x`` (T,) of one grid row (see :func:`_grid_rss`)."""
    y = np.empty(len(op))
    _stem_into(np.ascontiguousarray(op, dtype=float), float(S), float(J), float(a), int(law), y)
    return y


def _grid():
    """Rows ``(S, J, lag in samples, law)`` of the search: the frictionless rows first."""
    rows = [(0.0, 0.0, g, 0) for g in _LAG_SAMPLES]
    rows += [(s, r * s, g, law) for law in _LAWS for s in STEM_S_GRID for r in _J_RATIO for g in _LAG_SAMPLES]
    return np.array(rows, dtype=float)


def _refuse(op, mv) -> str | None:
    """Why the position cannot be read against the output (None when it can)."""
    if mv is None:
        return "no valve position recorded (map a position column with mv=NAME)"
    if not np.isfinite(mv).all():
        return "the valve position holds non-finite values"
    if np.max(np.abs(mv - op)) < 1e-6:
        return ("the position column equals the controller output: a readback of the output, not a "
                "measured stem position")
    op_span = float(np.quantile(op, 0.98) - np.quantile(op, 0.02))
    if op_span < 0.005:
        return f"the controller output hardly moves ({100 * op_span:.2g} % of the stroke)"
    return None


def stem_evidence(op, mv, dt: float = 1.0, band_needed: float = 0.01, ic_margin: float = 2.0) -> Evidence:
    """Stiction read from the recorded valve position ``mv`` against the output ``op``.

    Parameters
    ----------
    op, mv : (T,) arrays, fractions of the stroke (0..1)
    dt : float, sample time [s] (reported lag in seconds)
    band_needed : float, the band (fraction of stroke) a stick band must reach to matter in
        this loop (the friction verdict's ``band_needed``)
    ic_margin : float, how far the criterion must fall (the selection rule's ``ic_margin``)

    Returns
    -------
    Evidence, ``value`` = fitted stick band S; ``details``: ``S``, ``S_lo``, ``S_hi``, ``J``,
    ``J_lo``, ``J_hi``, ``delta_ic``, ``n_eff``, ``lag_s`` (positioner lag), ``pairing`` (0: the
    position of a row after its output acted, 1: before), ``span``, ``offset``, ``r2``, ``law`` (0
    Choudhury, 1 Kano), ``rmse`` (fraction of stroke), ``band_needed``, ``repeats`` (share of
    samples equal to the one before: above a half, the reason warns of a historian's compression)
    """
    op = np.ascontiguousarray(op, dtype=float)
    mv = None if mv is None else np.ascontiguousarray(mv, dtype=float)
    if mv is not None and mv.shape != op.shape:
        raise ValueError(f"op and mv must have the same shape, got {op.shape} and {mv.shape}")
    why = _refuse(op, mv)
    if why is not None:
        return not_applicable("stem", CITE, why, DOC)
    assert mv is not None
    mv_span = float(np.quantile(mv, 0.98) - np.quantile(mv, 0.02))
    op_span = float(np.quantile(op, 0.98) - np.quantile(op, 0.02))
    if mv_span < max(0.001, 0.05 * op_span):
        return Evidence("stem", CITE, False, float("nan"), 0.0, "undetermined",
                        f"the valve position stays within {100 * mv_span:.2g} % of the stroke while the output "
                        f"travels {100 * op_span:.2g} %: a seized valve or a frozen position signal; check the "
                        f"valve with the loop in manual", DOC,
                        {"frozen": 1.0, "mv_span": mv_span, "op_span": op_span})
    rows = _grid()
    res = _rss(op, mv, rows)
    for S, law, lag in _basins(rows, res[:, :, 0].min(axis=1)):
        # finer grids around the best bands: stick-slip makes the cost rugged in S and J, and a
        # coarse band a few per cent off the truth can lose to a wrong basin
        fine = _fine_grid(S, law, lag)
        rows = np.vstack([rows, fine])
        res = np.concatenate([res, _rss(op, mv, fine)])
    return _verdict(op, mv, dt, rows, _pole(rows), res, band_needed, ic_margin)


def _rss(op, mv, rows) -> np.ndarray:
    """:func:`_grid_rss` of the grid ``rows``."""
    return _grid_rss(op, mv, rows[:, 0], rows[:, 1], _pole(rows), rows[:, 3].astype(np.int64))


def _basins(rows, rss_row, n: int = 3) -> list[tuple[float, int, float]]:
    """``(band, law, lag)`` of the ``n`` lowest local minima of each law's coarse profile of S."""
    out = []
    for law in _LAWS:
        mine = (rows[:, 0] > 0.0) & (rows[:, 3] == law)
        best = [np.flatnonzero(mine & (rows[:, 0] == s)) for s in STEM_S_GRID]
        best = [idx[np.argmin(rss_row[idx])] for idx in best]
        prof = rss_row[best]
        ext = np.concatenate([[np.inf], prof, [np.inf]])
        minima = [i for i in range(len(prof)) if ext[i + 1] <= ext[i] and ext[i + 1] <= ext[i + 2]]
        out += [(prof[i], float(STEM_S_GRID[i]), law, float(rows[best[i], 2])) for i in minima]
    return [(s, law, lag) for _, s, law, lag in sorted(out)[:n]]


def _pole(rows) -> np.ndarray:
    """The positioner's discrete pole ``exp(-1 / lag)`` of each row (0 without a lag)."""
    lag = rows[:, 2]
    return np.where(lag > 0.0, np.exp(-1.0 / np.maximum(lag, 1e-9)), 0.0)


def _fine_grid(S: float, law: int, lag: float) -> np.ndarray:
    """Rows of ``law`` around band ``S``: 15 bands, ``J/S`` 0 to 1.25 by 0.05, 3 lags.

    The bands lie within two coarse steps of ``S``; the lags are the grid's ``lag`` and its two
    neighbours.
    """
    step = float(STEM_S_GRID[1] / STEM_S_GRID[0])
    k = int(np.argmin(np.abs(_LAG_SAMPLES - lag)))
    lags = _LAG_SAMPLES[max(0, k - 1):k + 2]
    return np.array([(s, r * s, g, law) for s in np.geomspace(S / step ** 2, S * step ** 2, 15)
                     for r in np.linspace(0.0, 1.25, 26) for g in lags], dtype=float)


def _verdict(op, mv, dt, rows, a, res, band_needed: float, ic_margin: float) -> Evidence:
    """The stem test's evidence from the grid's fits ``res`` (see :func:`_grid_rss`)."""
    from ..fit import effective_n

    rss = res[:, :, 0]
    i, j = np.unravel_index(int(np.argmin(rss)), rss.shape)
    n0 = int(np.sum(rows[:, 0] == 0.0))
    i0, j0 = np.unravel_index(int(np.argmin(rss[:n0])), rss[:n0].shape)
    rss0 = min(float(rss[i0, j0]), _frictionless_rss(op, mv))
    b, c = float(res[i, j, 1]), float(res[i, j, 2])
    x = _stem(op, rows[i, 0], rows[i, 1], a[i], int(rows[i, 3]))
    xp = x[1:] if j == 0 else x[:-1]
    resid = mv[1:] - (c + b * xp)
    n_eff = effective_n(resid)
    vm = float(np.sum((mv[1:] - mv[1:].mean()) ** 2))
    r2 = 1.0 - float(rss[i, j]) / max(vm, 1e-300)
    if not (0.2 <= abs(b) <= 5.0) or r2 < 0.2:
        return Evidence("stem", CITE, False, float("nan"), 0.0, "undetermined",
                        f"the recorded position does not follow the output through any valve tried (span "
                        f"{b:.2g}, R^2 {r2:.2f}); check that the column is the valve's position", DOC)
    floor = 1e-12 * max(vm, 1e-300)
    d_ic = n_eff * float(np.log((rss[i, j] + floor) / (rss0 + floor))) + 2.0 * float(np.log(n_eff))
    S, J = float(rows[i, 0]), float(rows[i, 1])
    lo_S, hi_S, lo_J, hi_J = _intervals(rows, rss.min(axis=1), float(rss[i, j]) + floor, n_eff)
    significant = d_ic < -ic_margin
    if significant and S >= band_needed:
        verdict = "stiction"
        reason = (f"the stem sticks: a band S = {100 * S:.2g} % of the stroke (90 % {100 * lo_S:.2g}-"
                  f"{100 * hi_S:.2g} %), slip jump J = {100 * J:.2g} % ({_LAW_NAMES[int(rows[i, 3])]}'s law), "
                  f"explains the recorded position better than "
                  f"a valve that follows the output (criterion {d_ic:+.1f}) and reaches the "
                  f"{100 * band_needed:.2g} % that matters in this loop")
    elif significant:
        verdict = "no stiction"
        reason = (f"the stem follows the output within a band of {100 * S:.2g} % of the stroke, below the "
                  f"{100 * band_needed:.2g} % that matters in this loop")
    else:
        verdict = "no stiction"
        reason = (f"the stem follows the output: no stick band explains the recorded position better "
                  f"(criterion {d_ic:+.1f})")
    repeats = float(np.mean(np.diff(mv) == 0.0))
    if verdict == "stiction" and repeats > 0.5:
        reason += (f"; caution: {100 * repeats:.0f} % of the position samples repeat the one before exactly, as a "
                   f"historian's compression or a held value does, which also looks like a stuck stem: confirm "
                   f"with uncompressed data or a valve test")
    det = {"S": S, "S_lo": lo_S, "S_hi": hi_S, "J": J, "J_lo": lo_J, "J_hi": hi_J, "delta_ic": d_ic,
           "repeats": repeats,
           "n_eff": n_eff, "lag_s": float(rows[i, 2]) * float(dt), "pairing": float(j), "span": b,
           "offset": c, "r2": r2, "law": float(rows[i, 3]), "rmse": float(np.sqrt(rss[i, j] / max(len(resid), 1))),
           "band_needed": float(band_needed)}
    return Evidence("stem", CITE, True, S, 1.0, verdict, reason, DOC, det)


def _frictionless_rss(op, mv) -> float:
    """The least RSS of a frictionless valve with its positioner pole searched continuously (0..0.98).

    A grid of lags leaves a small dynamic misfit that a stick band can absorb where the output
    jumps by much of the stroke (a saturating, aggressively tuned loop): the frictionless
    alternative gets the continuous search, so friction must explain more than that misfit.
    """
    from scipy.optimize import minimize_scalar

    z = np.zeros(1)

    def f(a: float, j: int) -> float:
        return float(_grid_rss(op, mv, z, z, np.array([a]), np.zeros(1, np.int64))[0, j, 0])

    best = [minimize_scalar(f, bounds=(0.0, 0.98), args=(j,), method="bounded", options={"xatol": 1e-4})
            for j in (0, 1)]
    return min(float(getattr(r, "fun")) for r in best)


def _intervals(rows, rss_row, rss_min: float, n_eff: float) -> tuple[float, float, float, float]:
    """Profile 90 % intervals of S and J over the grid, widened by half a grid step (log scale)."""
    inside = n_eff * np.log((rss_row + 1e-300) / rss_min) <= _CHI2_90
    S_in, J_in = rows[inside, 0], rows[inside, 1]
    half = float((STEM_S_GRID[1] / STEM_S_GRID[0]) ** (2.0 / 14.0))     # half a step of the fine grid
    wS, wJ = half * np.exp(DISCREPANCY_S), half * np.exp(DISCREPANCY_J)
    lo_S = float(S_in.min()) / wS if S_in.min() > 0 else 0.0
    lo_J = float(J_in.min()) / wJ if J_in.min() > 0 else 0.0
    return lo_S, float(S_in.max()) * wS, lo_J, float(J_in.max()) * wJ


def stem_size(ev: Evidence) -> SizeEstimate:
    """The stem test's S and J with their intervals (NaN where it did not apply)."""
    if ev.method != "stem" or not ev.applicable:
        return NAN_SIZE
    d = ev.details
    return SizeEstimate("stem", d["S"], d["S_lo"], d["S_hi"], d["J"], d["J_lo"], d["J_hi"])
