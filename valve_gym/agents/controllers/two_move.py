"""Two-move compensator (Srinivasan & Rengaswamy 2005, 2008): place the stem in two moves, then hold.

Idea [1]_ [2]_: at a constant set point a PI cycles a sticky valve because no
stem position it can reach gives zero error. With an estimate of the band
``S``, the slip ``J`` and of the steady valve position, two moves put the stem
where the error is zero: the first breaks the valve free (overshooting by the
band), the second, in the opposite direction, lands it; then the output is
held, and the limit cycle is gone after two reversals.

State machine (one loop; all loops run it side by side)
-------------------------------------------------------
``NORMAL``
    PI output. The direction of the PI's integral part is followed with the
    noise-robust hysteresis of
    :func:`valve_gym.agents.controllers.compensator.integral_direction`; at each
    reversal the extreme PI output of the phase that ended is kept
    (``u_hi`` after a rise, ``u_lo`` after a fall). At the third or a later
    reversal (so a whole cycle lies between reversals, not the approach to the
    set point) with ``u_hi - u_lo >= S/2`` (a cycle as large as stiction
    makes), the valve's steady position ``x_ss`` is estimated (below), and with
    ``d`` the direction that just ended:

    * **move 1** (this scan): ``op1 = u_ext + d S``, ``u_ext`` the extreme the
      valve stuck at, or further in direction ``d`` if the valve estimate
      (below) says the breakaway lies further (``S/2`` past it): the valve
      slips on in direction ``d``;
    * go to ``MOVE2``.
``MOVE2``
    **move 2**: ``op2 = x_ss - d (S - J)/2``. A reversal of more than ``S``
    (``op1 - op2 >= S + (S - J)/2``), so the valve breaks away and, moving in
    direction ``-d``, stops with its stem at ``op2 + d (S - J)/2 = x_ss``
    (Choudhury's model: a moving stem lags the input by ``(S - J)/2``). The
    PI's integral tracks ``op2`` (bumpless). Go to ``HOLD``.
``HOLD``
    The output stays ``op2`` and the PI's integral tracks it (the tracking
    mode of a DCS block). When the error leaves the band ``release`` or the
    set point changes (a load change or a new operating point, not the
    stiction cycle), the block returns to ``NORMAL``; the PI resumes from
    ``op2`` without a bump.

The steady stem position ``x_ss`` is the mean over the last full cycle (the
two half cycles before the trigger) of the stem estimated by running
Choudhury's model with ``S``, ``J`` on the block's own output
(:func:`valve_estimate`): with integral action the mean error over a cycle is
close to zero, so the mean stem is close to the position that holds the
level at the set point.

Defaults from the estimates: ``J = S/2`` when no slip estimate is given (the
middle of ``0 <= J <= S``), ``hyst`` as for constant reinforcement,
``release = max(S/(2 Kc), 4 noise)``: the error amplitude ``S/(2 Kc)`` of the
stick-slip cycle a PI runs with a band ``S`` (derived, DOMAIN O8; an error the
PI's own cycle would have anyway), and at least four standard deviations of
the measurement noise (a single noisy sample beyond ``4 noise`` has a
probability of 6e-5: about one false release in four hours at 1 s scans). A stem placed off
target by the estimates' error leaves a steady offset inside this band (or,
outside it, a release and a new cycle until the next two moves): the moves are
open loop and rely on ``S``, ``J`` and ``x_ss`` (the benchmark reports the
sensitivity to a wrong ``S``).

References
----------
.. [1] R. Srinivasan, R. Rengaswamy, "Stiction compensation in process control
   loops: a framework for integrating stiction measure and compensation",
   Industrial & Engineering Chemistry Research 44 (2005) 9164-9174.
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
from .pi import PIBlockState, PIScan

__all__ = ["TwoMove", "TwoMoveState", "ValveEstimate", "valve_estimate", "NORMAL", "MOVE2", "HOLD"]

NORMAL, MOVE2, HOLD = 0.0, 1.0, 2.0


class ValveEstimate(NamedTuple):
    """Choudhury's two-parameter valve model run on the block's own output, each field ``(n,)``.

    Attributes
    ----------
    x : estimated stem position [0..1]
    u_s : input at which the valve stuck [0..1]
    stuck : 1 while stuck, 0 while moving
    d : direction of the last motion (-1, 0, 1)
    u_prev : last input [0..1]
    """

    x: np.ndarray
    u_s: np.ndarray
    stuck: np.ndarray
    d: np.ndarray
    u_prev: np.ndarray


def valve_estimate(v: ValveEstimate, u: np.ndarray, S: float, J: float) -> ValveEstimate:
    """One sample of Choudhury's model (DOMAIN 1.2) on the input ``u`` (n,).

    Examples
    --------
    >>> v = ValveEstimate(*(np.zeros(1) for _ in range(5)))._replace(stuck=np.ones(1))
    >>> for u in [0.01, 0.03, 0.05, 0.04, 0.0]:
    ...     v = valve_estimate(v, np.array([u]), 0.04, 0.02)
    ...     print(round(float(v.x[0]), 3), int(v.stuck[0]))
    0.0 1
    0.0 1
    0.04 0
    0.04 1
    0.01 0
    """
    du = u - v.u_prev
    moving = v.stuck == 0
    keeps = moving & (np.sign(du) == v.d) & (v.d != 0)
    stops = moving & ~keeps
    u_s = np.where(stops, v.u_prev, v.u_s)
    dx = u - u_s
    reverse = (v.d == 0) | (np.sign(dx) != v.d)
    slips = ~keeps & (np.abs(dx) > np.where(reverse, S, J))
    d = np.where(slips, np.sign(dx), v.d)
    go = keeps | slips
    x = np.where(go, u - d * (S - J) / 2.0, v.x)
    return ValveEstimate(x=x, u_s=u_s, stuck=np.where(go, 0.0, 1.0), d=d, u_prev=u.copy())


class TwoMoveState(NamedTuple):
    """Memory of a :class:`TwoMove`, each field ``(n,)``.

    Attributes
    ----------
    pi : PIBlockState
    mode : NORMAL (0), MOVE2 (1) or HOLD (2)
    d : direction of the PI's integral part (-1, 0, 1)
    i_ext : extreme of the integral part since the last reversal
    op_ext : extreme PI output since the last reversal [0..1]
    u_hi, u_lo : PI output at the last top and bottom reversal [0..1] (NaN: none yet)
    op2 : output of move 2 and of the hold [0..1]
    sp_hold : set point when the hold began [m]
    valve : ValveEstimate, Choudhury model of the valve driven by the output
    x_sum, n_sum : sum and count of the estimated stem over the current half cycle
    x_prev, n_prev : the same over the previous half cycle
    turns : reversals of the PI output since the cycle detector (re)started
    """

    pi: PIBlockState
    mode: np.ndarray
    d: np.ndarray
    i_ext: np.ndarray
    op_ext: np.ndarray
    u_hi: np.ndarray
    u_lo: np.ndarray
    op2: np.ndarray
    sp_hold: np.ndarray
    valve: ValveEstimate
    x_sum: np.ndarray
    n_sum: np.ndarray
    x_prev: np.ndarray
    n_prev: np.ndarray
    turns: np.ndarray


class TwoMove(Compensator):
    """PI that, once a stiction cycle shows, places the stem in two moves and holds it.

    Parameters
    ----------
    **settings
        PI settings, ``S`` [-], ``noise`` [m], and optionally ``J`` [-],
        ``hyst`` [-], ``release`` [-] (module docstring).

    Examples
    --------
    A PI output cycling between 0.475 and 0.525 with ``S = 0.04`` (the valve
    estimate never moved, so ``x_ss = 0.50``): at the third reversal move 1
    goes ``S`` above the top (0.565), move 2 to
    ``x_ss - d (S - J)/2 = 0.50 - 0.01`` (``d = +1``, ``J = S/2``), then the
    output holds:

    >>> tm = TwoMove(S=0.04, Kc=1.0, Ti=1.0, hyst=0.001)
    >>> tm.reset(1.0, 1.0, 0.5)
    >>> errors = [0.005] * 4 + [-0.005] * 8 + [0.005] * 8 + [-0.005] * 3
    >>> ops = [tm.step(1.0, 1.0 - e) for e in errors]
    >>> [round(o, 3) for o in ops[-5:]]
    [0.52, 0.525, 0.565, 0.49, 0.49]
    """

    name = "two_move"
    OWN_SETTINGS = (
        S_SETTING,
        NOISE_SETTING,
        J_SETTING,
        HYST_SETTING,
        Setting("release", "m", None, 0.0, 10.0, "error that ends the hold; default max(S/(2 Kc), 4 noise)",
                lo_open=True, per_loop=True),
    )

    def _rules(self, s: dict) -> dict:
        s = slip_and_hysteresis(self.name, self.pi, s)
        if s["release"] is None:
            s["release"] = as_setting(np.maximum(s["S"] / (2.0 * self.pi.Kc), 4.0 * s["noise"]))
            if np.any(np.asarray(s["release"]) <= 0):
                raise ValueError(f"{self.name}: S = 0 and noise = 0 leave no default release band; "
                                 "give S > 0, noise > 0 or release > 0")
        return s

    def initial_state(self, sp, pv, op) -> TwoMoveState:
        """Bumpless start in NORMAL, no cycle seen yet."""
        pis = self.pi.initial_state(sp, pv, op)
        n = pis.op.shape[0]
        nan = np.full(n, np.nan)
        z = np.zeros(n)
        valve = ValveEstimate(x=pis.op.copy(), u_s=pis.op.copy(), stuck=np.ones(n), d=z, u_prev=pis.op.copy())
        return TwoMoveState(pi=pis, mode=z, d=z, i_ext=pis.integral.copy(), op_ext=pis.op.copy(), u_hi=nan,
                            u_lo=nan.copy(), op2=pis.op.copy(), sp_hold=np.asarray(sp, float).copy(),
                            valve=valve, x_sum=z, n_sum=z, x_prev=z, n_prev=z, turns=z)

    def _normal(self, st: TwoMoveState, scan: PIScan):
        """NORMAL: follow the cycle; returns (state fields, target op, trigger mask)."""
        S, J = self.p["S"], self.p["J"]
        d_old = st.d
        op_ext = np.where(d_old > 0, np.maximum(st.op_ext, scan.v),
                          np.where(d_old < 0, np.minimum(st.op_ext, scan.v), scan.v))
        d, i_ext, flipped = integral_direction(st.d, st.i_ext, scan.integral, self.p["hyst"])
        ended = flipped & (d_old != 0)
        u_hi = np.where(ended & (d_old > 0), op_ext, st.u_hi)
        u_lo = np.where(ended & (d_old < 0), op_ext, st.u_lo)
        cycle = ended & (st.turns >= 2) & (u_hi - u_lo >= S / 2.0)
        lo, hi = self.p["op_lo"], self.p["op_hi"]
        op1 = np.clip(self._move1(st.valve, np.where(d_old > 0, u_hi, u_lo), d_old), lo, hi)
        x_ss = (st.x_prev + st.x_sum) / np.maximum(st.n_prev + st.n_sum, 1.0)
        op2 = np.where(cycle, np.clip(x_ss - d_old * (S - J) / 2.0, lo, hi), st.op2)
        target = np.where(cycle, op1, scan.v)
        op_ext = np.where(flipped, scan.v, op_ext)
        started = flipped & (d_old == 0)
        return (d, i_ext, op_ext, u_hi, u_lo, op2, ended, started), target, cycle

    def _move1(self, valve: ValveEstimate, u_ext, d):
        """Move 1: ``S`` beyond the extreme ``u_ext`` in direction ``d``, and past the estimated breakaway.

        The valve estimate says where the valve stuck (``u_s``; the last input
        when it moves) and whether going on in ``d`` is a reversal for it
        (threshold ``S``) or not (``J``); the move goes ``S/2`` past that
        threshold, so it breaks the valve free whichever way it last moved.
        """
        S, J = self.p["S"], self.p["J"]
        anchor = np.where(valve.stuck > 0, valve.u_s, valve.u_prev)
        thr = np.where(valve.stuck > 0, np.where(valve.d == d, J, S), np.where(valve.d == d, 0.0, S))
        return d * np.maximum(d * (u_ext + d * S), d * (anchor + d * (thr + S / 2.0)))

    def _averages(self, st: TwoMoveState, valve: ValveEstimate, ended, restart):
        """Half-cycle sums of the estimated stem (shifted at each reversal, cleared on restart)."""
        x_sum, n_sum = st.x_sum + valve.x, st.n_sum + 1.0
        x_prev = np.where(restart, 0.0, np.where(ended, x_sum, st.x_prev))
        n_prev = np.where(restart, 0.0, np.where(ended, n_sum, st.n_prev))
        x_sum = np.where(ended | restart, 0.0, x_sum)
        n_sum = np.where(ended | restart, 0.0, n_sum)
        return x_sum, n_sum, x_prev, n_prev

    def advance(self, state: TwoMoveState, sp, pv):
        """One scan of the state machine: ``(state, sp, pv) -> (state, op)``."""
        S, J = self.p["S"], self.p["J"]
        scan = self.pi.propose(state.pi, sp, pv)
        (d, i_ext, op_ext, u_hi, u_lo, op2, ended, started), target, cycle = self._normal(state, scan)
        normal, move2, hold = state.mode == NORMAL, state.mode == MOVE2, state.mode == HOLD
        release = hold & ((np.abs(scan.e) > self.p["release"]) | (sp != state.sp_hold))
        held = hold & ~release
        target = np.where(normal | release, target, state.op2)
        pis, op = self.pi.finish(scan, target - scan.v)
        tracking = move2 | held   # the integral follows the held output (DCS tracking mode)
        pis = PIBlockState(*(np.where(tracking, t, p) for t, p in zip(self.pi.track(scan, op), pis)))
        valve = valve_estimate(state.valve, op, S, J)
        mode = np.where(normal & cycle, MOVE2, np.where(move2 | held, HOLD, NORMAL))
        restart = move2 | held | release   # the cycle detector starts afresh after a hold
        sums = self._averages(state, valve, ended & normal, restart | (started & normal))
        nan = np.full(op.shape, np.nan)
        new = TwoMoveState(
            pi=pis, mode=mode, d=np.where(restart, 0.0, d), i_ext=np.where(restart, pis.integral, i_ext),
            op_ext=np.where(restart, op, op_ext), u_hi=np.where(restart, nan, u_hi),
            u_lo=np.where(restart, nan, u_lo), op2=np.where(normal, op2, state.op2),
            sp_hold=np.where(move2, sp, state.sp_hold), valve=valve, x_sum=sums[0], n_sum=sums[1],
            x_prev=sums[2], n_prev=sums[3], turns=np.where(restart, 0.0, state.turns + (ended & normal)))
        return new, op
