"""SIMC tuning of the level loop: the default ``Kc``, ``Ti`` of every PI block.

Default tuning (SIMC)
---------------------
Linearising the tank ``A dL/dt = q_max h - k_out sqrt(L)`` at the level ``L0``
gives a first-order process from the valve input to the level::

    K = 2 q_max sqrt(L0) / k_out      [m per unit valve input]
    T = 2 A sqrt(L0) / k_out          [s]

For the default tank (``A = 0.2 m^2, q_max = 0.01 m^3/s, k_out = 0.005
m^2.5/s, L0 = 1 m``) that is ``K = 4 m``, ``T = 80 s``. The effective delay is
half the control period (zero-order hold) plus the valve time constant,
``theta = Ts/2 + tau = 0.6 s``. Skogestad's SIMC rules [1]_ give::

    Kc = T / (K (tau_c + theta)),   Ti = min(T, 4 (tau_c + theta))

The closed-loop time constant is chosen as ``tau_c = 10 s`` (about ``T/8``):
a fast loop for a level that is a few minutes slow, with a proportional kick
of only ``0.19`` of the stroke on a ``0.1 m`` set-point step and little
amplification of measurement noise; ``tau_c = theta`` (SIMC "tight") would
give ``Kc = 33``, far too nervous for a sticky valve. Result:
``Kc = 1.89 1/m``, ``Ti = 42.4 s``. On a friction-free valve (no noise) this loop
answers a 0.1 m set-point step with 5.5 % overshoot, settles within 2 mm in
95 s and removes the steady-state error of a load step (checked in
``tests/test_agents.py``).

References
----------
.. [1] S. Skogestad, "Simple analytic rules for model reduction and PID
   controller tuning", Journal of Process Control 13 (2003) 291-309.
.. [2] K.J. Åström, T. Hägglund, "Advanced PID control", ISA, 2006.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from valve_gym.params import TankParams, ValveParams

__all__ = ["PITuning", "simc_pi", "tank_model", "default_tuning", "DEFAULT_TAU_C"]

#: Closed-loop time constant of the default tuning [s].
DEFAULT_TAU_C = 10.0


class PITuning(NamedTuple):
    """PI settings with the numbers they came from.

    Attributes
    ----------
    Kc : float, controller gain [1/m]
    Ti : float, integral time [s]
    K : float, process gain [m per unit valve input]
    T : float, process time constant [s]
    theta : float, effective delay [s]
    tau_c : float, chosen closed-loop time constant [s]
    """

    Kc: float
    Ti: float
    K: float
    T: float
    theta: float
    tau_c: float


def tank_model(tank: TankParams = TankParams(), level: float = 1.0):
    """First-order model ``(K, T)`` of the tank linearised at ``level``.

    Parameters
    ----------
    tank : TankParams, scalar fields
    level : float, operating level [m] (> 0)

    Returns
    -------
    K : float, gain from valve input (0..1) to level [m]
    T : float, time constant [s]

    Examples
    --------
    >>> K, T = tank_model()
    >>> round(K, 6), round(T, 6)
    (4.0, 80.0)
    """
    if not level > 0:
        raise ValueError(f"level must be > 0 m to linearise the tank, got {level!r}")
    k = float(tank.k_out)
    if k <= 0:
        raise ValueError("tank.k_out must be > 0 for a self-regulating tank model")
    s = np.sqrt(level)
    return float(2.0 * float(tank.q_max) * s / k), float(2.0 * float(tank.area) * s / k)


def simc_pi(K: float, T: float, theta: float, tau_c: float) -> tuple:
    """SIMC PI settings for ``K exp(-theta s)/(T s + 1)`` (Skogestad 2003).

    ``Kc = T / (K (tau_c + theta))``, ``Ti = min(T, 4 (tau_c + theta))``.

    Examples
    --------
    >>> Kc, Ti = simc_pi(4.0, 80.0, 0.6, 10.0)
    >>> round(Kc, 3), round(Ti, 1)
    (1.887, 42.4)
    """
    for name, v in (("K", K), ("T", T), ("tau_c", tau_c)):
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive number, got {v!r}")
    if not (np.isfinite(theta) and theta >= 0):
        raise ValueError(f"theta must be >= 0 s, got {theta!r}")
    Kc = T / (K * (tau_c + theta))
    Ti = min(T, 4.0 * (tau_c + theta))
    return float(Kc), float(Ti)


def default_tuning(tank: TankParams = TankParams(), level: float = 1.0, Ts: float = 1.0,
                   valve: ValveParams = ValveParams(), tau_c: float = DEFAULT_TAU_C) -> PITuning:
    """SIMC tuning of the level loop (see the module docstring).

    Examples
    --------
    >>> t = default_tuning()
    >>> round(t.Kc, 2), round(t.Ti, 1), t.theta
    (1.89, 42.4, 0.6)
    """
    K, T = tank_model(tank, level)
    theta = 0.5 * Ts + float(np.max(valve.tau))
    Kc, Ti = simc_pi(K, T, theta, tau_c)
    return PITuning(Kc=Kc, Ti=Ti, K=K, T=T, theta=theta, tau_c=tau_c)
