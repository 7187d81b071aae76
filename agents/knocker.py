"""PI + knocker: Hägglund's friction compensator for pneumatic control valves.

The knocker adds a train of short pulses to the output of a PI controller;
each pulse gives the sticky valve the extra push it needs to break free, in
the direction the PI output has moved since the previous pulse [1]_::

    u_out(t) = sat( u(t) + u_k(t) )
    u_k(t)   = a * sign( u(t_p) - u(t_p - h_k) )   for t_p <= t < t_p + tau_k
    u_k(t)   = 0                                   for t_p + tau_k <= t < t_p + h_k

where ``u`` is the PI output, ``t_p = 0, h_k, 2 h_k, ...`` are the pulse
times, ``a`` the pulse amplitude, ``tau_k`` the pulse width and ``h_k`` the
time between pulses. The sign is fixed at the start of each pulse from the
change of the PI output since the previous pulse (zero change, no pulse). The
PI controller is wrapped, not copied: it integrates on its own output ``u``,
so the pulses never enter its integrator.

Choice of the parameters
------------------------
Hägglund [1]_ leaves three parameters and gives their roles: the pulse must be
short compared with the loop dynamics so that it moves the valve without
disturbing the process, the period long enough for the valve to respond to one
pulse before the next, and the amplitude (with the width, the pulse energy
``a * tau_k``) large enough to overcome the friction. Srinivasan and
Rengaswamy [2]_ show that the result depends mostly on the amplitude, that a
too large ``a`` only adds valve travel, and that ``a`` is best tied to the
size of the stiction. The rule used here:

* ``tau_k = Ts = 1 s``: one control period, the shortest pulse a sampled
  controller can apply and two orders of magnitude below the tank's 80 s time
  constant;
* ``h_k = 3 Ts = 3 s``: the valve gets two quiet periods to settle between
  pulses (pulse duty cycle 1/3), still short against the loop's ~40 s
  integral time so the compensation acts within one oscillation;
* ``a = 0.02`` (2 % of the stroke): of the size of the dead band plus stick
  band of the sticky valves of the benchmark (``e_dead`` up to 2-4 %). A
  sweep of ``a in {0.01, 0.02, 0.03, 0.05}`` and ``h_k in {2, 3, 5} s`` on
  100 sticky valves (``z_max`` 0.1-1.5 s, ``e_dead`` 0.5-4 %) with the
  benchmark's set-point and load schedule gave median IAE ratios to PI of
  0.98 (``a = 0.01``), 0.97 (``a = 0.02``) and no further gain above, while
  the valve travel grew from 1.03x to 1.12x, 1.3x and 1.7x of PI's; ``h_k``
  of 2 or 3 s were equal, 5 s slightly worse, and 3 s pulses less on healthy
  valves.

The knocker pulses whether or not the valve sticks: on a healthy valve it
adds valve travel for little gain, which the benchmark reports.

References
----------
.. [1] T. Hägglund, "A friction compensator for pneumatic control valves",
   Journal of Process Control 12 (2002) 897-904.
.. [2] R. Srinivasan, R. Rengaswamy, "Stiction compensation in process
   control loops: a framework for integrating stiction measure and
   compensation", Industrial & Engineering Chemistry Research 44 (2005)
   9164-9174.
"""
from __future__ import annotations

from typing import NamedTuple, Optional

import numpy as np

from valve_gym.control import PIState

from .base import as_obs_batch, episode_start_mask, u_to_action
from .pi import PIController

__all__ = ["KnockerController", "KnockerState", "KNOCKER_DEFAULTS"]

#: Default knocker parameters (see the module docstring for the rule).
KNOCKER_DEFAULTS = {"a": 0.02, "tau_k": 1.0, "h_k": 3.0}


class KnockerState(NamedTuple):
    """Batched state of :class:`KnockerController`, every field ``(n,)``.

    Attributes
    ----------
    pi : PIState, state of the wrapped PI controller
    phase : int array, samples since the start of the current pulse period
        (a pulse starts when ``phase == 0``)
    u_ref : float array, PI output at the start of the last pulse
    sign : float array, sign of the current pulse (-1, 0 or 1)
    """

    pi: PIState
    phase: np.ndarray
    u_ref: np.ndarray
    sign: np.ndarray


def _samples(value: float, Ts: float, name: str) -> int:
    k = value / Ts
    ki = int(round(k))
    if ki < 1 or abs(k - ki) > 1e-9 * max(1.0, k):
        raise ValueError(
            f"KnockerController.{name} = {value!r} s must be a whole number (>= 1) of control "
            f"periods Ts = {Ts!r} s; the environment holds each action for one period")
    return ki


class KnockerController:
    """PI controller plus Hägglund's knocker pulses (batched).

    Parameters
    ----------
    pi : PIController, optional
        The wrapped controller (default: :class:`PIController` with its
        default tuning).
    a : float
        Pulse amplitude, fraction of the valve stroke (>= 0).
    tau_k : float
        Pulse width [s], a whole number of control periods.
    h_k : float
        Time between pulse starts [s], a whole number of control periods,
        longer than ``tau_k``.

    Notes
    -----
    See the module docstring for the equations and the choice of the
    defaults. With ``a = 0`` the output equals the PI output exactly.

    Examples
    --------
    >>> import numpy as np
    >>> k = KnockerController(a=0.05, tau_k=1.0, h_k=2.0)
    >>> obs = np.array([[0.9, 1.0, 0.1, 0.5]])
    >>> a0, s = k.predict(obs)    # first pulse: PI output rose since the start
    >>> a1, s = k.predict(obs, s) # pulse over
    >>> u_pi = s.pi.u[0]
    >>> round(float((a0[0, 0] + 1) / 2 - 0.5), 4), round(float((a1[0, 0] + 1) / 2 - u_pi), 4)
    (0.0544, 0.0)
    """

    env_mode = "direct"

    def __init__(self, pi: Optional[PIController] = None, a: float = KNOCKER_DEFAULTS["a"],
                 tau_k: float = KNOCKER_DEFAULTS["tau_k"], h_k: float = KNOCKER_DEFAULTS["h_k"],
                 name: str = "knocker"):
        self.pi = PIController() if pi is None else pi
        if not hasattr(self.pi, "control"):
            raise TypeError(f"KnockerController wraps a PIController, got {type(self.pi).__name__}")
        for nm, v in (("a", a), ("tau_k", tau_k), ("h_k", h_k)):
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not np.isfinite(v):
                raise TypeError(f"KnockerController.{nm} must be a finite number, got {v!r}")
        if a < 0 or a > 1:
            raise ValueError(f"KnockerController.a must be in [0, 1] (fraction of stroke), got {a!r}")
        Ts = self.pi.Ts
        self.width = _samples(float(tau_k), Ts, "tau_k")
        self.period = _samples(float(h_k), Ts, "h_k")
        if self.period <= self.width:
            raise ValueError(
                f"KnockerController needs h_k > tau_k (a quiet time between pulses), got "
                f"tau_k = {tau_k!r} s, h_k = {h_k!r} s")
        self.a = float(a)
        self.tau_k = float(tau_k)
        self.h_k = float(h_k)
        self.name = name

    def __repr__(self) -> str:
        return f"KnockerController(pi={self.pi!r}, a={self.a:g}, tau_k={self.tau_k:g}, h_k={self.h_k:g})"

    def initial_state(self, obs) -> KnockerState:
        """Bumpless start: PI from the observation, first pulse at the next sample."""
        pi_state = self.pi.initial_state(obs)
        n = pi_state.u.shape[0]
        return KnockerState(pi=pi_state, phase=np.zeros(n, dtype=np.int64), u_ref=pi_state.u.copy(),
                            sign=np.zeros(n))

    def control(self, obs, state: Optional[KnockerState] = None, episode_start=None):
        """One sample in valve units: ``(obs, state) -> (u_out (n,), state)``.

        ``state.pi.u`` afterwards holds the PI output without the pulse.
        """
        obs, _ = as_obs_batch(obs)
        n = obs.shape[0]
        if state is None:
            state = self.initial_state(obs)
        else:
            state = KnockerState(*state)
            start = episode_start_mask(episode_start, n)
            if start.any():
                fresh = self.initial_state(obs)
                pis = PIState(*(np.where(start, f, o) for f, o in zip(fresh.pi, PIState(*state.pi))))
                state = KnockerState(pi=pis, phase=np.where(start, 0, state.phase),
                                     u_ref=np.where(start, fresh.u_ref, state.u_ref),
                                     sign=np.where(start, 0.0, state.sign))
        u, pis = self.pi.control(obs, state.pi)
        new_pulse = state.phase == 0
        sign = np.where(new_pulse, np.sign(u - state.u_ref), state.sign)
        u_ref = np.where(new_pulse, u, state.u_ref)
        u_k = np.where(state.phase < self.width, self.a * sign, 0.0)
        u_out = np.clip(u + u_k, self.pi.params.u_lo, self.pi.params.u_hi)
        phase = (state.phase + 1) % self.period
        return u_out, KnockerState(pi=pis, phase=phase, u_ref=u_ref, sign=sign)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style batched prediction; see :class:`agents.base.Controller`."""
        obs, single = as_obs_batch(observation)
        u, state = self.control(obs, state, episode_start)
        a = u_to_action(u)
        return (a[0] if single else a), state
