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
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["DEFAULT_COUNTS", "camera_phases", "format_report", "model_time",
           "publish_cameras", "run", "summarise"]

DEFAULT_COUNTS = (1, 2, 4, 8, 12, 16, 20, 24)
SCENE = "looming_over_stripes"
ANSWERED = 0.95
START_S = 1.0


def model_time(preset: str | None, frames: np.ndarray) -> dict:
    """Median and p99 milliseconds of one detector step on ``frames`` (after two warm-up frames;
    the kernels are loaded first, as the worker does before it takes frames)."""
    from asnn.evaluation.bench import time_detector
    from asnn.detectors import make_detector
    from asnn.warmup import compile_kernels

    compile_kernels((preset or "default",))  # the preset timed, as the worker loads its own
    seconds = time_detector(lambda: make_detector("asnn", preset), frames, warmup=2)
    ms = seconds * 1e3
    return {"median_ms": float(np.median(ms)), "p99_ms": float(np.percentile(ms, 99))}


class _Process:
    """An ``asnn`` command in its own process (``command``, the command line that runs
    ``asnn``, then ``args``); ``ready`` is the stderr text that says it runs."""

    def __init__(self, command: Sequence[str], args: list[str], ready: str):
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        env.pop("RUST_LOG", None)
        self.popen = subprocess.Popen([*command, *args],
                                      env=env, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.PIPE, text=True)
        self.what, self.ready_text = args[0], ready
        self.lines: list[str] = []
        self._ready = threading.Event()
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self):
        for line in self.popen.stderr:
            self.lines.append(line.rstrip())
            if self.ready_text in line:
                self._ready.set()

    def wait_ready(self, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while not self._ready.wait(0.1):
            if self.popen.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the {self.what} did not start: "
                                   + " | ".join(self.lines[-5:]))

    def stop(self) -> None:
        if self.popen.poll() is None:
            self.popen.terminate()
            try:
                self.popen.wait(10)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait()


def _worker_args(worker_id: str, config: Path, preset: str | None,
                 threads: int | None) -> list[str]:
    args = ["worker", "--config", str(config), "--log-level", "warning", "--id", worker_id]
    if threads:
        args += ["--threads", str(threads)]
    if preset:
        args += ["--preset", preset]
    return args


class _Collector:
    """Every response on ``<prefix>/*/response``: (robot, seq, received wall time, stamp,
    model_ms, worker)."""

    def __init__(self, session, prefix: str):
        from . import keys
        from .messages import decode_response

        self._decode = decode_response
        self._lock = threading.Lock()
        self.records: list[tuple[str, int, float, float, float | None, str]] = []
        self._sub = session.declare_subscriber(keys.responses(prefix), self._on)

    def _on(self, sample) -> None:
        now = time.time()
        try:
            r = self._decode(bytes(sample.payload.to_bytes()))
        except Exception:
            return
        with self._lock:
            self.records.append((r.robot, r.seq, now, r.stamp, r.model_ms, r.worker))

    def take(self) -> list[tuple[str, int, float, float, float | None, str]]:
        with self._lock:
            records, self.records = self.records, []
        return records

    def close(self) -> None:
        self._sub.undeclare()


def summarise(records, sent: int, fps: float, model_ms: float,
              workers: Sequence[str] = ()) -> dict:
    """One step's figures (see the module notes) from its responses.

    Parameters
    ----------
    records : list of (robot, seq, received, stamp, model_ms or None[, worker])
        ``received`` and ``stamp`` in seconds (wall clock); ``worker`` the worker that answered
        (counted per worker in ``robots_per_worker``).
    sent : int
        Frames published.
    fps : float
        Camera rate (the backlog test allows two frame periods).
    model_ms : float
        Model time to subtract for a response that does not report its own.
    workers : sequence of str
        The workers' ids, so that one that answered no robot counts 0 in
        ``robots_per_worker`` (a 2/0 split is not shown as 2).
    """
    out = {"frames": sent, "responses": len(records),
           "answered": len(records) / sent if sent else 0.0}
    if not records:
        return {**out, "keeps_up": False}
    latency = np.array([(r[2] - r[3]) * 1e3 for r in records])
    added = latency - np.array([model_ms if r[4] is None else r[4] for r in records])
    stamps = np.array([r[3] for r in records])
    if all(len(r) > 5 for r in records):
        robots: dict[str, set] = {w: set() for w in workers}
        for r in records:
            robots.setdefault(r[5], set()).add(r[0])
        out["robots_per_worker"] = {w: len(rs) for w, rs in sorted(robots.items())}
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

    Camera i announces itself (``<prefix>/@camera/<robot>``, as ``asnn camera`` does) and
    publishes ``frames`` in a loop from frame ``i * len(frames) // n``, at ``fps``, its first
    frame ``phases[i]`` frame periods (0 <= phase < 1) after the start. A camera that falls more
    than a period behind (this thread was held up) skips ahead instead of bursting.
    """
    import heapq

    from . import keys
    from .camera import FRAME_QOS
    from .messages import Frame, encode

    n, period = len(robots), 1.0 / fps
    publishers = [session.declare_publisher(keys.frame_key(r, prefix), **FRAME_QOS)
                  for r in robots]
    tokens = [session.liveliness().declare_token(keys.camera_token_key(r, prefix))
              for r in robots]
    try:
        deadline = time.monotonic() + wait
        while (not all(p.matching_status.matching for p in publishers)
               and time.monotonic() < deadline):
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
        for entity in [*publishers, *tokens]:
            entity.undeclare()


def camera_phases(n: int, phases: str, seed: int = 0) -> np.ndarray:
    """Start phases of n cameras, in frame periods: ``"spread"`` (i / n) or ``"random"``."""
    if phases == "spread":
        return np.arange(n) / n
    if phases == "random":
        return np.random.default_rng(seed).uniform(0.0, 1.0, n)
    raise ValueError(f"phases must be 'spread' or 'random', got {phases!r}")


def _step(session, collector, n: int, step: int, frames, fps: float, seconds: float,
          model_ms: float, prefix: str, phases: str, seed: int, workers: Sequence[str]) -> dict:
    robots = [f"bench{step + 1}-{i}" for i in range(n)]
    collector.take()
    started = time.time()
    published = publish_cameras(session, robots, frames, fps, seconds,
                                camera_phases(n, phases, seed), prefix)
    time.sleep(0.5 + 2.0 / fps)  # the last responses
    records = [r for r in collector.take() if r[0] in published]
    report = {"cameras": n, **summarise(records, sum(published.values()), fps, model_ms,
                                        workers)}
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


def _worker_ids(workers: int) -> list[str]:
    return ["bench"] if workers == 1 else [f"bench-w{i + 1}" for i in range(workers)]


def _fleet(command: Sequence[str], tmp: Path, workers: int, router: bool, preset: str | None,
           threads: int | None, stack: contextlib.ExitStack):
    """Start the workers (and the router); the options of this process's session."""
    from .config import ZenohOptions
    from .demo import free_port, loopback_options

    config = tmp / "zenoh.json5"
    config.write_text("{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    processes = []
    if router:
        processes.append(_Process(command, ["router", "--listen", endpoint, "--config", str(config)],
                                  "listening on"))
        processes[0].wait_ready()
        where = ["--mode", "client", "--connect", endpoint]
        session = ZenohOptions(mode="client", connect=(endpoint,), multicast_scouting=False,
                               gossip=False)
    else:  # one worker, listening: the cameras and the collector connect to it
        where = ["--mode", "peer", "--listen", endpoint]
        session = loopback_options(int(endpoint.rsplit(":", 1)[1]))[1]
    for worker_id in _worker_ids(workers):
        processes.append(_Process(command, _worker_args(worker_id, config, preset, threads) + where,
                                  "ready"))
    for process in processes:
        stack.callback(process.stop)
    for process in processes:
        process.wait_ready()
    return session


def run(command: Sequence[str], size=(320, 240), fps: float = 25.0, seconds: float = 4.0,
        counts=None,
        preset: str | None = None, progress=None, worker_threads: int | None = None,
        phases: str = "spread", seed: int = 0, workers: int = 1,
        router: bool | None = None) -> dict:
    """Ramp the number of cameras; returns the report as a dict (see the module notes).

    ``command`` is the command line that runs ``asnn`` (the command-line layer gives it: this
    module does not know where it is installed), for the workers and the router.

    ``workers`` worker processes share the cameras, each with ``worker_threads`` processing
    threads (default: the cores divided among the workers). ``router``: put an ``asnn router``
    process between them and this process (default: only for several workers; one worker
    listens itself, peer to peer).
    """
    import zenoh

    from asnn.params import DEFAULT_PRESET
    from asnn.stimuli import make_scene

    from .config import make_config
    from .core import default_threads
    from .keys import DEFAULT_PREFIX
    from .worker import SWITCH_INTERVAL, live_workers

    counts = sorted(set(counts or DEFAULT_COUNTS))
    camera_phases(1, phases, seed)  # fail now on a bad value
    if workers < 1:
        raise ValueError(f"need at least one worker, got {workers}")
    router = workers > 1 if router is None else router
    threads = worker_threads or max(1, default_threads() // workers)
    w, h = size
    scene = make_scene(SCENE, size=(w, h), frames=50, start=2, stop=48).frames
    frames = np.concatenate([scene, scene[-2:0:-1]])  # forwards then backwards: no jump
    model = model_time(preset, frames)
    steps = []
    with _switch_interval(SWITCH_INTERVAL), tempfile.TemporaryDirectory() as tmp, \
            contextlib.ExitStack() as stack:
        options = _fleet(command, Path(tmp), workers, router, preset, threads, stack)
        with zenoh.open(make_config(options)) as session:
            deadline = time.monotonic() + 30
            while len(live_workers(session)) < workers and time.monotonic() < deadline:
                time.sleep(0.1)
            collector = _Collector(session, DEFAULT_PREFIX)
            try:
                # warm-up, not reported: the workers load their compiled kernels, the sessions
                # match
                ids = _worker_ids(workers)
                _step(session, collector, 2 * workers, -1, frames, fps, 1.5, model["median_ms"],
                      DEFAULT_PREFIX, phases, seed, ids)
                for step, n in enumerate(counts):
                    if progress:
                        progress(f"{n} cameras")
                    result = _step(session, collector, n, step, frames, fps, seconds,
                                   model["median_ms"], DEFAULT_PREFIX, phases, seed, ids)
                    steps.append(result)
                    if not result["keeps_up"]:
                        break
            finally:
                collector.close()
    if progress:
        progress("done\n")
    kept = [s["cameras"] for s in steps if s["keeps_up"]]
    best = max(kept) if kept else None
    best_step = next((s for s in steps if s["cameras"] == best), None)
    cores = os.cpu_count() or 1
    return {"size": f"{w}x{h}", "fps": fps, "seconds": seconds, "scene": SCENE,
            "preset": preset or DEFAULT_PRESET, "model_ms": model,
            "workers": workers, "worker_threads": threads, "cores": cores,
            "worker": (f"{workers} separate process{'es' if workers > 1 else ''}, {threads} "
                       f"processing thread{'s' if threads > 1 else ''} each"),
            "steady_state_after_s": START_S,
            "cameras": f"one thread, phases {phases}" + (f" (seed {seed})"
                                                          if phases == "random" else ""),
            "transport": ("tcp/127.0.0.1 through an asnn router process" if router else
                          "tcp/127.0.0.1, peer sessions") + ", no scouting, no gossip",
            "steps": steps, "max_cameras": best,
            "cameras_per_worker": best / workers if best else None,
            "cameras_per_core": best / cores if best else None,
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
              "| start: added p99 ms | keeps up | robots per worker |",
              "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | --- |"]
    for s in report["steps"]:
        lat = (f"{s['latency_p50_ms']:.1f} | {s['latency_p99_ms']:.1f} | {s['added_p99_ms']:.1f}"
               if "latency_p50_ms" in s else "- | - | -")
        start = s.get("start_added_p99_ms")
        start = "-" if start is None else f"{start:.1f}"
        split = "/".join(str(n) for n in s.get("robots_per_worker", {}).values()) or "-"
        lines.append(f"| {s['cameras']} | {s['frames']} | {100 * s['answered']:.1f} % | {lat} | "
                     f"{start} | {'yes' if s['keeps_up'] else 'no'} | {split} |")
    best = report["max_cameras"]
    if best is None:
        lines.append("largest number of cameras that keeps up: none")
    else:
        per = ""
        if report.get("cameras_per_core") is not None:
            per = (f"; {report['cameras_per_worker']:g} per worker on average, "
                   f"{report['cameras_per_core']:g} per core of {report['cores']}")
        lines.append(f"largest number of cameras that keeps up: {best} "
                     f"(steady-state p99 added latency {report['added_p99_ms_at_max']:.1f} ms"
                     f"{per})")
    return "\n".join(lines)
