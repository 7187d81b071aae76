"""Controllers for sticky-valve level loops and the compensator benchmark.

Controllers are DCS function blocks, built by name::

    from valve_gym.agents import load_controller, available_controllers
    ctrl = load_controller("two_move", S=0.03)   # "pi", "knocker", "constant_reinforcement", ...
    ctrl.reset(sp, pv, op)                        # bumpless start
    op = ctrl.step(sp, pv)                        # one scan (ctrl.scan_s)

(:mod:`valve_gym.agents.controllers`). RL code calls Stable-Baselines3's batched
``predict(obs, state, episode_start, deterministic) -> (actions, state)``
(:class:`Controller`); :class:`BlockPolicy` gives any block that call, so
:func:`rollout` runs blocks and PPO policies alike. The benchmark
(:func:`run_benchmark`, ``valve-gym benchmark``) drives the blocks directly.

===============================  ================================================
:func:`load_controller`          a controller block by name (settings checked)
:func:`available_controllers`    the names load_controller accepts
:class:`BlockPolicy`             SB3 ``predict`` over any controller block
:func:`default_tuning`           the plant's PI tuning (SIMC for the default tank)
:class:`PPOController`           a trained SB3 policy with its observation transform
:func:`load_policy`              a PPO policy (safetensors + JSON; never a pickle)
:func:`rollout`                  one batched episode of any controller on many valves
:func:`run_benchmark`            the compensator benchmark (``valve-gym benchmark``)
===============================  ================================================

The learned compensator is ``load_controller("learned")``
(:mod:`valve_gym.agents.learned`). Per-valve scores: :func:`valve_gym.agents.evaluate.evaluate`;
training (evolution strategies for the learned compensator, PPO for policies):
:func:`valve_gym.agents.train.train` (``valve-gym train``).

The PPO, training and benchmark parts import stable-baselines3/torch on first
use only.
"""
from .base import BlockPolicy, Controller
from .controllers import available_controllers, load_controller
from .controllers.tuning import default_tuning

__all__ = ["load_controller", "available_controllers", "BlockPolicy", "Controller", "default_tuning",
           "PPOController", "ObsTransform", "load_policy", "rollout", "Rollout",
           "run_benchmark", "load_train_config"]

_LAZY = {
    "PPOController": "ppo", "ObsTransform": "ppo", "load_policy": "ppo",
    "rollout": "evaluate", "Rollout": "evaluate",
    "run_benchmark": "bench.pipeline",
    "load_train_config": "train",
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        mod = importlib.import_module(f".{_LAZY[name]}", __name__)
        return getattr(mod, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
