"""The teaching lab: the paper's valve, its level loop and the friction compensators, live in a browser.

``valve-gym lab`` serves it (:mod:`valve_gym.lab.cli`); in a notebook::

    import valve_gym.lab
    valve_gym.lab.build_app()          # displays the three pages

The experiments are :class:`param.Parameterized` objects of
:mod:`valve_gym.lab.models` (no browser needed); the pages are built by
:mod:`valve_gym.lab.app` with Panel and Bokeh (``pip install "valve_gym[lab]"``).
"""
from __future__ import annotations

__all__ = ["build_app", "valve_page", "loop_page", "compensator_page", "ValveLab", "LoopLab", "CompensatorLab"]

_LAZY = {"build_app": "app", "valve_page": "app", "loop_page": "app", "compensator_page": "app",
         "ValveLab": "models", "LoopLab": "models", "CompensatorLab": "models"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        from ._need import need_panel

        need_panel()
        mod = importlib.import_module(f".{_LAZY[name]}", __name__)
        return getattr(mod, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
