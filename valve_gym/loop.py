"""The closed-loop runner of valve_gym: the PI law of :mod:`valve_gym.control` on a :class:`~valve_gym.plant.Plant`.

One scan is: measure (the plant's sensor output plus white noise), compute the PI output
(:func:`valve_gym.control.pi_step`, bumpless start from the stem at rest), hold it over the scan
(:meth:`valve_gym.plant.Plant.advance`, with the load inflow of that scan; the inputs are checked once, up
front).  The synthetic recordings
(:mod:`valve_gym.diagnosis.synthetic`, and through them the fleet simulator) and the teaching figures
(:func:`valve_gym.figures.closed_loop_pi`) run their loops with it.

Example
-------
>>> import numpy as np
>>> from valve_gym.control import PIParams
>>> from valve_gym.params import ModelParams
>>> from valve_gym.plant import Plant
>>> plant = Plant(ModelParams(), 1)
>>> start = plant.reset(level=1.0)
>>> run = run_closed_loop(plant, start, np.full((300, 1), 1.2), PIParams(Kc=1.0, Ti=30.0))
>>> run.op.shape, run.pv.shape, abs(float(run.level[-1, 0]) - 1.2) < 0.01
((300, 1), (301, 1), True)
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .control import PIParams, pi_init, pi_step
from .plant import Plant, PlantOutput

__all__ = ["LoopRun", "run_closed_loop"]


class LoopRun(NamedTuple):
    """The signals of a closed-loop run of ``T`` scans of ``n`` loops.

    op : (T, n), valve input applied over scan ``k`` (0..1)
    pv : (T + 1, n), measured level at the start of scan ``k`` (row ``T``: after the last scan) [m]
    level : (T + 1, n), true level of the measured tank at the same instants [m]
    stem : (T + 1, n), stem position at the same instants (0..1)
    """

    op: np.ndarray
    pv: np.ndarray
    level: np.ndarray
    stem: np.ndarray


def run_closed_loop(plant: Plant, start: PlantOutput, sp, pi: PIParams, noise_std: float = 0.0,
                    rng: np.random.Generator | None = None, d=None) -> LoopRun:
    """Run the PI loop on ``plant`` for ``T`` scans from the state ``start`` it is in.

    Parameters
    ----------
    plant : Plant, reset (and its ``scan_s`` equal to ``pi.Ts``)
    start : PlantOutput, what the plant shows now (e.g. the return of :meth:`Plant.reset`)
    sp : (T, n) array, set point of each scan [m]
    pi : PIParams, the controller (gains scalars or ``(n,)``)
    noise_std : float, std of the white measurement noise [m] (>= 0)
    rng : numpy Generator, the noise's (one ``standard_normal(n)`` draw per measurement, the first
        at the start); needed when ``noise_std > 0``
    d : (T, n) or (T,) array, optional, extra inflow of each scan [m^3/s]

    Returns
    -------
    LoopRun
    """
    sp = np.asarray(sp, float)
    T, n = sp.shape
    if abs(pi.Ts - plant.scan_s) > 1e-9 * plant.scan_s:
        raise ValueError(f"the PI's Ts = {pi.Ts} s differs from the plant's scan_s = {plant.scan_s} s")
    if noise_std > 0 and rng is None:
        raise ValueError("noise_std > 0 needs a random generator rng (np.random.default_rng(seed))")
    if n != plant.n:
        raise ValueError(f"sp has {n} column(s) but the plant runs {plant.n} loop(s)")
    if not np.isfinite(sp).all():
        raise ValueError("sp contains NaN or inf; pass finite set points")
    dd = None if d is None else np.asarray(d, float)
    if dd is not None and (dd.shape not in ((T,), (T, n)) or not np.isfinite(dd).all()):
        raise ValueError(f"d must be a finite (T,) or (T, n) = ({T}, {n}) array of inflows, got shape {dd.shape}")

    def measure(y):
        return y + noise_std * rng.standard_normal(n) if noise_std > 0 else y.copy()  # type: ignore[union-attr]

    op = np.empty((T, n))
    pv, level, stem = (np.empty((T + 1, n)) for _ in range(3))
    pv[0], level[0], stem[0] = measure(start.y), start.pv, start.stem
    ctl = pi_init(start.stem, sp[0] - pv[0])
    U, D = np.empty((1, n)), np.zeros((1, n))     # inputs checked above: the plant's unchecked advance
    for k in range(T):
        ctl, u = pi_step(ctl, sp[k] - pv[k], pi)
        op[k] = u
        np.clip(u, 0.0, 1.0, out=U[0])
        if dd is not None:
            D[0] = dd[k]
        Y, H, LV = plant.advance(U, D)
        pv[k + 1], level[k + 1], stem[k + 1] = measure(Y[0]), LV[0], H[0]
    return LoopRun(op=op, pv=pv, level=level, stem=stem)
