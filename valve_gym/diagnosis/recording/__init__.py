"""Load a control-loop recording (CSV or Parquet) for the diagnosis tool.

A *recording* is a sampled control loop: the controller output ``op``, the
process variable ``pv``, optionally the set point ``sp`` and the valve stem
position ``mv``, on a uniform time grid.  :func:`load_recording` reads a CSV
or Parquet file, finds the columns, checks every value, repairs what can be
repaired safely (short gaps, non-finite or absurd values in them, small
time-stamp jitter, exact duplicate rows, values a hair outside the stated
range), conditions a very long record to the sample time its dynamics need,
and records each repair in :attr:`Recording.repairs`.  Anything it cannot
repair safely raises :class:`RecordingError` with a message that names the
file, the column, the lines, the problem and what to do about it.

The loader is made of parts that can be read and tested alone:

========================  ===================================================
:mod:`.sniff`             format (CSV / Parquet), encoding, delimiter, header
:mod:`.columns`           role -> column mapping (:class:`ColumnMap`)
:mod:`.read`              the mapped columns as read (:class:`RawColumns`)
:mod:`.parse`             cells to numbers and seconds (:class:`Parsed`)
:mod:`.validate`          options, time order, absurd values, ranges
:mod:`.repair`            duplicates, uniform grid, gaps (:class:`Grid`)
:mod:`.decimate`          long records: decimation, window (:class:`Conditioning`)
:mod:`.record`            the :class:`Recording` record
:mod:`.loader`            :func:`load_recording`, the steps in order
:mod:`.wide`              a historian's wide export: each tag read onto its own grid
========================  ===================================================

Real recordings shipped with the package (see ``valve_gym/data/README.md``)
are located with :func:`data_path`.

Examples
--------
>>> from valve_gym.diagnosis.recording import data_path, load_recording
>>> rec = load_recording(data_path("cascaded_tanks/estimation.csv"),
...                      columns={"t": "t_s", "op": "u_V", "pv": "y_V"},
...                      op_range=(0, 10))
>>> len(rec), rec.dt, rec.op_range
(1024, 4.0, (0.0, 10.0))
>>> round(float(rec.op.max()), 4)   # pump voltage 6.4712 V of 0..10 V
0.6471
>>> rec.sp is None, rec.repairs
(True, ())
"""

from __future__ import annotations

from ._base import DEFAULT_COLUMN_NAMES, MIN_SAMPLES, ROLES, RecordingError
from .columns import ColumnMap, parse_columns, resolve_columns
from .data import data_path
from .decimate import DEFAULT_MAX_SAMPLES, Conditioning, condition
from .loader import load_recording
from .record import Recording
from .validate import parse_range

__all__ = [
    "MIN_SAMPLES",
    "ROLES",
    "DEFAULT_COLUMN_NAMES",
    "DEFAULT_MAX_SAMPLES",
    "ColumnMap",
    "Conditioning",
    "Recording",
    "RecordingError",
    "condition",
    "data_path",
    "load_recording",
    "parse_columns",
    "parse_range",
    "resolve_columns",
]
