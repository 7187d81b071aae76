"""``valve-gym benchmark --quick``: every file written, every controller and band scored; bad input rejected."""

import numpy as np
import pandas as pd
import pytest

from valve_gym.agents.bench.config import BenchConfig, load_bench_config
from valve_gym.agents.bench.scores import BAND_GROUPS
from valve_gym.cli import main as cli_main

FILES = ("results.md", "results.csv", "loops.csv", "config.yaml", "trends.png", "bands.png", "pareto.png")


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "results"
    rc = cli_main(["benchmark", "--quick", "--out", str(out), "--jobs", "1", "--no-progress"])
    assert rc == 0
    return out


@pytest.mark.slow
def test_quick_run_writes_every_file(quick_run):
    for name in FILES:
        p = quick_run / name
        assert p.is_file() and p.stat().st_size > 0, name
    assert not list(quick_run.glob(".*.tmp"))          # atomic writes leave no temporaries
    assert (quick_run / "trends.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_quick_run_tables(quick_run):
    cfg = BenchConfig().quick_version()
    res = pd.read_csv(quick_run / "results.csv")
    assert list(res.columns) == ["part", "controller", "band", "metric", "stat", "value", "ci_lo", "ci_hi", "n", "unit"]
    assert set(res["part"]) == {"regulation", "servo", "generalisation"} and set(res["band"]) == set(BAND_GROUPS)
    gen = res[res.part == "generalisation"]
    assert {"PI (SIMC)", "knocker", "knocker (S known)", "learned", "learned_network"} <= set(gen["controller"])
    ctrls = set(res[res.part != "generalisation"]["controller"])
    assert {"PI frictionless", "PI (SIMC)", "PI Kc x0.5", "knocker", "knocker S x0.5", "two_move S x1.5",
            "constant_reinforcement", "integral_freeze"} <= ctrls
    r = res[(res.metric == "R") & (res.controller == "PI (SIMC)")]
    assert np.allclose(r["value"], 0.0)                                      # R of the reference is 0 by definition
    loops = pd.read_csv(quick_run / "loops.csv")
    n = 3 * cfg.quick.n_per_band
    assert len(loops) == 2 * n * len(ctrls)
    assert set(loops["model"]) == set(cfg.models)
    fr = loops[loops.controller == "PI frictionless"]
    # R of the frictionless PI is 1 where stiction costs the PI more than the floor, below 1 elsewhere
    pi = loops[loops.controller == "PI (SIMC)"].set_index(["part", "loop"])["iae_per_h"]
    f = fr.set_index(["part", "loop"])
    big = (pi - f["iae_per_h"]) >= 0.1 * f["iae_per_h"]
    r_fr, big_a = np.asarray(f["R"], float), np.asarray(big, bool)
    assert np.allclose(r_fr[big_a], 1.0)
    assert bool(np.all(r_fr[~big_a] < 1.0))
    assert bool(np.all(np.asarray(fr["lc_present"]) == 0))
    assert load_bench_config(quick_run / "config.yaml") == cfg
    md = (quick_run / "results.md").read_text()
    assert "## Headline" in md and "valve-gym benchmark --quick" in md and "## Generalisation" in md


def test_bad_config_and_options_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("bands:\n  sticky:\n    n: -3\n")
    assert cli_main(["benchmark", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "bands.sticky" in capsys.readouterr().err
    bad.write_text("models: [riihilahti, nosuchmodel]\n")
    assert cli_main(["benchmark", "--config", str(bad), "--quick", "--out", str(tmp_path / "o")]) == 2
    assert "nosuchmodel" in capsys.readouterr().err
    assert cli_main(["benchmark", "--config", str(tmp_path / "missing.yaml"), "--out", str(tmp_path)]) == 2
    assert cli_main(["benchmark", "--jobs", "0", "--out", str(tmp_path)]) == 2
    assert not (tmp_path / "o").exists()
