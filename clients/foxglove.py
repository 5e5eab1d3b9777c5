"""The live fleet in Foxglove: the robots' previews, targets, responses and warnings served
through the Foxglove SDK's WebSocket server (``asnn foxglove``).

:class:`FoxgloveBridge` takes the samples of ``<prefix>/<robot>/(response|warning|preview)``
(fed by :class:`clients.fleet.FleetSubscriber`, the dashboard's subscribers) and logs them on
topics named after the robot, in the schemas ``asnn detect --mcap`` writes
(:mod:`asnn.io.foxglove_mcap`), so one Foxglove layout serves a recorded run and the fleet:

``/<prefix>/<robot>/preview``      ``foxglove.CompressedImage``   the camera's thumbnail
``/<prefix>/<robot>/annotations``  ``foxglove.ImageAnnotations``  each response's targets, scaled
                                                                  to the thumbnail
``/<prefix>/<robot>/response``     JSON ``asnn.Response``         every response (plottable)
``/<prefix>/<robot>/warning``      JSON ``asnn.Response``         every warning

A second camera on a robot's key (the worker refuses its frames, not its previews) is shown as
the dashboard shows it: while the robot is answered, a preview is forwarded only where it can be
of the answered frames (:func:`clients.fleet.answered_frame`), so the robot's targets are never
drawn on, nor scaled to, the other camera's picture; the others are counted in ``skipped``
(``foreign-preview``).

The viewers are told in Foxglove's problems list (the protocol's status messages, by id) what
the dashboard's tiles show: a robot answered once and not for ``stale_after`` seconds has its
targets cleared (an empty ``ImageAnnotations`` at the latest stamp of its pictures, so that the
Image panel keeps no target nor red warning border over live pictures) and a Warning
``stale:<robot>``, both until its next response; the server's Zenoh session without a router
(:meth:`FoxgloveBridge.router_changed`, told by ``service.link.RouterWatch``) is an Error
``router``, until one is reached again; a worker's notice that it refuses a robot's frames
(``<prefix>/<robot>/refused``) is a Warning ``refused:<robot>`` naming the worker, the reason
and its detail (said again when the reason changes), until the robot's next
response, or for a ``second-publisher`` refusal until ``service.streams.CONTESTED_FOR_S``
after the latest notice (contested: the robot's own frames are answered meanwhile). The SDK
sends a status to the viewers connected at the time only: the problems shown are said again
within a second of a viewer's subscribing to a topic (one that connected since has them then).

Bounds (docs/operations.md, "Hostile input"), the dashboard's rules: every inbound message is
validated by :func:`clients.fleet.decode_fleet_sample`, as the dashboard validates it (previews of at
most ``service.messages.MAX_PREVIEW_BYTES``, decoded; at most ``MAX_TARGETS`` targets per
response); invalid ones are counted per reason and logged rate-limited (one line per reason
every ``log_interval`` seconds), never raised. The SDK's own WARNING and ERROR lines, one per
invalid message of a viewer or failed handshake, are rate-limited alike (:class:`SdkLogLimit`
on :data:`SDK_LOGGERS`). A robot costs four channels and the ``(seq, stamp)`` of its latest
``ANSWERED_FRAMES`` answered frames, for at most ``max_robots`` robots; when the table is full,
the robot silent longest makes room if it has been silent for ``stale_after`` seconds, and
robots silent for ``forget_after`` seconds are dropped (their channels unadvertised). No
picture is kept, each is forwarded as it comes, and the server holds at most ``backlog``
messages per connected viewer (the oldest are dropped for a slow one), so a viewer costs at
most ``backlog`` previews.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

# first: without the 'ros' extra, this import fails with a message naming it
from asnn.io.foxglove_mcap import (RESPONSE_SCHEMA, McapRecording, close_channels,
                                   response_message, target_annotations, time_ns, timestamp)

import foxglove
from foxglove.channels import CompressedImageChannel, ImageAnnotationsChannel
from foxglove.messages import CompressedImage, ImageAnnotations
from foxglove.websocket import ServerListener, StatusLevel

from service import keys
from service.logutil import RateLimitedLog
from service.messages import Preview, Refusal, Response, track_label

from .fleet import (ANSWERED_FRAMES, STALE_S, foreign_preview, refusal_shown, remember_answer,
                    stale_robot, take_fleet_sample)

__all__ = ["DEFAULT_PORT", "SDK_LOGGERS", "FoxgloveBridge", "SdkLogLimit", "robot_topics",
           "sdk_log_reason"]

log = logging.getLogger("asnn.foxglove")

DEFAULT_PORT = 8765   # Foxglove's usual WebSocket port
MAX_ROBOTS = 256
FORGET_S = 600.0      # a robot silent this long loses its channels
BACKLOG = 256         # messages queued per viewer before the oldest are dropped
RECORD_MAX_BYTES = 10**9  # a recording stops at this size (asnn foxglove --mcap-max-mb: 1000)
STATUS_INTERVAL = 1.0  # seconds between two messages of one status id to the viewers


# the SDK's loggers (its Rust modules' log lines, through pyo3-log) that write a line per
# invalid message of a viewer and per failed handshake: 20,000 ERROR lines in 4 s from one viewer
SDK_LOGGERS = ("foxglove.websocket.server", "foxglove.websocket.connected_client",
               "foxglove.websocket.connected_client.poller")
_CLIENT_ADDRESS = re.compile(r"\[[^\]\s]{1,64}\](?::\d+)?"             # [::1]:50600
                             r"|\b\d{1,3}(?:\.\d{1,3}){3}(?::\d+)?")  # 127.0.0.1:50600


def sdk_log_reason(record: logging.LogRecord) -> str:
    """The rate limit's reason for a line of the SDK: its logger and its words up to the first
    ``": "``, with the viewers' addresses and the numbers left out. What a viewer sent (the
    parser's error, after the colon) is never part of it, so a viewer cannot make a reason of
    each message (``Invalid message from 127.0.0.1:50600: key must be a string at line 1
    column 2`` -> ``...connected_client:Invalid message from <client>``)."""
    text = _CLIENT_ADDRESS.sub("<client>", record.getMessage()).split(": ", 1)[0]
    return f"{record.name}:{re.sub(r'[0-9]+', '#', text)[:100]}"


class SdkLogLimit(logging.Filter):
    """The Foxglove SDK's own WARNING and ERROR lines (a viewer's invalid messages, failed
    handshakes) as the server's own rejections are logged (``service.logutil.RateLimitedLog``):
    per reason (:func:`sdk_log_reason`) the first at once, then at most one every
    ``interval`` seconds, saying how many were not shown. Its lines below WARNING (a viewer
    registered, unregistered) pass."""

    def __init__(self, interval: float = 10.0, clock: Callable[[], float] = time.monotonic):
        super().__init__()
        self.limit = RateLimitedLog(log, interval, clock)

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.WARNING:
            return True
        hidden = self.limit.allow(sdk_log_reason(record))
        if hidden is None:
            return False
        if hidden:
            record.msg = f"{record.getMessage()} ({hidden} more like it since the last line)"
            record.args = ()
        return True


def robot_topics(prefix: str, robot: str) -> dict[str, str]:
    """The Foxglove topics of a robot: ``/<prefix>/<robot>/<kind>`` per kind."""
    return {kind: f"/{prefix}/{robot}/{kind}"
            for kind in ("preview", "annotations", "response", "warning")}


@dataclass
class _Robot:
    """The channels of one robot and what scaling its targets needs."""

    preview: CompressedImageChannel
    annotations: ImageAnnotationsChannel
    response: foxglove.Channel
    warning: foxglove.Channel
    size: tuple[int, int] | None = None            # the latest thumbnail's (width, height)
    scale: tuple[float, float] = (1.0, 1.0)        # frame pixels -> thumbnail pixels
    touched: float = 0.0
    answered: float | None = None                  # arrival (clock) of its latest response
    # (seq, stamp) of its latest answered frames: a preview of others is a second camera's
    shown: deque = field(default_factory=lambda: deque(maxlen=ANSWERED_FRAMES))
    stamp_ns: int | None = None                    # the latest logged on its image topics
    stale: bool = False                            # its drawing cleared, its status shown
    refusal: str | None = None                     # the reason of the refusal shown
    refused_at: float = 0.0                        # arrival (clock) of the latest notice

    def close(self) -> None:
        close_channels(self.preview, self.annotations, self.response, self.warning)


class _Subscriptions(ServerListener):
    """Notes that a viewer subscribed to a topic: a viewer that connected since the problems
    were said (the SDK sends a status to the viewers connected at the time only)."""

    def __init__(self) -> None:
        self.new = threading.Event()

    def on_subscribe(self, client, channel) -> None:
        self.new.set()


class FoxgloveBridge:
    """A Foxglove WebSocket server showing the fleet, fed with raw Zenoh samples. Use as a
    context manager, or call :meth:`close`.

    Parameters
    ----------
    prefix : str
        Key prefix of the samples given to :meth:`offer`.
    host, port : str, int
        Where the server listens (``port=0``: a free one, see :attr:`port`). 127.0.0.1 by
        default: the protocol has no authentication.
    max_robots : int
        Robots served at once; a message of one more is counted (``too-many-robots``) and
        dropped unless a robot silent for ``stale_after`` seconds makes room.
    stale_after : float
        Seconds without a response after which a robot is stale: its targets are cleared, a
        status names it, and it may give up its place.
    forget_after : float
        Seconds of silence after which a robot's channels are closed.
    backlog : int
        Messages queued per viewer (the SDK drops the oldest for a slow viewer).
    log_interval : float
        Seconds between two log lines of the same rejection reason.
    clock : callable
        Seconds, monotonic (staleness, forgetting, log rate); injectable for tests.
    record : str or Path, optional
        A new MCAP file that records every message the viewers are sent, as they are sent
        (:class:`asnn.io.foxglove_mcap.McapRecording`), until :meth:`close`; the problems
        (statuses) are not in it.
    record_max_bytes : float
        The recording stops, said at WARNING, once its file has reached this size (checked
        every sweep, about a second), or at the first write that failed (a full disk).
    """

    def __init__(self, prefix: str = keys.DEFAULT_PREFIX, *, host: str = "127.0.0.1",
                 port: int = DEFAULT_PORT, max_robots: int = MAX_ROBOTS,
                 stale_after: float = STALE_S, forget_after: float = FORGET_S,
                 backlog: int = BACKLOG, log_interval: float = 10.0,
                 clock: Callable[[], float] = time.monotonic,
                 record: str | Path | None = None,
                 record_max_bytes: float = RECORD_MAX_BYTES):
        self.prefix = keys.check_prefix(prefix)
        self.max_robots, self.stale_after = max_robots, stale_after
        self.forget_after, self.clock = forget_after, clock
        self.received: Counter = Counter()
        self.invalid: Counter = Counter()
        self.skipped: Counter = Counter()  # valid messages not forwarded (foreign-preview)
        self._robots: dict[str, _Robot] = {}
        self._statuses: dict[str, tuple[str, StatusLevel]] = {}  # shown to the viewers, by id
        self._told_at: dict[str, float] = {}  # when each status id was last told the viewers
        self._untold: set[str] = set()  # ids whose latest state waits for STATUS_INTERVAL
        self._lock = threading.Lock()
        self._log = RateLimitedLog(log, log_interval, clock)
        self._next_sweep = clock()
        self._context = foxglove.Context()  # the fleet's channels reach this server only
        # the SDK logs a line per invalid message of a viewer: rate-limited as ours are
        self._sdk_log = SdkLogLimit(log_interval, clock)
        self._subscriptions = _Subscriptions()
        for name in SDK_LOGGERS:
            logging.getLogger(name).addFilter(self._sdk_log)
        try:
            self.server = foxglove.start_server(
                name=f"asnn fleet ({self.prefix})", host=host, port=port, context=self._context,
                message_backlog_size=backlog, server_listener=self._subscriptions)
        except Exception as exc:  # the SDK's own error type: the port is taken, a bad address
            self._unfilter_sdk_log()
            raise OSError(f"cannot serve Foxglove on {host}:{port}: {exc}") from None
        self.host = host
        self.recording: McapRecording | None = None
        self.record_max_bytes = record_max_bytes
        if record is not None:
            try:
                self.recording = McapRecording(record, self._context)
            except OSError:
                self.server.stop()
                self._unfilter_sdk_log()
                raise
        # robots are forgotten in silence too: with the whole fleet quiet (its cameras stopped,
        # the router gone) no message comes to do it, and every new viewer saw the dead topics
        self._stopped = threading.Event()
        self._sweeper = threading.Thread(target=self._sweep, name="foxglove-sweep", daemon=True)
        self._sweeper.start()

    @property
    def port(self) -> int:
        return self.server.port

    @property
    def url(self) -> str:
        """Where a viewer connects: the loopback address for a server on every interface, an
        IPv6 address in brackets."""
        host = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}.get(self.host, self.host)
        return f"ws://{f'[{host}]' if ':' in host else host}:{self.port}"

    def robots(self) -> list[str]:
        with self._lock:
            return sorted(self._robots)

    # ------------------------------------------------------------------ input

    def offer(self, key: str, payload: bytes) -> str | None:
        """Take one sample of ``<prefix>/<robot>/(response|warning|preview|refused)`` and log
        it on the robot's topics (a refusal: a problem). Returns the robot id, or ``None``
        when the message was invalid (counted in ``invalid`` by reason and logged). Never
        raises for bad input."""
        sample = take_fleet_sample(key, payload, self.prefix, self._reject)
        if sample is None:
            return None
        robot, kind, message = sample
        with self._lock:
            if self._stopped.is_set():  # closed: no channel is made again
                return None
            now = self.clock()
            self._forget_locked(now)
            state = self._robot_locked(robot, now)
            if state is None:
                self.invalid["too-many-robots"] += 1
                self._log.warning("too-many-robots", "dropped a %s of %s: already serving %d "
                                  "robots", kind, robot, self.max_robots)
                return None
            state.touched = now
            self.received[kind] += 1
            if kind == "preview":
                if foreign_preview(message, state.shown, state.answered, now, self.stale_after):
                    # a second camera on the robot's key (the worker refuses its frames):
                    # forwarded, its picture showed the robot's targets at its own scale
                    self.skipped["foreign-preview"] += 1
                    return robot
                self._log_preview_locked(state, message)
            elif kind == "response":
                state.answered = now
                if state.stale:  # answered again
                    state.stale = False
                    self._unstatus_locked(f"stale:{robot}")
                if self._refusal_over_locked(state, now):
                    state.refusal = None
                    self._unstatus_locked(f"refused:{robot}")
                if (message.seq, message.stamp) not in state.shown:
                    remember_answer(state.shown, message.seq, message.stamp)
                self._log_response_locked(state, message)
            elif kind == "refused":
                self._refused_locked(robot, state, message, now)
            else:
                state.warning.log(response_message(message.model_dump(),
                                                   time_ns(message.stamp)))
        return robot

    def router_changed(self, connected: bool) -> None:
        """Whether the server's Zenoh session reaches its router (told by
        :class:`service.link.RouterWatch`): without one no message comes from any robot, so
        the viewers are told (an Error problem ``router``) rather than see every robot go
        stale as if its worker or camera had failed."""
        with self._lock:
            if self._stopped.is_set():
                return
            if connected:
                self._unstatus_locked("router")
            else:
                self._status_locked("router", "asnn foxglove lost its router: no robot's data "
                                    "arrives (robots unknown)", StatusLevel.Error)

    def _refused_locked(self, robot: str, state: _Robot, notice: Refusal, now: float) -> None:
        """A worker's notice that it refuses the robot's frames: a Warning problem
        ``refused:<robot>`` naming the worker, the reason and its detail, said again only when
        the reason changes (a worker sends a notice a second, each with its own detail)."""
        state.refused_at = now
        if state.refusal != notice.reason:
            state.refusal = notice.reason
            self._status_locked(f"refused:{robot}", f"robot {robot}: worker {notice.worker} "
                                f"refuses its frames ({notice.reason}: {notice.detail})",
                                StatusLevel.Warning)

    @staticmethod
    def _refusal_over_locked(state: _Robot, now: float) -> bool:
        """Whether the refusal shown is over: a response came after the latest notice, unless
        it is a second publisher's, which stays for CONTESTED_FOR_S after the latest notice
        (the robot's own frames are answered while the other camera's are refused: the
        worker's ``contested``), as on the dashboard."""
        return state.refusal is not None and not refusal_shown(
            state.refusal, state.refused_at, state.answered, now)

    def _reject(self, reason: str, detail: str, key) -> None:
        with self._lock:
            self.invalid[reason] += 1
        self._log.warning(reason, "invalid message on %r (%s): %s", str(key)[:200], reason,
                          detail[:300])
        return None

    def _robot_locked(self, robot: str, now: float) -> _Robot | None:
        """The robot's channels, made if there is room (as the dashboard makes it)."""
        state = self._robots.get(robot)
        if state is None:
            if len(self._robots) >= self.max_robots:
                quiet = stale_robot(self._robots, now, self.stale_after)
                if quiet is None:
                    return None
                self._drop_locked(quiet)
                self._log.info("make-room", "robot %s: silent for more than %.0f s, its topics "
                               "are closed to make room for %s", quiet, self.stale_after, robot)
            topics = robot_topics(self.prefix, robot)
            context = self._context
            state = self._robots[robot] = _Robot(
                preview=CompressedImageChannel(topics["preview"], context=context),
                annotations=ImageAnnotationsChannel(topics["annotations"], context=context),
                response=foxglove.Channel(topics["response"], schema=RESPONSE_SCHEMA,
                                          context=context),
                warning=foxglove.Channel(topics["warning"], schema=RESPONSE_SCHEMA,
                                         context=context))
            self._log.info("serving", "robot %s: serving %s", robot, ", ".join(topics.values()))
        return state

    def _drop_locked(self, name: str) -> None:
        """Close a robot's channels and take its statuses back."""
        self._robots.pop(name).close()
        self._unstatus_locked(f"stale:{name}", f"refused:{name}")

    def _status_locked(self, status_id: str, message: str, level: StatusLevel) -> None:
        """Show a status to the viewers (Foxglove's problems list), unless it is shown."""
        if self._statuses.get(status_id) != (message, level):
            self._statuses[status_id] = (message, level)
            self._tell_locked(status_id)

    def _unstatus_locked(self, *status_ids: str) -> None:
        """Take back the statuses of ``status_ids`` that are shown."""
        for status_id in status_ids:
            if self._statuses.pop(status_id, None) is not None:
                self._tell_locked(status_id)

    def _tell_locked(self, status_id: str) -> None:
        """Tell the viewers a status's latest state (shown or taken back), at most once per
        STATUS_INTERVAL per id; a later change waits for the sweeper's next round. Each status
        is a control message the SDK queues per viewer, and a viewer whose queue overflows is
        disconnected: 1,000-5,000 notices with alternating reasons did that to every viewer."""
        now = self.clock()
        # the router's status follows this server's own link, not anything a peer sends
        told = self._told_at.get(status_id, float("-inf"))
        if status_id != "router" and now - told < STATUS_INTERVAL:
            self._untold.add(status_id)
            return
        self._told_at[status_id] = now
        self._untold.discard(status_id)
        shown = self._statuses.get(status_id)
        if shown is None:
            self.server.remove_status([status_id])
        else:
            self.server.publish_status(shown[0], shown[1], id=status_id)

    @staticmethod
    def _log_preview_locked(state: _Robot, preview: Preview) -> None:
        state.size = (preview.width, preview.height)
        state.scale = (preview.width / (preview.frame_width or preview.width),
                       preview.height / (preview.frame_height or preview.height))
        state.stamp_ns = time_ns(preview.stamp)
        state.preview.log(CompressedImage(timestamp=timestamp(state.stamp_ns),
                                          frame_id="camera", data=preview.data,
                                          format=preview.format))

    @staticmethod
    def _log_response_locked(state: _Robot, response: Response) -> None:
        stamp_ns = time_ns(response.stamp)
        fields = response.model_dump()
        state.response.log(response_message(fields, stamp_ns))
        if state.size is not None:  # without a thumbnail there is no picture to draw on
            state.stamp_ns = stamp_ns
            # ids as asnn alerts and the dashboard show them: "25:3" for a new owner's track 3
            targets = [t if t.get("id") is None else {**t, "id": track_label(t["id"])}
                       for t in fields["targets"]]
            state.annotations.log(target_annotations(
                targets, stamp_ns, state.size, collision=response.collision,
                scale=state.scale))

    def _sweep(self) -> None:
        while not self._stopped.wait(max(min(self.forget_after / 10, self.stale_after / 2, 1.0),
                                         0.05)):
            self.sweep()

    def sweep(self) -> None:
        """Say the problems again after a viewer subscribed (one that connected since they were
        said has none), clear the drawing of the robots whose responses stopped and forget the
        silent ones: the sweeper thread's round, every second or so (a test with a clock may
        call it)."""
        with self._lock:
            now = self.clock()
            if self._subscriptions.new.is_set():  # a new viewer, maybe: the problems again
                self._subscriptions.new.clear()
                for status_id, (message, level) in self._statuses.items():
                    self.server.publish_status(message, level, id=status_id)
            for status_id in list(self._untold):
                self._tell_locked(status_id)
            for status_id in [i for i, t in self._told_at.items()
                              if now - t >= STATUS_INTERVAL and i not in self._untold]:
                del self._told_at[status_id]
            self._stale_locked(now)
            self._bound_recording()
            for name, state in self._robots.items():  # a second publisher's, 30 s on
                if self._refusal_over_locked(state, now):
                    state.refusal = None
                    self._unstatus_locked(f"refused:{name}")
            self._forget_locked(now)

    def _bound_recording(self) -> None:
        """Stop the recording at its size bound or its first failed write, and say so."""
        recording = self.recording
        if recording is None or recording.closed:
            return
        if recording.error is None and recording.size < self.record_max_bytes:
            return
        error = recording.close()
        if error is not None:
            log.error("recording to %s stopped: %s (the file is finished where it could be)",
                      recording.path, error.strerror or error)
        else:
            log.warning("recording to %s stopped at %.0f MB, its bound (--mcap-max-mb): "
                        "the viewers are served on", recording.path, recording.size / 1e6)

    def _stale_locked(self, now: float) -> None:
        """A robot answered once and not for ``stale_after`` seconds (its worker, camera or
        link stopped): its targets are cleared (an empty ImageAnnotations at the latest stamp
        of its pictures: the Image panel kept the latest targets, and the red border of a
        warning, over the live pictures of a robot no worker watched any more) and a status
        names it, taken back at its next response."""
        for name, state in self._robots.items():
            if (state.stale or state.answered is None
                    or now - state.answered <= self.stale_after):
                continue
            state.stale = True
            if state.stamp_ns is not None:
                state.annotations.log(ImageAnnotations(timestamp=timestamp(state.stamp_ns)))
            self._status_locked(
                f"stale:{name}", f"robot {name}: no response for {self.stale_after:g} s (its "
                "worker, camera or link stopped): its targets are cleared, its warnings unknown",
                StatusLevel.Warning)

    def _forget_locked(self, now: float) -> None:
        if now < self._next_sweep:
            return
        self._next_sweep = now + min(self.forget_after / 10, 10.0)
        for name in [n for n, s in self._robots.items() if now - s.touched > self.forget_after]:
            self._drop_locked(name)
            log.info("robot %s: silent for %.0f s, its topics are closed", name,
                     self.forget_after)

    # ------------------------------------------------------------------ lifetime

    def __enter__(self) -> FoxgloveBridge:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop serving and recording, and close every robot's channels; a sample offered
        since is dropped (a subscriber still feeding the bridge made a closed bridge's
        channels again)."""
        with self._lock:  # an offer under way ends first
            self._stopped.set()
        self._sweeper.join()
        if self.recording is not None and not self.recording.closed:
            error = self.recording.close()
            if error is not None:
                log.error("recording to %s: %s", self.recording.path, error.strerror or error)
            else:
                log.info("recorded %.1f MB to %s", self.recording.size / 1e6,
                         self.recording.path)
        with self._lock:
            for state in self._robots.values():
                state.close()
            self._robots.clear()
            self.server.stop()
        self._unfilter_sdk_log()

    def _unfilter_sdk_log(self) -> None:
        for name in SDK_LOGGERS:
            logging.getLogger(name).removeFilter(self._sdk_log)
