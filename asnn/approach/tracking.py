"""Tracking of looming targets across frames: ids, smoothed expansion, time to contact.

One :class:`TargetTracker` per stream. Each frame it takes the frame's object observations
(centre, size, box) and links them to the tracks of the previous frames by distance, greedily,
strongest track first. A track keeps its ``id`` while it is seen, and survives ``max_missed``
frames unseen. The caller then measures each seen track's expansion over the track's box (the
direct estimate of :mod:`asnn.approach.looming`) and hands it to :meth:`Track.measure`.

Per track, the expansion rate and the drift are exponentially smoothed. From them:

``ttc``
    Time to contact ``1 / expansion`` in seconds (Lee's tau: size over growth rate), None
    while the target does not grow.
``offset``
    How far off the camera the target's path points, in target sizes:
    ``|drift| / (expansion * size)``. For an object moving at constant velocity relative to the
    camera with lateral offset X and size S, the image drifts at ``x / tau`` and grows at
    ``s / tau``, so this ratio is ``X / S`` whatever the distance: near zero on a collision
    course (constant bearing), large for an object that will pass (a truck in the next lane, a
    pole at the roadside while driving). See :func:`approaching`.
``fit``
    How well one expanding, drifting surface explains the box's change (the smoothed share of
    it the expansion fit explains, :class:`asnn.approach.looming.Expansion`, and 0 while the frame's
    edge cuts the object): the partial-overlap regime of :func:`approach_test` accepts a wider
    offset only from a whole object whose box moves as one.

Persistence: a warning needs a few frames of approach in a row (:meth:`Track.judge`). An
object seen in fragments that change from frame to frame (a walker whose sway splits its
outline, so its head, its feet and its sides are tracked as different objects in turn) never
gives one track that many; with ``region_frames`` the tracker also counts a track that passes
now where approaching tracks overlapped its box in enough of the frames before
(:func:`persists_in_region`): persistence of the approach where it is seen, not of a track id.
An overlap speaks for the region only where it covers a fair share of the box that passes now
(``region_cover``): a large track appearing over a few small passing ones, which it takes in
with the scene around them, has not persisted.

Motion layers: where one box holds two motions (a car pulling away in front of the roadside
that expands behind it under our own forward motion), the fit over the box blends them into an
approach that neither has; with the layers of the box measured (:mod:`asnn.approach.motion_layers`),
a track passes only if one of them is itself an approach (:func:`layers_pass`).

Object ids: the fragments of one object are different tracks, so the target a warning reports
could change its id as one fragment takes over from another. With ``object_ids`` a track that
overlaps a counting track older than itself, before it has counted under its own id, is named
after that track's object (:func:`fragment_of`), and keeps that name: an object is reported
under the id it was first warned under.

References
----------
.. [1] D. N. Lee, "A theory of visual control of braking based on information about
   time-to-collision", Perception 5, 1976, pp. 437-459.
.. [2] D. Regan, A. Kaushal, "Monocular discrimination of the direction of motion in depth",
   Vision Research 34, 1994, pp. 163-177 (the ratio of lateral drift to expansion as the cue to
   where an approaching object will pass).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

__all__ = ["Observation", "Track", "TargetTracker", "approach_test", "approaching", "better_fit",
           "against_scene", "smoothed_run", "boxes_overlap", "box_cover", "persists_in_region",
           "persistence_frames", "count_in_regions", "fragment_of", "layer_estimates",
           "layers_pass", "layers_approach", "LAYER_SHARE", "LAYER_TAU_FACTOR",
           "LAYER_OFFSET_FACTOR", "ApproachVerdict", "approach_verdict", "approach_parts",
           "own_motion_weight"]


@dataclass(frozen=True, slots=True)
class Observation:
    """One object seen in one frame.

    Attributes
    ----------
    x, y : float
        Centre, pixels of the model's grid.
    size : float
        RMS radius of the object's approach activity about its centre, pixels.
    mass : float
        Its summed approach activity (orders the tracks when two compete).
    box : (x0, y0, x1, y1)
        The region its expansion is measured over, pixels (exclusive ends).
    """

    x: float
    y: float
    size: float
    mass: float
    box: tuple[float, float, float, float]


@dataclass(slots=True)
class Track:
    """A target followed across frames.

    Attributes
    ----------
    id : int
        Stable identifier within the stream.
    x, y, size, mass : float
        From the latest observation.
    box : (x0, y0, x1, y1)
        The region the expansion is measured over: each observation's box, blended with the
        previous box carried along by the track's own drift and expansion, so that a target
        whose attended outline changes from frame to frame keeps a steady region.
    expansion : float or None
        Smoothed expansion rate, per second.
    drift_x, drift_y : float
        Smoothed drift, pixels per second.
    missed : int
        Frames since the track was last seen (0: seen in the latest frame).
    streak : int
        Consecutive frames, up to the latest, in which the track passed the approach test
        (:meth:`judge`).
    fit : float or None
        Smoothed share of the box's change that the expansion fit explains (at most 1); the
        model measures 0 while the frame's edge cuts the object (its drift and size are then
        those of its visible part).
    own_expansion : float or None
        Its expansion rate against the scene, per second: measured over the pixels of its box
        that the scene's own expansion does not explain (:meth:`measure_own`), smoothed over
        the consecutive frames in which it is measured; None where it is not (the model
        measures it only while the track otherwise passes the approach test, and only with
        ``scene_relative``).
    own_fit : float or None
        The share of the box's change that the fit against the scene explains, smoothed over
        the same run; the model measures it only where the scene contracts
        (``receding_scene``), and None elsewhere; with ``receding_edge_rule`` it is measured
        as 0 while the frame's edge cuts the object (the 0 enters the smoothed value).
    layers : tuple of (share, ttc, offset), or None
        The motions its box held in the latest frame (:mod:`asnn.approach.motion_layers`): each
        one's share of the box's textured pixels, time to contact in seconds and offset (None unless
        it expands), the offset in this track's size (:meth:`measure_layers`); None where they were
        not measured (the model measures them, with ``motion_layers``, only while the track
        otherwise passes the approach test and the scene expands).
    verdict : ApproachVerdict or None
        The approach test's parts in the latest frame it was judged (:meth:`judge`); None
        before its first.
    reported_expansion : float or None
        The expansion rate its target reports, per second (:meth:`measure_reported`): smoothed
        under a constant-speed approach, from a fit refined where the object grows fast; the
        approach test reads :attr:`expansion`. None until the model measures it (only with
        ``refined_ttc``).
    """

    id: int
    x: float
    y: float
    size: float
    mass: float
    box: tuple[float, float, float, float]
    expansion: float | None = None
    drift_x: float = 0.0
    drift_y: float = 0.0
    missed: int = 0
    streak: int = 0
    fit: float | None = None
    own_expansion: float | None = None
    own_fit: float | None = None
    layers: tuple | None = None
    verdict: "ApproachVerdict | None" = None
    reported_expansion: float | None = None
    _smoothing: float = field(default=0.5, repr=False)

    def observe(self, obs: Observation, elapsed: float, box_weight: float) -> None:
        """Take a new observation of this target, ``elapsed`` seconds after the previous frame.

        The box becomes ``box_weight`` of the observation's box plus the rest of the previous
        box moved by the track's drift and scaled about its centre by its expansion.
        """
        self.x, self.y, self.size, self.mass = obs.x, obs.y, obs.size, obs.mass
        self.missed = 0
        x0, y0, x1, y1 = self.box
        grow = 1.0 + (self.expansion or 0.0) * elapsed
        cx, cy = 0.5 * (x0 + x1) + self.drift_x * elapsed, 0.5 * (y0 + y1) + self.drift_y * elapsed
        hw, hh = 0.5 * (x1 - x0) * grow, 0.5 * (y1 - y0) * grow
        carried = (cx - hw, cy - hh, cx + hw, cy + hh)
        self.box = tuple(box_weight * o + (1.0 - box_weight) * c
                         for o, c in zip(obs.box, carried))

    def measure(self, expansion: float, drift_x: float, drift_y: float,
                fit: float | None = None) -> None:
        """Take this frame's expansion rate (per second), drift (pixels per second) and, where
        known, the share of the box's change the fit explains."""
        if self.expansion is None:
            self.expansion, self.drift_x, self.drift_y = expansion, drift_x, drift_y
        else:
            a = self._smoothing
            self.expansion += a * (expansion - self.expansion)
            self.drift_x += a * (drift_x - self.drift_x)
            self.drift_y += a * (drift_y - self.drift_y)
        if fit is not None:
            self.fit = smoothed_run(self.fit, fit, self._smoothing)

    def measure_own(self, expansion: float | None, fit: float | None = None) -> None:
        """Take this frame's expansion rate against the scene (per second) and that fit's
        share, or None where they are not measured (which ends the run each is smoothed
        over)."""
        self.own_expansion = smoothed_run(self.own_expansion, expansion, self._smoothing)
        self.own_fit = smoothed_run(self.own_fit, fit, self._smoothing)

    def measure_layers(self, layers: Sequence | None) -> None:
        """Take this frame's motion layers ``(share, rate, drift_x, drift_y)`` (rate per
        second, drift in pixels per second at the box centre), or None where they are not
        measured (:func:`layer_estimates`)."""
        self.layers = layer_estimates(layers, self.size)

    def predicted_expansion(self, elapsed: float) -> float | None:
        """:attr:`reported_expansion` ``elapsed`` seconds on, were the object approaching at
        constant speed: its time to contact ``1 / rate`` less ``elapsed``, the rate at most
        doubled (within a frame of contact, where the prediction would run to infinity); the
        rate itself where it does not grow, None before its first measure."""
        rate = self.reported_expansion
        if rate is None or rate <= 0.0:
            return rate
        return rate / max(1.0 - rate * elapsed, 0.5)

    def measure_reported(self, expansion: float, elapsed: float) -> None:
        """Take this frame's expansion rate (per second) for the reported estimate,
        ``elapsed`` seconds after the previous frame.

        An exponential average, as :meth:`measure`'s, but of a prediction: under a
        constant-speed approach the rate ``1 / tau`` rises each frame (tau falls a second per
        second), and an average of the past trails it, reading the time to contact long
        (:meth:`predicted_expansion`). An object that stops measures a rate near 0, which the
        average takes at the same weight: its reported rate halves each frame or so, its time
        to contact lengthens, and it stops counting soon after.
        """
        predicted = self.predicted_expansion(elapsed)
        if predicted is None:
            self.reported_expansion = expansion
        else:
            self.reported_expansion = predicted + self._smoothing * (expansion - predicted)

    @property
    def reported_ttc(self) -> float | None:
        """Time to contact ``1 / reported_expansion``, seconds; None unless it grows."""
        if self.reported_expansion is None or self.reported_expansion <= 0:
            return None
        return 1.0 / self.reported_expansion

    @property
    def ttc(self) -> float | None:
        """Time to contact ``1 / expansion``, seconds; None unless the target grows."""
        if self.expansion is None or self.expansion <= 0:
            return None
        return 1.0 / self.expansion

    @property
    def offset(self) -> float | None:
        """``|drift| / (expansion * size)``: the path's offset from the camera in target sizes;
        None unless the target grows."""
        if self.expansion is None or self.expansion <= 0:
            return None
        return _offset(self.drift_x, self.drift_y, self.expansion, self.size)

    def judge(self, tau_max: float, offset_max: float, frames: int,
              overlap: tuple[float, float, float] | None = None,
              tolerance: float = 0.0) -> bool:
        """Update :attr:`verdict` and :attr:`streak` with this frame's approach test
        (:func:`approach_verdict`) and return whether the track has passed it in the last
        ``frames`` frames in a row: a warning needs a few consecutive frames of approach, not
        one lucky estimate."""
        self.verdict = approach_verdict(self, tau_max, offset_max, overlap, tolerance)
        self.streak = self.streak + 1 if self.verdict.passes else 0
        return self.streak >= frames


class ApproachVerdict(NamedTuple):
    """The parts of the approach test for one track in one frame (:func:`approach_verdict`):
    which of them it passed, so that a warning, or its absence, can be traced to them.

    Attributes
    ----------
    seen : bool
        Seen in the frame (a missed track is not judged on old estimates).
    course : bool
        On a collision course: ``ttc <= tau_max`` and ``offset <= offset_max``.
    overlap : bool
        Not on a collision course but within the partial-overlap regime (its wider limits,
        and a box its fit explains: the better of the box's fit and its fit against the scene).
    scene : bool
        Does not contract against the scene (:func:`against_scene`; True where not measured).
    layers : bool
        One of its box's motion layers is an approach (:func:`layers_pass`; True where not
        measured).
    """

    seen: bool
    course: bool
    overlap: bool
    scene: bool
    layers: bool

    @property
    def passes(self) -> bool:
        """Whether the track passes the test: seen, on a collision course or a partial
        overlap, not contracting against the scene, and a motion layer that approaches."""
        return self.seen and (self.course or self.overlap) and self.scene and self.layers


def approach_verdict(track: Track, tau_max: float, offset_max: float,
                     overlap: tuple[float, float, float] | None = None,
                     tolerance: float = 0.0) -> ApproachVerdict:
    """The approach test's parts for a track in the latest frame (:class:`ApproachVerdict`):
    :func:`approach_parts` of its estimates, with the better of its box's fit and its fit
    against the scene (where that is measured)."""
    return approach_parts(track.ttc, track.offset, better_fit(track.fit, track.own_fit),
                          track.own_expansion, track.expansion, track.layers, tau_max,
                          offset_max, overlap, tolerance, seen=track.missed == 0)


def approach_parts(ttc: float | None, offset: float | None, fit: float | None,
                   own_expansion: float | None, expansion: float | None, layers: tuple | None,
                   tau_max: float, offset_max: float,
                   overlap: tuple[float, float, float] | None = None, tolerance: float = 0.0,
                   seen: bool = True) -> ApproachVerdict:
    """The approach test's parts for an object's estimates (:class:`ApproachVerdict`):
    :func:`approach_test` on a collision course, else in the partial-overlap regime ``overlap``
    (with ``fit``), :func:`against_scene` with ``tolerance``, and :func:`layers_pass`. The one
    composition of the test, for a track (:func:`approach_verdict`) and for the held-out
    replay's traced estimates."""
    course = approach_test(ttc, offset, tau_max, offset_max)
    return ApproachVerdict(
        seen=seen,
        course=course,
        overlap=not course and approach_test(ttc, offset, tau_max, offset_max, fit, overlap),
        scene=against_scene(own_expansion, expansion, tolerance),
        layers=layers_pass(layers, ttc, offset, tau_max, offset_max, overlap))


def approaching(track: Track, tau_max: float, offset_max: float,
                overlap: tuple[float, float, float] | None = None,
                tolerance: float = 0.0) -> bool:
    """Whether a track looks, in the latest frame, like an object coming at the camera: it is
    seen now, passes :func:`approach_test` (with the better of its box's fit and its fit
    against the scene, where that is measured), where its expansion against the scene is
    measured, does not contract against the scene (:func:`against_scene`), and where its
    box's motion layers are measured, one of them is itself an approach
    (:func:`layers_pass`): :attr:`ApproachVerdict.passes` of :func:`approach_verdict`."""
    return approach_verdict(track, tau_max, offset_max, overlap, tolerance).passes


def layer_estimates(layers: Sequence | None, size: float) -> tuple | None:
    """``(share, ttc, offset)`` of each motion layer ``(share, rate, drift_x, drift_y)`` of an
    object's box (rate per second, drift in pixels per second at the box centre), its offset
    in the object's ``size`` as :attr:`Track.offset`; ttc and offset None unless the layer
    expands. None for None or no layers (the box held no motion to split: not measured)."""
    if not layers:
        return None
    return tuple((share, 1.0 / rate, _offset(dx, dy, rate, size))
                 if rate > 0 else (share, None, None)
                 for share, rate, dx, dy in layers)


def _offset(drift_x: float, drift_y: float, rate: float, size: float) -> float:
    """``|drift| / (rate * size)`` (:attr:`Track.offset`), the size at least 1 pixel."""
    return math.hypot(drift_x, drift_y) / (rate * max(size, 1.0))


def layers_pass(layers: tuple | None, ttc: float | None, offset: float | None, tau_max: float,
                offset_max: float, overlap: tuple[float, float, float] | None = None) -> bool:
    """The motion-layer part of the approach test for an object that passes the rest of it:
    where its layers are measured, one of them must be an approach (:func:`layers_approach`)
    within the limits of the test the object passes (the collision-course test's, else the
    partial-overlap regime's)."""
    if layers is None:
        return True
    if approach_test(ttc, offset, tau_max, offset_max):
        return layers_approach(layers, tau_max, offset_max)
    return overlap is not None and layers_approach(layers, overlap[0], overlap[1])


# a motion of a box counts as an approach with these margins over the test's own limits: a
# layer's estimate is one frame's, from the flow of part of the box (set on the suite's
# fresh-scenery variants 1-5: README, the stage table; docs/design-notes.md, "Motion layers")
LAYER_SHARE = 0.15
LAYER_TAU_FACTOR = 3.0
LAYER_OFFSET_FACTOR = 2.5


def layers_approach(layers: Iterable[tuple[float, float | None, float | None]], tau: float,
                    offset_limit: float) -> bool:
    """Whether one of a box's motions (``(share, ttc, offset)``, :attr:`Track.layers`) is
    itself an approach: it holds at least :data:`LAYER_SHARE` of the box's textured pixels,
    expands, reaches the camera within :data:`LAYER_TAU_FACTOR` times ``tau`` and points at it
    within :data:`LAYER_OFFSET_FACTOR` times ``offset_limit``.

    A box whose looming fit blends motions that none of its parts has (a car pulling away in
    front of the roadside expanding behind it, under our own forward motion) fails: its car
    contracts, its roadside drifts outward from our heading (a large offset). The margins are
    wide because a layer's estimate is one frame's, from part of the box: the test refuses
    only boxes where no motion looks like an approach at all.
    """
    return any(share >= LAYER_SHARE and ttc is not None and ttc <= LAYER_TAU_FACTOR * tau
               and offset is not None and offset <= LAYER_OFFSET_FACTOR * offset_limit
               for share, ttc, offset in layers)


def better_fit(fit: float | None, own_fit: float | None) -> float | None:
    """The larger of a box's fit and its fit against the scene (None: not measured)."""
    if own_fit is None or (fit is not None and fit >= own_fit):
        return fit
    return own_fit


def smoothed_run(average: float | None, value: float | None, weight: float) -> float | None:
    """A running average over consecutive measurements: ``value`` starts it (``average`` None),
    None ends it, and otherwise it moves by ``weight`` of the difference."""
    if value is None or average is None:
        return value
    return average + weight * (value - average)


def against_scene(own_expansion: float | None, expansion: float | None = None,
                  tolerance: float = 0.0) -> bool:
    """The scene-relative test: an object coming at the camera still expands once the pixels
    the scene's own expansion explains are left out of its fit: ``own_expansion >= -tolerance *
    expansion`` (None, not measured, passes). A car that cuts in ahead and pulls away, seen in
    one box with the roadside behind it, fails it: its box expands with the roadside, the car
    itself contracts. ``tolerance`` (a fraction of the track's own expansion rate) keeps a
    rate that is zero within the fit's noise from failing it: the second fit is over fewer
    pixels than the first."""
    if own_expansion is None:
        return True
    return own_expansion >= -tolerance * max(expansion or 0.0, 0.0)


def own_motion_weight(own_expansion: float | None, expansion: float | None, weight: float,
                      ratio: float) -> float:
    """The weight of a counting object's share of ``u``: ``weight`` where it approaches by its
    own motion, its expansion against the scene at least ``ratio`` of its own
    (``own_expansion >= ratio * expansion``), else 1.

    We drive at a parked car or the roadside, so their expansion is mostly the scene's; an
    object whose expansion the scene does not explain (a car turning across our path, a
    walker coming at a still camera) closes on us by itself, and is the more salient: the
    retina's object-motion-sensitive ganglion cells answer motion against the background and
    are silenced by the global motion the eye's own movement makes [1]_. Such an object's
    energy counts ``weight`` times (a dim one at night reaches the warning with less).

    Parameters
    ----------
    own_expansion : float or None
        The track's expansion rate against the scene, per second
        (:attr:`Track.own_expansion`; None where not measured: weight 1).
    expansion : float or None
        Its own expansion rate, per second (None or not above 0: weight 1).
    weight : float
        The weight of an object approaching by its own motion (1: every object alike).
    ratio : float
        The share of its own expansion its expansion against the scene must keep.

    Returns
    -------
    float

    References
    ----------
    .. [1] B. P. Olveczky, S. A. Baccus and M. Meister, "Segregation of object and
       background motion in the retina", Nature 423, 401-408 (2003).
    """
    if own_expansion is None or expansion is None or expansion <= 0:
        return 1.0
    return weight if own_expansion >= ratio * expansion else 1.0


def approach_test(ttc: float | None, offset: float | None, tau_max: float,
                  offset_max: float, fit: float | None = None,
                  overlap: tuple[float, float, float] | None = None) -> bool:
    """The approach test on a target's estimates.

    On a collision course: it reaches the camera within ``tau_max`` seconds at its current
    rate, and points at it (``offset <= offset_max``). With ``overlap = (tau, offset, fit_min)``
    also on a partial overlap: within ``tau`` seconds, ``offset`` at most the wider
    ``overlap[1]``, and a box that moves as one surface (``fit >= fit_min``; None fails).

    ``offset_max`` 1 is a path through the camera's own line of sight, right for a point-like
    camera; a car is as wide as the car that may hit it, and a partial-overlap collision (the
    commonest between cars) reads up to about 2.4. A wider offset is also what a misread
    expansion gives (a box holding an object and the scenery moving apart, which least squares
    reads as growth: offsets are drift over expansion), so it is accepted only later and only
    from a box the fit explains well.
    """
    if ttc is None or offset is None:
        return False
    if ttc <= tau_max and offset <= offset_max:
        return True
    return (overlap is not None and ttc <= overlap[0] and offset <= overlap[1]
            and fit is not None and fit >= overlap[2])


def boxes_overlap(a: Sequence[float], b: Sequence[float]) -> bool:
    """Whether two boxes ``(x0, y0, x1, y1)`` (exclusive ends) overlap; touching is not
    overlapping."""
    return b[0] < a[2] and a[0] < b[2] and b[1] < a[3] and a[1] < b[3]


def persists_in_region(box: Sequence[float], history: Iterable[Sequence[Sequence[float]]],
                       frames: int, cover: float = 0.0) -> bool:
    """Whether an approach seen in ``box`` now persisted in its region: in at least
    ``frames - 1`` of the earlier frames of ``history`` (each a list of the boxes of the tracks
    that passed the approach test then) a box overlapped it (:func:`boxes_overlap`) and covered
    at least the share ``cover`` of its area (:func:`box_cover`; 0: any overlap)."""
    seen = sum(any(boxes_overlap(box, b) and box_cover(box, b) >= cover for b in boxes)
               for boxes in history)
    return seen >= frames - 1


def box_cover(box: Sequence[float], other: Sequence[float]) -> float:
    """The share of ``box``'s area that ``other`` covers, in [0, 1] (0 for an empty box)."""
    width = min(box[2], other[2]) - max(box[0], other[0])
    height = min(box[3], other[3]) - max(box[1], other[1])
    area = (box[2] - box[0]) * (box[3] - box[1])
    return max(width, 0.0) * max(height, 0.0) / area if area > 0 else 0.0


def persistence_frames(frames: int, seconds: float | None, period: float) -> int:
    """Consecutive frames of approach a track needs: ``frames``, or fewer where fewer frames
    already span ``seconds`` at the frame ``period`` (s): ``k`` frames span ``(k - 1) * period``.

    The persistence of the approach test was set at 20 fps, where 3 frames span 0.1 s. A slower
    stream (a 10 fps camera, or a worker that skips every second frame under load) sees the
    object's image move twice as far between frames, and its estimates settle in fewer frames
    than the tracker needs to follow it: at 0.1 s, 2 frames in a row at 10 fps or slower.
    Faster streams keep ``frames`` (at 30 fps, 3 frames span 0.067 s).
    """
    if seconds is None or period <= 0.0:
        return frames
    # a thousandth of a frame's slack: timestamps 0.1 s apart read 0.0999... in floating point
    return max(1, min(frames, 1 + math.ceil(seconds / period - 1e-3)))


def count_in_regions(boxes: Sequence[Sequence[float]], passing: Sequence[bool],
                     steady: Sequence[bool], history: Iterable[Sequence[Sequence[float]]],
                     frames: int, cover: float = 0.0) -> list[bool]:
    """Which of a frame's tracks count as coming at the camera with region persistence.

    A track counts when it passed the approach test in its own last ``frames`` frames
    (``steady``), or when it passes now (``passing``), the approach persisted in its region
    (:func:`persists_in_region` over ``history``, with ``cover``) and no steady track's box
    overlaps it: that track speaks for the object, and this one would be a fragment of it (one
    target per object).
    """
    counted = [box for box, ok in zip(boxes, steady) if ok]
    return [ok or (passed and not any(boxes_overlap(box, other) for other in counted)
                   and persists_in_region(box, history, frames, cover))
            for box, passed, ok in zip(boxes, passing, steady)]


def fragment_of(box: Sequence[float], track_id: int,
                counting: Iterable[tuple[int, Sequence[float]]]) -> int | None:
    """The id of the oldest of the ``counting`` tracks, ``(id, box)``, older than ``track_id``
    (a smaller id) whose box overlaps ``box`` (:func:`boxes_overlap`); None if there is none.
    A track that appears over an object already counted is a fragment of that object."""
    older = [other for other, other_box in counting
             if other < track_id and boxes_overlap(box, other_box)]
    return min(older) if older else None


class TargetTracker:
    """Links each frame's observations to tracks (one tracker per stream).

    Parameters
    ----------
    link : float
        An observation continues a track when their centres are closer than
        ``link * (track size + observation size) + 8`` pixels.
    max_missed : int
        Frames a track survives unseen.
    smoothing : float
        Weight of a new expansion and drift estimate in the track's running average, (0, 1].
    box_weight : float
        Weight of a new observation's box in the track's box, (0, 1] (see :class:`Track`).
    region_frames : int
        With N > 0, :meth:`judge` also counts a track that passes the approach test now where
        passing tracks overlapped its box in ``frames - 1`` of the previous ``frames`` frames
        (:func:`persists_in_region`; ``frames`` is :meth:`judge`'s, the stream's persistence,
        at most N: N frames are kept); 0 counts each track's own frames only.
    region_cover : float
        With ``region_frames``, the share of the passing track's box an earlier box must cover
        to speak for its region, in [0, 1] (0: any overlap).
    object_ids : bool
        Name a fragment after the object it is part of (:meth:`object_id`): a track that,
        before it counted under its own id, overlapped a track counting in that frame or in
        one of the ``region_frames`` before it (one, without region persistence), takes the
        older track's object id for good (:func:`fragment_of`).

    Attributes
    ----------
    tracks : list of Track
        Live tracks, seen or recently missed.
    """

    def __init__(self, link: float = 1.0, max_missed: int = 3, smoothing: float = 0.5,
                 box_weight: float = 1.0, region_frames: int = 0, object_ids: bool = False,
                 region_cover: float = 0.0):
        for name, value in (("smoothing", smoothing), ("box_weight", box_weight)):
            if not 0.0 < value <= 1.0:
                raise ValueError(f"{name} must lie in (0, 1], got {value}")
        if region_frames < 0:
            raise ValueError(f"region_frames must be >= 0, got {region_frames}")
        if not 0.0 <= region_cover <= 1.0:
            raise ValueError(f"region_cover must lie in [0, 1], got {region_cover}")
        self.region_cover = region_cover
        self.link = link
        self.max_missed = max_missed
        self.smoothing = smoothing
        self.box_weight = box_weight
        self.tracks: list[Track] = []
        self._next_id = 0
        # the boxes of the tracks that passed the approach test, per frame, this frame's last
        self._passed: deque[list] | None = (deque(maxlen=region_frames + 1) if region_frames
                                            else None)
        # with object_ids: the object each fragment was named after, the ids that counted under
        # their own name, and the (id, box) of the tracks that counted in each of the frames
        # before, as many as region persistence looks back over (a track counted through its
        # region, after the object's own track missed the test for a frame, is a fragment of it)
        self._object_of: dict[int, int] | None = {} if object_ids else None
        self._named: set[int] = set()
        self._counted: deque[list[tuple[int, tuple]]] = deque(maxlen=max(region_frames, 1))

    def update(self, observations: list[Observation], elapsed: float) -> list[Track]:
        """Link this frame's observations to tracks, ``elapsed`` seconds after the previous frame.

        Returns
        -------
        list of Track
            The track of each observation, in the observations' order.
        """
        if self._passed is not None:
            self._passed.append([])
        assigned: list[Track | None] = [None] * len(observations)
        for track in sorted(self.tracks, key=lambda tr: -tr.mass):
            best, best_d = -1, math.inf
            for i, obs in enumerate(observations):
                if assigned[i] is not None:
                    continue
                d = math.hypot(obs.x - track.x, obs.y - track.y)
                if d < self.link * (track.size + obs.size) + 8.0 and d < best_d:
                    best, best_d = i, d
            if best < 0:
                track.missed += 1
            else:
                track.observe(observations[best], elapsed, self.box_weight)
                assigned[best] = track
        self.tracks = [tr for tr in self.tracks if tr.missed <= self.max_missed]
        for i, obs in enumerate(observations):
            if assigned[i] is None:
                track = Track(self._next_id, obs.x, obs.y, obs.size, obs.mass, obs.box,
                              _smoothing=self.smoothing)
                self._next_id += 1
                self.tracks.append(track)
                assigned[i] = track
        return assigned

    def judge(self, tracks: Sequence[Track], tau_max: float, offset_max: float, frames: int,
              overlap: tuple[float, float, float] | None = None,
              tolerance: float = 0.0) -> list[bool]:
        """Whether each of this frame's tracks (what :meth:`update` returned) counts as coming
        at the camera: it passed the approach test in its last ``frames`` frames in a row
        (:meth:`Track.judge`), or, with ``region_frames``, by :func:`count_in_regions`."""
        coming = [track.judge(tau_max, offset_max, frames, overlap, tolerance)
                  for track in tracks]
        if self._passed is not None:
            boxes = [track.box for track in tracks]
            passing = [track.streak > 0 for track in tracks]
            history = list(self._passed)[-frames - 1:-1]  # the previous `frames` frames
            coming = count_in_regions(boxes, passing, coming, history, frames,
                                      self.region_cover)
            self._passed[-1] = [box for box, passed in zip(boxes, passing) if passed]
        if self._object_of is not None:
            self._name_objects(tracks, coming)
        return coming

    def new_id(self) -> int:
        """An id no track has had or will have: for a target that is not a track (the
        surface ahead, :mod:`asnn.approach.surface`)."""
        self._next_id += 1
        return self._next_id - 1

    def object_id(self, track: Track) -> int:
        """The id to report ``track`` under: its object's (with ``object_ids``, the track a
        fragment was named after), else its own."""
        if self._object_of is None:
            return track.id
        return self._object_of.get(track.id, track.id)

    def _name_objects(self, tracks: Sequence[Track], coming: Sequence[bool]) -> None:
        """Name this frame's new fragments after the objects they overlap (``object_ids``)."""
        counting = [(track.id, track.box) for track, ok in zip(tracks, coming) if ok]
        for track in tracks:
            if track.id in self._object_of or track.id in self._named:
                continue
            older = fragment_of(track.box, track.id,
                                counting + [c for frame in self._counted for c in frame])
            if older is not None:
                self._object_of[track.id] = self._object_of.get(older, older)
        self._named.update(i for i, _ in counting if i not in self._object_of)
        self._counted.append(counting)
        # only live tracks need a name: the stream's state stays as small as its tracks
        live = {track.id for track in self.tracks}
        self._object_of = {i: name for i, name in self._object_of.items() if i in live}
        self._named &= live
