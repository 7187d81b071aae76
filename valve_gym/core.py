"""The one physics core: a pure, batched, fixed-step explicit-Euler simulator.

Everything that simulates in valve_gym (the Gymnasium env, the native vector
env, the diagnosis fitter, the benchmarks and the teaching figures) calls
:func:`simulate` / :func:`step`, or, for the lowest call overhead, the same
compiled kernel through :class:`Packed` and :func:`run_packed`. Nothing else
re-implements a line of physics.

Conventions
-----------
* Batch axis: ``n`` parallel systems. Every state field is an ``(n,)`` array;
  parameters are floats or ``(n,)`` arrays (see :mod:`valve_gym.params`).
* Inputs ``u`` are the valve input (controller output) normalised to 0..1,
  held constant over one controller sample of ``n_sub`` Euler steps (zero-order
  hold); values outside [0, 1] saturate.
* ``d`` is an extra inflow (load disturbance) in the process' flow units
  (m^3/s for tanks; output units for ``first_order``), negative for an offtake.
* No random numbers are drawn here: noise is added by the callers, which get
  their randomness through ``reset(seed=...)``.

The controller sample is ``n_sub * dt`` seconds.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ._numba import HAVE_NUMBA, njit
from .friction.choudhury import choudhury_sample
from .friction.kano import kano_sample
from .friction.karnopp import karnopp_step, substeps
from .friction.riihilahti import riihilahti_step
from .params import AREA_FLOOR, ModelParams, ParameterError

__all__ = ["State", "Trajectory", "Packed", "pack", "initial_state", "steady_input",
           "step", "simulate", "run_packed", "check_dt", "tank_shape_factor", "HAVE_NUMBA"]

# ---------------------------------------------------------------- layouts
# parameter rows of the packed (NP, n) array
TAU, VMAX, EDEAD, ZMAX, SJ_S, SJ_J, SJ_TAU, CH_R, CH_H0, P_A, P_Q, P_OUT, A2, K2, \
    LMAX, L2MAX, SPILL, QLEAK, DELAY, TAU_S, DIST_A, DIST_P, DIST_PHI, KP_W2, KP_C2, KP_DV, KP_M, \
    SH_A1, SH_A2, SH_REF = range(30)
NP = 30
# flag slots
F_FRIC, F_CHAR, F_ACT, F_PROC, F_DEAD, F_OVER, F_LEAK, F_SENS, F_DIST, F_SHAPE = range(10)
NF = 10
# friction codes of the F_FRIC slot: the seed valve (also 'none'), then the slip_jump laws
FRIC_RIIHILAHTI, FRIC_CHOUDHURY, FRIC_KANO, FRIC_KARNOPP = range(4)
_LAW_CODE = {"choudhury": FRIC_CHOUDHURY, "kano": FRIC_KANO, "karnopp": FRIC_KARNOPP}
# state rows of the packed (NS, n) array
S_Z, S_H, S_X, S_US, S_STUCK, S_SDIR, S_UPREV, S_L1, S_L2, S_Y, S_T, S_BIDX = range(12)
NS = 12
_PROC_CODE = {"tank": 0, "integrating": 1, "first_order": 2, "cascade": 3}


class State(NamedTuple):
    """Simulator state, each field an ``(n,)`` float64 array (``delay_buf`` ``(n, B)``).

    Fields
    ------
    z : friction state: Riihilahti valve: integral band state [s]; ``kano``: last
        input increment [-]; ``karnopp``: stem velocity [1/s]
    h : stem position (integrator state; the output is ``clip(h, 0, 1)``) [-]
    x : output of the slip-jump friction block (its positioner target) [-];
        ``karnopp``: actuator force / spring constant [-]
    u_s : input at which the slip-jump valve stuck [-]
    stuck : 1.0 while the slip-jump valve is stuck, else 0.0
    s_dir : last direction of motion of the slip-jump valve (-1, 0, 1)
    u_prev : input of the previous controller sample [-]
    level : level of the (upper) tank [m], or process output for ``first_order``
    level2 : level of the lower tank (``cascade``) [m]
    y : lagged measurement (``sensor_lag``), else equal to the measured level
    t : time [s]
    buf_idx : write position of the dead-time ring buffer
    delay_buf : ``(n, B)`` past flow fractions for ``dead_time``
    """

    z: np.ndarray
    h: np.ndarray
    x: np.ndarray
    u_s: np.ndarray
    stuck: np.ndarray
    s_dir: np.ndarray
    u_prev: np.ndarray
    level: np.ndarray
    level2: np.ndarray
    y: np.ndarray
    t: np.ndarray
    buf_idx: np.ndarray
    delay_buf: np.ndarray

    @property
    def n(self) -> int:
        """Batch size."""
        return self.z.shape[0]

    def measured(self) -> np.ndarray:
        """Noise-free measured process variable ``(n,)``."""
        return self.y.copy()


class Trajectory(NamedTuple):
    """Result of :func:`simulate`, time axis first.

    t : (T,) s, time at the end of each controller sample
    u : (T, n) input applied during each sample (after saturation to 0..1)
    y : (T, n) noise-free measured process variable at the end of each sample
    h : (T, n) stem position (clipped to 0..1) at the end of each sample
    level : (T, n) level of the measured tank (lower tank for ``cascade``)
    final : State at the end
    """

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    h: np.ndarray
    level: np.ndarray
    final: State


# ---------------------------------------------------------------- kernel
# One small inlined helper per block; numba inlines them into `_kernel` at the IR level, so the
# compiled loop is the one long function it was before (benchmarks/bench_kernel.py measures it
# against the frozen pre-split copy in benchmarks/kernel_reference.py). The friction blocks live
# in their models' modules (valve_gym.friction.*), the others here.
@njit(inline="always")
def _characteristic(char, hc, R, h0):  # pragma: no cover - compiled
    """Installed characteristic ``f(hc)``: 0 linear, 1 equal percentage, 2 quick opening."""
    if char == 0 and h0 == 0.0:
        return hc
    if hc <= h0:
        return 0.0
    r = (hc - h0) / (1.0 - h0)
    if char == 0:
        return r
    elif char == 1:
        return R ** (r - 1.0)
    return np.sqrt(r)


@njit(inline="always")
def _dead_time(buf, i, bidx, f, kdel, B):  # pragma: no cover - compiled
    """Ring buffer of flow fractions: write ``f``, read the one ``kdel`` steps old; ``(f, bidx)``."""
    buf[i, bidx] = f
    f = buf[i, (bidx - kdel) % B]
    return f, (bidx + 1) % B


@njit(inline="always")
def _tank(proc, over, L1, L2, qin, pa, pout, qleak, lmax, a2, k2, spill_f, l2max, dt):  # pragma: no cover
    """Torricelli tank (``proc`` 0), or upper + lower tank (3); returns ``(L1, L2, measured level)``."""
    q1 = pout * np.sqrt(L1) if L1 > 0.0 else 0.0
    if proc == 0:
        L1 = L1 + dt * (qin - q1 - qleak) / pa
    else:
        L1 = L1 + dt * (qin - q1) / pa
    if L1 < 0.0:
        L1 = 0.0
    spill = 0.0
    if over == 1 and L1 > lmax:
        spill = (L1 - lmax) * pa / dt
        L1 = lmax
    if proc == 3:
        q2 = k2 * np.sqrt(L2) if L2 > 0.0 else 0.0
        L2 = L2 + dt * (q1 + spill_f * spill - q2 - qleak) / a2
        if L2 < 0.0:
            L2 = 0.0
        if over == 1 and L2 > l2max:
            L2 = l2max
        return L1, L2, L2
    return L1, L2, L1


@njit(inline="always")
def _process(proc, over, L1, L2, qin, pa, pout, qleak, lmax, a2, k2, spill_f, l2max, dt):  # pragma: no cover
    """One Euler step of the process; returns ``(L1, L2, measured level)``."""
    if proc == 0 or proc == 3:
        return _tank(proc, over, L1, L2, qin, pa, pout, qleak, lmax, a2, k2, spill_f, l2max, dt)
    if proc == 1:                                   # integrating
        L1 = L1 + dt * (qin - pout - qleak) / pa
    else:                                           # first order
        L1 = L1 + dt * (qin + pout - qleak - L1) / pa
    if over == 1 and L1 > lmax:
        L1 = lmax
    return L1, L2, L1


@njit(inline="always")
def _shape_area(pa, L, a1, a2, ref, floor):  # pragma: no cover - compiled
    """Cross-section of a shaped tank at level ``L``: ``pa max(1 + a1 x + a2 x^2, floor)``, ``x = L/ref - 1``."""
    x = L / ref - 1.0
    g = 1.0 + x * (a1 + a2 * x)
    if g < floor:
        g = floor
    return pa * g


@njit(inline="always")
def _sensor(sens, y, lm, taus, dt):  # pragma: no cover - compiled
    """First-order sensor lag (``sens`` 1) or the level itself."""
    if sens == 1:
        return y + dt * (lm - y) / taus
    return lm


@njit(inline="always")
def _valve_sample(fric, u, uprev, x, us, stuck, sdir, z, sjS, sjJ):  # pragma: no cover - compiled
    """The once-per-sample friction blocks (``slip_jump`` laws choudhury, kano); ``(x, us, stuck, sdir, z)``."""
    if fric == FRIC_CHOUDHURY:
        x, us, stuck, sdir = choudhury_sample(u, uprev, x, us, stuck, sdir, sjS, sjJ)
    elif fric == FRIC_KANO:
        x, us, stuck, sdir, z = kano_sample(u, uprev, x, us, stuck, sdir, z, sjS, sjJ)
    return x, us, stuck, sdir, z


@njit(inline="always")
def _valve_step(fric, u, h, z, x, V, dt):  # pragma: no cover - compiled
    """One Euler step of the valve stem; ``V`` the valve's parameters (see `_kernel`); ``(h, z, x)``."""
    if fric == FRIC_RIIHILAHTI:
        h, z = riihilahti_step(u, h, z, V[0], V[1], V[2], V[3], dt)
    elif fric == FRIC_KARNOPP:
        h, z, x = karnopp_step(u, h, z, x, V[4], V[5], V[6], V[7], V[8], V[9], int(V[10]), dt)
    else:
        h += dt * (x - h) / V[6]
    return h, z, x


@njit(inline="always")
def _read_error(y, rd, target):  # pragma: no cover - compiled
    """Squared error to ``target`` of an output ``y`` as read through ``rd`` (sign, offset, upper, lower)."""
    v = y * rd[0] + rd[1]
    if v > rd[2]:
        v = rd[2]
    if v < rd[3]:
        v = rd[3]
    e = v - target
    return e * e


@njit(inline="always")
def _kernel_core(S, P, U, D, flags, buf, n_sub, dt, Y, H, LV, E, M, lim, acc):  # noqa: C901  # pragma: no cover
    """Advance the packed state ``S`` (NS, n) over the inputs ``U`` (T, n|1); see :func:`run_packed`.

    With a non-empty ``lim`` (n,), each system also sums the squared error of its PV as read
    (``M`` (4 n,): the rows sign, offset, upper and lower limit of the reading, one after the
    other) to the target ``E`` (T,)
    onto ``acc[i]``, and stops once the sum exceeds ``lim[i]`` (the rest of its outputs are
    not written, its state stays where it stopped); a system whose ``acc`` already exceeds
    its ``lim`` is not run.
    """
    T = U.shape[0]
    track = lim.shape[0] > 0
    n = S.shape[1]
    pb = P.shape[1] > 1
    ub = U.shape[1] > 1
    db = D.shape[1] > 1
    fric, char, act, proc = flags[F_FRIC], flags[F_CHAR], flags[F_ACT], flags[F_PROC]
    dead, over, leak, sens, dist = flags[F_DEAD], flags[F_OVER], flags[F_LEAK], flags[F_SENS], flags[F_DIST]
    shape = flags[F_SHAPE]
    B = buf.shape[1]
    for i in range(n):
        err = acc[i] if track else 0.0
        lim_i = lim[i] if track else np.inf
        rd = (M[i], M[n + i], M[2 * n + i], M[3 * n + i]) if track else (1.0, 0.0, np.inf, -np.inf)
        if err > lim_i:                         # stopped in an earlier call
            continue
        j = i if pb else 0
        # valve: tau, vmax, e_dead, z_max, S, J, tau_p, omega_n^2, 2 zeta omega_n, dv, sub-steps
        V = (P[TAU, j], P[VMAX, j], P[EDEAD, j], P[ZMAX, j], P[SJ_S, j], P[SJ_J, j], P[SJ_TAU, j],
             P[KP_W2, j], P[KP_C2, j], P[KP_DV, j], P[KP_M, j])
        sjS, sjJ = P[SJ_S, j], P[SJ_J, j]
        R, h0 = P[CH_R, j], P[CH_H0, j]
        pa, pq, pout = P[P_A, j], P[P_Q, j], P[P_OUT, j]
        a2, k2, lmax, l2max, spill_f = P[A2, j], P[K2, j], P[LMAX, j], P[L2MAX, j], P[SPILL, j]
        qleak = P[QLEAK, j] if leak == 1 else 0.0
        kdel = int(P[DELAY, j])
        taus = P[TAU_S, j]
        da, dw, dphi = P[DIST_A, j], 2.0 * np.pi / P[DIST_P, j], P[DIST_PHI, j]
        sa1, sa2, sref = (P[SH_A1, j], P[SH_A2, j], P[SH_REF, j]) if shape == 1 else (0.0, 0.0, 1.0)
        z, h, x, us = S[S_Z, i], S[S_H, i], S[S_X, i], S[S_US, i]
        stuck, sdir, uprev = S[S_STUCK, i], S[S_SDIR, i], S[S_UPREV, i]
        L1, L2, y, t = S[S_L1, i], S[S_L2, i], S[S_Y, i], S[S_T, i]
        bidx = int(S[S_BIDX, i])
        hc = h
        lm = L1
        for k in range(T):
            u = U[k, i if ub else 0]
            if u < 0.0:
                u = 0.0
            elif u > 1.0:
                u = 1.0
            dk = D[k, i if db else 0]
            if act == 0 and (fric == FRIC_CHOUDHURY or fric == FRIC_KANO):
                x, us, stuck, sdir, z = _valve_sample(fric, u, uprev, x, us, stuck, sdir, z, sjS, sjJ)
            uprev = u
            pak = _shape_area(pa, L1, sa1, sa2, sref, AREA_FLOOR) if shape == 1 else pa
            for s in range(n_sub):
                if act == 1:                        # pump: the input is the flow fraction
                    hc = u
                    f = u
                else:
                    h, z, x = _valve_step(fric, u, h, z, x, V, dt)
                    hc = h
                    if hc < 0.0:
                        hc = 0.0
                    elif hc > 1.0:
                        hc = 1.0
                    f = _characteristic(char, hc, R, h0)
                if dead == 1:
                    f, bidx = _dead_time(buf, i, bidx, f, kdel, B)
                qin = f * pq + dk
                if dist == 1:
                    qin += da * np.sin(dw * t + dphi)
                L1, L2, lm = _process(proc, over, L1, L2, qin, pak, pout, qleak, lmax, a2, k2, spill_f, l2max, dt)
                y = _sensor(sens, y, lm, taus, dt)
                t += dt
            Y[k, i] = y
            H[k, i] = hc if act == 0 else u
            LV[k, i] = lm
            if track:
                err += _read_error(y, rd, E[k])
                if err > lim_i:                # its whole error can only be larger: stop here
                    break
        S[S_Z, i], S[S_H, i], S[S_X, i], S[S_US, i] = z, h, x, us
        S[S_STUCK, i], S[S_SDIR, i], S[S_UPREV, i] = stuck, sdir, uprev
        S[S_L1, i], S[S_L2, i], S[S_Y, i], S[S_T, i] = L1, L2, y, t
        S[S_BIDX, i] = bidx
        if track:
            acc[i] = err


@njit(cache=True, nogil=True)
def _kernel(S, P, U, D, flags, buf, n_sub, dt, Y, H, LV):  # pragma: no cover - compiled
    """Advance the packed state ``S`` (NS, n) over the inputs ``U`` (T, n|1); see :func:`run_packed`."""
    e = S[0, :0]                        # empty: no tracking (a view, so nothing is allocated per call)
    _kernel_core(S, P, U, D, flags, buf, n_sub, dt, Y, H, LV, e, e, e, e)


@njit(cache=True, nogil=True)
def _kernel_bounded(S, P, U, D, flags, buf, n_sub, dt, Y, H, LV, E, M, lim, acc):  # pragma: no cover
    """:func:`_kernel` that sums each system's squared error onto ``acc`` and stops it past ``lim``."""
    _kernel_core(S, P, U, D, flags, buf, n_sub, dt, Y, H, LV, E, M, lim, acc)


@njit(cache=True, nogil=True)
def _kernel_reset(S, P, U, D, flags, buf, n_sub, dt, Y, H, LV, L_meas, every, E, M, lim, acc):  # pragma: no cover
    """:func:`_kernel` with the measured level state set to ``L_meas`` (T, n) every ``every`` samples.

    Before sample ``a`` (``a`` a positive multiple of ``every``) the level of the measured tank
    (and the sensor's output state) of each system is set to ``L_meas[a - 1]``, the level read
    at the end of the previous sample; the valve, the other states and the buffers run on.
    With a non-empty ``lim``, the systems run as in :func:`_kernel_bounded`.
    """
    T = U.shape[0]
    track = lim.shape[0] > 0
    for a in range(0, T, every):
        b = min(T, a + every)
        if a > 0:
            _restart_level(S, flags, L_meas[a - 1])
        if track:
            _kernel_bounded(S, P, U[a:b], D[a:b], flags, buf, n_sub, dt, Y[a:b], H[a:b], LV[a:b], E[a:b], M,
                            lim, acc)
        else:
            _kernel(S, P, U[a:b], D[a:b], flags, buf, n_sub, dt, Y[a:b], H[a:b], LV[a:b])


@njit(cache=True, nogil=True)
def _restart_level(S, flags, L_row):  # pragma: no cover - compiled
    """Set the measured tank's level (the lower one of a cascade) and the sensor output to ``L_row`` (n,)."""
    low = S_L2 if flags[F_PROC] == 3 else S_L1
    for i in range(S.shape[1]):
        lv = L_row[i]
        if lv < 0.0:
            lv = 0.0
        S[low, i] = lv
        S[S_Y, i] = lv


class Bound(NamedTuple):
    """Early stop of :func:`run_packed` and :func:`run_packed_reset`: the error of each system's reading.

    ``target`` (T,): the record the PV is compared with; ``read`` (4, n): per system the sign,
    offset, upper and lower limit of the reading ``PV = clip(sign * y + offset, lower, upper)``;
    ``limit`` (n,): a system stops once its sum of squared errors exceeds it; ``acc`` (n,): the
    sums, updated in place (start at 0). A stopped system's later outputs are not written
    and its state stays where it stopped: its ``acc`` exceeds its ``limit``.
    """

    target: np.ndarray
    read: np.ndarray
    limit: np.ndarray
    acc: np.ndarray


#: The empty bound the unbounded runs pass to the kernels (never written).
_NO_BOUND = Bound(np.empty(0), np.empty((4, 0)), np.empty(0), np.empty(0))


def _bound_args(bound: Bound, a: int = 0, b: int | None = None) -> tuple:
    """The kernel's arguments of ``bound`` for its systems ``a:b``."""
    b = len(bound.limit) if b is None else b
    return (bound.target, np.ascontiguousarray(bound.read[:, a:b]).ravel(), bound.limit[a:b], bound.acc[a:b])


def run_packed_reset(pk: Packed, S: np.ndarray, buf: np.ndarray, U: np.ndarray, D: np.ndarray, n_sub: int,
                     Y: np.ndarray, H: np.ndarray, LV: np.ndarray, L_meas: np.ndarray, every: int,
                     bound: Bound | None = None) -> None:
    """:func:`run_packed` (one thread) with the measured level reset to ``L_meas`` every ``every`` samples.

    A ``every``-step-ahead prediction instead of a free run: the states the
    record measures are taken from it at the start of each block of
    ``every`` samples, so a slow unmeasured load does not add up over the
    record.  ``L_meas`` (T, n): the level (lower tank of a cascade) that the
    measurement implies after each sample, per system.  ``bound``: stop each
    system early (see :class:`Bound`).  No checks are made.
    """
    _kernel_reset(S, pk.P, U, D, pk.flags, buf, n_sub, pk.dt, Y, H, LV, L_meas, int(every),
                  *_bound_args(_NO_BOUND if bound is None else bound))


def _flush_stale_kernel_cache() -> None:
    """Drop numba's on-disk cache of the kernels when a block module is newer than it.

    numba keys the cache on this file only; the inlined friction blocks live in
    other modules, so an edit there would otherwise run a stale kernel.
    """
    try:
        from .friction import choudhury, kano, karnopp, riihilahti
        newest = max(os.path.getmtime(m.__file__) for m in (choudhury, kano, karnopp, riihilahti)
                     if m.__file__)
        for kern in (_kernel, _kernel_bounded, _kernel_reset):
            idx = kern._cache._cache_file._index_path  # type: ignore[attr-defined]
            if os.path.exists(idx) and newest > os.path.getmtime(idx):
                kern._cache.flush()  # type: ignore[attr-defined]
    except Exception:  # pragma: no cover - numba internals moved: keep the cache as numba decides
        pass


if HAVE_NUMBA:
    _flush_stale_kernel_cache()


# ---------------------------------------------------------------- packing
@dataclass(frozen=True)
class Packed:
    """Parameters packed for the kernel: ``P`` (NP, n or 1), ``flags`` (NF,), ``buf_len``."""

    P: np.ndarray
    flags: np.ndarray
    buf_len: int
    dt: float
    params: ModelParams

    @property
    def n(self) -> int:
        """Batch size."""
        return self.P.shape[1]


def _col(v, n):
    a = np.asarray(v, dtype=np.float64)
    if a.ndim == 0:
        return np.full(n, float(a))
    a = a.reshape(-1)
    if a.shape[0] == 1:
        return np.full(n, float(a[0]))
    if a.shape[0] != n:
        raise ParameterError(f"a parameter array has length {a.shape[0]}, expected {n} (the batch size)")
    return a


def check_dt(params: ModelParams) -> None:
    """Raise :class:`ParameterError` if ``params.dt`` is too large for stable Euler.

    Explicit Euler on ``dx/dt = -x/T`` is oscillation-free for ``dt <= T``;
    we require it for every first-order time constant of the model: the valve
    ``tau`` (paper model), the positioner ``tau_p`` (slip-jump), the sensor
    ``tau_s``, the ``first_order`` process ``T``, and for the tank the
    linearised outflow time constant ``2 A sqrt(L)/k`` at the level where the
    inflow is 10 % of ``q_max`` (with ``tank_shape``, ``A`` the cross-section at
    that level). The force-balance valve (``law='karnopp'``)
    integrates its stem on sub-steps of ``dt``; a stem too stiff for ``dt``
    (:func:`valve_gym.friction.karnopp.substeps`) is refused too.
    """
    dt = params.dt
    checks = []
    act_pump = params.actuator is not None and params.actuator.kind == "pump"
    if not act_pump:
        if params.slip_jump is None:
            checks.append(("valve tau", params.valve.tau))
        else:
            checks.append(("slip_jump tau_p", params.slip_jump.tau_p))
    if params.sensor_lag is not None:
        checks.append(("sensor_lag tau_s", params.sensor_lag.tau_s))
    pr: Any = params.process        # the class follows process_kind (validated by ModelParams)
    if params.process_kind == "first_order":
        checks.append(("first_order T", pr.T))
    elif params.process_kind in ("tank", "cascade"):
        k = np.asarray(pr.k_out, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            checks.append(("tank outflow time constant 2*A*sqrt(L)/k at 10 % inflow",
                           np.asarray(pr.area) * 0.2 * np.asarray(pr.q_max) / k ** 2
                           * tank_shape_factor(params.tank_shape, (0.1 * np.asarray(pr.q_max) / k) ** 2)))
        if params.cascade is not None:
            k2 = np.asarray(params.cascade.k_out2, float)
            with np.errstate(divide="ignore"):
                checks.append(("lower tank outflow time constant",
                               np.asarray(params.cascade.area2) * 0.2 * np.asarray(pr.q_max)
                               / k2 ** 2))
    if params.slip_jump is not None and params.slip_jump.law == "karnopp" and not act_pump:
        substeps(dt, params.slip_jump.omega_n)        # raises for a stem too stiff for dt
    for what, T in checks:
        tmin = float(np.min(T))
        if dt > tmin * (1 + 1e-9):
            raise ParameterError(
                f"dt = {dt} s is too large to integrate the model stably: the {what} is {tmin:.4g} s "
                f"and explicit Euler needs dt <= that; use dt <= {tmin:.4g} s (more sub-steps per "
                f"controller sample) or a slower model")


def tank_shape_factor(shape, L):
    """Cross-section at level ``L`` relative to ``area``: the numpy twin of the kernel's ``_shape_area``.

    1 without a shape (``shape`` None); floored at :data:`~valve_gym.params.AREA_FLOOR`.
    """
    if shape is None:
        return 1.0
    x = np.asarray(L, float) / np.asarray(shape.L_ref, float) - 1.0
    g = 1.0 + x * (np.asarray(shape.taper, float) + np.asarray(shape.curvature, float) * x)
    return np.maximum(np.nan_to_num(g, nan=AREA_FLOOR, posinf=AREA_FLOOR, neginf=AREA_FLOOR), AREA_FLOOR)


def _pack_slip_jump(sj, dt: float, n: int, P: np.ndarray) -> int:
    """Fill the rows of the ``slip_jump`` block in ``P``; returns its friction code."""
    if sj.law not in _LAW_CODE:
        raise ParameterError(f"SlipJump.law = {sj.law!r} is a per-sample friction law run outside the compiled "
                             f"kernel; simulate it with valve_gym.plant.Plant, which applies it once per scan")
    P[SJ_S], P[SJ_J], P[SJ_TAU] = _col(sj.S, n), _col(sj.J, n), _col(sj.tau_p, n)
    if sj.law == "karnopp":
        w = _col(sj.omega_n, n)
        P[KP_W2], P[KP_C2], P[KP_DV] = w * w, 2.0 * _col(sj.zeta, n) * w, _col(sj.dv, n)
        P[KP_M] = substeps(dt, w)
    return _LAW_CODE[sj.law]


def _pack_plant_blocks(params: ModelParams, kind: str, n: int, P: np.ndarray, flags: np.ndarray) -> int:
    """Fill the rows and flags of the optional plant blocks; returns the dead-time buffer's length."""
    buf_len = 1
    if params.dead_time is not None:
        flags[F_DEAD] = 1
        kdel = np.rint(_col(params.dead_time.theta, n) / params.dt)
        P[DELAY] = kdel
        buf_len = int(kdel.max()) + 1
    if params.overflow is not None:
        o = params.overflow
        flags[F_OVER] = 1
        P[LMAX], P[L2MAX], P[SPILL] = _col(o.L_max, n), _col(o.L2_max, n), _col(o.spill_to_lower, n)
    if params.leak is not None:
        flags[F_LEAK] = 1
        P[QLEAK] = _col(params.leak.q_leak, n)
    if params.sensor_lag is not None:
        flags[F_SENS] = 1
        P[TAU_S] = _col(params.sensor_lag.tau_s, n)
    if params.oscillating_disturbance is not None:
        d = params.oscillating_disturbance
        flags[F_DIST] = 1
        P[DIST_A], P[DIST_P], P[DIST_PHI] = _col(d.amplitude, n), _col(d.period, n), _col(d.phase, n)
    if params.tank_shape is not None:
        if kind == "first_order":
            raise ParameterError("tank_shape needs a tank (process_kind 'tank', 'cascade' or 'integrating'); "
                                 "the first-order process has no level; switch tank_shape off")
        sh = params.tank_shape
        flags[F_SHAPE] = 1
        P[SH_A1], P[SH_A2], P[SH_REF] = _col(sh.taper, n), _col(sh.curvature, n), _col(sh.L_ref, n)
    return buf_len


def pack(params: ModelParams, n: int | None = None, check: bool = True) -> Packed:
    """Pack ``params`` for the kernel, broadcasting to batch size ``n``."""
    nb = params.batch_size()
    if n is None:
        n = nb
    elif nb not in (1, n):
        raise ParameterError(f"parameters have batch size {nb} but n = {n} was asked for")
    if check:
        check_dt(params)
    P = np.zeros((NP, n))
    flags = np.zeros(NF, dtype=np.int64)
    v = params.valve
    P[TAU], P[VMAX], P[EDEAD], P[ZMAX] = _col(v.tau, n), _col(v.v_max, n), _col(v.e_dead, n), _col(v.z_max, n)
    P[SJ_TAU] = 1.0
    P[CH_R] = 1.0 + 1e-9
    P[LMAX] = np.inf
    P[L2MAX] = np.inf
    P[DIST_P] = 1.0
    P[TAU_S] = 1.0
    P[A2] = 1.0
    P[KP_M] = 1.0
    if params.slip_jump is not None:
        flags[F_FRIC] = _pack_slip_jump(params.slip_jump, params.dt, n, P)
    if params.valve_characteristic is not None:
        c = params.valve_characteristic
        flags[F_CHAR] = c.code
        P[CH_R], P[CH_H0] = _col(c.R, n), _col(c.h0, n)
    if params.actuator is not None and params.actuator.kind == "pump":
        flags[F_ACT] = 1
    kind = params.process_kind
    flags[F_PROC] = _PROC_CODE[kind]
    pr: Any = params.process        # the class follows process_kind (validated by ModelParams)
    if kind in ("tank", "cascade"):
        P[P_A], P[P_Q], P[P_OUT] = _col(pr.area, n), _col(pr.q_max, n), _col(pr.k_out, n)
    elif kind == "integrating":
        P[P_A], P[P_Q], P[P_OUT] = _col(pr.area, n), _col(pr.q_max, n), _col(pr.q_out, n)
    else:
        P[P_A], P[P_Q], P[P_OUT] = _col(pr.T, n), _col(pr.K, n), _col(pr.b, n)
    if params.cascade is not None:
        P[A2], P[K2] = _col(params.cascade.area2, n), _col(params.cascade.k_out2, n)
    buf_len = _pack_plant_blocks(params, kind, n, P, flags)
    return Packed(P=P, flags=flags, buf_len=buf_len, dt=float(params.dt), params=params)


def _flow_fraction(params: ModelParams, h):
    """Installed characteristic ``f(h)`` (numpy; used for steady states only)."""
    h = np.clip(np.asarray(h, float), 0.0, 1.0)
    c = params.valve_characteristic
    if c is None or (params.actuator is not None and params.actuator.kind == "pump"):
        return h
    h0 = np.asarray(c.h0, float)
    r = np.clip((h - h0) / (1.0 - h0), 0.0, 1.0)
    if c.kind == "linear":
        f = r
    elif c.kind == "equal_percentage":
        f = np.asarray(c.R, float) ** (r - 1.0)
    else:
        f = np.sqrt(r)
    return np.where(h <= h0, 0.0, f)


def steady_input(params: ModelParams, level, n: int | None = None) -> np.ndarray:
    """Stem position that holds the measured level steady (no friction offset).

    For a tank ``q_max f(h) = k sqrt(L)``; inverted on a fine grid for
    non-linear characteristics. Returns ``(n,)`` values in [0, 1].
    """
    if n is None:
        n = max(params.batch_size(), np.size(level))
    level = _col(level, n)
    pr: Any = params.process        # the class follows process_kind (validated by ModelParams)
    if params.process_kind in ("tank", "cascade"):
        k = params.cascade.k_out2 if params.cascade is not None else pr.k_out
        f = _col(k, n) * np.sqrt(np.maximum(level, 0)) / _col(pr.q_max, n)
    elif params.process_kind == "integrating":
        f = _col(pr.q_out, n) / _col(pr.q_max, n)
    else:
        f = (level - _col(pr.b, n)) / _col(pr.K, n)
    if params.leak is not None:
        f = f + _col(params.leak.q_leak, n) / _col(pr.q_max if params.process_kind != "first_order"
                                                   else pr.K, n)
    return _inverse_flow_fraction(params, np.clip(f, 0.0, 1.0), n)


def _inverse_flow_fraction(params: ModelParams, f, n):
    """Smallest stem position ``h`` with ``f(h) = f`` (analytic inverse, O(n))."""
    c = params.valve_characteristic
    if c is None or (params.actuator is not None and params.actuator.kind == "pump"):
        return f.copy()
    h0 = _col(c.h0, n)
    if c.kind == "linear":
        r = f
    elif c.kind == "equal_percentage":
        R = _col(c.R, n)
        with np.errstate(divide="ignore"):
            r = np.where(f > 0, 1.0 + np.log(np.maximum(f, 1e-300)) / np.log(R), 0.0)
    else:
        r = f ** 2
    r = np.clip(r, 0.0, 1.0)
    return np.where(f > 0, h0 + r * (1.0 - h0), 0.0)


def initial_state(params: ModelParams, n: int | None = None, level=None, h=None,
                  level2=None, buf_len: int | None = None) -> State:
    """State at rest: ``z = 0`` (as in the paper), stem at ``h``, levels given.

    Parameters
    ----------
    params : ModelParams
    n : int, batch size (default: from the parameters)
    level : float or (n,), initial level of the (upper) tank / process output;
        default ``params.process.level0``
    h : float or (n,), initial stem position; default the steady input for
        the level, so the model starts near equilibrium
    level2 : float or (n,), lower-tank level (cascade); default ``cascade.level2_0``
    """
    if n is None:
        n = params.batch_size()
    lv = _col(params.process.level0 if level is None else level, n)
    lv2 = _col((params.cascade.level2_0 if params.cascade is not None else 0.0)
               if level2 is None else level2, n)
    meas = lv2 if params.process_kind == "cascade" else lv
    hh = steady_input(params, meas, n) if h is None else _col(h, n)
    if buf_len is None:
        buf_len = pack(params, n, check=False).buf_len
    z = np.zeros(n)
    f0 = _flow_fraction(params, hh)
    buf = np.repeat(np.asarray(f0, float).reshape(n, 1), buf_len, axis=1)
    return State(z=z, h=hh.copy(), x=hh.copy(), u_s=hh.copy(), stuck=np.ones(n), s_dir=np.zeros(n),
                 u_prev=hh.copy(), level=lv.copy(), level2=lv2.copy(), y=meas.copy(),
                 t=np.zeros(n), buf_idx=np.zeros(n), delay_buf=buf)


def state_to_array(state: State) -> np.ndarray:
    """Pack a :class:`State` into the kernel's ``(NS, n)`` array (a copy)."""
    return np.ascontiguousarray(np.stack([np.asarray(a, float) for a in state[:NS]]))


def array_to_state(S: np.ndarray, buf: np.ndarray) -> State:
    """Named views of the kernel's state array (no copy)."""
    return State(*S, delay_buf=buf)


def _as_2d(a, T_expected=None, name="u"):
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2:
        raise ValueError(f"{name} must have shape (T,) or (T, n), got {a.shape}")
    if a.shape[0] == 0:
        raise ValueError(f"{name} is empty; pass at least one sample")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} contains NaN or inf values; pass finite numbers")
    return np.ascontiguousarray(a)


def run_packed(pk: Packed, S: np.ndarray, buf: np.ndarray, U: np.ndarray, D: np.ndarray,
               n_sub: int, Y: np.ndarray, H: np.ndarray, LV: np.ndarray, threads: int = 1,
               bound: Bound | None = None) -> None:
    """Advance the packed state ``S`` in place over the inputs ``U`` (T, n|1).

    The low-overhead path used by the environments. ``U`` and ``D`` must be
    C-contiguous float64 with ``T`` rows (``D`` is read as ``D[k]``; pass
    zeros for no disturbance) and 1 or ``n`` columns; ``Y``, ``H``, ``LV``
    (T, n) receive the measured output, stem position and level after each
    sample. No checks are made here: use :func:`simulate` for checked calls.

    ``threads > 1`` splits the batch into that many column blocks run at once
    in threads (the compiled kernel releases the GIL).  The systems of a batch
    are independent, so the result is bit-for-bit the one of ``threads=1``;
    it pays from about a hundred thousand Euler steps per call
    (``benchmarks/bench_env_speed.py`` measures it).

    ``bound``: each system also sums the squared error of its reading to a
    target and stops once it passes a limit (:class:`Bound`; the fitter's
    early rejection of candidates that cannot beat their rivals).  The
    systems that run to the end are bit for bit those of a run without it.
    """
    n = S.shape[1]
    threads = min(int(threads), n) if HAVE_NUMBA else 1
    if threads <= 1:
        if bound is None:
            _kernel(S, pk.P, U, D, pk.flags, buf, n_sub, pk.dt, Y, H, LV)
        else:
            _kernel_bounded(S, pk.P, U, D, pk.flags, buf, n_sub, pk.dt, Y, H, LV, *_bound_args(bound))
        return
    edges = np.linspace(0, n, threads + 1).astype(int)

    def block(a, b):
        def cols(A):
            return A[:, a:b] if A.shape[1] > 1 else A
        args = (S[:, a:b], cols(pk.P), cols(U), cols(D), pk.flags, buf[a:b] if buf.shape[0] > 1 else buf,
                n_sub, pk.dt, Y[:, a:b], H[:, a:b], LV[:, a:b])
        if bound is None:
            _kernel(*args)
        else:
            _kernel_bounded(*args, *_bound_args(bound, a, b))

    pool = _thread_pool(threads - 1)
    futures = [pool.submit(block, a, b) for a, b in zip(edges[1:-1], edges[2:])]
    block(edges[0], edges[1])          # the calling thread runs the first block itself
    for f in futures:
        f.result()


# this process's kernel threads; a forked child must not use (or wait on) its parent's
_POOL: dict[str, Any] = {"pid": None, "pool": None, "lock": None}


def _thread_pool(n: int):
    """A pool of at least ``n`` kernel threads, made once per process and grown on demand.

    A pool that is replaced is not shut down: a caller in another thread may
    still be submitting to it.
    """
    pid = os.getpid()
    if _POOL["pid"] != pid:
        import threading
        _POOL.update(pid=pid, pool=None, lock=threading.Lock())
    with _POOL["lock"]:
        pool = _POOL["pool"]
        if pool is None or pool._max_workers < n:
            from concurrent.futures import ThreadPoolExecutor
            pool = ThreadPoolExecutor(max_workers=max(n, os.cpu_count() or 1),
                                      thread_name_prefix="valve_gym-kernel")
            _POOL["pool"] = pool
        return pool


def simulate(params: ModelParams, u, state: State | None = None, d=None, n_sub: int = 1,
             n: int | None = None) -> Trajectory:
    """Simulate ``params`` over the input sequence ``u``; pure (inputs untouched).

    Parameters
    ----------
    params : ModelParams, with floats or ``(n,)`` arrays
    u : (T,) or (T, n) array, valve input 0..1 per controller sample
    state : State, initial state (default :func:`initial_state`)
    d : (T,) or (T, n) array, load disturbance inflow (default 0)
    n_sub : int, Euler steps of ``params.dt`` per controller sample
    n : int, batch size (default from params, u and state)

    Returns
    -------
    Trajectory

    Examples
    --------
    >>> import numpy as np
    >>> from valve_gym.params import ModelParams
    >>> tr = simulate(ModelParams(), np.full(100, 0.6), n_sub=50)
    >>> tr.y.shape
    (100, 1)
    >>> bool(tr.y[-1, 0] > 1.0)  # more inflow, the level rises
    True
    """
    U = _as_2d(u, name="u")
    if n is None:
        n = max(params.batch_size(), U.shape[1], state.n if state is not None else 1)
    if U.shape[1] not in (1, n):
        raise ValueError(f"u has {U.shape[1]} columns, expected 1 or n = {n}")
    if not isinstance(n_sub, (int, np.integer)) or n_sub < 1:
        raise ValueError(f"n_sub must be a positive integer, got {n_sub!r}")
    pk = pack(params, n)
    if state is None:
        state = initial_state(params, n, buf_len=pk.buf_len)
    if state.n != n:
        raise ValueError(f"state has batch size {state.n}, expected {n}")
    S = state_to_array(state)
    buf = np.array(state.delay_buf, dtype=np.float64, copy=True)
    if buf.shape != (n, pk.buf_len):
        b2 = np.repeat(buf[:, -1:], pk.buf_len, axis=1) if buf.shape[0] == n else None
        if b2 is None:
            raise ValueError("state.delay_buf does not match the batch size")
        buf = b2
        S[S_BIDX] = 0.0
    D = np.zeros((1, 1)) if d is None else _as_2d(d, name="d")
    T = U.shape[0]
    if D.shape[0] == 1 and T > 1:
        D = np.ascontiguousarray(np.repeat(D, T, axis=0))
    if D.shape[0] != T:
        raise ValueError(f"d has {D.shape[0]} rows, expected {T} (one per sample of u)")
    Y = np.empty((T, n))
    H = np.empty((T, n))
    LV = np.empty((T, n))
    run_packed(pk, S, buf, U, D, int(n_sub), Y, H, LV)
    t = state.t.reshape(-1)[0] + np.arange(1, T + 1) * n_sub * params.dt
    Ucl = np.clip(np.broadcast_to(U, (T, n)), 0.0, 1.0)
    return Trajectory(t=t, u=Ucl, y=Y, h=H, level=LV, final=array_to_state(S, buf))


def step(state: State, u, params: ModelParams, d=None, n_sub: int = 1):
    """One controller sample: ``(state, u (n,)) -> (new_state, y (n,))``; pure.

    Examples
    --------
    >>> from valve_gym.params import ModelParams
    >>> p = ModelParams()
    >>> s0 = initial_state(p, n=3)
    >>> s1, y = step(s0, [0.5, 0.6, 0.7], p, n_sub=10)
    >>> y.shape
    (3,)
    """
    u = np.atleast_1d(np.asarray(u, dtype=np.float64))
    tr = simulate(params, u[None, :], state=state,
                  d=None if d is None else np.atleast_1d(np.asarray(d, float))[None, :],
                  n_sub=n_sub, n=state.n)
    return tr.final, tr.y[0]
