"""Speed of the diagnosis: a full diagnosis of a 3600-sample recording with every candidate.

Generates closed-loop recordings of 3600 samples (dt = 1 s, :mod:`valve_gym.diagnosis.synthetic`),
runs :func:`valve_gym.diagnosis.diagnose` with all candidate effects, the default
holdout and rule, and reports the wall time per recording, per stage and per
candidate fit, for ``--jobs`` worker processes (candidate fits of a round in
parallel).  The machine's load average is printed alongside: the timings are
wall-clock and other processes slow them down.

Usage::

    python benchmarks/bench_diagnosis.py [--samples 3600] [--jobs 2] [--repeat 1]
        [--effects none,overflow] [--effort auto] [--search full|fast] [--reference]
        [--before REV] [--old] [--coarse auto] [--early-stop-ab]

``--early-stop-ab`` also diagnoses every recording twice in this process (one worker, one kernel
thread), with the fitter's early stop (:data:`valve_gym.diagnosis.fit.EARLY_STOP`: a candidate stops
simulating once it cannot beat its rival) on and off, and reports both CPU times and whether the
effects and the final RMSE are the same.

``--before REV`` also diagnoses every recording, right after the timed run, with the
package as it was at git revision ``REV`` (extracted with ``git archive`` into a temporary
folder and run in a subprocess with the same ``--jobs``), and reports the wall- and
CPU-time ratios and what that version named: a before/after comparison under the same
machine load.  Both sides first diagnose a full-length recording with the same workers (not
timed): the numba kernel has a threaded specialisation that only full-size batches use, and a
revision extracted into a new folder has no compiled cache, so without it the first timed
recording of ``REV`` included a compilation of several seconds (earlier releases of this script
warmed up on 300 samples, which inflated the first recording's ratio to about 1.9x).
``--search fast`` times the opt-in fast search (:func:`valve_gym.diagnosis.diagnose`, ``search``;
fewer effects named).

``--reference`` also diagnoses every recording serially (one process, kernel
threads off) right after the timed run, and reports the ratio of the two wall
times: the machine's load affects both alike.  Both give the same result.

``--old`` also diagnoses every recording with the search of earlier versions
(every fit on every sample, ``coarse=1``) in the same run and reports the
wall-time ratio and whether the effects named and the stiction verdict are the
same.  The timed run can search records of 2400 samples and more
coarse-to-fine with ``--coarse auto`` (:func:`valve_gym.diagnosis.diagnose.coarse_factor`,
opt-in, off by default): the evolution of every fit runs on every third sample of a
3600-sample record, a short warm-started evolution and the least-squares refinement on
all samples.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from valve_gym.diagnosis import diagnose
from valve_gym.diagnosis.model import (
    CANDIDATE_EFFECTS,
    DataScales,
    ModelStructure,
    effect_applicability,
    kernel_threads,
    set_kernel_threads,
)
from valve_gym.diagnosis.synthetic import make_case


def _cpu():
    """CPU seconds of this process and its finished children."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def kernel_rate(n=3600):
    """Simulated samples per second of the batched core on this machine, now."""
    case = make_case("none", seed=0, n=n)
    r = case.recording
    sc = DataScales.from_signals(r.op, r.pv, r.dt)
    st = ModelStructure("tank", "valve", (), sc)
    W = np.random.default_rng(0).random((64, len(st.params)))
    st.simulate(W, r.op)
    t0 = time.perf_counter()
    for _ in range(5):
        st.simulate(W, r.op)
    return 5 * 64 * n / (time.perf_counter() - t0)


def _old_path(case, res, wall, a):
    """Time the search of earlier versions (every sample, ``coarse=1``) on the same recording."""
    t1 = time.perf_counter()
    c1 = _cpu()
    old = diagnose(case.recording, plant="tank", actuator="valve", jobs=a.jobs, effort=a.effort, coarse=1,
                   search=a.search)
    w_old = time.perf_counter() - t1
    OLD_CPU.append(_cpu() - c1)
    same_e = old.effects == res.effects
    same_v = old.stiction.get("present") == res.stiction.get("present")
    return (f" {w_old:.1f} | {w_old / wall:.2f}x | {'yes' if same_e else 'NO'}, "
            f"{'yes' if same_v else 'NO'} (RMSE {res.final.rmse_all:.4g} vs old {old.final.rmse_all:.4g}) |")


#: CPU seconds of the old-path runs (``--old``), in order.
OLD_CPU: list = []

#: Run in a subprocess on the package of another revision (``--before``): one diagnosis, JSON out.
_BEFORE_SCRIPT = r"""
import json, os, sys, time
sys.path.insert(0, sys.argv[1])
from valve_gym.diagnosis import diagnose
from valve_gym.diagnosis.synthetic import make_case
eff, seed, n, jobs, effort = sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), sys.argv[6]
# warm-up at full length and with the same workers: compiles (or loads) every kernel specialisation,
# the threaded one included, before the timed run
diagnose(make_case("none", seed=1, n=n).recording, candidates=(), effort="fast", jobs=jobs)
case = make_case(eff, seed=seed, n=n)
c = os.times(); c0 = c.user + c.system + c.children_user + c.children_system
t0 = time.perf_counter()
res = diagnose(case.recording, plant="tank", actuator="valve", jobs=jobs, effort=effort)
wall = time.perf_counter() - t0
c = os.times(); cpu = c.user + c.system + c.children_user + c.children_system - c0
print(json.dumps({"wall": wall, "cpu": cpu, "effects": list(res.effects), "present": res.stiction.get("present"),
                  "rmse": float(res.final.rmse_all), "pv": float(abs(case.recording.pv).sum()),
                  "module": sys.modules["valve_gym"].__file__}))
"""


AB_CPU: list[tuple[float, float]] = []


def _early_stop_ab(case, a) -> str:
    """The recording diagnosed serially with the fitter's early stop on, then off: CPU and equality."""
    from valve_gym.diagnosis import fit as fit_mod

    threads = kernel_threads()
    set_kernel_threads(1)
    out = []
    try:
        for on in (True, False):
            fit_mod.EARLY_STOP = on
            c0 = time.process_time()
            r = diagnose(case.recording, plant="tank", actuator="valve", jobs=1, effort=a.effort, search=a.search)
            out.append((time.process_time() - c0, r))
    finally:
        fit_mod.EARLY_STOP = True
        set_kernel_threads(threads)
    (c_on, r_on), (c_off, r_off) = out
    AB_CPU.append((c_on, c_off))
    same = r_on.effects == r_off.effects and r_on.final.rmse_all == r_off.final.rmse_all
    return f" {c_on:.1f} | {c_off:.1f} | {c_off / c_on:.2f}x | {'yes' if same else 'NO'} |"


def _export(rev: str, dest: str) -> str:
    """Extract the package of git revision ``rev`` into ``dest``; the folder to put on ``sys.path``."""
    root = subprocess.run(["git", "rev-parse", "--show-toplevel"], capture_output=True, text=True,
                          check=True, cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
    arch = subprocess.run(["git", "archive", rev, "valve_gym"], capture_output=True, check=True, cwd=root).stdout
    subprocess.run(["tar", "-x", "-C", dest], input=arch, check=True)
    return dest


def _before_path(tree: str, case, eff: str, seed: int, res, wall: float, cpu: float, a) -> str:
    """Diagnose the same recording with the package of ``--before`` (subprocess); table cells."""
    out = subprocess.run([sys.executable, "-c", _BEFORE_SCRIPT, tree, eff, str(seed), str(a.samples),
                          str(a.jobs), a.effort], capture_output=True, text=True, check=True)
    b = json.loads(out.stdout.strip().splitlines()[-1])
    if not b["module"].startswith(tree):
        raise SystemExit(f"--before: imported {b['module']}, not the package of {a.before}")
    if abs(b["pv"] - float(np.abs(case.recording.pv).sum())) > 1e-6 * b["pv"]:
        raise SystemExit(f"--before: {case.name}: revision {a.before} generates another recording")
    BEFORE.append((b["wall"], b["cpu"], wall, cpu))
    same_e = b["effects"] == list(res.effects)
    same_v = b["present"] == res.stiction.get("present")
    return (f" {b['wall']:.1f} | {b['wall'] / wall:.2f}x | {b['cpu'] / cpu:.2f}x | "
            f"{', '.join(b['effects']) or 'none'}, {'yes' if same_v else 'NO'} "
            f"({'same' if same_e else 'OTHER'}; RMSE {res.final.rmse_all:.4g} vs {b['rmse']:.4g}) |")


#: (wall, CPU) of the ``--before`` runs and of the timed runs, per recording.
BEFORE: list = []


def main(argv=None):
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--samples", type=int, default=3600)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--effects", default="none,overflow",
                    help="effects hidden in the benchmark recordings (one recording each)")
    ap.add_argument("--effort", default="auto", choices=("auto", "fast", "normal", "thorough"))
    ap.add_argument("--reference", action="store_true",
                    help="also time a serial diagnosis (1 process, no kernel threads) of each recording")
    ap.add_argument("--old", action="store_true",
                    help="also time the search of earlier versions (coarse=1) on each recording")
    ap.add_argument("--search", default="full", choices=("fast", "full"),
                    help="search of the timed run (diagnose(search=...))")
    ap.add_argument("--before", metavar="REV",
                    help="also diagnose each recording with the package of git revision REV "
                         "(subprocess, same jobs), right after the timed run")
    ap.add_argument("--early-stop-ab", action="store_true",
                    help="also diagnose every recording in this process (one worker, one kernel thread) with "
                         "the fitter's early stop on and off, and report the CPU ratio")
    ap.add_argument("--coarse", default="1",
                    help="coarse-to-fine decimation of the timed run: 'auto' or a whole number (default 1)")
    a = ap.parse_args(argv)
    # warm-up at full length with the timed run's workers (as in every --before subprocess): the kernel's
    # specialisations, the threaded one included, are compiled or loaded from numba's cache before timing
    diagnose(make_case("none", seed=1, n=a.samples).recording, candidates=(), effort="fast", jobs=a.jobs)
    rate = kernel_rate(a.samples)
    load = os.getloadavg()
    n_cand = sum(effect_applicability(e, "tank", "valve")[0] for e in CANDIDATE_EFFECTS)
    print(f"## Diagnosis speed ({a.samples}-sample recordings, all {n_cand} candidate effects, "
          f"{a.jobs} worker(s), effort {a.effort}, search {a.search})\n")
    print(f"Machine: {os.cpu_count()} cores, load average {load[0]:.1f} / {load[1]:.1f} / "
          f"{load[2]:.1f} (1/5/15 min) at the start; batched core {rate / 1e6:.1f} M simulated "
          f"samples/s (2 Euler steps each) in this process.\n")
    ref_head = " serial reference [s] | speed-up |" if a.reference else ""
    ref_head += " old path (coarse=1) [s] | speed-up | same effects, same verdict |" if a.old else ""
    ref_head += (f" before ({a.before}) [s] | wall ratio | CPU ratio | before: effects named, same verdict |"
                 if a.before else "")
    ref_head += (" CPU early stop on [s] | off [s] | ratio | same effects, RMSE |" if a.early_stop_ab else "")
    print("| recording | effects named | total [s] | base fit | selection (screen + confirm) | "
          "candidate fits | per candidate [s] | friction verdict | whole-record refits | locate |"
          + ref_head)
    print("|---|---|---|---|---|---|---|---|---|---|" + ("---|---|" if a.reference else "")
          + ("---|---|---|" if a.old else "") + ("---|---|---|---|" if a.before else "")
          + ("---|---|---|---|" if a.early_stop_ab else ""))
    tree = _export(a.before, tempfile.mkdtemp(prefix="valve_gym_before_")) if a.before else ""
    totals, cpu = [], []
    for eff in a.effects.split(","):
        for rep in range(a.repeat):
            case = make_case(eff.strip(), seed=100 + rep, n=a.samples)
            t0 = time.perf_counter()
            c0 = _cpu()
            coarse = a.coarse if a.coarse == "auto" else int(a.coarse)
            res = diagnose(case.recording, plant="tank", actuator="valve", jobs=a.jobs,
                           effort=a.effort, coarse=coarse, search=a.search)
            wall = time.perf_counter() - t0
            cpu.append(_cpu() - c0)
            totals.append(wall)
            t = res.timing
            ref = ""
            if a.reference:
                threads = kernel_threads()
                set_kernel_threads(1)
                try:
                    t1 = time.perf_counter()
                    res1 = diagnose(case.recording, plant="tank", actuator="valve", jobs=1,
                                    effort=a.effort, search=a.search)
                    serial = time.perf_counter() - t1
                finally:
                    set_kernel_threads(threads)
                if res1.effects != res.effects:
                    raise SystemExit(f"{case.name}: the serial run named {res1.effects}, "
                                     f"the timed run {res.effects}")
                ref = f" {serial:.1f} | {serial / wall:.2f}x |"
            if a.old:
                ref += _old_path(case, res, wall, a)
            if a.before:
                ref += _before_path(tree, case, eff.strip(), 100 + rep, res, wall, cpu[-1], a)
            if a.early_stop_ab:
                ref += _early_stop_ab(case, a)
            print(f"| {case.name} | {', '.join(res.effects) or 'none'} | {wall:.1f} | "
                  f"{t['base_fit']:.1f} | {t['selection']:.1f} | {t['candidate_fits']} | "
                  f"{t['per_candidate']:.2f} | {t['friction_verdict']:.1f} | "
                  f"{t['full_refit']:.1f} | {t['locate']:.1f} |" + ref)
    print(f"\nMean {np.mean(totals):.1f} s per recording (max {np.max(totals):.1f} s); "
          f"target <= 5 s. Load average at the end {os.getloadavg()[0]:.1f}. CPU time "
          f"(this process and its workers) per recording: "
          f"{', '.join(f'{c:.1f}' for c in cpu)} s, i.e. {np.mean(cpu) / a.jobs:.1f} s of wall "
          f"time on {a.jobs} otherwise idle core(s) if the work splits evenly.\n")
    if BEFORE:
        bw, bc, nw, nc = (np.sum([b[i] for b in BEFORE]) for i in range(4))
        print(f"Before ({a.before}) vs now, same recordings, same run: wall time {bw:.1f} s vs {nw:.1f} s "
              f"({bw / nw:.2f}x), CPU time {bc:.1f} s vs {nc:.1f} s ({bc / nc:.2f}x).\n")
    if AB_CPU:
        on, off = np.sum([c[0] for c in AB_CPU]), np.sum([c[1] for c in AB_CPU])
        print(f"Early stop on vs off (one process, one kernel thread, same recordings): CPU time {on:.1f} s vs "
              f"{off:.1f} s ({off / on:.2f}x).\n")
    if OLD_CPU:
        print(f"Old path (coarse=1) CPU time per recording: {', '.join(f'{c:.1f}' for c in OLD_CPU)} s; "
              f"CPU-time ratio old/new {np.sum(OLD_CPU) / np.sum(cpu):.2f}x (CPU time is much less "
              f"sensitive than wall time to other processes on a shared machine).\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
