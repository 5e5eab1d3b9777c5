"""The fleet's warning subscriber: one line per collision warning, readable or JSON.

Subscribes to ``<prefix>/<robot or *>/warning`` with an advanced subscriber that asks the
workers' warning caches for history, so a subscriber that joins late receives the latest warning
of each robot first, and recovers (through the workers' heartbeats) a warning it missed.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections import Counter, deque
from collections.abc import Callable

import zenoh

from service import keys
from service.logutil import RateLimitedLog
from service.messages import MessageError, Response, track_label

from .fleet import decode_fleet_sample, declare_warning_subscribers

__all__ = ["LinePrinter", "WarningListener", "format_json", "format_stamp", "format_warning"]

log = logging.getLogger("asnn.alerts")


# stamps between these (2000-01-01 and 2200-01-01 UTC) are shown as a local time of day
PLAUSIBLE_EPOCH = (946_684_800.0, 7_258_118_400.0)


def format_stamp(stamp: float) -> str:
    """A capture time as ``HH:MM:SS.mmm`` (local time) when it is a plausible epoch time in
    seconds, else as the number itself (a camera clock in nanoseconds, or counting from its
    start), so that no stamp can make a warning unprintable."""
    if PLAUSIBLE_EPOCH[0] <= stamp < PLAUSIBLE_EPOCH[1]:
        return time.strftime("%H:%M:%S", time.localtime(stamp)) + f".{int(stamp % 1 * 1000):03d}"
    return f"t={stamp:.3f}" if abs(stamp) < 1e9 else f"t={stamp:.6g}"


def format_warning(r: Response) -> str:
    """One readable line: time of capture, robot, seq, output and the looming targets."""
    clock = format_stamp(r.stamp)
    if r.targets:
        targets = "; ".join(_target(t) for t in r.targets)
    else:
        targets = "none located"
    return (f"{clock} WARNING robot {r.robot} seq {r.seq}: out {r.out:.3f}, "
            f"spike rate {r.spike_rate:.0f}, targets: {targets}")


def _target(t) -> str:
    """A target as text. A tracked one leads with its id, time to contact and path offset,
    and leaves out the motion's direction: an object on a collision course grows about its
    centre, its motion vectors cancel and their direction reads at random from frame to
    frame (the offset says instead how far its path passes from the camera)."""
    if t.id is None:
        return (f"({t.x:.0f}, {t.y:.0f}) heading {math.degrees(t.direction):+.0f} deg"
                f" energy {t.energy:.3g} {t.pixels} px")
    ttc = "no contact" if t.ttc is None else f"contact in {t.ttc:.2f} s"
    offset = "" if t.offset is None else f", path offset {t.offset:.2f}"
    return f"#{track_label(t.id)} {ttc}{offset} at ({t.x:.0f}, {t.y:.0f}) {t.pixels} px"


def format_json(r: Response) -> str:
    return json.dumps(r.model_dump(exclude_none=True), separators=(", ", ": "))


class WarningListener:
    """Declares the warning subscriber on a session and calls ``on_warning(Response)``.

    Invalid samples (:func:`clients.fleet.decode_fleet_sample`: among others, a warning must
    name the robot of its key and say ``collision``) are counted per reason in ``invalid`` and
    logged (at most one WARNING line per reason every 10 s); they never raise.
    Use as a context manager (or call ``close``).
    """

    def __init__(self, session: zenoh.Session, on_warning: Callable[[Response], None], *,
                 prefix: str = keys.DEFAULT_PREFIX, robot: str | None = None):
        self.on_warning = on_warning
        self.prefix = prefix
        self.invalid: Counter = Counter()
        self.received = 0
        self._log = RateLimitedLog(log)
        self._lock = threading.Lock()
        self.key = keys.warnings(prefix, robot)
        # an advanced subscriber (history, recovery) and a plain one, each warning taken once
        self.missed = 0
        self._subscribers = declare_warning_subscribers(session, self.key, self._on_sample,
                                                        self._on_miss)

    def _on_miss(self, count: int, publisher: str) -> None:
        with self._lock:
            self.missed += count
            missed = self.missed
        # a cut longer than the link's lease loses what was sent meanwhile: say so, or the
        # gap in the robots' seq is the only trace (an integrator's trial)
        self._log.warning("missed", "%d warnings of publisher %s were missed and could not be "
                          "recovered (%d in all): was this subscriber cut off from the router?",
                          count, publisher, missed)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            # as every fleet viewer takes it: the robot of its key, collision true
            _, _, response = decode_fleet_sample(str(sample.key_expr),
                                                 sample.payload.to_bytes(), self.prefix)
        except MessageError as exc:
            with self._lock:
                self.invalid[exc.reason] += 1
            self._log.warning(exc.reason, "invalid warning on %s (%s): %s",
                              str(sample.key_expr)[:200], exc.reason, exc.detail[:300])
            return
        with self._lock:
            self.received += 1
        try:
            self.on_warning(response)
        except Exception:
            log.exception("warning handler failed")

    def __enter__(self) -> WarningListener:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        subscribers, self._subscribers = self._subscribers, []
        for subscriber in subscribers:
            subscriber.undeclare()


class LinePrinter:
    """A warning handler writing one line per warning to ``out``, from a thread of its own.

    Zenoh calls the handler on its own threads: a write there that blocks (a reader that stopped
    reading: a pager, a stalled journal) held them, and with them Ctrl-C, until the reader went
    away. Lines wait in a queue of at most ``max_lines``; beyond it the oldest waiting line
    makes room for the newest, counted in ``unprinted`` and logged (at most one line every
    10 s): a reader slower than the warnings gets the latest, not ones many seconds old. A
    write that fails (the reader gone: ``BrokenPipeError``; a full disk) ends the printing:
    ``error`` holds it and ``on_error()`` is called once, so that the command can stop.

    Parameters
    ----------
    json_lines : bool
        One JSON object per line (:func:`format_json`) instead of :func:`format_warning`.
    out : text file
        Where the lines go; flushed after each, so that a pipe sees a warning at once.
    on_error : callable, optional
        Called (from the writing thread) when a write fails.
    max_lines : int
        Lines kept waiting for ``out`` at most.
    """

    def __init__(self, json_lines: bool, out, *, on_error: Callable[[], None] | None = None,
                 max_lines: int = 1000):
        self.out = out
        self.on_error = on_error
        self.max_lines = max_lines
        self.error: OSError | None = None
        self.unprinted = 0
        self._format = format_json if json_lines else format_warning
        self._lines: deque[str] = deque()
        self._ready = threading.Condition()
        self._closing = False
        self._log = RateLimitedLog(log)
        self._writer = threading.Thread(target=self._write, name="alerts-printer", daemon=True)
        self._writer.start()

    def __call__(self, response: Response) -> None:
        try:
            line = self._format(response)
        except Exception:  # never lose a warning to its formatting: fall back to JSON
            log.exception("cannot format a warning of %s; printed as JSON", response.robot)
            line = format_json(response)
        with self._ready:
            if self.error is not None:
                self.unprinted += 1
                return
            self._lines.append(line + "\n")
            self._ready.notify()
            if len(self._lines) <= self.max_lines:
                return
            self._lines.popleft()
            self.unprinted += 1
            unprinted = self.unprinted
        self._log.warning("unprinted", "the output is read slower than warnings come: %d older "
                          "warnings not printed (the latest %d wait for it)", unprinted,
                          self.max_lines)

    def _write(self) -> None:
        while True:
            with self._ready:
                while not self._lines and not self._closing:
                    self._ready.wait()
                if not self._lines:
                    return
                line = self._lines.popleft()
            try:
                self.out.write(line)
                self.out.flush()
            except OSError as exc:
                with self._ready:
                    self.error = exc
                    self.unprinted += 1 + len(self._lines)
                    self._lines.clear()
                if self.on_error is not None:
                    self.on_error()
                return

    def close(self, timeout: float = 2.0) -> bool:
        """Write the lines still waiting, for at most ``timeout`` seconds; True when all were
        written (or a write failed), False when ``out`` still blocks: those lines, and the one
        in the write that blocks, are then counted in ``unprinted``."""
        with self._ready:
            self._closing = True
            self._ready.notify()
        self._writer.join(timeout)
        if not self._writer.is_alive():
            return True
        with self._ready:
            self.unprinted += len(self._lines) + 1  # and the line in the write that blocks
            self._lines.clear()
        return False
