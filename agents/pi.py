"""PI controller: the baseline a plant would run on the level loop.

The control law itself is :func:`valve_gym.control.pi_step` (velocity form,
output clamped to the valve range, which is the anti-windup, and a bumpless
start from the current output); :class:`PIController` only wraps it behind the
batched ``predict`` interface of :mod:`agents.base`.

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

from typing import NamedTuple, Optional

import numpy as np

from valve_gym.control import PIParams, PIState, pi_init, pi_step
from valve_gym.params import TankParams, ValveParams

from .base import (OBS_ERROR, OBS_U, as_obs_batch, episode_start_mask, u_to_action)

__all__ = ["PIController", "PITuning", "simc_pi", "tank_model", "default_tuning"]

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


class PIController:
    """Batched PI level controller (wraps :func:`valve_gym.control.pi_step`).

    Parameters
    ----------
    Kc : float, optional
        Gain [valve fraction per m of error]; default from :func:`default_tuning`.
    Ti : float, optional
        Integral time [s]; default from :func:`default_tuning`.
    Ts : float
        Control period [s], the environment's (1 s).
    u_lo, u_hi : float
        Output limits (the valve range 0..1); the velocity-form integrator
        cannot run past them (anti-windup).

    Notes
    -----
    ``u_k = sat(u_{k-1} + Kc (e_k - e_{k-1}) + Kc Ts/Ti e_k)`` with
    ``e = sp - y`` taken from the observation. The state is the
    :class:`valve_gym.control.PIState` ``(u, e)`` of the batch; ``state=None``
    (or ``episode_start``) starts it from the observed last valve input and the
    current error, so the first output equals the current input plus one
    integral step (bumpless). Actions are ``2 u - 1`` (direct mode).

    Examples
    --------
    >>> import numpy as np
    >>> pi = PIController(Kc=1.0, Ti=10.0)
    >>> obs = np.array([[0.9, 1.0, 0.1, 0.5], [1.0, 1.0, 0.0, 0.3]], np.float32)
    >>> a, s = pi.predict(obs)
    >>> a.shape, a.dtype.name
    ((2, 1), 'float32')
    >>> np.round((a[:, 0] + 1) / 2, 3)   # 0.5 + 1*1/10*0.1, and unchanged
    array([0.51, 0.3 ], dtype=float32)
    """

    env_mode = "direct"

    def __init__(self, Kc: Optional[float] = None, Ti: Optional[float] = None, Ts: float = 1.0,
                 u_lo: float = 0.0, u_hi: float = 1.0, name: str = "pi"):
        if Kc is None or Ti is None:
            tun = default_tuning(Ts=Ts)
            Kc = tun.Kc if Kc is None else Kc
            Ti = tun.Ti if Ti is None else Ti
        for nm, v in (("Kc", Kc), ("Ti", Ti), ("Ts", Ts)):
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                raise TypeError(f"PIController.{nm} must be a number, got {v!r}")
        if not Kc > 0:
            raise ValueError(f"PIController.Kc must be > 0 (reverse acting inflow valve), got {Kc!r}")
        self.params = PIParams(Kc=float(Kc), Ti=float(Ti), Ts=float(Ts), u_lo=float(u_lo),
                               u_hi=float(u_hi))
        self.name = name

    @property
    def Kc(self) -> float:
        return self.params.Kc

    @property
    def Ti(self) -> float:
        return self.params.Ti

    @property
    def Ts(self) -> float:
        return self.params.Ts

    def __repr__(self) -> str:
        p = self.params
        return f"PIController(Kc={p.Kc:.4g}, Ti={p.Ti:.4g}, Ts={p.Ts:.4g})"

    def initial_state(self, obs) -> PIState:
        """Bumpless start from the observed last valve input and error."""
        obs, _ = as_obs_batch(obs)
        return pi_init(obs[:, OBS_U], obs[:, OBS_ERROR])

    def control(self, obs, state: Optional[PIState] = None, episode_start=None):
        """One PI sample in valve units: ``(obs, state) -> (u (n,), state)``.

        Parameters
        ----------
        obs : (n, obs_dim) array, environment observations
        state : PIState or None
        episode_start : (n,) bool array or None, rows to restart bumplessly

        Returns
        -------
        u : (n,) float64, valve input 0..1
        state : PIState
        """
        obs, _ = as_obs_batch(obs)
        n = obs.shape[0]
        e = obs[:, OBS_ERROR]
        if state is None:
            state = pi_init(obs[:, OBS_U], e)
        else:
            state = PIState(*state)
            if state.u.shape != (n,):
                raise ValueError(f"PI state has batch size {state.u.shape}, observation has {n} rows")
            start = episode_start_mask(episode_start, n)
            if start.any():
                u0 = np.where(start, obs[:, OBS_U], state.u)
                e0 = np.where(start, e, state.e)
                state = PIState(u=u0, e=e0)
        state, u = pi_step(state, e, self.params)
        return u, state

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style batched prediction; see :class:`agents.base.Controller`.

        Returns
        -------
        actions : (n, 1) float32 in [-1, 1] (``(1,)`` for a single observation row)
        state : PIState
        """
        obs, single = as_obs_batch(observation)
        u, state = self.control(obs, state, episode_start)
        a = u_to_action(u)
        return (a[0] if single else a), state
