"""Format sniffing: what kind of file a recording is, before it is read.

:func:`sniff` looks at the first bytes of a file only (it never reads a large
file whole) and returns a :class:`Sniffed` record: CSV (text encoding,
delimiter, header row) or Parquet (by its ``PAR1`` magic number), or raises
:class:`RecordingError` for a missing, unreadable, empty or binary file.
"""

from __future__ import annotations

import csv
import io
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..._io import not_regular_file
from ._base import RecordingError

__all__ = ["COLUMNWISE_BYTES", "DCS_EXPORT_SUFFIXES", "ENGINES", "Sniffed", "is_dcs_export", "recording_files",
           "sniff"]

#: CSV files larger than this (bytes) are read column-wise (``engine='auto'``).
COLUMNWISE_BYTES = 8 * 1024 * 1024

#: Readers :func:`load_recording` can use: ``'rows'`` parses every row with
#: the :mod:`csv` module (exact line numbers, ragged rows detected), ``'columns'``
#: reads only the mapped columns in chunks with pandas' C parser.
ENGINES = ("auto", "rows", "columns")

#: Tag-name suffixes of a DCS ``PROCESSDATA`` text export and the signal role of each: in this
#: naming (``MV`` manipulated variable, ``SV`` set value) ``MV`` is the controller output, not the
#: valve position.
DCS_EXPORT_SUFFIXES = {"MV": "op", "PV": "pv", "SV": "sp"}

_DCS_MAGIC = "PROCESSDATA"
_DATA_ROW = re.compile(r"^\s*(\d{4}-\d{2}-\d{2}|[-+]?\d)")
_PREFIX = 65536
_MAX_HEADER = 16 * 1024 * 1024
_PARQUET_MAGIC = b"PAR1"


@dataclass(frozen=True)
class Sniffed:
    """What :func:`sniff` found out about a recording file.

    Attributes
    ----------
    path : pathlib.Path
        The file.
    src : str
        The path as given, for messages.
    kind : {'csv', 'parquet'}
        File format.
    size : int
        File size in bytes.
    encoding : str or None
        Text encoding of a CSV file (``'utf-8-sig'`` or ``'latin-1'``).
    dialect : type of csv.Dialect or None
        Delimiter and quoting of a CSV file.
    header : tuple of str
        Column names (stripped), from the first non-blank row of a CSV file
        or the schema of a Parquet file; empty if a CSV prefix had none.
    header_line : int
        1-based line number of the CSV header row (0 for Parquet).
    engine : {'rows', 'columns'}
        The reader to use (see :data:`ENGINES`).
    data_line : int
        1-based line of the first data row when lines between the header and
        the data are not data (a DCS export's description and parameter lines);
        0: the data follow the header.
    roles : tuple of (role, column) pairs
        Columns the file format itself assigns to signal roles (a DCS export:
        the time stamps and ``TAG.MV``, ``TAG.PV``, ``TAG.SV``); a mapping the
        user gives wins.
    form : str
        ``'csv'``, ``'parquet'`` or ``'dcs-export'`` (a ``PROCESSDATA`` text export).
    """

    path: Path
    src: str
    kind: str
    size: int
    encoding: str | None
    dialect: Any
    header: tuple[str, ...]
    header_line: int
    engine: str
    data_line: int = 0
    roles: tuple[tuple[str, str], ...] = ()
    form: str = "csv"


def _open_prefix(path: Path, src: str) -> tuple[bytes, int]:
    """First bytes of the file and its size; errors for missing, folder, unreadable."""
    if not path.exists():
        raise RecordingError(f"{src}: file not found; check the path (relative paths start at {os.getcwd()})")
    if path.is_dir():
        raise RecordingError(f"{src}: is a folder, not a CSV file; give the path of a .csv file in it")
    why = not_regular_file(path)
    if why:  # a FIFO or a device would block the read or never end
        raise RecordingError(f"{src}: is {why.split(' is ', 1)[-1]}; give a recording file (CSV or Parquet)")
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            raw = f.read(_PREFIX)
            while b"\n" not in raw.lstrip(b"\r\n \t") and len(raw) < min(size, _MAX_HEADER):
                raw += f.read(_PREFIX)  # a very wide header: read on to its end
    except OSError as e:
        raise RecordingError(f"{src}: cannot be read ({e.strerror or e}); check the file's permissions") from None
    return raw, size


def decode(raw: bytes, partial: bool = False) -> tuple[str, str]:
    """Text of CSV bytes and the encoding used: UTF-8 (BOM allowed), else Latin-1.

    Parameters
    ----------
    raw : bytes
        File content (or its first bytes).
    partial : bool
        True when `raw` is a prefix: a multi-byte character cut at its end is
        dropped instead of switching to Latin-1.

    Returns
    -------
    text, encoding : str, str
    """
    try:
        return raw.decode("utf-8-sig"), "utf-8-sig"
    except UnicodeDecodeError as e:
        if partial and e.start >= len(raw) - 3:
            try:
                return raw[: e.start].decode("utf-8-sig"), "utf-8-sig"
            except UnicodeDecodeError:
                pass
    return raw.decode("latin-1"), "latin-1"


def sniff_dialect(text: str) -> Any:
    """The CSV dialect of a text sample (comma, semicolon or tab; excel if undecided)."""
    try:
        return csv.Sniffer().sniff(text[:8192], delimiters=",;\t")
    except csv.Error:
        return csv.excel


def _csv_header(text: str, dialect: Any) -> tuple[tuple[str, ...], int]:
    """Header cells and their 1-based line number from a CSV prefix (empty if none)."""
    reader = csv.reader(io.StringIO(text, newline=""), dialect)
    try:
        for rec in reader:
            if rec and any(c.strip() for c in rec):
                return tuple(c.strip() for c in rec), reader.line_num
    except csv.Error:
        pass
    return (), 0


def _starts_dcs_export(text: str) -> bool:
    """Whether the first non-blank line of ``text`` starts with the ``PROCESSDATA`` cell."""
    first = next((ln for ln in text.splitlines() if ln.strip()), "")
    return first.split("\t", 1)[0].strip().upper() == _DCS_MAGIC


def _dcs_export(text: str, src: str) -> tuple[tuple[str, ...], int, int, tuple[tuple[str, str], ...]] | None:
    """Header, header line, first data line and role columns of a DCS ``PROCESSDATA`` export, else None.

    The export (tab-separated) starts with a ``PROCESSDATA <tag> Data <time format>`` line and
    a line with the sampling period and start time; the line starting with ``tagname`` names
    the columns (time stamps first, then ``<tag>.MV``, ``<tag>.PV``, ``<tag>.SV``,
    ``<tag>.MODE``, ...), followed by description and parameter lines, then the data rows.
    """
    if not _starts_dcs_export(text):
        return None
    lines = text.splitlines()
    head = next((i for i, ln in enumerate(lines) if ln.split("\t")[0].strip().lower() == "tagname"), None)
    if head is None:
        raise RecordingError(f"{src}: a {_DCS_MAGIC} export without its 'tagname' line naming the columns; "
                             f"export the file again with the column names")
    header = tuple(c.strip() for c in lines[head].split("\t"))
    data = next((i for i in range(head + 1, len(lines)) if _DATA_ROW.match(lines[i])), None)
    if data is None:
        raise RecordingError(f"{src}: a {_DCS_MAGIC} export with no data rows after its header (line {head + 1})")
    roles = [("t", header[0])]
    for suffix, role in DCS_EXPORT_SUFFIXES.items():
        hits = [h for h in header[1:] if h.upper().endswith("." + suffix)]
        if len(hits) == 1:
            roles.append((role, hits[0]))
    return header, head + 1, data + 1, tuple(roles)


def is_dcs_export(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a readable file whose first non-blank line starts with ``PROCESSDATA``."""
    if not os.path.isfile(path):  # a FIFO or a device is not read (it could block)
        return False
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return False
    return _starts_dcs_export(decode(head, partial=True)[0])


def recording_files(folder: str, extra: tuple[str, ...] = ()) -> list[str]:
    """The recordings of a folder, sorted, not recursive.

    ``*.csv`` (and the suffixes in ``extra``), plus ``*.txt`` files that are DCS
    ``PROCESSDATA`` exports (other text files are left alone).
    """
    names = sorted(f for f in os.listdir(folder) if not f.startswith("."))
    paths = [os.path.join(folder, f) for f in names]
    return [p for p, f in zip(paths, names) if os.path.isfile(p) and (
        f.lower().endswith((".csv",) + extra) or (f.lower().endswith(".txt") and is_dcs_export(p)))]


def sniff(path: str | os.PathLike, engine: str = "auto") -> Sniffed:
    """Find the format of a recording file from its first bytes.

    Parameters
    ----------
    path : str or path-like
        The file.
    engine : {'auto', 'rows', 'columns'}
        Reader for CSV files; ``'auto'`` reads files above
        :data:`COLUMNWISE_BYTES` column-wise.  Parquet is always read
        column-wise.

    Returns
    -------
    Sniffed

    Raises
    ------
    RecordingError
        File missing, a folder, unreadable, empty, or binary and not Parquet.
    """
    src = os.fspath(path)
    p = Path(src)
    raw, size = _open_prefix(p, src)
    if raw.startswith(_PARQUET_MAGIC):
        return Sniffed(p, src, "parquet", size, None, None, (), 0, "columns")
    if not raw.strip() and size <= len(raw):
        raise RecordingError(f"{src}: file is empty; expected a CSV file with a header row and data rows")
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise RecordingError(
            f"{src}: UTF-16 text (a spreadsheet's 'Unicode text' export); save it as CSV in UTF-8 "
            f"(e.g. 'CSV UTF-8' in the spreadsheet's Save As) or convert it: iconv -f UTF-16 -t UTF-8")
    if b"\x00" in raw:
        raise RecordingError(
            f"{src}: not a text CSV file (binary content); if it is a spreadsheet, export it as CSV "
            f"(or save the table as Parquet)"
        )
    text, encoding = decode(raw, partial=size > len(raw))
    if engine == "auto":
        engine = "columns" if size > COLUMNWISE_BYTES else "rows"
    dcs = _dcs_export(text, src)
    if dcs is not None:
        header, line, data_line, roles = dcs
        return Sniffed(p, src, "csv", size, encoding, csv.excel_tab, header, line, engine, data_line, roles,
                       "dcs-export")
    dialect = sniff_dialect(text)
    header, line = _csv_header(text, dialect)
    return Sniffed(p, src, "csv", size, encoding, dialect, header, line, engine)
