"""Stopping a training run cleanly on SIGINT/SIGTERM (shared by the trainers)."""
from __future__ import annotations

import signal
from contextlib import contextmanager

__all__ = ["STOP", "stop_on_signals"]

#: Set by SIGINT/SIGTERM inside :func:`stop_on_signals`: ``flag`` (bool) and ``signal`` (its number).
STOP = {"flag": False, "signal": None}


@contextmanager
def stop_on_signals():
    """Within the block, SIGINT and SIGTERM set ``STOP['flag']`` instead of killing the process.

    The trainers poll the flag, write a checkpoint of the last completed step and return; the
    previous handlers are restored on exit.
    """
    STOP["flag"] = False
    STOP["signal"] = None

    def on_signal(signum, frame):
        STOP["flag"] = True
        STOP["signal"] = signum

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield STOP
    finally:
        for s, h in old.items():
            signal.signal(s, h)
