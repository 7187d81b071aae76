"""valve_gym: sticky control valves in a level loop.

One batched physics core (:mod:`valve_gym.core`) with the valve model of
Riihilahti / Yamé & El Bahir and optional physics blocks
(:mod:`valve_gym.params`), the batched PI law (:mod:`valve_gym.control`),
loop metrics (:mod:`valve_gym.metrics`), YAML configuration
(:mod:`valve_gym.config`) and Gymnasium environments (:mod:`valve_gym.envs`),
registered on import as ``valve_gym/ValveTank-v0`` and
``valve_gym/ValveTankFixed-v0``.

>>> import gymnasium as gym
>>> import valve_gym
>>> env = gym.make("valve_gym/ValveTank-v0")
>>> envs = gym.make_vec("valve_gym/ValveTank-v0", num_envs=8, vectorization_mode="vector_entry_point")
>>> envs.num_envs, envs.metadata["autoreset_mode"].name
(8, 'NEXT_STEP')
"""
from __future__ import annotations

from . import metrics
from .config import (
    ConfigError,
    EnvConfig,
    LoadSchedule,
    PISettings,
    RewardWeights,
    SetpointSchedule,
    ValveRandomisation,
    config_to_dict,
    load_config,
    save_config,
)
from .control import PIParams, PIState, pi_init, pi_step
from .core import Packed, State, Trajectory, check_dt, initial_state, pack, run_packed, simulate, steady_input, step
from .envs import ENV_IDS, ValveTankEnv, ValveTankVectorEnv, register_envs
from .params import (
    EFFECTS,
    PROCESSES,
    Actuator,
    Cascade,
    DeadTime,
    FirstOrderParams,
    IntegratingParams,
    Leak,
    ModelParams,
    OscillatingDisturbance,
    Overflow,
    ParameterError,
    SensorLag,
    SlipJump,
    TankParams,
    ValveCharacteristic,
    ValveParams,
)

__version__ = "0.1.0"

__all__ = [
    # physics
    "ModelParams", "ValveParams", "TankParams", "IntegratingParams", "FirstOrderParams",
    "SlipJump", "ValveCharacteristic", "DeadTime", "Overflow", "Leak", "SensorLag",
    "OscillatingDisturbance", "Cascade", "Actuator", "EFFECTS", "PROCESSES", "ParameterError",
    "State", "Trajectory", "Packed", "pack", "initial_state", "steady_input", "step", "simulate",
    "run_packed", "check_dt",
    # control
    "PIParams", "PIState", "pi_init", "pi_step",
    # configuration
    "EnvConfig", "ValveRandomisation", "SetpointSchedule", "LoadSchedule", "PISettings",
    "RewardWeights", "ConfigError", "load_config", "config_to_dict", "save_config",
    # environments
    "ValveTankEnv", "ValveTankVectorEnv", "ENV_IDS", "register_envs",
    # modules
    "metrics",
    "__version__",
]

register_envs()
