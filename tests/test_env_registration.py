"""The registration that ``import valve_gym`` does: light, complete, and in step with the env configs."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym

import valve_gym
from valve_gym._registration import ENV_IDS, MAX_EPISODE_STEPS_BY_ID


def test_every_id_is_registered_with_the_configs_time_limit():
    from valve_gym.config import EnvConfig, preset
    from valve_gym.envs.family_env import FamilyConfig
    from valve_gym.envs.regulation import RegulationTaskConfig

    expected = {"valve_gym/ValveTank-v0": EnvConfig().episode_steps,
                "valve_gym/ValveTankFixed-v0": preset("fixed").episode_steps,
                "valve_gym/ValveTankRegulation-v0": RegulationTaskConfig().steps,
                "valve_gym/ValveFamilyRegulation-v0": FamilyConfig().steps}
    assert set(ENV_IDS) == set(expected) == set(MAX_EPISODE_STEPS_BY_ID)
    for env_id, steps in expected.items():
        assert gym.spec(env_id).max_episode_steps == steps == MAX_EPISODE_STEPS_BY_ID[env_id], env_id


def test_import_is_light_and_reads_no_argv():
    code = ("import sys; sys.argv = ['valve-gym']; import valve_gym; "
            "heavy = [m for m in ('numba', 'valve_gym.core', 'valve_gym.envs', 'valve_gym.agents', 'torch', "
            "'ray', 'stable_baselines3', 'scipy', 'pandas', 'matplotlib') if m in sys.modules]; print(heavy)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"
    assert "valve_gym/ValveTank-v0" in subprocess.run(
        [sys.executable, "-c", "import gymnasium, valve_gym; print(list(gymnasium.registry))"],
        capture_output=True, text=True, timeout=120).stdout


def test_lazy_names_resolve_and_unknown_names_fail():
    assert valve_gym.ValveParams.__name__ == "ValveParams"
    assert valve_gym.metrics.__name__ == "valve_gym.metrics"
    assert sorted(set(valve_gym.__all__) - set(dir(valve_gym))) == []
    try:
        valve_gym.no_such_name  # noqa: B018
    except AttributeError as e:
        assert "no_such_name" in str(e)
    else:
        raise AssertionError("an unknown attribute must raise AttributeError")


def test_no_top_level_agents_package_is_installed():
    import importlib.util
    import pathlib

    root = pathlib.Path(valve_gym.__file__).resolve().parents[1]
    assert not (root / "agents").exists()
    spec = importlib.util.find_spec("valve_gym.agents")
    assert spec is not None and spec.origin is not None and "valve_gym" in spec.origin


def test_a_command_whose_extra_is_missing_names_the_extra(monkeypatch, capsys):
    import builtins

    from valve_gym import cli

    real = builtins.__import__

    def no_sb3(name, *a, **k):
        if name.split(".")[0] == "stable_baselines3":
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return real(name, *a, **k)

    for mod in [m for m in sys.modules if m.startswith(("valve_gym.agents.train", "valve_gym.agents.ppo"))]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setattr(builtins, "__import__", no_sb3)
    import valve_gym.agents.ppo as ppo  # the policy files and the numpy controller import without SB3

    assert callable(ppo.load_policy)
    cfg = str(Path(__file__).resolve().parents[1] / "configs" / "rl" / "ppo.yaml")
    assert cli.main(["train", "--config", cfg, "--out", "/tmp/valve_gym_never_written"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == ("valve-gym train: this needs stable_baselines3, which the core install leaves out: "
                           'pip install "valve_gym[rl]"')
