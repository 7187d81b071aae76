"""Fixtures shared by several test files."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
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


def stick_slip_level(blk, S: float, J: float, T: int = 3000, seed: int = 0, outlet: bool = False):
    """A level held by a two-parameter stick-slip valve (a loop written here, no core code): ``(levels, S_hat)``.

    The valve fills the tank against a pumped outlet slightly above its flow at half opening, or (``outlet``)
    drains a tank fed slightly above the valve's flow at half opening; the level starts at the set point 1 and
    an outlet tank cannot drain below empty. ``S_hat`` is the block's estimate of the band, where it has one.
    """
    rng = np.random.default_rng(seed)
    x, ref, last = 0.5, 0.5, 1.0
    y, sp = 1.0, 1.0
    blk.reset(sp, y, 0.5)
    ys, shat = [], []
    for _ in range(T):
        u = blk.step(sp, y + 0.001 * rng.standard_normal())
        d = u - ref
        if abs(d) > (J if d * last > 0 else S):
            last = np.sign(d)
            x, ref = u - last * (S - J) / 2.0, u
        if outlet:
            y = max(y + (0.0052 - 0.01 * x) / 0.5, 0.0)
        else:
            y += (0.01 * x - 0.0052) / 0.5
        ys.append(y)
        state = getattr(blk, "state", None)
        shat.append(float(state.s_hat[0]) if hasattr(state, "s_hat") else np.nan)
    return np.array(ys), np.array(shat)


def check_family_starts_at_rest(sim_cls, rows: list[dict], output_above: bool = False, read: bool = False) -> None:
    """A held-out family's loops, sticky and frictionless, stay at rest at their set point for 120 s.

    ``output_above``: the sticky valves' output sits above the stem (stuck after an upward move);
    ``read``: the transmitter reads the set point within its resolution (``sim.res``).
    """
    import numpy as np

    for fr in (False, True):
        for scan in sorted({r["scan"] for r in rows}):
            sub = [r for r in rows if r["scan"] == scan]
            sim = sim_cls(sub, scan, fr)
            y0, x0, u0 = sim.reset()
            np.testing.assert_allclose(x0, [r["x0"] for r in sub])
            if output_above:
                assert fr or (u0 > x0).all()                # stuck after an upward move: the output above the stem
            for _ in range(int(120 / scan)):
                y, x = sim.step(u0, np.zeros(len(sub)))
            np.testing.assert_allclose(y, y0, atol=1e-9)
            np.testing.assert_allclose(x, x0, atol=1e-9)
            if read:
                np.testing.assert_allclose(sim.measure(y, np.zeros(len(sub))), y0, atol=sim.res.max())


@pytest.fixture(scope="session")
def stick_slip():
    """:func:`stick_slip_level`, for the tests of the controller blocks."""
    return stick_slip_level


@pytest.fixture(scope="session")
def starts_at_rest():
    """:func:`check_family_starts_at_rest`, for the tests of the held-out family scripts."""
    return check_family_starts_at_rest


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
