"""Paths of the recordings shipped in ``valve_gym/data``."""

from __future__ import annotations

from pathlib import Path

__all__ = ["data_path"]

_DATA_DIR = Path(__file__).resolve().parent.parent.parent / "data"


def data_path(name: str) -> Path:
    """Path of a data file or folder shipped in ``valve_gym/data``.

    Parameters
    ----------
    name : str
        Relative path inside the data folder, e.g.
        ``"cascaded_tanks/estimation.csv"`` or ``"stictiongpt_plant_loops"``.

    Returns
    -------
    pathlib.Path
        Existing path.

    Raises
    ------
    FileNotFoundError
        If nothing of that name is shipped; the message lists what is.

    Examples
    --------
    >>> data_path("cascaded_tanks/estimation.csv").name
    'estimation.csv'
    """
    rel = Path(str(name))
    if rel.is_absolute() or ".." in rel.parts:
        raise FileNotFoundError(
            f"data_path({name!r}): give a path relative to the package data folder {_DATA_DIR}"
        )
    p = _DATA_DIR / rel
    if not p.exists():
        parent = p.parent if p.parent.is_dir() else _DATA_DIR
        try:
            avail = sorted(c.name + ("/" if c.is_dir() else "") for c in parent.iterdir())
        except OSError:
            avail = []
        shown = ", ".join(avail[:20]) + (", ..." if len(avail) > 20 else "")
        raise FileNotFoundError(
            f"data_path({name!r}): no shipped data file {p}; "
            f"{parent} holds: {shown or '(nothing - is the package data installed?)'}"
        )
    return p
