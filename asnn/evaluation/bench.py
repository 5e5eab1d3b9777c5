"""Per-frame cost of the models (``asnn bench``).

Every model and ASNN preset runs on a generated scene (:func:`asnn.stimuli.make_scene`,
``looming_over_stripes``: a looming disk over translating stripes, so that every stage and the
clustering have work to do) at each size, one thread: :func:`pin_threads` sets OpenCV's thread
count and the OpenMP / BLAS / numba variables to 1 before anything is timed. Each frame is timed
with ``time.perf_counter`` around ``step``, targets included; the first ``warmup`` frames (the
first one only primes the state) are not counted. The numba kernels are compiled, or loaded from
numba's cache, before anything is timed (:func:`asnn.warmup.compile_kernels`): some are first
called only on a later frame (the clustering on the first frame with attended pixels), and that
call would otherwise be timed as a step of 10 ms or more. The same run
times the straightforward float64 form (``ASNN(params, optimised=False)``) of the default preset
and reports the speed-up as a ratio of medians. The default preset's cost against the published
variant (``vs_published``) is measured a second way as well, with the two stepped in turn over
the same frames (:func:`time_in_turn`), since timed one after the other their ratio moves with
the machine's slower and faster moments. With a case of the labelled suite instead
(``asnn bench --case NAME``), the models run on its frames: a drive, where the stages that act
only under the camera's own forward motion (the motion layers) have work.
"""

from __future__ import annotations

import os
import platform
import time

import numpy as np

__all__ = ["THREAD_VARIABLES", "pin_threads", "machine", "time_detector", "time_in_turn", "run"]

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
DEFAULT_SIZES = ((128, 128), (320, 240), (640, 480))
SCENE = "looming_over_stripes"
TURN_ROUNDS = 3  # passes over the clip of the default and the published variant stepped in turn
# pixels of the generated clip, which is drawn at once (in float64, some 26 bytes a pixel while
# drawn): at most 60 frames at 1920x1080, as the paper's scenes at the largest size (3 GB)
MAX_CLIP_PIXELS = 60 * 1920 * 1080


def pin_threads() -> str:
    """One thread everywhere; returns a description for the report.

    The environment variables apply fully only before NumPy's BLAS is loaded; the ``asnn bench``
    command calls this first thing. Numba's pool is set with ``numba.set_num_threads`` (its kernels
    here are not parallel anyway): setting ``NUMBA_NUM_THREADS`` after numba has started its
    threads makes every later compilation fail.
    """
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    import cv2

    cv2.setNumThreads(1)
    try:
        import numba

        numba.set_num_threads(1)
    except (ImportError, ValueError):
        pass
    # NumPy, imported by then, keeps its BLAS pool (no BLAS call is timed): the variables
    # reach the processes started from here
    return ("cv2.setNumThreads(1); numba.set_num_threads(1); "
            + ", ".join(f"{n}=1" for n in THREAD_VARIABLES) + " for the processes it starts")


def machine() -> dict:
    """CPU model, logical cores and library versions."""
    import cv2
    import numba

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "opencv": cv2.__version__, "numba": numba.__version__}


def time_detector(make, frames: np.ndarray, warmup: int = 2) -> np.ndarray:
    """Seconds per ``step`` of a fresh detector over ``frames``, after ``warmup`` frames."""
    detector = make()
    times = []
    for i, frame in enumerate(frames):
        start = time.perf_counter()
        detector.step(frame)
        elapsed = time.perf_counter() - start
        if i >= warmup:
            times.append(elapsed)
    return np.array(times)


def time_in_turn(makes, frames: np.ndarray, warmup: int = 2) -> list[np.ndarray]:
    """Seconds per ``step`` of fresh detectors stepped in turn over the same frames.

    Every detector takes frame ``i`` before any takes frame ``i + 1``, and the one that goes
    first changes from frame to frame, so that a slower moment of the machine, and the order,
    fall on all of them alike: their ratio is then measured side by side. Each detector's state
    leaves the processor's caches while the others step, so each step costs more than in
    :func:`time_detector`, where one detector runs alone (as a worker serving several cameras
    runs it).

    Returns
    -------
    list of ndarray
        Per detector, in the order of ``makes``, the seconds of its steps after ``warmup``.
    """
    detectors = [make() for make in makes]
    times: list[list[float]] = [[] for _ in detectors]
    n = len(detectors)
    for i, frame in enumerate(frames):
        for k in range(n):
            j = (i + k) % n
            start = time.perf_counter()
            detectors[j].step(frame)
            elapsed = time.perf_counter() - start
            if i >= warmup:
                times[j].append(elapsed)
    return [np.array(t) for t in times]


def _stats(seconds: np.ndarray) -> dict:
    ms = seconds * 1e3
    return {"median_ms": float(np.median(ms)), "p90_ms": float(np.percentile(ms, 90)),
            "frames": int(len(ms))}


def _state_bytes(model) -> int:
    """Bytes of per-stream state of an ASNN after a few frames (cascades, previous frame, and
    in a dim, noisy view the temporal summation's running average), each array once."""
    summation = getattr(model, "_summation", None)
    arrays = [getattr(model, name, None) for name in ("stages_on", "stages_off", "previous")]
    arrays += [getattr(summation, "average", None), *getattr(model, "history", [])]
    # the running average is the previous frame itself unless the brightness compensation
    # scaled it: counted by identity, not twice
    unique = {id(a): a for a in arrays if isinstance(a, np.ndarray)}
    return sum(a.nbytes for a in unique.values())


PUBLISHED = "reference32"  # the published variant in float32: the default before `robust`


def _check_clip_pixels(sizes, frames: int, warmup: int) -> None:
    """ValueError if a clip of ``frames`` timed frames after ``warmup`` at one of ``sizes``
    would be larger than :data:`MAX_CLIP_PIXELS`: it is drawn at once, before a frame is
    timed."""
    for w, h in sizes:
        if (frames + warmup) * w * h > MAX_CLIP_PIXELS:
            most = MAX_CLIP_PIXELS // (w * h) - warmup
            raise ValueError(f"{frames} frames at {w}x{h} are more than the bench draws at "
                             f"once: at most {most} at that size")


def _preset_params(names: list[str] | None) -> dict:
    """Each preset to time, by the name its row gets: a preset's key (:func:`preset_key`), or a
    spec with changed fields (``robust/top_k=0``, as the command line writes it) mapped to its
    parameters. ``None``: every preset."""
    from ..params import PRESETS, preset_key
    from .runs import DetectorSpec, parse_detector

    if names is None:
        return {name: name for name in PRESETS}
    timed = {}
    for name in names:
        if "/" not in name:
            key = preset_key(name)
            timed.setdefault(key, key)
            continue
        spec = parse_detector(f"asnn:{name}")
        # named by the preset's key, as a plain name is: default/top_k=0 is robust/top_k=0
        spec = DetectorSpec("asnn", preset_key(spec.preset or "default"), spec.overrides)
        timed.setdefault(spec.name.removeprefix("asnn:"), spec.params)
    return timed


def run(sizes=DEFAULT_SIZES, frames: int = 40, presets: list[str] | None = None,
        models: tuple[str, ...] | None = None, straightforward: bool = True,
        progress=None, case: str | None = None, repeat: int = 1) -> dict:
    """Time every model and preset at every size; returns the report as a dict.

    With ``case``, a case of the labelled suite (:func:`asnn.stimuli.suite.make_case`) is the
    clip instead of the generated scene, at its own size and length (``sizes`` and ``frames``
    are not used): a driving scene, where the stages that act only while the scene expands
    under the camera's own motion have work to do.

    ``models`` are names of :data:`asnn.detectors.MODELS` (None: all). ``presets`` are names
    of :func:`asnn.params.preset` (``None``: all), each optionally with fields changed after
    slashes as a detector spec has them (``robust/top_k=0``: a stage's cost is the difference
    of its two rows, timed in one run). With ``straightforward``,
    the default preset is timed too, since the straightforward form's ratio is against it.
    Whenever the default preset is timed, the published variant in float32 (``reference32``,
    the default before the robust preset) is timed with it, and the default's row carries
    what the robust additions cost: ``vs_published``, the ratio of their median times stepped
    in turn (:func:`time_in_turn`, :data:`TURN_ROUNDS` passes over the clip, pooled), and
    ``vs_published_apart``, the ratio of the two rows' medians (each timed alone). With
    ``repeat`` > 1 the comparison in turn is made that many times, each with fresh detectors:
    ``vs_published_runs`` holds every ratio and ``vs_published`` is their median, so that the
    spread a machine's slower and faster moments give the ratio is measured in one command.

    Raises
    ------
    ValueError
        If a preset name or field is unknown, ``repeat`` is below 1, or a generated clip would
        have more than :data:`MAX_CLIP_PIXELS` pixels.
    """
    if repeat < 1:
        raise ValueError(f"repeat must be at least 1, not {repeat}")
    from ..detectors import MODELS, make_detector
    from ..model import ASNN
    from ..warmup import compile_kernels
    from ..params import DEFAULT_PRESET
    from ..stimuli import make_scene

    models = MODELS if models is None else models
    timed_params = _preset_params(presets)
    presets = list(timed_params)
    if straightforward and "asnn" in models and DEFAULT_PRESET not in presets:
        presets.append(DEFAULT_PRESET)  # the straightforward form's ratio is against it
    if DEFAULT_PRESET in presets and PUBLISHED not in presets:
        presets.append(PUBLISHED)  # the default's cost is reported against it
    warmup = 2  # the first frame only primes the state
    if case is None:
        _check_clip_pixels(sizes, frames, warmup)
    if "asnn" in models:
        # every preset timed (compile_kernels' own default is the default and reference: a
        # float32 preset without the robust additions, paper or reference32, calls float32
        # kernels neither of those does, and a fresh install timed their compiling)
        compile_kernels([timed_params.get(name, name) for name in presets],
                        straightforward=straightforward)
    rows = []
    if case is not None:
        from ..stimuli.suite import make_case

        clips = [make_case(case).frames]
        frames = len(clips[0]) - warmup
    else:
        clips = (make_scene(SCENE, size=(w, h), frames=frames + warmup, start=2,
                            stop=max(3, frames + warmup - 2)).frames for w, h in sizes)
    for clip in clips:
        h, w = clip.shape[1:3]

        def add(model: str, preset: str, form: str, make):
            if progress:
                progress(f"{w}x{h} {model} {preset or '-'} {form}")
            row = {"size": f"{w}x{h}", "model": model, "preset": preset, "form": form,
                   **_stats(time_detector(make, clip, warmup))}
            if model == "asnn":
                probe = make()
                for f in clip[:2]:
                    probe.step(f)
                row["state_mb"] = _state_bytes(probe) / 2**20
            rows.append(row)
            return row

        for model in models:
            if model != "asnn":
                add(model, "", "optimised", lambda m=model: make_detector(m, None))
                continue
            timed = {name: add("asnn", name, "optimised",
                               lambda n=timed_params.get(name, name): ASNN(n))
                     for name in presets}
            if DEFAULT_PRESET in timed and DEFAULT_PRESET != PUBLISHED:
                row = timed[DEFAULT_PRESET]
                row["vs_published_apart"] = row["median_ms"] / timed[PUBLISHED]["median_ms"]
                if progress:
                    progress(f"{w}x{h} asnn {DEFAULT_PRESET} and {PUBLISHED} in turn")
                ratios = []
                for _ in range(repeat):
                    rounds = [time_in_turn((lambda: ASNN(DEFAULT_PRESET),
                                            lambda: ASNN(PUBLISHED)), clip, warmup)
                              for _ in range(TURN_ROUNDS)]
                    default, published = (np.concatenate(t) for t in zip(*rounds))
                    ratios.append(float(np.median(default) / np.median(published)))
                row["vs_published"] = float(np.median(ratios))
                if repeat > 1:
                    row["vs_published_runs"] = ratios
        if straightforward and "asnn" in models:
            slow = add("asnn", DEFAULT_PRESET, "straightforward",
                       lambda: ASNN(DEFAULT_PRESET, optimised=False))
            fast = next(r for r in rows if r["size"] == f"{w}x{h}" and r["model"] == "asnn"
                        and r["preset"] == DEFAULT_PRESET and r["form"] == "optimised")
            slow["speedup"] = slow["median_ms"] / fast["median_ms"]
    return {"scene": case or SCENE, "frames": frames, "warmup": warmup,
            "default_preset": DEFAULT_PRESET, "results": rows}


def format_table(report: dict) -> str:
    """The report as a Markdown table."""
    lines = ["| size | model | preset | form | median ms | p90 ms | state MiB | note |",
             "| --- | --- | --- | --- | ---: | ---: | ---: | --- |"]
    for r in report["results"]:
        note = f"{r['speedup']:.1f}x slower than optimised (timed apart)" if "speedup" in r else ""
        if "vs_published" in r:
            runs = r.get("vs_published_runs")
            spread = (f", median of {len(runs)} runs, {min(runs):.2f}-{max(runs):.2f}x"
                      if runs else "")
            note = (f"{r['vs_published']:.2f}x the time of {PUBLISHED} stepped in turn"
                    f"{spread} ({r['vs_published_apart']:.2f}x timed apart)")
        state = f"{r['state_mb']:.2f}" if "state_mb" in r else ""
        lines.append(f"| {r['size']} | {r['model']} | {r['preset'] or '-'} | {r['form']} | "
                     f"{r['median_ms']:.2f} | {r['p90_ms']:.2f} | {state} | {note} |")
    return "\n".join(lines)
