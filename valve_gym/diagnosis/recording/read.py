"""Reading a sniffed recording file into raw columns (one array per signal role).

Three readers share one result, :class:`RawColumns`:

* :func:`read_rows` parses every row of a CSV file with :mod:`csv` (exact line
  numbers in messages, rows with a wrong number of fields are an error);
* :func:`read_csv_columns` reads only the mapped columns of a large CSV file
  with pandas' C parser in chunks of :data:`CHUNK_ROWS` rows;
* :func:`read_parquet` reads only the mapped columns of a Parquet file, batch
  by batch.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ._base import MISSING_TOKENS, RecordingError, fmt_lines
from .columns import ColumnMap, resolve_columns
from .sniff import Sniffed, decode, sniff_dialect

__all__ = ["CHUNK_ROWS", "RawColumns", "read_columns", "read_csv_columns", "read_header", "read_parquet", "read_rows"]

#: Rows per chunk of the column-wise readers.
CHUNK_ROWS = 250_000

# pandas matches missing-value tokens exactly: the usual spellings of MISSING_TOKENS.
_NA_VALUES = sorted({v for tok in MISSING_TOKENS for v in (tok, tok.upper(), tok.capitalize())})


@dataclass(frozen=True)
class RawColumns:
    """The mapped columns of a recording file, as read.

    Attributes
    ----------
    columns : ColumnMap
        Role to column.
    data : dict of str to ndarray, shape (n,)
        Role to its cells: float64 (NaN = missing), datetime64 (Parquet time
        stamps) or object (text cells, or floats where a chunk was numeric).
    lines : ndarray of int64, shape (n,)
        1-based line number in the file (CSV) or row number (Parquet) of
        each data row.
    unit : {'line', 'row'}
        What `lines` counts, for messages.
    drop_blank : bool
        True when rows whose mapped cells are all missing are blank lines to
        drop (column-wise CSV reading keeps blank lines to count lines).
    """

    columns: ColumnMap
    data: dict[str, np.ndarray]
    lines: np.ndarray
    unit: str
    drop_blank: bool = False


def _read_text(sn: Sniffed) -> str:
    try:
        raw = sn.path.read_bytes()
    except OSError as e:
        raise RecordingError(f"{sn.src}: cannot be read ({e.strerror or e}); check the file's permissions") from None
    if not raw.strip():
        raise RecordingError(f"{sn.src}: file is empty; expected a CSV file with a header row and data rows")
    return decode(raw)[0]


def _rows(text: str, src: str, sn: Sniffed | None = None) -> tuple[list[str] | None, list[list[str]], list[int]]:
    """Header, data rows (as strings) and their file line numbers; blank rows skipped.

    With ``sn.data_line`` set (a DCS export), the lines before the header line and those
    between it and the first data line (title, descriptions, parameters) are skipped.
    """
    head, first = (sn.header_line, sn.data_line) if sn is not None and sn.data_line > 0 else (0, 0)
    preamble = first > 0
    reader = csv.reader(io.StringIO(text, newline=""),
                        sn.dialect if sn is not None and preamble else sniff_dialect(text))
    header: list[str] | None = None
    rows: list[list[str]] = []
    lines: list[int] = []
    try:
        for rec in reader:
            if not rec or all(not c.strip() for c in rec):
                continue
            if preamble and (reader.line_num < head or head < reader.line_num < first):
                continue
            if header is None:
                header = [c.strip() for c in rec]
                continue
            rows.append(rec)
            lines.append(reader.line_num)
    except csv.Error as e:
        raise RecordingError(
            f"{src}: not a valid CSV file near line {reader.line_num} ({e}); check quoting and separators"
        ) from None
    return header, rows, lines


def _check_shape(header: list[str] | None, rows: list[list[str]], lines: list[int], src: str) -> list[str]:
    """The header; rows with too many (non-blank) or too few fields are an error."""
    if header is None:
        raise RecordingError(f"{src}: file has no header row; the first line must name the columns")
    if len(header) < 2:
        raise RecordingError(
            f"{src}: only one column ({header[0]!r}) found; expected a CSV file with a header row and "
            f"comma-, semicolon- or tab-separated columns for time, controller output and process variable"
        )
    ncol = len(header)
    bad = []
    for i, (rec, ln) in enumerate(zip(rows, lines)):
        if len(rec) < ncol:
            bad.append(ln)
        elif len(rec) > ncol:
            if any(c.strip() for c in rec[ncol:]):
                bad.append(ln)
            else:
                rows[i] = rec[:ncol]
    if bad:
        raise RecordingError(
            f"{src}: the header has {ncol} columns but lines {fmt_lines(bad)} have a different number "
            f"of fields; fix or delete those lines"
        )
    if not rows:
        raise RecordingError(f"{src}: no data rows under the header; the file holds no samples")
    return header


def read_rows(sn: Sniffed, columns: Mapping[str, str | None] | None) -> RawColumns:
    """Read a CSV file row by row with :mod:`csv`.

    Parameters
    ----------
    sn : Sniffed
        A CSV file.
    columns : mapping, optional
        Role to column name (see :func:`resolve_columns`).

    Returns
    -------
    RawColumns
        Object arrays of the cells as text; exact line numbers.

    Raises
    ------
    RecordingError
        Invalid CSV, no header, one column only, rows with a different number
        of fields than the header, no data rows, or a column mapping problem.
    """
    header, rows, lines = _rows(_read_text(sn), sn.src, sn)
    header = _check_shape(header, rows, lines, sn.src)
    cmap = resolve_columns(header, columns, sn.src)
    data = {}
    for r, j in cmap.index.items():
        a = np.empty(len(rows), dtype=object)
        a[:] = [row[j] for row in rows]
        data[r] = a
    return RawColumns(cmap, data, np.asarray(lines, dtype=np.int64), "line")


def _merge(chunks: list[np.ndarray]) -> np.ndarray:
    """One array of the chunks of a column: float64 if all numeric, else object."""
    if all(c.dtype.kind in "fiub" for c in chunks):
        return np.concatenate([c.astype(np.float64, copy=False) for c in chunks]) if chunks else np.empty(0)
    return np.concatenate([c.astype(object) for c in chunks])


def _header_checks(sn: Sniffed) -> None:
    header = list(sn.header)
    if not header:
        raise RecordingError(f"{sn.src}: file has no header row; the first line must name the columns")
    if len(sn.header) < 2:
        raise RecordingError(
            f"{sn.src}: only one column ({header[0]!r}) found; expected a CSV file with a header row and "
            f"comma-, semicolon- or tab-separated columns for time, controller output and process variable"
        )


def read_csv_columns(sn: Sniffed, columns: Mapping[str, str | None] | None) -> RawColumns:
    """Read only the mapped columns of a CSV file, in chunks, with pandas' C parser.

    Parameters
    ----------
    sn : Sniffed
        A CSV file (its header and dialect from :func:`sniff`).
    columns : mapping, optional
        Role to column name.

    Returns
    -------
    RawColumns
        float64 columns where every cell is a number or a missing-value
        token, object columns otherwise; line numbers count every physical
        line after the header (blank lines are kept and dropped later, so
        quoted cells spanning lines would shift them).

    Raises
    ------
    RecordingError
        No header or one column; invalid CSV such as an unterminated quote
        (pandas' message names the place); a column mapping problem.

    Notes
    -----
    Unlike :func:`read_rows`, a line with more or fewer fields than the
    header is not rejected: its mapped cells are read as they stand (missing
    where the line is short).
    """
    import pandas as pd

    _header_checks(sn)
    cmap = resolve_columns(sn.header, columns, sn.src)
    pos = sorted(cmap.index.values())
    chunks: dict[int, list[np.ndarray]] = {j: [] for j in pos}
    d = sn.dialect
    try:
        reader = pd.read_csv(
            sn.path, sep=d.delimiter, quotechar=d.quotechar or '"', header=None, skiprows=_first_data(sn) - 1,
            usecols=pos, na_values=_NA_VALUES, keep_default_na=False, skip_blank_lines=False,
            encoding=sn.encoding, chunksize=CHUNK_ROWS, engine="c", low_memory=True,
        )
        with reader:
            for chunk in reader:
                for j in pos:
                    chunks[j].append(chunk[j].to_numpy())
    except pd.errors.EmptyDataError:
        raise RecordingError(f"{sn.src}: no data rows under the header; the file holds no samples") from None
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as e:
        msg = str(e).strip().splitlines()[-1] if str(e).strip() else type(e).__name__
        raise RecordingError(f"{sn.src}: not a valid CSV file ({msg}); check quoting and separators there, "
                             f"or read it with engine='rows' for a check of every line") from None
    data = {r: _merge(chunks[j]) for r, j in cmap.index.items()}
    n = len(data["op"])
    if n == 0:
        raise RecordingError(f"{sn.src}: no data rows under the header; the file holds no samples")
    lines = _first_data(sn) + np.arange(n, dtype=np.int64)
    return RawColumns(cmap, data, lines, "line", drop_blank=True)


def _first_data(sn: Sniffed) -> int:
    """1-based line of the first data row of a CSV file."""
    return sn.data_line if sn.data_line > 0 else sn.header_line + 1


def arrow_to_numpy(col, name: str, src: str) -> np.ndarray:
    """A pyarrow column as float64 (NaN = null), datetime64[ns] or object text."""
    import pyarrow as pa
    import pyarrow.compute as pc

    ty = col.type
    if pa.types.is_integer(ty) or pa.types.is_floating(ty) or pa.types.is_boolean(ty) or pa.types.is_decimal(ty):
        return pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False)
    if pa.types.is_timestamp(ty) or pa.types.is_date(ty):
        return _times(col)
    if pa.types.is_string(ty) or pa.types.is_large_string(ty) or pa.types.is_dictionary(ty):
        out = np.asarray(pc.fill_null(pc.cast(col, pa.string()), "").to_pylist(), dtype=object)
        return out
    raise RecordingError(
        f"{src}: column {name!r} has the Parquet type {ty}; expected numbers, time stamps or text"
    )


def _times(col) -> np.ndarray:
    """Time stamps (UTC) as datetime64[ns], nulls as NaT."""
    import pyarrow as pa
    import pyarrow.compute as pc

    return pc.cast(col, pa.timestamp("ns")).to_numpy(zero_copy_only=False).astype("datetime64[ns]")


def _pyarrow(src: str) -> None:
    """Raise RecordingError, naming the extra to install, where pyarrow (for Parquet files) is missing."""
    import importlib.util

    if importlib.util.find_spec("pyarrow") is None:
        raise RecordingError(f"{src}: reading a Parquet file needs pyarrow, which the core install leaves out: "
                             f'pip install "valve_gym[fleet]" (or export the recording as CSV)')


def read_header(sn: Sniffed) -> tuple[str, ...]:
    """Column names of a sniffed file: the CSV header row, or the schema of a Parquet file.

    Raises
    ------
    RecordingError
        A Parquet file that cannot be read, or pyarrow missing (the message names the extra).
    """
    if sn.kind != "parquet":
        return tuple(sn.header)
    _pyarrow(sn.src)
    import pyarrow.parquet as pq

    try:
        return tuple(str(n) for n in pq.read_schema(sn.path).names)
    except Exception as e:  # pyarrow raises several types for a bad file
        raise RecordingError(f"{sn.src}: not a readable Parquet file ({e}); export it again") from None


def read_parquet(sn: Sniffed, columns: Mapping[str, str | None] | None) -> RawColumns:
    """Read only the mapped columns of a Parquet file, batch by batch.

    Parameters
    ----------
    sn : Sniffed
        A Parquet file.
    columns : mapping, optional
        Role to column name.

    Returns
    -------
    RawColumns
        Row numbers (1-based) instead of line numbers.

    Raises
    ------
    RecordingError
        Not a readable Parquet file; a column of a type other than numbers,
        time stamps or text; no rows; a column mapping problem; pyarrow not installed (the
        message names the extra).
    """
    _pyarrow(sn.src)
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        pf = pq.ParquetFile(sn.path)
        header = [str(n) for n in pf.schema_arrow.names]
        cmap = resolve_columns(header, columns, sn.src)
        names = [header[j] for j in cmap.index.values()]
        parts: dict[str, list[np.ndarray]] = {r: [] for r in cmap.index}
        for batch in pf.iter_batches(batch_size=CHUNK_ROWS, columns=names):
            for r, j in cmap.index.items():
                parts[r].append(arrow_to_numpy(batch.column(batch.schema.get_field_index(header[j])),
                                                header[j], sn.src))
    except RecordingError:
        raise
    except (pa.ArrowException, OSError, UnicodeDecodeError, ValueError) as e:
        raise RecordingError(
            f"{sn.src}: not a readable Parquet file ({e}); check the file or export it again"
        ) from None
    data = {r: (np.concatenate(p) if p else np.empty(0)) for r, p in parts.items()}
    n = len(data["op"])
    if n == 0:
        raise RecordingError(f"{sn.src}: no data rows; the file holds no samples")
    return RawColumns(cmap, data, np.arange(1, n + 1, dtype=np.int64), "row")


def read_columns(sn: Sniffed, columns: Mapping[str, str | None] | None) -> RawColumns:
    """Read a sniffed file with the reader its format and engine call for.

    Parameters
    ----------
    sn : Sniffed
    columns : mapping, optional
        Role to column name.

    Returns
    -------
    RawColumns
    """
    if sn.roles:                  # the columns the format assigns; the user's mapping wins
        columns = {**dict(sn.roles), **dict(columns or {})}
    if sn.kind == "parquet":
        return read_parquet(sn, columns)
    if sn.engine == "columns":
        return read_csv_columns(sn, columns)
    return read_rows(sn, columns)
