"""The ASNN model: one stateful object per camera stream, ``step(frame) -> Response``.

``ASNN.step`` has two implementations of the same equations. The straightforward one calls the
functions of :mod:`asnn.retina` stage by stage on float64 arrays: it is the definition, and
``ASNN(params, optimised=False)`` runs it. The optimised one (the default) computes the
expensive stages with the fused kernels of :mod:`asnn._fast`, in the preset's ``precision``;
the cheap stages (photoreceptors, attention blurs, output, targets) call the same retina
functions. ``tests/test_equivalence.py`` keeps the two together.

A step has three parts: taking the frame (luminance, repeats, the background's translation,
photoreceptors), the fused pass (everything that advances the retina's state) and finishing
(attention, output, and, for presets that track objects, the objects, looming fits, tracks and
approach gate of :class:`asnn.approach.ApproachStage`). ``ASNN(params, threads=N)`` computes
the fused pass in bands on N threads, and ``ASNN.stream`` finishes each frame while the next
one's pass runs (:mod:`asnn._parallel`); the responses are those of ``step``, bit for bit.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import statistics
import sys
import threading
import weakref
from collections import deque
from collections.abc import Iterable, Iterator

import cv2
import numpy as np

from . import _fast, _parallel, brightness, light, retina, summation
from .approach import ApproachStage, FramePair, frame_pixel
from .errors import TimingWarning, _warn_at_caller
from .frames import LEVELS, FrameError, check_frame, frame_time, luma, to_luminance
from .params import (CEILING_GAPS, CEILING_MARGIN, CEILING_MIN_GAPS, MAX_THREADS,
                     MAX_FRAME_GAP_S, MIN_FRAME_GAP_S, PERIOD_FRAMES, ASNNParams, preset, timed_gap)
from .response import Maps, Response
from .stabilisation import background_shift, search_radius, shift_image
from .targets import extract_targets

TIMED_RUN = 3  # gaps believed in a row before one over MAX_FRAME_GAP_S is believed too
SAME_INSTANT_HELD = 2  # frames in a row at one instant the frame-rate ceiling may hold

__all__ = ["ASNN", "FrameError", "spike_step"]

N_ORIENTATIONS = 8  # theta = k pi / 4; four are computed, four are their negatives


class ASNN:
    """Approach-Sensitive Neural Network for one stream of frames.

    Parameters
    ----------
    params : ASNNParams or str
        A parameter set or a preset name (see :mod:`asnn.params`).
    record_maps : bool
        Attach the intermediate maps (:class:`~asnn.response.Maps`) to every response but a
        stream's first (it only primes the model: ``maps`` is None).
    record_tracks : bool
        Attach every tracked object with its approach test
        (:class:`~asnn.response.TrackReport`) to every response: why the model warned, or did
        not. Presets that track objects only (``targets='objects'``).
    optimised : bool
        Use the fused kernels of :mod:`asnn._fast` in ``params.precision`` (default), or the
        straightforward float64 form of :mod:`asnn.retina` (``False``; for comparisons). Kernel
        sizes other than 5x5 always use the straightforward form.
    threads : int
        Threads the optimised form uses for one stream, 1 to :data:`asnn.params.MAX_THREADS`
        (256; default 1: only the calling one). With
        more, each frame's fused pass is computed in bands of rows, one per thread, and
        :meth:`stream` finishes each frame (attention, objects, tracking, output) on the calling
        thread while the worker threads compute the next frame's pass. The results are the same
        whatever the number: only the time changes. The worker threads belong to the model
        (:meth:`close`, or a ``with`` block); the model is still used from one thread at a
        time. A process that steps many models at once on threads of its own (the service's
        worker) leaves this at 1.

    Attributes
    ----------
    params : ASNNParams
    index : int
        Frames taken since the stream began (or :meth:`reset`): the next response's ``index``.
    shape : (H, W) or None
        The stream's frame size, fixed by its first frame.
    min_side : int
        The smallest height and width of a frame the model takes (its largest kernel's).
    previous : ndarray (H, W)
        Luminance of the last frame, after the optional input blur.
    previous_blocks : ndarray or None
        Its means over ``repeat_block`` x ``repeat_block`` blocks, what the next frame's
        repeat test compares (``skip_repeats``; None without it).
    history : deque of ndarray (H, W)
        The last N_p photoreceptor activations, most recent first.
    stages_on, stages_off : ndarray (n_s + 2, H, W)
        Leaky-integrator cascades of the ON and OFF bipolar channels (z_0..z_{n_s+1}), in
        :attr:`dtype`; the optimised step keeps them in difference form
        (:func:`asnn._fast.to_differences`). With ``threads`` > 1 the rows where two threads'
        bands meet live in a second pair of arrays during a stream.
    dtype : numpy dtype
        Floating-point type of the state and the computation.
    spike_window : deque of int
        Spikes of the last N_t frames.
    approach : ApproachStage or None
        The objects of the attended masks, their tracks and which of them approach
        (:class:`~asnn.approach.ApproachStage`: the tracker, the objects of the latest frame,
        the camera's rig), for presets with ``targets='objects'``; None for the others.
    repeated : bool
        Whether the latest frame was a repeat (its response repeats the one before), or was
        held by the frame-rate ceiling (``params.max_step_rate``).
    ceiling_held : int
        Frames of the stream the frame-rate ceiling held (answered as the frame before, not
        stepped): :attr:`index` less this is what a hand-over's warm-up counts (a repeated
        frame, held by the repeat test, counts there: both models hold it alike).
    periods : deque of float
        The times between the last processed frames, seconds (at most 5; repeats not counted):
        :attr:`frame_period` is their median.

    Raises
    ------
    TypeError
        If ``params`` is neither a preset's name nor an :class:`~asnn.params.ASNNParams`,
        ``threads`` is not an int, or a flag is not True or False.
    ValueError
        If the preset's name is unknown or the parameters are invalid, ``record_tracks`` is
        asked of a preset that does not track objects, or ``threads`` is out of range.

    Notes
    -----
    The retina integrates with the fixed step ``params.dt`` (0.05 s by default) whatever the
    frames' timestamps: the paper assumes a constant frame rate. Time to contact and expansion
    rates are measured in the frames' own time: ``step(frame, t)`` with the frame's timestamp in
    seconds, or ``params.dt`` per frame without one. The first frame of a stream only primes
    the state: its response is silent (u = 0, out = 0.5, no spikes, no targets).

    Examples
    --------
    One model per stream, stepped with each frame and its time in seconds; here a generated
    scene, a dark disk on a 64 x 64 view that starts growing at frame 10 (20 fps):

    >>> from asnn import ASNN
    >>> from asnn.stimuli import make_scene
    >>> scene = make_scene("looming", size=(64, 64))
    >>> model = ASNN("default")
    >>> responses = [model.step(frame, i / scene.fps) for i, frame in enumerate(scene.frames)]
    >>> responses[0].u, responses[0].collision  # the first frame only primes the model
    (0.0, False)
    >>> warned = [r.index for r in responses if r.collision]
    >>> scene.onset_frame < warned[0] < scene.contact_frame  # warned during the approach
    True
    >>> target = responses[warned[0]].targets[0]  # what approaches: where, and how soon
    >>> target.approaching, 0 < target.ttc < 5, 0 <= target.x < 64
    (True, True, True)

    :meth:`stream` takes ``(t, frame)`` pairs and yields the same responses; :meth:`reset`
    starts a new stream.
    """

    _close_pending = False  # the instance's; a class default for models pickled before it
    _unfinished = 0  # likewise (see _claim)
    # the brightness compensation's state (reset), likewise: a model pickled before the stage
    # measures its first change on the frame after the next
    _log_gain = 0.0
    _sampled: np.ndarray | None = None

    def __init__(self, params: ASNNParams | str = "default", *, record_maps: bool = False,
                 record_tracks: bool = False, optimised: bool = True, threads: int = 1):
        if isinstance(params, str):
            params = preset(params)
        elif not isinstance(params, ASNNParams):
            raise TypeError("params must be a preset's name or an ASNNParams (asnn.preset(name, "
                            f"**changes) makes one), got {type(params).__name__}")
        if isinstance(threads, bool) or not isinstance(threads, numbers.Integral):
            raise TypeError(f"threads must be an int, got {threads!r}")
        for name, flag in (("record_maps", record_maps), ("record_tracks", record_tracks),
                           ("optimised", optimised)):
            if not isinstance(flag, (bool, np.bool_)):  # bool("no") is True
                raise TypeError(f"{name} must be True or False, got {flag!r}")
        # validated again: pydantic's model_copy(update=...) skips the checks, and the kernels
        # index by the parameters without bounds checks (n_fast >= n_slow read past an array)
        params = ASNNParams.model_validate(params.model_dump())
        self.params = params
        self.record_maps = bool(record_maps)
        p = self.params
        if record_tracks and p.targets != "objects":
            raise ValueError("record_tracks needs a preset that tracks objects "
                             f"(targets='objects'), not targets={p.targets!r}")
        self.record_tracks = bool(record_tracks)
        self.optimised = bool(optimised) and _fast.supported(p)
        self.dtype = np.dtype(p.precision if self.optimised else np.float64)
        self.min_side = p.min_side
        self._p_weights = retina.photoreceptor_weights(p.n_p, p.p_u)
        self._dog = retina.dog_kernel(p.dog_gain, p.dog_sigma1, p.dog_sigma2, p.dog_size,
                                      p.dog_normalisation)
        half = N_ORIENTATIONS // 2
        self._gabor = [retina.gabor_pair(k * math.pi / half, p.ds_sigma, p.ds_wavelength,
                                         p.kernel_size, p.kernel_extent) for k in range(half)]
        self._cs = retina.center_surround_kernel(p.cs_sigma, p.cs_wavelength, p.cs_phase,
                                                 p.kernel_size, p.kernel_extent)
        if not 1 <= threads <= MAX_THREADS:
            raise ValueError(f"threads must be 1 to {MAX_THREADS}, got {threads}")
        # band servers poll POSIX clocks (asnn._parallel); elsewhere the model uses one thread
        self.threads = int(threads) if self.optimised and _parallel.supported() else 1
        self._banded: _parallel.BandedFront | None = None
        self._in_use = threading.Lock()  # a step or a stream in progress (_claim)
        self._close_pending = False  # close() asked while in use: done when the use ends
        if self.optimised:
            t = self.dtype
            env, scales = _fast.dog_factors(p.dog_gain, p.dog_sigma1, p.dog_sigma2, p.dog_size,
                                            p.dog_normalisation)
            self._coefficients = _fast.FrontCoefficients.make(
                env.astype(t), scales.astype(t), p.dt / p.tau, p.c, p.decay, p.leaky_input,
                p.gain, p.n_fast, p.n_slow, p.target_polarity == "light",
                _fast.gabor_factors(p.ds_sigma, p.ds_wavelength, p.kernel_size,
                                    p.kernel_extent).astype(t),
                np.array([p.v_on, p.v_off], t), _fast.cs_classes(self._cs).astype(t),
                np.array([p.w1_on, -p.w2_off, p.w1_off, -p.w2_on], t), p.grouping)
            self._blur = _fast.AttentionBlur(p.attention_sigma, p.attention_size,
                                             p.attention_normalised, p.attention_step)
        self.reset()

    # ------------------------------------------------------------------ threads

    def _banded_front(self) -> "_parallel.BandedFront":
        """The banded pass and its worker threads (``threads`` > 1), started when a stream or
        a step first needs them (again after a worker's failure, once it was raised) and
        stopped when the model is closed or collected."""
        if self._banded is not None and self._banded.failed:
            self._close_now()  # the caller holds the model: close() would wait for it
        if self._banded is None:
            self._banded = _parallel.BandedFront(self._coefficients, self.threads - 1)
            self._finalizer = weakref.finalize(self, self._banded.close)
        return self._banded

    def close(self) -> None:
        """Stop the model's worker threads (``threads`` > 1); a later frame starts new ones.
        While a step or a stream of the model is under way (a stream left suspended, a with
        block left with its generator alive), they are stopped once it ends."""
        if not self._in_use.acquire(blocking=False):
            self._close_pending = True
            # the use may have ended before the flag was set: then it is this call's to close
            if not self._in_use.acquire(blocking=False):
                return
        try:
            self._close_now()
        finally:
            self._in_use.release()

    def _close_now(self) -> None:
        self._close_pending = False
        if self._banded is not None:
            self._finalizer()
            self._banded = None

    def _release(self) -> None:
        """End a step or a stream: close the model if asked meanwhile, then release it (closed
        after, a stream claimed on another thread in between had its workers stopped)."""
        try:
            if self._close_pending:
                self._close_now()
        finally:
            self._in_use.release()

    def __enter__(self) -> "ASNN":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ state

    def reset(self) -> None:
        """Forget the stream: the next frame starts a new one (of any size).

        Raises
        ------
        RuntimeError
            While a step is under way on another thread, or a stream with worker threads
            (``threads`` > 1), which has taken frames ahead of its responses: reset it between
            streams (or before :meth:`stream`, whose frames then start afresh).
        """
        if self._in_use.locked():
            raise RuntimeError("this ASNN model is stepping (a stream of it is under way, or a "
                               "step on another thread): reset it between streams")
        self.shape: tuple[int, int] | None = None
        self.previous: np.ndarray | None = None
        self.previous_blocks: np.ndarray | None = None
        self._search_radii = (0, 0)  # the stabilisation's search and wider search, pixels
        self._log_gain = 0.0  # the global brightness compensation's gain, log
        self._sampled: np.ndarray | None = None  # its sample of the previous frame stepped
        p = self.params
        self._light = (None if p.contrast_light is None or p.contrast_gain is None
                       else light.LightAdaptation(p.contrast_gain, p.contrast_light,
                                                  p.contrast_light_floor, p.contrast_light_tau,
                                                  p.contrast_light_spread))
        self._summation = (None if p.noise_summation is None or not p.input_blur
                           or self._light is None
                           else summation.NoiseSummation(p.noise_summation,
                                                         p.temporal_summation))
        self._semi_saturation = p.contrast_gain  # the gain control's c for the frame stepped
        self.history: deque[np.ndarray] = deque(maxlen=self.params.n_p)
        self.stages_on: np.ndarray | None = None
        self.stages_off: np.ndarray | None = None
        self.spike_window: deque[int] = deque(maxlen=self.params.n_t)
        self.index = 0
        self.approach = ApproachStage(self.params) if self.params.targets == "objects" else None
        self._stamp: float | None = None
        self._timed = 0  # believed gaps in a row (one is a ms clock's chance, not a timing)
        self._untimed = 0  # given times in a row whose gaps are not believed (-1: warned)
        self._timing_note: str | None = None  # the TimingWarning step() raises next
        self._clock: float | None = None  # the latest frame's time, once a frame had one
        self.periods: deque[float] = deque(maxlen=PERIOD_FRAMES)
        self._last: Response | None = None
        self._repeats = 0
        self._difference = 0.0
        self.repeated = False
        self._received: float | None = None  # the latest timed frame's time, held or not
        self._gaps: deque[float] = deque(maxlen=CEILING_GAPS)  # between the frames received
        self._same_instant = 0  # frames in a row received at the instant of the one before
        self.ceiling_held = 0
        self._unfinished = 0  # frames taken (their state changes begun) and not finished

    @property
    def frame_period(self) -> float:
        """The stream's frame period, seconds: the median of :attr:`periods` (``params.dt``
        before the second frame)."""
        return statistics.median(self.periods) if self.periods else self.params.dt

    # ------------------------------------------------------------------ step

    def _luminance(self, frame: np.ndarray) -> np.ndarray:
        p = self.params
        # sized once, and only where the frame could pass check_frame (a 0-pixel side is its
        # FrameError, not _retina_size's ZeroDivisionError; to_luminance refuses the rest)
        h, w = frame.shape[:2] if isinstance(frame, np.ndarray) and frame.ndim >= 2 else (0, 0)
        size = self._retina_size(h, w) if min(h, w) >= self.min_side else None
        # shrunk: narrower and not taller (a frame wider than max_width, or one whose working
        # area the cap in _retina_size bounds)
        shrink = size is not None and size[0] < w and size[1] <= h
        resize = size is not None and size != (w, h)
        if shrink and self.optimised and frame.dtype == np.uint8:
            # the same luminance as below, bit for bit, without the float64 frame
            frame = check_frame(frame, self.min_side, self.shape)
            self.shape = (h, w)
            gray = np.ascontiguousarray(luma(frame))  # one compiled form of the kernel
            lum = _fast.shrunk_luminance(gray, size, LEVELS, self.dtype)
        else:
            # a frame to resize is converted and resized in float64, so that the float32 and
            # float64 forms of a preset see the same luminance to its last rounding
            lum = to_luminance(frame, self.min_side, self.shape,
                               np.float64 if resize else self.dtype)
            if self.shape is None:
                self.shape = lum.shape
            if resize:
                lum = cv2.resize(lum, size,
                                 interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
        if lum.dtype != self.dtype:
            lum = lum.astype(self.dtype)
        if self._summation is not None:  # the fixed blur, or a wider one in a dim, noisy view
            lum = self._summation.blurred(
                lum, dim=self._semi_saturation < summation.DIM * p.contrast_gain)
        elif p.input_blur:
            lum = summation.fixed_blur(lum)
        return lum

    def _retina_size(self, h: int, w: int) -> tuple[int, int]:
        """(W, H) of an (H, W) frame on the retina. The retina's kernels and the added stages
        count in pixels, so a frame wider than ``max_width`` or narrower than ``min_width`` is
        seen at the scale they were made for (targets are reported in the frame's own pixels).
        An enlarged frame is at most ``4 * min_width`` high (or its own height), and with
        ``max_width`` no frame is worked on at more pixels than a 3:4 portrait ``max_width``
        wide (480 x 640 for the default; a taller one is shrunk both ways, below ``min_width``
        or ``max_width`` if need be): a tall, narrow frame does not make the model's state grow
        past what a large frame's does (480 x 4096 held 8.5 times 4096 x 4096's)."""
        p = self.params
        if p.max_width is not None and w > p.max_width:
            size = p.max_width, max(round(h * p.max_width / w), self.min_side)
        elif p.min_width is not None and w < p.min_width:
            factor = max(1.0, min(p.min_width / w, 4 * p.min_width / h))
            size = round(w * factor), round(h * factor)
        else:
            size = w, h
        # the area of a 3:4 portrait max_width wide at most (a landscape frame never reaches it)
        if p.max_width is not None:
            limit = p.max_width * p.max_width * 4 // 3
            if size[0] * size[1] > limit:
                f = (limit / (size[0] * size[1])) ** 0.5
                size = (max(int(size[0] * f), self.min_side), max(int(size[1] * f), self.min_side))
        return size

    def step(self, frame: np.ndarray, t: float | None = None) -> Response:
        """Process one frame and return the model's response to it.

        Parameters
        ----------
        frame : ndarray
            Gray (H, W) or BGR (H, W, 3), uint8 or float in [0, 1].
        t : float, optional
            The frame's time in seconds (any origin, increasing). Used for expansion rates and
            time to contact; without it, or where it is NaN or infinite or does not advance by
            at least 0.1 ms and at most 1 s (a clock in milliseconds or smaller units, a stall),
            frames are ``params.dt`` apart (a frame without it in a stream whose frames had
            times comes :attr:`frame_period` after the latest), except a gap of more than 1 s
            right after three believed in a row: frames lost for a while, which keeps its own
            time (read as one frame's, the growth of seconds gave a time to contact tens of
            times short, and a warning). A clock in larger units
            (minutes) is believed as seconds: its expansion reads 60 times too fast, and the
            default warns early.

        Returns
        -------
        Response
            The model's response to the frame (:class:`~asnn.response.Response`, its
            ``index`` the frame's in the stream): u(t), out(t), its spikes, the spike rate,
            the collision warning and the looming targets, in the frame's pixels; the
            intermediate maps with ``record_maps``, the tracked objects with
            ``record_tracks``. A stream's first frame only primes the model
            (:meth:`~asnn.response.Response.silent`: u = 0, out = 0.5, no spikes, no maps). A
            frame held as a repeat (``params.skip_repeats``) or by the frame-rate ceiling
            (``params.max_step_rate``) gets the latest response again (:attr:`repeated`), its
            targets' time to contact shortened by the time since the frame stepped last.

        Raises
        ------
        FrameError
            If the frame is not an image the model accepts, its size differs from the stream's,
            or ``t`` is not a number (a str, a bool); the model's state is then as it was.
        RuntimeError
            If the model is stepping already, on another thread or in a :meth:`stream` with
            worker threads not finished: one model serves one stream from one thread at a time.
            Or if a step was interrupted part-way, after its frame was taken (an exception
            other than :class:`FrameError` raised by the step, a KeyboardInterrupt, a worker
            thread's failure): its frame's state changes are half made, and cannot be undone,
            so the model refuses every frame until :meth:`reset` starts a new stream.

        Warns
        -----
        TimingWarning
            Once per stream, when five frames in a row come at times it cannot time them by
            (:class:`~asnn.errors.TimingWarning`), after the frame is stepped.
        """
        response = self._step(frame, t)
        self._tell_timing()
        return response

    def _step(self, frame: np.ndarray, t: float | None) -> Response:
        """:meth:`step` without telling of its frame times (:meth:`_tell_timing`)."""
        self._claim()
        try:
            taken = self._take(frame, t)
            if taken.photo is not None:
                self._front(taken)
            return self._finish(taken)
        finally:
            self._release()

    def _claim(self) -> None:
        """Take the model for one step or one stream with worker threads: RuntimeError where
        another thread steps it, or a stream of it is under way (a model serves one stream
        from one thread at a time: two at once mixed their states without a word)."""
        if not self._in_use.acquire(blocking=False):
            raise RuntimeError("this ASNN model is stepping already (on another thread, or in "
                               "a stream not finished): one model serves one stream, from one "
                               "thread at a time")
        if self._unfinished:
            # a frame taken and never finished left the state part-way through a step (the
            # previous frame, the cascades advanced, no response): stepped on, a held frame
            # read the response that never came (AttributeError on None), and a new one
            # stepped from a state no stream of frames gives
            self._release()
            raise RuntimeError("a step of this ASNN model was interrupted part-way (an "
                               "exception or a KeyboardInterrupt after its frame was taken): "
                               "its state is half a frame's; reset() it to start a new stream")

    def __getstate__(self) -> dict:
        """For copy and pickle: without the lock and the worker threads, which a copy starts
        again when it needs them. RuntimeError while the model steps, or a stream of it is under
        way: its worker threads then hold part of its state, which the copy would miss."""
        if self._in_use.locked():
            raise RuntimeError("this ASNN model is stepping (a stream of it is under way, or a "
                               "step on another thread): copy it between steps")
        state = dict(self.__dict__)
        del state["_in_use"]
        state.pop("_finalizer", None)
        state["_banded"] = None
        state["_close_pending"] = False
        return state

    def __copy__(self) -> "ASNN":
        """A copy is a snapshot: a deep copy (a shallow one shared the state's arrays, deques and
        approach stage with the model, so that stepping either changed the other)."""
        import copy

        return copy.deepcopy(self)

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._in_use = threading.Lock()
        params = self.params
        if set(type(params).model_fields) - set(vars(params)):
            # pickled before a field was added: unpickling does not fill it in, so the stages
            # added since read their defaults (every one off) rather than raise at reset()
            self.params = type(params).model_validate(vars(params))
        if "_semi_saturation" not in state:  # pickled before the light adaptation: fixed c
            self._light, self._semi_saturation = None, self.params.contrast_gain
        if "_summation" not in state:  # pickled before the noise summation: the fixed blur
            self._summation = None

    def stream(self, frames: Iterable[tuple[float | None, np.ndarray]]) -> Iterator[Response]:
        """The responses to ``(t, frame)`` pairs, in order: ``step(frame, t)`` for each.

        With ``threads`` > 1, frame n is finished (attention, objects, tracking, output) on the
        calling thread while the worker threads compute their bands of frame n + 1's fused
        pass, and response n is yielded while they still do: it comes once frame n + 1 has been
        taken. An exception raised by ``frames``, or by a frame (:class:`FrameError`), is
        raised after the responses to the frames before it; a KeyboardInterrupt raised by
        ``frames`` leaves the model as :meth:`step` would after the frames before it (their
        responses not yielded). While the stream runs, the model's
        attributes may already describe the next frame. A stream left early (``break``, or the
        generator closed) finishes the frames it had taken, up to two beyond the last response
        yielded, without yielding them: ``index`` counts them, and the model goes on from there
        as a step-by-step run would.

        Parameters
        ----------
        frames : iterable of (t, frame)
            The frames in order, each with its time in seconds or None: what :meth:`step`
            takes as ``t`` and ``frame``.

        Yields
        ------
        Response
            :meth:`step`'s response to each frame, in order.

        Raises
        ------
        FrameError, RuntimeError
            As :meth:`step` does, after the responses to the frames before.
        """
        if self.threads == 1:
            for t, frame in frames:
                response = self._step(frame, t)
                self._tell_timing()
                yield response
            return
        self._claim()
        inner = self._banded_stream(frames)
        try:
            for response in inner:
                self._tell_timing()
                yield response
        finally:
            try:
                inner.close()  # a stream left early finishes the frames it took, then releases
            finally:
                self._release()

    def _banded_stream(self, frames: Iterable[tuple[float | None, np.ndarray]]
                       ) -> Iterator[Response]:
        """:meth:`stream` with worker threads (``threads`` > 1)."""
        banded = self._banded_front()
        iterator = iter(frames)
        # Taken frames not finished yet, oldest first: a frame is finished while the workers
        # compute the next frame's pass and the one after it is taken (two passes in flight:
        # a worker never waits for this thread to join one).
        pending: deque[_Frame] = deque()
        taken = None  # the frame taken latest, until it is pending
        try:
            while True:
                try:
                    t, frame = next(iterator)
                    taken = self._take(frame, t)
                except StopIteration:
                    break
                except Exception:  # the responses before it first
                    while pending:
                        yield self._finish(self._joined(pending.popleft()))
                    raise
                except BaseException:  # a KeyboardInterrupt while the source read a frame:
                    # between two frames, as with one thread, so the frames taken are finished
                    # (their responses dropped, as for a stream left early); left unfinished,
                    # the model refused every frame until reset
                    while pending:
                        self._finish(self._joined(pending.popleft()))
                    raise
                if taken.photo is not None:  # the workers' bands queue behind the previous ones
                    self._start(taken, overlapped=True)
                if len(pending) == 2:
                    yield self._finish(pending.popleft())  # joined before
                if pending:
                    self._joined(pending[0])  # its maps are complete, and the cascades it wrote
                if taken.photo is not None:
                    banded.run_own(taken.flight)
                pending.append(taken)
                taken = None
            while pending:
                yield self._finish(self._joined(pending.popleft()))
        except GeneratorExit:
            if sys.is_finalizing():  # a stream left suspended at the interpreter's exit: its
                raise  # worker threads are gone, and waiting for their passes hung the exit
            # the caller stopped early: the frames already taken are finished (their responses
            # dropped), so that the model is as step() would leave it after ``index`` frames
            while pending:
                self._finish(self._joined(pending.popleft()))
            if taken is not None:  # taken before the response that was yielded last
                if taken.photo is not None:
                    banded.run_own(taken.flight)
                self._finish(self._joined(taken))
            raise
        finally:
            if not sys.is_finalizing():
                banded.abandon()  # an abandoned stream: no worker goes on behind the caller
                if self.stages_on is not None:
                    banded.settle((self.stages_on, self.stages_off))

    def _note_untimed(self, gap: float) -> None:
        """Count a given time whose gap the model does not believe; when PERIOD_FRAMES come in
        a row, note the stream's :class:`~asnn.errors.TimingWarning` (once per stream), which
        :meth:`step` and :meth:`stream` raise once the frame is stepped (raised here, under
        warnings as errors, it left the model half-stepped)."""
        if self._untimed < 0:
            return
        self._untimed += 1
        if self._untimed >= PERIOD_FRAMES:
            self._untimed = -1
            slow = gap > MAX_FRAME_GAP_S
            self._timing_note = (
                f"{PERIOD_FRAMES} frames in a row came at times the model cannot time them by "
                f"(the last {gap:g} s after the frame before; it believes {MIN_FRAME_GAP_S:g} "
                f"to {MAX_FRAME_GAP_S:g} s): each is timed at params.dt = {self.params.dt:g} s "
                "instead, so expansion rates and time to contact are off by as much as the "
                "clock is. Pass each frame's time in seconds: " + (
                    "these read like a clock in milliseconds or nanoseconds, or a camera slower "
                    "than a frame a second, far below the 20 fps the default is made for"
                    if slow else "these read like a clock that stands still or goes back, "
                    "or frames stamped under 0.1 ms apart"))

    def _tell_timing(self) -> None:
        """Raise the stream's noted :class:`~asnn.errors.TimingWarning`, if any, once, at the
        caller's line that stepped the model (the first outside asnn)."""
        note, self._timing_note = self._timing_note, None
        if note is not None:
            _warn_at_caller(note, TimingWarning)

    def _stabilisation_radii(self, width: int) -> tuple[int, int]:
        """The background stabilisation's search radius and its wider search's (0: none),
        pixels per frame, on a grid ``width`` pixels wide (:mod:`asnn.stabilisation`)."""
        p = self.params
        radius = search_radius(width, p.stabilise_radius, p.stabilise_reach)
        wider = (0 if p.stabilise_wider is None else
                 search_radius(width, p.stabilise_radius, p.stabilise_reach, p.stabilise_wider))
        return radius, wider

    def _take(self, frame: np.ndarray, t: float | None) -> "_Frame":
        """The first part of a step: the frame's luminance, whether it is new, and P."""
        p = self.params
        index = self.index
        if t is not None:
            t = frame_time(t)  # checked before any state changes
            if not math.isfinite(t):
                t = None  # NaN or infinite: no usable time, as a frame given none (a NaN stamp
                # kept as the stream's latest spoiled the next good frame's gap too)
        # a frame without a time in a timed stream comes a frame period after the latest
        # (index * dt there read the gap from another clock: 0.5 s for a 30 fps camera's 30th
        # frame, believed, and the next timed frame's gap negative)
        stamp = (t if t is not None else index * p.dt if self._clock is None
                 else self._clock + self.frame_period)
        lum = self._luminance(frame)
        self._unfinished += 1  # the state changes from here on, until _finish (see _claim)
        self.index += 1
        if t is not None or self._clock is not None:
            self._clock = stamp
        blocks = self._blocks(lum) if p.skip_repeats else None
        if self.previous is None:
            self.previous, self.previous_blocks = lum, blocks
            if p.global_gain is not None:
                self._sampled = brightness.sampled(lum)
            if p.stabilise:  # the stream's grid keeps this width
                self._search_radii = self._stabilisation_radii(lum.shape[1])
            self.stages_on = np.zeros((p.n_slow + 2, *lum.shape), self.dtype)
            self.stages_off = np.zeros_like(self.stages_on)
            self._stamp = stamp
            self._received = None if t is None else stamp
            return _Frame(index)
        if self._held(None if t is None else stamp):
            self.repeated = True
            self.ceiling_held += 1
            return _Frame(index, repeat=True, since_stepped=stamp - self._stamp)
        self.repeated = blocks is not None and self._is_repeat(blocks)
        if self.repeated:
            return _Frame(index, repeat=True, since_stepped=stamp - self._stamp)
        elapsed = stamp - self._stamp
        if timed_gap(elapsed):
            self._timed += 1
            self._untimed = min(self._untimed, 0)
        elif self._timed >= TIMED_RUN and MAX_FRAME_GAP_S < elapsed < math.inf:
            # a timed stream's stall, frames lost for over MAX_FRAME_GAP_S, keeps its own time
            # (timed at dt it read the change of seconds as one frame's, a time to contact
            # 50-300 times short); the next such gap must follow believed ones again (one
            # chance gap of a millisecond clock under 1 ms timed all its later ones as seconds)
            self._timed = 0
        else:  # no usable times: the nominal frame period
            if t is not None:
                self._note_untimed(elapsed)
            elapsed = p.dt
            self._timed = 0
        self._stamp = stamp
        self.periods.append(elapsed)
        if self._summation is not None:  # a dim, noisy view summed in time (after the repeats
            # are held: a repeated frame is not a second look at the scene)
            lum = self._summation.integrated(lum, elapsed)
        if p.global_gain is not None:
            lum = self._compensated(lum, elapsed)
        background = None
        if p.stabilise:
            radius, wider = self._search_radii
            shift = background_shift(self.previous, lum, radius, p.stabilise_share,
                                     p.stabilise_spread, wider)
            if shift != (0, 0):  # where nothing moved in, the frame differs by nothing
                background = shift_image(self.previous, *shift, border=lum)
        if self._light is not None:
            self._semi_saturation = self._light.step(brightness.sampled(lum), elapsed)
        previous, self.previous, self.previous_blocks = self.previous, lum, blocks
        taken = _Frame(index, lum=lum, elapsed=elapsed, previous=previous, background=background,
                       semi_saturation=self._semi_saturation)
        if self.optimised:
            # with threads of its own, P goes where the fused pass will read it (a front that
            # failed is left as it is: the pass in flight raises its error)
            banded = self._banded
            out = (banded.next_photo((self.stages_on, self.stages_off))
                   if banded is not None and not banded.failed else None)
            taken.photo = self._photoreceptors(lum, previous if background is None
                                               else background, taken.semi_saturation, out)
        return taken

    def _compensated(self, lum: np.ndarray, elapsed: float) -> np.ndarray:
        """The frame's luminance scaled by the global brightness compensation's gain
        (``params.global_gain``, :mod:`asnn.brightness`), its change measured against the
        previous frame stepped, both as the input stages gave them (blurred, and in a dim, noisy
        view summed in time: a step under 8 gray levels there comes in over the temporal
        summation's time constant); the gain is the model's state."""
        sampled = brightness.sampled(lum)
        change = (0.0 if self._sampled is None
                  else brightness.global_change(sampled, self._sampled))
        self._sampled = sampled
        self._log_gain = brightness.compensation_step(self._log_gain, change, elapsed,
                                                      self.params.global_gain)
        if self._log_gain == 0.0:
            return lum
        return lum * lum.dtype.type(math.exp(self._log_gain))

    def _front(self, frame: "_Frame") -> None:
        """The fused pass of a frame :meth:`_take` took (optimised form): its maps."""
        if self.threads == 1:
            frame.maps = _fast.workspace(frame.lum.shape, self.dtype).maps
            _fast.front(frame.photo, (self.stages_on, self.stages_off), self._coefficients,
                        frame.maps, _fast.scratch(frame.lum.shape[1], self.dtype))
            return
        banded = self._banded_front()
        self._start(frame)
        try:
            banded.run_own(frame.flight)
        finally:
            self._joined(frame)
            banded.settle((self.stages_on, self.stages_off))

    def _start(self, frame: "_Frame", overlapped: bool = False) -> None:
        """Start a frame's banded pass (``threads`` > 1): it advances the cascades from one pair
        of arrays into the other, which become the model's."""
        frame.flight = self._banded.start(frame.photo, (self.stages_on, self.stages_off),
                                          overlapped)
        frame.maps = frame.flight.maps  # valid while two more frames are taken (see stream)

    def _joined(self, frame: "_Frame") -> "_Frame":
        """The frame, once the workers' bands of its pass are done (``threads`` > 1)."""
        if frame.flight is not None:
            self._banded.join(frame.flight)
            frame.flight = None
        return frame

    def _finish(self, frame: "_Frame") -> Response:
        """The last part of a step: the response to a frame whose maps are complete."""
        if frame.since_stepped > 0.0:  # the last response, its targets aged (kept as it was)
            response = dataclasses.replace(self._last, index=frame.index, targets=aged_targets(
                self._last.targets, frame.since_stepped))
        else:
            if frame.lum is None:
                self._last = (dataclasses.replace(self._last, index=frame.index) if frame.repeat
                              else Response.silent(frame.index,
                                                   [] if self.record_tracks else None))
            elif self.optimised:
                self._last = self._respond_optimised(frame)
            else:
                self._last = self._respond(frame)
            response = self._last
        self._unfinished -= 1
        return response

    def _held(self, stamp: float | None) -> bool:
        """Whether the frame-rate ceiling holds a frame of time ``stamp`` (None: untimed)
        (``params.max_step_rate``, r): while the camera is fast (:meth:`_fast`), a frame in the
        same cell of a grid of 1 / r seconds as the frame received before it is held, and so
        is a frame stamped at the same instant as it (a frame delivered twice, a bag's stamp
        that went back retimed to the latest), up to :data:`SAME_INSTANT_HELD` in a row: more
        are a clock that stopped, stepped (timed at ``params.dt``, and warned of as such).

        The cells are fixed by the times alone, not by the frames stepped, so that two models
        started on different frames of a stream step the same frames once both have judged the
        rate (a worker taking a robot over); a hold counted from the last frame stepped kept a
        model started on an odd frame of a 60 fps stream on the other half for good. A camera
        slower than :data:`CEILING_MARGIN` r is never held, however its stamps jitter or come
        in pairs. A camera between that and 2 r is stepped unevenly (at 40 fps 25 or 50 ms
        apart, at 50 fps 20 or 40), and so is a 60 fps camera whose stamps jitter about the
        grid's lines (a frame on either side of a line: now and then 17 or 50 ms)."""
        rate = self.params.max_step_rate
        previous, self._received = self._received, stamp
        if rate is None or stamp is None or previous is None:
            return False
        gap = stamp - previous
        if 0.0 <= gap < MIN_FRAME_GAP_S:  # the same instant: it tells nothing of the rate
            self._same_instant += 1
            if self._same_instant <= SAME_INSTANT_HELD:
                return self._fast(rate)
            # more in a row: a clock that stopped, not a frame sent twice (held for good, a
            # fast camera's model froze without a word): the rate is unknown again
            self._gaps.clear()
            return False
        self._same_instant = 0
        if not timed_gap(gap):  # a clock that jumped, or stamps in other units: stepped
            self._gaps.clear()
            return False
        self._gaps.append(gap)
        # the cells first: a camera at or below the grid's rate has its frames in cells of
        # their own, and its rate need not be judged at every frame
        return _grid_cell(stamp, rate) == _grid_cell(previous, rate) and self._fast(rate)

    def _fast(self, rate: float) -> bool:
        """Whether the camera is faster than :data:`CEILING_MARGIN` times ``rate``: over the
        last gaps between the frames received (:data:`CEILING_GAPS`, from
        :data:`CEILING_MIN_GAPS` on), both their mean and the median of the spans of two
        gaps, halved, under 1 / (CEILING_MARGIN ``rate``). A 30 fps camera read two frames
        at a time (gaps of 4 and 63 ms) had a median gap of 4 ms, and half its frames held;
        the mean is the camera's rate however its stamps bunch, but over the first few gaps
        of such a pair it reads short, where every two-gap span reads the camera's period."""
        gaps = self._gaps
        if len(gaps) < CEILING_MIN_GAPS:
            return False
        limit = 1.0 / (CEILING_MARGIN * rate)
        spans = [gaps[k - 1] + gaps[k] for k in range(1, len(gaps))]
        return sum(gaps) < len(gaps) * limit and statistics.median(spans) < 2.0 * limit

    def _blocks(self, lum: np.ndarray) -> np.ndarray:
        """The frame's means over ``repeat_block`` x ``repeat_block`` blocks (the frame itself
        for 1), what :meth:`_is_repeat` compares."""
        k = self.params.repeat_block
        if k == 1:
            return lum
        h, w = lum.shape
        return _fast.block_means(lum, (max(w // k, 1), max(h // k, 1)))  # cv2's INTER_AREA

    def _is_repeat(self, blocks: np.ndarray) -> bool:
        """Whether a frame, given by its :meth:`_blocks`, repeats the previous one
        (``params.skip_repeats``).

        Video converted to a higher frame rate repeats frames, and a repeat would read as a
        moment in which nothing moved: the model would see the world stop and start again.
        A frame counts as a repeat when its mean absolute difference from the previous frame is
        below ``repeat_level`` and below ``repeat_fraction`` of the difference the last frame
        that was not a repeat had, so that a still scene with sensor noise is not a repeat; and
        at most ``repeat_run`` frames in a row are repeats: a scene that stops moving is news.
        The difference is that of the block means: the sensor noise a camera adds to each copy
        of a repeated frame averages out over a block (a 4-gray-level noise to half a level
        over 8 x 8 pixels), where per pixel it would hide the repeat, while a frame in which
        something moved still differs in its blocks.
        """
        p = self.params
        diff = float(cv2.norm(blocks, self.previous_blocks, cv2.NORM_L1)) / blocks.size
        if (diff < p.repeat_level and diff < p.repeat_fraction * self._difference
                and self._repeats < p.repeat_run):
            self._repeats += 1
            return True
        self._repeats = 0
        self._difference = diff
        return False

    def _spikes(self, u: float, n_cells: int) -> tuple[float, int, float]:
        return spike_step(u, n_cells, self.spike_window, self.params)

    def _photoreceptors(self, lum: np.ndarray, previous: np.ndarray,
                        semi_saturation: float | None,
                        out: np.ndarray | None = None) -> np.ndarray:
        """P (eq. 1) from the frame and the previous one, after the contrast gain control where
        the preset has it (its ``c`` the frame's ``semi_saturation``). The optimised form
        without photoreceptor history computes the
        difference and the gain control's pool together
        (:func:`asnn._fast.gain_controlled_change`), into ``out`` where given."""
        p = self.params
        if self.optimised and not p.n_p and p.contrast_gain is not None:
            return _fast.gain_controlled_change(lum, previous, semi_saturation,
                                                p.contrast_pool, p.contrast_scale, out)
        photo = retina.photoreceptor(lum, previous, list(self.history), self._p_weights)
        if p.n_p:
            self.history.appendleft(photo)
        if p.contrast_gain is not None:
            gain_control = (_fast if self.optimised else retina).contrast_gain_control
            photo = gain_control(photo, semi_saturation, p.contrast_pool, p.contrast_scale)
        return photo

    def _respond_optimised(self, frame: "_Frame") -> Response:
        """:meth:`_respond` with the fused kernels of :mod:`asnn._fast`, from the fused pass's
        maps (:meth:`_front`) on."""
        p = self.params
        index, lum, photo = frame.index, frame.lum, frame.photo
        ws = _fast.workspace(lum.shape, self.dtype)
        # r: R^theta for k = 0..3 (R^{theta + pi} = -R^theta); v = V; g = G after grouping
        r, v, g = frame.maps.r, frame.maps.v, frame.maps.g
        total, count, blur_g, blur_v, _ = _fast.attention(
            g, r, v, frame.maps.sums(), ws, self._blur, p.gamma_a, p.gamma_d, p.top_k, p.u_abs,
            full=self.record_maps)
        attended = ws.mask

        vectors = _fast.MotionVectors(r, v)  # at (rows, cols); summed per object
        if p.targets == "objects":
            total, targets = self._objects(attended if count else None, g, vectors, frame,
                                           total, points=(ws.rows[:count], ws.cols[:count]))
        else:
            targets = []
            if count:
                targets = self._in_frame(extract_targets(
                    attended, None, None, p.cluster_eps, p.cluster_min_samples, p.origin_seed,
                    vectors=vectors, points=(ws.rows[:count], ws.cols[:count])), g.shape)
        u = float(p.u_scale * total)
        out, spikes, spike_rate = self._spikes(u, g.size)
        maps = None
        if self.record_maps:
            m_a = blur_g > p.gamma_a
            m_d = blur_v > p.gamma_d  # full=True: the window is the whole frame
            mask = attended.copy()
            whole = np.concatenate([r, -r])  # R^{theta + pi} = -R^theta
            maps = Maps(P=photo.copy(), R=whole, V=v.copy(),
                        phi=retina.motion_direction(whole), G=g.copy(), M_a=m_a, M_d=m_d,
                        G_prime=g * mask,  # eq. 27 with the kernels' M_a M_d
                        rig=self._rig_mask())
        return Response(index=index, u=u, out=out, spikes=spikes, spike_rate=spike_rate,
                        collision=retina.collision_warning(spike_rate, p.t_c), targets=targets,
                        maps=maps, tracks=frame.tracks)

    def _respond(self, frame: "_Frame") -> Response:
        """One step in the straightforward float64 form (:mod:`asnn.retina`, stage by stage)."""
        p = self.params
        photo = self._photoreceptors(frame.lum, frame.previous if frame.background is None
                                     else frame.background, frame.semi_saturation)

        on0, off0 = retina.bipolar(photo, self._dog)
        if p.target_polarity == "light":
            on0, off0 = off0, on0
        rate = p.dt / p.tau
        retina.temporal_filter_step(self.stages_on, on0, rate, p.c, p.decay, p.leaky_input)
        retina.temporal_filter_step(self.stages_off, off0, rate, p.c, p.decay, p.leaky_input)
        fast_on = retina.temporal_readout(self.stages_on, p.gain, p.n_fast)
        slow_on = retina.temporal_readout(self.stages_on, p.gain, p.n_slow)
        fast_off = retina.temporal_readout(self.stages_off, p.gain, p.n_fast)
        slow_off = retina.temporal_readout(self.stages_off, p.gain, p.n_slow)

        r = retina.motion_energy(slow_on, fast_on, slow_off, fast_off, self._gabor,
                                 p.v_on, p.v_off)
        v = retina.motion_strength(r)
        phi = retina.motion_direction(r)

        g = retina.approach_map(slow_on, fast_on, slow_off, fast_off, self._cs,
                                (p.w1_on, p.w2_off, p.w1_off, p.w2_on))
        if p.grouping:
            g = retina.group(g)
        m_a = retina.approach_attention(g, p.attention_sigma, p.attention_size,
                                        p.attention_normalised, p.gamma_a, p.attention_step)
        m_d = retina.direction_attention(r, v, p.top_k, p.attention_sigma, p.attention_size,
                                         p.attention_normalised, p.gamma_d, p.attention_step)
        attended = m_a & m_d
        g_prime = retina.attended_response(g, m_a, m_d)
        dx, dy = retina.motion_components(v, phi)

        if p.targets == "objects":
            total, targets = self._objects(
                attended if attended.any() else None, g, lambda rows, cols: (dx[rows, cols],
                                                                             dy[rows, cols]),
                frame, retina.membrane_potential(g_prime, 1.0, p.u_abs))
            u = float(p.u_scale * total)
        else:
            u = retina.membrane_potential(g_prime, p.u_scale, p.u_abs)
            targets = self._in_frame(extract_targets(attended, dx, dy, p.cluster_eps,
                                                     p.cluster_min_samples, p.origin_seed),
                                     g.shape)
        out, spikes, spike_rate = self._spikes(u, g.size)
        maps = Maps(P=photo, R=r, V=v, phi=phi, G=g, M_a=m_a, M_d=m_d, G_prime=g_prime,
                    rig=self._rig_mask()) if self.record_maps else None
        return Response(index=frame.index, u=u, out=out, spikes=spikes, spike_rate=spike_rate,
                        collision=retina.collision_warning(spike_rate, p.t_c), targets=targets,
                        maps=maps, tracks=frame.tracks)

    def _in_frame(self, targets: list, grid: tuple[int, int]) -> list:
        """Cluster targets found on the model's ``grid`` (rows, cols) in the input frame's
        pixels, where ``max_width`` or ``min_width`` resized the frame (the objects' stage
        scales its own)."""
        sx, sy = self._frame_scale(grid)
        if sx == sy == 1.0:
            return targets
        return [dataclasses.replace(t, x=frame_pixel(t.x, sx), y=frame_pixel(t.y, sy),
                                    pixels=round(t.pixels * sx * sy)) for t in targets]

    def _frame_scale(self, grid: tuple[int, int]) -> tuple[float, float]:
        """Input-frame pixels per pixel of the model's ``grid`` (rows, cols): (x, y)."""
        return self.shape[1] / grid[1], self.shape[0] / grid[0]

    def _objects(self, attended: np.ndarray | None, g: np.ndarray, vectors, frame: "_Frame",
                 total: float, points: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[float, list]:
        """The approach stage's step (``targets='objects'``): the (unscaled) membrane
        potential and the targets (:meth:`asnn.approach.ApproachStage.step`); the tracks'
        reports go to the frame (``record_tracks``)."""
        total, targets, frame.tracks = self.approach.step(
            attended, g, vectors,
            FramePair(frame.previous, frame.lum, frame.background, frame.elapsed), total,
            self.frame_period, self._frame_scale(g.shape), points, self.record_tracks)
        return total, targets

    def _rig_mask(self) -> np.ndarray | None:
        """The pixels the looming fits left out as the camera's rig in the latest frame."""
        return None if self.approach is None else self.approach.rig.mask


@dataclasses.dataclass(slots=True)
class _Frame:
    """A frame between the parts of :meth:`ASNN.step`: what the later ones need."""

    index: int
    repeat: bool = False  # a repeat of the previous frame (no lum: no new response either)
    # a frame not stepped (held by the frame-rate ceiling, or a repeat): seconds since the frame
    # stepped last, by which its response's targets are aged
    since_stepped: float = 0.0
    lum: np.ndarray | None = None
    elapsed: float = 0.0
    previous: np.ndarray | None = None
    # the previous frame moved by the background's translation since (None: no translation)
    background: np.ndarray | None = None
    photo: np.ndarray | None = None
    # the contrast gain control's c for this frame (light-adapted where the preset adapts it):
    # the straightforward form computes P after the next frame may have been taken
    semi_saturation: float | None = None
    maps: _fast.FrontMaps | None = None
    flight: "_parallel._Pass | None" = None  # its banded pass, until joined
    tracks: list | None = None  # its objects' approach tests (record_tracks)


def aged_targets(targets: list, seconds: float) -> list:
    """The targets of a response ``seconds`` on, for a frame the model does not step (held by the
    frame-rate ceiling, or a repeat of the one before): each time to contact shortened by
    ``seconds`` and its expansion rate the inverse (an approach at constant speed, as the
    reported estimate assumes: a held frame repeated it a frame old, +37 % at 60 fps in an
    approach's last frames, and a repeat between held frames read it back up); a target that
    would reach the camera within them keeps its own."""
    return [dataclasses.replace(t, ttc=t.ttc - seconds, expansion=1.0 / (t.ttc - seconds))
            if t.ttc is not None and t.ttc > seconds else t for t in targets]


def spike_step(u: float, n_cells: int, window: deque, params: ASNNParams
               ) -> tuple[float, int, float]:
    """The output stage for one frame: ``out`` (eq. 32), the spikes (eq. 33), appended to
    ``window`` (the spikes of the last ``n_t`` frames), and the spike rate over it (eq. 34).
    A warning is a rate of at least ``params.t_c``."""
    out = retina.sigmoid_output(u, n_cells)
    spikes = retina.spike_count(out, params.k_sp, params.t_sp)
    window.append(spikes)
    return out, spikes, retina.spike_rate(window, params.n_t, params.window_dt)


def _grid_cell(stamp: float, rate: float) -> int:
    """The cell of a grid of ``1 / rate`` seconds that a time lies in (:meth:`ASNN._held`). A
    millionth of a cell is added so that times generated on the grid's lines (``k / 60`` at a
    rate of 30) fall in the cell they begin, not in the one before by a rounding."""
    return math.floor(stamp * rate + 1e-6)
