"""How a recorder pairs the controller output with the PV, read from the controller's own reaction.

A feedback controller moves its output against every PV move it reads, measurement noise
included, in the scan that read it.  In the first differences of the record that reaction is
a correlation between an OP move and the PV move of the sample the controller read:

* ``op_lag = 1`` (a scan logged as it ran: ``op[k]`` computed from the ``pv[k]`` beside it,
  or an input sampled with the output): the reaction is at lag 0, ``corr(dop[k], dpv[k])``;
* ``op_lag = 0`` (the model's convention: ``pv[k]`` measured after ``op[k]`` acted, so
  ``op[k]`` was computed from ``pv[k-1]``): the reaction is at lag 1,
  ``corr(dop[k], dpv[k-1])``; lag 0 then holds the process's own answer to ``op[k]``,
  which has the opposite sign.

The controller's sign is the opposite of the process gain's (negative feedback), so with the
process gain's sign ``s`` the reaction at lag ``l`` is ``c(l) = -s corr(dop[k], dpv[k-l])``:
positive at the controller's lag, negative where the process answers the output.  The pairing
is 1 when ``c(0) - c(1)`` exceeds ``3 / sqrt(N)`` (three standard errors of a sample correlation
of ``N`` moves), 0 when ``c(1) - c(0)`` does (the controller answering the previous row, or the
process answering its own row's output, which it cannot do when the PV was read first);
otherwise a second reading separates the two rows: when the PV's moves are themselves
correlated from sample to sample (coloured noise, a slow cycle), both marginal correlations are
high, so ``dop[k]`` is regressed on ``dpv[k]`` and ``dpv[k-1]`` together (least squares) and
each coefficient's t statistic ``t(l) = -s beta_l / se(beta_l)`` read: the controller reacts to
exactly one of the two rows, so the pairing is 1 when ``t(0) > 3`` and ``t(1) < 3``, 0 when
``t(1) > 3`` and ``t(0) < 3``.  When both or neither stand out (an open-loop record read before
its input acts, a smooth PV with no noise for the controller to answer, a loop whose cycle
dominates every lag) it is undecided and the diagnosis falls back on fitting the base model
both ways.  Differencing removes slow loads
and the set point's level; the record's own pairing does not depend on the valve, so a sticky
valve does not change the test (the controller output, not the stem, is recorded).
"""
from __future__ import annotations

import numpy as np

__all__ = ["controller_reaction", "Z_MARGIN"]

#: Standard errors (``1/sqrt(N)``) by which the controller's lag must stand out.
Z_MARGIN = 3.0


def _corr(a: np.ndarray, b: np.ndarray, lag: int) -> float:
    """``corr(a[k], b[k - lag])`` over the samples where both exist (0 for a constant series)."""
    if lag > 0:
        x, y = a[lag:], b[:-lag]
    elif lag < 0:
        x, y = a[:lag], b[-lag:]
    else:
        x, y = a, b
    x = x - x.mean()
    y = y - y.mean()
    den = float(np.sqrt(np.dot(x, x) * np.dot(y, y)))
    return float(np.dot(x, y) / den) if den > 0 else 0.0


def controller_reaction(op, pv, process_sign: float = 1.0) -> dict:
    """The controller's reaction to PV moves at lag 0 and 1, and the pairing it implies.

    Parameters
    ----------
    op, pv : (T,) controller output and process variable as logged (rows paired as recorded)
    process_sign : +1 when more output raises the PV (a valve filling a tank, a flow valve),
        -1 when it lowers it (a valve draining a vessel)

    Returns
    -------
    dict (JSON-ready): ``corr`` ``{lag: corr(dop[k], dpv[k-lag])}`` for lags -1..2,
    ``reaction`` ``{"0": c(0), "1": c(1)}`` (``-process_sign * corr``), ``margin``
    (``Z_MARGIN / sqrt(N)``), ``n`` (moves), ``op_lag`` (1, 0, or None: undecided),
    ``method`` (``'correlation'`` or, where the correlations do not decide,
    ``'partial regression'`` with its ``t`` statistics ``{"0": t(0), "1": t(1)}``) and ``reason``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> pv = 1.0 + 0.01 * rng.standard_normal(500)
    >>> op = 0.5 - 2.0 * (pv - 1.0)          # a P controller logged beside the PV it read
    >>> controller_reaction(op, pv)["op_lag"]
    1
    >>> controller_reaction(op[:-1], pv[1:])["op_lag"]     # each PV logged after the output beside it
    0
    """
    op = np.asarray(op, float)
    pv = np.asarray(pv, float)
    ok = np.isfinite(op) & np.isfinite(pv)
    a, b = np.diff(op[ok]), np.diff(pv[ok])
    n = len(a)
    sign = 1.0 if process_sign >= 0 else -1.0
    out: dict = {"n": int(n), "process_sign": sign}
    if n < 20 or not np.any(a) or not np.any(b):
        out.update(corr={}, reaction={}, margin=float("nan"), op_lag=None,
                   reason="too few moves of the controller output or the PV to read the controller's reaction")
        return out
    corr = {str(lag): _corr(a, b, lag) for lag in (-1, 0, 1, 2)}
    c0, c1 = -sign * corr["0"], -sign * corr["1"]
    m = Z_MARGIN / np.sqrt(n)
    out.update(corr=corr, reaction={"0": c0, "1": c1}, margin=float(m))
    why = (f"reaction of the output to its own row's PV move {c0:.2f}, to the previous row's {c1:.2f}, "
           f"margin {m:.2f}")
    if c0 - c1 > m:
        out.update(op_lag=1, method="correlation",
                   reason=f"each output was computed from the PV logged beside it ({why})")
    elif c1 - c0 > m:
        out.update(op_lag=0, method="correlation",
                   reason=f"each PV was measured after the output beside it acted ({why})")
    else:
        t0, t1 = _partial_t(a, b, sign)
        why = f"{why}; regressed on both rows' PV moves: t {t0:.1f} for its own row, {t1:.1f} for the previous"
        out.update(method="partial regression", t={"0": t0, "1": t1})
        # a controller's reaction is a spike at its lag: the correlation there also stands out of the
        # lag beyond it (an open-loop record's smooth input-output relation does not)
        cm1, c2 = -sign * corr["-1"], -sign * corr["2"]
        if t0 > Z_MARGIN > t1 and c0 - cm1 > m:
            out.update(op_lag=1, reason=f"each output was computed from the PV logged beside it ({why})")
        elif t1 > Z_MARGIN > t0 and c1 - c2 > m:
            out.update(op_lag=0, reason=f"each PV was measured after the output beside it acted ({why})")
        else:
            out.update(op_lag=None, reason=f"no clear controller reaction ({why})")
    return out


def _partial_t(a: np.ndarray, b: np.ndarray, sign: float) -> tuple[float, float]:
    """The t statistics ``-sign beta_l / se`` of ``a[k] ~ beta_0 b[k] + beta_1 b[k-1]`` (least squares, centred)."""
    X = np.column_stack([b[1:], b[:-1]])
    X = X - X.mean(axis=0)
    y = a[1:] - a[1:].mean()
    gram = X.T @ X
    if np.linalg.cond(gram) > 1e12:          # one row's moves a multiple of the other's: nothing to separate
        return 0.0, 0.0
    beta = np.linalg.solve(gram, X.T @ y)
    r = y - X @ beta
    s2 = float(r @ r) / max(len(y) - 2, 1)
    se = np.sqrt(np.maximum(s2 * np.diag(np.linalg.inv(gram)), 1e-300))
    t = -sign * beta / se
    return float(t[0]), float(t[1])
