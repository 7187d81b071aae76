"""Stand-ins used only while the plant stepper and the friction registry are not importable.

:class:`CorePlant` is the plant contract (``reset(level)``, ``step(op, d)``)
on :mod:`valve_gym.core`; :func:`core_valve_model` sizes the two friction
models the core already has from ``(S, J)``. Both are replaced by
:class:`valve_gym.plant.Plant` and :func:`valve_gym.friction.valve_model`
where those exist (see :mod:`agents.bench.runner`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from valve_gym import core
from valve_gym.params import ModelParams, SlipJump, ValveParams

__all__ = ["CorePlant", "PlantOutput", "core_valve_model"]


class PlantOutput(NamedTuple):
    """One scan's outputs, each ``(n,)``: level ``pv`` [m], ``stem`` 0..1, applied input ``op`` 0..1."""

    pv: np.ndarray
    stem: np.ndarray
    op: np.ndarray


def core_valve_model(model: str, S, J) -> ModelParams:
    """Default tank with ``model`` friction of stick band ``S`` and slip jump ``J`` (fractions of stroke)."""
    S = np.asarray(S, float)
    J = np.asarray(J, float)
    if model == "none":
        return ModelParams(valve=ValveParams(e_dead=0.0, z_max=0.0))
    if model == "choudhury":
        return ModelParams(valve=ValveParams(e_dead=0.0, z_max=0.0)).with_effect("slip_jump", SlipJump(S=S, J=J))
    if model == "riihilahti":
        return ModelParams(valve=ValveParams(e_dead=0.5 * S, z_max=0.0))
    raise ValueError(f"friction model {model!r} needs valve_gym.friction.valve_model, which is not available; "
                     "use 'riihilahti', 'choudhury' or 'none'")


class CorePlant:
    """``n`` batched tank loops on :func:`valve_gym.core.step` with the plant contract's interface."""

    def __init__(self, params: ModelParams, n: int, scan_s: float = 1.0):
        self.params, self.n, self.scan_s = params, int(n), float(scan_s)
        self.n_sub = max(1, int(round(self.scan_s / float(params.dt))))
        self.state = core.initial_state(params, self.n)
        self.t = 0.0

    def reset(self, level=1.0) -> PlantOutput:
        """Steady state at ``level`` [m] (scalar or ``(n,)``), valve at the steady input."""
        self.state = core.initial_state(self.params, self.n, level=level)
        self.t = 0.0
        h = np.clip(self.state.h, 0.0, 1.0)
        return PlantOutput(self.state.level.copy(), h, self.state.u_prev.copy())

    def step(self, op, d=None) -> PlantOutput:
        """Hold ``op`` (n,) over one scan with extra inflow ``d`` (n,) [m^3/s]."""
        self.state, y = core.step(self.state, op, self.params, d=d, n_sub=self.n_sub)
        self.t += self.scan_s
        return PlantOutput(np.asarray(y, float), np.clip(self.state.h, 0.0, 1.0),
                           np.clip(np.asarray(op, float), 0.0, 1.0))


class FallbackPI:
    """Positional PI with anti-windup by output tracking (the block contract), SIMC defaults."""

    name = "pi"

    def __init__(self, Kc: float = 1.8868, Ti: float = 42.4, detune: float = 1.0, scan_s: float = 1.0):
        self.Kc, self.Ti, self.scan_s = Kc * detune, Ti, scan_s
        self.settings = {"Kc": Kc, "Ti": Ti, "detune": detune, "scan_s": scan_s}
        self.integral = np.zeros(1)

    def reset(self, sp, pv, op) -> None:
        """Bumpless start from the applied input ``op``."""
        self.integral = np.asarray(op, float) - self.Kc * (np.asarray(sp, float) - np.asarray(pv, float))

    def step(self, sp, pv) -> np.ndarray:
        """One scan."""
        e = np.asarray(sp, float) - np.asarray(pv, float)
        self.integral = self.integral + self.Kc * self.scan_s / self.Ti * e
        v = self.Kc * e + self.integral
        u = np.clip(v, 0.0, 1.0)
        self.integral = self.integral + (u - v)
        return u
