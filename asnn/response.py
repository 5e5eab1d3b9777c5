"""What every detector returns for one frame."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .targets import Target

if TYPE_CHECKING:  # the approach stage builds its reports from this module: no import cycle
    from .approach.tracking import ApproachVerdict

__all__ = ["Maps", "Response", "TrackReport"]


@dataclass(frozen=True, slots=True)
class Maps:
    """Intermediate maps of one ASNN step, for figures and debugging (all (H, W) unless noted).

    The maps are on the model's own grid: the frame's size, or where ``max_width`` shrinks
    wider frames (or taller ones, past a 3:4 portrait's area) or ``min_width`` enlarges
    narrower ones, that size (targets and tracks stay in the frame's pixels). ``P`` is
    the photoreceptors' output after the input stages the preset has (input blur, widened and
    summed in time in a dim, noisy view; global brightness compensation; background
    stabilisation; contrast gain control, light-adapted), not the raw frame difference. The
    bipolar and temporal-filter outputs are not kept: the bipolar inputs are
    :func:`asnn.retina.bipolar` of ``P`` with the preset's :func:`asnn.retina.dog_kernel` (ON
    and OFF swapped for ``target_polarity="light"``), and an ``ASNN(..., optimised=False)``
    model keeps its cascades as eq. 5 writes them (``stages_on``, ``stages_off``), from which
    :func:`asnn.retina.temporal_readout` gives the temporal filter's outputs (the optimised
    form keeps them in another form; with ``leaky_input`` the first stage integrates the
    bipolar input rather than holding it).

    The float maps are in the model's dtype (:attr:`asnn.ASNN.dtype`: the preset's
    ``precision``, float64 with ``optimised=False``).

    Attributes
    ----------
    P : ndarray (H, W)
        Photoreceptor activation (eq. 1; after the input stages the preset has, above).
    R : ndarray (n_theta, H, W)
        Motion energy per orientation theta_k = 2 pi k / n_theta (eqs. 10, 15, 16; n_theta 8).
    V : ndarray (H, W)
        Maximal motion energy over orientations (eq. 17).
    phi : ndarray (H, W)
        Estimated motion direction, radians in [-pi, pi], image coordinates (eq. 18).
    G : ndarray (H, W)
        Approach-sensitive map (eqs. 19, 20; after grouping, where the preset groups).
    M_a, M_d : ndarray of bool (H, W)
        The approach and the directional attention masks (eqs. 23, 26).
    G_prime : ndarray (H, W)
        G M_a M_d (eq. 27).
    rig : ndarray of bool (H, W), or None
        The pixels the looming fits left out as the camera's own rig (``ignore_rig``;
        :func:`asnn.approach.looming.rig_pixels`); None where none were.
    """

    P: np.ndarray
    R: np.ndarray
    V: np.ndarray
    phi: np.ndarray
    G: np.ndarray
    M_a: np.ndarray
    M_d: np.ndarray
    G_prime: np.ndarray
    rig: np.ndarray | None = None


@dataclass(frozen=True, slots=True)
class TrackReport:
    """One tracked object as the approach test saw it in one frame, for tracing why the model
    warned or stayed silent (:class:`asnn.model.ASNN` with ``record_tracks``). The surface
    ahead (``surface_ahead``), in the frames it counts, is reported as one more: the whole
    frame as its box, its RMS radius as its size, the whole frame's fit, and a test passed on
    the collision course.

    Attributes
    ----------
    id : int
        The track's own id.
    object_id : int
        The id its target is reported under (the object a fragment is part of; else ``id``).
    x, y : float
        Centre, input-frame pixels.
    size : float
        RMS radius of its approach activity, input-frame pixels.
    box : (x0, y0, x1, y1)
        The region its expansion is measured over, input-frame pixels.
    expansion, ttc, offset, fit, own_expansion, layers
        As :class:`asnn.approach.tracking.Track` keeps them (per second, seconds, object sizes,
        share; ``layers`` as ``(share, ttc, offset)`` per motion of the box, None where not
        measured): what the approach test read. A target's own ``expansion`` and ``ttc`` can
        differ (``refined_ttc``: :attr:`~asnn.approach.tracking.Track.reported_expansion`).
    streak : int
        Consecutive frames, up to this one, in which it passed the approach test.
    test : ApproachVerdict
        The approach test's parts in this frame (:func:`asnn.approach.tracking.approach_verdict`).
    counts : bool
        Whether it counts as coming at the camera in this frame (its streak, or the region's
        persistence: :meth:`asnn.approach.tracking.TargetTracker.judge`): only these drive u(t).
    share : float
        What it adds to u(t) before ``u_scale``, where it counts: its share of the attended
        ``G'``, times ``own_motion_weight`` where it closes on us by its own motion.
    """

    id: int
    object_id: int
    x: float
    y: float
    size: float
    box: tuple[float, float, float, float]
    expansion: float | None
    ttc: float | None
    offset: float | None
    fit: float | None
    own_expansion: float | None
    layers: tuple | None
    streak: int
    test: ApproachVerdict
    counts: bool
    share: float

    def to_dict(self) -> dict:
        """JSON-ready fields (the test's parts and ``passes`` as a map).

        Returns
        -------
        dict
            Every field by its name, ``box`` and ``layers`` as lists, ``test`` as a map of the
            approach test's parts and ``passes``.
        """
        return {"id": self.id, "object_id": self.object_id, "x": self.x, "y": self.y,
                "size": self.size, "box": list(self.box), "expansion": self.expansion,
                "ttc": self.ttc, "offset": self.offset, "fit": self.fit,
                "own_expansion": self.own_expansion,
                "layers": None if self.layers is None else [list(m) for m in self.layers],
                "streak": self.streak,
                "test": {**self.test._asdict(), "passes": self.test.passes},
                "counts": self.counts, "share": self.share}


@dataclass(frozen=True, slots=True)
class Response:
    """One frame's output of a detector.

    Attributes
    ----------
    index : int
        0-based number of the frame in the stream.
    u : float
        Membrane potential u(t) (paper eq. 28; for the LGMD models, their summed excitation).
        With the approach gate (``approach_gate``, the default preset) it sums G' over the
        objects that count as coming at the camera only (``TrackReport.share``), so it can be
        0 where G' is not.
    out : float
        Sigmoid output in [0.5, 1] (1.0 only where it saturates in floating point).
    spikes : int
        Spikes fired in this frame.
    spike_rate : float
        The spikes of the warning window (the last ``n_t`` frames) over ``n_t`` times the
        window's frame period (``spike_dt``, or ``dt``): spikes per second of the frames where
        ``spike_dt`` is None and frames come ``dt`` apart. The presets that keep the published
        window of 25 ms a frame whatever the frame rate (``reference``, ``reference32``,
        ``light``, the default; eq. 34) read twice the spikes per second of 20 fps frames,
        1.33 times those of 30 fps frames.
    collision : bool
        The collision warning.
    targets : list of Target
        Looming regions (always empty for the LGMD models).
    maps : Maps or None
        Intermediate maps when the model was asked to record them; None on a stream's first
        frame, which only primes the model (:meth:`silent`).
    tracks : list of TrackReport or None
        Every object tracked in the frame with its approach test, when the model was asked to
        record them (presets that track objects).
    """

    index: int
    u: float
    out: float
    spikes: int
    spike_rate: float
    collision: bool
    targets: list[Target] = field(default_factory=list)
    maps: Maps | None = None
    tracks: list[TrackReport] | None = None

    @classmethod
    def silent(cls, index: int, tracks: list[TrackReport] | None = None) -> "Response":
        """The response to a frame that only primes a stream (its first): u = 0, no spikes.

        Parameters
        ----------
        index : int
            The frame's index in its stream.
        tracks : list of TrackReport, optional
            None where tracks are not recorded, ``[]`` where they are (there are none yet).

        Returns
        -------
        Response
            u = 0, out = 0.5, no spikes, a spike rate of 0, no warning and no targets.
        """
        return cls(index=index, u=0.0, out=0.5, spikes=0, spike_rate=0.0, collision=False,
                   tracks=tracks)

    def to_dict(self) -> dict:
        """JSON-ready fields (maps and tracks excluded).

        Returns
        -------
        dict
            ``u``, ``out``, ``spikes``, ``spike_rate``, ``collision`` as Python numbers and
            bool, and ``targets`` as a list of :meth:`Target.to_dict <asnn.targets.Target.to_dict>`
            maps (``index`` excluded too: :meth:`record` adds the frame's number and time).
        """
        return {"u": self.u, "out": self.out, "spikes": self.spikes,
                "spike_rate": self.spike_rate, "collision": self.collision,
                "targets": [t.to_dict() for t in self.targets]}

    def record(self, frame: int, t: float) -> dict:
        """The frame's line of ``asnn detect --jsonl`` (CONTRACT.md), what
        :func:`asnn.evaluation.scoring.score_clip` reads.

        Parameters
        ----------
        frame : int
            The frame's number in the clip (0-based).
        t : float
            Its time in seconds, rounded to the microsecond.

        Returns
        -------
        dict
            ``frame``, ``t`` and :meth:`to_dict`'s fields.
        """
        return {"frame": frame, "t": round(t, 6), **self.to_dict()}
