"""A third held-out check of the stiction compensators: plants, valves, loads and noise coded here alone.

Like the second held-out family (``benchmarks/learned_unseen_check.py``, whose harness this script uses:
SIMC tuning from a step test of the frictionless loop, one ``load_controller`` block per scan group, the
benchmark's scores), nothing here was used while the compensators were designed, trained or tuned, and every
choice below was fixed before any compensator was run on it. Nothing physical is imported from valve_gym.
Every loop starts at rest at its set point, its stem stuck just after an upward move (positioner output
``F_c`` above the stem, or ``S / 2`` for the dead band; the controller's output there), as a running loop
leaves it; the set point is held; ``pv`` is in the units named below.

Plants (``kind``)
    ``cone``: level ``L`` [m] of a conical tank (cross-section ``A_b (1 + c L)^2``, ``c`` 1-3 /m) with a
    gravity drain ``k sqrt(L)``, inflow ``q_max (x + d)``; time constant 40-150 s at the operating level
    (0.4-0.8 m, tank 1.2 m), longer above it.
    ``mixing``: outlet composition of a blend, dead-time dominant: the valve stream (composition 1) mixes with
    a stream of flow ``r_b`` (composition 0), ``c = (x + d) / (x + d + r_b)``, carried through a line of dead
    time ``theta`` into a mixed tank of time constant ``T`` (10-40 s, ``theta / T`` 1-3).
    ``neutral``: a neutralisation: reagent-to-feed ratio ``s`` mixed in a tank (``T_m`` 20-60 s, the valve
    passes ``x + d``), a transport delay of 2-8 s, a sigmoid titration curve ``1 / (1 + exp(-beta (s - s_eq)))``
    (``beta`` 8-25 per unit ratio, so the static gain varies several-fold over the valve's travel) seen through
    an electrode lag of 3-10 s; the operating point sits at 0.25-0.75 of the curve.
    ``flow``: a liquid flow loop with pipe inertia, ``tau dq/dt = (1 + d)^2 - (k_p + 1/x^2) q^2`` (supply
    pressure ``(1 + d)^2``, pipe loss ``k_p`` 0.5-3, linear trim), linearised time constant ``T`` 0.5-3 s,
    measured through a flowmeter lag of 0.3-2 s; ``pv`` = flow / the full-open flow without pipe loss.
Valves (behind a first-order positioner, ``tau_p`` 0.3-2 s, output ``p`` in fractions of stroke)
    The stiction size ``S`` (reversal band: dead band plus stick band) and slip ``J`` are fractions of stroke;
    healthy valves have ``S < 0.004``, sticky ones 0.005-0.10.

    ``force_balance``: Kayihan & Doyle (2000) stem force balance ``m x'' = k (p - x) - c x' - F_f`` divided by
    the spring rate ``k`` (forces in stroke units): ``x'' = wn^2 (p - x - F_f) - 2 zeta wn x'`` (``wn``
    30-120 rad/s, ``zeta`` 0.5-1.2); Karnopp stick condition (stuck while ``|p - x| <= F_s``) and, while
    sliding, Coulomb plus Stribeck friction ``F_c + (F_s - F_c) exp(-|v| / v_s)`` (``v_s`` 0.002-0.01
    stroke/s). ``F_s = (S + J) / 2``, ``F_c = (S - J) / 2``: a reversal from rest needs an input move
    ``F_s + F_c = S``, a breakaway slips by about ``F_s - F_c = J`` (more with an underdamped stem, less where
    the Stribeck curve re-sticks it early). Integrated semi-implicitly in 1-ms steps while the stem moves.

    ``lugre``: the LuGre dynamic friction model (Canudas de Wit et al. 1995) on the same stem:
    ``dz/dt = v - sigma0 |v| z / g(v)``, ``g(v) = F_c + (F_s - F_c) exp(-|v| / v_s)``,
    ``F_f = sigma0 z + sigma1 dz/dt`` (viscous part in ``zeta``), bristle stiffness ``sigma0`` 100-200 spring
    rates (Garcia's valve: 124), critically damped bristles (``sigma1 = 2 sqrt(sigma0) / wn``), ``wn`` 20-40
    rad/s (the bristles' ``wn sqrt(sigma0)`` stays below 600 rad/s for the 0.5-ms steps); the same
    ``F_s``, ``F_c`` from ``S``, ``J`` (pre-sliding creep ``F_s / sigma0`` before breakaway). 0.5-ms steps.

    ``dead_band``: pure backlash of total width ``S``: the stem stays while ``|p - x| <= S / 2`` and is
    dragged at ``S / 2`` behind ``p`` beyond it; no slip (``J = 0``).
Loads ``d`` (fraction of the valve's full flow; for ``flow`` a relative supply change)
    ``ou``: Ornstein-Uhlenbeck, std 0.002-0.01, time constant 60-600 s; ``walk``: a random walk of
    5e-5-2e-4 per sqrt(s); ``sine``: 0.005-0.02 amplitude, period 300-1200 s, on a small OU (std 0.001-0.003);
    ``step``: 1-4 % of full flow at 20-60 % of the record, on the same small OU.
Measurement
    AR(1) coloured noise (std 0.0005-0.004 pv units, i.e. 0.5-4 mm on the tank; correlation time 1-10 s),
    then a 12-bit transmitter: the reading is quantised to ``span / 4096`` (``span`` 1.2 m for the tank,
    1 elsewhere).
Design (fixed before any compensator ran)
    4 plants x 3 valves, balanced (loop ``i``: plant ``i % 4``, valve ``(i // 4 + i // 12) % 3``, load
    ``(i // 12) % 4``), every third loop healthy; the scan fits the loop: 0.25 or 1.5 s for the flow loop,
    1.5 or 4 s for the others; 48 loops of one hour, seed 2718.

Usage::

    python benchmarks/learned_third_check.py [--n 48] [--seed 2718] [--names pi knocker learned learned_network]
        [--policy LABEL=FILE ...]

Besides the second script's table it prints, for each row, the LC share and the median compensation ratio
``R`` on the sticky loops by plant, by valve and by load.

Under the PI alone (``--names pi``, the only controller run while the family was written), every force-balance
and LuGre sticky loop but one stick-slips (median 8 slips of more than ``J / 2`` per hour), the PI's stem
travels 0.18 of the frictionless PI's (median) and its IAE is 1.6 times the frictionless one's (median over the
32 sticky loops). Its cycles are slow (5-20 min on the neutralisation and mixing loops), asymmetric on the
titration curve and jittered by the loads, so the benchmark's limit-cycle rule calls few of them regular (2 of
32 in one hour, as many as under the frictionless PI, whose calls come from the sine and step loads): on this
family ``R`` and the travel say more than the LC share. On the loops without dead time (the tank, the flow
loop) stiction shows more as irregular, noise-driven hunting than as a cycle.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from numba import njit

_HERE = Path(__file__).resolve().parent
for _p in (_HERE.parent, _HERE):                 # this checkout's package, and the second script's harness
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

from learned_unseen_check import (  # noqa: E402, F401  (KNOWN, DIAGNOSED, check_family: the family's rows and runner)
    DIAGNOSED,
    KNOWN,
    check_family,
    factorial_loop,
    family_main,
)

KINDS = ("cone", "mixing", "neutral", "flow")
VALVE_KINDS = ("force_balance", "lugre", "dead_band")
#: The process kind an engineer would give the diagnosis for each plant (``--diagnosed``).
DIAG_KIND = {"cone": "tank", "mixing": "first_order", "neutral": "first_order", "flow": "first_order"}
LOAD_KINDS = ("ou", "walk", "sine", "step")
SCANS = (0.25, 1.5, 4.0)
#: Plant sub-step [s]; valve sub-steps [s] of the force balance and of LuGre.
H_PLANT, DT_FB, DT_LUGRE = 0.05, 1e-3, 5e-4
#: Length of the tuning step test [s] (the slow tanks settle within it).
TEST_S = 1800.0
#: Healthy valves: S below this (fraction of stroke).
HEALTHY_S = 0.004

# parameter columns of the kernel
(P_KIND, P_VALVE, P_FS, P_FC, P_S, P_WN, P_C, P_VS, P_SIG0, P_SIG1, P_TAUP,
 P_A, P_B, P_C2, P_D, P_E, P_F, N_PAR) = range(18)
# state columns of the kernel
(X_P, X_X, X_V, X_Z, X_Y1, X_Y2, X_Y3, N_ST) = range(8)


def draw(n: int, seed: int) -> list[dict]:
    """``n`` loops of the family (see the module docstring); one dict per loop."""
    out = []
    for i in range(n):
        r = np.random.default_rng([seed, i])
        kind, valve, load, S, J = factorial_loop(r, i, KINDS, VALVE_KINDS, LOAD_KINDS, HEALTHY_S,
                                                  slip_free=("dead_band",))
        scan = SCANS[int(r.integers(2))] if kind == "flow" else SCANS[1 + int(r.integers(2))]
        row = dict(kind=kind, valve=valve, load=load, S=S, J=J, scan=scan, tau_p=r.uniform(0.3, 2.0),
                   x0=r.uniform(0.35, 0.65), wn=r.uniform(20.0, 40.0) if valve == "lugre" else r.uniform(30.0, 120.0),
                   zeta=r.uniform(0.5, 1.2), vs=r.uniform(0.002, 0.01), sigma0=r.uniform(100.0, 200.0),
                   noise=r.uniform(0.0005, 0.004), t_noise=r.uniform(1.0, 10.0), seed=int(r.integers(1 << 30)))
        if kind == "cone":
            row.update(level=r.uniform(0.4, 0.8), Ab=r.uniform(0.05, 0.2), cone=r.uniform(1.0, 3.0),
                       T=r.uniform(40.0, 150.0), span=1.2)
        elif kind == "mixing":
            T = r.uniform(10.0, 40.0)
            row.update(T=T, delay=T * r.uniform(1.0, 3.0), rb=r.uniform(0.5, 2.0), span=1.0)
        elif kind == "neutral":
            row.update(T=r.uniform(20.0, 60.0), Te=r.uniform(3.0, 10.0), delay=r.uniform(2.0, 8.0),
                       beta=r.uniform(8.0, 25.0), pv0=r.uniform(0.25, 0.75), span=1.0)
        else:
            row.update(T=r.uniform(0.5, 3.0), Ts=r.uniform(0.3, 2.0), kp=r.uniform(0.5, 3.0), span=1.0)
        if load == "ou":
            row.update(ou=r.uniform(0.002, 0.01), t_ou=r.uniform(60.0, 600.0))
        else:
            row.update(ou=r.uniform(0.001, 0.003), t_ou=r.uniform(60.0, 600.0))
        row.update(walk=r.uniform(5e-5, 2e-4) if load == "walk" else 0.0,
                   sine=r.uniform(0.005, 0.02) if load == "sine" else 0.0, period=r.uniform(300.0, 1200.0),
                   phase=r.uniform(0.0, 2.0 * math.pi),
                   step=(r.uniform(0.01, 0.04) * r.choice([-1.0, 1.0])) if load == "step" else 0.0,
                   t_step=r.uniform(0.2, 0.6))
        if load == "walk":
            row["ou"] = 0.0
        out.append(row)
    return out


@njit(cache=False)
def _valve_fb(par, st, op, a_pf, nf):
    """``nf`` force-balance steps of ``DT_FB`` with the positioner driven by ``op`` (one loop, in place)."""
    fs, fc, wn2, c, vs = par[P_FS], par[P_FC], par[P_WN] ** 2, par[P_C], par[P_VS]
    p, x, v = st[X_P], st[X_X], st[X_V]
    for _ in range(nf):
        p = op + (p - op) * a_pf
        F = p - x
        if v == 0.0:
            if abs(F) <= fs:
                continue
            s = 1.0 if F > 0.0 else -1.0
        else:
            s = 1.0 if v > 0.0 else -1.0
        fr = fc + (fs - fc) * math.exp(-abs(v) / vs)
        vn = (v + DT_FB * wn2 * (F - s * fr)) / (1.0 + DT_FB * wn2 * c)
        if vn * s <= 0.0:
            v = 0.0
        else:
            v = vn
            x += DT_FB * v
            if x <= 0.0 or x >= 1.0:
                x, v = min(max(x, 0.0), 1.0), 0.0
    st[X_P], st[X_X], st[X_V] = p, x, v


@njit(cache=False)
def _valve_lugre(par, st, op, a_pf, nf):
    """``nf`` LuGre steps of ``DT_LUGRE`` (one loop, in place)."""
    fs, fc, wn2, c, vs = par[P_FS], par[P_FC], par[P_WN] ** 2, par[P_C], par[P_VS]
    s0, s1 = par[P_SIG0], par[P_SIG1]
    p, x, v, z = st[X_P], st[X_X], st[X_V], st[X_Z]
    dt = DT_LUGRE
    for _ in range(nf):
        p = op + (p - op) * a_pf
        g = max(fc + (fs - fc) * math.exp(-abs(v) / vs), 1e-9)
        av = s0 * abs(v) / g * dt
        if av > 1e-12:
            zss = (g if v > 0.0 else -g) / s0
            zn = zss + (z - zss) * math.exp(-av)
        else:
            zn = z + v * dt
        zd = (zn - z) / dt
        z = zn
        ff = s0 * z + s1 * zd
        v = (v + dt * wn2 * (p - x - ff)) / (1.0 + dt * wn2 * c)
        x += dt * v
        if x <= 0.0 or x >= 1.0:
            x, v = min(max(x, 0.0), 1.0), 0.0
    st[X_P], st[X_X], st[X_V], st[X_Z] = p, x, v, z


@njit(cache=False)
def _advance(par, st, buf, delay, j0, op, load, m, a_p, a_pf, nf):
    """``m`` plant sub-steps of ``H_PLANT`` of every loop with inputs ``op`` (n,) and ``load`` (n,) held."""
    n = par.shape[0]
    nb = buf.shape[1]
    h = H_PLANT
    for i in range(n):
        pr = par[i]
        s = st[i]
        u = min(max(op[i], 0.0), 1.0)
        d = load[i]
        kind, valve = int(pr[P_KIND]), int(pr[P_VALVE])
        for k in range(m):
            if valve == 0:
                p_end = u + (s[X_P] - u) * a_p[i]
                if s[X_V] == 0.0 and abs(s[X_P] - s[X_X]) <= pr[P_FS] and abs(p_end - s[X_X]) <= pr[P_FS]:
                    s[X_P] = p_end                       # stuck over the whole sub-step (p is monotone)
                else:
                    _valve_fb(pr, s, u, a_pf[i], nf[i])
            elif valve == 1:
                _valve_lugre(pr, s, u, a_pf[i], nf[i])
            else:
                s[X_P] = u + (s[X_P] - u) * a_p[i]
                if valve == 2:
                    b = 0.5 * pr[P_S]
                    if s[X_P] - s[X_X] > b:
                        s[X_X] = s[X_P] - b
                    elif s[X_P] - s[X_X] < -b:
                        s[X_X] = s[X_P] + b
                else:
                    s[X_X] = s[X_P]
                s[X_X] = min(max(s[X_X], 0.0), 1.0)
            x = s[X_X]
            jj = j0 + k
            if kind == 0:                                # cone: A, B, C2, D = Ab, c, q_max, k_out; E = H
                L = s[X_Y1]
                area = pr[P_A] * (1.0 + pr[P_B] * L) ** 2
                qin = pr[P_C2] * max(x + d, 0.0)
                s[X_Y1] = min(max(L + h * (qin - pr[P_D] * math.sqrt(max(L, 0.0))) / area, 0.0), pr[P_E])
            elif kind == 1:                              # mixing: A = rb, B = exp(-h/T)
                q = max(x + d, 0.0)
                buf[i, jj % nb] = q / (q + pr[P_A])
                cd = buf[i, (jj - delay[i]) % nb]
                s[X_Y1] = cd + (s[X_Y1] - cd) * pr[P_B]
            elif kind == 2:                              # neutral: A = exp(-h/Tm), B = beta, C2 = s_eq, D = exp(-h/Te)
                q = max(x + d, 0.0)
                s[X_Y2] = q + (s[X_Y2] - q) * pr[P_A]
                buf[i, jj % nb] = s[X_Y2]
                sd = buf[i, (jj - delay[i]) % nb]
                ph = 1.0 / (1.0 + math.exp(-pr[P_B] * (sd - pr[P_C2])))
                s[X_Y1] = ph + (s[X_Y1] - ph) * pr[P_D]
            else:                                        # flow: A = tau, B = kp, D = exp(-h/Ts)
                a = (1.0 + d) ** 2
                bq = (pr[P_B] + 1.0 / max(x, 0.02) ** 2) * h / pr[P_A]
                qq = s[X_Y2] + h * a / pr[P_A]
                s[X_Y2] = (-1.0 + math.sqrt(1.0 + 4.0 * bq * qq)) / (2.0 * bq)   # implicit Euler
                s[X_Y1] = s[X_Y2] + (s[X_Y1] - s[X_Y2]) * pr[P_D]


class ThirdLoops:
    """Batched simulation of the family's loops of one scan time (the harness's simulator interface).

    Parameters
    ----------
    rows : list of dict, from :func:`draw`
    scan : float, s
    frictionless : bool
        Every stem follows its positioner (the reference loops).
    """

    def __init__(self, rows: list[dict], scan: float, frictionless: bool):
        self.rows, self.scan, self.n = rows, float(scan), len(rows)
        self.m = max(1, int(round(self.scan / H_PLANT)))
        n = self.n
        par = np.zeros((n, N_PAR))
        delay = np.zeros(n, np.int64)
        self.x0 = np.array([r["x0"] for r in rows], float)
        self.y0 = np.empty(n)
        h = H_PLANT
        for i, r in enumerate(rows):
            pr = par[i]
            pr[P_KIND] = KINDS.index(r["kind"])
            pr[P_VALVE] = -1 if frictionless else VALVE_KINDS.index(r["valve"])
            S, J = float(r["S"]), float(r["J"])
            pr[P_FS], pr[P_FC], pr[P_S] = (S + J) / 2.0, (S - J) / 2.0, S
            pr[P_WN], pr[P_C], pr[P_VS] = r["wn"], 2.0 * r["zeta"] / r["wn"], r["vs"]
            pr[P_SIG0], pr[P_SIG1] = r["sigma0"], 2.0 * math.sqrt(r["sigma0"]) / r["wn"]
            pr[P_TAUP] = r["tau_p"]
            x0 = r["x0"]
            if r["kind"] == "cone":
                L0, Ab, c = r["level"], r["Ab"], r["cone"]
                qmax = 2.0 * Ab * (1.0 + c * L0) ** 2 * L0 / (r["T"] * x0)
                pr[P_A], pr[P_B], pr[P_C2], pr[P_D], pr[P_E] = Ab, c, qmax, qmax * x0 / math.sqrt(L0), r["span"]
                self.y0[i] = L0
            elif r["kind"] == "mixing":
                pr[P_A], pr[P_B] = r["rb"], math.exp(-h / r["T"])
                delay[i] = max(1, int(round(r["delay"] / h)))
                self.y0[i] = x0 / (x0 + r["rb"])
            elif r["kind"] == "neutral":
                pv0, beta = r["pv0"], r["beta"]
                pr[P_A], pr[P_B], pr[P_D] = math.exp(-h / r["T"]), beta, math.exp(-h / r["Te"])
                pr[P_C2] = x0 - math.log(pv0 / (1.0 - pv0)) / beta
                delay[i] = max(1, int(round(r["delay"] / h)))
                self.y0[i] = pv0
            else:
                q0 = x0 / math.sqrt(1.0 + r["kp"] * x0 ** 2)
                pr[P_A], pr[P_B], pr[P_D] = 2.0 * r["T"] / q0, r["kp"], math.exp(-h / r["Ts"])
                self.y0[i] = q0
        self.par, self.delay = par, delay
        valve = par[:, P_VALVE]
        tau_p = par[:, P_TAUP]
        self.a_p = np.exp(-h / tau_p)
        dt = np.where(valve == 1, DT_LUGRE, DT_FB)
        self.nf = np.rint(h / dt).astype(np.int64)
        self.a_pf = np.exp(-dt / tau_p)
        self.nb = int(delay.max()) + 2
        self.span = np.array([r["span"] for r in rows], float)
        #: positioner output above the stem at rest after an upward move
        self.lead = np.where(valve == 2, 0.5 * par[:, P_S], np.where(valve >= 0, par[:, P_FC], 0.0))

    def _steady_inner(self) -> np.ndarray:
        """The neutralisation's mixed ratio and the flow loop's true flow at rest (the second state)."""
        out = np.zeros(self.n)
        for i, r in enumerate(self.rows):
            if r["kind"] == "neutral":
                out[i] = r["x0"]
            elif r["kind"] == "flow":
                out[i] = self.y0[i]
        return out

    def reset(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rest at the operating point: ``(pv (n,), stem (n,), op (n,))``."""
        st = np.zeros((self.n, N_ST))
        st[:, X_X] = self.x0
        st[:, X_P] = self.x0 + self.lead
        st[:, X_Z] = np.where(self.par[:, P_VALVE] == 1, self.lead / self.par[:, P_SIG0], 0.0)
        st[:, X_Y1] = self.y0
        st[:, X_Y2] = self._steady_inner()
        self.st = st
        fill = np.where(self.par[:, P_KIND] == 1, self.y0, st[:, X_Y2])
        self.buf = np.repeat(fill[:, None], self.nb, axis=1)
        self.j = 0
        return self.st[:, X_Y1].copy(), self.st[:, X_X].copy(), st[:, X_P].copy()

    def step(self, op, load) -> tuple[np.ndarray, np.ndarray]:
        """One scan with input ``op`` (n,) and load ``load`` (n,) held: ``(pv, stem)`` after it."""
        _advance(self.par, self.st, self.buf, self.delay, self.j, np.asarray(op, float), np.asarray(load, float),
                 self.m, self.a_p, self.a_pf, self.nf)
        self.j += self.m
        return self.st[:, X_Y1].copy(), self.st[:, X_X].copy()

    @staticmethod
    def disturbances(rows: list[dict], scan: float, T: int, duration: float) -> tuple[np.ndarray, np.ndarray]:
        """``(noise (T, n), load (T, n))``: AR(1) measurement noise and the loop's load (see the docstring)."""
        from scipy.signal import lfilter

        noise, load = np.empty((T, len(rows))), np.empty((T, len(rows)))
        t = np.arange(T) * scan
        for i, r in enumerate(rows):
            g = np.random.default_rng(r["seed"])
            phi = math.exp(-scan / r["t_noise"])
            w = g.standard_normal(T)
            w[1:] *= math.sqrt(1.0 - phi ** 2)
            noise[:, i] = r["noise"] * lfilter([1.0], [1.0, -phi], w)
            a = math.exp(-scan / r["t_ou"])
            w = g.standard_normal(T)
            w[1:] *= math.sqrt(1.0 - a ** 2)
            ou = r["ou"] * lfilter([1.0], [1.0, -a], w)
            walk = np.cumsum(g.standard_normal(T)) * r["walk"] * math.sqrt(scan)
            sine = r["sine"] * (np.sin(2.0 * math.pi * t / r["period"] + r["phase"]) - math.sin(r["phase"]))
            step = r["step"] * (t >= r["t_step"] * duration)
            load[:, i] = ou + walk + sine + step
        return noise, load

    def measure(self, pv: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """The 12-bit transmitter's reading of ``pv + noise``."""
        q = self.span / 4096.0
        return np.round((pv + noise) / q) * q


def main(argv=None) -> int:
    groups = [("kind", k) for k in KINDS] + [("valve", v) for v in VALVE_KINDS] + [("load", lk) for lk in LOAD_KINDS]
    return family_main(__doc__, ThirdLoops, draw, 48, 2718, argv, healthy_s=HEALTHY_S, test_s=TEST_S,
                       diag_kind=DIAG_KIND, groups=groups)


if __name__ == "__main__":
    raise SystemExit(main())
