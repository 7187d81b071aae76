"""Speed of the valve_gym environments against Gymnasium's CartPole, in one run.

Measures

(a) steps/s of one environment through ``gymnasium.make`` (with its default
    wrappers: PassiveEnvChecker, OrderEnforcing, TimeLimit) at the default
    config, and of ``CartPole-v1`` made the same way;
(b) env-steps/s of the native vector env ``ValveTankVectorEnv`` and of
    Gymnasium's ``CartPoleVectorEnv`` at N = 1, 64, 1024, 4096, and at
    N = 1024, 4096 with the plant run in two kernel threads (``threads=2``);
(c) plant Euler sub-steps/s (= env-steps/s x substeps), next to the bare kernel
    (:func:`valve_gym.core.run_packed` alone, same valves and random inputs);
(d) the numba kernel of :mod:`valve_gym.core` against its pure-Python version
    (``core._kernel_core.py_func``) at a small size.

``benchmarks/bench_kernel.py`` compares the kernel (one inlined helper per
block) with its frozen pre-split version, single env and vector env.

Actions are pre-generated uniform samples of the action space (the valve
moves at every step, the costly case for the kernel); episodes end and reset
inside the timed loops as in training. Every figure is the best of several
timed repeats after a warm-up. Prints a markdown table; ``--json OUT`` also
writes the numbers.

Usage::

    python benchmarks/bench_env_speed.py [--quick] [--json OUT]
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time

import numpy as np


def _best(fns, repeats):
    """Best time of each of ``fns`` (name -> callable), the repeats interleaved so
    that a change of machine load affects all alike; one warm-up call each."""
    for fn in fns.values():
        fn()
    best = {k: float("inf") for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - t0)
    return best


def single_runner(env_id, n_steps, **kwargs):
    """A timed loop over ``gymnasium.make(env_id)`` with pre-generated random actions."""
    import gymnasium as gym

    import valve_gym  # noqa: F401  (registers the environments)

    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    env.action_space.seed(0)
    acts = [env.action_space.sample() for _ in range(n_steps)]
    step, reset = env.step, env.reset

    def run():
        for a in acts:
            _, _, term, trunc, _ = step(a)
            if term or trunc:
                reset()

    return run


def vector_runner(env, n_steps, discrete):
    """A timed loop over a native vector env (autoreset inside)."""
    n_envs = env.num_envs
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    n_act = min(n_steps, 64)
    if discrete:
        acts = [rng.integers(0, 2, n_envs) for _ in range(n_act)]
    else:
        acts = [rng.uniform(-1, 1, (n_envs, 1)).astype(np.float32) for _ in range(n_act)]
    step = env.step

    def run():
        for i in range(n_steps):
            step(acts[i % n_act])

    return run


def kernel_runner(env, n_steps, threads=1):
    """The bare kernel on the vector env's valves, same random inputs (no env around it)."""
    from valve_gym import core
    from valve_gym.plant import Plant

    env.reset(seed=0)
    n = env.num_envs
    rng = np.random.default_rng(0)
    n_act = min(n_steps, 64)
    us = [rng.uniform(0, 1, (1, n)) for _ in range(n_act)]
    D = np.zeros((1, n))
    Y, H, LV = (np.empty((1, n)) for _ in range(3))
    plant = Plant(env.model, n, scan_s=env.config.control_period, check=False)   # the env's valves, at rest
    plant.reset()
    args = plant.scan_args(us[0], D, (Y, H, LV))
    pk, S, buf, ns = args[0], args[1], args[2], args[5]

    def run():
        for i in range(n_steps):
            core.run_packed(pk, S, buf, us[i % n_act], D, ns, Y, H, LV, threads=threads)

    return run


def bench_kernel(n, T, n_sub, repeats):
    """Sub-steps/s of the compiled kernel and of its pure-Python version."""
    from valve_gym import core
    from valve_gym.params import ModelParams, ValveParams

    p = ModelParams(valve=ValveParams(z_max=0.1, e_dead=0.01))
    pk = core.pack(p, n)
    st = core.initial_state(p, n)
    rng = np.random.default_rng(0)
    U = rng.uniform(0.3, 0.7, (T, n))
    D = np.zeros((T, 1))
    res = {}
    def python_kernel(*args):           # the kernel's own body, interpreted (its block helpers stay compiled)
        e = np.empty(0)
        core._kernel_core.py_func(*args, e, e, e, e)

    for name, fn in (("numba", core._kernel), ("python", python_kernel)):
        Y, H, LV = (np.empty((T, n)) for _ in range(3))

        def run():
            S = core.state_to_array(st)
            buf = np.array(st.delay_buf, copy=True)
            fn(S, pk.P, U, D, pk.flags, buf, n_sub, pk.dt, Y, H, LV)

        res[name] = n * T * n_sub / _best({name: run}, repeats if name == "numba" else 1)[name]
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer steps and repeats (a smoke run)")
    ap.add_argument("--json", metavar="OUT", help="also write the results as JSON")
    args = ap.parse_args(argv)

    import gymnasium as gym
    from gymnasium.envs.classic_control.cartpole import CartPoleVectorEnv

    import valve_gym
    from valve_gym.envs import ValveTankVectorEnv

    q = args.quick
    reps = 2 if q else 5
    substeps = valve_gym.EnvConfig().substeps
    out = {"python": sys.version.split()[0], "numpy": np.__version__, "gymnasium": gym.__version__,
           "machine": platform.machine(), "substeps": substeps}

    # (a) one env through gymnasium.make
    n1 = 5_000 if q else 50_000
    t = _best({"valve": single_runner("valve_gym/ValveTank-v0", n1),
               "residual": single_runner("valve_gym/ValveTank-v0", n1, config={"action_mode": "residual"}),
               "cartpole": single_runner("CartPole-v1", n1)}, reps)
    vt, vr, cp = n1 / t["valve"], n1 / t["residual"], n1 / t["cartpole"]
    out["single"] = {"ValveTank-v0": vt, "ValveTank-v0 residual": vr, "CartPole-v1": cp}

    # (b), (c) native vector envs (episodes of 600 steps: the long runs cross a reset)
    out["vector"] = {}
    for n in (1, 64, 1024, 4096):
        steps = {1: 20_000, 64: 3_000, 1024: 700, 4096: 700}[n]
        if q:
            steps = max(steps // 10, 20)
        t = _best({"valve": vector_runner(ValveTankVectorEnv(n), steps, False),
                   "cartpole": vector_runner(CartPoleVectorEnv(num_envs=n), steps, True),
                   "kernel": kernel_runner(ValveTankVectorEnv(n), steps)},
                  max(reps - 2, 2))
        v, c = n * steps / t["valve"], n * steps / t["cartpole"]
        out["vector"][n] = {"ValveTank": v, "CartPole": c, "substeps_per_s": v * substeps,
                            "kernel_substeps_per_s": n * steps * substeps / t["kernel"]}
    out["vector_threads"] = {}
    for n in (1024, 4096):
        steps = max(70, 700 // (10 if q else 1))
        t = _best({"valve": vector_runner(ValveTankVectorEnv(n, threads=2), steps, False),
                   "cartpole": vector_runner(CartPoleVectorEnv(num_envs=n), steps, True),
                   "kernel": kernel_runner(ValveTankVectorEnv(n), steps, threads=2)},
                  max(reps - 2, 2))
        v, c = n * steps / t["valve"], n * steps / t["cartpole"]
        out["vector_threads"][n] = {"ValveTank": v, "CartPole": c, "substeps_per_s": v * substeps,
                                    "kernel_substeps_per_s": n * steps * substeps / t["kernel"]}

    # (d) numba against pure Python
    out["kernel"] = bench_kernel(n=4, T=50 if q else 200, n_sub=substeps, repeats=reps)

    # report
    lines = ["| measurement | valve_gym | CartPole | ratio | plant sub-steps/s | bare kernel sub-steps/s |",
             "|---|---:|---:|---:|---:|---:|"]
    lines.append(f"| gymnasium.make, 1 env, steps/s | {vt:,.0f} | {cp:,.0f} | {vt / cp:.2f} | "
                 f"{vt * substeps / 1e6:.1f} M | |")
    lines.append(f"| gymnasium.make, 1 env, residual mode, steps/s | {vr:,.0f} | {cp:,.0f} | "
                 f"{vr / cp:.2f} | {vr * substeps / 1e6:.1f} M | |")
    for n, r in out["vector"].items():
        lines.append(f"| vector env N={n}, env-steps/s | {r['ValveTank']:,.0f} | {r['CartPole']:,.0f} | "
                     f"{r['ValveTank'] / r['CartPole']:.2f} | {r['substeps_per_s'] / 1e6:.1f} M | "
                     f"{r['kernel_substeps_per_s'] / 1e6:.1f} M |")
    for n, r in out["vector_threads"].items():
        lines.append(f"| vector env N={n}, 2 kernel threads, env-steps/s | {r['ValveTank']:,.0f} | "
                     f"{r['CartPole']:,.0f} | {r['ValveTank'] / r['CartPole']:.2f} | "
                     f"{r['substeps_per_s'] / 1e6:.1f} M | {r['kernel_substeps_per_s'] / 1e6:.1f} M |")
    kn = out["kernel"]
    lines.append(f"| kernel n=4: numba vs its pure-Python version, sub-steps/s | {kn['numba']:,.0f} | "
                 f"{kn['python']:,.0f} (Python) | {kn['numba'] / kn['python']:.0f}x | | |")
    print(f"valve_gym environment speed ({substeps} Euler sub-steps per env step; best of "
          f"{reps} repeats; Python {out['python']}, numpy {out['numpy']}, gymnasium "
          f"{out['gymnasium']})\n")
    print("\n".join(lines))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(out, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
