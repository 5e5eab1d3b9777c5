"""``asnn demo``: camera, worker and warning subscriber in one process.

Three Zenoh sessions talk over TCP loopback on a free port, with multicast scouting and gossip
off, so the demo needs no router, no well-known port and no network.
"""

from __future__ import annotations

import socket
import threading
import time

import zenoh

from .camera import Source, publish_frames
from .config import ZenohOptions, make_config
from .core import WorkerCore
from .worker import Worker

__all__ = ["DEMO_SCENE", "free_port", "loopback_options", "run_pipeline"]

#: The demo's default scene: a case of the labelled suite (:mod:`asnn.stimuli.suite`), a dark
#: disk coming at the camera at constant speed from frame 20 (it fills the view at frame 74 of
#: 77). Unlike the paper's ``looming`` (a radius growing by a pixel a frame, which no approach
#: at constant speed produces), its time to contact shrinks as a real approach's does.
DEMO_SCENE = "loom-dark-c1.0-d12-center"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def loopback_options(port: int) -> tuple[ZenohOptions, ZenohOptions]:
    """(hub, spoke) options: the hub listens on 127.0.0.1:port, spokes connect to it."""
    endpoint = f"tcp/127.0.0.1:{port}"
    hub = ZenohOptions(mode="peer", listen=(endpoint,), multicast_scouting=False, gossip=False)
    spoke = ZenohOptions(mode="peer", connect=(endpoint,), multicast_scouting=False, gossip=False)
    return hub, spoke


def run_pipeline(source: Source, core: WorkerCore, listener_factory, *, robot: str = "demo",
                 fps: float | None = None, format: str = "gray8", timeout: float = 10.0,
                 stop: threading.Event | None = None) -> dict:
    """Play ``source`` as robot ``robot`` through a worker running ``core``.

    ``listener_factory(session)`` declares the warning subscriber (a context manager with a
    ``received`` count); ``stop``, when set, ends the play and the waits for its answers (the
    reader of the warnings went away). Returns counters: frames published, responses,
    warnings sent and received.
    """
    stop = stop or threading.Event()
    hub, spoke = loopback_options(free_port())
    responses: list = []

    def on_response(response) -> None:
        responses.append(response)

    with zenoh.open(make_config(hub)) as worker_session, \
            zenoh.open(make_config(spoke)) as alerts_session, \
            zenoh.open(make_config(spoke)) as camera_session, \
            Worker(worker_session, core, on_response=on_response, stats_every=0) as worker, \
            listener_factory(alerts_session) as listener:
        published = publish_frames(camera_session, robot, source, prefix=core.prefix, fps=fps,
                                   format=format, wait=timeout, stop=stop)
        deadline = time.monotonic() + timeout
        # frames are best effort: stop waiting when the last one is answered or nothing moves
        while time.monotonic() < deadline and not stop.is_set():
            if responses and responses[-1].seq == published - 1 and worker.idle():
                break
            time.sleep(0.02)
        sent = sum(r.collision for r in responses)
        while listener.received < sent and time.monotonic() < deadline and not stop.is_set():
            time.sleep(0.02)
        return {"published": published, "responses": len(responses), "warnings": sent,
                "received": listener.received, "stats": core.stats()}
