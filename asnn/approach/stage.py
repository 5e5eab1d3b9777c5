"""The object stage of the robust preset: which of the attended pixels come at the camera.

The paper's model sums ``G'`` over every attended pixel (eq. 28) and reports its targets by
clustering them (eqs. 29-31). Presets with ``targets='objects'`` hand each frame's attended
mask ``M_a M_d`` and approach map ``G`` to one :class:`ApproachStage` per stream instead, which

1. takes the mask's objects (:func:`asnn.targets.extract_objects`) and links them to tracks
   (:class:`asnn.approach.tracking.TargetTracker`);
2. fits each track's box's expansion and drift on the frames themselves
   (:func:`asnn.approach.looming.region_and_rim_expansion`), leaving out the camera's own rig
   (:class:`CameraRig`, ``ignore_rig``);
3. measures the tracks that pass the approach test against the scene around them, and splits
   their boxes into motion layers where the scene expands (``scene_relative``,
   ``motion_layers``);
4. judges the approach test with its persistence
   (:meth:`asnn.approach.tracking.TargetTracker.judge`);
5. beside the objects, measures the whole view for a surface ahead (a wall filling it, which
   the retina's filtering cancels: :mod:`asnn.approach.surface`, ``surface_ahead``), and
   where it reads as a corridor instead, lets no object count (its walls: ``corridor_gate``);

and gives back the membrane potential summed over the approaching objects only (the approach
gate, ``approach_gate``; an object closing on us by its own motion counts ``own_motion_weight``
times), and a surface ahead's, with one target per approaching object. Every
stage is in
``docs/robust-preset.md`` with its reason and its switch.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import cv2
import numpy as np

from .._jit import kernel
from ..params import ASNNParams
from ..retina import potential_for_output
from ..response import TrackReport
from ..targets import Target, extract_objects
from .looming import (FIT_SIDE, RIG_WEIGHT, Expansion, moved_by_expansion,
                      refined_expansion, region_and_rim_expansion, region_expansion, rig_pixels,
                      rig_rows, rim_scaled, scene_expansion)
from .motion_layers import motion_layers
from .surface import SurfaceWatch, surface_frames
from .tracking import (ApproachVerdict, Observation, TargetTracker, approach_test,
                       own_motion_weight, persistence_frames)

__all__ = ["ApproachStage", "CameraRig", "FramePair", "frame_pixel"]

# the scene "expands" (our own forward motion) from this rate per second: driving scenes expand
# at about 0.7, a still camera's noise reads below 0.1
_SCENE_EXPANDS = 0.2
# the scene moves in depth at all from this rate per second (a time to contact of 500 s): a
# refit against a scene "expanding" at 1e-5 per second, a fit of noise, leaves out the pixels
# where its reference, within rounding of the previous frame, ties with it, and float32 and
# float64 break those ties apart. (At 0.02, a turn's slight expansion was no longer refitted
# against, and a generated cut-in in a turn warned: design notes, "A scene that does not move
# in depth is not refitted against".)
_SCENE_MOVES = 0.002
# a counting target's reported expansion is refined where its motion moves its box's edge by
# more than this many pixels a frame at the looming fit's grid (at most 64 px a side): beyond
# the gradient fit's small-motion range (asnn.approach.looming.refined_expansion)
_REFINE_EDGE = 1.0


class FramePair(NamedTuple):
    """The two frames a step's looming fits compare, on the model's grid."""

    previous: np.ndarray
    current: np.ndarray
    # the previous frame moved by the background's translation since (None: no translation)
    background: np.ndarray | None
    elapsed: float  # seconds between them


def frame_pixel(coordinate: float, scale: float) -> float:
    """A model pixel's coordinate in the input frame's pixels, ``scale`` frame pixels per model
    pixel: pixel centres, model pixel i covering the frame's pixels [i scale, (i + 1) scale)."""
    return float((coordinate + 0.5) * scale - 0.5)


def _pixel_box(box: tuple[float, float, float, float], w: int,
               h: int) -> tuple[int, int, int, int]:
    """The whole pixels of a track's box inside a ``w`` x ``h`` frame, ``(x0, y0, x1, y1)``
    with ``0 <= x0 <= x1 <= w`` and ``0 <= y0 <= y1 <= h``: empty where the box lies outside
    the frame (a smoothed box can trail its object past the edge), since a slice with a
    negative end would count from the frame's far side."""
    x0, y0 = min(max(int(box[0]), 0), w), min(max(int(box[1]), 0), h)
    return (x0, y0, max(min(int(math.ceil(box[2])), w), x0),
            max(min(int(math.ceil(box[3])), h), y0))


class CameraRig:
    """The running means that find the camera's own rig (:func:`~asnn.approach.looming.rig_pixels`),
    and its pixels, which the looming fits leave out (``ignore_rig``).

    Attributes
    ----------
    mean, change : ndarray (h, w) or None
        Running means (weight :data:`~asnn.approach.looming.RIG_WEIGHT` a frame) of the frames and
        of each pixel's frame-to-frame change, at half the resolution (the rig is large); kept
        in the rows :func:`~asnn.approach.looming.rig_pixels` reads
        (:func:`~asnn.approach.looming.rig_rows`), the rows between them hold the first frame's.
    frames : int
        Frames they averaged.
    mask : ndarray (H, W) of bool, or None
        The rig's pixels at full resolution after the latest frame (None: none).
    """

    def __init__(self) -> None:
        self.mean: np.ndarray | None = None
        self.change: np.ndarray | None = None
        self.frames = 0
        self.mask: np.ndarray | None = None
        self._last: tuple | None = None  # the last frame, and it at half resolution

    def update(self, previous: np.ndarray, current: np.ndarray) -> np.ndarray | None:
        """Take a frame and the one before it; return :attr:`mask`."""
        h, w = current.shape
        half = (max(w // 2, 1), max(h // 2, 1))  # 2x2 area means
        last = self._last
        before = (last[1] if last is not None and last[0] is previous
                  else cv2.resize(previous, half, interpolation=cv2.INTER_AREA))
        now = cv2.resize(current, half, interpolation=cv2.INTER_AREA)
        self._last = (current, now)
        if self.change is None or self.change.shape != now.shape:
            self.change, self.mean, self.frames = np.abs(now - before), now.copy(), 1
        else:
            weight = now.dtype.type(RIG_WEIGHT)
            for rows in rig_rows(now.shape[0]):  # the rows rig_pixels reads
                _running_means(now, before, rows.start, rows.stop, weight, self.change,
                               self.mean)
            self.frames += 1
        rig = rig_pixels(self.change, self.mean, self.frames)
        self.mask = None if rig is None else _nearest(rig, h, w)
        return self.mask


@kernel()
def _running_means(now, before, y0, y1, weight, change, mean):
    """``change += weight (|now - before| - change)`` and ``mean += weight (now - mean)`` on
    the rows ``[y0, y1)``, in the arrays' precision as NumPy computes them."""
    for y in range(y0, y1):
        for x in range(now.shape[1]):
            change[y, x] += weight * (abs(now[y, x] - before[y, x]) - change[y, x])
            mean[y, x] += weight * (now[y, x] - mean[y, x])


def _nearest(mask: np.ndarray, h: int, w: int) -> np.ndarray:
    """A boolean ``mask`` resized to ``h`` x ``w`` as ``cv2.resize`` with INTER_NEAREST resizes
    it; where that doubles it both ways, each cell copied to its 2 x 2 pixels by a kernel (a
    fraction of OpenCV's time on a dashcam's 432 x 240 frames)."""
    if (h, w) != (2 * mask.shape[0], 2 * mask.shape[1]):
        return cv2.resize(mask.view(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST).view(bool)
    out = np.empty((h, w), np.bool_)
    _doubled(mask.view(np.uint8), out.view(np.uint16))
    return out


@kernel()
def _doubled(cells, pairs):
    """Each byte of ``cells`` (H, W) twice across, as one 16-bit word of ``pairs`` (2H, W), in
    two rows."""
    for y in range(cells.shape[0]):
        top, bottom, row = pairs[2 * y], pairs[2 * y + 1], cells[y]
        for x in range(row.shape[0]):
            top[x] = np.uint16(row[x]) * np.uint16(257)
        bottom[:] = top


class ApproachStage:
    """The objects of one stream's attended masks, their tracks and which of them approach.

    Parameters
    ----------
    params : ASNNParams
        The model's parameters (``targets='objects'``).

    Attributes
    ----------
    tracker : TargetTracker
        The tracked objects.
    rig : CameraRig
        The camera's rig, which the looming fits leave out (``ignore_rig``).
    surface : SurfaceWatch
        The whole view's expansion and its verdicts (``surface_ahead``).
    objects : list of (Track, float)
        The objects seen in the latest frame with their share of ``sum |G'|`` (or
        ``sum G'``), in the frame's order; what the approach gate decided on.
    against_scene : dict of int to float or None
        Track id -> its expansion rate against the scene in the latest frame, per second (None:
        not measured); with :attr:`measure_all_against_scene`, of every growing track.
    fit_against_scene : dict of int to float or None
        Track id -> that fit's share of the box's change, where the scene contracts
        (``receding_scene``; None elsewhere).
    layers : dict of int to list
        Track id -> its box's motion layers ``(share, rate /s, drift_x px/s, drift_y px/s)``,
        where measured (``motion_layers``, while the scene expands).
    measure_all_against_scene : bool
        Measure every growing track against the scene, not only the candidates (the held-out
        replay's trace, :mod:`asnn.evaluation.gate_replay`); the tracks' state is still only that
        of the candidates.
    """

    def __init__(self, params: ASNNParams):
        p = self.params = params
        self.tracker = TargetTracker(p.track_link, p.track_missed, p.track_smoothing,
                                     p.track_box,
                                     p.approach_frames if p.region_persistence else 0,
                                     p.object_ids, p.region_cover)
        self.rig = CameraRig()
        self.surface = SurfaceWatch()
        # |u| / N at which out(t) (eq. 32) reads T_sp + 1 / (2 K_sp): one spike a frame
        # (floor(e^0.5), eq. 33) while a surface ahead counts, whatever the preset
        self._surface_potential = potential_for_output(min(p.t_sp + 0.5 / p.k_sp, 0.999))
        self.objects: list = []
        self.against_scene: dict[int, float | None] = {}
        self.fit_against_scene: dict[int, float | None] = {}
        self.layers: dict[int, list] = {}
        self.measure_all_against_scene = False
        self._overlap = p.overlap  # the approach test's partial-overlap regime, or None
        self._scene_reference: np.ndarray | None = None
        self._scene_average: list = [None, None]  # scene_expansion's memo of the last frame

    def step(self, attended: np.ndarray | None, g: np.ndarray,
             vectors: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
             frames: FramePair, total: float, period: float, scale: tuple[float, float],
             points: tuple[np.ndarray, np.ndarray] | None = None, record: bool = False
             ) -> tuple[float, list[Target], list[TrackReport] | None]:
        """One frame: its objects, their expansion, the tracker, and the approach gate.

        Parameters
        ----------
        attended : ndarray (H, W) of bool, or None
            The attended mask ``M_a M_d``; None where it is empty.
        g : ndarray (H, W)
            The approach map G.
        vectors : callable
            ``vectors(rows, cols) -> (dx, dy)``: the motion vectors at those pixels.
        frames : FramePair
            The frame, the one before it and the time between them.
        total : float
            ``sum G'`` over the attended pixels (eq. 28, before ``u_scale``).
        period : float
            The stream's frame period, seconds (persistence at low frame rates).
        scale : (float, float)
            Input-frame pixels per model pixel, across and down.
        points : (rows, cols), optional
            The attended pixels, where the caller has them.
        record : bool
            Also return every track's report (:class:`~asnn.response.TrackReport`).

        Returns
        -------
        total : float
            With ``approach_gate``, ``sum G'`` over the approaching objects only; else ``total``.
        targets : list of Target
            With ``approach_gate``, the approaching objects; else every object (one target
            per object id).
        reports : list of TrackReport or None
            With ``record``.
        """
        p = self.params
        elapsed = frames.elapsed
        if p.ignore_rig:
            self.rig.update(frames.previous, frames.current)
        self.against_scene = {}
        self.fit_against_scene = {}
        self.layers = {}
        surface = self._surface_ahead(frames, g.size, period, scale, record)
        if attended is None:
            self.tracker.update([], elapsed)
            if p.scene_relative:
                self._measure_against_scene([], [], [], [], frames)
            self.objects = []
            total = 0.0 if p.approach_gate else total
            if surface is not None:
                potential, target, report = surface
                return total + potential, [target], report
            return total, [], ([] if record else None)
        regions = extract_objects(attended, g, vectors, p.min_object_pixels, p.u_abs,
                                  points=points)
        h, w = attended.shape
        # the regions' numbers as Python's: a frame's few objects are read one number at a time
        object_boxes, xs, ys, shares = (regions.boxes.tolist(), regions.x.tolist(),
                                        regions.y.tolist(), regions.share.tolist())
        observations = []
        for (x0, y0, x1, y1), x, y, size, mass in zip(object_boxes, xs, ys,
                                                      regions.size.tolist(),
                                                      regions.mass.tolist()):
            pad = p.looming_margin * max(x1 - x0, y1 - y0) + 4
            observations.append(Observation(x, y, size, mass,
                                            (x0 - pad, y0 - pad, x1 + pad, y1 + pad)))
        tracks = self.tracker.update(observations, elapsed)
        # where the background slides, each box is fitted over its object's rim too
        rim = attended if p.rim_expansion and frames.background is not None else None
        boxes, rates, estimates, wholes = [], [], [], []
        for k, tr in enumerate(tracks):
            box = _pixel_box(tr.box, w, h)
            est = rim_scaled(*region_and_rim_expansion(
                frames.previous, frames.current, box, rim, frames.background, self.rig.mask),
                max(box[2] - box[0], box[3] - box[1]), p.rim_motion_max)
            # an object the frame's edge cuts is measured on its visible part: its drift and
            # size, so its offset, are not the object's, whatever the fit
            ox0, oy0, ox1, oy1 = object_boxes[k]
            whole = ox0 > 0 and oy0 > 0 and ox1 < w and oy1 < h
            if est is not None:
                tr.measure(est.rate / elapsed, est.drift_x / elapsed, est.drift_y / elapsed,
                           est.fit if whole else 0.0)
            boxes.append(box)
            wholes.append(whole)
            estimates.append(est)
            rates.append(None if est is None else est.rate / elapsed)
        if p.scene_relative:
            self._measure_against_scene(tracks, boxes, rates, wholes, frames)
        persistence = persistence_frames(p.approach_frames, p.approach_seconds, period)
        coming = self.tracker.judge(tracks, p.tau_max, p.offset_max, persistence,
                                    self._overlap, p.scene_tolerance)
        if p.corridor_gate and self._in_corridor(period):
            # a corridor's objects are pieces of its walls (the tracks keep their state: an
            # object standing ahead counts once it ends the corridor reading)
            coming = [False] * len(coming)
        if p.refined_ttc:
            self._measure_reported(tracks, boxes, estimates, coming, frames)
        self.objects = list(zip(tracks, shares))
        # what each object adds to u where it counts: its share, times own_motion_weight where it
        # closes on us by its own motion
        counted = regions.share
        if p.own_motion_weight != 1.0:
            counted = counted * np.array(
                [own_motion_weight(tr.own_expansion, tr.expansion, p.own_motion_weight,
                                   p.own_motion_ratio) for tr in tracks])
        if p.approach_gate:  # NumPy's sum, in its order (none coming: 0)
            total = float(counted[np.asarray(coming, bool)].sum()) if any(coming) else 0.0
        sx, sy = scale
        reports = ([self._report(tr, coming[k], float(counted[k]), sx, sy)
                    for k, tr in enumerate(tracks)] if record else None)
        targets: dict[int, Target] = {}  # by object id
        for k, tr in enumerate(tracks):
            if p.approach_gate and not coming[k]:
                continue
            target = Target(x=frame_pixel(xs[k], sx), y=frame_pixel(ys[k], sy),
                            direction=float(regions.direction[k]),
                            energy=float(regions.energy[k]),
                            pixels=round(int(regions.pixels[k]) * sx * sy),
                            id=self.tracker.object_id(tr),
                            expansion=tr.reported_expansion if p.refined_ttc else tr.expansion,
                            ttc=tr.reported_ttc if p.refined_ttc else tr.ttc,
                            offset=tr.offset, approaching=coming[k])
            # an object seen as several fragments is one target: its largest
            if target.id not in targets or target.pixels > targets[target.id].pixels:
                targets[target.id] = target
        if surface is not None:
            potential, target, report = surface
            total += potential
            targets[target.id] = target
            if record:
                reports += report
        return total, list(targets.values()), reports

    def _measure_reported(self, tracks: list, boxes: list, estimates: list, coming: list,
                          frames: FramePair) -> None:
        """Each measured track's reported expansion (``refined_ttc``;
        :meth:`~asnn.approach.tracking.Track.measure_reported`), after the approach test has
        been judged on its own: this frame's fit, refined
        (:func:`~asnn.approach.looming.refined_expansion`) where the track counts and the
        larger of the fit and the reported rate's prediction
        (:meth:`~asnn.approach.tracking.Track.predicted_expansion`) moves the box's edge by
        more than :data:`_REFINE_EDGE` pixels a frame at the fit's grid, starting from the
        larger of the two (a saturated fit can lie too far below the answer for two steps to
        reach it)."""
        previous, current, background, elapsed = frames
        for k, tr in enumerate(tracks):
            est = estimates[k]
            if est is None:
                continue
            if coming[k]:
                x0, y0, x1, y1 = boxes[k]
                edge = 0.5 * min(max(x1 - x0, y1 - y0), FIT_SIDE)
                predicted = (tr.predicted_expansion(elapsed) or 0.0) * elapsed
                guess = est
                if predicted > est.rate:  # the prediction's rate, the fit's offset
                    ratio = predicted / est.rate if est.rate > 0.0 else 0.0
                    guess = Expansion(est.drift_x * ratio, est.drift_y * ratio, predicted,
                                      est.brightness, est.fit)
                if guess.rate * edge > _REFINE_EDGE:
                    est = refined_expansion(previous, current, boxes[k], est, guess,
                                            background, self.rig.mask)
            tr.measure_reported(est.rate / elapsed, elapsed)

    def _surface_ahead(self, frames: FramePair, cells: int, period: float,
                       scale: tuple[float, float], record: bool
                       ) -> tuple[float, Target, list[TrackReport] | None] | None:
        """With ``surface_ahead`` (or ``corridor_gate``, which reads the same watch), the whole
        view measured (:class:`SurfaceWatch`); with ``surface_ahead``, where it has been a
        surface ahead for :data:`~asnn.approach.surface.SECONDS` at the stream's
        frame ``period`` (:func:`~asnn.approach.surface.surface_frames`), what it adds to the
        summed ``G'`` (the potential of one spike on ``cells`` cells: eq. 32-33), its target
        (the focus of expansion, the whole frame's pixels, a new id for each run of frames)
        and, with ``record``, its report for ``--tracks`` (the whole frame as its box) in a
        list."""
        p = self.params
        if not (p.surface_ahead or p.corridor_gate):
            return None
        watch = self.surface
        s = watch.step(frames.previous, frames.current, frames.elapsed, p.tau_max, p.offset_max,
                       self.rig.mask)
        if not p.surface_ahead or watch.streak < surface_frames(period) or watch.corridor:
            return None
        if watch.id is None:
            watch.id = self.tracker.new_id()
        sx, sy = scale
        h, w = frames.current.shape
        potential = self._surface_potential * cells / p.u_scale
        x, y, ttc = frame_pixel(s.x, sx), frame_pixel(s.y, sy), 1.0 / s.rate
        target = Target(x=x, y=y, direction=0.0, energy=0.0, pixels=round(w * h * sx * sy),
                        id=watch.id, expansion=s.rate, ttc=ttc, offset=s.offset,
                        approaching=True)
        if not record:
            return potential, target, None
        report = TrackReport(
            id=watch.id, object_id=watch.id, x=x, y=y,
            size=math.sqrt((w * w + h * h) / 12.0 * sx * sy), box=(0.0, 0.0, w * sx, h * sy),
            expansion=s.rate, ttc=ttc, offset=s.offset, fit=s.fit, own_expansion=None,
            layers=None, streak=watch.streak,
            test=ApproachVerdict(True, True, False, True, True), counts=True, share=potential)
        return potential, target, [report]

    def _in_corridor(self, period: float) -> bool:
        """Whether the whole view has passed the surface test (over the baseline or over one
        frame: :attr:`SurfaceWatch.view_streak`) for :data:`~asnn.approach.surface.SECONDS` at
        the frame ``period`` and its tiles read a corridor (:attr:`SurfaceWatch.corridor`):
        walls passing around the camera."""
        watch = self.surface
        return watch.corridor and watch.view_streak >= surface_frames(period)

    def _report(self, track, counts: bool, share: float, sx: float, sy: float) -> TrackReport:
        """A track as the approach test saw it in this frame, in the input frame's pixels."""
        x0, y0, x1, y1 = track.box
        return TrackReport(
            id=track.id, object_id=self.tracker.object_id(track),
            x=frame_pixel(track.x, sx), y=frame_pixel(track.y, sy),
            size=float(track.size * math.sqrt(sx * sy)),
            box=(float(x0 * sx), float(y0 * sy), float(x1 * sx), float(y1 * sy)),
            expansion=track.expansion, ttc=track.ttc, offset=track.offset, fit=track.fit,
            own_expansion=track.own_expansion, layers=track.layers, streak=track.streak,
            test=track.verdict, counts=bool(counts), share=share if counts else 0.0)

    def _measure_against_scene(self, tracks: list, boxes: list, rates: list, wholes: list,
                               frames: FramePair) -> None:
        """Each track that otherwise passes the approach test gets its expansion against the
        scene (:meth:`~asnn.approach.tracking.Track.measure_own`); the others None.

        The scene's own expansion is fitted over the frame outside the tracks' boxes
        (:func:`~asnn.approach.looming.scene_expansion`); where it expands, a track's box is fitted
        again leaving out the pixels it explains better than no motion (or than the background's
        translation): what is left is the object's motion against the scene. Where the scene
        does not expand, or by 0.002 per second or less (a time to contact of 500 s or more: no
        motion in depth, and a refit would only trade pixels by rounding), nothing is left out,
        and the box's own rate stands. The rates go to
        :attr:`against_scene` too; with :attr:`measure_all_against_scene` (the held-out
        replay's trace) every growing track's is measured there, and the tracks' state is
        still only that of the candidates.

        With ``receding_scene``, where the scene contracts (the camera moves away from it; by
        more than 0.002 per second),
        the boxes are fitted against it in the same way, and so are those of the tracks that
        pass the partial-overlap regime but for its fit test; the share of each box's change
        that this fit explains goes to :attr:`fit_against_scene` and to the track
        (``own_fit``), whose regime test takes the better of the two fits
        (:func:`~asnn.approach.tracking.approaching`). An object expanding in a contracting scene
        moves against it, so the pixels the scene explains are the scenery's; where the scene
        expands, object and scenery expand alike, and the box's own fit stands. With
        ``receding_edge_rule``, that fit is 0 while the frame's edge cuts the object (``wholes``
        False), as the box's own fit is: its offset is then its visible part's, whatever the fit
        (a car overtaking us into view at the frame's side edge otherwise passes the regime).

        With ``motion_layers``, where the scene expands at least 0.2 per second (our own forward
        motion), each candidate's box is split into its motions
        (:func:`~asnn.approach.motion_layers.motion_layers`, on the frames as the camera gave them),
        per second in :attr:`layers` and to the track
        (:meth:`~asnn.approach.tracking.Track.measure_layers`), whose approach test then needs one
        of them to be an approach (:func:`~asnn.approach.tracking.layers_pass`); with
        :attr:`measure_all_against_scene`, every growing track's box too.
        """
        p = self.params
        overlap = self._overlap
        previous, current, background, elapsed = frames
        rig = self.rig.mask
        chosen = {k for k, tr in enumerate(tracks)
                  if tr.missed == 0 and approach_test(tr.ttc, tr.offset, p.tau_max, p.offset_max,
                                                      tr.fit, overlap)}
        unfit = set()  # passing the regime but for its fit test
        if p.receding_scene and overlap is not None:
            unfit = {k for k, tr in enumerate(tracks)
                     if k not in chosen and tr.missed == 0
                     and approach_test(tr.ttc, tr.offset, p.tau_max, p.offset_max, 1.0, overlap)}
        growing = ({k for k, tr in enumerate(tracks) if tr.ttc is not None}
                   if self.measure_all_against_scene else set())
        # the surface watch (surface_ahead, corridor_gate) has averaged both frames already
        scene = (scene_expansion(previous, current, boxes, background, rig, self._scene_average,
                                 self.surface.averages())
                 if chosen or unfit or growing else None)
        scene_rate = 0.0 if scene is None else scene.rate / elapsed
        contracts = p.receding_scene and scene_rate < -_SCENE_MOVES
        if contracts:
            chosen |= unfit
        against = scene_rate > _SCENE_MOVES or contracts
        if against and (self._scene_reference is None
                        or self._scene_reference.shape != current.shape):
            self._scene_reference = np.empty_like(current)
        for k in sorted(chosen | growing):
            rate, fit = rates[k], None
            if against:
                x0, y0, x1, y1 = box = boxes[k]
                before = (previous if background is None else background)[y0:y1, x0:x1]
                moved = moved_by_expansion(previous, scene, box)
                now = current[y0:y1, x0:x1]
                # per pixel whichever motion explains it better, the scene's or the background's
                # translation (none: the previous frame); region_expansion leaves it out if that
                # beats no motion
                self._scene_reference[y0:y1, x0:x1] = np.where(
                    np.abs(now - moved) < np.abs(now - before), moved, before)
                own = region_expansion(previous, current, box, self._scene_reference, rig)
                rate = None if own is None else own.rate / elapsed
                if contracts and own is not None:
                    fit = own.fit if wholes[k] or not p.receding_edge_rule else 0.0
            self.against_scene[tracks[k].id] = rate
            self.fit_against_scene[tracks[k].id] = fit
        layered = p.motion_layers and scene_rate >= _SCENE_EXPANDS
        for k in sorted(chosen | growing) if layered else ():
            self.layers[tracks[k].id] = [
                (layer.share, layer.rate / elapsed, layer.drift_x / elapsed,
                 layer.drift_y / elapsed)
                for layer in motion_layers(previous, current, boxes[k])]
        ids = {tracks[k].id for k in chosen}
        for tr in self.tracker.tracks:
            if tr.id in ids:
                tr.measure_own(self.against_scene.get(tr.id), self.fit_against_scene.get(tr.id))
                tr.measure_layers(self.layers.get(tr.id))
            else:
                tr.measure_own(None)
                tr.measure_layers(None)
