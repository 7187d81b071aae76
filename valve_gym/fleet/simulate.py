"""A simulated plant fleet: level loops at a constant set point, some behind sticky valves.

Test and benchmark data for the fleet mode.  Every loop is the package's level
loop (:func:`valve_gym.diagnosis.synthetic.simulate_closed_loop`: Torricelli
tank, the one physics core, a lambda-tuned PI on a noisy level) held at a
constant set point under a slowly varying load, as loops run between
set-point changes, which is where stiction limit cycles live.  Each loop is
one of four kinds (plant, valve, tuning and noise drawn from its seed):

``healthy``
    the paper's valve with a small dead band (``e_dead`` 0.1-0.3 % of stroke).
``sticky``
    Choudhury's slip-jump valve, ``S`` 1-5 % of stroke, ``J`` 0.5-1.0 ``S``.
``severe``
    the same with ``S`` 5-10 % of stroke.
``disturbance``
    a healthy valve and an oscillating inflow (period 60-200 s): the loop
    oscillates, the valve is not the cause.

Examples
--------
>>> loop = simulate_loop("sticky", seed=1, n=600)
>>> loop.kind, len(loop.recording), 0.01 <= loop.S <= 0.05
('sticky', 600, True)
"""
from __future__ import annotations

import os
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ..control import PIParams
from ..diagnosis.recording import Recording
from ..params import ModelParams, OscillatingDisturbance, SlipJump, TankParams, ValveParams
from ..signals import ou_sequence

__all__ = ["KINDS", "DEFAULT_MIX", "SimulatedLoop", "simulate_loop", "fleet_kinds", "write_fleet"]

#: Kinds of simulated loops.
KINDS = ("healthy", "sticky", "severe", "disturbance")
#: Default share of each kind in a fleet (20-30 % of a plant's loops oscillate).
DEFAULT_MIX = {"healthy": 0.72, "sticky": 0.15, "severe": 0.05, "disturbance": 0.08}


class SimulatedLoop(NamedTuple):
    """One simulated loop and its truth.

    Attributes
    ----------
    name : str
    kind : str, one of :data:`KINDS`
    S, J : float, slip-jump stick band and jump [fraction of stroke] (0 without slip-jump friction)
    recording : Recording, OP 0..1, PV and SP in m, sample time ``dt`` s
    """

    name: str
    kind: str
    S: float
    J: float
    recording: Recording


def simulate_loop(kind: str, seed: int, n: int = 900, dt: float = 1.0, noise: float = 0.002,
                  name: str | None = None) -> SimulatedLoop:
    """Simulate one loop of kind ``kind`` for ``n`` samples of ``dt`` seconds.

    Parameters
    ----------
    kind : str, one of :data:`KINDS`
    seed : int, seed of the plant, valve, tuning, load and noise
    n : int, samples
    dt : float, controller scan [s]
    noise : float, measurement noise std [m]
    name : str, optional, the loop's name (default ``f"{kind}_{seed}"``)

    Returns
    -------
    SimulatedLoop
    """
    from ..diagnosis.synthetic import simulate_closed_loop

    if kind not in KINDS:
        raise ValueError(f"unknown loop kind {kind!r}; choose one of {', '.join(KINDS)}")
    rng = np.random.default_rng(seed)
    area, q_max, k_out = rng.uniform(0.15, 0.3), rng.uniform(0.008, 0.014), rng.uniform(0.004, 0.006)
    tau_v = rng.uniform(0.1, 0.5)
    n_sub = int(np.ceil(dt / min(tau_v, 0.1)))
    tank = TankParams(area=area, q_max=q_max, k_out=k_out, level0=1.0)
    valve = ValveParams(tau=tau_v, v_max=rng.uniform(0.2, 1.0), e_dead=rng.uniform(0.001, 0.003), z_max=0.0)
    p = ModelParams(valve=valve, process=tank, process_kind="tank", dt=dt / n_sub)
    S = J = 0.0
    if kind in ("sticky", "severe"):
        S = rng.uniform(0.01, 0.05) if kind == "sticky" else rng.uniform(0.05, 0.10)
        J = S * rng.uniform(0.5, 1.0)
        p = replace(p, slip_jump=SlipJump(S=S, J=J, tau_p=tau_v))
    elif kind == "disturbance":
        p = replace(p, oscillating_disturbance=OscillatingDisturbance(
            rng.uniform(0.08, 0.15) * k_out, rng.uniform(60.0, 200.0), rng.uniform(0, 2 * np.pi)))
    tau_p = 2 * area / k_out
    gain = 2 * q_max / k_out
    lam = tau_p * rng.uniform(0.3, 0.6)
    pi = PIParams(Kc=float(tau_p / (gain * lam)), Ti=float(tau_p * rng.uniform(0.3, 0.6)), Ts=dt)
    sp = np.full(n, rng.uniform(0.7, 1.3))
    d = 0.01 * k_out * ou_sequence(rng.normal(size=n), np.exp(-dt / 200.0))
    op, pv, _, _ = simulate_closed_loop(p, sp, pi, noise, rng, n_sub, level0=float(sp[0]), d=d)
    nm = name or f"{kind}_{seed}"
    rec = Recording(t=np.arange(n) * dt, op=np.clip(op, 0, 1), pv=pv, sp=sp, dt=dt, name=nm,
                    columns={"t": "t", "op": "op", "pv": "pv", "sp": "sp"})
    return SimulatedLoop(nm, kind, float(S), float(J), rec)


def fleet_kinds(n_loops: int, seed: int = 0, mix: dict[str, float] | None = None) -> list[str]:
    """The kind of each of ``n_loops`` loops, drawn with shares ``mix`` (default :data:`DEFAULT_MIX`)."""
    mix = dict(DEFAULT_MIX if mix is None else mix)
    kinds = list(mix)
    pr = np.array([mix[k] for k in kinds], float)
    return [kinds[i] for i in np.random.default_rng(seed).choice(len(kinds), size=n_loops, p=pr / pr.sum())]


def write_fleet(folder: str, n_loops: int, seed: int = 0, n: int = 900, dt: float = 1.0,
                mix: dict[str, float] | None = None) -> list[SimulatedLoop]:
    """Write ``n_loops`` simulated loops as ``folder/<kind>_<i>.csv`` (``t_s, OP`` in %, ``PV, SP``).

    Returns the loops without their recordings' data kept (``recording`` is None-free but small
    loops only; for large fleets use :func:`simulate_loop` one at a time).
    """
    from ..diagnosis.synthetic import write_csv

    os.makedirs(folder, exist_ok=True)
    out = []
    for i, kind in enumerate(fleet_kinds(n_loops, seed, mix)):
        loop = simulate_loop(kind, seed=seed * 100_000 + i, n=n, dt=dt, name=f"L{i:05d}")
        write_csv(loop.recording, os.path.join(folder, f"{loop.name}.csv"))
        out.append(loop._replace(recording=None))  # type: ignore[arg-type]
    return out
