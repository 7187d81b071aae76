"""What the stiction compensators share: the wrapped PI, ``S`` and the noise-robust direction.

A compensator is a :class:`~valve_gym.agents.controllers.pi.PIBlock` plus a law that adds to
its output (composition: the PI is an attribute, :attr:`Compensator.pi`). Its
settings are the PI's (``Kc``, ``Ti``, ``detune``, ``scan_s``, ``op_lo``,
``op_hi``) plus the stiction estimate ``S`` (stick band plus dead band,
fraction of the stroke, Choudhury et al. 2005) and the measurement noise
``noise`` [m] (standard deviation of the level measurement), from which each
compensator sets its own parameters by its paper's rule.

Direction of the controller output, robust to noise
---------------------------------------------------
Compensators that push "in the direction the controller output moves" read
that direction from the **integral part** ``I`` of the PI, not from the raw
output: ``Kc (e_k - e_{k-1})`` follows every sample of measurement noise,
while ``I`` moves by ``Kc Ts/Ti e`` per scan and changes direction only when
the error changes sign (Hägglund 2002 uses the integral part for the
knocker's pulse direction for this reason). :func:`integral_direction` adds a
hysteresis ``hyst``: the direction flips only once ``I`` has come back by more
than ``hyst`` from its extreme since the last flip. White noise of standard
deviation ``noise`` on the level makes ``I`` random-walk with a standard
deviation of ``Kc noise sqrt(Ts/Ti)`` over one integral time ``Ti``; the
default ``hyst`` is three times that (Notes of :func:`default_hysteresis`).
"""
from __future__ import annotations

import numpy as np

from .block import FunctionBlock, Setting, fmt
from .pi import PI_SETTINGS, PIBlock, resolve_pi

__all__ = ["Compensator", "S_SETTING", "NOISE_SETTING", "J_SETTING", "HYST_SETTING", "integral_direction",
           "default_hysteresis", "as_setting", "check_slip", "slip_and_hysteresis"]

#: The stiction estimate every compensator takes.
S_SETTING = Setting("S", "-", 0.02, 0.0, 0.5,
                    "stiction estimate: stick band plus dead band, fraction of stroke (Choudhury's S)",
                    per_loop=True)
#: Measurement noise on the level, for noise-robust rules.
NOISE_SETTING = Setting("noise", "m", 0.002, 0.0, 1.0, "standard deviation of the level measurement noise",
                        per_loop=True)
#: The slip-jump estimate of the compensators that move the valve by it (default S/2, see
#: :func:`slip_and_hysteresis`).
J_SETTING = Setting("J", "-", None, 0.0, 0.5, "slip-jump estimate, fraction of stroke (<= S); default S/2",
                    per_loop=True)
#: Hysteresis on the PI's integral part that noise does not cross (default :func:`default_hysteresis`).
HYST_SETTING = Setting("hyst", "-", None, 0.0, 1.0, "hysteresis on the integral part; default 3 Kc noise sqrt(Ts/Ti)",
                       per_loop=True)


def as_setting(x) -> float | np.ndarray:
    """A rule's result as a float, or a float array when a per-loop setting made it one."""
    return float(x) if np.ndim(x) == 0 else np.asarray(x, dtype=np.float64)


def check_slip(block: str, s: dict) -> None:
    """``J <= S`` (Choudhury's model without overshoot), with a message naming both."""
    if np.any(np.asarray(s["J"]) > np.asarray(s["S"])):
        raise ValueError(f"{block}: settings need J <= S (slip no larger than the band), "
                         f"got S = {fmt(s['S'])}, J = {fmt(s['J'])}")


def slip_and_hysteresis(block: str, pi, s: dict) -> dict:
    """Fill the defaults of :data:`J_SETTING` (``S/2``) and :data:`HYST_SETTING` in settings ``s``.

    Checks ``J <= S`` (:func:`check_slip`); ``pi`` is the block's PI (its ``Kc``, ``Ti``).
    """
    s["J"] = s["S"] / 2.0 if s["J"] is None else s["J"]
    check_slip(block, s)
    if s["hyst"] is None:
        s["hyst"] = default_hysteresis(pi.Kc, pi.Ti, s["scan_s"], s["noise"])
    return s


def default_hysteresis(Kc, Ti, scan_s: float, noise) -> float | np.ndarray:
    """Hysteresis on the integral part that white measurement noise does not cross.

    Notes
    -----
    ``hyst = 3 Kc noise sqrt(Ts/Ti)``: with white noise of standard deviation
    ``noise`` on the error, ``I`` takes steps ``Kc Ts/Ti noise`` per scan and
    wanders by ``Kc noise sqrt(Ts/Ti)`` (one standard deviation) over ``Ti/Ts``
    scans. For the default loop (Kc 1.89 /m, Ti 42.4 s, 2 mm) it is 0.0017,
    about a tenth of a 2 % stiction band.

    Examples
    --------
    >>> round(default_hysteresis(1.89, 42.4, 1.0, 0.002), 5)
    0.00174
    """
    with np.errstate(over="ignore", divide="ignore"):   # an absurd Ti gives inf: refused by the range check
        return as_setting(3.0 * Kc * noise * np.sqrt(scan_s / np.asarray(Ti)))


def integral_direction(d: np.ndarray, i_ext: np.ndarray, integral: np.ndarray,
                       hyst: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Direction of the integral part with hysteresis (a peak-detecting relay).

    Parameters
    ----------
    d : (n,) array of -1, 0, 1, the direction so far (0: not yet known)
    i_ext : (n,) array, extreme of ``I`` since the last flip (its start for ``d = 0``)
    integral : (n,) array, integral part now
    hyst : float, how far ``I`` must come back from its extreme to flip

    Returns
    -------
    d, i_ext : (n,) arrays, updated
    flipped : (n,) bool array, True where the direction changed this scan

    Examples
    --------
    >>> d, ext = np.zeros(1), np.zeros(1)
    >>> for i in [0.1, 0.3, 0.27, 0.2]:
    ...     d, ext, f = integral_direction(d, ext, np.array([i]), 0.05)
    ...     print(int(d[0]), bool(f[0]))
    1 True
    1 False
    1 False
    -1 True
    """
    ext = np.where(d > 0, np.maximum(i_ext, integral), np.where(d < 0, np.minimum(i_ext, integral), i_ext))
    up = (d <= 0) & (integral > ext + hyst)
    down = (d >= 0) & (integral < ext - hyst)
    new_d = np.where(up, 1.0, np.where(down, -1.0, d))
    flipped = up | down
    return new_d, np.where(flipped, integral, ext), flipped


class Compensator(FunctionBlock):
    """Base of the compensators: settings = PI settings + ``S`` + own ones; holds the PI.

    Attributes
    ----------
    pi : PIBlock, the wrapped PI (its settings are this block's PI settings)
    """

    OWN_SETTINGS: tuple[Setting, ...] = ()

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        cls.SETTINGS = PI_SETTINGS + cls.OWN_SETTINGS

    def _resolve(self, settings: dict) -> dict:
        s = resolve_pi(self.name, settings)
        self.pi = PIBlock(**{k.name: s[k.name] for k in PI_SETTINGS if k.name != "action"})   # acts on what the
        # block hands it: FunctionBlock applies the action once, before initial_state and advance
        return self._rules(s)

    def _rules(self, s: dict) -> dict:
        """Fill the paper-rule defaults (settings still None)."""
        return s
