"""PI with a dead zone in the integral: stop integrating while the error is inside a band.

Law (PI with an error dead zone on the integral action; Farenzena &
Trierweiler 2012 [1]_, Hägglund's and Åström's "conditional integration"
[2]_)::

    I_k = I_{k-1} + Kc Ts/Ti e_k    if |e_k| > band
    I_k = I_{k-1}                   otherwise          (proportional action stays)

A sticky valve under PI cycles because the integral keeps winding the output
through the stick band while the error is small. Inside the band the integral
holds, so a stuck valve whose stem is close enough is left alone.

Band from the stiction estimate ``S`` and the noise (default)::

    band = max( S / (2 Kc), 3 noise )

``S/(2 Kc)`` is the error amplitude of the stick-slip cycle a PI sustains with
a valve of band ``S`` (derived: PV triangle amplitude ``S/(2 Kc)``, DOMAIN O8):
the integral stops inside the cycle the PI would otherwise run. ``3 noise``
keeps measurement noise from switching the integral on and off (three standard
deviations of the level noise). A steady offset up to ``band`` remains: the
price of a quiet valve, reported by the benchmark's offset.

References
----------
.. [1] M. Farenzena, J.O. Trierweiler (2012): PI with an error dead zone as a
   stiction remedy, as listed among the controller-side fixes in the
   stiction-compensation literature (full title not checked here).
.. [2] K.J. Åström, T. Hägglund, "Advanced PID control", ISA, 2006, sec. 3.5.
"""
from __future__ import annotations

import numpy as np

from .block import Setting
from .compensator import NOISE_SETTING, S_SETTING, Compensator, as_setting
from .pi import PIBlockState

__all__ = ["IntegralFreeze"]


class IntegralFreeze(Compensator):
    """PI whose integral holds while ``|sp - pv| <= band``.

    Parameters
    ----------
    **settings
        PI settings, ``S`` [-], ``noise`` [m] and optionally ``band`` [m].

    Examples
    --------
    >>> f = IntegralFreeze(S=0.02, Kc=2.0, Ti=10.0, noise=0.0)   # band = 0.02/4 = 5 mm
    >>> f.settings["band"]
    0.005
    >>> f.reset(1.0, 1.0, 0.5)
    >>> f.step(1.0, 0.997), float(f.state.integral[0])    # 3 mm inside the band: P only
    (0.506, 0.5)
    >>> round(f.step(1.0, 0.99), 4)                 # 1 cm: integrates again
    0.522
    """

    name = "integral_freeze"
    OWN_SETTINGS = (
        S_SETTING,
        NOISE_SETTING,
        Setting("band", "m", None, 0.0, 10.0, "error band without integration; default max(S/(2 Kc), 3 noise)",
                per_loop=True),
    )

    def _rules(self, s: dict) -> dict:
        if s["band"] is None:
            s["band"] = as_setting(np.maximum(s["S"] / (2.0 * self.pi.Kc), 3.0 * s["noise"]))
        return s

    def initial_state(self, sp, pv, op) -> PIBlockState:
        """Bumpless start (the PI's memory)."""
        return self.pi.initial_state(sp, pv, op)

    def advance(self, state: PIBlockState, sp, pv):
        """One scan: ``(state, sp, pv) -> (state, op)``."""
        integrate = np.abs(np.asarray(sp, float) - np.asarray(pv, float)) > self.p["band"]
        return self.pi.finish(self.pi.propose(state, sp, pv, integrate))
