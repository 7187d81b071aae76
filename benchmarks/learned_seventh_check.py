"""A seventh held-out check of the stiction compensators: the classic stick-slip limit cycle.

Like the second to sixth held-out families (``benchmarks/learned_unseen_check.py``, whose harness this script
uses: SIMC tuning from a step test of the frictionless loop, one ``load_controller`` block per scan group, the
benchmark's scores; ``benchmarks/learned_third_check.py`` to ``benchmarks/learned_sixth_check.py``), nothing here
was used while the compensators were designed, trained or tuned, and every choice below was fixed before any
compensator was run on it. Nothing physical is imported from valve_gym: every equation is coded here. The theme is
the case plant engineers know best: a PI at a constant set point on a sticky valve under only a small load. Every
loop starts at rest at its set point, its stem stuck just after an upward move (the controller's output ``F_c``
above the stem, see below); the set point is held. ``pv`` is the transmitter's reading in fractions of its span;
a load ``d`` (a fraction of the valve's full flow) acts as extra valve flow (``d > 0`` raises ``pv``).

Plants (``kind``; the valves are linear)
    ``torricelli``: a level tank with a free outlet through a hand valve, ``A L' = Q (x + d) - c sqrt(L)``, area
    ``A`` 0.2-3 m^2, level ``L_0`` 0.3-0.7 m on a 1-m span, time constant ``2 A L_0 / q_0`` 30-400 s (log-
    uniform) at the operating point; gain ``2 L_0 / x_0`` per stroke.
    ``pumped``: an integrating level drawn by a constant-speed pump, ``A L' = Q (x + d) - q_pump`` (``q_pump =
    Q x_0``), ``A`` 0.2-3 m^2, ``L_0`` 0.3-0.6 m on a 1-m span; a full-stroke imbalance fills 1 m in ``T_fill =
    A / Q`` 100-400 s.
    ``sphere``: a spherical vessel (radius ``R`` 0.5-1.2 m, span ``2 R``) with a free outlet, ``A(L) L' = Q (x +
    d) - c sqrt(L)``, ``A(L) = pi L (2 R - L)``, filled to 25-60 % of its height; time constant ``2 A(L_0) L_0 /
    q_0`` 30-400 s (log-uniform): the time constant and the gain change with the level.
    ``pressure``: a gas receiver, ``(V / R T) P' = q_in - q_out``, fed from a supply ``P_s`` (6-10 bar a)
    through the valve and drawn by a fixed orifice to the atmosphere, both by IEC 60534's gas flow ``p_1 Y
    sqrt(x)``, ``x = min((p_1 - p_2) / p_1, x_T)`` (choked beyond ``x_T``: 0.6-0.8 at the valve, 0.5-0.7 at the
    orifice), ``Y = 1 - x / (3 x_T)``; ``P_0`` 35-60 % of ``P_s``, time constant 5-30 s (log-uniform); the
    transmitter reads gauge pressure on a span that puts ``P_0`` at 50-70 % of it.
Valves (a first-order positioner, ``tau_p`` 0.3-2 s, whose output ``p`` drives the stem; fractions of stroke)
    The stiction size ``S`` (reversal band) and slip ``J``: healthy valves have ``S < 0.004``, sticky ones
    0.005-0.10 (log-uniform), ``J`` uniform in ``[0, S]``; ``F_s = (S + J) / 2``, ``F_c = (S - J) / 2``.

    ``kano``: Kano, Maruta, Kugemoto & Shimizu (2004), on ``p`` every 0.05 s: the moving valve stops where
    its input stops or turns (``dp dp_old <= 0``; the stick input ``u_s`` the last input); stopped, it moves
    against its last direction ``d`` once ``-d (p - u_s) > S`` and on in it once ``d (p - u_s) > J``, to ``p -
    d (S - J) / 2``, and follows that line while it moves.

    ``choudhury``: Choudhury, Thornhill & Shah (2005), on ``p`` every 0.05 s: the sign ``v`` of the input's
    velocity decides; the moving valve sticks where ``v`` is zero or turns against the last motion (``x_ss``
    the last input); stuck, it slips once ``|p - x_ss|`` exceeds ``J`` with ``v`` the last direction, ``S``
    against it, to ``p - v (S - J) / 2``.

    ``karnopp``: a force balance on the stem, ``x'' = wn^2 (p - x - F_f) - 2 zeta wn x'`` (``wn`` 8-25 rad/s,
    ``zeta`` 0.6-0.9; friction over the spring rate), 1-ms steps; Karnopp's zero-velocity window (``|x'| <
    1e-5`` stroke/s): there the friction takes the spring's force up to ``F_s`` and the stem holds; beyond it
    breaks away; outside the window ``F_f = F_c sgn(x')``. A reversal from rest needs ``S``, a move on ``J``;
    a breakaway slips ``J`` to 1.1 ``J`` (the stem's overshoot).

    Rest offset (controller output above the stem): ``F_c`` for all three. The frictionless valves keep the
    positioner's lag.
Loads ``d`` (small only; ``LOAD_SLOTS``)
    ``ou`` (24 of 48 loops): Ornstein-Uhlenbeck inflow, std 0.1-0.5 % of full flow, correlation time 60-600 s,
    from 0; ``drift`` (12): a ramp from 0 to +-0.2-1 % over the record; ``offset`` (12): a constant +-0.2-1 %
    from the first scan, so the valve has to move off the opening it rests at.
Measurement
    White noise, std 0.001-0.003 of the span (1-3 mm on the 1-m tanks), a 14-bit transmitter (``span / 16384``).
Design (fixed before any compensator ran)
    4 plants x 3 valves x 4 load slots, a full factorial (loop ``i``: plant ``i % 4``, valve ``(i // 4 + i //
    12) % 3``, load ``LOAD_SLOTS[(i // 12) % 4]``), every third loop healthy; scans 1 s on 3 loops in 4, 2 s on
    the others for the levels, 0.5 s for the receiver; tuning step test 1200 s; 48 loops of one hour, seed 7171.

Usage::

    python benchmarks/learned_seventh_check.py --names pi knocker learned learned_network --known
        [--n 48] [--seed 7171] [--policy LABEL=FILE ...] [--diagnosed]

Besides the second script's table it prints, for each row, the LC share and the median compensation ratio
``R`` on the sticky loops by plant, by valve and by load.

Under the PI alone (``--names pi``, the only controller run while the family was written), the stem still
stick-slips in the second half of the hour on 29 of the 32 sticky loops (2 or more separate episodes of stem
motion; 4 or more on 25; median 17): on every receiver (median 120) and sphere (16), on 6 of the 8 free-outlet
tanks (median 9) and on the pumped levels slowly (median 2). Its IAE is 1.35 times the frictionless PI's (median
over the sticky loops; 1.005-5.5): 2.5 on the receiver, 1.5 on the tank and the pumped level, 1.2 on the sphere;
2.0 with the Kano valves, 1.5 with the Karnopp stems, 1.0 with the Choudhury valves, whose stuck stem follows
any excursion of the noisy input beyond ``J`` (median 141 episodes). The frictionless PI holds its set point
(median offset 0.07 pv x1000; at most 2.7, a pumped level under a drift, which a PI on an integrating plant
follows with a constant error). The benchmark's limit-cycle rule calls 6 of the 32 under the PI (4 receivers,
a tank and a sphere; periods 19-450 s) and none under the frictionless PI. The rest are not regular within the
hour: with a small load the valve rests close to the opening the load needs, so the PI's integral winds up
the band slowly and the half-periods follow the load's wander; the noise, amplified by the tanks' tight SIMC
tuning (``K_c K`` about 5), moves the output by a good part of the smaller bands each scan; and the pumped
level's cycle (regular, the classic integrating case) takes 30-60 min a period under the tuning of a 1200-s
step test, beyond the rule's five periods an hour. On this family the stick-slip counts, the travel and ``R``
say more than the LC share.
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

from learned_unseen_check import (  # noqa: E402, F401  (KNOWN, DIAGNOSED, check_family, run, tune: the harness)
    DIAGNOSED,
    KNOWN,
    check_family,
    factorial_loop,
    family_main,
    log_uniform,
    run,
    tune,
)

KINDS = ("torricelli", "pumped", "sphere", "pressure")
VALVE_KINDS = ("kano", "choudhury", "karnopp")
#: The process kind an engineer would give the diagnosis for each plant (``--diagnosed``).
DIAG_KIND = {"torricelli": "tank", "pumped": "integrating", "sphere": "tank", "pressure": "first_order"}
#: The load of each quarter of the design (loop ``i``: ``LOAD_SLOTS[(i // 12) % 4]``): half OU, a quarter each
#: drift and offset.
LOAD_SLOTS = ("ou", "drift", "ou", "offset")
LOAD_KINDS = ("ou", "drift", "offset")
#: Scan times [s] of each plant: ``(usual, occasional)``; the usual one on 3 loops in 4.
SCANS = {"torricelli": (1.0, 2.0), "pumped": (1.0, 2.0), "sphere": (1.0, 2.0), "pressure": (1.0, 0.5)}
#: White measurement noise std [fraction of the transmitter's span] (drawn uniformly).
NOISE = {k: (0.001, 0.003) for k in KINDS}
#: Length of the tuning step test [s].
TEST_S = 1200.0
#: Healthy valves: S below this (fraction of stroke).
HEALTHY_S = 0.004
#: Plant sub-step [s]; the Karnopp stem's step [s]; its zero-velocity window [stroke/s].
H_PLANT, DT_STEM, DV_STEM = 0.05, 1e-3, 1e-5
#: Transmitter resolution: 14 bits of the span (``pv`` is in fractions of the span).
LEVELS = 16384
#: Atmospheric pressure [bar a] (the receiver's orifice discharges to it; its transmitter reads gauge).
P_ATM = 1.01325

# parameter columns of the kernel
(C_KIND, C_VALVE, C_S, C_J, C_FS, C_FC, C_WN, C_ZETA, C_AP, C_APF,
 C_Q, C_A, C_OUT, C_R, C_SPAN, C_PS, C_XT, C_XTO, C_CAP, N_COL) = range(20)
# state columns of the kernel: positioner, stem, stem velocity, stuck flag, stick input, direction of the last
# motion, last input increment, last input, the plant's variable (level [m] or pressure [bar a])
(S_P, S_X, S_V, S_STUCK, S_US, S_DIR, S_DU, S_PREV, S_Y, N_STATE) = range(10)


def _plant_row(r, kind: str) -> dict:
    """The plant's settings (see the module docstring), drawn in a fixed order whatever the kind."""
    k = dict(
        torricelli=dict(area=r.uniform(0.2, 3.0), tau=log_uniform(r, 30.0, 400.0), L0=r.uniform(0.3, 0.7)),
        pumped=dict(area=r.uniform(0.2, 3.0), T_fill=r.uniform(100.0, 400.0), L0=r.uniform(0.3, 0.6)),
        sphere=dict(radius=r.uniform(0.5, 1.2), tau=log_uniform(r, 30.0, 400.0), fill=r.uniform(0.25, 0.6)),
        pressure=dict(P_s=r.uniform(6.0, 10.0), ratio=r.uniform(0.35, 0.6), x_T=r.uniform(0.6, 0.8),
                      x_To=r.uniform(0.5, 0.7), tau=log_uniform(r, 5.0, 30.0), pv0=r.uniform(0.5, 0.7)),
    )[kind]
    if kind == "pressure":           # the transmitter ranged 0 to P0 / pv0 bar g
        k["span"] = (k["ratio"] * k["P_s"] - P_ATM) / k["pv0"]
    else:
        k["span"] = 2.0 * k["radius"] if kind == "sphere" else 1.0
    return k


def draw(n: int, seed: int) -> list[dict]:
    """``n`` loops of the family (see the module docstring); one dict per loop."""
    out = []
    for i in range(n):
        r = np.random.default_rng([seed, i])
        kind, valve, load, S, J = factorial_loop(r, i, KINDS, VALVE_KINDS, LOAD_SLOTS, HEALTHY_S)
        usual, other = SCANS[kind]
        row = dict(kind=kind, valve=valve, load=load, S=S, J=J, scan=usual if r.uniform() < 0.75 else other,
                   tau_p=r.uniform(0.3, 2.0), x0=r.uniform(0.35, 0.65), wn=r.uniform(8.0, 25.0),
                   zeta=r.uniform(0.6, 0.9), noise=r.uniform(*NOISE[kind]), seed=int(r.integers(1 << 30)))
        row.update(_plant_row(r, kind))
        ou, t_ou = r.uniform(0.001, 0.005), r.uniform(60.0, 600.0)
        drift = r.uniform(0.002, 0.01) * float(r.choice([-1.0, 1.0]))
        offset = r.uniform(0.002, 0.01) * float(r.choice([-1.0, 1.0]))
        row.update(ou=ou if load == "ou" else 0.0, t_ou=t_ou, drift=drift if load == "drift" else 0.0,
                   offset=offset if load == "offset" else 0.0)
        out.append(row)
    return out


# ----------------------------------------------------------------------------------------------- valves
@njit(cache=False)
def kano_step(p, s, S, J):
    """Kano et al. (2004) on one sample ``p`` of the positioner's output, state row ``s`` in place.

    The valve stops where its input stops or turns (``dp dp_old <= 0``: the stick input ``u_s`` is the last
    input); stopped, it moves against its last direction ``d`` once ``-d (p - u_s) > S`` (``d`` flips) and on
    in it once ``d (p - u_s) > J``, to ``p - d (S - J) / 2``; it follows that line while it moves.
    """
    dp = p - s[S_PREV]
    if s[S_STUCK] == 0.0 and dp * s[S_DU] <= 0.0:
        s[S_STUCK], s[S_US] = 1.0, s[S_PREV]
    d = s[S_DIR]
    if s[S_STUCK] == 1.0:
        if -d * (p - s[S_US]) > S:
            d = -d
            s[S_STUCK] = 0.0
        elif d * (p - s[S_US]) > J:
            s[S_STUCK] = 0.0
    if s[S_STUCK] == 0.0:
        s[S_X] = min(max(p - 0.5 * d * (S - J), 0.0), 1.0)
    s[S_DIR], s[S_DU], s[S_PREV] = d, dp, p


@njit(cache=False)
def choudhury_step(p, s, S, J):
    """Choudhury, Thornhill & Shah (2005) on one sample ``p`` of the positioner's output, state ``s`` in place.

    The sign of the input's velocity ``v`` decides: the moving valve sticks where ``v`` is zero or differs
    from the direction ``d`` of the last motion (``x_ss`` the last input); stuck, it slips once ``|p - x_ss|``
    exceeds ``J`` with ``v = d`` (the input goes on) or ``S`` with ``v = -d`` (it has turned), to ``p - v (S -
    J) / 2``, and follows that line while ``v = d``.
    """
    dp = p - s[S_PREV]
    v = 0.0 if dp == 0.0 else math.copysign(1.0, dp)
    moving = s[S_STUCK] == 0.0
    if moving and v != s[S_DIR]:
        moving = False
        s[S_US] = s[S_PREV]                               # x_ss: where the input stopped or turned
    if not moving and v != 0.0:
        band = J if v == s[S_DIR] else S
        moving = abs(p - s[S_US]) > band
    if moving:
        s[S_DIR] = v
        s[S_X] = min(max(p - 0.5 * v * (S - J), 0.0), 1.0)
    s[S_STUCK] = 0.0 if moving else 1.0
    s[S_DU], s[S_PREV] = dp, p


@njit(cache=False)
def karnopp_steps(u, s, c, nf):
    """``nf`` steps of ``DT_STEM`` of the positioner and the Karnopp stem, state row ``s`` in place.

    ``x'' = wn^2 (p - x - F_f) - 2 zeta wn x'``; in the window ``|x'| < DV_STEM`` the friction takes the
    spring's force ``p - x`` up to ``F_s`` (the stem holds, ``x' = 0``) and breaks away beyond it with ``F_f =
    F_s``; outside it ``F_f = F_c sgn(x')``. A velocity that changes sign over a step ends in the window.
    """
    fs, fc, a_pf = c[C_FS], c[C_FC], c[C_APF]
    wn2, damp = c[C_WN] ** 2, 2.0 * c[C_ZETA] * c[C_WN]
    p, x, v = s[S_P], s[S_X], s[S_V]
    h = DT_STEM
    for _ in range(nf):
        p = u + (p - u) * a_pf
        spring = p - x
        if abs(v) < DV_STEM:
            if abs(spring) <= fs:
                v = 0.0
                continue
            ff = math.copysign(fs, spring)
        else:
            ff = math.copysign(fc, v)
        vn = (v + h * wn2 * (spring - ff)) / (1.0 + h * damp)
        if v != 0.0 and vn * v < 0.0:
            vn = 0.0
        v = vn
        x += h * v
        if x <= 0.0 or x >= 1.0:
            x, v = min(max(x, 0.0), 1.0), 0.0
    s[S_P], s[S_X], s[S_V] = p, x, v


@njit(cache=False)
def _valve(c, s, u, a_p, nf):
    """One plant sub-step of ``H_PLANT`` of one loop's positioner and valve."""
    valve = int(c[C_VALVE])
    if valve == 2:
        karnopp_steps(u, s, c, nf)
        return
    p = u + (s[S_P] - u) * a_p
    s[S_P] = p
    if valve == 0:
        kano_step(p, s, c[C_S], c[C_J])
    elif valve == 1:
        choudhury_step(p, s, c[C_S], c[C_J])
    else:
        s[S_X] = min(max(p, 0.0), 1.0)


# ----------------------------------------------------------------------------------------------- plants
@njit(cache=False)
def gas_flow(p1, p2, x_t):
    """IEC 60534 gas flow through a restriction per unit coefficient: ``p1 Y sqrt(x)``, ``x = min((p1 - p2) /
    p1, x_T)`` (choked from ``x_T`` on), expansion factor ``Y = 1 - x / (3 x_T)``; 0 without a forward drop."""
    if p1 <= p2:
        return 0.0
    x = min((p1 - p2) / p1, x_t)
    return p1 * (1.0 - x / (3.0 * x_t)) * math.sqrt(x)


@njit(cache=False)
def sphere_area(L, R):
    """Surface area [m^2] of a sphere of radius ``R`` filled to ``L`` (at least 2 % of its equator's)."""
    return max(math.pi * L * (2.0 * R - L), 0.02 * math.pi * R * R)


@njit(cache=False)
def _plant(c, s, x, d):
    """One sub-step of ``H_PLANT`` of one loop's plant with stem ``x`` and load ``d`` (extra valve flow)."""
    h = H_PLANT
    kind = int(c[C_KIND])
    y = s[S_Y]
    if kind == 3:                                        # pressure [bar a]
        q_in = c[C_Q] * (x + d) * gas_flow(c[C_PS], y, c[C_XT])
        q_out = c[C_OUT] * gas_flow(y, P_ATM, c[C_XTO])
        s[S_Y] = max(y + h * (q_in - q_out) / c[C_CAP], P_ATM)
        return
    q_in = c[C_Q] * (x + d)
    if kind == 1:                                        # pumped: a constant-speed pump draws the tank
        q_out = c[C_OUT]
    else:                                                # free outlet through a hand valve
        q_out = c[C_OUT] * math.sqrt(max(y, 0.0))
    area = sphere_area(y, c[C_R]) if kind == 2 else c[C_A]
    s[S_Y] = max(y + h * (q_in - q_out) / area, 0.0)


@njit(cache=False)
def _advance(cols, st, op, load, m, a_p, nf):
    """``m`` plant sub-steps of ``H_PLANT`` of every loop with inputs ``op`` (n,) and ``load`` (n,) held."""
    for i in range(cols.shape[0]):
        c, s = cols[i], st[i]
        u = min(max(op[i], 0.0), 1.0)
        for _ in range(m):
            _valve(c, s, u, a_p[i], nf)
            _plant(c, s, s[S_X], load[i])


def plant_design(r: dict) -> dict:
    """The plant's coefficients and its operating point ``y0`` (level [m] or pressure [bar a]) from its row."""
    kind, x0 = r["kind"], r["x0"]
    if kind == "torricelli":            # A L' = Q (x + d) - c sqrt(L); tau = 2 A L0 / q0
        q0 = 2.0 * r["area"] * r["L0"] / r["tau"]
        return dict(Q=q0 / x0, A=r["area"], out=q0 / math.sqrt(r["L0"]), R=0.0, y0=r["L0"])
    if kind == "pumped":                # A L' = Q (x + d) - q_pump; a full-stroke imbalance fills 1 m in T_fill
        Q = r["area"] / r["T_fill"]
        return dict(Q=Q, A=r["area"], out=Q * x0, R=0.0, y0=r["L0"])
    if kind == "sphere":                # A(L) L' = Q (x + d) - c sqrt(L); tau = 2 A(L0) L0 / q0
        L0 = 2.0 * r["radius"] * r["fill"]
        q0 = 2.0 * float(sphere_area(L0, r["radius"])) * L0 / r["tau"]
        return dict(Q=q0 / x0, A=0.0, out=q0 / math.sqrt(L0), R=r["radius"], y0=L0)
    P0 = r["ratio"] * r["P_s"]          # V/(R T) P' = q_in - q_out, q0 = 1
    Q = 1.0 / (x0 * float(gas_flow(r["P_s"], P0, r["x_T"])))
    out = 1.0 / float(gas_flow(P0, P_ATM, r["x_To"]))
    dp = 1e-6 * P0
    slope = (out * (gas_flow(P0 + dp, P_ATM, r["x_To"]) - gas_flow(P0 - dp, P_ATM, r["x_To"]))
             - Q * x0 * (gas_flow(r["P_s"], P0 + dp, r["x_T"]) - gas_flow(r["P_s"], P0 - dp, r["x_T"]))) / (2 * dp)
    return dict(Q=Q, A=0.0, out=out, R=0.0, y0=P0, cap=r["tau"] * slope)


class SeventhLoops:
    """Batched simulation of the family's loops of one scan time (the harness's simulator interface).

    Parameters
    ----------
    rows : list of dict, from :func:`draw`
    scan : float, s
    frictionless : bool
        Every stem follows its positioner (no friction): the reference.
    """

    def __init__(self, rows: list[dict], scan: float, frictionless: bool):
        self.rows, self.scan, self.n = rows, float(scan), len(rows)
        self.m = max(1, int(round(self.scan / H_PLANT)))
        n = self.n
        cols = np.zeros((n, N_COL))
        self.x0 = np.array([r["x0"] for r in rows], float)
        self.y0, self.span = np.zeros(n), np.array([r["span"] for r in rows], float)
        self.zero = np.array([P_ATM if r["kind"] == "pressure" else 0.0 for r in rows])
        for i, r in enumerate(rows):
            c = cols[i]
            c[C_KIND] = KINDS.index(r["kind"])
            c[C_VALVE] = -1 if frictionless else VALVE_KINDS.index(r["valve"])
            S, J = float(r["S"]), float(r["J"])
            c[C_S], c[C_J], c[C_FS], c[C_FC] = S, J, (S + J) / 2.0, (S - J) / 2.0
            c[C_WN], c[C_ZETA] = r["wn"], r["zeta"]
            c[C_AP], c[C_APF] = math.exp(-H_PLANT / r["tau_p"]), math.exp(-DT_STEM / r["tau_p"])
            g = plant_design(r)
            c[C_Q], c[C_A], c[C_OUT], c[C_R], c[C_SPAN] = g["Q"], g["A"], g["out"], g["R"], r["span"]
            if r["kind"] == "pressure":
                c[C_PS], c[C_XT], c[C_XTO], c[C_CAP] = r["P_s"], r["x_T"], r["x_To"], g["cap"]
            self.y0[i] = g["y0"]
        self.cols = cols
        self.a_p = cols[:, C_AP].copy()
        self.nf = int(round(H_PLANT / DT_STEM))
        #: controller output above the stem at rest after an upward move: F_c (none without friction)
        self.lead = np.where(cols[:, C_VALVE] >= 0, cols[:, C_FC], 0.0)
        self.res = np.full(n, 1.0 / LEVELS)

    def reset(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rest at the operating point, stuck after an upward move: ``(pv (n,), stem (n,), op (n,))``."""
        st = np.zeros((self.n, N_STATE))
        u0 = self.x0 + self.lead
        st[:, S_X], st[:, S_P], st[:, S_PREV], st[:, S_US] = self.x0, u0, u0, u0
        st[:, S_STUCK], st[:, S_DIR], st[:, S_Y] = 1.0, 1.0, self.y0
        self.st = st
        return (self.y0 - self.zero) / self.span, self.x0.copy(), u0

    def step(self, op, load) -> tuple[np.ndarray, np.ndarray]:
        """One scan with input ``op`` (n,) and load ``load`` (n,) held: ``(pv, stem)`` after it."""
        _advance(self.cols, self.st, np.asarray(op, float), np.asarray(load, float), self.m, self.a_p, self.nf)
        return (self.st[:, S_Y] - self.zero) / self.span, self.st[:, S_X].copy()

    @staticmethod
    def disturbances(rows: list[dict], scan: float, T: int, duration: float) -> tuple[np.ndarray, np.ndarray]:
        """``(noise (T, n), load (T, n))``: white measurement noise and the loop's small load (module docstring)."""
        noise, load = np.empty((T, len(rows))), np.empty((T, len(rows)))
        t = np.arange(T) * scan
        for i, r in enumerate(rows):
            g = np.random.default_rng(r["seed"])
            noise[:, i] = r["noise"] * g.standard_normal(T)
            w = g.standard_normal(T)
            a = math.exp(-scan / r["t_ou"])
            ou = np.empty(T)
            level = 0.0                                   # the OU load starts at zero
            for k in range(T):
                level = a * level + math.sqrt(1.0 - a * a) * w[k]
                ou[k] = level
            load[:, i] = r["ou"] * ou + r["drift"] * t / duration + r["offset"]
        return noise, load

    def measure(self, pv: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """The transmitter's reading of ``pv + noise`` (fractions of its span), quantised to 14 bits."""
        return np.round((pv + noise) / self.res) * self.res


def main(argv=None) -> int:
    groups = [("kind", k) for k in KINDS] + [("valve", v) for v in VALVE_KINDS] + [("load", lk) for lk in LOAD_KINDS]
    return family_main(__doc__, SeventhLoops, draw, 48, 7171, argv, healthy_s=HEALTHY_S, test_s=TEST_S,
                       diag_kind=DIAG_KIND, groups=groups)


if __name__ == "__main__":
    raise SystemExit(main())
