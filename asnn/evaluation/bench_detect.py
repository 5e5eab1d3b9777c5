"""Per-frame cost of the whole ``asnn detect`` process, and of its stages (``asnn bench --detect``).

For each size, a generated clip of ``frames`` frames (mp4v: ``looming_over_stripes``, the disk
growing over 50 frames, played forwards then backwards, again and again, as ``asnn bench
--service`` plays it) and a clip of its first two frames are written to a temporary directory,
and ``asnn detect CLIP --jsonl OUT`` runs as its own process ``repeat`` times on each. The
per-frame cost is (median time on the long clip - median time on the short one) / (frames - 2):
the start-up (interpreter, imports, the kernels loaded from numba's cache, opening the file)
cancels out. Where the long clip's median is not longer than the short one's by more than the
short runs' own spread (too few frames for the start-up's noise), the per-frame cost is not
measured: ``None``, "n/a" in the table (:func:`per_frame_ms`). One untimed run on the short clip comes first: ``asnn detect`` has numba use
512-bit vectors where the processor has them (``cli/main.py``), so the first such process
compiles its kernels. The process uses the machine's cores as ``asnn detect`` does: the model
computes each frame's fused pass in bands on a thread per core and finishes each frame while
the next one's pass runs (:meth:`asnn.model.ASNN.stream`), decoding and writing in between.

The same run, in this process, times each stage of one loop over the same frames, decoding
them again for each pass and keeping none (:func:`time_stages`): **decode** (the source's
frames, in a pass of their own), **model** (the detector's step without the targets),
**targets** (the targets inside the step: the clustering, :func:`asnn.targets.extract_targets`,
or with ``targets='objects'`` the objects, their looming fits, the tracker and the approach
gate, ``ASNN._objects``; timed by wrapping them where the model calls them) and **output**
(formatting and writing the JSON lines); their sum is what the loop costs on one thread.
**stream** is the model alone over the clip's first decoded frames (up to
:data:`STREAM_BYTES`) with the threads ``asnn detect`` gives it. The baseline is the
straightforward float64 form of the same preset (``ASNN(preset, optimised=False)``) stepping
over one period of the same loop on one thread, as ``asnn bench`` times it: its mean step (the
per-frame costs of both forms depend on the frames' content, so they are compared over the
same frames), timed once between each pair of processes and taken as the median, like the
processes' times. ``identical`` says whether the process's JSON lines equal those of one loop
over the same frames here.

The clip's content matters: on frames where a large region has been still for a few seconds
(the disk of a long clip near its end, a camera that stops), the default preset's float32
cascades decay into subnormal numbers, which the processor handles slowly, and its step costs
several times as much (README, Performance). The looping clip stays clear of that.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .bench import SCENE, THREAD_VARIABLES

__all__ = ["DEFAULT_SIZES", "DEFAULT_FRAMES", "STREAM_BYTES", "run", "per_frame_ms", "format_table",
           "time_stages"]

DEFAULT_SIZES = ((320, 240), (640, 480))
# frames of the long clip: a spread of 0.1 s in the processes' start-up (as on a shared virtual
# machine) moves the per-frame figure by 0.08 ms over 1198 frames, by 0.34 ms over 298
DEFAULT_FRAMES = 1200
STREAM_BYTES = 256 * 2**20  # decoded frames the stream stage holds at most


def _detect_seconds(command: Sequence[str], clip: Path, out: Path, preset: str | None) -> float:
    """Wall-clock seconds of one ``asnn detect CLIP --jsonl OUT`` process."""
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    args = [*command, "detect", str(clip), "--jsonl", str(out)]
    if preset:
        args += ["--preset", preset]
    start = time.perf_counter()
    proc = subprocess.run(args, env=env, capture_output=True, text=True, timeout=1800)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"asnn detect failed: {proc.stderr.strip()[-500:]}")
    return elapsed


@contextlib.contextmanager
def _timed_targets(totals: list[float]):
    """Add the seconds spent in the model's targets (``extract_targets``, or the objects stage
    ``ASNN._objects`` of ``targets='objects'``) to ``totals[0]``."""
    from .. import model

    def timed(original):
        def call(*args, **kwargs):
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                totals[0] += time.perf_counter() - start
        return call

    # (owner, name) of each call timed: one renamed must fail here, not read 0 s in the column
    places = [(model, "extract_targets"), (model.ASNN, "_objects")]
    missing = [name for owner, name in places if not hasattr(owner, name)]
    if missing:
        raise AttributeError(f"the targets' time cannot be measured: the model has no "
                             f"{', '.join(missing)}")
    originals = [getattr(owner, name) for owner, name in places]
    for (owner, name), original in zip(places, originals):
        setattr(owner, name, timed(original))
    try:
        yield
    finally:
        for (owner, name), original in zip(places, originals):
            setattr(owner, name, original)


def time_stages(clip: Path, preset: str | None, out: Path) -> tuple[dict, list[dict]]:
    """Milliseconds per frame of each stage of one loop over ``clip``, and of the model's
    stream with a thread per core (``stream``), and the loop's records.

    Each pass decodes the clip again and drops each frame once it is done with it, as
    ``asnn detect`` does: the 1200 frames held at once would take 1.1 GB at 640x480, and
    timing them would time the memory's first touch. The stream is timed over the clip's first
    frames, up to :data:`STREAM_BYTES` of them, kept from the loop's pass.
    """
    from ..detectors import available_cores, make_detector
    from ..io.sources import open_source

    start = time.perf_counter()
    for _ in open_source(str(clip)).timed_frames():
        pass
    decode = time.perf_counter() - start
    detector = make_detector("asnn", preset)
    targets = [0.0]
    step = output = 0.0
    records, held, size = [], [], 0
    with _timed_targets(targets), open(out, "w", encoding="utf-8") as fh:
        for index, (t, frame) in enumerate(open_source(str(clip)).timed_frames()):
            size += frame.nbytes
            if not held or size <= STREAM_BYTES:
                held.append((t, frame))
            start = time.perf_counter()
            response = detector.step(frame, t)
            stepped = time.perf_counter()
            record = response.record(index, t)
            fh.write(json.dumps(record) + "\n")
            output += time.perf_counter() - stepped
            step += stepped - start
            records.append(record)
    with make_detector("asnn", preset, threads=available_cores()) as model:
        start = time.perf_counter()
        for _ in model.stream(held):
            pass
        stream = (time.perf_counter() - start) / len(held)
    n = len(records)
    ms = {"decode": decode / n, "model": (step - targets[0]) / n, "targets": targets[0] / n,
          "output": output / n, "stream": stream}
    return {k: 1e3 * v for k, v in ms.items()}, records


def _straightforward_ms(frames: np.ndarray, preset: str | None) -> float:
    """Mean milliseconds of the straightforward float64 step over ``frames`` (after the first,
    which only primes the state), on one OpenCV thread."""
    import cv2

    from ..model import ASNN
    from ..params import preset as make_preset
    from .bench import time_detector

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        params = make_preset(preset or "default")
        seconds = time_detector(lambda: ASNN(params, optimised=False), frames, warmup=1)
    finally:
        cv2.setNumThreads(threads)
    return float(np.mean(seconds) * 1e3)


def _loop(size: tuple[int, int]) -> np.ndarray:
    """One period of the bench clip's frames: the scene forwards, then backwards (no jump)."""
    from ..stimuli import make_scene

    scene = make_scene(SCENE, size=size, frames=50, start=2, stop=48).frames
    return np.concatenate([scene, scene[-2:0:-1]])


def _clip(loop: np.ndarray, frames: int):
    """The bench clip's ``frames`` frames, one by one: the loop again and again."""
    return (loop[i % len(loop)] for i in range(frames))


def per_frame_ms(long_runs: Sequence[float], short_runs: Sequence[float],
                 frames: int) -> float | None:
    """Milliseconds per frame from the processes' seconds on the long clip (``frames``
    frames) and on the two-frame one: the difference of their medians over ``frames - 2``.
    None where that difference is not above the spread of the short runs (the start-up's
    noise): with few frames it can even come out negative."""
    extra = float(np.median(long_runs) - np.median(short_runs))
    if extra <= float(np.ptp(short_runs)) or extra <= 0:
        return None
    return extra / (frames - 2) * 1e3


def run(command: Sequence[str], sizes=DEFAULT_SIZES, frames: int = DEFAULT_FRAMES,
        repeat: int = 4, preset: str | None = None, progress=None) -> dict:
    """Time ``asnn detect`` at every size; the report as a dict (see the module notes).
    ``command`` is the command line that runs ``asnn`` (the command-line layer gives it).

    Raises
    ------
    ValueError
        For fewer than 10 frames or an unknown preset.
    RuntimeError
        If ``asnn detect`` fails.
    """
    from ..warmup import compile_kernels
    from ..params import DEFAULT_PRESET, preset_key
    from ..io.video import write_video

    if frames < 10:
        raise ValueError(f"--detect needs at least 10 frames, got {frames}")
    name = preset_key(preset) if preset else DEFAULT_PRESET
    compile_kernels(straightforward=True)  # its baseline steps the straightforward form
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for w, h in sizes:
            if progress:
                progress(f"{w}x{h}")
            loop = _loop((w, h))
            # the baseline's frames: one period of the clip's loop (and the frame that primes)
            baseline_frames = np.stack(list(_clip(loop, min(frames, len(loop) + 1))))
            long_clip, short_clip = tmp / f"{w}x{h}.mp4", tmp / f"{w}x{h}-2.mp4"
            write_video(_clip(loop, frames), long_clip, fps=25.0)
            write_video(_clip(loop, 2), short_clip, fps=25.0)
            out = tmp / "detect.jsonl"
            # untimed: numba's cache may hold no kernels yet for the process's CPU features
            _detect_seconds(command, short_clip, tmp / "short.jsonl", preset)
            long_runs, short_runs, baselines = [], [], []
            for _ in range(repeat):
                # the baseline between the processes, so that a spell in which the machine is
                # slower (another virtual machine on the host) weighs on both sides alike
                long_runs.append(_detect_seconds(command, long_clip, out, preset))
                baselines.append(_straightforward_ms(baseline_frames, preset))
                short_runs.append(_detect_seconds(command, short_clip, tmp / "short.jsonl", preset))
            produced = [json.loads(line) for line in out.read_text().splitlines()]
            stages, records = time_stages(long_clip, preset, tmp / "loop.jsonl")
            per_frame = per_frame_ms(long_runs, short_runs, frames)
            baseline = float(np.median(baselines))
            rows.append({
                "size": f"{w}x{h}", "frames": frames, "repeat": repeat,
                "detect_ms": per_frame, "startup_s": float(np.median(short_runs)),
                "stages_ms": stages,
                "loop_ms": float(sum(v for k, v in stages.items() if k != "stream")),
                "straightforward_ms": baseline,
                "ratio": None if per_frame is None else baseline / per_frame,
                "identical": produced == json.loads(json.dumps(records))})
    return {"scene": SCENE, "preset": name, "results": rows,
            "baseline": f"ASNN({name!r}, optimised=False) on the same frames, one thread, "
                        "mean step, median of one timing between each pair of processes"}


def format_table(report: dict) -> str:
    """The report as a Markdown table."""
    lines = ["| size | asnn detect ms/frame | decode | model | targets | output | one loop | "
             "model stream | straightforward ms | detect / straightforward | identical |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
    unmeasured = False
    for r in report["results"]:
        s = r["stages_ms"]
        if r["detect_ms"] is None:
            unmeasured = True
            detect, ratio = "n/a", "n/a"
        else:
            detect, ratio = f"{r['detect_ms']:.2f}", f"1/{r['ratio']:.1f}"
        lines.append(f"| {r['size']} | {detect} | {s['decode']:.2f} | "
                     f"{s['model']:.2f} | {s['targets']:.2f} | {s['output']:.3f} | "
                     f"{r['loop_ms']:.2f} | {s['stream']:.2f} | {r['straightforward_ms']:.1f} | "
                     f"{ratio} | {'yes' if r['identical'] else 'NO'} |")
    if unmeasured:
        lines.append("\nn/a: the longer clip took no longer than the start-up's own spread; "
                     "give more --frames (the stages are timed all the same)")
    return "\n".join(lines)
