"""A sixth held-out check of the stiction compensators: plants, valves, loads and noise coded here alone.

Like the second to fifth held-out families (``benchmarks/learned_unseen_check.py``, whose harness this script
uses: SIMC tuning from a step test of the frictionless loop, one ``load_controller`` block per scan group, the
benchmark's scores; ``benchmarks/learned_third_check.py``, ``benchmarks/learned_fourth_check.py``,
``benchmarks/learned_fifth_check.py``), nothing here was used while the compensators were designed, trained or
tuned, and every choice below was fixed before any compensator was run on it. Nothing physical is imported from
valve_gym. Every loop starts at rest at its set point, its stem stuck just after an upward move (the controller's
output a valve's rest offset above the stem, see below), as a running loop leaves it; the set point is held;
``pv`` is in the units named below. A load ``d`` acts on every plant as extra valve flow would (on the reactor
as less coolant; ``d > 0`` raises ``pv``).

Plants (``kind``; ``f(x)`` the valve's inherent characteristic: equal-percentage ``R^(x - 1)`` (``R`` 20-50) on
the reboiler's steam, linear elsewhere)
    ``cstr``: temperature ``T`` of a jacketed stirred-tank reactor with a first-order exothermic reaction,
    cooled by tempered water through an air-to-close valve (the stem closes it: coolant flow ``1 - x - d`` of
    full, the load ``d`` coolant drawn by other users). ``c' = (1 - c) / theta - k(T) c``, ``T' = (T_f - T) /
    theta + dT_ad k(T) c - alpha (T - T_j)``, ``T_j' = (q / (q_0 tau_j)) (T_ci - T_j) + alpha_j (T - T_j)``,
    ``k(T) = k_0 exp(-(E/R) (1/T - 1/T_0))``: ``T_0`` 330-370 K, ``E/R`` 3000-7000 K, residence time ``theta``
    300-600 s, conversion ``X_0`` 0.6-0.9 there, jacket residence ``tau_j`` 4-12 s at the operating flow. The
    rest (:func:`cstr_design`) follows from a heat-removal time ``tau_r`` 40-100 s (``1 / tau_r = 1 / theta +
    alpha (1 - beta)``), the jacket's share ``beta`` 0.5-0.8 (``beta = alpha_j tau_j / (1 + alpha_j tau_j)``:
    how far the jacket follows the reactor), the exotherm's share ``phi`` 0.3-0.6 of the removal slope (the
    heat release's slope in ``T`` at a fixed concentration over ``1 / tau_r``: the fast gain is ``1 / (1 -
    phi)`` times the unreacting one's) and a cold feed taking ``psi_f`` 0-0.2 of the heat released; so ``dT_ad``
    43-393 K, coolant 7-29 K below the reactor. Open loop the reactor is stable, overshoots its final rise by
    up to 26 % (the hotter reactor depletes its reactant, which takes part of the rise back with time constant
    about ``theta (1 - X_0)``) and heats more for a closing than it cools for an opening move (the jacket's
    duty saturates with the flow; the exotherm's slope grows with ``T``). ``pv = pv_0 + (T - T_0) / 20 K``
    (``pv_0`` 0.4-0.6) read by an RTD in a thermowell (lag 3-10 s) in 0.005-K steps; gain 0.5-1.9 per stroke.
    ``tray``: temperature of a column's sensitive tray near the bottom, the valve on the reboiler's steam: the
    boilup ``V = f(x) + d`` follows through the reboiler's lag ``T_r`` (3-10 s); the composition front reaches
    the tray after a dead time of 2-6 s and two lags (``T_1`` 20-60 s, ``T_2`` 5-20 s) and moves its
    temperature along a sigmoid, ``pv_0 + A (tanh(z / w_s + o) - tanh(o))`` (``z`` the relative change of the
    lagged boilup, ``w_s`` 0.2-0.5, ``o`` +-0.6: the gain falls as the front moves off the tray, unequally up and
    down; ``A`` gives ``K`` 0.6-1.8 per stroke at the operating point); inverse response: more vapour first
    pushes liquid down from the trays above (tray hydraulics), which cools the tray by ``kappa K / ln R`` (``kappa``
    0.1-0.4) per unit of relative boilup above its value lagged by the hydraulics' ``T_h`` (5-20 s): the tray
    first cools by 3.5-19 % of its final rise. Thermocouple lag 1-4 s; ``pv_0`` 0.4-0.6.
    ``header``: pressure ``P`` of a steam header (fraction of the HP main's), fed through a let-down valve from
    the main with flow ``C_v (x + d) psi(P)``: choked, ``psi = 1``, while ``P <= 0.55``, ``psi = sqrt(1 - ((P -
    0.55) / 0.45)^2)`` above it; drawn by a back-pressure turbine whose nozzles are choked (Stodola: ``k_t P``,
    ``s_t`` 50-80 % of the flow at the operating point) and by process users through a let-down to the LP
    header (``P_b`` 0.1-0.2): ``k_u sqrt(P - P_b)``. ``P_0`` 0.35-0.7 (the valve choked at the operating point
    on 7 of the 12 header loops), header time constant 4-15 s, gain 0.7-1.7 per stroke; ``pv = P`` read through
    the transmitter's damping (a lag of 0.3-1.5 s).
    ``twotank``: level ``L_1`` [m] of the first of two interacting tanks: inflow ``q_0 (x + d) / x_0``, a hand
    valve at a fixed opening between them, ``c_12 sgn(L_1 - L_2) sqrt|L_1 - L_2|`` (a drop of 0.1-0.3 m at the
    operating point), the second drained through its own hand valve, ``c_2 sqrt(L_2)`` (``L_2`` 0.3-0.8 m); the
    first tank's time constant ``2 A_1 (L_1 - L_2) / q_0`` 5-20 s, the second's ``2 A_2 L_2 / q_0`` 40-150 s:
    the level jumps as the head over the hand valve builds, then creeps as the second tank fills (63 % after
    61-300 s); gain ``2 L_1 / x_0``, 2.2-5.4 m per stroke.
Valves (a first-order positioner, ``tau_p`` 0.2-1.2 s, output ``p`` in fractions of stroke, then a spring-
diaphragm actuator: an air-volume lag ``tau_a`` 0.1-0.5 s to the pressure ``P_a`` in stroke units, and a
second-order stem ``x'' = wn^2 (P_a - x - F_f) - 2 zeta wn x'``, ``wn`` 10-30 rad/s, ``zeta`` 0.3-0.8, friction
``F_f`` over the spring rate, integrated semi-implicitly in 1-ms steps)
    The stiction size ``S`` (reversal band: the input change that reverses a stem at rest) and slip ``J`` are
    fractions of stroke; healthy valves have ``S < 0.004``, sticky ones 0.005-0.10 (log-uniform), ``J``
    uniform in ``[0, S]``. Every model takes ``F_s = (S + J) / 2`` and ``F_c = (S - J) / 2`` (scaled as below),
    holds the stem while ``|P_a - x| <= F_s`` (a hard stop: no presliding), and sticks it again when its
    velocity reverses. At rest after an upward move ``P_a - x = F_c``: a reversal needs an input move of ``F_c +
    F_s = S``, a move on in the same direction ``F_s - F_c = J``, and the stem then slips by about ``J`` (more
    with the underdamped stem's overshoot).

    ``dahl_karnopp``: Karnopp's static band with Dahl's friction in motion: from breakaway the friction relaxes
    from ``F_s`` to ``F_c`` along the stem's path, ``dF_f / ds = (F_c sgn(x') - F_f) / lambda`` (Dahl's model
    with exponent 1, stiffness ``F_c / lambda``), ``lambda`` 2-15 % of ``S``: a breakaway slips 1.0-1.35 ``J``
    (less where ``lambda`` is long against ``J``).

    ``wear_band``: packing worn where the stem sits most: ``F_s`` and ``F_c`` scale with ``m(x) = (1 + w (1 -
    exp(-((x - x_w) / b)^2))) / m_0``, the band's centre ``x_w`` within 0.02 of the operating point, ``b``
    0.02-0.06, ``w`` 0.5-1.5, ``m_0`` making ``m(x_0) = 1``; Coulomb friction ``F_c m(x)`` in motion. ``S`` and
    ``J`` are the band and slip at the operating point; a stem pushed out of the worn band meets up to ``1 +
    w`` times them (on a slow ramp over ``4 S`` from the operating point, slips of 0.9-2.4 ``J``).

    ``drying``: packing drying out (or tightened) over the hour: ``F_s`` and ``F_c`` scale with ``m(t) = 1 + g
    (t / 3600 s - 1/2)`` (``g`` 0.3-0.8, ``t`` from the start of the record), so the band and slip are ``S`` and
    ``J`` at mid-record (their means over the hour), ``1 - g/2`` of them at the start and ``1 + g/2`` at the
    end; in motion an exponential Stribeck curve, ``F_f = sgn(x') m(t) (F_c + (F_s - F_c) exp(-|x'| / v_s))``
    (``v_s`` 0.0005-0.002 stroke/s).

    Rest offsets (controller output above the stem): ``F_c`` (``dahl_karnopp``, ``wear_band``), ``F_c (1 -
    g/2)`` (``drying``). The frictionless valves keep the positioner's lag and the air lag.
Loads ``d`` (fraction of the valve's full flow; of the full coolant flow on the reactor; every load starts at 0)
    small (24 of 48 loops): ``ou``: Ornstein-Uhlenbeck, std 0.001-0.005, time constant 60-600 s; ``drift``: a
    ramp of +-0.001-0.005 over the record plus a random walk of 1e-5-3e-5 per sqrt(s);
    medium: ``triangle``: a triangular wave between +-0.4-1.2 % (period 600-1800 s), from 0; ``telegraph``: a
    random telegraph between 0 and +-0.3-1 % (mean dwell 120-600 s); each on a small OU (std 0.001, 300 s).
Measurement
    ``cstr``: white (half the loops) or AR(1) noise (1-5 s), 0.5-2 pv x1000 (0.01-0.04 K), the RTD's 0.005-K
    steps; ``tray``: white noise, 0.5-1.5 pv x1000, with outliers (a thermocouple's spikes: 0.2-1 % of the
    scans, 4-10 times the noise, either sign); ``header``: 1-3 pv x1000, filtered by the transmitter's damping
    (AR(1) with its time constant); ``twotank``: AR(1) noise (the surface; 1-5 s), 0.5-3 mm. Tray, header and
    levels: a 14-bit transmitter (``span / 16384``; span 1, 1 and 1.5 m).
Design (fixed before any compensator ran)
    4 plants x 3 valves x 4 loads, a full factorial (loop ``i``: plant ``i % 4``, valve ``(i // 4 + i // 12)
    % 3``, load ``(i // 12) % 4``), every third loop healthy; scans 1 or 2 s for the reactor and the tray, 0.5 or
    1 s for the header and the tanks; tuning step test 1200 s; 48 loops of one hour, seed 6161.

Usage::

    python benchmarks/learned_sixth_check.py [--n 48] [--seed 6161] [--names pi knocker learned learned_network]
        [--policy LABEL=FILE ...]

Besides the second script's table it prints, for each row, the LC share and the median compensation ratio
``R`` on the sticky loops by plant, by valve and by load.

Under the PI alone (``--names pi``, the only controller run while the family was written), all 32 sticky loops
stick-slip (at least two slips an hour, a slip being a stem move of more than ``J / 2`` and 0.2 % of stroke
within one scan; median 23.5 per hour: 21 with a small load, 25.5 with a medium one; all 16 sticky loops with a
small load). The fewest, 2-4 an hour, are on 7 loops, bands of 1.1-9 % on the slower tray and reactor; the
header (median 106 an hour) and the tanks (88) slip most. The PI's stem travels 0.15 of the frictionless PI's
(median; 0.004-15: more than the frictionless PI's on 3 loops, two tanks and a tray, whose 5-10 % bands cycle)
and its IAE is 2.22 times the frictionless one's (median over the 32 sticky loops; IAE ratio 1.02-33): 3.2 on
the reactor, 2.7 on the tray, 1.4 on the header, 3.2 on the tanks; 2.2 with the Dahl-Karnopp valves, 5.8 with
the wear band, 1.5 with the drying packing; 1.6 under an OU load, 2.2 under a drift, 3.6 under the triangle, 2.2
under the telegraph. On 5 of the 32 stiction costs the PI less than 10 % of the frictionless IAE, all bands of
1.6 % or less (4 of them drying valves): a 0.9 % and a 0.6 % band on the tanks and a 1.1 % band with ``J =
0.15 S`` on the header, whose many small slips (136-572 an hour) cost little against the noise; a 0.9 % band
with ``J = 0.34 S`` on the reactor under a drift (1.08); and a 1.6 % band on the reactor whose drift stays under
the band, so the stem slips twice in the hour (1.02); the frictionless PI's own ``R`` is under 1 there (the
floor of ``R``). The benchmark's limit-cycle rule calls 6 of the 32 under the PI (2 header loops, 3 tank loops,
1 reactor; periods 31-420 s) and 1 under the frictionless PI (a reactor under the triangle, the load's own
period): the PI's slips here are many but irregular, jittered by the noise and the loads; on this family ``R``
and the travel say more than the LC share.
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
    ar1,
    check_family,
    factorial_loop,
    family_main,
)

KINDS = ("cstr", "tray", "header", "twotank")
VALVE_KINDS = ("dahl_karnopp", "wear_band", "drying")
#: The process kind an engineer would give the diagnosis for each plant (``--diagnosed``).
DIAG_KIND = {"cstr": "first_order", "tray": "first_order", "header": "first_order", "twotank": "tank"}
LOAD_KINDS = ("ou", "drift", "triangle", "telegraph")
#: Scan times [s] of each plant (one drawn per loop).
SCANS = {"cstr": (1.0, 2.0), "tray": (1.0, 2.0), "header": (0.5, 1.0), "twotank": (0.5, 1.0)}
#: Measurement noise std of each plant [pv units] (drawn uniformly).
NOISE = {"cstr": (0.0005, 0.002), "tray": (0.0005, 0.0015), "header": (0.001, 0.003), "twotank": (0.0005, 0.003)}
#: Plant sub-step [s]; stem step [s].
H_PLANT, DT_STEM = 0.05, 1e-3
#: Length of the tuning step test [s] (the reactor's slow conversion mode and the second tank settle within it).
TEST_S = 1200.0
#: Healthy valves: S below this (fraction of stroke).
HEALTHY_S = 0.004
#: Transmitter resolution ``span / LEVELS`` (14 bits); the reactor's RTD reads in 0.005-K steps.
LEVELS, CSTR_RES_K = 16384, 0.005
#: The reactor's temperature span [K] (``pv = pv_0 + (T - T_0) / CSTR_SPAN``).
CSTR_SPAN = 20.0
#: Critical pressure ratio of the steam let-down valve (choked below it).
R_CRIT = 0.55
#: The drying valve's friction ramp is referred to a record of this length [s] (its mean over it is ``S``).
HOUR = 3600.0

# parameter columns of the kernel
(P_KIND, P_VALVE, P_FS, P_FC, P_WN, P_C, P_LAM, P_XW, P_BW, P_WW, P_MN, P_GR, P_VS, P_CHAR, P_F0,
 P_A, P_B, P_C2, P_D, P_E, P_F, P_G, P_H, P_I, P_K, P_L, P_M, N_PAR) = range(28)
# state columns of the kernel
(X_P, X_A, X_X, X_V, X_F, X_M, X_T, X_Y1, X_Y2, X_Y3, X_Y4, X_Y5, N_ST) = range(13)


def _loads(r, row: dict, load: str) -> None:
    """The load's settings (see the module docstring), drawn in a fixed order whatever the load kind."""
    ou, t_ou = r.uniform(0.001, 0.005), r.uniform(60.0, 600.0)
    drift, walk = r.uniform(0.001, 0.005) * float(r.choice([-1.0, 1.0])), r.uniform(1e-5, 3e-5)
    tri, tri_period = r.uniform(0.004, 0.012) * float(r.choice([-1.0, 1.0])), r.uniform(600.0, 1800.0)
    tel, tel_dwell = r.uniform(0.003, 0.010) * float(r.choice([-1.0, 1.0])), r.uniform(120.0, 600.0)
    row.update(ou=0.0, t_ou=300.0, drift=0.0, walk=0.0, tri=0.0, tri_period=tri_period, tel=0.0,
               tel_dwell=tel_dwell)
    if load == "ou":
        row.update(ou=ou, t_ou=t_ou)
    elif load == "drift":
        row.update(drift=drift, walk=walk)
    elif load == "triangle":
        row.update(ou=0.001, tri=tri)
    else:
        row.update(ou=0.001, tel=tel)


def _plant_row(r, row: dict, kind: str) -> None:
    """The plant's settings (see the module docstring), drawn in a fixed order whatever the kind."""
    k = dict(
        cstr=dict(T0=r.uniform(330.0, 370.0), ER=r.uniform(3000.0, 7000.0), theta=r.uniform(300.0, 600.0),
                  X0=r.uniform(0.6, 0.9), tau_r=r.uniform(40.0, 100.0), phi=r.uniform(0.3, 0.6),
                  beta=r.uniform(0.5, 0.8), tau_j=r.uniform(4.0, 12.0), psi_f=r.uniform(0.0, 0.2),
                  Tm=r.uniform(3.0, 10.0), pv0=r.uniform(0.4, 0.6)),
        tray=dict(R=r.uniform(20.0, 50.0), K=r.uniform(0.6, 1.8), T_r=r.uniform(3.0, 10.0),
                  T1=r.uniform(20.0, 60.0), T2=r.uniform(5.0, 20.0), delay=r.uniform(2.0, 6.0),
                  T_h=r.uniform(5.0, 20.0), kappa=r.uniform(0.1, 0.4), w_s=r.uniform(0.2, 0.5),
                  off=r.uniform(-0.6, 0.6), Tm=r.uniform(1.0, 4.0), pv0=r.uniform(0.4, 0.6)),
        header=dict(P0=r.uniform(0.35, 0.7), s_t=r.uniform(0.5, 0.8), P_b=r.uniform(0.1, 0.2),
                    tau_h=r.uniform(4.0, 15.0), Tm=r.uniform(0.3, 1.5)),
        twotank=dict(L2=r.uniform(0.3, 0.8), dL=r.uniform(0.1, 0.3), tau1=r.uniform(5.0, 20.0),
                     tau2=r.uniform(40.0, 150.0), t_noise=r.uniform(1.0, 5.0)),
    )[kind]
    row.update(k)
    row["span"] = {"cstr": 1.0, "tray": 1.0, "header": 1.0, "twotank": 1.5}[kind]


def draw(n: int, seed: int) -> list[dict]:
    """``n`` loops of the family (see the module docstring); one dict per loop."""
    out = []
    for i in range(n):
        r = np.random.default_rng([seed, i])
        kind, valve, load, S, J = factorial_loop(r, i, KINDS, VALVE_KINDS, LOAD_KINDS, HEALTHY_S)
        scans = SCANS[kind]
        row = dict(kind=kind, valve=valve, load=load, S=S, J=J, scan=scans[int(r.integers(2))],
                   tau_p=r.uniform(0.2, 1.2), tau_a=r.uniform(0.1, 0.5), x0=r.uniform(0.35, 0.65),
                   wn=r.uniform(10.0, 30.0), zeta=r.uniform(0.3, 0.8), lam=r.uniform(0.02, 0.15),
                   x_w=r.uniform(-0.02, 0.02), b_w=r.uniform(0.02, 0.06), w_w=r.uniform(0.5, 1.5),
                   g=r.uniform(0.3, 0.8), vs=r.uniform(0.0005, 0.002), noise=r.uniform(*NOISE[kind]),
                   t_noise=r.uniform(1.0, 5.0) if r.uniform() < 0.5 else 0.0,
                   p_spike=r.uniform(0.002, 0.01), seed=int(r.integers(1 << 30)))
        _plant_row(r, row, kind)
        if kind == "tray":
            row["t_noise"] = 0.0                             # white, with outliers
        elif kind == "header":
            row["t_noise"] = row["Tm"]                       # the transmitter's damping filters its noise
        _loads(r, row, load)
        out.append(row)
    return out


@njit(cache=False)
def _char(x, R):
    """Inherent characteristic: linear (``R = 0``), or equal-percentage ``R^(x - 1)``."""
    return R ** (x - 1.0) if R > 0.0 else x


@njit(cache=False)
def wear_factor(x, par):
    """The wear band's friction factor at stem ``x``: 1 at the operating point, ``(1 + w)`` times the band's
    floor far from its centre."""
    return (1.0 + par[P_WW] * (1.0 - math.exp(-((x - par[P_XW]) / par[P_BW]) ** 2))) * par[P_MN]


@njit(cache=False)
def drying_factor(t, g):
    """The drying packing's friction factor ``t`` seconds into the record: ``1 + g (t / HOUR - 1/2)``."""
    return max(1.0 + g * (t / HOUR - 0.5), 0.05)


@njit(cache=False)
def _valve_fric(par, st, u, a_pf, a_af, nf):
    """``nf`` stem steps of ``DT_STEM`` of a sticky valve (one loop, in place)."""
    valve = int(par[P_VALVE])
    fs0, fc0, lam, vs = par[P_FS], par[P_FC], par[P_LAM], par[P_VS]
    wn2, c = par[P_WN] ** 2, par[P_C]
    p, pa, x, v, F, mode, t = st[X_P], st[X_A], st[X_X], st[X_V], st[X_F], st[X_M], st[X_T]
    dt = DT_STEM
    den = 1.0 + dt * wn2 * c + dt * dt * wn2
    for _ in range(nf):
        p = u + (p - u) * a_pf
        pa = p + (pa - p) * a_af
        t += dt
        if valve == 1:
            m = wear_factor(x, par)
        elif valve == 2:
            m = drying_factor(t, par[P_GR])
        else:
            m = 1.0
        fs, fc = fs0 * m, fc0 * m
        if mode == 0.0:
            if abs(pa - x) <= fs:
                continue                         # a hard stop: the friction takes the applied force
            mode = 1.0 if pa > x else -1.0
            F = mode * fs                        # the friction at breakaway
        if valve == 0:
            ff = F
        elif valve == 2:
            ff = mode * (fc + (fs - fc) * math.exp(-abs(v) / vs))
        else:
            ff = mode * fc
        vn = (v + dt * wn2 * (pa - x - ff)) / den
        if vn * mode <= 0.0:
            mode, v = 0.0, 0.0                   # the stem stops: it sticks
            continue
        dx = dt * vn
        if valve == 0:                           # Dahl: the friction relaxes to F_c along the path
            F = mode * fc + (F - mode * fc) * math.exp(-abs(dx) / lam)
        v = vn
        x += dx
        if x <= 0.0 or x >= 1.0:
            x, v, mode = min(max(x, 0.0), 1.0), 0.0, 0.0
    st[X_P], st[X_A], st[X_X], st[X_V], st[X_F], st[X_M], st[X_T] = p, pa, x, v, F, mode, t


@njit(cache=False)
def _valve(pr, s, u, a_p, a_a, a_pf, a_af, nf):
    """One plant sub-step of ``H_PLANT`` of one loop's valve."""
    if pr[P_VALVE] >= 0.0:
        _valve_fric(pr, s, u, a_pf, a_af, nf)
    else:
        s[X_P] = u + (s[X_P] - u) * a_p
        s[X_A] = s[X_P] + (s[X_A] - s[X_P]) * a_a
        s[X_X] = min(max(s[X_A], 0.0), 1.0)


@njit(cache=False)
def choke(r):
    """The let-down valve's flow factor at pressure ratio ``r``: 1 while choked, falling to 0 at ``r = 1``."""
    if r <= R_CRIT:
        return 1.0
    z = min((r - R_CRIT) / (1.0 - R_CRIT), 1.0)
    return math.sqrt(1.0 - z * z)


@njit(cache=False)
def _sqrt_s(z):
    """``sgn(z) sqrt(|z|)``, linear within 1e-4 of zero."""
    az = abs(z)
    if az < 1e-4:
        return z / 1e-2
    return math.copysign(math.sqrt(az), z)


@njit(cache=False)
def _plant(pr, s, x, d, buf, i, jj, dl):
    """One sub-step of ``H_PLANT`` of one loop's plant with stem ``x`` and load ``d``."""
    h = H_PLANT
    kind = int(pr[P_KIND])
    nb = buf.shape[1]
    if kind == 0:                # cstr: Y2 = c, Y3 = T, Y4 = T_j; see _plant_par for the columns
        c, T, Tj = s[X_Y2], s[X_Y3], s[X_Y4]
        k = pr[P_E] * math.exp(-pr[P_F] * (1.0 / T - 1.0 / pr[P_G]))
        qc = max(1.0 - x - d, 0.0)
        s[X_Y2] = c + h * ((1.0 - c) * pr[P_I] - k * c)
        s[X_Y3] = T + h * ((pr[P_H] - T) * pr[P_I] + pr[P_D] * k * c - pr[P_A] * (T - Tj))
        s[X_Y4] = Tj + h * (pr[P_C2] * qc * (pr[P_K] - Tj) + pr[P_B] * (T - Tj))
        y = pr[P_M] + (s[X_Y3] - pr[P_G]) / CSTR_SPAN
        s[X_Y1] = y + (s[X_Y1] - y) * pr[P_L]
    elif kind == 1:              # tray: Y2 = V_r, Y3 = w1, Y4 = w2, Y5 = V_h
        V = _char(x, pr[P_CHAR]) + d
        s[X_Y2] = V + (s[X_Y2] - V) * pr[P_A]
        buf[i, jj % nb] = s[X_Y2]
        vd = buf[i, (jj - dl) % nb]
        s[X_Y3] = vd + (s[X_Y3] - vd) * pr[P_B]
        s[X_Y4] = s[X_Y3] + (s[X_Y4] - s[X_Y3]) * pr[P_C2]
        s[X_Y5] = s[X_Y2] + (s[X_Y5] - s[X_Y2]) * pr[P_D]
        f0, ws, off = pr[P_F0], pr[P_G], pr[P_H]
        z = (s[X_Y4] - f0) / f0
        y = pr[P_M] + pr[P_E] * (math.tanh(z / ws + off) - math.tanh(off)) - pr[P_F] * (s[X_Y2] - s[X_Y5]) / f0
        s[X_Y1] = y + (s[X_Y1] - y) * pr[P_L]
    elif kind == 2:              # header: Y2 = P
        P = s[X_Y2]
        qin = pr[P_A] * (x + d) * choke(P)
        qout = pr[P_B] * P + pr[P_C2] * math.sqrt(max(P - pr[P_D], 0.0))
        s[X_Y2] = min(max(P + h * (qin - qout) / pr[P_E], 0.0), 1.0)
        s[X_Y1] = s[X_Y2] + (s[X_Y1] - s[X_Y2]) * pr[P_L]
    else:                        # twotank: Y1 = L1, Y2 = L2
        L1, L2 = s[X_Y1], s[X_Y2]
        q12 = pr[P_C2] * _sqrt_s(L1 - L2)
        s[X_Y1] = max(L1 + h * ((x + d) * pr[P_E] - q12) / pr[P_A], 0.0)
        s[X_Y2] = max(L2 + h * (q12 - pr[P_D] * math.sqrt(max(L2, 0.0))) / pr[P_B], 0.0)


@njit(cache=False)
def _advance(par, st, buf, delay, j0, op, load, m, a_p, a_a, a_pf, a_af, nf):
    """``m`` plant sub-steps of ``H_PLANT`` of every loop with inputs ``op`` (n,) and ``load`` (n,) held."""
    for i in range(par.shape[0]):
        pr, s = par[i], st[i]
        u = min(max(op[i], 0.0), 1.0)
        for k in range(m):
            _valve(pr, s, u, a_p[i], a_a[i], a_pf[i], a_af[i], nf[i])
            _plant(pr, s, s[X_X], load[i], buf, i, j0 + k, delay[i])


def cstr_design(r: dict) -> dict:
    """The reactor's coefficients from its drawn settings (see the module docstring)."""
    T0, th, X0, tau_r, phi, beta, tau_j = r["T0"], r["theta"], r["X0"], r["tau_r"], r["phi"], r["beta"], r["tau_j"]
    eps = r["ER"] / T0 ** 2
    alpha = (1.0 / tau_r - 1.0 / th) / (1.0 - beta)
    g0 = phi / (tau_r * eps)                     # heat released at the operating point [K/s]
    dT_f = r["psi_f"] * g0 * th                  # the cold feed takes psi_f of it
    dT_j = (g0 - dT_f / th) / alpha              # the jacket the rest
    Tj0 = T0 - dT_j
    return dict(alpha=alpha, alpha_j=beta / ((1.0 - beta) * tau_j), dT_ad=g0 * th / X0, k0=X0 / ((1.0 - X0) * th),
                T_f=T0 - dT_f, Tj0=Tj0, T_ci=Tj0 - dT_j * beta / (1.0 - beta), c0=1.0 - X0)


def _plant_par(pr: np.ndarray, r: dict, f0: float, x0: float) -> tuple[tuple, float, int]:
    """Fill one loop's plant columns; ``((Y1, .., Y5) at rest, delay line at rest, dead time in sub-steps)``."""
    h = H_PLANT
    kind = r["kind"]
    if kind == "cstr":
        c = cstr_design(r)
        pr[P_A], pr[P_B], pr[P_C2], pr[P_D] = c["alpha"], c["alpha_j"], 1.0 / (r["tau_j"] * (1.0 - x0)), c["dT_ad"]
        pr[P_E], pr[P_F], pr[P_G], pr[P_H], pr[P_I] = c["k0"], r["ER"], r["T0"], c["T_f"], 1.0 / r["theta"]
        pr[P_K], pr[P_L], pr[P_M] = c["T_ci"], math.exp(-h / r["Tm"]), r["pv0"]
        return (r["pv0"], c["c0"], r["T0"], c["Tj0"], 0.0), 0.0, 0
    if kind == "tray":
        lnR = math.log(r["R"])
        sech2 = 1.0 / math.cosh(r["off"]) ** 2
        pr[P_A], pr[P_B], pr[P_C2] = math.exp(-h / r["T_r"]), math.exp(-h / r["T1"]), math.exp(-h / r["T2"])
        pr[P_D], pr[P_E] = math.exp(-h / r["T_h"]), r["K"] * r["w_s"] / (sech2 * lnR)
        pr[P_F], pr[P_G], pr[P_H] = r["kappa"] * r["K"] / lnR, r["w_s"], r["off"]
        pr[P_L], pr[P_M] = math.exp(-h / r["Tm"]), r["pv0"]
        return (r["pv0"], f0, f0, f0, f0), f0, max(1, int(round(r["delay"] / h)))
    if kind == "header":
        P0, st_, pb = r["P0"], r["s_t"], r["P_b"]
        cv = 1.0 / (x0 * choke(P0))
        kt, ku = st_ / P0, (1.0 - st_) / math.sqrt(P0 - pb)
        z = (P0 - R_CRIT) / (1.0 - R_CRIT)
        slope_in = cv * x0 * z / ((1.0 - R_CRIT) * choke(P0)) if P0 > R_CRIT else 0.0
        slope = kt + 0.5 * ku / math.sqrt(P0 - pb) + slope_in
        pr[P_A], pr[P_B], pr[P_C2], pr[P_D], pr[P_E] = cv, kt, ku, pb, r["tau_h"] * slope
        pr[P_L] = math.exp(-h / r["Tm"])
        return (P0, P0, 0.0, 0.0, 0.0), 0.0, 0
    L2, dL = r["L2"], r["dL"]
    pr[P_A], pr[P_B] = r["tau1"] / (2.0 * dL), r["tau2"] / (2.0 * L2)
    pr[P_C2], pr[P_D], pr[P_E] = 1.0 / math.sqrt(dL), 1.0 / math.sqrt(L2), 1.0 / x0
    return (L2 + dL, L2, 0.0, 0.0, 0.0), 0.0, 0


class SixthLoops:
    """Batched simulation of the family's loops of one scan time (the harness's simulator interface).

    Parameters
    ----------
    rows : list of dict, from :func:`draw`
    scan : float, s
    frictionless : bool
        Every stem follows its positioner through the air lag (no friction): the reference.
    """

    def __init__(self, rows: list[dict], scan: float, frictionless: bool):
        self.rows, self.scan, self.n = rows, float(scan), len(rows)
        self.m = max(1, int(round(self.scan / H_PLANT)))
        n = self.n
        par = np.zeros((n, N_PAR))
        delay = np.zeros(n, np.int64)
        self.x0 = np.array([r["x0"] for r in rows], float)
        self.y_init, self.b0 = np.zeros((n, 5)), np.zeros(n)
        h = H_PLANT
        for i, r in enumerate(rows):
            pr = par[i]
            pr[P_KIND] = KINDS.index(r["kind"])
            pr[P_VALVE] = -1 if frictionless else VALVE_KINDS.index(r["valve"])
            S, J = float(r["S"]), float(r["J"])
            pr[P_FS], pr[P_FC] = (S + J) / 2.0, (S - J) / 2.0
            pr[P_WN], pr[P_C], pr[P_LAM], pr[P_VS] = r["wn"], 2.0 * r["zeta"] / r["wn"], r["lam"] * S, r["vs"]
            pr[P_XW], pr[P_BW], pr[P_WW], pr[P_MN] = r["x0"] + r["x_w"], r["b_w"], r["w_w"], 1.0
            pr[P_MN] = 1.0 / wear_factor(r["x0"], pr)
            pr[P_GR] = r["g"]
            pr[P_CHAR] = r["R"] if r["kind"] == "tray" else 0.0
            pr[P_F0] = f0 = float(_char(r["x0"], pr[P_CHAR]))
            self.y_init[i], self.b0[i], delay[i] = _plant_par(pr, r, f0, r["x0"])
        self.par, self.delay = par, delay
        tau_p = np.array([r["tau_p"] for r in rows], float)
        tau_a = np.array([r["tau_a"] for r in rows], float)
        self.a_p, self.a_a = np.exp(-h / tau_p), np.exp(-h / tau_a)
        self.nf = np.full(n, int(round(h / DT_STEM)), np.int64)
        self.a_pf, self.a_af = np.exp(-DT_STEM / tau_p), np.exp(-DT_STEM / tau_a)
        self.nb = int(delay.max()) + 2
        valve = par[:, P_VALVE]
        #: controller output above the stem at rest after an upward move: F_c (the drying valve's at t = 0)
        self.lead = np.where(valve == 2, par[:, P_FC] * (1.0 - 0.5 * par[:, P_GR]),
                             np.where(valve >= 0, par[:, P_FC], 0.0))
        self.res = np.array([CSTR_RES_K / CSTR_SPAN if r["kind"] == "cstr" else r["span"] / LEVELS for r in rows])

    def reset(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rest at the operating point: ``(pv (n,), stem (n,), op (n,))``."""
        st = np.zeros((self.n, N_ST))
        par = self.par
        st[:, X_X] = self.x0
        st[:, X_P] = st[:, X_A] = self.x0 + self.lead
        st[:, X_F] = par[:, P_FC]
        st[:, X_Y1:X_Y5 + 1] = self.y_init
        self.st = st
        self.buf = np.repeat(self.b0[:, None], self.nb, axis=1)
        self.j = 0
        return st[:, X_Y1].copy(), st[:, X_X].copy(), self.x0 + self.lead

    def step(self, op, load) -> tuple[np.ndarray, np.ndarray]:
        """One scan with input ``op`` (n,) and load ``load`` (n,) held: ``(pv, stem)`` after it."""
        _advance(self.par, self.st, self.buf, self.delay, self.j, np.asarray(op, float), np.asarray(load, float),
                 self.m, self.a_p, self.a_a, self.a_pf, self.a_af, self.nf)
        self.j += self.m
        return self.st[:, X_Y1].copy(), self.st[:, X_X].copy()

    @staticmethod
    def disturbances(rows: list[dict], scan: float, T: int, duration: float) -> tuple[np.ndarray, np.ndarray]:
        """``(noise (T, n), load (T, n))``: the measurement noise and the loop's load (see the module docstring)."""

        noise, load = np.empty((T, len(rows))), np.empty((T, len(rows)))
        t = np.arange(T) * scan


        for i, r in enumerate(rows):
            g = np.random.default_rng(r["seed"])
            w = g.standard_normal(T)
            # drawn for every loop (a fixed order of draws), used on the tray's thermocouple only
            spikes = (g.uniform(size=T) < r["p_spike"]) * g.uniform(4.0, 10.0, T) * np.sign(g.standard_normal(T))
            if r["t_noise"] > 0.0:
                w = ar1(w, r["t_noise"], scan)
            if r["kind"] == "tray":                  # the thermocouple's occasional outliers
                w = w + spikes
            noise[:, i] = r["noise"] * w
            ou = r["ou"] * ar1(g.standard_normal(T), r["t_ou"], scan, stationary=False)
            walk = np.cumsum(g.standard_normal(T)) * r["walk"] * math.sqrt(scan)
            ph = t / r["tri_period"]
            tri = r["tri"] * (1.0 - 4.0 * np.abs(ph + 0.25 - np.floor(ph + 0.75)))
            flips = np.cumsum(g.uniform(size=T) < scan / r["tel_dwell"]) % 2
            load[:, i] = ou + walk + r["drift"] * t / duration + tri + r["tel"] * flips
        return noise, load

    def measure(self, pv: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """The transmitter's reading of ``pv + noise``, quantised."""
        return np.round((pv + noise) / self.res) * self.res


def main(argv=None) -> int:
    groups = [("kind", k) for k in KINDS] + [("valve", v) for v in VALVE_KINDS] + [("load", lk) for lk in LOAD_KINDS]
    return family_main(__doc__, SixthLoops, draw, 48, 6161, argv, healthy_s=HEALTHY_S, test_s=TEST_S,
                       diag_kind=DIAG_KIND, groups=groups)


if __name__ == "__main__":
    raise SystemExit(main())
