"""valve_gym.agents.bench.config: the YAML file is the default; every mistake names its key path."""
from pathlib import Path

import pytest

from valve_gym.agents.bench.config import DEFAULT_CONFIG_PATH, BenchConfig, bench_config_to_dict, load_bench_config
from valve_gym.config import ConfigError


def test_shipped_yaml_equals_defaults():
    assert DEFAULT_CONFIG_PATH == Path(__file__).resolve().parents[1] / "configs" / "benchmark.yaml"
    assert load_bench_config(DEFAULT_CONFIG_PATH) == BenchConfig()


def test_round_trip_and_override():
    cfg = load_bench_config({"bands": {"sticky": {"n": 12}}, "regulation": {"load": {"sigma": 2.0e-4}}})
    assert cfg.bands.sticky.n == 12 and cfg.bands.severe.n == BenchConfig().bands.severe.n
    assert cfg.regulation.load.sigma == 2.0e-4
    assert load_bench_config(bench_config_to_dict(cfg)) == cfg


def test_at_least_100_valves_per_part_and_three_models():
    cfg = BenchConfig()
    assert cfg.bands.healthy.n + cfg.bands.sticky.n + cfg.bands.severe.n >= 100
    assert len(cfg.models) >= 3 and {"riihilahti", "choudhury"} <= set(cfg.models)


@pytest.mark.parametrize("data, match", [
    ({"bands": {"stiky": {}}}, r"unknown key 'bands\.stiky' \(did you mean 'sticky'\?\)"),
    ({"regulation": {"load": {"tua": 1.0}}}, r"regulation\.load\.tua"),
    ({"regulation": {"noise_std": "2e-3"}}, r"regulation\.noise_std.*write 2\.0e-3"),
    ({"regulation": {"levels": "1.0"}}, r"regulation\.levels must be a list"),
    ({"bands": {"sticky": {"S": [0.05, 0.01]}}}, r"bands\.sticky\.S must be \[low, high\]"),
    ({"bands": {"healthy": {"S": [0.0, 0.005], "log_uniform": True}}}, r"bands\.healthy\.S"),
    ({"controllers": {"detune": [5.0]}}, r"controllers\.detune factors must be in \(0, 4\]"),
    ({"controllers": {"detune": [1.0]}}, r"controllers\.detune factors must be in \(0, 4\] and not 1"),
    ({"controllers": {"estimate_factors": [0.5, 1.0]}}, r"controllers\.estimate_factors must start with 1\.0"),
    ({"scores": {"n_boot": 10}}, r"scores\.n_boot must be >= 100"),
    ({"models": ["none"]}, r"models must name"),
    ({"seed": 1.5}, r"seed must be an integer"),
])
def test_errors_name_the_key(data, match):
    with pytest.raises(ConfigError, match=match):
        load_bench_config(data)


def test_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "b.yaml"
    bad.write_text("servo:\n  step: -1.0\n")
    with pytest.raises(ConfigError, match=r"servo\.step must be > 0.*b\.yaml"):
        load_bench_config(bad)
    with pytest.raises(ConfigError, match="benchmark config is a YAML file or a mapping"):
        load_bench_config(3)  # type: ignore[arg-type]


def test_quick_version_is_small():
    q = BenchConfig().quick_version()
    assert q.bands.sticky.n == q.quick.n_per_band and q.regulation.duration_s == q.quick.duration_s
    assert q.scores.n_boot == q.quick.n_boot and q.servo.interval_s <= q.servo.duration_s / 2


try:
    from hypothesis import given, settings
    from hypothesis import strategies as st
except ImportError:  # pragma: no cover - hypothesis is a test extra
    given = None

if given is not None:
    _SECTIONS = ("bands", "regulation", "servo", "controllers", "scores", "quick")

    @settings(max_examples=40, deadline=None)
    @given(section=st.sampled_from(_SECTIONS),
           key=st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=12),
           value=st.one_of(st.integers(), st.floats(allow_nan=False), st.text(max_size=5)))
    def test_any_unknown_key_is_named(section, key, value):
        known = set(BenchConfig.__dataclass_fields__[section].default_factory().__dataclass_fields__)
        if key in known:
            return
        with pytest.raises(ConfigError, match=rf"unknown key '{section}\.{key}'"):
            load_bench_config({section: {key: value}})


def test_docstring_examples_of_the_benchmark_modules():
    import doctest

    import valve_gym.agents.bench.config
    import valve_gym.agents.bench.scenarios
    import valve_gym.agents.bench.scores

    for mod in (valve_gym.agents.bench.config, valve_gym.agents.bench.scenarios, valve_gym.agents.bench.scores):
        res = doctest.testmod(mod)
        assert res.attempted > 0 and res.failed == 0, mod.__name__
