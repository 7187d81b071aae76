"""Atomic file writing, shared by every command that writes results."""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence

__all__ = ["write_atomic", "staged_folder", "existing_part", "folder_problem"]


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


@contextlib.contextmanager
def staged_folder(folder, last: Sequence[str] = ()) -> Iterator[str]:
    """Write a set of result files as one unit: yields a staging folder, published into ``folder`` on success.

    The files are written into a hidden staging folder beside ``folder``. When the block ends
    normally they are published: where ``folder`` does not exist yet the staging folder is renamed
    to it (one atomic rename); otherwise each file replaces its namesake atomically, the names in
    ``last`` (the index files that refer to the others, e.g. ``report.md``) after every other file,
    and files of ``folder`` that were not written are left alone. When the block raises (an error,
    Ctrl-C) the staging folder is removed and ``folder`` is left as it was: an interrupted command
    never leaves a half-written set of results.
    """
    folder = os.path.abspath(os.fspath(folder))
    parent = os.path.dirname(folder)
    os.makedirs(parent, exist_ok=True)
    stage = tempfile.mkdtemp(prefix="." + os.path.basename(folder) + ".", suffix=".partial", dir=parent)
    try:
        yield stage
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(stage, 0o777 & ~umask)  # mkdtemp makes 0700; give results the usual mode
        if not os.path.exists(folder):
            os.rename(stage, folder)
            return
        names = sorted(os.listdir(stage), key=lambda n: (n in last, last.index(n) if n in last else 0, n))
        for name in names:
            src, dst = os.path.join(stage, name), os.path.join(folder, name)
            if os.path.isdir(src) and os.path.isdir(dst) and not os.path.islink(dst):
                shutil.rmtree(dst)          # a folder of results replaces the old one whole
            os.replace(src, dst)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


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
