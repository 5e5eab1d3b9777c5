"""The approach gate traced once per clip and replayed per threshold (``asnn eval --held-out``).

Running the model once per grid point would cost the grid's size in model runs. The gate acts
after everything else, so each clip is run once (:func:`trace_clip`) with the objects of every
frame recorded (their time to contact, offset and share of ``u``), and the gate, the spikes and
the warning are replayed for each grid point (:func:`replay`); the replay with the preset's own
thresholds reproduces the model's warnings frame for frame (``tests/test_heldout.py``), and
every held-out run checks that it does on each clip it traced (:func:`check_replay`). The
replays, a grid point's on every clip at a time, are spread over the run's processes (``jobs``).

The surface-ahead pathway (``surface_ahead``) is not replayed: it reads the frames, not the
objects. Where it counts, the check above fails, so a traced clip it warned on is refused
rather than scored wrong. On the clips and cases this procedure traces it never counts: at the
grid's loosest limits (``tau_max`` 2.5 s, ``offset_max`` 2) the rule passes in at most one
frame in a row of the real clips and three of the suite's cases, where 0.3 s of frames (10 at
30 fps, 7 at 20) are needed (a screen of the rule on the frames, 2026-11-29). The corridor gate
(``corridor_gate``), which reads the same watch, is not replayed either, and for the same
reason never applies on them.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..approach import frame_pixel
from ..approach.tracking import (approach_parts, approach_test, better_fit, count_in_regions,
                                 layer_estimates, own_motion_weight, persistence_frames,
                                 smoothed_run)
from ..errors import timing_warnings_to
from ..model import ASNN, spike_step
from ..params import ASNNParams
from ..retina import collision_warning, sigmoid_output, spike_count, spike_rate
from .clips import open_labelled_clip

__all__ = ["FrameTrace", "ClipTrace", "trace_clip", "check_replay", "replay", "replays",
           "trace_item"]


@dataclass(frozen=True)
class FrameTrace:
    """What the approach gate saw in one frame.

    Attributes
    ----------
    repeat : bool
        The frame repeated the one before (its response is the previous one).
    objects : tuple of (id, ttc, offset, share, x, y, own, fit, own_fit, box, layers)
        Each object seen: its track's id, time to contact and offset (None while it does not
        grow), its share of ``u`` before ``u_scale``, its centre in the frame's pixels, its
        expansion rate against the scene in this frame (per second; None where not measured:
        with ``scene_relative`` it is measured for every growing track, so that the replay can
        smooth it over the frames in which a track passes any grid point's test), its track's fit
        (:attr:`asnn.approach.tracking.Track.fit`), and the share of its box's change the fit
        against the scene explains in this frame (None unless the scene contracts, with
        ``receding_scene``), its track's box (for ``region_persistence``), and its box's motion
        layers as ``(share, ttc, offset)`` (:func:`asnn.approach.tracking.layer_estimates`; None
        where not measured: with ``motion_layers`` they are measured for every growing track while
        the scene expands).
    period : float or None
        The stream's frame period then (:attr:`asnn.model.ASNN.frame_period`), which sets how many
        frames of approach a track needs (:func:`asnn.approach.tracking.persistence_frames`); None
        for the first frame and repeats, which are not judged.
    """

    repeat: bool
    objects: tuple = ()
    period: float | None = None


@dataclass
class ClipTrace:
    """One clip run through the model with its gate's inputs recorded, and the warnings the
    model gave (``warnings``, one per frame; None where not recorded), which the replay with
    the same parameters must reproduce (:func:`check_replay`)."""

    clip: str
    cells: int
    frames: list[FrameTrace] = field(default_factory=list)
    warnings: list[bool] | None = None
    fps: float | None = None  # the clip's frame rate as decoded, and its frames' (width, height):
    size: tuple[int, int] | None = None  # what its label is checked against
    stamps: tuple[int, int, str | None, int] = (0, 0, None, 0)  # a bag's (clips.clip_warnings)
    timing: tuple[str, ...] = ()  # the model's TimingWarning of the clip's frame times


def trace_clip(timed_frames, params: ASNNParams, clip: str = "") -> ClipTrace:
    """Run the model over ``(t, frame)`` pairs and record what its approach gate saw.

    Raises
    ------
    ValueError
        If the parameters have no approach gate (nothing to replay).
    """
    if not params.approach_gate:
        raise ValueError("only a preset with the approach gate can be traced")
    model = ASNN(params)
    approach = model.approach
    approach.measure_all_against_scene = True
    trace = ClipTrace(clip=clip, cells=0, warnings=[])
    for index, (t, frame) in enumerate(timed_frames):
        trace.warnings.append(bool(model.step(frame, t).collision))
        if index == 0:
            trace.size = (frame.shape[1], frame.shape[0])
            trace.frames.append(FrameTrace(repeat=False))
            continue
        if model.repeated:
            trace.frames.append(FrameTrace(repeat=True))
            continue
        h, w = model.previous.shape
        trace.cells = h * w
        sx, sy = model.shape[1] / w, model.shape[0] / h
        trace.frames.append(FrameTrace(repeat=False, objects=tuple(
            (tr.id, tr.ttc, tr.offset, share, frame_pixel(tr.x, sx), frame_pixel(tr.y, sy),
             approach.against_scene.get(tr.id), tr.fit, approach.fit_against_scene.get(tr.id),
             tuple(tr.box), layer_estimates(approach.layers.get(tr.id), tr.size))
            for tr, share in approach.objects), period=model.frame_period))
    return trace


def check_replay(trace: ClipTrace, params: ASNNParams) -> None:
    """Refuse a trace whose replay with the parameters it was made with does not give the
    model's own warnings: a stage that acts in the approach gate but that :func:`replay` does
    not know would otherwise be left out of every held-out figure without a word.

    Raises
    ------
    ValueError
        If the replay's warnings differ from those recorded (none recorded: nothing to check).
    """
    if trace.warnings is None:
        return
    replayed = [record["collision"] for record in replay(trace, params)]
    if replayed != trace.warnings:
        first = next((k for k, (a, b) in enumerate(zip(replayed, trace.warnings)) if a != b),
                     min(len(replayed), len(trace.warnings)))
        model = ("warns" if first < len(trace.warnings) and trace.warnings[first]
                 else "is quiet")
        raise ValueError(
            f"the held-out replay does not reproduce the model's warnings on {trace.clip!r} "
            f"(first at frame {first}, where the model {model}): a stage of the approach gate "
            "that asnn.evaluation.gate_replay.replay does not know (teach it to trace_clip and "
            "replay)")


def replay(trace: ClipTrace, params: ASNNParams) -> list[dict]:
    """The per-frame records (``frame``, ``collision``, ``targets``) the model would give with
    ``params``' gate thresholds, from a trace made with the same parameters otherwise."""
    return replays(trace, params, (params.own_motion_ratio,))[0]


def replays(trace: ClipTrace, params: ASNNParams, ratios: Sequence[float]) -> list[list[dict]]:
    """:func:`replay` for ``params`` with each ``own_motion_ratio`` of ``ratios``, in one pass:
    the ratio weighs the objects that count, not which count, so the gate is judged once and
    the spikes and warnings follow each ratio's sum."""
    p = params
    streak: dict[int, int] = {}
    # the smoothed expansion against the scene, as Track keeps it, and that fit's share
    # (Track.own_fit), per track measured in the frame before
    own: tuple[dict, dict] = ({}, {})
    windows: list[deque[int]] = [deque(maxlen=p.n_t) for _ in ratios]
    # the boxes of the tracks that passed, per processed frame (TargetTracker.judge)
    passed: deque[list] = deque(maxlen=p.approach_frames)
    # in a frame where nothing counts (most frames) u is 0, whose spikes (eq. 32-33) never vary
    quiet = spike_count(sigmoid_output(0.0, 1), p.k_sp, p.t_sp)
    window_dt = p.window_dt
    runs: list[list[dict]] = [[] for _ in ratios]
    for index, frame in enumerate(trace.frames):
        if index > 0 and not frame.repeat:
            if frame.objects:
                totals, targets, own = _judge(frame, p, streak, own, passed, ratios)
            else:  # a track not seen in this frame starts afresh (Track.measure_own)
                totals, targets, own = [0.0] * len(ratios), [], ({}, {})
                passed.append([])
        for k, records in enumerate(runs):
            if index == 0:
                record = {"frame": 0, "collision": False, "targets": []}
            elif frame.repeat:
                record = {**records[-1], "frame": index}
            else:
                if totals[k]:
                    rate = spike_step(p.u_scale * totals[k], trace.cells, windows[k], p)[2]
                else:
                    windows[k].append(quiet)
                    rate = spike_rate(windows[k], p.n_t, window_dt)
                record = {"frame": index, "collision": collision_warning(rate, p.t_c),
                          "targets": targets}
            records.append(record)
    return runs


def _judge(frame: FrameTrace, p: ASNNParams, streak: dict[int, int], own: tuple[dict, dict],
           passed: deque, ratios: Sequence[float]) -> tuple[list[float], list[dict],
                                                         tuple[dict, dict]]:
    """One processed frame's objects judged as the approach gate would with ``p``: the u
    they add before ``u_scale`` with each ``own_motion_ratio`` of ``ratios``, the targets that
    count, and the tracks' smoothed expansion against the scene and its fit (``own``, for the
    next frame). Updates ``streak`` (frames of approach per track) and ``passed``."""
    frames = persistence_frames(p.approach_frames, p.approach_seconds, frame.period)
    overlap = p.overlap
    judged = []  # (id, ttc, share, x, y) of each object
    boxes, passing, coming = [], [], []  # its box, passes now, counts by its own frames
    measured, measured_fits = {}, {}
    for ident, ttc, offset, share, x, y, against, fit, own_fit, box, layers in frame.objects:
        passes = approach_test(ttc, offset, p.tau_max, p.offset_max, fit, overlap)
        # where the scene contracts, the regime's candidates but for the fit test are
        # measured too (their fit against the scene is known only there); one whose
        # fit is not known would fail the regime anyway, and is left unmeasured
        unfit = (not passes and p.receding_scene and own_fit is not None
                 and approach_test(ttc, offset, p.tau_max, p.offset_max, 1.0, overlap))
        if p.scene_relative and (passes or unfit):
            measured[ident] = smoothed_run(own[0].get(ident), against, p.track_smoothing)
            measured_fits[ident] = smoothed_run(own[1].get(ident), own_fit, p.track_smoothing)
            passes = approach_parts(
                ttc, offset, better_fit(fit, measured_fits[ident]), measured[ident],
                1.0 / ttc, layers if p.motion_layers else None, p.tau_max, p.offset_max,
                overlap, p.scene_tolerance).passes
        streak[ident] = streak.get(ident, 0) + 1 if passes else 0
        judged.append((ident, ttc, share, x, y))
        boxes.append(box)
        passing.append(passes)
        coming.append(streak[ident] >= frames)
    if p.region_persistence and any(passing):  # as TargetTracker.judge
        coming = count_in_regions(boxes, passing, coming, list(passed)[-frames:],
                                  frames, p.region_cover)
    totals, targets = [0.0] * len(ratios), []
    for (ident, ttc, share, x, y), counts in zip(judged, coming):
        if counts:
            totals = [total + own_motion_weight(measured.get(ident), 1.0 / ttc if ttc else None,
                                                p.own_motion_weight, ratio) * share
                      for total, ratio in zip(totals, ratios)]
            targets.append({"x": x, "y": y})
    passed.append([box for box, passes in zip(boxes, passing) if passes])
    # a track not measured in this frame starts afresh (Track.measure_own)
    return totals, targets, (measured, measured_fits)


def trace_item(kind: str, name: str, topic: str | None, params: ASNNParams) -> ClipTrace:
    """A worker's task (:func:`asnn.evaluation.pool.run_tasks`): the trace of a clip (``kind``
    ``"clip"``: ``name`` its path, ``topic`` its bag's image topic) or of a suite case
    (``"case"``: ``name`` the case's)."""
    if kind == "case":
        return _trace_case(name, params)
    return _trace_source(name, topic, params)


def _trace_source(spec: str, topic: str | None, params: ASNNParams) -> ClipTrace:
    source, stamps = open_labelled_clip(spec, topic)  # as asnn eval reads it
    timing: list[str] = []  # as asnn eval's _run_clip: a line of the run's warnings
    with timing_warnings_to(timing.append):
        trace = trace_clip(source.timed_frames(), params, Path(spec).name)
    trace.timing = tuple(timing)
    trace.fps = source.fps
    trace.stamps = stamps.tally
    return trace


def _trace_case(name: str, params: ASNNParams) -> ClipTrace:
    from ..stimuli.suite import make_case
    from .runs import at_rate

    scene = make_case(name)
    return trace_clip(at_rate(scene.frames, scene.fps), params, name)
