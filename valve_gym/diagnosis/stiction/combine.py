r"""Combine the methods' evidence into one calibrated stiction probability and a stiction size.

Each :class:`~._base.Evidence` becomes one or two features, weighted by the
method's own reliability on the record (a method that does not apply
contributes 0, the neutral value).  A logistic model maps the features to the
probability that the valve sticks; its weights are fitted by
``benchmarks/validate_stiction.py`` (L2-penalised, class-balanced maximum
likelihood on simulated loops with known friction and the labelled plant
loops; the same script measures it held out) and stored in
:mod:`._weights`.

Notes
-----
.. math:: p = \sigma\Big(b + \sum_i w_i \frac{f_i - \mu_i}{s_i}\Big), \qquad
          \sigma(z) = 1/(1 + e^{-z})

Fitted by Newton's method (iteratively reweighted least squares) on
``-sum_k c_k [y_k ln p_k + (1-y_k) ln(1-p_k)] + lambda/2 |w|^2`` with class
weights ``c_k`` that give both classes the same total weight.  Verdict:
``'stiction'`` for ``p >= 0.5 + margin``, ``'no stiction'`` for
``p <= 0.5 - margin``, ``'undecided'`` between (``margin = 0.1``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ._base import Evidence
from .hammerstein import NAN_SIZE, SizeEstimate, fit_moves

__all__ = ["FEATURES", "features", "LogisticModel", "fit_logistic", "StictionAssessment",
           "combine_sizes", "MARGIN", "KSTEP_FINDS", "KSTEP_BANDS", "band_matters", "stiction_present",
           "public_present"]

#: Names of the features, in the order of :func:`features`.
FEATURES = ("horch_ccf", "horch_int", "bicoherence", "ellipse", "waveform", "episodes", "hammerstein",
            "hammerstein_band", "oscillating")
#: Half-width of the undecided band around p = 0.5.
MARGIN = 0.1


def features(evidence: Sequence[Evidence], plant: str) -> np.ndarray:
    """Feature vector ``(len(FEATURES),)`` of one record's evidence (neutral value 0).

    Two regimes: in a loop that oscillates regularly (``oscillating`` = 1) the shape methods
    read the cycle; in one that does not, the stick-episode index reads the stick episodes
    (it is 0 in the oscillating regime, where a limit cycle's turning points are not stick
    episodes).  ``oscillating`` gives each regime its own intercept; the model-based pair
    applies in both.
    """
    ev = {e.method: e for e in evidence}
    f = dict.fromkeys(FEATURES, 0.0)

    def use(name):
        e = ev.get(name)
        return e if (e is not None and e.applicable and np.isfinite(e.value)) else None

    h = use("horch")
    if h is not None:
        key, centre = ("horch_int", 0.7) if plant == "integrating" else ("horch_ccf", 0.5)
        f[key] = h.reliability * (h.value - centre)
    b = use("bicoherence")
    if b is not None:
        f["bicoherence"] = b.reliability * float(np.clip(b.value, 0.0, 0.5))
    for name in ("ellipse", "waveform"):
        e = use(name)
        if e is not None:
            f[name] = e.reliability * (e.value - 0.5)
    m = use("hammerstein")
    if m is not None:
        f["hammerstein"] = float(np.clip(m.value, -3.0, 5.0))
        f["hammerstein_band"] = float(np.clip(m.details.get("log_band_ratio", 0.0), -2.0, 1.0))
    osc = ev["episodes"].details.get("regular_oscillation", 0.0) if "episodes" in ev else 0.0
    f["oscillating"] = float(osc)
    ep = use("episodes")
    if ep is not None and not osc:
        f["episodes"] = ep.value - 0.3
    return np.array([f[k] for k in FEATURES])


@dataclass(frozen=True)
class LogisticModel:
    """A fitted logistic model over :data:`FEATURES`.

    Attributes
    ----------
    names : tuple of str, feature names
    mean, scale : tuple of float, standardisation of each feature
    coef : tuple of float, weight of each standardised feature
    intercept : float
    l2 : float, penalty it was fitted with
    n_train : int, records it was fitted on
    """

    names: tuple[str, ...]
    mean: tuple[float, ...]
    scale: tuple[float, ...]
    coef: tuple[float, ...]
    intercept: float
    l2: float = 1.0
    n_train: int = 0

    def decision(self, X) -> np.ndarray:
        """Log-odds of stiction, ``(n,)`` for features ``X`` (n, len(names))."""
        X = np.atleast_2d(np.asarray(X, float))
        Z = (X - np.asarray(self.mean)) / np.asarray(self.scale)
        return Z @ np.asarray(self.coef) + self.intercept

    def probability(self, X) -> np.ndarray:
        """Probability of stiction, ``(n,)``."""
        return 1.0 / (1.0 + np.exp(-np.clip(self.decision(X), -40, 40)))

    def to_dict(self) -> dict:
        """JSON-ready dict."""
        return {"names": list(self.names), "mean": list(self.mean), "scale": list(self.scale),
                "coef": list(self.coef), "intercept": self.intercept, "l2": self.l2,
                "n_train": self.n_train}

    @staticmethod
    def from_dict(d: dict) -> LogisticModel:
        """Inverse of :meth:`to_dict`; checks the feature names."""
        if tuple(d["names"]) != FEATURES:
            raise ValueError(f"stiction model features {d['names']} do not match {list(FEATURES)}; "
                             "refit with benchmarks/validate_stiction.py --write-model")
        return LogisticModel(tuple(d["names"]), tuple(d["mean"]), tuple(d["scale"]), tuple(d["coef"]),
                             float(d["intercept"]), float(d.get("l2", 1.0)), int(d.get("n_train", 0)))


def fit_logistic(X, y, l2: float = 1.0, iters: int = 50, weights=None,
                 use: Sequence[str] | None = None) -> LogisticModel:
    """Class-balanced, L2-penalised logistic regression by Newton's method (see module notes).

    Parameters
    ----------
    X : (n, len(FEATURES)) features
    y : (n,) 0/1 labels (1 = stiction); both classes must occur
    l2 : float, penalty on the standardised weights (not on the intercept)
    iters : int, Newton steps at most
    weights : (n,) array, optional, weight of each record (e.g. 1/records per loop tag)
    use : sequence of feature names, optional (default all): the others get weight 0
        (mean 0, scale 1), i.e. the model ignores them
    """
    X = np.asarray(X, float)
    y = np.asarray(y, float)
    if X.ndim != 2 or X.shape[1] != len(FEATURES) or len(y) != len(X):
        raise ValueError(f"X must be (n, {len(FEATURES)}) and y (n,), got {X.shape} and {y.shape}")
    unknown = set(use or ()) - set(FEATURES)
    if unknown:
        raise ValueError(f"unknown stiction features {sorted(unknown)}; use names from {list(FEATURES)}")
    on = np.array([use is None or k in use for k in FEATURES])
    sw = np.ones(len(y)) if weights is None else np.asarray(weights, float)
    n1, n0 = np.sum(sw * y), np.sum(sw * (1 - y))
    if n1 == 0 or n0 == 0:
        raise ValueError("fit_logistic needs records of both classes (stiction and not)")
    mu = np.where(on, np.average(X, axis=0, weights=sw), 0.0)
    sd = np.sqrt(np.average((X - mu) ** 2, axis=0, weights=sw))
    sd = np.where((sd > 1e-9) & on, sd, 1.0)
    Z = np.column_stack([((X - mu) / sd)[:, on], np.ones(len(X))])
    c = sw * np.where(y == 1, 0.5 * sw.sum() / n1, 0.5 * sw.sum() / n0)
    beta = np.zeros(Z.shape[1])
    pen = np.full(Z.shape[1], l2)
    pen[-1] = 0.0
    for _ in range(iters):
        p = 1 / (1 + np.exp(-np.clip(Z @ beta, -40, 40)))
        g = Z.T @ (c * (p - y)) + pen * beta
        H = (Z * (c * p * (1 - p))[:, None]).T @ Z + np.diag(pen + 1e-9)
        step = np.linalg.solve(H, g)
        beta -= step
        if np.max(np.abs(step)) < 1e-8:
            break
    coef = np.zeros(len(FEATURES))
    coef[on] = beta[:-1]
    return LogisticModel(FEATURES, tuple(map(float, mu)), tuple(map(float, sd)),
                         tuple(map(float, coef)), float(beta[-1]), float(l2), int(len(y)))


def verdict_of(p: float, margin: float = MARGIN) -> str:
    """``'stiction'``, ``'no stiction'`` or ``'undecided'`` for probability ``p``."""
    if p >= 0.5 + margin:
        return "stiction"
    if p <= 0.5 - margin:
        return "no stiction"
    return "undecided"


#: Criterion change of the k-step test (:mod:`.kstep`) below which it finds friction on its own:
#: the usual margin of the information criterion (``SelectionRule.ic_margin``).
KSTEP_FINDS = -2.0


def band_matters(verdict: Mapping, bands: Sequence[str] = ("band",)) -> bool:
    """Whether a tested friction verdict's band reaches ``band_needed``.

    ``bands`` names the bands read, any of which may reach it: ``'band'`` (the free-run fit's dead
    band or stick band) and ``'kstep_band'`` (the k-step fit's, see :func:`stiction_present`).

    >>> band_matters({"tested": True, "band": 0.012, "band_needed": 0.01}), band_matters({"tested": False})
    (True, False)
    >>> v = {"tested": True, "band": 0.002, "kstep_band": 0.015, "band_needed": 0.01}
    >>> band_matters(v), band_matters(v, ("band", "kstep_band"))
    (False, True)
    """
    need = float(verdict.get("band_needed", np.inf))
    return bool(verdict.get("tested")) and any(float(verdict.get(b, 0.0)) >= need for b in bands)


#: The bands the k-step branch of :func:`stiction_present` reads (:func:`band_matters`).
KSTEP_BANDS = ("band", "kstep_band")


def stiction_present(verdict: str, model_based_present: bool, kstep_delta_ic: float | None,
                     band_ok: bool = False) -> bool:
    """The public verdict ``stiction.present`` of a diagnosis.

    True when the methods combined say ``'stiction'``, or when a model-based friction test finds
    friction:

    * the free-run verdict finds it and the k-step test (:mod:`.kstep`) does not contradict it:
      friction also lowers the information criterion of the k-step-ahead predictions
      (``kstep_delta_ic < 0``);
    * or the k-step test finds it on its own (``kstep_delta_ic`` below :data:`KSTEP_FINDS`) and the
      friction band is one that matters (``band_ok``: the free-run fit's band or the k-step
      fit's own is at least the one the free-run verdict asks for, :func:`band_matters` with
      :data:`KSTEP_BANDS`).

    Without a k-step test (``None``: a pump, a measurement effect in the model) the free-run
    verdict counts alone.  ``'undecided'`` alone is not stiction.

    The two model-based tests see a slow unmeasured load differently.  The free run must
    reproduce the load from the controller output alone: a load can outweigh what friction
    explains (few effective samples, no criterion gain) or be taken for friction.  The k-step test
    restarts the level from the record every few samples, so a load does not accumulate there,
    while a sticking valve still shows after each controller move.  So a free-run friction that the
    k-step predictions do not want is most often a load, and a friction that the k-step predictions
    want is believed even where the free run, swamped by the load, cannot show it, provided its
    band is one the free-run verdict would call (a small band that helps the predictions is
    not a sticking valve an engineer has to act on).

    Examples
    --------
    >>> stiction_present("stiction", False, None), stiction_present("no stiction", True, -11.5)
    (True, True)
    >>> stiction_present("no stiction", True, 4.0), stiction_present("undecided", True, None)
    (False, True)
    >>> stiction_present("no stiction", False, -13.5), stiction_present("no stiction", False, -13.5, True)
    (False, True)
    >>> stiction_present("no stiction", False, -1.5, True)
    False
    """
    if verdict == "stiction":
        return True
    if kstep_delta_ic is None or not np.isfinite(kstep_delta_ic):
        return bool(model_based_present)
    if band_ok and float(kstep_delta_ic) < KSTEP_FINDS:
        return True
    return bool(model_based_present and float(kstep_delta_ic) < 0.0)


def public_present(verdict: str, friction: Mapping) -> bool:
    """:func:`stiction_present` of a diagnosis' friction verdict ``friction`` (its ``stiction`` dict).

    Reads ``model_based_present`` (the free-run verdict), ``kstep_delta_ic``, the bands of
    :data:`KSTEP_BANDS` against ``band_needed`` and whether the k-step fit's valve slips
    (``kstep_slips`` and ``op_working_range``, :func:`~.hammerstein.friction_moves`); ``verdict`` is the methods'
    combined verdict.

    >>> public_present("no stiction", {"tested": True, "model_based_present": False, "kstep_delta_ic": -5.0,
    ...                                "band": 0.001, "kstep_band": 0.02, "band_needed": 0.01})
    True
    """
    return stiction_present(verdict, bool(friction.get("model_based_present")), friction.get("kstep_delta_ic"),
                            band_matters(friction, KSTEP_BANDS) and fit_moves(friction, "kstep_slips"))


def combine_sizes(sizes: Sequence[SizeEstimate]) -> tuple[SizeEstimate, bool | None]:
    """One S, J estimate from several methods, and whether their S intervals overlap.

    The first method with a finite S is the primary one (the fitted friction block: it
    estimates S itself; the ellipse's apparent stiction is a loop-dependent proxy of it):
    its S, J and intervals are reported.  The others check it: ``agree`` is True when
    every S interval overlaps the primary one, False when one does not (then trust
    neither alone), None with a single method.
    """
    ok = [s for s in sizes if np.isfinite(s.S)]
    if not ok:
        return NAN_SIZE, None
    main = ok[0]
    if len(ok) == 1:
        return main, None
    agree = all(s.S_lo <= main.S_hi and main.S_lo <= s.S_hi for s in ok[1:])
    return main._replace(method="+".join(s.method for s in ok)), bool(agree)


@dataclass(frozen=True)
class StictionAssessment:
    """The combined stiction verdict of one record.

    Attributes
    ----------
    probability : float, 0..1, calibrated probability that the valve sticks
    verdict : str, ``'stiction'``, ``'no stiction'`` or ``'undecided'``
    S, J : float, stiction band and slip jump, fractions of stroke (nan if unknown)
    S_interval, J_interval : (float, float), 90 % intervals, fractions of stroke
    sizes_agree : bool or None, whether the methods' S intervals overlap (None: one method)
    sizes : list of SizeEstimate, each method's own estimate
    evidence : list of Evidence, each method's reading
    features : dict of str to float, the model's inputs
    contributions : dict of str to float, each feature's pull on the log-odds relative to the
        same method being silent (feature 0): ``coef * f / scale``
    """

    probability: float
    verdict: str
    S: float
    J: float
    S_interval: tuple[float, float]
    J_interval: tuple[float, float]
    sizes_agree: bool | None
    sizes: list[SizeEstimate] = field(default_factory=list)
    evidence: list[Evidence] = field(default_factory=list)
    features: dict[str, float] = field(default_factory=dict)
    contributions: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready dict (nan becomes None)."""
        def f(x):
            x = float(x)
            return x if np.isfinite(x) else None
        return {"probability": f(self.probability), "verdict": self.verdict, "S": f(self.S),
                "J": f(self.J), "S_interval": [f(v) for v in self.S_interval],
                "J_interval": [f(v) for v in self.J_interval], "sizes_agree": self.sizes_agree,
                "sizes": [{k: (f(v) if k != "method" else v) for k, v in s._asdict().items()}
                          for s in self.sizes],
                "evidence": [e.to_dict() for e in self.evidence],
                "features": {k: f(v) for k, v in self.features.items()},
                "contributions": {k: f(v) for k, v in self.contributions.items()}}
