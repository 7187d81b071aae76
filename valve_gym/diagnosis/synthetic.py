"""Synthetic closed-loop recordings with one concealed effect (test and benchmark data).

Each recording is a level loop simulated by the one physics core
(:mod:`valve_gym.core`): a tank with Torricelli outflow fed through the
paper's sticky valve, controlled by the PI law of :mod:`valve_gym.control`
from a noisy level measurement, with set-point steps that move the loop
through its operating range.  At most one optional effect of
:data:`valve_gym.params.EFFECTS` is switched on, at a magnitude chosen so that
the loop still looks normal (the PI controller compensates most of it): the
diagnosis tool has to find it from OP and PV alone.

The valve friction of every case (also the ``'none'`` cases) is randomised,
so "no effect" never means "ideal valve".  The valve of the data has a real
stem time constant (``tau`` 0.1-0.5 s), the fitter's valve is quasi-static:
a deliberate small model mismatch.

Examples
--------
>>> rec = make_recording("dead_time", seed=3, n=300)
>>> len(rec), rec.dt
(300, 1.0)
>>> case = make_case("overflow", seed=3, n=300)
>>> case.effect, sorted(case.truth)[:2]
('overflow', ['overflow.L_max', 'process.area'])
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..control import PIParams
from ..params import (
    DeadTime,
    Leak,
    ModelParams,
    OscillatingDisturbance,
    Overflow,
    SensorLag,
    SlipJump,
    TankParams,
    TankShape,
    ValveCharacteristic,
    ValveParams,
)
from .recording import Recording

__all__ = ["SUITE_EFFECTS", "SyntheticCase", "make_case", "make_recording", "concealed_suite",
           "simulate_closed_loop", "write_csv"]

#: Effects of the concealed-effect suite (plus ``'none'``).
SUITE_EFFECTS = ("slip_jump", "valve_characteristic", "dead_time", "overflow", "leak",
                 "sensor_lag", "oscillating_disturbance", "tank_shape")


@dataclass
class SyntheticCase:
    """One generated recording and its ground truth.

    Attributes
    ----------
    name : str
    effect : str, the effect switched on, or ``'none'``
    recording : Recording
    truth : dict, true parameter values by core field name (units of
        :mod:`valve_gym.params`: m, m^3/s, s, fraction of stroke)
    params : ModelParams, the data-generating model
    """

    name: str
    effect: str
    recording: Recording
    truth: dict[str, float]
    params: ModelParams


def simulate_closed_loop(params: ModelParams, sp, pi: PIParams, noise_std: float, rng,
                         n_sub: int, level0: float, d=None):
    """PI loop on the plant, one controller sample at a time (:func:`valve_gym.loop.run_pi_loop`).

    Parameters
    ----------
    params : ModelParams (scalars)
    sp : (T,) set point [m]
    pi : PIParams, ``Ts`` = controller sample [s]
    noise_std : float, std of the additive measurement noise [m]
    rng : numpy Generator (noise)
    n_sub : int, Euler steps per sample (``params.dt * n_sub == pi.Ts``)
    level0 : float, initial level [m] (the loop starts at rest there)
    d : (T,) array, optional unmeasured inflow disturbance [m^3/s]

    Returns
    -------
    op : (T,) controller output 0..1 over sample ``k``; pv : (T,) measured level [m],
    level : (T,) true level [m], stem : (T,) stem position 0..1, each at the end of sample ``k``
    """
    from ..loop import run_pi_loop
    from ..plant import Plant

    sp = np.asarray(sp, float)
    plant = Plant(params, 1, scan_s=pi.Ts)
    if plant.n_sub != n_sub:
        raise ValueError(f"n_sub = {n_sub} Euler steps per sample, but pi.Ts / params.dt = {plant.n_sub}")
    start = plant.reset(level=level0)
    run = run_pi_loop(plant, start, sp[:, None], pi, noise_std, rng, None if d is None else np.asarray(d, float))
    return run.op[:, 0], run.pv[1:, 0], run.level[1:, 0], run.stem[1:, 0]


def _sp_profile(rng, T, dt, lo, hi, hold=(150.0, 400.0)):
    sp = np.empty(T)
    k = 0
    cur = rng.uniform(lo, hi)
    while k < T:
        m = int(rng.uniform(*hold) / dt)
        sp[k:k + m] = cur
        k += m
        nxt = rng.uniform(lo, hi)
        while abs(nxt - cur) < 0.15 * (hi - lo):
            nxt = rng.uniform(lo, hi)
        cur = nxt
    return sp


def make_case(effect: str = "none", seed: int = 0, n: int = 1800, dt: float = 1.0,
              noise: float = 0.004, magnitude: float = 1.0,
              load_disturbance: float = 0.0, friction: float = 1.0) -> SyntheticCase:
    """Generate one closed-loop level recording with ``effect`` concealed in it.

    Parameters
    ----------
    effect : str
        ``'none'`` or one of :data:`SUITE_EFFECTS`.
    seed : int
        Seed of everything random (plant, valve, tuning, set points, noise).
    n : int
        Samples (controller sample ``dt`` seconds).
    noise : float
        Measurement noise std [m] (the level moves between about 0.5 and 1.6 m).
    magnitude : float
        Scales the effect's strength (1 = the suite's default range).
    load_disturbance : float
        Std of a slowly varying unmeasured inflow, as a fraction of the mean
        inflow (0 = none).
    friction : float
        Scales the valve's drawn dead band and friction band (``e_dead``,
        ``z_max``; 0 = a frictionless valve); the random draws do not change.

    Returns
    -------
    SyntheticCase
    """
    if effect != "none" and effect not in SUITE_EFFECTS:
        raise ValueError(f"unknown effect {effect!r}; choose 'none' or one of {SUITE_EFFECTS}")
    rng = np.random.default_rng(seed)
    area = rng.uniform(0.15, 0.3)
    q_max = rng.uniform(0.008, 0.014)
    k_out = rng.uniform(0.004, 0.006)
    tau_v = rng.uniform(0.1, 0.5)
    e_dead = rng.uniform(0.001, 0.006)
    z_max = rng.uniform(0.0, 0.03)
    if not (np.isfinite(friction) and friction >= 0):
        raise ValueError(f"friction must be a finite number >= 0 (a scale of the drawn friction), "
                         f"got {friction!r}")
    e_dead, z_max = e_dead * friction, z_max * friction
    n_sub = int(np.ceil(dt / min(tau_v, 0.1)))
    dte = dt / n_sub
    tank = TankParams(area=area, q_max=q_max, k_out=k_out, level0=1.0)
    valve = ValveParams(tau=tau_v, v_max=rng.uniform(0.2, 1.0), e_dead=e_dead, z_max=z_max)
    p = ModelParams(valve=valve, process=tank, process_kind="tank", dt=dte)
    lo = 0.5
    mag = float(magnitude)
    truth = {"process.area": area, "process.q_max": q_max, "process.k_out": k_out,
             "valve.e_dead": e_dead, "valve.z_max": z_max, "valve.tau": tau_v}
    p, hi = _conceal(effect, p, tank, truth, rng, mag, dt, q_max, k_out, tau_v)
    pi = _pi_tuning(rng, area, q_max, k_out, dt)
    sp = _sp_profile(rng, n, dt, lo, hi)
    d = _load_disturbance(rng, n, dt, load_disturbance, k_out)
    op, pv, lev, stem = simulate_closed_loop(p, sp, pi, noise, rng, n_sub, level0=float(sp[0]), d=d)
    t = np.arange(n) * dt
    rec = Recording(t=t, op=np.clip(op, 0, 1), pv=pv, sp=sp, dt=dt,
                    name=f"{effect}_{seed}", op_range=(0.0, 1.0),
                    columns={"t": "t", "op": "op", "pv": "pv", "sp": "sp"})
    return SyntheticCase(name=f"{effect}_{seed}", effect=effect, recording=rec, truth=truth,
                         params=p)


def _conceal(effect: str, p: ModelParams, tank: TankParams, truth: dict[str, float], rng, mag: float,
             dt: float, q_max: float, k_out: float, tau_v: float) -> tuple[ModelParams, float]:
    """Add ``effect`` to the model ``p`` of ``tank`` (its true parameters go into ``truth``).

    Returns the model and the highest set point [m].
    """
    hi = 1.5
    if effect == "slip_jump":
        S = rng.uniform(0.01, 0.025) * mag
        J = S * rng.uniform(0.6, 1.6)
        p = replace(p, slip_jump=SlipJump(S=S, J=J, tau_p=tau_v))
        truth.update({"slip_jump.S": S, "slip_jump.J": J})
        for k_ in ("valve.e_dead", "valve.z_max"):
            truth.pop(k_)
    elif effect == "valve_characteristic":
        if rng.random() < 0.6:
            R = rng.uniform(15, 50) ** mag
            p = replace(p, valve_characteristic=ValveCharacteristic("equal_percentage", R=R))
            truth["valve_characteristic.R"] = R
            # same flow at 60 % opening as the linear valve
            q_new = q_max * 0.6 / R ** (0.6 - 1.0)
            p = replace(p, process=replace(tank, q_max=q_new))
        else:
            p = replace(p, valve_characteristic=ValveCharacteristic("quick_opening"))
            truth["valve_characteristic.quick_opening"] = 1.0
            q_new = q_max * 0.6 / float(np.sqrt(0.6))
            p = replace(p, process=replace(tank, q_max=q_new))
        truth["process.q_max"] = q_new
    elif effect == "dead_time":
        theta = rng.uniform(3.0, 8.0) * mag * dt
        p = replace(p, dead_time=DeadTime(theta=theta))
        truth["dead_time.theta"] = theta
    elif effect == "overflow":
        L_max = rng.uniform(1.25, 1.4)
        p = replace(p, overflow=Overflow(L_max=L_max))
        truth["overflow.L_max"] = L_max
        hi = 1.6
    elif effect == "leak":
        # extra outflow: 10-25 % of the mean inflow
        q_leak = rng.uniform(0.10, 0.25) * mag * k_out * 1.0
        p = replace(p, leak=Leak(q_leak=q_leak))
        truth["leak.q_leak"] = q_leak
    elif effect == "sensor_lag":
        tau_s = rng.uniform(4.0, 12.0) * mag * dt
        p = replace(p, sensor_lag=SensorLag(tau_s=tau_s))
        truth["sensor_lag.tau_s"] = tau_s
    elif effect == "oscillating_disturbance":
        amp = rng.uniform(0.06, 0.12) * mag * k_out
        period = rng.uniform(60.0, 200.0) * dt
        phase = rng.uniform(0, 2 * np.pi)
        p = replace(p, oscillating_disturbance=OscillatingDisturbance(amp, period, phase))
        truth.update({"oscillating_disturbance.amplitude": amp,
                      "oscillating_disturbance.period": period,
                      "oscillating_disturbance.phase": phase})
    elif effect == "tank_shape":
        # a vessel whose cross-section grows as L^e from its bottom, e 1-2 (a wedge or trough to an upright
        # cone), with the drawn area at the nominal 1 m: A/area = (L/1 m)^e = 1 + e x + e (e-1)/2 x^2 + ...,
        # exact in the block's quadratic for e = 1 and 2
        e = 1.0 + rng.uniform(0.0, 1.0) * mag
        taper, curvature = e, e * (e - 1.0) / 2.0
        p = replace(p, tank_shape=TankShape(taper=taper, curvature=curvature, L_ref=1.0))
        truth.update({"tank_shape.taper": taper, "tank_shape.curvature": curvature})
    return p, hi


def _pi_tuning(rng, area: float, q_max: float, k_out: float, dt: float) -> PIParams:
    """PI tuning of the case: lambda tuning on the linearised tank at 1 m (+-30 %)."""
    tau_p = 2 * area * 1.0 / k_out
    gain = q_max * 2 * 1.0 / k_out          # dL/df at 1 m
    lam = tau_p * rng.uniform(0.4, 0.9)
    return PIParams(Kc=float(tau_p / (gain * lam) * rng.uniform(0.7, 1.3)),
                    Ti=float(tau_p * rng.uniform(0.6, 1.2)), Ts=dt)


def _load_disturbance(rng, n: int, dt: float, load_disturbance: float, k_out: float) -> np.ndarray | None:
    """Slowly varying unmeasured inflow (n,) [m^3/s] (first order, 100 s), or None."""
    d = None
    if load_disturbance > 0:
        from ..signals import ou_sequence
        d = load_disturbance * k_out * ou_sequence(rng.normal(size=n), np.exp(-dt / 100.0))
    return d


def make_recording(effect: str = "none", seed: int = 0, n: int = 1800, **kw) -> Recording:
    """The :class:`Recording` of :func:`make_case` (same arguments)."""
    return make_case(effect, seed=seed, n=n, **kw).recording


def concealed_suite(n_per_effect: int = 6, n_none: int = 12, seed: int = 0, n: int = 1800,
                    effects=SUITE_EFFECTS, **kw) -> list[SyntheticCase]:
    """The concealed-effect suite: ``n_per_effect`` cases per effect plus ``n_none`` base cases.

    Seeds are ``seed * 1000 + i``; every case differs in plant, valve,
    tuning, set points, effect magnitude and noise.
    """
    cases = []
    i = 0
    for e in ("none",) + tuple(effects):
        m = n_none if e == "none" else n_per_effect
        for _ in range(m):
            cases.append(make_case(e, seed=seed * 1000 + i, n=n, **kw))
            i += 1
    return cases


def write_csv(rec: Recording, path, percent: bool = True) -> None:
    """Write a recording as CSV (``t_s, OP, PV, SP``; OP in percent if ``percent``)."""
    import csv
    import io

    from .._io import write_atomic
    f = io.StringIO(newline="")
    w = csv.writer(f)
    cols = ["t_s", "OP", "PV"] + (["SP"] if rec.sp is not None else [])
    w.writerow(cols)
    op = rec.op * (100.0 if percent else 1.0)
    for k in range(len(rec)):
        row = [f"{rec.t[k]:.6g}", f"{op[k]:.8g}", f"{rec.pv[k]:.8g}"]
        if rec.sp is not None:
            row.append(f"{rec.sp[k]:.8g}")
        w.writerow(row)
    text = f.getvalue()
    write_atomic(path, lambda fh: fh.write(text.encode("utf-8")))
