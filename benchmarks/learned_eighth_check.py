"""An eighth held-out check of the stiction compensators: process loops of mixed speed.

Like the second to seventh held-out families (``benchmarks/learned_unseen_check.py``, whose harness this script
uses: SIMC tuning from a step test of the frictionless loop, one ``load_controller`` block per scan group, the
benchmark's scores; ``benchmarks/learned_third_check.py`` to ``benchmarks/learned_seventh_check.py``), nothing
here was used while the compensators were designed, trained or tuned, and every choice below was fixed before any
compensator was run on it. Nothing physical is imported from valve_gym: every equation is coded here. The theme
is the process plant's mix of speeds: a fast turbine, a line with a transport delay that changes with the flow,
a slow aeration basin and a composition read by a sampling analyser. Every loop starts at rest at its set point,
its stem stuck just after an upward move (the controller's output ``F_c`` above the stem, see below); the set
point is held. ``pv`` is the transmitter's reading in fractions of its span; a load ``d`` (a fraction of the
valve's full flow) acts as extra valve flow (``d > 0`` raises ``pv``); every loop is reverse acting (opening the
valve raises ``pv``). Plants and valves are new to the held-out families.

Plants (``kind``; linear valves; flows in fractions of the valve's full flow; sub-steps of 0.05 s)
    ``pipeline``: supply temperature at the far end of a long hot-water line (district heating): the valve sets
    the flow ``q = x + d`` (at least 0.02) of water leaving the heater at ``T_h``; plug flow, so the water
    arriving now entered ``tau_r`` ago, ``int_{t - tau_r}^t q dt = V`` (the delay changes with the flow: ``V /
    q_0`` 30-150 s at the operating point), and lost heat to the ground on the way, ``T = T_g + (T_h - T_g)
    exp(-tau_r / tau_L)`` (``tau_r / tau_L`` 0.05-0.25 at the operating point, ``T_h - T_g`` 50-90 K): more flow
    arrives sooner and warmer. A step of the flow shows at the far end as a ramp that lasts one residence (the
    water already in the line speeds up at once), so how long the loop takes to see a move changes with the
    flow. The pipe wall's heat capacity (a lag of 10-40 s) and a thermowell (5-20 s) follow; ``pv = pv_0 + (T -
    T_0) / 20 K``, ``pv_0`` 0.4-0.6; gain 0.3-1.5 per stroke. The residence is tracked on a delay line of the
    volume passed, capped at 819 s.
    ``analyser``: removal of an impurity in a stirred reactor by a reagent dosed through the valve, second-order
    reaction, both in units of the feed's impurity: ``c' = (1 - c) / theta - k c r``, ``r' = (rho (x + d) - r) /
    theta - k c r`` (residence ``theta`` 150-600 s; at the operating point removal ``X_0 = 1 - c_0`` 0.6-0.9
    and reagent excess ``r_0 = e X_0``, ``e`` 0.1-0.5, which fix ``k`` and ``rho``). ``pv = X = 1 - c`` (the
    removal), read by an online analyser at the end of a sample line (dead time 10-40 s) that takes a sample
    every ``T_a`` (30-120 s, whole seconds), analyses it for one cycle and holds the result until the next:
    each reading is 1-2 cycles plus the line old. The slowest loop.
    ``aeration``: dissolved oxygen ``C`` [mg/l] in an activated-sludge basin, air through the valve: ``C' =
    kLa_0 (q / q_0)^n (C_s - C) - OUR`` (``q = x + d``, ``n`` 0.7-0.95: diffusers transfer less per unit air
    at high flow; ``C_s`` 8-10 mg/l, ``C_0`` 1.5-3 mg/l, ``1 / kLa_0`` 120-480 s, ``OUR`` fixed by the
    operating point), the gain falls as ``C`` nears saturation; an optical probe's lag of 20-60 s. ``pv = C /
    10 mg/l``.
    ``turbine``: speed ``w`` of a steam turbine driving a centrifugal pump: the steam flow ``q_s`` follows ``x
    + d`` through the steam chest (lag 0.3-1.5 s), ``M w' = q_s (a - b w) - w^2`` (the turbine's torque falls
    with speed, ``b / (a - b)`` 0.5-1 at rated speed ``w_0 = 1``; the pump's torque goes with ``w^2``), speed
    time constant ``M / (q_0 b + 2)`` 3-12 s at the operating point; ``pv = w / w_span`` (``w_span`` 1.2-1.6);
    gain ``1 / (x_0 (2 + b / (a - b)) w_span)`` per stroke. The fastest loop.
Valves (a first-order positioner, ``tau_p`` 0.2-2 s, whose output ``p`` reaches a spring-diaphragm actuator as
the pressure ``P_a`` (stroke units) through an air lag ``tau_a`` 0.1-0.4 s; a second-order stem ``x'' = wn^2 (P_a
- x - F_f) - 2 zeta wn x'`` (``wn`` 8-25 rad/s, ``zeta`` 0.6-0.9: the packing's viscous friction and the
actuator's damping; friction ``F_f`` over the spring rate), integrated semi-implicitly in 1-ms steps)
    The stiction size ``S`` (reversal band: the input change that reverses a stem at rest) and slip ``J``:
    healthy valves have ``S < 0.004``, sticky ones 0.005-0.10 (log-uniform), ``J`` uniform in ``[0, S]``;
    ``F_s = (S + J) / 2``, ``F_c = (S - J) / 2``. A reversal from rest needs ``F_c + F_s = S``, a move on in
    the same direction ``F_s - F_c = J``, and the stem then slips by about ``J`` (up to 1.1 ``J`` with the
    stem's overshoot).

    ``reset``: the reset-integrator model of Haessig & Friedland (1991): a bristle deflection ``z`` integrates
    the stem's velocity while ``|z| < z_s`` (stuck: ``F_f = F_s z / z_s`` plus a damping that makes the stem
    critically damped on the bristle's stiffness), and is held at ``+-z_s`` once it gets there (sliding:
    ``F_f = F_c sgn(z)``); when the sliding stem stops or turns, the bristle takes the load again at ``z = z_s``
    (the model's jump back to the static level). ``z_s`` 1-2 % of ``S`` (the presliding move).

    ``ageing``: seal ageing: Coulomb sliding friction ``F_c`` and a static friction that grows with the time
    ``t_d`` the stem has rested (Kato's law, as Rabinowicz observed it): ``F_s(t_d) = F_c + J (1 - (1 - beta)
    exp(-sqrt(t_d / tau_k)))`` (``beta`` 0.2-0.5 of ``J`` right after a stop, ``tau_k`` 20-120 s); stuck while
    ``|P_a - x| <= F_s(t_d)``, breaks away beyond it, sticks again when its velocity reverses (``t_d`` from 0).
    ``S`` and ``J`` are those after a long rest (the loops start aged); a stem that stopped ``t_d`` ago needs
    ``J (1 - beta) exp(-sqrt(t_d / tau_k))`` less and slips as much less.

    ``slewing``: an actuator whose speed the supply limits: the positioner's relay fills the diaphragm at most
    at ``r sqrt((P_sup - P_a) / P_sup)`` and vents it at most at ``r sqrt(P_a / P_sup)`` (stroke/s; ``r``
    0.03-0.15, ``P_sup`` 1.5 stroke units), so a large move ramps; the stem sticks while ``|P_a - x| <= F_s``
    and slides against a power-law Stribeck friction (Bo & Pavelescu, exponent 1/2), ``F_f = sgn(x') (F_c +
    (F_s - F_c) exp(-sqrt(|x'| / v_s)))`` (``v_s`` 0.002-0.01 stroke/s), until its velocity reverses.

    Rest offset (controller output above the stem): ``F_c`` for all three (the reset integrator's bristle
    at ``z = z_s F_c / F_s``). The frictionless valves keep the positioner, the air lag and the slew limit.
Loads ``d`` (fraction of the valve's full flow; all start at 0)
    ``ou_small``: Ornstein-Uhlenbeck, std 0.1-0.5 %, correlation time 60-600 s; ``ou_large``: OU, std 1-3 %,
    120-900 s; ``steps``: 2-4 steps of +-0.5-2 % at random times in 10-90 % of the record, on a small OU (std 0.1
    %, 300 s); ``daily``: a slow sine of amplitude 0.5-2 % and period 3-8 h (random phase, shifted to start at 0:
    a plant's daily swing compressed), on the same small OU.
Measurement
    White (half the loops) or AR(1) noise (correlation time 1-10 s), std 0.0005-0.003 of the span; the
    analyser's noise is one draw per analysis, held with its reading (0.0005-0.002). A 14-bit transmitter
    (``span / 16384``).
Design (fixed before any compensator ran)
    4 plants x 3 valves x 4 loads, a full factorial (loop ``i``: plant ``i % 4``, valve ``(i // 4 + i // 12)
    % 3``, load ``(i // 12) % 4``), every third loop healthy; scans 0.5 s on 3 turbines in 4 (else 1 s), 1 s on
    3 pipelines and basins in 4 (else 2 s), 2 s on 3 analysers in 4 (else 1 s); tuning step test 1800 s; 48
    loops of one hour, seed 8181.

Usage::

    python benchmarks/learned_eighth_check.py --names pi knocker learned learned_network --known
        [--n 48] [--seed 8181] [--policy LABEL=FILE ...] [--diagnosed]

Besides the second script's table it prints, for each row, the LC share and the median compensation ratio
``R`` on the sticky loops by plant, by valve and by load.

Under the PI alone (``--names pi``, the only controller run while the family was written; 9 s for the 48 loops):

    controller        LC share  mean LC amp.  median R  travel / fr. PI  median abs. offset  healthy IAE / PI
                                [pv x1000]                                [pv x1000]
    PI frictionless   0.00      0.00          1.00      1.00             0.13                0.99
    pi                0.00      0.00          0.00      0.07             0.23                1.00

The frictionless PI holds its set point (median offset 0.13 pv x1000, at most 2.7: an analyser loop under the
large OU load, which the slow loop follows with a wandering error). The sticky PI's IAE exceeds the frictionless
PI's on 31 of the 32 sticky loops (median 1.35 times, 0.97-3.9): 1.35 on the pipeline, 1.2 on the analyser, 1.7
on the aeration basin, 1.45 on the turbine; 1.34 with the reset integrator, 1.49 with the ageing seals, 1.32
with the slewing actuator; 1.31 under the small OU, 1.22 under the large OU, 1.57 under the steps, 1.43 under
the daily swing. On 8 of the 32 stiction costs less than 10 % of the frictionless IAE, all bands under 1 % (the
one below 1, 0.97, a 0.5 % band on an analyser under the large OU). The stem stick-slips in the second half of
the hour (2 or more separate episodes of stem motion, ``slip_episodes`` of ``benchmarks/gen_stick_slip.py``) on
23 of the 32 (4 or more on 19; median 4.5): on all 8 turbines (median 41.5), 7 of the 8 pipelines (median 6), 5
of the 8 basins (3) and 3 of the 8 analysers (1); 7 of 10 reset-integrator, 9 of 11 ageing and 7 of 11 slewing
valves. The other 9 (5 analysers, 3 basins, a pipeline; 5 of them under the small OU) are bands of 0.6-9 % on
the slow loops that a small or a stepped load does not push through again within the half hour: the stem stays
stuck near the opening the load needs and the PI's integral winds slowly through the band. The PI's stem travels
0.07 of the frictionless PI's (median). The benchmark's limit-cycle rule calls none of the 32 under either PI:
the turbines' many slips are jittered by the noise and the loads, and the slow loops' cycles (where they cycle)
take longer than the rule's five periods an hour; on this family the IAE ratio, the travel and ``R`` say more
than the LC share.
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
    ar1,
    check_family,
    factorial_loop,
    family_main,
    log_uniform,
    run,
    tune,
)

KINDS = ("pipeline", "analyser", "aeration", "turbine")
VALVE_KINDS = ("reset", "ageing", "slewing")
#: The process kind an engineer would give the diagnosis for each plant (``--diagnosed``).
DIAG_KIND = {"pipeline": "first_order", "analyser": "first_order", "aeration": "first_order",
             "turbine": "first_order"}
LOAD_KINDS = ("ou_small", "ou_large", "steps", "daily")
#: Scan times [s] of each plant: ``(usual, occasional)``; the usual one on 3 loops in 4.
SCANS = {"pipeline": (1.0, 2.0), "analyser": (2.0, 1.0), "aeration": (1.0, 2.0), "turbine": (0.5, 1.0)}
#: Measurement noise std [fraction of the transmitter's span] (drawn uniformly).
NOISE = {"pipeline": (0.0005, 0.003), "analyser": (0.0005, 0.002), "aeration": (0.0005, 0.003),
         "turbine": (0.0005, 0.003)}
#: Length of the tuning step test [s].
TEST_S = 1800.0
#: Healthy valves: S below this (fraction of stroke).
HEALTHY_S = 0.004
#: Plant sub-step [s]; the stem's step [s].
H_PLANT, DT_STEM = 0.05, 1e-3
#: Transmitter resolution: 14 bits of the span.
LEVELS = 16384
#: The slewing actuator's supply pressure [stroke units].
P_SUP = 1.5
#: Delay-line length [plant sub-steps] (the pipeline's residence is capped at NB * H_PLANT = 819 s).
NB = 16384
#: The pipeline's transmitter span [K] and the DO transmitter's [mg/l].
T_SPAN, DO_SPAN = 20.0, 10.0

# parameter columns of the kernel
(C_KIND, C_VALVE, C_S, C_J, C_FS, C_FC, C_WN, C_ZETA, C_APF, C_AAF, C_RATE, C_ZS, C_SIG1, C_BETA, C_TK, C_VS,
 C_A, C_B, C_C, C_D, C_E, C_F, C_G, C_H, C_X0, N_COL) = range(26)
# state columns: positioner, diaphragm pressure, stem, velocity, bristle, sliding direction (0 stuck), dwell [s],
# plant states Y1..Y4, the pipeline's residence pointer, the analyser's clock, its held reading, its sample
(S_P, S_PA, S_X, S_V, S_Z, S_SLIDE, S_DWELL, S_Y1, S_Y2, S_Y3, S_Y4, S_K, S_CLK, S_HOLD, S_SAMP, N_STATE) = range(16)


def _plant_row(r, kind: str) -> dict:
    """The plant's settings (module docstring), drawn in a fixed order whatever the kind."""
    return dict(
        pipeline=dict(tau_r=log_uniform(r, 30.0, 150.0), loss=r.uniform(0.05, 0.25), dT=r.uniform(50.0, 90.0),
                      T_wall=r.uniform(10.0, 40.0), T_well=r.uniform(5.0, 20.0), pv0=r.uniform(0.4, 0.6)),
        analyser=dict(theta=log_uniform(r, 150.0, 600.0), X0=r.uniform(0.6, 0.9), excess=r.uniform(0.1, 0.5),
                      line=r.uniform(10.0, 40.0), cycle=float(r.integers(30, 121))),
        aeration=dict(n_kla=r.uniform(0.7, 0.95), C_s=r.uniform(8.0, 10.0), C0=r.uniform(1.5, 3.0),
                      tau=log_uniform(r, 120.0, 480.0), T_probe=r.uniform(20.0, 60.0)),
        turbine=dict(tau_s=r.uniform(0.3, 1.5), droop=r.uniform(0.5, 1.0), tau=log_uniform(r, 3.0, 12.0),
                     w_span=r.uniform(1.2, 1.6)),
    )[kind]


def draw(n: int, seed: int) -> list[dict]:
    """``n`` loops of the family (see the module docstring); one dict per loop."""
    out = []
    for i in range(n):
        r = np.random.default_rng([seed, i])
        kind, valve, load, S, J = factorial_loop(r, i, KINDS, VALVE_KINDS, LOAD_KINDS, HEALTHY_S)
        usual, other = SCANS[kind]
        row = dict(kind=kind, valve=valve, load=load, S=S, J=J, scan=usual if r.uniform() < 0.75 else other,
                   tau_p=r.uniform(0.2, 2.0), tau_a=r.uniform(0.1, 0.4), x0=r.uniform(0.35, 0.65),
                   wn=r.uniform(8.0, 25.0), zeta=r.uniform(0.6, 0.9), z_s=r.uniform(0.01, 0.02),
                   beta=r.uniform(0.2, 0.5), tau_k=r.uniform(20.0, 120.0), rate=r.uniform(0.03, 0.15),
                   v_s=r.uniform(0.002, 0.01), noise=r.uniform(*NOISE[kind]),
                   t_noise=r.uniform(1.0, 10.0) if r.uniform() < 0.5 else 0.0, seed=int(r.integers(1 << 30)))
        row.update(_plant_row(r, kind))
        ou_s, t_ou_s = r.uniform(0.001, 0.005), r.uniform(60.0, 600.0)
        ou_l, t_ou_l = r.uniform(0.01, 0.03), r.uniform(120.0, 900.0)
        n_steps = int(r.integers(2, 5))
        steps = [(r.uniform(0.1, 0.9), r.uniform(0.005, 0.02) * float(r.choice([-1.0, 1.0]))) for _ in range(4)]
        amp, period, phase = r.uniform(0.005, 0.02), r.uniform(10800.0, 28800.0), r.uniform(0.0, 2 * math.pi)
        if load == "ou_small":
            row.update(ou=ou_s, t_ou=t_ou_s)
        elif load == "ou_large":
            row.update(ou=ou_l, t_ou=t_ou_l)
        else:
            row.update(ou=0.001, t_ou=300.0)
        row.update(steps=steps[:n_steps] if load == "steps" else [], sine=amp if load == "daily" else 0.0,
                   period=period, phase=phase)
        out.append(row)
    return out


# ----------------------------------------------------------------------------------------------- valves
@njit(cache=False)
def _air(p, pa, a_a, rate):
    """One ``DT_STEM`` of the diaphragm pressure behind the air lag (and the relay's supply-limited fill and
    vent where ``rate > 0``)."""
    dpa = (p - pa) * (1.0 - a_a)
    if rate > 0.0:
        if dpa > 0.0:
            dpa = min(dpa, rate * DT_STEM * math.sqrt(max(P_SUP - pa, 0.0) / P_SUP))
        else:
            dpa = max(dpa, -rate * DT_STEM * math.sqrt(max(pa, 0.0) / P_SUP))
    return pa + dpa


@njit(cache=False)
def reset_step(c, pa, x, v, z, slide, wn2, damp):
    """One ``DT_STEM`` of the reset-integrator stem (Haessig & Friedland 1991): ``(x, v, z, slide)``."""
    h, zs = DT_STEM, c[C_ZS]
    if slide != 0.0:                                     # sliding: the bristle held at +-z_s, F_f = F_c
        vn = (v + h * wn2 * (pa - x - c[C_FC] * slide)) / (1.0 + h * damp)
        if vn * slide <= 0.0:                            # stops or turns: the bristle takes the load at z = +-z_s
            vn, slide = 0.0, 0.0
        return x + h * vn, vn, z, slide
    vn = (v + h * wn2 * (pa - x - c[C_FS] * z / zs)) / (1.0 + h * (damp + wn2 * c[C_SIG1]))
    z += h * vn
    if z >= zs:
        z, slide = zs, 1.0
    elif z <= -zs:
        z, slide = -zs, -1.0
    return x + h * vn, vn, z, slide


@njit(cache=False)
def stick_slip_step(c, vk, pa, x, v, slide, fsd, wn2, damp):
    """One ``DT_STEM`` of the ageing (``vk`` 1) or slewing (2) stem: ``(x, v, slide, stopped)``; stuck while
    ``|P_a - x| <= fsd`` (the static level now), sliding until the velocity reverses (``stopped``)."""
    spring = pa - x
    if slide == 0.0:
        if abs(spring) <= fsd:
            return x, 0.0, 0.0, False
        slide = math.copysign(1.0, spring)
        ff = slide * fsd
    elif vk == 1:
        ff = slide * c[C_FC]
    else:                                                # power-law Stribeck (Bo & Pavelescu, exponent 1/2)
        ff = slide * (c[C_FC] + (c[C_FS] - c[C_FC]) * math.exp(-math.sqrt(abs(v) / c[C_VS])))
    vn = (v + DT_STEM * wn2 * (spring - ff)) / (1.0 + DT_STEM * damp)
    if vn * slide <= 0.0:                                # the velocity reverses: stuck again, the rest begins
        return x, 0.0, 0.0, True
    return x + DT_STEM * vn, vn, slide, False


@njit(cache=False)
def _valve(c, s, u, nf):
    """``nf`` steps of ``DT_STEM`` of one loop's positioner, actuator and stem, state row ``s`` in place."""
    vk = int(c[C_VALVE])
    a_p, a_a, rate = c[C_APF], c[C_AAF], c[C_RATE]
    wn2, damp = c[C_WN] ** 2, 2.0 * c[C_ZETA] * c[C_WN]
    p, pa, x, v, z, slide = s[S_P], s[S_PA], s[S_X], s[S_V], s[S_Z], s[S_SLIDE]
    fsd = c[C_FS]
    if vk == 1:                    # ageing: the static level after the rest so far (changes slowly: per sub-step)
        fsd = c[C_FC] + c[C_J] * (1.0 - (1.0 - c[C_BETA]) * math.exp(-math.sqrt(s[S_DWELL] / c[C_TK])))
    for _ in range(nf):
        p = u + (p - u) * a_p
        pa = _air(p, pa, a_a, rate)
        if vk < 0:                                       # frictionless
            x = min(max(pa, 0.0), 1.0)
            continue
        if vk == 0:
            x, v, z, slide = reset_step(c, pa, x, v, z, slide, wn2, damp)
        else:
            x, v, slide, stopped = stick_slip_step(c, vk, pa, x, v, slide, fsd, wn2, damp)
            if slide == 0.0:
                s[S_DWELL] += DT_STEM
            if stopped:
                s[S_DWELL] = 0.0
                if vk == 1:
                    fsd = c[C_FC] + c[C_J] * c[C_BETA]
        if x <= 0.0 or x >= 1.0:
            x, v = min(max(x, 0.0), 1.0), 0.0
    s[S_P], s[S_PA], s[S_X], s[S_V], s[S_Z], s[S_SLIDE] = p, pa, x, v, z, slide


# ----------------------------------------------------------------------------------------------- plants
@njit(cache=False)
def _plant(c, s, buf, j, x, d):
    """One sub-step of ``H_PLANT`` of one loop's plant with stem ``x`` and load ``d``; ``buf`` its delay line,
    ``j`` the sub-step's index. Returns ``pv``."""
    h = H_PLANT
    kind = int(c[C_KIND])
    q = x + d
    if kind == 0:                        # pipeline: Y1 volume passed [pipe volumes], Y2 wall, Y3 thermowell
        w = s[S_Y1] + h * max(q, 0.02) * c[C_A]
        s[S_Y1] = w
        buf[j % NB] = w
        k = int(s[S_K]) + 1                              # the arriving plug is one sub-step older ...
        while k > 1 and w - buf[(j - k + 1) % NB] >= 1.0:
            k -= 1                                       # ... unless a later one has passed the pipe
        k = min(k, NB - 1)
        s[S_K] = k
        w_in, w_out = w - buf[(j - k + 1) % NB], w - buf[(j - k) % NB]
        tau = h * (k - 1 + (1.0 - w_in) / (w_out - w_in)) if w_out >= 1.0 else h * k
        t_arr = math.exp(-tau * c[C_B])                  # (T - T_g) / (T_h - T_g) of the water arriving
        s[S_Y2] += (t_arr - s[S_Y2]) * c[C_C]
        s[S_Y3] += (s[S_Y2] - s[S_Y3]) * c[C_D]
        return c[C_F] + c[C_E] * (s[S_Y3] - c[C_G])
    if kind == 1:                        # analyser: Y1 impurity c, Y2 reagent r
        cc, rr = s[S_Y1], s[S_Y2]
        rate = c[C_B] * cc * rr
        s[S_Y1] = cc + h * ((1.0 - cc) * c[C_A] - rate)
        s[S_Y2] = max(rr + h * ((c[C_C] * max(q, 0.0) - rr) * c[C_A] - rate), 0.0)
        buf[j % NB] = 1.0 - s[S_Y1]
        s[S_CLK] += h
        if s[S_CLK] >= c[C_E] - 1e-9:                    # a cycle ends: publish the last sample, take the next
            s[S_CLK] -= c[C_E]
            s[S_HOLD] = s[S_SAMP]
            s[S_SAMP] = buf[(j - int(c[C_D])) % NB]
        return s[S_HOLD]
    if kind == 2:                        # aeration: Y1 dissolved oxygen [mg/l], Y2 the probe's reading
        do = s[S_Y1]
        s[S_Y1] = do + h * (c[C_A] * (max(q, 0.0) / c[C_X0]) ** c[C_B] * (c[C_C] - do) - c[C_D])
        s[S_Y2] += (s[S_Y1] - s[S_Y2]) * c[C_E]
        return s[S_Y2] / DO_SPAN
    # turbine: Y1 steam flow, Y2 speed
    s[S_Y1] += (max(q, 0.0) - s[S_Y1]) * c[C_A]
    wr = s[S_Y2]
    s[S_Y2] = max(wr + h * (s[S_Y1] * (c[C_B] - c[C_C] * wr) - wr * wr) / c[C_D], 0.0)
    return s[S_Y2] / c[C_E]


@njit(cache=False)
def _advance(cols, st, buf, j0, op, load, m, nf, pv):
    """``m`` plant sub-steps of every loop with inputs ``op`` (n,) and ``load`` (n,) held; ``pv`` (n,) out."""
    for i in range(cols.shape[0]):
        c, s, b = cols[i], st[i], buf[i]
        u = min(max(op[i], 0.0), 1.0)
        for k in range(m):
            _valve(c, s, u, nf)
            pv[i] = _plant(c, s, b, j0 + k, s[S_X], load[i])


def plant_design(r: dict) -> tuple[dict, float, float]:
    """``(coefficients, the delay line's value at rest, pv at rest)`` of one loop's plant from its row."""
    kind, x0, h = r["kind"], r["x0"], H_PLANT
    if kind == "pipeline":
        tau_l = r["tau_r"] / r["loss"]
        t0 = math.exp(-r["loss"])
        g = dict(A=1.0 / (r["tau_r"] * x0), B=1.0 / tau_l, C=1.0 - math.exp(-h / r["T_wall"]),
                 D=1.0 - math.exp(-h / r["T_well"]), E=r["dT"] / T_SPAN, F=r["pv0"], G=t0, y=(0.0, t0, t0, 0.0))
        return g, 0.0, r["pv0"]
    if kind == "analyser":
        X0 = r["X0"]
        c0, r0 = 1.0 - X0, r["excess"] * X0
        k = X0 / (c0 * r0 * r["theta"])                  # (1 - c0) / theta = k c0 r0
        g = dict(A=1.0 / r["theta"], B=k, C=(r0 + X0) / x0, D=int(round(r["line"] / h)), E=r["cycle"], F=0.0,
                 G=0.0, y=(c0, r0, 0.0, 0.0))
        return g, X0, X0
    if kind == "aeration":
        kla = 1.0 / r["tau"]
        g = dict(A=kla, B=r["n_kla"], C=r["C_s"], D=kla * (r["C_s"] - r["C0"]),
                 E=1.0 - math.exp(-h / r["T_probe"]), F=0.0, G=0.0, y=(r["C0"], r["C0"], 0.0, 0.0))
        return g, 0.0, r["C0"] / DO_SPAN
    # turbine: a - b = 1 / x0 (torque 1 at rated speed and q0 = x0), b = droop / x0; tau = M / (q0 b + 2)
    b = r["droop"] / x0
    g = dict(A=1.0 - math.exp(-h / r["tau_s"]), B=1.0 / x0 + b, C=b, D=r["tau"] * (r["droop"] + 2.0),
             E=r["w_span"], F=0.0, G=0.0, y=(x0, 1.0, 0.0, 0.0))
    return g, 0.0, 1.0 / r["w_span"]


class EighthLoops:
    """Batched simulation of the family's loops of one scan time (the harness's simulator interface).

    Parameters
    ----------
    rows : list of dict, from :func:`draw`
    scan : float, s
    frictionless : bool
        Every stem follows its actuator (no friction): the reference.
    """

    def __init__(self, rows: list[dict], scan: float, frictionless: bool):
        self.rows, self.scan, self.n = rows, float(scan), len(rows)
        self.m = max(1, int(round(self.scan / H_PLANT)))
        self.nf = int(round(H_PLANT / DT_STEM))
        n = self.n
        cols = np.zeros((n, N_COL))
        self.x0 = np.array([r["x0"] for r in rows], float)
        self.y_init, self.b0, self.pv0 = np.zeros((n, 4)), np.zeros(n), np.zeros(n)
        for i, r in enumerate(rows):
            c = cols[i]
            c[C_KIND] = KINDS.index(r["kind"])
            c[C_VALVE] = -1 if frictionless else VALVE_KINDS.index(r["valve"])
            S, J = float(r["S"]), float(r["J"])
            fs, fc = (S + J) / 2.0, (S - J) / 2.0
            c[C_S], c[C_J], c[C_FS], c[C_FC] = S, J, fs, fc
            c[C_WN], c[C_ZETA] = r["wn"], r["zeta"]
            c[C_APF], c[C_AAF] = math.exp(-DT_STEM / r["tau_p"]), math.exp(-DT_STEM / r["tau_a"])
            c[C_RATE] = r["rate"] if r["valve"] == "slewing" else 0.0
            c[C_ZS] = r["z_s"] * S
            k_s = fs / c[C_ZS]                            # the bristle's stiffness over the spring rate
            c[C_SIG1] = 2.0 * (math.sqrt(1.0 + k_s) - r["zeta"]) / r["wn"]
            c[C_BETA], c[C_TK], c[C_VS], c[C_X0] = r["beta"], r["tau_k"], r["v_s"], r["x0"]
            g, self.b0[i], self.pv0[i] = plant_design(r)
            c[C_A], c[C_B], c[C_C], c[C_D], c[C_E], c[C_F], c[C_G] = (g[k] for k in "ABCDEFG")
            self.y_init[i] = g["y"]
        self.cols = cols
        #: controller output above the stem at rest after an upward move: F_c (none without friction)
        self.lead = np.where(cols[:, C_VALVE] >= 0, cols[:, C_FC], 0.0)
        self.res = np.full(n, 1.0 / LEVELS)

    def reset(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rest at the operating point, stuck after an upward move: ``(pv (n,), stem (n,), op (n,))``."""
        st = np.zeros((self.n, N_STATE))
        cols = self.cols
        u0 = self.x0 + self.lead
        st[:, S_X], st[:, S_P], st[:, S_PA] = self.x0, u0, u0
        fs = np.where(cols[:, C_FS] > 0, cols[:, C_FS], 1.0)
        st[:, S_Z] = np.where(cols[:, C_VALVE] == 0, cols[:, C_ZS] * cols[:, C_FC] / fs, 0.0)
        st[:, S_DWELL] = 1e9                             # long at rest: the seals aged
        st[:, S_Y1:S_Y4 + 1] = self.y_init
        st[:, S_HOLD] = st[:, S_SAMP] = self.pv0
        st[:, S_K] = NB - 1                               # the pipeline's pointer finds its plug on the first step
        self.st = st
        # the delay lines: the pipeline's volume passed at the steady flow (its last sub-step index -1), the
        # analyser's removal
        self.buf = np.repeat(self.b0[:, None], NB, axis=1)
        for i, r in enumerate(self.rows):
            if r["kind"] == "pipeline":
                age = NB - 1 - np.arange(NB)              # slot j % NB holds sub-step j; slot NB - 1 is j = -1
                self.buf[i] = -age * H_PLANT * cols[i, C_A] * self.x0[i]
        self.j = 0
        return self.pv0.copy(), self.x0.copy(), u0

    def step(self, op, load) -> tuple[np.ndarray, np.ndarray]:
        """One scan with input ``op`` (n,) and load ``load`` (n,) held: ``(pv, stem)`` after it."""
        pv = np.empty(self.n)
        _advance(self.cols, self.st, self.buf, self.j, np.asarray(op, float), np.asarray(load, float), self.m,
                 self.nf, pv)
        self.j += self.m
        return pv, self.st[:, S_X].copy()

    @staticmethod
    def disturbances(rows: list[dict], scan: float, T: int, duration: float) -> tuple[np.ndarray, np.ndarray]:
        """``(noise (T, n), load (T, n))``: the measurement noise and the loop's load (module docstring)."""

        noise, load = np.empty((T, len(rows))), np.empty((T, len(rows)))
        t = np.arange(T) * scan


        for i, r in enumerate(rows):
            g = np.random.default_rng(r["seed"])
            w = g.standard_normal(T)
            if r["kind"] == "analyser":                   # one draw per analysis, held with its reading
                w = w[(t // r["cycle"]).astype(int)]
            elif r["t_noise"] > 0.0:
                w = ar1(w, r["t_noise"], scan)
            noise[:, i] = r["noise"] * w
            d = r["ou"] * ar1(g.standard_normal(T), r["t_ou"], scan, stationary=False)
            for when, size in r["steps"]:
                d = d + size * (t >= when * duration)
            d = d + r["sine"] * (np.sin(2 * math.pi * t / r["period"] + r["phase"]) - math.sin(r["phase"]))
            load[:, i] = d
        return noise, load

    def measure(self, pv: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """The transmitter's reading of ``pv + noise`` (fractions of its span), quantised to 14 bits."""
        return np.round((pv + noise) / self.res) * self.res


def main(argv=None) -> int:
    groups = [("kind", k) for k in KINDS] + [("valve", v) for v in VALVE_KINDS] + [("load", lk) for lk in LOAD_KINDS]
    return family_main(__doc__, EighthLoops, draw, 48, 8181, argv, healthy_s=HEALTHY_S, test_s=TEST_S,
                       diag_kind=DIAG_KIND, groups=groups)


if __name__ == "__main__":
    raise SystemExit(main())
