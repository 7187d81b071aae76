"""The compensator benchmark (``valve-gym benchmark``): scenarios -> runs -> scores -> report -> figures.

==========================  ==========================================================
:mod:`.config`              :class:`BenchConfig` and :func:`load_bench_config` (YAML)
:mod:`.scenarios`           :func:`regulation_scenarios`, :func:`servo_scenarios`
:mod:`.runner`              :func:`run_loops` (one block on all loops, batched), line-up
:mod:`.scores`              per-loop scores, compensation ratio, bootstrap CIs
:mod:`.pipeline`            :func:`run_benchmark` (every controller, both parts)
:mod:`.report`              ``results.md``, ``results.csv``, ``loops.csv``, ``config.yaml``
:mod:`.figures`             trends, bands, Pareto plot (matplotlib, lazily)
:mod:`.cli`                 ``main(argv)``
==========================  ==========================================================
"""
from .config import BenchConfig, load_bench_config
from .runner import Runs, run_loops
from .scenarios import Scenarios, regulation_scenarios, servo_scenarios

__all__ = ["BenchConfig", "load_bench_config", "Scenarios", "regulation_scenarios", "servo_scenarios", "Runs",
           "run_loops"]
