"""A ninth held-out check of the stiction compensators: utility and energy loops.

Like the second to eighth held-out families (``benchmarks/learned_unseen_check.py``, whose harness this script
uses: SIMC tuning from a step test of the frictionless loop, one ``load_controller`` block per scan group, the
benchmark's scores; ``benchmarks/learned_third_check.py`` to ``benchmarks/learned_eighth_check.py``), nothing
here was used while the compensators were designed, trained or tuned, and every choice below was fixed before any
compensator was run on it. Nothing physical is imported from valve_gym: every equation is coded here from its
textbook statement. The theme is the utility side of a site: a boiler's firing, a desuperheater's spray, a
compressor's recycle and a cooling tower's bypass, with actuators found there (an electric actuator, a pneumatic
piston, a butterfly valve on a spring-return actuator). Every loop starts at rest at its set point, its stem
stuck just after an upward move (the controller's output above the stem, see below); the set point is held.
``pv`` is the transmitter's reading in fractions of its span; a load ``d`` (a fraction of the valve's full flow)
acts as extra valve flow (``d > 0`` raises ``pv``); every loop is reverse acting (opening the valve raises
``pv``; on the desuperheater, where more spray cools the steam, ``pv`` counts the temperature downwards). Plants
and valves are new to the held-out families.

Plants (``kind``; linear valves; flows in fractions of the valve's full flow; sub-steps of 0.05 s)
    ``boiler``: drum steam pressure ``P`` under firing-rate control, the valve on the fuel: the fuel ``x + d``
    burns after the burners' dead time (2-6 s) and heats the water through the furnace's lag (10-30 s) as
    ``Q``; the drum and its water store the energy, ``C P' = Q - k sqrt(P^2 - P_b^2)`` (the users draw through
    a fixed valve: gas flow, back pressure ``P_b`` 0.3-0.6 ``P_0``), ``P_0`` 0.5-0.75 of the span; the storage
    time constant ``C / (dq / dP)`` is 100-400 s (log-uniform) at the operating point; a transmitter lag of
    1-3 s; ``pv = P``, gain ``(P_0^2 - P_b^2) / (x_0 P_0)`` (0.64-1.41 per stroke). The slow loops with the
    towers (63 % of a step in 140-370 s).
    ``desuper``: outlet temperature of a spray desuperheater, the valve on the spray water ``w = x + d``: the
    mixed steam's temperature above the water's enthalpy expressed as steam temperature is ``E / (1 + w /
    rho)`` (an enthalpy balance; ``E`` 1000-1400 K, ``rho`` the steam flow in full spray flows, set by a spray
    of 4-8 % of the steam at the operating point, so the gain falls as the spray grows); the spray evaporates
    through a lag of 1-4 s and reaches the thermowell (lag 4-15 s) after a transport delay of 1-4 s. More
    spray cools, so ``pv = pv_0 - (T - T_0) / 150 K`` (``pv_0`` 0.4-0.6) is the temperature counted
    downwards, and ``d`` is extra spray (or a cooler inlet); gain 0.65-1.16 per stroke, 63 % in 10-21 s.
    ``compressor``: suction pressure ``P_s`` of a reciprocating compressor with a recycle valve (pressures in
    the suction's operating value): the machine draws ``q_c0 P_s`` (a fixed swept volume), the process feeds
    ``q_i0 sqrt((P_u - P_s) / (P_u - 1)) + d`` (``P_u`` 1.1-1.4), the recycle ``x sqrt((P_d - P_s) / (P_d0 -
    1))`` leaves the discharge drum at once and reaches the suction after its cooler's line (0.3-1.5 s), the
    discharge drum (``P_d0`` 2-3.5) feeds a header at ``P_h`` (0.8-0.95 ``P_d0``) through ``q_i0 sqrt((P_d -
    P_h) / (P_d0 - P_h))``; the recycle carries 25-50 % of the machine's flow at the operating point; the
    drums' time constants on their own slopes are 2-8 s (suction) and 3-10 s (discharge), and the two
    interact: the emptying discharge drum takes back up to 0.5 % of a step's rise. A transmitter lag of 0.2-1
    s; ``pv = pv_0 + (P_s - 1) / w`` (``w`` 0.2-0.4 of the operating pressure, ``pv_0`` 0.4-0.6); gain
    0.35-1.7 per stroke, 63 % in 3-10 s. The fastest loop.
    ``tower``: basin temperature ``theta`` of a cooling tower (above the wet bulb), the valve on the fill's
    bypass: the condenser returns the basin's water ``dT`` (5-10 K) warmer after the loop's transport delay
    ``D`` (20-60 s), ``theta_h = theta(t - D) + dT``; a share ``b = b_max (x + d)`` (``b_max`` 0.3-0.5)
    bypasses the fill, the rest is cooled toward the wet bulb with effectiveness ``eps`` (0.6-0.8), and the
    basin mixes, ``tau_b theta' = theta_h (1 - (1 - b) eps) - theta`` (``tau_b`` 100-360 s, log-uniform), so
    the water comes round again warmer (a positive feedback through the delay: each pass echoes the last); at
    rest ``theta_0 = dT / ((1 - b_0) eps) - dT``; a sensor lag of 10-30 s; ``pv = pv_0 + (theta - theta_0) /
    8 K``; gain ``b_max dT / ((1 - b_0)^2 eps 8 K)`` (0.65-1.28 per stroke), 63 % in 250-660 s.
Valves (a first-order positioner (for the electric actuator its input filter), ``tau_p`` 0.2-2 s, whose output
``p`` drives the actuator; stems integrated in 1-ms steps)
    The stiction size ``S`` (reversal band: the input change that reverses a stem at rest) and slip ``J``:
    healthy valves have ``S < 0.004``, sticky ones 0.005-0.10 (log-uniform), ``J`` uniform in ``[0, S]``;
    ``F_s = (S + J) / 2``, ``F_c = (S - J) / 2``. A reversal from rest needs ``F_c + F_s = S``, a move on in the
    same direction ``F_s - F_c = J``.

    ``electric``: an electric actuator with a self-locking gear, driven by a three-position (raise / stop /
    lower) step controller: the motor starts once the error ``p - x`` exceeds ``F_s``, runs at its fixed speed
    (a full stroke in 15-60 s) and stops once the error has fallen to ``F_c`` (the controller's switching
    hysteresis); the gear holds the stem while the motor stands. A breakaway moves the stem ``J`` (past it by
    at most one millisecond's run), as a ramp at the motor's speed, not a jump.

    ``piston``: a double-acting pneumatic piston without a spring: the positioner's relay sets the chambers'
    pressure difference ``D`` (stroke units: the positioner's stiffness) toward its error, ``D' = (p - x - D) /
    tau_c`` (``tau_c`` 0.02-0.1 s), and the piston, ``x'' = wn^2 (D - F_f) - 2 zeta wn x'`` (``wn`` 8-25 rad/s,
    ``zeta`` 0.6-0.9), sticks while ``|D| <= F_s m(t)``, slides against ``F_c m(t)`` and sticks again when its
    velocity reverses. The O-ring seals' friction grows with the pressure they seal: a share ``phi`` (0.5-0.9)
    of it goes with the instrument-air supply, which cycles as the air compressor loads and unloads, up from
    cut-in to cut-out over a share 0.4-0.6 of a cycle of 300-900 s and down again (``+-a``, ``a`` 3-8 % of the
    mean): ``m(t) = 1 + phi a (2 tri(t) - 1)``, at cut-in at the start. ``S`` and ``J`` are the band and slip at
    the mean supply; the band swings by ``+-phi a`` with the supply. Without a spring the piston overshoots
    while the chambers catch up: a breakaway slips 1.1-1.9 ``J``.

    ``butterfly``: a butterfly valve on a spring-diaphragm, rack-and-pinion actuator (an air lag ``tau_a``
    0.1-0.4 s to the pressure ``P_a``, stroke units), the disc's flow torque closing it, ``T_d = c_t sin(pi x)``
    (``c_t`` 0.03-0.12 of the spring's range): ``x'' = wn^2 (P_a - x - T_d(x) - F_f) - 2 zeta wn x'``; the disc
    sticks while ``|P_a - x - T_d(x)| <= F_s``, slides against ``F_c`` and sticks when its velocity reverses.
    The flow torque's slope adds to the spring's below mid-travel and takes from it above, so a breakaway slips
    0.94-1.21 ``J``.

    Rest offsets (controller output above the stem): ``F_c`` (electric), ``F_c m(0)`` (piston), ``F_c +
    T_d(x_0)`` (butterfly). The frictionless valves keep the positioner, the motor's speed, the chambers' and
    the air lags and the flow torque.
Loads ``d`` (fraction of the valve's full flow; all start at 0)
    ``ou_small``: Ornstein-Uhlenbeck, std 0.1-0.5 %, correlation time 60-600 s; ``ou_large``: OU, std 1-3 %,
    120-900 s; ``steps``: 2-4 steps of +-0.5-2 % at random times in 10-90 % of the record, on a small OU (std 0.1
    %, 300 s); ``ramp``: a slow ramp from 0 to +-0.5-2 % over the hour (a day's swing in demand or in the wet
    bulb), on the same small OU.
Measurement
    White (half the loops) or AR(1) noise (correlation time 1-10 s), std 0.0005-0.003 of the span (0.0005-0.002
    on the towers); a 14-bit transmitter (``span / 16384``).
Design (fixed before any compensator ran)
    4 plants x 3 valves x 4 loads, a full factorial (loop ``i``: plant ``i % 4``, valve ``(i // 4 + i // 12)
    % 3``, load ``(i // 12) % 4``), every third loop healthy; scans drawn, the usual one with probability 3/4:
    1 s (else 2 s) on the boilers, 0.5 s (else 1 s) on the desuperheaters and compressors, 2 s (else 1 s) on the
    towers; tuning step test 2400 s; 48 loops of one hour, seed 9191.

Usage::

    python benchmarks/learned_ninth_check.py --names pi knocker learned learned_network --known
        [--n 48] [--seed 9191] [--policy LABEL=FILE ...] [--diagnosed]

Besides the second script's table it prints, for each row, the LC share and the median compensation ratio
``R`` on the sticky loops by plant, by valve and by load.

Under the PI alone (``--names pi``, the only controller run while the family was written; 12 s for the 48 loops):

    controller        LC share  mean LC amp.  median R  travel / fr. PI  median abs. offset  healthy IAE / PI
                                [pv x1000]                                [pv x1000]
    PI frictionless   0.00      0.00          1.00      1.00             0.11                1.00
    pi                0.09      1.55          0.00      0.14             0.15                1.00

The frictionless PI holds its set point (median offset 0.12 pv x1000 over the 48 loops, at most 1.6: a tower
under the large OU load, which the slow loop follows with a wandering error). The sticky PI's IAE exceeds the
frictionless PI's on 31 of the 32 sticky loops (median 1.33 times, 0.99-7.0): 1.39 on the boiler, 2.0 on the
desuperheater, 1.45 on the compressor, 1.15 on the tower; 1.64 with the electric actuators, 1.30 with the
pistons, 1.19 with the butterfly valves; 1.25 under the small OU, 1.32 under the large OU, 1.54 under the steps,
1.63 under the ramp. On 5 of the 32 stiction costs less than 10 % of the frictionless IAE, all bands under 0.75
% (the one below 1, 0.99, a 0.5 % butterfly band on a tower under the small OU, which slips 88 times in the
second half against the noise). The stem stick-slips in the second half of the hour (2 or more separate episodes
of stem motion, ``slip_episodes`` of ``benchmarks/gen_stick_slip.py``) on 29 of the 32 (4 or more on 27; median
15): on all 8 desuperheaters (median 16.5) and compressors (80), 6 of the 8 boilers (4.5) and 7 of the 8 towers
(9.5); 9 of 10 electric, 10 of 11 piston and 10 of 11 butterfly valves. The other 3 are bands of 4-6.5 % on the
slow loops (a tower and a boiler under the small OU, a boiler under the steps) that the load does not push
through again within the half hour. The PI's stem travels 0.14 of the frictionless PI's (median). The
benchmark's limit-cycle rule calls 3 of the 32 under the PI (a desuperheater and a compressor with electric
actuators, bands of 5.6 and 7.1 % with ``J`` near ``S``, and a boiler with a 6 % piston band) and none under the
frictionless PI: the many slips are jittered by the noise and the loads, and the slow loops' cycles take longer
than the rule's five periods an hour; on this family the IAE ratio, the travel and ``R`` say more than the LC
share.
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

KINDS = ("boiler", "desuper", "compressor", "tower")
VALVE_KINDS = ("electric", "piston", "butterfly")
#: The process kind an engineer would give the diagnosis for each plant (``--diagnosed``).
DIAG_KIND = {"boiler": "first_order", "desuper": "first_order", "compressor": "first_order",
             "tower": "first_order"}
LOAD_KINDS = ("ou_small", "ou_large", "steps", "ramp")
#: Scan times [s] of each plant: ``(usual, occasional)``; the usual one on 3 loops in 4.
SCANS = {"boiler": (1.0, 2.0), "desuper": (0.5, 1.0), "compressor": (0.5, 1.0), "tower": (2.0, 1.0)}
#: Measurement noise std [fraction of the transmitter's span] (drawn uniformly).
NOISE = {"boiler": (0.0005, 0.003), "desuper": (0.0005, 0.003), "compressor": (0.0005, 0.003),
         "tower": (0.0005, 0.002)}
#: Length of the tuning step test [s].
TEST_S = 2400.0
#: Healthy valves: S below this (fraction of stroke).
HEALTHY_S = 0.004
#: Plant sub-step [s]; the actuator's and stem's step [s].
H_PLANT, DT_STEM = 0.05, 1e-3
#: Transmitter resolution: 14 bits of the span.
LEVELS = 16384
#: Delay-line length [plant sub-steps] (102 s).
NB = 2048
#: Transmitter spans: the desuperheater's [K] (inverted), the basin's [K].
DS_SPAN, TW_SPAN = 150.0, 8.0

# parameter columns of the kernel
(C_KIND, C_VALVE, C_FS, C_FC, C_WN, C_ZETA, C_APF, C_AAF, C_RATE, C_TQ, C_PHI, C_AMP, C_TC, C_FUP,
 C_A, C_B, C_C, C_D, C_E, C_F, C_G, C_H, C_I, C_K, C_DEL, C_PV0, N_COL) = range(27)
# state columns: positioner, actuator pressure (the piston's chamber difference), stem, velocity, motion
# (0 at rest, +-1 moving up/down), plant states Y1..Y4
(S_P, S_PA, S_X, S_V, S_MODE, S_Y1, S_Y2, S_Y3, S_Y4, N_STATE) = range(10)


def _plant_row(r, kind: str) -> dict:
    """The plant's settings (module docstring), drawn in a fixed order whatever the kind."""
    return dict(
        boiler=dict(P0=r.uniform(0.5, 0.75), Pb=r.uniform(0.3, 0.6), tau=log_uniform(r, 100.0, 400.0),
                    T_f=r.uniform(10.0, 30.0), dead=r.uniform(2.0, 6.0), T_tx=r.uniform(1.0, 3.0)),
        desuper=dict(E=r.uniform(1000.0, 1400.0), s0=r.uniform(0.04, 0.08), T_e=r.uniform(1.0, 4.0),
                     dead=r.uniform(1.0, 4.0), T_well=r.uniform(4.0, 15.0), pv0=r.uniform(0.4, 0.6)),
        compressor=dict(rs=r.uniform(0.25, 0.5), Pu=r.uniform(1.1, 1.4), Pd=r.uniform(2.0, 3.5),
                        Ph=r.uniform(0.8, 0.95), tau_s=r.uniform(2.0, 8.0), tau_d=r.uniform(3.0, 10.0),
                        dead=r.uniform(0.3, 1.5), T_tx=r.uniform(0.2, 1.0), w=r.uniform(0.2, 0.4),
                        pv0=r.uniform(0.4, 0.6)),
        tower=dict(dT=r.uniform(5.0, 10.0), eff=r.uniform(0.6, 0.8), bmax=r.uniform(0.3, 0.5),
                   tau=log_uniform(r, 100.0, 360.0), dead=r.uniform(20.0, 60.0), T_s=r.uniform(10.0, 30.0),
                   pv0=r.uniform(0.4, 0.6)),
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
                   wn=r.uniform(8.0, 25.0), zeta=r.uniform(0.6, 0.9), stroke_s=r.uniform(15.0, 60.0),
                   torque=r.uniform(0.03, 0.12), phi=r.uniform(0.5, 0.9), supply=r.uniform(0.03, 0.08),
                   cycle=r.uniform(300.0, 900.0), rise=r.uniform(0.4, 0.6), tau_c=r.uniform(0.02, 0.1),
                   noise=r.uniform(*NOISE[kind]), t_noise=r.uniform(1.0, 10.0) if r.uniform() < 0.5 else 0.0,
                   seed=int(r.integers(1 << 30)))
        row.update(_plant_row(r, kind))
        ou_s, t_ou_s = r.uniform(0.001, 0.005), r.uniform(60.0, 600.0)
        ou_l, t_ou_l = r.uniform(0.01, 0.03), r.uniform(120.0, 900.0)
        n_steps = int(r.integers(2, 5))
        steps = [(r.uniform(0.1, 0.9), r.uniform(0.005, 0.02) * float(r.choice([-1.0, 1.0]))) for _ in range(4)]
        slope = r.uniform(0.005, 0.02) * float(r.choice([-1.0, 1.0]))
        if load == "ou_small":
            row.update(ou=ou_s, t_ou=t_ou_s)
        elif load == "ou_large":
            row.update(ou=ou_l, t_ou=t_ou_l)
        else:
            row.update(ou=0.001, t_ou=300.0)
        row.update(steps=steps[:n_steps] if load == "steps" else [], ramp=slope if load == "ramp" else 0.0)
        out.append(row)
    return out


# ----------------------------------------------------------------------------------------------- valves
@njit(cache=False)
def supply_scale(c, t):
    """The piston's seal friction over its value at the mean supply pressure, at time ``t`` [s]: the instrument
    air cycles between cut-in (``t = 0``) and cut-out as its compressor loads and unloads."""
    ph = (t % c[C_TC]) / c[C_TC]
    tri = ph / c[C_FUP] if ph < c[C_FUP] else (1.0 - ph) / (1.0 - c[C_FUP])
    return 1.0 + c[C_PHI] * c[C_AMP] * (2.0 * tri - 1.0)


@njit(cache=False)
def _electric(c, p, x, mode, fs, fc):
    """One ``DT_STEM`` of the electric actuator: ``(x, mode)``; the motor starts beyond ``fs``, runs at its
    fixed speed and stops once the error has fallen to ``fc`` (no friction: follows at the fixed speed)."""
    step = c[C_RATE] * DT_STEM
    if fs <= 0.0:
        return x + min(max(p - x, -step), step), 0.0
    if mode == 0.0:
        e = p - x
        if abs(e) <= fs:
            return x, 0.0
        mode = math.copysign(1.0, e)
    x += mode * step
    if mode * (p - x) <= fc:
        mode = 0.0
    return x, mode


@njit(cache=False)
def _stem(force, x, v, mode, fs, fc, wn2, damp):
    """One ``DT_STEM`` of a stem driven by ``force`` (stroke units) against static ``fs`` and sliding ``fc``
    friction: ``(x, v, mode)``; stuck while ``|force| <= fs``, sliding until its velocity reverses."""
    if fs <= 0.0:                                        # frictionless
        vn = (v + DT_STEM * wn2 * force) / (1.0 + DT_STEM * damp)
        return x + DT_STEM * vn, vn, 0.0
    if mode == 0.0:
        if abs(force) <= fs:
            return x, 0.0, 0.0
        mode = math.copysign(1.0, force)
        ff = mode * fs
    else:
        ff = mode * fc
    vn = (v + DT_STEM * wn2 * (force - ff)) / (1.0 + DT_STEM * damp)
    if vn * mode <= 0.0:
        return x, 0.0, 0.0
    return x + DT_STEM * vn, vn, mode


@njit(cache=False)
def _valve(c, s, u, nf, t):
    """``nf`` steps of ``DT_STEM`` of one loop's positioner, actuator and stem at time ``t``, row ``s`` in place."""
    vk = int(c[C_VALVE])
    a_p, a_a = c[C_APF], c[C_AAF]
    wn2, damp = c[C_WN] ** 2, 2.0 * c[C_ZETA] * c[C_WN]
    m = supply_scale(c, t) if vk == 1 else 1.0
    fs, fc = c[C_FS] * m, c[C_FC] * m
    p, pa, x, v, mode = s[S_P], s[S_PA], s[S_X], s[S_V], s[S_MODE]
    for _ in range(nf):
        p = u + (p - u) * a_p
        if vk == 0:
            x, mode = _electric(c, p, x, mode, fs, fc)
        elif vk == 1:                                    # the chambers' difference follows the positioner's error
            pa = (p - x) + (pa - (p - x)) * a_a
            x, v, mode = _stem(pa, x, v, mode, fs, fc, wn2, damp)
        else:                                            # spring-return actuator against the flow torque
            pa = p + (pa - p) * a_a
            x, v, mode = _stem(pa - x - c[C_TQ] * math.sin(math.pi * x), x, v, mode, fs, fc, wn2, damp)
        if x <= 0.0 or x >= 1.0:
            x, v = min(max(x, 0.0), 1.0), 0.0
    s[S_P], s[S_PA], s[S_X], s[S_V], s[S_MODE] = p, pa, x, v, mode


# ----------------------------------------------------------------------------------------------- plants
@njit(cache=False)
def _boiler(c, s, buf, j, q):
    """Drum pressure under firing: fuel through the burners' dead time and the furnace's lag, storage."""
    buf[j % NB] = max(q, 0.0)
    fuel = buf[(j - int(c[C_DEL])) % NB]
    s[S_Y1] += (fuel - s[S_Y1]) * c[C_A]
    P = s[S_Y2]
    steam = c[C_B] * math.sqrt(max(P * P - c[C_C] * c[C_C], 0.0))
    s[S_Y2] = P + H_PLANT * (s[S_Y1] - steam) / c[C_D]
    s[S_Y3] += (s[S_Y2] - s[S_Y3]) * c[C_E]
    return s[S_Y3]


@njit(cache=False)
def _desuper(c, s, buf, j, q):
    """Spray desuperheater: mixing, evaporation lag, transport to the thermowell; ``pv`` inverted."""
    buf[j % NB] = c[C_A] / (1.0 + max(q, 0.0) * c[C_B])
    s[S_Y1] += (buf[(j - int(c[C_DEL])) % NB] - s[S_Y1]) * c[C_C]
    s[S_Y2] += (s[S_Y1] - s[S_Y2]) * c[C_D]
    return c[C_PV0] - (s[S_Y2] - c[C_E]) / DS_SPAN


@njit(cache=False)
def _compressor(c, s, buf, j, x, d):
    """Suction and discharge drums of a reciprocating compressor with a recycle valve (``x``)."""
    ps, pd = s[S_Y1], s[S_Y2]
    rec = max(x, 0.0) * math.sqrt(max(pd - ps, 0.0) * c[C_A])
    buf[j % NB] = rec
    rec_in = buf[(j - int(c[C_DEL])) % NB]
    comp = c[C_B] * ps
    q_in = c[C_C] * math.sqrt(max(c[C_F] - ps, 0.0)) + d
    q_out = c[C_D] * math.sqrt(max(pd - c[C_G], 0.0))
    s[S_Y1] = ps + H_PLANT * (q_in + rec_in - comp) / c[C_H]
    s[S_Y2] = pd + H_PLANT * (comp - rec - q_out) / c[C_I]
    s[S_Y3] += (s[S_Y1] - s[S_Y3]) * c[C_E]
    return c[C_PV0] + (s[S_Y3] - 1.0) / c[C_K]


@njit(cache=False)
def _tower(c, s, buf, j, q):
    """Cooling-tower basin (above the wet bulb) with a fill bypass; the condenser loop's return delayed."""
    buf[j % NB] = s[S_Y1]
    hot = buf[(j - int(c[C_DEL])) % NB] + c[C_A]
    b = min(max(c[C_B] * q, 0.0), 1.0)
    s[S_Y1] += H_PLANT * (hot * (1.0 - (1.0 - b) * c[C_C]) - s[S_Y1]) / c[C_D]
    s[S_Y2] += (s[S_Y1] - s[S_Y2]) * c[C_E]
    return c[C_PV0] + (s[S_Y2] - c[C_F]) / TW_SPAN


@njit(cache=False)
def _advance(cols, st, buf, j0, op, load, m, nf, pv):
    """``m`` plant sub-steps of every loop with inputs ``op`` (n,) and ``load`` (n,) held; ``pv`` (n,) out."""
    for i in range(cols.shape[0]):
        c, s, b = cols[i], st[i], buf[i]
        u = min(max(op[i], 0.0), 1.0)
        kind = int(c[C_KIND])
        for k in range(m):
            j = j0 + k
            _valve(c, s, u, nf, j * H_PLANT)
            x, d = s[S_X], load[i]
            if kind == 0:
                pv[i] = _boiler(c, s, b, j, x + d)
            elif kind == 1:
                pv[i] = _desuper(c, s, b, j, x + d)
            elif kind == 2:
                pv[i] = _compressor(c, s, b, j, x, d)
            else:
                pv[i] = _tower(c, s, b, j, x + d)


def plant_design(r: dict) -> tuple[dict, float, float]:
    """``(coefficients, the delay line's value at rest, pv at rest)`` of one loop's plant from its row."""
    kind, x0, h = r["kind"], r["x0"], H_PLANT
    dead = int(round(r["dead"] / h))
    if kind == "boiler":
        P0, Pb = r["P0"], r["Pb"] * r["P0"]
        k = x0 / math.sqrt(P0 * P0 - Pb * Pb)            # the users draw x0 at P0
        slope = k * P0 / math.sqrt(P0 * P0 - Pb * Pb)
        g = dict(A=1.0 - math.exp(-h / r["T_f"]), B=k, C=Pb, D=r["tau"] * slope, E=1.0 - math.exp(-h / r["T_tx"]),
                 y=(x0, P0, P0, 0.0))
        return dict(g, DEL=dead), x0, P0
    if kind == "desuper":
        rho_inv = r["s0"] / x0                           # 1 / (steam flow in full spray flows)
        T0 = r["E"] / (1.0 + r["s0"])
        g = dict(A=r["E"], B=rho_inv, C=1.0 - math.exp(-h / r["T_e"]), D=1.0 - math.exp(-h / r["T_well"]), E=T0,
                 y=(T0, T0, 0.0, 0.0))
        return dict(g, DEL=dead, PV0=r["pv0"]), T0, r["pv0"]
    if kind == "compressor":
        qc0 = x0 / r["rs"]
        qi0 = qc0 - x0
        Pd0, Ph = r["Pd"], r["Ph"] * r["Pd"]
        ki, ko = qi0 / math.sqrt(r["Pu"] - 1.0), qi0 / math.sqrt(Pd0 - Ph)
        slope_s = qc0 + ki / (2.0 * math.sqrt(r["Pu"] - 1.0)) + x0 / (2.0 * (Pd0 - 1.0))
        slope_d = ko / (2.0 * math.sqrt(Pd0 - Ph)) + x0 / (2.0 * (Pd0 - 1.0))
        g = dict(A=1.0 / (Pd0 - 1.0), B=qc0, C=ki, D=ko, E=1.0 - math.exp(-h / r["T_tx"]), F=r["Pu"], G=Ph,
                 H=r["tau_s"] * slope_s, I=r["tau_d"] * slope_d, K=r["w"], y=(1.0, Pd0, 1.0, 0.0))
        return dict(g, DEL=dead, PV0=r["pv0"]), x0, r["pv0"]
    b0 = r["bmax"] * x0
    th0 = r["dT"] / ((1.0 - b0) * r["eff"]) - r["dT"]    # the basin above the wet bulb at rest
    g = dict(A=r["dT"], B=r["bmax"], C=r["eff"], D=r["tau"], E=1.0 - math.exp(-h / r["T_s"]), F=th0,
             y=(th0, th0, 0.0, 0.0))
    return dict(g, DEL=dead, PV0=r["pv0"]), th0, r["pv0"]


def rest_offset(r: dict, frictionless: bool) -> float:
    """The controller's output above the stem at rest at ``x0`` after an upward move."""
    S, J = float(r["S"]), float(r["J"])
    fc = 0.0 if frictionless else (S - J) / 2.0
    if r["valve"] == "piston":
        return fc * (1.0 - r["phi"] * r["supply"])       # at cut-in
    if r["valve"] == "butterfly":
        return fc + r["torque"] * math.sin(math.pi * r["x0"])
    return fc


class NinthLoops:
    """Batched simulation of the family's loops of one scan time (the harness's simulator interface).

    Parameters
    ----------
    rows : list of dict, from :func:`draw`
    scan : float, s
    frictionless : bool
        No friction (and no motor dead band): the reference.
    """

    def __init__(self, rows: list[dict], scan: float, frictionless: bool):
        self.rows, self.scan, self.n = rows, float(scan), len(rows)
        self.m = max(1, int(round(self.scan / H_PLANT)))
        self.nf = int(round(H_PLANT / DT_STEM))
        n = self.n
        cols = np.zeros((n, N_COL))
        self.x0 = np.array([r["x0"] for r in rows], float)
        self.y_init, self.b0, self.pv0 = np.zeros((n, 4)), np.zeros(n), np.zeros(n)
        self.lead = np.array([rest_offset(r, frictionless) for r in rows])
        for i, r in enumerate(rows):
            c = cols[i]
            c[C_KIND], c[C_VALVE] = KINDS.index(r["kind"]), VALVE_KINDS.index(r["valve"])
            S, J = float(r["S"]), float(r["J"])
            if not frictionless:
                c[C_FS], c[C_FC] = (S + J) / 2.0, (S - J) / 2.0
            c[C_WN], c[C_ZETA] = r["wn"], r["zeta"]
            lag = r["tau_c"] if r["valve"] == "piston" else r["tau_a"]
            c[C_APF], c[C_AAF] = math.exp(-DT_STEM / r["tau_p"]), math.exp(-DT_STEM / lag)
            c[C_RATE], c[C_TQ] = 1.0 / r["stroke_s"], r["torque"] if r["valve"] == "butterfly" else 0.0
            c[C_PHI], c[C_AMP], c[C_TC], c[C_FUP] = r["phi"], r["supply"], r["cycle"], r["rise"]
            g, self.b0[i], self.pv0[i] = plant_design(r)
            for key, col in (("A", C_A), ("B", C_B), ("C", C_C), ("D", C_D), ("E", C_E), ("F", C_F), ("G", C_G),
                             ("H", C_H), ("I", C_I), ("K", C_K), ("DEL", C_DEL), ("PV0", C_PV0)):
                c[col] = g.get(key, 0.0)
            self.y_init[i] = g["y"]
        self.cols = cols
        self.res = np.full(n, 1.0 / LEVELS)

    def reset(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rest at the operating point, stuck after an upward move: ``(pv (n,), stem (n,), op (n,))``."""
        st = np.zeros((self.n, N_STATE))
        u0 = self.x0 + self.lead
        piston = self.cols[:, C_VALVE] == 1
        st[:, S_X], st[:, S_P] = self.x0, u0
        st[:, S_PA] = np.where(piston, self.lead, u0)    # the piston's chambers hold the rest offset
        st[:, S_Y1:S_Y4 + 1] = self.y_init
        self.st = st
        self.buf = np.repeat(self.b0[:, None], NB, axis=1)
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
            if r["t_noise"] > 0.0:
                w = ar1(w, r["t_noise"], scan)
            noise[:, i] = r["noise"] * w
            d = r["ou"] * ar1(g.standard_normal(T), r["t_ou"], scan, stationary=False)
            for when, size in r["steps"]:
                d = d + size * (t >= when * duration)
            load[:, i] = d + r["ramp"] * t / duration
        return noise, load

    def measure(self, pv: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """The transmitter's reading of ``pv + noise`` (fractions of its span), quantised to 14 bits."""
        return np.round((pv + noise) / self.res) * self.res


def main(argv=None) -> int:
    groups = [("kind", k) for k in KINDS] + [("valve", v) for v in VALVE_KINDS] + [("load", lk) for lk in LOAD_KINDS]
    return family_main(__doc__, NinthLoops, draw, 48, 9191, argv, healthy_s=HEALTHY_S, test_s=TEST_S,
                       diag_kind=DIAG_KIND, groups=groups)


if __name__ == "__main__":
    raise SystemExit(main())
