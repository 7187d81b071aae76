"""Adaptive stiction compensator: a PI whose reinforcement and knocker pulses follow an online stick-band estimate.

The block needs no stiction estimate: it measures the stick band ``S_hat`` from its own signals, as
the output travel between a reversal of its output and the moment the measurement answers it, and
sizes its compensation by it. Per scan (``e = sp - pv``, PI as :class:`~.pi.PIBlock` with integral
time ``ti_factor * Ti``, ``a = min(1, Ts / (f_tau Ti))``)::

    sigma <- sigma + r (0.63 |e_k - e_{k-1}| - sigma)     measurement noise (r = max(Ts/200 s, 1/k))
    e_f   <- e_f + a (e - e_f);  s <- s + a ((e_f - e_f,prev)/Ts - s)     trend of the error
    d      = direction of the PI's integral part, hysteresis c_h Kc sigma sqrt(Ts/Ti) (integral_direction)
    o      = Kc e_f + I + k_c S_hat d                    the sustained output (no pulses, filtered P part)
    o_flip = the extreme of o against d since the flip (where the output turned); s_0 the trend at the flip; armed
    while armed, once d (s_0 - s) > c_d a^1.5 sigma / (sqrt(2) Ts)   (the error's trend turned: the valve moved;
        with answer = 1, s_0 is taken as 0 where d s_0 > 0: the trend must turn against d, not only slow down)
        S_hat <- clip(S_hat + eta g (beta |o - o_flip| - S_hat), 0.001, 0.2); disarmed
        (g = 1 for a measurement above the estimate, rho below: reversals within the noise, answered
        at once and far more frequent than the stick-slip cycle's, wear it down only slowly)
    at a flip while still armed: the travel so far is a lower bound; S_hat rises to it at the rate eta
    u = sat(o + pulse),  pulse = k_k S_hat d one scan in every three
    (k_i > 0: while armed, each scan's integral increment is taken 1 + k_i times)
    (k_z > 0: the integral holds while |e_f| < k_z S_hat / (2 Kc), an integral dead zone sized to the
    stick-slip cycle's error amplitude S/(2 Kc) on a valve of band S_hat)
    (confirm > 0: an answer counts only once the trend has stayed turned for confirm f_tau Ti seconds, its
    travel the one at the turn; a turn that goes back first was the load's or the noise's, and the block waits on)

With a sticky valve the output has to travel the stick band after a reversal before the stem moves
and the error's trend turns, so the travel measures ``S`` (the reinforcement ``2 k_c S_hat`` jumped
at the flip included; with ``2 k_c < 1`` an estimate above ``S`` shrinks, one below grows). On a
healthy valve the trend turns at once and the estimate falls to the noise's level. The
reinforcement (Ivan & Lakshminarayanan 2009) carries the stem through the band at each reversal,
the pulses (Hägglund 2002) move it in small steps while the output ramps.

The ten numbers of :data:`PARAMS` are the block's settings; ``load_controller("learned")``
takes them from the trained file ``valve_gym/agents/policies/adaptive.safetensors`` + ``.json``
(evolution strategies over a randomised family of plants, :mod:`valve_gym.agents.adaptive_train`).
The block sees SP, PV and its own output only, and keeps the PI's integral action (no steady offset).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .block import Setting
from .compensator import Compensator, integral_direction
from .pi import PI_SETTINGS, PIBlock, PIBlockState

__all__ = ["AdaptiveStiction", "AdaptiveState", "PARAMS", "PARAM_NAMES", "SWITCHES", "SWITCH_RANGES"]

#: The trained settings: name, unit, low, high, one line.
PARAMS = (
    ("k_k", "-", 0.0, 1.5, "knocker pulse amplitude over the stick-band estimate"),
    ("k_c", "-", 0.0, 0.6, "constant reinforcement over the stick-band estimate"),
    ("eta", "-", 0.01, 0.8, "step of the stick-band estimate per measurement"),
    ("beta", "-", 0.3, 1.5, "scale of the measured output travel in the estimate"),
    ("rho", "-", 0.005, 1.0, "a measurement below the estimate moves it rho times as far as one above"),
    ("S0", "-", 0.001, 0.06, "stick-band estimate at the start, fraction of stroke"),
    ("c_h", "-", 0.5, 8.0, "hysteresis on the integral part, in units of the noise's random walk"),
    ("ti_factor", "-", 0.5, 3.0, "factor on the PI's integral time"),
    ("f_tau", "-", 0.02, 0.5, "time constant of the error's trend filter over Ti"),
    ("c_d", "-", 1.0, 10.0, "turn of the error's trend that counts as an answer, in noise units"),
)
PARAM_NAMES = tuple(p[0] for p in PARAMS)
#: The block's untrained settings that a trained file names beside its ten numbers (off at 0).
SWITCHES = ("answer", "k_i", "k_z", "confirm")
_S_MIN, _S_MAX = 0.001, 0.2


class AdaptiveState(NamedTuple):
    """Memory of an :class:`AdaptiveStiction`, each field ``(n,)``.

    Attributes
    ----------
    pi : PIBlockState
    d : direction of the integral part (-1, 0, 1)
    i_ext : extreme of the integral part since the last flip
    s_hat : stick-band estimate, fraction of stroke
    sigma : measurement-noise estimate [pv units]
    e_prev : last error [pv units]
    e_f, trend : filtered error [pv] and its trend [pv/s]
    o_prev : last sustained output (PI + reinforcement)
    o_ext : extreme of the sustained output since the last flip, in the direction ``d``
    o_flip, trend0 : extreme of the sustained output against ``d`` around the last flip (where the output
        turned), and the trend at the flip
    armed : 1 while the answer to the last flip is awaited
    p_travel, p_age : with ``confirm`` > 0, the output travel at an answer that awaits confirmation and the
        scans since it (``p_age`` -1: none pending)
    phase : scans since the last pulse start (0, 1, 2)
    k : scans since the start
    """

    pi: PIBlockState
    d: np.ndarray
    i_ext: np.ndarray
    s_hat: np.ndarray
    sigma: np.ndarray
    e_prev: np.ndarray
    e_f: np.ndarray
    trend: np.ndarray
    o_prev: np.ndarray
    o_ext: np.ndarray
    o_flip: np.ndarray
    trend0: np.ndarray
    armed: np.ndarray
    p_travel: np.ndarray
    p_age: np.ndarray
    phase: np.ndarray
    k: np.ndarray


class AdaptiveStiction(Compensator):
    """PI + reinforcement + knocker pulses sized by an online stick-band estimate (batched DCS block).

    Parameters
    ----------
    **settings
        PI settings (``Kc``, ``Ti``, ``detune``, ``scan_s``, ``op_lo``, ``op_hi``) and the numbers of
        :data:`PARAMS` (defaults: mid-range; ``load_controller("learned")`` gives the trained ones).

    Examples
    --------
    >>> blk = AdaptiveStiction(Kc=1.0, Ti=10.0)
    >>> blk.reset(1.0, 1.0, 0.5)
    >>> blk.step(1.0, 1.0)
    0.5
    """

    name = "adaptive_stiction"
    OWN_SETTINGS = tuple(Setting(n, u, (lo + hi) / 2.0, lo, hi, doc, per_loop=True) for n, u, lo, hi, doc in PARAMS) + (
        Setting("answer", "-", 0.0, 0.0, 1.0, "what counts as the valve's answer to a reversal: 0, the error's "
                "trend turns by c_d noise units from its value at the reversal; 1, it turns against the output's "
                "direction (a process settling while the stem sticks is no answer); a trained file says which",
                per_loop=True),
        Setting("k_i", "-", 0.0, 0.0, 10.0, "integral boost: while a reversal awaits the valve's answer the integral "
                "part moves (1 + k_i) times as fast; a trained file says how much", per_loop=True),
        Setting("k_z", "-", 0.0, 0.0, 4.0, "integral dead zone: the integral part holds while the filtered error is "
                "within k_z S_hat / (2 Kc), k_z times the error amplitude of the stick-slip cycle a PI sustains on a "
                "valve of band S_hat (0: off; a trained file says how much)", per_loop=True),
        Setting("confirm", "-", 0.0, 0.0, 5.0, "answers must hold: the error's trend must stay turned for confirm "
                "time constants of its filter (f_tau Ti) before the travel counts; a turn that goes back is no "
                "answer and the block keeps waiting (0: off; a trained file says how much)", per_loop=True),)

    def _resolve(self, settings: dict) -> dict:
        s = super()._resolve(settings)
        pi_kw = {k.name: s[k.name] for k in PI_SETTINGS if k.name != "action"}   # the action: FunctionBlock
        pi_kw["Ti"] = s["Ti"] * s["ti_factor"]
        self.pi = PIBlock(**pi_kw)
        self.alpha = np.minimum(1.0, s["scan_s"] / (s["f_tau"] * s["Ti"]))
        self._dead_zone, self._confirm = bool(np.any(s["k_z"] > 0)), bool(np.any(s["confirm"] > 0))   # switches on
        return s

    def for_loop(self, Kc: float, Ti: float, scan_s: float) -> AdaptiveStiction:
        """The same trained numbers as the block of a loop with its own tuning and scan.

        PI gain ``Kc``, integral time ``Ti`` [s] and scan ``scan_s`` [s]; the other PI settings are kept. This is
        how the benchmark runs a trained file given as a policy.

        Examples
        --------
        >>> blk = AdaptiveStiction(k_k=0.3, Kc=1.0, Ti=10.0).for_loop(2.0, 30.0, 0.5)
        >>> blk.settings["k_k"], blk.settings["Kc"], blk.scan_s
        (0.3, 2.0, 0.5)
        """
        own = {st.name: self.settings[st.name] for st in self.OWN_SETTINGS}      # trained numbers and switches
        pi = {k.name: self.settings[k.name] for k in PI_SETTINGS if k.name not in ("Kc", "Ti", "scan_s")}
        return type(self)(**own, **pi, Kc=float(Kc), Ti=float(Ti), scan_s=float(scan_s))

    def initial_state(self, sp, pv, op) -> AdaptiveState:
        """Bumpless start; the estimate at ``S0``, no direction yet."""
        pis = self.pi.initial_state(sp, pv, op)
        n = pis.op.shape[0]
        z = np.zeros(n)
        e = np.asarray(sp, float) - np.asarray(pv, float)
        return AdaptiveState(pi=pis, d=z.copy(), i_ext=pis.integral.copy(),
                             s_hat=np.broadcast_to(self.p["S0"], (n,)).astype(float), sigma=z.copy(),
                             e_prev=e.copy(), e_f=e.copy(), trend=z.copy(), o_prev=pis.op.copy(),
                             o_ext=pis.op.copy(), o_flip=pis.op.copy(), trend0=z.copy(), armed=z.copy(),
                             p_travel=z.copy(), p_age=np.full(n, -1.0), phase=z.copy(), k=z.copy())

    def _estimate(self, st: AdaptiveState, flipped, d, o, o_flip, trend, sigma):
        """The stick-band estimate after this scan: ``(s_hat, armed, p_travel, p_age)``."""
        p, a = self.p, self.alpha
        thr = p["c_d"] * a ** 1.5 * sigma / (np.sqrt(2.0) * self.scan_s)
        travel = np.abs(o - o_flip)
        # answer = 1: where the error still grew in the output's direction at the reversal, its trend must turn
        # against that direction; a first-order process settling while the stem sticks only slows that growth
        ref = np.where((p["answer"] > 0.5) & (d * st.trend0 > 0), 0.0, st.trend0)
        turned = d * (ref - trend)
        answered = (st.armed > 0) & ~flipped & (turned > thr)
        p_travel, p_age = st.p_travel, st.p_age
        if self._confirm:
            # a turn counts once it has held for confirm filter time constants; one that goes back is no answer
            held = ~flipped & (st.p_age >= 0) & (turned > 0.0)
            window = p["confirm"] / a                  # confirm time constants of the trend's filter, in scans
            confirmed = held & (st.p_age + 1.0 >= window)
            start = answered & (st.p_age < 0)
            wait = p["confirm"] > 0
            p_age = np.where(wait & start, 0.0, np.where(wait & held & ~confirmed, st.p_age + 1.0, -1.0))
            p_travel = np.where(wait & start, travel, st.p_travel)
            travel = np.where(wait, st.p_travel, travel)
            answered = np.where(wait, confirmed, answered)
        meas = p["beta"] * travel - st.s_hat
        step = np.where(answered, p["eta"] * np.where(meas > 0, 1.0, p["rho"]) * meas, 0.0)
        bound = np.abs(st.o_ext - st.o_flip)           # flipped before any answer: at least this far
        step = np.where(flipped & (st.armed > 0) & (bound > st.s_hat), p["eta"] * (bound - st.s_hat), step)
        s_hat = np.clip(st.s_hat + step, _S_MIN, _S_MAX)
        armed = np.where(flipped, 1.0, np.where(answered, 0.0, st.armed))
        return s_hat, armed, p_travel, p_age

    def advance(self, state: AdaptiveState, sp, pv):
        """One scan: ``(state, sp, pv) -> (state, op)``."""
        p, ts, st = self.p, self.scan_s, state
        e_f = st.e_f + self.alpha * ((np.asarray(sp, float) - np.asarray(pv, float)) - st.e_f)
        integrate = True
        if self._dead_zone:                                                  # the integral dead zone
            integrate = np.abs(e_f) >= p["k_z"] * st.s_hat / (2.0 * self.pi.Kc)
        scan = self.pi.propose(st.pi, sp, pv, integrate=integrate)
        boost = p["k_i"] * st.armed * (scan.integral - st.pi.integral)     # faster across the band while stuck
        scan = scan._replace(integral=scan.integral + boost, v=scan.v + boost)
        k = st.k + 1.0
        rate = np.maximum(min(1.0, ts / 200.0), 1.0 / k)
        sigma = st.sigma + rate * (0.63 * np.abs(scan.e - st.e_prev) - st.sigma)
        trend = st.trend + self.alpha * ((e_f - st.e_f) / ts - st.trend)
        hyst = p["c_h"] * self.pi.Kc * sigma * np.sqrt(ts / self.pi.Ti)
        d, i_ext, flipped = integral_direction(st.d, st.i_ext, scan.integral, hyst)
        o = self.pi.Kc * e_f + scan.integral + p["k_c"] * st.s_hat * d
        turned = np.where(d > 0, np.minimum(st.o_flip, o), np.maximum(st.o_flip, o))
        o_flip = np.where(flipped, st.o_ext, turned)
        o_ext = np.where(flipped | (d == 0), o, np.where(d > 0, np.maximum(st.o_ext, o), np.minimum(st.o_ext, o)))
        s_hat, armed, p_travel, p_age = self._estimate(st, flipped, d, o, o_flip, trend, sigma)
        trend0 = np.where(flipped, trend, st.trend0)
        bias = p["k_c"] * s_hat * d
        pulse = np.where(st.phase == 0, p["k_k"] * s_hat * d, 0.0)
        _, op = self.pi.finish(scan, bias + pulse)
        alone, _ = self.pi.finish(scan, bias)
        pis = PIBlockState(integral=alone.integral, op=op)
        return AdaptiveState(pis, d, i_ext, s_hat, sigma, scan.e, e_f, trend, o, o_ext, o_flip, trend0,
                             armed, p_travel, p_age, (st.phase + 1) % 3, k), op


#: The numeric untrained switches (all but ``answer``) and their ranges ``(lo, hi)``, from the block's settings.
SWITCH_RANGES = {st.name: (st.lo, st.hi) for st in AdaptiveStiction.OWN_SETTINGS
                 if st.name in SWITCHES and st.name != "answer"}
