"""More bad input refused with a clear message: a fleet's --out that is its input folder (and the outputs
an earlier such run left there), a learned block stepped with another number of loops than it was reset
with, an episode too long for memory, and ``--jobs`` beyond the benchmark's tasks reported as used."""
from __future__ import annotations

import io
import os

import gymnasium as gym
import numpy as np
import pytest

import valve_gym  # noqa: F401 - registers the environments
from valve_gym.agents import load_controller
from valve_gym.config import MAX_EPISODE_STEPS, ConfigError, EnvConfig
from valve_gym.diagnosis import cli
from valve_gym.diagnosis.recording import RecordingError
from valve_gym.diagnosis.synthetic import write_csv
from valve_gym.envs.regulation import RegulationTaskConfig
from valve_gym.fleet import FleetSettings, discover_loops, loop_key, run_fleet
from valve_gym.fleet.analyse import failed_result
from valve_gym.fleet.runner import check_out_dir
from valve_gym.fleet.simulate import simulate_loop
from valve_gym.fleet.sources import fleet_outputs, is_fleet_output
from valve_gym.fleet.table import write_result, write_table
from valve_gym.fleet.worklist import write_worklist

SETTINGS = FleetSettings(op_range=(0.0, 100.0), effort="fast", candidates=())


# --------------------------------------------------------------------------- 1. fleet --out and old outputs
@pytest.fixture
def recs(tmp_path):
    """A folder of two loops, as tests/test_fleet.py writes them."""
    d = tmp_path / "fleet2"
    d.mkdir()
    for i in range(2):
        write_csv(simulate_loop("healthy", seed=i, n=300).recording, d / f"loop{i}.csv")
    return d


def _contents(d) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in d.rglob("*"))


def _old_fleet_output(folder, sources) -> None:
    """What a fleet run with ``--out`` = its input folder left there before it was refused."""
    rows = [failed_result(s, "k", "failed", f"{s.path}: no column for the time") for s in sources]
    for r in rows:
        write_result(r, os.path.join(folder, "loops", r.loop + ".json"))
    write_table(rows, str(folder))
    write_worklist(rows, sources, str(folder), top=0)


def test_cli_refuses_out_that_is_the_input_folder_before_any_work(recs, tmp_path, capsys):
    before = _contents(recs)
    link = tmp_path / "link"
    link.symlink_to(recs, target_is_directory=True)
    for out in (recs, f"{recs}/.", link):                 # the same folder, however spelled
        code = cli.main([str(recs), "--op-range", "0,100", "--out", str(out), "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and "Traceback" not in err
        assert f"--out {str(out)!r} is the input folder itself" in err
        assert "would be written among the recordings; give another folder, e.g." in err
        assert "fleet2-fleet" in err
    assert _contents(recs) == before                      # nothing written: no loops/, no table


def test_run_fleet_refuses_its_input_folder_and_a_table_it_would_overwrite(recs):
    with pytest.raises(ValueError, match=r"out_dir '.*fleet2' is the input folder itself"):
        run_fleet(str(recs), str(recs), SETTINGS, stream=None)
    assert not (recs / "loops").exists()
    export = recs / "loops.csv"                           # a wide export named like the fleet's table
    export.write_text("timestamp,FIC1.PV,FIC1.OP\n0,1,50\n")
    with pytest.raises(ValueError, match=r"would overwrite the input .*loops\.csv.* with the fleet's loops\.csv"):
        check_out_dir(str(export), str(recs))
    check_out_dir(str(export), str(recs / "out"))         # elsewhere: fine


def test_out_inside_the_input_folder_is_allowed_and_not_discovered(recs):
    out = recs / "out"
    check_out_dir(str(recs), str(out))                    # no error
    names = [s.name for s in discover_loops(str(recs))]
    _old_fleet_output(out, discover_loops(str(recs)))     # the subfolder's outputs ...
    assert [s.name for s in discover_loops(str(recs))] == names == ["loop0", "loop1"]   # ... are not loops


def test_outputs_of_an_earlier_fleet_run_in_the_folder_are_not_loops(recs):
    _old_fleet_output(recs, discover_loops(str(recs)))
    assert {"loops.csv", "loops.parquet", "worklist.md", "worklist.html", "loops"} <= set(os.listdir(recs))
    assert [s.name for s in discover_loops(str(recs))] == ["loop0", "loop1"]
    assert [os.path.basename(f) for f in fleet_outputs(str(recs))] == ["loops.csv", "loops.parquet"]
    # without the loops/ folder, the table is still known by its header
    for f in (recs / "loops").iterdir():
        f.unlink()
    (recs / "loops").rmdir()
    assert is_fleet_output(str(recs / "loops.csv")) and is_fleet_output(str(recs / "loops.parquet"))
    assert [s.name for s in discover_loops(str(recs))] == ["loop0", "loop1"]


def test_a_recording_called_loops_csv_is_still_a_loop(tmp_path):
    d = tmp_path / "plant"
    d.mkdir()
    write_csv(simulate_loop("healthy", seed=0, n=300).recording, d / "loops.csv")
    assert not is_fleet_output(str(d / "loops.csv"))
    assert [(s.name, s.kind) for s in discover_loops(str(d))] == [("loops", "csv")]


def test_a_folder_or_file_of_fleet_outputs_only_says_so(recs, tmp_path):
    old = tmp_path / "old"
    _old_fleet_output(old, discover_loops(str(recs)))
    with pytest.raises(RecordingError, match=r"holds only the outputs of a fleet run \(loops\.csv, loops\.parquet\), "
                                             r"no recordings; give the folder of the recordings"):
        discover_loops(str(old))
    with pytest.raises(RecordingError, match=r"loops\.csv: this is the table of a fleet run .*, not a recording"):
        discover_loops(str(old / "loops.csv"))


def test_a_rerun_on_a_folder_with_old_outputs_skips_them_and_says_so(recs, tmp_path):
    srcs = discover_loops(str(recs))
    _old_fleet_output(recs, srcs)
    out = tmp_path / "out"
    for s in srcs:        # stored results of every loop: nothing to run, so no Ray
        key = loop_key(s.fingerprint, s.kind, s.tag, SETTINGS)
        write_result(failed_result(s, key, "failed", "too short"), str(out / "loops" / (s.name + ".json")))
    said = io.StringIO()
    run = run_fleet(str(recs), str(out), SETTINGS, stream=said, top=0)
    assert run.n_loops == 2 and run.resumed == 2 and run.done == 0
    assert [r.loop for r in run.results] == ["loop0", "loop1"]
    assert "note: skipped loops.csv, loops.parquet in" in said.getvalue()
    assert "the outputs of an earlier fleet run, not recordings" in said.getvalue()


# --------------------------------------------------------------------------- 2. learned block, loop count
def test_learned_step_with_another_number_of_loops_says_so_as_the_other_blocks():
    msgs = {}
    for name in ("pi", "learned"):
        c = load_controller(name)
        c.reset(1.0, 1.0, 0.5)                            # one loop
        with pytest.raises(ValueError) as e:
            c.step(1.0, np.array([0.9, 1.0]))
        msgs[name] = str(e.value)
    assert msgs["learned"] == ("learned: reset() was given 1 loop(s) but step() 2; call reset(sp, pv, op) "
                               "again for the new set of loops")
    assert msgs["learned"].replace("learned", "pi", 1) == msgs["pi"]   # the same check, not a copy
    c = load_controller("learned")
    c.reset([1.0, 1.0], [1.0, 1.0], [0.5, 0.5])
    with pytest.raises(ValueError, match=r"^learned: reset\(\) was given 2 loop\(s\) but step\(\) 3;"):
        c.step([1.0] * 3, [1.0] * 3)
    with pytest.warns(RuntimeWarning, match=r"^learned: bad measurement .* at loop\(s\) \[1\]; output held"):
        held = c.step(1.0, [1.0, np.nan])                 # a bad PV holds that loop's output (DCS bad-PV hold)
    assert held[1] == 0.5 and c.held.tolist() == [False, True]
    assert np.shape(c.step(1.0, [0.9, 1.0])) == (2,)      # still usable; a scalar is shared by the loops
    assert np.shape(c.step(1.0, 1.0)) == (2,)


# --------------------------------------------------------------------------- 3. episode length bound
def test_an_episode_too_long_for_memory_is_a_config_error():
    with pytest.raises(ConfigError) as e:
        gym.make("valve_gym/ValveTank-v0", config={"episode_seconds": 1e12})
    msg = str(e.value)
    assert msg.startswith("episode_seconds = 1e+12 s is 1e+12 steps of control_period = 1 s; "
                          "at most 1,000,000 steps per episode (1e+06 s at this control_period)")
    assert "arrays of one value per step" in msg and "7.45e+03 GiB" in msg and "use a shorter episode_seconds" in msg
    with pytest.raises(ConfigError, match=r"^episode_s = 1e\+12 s is 1e\+12 steps of block.scan_s = 1 s; at most "
                                          r"1,000,000 steps"):
        gym.make("valve_gym/ValveTankRegulation-v0", config={"episode_s": 1e12})
    # the bound counts steps: a longer control period allows a longer episode; the documented ones pass
    EnvConfig(episode_seconds=float(MAX_EPISODE_STEPS))
    EnvConfig(control_period=2.0, episode_seconds=2.0 * MAX_EPISODE_STEPS)
    with pytest.raises(ConfigError, match="at most 1,000,000 steps"):
        EnvConfig(episode_seconds=float(MAX_EPISODE_STEPS + 1))
    for s in (600.0, 1800.0, 3600.0):
        assert EnvConfig(episode_seconds=s).episode_steps == RegulationTaskConfig(episode_s=s).steps == int(s)


# --------------------------------------------------------------------------- 4. benchmark --jobs
def test_jobs_used_and_their_text():
    from valve_gym.agents.bench.pipeline import jobs_text, jobs_used

    assert jobs_used(1000, 8) == 8 and jobs_used(2, 8) == 2 and jobs_used(3, 0) == 1
    assert jobs_text(8, 1000, 8) == "8 job(s) (1000 asked; only 8 tasks)"
    assert jobs_text(2, 2, 22) == "2 job(s)"


TINY = """\
bands: {healthy: {n: 1}, sticky: {n: 1}, severe: {n: 1}}
regulation: {duration_s: 120.0}
servo: {duration_s: 120.0, interval_s: 60.0}
controllers: {detune: [], compensators: [], estimate_factors: [1.0], learned: false}
scores: {n_boot: 100}
"""


def test_benchmark_reports_the_jobs_it_used(tmp_path, capsys):
    from valve_gym.agents.bench.cli import main

    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(TINY)
    out = tmp_path / "res"
    assert main(["--config", str(cfg), "--out", str(out), "--jobs", "1000", "--no-figures", "--no-progress"]) == 0
    said = capsys.readouterr().out
    # two controllers (PI frictionless, PI (SIMC)) x two parts = 4 tasks: 4 processes, not 1000
    assert "with 4 job(s) (1000 asked; only 4 tasks); wrote" in said and "1000 job(s)" not in said
    md = (out / "results.md").read_text()
    assert "with 4 worker process(es) (1000 asked; only 4 tasks); CPU time" in md
    assert "(on 4 free core(s)" in md and "1000 worker" not in md


# --------------------------------------------------------------------------- second review
def test_an_output_folder_without_write_permission_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    """As root every folder is writable, so the permission is taken away where it is read (os.access)."""
    import valve_gym._io as io
    from valve_gym.diagnosis import cli as dcli

    ro = tmp_path / "ro"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(io.os, "access", lambda p, mode: False if os.fspath(p) == str(ro) else real(p, mode))
    assert "permission denied" in io.folder_problem(ro / "out")
    rec = tmp_path / "r.csv"
    rec.write_text("t,OP,PV\n" + "".join(f"{i},{50 + i % 7},{1 + 0.01 * (i % 5)}\n" for i in range(80)))
    for opt in (["--json", str(ro / "x.json")], ["--report", str(ro / "rep")]):
        code = dcli.main([str(rec), "--op-range", "0,100", *opt])
        err = capsys.readouterr().err
        assert code == 2 and f"cannot write into {ro} (permission denied)" in err and "fitting" not in err


def test_the_regulation_env_accepts_render_mode_none_and_refuses_a_mode():
    env = gym.make("valve_gym/ValveTankRegulation-v0", render_mode=None)
    env.reset(seed=0)
    assert env.render_mode is None
    # gymnasium itself warns first that the mode is not in the env's metadata; the env then refuses it
    with pytest.raises(ValueError, match=r"render_mode must be None or one of \[.rgb_array.\], got .ansi."), \
            pytest.warns(UserWarning, match="render_mode='ansi'"):
        gym.make("valve_gym/ValveTankRegulation-v0", render_mode="ansi")
    vec = gym.make_vec("valve_gym/ValveTankRegulation-v0", num_envs=2, vectorization_mode="vector_entry_point",
                       render_mode=None)
    assert vec.num_envs == 2


def test_a_yaml_key_given_twice_is_refused_and_merge_keys_still_work(tmp_path):
    from valve_gym.config import read_yaml

    p = tmp_path / "c.yaml"
    p.write_text("seed: 3\nother: {a: 1}\nseed: 5\n")
    with pytest.raises(ConfigError, match=r"key 'seed' is given twice \(lines 1 and 3\); keep one"):
        read_yaml(p)
    p.write_text("base: &b\n  a: 1\n  b: 2\nother:\n  <<: *b\n  a: 3\n")
    assert read_yaml(p) == {"base": {"a": 1, "b": 2}, "other": {"a": 3, "b": 2}}


def test_layer_sizes_are_bounded_and_section_messages_are_not_prefixed_twice():
    from valve_gym.agents.es import ESHyper, load_learned_train_config

    with pytest.raises(ConfigError, match=r"es.hidden must be a list of layer sizes from 1 to 4096"):
        ESHyper(hidden=(100_000_000, 8))
    with pytest.raises(ConfigError) as e:                        # before: 'es.es.hidden', then a MemoryError
        load_learned_train_config({"es": {"hidden": [100_000_000]}})
    assert str(e.value).startswith("es.hidden must be a list of layer sizes")
    with pytest.raises(ConfigError) as e:                        # before: 'eval.eval.every'
        load_learned_train_config({"eval": {"every": 0}})
    assert str(e.value).startswith("eval.every and eval.n_loops must be >= 1")


def test_a_missing_role_suggests_the_column_its_name_points_to(tmp_path):
    """A factory export names its columns by tag: the message offers the one whose name holds ``OP``."""
    from valve_gym.diagnosis import load_recording
    from valve_gym.diagnosis.recording import RecordingError

    p = tmp_path / "lic.csv"
    p.write_text("timestamp,t_s,flow_FT115,OP_level_valve_LV106\n" +
                 "".join(f"2024-11-21 00:{k // 60:02d}:{k % 60:02d},{k},{100 + k % 7},{43 + k % 5}\n"
                         for k in range(120)))
    with pytest.raises(RecordingError, match=r"perhaps 'OP_level_valve_LV106': --columns op=OP_level_valve_LV106"):
        load_recording(str(p), op_range=(0, 100))
    with pytest.raises(RecordingError, match=r"perhaps 'flow_FT115': --columns pv=flow_FT115\)$"):
        load_recording(str(p), columns={"op": "OP_level_valve_LV106"}, op_range=(0, 100))
    rec = load_recording(str(p), columns={"op": "OP_level_valve_LV106", "pv": "flow_FT115"}, op_range=(0, 100))
    assert len(rec) == 120
