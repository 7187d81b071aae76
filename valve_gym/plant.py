"""A plant stepper: ``n`` valve-and-process loops advanced one control period at a time.

:class:`Plant` is what a controller loop, the benchmark and the environments
share: it holds the packed parameters and the state of the one physics core
(:mod:`valve_gym.core`) and advances them by one scan with the valve input held
(zero-order hold), with no per-step checks beyond the input's.

>>> import numpy as np
>>> from valve_gym.friction import valve_model
>>> plant = Plant(valve_model("choudhury", S=0.03, J=0.01), n=2)
>>> out = plant.reset(level=1.0)
>>> out.pv, plant.t
(array([1., 1.]), 0.0)
>>> out = plant.step(np.array([0.6, 0.7]))
>>> out.op.shape, plant.t
((2,), 1.0)
"""
from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np

from . import core
from .friction.spec import MEM_ROWS, SampleLaw, friction_spec
from .params import SLIP_JUMP_LAWS, ModelParams, ParameterError

__all__ = ["Plant", "PlantOutput"]


class PlantOutput(NamedTuple):
    """What the plant shows after a reset or a scan, each an ``(n,)`` float array.

    pv : true (noise-free) level of the measured tank [m] (process output for ``first_order``)
    stem : stem position, fraction of stroke 0..1
    op : valve input applied over the scan, after saturation to 0..1
    y : level seen through the sensor (equals ``pv`` without ``sensor_lag``) [m]
    """

    pv: np.ndarray
    stem: np.ndarray
    op: np.ndarray
    y: np.ndarray


class Plant:
    """``n`` independent loops of ``params`` advanced one control period (scan) per :meth:`step`.

    Parameters
    ----------
    params : ModelParams
        Plant and valve (floats or ``(n,)`` arrays), e.g. from
        :func:`valve_gym.friction.valve_model`.
    n : int
        Number of loops in the batch.
    scan_s : float, s
        Control period; a whole multiple of ``params.dt`` (``scan_s / dt``
        Euler steps per scan).
    threads : int
        Kernel threads for large batches (see :func:`valve_gym.core.run_packed`).

    Raises
    ------
    valve_gym.params.ParameterError
        Bad ``n``, a ``scan_s`` that is not a multiple of ``params.dt``, or
        parameters the core cannot integrate stably at ``params.dt``.

    Notes
    -----
    A friction model registered with a ``sample_law`` (not compiled into the
    kernel, see :class:`valve_gym.friction.FrictionSpec`) is applied here, once
    per scan, to the input; its output drives the core's positioner lag.

    :meth:`reset` leaves the valve in the core's rest state
    (:func:`valve_gym.core.initial_state`: stuck, no direction of motion yet).
    From there Kano's model (and He's example) first slips after ``(S + J)/2``
    of input either way with a jump ``J``; the core's Choudhury block, whose
    flow chart tests the distance as ``|u - u_s|``, first slips after ``J``
    to ``u -+ (S - J)/2`` (a step against the input when ``J < S/3``), and
    behaves as the paper's model from its first reversal on.
    """

    def __init__(self, params: ModelParams, n: int, scan_s: float = 1.0, threads: int = 1):
        if not isinstance(params, ModelParams):
            raise ParameterError(f"params must be a valve_gym.params.ModelParams, got {type(params).__name__}")
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ParameterError(f"n must be a positive integer (number of loops), got {n!r}")
        if not (isinstance(scan_s, (int, float)) and np.isfinite(scan_s) and scan_s > 0):
            raise ParameterError(f"scan_s must be a positive number of seconds, got {scan_s!r}")
        n_sub = int(round(scan_s / params.dt))
        if n_sub < 1 or abs(n_sub * params.dt - scan_s) > 1e-9 * scan_s:
            raise ParameterError(f"scan_s = {scan_s} s is not a whole multiple of the Euler step dt = {params.dt} s; "
                                 f"choose scan_s = k*dt or set ModelParams(dt=...) to divide it")
        self.params = params
        self.n = int(n)
        self.scan_s = float(scan_s)
        self.n_sub = n_sub
        self.threads = int(threads)
        self._law: SampleLaw | None = None
        self._mem = np.zeros((MEM_ROWS, self.n))
        sj = params.slip_jump
        if sj is not None and sj.law not in SLIP_JUMP_LAWS:
            if params.friction_model != "none":       # a pump has no valve
                self._law = friction_spec(sj.law).sample_law
            # the core runs the positioner lag only: a zero band passes its input through unchanged
            params = replace(params, slip_jump=replace(sj, law="choudhury", S=0.0, J=0.0))
        self._pk = core.pack(params, self.n)
        self._U = np.zeros((1, self.n))
        self._D = np.zeros((1, self.n))
        self._Y = np.empty((1, self.n))
        self._H = np.empty((1, self.n))
        self._LV = np.empty((1, self.n))
        self._S: np.ndarray | None = None
        self._k = 0
        self._buf = np.zeros((self.n, self._pk.buf_len))

    # ------------------------------------------------------------------ state
    @property
    def t(self) -> float:
        """Time since the last :meth:`reset` [s] (scans x ``scan_s``)."""
        return self._k * self.scan_s

    @property
    def state(self) -> core.State:
        """A copy of the core state (:class:`valve_gym.core.State`)."""
        self._need_reset()
        assert self._S is not None
        return core.array_to_state(self._S.copy(), self._buf.copy())

    def _need_reset(self):
        if self._S is None:
            raise RuntimeError("call Plant.reset() before step() or state")

    def reset(self, level=None) -> PlantOutput:
        """Steady state at ``level`` with the valve resting at the input that holds it.

        Parameters
        ----------
        level : float or (n,) array, m, optional
            Level of the measured tank (the lower one for ``cascade``);
            default ``params.process.level0``. For ``cascade`` the upper tank
            starts at the level that feeds the lower one steadily.

        Returns
        -------
        PlantOutput
            ``op`` and ``stem`` equal the steady input.
        """
        p = self.params
        lv = core._col(p.process.level0 if level is None else level, self.n)
        if not np.isfinite(lv).all() or (p.process_kind != "integrating" and (lv < 0).any()):
            raise ParameterError(f"level must be finite and >= 0 m, got {level!r}")
        if p.process_kind == "cascade":
            assert p.cascade is not None
            q = core._col(p.cascade.k_out2, self.n) * np.sqrt(lv)
            if p.leak is not None:
                q = q + core._col(p.leak.q_leak, self.n)
            k1 = core._col(getattr(p.process, "k_out"), self.n)
            with np.errstate(divide="ignore", invalid="ignore"):
                l1 = np.where(k1 > 0, (q / k1) ** 2, lv)
            st = core.initial_state(p, self.n, level=l1, level2=lv, buf_len=self._pk.buf_len)
        else:
            st = core.initial_state(p, self.n, level=lv, buf_len=self._pk.buf_len)
        self._S = core.state_to_array(st)
        self._k = 0
        self._mem[:] = 0.0
        self._mem[0] = st.x
        self._mem[1] = st.u_prev
        self._buf = np.ascontiguousarray(st.delay_buf, dtype=np.float64)
        h = np.clip(st.h, 0.0, 1.0)
        return PlantOutput(pv=lv.copy(), stem=h, op=st.u_prev.copy(), y=st.y.copy())

    def step(self, op, d=None) -> PlantOutput:
        """Advance every loop by one scan with valve input ``op`` held.

        Parameters
        ----------
        op : float or (n,) array
            Valve input, fraction 0..1 (saturated to that range).
        d : float or (n,) array, optional
            Extra inflow over the scan, m^3/s (process units for
            ``first_order``); negative for an offtake.

        Returns
        -------
        PlantOutput
            At the end of the scan.
        """
        self._need_reset()
        U = self._U
        a = np.asarray(op, dtype=float)
        if a.ndim > 1 or a.size not in (1, self.n):
            raise ValueError(f"op must be a number or an (n,) = ({self.n},) array, got shape {a.shape}")
        U[0] = a
        if not np.isfinite(U).all():
            raise ValueError(f"op contains NaN or inf: {op!r}; pass valve inputs in 0..1")
        np.clip(U, 0.0, 1.0, out=U)
        if d is None:
            self._D[0] = 0.0
        else:
            b = np.asarray(d, dtype=float)
            if b.ndim > 1 or b.size not in (1, self.n):
                raise ValueError(f"d must be a number or an (n,) = ({self.n},) array, got shape {b.shape}")
            self._D[0] = b
            if not np.isfinite(self._D).all():
                raise ValueError(f"d contains NaN or inf: {d!r}; pass inflows in m^3/s")
        assert self._S is not None
        X = U
        if self._law is not None:
            assert self.params.slip_jump is not None
            X = np.empty_like(U)
            X[0] = self._law(U[0].copy(), self._mem, self.params.slip_jump)
        core.run_packed(self._pk, self._S, self._buf, X, self._D, self.n_sub, self._Y, self._H, self._LV,
                        threads=self.threads)
        self._k += 1
        return PlantOutput(pv=self._LV[0].copy(), stem=self._H[0].copy(), op=U[0].copy(), y=self._Y[0].copy())
