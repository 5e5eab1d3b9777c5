"""The ASNN worker on Zenoh: frames of every robot in, responses and warnings out.

Subscribes to ``<prefix>/*/frame`` (best-effort frames), runs :class:`~service.core.WorkerCore`
on a processing thread and publishes, for every processed frame, a Response on
``<prefix>/<robot>/response`` and, when ``collision`` is true, on ``<prefix>/<robot>/warning``.
Responses and warnings are reliable, with blocking congestion control and a higher priority than
frames. Warnings go through an advanced publisher that caches the robot's latest warning, so an
advanced subscriber that joins late (``clients.alerts``) receives it.
"""

from __future__ import annotations

import logging
import threading
import time

import zenoh
from zenoh.ext import CacheConfig, MissDetectionConfig, declare_advanced_publisher

from . import keys
from .core import WorkerCore
from .messages import Response, encode

__all__ = ["RESPONSE_QOS", "WARNING_QOS", "Worker"]

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


class _Outlets:
    """The two publishers of one robot."""

    def __init__(self, session: zenoh.Session, robot: str, prefix: str):
        self.response = session.declare_publisher(keys.response_key(robot, prefix), **RESPONSE_QOS)
        self.warning = declare_advanced_publisher(
            session, keys.warning_key(robot, prefix), cache=CacheConfig(max_samples=1),
            publisher_detection=True, sample_miss_detection=MISS_DETECTION, **WARNING_QOS)

    def undeclare(self) -> None:
        for pub in (self.response, self.warning):
            try:
                pub.undeclare()
            except Exception:  # the session may already be closed
                pass


class Worker:
    """Runs a :class:`WorkerCore` on a Zenoh session (use as a context manager, or start/close).

    Parameters
    ----------
    session : zenoh.Session
    core : WorkerCore
    on_response : callable, optional
        Called with every published Response (for the demo and tests).
    """

    def __init__(self, session: zenoh.Session, core: WorkerCore, *, on_response=None,
                 stats_every: float = 30.0):
        self.session = session
        self.core = core
        self.on_response = on_response
        self.stats_every = stats_every
        self._outlets: dict[str, _Outlets] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._subscriber = None

    def __enter__(self) -> Worker:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:
        prefix = self.core.prefix
        self._thread = threading.Thread(target=self._run, name="asnn-worker", daemon=True)
        self._thread.start()
        self._subscriber = self.session.declare_subscriber(keys.frames(prefix), self._on_frame)
        log.info("worker %s: %s/%s on %s", self.core.worker_id, self.core.model,
                 self.core.preset or "-", keys.frames(prefix))

    def _on_frame(self, sample: zenoh.Sample) -> None:
        try:
            self.core.offer(str(sample.key_expr), sample.payload.to_bytes())
        except Exception:  # never let a bug in one message kill the subscriber
            log.exception("unexpected error on a frame from %s", sample.key_expr)

    def _run(self) -> None:
        last_stats = last_evict = time.monotonic()
        while not self._stop.is_set():
            job = self.core.take(timeout=0.2)
            if job is not None:
                try:
                    response = self.core.process(job)
                    if response is not None:
                        self.publish(response.model_copy(
                            update={"latency_ms": self.core.latency_ms(job)}))
                except Exception:
                    log.exception("robot %s: frame %d failed", job.robot, job.frame.seq)
            now = time.monotonic()
            if now - last_evict >= 1.0:
                last_evict = now
                for robot in self.core.evict_idle():
                    outlets = self._outlets.pop(robot, None)
                    if outlets is not None:
                        outlets.undeclare()
            if self.stats_every and now - last_stats >= self.stats_every:
                last_stats = now
                log.info("stats %s", self.core.stats())

    def publish(self, response: Response) -> None:
        """Put a response (and, for a collision, the warning)."""
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

    def close(self) -> None:
        """Stop taking frames, finish the current one, undeclare everything."""
        if self._subscriber is not None:
            self._subscriber.undeclare()
            self._subscriber = None
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
            self._thread = None
        for outlets in self._outlets.values():
            outlets.undeclare()
        self._outlets.clear()
