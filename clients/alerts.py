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
from collections import Counter
from collections.abc import Callable

import zenoh

from service import keys
from service.logutil import RateLimitedLog
from service.messages import MessageError, Response, track_label

from .fleet import decode_fleet_sample, declare_warning_subscribers

__all__ = ["WarningListener", "format_stamp", "format_warning"]

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
            f"{r.spike_rate:.0f} spikes/s, targets: {targets}")


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
        self._subscribers = declare_warning_subscribers(session, self.key, self._on_sample)

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


def printer(json_lines: bool, out) -> Callable[[Response], None]:
    """A handler writing one line per warning to ``out`` (flushed: pipes see it at once)."""
    lock = threading.Lock()
    fmt = format_json if json_lines else format_warning

    def show(response: Response) -> None:
        try:
            line = fmt(response)
        except Exception:  # never lose a warning to its formatting: fall back to JSON
            log.exception("cannot format a warning of %s; printed as JSON", response.robot)
            line = format_json(response)
        with lock:
            out.write(line + "\n")
            out.flush()

    return show
