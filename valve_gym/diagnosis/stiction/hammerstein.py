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
Profile region: with ``n_eff`` the effective number of independent residual
samples (:func:`valve_gym.diagnosis.fit.effective_n`) and ``SSE(S, J)`` the
free-run squared error with the other parameters at their optimum, the 90 %
region is ``n_eff ln(SSE/SSE_min) <= chi2_{1, 0.90} = 2.71``; the intervals
are its projections on ``S`` and on ``J`` (conditional on the other
parameters, hence narrower than a full profile; floored at one grid step).

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
from ._base import Evidence, not_applicable

__all__ = ["SizeEstimate", "hammerstein_evidence", "slip_jump_profile"]

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


def hammerstein_evidence(verdict: Mapping, s_slip: float = float("nan")) -> Evidence:
    """Evidence from the friction verdict of :func:`valve_gym.diagnosis.diagnose`.

    Parameters
    ----------
    verdict : mapping with ``tested``, ``delta_ic``, ``band`` and ``band_needed``
        (fractions of stroke) and ``present``
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


def slip_jump_profile(fit: FitResult | None, u, y, n_s: int = 25, n_j: int = 13) -> SizeEstimate:
    """S and J of a fitted slip-jump model with 90 % profile intervals.

    Parameters
    ----------
    fit : FitResult of a structure with the ``slip_jump`` effect (None: no estimate)
    u : (T,) controller output 0..1
    y : (T,) measured PV
    n_s, n_j : grid sizes over ``S`` and ``J/S``

    Returns
    -------
    SizeEstimate (fractions of stroke), method ``'hammerstein'``
    """
    if fit is None or "slip_jump" not in fit.structure.effects:
        return NAN_SIZE
    st = fit.structure
    i_s, i_j = st.index("S"), st.index("J_rel")
    p_s = st.params[i_s]
    p_j = st.params[i_j]
    s_hat = float(p_s.value(fit.w[i_s]))
    s_max = min(float(p_s.hi), max(3.0 * s_hat, 0.01))
    s_grid = np.linspace(0.0, s_max, n_s)
    j_grid = np.linspace(float(p_j.lo), float(p_j.hi), n_j)
    SS, JJ = np.meshgrid(s_grid, j_grid, indexing="ij")
    W = np.repeat(fit.w[None, :], SS.size + 1, axis=0)
    W[:-1, i_s] = p_s.coord(SS.ravel())
    W[:-1, i_j] = p_j.coord(JJ.ravel())
    Y = st.simulate(W, u)
    sse = np.nansum((Y - np.asarray(y, float)[:, None]) ** 2, axis=0)
    sse[~np.isfinite(Y).all(axis=0)] = np.inf
    n_eff = effective_n(fit.residual)
    best = float(min(sse.min(), fit.cost if fit.n_fit == len(y) else sse[-1]))
    dev = n_eff * np.log(sse[:-1] / max(best, 1e-300))
    inside = dev <= 2.71
    s_vals, j_vals = SS.ravel(), (SS * JJ).ravel()
    if not inside.any():
        inside = dev <= dev.min()
    ds = s_grid[1] - s_grid[0]
    j_hat = float(fit.physical.get("slip_jump.J", s_hat * p_j.value(fit.w[i_j])))
    s_lo, s_hi = float(s_vals[inside].min()), float(s_vals[inside].max())
    j_lo, j_hi = float(j_vals[inside].min()), float(j_vals[inside].max())
    s_lo, s_hi = max(0.0, min(s_lo, s_hat - ds)), max(s_hi, s_hat + ds)
    j_lo, j_hi = max(0.0, min(j_lo, j_hat - ds)), max(j_hi, j_hat + ds)
    return SizeEstimate("hammerstein", s_hat, s_lo, s_hi, j_hat, j_lo, j_hi)
