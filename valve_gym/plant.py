"""A plant stepper: ``n`` valve-and-process loops advanced one control period at a time.

:class:`Plant` is what a controller loop, the benchmark, the environments and
the diagnosis fitter share: it holds the packed parameters and the state of
the one physics core (:mod:`valve_gym.core`) and advances them with the valve
input held over each scan (zero-order hold). It starts from rest
(:meth:`Plant.reset`: a level, optionally a stem position anywhere in the
valve's band and, for a cascade, the upper level) or from any core state
(:meth:`Plant.set_state`), and takes new parameters with its state kept
(:meth:`Plant.set_params`). Three ways to advance it:

* :meth:`Plant.step` — one scan, inputs checked, outputs copied (a controller loop);
* :meth:`Plant.advance` — one scan, no checks and no copies, into preallocated
  arrays (the environments, which validated their inputs already);
* :meth:`Plant.run` — an open-loop run over a whole input record in one kernel
  call (the fitter, the teaching figures).

>>> import numpy as np
>>> from valve_gym.friction import valve_model
>>> plant = Plant(valve_model("choudhury", S=0.03, J=0.01), n=2)
>>> out = plant.reset(level=1.0)
>>> out.pv, plant.t
(array([1., 1.]), 0.0)
>>> out = plant.step(np.array([0.6, 0.7]))
>>> out.op.shape, plant.t
((2,), 1.0)
>>> y, stem, level = plant.run(np.full((5, 1), 0.65))
>>> level.shape, plant.t
((5, 2), 6.0)
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


def _index(index, n: int) -> np.ndarray:
    """Loop indices of ``reset(index=...)``: an int array of positions in ``range(n)``."""
    idx = np.asarray(index)
    if idx.dtype == np.bool_:
        if idx.shape != (n,):
            raise ValueError(f"index must be a bool mask of shape ({n},) or integer positions, got shape {idx.shape}")
        return np.flatnonzero(idx)
    if idx.ndim > 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
        raise ValueError(f"index must be integer positions of loops (or a bool mask), got {index!r}")
    idx = idx.reshape(-1).astype(np.int64)
    if idx.size and (idx.min() < -n or idx.max() >= n):
        raise ValueError(f"index {index!r} is out of range for n = {n} loops")
    return idx % n if idx.size else idx


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
    check : bool
        ``True`` (default): refuse parameters the core cannot integrate stably
        (:func:`valve_gym.core.check_dt`) and non-finite or negative initial
        levels. ``False`` skips these checks, for callers that screen many
        candidate parameter rows and handle the ``nan`` columns that invalid
        rows give (the diagnosis fitter); the structural checks (``n``,
        ``scan_s``, input shapes) are always made.

    Raises
    ------
    valve_gym.params.ParameterError
        Bad ``n``, a ``scan_s`` that is not a multiple of ``params.dt``, or
        (with ``check``) parameters the core cannot integrate stably at ``params.dt``.

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

    def __init__(self, params: ModelParams, n: int, scan_s: float = 1.0, threads: int = 1, check: bool = True):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ParameterError(f"n must be a positive integer (number of loops), got {n!r}")
        if not (isinstance(scan_s, (int, float)) and np.isfinite(scan_s) and scan_s > 0):
            raise ParameterError(f"scan_s must be a positive number of seconds, got {scan_s!r}")
        self.n = int(n)
        self.scan_s = float(scan_s)
        self.threads = int(threads)
        self.check = bool(check)
        self._mem = np.zeros((MEM_ROWS, self.n))
        self._U = np.zeros((1, self.n))
        self._D = np.zeros((1, self.n))
        self._D0 = np.zeros((1, 1))
        self._Y = np.empty((1, self.n))
        self._H = np.empty((1, self.n))
        self._LV = np.empty((1, self.n))
        self._S: np.ndarray | None = None
        self._k = 0
        self._configure(params)
        self._buf = np.zeros((self.n, self._pk.buf_len))

    def _configure(self, params: ModelParams) -> None:
        """Check ``params`` against ``n`` and ``scan_s`` and pack them (see :meth:`set_params`)."""
        if not isinstance(params, ModelParams):
            raise ParameterError(f"params must be a valve_gym.params.ModelParams, got {type(params).__name__}")
        n_sub = int(round(self.scan_s / params.dt))
        if n_sub < 1 or abs(n_sub * params.dt - self.scan_s) > 1e-9 * self.scan_s:
            raise ParameterError(f"scan_s = {self.scan_s} s is not a whole multiple of the Euler step "
                                 f"dt = {params.dt} s; choose scan_s = k*dt or set ModelParams(dt=...) to divide it")
        law: SampleLaw | None = None
        packed = params
        sj = params.slip_jump
        if sj is not None and sj.law not in SLIP_JUMP_LAWS:
            if params.friction_model != "none":       # a pump has no valve
                law = friction_spec(sj.law).sample_law
            # the core runs the positioner lag only: a zero band passes its input through unchanged
            packed = replace(params, slip_jump=replace(sj, law="choudhury", S=0.0, J=0.0))
        self._pk = core.pack(packed, self.n, check=self.check)
        self.params = params
        self.n_sub = n_sub
        self._law = law

    # ------------------------------------------------------------------ state
    @property
    def t(self) -> float:
        """Time since the last full :meth:`reset` [s] (scans x ``scan_s``)."""
        return self._k * self.scan_s

    @property
    def sample_law(self) -> SampleLaw | None:
        """The per-scan law of a friction model run outside the kernel (None for the kernel's own models)."""
        return self._law

    @property
    def packed(self) -> core.Packed:
        """The parameters as packed for the kernel (:class:`valve_gym.core.Packed`)."""
        return self._pk

    @property
    def state(self) -> core.State:
        """A copy of the core state (:class:`valve_gym.core.State`)."""
        self._need_reset()
        assert self._S is not None
        return core.array_to_state(self._S.copy(), self._buf.copy())

    def _need_reset(self):
        if self._S is None:
            raise RuntimeError("call Plant.reset() before step(), advance(), run() or state")

    def set_params(self, params: ModelParams) -> None:
        """Replace the parameters, keeping the state of every loop (e.g. a new valve per episode).

        ``params`` must have batch size 1 or ``n`` and ``scan_s`` must be a
        multiple of its ``dt``; checked as at construction. If the new
        parameters need another dead-time buffer length, the state is dropped
        and :meth:`reset` must be called before the next scan.
        """
        buf_len = self._pk.buf_len
        self._configure(params)
        if self._pk.buf_len != buf_len:
            self._S = None
            self._buf = np.zeros((self.n, self._pk.buf_len))

    def reset(self, level=None, stem=None, level_upper=None) -> PlantOutput:
        """Put every loop at rest: the measured tank at ``level``, the valve stuck at ``stem``.

        Parameters
        ----------
        level : float or (n,) array, m, optional
            Level of the measured tank (the lower one for ``cascade``);
            default ``params.process.level0``.
        stem : float or (n,) array, fraction of stroke, optional
            Stem position the valve rests at (friction state ``z = 0``, stuck,
            no direction of motion yet; the last input equals it); default the
            input that holds ``level`` steady (:func:`valve_gym.core.steady_input`).
        level_upper : float or (n,) array, m, optional
            ``cascade`` only: level of the upper tank; default the level that
            feeds the lower one steadily.

        Returns
        -------
        PlantOutput
            ``op`` equals the stem position; :attr:`t` restarts at 0.
        """
        p = self.params
        n = self.n
        lv = core._col(p.process.level0 if level is None else level, n)
        if self.check and (not np.isfinite(lv).all() or (p.process_kind != "integrating" and (lv < 0).any())):
            raise ParameterError(f"level must be finite and >= 0 m, got {level!r}")
        l1 = None
        if level_upper is not None:
            if p.process_kind != "cascade":
                raise ParameterError(f"level_upper is the upper tank of process_kind='cascade'; this plant is "
                                     f"{p.process_kind!r}: leave it out")
            l1 = core._col(level_upper, n)
            if self.check and (not np.isfinite(l1).all() or (l1 < 0).any()):
                raise ParameterError(f"level_upper must be finite and >= 0 m, got {level_upper!r}")
        h = None
        if stem is not None:
            h = core._col(stem, n)
            if self.check and not (np.isfinite(h).all() and (h >= 0).all() and (h <= 1).all()):
                raise ParameterError(f"stem must be a fraction of stroke in 0..1, got {stem!r}")
        st = self._rest_state(lv, h, l1)
        self._S = core.state_to_array(st)
        self._buf = np.ascontiguousarray(st.delay_buf, dtype=np.float64)
        self._k = 0
        self._mem[:] = 0.0
        self._mem[0], self._mem[1] = st.x, st.u_prev
        return PlantOutput(pv=lv.copy(), stem=np.clip(st.h, 0.0, 1.0), op=st.u_prev.copy(), y=st.y.copy())

    def _rest_state(self, lv: np.ndarray, h, l1) -> core.State:
        """The core's rest state of the ``n`` loops, measured level ``lv``."""
        p = self.params
        buf_len = self._pk.buf_len
        if p.process_kind != "cascade":
            return core.initial_state(p, self.n, level=lv, h=h, buf_len=buf_len)
        assert p.cascade is not None
        if l1 is None:
            q = core._col(p.cascade.k_out2, self.n) * np.sqrt(lv)
            if p.leak is not None:
                q = q + core._col(p.leak.q_leak, self.n)
            k1 = core._col(getattr(p.process, "k_out"), self.n)
            with np.errstate(divide="ignore", invalid="ignore"):
                l1 = np.where(k1 > 0, (q / k1) ** 2, lv)
        return core.initial_state(p, self.n, level=l1, level2=lv, h=h, buf_len=buf_len)

    def set_state(self, state: core.State, index=None) -> None:
        """Start loops from an explicit core state (a copy is taken).

        Parameters
        ----------
        state : valve_gym.core.State
            Of ``n`` loops, or of one loop (copied into every loop), e.g. from
            :func:`valve_gym.core.initial_state` (a valve at rest anywhere in
            its band: ``initial_state(params, n, level=..., h=..., level2=...)``)
            or an earlier :attr:`state`. Its ``delay_buf`` must have the plant's
            buffer length (``packed.buf_len``).
        index : int array or (n,) bool mask, optional
            Write only these loops (the others keep their state); without it,
            every loop is written and :attr:`t` restarts at 0.
        """
        if not isinstance(state, core.State):
            raise ValueError(f"state must be a valve_gym.core.State (e.g. from core.initial_state or "
                             f"Plant.state), got {type(state).__name__}")
        S = core.state_to_array(state)
        buf = np.asarray(state.delay_buf, dtype=np.float64)
        n, m, B = self.n, S.shape[1], self._pk.buf_len
        if m not in (1, n) or buf.shape != (m, B):
            raise ValueError(f"state must hold 1 or n = {n} loops with delay_buf of shape (loops, {B}); got "
                             f"{m} loops and delay_buf {buf.shape}")
        if self.check and not (np.isfinite(S).all() and np.isfinite(buf).all()):
            raise ParameterError("state contains NaN or inf values; pass a finite state")
        if index is None:
            self._S = S if m == n else np.repeat(S, n, axis=1)
            self._buf = np.repeat(buf, n, axis=0) if m == 1 and n > 1 else buf.copy()
            self._k = 0
            cols: slice | np.ndarray = slice(None)
        else:
            if self._S is None:
                raise RuntimeError("set_state(index=...) writes some loops of a running plant: call reset() "
                                   "or set_state() without index first")
            cols = _index(index, n)
            self._S[:, cols] = S if m == 1 else S[:, cols]
            self._buf[cols] = buf if m == 1 else buf[cols]
        mem = self._mem
        mem[:, cols] = 0.0
        mem[0, cols] = self._S[core.S_X, cols]
        mem[1, cols] = self._S[core.S_UPREV, cols]

    # ------------------------------------------------------------------ scans
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
        Y, H, LV = self.advance(U, self._D)
        return PlantOutput(pv=LV[0].copy(), stem=H[0].copy(), op=U[0].copy(), y=Y[0].copy())

    def advance(self, u: np.ndarray, d: np.ndarray | None = None, out=None):
        """Advance every loop by one scan, with no checks and no copies (inputs already validated).

        Parameters
        ----------
        u : (1, n) or (1, 1) C-contiguous float64 array
            Valve input of the scan (the kernel saturates it to 0..1).
        d : (1, n) or (1, 1) C-contiguous float64 array, optional
            Extra inflow over the scan (default none).
        out : tuple of three (1, n) float64 arrays, optional
            ``(y, stem, level)`` to write into; default the plant's own, which
            the next scan overwrites.

        Returns
        -------
        y, stem, level : (1, n) arrays
            The arrays of ``out``, after the scan.
        """
        S = self._S
        if S is None:
            raise RuntimeError("call Plant.reset() before step(), advance(), run() or state")
        Y, H, LV = (self._Y, self._H, self._LV) if out is None else out
        if self._law is not None:
            u = self._sample(u)
        core.run_packed(self._pk, S, self._buf, u, self._D0 if d is None else d, self.n_sub, Y, H, LV,
                        threads=self.threads)
        self._k += 1
        return Y, H, LV

    def scan_args(self, u: np.ndarray, d: np.ndarray, out) -> tuple:
        """The arguments of :func:`valve_gym.core.run_packed` for one scan, for the tightest loops.

        ``core.run_packed(*plant.scan_args(u, d, out))`` advances the loops as
        :meth:`advance` does (same arrays, bit for bit), without its Python
        frame, reading ``u`` and ``d`` (1, n|1) and writing ``out`` (three (1, n)
        arrays) in place at each call; :attr:`t` does not advance. The tuple
        holds the plant's current arrays: make it again after :meth:`reset`,
        :meth:`set_state` or :meth:`set_params`. Not for a friction model with a
        per-scan ``sample_law`` (ValueError), which needs :meth:`advance`.
        """
        self._need_reset()
        if self._law is not None:
            raise ValueError(f"friction model {self.params.friction_model!r} runs a per-scan law outside the "
                             f"kernel: use Plant.advance()")
        Y, H, LV = out
        return (self._pk, self._S, self._buf, u, d, self.n_sub, Y, H, LV)

    def _sample(self, u: np.ndarray) -> np.ndarray:
        """The friction model's per-scan law on the saturated input: what drives the positioner, ``(1, n)``."""
        assert self.params.slip_jump is not None and self._law is not None
        x = np.clip(np.broadcast_to(u[0], (self.n,)), 0.0, 1.0)
        return self._law(x, self._mem, self.params.slip_jump).reshape(1, self.n)

    def run(self, U, D=None, out=None, threads: int | None = None):
        """Open-loop run over a whole input record from the current state (one kernel call).

        Parameters
        ----------
        U : (T,), (T, 1) or (T, n) array
            Valve input of each scan, fraction 0..1 (saturated by the kernel);
            one column is shared by every loop.
        D : (T,), (T, 1) or (T, n) array, optional
            Extra inflow over each scan (default none).
        out : tuple of three (T, n) float64 arrays, optional
            ``(y, stem, level)`` to write into (reused scratch); default new arrays.
        threads : int, optional
            Kernel threads for this run (default :attr:`threads`).

        Returns
        -------
        y, stem, level : (T, n) arrays
            Sensor output, stem position and measured level after each scan;
            the plant's state and :attr:`t` have advanced by ``T`` scans.

        Notes
        -----
        Equal bit for bit to ``T`` calls of :meth:`advance` (or :meth:`step`
        with inputs in 0..1). A friction model with a per-scan ``sample_law``
        runs scan by scan (``T`` kernel calls).
        """
        self._need_reset()
        U = self._record(U, "U")
        T = U.shape[0]
        if D is None:
            D = np.zeros((T, 1))
        else:
            D = self._record(D, "D")
            if D.shape[0] != T:
                raise ValueError(f"D has {D.shape[0]} rows, expected {T} (one per row of U)")
        if out is None:
            out = (np.empty((T, self.n)), np.empty((T, self.n)), np.empty((T, self.n)))
        elif len(out) != 3 or any(np.shape(a) != (T, self.n) or np.asarray(a).dtype != np.float64 for a in out):
            raise ValueError(f"out must be three float64 arrays of shape (T, n) = ({T}, {self.n})")
        Y, H, LV = out
        threads = self.threads if threads is None else int(threads)
        if self._law is None:
            assert self._S is not None
            core.run_packed(self._pk, self._S, self._buf, U, D, self.n_sub, Y, H, LV, threads=threads)
            self._k += T
        else:
            for k in range(T):
                self.advance(U[k:k + 1], D[k:k + 1], out=(Y[k:k + 1], H[k:k + 1], LV[k:k + 1]))
        return Y, H, LV

    def _record(self, a, name: str) -> np.ndarray:
        """``a`` as a checked C-contiguous float64 (T, 1|n) record."""
        try:
            r = np.asarray(a, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be an array of numbers, got {type(a).__name__}") from None
        if r.ndim == 1:
            r = r[:, None]
        if r.ndim != 2 or r.shape[0] < 1 or r.shape[1] not in (1, self.n):
            raise ValueError(f"{name} must have shape (T,), (T, 1) or (T, n) = (T, {self.n}) with T >= 1, "
                             f"got {np.shape(a)}")
        if not np.isfinite(r).all():
            raise ValueError(f"{name} contains NaN or inf values; pass finite numbers")
        return np.ascontiguousarray(r)
