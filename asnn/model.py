"""The ASNN model: one stateful object per camera stream, ``step(frame) -> Response``.

``ASNN.step`` has two implementations of the same equations. The straightforward one calls the
functions of :mod:`asnn.retina` stage by stage on float64 arrays: it is the definition, and
``ASNN(params, optimised=False)`` runs it. The optimised one (the default) computes the
expensive stages with the fused kernels of :mod:`asnn._fast`, in the preset's ``precision``;
the cheap stages (photoreceptors, attention blurs, output, targets) call the same retina
functions. ``tests/test_equivalence.py`` keeps the two together.
"""

from __future__ import annotations

import math
from collections import deque

import cv2
import numpy as np

from . import _fast, retina
from .frames import FrameError, to_luminance
from .params import ASNNParams, preset
from .response import Maps, Response
from .targets import extract_targets

__all__ = ["ASNN", "FrameError", "compile_kernels"]

N_ORIENTATIONS = 8  # theta = k pi / 4; four are computed, four are their negatives


class ASNN:
    """Approach-Sensitive Neural Network for one stream of frames.

    Parameters
    ----------
    params : ASNNParams or str
        A parameter set or a preset name (see :mod:`asnn.params`).
    record_maps : bool
        Attach the intermediate maps (:class:`~asnn.response.Maps`) to every response.
    optimised : bool
        Use the fused kernels of :mod:`asnn._fast` in ``params.precision`` (default), or the
        straightforward float64 form of :mod:`asnn.retina` (``False``; for comparisons). Kernel
        sizes other than 5x5 always use the straightforward form.

    Attributes
    ----------
    params : ASNNParams
    shape : (H, W) or None
        The stream's frame size, fixed by its first frame.
    previous : ndarray (H, W)
        Luminance of the last frame, after the optional input blur.
    history : deque of ndarray (H, W)
        The last N_p photoreceptor activations, most recent first.
    stages_on, stages_off : ndarray (n_s + 2, H, W)
        Leaky-integrator cascades of the ON and OFF bipolar channels (z_0..z_{n_s+1}), in
        :attr:`dtype`; the optimised step keeps them in difference form
        (:func:`asnn._fast.to_differences`).
    dtype : numpy dtype
        Floating-point type of the state and the computation.
    spike_window : deque of int
        Spikes of the last N_t frames.

    Notes
    -----
    The model integrates with the fixed step ``params.dt`` (0.05 s by default) whatever the
    frames' timestamps: the paper assumes a constant frame rate. The first frame of a stream
    only primes the state: its response is all zeros (u = 0, out = 0.5, no spikes).
    """

    def __init__(self, params: ASNNParams | str = "default", *, record_maps: bool = False,
                 optimised: bool = True):
        self.params = preset(params) if isinstance(params, str) else params
        self.record_maps = record_maps
        p = self.params
        self.optimised = bool(optimised) and _fast.supported(p)
        self.dtype = np.dtype(p.precision if self.optimised else np.float64)
        self._min_side = max(p.dog_size, p.kernel_size, p.attention_size)
        self._p_weights = retina.photoreceptor_weights(p.n_p, p.p_u)
        self._dog = retina.dog_kernel(p.dog_gain, p.dog_sigma1, p.dog_sigma2, p.dog_size,
                                      p.dog_normalisation)
        half = N_ORIENTATIONS // 2
        self._gabor = [retina.gabor_pair(k * math.pi / half, p.ds_sigma, p.ds_wavelength,
                                         p.kernel_size, p.kernel_extent) for k in range(half)]
        self._cs = retina.center_surround_kernel(p.cs_sigma, p.cs_wavelength, p.cs_phase,
                                                 p.kernel_size, p.kernel_extent)
        if self.optimised:
            t = self.dtype
            env, scales = _fast.dog_factors(p.dog_gain, p.dog_sigma1, p.dog_sigma2, p.dog_size,
                                            p.dog_normalisation)
            self._env, self._scales = env.astype(t), scales.astype(t)
            self._factors = _fast.gabor_factors(p.ds_sigma, p.ds_wavelength, p.kernel_size,
                                                p.kernel_extent).astype(t)
            self._cs_classes = _fast.cs_classes(self._cs).astype(t)
            self._v_weights = np.array([p.v_on, p.v_off], t)
            self._a_weights = np.array([p.w1_on, -p.w2_off, p.w1_off, -p.w2_on], t)
            self._blur = _fast.AttentionBlur(p.attention_sigma, p.attention_size,
                                             p.attention_normalised)
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self) -> None:
        """Forget the stream: the next frame starts a new one (of any size)."""
        self.shape: tuple[int, int] | None = None
        self.previous: np.ndarray | None = None
        self.history: deque[np.ndarray] = deque(maxlen=self.params.n_p)
        self.stages_on: np.ndarray | None = None
        self.stages_off: np.ndarray | None = None
        self.spike_window: deque[int] = deque(maxlen=self.params.n_t)
        self.index = 0

    # ------------------------------------------------------------------ step

    def _luminance(self, frame: np.ndarray) -> np.ndarray:
        lum = to_luminance(frame, self._min_side, self.shape)
        if lum.dtype != self.dtype:
            lum = lum.astype(self.dtype)
        if self.params.input_blur:
            lum = cv2.GaussianBlur(lum, (3, 3), 1.0, borderType=cv2.BORDER_REFLECT_101)
        return lum

    def step(self, frame: np.ndarray, t: float | None = None) -> Response:
        """Process one frame and return the model's response to it.

        ``t``, the frame's time in seconds, is not used yet.

        Raises
        ------
        FrameError
            If the frame is not an image the model accepts, or its size differs from the stream's.
        """
        lum = self._luminance(frame)
        index = self.index
        self.index += 1
        if self.previous is None:
            p = self.params
            self.shape = lum.shape
            self.previous = lum
            self.stages_on = np.zeros((p.n_slow + 2, *lum.shape), self.dtype)
            self.stages_off = np.zeros_like(self.stages_on)
            return Response.silent(index)
        if self.optimised:
            return self._respond_optimised(index, lum)
        return self._respond(index, lum)

    def _spikes(self, u: float, n_cells: int) -> tuple[float, int, float]:
        p = self.params
        out = retina.sigmoid_output(u, n_cells)
        spikes = retina.spike_count(out, p.k_sp, p.t_sp)
        self.spike_window.append(spikes)
        return out, spikes, sum(self.spike_window) / (p.n_t * p.window_dt)

    def _respond_optimised(self, index: int, lum: np.ndarray) -> Response:
        """:meth:`_respond` with the fused kernels of :mod:`asnn._fast`."""
        p = self.params
        ws = _fast.workspace(lum.shape, self.dtype)
        photo = retina.photoreceptor(lum, self.previous, list(self.history), self._p_weights)
        self.previous = lum
        if p.n_p:
            self.history.appendleft(photo)

        r, v, g, sums = _fast.front(
            photo, ws, self._env, self._scales, self.stages_on, self.stages_off, p.dt / p.tau, p.c,
            p.decay, p.leaky_input, p.gain, p.n_fast, p.n_slow, p.target_polarity == "light",
            self._factors, self._v_weights, self._cs_classes, self._a_weights, p.grouping)
        # r: R^theta for k = 0..3 (R^{theta + pi} = -R^theta); v = V; g = G after grouping
        total, count, blur_g, blur_v, _ = _fast.attention(
            g, r, v, sums, ws, self._blur, p.gamma_a, p.gamma_d, p.top_k, p.u_abs,
            full=self.record_maps)
        attended = ws.mask

        u = float(p.u_scale * total)
        out, spikes, spike_rate = self._spikes(u, g.size)

        targets = []
        if count:
            def vectors(rows, cols):
                rr = r[:, rows, cols].astype(np.float64)
                vv = v[rows, cols].astype(np.float64)
                phi = np.arctan2(rr[2], rr[0])
                return vv * np.cos(phi), vv * np.sin(phi)

            targets = extract_targets(attended, None, None, p.cluster_eps, p.cluster_min_samples,
                                      p.origin_seed, vectors=vectors,
                                      points=(ws.rows[:count], ws.cols[:count]))
        maps = None
        if self.record_maps:
            m_a = blur_g > p.gamma_a
            m_d = blur_v > p.gamma_d  # full=True: the window is the whole frame
            mask = attended.copy()
            maps = Maps(P=photo.copy(), R=np.concatenate([r, -r]), V=v.copy(),
                        phi=np.arctan2(r[2], r[0]), G=g.copy(), M_a=m_a, M_d=m_d,
                        G_prime=g * mask)
        return Response(index=index, u=u, out=out, spikes=spikes, spike_rate=spike_rate,
                        collision=spike_rate >= p.t_c, targets=targets, maps=maps)

    def _respond(self, index: int, lum: np.ndarray) -> Response:
        """One step in the straightforward float64 form (:mod:`asnn.retina`, stage by stage)."""
        p = self.params
        photo = retina.photoreceptor(lum, self.previous, list(self.history), self._p_weights)
        self.previous = lum
        if p.n_p:
            self.history.appendleft(photo)

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
        v = r.max(axis=0)
        phi = np.arctan2(r[2], r[0])  # R^{pi/2}, R^0

        g = retina.approach_map(slow_on, fast_on, slow_off, fast_off, self._cs,
                                (p.w1_on, p.w2_off, p.w1_off, p.w2_on))
        if p.grouping:
            g = retina.group(g)
        m_a = retina.approach_attention(g, p.attention_sigma, p.attention_size,
                                        p.attention_normalised, p.gamma_a)
        m_d = retina.direction_attention(r, v, p.top_k, p.attention_sigma, p.attention_size,
                                         p.attention_normalised, p.gamma_d)
        attended = m_a & m_d
        g_prime = g * attended

        u = retina.membrane_potential(g_prime, p.u_scale, p.u_abs)
        out = retina.sigmoid_output(u, g.size)
        spikes = retina.spike_count(out, p.k_sp, p.t_sp)
        self.spike_window.append(spikes)
        spike_rate = sum(self.spike_window) / (p.n_t * p.window_dt)

        targets = extract_targets(attended, v * np.cos(phi), v * np.sin(phi), p.cluster_eps,
                                  p.cluster_min_samples, p.origin_seed)
        maps = Maps(P=photo, R=r, V=v, phi=phi, G=g, M_a=m_a, M_d=m_d,
                    G_prime=g_prime) if self.record_maps else None
        return Response(index=index, u=u, out=out, spikes=spikes, spike_rate=spike_rate,
                        collision=spike_rate >= p.t_c, targets=targets, maps=maps)


def compile_kernels() -> None:
    """Compile the optimised step's numba kernels for both precisions, or load them from numba's
    on-disk cache (seconds on a fresh install, milliseconds afterwards).

    Long-running processes call it before they take their first frame, so that frame does not
    wait for the compiler.
    """
    from .stimuli import make_scene

    # a small off-centre looming disk: every stage, including the clustering, has work
    frames = make_scene("looming", size=(64, 64), start=2, stop=12, center=(30.0, 33.0)).frames
    for name in ("default", "reference"):  # float32 and float64
        model = ASNN(name)
        for frame in frames:
            model.step(frame)
