"""The camera: frames of a file, a device, a stream URL, a generated scene or a ROS 2 bag,
published on Zenoh.

Sources are opened by :func:`asnn.io.sources.open_source` (the one place every command opens its
input). Frames go to ``<prefix>/<robot>/frame``, best effort (congestion control drop, lowest
data priority): a late frame is worth less than the next one. ``seq`` counts from 0 and keeps
increasing across ``--loop`` repetitions; ``stamp`` is the wall-clock time of capture for a
live source, and a replayed one's recorded time shifted to start now (:func:`publish_frames`).

Files and scenes are replayed at their frame rate, bags at their recorded pace (the differences
of their header stamps; a pause longer than :data:`MAX_REPLAY_GAP` is shortened to it), unless
``fps`` sets a rate. A bag message that cannot be used, or a cut in the file, is a counted and
logged rejection (:class:`SourceRejections`), never the end of the camera. After a bag's clock
reset the reader's times go on from the latest frame's (:meth:`asnn.io.rosbag.BagClip.frames`),
so the pace is the new stamps' differences: no wait for the jump, nor a burst.

The camera announces itself with the liveliness token ``<prefix>/@camera/<robot>`` while it
publishes (an optional extension, docs/contract.md): the robot's worker then subscribes to its
frames before the first one, without scanning for them.

A worker that refuses the camera's frames says why on ``<prefix>/<robot>/refused``
(:class:`RefusalNotices` logs it), so that a camera nothing answers does not stay silent about it.

Optionally (``preview_hz`` > 0), a small jpeg thumbnail of the current frame goes to
``<prefix>/<robot>/preview`` a few times a second for dashboards (docs/contract.md), with the
same best-effort delivery as frames.

Optionally (``asnn camera --record OUT.mcap``, :func:`open_recording`), every frame published
is also recorded, as it was sent and with its stamp, as a ROS 2 bag on the topic
``/<prefix>/<robot>/frame`` made a valid ROS 2 name (:func:`recording_topic`: ``-`` becomes
``_``) (:class:`asnn.io.bag_recording.BagRecording`, the ``ros`` extra),
for ``asnn detect`` or ``asnn camera --source`` to replay. A recording that stops (its size
bound, a failed write, a disk that does not keep up) says so in one line; the camera publishes
on.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections import Counter

import numpy as np
import zenoh

from asnn.io.sources import CLOCK_RESET, STAMP_UNSET, Source, SourceError, open_source

from . import keys
from .logutil import RateLimitedLog
from .messages import (FORMATS, PREVIEW_WIDTH, Frame, MessageError, Preview, decode_refusal,
                       encode)

__all__ = ["FRAME_QOS", "MAX_NOTICES", "MAX_REPLAY_GAP", "PREVIEW_HZ", "PREVIEW_WIDTH",
           "RECORD_MAX_BYTES", "RefusalNotices", "Source", "SourceError", "SourceRejections",
           "SubscriberWatch", "open_recording", "open_source", "publish_frames",
           "recording_topic"]

log = logging.getLogger("asnn.camera")

FRAME_QOS = dict(congestion_control=zenoh.CongestionControl.DROP,
                 priority=zenoh.Priority.DATA_LOW, reliability=zenoh.Reliability.BEST_EFFORT)
PREVIEW_HZ = 2.0     # thumbnails per second on <prefix>/<robot>/preview (0: none)
MAX_REPLAY_GAP = 5.0  # seconds: a longer pause between two recorded frames is shortened to this
MAX_NOTICES = 64  # workers whose latest refusal notice a camera keeps
RECORD_MAX_BYTES = 10**9  # a recording of the frames stops at this size (--record-max-mb 1000)


class SourceRejections:
    """What a camera could not publish, counted per reason (``counts``) and logged at WARNING,
    at most one line per reason every 10 s. Pass it as ``on_error`` to :func:`open_source`.

    A bag's clock reset (:data:`~asnn.io.sources.CLOCK_RESET`) is no rejection: its frame is
    published, paced on the new timeline. It is counted apart (``resets``) and logged at
    WARNING, at most one line every 10 s. Nor is a frame whose header stamp is unset, held at
    the latest frame's time (:data:`~asnn.io.sources.STAMP_UNSET`): it is published at once,
    counted apart (``unset``) and logged so too."""

    def __init__(self, robot: str):
        self.robot = robot
        self.counts: Counter = Counter()
        self.resets = 0
        self.unset = 0
        self._log = RateLimitedLog(log)
        self._lock = threading.Lock()

    def __call__(self, reason: str, message: str) -> None:
        if reason in (CLOCK_RESET, STAMP_UNSET):  # notices: the frame is published
            with self._lock:
                if reason == CLOCK_RESET:
                    self.resets += 1
                else:
                    self.unset += 1
            self._log.warning(reason, "camera %s: %s", self.robot, message[:300])
            return
        with self._lock:
            self.counts[reason] += 1
        self._log.warning(reason, "camera %s: rejected (%s): %s", self.robot, reason,
                          message[:300])

    def summary(self) -> str:
        """The camera's exit line's part: ``rejected: <reason> <count>, ...`` (or ``none``),
        then the clock resets and the unset stamps, each only if there were any."""
        with self._lock:
            rejected = ", ".join(f"{k} {v}" for k, v in sorted(self.counts.items())) or "none"
            parts = [f"rejected: {rejected}"]
            if self.resets:
                parts.append(f"clock resets (re-based): {self.resets}")
            if self.unset:
                parts.append(f"held at the latest frame's time (header stamp unset): "
                             f"{self.unset}")
        return "; ".join(parts)


# seconds without a refusal notice after which a camera says the refusals are over (a worker
# that refuses a robot's frames says so at most once a second, and keeps saying it)
REFUSALS_OVER_S = 5.0


class RefusalNotices:
    """What the workers say about this camera's frames (``<prefix>/<robot>/refused``,
    :class:`~service.messages.Refusal`): per worker (at most MAX_NOTICES), its latest notice
    (``latest``: the reason and the frames it has refused in all), logged at WARNING, at most
    one line every 10 s whatever the notices say (anyone on an open router can send them). A
    notice that is not a valid Refusal of this robot is counted under ``invalid`` and otherwise
    ignored."""

    def __init__(self, robot: str, clock=time.monotonic):
        self.robot = robot
        self.latest: dict[str, tuple[str, int]] = {}
        self.invalid = 0
        self._log = RateLimitedLog(log)
        self._lock = threading.Lock()
        self._clock = clock
        self._refused_at: float | None = None  # the latest valid notice, until said over

    def __call__(self, sample: zenoh.Sample) -> None:
        try:
            notice = decode_refusal(sample.payload.to_bytes(), robot=self.robot)
        except MessageError:
            with self._lock:
                self.invalid += 1
            return
        with self._lock:
            if len(self.latest) < MAX_NOTICES or notice.worker in self.latest:
                self.latest[notice.worker] = (notice.reason, notice.count)
            self._refused_at = self._clock()
        # the notices are the worker's for the robot id, whoever published the frames: with
        # two cameras on one key both hear them (an operations trial read the good camera's
        # log as the intruder's)
        self._log.warning("refused", "camera %s: worker %r refuses frames on this robot's key "
                          "(%r, %d so far, this camera's or another publisher's): %r",
                          self.robot, notice.worker, notice.reason, notice.count, notice.detail)

    def check_quiet(self) -> bool:
        """Say once (INFO) when no notice has come for :data:`REFUSALS_OVER_S` after one did: a
        refusing worker repeats its notice every second, so the refusals are over (the last
        WARNING would otherwise stand as the camera's state). True when it said so."""
        with self._lock:
            over = (self._refused_at is not None
                    and self._clock() - self._refused_at > REFUSALS_OVER_S)
            if over:
                self._refused_at = None
        if over:
            log.info("camera %s: no worker has refused this robot's frames for %.0f s: they are "
                     "taken again (or none receives them: the subscriber lines say)", self.robot,
                     REFUSALS_OVER_S)
        return over

    def summary(self) -> str:
        """``count by worker (latest reason)`` per worker, or ``none``."""
        with self._lock:
            return ", ".join(f"{count} by {worker!r} (latest {reason})" for worker, (reason, count)
                             in sorted(self.latest.items())) or "none"


class SubscriberWatch:
    """Logs when a camera's frames lose their last subscriber (no worker takes them: its
    robot goes unanswered, and nothing else would say so) and when one subscribes again.
    A Zenoh matching listener's handler (:meth:`zenoh.Publisher.declare_matching_listener`);
    ``matching`` is the latest status seen (``None``: not known yet).

    Each of the two lines at most once every ``interval`` seconds, the next one saying how many
    changes it did not show: with several workers, the scanning one subscribes to every
    robot's frames for a moment every second (:data:`service.worker.SCAN_INTERVAL`), so a
    camera no worker serves saw a subscriber come and go twice a line a second.

    ``unheard`` counts the frames :meth:`published` while no subscriber took them (lost:
    frames are best effort), for the camera's exit line."""

    def __init__(self, robot: str, key: str, matching: bool | None = None, *,
                 interval: float = 10.0, clock=time.monotonic):
        self.robot, self.key = robot, key
        self.matching = matching
        self.unheard = 0
        self._lines = RateLimitedLog(log, interval, clock)  # one reason per status
        self._lock = threading.Lock()

    def published(self) -> None:
        """A frame was put: counted in ``unheard`` when no subscriber takes it."""
        if self.matching is False:
            self.unheard += 1

    def __call__(self, status) -> None:
        with self._lock:
            before, self.matching = self.matching, bool(status.matching)
            matching = self.matching
        if before == matching:
            return
        hidden = self._lines.allow("subscribed" if matching else "unsubscribed")
        if hidden is None:
            return
        more = (f" ({hidden} more times since the last such line: a worker scanning the prefix "
                "subscribes to every robot's frames for a moment)") if hidden else ""
        if matching:
            log.info("camera %s: a subscriber (a worker) takes its frames on %s%s", self.robot,
                     self.key, more)
        else:
            log.warning("camera %s: no subscriber on %s any more (its worker stopped, the "
                        "router went, or this camera's own session lapsed: a pause longer than "
                        "its lease): its frames are lost until a worker subscribes again%s",
                        self.robot, self.key, more)


def recording_topic(robot: str, prefix: str = keys.DEFAULT_PREFIX) -> str:
    """The topic of a camera's recorded frames: its frame key ``<prefix>/<robot>/frame`` as a
    valid ROS 2 name (:func:`asnn.io.rosbag.ros_topic`), ``/asnn/r1/frame`` for robot ``r1``.

    ROS 2 takes fewer characters than a robot id or a prefix may hold: each run of other
    characters than letters and digits (in a robot id, ``-`` and ``_``) becomes one ``_``,
    none kept at either end of a part, and a part starting with a digit gets an ``r`` in front
    (``cam-2`` -> ``/asnn/cam_2/frame``, ``7`` -> ``/asnn/r7/frame``). So robots ``cam-2``
    and ``cam_2`` record on one topic name; a recording holds one robot, so they never meet in
    a bag, but merged bags of both would share the topic.

    Raises
    ------
    ImportError
        Without the ``ros`` extra (the message names it).
    KeySchemeError
        For an invalid robot id or prefix.
    ValueError
        For a topic longer than ROS 2 allows (a long prefix: with a 64-character robot id,
        one of more than about 170 characters).
    """
    from asnn.io.rosbag import ros_topic

    return ros_topic(keys.frame_key(robot, prefix))


def open_recording(path, robot: str, *, prefix: str = keys.DEFAULT_PREFIX,
                   format: str = "gray8", frame_id: str = "",
                   max_bytes: float = RECORD_MAX_BYTES):
    """A new recording of the camera's frames (:class:`asnn.io.bag_recording.BagRecording`) on
    :func:`recording_topic`, for :func:`publish_frames`' ``recording``; it says when it stops
    (at WARNING for its bound, at ERROR otherwise), and warns now when the disk has less room
    than the bound.

    Raises
    ------
    ImportError
        Without the ``ros`` extra (the message names it).
    OSError
        One line: the file exists, cannot be created, or its disk is full.
    ValueError
        A topic longer than ROS 2 allows (:func:`recording_topic`); no file is made.
    """
    from asnn.io.bag_recording import BagRecording

    def stopped(reason: str, detail: str) -> None:
        if reason == "bound":
            log.warning("camera %s: recording to %s stopped at %s (--record-max-mb): the frames "
                        "are published on", robot, path, detail)
        else:
            log.error("camera %s: recording to %s stopped: %s; the frames are published on",
                      robot, path, detail)

    recording = BagRecording(path, recording_topic(robot, prefix), frame_format=format,
                             frame_id=frame_id, max_bytes=max_bytes, on_stop=stopped)
    if recording.free_bytes is not None and recording.free_bytes < max_bytes:
        log.warning("camera %s: the disk of %s has %.0f MB free, less than the recording's "
                    "bound (%.0f MB): it will stop when the disk is full", robot, path,
                    recording.free_bytes / 1e6, max_bytes / 1e6)
    return recording


def publish_frames(session: zenoh.Session, robot: str, source: Source, *,
                   prefix: str = keys.DEFAULT_PREFIX, fps: float | None = None,
                   loop: bool = False, format: str = "gray8", wait: float = 0.0,
                   stop: threading.Event | None = None, max_frames: int | None = None,
                   preview_hz: float = PREVIEW_HZ, preview_width: int = PREVIEW_WIDTH,
                   announce: bool = True, refusals: RefusalNotices | None = None,
                   subscribers: SubscriberWatch | None = None, recording=None) -> int:
    """Publish the source's frames paced at ``fps`` (default: the source's own times).

    ``stamp``: the capture time of a live source's frame (wall clock when it was read); a
    replayed source's (file, bag, generated scene) recorded time shifted to start now, so that
    frames published late or bunched keep the spacing the scene was recorded with; with
    ``fps``, a replayed source is played and stamped ``1 / fps`` apart instead (the scene sped
    up or slowed down: a fast-forward for tests and benchmarks), and a live one thinned out.

    ``wait``: seconds to wait, at most, for a subscriber (a worker) before the first frame.
    ``announce``: declare the camera's liveliness token while publishing.
    ``preview_hz``: thumbnails (``preview_width`` pixels wide) per second on the preview key,
    at most one per frame; 0 publishes none.
    ``refusals``: collects and logs the workers' notices that they refuse the frames (a new
    :class:`RefusalNotices` if not given). ``subscribers``: logs when the frames lose their
    last subscriber, and counts the frames published meanwhile (a new :class:`SubscriberWatch`
    if not given). ``recording``: each frame published is handed to it as it was sent, with its
    stamp (:func:`open_recording`, made for the frames' ``format``); it neither blocks nor
    raises, and closing it is the caller's.
    Returns the number of frames published. Ends at the end of the source unless ``loop``
    (a live source is never replayed), when ``stop`` is set, or after ``max_frames``.
    """
    if format not in FORMATS:
        raise ValueError(f"unknown frame format {format!r}; choose one of {', '.join(FORMATS)}")
    rate = float(fps or source.fps)
    if not rate > 0:
        raise ValueError(f"frame rate must be positive, got {rate}")
    if not preview_hz >= 0 or preview_width < 1:
        raise ValueError(f"need preview_hz >= 0 and preview_width >= 1, got {preview_hz}, "
                         f"{preview_width}")
    period = 1.0 / rate
    stop = stop or threading.Event()
    key = keys.frame_key(robot, prefix)
    with contextlib.ExitStack() as declared:  # each undeclared on the way out, whatever fails

        def declare(entity):
            declared.callback(entity.undeclare)
            return entity

        refusals = refusals or RefusalNotices(robot)
        declare(session.declare_subscriber(keys.refusal_key(robot, prefix), refusals))
        publisher = declare(session.declare_publisher(key, **FRAME_QOS))
        if announce:
            declare(session.liveliness().declare_token(keys.camera_token_key(robot, prefix)))
        previews = (declare(session.declare_publisher(keys.preview_key(robot, prefix),
                                                      **FRAME_QOS))
                    if preview_hz > 0 else None)
        next_preview = time.monotonic()
        deadline = time.monotonic() + wait
        while (not publisher.matching_status.matching and time.monotonic() < deadline
               and not stop.is_set()):
            time.sleep(0.05)
        if stop.is_set():  # stopped while it waited: nothing was published
            return 0
        if wait and not publisher.matching_status.matching:
            log.warning("no subscriber on %s after %.1f s; publishing anyway", key, wait)
        # a worker that dies or stops later leaves the camera publishing into nothing: say so
        subscribers = subscribers or SubscriberWatch(robot, key)
        subscribers.matching = publisher.matching_status.matching
        declare(publisher.declare_matching_listener(subscribers))
        log.info("camera %s: %s at %.1f fps as %s on %s", robot, source.name, rate, format, key)
        if not (fps or source.live or source.fps_stated):  # a live source stamps its own times
            log.warning("camera %s: %s %s; its frames are paced and stamped at %.1f fps (set "
                        "--fps)", robot, source.name, source.rate_problem(), rate)
        seq = 0
        next_time = time.monotonic()
        # a replayed source's frames are stamped with their recorded times, shifted to now:
        # the publishing jitter of this process is not the scene's motion
        start, replayed = time.time(), 0.0
        while not stop.is_set():
            previous_t = None
            for t, image in source.timed_frames():
                if stop.is_set() or (max_frames is not None and seq >= max_frames):
                    return seq
                now = time.monotonic()
                if source.live:  # paced by its capture; --fps only thins it out
                    if fps and now < next_time:
                        continue
                    next_time = max(next_time + period, now) if fps else now
                else:
                    step = period
                    if previous_t is not None and not fps:  # the recorded pace
                        step = min(max(t - previous_t, 0.0), MAX_REPLAY_GAP)
                        next_time += step - period
                    if seq:
                        replayed += step
                    previous_t = t
                    if next_time > now:
                        if stop.wait(next_time - now):
                            return seq
                    elif now - next_time > period:  # fell behind: do not burst to catch up
                        next_time = now
                    next_time += period
                stamp = time.time() if source.live else start + replayed
                frame = Frame.from_image(np.ascontiguousarray(image), seq=seq, stamp=stamp,
                                         format=format)
                publisher.put(encode(frame))
                subscribers.published()
                if recording is not None:
                    try:
                        recording.write(frame.width, frame.height, frame.data,
                                        recording.time_ns(frame.stamp))
                    except Exception:  # a recording is never worth losing the frames over
                        log.exception("camera %s: recording frame %d failed; recording no more",
                                      robot, seq)
                        recording = None
                refusals.check_quiet()
                if previews is not None and time.monotonic() >= next_preview:
                    next_preview = max(next_preview + 1.0 / preview_hz, time.monotonic())
                    try:
                        previews.put(encode(Preview.from_frame_image(
                            image, seq=seq, stamp=frame.stamp, width=preview_width)))
                    except Exception:  # a thumbnail is never worth losing the frames over
                        log.exception("camera %s: preview of frame %d failed", robot, seq)
                seq += 1
            if not loop or source.live or seq == 0:
                break
        return seq
