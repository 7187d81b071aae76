"""Atomic file writing, shared by every command that writes results."""
from __future__ import annotations

import contextlib
import os
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterator, Sequence

__all__ = ["write_atomic", "staged_folder", "existing_part", "folder_problem", "output_target",
           "OutputPathError", "not_regular_file"]


class OutputPathError(OSError):
    """An output path that no result file may be written to (a FIFO, a device, a socket, a folder)."""


def _kind(mode: int) -> str:
    """What a file of mode ``mode`` (``os.stat().st_mode``) is, in words."""
    for test, name in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder")):
        if test(mode):
            return name
    return "not a regular file"


def not_regular_file(path) -> str:
    """Why ``path`` (links followed) is not a regular file that can be read or replaced, or ``''``.

    ``''`` also when ``path`` does not exist.  Used by the writers here and by the readers of
    recordings, so that a FIFO or a device is refused at once instead of hanging or being replaced.
    """
    try:
        mode = os.stat(os.fspath(path)).st_mode
    except OSError:
        return ""
    return "" if stat.S_ISREG(mode) else f"{os.fspath(path)} is {_kind(mode)}, not a regular file"


def output_target(path) -> str:
    """The file that writing ``path`` must replace: ``path`` itself, or a symbolic link's target.

    A link is written through (its target is replaced, the link kept), as ``open(path, 'w')``
    would; a dangling link creates its target.  Raises :class:`OutputPathError` when the target is
    a FIFO, a device, a socket or a folder (a plain file would otherwise silently replace it) or
    when the links form a loop.
    """
    path = os.path.abspath(os.fspath(path))
    if os.path.islink(path):
        try:
            path = os.path.realpath(path, strict=False)
            os.stat(path)
        except FileNotFoundError:
            pass
        except OSError as exc:  # ELOOP: the link points to itself
            raise OutputPathError(f"{path}: cannot follow the symbolic link ({exc.strerror}); "
                                  f"remove the link or give another path") from None
    why = not_regular_file(path)
    if why:
        raise OutputPathError(f"{why}; give the path of a regular file (or a new one) to write the "
                              f"results to")
    return path


def write_atomic(path, write: Callable) -> str:
    """Call ``write(f)`` on a temporary binary file next to ``path``, then rename it to ``path``.

    The rename is atomic, so an interrupted run leaves either the old file or the new one, never a
    half-written file; the temporary file is removed on any error. Creates the folder if needed.
    A symbolic link is written through (see :func:`output_target`: its target is replaced); a
    FIFO, a device, a socket or a folder at ``path`` raises :class:`OutputPathError` (an
    ``OSError``) before anything is written.  Returns ``path`` as given.
    """
    given = os.fspath(path)
    path = output_target(given)
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
    return given


@contextlib.contextmanager
def staged_folder(folder, last: Sequence[str] = ()) -> Iterator[str]:
    """Write a set of result files as one unit: yields a staging folder, published into ``folder`` on success.

    The files are written into a hidden staging folder beside ``folder``. When the block ends
    normally they are published: where ``folder`` does not exist yet the staging folder is renamed
    to it (one atomic rename); otherwise each file replaces its namesake atomically, the names in
    ``last`` (the index files that refer to the others, e.g. ``report.md``) after every other file,
    and files of ``folder`` that were not written are left alone. When the block raises (an error,
    Ctrl-C) the staging folder is removed and ``folder`` is left as it was: an interrupted command
    never leaves a half-written set of results.  A symbolic link to a folder is written through; a
    file of the folder that is a link is replaced through it (its target is updated), and one that
    is a FIFO or a device raises :class:`OutputPathError` (nothing is published).
    """
    folder = os.path.realpath(os.fspath(folder))
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise OutputPathError(f"{folder} is {_kind(os.stat(folder).st_mode)}; give a folder for the results")
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
        targets = {}
        for name in names:  # every target checked before the first file is published
            src, dst = os.path.join(stage, name), os.path.join(folder, name)
            targets[name] = dst if os.path.isdir(src) else output_target(dst)
        for name in names:
            src, dst = os.path.join(stage, name), targets[name]
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
        mode = os.stat(part).st_mode
        what = "a file" if stat.S_ISREG(mode) else _kind(mode)
        return f"{part} is {what}, not a folder"
    if not os.access(part, os.W_OK | os.X_OK):
        return f"cannot write into {part} (permission denied); give another folder"
    try:  # the permission bits do not tell everything (/proc, a read-only mount, a full disk)
        os.rmdir(tempfile.mkdtemp(prefix=".valve_gym-probe-", dir=part))
    except OSError as exc:
        return f"cannot create a folder in {part} ({exc.strerror or exc}); give another folder"
    return ""
