"""Markdown table cells that show any text as it is (failure messages, recording names, notes)."""
from __future__ import annotations

import re

__all__ = ["md_cell", "md_unescape", "md_row", "md_cells"]

#: Characters that mean something inside a Markdown table cell (CommonMark, GitHub's tables and math):
#: each is written behind a backslash, so that the cell shows the text as it is.
_MD_SPECIAL = re.compile(r"[\\|`*\[\]~$]|<(?=[A-Za-z/!?])|&(?=#?\w+;)|_+")


def md_cell(value) -> str:
    """``value`` as the text of one Markdown table cell: on one line, shown as it is.

    Every run of white space (a line break included) becomes one space; a pipe, backslash, backtick,
    ``*``, ``[``, ``]``, ``~``, ``$``, a ``<`` that would open a tag or a link, an ``&`` that would
    start an entity and a ``_`` that could start or end emphasis (not one inside a word, as in tag
    names) are escaped with a backslash (``w <= 0.33`` stays as it is).  :func:`md_unescape` reverses it.
    """
    text = re.sub(r"\s+", " ", str(value)).strip()

    def escaped(m: re.Match) -> str:
        i, j = m.span()
        if m.group()[0] == "_" and 0 < i and j < len(text) and text[i - 1].isalnum() and text[j].isalnum():
            return m.group()                    # inside a word (FIC_101, no_stiction__2111...): no emphasis
        return "".join("\\" + c for c in m.group())

    return _MD_SPECIAL.sub(escaped, text)


def md_unescape(cell: str) -> str:
    """The text of a cell written by :func:`md_cell` (its backslash escapes removed)."""
    return re.sub(r"\\([!-/:-@\[-`{-~])", r"\1", cell)


def md_row(cells) -> str:
    """One Markdown table row, each cell through :func:`md_cell`."""
    return "| " + " | ".join(md_cell(c) for c in cells) + " |"


def md_cells(line: str) -> list[str]:
    """The cells of a table row written by :func:`md_row` (a pipe behind a backslash is text)."""
    cells, cur, i, body = [], [], 0, line.strip()
    body = body[1:] if body.startswith("|") else body
    while i < len(body):
        c = body[i]
        if c == "\\" and i + 1 < len(body):
            cur.append(body[i:i + 2])
            i += 2
            continue
        if c == "|":
            cells.append("".join(cur))
            cur = []
        else:
            cur.append(c)
        i += 1
    if "".join(cur).strip():
        cells.append("".join(cur))
    return [md_unescape(c.strip()) for c in cells]
