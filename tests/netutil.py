"""Helpers of the networked tests: child ``asnn`` processes, a router config with a short lease,
a response collector and a frame publisher thread."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from service import keys
from service.messages import Frame, decode_response, encode

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 30.0

# what the reliability tests use (and deploy/zenoh/*.json5): no scouting, a 1 s lease
SHORT_LEASE = ("{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } },"
               " transport: { link: { tx: { lease: 1000, keep_alive: 4 } } } }")


def wait_for(predicate, timeout=TIMEOUT, what="condition", step=0.02):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(step)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


class Proc:
    """A child ``asnn`` process whose output is drained by threads into lists; with
    ``program=()``, the Python script that ``args`` begin with."""

    def __init__(self, *args, env=None, program=("-m", "cli.main")):
        env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
        env.pop("RUST_LOG", None)
        self.args = args
        self.popen = subprocess.Popen([sys.executable, *program, *args], cwd=ROOT,
                                      env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True)
        self.out, self.err = [], []
        self.threads = [threading.Thread(target=self._drain, args=(s, lines), daemon=True)
                        for s, lines in ((self.popen.stdout, self.out),
                                         (self.popen.stderr, self.err))]
        for thread in self.threads:
            thread.start()

    @staticmethod
    def _drain(stream, lines):
        for line in stream:
            lines.append(line.rstrip("\n"))

    def wait_line(self, text, stream="err", timeout=TIMEOUT):
        lines = self.err if stream == "err" else self.out
        wait_for(lambda: any(text in line for line in lines) or self.popen.poll() is not None,
                 timeout=timeout, what=f"{text!r} from {self.args[0]}")
        assert any(text in line for line in lines), "\n".join(self.err[-30:])

    def stop(self, sig=signal.SIGINT, timeout=TIMEOUT):
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
        try:
            code = self.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            code = self.popen.wait()
        for thread in self.threads:
            thread.join(timeout=5)
        return code

    def kill(self):
        if self.popen.poll() is None:
            self.popen.kill()
        self.popen.wait()


class Procs:
    """Starts processes and kills whatever is still running at the end (use as a fixture)."""

    def __init__(self):
        self.started: list[Proc] = []

    def __call__(self, *args, **kwargs) -> Proc:
        self.started.append(Proc(*args, **kwargs))
        return self.started[-1]

    def cleanup(self):
        for proc in self.started:
            proc.kill()
            for thread in proc.threads:
                thread.join(timeout=5)


class Fleet:
    """``asnn router``, ``asnn worker --id w1`` and ``asnn alerts --json`` as OS processes on a free
    loopback port, as in the compose topology; ``common`` are the client options for more parts."""

    def __init__(self, procs: Procs, tmp_path: Path, config_text: str):
        from service.demo import free_port

        self.config = tmp_path / "zenoh.json5"
        self.config.write_text(config_text)
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.common = ["--config", str(self.config), "--connect", self.endpoint,
                       "--mode", "client"]
        self.procs = procs
        self.router = self.start_router()
        self.worker = procs("worker", "--id", "w1", *self.common)
        self.alerts = procs("alerts", "--json", *self.common)
        self.worker.wait_line("ready", timeout=60)
        self.alerts.wait_line("listening on")

    def start_router(self) -> Proc:
        router = self.procs("router", "--listen", self.endpoint, "--config", str(self.config))
        router.wait_line("listening on")
        return router


class Responses:
    """Every response of every robot from a plain subscriber, with its arrival time."""

    def __init__(self, session, prefix="asnn"):
        self.items: list[tuple[float, object]] = []
        self.invalid = 0
        self.lock = threading.Lock()
        self.sub = session.declare_subscriber(keys.responses(prefix), self._on)

    def _on(self, sample):
        try:
            response = decode_response(sample.payload.to_bytes())
        except Exception:
            with self.lock:
                self.invalid += 1
            return
        with self.lock:
            self.items.append((time.monotonic(), response))

    def since(self, t0: float, robot: str | None = None) -> list:
        with self.lock:
            return [r for t, r in self.items if t >= t0 and (robot is None or r.robot == robot)]

    def answered(self, seq: int, robot: str) -> bool:
        """Whether any worker has answered frame ``seq`` of ``robot``."""
        with self.lock:
            return any(r.seq == seq and r.robot == robot for _, r in self.items)

    def first_after(self, t0: float, robot: str, worker: str) -> float | None:
        with self.lock:
            return next((t for t, r in self.items
                         if t >= t0 and r.robot == robot and r.worker == worker), None)

    def count(self) -> int:
        with self.lock:
            return len(self.items)


class FramePump:
    """A thread putting frames of several robots at ``fps`` each until stopped."""

    def __init__(self, session, robots, fps=20.0, size=(64, 64), prefix="asnn"):
        self.session, self.robots, self.period = session, list(robots), 1.0 / fps
        rng = np.random.default_rng(1)
        self.images = [rng.integers(0, 256, size=size[::-1], dtype=np.uint8) for _ in range(8)]
        self.prefix = prefix
        self.sent = dict.fromkeys(self.robots, 0)
        self.stop_event = threading.Event()
        self.publishers = {r: session.declare_publisher(keys.frame_key(r, prefix))
                           for r in self.robots}
        self.thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop_event.set()
        self.thread.join(timeout=10)

    def _run(self):
        seq = 0
        next_time = time.monotonic()
        while not self.stop_event.is_set():
            for robot in self.robots:
                frame = Frame.from_image(self.images[seq % len(self.images)], seq=seq,
                                         stamp=time.time())
                try:
                    self.publishers[robot].put(encode(frame))
                except Exception:  # the session closes under us at the end of a test
                    return
                self.sent[robot] += 1
            seq += 1
            next_time += self.period
            delay = next_time - time.monotonic()
            if delay > 0:
                self.stop_event.wait(delay)
            else:
                next_time = time.monotonic()


class AnnouncedCameras:
    """Cameras that announce themselves (``<prefix>/@camera/<robot>``, as ``asnn camera`` does)
    and publish bursts of frames with blocking congestion control, so that none is lost on the
    way and every count can be exact."""

    def __init__(self, session, robots, size=(64, 64), prefix="asnn"):
        import zenoh

        self.robots, self.prefix = list(robots), prefix
        rng = np.random.default_rng(2)
        self.images = [rng.integers(0, 256, size=size[::-1], dtype=np.uint8) for _ in range(8)]
        self.tokens = [session.liveliness().declare_token(keys.camera_token_key(r, prefix))
                       for r in self.robots]
        self.publishers = {r: session.declare_publisher(
            keys.frame_key(r, prefix), congestion_control=zenoh.CongestionControl.BLOCK)
            for r in self.robots}
        self.seq = 0
        self.sent_bytes = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for entity in [*self.publishers.values(), *self.tokens]:
            try:
                entity.undeclare()
            except Exception:
                pass

    def matched(self) -> bool:
        """Every camera's frames have a subscriber (its worker)."""
        return all(p.matching_status.matching for p in self.publishers.values())

    def burst(self, frames: int, fps: float = 25.0, stamp=None) -> None:
        """``frames`` frames per camera at ``fps``; seq continues from the previous burst."""
        next_time = time.monotonic()
        for _ in range(frames):
            for robot in self.robots:
                frame = Frame.from_image(self.images[self.seq % len(self.images)], seq=self.seq,
                                         stamp=time.time() if stamp is None else stamp(self.seq))
                payload = encode(frame)
                self.publishers[robot].put(payload)
                self.sent_bytes += len(payload)
            self.seq += 1
            next_time += 1.0 / fps
            delay = next_time - time.monotonic()
            if delay > 0:
                time.sleep(delay)

    def answered(self, responses) -> bool:
        """Every camera's latest frame has been answered."""
        latest = {}
        for _, r in list(responses.items):
            latest[r.robot] = max(latest.get(r.robot, -1), r.seq)
        return all(latest.get(robot, -1) == self.seq - 1 for robot in self.robots)
