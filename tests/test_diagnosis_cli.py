"""Tests of ``valve-gym diagnose``: end to end on a small CSV, and every bad input."""
from __future__ import annotations

import csv
import json
import os

import numpy as np
import pytest

from valve_gym.diagnosis.cli import main
from valve_gym.diagnosis.synthetic import make_recording, write_csv


@pytest.fixture(scope="module")
def small_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    p = d / "loop.csv"
    write_csv(make_recording("overflow", seed=31, n=400), p)
    return str(p)


def run(argv, capsys):
    rc = main(argv)
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "Traceback" not in out
    return rc, out, err


@pytest.mark.slow
def test_end_to_end(small_csv, tmp_path, capsys):
    js = tmp_path / "out.json"
    rep = tmp_path / "rep"
    rc, out, err = run([small_csv, "--op-range", "0,100", "--plant", "tank",
                        "--effects", "overflow,leak", "--effort", "fast", "--jobs", "1",
                        "--json", str(js), "--report", str(rep), "--validate", small_csv,
                        "--quiet"], capsys)
    assert rc == 0, err
    assert "effects:" in out
    d = json.loads(js.read_text())
    for k in ("effects", "base", "final", "mismatch", "stiction", "validation"):
        assert k in d
    assert {"rmse", "fit_percent", "params"} <= set(d["base"])
    assert {"base_rmse", "final_rmse"} <= set(d["validation"])
    assert {"report.md", "overlay.png", "residuals.png", "acf.png", "diagnosis.json",
            "validation.png"} <= set(os.listdir(rep))
    assert not [f for f in os.listdir(rep) if f.endswith(".tmp")]


@pytest.mark.slow
def test_folder(small_csv, tmp_path, capsys):
    """A folder runs through the batch engine: every loop screened, a summary table, the loops in the JSON."""
    folder = tmp_path / "recs"
    folder.mkdir()
    for i in range(2):
        write_csv(make_recording("none", seed=40 + i, n=300), folder / f"r{i}.csv")
    js = tmp_path / "all.json"
    rc, out, err = run([str(folder), "--op-range", "0,100", "--effects", "none",
                        "--effort", "fast", "--jobs", "2", "--json", str(js), "--full"], capsys)
    assert rc == 0, err
    assert "| r0 | ok | full |" in out and "| r1 | ok | full |" in out
    assert "2/2 done, 0 failed" in err
    d = json.loads(js.read_text())
    assert [r["loop"] for r in d["loops"]] == ["r0", "r1"] and all(r["status"] == "ok" for r in d["loops"])


def test_help(capsys):
    rc = main(["--help"])
    out, _ = capsys.readouterr()
    assert rc == 0 and "--op-range" in out


def _write(path, header, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    return str(path)


def _rows(n=200, const_pv=False, nan_block=None):
    t = np.arange(n)
    op = 50 + 10 * np.sign(np.sin(t / 15))
    pv = np.full(n, 1.0) if const_pv else 1 + 0.01 * np.cumsum(op - 50) / 50
    rows = [[f"{a}", f"{b}", f"{c}"] for a, b, c in zip(t, op, pv)]
    if nan_block:
        for i in range(*nan_block):
            rows[i][2] = "nan"
    return rows


@pytest.mark.parametrize("case, argv_extra, message", [
    ("missing", [], "no such file"),
    ("columns", ["--columns", "t=time_s,op=OUT,pv=LEVEL"], "column"),
    ("oprange", ["--op-range", "100,0"], "LO >= HI"),
    ("oprange_text", ["--op-range", "zero,100"], "non-number"),
    ("short", [], "samples"),
    ("constant", [], "constant"),
    ("nan", ["--gaps", "error"], "missing"),          # a long gap is kept out by default; asked to stop
    ("effects", ["--effects", "friction"], "unknown effect"),
    ("holdout", ["--holdout", "0.95"], "--holdout"),
    ("plant", ["--plant", "boiler"], "invalid choice"),
    ("jobs", ["--jobs", "two"], "--jobs"),
    ("json_dir", ["--json", "/nonexistent_dir_xyz/out.json"], "does not exist"),
])
def test_bad_input_exit_2(tmp_path, capsys, case, argv_extra, message):
    good = _write(tmp_path / "good.csv", ["t", "OP", "PV"], _rows())
    path = {
        "missing": str(tmp_path / "nope.csv"),
        "short": _write(tmp_path / "short.csv", ["t", "OP", "PV"], _rows(20)),
        "constant": _write(tmp_path / "const.csv", ["t", "OP", "PV"], _rows(const_pv=True)),
        "nan": _write(tmp_path / "nan.csv", ["t", "OP", "PV"], _rows(nan_block=(50, 80))),
    }.get(case, good)
    extra = list(argv_extra)
    if "--op-range" not in extra:
        extra += ["--op-range", "0,100"]
    rc, out, err = run([path, *extra, "--quiet"], capsys)
    assert rc == 2
    assert "error" in err.lower()
    assert message.lower() in err.lower(), err


@pytest.mark.slow
def test_fleet_mode(tmp_path, capsys):
    from valve_gym.fleet.simulate import simulate_loop
    folder = tmp_path / "recs"
    folder.mkdir()
    write_csv(simulate_loop("disturbance", seed=2, n=600).recording, folder / "osc.csv")
    write_csv(simulate_loop("healthy", seed=0, n=300).recording, folder / "quiet.csv")
    (folder / "bad.csv").write_text("t_s,OP,PV\n0,50,1\n")
    out = tmp_path / "out"
    js = tmp_path / "fleet.json"
    argv = [str(folder), "--out", str(out), "--op-range", "0,100", "--effects", "none", "--effort", "fast",
            "--jobs", "1", "--json", str(js), "--top", "1"]
    rc, stdout, err = run(argv, capsys)
    assert rc == 2, err                       # a loop's data could not be used: listed, the others done
    assert "3 loops: 2 analysed, 1 failed; 3 run now" in stdout and "bad (failed)" in stdout and "osc:" in stdout
    assert "3/3 done, 1 failed" in err
    assert {"loops", "loops.parquet", "loops.csv", "worklist.md", "worklist.html"} <= set(os.listdir(out))
    assert sorted(os.listdir(out / "loops")) == ["bad.json", "osc.json", "quiet.json"]
    d = json.loads(js.read_text())
    assert [r["loop"] for r in d["loops"]] == ["bad", "osc", "quiet"] and d["interrupted"] is False
    rc, stdout, err = run(argv[:-4] + ["--quiet"], capsys)       # resumed: nothing left to do
    assert rc == 2 and "0 run now, 3 kept from an earlier run, 0 left" in stdout and err == ""


@pytest.mark.parametrize("argv_extra, message", [
    (["--top", "3"], "--out"),
    (["--out", "OUT", "--validate", "X.csv"], "--validate"),
    (["--out", "OUT", "--max-loops", "0"], "--max-loops"),
])
def test_fleet_bad_usage(tmp_path, capsys, argv_extra, message):
    argv = [str(tmp_path)] + [str(tmp_path / a) if a == "OUT" else a for a in argv_extra] + ["--quiet"]
    rc, out, err = run(argv, capsys)
    assert rc == 2 and message in err


@pytest.mark.slow
def test_report_states_the_repairs_of_the_data(small_csv, tmp_path, capsys):
    """A short gap of non-finite values is repaired, and the report says so (not only the JSON)."""
    rows = list(csv.reader(open(small_csv)))
    header, body = rows[0], rows[1:]
    col = header.index("pv") if "pv" in header else 2
    for r in body[100:102]:
        r[col] = "inf"
    p = tmp_path / "gap.csv"
    with open(p, "w", newline="") as f:
        csv.writer(f).writerows([header] + body)
    rep = tmp_path / "rep"
    rc, out, err = run([str(p), "--op-range", "0,100", "--plant", "tank", "--effects", "none",
                        "--effort", "fast", "--jobs", "1", "--report", str(rep), "--quiet"], capsys)
    assert rc == 0, err
    d = json.loads((rep / "diagnosis.json").read_text())
    assert d["recording"]["repairs"], "the inf values must be repaired and recorded"
    md = (rep / "report.md").read_text()
    assert "What was done to the data before fitting" in md
    assert d["recording"]["repairs"][0] in md


def test_ray_without_its_extra_names_the_extra(tmp_path, capsys, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "ray" else real(name, *a))
    rec = tmp_path / "recs"
    rec.mkdir()
    (rec / "loop.csv").write_text("t,op,pv\n0,0.5,1.0\n1,0.5,1.0\n")
    assert main([str(rec), "--out", str(tmp_path / "out"), "--ray"]) == 2
    err = capsys.readouterr().err
    assert '--ray and --address run the loops on Ray, which needs ray: pip install "valve_gym[fleet]"' in err
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_folder_options_with_one_recording_are_refused(small_csv, capsys):
    rc, out, err = run([small_csv, "--address", "auto", "--quiet"], capsys)
    assert rc == 2 and "give a folder" in err
