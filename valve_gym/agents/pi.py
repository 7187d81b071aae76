"""PI controller for RL code: SB3's ``predict`` over the ``"pi"`` block.

The control law is the PI function block :class:`valve_gym.agents.controllers.PIBlock`
(positional PI, output limits, anti-windup by output tracking, bumpless
start); :class:`PIController` only gives it the batched ``predict`` of
:mod:`valve_gym.agents.base` through :class:`valve_gym.agents.base.BlockPolicy`. New code uses
``load_controller("pi", ...)`` directly. The default tuning (SIMC for the
default tank, ``Kc = 1.89 1/m``, ``Ti = 42.4 s``) is documented in
:mod:`valve_gym.agents.controllers.tuning` and re-exported here.
"""
from __future__ import annotations

import numpy as np

from valve_gym.control import PIParams

from .base import BlockPolicy
from .controllers.pi import PIBlock
from .controllers.tuning import DEFAULT_TAU_C, PITuning, default_tuning, simc_pi, tank_model

__all__ = ["PIController", "PITuning", "simc_pi", "tank_model", "default_tuning", "DEFAULT_TAU_C"]


class PIController(BlockPolicy):
    """Batched PI level controller with SB3's ``predict`` (adapter over :class:`PIBlock`).

    Parameters
    ----------
    Kc : float, optional
        Gain [valve fraction per m of error]; default SIMC (:func:`default_tuning`).
    Ti : float, optional
        Integral time [s]; default SIMC.
    Ts : float
        Control period [s], the environment's (1 s).
    u_lo, u_hi : float
        Output limits (the valve range 0..1).
    name : str

    Notes
    -----
    ``u_k = sat(Kc e_k + I_k)``, ``I_k = I_{k-1} + Kc Ts/Ti e_k``, the
    integral tracking the limits; ``e = sp - y`` from the observation. The
    state is the block's :class:`valve_gym.agents.controllers.pi.PIBlockState`
    ``(integral, op)``; ``state=None`` (or ``episode_start``) starts from the
    observed last valve input, so the first output is that input plus one
    integral step (bumpless). Actions are ``2 u - 1`` (direct mode).

    Examples
    --------
    >>> import numpy as np
    >>> pi = PIController(Kc=1.0, Ti=10.0)
    >>> obs = np.array([[0.9, 1.0, 0.1, 0.5], [1.0, 1.0, 0.0, 0.3]], np.float32)
    >>> a, s = pi.predict(obs)
    >>> a.shape, a.dtype.name
    ((2, 1), 'float32')
    >>> np.round((a[:, 0] + 1) / 2, 3)   # 0.5 + 1*1/10*0.1, and unchanged
    array([0.51, 0.3 ], dtype=float32)
    """

    def __init__(self, Kc: float | None = None, Ti: float | None = None, Ts: float = 1.0,
                 u_lo: float = 0.0, u_hi: float = 1.0, name: str = "pi"):
        for nm, v in (("Kc", Kc), ("Ti", Ti), ("Ts", Ts)):
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer))):
                raise TypeError(f"PIController.{nm} must be a number, got {v!r}")
        block = PIBlock(Kc=Kc, Ti=Ti, scan_s=Ts, op_lo=u_lo, op_hi=u_hi)
        super().__init__(block, name=name)
        s = block.settings
        self.params = PIParams(Kc=s["Kc"], Ti=s["Ti"], Ts=s["scan_s"], u_lo=s["op_lo"], u_hi=s["op_hi"])

    @property
    def Kc(self) -> float:
        """Gain [1/m]."""
        return float(np.asarray(self.params.Kc).reshape(-1)[0])

    @property
    def Ti(self) -> float:
        """Integral time [s]."""
        return float(np.asarray(self.params.Ti).reshape(-1)[0])

    @property
    def Ts(self) -> float:
        """Control period [s]."""
        return self.params.Ts

    def __repr__(self) -> str:
        p = self.params
        return f"PIController(Kc={p.Kc:.4g}, Ti={p.Ti:.4g}, Ts={p.Ts:.4g})"
