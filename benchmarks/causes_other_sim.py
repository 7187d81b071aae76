"""Oscillating control loops of every cause, from a simulator written apart from the package's core.

Nothing here imports :mod:`valve_gym.core` or :mod:`valve_gym.plant`: the process, the valve, the PI
controller and the sensor are written out below, each in a few lines, so that the diagnosis is scored
on loops its own simulator did not make.  Every loop runs at a constant set point with a small
drifting load and measurement noise, and oscillates for one known cause:

* ``stiction`` -- a sticky valve: Choudhury et al. (2005), Kano et al. (2004) or a Karnopp
  stick-slip stem (static and Coulomb friction on a mass-spring-damper stem, Karnopp 1985),
  S 1..8 % of the stroke, J 0..S; the loop tuned normally (SIMC, Skogestad 2003);
* ``tuning`` -- a healthy valve, the controller's gain set to a gain margin of 1.02..1.15 (a lightly
  damped loop that rings under its noise and load);
* ``disturbance`` -- a healthy valve and normal tuning; a sinusoidal (or rounded square) load of
  period 4..25 process time constants enters at the process input;
* ``quantisation`` -- a healthy valve; the PV transmitter resolves only steps of 0.5..2 % of the
  PV's span, and the set point lies between two steps: integral action hunts between them;
* ``saturation`` -- an undersized valve: the load asks for more than the open valve gives for part
  of each load cycle, the output sits at 100 % and the integral winds up.

Processes: first order plus dead time, second order plus dead time, and integrating with dead time,
with gains and offsets so that the PV is in arbitrary units (negative values too).  The output is
logged in percent or as a fraction (half of each), as historians do.

:func:`make_loop` returns a dict with ``t``, ``op``, ``pv``, ``sp`` (arrays), ``cause``, ``S``,
``J`` (fractions of stroke; 0 for healthy valves), ``valve``, ``process`` and ``op_scale`` (100 for
percent, 1 for a fraction).  Seeds are passed in; nothing here was tuned to the diagnosis.
"""
from __future__ import annotations

import math

import numpy as np

CAUSES = ("stiction", "tuning", "disturbance", "quantisation", "saturation")
PROCESSES = ("fopdt", "sopdt", "integrating")
STICKY_VALVES = ("choudhury", "kano", "karnopp")


# --------------------------------------------------------------------------- valves
class _Choudhury:
    """Two-parameter data-driven stiction (Choudhury, Thornhill & Shah 2005), input and output in % of stroke."""

    def __init__(self, S: float, J: float, x0: float, kano: bool = False):
        self.S, self.J, self.kano = S, J, kano
        self.x = x0
        self.us = x0
        self.u_prev = x0
        self.stuck = True
        self.d_prev = 0.0

    def step(self, u: float) -> float:
        du = u - self.u_prev
        self.u_prev = u
        d = float(np.sign(du))
        if d == 0.0:
            return self.x
        if not self.stuck and d != self.d_prev:
            self.stuck = True              # a reversal of a moving valve: it sticks where the input turned
            self.us = u - du
            self.rev = True
        elif self.stuck and d != self.d_prev and self.kano:
            pass                           # Kano: the stick point is kept while the valve has not moved
        elif self.stuck and d != self.d_prev:
            self.rev = True                # Choudhury: any reversal while stuck needs the full band again
        self.d_prev = d
        if self.stuck:
            band = self.S if getattr(self, "rev", True) else self.J
            if abs(u - self.us) > band:
                self.stuck = False
                self.rev = False
                self.x = u - d * (self.S - self.J) / 2.0
        else:
            self.x = u - d * (self.S - self.J) / 2.0
        return self.x


class _Karnopp:
    """Stem on a spring and damper with static and Coulomb friction (Karnopp's stick zone), in fractions."""

    def __init__(self, S: float, J: float, x0: float, dt: float):
        self.fs, self.fc = S / 2.0, max(S - J, 0.0) / 2.0      # friction over spring rate [stroke]
        self.wn, self.zeta = 2.0 * math.pi / 1.0, 0.7           # stem natural frequency 1 Hz
        self.x, self.v = x0, 0.0
        self.dt = dt

    def step(self, u: float) -> float:
        n = max(1, int(math.ceil(self.dt / 0.02)))
        h = self.dt / n
        for _ in range(n):
            f_drive = u - self.x - 2 * self.zeta / self.wn * self.v
            if abs(self.v) < 1e-4 and abs(f_drive) <= self.fs:
                self.v = 0.0                                   # stuck
                continue
            fr = self.fc * (np.sign(self.v) if self.v != 0.0 else np.sign(f_drive))
            a = self.wn ** 2 * (f_drive - fr)
            v_new = self.v + h * a
            if self.v != 0.0 and np.sign(v_new) != np.sign(self.v):
                v_new = 0.0
            self.v = v_new
            self.x += h * self.v
        return self.x


class _Healthy:
    """A valve that follows the output with a positioner lag of ``tau`` seconds."""

    def __init__(self, x0: float, dt: float, tau: float = 0.5):
        self.x, self.a = x0, math.exp(-dt / tau)

    def step(self, u: float) -> float:
        self.x = self.a * self.x + (1 - self.a) * u
        return self.x


# --------------------------------------------------------------------------- processes
class _Process:
    """Valve position (0..1) plus load to PV: FOPDT, SOPDT or integrating with dead time, integrated exactly."""

    def __init__(self, kind: str, K: float, tau: float, tau2: float, theta: float, dt: float, y0: float):
        self.kind, self.K, self.dt = kind, K, dt
        self.a1 = math.exp(-dt / tau)
        self.a2 = math.exp(-dt / tau2) if kind == "sopdt" else 0.0
        self.delay = [0.0] * max(0, int(round(theta / dt)))
        self.s1 = 0.0
        self.s2 = 0.0
        self.y0 = y0
        self.tau = tau

    def step(self, x: float) -> float:
        self.delay.append(x)
        xd = self.delay.pop(0)
        if self.kind == "integrating":
            self.s1 += self.K * xd * self.dt / self.tau
            return self.y0 + self.s1
        self.s1 = self.a1 * self.s1 + (1 - self.a1) * self.K * xd
        if self.kind == "sopdt":
            self.s2 = self.a2 * self.s2 + (1 - self.a2) * self.s1
            return self.y0 + self.s2
        return self.y0 + self.s1


def _ultimate(kind: str, K: float, tau: float, tau2: float, theta: float, dt: float) -> tuple[float, float]:
    """Ultimate gain and period of the loop (P control), from its frequency response (numerically)."""
    w = np.geomspace(1e-5 / tau, math.pi / dt, 20000)
    th = theta + 1.5 * dt
    if kind == "integrating":
        G = K / tau / (1j * w) * np.exp(-1j * w * th)
    elif kind == "sopdt":
        G = K / ((1j * w * tau + 1) * (1j * w * tau2 + 1)) * np.exp(-1j * w * th)
    else:
        G = K / (1j * w * tau + 1) * np.exp(-1j * w * th)
    ph = np.unwrap(np.angle(G))
    i = int(np.flatnonzero(ph <= -math.pi)[0])
    return 1.0 / abs(G[i]), 2 * math.pi / w[i]


def _simc(kind: str, K: float, tau: float, tau2: float, theta: float, dt: float) -> tuple[float, float]:
    """SIMC PI settings (Skogestad 2003) with tau_c = theta (plus the sampling delay)."""
    th = theta + 1.5 * dt
    if kind == "integrating":
        kp = K / tau
        return 1.0 / (kp * 2 * th), 8 * th
    t1 = tau
    th_eff = th + (tau2 / 2 if kind == "sopdt" else 0.0)
    t1 = tau + (tau2 / 2 if kind == "sopdt" else 0.0)
    return t1 / (K * 2 * th_eff), min(t1, 8 * th_eff)


def _run(valve, proc: _Process, Kc: float, Ti: float, dt: float, sp: np.ndarray, load: np.ndarray, offset: float,
         noise_std: float, q: float, x0: float, sign: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """The closed loop, sample by sample: PI (velocity form, output limited to 0..1), valve, process, sensor."""
    n = len(sp)
    op = np.zeros(n)
    pv = np.zeros(n)
    u = x0
    e_prev = 0.0
    y_meas = sp[0]
    for k in range(n):
        e = sp[k] - y_meas
        u = u + sign * Kc * ((e - e_prev) + dt / Ti * e)
        u = min(max(u, 0.0), 1.0)                              # the output's limits; the integral winds up
        e_prev = e
        op[k] = u
        x = valve.step(u)
        x = min(max(x, 0.0), 1.0)
        y = proc.step(x + load[k]) + offset
        y_meas = y + rng.normal(0, noise_std) if noise_std > 0 else y
        if q > 0:
            y_meas = math.floor((y_meas - offset) / q + 0.5) * q + offset
        pv[k] = y_meas
    return op, pv


def make_loop(cause: str, seed: int, n: int = 1500) -> dict:
    """One closed loop oscillating for ``cause`` (module docstring), at a constant set point.

    Parameters
    ----------
    cause : str, one of :data:`CAUSES`
    seed : int
    n : int, samples

    Returns
    -------
    dict with ``t``, ``op``, ``pv``, ``sp`` (ndarray, shape (n,)), ``cause``, ``S``, ``J``, ``valve``,
    ``process``, ``op_scale``, ``dt``
    """
    rng = np.random.default_rng(seed)
    kind = PROCESSES[int(rng.integers(len(PROCESSES)))]
    dt = float(rng.choice([1.0, 2.0, 5.0]))
    tau = float(rng.uniform(8, 40)) * dt
    tau2 = tau * float(rng.uniform(0.1, 0.4))
    theta = float(rng.integers(2, 8)) * dt
    span = float(10 ** rng.uniform(-2, 3))                    # the PV's span in its own units
    K = span * float(rng.uniform(0.5, 1.2)) * float(rng.choice([1.0, -1.0]))
    offset = float(rng.uniform(-2, 2)) * span
    Kc, Ti = _simc(kind, abs(K), tau, tau2, theta, dt)
    valve_name, S, J = "linear", 0.0, 0.0
    x0 = float(rng.uniform(0.35, 0.65))
    if cause == "tuning":
        Ku, Pu = _ultimate(kind, abs(K), tau, tau2, theta, dt)
        gm = float(rng.uniform(1.02, 1.15))
        Kc, Ti = Ku / gm, max(Pu * float(rng.uniform(1.5, 4.0)), 2 * dt)
        if kind == "integrating":       # a PI on an integrator: keep Ti long enough that the gain sets the margin
            Ti = max(Ti, 4 * Pu)
    if cause == "stiction":
        valve_name = STICKY_VALVES[int(rng.integers(len(STICKY_VALVES)))]
        S = float(rng.uniform(0.01, 0.08))
        J = S * float(rng.uniform(0.0, 0.9))
    valve: _Choudhury | _Karnopp | _Healthy
    if valve_name in ("choudhury", "kano"):
        valve = _Choudhury(S, J, x0, kano=valve_name == "kano")
    elif valve_name == "karnopp":
        valve = _Karnopp(S, J, x0, dt)
    else:
        valve = _Healthy(x0, dt)
    proc = _Process(kind, K, tau, tau2, theta, dt, 0.0)
    if kind != "integrating":                                   # start at the steady state of x0
        proc.s1 = proc.s2 = K * x0
        proc.delay = [x0] * len(proc.delay)
    # the steady state at x0 (no load): the set point there
    y_ss = (K * x0) if kind != "integrating" else 0.0
    sp = np.full(n, y_ss + offset)
    # loads (valve-position equivalent): a slow drift always, plus the cause's own
    drift = np.cumsum(rng.normal(0, 1, n)) * 0.0003 * float(rng.uniform(0.2, 1.0))
    drift -= np.linspace(0, drift[-1], n)
    load = drift
    t = np.arange(n) * dt
    if kind == "integrating":
        load = load - x0                                         # the outflow that balances x0
    if cause == "disturbance":
        P = tau * float(rng.uniform(4, 25))
        amp = float(rng.uniform(0.03, 0.1))
        wave = np.sin(2 * math.pi * t / P + rng.uniform(0, 2 * math.pi))
        if rng.random() < 0.4:
            wave = np.tanh(3 * wave)
        load = load + amp * wave
    if cause == "saturation":
        P = tau * float(rng.uniform(6, 20))
        amp = float(rng.uniform(0.2, 0.35))
        x0 = 0.8
        sp = np.full(n, (K * x0 if kind != "integrating" else 0.0) + offset)
        load = load + amp * np.sin(2 * math.pi * t / P) + (0.0 if kind != "integrating" else x0 - (x0 - 0.0))
        if kind == "integrating":
            load = drift - x0 + amp * np.sin(2 * math.pi * t / P)
        valve = _Healthy(x0, dt)
    noise_std = span * float(rng.uniform(0.001, 0.006))
    if cause == "tuning":
        noise_std *= 0.3
    if cause == "quantisation":
        q = span * float(rng.uniform(0.005, 0.02))
        noise_std = 0.0
        load = load - drift
        sp = np.round((sp - offset) / q) * q + offset + 0.5 * q     # between two steps
    else:
        q = 0.0
    op, pv = _run(valve, proc, Kc, Ti, dt, sp, load, offset, noise_std, q, x0, 1.0 if K > 0 else -1.0, rng)
    op_scale = 100.0 if rng.random() < 0.5 else 1.0
    return {"t": t, "op": op * op_scale, "pv": pv, "sp": sp, "cause": cause, "S": S, "J": J, "valve": valve_name,
            "process": kind, "op_scale": op_scale, "dt": dt}
