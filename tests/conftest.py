"""Fixtures shared by several test files."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def he_model():
    """docs/examples/he_friction.py (a friction model with a per-scan law), imported once: it registers 'he'."""
    name = "valve_gym_docs_he_friction"
    if name not in sys.modules:
        path = Path(__file__).resolve().parents[1] / "docs" / "examples" / "he_friction.py"
        spec = importlib.util.spec_from_file_location(name, path)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


@pytest.fixture(scope="module")
def ray_session():
    """Ray in this process for one test module (2 CPUs), shut down after it unless it ran already."""
    ray = pytest.importorskip("ray")
    started = not ray.is_initialized()
    if started:
        ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=True,
                 logging_level="ERROR")
    yield ray
    if started:
        ray.shutdown()
