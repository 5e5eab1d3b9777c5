"""Progress on stderr for long runs (evaluation, detection), without a dependency."""

from __future__ import annotations

import sys
import time

__all__ = ["ProgressPrinter", "Silent"]


class ProgressPrinter:
    """A tiny progress bar on a stream (stderr by default).

    On a terminal it redraws ``label [#####     ] done/total note`` in place; elsewhere it prints
    one line each time a piece of work (``note``) finishes, so logs stay readable.

    Parameters
    ----------
    stream : file, optional
    width : int
        Characters of the bar.
    """

    def __init__(self, stream=None, width: int = 30):
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.total, self.done, self.label, self._last = 0, 0, "", 0.0

    def start(self, total: int, label: str) -> None:
        self.total, self.done, self.label, self._last = max(int(total), 0), 0, label, 0.0

    def advance(self, n: int = 1, note: str = "") -> None:
        self.done += n
        now = time.monotonic()
        if self.tty and (now - self._last > 0.1 or self.done >= self.total):
            self._last = now
            frac = min(self.done / self.total, 1.0) if self.total else 1.0
            bar = "#" * int(round(self.width * frac))
            self.stream.write(f"\r{self.label} [{bar:<{self.width}}] {self.done}/{self.total} "
                              f"{note[:40]:<40}")
            self.stream.flush()

    def note(self, text: str) -> None:
        """A finished piece of work (printed as a line when the stream is not a terminal)."""
        if not self.tty:
            self.stream.write(f"{self.label}: {text} ({self.done}/{self.total})\n")
            self.stream.flush()

    def finish(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


class Silent:
    """A progress printer that prints nothing."""

    def start(self, total: int, label: str) -> None: ...
    def advance(self, n: int = 1, note: str = "") -> None: ...
    def note(self, text: str) -> None: ...
    def finish(self) -> None: ...
