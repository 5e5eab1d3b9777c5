"""Logging helpers of the service."""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable

__all__ = ["RateLimitedLog"]


class RateLimitedLog:
    """WARNING lines per reason: the first at once, then at most one every ``interval`` seconds,
    each saying how many were not shown since the previous one."""

    def __init__(self, logger: logging.Logger, interval: float = 10.0,
                 clock: Callable[[], float] = time.monotonic):
        self.logger = logger
        self.interval = float(interval)
        self.clock = clock
        self._last: dict[str, float] = {}
        self._hidden: Counter = Counter()
        self._lock = threading.Lock()

    def warning(self, reason: str, message: str, *args) -> bool:
        """Log (or count) one event of ``reason``; True if a line was written."""
        now = self.clock()
        with self._lock:
            last = self._last.get(reason)
            if last is not None and now - last < self.interval:
                self._hidden[reason] += 1
                return False
            hidden = self._hidden.pop(reason, 0)
            self._last[reason] = now
        if hidden:
            message += " (%d more %s since the last line)"
            args = (*args, hidden, reason)
        self.logger.warning(message, *args)
        return True
