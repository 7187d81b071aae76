r"""Bicoherence test of non-Gaussianity and nonlinearity (Choudhury, Shah & Thornhill 2004).

A linear loop driven by Gaussian noise has a flat (zero) squared
bicoherence; stiction is a nonlinearity whose limit cycle couples the
fundamental with its harmonics, which shows as significant bicoherence peaks.

Notes
-----
With segments ``X_i(f)`` (Hann window, 50 % overlap, ``K`` segments)

.. math:: bic^2(f_1, f_2) = \frac{|\sum_i X_i(f_1) X_i(f_2) X_i^*(f_1+f_2)|^2}
          {\sum_i |X_i(f_1) X_i(f_2)|^2 \; \sum_i |X_i(f_1+f_2)|^2}

over the principal domain.  The 5 % significance level of a Gaussian signal is
``bic^2_crit = chi^2_{2, 0.95} / (2 K) = 5.99 / (2K)``.  Then
``NGI = mean(bic^2 > crit) - crit`` (0 when none is significant) and
``NLI = |bic^2_max - (mean + 2 std)|`` of the significant values.  A Gaussian
signal has 5 % of its pairs above ``crit`` by chance: NGI is taken as
``-crit`` (Gaussian) unless more pairs are significant than that chance count
(binomial mean + 2 standard deviations).  Published
decision: non-Gaussian if ``NGI > 0.001``, nonlinear if also ``NLI > 0.01``.
Following the paper, the signal (the control error or PV) is band-limited to
the oscillation's band before the test.

References
----------
.. [1] M.A.A.S. Choudhury, S.L. Shah, N.F. Thornhill, "Diagnosis of poor
   control-loop performance using higher-order statistics", Automatica 40
   (2004) 1719-1728.
"""
from __future__ import annotations

import numpy as np

from ._base import Evidence, check_signals, not_applicable, oscillation, reliability

__all__ = ["bicoherence", "bicoherence_evidence"]

CITE = "Choudhury, Shah & Thornhill 2004, Automatica 40, 1719-1728"
DOC = ("NLI = |max bic^2 - (mean + 2 std)| of significant squared bicoherence; nonlinear (stiction "
       "possible) if NGI > 0.001 and NLI > 0.01")


def bicoherence(x, nfft: int = 64):
    """Squared bicoherence of ``x`` over the principal domain.

    Parameters
    ----------
    x : (T,) array
    nfft : int, segment length [samples]

    Returns
    -------
    bic2 : (m,) array, squared bicoherence at the frequency pairs
    crit : float, 5 % significance level of ``bic2``
    """
    x = np.asarray(x, float)
    x = x - x.mean()
    step = nfft // 2
    starts = np.arange(0, len(x) - nfft + 1, step)
    win = np.hanning(nfft)
    segs = np.stack([x[s:s + nfft] for s in starts])
    segs = segs - segs.mean(axis=1, keepdims=True)
    X = np.fft.fft(segs * win, axis=1)
    half = nfft // 2
    f1, f2 = np.meshgrid(np.arange(1, half), np.arange(1, half), indexing="ij")
    keep = (f2 <= f1) & (f1 + f2 < half)
    f1, f2 = f1[keep], f2[keep]
    a = X[:, f1] * X[:, f2]
    b = X[:, f1 + f2]
    num = np.abs(np.sum(a * np.conj(b), axis=0)) ** 2
    den = np.sum(np.abs(a) ** 2, axis=0) * np.sum(np.abs(b) ** 2, axis=0)
    bic2 = np.where(den > 0, num / np.maximum(den, 1e-300), 0.0)
    crit = 5.99 / (2.0 * len(starts))
    return bic2, float(crit)


def bicoherence_evidence(op, pv, dt: float = 1.0, sp=None) -> Evidence:
    """Non-Gaussianity and nonlinearity indices of the control error (or the PV).

    Parameters
    ----------
    op, pv : (T,) arrays
    dt : float, sample time [s]
    sp : (T,) array, optional, set point (the error ``sp - pv`` is tested; else the PV)

    Returns
    -------
    Evidence, ``value`` = NLI (0 when the signal is Gaussian), ``details``:
    ``ngi``, ``nli``, ``crit``, ``bic2_max``, ``segment_samples``
    """
    op, pv = check_signals(op, pv, dt)
    e = pv if sp is None else np.asarray(sp, float) - pv
    osc = oscillation(e)
    n = len(e)
    nfft = 128 if n >= 128 * 6 else 64
    if n < nfft * 3:
        return not_applicable("bicoherence", CITE, f"too short for the test (< {3 * nfft} samples)", DOC)
    if osc.present and osc.period_samples * 2.5 > nfft and n >= 256 * 5:
        nfft = 256
    bic2, crit = bicoherence(e, nfft)
    sig = bic2[bic2 > crit]
    chance = 0.05 * len(bic2) + 2.0 * np.sqrt(0.05 * 0.95 * len(bic2))
    if len(sig) <= chance:
        ngi, nli = -crit, 0.0
    else:
        ngi = float(sig.mean() - crit)
        nli = float(abs(bic2.max() - (sig.mean() + 2 * sig.std())))
    nonlin = ngi > 0.001 and nli > 0.01
    verdict = ("stiction" if (nonlin and osc.present) else
               ("no stiction" if not nonlin else "undetermined"))
    reason = ("nonlinear and oscillating: stiction possible" if verdict == "stiction" else
              "Gaussian or linear: no nonlinearity" if not nonlin else
              "nonlinear but no regular oscillation")
    rel = 0.3 + 0.7 * reliability(osc)
    return Evidence("bicoherence", CITE, True, nli if ngi > 0.001 else 0.0, rel, verdict, reason, DOC,
                    {"ngi": ngi, "nli": nli, "crit": crit, "bic2_max": float(bic2.max()),
                     "segment_samples": float(nfft)})
