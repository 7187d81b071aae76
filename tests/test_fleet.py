"""Tests of the batch engine (valve_gym.fleet): sources, screening, actions, and runs on Ray (one session)."""
from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np
import pandas as pd
import pytest

from valve_gym.diagnosis.synthetic import write_csv
from valve_gym.fleet import (
    FleetSettings,
    LoopResult,
    discover_loops,
    load_loop,
    recommend,
    resample_loop,
    run_fleet,
    stiction_numbers,
)
from valve_gym.fleet.actions import evidence_weight, score
from valve_gym.fleet.simulate import simulate_loop
from valve_gym.oscillation import detect_oscillation

SETTINGS = FleetSettings(op_range=(0.0, 100.0), effort="fast", candidates=())


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Five loops (two oscillating) and one recording too short to use."""
    d = tmp_path_factory.mktemp("fleet") / "recs"
    d.mkdir()
    for i, (kind, seed) in enumerate((("healthy", 0), ("disturbance", 2), ("healthy", 2), ("severe", 3),
                                      ("healthy", 4))):
        write_csv(simulate_loop(kind, seed=seed, n=600).recording, d / f"loop{i}.csv")
    (d / "broken.csv").write_text("t_s,OP,PV\n0,50,1.0\n1,50,1.0\n")
    return str(d)


# --------------------------------------------------------------------------- no Ray
def test_resample_irregular_with_gap():
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.8, 1.2, 300))
    t = np.concatenate([t[:100], t[100:] + 30.0])          # a 30 s hole
    pv = np.sin(t / 10)
    op = np.full(t.size, 0.5)
    grid, vals, gaps, notes = resample_loop(t, {"pv": pv, "op": op}, max_gap=5)
    assert np.allclose(np.diff(grid), np.median(np.diff(t[:100])), rtol=0.2)
    assert np.ptp(np.diff(grid)) < 1e-9                     # uniform
    assert len(gaps) == 2 and {g.role for g in gaps} == {"pv", "op"}
    assert gaps[0].seconds > 30
    assert grid[0] > t[100]                                 # the longer stretch (after the hole) kept
    assert np.allclose(vals["pv"], np.sin(grid / 10), atol=0.02)
    assert any("irregular" in n for n in notes) and any("gap" in n for n in notes)


def _wide_frame(n=600, seed=0):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5, 1.5, n))
    df = pd.DataFrame({"timestamp": pd.Timestamp("2024-01-01") + pd.to_timedelta(t, unit="s")})
    for tag, k in (("FIC101", 0), ("LIC202", 1)):
        loop = simulate_loop("disturbance" if k else "healthy", seed=seed + k, n=n).recording
        df[f"{tag}.PV"] = loop.pv
        df[f"{tag}.OP"] = 100 * loop.op
        df[f"{tag}.SP"] = loop.sp
    df["LIC202.MODE"] = ["MAN" if i < 50 else "AUTO" for i in range(n)]
    df.loc[::7, "FIC101.OP"] = np.nan                     # OP stored less often than PV
    df["TI303.PV"] = 1.0                                    # a tag without OP
    return df


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_wide_export_split_and_load(tmp_path, fmt):
    df = _wide_frame()
    p = tmp_path / f"export.{fmt}"
    df.to_csv(p, index=False) if fmt == "csv" else df.to_parquet(p, index=False)
    srcs = discover_loops(str(p))
    assert [s.name for s in srcs] == ["FIC101", "LIC202", "TI303"]
    assert [s.kind for s in srcs] == ["wide", "wide", "bad"] and "TI303.OP" in srcs[2].problem
    a = load_loop(srcs[0], op_range=(0, 100))
    b = load_loop(srcs[1], op_range=(0, 100))
    assert np.ptp(np.diff(a.recording.t)) < 1e-9 and 0.8 < a.recording.dt < 1.2
    assert any("resampled" in n for n in a.notes)
    assert any("MODE manual" in n for n in b.notes) and len(b.recording) < len(a.recording)
    assert a.recording.start is not None and a.recording.start.startswith("2024-01-01")
    c = load_loop(srcs[0])                                   # OP in percent without a range: read from the values
    assert c.recording.op_range == (0.0, 100.0) and any("OP read in percent" in n for n in c.notes)
    np.testing.assert_allclose(c.recording.op, a.recording.op)


def test_screen_rule_of_the_oscillation_detector():
    t = np.arange(1500.0)
    rng = np.random.default_rng(1)
    sine = detect_oscillation(0.1 * np.sin(2 * np.pi * t / 80) + 0.02 * rng.normal(size=t.size), 1.0, "screen")
    assert sine.present and abs(sine.period_s - 80) < 3 and abs(sine.amplitude - 0.1) < 0.01
    noise = detect_oscillation(rng.normal(size=t.size), 1.0, "screen")
    walk = detect_oscillation(np.cumsum(rng.normal(size=t.size)), 1.0, "screen")
    assert not noise.present and not walk.present and noise.amplitude == 0.0


def test_actions_table():
    assert recommend("failed", "bad file", False, "not tested", math.nan, math.nan, math.nan)[0] == "data"
    assert recommend("ok", "", False, "no", 0.1, math.nan, 0.0)[0] == "quiet"
    assert recommend("ok", "", False, "yes", 0.9, 0.03, 0.0)[0] == "inspect"
    assert recommend("ok", "", True, "yes", 0.9, 0.08, 0.03)[0] == "repair"
    name, text = recommend("ok", "", True, "yes", 0.9, 0.02, 0.03)
    assert name == "compensate" and "knocker" in text and "2.0 %" in text
    assert recommend("ok", "", True, "no", 0.1, math.nan, 0.03)[0] == "retune"
    assert recommend("ok", "", True, "undecided", 0.5, math.nan, 0.03)[0] == "undecided"
    assert recommend("ok", "", True, "not tested", 0.9, math.nan, 0.07)[0] == "repair"   # OP swing stands in
    assert evidence_weight(0.8, "no", 0.1) == (0.8, "calibrated probability")
    assert evidence_weight(math.nan, "yes", 0.5)[0] == pytest.approx(0.75)
    assert evidence_weight(math.nan, "not tested", math.nan)[0] == 0.5
    assert score(0.5, 0.04, True) == pytest.approx(2.0) and score(1.0, 0.04, False) == 0.0


class _Fake:
    def __init__(self, stiction, **kw):
        self.stiction = stiction
        for k, v in kw.items():
            setattr(self, k, v)


def test_stiction_numbers_reads_what_is_reported():
    a = stiction_numbers(_Fake({"present": True, "tested": True, "parameters": {"S": 0.03, "J": 0.01}}))
    assert (a.verdict, a.S, a.J) == ("yes", 0.03, 0.01) and math.isnan(a.p) and "probability" in a.note
    b = stiction_numbers(_Fake({"present": False, "verdict": "undecided", "probability": 0.55,
                                "S": {"value": 0.02, "interval": [0.01, 0.03]}, "J": {"value": 0.0}}))
    assert (b.verdict, b.S, b.J, b.p, b.note) == ("undecided", 0.02, 0.0, 0.55, "")
    c = stiction_numbers(_Fake({"present": False, "tested": False, "parameters": {}}))
    assert c.verdict == "not tested" and math.isnan(c.S)


def test_result_json_round_trip():
    r = LoopResult("L1", "ok", "m", S=0.02, notes=("a",), oscillating=True)
    back = LoopResult.from_dict(json.loads(json.dumps(r.to_dict(), allow_nan=False)))
    assert back.S == 0.02 and math.isnan(back.J) and back.notes == ("a",) and back.oscillating


def test_missing_path_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="no such file"):
        discover_loops(str(tmp_path / "nope"))
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no .csv or .parquet"):
        discover_loops(str(tmp_path / "empty"))


# --------------------------------------------------------------------------- on Ray
def _table(out):
    df = pd.read_parquet(os.path.join(out, "loops.parquet"))
    return df.drop(columns=["seconds", "cpu_seconds"]).sort_values("loop").reset_index(drop=True)


@pytest.mark.slow
def test_interrupted_and_resumed_equals_uninterrupted(ray_session, folder, tmp_path):
    whole = run_fleet(folder, str(tmp_path / "whole"), SETTINGS, stream=None, engine="ray", top=2)
    assert whole.n_loops == 6 and whole.done == 6 and not whole.interrupted and whole.remaining == 0
    out = str(tmp_path / "parts")
    first = run_fleet(folder, out, SETTINGS, max_loops=2, stream=None, engine="ray", top=0)
    assert first.done == 2 and first.remaining == 4 and len(pd.read_csv(os.path.join(out, "loops.csv"))) == 2
    # a worker killed while writing leaves at most a temporary file; a damaged result is recomputed
    loops = sorted(os.listdir(os.path.join(out, "loops")))
    with open(os.path.join(out, "loops", "." + loops[0] + ".123.tmp"), "w") as f:
        f.write("{")
    with open(os.path.join(out, "loops", loops[1]), "w") as f:
        f.write("{\"loop\": ")

    def ctrl_c(res):                                                     # Ctrl-C after one more loop
        raise KeyboardInterrupt

    stopped = run_fleet(folder, out, SETTINGS, stream=None, engine="ray", top=0, on_result=ctrl_c)
    assert stopped.interrupted and stopped.done == 1 and stopped.remaining == 4
    assert len(pd.read_csv(os.path.join(out, "loops.csv"))) == 2                   # 1 kept + 1 new
    second = run_fleet(folder, out, SETTINGS, stream=None, engine="ray", top=2)
    assert second.resumed == 2 and second.done == 4 and second.remaining == 0
    a, b = _table(os.path.join(tmp_path, "whole")), _table(out)
    assert len(b) == 6 and b["loop"].is_unique
    pd.testing.assert_frame_equal(a, b)
    third = run_fleet(folder, out, SETTINGS, stream=None, engine="ray", top=0)          # nothing left to do
    assert third.done == 0 and third.resumed == 6
    changed = run_fleet(folder, out, FleetSettings(op_range=(0.0, 100.0), effort="fast", candidates=(),
                                                   seed=1), stream=None, engine="ray", top=0, max_loops=1)
    assert changed.done == 1                                              # other settings: not reused
    fast = run_fleet(folder, out, dataclasses.replace(SETTINGS, search="fast"), stream=None, engine="ray", top=0,
                     max_loops=1)
    assert fast.done == 1                                                 # the fast search: not reused either
    lag = run_fleet(folder, out, dataclasses.replace(SETTINGS, op_lag=1), stream=None, engine="ray", top=0,
                    max_loops=1)
    assert lag.done == 1                                                  # another OP/PV pairing: not reused
    assert '"op_lag": "auto"' in SETTINGS.hash_text()
    assert '"op_lag": 1' in dataclasses.replace(SETTINGS, op_lag=1).hash_text()
    assert "op_lag" not in dataclasses.replace(SETTINGS, op_lag=0).hash_text()   # the old default's keys stay


@pytest.mark.slow
def test_bad_recording_is_a_failed_row(ray_session, folder, tmp_path):
    out = str(tmp_path / "o")
    run = run_fleet(folder, out, SETTINGS, stream=None, engine="ray", top=3)
    df = pd.read_csv(os.path.join(out, "loops.csv"))
    assert list(df.columns[:11]) == ["loop", "status", "message", "stiction", "S", "J", "effects", "rmse_base",
                                     "rmse_final", "oscillation", "seconds"]
    bad = df[df["loop"] == "broken"].iloc[0]
    assert bad["status"] == "failed" and "samples" in bad["message"]
    good = df[df["loop"] != "broken"]
    assert (good["status"] == "ok").all() and run.failed == 1
    osc = good[good["oscillating"]]
    assert len(osc) == 2 and (osc["stage"] == "full").all() and osc["effects"].notna().all()
    assert (good[~good["oscillating"]]["stage"] == "screen").all()
    assert np.isfinite(osc["rmse_final"]).all() and (osc["score"] > 0).all()
    d = json.load(open(os.path.join(out, "loops", "broken.json")))
    assert d["status"] == "failed" and d["key"]
    md = open(os.path.join(out, "worklist.md")).read()
    html = open(os.path.join(out, "worklist.html")).read()
    assert "| 1 |" in md and "broken" in md and "How the ranking works" in md
    assert html.count("data:image/png;base64,") == 2 * len(osc)
    assert not [f for f in os.listdir(os.path.join(out, "loops")) if f.endswith(".tmp")]


def test_a_loop_a_node_cannot_see_is_analysed_from_the_bytes_its_task_carries(folder, tmp_path):
    """On a cluster a node need not see the files of the machine that runs the fleet: the task carries the
    file's bytes (a node without the files failed every loop with 'file not found' before)."""
    from valve_gym.fleet.analyse import analyse_loop
    from valve_gym.fleet.runner import analyse_shipped

    srcs = {s.name: s for s in discover_loops(folder)}
    elsewhere = tmp_path / "on_another_machine"

    def moved(src):
        return dataclasses.replace(src, path=str(elsewhere / os.path.basename(src.path)))

    def data(src):
        with open(src.path, "rb") as f:
            return f.read()

    good, broken = srcs["loop0"], srcs["broken"]
    assert analyse_loop(moved(good), SETTINGS, "k").status == "failed"          # without its bytes: not found
    here, shipped = analyse_loop(good, SETTINGS, "k"), analyse_shipped(moved(good), data(good), SETTINGS, "k")
    assert shipped.status == "ok" and shipped.source == moved(good).path
    differ = [f.name for f in dataclasses.fields(here) if f.name not in {"seconds", "cpu_seconds", "source"}
              and repr(getattr(shipped, f.name)) != repr(getattr(here, f.name))]          # repr: nan == nan
    assert not differ
    bad = analyse_shipped(moved(broken), data(broken), SETTINGS, "k")
    assert bad.status == "failed" and "samples" in bad.message
    assert moved(broken).path in bad.message and "valve_gym-loop-" not in bad.message    # named as sent
    assert not [d for d in os.listdir(tmp_path) if d.startswith("valve_gym-loop-")]


def test_a_file_is_put_once_for_its_loops_in_flight_and_dropped_after_the_last(ray_session, tmp_path):
    from valve_gym.fleet.runner import _Shipper

    p = tmp_path / "export.parquet"
    _wide_frame(n=200, seed=1).to_parquet(p, index=False)
    a, b, bad = discover_loops(str(p))
    ship = _Shipper(True)
    ra, rb = ship.ref(a), ship.ref(b)
    assert ra is rb and ship.refs[str(p)][1] == 2 and ship.ref(bad) is None     # one object for the file
    assert ray_session.get(ra) == p.read_bytes()
    ship.done(a)
    assert ship.refs[str(p)][1] == 1
    ship.done(b)
    assert not ship.refs                                                         # the last loop back: dropped
    assert _Shipper(False).ref(a) is None                                        # this process's own Ray


def test_a_cluster_that_cannot_run_the_tasks_is_refused_before_any_loop(ray_session, monkeypatch):
    """The probe task runs where the loops' tasks run: valve_gym must import there, in the same version."""
    import re

    import valve_gym
    from valve_gym._version import __version__ as installed
    from valve_gym.fleet.runner import _probe_cluster

    _probe_cluster("here", {})                              # this session's workers import valve_gym: fine
    monkeypatch.setattr(valve_gym, "__version__", "9.9.9")   # as if the nodes ran another release
    with pytest.raises(ValueError, match=rf"runs valve_gym {re.escape(installed)}, this process 9\.9\.9: install"):
        _probe_cluster("here", {})


def test_a_task_error_is_read_from_its_last_line_without_colour_codes():
    from valve_gym.fleet.runner import task_error_cause

    raw = ("\x1b[36mray::task()\x1b[39m (pid=1, ip=10.0.0.2)\nRuntimeError: The remote function failed to "
           "import on the worker.\n\n\x1b[36mray::task()\x1b[39m (pid=1)\n               ^^^^^^^^^^^^\n"
           "ModuleNotFoundError: No module named 'valve_gym'")
    assert task_error_cause(RuntimeError(raw)) == "ModuleNotFoundError: No module named 'valve_gym'"
    assert task_error_cause(RuntimeError("")) == "RuntimeError"


def test_wide_export_fleet(ray_session, tmp_path):
    p = tmp_path / "export.parquet"
    _wide_frame(n=500, seed=3).to_parquet(p, index=False)
    run = run_fleet(str(p), str(tmp_path / "o"), SETTINGS, stream=None, engine="ray", top=1)
    rows = {r.loop: r for r in run.results}
    assert set(rows) == {"FIC101", "LIC202", "TI303"}
    assert rows["TI303"].status == "failed" and "TI303.OP" in rows["TI303"].message
    assert rows["FIC101"].status == "ok" and rows["FIC101"].tag == "FIC101"
    assert rows["LIC202"].status == "ok" and rows["LIC202"].oscillating
    assert any("MODE manual" in n for n in rows["LIC202"].notes)


def test_csv_with_a_long_gap_keeps_the_longest_stretch(tmp_path):
    t = np.arange(400.0)
    rows = ["t_s,OP,PV"] + [f"{a},{50 + 10 * np.sin(a / 20)},{1 + 0.1 * np.sin(a / 20 - 0.5)}" for a in t]
    (tmp_path / "g.csv").write_text("\n".join(rows[:101] + rows[121:]))          # 20 samples missing
    loop = load_loop(discover_loops(str(tmp_path))[0], op_range=(0, 100))
    assert len(loop.gaps) == 1 and len(loop.recording) == 280
    assert any("gap" in n for n in loop.notes)


def test_check_address_refuses_at_once_what_cannot_be_a_cluster():
    from valve_gym.fleet.runner import check_address
    check_address(None)
    check_address("auto")                                   # Ray finds a local cluster itself
    with pytest.raises(ValueError, match="no Ray cluster answers there.*ray start --head"):
        check_address("127.0.0.1:9")
    with pytest.raises(ValueError, match="HOST:PORT"):
        check_address("garbage")
    # a Ray Client address is checked as well (Ray would wait about 30 s, then blame the connection)
    with pytest.raises(ValueError, match="no Ray Client server answers there"):
        check_address("ray://127.0.0.1:9")
    with pytest.raises(ValueError, match="HOST:PORT"):
        check_address("ray://127.0.0.1:port")


@pytest.mark.slow
def test_in_process_ray_ignores_a_cluster_named_in_the_environment(folder, tmp_path):
    """``RAY_ADDRESS`` (or a cluster started with ``ray start`` on this machine) must not capture the
    default in-process run: plain ``ray.init(num_cpus=...)`` would join it and refuse ``num_cpus``."""
    import shutil
    import subprocess
    import sys
    recs, out = tmp_path / "recs", tmp_path / "fleet"
    recs.mkdir()
    for name in ("loop0.csv", "loop1.csv"):
        shutil.copy(os.path.join(folder, name), recs / name)
    env = dict(os.environ, RAY_ADDRESS="127.0.0.1:9")      # nothing listens there
    cmd = [sys.executable, "-m", "valve_gym.cli", "diagnose", str(recs), "--op-range", "0,100", "--effects", "none",
           "--effort", "fast", "--jobs", "1", "--quiet", "--out", str(out), "--ray"]
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=240)
    assert p.returncode == 0, (p.stdout + p.stderr)[-2000:]
    assert len(list((out / "loops").glob("*.json"))) == 2
