"""How many frames a detector started cold needs before it warns as one that ran all along.

When a robot's stream moves to another worker (a worker joins, stops or dies), the new owner's
model starts from an empty state. This module measures, over generated scenes (or labelled
clips), how many frames that fresh model must see before its warnings equal those of a model
that saw the whole stream: the *warm-up* a hand-over needs (``asnn bench --handover``; the
service's ``--warmup-frames``, docs/operations.md).

For a scene of n frames and a hand-over at frame k, a fresh detector steps frames k, k+1, ...
(each with its time); it agrees after j frames when its ``collision`` equals the uninterrupted
detector's on every frame from k + j to the end, and its warm-up is the frames its model stepped
among those j: all of them but those a fast camera's frame-rate ceiling held
(:attr:`asnn.ASNN.ceiling_held`), which is what the worker counts. Hand-overs are tried every
``every`` frames.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .runs import DetectorSpec, parse_detector

__all__ = ["covered", "format_report", "handover_warmups", "run", "summarise_warmups",
           "warmup_after"]


def warmup_after(reference: Sequence[bool], cold: Sequence[bool]) -> int:
    """Frames before ``cold`` agrees with ``reference`` (the same frames) for good.

    Parameters
    ----------
    reference : sequence of bool
        The uninterrupted detector's warnings on the frames from the hand-over on.
    cold : sequence of bool
        The fresh detector's warnings on the same frames.

    Returns
    -------
    int
        The smallest j with ``cold[i] == reference[i]`` for every i >= j (0: agrees at once).
    """
    if len(reference) != len(cold):
        raise ValueError(f"{len(reference)} reference and {len(cold)} cold warnings")
    disagree = [i for i, (r, c) in enumerate(zip(reference, cold)) if bool(r) != bool(c)]
    return disagree[-1] + 1 if disagree else 0


def _warnings(spec: DetectorSpec, frames: np.ndarray, times: np.ndarray
              ) -> tuple[list[bool], list[int]]:
    """A fresh detector's warnings on the frames, and after each frame how many of them its
    model stepped (the frames its frame-rate ceiling held not counted)."""
    detector = spec.make()
    warnings, steps = [], []
    for count, (frame, t) in enumerate(zip(frames, times), 1):
        warnings.append(detector.step(frame, float(t)).collision)
        steps.append(count - getattr(detector, "ceiling_held", 0))
    return warnings, steps


def handover_warmups(scenes: Iterable[tuple[str, object]], detector: DetectorSpec | str = "asnn",
                     every: int = 3, on_scene: Callable[[str], None] | None = None) -> list[dict]:
    """Warm-up of a hand-over every ``every`` frames of each scene.

    Parameters
    ----------
    scenes : iterable of (name, Scene)
        :class:`asnn.stimuli.scene.Scene` objects (frames, fps, and for collisions the onset
        and contact frames), or clips of the same fields with ``times`` (each frame's, seconds;
        without it, frames are ``1 / fps`` apart).
    detector : DetectorSpec or str
        The detector (``asnn`` is the default preset).
    every : int
        Frames between two tried hand-overs (the first at frame 1).
    on_scene : callable, optional
        Called with each scene's name when it is done (progress).

    Returns
    -------
    list of dict
        One per hand-over: ``scene``, ``frame`` (k), ``warmup`` (frames the model stepped),
        ``approach`` (whether k lies within the scene's approach, onset to contact).
    """
    spec = parse_detector(detector) if isinstance(detector, str) else detector
    if every < 1:
        raise ValueError(f"every must be at least 1, got {every}")
    rows = []
    for name, scene in scenes:
        frames = np.asarray(scene.frames)
        times = getattr(scene, "times", None)
        times = np.arange(len(frames)) / scene.fps if times is None else np.asarray(times)
        reference, _ = _warnings(spec, frames, times)
        onset, contact = getattr(scene, "onset_frame", None), getattr(scene, "contact_frame", None)
        for k in range(1, len(frames) - 1, every):
            cold, steps = _warnings(spec, frames[k:], times[k:])
            agrees = warmup_after(reference[k:], cold)
            rows.append({"scene": name, "frame": k, "warmup": steps[agrees - 1] if agrees else 0,
                         "approach": onset is not None and contact is not None
                         and onset <= k <= contact})
        if on_scene is not None:
            on_scene(name)
    return rows


def summarise_warmups(rows: Sequence[dict], quantile: float = 0.99) -> dict:
    """Distribution of the warm-ups: all hand-overs, and those within an approach.

    Returns ``handovers``, ``max``, ``quantile`` (the ``quantile`` of the warm-ups), ``counts``
    (warm-up -> hand-overs) and the same for ``approach`` (hand-overs during an approach), plus
    ``worst`` (the hand-overs with the largest warm-up).
    """
    def part(selected):
        values = np.array([r["warmup"] for r in selected], int)
        if not len(values):
            return {"handovers": 0, "max": None, "quantile": None, "counts": {}}
        counts = dict(zip(*np.unique(values, return_counts=True)))
        return {"handovers": int(len(values)), "max": int(values.max()),
                # a value taken (not one between two): "99 % need at most it" then holds
                "quantile": int(np.quantile(values, quantile, method="higher")),
                "counts": {int(k): int(v) for k, v in counts.items()}}

    worst = sorted(rows, key=lambda r: -r["warmup"])[:5]
    return {"quantile_level": quantile, "all": part(rows),
            "approach": part([r for r in rows if r["approach"]]), "worst": worst}


@dataclass(frozen=True)
class _Clip:
    """A labelled clip's frames as :func:`handover_warmups` takes a scene."""

    frames: np.ndarray
    times: list
    fps: float
    onset_frame: int | None
    contact_frame: int | None


def _labelled_clips(clips_dir: Path, labels: Sequence[Mapping]):
    """``(file, clip)`` of each labelled clip, read as ``asnn eval`` reads it (one at a time:
    a clip's frames are held while its hand-overs are tried)."""
    from .clips import open_labelled_clip

    for label in labels:
        source, _ = open_labelled_clip(str(clips_dir / label["file"]), label.get("topic"))
        times, frames = [], []
        for t, frame in source.timed_frames():
            times.append(t)
            frames.append(frame)
        if not frames:
            raise ValueError(f"{label['file']}: no frame to hand over")
        yield label["file"], _Clip(np.stack(frames), times, source.fps,
                                   label.get("onset_frame"), label.get("contact_frame"))


def run(detector: str = "asnn", cases: str | None = None, every: int = 3,
        progress: Callable[[str], None] | None = None,
        clips_dir: str | Path | None = None, looms: float | None = None) -> dict:
    """Warm-ups over the labelled suite (``asnn bench --handover``), over the labelled clips
    of ``clips_dir`` (its ``labels.json``, as ``asnn eval`` reads them), or over the
    constant-speed approaches of ``asnn eval --ttc`` at ``looms`` frames a second (24; the suite
    and the clips are 30 fps or slower); the report as a dict.

    ``cases`` selects suite cases (patterns of :func:`asnn.stimuli.suite.suite_cases`; None:
    all of them).

    Raises
    ------
    ValueError
        For ``cases`` with ``clips_dir`` or ``looms``, both of those, a frame rate that is not
        positive, a labels file that cannot be read, or a labelled clip that cannot be opened
        (before anything runs).
    """
    from ..params import DEFAULT_PRESET

    spec = parse_detector(detector)
    if (cases is not None) + (clips_dir is not None) + (looms is not None) > 1:
        raise ValueError("the hand-overs run over suite cases, labelled clips or generated "
                         "approaches: one of them (cases, clips_dir, looms)")
    source = None
    if looms is not None:
        from . import ttc

        approaches = ttc.looms(dataclasses.replace(ttc.DEFAULT_DESIGN, frame_rates=(looms,)))
        scenes = ((scene.name, scene) for scene in map(ttc.loom_scene, approaches))
        count, source = len(approaches), f"approaches at {looms:g} fps"
    elif clips_dir is not None:
        from .clips import check_clips
        from .labels import load_labels

        clips_dir = Path(clips_dir)
        labels = load_labels(clips_dir / "labels.json")
        check_clips(clips_dir, labels)
        scenes, count = _labelled_clips(clips_dir, labels), len(labels)
        source = f"labelled clips of {clips_dir}"
    else:
        from ..stimuli.suite import make_case, suite_cases

        names = suite_cases(cases)
        scenes = ((name, make_case(name)) for name in names)
        count = len(names)
    rows = handover_warmups(scenes, spec, every=every, on_scene=progress)
    return {"detector": spec.name,
            "preset": (spec.preset or DEFAULT_PRESET) if spec.model == "asnn" else None,
            "cases": count, "source": source, "every": every, **summarise_warmups(rows)}


def covered(counts: dict, frames: int) -> float:
    """The fraction of hand-overs whose warm-up is at most ``frames``."""
    total = sum(counts.values())
    return sum(n for k, n in counts.items() if int(k) <= frames) / total if total else 1.0


def format_report(report: dict, current: int | None = None) -> str:
    """The report as text; ``current``: the warm-up in use, with the hand-overs it covers."""
    preset = f" (preset {report['preset']})" if report.get("preset") else ""
    where = f"{report['cases']} {report.get('source') or 'cases of the labelled suite'}"
    lines = [f"# {report['detector']}{preset}: {where}, a hand-over "
             f"every {report['every']} frames; warm-up = frames a fresh model steps (those a "
             "fast camera's frame-rate ceiling holds not counted) before its warnings equal an "
             "uninterrupted one's for good"]
    for part, title in (("all", "all hand-overs"), ("approach", "during an approach")):
        s = report[part]
        if not s["handovers"]:
            continue
        dist = ", ".join(f"{k}: {n}" for k, n in sorted(s["counts"].items(), key=lambda kv: int(kv[0])))
        lines.append(f"{title}: {s['handovers']}; {int(report['quantile_level'] * 100)} % need "
                     f"at most {s['quantile']} frames, the worst {s['max']} (frames: hand-overs "
                     f"{dist})")
        if current is not None:
            lines.append(f"  with {current} frames (the worker's --warmup-frames): "
                         f"{100 * covered(s['counts'], current):.2f} % of them")
    lines.append("worst: " + "; ".join(f"{w['scene']} at frame {w['frame']}: {w['warmup']}"
                                        for w in report["worst"]))
    return "\n".join(lines)
