"""Hägglund's knocker: short pulses added to the PI output in the direction it moves.

Law (Hägglund 2002 [1]_; patent US 6 285 913 [2]_, claim 1: the compensating
signal has the sign of the time-derivative of the control signal; claim 2: as
a pulse train)::

    u_out(t) = sat( u(t) + u_k(t) )
    u_k(t)   = a sign( I(t_p) - I(t_p - h_k) )    for t_p <= t < t_p + tau_k
    u_k(t)   = 0                                  for t_p + tau_k <= t < t_p + h_k

with ``u`` the PI output, ``I`` its **integral part**, ``t_p = 0, h_k, 2 h_k,
...`` the pulse starts, ``a`` the amplitude, ``tau_k`` the width and ``h_k``
the time between pulses. The direction comes from the change of the integral
part since the previous pulse, as in the paper: the raw output difference
contains ``Kc`` times the change of the measurement noise and would flip the
pulses at random; the integral part moves only with the sign of the error.
No change, no pulse. The pulses never enter the PI's integral (it tracks only
the output limits, :meth:`valve_gym.agents.controllers.pi.PIBlock.finish`).

Parameters from the stiction estimate ``S`` (defaults)
------------------------------------------------------
The paper leaves three parameters and gives their roles: the pulse short
against the loop dynamics, the period long enough for the valve to answer
one pulse before the next, the amplitude (with the width, the pulse energy
``a tau_k``) large enough to move the stem. The values below follow the
recommendations reported for the paper in the stiction-compensation
literature (pulse width one controller sample, period a few widths, amplitude
of the order of the stick band); they were not re-checked against the full
text here.

* ``tau_k = scan_s`` (one scan): the shortest pulse a sampled controller
  applies, two orders of magnitude below the default tank's 80 s time constant.
* ``h_k = 3 scan_s``: the middle of the reported 2-5 pulse widths, so the
  valve settles between pulses.
* ``a = S/2``: with Choudhury's model a reversal needs an input change ``S``;
  a pulse ``+a`` before the reversal and ``-a`` after it contribute ``2a``, so
  ``a = S/2`` makes the pulses alone carry the stem through the band, and a
  larger ``a`` only adds travel (Srinivasan & Rengaswamy 2008 [3]_ find the
  result governed by ``a`` and the travel growing with it). The choice of
  ``S/2`` within "of the order of the band" is a rule derived for valve_gym.

The knocker pulses whether or not the valve sticks: on a healthy valve, and
at the set point under noise, it adds valve travel (the benchmark reports it).

Every setting can be given explicitly (``a``, ``tau_k``, ``h_k``); ``tau_k``
and ``h_k`` are whole numbers of scans with ``h_k > tau_k``.

References
----------
.. [1] T. Hägglund, "A friction compensator for pneumatic control valves",
   Journal of Process Control 12 (2002) 897-904.
.. [2] T. Hägglund, "Method and device for friction compensation",
   US patent 6 285 913 B1 (2001), Alfa Laval Automation.
.. [3] R. Srinivasan, R. Rengaswamy, "Approaches for efficient stiction
   compensation in process control valves", Computers & Chemical Engineering
   32 (2008) 218-229.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .block import Setting, whole_scans
from .compensator import S_SETTING, Compensator
from .pi import PIBlockState

__all__ = ["Knocker", "KnockerState"]


class KnockerState(NamedTuple):
    """Memory of a :class:`Knocker`, each field ``(n,)``.

    Attributes
    ----------
    pi : PIBlockState, the wrapped PI's memory
    phase : scans since the start of the current pulse period (a pulse starts at 0)
    i_ref : integral part at the start of the last pulse [output fraction]
    sign : sign of the current pulse (-1, 0, 1)
    """

    pi: PIBlockState
    phase: np.ndarray
    i_ref: np.ndarray
    sign: np.ndarray


class Knocker(Compensator):
    """PI plus Hägglund's knocker pulses (batched DCS block).

    Parameters
    ----------
    **settings
        PI settings (``Kc``, ``Ti``, ``detune``, ``scan_s``, ``op_lo``,
        ``op_hi``), ``S`` [-] and optionally ``a`` [-], ``tau_k`` [s],
        ``h_k`` [s] (module docstring).

    Examples
    --------
    >>> k = Knocker(S=0.04, Kc=1.0, Ti=10.0)       # a = 0.02, tau_k = 1 s, h_k = 3 s
    >>> k.reset(1.0, 1.0, 0.5)
    >>> pulses = []
    >>> for _ in range(6):                 # error +1 cm: the integral rises, pulses up
    ...     op = k.step(1.0, 0.99)
    ...     pulses.append(round(op - float(k.state.pi.integral[0]) - 0.01, 4))
    >>> pulses
    [0.02, 0.0, 0.0, 0.02, 0.0, 0.0]
    """

    name = "knocker"
    OWN_SETTINGS = (
        S_SETTING,
        Setting("a", "-", None, 0.0, 1.0, "pulse amplitude, fraction of stroke; default S/2", per_loop=True),
        Setting("tau_k", "s", None, 0.0, 3600.0, "pulse width; default one scan", lo_open=True),
        Setting("h_k", "s", None, 0.0, 36000.0, "time between pulse starts; default 3 scans", lo_open=True),
    )

    def _rules(self, s: dict) -> dict:
        s["a"] = s["S"] / 2.0 if s["a"] is None else s["a"]
        s["tau_k"] = s["scan_s"] if s["tau_k"] is None else s["tau_k"]
        s["h_k"] = 3.0 * s["scan_s"] if s["h_k"] is None else s["h_k"]
        self.width = whole_scans(self.name, "tau_k", s["tau_k"], s["scan_s"])
        self.period = whole_scans(self.name, "h_k", s["h_k"], s["scan_s"])
        if self.period <= self.width:
            raise ValueError(f"{self.name}: settings need h_k > tau_k (a quiet time between pulses), "
                             f"got tau_k = {s['tau_k']:g} s, h_k = {s['h_k']:g} s")
        return s

    def initial_state(self, sp, pv, op) -> KnockerState:
        """Bumpless start; the first pulse at the first scan."""
        pis = self.pi.initial_state(sp, pv, op)
        n = pis.op.shape[0]
        return KnockerState(pi=pis, phase=np.zeros(n), i_ref=pis.integral.copy(), sign=np.zeros(n))

    def advance(self, state: KnockerState, sp, pv):
        """One scan: PI output plus the pulse, ``(state, sp, pv) -> (state, op)``."""
        scan = self.pi.propose(state.pi, sp, pv)
        start = state.phase == 0
        sign = np.where(start, np.sign(scan.integral - state.i_ref), state.sign)
        pulse = np.where(state.phase < self.width, self.p["a"] * sign, 0.0)
        _, op = self.pi.finish(scan, pulse)
        # the integral tracks the PI's own limits only: a pulse cut by a limit lasts one pulse, and
        # letting its cut part into the integral would shift the PI output for good (a steady offset
        # wherever the valve works within a of a limit)
        alone, _ = self.pi.finish(scan)
        pis = PIBlockState(integral=alone.integral, op=op)
        i_ref = np.where(start, pis.integral, state.i_ref)
        phase = (state.phase + 1) % self.period
        return KnockerState(pi=pis, phase=phase, i_ref=i_ref, sign=sign), op
