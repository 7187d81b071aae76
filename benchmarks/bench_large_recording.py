"""A 1,000,000-row recording through ``valve-gym diagnose``: wall time and peak memory.

A day of a 10 Hz historian tag is about a million rows.  This script simulates
a closed level loop with the project's core (:func:`valve_gym.diagnosis.synthetic.make_case`:
a tank fed through a sticky valve, PI control, set-point steps, measurement
noise) at ``--dt`` seconds for ``--rows`` samples and writes it as CSV
(``t_s, OP [%], PV [m], SP [m]``).  In the same run it writes the same loop
(same seed: same plant, valve and tuning) sampled at 1 s for ``--ref-rows``
samples, the size of the diagnosis benchmark's recordings, as the reference.

Each file is then run through the real command line in a subprocess,

    valve-gym diagnose FILE --op-range 0,100 --json OUT.json --quiet [--jobs 2]

and measured: wall time; the peak resident memory of the largest process
(``os.wait4``'s ``ru_maxrss``, the kernel's own account, which covers the
worker processes the command waits for); and the peak of the summed resident
memory of the whole process tree (``/proc``, sampled every 0.1 s: workers run
at the same time, so their memory adds up).  Two "load only" rows run just
:func:`valve_gym.diagnosis.recording.load_recording` on the big file, as CSV
and as Parquet, in a subprocess, to show what reading and conditioning cost.

Usage::

    python benchmarks/bench_large_recording.py [--rows 1000000] [--dt 0.1]
        [--ref-rows 3600] [--effect slip_jump] [--seed 7] [--jobs 2]
        [--workdir DIR] [--json OUT.json]

The limits of the issue (5 minutes, 2 GB on 2 cores) are printed beside the
numbers; the script exits 1 if the big file's diagnosis fails or exceeds them.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from valve_gym.diagnosis.synthetic import make_case

LIMIT_S = 300.0
LIMIT_MB = 2048.0


@dataclass
class Run:
    """One measured subprocess."""

    name: str
    rows: int
    rc: int
    wall_s: float
    maxrss_mb: float
    tree_peak_mb: float
    tail: str


def write_loop(path: Path, rows: int, dt: float, effect: str, seed: int, parquet: Path | None = None) -> float:
    """Simulate the loop and write it as CSV (and Parquet); returns the seconds it took."""
    t0 = time.perf_counter()
    rec = make_case(effect, seed=seed, n=rows, dt=dt).recording
    data = np.column_stack([rec.t, 100.0 * rec.op, rec.pv, rec.sp])
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as f:
        np.savetxt(f, data, fmt=["%.2f", "%.5f", "%.6f", "%.6f"], delimiter=",", header="t_s,OP,PV,SP",
                   comments="")
    os.replace(tmp, path)
    if parquet is not None:
        import pandas as pd

        pd.DataFrame(data, columns=["t_s", "OP", "PV", "SP"]).to_parquet(parquet)
    return time.perf_counter() - t0


def _tree_rss_kb(root: int, root_only: bool = False) -> int:
    """Summed VmRSS [kB] of `root` and all its descendants (Linux /proc); of `root` alone with `root_only`."""
    if root_only:
        try:
            with open(f"/proc/{root}/status") as f:
                return next((int(ln.split()[1]) for ln in f if ln.startswith("VmRSS:")), 0)
        except OSError:
            return 0
    parent: dict[int, int] = {}
    rss: dict[int, int] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/status") as f:
                txt = f.read()
        except OSError:
            continue
        pid = int(d)
        for line in txt.splitlines():
            if line.startswith("PPid:"):
                parent[pid] = int(line.split()[1])
            elif line.startswith("VmRSS:"):
                rss[pid] = int(line.split()[1])
    keep = {root}
    changed = True
    while changed:
        changed = False
        for pid, pp in parent.items():
            if pp in keep and pid not in keep:
                keep.add(pid)
                changed = True
    return sum(rss.get(p, 0) for p in keep)


_MEASURER = """
import json, os, subprocess, sys
p = subprocess.Popen(json.loads(sys.argv[1]), stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
out = p.stdout.read()
_, status, ru = os.wait4(p.pid, 0)
sys.stdout.write(out.decode(errors="replace"))
print("\\n@@" + json.dumps({"rc": os.waitstatus_to_exitcode(status), "maxrss_kb": ru.ru_maxrss}))
"""


def measure(name: str, rows: int, cmd: list[str]) -> Run:
    """Run `cmd` under a small measuring Python; wall time, wait4 max RSS, sampled peak of the tree's RSS.

    The measuring process is a fresh interpreter without numpy, so the command's
    processes are not forked from this (large) one, whose memory would count in
    their ``ru_maxrss``; it is left out of the tree sum too.
    """
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-S", "-c", _MEASURER, json.dumps(cmd)], stdout=subprocess.PIPE)
    peak = [0]
    done = threading.Event()

    def sample() -> None:
        while not done.is_set():
            try:
                peak[0] = max(peak[0], _tree_rss_kb(proc.pid) - _tree_rss_kb(proc.pid, root_only=True))
            except Exception:  # noqa: BLE001 - a process vanished while reading /proc
                pass
            done.wait(0.1)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    out = proc.stdout.read().decode(errors="replace") if proc.stdout else ""
    proc.wait()
    wall = time.perf_counter() - t0
    done.set()
    th.join()
    text, _, tail_json = out.rpartition("\n@@")
    try:
        info = json.loads(tail_json)
    except ValueError:
        info = {"rc": -1, "maxrss_kb": 0}
    tail = text.strip().splitlines()[-3:]
    return Run(name, rows, int(info["rc"]), wall, info["maxrss_kb"] / 1024.0, peak[0] / 1024.0, " | ".join(tail))


def diagnose_cmd(path: Path, out_json: Path, jobs: int) -> list[str]:
    exe = Path(sys.executable).with_name("valve-gym")
    head = [str(exe)] if exe.exists() else [sys.executable, "-m", "valve_gym.cli"]
    return head + ["diagnose", str(path), "--op-range", "0,100", "--json", str(out_json), "--quiet",
                   "--jobs", str(jobs)]


def load_cmd(path: Path) -> list[str]:
    code = ("import sys; from valve_gym.diagnosis.recording import load_recording; "
            f"r = load_recording({str(path)!r}, op_range=(0, 100)); "
            "print(len(r), r.dt); print(*r.repairs, sep='\\n')")
    return [sys.executable, "-c", code]


def _summary(res_path: Path) -> str:
    try:
        d = json.loads(res_path.read_text())
    except (OSError, ValueError):
        return "no JSON"
    rec = d.get("recording", {})
    return (f"n={rec.get('n', rec.get('samples', '?'))}, dt={rec.get('dt', '?')} s, effects={d.get('effects')}, "
            f"final RMSE={d.get('final', {}).get('rmse')}, friction={d.get('stiction', {}).get('present')}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--dt", type=float, default=0.1, help="sample time of the big file [s] (10 Hz)")
    ap.add_argument("--ref-rows", type=int, default=3600)
    ap.add_argument("--effect", default="slip_jump")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--workdir", help="keep the files here (default: a temporary folder, removed)")
    ap.add_argument("--json", help="write the measurements as JSON")
    a = ap.parse_args(argv)
    work = Path(a.workdir) if a.workdir else Path(tempfile.mkdtemp(prefix="bench_large_"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        big, ref = work / f"loop_{a.rows}.csv", work / f"loop_{a.ref_rows}.csv"
        big_pq = work / f"loop_{a.rows}.parquet"
        s_big = write_loop(big, a.rows, a.dt, a.effect, a.seed, parquet=big_pq)
        s_ref = write_loop(ref, a.ref_rows, 1.0, a.effect, a.seed)
        print(f"generated {big.name} ({big.stat().st_size / 1e6:.1f} MB, {s_big:.1f} s) and "
              f"{ref.name} ({s_ref:.1f} s) in {work}", flush=True)
        print(f"load average at start: {os.getloadavg()[0]:.2f}", flush=True)
        runs = [
            measure(f"reference: {a.ref_rows} rows, dt=1 s", a.ref_rows,
                    diagnose_cmd(ref, work / "ref.json", a.jobs)),
            measure(f"load only: {a.rows} rows, CSV", a.rows, load_cmd(big)),
            measure(f"load only: {a.rows} rows, Parquet", a.rows, load_cmd(big_pq)),
            measure(f"{a.rows} rows, dt={a.dt:g} s", a.rows, diagnose_cmd(big, work / "big.json", a.jobs)),
        ]
        print(f"load average at end: {os.getloadavg()[0]:.2f}\n")
        print("| run | exit | wall [s] | peak RSS, largest process [MB] | peak RSS, process tree [MB] |")
        print("|---|---:|---:|---:|---:|")
        for r in runs:
            print(f"| {r.name} | {r.rc} | {r.wall_s:.1f} | {r.maxrss_mb:.0f} | {r.tree_peak_mb:.0f} |")
        for r in runs:
            if r.rc != 0:
                print(f"\n{r.name} failed (exit {r.rc}): {r.tail}")
        ref_run, load_run, _, big_run = runs
        print(f"\nratio big / reference: wall {big_run.wall_s / ref_run.wall_s:.2f}x, "
              f"tree RSS {big_run.tree_peak_mb / max(ref_run.tree_peak_mb, 1):.2f}x")
        print(f"reference result: {_summary(work / 'ref.json')}")
        print(f"big result:       {_summary(work / 'big.json')}")
        print(f"load only output: {load_run.tail}")
        ok = (big_run.rc == 0 and big_run.wall_s <= LIMIT_S and big_run.tree_peak_mb <= LIMIT_MB)
        print(f"\nlimits {LIMIT_S:.0f} s and {LIMIT_MB:.0f} MB: {'met' if ok else 'NOT met'}")
        if a.json:
            Path(a.json).write_text(json.dumps({"runs": [asdict(r) for r in runs], "rows": a.rows, "dt": a.dt,
                                                "effect": a.effect, "seed": a.seed, "jobs": a.jobs}, indent=2))
        return 0 if ok else 1
    finally:
        if not a.workdir:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
