"""Speed of the physics kernel against its frozen pre-split reference, side by side in one run.

The kernel of :mod:`valve_gym.core` calls one small inlined helper per block; the
reference (``benchmarks/kernel_reference.py``) is the single long function it
replaced. Both are called directly (no ``run_packed`` wrapper) on the same packed
parameters, state and inputs, in the call patterns of valve_gym's users:

* ``single env``: one system, one controller sample per call (``gymnasium.make``
  env step), the env's default sub-steps;
* ``vector env N``: N systems, one sample per call (native vector env);
* ``batch``: 64 systems, 2000 samples in one call (fitter, benchmark runs);

for the seed (Riihilahti) valve and for the Choudhury slip-jump valve; then the
environments themselves (``gymnasium.make`` single env, native vector env), run
once with the current kernel and once with the reference swapped into
:mod:`valve_gym.core` (the reference reads only the parameter rows it knows). Each row
is the best of several timed repeats after a warm-up (CPU time of the calling
thread, so the load of other processes on a shared machine does not count), the
two kernels' repeats interleaved so that a change of machine load hits both alike. The ratio is
current / reference sub-steps per second (>= 0.95 is the project's bar). Before
timing, each case checks that both kernels give bit-for-bit the same state and
outputs.

Usage::

    python benchmarks/bench_kernel.py [--quick] [--repeats R] [--json OUT]
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from kernel_reference import NP as REF_NP  # noqa: E402
from kernel_reference import reference_kernel  # noqa: E402

from valve_gym import core  # noqa: E402
from valve_gym._io import write_atomic  # noqa: E402
from valve_gym.config import EnvConfig  # noqa: E402
from valve_gym.params import ModelParams, SlipJump, ValveParams  # noqa: E402


def model(kind: str, n: int, rng) -> ModelParams:
    """A batch of ``n`` sticky valves on the default tank: ``seed`` (Riihilahti) or ``slip_jump``."""
    if kind == "seed":
        return ModelParams(valve=ValveParams(e_dead=rng.uniform(0.0, 0.02, n), z_max=rng.uniform(0.002, 0.5, n)))
    return ModelParams(slip_jump=SlipJump(S=rng.uniform(0.005, 0.08, n), J=rng.uniform(0.0, 0.04, n)))


def case(kind: str, n: int, T: int, calls: int, n_sub: int, seed: int = 0):
    """Packed arguments and a runner per kernel for ``calls`` calls of ``T`` samples on ``n`` systems."""
    rng = np.random.default_rng(seed)
    p = model(kind, n, rng)
    pk = core.pack(p, n)
    st = core.initial_state(p, n, buf_len=pk.buf_len)
    n_in = min(calls, 64)
    us = [np.ascontiguousarray(rng.uniform(0.2, 0.8, (T, n))) for _ in range(n_in)]
    D = np.zeros((T, 1))
    P_new = pk.P
    P_ref = np.ascontiguousarray(pk.P[:REF_NP])

    def runner(kern, P):
        S = core.state_to_array(st)
        buf = np.array(st.delay_buf, copy=True)
        Y, H, LV = (np.empty((T, n)) for _ in range(3))

        def run():
            for i in range(calls):
                kern(S, P, us[i % n_in], D, pk.flags, buf, n_sub, pk.dt, Y, H, LV)
            return S, buf, Y, H, LV

        return run

    return runner(core._kernel, P_new), runner(reference_kernel, P_ref)


def timed(fns: dict, repeats: int) -> dict:
    """Best CPU time of each callable (this thread's, so other processes' load does not count),
    repeats interleaved; one warm-up call each."""
    for fn in fns.values():
        fn()
    best = {k: float("inf") for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t0 = time.thread_time()
            fn()
            best[k] = min(best[k], time.thread_time() - t0)
    return best


def env_runners(kind: str, n: int, steps: int):
    """A timed loop over the single env (``n = 0``: ``gymnasium.make``) or the native vector env of ``n``,
    run with the current kernel or with the reference swapped into :mod:`valve_gym.core`."""
    import gymnasium as gym

    from valve_gym.envs import ValveTankVectorEnv

    env = gym.make("valve_gym/ValveTank-v0") if n == 0 else ValveTankVectorEnv(n)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    shape = (1,) if n == 0 else (n, 1)
    acts = [rng.uniform(-1, 1, shape).astype(np.float32) for _ in range(64)]
    current = core._kernel

    def make(kern):
        def run():
            core._kernel = kern
            try:
                for i in range(steps):
                    out = env.step(acts[i % 64])
                    if n == 0 and (out[2] or out[3]):
                        env.reset()
            finally:
                core._kernel = current
        return run

    return make(current), make(reference_kernel)


def check_identical(kind: str, n_sub: int) -> None:
    """Both kernels, same inputs: bit-for-bit the same state, buffer and outputs."""
    new, ref = case(kind, 16, 50, 3, n_sub, seed=1)
    for a, b in zip(new(), ref()):
        if not np.array_equal(a, b):
            raise SystemExit(f"{kind}: the current kernel differs from the pre-split reference")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer calls (a smoke run)")
    ap.add_argument("--repeats", type=int, default=7, help="timed repeats per row (best is kept)")
    ap.add_argument("--json", metavar="OUT", help="also write the results as JSON")
    args = ap.parse_args(argv)
    n_sub = EnvConfig().substeps
    scale = 10 if args.quick else 1
    rows = [("single env", 1, 1, 20_000), ("vector env N=1024", 1024, 1, 300), ("vector env N=4096", 4096, 1, 80),
            ("batch n=64, T=2000", 64, 2000, 1)]
    out = {"python": sys.version.split()[0], "numpy": np.__version__, "machine": platform.machine(),
           "substeps": n_sub, "repeats": args.repeats, "rows": []}
    print(f"physics kernel vs its pre-split reference ({n_sub} Euler sub-steps per sample; best of "
          f"{args.repeats} interleaved repeats; Python {out['python']}, numpy {out['numpy']})\n")
    print("| valve | call pattern | current M sub-steps/s | reference M sub-steps/s | current / reference |")
    print("|---|---|---:|---:|---:|")
    for kind in ("seed", "slip_jump"):
        check_identical(kind, n_sub)
        for label, n, T, calls in rows:
            calls = max(1, calls // scale)
            new, ref = case(kind, n, T, calls, n_sub)
            t = timed({"current": new, "reference": ref}, args.repeats)
            work = n * T * calls * n_sub
            r = {"valve": kind, "pattern": label, "current": work / t["current"],
                 "reference": work / t["reference"]}
            r["ratio"] = r["current"] / r["reference"]
            out["rows"].append(r)
            print(f"| {kind} | {label} | {r['current'] / 1e6:.1f} | {r['reference'] / 1e6:.1f} | {r['ratio']:.3f} |")
    print("\n| environment | current env-steps/s | reference env-steps/s | current / reference |")
    print("|---|---:|---:|---:|")
    for label, n, steps in (("gymnasium.make, 1 env", 0, 20_000), ("vector env N=1024", 1024, 200),
                            ("vector env N=4096", 4096, 60)):
        steps = max(10, steps // scale)
        new, ref = env_runners("seed", n, steps)
        t = timed({"current": new, "reference": ref}, args.repeats)
        r = {"valve": "env default", "pattern": label, "current": max(n, 1) * steps / t["current"],
             "reference": max(n, 1) * steps / t["reference"]}
        r["ratio"] = r["current"] / r["reference"]
        out["rows"].append(r)
        print(f"| {label} | {r['current']:,.0f} | {r['reference']:,.0f} | {r['ratio']:.3f} |")
    if args.json:
        text = json.dumps(out, indent=2).encode()
        write_atomic(args.json, lambda f: f.write(text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
