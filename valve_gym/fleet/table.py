"""The fleet table: ``loops.csv`` and ``loops.parquet``, one row per loop, written atomically.

``loops.parquet`` needs pyarrow (the ``[fleet]`` extra); a core install writes ``loops.csv`` alone.
"""
from __future__ import annotations

import importlib.util
import io
import json
import os
from collections.abc import Iterable

from .._io import write_atomic
from .result import TABLE_COLUMNS, LoopResult

__all__ = ["write_table", "read_result", "write_result", "table_frame"]


def table_frame(results: Iterable[LoopResult]):
    """The results as a :class:`pandas.DataFrame` with columns :data:`TABLE_COLUMNS` (NaN where unknown)."""
    import pandas as pd

    rows = [r.row() for r in results]
    df = pd.DataFrame(rows, columns=list(TABLE_COLUMNS))
    for c in ("S", "J", "rmse_base", "rmse_final", "oscillation", "seconds", "cpu_seconds", "p_stiction", "weight",
              "score", "regularity", "period_s", "amplitude_op", "horch_index", "dt"):
        df[c] = df[c].astype("float64")
    for c in ("n", "gaps"):
        df[c] = df[c].astype("int64")
    df["oscillating"] = df["oscillating"].astype(bool)
    return df


def write_table(results: Iterable[LoopResult], out_dir: str) -> tuple[str, str]:
    """Write ``out_dir/loops.csv`` and, where pyarrow is installed, ``out_dir/loops.parquet`` (atomic).

    Returns
    -------
    (table, csv) : the paths of ``loops.parquet`` (``loops.csv`` without pyarrow: an older
        ``loops.parquet`` there is removed, so that it cannot be read for the new table) and ``loops.csv``
    """
    df = table_frame(results)
    pq_path = os.path.join(out_dir, "loops.parquet")
    csv_path = os.path.join(out_dir, "loops.csv")
    if importlib.util.find_spec("pyarrow") is not None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pandas(df, preserve_index=False)
        write_atomic(pq_path, lambda f: pq.write_table(table, f))
    else:
        if os.path.isfile(pq_path):
            os.remove(pq_path)
        pq_path = csv_path
    text = io.StringIO()
    df.to_csv(text, index=False)
    write_atomic(csv_path, lambda f: f.write(text.getvalue().encode("utf-8")))
    return pq_path, csv_path


def write_result(res: LoopResult, path: str) -> None:
    """Write one loop's result as JSON (atomic)."""
    data = json.dumps(res.to_dict(), indent=1, allow_nan=False).encode("utf-8")
    write_atomic(path, lambda f: f.write(data))


def read_result(path: str) -> LoopResult | None:
    """A stored loop result, or None when the file is missing or unreadable (then it is recomputed)."""
    try:
        with open(path, encoding="utf-8") as f:
            return LoopResult.from_dict(json.load(f))
    except (OSError, ValueError, TypeError):
        return None
