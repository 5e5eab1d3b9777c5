"""The worker's logic without the network: per-robot model state, newest frame wins, counters.

:class:`WorkerCore` takes raw payloads (``offer``, from any thread) and hands out one job per
robot at a time (``take``, ``process``, from one or more processing threads). It imports no Zenoh,
so tests can drive it directly.

Per-robot state
---------------
A robot's model state is created on its first valid frame. Each frame that arrives is placed
in the robot's **streams** (:mod:`service.streams`: whether it continues the robot's stream,
starts a new one for a reset rule, arrives ``late``, or is a second publisher's on its key).
When the worker processes the first frame of a new stream, the model state is **reset** (that
frame only primes the model) and the reset is counted under the rule; every response says how
many frames its model has stepped in the current stream (``stream_frames``, docs/contract.md).

The retina integrates with its fixed time step (0.05 s) whatever the stamps say; the targets'
time to contact, and with it the default's approach gate, read the stamps' gaps (a gap below
MIN_FRAME_GAP_S or above MAX_FRAME_GAP_S reads as the nominal period, logged when it lasts: a
camera clock in other units). A robot that sends no frame for ``idle_timeout`` seconds is
evicted (its state is forgotten); when every slot is taken, one silent for ``takeover_after``
seconds is forgotten to make room for a new robot.

Newest frame wins, robots in turn
---------------------------------
Each robot has one pending slot. A frame that arrives while the previous one is still waiting
replaces it, and the replaced one is counted in the next response's ``dropped``. The robot keeps
its place in the queue: the next robot served is the one that has waited longest, counted from
the arrival of the first frame it has been waiting with, so under overload robots are taken in
turn instead of by the arrival time of their newest frame.

Slots
-----
``max_robots`` bounds the robots with a model state. A robot takes a slot only once one of its
frames was valid (decoded and accepted by the model): until then it is a *candidate*, with at
most its pending frame held (at most ``max_robots`` candidates at once), and it is forgotten as
soon as a frame of it fails. So ids that send only undecodable frames cannot lock new robots out.

Invalid input never raises out of ``offer``/``process``: it is counted per reason (``invalid``,
the labels of :data:`service.messages.REASONS` plus ``frame-rejected``, ``model-failed``
(a bug), ``too-many-robots``, ``second-publisher`` and ``late``) and logged at WARNING,
rate-limited: the first rejection of a reason at once, then at most one line per reason every
``log_interval`` seconds, with the count of those not shown.

Ownership: with ``owns`` (a predicate on robot ids, see :mod:`service.ownership` and
:mod:`service.routing`), frames of robots the worker does not take are skipped before they are
decoded and counted in ``foreign``; :meth:`WorkerCore.release_unowned` forgets the robots it no
longer takes. With ``answers`` (another predicate), the frames of a robot the worker does not
answer yet are stepped without a response (counted in ``warmup``): a worker taking a robot over
warms its model up on them while the previous owner still answers (docs/operations.md). A robot
is *warm* (:meth:`WorkerCore.warm`) once its model has stepped ``warmup_frames`` frames of the
stream it is on (a fast camera's frames its frame-rate ceiling held do not count), without a reset
pending.

A frame whose ``seq``, ``stamp`` and data equal those of the robot's previous arrival is the same
frame delivered twice (two subscriptions of the worker matched it for a moment): it is ignored and
counted in ``duplicates``, never taken for a camera restart.

Memory: at most two frames per robot are held (the pending one and the one being processed; the
latest one taken in is kept for the duplicate check, and is one of them or the last processed), for
at most ``max_robots`` robots, plus one pending frame per candidate, each frame at most
``messages.MAX_PAYLOAD`` bytes; plus one model state per robot (docs/operations.md gives the
numbers). Overload never grows it: a frame that arrives while one waits replaces it.
"""

from __future__ import annotations

import logging
import os
import re
import socket
import statistics
import threading
import time
import warnings
from collections import Counter, OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, field

from asnn.detectors import available_cores, make_detector
from asnn.errors import FrameError, TimingWarning
from asnn.params import (DEFAULT_PRESET, MAX_FRAME_GAP_S, MIN_FRAME_GAP_S, PERIOD_FRAMES,
                         SLOW_FPS, preset_from_spec, timed_gap)

from . import keys
from .logutil import RateLimitedLog
from .messages import (MAX_NOTE_LEN, MAX_PAYLOAD, MAX_REASON_LEN, MAX_SIDE, VERSION, Frame,
                       MessageError, Response, decode_frame, response_from, track_id_base)
from .streams import (CONTESTED_FOR_S, RESTARTS_WARNED, STEP_FRAMES, Stream, learn_step,
                      place_frame, withdraw_frame)

__all__ = ["HANDOVER_WARMUP_FRAMES", "Job", "RobotView", "WorkerCore", "default_threads",
           "default_worker_id", "started_here", "worker_host"]

log = logging.getLogger("asnn.worker")
# the worker logs a robot's unusable stamps itself, per robot and spell (_note_untimed), where
# the model's warning says it once per process for whichever robot was first
warnings.filterwarnings("ignore", category=TimingWarning, module=r"service\.core$")

# Frames a new owner steps a robot's stream silently before it answers: a fresh model of the
# default (robust) preset that has stepped 30 frames warns as one that saw the whole stream at
# 99.45 % of 4,152 hand-overs tried over the labelled suite, 99.34 % of the 1,504 during an
# approach (the tracker needs a few frames of approach in a row, and the camera-rig stage its
# running means; the worst need 53 during an approach, 64 before one):
# `asnn bench --handover --every 3`, README "Service". Re-measure when the default changes (last:
# 2026-12-01, with the global brightness compensation's time constant at 0.5 s: the suite's
# figures unchanged; the real clips' and the indoor set's in docs/operations.md).
HANDOVER_WARMUP_FRAMES = 30
# robot ids whose latest refusal the status keeps (the most recently refused)
MAX_REFUSED = 256
# the worker's defaults (asnn worker --idle-timeout, --max-gap, --max-robots, --takeover-after)
IDLE_TIMEOUT_S = 60.0
MAX_GAP = 20
MAX_ROBOTS = 256
TAKEOVER_AFTER_S = 3.0
# A robot's rate is its model's own (the median over asnn.params.PERIOD_FRAMES gaps between the
# stamps of the new frames it stepped); when it reads below SLOW_FPS for PERIOD_FRAMES frames in
# a row the worker logs it (_measure_rate)


def worker_host() -> str:
    """The host part of :func:`default_worker_id`: the host name in the robot-id alphabet (at
    most 40 characters)."""
    return re.sub(r"[^A-Za-z0-9_-]", "-", socket.gethostname())[:40] or "worker"


def default_worker_id() -> str:
    """``<host>-<pid>``, restricted to the robot-id alphabet."""
    return f"{worker_host()}-{os.getpid()}"


def started_here(worker_id: str) -> bool:
    """Whether ``worker_id`` is the default id of a process of this host, ``<host>-<pid>``
    (in a container, whose host name is its own: the container's worker)."""
    return re.fullmatch(re.escape(worker_host()) + r"-[0-9]+", worker_id) is not None


def default_threads() -> int:
    """A worker's processing threads by default: the cores this process may run on."""
    return available_cores()


@dataclass
class _Robot:
    """What the worker knows about one robot."""

    detector: object | None = None
    proven: bool = False  # one of its frames was valid: it holds a slot
    shape: tuple[int, int] | None = None  # (width, height) of the stream being processed
    last_seq: int | None = None
    last_seen: float = 0.0
    stream: Stream | None = None  # the stream its frames arrive in
    previous: Stream | None = None  # the stream the latest break replaced
    streams: int = 0  # streams started
    processed_stream: int | None = None  # number of the stream the model state belongs to
    stepped: int = 0  # frames processed in the model's current stream, held ones included
    # when a second publisher's frame on its key last arrived (None: never), found by an
    # intrusion or refused as one: it is *contested* for CONTESTED_FOR_S after
    intruder_seen: float | None = None
    intrusions: int = 0
    restarts: int = 0  # streams in a row that ended within SHORT_STREAM_FRAMES frames
    # the latest intrusion: the number of the stream taken for a second publisher's, and when
    # one was seen before it (None: never)
    intrusion: tuple[int, float | None] | None = None
    pending: tuple[Frame, float, Stream] | None = None  # (frame, received, its stream)
    waiting_since: int = 0  # arrival order of the first frame it has been waiting with
    dropped: int = 0  # frames replaced since the last response
    busy: bool = False
    processed: int = 0
    resets: int = 0
    id_base: int = 0  # its model's first target id on the wire (messages.track_id_base)
    arrived: int = 0  # frames taken in
    arrived_bytes: int = 0
    # seq, stamp and data of the latest frame taken in (the data is the pending frame's or the
    # one being processed, or the last one processed: never a third frame held)
    last_arrival: tuple[int, float, bytes] | None = None
    # its seq's step (1 until a steady other one is seen) and the latest growths of its seq
    # between arriving frames, from which a steady step is read (streams.learn_step)
    seq_step: int = 1
    seq_growths: deque = field(default_factory=lambda: deque(maxlen=STEP_FRAMES))
    # the stamps' gaps between the frames processed in the current stream (after the worker's
    # own skips; the rate of a baseline, which times nothing), and how long it has read slow
    stamp: float | None = None
    periods: deque = field(default_factory=lambda: deque(maxlen=PERIOD_FRAMES))
    slow_frames: int = 0  # frames in a row whose rate read below SLOW_FPS
    slow_logged: bool = False  # this slow spell was logged
    untimed_frames: int = 0  # frames in a row whose stamp gap the model cannot believe
    untimed_logged: bool = False  # this spell was logged

    @property
    def model_periods(self) -> deque:
        """The gaps its rate is read from: the ASNN model's own (:attr:`asnn.ASNN.periods`: a
        repeated frame is no new frame to it, an untimed gap is its nominal period), else
        :attr:`periods` (the baselines time nothing)."""
        own = getattr(self.detector, "periods", None)
        return self.periods if own is None else own

    @property
    def model_steps(self) -> int:
        """Frames of the current stream its model stepped, what a hand-over's warm-up counts:
        :attr:`stepped` less those the ASNN model's frame-rate ceiling held
        (:attr:`asnn.ASNN.ceiling_held`: at 60 fps, every second frame)."""
        return self.stepped - getattr(self.detector, "ceiling_held", 0)

    @property
    def fps(self) -> float | None:
        """New frames a second its model is stepped at: the median of :attr:`model_periods`;
        None while the stamps tell no rate (the last PERIOD_FRAMES gaps each under
        MIN_FRAME_GAP_S or over MAX_FRAME_GAP_S: the model times them at its nominal period,
        which is not the camera's)."""
        return None if self.untimed_frames >= PERIOD_FRAMES else _rate(self.model_periods)

    @property
    def processed_fps(self) -> float | None:
        """Frames a second the worker processes for it, repeats included: the median of
        :attr:`periods`."""
        return _rate(self.periods)

    def contested(self, now: float) -> bool:
        """Whether a second publisher's frame arrived on its key within CONTESTED_FOR_S."""
        return self.intruder_seen is not None and now - self.intruder_seen <= CONTESTED_FOR_S


def _rate(periods) -> float | None:
    """Frames a second from the gaps between frames, seconds: the reciprocal of their median,
    to a tenth (None without a gap)."""
    return round(1.0 / statistics.median(periods), 1) if periods else None


@dataclass(frozen=True)
class RobotView:
    """What routing needs to know of a robot the core tracks."""

    proven: bool  # one of its frames was valid: it holds a slot
    warm: bool  # its model has stepped enough frames of its current stream to answer
    last_seen: float  # clock() of its latest arriving frame


@dataclass(frozen=True)
class Job:
    """One frame taken for processing."""

    robot: str
    frame: Frame
    received: float  # clock() when the frame arrived
    dropped: int  # frames of this robot skipped since its previous response
    stream: int = 0  # the robot's stream the frame belongs to
    reset_reason: str | None = None  # why that stream started


@dataclass
class _Stats:
    received: int = 0
    processed: int = 0
    dropped: int = 0
    warnings: int = 0
    evicted: int = 0
    foreign: int = 0  # frames of robots another worker owns
    released: int = 0  # robots handed over to another worker
    intrusions: int = 0  # second publishers detected on a robot's key
    duplicates: int = 0  # the same frame delivered twice
    warmup: int = 0  # frames stepped without a response, warming up to take a robot over
    invalid: Counter = field(default_factory=Counter)
    resets: Counter = field(default_factory=Counter)


class WorkerCore:
    """Per-robot ASNN state behind a newest-frame-wins queue.

    Parameters
    ----------
    model : str
        One of :data:`asnn.detectors.MODELS`: ``asnn`` or a baseline.
    preset : str, optional
        ASNN preset spec, ``NAME[/FIELD=VALUE...]`` (:func:`asnn.params.parse_preset_spec`;
        ``None``: the default preset), reported as given in every response.
    worker_id : str, optional
        Reported in every response; default ``<host>-<pid>``.
    prefix : str
        Key prefix; frames are taken from ``<prefix>/<robot>/frame``.
    idle_timeout : float
        Seconds without frames after which a robot's state is evicted.
    max_gap : int
        Largest forward jump of ``seq``, in the robot's steps, that keeps the state (see
        :mod:`service.streams`).
    max_robots : int
        Robots with a model state at once; frames of further robots are rejected
        (``too-many-robots``). As many candidates (robots none of whose frames was valid yet)
        may wait besides.
    takeover_after : float
        Seconds a robot's stream must be silent before the frames of another publisher on its
        key may replace it, once two publishers were seen there (see :mod:`service.streams`).
    clock : callable
        Monotonic seconds (tests may pass a fake one).
    owns : callable, optional
        ``owns(robot) -> bool``: whether this worker takes the robot's frames (default: every
        robot's).
    answers : callable, optional
        ``answers(robot) -> bool``: whether its frames are answered (default: every robot's);
        the others are stepped silently (warming up to take the robot over).
    warmup_frames : int
        Frames a robot's model must step on its current stream before it is :meth:`warm` (the
        frames the ASNN model's frame-rate ceiling holds do not count).
    log_interval : float
        Seconds between two WARNING lines of the same kind (a rejection's reason, a robot's
        intrusion, restarts, lost frames, slow or untimed stream; a model's failure).

    Raises
    ------
    ValueError
        For an unknown model or preset.
    """

    def __init__(self, model: str = "asnn", preset: str | None = None, *,
                 worker_id: str | None = None, prefix: str = keys.DEFAULT_PREFIX,
                 idle_timeout: float = IDLE_TIMEOUT_S, max_gap: int = MAX_GAP,
                 max_robots: int = MAX_ROBOTS, takeover_after: float = TAKEOVER_AFTER_S,
                 clock: Callable[[], float] = time.monotonic,
                 owns: Callable[[str], bool] | None = None,
                 answers: Callable[[str], bool] | None = None,
                 warmup_frames: int = HANDOVER_WARMUP_FRAMES,
                 log_interval: float = 10.0):
        if model != "asnn" and preset is not None:  # dropped without a word, and not reported
            raise ValueError(f"--preset applies to the ASNN model only, not {model}")
        self.model = model
        self.preset = (DEFAULT_PRESET if preset in (None, "default") else preset) \
            if model == "asnn" else ""
        # the parameters each robot's model is made of (a spec checked now, not on the first
        # frame); the responses report the spec as given
        self.params = preset_from_spec(self.preset) if model == "asnn" else None
        # frames smaller than this are refused as they arrive, before they can start a stream
        self.min_side = make_detector(model, self.params).min_side
        self.worker_id = worker_id or default_worker_id()
        if len(self.worker_id) > MAX_NOTE_LEN:  # viewers show no more of it (clients.fleet)
            raise ValueError(f"a worker id has at most {MAX_NOTE_LEN} characters, got "
                             f"{len(self.worker_id)}")
        self.prefix = keys.check_prefix(prefix)
        self.idle_timeout = float(idle_timeout)
        if max_gap < 1:  # a gap of 0 steps would make every next frame a new stream
            raise ValueError(f"max_gap must be 1 or more (1: any frame lost starts the robot's "
                             f"model afresh), got {max_gap}")
        self.max_gap = int(max_gap)
        self.max_robots = int(max_robots)
        self.takeover_after = float(takeover_after)
        self.clock = clock
        self.owns = owns
        self.answers = answers
        if warmup_frames < 0:
            raise ValueError(f"warmup_frames must be 0 or more, got {warmup_frames}")
        self.warmup_frames = int(warmup_frames)
        self.started = clock()
        self._limited_log = RateLimitedLog(log, log_interval, clock)
        # the latest refusal of each of the last MAX_REFUSED robot ids refused, for the status:
        # a camera none of whose frames is taken never appears among the robots
        self._refused: OrderedDict[str, dict] = OrderedDict()
        self._robots: dict[str, _Robot] = {}
        # robots handed over while a frame of theirs was processed, forgotten when it was
        # done: release_unowned() returns them next (one entry per robot, so bounded by them)
        self._released_busy: dict[str, None] = {}
        self._stats = _Stats()
        self._arrivals = 0  # frames taken in, for the order of the queue
        self._lock = threading.Lock()
        self._ready = threading.Condition(self._lock)

    # ------------------------------------------------------------------ input side

    def offer(self, key: str, payload: bytes, received: float | None = None) -> str | None:
        """Validate a frame message and make it the robot's pending frame.

        Returns the robot id, or ``None`` when the message was rejected (and counted).
        Never raises for bad input.
        """
        received = self.clock() if received is None else received
        try:
            robot, kind = keys.parse_key(key, self.prefix)
            if kind != "frame":
                raise MessageError("bad-key", f"{key!r} is not a frame key")
            if self.owns is not None and not self.owns(robot):
                with self._lock:
                    self._stats.foreign += 1
                return None
            frame = decode_frame(payload)
            frame.check_size()
            if min(frame.width, frame.height) < self.min_side:
                # refused here, not by the model: a stray small frame taken in would start a
                # stream of its own, reset the robot's model and mark the robot contested when
                # its camera's next frame continued the stream it broke (a client's trial)
                raise MessageError("frame-rejected", f"frame {frame.width}x{frame.height} is "
                                   f"smaller than the model's {self.min_side}x{self.min_side} "
                                   "kernels")
        except keys.KeySchemeError as exc:
            self._reject("bad-key", str(exc), key)
            return None
        except MessageError as exc:
            self._reject(exc.reason, exc.detail, key)
            return None
        with self._lock:
            state = self._robots.get(robot)
            if state is None:
                full = self._full_locked(candidate=True)
                if full:
                    self._reject_locked("too-many-robots", full, key)
                    return None
                state = self._robots[robot] = _Robot()
            if state.last_arrival == (frame.seq, frame.stamp, frame.data):
                self._stats.duplicates += 1  # delivered twice: already taken
                return None
            if state.stream is not None and state.stream.outran(frame, self._gap(state)):
                self._reject_locked("late", f"frame {frame.seq} of {robot} arrived after frame "
                                    f"{state.stream.seq}: the model does not go back in time",
                                    key)
                return None
            intrusions = state.intrusions
            stream = place_frame(robot, state, frame, received, max_gap=self.max_gap,
                                 takeover_after=self.takeover_after, prefix=self.prefix,
                                 limited_log=self._limited_log)
            self._stats.intrusions += state.intrusions - intrusions  # one it found, if any
            if stream is None:
                self._reject_locked("second-publisher", f"frame {frame.seq} does not continue "
                                    f"the stream of {robot} (last seq {state.stream.seq})",
                                    key)
                return None
            self._stats.received += 1
            state.arrived += 1
            state.arrived_bytes += len(payload)
            if state.last_arrival is not None:  # after the gap rule: a new step counts once
                learn_step(state, frame.seq - state.last_arrival[0])
            state.last_arrival = (frame.seq, frame.stamp, frame.data)
            if state.pending is not None:
                state.dropped += 1
                self._stats.dropped += 1
            else:
                self._arrivals += 1
                state.waiting_since = self._arrivals
            state.pending = (frame, received, stream)
            state.last_seen = received
            self._ready.notify()
        return robot

    def _gap(self, state: _Robot) -> int:
        """The largest forward jump of a robot's ``seq`` that continues its stream:
        ``max_gap`` of its steps."""
        return self.max_gap * state.seq_step

    def _full_locked(self, candidate: bool = False) -> str | None:
        """Why a new robot cannot take a slot (or, ``candidate``, wait for one) now; None if
        it can. A full table makes room first by forgetting the robot silent longest, if it
        has been silent for ``takeover_after`` seconds: ids that sent a frame or two and went
        (a flood of them, or cameras renamed) cannot lock a new camera out for
        ``idle_timeout``."""
        proven = sum(s.proven for s in self._robots.values())
        if proven >= self.max_robots and not self._make_room_locked():
            return f"already tracking {self.max_robots} robots"
        if candidate and len(self._robots) - proven >= self.max_robots:
            return f"already {self.max_robots} new robots waiting for a first valid frame"
        return None

    def _make_room_locked(self) -> bool:
        """Forget the proven robot silent longest if it has been silent for
        ``takeover_after`` seconds (and has no frame waiting or in process); whether one was."""
        now = self.clock()
        quiet = [(s.last_seen, r) for r, s in self._robots.items()
                 if s.proven and not s.busy and s.pending is None
                 and now - s.last_seen >= self.takeover_after]
        if not quiet:
            return False
        last_seen, robot = min(quiet)
        del self._robots[robot]
        self._stats.evicted += 1
        log.info("robot %s: forgotten after %.0f s without frames to make room for a new one",
                 robot, now - last_seen)
        return True

    def _reject(self, reason: str, detail: str, key: str) -> None:
        with self._lock:
            self._reject_locked(reason, detail, key)

    def _reject_locked(self, reason: str, detail: str, key: str) -> None:
        self._stats.invalid[reason] += 1
        n = self._stats.invalid[reason]
        try:
            robot = keys.parse_key(key, self.prefix)[0]
        except keys.KeySchemeError:
            robot = None  # not a robot's key: counted, and logged, only
        if robot is not None:
            last = self._refused.pop(robot, None)
            self._refused[robot] = {"reason": reason[:MAX_REASON_LEN],
                                    "detail": detail[:MAX_NOTE_LEN],
                                    "count": (last["count"] if last else 0) + 1,
                                    "at": self.clock(), "told": False}
            if len(self._refused) > MAX_REFUSED:
                self._refused.popitem(last=False)
        self._limited_log.warning(reason, "invalid frame on %r (%s, #%d): %s", str(key)[:200],
                                 reason, n, detail[:300])

    def refusals_to_tell(self) -> list[tuple[str, str, str, int]]:
        """The refusals made since the last call, for the robots' cameras: ``(robot, reason,
        detail, count)``, the latest per robot (at most :data:`MAX_REFUSED`)."""
        with self._lock:
            told = [(r, e["reason"], e["detail"], e["count"]) for r, e in self._refused.items()
                    if not e["told"]]
            for robot, *_ in told:
                self._refused[robot]["told"] = True
        return told

    # ------------------------------------------------------------------ processing side

    def take(self, timeout: float | None = 0.0) -> Job | None:
        """The frame of the robot that has waited longest (not being processed), or None.

        A robot's wait starts with the first frame it waits with, however often a newer frame
        replaces it. Waits up to ``timeout`` seconds for one (``None``: forever). The robot
        stays busy until :meth:`process` finishes with the job.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._ready:
            while True:
                ready = [(s.waiting_since, r) for r, s in self._robots.items()
                         if s.pending is not None and not s.busy
                         and (self.owns is None or self.owns(r))]
                if ready:
                    robot = min(ready)[1]
                    state = self._robots[robot]
                    frame, received, stream = state.pending
                    job = Job(robot, frame, received, state.dropped, stream.number,
                              stream.reason)
                    state.pending, state.dropped, state.busy = None, 0, True
                    return job
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return None
                self._ready.wait(remaining)

    def notify(self) -> None:
        """Wake a thread waiting in :meth:`take` (ownership changed, or the worker stops)."""
        with self._ready:
            self._ready.notify_all()

    def process(self, job: Job, publish: Callable[[Response], None] | None = None
                ) -> Response | None:
        """Run the robot's model on the job's frame; the wire Response, or None if rejected.

        ``publish`` is called with the response before the robot is released: with several
        processing threads, another thread could otherwise step the robot's next frame and send
        its response first (a user trial saw 83 inversions in 11,624 responses at 300 fps).
        """
        try:
            response = self._process(job)
            if response is not None and publish is not None:
                publish(response)
            return response
        finally:
            with self._ready:
                state = self._robots.get(job.robot)
                if state is not None:
                    state.busy = False
                    if self.owns is not None and not self.owns(job.robot):
                        del self._robots[job.robot]  # handed over while it was processed
                        self._stats.released += 1
                        self._released_busy[job.robot] = None
                    elif not state.proven and state.pending is None:
                        del self._robots[job.robot]  # a candidate whose frame failed
                    elif state.pending is not None:
                        self._ready.notify()

    def _process(self, job: Job) -> Response | None:
        frame = job.frame
        with self._lock:
            state = self._robots.get(job.robot)
            if state is None:  # evicted meanwhile (cannot happen while busy, but be safe)
                state = self._robots[job.robot] = _Robot(last_seen=job.received, busy=True)
        try:
            image = frame.image()
        except MessageError as exc:
            self._refuse_taken(state, job, exc.reason, exc.detail)
            return None
        if not state.proven:
            with self._lock:
                full = self._full_locked()
                if full is None:
                    state.proven = True  # counted from now on; undone if the model refuses
            if full:
                self._refuse_taken(state, job, "too-many-robots", full)
                return None
        reset = state.processed_stream not in (None, job.stream)
        if state.detector is None:
            state.detector = make_detector(self.model, self.params)
            state.id_base = track_id_base(frame.seq)
        elif reset:
            reason = job.reset_reason or "seq-backwards"
            state.detector.reset()
            state.id_base = track_id_base(frame.seq)
            state.resets += 1
            with self._lock:
                self._stats.resets[reason] += 1
            if state.restarts < RESTARTS_WARNED:  # past it, offer's rate-limited WARNING says it
                # (a camera whose seq never grows resets on every frame: 72,000 lines an hour)
                log.info("robot %s: state reset (%s) at seq %d", job.robot, reason, frame.seq)
        started = self.clock()
        try:
            result = state.detector.step(image, frame.stamp)
        except FrameError as exc:
            if state.processed == 0:
                with self._lock:
                    state.proven = False
            if reset:  # the model was reset for the stream this frame began: the next
                state.processed_stream = None  # response says so (stream_frames 1)
            self._refuse_taken(state, job, "frame-rejected", str(exc))
            return None
        except Exception as exc:  # a bug: the frame is refused, counted and told, not lost,
            # its traceback logged at most once per log_interval (not once per frame), and the
            # model, stopped halfway through a step, starts afresh on the next frame
            self._limited_log.exception("model-failed-trace",
                                        "robot %s: the model failed on frame %d", job.robot,
                                        frame.seq)
            state.detector = state.processed_stream = None
            self._refuse_taken(state, job, "model-failed", f"{type(exc).__name__}: {exc}")
            return None
        if state.processed == 0:
            log.info("robot %s: first frame (%dx%d %s)", job.robot, frame.width, frame.height,
                     frame.format)
        state.stepped = 1 if state.processed_stream != job.stream else state.stepped + 1
        self._measure_rate(job.robot, state, frame.stamp)
        state.shape = (frame.width, frame.height)
        state.last_seq = frame.seq
        state.processed_stream = job.stream
        state.processed += 1
        if self.answers is not None and not self.answers(job.robot):
            with self._lock:
                self._stats.warmup += 1
            return None
        response = response_from(result, robot=job.robot, frame=frame, model=self.model,
                                 preset=self.preset, worker=self.worker_id,
                                 latency_ms=(self.clock() - job.received) * 1e3,
                                 dropped=job.dropped, model_ms=(self.clock() - started) * 1e3,
                                 id_base=state.id_base, stream_frames=state.model_steps)
        with self._lock:
            self._stats.processed += 1
            self._stats.warnings += response.collision
        return response

    def _measure_rate(self, robot: str, state: _Robot, stamp: float) -> None:
        """Note the gap since the robot's previous processed frame; log when its model has
        been stepped at less than :data:`asnn.params.SLOW_FPS` for PERIOD_FRAMES frames in a row
        (a slow camera, or frames skipped under load; a moment's skips are not logged, and a
        slowdown after the rate recovered is logged again, at most once every 10 s): the
        default preset loses hits there (docs/evaluation.md, "At half the frame rate")."""
        if state.stepped == 1:
            state.periods.clear()
            state.slow_frames = state.untimed_frames = 0
        elif state.stamp is not None:
            gap = stamp - state.stamp
            timed = timed_gap(gap)
            if timed:
                state.periods.append(gap)
            self._note_untimed(robot, state, timed, gap)
        state.stamp = stamp
        fps = state.fps
        slow = len(state.model_periods) == PERIOD_FRAMES and fps is not None and fps < SLOW_FPS
        state.slow_frames = state.slow_frames + 1 if slow else 0
        if not slow:
            state.slow_logged = False
        elif state.slow_frames >= PERIOD_FRAMES and not state.slow_logged:
            # slow for a while, not a moment's skips; logged once per slow spell, when the
            # rate limit lets it through (so a relapse soon after one is logged later)
            processed = state.processed_fps
            why = ("the camera's rate, or frames skipped under load" if processed is None
                   or processed < SLOW_FPS else
                   f"{processed:.1f} frames a second are processed, the others repeating the "
                   "frame before: a still scene seen without sensor noise, or a camera that "
                   "sends its frames twice")
            state.slow_logged = self._limited_log.warning(
                f"slow:{robot}", "robot %s: its model steps %.1f new frames per second (%s); the "
                "default preset is made for 20 or more", robot, fps, why)

    def _note_untimed(self, robot: str, state: _Robot, timed: bool, gap: float) -> None:
        """Log when PERIOD_FRAMES frames in a row are stamped less than MIN_FRAME_GAP_S or more
        than MAX_FRAME_GAP_S apart: the model then times them at its nominal period, so the targets'
        time to contact is off by the camera's true period over the nominal one (a clock
        in milliseconds, or one that never moves); once per spell, rate-limited."""
        state.untimed_frames = 0 if timed else state.untimed_frames + 1
        if self.model != "asnn":  # the baselines time nothing
            return
        if timed:
            state.untimed_logged = False
        elif state.untimed_frames >= PERIOD_FRAMES and not state.untimed_logged:
            state.untimed_logged = self._limited_log.warning(
                f"untimed:{robot}", "robot %s: its frames' stamps are %g s apart, not a frame "
                "period the model believes (%g to %g s): the targets' time to contact is timed "
                "at %g frames a second instead; stamps are the camera's clock in seconds "
                "(CONTRACT.md), and %s", robot, gap, MIN_FRAME_GAP_S, MAX_FRAME_GAP_S,
                1.0 / state.detector.params.dt,
                "a camera slower than a frame a second is far below the 20 fps the default "
                "is made for" if gap > MAX_FRAME_GAP_S else
                "these read like a clock that stands still, or stamps under 0.1 ms apart")

    def _refuse_taken(self, state: _Robot, job: Job, reason: str, detail: str) -> None:
        """A frame taken in is refused when it is processed (its image, its robot's place, the
        model): it counts as refused, not as received, and its skipped count moves to the
        robot's next response."""
        with self._lock:
            state.dropped += job.dropped
            self._stats.received -= 1
            if withdraw_frame(state, job.stream):  # it had been taken for an intrusion
                self._stats.intrusions -= 1
        self._reject(reason, detail, keys.frame_key(job.robot, self.prefix))

    # ------------------------------------------------------------------ housekeeping

    def evict_idle(self, now: float | None = None) -> list[str]:
        """Forget robots idle for longer than ``idle_timeout``; returns their ids."""
        now = self.clock() if now is None else now
        with self._lock:
            gone = [r for r, s in self._robots.items()
                    if not s.busy and s.pending is None and now - s.last_seen > self.idle_timeout]
            for robot in gone:
                del self._robots[robot]
            self._stats.evicted += len(gone)
        for robot in gone:
            log.info("robot %s: evicted after %.0f s without frames", robot, self.idle_timeout)
        return gone

    def release_unowned(self) -> list[str]:
        """Forget the robots this worker no longer owns (their pending frames are discarded;
        one being processed is forgotten when it is done); returns their ids, with those of
        the robots forgotten so since the last call (each once)."""
        if self.owns is None:
            return []
        with self._lock:
            gone = [r for r, s in self._robots.items() if not self.owns(r)]
            # counted when they were forgotten; not where the robot is back with this worker
            released = [r for r in self._released_busy if r not in self._robots]
            self._released_busy.clear()
            for robot in gone:
                state = self._robots[robot]
                state.pending = None
                if not state.busy:
                    del self._robots[robot]
                    released.append(robot)
                    self._stats.released += 1
        return released  # the worker logs each, with its new owner

    def robots(self) -> list[str]:
        """Robots currently tracked."""
        with self._lock:
            return sorted(self._robots)

    def warm(self, robot: str) -> bool:
        """Whether the robot's model has stepped ``warmup_frames`` frames of the stream its
        frames arrive in, the frames its frame-rate ceiling held not counted (so its responses
        are those of a model that saw the whole stream)."""
        with self._lock:
            state = self._robots.get(robot)
            return state is not None and self._warm_locked(state)

    def _warm_locked(self, state: _Robot) -> bool:
        return (state.detector is not None and state.model_steps >= self.warmup_frames
                and (state.stream is None or state.stream.number == state.processed_stream))

    def views(self) -> dict[str, RobotView]:
        """Every tracked robot's :class:`RobotView` (for routing)."""
        with self._lock:
            return {r: RobotView(s.proven, self._warm_locked(s), s.last_seen)
                    for r, s in self._robots.items()}

    def backlog(self) -> int:
        """Frames waiting or being processed (at most two per robot)."""
        with self._lock:
            return sum((s.pending is not None) + s.busy for s in self._robots.values())

    def stats(self) -> dict:
        """Counters: received, processed, dropped, warnings, evicted, foreign, released, robots
        (with a slot), candidates (waiting for a first valid frame), intrusions (second
        publishers detected), duplicates (frames delivered twice), warmup (frames stepped
        without a response), invalid{reason}, resets{reason}."""
        with self._lock:
            s = self._stats
            proven = sum(r.proven for r in self._robots.values())
            return {"received": s.received, "processed": s.processed, "dropped": s.dropped,
                    "warnings": s.warnings, "evicted": s.evicted, "foreign": s.foreign,
                    "released": s.released, "robots": proven,
                    "candidates": len(self._robots) - proven, "intrusions": s.intrusions,
                    "duplicates": s.duplicates, "warmup": s.warmup,
                    "invalid": dict(s.invalid), "resets": dict(s.resets)}

    @property
    def log_interval(self) -> float:
        """Seconds between two lines of one reason in its rate-limited log (``log_interval``)."""
        return self._limited_log.interval

    def status(self) -> dict:
        """What the status queryable answers (docs/operations.md): identity, limits, counters
        and the robots tracked, with their pending work."""
        with self._lock:
            now = self.clock()
            robots = {r: {"processed": s.processed, "resets": s.resets,
                          "pending": s.pending is not None, "busy": s.busy,
                          "last_seq": s.last_seq, "seq_step": s.seq_step,
                          "size": list(s.shape) if s.shape else None,
                          "candidate": not s.proven, "contested": s.contested(now),
                          "intrusions": s.intrusions, "frames": s.arrived,
                          "bytes": s.arrived_bytes, "warm": self._warm_locked(s),
                          # its stamps no frame period (a camera under 1 fps, a clock in
                          # other units): fps None, and no less in trouble than a slow one
                          "fps": s.fps, "untimed": s.untimed_frames >= PERIOD_FRAMES,
                          # since its latest frame arrived: a camera that died stays listed
                          # until idle_timeout, and only this tells it from a live one
                          "idle_s": round(now - s.last_seen, 1)}
                      for r, s in sorted(self._robots.items())}
            backlog = sum((s.pending is not None) + s.busy for s in self._robots.values())
            refused = {r: {"reason": e["reason"], "detail": e["detail"], "count": e["count"],
                           "seconds_ago": round(now - e["at"], 1)}
                       for r, e in self._refused.items()}
        return {"v": VERSION, "worker": self.worker_id, "model": self.model, "preset": self.preset,
                "prefix": self.prefix, "uptime_s": round(self.clock() - self.started, 3),
                "limits": {"max_side": MAX_SIDE, "max_payload": MAX_PAYLOAD,
                           "max_robots": self.max_robots, "max_gap": self.max_gap,
                           "idle_timeout": self.idle_timeout,
                           "takeover_after": self.takeover_after,
                           "warmup_frames": self.warmup_frames},
                "backlog": backlog, "stats": self.stats(), "robots": robots,
                "refused": refused}

