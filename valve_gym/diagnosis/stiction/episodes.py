"""Stick episodes: the controller pushes, the process does not answer (after Kano et al. 2004).

Plant records of sticky valves often hold no limit cycle but one or two
long *stick episodes*: the PV sits off its set point, the integral action
ramps the controller output steadily, and the PV does not move until the
valve breaks away and jumps.  Kano et al. (2004) detect stiction from
sections where the output moves while the valve (or, without a position
measurement, the process) stays constant; Damarla et al. (2022) from the
ratio of output and process slopes in short windows.  Here, in windows of
``w`` samples:

* the OP *ramps* when the t-statistic of its least-squares slope exceeds 3;
* the process *answers* when the t-statistic of the PV slope exceeds 2 (for
  an integrating loop: of the PV's curvature, i.e. its rate changes);
* a window is *stuck* when the OP ramps, the control error has the sign that
  drives that ramp (integral action on a persistent error), and the process
  does not answer.

Notes
-----
Index ``value = sum |dOP| over stuck windows / sum |dOP| over ramping windows``
(0..1; not applicable when the OP ramps in fewer than 3 windows), computed at two window lengths
(``w = max(6, n/60)`` and ``3 w``) and the larger taken.  In a regularly oscillating loop the
windows must stay within a quarter cycle (a window over a turning point has no slope): ``w`` is
then at most a quarter period and the long window is dropped.  A working valve
answers an OP ramp within a window; a regulating loop that counters a load
moves its OP while the PV stays *at* the set point, which is not counted
(the error must drive the ramp).  Published decision thresholds do not exist
for this variant; the logistic combination learns its weight.

References
----------
.. [1] M. Kano, H. Maruta, H. Kugemoto, K. Shimizu, "Practical model and
   detection algorithm for valve stiction", IFAC DYCOPS, 2004.
.. [2] S.K. Damarla, X. Sun, F. Xu, A. Shah, B. Huang, "A linear
   regression-based method for detection of valve stiction", Industrial &
   Engineering Chemistry Research 61 (2022) 502-514.
"""
from __future__ import annotations

import numpy as np

from ._base import Evidence, check_signals, not_applicable, oscillation

__all__ = ["stuck_share", "episodes_evidence"]

CITE = "Kano et al. 2004 (IFAC DYCOPS); Damarla et al. 2022, Ind. Eng. Chem. Res. 61, 502-514"
DOC = ("share of the OP's ramping travel during which the error drives the ramp and the process does not "
       "answer (0..1)")


def _slopes(x, w):
    """Least-squares slope and its t-statistic in non-overlapping windows of ``w`` samples."""
    m = len(x) // w
    X = x[:m * w].reshape(m, w)
    t = np.arange(w) - (w - 1) / 2.0
    sxx = float(t @ t)
    b = (X - X.mean(axis=1, keepdims=True)) @ t / sxx
    res = X - X.mean(axis=1, keepdims=True) - b[:, None] * t[None, :]
    se = np.sqrt(np.maximum(np.sum(res * res, axis=1) / max(w - 2, 1), 1e-300) / sxx)
    return b, np.abs(b) / se, X.mean(axis=1)


def _curvature_t(x, w):
    """t-statistic of the quadratic term of a least-squares parabola in windows of ``w`` samples."""
    m = len(x) // w
    X = x[:m * w].reshape(m, w)
    t = np.arange(w) - (w - 1) / 2.0
    A = np.column_stack([np.ones(w), t, t * t])
    coef, *_ = np.linalg.lstsq(A, X.T, rcond=None)
    res = X.T - A @ coef
    s2 = np.sum(res * res, axis=0) / max(w - 3, 1)
    cov22 = np.linalg.inv(A.T @ A)[2, 2]
    return np.abs(coef[2]) / np.sqrt(np.maximum(s2 * cov22, 1e-300))


def stuck_share(op, pv, e, w: int, integrating: bool) -> float:
    """Index of the module notes for one window length ``w`` (nan if the OP ramps in < 3 windows)."""
    b_op, t_op, _ = _slopes(op, w)
    t_y = _curvature_t(pv, w) if integrating else _slopes(pv, w)[1]
    m = len(b_op)
    e_mean = e[:m * w].reshape(m, w).mean(axis=1)
    e_sd = np.std(np.diff(e)) / np.sqrt(2) / np.sqrt(w) + 1e-300
    ramp = t_op > 3.0
    if ramp.sum() < 3:
        return float("nan")
    # the controller's output rises for a positive error (reverse or direct acting: take the sign
    # that the record shows most often while ramping)
    s = np.sign(np.sum(np.sign(b_op[ramp]) * np.sign(e_mean[ramp]))) or 1.0
    drives = (np.sign(b_op) == s * np.sign(e_mean)) & (np.abs(e_mean) > 2 * e_sd)
    stuck = ramp & drives & (t_y < 2.0)
    travel = np.abs(b_op) * w
    return float(travel[stuck].sum() / travel[ramp].sum())


def episodes_evidence(op, pv, dt: float = 1.0, plant: str = "first_order", sp=None) -> Evidence:
    """Stick-episode index of one record.

    Parameters
    ----------
    op, pv : (T,) arrays
    dt : float, sample time [s]
    plant : str, ``'integrating'`` tests the change of the PV rate instead of the PV
    sp : (T,) set point, optional (default: the mean PV)

    Returns
    -------
    Evidence, ``value`` = stuck share (0..1); ``details``: ``share_short``, ``share_long``, ``window``,
    ``regular_oscillation`` (1 when the PV or the OP oscillates regularly, else 0; also when not
    applicable: the combination reads its regime from it)
    """
    op, pv = check_signals(op, pv, dt)
    n = len(op)
    w = max(6, n // 60)
    osc = oscillation(pv)
    regular = float(osc.present or oscillation(op).present)
    long_ok = n >= 12 * w
    if osc.present and 3 * w > osc.period_samples / 4:      # slopes need windows within a quarter cycle
        long_ok = False
        w = max(4, min(w, int(osc.period_samples / 4)))
    if n < 4 * w:
        return _silent(f"too short (< {4 * w} samples)", regular)
    e = (np.asarray(sp, float) if sp is not None else np.full(n, pv.mean())) - pv
    integ = plant == "integrating"
    a = stuck_share(op, pv, e, w, integ)
    b = stuck_share(op, pv, e, 3 * w, integ) if long_ok else float("nan")
    vals = [v for v in (a, b) if np.isfinite(v)]
    if not vals:
        return _silent("the controller output never ramps", regular)
    v = max(vals)
    verdict = "stiction" if v > 0.5 else ("no stiction" if v < 0.2 else "undetermined")
    return Evidence("episodes", CITE, True, v, 1.0, verdict,
                    f"{100 * v:.0f} % of the OP's ramping travel met no process response", DOC,
                    {"share_short": a, "share_long": b, "window": float(w), "regular_oscillation": regular})


def _silent(reason: str, regular: float) -> Evidence:
    e = not_applicable("episodes", CITE, reason, DOC)
    return Evidence(e.method, e.citation, False, e.value, 0.0, e.verdict, reason, DOC,
                    {"regular_oscillation": regular})
