r"""Free-run simulation-error fitting of a model structure to a recording.

The fitter simulates whole populations of candidate parameter sets in one
call of the batched physics core and minimises the free-run simulation error

.. math:: J(\theta) = \sum_{k \in \text{fit}} (y_k - \hat y_k(\theta))^2

where :math:`\hat y` is simulated from the recorded controller output alone
(no measured output is fed back), starting from an initial state that is
part of :math:`\theta`.  Search: differential evolution written over the
batch axis (JADE's *current-to-pbest/1/bin* with dithered ``F`` and ``CR``
[1]_), then a bounded Gauss-Newton refinement (:func:`scipy.optimize.least_squares`,
trust-region reflective) whose finite-difference Jacobian is one batched
simulation of ``k + 1`` parameter sets.

References
----------
.. [1] J. Zhang, A.C. Sanderson, "JADE: adaptive differential evolution with
   optional external archive", IEEE Trans. Evolutionary Computation 13(5),
   945-958, 2009.
.. [2] L. Ljung, "System identification: theory for the user", 2nd ed.,
   Prentice Hall, 1999 (simulation-error criterion, fit percentage).
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from ..params import ModelParams
from ..signals import acf as autocorrelation
from .model import DataScales, ModelStructure
from .recording import Recording

__all__ = ["ModelFitter", "FitResult", "fit_structure", "fit_with_friction", "fit_initial_state", "rmse",
           "fit_percent", "effective_n", "information_criterion", "ParamUncertainty", "parameter_uncertainty"]

_BIG = 1e300
#: Stop simulating a candidate once it cannot beat its rival (the same fits; off only to measure it:
#: ``benchmarks/bench_diagnosis.py --early-stop-ab``).
EARLY_STOP = True
_PBEST = 0.5


# --------------------------------------------------------------------------- metrics
def rmse(y, yhat) -> float:
    """Root-mean-square error [PV units]."""
    y, yhat = np.asarray(y, float), np.asarray(yhat, float)
    if y.size == 0:
        return float("nan")
    return float(np.sqrt(np.mean((y - yhat) ** 2)))


def fit_percent(y, yhat) -> float:
    """NRMSE fit [%]: ``100 (1 - ||y - yhat|| / ||y - mean(y)||)`` (100 = perfect, can be < 0)."""
    y, yhat = np.asarray(y, float), np.asarray(yhat, float)
    if y.size == 0:
        return float("nan")
    den = np.linalg.norm(y - y.mean())
    if den == 0:
        return float("nan")
    return float(100.0 * (1.0 - np.linalg.norm(y - yhat) / den))


def effective_n(residual, max_lag: int | None = None) -> float:
    """Effective number of independent samples of an autocorrelated residual.

    ``N / (1 + 2 sum_k rho_k)``, summing the sample autocorrelation up to its
    first non-positive value (Geyer's initial-positive-sequence idea); at
    least 5, at most ``N``.  Free-run residuals are strongly autocorrelated,
    and information criteria computed with the raw ``N`` would reward every
    extra parameter.
    """
    r = np.asarray(residual, float)
    r = r - r.mean()
    n = len(r)
    if n < 4 or not np.any(r):
        return float(max(n, 1))
    m = float(np.abs(r).max())
    if not 1e-100 < m < 1e100:          # tiny or huge units: the squares would under- or overflow
        r = r / m
    L = min(max_lag or min(n // 3, 500), n - 1)
    acf = autocorrelation(r, L, demean=False)      # r is centred above
    s = 0.0
    for k in range(1, L + 1):
        if acf[k] <= 0:
            break
        s += acf[k]
    return float(np.clip(n / (1.0 + 2.0 * s), min(5.0, n), n))


def information_criterion(sse: float, n_eff: float, k: int, n: int, kind: str = "bic") -> float:
    """Gaussian information criterion of a free-run fit with effective sample size.

    ``n_eff * ln(SSE / n) + k * ln(n_eff)`` (BIC) or ``+ 2 k`` (AIC).
    Differences between models fitted to the same samples are what matter.
    """
    sse = max(float(sse), 1e-300)
    pen = np.log(max(n_eff, 2.0)) if kind == "bic" else 2.0
    return float(n_eff * np.log(sse / max(n, 1)) + k * pen)


# --------------------------------------------------------------------------- result
@dataclass
class FitResult:
    """Outcome of fitting one model structure.

    Attributes
    ----------
    structure : ModelStructure
    w : (k,) ndarray, unit coordinates of the optimum
    params : ModelParams, the fitted core parameters (scalars)
    physical : dict, fitted parameters by core field name (see ``units``)
    units : dict, unit of each entry of ``physical``
    y_sim : (T,) ndarray, free-run simulated PV over the whole record [PV]
    n_fit : int, samples used for fitting (the first ``n_fit``)
    cost : float, sum of squared errors on the fit samples [PV^2]
    rmse, fit_percent : on the fit samples [PV], [%]
    holdout_rmse, holdout_fit_percent : on the samples after ``n_fit`` (nan if none)
    rmse_all, fit_percent_all : over the whole record
    k : int, number of free parameters
    n_sub : int, Euler steps per controller sample of ``y_sim``
    n_evals : int, simulated parameter sets
    seconds : float, wall time
    horizon : int or None, samples: ``y_sim`` (and the cost) is an ``horizon``-step-ahead
        prediction, the measured level restarting from the record every ``horizon`` samples
        (:func:`fit_structure`, ``horizon``); None for the free run
    """

    structure: ModelStructure
    w: np.ndarray
    params: ModelParams
    physical: dict[str, float]
    units: dict[str, str]
    y_sim: np.ndarray
    y: np.ndarray
    n_fit: int
    cost: float
    rmse: float
    fit_percent: float
    holdout_rmse: float
    holdout_fit_percent: float
    rmse_all: float
    fit_percent_all: float
    k: int
    n_sub: int
    n_evals: int
    seconds: float
    horizon: int | None = None

    @property
    def residual(self) -> np.ndarray:
        """Measured minus simulated PV over the whole record, (T,) [PV]."""
        return self.y - self.y_sim

    @property
    def label(self) -> str:
        """Short name of the fitted structure (base and named effects)."""
        return self.structure.label()

    def summary(self) -> dict:
        """JSON-ready summary (floats, lists)."""
        return {"model": self.label, "effects": list(self.structure.effects),
                "variants": dict(self.structure.variants),
                "rmse": self.rmse_all, "fit_percent": self.fit_percent_all,
                "rmse_fit_part": self.rmse, "fit_percent_fit_part": self.fit_percent,
                "holdout_rmse": _nan_none(self.holdout_rmse),
                "holdout_fit_percent": _nan_none(self.holdout_fit_percent),
                "n_params": self.k, "params": dict(self.physical), "units": dict(self.units),
                "n_sub": self.n_sub}


def _nan_none(x):
    return None if x is None or not np.isfinite(x) else float(x)


# --------------------------------------------------------------------------- optimiser
class _Objective:
    """Batched SSE of unit coordinates over a subset of free coordinates."""

    def __init__(self, structure: ModelStructure, u, y, n_fit, free_idx, w_fixed, horizon: int | None = None):
        self.s = structure
        self.u = np.ascontiguousarray(u[:n_fit])
        self.y = np.asarray(y[:n_fit], float)
        self.free = np.asarray(free_idx, int)
        self.w_fixed = np.asarray(w_fixed, float)
        self.n_evals = 0
        self.reset = None if horizon is None else (self.y, int(horizon))

    def full(self, X):
        X = np.atleast_2d(X)
        W = np.repeat(self.w_fixed[None, :], X.shape[0], axis=0)
        W[:, self.free] = X
        return W

    def sim(self, X):
        self.n_evals += np.atleast_2d(X).shape[0]
        try:
            return self.s.simulate(self.full(X), self.u, reset=self.reset)
        except (ValueError, ZeroDivisionError, FloatingPointError):
            return np.full((len(self.u), np.atleast_2d(X).shape[0]), np.nan)

    def __call__(self, X, bound=None):
        """Costs of the rows ``X`` (n, k).

        With ``bound`` (n,), a row whose cost exceeds its bound may be stopped early and cost
        ``inf``: its true cost is larger than the bound, so a comparison with the bound comes out
        the same (:meth:`~valve_gym.diagnosis.model.ModelStructure.bounded_costs`).  Without one,
        every row's whole cost (the kernel's sums, which are the costs summed from the simulated PV).
        """
        X = np.atleast_2d(X)
        if bound is None:                    # the kernel's sums with no stop: the same costs
            bound = np.full(X.shape[0], np.inf)
        self.n_evals += X.shape[0]
        try:
            c = self.s.bounded_costs(self.full(X), self.u, self.y, bound, reset=self.reset)
        except (ValueError, ZeroDivisionError, FloatingPointError):
            c = np.full(X.shape[0], np.nan)
        c[np.isnan(c)] = _BIG                # not finite; ``inf``: stopped early
        return c


def _lhs(rng, pop, k):
    return (rng.permuted(np.tile(np.arange(pop), (k, 1)), axis=1).T + rng.random((pop, k))) / pop


def _de(obj: _Objective, rng, pop: int, gens: int, seeds=None, spread=None, tol=1e-7,
        patience=20, islands: int = 2, stop_after: int | None = None):
    """Differential evolution (current-to-pbest/1/bin) in the unit cube; all rows at once.

    ``islands`` independent populations of ``pop`` members evolve side by
    side (their trial vectors are simulated in one batch); the budget is
    ``islands * pop * gens`` evaluations.  An island whose population has
    converged or stalled restarts from a fresh Latin hypercube that keeps the
    best member found so far.  Stick-slip friction makes the cost rugged;
    several independent populations make the search much less of a lottery.

    Warm start: the ``seeds`` rows are simulated once and put into every
    island; with ``spread`` up to half of each island is drawn around the
    best seed (normal with standard deviation ``spread`` per coordinate,
    uniform where ``spread >= 1``), the rest stays a Latin hypercube.
    ``stop_after``: the evolution ends once the best cost has not fallen by
    a relative ``1e-6`` for that many generations (None: the whole budget).
    """
    k = len(obj.free)
    n_isl = max(1, int(islands))
    X = np.stack([_lhs(rng, pop, k) for _ in range(n_isl)])          # (n_isl, pop, k)
    if seeds is None:
        fx = obj(X.reshape(-1, k)).reshape(n_isl, pop)
    else:
        S = np.atleast_2d(np.asarray(seeds, float))[:, obj.free]
        m = min(len(S), pop)
        fs = obj(S[:m])                                              # each seed simulated once
        X[:, :m] = S[:m]
        if spread is not None and m < pop:
            sp = np.asarray(spread, float)[obj.free]
            nc = min(pop - m, pop // 2)
            centre = S[int(np.argmin(fs))]
            for j in range(n_isl):
                C = centre[None, :] + rng.normal(size=(nc, k)) * sp[None, :]
                wide = sp >= 1.0
                C[:, wide] = rng.random((nc, int(wide.sum())))
                X[j, m:m + nc] = np.clip(C, 0.0, 1.0)
        fx = np.empty((n_isl, pop))
        fx[:, :m] = fs[None, :]
        if m < pop:
            fx[:, m:] = obj(X[:, m:].reshape(-1, k)).reshape(n_isl, pop - m)
    return _evolve(obj, rng, X, fx, n_isl * pop * gens, tol, patience, stop_after)


def _evolve(obj: _Objective, rng, X, fx, budget: int, tol: float, patience: int, stop_after: int | None):
    """The generations of :func:`_de` from the evaluated islands ``X`` (n_isl, pop, k), costs ``fx``."""
    n_isl, pop, k = X.shape
    used = n_isl * pop
    best = fx.min(axis=1)
    med = np.median(fx, axis=1)
    stall = np.zeros(n_isl, int)
    muF = np.full(n_isl, 0.6)
    muCR = np.full(n_isl, 0.9)
    gi = np.unravel_index(int(np.argmin(fx)), fx.shape)
    gbest_x, gbest_f = X[gi].copy(), float(fx[gi])
    p = max(2, int(round(_PBEST * pop)))
    ar = np.arange(pop)
    quiet = 0                                   # generations without a gain of the best cost
    while used < budget:
        order = np.argsort(fx, axis=1)
        pb = np.take_along_axis(order, rng.integers(0, p, (n_isl, pop)), axis=1)
        r1 = rng.integers(0, pop, (n_isl, pop))
        r2 = rng.integers(0, pop, (n_isl, pop))
        F = np.clip(muF[:, None] + 0.1 * rng.standard_cauchy((n_isl, pop)), 0.1, 1.0)[..., None]
        CR = np.clip(rng.normal(muCR[:, None], 0.1, (n_isl, pop)), 0.0, 1.0)[..., None]
        Xp = np.take_along_axis(X, pb[..., None], axis=1)
        X1 = np.take_along_axis(X, r1[..., None], axis=1)
        X2 = np.take_along_axis(X, r2[..., None], axis=1)
        V = X + F * (Xp - X) + F * (X1 - X2)
        low, high = V < 0, V > 1
        V[low] = X[low] * rng.random(low.sum())
        V[high] = X[high] + (1 - X[high]) * rng.random(high.sum())
        cross = rng.random((n_isl, pop, k)) < CR
        jr = rng.integers(0, k, (n_isl, pop))
        cross[np.arange(n_isl)[:, None], ar[None, :], jr] = True
        U = np.where(cross, V, X)
        # a trial that costs more than its parent is rejected: its simulation may stop there
        bound = np.where(fx < _BIG, fx, np.inf).reshape(-1) if EARLY_STOP else None
        fu = obj(U.reshape(-1, k), bound=bound).reshape(n_isl, pop)
        used += n_isl * pop
        better = fu <= fx
        strict = fu < fx
        for j in range(n_isl):
            if strict[j].any():
                sF, sC = F[j, strict[j], 0], CR[j, strict[j], 0]
                muF[j] = 0.9 * muF[j] + 0.1 * float(np.sum(sF ** 2) / np.sum(sF))
                muCR[j] = 0.9 * muCR[j] + 0.1 * float(np.mean(sC))
        X[better] = U[better]
        fx[better] = fu[better]
        b, m = fx.min(axis=1), np.median(fx, axis=1)
        moving = (b < best * (1 - 1e-6)) | (m < med * (1 - 1e-3))
        stall = np.where(moving, 0, stall + 1)
        best, med = np.minimum(b, best), np.minimum(m, med)
        gi = np.unravel_index(int(np.argmin(fx)), fx.shape)
        quiet = 0 if fx[gi] < gbest_f * (1 - 1e-6) else quiet + 1
        if fx[gi] < gbest_f:
            gbest_x, gbest_f = X[gi].copy(), float(fx[gi])
        if stop_after is not None and quiet >= stop_after:
            break
        done = ((m - b) / np.maximum(np.abs(b), 1e-300) < tol) | (stall >= patience)
        if done.any():
            if budget - used < 0.25 * budget:
                break
            for j in np.where(done)[0]:
                X[j] = _lhs(rng, pop, k)
                X[j, 0] = gbest_x
                fx[j] = obj(X[j])
                used += pop
                best[j], med[j], stall[j] = fx[j].min(), np.median(fx[j]), 0
                muF[j], muCR[j] = 0.6, 0.9
    return gbest_x, gbest_f, X, fx


_BLAS_LIBS: list = []


def _blas_libs() -> list:
    """The OpenBLAS libraries numpy and scipy ship (ctypes handles; empty where they use another BLAS)."""
    if not _BLAS_LIBS:
        import ctypes
        import glob
        import os

        import scipy

        found = []
        for mod in (np, scipy):
            folder = os.path.join(os.path.dirname(os.path.dirname(mod.__file__ or "")), mod.__name__ + ".libs")
            for path in glob.glob(os.path.join(folder, "*openblas*.so*")):
                try:
                    fn = ctypes.CDLL(path).openblas_set_num_threads_local
                except (OSError, AttributeError):
                    continue
                fn.restype, fn.argtypes = ctypes.c_int, [ctypes.c_int]
                found.append(fn)
        _BLAS_LIBS.append(found)
    return _BLAS_LIBS[0]


class _SerialBlas:
    """Context: numpy's and scipy's OpenBLAS run in one thread (this thread only), then as before.

    The least-squares refinement factorises tall Jacobians (``N x k``, ``k`` <= 10) every
    step: microseconds of work that threaded OpenBLAS spreads over all cores, and on cores
    busy with other work (the other worker, the kernel's threads) its threads wait for each
    other: 0.2 ms serial against 6-20 ms threaded per SVD of 2520 x 7 measured on a loaded
    2-core machine.  A no-op where numpy or scipy use another BLAS.
    """

    def __enter__(self):
        self.prev = [fn(1) for fn in _blas_libs()]
        return self

    def __exit__(self, *exc):
        for fn, n in zip(_blas_libs(), self.prev):
            fn(n)
        return False


def _refine(obj: _Objective, x0, max_nfev=40, step=2e-3):
    """Bounded least-squares refinement; Jacobian = one batched simulation."""
    from scipy.optimize import least_squares

    disc = np.array([obj.s.params[j].discrete for j in obj.free], bool)
    cont = np.where(~disc)[0]
    if cont.size == 0:
        return x0, float(obj(x0[None, :])[0])
    x0 = np.asarray(x0, float)
    scale = 1.0 / np.sqrt(len(obj.y))

    def expand(z):
        x = x0.copy()
        x[cont] = z
        return x

    last: list = [None, None]          # the point of the last residual and its simulation

    def fun(z):
        Y = obj.sim(expand(z)[None, :])
        last[0], last[1] = np.array(z, float, copy=True), Y
        r = (Y[:, 0] - obj.y) * scale
        if not np.all(np.isfinite(r)):
            r = np.full_like(obj.y, 1e6)
        return r

    def jac(z):
        x = expand(z)
        h = np.full(cont.size, step)
        up = z + h > 1.0
        h[up] = -h[up]
        X = np.repeat(x[None, :], cont.size + 1, axis=0)
        for j, c in enumerate(cont):
            X[j + 1, c] += h[j]
        if last[0] is not None and np.array_equal(last[0], z):
            # the solver asks for the Jacobian where it has just evaluated the residual: the
            # systems of a batch are independent, so that simulation is the batch's first column
            Y = np.hstack([last[1], obj.sim(X[1:])])
        else:
            Y = obj.sim(X)
        if not np.all(np.isfinite(Y)):
            Y = np.where(np.isfinite(Y), Y, Y[:, :1])
        return ((Y[:, 1:] - Y[:, :1]) / h[None, :]) * scale

    z0 = np.clip(x0[cont], 0.0, 1.0)
    try:
        with _SerialBlas():
            res = least_squares(fun, z0, jac=jac,  # pyright: ignore[reportArgumentType]  # a callable jac is valid
                                bounds=(0.0, 1.0), method="trf",
                                max_nfev=max_nfev, x_scale=1.0, xtol=1e-8, ftol=1e-10)
        x = expand(np.clip(res.x, 0.0, 1.0))
    except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - defensive
        x = x0
    c = float(obj(x[None, :])[0])
    return x, c


def _take_best(obj: _Objective, X, x, c):
    """Simulate the candidate rows ``X`` in one batch; keep the best if it lowers the cost ``c``."""
    bound = c * (1 - 1e-9)
    f = obj(X, bound=np.full(len(X), bound if bound < _BIG else np.inf) if EARLY_STOP else None)
    i = int(np.argmin(f))
    if f[i] < bound:
        return X[i].copy(), float(f[i]), True
    return x, c, False


def _grid_polish(obj: _Objective, x, c, rounds: int = 4, n_grid: int = 17):
    """Batched grid scans over the rugged coordinates around ``x``.

    Friction pairs (``S, J/S`` or ``e_dead, z_max``) are scanned on a 2-D grid
    of relative changes (x0.4 .. x2.5 and zero), the dead time over every
    Euler step within +-8 controller samples; each scan is one batched
    simulation.  Stick-slip events make the cost jump with these parameters,
    which defeats gradient refinement.
    """
    st = obj.s
    names = [st.params[j].name for j in obj.free]
    pos = {n: i for i, n in enumerate(names)}
    groups = []
    for a, b in (("S", "J_rel"), ("e_dead", "z_max")):
        if a in pos and b in pos:
            groups.append((a, b))
    x = np.asarray(x, float).copy()
    for _ in range(rounds):
        improved = False
        for a, b in groups:
            ia, ib = pos[a], pos[b]
            pa, pb = st.params[obj.free[ia]], st.params[obj.free[ib]]
            va, vb = float(pa.value(x[ia])), float(pb.value(x[ib]))
            fac = np.concatenate([[0.0], np.geomspace(0.4, 2.5, n_grid - 1)])
            ga = np.unique(np.clip(np.concatenate([fac * max(va, 1e-4 * pa.hi)]), pa.lo, pa.hi))
            gb = np.unique(np.clip(np.concatenate([fac * max(vb, 1e-4 * pb.hi)]), pb.lo, pb.hi))
            A, B = np.meshgrid(ga, gb, indexing="ij")
            X = np.repeat(x[None, :], A.size, axis=0)
            X[:, ia] = pa.coord(A.ravel())
            X[:, ib] = pb.coord(B.ravel())
            x, c, better = _take_best(obj, X, x, c)
            improved |= better
        if "dh0" in pos:
            it = pos["dh0"]
            X = np.repeat(x[None, :], 41, axis=0)
            X[:, it] = np.linspace(0.0, 1.0, 41)
            x, c, better = _take_best(obj, X, x, c)
            improved |= better
        if "theta" in pos:
            it = pos["theta"]
            pt = st.params[obj.free[it]]
            dte = st.dt_euler
            th = float(pt.value(x[it]))
            ks = np.arange(max(0, round(th / dte) - 8 * st.n_sub),
                           min(round(pt.hi / dte), round(th / dte) + 8 * st.n_sub) + 1)
            X = np.repeat(x[None, :], len(ks), axis=0)
            X[:, it] = pt.coord(ks * dte)
            x, c, better = _take_best(obj, X, x, c)
            improved |= better
        if not improved:
            break
    return x, c


_EFFORT = {"fast": (0.7, 0.45), "normal": (1.0, 0.6), "thorough": (1.25, 1.0)}

#: Early stop (``fit_structure(early_stop=True)``): the evolution ends after
#: ``max(a, b * generations)`` generations without a gain of the best cost.
_STOP = (20, 0.25)

#: ``effort='auto'`` searches thoroughly up to this many samples, normally above: a thorough
#: diagnosis of 1800 samples takes 12-17 s on two cores, of 3600 about 30 s
#: (``benchmarks/bench_diagnosis.py --effort thorough``).
AUTO_THOROUGH_SAMPLES = 1800


def resolve_effort(effort: str, n_samples: int) -> str:
    """The search budget ``effort`` stands for on a record of ``n_samples``."""
    if effort == "auto":
        return "thorough" if n_samples <= AUTO_THOROUGH_SAMPLES else "normal"
    if effort not in _EFFORT:
        raise ValueError(f"effort must be one of auto, {', '.join(_EFFORT)}, got {effort!r}")
    return effort


def search_cost(structure: ModelStructure, n_samples: int, effort: str = "normal", coarse: int = 1) -> float:
    """Estimated work of :func:`fit_structure` on ``n_samples``: its global search's budget of samples.

    Used to hand out the longest fits first; the run time also depends on the cost surface.
    """
    k = len(structure.names)
    pf, gf = _EFFORT[resolve_effort(effort, n_samples)]
    pop = int(np.clip(round(pf * (10 + 4 * k)), 10, 48))
    gens = int(round(gf * (40 + 15 * k)))
    return float(pop * gens * n_samples / max(1, int(coarse)))


def fit_structure(structure: ModelStructure, u, y, n_fit: int | None = None, *,
                  seeds=None, spread=None, free: Sequence[str] | None = None,
                  w_fixed=None, rng=None, popsize: int | None = None,
                  maxiter: int | None = None, local: bool = True, effort: str = "normal",
                  final_n_sub: bool = True, coarse: int = 1, early_stop: bool = False,
                  horizon: int | None = None) -> FitResult:
    """Fit ``structure`` to ``y`` (T,) driven by ``u`` (T,), free-run, on the first ``n_fit`` samples.

    Parameters
    ----------
    structure : ModelStructure
    u : (T,) array, controller output 0..1
    y : (T,) array, measured PV [PV units]
    n_fit : int, optional
        Samples used in the cost (default all); the rest is held out.
    seeds : (m, k) array, optional
        Coordinate vectors put into the initial population (warm start).
    spread : (k,) array, optional
        Standard deviation of a cloud of starts around ``seeds[0]`` per
        coordinate; ``>= 1`` draws that coordinate uniformly.
    free : sequence of str, optional
        Names of the coordinates to fit (default all); the others stay at
        ``w_fixed``.
    w_fixed : (k,) array, optional
        Values of the coordinates not fitted (default ``seeds[0]``).
    rng : numpy Generator or int
    popsize, maxiter : int, optional
        Population size and generation limit of the evolution (defaults
        scale with the number of free parameters and ``effort``).
    local : bool
        Refine the best member by least squares.
    effort : {'auto', 'fast', 'normal', 'thorough'}
    final_n_sub : bool
        Re-simulate the optimum with the smallest ``n_sub`` that passes the
        core's Euler stability check (:func:`valve_gym.core.check_dt`).
    coarse : int
        Coarse-to-fine search (``> 1``, all coordinates free): the evolution
        first runs on every ``coarse``-th sample (controller sample
        ``coarse * dt``, same parameter ranges), then a short evolution
        warm-started from that optimum (a quarter of the generations) and the
        local refinement run on the full record.  Cheaper for long records;
        ignored when fewer than 300 samples would remain.
    early_stop : bool
        End the evolution once its best cost has not fallen (by a relative
        ``1e-6``) for ``max(20, generations / 4)`` generations, instead of
        always spending the whole budget.  Meant for warm starts with a
        ``spread`` (a cloud around the seed): without one the population spends
        its first generations catching up with the seed, and would stop there.
    horizon : int, optional
        Fit the ``horizon``-step-ahead prediction instead of the free run: every
        ``horizon`` samples the measured level restarts from the recorded PV
        (:meth:`ModelStructure.simulate`, ``reset``), so that a slow unmeasured
        load does not accumulate into the error (a prediction-error fit; Ljung,
        *System Identification*, 2nd ed., 1999, ch. 7).  No coarse-to-fine search;
        the result keeps the search's ``n_sub``.

    Returns
    -------
    FitResult
    """
    t0 = time.perf_counter()
    if horizon is not None:
        coarse, final_n_sub = 1, False
    if coarse > 1 and free is None and (len(y) if n_fit is None else int(n_fit)) // coarse >= 300:
        return _coarse_to_fine(structure, u, y, n_fit, seeds=seeds, spread=spread, rng=rng,
                               popsize=popsize, maxiter=maxiter, local=local, effort=effort,
                               final_n_sub=final_n_sub, q=int(coarse))
    rng = np.random.default_rng(rng)
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    T = len(y)
    n_fit = T if n_fit is None else int(n_fit)
    if w_fixed is None:
        w_fixed = (np.atleast_2d(seeds)[0] if seeds is not None
                   else np.array([structure.neutral_coord(p) for p in structure.params]))
    names = structure.names
    free_idx = [names.index(n) for n in (free if free is not None else names)]
    if early_stop and _new_friction(structure, spread):
        early_stop, spread = False, None        # a new friction law: the whole global search
    obj = _Objective(structure, u, y, n_fit, free_idx, w_fixed, horizon)
    kf = len(free_idx)
    pf, gf = _EFFORT[resolve_effort(effort, len(u))]
    if kf == 0:
        w = np.asarray(w_fixed, float).copy()
    else:
        pop = popsize or int(np.clip(round(pf * (10 + 4 * kf)), 10, 48))
        gens = maxiter or int(round(gf * (40 + 15 * kf)))
        stop = int(max(_STOP[0], round(_STOP[1] * gens))) if early_stop else None
        x, c, X, fx = _de(obj, rng, pop, gens, seeds=seeds, spread=spread, stop_after=stop)
        if local:
            for _ in range(2):
                c_start = c
                x, c = _grid_polish(obj, x, c)
                x2, c2 = _refine(obj, x)
                if c2 < c:
                    x, c = x2, c2
                if c > c_start * (1 - 1e-4):
                    break
        w = obj.full(x[None, :])[0]
    ns = structure.stable_n_sub(w) if final_n_sub else structure.n_sub
    y_sim = structure.simulate(w[None, :], u, n_sub=ns, reset=None if horizon is None else (y, horizon))[:, 0]
    res = _make_result(structure, w, y, y_sim, n_fit, ns, obj.n_evals, time.perf_counter() - t0)
    if horizon is not None:
        res = replace(res, horizon=int(horizon))
    structure.release_scratch()                  # the search's scratch arrays: not kept with the result
    return res


#: Coordinates of the friction laws (the rugged ones, see :func:`_grid_polish`).
_FRICTION_COORDS = ("S", "J_rel", "e_dead", "z_max")


def _new_friction(structure: ModelStructure, spread) -> bool:
    """Whether a warm start with ``spread`` leaves friction coordinates of ``structure`` unknown (spread >= 1).

    Stick-slip makes the cost of a friction law multimodal in its band and jump:
    a cloud around a seed that does not know them, and an early stop, miss the
    better basins that the whole global search finds.
    """
    if spread is None:
        return False
    sp = np.asarray(spread, float)
    return any(sp[i] >= 1.0 for i, n in enumerate(structure.names) if n in _FRICTION_COORDS)


def _recode(src: ModelStructure, dst: ModelStructure, W) -> np.ndarray:
    """Unit coordinates ``W`` (m, k) of ``src`` as coordinates of ``dst`` (same internal values)."""
    vals = src.decode(W)
    rows = [dst.encode({k: float(v[i]) for k, v in vals.items()}) for i in range(len(W))]
    return np.vstack(rows)


def _coarse_to_fine(structure: ModelStructure, u, y, n_fit, *, seeds, spread, rng, popsize, maxiter,
                    local, effort, final_n_sub, q: int) -> FitResult:
    """Evolution on every ``q``-th sample, then a short warm-started search on all samples."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(rng)
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    n_fit = len(y) if n_fit is None else int(n_fit)
    sc = structure.scales
    st_c = structure.with_effects(structure.effects, scales=replace(sc, dt=sc.dt * q, n=max(sc.n // q, 1)))
    seeds_c = None if seeds is None else _recode(structure, st_c, np.atleast_2d(seeds))
    rc = fit_structure(st_c, u[::q], y[::q], -(-n_fit // q), seeds=seeds_c, spread=spread, rng=rng,
                       popsize=popsize, maxiter=maxiter, local=False, effort=effort, final_n_sub=False)
    w_c = _recode(st_c, structure, rc.w[None, :])
    seeds_f = w_c if seeds is None else np.vstack([w_c, np.atleast_2d(seeds)])
    kf = len(structure.params)
    gens = maxiter or int(round(_EFFORT[resolve_effort(effort, len(u))][1] * (40 + 15 * kf)))
    spread_f = np.full(kf, 0.05)
    res = fit_structure(structure, u, y, n_fit, seeds=seeds_f, spread=spread_f, rng=rng, popsize=popsize,
                        maxiter=max(4, gens // 4), local=local, effort=effort, final_n_sub=final_n_sub)
    return replace(res, n_evals=res.n_evals + rc.n_evals, seconds=time.perf_counter() - t0)


def fit_with_friction(structure: ModelStructure, u, y, n_fit=None, *, seeds=None, rng=None,
                      effort: str = "normal", frictionless: FitResult | None = None,
                      coarse: int = 1, fast: bool = False):
    """Fit a valve model and its frictionless twin so that the friction fit is nested.

    The frictionless model (``z_max = e_dead = 0``, no slip-jump) is fitted
    first (fewer parameters, smoother cost); the model with friction starts
    from its optimum with the friction parameters at zero, so its cost can
    only be lower.  ``fast``: both searches stop early (see :func:`fit_structure`),
    the friction fit from a cloud around the frictionless optimum.  Without a
    valve (or with ``structure.friction`` False) the structure is fitted alone.

    Returns
    -------
    (FitResult with friction, FitResult frictionless or None)
    """
    rng = np.random.default_rng(rng)
    if structure.actuator != "valve" or not structure.friction:
        return fit_structure(structure, u, y, n_fit, seeds=seeds, rng=rng, effort=effort, coarse=coarse,
                             early_stop=fast), None
    st0 = structure.with_effects(tuple(e for e in structure.effects if e != "slip_jump"),
                                 friction=False)
    if frictionless is None:
        s0 = None
        if seeds is not None:
            s0 = np.vstack([transfer(_pseudo(structure, w), st0)[0] for w in np.atleast_2d(seeds)])
        frictionless = fit_structure(st0, u, y, n_fit, seeds=s0, rng=rng, effort=effort, coarse=coarse,
                                     early_stop=fast)
    s1, spread1 = transfer(frictionless, structure)
    for name in ("e_dead", "z_max", "S"):
        if name in structure.names:
            s1[0, structure.index(name)] = 0.0
    if seeds is not None:
        s1 = np.vstack([s1, np.atleast_2d(seeds)])
    fr = fit_structure(structure, u, y, n_fit, seeds=s1, spread=spread1 if fast else None, rng=rng,
                       effort=effort, coarse=coarse, early_stop=fast)
    return fr, frictionless


class _Pseudo:
    """Coordinates ``w`` (k,) of ``structure`` without a fit: enough for :func:`transfer`."""

    def __init__(self, structure: ModelStructure, w):
        self.structure = structure
        self.w = np.asarray(w, float)


def _pseudo(structure, w):
    return _Pseudo(structure, w)


def _make_result(structure, w, y, y_sim, n_fit, ns, n_evals, seconds) -> FitResult:
    T = len(y)
    yf, sf = y[:n_fit], y_sim[:n_fit]
    finite = np.all(np.isfinite(y_sim))
    cost = float(np.sum((yf - sf) ** 2)) if finite else _BIG
    if n_fit < T:
        hr, hf = rmse(y[n_fit:], y_sim[n_fit:]), fit_percent(y[n_fit:], y_sim[n_fit:])
    else:
        hr = hf = float("nan")
    return FitResult(structure=structure, w=np.asarray(w, float), params=structure.model_params(w, n_sub=ns),
                     physical=structure.physical(w, n_sub=ns), units=structure.units(),
                     y_sim=y_sim, y=y, n_fit=n_fit, cost=cost, rmse=rmse(yf, sf),
                     fit_percent=fit_percent(yf, sf), holdout_rmse=hr, holdout_fit_percent=hf,
                     rmse_all=rmse(y, y_sim), fit_percent_all=fit_percent(y, y_sim),
                     k=structure.k, n_sub=ns, n_evals=n_evals, seconds=seconds)


def init_names(structure: ModelStructure):
    """Names of the initial-state coordinates of a structure."""
    return [n for n in structure.names if n in ("y0", "x1_0", "dh0")]


def fit_initial_state(result: FitResult, u, y, rng=None) -> FitResult:
    """Simulate a fitted model on another input, refitting only its initial state.

    The model parameters stay as fitted; the initial level(s) are refitted
    (free run over the whole of ``y``), as for a second record of the same
    plant whose starting point is unknown.

    Parameters
    ----------
    result : FitResult, the fitted model
    u : (T,) array, the other record's controller output 0..1
    y : (T,) array, the other record's PV

    Returns
    -------
    FitResult on the other record (``n_fit = T``; ``cost``/``rmse`` are the
    validation error).
    """
    y = np.asarray(y, float)
    k = max(3, min(5, len(y) // 20))
    sc2 = replace(result.structure.scales, y0=float(np.median(y[:k])))
    st = ModelStructure(result.structure.plant, result.structure.actuator,
                        result.structure.effects, sc2, n_sub=result.n_sub,
                        friction=result.structure.friction, variants=result.structure.variants,
                        period_hint=result.structure.period_hint,
                        output_offset=result.structure.output_offset)
    w = result.w.copy()
    names = init_names(st)
    # the other record's first sample is the natural starting level
    w[st.index("y0")] = float(st.params[st.index("y0")].coord(0.0))
    return fit_structure(st, u, y, None, seeds=w[None, :], w_fixed=w, free=names, rng=rng,
                         popsize=12, maxiter=30, final_n_sub=False)


# --------------------------------------------------------------------------- estimator
class ModelFitter:
    """Fit the simulator to a recording by free-run simulation error (scikit-learn style).

    Parameters
    ----------
    plant : {'tank', 'integrating', 'first_order', 'cascade'}
        Process model (see :mod:`valve_gym.diagnosis.model`).
    actuator : {'valve', 'pump'}
        The paper's valve with friction (``z_max``, ``e_dead`` free) or a pump.
    effects : sequence of str
        Optional physics switched on (names of :data:`valve_gym.params.EFFECTS`
        that the fitter supports, :data:`~valve_gym.diagnosis.model.CANDIDATE_EFFECTS`).
    friction : bool
        ``False`` fits a frictionless valve.
    variants : dict, optional
        ``{'valve_characteristic': 'equal_percentage' | 'quick_opening'}``.
    holdout : float
        Fraction (0..0.9) of the record, at its end, left out of the fit;
        ``holdout_rmse_`` reports the error there (the model runs on from
        the fit part without reset).
    n_sub : int
        Euler steps per controller sample during the search (the reported
        simulation uses the smallest ``n_sub >=`` this that passes the core's
        stability check).
    saturation : 'auto', None or (lo, hi)
        Sensor range of the PV (see :class:`~valve_gym.diagnosis.model.DataScales`).
    period_hint : float, optional
        Period [s] around which ``oscillating_disturbance`` searches.
    effort : {'auto', 'fast', 'normal', 'thorough'}
        Search budget.
    popsize, maxiter : int, optional
        Override the evolution's population size and generation limit.
    local : bool
        Least-squares refinement of the best member.
    seed : int
        Seed of the search's random generator (results are reproducible).

    Attributes
    ----------
    params_ : ModelParams
        Fitted core parameters (scalars).
    physical_ : dict
        Fitted parameters by core field name; ``units_`` their units.
    initial_state_ : dict
        Fitted initial level(s) and stem position.
    cost_ : float
        Sum of squared free-run errors on the fit samples [PV^2].
    rmse_, fit_percent_ : float
        Over the whole record [PV], [%] (NRMSE fit, 100 = perfect).
    holdout_rmse_, holdout_fit_percent_ : float
        On the held-out end of the record (nan without holdout).
    y_sim_ : (T,) ndarray
        Free-run simulated PV [PV].
    result_ : FitResult
        Everything above and more.

    Examples
    --------
    >>> from valve_gym.diagnosis.synthetic import make_recording
    >>> rec = make_recording("none", seed=1, n=400)
    >>> f = ModelFitter(plant="tank", effort="fast").fit(rec)
    >>> bool(f.fit_percent_ > 80)
    True
    """

    def __init__(self, plant: str = "tank", actuator: str = "valve", effects: Sequence[str] = (),
                 *, friction: bool = True, variants: dict | None = None,
                 holdout: float = 0.0, n_sub: int = 2, saturation="auto",
                 period_hint: float | None = None, output_offset: bool | None = None,
                 effort: str = "normal", popsize: int | None = None,
                 maxiter: int | None = None, local: bool = True, seed: int = 0):
        self.plant = plant
        self.actuator = actuator
        self.effects = effects
        self.friction = friction
        self.variants = variants
        self.holdout = holdout
        self.n_sub = n_sub
        self.saturation = saturation
        self.period_hint = period_hint
        self.output_offset = output_offset
        self.effort = effort
        self.popsize = popsize
        self.maxiter = maxiter
        self.local = local
        self.seed = seed

    def _structure(self, rec: Recording, n_fit: int) -> ModelStructure:
        sc = DataScales.from_signals(rec.op[:n_fit], rec.pv[:n_fit], rec.dt,
                                     saturation=self.saturation)
        if self.saturation == "auto":
            full = DataScales.from_signals(rec.op, rec.pv, rec.dt, saturation="auto")
            sc = replace(sc, sat_hi=full.sat_hi, sat_lo=full.sat_lo)
        return ModelStructure(self.plant, self.actuator, tuple(self.effects), sc,
                              n_sub=self.n_sub, friction=self.friction, variants=self.variants,
                              period_hint=self.period_hint, output_offset=self.output_offset)

    def fit(self, recording: Recording, init=None) -> ModelFitter:
        """Fit to ``recording``; returns ``self``.

        Parameters
        ----------
        recording : Recording
        init : FitResult or (k,) array, optional
            Warm start: a previous fit of a structure with a subset of these
            effects, or unit coordinates of this structure.
        """
        if not isinstance(recording, Recording):
            raise TypeError("fit() needs a Recording (see valve_gym.diagnosis.load_recording)")
        if not 0.0 <= float(self.holdout) <= 0.9:
            raise ValueError(f"holdout must be a fraction in [0, 0.9], got {self.holdout!r}")
        T = len(recording)
        n_fit = T - int(round(float(self.holdout) * T))
        if n_fit < 20:
            raise ValueError(f"only {n_fit} samples left to fit after the holdout; use a "
                             f"longer recording or a smaller holdout")
        st = self._structure(recording, n_fit)
        seeds = spread = None
        if isinstance(init, FitResult):
            seeds, spread = transfer(init, st)
        elif init is not None:
            seeds = np.atleast_2d(np.asarray(init, float))
        res = fit_structure(st, recording.op, recording.pv, n_fit, seeds=seeds, spread=spread,
                            rng=self.seed, popsize=self.popsize, maxiter=self.maxiter,
                            local=self.local, effort=self.effort)
        self._set(res)
        return self

    def _set(self, res: FitResult):
        self.result_ = res
        self.structure_ = res.structure
        self.params_ = res.params
        self.physical_ = res.physical
        self.units_ = res.units
        self.initial_state_ = res.structure.initial_values(res.w)
        self.cost_ = res.cost
        self.rmse_ = res.rmse_all
        self.fit_percent_ = res.fit_percent_all
        self.holdout_rmse_ = res.holdout_rmse
        self.holdout_fit_percent_ = res.holdout_fit_percent
        self.y_sim_ = res.y_sim
        self.n_sub_ = res.n_sub
        return self

    def predict(self, recording: Recording, refit_initial: bool = True) -> np.ndarray:
        """Free-run PV ``(T,)`` of the fitted model on another recording's controller output.

        With ``refit_initial`` the initial level(s) are refitted to that
        recording (the model parameters are not); otherwise the fitted
        initial state is used.
        """
        if not hasattr(self, "result_"):
            raise RuntimeError("ModelFitter is not fitted yet; call fit(recording) first")
        if refit_initial:
            return fit_initial_state(self.result_, recording.op, recording.pv, rng=self.seed).y_sim
        return self.structure_.simulate(self.result_.w[None, :], recording.op,
                                        n_sub=self.n_sub_)[:, 0]

    def score(self, recording: Recording) -> float:
        """NRMSE fit [%] on ``recording`` (initial state refitted)."""
        return fit_percent(recording.pv, self.predict(recording))


def transfer(prev: FitResult | _Pseudo, st: ModelStructure):
    """Warm start for ``st`` from a fit of a related structure.

    Shared internal parameters keep their fitted values, new effect
    parameters start where they leave the model unchanged.  Returns
    ``(seeds, spread)`` for :func:`fit_structure`: the seed and a per
    coordinate spread (small for known, uniform for new coordinates).
    """
    vals = prev.structure.decode(prev.w[None, :])
    common = {k: float(v[0]) for k, v in vals.items() if k in st.names}
    w0 = st.encode(common)
    spread = np.array([0.05 if p.name in common else 1.0 for p in st.params])
    return w0[None, :], spread


class ParamUncertainty(NamedTuple):
    """One fitted parameter with its standard error.

    ``name`` internal parameter name, ``value`` and ``sd`` in ``unit``; the
    90 % interval is ``value +- 1.645 sd`` (local, Gaussian approximation).
    """

    name: str
    value: float
    sd: float
    unit: str


def parameter_uncertainty(fit: FitResult, u, y, step: float = 1e-3) -> list[ParamUncertainty]:
    """Standard errors of the fitted parameters from the free-run Jacobian at the optimum.

    Parameters
    ----------
    fit : FitResult (its first ``n_fit`` samples are the ones fitted)
    u : (T,) controller output 0..1, y : (T,) measured PV
    step : float, finite-difference step in unit coordinates

    Returns
    -------
    list of ParamUncertainty, one per continuous free parameter

    Notes
    -----
    ``cov(w) = s^2 (J^T J)^{-1} N / n_eff`` with ``J`` the Jacobian of the
    simulated PV with respect to the unit coordinates (one batched
    simulation), ``s^2 = SSE / (N - k)`` and ``n_eff`` the effective number of
    independent residual samples (:func:`effective_n`): free-run residuals are
    autocorrelated, and the plain formula would claim ``N / n_eff`` times too
    much information.  Mapped to parameter values by the derivative of each
    coordinate's scale.  A local approximation: it says nothing of other
    optima of a rugged cost.
    """
    st = fit.structure
    w = np.asarray(fit.w, float)
    n = int(fit.n_fit)
    y = np.asarray(y, float)[:n]
    free = [i for i, p in enumerate(st.params) if not p.discrete]
    h = np.where(w[free] + step <= 1.0, step, -step)
    W = np.repeat(w[None, :], len(free) + 1, axis=0)
    for j, i in enumerate(free):
        W[j + 1, i] += h[j]
    Y = st.simulate(W, u, n_sub=fit.n_sub)[:n]
    r = y - Y[:, 0]
    Jm = (Y[:, 1:] - Y[:, :1]) / h[None, :]
    s2 = float(r @ r) / max(n - len(free), 1)
    cov = np.linalg.pinv(Jm.T @ Jm) * s2 * (n / effective_n(r))
    sd_w = np.sqrt(np.maximum(np.diag(cov), 0.0))
    out = []
    for j, i in enumerate(free):
        p = st.params[i]
        lo, hi = max(w[i] - 1e-4, 0.0), min(w[i] + 1e-4, 1.0)
        dv = (float(p.value(hi)) - float(p.value(lo))) / max(hi - lo, 1e-12)
        out.append(ParamUncertainty(p.name, float(p.value(w[i])), float(abs(dv) * sd_w[j]), p.unit))
    return out
