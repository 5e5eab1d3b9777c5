"""The dashboard's fleet state (:class:`FleetStore`): every robot's latest response, spike-rate
history, warning and preview, and the log of warnings, as deltas since a version; no Zenoh, no
browser. Its bounds and the states a robot is shown in: :mod:`clients.dashboard`."""

from __future__ import annotations

import base64
import json
import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field

from asnn.params import SLOW_FPS
from service import keys
from service.logutil import RateLimitedLog
from service.messages import Preview, Refusal, Response, track_label

from ..fleet import (ANSWERED_FRAMES, STALE_S, foreign_preview, refusal_shown, remember_answer,
                     stale_robot, take_fleet_sample)

__all__ = ["FleetStore", "HOLD_S"]

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
    shown: deque = field(default_factory=lambda: deque(maxlen=ANSWERED_FRAMES))  # (seq, stamp)
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
        self._router: bool | None = None  # whether the session reaches its router, once known
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
            if kind == "preview" and foreign_preview(message, state.shown, state.answered, now,
                                                     self.stale_after):
                # a second publisher's thumbnail (the worker follows the other camera):
                # shown, it put one camera's picture under the other's targets
                self.skipped["foreign-preview"] += 1
                return robot
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

    def router_changed(self, connected: bool) -> None:
        """Whether the dashboard's Zenoh session reaches its router (told by
        :class:`service.link.RouterWatch`): without one no message comes from any robot, so
        the page says so rather than show every robot stale as if its worker or camera had
        failed."""
        with self._lock:
            if self._router != connected:
                self._router = connected
                self._bump_locked()
                self._changed.notify_all()

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
        remember_answer(state.shown, response.seq, response.stamp)
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
        # where the entry is in the log, if still there: the log is ordered by last change,
        # not by id (an id test took a continuing episode behind a newer one for gone)
        at = None if entry is None else next(
            (i for i, (_, item) in enumerate(self._log) if item is entry), None)
        if (at is not None
                and entry["first_seq"] <= w.seq <= entry["seq"] + EPISODE_GAP
                and entry["first_stamp"] <= w.stamp <= entry["stamp"] + EPISODE_GAP_S):
            entry["count"] += 1
            entry["peak_rate"] = max(entry["peak_rate"], w.spike_rate)
            entry["peak_out"] = max(entry["peak_out"], w.out)
            if w.seq >= entry["seq"]:
                entry.update(seq=w.seq, stamp=w.stamp, out=w.out, spike_rate=w.spike_rate,
                             targets=len(w.targets))
            del self._log[at]  # to the end: the log is ordered by the last change
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
        replaces everything the receiver had; ``router``: whether the dashboard's session
        reaches its router (``None`` until a router was seen: peers without one, or the start).
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
                    robots[name] = self._tile_locked(state, since, full, collision, stale,
                                                     now)
            warnings = [dict(entry) for version, entry in self._log if full or version > since]
            return {
                "version": self._version, "full": full, "robots": robots, "live": live,
                "warnings": warnings, "router": self._router,
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
                     stale: bool, now: float) -> dict:
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
            "refused": self._refused_locked(state, now),
            "targets": self._targets_locked(state, collision),
        }
        if state.preview is not None:
            fresh = full or state.preview_changed > since
            tile["preview"] = state.preview if fresh else {
                k: v for k, v in state.preview.items() if k != "src"}
        return tile

    @staticmethod
    def _refused_locked(state: _Robot, now: float) -> dict | None:
        """A worker's refusal of the robot's frames, unless a response came after it; a second
        publisher's for CONTESTED_FOR_S whatever came after (the robot's own frames are
        answered while the other camera's are refused: the worker's ``contested``)."""
        notice = state.refused
        if notice is None or not refusal_shown(notice.reason, state.refused_at, state.answered,
                                               now):
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
