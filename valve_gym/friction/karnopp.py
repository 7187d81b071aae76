r"""``karnopp``: force balance on the valve stem with Karnopp's stick-velocity window.

The core's ``slip_jump`` block with ``law='karnopp'``, integrated every Euler
step. All forces are divided by the spring constant ``k`` so that they read as
stem positions in fraction of the stroke.

Notes
-----
Actuator force (diaphragm pressure) behind the input by the positioner lag,
stem of mass ``m`` on a spring ``k``, static friction ``Fs``, Coulomb friction
``Fc`` and viscous friction ``Fv`` (DOMAIN 1.6; Karnopp 1985):

.. math::
   \tau_p \dot p = u - p, \qquad
   \ddot x = \omega_n^2 \left(p - x - f_f\right), \qquad \omega_n^2 = k/m

with ``p = F_a/k`` and ``f_f = F_f/k``. Karnopp's rule: while ``|v| < dv``
the stem is stuck as long as the net force ``f_e = p - x`` satisfies
``|f_e| <= f_s`` (no motion at all inside the band); it breaks away when
``|f_e| > f_s``; while sliding
``f_f = f_c sign(v) + (2 zeta / omega_n) v``.

Sizing by ``S`` and ``J`` (quasi-static, DOMAIN 1.2): reversing needs a force
change ``Fs + Fc`` and the slip moves the stem until sliding friction balances,
``Fs - Fc``, so

.. math:: f_s = F_s/k = (S + J)/2, \qquad f_c = F_c/k = (S - J)/2

(``J <= S``). With ``zeta >= 1`` (default 1.146) the slip ends without
overshoot and the jump is ``J``; with ``zeta < 1`` the stem's inertia carries
it to ``J (1 + exp(-pi zeta / sqrt(1 - zeta^2)))`` (up to ``2 J`` undamped)
and a slow ramp gives stick-slip steps of that size. While moving at speed
``s`` the stem lags the actuator by ``(S - J)/2 + 2 zeta s / omega_n``.

Integration: ``p`` by explicit Euler at the kernel's ``dt`` (stable for
``dt <= tau_p``, checked by :func:`valve_gym.core.check_dt`); the stem by
semi-implicit Euler (viscous term implicit) on ``m`` sub-steps with
``omega_n dt / m <= 0.05`` (:func:`substeps`); a velocity that reaches or
crosses zero within a sub-step is set to zero and the next sub-step decides
between sticking and slipping. A stuck stem whose force stays inside the band
costs one test per Euler step. Settings that would need more than
:data:`MAX_SUBSTEPS` sub-steps are refused with a clear error.

Default mechanics: ``omega_n = sqrt(k/m)`` and ``zeta = Fv/(2 sqrt(k m))`` of
the valve of Kayihan & Doyle (2000), reused by Choudhury et al. (2005):
``m = 1.36 kg``, ``k = 52 538 N/m``, ``Fv = 612.9 N s/m``.

References
----------
.. [1] D. Karnopp, "Computer simulation of stick-slip friction in mechanical
   dynamic systems", ASME J. Dynamic Systems, Measurement, and Control 107(1)
   (1985) 100-103.
.. [2] A. Kayihan, F.J. Doyle III, "Friction compensation for a process
   control valve", Control Engineering Practice 8 (2000) 799-812.
.. [3] C. Garcia, "Comparison of friction models applied to a control valve",
   Control Engineering Practice 16 (2008) 1231-1243.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .._numba import njit
from ..params import ModelParams, ParameterError, SlipJump
from .spec import FrictionSpec, ParamSpec, register

__all__ = ["SPEC", "build", "karnopp_step", "substeps", "OMEGA_H", "MAX_SUBSTEPS"]

#: Largest ``omega_n * h`` of a stem sub-step.
OMEGA_H = 0.05
#: Most stem sub-steps per Euler step.
MAX_SUBSTEPS = 2000


def build(base: ModelParams, S, J) -> ModelParams:
    """``base`` (friction removed) with ``SlipJump(S, J, tau_p = base.valve.tau, law='karnopp')``."""
    return replace(base, slip_jump=SlipJump(S=S, J=J, tau_p=base.valve.tau, law="karnopp"))


def substeps(dt: float, omega_n) -> np.ndarray:
    """Stem sub-steps per Euler step ``dt`` [s]: ``ceil(omega_n dt / OMEGA_H)``, at least 1.

    Raises
    ------
    ParameterError
        When more than :data:`MAX_SUBSTEPS` would be needed (a stiff stem at a long step).
    """
    w = np.atleast_1d(np.asarray(omega_n, float))
    m = np.maximum(1.0, np.ceil(w * dt / OMEGA_H - 1e-9))
    if (m > MAX_SUBSTEPS).any():
        wmax = float(w.max())
        raise ParameterError(
            f"the force-balance valve (law='karnopp') with omega_n = {wmax:.4g} rad/s needs "
            f"{int(m.max())} stem sub-steps per Euler step dt = {dt} s (at most {MAX_SUBSTEPS}); "
            f"use dt <= {MAX_SUBSTEPS * OMEGA_H / wmax:.3g} s or a slower stem (smaller omega_n)")
    return m


@njit(inline="always")
def karnopp_step(u, h, v, p, S, J, taup, w2, c2, dv, m, dt):  # pragma: no cover - compiled into the kernel
    """One Euler step ``dt`` of the force-balance valve.

    Parameters
    ----------
    u : float
        Valve input, 0..1 (held over the step).
    h, v, p : float
        Stem position, stem velocity [1/s], actuator force / k (fraction of stroke).
    S, J, taup : float
        Stick band, slip jump (fractions of stroke) and actuator lag [s].
    w2, c2, dv : float
        ``omega_n**2`` [1/s^2], ``2 zeta omega_n`` [1/s], stick-velocity window [1/s].
    m : int
        Stem sub-steps.
    dt : float
        Euler step [s].

    Returns
    -------
    h, v, p : float
    """
    p += dt * (u - p) / taup
    fs = 0.5 * (S + J)
    fc = 0.5 * (S - J)
    if v == 0.0 and abs(p - h) <= fs:
        return h, v, p                       # stuck: p is held over the step, so it stays stuck
    hs = dt / m
    den = 1.0 + hs * c2
    for _ in range(m):
        fe = p - h
        if v == 0.0:
            if fe > fs:
                sg = 1.0
            elif fe < -fs:
                sg = -1.0
            else:
                break                        # sticks for the rest of the step
            v = hs * w2 * (fe - fc * sg) / den
        else:
            sg = 1.0 if v > 0.0 else -1.0
            vn = (v + hs * w2 * (fe - fc * sg)) / den
            if vn * sg <= 0.0 or abs(vn) < dv:
                vn = 0.0                     # the velocity reached zero: Karnopp's stick window
            v = vn
        h += hs * v
        if h > 1.0:                          # travel stops
            h = 1.0
            v = 0.0
        elif h < 0.0:
            h = 0.0
            v = 0.0
    return h, v, p


SPEC = register(FrictionSpec(
    name="karnopp",
    title="force balance with Karnopp friction",
    params=(ParamSpec("S", "-", 0.0, 0.99, 0.02, "sq", "reversal band (Fs + Fc)/k, fraction of stroke"),
            ParamSpec("J", "-", 0.0, 0.99, 0.01, "lin", "slip jump (Fs - Fc)/k, fraction of stroke (J <= S)"),
            ParamSpec("tau_p", "s", 1e-3, 10.0, 0.1, "fixed", "actuator lag (from the base valve)"),
            ParamSpec("omega_n", "rad/s", 1.0, 2000.0, 196.5, "log", "stem natural frequency sqrt(k/m)"),
            ParamSpec("zeta", "-", 0.01, 200.0, 1.146, "log", "viscous damping ratio Fv / (2 sqrt(k m))"),
            ParamSpec("dv", "1/s", 1e-9, 1e-2, 1e-5, "fixed", "stick-velocity window, strokes per second")),
    kernel="slip_jump block of the core with law='karnopp', every Euler step: actuator lag, then the stem's "
           "force balance on sub-steps with omega_n*h <= 0.05 (semi-implicit Euler), Karnopp's stick window.",
    signature="Flat stem after a reversal until the actuator force has changed by Fs + Fc (S of input), then a "
              "slip of (Fs - Fc)/k = J, larger with little damping; slow ramps give stick-slip steps when "
              "zeta < 1; moving lag (S - J)/2 plus a speed-proportional viscous part.",
    report="Friction (force balance on the stem, Karnopp 1985) sized to a reversal band S = {S} % and a slip jump "
           "J = {J} % of stroke: static friction Fs/k = (S + J)/2, Coulomb friction Fc/k = (S - J)/2.",
    citation="D. Karnopp, \"Computer simulation of stick-slip friction in mechanical dynamic systems\", ASME J. "
             "Dynamic Systems, Measurement, and Control 107(1) (1985) 100-103; stem parameters of A. Kayihan, "
             "F.J. Doyle III, \"Friction compensation for a process control valve\", Control Engineering Practice 8 "
             "(2000) 799-812.",
    build=build,
))
