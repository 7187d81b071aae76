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
``valve_gym/ValveFamilyRegulation-v0``
    The same block on the randomised family of plants, valves, scans, loads and noise that
    ``learned`` is trained on, one loop per episode (:class:`ValveFamilyRegulationEnv`,
    :mod:`valve_gym.envs.family_env`).

The first two truncate after 600 steps (``max_episode_steps``) and support
``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``.
:class:`~valve_gym.envs.sb3.SB3VecEnv` (imported on first use, it needs
stable-baselines3) adapts the vector env to Stable-Baselines3.
"""
from __future__ import annotations

from .family_env import ValveFamilyRegulationEnv, ValveFamilyRegulationVectorEnv
from .regulation_env import ValveTankRegulationEnv, ValveTankRegulationVectorEnv
from .valve_tank import ValveTankEnv, draw_episodes, make_config
from .vector import ValveTankVectorEnv

__all__ = ["ValveTankEnv", "ValveTankVectorEnv", "ValveTankRegulationEnv", "ValveTankRegulationVectorEnv",
           "ValveFamilyRegulationEnv", "ValveFamilyRegulationVectorEnv",
           "SB3VecEnv", "register_envs", "ENV_IDS",
           "draw_episodes", "make_config"]

from .._registration import ENV_IDS, register_envs


def __getattr__(name):
    if name == "SB3VecEnv":
        from .sb3 import SB3VecEnv

        return SB3VecEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
