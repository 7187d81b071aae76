"""Compatibility module: the benchmark lives in :mod:`agents.bench` (``valve-gym benchmark``).

``run_benchmark``, ``load_benchmark_config`` and ``main`` are the new ones;
``_readable`` and ``_atomic_write_text`` remain for callers that still import them.
"""
from __future__ import annotations

import os
from pathlib import Path

from valve_gym._io import write_atomic

from .bench.cli import main
from .bench.config import load_bench_config as load_benchmark_config
from .bench.pipeline import run_benchmark

__all__ = ["main", "run_benchmark", "load_benchmark_config"]


def _readable(path: str) -> None:
    """Give a written file the usual permissions under the umask."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(path, 0o666 & ~mask)


def _atomic_write_text(path: Path, text: str) -> None:
    data = text.encode("utf-8")
    write_atomic(path, lambda f: f.write(data))
