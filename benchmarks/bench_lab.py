"""Speed of the teaching lab's re-simulation after a slider move, side by side with the plain simulation calls.

The lab's target: after a parameter change, a one-hour loop at a 1-s scan (3600 PI scans, 50
Euler steps each) is re-simulated in <= 100 ms. Rows, each timed after a warm-up, the cases'
repeats interleaved so that a change of machine load hits all alike:

* ``closed_loop_pi`` (reference): :func:`valve_gym.figures.closed_loop_pi`, the PI loop the
  loop page calls, on the same model, once;
* ``core.simulate`` (reference): the core's open-loop run over the same hour (3600 held inputs,
  one kernel call; no controller);
* ``loop page: z_max moved``: :meth:`valve_gym.lab.models.LoopLab.simulate` after a friction
  slider move (the sticky loop re-run, the benchmark's limit-cycle detector; the frictionless
  ghost is cached because a friction slider does not change it);
* ``loop page: Kc moved``: the same after a PI slider move (the ghost re-run too);
* ``loop page + plots: z_max moved``: the server's whole update, the simulation and the two
  Bokeh figures (:meth:`valve_gym.lab.app.LoopPage.plots`);
* ``valve page: z_max moved``: the valve page's fig-7 experiment (130 s of input at 50 ms,
  1 ms Euler steps) and its healthy ghost (cached);
* ``compensator page: S_est moved``: the knocker on the page's 4 benchmark loops (one hour
  each; the PI references are cached).

Each row reports the median and the best of the repeats, wall clock and CPU time of the
calling thread (the CPU time leaves out other processes' load on a shared machine), and the
ratio of the median wall time to ``closed_loop_pi``'s.

Usage::

    python benchmarks/bench_lab.py [--repeats R] [--json OUT]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))    # this checkout's valve_gym

from valve_gym import core, figures  # noqa: E402
from valve_gym._io import write_atomic  # noqa: E402
from valve_gym.lab.app import LoopPage  # noqa: E402
from valve_gym.lab.models import CompensatorLab, LoopLab, ValveLab  # noqa: E402


def cases() -> dict[str, Callable[[int], object]]:
    """Name -> ``f(i)`` doing one timed call; ``i`` alternates the moved setting so that each call is a change."""
    loop = LoopLab()
    loop_kc = LoopLab()
    page = LoopPage()
    valve = ValveLab(preset="fig7")
    comp = CompensatorLab()
    params = loop.params()
    T = int(round(loop.seconds))
    sp = np.where(np.arange(T) >= loop.sp_at, 1.2, 1.0)
    st = core.initial_state(params, 1, level=1.0)
    u = np.full((T, 1), 0.55)
    zs = (0.3, 0.25)

    def ref_pi(i):
        return figures.closed_loop_pi(params, sp, loop.Kc, loop.Ti, 1.0, float(T), state=st)

    def ref_core(i):
        return core.simulate(params, u, state=st, n_sub=int(round(1.0 / params.dt)))

    def loop_z(i):
        loop.z_max = zs[i % 2]
        return loop.simulate()

    def loop_k(i):
        loop_kc.Kc = 1.0 + 0.01 * (i + 2)        # a new gain every call: the ghost is re-run too
        return loop_kc.simulate()

    def page_z(i):
        page.z_max = zs[i % 2]
        return page.plots()

    def valve_z(i):
        valve.z_max = (0.2, 0.15)[i % 2]
        return valve.simulate()

    def comp_s(i):
        comp.S_est = (0.04, 0.035)[i % 2]
        return comp.simulate()

    return {"closed_loop_pi (reference)": ref_pi, "core.simulate (reference, open loop)": ref_core,
            "loop page: z_max moved": loop_z, "loop page: Kc moved": loop_k,
            "loop page + plots: z_max moved": page_z, "valve page: z_max moved": valve_z,
            "compensator page: S_est moved": comp_s}


def main(argv=None) -> int:
    """Time every case; print the table (and write JSON with ``--json``)."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7, help="timed calls per case (default 7)")
    ap.add_argument("--json", metavar="OUT", help="also write the results as JSON")
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error("--repeats must be >= 1")
    fns = cases()
    print("warming up (numba compiles the kernel on a cold cache) ...", flush=True)
    for f in fns.values():
        f(-1)
    wall: dict[str, list[float]] = {k: [] for k in fns}
    cpu: dict[str, list[float]] = {k: [] for k in fns}
    heavy = "compensator page: S_est moved"
    for r in range(args.repeats):
        for name, f in fns.items():
            if name == heavy and r >= max(1, args.repeats // 2):
                continue                      # seconds per call: half the repeats are enough
            w0, c0 = time.perf_counter(), time.thread_time()
            f(r)
            cpu[name].append(time.thread_time() - c0)
            wall[name].append(time.perf_counter() - w0)
        print(f"repeat {r + 1}/{args.repeats} done", flush=True)
    ref = float(np.median(wall["closed_loop_pi (reference)"]))
    rows = []
    print(f"\n{'case':40s} {'wall median':>12s} {'wall best':>10s} {'CPU median':>11s} {'CPU best':>9s} "
          f"{'/ closed_loop_pi':>17s}")
    for name in fns:
        w, c = np.array(wall[name]) * 1e3, np.array(cpu[name]) * 1e3
        row = dict(case=name, wall_median_ms=float(np.median(w)), wall_best_ms=float(w.min()),
                   cpu_median_ms=float(np.median(c)), cpu_best_ms=float(c.min()),
                   ratio_to_closed_loop_pi=float(np.median(w)) / (ref * 1e3), repeats=int(w.size))
        rows.append(row)
        print(f"{name:40s} {row['wall_median_ms']:10.1f} ms {row['wall_best_ms']:7.1f} ms "
              f"{row['cpu_median_ms']:8.1f} ms {row['cpu_best_ms']:6.1f} ms {row['ratio_to_closed_loop_pi']:15.2f}x")
    target = next(r for r in rows if r["case"] == "loop page: z_max moved")
    print(f"\nloop page re-simulation after a slider move (1 h at 1-s scan): median {target['wall_median_ms']:.1f} ms "
          f"wall, {target['cpu_median_ms']:.1f} ms CPU; target <= 100 ms")
    if args.json:
        info = dict(python=platform.python_version(), machine=platform.machine(), processor=platform.processor(),
                    cpus=os.cpu_count(), rows=rows)
        write_atomic(args.json, lambda fh: fh.write(json.dumps(info, indent=2).encode()))
        print(args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
