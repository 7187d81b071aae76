"""The PI control law, batched: the one implementation used by the environment's
residual mode, the PI and knocker controllers of ``agents/`` and the figures.

Velocity (incremental) form, as run by distributed control systems::

    u_k = sat( u_{k-1} + Kc*(e_k - e_{k-1}) + Kc*Ts/Ti * e_k ),   e = sp - pv

The saturation of the accumulated output is the anti-windup (the integral
cannot run past the output limits), and starting from the current output
``u0`` with ``e_{-1} = e_0`` makes the start bumpless.

References
----------
.. [1] K.J. Åström, T. Hägglund, "Advanced PID control", ISA, 2006, sec. 3.5
   (windup) and 13.5 (incremental algorithms).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = ["PIParams", "PIState", "pi_init", "pi_step"]


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

    Kc: float = 1.0
    Ti: float = 20.0
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
    u = state.u + p.Kc * (e - state.e) + (p.Kc * p.Ts / p.Ti) * e
    u = np.minimum(np.maximum(u, p.u_lo), p.u_hi)
    e_new = e.copy() if e.shape == u.shape else np.full(u.shape, e)
    return PIState(u=u, e=e_new), u
