"""The ASNN worker on Zenoh: frames of every robot in, responses and warnings out.

Subscribes to ``<prefix>/*/frame`` (best-effort frames), runs :class:`~service.core.WorkerCore`
on a processing thread and publishes, for every processed frame, a Response on
``<prefix>/<robot>/response`` and, when ``collision`` is true, on ``<prefix>/<robot>/warning``.
Responses and warnings are reliable, with blocking congestion control and a higher priority than
frames. Warnings go through an advanced publisher that caches the robot's latest warning, so an
advanced subscriber that joins late (``clients.alerts``) receives it.

Several workers share the robots (:mod:`service.ownership`): each declares the liveliness token
``<prefix>/@worker/<id>``, watches the others' and serves only the robots that rendezvous hashing
gives it over the live set. A worker that stops withdraws its token first, so the others take its
robots at once; one that dies loses its token when the router sees its session close or its
lease expire. Each worker answers queries on ``<prefix>/@worker/<id>/status`` with a msgpack map
(:meth:`service.core.WorkerCore.status` plus the live workers).
"""

from __future__ import annotations

import logging
import os
import sys
import threading
import time

import zenoh
from zenoh.ext import CacheConfig, MissDetectionConfig, declare_advanced_publisher

from asnn.model import compile_kernels

from . import keys
from .core import WorkerCore
from .messages import Response, encode
from .ownership import Membership

__all__ = ["COMPUTE_NICENESS", "RESPONSE_QOS", "SWITCH_INTERVAL", "WARNING_QOS", "Worker",
           "WorkerIdTaken", "live_workers", "query_status", "tune_process"]

log = logging.getLogger("asnn.worker")

RESPONSE_QOS = dict(congestion_control=zenoh.CongestionControl.BLOCK,
                    priority=zenoh.Priority.DATA_HIGH, reliability=zenoh.Reliability.RELIABLE)
WARNING_QOS = dict(congestion_control=zenoh.CongestionControl.BLOCK,
                   priority=zenoh.Priority.INTERACTIVE_HIGH, reliability=zenoh.Reliability.RELIABLE)
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


def tune_process() -> None:
    """Process-wide settings for a worker process (the ``asnn worker`` command calls it).

    Parallelism comes from the processing threads, one robot each: OpenCV's own thread pool
    (for the attention blur) would only compete with them, so it is set to one thread; and the
    interpreter's switch interval is shortened to :data:`SWITCH_INTERVAL`.
    """
    import cv2

    cv2.setNumThreads(1)
    sys.setswitchinterval(SWITCH_INTERVAL)


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


class WorkerIdTaken(RuntimeError):
    """Another live worker already uses this worker id."""


def live_workers(session: zenoh.Session, prefix: str = keys.DEFAULT_PREFIX,
                 timeout: float = 2.0) -> list[str]:
    """Ids of the workers whose liveliness tokens are alive under ``prefix``."""
    found = set()
    for reply in session.liveliness().get(keys.worker_tokens(prefix), timeout=timeout):
        try:
            found.add(keys.parse_worker_token(str(reply.ok.key_expr), prefix))
        except Exception:  # an error reply, or a token that is not a worker's
            continue
    return sorted(found)


def query_status(session: zenoh.Session, prefix: str = keys.DEFAULT_PREFIX,
                 worker: str | None = None, timeout: float = 2.0) -> dict[str, dict]:
    """The status maps of one worker or (``worker=None``) of all, by worker id."""
    import msgpack

    key = keys.worker_status_key(worker, prefix) if worker else keys.worker_statuses(prefix)
    out = {}
    for reply in session.get(key, target=zenoh.QueryTarget.ALL, timeout=timeout,
                             consolidation=zenoh.ConsolidationMode.NONE):
        try:
            status = msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False)
            out[str(status["worker"])] = status
        except Exception:  # an error reply or a payload that is not a status map
            continue
    return out


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
    threads : int
        Processing threads. The model's kernels release the GIL, so each core can run one
        (:func:`service.core.default_threads`, with :func:`tune_process`); a robot is still
        processed by one thread at a time (:class:`WorkerCore`).
    """

    def __init__(self, session: zenoh.Session, core: WorkerCore, *, on_response=None,
                 stats_every: float = 30.0, shared: bool = True, threads: int = 1):
        if threads < 1:
            raise ValueError(f"a worker needs at least one processing thread, got {threads}")
        self.session = session
        self.core = core
        self.on_response = on_response
        self.stats_every = stats_every
        self.shared = shared
        self.membership = Membership(core.worker_id)
        self._outlets: dict[str, _Outlets] = {}
        self._outlets_lock = threading.Lock()
        self._stop = threading.Event()
        self.threads = threads
        self._threads: list[threading.Thread] = []
        self._subscriber = None
        self._token = None
        self._workers_sub = None
        self._status = None
        self._membership_changed = threading.Event()

    def __enter__(self) -> Worker:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:
        """Compile the model's kernels, join the live worker set, then take frames.

        Raises
        ------
        WorkerIdTaken
            If a live worker already has this id (two workers with one id would both serve the
            same robots).
        """
        if self.core.model == "asnn":
            # a cold numba cache takes seconds: frames waiting that long would all be dropped
            compile_kernels()
        prefix, me = self.core.prefix, self.core.worker_id
        if self.shared:
            # the live set first, so that no frame is taken while this worker thinks it is alone
            others = live_workers(self.session, prefix)
            if me in others:
                raise WorkerIdTaken(f"worker id {me!r} is already live under {prefix!r}")
            for worker in others:
                self.membership.add(worker)
            self.core.owns = self.membership.owns
            self._workers_sub = self.session.liveliness().declare_subscriber(
                keys.worker_tokens(prefix), self._on_worker, history=True)
            self._token = self.session.liveliness().declare_token(keys.worker_token_key(me,
                                                                                        prefix))
        self._status = self.session.declare_queryable(keys.worker_status_key(me, prefix),
                                                      self._on_status_query)
        self._threads = [threading.Thread(target=self._run, args=(i == 0,), daemon=True,
                                          name=f"asnn-worker-{i}") for i in range(self.threads)]
        for thread in self._threads:
            thread.start()
        self._subscriber = self.session.declare_subscriber(keys.frames(prefix), self._on_frame)
        log.info("worker %s: %s/%s on %s; workers %s", me, self.core.model,
                 self.core.preset or "-", keys.frames(prefix), self.membership.live())

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
            self._membership_changed.set()
            self.core.notify()

    def _on_status_query(self, query: zenoh.Query) -> None:
        import msgpack

        try:
            status = self.core.status()
            status["workers"] = self.membership.live()
            query.reply(keys.worker_status_key(self.core.worker_id, self.core.prefix),
                        msgpack.packb(status, use_bin_type=True))
        except Exception:
            log.exception("status query failed")

    def _on_frame(self, sample: zenoh.Sample) -> None:
        try:
            self.core.offer(str(sample.key_expr), sample.payload.to_bytes())
        except Exception:  # never let a bug in one message kill the subscriber
            log.exception("unexpected error on a frame from %s", sample.key_expr)

    def _run(self, housekeeping: bool) -> None:
        """Process frames; the first thread also follows membership, evicts and logs stats."""
        _lower_priority(COMPUTE_NICENESS)
        last_stats = last_evict = time.monotonic()
        while not self._stop.is_set():
            job = self.core.take(timeout=0.2)
            if job is not None:
                try:
                    response = self.core.process(job)
                    if response is not None:
                        self.publish(response)
                except Exception:
                    log.exception("robot %s: frame %d failed", job.robot, job.frame.seq)
            if not housekeeping:
                continue
            if self._membership_changed.is_set():
                self._membership_changed.clear()
                self.core.release_unowned()
                self._drop_outlets()
            now = time.monotonic()
            if now - last_evict >= 1.0:
                last_evict = now
                self.core.evict_idle()
                self.core.release_unowned()
                self._drop_outlets()
            if self.stats_every and now - last_stats >= self.stats_every:
                last_stats = now
                log.info("stats %s", self.core.stats())

    def _drop_outlets(self) -> None:
        """Undeclare the publishers of robots the core no longer tracks (evicted, handed over)."""
        tracked = set(self.core.robots())
        with self._outlets_lock:
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

    def _release(self, *names: str) -> None:
        """Undeclare the named entities of this worker, once each."""
        for name in names:
            entity = getattr(self, name)
            setattr(self, name, None)
            if entity is not None:
                _undeclare(entity)

    def close(self) -> None:
        """Stop taking frames, hand the robots over (the token goes first, so the other workers
        take them at once), finish the current frame, undeclare everything."""
        self._release("_subscriber", "_token")
        self._stop.set()
        self.core.notify()
        for thread in self._threads:
            thread.join(timeout=30)
        self._threads = []
        self._release("_status", "_workers_sub")
        with self._outlets_lock:
            outlets, self._outlets = list(self._outlets.values()), {}
        for outlet in outlets:
            outlet.undeclare()
