"""Logging helpers of the service."""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, OrderedDict
from collections.abc import Callable

__all__ = ["MAX_REASONS", "RateLimitedLog"]

MAX_REASONS = 1024


class RateLimitedLog:
    """WARNING lines (or ERROR lines with a traceback, :meth:`exception`) per reason: the first
    at once, then at most one every ``interval`` seconds, each saying how many were not shown
    since the previous one.

    Reasons may name a robot (``intrusion:<robot>``): it keeps :data:`MAX_REASONS` of them at
    most, forgetting the longest unlogged first, so ids that come and go cannot grow it (nor a
    burst of new ones within ``interval``: a forgotten reason's next event is a line at once).
    """

    def __init__(self, logger: logging.Logger, interval: float = 10.0,
                 clock: Callable[[], float] = time.monotonic):
        self.logger = logger
        self.interval = float(interval)
        self.clock = clock
        self._last: OrderedDict[str, float] = OrderedDict()  # by when each last wrote a line
        self._hidden: Counter = Counter()
        self._lock = threading.Lock()

    def allow(self, reason: str) -> int | None:
        """Count one event of ``reason``: None if its line is not due yet, else the number of
        events not shown since its previous line (the caller writes the line)."""
        now = self.clock()
        with self._lock:
            last = self._last.get(reason)
            if last is not None and now - last < self.interval:
                self._hidden[reason] += 1
                return None
            hidden = self._hidden.pop(reason, 0)
            if last is None:
                while len(self._last) >= MAX_REASONS:  # the oldest first: each a step, not a scan
                    self._hidden.pop(self._last.popitem(last=False)[0], None)
            self._last[reason] = now
            self._last.move_to_end(reason)
        return hidden

    def warning(self, reason: str, message: str, *args) -> bool:
        """Log (or count) one event of ``reason`` at WARNING; True if a line was written."""
        return self._write(logging.WARNING, reason, message, args)

    def info(self, reason: str, message: str, *args) -> bool:
        """Log (or count) one event of ``reason`` at INFO; True if a line was written."""
        return self._write(logging.INFO, reason, message, args)

    def exception(self, reason: str, message: str, *args) -> bool:
        """Log (or count) one event of ``reason`` at ERROR with the traceback being handled
        (call it in an ``except`` block); True if a line was written.

        For a bug that may fail every message or frame: one traceback per ``interval``, not
        one per event. The line after hidden ones ends ``(N more since the last line)``: the
        message names what failed, so the reason is not repeated.
        """
        hidden = self.allow(reason)
        if hidden is None:
            return False
        if hidden:
            message += " (%d more since the last line)"
            args = (*args, hidden)
        self.logger.error(message, *args, exc_info=True)
        return True

    def _write(self, level: int, reason: str, message: str, args: tuple) -> bool:
        hidden = self.allow(reason)
        if hidden is None:
            return False
        if hidden:
            message += " (%d more %s since the last line)"
            args = (*args, hidden, reason)
        self.logger.log(level, message, *args)
        return True
