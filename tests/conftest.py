"""Fixtures shared by several test files."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def load_repo_module(relpath: str, name: str, keep: bool = False):
    """The repository file ``relpath`` (a benchmark script, a docs example) imported as module ``name``.

    ``keep``: registered in ``sys.modules`` and imported once (for a file whose import registers something).
    """
    if keep and name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, ROOT / relpath)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    if keep:
        sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="session")
def repo_module():
    """:func:`load_repo_module`, for the tests of the benchmark scripts and the docs' examples."""
    return load_repo_module


@pytest.fixture(scope="session")
def he_model():
    """docs/examples/he_friction.py (a friction model with a per-scan law), imported once: it registers 'he'."""
    return load_repo_module("docs/examples/he_friction.py", "valve_gym_docs_he_friction", keep=True)


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
