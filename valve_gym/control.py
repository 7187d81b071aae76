"""The PI control law, batched: the one implementation of the PI in valve_gym.

Used by the environment's residual mode, the controller blocks of
``valve_gym/agents/controllers`` and the figures.

Velocity (incremental) form, as run by distributed control systems::

    u_k = sat( u_{k-1} + Kc*(e_k - e_{k-1}) + Kc*Ts/Ti * e_k ),   e = sp - pv

The saturation of the accumulated output is the anti-windup (the integral
cannot run past the output limits), and starting from the current output
``u0`` with ``e_{-1} = e_0`` makes the start bumpless.

The same law in positional form with an explicit integral ``I`` (the form of
the DCS function blocks in :mod:`valve_gym.agents.controllers`) is :func:`pi_scan` and
:func:`pi_track`::

    I_k = I_{k-1} + Kc*Ts/Ti * e_k,     v_k = Kc*e_k + I_k,     u_k = sat(v_k + b_k)
    I_k <- u_k - b_k - Kc*e_k           (output tracking, only where sat() acted)

with ``b`` what a compensator adds to the PI output. With ``b = 0`` the two
forms give the same outputs: :func:`pi_step` is written with them.

References
----------
.. [1] K.J. Åström, T. Hägglund, "Advanced PID control", ISA, 2006, sec. 3.5
   (windup) and 13.5 (incremental algorithms).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = ["PIParams", "PIState", "pi_init", "pi_step", "pi_scan", "pi_track"]


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
    integral = np.where(integrate, integral + (Kc * Ts / Ti) * e, integral)
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
    return np.asarray(applied, float) - bias - p


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
