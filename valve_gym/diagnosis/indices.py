r"""Data-driven stiction indices, reported beside the model-based friction verdict.

The friction verdict of :func:`valve_gym.diagnosis.diagnose` comes from fitting
the simulator with and without friction.  Plant engineers also know the
classical shape tests that need no model; the one computed here is a second,
independent opinion on the same record, and a reference method for the
labelled plant loops (``benchmarks/real_data.py``).

Horch's cross-correlation test [1]_: in a self-regulating loop that oscillates
because the valve sticks, the cross-correlation of controller output and
process variable is an *odd* function of the lag (the PV follows the integral
of the output's square wave: a quarter period of phase), while an oscillation
from aggressive tuning or an external disturbance gives an *even* one (output
and PV in counter-phase).  With ``tau_l`` and ``tau_r`` the distances from lag
0 to the first zero crossing on the left and on the right, the phase index

.. math:: \Delta\phi = \pi\,\frac{|\tau_r - \tau_l|}{\tau_r + \tau_l}

is near 0 for an even and near ``pi`` for an odd function; the decision bands
used in the stiction literature are ``< pi/3`` no stiction, ``> 2 pi/3``
stiction, undetermined in between.  The test assumes a self-regulating
process (flow, pressure, a tank draining through an outlet); for integrating
levels it does not apply and says so.

References
----------
.. [1] A. Horch, "A simple method for detection of stiction in control
   valves", Control Engineering Practice 7(10), 1221-1231, 1999.
"""
from __future__ import annotations

import numpy as np

from .locate import _ccf

__all__ = ["horch_ccf"]


def _first_crossing(c):
    """Distance (in lags, interpolated) to the first sign change of ``c[0], c[1], ...``; None if none."""
    if c[0] == 0.0:
        return 0.0
    s0 = np.sign(c[0])
    for k in range(1, len(c)):
        if np.sign(c[k]) != s0:
            return (k - 1) + c[k - 1] / (c[k - 1] - c[k])
    return None


def _checked_inputs(op, pv, dt: float, max_lag) -> tuple[np.ndarray, np.ndarray]:
    """Validate the inputs of :func:`horch_ccf`; ``op`` and ``pv`` as float arrays, (T,) each."""
    op = np.asarray(op, float)
    pv = np.asarray(pv, float)
    if op.ndim != 1 or pv.ndim != 1 or op.shape != pv.shape:
        raise ValueError(f"op and pv must be 1-D arrays of the same length, got shapes {op.shape} "
                         f"and {pv.shape}")
    if not (np.isfinite(op).all() and np.isfinite(pv).all()):
        raise ValueError("op and pv contain NaN or inf values; repair or drop those samples first "
                         "(load_recording does)")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    if max_lag is not None and not (isinstance(max_lag, (int, np.integer)) and 1 <= max_lag < len(op)):
        raise ValueError(f"max_lag must be a whole number from 1 to len(op) - 1 = {len(op) - 1}, "
                         f"got {max_lag!r}")
    return op, pv


def horch_ccf(op, pv, dt: float = 1.0, plant: str = "first_order", max_lag=None) -> dict:
    """Horch's cross-correlation stiction test on one record.

    Parameters
    ----------
    op, pv : (T,) arrays, controller output and process variable (any units)
    dt : float, sample time [s]
    plant : str, ``'integrating'`` is outside the test's scope (the tank and cascade
        plants drain through an outlet and regulate themselves)
    max_lag : int, optional, largest lag examined (default ``T // 3``)

    Returns
    -------
    dict with ``verdict`` (``'stiction'``, ``'no stiction'``, ``'undetermined'``
    or ``'not applicable'``), ``phase_index`` (``delta_phi / pi``, 0..1, or
    None), ``tau_left_s``, ``tau_right_s``, ``ccf_at_zero`` and ``reason``.
    """
    op, pv = _checked_inputs(op, pv, dt, max_lag)
    out = {"method": "Horch 1999, cross-correlation of OP and PV", "verdict": "undetermined",
           "phase_index": None, "tau_left_s": None, "tau_right_s": None, "ccf_at_zero": None,
           "reason": ""}
    if plant == "integrating":
        out.update(verdict="not applicable",
                   reason="the test assumes a self-regulating process; this level integrates")
        return out
    n = len(op)
    if n < 20:
        out["reason"] = "too short (fewer than 20 samples)"
        return out
    t = np.arange(n)
    op_d = op - np.polyval(np.polyfit(t, op, 1), t)
    pv_d = pv - np.polyval(np.polyfit(t, pv, 1), t)
    for name, x, xd in (("OP", op, op_d), ("PV", pv, pv_d)):
        if np.std(xd) <= 1e-9 * max(np.ptp(x), np.abs(x).max(), 1e-300):
            out["reason"] = f"the {name} is constant or a straight ramp: nothing oscillates"
            return out
    L = int(max_lag or max(n // 3, 2))
    lags, c = _ccf(pv_d, op_d, L)                 # c[L + k]: PV k samples after OP
    out["ccf_at_zero"] = float(c[L])
    if c[L] == 0.0:      # an exact zero at lag 0 is the crossing of an odd function: count it once
        c = c.copy()
        c[L] = 1e-12 * (np.sign(c[L + 1]) or 1.0)
    bound = 2.0 / np.sqrt(n)
    if np.max(np.abs(c)) < bound:
        out["reason"] = f"no correlation between OP and PV (|ccf| < {bound:.3f})"
        return out
    tr = _first_crossing(c[L:])
    tl = _first_crossing(c[L::-1])
    if tr is None or tl is None:
        out["reason"] = "the cross-correlation does not cross zero on both sides: no oscillation"
        return out
    out["tau_left_s"], out["tau_right_s"] = float(tl * dt), float(tr * dt)
    half = tl + tr                       # half a period of the oscillation, in samples
    if half < 4:
        out["reason"] = ("the cross-correlation changes sign within a few samples: no oscillation "
                         "slower than 8 samples")
        return out
    m = int(np.ceil(half))
    if np.max(np.abs(c[max(L - m, 0):L + m + 1])) < 1.5 * bound:
        out["reason"] = f"no significant correlation within half a period of lag 0 (< {1.5 * bound:.3f})"
        return out
    idx = abs(tr - tl) / (tr + tl)
    out["phase_index"] = float(idx)
    if idx < 1 / 3:
        out.update(verdict="no stiction",
                   reason="even cross-correlation: OP and PV swing in counter-phase (tuning or a "
                          "disturbance)")
    elif idx > 2 / 3:
        out.update(verdict="stiction",
                   reason="odd cross-correlation: OP and PV are about a quarter period out of "
                          "phase, as behind a sticking valve")
    else:
        out["reason"] = "between odd and even"
    return out
