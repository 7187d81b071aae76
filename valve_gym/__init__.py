"""valve_gym: sticky control valves in a level loop.

One batched physics core (:mod:`valve_gym.core`) with the valve model of
Riihilahti / Yamé & El Bahir and optional physics blocks
(:mod:`valve_gym.params`), friction models sized by stick band and slip jump
(:mod:`valve_gym.friction`: none, Riihilahti, Choudhury, Kano, Karnopp), the
plant stepper the benchmark and the envs share (:mod:`valve_gym.plant`), loop
metrics (:mod:`valve_gym.metrics`), YAML configuration
(:mod:`valve_gym.config`), Gymnasium environments (:mod:`valve_gym.envs`,
registered on import: :data:`ENV_IDS`), the controllers and the benchmark
(:mod:`valve_gym.agents`) and the diagnosis tool (:mod:`valve_gym.diagnosis`).

The import is light: it registers the environments with Gymnasium and loads
every other module (and numba) on first use.

>>> import gymnasium as gym
>>> import valve_gym
>>> env = gym.make("valve_gym/ValveTank-v0")
>>> envs = gym.make_vec("valve_gym/ValveTank-v0", num_envs=8, vectorization_mode="vector_entry_point")
>>> envs.num_envs, envs.metadata["autoreset_mode"].name
(8, 'NEXT_STEP')
"""
from __future__ import annotations

import importlib as _importlib

from ._registration import ENV_IDS, register_envs
from ._version import __version__

__all__ = [
    # physics: parameters, the one batched core, friction models, the plant stepper
    "ModelParams", "ValveParams", "TankParams", "SlipJump", "ParameterError",
    "simulate", "step", "initial_state", "steady_input",
    "FRICTION_MODELS", "friction_spec", "valve_model", "Plant", "PlantOutput",
    # configuration and environments
    "EnvConfig", "ConfigError", "load_config", "ValveTankEnv", "ValveTankVectorEnv", "ENV_IDS",
    "register_envs",
    # modules
    "metrics",
    "__version__",
]

#: name -> module that defines it, imported on first access (PEP 562)
_LAZY = {
    "ConfigError": "config", "EnvConfig": "config", "load_config": "config",
    "initial_state": "core", "simulate": "core", "steady_input": "core", "step": "core",
    "ValveTankEnv": "envs", "ValveTankVectorEnv": "envs",
    "FRICTION_MODELS": "friction", "friction_spec": "friction", "valve_model": "friction",
    "ModelParams": "params", "ParameterError": "params", "SlipJump": "params", "TankParams": "params",
    "ValveParams": "params",
    "Plant": "plant", "PlantOutput": "plant",
}
_SUBMODULES = {"agents", "config", "control", "core", "diagnosis", "effects", "envs", "figures", "fleet",
               "friction", "lab", "metrics", "params", "plant", "signals"}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(_importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return _importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__) | _SUBMODULES)


register_envs()
