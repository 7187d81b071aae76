"""Plants of the benchmark's generalisation part, written apart from the package's physics core.

Nothing here imports :mod:`valve_gym.core`, :mod:`valve_gym.plant`, :mod:`valve_gym.friction` or
:mod:`valve_gym.params`: the valves and processes below are coded from their textbook equations, so
that a compensator trained on the core's simulator meets another simulator's valves and plants (as
the diagnosis' textbook-loop simulator does for the diagnosis).

Each loop is a positioner, a sticky stem and a process, integrated with ``n_sub`` sub-steps per
controller scan (``dt = scan_s / n_sub``, at most 0.5 s), input held over the scan:

Positioner
    first-order lag ``tau_p dp/dt = op - p`` (exact discretisation), ``tau_p`` 0.2-2 s.
Valves (stick band ``S`` and slip jump ``J``, fractions of the stroke)
    ``"stick_band"``: the two-parameter stick-slip description of Choudhury, Thornhill & Shah
    (2005) coded from its statement: a stuck stem breaks away once the positioner output has moved
    by ``J`` on in the direction of the last motion, or by ``S`` back against it, and then follows
    it at ``(S - J)/2`` behind.

    ``"force_balance"``: an overdamped stem with Karnopp's stick condition (Karnopp 1985) and
    static friction that varies along the stroke (packing wear): net force ``F = p - x`` (in units
    of stroke, force over spring rate); stuck while ``|F| <= f_s(x)``, then
    ``tau_s dx/dt = F - f_c sign(dx/dt)`` until the velocity reaches zero; ``f_s = (S + J)/2
    (1 + 0.3 sin(6 pi x))``, ``f_c = (S - J)/2``, stem time constant ``tau_s`` 0.3-1 s. A reversal
    from rest needs an input change ``f_c + f_s`` (= ``S`` where the sine is 0), a breakaway jumps
    by ``f_s - f_c`` over ``tau_s``. None of the package's friction models has a stroke-dependent
    band or a stem that slides over several scans.
Processes (valve flow ``q = q_max x``, extra inflow ``d`` [m^3/s])
    ``"tank"``: ``A dL/dt = q + d - k_out sqrt(L)``;
    ``"integrating"``: ``A dL/dt = q + d - q_out`` (pumped outlet, ``q_out`` constant);
    ``"fopdt"``: a flow loop, ``T dy/dt = K x(t - theta) + d' - y``, ``y`` in normalised flow units
    (the blocks' ``pv``), ``d'`` the load in the same units.

Every loop starts at rest at its set point with the valve at the opening that holds it there.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["PlantSpec", "UnseenPlants", "VALVES", "PROCESSES", "pi_tuning"]

#: Valve models of this module.
VALVES = ("stick_band", "force_balance")
#: Process kinds of this module.
PROCESSES = ("tank", "integrating", "fopdt")


@dataclass(frozen=True)
class PlantSpec:
    """One loop's plant (scalars).

    Attributes
    ----------
    process : str, one of :data:`PROCESSES`
    valve : str, one of :data:`VALVES` (or ``"none"``: the stem follows the positioner)
    S, J : float, fraction of stroke (``0 <= J <= S``)
    tau_p : float, s, positioner lag
    tau_s : float, s, stem time constant of ``force_balance``
    area : float, m^2 (tank, integrating)
    q_max : float, m^3/s (tank, integrating); for ``fopdt`` the gain ``K`` [pv per unit opening]
    k_out : float, m^2.5/s (tank); ``T`` [s] for ``fopdt``
    theta : float, s, dead time of ``fopdt`` (0 otherwise)
    level : float, operating point (m, or flow units for ``fopdt``)
    """

    process: str
    valve: str
    S: float
    J: float
    tau_p: float
    tau_s: float
    area: float
    q_max: float
    k_out: float
    theta: float
    level: float

    def opening(self) -> float:
        """Steady valve opening at the operating point, no load (fraction of stroke)."""
        if self.process == "tank":
            return self.k_out * math.sqrt(self.level) / self.q_max
        if self.process == "fopdt":
            return self.level / self.q_max
        return 0.5                             # integrating: the pump takes half the full flow

    def model(self) -> tuple[float, float, float]:
        """``(K, T, delay)`` of the loop's first-order (or integrating, ``T = inf``) model, for tuning.

        ``K``: pv per unit opening (integrating: pv per second per unit opening); ``delay``: dead time
        plus the positioner lag [s] (the scan's half is added by :func:`pi_tuning`).
        """
        if self.process == "tank":
            s = math.sqrt(self.level)
            return 2.0 * self.q_max * s / self.k_out, 2.0 * self.area * s / self.k_out, self.tau_p
        if self.process == "integrating":
            return self.q_max / self.area, math.inf, self.tau_p
        return self.q_max, self.k_out, self.theta + self.tau_p


def pi_tuning(spec: PlantSpec, scan_s: float) -> tuple[float, float]:
    """The loop's PI tuning ``(Kc [1/pv], Ti [s])``: SIMC (Skogestad 2003) with a moderate ``tau_c``.

    ``tau_c = max(T/8, 4 theta)`` for a self-regulating loop (the default tank's rule, ``T/8``) and
    ``tau_c = 20 s + 4 theta`` for the integrating one; ``theta = delay + scan_s/2``.
    """
    K, T, delay = spec.model()
    theta = delay + scan_s / 2.0
    if math.isinf(T):
        tc = 20.0 + 4.0 * theta
        return 1.0 / (K * (tc + theta)), 4.0 * (tc + theta)
    tc = max(T / 8.0, 4.0 * theta)
    return T / (K * (tc + theta)), min(T, 4.0 * (tc + theta))


def _col(specs, name) -> np.ndarray:
    return np.array([getattr(s, name) for s in specs], dtype=float)


class UnseenPlants:
    """``n`` loops of :class:`PlantSpec` at one scan time, advanced one scan per :meth:`step`.

    Parameters
    ----------
    specs : sequence of PlantSpec
    scan_s : float, s
    frictionless : bool, optional
        Run every valve without friction (the stem follows the positioner).
    """

    def __init__(self, specs, scan_s: float, frictionless: bool = False):
        self.n = len(specs)
        self.scan_s = float(scan_s)
        self.n_sub = max(1, int(math.ceil(self.scan_s / 0.5 - 1e-9)))
        self.dt = self.scan_s / self.n_sub
        kinds = np.array([s.process for s in specs])
        self.tank, self.integ, self.fopdt = (kinds == k for k in PROCESSES)
        valves = np.array(["none" if frictionless else s.valve for s in specs])
        self.band, self.force = valves == "stick_band", valves == "force_balance"
        self.S, self.J = _col(specs, "S"), _col(specs, "J")
        self.a_p = np.exp(-self.dt / _col(specs, "tau_p"))
        self.a_s = np.exp(-self.dt / _col(specs, "tau_s"))
        self.area, self.q_max, self.k_out = _col(specs, "area"), _col(specs, "q_max"), _col(specs, "k_out")
        self.level0 = _col(specs, "level")
        self.x0 = np.array([s.opening() for s in specs])
        self.delay = np.rint(_col(specs, "theta") / self.dt).astype(int)
        self.fc = (self.S - self.J) / 2.0

    def reset(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rest at the operating point: ``(pv (n,), stem (n,), op (n,))``."""
        self.y = self.level0.copy()
        self.p = self.x0.copy()
        self.x = self.x0.copy()
        self.ref = self.x0.copy()              # positioner output where the stem last stuck
        self.dir = np.ones(self.n)              # direction of the last motion
        self.stuck = np.ones(self.n, bool)
        self.moving = np.zeros(self.n)          # force_balance: +-1 while sliding, 0 at rest
        self.buf = np.repeat(self.x0[None, :], int(self.delay.max()) + 1, axis=0)
        self.k = 0
        self.q_out = self.q_max * self.x0       # integrating: constant pumped outflow
        return self.y.copy(), self.x.copy(), self.x0.copy()

    def _stick_band(self) -> None:
        p, m = self.p, self.band
        d = p - self.ref
        thr = np.where(d * self.dir > 0, self.J, self.S)
        brk = m & self.stuck & (np.abs(d) > thr)
        new_dir = np.where(brk, np.sign(d), self.dir)
        follow = p - new_dir * self.fc
        go = m & (brk | (~self.stuck & ((follow - self.x) * new_dir > 0)))
        stop = m & ~self.stuck & ~go
        self.x = np.where(go, follow, self.x)
        self.dir = np.where(m, new_dir, self.dir)
        self.ref = np.where(stop, p, self.ref)
        self.stuck = np.where(m, (self.stuck & ~brk) | stop, self.stuck)

    def _force_balance(self) -> None:
        m = self.force
        F = self.p - self.x
        fs = (self.S + self.J) / 2.0 * (1.0 + 0.3 * np.sin(6.0 * np.pi * self.x))
        start = m & (self.moving == 0) & (np.abs(F) > fs)
        mv = np.where(start, np.sign(F), self.moving)
        target = self.p - mv * self.fc
        x_new = target + (self.x - target) * self.a_s
        slide = m & (mv != 0) & ((target - self.x) * mv > 0)
        self.x = np.where(slide, x_new, self.x)
        self.moving = np.where(m, np.where(slide, mv, 0.0), self.moving)

    def step(self, op: np.ndarray, load: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One scan with valve input ``op`` (n,) and load ``load`` (n,) held: ``(pv, stem)`` after it."""
        op = np.clip(np.asarray(op, float), 0.0, 1.0)
        free = ~(self.band | self.force)
        for _ in range(self.n_sub):
            self.p = op + (self.p - op) * self.a_p
            self._stick_band()
            self._force_balance()
            self.x = np.clip(np.where(free, self.p, self.x), 0.0, 1.0)
            self.buf[self.k % self.buf.shape[0]] = self.x
            xd = self.buf[(self.k - self.delay) % self.buf.shape[0], np.arange(self.n)]
            self.k += 1
            q = self.q_max * self.x + load
            dl_tank = (q - self.k_out * np.sqrt(np.maximum(self.y, 0.0))) / self.area
            dl_int = (q - self.q_out) / self.area
            dy_f = (self.q_max * xd + load - self.y) / np.maximum(self.k_out, 1e-9)
            dy = np.where(self.tank, dl_tank, np.where(self.integ, dl_int, dy_f))
            self.y = np.maximum(self.y + self.dt * dy, 0.0)
        return self.y.copy(), self.x.copy()
