"""``choudhury``: the two-parameter data-driven stiction model of Choudhury, Thornhill & Shah (2005).

The core's ``slip_jump`` block (:class:`valve_gym.params.SlipJump`), run once per
controller sample on the input ``u``; its output ``x`` drives the positioner lag
``dh/dt = (x - h)/tau_p``. ``S`` and ``J`` are the model's own parameters.

Notes
-----
State: stuck flag, stuck input ``u_s``, direction of the last motion ``d``.
While moving ``x = u - d (S - J)/2``. The valve sticks when the input stops
(``du = 0``) or reverses (sign of ``du`` differs from ``d``) and slips when
``|u - u_s| > S`` after a reversal or ``|u - u_s| > J`` when the input goes on in
the direction of the last motion; the slip is a jump of ``J`` (with ``S`` of
input travel after a reversal). This block (the core's ``slip_jump`` since its
first version) judges the direction by the sign of the current input increment
and the distance by ``|u - u_s|``; other readings of the paper's flow chart
test the signed distance ``sign(u - u_s)`` instead, as Kano et al. (2004) do
(:mod:`valve_gym.friction.kano`). All agree on smooth inputs once the valve
has moved (oracle O5). They differ after a stop followed by a small
back-and-forth of the input, where this block slips at once, and at the rest
state of :func:`valve_gym.core.initial_state` (no direction yet), from which it
slips after ``J`` of input to ``u -+ (S - J)/2`` (against the input when
``J < S/3``); both are tested in ``tests/test_friction_models.py``.
"""
from __future__ import annotations

from dataclasses import replace

from .._numba import njit
from ..params import ModelParams, SlipJump
from .spec import FrictionSpec, ParamSpec, register

__all__ = ["SPEC", "build", "choudhury_sample"]


def build(base: ModelParams, S, J) -> ModelParams:
    """``base`` (friction removed) with the Choudhury block ``SlipJump(S, J, tau_p = base.valve.tau)``."""
    return replace(base, slip_jump=SlipJump(S=S, J=J, tau_p=base.valve.tau))


@njit(inline="always")
def choudhury_sample(u, uprev, x, us, stuck, sdir, S, J):  # pragma: no cover - compiled into the core's kernel
    """One controller sample of the Choudhury block.

    Parameters
    ----------
    u, uprev : float
        Input of this and of the previous sample, 0..1.
    x : float
        Block output (positioner target) of the previous sample.
    us, stuck, sdir : float
        Stuck input, stuck flag (1.0 stuck), direction of the last motion (-1, 0, 1).
    S, J : float
        Stick band and slip jump, fractions of stroke.

    Returns
    -------
    x, us, stuck, sdir : float
        ``x`` clipped to [0, 1].
    """
    du = u - uprev
    dsg = 0.0
    if du > 0.0:
        dsg = 1.0
    elif du < 0.0:
        dsg = -1.0
    if dsg == 0.0:
        if stuck == 0.0:
            stuck = 1.0
            us = uprev
    else:
        # sdir: direction of the last *motion* of the valve, kept
        # while it is stuck, so a reversal is remembered until it slips
        reversed_ = (sdir != 0.0) and (dsg != sdir)
        if stuck == 0.0 and reversed_:
            stuck = 1.0
            us = uprev
        if stuck == 1.0:
            thr = S if reversed_ else J
            if abs(u - us) > thr:
                stuck = 0.0
                x = u - dsg * (S - J) / 2.0
                sdir = dsg
        else:
            x = u - dsg * (S - J) / 2.0
            sdir = dsg
    if x < 0.0:
        x = 0.0
    elif x > 1.0:
        x = 1.0
    return x, us, stuck, sdir


SPEC = register(FrictionSpec(
    name="choudhury",
    title="Choudhury, Thornhill & Shah two-parameter stiction",
    params=(ParamSpec("S", "-", 0.0, 0.99, 0.02, "sq", "dead band + stick band, fraction of stroke"),
            ParamSpec("J", "-", 0.0, 0.99, 0.01, "lin", "slip jump, fraction of stroke"),
            ParamSpec("tau_p", "s", 1e-3, 10.0, 0.1, "fixed", "positioner time constant (from the base valve)")),
    kernel="slip_jump block of the core, once per controller sample on the saturated input; its output is "
           "the target of the positioner lag, integrated every Euler step.",
    signature="Flat stem after every reversal until the controller output has moved S, then a jump J; "
              "while moving the stem lags the output by (S - J)/2 (parallelogram with vertical jumps in "
              "the OP-MV plot).",
    report="Stiction (Choudhury, Thornhill & Shah 2005): stick band + dead band S = {S} % of stroke, slip "
           "jump J = {J} %; after each reversal the valve stays stuck until the controller output has "
           "moved S, then jumps J.",
    citation="M.A.A.S. Choudhury, N.F. Thornhill, S.L. Shah, \"Modelling valve stiction\", Control "
             "Engineering Practice 13 (2005) 641-658, doi:10.1016/j.conengprac.2004.05.005.",
    build=build,
))
