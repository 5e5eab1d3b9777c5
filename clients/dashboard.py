"""The fleet dashboard: every robot seen on the wildcard keys, live in a browser.

Three parts, each usable alone:

- :class:`FleetStore` keeps the per-robot state (latest response, a ten-second spike-rate
  history, the latest warning, the latest preview thumbnail) and the log of the latest warnings.
  It validates every inbound message (a bad one is counted per reason, never raised), is thread
  safe, and hands out *deltas*: what changed since a version number. It needs neither Zenoh nor
  a browser.
- :class:`FleetSubscriber` feeds a store from a Zenoh session: ``<prefix>/*/response``,
  ``<prefix>/*/preview`` and ``<prefix>/*/warning`` (an advanced subscriber asking the workers'
  caches for history, so the latest warning of each robot shows at once, as in ``asnn alerts``),
  and for the dashboard ``<prefix>/*/refused`` (a worker refuses a robot's frames: its tile
  says why until a response comes).
- :class:`DashboardServer` serves the page (one HTML, one script, one style sheet, all from this
  package: nothing from the network) and Server-Sent Events from the standard library's
  ``ThreadingHTTPServer``. Each browser gets one full snapshot, then coalesced deltas, at most
  ``push_hz`` a second plus a heartbeat every second, so fifty robots at twenty responses a
  second stay cheap for the server and the page.

HTTP routes: ``/`` the page, ``/static/dashboard.js`` and ``/static/dashboard.css``, ``/events``
(``text/event-stream``: event ``snapshot`` then ``update``), ``/state`` (the full snapshot as JSON,
for scripts).

Bounds (docs/operations.md, "Hostile input"): at most ``max_robots`` robots (when the table is
full, the one silent longest makes room if it is stale); per robot a preview of at most
``service.messages.MAX_PREVIEW_BYTES`` and at most ``clients.fleet.MAX_TARGETS`` targets per
response (:func:`clients.fleet.decode_fleet_sample`, shared with the Foxglove server and ``asnn
alerts``), at most MAX_POINTS spike-rate points; all previews together at most
``max_preview_total`` bytes (the oldest previews are forgotten first), taken at most one a
robot every PREVIEW_INTERVAL seconds and PREVIEW_RATE bytes a second in all (the others are
counted as ``skipped``), so what a page is sent is bounded in bytes a second too. The server
closes connections idle for ``idle_timeout`` seconds (a request that does not arrive whole, a
kept-alive connection without a next request), reads a request's line and headers up to
MAX_REQUEST_BYTES, drops an event stream whose client has not taken an event within
``send_timeout`` seconds (at most SEND_BUFFER bytes wait in the kernel for each), holds at most
``max_streams`` event streams (``max_streams_per_address`` from one address) and ``max_streams
+ spare_connections`` connections in all (``max_streams_per_address + spare_connections / 2``
from one address), so that a browser can still load the page while another address holds what
it may (clients at three addresses can hold every connection: expose the dashboard to untrusted
networks only behind a proxy that authenticates), and sends at most MAX_FULL_SENDS full
snapshots (``/state``, a new stream's first event) at once, each the whole state encoded.
Invalid messages and dropped connections are logged rate-limited, without tracebacks.

Robot state as shown: **stale** when no response arrived for ``stale_after`` seconds (or none
ever did: a robot known only from a cached warning, or from its camera's previews): its camera
may still send previews, but no worker answers it, so nothing watches it; **collision**, unless
stale, when the latest response says so, or the robot's latest warning is at most ``hold``
seconds older (camera clock) than its latest response (or as much newer), so a warning that
lasts a few frames stays visible. A robot whose worker dies, or whose camera ends, mid-warning turns stale, not
held in collision.
"""

from __future__ import annotations

import base64
import contextlib
import http.server
import io
import json
import logging
import socket
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources

from asnn.params import SLOW_FPS
from service import keys
from service.logutil import RateLimitedLog
from service.messages import Preview, Refusal, Response, track_label

from .fleet import STALE_S, declare_warning_subscribers, stale_robot, take_fleet_sample

__all__ = ["DashboardServer", "FleetStore", "FleetSubscriber", "STATIC_FILES"]

log = logging.getLogger("asnn.dashboard")

HISTORY_S = 10.0      # spike-rate sparkline span, camera clock
HOLD_S = 3.0          # a warning keeps the robot in the collision state this long
FORGET_S = 600.0      # a robot silent this long is dropped from the dashboard
MAX_ROBOTS = 1000     # bound on the state a misbehaving publisher can make us keep
MAX_POINTS = 400      # per robot, whatever the stamps say (10 s at 40 responses a second)
LOG_SIZE = 50         # warning episodes kept in the log
LATE_RESPONSES = 3    # responses in a row behind the latest (a seq above 0) that are a restart
EPISODE_GAP = 20      # a warning at most this many frames after a robot's previous one extends
                      # the same log entry (one row per episode, not twenty rows a second) ...
EPISODE_GAP_S = 5.0   # ... and at most this many seconds later by its stamp (not a camera that
                      # restarted with its seq counting up again from below)
RECENT_TARGETS = 32   # responses whose targets are kept to match a preview's seq
MAX_PREVIEW_TOTAL = 16 * 1024 * 1024   # all thumbnails held, encoded
# thumbnails taken, so that what every page is sent stays bounded in bytes a second (a flood of
# 30 KB previews from 1,000 ids sent each page 20-34 MB/s, and a browser fell behind and was
# dropped): at most one a robot every PREVIEW_INTERVAL seconds (cameras send 2 a second), and
# PREVIEW_RATE encoded bytes a second in all; the others are skipped (counted)
PREVIEW_INTERVAL = 0.25
PREVIEW_RATE = 2 * 1024 * 1024
# full snapshots (a new event stream's first event, /state) encoded and being sent at once: each
# holds the whole state encoded (up to about 35 MB) until a slow client has taken it
MAX_FULL_SENDS = 4
IDLE_TIMEOUT = 10.0   # seconds a connection may wait for a whole request
SEND_TIMEOUT = 10.0   # seconds an event stream may wait for its client to take an event
SEND_BUFFER = 256 * 1024  # bytes the kernel may hold for one event stream
MAX_STREAMS = 32
MAX_STREAMS_PER_ADDRESS = 8
SPARE_CONNECTIONS = 32  # connections beyond the streams: page loads, /state
MAX_REQUEST_BYTES = 64 * 1024  # a request line and its headers (the pages send about 1 KB)

STATIC_FILES = {  # the only files served: name -> content type
    "index.html": "text/html; charset=utf-8",
    "dashboard.js": "text/javascript; charset=utf-8",
    "dashboard.css": "text/css; charset=utf-8",
}
SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; object-src 'none'; "
                               "base-uri 'none'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}


def _target(t) -> dict:
    """A target as the page draws it: the contract's fields, and the tracker's id and time to
    contact where the model gives them (robust default); ``label``, the id as ``asnn alerts``
    shows it (``"25:3"`` for track 3 of a model started at frame 25)."""
    out = {"x": t.x, "y": t.y, "direction": t.direction, "energy": t.energy, "pixels": t.pixels}
    if t.id is not None:
        out["id"] = t.id
        out["label"] = track_label(t.id)
    if t.ttc is not None:
        out["ttc"] = t.ttc
    return out


@dataclass
class _Robot:
    name: str
    changed: int = 0                  # version of the last change shown on the tile
    preview_changed: int = 0          # version of the last new preview
    points_reset: int = 0             # version at which the spike history was cleared
    response: Response | None = None
    warning: Response | None = None   # the latest warning
    preview: dict | None = None
    answered: float | None = None     # arrival (store clock) of the latest response
    touched: float = 0.0              # arrival of anything, for forgetting
    points: deque = field(default_factory=deque)  # (version, stamp, spike_rate)
    # (seq, its targets as JSON) of the latest responses
    recent_targets: deque = field(default_factory=lambda: deque(maxlen=RECENT_TARGETS))
    shown: deque = field(default_factory=lambda: deque(maxlen=RECENT_TARGETS))  # (seq, stamp)
    episode: dict | None = None       # its latest entry in the warning log
    refused: Refusal | None = None    # a worker's latest notice that it refuses its frames
    refused_at: float = 0.0           # its arrival (store clock)
    preview_at: float | None = None   # arrival (store clock) of the latest preview taken
    behind: int = 0                   # responses in a row stamped before the latest shown
    responses: int = 0
    warnings: int = 0
    previews: int = 0

    def latest_stamp(self) -> float | None:
        """The latest response's stamp, where the spike-rate history ends (a warning's is not:
        one of a clock gone back since, or forged far ahead, would push the history out)."""
        return None if self.response is None else self.response.stamp

    def collision(self, hold: float) -> bool:
        if self.response is not None and self.response.collision:
            return True
        if self.warning is None:
            return False
        if self.response is None:
            return True
        # within ``hold`` of the latest response, either way (a warning may arrive before its
        # frame's response); one far ahead of it is from a clock that went back since (a
        # camera that restarted) or forged, and would otherwise hold the collision for ever
        return abs(self.response.stamp - self.warning.stamp) <= hold


class FleetStore:
    """Per-robot state of the fleet, fed with raw Zenoh samples, read as JSON-ready deltas.

    Parameters
    ----------
    prefix : str
        Key prefix of the samples given to :meth:`offer`.
    history : float
        Seconds of the camera's clock the spike-rate sparkline spans.
    hold : float
        Seconds a warning keeps the robot in the collision state.
    stale_after : float
        Seconds without a response after which a robot is shown stale, and may be dropped to
        make room for a new one.
    forget_after : float
        Seconds of silence after which a robot is dropped.
    max_robots : int
        Robots held at once (a message of one more is counted, ``too-many-robots``).
    max_preview_total : int
        Encoded bytes of all thumbnails held.
    log_size : int
        Warning episodes kept in the log.
    log_interval : float
        Seconds between two log lines of the same rejection reason.
    clock : callable
        Seconds, monotonic (arrival times, staleness); injectable for tests.
    """

    def __init__(self, prefix: str = keys.DEFAULT_PREFIX, *, history: float = HISTORY_S,
                 hold: float = HOLD_S, stale_after: float = STALE_S,
                 forget_after: float = FORGET_S, max_robots: int = MAX_ROBOTS,
                 max_preview_total: int = MAX_PREVIEW_TOTAL, log_size: int = LOG_SIZE,
                 log_interval: float = 10.0, clock: Callable[[], float] = time.monotonic):
        self.prefix = keys.check_prefix(prefix)
        self.history, self.hold, self.stale_after = history, hold, stale_after
        self.forget_after, self.max_robots = forget_after, max_robots
        self.max_preview_total = max_preview_total
        self.clock = clock
        self._log_limited = RateLimitedLog(log, log_interval, clock)
        self._preview_bytes = 0  # encoded bytes of every preview held
        self._preview_budget, self._budget_at = float(PREVIEW_RATE), clock()  # PREVIEW_RATE
        self.skipped: Counter = Counter()  # valid messages not shown (previews over the rate)
        self.invalid: Counter = Counter()
        self.received: Counter = Counter()
        self._robots: dict[str, _Robot] = {}
        self._log: deque = deque(maxlen=log_size)  # (version, entry)
        self._version = 0
        self._next_entry = 0
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)

    # ------------------------------------------------------------------ input

    def offer(self, key: str, payload: bytes) -> str | None:
        """Take one sample of ``<prefix>/<robot>/(response|warning|preview|refused)``.

        Returns the robot id, or ``None`` when the message was invalid (counted in
        ``invalid`` by reason and logged). Never raises for bad input.
        """
        sample = take_fleet_sample(key, payload, self.prefix, self._reject)
        if sample is None:
            return None
        robot, kind, message = sample
        with self._lock:
            state = self._robot_locked(robot)
            if state is None:
                self.invalid["too-many-robots"] += 1
                self._log_limited.warning("too-many-robots", "dropped a %s of %s: already "
                                          "showing %d robots", kind, robot, self.max_robots)
                return None
            self.received[kind] += 1
            now = self.clock()
            state.touched = now
            if kind == "preview" and not self._take_preview_locked(state, len(message.data), now):
                self.skipped["preview"] += 1
                return robot
            version = self._bump_locked()
            if kind == "preview":
                self._add_preview_locked(state, message, version)
            elif kind == "refused":
                state.refused, state.refused_at, state.changed = message, now, version
            elif kind == "response":
                self._add_response_locked(state, message, version, now)
            else:
                self._add_warning_locked(state, message, version)
            self._changed.notify_all()
        return robot

    def _reject(self, reason: str, detail: str, key) -> None:
        with self._lock:
            self.invalid[reason] += 1
        self._log_limited.warning(reason, "invalid message on %r (%s): %s", str(key)[:200],
                                  reason, detail[:300])
        return None

    def _robot_locked(self, robot: str) -> _Robot | None:
        """The robot's state, made if there is room: when the table is full, the robot silent
        longest makes room if it is stale (a burst of ids cannot hide new robots for long)."""
        state = self._robots.get(robot)
        if state is None:
            if len(self._robots) >= self.max_robots:
                quiet = stale_robot(self._robots, self.clock(), self.stale_after)
                if quiet is None:
                    return None
                self._forget_robot_locked(quiet)
            state = self._robots[robot] = _Robot(robot)
        return state

    def _forget_robot_locked(self, name: str) -> None:
        state = self._robots.pop(name)
        if state.preview is not None:
            self._preview_bytes -= state.preview["bytes"]

    def _bump_locked(self) -> int:
        self._version += 1
        return self._version

    def _add_response_locked(self, state: _Robot, response: Response, version: int,
                             now: float) -> None:
        previous = state.response
        if (response.seq, response.stamp) in state.shown:
            # a second answer to a frame already shown: both workers may answer one frame
            # around a hand-over, the old one last, and it is no restart of the camera
            state.responses += 1
            return
        state.shown.append((response.seq, response.stamp))
        if previous is not None and response.stamp < previous.stamp:
            state.behind += 1
            if response.seq > 0 and state.behind < LATE_RESPONSES:
                # a late answer (a worker that stalled and resumed after another took the robot
                # over answered frames seconds old): counted, not shown, the history kept
                state.responses += 1
                return
            state.points.clear()  # the camera's clock went back (restart): a new history
            state.points_reset = version
        state.behind = 0
        state.response, state.answered, state.changed = response, now, version
        state.responses += 1
        state.points.append((version, response.stamp, response.spike_rate))
        # at most MAX_TARGETS, kept as the page draws them, in JSON: as Response objects the
        # targets of 32 responses of 1,000 robot ids held 670 MB (1.3 KB a target)
        state.recent_targets.append((response.seq, json.dumps(
            [_target(t) for t in response.targets], separators=(",", ":")).encode()))
        horizon = response.stamp - self.history
        while state.points and (state.points[0][1] < horizon or len(state.points) > MAX_POINTS):
            state.points.popleft()

    def _add_warning_locked(self, state: _Robot, warning: Response, version: int) -> None:
        held, latest = state.warning, state.response
        if (held is None or warning.stamp >= held.stamp
                or (latest is not None and held.stamp - latest.stamp > self.hold)):
            state.warning = warning  # the latest, unless the one held is of a clock gone back
        state.warnings += 1
        state.changed = version
        self._log_warning_locked(state, warning, version)

    def _log_warning_locked(self, state: _Robot, w: Response, version: int) -> None:
        """One log entry per warning episode: consecutive warnings of a robot extend it."""
        entry = state.episode
        if (entry is not None and self._log and entry["id"] >= self._log[0][1]["id"]
                and entry["first_seq"] <= w.seq <= entry["seq"] + EPISODE_GAP
                and entry["first_stamp"] <= w.stamp <= entry["stamp"] + EPISODE_GAP_S):
            entry["count"] += 1
            entry["peak_rate"] = max(entry["peak_rate"], w.spike_rate)
            entry["peak_out"] = max(entry["peak_out"], w.out)
            if w.seq >= entry["seq"]:
                entry.update(seq=w.seq, stamp=w.stamp, out=w.out, spike_rate=w.spike_rate,
                             targets=len(w.targets))
            # move it to the end: the log is ordered by the last change
            for i, (_, item) in enumerate(self._log):
                if item is entry:
                    del self._log[i]
                    break
            self._log.append((version, entry))
            return
        self._next_entry += 1
        entry = state.episode = {
            "id": self._next_entry, "robot": w.robot, "first_seq": w.seq, "seq": w.seq,
            "first_stamp": w.stamp, "stamp": w.stamp, "count": 1, "out": w.out,
            "spike_rate": w.spike_rate, "peak_rate": w.spike_rate, "peak_out": w.out,
            "targets": len(w.targets),
            "worker": w.worker}
        self._log.append((version, entry))

    def _take_preview_locked(self, state: _Robot, size: int, now: float) -> bool:
        """Whether a thumbnail of ``size`` bytes arriving at ``now`` is taken: at most one a
        robot every PREVIEW_INTERVAL seconds, and PREVIEW_RATE bytes a second in all (a bucket
        that fills at that rate, holding at most a second's worth)."""
        if state.preview_at is not None and now - state.preview_at < PREVIEW_INTERVAL:
            return False
        self._preview_budget = min(PREVIEW_RATE, self._preview_budget
                                   + (now - self._budget_at) * PREVIEW_RATE)
        self._budget_at = now
        if size > self._preview_budget:
            return False
        self._preview_budget -= size
        state.preview_at = now
        return True

    def _add_preview_locked(self, state: _Robot, preview: Preview, version: int) -> None:
        if state.preview is not None:
            self._preview_bytes -= state.preview["bytes"]
        state.preview = {
            "seq": preview.seq, "stamp": preview.stamp, "width": preview.width,
            "height": preview.height, "frame_width": preview.frame_width or preview.width,
            "frame_height": preview.frame_height or preview.height,
            "bytes": len(preview.data),
            "src": f"data:image/{preview.format};base64,"
                   + base64.b64encode(preview.data).decode("ascii")}
        self._preview_bytes += len(preview.data)
        state.preview_changed, state.changed = version, version
        state.previews += 1
        if self._preview_bytes > self.max_preview_total:  # forget the oldest previews first
            for other in sorted(self._robots.values(), key=lambda s: s.preview_changed):
                if self._preview_bytes <= self.max_preview_total:
                    break
                if other.preview is not None and other is not state:
                    self._preview_bytes -= other.preview["bytes"]
                    other.preview, other.changed = None, version

    @property
    def preview_bytes(self) -> int:
        """Encoded bytes of every preview held (at most ``max_preview_total``)."""
        with self._lock:
            return self._preview_bytes

    # ------------------------------------------------------------------ output

    @property
    def version(self) -> int:
        with self._lock:
            return self._version

    def wait(self, since: int, timeout: float) -> int:
        """Block until the version passes ``since`` or ``timeout`` elapses; the version."""
        with self._lock:
            self._changed.wait_for(lambda: self._version > since, timeout)
            return self._version

    def robots(self) -> list[str]:
        with self._lock:
            return sorted(self._robots)

    def delta(self, since: int = 0) -> dict:
        """What changed after version ``since`` (0: everything), JSON-ready.

        ``robots``: the tile of every robot changed since then, with the spike-rate points and
        (if new) the preview added since then; ``live``: for every robot, ``[age, stale,
        collision]`` (age in seconds since its last response, ``None`` if none);
        ``warnings``: log entries added since then, oldest first; ``full``: whether this
        replaces everything the receiver had.
        """
        with self._lock:
            now = self.clock()
            self._forget_locked(now)
            full = since <= 0
            robots, live = {}, {}
            for name in sorted(self._robots):
                state = self._robots[name]
                age = None if state.answered is None else max(now - state.answered, 0.0)
                stale = age is None or age > self.stale_after
                # a robot no worker answers is not watched: whatever it warned of last is
                # unknown now (its worker died, its camera ended), not a collision held
                collision = not stale and state.collision(self.hold)
                live[name] = [None if age is None else round(age, 3), stale, collision]
                if full or state.changed > since:
                    robots[name] = self._tile_locked(state, since, full, collision, stale)
            warnings = [dict(entry) for version, entry in self._log if full or version > since]
            return {
                "version": self._version, "full": full, "robots": robots, "live": live,
                "warnings": warnings,
                "config": {"history": self.history, "hold": self.hold,
                           "stale_after": self.stale_after, "slow_fps": SLOW_FPS,
                           "max_points": MAX_POINTS},
                "counts": {"robots": len(self._robots),
                           "collision": sum(v[2] for v in live.values()),
                           "stale": sum(v[1] for v in live.values()),
                           "received": dict(self.received), "invalid": dict(self.invalid),
                           "skipped": dict(self.skipped)},
            }

    def _tile_locked(self, state: _Robot, since: int, full: bool, collision: bool,
                     stale: bool) -> dict:
        r, w = state.response, state.warning
        reset = full or state.points_reset > since
        tile = {
            "robot": state.name, "collision": collision, "stale": stale,
            "responses": state.responses, "warnings": state.warnings, "previews": state.previews,
            "latest_stamp": state.latest_stamp(),
            "points_reset": reset,
            "points": [[stamp, rate] for version, stamp, rate in state.points
                       if reset or version > since],
            "response": None if r is None else {
                "seq": r.seq, "stamp": r.stamp, "u": r.u, "out": r.out, "spikes": r.spikes,
                "spike_rate": r.spike_rate, "collision": r.collision, "model": r.model,
                "preset": r.preset, "worker": r.worker, "latency_ms": r.latency_ms,
                "dropped": r.dropped},
            "last_warning": None if w is None else {"seq": w.seq, "stamp": w.stamp},
            "refused": self._refused_locked(state),
            "targets": self._targets_locked(state, collision),
        }
        if state.preview is not None:
            fresh = full or state.preview_changed > since
            tile["preview"] = state.preview if fresh else {
                k: v for k, v in state.preview.items() if k != "src"}
        return tile

    @staticmethod
    def _refused_locked(state: _Robot) -> dict | None:
        """A worker's refusal of the robot's frames, unless a response came after it."""
        notice = state.refused
        if notice is None or (state.answered is not None and state.answered >= state.refused_at):
            return None
        return {"worker": notice.worker, "reason": notice.reason, "detail": notice.detail,
                "count": notice.count}

    @staticmethod
    def _targets_locked(state: _Robot, collision: bool) -> list[dict]:
        """What to draw on the thumbnail: the looming targets of the response to the previewed
        frame when known; else the latest response's; else, while a warning holds the
        collision state, that warning's."""
        if state.preview is not None:
            for seq, targets in reversed(state.recent_targets):
                if seq == state.preview["seq"]:
                    return json.loads(targets)
        r, w = state.response, state.warning
        if r is not None and r.targets:
            return [_target(t) for t in r.targets]
        if w is not None and collision:
            return [_target(t) for t in w.targets]
        return []

    def _forget_locked(self, now: float) -> None:
        for name in [n for n, s in self._robots.items() if now - s.touched > self.forget_after]:
            self._forget_robot_locked(name)
            log.info("robot %s: silent for %.0f s, forgotten", name, self.forget_after)


class FleetSubscriber:
    """Declares the fleet viewers' subscribers on ``session`` (responses, previews, warnings,
    and with ``refusals`` the workers' refusal notices), feeding ``store`` (a
    :class:`FleetStore`, or anything with a ``prefix`` and an ``offer(key, payload)`` that never
    raises, such as the Foxglove bridge of :mod:`clients.foxglove`)."""

    def __init__(self, session, store: FleetStore, *, refusals: bool = False):
        prefix = store.prefix
        self.store = store
        self.keys = [keys.responses(prefix), keys.warnings(prefix), keys.previews(prefix)]
        if refusals:
            self.keys.append(keys.refusals(prefix))
        self._subscribers = [
            *(session.declare_subscriber(key, self._on_sample)
              for key in self.keys if key != keys.warnings(prefix)),
            # an advanced subscriber (history, recovery) and a plain one, each warning once
            *declare_warning_subscribers(session, keys.warnings(prefix), self._on_sample),
        ]

    def _on_sample(self, sample) -> None:
        try:
            self.store.offer(str(sample.key_expr), sample.payload.to_bytes())
        except Exception:  # offer never raises for bad input; this is a bug, keep listening
            log.exception("unexpected error on %s", sample.key_expr)

    def __enter__(self) -> FleetSubscriber:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        for subscriber in self._subscribers:
            try:
                subscriber.undeclare()
            except Exception:  # the session may already be closed
                pass
        self._subscribers = []


def load_static() -> dict[str, bytes]:
    """The page's files, from the installed package."""
    folder = resources.files("clients") / "dashboard_static"
    return {name: (folder / name).read_bytes() for name in STATIC_FILES}


class _RequestDeadline(io.RawIOBase):
    """A connection's bytes for the request reader, each request's to arrive whole by the
    handler's ``deadline``: a socket timeout alone bounds one wait, and a client sending a byte
    every few seconds would hold the connection for ever (a user trial held all of them)."""

    def __init__(self, sock: socket.socket, handler):
        super().__init__()
        self._sock, self._handler = sock, handler

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        remaining = self._handler.deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError("the request did not arrive whole in time")
        # the request line and headers in bytes: the standard library takes 100 headers of
        # 64 KiB each, 6.4 MB held per connection (a probe: 400 MB over 64 of them)
        if self._handler.request_bytes >= MAX_REQUEST_BYTES:
            raise ConnectionAbortedError(f"a request of more than {MAX_REQUEST_BYTES} bytes")
        self._sock.settimeout(remaining)
        received = self._sock.recv_into(buffer)
        self._handler.request_bytes += received
        return received


class _HTTPServer(http.server.ThreadingHTTPServer):
    """The standard threading server with a cap on connections and quiet error handling."""

    daemon_threads = True
    request_queue_size = 128  # the listen backlog (5 by default): bursts of page loads

    def __init__(self, address, handler, *, max_connections: int, max_per_address: int,
                 log_limited: RateLimitedLog):
        self.max_connections = max_connections
        self.max_per_address = max_per_address
        self.connections = 0
        self.refused = 0
        self._by_address: Counter = Counter()
        self._count_lock = threading.Lock()
        self._log_limited = log_limited
        super().__init__(address, handler)

    def process_request(self, request, client_address):
        address = client_address[0]
        with self._count_lock:
            full = (self.connections >= self.max_connections
                    or self._by_address[address] >= self.max_per_address)
            if full:
                self.refused += 1
            else:
                self.connections += 1
                self._by_address[address] += 1
        if full:  # answered here, on the accepting thread: no thread per refused connection
            self._log_limited.warning("connections", "refused a connection from %s: %d open "
                                      "(at most %d, %d from one address)", address,
                                      self.connections, self.max_connections,
                                      self.max_per_address)
            try:
                request.settimeout(0.5)
                request.sendall(b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\n"
                                b"Connection: close\r\n\r\n")
            except OSError:
                pass
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except Exception:
            self._release(address)
            raise

    def process_request_thread(self, request, client_address):
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._release(client_address[0])

    def _release(self, address: str) -> None:
        with self._count_lock:
            self.connections -= 1
            self._by_address[address] -= 1
            if not self._by_address[address]:
                del self._by_address[address]

    def handle_error(self, request, client_address):
        """A connection that failed (reset, timed out): one rate-limited line, no traceback."""
        import sys

        exc = sys.exc_info()[1]
        self._log_limited.warning("connection-error", "connection from %s ended: %s",
                                  client_address[0], f"{type(exc).__name__}: {exc}"[:200])


class DashboardServer:
    """The page and its event stream on ``host:port`` (``port=0``: a free one, see ``url``).

    Use as a context manager, or call ``start`` and ``close``. The limits are described in the
    module notes.
    """

    def __init__(self, store: FleetStore, host: str = "127.0.0.1", port: int = 8080, *,
                 push_hz: float = 5.0, heartbeat: float = 1.0, max_streams: int = MAX_STREAMS,
                 max_streams_per_address: int = MAX_STREAMS_PER_ADDRESS,
                 spare_connections: int = SPARE_CONNECTIONS,
                 idle_timeout: float = IDLE_TIMEOUT, send_timeout: float = SEND_TIMEOUT,
                 send_buffer: int = SEND_BUFFER, log_interval: float = 10.0):
        self.store = store
        self.min_interval = 1.0 / push_hz
        self.heartbeat = heartbeat
        self.max_streams = max_streams
        self.max_streams_per_address = max_streams_per_address
        self.idle_timeout = idle_timeout
        self.send_timeout = send_timeout
        self.send_buffer = send_buffer
        self.closing = threading.Event()
        self.clients = 0
        self.dropped_streams = 0  # event streams dropped because their client did not read
        self._streams_by_address: Counter = Counter()
        self._clients_lock = threading.Lock()
        self._full_sends = threading.BoundedSemaphore(MAX_FULL_SENDS)
        self._log_limited = RateLimitedLog(log, log_interval)
        self._static = load_static()
        self._httpd = _HTTPServer((host, port), self._handler_class(),
                                  max_connections=max_streams + spare_connections,
                                  max_per_address=max_streams_per_address
                                  + spare_connections // 2,
                                  log_limited=self._log_limited)
        self._thread: threading.Thread | None = None

    @property
    def connections(self) -> int:
        """Connections open now (event streams included)."""
        return self._httpd.connections

    @property
    def address(self) -> tuple[str, int]:
        return self._httpd.server_address[:2]

    @property
    def url(self) -> str:
        host, port = self.address
        return f"http://{'127.0.0.1' if host in ('0.0.0.0', '') else host}:{port}/"

    def start(self) -> DashboardServer:
        """Serve on a thread of its own; once (``with DashboardServer(...).start()`` starts it
        once, not twice)."""
        if self._thread is not None:
            return self
        self._thread = threading.Thread(target=self._httpd.serve_forever, kwargs={
            "poll_interval": 0.2}, name="asnn-dashboard-http", daemon=True)
        self._thread.start()
        return self

    def __enter__(self) -> DashboardServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop serving; open event streams end within a heartbeat."""
        self.closing.set()
        if self._thread is not None:
            self._httpd.shutdown()
            self._thread.join(timeout=10)
            self._thread = None
        self._httpd.server_close()

    # ------------------------------------------------------------------ requests

    def _handler_class(self):
        server = self

        class Handler(http.server.BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"
            server_version = "asnn-dashboard"
            sys_version = ""
            timeout = server.idle_timeout  # a request must arrive whole within it
            deadline = 0.0
            request_bytes = 0  # read for the request in hand (MAX_REQUEST_BYTES)

            def setup(self):
                super().setup()
                self.rfile = io.BufferedReader(_RequestDeadline(self.connection, self))

            def handle_one_request(self):
                # from the connection's start or the previous answer: idle time counts too
                self.deadline = time.monotonic() + self.timeout
                self.request_bytes = 0
                super().handle_one_request()

            def parse_request(self):
                parsed = super().parse_request()
                self.connection.settimeout(self.timeout)  # writing the answer: the full time
                return parsed

            def end_headers(self):
                # on every answer, the standard library's error pages (400, 431, 501) included
                for name, value in SECURITY_HEADERS.items():
                    self.send_header(name, value)
                super().end_headers()

            def log_message(self, format, *args):  # noqa: A002 (the base class's name)
                log.debug("%s %s", self.address_string(), format % args)

            def do_HEAD(self):
                self.do_GET(head=True)

            def do_GET(self, head: bool = False):
                path = self.path.split("?", 1)[0]
                if path in ("/", "/index.html"):
                    self._send(200, STATIC_FILES["index.html"], server._static["index.html"],
                               head)
                elif path.startswith("/static/") and path[8:] in STATIC_FILES:
                    name = path[8:]
                    self._send(200, STATIC_FILES[name], server._static[name], head)
                elif path == "/state":
                    with server._full_send() as taken:
                        if not taken:
                            self.close_connection = True
                            self._send(503, "text/plain; charset=utf-8", b"busy: try again\n",
                                       head, cache=False)
                            return
                        body = json.dumps(server.store.delta(0)).encode()
                        self._send(200, "application/json", body, head, cache=False)
                elif path == "/events" and head:
                    # a health check's HEAD: the stream's headers, no stream held open
                    server._stream_headers(self)
                elif path == "/events":
                    server._stream(self)
                else:
                    self._send(404, "text/plain; charset=utf-8", b"not found\n", head)

            def _send(self, status, ctype, body, head, cache=True):
                self.send_response(status)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-cache" if cache else "no-store")
                self.end_headers()
                if not head:
                    self.wfile.write(body)

        return Handler

    @contextlib.contextmanager
    def _full_send(self):
        """One of the MAX_FULL_SENDS slots for a full snapshot, waited for up to
        ``send_timeout``: yields whether it was taken (each holds the whole state encoded)."""
        taken = self._full_sends.acquire(timeout=self.send_timeout)
        try:
            yield taken
        finally:
            if taken:
                self._full_sends.release()

    @staticmethod
    def _stream_headers(handler) -> None:
        handler.send_response(200)
        handler.send_header("Content-Type", "text/event-stream; charset=utf-8")
        handler.send_header("Cache-Control", "no-store")
        handler.send_header("X-Accel-Buffering", "no")
        handler.end_headers()

    def _stream(self, handler) -> None:
        """Server-Sent Events: a snapshot, then deltas at most every ``min_interval``."""
        address = handler.client_address[0]
        with self._clients_lock:
            full = (self.clients >= self.max_streams
                    or self._streams_by_address[address] >= self.max_streams_per_address)
            if not full:
                self.clients += 1
                self._streams_by_address[address] += 1
        if full:
            handler.close_connection = True
            handler._send(503, "text/plain; charset=utf-8", b"too many dashboards open\n",
                          False, cache=False)
            return
        try:
            sock = handler.connection
            # what a client that does not read can make us hold: the kernel's buffer, one event
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.send_buffer)
            sock.settimeout(self.send_timeout)
            self._stream_headers(handler)
            handler.close_connection = True
            out = handler.wfile
            out.write(b"retry: 2000\n\n")
            since, event, last = 0, "snapshot", 0.0
            while not self.closing.is_set():
                with self._full_send() if since == 0 else contextlib.nullcontext(True) as taken:
                    if not taken:
                        break  # closed: the page opens another stream
                    delta = self.store.delta(since)
                    since = delta["version"]
                    out.write(f"event: {event}\ndata: {json.dumps(delta)}\n\n".encode())
                    out.flush()
                del delta  # not held while waiting: a snapshot is the whole state
                event, last = "update", time.monotonic()
                self.store.wait(since, self.heartbeat)
                # coalesce: everything that arrives within the interval goes in one delta
                pause = self.min_interval - (time.monotonic() - last)
                if pause > 0 and self.closing.wait(pause):
                    break
        except TimeoutError:  # the client took no event for send_timeout seconds
            with self._clients_lock:
                self.dropped_streams += 1
            self._log_limited.warning("slow-client", "dropped the event stream of %s: it took "
                                      "no event for %.0f s", address, self.send_timeout)
        except (BrokenPipeError, ConnectionResetError, ConnectionAbortedError):
            pass  # the browser went away
        finally:
            with self._clients_lock:
                self.clients -= 1
                self._streams_by_address[address] -= 1
                if not self._streams_by_address[address]:
                    del self._streams_by_address[address]
