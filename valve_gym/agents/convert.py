"""Convert a trusted pickle-based policy (SB3 ``.zip``) to safetensors + JSON.

``valve-gym convert-policy --trust-pickle IN.zip OUT [--vecnormalize VECNORM.pkl] [--algorithm sac]``

Loading an SB3 ``.zip`` unpickles it, which runs any code the file carries: do this only for a file
whose origin you trust (e.g. one you trained yourself). Every other command refuses such files.

* A policy of ``valve_gym/ValveTankRegulation-v0`` (PPO, A2C, SAC, TD3, DDPG; two actions) becomes a
  regulation policy export (:func:`valve_gym.agents.bench.policies.export_policy`, with the
  ``VecNormalize`` observation statistics of ``--vecnormalize``) that ``valve-gym benchmark --policy``
  and :func:`valve_gym.agents.bench.policies.evaluate` run.
* An old PPO policy of ``valve_gym/ValveTank-v0`` (one action) becomes a ``valve_gym.ppo_policy/1`` file
  for :func:`valve_gym.agents.ppo.load_policy`.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
import zipfile

__all__ = ["convert_sb3_zip", "main"]


ALGORITHMS = ("ppo", "a2c", "sac", "td3", "ddpg")


def _algorithm_of(src: str) -> str:
    """The SB3 algorithm of a zip from its ``data`` JSON (its policy class), without unpickling anything."""
    try:
        with zipfile.ZipFile(src) as z:
            data = json.loads(z.read("data").decode("utf-8")) if "data" in z.namelist() else {}
    except (ValueError, KeyError, zipfile.BadZipFile):
        data = {}
    text = json.dumps(data.get("policy_class", ""))
    for name, key in (("sac", "stable_baselines3.sac"), ("td3", "stable_baselines3.td3"),
                      ("ddpg", "stable_baselines3.td3"), ("a2c", "ActorCriticPolicy")):
        if key in text:
            return "ppo" if name == "a2c" else name
    return "ppo"


def convert_sb3_zip(src: str, dst: str, vecnormalize: str | None = None, algorithm: str | None = None) -> str:
    """Unpickle the trusted SB3 policy ``src`` and write it as ``dst.safetensors`` + ``dst.json``; returns the JSON.

    Parameters
    ----------
    src : str
        The SB3 ``.zip`` (trusted).
    dst : str
        Output stem.
    vecnormalize : str, optional
        The ``VecNormalize`` pickle saved with the model (trusted; ``VecNormalize.save``): its observation
        statistics go into the export.
    algorithm : str, optional
        ``ppo``, ``a2c``, ``sac``, ``td3`` or ``ddpg`` (default: read from the zip's policy class).
    """
    import stable_baselines3 as sb3

    algo = (algorithm or _algorithm_of(src)).lower()
    if algo not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algorithm!r}; one of {', '.join(ALGORITHMS)}")
    warnings.warn(f"unpickling {src}: this runs any code inside the file; only do it for a file you trust",
                  stacklevel=2)
    meta: dict = {}
    with zipfile.ZipFile(src) as z:
        if "valve_gym.json" in z.namelist():
            meta = json.loads(z.read("valve_gym.json").decode("utf-8"))
    model = getattr(sb3, algo.upper()).load(src, device="cpu")
    if int(model.action_space.shape[0]) == 2:      # a regulation-env policy
        from .bench.policies import export_policy

        vn = None
        if vecnormalize:
            import pickle

            with open(vecnormalize, "rb") as fh:   # trusted, like src (--trust-pickle)
                vn = pickle.load(fh)
        meta["converted_from"] = str(src)
        return export_policy(model, dst, vecnormalize=vn, meta=meta)
    if vecnormalize:
        raise ValueError("--vecnormalize is for policies of valve_gym/ValveTankRegulation-v0")
    from .ppo import save_policy
    meta["converted_from"] = str(src)
    pk = model.policy_kwargs or {}
    arch = pk.get("net_arch", {})
    act = pk.get("activation_fn")
    pkw = meta.setdefault("train_config", {}).setdefault("ppo", {}).setdefault("policy_kwargs", {})
    pkw.setdefault("net_arch", list(arch.get("pi", [64, 64]) if isinstance(arch, dict) else arch))
    pkw.setdefault("activation_fn", "relu" if act is not None and "ReLU" in getattr(act, "__name__", "") else "tanh")
    return save_policy(model, dst, meta)


def _check_src(src: str) -> str:
    """What is wrong with the input ``src`` (empty if nothing): checked before anything is unpickled."""
    if os.path.isdir(src):
        return f"{src} is a folder, not a file; give the old policy .zip"
    if not os.path.isfile(src):
        return f"{src} does not exist; give the path of the old policy .zip (stable-baselines3)"
    try:
        ok = zipfile.is_zipfile(src)
    except OSError as exc:
        return f"cannot read {src}: {exc.strerror or exc}"
    if not ok:
        return f"{src} is not a zip file; give an old stable-baselines3 policy .zip"
    return ""


def main(argv=None) -> int:
    """Command line; exit 0 done, 1 failed, 2 bad usage."""
    p = argparse.ArgumentParser(prog="valve-gym convert-policy", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--trust-pickle", action="store_true", required=True,
                   help="required: you trust the file (unpickling runs any code inside it)")
    p.add_argument("src", help="old policy .zip (stable-baselines3)")
    p.add_argument("dst", help="output stem: writes DST.safetensors and DST.json")
    p.add_argument("--vecnormalize", default=None, metavar="PKL",
                   help="the VecNormalize statistics saved with the model (trusted pickle, VecNormalize.save)")
    p.add_argument("--algorithm", default=None, choices=ALGORITHMS,
                   help="the SB3 algorithm (default: read from the zip)")
    args = p.parse_args(argv)
    problem = _check_src(args.src)
    if problem:
        print(f"valve-gym convert-policy: {problem}", file=sys.stderr)
        return 2
    try:
        if args.vecnormalize and not os.path.isfile(args.vecnormalize):
            print(f"valve-gym convert-policy: --vecnormalize {args.vecnormalize} does not exist", file=sys.stderr)
            return 2
        out = convert_sb3_zip(args.src, args.dst, args.vecnormalize, args.algorithm)
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
        print(f"convert: {args.src}: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out} (and its .safetensors)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
