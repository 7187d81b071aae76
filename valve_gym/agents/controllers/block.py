"""The DCS function-block interface shared by every controller of valve_gym.

A controller is a block a plant would run once per scan (IEC 61131-3 PID
block, simple-pid's ``PID(...)(pv)`` feel)::

    ctrl.reset(sp, pv, op)     # bumpless start from the valve input op now applied
    op = ctrl.step(sp, pv)     # one scan of ctrl.scan_s seconds

``sp`` and ``pv`` are levels [m], ``op`` the valve input as a fraction of the
stroke (0..1). Scalars give a float back; ``(n,)`` arrays run ``n``
independent loops in one object and give an ``(n,)`` array back (a scalar
``sp`` is shared by all loops). The block's memory is an explicit named tuple
of ``(n,)`` arrays (:attr:`FunctionBlock.state`), advanced by the pure methods
:meth:`FunctionBlock.initial_state` and :meth:`FunctionBlock.advance`;
``reset``/``step`` only keep it between calls.

Settings are declared per block as :class:`Setting` rows; :func:`resolve_settings`
checks names, types and ranges and fills defaults, so a typo or an
out-of-range value is a :class:`ValueError` that lists what is allowed.
Settings marked ``per_loop`` (the gains, the stiction estimate ``S`` and what
the rules derive from it) also take an ``(n,)`` array, one value per loop: one
block then runs ``n`` loops with different estimates, exactly as ``n`` blocks
would. ``ctrl.settings`` gives them back as lists (JSON-able).
"""
from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

__all__ = ["Setting", "FunctionBlock", "resolve_settings", "check_inputs", "check_step_inputs", "merge_rows",
           "whole_scans", "json_settings", "fmt", "PVGuard", "PV_RANGE"]

ArrayOrFloat = float | np.ndarray


@dataclass(frozen=True)
class Setting:
    """One setting of a block: name, unit, default and allowed range.

    Attributes
    ----------
    name : str
    unit : str, unit of the value ('-' for fractions of the stroke)
    default : float or None, None means "set by the block's rule" (documented
        in ``doc``) once the other settings are known
    lo, hi : float, allowed closed range ``[lo, hi]`` (``lo`` excluded when
        ``lo_open``)
    doc : str, one line for error messages and listings
    lo_open : bool
    per_loop : bool, the setting may also be an ``(n,)`` array, one value per
        loop (e.g. each loop's stiction estimate ``S``)
    """

    name: str
    unit: str
    default: float | None
    lo: float
    hi: float
    doc: str
    lo_open: bool = False
    per_loop: bool = False

    def describe(self) -> str:
        """``name [unit] in [lo, hi]`` for error messages."""
        left = "(" if self.lo_open else "["
        return f"{self.name} [{self.unit}] in {left}{self.lo:g}, {self.hi:g}]"

    def check(self, block: str, value: Any) -> float | np.ndarray:
        """The value as a float (or a float array for ``per_loop``), or a ValueError naming the range."""
        if self.per_loop and isinstance(value, (list, tuple, np.ndarray)):
            a = np.asarray(value)
            if a.ndim != 1 or a.size == 0 or a.dtype.kind not in "iuf":
                raise ValueError(f"{block}: setting {self.name} must be a number or a non-empty (n,) array of "
                                 f"numbers (one per loop), got {type(value).__name__} of shape {a.shape}")
            a = a.astype(np.float64)
            below = a <= self.lo if self.lo_open else a < self.lo
            bad = ~np.isfinite(a) | below | (a > self.hi)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise ValueError(f"{block}: setting {self.name}[{i}] = {float(a[i])!r} is out of range; "
                                 f"allowed: {self.describe()} ({self.doc})")
            return a
        ok_type = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
        if not ok_type:
            kind = "a number or an (n,) array of numbers" if self.per_loop else "a number"
            raise ValueError(f"{block}: setting {self.name} must be {kind} ({self.doc}), got "
                             f"{value!r} of type {type(value).__name__}; allowed: {self.describe()}")
        v = float(value)
        below = v <= self.lo if self.lo_open else v < self.lo
        if not math.isfinite(v) or below or v > self.hi:
            raise ValueError(f"{block}: setting {self.name} = {value!r} is out of range; "
                             f"allowed: {self.describe()} ({self.doc})")
        return v


def resolve_settings(block: str, table: tuple[Setting, ...], given: dict) -> dict:
    """Check ``given`` against ``table``; defaults filled (None stays None for rules).

    Raises
    ------
    ValueError
        For an unknown key (listing the known ones), a non-number or a value out
        of range (naming the range).

    Examples
    --------
    >>> t = (Setting("a", "-", 0.5, 0.0, 1.0, "amplitude"),)
    >>> resolve_settings("x", t, {})
    {'a': 0.5}
    >>> resolve_settings("x", t, {"b": 1})
    Traceback (most recent call last):
    ...
    ValueError: x: unknown setting(s) ['b']; known settings: a [-] in [0, 1]
    """
    known = {s.name: s for s in table}
    unknown = sorted(set(given) - set(known))
    if unknown:
        listing = ", ".join(s.describe() for s in table)
        raise ValueError(f"{block}: unknown setting(s) {unknown}; known settings: {listing}")
    out = {}
    for s in table:
        v = given.get(s.name, s.default)
        out[s.name] = None if v is None else s.check(block, v)
    return out


def json_settings(settings: dict) -> dict:
    """Settings with per-loop arrays as lists (JSON-able)."""
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in settings.items()}


def fmt(v) -> str:
    """A setting for messages: ``0.02`` or ``[0.01, 0.02, ...]``."""
    if isinstance(v, np.ndarray):
        head = ", ".join(f"{x:g}" for x in v[:4])
        return f"[{head}{', ...' if v.size > 4 else ''}]"
    return f"{v:g}"


def whole_scans(block: str, name: str, value: float, scan_s: float) -> int:
    """``value`` [s] as a whole number (>= 1) of scans, or a ValueError saying so."""
    k = value / scan_s
    ki = int(round(k))
    if ki < 1 or abs(k - ki) > 1e-9 * max(1.0, k):
        raise ValueError(f"{block}: setting {name} = {value!r} s must be a whole number (>= 1) of "
                         f"scans of scan_s = {scan_s!r} s; the block acts once per scan")
    return ki


#: Default plausible range of the set point and the measurement [PV units]: a value outside it (a
#: historian's bad-value code such as -3.4e38, an overflow) is a bad measurement, as is NaN or inf.
PV_RANGE = (-1.0e6, 1.0e6)


def _pv_range(block: str, value) -> tuple[float, float]:
    """``value`` as a checked ``(lo, hi)`` pair of finite floats with ``lo < hi``."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{block}: pv_range must be a pair (lo, hi) of numbers in the PV's units, got "
                         f"{value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ValueError(f"{block}: pv_range must be finite with lo < hi, got {value!r}")
    return lo, hi


class PVGuard:
    """The bad-measurement hold of a DCS block: a scan with a bad SP or PV keeps the last output.

    A measurement is bad when it is NaN or inf or outside ``pv_range`` (the plausible range of the
    loop's PV, default :data:`PV_RANGE`; give the transmitter's range, e.g. ``(0, 2)`` m, to catch
    codes such as 9999 too).  On such a scan the block does what a DCS PID block does with a
    ``BAD`` PV status: it holds its output and its memory (no integration on a value that is not a
    measurement), and it says so: :attr:`held` marks the loops held on the last scan,
    :attr:`bad_pv_scans` counts them per loop, and a ``RuntimeWarning`` is issued once per block.

    Parameters
    ----------
    block : str, the block's name (for messages)
    pv_range : (2,) float, [PV units]
    """

    def __init__(self, block: str, pv_range=PV_RANGE):
        self.block = block
        self.pv_range = _pv_range(block, pv_range)
        self.held = np.zeros(0, dtype=bool)
        self.bad_pv_scans = np.zeros(0, dtype=np.int64)
        self.last_op = np.zeros(0)
        self._warned = False

    def start(self, op: np.ndarray) -> None:
        """At ``reset``: the output now applied ``op`` (n,); counters cleared."""
        self.last_op = np.asarray(op, float).copy()
        self.held = np.zeros(op.shape, dtype=bool)
        self.bad_pv_scans = np.zeros(op.shape, dtype=np.int64)

    def screen(self, sp: np.ndarray, pv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(sp, pv, bad)``: the bad loops' signals replaced by harmless values, ``bad`` (n,) bool."""
        lo, hi = self.pv_range
        with np.errstate(invalid="ignore"):
            bad = ~(np.isfinite(sp) & np.isfinite(pv) & (pv >= lo) & (pv <= hi) & (sp >= lo) & (sp <= hi))
        if bad.any():
            sp = np.where(bad, 0.0, sp)
            pv = np.where(bad, 0.0, pv)
            if not self._warned:
                import warnings

                self._warned = True
                warnings.warn(f"{self.block}: bad measurement (NaN, inf or outside pv_range = {self.pv_range}) "
                              f"at loop(s) {np.flatnonzero(bad)[:10].tolist()}; output held at its last value "
                              f"while it lasts (see .held, .bad_pv_scans)", RuntimeWarning, stacklevel=4)
        return sp, pv, bad

    def finish(self, op: np.ndarray, bad: np.ndarray) -> np.ndarray:
        """The output of this scan: ``op`` where the measurement was good, the last output where not."""
        if bad.any():
            op = np.where(bad, self.last_op, op)
        self.held = bad
        self.bad_pv_scans = self.bad_pv_scans + bad
        self.last_op = np.asarray(op, float).copy()
        return op


def _as_array(block: str, name: str, x, allow_bad: bool = False) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{block}: {name} must be a number or an (n,) array of numbers, "
                         f"got {type(x).__name__}") from None
    if a.ndim > 1:
        raise ValueError(f"{block}: {name} must be a scalar or an (n,) array (one value per loop), "
                         f"got shape {a.shape}; flatten it or pass one loop per entry")
    bad = ~np.isfinite(a)
    if bad.any() and not allow_bad:
        where = "" if a.ndim == 0 else f" at loop(s) {np.flatnonzero(bad)[:10].tolist()}"
        raise ValueError(f"{block}: {name} contains NaN or inf{where}; pass finite values "
                         f"(hold the last good measurement while a signal is bad)")
    return a


def check_inputs(block: str, allow_bad: bool = False, **signals) -> tuple[tuple[np.ndarray, ...], int, bool]:
    """Signals as ``(n,)`` float arrays with one common ``n``.

    Returns
    -------
    arrays : tuple of (n,) float64 arrays, in the order given
    n : int, number of loops
    scalar : bool, True when every signal was a scalar

    Raises
    ------
    ValueError
        For non-numbers, arrays of more than one dimension, NaN/inf, or arrays
        of different lengths (naming each length).

    Examples
    --------
    >>> (sp, pv), n, scalar = check_inputs("pi", sp=1.0, pv=[0.9, 1.1])
    >>> sp, n, scalar
    (array([1., 1.]), 2, False)
    """
    arrs = {k: _as_array(block, k, v, allow_bad) for k, v in signals.items()}
    sizes = {k: a.shape[0] for k, a in arrs.items() if a.ndim == 1}
    if len(set(sizes.values())) > 1:
        raise ValueError(f"{block}: the loops' signals have different lengths {sizes}; pass (n,) arrays "
                         "of one length n (or scalars, shared by all loops)")
    n = next(iter(sizes.values())) if sizes else 1
    if n == 0:
        raise ValueError(f"{block}: got empty arrays; pass at least one loop")
    out = tuple(np.broadcast_to(a, (n,)).astype(np.float64) for a in arrs.values())
    return out, n, not sizes


def check_step_inputs(block: str, n_loops: int, sp, pv, allow_bad: bool = False
                      ) -> tuple[np.ndarray, np.ndarray, bool]:
    """``step()``'s set point and measurement as ``(n_loops,)`` arrays, for a block reset with ``n_loops`` loops.

    Returns
    -------
    sp, pv : (n_loops,) float64 arrays (scalars are shared by all loops)
    scalar : bool, True when both were scalars

    Raises
    ------
    ValueError
        As :func:`check_inputs`, and for arrays of another length than ``reset()`` was given.
        NaN and inf pass when ``allow_bad`` (a block's :class:`PVGuard` holds those scans).

    Examples
    --------
    >>> check_step_inputs("pi", 1, 1.0, [0.9, 1.0])
    Traceback (most recent call last):
    ...
    ValueError: pi: reset() was given 1 loop(s) but step() 2; call reset(sp, pv, op) again for the new set of loops
    """
    (sp, pv), n, scalar = check_inputs(block, allow_bad, sp=sp, pv=pv)
    if scalar:                      # scalars are shared by all loops
        return np.full(n_loops, sp[0]), np.full(n_loops, pv[0]), True
    if n != n_loops:
        raise ValueError(f"{block}: reset() was given {n_loops} loop(s) but step() {n}; "
                         "call reset(sp, pv, op) again for the new set of loops")
    return sp, pv, False


def merge_rows(mask: np.ndarray, fresh, old):
    """Rows of state ``fresh`` where ``mask``, of ``old`` elsewhere (nested named tuples)."""
    if isinstance(fresh, tuple):
        return type(fresh)(*(merge_rows(mask, f, o) for f, o in zip(fresh, old)))
    return np.where(mask, fresh, old)


def check_op_limits(block: str, op: np.ndarray, lo: float, hi: float) -> None:
    """Refuse a start from an output outside ``[lo, hi]`` (the first scan would clip it: a bump)."""
    if np.any(op < lo) or np.any(op > hi):
        raise ValueError(f"{block}: op must be the valve input now applied, within the output limits "
                         f"[op_lo, op_hi] = [{lo:g}, {hi:g}], got {op.tolist()[:10]}")


def not_reset_error(block: str) -> ValueError:
    """The error of ``step()`` called before ``reset()``, the same for every block."""
    return ValueError(f"{block}: step() called before reset(); call reset(sp, pv, op) first "
                      "with the valve input now applied (bumpless start)")


def _rule_inputs(p: dict, s: Setting) -> str:
    """The settings that a rule-made setting ``s`` reads, as ``name=value`` (those its doc names)."""
    import re

    words = set(re.findall(r"[A-Za-z_]+", s.doc))
    used = [f"{k}={fmt(v)}" for k, v in p.items() if k != s.name and k in words]
    return ", ".join(used) or "the other settings"


class GuardedBlock:
    """What a block with a :class:`PVGuard` (``self.guard``) reports of its bad-measurement holds."""

    guard: PVGuard

    @property
    def held(self) -> np.ndarray:
        """(n,) bool: the loops whose output the last scan held on a bad measurement (see :class:`PVGuard`)."""
        return self.guard.held

    @property
    def bad_pv_scans(self) -> np.ndarray:
        """(n,) int: scans held on a bad measurement since :meth:`reset`, per loop."""
        return self.guard.bad_pv_scans


def _acting(method, name: str):
    """``method`` (a block's ``initial_state`` or ``advance``) on ``action * sp``, ``action * pv``.

    A direct-acting loop (``action`` -1: opening the valve lowers pv) is the reverse-acting loop of the mirrored
    measurement, so every block's law, written for the reverse-acting case, serves both. The sign is applied
    once per call from outside: a subclass's override that calls ``super()`` is not mirrored twice. A block
    whose loops are all reverse acting (``_mirror`` None, set at construction) pays one attribute lookup.
    """
    def mirrored(self, sp, pv, call):
        if self._acting:
            return call(sp, pv)
        a = self._mirror
        self._acting = True
        try:
            return call(a * np.asarray(sp, float), a * np.asarray(pv, float))
        finally:
            self._acting = False

    if name == "initial_state":
        @functools.wraps(method)
        def start(self, sp, pv, op):
            if self._mirror is None:
                return method(self, sp, pv, op)
            return mirrored(self, sp, pv, lambda s, p: method(self, s, p, op))
        return start

    @functools.wraps(method)
    def scan(self, state, sp, pv):
        if self._mirror is None:
            return method(self, state, sp, pv)
        return mirrored(self, sp, pv, lambda s, p: method(self, state, s, p))
    return scan


class FunctionBlock(GuardedBlock, ABC):
    """Base of the controller blocks: settings, validation, reset/step.

    Subclasses declare ``name`` and ``SETTINGS`` and implement
    :meth:`initial_state` and :meth:`advance` (pure functions of explicit
    ``(n,)`` state arrays). Where the settings have an ``action`` (the PI's: +1
    reverse, -1 direct acting), both see ``action * sp`` and ``action * pv``:
    the subclass writes its law for the reverse-acting loop only.

    Attributes
    ----------
    name : str, registry name of the block
    settings : dict, the resolved settings (JSON-able: floats, or lists for
        per-loop settings given as arrays)
    scan_s : float, scan time [s]
    """

    name: ClassVar[str] = "block"
    SETTINGS: ClassVar[tuple[Setting, ...]] = ()
    #: the ``action`` of each loop where some loop is direct acting, None where all are reverse acting
    _mirror: Any = None
    _acting: bool = False

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        for name in ("initial_state", "advance"):
            if name in cls.__dict__ and not getattr(cls.__dict__[name], "__isabstractmethod__", False):
                setattr(cls, name, _acting(cls.__dict__[name], name))

    def __init__(self, pv_range=PV_RANGE, **settings):
        #: the bad-measurement hold (see :class:`PVGuard`); ``pv_range`` [PV units] its plausible range
        self.guard = PVGuard(self.name, pv_range)
        #: resolved settings as floats or (n,) float arrays, for the block's arithmetic
        given = resolve_settings(self.name, self.SETTINGS, settings)
        ruled = [k for k, v in given.items() if v is None]
        self.p: dict[str, Any] = self._resolve(given)
        action = self.p.get("action", 1.0)
        self._mirror = None if np.all(np.asarray(action) == 1.0) else action
        for s in self.SETTINGS:
            if s.name in ruled:
                try:
                    s.check(self.name, self.p[s.name])
                except ValueError:
                    raise ValueError(f"{self.name}: the rule for {s.name} ({s.doc}) gives {fmt(self.p[s.name])} "
                                     f"with these settings, outside its range {s.describe()}; check the settings "
                                     f"it is made from ({_rule_inputs(self.p, s)}: each in the PV's units where it "
                                     f"has one) or give {s.name} explicitly") from None
        self.loops()
        self._state: Any = None
        self._n: int | None = None
        self._scalar = False

    def _resolve(self, settings: dict) -> dict:
        """Fill rule-based defaults and check settings against each other."""
        return settings

    @property
    def settings(self) -> dict:
        """The resolved settings, JSON-able (per-loop arrays as lists)."""
        return json_settings(self.p)

    @property
    def scan_s(self) -> float:
        """Scan time [s]."""
        return float(self.p["scan_s"])

    def loops(self) -> int | None:
        """Number of loops fixed by per-loop settings (None: any)."""
        sizes = {k: v.size for k, v in self.p.items() if isinstance(v, np.ndarray)}
        if len(set(sizes.values())) > 1:
            raise ValueError(f"{self.name}: per-loop settings have different lengths {sizes}; give one value "
                             "per loop for every array setting (or scalars)")
        return next(iter(sizes.values())) if sizes else None

    @property
    def state(self) -> Any:
        """The block's memory (named tuple of ``(n,)`` arrays), None before :meth:`reset`."""
        return self._state

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={fmt(v)}" for k, v in self.p.items())
        return f"load_controller({self.name!r}, {args})"

    def reset(self, sp, pv, op) -> None:
        """Start bumplessly from the valve input ``op`` now applied.

        Parameters
        ----------
        sp, pv : float or (n,) array, set point and measured level [m]
        op : float or (n,) array, valve input now applied [0..1]
        """
        (sp, pv, op), n, scalar = check_inputs(self.name, sp=sp, pv=pv, op=op)
        want = self.loops()
        if want is not None and n != want:
            if not scalar:
                raise ValueError(f"{self.name}: the per-loop settings are for {want} loops, reset() got {n}; "
                                 "pass one sp, pv, op per loop")
            sp, pv, op = (np.full(want, x[0]) for x in (sp, pv, op))
            n, scalar = want, False
        check_op_limits(self.name, op, self.p["op_lo"], self.p["op_hi"])
        self._state = self.initial_state(sp, pv, op)
        self._n, self._scalar = n, scalar
        self.guard.start(op)

    def step(self, sp, pv) -> ArrayOrFloat:
        """One scan: the valve input to apply for the next ``scan_s`` seconds.

        A loop whose ``sp`` or ``pv`` is bad (NaN, inf, outside ``pv_range``) keeps its last output
        and memory on this scan, as a DCS block on a ``BAD`` PV status (see :class:`PVGuard`).

        Parameters
        ----------
        sp, pv : float or (n,) array, set point and measured level [m]

        Returns
        -------
        op : float (scalar inputs) or (n,) array, valve input [0..1]
        """
        if self._state is None:
            raise not_reset_error(self.name)
        sp, pv, scalar = check_step_inputs(self.name, int(self._n or 1), sp, pv, allow_bad=True)
        sp, pv, bad = self.guard.screen(sp, pv)
        state, op = self.advance(self._state, sp, pv)
        self._state = merge_rows(~bad, state, self._state) if bad.any() else state
        op = self.guard.finish(op, bad)
        return float(op[0]) if (scalar and self._scalar) else op

    @abstractmethod
    def initial_state(self, sp: np.ndarray, pv: np.ndarray, op: np.ndarray) -> Any:
        """Bumpless memory for loops at ``sp``, ``pv`` [m] with input ``op``, all ``(n,)``."""

    @abstractmethod
    def advance(self, state: Any, sp: np.ndarray, pv: np.ndarray) -> tuple[Any, np.ndarray]:
        """One scan, pure: ``(state, sp (n,), pv (n,)) -> (state, op (n,))``."""
