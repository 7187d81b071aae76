"""The :class:`Recording` record: a validated control-loop recording on a uniform grid."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._base import ROLES

__all__ = ["Recording"]

_UNIFORM_RTOL = 1e-6


def _as_signal(x: Any, what: str, n: int | None = None) -> np.ndarray:
    a = np.array(x, dtype=np.float64, copy=True)
    if a.ndim != 1:
        raise ValueError(f"Recording.{what} must be 1-D, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"Recording.{what} has {a.shape[0]} samples, t has {n}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"Recording.{what} contains NaN or infinite values")
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False, repr=False)
class Recording:
    """A validated control-loop recording on a uniform time grid.

    Attributes
    ----------
    t : ndarray, shape (n,), float64
        Sample times in seconds, uniformly spaced by `dt`.  For files whose
        time column holds date strings, seconds since the first sample
        (see `start`).
    op : ndarray, shape (n,), float64
        Controller output normalised to 0..1 with `op_range`
        (``(op_raw - lo) / (hi - lo)``).
    pv : ndarray, shape (n,), float64
        Process variable in its own engineering units.
    sp : ndarray, shape (n,), float64, or None
        Set point in the units of `pv`, if recorded.
    mv : ndarray, shape (n,), float64, or None
        Valve stem position normalised to 0..1, if recorded.
    dt : float
        Uniform sample time in seconds.  If None at construction, taken from
        `t`.
    name : str
        Label of the record (by default the file name without extension).
    op_range : tuple of float
        ``(lo, hi)`` of the raw controller output that maps to 0..1.
    repairs : tuple of str
        One human-readable line per repair done while loading (empty if the
        file was used as it is).
    columns : dict of str to str
        Role (``"t"``, ``"op"``, ``"pv"``, ``"sp"``, ``"mv"``) to the column
        name used in the file; only the roles present.
    start : str or None
        First time stamp as written in the file when the time column held
        date strings, else None.
    notes : tuple of str
        Statements about how the record was read and conditioned that do not
        change the data (e.g. the reader used, the estimated dominant time
        scale); changes to the data are in `repairs`.

    Notes
    -----
    The arrays are read-only copies.  Equality is identity (arrays do not
    compare to a single bool).
    """

    t: np.ndarray
    op: np.ndarray
    pv: np.ndarray
    sp: np.ndarray | None = None
    mv: np.ndarray | None = None
    dt: float | None = None
    name: str = "recording"
    op_range: tuple[float, float] = (0.0, 1.0)
    repairs: tuple[str, ...] = ()
    columns: dict[str, str] = field(default_factory=dict)
    start: str | None = None
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        t = _as_signal(self.t, "t")
        n = t.shape[0]
        if n < 1:
            raise ValueError("Recording needs at least one sample")
        set_ = object.__setattr__
        set_(self, "t", t)
        set_(self, "op", _as_signal(self.op, "op", n))
        set_(self, "pv", _as_signal(self.pv, "pv", n))
        set_(self, "sp", None if self.sp is None else _as_signal(self.sp, "sp", n))
        set_(self, "mv", None if self.mv is None else _as_signal(self.mv, "mv", n))

        dt = self.dt
        if dt is None:
            if n < 2:
                raise ValueError("Recording.dt must be given for a single sample")
            dt = float(np.median(np.diff(t)))
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"Recording.dt must be a positive number of seconds, got {dt!r}")
        if n >= 2:
            tol = _UNIFORM_RTOL * dt + 8 * np.finfo(float).eps * float(np.max(np.abs(t)))
            dev = float(np.max(np.abs(np.diff(t) - dt)))
            if dev > tol:
                raise ValueError(
                    f"Recording.t is not uniformly spaced by dt={dt:g} s "
                    f"(steps deviate by up to {dev:g} s); use load_recording to resample"
                )
        set_(self, "dt", dt)

        for what in ("op", "mv"):
            a = getattr(self, what)
            if a is not None and (a.min() < 0.0 or a.max() > 1.0):
                raise ValueError(
                    f"Recording.{what} must be normalised to 0..1, "
                    f"got values {a.min():g}..{a.max():g}"
                )
        try:
            if isinstance(self.op_range, (str, bytes)):
                raise TypeError
            lo, hi = (float(v) for v in self.op_range)
        except (TypeError, ValueError):
            raise ValueError(
                f"Recording.op_range must be a pair of numbers (lo, hi), e.g. (0, 100), got {self.op_range!r}"
            ) from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"Recording.op_range must be (lo, hi) with lo < hi, got {self.op_range!r}")
        set_(self, "op_range", (lo, hi))
        set_(self, "name", str(self.name))
        set_(self, "repairs", tuple(str(r) for r in self.repairs))
        set_(self, "columns", dict(self.columns))
        set_(self, "notes", tuple(str(r) for r in self.notes))

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def __repr__(self) -> str:
        roles = ", ".join(r for r in ROLES[1:] if getattr(self, r, None) is not None)
        return (
            f"Recording(name={self.name!r}, n={len(self)}, dt={self.dt:g} s, "
            f"signals=[{roles}], op_range={self.op_range}, repairs={len(self.repairs)})"
        )

    @property
    def duration(self) -> float:
        """Length of the record in seconds, ``n * dt``."""
        return len(self) * float(self.dt or 0.0)

    def slice(self, i0: int | None = None, i1: int | None = None) -> Recording:
        """Samples ``i0`` to ``i1 - 1`` as a new Recording.

        Parameters
        ----------
        i0, i1 : int or None
            Start (inclusive) and stop (exclusive) sample indices with Python
            slice semantics (negative counts from the end, None = open).

        Returns
        -------
        Recording
            Same `dt`, `op_range`, `repairs` and `columns`; `t` keeps the
            original times; `name` gets ``[i0:i1]`` appended.

        Raises
        ------
        ValueError
            If the slice is empty.
        """
        s = slice(i0, i1)
        a, b, _ = s.indices(len(self))
        if b <= a:
            raise ValueError(
                f"Recording.slice({i0}, {i1}) of {self.name!r} (n={len(self)}) is empty"
            )

        def cut(x: np.ndarray | None) -> np.ndarray | None:
            return None if x is None else x[a:b]

        return Recording(
            t=self.t[a:b], op=self.op[a:b], pv=self.pv[a:b], sp=cut(self.sp), mv=cut(self.mv),
            dt=self.dt, name=f"{self.name}[{a}:{b}]", op_range=self.op_range,
            repairs=self.repairs, columns=self.columns, start=self.start if a == 0 else None,
            notes=self.notes,
        )

    def with_op_lag(self, lag: int) -> Recording:
        """The record with the controller output paired with the PV ``lag`` samples later.

        ``lag = 1`` pairs ``op[k - 1]`` with ``pv[k]`` (one sample shorter): for a
        recorder that logs, at each scan, the PV a controller read next to the
        output it computed from it, so that ``op[k]`` acts only after ``pv[k]``
        was measured.  The diagnosis' model reads ``pv[k]`` as measured after
        ``op[k]`` acted for one sample; ``lag = 0`` returns the record as it is.
        The set point and the stem position stay with the PV (measured, or
        read, at the same scan).

        Examples
        --------
        >>> import numpy as np
        >>> r = Recording(t=np.arange(4.0), op=[0.1, 0.2, 0.3, 0.4], pv=[1.0, 2.0, 3.0, 4.0])
        >>> r1 = r.with_op_lag(1)
        >>> r1.op.tolist(), r1.pv.tolist()
        ([0.1, 0.2, 0.3], [2.0, 3.0, 4.0])
        """
        if lag not in (0, 1) or isinstance(lag, bool):
            raise ValueError(f"op lag must be 0 or 1 samples, got {lag!r}")
        if lag == 0:
            return self
        if len(self) < 3:
            raise ValueError(f"{self.name!r} has {len(self)} samples; pairing OP with the next PV needs at least 3")

        def later(x: np.ndarray | None) -> np.ndarray | None:
            return None if x is None else x[1:]

        return Recording(
            t=self.t[1:], op=self.op[:-1], pv=self.pv[1:], sp=later(self.sp), mv=later(self.mv), dt=self.dt,
            name=self.name, op_range=self.op_range, repairs=self.repairs,
            columns=self.columns, start=None, notes=self.notes + (
                "controller output paired with the PV one sample later (op[k-1] with pv[k]): the output "
                "logged at a scan acts after the PV logged with it",),
        )

    def to_dataframe(self):
        """The signals as a :class:`pandas.DataFrame`.

        Returns
        -------
        pandas.DataFrame
            Columns ``t``, ``op``, ``pv`` and, when present, ``sp``, ``mv``
            (n rows; op and mv normalised 0..1).  ``df.attrs`` holds
            ``name``, ``dt``, ``op_range``, ``repairs``, ``columns``, ``start``.
        """
        import pandas as pd

        data = {"t": self.t, "op": self.op, "pv": self.pv}
        if self.sp is not None:
            data["sp"] = self.sp
        if self.mv is not None:
            data["mv"] = self.mv
        df = pd.DataFrame({k: np.array(v) for k, v in data.items()})
        df.attrs.update(
            name=self.name, dt=self.dt, op_range=self.op_range, repairs=list(self.repairs),
            columns=dict(self.columns), start=self.start, notes=list(self.notes),
        )
        return df
