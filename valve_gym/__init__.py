"""valve_gym: sticky control valves in a level loop.

One batched physics core (:mod:`valve_gym.core`) with the valve model of
Riihilahti / Yamé & El Bahir and optional physics blocks
(:mod:`valve_gym.params`), friction models sized by stick band and slip jump
(:mod:`valve_gym.friction`: none, Riihilahti, Choudhury, Kano, Karnopp), the
plant stepper the benchmark and the envs share (:mod:`valve_gym.plant`), loop
metrics (:mod:`valve_gym.metrics`), YAML configuration
(:mod:`valve_gym.config`) and Gymnasium environments (:mod:`valve_gym.envs`),
registered on import (:data:`ENV_IDS`). Less used names live in their modules.

>>> import gymnasium as gym
>>> import valve_gym
>>> env = gym.make("valve_gym/ValveTank-v0")
>>> envs = gym.make_vec("valve_gym/ValveTank-v0", num_envs=8, vectorization_mode="vector_entry_point")
>>> envs.num_envs, envs.metadata["autoreset_mode"].name
(8, 'NEXT_STEP')
"""
from __future__ import annotations

import sys as _sys

from ._startup import quiet_interrupt_while_loading

quiet_interrupt_while_loading(_sys.argv)   # the ``valve-gym`` command: Ctrl-C while this package loads

from . import metrics  # noqa: E402
from .config import ConfigError, EnvConfig, load_config  # noqa: E402
from .core import initial_state, simulate, steady_input, step  # noqa: E402
from .envs import ENV_IDS, ValveTankEnv, ValveTankVectorEnv, register_envs  # noqa: E402
from .friction import FRICTION_MODELS, friction_spec, valve_model  # noqa: E402
from .params import ModelParams, ParameterError, SlipJump, TankParams, ValveParams  # noqa: E402
from .plant import Plant, PlantOutput  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    # physics: parameters, the one batched core, friction models, the plant stepper
    "ModelParams", "ValveParams", "TankParams", "SlipJump", "ParameterError",
    "simulate", "step", "initial_state", "steady_input",
    "FRICTION_MODELS", "friction_spec", "valve_model", "Plant", "PlantOutput",
    # configuration and environments
    "EnvConfig", "ConfigError", "load_config", "ValveTankEnv", "ValveTankVectorEnv", "ENV_IDS",
    # modules
    "metrics",
    "__version__",
]

register_envs()
