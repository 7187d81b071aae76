"""``valve-gym`` command line: one entry point, one sub-command per job.

Sub-commands (each module's ``main(argv)`` does the work)::

    valve-gym benchmark  --out DIR [--quick] [--config FILE] [--jobs N]   compensator benchmark (the main job)
    valve-gym train      --config configs/learned.yaml --out DIR [--resume | --overwrite]
    valve-gym figures    --out DIR                  teaching figures of valve friction
    valve-gym diagnose   REC.csv|DIR [options]      model-mismatch diagnosis of a recording or a fleet
    valve-gym convert-policy --trust-pickle IN.zip OUT   one-off conversion of a trusted old SB3 zip
"""
from __future__ import annotations

import importlib
import sys

_COMMANDS = {
    "benchmark": ("valve_gym.agents.bench.cli", "compensator benchmark: regulation and servo on sticky valves"),
    "train": ("valve_gym.agents.train", "train the learned compensator (ES) or a PPO policy from a YAML config"),
    "figures": ("valve_gym.figures", "write the teaching figures (PNG)"),
    "diagnose": ("valve_gym.diagnosis.cli", "diagnose a recording (or a folder of loops, locally or on Ray): "
                 "locate the mismatch, name the missing physics, rank the valves"),
    "lab": ("valve_gym.lab.cli", "serve the teaching lab in the browser: the valve, its loop, the compensators"),
    "convert-policy": ("valve_gym.agents.convert", "convert a TRUSTED old pickle-based SB3 zip to safetensors + JSON"),
}


#: The optional packages and the extra that installs each (pyproject.toml's optional-dependencies).
EXTRA_OF = {"stable_baselines3": "rl", "torch": "rl", "tensorboard": "rl", "ray": "fleet", "pyarrow": "fleet",
            "panel": "lab", "bokeh": "lab", "param": "lab"}


def missing_extra(exc: ModuleNotFoundError, cmd: str) -> str | None:
    """The one line for a command whose optional package is missing (``None``: not an extra's package)."""
    top = (exc.name or "").split(".")[0]
    if top not in EXTRA_OF:
        return None
    return (f'valve-gym {cmd}: this needs {top}, which the core install leaves out: '
            f'pip install "valve_gym[{EXTRA_OF[top]}]"')


def _usage() -> str:
    lines = ["usage: valve-gym COMMAND [options]", "", "commands:"]
    lines += [f"  {k:<15} {v[1]}" for k, v in _COMMANDS.items()]
    lines += ["", "valve-gym COMMAND --help shows the options of a command."]
    return "\n".join(lines)


def _out_problem(cmd: str, rest: list) -> str:
    """One line on why the ``--out`` folder of ``rest`` cannot be used, or ``''`` (checked before any work).

    Every command's ``--out`` names a folder (created when absent); a path through a file, a FIFO
    or a device, a folder without write permission or a place where nothing can be created
    (``/proc``) is refused here with exit status 2, before the command starts.
    """
    if "-h" in rest or "--help" in rest:
        return ""
    from ._io import folder_problem

    for i, a in enumerate(rest):
        out = rest[i + 1] if a == "--out" and i + 1 < len(rest) else a[6:] if a.startswith("--out=") else None
        if out is not None and out.strip():
            why = folder_problem(out)
            if why:
                return f"valve-gym {cmd}: --out {out}: {why}"
    return ""


def main(argv=None) -> int:
    """Run ``valve-gym COMMAND [options]``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0
    cmd, rest = argv[0], argv[1:]
    if cmd not in _COMMANDS:
        print(f"valve-gym: unknown command {cmd!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    why = _out_problem(cmd, rest)
    if why:
        print(why, file=sys.stderr)
        return 2
    try:
        mod = importlib.import_module(_COMMANDS[cmd][0])
        rc = mod.main(rest)
    except KeyboardInterrupt:
        print("valve-gym: interrupted", file=sys.stderr)
        return 130
    except ModuleNotFoundError as e:
        said = missing_extra(e, cmd)
        if said is None:
            raise
        print(said, file=sys.stderr)
        return 2
    return int(rc or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
