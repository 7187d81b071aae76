"""Constant reinforcement: ``u_out = u + a sign(du/dt)`` (Ivan & Lakshminarayanan 2009).

Law [1]_::

    u_out(t) = sat( u(t) + a d(t) ),    d(t) = direction of the PI output u

continuously (not pulsed, unlike the knocker): while the controller moves the
valve one way the output is held ``a`` ahead of the PI output, and on a
reversal it jumps by ``2a``. The paper sets ``a`` from the estimated
stiction, at about half the band [1]_ (as reported in the literature; not
re-checked against the full text here). Default here::

    a = (S - J)/2

half the dead band ``S - J`` of Choudhury's model: a moving stem lags its
input by exactly ``(S - J)/2``, which the reinforcement cancels, so the stem
follows the PI output while it moves. For a pure dead band (``J = 0``) this is
the paper's ``a = S/2``; with a slip ``J > 0`` the larger ``a = S/2`` would
push the stem ``J/2`` past the PI output at every reversal and turn the
compensator into a relay that sustains its own oscillation. ``J`` is the
slip estimate (default ``S/2``, the middle of ``0 <= J <= S``).

CR cancels the dead band, not the stick-slip: at a constant set point with
``J > 0`` the PI's stick-slip cycle remains, and on a pure dead band (where a
PI alone settles) the ``2a`` jumps at every reversal of the integral can
sustain a relay-like cycle of their own (``benchmarks/bench_controllers.py``
measures both).

Direction robust to noise: ``d`` is the direction of the PI's **integral
part** with the hysteresis of
:func:`valve_gym.agents.controllers.compensator.integral_direction` (``hyst`` default
``3 Kc noise sqrt(Ts/Ti)``, 0.0017 for the default loop and 2 mm noise), so
measurement noise does not flip the reinforcement every scan (the raw
``sign(Delta u)`` would: ``Delta u`` contains ``Kc`` times the noise's
change). ``d = 0`` (no reinforcement) until the integral has first moved by
``hyst``. The reinforcement never enters the PI's integral.

References
----------
.. [1] L.Z.X. Ivan, S. Lakshminarayanan, "A new unified approach to valve
   stiction quantification and compensation", Industrial & Engineering
   Chemistry Research 48 (2009) 3474-3483.
.. [2] R. Srinivasan, R. Rengaswamy, "Approaches for efficient stiction
   compensation in process control valves", Computers & Chemical Engineering
   32 (2008) 218-229.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .block import Setting
from .compensator import (
    HYST_SETTING,
    J_SETTING,
    NOISE_SETTING,
    S_SETTING,
    Compensator,
    as_setting,
    integral_direction,
    slip_and_hysteresis,
)
from .pi import PIBlockState

__all__ = ["ConstantReinforcement", "CRState"]


class CRState(NamedTuple):
    """Memory of a :class:`ConstantReinforcement`, each field ``(n,)``.

    Attributes
    ----------
    pi : PIBlockState
    d : direction of the PI's integral part (-1, 0, 1)
    i_ext : extreme of the integral part since the last flip [output fraction]
    """

    pi: PIBlockState
    d: np.ndarray
    i_ext: np.ndarray


class ConstantReinforcement(Compensator):
    """PI plus a constant push ``a`` in the direction the PI output moves.

    Parameters
    ----------
    **settings
        PI settings, ``S`` [-], ``noise`` [m], and optionally ``J`` [-],
        ``a`` [-], ``hyst`` [-] (module docstring).

    Examples
    --------
    >>> cr = ConstantReinforcement(S=0.04, J=0.0, Kc=1.0, Ti=10.0, hyst=0.001)   # a = 0.02
    >>> cr.reset(1.0, 1.0, 0.5)
    >>> up = [cr.step(1.0, 0.99) for _ in range(3)]     # integral rises: +a
    >>> round(up[-1] - (float(cr.state.pi.integral[0]) + 0.01), 6)
    0.02
    >>> down = [cr.step(1.0, 1.01) for _ in range(3)]   # falls: -a
    >>> round(down[-1] - (float(cr.state.pi.integral[0]) - 0.01), 6)
    -0.02
    """

    name = "constant_reinforcement"
    OWN_SETTINGS = (
        S_SETTING,
        NOISE_SETTING,
        J_SETTING,
        Setting("a", "-", None, 0.0, 1.0, "reinforcement, fraction of stroke; default (S - J)/2", per_loop=True),
        HYST_SETTING,
    )

    def _rules(self, s: dict) -> dict:
        s = slip_and_hysteresis(self.name, self.pi, s)
        s["a"] = as_setting((s["S"] - s["J"]) / 2.0) if s["a"] is None else s["a"]
        return s

    def initial_state(self, sp, pv, op) -> CRState:
        """Bumpless start, no direction yet."""
        pis = self.pi.initial_state(sp, pv, op)
        return CRState(pi=pis, d=np.zeros(pis.op.shape[0]), i_ext=pis.integral.copy())

    def advance(self, state: CRState, sp, pv):
        """One scan: ``(state, sp, pv) -> (state, op)``."""
        scan = self.pi.propose(state.pi, sp, pv)
        d, i_ext, _ = integral_direction(state.d, state.i_ext, scan.integral, self.p["hyst"])
        pis, op = self.pi.finish(scan, self.p["a"] * d)
        return CRState(pi=pis, d=d, i_ext=i_ext), op
