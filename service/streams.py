"""The streams of a robot's frames: whether a frame that arrives continues its robot's stream,
starts a new one (its model is then reset), arrives late, or is a second publisher's.

:class:`service.core.WorkerCore` places each frame it takes in with :func:`place_frame` (under
its lock), refuses the late ones first (``Stream.outran``), learns the robot's ``seq`` step from
the frames it takes in (:func:`learn_step`), and undoes a stream a refused frame began with
:func:`withdraw_frame`. The robot's record (:class:`service.core._Robot`) holds the streams; the
worker holds the counters and the rate-limited log, which it hands in.

The reset rule
--------------
Each frame that arrives is compared with the previous frame that arrived for the robot (not with
the last one processed, so the frames the worker skips itself never count as a gap). It
continues the robot's **stream** when its size is the same, its ``seq`` is greater by at most
``max_gap`` steps and its ``stamp`` is not smaller. A step is how much the robot's ``seq`` grows
from one frame to the next: 1, until :data:`STEP_FRAMES` growths in a row between arriving
frames agree on another (the largest less than twice the smallest, which becomes the step): a
camera whose ``seq`` counts by 10, or is a clock in milliseconds (CONTRACT.md asks only that
``seq`` increase). One frame, a stranger's or one after frames were lost, cannot change it.
Otherwise a new stream starts, for the first rule that failed:

* ``size``: the frame size (width x height) differs;
* ``seq-backwards``: ``seq`` is not greater (the camera restarted);
* ``seq-gap``: ``seq`` jumps ahead by more than ``max_gap`` steps (frames were lost on the
  way; a camera whose step is larger than 1 resets on its first frames, until its step is
  known);
* ``stamp-backwards``: ``stamp`` is smaller.

When the worker processes the first frame of a new stream, the model state is **reset** (that
frame only primes the model) and the reset is counted under the rule.

A frame that belongs to the stream but arrives after later ones did (the same size, a ``seq``
above 0 and at most ``max_gap`` steps behind the latest, a ``stamp`` no later than its: reordered on
the way) is refused as ``late`` instead: the model does not go back in time, and a restart is
not what happened. A camera that restarts begins again at ``seq`` 0 (or with a later stamp).
A robot whose streams keep ending within a few frames (a camera whose ``seq`` never grows, or
keeps going back every other frame) has its model reset before it could warn: after
:data:`RESTARTS_WARNED` streams in a row of at most :data:`SHORT_STREAM_FRAMES` frames the worker
logs it at WARNING, and every response says how many frames its model has
stepped in the current stream (``stream_frames``, docs/contract.md).

Two publishers on one key
-------------------------
A second publisher on a robot's key (a stray camera, or an attacker in an open deployment)
interleaves its frames with the robot's: every frame of one breaks the other's stream. The
worker detects it when the stream that a frame has just replaced continues (a frame fits the
previous stream, which sent a frame less than ``takeover_after`` seconds ago): it counts an
intrusion, logs it (rate-limited), marks the robot *contested* and returns to the stream that
was there first (a ``second-publisher`` reset if the other's frame was processed meanwhile);
the other's later frames, continuing its own stream, are refused as ``second-publisher``
(until the stream there first has been silent for ``CONTESTED_FOR_S``: then the other's is the
robot's, said at WARNING).
From then on, while the robot's stream keeps sending (a frame less than ``takeover_after``
seconds ago), a frame that does not continue it is refused as ``second-publisher``, until
``CONTESTED_FOR_S`` (30 s) after the last frame so refused. So an
intruder costs the robot at most two resets, however long it keeps publishing. A camera that
really restarts is followed as soon as its previous stream has been silent for
``takeover_after`` seconds. A second camera whose ``seq`` runs a few frames ahead of the
robot's continues the robot's stream with its first frame: the stream the robot's next frame
begins is then taken for the robot's (the other's had jumped over it), and while the robot is
contested a frame that fits both streams is the one it follows more closely. A publisher that
copies the robot's ``seq`` and ``stamp``, or runs exactly one ``seq`` ahead, or keeps pace a
few frames ahead at a lower rate than the robot's camera, cannot be told apart this way: only
the secured deployment (one credential per camera, allowed to publish
its own robot's key only) stops it (docs/operations.md).
"""

from __future__ import annotations

from dataclasses import dataclass

from . import keys
from .logutil import RateLimitedLog
from .messages import Frame

__all__ = ["CONTESTED_FOR_S", "RESTARTS_WARNED", "SHORT_STREAM_FRAMES", "STEP_FRAMES", "Stream",
           "learn_step", "place_frame", "withdraw_frame"]

# streams in a row that last at most SHORT_STREAM_FRAMES frames before the worker logs that a
# robot's model cannot warn: a fresh model of the default warns from its 5th frame at the
# soonest (over every sixth case of the suite, a fresh model started at every third frame of
# each approach); streams of one frame alone were counted, so a seq going 0, 1, 0, 1 ... was not
RESTARTS_WARNED = 10
SHORT_STREAM_FRAMES = 4
# a robot stays contested this long after the last frame refused as a second publisher's: then
# a restart of its own camera is followed at once again (contested for good, each later
# restart lost takeover_after seconds of frames: a soak); an intruder that keeps publishing
# keeps it contested, one that comes back less often costs the robot its two resets again
CONTESTED_FOR_S = 30.0
# growths of a robot's seq in a row that must agree (the largest less than twice the smallest)
# before the smallest becomes its step: one frame, a stranger's or a lost one's, cannot change it
STEP_FRAMES = 3


def learn_step(state, growth: int) -> None:
    """Take one growth of a robot's ``seq`` between two arriving frames; a run of
    :data:`STEP_FRAMES` steady ones sets its step (a seq that went back starts a new run).
    ``state`` is the robot's record (:class:`service.core._Robot`)."""
    if growth <= 0:
        state.seq_growths.clear()
        return
    state.seq_growths.append(growth)
    if len(state.seq_growths) == STEP_FRAMES:
        smallest = min(state.seq_growths)
        if max(state.seq_growths) < 2 * smallest:
            state.seq_step = smallest


@dataclass
class Stream:
    """The frames of one source as they arrive: the latest one's seq, stamp, size and time."""

    number: int          # the robot's stream counter when it started
    reason: str | None   # why the robot switched to it (a reset rule); None for the first
    seq: int
    stamp: float
    size: tuple[int, int]
    arrival: float
    frames: int = 1  # frames that arrived in it
    prior_seq: int | None = None  # the seq before the latest frame's (None: one frame so far)

    def continues(self, frame: Frame, max_gap: int) -> str | None:
        """None if ``frame`` continues this stream, else the rule it breaks."""
        if (frame.width, frame.height) != self.size:
            return "size"
        if frame.seq <= self.seq:
            return "seq-backwards"
        if frame.seq - self.seq > max_gap:
            return "seq-gap"
        if frame.stamp < self.stamp:
            return "stamp-backwards"
        return None

    def outran(self, frame: Frame, max_gap: int) -> bool:
        """Whether ``frame`` is one of this stream's own, arriving after later ones did: the
        same size, a ``seq`` at most ``max_gap`` back but not 0 (a camera starts at 0) and no
        later ``stamp``: a late or reordered delivery, not a camera that restarted."""
        return ((frame.width, frame.height) == self.size and frame.seq > 0
                and self.seq - max_gap <= frame.seq <= self.seq and frame.stamp <= self.stamp)

    def advance(self, frame: Frame, arrival: float) -> None:
        self.prior_seq = self.seq
        self.seq, self.stamp, self.arrival = frame.seq, frame.stamp, arrival
        self.size = (frame.width, frame.height)
        self.frames += 1


def place_frame(robot: str, state, frame: Frame, received: float, *, max_gap: int,
                takeover_after: float, prefix: str,
                limited_log: RateLimitedLog) -> Stream | None:
    """Place an arriving frame in the robot's streams (see the module notes).

    Parameters
    ----------
    robot : str
        The robot's id.
    state : service.core._Robot
        The robot's record: its streams, its ``seq`` step and its intrusions, updated here.
    frame : Frame
        The frame, valid and not late.
    received : float
        When it arrived (the worker's clock).
    max_gap : int
        The worker's ``max_gap``: the largest forward jump of ``seq``, in the robot's steps.
    takeover_after : float
        The worker's ``takeover_after``, seconds.
    prefix : str
        The worker's key prefix (the frame key its intrusion line names).
    limited_log : RateLimitedLog
        The worker's, for the intrusion, take-over, restarts and lost-frames lines.

    Returns
    -------
    Stream or None
        The stream it belongs to, or None when it is refused as a second publisher's.
    """
    current = state.stream
    gap = max_gap * state.seq_step
    broken = None if current is None else current.continues(frame, gap)
    previous = state.previous
    if (current is not None and broken is None and previous is not None
            and received - previous.arrival <= takeover_after
            and previous.continues(frame, gap) is None):
        # the frame fits both streams: two cameras whose seqs run within max_gap of each other
        if state.contested(received) and frame.seq - previous.seq < frame.seq - current.seq:
            # the second camera's (the robot's stream is followed, the other's refused): a
            # frame is the stream's it follows more closely (one a few frames ahead of the
            # robot's continues the robot's stream too)
            previous.advance(frame, received)
            state.intruder_seen = received
            return None
        if (current.frames == 1 and current.reason == "seq-backwards"
                and previous.seq > current.seq and current.stamp > previous.stamp):
            # the stream just replaced goes on after the one-frame stream that replaced it
            # (one camera's frames reordered come with stamps in order: not this): two
            # publishers interleave, not a restart
            if previous.prior_seq is not None and previous.prior_seq < current.seq:
                # the replaced stream's latest frame had jumped ahead over the one that
                # began this stream: that frame and this one are a second camera's a few
                # frames ahead, and this stream goes on with the robot's own
                _intrusion(robot, state, frame, previous, received, prefix, limited_log)
                previous.reason = "second-publisher"
                previous.advance(frame, received)
                return None
            broken = "interleaved"
    if current is not None and broken is None:
        current.advance(frame, received)
        return current
    if (current is not None and previous is not None
            and received - previous.arrival <= takeover_after
            and previous.continues(frame, gap) is None):
        if previous.number > current.number:
            # the other publisher's stream takes the robot only once the stream there first
            # has been silent for CONTESTED_FOR_S: a camera that pauses or restarts for a
            # few seconds (a new stream of its own: followed after takeover_after, below)
            # must not hand its robot to an intruder that kept publishing
            if received - current.arrival <= max(takeover_after, CONTESTED_FOR_S):
                # the intruder's stream goes on while the one there first keeps sending
                previous.advance(frame, received)
                state.intruder_seen = received
                return None
            # the stream there first has been silent for takeover_after: its camera went
            # (or restarted as this one), so this stream is the robot's now
            limited_log.warning(
                f"takeover:{robot}", "robot %s: its stream of seq %d has been silent for "
                "%.0f s; following the other publisher's (seq %d)", robot, current.seq,
                received - current.arrival, frame.seq)
            previous.reason = "second-publisher"
            previous.advance(frame, received)
            state.stream, state.previous = previous, current
            return previous
        # the stream this one replaced goes on: two publishers interleave on the key
        _intrusion(robot, state, frame, current, received, prefix, limited_log)
        previous.reason = "second-publisher"
        previous.advance(frame, received)
        state.stream, state.previous = previous, current
        return previous
    if (state.contested(received) and current is not None
            and received - current.arrival <= takeover_after):
        # an intruder's frame, or the robot's camera restarting: either keeps it contested
        state.intruder_seen = received
        return None
    if current is not None:
        short = current.frames <= SHORT_STREAM_FRAMES
        state.restarts = state.restarts + 1 if short else 0
        if state.restarts >= RESTARTS_WARNED:
            limited_log.warning(
                f"restarts:{robot}", "robot %s: its last %d streams each ended within %d "
                "frames (the latest: %s): its model is reset every few frames and cannot "
                "warn; a camera's seq must grow from frame to frame and its stamp must not "
                "go back",
                robot, state.restarts, SHORT_STREAM_FRAMES, broken)
    if broken == "seq-gap":
        # frames lost on the way (a link that drops, a camera faster than its link or its
        # worker can take): each such gap resets the model, which cannot warn until it has
        # stepped a few frames again; an INFO line per reset hid a soak trial's 28 in 32 s
        limited_log.warning(
            f"seq-gap:{robot}", "robot %s: seq %d after %d: frames lost on the way, more "
            "than --max-gap (%d steps of %d); its model starts again and cannot warn until "
            "it has warmed up (frequent: a link that drops frames, or a camera faster than "
            "its link or worker; every robot at once: the router or its link was lost for a "
            "while)", robot, frame.seq, current.seq, max_gap,
            state.seq_step)
    state.streams += 1
    state.previous = current
    state.stream = Stream(state.streams, broken, frame.seq, frame.stamp,
                           (frame.width, frame.height), received)
    return state.stream


def _intrusion(robot: str, state, frame: Frame, others: Stream, received: float, prefix: str,
               limited_log: RateLimitedLog) -> None:
    """Count and log a second publisher on the robot's key (``frame`` coming after the robot's
    latest, ``state.stream``'s), ``others`` the stream taken for its: the robot is contested
    from now."""
    state.intrusion = (others.number, state.intruder_seen)  # undone if its one frame is
    state.intruder_seen = received  # refused when processed (withdraw_frame)
    state.intrusions += 1  # the worker counts it in its stats
    limited_log.warning(
        f"intrusion:{robot}", "robot %s: two publishers interleave frames on %s (seq %d after "
        "%d); following the stream that was there first and refusing frames that do not "
        "continue it", robot, keys.frame_key(robot, prefix), frame.seq, state.stream.seq)


def withdraw_frame(state, stream: int) -> bool:
    """Undo what a frame of stream number ``stream`` did to the robot's streams as it arrived,
    now that it is refused (its image, its robot's place, the model); whether that undid an
    intrusion (the worker's count of them goes down by one).

    Parameters
    ----------
    state : service.core._Robot
        The robot's record.
    stream : int
        The number of the stream the refused frame was placed in.
    """
    current = state.stream
    if (current is not None and current.number == stream and current.frames == 1
            and state.previous is not None):
        # it began a stream (another size, a seq back) and nothing followed it yet:
        # the frames after it continue the stream before it, as if it had not come
        # (not a new stream that the next frame would break as an intruder's)
        state.stream, state.previous = state.previous, None
    elif (state.previous is not None and state.previous.number == stream
          and state.previous.frames == 1 and state.intrusion is not None
          and state.intrusion[0] == stream):
        # the same, with the camera's next frame come while this one waited or was
        # processed: it was taken for a second publisher's interleaving (the robot
        # marked contested, so that its camera's restart would have been refused)
        state.previous, state.intruder_seen = None, state.intrusion[1]
        state.intrusion = None
        state.intrusions -= 1
        return True
    return False
