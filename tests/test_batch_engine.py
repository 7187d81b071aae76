"""One batch engine: ``valve-gym diagnose DIR``, with or without ``--out``, runs valve_gym.fleet.run_fleet.

The same screening and the same verdicts either way; without Ray (and without pyarrow) by default.
"""
from __future__ import annotations

import builtins
import importlib
import importlib.util
import json
import math
import os

import numpy as np
import pytest

from valve_gym.diagnosis.cli import main
from valve_gym.diagnosis.synthetic import write_csv
from valve_gym.fleet.simulate import simulate_loop

FAST = ["--op-range", "0,100", "--effects", "none", "--effort", "fast", "--jobs", "1", "--quiet"]

#: What a loop's row says: the screen, the verdict of the full diagnosis and the action.
VERDICT_FIELDS = ("loop", "status", "stage", "oscillating", "regularity", "amplitude_op", "horch", "stiction",
                  "p_stiction", "S", "J", "effects", "rmse_base", "rmse_final", "cause", "action")


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    """An oscillating loop (diagnosed in full), a quiet one (screened only) and one too short to use."""
    d = tmp_path_factory.mktemp("batch") / "recs"
    d.mkdir()
    write_csv(simulate_loop("disturbance", seed=2, n=600).recording, d / "osc.csv")
    write_csv(simulate_loop("healthy", seed=0, n=300).recording, d / "quiet.csv")
    (d / "bad.csv").write_text("t_s,OP,PV\n0,50,1\n")
    return str(d)


def _loops(path) -> list[dict]:
    return json.loads(open(path).read())["loops"]


def _verdicts(loops: list[dict]) -> list[tuple]:
    return [tuple(repr(r.get(k)) for k in VERDICT_FIELDS) for r in loops]


def test_a_folder_gets_the_same_screening_and_verdicts_with_and_without_out(recs, tmp_path, capsys):
    rc = main([recs, *FAST, "--json", str(tmp_path / "a.json")])
    table = capsys.readouterr().out
    assert rc == 2                                    # a loop's data could not be used: listed, the others done
    assert rc == main([recs, *FAST, "--out", str(tmp_path / "fleet"), "--json", str(tmp_path / "b.json")])
    capsys.readouterr()
    a, b = _loops(tmp_path / "a.json"), _loops(tmp_path / "b.json")
    assert [r["loop"] for r in a] == ["bad", "osc", "quiet"]
    assert _verdicts(a) == _verdicts(b)
    rows = {r["loop"]: r for r in a}
    assert rows["osc"]["stage"] == "full" and rows["osc"]["oscillating"] and rows["osc"]["stiction"] != "not tested"
    assert rows["quiet"]["stage"] == "screen" and rows["quiet"]["stiction"] == "not tested"
    assert rows["bad"]["status"] == "failed"
    assert "| osc | ok | full | yes |" in table and "| quiet | ok | screen | no | not tested |" in table
    assert "| bad | failed |" in table


def _wide_csv(path) -> None:
    """A historian's wide export of two quiet loops (OP in percent)."""
    a = simulate_loop("healthy", seed=1, n=300).recording
    b = simulate_loop("healthy", seed=3, n=300).recording
    rows = ["timestamp,FIC1.PV,FIC1.OP,LIC2.PV,LIC2.OP"]
    rows += [",".join(repr(float(v)) for v in (t, pa, 100 * oa, pb, 100 * ob)) for t, pa, oa, pb, ob in
             zip(a.t, a.pv, a.op, b.pv, b.op)]
    path.write_text("\n".join(rows) + "\n")


def _core_install(monkeypatch, extras=("ray", "pyarrow")) -> None:
    """As in a core install: ``import ray`` and ``import pyarrow`` fail, and neither is found."""
    real_import, real_find = builtins.__import__, importlib.util.find_spec

    def imp(name, *a, **k):
        if name.split(".")[0] in extras:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", imp)
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name.split(".")[0] in extras else real_find(name, *a))


@pytest.fixture
def without_ray_or_pyarrow(monkeypatch):
    _core_install(monkeypatch)


def test_a_folder_is_diagnosed_in_process_without_ray_or_pyarrow(tmp_path, capsys, without_ray_or_pyarrow):
    folder = tmp_path / "recs"
    folder.mkdir()
    write_csv(simulate_loop("healthy", seed=0, n=300).recording, folder / "quiet.csv")
    _wide_csv(folder / "export.csv")
    out = tmp_path / "fleet"
    rc = main([str(folder), *FAST, "--out", str(out)])
    said = capsys.readouterr()
    assert rc == 0, said.out + said.err
    assert "3 loops: 3 analysed, 0 failed" in said.out and "Traceback" not in said.err
    assert f"table: {out / 'loops.csv'}" in said.out
    assert sorted(os.listdir(out)) == ["loops", "loops.csv", "worklist.html", "worklist.md"]   # no Parquet
    assert sorted(os.listdir(out / "loops")) == ["FIC1.json", "LIC2.json", "quiet.json"]
    lines = (out / "loops.csv").read_text().splitlines()
    assert len(lines) == 4 and all(",ok," in ln for ln in lines[1:])
    assert main([str(folder), *FAST]) == 0                               # no --out: the table on stdout
    table = capsys.readouterr().out
    assert all(f"| {n} | ok | screen |" in table for n in ("FIC1", "LIC2", "quiet"))
    assert main([str(folder), *FAST, "--ray"]) == 2                      # Ray only when asked for
    err = capsys.readouterr().err
    assert 'needs ray: pip install "valve_gym[fleet]"' in err and "Traceback" not in err


def test_a_wide_export_reads_the_same_without_pyarrow(tmp_path, monkeypatch):
    """The recording pipeline reads a wide CSV export's tag with its own readers (pyarrow is not needed)."""
    from valve_gym.fleet import discover_loops, load_loop

    p = tmp_path / "export.csv"
    _wide_csv(p)
    with_arrow = {s.name: load_loop(s, op_range=(0, 100)).recording for s in discover_loops(str(p))}
    _core_install(monkeypatch, ("pyarrow",))
    without = {s.name: load_loop(s, op_range=(0, 100)).recording for s in discover_loops(str(p))}
    assert set(with_arrow) == set(without) == {"FIC1", "LIC2"}
    a = simulate_loop("healthy", seed=1, n=300).recording
    np.testing.assert_array_equal(without["FIC1"].pv, a.pv)            # read exactly as written
    for name, rec in without.items():
        np.testing.assert_array_equal(rec.op, with_arrow[name].op)
        np.testing.assert_array_equal(rec.pv, with_arrow[name].pv)


def test_the_local_executor_runs_in_worker_processes_and_stops_when_asked():
    import math

    from valve_gym.fleet.runner import local_results

    items = [1.0, 4.0, 9.0, 16.0, 25.0]
    got = {i: r for i, r, e in local_results(math.sqrt, items, 2) if i >= 0 and e is None}
    assert got == {0: 1.0, 1: 2.0, 2: 3.0, 3: 4.0, 4: 5.0}
    assert [r for _, r, _ in local_results(math.sqrt, items, 1)] == [1.0, 2.0, 3.0, 4.0, 5.0]   # in order
    assert list(local_results(math.sqrt, items, 2, stop=lambda: True)) == []                    # nothing run
    seen = []
    for i, r, _ in local_results(math.sqrt, items, 1, stop=lambda: len(seen) >= 2):
        seen.append(r)
    assert seen == [1.0, 2.0]


def _die_on_first(task):
    """A diagnosis job whose worker process dies (as when the system kills it for memory)."""
    if task[0].endswith("die.csv"):
        os._exit(1)
    return {"path": task[0], "ok": False, "error": "not run", "seconds": 0.0}


def test_a_lost_worker_is_reported_per_recording_not_raised(monkeypatch):
    """``diagnose_many`` on local workers: a worker process that dies gives its recordings an error row
    ("worker lost"), never an exception or a hole in the results."""
    import multiprocessing

    diag_mod = importlib.import_module("valve_gym.diagnosis.diagnose")
    if multiprocessing.get_start_method(allow_none=True) not in (None, "fork"):
        pytest.skip("the patched job reaches the workers only when they fork")
    monkeypatch.setattr(diag_mod, "_diagnose_job", _die_on_first)
    out = diag_mod.diagnose_many(["a/die.csv", "b/ok.csv", "c/ok.csv"], jobs=2)
    assert len(out) == 3 and all(r is not None for r in out)
    lost = [r for r in out if "worker lost" in r.get("error", "")]
    assert lost and all(not r["ok"] and math.isnan(r["seconds"]) for r in lost)
