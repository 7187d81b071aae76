"""Every flag of ``valve-gym diagnose --help``, run once: it does what the help says.

Exit codes (issue: a truthful interface): 0 success, 1 failure of the work,
2 bad usage / bad input.  The flags are read from the help text itself, so a
flag added without a case here fails :func:`test_every_help_flag_has_a_case`.

Most cases call :func:`valve_gym.diagnosis.cli.main` in this process on a
300-sample recording with ``--effects none --effort fast`` (about a second
each); the real console script is run once in a subprocess for the exit codes,
and fleet mode (Ray) once in a subprocess.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from valve_gym.diagnosis import cli
from valve_gym.diagnosis.synthetic import make_recording, write_csv

pytestmark = pytest.mark.slow   # end-to-end runs of several seconds each: outside the fast subset

FAST = ["--effects", "none", "--effort", "fast", "--jobs", "1", "--quiet"]


@pytest.fixture(scope="module")
def rec_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli_flags")
    write_csv(make_recording("none", seed=4, n=300), d / "loop.csv")
    write_csv(make_recording("none", seed=4, n=300), d / "other.csv")
    return d


def run(argv, capsys):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def run_json(rec_dir, tmp_path, capsys, *flags, path=None):
    out_json = tmp_path / "out.json"
    code, out, err = run([path or rec_dir / "loop.csv", "--op-range", "0,100", *FAST, "--json", out_json,
                          *flags], capsys)
    assert code == 0, err
    return json.loads(out_json.read_text()), out, err


# --------------------------------------------------------------------------
# the list of flags
# --------------------------------------------------------------------------

CASES = {"-h", "--help", "--columns", "--op-range", "--mv-range", "--max-gap", "--gaps",
         "--plant", "--actuator", "--validate", "--validate-columns", "--dt", "--holdout",
         "--json", "--report", "--effects", "--jobs", "--effort", "--search", "--op-lag", "--seed", "--quiet", "--out",
         "--address", "--ray", "--full", "--max-loops", "--top", "--dayfirst", "--monthfirst", "--time-unit"}


def test_every_help_flag_has_a_case(capsys):
    code, out, _ = run(["--help"], capsys)
    assert code == 0 and out.startswith("usage: valve-gym diagnose")
    flags = set(re.findall(r"(?<![\w-])(--?[a-z][\w-]*)", out.split("options:", 1)[1]))
    assert flags == CASES, f"flags without a case: {flags - CASES}; cases without a flag: {CASES - flags}"


def test_help_exit_code_of_console_script():
    exe = Path(sys.executable).with_name("valve-gym")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "valve_gym.cli"]
    r = subprocess.run(cmd + ["diagnose", "--help"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "--op-range" in r.stdout
    r = subprocess.run(cmd + ["diagnose", "--plant", "nope", "x.csv"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "--plant" in r.stderr


# --------------------------------------------------------------------------
# one case per flag
# --------------------------------------------------------------------------


def test_columns(tmp_path, capsys):
    rec = make_recording("none", seed=4, n=300)
    p = tmp_path / "odd.csv"
    p.write_text("time,valve_cmd,lvl\n" + "".join(f"{a},{100 * b},{c}\n" for a, b, c in zip(rec.t, rec.op, rec.pv)))
    code, _, err = run([p, "--op-range", "0,100", *FAST], capsys)
    assert code == 2 and "--columns op=NAME" in err and "Traceback" not in err
    d, _, _ = run_json(None, tmp_path, capsys, "--columns", "t=time,op=valve_cmd,pv=lvl", path=p)
    assert d["recording"]["columns"] == {"t": "time", "op": "valve_cmd", "pv": "lvl"}
    code, _, err = run([p, "--op-range", "0,100", "--columns", "t=time,op", *FAST], capsys)
    assert code == 2 and "no '='" in err


def test_op_range(rec_dir, tmp_path, capsys):
    code, out, err = run([rec_dir / "loop.csv", *FAST], capsys)       # percent, read from the values
    assert code == 0 and "read: OP read in percent" in out, err
    d, _, _ = run_json(rec_dir, tmp_path, capsys)
    assert d["recording"]["op_range"] == [0.0, 100.0]
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "5,5", *FAST], capsys)
    assert code == 2 and "LO >= HI" in err


def test_mv_range(rec_dir, capsys):
    """A bad range is refused; reading a position in its own range: tests/test_stem.py."""
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--mv-range", "5,5", *FAST], capsys)
    assert code == 2 and "LO >= HI" in err
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--mv-range", "abc", *FAST], capsys)
    assert code == 2 and "Traceback" not in err


def test_max_gap_and_gaps(rec_dir, tmp_path, capsys):
    """A gap longer than --max-gap is refused with the flags that would accept it; they do."""
    lines = (rec_dir / "loop.csv").read_text().splitlines()
    holed = [lines[0]] + [",".join(c if j == 0 or k not in range(100, 108) else "" for j, c in
                                   enumerate(row.split(","))) for k, row in enumerate(lines[1:])]
    p = tmp_path / "holed.csv"
    p.write_text("\n".join(holed) + "\n")                  # op, pv, sp blank for 8 samples
    code, _, err = run([p, "--op-range", "0,100", "--gaps", "error", *FAST], capsys)
    assert code == 2 and "--max-gap" in err and "--gaps longest" in err
    d, out, _ = run_json(rec_dir, tmp_path, capsys, "--max-gap", "10", path=p)
    assert d["recording"]["n"] == 300 and "by linear interpolation" in d["recording"]["repairs"][0]
    assert "recording repaired (3): filled 8 missing value(s)" in out          # the console says so too
    for flags in (("--gaps", "longest"), ()):                       # the default keeps the longest stretch
        d, out, _ = run_json(rec_dir, tmp_path, capsys, *flags, path=p)
        assert d["recording"]["n"] == 192 and d["recording"]["repairs"][0].startswith("kept the longest stretch")
    code, _, err = run([p, "--op-range", "0,100", "--max-gap", "abc", *FAST], capsys)
    assert code == 2 and "--max-gap must be a whole number" in err
    code, out, err = run([p, "--op-range", "0,100", "--gaps", "error", "--out", tmp_path / "fl", *FAST], capsys)
    assert code == 2 and "holed (failed)" in out and "--gaps longest" in out       # the batch engine: a failed row


@pytest.mark.slow
def test_plant(rec_dir, tmp_path, capsys):
    d, out, _ = run_json(rec_dir, tmp_path, capsys, "--plant", "first_order")
    assert d["settings"]["plant"] == "first_order" and "plant first_order" in out
    code, _, err = run([rec_dir / "loop.csv", "--plant", "lake", *FAST], capsys)
    assert code == 2 and "invalid choice" in err
    # default auto: the loop tag in the file name picks the model, and the output says why; without a tag,
    # the data choose between a self-regulating and an integrating model (never the level tank)
    d, out, _ = run_json(rec_dir, tmp_path, capsys)
    assert d["settings"]["plant"] in ("first_order", "integrating") and d["settings"]["plant_choice"]["asked"] == "auto"
    assert d["settings"]["plant_choice"]["source"] == "data" and "ARX" in d["settings"]["plant_choice"]["reason"]
    tagged = tmp_path / "2411LIC10201_0005.csv"
    tagged.write_bytes((rec_dir / "loop.csv").read_bytes())
    d, out, _ = run_json(rec_dir, tmp_path, capsys, path=tagged)
    assert d["settings"]["plant"] == "integrating" and "LIC in the name" in out
    assert "integrates its inflow" in d["settings"]["plant_choice"]["reason"]
    d, out, _ = run_json(rec_dir, tmp_path, capsys, "--plant", "tank", path=tagged)     # named outright
    assert d["settings"]["plant"] == "tank" and "reason" not in d["settings"]["plant_choice"]
    # the PV column's name is read first: a level loop's file whose PV is the flow through its valve
    lines = (rec_dir / "loop.csv").read_text().splitlines()
    head = lines[0].split(",")
    head[head.index("PV")] = "flow_FT115"
    flow = tmp_path / "LIC-106.csv"
    flow.write_text("\n".join([",".join(head)] + lines[1:]) + "\n")
    d, out, _ = run_json(rec_dir, tmp_path, capsys, "--columns", "pv=flow_FT115", path=flow)
    assert d["settings"]["plant"] == "first_order" and "PV column 'flow_FT115'" in out


def test_actuator(rec_dir, tmp_path, capsys):
    d, out, _ = run_json(rec_dir, tmp_path, capsys, "--actuator", "pump")
    assert d["settings"]["actuator"] == "pump" and "actuator pump" in out


def test_validate(rec_dir, tmp_path, capsys):
    d, out, _ = run_json(rec_dir, tmp_path, capsys, "--validate", rec_dir / "other.csv")
    v = d["validation"]
    assert v["recording"] == "other" and np.isfinite(v["final_rmse"]) and "validation on other" in out
    code, _, err = run([rec_dir, "--op-range", "0,100", "--validate", rec_dir / "other.csv", *FAST], capsys)
    assert code == 2 and "single recording" in err
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--validate", tmp_path / "nope.csv", *FAST],
                       capsys)
    assert code == 2 and "nope.csv" in err


def test_dt_and_validate_columns(rec_dir, tmp_path, capsys):
    """A file without a time column, read with ``--dt``; its other record validated with ``--validate-columns``."""
    import pandas as pd

    df = pd.read_csv(rec_dir / "loop.csv").drop(columns="t_s")
    both = pd.DataFrame({"OP": df.OP, "PV": df.PV, "OP2": df.OP[::-1].to_numpy(), "PV2": df.PV[::-1].to_numpy()})
    path = tmp_path / "untimed.csv"
    both.to_csv(path, index=False)
    d, _, _ = run_json(rec_dir, tmp_path, capsys, "--dt", "1", "--validate", path, "--validate-columns",
                       "op=OP2,pv=PV2", path=path)
    assert d["recording"]["dt"] == 1.0 and d["recording"]["columns"]["t"] == "row x 1 s"
    assert d["validation"]["recording"] == "untimed" and np.isfinite(d["validation"]["final_rmse"])
    code, _, err = run([path, "--op-range", "0,100", *FAST], capsys)
    assert code == 2 and "--dt SECONDS" in err
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--validate-columns", "op=OP", *FAST], capsys)
    assert code == 2 and "give --validate too" in err


def test_holdout(rec_dir, tmp_path, capsys):
    d, _, _ = run_json(rec_dir, tmp_path, capsys, "--holdout", "0.2")
    assert d["settings"]["holdout"] == 0.2 and d["holdout"]["n_fit"] == 240
    for bad in ("abc", "0.9"):
        code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--holdout", bad, *FAST], capsys)
        assert code == 2 and "--holdout" in err


def test_json(rec_dir, tmp_path, capsys):
    d, _, _ = run_json(rec_dir, tmp_path, capsys)
    assert {"effects", "base", "final", "stiction"} <= set(d) and np.isfinite(d["final"]["rmse"])
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", *FAST, "--json", tmp_path / "no" / "o.json"],
                       capsys)
    assert code == 2 and "does not exist" in err


def test_report(rec_dir, tmp_path, capsys):
    rep = tmp_path / "rep"
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", *FAST, "--report", rep], capsys)
    assert code == 0, err
    names = set(os.listdir(rep))
    assert {"report.md", "diagnosis.json", "overlay.png", "residuals.png"} <= names
    assert not [n for n in names if n.endswith(".tmp")]
    text = (rep / "report.md").read_text()
    assert "no loop tag" in text and "fitted and compared" in text
    assert "## Why the loop oscillates" in text


def test_effects(rec_dir, tmp_path, capsys):
    out_json = tmp_path / "o.json"
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--effort", "fast", "--jobs", "1", "--quiet",
                        "--effects", "leak,dead_time", "--json", out_json], capsys)
    assert code == 0, err
    d = json.loads(out_json.read_text())
    assert set(d["settings"]["candidates"]) == {"leak", "dead_time"}
    assert {c["effect"] for c in d["candidates"]} <= {"leak", "dead_time"}
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--effects", "bogus"], capsys)
    assert code == 2 and "unknown effect 'bogus'" in err


def test_jobs(rec_dir, tmp_path, capsys, monkeypatch):
    import importlib

    diag_mod = importlib.import_module("valve_gym.diagnosis.diagnose")
    seen = {}
    real = diag_mod.diagnose

    def spy(*a, **kw):
        seen["jobs"] = kw.get("jobs")
        return real(*a, **kw)

    monkeypatch.setattr(diag_mod, "diagnose", spy)
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--effects", "none", "--effort", "fast",
                        "--quiet", "--jobs", "2"], capsys)
    assert code == 0 and seen["jobs"] == 2, err
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--jobs", "0"], capsys)
    assert code == 2 and "--jobs" in err


def test_effort(rec_dir, tmp_path, capsys):
    d, _, _ = run_json(rec_dir, tmp_path, capsys, "--effort", "normal")
    assert d["settings"]["effort"] == "normal"
    code, _, err = run([rec_dir / "loop.csv", "--effort", "max"], capsys)
    assert code == 2 and "invalid choice" in err


def test_search(rec_dir, tmp_path, capsys):
    d, _, _ = run_json(rec_dir, tmp_path, capsys, "--search", "fast")
    assert d["settings"]["search"] == "fast"
    code, _, err = run([rec_dir / "loop.csv", "--search", "quick"], capsys)
    assert code == 2 and "invalid choice" in err


def test_op_lag(rec_dir, tmp_path, capsys):
    d, _, _ = run_json(rec_dir, tmp_path, capsys, "--op-lag", "1")
    assert d["settings"]["op_lag"] == 1 and d["recording"]["n"] == 299     # op[k-1] paired with pv[k]
    d, _, _ = run_json(rec_dir, tmp_path, capsys, "--op-lag", "auto")
    t = d["settings"]["op_lag_test"]
    assert t["tested"] and d["settings"]["op_lag"] == t["chosen"] in (0, 1)
    if t["method"] == "controller reaction":
        assert t["controller_reaction"]["op_lag"] == t["chosen"]
    else:
        assert t["controller_reaction"]["op_lag"] is None and set(t["rmse_fit_part"]) == {"0", "1"}
        assert (t["chosen"] == 1) == (t["delta_ic"] < -2.0)
    code, _, err = run([rec_dir / "loop.csv", "--op-lag", "2"], capsys)
    assert code == 2 and "invalid choice" in err


def test_seed(rec_dir, tmp_path, capsys):
    d, _, _ = run_json(rec_dir, tmp_path, capsys, "--seed", "3")
    assert d["settings"]["seed"] == 3
    code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", "--seed", "-1"], capsys)
    assert code == 2 and "--seed" in err


def test_quiet(rec_dir, capsys):
    base = [rec_dir / "loop.csv", "--op-range", "0,100", "--effects", "none", "--effort", "fast", "--jobs", "1"]
    code, out, err = run(base, capsys)
    assert code == 0 and "fitting the base model" in err
    code, out_q, err_q = run(base + ["--quiet"], capsys)
    assert code == 0 and err_q == "" and out_q == out


def test_folder_flags_need_a_folder(rec_dir, capsys):
    for flag in (["--address", "auto"], ["--ray"], ["--full"], ["--max-loops", "1"], ["--top", "-1"]):
        code, _, err = run([rec_dir / "loop.csv", "--op-range", "0,100", *flag], capsys)
        assert code == 2 and "give a folder" in err, flag


@pytest.mark.slow
def test_fleet_flags(tmp_path):
    """--out, --max-loops, --full, --top, --op-lag, --max-gap (and --address's local default) in one fleet run."""
    pytest.importorskip("ray")
    src = tmp_path / "loops"
    src.mkdir()
    for i, e in enumerate(("none", "slip_jump")):
        write_csv(make_recording(e, seed=4 + i, n=300), src / f"loop{i}.csv")
    for f in src.iterdir():         # op, pv, sp blank for 8 samples in each: bridged by --max-gap 10
        lines = f.read_text().splitlines()
        f.write_text("\n".join([lines[0]] + [",".join(
            c if j == 0 or k not in range(100, 108) else "" for j, c in enumerate(row.split(",")))
            for k, row in enumerate(lines[1:])]) + "\n")
    out = tmp_path / "fleet"
    exe = Path(sys.executable).with_name("valve-gym")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "valve_gym.cli"]
    r = subprocess.run(cmd + ["diagnose", str(src), "--out", str(out), "--op-range", "0,100", "--effects", "none",
                              "--effort", "fast", "--jobs", "1", "--full", "--top", "1", "--max-loops", "1",
                              "--op-lag", "1", "--max-gap", "10", "--quiet"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert len(os.listdir(out / "loops")) == 1  # --max-loops 1
    assert {"loops.csv", "loops.parquet", "worklist.md", "worklist.html"} <= set(os.listdir(out))
    import pandas as pd

    table = pd.read_csv(out / "loops.csv")
    assert list(table["stage"]) == ["full"]  # --full: diagnosed, not only screened
    assert list(table["n"]) == [300]  # --max-gap 10 bridged the 8-sample hole (the default keeps 192 samples)
    assert "1 left" in r.stdout


def test_folder_mode_keeps_good_results_past_a_bad_recording(rec_dir, tmp_path, capsys):
    folder = tmp_path / "mixed"
    folder.mkdir()
    (folder / "a_good.csv").write_bytes((rec_dir / "loop.csv").read_bytes())
    text = (rec_dir / "loop.csv").read_text().splitlines()
    text[40] = text[40].split(",")[0] + ",1e308,inf,x"  # line 41 broken: non-numeric set point
    (folder / "b_bad.csv").write_text("\n".join(text) + "\n")
    out_json = tmp_path / "all.json"
    code, out, err = run([folder, "--op-range", "0,100", *FAST, "--json", out_json], capsys)
    assert code == 2 and "Traceback" not in err
    d = json.loads(out_json.read_text())
    assert [(r["loop"], r["status"]) for r in d["loops"]] == [("a_good", "ok"), ("b_bad", "failed")]
    assert "b_bad.csv" in d["loops"][1]["message"] and "line(s) 41" in d["loops"][1]["message"]
    assert "| b_bad | failed |" in out and "| a_good | ok |" in out


def test_dayfirst_monthfirst_and_time_unit(tmp_path, capsys):
    """Dates that read both ways are asked about in one line; --dayfirst/--monthfirst and --time-unit decide."""
    rec = make_recording("none", seed=4, n=300)
    from datetime import datetime, timedelta
    days = [(datetime(2024, 2, 1) + timedelta(days=int(k))) for k in range(300)]
    p = tmp_path / "days.csv"          # daily samples from 1 February: 01/02/2024, 02/02/2024, ... (M/D reads too)
    p.write_text("time,OP,PV\n" + "".join(f"{d:%d/%m/%Y},{100 * b},{c}\n" for d, b, c in zip(days[:12], rec.op,
                                                                                           rec.pv)))
    code, _, err = run([p, *FAST], capsys)
    assert code == 2 and "--dayfirst or --monthfirst" in err and len(err.strip().splitlines()) == 1
    long_ = tmp_path / "days_long.csv"
    long_.write_text("time,OP,PV\n" + "".join(f"{d:%d/%m/%Y},{100 * b},{c}\n" for d, b, c in zip(days, rec.op,
                                                                                                rec.pv)))
    d, out, _ = run_json(None, tmp_path, capsys, "--dayfirst", path=long_)
    assert d["recording"]["dt"] == 86400.0 and "as given" in " ".join(d["recording"]["notes"])
    code, _, err = run([long_, "--monthfirst", *FAST], capsys)                 # 13/02/2024 cannot be M/D/Y
    assert code == 2 and "contradicts --monthfirst" in err
    ms = tmp_path / "ms.csv"
    ms.write_text("t,OP,PV\n" + "".join(f"{1720000000000 + 1000 * k},{100 * b},{c}\n"
                                        for k, (b, c) in enumerate(zip(rec.op, rec.pv))))
    d, _, _ = run_json(None, tmp_path, capsys, path=ms)
    assert d["recording"]["dt"] == 1.0 and "epoch milliseconds" in " ".join(d["recording"]["notes"])
    d, _, _ = run_json(None, tmp_path, capsys, "--time-unit", "s", path=ms)
    assert d["recording"]["dt"] == 1000.0
