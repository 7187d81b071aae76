"""A progress line for a fleet run: loops done, failed, rate and time left."""
from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["Progress"]


class Progress:
    """Progress of ``total`` loops on ``stream`` (a bar redrawn in place on a terminal, lines otherwise).

    Parameters
    ----------
    total : int, loops to do in this run
    skipped : int, loops already done (resumed), shown but not timed
    stream : text stream, default ``sys.stderr``; None for silence
    every : float, seconds between lines when the stream is not a terminal
    """

    def __init__(self, total: int, skipped: int = 0, stream: TextIO | None = sys.stderr, every: float = 10.0):
        self.total, self.skipped, self.stream, self.every = int(total), int(skipped), stream, float(every)
        self.done = self.failed = 0
        self.t0 = time.perf_counter()
        self._last = -1e9
        self._tty = bool(stream is not None and getattr(stream, "isatty", lambda: False)())
        self._open = False      # a bar drawn on a terminal, its line not ended

    def line(self) -> str:
        """The progress text, e.g. ``[#####-----] 50/100 done, 2 failed, 3.1 loops/s, 0:00:16 left``."""
        el = time.perf_counter() - self.t0
        rate = self.done / el if el > 0 else 0.0
        left = (self.total - self.done) / rate if rate > 0 else float("nan")
        eta = "?" if left != left else time.strftime("%H:%M:%S", time.gmtime(left))
        w = 24
        k = int(w * self.done / self.total) if self.total else w
        skip = f" ({self.skipped} resumed)" if self.skipped else ""
        return (f"[{'#' * k}{'-' * (w - k)}] {self.done}/{self.total} done{skip}, {self.failed} failed, "
                f"{rate:.2f} loops/s, {eta} left")

    def update(self, failed: bool = False, force: bool = False) -> None:
        """Count one finished loop and redraw (throttled)."""
        self.done += 1
        self.failed += int(bool(failed))
        self.show(force or self.done == self.total)

    def show(self, force: bool = False) -> None:
        """Redraw now if ``force`` or enough time has passed."""
        if self.stream is None:
            return
        now = time.perf_counter()
        if not force and now - self._last < (0.2 if self._tty else self.every):
            return
        self._last = now
        if self._tty:
            self.stream.write("\r" + self.line() + ("\n" if self.done >= self.total else ""))
            self._open = self.done < self.total
        else:
            self.stream.write(self.line() + "\n")
        self.stream.flush()

    def note(self, text: str) -> None:
        """Write ``text`` on a line of its own (ending the bar's line first on a terminal)."""
        if self.stream is None:
            return
        self.stream.write(("\n" if self._open else "") + text + "\n")
        self.stream.flush()
        self._open = False

    def close(self) -> None:
        """End the bar's line on a terminal."""
        if self.stream is not None and self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False
