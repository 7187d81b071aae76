"""Gymnasium environments of valve_gym and their registration.

Registered ids (after ``import valve_gym``, or as ``"valve_gym:<id>"`` without it):

``valve_gym/ValveTank-v0``
    Level control through a valve whose friction is drawn each episode
    (:class:`ValveTankEnv`, native vector env :class:`ValveTankVectorEnv`).
``valve_gym/ValveTankFixed-v0``
    The same task with one fixed sticky valve and deterministic episodes, for
    teaching and debugging (``preset='fixed'``).
``valve_gym/ValveTankRegulation-v0``
    Regulation at a constant set point with a randomised sticky valve, OU load and noise
    (:class:`ValveTankRegulationEnv`, native vector env :class:`ValveTankRegulationVectorEnv`);
    the agent is the inside of a PI block (task rules in :mod:`valve_gym.envs.regulation`).

The first two truncate after 600 steps (``max_episode_steps``) and support
``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``.
:class:`~valve_gym.envs.sb3.SB3VecEnv` (imported on first use, it needs
stable-baselines3) adapts the vector env to Stable-Baselines3.
"""
from __future__ import annotations

from .regulation_env import ValveTankRegulationEnv, ValveTankRegulationVectorEnv
from .valve_tank import ValveTankEnv, draw_episodes, make_config
from .vector import ValveTankVectorEnv

__all__ = ["ValveTankEnv", "ValveTankVectorEnv", "ValveTankRegulationEnv", "ValveTankRegulationVectorEnv",
           "SB3VecEnv", "register_envs", "ENV_IDS",
           "draw_episodes", "make_config"]

#: The registered environment ids.
ENV_IDS = ("valve_gym/ValveTank-v0", "valve_gym/ValveTankFixed-v0", "valve_gym/ValveTankRegulation-v0")


def register_envs() -> None:
    """Register :data:`ENV_IDS` with Gymnasium (idempotent)."""
    import gymnasium

    from ..config import EnvConfig, preset

    specs = {
        "valve_gym/ValveTank-v0": ({}, EnvConfig().episode_steps),
        "valve_gym/ValveTankFixed-v0": ({"preset": "fixed"}, preset("fixed").episode_steps),
    }
    for env_id, (kwargs, steps) in specs.items():
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point="valve_gym.envs.valve_tank:ValveTankEnv",
            vector_entry_point="valve_gym.envs.vector:ValveTankVectorEnv",
            max_episode_steps=steps,
            kwargs=kwargs,
        )
    if "valve_gym/ValveTankRegulation-v0" not in gymnasium.registry:
        from .regulation import RegulationConfig

        gymnasium.register(
            id="valve_gym/ValveTankRegulation-v0",
            entry_point="valve_gym.envs.regulation_env:ValveTankRegulationEnv",
            vector_entry_point="valve_gym.envs.regulation_env:ValveTankRegulationVectorEnv",
            max_episode_steps=RegulationConfig().steps,
        )


def __getattr__(name):
    if name == "SB3VecEnv":
        from .sb3 import SB3VecEnv

        return SB3VecEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
