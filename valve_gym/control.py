"""The PI control law, batched: the one implementation of the PI in valve_gym.

Used by the environment's residual mode, the controller blocks of
``valve_gym/agents/controllers`` and the figures.

Velocity (incremental) form, as run by distributed control systems::

    u_k = sat( u_{k-1} + Kc*(e_k - e_{k-1}) + Kc*Ts/Ti * e_k ),   e = sp - pv

The saturation of the accumulated output is the anti-windup (the integral
cannot run past the output limits), and starting from the current output
``u0`` with ``e_{-1} = e_0`` makes the start bumpless.

The same law in positional form with an explicit integral ``I`` (the form of
the DCS function blocks in :mod:`valve_gym.agents.controllers`) is :func:`pi_scan1`,
one compiled scan of one loop, and its batched numpy faces :func:`pi_scan` and
:func:`pi_track`::

    I_k = I_{k-1} + g_k Kc*Ts/Ti * e_k,  v_k = Kc*e_k + I_k,     u_k = sat(v_k + b_k)
    I_k <- u_k - b_k - Kc*e_k           (output tracking, only where sat() acted)

with ``b`` what a compensator adds to the PI output and ``g`` an integrator
gate in [0, 1] (1: plain PI; 0: a frozen integral, a dead zone). With
``b = 0`` and ``g = 1`` the two forms give the same outputs: :func:`pi_step`
is written with them. :func:`pi_scan1` also runs the law with the integral
advanced *after* the output (``integrate_first=False``: ``v_k = Kc e_k +
I_{k-1} + b_k``, then ``I_k = I_{k-1} + g_k Kc Ts/Ti e_k`` unless tracked), the
form of the regulation block (:class:`valve_gym.envs.regulation.BlockLaw`).
The formulas are written once, in the compiled helpers :func:`integral_gain`,
:func:`pi_integrate` and :func:`pi_tracked`; the numpy functions evaluate the
same Python functions (``.py_func``) on arrays.

numba's on-disk cache (``cache=True``) of a compiled caller such as the regulation
block's ``_law_act`` is keyed on the caller's own file: after editing this module,
delete the callers' ``__pycache__/*.nbi`` and ``*.nbc`` files (a fresh install has
none), or they keep the old law.

References
----------
.. [1] K.J. Åström, T. Hägglund, "Advanced PID control", ISA, 2006, sec. 3.5
   (windup) and 13.5 (incremental algorithms).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ._numba import njit

__all__ = ["PIParams", "PIState", "pi_init", "pi_step", "pi_scan", "pi_track", "pi_scan1", "integral_gain",
           "pi_integrate", "pi_tracked"]


@njit(cache=True, nogil=True)
def integral_gain(Kc, Ti, Ts):
    """Integral gain per scan ``ki = Kc Ts / Ti`` [output fraction per PV unit per scan].

    Parameters
    ----------
    Kc : float or (n,), gain [output fraction per PV unit]
    Ti : float or (n,), integral time [s] (> 0)
    Ts : float, scan time [s]

    Examples
    --------
    >>> round(integral_gain(1.89, 42.4, 1.0), 6)
    0.044575
    """
    return Kc * Ts / Ti


@njit(cache=True, nogil=True)
def pi_integrate(integral, e, ki, gate):
    """The integral after one scan: ``I + gate ki e`` (``gate`` in [0, 1]; 1 for the plain PI)."""
    return integral + gate * ki * e


@njit(cache=True, nogil=True)
def pi_tracked(applied, bias, p):
    """Integral that reproduces the applied output: ``I = u_applied - b - p`` (``p = Kc e``)."""
    return applied - bias - p


@njit(cache=True, nogil=True)
def pi_scan1(integral, e, kc, ki, gate, bias, lo, hi, integrate_first=True):  # pragma: no cover - compiled
    """One scan of the positional PI of one loop, limits and tracking anti-windup included.

    Parameters
    ----------
    integral : float, integral part before the scan [output fraction]
    e : float, control error ``sp - pv`` [PV unit]
    kc : float, gain [output fraction per PV unit]
    ki : float, integral gain per scan (:func:`integral_gain`)
    gate : float, integrator gate in [0, 1] (1: plain PI, 0: frozen integral)
    bias : float, what a compensator adds to the PI output [output fraction]
    lo, hi : float, output limits
    integrate_first : bool
        True: the integral advances before the output (``v = Kc e + I_k + b``, the DCS blocks and
        :func:`pi_scan`); False: after it (``v = Kc e + I_{k-1} + b``, the regulation block).

    Returns
    -------
    u : float, the output ``sat(v)``
    integral : float, the integral after the scan (tracked, ``u - b - Kc e``, where ``sat`` acted)
    """
    p = kc * e
    if integrate_first:
        integral = pi_integrate(integral, e, ki, gate)
    v = p + integral + bias
    u = min(max(v, lo), hi)
    if u != v:  # tracking; b and p subtracted in the order each form has always used (same bits)
        return u, pi_tracked(u, bias, p) if integrate_first else pi_tracked(u, p, bias)
    if integrate_first:
        return u, integral
    return u, pi_integrate(integral, e, ki, gate)


@dataclass(frozen=True)
class PIParams:
    """PI settings.

    Parameters
    ----------
    Kc : float or (n,), controller gain [output fraction per PV unit]; > 0 for
        reverse action (more output raises the PV, as for an inflow valve).
    Ti : float or (n,), integral time [s] (> 0).
    Ts : float, sample time [s] (> 0).
    u_lo, u_hi : float, output limits (0..1 by default).
    """

    Kc: float | np.ndarray = 1.0
    Ti: float | np.ndarray = 20.0
    Ts: float = 1.0
    u_lo: float = 0.0
    u_hi: float = 1.0

    def __post_init__(self):
        for name in ("Kc", "Ti", "Ts", "u_lo", "u_hi"):
            v = np.asarray(getattr(self, name), float)
            if not np.isfinite(v).all():
                raise ValueError(f"PIParams.{name} must be finite, got {getattr(self, name)!r}")
        if np.any(np.asarray(self.Ti) <= 0):
            raise ValueError(f"PIParams.Ti must be > 0 s, got {self.Ti!r}")
        if self.Ts <= 0:
            raise ValueError(f"PIParams.Ts must be > 0 s, got {self.Ts!r}")
        if not self.u_lo < self.u_hi:
            raise ValueError(f"PIParams needs u_lo < u_hi, got {self.u_lo}, {self.u_hi}")


class PIState(NamedTuple):
    """``u`` (n,) last output, ``e`` (n,) last error."""

    u: np.ndarray
    e: np.ndarray


def pi_init(u0, e0) -> PIState:
    """Bumpless start from the current output ``u0`` and error ``e0``."""
    u0 = np.array(u0, dtype=float, ndmin=1)
    e0 = np.broadcast_to(np.asarray(e0, float), u0.shape).copy()
    return PIState(u=u0.copy(), e=e0)


def pi_scan(integral, e, Kc, Ti, Ts, integrate=True):
    """One scan of the positional PI law, before the output limits.

    Parameters
    ----------
    integral : (n,) array, integral part ``I_{k-1}`` [output fraction]
    e : (n,) array, control error ``sp - pv`` [PV unit]
    Kc : float or (n,), gain [output fraction per PV unit]
    Ti : float or (n,), integral time [s]
    Ts : float, scan time [s]
    integrate : bool or (n,) bool array, where the integral advances (False
        freezes it: a dead zone in the integral)

    Returns
    -------
    p : (n,) array, proportional part ``Kc e_k``
    integral : (n,) array, ``I_k = I_{k-1} + Kc Ts/Ti e_k`` (where integrating)
    v : (n,) array, unlimited PI output ``p + I_k``

    Examples
    --------
    >>> p, i, v = pi_scan(np.array([0.5]), np.array([0.1]), 1.0, 10.0, 1.0)
    >>> float(p[0]), round(float(i[0]), 6), round(float(v[0]), 6)
    (0.1, 0.51, 0.61)
    """
    e = np.asarray(e, float)
    p = Kc * e
    integral = np.where(integrate, pi_integrate.py_func(integral, e, integral_gain.py_func(Kc, Ti, Ts), 1.0),
                        integral)
    return p, integral, p + integral


def pi_track(applied, bias, p):
    """Integral part that reproduces the applied output (external reset).

    ``I = u_applied - b - Kc e``: the integrator follows the output actually
    sent to the valve, minus what a compensator added (``bias``), so it cannot
    wind up while the limits clamp, and restarts bumplessly from any output.

    Examples
    --------
    >>> float(pi_track(1.0, 0.0, 0.3))
    0.7
    """
    return pi_tracked.py_func(np.asarray(applied, float), bias, p)


def pi_step(state: PIState, e, p: PIParams):
    """One sample of the PI law: ``(state, e (n,)) -> (state, u (n,))``.

    Examples
    --------
    >>> s = pi_init(0.5, 0.0)
    >>> s, u = pi_step(s, 0.1, PIParams(Kc=1.0, Ti=10.0, Ts=1.0))
    >>> round(float(u[0]), 3)  # 0.5 + 1*(0.1-0) + 1*1/10*0.1
    0.61
    """
    e = np.asarray(e, float)
    integral = pi_track(state.u, 0.0, p.Kc * state.e)
    _, _, u = pi_scan(integral, e, p.Kc, p.Ti, p.Ts)
    u = np.minimum(np.maximum(u, p.u_lo), p.u_hi)
    e_new = e.copy() if e.shape == u.shape else np.full(u.shape, e)
    return PIState(u=u, e=e_new), u
