"""The targets' time to contact on approaches of known contact time (``asnn eval --ttc``).

Each scene is a constant-speed collision course on the image plane
(:func:`asnn.stimuli.planar.planar_scene`, ``motion="loom"``), whose label carries the true time
to contact ``Z / v`` in every frame. The design (:class:`Design`) crosses frame rates, dark and
light objects, image sizes at onset, times to contact at onset and positions in the frame; every
scene has its own seed of sensor noise, so a run is the same each time. A detector is stepped
through each scene with the frames' own times (``index / fps``).

In every frame of the approach (onset to contact, where the label's time to contact is above 0)
the target nearest the labelled centre, within half the object's image size plus
:data:`MATCH_MARGIN_PX`, is the object's; the frame *has a ttc* when that target exists and
carries one. Its relative error is ``ttc / true - 1`` (below 0: it reads short, the safe side).
The frames are grouped by frame rate and by how much the object's image grows from the
previous frame to this one (:data:`GROWTH_EDGES`): the fit behind ``ttc`` is first-order, and it
saturates once the image grows by a large part of itself in one frame (docs/contract.md,
"Targets"), which happens in the last frames before contact, the sooner the lower the frame
rate.

Nothing here reads or writes files: :func:`evaluate_ttc` returns the results as a dict and
:func:`format_report` the report's text.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from ..stimuli.planar import planar_scene
from ..stimuli.scene import Scene
from .pool import run_tasks
from .progress import Silent
from .runs import DetectorSpec, parse_detector

__all__ = ["DEFAULT_DESIGN", "Design", "GROWTH_EDGES", "Loom", "MATCH_MARGIN_PX", "evaluate_ttc",
           "format_report", "growth_bin", "lead", "lead_rows", "loom_samples", "loom_scene",
           "looms", "scene_samples", "summarise", "ttc_rows"]

# image growth per frame, size[k] / size[k - 1] - 1: the bins' edges (the last is open)
GROWTH_EDGES = (0.0, 0.02, 0.05, 0.1, 0.2, 0.5, math.inf)
# a target counts as the object's within half the object's image size plus this, pixels
MATCH_MARGIN_PX = 10.0


@dataclass(frozen=True)
class Loom:
    """One approach of the design: the options of its :func:`~asnn.stimuli.planar.planar_scene`.

    Attributes
    ----------
    fps : float
    polarity : {'dark', 'light'}
    height : float
        Image height at onset, pixels (of 160x120).
    tau : float
        Time to contact at onset, seconds.
    position : (x, y) or None
        Image centre, pixels; None for the frame's centre.
    contrast : float
        Weber contrast against the background.
    noise : float
        Standard deviation of the sensor noise, gray levels.
    seed : int
        Of the sensor noise.
    """

    fps: float
    polarity: str
    height: float
    tau: float
    position: tuple[float, float] | None
    contrast: float
    noise: float
    seed: int

    @property
    def onset(self) -> int:
        """The first frame of the approach: half a second of still scene first, at least 10
        frames (the model's start-up)."""
        return max(10, round(0.5 * self.fps))

    @property
    def where(self) -> str:
        """``centre`` or ``x,y``."""
        return "centre" if self.position is None else "{:g},{:g}".format(*self.position)


@dataclass(frozen=True)
class Design:
    """The approaches of a run: every combination of the values below (:func:`looms`).

    The default, :data:`DEFAULT_DESIGN`, is what ``asnn eval --ttc`` runs (96 approaches,
    about 9 500 frames of 160x120, of which about 7 800 lie in an approach).
    """

    frame_rates: tuple[float, ...] = (10.0, 20.0, 30.0, 60.0)
    polarities: tuple[str, ...] = ("dark", "light")
    heights: tuple[float, ...] = (6.0, 12.0, 24.0)
    taus: tuple[float, ...] = (2.0, 4.0)
    positions: tuple[tuple[float, float] | None, ...] = (None, (40.0, 30.0))
    contrast: float = 0.6
    noise: float = 2.0
    seed: int = 0

    def to_dict(self) -> dict:
        return {key: (list(value) if isinstance(value, tuple) else value)
                for key, value in asdict(self).items()}


# what ``asnn eval --ttc`` runs
DEFAULT_DESIGN = Design()


def looms(design: Design = DEFAULT_DESIGN) -> list[Loom]:
    """The approaches of ``design``, each with its own seed (``design.seed`` plus its index).

    Raises
    ------
    ValueError
        For a design without any approach, or a frame rate, height or time to contact that is
        not positive.
    """
    values = (design.frame_rates, design.polarities, design.heights, design.taus,
              design.positions)
    if not all(values):
        raise ValueError("the design has no approach (a list of values is empty)")
    for name, given in (("frame rate", design.frame_rates), ("height", design.heights),
                        ("time to contact", design.taus)):
        if any(not (math.isfinite(v) and v > 0) for v in given):
            raise ValueError(f"every {name} must be above 0, got {list(given)}")
    return [Loom(float(fps), polarity, float(height), float(tau), position, design.contrast,
                 design.noise, design.seed + index)
            for index, (fps, polarity, height, tau, position)
            in enumerate(itertools.product(*values))]


def loom_scene(loom: Loom) -> Scene:
    """The labelled clip of one approach (160x120; it ends 2 frames after contact)."""
    return planar_scene("loom", fps=loom.fps, onset=loom.onset, polarity=loom.polarity,
                        contrast=loom.contrast, height=loom.height, tau=loom.tau,
                        position=loom.position, noise=loom.noise, seed=loom.seed,
                        name=f"loom-{loom.polarity}-d{loom.height:g}-tau{loom.tau:g}s-"
                             f"{loom.where}-{loom.fps:g}fps")


def growth_bin(growth: float) -> int:
    """The index of the bin of :data:`GROWTH_EDGES` that holds ``growth`` (0 below 0)."""
    for index, upper in enumerate(GROWTH_EDGES[1:]):
        if growth < upper:
            return index
    return len(GROWTH_EDGES) - 2


def _bin_name(index: int) -> str:
    lower, upper = GROWTH_EDGES[index], GROWTH_EDGES[index + 1]
    if index == 0:
        return f"< {100 * upper:g} %"
    if math.isinf(upper):
        return f">= {100 * lower:g} %"
    return f"{100 * lower:g}-{100 * upper:g} %"


def _field(target, name: str):
    return target.get(name) if isinstance(target, Mapping) else getattr(target, name, None)


def scene_samples(scene: Scene, targets: Sequence[Sequence]) -> list[dict]:
    """One sample per approach frame of ``scene``: the truth and the object's target's ``ttc``.

    Parameters
    ----------
    scene : Scene
        A looming scene with its per-frame ``track``, ``target_size`` and ``ttc``.
    targets : sequence of sequences
        The targets reported in each frame of the scene (:class:`asnn.targets.Target` or
        mappings with ``x``, ``y`` and ``ttc``).

    Returns
    -------
    list of dict
        Per frame from onset to contact whose true time to contact is above 0: ``frame``,
        ``true`` (seconds), ``growth`` (the image's size over the previous frame's, minus 1),
        ``ttc`` (the matched target's, None where no target matches or it carries none) and
        ``error`` (``ttc / true - 1``, or None).

    Raises
    ------
    ValueError
        For targets of another number of frames than the scene's, or a scene without a
        labelled approach.
    """
    if len(targets) != len(scene.frames):
        raise ValueError(f"{len(targets)} frames of targets for a scene of {len(scene.frames)}")
    if scene.onset_frame is None or scene.contact_frame is None or scene.ttc is None \
            or scene.track is None or scene.target_size is None:
        raise ValueError(f"{scene.name}: no labelled approach (onset, contact, track, size, ttc)")
    samples = []
    for k in range(scene.onset_frame, scene.contact_frame + 1):
        true, size = float(scene.ttc[k]), float(scene.target_size[k])
        if not (math.isfinite(true) and true > 0):
            continue
        previous = float(scene.target_size[k - 1]) if k > 0 else size
        cx, cy = (float(v) for v in scene.track[k])
        reach = 0.5 * size + MATCH_MARGIN_PX
        best, best_distance = None, math.inf
        for target in targets[k]:
            distance = math.hypot(float(_field(target, "x")) - cx, float(_field(target, "y")) - cy)
            if distance <= reach and distance < best_distance:
                best, best_distance = target, distance
        ttc = None if best is None else _field(best, "ttc")
        ttc = float(ttc) if ttc is not None and math.isfinite(ttc) else None
        samples.append({"frame": k, "true": true,
                        "growth": size / previous - 1.0 if previous > 0 else 0.0,
                        "ttc": ttc, "error": None if ttc is None else ttc / true - 1.0})
    return samples


def loom_samples(loom: Loom, make: Callable[[], object]) -> list[dict]:
    """A worker's task: generate one approach, step a fresh detector (``make()``) through it
    with the frames' own times, and return its samples (:func:`scene_samples`), each with
    ``fps`` and ``warned`` (whether the detector warned in that frame)."""
    scene = loom_scene(loom)
    detector = make()
    responses = [detector.step(frame, index / loom.fps) for index, frame in enumerate(scene.frames)]
    targets = [list(response.targets) for response in responses]
    return [{**sample, "fps": loom.fps, "warned": bool(responses[sample["frame"]].collision)}
            for sample in scene_samples(scene, targets)]


def lead(samples: Sequence[Mapping]) -> float | None:
    """Seconds from the first warning in an approach's samples to its contact (its last sample:
    the image as tall as the frame); None where it never warned."""
    first = next((s for s in samples if s.get("warned")), None)
    if first is None:
        return None
    return (samples[-1]["frame"] - first["frame"]) / samples[-1]["fps"]


def lead_rows(per_loom: Sequence[Sequence[Mapping]]) -> list[dict]:
    """Per frame rate, then over all: ``approaches``, ``warned`` (how many warned before
    contact), and the ``median`` and ``p10`` of their first warning's :func:`lead`, seconds
    (None where none warned)."""
    leads = [(group[-1]["fps"], lead(group)) for group in per_loom if group]
    rows = []
    for fps in [*sorted({f for f, _ in leads}), None]:
        chosen = [value for f, value in leads if fps is None or f == fps]
        warned = np.array([value for value in chosen if value is not None], float)
        rows.append({"fps": fps, "approaches": len(chosen), "warned": int(warned.size),
                     "median": float(np.median(warned)) if warned.size else None,
                     "p10": float(np.percentile(warned, 10)) if warned.size else None})
    return rows


def summarise(samples: Iterable[Mapping], horizon: float | None = None) -> dict:
    """The figures of a group of samples.

    Parameters
    ----------
    samples : iterable of dict
        :func:`scene_samples`' samples.
    horizon : float, optional
        A time to contact, seconds (the preset's ``tau_max``): ``share_within`` is the share of
        the frames with a ttc among those whose true time to contact is at most this.

    Returns
    -------
    dict
        ``frames`` (samples), ``with_ttc`` and ``share`` (of them with a ttc),
        ``share_within``, and over the frames with a ttc: ``median``, ``p10`` and ``p90`` of
        the relative error, ``median_abs`` (of its size) and ``long`` (the share reading more
        than 25 % long); None where no sample has a ttc (or, for ``share_within``, no horizon
        or no sample within it).
    """
    samples = list(samples)
    errors = np.array([s["error"] for s in samples if s["error"] is not None], float)
    within = [s for s in samples if horizon is not None and s["true"] <= horizon]
    row = {"frames": len(samples), "with_ttc": int(errors.size),
           "share": errors.size / len(samples) if samples else None,
           "share_within": (sum(s["error"] is not None for s in within) / len(within)
                            if within else None)}
    if not errors.size:
        return {**row, "median": None, "p10": None, "p90": None, "median_abs": None,
                "long": None}
    return {**row, "median": float(np.median(errors)),
            "p10": float(np.percentile(errors, 10)), "p90": float(np.percentile(errors, 90)),
            "median_abs": float(np.median(np.abs(errors))),
            "long": float(np.mean(errors > 0.25))}


def ttc_rows(samples: Sequence[Mapping], horizon: float | None = None) -> list[dict]:
    """The report's rows: per frame rate each growth bin that holds samples, then the frame
    rate's whole approach; then each bin over every frame rate, and everything (``horizon``:
    as :func:`summarise`'s).

    Returns
    -------
    list of dict
        :func:`summarise`'s figures with ``fps`` (None: every frame rate) and ``growth`` (the
        bin's name, or ``all``).
    """
    rates = sorted({s["fps"] for s in samples})
    bins = [growth_bin(s["growth"]) for s in samples]
    rows = []
    for fps in [*rates, None]:
        chosen = [i for i, s in enumerate(samples) if fps is None or s["fps"] == fps]
        for index in range(len(GROWTH_EDGES) - 1):
            group = [samples[i] for i in chosen if bins[i] == index]
            if group:
                rows.append({"fps": fps, "growth": _bin_name(index),
                             **summarise(group, horizon)})
        rows.append({"fps": fps, "growth": "all",
                     **summarise((samples[i] for i in chosen), horizon)})
    return rows


def evaluate_ttc(detector: DetectorSpec | str = "asnn", design: Design | None = None,
                 jobs: int = 1, progress=None) -> dict:
    """Run ``detector`` over the approaches of ``design`` and measure its ``ttc``.

    Parameters
    ----------
    detector : DetectorSpec or str
        A detector spec (:mod:`asnn.evaluation.runs`; ``asnn`` is the default preset). Detectors
        whose targets carry no ``ttc`` get rows without errors.
    design : Design, optional
        The approaches; None: :data:`DEFAULT_DESIGN`.
    jobs : int
        Processes running approaches in parallel.
    progress : ProgressPrinter-like, optional

    Returns
    -------
    dict
        ``detector`` (its name), ``description``, ``design`` (:meth:`Design.to_dict`),
        ``growth_edges``, ``match_margin_px``, ``horizon_s`` (an ASNN preset's ``tau_max``, the
        longest time to contact its targets are reported at; None for the LGMDs), ``looms``
        (the approaches: their options,
        ``onset``, and ``frames``, ``with_ttc`` and ``median`` of their samples), ``rows``
        (:func:`ttc_rows`), ``leads`` (:func:`lead_rows`: how soon before contact it warned).

    Raises
    ------
    ValueError
        For an unknown detector, a design without approaches, or ``jobs`` below 1.
    """
    spec = parse_detector(detector) if isinstance(detector, str) else detector
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs}")
    design = DEFAULT_DESIGN if design is None else design
    approaches = looms(design)
    progress = progress or Silent()
    progress.start(len(approaches), "eval --ttc")
    per_loom: list[list[dict] | None] = [None] * len(approaches)
    summaries: list[dict | None] = [None] * len(approaches)
    for index, samples in run_tasks(loom_samples, [(loom, spec.make) for loom in approaches],
                                    jobs):
        per_loom[index], summaries[index] = samples, summarise(samples)
        loom, summary = approaches[index], summaries[index]
        name = f"{loom.fps:g} fps {loom.polarity} d{loom.height:g} tau {loom.tau:g} s {loom.where}"
        progress.advance(1, name)
        progress.note(f"{name}: {summary['with_ttc']}/{summary['frames']} frames with a ttc")
    progress.finish()
    samples = [s for group in per_loom for s in group]
    horizon = spec.params.tau_max if spec.model == "asnn" else None
    return {"detector": spec.name, "description": spec.description, "design": design.to_dict(),
            "growth_edges": [e if math.isfinite(e) else None for e in GROWTH_EDGES],
            "match_margin_px": MATCH_MARGIN_PX, "horizon_s": horizon,
            "looms": [{**asdict(loom), "onset": loom.onset,
                       **{k: summary[k] for k in ("frames", "with_ttc", "median")}}
                      for loom, summary in zip(approaches, summaries)],
            "rows": ttc_rows(samples, horizon), "leads": lead_rows(per_loom)}


def _percent(value: float | None, sign: bool = True, digits: int = 1) -> str:
    if value is None:
        return "–"
    return f"{100 * value:{'+' if sign else ''}.{digits}f} %"


def format_report(results: Mapping) -> str:
    """The report of :func:`evaluate_ttc`'s results: a paragraph and a Markdown table."""
    design = results["design"]
    n = len(results["looms"])
    rates = "/".join(f"{fps:g}" for fps in design["frame_rates"])
    where = ", ".join("centre" if p is None else "({:g}, {:g})".format(*p)
                      for p in design["positions"])
    lines = [
        f"# Time to contact of `{results['detector']}`'s targets ({results['description']})",
        "",
        f"{n} constant-speed approaches (asnn.stimuli.planar, loom, 160x120) at {rates} fps: "
        f"{' and '.join(design['polarities'])} disks of Weber contrast {design['contrast']:g}, "
        f"{'/'.join(f'{h:g}' for h in design['heights'])} px tall and "
        f"{'/'.join(f'{t:g}' for t in design['taus'])} s from contact at onset, at {where}; "
        f"sensor noise {design['noise']:g} gray levels, seeds from {design['seed']}. Every frame "
        "from onset to contact (the image as tall as the frame) is a sample; the object's target "
        f"is the nearest to its labelled centre within half its size + "
        f"{results['match_margin_px']:g} px. Error = ttc / true - 1 (below 0: short, the safe "
        "side), over the frames whose target carries a ttc; growth = the image's size over the "
        "previous frame's, minus 1. `> +25 %`: share of those reading more than 25 % long.",
    ]
    horizon = results.get("horizon_s")
    if horizon is not None:
        lines[-1] += (" The default preset reports only objects that pass its approach test (a "
                      f"ttc up to tau_max, here {horizon:g} s, for some frames in a row), so the "
                      "frames further from contact carry none: `with ttc, true <= "
                      f"{horizon:g} s` counts the frames within it.")
    lines += [
        "",
        "| fps | growth per frame | frames | with ttc | "
        + (f"with ttc, true <= {horizon:g} s | " if horizon is not None else "")
        + "median error | p10 | p90 | median abs. error | > +25 % |",
        "| --- " * (9 if horizon is None else 10) + "|",
    ]
    for row in results["rows"]:
        fps = "all" if row["fps"] is None else f"{row['fps']:g}"
        growth = f"**{row['growth']}**" if row["growth"] == "all" else row["growth"]
        within = (f"{_percent(row['share_within'], False, 0)} | " if horizon is not None else "")
        lines.append(f"| {fps} | {growth} | {row['frames']} | {_percent(row['share'], False, 0)} | "
                     f"{within}{_percent(row['median'])} | {_percent(row['p10'])} | "
                     f"{_percent(row['p90'])} | {_percent(row['median_abs'], False)} | "
                     f"{_percent(row['long'], False, 0)} |")
    lines += ["", "First warning before contact, per frame rate (the same approaches):", "",
              "| fps | approaches | warned | median lead | p10 lead |", "| --- " * 5 + "|"]
    for row in results["leads"]:
        fps = "all" if row["fps"] is None else f"{row['fps']:g}"
        seconds = ["–" if v is None else f"{v:.2f} s" for v in (row["median"], row["p10"])]
        lines.append(f"| {fps} | {row['approaches']} | {row['warned']} | {seconds[0]} | "
                     f"{seconds[1]} |")
    return "\n".join(lines) + "\n"
