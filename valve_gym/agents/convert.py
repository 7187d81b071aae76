"""Convert a trusted old pickle-based policy (SB3 ``.zip``) to safetensors + JSON.

``python -m valve_gym.agents.convert --trust-pickle IN.zip OUT``

Loading an SB3 ``.zip`` unpickles it, which runs any code the file carries: do this only for a file
whose origin you trust (e.g. one you trained yourself with an older valve-gym). Every other
command refuses such files. The output ``OUT.safetensors`` + ``OUT.json`` loads with
:func:`valve_gym.agents.ppo.load_policy` without unpickling.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
import zipfile

__all__ = ["convert_sb3_zip", "main"]


def convert_sb3_zip(src: str, dst: str) -> str:
    """Unpickle the trusted SB3 policy ``src`` and write it as ``dst.safetensors`` + ``dst.json``; returns the JSON."""
    from stable_baselines3 import PPO

    from .ppo import save_policy

    warnings.warn(f"unpickling {src}: this runs any code inside the file; only do it for a file you trust",
                  stacklevel=2)
    meta: dict = {}
    with zipfile.ZipFile(src) as z:
        if "valve_gym.json" in z.namelist():
            meta = json.loads(z.read("valve_gym.json").decode("utf-8"))
    model = PPO.load(src, device="cpu")
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
    args = p.parse_args(argv)
    problem = _check_src(args.src)
    if problem:
        print(f"valve-gym convert-policy: {problem}", file=sys.stderr)
        return 2
    try:
        out = convert_sb3_zip(args.src, args.dst)
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
        print(f"convert: {args.src}: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out} (and its .safetensors)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
