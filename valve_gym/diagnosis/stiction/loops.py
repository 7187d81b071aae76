"""Textbook closed loops with sticky valves, written independently of :mod:`valve_gym.core`.

A PI controller (velocity form, sample time ``Ts``) drives a valve with one
of three friction models into one of three processes; measurement noise can
be white or coloured, an unmeasured load can drift, and an external
oscillating disturbance or an over-aggressive tuning gives oscillations that
are *not* stiction.  Used to validate the stiction verdict and the S/J
estimates on loops that the package's own simulator did not make.

Valve models (``u`` controller output, ``x`` valve position, fractions of stroke):

* ``'choudhury'``: two-parameter data-driven model (Choudhury, Thornhill & Shah 2005):
  stuck until ``|u - u_s| > S`` after a reversal or ``> J`` in the same direction,
  then ``x = u - sign(du) (S - J)/2``; ``u_s`` is re-anchored at every input reversal.
* ``'kano'``: Kano et al. (2004): the same two parameters, but the stick point
  ``u_s`` is kept while the valve has not moved (input reversals inside the band
  do not re-anchor it).
* ``'force_balance'``: stem mass-spring-damper with static/Coulomb friction
  (Karnopp-style stick), ``x'' = w_n^2 (u - x - f)``, ``f`` friction over spring
  rate; ``S = 2 f_s``, ``J = 2 (f_s - f_c)`` (Garcia 2008 mapping).
* ``'linear'``: no friction (a healthy valve with a first-order positioner lag).

Processes (``x`` valve position, ``y`` PV):

* ``'foptd'``: ``tau y' = -y + K x(t - theta)``;
* ``'integrating'``: ``y' = k_i (x(t - theta) - x_0)``;
* ``'tank'``: ``A(y) y' = q_max x(t - theta) - c sqrt(y)`` (Torricelli outflow), with the
  cross-section ``A(y)`` of a vertical cylinder (constant), an upright cone (apex down,
  ``A ~ y^2``), a sphere or a horizontal cylinder (``A`` largest half full), scaled so that
  ``A = area`` at the initial level.

Optional plant effects (all off by default), for tests of effect naming on loops this
simulator makes: an installed flow characteristic ``f(x)`` between the valve position and
the flow (``'equal_percentage'``: ``R^(x - 1)``; ``'quick_opening'``: ``sqrt(x)``), a tank
that spills over at ``level_max`` (the level cannot rise above it), a first-order lag of the
level sensor (``sensor_tau``), the transport delay ``theta`` and a constant leak.

References
----------
.. [1] M.A.A.S. Choudhury, N.F. Thornhill, S.L. Shah, "Modelling valve stiction",
   Control Engineering Practice 13 (2005) 641-658.
.. [2] M. Kano, H. Maruta, H. Kugemoto, K. Shimizu, "Practical model and
   detection algorithm for valve stiction", IFAC DYCOPS 2004.
.. [3] C. Garcia, "Comparison of friction models applied to a control valve",
   Control Engineering Practice 16 (2008) 1231-1243.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..recording import Recording

__all__ = ["LoopSpec", "simulate_loop", "random_spec", "VALVES", "PROCESSES", "TANK_SHAPES", "CHARACTERISTICS"]

VALVES = ("choudhury", "kano", "force_balance", "linear")
PROCESSES = ("foptd", "integrating", "tank")
TANK_SHAPES = ("cylinder", "cone", "sphere", "horizontal_cylinder")
CHARACTERISTICS = ("linear", "equal_percentage", "quick_opening")


@dataclass(frozen=True)
class LoopSpec:
    """One textbook loop.

    Attributes
    ----------
    process : str, one of :data:`PROCESSES`
    valve : str, one of :data:`VALVES`
    S, J : float, friction band and slip jump, fractions of stroke
    K, tau, theta : float, gain [PV/stroke], time constant [s], dead time [s] (foptd; theta all)
    k_i : float, integrating rate [PV/s per stroke]
    area, q_max, c_out : float, tank area [m^2], max inflow [m^3/s], outflow coefficient [m^2.5/s]
    Kc, Ti : float, PI gain [stroke/PV] and integral time [s]
    Ts : float, controller sample time [s]
    noise : float, measurement noise std [PV]
    noise_pole : float, AR(1) pole of the noise (0 white)
    load : float, std of a slowly drifting load, fraction of stroke equivalent
    dist_amp, dist_period : float, external sinusoidal load [stroke equivalent], period [s]
    tau_v : float, positioner time constant [s]
    n : int, samples
    sp_step : float, set-point offset from the initial steady state [PV] (excites a noise-free loop)
    sp_moves : float, set-point steps of this size [PV] (random sign) every n/6 samples (0: none)
    leak : float, extra constant outflow of the tank [m^3/s] (``'tank'`` only)
    shape : str, tank cross-section, one of :data:`TANK_SHAPES` (``'tank'`` only)
    characteristic : str, installed flow characteristic, one of :data:`CHARACTERISTICS`
    rangeability : float, ``R`` of the equal-percentage characteristic
    level_max : float, level at which the tank spills over [m] (``'tank'`` only; 0: never)
    sensor_tau : float, time constant of a first-order lag of the PV sensor [s] (0: none)

    The measurement noise of :func:`random_spec` is drawn in controller-output
    terms (0.03-0.3 % of stroke after the PI gain), so that it matters as much
    for a loop with a small gain as for one with a large gain.
    """

    process: str = "foptd"
    valve: str = "choudhury"
    S: float = 0.03
    J: float = 0.01
    K: float = 1.0
    tau: float = 50.0
    theta: float = 10.0
    k_i: float = 0.02
    area: float = 1.0
    q_max: float = 0.02
    c_out: float = 0.01
    Kc: float = 1.0
    Ti: float = 50.0
    Ts: float = 1.0
    noise: float = 0.002
    noise_pole: float = 0.0
    load: float = 0.0
    dist_amp: float = 0.0
    dist_period: float = 100.0
    tau_v: float = 0.3
    n: int = 1800
    sp_step: float = 0.0
    sp_moves: float = 0.0
    leak: float = 0.0
    shape: str = "cylinder"
    characteristic: str = "linear"
    rangeability: float = 30.0
    level_max: float = 0.0
    sensor_tau: float = 0.0

    @property
    def sticky(self) -> bool:
        """True when the valve has friction (S > 0 with a friction model)."""
        return self.valve != "linear" and self.S > 0


class _TwoParam:
    """Choudhury (stick point re-anchored at input reversals) or Kano (kept while stuck) valve."""

    def __init__(self, S, J, kano, u0):
        self.S, self.J, self.kano = S, J, kano
        self.x = u0
        self.us = u0
        self.u_prev = u0
        self.d = 0.0          # direction of the last valve motion
        self.s_in = 0.0       # direction of the last input move
        self.stuck = True

    def step(self, u):
        du = u - self.u_prev
        s = float(np.sign(du))
        if not self.stuck and (s == 0 or s != self.d):
            self.stuck, self.us = True, self.u_prev
        elif self.stuck and not self.kano and s != 0 and s != self.s_in:
            self.us = self.u_prev
        if self.stuck:
            dev = u - self.us
            need = self.J if (dev > 0) == (self.d > 0) and self.d != 0 else self.S
            if abs(dev) > need:
                self.d = 1.0 if dev > 0 else -1.0
                self.stuck = False
        if not self.stuck:
            self.x = u - self.d * (self.S - self.J) / 2.0
        self.u_prev = u
        if s != 0:
            self.s_in = s
        return self.x


class _ForceBalance:
    """Stem with mass, spring, viscous damping, static and Coulomb friction (normalised)."""

    def __init__(self, S, J, wn, u0):
        self.fs = S / 2.0
        self.fc = max(S - J, 0.0) / 2.0
        self.wn = wn
        self.x = u0 - self.fs * 0.0
        self.v = 0.0

    def step(self, u, h, n):
        wn2 = self.wn ** 2
        zeta = 0.7
        for _ in range(n):
            net = u - self.x
            if self.v == 0.0 and abs(net) <= self.fs:
                continue
            fr = self.fc * (np.sign(self.v) if self.v != 0.0 else np.sign(net))
            a = wn2 * (net - fr) - 2 * zeta * self.wn * self.v
            v_new = self.v + h * a
            if self.v != 0.0 and np.sign(v_new) != np.sign(self.v):
                self.v = 0.0          # velocity crosses zero: the stem sticks
                continue
            self.v = v_new
            self.x += h * self.v
        return self.x


def _noise(rng, n, std, pole):
    w = rng.normal(size=n)
    if pole <= 0:
        return std * w
    out = np.empty(n)
    acc = 0.0
    g = math.sqrt(1 - pole * pole)
    for k in range(n):
        acc = pole * acc + g * w[k]
        out[k] = acc
    return std * out


def _area(spec: LoopSpec, y: float, y0: float) -> float:
    """Cross-section of the tank at level ``y`` [m^2]; ``spec.area`` at the initial level ``y0``.

    Cone (apex down): ``A ~ y^2``; sphere of diameter ``2 y0``: ``A ~ y (2 y0 - y)``; horizontal
    cylinder of diameter ``2 y0``: ``A ~ sqrt(y (2 y0 - y))``.  Floored at 5 % of ``spec.area``
    (the bottom of a cone or sphere, the top of a sphere).
    """
    r = y / y0
    if spec.shape == "cone":
        g = r * r
    elif spec.shape == "sphere":
        g = r * (2.0 - r)
    elif spec.shape == "horizontal_cylinder":
        g = math.sqrt(max(r * (2.0 - r), 0.0))
    else:
        g = 1.0
    return spec.area * max(g, 0.05)


def _flow_fraction(spec: LoopSpec, x: float) -> float:
    """Installed characteristic: flow fraction at valve position ``x`` (0..1)."""
    if spec.characteristic == "equal_percentage":
        return spec.rangeability ** (x - 1.0)
    if spec.characteristic == "quick_opening":
        return math.sqrt(max(x, 0.0))
    return x


def _process_rate(spec: LoopSpec, y, x, y0: float = 1.0):
    """``dy/dt`` at level/output ``y`` for the flow fraction ``x`` (characteristic and load applied)."""
    if spec.process == "foptd":
        return (-y + spec.K * x) / spec.tau
    if spec.process == "integrating":
        return spec.k_i * (x - _flow_fraction(spec, 0.5))
    return (spec.q_max * x - spec.c_out * math.sqrt(max(y, 0.0)) - spec.leak) / _area(spec, y, y0)


def _steady(spec: LoopSpec, x0: float) -> float:
    f0 = _flow_fraction(spec, x0)
    if spec.process == "foptd":
        return spec.K * f0
    if spec.process == "integrating":
        return 1.0
    return (max(spec.q_max * f0 - spec.leak, 1e-9) / spec.c_out) ** 2


def simulate_loop(spec: LoopSpec, seed: int = 0, name: str | None = None, stem: bool = False) -> Recording:
    """Simulate ``spec`` at constant set point and return the recording (OP 0..1).

    The loop starts at rest at 50 % valve opening; the first 10 % of the run is
    discarded as start-up.  Euler integration with 20 steps per controller sample.
    ``stem=True`` also records the valve's position (``mv``, 0..1: the positioner's
    output at the end of each sample, as a travel sensor reads it); the other
    signals are the same with or without it.
    """
    rng = np.random.default_rng(seed)
    n_total = int(spec.n * 1.1) + 1
    sub = 20
    h = spec.Ts / sub
    if spec.process not in PROCESSES or spec.valve not in VALVES or spec.shape not in TANK_SHAPES:
        raise ValueError(f"unknown process {spec.process!r}, valve {spec.valve!r} or tank shape "
                         f"{spec.shape!r}; use one of {PROCESSES}, {VALVES}, {TANK_SHAPES}")
    x0 = 0.5
    y = _steady(spec, x0)
    y0 = max(y, 1e-9)
    sp = y + spec.sp_step
    valve = (_TwoParam(spec.S, spec.J, spec.valve == "kano", x0) if spec.valve in ("choudhury", "kano")
             else _ForceBalance(spec.S, spec.J, 8.0 / spec.Ts, x0) if spec.valve == "force_balance"
             else None)
    if spec.characteristic not in CHARACTERISTICS:
        raise ValueError(f"unknown characteristic {spec.characteristic!r}; use one of {CHARACTERISTICS}")
    if not (spec.sensor_tau == 0.0 or spec.sensor_tau >= h):
        raise ValueError(f"sensor_tau = {spec.sensor_tau} s is shorter than the integration step {h} s; "
                         f"use 0 (no lag) or at least Ts/20")
    spill = spec.process == "tank" and spec.level_max > 0
    lag_s = spec.sensor_tau > 0
    ys = y
    nz = _noise(rng, n_total, spec.noise, spec.noise_pole)
    ld = _noise(rng, n_total, spec.load, 0.995) if spec.load > 0 else np.zeros(n_total)
    lag = max(0, int(round(spec.theta / h)))
    fifo = [x0] * (lag + 1)
    xv = x0              # positioner output
    u = x0
    e_prev = 0.0
    op = np.empty(n_total)
    pv = np.empty(n_total)
    mv = np.empty(n_total)
    sps = _sp_profile(rng, n_total, sp, spec.sp_moves)
    for k in range(n_total):
        t = k * spec.Ts
        ym = ys + nz[k]
        e = sps[k] - ym
        u = u + spec.Kc * (e - e_prev + spec.Ts / spec.Ti * e)
        u = float(min(max(u, 0.0), 1.0))
        e_prev = e
        op[k], pv[k] = u, ym
        if valve is None:
            target = u
        elif isinstance(valve, _ForceBalance):
            target = valve.step(u, h, sub)
        else:
            target = valve.step(u)
        dist = ld[k] + spec.dist_amp * math.sin(2 * math.pi * t / spec.dist_period)
        for _ in range(sub):
            xv += h / max(spec.tau_v, h) * (target - xv)
            fifo.append(xv)
            xd = fifo.pop(0)
            y += h * _process_rate(spec, y, min(max(_flow_fraction(spec, xd) + dist, 0.0), 1.0), y0)
            if spill and y > spec.level_max:
                y = spec.level_max
            ys = ys + h / spec.sensor_tau * (y - ys) if lag_s else y
        mv[k] = min(max(xv, 0.0), 1.0)      # a travel sensor reads the stroke 0..1
    k0 = n_total - spec.n
    t = np.arange(spec.n) * spec.Ts
    cols = {"t": "t", "op": "op", "pv": "pv", "sp": "sp"} | ({"mv": "mv"} if stem else {})
    return Recording(t=t, op=op[k0:], pv=pv[k0:], sp=sps[k0:], mv=mv[k0:] if stem else None, dt=spec.Ts,
                     name=name or f"{spec.process}_{spec.valve}_{seed}", op_range=(0.0, 1.0), columns=cols)


def _sp_profile(rng, n: int, sp0: float, size: float) -> np.ndarray:
    """Set point: ``sp0``, moved by +-``size`` every n/6 samples (kept within 2 sizes of ``sp0``)."""
    out = np.full(n, sp0)
    if size <= 0:
        return out
    cur = sp0
    seg = max(n // 6, 1)
    for k in range(seg, n, seg):
        step = size * (1.0 if rng.random() < 0.5 else -1.0)
        if abs(cur + step - sp0) > 2 * size:
            step = -step
        cur += step
        out[k:] = cur
    return out


def _tuning(rng, spec: dict[str, float], process: str, aggressive: bool):
    """PI gains: SIMC-like with random detuning; ``aggressive`` puts the loop near its limit."""
    theta = spec["theta"] + spec["tau_v"] + spec["Ts"] / 2
    if process == "foptd":
        K, tau = spec["K"], spec["tau"]
    elif process == "integrating":
        K, tau = spec["k_i"], None
    else:
        y0 = (spec["q_max"] * 0.5 / spec["c_out"]) ** 2
        tau = 2 * spec["area"] * math.sqrt(y0) / spec["c_out"]
        K = spec["q_max"] * tau / spec["area"]
    tc = theta * (rng.uniform(0.3, 0.5) if aggressive else rng.uniform(1.0, 4.0))
    if tau is None:
        Kc = 1.0 / (K * (tc + theta))
        Ti = 4 * (tc + theta)
    else:
        Kc = tau / (K * (tc + theta))
        Ti = min(tau, 4 * (tc + theta))
    if aggressive:
        Kc *= rng.uniform(1.6, 2.4)
    return Kc, Ti


def random_spec(rng, sticky: bool, valve: str | None = None, process: str | None = None,
                n: int = 1200, disturbance: str | None = None) -> LoopSpec:
    """A random textbook loop (plant, tank shape, tuning, noise colour, sample time, actuator, friction).

    ``sticky`` draws S in 0.5-10 % of stroke and J in 0.1-1.2 S; otherwise the
    valve is linear and ``disturbance`` (default random) is ``'none'``,
    ``'sine'`` (external oscillating load) or ``'tuning'`` (aggressive PI).  A tank's
    shape is drawn last (the draws of the other processes do not depend on it); the PI
    is tuned for the cross-section at the initial level.
    """
    process = process or str(rng.choice(PROCESSES))
    valve = valve or (str(rng.choice(VALVES[:3])) if sticky else "linear")
    Ts = float(rng.choice([0.5, 1.0, 2.0, 5.0]))
    p = {"Ts": Ts, "theta": float(rng.uniform(0.0, 8.0) * Ts), "tau_v": float(rng.uniform(0.05, 0.4) * Ts),
         "K": float(rng.uniform(0.5, 3.0)),
         "tau": float(rng.uniform(10, 60) * Ts), "k_i": float(rng.uniform(0.005, 0.03) / Ts),
         "area": float(rng.uniform(0.5, 3.0)), "q_max": float(rng.uniform(0.01, 0.05)),
         "c_out": float(rng.uniform(0.01, 0.03))}
    if process == "foptd" and p["theta"] < Ts:
        p["theta"] = float(rng.uniform(1.0, 8.0) * Ts)
    if process == "tank":
        p["area"] = float(p["area"] * Ts)
    dist = disturbance or ("none" if sticky else str(rng.choice(["none", "sine", "tuning"])))
    Kc, Ti = _tuning(rng, p, process, dist == "tuning")
    S = float(rng.uniform(0.005, 0.10)) if sticky else 0.0
    J = float(S * rng.uniform(0.1, 1.2)) if sticky else 0.0
    spec = LoopSpec(process=process, valve=valve, S=S, J=J, Kc=Kc, Ti=Ti, n=n,
                    noise=float(rng.uniform(0.0003, 0.003) / Kc),
                    noise_pole=float(rng.choice([0.0, rng.uniform(0.5, 0.95)])),
                    load=float(rng.uniform(0.0, 0.01)),
                    dist_amp=float(rng.uniform(0.01, 0.05)) if dist == "sine" else 0.0,
                    dist_period=float(rng.uniform(20, 80) * Ts), Ts=p["Ts"], theta=p["theta"],
                    tau_v=p["tau_v"], K=p["K"], tau=p["tau"], k_i=p["k_i"], area=p["area"],
                    q_max=p["q_max"], c_out=p["c_out"])
    if process == "tank":
        spec = replace(spec, shape=str(rng.choice(TANK_SHAPES)))
    return spec
