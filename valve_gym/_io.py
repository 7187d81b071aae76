"""Atomic file writing, shared by every command that writes results."""
from __future__ import annotations

import os
import tempfile
from collections.abc import Callable

__all__ = ["write_atomic"]


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
