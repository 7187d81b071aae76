"""The one check for the lab's optional dependencies (Panel, Bokeh, param)."""
from __future__ import annotations

import importlib.util

__all__ = ["MISSING", "need_panel"]

#: The line shown when the lab's dependencies are missing.
MISSING = 'the teaching lab needs Panel and Bokeh: pip install "valve_gym[lab]"'


def need_panel() -> None:
    """Raise ImportError with :data:`MISSING` when panel, bokeh or param is not installed."""
    for mod in ("panel", "bokeh", "param"):
        if importlib.util.find_spec(mod) is None:
            raise ImportError(MISSING)
