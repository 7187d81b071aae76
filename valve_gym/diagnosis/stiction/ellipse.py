r"""Ellipse fitting on the filtered PV-OP plot: apparent stiction (Choudhury et al. 2006, 2008).

Behind a sticking valve the PV-OP plot of a limit cycle is a loop whose
width along the OP axis is the controller travel during which the valve
does not move.  After band-pass filtering both signals around the
oscillation, a least-squares ellipse (Fitzgibbon, Pilu & Fisher 1999) is
fitted to the plot; its chord along the OP axis through its centre is the
*apparent stiction*.

Notes
-----
With semi-axes ``m``, ``n`` and rotation ``alpha`` of the fitted ellipse,

.. math:: S_{app} = \frac{2 m n}{\sqrt{m^2 \sin^2\alpha + n^2 \cos^2\alpha}}

in the OP's units (fraction of stroke for a normalised recording).  The chord
along the OP axis does not change when the PV axis is scaled, so the PV is
standardised before the fit.  The 90 % interval comes from the spread of the
same estimate over windows of two periods (5 % and 95 % quantiles, widened to
at least +-25 % of the estimate when fewer than 6 windows exist).

The apparent stiction of the filtered plot is not ``S``: band-pass filtering
keeps the fundamental of a triangular or square OP, and the chord of an
ellipse through a loop with sharp corners is shorter than the loop's width.
:func:`ellipse_size` turns it into an estimate of ``S`` with a scale
:data:`ELLIPSE_SCALE` and a model discrepancy :data:`DISCREPANCY_ELLIPSE`
(log-scale widening of the window interval), both chosen on the textbook
loops of :mod:`.loops` (``benchmarks/sizes_on_benchmark_loops.py
--calibrate``) and checked on the benchmark's loops (other friction models).  The index
``value`` is ``S_app`` divided by the filtered OP's peak-to-peak range:
``|sin(phi)|`` for a phase lag ``phi`` between OP and PV, near 1 for the
quarter-period lag of stiction in self-regulating loops, near 0 for
counter-phase (tuning) oscillations.

References
----------
.. [1] M.A.A.S. Choudhury, S.L. Shah, N.F. Thornhill, D.S. Shook, "Automatic
   detection and quantification of stiction in control valves", Control
   Engineering Practice 14 (2006) 1395-1412.
.. [2] M.A.A.S. Choudhury, S.L. Shah, N.F. Thornhill, Diagnosis of Process
   Nonlinearities and Valve Stiction, Springer, 2008.
.. [3] A. Fitzgibbon, M. Pilu, R.B. Fisher, "Direct least square fitting of
   ellipses", IEEE Trans. PAMI 21(5) (1999) 476-480.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._base import Evidence, bandpass, check_signals, not_applicable, oscillation, reliability

__all__ = ["EllipseFit", "fit_ellipse", "apparent_stiction", "ellipse_evidence", "ellipse_size"]

CITE = "Choudhury, Shah, Thornhill & Shook 2006, Control Engineering Practice 14, 1395-1412"
DOC = ("apparent stiction / filtered OP peak-to-peak (= |sin phi| of the OP-PV phase lag); near 1 "
       "quarter-period lag (stiction in self-regulating loops), near 0 counter-phase")


#: S over the apparent stiction of the filtered PV-OP plot (median on the textbook loops of :mod:`.loops`).
ELLIPSE_SCALE = 2.21
#: Log-scale widening of the scaled window interval (loop-to-loop spread of the ratio S / apparent stiction).
DISCREPANCY_ELLIPSE = 0.9


def ellipse_size(s_app: float, lo: float, hi: float, scale: float | None = None,
                 discrepancy: float | None = None) -> tuple[float, float, float]:
    """Estimate of ``S`` (with a 90 % interval) from the apparent stiction and its window interval.

    ``(scale s_app, scale lo exp(-c), scale hi exp(c))`` with ``scale``
    :data:`ELLIPSE_SCALE` and ``c`` :data:`DISCREPANCY_ELLIPSE` unless given.
    """
    k = ELLIPSE_SCALE if scale is None else float(scale)
    g = float(np.exp(DISCREPANCY_ELLIPSE if discrepancy is None else discrepancy))
    return k * s_app, k * lo / g, k * hi * g


class EllipseFit(NamedTuple):
    """A fitted ellipse: centre ``(x0, y0)``, semi-axes ``m >= n``, rotation ``alpha`` [rad]."""

    x0: float
    y0: float
    m: float
    n: float
    alpha: float


def fit_ellipse(x, y) -> EllipseFit | None:
    """Direct least-squares ellipse through points ``(x, y)`` (Fitzgibbon et al. 1999).

    Returns None when the points do not determine an ellipse (a line, too few points).
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if len(x) < 6:
        return None
    mx, my = x.mean(), y.mean()
    sx, sy = max(x.std(), 1e-300), max(y.std(), 1e-300)
    u, v = (x - mx) / sx, (y - my) / sy
    D1 = np.column_stack([u * u, u * v, v * v])
    D2 = np.column_stack([u, v, np.ones_like(u)])
    S1, S2, S3 = D1.T @ D1, D1.T @ D2, D2.T @ D2
    try:
        T = -np.linalg.solve(S3, S2.T)
    except np.linalg.LinAlgError:
        return None
    M = S1 + S2 @ T
    M = np.array([M[2] / 2, -M[1], M[0] / 2])
    w, V = np.linalg.eig(M)
    V = np.real(V)
    cond = 4 * V[0] * V[2] - V[1] ** 2
    ok = np.nonzero(cond > 0)[0]
    if len(ok) == 0:
        return None
    a1 = V[:, ok[0]]
    A, B, C = a1
    Dd, E, F = T @ a1
    # back to the original coordinates: u = (x - mx)/sx, v = (y - my)/sy
    return _geometric(A, B, C, Dd, E, F, mx, my, sx, sy)


def _geometric(A, B, C, D, E, F, mx, my, sx, sy) -> EllipseFit | None:
    den = B * B - 4 * A * C
    if den >= 0:
        return None
    uc = (2 * C * D - B * E) / den
    vc = (2 * A * E - B * D) / den
    Fc = A * uc * uc + B * uc * vc + C * vc * vc + D * uc + E * vc + F
    Q = np.array([[A, B / 2], [B / 2, C]])
    Q = Q / (-Fc)                            # (p)^T Q p = 1 in (u, v) about the centre
    Sc = np.diag([1 / sx, 1 / sy])
    Qx = Sc @ Q @ Sc                         # the same in (x, y)
    ev, evec = np.linalg.eigh(Qx)
    if np.any(ev <= 0):
        return None
    axes = 1 / np.sqrt(ev)
    i = int(np.argmax(axes))
    alpha = float(np.arctan2(evec[1, i], evec[0, i]))
    return EllipseFit(float(mx + uc * sx), float(my + vc * sy), float(axes[i]), float(axes[1 - i]),
                      alpha)


def apparent_stiction(e: EllipseFit) -> float:
    """Chord of the ellipse along the x (OP) axis through its centre, x units."""
    m, n, a = e.m, e.n, e.alpha
    return float(2 * m * n / np.sqrt(m * m * np.sin(a) ** 2 + n * n * np.cos(a) ** 2))


def _window_estimates(opf, pvf, period):
    w = int(round(2 * period))
    if w < 12:
        return np.array([])
    out = []
    for s in range(0, len(opf) - w + 1, max(1, int(round(period)))):
        e = fit_ellipse(opf[s:s + w], pvf[s:s + w])
        if e is not None:
            out.append(apparent_stiction(e))
    return np.asarray(out)


def ellipse_evidence(op, pv, dt: float = 1.0) -> Evidence:
    """Apparent stiction from the filtered PV-OP plot, with a 90 % interval.

    Parameters
    ----------
    op : (T,) array, controller output (fraction of stroke for a normalised recording)
    pv : (T,) array, process variable (any units)
    dt : float, sample time [s]

    Returns
    -------
    Evidence, ``value`` the phase index (see module notes); ``details``:
    ``S_app`` (OP units), ``S_lo``, ``S_hi`` (its 90 % window interval), ``S_est``,
    ``S_est_lo``, ``S_est_hi`` (the estimate of ``S`` with its 90 % interval,
    :func:`ellipse_size`), ``n_windows``, ``period_samples``
    """
    op, pv = check_signals(op, pv, dt)
    osc = oscillation(pv)
    if not osc.present:
        osc_op = oscillation(op)
        if not osc_op.present:
            return not_applicable("ellipse", CITE, "neither PV nor OP oscillates regularly", DOC)
        osc = osc_op
    opf = bandpass(op, osc.period_samples)
    pvf = bandpass(pv, osc.period_samples)
    e = fit_ellipse(opf, pvf)
    if e is None:
        return not_applicable("ellipse", CITE, "the PV-OP plot is not an ellipse (a line)", DOC)
    s = apparent_stiction(e)
    amp = float(np.quantile(opf, 0.98) - np.quantile(opf, 0.02))
    idx = float(np.clip(s / max(amp, 1e-300), 0.0, 1.0))
    wins = _window_estimates(opf, pvf, osc.period_samples)
    if len(wins) >= 2:
        lo, hi = float(np.quantile(wins, 0.05)), float(np.quantile(wins, 0.95))
    else:
        lo, hi = s, s
    if len(wins) < 6:
        lo, hi = min(lo, 0.75 * s), max(hi, 1.25 * s)
    lo, hi = min(lo, s), max(hi, s)
    est = ellipse_size(s, lo, hi)
    verdict = "stiction" if idx > 2 / 3 else ("no stiction" if idx < 1 / 3 else "undetermined")
    return Evidence("ellipse", CITE, True, idx, reliability(osc), verdict,
                    f"apparent stiction {100 * s:.2g} % of the OP range over a filtered OP swing of "
                    f"{100 * amp:.2g} %", DOC,
                    {"S_app": s, "S_lo": lo, "S_hi": hi, "S_est": est[0], "S_est_lo": est[1],
                     "S_est_hi": est[2], "n_windows": float(len(wins)),
                     "period_samples": osc.period_samples, "op_pp_filtered": amp})
