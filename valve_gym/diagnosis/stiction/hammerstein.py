"""Model-based stiction evidence: the package's friction block inside a Hammerstein model.

The diagnosis fits the process model with a frictionless valve and with a
friction block (the paper's valve, and Choudhury's two-parameter slip-jump
valve) in front of the same linear or tank dynamics, by free-run simulation
error (Jelali 2008; Choudhury et al. 2008).  The evidence is the drop of the
information criterion that friction buys over the best frictionless
alternative (including a dead time or a sensor lag, the other ways to delay
a response), and the fitted band.  :func:`slip_jump_profile` turns the
slip-jump fit into estimates of ``S`` and ``J`` with 90 % intervals.

Notes
-----
Profile likelihood: at every ``S`` of a grid (0 to 3 ``S_hat``, then up to the
controller output's swing) the other parameters are re-optimised (best ``J/S``
on a grid, then a short least-squares refinement, continuing outwards from the
optimum).  With ``n_eff`` the effective number of independent residual samples
(:func:`valve_gym.diagnosis.fit.effective_n`) the 90 % interval of ``S`` is
``n_eff ln(SSE(S)/SSE_min) <= chi2_{1, 0.90} = 2.71``, interpolated between
grid points; ``J``'s interval is the range of ``J`` over a ``J/S`` scan at every
profile point with the same criterion.  Two widenings follow
(:func:`widen`): the spread of the best ``S`` over four windows of the record
(its standard error, 90 %, added in quadrature: the fitted block is not the
loop's friction law, and the windows disagree more than the noise says), and a
model discrepancy (:data:`DISCREPANCY_HAMMERSTEIN`,
:data:`DISCREPANCY_HAMMERSTEIN_J`: a log-scale widening chosen on textbook
loops, seeds no score uses, by ``benchmarks/sizes_on_benchmark_loops.py
--calibrate``).

References
----------
.. [1] M. Jelali, "Estimation of valve stiction in control loops using
   separable least-squares and global search algorithms", Journal of Process
   Control 18 (2008) 632-642.
.. [2] M.A.A.S. Choudhury, M. Jain, S.L. Shah, "Stiction - definition,
   modelling, detection and quantification", Journal of Process Control 18
   (2008) 232-243.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from ..fit import FitResult, effective_n
from ..select import op_working_range
from ._base import Evidence, not_applicable

__all__ = ["SizeEstimate", "hammerstein_evidence", "profile_interval", "slip_jump_profile", "widen", "MIN_SLIPS",
           "SEIZED_TRAVEL", "friction_moves", "fit_moves"]

CITE = "Jelali 2008, J. Process Control 18, 632-642; Choudhury, Jain & Shah 2008"
DOC = ("asinh(-delta IC / 2) of the best friction model against the best frictionless one "
       "(> 0.9: friction pays, delta IC < -2)")


class SizeEstimate(NamedTuple):
    """Stiction size of one method, fractions of the valve stroke.

    ``S``, ``J`` point estimates; ``S_lo, S_hi``, ``J_lo, J_hi`` 90 % interval
    (nan where the method gives none); ``method`` its name.
    """

    method: str
    S: float
    S_lo: float
    S_hi: float
    J: float
    J_lo: float
    J_hi: float


NAN_SIZE = SizeEstimate("none", *([float("nan")] * 6))
#: 90 % quantile of chi-square with one degree of freedom (the profile threshold).
CHI2_90 = 2.706
#: Model discrepancy of the fitted slip-jump block: log-scale widenings ``c`` of its S and J
#: intervals (``lo e^-c``, ``hi e^c``).  The simulator's friction law (Kano, Choudhury, force
#: balance, ...) is not the fitted one, a bias that no amount of data removes.  Chosen on the
#: textbook loops of :mod:`.loops` (``benchmarks/sizes_on_benchmark_loops.py --calibrate``),
#: checked on the benchmark's loops (other friction models).
DISCREPANCY_HAMMERSTEIN = 1.1
DISCREPANCY_HAMMERSTEIN_J = 1.5


#: Output travel (working range, fraction of stroke) above which a valve that does not move is seized:
#: a valve with less than 10 % stiction moves over such a travel (``benchmarks/stem_verdict.py``: healthy
#: textbook loops with a frozen position signal and 2.5-8 % of travel fitted bands of 3-6 %).  Read by the
#: stem test's frozen position (:func:`valve_gym.diagnosis.verdict.frozen_position`) and by :func:`friction_moves`.
SEIZED_TRAVEL = 0.1

#: Slips of a fitted friction valve below which the fit shows no stick-slip: a valve that sticks also
#: slips, and a fit whose band holds the stem still through the record (or moves it once) explains the
#: process without the controller output's moves.
MIN_SLIPS = 2


def friction_moves(slips: int, op_range: float) -> bool:
    """Whether a friction fit whose valve slips ``slips`` times can show a sticking valve.

    At least :data:`MIN_SLIPS` slips; or any number where the output's working range ``op_range``
    reaches :data:`SEIZED_TRAVEL`: a valve that does not move while the output travels that far is
    seized, the extreme of sticking.  Below that travel a band wider than the output's moves fits a
    quiet healthy loop whose output moves answer the measurement noise as well as a stuck valve (the
    closed-loop bias of an output-error fit: each output is correlated with the next PV noise).

    >>> friction_moves(0, 0.012), friction_moves(3, 0.012), friction_moves(0, 0.2)
    (False, True, True)
    """
    return slips >= MIN_SLIPS or op_range >= SEIZED_TRAVEL


def fit_moves(verdict: Mapping, key: str = "slips") -> bool:
    """:func:`friction_moves` of a friction verdict's slip count ``key`` (``'slips'``, ``'kstep_slips'``).

    Reads ``op_working_range`` with it; True where the count is missing or None (no such fit).

    >>> fit_moves({"slips": 0, "op_working_range": 0.02}), fit_moves({"slips": None}), fit_moves({})
    (False, True, True)
    """
    slips = verdict.get(key)
    if slips is None:
        return True
    return friction_moves(int(slips), float(verdict.get("op_working_range") or 0.0))


def hammerstein_evidence(verdict: Mapping, s_slip: float = float("nan")) -> Evidence:
    """Evidence from the friction verdict of :func:`valve_gym.diagnosis.diagnose`.

    Parameters
    ----------
    verdict : mapping with ``tested``, ``delta_ic``, ``band`` and ``band_needed``
        (fractions of stroke) and ``present``; optionally ``slips`` (how often the friction fit's
        valve moves) and ``op_working_range``: a friction fit that lowers the criterion with a
        valve that does not slip (:func:`friction_moves`) is no evidence (not applicable)
    s_slip : float, optional, S of the fitted slip-jump block (fraction of stroke).  The
        band of the paper's valve is its dead band ``2 e_dead`` only (its stick band
        ``z_max`` is in seconds of integrated error), so when that model wins, the
        slip-jump ``S`` is the better measure of how wide the friction is: the larger
        of the two is used.

    Returns
    -------
    Evidence, ``value = asinh(-delta_ic / 2)``; ``details``: ``delta_ic``,
    ``band``, ``band_needed``, ``log_band_ratio``
    """
    if not verdict.get("tested"):
        return not_applicable("hammerstein", CITE, str(verdict.get("reason", "not tested")), DOC)
    d_ic = float(verdict["delta_ic"])
    if d_ic < 0 and not fit_moves(verdict):
        return not_applicable("hammerstein", CITE, f"the friction fit lowers the criterion ({d_ic:+.1f}) but its "
                              f"valve slips {int(verdict['slips'])} time(s) over the record: it explains the "
                              f"process without the output's moves, which shows no stick-slip", DOC)
    band = float(verdict["band"])
    if np.isfinite(s_slip):
        band = max(band, float(s_slip))
    need = float(verdict["band_needed"])
    ratio = float(np.log10(max(band, 1e-5) / max(need, 1e-5)))
    v = float(np.arcsinh(-d_ic / 2.0))
    rel = 1.0 if band >= need else 0.5
    return Evidence("hammerstein", CITE, True, v, rel,
                    "stiction" if verdict.get("present") else "no stiction",
                    f"friction changes the information criterion by {d_ic:.1f}; fitted band "
                    f"{100 * band:.2g} % of stroke (needed {100 * need:.2g} %)", DOC,
                    {"delta_ic": d_ic, "band": band, "band_needed": need, "log_band_ratio": ratio})


class _Profile(NamedTuple):
    """SSE profile over S, the other parameters re-optimised at every S.

    Grid ``s`` (n,), SSE ``sse`` (n,), coordinates ``w`` (n, k), simulations ``y_sim``
    (T, n), and a scan of J at every S: ``j`` (n, m) fractions of stroke, SSE ``sse_j`` (n, m).
    """

    s: np.ndarray
    sse: np.ndarray
    w: np.ndarray
    y_sim: np.ndarray
    j: np.ndarray
    sse_j: np.ndarray


def _sse(st, W, u, y, n_fit: int) -> tuple[np.ndarray, np.ndarray]:
    """Free-run SSE over the first ``n_fit`` samples of every row of ``W``, and the simulations."""
    Y = st.simulate(W, u)
    with np.errstate(over="ignore", invalid="ignore"):
        sse = np.sum((Y[:n_fit] - y[:n_fit, None]) ** 2, axis=0)
    sse[~np.isfinite(sse)] = np.inf
    return sse, Y


def _reoptimise(fit: FitResult, u, y, w, free: list[str], j_coords) -> np.ndarray:
    """The other parameters at a fixed S: best J/S on a grid, then a short least-squares refinement."""
    from ..fit import fit_structure

    st = fit.structure
    i_j = st.index("J_rel")
    W = np.repeat(w[None, :], len(j_coords), axis=0)
    W[:, i_j] = j_coords
    sse, _ = _sse(st, W, u, y, fit.n_fit)
    w = W[int(np.argmin(sse))]
    res = fit_structure(st, u, y, fit.n_fit, seeds=w[None, :], w_fixed=w, free=free, popsize=4,
                        maxiter=1, final_n_sub=False, rng=0)
    return np.asarray(res.w, float)


def _profile_branch(args) -> np.ndarray:
    """One side of the profile: the other parameters re-optimised at each ``S`` in ``s_path``, in order."""
    fit, u, y, s_path, free, jc = args
    st = fit.structure
    i_s = st.index("S")
    p_s = st.params[i_s]
    w = np.asarray(fit.w, float).copy()
    out = np.empty((len(s_path), len(w)))
    for k, s_k in enumerate(s_path):
        w[i_s] = p_s.coord(s_k)
        w = _reoptimise(fit, u, y, w, free, jc)
        out[k] = w
    return out


def _profile(fit: FitResult, u, y, n_s: int, n_j: int, map_fn=None) -> _Profile:
    """SSE profile over S, the other parameters re-optimised at every S (continuation from the optimum).

    The two sides of the optimum are independent continuations; ``map_fn`` (a map-like
    callable, e.g. an executor's ``map``) runs them side by side (same result).
    """
    st = fit.structure
    i_s, i_j = st.index("S"), st.index("J_rel")
    p_s, p_j = st.params[i_s], st.params[i_j]
    s_hat = float(p_s.value(fit.w[i_s]))
    s_max = min(float(p_s.hi), max(3.0 * s_hat, 0.01))
    # beyond 3 S_hat up to the controller output's swing: a missed optimum at a larger band shows up
    swing = min(float(p_s.hi), op_working_range(u))
    far = np.geomspace(s_max, swing, 5)[1:] if swing > 1.2 * s_max else []
    s = np.unique(np.concatenate([np.linspace(0.0, s_max, n_s), far, [s_hat]]))
    k0 = int(np.argmin(np.abs(s - s_hat)))
    jc = np.unique(np.concatenate([np.linspace(0.0, 1.0, n_j), [fit.w[i_j]]]))
    free = [p.name for i, p in enumerate(st.params) if i != i_s and not p.discrete]
    up, down = list(range(k0, len(s))), list(range(k0 - 1, -1, -1))
    tasks = [(fit, u, y, s[order], free, jc) for order in (up, down)]
    ws = np.empty((len(s), len(fit.w)))
    for order, rows in zip((up, down), (map_fn or map)(_profile_branch, tasks)):
        ws[order] = rows
    sse, Y = _sse(st, ws, u, y, fit.n_fit)
    WJ = np.repeat(ws, len(jc), axis=0)
    WJ[:, i_j] = np.tile(jc, len(s))
    sse_j, _ = _sse(st, WJ, u, y, fit.n_fit)
    J = s[:, None] * np.asarray(p_j.value(jc), float)[None, :]
    return _Profile(s, sse, ws, Y, J, sse_j.reshape(len(s), len(jc)))


def _crossing(s, dev, k0: int, step: int) -> float:
    """Where ``dev`` first exceeds the threshold walking from ``k0`` by ``step`` (linear interpolation)."""
    k = k0
    while 0 <= k + step < len(s) and dev[k + step] <= CHI2_90:
        k += step
    if not 0 <= k + step < len(s):
        return float(s[k])
    a, b = float(dev[k]), float(dev[k + step])
    f = 1.0 if not np.isfinite(b) or b <= a else (CHI2_90 - a) / (b - a)
    return float(s[k] + np.clip(f, 0.0, 1.0) * (s[k + step] - s[k]))


def _window_error(pr: _Profile, y, n_fit: int, n_win: int = 4) -> float:
    """Standard error of S from the spread of its best value over ``n_win`` windows of the record."""
    r2 = (pr.y_sim[:n_fit] - np.asarray(y, float)[:n_fit, None]) ** 2
    edges = np.linspace(0, n_fit, n_win + 1).astype(int)
    est = [pr.s[int(np.argmin(np.sum(r2[a:b], axis=0)))] for a, b in zip(edges[:-1], edges[1:])
           if np.all(np.isfinite(r2[a:b]))]
    return float(np.std(est, ddof=1) / np.sqrt(len(est))) if len(est) >= 2 else 0.0


def profile_interval(fit: FitResult, u, y, n_s: int = 13, n_j: int = 9,
                     map_fn=None) -> tuple[SizeEstimate, float]:
    """Statistical part of the S, J estimate of a fitted slip-jump block.

    Parameters
    ----------
    fit : FitResult of a structure with the ``slip_jump`` effect
    u : (T,) controller output 0..1
    y : (T,) measured PV
    n_s, n_j : grid sizes over ``S`` and ``J/S``
    map_fn : map-like callable, optional (e.g. an executor's ``map``): runs the two sides
        of the profile side by side

    Returns
    -------
    (SizeEstimate, float): the profile estimate with its 90 % profile intervals (no
    model discrepancy), and the window standard error of ``S`` (fraction of stroke)
    """
    y = np.asarray(y, float)
    pr = _profile(fit, np.asarray(u, float), y, n_s, n_j, map_fn)
    n_eff = effective_n(fit.residual)
    best = max(float(min(pr.sse.min(), pr.sse_j.min())), 1e-300)
    dev = n_eff * np.log(pr.sse / best)
    k0 = int(np.argmin(dev))
    st = fit.structure
    s_hat = float(pr.s[k0])
    j_hat = s_hat * float(st.params[st.index("J_rel")].value(pr.w[k0, st.index("J_rel")]))
    dev_j = n_eff * np.log(pr.sse_j / best)
    inside = dev_j <= CHI2_90
    jv = pr.j[inside] if inside.any() else np.array([j_hat])
    est = SizeEstimate("hammerstein", s_hat, _crossing(pr.s, dev, k0, -1), _crossing(pr.s, dev, k0, +1),
                       j_hat, min(float(jv.min()), j_hat), max(float(jv.max()), j_hat))
    return est, _window_error(pr, y, int(fit.n_fit))


def widen(est: SizeEstimate, s_err: float, c_s: float | None = None, c_j: float | None = None) -> SizeEstimate:
    """Add a window standard error ``s_err`` of S (in quadrature, 90 %) and the model discrepancy.

    The discrepancies ``c_s``, ``c_j`` (default :data:`DISCREPANCY_HAMMERSTEIN`,
    :data:`DISCREPANCY_HAMMERSTEIN_J`) widen the S and J intervals on the log
    scale: ``lo exp(-c)``, ``hi exp(c)``.
    """
    h = 1.645 * s_err
    lo = max(0.0, est.S - float(np.hypot(est.S - est.S_lo, h)))
    hi = est.S + float(np.hypot(est.S_hi - est.S, h))
    gs = float(np.exp(DISCREPANCY_HAMMERSTEIN if c_s is None else c_s))
    gj = float(np.exp(DISCREPANCY_HAMMERSTEIN_J if c_j is None else c_j))
    return est._replace(S_lo=lo / gs, S_hi=hi * gs, J_lo=est.J_lo / gj, J_hi=est.J_hi * gj)


def slip_jump_profile(fit: FitResult | None, u, y, n_s: int = 13, n_j: int = 9, map_fn=None) -> SizeEstimate:
    """S and J of a fitted slip-jump model with 90 % intervals.

    The profile likelihood re-optimises the other parameters at every ``S``
    (:func:`profile_interval`); the interval is widened by the spread of ``S``
    over windows of the record and by the model discrepancies
    :data:`DISCREPANCY_HAMMERSTEIN`, :data:`DISCREPANCY_HAMMERSTEIN_J` (:func:`widen`).

    Parameters
    ----------
    fit : FitResult of a structure with the ``slip_jump`` effect (None: no estimate)
    u : (T,) controller output 0..1
    y : (T,) measured PV
    n_s, n_j : grid sizes over ``S`` and ``J/S``
    map_fn : map-like callable, optional (see :func:`profile_interval`)

    Returns
    -------
    SizeEstimate (fractions of stroke), method ``'hammerstein'``
    """
    if fit is None or "slip_jump" not in fit.structure.effects:
        return NAN_SIZE
    est, s_err = profile_interval(fit, u, y, n_s, n_j, map_fn)
    return widen(est, s_err)
