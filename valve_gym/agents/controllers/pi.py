"""PI function block: the plant's level controller and the core of every compensator.

Positional PI with an explicit integral part, output limits and anti-windup by
output tracking (external reset), one scan per :meth:`PIBlock.step`::

    e_k = sp_k - pv_k
    I_k = I_{k-1} + Kc Ts/Ti e_k            (frozen where a dead zone says so)
    v_k = Kc e_k + I_k                      (PI output)
    u_k = sat(v_k + b_k)                    (b: what a compensator adds; 0 for plain PI)
    I_k <- u_k - b_k - Kc e_k               where sat() acted (the integral tracks
                                            the output actually applied)

``reset(sp, pv, op)`` sets ``I = op - Kc (sp - pv)``, so the first output is
``op + Kc Ts/Ti e`` (exactly ``op`` when ``e = 0``): bumpless. ``Kc`` is
positive; the ``action`` setting says which way the loop acts (below). The law
is :func:`valve_gym.control.pi_scan` / :func:`valve_gym.control.pi_track`,
the same as the environment's built-in PI.

Compensators contain a :class:`PIBlock` and call :meth:`PIBlock.propose`
(the PI's scan, not yet limited) then :meth:`PIBlock.finish` with what they
add; the PI's integral never integrates the compensation, only tracks the
limits.

Settings
--------
========  ======  ==========================================  ============
name      unit    meaning                                      default
========  ======  ==========================================  ============
Kc        1/m     gain (before ``detune``)                     SIMC, 1.89
Ti        s       integral time                                SIMC, 42.4
detune    -       factor on Kc (detuned PI, Pareto over Kc)    1.0
scan_s    s       scan time                                    1.0
op_lo     -       lower output limit                           0.0
op_hi     -       upper output limit                           1.0
action    -       +1 reverse, -1 direct acting (see below)     +1
========  ======  ==========================================  ============

``action``: the block works on ``action * (sp - pv)``. The default (+1, reverse acting) is for a loop where
opening the valve raises the measurement (the inflow valve of a level); a loop where it lowers it (a valve on
the outlet, a cooling valve, a vent) takes -1 with the same positive ``Kc``. Every block built on the PI takes
it, and behaves on a direct-acting loop as it does on the mirrored reverse-acting one.

The SIMC defaults are :func:`valve_gym.agents.controllers.tuning.default_tuning` for the
default tank at ``scan_s``.

References
----------
.. [1] K.J. Åström, T. Hägglund, "Advanced PID control", ISA, 2006, sec. 3.5
   (windup, tracking) and 13.5 (bumpless transfer).
.. [2] IEC 61131-3, Programmable controllers - Part 3: Programming languages
   (PID function block with tracking input).
"""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from valve_gym.control import pi_scan, pi_track

from .block import FunctionBlock, Setting
from .tuning import default_tuning

__all__ = ["PIBlock", "PIBlockState", "PIScan", "PI_SETTINGS", "check_action"]

#: Settings shared by the PI block and every compensator that wraps it.
PI_SETTINGS = (
    Setting("Kc", "1/m", None, 0.0, 1e4, "PI gain, positive whichever way the loop acts (see action); default SIMC "
            "for the default tank", lo_open=True, per_loop=True),
    Setting("Ti", "s", None, 0.0, 1e6, "integral time; default SIMC for the default tank", lo_open=True,
            per_loop=True),
    Setting("detune", "-", 1.0, 0.0, 100.0, "factor on Kc (detuned PI)", lo_open=True, per_loop=True),
    Setting("scan_s", "s", 1.0, 0.0, 3600.0, "scan time", lo_open=True),
    Setting("op_lo", "-", 0.0, 0.0, 1.0, "lower output limit, fraction of stroke"),
    Setting("op_hi", "-", 1.0, 0.0, 1.0, "upper output limit, fraction of stroke"),
    Setting("action", "-", 1.0, -1.0, 1.0, "controller action: +1 reverse (opening the valve raises pv, the default), "
            "-1 direct (opening it lowers pv: a valve on a tank's outlet, a cooling valve)", per_loop=True),
)


class PIBlockState(NamedTuple):
    """Memory of a :class:`PIBlock`, each field ``(n,)``.

    Attributes
    ----------
    integral : integral part ``I`` [output fraction]
    op : last output applied [0..1]
    """

    integral: np.ndarray
    op: np.ndarray


class PIScan(NamedTuple):
    """One PI scan before the limits (:meth:`PIBlock.propose`), each field ``(n,)``.

    Attributes
    ----------
    e : control error ``sp - pv`` [m]
    p : proportional part ``Kc e`` [output fraction]
    integral : integral part after this scan's integration [output fraction]
    v : PI output ``p + integral`` [output fraction], not limited
    """

    e: np.ndarray
    p: np.ndarray
    integral: np.ndarray
    v: np.ndarray


def check_action(block: str, action) -> None:
    """A ValueError unless ``action`` is +1 or -1 (one value, or one per loop)."""
    if isinstance(action, bool) or not np.all(np.abs(np.asarray(action, float)) == 1.0):
        raise ValueError(f"{block}: setting action must be +1 (reverse acting: opening the valve raises pv) or -1 "
                         f"(direct acting: opening it lowers pv), one value per loop if need be; got "
                         f"{np.ravel(action).tolist()}")


def resolve_pi(block: str, s: dict) -> dict:
    """Fill the SIMC defaults of ``Kc``, ``Ti`` and check the output limits."""
    if s["Kc"] is None or s["Ti"] is None:
        tun = default_tuning(Ts=s["scan_s"])
        s["Kc"] = tun.Kc if s["Kc"] is None else s["Kc"]
        s["Ti"] = tun.Ti if s["Ti"] is None else s["Ti"]
    check_action(block, s["action"])
    if not s["op_lo"] < s["op_hi"]:
        raise ValueError(f"{block}: settings need op_lo < op_hi, got op_lo = {s['op_lo']:g}, "
                         f"op_hi = {s['op_hi']:g}")
    return s


class PIBlock(FunctionBlock):
    """PI level controller as a DCS block (batched, bumpless, output tracking).

    Parameters
    ----------
    **settings
        See the module docstring (``Kc``, ``Ti``, ``detune``, ``scan_s``,
        ``op_lo``, ``op_hi``).

    Examples
    --------
    >>> pi = PIBlock(Kc=1.0, Ti=10.0)
    >>> pi.reset(sp=1.0, pv=1.0, op=0.4)
    >>> pi.step(1.0, 1.0)              # no error: bumpless, output unchanged
    0.4
    >>> round(pi.step(1.0, 0.9), 4)    # 0.4 + 1.0*0.1 + 1.0*1/10*0.1
    0.51
    >>> pi.reset([1.0, 1.0], [0.9, 1.1], [0.5, 0.5])
    >>> pi.step([1.0, 1.0], [0.9, 1.1]).round(3)
    array([0.51, 0.49])
    """

    name = "pi"
    SETTINGS = PI_SETTINGS

    def _resolve(self, settings: dict) -> dict:
        return resolve_pi(self.name, settings)

    @property
    def Kc(self) -> Any:
        """Effective gain ``Kc * detune`` [output fraction per m], float or (n,) array."""
        return self.p["Kc"] * self.p["detune"]

    @property
    def Ti(self) -> Any:
        """Integral time [s], float or (n,) array."""
        return self.p["Ti"]

    def initial_state(self, sp, pv, op) -> PIBlockState:
        """Bumpless start: ``I = op - Kc (sp - pv)``."""
        op = np.asarray(op, float)
        return PIBlockState(integral=pi_track(op, 0.0, self.Kc * (sp - pv)), op=op.copy())

    def propose(self, state: PIBlockState, sp, pv, integrate=True) -> PIScan:
        """The PI's scan before the limits; ``integrate`` False freezes the integral."""
        e = np.asarray(sp, float) - np.asarray(pv, float)
        p, integral, v = pi_scan(state.integral, e, self.Kc, self.Ti, self.scan_s, integrate)
        return PIScan(e=e, p=p, integral=integral, v=v)

    def finish(self, scan: PIScan, bias: float | np.ndarray = 0.0) -> tuple[PIBlockState, np.ndarray]:
        """Apply the limits to ``v + bias`` and track the integral where they act.

        Parameters
        ----------
        scan : PIScan, from :meth:`propose`
        bias : float or (n,) array, what a compensator adds to the PI output

        Returns
        -------
        state : PIBlockState
        op : (n,) array, the output to apply [0..1]
        """
        want = scan.v + bias
        op = np.clip(want, self.p["op_lo"], self.p["op_hi"])
        integral = np.where(op != want, pi_track(op, bias, scan.p), scan.integral)
        return PIBlockState(integral=integral, op=op), op

    def track(self, scan: PIScan, op) -> PIBlockState:
        """Memory whose PI output equals ``op`` now (tracking input of a DCS block)."""
        op = np.asarray(op, float)
        return PIBlockState(integral=pi_track(op, 0.0, scan.p), op=op.copy())

    def advance(self, state: PIBlockState, sp, pv):
        """One PI scan: ``(state, sp, pv) -> (state, op)``."""
        return self.finish(self.propose(state, sp, pv))
