"""The command line of ``valve-gym benchmark``, ``train`` and ``convert-policy``: bad input is exit 2, a message that
names the problem, no traceback, refused before any work starts and nothing left on disk.

Every test replaces the long-running work (benchmark, training, unpickling) with a function that
fails the test, so a refusal that comes too late shows up as a failure, never as a slow test.
"""
import warnings
from pathlib import Path

import pytest

from valve_gym.cli import main as cli_main
from valve_gym.config import ConfigError, load_config, read_yaml

ROOT = Path(__file__).resolve().parents[1]
LEARNED = str(ROOT / "configs" / "learned.yaml")
PPO = str(ROOT / "configs" / "ppo_residual.yaml")


class WorkStarted(BaseException):
    """Raised by the stand-in for the long work (a BaseException: the commands' handlers let it pass)."""


def _no_work(*args, **kwargs):
    raise WorkStarted("bad input must be refused before the work starts")


@pytest.fixture
def probe(tmp_path, monkeypatch):
    """Run in an empty folder with the long work disabled; returns a snapshot function of the folder."""
    import valve_gym.agents.bench.cli
    import valve_gym.agents.convert
    import valve_gym.agents.es
    import valve_gym.agents.train

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(valve_gym.agents.bench.cli, "run_benchmark", _no_work)
    monkeypatch.setattr(valve_gym.agents.train, "train", _no_work)
    monkeypatch.setattr(valve_gym.agents.es, "train_learned", _no_work)
    monkeypatch.setattr(valve_gym.agents.convert, "convert_sb3_zip", _no_work)

    def snapshot():
        return sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    return snapshot


def _refused(argv, capsys, snapshot, *words):
    """Run ``valve-gym ARGV``: exit 2, one message naming ``words``, the folder unchanged."""
    before = snapshot()
    rc = cli_main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err and "Warning" not in err
    for w in words:
        assert w in err, (w, err)
    assert snapshot() == before
    return err


# ----------------------------------------------------------------- benchmark --out is a file
def test_benchmark_out_is_a_file(probe, capsys):
    Path("ok.csv").write_text("x\n")
    err = _refused(["benchmark", "--quick", "--out", "ok.csv", "--jobs", "1"], capsys, probe,
                   "--out ok.csv", "is a file", "folder")
    assert Path("ok.csv").read_text() == "x\n", err


def test_benchmark_out_below_a_file(probe, capsys):
    Path("ok.csv").write_text("x\n")
    _refused(["benchmark", "--quick", "--out", "ok.csv/sub", "--jobs", "1"], capsys, probe,
             "ok.csv", "is a file", "folder")


# ----------------------------------------------------------------- empty config files
@pytest.mark.parametrize("text", ["", "# only a comment\n", "null\n", "~\n", "\n\n"])
def test_benchmark_empty_config(probe, capsys, text):
    Path("empty.yaml").write_text(text)
    _refused(["benchmark", "--config", "empty.yaml", "--out", "Y"], capsys, probe,
             "empty.yaml", "is empty", "leave out --config")


@pytest.mark.parametrize("text", ["", "# only a comment\n", "null\n"])
def test_train_empty_config(probe, capsys, text):
    Path("empty.yaml").write_text(text)
    _refused(["train", "--config", "empty.yaml", "--out", "X"], capsys, probe,
             "empty.yaml", "is empty", "configs/learned.yaml")


def test_load_config_refuses_empty_file(tmp_path):
    (tmp_path / "empty.yaml").write_text("# nothing\n")
    with pytest.raises(ConfigError, match="is empty"):
        load_config(tmp_path / "empty.yaml")
    with pytest.raises(ConfigError, match="is empty"):
        read_yaml(tmp_path / "empty.yaml")
    assert load_config(None) == load_config({})        # no file at all: the defaults


# ----------------------------------------------------------------- numeric options
@pytest.mark.parametrize("config,opts,words", [
    (LEARNED, ["--seed", "-1", "--generations", "1"], ["--seed", "-1"]),
    (PPO, ["--seed", "-1"], ["--seed", "-1"]),
    (LEARNED, ["--seed", str(2**32)], ["--seed"]),
    (LEARNED, ["--generations", "0"], ["--generations", "0"]),
    (LEARNED, ["--generations", "-3"], ["--generations", "-3"]),
    (PPO, ["--timesteps", "-1"], ["--timesteps", "-1"]),
    (PPO, ["--timesteps", "0"], ["--timesteps", "0"]),
    (LEARNED, ["--timesteps", "-1"], ["--timesteps"]),
])
def test_train_bad_numbers(probe, capsys, config, opts, words):
    _refused(["train", "--config", config, "--out", "trout13", *opts], capsys, probe, *words)
    assert not Path("trout13").exists()


def test_train_bad_seed_leaves_out_usable(probe, capsys):
    """The refused run leaves nothing behind, so the next run is not told '--out is not empty'."""
    _refused(["train", "--config", LEARNED, "--out", "trout13", "--seed", "-1"], capsys, probe, "--seed")
    with pytest.raises(WorkStarted):                  # the good run gets as far as the training
        cli_main(["train", "--config", LEARNED, "--out", "trout13", "--seed", "1", "--generations", "1",
                  "--no-progress"])
    assert "not empty" not in capsys.readouterr().err


# ----------------------------------------------------------------- config is a folder
@pytest.mark.parametrize("cmd", [["train", "--out", "X"], ["benchmark", "--out", "Y"]])
def test_config_is_a_folder(probe, capsys, cmd):
    Path("adir").mkdir()
    err = _refused([*cmd, "--config", "adir"], capsys, probe, "adir", "is a folder, not a file")
    assert "does not exist" not in err


def test_config_missing_still_says_so(probe, capsys):
    _refused(["train", "--config", "nope.yaml", "--out", "X"], capsys, probe, "nope.yaml", "does not exist")


# ----------------------------------------------------------------- convert-policy input
def test_convert_missing_input_no_warning(probe, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error")              # any warning (the unpickling one) fails the test
        _refused(["convert-policy", "--trust-pickle", "nonexist.zip", "outstem"], capsys, probe,
                 "nonexist.zip", "does not exist")


def test_convert_input_folder_or_not_zip(probe, capsys):
    Path("adir").mkdir()
    Path("notzip.zip").write_text("hello\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _refused(["convert-policy", "--trust-pickle", "adir", "outstem"], capsys, probe, "adir", "is a folder")
        _refused(["convert-policy", "--trust-pickle", "notzip.zip", "outstem"], capsys, probe,
                 "notzip.zip", "not a zip file")
