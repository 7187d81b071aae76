"""Column mapping: which column of a file holds which signal role.

:func:`parse_columns` reads the CLI form ``"t=t_s,op=OP,pv=PV"``;
:func:`resolve_columns` maps roles to the columns of a file's header, by the
names given or by :data:`DEFAULT_COLUMN_NAMES`, into a :class:`ColumnMap`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from ._base import DEFAULT_COLUMN_NAMES, REQUIRED, ROLE_WORDS, ROLES, RecordingError

__all__ = ["ColumnMap", "as_column_mapping", "parse_columns", "resolve_columns", "WIDE_COLUMN_RE", "WIDE_SUFFIXES",
           "wide_tags"]

#: A historian's tag-prefixed column (``FIC101.PV``, ``FIC101.OP``, ``FIC101.SP``, ``FIC101.MODE``) and
#: the signal role of each suffix. Fleet mode reads every tag of such a wide export as a loop; a single
#: recording whose columns have no default name takes the columns of its one tag.
WIDE_COLUMN_RE = re.compile(r"^(?P<tag>.+)\.(?P<role>PV|OP|SP|MODE)$", re.IGNORECASE)
WIDE_SUFFIXES = {"PV": "pv", "OP": "op", "SP": "sp", "MODE": "mode"}


@dataclass(frozen=True)
class ColumnMap:
    """Where each signal role is in a file.

    Attributes
    ----------
    index : dict of str to int
        Role to the 0-based column position in the header, for the roles
        present (always ``t``, ``op``, ``pv``), in the order of :data:`ROLES`.
    names : dict of str to str
        Role to the column name as written in the header.
    """

    index: dict[str, int]
    names: dict[str, str]

    @property
    def roles(self) -> list[str]:
        """Roles present, in the order of :data:`ROLES`."""
        return [r for r in ROLES if r in self.index]

    @property
    def signal_roles(self) -> list[str]:
        """Roles present other than time."""
        return [r for r in self.roles if r != "t"]


def parse_columns(text: str) -> dict[str, str | None]:
    """Parse a column mapping such as ``"t=t_s,op=OP,pv=PV,sp=SP"``.

    Parameters
    ----------
    text : str
        Comma-separated ``role=COLUMN`` items; roles are ``t, op, pv, sp, mv, mode``.
        An empty column (``sp=``) means "do not use this role".  Column names
        cannot contain commas.

    Returns
    -------
    dict
        Role to column name (or None), suitable for ``load_recording(columns=...)``.

    Raises
    ------
    RecordingError
        For an item without ``=``, an unknown or repeated role, or an empty
        column for ``t``, ``op`` or ``pv``.

    Examples
    --------
    >>> parse_columns("t=t_s, op=OP, pv=PV, sp=")
    {'t': 't_s', 'op': 'OP', 'pv': 'PV', 'sp': None}
    """
    usage = ("expected --columns role=COLUMN[,role=COLUMN...] with roles t, op, pv, sp, mv, mode, "
             "e.g. t=t_s,op=OP,pv=PV")
    if text is None or not str(text).strip():
        raise RecordingError(f"empty column mapping: {usage}")
    out: dict[str, str | None] = {}
    for item in str(text).split(","):
        item = item.strip()
        if not item:
            continue
        if "=" not in item:
            raise RecordingError(f"column mapping item {item!r} has no '=': {usage}")
        role, col = (s.strip() for s in item.split("=", 1))
        role = role.lower()
        if role not in ROLES:
            raise RecordingError(f"unknown role {role!r} in column mapping {text!r}: {usage}")
        if role in out:
            raise RecordingError(f"role {role!r} given twice in column mapping {text!r}: {usage}")
        if not col and role in REQUIRED:
            raise RecordingError(
                f"role {role!r} ({ROLE_WORDS[role]}) needs a column name in {text!r}: {usage}"
            )
        out[role] = col or None
    if not out:
        raise RecordingError(f"empty column mapping {text!r}: {usage}")
    return out


def as_column_mapping(columns: object, src: str) -> Mapping[str, str | None] | None:
    """The ``columns`` argument of :func:`load_recording` as a mapping.

    A dict (any mapping) or None is returned as it is; a string is read as the CLI's
    ``"role=COLUMN,role=COLUMN"`` (:func:`parse_columns`).

    Raises
    ------
    RecordingError
        Anything else, or a string that :func:`parse_columns` refuses.
    """
    if columns is None or isinstance(columns, Mapping):
        return columns
    if isinstance(columns, str):
        try:
            return parse_columns(columns)
        except RecordingError as e:
            raise RecordingError(f"{src}: columns: {e}") from None
    raise RecordingError(
        f"{src}: columns must be a dict of role to column name like {{'op': 'OP', 'pv': 'PV'}}, or the "
        f"CLI's string form 'op=OP,pv=PV'; got {type(columns).__name__} {columns!r:.80}"
    )


def _named(header: Sequence[str], lower: dict[str, list[int]], role: str, name: str, src: str) -> int:
    """Position of the column `name` given for `role` (exact match, else case-insensitive)."""
    avail = ", ".join(repr(h) for h in header)
    exact = [j for j, h in enumerate(header) if h == name]
    hits = exact or lower.get(name.lower(), [])
    if not hits:
        raise RecordingError(
            f"{src}: column {name!r} given for the {ROLE_WORDS[role]} ({role}) is not in the "
            f"file; available columns: {avail}"
        )
    if len(hits) > 1:
        raise RecordingError(
            f"{src}: column name {name!r} ({role}) appears {len(hits)} times in the header; "
            f"rename the duplicates in the file"
        )
    return hits[0]


def _default(lower: dict[str, list[int]], role: str, taken: set[int]) -> int | None:
    """Position of the first default name of `role` found once in the header, else None."""
    for cand in DEFAULT_COLUMN_NAMES[role]:
        hits = lower.get(cand, [])
        if len(hits) == 1 and hits[0] not in taken:
            return hits[0]
    return None


def wide_tags(header: Sequence[str]) -> dict[str, dict[str, str]]:
    """The ``TAG.<ROLE>`` columns of a header (:data:`WIDE_COLUMN_RE`): ``{tag: {role: column}}``.

    >>> wide_tags(["timestamp", "FIC1.PV", "FIC1.OP", "LIC2.pv"])
    {'FIC1': {'pv': 'FIC1.PV', 'op': 'FIC1.OP'}, 'LIC2': {'pv': 'LIC2.pv'}}
    """
    tags: dict[str, dict[str, str]] = {}
    for col in header:
        m = WIDE_COLUMN_RE.match(col)
        if m:
            tags.setdefault(m["tag"], {})[WIDE_SUFFIXES[m["role"].upper()]] = col
    return tags


def wide_duplicates(header: Sequence[str]) -> dict[tuple[str, str], list[int]]:
    """``TAG.<ROLE>`` roles given by more than one column: ``{(tag, role): [positions]}``.

    The same name twice, or two spellings of one role (``FIC1.PV`` and ``FIC1.pv``): a reader would
    take one of them without a word, so the loaders refuse such a tag.

    >>> wide_duplicates(["t", "FIC1.PV", "FIC1.OP", "FIC1.pv", "LIC2.PV"])
    {('FIC1', 'pv'): [1, 3]}
    """
    roles: dict[tuple[str, str], list[int]] = {}
    for j, col in enumerate(header):
        m = WIDE_COLUMN_RE.match(col)
        if m:
            roles.setdefault((m["tag"], WIDE_SUFFIXES[m["role"].upper()]), []).append(j)
    return {k: js for k, js in roles.items() if len(js) > 1}


def duplicate_problem(header: Sequence[str], tag: str, role: str, js: Sequence[int]) -> str:
    """What is wrong with tag ``tag``'s ``role`` given by the columns at ``js`` (:func:`wide_duplicates`)."""
    names = sorted({header[j] for j in js})
    what = (f"column {names[0]!r} appears {len(js)} times" if len(names) == 1 else
            f"columns {' and '.join(map(repr, names))} both name its {role.upper()}")
    return (f"tag {tag!r}: {what} (columns {', '.join(str(j + 1) for j in js)} of the header), so which one holds "
            f"the tag's {role.upper()} is unknown; delete or rename the duplicate column in the export")


def _tagged(header: list[str], role: str, taken: set[int]) -> tuple[int | None, str, list[str]]:
    """The one ``TAG.<ROLE>`` column of `role` (:func:`wide_tags`).

    Returns ``(position, tag, [])``, or ``(None, '', tags)`` with the tags found when there is
    not exactly one.
    """
    hits = [(header.index(cols[role]), tag) for tag, cols in wide_tags(header).items() if role in cols]
    hits = [(j, tag) for j, tag in hits if j not in taken]
    if len(hits) == 1:
        return hits[0][0], hits[0][1], []
    return None, "", sorted({t for _, t in hits})


def _default_blocked(lower: dict[str, list[int]], role: str, header: list[str], out: dict[str, int]) -> str:
    """Why a default name of `role` that is in the header was not taken (repeated, or mapped to another role)."""
    for cand in DEFAULT_COLUMN_NAMES[role]:
        hits = lower.get(cand, [])
        if len(hits) > 1:
            return (f"the header names {header[hits[0]]!r} {len(hits)} times (columns "
                    f"{', '.join(str(j + 1) for j in hits)}); give each column its own name")
        other = [r for r, j in out.items() if hits and j == hits[0]]
        if other:
            return f"its default column {header[hits[0]]!r} is mapped to {other[0]}"
    return ""


def _refuse_taken_default(header: list[str], lower: dict[str, list[int]], role: str, out: dict[str, int],
                          src: str) -> None:
    """Refuse a mapping that gave another role the column an optional `role` would be found in by its name.

    One column serves one role only: ``pv=SP`` would otherwise read the set point as the process variable
    and drop the set point without a word.

    Raises
    ------
    RecordingError
        `role`'s default column (:data:`DEFAULT_COLUMN_NAMES`, or its one ``TAG.<ROLE>`` column) is
        mapped to another role.
    """
    j = _default(lower, role, set())
    if j is None and role in WIDE_SUFFIXES.values():
        j = _tagged(header, role, set())[0]
    other = [r for r, k in out.items() if k == j]
    if j is not None and other:
        raise RecordingError(
            f"{src}: column {header[j]!r} is given for {other[0]} ({ROLE_WORDS[other[0]]}) but by its name holds "
            f"the {ROLE_WORDS[role]} ({role}); one column may serve one role only: map {other[0]} to its own "
            f"column, or if {header[j]!r} really holds the {ROLE_WORDS[other[0]]}, switch the {ROLE_WORDS[role]} "
            f"off with --columns {role}= (columns={{'{role}': None}} in Python)"
        )


def _by_default(header: list[str], lower: dict[str, list[int]], role: str, out: dict[str, int],
                tags: dict[str, str], src: str) -> int | None:
    """Position of `role`'s column found without a name given (None: an optional role not found).

    A default name (:data:`DEFAULT_COLUMN_NAMES`), else the one ``TAG.<ROLE>`` column (its tag
    noted in `tags`).

    Raises
    ------
    RecordingError
        A required role not found, or found for several tags.
    """
    j = _default(lower, role, set(out.values()))
    several: list[str] = []
    if j is None and role in WIDE_SUFFIXES.values():
        j, tag, several = _tagged(header, role, set(out.values()))
        if j is not None:
            dup = wide_duplicates(header).get((tag, role))
            if dup:
                raise RecordingError(f"{src}: {duplicate_problem(header, tag, role, dup)}, or name the column "
                                     f"with --columns {role}=NAME")
            tags[role] = tag
    if j is None and role not in REQUIRED:
        _refuse_taken_default(header, lower, role, out, src)
    if j is not None or role not in REQUIRED:
        return j
    if len(several) > 1:
        raise RecordingError(
            f"{src}: the columns hold several loops' {ROLE_WORDS[role]} ({', '.join(several)}); "
            f"diagnose them all in fleet mode (valve-gym diagnose FILE --out OUTDIR reads each tag as "
            f"a loop), or pick one loop's columns with --columns {role}=NAME,...")
    avail = ", ".join(repr(h) for h in header)
    why = _default_blocked(lower, role, header, out) or (
        f"none of the default names {', '.join(DEFAULT_COLUMN_NAMES[role])} (or one TAG.{role.upper()} "
        f"column) is among the columns {avail}")
    likely = _likely_columns(header, role, set(out.values()))
    hint = (f" (by its name perhaps {' or '.join(repr(header[j]) for j in likely[:3])}: "
            f"--columns {role}={header[likely[0]]})" if likely else "")
    if role == "t":
        hint += ("; for a file without a time column (rows equally spaced) give the sample time instead: "
                 "dt=SECONDS (CLI: --dt SECONDS)")
    raise RecordingError(f"{src}: no column for the {ROLE_WORDS[role]} ({role}): {why}; "
                         f"pass columns={{'{role}': NAME}} (CLI: --columns {role}=NAME){hint}")


#: Words that, as a part of a column's name, suggest its role (a suggestion only; never taken unasked).
_ROLE_WORDS_IN_NAMES = {"op": ("op", "co", "out", "output"), "pv": ("pv", "level", "flow", "meas", "pressure"),
                        "t": ("time", "timestamp", "date", "datetime")}


def _likely_columns(header: Sequence[str], role: str, taken: set[int]) -> list[int]:
    """Columns whose name holds a word that suggests ``role`` (``OP_level_valve_LV106`` for the op).

    >>> _likely_columns(["timestamp", "flow_FT115", "OP_level_valve_LV106"], "op", set())
    [2]
    >>> _likely_columns(["timestamp", "flow_FT115", "OP_level_valve_LV106"], "pv", {2})
    [1]
    """
    words = _ROLE_WORDS_IN_NAMES.get(role, ())
    out = []
    for j, h in enumerate(header):
        parts = [w for w in re.split(r"[^a-z0-9]+", re.sub(r"([a-z])([A-Z])", r"\1_\2", h).lower()) if w]
        if j not in taken and any(w in words for w in parts):
            out.append(j)
    return out


def resolve_columns(
    header: Sequence[str], columns: Mapping[str, str | None] | None, src: str
) -> ColumnMap:
    """Map the signal roles to columns of `header`.

    Parameters
    ----------
    header : sequence of str
        Column names of the file, in order.
    columns : mapping, optional
        Role to column name (None or "" switches an optional role off); the
        roles left out are looked up among :data:`DEFAULT_COLUMN_NAMES`.
    src : str
        The file, for messages.

    Returns
    -------
    ColumnMap

    Raises
    ------
    RecordingError
        Unknown role; a required role switched off or not found; a named
        column absent (the message lists the available ones) or repeated in
        the header; one column used for two roles.
    """
    header = list(header)
    columns = dict(as_column_mapping(columns, src) or {})
    avail = ", ".join(repr(h) for h in header)
    for role in columns:
        if role not in ROLES:
            raise RecordingError(f"{src}: unknown role {role!r} in columns; roles are {', '.join(ROLES)}")
    lower: dict[str, list[int]] = {}
    for j, h in enumerate(header):
        lower.setdefault(h.lower(), []).append(j)
    out: dict[str, int] = {}
    tags: dict[str, str] = {}           # role -> tag, for the roles read from a TAG.<ROLE> column
    for role in ROLES:
        if role not in columns:
            j = _by_default(header, lower, role, out, tags, src)
        elif columns[role] is None or not str(columns[role]).strip():
            if role in REQUIRED and role != "t":      # no time column: load_recording's dt gives the time
                raise RecordingError(
                    f"{src}: the {ROLE_WORDS[role]} ({role}) cannot be switched off; "
                    f"name its column (available: {avail})"
                )
            j = None
        else:
            j = _named(header, lower, role, str(columns[role]).strip(), src)
        if j is not None:
            out[role] = j
    if len(set(tags.values())) > 1:
        pairs = ", ".join(f"{r} from {header[out[r]]!r}" for r in tags)
        raise RecordingError(f"{src}: the signals would come from different tags ({pairs}); name the loop's "
                             f"columns with --columns op=NAME,pv=NAME")
    seen: dict[int, str] = {}
    for role, j in out.items():
        if j in seen:
            raise RecordingError(
                f"{src}: column {header[j]!r} is used for both {seen[j]} and {role}; "
                f"map each role to its own column"
            )
        seen[j] = role
    return ColumnMap(index=out, names={r: header[j] for r, j in out.items()})
