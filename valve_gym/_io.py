"""Atomic file writing, shared by every command that writes results."""
from __future__ import annotations

import os
import tempfile
from collections.abc import Callable

__all__ = ["write_atomic", "existing_part", "folder_problem"]


def write_atomic(path, write: Callable) -> str:
    """Call ``write(f)`` on a temporary binary file next to ``path``, then rename it to ``path``.

    The rename is atomic, so an interrupted run leaves either the old file or the new one, never a
    half-written file; the temporary file is removed on any error. Creates the folder if needed.
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path)) or "."
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give results the usual mode
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path


def existing_part(path) -> str:
    """The longest leading part of ``path`` (made absolute) that exists."""
    part = os.path.abspath(os.fspath(path))
    while not os.path.exists(part):
        part = os.path.dirname(part)
    return part


def folder_problem(path) -> str:
    """Why no folder can be made or used at ``path`` (a file on the way, no write permission), or ``''``.

    Checked by every command before its work starts, so that an output option naming a file fails at
    once and not when the results are written.
    """
    part = existing_part(path)
    if not os.path.isdir(part):
        return f"{part} is a file, not a folder"
    if not os.access(part, os.W_OK | os.X_OK):
        return f"cannot write into {part} (permission denied); give another folder"
    return ""
