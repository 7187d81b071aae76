"""Plant-scale diagnosis: valve_gym's one batch engine, a fleet of loops ranked into a worklist.

``valve-gym diagnose DIR [--out OUT] [--jobs N] [--ray | --address ADDR]`` runs
:func:`run_fleet`: every loop of a folder (one CSV per loop) or of a
historian's wide export (``TAG.PV``, ``TAG.OP``, ``TAG.SP``, ``TAG.MODE``) is
screened (oscillation index, Horch's test), diagnosed in full where it
oscillates, and (with ``--out``) written as it finishes; ``loops.csv`` (and
``loops.parquet`` with pyarrow) hold one row per loop and
``worklist.md``/``worklist.html`` rank the loops by the cost of stiction with a
recommended action.  The loops run without Ray by default (this process, or
local worker processes), on Ray when asked.  See ``docs/fleet.md``.

Public API
----------
run_fleet, FleetRun
    run a fleet locally (no Ray) or on Ray (in this process, or on a cluster), resumable.
FleetSettings, LoopResult, TABLE_COLUMNS
    the settings of a run and one loop's typed result.
discover_loops, load_loop, LoopSource, resample_loop
    find the loops of a folder or a wide export; read one.
analyse_loop
    one loop's work (what each worker runs).
screen_recording
    the fast screening stage (the oscillation detector's "screen" rule, Horch's test).
write_worklist, RULES
    the ranked worklist and its action table.
"""
from .actions import RULES, evidence_weight, recommend, score
from .analyse import analyse_loop, stiction_numbers
from .result import TABLE_COLUMNS, FleetSettings, LoopResult, loop_key
from .runner import FleetRun, run_fleet
from .screen import screen_recording
from .sources import LoopSource, discover_loops, load_loop, resample_loop
from .worklist import write_worklist

__all__ = ["run_fleet", "FleetRun", "FleetSettings", "LoopResult", "TABLE_COLUMNS", "loop_key",
           "discover_loops", "load_loop", "LoopSource", "resample_loop", "analyse_loop", "stiction_numbers",
           "screen_recording", "write_worklist", "RULES", "evidence_weight", "recommend",
           "score"]
