"""A second held-out check of the stiction compensators, on plants and valves coded here alone.

Nothing in this script was used while the compensators were designed or trained, and nothing here is
shared with the physics core (:mod:`valve_gym.core`) or with the benchmark's generalisation plants
(:mod:`valve_gym.agents.bench.unseen_plants`). The scores are the benchmark's
(:func:`valve_gym.agents.bench.scores.score_runs`, :func:`~valve_gym.agents.bench.scores.compensation_ratio`).

Plants (one scan per loop: 1 or 3 s)
    ``cascade``: two non-interacting Torricelli tanks in series, the lower tank's level measured;
    ``thermal``: a second-order-plus-dead-time loop (two lags 5-60 s, 2-10 s delay), equal-percentage valve;
    ``vessel``: a gas vessel, pressure ``P`` with inflow ``q_max x sqrt(P_s - P)`` and outflow ``k P``.
Valves
    He, Wang, Pottmann & Qin (2007) two-layer model (static ``f_s``, dynamic ``f_d`` friction, a residual
    force that accumulates the input's moves), and Stenman's one-parameter model (the stem jumps to the
    input once they differ by more than ``d``), each behind a first-order positioner (0.5-3 s).
Loads
    a load step of 1-4 % of full flow at a random time in the first half plus a slow random walk.

Each controller comes from ``load_controller(name)`` with the loop's PI tuning (SIMC on a first-order
model found by a step test of the frictionless loop, ``tau_c = max(T/6, 3 theta)``) and its scan only.

Usage::

    python benchmarks/learned_unseen_check.py [--n 36] [--seed 913] [--names pi knocker learned learned_network]
        [--policy LABEL=FILE ...]

``--diagnosed`` adds the rows of a plant's workflow: each loop's record under the PI is diagnosed
(:func:`valve_gym.diagnosis.diagnose`, the process kind an engineer knows: ``cascade``, and ``first_order``
for the thermal loop and the vessel), and the knocker and ``learned`` get the diagnosed ``S`` where
the verdict is stiction (``S0``; frozen or adapting), nothing elsewhere.

The harness (:func:`tune`, :func:`run`, :func:`check_family`, :func:`print_table`) takes the family's simulator
class (here :class:`Loops`): ``benchmarks/learned_third_check.py`` runs the third held-out family on it.

``--policy LABEL=FILE`` adds a row of one's own policy export (``valve_gym.agents.bench.policies.export_policy``,
``NAME.json`` + ``NAME.safetensors``), given each loop's tuning and scan as every other block
(:meth:`~valve_gym.agents.bench.policies.PolicyBlock.for_loop`).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[1]
if str(_ROOT) not in sys.path:                   # this checkout's package, whatever is installed
    sys.path.insert(0, str(_ROOT))

from valve_gym.agents import load_controller  # noqa: E402
from valve_gym.agents.bench.config import BenchConfig  # noqa: E402
from valve_gym.agents.bench.runner import ControllerBank, Runs  # noqa: E402
from valve_gym.agents.bench.scores import compensation_ratio, score_runs  # noqa: E402

KINDS = ("cascade", "thermal", "vessel")
#: Rows of policy exports (``--policy LABEL=FILE``): label -> block.
POLICIES: dict = {}
VALVE_KINDS = ("he2007", "stenman")
#: ``--diagnosed`` rows: label -> (block, whether its estimate adapts); the process kind given to the diagnosis.
DIAGNOSED = {"knocker (S diagnosed)": ("knocker", None), "learned (S diagnosed, adapts)":
             ("learned", True), "learned (S diagnosed, frozen)": ("learned", False)}
DIAG_KIND = {"cascade": "cascade", "thermal": "first_order", "vessel": "first_order"}
#: ``--known`` rows (a diagnostic, not a block a plant could run): label -> (block, whether its estimate adapts),
#: given each loop's true ``S`` as the benchmark's "(S known)" rows are.
KNOWN = {"knocker (S known)": ("knocker", None), "learned (S known, frozen)": ("learned", False)}


def log_uniform(r: np.random.Generator, lo: float, hi: float) -> float:
    """A number log-uniform in ``[lo, hi]`` from ``r`` (one draw)."""
    return math.exp(r.uniform(math.log(lo), math.log(hi)))


def factorial_loop(r: np.random.Generator, i: int, kinds, valves, loads, healthy_s: float,
                   slip_free: tuple[str, ...] = ()) -> tuple[str, str, str, float, float]:
    """Loop ``i`` of the later families' design: ``(kind, valve, load, S, J)``.

    4 plants x 3 valves x 4 loads, a full factorial over 48 loops (plant ``i % 4``, valve ``(i // 4 + i // 12)
    % 3``, load ``(i // 12) % 4``); every third loop healthy (``S`` uniform below 0.95 ``healthy_s``), the
    others ``S`` log-uniform in 0.5-10 % of stroke; ``J`` uniform in ``[0, S]`` (0, and no draw, for a valve
    in ``slip_free``). The draws come from ``r`` in this order, first for the loop.
    """
    kind, valve, load = kinds[i % 4], valves[(i // 4 + i // 12) % 3], loads[(i // 12) % 4]
    S = r.uniform(0.0005, healthy_s * 0.95) if i % 3 == 0 else log_uniform(r, 0.005, 0.10)
    J = 0.0 if valve in slip_free else r.uniform(0.0, 1.0) * S
    return kind, valve, load, S, J


def ar1(w: np.ndarray, tau: float, scan: float, stationary: bool = True) -> np.ndarray:
    """White noise ``w`` (one sample per scan) through a first-order filter of time constant ``tau`` [s], unit
    variance: stationary from the first sample, or (``stationary`` False) starting from 0."""
    from scipy.signal import lfilter

    a = math.exp(-scan / tau)
    w = w.copy()
    if stationary:
        w[1:] *= math.sqrt(1.0 - a ** 2)
    else:
        w *= math.sqrt(1.0 - a ** 2)
    return lfilter([1.0], [1.0, -a], w)


def draw(n: int, seed: int) -> list[dict]:
    """``n`` loops: every third healthy (S <= 0.4 %), the others S 1-9 % of stroke."""
    out = []
    for i in range(n):
        r = np.random.default_rng([seed, i])
        S = r.uniform(0.0, 0.004) if i % 3 == 0 else r.uniform(0.01, 0.09)
        out.append(dict(kind=KINDS[i % 3], valve=VALVE_KINDS[(i // 3) % 2], S=S, J=r.uniform(0.0, 1.0) * S,
                        tau_p=r.uniform(0.5, 3.0), scan=(1.0, 3.0)[int(r.integers(2))], x0=r.uniform(0.35, 0.65),
                        a1=r.uniform(0.2, 0.6), a2=r.uniform(0.2, 0.6), T1=r.uniform(5.0, 60.0),
                        T2=r.uniform(5.0, 60.0), delay=r.uniform(2.0, 10.0), noise=r.uniform(0.0005, 0.004),
                        step=r.uniform(0.01, 0.04) * r.choice([-1.0, 1.0]), t_step=r.uniform(0.1, 0.5),
                        walk=r.uniform(0.0, 2e-4), seed=int(r.integers(1 << 30))))
    return out


class Loops:
    """Batched simulation of loops of one scan time (Euler, 0.1-s steps)."""

    def __init__(self, rows: list[dict], scan: float, frictionless: bool):
        self.rows, self.scan, self.n = rows, scan, len(rows)
        self.m = int(round(scan / 0.1))
        self.h = scan / self.m
        c = {k: np.array([r[k] for r in rows], float) for k in ("S", "J", "tau_p", "x0", "a1", "a2", "T1", "T2",
                                                                  "delay")}
        self.c = c
        self.kind = np.array([r["kind"] for r in rows])
        self.he = np.array([r["valve"] == "he2007" for r in rows]) & (not frictionless)
        self.st = np.array([r["valve"] == "stenman" for r in rows]) & (not frictionless)
        self.fs, self.fd = (c["S"] + c["J"]) / 2.0, (c["S"] - c["J"]) / 2.0
        self.D = np.maximum(1, np.rint(c["delay"] / self.h).astype(int))

    def flow(self, x):
        """Valve flow fraction: linear, equal-percentage (R = 30) for the thermal loop."""
        return np.where(self.kind == "thermal", 30.0 ** (x - 1.0), x)

    def reset(self):
        """Rest at the operating point: ``(pv, stem, op)``."""
        f0 = self.flow(self.c["x0"])
        self.k1 = f0.copy()                                  # cascade: both levels 1 at f0 (k sqrt(1) = f0)
        self.L1, self.L2 = np.ones(self.n), np.ones(self.n)
        self.y1, self.y2 = f0.copy(), f0.copy()               # thermal: two lags, unit gain on the flow
        self.P = np.full(self.n, 0.5)                        # vessel: supply 1, P = 0.5 at x0
        self.k_v = f0 * math.sqrt(0.5) / 0.5
        x0 = self.c["x0"]
        self.p, self.x, self.u_prev = x0.copy(), x0.copy(), x0.copy()
        self.ur = np.zeros(self.n)
        self.buf = np.repeat(f0[None, :], int(self.D.max()) + 1, axis=0)
        self.j = 0
        return self.pv(), self.x.copy(), x0.copy()

    def pv(self):
        """Measured variable: lower level (cascade), outlet temperature (thermal), pressure (vessel)."""
        return np.where(self.kind == "cascade", self.L2, np.where(self.kind == "thermal", self.y2, self.P))

    def _valve(self):
        du = self.p - self.u_prev
        self.u_prev = self.p.copy()
        ur = self.ur + du                                   # He et al. 2007: residual force
        slip = np.abs(ur) > self.fs
        x_he = np.where(slip, self.x + ur - np.sign(ur) * self.fd, self.x)
        ur = np.where(slip, np.sign(ur) * self.fd, ur)
        x_st = np.where(np.abs(self.p - self.x) > self.c["S"], self.p, self.x)   # Stenman
        self.ur = np.where(self.he, ur, self.ur)
        self.x = np.clip(np.where(self.he, x_he, np.where(self.st, x_st, self.p)), 0.0, 1.0)

    def step(self, op, load):
        """One scan with input ``op`` and load ``load`` (fraction of full flow) held."""
        c, h = self.c, self.h
        a_p = np.exp(-h / c["tau_p"])
        op = np.clip(op, 0.0, 1.0)
        for _ in range(self.m):
            self.p = op + (self.p - op) * a_p
            self._valve()
            f = self.flow(self.x) + load
            self.buf[self.j % self.buf.shape[0]] = f
            fdel = self.buf[(self.j - self.D) % self.buf.shape[0], np.arange(self.n)]
            self.j += 1
            q1 = self.k1 * np.sqrt(np.maximum(self.L1, 0.0))
            q2 = self.k1 * np.sqrt(np.maximum(self.L2, 0.0))
            self.L1 = np.maximum(self.L1 + h * (f - q1) / (c["a1"] * 100.0), 0.0)
            self.L2 = np.maximum(self.L2 + h * (q1 - q2) / (c["a2"] * 100.0), 0.0)
            self.y1, self.y2 = self.y1 + h * (fdel - self.y1) / c["T1"], self.y2 + h * (self.y1 - self.y2) / c["T2"]
            qin = f * np.sqrt(np.maximum(1.0 - self.P, 0.0))     # k_v P = f0 sqrt(0.5) at P = 0.5
            self.P = np.clip(self.P + h * (qin - self.k_v * self.P) / c["T1"], 0.0, 1.0)
        return self.pv(), self.x.copy()

    @staticmethod
    def disturbances(rows: list[dict], scan: float, T: int, duration: float) -> tuple[np.ndarray, np.ndarray]:
        """``(noise (T, n), load (T, n))`` of ``T`` scans: white noise, a load step plus a random walk."""
        rng = [np.random.default_rng(r["seed"]) for r in rows]
        noise = np.stack([g.standard_normal(T) * r["noise"] for g, r in zip(rng, rows)], axis=1)
        walk = np.cumsum(np.stack([g.standard_normal(T) * r["walk"] for g, r in zip(rng, rows)], axis=1), axis=0)
        step = np.array([r["step"] for r in rows])[None, :] * (np.arange(T)[:, None] * scan
                                                               >= np.array([r["t_step"] for r in rows]) * duration)
        return noise, step + walk

    def measure(self, pv: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """What the controller reads: ``pv + noise``."""
        return pv + noise


def tune(sim_cls, rows: list[dict], scan: float, test_s: float = 1200.0) -> tuple[np.ndarray, np.ndarray]:
    """SIMC PI from an open-loop step of +0.05 on the frictionless loop (first-order fit, 63 % method).

    ``sim_cls(rows, scan, frictionless)``: the family's simulator (``reset``, ``step(op, load)``); ``test_s``:
    length of the step test [s]. Returns ``(Kc, Ti)``, each ``(n,)``.
    """
    sim = sim_cls(rows, scan, frictionless=True)
    y0, _, x0 = sim.reset()
    T = int(round(test_s / scan))
    ys = np.empty((T, sim.n))
    for k in range(T):
        ys[k], _ = sim.step(x0 + 0.05, np.zeros(sim.n))
    dy = ys - y0
    K = dy[-1] / 0.05
    frac = dy / np.where(dy[-1] == 0, 1e-12, dy[-1])
    t = (np.arange(T) + 1) * scan
    t05 = np.array([t[np.argmax(frac[:, i] >= 0.05)] for i in range(sim.n)])
    t63 = np.array([t[np.argmax(frac[:, i] >= 0.632)] for i in range(sim.n)])
    theta = np.maximum(t05 - scan, 0.0) + scan / 2.0 + np.array([r["tau_p"] for r in rows])
    Tc = np.maximum(t63 - t05, scan)
    tc = np.maximum(Tc / 6.0, 3.0 * theta)
    return Tc / (np.abs(K) * (tc + theta)), np.minimum(Tc, 4.0 * (tc + theta))


def run(sim_cls, name: str, rows: list[dict], scan: float, Kc, Ti, frictionless: bool, duration: float) -> Runs:
    """One controller on the loops of one scan time, on the family's simulator ``sim_cls`` (see :func:`tune`).

    ``sim_cls.disturbances(rows, scan, T, duration)`` gives the noise and load, ``sim.measure(pv, noise)`` what
    the controller reads.
    """
    sim = sim_cls(rows, scan, frictionless)
    y, x, u0 = sim.reset()
    T = int(round(duration / scan))
    n = sim.n
    noise, load = sim_cls.disturbances(rows, scan, T, duration)
    try:
        if name in DIAGNOSED or name in KNOWN:
            block, adapts = DIAGNOSED[name] if name in DIAGNOSED else KNOWN[name]
            S = np.maximum([r["S_diag" if name in DIAGNOSED else "S"] for r in rows], 0.001)
            kw = {"S": S} if adapts is None else {"S0": np.clip(S, 0.001, 0.06), **({} if adapts else {"eta": 0.01})}
            ctrl = load_controller(block, Kc=Kc, Ti=Ti, scan_s=scan, **kw)
        elif name in POLICIES:
            blk = POLICIES[name]          # a policy export: one block per loop with the loop's tuning and scan
            ctrl = ControllerBank([blk.for_loop(float(a), float(b), scan) for a, b in zip(Kc, Ti)],
                                  [np.array([i]) for i in range(n)], n) if hasattr(blk, "for_loop") else blk
        else:
            ctrl = load_controller(name, Kc=Kc, Ti=Ti, scan_s=scan)
    except (ValueError, TypeError):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            blocks = [load_controller(name, Kc=float(a), Ti=float(b), scan_s=scan) for a, b in zip(Kc, Ti)]
            ctrl = ControllerBank(blocks, [np.array([i]) for i in range(n)], n)
    sp = y.copy()
    ctrl.reset(sp, sim.measure(y, noise[0]), u0)
    lv, pv, st, op = np.empty((T, n)), np.empty((T, n)), np.empty((T, n)), np.empty((T, n))
    for k in range(T):
        lv[k], st[k] = y, x
        pv[k] = sim.measure(y, noise[k])
        op[k] = np.asarray(ctrl.step(sp, pv[k]), float)
        y, x = sim.step(op[k], load[k])
    return Runs(name, "check", scan, np.broadcast_to(sp, (T, n)), pv, lv, op, st)


def diagnosed_band(args) -> tuple[bool, float]:
    """``(stiction called, diagnosed S)`` of one PI record ``(t, op, pv, sp, kind)``; ``S`` 0 when not called."""
    t, op, pv, sp, kind = args
    from valve_gym.diagnosis import diagnose
    from valve_gym.diagnosis.recording import Recording

    v = diagnose(Recording(t=t, op=op, pv=pv, sp=sp, name="loop"), plant=kind, candidates=(), effort="fast").stiction
    ok = v["present"] and v["S"] is not None and math.isfinite(v["S"])
    return bool(v["present"]), float(v["S"]) if ok else 0.0


def diagnose_loops(sim_cls, rows: list[dict], scans: np.ndarray, duration: float, diag_kind: dict,
                   jobs: int = 2) -> None:
    """Record every loop under its PI, diagnose the record, store the diagnosed ``S`` as ``row['S_diag']``.

    ``diag_kind``: the process kind given to the diagnosis for each plant kind of the family.
    """
    from multiprocessing import get_context

    tasks, where = [], []
    for scan in np.unique(scans):
        idx = np.flatnonzero(scans == scan)
        sub = [rows[i] for i in idx]
        Kc, Ti = tune(sim_cls, sub, float(scan))
        r = run(sim_cls, "pi", sub, float(scan), Kc, Ti, False, duration)
        t = np.arange(r.pv.shape[0]) * float(scan)
        for j, i in enumerate(idx):
            tasks.append((t, np.clip(r.op[:, j], 0.0, 1.0), r.pv[:, j], r.sp[:, j], diag_kind[rows[i]["kind"]]))
            where.append(int(i))
    with get_context("fork").Pool(jobs) as pool:
        found = pool.map(diagnosed_band, tasks)
    for i, (called, S) in zip(where, found):
        rows[i]["S_diag"], rows[i]["called"] = S, called
    sticky = np.array([r["S"] > 0.005 for r in rows])
    called = np.array([r["called"] for r in rows])
    ok = called & sticky & (np.array([r["S_diag"] for r in rows]) > 0)
    err = [abs(rows[i]["S_diag"] / rows[i]["S"] - 1.0) for i in np.flatnonzero(ok)]
    print(f"diagnosis of the PI's records: stiction called on {int((called & sticky).sum())} of {int(sticky.sum())} "
          f"sticky loops and {int((called & ~sticky).sum())} of {int((~sticky).sum())} healthy ones; median "
          f"|S_est / S - 1| = {np.median(err) if err else float('nan'):.2f} over {int(ok.sum())}", flush=True)


def check_family(sim_cls, rows: list[dict], names: list[str], duration: float, cfg: BenchConfig | None = None,
                 test_s: float = 1200.0) -> dict[str, dict[str, np.ndarray]]:
    """Every controller of ``names`` and the frictionless PI on every loop of ``rows`` (one group per scan).

    Parameters
    ----------
    sim_cls : the family's simulator class (see :func:`tune` and :func:`run`)
    rows : list of dict, one per loop (``scan`` [s], ``tau_p`` [s] and what ``sim_cls`` reads)
    names : controller names (``load_controller``), :data:`POLICIES` labels or :data:`DIAGNOSED` labels
    duration : float, s, record length
    cfg : BenchConfig, optional, the scores' settings (default ``BenchConfig()``)
    test_s : float, s, length of the tuning step test

    Returns
    -------
    dict
        Row label (``"PI frictionless"`` first, then ``names``) -> per-loop scores, each ``(n,)``: ``lc``
        (limit cycle present), ``amp`` (its amplitude, pv units), ``iae`` (per hour), ``travel`` (strokes per
        hour), ``offset`` (abs. mean error).
    """
    cfg = BenchConfig() if cfg is None else cfg
    n = len(rows)
    scans = np.array([r["scan"] for r in rows])
    groups = []                                     # (scan, loop indices, their rows, Kc, Ti): tuned once
    for scan in np.unique(scans):
        idx = np.flatnonzero(scans == scan)
        sub = [rows[i] for i in idx]
        groups.append((float(scan), idx, sub, *tune(sim_cls, sub, float(scan), test_s)))
    res = {}
    for label, name, fr in [("PI frictionless", "pi", True)] + [(nm, nm, False) for nm in names]:
        per = {f: np.empty(n) for f in ("lc", "amp", "iae", "travel", "offset")}
        for scan, idx, sub, Kc, Ti in groups:
            sc = score_runs(run(sim_cls, name, sub, scan, Kc, Ti, fr, duration), cfg)
            per["lc"][idx], per["amp"][idx], per["iae"][idx] = sc.lc_present, sc.lc_amplitude, sc.iae_per_h
            per["travel"][idx], per["offset"][idx] = sc.travel_per_h, np.abs(sc.offset)
        res[label] = per
    return res


def print_table(res: dict[str, dict[str, np.ndarray]], sticky: np.ndarray) -> None:
    """The check's table (markdown): one row per controller of ``res`` (:func:`check_family`), ``sticky`` (n,) bool."""
    pi, fr0 = res["pi"], res["PI frictionless"]
    print("| controller | LC share | mean LC amp. [pv x1000] | median R | travel / frictionless PI | "
          "median abs. offset [pv x1000] | healthy IAE / PI |")
    print("|---|---|---|---|---|---|---|")
    for label, p in res.items():
        R = compensation_ratio(pi["iae"], p["iae"], fr0["iae"])
        print(f"| {label} | {p['lc'][sticky].mean():.2f} | {1000 * p['amp'][sticky].mean():.2f} | "
              f"{np.median(R[sticky]):.2f} | {np.median(p['travel'][sticky] / fr0['travel'][sticky]):.2f} | "
              f"{1000 * np.median(p['offset'][sticky]):.2f} | "
              f"{np.median(p['iae'][~sticky] / pi['iae'][~sticky]):.2f} |")


def add_policies(ap: argparse.ArgumentParser, items: list[str], names: list[str]) -> None:
    """Register each ``--policy LABEL=FILE`` of ``items`` in :data:`POLICIES` and append its label to ``names``."""
    from valve_gym.agents.bench.policies import as_block

    for item in items:
        label, sep, path = item.partition("=")
        if not sep or not label or not path:
            ap.error(f"--policy takes LABEL=FILE (e.g. ppo_family=valve_gym/agents/policies/rl_family/ppo_seed0.json), "
                     f"got {item!r}")
        POLICIES[label] = as_block(path, name=label)
        names.append(label)


def family_args(doc: str | None, n: int, seed: int, argv=None) -> argparse.Namespace:
    """The command line of a held-out family's script: ``--n``, ``--seed``, ``--duration``, ``--names``,
    ``--policy`` (registered in :data:`POLICIES`), ``--diagnosed`` and ``--known``; ``pi``, the reference of R,
    is always among the names."""
    ap = argparse.ArgumentParser(description=(doc or "").splitlines()[0])
    ap.add_argument("--n", type=int, default=n, help="loops (every third healthy)")
    ap.add_argument("--seed", type=int, default=seed)
    ap.add_argument("--duration", type=float, default=3600.0, help="record length [s]")
    ap.add_argument("--names", nargs="+", default=["pi", "knocker", "learned", "learned_network"])
    ap.add_argument("--policy", action="append", default=[], metavar="LABEL=FILE",
                    help="a policy export as one more row (repeatable)")
    ap.add_argument("--diagnosed", action="store_true",
                    help="add the rows that get the S diagnosed in each loop's PI record (see above)")
    ap.add_argument("--known", action="store_true",
                    help="add the knocker and learned (frozen) given each loop's true S (a diagnostic)")
    a = ap.parse_args(argv)
    if a.n < 1 or a.duration <= 0:
        ap.error(f"--n must be >= 1 and --duration > 0, got --n {a.n} --duration {a.duration}")
    if "pi" not in a.names:
        a.names.insert(0, "pi")
    add_policies(ap, a.policy, a.names)
    return a


def print_breakdown(res: dict, rows: list[dict], sticky: np.ndarray, groups: list[tuple[str, str]]) -> None:
    """LC share / median R on the sticky loops of each row of ``res``, by the loops' ``groups`` (markdown).

    ``groups``: ``(field, value)`` pairs; a loop is in a group where ``row[field] == value``.
    """
    pi, fr0 = res["pi"], res["PI frictionless"]
    masks = [np.array([r[f] == v for r in rows]) & sticky for f, v in groups]
    print("\nLC share / median R on the sticky loops, by plant, valve and load (loops in brackets):\n")
    print("| controller | " + " | ".join(f"{v} ({int(mk.sum())})" for (_, v), mk in zip(groups, masks)) + " |")
    print("|---|" + "---|" * len(groups))
    for label, p in res.items():
        R = compensation_ratio(pi["iae"], p["iae"], fr0["iae"])
        cells = [f"{p['lc'][mk].mean():.2f} / {np.median(R[mk]):.2f}" if mk.any() else "-" for mk in masks]
        print(f"| {label} | " + " | ".join(cells) + " |")


def family_main(doc: str | None, sim_cls, draw_fn, n: int, seed: int, argv, *, healthy_s: float, test_s: float,
                diag_kind: dict, groups: list[tuple[str, str]]) -> int:
    """The command line of a held-out family's script (the third and later): draw, run, print.

    Parameters
    ----------
    doc : the script's docstring (its first line describes the command)
    sim_cls : the family's simulator class; ``draw_fn(n, seed)`` its loops
    n, seed : the family's default size and seed
    healthy_s : loops with ``S`` below it are healthy
    test_s : length of the tuning step test [s]
    diag_kind : plant kind -> the process kind given to the diagnosis (``--diagnosed``)
    groups : the breakdown's ``(field, value)`` groups (:func:`print_breakdown`)
    """
    a = family_args(doc, n, seed, argv)
    t0 = time.perf_counter()
    rows = draw_fn(a.n, a.seed)
    sticky = np.array([r["S"] >= healthy_s for r in rows])
    if a.diagnosed:
        diagnose_loops(sim_cls, rows, np.array([r["scan"] for r in rows]), a.duration, diag_kind)
        a.names += list(DIAGNOSED)
    if a.known:
        a.names += list(KNOWN)
    res = check_family(sim_cls, rows, a.names, a.duration, test_s=test_s)
    print(f"{a.n} loops ({int(sticky.sum())} sticky, S 0.5-10 %), seed {a.seed}, {a.duration:g} s, "
          f"{time.perf_counter() - t0:.0f} s")
    print_table(res, sticky)
    print_breakdown(res, rows, sticky, groups)
    return 0


def main(argv=None) -> int:
    a = family_args(__doc__, 36, 913, argv)
    t0 = time.perf_counter()
    rows = draw(a.n, a.seed)
    cfg = BenchConfig()
    scans = np.array([r["scan"] for r in rows])
    sticky = np.array([r["S"] > 0.005 for r in rows])
    if a.diagnosed:
        diagnose_loops(Loops, rows, scans, a.duration, DIAG_KIND)
        a.names += list(DIAGNOSED)
    if a.known:
        a.names += list(KNOWN)
    res = check_family(Loops, rows, a.names, a.duration, cfg)
    print(f"{a.n} loops ({int(sticky.sum())} sticky, S 1-9 %), seed {a.seed}, {a.duration:g} s, "
          f"{time.perf_counter() - t0:.0f} s")
    print_table(res, sticky)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
