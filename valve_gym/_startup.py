"""What the ``valve-gym`` command needs before the package's heavy imports (numba, gymnasium).

Python's console-script launcher imports ``valve_gym`` (about two seconds: the numba core, gymnasium)
before :func:`valve_gym.cli.main` runs, so a Ctrl-C in that time would print Python's traceback.
:func:`quiet_interrupt_while_loading` turns it into the command's one-line message and exit status 130;
:func:`valve_gym.cli.main` puts Python's own SIGINT handler back once the package is loaded. Nothing
changes for ``import valve_gym`` in a program or a notebook, nor where SIGINT is ignored (a job started
in the background keeps ignoring it).
"""
from __future__ import annotations

import signal
import sys

__all__ = ["COMMAND", "quiet_interrupt_while_loading", "restore_interrupt"]

#: Name of the console script (``[project.scripts]`` in pyproject.toml).
COMMAND = "valve-gym"


def _interrupted_while_loading(signum, frame) -> None:
    print(f"{COMMAND}: interrupted", file=sys.stderr)
    raise SystemExit(130)


def quiet_interrupt_while_loading(argv) -> bool:
    """Install the quiet Ctrl-C handler when this process is the ``valve-gym`` command; True if installed.

    Only in the command's own process (not in its worker processes) and where SIGINT has Python's
    default handler (not ignored, not set by the program).
    """
    name = str(argv[0]) if argv else ""
    if name.replace("\\", "/").rsplit("/", 1)[-1] not in (COMMAND, COMMAND + ".exe"):
        return False
    import multiprocessing

    if multiprocessing.parent_process() is not None:   # a worker process started by the command (spawn,
        return False                                     # forkserver) inherits its argv but not its role
    try:
        if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
            return False
        signal.signal(signal.SIGINT, _interrupted_while_loading)
    except ValueError:                 # not the main thread: leave signals alone
        return False
    return True


def restore_interrupt() -> None:
    """Python's own SIGINT handler again (KeyboardInterrupt), if the loading one is still installed."""
    try:
        if signal.getsignal(signal.SIGINT) is _interrupted_while_loading:
            signal.signal(signal.SIGINT, signal.default_int_handler)
    except ValueError:
        pass
