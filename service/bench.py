"""``asnn bench --service``: how many cameras one worker process keeps up with, over Zenoh.

A worker runs as its own OS process (``asnn worker``, as deployed, with its default processing
threads unless ``worker_threads`` says otherwise), listening on a free TCP port on 127.0.0.1
with multicast scouting and gossip off. This process opens a peer session to it, warms it up
with one camera for 1.5 s (not reported) and, for N = 1, 2, 4, ... cameras, publishes N camera
streams for ``seconds`` while a subscriber collects every response. Each step uses new robot
names, so every camera starts a fresh stream.

The cameras
-----------
Deployed cameras run on the robots, not on the worker's machine; here they share its two
cores, so they must cost as little as possible. One thread plays all N: each camera has its
own publisher, ``seq`` and stamps, and publishes gray8 frames at ``fps`` on its own schedule.
Each loops over a generated scene played forwards then backwards (a loop without a jump, whose
first frame would be an artificial whole-frame change), from its own point of the loop, as
independent cameras do not all see an approach at the same moment.

``phases`` sets when, within a frame period, each camera publishes: ``"spread"`` evenly, the
arrangement that loads the worker most evenly; ``"random"`` uniformly at random (``seed``), as
free-running cameras drift into any arrangement over time. Random phases bunch some frames
together, and a frame then waits for the steps of the ones ahead of it.

Per step
--------
* answered: responses received / frames published;
* end-to-end latency: response received minus the frame's ``stamp`` (wall clock at publication;
  same machine, same clock);
* added latency: end-to-end minus the model's time for that frame, as the worker reports it in
  each response (``model_ms``, an optional Response field: docs/contract.md). The same detector
  on the same frames is also timed here, one thread (the report's ``model_ms``: median and
  p99), and its median stands in for a response without the field;
* the latency percentiles are those of the **steady state**: frames published after the
  step's first ``START_S`` seconds. In that first second all N cameras start within one frame
  period, and each new stream's first steps cost the worker several times a normal one (the
  model state is allocated and first touched); ``start_added_p99_ms`` reports that second
  separately;
* this process shortens the interpreter's switch interval as the worker does
  (:data:`service.worker.SWITCH_INTERVAL`), so that a response is not timed late because the
  camera thread held the GIL;
* keeps up: at least 95 % of the frames answered and no growing backlog (the median end-to-end
  latency of the step's last quarter is within 2 frame periods of its first quarter's).

The report's ``max_cameras`` is the largest N that keeps up (``None`` if even the first does
not); the ramp stops after the first step that does not.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

__all__ = ["DEFAULT_COUNTS", "camera_phases", "format_report", "model_time",
           "publish_cameras", "run", "summarise"]

DEFAULT_COUNTS = (1, 2, 4, 8, 12, 16, 20, 24)
SCENE = "looming_over_stripes"
ROOT = Path(__file__).resolve().parents[1]
ANSWERED = 0.95
START_S = 1.0


def model_time(size: tuple[int, int], preset: str | None, frames: np.ndarray) -> dict:
    """Median and p99 milliseconds of one detector step on ``frames`` (after two warm-up frames;
    the kernels are loaded first, as the worker does before it takes frames)."""
    from asnn.evaluation.bench import time_detector
    from asnn.detectors import make_detector
    from asnn.model import compile_kernels

    compile_kernels()
    seconds = time_detector(lambda: make_detector("asnn", preset), frames, warmup=2)
    ms = seconds * 1e3
    return {"median_ms": float(np.median(ms)), "p99_ms": float(np.percentile(ms, 99))}


class _WorkerProcess:
    """``asnn worker`` in its own process, listening on ``endpoint``."""

    def __init__(self, endpoint: str, config: Path, preset: str | None, threads: int | None):
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        env.pop("RUST_LOG", None)
        args = [sys.executable, "-m", "cli.main", "worker", "--listen", endpoint, "--mode", "peer",
                "--config", str(config), "--log-level", "warning", "--id", "bench"]
        if threads:
            args += ["--threads", str(threads)]
        if preset:
            args += ["--preset", preset]
        self.popen = subprocess.Popen(args, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.PIPE, text=True)
        self.lines: list[str] = []
        self._ready = threading.Event()
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self):
        for line in self.popen.stderr:
            self.lines.append(line.rstrip())
            if "ready" in line:
                self._ready.set()

    def wait_ready(self, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while not self._ready.wait(0.1):
            if self.popen.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("the worker did not start: " + " | ".join(self.lines[-5:]))

    def stop(self) -> None:
        if self.popen.poll() is None:
            self.popen.terminate()
            try:
                self.popen.wait(10)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()


class _Collector:
    """Every response on ``<prefix>/*/response``: (robot, seq, received wall time, stamp)."""

    def __init__(self, session, prefix: str):
        from . import keys
        from .messages import decode_response

        self._decode = decode_response
        self._lock = threading.Lock()
        self.records: list[tuple[str, int, float, float, float | None]] = []
        self._sub = session.declare_subscriber(keys.responses(prefix), self._on)

    def _on(self, sample) -> None:
        now = time.time()
        try:
            r = self._decode(bytes(sample.payload.to_bytes()))
        except Exception:
            return
        with self._lock:
            self.records.append((r.robot, r.seq, now, r.stamp, r.model_ms))

    def take(self) -> list[tuple[str, int, float, float, float | None]]:
        with self._lock:
            records, self.records = self.records, []
        return records

    def close(self) -> None:
        self._sub.undeclare()


def summarise(records, sent: int, fps: float, model_ms: float) -> dict:
    """One step's figures (see the module notes) from its responses.

    Parameters
    ----------
    records : list of (robot, seq, received, stamp, model_ms or None)
        ``received`` and ``stamp`` in seconds (wall clock).
    sent : int
        Frames published.
    fps : float
        Camera rate (the backlog test allows two frame periods).
    model_ms : float
        Model time to subtract for a response that does not report its own.
    """
    out = {"frames": sent, "responses": len(records),
           "answered": len(records) / sent if sent else 0.0}
    if not records:
        return {**out, "keeps_up": False}
    latency = np.array([(now - stamp) * 1e3 for _, _, now, stamp, _ in records])
    added = latency - np.array([model_ms if ms is None else ms for *_, ms in records])
    stamps = np.array([stamp for _, _, _, stamp, _ in records])
    span = stamps.max() - stamps.min()
    first = latency[stamps <= stamps.min() + span / 4]
    last = latency[stamps >= stamps.max() - span / 4]
    steady = stamps >= stamps.min() + START_S
    if not steady.any():  # a step shorter than the start: report it whole
        steady[:] = True
    out.update({
        "latency_p50_ms": float(np.median(latency[steady])),
        "latency_p99_ms": float(np.percentile(latency[steady], 99)),
        "added_p50_ms": float(np.median(added[steady])),
        "added_p99_ms": float(np.percentile(added[steady], 99)),
        "start_added_p99_ms": float(np.percentile(added[~steady], 99))
        if (~steady).any() else None,
        "first_quarter_p50_ms": float(np.median(first)),
        "last_quarter_p50_ms": float(np.median(last)),
    })
    growing = out["last_quarter_p50_ms"] > out["first_quarter_p50_ms"] + 2e3 / fps
    out["keeps_up"] = bool(out["answered"] >= ANSWERED and not growing)
    return out


def publish_cameras(session, robots: list[str], frames: np.ndarray, fps: float,
                    seconds: float, phases: np.ndarray, prefix: str,
                    wait: float = 2.0) -> dict[str, int]:
    """Play ``len(robots)`` cameras from this thread for ``seconds``; frames published per robot.

    Camera i publishes ``frames`` in a loop from frame ``i * len(frames) // n``, at ``fps``, its
    first frame ``phases[i]`` frame periods (0 <= phase < 1) after the start. A camera that
    falls more than a period behind (this thread was held up) skips ahead instead of bursting.
    """
    import heapq

    from . import keys
    from .camera import FRAME_QOS
    from .messages import Frame, encode

    n, period = len(robots), 1.0 / fps
    publishers = [session.declare_publisher(keys.frame_key(r, prefix), **FRAME_QOS)
                  for r in robots]
    try:
        deadline = time.monotonic() + wait
        while not all(p.matching_status for p in publishers) and time.monotonic() < deadline:
            time.sleep(0.05)
        sent = [0] * n
        start = time.monotonic() + period
        end = start + seconds
        due = [(start + phases[i] * period, i) for i in range(n)]
        heapq.heapify(due)
        while due[0][0] < end:
            at, i = heapq.heappop(due)
            now = time.monotonic()
            if at > now:
                time.sleep(at - now)
            elif now - at > period:
                at = now
            image = frames[(i * len(frames) // n + sent[i]) % len(frames)]
            publishers[i].put(encode(Frame.from_image(image, seq=sent[i], stamp=time.time())))
            sent[i] += 1
            heapq.heappush(due, (at + period, i))
        return dict(zip(robots, sent))
    finally:
        for p in publishers:
            p.undeclare()


def camera_phases(n: int, phases: str, seed: int = 0) -> np.ndarray:
    """Start phases of n cameras, in frame periods: ``"spread"`` (i / n) or ``"random"``."""
    if phases == "spread":
        return np.arange(n) / n
    if phases == "random":
        return np.random.default_rng(seed).uniform(0.0, 1.0, n)
    raise ValueError(f"phases must be 'spread' or 'random', got {phases!r}")


def _step(session, collector, n: int, step: int, frames, fps: float, seconds: float,
          model_ms: float, prefix: str, phases: str, seed: int) -> dict:
    robots = [f"bench{step + 1}-{i}" for i in range(n)]
    collector.take()
    started = time.time()
    published = publish_cameras(session, robots, frames, fps, seconds,
                                camera_phases(n, phases, seed), prefix)
    time.sleep(0.5 + 2.0 / fps)  # the last responses
    records = [r for r in collector.take() if r[0] in published]
    report = {"cameras": n, **summarise(records, sum(published.values()), fps, model_ms)}
    report["wall_s"] = time.time() - started
    return report


@contextlib.contextmanager
def _switch_interval(seconds: float):
    before = sys.getswitchinterval()
    sys.setswitchinterval(seconds)
    try:
        yield
    finally:
        sys.setswitchinterval(before)


def run(size=(320, 240), fps: float = 25.0, seconds: float = 4.0, counts=None,
        preset: str | None = None, progress=None, worker_threads: int | None = None,
        phases: str = "spread", seed: int = 0) -> dict:
    """Ramp the number of cameras; returns the report as a dict (see the module notes)."""
    import zenoh

    from asnn.params import DEFAULT_PRESET
    from asnn.stimuli import make_scene

    from .config import make_config
    from .core import default_threads
    from .demo import free_port, loopback_options
    from .keys import DEFAULT_PREFIX
    from .worker import SWITCH_INTERVAL

    counts = sorted(set(counts or DEFAULT_COUNTS))
    camera_phases(1, phases, seed)  # fail now on a bad value
    w, h = size
    scene = make_scene(SCENE, size=(w, h), frames=50, start=2, stop=48).frames
    frames = np.concatenate([scene, scene[-2:0:-1]])  # forwards then backwards: no jump
    model = model_time(size, preset, frames)
    port = free_port()
    hub, spoke = loopback_options(port)
    steps = []
    with _switch_interval(SWITCH_INTERVAL), tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "zenoh.json5"
        config.write_text("{ scouting: { multicast: { enabled: false }, "
                          "gossip: { enabled: false } } }")
        worker = _WorkerProcess(f"tcp/127.0.0.1:{port}", config, preset, worker_threads)
        try:
            worker.wait_ready()
            with zenoh.open(make_config(spoke)) as session:
                collector = _Collector(session, DEFAULT_PREFIX)
                try:
                    # warm-up, not reported: the worker loads its compiled kernels, the
                    # sessions match
                    _step(session, collector, 1, -1, frames, fps, 1.5, model["median_ms"],
                          DEFAULT_PREFIX, phases, seed)
                    for step, n in enumerate(counts):
                        if progress:
                            progress(f"{n} cameras")
                        result = _step(session, collector, n, step, frames, fps, seconds,
                                       model["median_ms"], DEFAULT_PREFIX, phases, seed)
                        steps.append(result)
                        if not result["keeps_up"]:
                            break
                finally:
                    collector.close()
        finally:
            worker.stop()
    if progress:
        progress("done\n")
    kept = [s["cameras"] for s in steps if s["keeps_up"]]
    best = max(kept) if kept else None
    best_step = next((s for s in steps if s["cameras"] == best), None)
    return {"size": f"{w}x{h}", "fps": fps, "seconds": seconds, "scene": SCENE,
            "preset": preset or DEFAULT_PRESET, "model_ms": model,
            "worker": f"separate process, {worker_threads or default_threads()} processing "
                      "thread(s)",
            "steady_state_after_s": START_S,
            "cameras": f"one thread, phases {phases}" + (f" (seed {seed})"
                                                          if phases == "random" else ""),
            "transport": "tcp/127.0.0.1, peer sessions, no scouting, no gossip",
            "steps": steps, "max_cameras": best,
            "added_p99_ms_at_max": best_step.get("added_p99_ms") if best_step else None}


def format_report(report: dict) -> str:
    """The report as text: a header and a Markdown table of the steps."""
    m = report.get("machine", {})
    lines = []
    if m:
        lines.append(f"# asnn bench --service: {m['cpu']}, {m['cores']} logical cores")
    lines += [f"# {report['size']} at {report['fps']:g} fps per camera, {report['seconds']:g} s "
              f"per step, preset {report['preset']}, worker in a {report['worker']}; "
              f"cameras: {report.get('cameras', 'one thread')}; {report['transport']}",
              f"# model time per frame (one thread, this process): median "
              f"{report['model_ms']['median_ms']:.2f} ms, p99 {report['model_ms']['p99_ms']:.2f} ms",
              f"# latencies of the steady state: frames published after each step's first "
              f"{report.get('steady_state_after_s', START_S):g} s (the start column: that "
              f"first second, all streams new)",
              "| cameras | frames | answered | latency p50 ms | latency p99 ms | added p99 ms "
              "| start: added p99 ms | keeps up |",
              "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
    for s in report["steps"]:
        lat = (f"{s['latency_p50_ms']:.1f} | {s['latency_p99_ms']:.1f} | {s['added_p99_ms']:.1f}"
               if "latency_p50_ms" in s else "- | - | -")
        start = s.get("start_added_p99_ms")
        start = "-" if start is None else f"{start:.1f}"
        lines.append(f"| {s['cameras']} | {s['frames']} | {100 * s['answered']:.1f} % | {lat} | "
                     f"{start} | {'yes' if s['keeps_up'] else 'no'} |")
    best = report["max_cameras"]
    if best is None:
        lines.append("largest number of cameras that keeps up: none")
    else:
        lines.append(f"largest number of cameras that keeps up: {best} "
                     f"(steady-state p99 added latency {report['added_p99_ms_at_max']:.1f} ms)")
    return "\n".join(lines)
