"""Tests of valve_gym.config: YAML onto frozen dataclasses, and every bad-input case."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from valve_gym.config import (
    ConfigError,
    EnvConfig,
    ValveRandomisation,
    config_to_dict,
    load_config,
    preset,
    save_config,
)
from valve_gym.params import DeadTime, IntegratingParams, ModelParams, SensorLag, TankParams, ValveParams

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


# --------------------------------------------------------------------------- files
def test_default_yaml_equals_dataclass_defaults():
    path = CONFIGS / "env_default.yaml"
    assert load_config(path) == EnvConfig()
    # the file spells out every key, with the default value
    assert yaml.safe_load(path.read_text()) == config_to_dict(EnvConfig())


def test_fixed_yaml_equals_fixed_preset():
    cfg = load_config(CONFIGS / "env_fixed.yaml")
    assert cfg == preset("fixed")
    assert not cfg.randomise.enabled
    assert (cfg.model.valve.z_max, cfg.model.valve.e_dead) == (0.1, 0.01)


def test_defaults_are_the_documented_model():
    cfg = EnvConfig()
    p = cfg.model.process
    assert (p.area, p.q_max, p.k_out, p.level0) == (0.2, 0.01, 0.005, 1.0)
    assert (cfg.model.valve.tau, cfg.model.valve.v_max, cfg.model.dt) == (0.1, 0.5, 0.02)
    assert cfg.substeps == 50 and cfg.episode_steps == 600
    assert cfg.randomise.z_max == (0.002, 0.5)
    assert cfg.noise_std == 0.002 and cfg.pi.Kc == 1.0 and cfg.pi.Ti == 30.0


# --------------------------------------------------------------------------- mapping
def test_nested_mapping_and_optional_blocks_by_name():
    cfg = load_config({"model": {"valve": {"tau": 0.15}, "sensor_lag": {"tau_s": 3.0},
                                 "dead_time": True},
                       "control_period": 0.5, "randomise": {"tau": [0.1, 0.2]}})
    assert cfg.model.valve == ValveParams(tau=0.15)
    assert cfg.model.sensor_lag == SensorLag(tau_s=3.0)
    assert cfg.model.dead_time == DeadTime()
    assert cfg.substeps == 25
    assert cfg.randomise.tau == (0.1, 0.2)
    assert cfg.randomise.z_max == ValveRandomisation().z_max  # untouched keys keep defaults


def test_process_follows_process_kind():
    cfg = load_config({"model": {"process_kind": "integrating", "process": {"q_out": 0.2}}},
                      base=EnvConfig())
    assert isinstance(cfg.model.process, IntegratingParams)
    assert cfg.model.process.q_out == 0.2
    m = load_config({"process": {"area": 0.5}}, cls=ModelParams)
    assert m.process == TankParams(area=0.5)


def test_base_overlay_and_round_trip(tmp_path):
    base = preset("fixed")
    cfg = load_config({"noise_std": 0.001}, base=base)
    assert cfg.noise_std == 0.001 and cfg.model.valve.z_max == 0.1
    full = load_config({"model": {"leak": {"q_leak": 0.0002}, "sensor_lag": {"tau_s": 2.0}},
                        "action_mode": "residual", "measure_stem": True})
    assert load_config(config_to_dict(full)) == full
    out = tmp_path / "used.yaml"
    save_config(full, out)
    assert load_config(out) == full


def test_null_switches_block_off():
    cfg = load_config({"model": {"sensor_lag": None}},
                      base=load_config({"model": {"sensor_lag": {"tau_s": 2.0}}}))
    assert cfg.model.sensor_lag is None


# --------------------------------------------------------------------------- errors
def _err(data, **kw):
    with pytest.raises(ConfigError) as ei:
        load_config(data, **kw)
    return str(ei.value)


def test_config_error_is_value_error():
    assert issubclass(ConfigError, ValueError)


def test_unknown_key_names_full_path_and_suggests():
    msg = _err({"model": {"valve": {"tua": 0.2}}})
    assert "'model.valve.tua'" in msg and "did you mean 'tau'" in msg
    msg = _err({"setpoint": {"intervall": [1.0, 2.0]}})
    assert "'setpoint.intervall'" in msg and "'interval'" in msg
    assert "'episode_second'" in _err({"episode_second": 10.0})
    assert "'model.sensor_lag.tau'" in _err({"model": {"sensor_lag": {"tau": 1.0}}})


def test_string_number_says_write_with_a_dot():
    msg = _err({"model": {"valve": {"z_max": "1e-3"}}})
    assert "model.valve.z_max" in msg and "1.0e-3" in msg
    # as PyYAML really reads it
    data = yaml.safe_load("noise_std: 2e-3\n")
    assert isinstance(data["noise_std"], str)
    msg = _err(data)
    assert "noise_std" in msg and "2.0e-3" in msg
    assert "model.dt" in _err({"model": {"dt": "fast"}})
    assert "randomise.z_max[1]" in _err({"randomise": {"z_max": [0.001, "5e-1"]}})


@pytest.mark.parametrize("data, path", [
    ({"model": {"valve": {"tau": True}}}, "model.valve.tau"),
    ({"model": {"valve": [0.1]}}, "model.valve"),
    ({"measure_stem": "yes"}, "measure_stem"),
    ({"action_mode": 1}, "action_mode"),
    ({"randomise": {"tau": 0.1}}, "randomise.tau"),
    ({"randomise": {"tau": [0.1, 0.2, 0.3]}}, "randomise.tau"),
    ({"action_mode": "resid"}, "action_mode"),
    ({"model": {"valve_characteristic": {"kind": "square"}}}, "model.valve_characteristic.kind"),
    ({"model": {"process_kind": "pond"}}, "model.process_kind"),
])
def test_wrong_type_names_path(data, path):
    assert path in _err(data)


def test_negative_time_constants():
    assert "model.valve.tau" in _err({"model": {"valve": {"tau": -0.1}}})
    assert "randomise.tau" in _err({"randomise": {"tau": [-0.1, 0.2]}})
    assert "model.sensor_lag.tau_s" in _err({"model": {"sensor_lag": {"tau_s": -1.0}}})
    assert "pi.Ti" in _err({"pi": {"Ti": 0.0}})
    assert "control_period" in _err({"control_period": -1.0})


def test_negative_z_max():
    assert "model.valve.z_max" in _err({"model": {"valve": {"z_max": -0.01}}})
    assert "randomise.z_max" in _err({"randomise": {"z_max": [-0.01, 0.5]}})
    # log-uniform needs a positive low end
    assert "randomise.z_max" in _err({"randomise": {"z_max": [0.0, 0.5]}})
    assert load_config({"randomise": {"z_max": [0.0, 0.0]}}).randomise.z_max == (0.0, 0.0)


def test_unstable_dt():
    msg = _err({"model": {"dt": 0.5, "valve": {"tau": 0.1}}, "control_period": 1.0,
                "randomise": {"enabled": False}})
    assert "model.dt" in msg and "0.1" in msg
    # the randomised valve may be faster than the nominal one
    msg = _err({"randomise": {"tau": [0.01, 0.2]}})
    assert "model.dt" in msg and "randomise.tau" in msg


def test_periods_must_divide():
    assert "control_period" in _err({"control_period": 0.03})
    assert "episode_seconds" in _err({"episode_seconds": 10.5})


def test_ranges_checked():
    assert "setpoint.initial" in _err({"setpoint": {"initial": [1.3, 0.7]}})
    assert "setpoint.initial" in _err({"setpoint": {"initial": [0.2, 1.0]}})  # outside limits
    assert "load.magnitude" in _err({"load": {"magnitude": [-0.001, 0.001]}})
    assert "reward.error_scale" in _err({"reward": {"error_scale": 0.0}})
    assert "setpoint.interval" in _err({"setpoint": {"interval": [0.5, 2.0]}})


def test_file_errors(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("model:\n  valve:\n    tua: 0.2\n")
    msg = _err(bad)
    assert "model.valve.tua" in msg and "bad.yaml" in msg
    assert "does not exist" in _err(tmp_path / "missing.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    assert "mapping" in _err(tmp_path / "list.yaml")
    (tmp_path / "empty.yaml").write_text("")
    with pytest.raises(ConfigError, match="is empty"):          # a mistake, not a request for the defaults
        load_config(tmp_path / "empty.yaml")
    assert load_config(None) == EnvConfig()


def test_direct_construction_validates():
    with pytest.raises(ConfigError, match="control_period"):
        EnvConfig(control_period=0.0)
    with pytest.raises(ConfigError, match="scalars"):
        import numpy as np
        EnvConfig(model=ModelParams(valve=ValveParams(z_max=np.array([0.1, 0.2]))))
    with pytest.raises(ConfigError, match="unknown preset"):
        preset("teaching")
