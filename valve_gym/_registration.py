"""Gymnasium registration of valve_gym's environments, without importing them.

``import valve_gym`` calls :func:`register_envs`, which imports only Gymnasium: the entry points are
strings, so the numba core and the env modules load on the first ``gymnasium.make``. The time limits
are written here as numbers; ``tests/test_env_registration.py`` checks them against the env configs.
"""
from __future__ import annotations

__all__ = ["ENV_IDS", "MAX_EPISODE_STEPS_BY_ID", "register_envs"]

#: The registered environment ids.
ENV_IDS = ("valve_gym/ValveTank-v0", "valve_gym/ValveTankFixed-v0", "valve_gym/ValveTankRegulation-v0",
           "valve_gym/ValveFamilyRegulation-v0")

#: ``max_episode_steps`` of each id: ``EnvConfig().episode_steps``, ``preset("fixed").episode_steps`` and
#: ``RegulationTaskConfig().steps`` and ``FamilyConfig().steps`` (checked by the tests).
MAX_EPISODE_STEPS_BY_ID = {
    "valve_gym/ValveTank-v0": 600,
    "valve_gym/ValveTankFixed-v0": 600,
    "valve_gym/ValveTankRegulation-v0": 1800,
    "valve_gym/ValveFamilyRegulation-v0": 1200,
}

_ENTRY = {
    "valve_gym/ValveTank-v0": ("valve_gym.envs.valve_tank:ValveTankEnv", "valve_gym.envs.vector:ValveTankVectorEnv",
                               {}),
    "valve_gym/ValveTankFixed-v0": ("valve_gym.envs.valve_tank:ValveTankEnv",
                                    "valve_gym.envs.vector:ValveTankVectorEnv", {"preset": "fixed"}),
    "valve_gym/ValveTankRegulation-v0": ("valve_gym.envs.regulation_env:ValveTankRegulationEnv",
                                         "valve_gym.envs.regulation_env:ValveTankRegulationVectorEnv", {}),
    "valve_gym/ValveFamilyRegulation-v0": ("valve_gym.envs.family_env:ValveFamilyRegulationEnv",
                                           "valve_gym.envs.family_env:ValveFamilyRegulationVectorEnv", {}),
}


def register_envs() -> None:
    """Register :data:`ENV_IDS` with Gymnasium (idempotent)."""
    import gymnasium

    for env_id in ENV_IDS:
        if env_id in gymnasium.registry:
            continue
        entry, vector_entry, kwargs = _ENTRY[env_id]
        gymnasium.register(id=env_id, entry_point=entry, vector_entry_point=vector_entry,
                           max_episode_steps=MAX_EPISODE_STEPS_BY_ID[env_id], kwargs=dict(kwargs))
