"""``kano``: the stiction model of Kano, Maruta, Kugemoto & Shimizu (2004).

The core's ``slip_jump`` block with ``law='kano'``, run once per controller
sample on the input ``u``; its output ``x`` drives the positioner lag
``dh/dt = (x - h)/tau_p``, as for :mod:`~valve_gym.friction.choudhury`.

Notes
-----
State: stop flag, stuck input ``u_s``, direction ``d`` of the last motion
(the direction the friction force opposes), last input increment ``du_old``.
With ``du = u(k) - u(k-1)``:

* the valve stops when it was moving and ``du * du_old <= 0`` (the input
  stops or turns): ``u_s = u(k-1)``;
* a stopped valve slips backwards when ``-d (u - u_s) > S`` (``d`` flips),
  forwards when ``d (u - u_s) > J``; else the stem stays where it is;
* while moving ``x = u - d (S - J)/2``.

Against Choudhury's model (which tests the direction by the sign of the current
increment and the distance by ``|u - u_s|``) the signed distance ``d (u - u_s)``
keeps the valve stuck when the input, after a stop or a small reversal, drifts
back towards and past the stuck point by less than ``J``; Choudhury's test
slips there at once, even backwards. On smooth inputs the two agree sample for
sample (oracle O5).

Start: a valve at rest with no direction yet (``d = 0``, the state of
:func:`valve_gym.core.initial_state`) sits in the middle of its band: it slips
when ``|u - u_s| > (S + J)/2``, with a jump of ``J``.

References
----------
.. [1] M. Kano, H. Maruta, H. Kugemoto, K. Shimizu, "Practical model and
   detection algorithm for valve stiction", Proc. 7th IFAC Symposium on
   Dynamics and Control of Process Systems (DYCOPS), Cambridge, MA, 2004.
"""
from __future__ import annotations

from dataclasses import replace

from .._numba import njit
from ..params import ModelParams, SlipJump
from .spec import FrictionSpec, ParamSpec, register

__all__ = ["SPEC", "build", "kano_sample"]


def build(base: ModelParams, S, J) -> ModelParams:
    """``base`` (friction removed) with ``SlipJump(S, J, tau_p = base.valve.tau, law='kano')``."""
    return replace(base, slip_jump=SlipJump(S=S, J=J, tau_p=base.valve.tau, law="kano"))


@njit(inline="always")
def kano_sample(u, uprev, x, us, stuck, d, du_old, S, J):  # pragma: no cover - compiled into the core's kernel
    """One controller sample of Kano's model.

    Parameters
    ----------
    u, uprev : float
        Input of this and of the previous sample, 0..1.
    x : float
        Block output (positioner target) of the previous sample.
    us, stuck, d, du_old : float
        Stuck input, stop flag (1.0 stopped), direction of the last motion
        (-1, 0, 1), previous input increment.
    S, J : float
        Stick band and slip jump, fractions of stroke.

    Returns
    -------
    x, us, stuck, d, du : float
        ``x`` clipped to [0, 1]; ``du`` is the next sample's ``du_old``.
    """
    du = u - uprev
    if stuck == 0.0 and du * du_old <= 0.0:
        us = uprev
        stuck = 1.0
    half = 0.5 * (S - J)
    if stuck == 0.0:
        x = u - d * half
    elif d == 0.0:
        if u - us > 0.5 * (S + J):
            d = 1.0
            x = u - half
            stuck = 0.0
        elif us - u > 0.5 * (S + J):
            d = -1.0
            x = u + half
            stuck = 0.0
    elif -d * (u - us) > S:
        d = -d
        x = u - d * half
        stuck = 0.0
    elif d * (u - us) > J:
        x = u - d * half
        stuck = 0.0
    if x < 0.0:
        x = 0.0
    elif x > 1.0:
        x = 1.0
    return x, us, stuck, d, du


SPEC = register(FrictionSpec(
    name="kano",
    title="Kano et al. stiction model",
    params=(ParamSpec("S", "-", 0.0, 0.99, 0.02, "sq", "dead band + stick band, fraction of stroke"),
            ParamSpec("J", "-", 0.0, 0.99, 0.01, "lin", "slip jump, fraction of stroke"),
            ParamSpec("tau_p", "s", 1e-3, 10.0, 0.1, "fixed", "positioner time constant (from the base valve)")),
    kernel="slip_jump block of the core with law='kano', once per controller sample on the saturated input; "
           "its output is the target of the positioner lag, integrated every Euler step.",
    signature="As Choudhury's model on smooth inputs (flat stem for S of input travel after a reversal, jump J); "
              "after a stop or a small back-and-forth of the input the stem stays stuck until the input is J "
              "past the stuck point in the direction of the last motion.",
    report="Stiction (Kano et al. 2004): stick band + dead band S = {S} % of stroke, slip jump J = {J} %; the valve "
           "stops whenever the input stops or turns and moves again after S against, or J along, its last "
           "direction of motion.",
    citation="M. Kano, H. Maruta, H. Kugemoto, K. Shimizu, \"Practical model and detection algorithm for valve "
             "stiction\", Proc. 7th IFAC Symposium on Dynamics and Control of Process Systems (DYCOPS), "
             "Cambridge, MA, 2004.",
    build=build,
))
