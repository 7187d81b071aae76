"""``valve-gym benchmark --quick``: files, columns, controllers, bands, metrics; config errors."""
import numpy as np
import pandas as pd
import pytest

from agents.benchmark import (BANDS, METRICS, BandRule, assign_bands, default_policies,
                              load_benchmark_config, make_valve_set)
from valve_gym.cli import main as cli_main
from valve_gym.config import ConfigError

REQUIRED_METRICS = ("iae", "ise", "error_std", "lc_amplitude", "lc_period", "valve_travel",
                    "valve_reversals_per_hour", "op_travel", "op_reversals_per_hour")


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "tmp"
    rc = cli_main(["benchmark", "--quick", "--out", str(out), "--no-progress"])
    assert rc == 0
    return out


def test_quick_writes_results_csv(quick_run):
    df = pd.read_csv(quick_run / "results.csv")
    assert {"controller", "band", "metric", "median", "q25", "q75"} <= set(df.columns)
    ctrls = set(df.controller)
    assert {"pi", "knocker"} <= ctrls
    if default_policies():
        assert any(c.startswith("ppo") for c in ctrls)
    assert {"healthy", "sticky", "all"} <= set(df.band)
    assert set(REQUIRED_METRICS) <= set(df.metric)
    # quartiles bracket the median where defined
    ok = df.dropna(subset=["median"])
    assert np.all(ok["q25"] <= ok["median"] + 1e-12) and np.all(ok["median"] <= ok["q75"] + 1e-12)


def test_quick_writes_figures_raw_metrics_and_config(quick_run, capsys):
    for name in ("boxplots.png", "trajectories.png", "op_vs_stem.png", "ratio_vs_friction.png"):
        data = (quick_run / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    ep = pd.read_csv(quick_run / "episodes.csv")
    assert {"controller", "valve", "band", "z_max", "e_dead", "tau", "v_max", "iae"} <= set(ep.columns)
    assert ep.groupby("controller").valve.nunique().min() == 6
    cfg = load_benchmark_config(quick_run / "config.yaml")
    assert cfg.env.episode_seconds == 120.0
    md = (quick_run / "results.md").read_text()
    assert "| metric |" in md and "Where controllers lose" in md
    assert not list(quick_run.glob("*.tmp")) and not list(quick_run.glob(".*"))


def test_quick_prints_markdown_table(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)                 # any cwd: embedded config, shipped policies
    rc = cli_main(["benchmark", "--quick", "--out", "tmp", "--no-progress", "--no-policy"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "| metric | pi | knocker |" in out and "### Band `sticky`" in out
    assert (tmp_path / "tmp" / "results.csv").exists()


def test_valve_set_is_fixed_and_spans_bands():
    cfg = load_benchmark_config()
    a, b = make_valve_set(cfg), make_valve_set(cfg)
    assert len(a) >= 100 and a.equals(b)
    counts = a.band.value_counts()
    assert counts["healthy"] >= 20 and counts["sticky"] >= 40 and counts["outside_training"] >= 20
    q = make_valve_set(cfg, quick=True)
    assert len(q) == 6


def test_bands_from_parameters():
    rule = BandRule()
    v = pd.DataFrame({"z_max": [0.005, 0.005, 0.2, 0.8, 0.1], "e_dead": [0.001, 0.01, 0.0, 0.01, 0.03],
                      "tau": [0.1] * 5, "v_max": [0.5] * 5})
    assert list(assign_bands(v, rule)) == ["healthy", "sticky", "sticky", "outside_training",
                                            "outside_training"]
    assert set(BANDS) == {"healthy", "sticky", "outside_training", "all"}
    assert set(REQUIRED_METRICS) <= set(METRICS)


@pytest.mark.parametrize("data,msg", [
    ({"valves": {"sticky": {"zmax": [0.1, 0.2]}}}, "valves.sticky.zmax"),
    ({"knocker": {"a": "1e-2"}}, "knocker.a"),
    ({"env": {"noise_std": -1.0}}, "env.noise_std"),
    ({"valves": {"severe": {"z_max": [0.0, 1.0]}}}, "valves.severe.z_max"),
    ({"policies": "x.zip"}, "policies"),
])
def test_bad_config_names_key_path(data, msg):
    with pytest.raises(ConfigError, match=msg.replace(".", r"\.")):
        load_benchmark_config(data)


def test_cli_bad_config_and_missing_policy(tmp_path, capsys):
    bad = tmp_path / "b.yaml"
    bad.write_text("valves:\n  stiky: {}\n")
    assert cli_main(["benchmark", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "valves.stiky" in capsys.readouterr().err
    assert cli_main(["benchmark", "--quick", "--policy", str(tmp_path / "nope.zip"),
                     "--out", str(tmp_path / "o")]) == 2


def test_shipped_yaml_is_the_embedded_default():
    from pathlib import Path

    from agents.benchmark import BenchmarkConfig

    path = Path(__file__).resolve().parents[1] / "configs" / "benchmark.yaml"
    assert load_benchmark_config(path) == BenchmarkConfig()
