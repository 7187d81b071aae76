r"""``riihilahti``: the seed valve of Riihilahti (1997) / Yamé & El Bahir, sized by ``S`` and ``J``.

The model (:class:`valve_gym.params.ValveParams`) has a dead band ``e_dead`` and
an integral friction band ``z_max`` rather than a stick band and a jump, so
``S`` and ``J`` are mapped onto it by a derived rule, exact at one reference
input speed.

Notes
-----
Derived behaviour (oracle O2 of the domain notes, checked by simulation): after
a reversal of an input ramp of slope ``s`` (``v_max`` not limiting) the input
travels

.. math:: \Delta u_b = 2 e_{dead} + s \tau \ln 2 + 2\sqrt{s z_{max}}

before the stem breaks away, and at break-away the error beyond the dead band
is ``2 sqrt(s z_max)``, which the stem then makes up in a fast first-order
catch-up (the model's "slip"). Equating the break-away travel with ``S`` and
the catch-up with ``J`` at the reference speed ``s_ref`` gives the rule

.. math:: z_{max} = J^2 / (4 s_{ref}), \qquad
          e_{dead} = \max\left(0, (S - J - s_{ref} \tau \ln 2)/2\right)

with ``s_ref`` = :data:`REF_RATE` = 0.001 /s (0.1 % of stroke per second, the
speed of a PI output creeping through a stick band of a few % in a level loop)
and ``tau`` the base valve's time constant.

Limits (what the paper's model cannot do, so ``J`` is honoured only in part):

* the stick band is an integral threshold: at input speed ``s`` the
  break-away travel is ``2 e_dead + s tau ln2 + J sqrt(s/s_ref)`` and the
  catch-up ``J sqrt(s/s_ref)``: larger for faster inputs, smaller for slower;
* the "jump" is a first-order catch-up with ``tau`` (limited by ``v_max``),
  never an instantaneous step, and never an overshoot (``J > S`` impossible);
* no re-stick after a stop in the same direction (the stem restarts at once);
* for ``J`` close to ``S`` the dead band ``e_dead`` is clipped at 0 and the
  break-away travel is ``s tau ln2 + J`` (slightly above ``S``).

References
----------
.. [1] M. Riihilahti, "Modeling and simulation of control valve
   nonlinearities", Helsinki University of Technology, 1997.
.. [2] K. Yamé, L. El Bahir, "Teaching control valve friction using modeling
   and simulation".
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .._numba import njit
from ..params import ModelParams
from .spec import FrictionSpec, ParamSpec, register

__all__ = ["SPEC", "REF_RATE", "build", "breakaway_travel", "riihilahti_step"]

#: Reference input speed of the S/J mapping, fraction of stroke per second.
REF_RATE = 1e-3


def build(base: ModelParams, S, J, rate: float = REF_RATE) -> ModelParams:
    """``base`` (friction removed) with ``e_dead``, ``z_max`` mapped from ``S``, ``J`` at input speed ``rate``.

    Parameters
    ----------
    base : ModelParams
        Plant and valve; its ``valve.tau`` enters the rule.
    S, J : float or (n,) array
        Break-away travel after a reversal and catch-up size at ``rate``, fractions of stroke.
    rate : float, 1/s
        Reference input speed (default :data:`REF_RATE`).

    Returns
    -------
    ModelParams
        With ``valve.e_dead`` and ``valve.z_max`` set (see the module notes).
    """
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a positive speed in fraction of stroke per second, got {rate!r}")
    tau = np.asarray(base.valve.tau, float)
    S = np.asarray(S, float)
    J = np.asarray(J, float)
    e_dead = np.maximum(0.0, (S - J - rate * tau * np.log(2.0)) / 2.0)
    z_max = J ** 2 / (4.0 * rate)
    return replace(base, valve=replace(base.valve, e_dead=_same_kind(e_dead), z_max=_same_kind(z_max)))


@njit(inline="always")
def riihilahti_step(u, h, z, tau, vmax, ed, zmax, dt):  # pragma: no cover - compiled into the core's kernel
    """One Euler step of the Riihilahti valve: ``(h, z)`` after ``dt`` with input ``u``.

    Parameters
    ----------
    u : float
        Valve input, 0..1.
    h, z : float
        Stem position (integrator state, unclipped) and friction state [s].
    tau, vmax, ed, zmax, dt : float
        ``ValveParams`` fields and the Euler step [s].

    Returns
    -------
    h, z : float

    Notes
    -----
    ``z`` is held at the edge of its band while outside it (continuous-time
    ``dz/dt = 0`` there): the stem slips while ``z`` is at an edge and ``e``
    pushes outwards, else it is stuck.
    """
    e = u - h
    if e > ed:
        e = e - ed
    elif e < -ed:
        e = e + ed
    else:
        e = 0.0
    v = 0.0
    if (z >= zmax and e > 0.0) or (z <= -zmax and e < 0.0):
        v = abs(e) / tau
        if v > vmax:
            v = vmax
        if e < 0.0:
            v = -v
    else:
        z += dt * e
        if z > zmax:
            z = zmax
        elif z < -zmax:
            z = -zmax
    h += dt * v
    return h, z


def _same_kind(a: np.ndarray):
    return float(a) if a.ndim == 0 else a


def breakaway_travel(e_dead, z_max, tau, rate):
    """Input travel from a ramp reversal to break-away (oracle O2), fraction of stroke.

    ``2 e_dead + rate tau ln2 + 2 sqrt(rate z_max)``; valid when ``v_max`` does not limit the stem.
    """
    return 2.0 * np.asarray(e_dead) + rate * np.asarray(tau) * np.log(2.0) + 2.0 * np.sqrt(rate * np.asarray(z_max))


SPEC = register(FrictionSpec(
    name="riihilahti",
    title="Riihilahti integral-band friction (seed model)",
    params=(ParamSpec("e_dead", "-", 0.0, 0.5, 0.005, "sq", "half the dead band, fraction of stroke"),
            ParamSpec("z_max", "s", 0.0, 250.0, 0.005, "sq", "half width of the integral friction band"),
            ParamSpec("tau", "s", 1e-3, 10.0, 0.1, "fixed", "stem time constant (from the base valve)"),
            ParamSpec("v_max", "1/s", 1e-3, float("inf"), 0.5, "fixed", "stem speed limit (from the base valve)")),
    kernel="Riihilahti block of the core, every Euler step: dead band on e = u - h, integral band |z| <= z_max, "
           "first-order stem motion with tau, speed limit v_max. S and J map to e_dead, z_max at the "
           "reference input speed 0.001 /s.",
    signature="Stem flat after each reversal for a time that shrinks with the input speed (the stick band grows "
              "as sqrt(speed)); no re-stick after a stop in the same direction; no overshoot.",
    report="Friction (Riihilahti 1997 model) sized to break away after S = {S} % of input travel with a catch-up "
           "of J = {J} % at an input speed of 0.1 %/s; faster inputs see a larger band.",
    citation="M. Riihilahti, \"Modeling and simulation of control valve nonlinearities\", Helsinki University of "
             "Technology, 1997; as implemented by K. Yamé, L. El Bahir, \"Teaching control valve friction using "
             "modeling and simulation\".",
    build=build,
))
