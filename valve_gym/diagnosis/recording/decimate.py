"""Conditioning a long recording to the sample time its physics needs.

A day of a 10 Hz historian tag is a million samples; the loop's dynamics (a
level's or flow's time constant, a stick-slip limit cycle) span seconds to
minutes.  :func:`condition` estimates the record's dominant time scale,
decimates by block means (the anti-alias filter) to about
:data:`SAMPLES_PER_TIME_SCALE` samples per time scale, and, when the record
is still longer than ``max_samples``, keeps its most informative window.
Each step is returned in a :class:`Conditioning` record and stated in the
recording's ``repairs``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...signals import acf as autocorrelation

__all__ = ["DEFAULT_MAX_SAMPLES", "MIN_AFTER_DECIMATION", "MIN_SAMPLES_PER_TIME_SCALE", "SAMPLES_PER_TIME_SCALE",
           "Conditioning",
           "condition", "time_scale"]

#: Records longer than this (samples) are conditioned by :func:`load_recording`.
DEFAULT_MAX_SAMPLES = 12_000

#: Samples kept per dominant time scale when decimating, by preference.
SAMPLES_PER_TIME_SCALE = 20

#: Fewest samples per dominant time scale that decimation may leave to fit
#: ``max_samples``; beyond that a window is kept instead.
MIN_SAMPLES_PER_TIME_SCALE = 8

#: Decimation never leaves fewer samples than this.
MIN_AFTER_DECIMATION = 2_000


@dataclass(frozen=True)
class Conditioning:
    """What :func:`condition` did to a long record.

    Attributes
    ----------
    n_in : int
        Samples before.
    dt_in : float
        Sample time before [s].
    time_scale : float
        Estimated dominant time scale [s] (see :func:`time_scale`).
    factor : int
        Decimation factor (1: none); the new sample time is ``factor * dt_in``.
    window : tuple of int or None
        ``(i0, i1)`` of the window kept, in decimated samples, or None.
    n_out : int
        Samples after.
    """

    n_in: int
    dt_in: float
    time_scale: float
    factor: int
    window: tuple[int, int] | None
    n_out: int

    @property
    def dt_out(self) -> float:
        """Sample time after conditioning [s] (``factor * dt_in`` to 12 significant digits)."""
        return float(f"{self.factor * self.dt_in:.12g}")

    def statements(self, t0: float) -> list[str]:
        """Lines for ``Recording.repairs`` (``t0``: time of the first sample kept [s])."""
        out = []
        if self.factor > 1:
            out.append(
                f"decimated by {self.factor} from dt={self.dt_in:g} s to dt={self.dt_out:g} s "
                f"({self.n_in} -> {self.n_in // self.factor} samples): means of blocks of {self.factor} "
                f"samples (the anti-alias filter), times at the block centres; the dominant time scale "
                f"{self.time_scale:.4g} s keeps {self.time_scale / self.dt_out:.3g} samples"
            )
        if self.window is not None:
            i0, i1 = self.window
            out.append(
                f"kept the most informative window of {i1 - i0} samples (t={t0:g} to "
                f"{t0 + (i1 - i0 - 1) * self.dt_out:g} s; largest op and pv variance) of "
                f"{self.n_in // self.factor}, as the record is longer than max_samples"
            )
        return out


def _acf_scale(x: np.ndarray) -> float:
    """Lag (samples) where the autocorrelation, relative to its lag-1 value, falls below 1/e."""
    n = len(x)
    y = x - x.mean()
    if not np.any(y):
        return float(n)
    acf = autocorrelation(x, n - 1, normalise=False)      # removes the mean itself
    if acf[0] <= 0 or acf[1] <= 0:
        return 1.0
    below = np.flatnonzero(acf[1:] < acf[1] / np.e)
    return float(below[0] + 1) if below.size else float(n)


def time_scale(x: np.ndarray, dt: float, max_len: int = 200_000) -> float:
    """Dominant time scale of a signal [s].

    Parameters
    ----------
    x : ndarray, shape (n,)
        Signal, finite.
    dt : float
        Sample time [s].
    max_len : int
        Longer signals are first averaged over blocks to at most this length
        (the scale found is far longer than such a block, or it is one block).

    Returns
    -------
    float
        The lag at which the autocorrelation falls below ``1/e`` of its
        lag-1 value [s]; lag 1 rather than 0 so that white measurement noise
        does not make every record look fast.

    Notes
    -----
    For a first-order response ``exp(-t/T)`` the autocorrelation of its
    output under white input decays as ``exp(-|lag|/T)``: the scale is
    ``T``.  A limit cycle of period ``P`` gives a scale of about ``P/6``
    (the cosine falls below ``1/e`` at ``0.19 P``).
    """
    q = max(1, int(np.ceil(len(x) / max_len)))
    if q > 1:
        m = len(x) // q
        x = x[: m * q].reshape(m, q).mean(axis=1)
    return _acf_scale(np.asarray(x, dtype=np.float64)) * q * dt


def _block_mean(x: np.ndarray, q: int) -> np.ndarray:
    m = len(x) // q
    return x[: m * q].reshape(m, q).mean(axis=1)


def _best_window(op: np.ndarray, pv: np.ndarray, w: int) -> int:
    """Start of the window of `w` samples with the largest sum of normalised op and pv variances."""
    score = np.zeros(len(op) - w + 1)
    for x in (op, pv):
        c1 = np.concatenate(([0.0], np.cumsum(x - x.mean())))
        c2 = np.concatenate(([0.0], np.cumsum((x - x.mean()) ** 2)))
        s1 = c1[w:] - c1[:-w]
        var = (c2[w:] - c2[:-w]) / w - (s1 / w) ** 2
        score += var / max(float(np.var(x)), 1e-300)
    return int(np.argmax(score))


def condition(t: np.ndarray, signals: dict[str, np.ndarray], dt: float,
              max_samples: int | None) -> tuple[np.ndarray, dict[str, np.ndarray], Conditioning | None]:
    """Decimate and window a long record to the sample time its physics needs.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Uniform sample times [s].
    signals : dict of str to ndarray, shape (n,)
        Role to finite values; ``op`` and ``pv`` required.
    dt : float
        Sample time [s].
    max_samples : int or None
        Records of at most this many samples (or any, with None) are
        returned unchanged.

    Returns
    -------
    t : ndarray, shape (m,)
        Sample times [s] of the result (block centres).
    signals : dict of str to ndarray, shape (m,)
    conditioning : Conditioning or None
        None when nothing was done.

    Notes
    -----
    The decimation factor is ``q = floor(T / (20 dt))`` with ``T`` the
    smaller dominant time scale of op and pv (:func:`time_scale`), raised
    towards ``ceil(n / max_samples)`` as far as ``floor(T / (8 dt))`` allows
    (at least 8 samples per time scale), at least 1 and at most ``n // 2000``.
    Block means are a moving-average anti-alias filter (first zero at the new sampling frequency, no overshoot, so a
    normalised op stays in 0..1); each mean is placed at its block's centre,
    so no phase shift is added.  If ``n / q`` still exceeds `max_samples`,
    the window of `max_samples` decimated samples with the largest sum of op
    and pv variances (each relative to its whole-record variance) is kept.
    """
    n = len(t)
    if max_samples is None or n <= max_samples:
        return t, signals, None
    scale = min(time_scale(signals["op"], dt), time_scale(signals["pv"], dt))
    q_pref = int(np.floor(scale / (SAMPLES_PER_TIME_SCALE * dt)))
    q_coarsest = int(np.floor(scale / (MIN_SAMPLES_PER_TIME_SCALE * dt)))
    q_budget = -(-n // max_samples)
    q = int(np.clip(max(q_pref, min(q_budget, q_coarsest)), 1, max(1, n // MIN_AFTER_DECIMATION)))
    out = signals
    t_out = t
    if q > 1:
        out = {r: _block_mean(v, q) for r, v in signals.items()}
        t_out = t[0] + (q - 1) / 2 * dt + float(f"{q * dt:.12g}") * np.arange(len(out["op"]))
    m = len(t_out)
    window = None
    if m > max_samples:
        i0 = _best_window(out["op"], out["pv"], max_samples)
        window = (i0, i0 + max_samples)
        out = {r: v[i0:i0 + max_samples] for r, v in out.items()}
        t_out = t_out[i0:i0 + max_samples]
    return t_out, out, Conditioning(n, dt, scale, q, window, len(t_out))
