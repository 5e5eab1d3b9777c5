"""A minimal progress bar on stderr, shown only when stderr is a terminal."""

from __future__ import annotations

import sys
import time


class Progress:
    """Context manager: ``update()`` once per item; draws ``label [#####     ] n/total``."""

    def __init__(self, total: int, label: str, stream=None):
        self.total, self.label, self.count = max(total, 0), label, 0
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty()
        self._last = 0.0

    def __enter__(self) -> "Progress":
        return self

    def update(self, n: int = 1) -> None:
        self.count += n
        now = time.monotonic()
        if self.enabled and (now - self._last > 0.1 or self.count == self.total):
            self._last = now
            self._draw()

    def _draw(self) -> None:
        if self.total:
            done = min(self.count / self.total, 1.0)
            bar = "#" * int(30 * done)
            self.stream.write(f"\r{self.label} [{bar:<30}] {self.count}/{self.total}")
        else:
            self.stream.write(f"\r{self.label} {self.count}")
        self.stream.flush()

    def __exit__(self, *exc) -> None:
        if self.enabled:
            self._draw()
            self.stream.write("\n")
            self.stream.flush()
