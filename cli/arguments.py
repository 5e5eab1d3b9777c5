"""Argument types shared by several sub-commands.

The parser is built by every command, the router's too: what a type checks against that lives
beside the model or the evaluation (OpenCV, numba) is imported when the type is called, as
:func:`preset_spec` does."""

from __future__ import annotations

import argparse
import math

from asnn.params import MAX_THREADS  # --threads
from service import keys

# --frames: 10000 frames, over 8 minutes at 20 a second; a generated clip is held at once
MAX_FRAMES = 10_000
# --jobs, --workers: processes of about 100 MB each, all started at once (a pool of 10000 forked
# processes filled the machine for one case)
MAX_PROCESSES = 64
# durations given by hand (timeouts, waits): 11 days; Python's waits overflow past 9.2e9 s and
# Zenoh took 1e20 s for a negative timeout
MAX_SECONDS = 1e6
# --cameras of the service bench: as many robots as a worker takes by default (--max-robots)
MAX_CAMERAS = 256


class Joined(argparse.Action):
    """A comma-separated list option given more than once: the uses add up (``--cases 'a-*'
    --cases 'b-*'`` is ``--cases 'a-*,b-*'``; it kept the last alone). A str value is joined
    with commas, a list one (its type's result) extended without repeats. The first use
    replaces the default."""

    def __call__(self, parser, namespace, values, option_string=None):
        marker = f"_{self.dest}_given"
        before = getattr(namespace, self.dest) if getattr(namespace, marker, False) else None
        setattr(namespace, marker, True)
        if before is None:
            joined = values
        elif isinstance(values, list):
            joined = before + [v for v in values if v not in before]
        else:
            joined = f"{before},{values}"
        setattr(namespace, self.dest, joined)


def nonempty_path(value: str) -> str:
    """A file or folder name, not empty: an empty one would be taken as no output at all, or
    as the current folder."""
    if not value:
        raise argparse.ArgumentTypeError("an empty path")
    return value


def host_address(value: str) -> str:
    """An address to serve on: not empty (an empty one served on every interface, where the
    default is this machine only) and without spaces."""
    if not value or value != value.strip() or " " in value:
        raise argparse.ArgumentTypeError(f"not an address to serve on: {value!r} (127.0.0.1 "
                                         "for this machine, 0.0.0.0 for every interface)")
    return value


def frame_size(text: str) -> tuple[int, int]:
    """``WxH`` (or ``N`` for NxN) as (width, height); at least 32x32, a round size just above
    the smallest frame the model takes (31x31, ``ASNNParams.min_side``), and at most 1920x1080,
    the largest the suite's scenes are rendered at (a generated clip is held at once)."""
    try:
        w, _, h = text.lower().partition("x")
        size = (int(w), int(h or w))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    from asnn.stimuli.suite import LARGEST_SIZE

    if min(size) < 32:
        raise argparse.ArgumentTypeError(f"frames must be at least 32x32, got {text!r}")
    largest = LARGEST_SIZE
    if size[0] > largest[0] or size[1] > largest[1]:
        raise argparse.ArgumentTypeError(
            f"frames must be at most {largest[0]}x{largest[1]}, got {text!r}")
    return size


def port(value: str) -> int:
    """A TCP port number, 0..65535 (0: a free one)."""
    try:
        number = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {value!r}") from None
    if not 0 <= number <= 65535:
        raise argparse.ArgumentTypeError(f"not a port number: {value!r}")
    return number


def key_prefix(value: str) -> str:
    """A key-expression prefix (``--prefix``)."""
    try:
        return keys.check_prefix(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _key_chunk(value: str, what: str) -> str:
    """An id that is one key chunk, ``[A-Za-z0-9_-]{1,64}`` (a robot's or a worker's)."""
    try:
        return keys.check_robot(value, what)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def robot_id(value: str) -> str:
    """A robot id: one key chunk of ``[A-Za-z0-9_-]{1,64}``."""
    return _key_chunk(value, "robot")


def worker_id(value: str) -> str:
    """A worker id: a key chunk as a robot id is."""
    return _key_chunk(value, "worker")


def _number(value: str) -> float:
    """A finite number: ``inf`` and ``nan``, which float() takes, are no option's value."""
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {value!r}") from None
    if not math.isfinite(number):
        raise argparse.ArgumentTypeError(f"not a finite number: {value!r}")
    return number


def finite(value: str) -> float:
    """Any finite number."""
    return _number(value)


def _interval(value: str, low: float, high: float, *, open_low: bool, unit: str = "") -> float:
    """A finite number in (low, high] (``open_low``) or [low, high]."""
    number = _number(value)
    if not (low < number if open_low else low <= number) or not number <= high:
        raise argparse.ArgumentTypeError(
            f"must lie in {'(' if open_low else '['}{low:g}, {high:g}]{' ' + unit if unit else ''}"
            f": {value!r}")
    return number


def contrast(value: str) -> float:
    """A Weber contrast a scene can draw: more than 0 (an object to see), at most 1."""
    return _interval(value, 0, 1, open_low=True)


MAX_EDGE_SPEED = 1024.0  # px a frame: a scene's edge faster than that leaves the largest frame


def edge_speed(value: str) -> float:
    """A generated scene's edge speed, px a frame: more than 0, at most
    :data:`MAX_EDGE_SPEED` (1e308 drew black frames and a label whose contact was not the
    clip's)."""
    return _interval(value, 0, MAX_EDGE_SPEED, open_low=True, unit="px a frame")


def seconds(value: str) -> float:
    """A duration of more than 0 and at most :data:`MAX_SECONDS`."""
    return _interval(value, 0, MAX_SECONDS, open_low=True, unit="seconds")


def seconds_or_zero(value: str) -> float:
    """A duration of 0 to :data:`MAX_SECONDS`."""
    return _interval(value, 0, MAX_SECONDS, open_low=False, unit="seconds")


def megabytes(value: str) -> float:
    """A file size in MB: more than 0, at most a petabyte."""
    return _interval(value, 0, 1e9, open_low=True, unit="MB")


def mcap_output(value: str) -> str:
    """A path for a new MCAP file: it ends in ``.mcap``."""
    value = nonempty_path(value)
    if not value.endswith(".mcap"):
        raise argparse.ArgumentTypeError(f"an MCAP file's name ends in .mcap: {value!r}")
    return value


def non_negative(value: str) -> float:
    """A number of 0 or more."""
    number = _number(value)
    if not number >= 0:
        raise argparse.ArgumentTypeError(f"must be zero or more: {value!r}")
    return number


def tolerance_seconds(value: str) -> float:
    """Seconds of early tolerance: 0 to ``asnn.evaluation.scoring.MAX_EARLY_TOLERANCE_S``."""
    from asnn.evaluation.scoring import MAX_EARLY_TOLERANCE_S

    number = _number(value)
    if not 0 <= number <= MAX_EARLY_TOLERANCE_S:
        raise argparse.ArgumentTypeError(
            f"must be 0 to {MAX_EARLY_TOLERANCE_S:g} seconds: {value!r}")
    return number


def frame_rate(value: str) -> float:
    """Frames a second, within :data:`asnn.io.rates.FPS_RANGE`: beyond it no camera runs, and a
    video writer given such a rate (inf) may never return."""
    from asnn.io.rates import FPS_RANGE

    number = _number(value)
    low, high = FPS_RANGE
    if not low <= number <= high:
        raise argparse.ArgumentTypeError(
            f"a frame rate is {low:g} to {high:g} frames a second, got {value!r}")
    return number


def frame_rates(value: str) -> tuple[float, ...]:
    """Comma-separated frame rates (:func:`frame_rate` each), at least one, none twice."""
    rates = tuple(frame_rate(part.strip()) for part in value.split(","))
    if len(set(rates)) < len(rates):
        raise argparse.ArgumentTypeError(f"a frame rate is given twice in {value!r}")
    return rates


def _whole(value: str, at_least: int, at_most: int | None = None) -> int:
    try:
        number = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {value!r}") from None
    if number < at_least:
        raise argparse.ArgumentTypeError(f"must be at least {at_least}: {value!r}")
    if at_most is not None and number > at_most:
        raise argparse.ArgumentTypeError(f"must be at most {at_most}: {value!r}")
    return number


MAX_FLEET = 4096  # robots one worker or viewer keeps a place for, at most


def fleet_size(value: str) -> int:
    """A number of robots to keep places for: 1 to :data:`MAX_FLEET` (10**27 was taken, and
    a worker's routing table is sized by it)."""
    return _whole(value, 1, MAX_FLEET)


def count(value: str) -> int:
    """A whole number of at least 1."""
    return _whole(value, 1)


def whole(value: str) -> int:
    """A whole number of 0 or more."""
    return _whole(value, 0)


def frames(value: str) -> int:
    """A number of frames: 1 to :data:`MAX_FRAMES`."""
    return _whole(value, 1, MAX_FRAMES)


def warmup_frames(value: str) -> int:
    """Frames left out at a clip's start: 0 to :data:`MAX_FRAMES`."""
    return _whole(value, 0, MAX_FRAMES)


def threads(value: str) -> int:
    """A model's number of threads: 1 to :data:`MAX_THREADS`."""
    return _whole(value, 1, MAX_THREADS)


def processes(value: str) -> int:
    """A number of processes: 1 to :data:`MAX_PROCESSES`."""
    return _whole(value, 1, MAX_PROCESSES)


def cameras(value: str) -> int:
    """A number of cameras: 1 to :data:`MAX_CAMERAS`."""
    return _whole(value, 1, MAX_CAMERAS)


def seed(value: str) -> int:
    """A random seed: a whole number of 0 or more."""
    return whole(value)


def preset_spec(text: str) -> str:
    """An ASNN preset name with optional ``/field=value`` changes (``robust/top_k=0``;
    :func:`asnn.params.parse_preset_spec`)."""
    from asnn.params import parse_preset_spec

    if not text.strip():  # the default's name, if that is meant
        raise argparse.ArgumentTypeError("give a preset's name (default: the default preset)")
    try:
        parse_preset_spec(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def perturbation(name: str) -> str:
    """A ``--perturb`` value: a perturbation's name, or a family's with its strength."""
    from asnn.evaluation.perturb import check_perturbation

    try:
        check_perturbation(name)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return name


def frame_perturbation(name: str) -> str:
    """A ``--perturb`` value that keeps every frame at its size and in its place
    (:func:`asnn.evaluation.perturb.keeps_frames`): ``asnn detect`` writes one record per
    input frame, its targets in the input's pixels. An unknown name's error lists these only."""
    from asnn.evaluation.perturb import FAMILIES, PERTURBATIONS, check_perturbation, keeps_frames

    kept = ", ".join([n for n in PERTURBATIONS if keeps_frames(n)] + list(FAMILIES))
    try:
        check_perturbation(name)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"unknown perturbation {name!r}; asnn detect takes those that keep every frame "
            f"({kept}; jpegQ: quality Q, 1-100; gainG: brightness times G; noiseS: S gray "
            f"levels of noise)") from None
    if not keeps_frames(name):
        raise argparse.ArgumentTypeError(
            f"{name} changes the frames' number or size; asnn detect takes those that keep "
            f"every frame ({kept}), asnn eval takes them all")
    return name


def clips_problem(clips_dir, labels=None) -> tuple[str, str] | None:
    """Why a folder of labelled clips cannot be read, found before anything runs, as ``(what,
    why)``: the folder and ``"not a folder"``, or the labels file (by default
    ``CLIPS/labels.json``) and ``"no labels file (...)"``, or either path and why it cannot
    even be looked up (:func:`asnn.io.files.path_problem`); None where both are there. What
    ``asnn eval`` and ``asnn bench --handover --clips`` say alike."""
    from pathlib import Path

    from asnn.io.files import path_problem

    labels = Path(clips_dir) / "labels.json" if labels is None else Path(labels)
    for path in (clips_dir, labels):  # a name too long, a loop of links: is_dir raises for it
        problem = path_problem(path)
        if problem:
            return str(path), problem
    if not Path(clips_dir).is_dir():
        return str(clips_dir), "not a folder"
    if not labels.is_file():
        return str(labels), f"no labels file (asnn label {clips_dir} starts one)"
    return None
