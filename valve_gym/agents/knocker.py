"""PI + knocker for RL code: SB3's ``predict`` over the ``"knocker"`` block.

The law (Hägglund 2002: pulses of amplitude ``a``, width ``tau_k``, every
``h_k``, in the direction of the change of the PI's integral part) and the
rule for its parameters from the stiction estimate ``S`` are documented in
:mod:`valve_gym.agents.controllers.knocker`; :class:`KnockerController` gives that
block the batched ``predict`` of :mod:`valve_gym.agents.base`. New code uses
``load_controller("knocker", S=...)`` directly.
"""
from __future__ import annotations

from .base import BlockPolicy
from .controllers.knocker import Knocker
from .controllers.registry import load_controller
from .pi import PIController

__all__ = ["KnockerController", "KNOCKER_DEFAULTS"]

_DEFAULT = load_controller("knocker").settings
#: Default knocker parameters: the paper's rule at the default stiction estimate S = 0.02.
KNOCKER_DEFAULTS = {"a": _DEFAULT["a"], "tau_k": _DEFAULT["tau_k"], "h_k": _DEFAULT["h_k"]}


class KnockerController(BlockPolicy):
    """PI controller plus Hägglund's knocker pulses, with SB3's ``predict``.

    Parameters
    ----------
    pi : PIController, optional
        The PI whose tuning (``Kc``, ``Ti``, ``Ts``, limits) the knocker wraps
        (default: SIMC).
    a : float
        Pulse amplitude, fraction of the valve stroke (default ``S/2`` for
        ``S = 0.02``).
    tau_k : float
        Pulse width [s], a whole number of control periods.
    h_k : float
        Time between pulse starts [s], a whole number of periods, > ``tau_k``.
    name : str

    Examples
    --------
    >>> import numpy as np
    >>> k = KnockerController(a=0.05, tau_k=1.0, h_k=2.0)
    >>> obs = np.array([[0.9, 1.0, 0.1, 0.5]])
    >>> a0, s = k.predict(obs)     # first pulse: the integral part rose
    >>> a1, s = k.predict(obs, s)  # pulse over
    >>> round(float((a0[0, 0] + 1) / 2 - 0.5), 4)   # a + Kc Ts/Ti e = 0.05 + 1.89/42.4*0.1
    0.0544
    >>> round(float((a1[0, 0] + 1) / 2 - s.pi.op[0]), 4)
    0.0
    """

    def __init__(self, pi: PIController | None = None, a: float = KNOCKER_DEFAULTS["a"],
                 tau_k: float = KNOCKER_DEFAULTS["tau_k"], h_k: float = KNOCKER_DEFAULTS["h_k"],
                 name: str = "knocker"):
        self.pi = PIController() if pi is None else pi
        if not isinstance(self.pi, PIController):
            raise TypeError(f"KnockerController wraps a PIController, got {type(self.pi).__name__}")
        p = self.pi.params
        block = Knocker(Kc=p.Kc, Ti=p.Ti, scan_s=p.Ts, op_lo=p.u_lo, op_hi=p.u_hi, a=a, tau_k=tau_k, h_k=h_k)
        super().__init__(block, name=name)
        self.a, self.tau_k, self.h_k = block.settings["a"], block.settings["tau_k"], block.settings["h_k"]

    def __repr__(self) -> str:
        return f"KnockerController(pi={self.pi!r}, a={self.a:g}, tau_k={self.tau_k:g}, h_k={self.h_k:g})"
