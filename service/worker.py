"""The ASNN worker on Zenoh: frames of its robots in, responses and warnings out.

Subscribes to the frames of the robots it serves (best effort), runs
:class:`~service.core.WorkerCore` on processing threads and publishes, for every answered frame,
a Response on ``<prefix>/<robot>/response`` and, when ``collision`` is true, on
``<prefix>/<robot>/warning``. Responses and warnings are reliable, with blocking congestion
control and a higher priority than frames. Warnings go through an advanced publisher that caches
the robot's latest warning, so an advanced subscriber that joins late (``clients.alerts``)
receives it.

Several workers share the robots (:mod:`service.ownership`, :mod:`service.routing`): each
declares the liveliness token ``<prefix>/@worker/<id>``, watches the others' and serves the
robots that rendezvous hashing gives it over the live set, subscribing to
``<prefix>/<robot>/frame`` for each, so every frame reaches one worker. A worker alone on its
prefix also subscribes to ``<prefix>/*/frame``; with several, one scans it now and then for
cameras that do not announce themselves. Hand-overs are warm: the new owner steps the robot's
frames silently until its model is warm, while the previous owner answers, and a worker that
stops answers its robots until their new owners are warm (at most ``handover_timeout``). One
that dies loses its tokens when the router sees its session close or its lease expire, and its
robots start cold at their new owners. A robot whose frames the worker refuses (an invalid
message, a second publisher, a full table, ...) is told why on ``<prefix>/<robot>/refused``, at
most once a second (:class:`~service.messages.Refusal`). Each worker answers queries on
``<prefix>/@worker/<id>/status`` with a msgpack map (:meth:`service.core.WorkerCore.status` plus
the live workers, the routes and the frames received). A bug that fails frames outside the
model (publishing a response, a frame callback) has its traceback logged at most once every
``log_interval`` (the core's) per robot, or per callback, with the count of those not shown.
"""

from __future__ import annotations

import logging
import math
import os
import sys
import threading
import time
from collections.abc import Callable

import zenoh
from zenoh.ext import CacheConfig, MissDetectionConfig, declare_advanced_publisher

from . import keys
from .core import Job, WorkerCore
from .logutil import RateLimitedLog
from .messages import (MAX_NOTE_LEN, MessageError, Refusal, Response, decode_status, encode,
                       encode_status)
from .routing import Routes

__all__ = ["COMPUTE_NICENESS", "HANDOVER_TIMEOUT", "REFUSAL_QOS", "RESPONSE_QOS", "SCAN_INTERVAL",
           "SCAN_WINDOW", "SWITCH_INTERVAL", "WARNING_QOS", "Worker", "WorkerIdTaken",
           "announced_cameras", "check_scan", "fleet_claims", "live_workers", "query_status",
           "status_replies", "tune_process"]

log = logging.getLogger("asnn.worker")

RESPONSE_QOS = dict(congestion_control=zenoh.CongestionControl.BLOCK,
                    priority=zenoh.Priority.DATA_HIGH, reliability=zenoh.Reliability.RELIABLE)
WARNING_QOS = dict(congestion_control=zenoh.CongestionControl.BLOCK,
                   priority=zenoh.Priority.INTERACTIVE_HIGH, reliability=zenoh.Reliability.RELIABLE)
# A refusal notice is worth less than anything else the worker sends, and never waits.
REFUSAL_QOS = dict(congestion_control=zenoh.CongestionControl.DROP,
                   priority=zenoh.Priority.BACKGROUND)
# Per-publisher sequence numbers. Without them the advanced subscriber orders samples by
# timestamp per session, and a late joiner can lose the cached warning of every robot but the
# most recent one (all warning publishers of a worker share its session). The sporadic heartbeat
# also lets subscribers recover a warning they missed.
MISS_DETECTION = MissDetectionConfig(heartbeat=None, sporadic_heartbeat=1.0)
# The processing threads give the GIL up inside every model kernel and need it back after each
# one. With the interpreter's default 5 ms switch interval, a thread running Python (another
# processing thread, a Zenoh callback decoding a frame) can keep it for up to 5 ms meanwhile.
# With this interval and two threads, the worker's p99 at 16 cameras went from 18-20 ms (one
# thread) to 4-8 ms (docs/operations.md).
SWITCH_INTERVAL = 0.0005
# The processing threads run at this niceness above the process's (Linux, per thread), so that
# the threads that move messages (Zenoh's, the frame callback, liveliness and status) take a
# core at once when they wake up instead of waiting for a model step to end. Under load that
# halved the worker's p99 wait between a frame's arrival and its processing; under overload it
# keeps the liveliness token and status queries answered.
COMPUTE_NICENESS = 5
# Discovery of cameras that do not announce themselves, when several workers share a prefix: the
# scanning worker subscribes to every robot's frames for SCAN_WINDOW seconds every SCAN_INTERVAL
# seconds, so such a camera gets an owner within about a second (at 10 fps or more), for
# SCAN_WINDOW / SCAN_INTERVAL of the frame traffic again at that one worker. Cameras that
# announce themselves (asnn camera) are known at once and need no scan (--scan-interval 0).
SCAN_INTERVAL = 1.0
SCAN_WINDOW = 0.1
# A worker that stops answers its robots until their new owners are warm, for at most this long.
HANDOVER_TIMEOUT = 5.0
# ... but not for robots whose frames stopped this long ago (no new owner can warm up on them).
STALE_AFTER = 2.0
# Seconds between two passes of the routes when nothing changed (warm-ups, scan windows, expiry).
ROUTE_TICK = 0.05
# how often a worker asks who else answers for its id (Worker._check_twins)
TWIN_CHECK_S = 10.0
# ``query_status``: any process on the prefix may answer a status query, as often as it likes,
# with maps of up to STATUS_MAX_BYTES (16 MiB) each, and the worker's own health check runs in
# its container: replies waiting to be read, and statuses kept, are bounded
STATUS_QUEUE = 8  # replies Zenoh holds until they are read
MAX_STATUSES = 256  # workers answering
MAX_STATUS_BYTES_KEPT = 64 * 2**20  # of the statuses kept, as received


def tune_process() -> None:
    """Process-wide settings for a worker process (the ``asnn worker`` command calls it).

    Parallelism comes from the processing threads, one robot each: OpenCV's own thread pool
    (for the attention blur) would only compete with them, so it is set to one thread; and the
    interpreter's switch interval is shortened to :data:`SWITCH_INTERVAL`.
    """
    import cv2

    cv2.setNumThreads(1)
    sys.setswitchinterval(SWITCH_INTERVAL)


def check_scan(interval: float, window: float = SCAN_WINDOW) -> None:
    """Raise ValueError unless ``interval`` is 0 (no scan) or longer than ``window`` > 0."""
    if not (interval >= 0 and window > 0):
        raise ValueError(f"need a scan interval >= 0 and a window > 0, got {interval}, {window}")
    if interval and window >= interval:
        raise ValueError(f"the scan interval ({interval:g} s) must be longer than its window "
                         f"({window:g} s), or 0 for no scan")


def _lower_priority(increment: int) -> None:
    """Raise the calling thread's niceness by ``increment`` (Linux only: elsewhere
    ``setpriority`` would apply to the whole process)."""
    if not sys.platform.startswith("linux"):
        return
    tid = threading.get_native_id()
    try:
        os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + increment)
    except OSError:  # not allowed here: run at the process's priority
        log.debug("could not lower the priority of thread %d", tid)


def _undeclare(entity) -> None:
    """Undeclare a Zenoh entity; the session may already be closed."""
    try:
        entity.undeclare()
    except Exception:
        pass


def _on_network_thread(callback: Callable[[zenoh.Sample], None]):
    """A frame subscriber's handler that runs ``callback`` on the Zenoh thread that received
    the sample.

    A plain Python callable gets a thread of its own per subscriber (zenoh-python's default),
    fed by a queue with no bound: a worker serving 40 robots kept 40 more threads, and a
    callback that falls behind queues every sample (a 1 MB stream at twice a slow callback's
    pace: +370 MB in 10 s). Run where they arrive, frames that come faster than the model
    takes them are replaced by newer ones (the worker's own drops, counted in its status) or,
    past what the thread can file, wait in the link's bounded buffers and are dropped there, as
    their best-effort QoS allows (a 100-robot flood: a thread per robot before, none now; the
    frames answered and the latency as before). The frame callbacks only decode and file the
    frame, under locks never held across a Zenoh call, so they cannot stall the thread (they
    may log, rate-limited). ``indirect`` is marked unstable in zenoh-python 1.x: without it,
    the default applies.
    """
    try:
        return zenoh.handlers.Callback(callback, indirect=False)
    except TypeError:
        return callback


class WorkerIdTaken(RuntimeError):
    """Another live worker already uses this worker id."""


def _live_tokens(session: zenoh.Session, key: str, parse, timeout: float) -> list:
    """``parse(key)`` of every live liveliness token matching ``key`` (tokens that do not parse,
    and error replies, are skipped)."""
    found = set()
    for reply in session.liveliness().get(key, timeout=timeout):
        try:
            found.add(parse(str(reply.ok.key_expr)))
        except Exception:
            continue
    return sorted(found)


def live_workers(session: zenoh.Session, prefix: str = keys.DEFAULT_PREFIX,
                 timeout: float = 2.0) -> list[str]:
    """Ids of the workers whose liveliness tokens are alive under ``prefix``."""
    return _live_tokens(session, keys.worker_tokens(prefix),
                        lambda key: keys.parse_worker_token(key, prefix), timeout)


def fleet_claims(session: zenoh.Session, prefix: str = keys.DEFAULT_PREFIX,
                 timeout: float = 2.0) -> list[tuple[str, str]]:
    """``(worker, robot)`` of every live claim under ``prefix``."""
    return _live_tokens(session, keys.claims(prefix), lambda key: keys.parse_claim(key, prefix),
                        timeout)


def announced_cameras(session: zenoh.Session, prefix: str = keys.DEFAULT_PREFIX,
                      timeout: float = 2.0) -> list[str]:
    """Robots whose cameras announce themselves under ``prefix``."""
    return _live_tokens(session, keys.camera_tokens(prefix),
                        lambda key: keys.parse_camera_token(key, prefix), timeout)


def query_status(session: zenoh.Session, prefix: str = keys.DEFAULT_PREFIX,
                 worker: str | None = None, timeout: float = 2.0,
                 keep: Callable[[str], bool] | None = None) -> dict[str, dict]:
    """The status maps of one worker or (``worker=None``) of all, by worker id (where two
    processes answer for one id, the last to answer: :func:`status_replies` keeps both)."""
    return {status["worker"]: status
            for status in status_replies(session, prefix, worker, timeout, keep)}


def status_replies(session: zenoh.Session, prefix: str = keys.DEFAULT_PREFIX,
                   worker: str | None = None, timeout: float = 2.0,
                   keep: Callable[[str], bool] | None = None) -> list[dict]:
    """The status maps of one worker or (``worker=None``) of all, as they answered (one per
    process: two processes with one id give two); with ``keep``, of the workers whose id it
    accepts (the others are dropped unread, by their reply's key).

    Any process on the prefix may answer, so what is held is bounded: :data:`STATUS_QUEUE`
    replies waiting, each decoded within the status bounds, and at most :data:`MAX_STATUSES`
    statuses of :data:`MAX_STATUS_BYTES_KEPT` in all kept (the first to come).
    """
    key = keys.worker_status_key(worker, prefix) if worker else keys.worker_statuses(prefix)
    out, kept = [], 0
    for reply in session.get(key, zenoh.handlers.FifoChannel(STATUS_QUEUE),
                             target=zenoh.QueryTarget.ALL, timeout=timeout,
                             consolidation=zenoh.ConsolidationMode.NONE):
        if reply.ok is None:  # an error reply
            continue
        if keep is not None and not keep(_replier(str(reply.ok.key_expr), prefix)):
            continue  # not decoded at all
        payload = reply.ok.payload.to_bytes()
        if len(out) >= MAX_STATUSES or kept + len(payload) > MAX_STATUS_BYTES_KEPT:
            continue
        try:
            status = decode_status(payload)
        except MessageError:
            continue
        if keep is None or keep(status["worker"]):
            kept += len(payload)
            out.append(status)
    return out


def _replier(key: str, prefix: str) -> str:
    """The worker id of a status reply's key (``<prefix>/@worker/<id>/status``); "" for a key
    of another form."""
    try:
        return keys.parse_worker_token(key.removesuffix("/status"), prefix)
    except keys.KeySchemeError:
        return ""


class _Outlets:
    """The two publishers of one robot."""

    def __init__(self, session: zenoh.Session, robot: str, prefix: str):
        self.response = session.declare_publisher(keys.response_key(robot, prefix), **RESPONSE_QOS)
        self.warning = declare_advanced_publisher(
            session, keys.warning_key(robot, prefix), cache=CacheConfig(max_samples=1),
            publisher_detection=True, sample_miss_detection=MISS_DETECTION, **WARNING_QOS)

    def undeclare(self) -> None:
        _undeclare(self.response)
        _undeclare(self.warning)


class Worker:
    """Runs a :class:`WorkerCore` on a Zenoh session (use as a context manager, or start/close).

    Parameters
    ----------
    session : zenoh.Session
    core : WorkerCore
    on_response : callable, optional
        Called with every published Response (for the demo and tests).
    stats_every : float
        Seconds between two log lines of counters (0: none).
    shared : bool
        Take part in the fleet (liveliness token, claims, routes); False serves every robot
        whose frames arrive, alone.
    threads : int
        Processing threads. The model's kernels release the GIL, so each core can run one
        (:func:`service.core.default_threads`, with :func:`tune_process`); a robot is still
        processed by one thread at a time (:class:`WorkerCore`).
    scan_interval, scan_window : float
        How often, and for how long, the scanning worker subscribes to every robot's frames
        when several workers share the prefix (:data:`SCAN_INTERVAL`, :data:`SCAN_WINDOW`;
        ``scan_interval=0``: never, only announced or claimed robots are served).
    handover_timeout : float
        Seconds a stopping worker answers its robots at most, waiting for their new owners to
        be warm (:data:`HANDOVER_TIMEOUT`).
    """

    def __init__(self, session: zenoh.Session, core: WorkerCore, *, on_response=None,
                 stats_every: float = 30.0, shared: bool = True, threads: int = 1,
                 scan_interval: float = SCAN_INTERVAL, scan_window: float = SCAN_WINDOW,
                 handover_timeout: float = HANDOVER_TIMEOUT):
        if threads < 1:
            raise ValueError(f"a worker needs at least one processing thread, got {threads}")
        check_scan(scan_interval, scan_window)
        if not handover_timeout >= 0:
            raise ValueError(f"need handover_timeout >= 0, got {handover_timeout}")
        self.session = session
        self._instance = str(session.zid())  # tells this process from another with its id
        self._twin_lock = threading.Lock()
        self._twin_check = self._twin_logged = 0  # the latest check, and the one that logged
        self.core = core
        self.on_response = on_response
        self.stats_every = stats_every
        self.shared = shared
        self.threads = threads
        self.scan_interval, self.scan_window = float(scan_interval), float(scan_window)
        self.handover_timeout = float(handover_timeout)
        self.routes = Routes(core.worker_id, remember=core.idle_timeout,
                             max_known=4 * core.max_robots)
        self.membership = self.routes.membership
        self._outlets: dict[str, _Outlets] = {}
        self._outlets_lock = threading.Lock()
        self._subscriptions: dict[str, zenoh.Subscriber] = {}  # per robot, once declared
        self._claims: dict[str, zenoh.LivelinessToken] = {}
        self._catch_all = None
        self._scan_next = self._scan_until = 0.0
        self._traffic = dict.fromkeys(("frames", "bytes", "scanned_frames", "scanned_bytes"), 0)
        self._traffic_lock = threading.Lock()
        self._routes_lock = threading.Lock()  # one pass over the routes at a time
        self._changed = threading.Event()
        self._stop = threading.Event()
        self._stop_routes = threading.Event()
        self._threads: list[threading.Thread] = []
        self._router: threading.Thread | None = None
        self._token = self._status_queryable = None
        self._watchers: list = []  # liveliness subscribers: workers, claims, cameras
        self._kernels_loaded = False
        # a bug that fails every frame logged a traceback per frame, at the frame rate: one per
        # kind (per robot for a frame's processing) every log_interval, by the core's clock
        self._failures = RateLimitedLog(log, core.log_interval, core.clock)

    def __enter__(self) -> Worker:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def load_kernels(self) -> None:
        """Compile the model's kernels (its own preset's: the others' are not run), or load
        them from numba's cache; once. :meth:`start` calls it; a process may call it first,
        while an interrupt still stops it (``asnn worker``: a cold compile takes under a
        minute, and Ctrl-C meanwhile should not wait for it)."""
        if self.core.model != "asnn" or self._kernels_loaded:
            return
        # a cold numba cache takes under a minute: frames waiting that long would all be
        # dropped, and a worker silent that long looks hung
        log.info("worker %s: loading the model's kernels (compiling them takes under a "
                 "minute where numba has no cache yet)", self.core.worker_id)
        from asnn.warmup import compile_kernels  # the model's: not ``asnn status``'s

        started = time.monotonic()
        compile_kernels((self.core.params,))
        self._kernels_loaded = True
        log.info("worker %s: kernels ready in %.1f s", self.core.worker_id,
                 time.monotonic() - started)

    def check_id(self) -> None:
        """Raise :class:`WorkerIdTaken` if a live worker has this worker's id already: called
        before :meth:`load_kernels` (a minute of compiling on a fresh install, for a worker
        that cannot join), and by :meth:`start` again for one that joined meanwhile."""
        prefix, me = self.core.prefix, self.core.worker_id
        if self.shared and me in live_workers(self.session, prefix):
            raise WorkerIdTaken(f"worker id {me!r} is already live under {prefix!r}")

    def start(self) -> None:
        """Compile the model's kernels (:meth:`load_kernels`), learn the fleet (live workers, claims, announced
        cameras), join it, subscribe to this worker's robots, then take frames.

        Raises
        ------
        WorkerIdTaken
            If a live worker already has this id (two workers with one id would both serve the
            same robots).
        """
        self.load_kernels()
        prefix, me = self.core.prefix, self.core.worker_id
        if self.shared:
            # the fleet first, so that no frame is taken while this worker thinks it is alone
            others = live_workers(self.session, prefix)
            if me in others:
                raise WorkerIdTaken(f"worker id {me!r} is already live under {prefix!r}")
            for worker in others:
                self.membership.add(worker)
            for worker, robot in fleet_claims(self.session, prefix):
                self.routes.claim(worker, robot, True)
            for robot in announced_cameras(self.session, prefix):
                self.routes.camera(robot, True)
            self.core.owns, self.core.answers = self.routes.takes, self._answers
            liveliness = self.session.liveliness()
            self._watchers = [
                liveliness.declare_subscriber(keys.worker_tokens(prefix), self._on_worker,
                                              history=True),
                liveliness.declare_subscriber(keys.claims(prefix), self._on_claim, history=True),
                liveliness.declare_subscriber(keys.camera_tokens(prefix), self._on_camera,
                                              history=True)]
            self._token = liveliness.declare_token(keys.worker_token_key(me, prefix))
        self._status_queryable = self.session.declare_queryable(
            keys.worker_status_key(me, prefix), self._on_status_query)
        self._threads = [threading.Thread(target=self._run, daemon=True,
                                          name=f"asnn-worker-{i}") for i in range(self.threads)]
        for thread in self._threads:
            thread.start()
        self._route()  # this worker's subscriptions before start() returns
        self._router = threading.Thread(target=self._run_routes, daemon=True, name="asnn-routes")
        self._router.start()
        log.info("worker %s: %s/%s on %s; workers %s", me, self.core.model,
                 self.core.preset or "-", prefix, self.membership.live())

    # ------------------------------------------------------------------ the fleet

    def _on_worker(self, sample: zenoh.Sample) -> None:
        try:
            worker = keys.parse_worker_token(str(sample.key_expr), self.core.prefix)
        except keys.KeySchemeError:
            return
        if sample.kind == zenoh.SampleKind.DELETE:
            changed = self.membership.remove(worker)
        else:
            changed = self.membership.add(worker)
        if changed:
            log.info("workers now %s", self.membership.live())
            self._changed.set()
            self.core.notify()

    def _on_claim(self, sample: zenoh.Sample) -> None:
        try:
            worker, robot = keys.parse_claim(str(sample.key_expr), self.core.prefix)
        except keys.KeySchemeError:
            return
        if self.routes.claim(worker, robot, sample.kind != zenoh.SampleKind.DELETE):
            self._changed.set()

    def _on_camera(self, sample: zenoh.Sample) -> None:
        try:
            robot = keys.parse_camera_token(str(sample.key_expr), self.core.prefix)
        except keys.KeySchemeError:
            return
        if self.routes.camera(robot, sample.kind != zenoh.SampleKind.DELETE):
            self._changed.set()

    def _on_status_query(self, query: zenoh.Query) -> None:
        try:
            status = self.core.status()
            status["instance"] = self._instance
            status["workers"] = self.membership.live()
            status["traffic"] = self.traffic()
            status["routes"] = self.routes.counts()
            status["scan"] = {"interval": self.scan_interval, "window": self.scan_window,
                              "subscribed": self._catch_all is not None}
            for robot, info in status["robots"].items():
                info["route"] = self.routes.role(robot)
            query.reply(keys.worker_status_key(self.core.worker_id, self.core.prefix),
                        encode_status(status))
        except Exception:
            log.exception("status query failed")

    # ------------------------------------------------------------------ frames in

    def _count(self, size: int, scanned: bool) -> None:
        with self._traffic_lock:
            self._traffic["frames"] += 1
            self._traffic["bytes"] += size
            if scanned:
                self._traffic["scanned_frames"] += 1
                self._traffic["scanned_bytes"] += size

    def traffic(self) -> dict[str, int]:
        """Frame messages Zenoh delivered to this worker, and their bytes: all of them, and those
        that came through the scan (``<prefix>/*/frame``) rather than a robot's own
        subscription."""
        with self._traffic_lock:
            return dict(self._traffic)

    def _on_frame(self, sample: zenoh.Sample) -> None:
        """A frame on a robot's own subscription."""
        try:
            payload = sample.payload.to_bytes()
            self._count(len(payload), scanned=False)
            self.core.offer(str(sample.key_expr), payload)
        except Exception:  # never let a bug in one message kill the subscriber
            self._failures.exception("frame-in", "unexpected error on a frame from %s",
                                     sample.key_expr)

    def _on_scanned_frame(self, sample: zenoh.Sample) -> None:
        """A frame on ``<prefix>/*/frame``: a robot nobody knows yet is adopted."""
        try:
            key = str(sample.key_expr)
            try:
                robot = keys.parse_key(key, self.core.prefix)[0]
            except keys.KeySchemeError:
                robot = None  # the core counts it (bad-key)
            if robot in self._subscriptions:
                return  # its own subscription delivers it too
            payload = sample.payload.to_bytes()
            self._count(len(payload), scanned=True)
            if self.core.offer(key, payload) is not None and self.routes.adopt(robot):
                log.info("robot %s: found by its frames (its camera does not announce it)", robot)
                self._changed.set()
        except Exception:
            self._failures.exception("scanned-frame-in", "unexpected error on a frame from %s",
                                     sample.key_expr)

    def _answers(self, robot: str) -> bool:
        """Whether a robot's frame is answered: it is served (or being released), or this
        worker is warming up to take it over and this frame made it warm. The previous owner
        may see the claim that follows before it answers that frame itself, so the new owner
        answers it (a frame may then be answered by both, never by neither)."""
        if self.routes.answers(robot):
            return True
        return self.routes.role(robot) == "warming" and self.core.warm(robot)

    # ------------------------------------------------------------------ routes

    def _route(self) -> None:
        """One pass: subscriptions, claims and model states after the routes' plan, then the
        scan subscription."""
        prefix = self.core.prefix
        with self._routes_lock:
            plan = self.routes.plan(self.core.views())
            for robot in plan.keys() - self._subscriptions.keys():
                self._subscriptions[robot] = self.session.declare_subscriber(
                    keys.frame_key(robot, prefix), _on_network_thread(self._on_frame))
                # which robots a worker serves, in its log as well as in its status
                log.info("robot %s: subscribed to its frames", robot)
            for robot in self._subscriptions.keys() - plan.keys():
                _undeclare(self._subscriptions.pop(robot))
                log.info("robot %s: unsubscribed from its frames", robot)
            if self.shared:
                claims = {robot for robot, route in plan.items() if route.claim}
                for robot in claims - self._claims.keys():
                    self._claims[robot] = self.session.liveliness().declare_token(
                        keys.claim_key(self.core.worker_id, robot, prefix))
                for robot in self._claims.keys() - claims:
                    _undeclare(self._claims.pop(robot))
            for robot in self.core.release_unowned():
                log.info("robot %s: handed over to %s", robot, self.routes.membership.owner(robot))
            self._drop_outlets()
            self._update_scan(time.monotonic())

    def _update_scan(self, now: float) -> None:
        """Subscribe to every robot's frames while alone, or during the scan windows of the
        scanning worker; not while leaving."""
        if not self.shared or self.routes.alone():
            wanted = True
        elif self.scan_interval and self.routes.scanner():
            if now >= self._scan_next:
                self._scan_until, self._scan_next = now + self.scan_window, now + self.scan_interval
            wanted = now < self._scan_until
        else:
            wanted = False
        if wanted and self._catch_all is None:
            self._catch_all = self.session.declare_subscriber(
                keys.frames(self.core.prefix), _on_network_thread(self._on_scanned_frame))
        elif not wanted and self._catch_all is not None:
            self._release("_catch_all")

    def _run_routes(self) -> None:
        """Follow the fleet: route passes, idle robots, the counters in the log."""
        last_stats = last_evict = time.monotonic()
        last_twin_check = last_stats - TWIN_CHECK_S + 1.0  # the first a second after start
        while not self._stop_routes.is_set():
            self._changed.wait(ROUTE_TICK)
            self._changed.clear()
            now = time.monotonic()
            if now - last_evict >= 1.0:
                last_evict = now
                self.core.evict_idle()
                self._tell_refusals()
            try:
                self._route()
            except Exception:  # e.g. the session closing under us
                if not self._stop_routes.is_set():
                    log.exception("routing pass failed")
            if self.stats_every and now - last_stats >= self.stats_every:
                last_stats = now
                log.info("stats %s; frames in %s", self.core.stats(), self.traffic())
            if now - last_twin_check >= TWIN_CHECK_S:
                last_twin_check = now
                self._check_twins()

    def _check_twins(self) -> None:
        """Ask this worker's own status key who answers (the replies come on Zenoh's thread):
        another process answering for this id was started where this one had gone silent (a
        hang past the lease) or with the same ``--id`` on another host, and both serve the same
        robots, every frame answered twice. Logged at ERROR, once per check (every
        :data:`TWIN_CHECK_S` seconds) while it lasts; ``asnn status`` lists both."""
        with self._twin_lock:
            self._twin_check += 1
        try:
            self.session.get(keys.worker_status_key(self.core.worker_id, self.core.prefix),
                             self._on_twin_reply, target=zenoh.QueryTarget.ALL,
                             timeout=TWIN_CHECK_S / 2, consolidation=zenoh.ConsolidationMode.NONE)
        except Exception:  # e.g. the session closing under us
            if not self._stop_routes.is_set():
                log.exception("checking this worker's id failed")

    def _on_twin_reply(self, reply) -> None:
        try:
            if reply.ok is None:
                return
            status = decode_status(reply.ok.payload.to_bytes())
        except Exception:  # anything may answer on the key: only a worker's status counts
            return
        instance = status.get("instance")
        if (status["worker"] != self.core.worker_id or not isinstance(instance, str)
                or instance == self._instance):
            return
        with self._twin_lock:  # anyone on the prefix may answer, as often as it likes
            if self._twin_logged == self._twin_check:
                return
            self._twin_logged = self._twin_check
        uptime = status.get("uptime_s")
        shown = "".join(c if c.isprintable() else "?" for c in instance[:40])
        log.error("worker id %s is also answered by another process (instance %s%s): both "
                  "serve the same robots and every frame is answered twice; stop one of them",
                  self.core.worker_id, shown, f", up {uptime:.0f} s"
                  if isinstance(uptime, (int, float)) and math.isfinite(uptime) else "")

    def _tell_refusals(self) -> None:
        """Tell each robot refused since the last call why, on ``<prefix>/<robot>/refused``
        (best effort: a notice, not data)."""
        for robot, reason, detail, count in self.core.refusals_to_tell():
            try:  # the core keeps reason and detail within the Refusal's bounds
                notice = Refusal(robot=robot, worker=self.core.worker_id[:MAX_NOTE_LEN],
                                 reason=reason, detail=detail, count=count)
                self.session.put(keys.refusal_key(robot, self.core.prefix), encode(notice),
                                 **REFUSAL_QOS)
            except Exception:  # e.g. the session closing under us; the status keeps it
                if not self._stop_routes.is_set():
                    log.exception("robot %s: telling it its frames are refused failed", robot)

    # ------------------------------------------------------------------ processing

    def _run(self) -> None:
        """Process frames (at a lower priority than the threads that move messages)."""
        _lower_priority(COMPUTE_NICENESS)
        while not self._stop.is_set():
            job = self.core.take(timeout=0.2)
            if job is not None:
                self._step(job)

    def _step(self, job: Job) -> None:
        """Process one job taken from the core and publish its response; never raises."""
        try:
            response = self.core.process(job, publish=self.publish)
            if response is None and self.routes.role(job.robot) == "warming":
                self._changed.set()  # it may be warm now: claim it
        except Exception:  # a bug (publishing, a callback): the thread goes on
            self._failures.exception(f"frame-failed:{job.robot}", "robot %s: frame %d failed",
                                     job.robot, job.frame.seq)

    def _drop_outlets(self) -> None:
        """Undeclare the publishers of robots the core no longer tracks (evicted, handed over)."""
        with self._outlets_lock:
            # the robots tracked read under the lock (publish() never holds the core's): read
            # before, a robot tracked and answered in between lost the publishers it had just
            # declared, as one no longer tracked, and a put on them failed its response
            tracked = set(self.core.robots())
            gone = [r for r in self._outlets if r not in tracked]
            outlets = [self._outlets.pop(r) for r in gone]
        for outlet in outlets:
            outlet.undeclare()

    def publish(self, response: Response) -> None:
        """Put a response (and, for a collision, the warning)."""
        with self._outlets_lock:
            outlets = self._outlets.get(response.robot)
            if outlets is None:
                outlets = self._outlets[response.robot] = _Outlets(self.session, response.robot,
                                                                   self.core.prefix)
        payload = encode(response)
        outlets.response.put(payload)
        if response.collision:
            outlets.warning.put(payload)
        if self.on_response is not None:
            self.on_response(response)

    def idle(self) -> bool:
        """True when no frame is waiting or being processed."""
        return self.core.backlog() == 0

    # ------------------------------------------------------------------ stopping

    def _release(self, *names: str) -> None:
        """Undeclare the named entities of this worker, once each."""
        for name in names:
            entity = getattr(self, name)
            setattr(self, name, None)
            if entity is not None:
                _undeclare(entity)

    def _hand_over(self) -> None:
        """Answer the robots this worker serves until their new owners claim them (warm), at
        most ``handover_timeout`` seconds. Robots without a frame for :data:`STALE_AFTER`
        seconds are not waited for: no new owner can warm up on them."""
        deadline = time.monotonic() + self.handover_timeout
        while True:
            views = self.core.views()
            now = self.core.clock()
            waiting = [r for r in list(self._subscriptions)
                       if self.routes.role(r) == "releasing" and r in views
                       and now - views[r].last_seen < STALE_AFTER]
            if not waiting or not self.membership.others():
                return
            if time.monotonic() >= deadline:
                log.warning("stopping before %d robots were taken over: %s", len(waiting),
                            ", ".join(sorted(waiting)[:20]))
                return
            time.sleep(ROUTE_TICK)

    def close(self) -> None:
        """Leave the fleet and stop. The worker token goes first, so the other workers compute
        the robots' new owners, which warm up on their frames; meanwhile this worker answers
        them, until each is claimed (at most ``handover_timeout``); then everything is
        undeclared."""
        if self._token is not None:
            self._release("_token")
            self.membership.leave()
            self._changed.set()
            self._hand_over()
        self._stop_routes.set()
        if self._router is not None:
            self._router.join(timeout=30)
            self._router = None
        self._release("_catch_all")
        for robot in list(self._subscriptions):
            _undeclare(self._subscriptions.pop(robot))
        self._stop.set()
        self.core.notify()
        for thread in self._threads:
            thread.join(timeout=30)
        self._threads = []
        for robot in list(self._claims):
            _undeclare(self._claims.pop(robot))
        self._release("_status_queryable")
        for watcher in self._watchers:
            _undeclare(watcher)
        self._watchers = []
        with self._outlets_lock:
            outlets, self._outlets = list(self._outlets.values()), {}
        for outlet in outlets:
            outlet.undeclare()
