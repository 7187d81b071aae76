"""``valve-gym benchmark --out DIR [--quick] [--config FILE] [--jobs N] [--policy FILE --name NAME ...]``.

The compensator benchmark; ``--policy`` adds one's own policies (a regulation-env policy exported with
:func:`valve_gym.agents.bench.policies.export_policy` or ``valve-gym convert-policy``, a learned-block file, a
trained adaptive-compensator file, or a folder of them = the seeds of one row) beside the classical rows.
"""
from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from valve_gym._io import folder_problem
from valve_gym.config import ConfigError

from .config import BenchConfig, load_bench_config
from .pipeline import default_jobs, print_progress, run_benchmark

__all__ = ["main", "build_parser", "check_out"]


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser."""
    p = argparse.ArgumentParser(
        prog="valve-gym benchmark",
        description="Compensator benchmark: every controller on sticky valves at a constant set point "
                    "(regulation) and on set-point steps (servo). See docs/benchmark.md.")
    p.add_argument("--out", default="results",
                   help="output folder, created if absent; must not be a file (default: results)")
    p.add_argument("--quick", action="store_true", help="a few short loops (seconds; a smoke test)")
    p.add_argument("--config", default=None, help="benchmark YAML (default: the built-in = configs/benchmark.yaml)")
    p.add_argument("--jobs", type=int, default=None, help="worker processes (default: the cores available)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--no-progress", action="store_true", help="no progress lines on stderr")
    p.add_argument("--policy", action="append", default=[], metavar="FILE",
                   help="a policy of valve_gym/ValveTankRegulation-v0 to add as a row: NAME.json (+ NAME.safetensors) "
                        "from export_policy / convert-policy, a learned-block or trained adaptive-compensator file "
                        "(valve_gym.agents.adaptive_train), or a folder of them (the seeds "
                        "of one row); repeat for more rows. SB3 .zip files are refused: convert a trusted one with "
                        "`valve-gym convert-policy --trust-pickle IN.zip OUT`")
    p.add_argument("--name", action="append", default=[], metavar="NAME",
                   help="row label of the --policy of the same position (default: the file or folder name); "
                        "--policy files given the same --name are the seeds of one row")
    return p


def check_out(out: str) -> None:
    """Refuse an ``--out`` that the report could not be written into (before the benchmark runs).

    ``--out`` must be a folder or not exist yet (it is created; existing result files in it are
    replaced). Raises :class:`ConfigError` naming the problem and what to do.
    """
    if not str(out).strip():
        raise ConfigError("--out must not be empty; give an output folder (default: results)")
    why = folder_problem(out)
    if why:
        raise ConfigError(f"--out {out}: {why}" + ("" if "permission" in why else
                                                   "; give a folder (it is created if it does not exist) or "
                                                   "move the file"))


def _load(args) -> BenchConfig:
    cfg = load_bench_config(args.config) if args.config else BenchConfig()
    return cfg.quick_version() if args.quick else cfg


def _policies(args) -> dict | None:
    """The ``--policy`` rows as ``{label: [block, ...]}`` (loaded and shape-checked before anything runs)."""
    if len(args.name) > len(args.policy):
        raise ValueError(f"{len(args.name)} --name for {len(args.policy)} --policy; give one --name per --policy "
                         "(or fewer: the rest are named after their files)")
    if not args.policy:
        return None
    from .policies import as_blocks

    return as_blocks(args.policy, args.name)


def main(argv=None) -> int:
    """Run the benchmark; 0 on success, 2 on a bad config or option (message on stderr)."""
    args = build_parser().parse_args(argv)
    try:
        check_out(args.out)
        cfg = _load(args)
        blocks = _policies(args)
    except (ConfigError, OSError, ValueError, TypeError) as exc:  # bad file or value: one line, no traceback
        print(f"valve-gym benchmark: {exc}", file=sys.stderr)
        return 2
    jobs = default_jobs() if args.jobs is None else args.jobs
    if jobs < 1:
        print(f"valve-gym benchmark: --jobs must be >= 1, got {jobs}", file=sys.stderr)
        return 2
    command = "valve-gym benchmark " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[2:]))
    t0 = time.perf_counter()
    try:
        res = run_benchmark(cfg, jobs=jobs, progress=None if args.no_progress else print_progress,
                            **({"policies": blocks} if blocks else {}))
    except ConfigError as exc:
        print(f"valve-gym benchmark: {exc}", file=sys.stderr)
        return 2
    from valve_gym._io import staged_folder

    from .report import write_report

    # staged and published together, results.md last: an interrupt while the figures are drawn
    # leaves the folder as it was, never a new results.md beside old or missing figures
    with staged_folder(args.out, last=("results.md",)) as stage:
        files = list(write_report(res, Path(stage), command.strip()))
        if not args.no_figures:
            from .figures import write_figures

            files += list(write_figures(res, Path(stage)))
    files = [Path(args.out) / f.name for f in files]
    for n in res.notes:
        print(f"note: {n}", file=sys.stderr)
    print(f"benchmark done in {time.perf_counter() - t0:.0f} s with {res.jobs_text()}; wrote "
          + ", ".join(str(f) for f in files))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
