"""Compatibility module: the benchmark lives in :mod:`agents.bench` (``valve-gym benchmark``).

``run_benchmark``, ``load_benchmark_config`` (= :func:`agents.bench.config.load_bench_config`) and ``main``
are re-exported for code that imported them from here.
"""
from __future__ import annotations

from .bench.cli import main
from .bench.config import load_bench_config as load_benchmark_config
from .bench.pipeline import run_benchmark

__all__ = ["main", "run_benchmark", "load_benchmark_config"]
