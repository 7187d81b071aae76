"""Reliability findings of the bad-input sweep: each test failed before its fix.

Output paths (links written through, FIFOs and devices refused), size limits checked before
allocation, learned-block weights validated at load, the DCS bad-PV hold, recordings that are
FIFOs, and every command's unusable ``--out`` (one line, exit 2).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from valve_gym._io import OutputPathError, staged_folder, write_atomic
from valve_gym.config import ConfigError

ROOT = Path(__file__).resolve().parents[1]
needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this system")


def _char_device(tmp_path):
    """A private character device (a copy of /dev/null) in ``tmp_path``, so that no real device is ever at risk."""
    import stat
    dev = tmp_path / "null"
    try:
        os.mknod(dev, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except (OSError, AttributeError):
        pytest.skip("cannot make a device node here (needs root)")
    return dev


# ------------------------------------------------------------------ output paths
def test_write_atomic_writes_through_a_symlink(tmp_path):
    target = tmp_path / "real.txt"
    target.write_text("old")
    link = tmp_path / "link.txt"
    link.symlink_to(target)
    write_atomic(link, lambda f: f.write(b"new"))
    assert link.is_symlink(), "the link must stay a link"
    assert target.read_text() == "new", "the link's target must be updated"


def test_write_atomic_through_a_dangling_link_creates_the_target(tmp_path):
    link = tmp_path / "link.txt"
    link.symlink_to(tmp_path / "made.txt")
    write_atomic(link, lambda f: f.write(b"x"))
    assert link.is_symlink() and (tmp_path / "made.txt").read_text() == "x"


@needs_fifo
def test_write_atomic_refuses_a_fifo(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(OutputPathError, match="FIFO"):
        write_atomic(fifo, lambda f: f.write(b"x"))
    assert fifo.is_fifo(), "the FIFO must not be replaced by a plain file"


def test_write_atomic_refuses_a_device(tmp_path):
    dev = _char_device(tmp_path)
    with pytest.raises(OutputPathError, match="character device"):
        write_atomic(dev, lambda f: f.write(b"x"))
    assert dev.is_char_device(), "the device must not be replaced by a plain file"


def test_staged_folder_writes_through_links_and_refuses_fifos(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    target = tmp_path / "kept.md"
    target.write_text("old")
    (out / "report.md").symlink_to(target)
    with staged_folder(out) as stage:
        Path(stage, "report.md").write_text("new")
    assert (out / "report.md").is_symlink() and target.read_text() == "new"
    if hasattr(os, "mkfifo"):
        os.mkfifo(out / "pipe.csv")
        with pytest.raises(OutputPathError, match="FIFO"):
            with staged_folder(out) as stage:
                Path(stage, "report.md").write_text("newer")
                Path(stage, "pipe.csv").write_text("x")
        assert (out / "pipe.csv").is_fifo() and target.read_text() == "new", "nothing is published"


def test_save_config_goes_through_the_atomic_writer(tmp_path):
    from valve_gym.config import EnvConfig, save_config
    target = tmp_path / "real.yaml"
    target.write_text("old")
    link = tmp_path / "cfg.yaml"
    link.symlink_to(target)
    save_config(EnvConfig(), link)
    assert link.is_symlink() and "control_period" in target.read_text()


# ------------------------------------------------------------------ size limits
def test_make_vec_refuses_too_many_envs_before_allocating():
    import gymnasium as gym

    import valve_gym  # noqa: F401  (registers the envs)
    for env_id in ("valve_gym/ValveTank-v0", "valve_gym/ValveTankRegulation-v0"):
        with pytest.raises(ConfigError, match=r"num_envs = 1,000,000,000 is above the limit of 100,000"):
            gym.make_vec(env_id, num_envs=10 ** 9, vectorization_mode="vector_entry_point")


def test_train_config_refuses_too_many_envs():
    from valve_gym.agents.train import PPOHyper
    with pytest.raises(ConfigError, match=r"ppo.n_envs = 100,000,000 is above the limit of 100,000"):
        PPOHyper(n_envs=100_000_000, batch_size=256)


def test_benchmark_band_and_scan_limits():
    from valve_gym.agents.bench.config import load_bench_config
    with pytest.raises(ConfigError, match=r"bands.sticky.n = 1,000,000,000 is above the limit of 100,000"):
        load_bench_config({"bands": {"sticky": {"n": 1e9}}})
    with pytest.raises(ConfigError, match=r"scan_s = 100000 s leaves regulation.duration_s = 3600 s only"):
        load_bench_config({"scan_s": 100000.0})
    with pytest.raises(ConfigError, match=r"at most 1,000,000 per record"):
        load_bench_config({"scan_s": 0.0001})


def test_es_pairs_limit():
    from valve_gym.agents.es import ESHyper
    with pytest.raises(ConfigError, match=r"es.pairs = 1,000,000,000 is above the limit of 4,096"):
        ESHyper(pairs=10 ** 9)


# ------------------------------------------------------------------ learned-block weights
def _tamper(tmp_path, name, value):
    """The shipped learned block copied to ``tmp_path`` with tensor ``name`` replaced by ``value``."""
    from safetensors.numpy import load_file, save_file

    from valve_gym.agents.learned import DEFAULT_POLICY
    src = Path(DEFAULT_POLICY)
    tensors = load_file(str(src.with_suffix(".safetensors")))
    tensors[name] = value(tensors[name])
    save_file(tensors, str(tmp_path / "blk.safetensors"))
    (tmp_path / "blk.json").write_text(src.with_suffix(".json").read_text())
    return tmp_path / "blk.json"


@pytest.mark.parametrize("name, value, match", [
    ("W0", lambda a: np.where(np.arange(a.size).reshape(a.shape) == 3, np.nan, a), r"W0 holds 1 NaN or inf"),
    ("obs_mean", lambda a: np.full_like(a, np.nan), r"obs_mean holds \d+ NaN or inf"),
    ("obs_std", lambda a: np.full_like(a, np.inf), r"obs_std holds \d+ NaN or inf"),
    ("obs_std", lambda a: np.zeros_like(a), r"obs_std must be > 0"),
    ("W0", lambda a: a > 0, r"W0 has dtype bool, expected a float dtype"),
    ("b0", lambda a: a[:-1], r"b0 has shape"),
])
def test_learned_block_weights_are_validated_at_load(tmp_path, name, value, match):
    from valve_gym.agents.learned import load_learned
    with pytest.raises(ValueError, match=match):
        load_learned(_tamper(tmp_path, name, value))


# ------------------------------------------------------------------ DCS bad-PV hold
@pytest.mark.parametrize("name", ["pi", "knocker", "constant_reinforcement", "two_move", "integral_freeze",
                                  "learned"])
@pytest.mark.parametrize("bad", [-3.4e38, np.nan, np.inf, 2e6])
def test_blocks_hold_their_output_on_a_bad_pv(name, bad):
    from valve_gym.agents import load_controller
    c = load_controller(name, **({} if name in ("pi", "learned") else {"S": 0.02}))
    c.reset(1.0, 1.0, 0.5)
    for _ in range(5):
        op = c.step(1.0, 0.98)
    with pytest.warns(RuntimeWarning, match="output held"):
        held = [c.step(1.0, bad) for _ in range(10)]
    assert held == [op] * 10, "the output is held at its last value"
    assert c.bad_pv_scans.tolist() == [10] and c.held.tolist() == [True]
    nxt = c.step(1.0, 0.98)
    assert 0.0 <= nxt <= 1.0 and abs(nxt - op) < 0.05, "the loop goes on from where it was"
    assert c.held.tolist() == [False]


def test_step_with_huge_opposite_signals_is_never_nan():
    from valve_gym.agents import load_controller
    c = load_controller("pi")
    c.reset(1.0, 1.0, 0.5)
    with pytest.warns(RuntimeWarning):
        u = c.step(1e308, -1e308)
    assert u == 0.5


def test_configured_pv_range_catches_historian_codes_per_loop():
    from valve_gym.agents import load_controller
    c = load_controller("pi", pv_range=(0.0, 2.0))
    c.reset([1.0, 1.0], [1.0, 1.0], [0.5, 0.5])
    with pytest.warns(RuntimeWarning, match=r"loop\(s\) \[0\]"):
        u = np.asarray(c.step(1.0, [9999.0, 0.9]))
    assert u[0] == 0.5 and u[1] > 0.5 and c.held.tolist() == [True, False]
    with pytest.raises(ValueError, match="pv_range"):
        load_controller("pi", pv_range=(2.0, 0.0))


# ------------------------------------------------------------------ recordings
@needs_fifo
def test_a_fifo_given_as_a_recording_is_refused(tmp_path):
    from valve_gym.diagnosis import load_recording
    from valve_gym.diagnosis.recording import RecordingError
    fifo = tmp_path / "loop.csv"
    os.mkfifo(fifo)
    with pytest.raises(RecordingError, match="is a FIFO"):
        load_recording(str(fifo))        # hung before
    with pytest.raises(RecordingError, match="is a character device"):
        load_recording(str(_char_device(tmp_path)))


# ------------------------------------------------------------------ unusable --out
def _cli(*args, timeout=120):
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "valve_gym.cli", *args], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.parametrize("cmd", [
    ["benchmark", "--quick", "--no-figures"],
    ["figures"],
    ["train", "--config", "configs/learned.yaml"],
    ["diagnose", "valve_gym/data/stictiongpt_plant_loops"],
])
def test_unusable_out_is_one_line_and_exit_2(tmp_path, cmd):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for out in ("/proc/valve_gym_x", str(blocker / "sub")):
        r = _cli(*cmd, "--out", out)
        assert r.returncode == 2, (cmd, out, r.stderr[-500:])
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and "--out" in lines[0] and "Traceback" not in r.stderr, r.stderr


def test_json_of_the_learned_block_is_unchanged_by_the_checks(tmp_path):
    """The shipped block still loads (the checks refuse only broken files)."""
    from valve_gym.agents.learned import DEFAULT_POLICY, load_learned
    blk = load_learned()
    assert json.loads(Path(DEFAULT_POLICY).with_suffix(".json").read_text())["format"] == blk.meta["format"]
