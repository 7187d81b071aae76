"""A fifth held-out check of the stiction compensators: plants, valves, loads and noise coded here alone.

Like the second, third and fourth held-out families (``benchmarks/learned_unseen_check.py``, whose harness this
script uses: SIMC tuning from a step test of the frictionless loop, one ``load_controller`` block per scan group,
the benchmark's scores; ``benchmarks/learned_third_check.py``, ``benchmarks/learned_fourth_check.py``), nothing
here was used while the compensators were designed, trained or tuned, and every choice below was fixed before any
compensator was run on it. Nothing physical is imported from valve_gym. Every loop starts at rest at its set
point, its stem stuck just after an upward move (the controller's output a valve's rest offset above the stem,
see below), as a running loop leaves it; the set point is held; ``pv`` is in the units named below. A load ``d``
acts on every plant as extra valve flow would (``d > 0`` raises ``pv``).

Plants (``kind``; ``f(x)`` the valve's inherent characteristic: equal-percentage ``R^(x - 1)`` (``R`` 20-50) on
the kiln's fuel, linear elsewhere)
    ``drum``: water level ``L`` [m] of a boiler drum fed through the valve, integrating with shrink and swell:
    ``L = L_0 + m + w_v + w_d``, ``m' = (f(x) + d - f_0) / T_f`` (``T_f`` 100-300 s: the time a full-flow
    imbalance takes to raise the level 1 m), ``w_v`` following ``-(t_s / T_f) (f(x) - f_0)`` and ``w_d``
    following ``-(t_d / T_f) d`` through the bubbles' lag ``T_w`` (5-15 s; ``t_s`` 30-60 s, ``t_d`` 60-120 s):
    more cold feedwater, or less steam drawn (``d > 0``), first collapses steam bubbles and lowers the level,
    which recovers after about ``t_s`` (``t_d``) and then rises. ``L_0`` 0.3-0.5 m on a 0.8-m transmitter span,
    read through a damping lag of 0.5-2 s.
    ``weir``: level ``L`` [m] of a vertical tank drained over a rectangular notch whose sill is ``h_w`` (0.5-1.5
    m) above the bottom, outflow ``c (L - h_w)^1.5`` (none below the sill), inflow ``f(x) + d`` through a
    launder with a dead time of 5-20 s; head over the sill 0.4-0.8 m and time constant ``2 A h / (3 q)`` 40-150
    s at the operating point; the gain ``2 h / (3 q)`` (0.45-1.4 m per stroke) falls slowly as the flow rises.
    ``kiln``: a fired kiln (continuous dryer): gas temperature ``u`` (1000 K), ``C u' = 1 + (phi / f_0) (f(x) +
    d - f_0) - a (u - u_a) - b (u^4 - u_a^4)`` (heat in units of the loss at the operating point ``u_0`` 1.1-1.3,
    ``u_a`` 0.3; the valve trims ``phi`` 0.2-0.4 of the heat; radiation ``rho`` 0.3-0.7 of the loss there;
    ``C`` puts the gas lag at 5-20 s), so the loss grows faster than the temperature and the gain falls as the
    kiln gets hotter; the solids follow the gas through a slow lag of 40-120 s and reach the discharge pyrometer
    after a transport delay of 10-40 s (pyrometer lag 2-6 s). ``pv = pv_0 + (T - T_0) / 500 K``, ``pv_0``
    0.4-0.6; gain 0.6-1.8 per stroke.
    ``basis``: basis weight of a paper machine, the valve on the thick stock: headbox solids ``s_h`` mix in the
    fan pump (lag 2-6 s) from the thick stock ``f(x) + d`` and the white water ``(1 - r) w``, ``w`` following
    ``s_h`` through the wire pit (lag ``T_w`` 40-120 s), first-pass retention ``r`` 0.5-0.85; the web carries
    ``r s_h``, so a step jumps to ``r`` of its final value and creeps the rest with time constant ``T_w / r``;
    it reaches the reel scanner after 10-30 s; the scanner averages a traverse (a lag of half a traverse) and
    its reading is held for the next traverse (10-25 s, a whole number of scans). ``pv = pv_0 f_web / f_0``,
    ``pv_0`` 0.4-0.7 (gain 0.6-1.9 per stroke).
Valves (a first-order positioner, ``tau_p`` 0.2-1.5 s, output ``p`` in fractions of stroke, then a spring-
diaphragm actuator: an air-volume lag ``tau_a`` 0.1-0.6 s to the pressure ``P_a`` in stroke units, and a
second-order stem ``x'' = wn^2 (P_a - x - F_f) - 2 zeta wn x'``, ``wn`` 8-25 rad/s, ``zeta`` 0.4-0.9, friction
``F_f`` over the spring rate, integrated semi-implicitly in 1-ms steps)
    The stiction size ``S`` (reversal band: the input change that reverses a stem at rest) and slip ``J`` are
    fractions of stroke; healthy valves have ``S < 0.004``, sticky ones 0.005-0.10 (log-uniform), ``J``
    uniform in ``[0, S]``. Every model takes ``F_s = (S + J) / 2`` and ``F_c = (S - J) / 2``.

    ``elastoplastic``: the single-state elasto-plastic model of Dupont, Hayward, Armstrong & Altpeter (2002):
    ``z' = x' (1 - alpha(z, x') z / z_ss(x'))``, ``F_f = sigma_0 z + sigma_1 z'``, ``z_ss(v) = F_ss(v) /
    sigma_0``, ``F_ss(v) = F_c + (F_s - F_c) exp(-|v| / v_s)`` (``v_s`` 0.0002-0.001 stroke/s); ``alpha = 0``
    (purely elastic: no creep) while ``|z| <= z_ba`` or ``z`` opposes the motion, 1 from ``z_ss(v)`` on, a half
    sine between; ``z_ba = beta F_c / sigma_0`` (``beta`` 0.5-0.9, below every steady deflection);
    ``sigma_0 = F_s / (delta S)`` (presliding ``delta`` 1-3 % of ``S`` at the static level), critically damped
    bristles ``sigma_1 = 2 sqrt(sigma_0) / wn``. At rest after an upward move ``sigma_0 z = F_c``: a reversal
    goes back elastically through zero and breaks away at ``-F_s``, an input move of ``F_c + F_s = S`` (plus
    ``delta S``); the friction then falls to ``F_c`` and the stem slips by about ``F_s - F_c = J`` (0.7-1 ``J``:
    the friction recovers as the stem slows); a further upward move creeps plastically until the friction has
    risen the ``J`` to ``F_s``.

    ``positioner``: a smart positioner with integral action in front of a stick-slip stem (positioner
    hunting). The stem sticks while ``|P_a - x| <= F_s`` and slides against Coulomb friction ``F_c`` until its
    velocity reverses (a reversal from rest needs ``S``; a breakaway slips ``J`` to 1.25 ``J`` with the
    underdamped stem). The positioner drives ``u + I``, ``I' = dz(u - x, delta_p) / T_i`` (a dead zone of
    ``delta_p`` 2-8 % of ``S``, ``T_i`` 30-120 s, ``|I| <= 0.2``): a quick input move needs ``S``, but a held
    error over ``delta_p`` breaks the stem loose within about ``T_i`` (so slow input moves need less), and a slip
    of more than about ``2 delta_p`` lands beyond the dead zone on the other side, so the stem hunts around a
    steady input (amplitude about ``J``, period of the order of ``4 T_i S / J``); with ``J`` under it the stem
    settles within ``delta_p``.

    ``armstrong``: the seven-parameter model of Armstrong-Helouvry, Dupont & Canudas de Wit (1994). Stuck,
    the friction is a presliding spring to an anchor, ``F_f = sigma_0 (x - x_a)`` (``sigma_0`` as above,
    critically damped), until ``|F_f|`` exceeds ``F_C + F_S(gamma, t_2)``, ``F_S(gamma, t_2) = F_S,a + (J -
    F_S,a) t_2 / (t_2 + gamma)`` (rising static friction: ``t_2`` the dwell, ``gamma`` 1-10 s, ``F_S,a`` 0.2-0.5
    ``J``); sliding, ``F_f = sgn(x') (F_C + F_S / (1 + (v_L / v_s)^2))`` with ``F_S`` the level of that
    breakaway and ``v_L`` the velocity through a lag ``tau_L`` of 3-20 ms (frictional memory); ``F_V`` is the
    stem's damping; the stem re-sticks when its velocity reverses (the spring takes the applied force, up to
    ``F_C + F_S,a``). ``F_C = F_c``: after a dwell long against ``gamma`` (every dwell under the PI) a reversal
    from rest needs ``F_c + F_c + J = S`` and slips about ``J`` (0.8-1.2 ``J``); after a dwell ``t_2`` both are
    ``(J - F_S,a) gamma / (t_2 + gamma)`` less.

    Rest offsets (controller output above the stem): ``F_c`` for ``elastoplastic`` (``sigma_0 z = F_c``) and
    ``armstrong`` (``t_2 = 0``), ``delta_p / 2`` for ``positioner`` (``I = F_c - delta_p / 2``). The
    frictionless valves keep the positioner's lag and the air lag (no friction, no positioner integral).
Loads ``d`` (fraction of the valve's full flow; for the drum a fall in steam draw, with its own swell)
    small (24 of 48 loops): ``ou``: Ornstein-Uhlenbeck, std 0.002-0.005, time constant 120-900 s; ``drift``:
    a ramp of +-0.002-0.005 over the record plus a random walk of 2e-5-4e-5 per sqrt(s);
    medium: ``square``: a square wave between 0 and +-0.5-1.5 % (period 400-1500 s, random phase) on a small OU
    (std 0.001, 300 s); ``bursts``: 3-6 bursts of 60-240 s at random times in 5-90 % of the record, each an OU of
    std 0.3-0.8 % (time constant 60-180 s), on a ramp of +-0.5-1.5 % over the record.
Measurement
    ``drum``: AR(1) noise (the boiling surface; correlation time 0.5-3 s), std 1-3 mm; ``weir``: white (half the
    loops) or AR(1) noise (1-8 s), 0.5-1 mm, read by a slew-limited gauge (the reading moves at most 1-3 mm/s);
    ``kiln``: white or AR(1) noise, 0.5-2 pv x1000 (0.25-1 K), the pyrometer's reading quantised to 0.5 K (0.001);
    ``basis``: 0.5-1.5 pv x1000, one draw per traverse, held with the scanner's reading. Drum, weir and basis
    weight: a 14-bit transmitter (``span / 16384``; span 0.8 m, ``h_w`` + 1 m, 1).
Design (fixed before any compensator ran)
    4 plants x 3 valves x 4 loads, a full factorial (loop ``i``: plant ``i % 4``, valve ``(i // 4 + i // 12)
    % 3``, load ``(i // 12) % 4``), every third loop healthy; scans 0.5 or 1 s for the drum, 1 or 2 s for the
    others; tuning step test 600 s; 48 loops of one hour, seed 5151.

Usage::

    python benchmarks/learned_fifth_check.py [--n 48] [--seed 5151] [--names pi knocker learned learned_network]
        [--policy LABEL=FILE ...]

Besides the second script's table it prints, for each row, the LC share and the median compensation ratio
``R`` on the sticky loops by plant, by valve and by load.

Under the PI alone (``--names pi``, the only controller run while the family was written), 21 of the 32 sticky
loops stick-slip (at least two slips an hour, a slip being a stem move of more than ``J / 2`` and 0.2 % of
stroke within one scan; median 4 per hour: 2.5 with a small load, 5 with a medium one; 9 of the 16 sticky loops
with a small load). Of the other 11, 8 have ``J`` under 0.4 % (their slips fall under the 0.2-% floor: the stem
moves as through a dead band, or not at all) and 3 are bands of 3-6.5 % with large slips that a small load
does not push through within the hour (the stem stays stuck). The PI's stem travels 0.10 of the frictionless
PI's (median; 0.01-3.2, more than the frictionless PI's where the positioner hunts) and its IAE is 1.89 times
the frictionless one's (median over the 32 sticky loops; IAE ratio 1.01-12.1): 2.1 on the drum, 2.0 on the weir,
1.6 on the kiln, 2.2 on the basis-weight loop; 3.2 with the elasto-plastic valves, 1.9 with the positioner, 1.6
with the Armstrong valves; 1.7 under an OU load, 1.8 under a drift, 2.3 under the square wave, 1.9 under bursts.
On 3 of the 32 stiction costs the PI less than 10 % of the frictionless IAE (a 0.6 % band behind the positioner
on the weir, where the stem hunts some 160 times an hour, too fast to pass the tank; a 0.8 % band behind the
positioner on the drum, whose integral follows the PI's slow moves, under bursts that dominate the IAE; a 0.8 %
band with ``J = 0.07 S`` on the basis-weight loop under a drift: 1.099), so the frictionless PI's own ``R`` is
under 1 there (the floor of ``R``). The benchmark's limit-cycle rule calls 1 of the 32 under the PI (the weir's
positioner under bursts, period 350 s) and 1 under the frictionless PI (a kiln under the square wave): the PI's
slips here are few and irregular, jittered by the noise and the loads, and the largest bands stay stuck; on this
family ``R`` and the travel say more than the LC share.
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

KINDS = ("drum", "weir", "kiln", "basis")
VALVE_KINDS = ("elastoplastic", "positioner", "armstrong")
#: The process kind an engineer would give the diagnosis for each plant (``--diagnosed``).
DIAG_KIND = {"drum": "integrating", "weir": "tank", "kiln": "first_order", "basis": "first_order"}
LOAD_KINDS = ("ou", "drift", "square", "bursts")
#: Scan times [s] of each plant (one drawn per loop).
SCANS = {"drum": (0.5, 1.0), "weir": (1.0, 2.0), "kiln": (1.0, 2.0), "basis": (1.0, 2.0)}
#: Measurement noise std of each plant [pv units] (drawn uniformly).
NOISE = {"drum": (0.001, 0.003), "weir": (0.0005, 0.001), "kiln": (0.0005, 0.002), "basis": (0.0005, 0.0015)}
#: Plant sub-step [s]; stem step [s].
H_PLANT, DT_STEM = 0.05, 1e-3
#: Length of the tuning step test [s] (the kiln settles within it).
TEST_S = 600.0
#: Healthy valves: S below this (fraction of stroke).
HEALTHY_S = 0.004
#: Transmitter resolution ``span / LEVELS`` (drum, weir, basis weight); the kiln's pyrometer reads in 0.5-K steps.
LEVELS, KILN_RES = 16384, 0.001
#: The positioner's integral authority (fraction of stroke).
I_MAX = 0.2
#: Ambient / feed temperature of the kiln (1000 K units).
U_AMB = 0.3

# parameter columns of the kernel
(P_KIND, P_VALVE, P_FS, P_FC, P_J, P_WN, P_C, P_VS, P_SIG, P_SIG1, P_BETA, P_DB, P_TI, P_FSA, P_GAM, P_EL, P_CE,
 P_CHAR, P_F0, P_A, P_B, P_C2, P_D, P_E, P_F, P_G, P_H, P_NTR, N_PAR) = range(29)
# state columns of the kernel
(X_P, X_A, X_X, X_V, X_Z, X_M, X_T, X_VL, X_W, X_Y1, X_Y2, X_Y3, X_Y4, N_ST) = range(14)


def _loads(r, row: dict, load: str) -> None:
    """The load's settings (see the module docstring), drawn in a fixed order whatever the load kind."""
    ou, t_ou = r.uniform(0.002, 0.005), r.uniform(120.0, 900.0)
    drift, walk = r.uniform(0.002, 0.005) * float(r.choice([-1.0, 1.0])), r.uniform(2e-5, 4e-5)
    sq, sq_period = r.uniform(0.005, 0.015) * float(r.choice([-1.0, 1.0])), r.uniform(400.0, 1500.0)
    sq_off = r.uniform()
    n_b = int(r.integers(3, 7))
    b_start, b_len = np.sort(r.uniform(0.05, 0.9, n_b)), r.uniform(60.0, 240.0, n_b)
    b_std, b_tau, b_ramp = r.uniform(0.003, 0.008), r.uniform(60.0, 180.0), r.uniform(0.005, 0.015) * float(
        r.choice([-1.0, 1.0]))
    row.update(ou=0.0, t_ou=300.0, drift=0.0, walk=0.0, sq=0.0, sq_period=sq_period, sq_off=sq_off,
               b_start=[], b_len=[], b_std=0.0, b_tau=b_tau, b_ramp=0.0)
    if load == "ou":
        row.update(ou=ou, t_ou=t_ou)
    elif load == "drift":
        row.update(drift=drift, walk=walk)
    elif load == "square":
        row.update(ou=0.001, sq=sq)
    else:
        row.update(b_start=b_start.tolist(), b_len=b_len.tolist(), b_std=b_std, b_ramp=b_ramp)


def _plant_row(r, row: dict, kind: str) -> None:
    """The plant's settings (see the module docstring), drawn in a fixed order whatever the kind."""
    k = dict(
        drum=dict(T_f=r.uniform(100.0, 300.0), t_s=r.uniform(30.0, 60.0), t_d=r.uniform(60.0, 120.0),
                  T_w=r.uniform(5.0, 15.0), Tm=r.uniform(0.5, 2.0), level=r.uniform(0.3, 0.5), span=0.8),
        weir=dict(h0=r.uniform(0.4, 0.8), h_w=r.uniform(0.5, 1.5), T=r.uniform(40.0, 150.0),
                  delay=r.uniform(5.0, 20.0), slew=r.uniform(0.001, 0.003)),
        kiln=dict(u0=r.uniform(1.1, 1.3), rho=r.uniform(0.3, 0.7), phi=r.uniform(0.2, 0.4), R=r.uniform(20.0, 50.0),
                  T_g=r.uniform(5.0, 20.0), T_s=r.uniform(40.0, 120.0), delay=r.uniform(10.0, 40.0),
                  Tm=r.uniform(2.0, 6.0), pv0=r.uniform(0.4, 0.6), span=1.0),
        basis=dict(ret=r.uniform(0.5, 0.85), T_m=r.uniform(2.0, 6.0), T_w=r.uniform(40.0, 120.0),
                   delay=r.uniform(10.0, 30.0), traverse=r.uniform(10.0, 25.0), pv0=r.uniform(0.4, 0.7), span=1.0),
    )[kind]
    if kind == "weir":
        k["span"] = k["h_w"] + 1.0
    if kind == "basis":
        k["traverse"] = row["scan"] * max(1, round(k["traverse"] / row["scan"]))
    row.update(k)


def draw(n: int, seed: int) -> list[dict]:
    """``n`` loops of the family (see the module docstring); one dict per loop."""
    out = []
    for i in range(n):
        r = np.random.default_rng([seed, i])
        kind, valve, load, S, J = factorial_loop(r, i, KINDS, VALVE_KINDS, LOAD_KINDS, HEALTHY_S)
        scans = SCANS[kind]
        row = dict(kind=kind, valve=valve, load=load, S=S, J=J, scan=scans[int(r.integers(2))],
                   tau_p=r.uniform(0.2, 1.5), tau_a=r.uniform(0.1, 0.6), x0=r.uniform(0.35, 0.65),
                   wn=r.uniform(8.0, 25.0), zeta=r.uniform(0.4, 0.9), vs=r.uniform(0.0002, 0.001),
                   delta=r.uniform(0.01, 0.03), beta=r.uniform(0.5, 0.9), db=r.uniform(0.02, 0.08),
                   ti=r.uniform(30.0, 120.0), fsa=r.uniform(0.2, 0.5), gam=r.uniform(1.0, 10.0),
                   tau_l=r.uniform(0.003, 0.02), noise=r.uniform(*NOISE[kind]),
                   t_noise=r.uniform(1.0, 8.0) if r.uniform() < 0.5 else 0.0, seed=int(r.integers(1 << 30)))
        _plant_row(r, row, kind)
        if kind == "drum":
            row["t_noise"] = r.uniform(0.5, 3.0)             # the boiling surface: always coloured
        elif kind == "basis":
            row["t_noise"] = 0.0                             # one reading per traverse
        _loads(r, row, load)
        out.append(row)
    return out


@njit(cache=False)
def _char(x, R):
    """Inherent characteristic: linear (``R = 0``), or equal-percentage ``R^(x - 1)``."""
    return R ** (x - 1.0) if R > 0.0 else x


@njit(cache=False)
def ep_alpha(z, zba, zss):
    """Elasto-plastic ``alpha(z)`` for ``z`` in the direction of motion: 0 below ``z_ba``, 1 above ``z_ss(v)``."""
    az = abs(z)
    if az <= zba:
        return 0.0
    if az >= zss:
        return 1.0
    return 0.5 * math.sin(math.pi * (az - 0.5 * (zss + zba)) / (zss - zba)) + 0.5


@njit(cache=False)
def _valve_ep(par, st, u, a_pf, a_af, nf):
    """``nf`` stem steps of ``DT_STEM`` with elasto-plastic friction (one loop, in place)."""
    fs, fc, vs, s0, s1 = par[P_FS], par[P_FC], par[P_VS], par[P_SIG], par[P_SIG1]
    wn2, c = par[P_WN] ** 2, par[P_C]
    zba = par[P_BETA] * fc / s0                  # z_ba below every steady deflection z_ss(v) = F_ss(v) / sigma0
    p, pa, x, v, z = st[X_P], st[X_A], st[X_X], st[X_V], st[X_Z]
    dt = DT_STEM
    for _ in range(nf):
        p = u + (p - u) * a_pf
        pa = p + (pa - p) * a_af
        g, al, zss = 1.0, 0.0, 1.0               # dz/dx: 1 while elastic (alpha = 0), 0 in steady sliding
        if v * z > 0.0:
            zss = (fc + (fs - fc) * math.exp(-abs(v) / vs)) / s0
            al = ep_alpha(z, zba, zss)
            g = min(max(1.0 - al * abs(z) / zss, 0.0), 1.0)
        vn = (v + dt * wn2 * (pa - x - s0 * z)) / (1.0 + dt * wn2 * (c + s1 * g) + dt * dt * wn2 * (1.0 + s0 * g))
        dx = dt * vn
        if dx * z > 0.0 and al > 0.0:
            z = (z + dx) / (1.0 + al * abs(dx) / zss)
        else:
            z += dx
        v = vn
        x += dx
        if x <= 0.0 or x >= 1.0:
            x, v = min(max(x, 0.0), 1.0), 0.0
    st[X_P], st[X_A], st[X_X], st[X_V], st[X_Z] = p, pa, x, v, z


@njit(cache=False)
def _valve_pos(par, st, u, a_pf, a_af, nf):
    """``nf`` stem steps of ``DT_STEM``: integrating positioner with a dead band, stick-slip stem (in place)."""
    fs, fc, db, ti = par[P_FS], par[P_FC], par[P_DB], par[P_TI]
    wn2, c = par[P_WN] ** 2, par[P_C]
    p, pa, x, v, ii, mode = st[X_P], st[X_A], st[X_X], st[X_V], st[X_Z], st[X_M]
    dt = DT_STEM
    for _ in range(nf):
        e = u - x
        if e > db:
            ii = min(ii + dt * (e - db) / ti, I_MAX)
        elif e < -db:
            ii = max(ii + dt * (e + db) / ti, -I_MAX)
        tgt = u + ii
        p = tgt + (p - tgt) * a_pf
        pa = p + (pa - p) * a_af
        if mode == 0.0:
            if abs(pa - x) <= fs:
                continue
            mode = 1.0 if pa > x else -1.0
        vn = (v + dt * wn2 * (pa - x - mode * fc)) / (1.0 + dt * wn2 * c + dt * dt * wn2)
        if vn * mode <= 0.0:
            mode, v = 0.0, 0.0                   # the stem stops: it sticks
            continue
        v = vn
        x += dt * v
        if x <= 0.0 or x >= 1.0:
            x, v, mode = min(max(x, 0.0), 1.0), 0.0, 0.0
    st[X_P], st[X_A], st[X_X], st[X_V], st[X_Z], st[X_M] = p, pa, x, v, ii, mode


@njit(cache=False)
def arm_static(par, t2):
    """Armstrong's breakaway level after a dwell ``t2``: ``F_C + F_S,a + (F_S,inf - F_S,a) t2 / (t2 + gamma)``."""
    return par[P_FC] + par[P_FSA] + (par[P_J] - par[P_FSA]) * t2 / (t2 + par[P_GAM])


@njit(cache=False)
def _valve_arm(par, st, u, a_pf, a_af, nf):
    """``nf`` stem steps of ``DT_STEM`` with Armstrong's seven-parameter friction (one loop, in place)."""
    fc, vs, s0, el, ce = par[P_FC], par[P_VS], par[P_SIG], par[P_EL], par[P_CE]
    wn2, c = par[P_WN] ** 2, par[P_C]
    p, pa, x, v, xa, mode, t2, vl, fsb = st[X_P], st[X_A], st[X_X], st[X_V], st[X_Z], st[X_M], st[X_T], st[X_VL], \
        st[X_W]
    dt = DT_STEM
    for _ in range(nf):
        p = u + (p - u) * a_pf
        pa = p + (pa - p) * a_af
        vl = v + (vl - v) * el                   # frictional memory: the Stribeck term sees a lagged velocity
        if mode == 0.0:                          # presliding: a spring to the anchor xa, critically damped
            t2 += dt
            ff = s0 * (x - xa)
            brk = arm_static(par, t2)
            if abs(ff) <= brk:
                v = (v + dt * wn2 * (pa - x - ff)) / (1.0 + dt * (wn2 * c + ce) + dt * dt * wn2 * (1.0 + s0))
                x += dt * v
                continue
            mode = 1.0 if ff > 0.0 else -1.0     # breakaway: the Stribeck level of this slide
            fsb = brk - fc
            v = max(v * mode, 0.0) * mode
        ff = mode * (fc + fsb / (1.0 + (vl / vs) ** 2))
        vn = (v + dt * wn2 * (pa - x - ff)) / (1.0 + dt * wn2 * c + dt * dt * wn2)
        if vn * mode <= 0.0:                     # the stem stops: presliding, holding what it can of the force
            mode, v, t2 = 0.0, 0.0, 0.0
            lim = arm_static(par, 0.0)
            xa = x - min(max(pa - x, -lim), lim) / s0
            continue
        v = vn
        x += dt * v
        if x <= 0.0 or x >= 1.0:
            x, v, mode, t2 = min(max(x, 0.0), 1.0), 0.0, 0.0, 0.0
            xa = x
    st[X_P], st[X_A], st[X_X], st[X_V], st[X_Z], st[X_M], st[X_T], st[X_VL], st[X_W] = p, pa, x, v, xa, mode, t2, vl, \
        fsb


@njit(cache=False)
def _valve(pr, s, u, a_p, a_a, a_pf, a_af, nf):
    """One plant sub-step of ``H_PLANT`` of one loop's valve."""
    valve = int(pr[P_VALVE])
    if valve == 0:
        _valve_ep(pr, s, u, a_pf, a_af, nf)
    elif valve == 1:
        _valve_pos(pr, s, u, a_pf, a_af, nf)
    elif valve == 2:
        _valve_arm(pr, s, u, a_pf, a_af, nf)
    else:
        s[X_P] = u + (s[X_P] - u) * a_p
        s[X_A] = s[X_P] + (s[X_A] - s[X_P]) * a_a
        s[X_X] = min(max(s[X_A], 0.0), 1.0)


@njit(cache=False)
def kiln_loss(u, a, b):
    """The kiln's heat loss at gas temperature ``u`` (1000 K): convection plus radiation."""
    return a * (u - U_AMB) + b * (u ** 4 - U_AMB ** 4)


@njit(cache=False)
def _plant(pr, s, x, d, buf, i, jj, dl):
    """One sub-step of ``H_PLANT`` of one loop's plant with stem ``x`` and load ``d``."""
    h = H_PLANT
    kind = int(pr[P_KIND])
    f = _char(x, pr[P_CHAR])
    nb = buf.shape[1]
    if kind == 0:                # drum: A = k_i, B = k_i t_s, C2 = k_i t_d, D = exp(-h/T_w), E = exp(-h/Tm), G = L0
        s[X_Y2] += h * pr[P_A] * (f + d - pr[P_F0])
        tv, td = -pr[P_B] * (f - pr[P_F0]), -pr[P_C2] * d
        s[X_Y3] = tv + (s[X_Y3] - tv) * pr[P_D]
        s[X_Y4] = td + (s[X_Y4] - td) * pr[P_D]
        lv = pr[P_G] + s[X_Y2] + s[X_Y3] + s[X_Y4]
        s[X_Y1] = lv + (s[X_Y1] - lv) * pr[P_E]
    elif kind == 1:              # weir: A = area, B = c, C2 = sill height; inflow through the launder's dead time
        buf[i, jj % nb] = f + d
        q = buf[i, (jj - dl) % nb]
        L = s[X_Y1]
        s[X_Y1] = max(L + h * (q - pr[P_B] * max(L - pr[P_C2], 0.0) ** 1.5) / pr[P_A], 0.0)
    elif kind == 2:              # kiln: A = phi / f0, B = a, C2 = b, D = 1/C_g, E, F = exp(-h/T_s, Tm), G = u0, H = pv0
        u = s[X_Y2]
        heat = 1.0 + pr[P_A] * (f + d - pr[P_F0])
        s[X_Y2] = u + h * (heat - kiln_loss(u, pr[P_B], pr[P_C2])) * pr[P_D]
        s[X_Y3] = s[X_Y2] + (s[X_Y3] - s[X_Y2]) * pr[P_E]
        buf[i, jj % nb] = s[X_Y3]
        y = pr[P_H] + 2.0 * (buf[i, (jj - dl) % nb] - pr[P_G])
        s[X_Y1] = y + (s[X_Y1] - y) * pr[P_F]
    else:                        # basis: A = retention, B, C2, D = exp(-h/T_m, T_w, T_avg), E = pv0 / f0
        ret = pr[P_A]
        tgt = f + d + (1.0 - ret) * s[X_Y3]
        s[X_Y2] = tgt + (s[X_Y2] - tgt) * pr[P_B]
        s[X_Y3] = s[X_Y2] + (s[X_Y3] - s[X_Y2]) * pr[P_C2]
        buf[i, jj % nb] = ret * s[X_Y2]
        w = buf[i, (jj - dl) % nb]
        s[X_Y4] = w + (s[X_Y4] - w) * pr[P_D]
        if (jj + 1) % int(pr[P_NTR]) == 0:
            s[X_Y1] = pr[P_E] * s[X_Y4]            # the scanner's reading of the traverse just ended


@njit(cache=False)
def _advance(par, st, buf, delay, j0, op, load, m, a_p, a_a, a_pf, a_af, nf):
    """``m`` plant sub-steps of ``H_PLANT`` of every loop with inputs ``op`` (n,) and ``load`` (n,) held."""
    for i in range(par.shape[0]):
        pr, s = par[i], st[i]
        u = min(max(op[i], 0.0), 1.0)
        for k in range(m):
            _valve(pr, s, u, a_p[i], a_a[i], a_pf[i], a_af[i], nf[i])
            _plant(pr, s, s[X_X], load[i], buf, i, j0 + k, delay[i])


def _plant_par(pr: np.ndarray, r: dict, f0: float) -> tuple[tuple[float, float, float, float], float, int]:
    """Fill one loop's plant columns; ``((Y1, Y2, Y3, Y4) at rest, delay line at rest, dead time in sub-steps)``."""
    h = H_PLANT
    kind = r["kind"]
    if kind == "drum":
        ki = 1.0 / r["T_f"]
        pr[P_A], pr[P_B], pr[P_C2] = ki, ki * r["t_s"], ki * r["t_d"]
        pr[P_D], pr[P_E], pr[P_G] = math.exp(-h / r["T_w"]), math.exp(-h / r["Tm"]), r["level"]
        return (r["level"], 0.0, 0.0, 0.0), 0.0, 0
    dl = max(1, int(round(r["delay"] / h)))
    if kind == "weir":
        h0 = r["h0"]
        pr[P_A], pr[P_B], pr[P_C2] = 1.5 * f0 * r["T"] / h0, f0 / h0 ** 1.5, r["h_w"]
        return (r["h_w"] + h0, 0.0, 0.0, 0.0), f0, dl
    if kind == "kiln":
        u0, rho = r["u0"], r["rho"]
        a, b = (1.0 - rho) / (u0 - U_AMB), rho / (u0 ** 4 - U_AMB ** 4)
        pr[P_A], pr[P_B], pr[P_C2], pr[P_D] = r["phi"] / f0, a, b, 1.0 / (r["T_g"] * (a + 4.0 * b * u0 ** 3))
        pr[P_E], pr[P_F], pr[P_G], pr[P_H] = math.exp(-h / r["T_s"]), math.exp(-h / r["Tm"]), u0, r["pv0"]
        return (r["pv0"], u0, u0, 0.0), u0, dl
    ret = r["ret"]
    pr[P_A], pr[P_B], pr[P_C2] = ret, math.exp(-h / r["T_m"]), math.exp(-h / r["T_w"])
    pr[P_D], pr[P_E], pr[P_NTR] = math.exp(-2.0 * h / r["traverse"]), r["pv0"] / f0, round(r["traverse"] / h)
    return (r["pv0"], f0 / ret, f0 / ret, f0), f0, dl


class FifthLoops:
    """Batched simulation of the family's loops of one scan time (the harness's simulator interface).

    Parameters
    ----------
    rows : list of dict, from :func:`draw`
    scan : float, s
    frictionless : bool
        Every stem follows its positioner through the air lag (no friction, no positioner integral): the reference.
    """

    def __init__(self, rows: list[dict], scan: float, frictionless: bool):
        self.rows, self.scan, self.n = rows, float(scan), len(rows)
        self.m = max(1, int(round(self.scan / H_PLANT)))
        n = self.n
        par = np.zeros((n, N_PAR))
        delay = np.zeros(n, np.int64)
        self.x0 = np.array([r["x0"] for r in rows], float)
        self.y_init, self.b0 = np.zeros((n, 4)), np.zeros(n)
        h = H_PLANT
        for i, r in enumerate(rows):
            pr = par[i]
            pr[P_KIND] = KINDS.index(r["kind"])
            pr[P_VALVE] = -1 if frictionless else VALVE_KINDS.index(r["valve"])
            S, J = float(r["S"]), float(r["J"])
            pr[P_FS], pr[P_FC], pr[P_J] = (S + J) / 2.0, (S - J) / 2.0, J
            pr[P_WN], pr[P_C], pr[P_VS] = r["wn"], 2.0 * r["zeta"] / r["wn"], r["vs"]
            pr[P_SIG] = pr[P_FS] / (r["delta"] * S)          # presliding: delta S at the static level
            pr[P_SIG1], pr[P_CE] = 2.0 * math.sqrt(pr[P_SIG]) / r["wn"], 2.0 * r["wn"] * math.sqrt(pr[P_SIG])
            pr[P_BETA], pr[P_DB], pr[P_TI] = r["beta"], r["db"] * S, r["ti"]
            pr[P_FSA], pr[P_GAM], pr[P_EL] = r["fsa"] * J, r["gam"], math.exp(-DT_STEM / r["tau_l"])
            pr[P_CHAR] = r["R"] if r["kind"] == "kiln" else 0.0
            pr[P_F0] = f0 = float(_char(r["x0"], pr[P_CHAR]))
            self.y_init[i], self.b0[i], delay[i] = _plant_par(pr, r, f0)
        self.par, self.delay = par, delay
        valve = par[:, P_VALVE]
        tau_p = np.array([r["tau_p"] for r in rows], float)
        tau_a = np.array([r["tau_a"] for r in rows], float)
        self.a_p, self.a_a = np.exp(-h / tau_p), np.exp(-h / tau_a)
        self.nf = np.full(n, int(round(h / DT_STEM)), np.int64)
        self.a_pf, self.a_af = np.exp(-DT_STEM / tau_p), np.exp(-DT_STEM / tau_a)
        self.nb = int(delay.max()) + 2
        #: controller output above the stem at rest after an upward move
        self.lead = np.where(valve == 1, par[:, P_DB] / 2.0, np.where(valve >= 0, par[:, P_FC], 0.0))
        kinds = [r["kind"] for r in rows]
        self.res = np.array([KILN_RES if k == "kiln" else r["span"] / LEVELS for k, r in zip(kinds, rows)])
        self.slew = np.array([r["slew"] if k == "weir" else np.inf for k, r in zip(kinds, rows)])

    def reset(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rest at the operating point: ``(pv (n,), stem (n,), op (n,))``."""
        st = np.zeros((self.n, N_ST))
        par = self.par
        valve = par[:, P_VALVE]
        st[:, X_X] = self.x0
        st[:, X_P] = st[:, X_A] = self.x0 + np.where(valve >= 0, par[:, P_FC], 0.0)
        st[:, X_Z] = np.select([valve == 0, valve == 1, valve == 2],
                               [par[:, P_FC] / par[:, P_SIG],                 # elasto-plastic: sigma0 z = F_c
                                par[:, P_FC] - par[:, P_DB] / 2.0,            # positioner: its integral
                                self.x0 - par[:, P_FC] / par[:, P_SIG]], 0.0)  # Armstrong: the presliding anchor
        st[:, X_Y1:X_Y4 + 1] = self.y_init
        self.st = st
        self.buf = np.repeat(self.b0[:, None], self.nb, axis=1)
        self.j = 0
        self.read = None
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
        k = np.arange(T)


        for i, r in enumerate(rows):
            g = np.random.default_rng(r["seed"])
            w = g.standard_normal(T)
            if r["t_noise"] > 0.0:
                w = ar1(w, r["t_noise"], scan)
            if r["kind"] == "basis":                 # one reading per traverse, held
                nsc = int(round(r["traverse"] / scan))
                w = w[(k // nsc) * nsc]
            noise[:, i] = r["noise"] * w
            ou = r["ou"] * ar1(g.standard_normal(T), r["t_ou"], scan)
            walk = np.cumsum(g.standard_normal(T)) * r["walk"] * math.sqrt(scan)
            half = 0.5 * r["sq_period"]
            square = r["sq"] * (np.floor((t + r["sq_off"] * half) / half) % 2 == 1)
            gate = np.zeros(T, bool)
            for t0, ln in zip(r["b_start"], r["b_len"]):
                gate |= (t >= t0 * duration) & (t < t0 * duration + ln)
            burst = r["b_std"] * ar1(g.standard_normal(T), r["b_tau"], scan) * gate
            load[:, i] = ou + walk + (r["drift"] + r["b_ramp"]) * t / duration + square + burst
        return noise, load

    def measure(self, pv: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """The transmitter's reading of ``pv + noise``: slew-limited on the weir, then quantised."""
        y = pv + noise
        if self.read is None:
            self.read = y.copy()
        else:
            lim = self.slew * self.scan
            self.read = np.where(np.isinf(lim), y, self.read + np.clip(y - self.read, -lim, lim))
        return np.round(self.read / self.res) * self.res


def main(argv=None) -> int:
    groups = [("kind", k) for k in KINDS] + [("valve", v) for v in VALVE_KINDS] + [("load", lk) for lk in LOAD_KINDS]
    return family_main(__doc__, FifthLoops, draw, 48, 5151, argv, healthy_s=HEALTHY_S, test_s=TEST_S,
                       diag_kind=DIAG_KIND, groups=groups)


if __name__ == "__main__":
    raise SystemExit(main())
