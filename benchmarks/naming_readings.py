"""Load-robust readings of the effect selection, compared on the other simulator's loops.

The effect naming on :mod:`valve_gym.diagnosis.stiction.loops` (``benchmarks/naming_other_sim.py``) is
limited by the loops' slowly drifting unmeasured load.  This script reads the first round of each
diagnosis' selection in several ways, all on the same free-run fits, and counts how often the first
effect it would name is the concealed one:

* ``free run``: the release's reading, the selection's own verdict on each candidate (criterion on the
  effective samples of the free-run residual, held-out RMSE, friction band;
  :func:`valve_gym.diagnosis.select.compare`);
* ``whitened AR(p), base``: every model's residual filtered by the AR(p) noise model of the base
  model's fit-part residual (one-step prediction errors), criterion on the filtered samples, held-out
  RMSE of the filtered held-out part;
* ``own AR(p)``: each model's residual filtered by an AR(p) fitted to its own residual;
* ``load model (Kalman)``: each model's residual read as a stationary AR(1) level disturbance plus white
  noise, pole (at most 0.9999) and variance ratio by maximum likelihood per model, the criterion the
  Kalman filter's ``-2 log L``; the held-out test the free-run one;
* ``blocks w/B`` (``+ held-out``): the free-run criterion and band, with the held-out test replaced by
  (or joined to) a consistency test: the whole record (fit part and held-out end) cut into ``B`` equal
  blocks, the candidate must lower the squared error of at least ``w`` of them.  A real effect should fit
  better at every level the loop visits; a term that fits one stretch of the drifting load should not;
* ``swap on the whole record``: a candidate that adds no parameter (slip-jump friction in place of the
  paper's) judged by the criterion on the whole record's residual (fit part and held-out end, its
  effective samples), with no held-out test: in these loops the two parts often disagree under the load.

The decision is the default rule's (:class:`valve_gym.diagnosis.select.SelectionRule`: the criterion
falls past its margin, the held-out test, the friction band) on the round's confirmed candidates; the
first round's winner is compared with the concealed effect.  So read, a loop whose selection names
``tank_shape`` first on a tank that is not a cylinder counts as wrong here (``naming_other_sim.py`` sets
it aside), so the ``free run`` column is a little below that script's count.  Docs:
docs/diagnosis.md, "Tried on these draws and not kept".

Usage::

    nice -n 10 python benchmarks/naming_readings.py [--per-effect 6] [--first 0] [--jobs 2]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from naming_other_sim import EFFECTS, make_case  # noqa: E402

from valve_gym._numba import njit  # noqa: E402
from valve_gym.diagnosis import diagnose  # noqa: E402
from valve_gym.diagnosis.fit import effective_n  # noqa: E402
from valve_gym.diagnosis.select import SelectionRule, friction_band, holdout_pays  # noqa: E402

#: Grid of the load model's pole and variance ratio (load innovations over white noise).
RHOS = np.array([0.0, 0.5, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995, 0.998, 0.999, 0.9995, 0.9999])
LAMS = 10.0 ** np.arange(-5.0, 2.01, 0.5)


def ar_fit(r: np.ndarray, p: int) -> np.ndarray:
    """Least-squares AR(p) coefficients of ``r`` (its mean removed)."""
    r = r - r.mean()
    X = np.column_stack([r[p - j - 1: len(r) - j - 1] for j in range(p)])
    return np.linalg.lstsq(X, r[p:], rcond=None)[0]


def ar_filter(r: np.ndarray, a: np.ndarray) -> np.ndarray:
    """One-step prediction errors ``A(q) r`` (the first ``len(a)`` samples dropped)."""
    p = len(a)
    out = r[p:].copy()
    for j in range(p):
        out -= a[j] * r[p - j - 1: len(r) - j - 1]
    return out


@njit(cache=True)
def kalman_m2ll(r, rho, lam):  # pragma: no cover - compiled
    """``-2 log L`` (scale profiled out) of ``r`` as a stationary AR(1) state (pole ``rho``, innovation
    variance ``lam``) observed in unit white noise."""
    n = r.shape[0]
    P = lam / (1.0 - rho * rho)
    x = 0.0
    sld = 0.0
    sq = 0.0
    for t in range(n):
        S = P + 1.0
        nu = r[t] - x
        sld += np.log(S)
        sq += nu * nu / S
        K = P / S
        x = rho * (x + K * nu)
        P = rho * rho * (P - K * P) + lam
    return n * np.log(sq / n) + sld


def load_m2ll(r: np.ndarray) -> float:
    """The load model's ``-2 log L`` of ``r``, maximised over :data:`RHOS` x :data:`LAMS`."""
    r = np.ascontiguousarray(r, dtype=float)
    return min(kalman_m2ll(r, rho, lam) for rho in RHOS for lam in LAMS)


def _decide(rows, rule: SelectionRule) -> str:
    """The round's winner: ``rows`` of (effect, criterion change, held-out change, dk, band ok)."""
    best = None
    for effect, d, h, dk, band_ok in rows:
        if d < -rule.ic_margin and holdout_pays(h, rule, dk) and band_ok and (best is None or d < best[1]):
            best = (effect, d)
    return "none" if best is None else best[0]


#: The block readings measured: (blocks, blocks the candidate must win).
BLOCKS = ((6, 4), (6, 5), (9, 5), (9, 6), (9, 8))


def block_wins(base_residual: np.ndarray, residual: np.ndarray, blocks: int) -> int:
    """In how many of ``blocks`` equal blocks of the record ``residual`` has less squared error than the base's."""
    edges = np.linspace(0, len(base_residual), blocks + 1).astype(int)
    return sum(float(np.sum(residual[a:b] ** 2)) < float(np.sum(base_residual[a:b] ** 2))
               for a, b in zip(edges[:-1], edges[1:]))


def readings(case) -> dict[str, str]:
    """The first effect each reading names for one diagnosed case.

    ``case``: ``n_fit``, ``base`` (FitResult), ``cands`` (the first round's confirmed candidates,
    :class:`~valve_gym.diagnosis.select.CandidateFit`), ``u`` (the controller output as paired).
    The free-run reading is the selection's own judgement of each candidate (``pays``, ``delta_ic``).
    """
    n, base, cands, u, rule = case["n_fit"], case["base"], case["cands"], case["u"], SelectionRule()
    need = rule.band_needed(u)
    paying = [c for c in cands if c.pays]
    out: dict[str, str] = {"free run": min(paying, key=lambda c: c.delta_ic).effect if paying else "none"}

    def run(name, crit, hold):
        cb, hb = crit(base), hold(base)
        rows = [(c.effect, crit(c.fit) - cb, hold(c.fit) / hb - 1.0, c.fit.k - base.k,
                 c.effect != "slip_jump" or friction_band(c.fit) >= need) for c in cands]
        out[name] = _decide(rows, rule)

    for p in (1, 2, 4):
        a = ar_fit(base.residual[:n], p)
        N = n - p
        run(f"whitened AR({p}), base",
            lambda f, a=a, N=N: N * np.log(np.mean(ar_filter(f.residual[:n], a) ** 2)) + f.k * np.log(N),
            lambda f, a=a: float(np.sqrt(np.mean(ar_filter(f.residual[n - len(a):], a) ** 2))))
        run(f"own AR({p})",
            lambda f, p=p, N=N: (N * np.log(np.mean(ar_filter(f.residual[:n], ar_fit(f.residual[:n], p)) ** 2))
                            + f.k * np.log(N)),
            lambda f, p=p: float(np.sqrt(np.mean(
                ar_filter(f.residual[n - p:], ar_fit(f.residual[:n], p)) ** 2))))
    run("load model (Kalman)", lambda f: load_m2ll(f.residual[:n]) + f.k * np.log(n), lambda f: f.holdout_rmse)
    # a swap (no parameter added: slip-jump friction for the paper's) judged on the whole record's residual
    ne_all, sse_b = effective_n(base.residual), float(np.sum(base.residual ** 2))
    rows = [(c.effect, ne_all * np.log(float(np.sum(c.fit.residual ** 2)) / sse_b), -np.inf, 0,
             c.effect != "slip_jump" or friction_band(c.fit) >= need) if c.fit.k == base.k else
            (c.effect, c.delta_ic, c.holdout_change, c.fit.k - base.k, True) for c in cands]
    out["swap on the whole record"] = _decide(rows, rule)
    for blocks, need_w in BLOCKS:
        wins = {id(c): block_wins(base.residual, c.fit.residual, blocks) >= need_w for c in cands}
        for keep_h in (False, True):
            rows = [(c.effect, c.delta_ic if wins[id(c)] else np.inf,
                     c.holdout_change if keep_h else -np.inf, c.fit.k - base.k,
                     c.effect != "slip_jump" or friction_band(c.fit) >= need) for c in cands]
            out[f"blocks {need_w}/{blocks}" + (" + held-out" if keep_h else "")] = _decide(rows, rule)
    return out


def run_case(args):
    effect, seed = args
    _, rec = make_case(effect, seed, True, True)
    res = diagnose(rec, plant="tank", actuator="valve", jobs=1)
    sel = res.selection
    cands = [c for c in sel.candidates if c.round == 1 and c.confirmed]
    case = {"n_fit": sel.base.n_fit, "base": sel.base, "cands": cands, "u": res.recording.op}
    return effect, seed, readings(case)


def main(argv=None):
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--per-effect", type=int, default=6)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args(argv)
    tasks = [(e, a.first + i) for i, e in enumerate(EFFECTS * a.per_effect)]     # naming_other_sim.py's cases
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max(1, a.jobs)) as ex:
        out = []
        for i, r in enumerate(ex.map(run_case, tasks), 1):
            out.append(r)
            print(f"  {i}/{len(tasks)} {r[0]}_{r[1]}", file=sys.stderr, flush=True)
    names = list(out[0][2])
    print(f"## Readings of the first selection round ({len(out)} loops, cases {a.first}-"
          f"{a.first + len(tasks) - 1}; {time.perf_counter() - t0:.0f} s)\n")
    print("| reading | " + " | ".join(EFFECTS) + " | all |")
    print("|---|" + "---|" * (len(EFFECTS) + 1))
    for name in names:
        right = {e: sum(r[2][name] == e for r in out if r[0] == e) for e in EFFECTS}
        print(f"| {name} | " + " | ".join(f"{right[e]} of {a.per_effect}" for e in EFFECTS)
              + f" | **{sum(right.values())} of {len(out)}** |")


if __name__ == "__main__":
    main()
