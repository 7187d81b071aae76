"""``valve-gym diagnose``: command line of the diagnosis tool.

Usage::

    valve-gym diagnose REC.csv|DIR [--columns t=COL,op=COL,pv=COL,sp=COL,mv=COL]
        [--op-range LO,HI] [--mv-range LO,HI] [--dt SECONDS] [--dayfirst|--monthfirst]
        [--time-unit s|ms|us|days] [--gaps longest|error] [--plant auto|tank|integrating|first_order|cascade]
        [--actuator valve|pump] [--validate OTHER.csv [--validate-columns MAPPING]] [--holdout FRAC]
        [--json OUT.json] [--report DIR] [--effects LIST] [--jobs N]
        [--effort auto|fast|normal|thorough] [--search full|fast] [--op-lag auto|0|1] [--seed N] [--quiet]
    valve-gym diagnose DIR [--out OUTDIR] [--jobs N] [--ray | --address ADDR] [--full]
        [--max-loops N] [--top N] [same options as above]
    valve-gym diagnose EXPORT --out OUTDIR [same options]

A folder of loops (or, with ``--out``, a historian's wide export) is diagnosed by the one batch
engine, :func:`valve_gym.fleet.run_fleet` (:mod:`valve_gym.fleet`), with or without ``--out``: every
loop is screened (oscillation index, Horch's test) and diagnosed in full where it oscillates (every
loop with ``--full``), with a progress line on stderr.  The loops run without Ray by default: one
after another in this process with ``--jobs 1``, in ``--jobs`` local worker processes otherwise;
``--ray`` runs them as Ray tasks (Ray in this process), ``--address`` on a Ray cluster (the
``[fleet]`` extra).  Without ``--out`` a summary table (one row per loop) is printed on stdout and
nothing is kept; with ``--out`` each loop's result is written to ``OUTDIR/loops/`` as it finishes,
``OUTDIR/loops.csv`` (and ``loops.parquet`` with pyarrow) hold one row per loop,
``OUTDIR/worklist.md``/``.html`` rank the loops, and running again continues an interrupted run.
Exit status: 0 on success, 2 for bad input (the message says what is wrong and how to fix it; no
traceback; for a folder also when a loop's data could not be used), 1 for an internal error, 130 when
a folder's run was interrupted (finished loops are kept).
"""
from __future__ import annotations

import argparse
import math
import os
import re
import sys

from .._io import folder_problem
from ..effects import candidate_effects
from .model import ACTUATORS, CANDIDATE_EFFECTS, PLANTS
from .recording import RecordingError, load_recording, parse_columns, parse_range
from .report import _g

__all__ = ["main", "build_parser", "fleet_summary_table"]


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # noqa: D102 - argparse hook
        raise _UsageError(message)


#: Values of ``--op-lag`` (the command line's spelling of ``diagnose(op_lag=...)``).
OP_LAG_CHOICES = ("auto", "0", "1")


def op_lag_value(text: str) -> int | str:
    """``diagnose``'s ``op_lag`` for a ``--op-lag`` value: ``'auto'``, or the lag as a whole number."""
    return text if text == "auto" else int(text)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``valve-gym diagnose``."""
    p = _Parser(prog="valve-gym diagnose",
                description="Fit the valve/process simulator to a recorded loop by free-run "
                            "simulation error, locate where it misses, name the missing physics "
                            "and judge whether the valve sticks.")
    p.add_argument("path", help="recording CSV file, or a folder of them")
    p.add_argument("--columns", help="column mapping, e.g. t=t_s,op=OP,pv=PV,sp=SP "
                                     "(default: common names are recognised); a loop-mode column (mode, "
                                     "TAG.MODE) keeps the longest automatic stretch, mode= reads the "
                                     "whole record")
    p.add_argument("--op-range", help="raw controller-output range LO,HI that maps to 0..1, "
                                      "e.g. 0,100 for percent (default: read from the values: 0..1 a fraction, "
                                      "up to 100 percent, else the observed range, the span unknown; the choice "
                                      "is reported)")
    p.add_argument("--mv-range", help="raw valve-position range LO,HI that maps to 0..1 (default: the "
                                      "--op-range); the position column is read by the stem test")
    p.add_argument("--dt", metavar="SECONDS",
                   help="sample time of a file without a time column (rows equally spaced; single files and "
                        "folders)")
    p.add_argument("--max-gap", default="5", metavar="N",
                   help="longest run of missing samples filled by interpolation (default 5); of a record with "
                        "longer gaps the longest stretch without one is kept (reported), unless --gaps error")
    p.add_argument("--gaps", default="longest", choices=("error", "longest"),
                   help="a gap longer than --max-gap: keep the longest stretch without one (default), or stop "
                        "with an error (single files and folders)")
    dates = p.add_mutually_exclusive_group()
    dates.add_argument("--dayfirst", dest="dayfirst", action="store_const", const=True, default=None,
                       help="dates are written D/M/Y (default: read from the data; asked only when both fit)")
    dates.add_argument("--monthfirst", dest="dayfirst", action="store_const", const=False,
                       help="dates are written M/D/Y")
    p.add_argument("--time-unit", choices=("s", "ms", "us", "days"), default=None,
                   help="unit of a numeric time column: s, ms, us (since the start or the epoch) or days "
                        "(spreadsheet serial days); default: read from the values' size and step")
    p.add_argument("--plant", default="auto", choices=("auto",) + tuple(PLANTS),
                   help="process model (default auto: from the ISA tag of the PV column, else of the file name: "
                        "LIC/LT... integrating, FIC/PIC/TIC/AIC... first_order, no tag: tank)")
    p.add_argument("--actuator", default="valve", choices=ACTUATORS,
                   help="valve (with friction) or pump (default valve)")
    p.add_argument("--validate", metavar="OTHER.csv",
                   help="another recording of the same loop to validate the fitted models on")
    p.add_argument("--validate-columns", metavar="MAPPING",
                   help="column mapping of the --validate recording where it differs from --columns (e.g. "
                        "op=uVal,pv=yVal: the other record of the same file)")
    p.add_argument("--holdout", default="0.3",
                   help="fraction at the end of the record held out of the fit (default 0.3)")
    p.add_argument("--json", metavar="OUT.json", help="write the result as JSON")
    p.add_argument("--report", metavar="DIR", help="write figures and a markdown report")
    p.add_argument("--effects", default="all",
                   help="candidate effects, comma-separated, 'all' (default) or 'none'; known: "
                        + ", ".join(CANDIDATE_EFFECTS))
    p.add_argument("--jobs", default="2",
                   help="workers (default 2): loops in parallel for a folder (local worker processes, 1: one "
                        "after another in this process; Ray workers with --ray), candidate fits in parallel "
                        "for one file")
    p.add_argument("--effort", default="auto", choices=("auto", "fast", "normal", "thorough"),
                   help="search budget (default auto: thorough up to 1800 samples, normal above)")
    p.add_argument("--search", default="full", choices=("full", "fast"),
                   help="full (default) or fast: warm-start clouds and early stops, about 1.15x less CPU, "
                        "fits up to 18 %% worse; for a folder it applies to the full diagnoses")
    p.add_argument("--op-lag", default="auto", choices=OP_LAG_CHOICES,
                   help="how the recorder pairs OP and PV: 0 PV[k] measured after OP[k] acted for one "
                        "sample; 1 OP[k] computed from the PV[k] beside it (a scan logged as it happened, or a "
                        "zero-order-hold input sampled with the output): OP[k-1] is paired with PV[k]; auto "
                        "(default) reads it from the controller's reaction to PV moves (else fits both and keeps 1 "
                        "only when it is clearly better); for a folder it applies to the full diagnoses")
    p.add_argument("--seed", default="0", help="seed of the search (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    _add_folder_options(p)
    return p


def _add_folder_options(p: argparse.ArgumentParser) -> None:
    """The options of a folder of loops (the batch engine, :func:`valve_gym.fleet.run_fleet`)."""
    g = p.add_argument_group("a folder of loops, or a wide export with --out (see docs/fleet.md)")
    g.add_argument("--out", metavar="OUTDIR",
                   help="keep the results: per loop in OUTDIR/loops/, OUTDIR/loops.csv (+ loops.parquet with "
                        "pyarrow), worklist.md + worklist.html; resumes a stopped run; also runs the tags of a "
                        "historian's wide export")
    g.add_argument("--ray", action="store_true",
                   help="run the loops as Ray tasks, Ray in this process with --jobs workers (default: without "
                        "Ray); needs the [fleet] extra")
    g.add_argument("--address", metavar="ADDR",
                   help="address of a running Ray cluster to run the loops on ('auto', host:port, or "
                        "ray://host:port of its Ray Client); implies --ray")
    g.add_argument("--full", action="store_true",
                   help="full diagnosis of every loop (default: only of the loops that oscillate)")
    g.add_argument("--max-loops", metavar="N",
                   help="analyse at most N new loops in this run (with --out, the others in the next)")
    g.add_argument("--top", default="10", metavar="N", help="loops with plots in worklist.html (default 10)")


def _joined_ranges(argv: list[str]) -> list[str]:
    """``--op-range -1,0`` as ``--op-range=-1,0``: a value that starts with a minus sign would read as an option."""
    out: list[str] = []
    for tok in argv:
        if out and out[-1] in ("--op-range", "--mv-range") and re.match(r"-[\d.]", tok):
            out[-1] = f"{out[-1]}={tok}"
        else:
            out.append(tok)
    return out


def _parse_effects(text: str) -> tuple:
    t = text.strip().lower()
    if not t:
        raise _UsageError("--effects is empty; give 'all' (the default), 'none' or effects separated by commas")
    if t == "all":
        return candidate_effects()
    if t == "none":
        return ()
    out = []
    for e in (s.strip() for s in t.split(",")):
        if not e:
            continue
        if e in ("all", "none"):
            raise _UsageError(f"--effects: {e!r} stands alone; it cannot be listed with other effects")
        if e not in candidate_effects():
            raise _UsageError(f"--effects: unknown effect {e!r}; known effects: "
                              f"{', '.join(candidate_effects())} (or 'all', 'none')")
        if e not in out:
            out.append(e)
    return tuple(out)


def _number(text, name, kind=float, lo=None, hi=None):
    try:
        v = kind(text)
    except (TypeError, ValueError):
        raise _UsageError(f"{name} must be a {'whole ' if kind is int else ''}number, "
                          f"got {text!r}") from None
    if kind is float and not math.isfinite(v):
        raise _UsageError(f"{name} must be a finite number, got {text!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise _UsageError(f"{name} must be between {lo} and {hi}, got {text!r}")
    return v


def _check_out(path: str | None, what: str, is_dir: bool):
    """Refuse, before any work, an output path that cannot be written: ``is_dir`` a folder, else a file."""
    if path is None:
        return
    if not path.strip():
        raise _UsageError(f"{what} is empty; give a {'folder' if is_dir else 'file'} name or leave the option out")
    target = os.path.abspath(path)
    if not is_dir and os.path.isdir(target):
        raise _UsageError(f"{what} {path!r} is a folder; give a file name such as out.json")
    why = folder_problem(target if is_dir else os.path.dirname(target))
    if why:
        raise _UsageError(f"{what} {path!r}: {why}")
    if not is_dir and not os.path.isdir(os.path.dirname(target)):
        raise _UsageError(f"{what}: folder {os.path.dirname(target)!r} does not exist; create it first")


def _check_outputs(a) -> None:
    """The output options, each on its own, and not two of them on the same path."""
    _check_out(a.json, "--json", False)
    _check_out(a.report, "--report", True)
    if a.json and a.report and os.path.abspath(a.json) == os.path.abspath(a.report):
        raise _UsageError("--json and --report name the same path; the JSON is a file, the report a folder")
    if a.json and a.out and os.path.abspath(a.json) == os.path.abspath(a.out):
        raise _UsageError("--json and --out name the same path; the JSON is a file, --out a folder")


def _check_address(address: str | None) -> None:
    """Refuse an unusable Ray address as a usage error (:func:`valve_gym.fleet.runner.check_address`)."""
    from ..fleet.runner import check_address

    try:
        check_address(address)
    except ValueError as e:
        raise _UsageError(f"--{e}") from None


def main(argv: list[str] | None = None) -> int:
    """Run ``valve-gym diagnose`` with ``argv``; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return _main(argv)
    except _UsageError as e:
        print(f"valve-gym diagnose: error: {e}\n(run 'valve-gym diagnose --help' for the options)",
              file=sys.stderr)
        return 2
    except RecordingError as e:
        print(f"valve-gym diagnose: error: {e}", file=sys.stderr)
        return 2
    except (ValueError, TypeError) as e:
        print(f"valve-gym diagnose: error: {e}", file=sys.stderr)
        return 2
    except SystemExit as e:  # --help
        return int(e.code or 0)
    except Exception as e:  # pragma: no cover - internal error
        if os.environ.get("VALVE_GYM_DEBUG"):
            raise
        print(f"valve-gym diagnose: internal error: {type(e).__name__}: {e} "
              f"(set VALVE_GYM_DEBUG=1 for the traceback)", file=sys.stderr)
        return 1


def _sample_time(a) -> dict:
    """``{'dt': seconds}`` from ``--dt`` (a file without a time column), or ``{}``."""
    if a.dt is None:
        return {}
    return {"dt": _number(a.dt, "--dt", float, 1e-6, 1e6)}


def _check_mode_options(a) -> None:
    """Refuse options that the chosen mode (a folder or ``--out``: the batch engine; else one file) does not use."""
    if a.validate_columns is not None and not a.validate:
        raise _UsageError("--validate-columns maps the columns of the --validate recording: give --validate too")


def _main(argv: list[str]) -> int:
    from .diagnose import diagnose

    a = build_parser().parse_args(_joined_ranges(argv))
    columns = parse_columns(a.columns) if a.columns is not None else None
    op_range = parse_range(a.op_range) if a.op_range is not None else None
    mv_range = parse_range(a.mv_range, "--mv-range") if a.mv_range is not None else None
    holdout = _number(a.holdout, "--holdout", float, 0.0, 0.6)
    jobs = int(_number(a.jobs, "--jobs", int, 1, 64))
    seed = int(_number(a.seed, "--seed", int, 0, 2 ** 31 - 1))
    cands = _parse_effects(a.effects)
    _check_outputs(a)
    say = (lambda s: None) if a.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    max_gap = int(_number(a.max_gap, "--max-gap", int, 0, 10 ** 6))
    load_kw = {"columns": columns, "op_range": op_range, "mv_range": mv_range, "max_gap": max_gap,
               "gaps": a.gaps, "dayfirst": a.dayfirst, "time_unit": a.time_unit, **_sample_time(a)}
    diag_kw = {"plant": a.plant, "actuator": a.actuator, "candidates": cands,
               "holdout": holdout, "effort": a.effort, "seed": seed, "search": a.search,
               "op_lag": op_lag_value(a.op_lag)}
    path = a.path
    _check_mode_options(a)
    if a.out or os.path.isdir(path):
        return _fleet(a, path, jobs, seed, holdout, cands, op_range, max_gap, say)
    if a.address or a.ray or a.full or a.max_loops or a.top != "10":
        raise _UsageError("--ray, --address, --full, --max-loops and --top work with a folder of loops (or with "
                          "--out OUTDIR); give a folder, or leave them out for one recording")
    if not os.path.exists(path):
        raise RecordingError(f"{path}: no such file or folder")
    rec = load_recording(path, **load_kw)
    other = None
    if a.validate:
        vcols = parse_columns(a.validate_columns) if a.validate_columns is not None else load_kw["columns"]
        other = load_recording(a.validate, **{**load_kw, "columns": vcols})
    res = diagnose(rec, validate=other, jobs=jobs, progress=say, **diag_kw)
    _print_summary(res)
    if a.json:
        from .report import write_json
        write_json(res, a.json)
    if a.report:
        from .report import write_report
        paths = write_report(res, a.report)
        say(f"report written to {a.report} ({len(paths)} files)")
    return 0


def _fleet(a, path, jobs, seed, holdout, cands, op_range, max_gap, say) -> int:
    """A folder (or, with ``--out``, a wide export) through the batch engine, :func:`valve_gym.fleet.run_fleet`."""
    import importlib.util

    use_ray = bool(a.ray or a.address)
    if use_ray and importlib.util.find_spec("ray") is None:
        raise _UsageError('--ray and --address run the loops on Ray, which needs ray: pip install "valve_gym[fleet]" '
                          '(or leave them out: the loops then run without Ray)')
    from ..fleet import FleetSettings, run_fleet
    if a.validate:
        raise _UsageError("--validate works with a single recording, not with a folder or --out")
    if not os.path.exists(path):
        raise RecordingError(f"{path}: no such file or folder")
    if a.out:
        _check_out(a.out, "--out", True)
        from ..fleet.runner import check_out_dir
        try:
            check_out_dir(path, a.out, "--out")
        except ValueError as e:
            raise _UsageError(str(e)) from None
    elif a.top != "10":
        raise _UsageError("--top sets the loops with plots in the worklist, which --out OUTDIR writes: add --out")
    _check_address(a.address)
    max_loops = int(_number(a.max_loops, "--max-loops", int, 1, 10 ** 9)) if a.max_loops else None
    top = int(_number(a.top, "--top", int, 0, 1000))
    cols = parse_columns(a.columns) if a.columns else None
    settings = FleetSettings(plant=a.plant, actuator=a.actuator, candidates=tuple(cands), holdout=holdout,
                             effort=a.effort, search=a.search, seed=seed, full=bool(a.full),
                             op_lag=op_lag_value(a.op_lag),
                             columns=tuple(sorted(cols.items())) if cols else None, op_range=op_range,
                             mv_range=parse_range(a.mv_range, "--mv-range") if a.mv_range else None,
                             max_gap=max_gap, dayfirst=a.dayfirst, time_unit=a.time_unit,
                             dt=_sample_time(a).get("dt"), gaps=a.gaps, report_dir=a.report)

    kept = os.path.join(a.out, "loops") if a.out else ""
    try:
        run = run_fleet(path, a.out or None, settings, jobs=jobs, address=a.address, max_loops=max_loops,
                        stream=None if a.quiet else sys.stderr, top=top, engine="ray" if use_ray else "local")
    except KeyboardInterrupt:       # while the loops were found, or a second Ctrl-C
        more = (f"the loops finished so far are kept in {kept}; run the same command again to continue (it also "
                f"writes the table and the worklist)" if a.out else "add --out OUTDIR to keep the finished loops")
        print(f"valve-gym diagnose: interrupted: {more}", file=sys.stderr)
        return 130
    if not a.out:
        print(fleet_summary_table(run.results))
    _print_fleet(run, max_loops)
    if a.json:
        import json

        from .._io import write_atomic
        text = json.dumps({"loops": [r.to_dict() for r in run.results], "seconds": run.seconds,
                           "interrupted": run.interrupted, "remaining": run.remaining}, indent=1,
                          allow_nan=False).encode()
        write_atomic(a.json, lambda f: f.write(text))
    if a.report:
        from .report import write_text
        write_text(f"# Diagnosis of {run.n_loops} loops\n\n{fleet_summary_table(run.results)}",
                   os.path.join(a.report, "summary.md"))
    if run.interrupted:
        if a.out:
            rest = (f"run the same command again to continue the other {run.remaining}" if run.remaining else
                    "every loop had finished, and the table and the worklist are written")
            print(f"valve-gym diagnose: interrupted: {run.done} loop(s) finished in this run, {len(run.results)} "
                  f"of {run.n_loops} in all, are kept in {kept}; {rest}", file=sys.stderr)
        else:
            print(f"valve-gym diagnose: interrupted: {len(run.results)} of {run.n_loops} loop(s) finished (above); "
                  f"add --out OUTDIR to keep the finished loops and continue later", file=sys.stderr)
        return 130
    statuses = {r.status for r in run.results}
    return 1 if "error" in statuses else 2 if "failed" in statuses else 0


def fleet_summary_table(results) -> str:
    """Markdown table of the batch engine's results (:class:`~valve_gym.fleet.LoopResult`), one row per loop.

    Columns: loop, status, stage (``screen`` or ``full``), whether it oscillates, the stiction verdict with
    its probability and stick band ``S`` [% of stroke], the effects named, the free-run RMSE of the base and
    final models [PV units], the recommended action (or why the loop failed) and the loop's wall time [s].
    """
    from .._markdown import md_cell

    L = ["| loop | status | stage | oscillating | stiction | p | S % | effects | RMSE base | RMSE final | "
         "action | s |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        if r.status != "ok":
            L.append(f"| {md_cell(r.loop)} | {r.status} | | | | | | | | | {md_cell(r.message)} | "
                     f"{_g(r.seconds, 3)} |")
            continue
        L.append(f"| {md_cell(r.loop)} | ok | {r.stage} | {'yes' if r.oscillating else 'no'} | {r.stiction} | "
                 f"{_g(r.p_stiction, 2)} | {_g(100 * r.S, 3)} | {md_cell(r.effects or '–')} | {_g(r.rmse_base)} | "
                 f"{_g(r.rmse_final)} | {md_cell(r.action)} | {_g(r.seconds, 3)} |")
    return "\n".join(L) + "\n"


def _print_fleet(run, max_loops: int | None = None) -> None:
    from ..fleet.worklist import rank
    ok = [r for r in run.results if r.status == "ok"]
    print(f"{run.n_loops} loops: {len(ok)} analysed, {run.failed} failed; {run.done} run now, {run.resumed} "
          f"kept from an earlier run, {run.remaining} left; {run.seconds:.1f} s")
    top = [r for r in rank(ok) if r.oscillating][:10]
    if top:
        print("top loops (score = w x OP amplitude [% of stroke]):")
        for i, r in enumerate(top, 1):
            print(f"  {i:>2}. {r.loop}: score {r.score:.2f}; {r.action}")
    bad = [r for r in run.results if r.status != "ok"]
    if bad:
        print(f"{len(bad)} loop(s) failed:")
        for r in bad:
            print(f"  {r.loop} ({r.status}): {r.message}")
    if run.paths:
        print(f"worklist: {run.paths['worklist_md']}, {run.paths['worklist_html']}; table: {run.paths['table']}")
    if run.remaining and not run.interrupted:
        again = "run the same command again to continue them" if run.paths else "add --out OUTDIR to keep and resume"
        print(f"partial run (--max-loops {max_loops}): {run.remaining} of {run.n_loops} loops not analysed yet; "
              f"{again}")


def _print_summary(res) -> None:
    d = res.to_dict()
    choice = res.settings.get("plant_choice", {})
    how = f" ({choice['reason']})" if choice.get("asked") == "auto" else ""
    print(f"{d['recording']['name']}: plant {res.plant}{how}, actuator {res.actuator}")
    for note in d["recording"].get("notes") or []:
        print(f"  read: {note}")
    reps = d["recording"].get("repairs") or []
    if reps:
        print(f"  recording repaired ({len(reps)}): " + "; ".join(reps[:3]) + ("; ..." if len(reps) > 3 else ""))
    print(f"  effects: {', '.join(d['effects']) or 'none'}")
    print(f"  RMSE base {d['base']['rmse']:.4g} -> final {d['final']['rmse']:.4g} "
          f"(fit {d['base']['fit_percent']:.1f} % -> {d['final']['fit_percent']:.1f} %)")
    h = d["holdout"]
    if h["base_rmse"] is not None:
        print(f"  held-out RMSE base {_g(h['base_rmse'])} -> final {_g(h['final_rmse'])}")
    if d["validation"]:
        v = d["validation"]
        print(f"  validation on {v['recording']}: RMSE base {_g(v['base_rmse'])} -> final "
              f"{_g(v['final_rmse'])} (initial state refitted); {_g(v['base_rmse_same_state'])} "
              f"-> {_g(v['final_rmse_same_state'])} from the fitted recording's initial state")
    s = d["stiction"]
    if s.get("verdict_source") == "stem":
        st = next(e for e in s["evidence"] if e["method"] == "stem")["details"]
        print(f"  valve friction: {'present' if s.get('present') else 'not significant'} (read from the "
              f"recorded valve position: S = {st['S']:.4g}, J = {st['J']:.4g} of the stroke)")
    else:
        print(f"  valve friction: {'present' if s.get('present') else 'not significant'}"
              + (f" ({s['model']}: " + ", ".join(f"{k} = {v:.4g}" for k, v in s['parameters'].items()
                                              if isinstance(v, float)) + ")" if s.get("tested") else
                 " (not tested)"))
    stem = next((e for e in s.get("evidence") or [] if e["method"] == "stem"), None)
    if stem is not None and s.get("verdict_source") != "stem":
        print(f"  recorded valve position: {stem['reason']}")
    h = s.get("horch")
    if h:
        print(f"  Horch's cross-correlation test (model-free, not part of the verdict): {h['verdict']}"
              + ("" if h["phase_index"] is None else f" (phase index {h['phase_index']:.2f})"))
    if d["mismatch"]:
        r = d["mismatch"][0]
        print(f"  largest mismatch: {r['t_start']:g}-{r['t_end']:g} s "
              f"({100 * r['share_sse']:.0f} % of the squared error); {len(d['mismatch'])} region(s)")
    c = d.get("cause")
    if c and c.get("oscillating"):
        print("  cause of the oscillation: " + c["summary"])
        print("  action: " + c["action"])
    for p in d["explanation"]:
        print("  - " + p)
