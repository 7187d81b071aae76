"""Speed and memory of the fleet mode (valve_gym.fleet) on simulated plant loops.

Two measurements::

    python benchmarks/bench_fleet.py scaling [--loops 40] [--n 600] [--repeat 1]
        the same loops, full diagnosis of each (CPU-bound work), with 1 and then 2 Ray workers
        (``--repeat`` interleaved pairs); reports wall time of each run (Ray start excluded), the
        steady-state rate after each worker's first loops, and the speed-up 2 workers / 1 worker of
        the best run of each, in the same invocation
    python benchmarks/bench_fleet.py fleet [--loops 2000] [--n 600] [--jobs 2] [--engine ray|local]
        a whole simulated fleet the way `valve-gym diagnose DIR --out OUT --ray` runs it (``--engine
        local``: as `valve-gym diagnose DIR --out OUT` runs it, without Ray): screening of every
        loop, full diagnosis (base model + friction verdict, effort fast) of the oscillating ones;
        reports wall time, loops/s, full diagnoses, and peak memory of the whole process tree
        (driver + Ray or local worker processes; the sum of their resident sets, an upper bound as they
        share pages)

The simulated loops (valve_gym.fleet.simulate: level loops at a constant set point, 72 % healthy,
15 % sticky, 5 % severe, 8 % with an oscillating disturbance) are written once to
``--data`` (default /tmp/valve_gym_bench_fleet) and reused.  The load average of the machine is
printed before and after: other work on the machine slows both arms of the ratio.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import sys
import threading
import time

import numpy as np

from valve_gym.fleet import FleetSettings, run_fleet
from valve_gym.fleet.simulate import write_fleet


def _tree_rss_mb(root: int) -> float:
    """Sum of VmRSS [MB] of ``root`` and all its descendants (from /proc)."""
    kids: dict[int, list[int]] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        kids.setdefault(ppid, []).append(int(d))
    total, todo = 0.0, [root]
    while todo:
        p = todo.pop()
        todo += kids.get(p, [])
        try:
            with open(f"/proc/{p}/status") as f:
                for line in f:
                    if line.startswith("VmRSS:"):
                        total += int(line.split()[1]) / 1024
        except OSError:
            pass
    return total


class PeakMemory:
    """Samples the process tree's RSS every ``every`` seconds in a thread; ``peak`` in MB."""

    def __init__(self, every: float = 0.5):
        self.every, self.peak, self._stop = every, 0.0, threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while not self._stop.is_set():
            self.peak = max(self.peak, _tree_rss_mb(os.getpid()))
            self._stop.wait(self.every)

    def __enter__(self):
        self._t.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._t.join()


def _data(root: str, loops: int, n: int, seed: int) -> str:
    folder = os.path.join(root, f"fleet_{loops}_{n}_{seed}")
    if not os.path.isdir(folder) or len(os.listdir(folder)) != loops:
        shutil.rmtree(folder, ignore_errors=True)
        t0 = time.perf_counter()
        write_fleet(folder + ".tmp", loops, seed=seed, n=n)
        os.replace(folder + ".tmp", folder)
        print(f"wrote {loops} simulated loops of {n} samples to {folder} in {time.perf_counter() - t0:.1f} s",
              file=sys.stderr)
    return folder


def _run(folder: str, out: str, settings: FleetSettings, jobs: int, quiet: bool, engine: str = "ray") -> dict:
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    if engine == "ray":
        import ray

        ray.init(address="local", num_cpus=jobs, include_dashboard=False, log_to_driver=False,
                 configure_logging=True, logging_level="ERROR")
    t_ray = time.perf_counter() - t0
    stamps: list[float] = []
    with PeakMemory() as mem:
        c1 = resource.getrusage(resource.RUSAGE_SELF)
        t1 = time.perf_counter()
        run = run_fleet(folder, out, settings, jobs=jobs, stream=None if quiet else sys.stderr, top=10,
                        on_result=lambda r: stamps.append(time.perf_counter()), engine=engine)
        t_run = time.perf_counter() - t1
        c2 = resource.getrusage(resource.RUSAGE_SELF)
    if engine == "ray":
        import ray

        ray.shutdown()
    driver_cpu = (c2.ru_utime + c2.ru_stime) - (c1.ru_utime + c1.ru_stime)
    st = np.array(stamps) - t1
    k = min(2 * jobs, len(st) - 1)          # steady state: after each worker's first loops (numba compiled)
    steady = (len(st) - 1 - k) / (st[-1] - st[k]) if len(st) > k + 1 and st[-1] > st[k] else float("nan")
    bad = [r for r in run.results if r.status != "ok"]
    if bad:
        print(f"{len(bad)} loop(s) failed, e.g. {bad[0].loop}: {bad[0].message}", file=sys.stderr)
    full = sum(r.stage == "full" for r in run.results)
    cpu = float(np.nansum([r.cpu_seconds for r in run.results]))
    return {"engine": engine, "jobs": jobs, "loops": run.n_loops, "failed": run.failed, "full_diagnoses": full,
            "ray_start_s": round(t_ray, 2), "run_s": round(t_run, 2), "loops_per_s": round(run.n_loops / t_run, 3),
            "steady_loops_per_s": round(steady, 3), "peak_tree_rss_mb": round(mem.peak, 1),
            "wall_s_per_loop_median": round(float(np.median([r.seconds for r in run.results])), 3),
            "task_cpu_s": round(cpu, 1), "driver_cpu_s": round(driver_cpu, 1),
            "cpu_share_of_workers": round(cpu / (t_run * jobs), 3),
            "loadavg_1min": round(os.getloadavg()[0], 2)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=("scaling", "fleet"))
    ap.add_argument("--loops", type=int, default=None, help="loops (default 40 for scaling, 2000 for fleet)")
    ap.add_argument("--n", type=int, default=600, help="samples per loop (1 s scan)")
    ap.add_argument("--jobs", type=int, default=2, help="workers of the fleet run")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=1, help="scaling: pairs of (1 worker, 2 workers) runs")
    ap.add_argument("--engine", choices=("ray", "local"), default="ray",
                    help="fleet: Ray tasks (default, as the published runs) or the local executor (no Ray)")
    ap.add_argument("--data", default="/tmp/valve_gym_bench_fleet")
    ap.add_argument("--json", help="write the numbers as JSON")
    a = ap.parse_args(argv)
    loops = a.loops or (40 if a.what == "scaling" else 2000)
    folder = _data(a.data, loops, a.n, a.seed)
    out = os.path.join(a.data, f"out_{a.what}")
    print(f"load average before: {os.getloadavg()}", file=sys.stderr)
    rows = []
    if a.what == "scaling":
        s = FleetSettings(op_range=(0.0, 100.0), effort="fast", candidates=(), full=True)
        for _ in range(a.repeat):                       # interleaved, so a change of the machine's load hits both
            for jobs in (1, 2):
                rows.append(_run(folder, out, s, jobs, quiet=True))
                print(json.dumps(rows[-1]), file=sys.stderr)
        good = [r for r in rows if r["failed"] == 0]          # a run hit by a broken install does not count
        best = {j: min((r for r in good if r["jobs"] == j), key=lambda r: r["run_s"]) for j in (1, 2)}
        rows.append({"speedup_best_run": round(best[1]["run_s"] / best[2]["run_s"], 3),
                     "speedup_best_steady": round(best[2]["steady_loops_per_s"] / best[1]["steady_loops_per_s"], 3),
                     "cpu_per_loop_ratio": round(best[2]["task_cpu_s"] / best[1]["task_cpu_s"], 3),
                     "repeats": a.repeat})
    else:
        s = FleetSettings(op_range=(0.0, 100.0), effort="fast", candidates=())
        rows.append(_run(folder, out, s, a.jobs, quiet=False, engine=a.engine))
    print(f"load average after: {os.getloadavg()}", file=sys.stderr)
    for r in rows:
        print(json.dumps(r))
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"what": a.what, "n": a.n, "rows": rows, "loadavg_after": os.getloadavg()}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
