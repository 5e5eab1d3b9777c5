"""The layers of the ASNN retina, one pure function per stage of the paper.

Each function takes and returns plain NumPy arrays (H x W, row-major, x to the right and y
downwards) and names the equation of Huang et al. it implements. Spatial filtering is 2-D
*correlation* with OpenCV's reflect-101 border, as in the published implementation; for the
symmetric kernels this equals the paper's convolution, and for the odd Gabor kernel the sign
convention of :func:`gabor_pair` absorbs the flip.

References
----------
.. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
   Detection in Cluttered and Dynamic Backgrounds".
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import cv2
import numpy as np

__all__ = [
    "correlate",
    "photoreceptor_weights",
    "photoreceptor",
    "contrast_gain_control",
    "contrast_pool",
    "contrast_pool_spread",
    "dog_kernel",
    "dog_norms",
    "bipolar",
    "temporal_filter_step",
    "temporal_readout",
    "gabor_pair",
    "center_surround_kernel",
    "motion_energy",
    "motion_strength",
    "motion_direction",
    "motion_components",
    "center_surround_inhibition",
    "approach_map",
    "group",
    "attention_blur",
    "coarse_grid",
    "coarse_attention_blur",
    "coarse_grid_blur",
    "approach_attention",
    "direction_attention",
    "attended_response",
    "membrane_potential",
    "sigmoid_output",
    "potential_for_output",
    "spike_count",
    "spike_rate",
    "collision_warning",
]

_BORDER = cv2.BORDER_REFLECT_101
_POOL_STEP = 4  # grid step of the contrast gain control's pool


def correlate(image: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """2-D correlation with a centred kernel and reflect-101 border, in the image's float type."""
    depth = cv2.CV_32F if image.dtype == np.float32 else cv2.CV_64F
    return cv2.filter2D(image, depth, kernel, borderType=_BORDER)


# --------------------------------------------------------------------------- photoreceptors


def photoreceptor_weights(n_p: int, u: float = 1.0) -> np.ndarray:
    """Decay coefficients p_i = 1 / (1 + exp(u i)), i = 1..N_p (paper eq. 1 [1]_).

    Parameters
    ----------
    n_p : int
        N_p, the frames of photoreceptor history (``ASNNParams.n_p``); 0 gives no weights.
    u : float
        u of p_i (``ASNNParams.p_u``; the paper chooses 1).

    Returns
    -------
    p : ndarray of float64 (N_p,)
        p_1..p_N_p, the weights of P(t-1)..P(t-N_p) in :func:`photoreceptor`; decreasing for
        u > 0 (0.269, 0.119, 0.047, ... for u = 1), and 0 where exp(u i) overflows a float.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 1.
    """
    i = np.arange(1, n_p + 1, dtype=np.float64)
    with np.errstate(over="ignore"):  # exp(u i) beyond a float: p_i is 0, as it should be
        return 1.0 / (1.0 + np.exp(u * i))


def photoreceptor(current: np.ndarray, previous: np.ndarray, history: list[np.ndarray],
                  weights: np.ndarray) -> np.ndarray:
    """Photoreceptor activation, paper eq. 1 [1]_.

    ``P(t) = I(t) - I(t-1) + sum_i p_i P(t-i)``

    Parameters
    ----------
    current, previous : ndarray (H, W)
        Luminance of frames t and t-1 (on the scale the thresholds use, [0, 1]).
    history : list of ndarray (H, W)
        Earlier activations, most recent first: ``history[i-1] = P(t-i)``.
    weights : ndarray (N_p,)
        Decay coefficients from :func:`photoreceptor_weights`.

    Returns
    -------
    P : ndarray (H, W)

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 1.
    """
    p = current - previous
    for w, past in zip(weights, history):
        p += w * past
    return p


def contrast_gain_control(p: np.ndarray, semi_saturation: float, sigma: float,
                          scale: float) -> np.ndarray:
    """Divisive contrast gain control of the photoreceptor signal (robust addition).

    ``P' = s P / (c + g_sigma * |P|)``: each pixel's change is divided by the pooled magnitude
    of the changes around it. A moving edge then drives the bipolar cells by about the same
    amount whatever its contrast (Weber contrast 0.2 or 1), and a faint approach is not cut off
    by the fixed attention thresholds downstream; ``c`` keeps changes much smaller than it
    (sensor noise) small. This is the retina's contrast adaptation [1]_, [2]_ in the canonical
    divisive-normalisation form [3]_; the pool is a Gaussian of ``sigma`` pixels, computed on a
    grid four times coarser (area-averaged down, blurred, bilinearly up): the pool is smooth at
    that scale, and the full-resolution blur would cost more than the rest of the stage.

    Parameters
    ----------
    p : ndarray (H, W)
        Photoreceptor activation P.
    semi_saturation : float
        c, in [0, 1] intensity units.
    sigma : float
        Standard deviation of the pooling Gaussian, pixels.
    scale : float
        s, the output scale.

    Returns
    -------
    ndarray (H, W)

    References
    ----------
    .. [1] R. M. Shapley, J. D. Victor, "The effect of contrast on the transfer properties of
       cat retinal ganglion cells", J. Physiol. 285, 1978, pp. 275-298.
    .. [2] S. A. Baccus, M. Meister, "Fast and slow contrast adaptation in retinal circuitry",
       Neuron 36, 2002, pp. 909-919.
    .. [3] M. Carandini, D. J. Heeger, "Normalization as a canonical neural computation",
       Nat. Rev. Neurosci. 13, 2012, pp. 51-62.
    """
    return p * (scale / (semi_saturation + contrast_pool(p, sigma)))


def contrast_pool(p: np.ndarray, sigma: float) -> np.ndarray:
    """The pooled magnitude ``g_sigma * |P|`` of :func:`contrast_gain_control`, on its coarse
    grid and bilinearly interpolated back."""
    h, w = p.shape
    coarse = cv2.resize(np.abs(p), (max(w // _POOL_STEP, 1), max(h // _POOL_STEP, 1)),
                        interpolation=cv2.INTER_AREA)
    return contrast_pool_spread(coarse, sigma, (h, w))


def contrast_pool_spread(coarse: np.ndarray, sigma: float, shape: tuple[int, int]) -> np.ndarray:
    """:func:`contrast_pool` from the area averages of ``|P|`` on its coarse grid: blurred
    there and bilinearly interpolated back to ``shape`` (H, W)."""
    coarse = cv2.GaussianBlur(coarse, (0, 0), sigma / _POOL_STEP, borderType=_BORDER)
    return cv2.resize(coarse, (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)


# --------------------------------------------------------------------------- bipolar cells


def dog_kernel(gain: float, sigma1: float, sigma2: float, size: int,
               normalisation: str = "paper") -> np.ndarray:
    """Difference-of-Gaussians kernel g_I, paper eq. 3 [1]_, sampled on integer pixel offsets.

    ``normalisation='paper'`` uses F/(sqrt(2 pi) sigma) as printed; ``'2d'`` uses the
    two-dimensional F/(2 pi sigma^2) of the published implementation. Neither is renormalised.

    Parameters
    ----------
    gain : float
        F.
    sigma1, sigma2 : float
        The centre's and the surround's standard deviations, pixels.
    size : int
        The kernel's side (odd).
    normalisation : {'paper', '2d'}

    Returns
    -------
    g_I : ndarray (size, size)

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 3.
    """
    r = size // 2
    y, x = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float64)
    r2 = x * x + y * y
    norm1, norm2 = dog_norms(sigma1, sigma2, normalisation)
    return gain * (np.exp(-r2 / (2 * sigma1**2)) / norm1 - np.exp(-r2 / (2 * sigma2**2)) / norm2)


def dog_norms(sigma1: float, sigma2: float, normalisation: str) -> tuple[float, float]:
    """Denominators of the two Gaussians of g_I: ``sqrt(2 pi) sigma`` ('paper') or ``2 pi sigma^2``
    ('2d')."""
    if normalisation == "paper":
        return math.sqrt(2 * math.pi) * sigma1, math.sqrt(2 * math.pi) * sigma2
    if normalisation == "2d":
        return 2 * math.pi * sigma1**2, 2 * math.pi * sigma2**2
    raise ValueError(f"unknown normalisation {normalisation!r}")


def bipolar(p: np.ndarray, dog: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ON and OFF bipolar inputs B+^0, B-^0: half-wave rectification then g_I (paper
    eqs. 2, 4 [1]_).

    Parameters
    ----------
    p : ndarray (H, W)
        Photoreceptor activation P.
    dog : ndarray (k, k)
        g_I (:func:`dog_kernel`).

    Returns
    -------
    on, off : ndarray (H, W)
        ``relu(P) (*) g_I`` and ``relu(-P) (*) g_I``.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eqs. 2, 4.
    """
    return correlate(np.maximum(p, 0.0), dog), correlate(np.maximum(-p, 0.0), dog)


# --------------------------------------------------------------------------- temporal filter


def temporal_filter_step(stages: np.ndarray, x: np.ndarray, rate: float, transmission: float,
                         decay: float, leaky_input: bool) -> None:
    """Advance the leaky-integrator cascade by one frame, in place (paper eq. 5 [1]_).

    ``tau dz_n/dt = -A z_n + C z_{n-1}``, integrated with forward Euler, ``rate = dt / tau``,
    stage by stage so that each stage sees its predecessor as already updated in this frame
    (the published implementation's order; both converge to eq. 5 as dt -> 0).

    Parameters
    ----------
    stages : ndarray (n_s + 2, H, W)
        ``stages[i]`` is z_i. With ``leaky_input=False`` (the paper), z_0 is the input itself and
        z_1..z_{n_s+1} integrate; with ``leaky_input=True`` (the published implementation), z_0 is
        an integrator of the input as well.
    x : ndarray (H, W)
        The bipolar input B^0 of this frame.
    rate : float
        ``dt / tau``, the Euler step in units of the stages' time constant.
    transmission : float
        C, the gain with which each stage takes its predecessor.
    decay : float
        A, each stage's leak.
    leaky_input : bool
        Whether z_0 integrates the input (the published implementation) or is the input.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 5.
    """
    if leaky_input:
        stages[0] += rate * (transmission * x - decay * stages[0])
    else:
        stages[0] = x
    for i in range(1, stages.shape[0]):
        stages[i] += rate * (transmission * stages[i - 1] - decay * stages[i])


def temporal_readout(stages: np.ndarray, gain: float, n: int) -> np.ndarray:
    """Temporal filter output L(K, n, z_0) = K (z_n - z_{n+1}) (paper eq. 6 [1]_); read at
    n = n_f and n = n_s it gives the fast and slow bipolar responses B^f, B^s (eq. 7).

    Parameters
    ----------
    stages : ndarray (n_s + 2, H, W)
        The cascade z_0..z_{n_s+1} of :func:`temporal_filter_step`.
    gain : float
        K.
    n : int
        The stage read: n_f for the fast response B^f, n_s for the slow B^s.

    Returns
    -------
    ndarray (H, W)

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eqs. 6, 7.
    """
    return gain * (stages[n] - stages[n + 1])


# --------------------------------------------------------------------------- amacrine cells


def _grid(size: int, extent: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample coordinates (X along columns, Y along rows) spanning [-extent, extent]."""
    axis = np.linspace(-extent, extent, size)
    x, y = np.meshgrid(axis, axis)
    return x, y


def gabor_pair(theta: float, sigma: float, wavelength: float, size: int,
               extent: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Even and odd Gabor kernels g^0_DS, g^{pi/2}_DS at orientation theta (paper eq. 9 [1]_).

    ``g = exp(-(x'^2 + y'^2) / (2 sigma^2)) cos(2 pi x' / lambda + psi)`` with
    ``x' = x cos(theta) + y sin(theta)``, ``y' = -x sin(theta) + y cos(theta)``, x along columns
    and y along rows (downwards). The odd kernel is ``exp(...) sin(2 pi x' / lambda)``
    (psi = -pi/2): with correlation, this sign makes the direction estimate of
    :func:`motion_energy` point the way things move in image coordinates.

    The published implementation uses ``theta' = pi - theta``; its orientation k is this
    function's orientation (4 - k) mod 8, so all its sums, maxima and masks are the same and
    only the x component of its motion vectors has the opposite sign.

    Parameters
    ----------
    theta : float
        Orientation, radians.
    sigma, wavelength : float
        The envelope's standard deviation and lambda, in the sampled coordinates.
    size : int
        The kernel's side (odd).
    extent : float
        The samples span [-extent, extent] in x and y (SPEC ruling).

    Returns
    -------
    even, odd : ndarray (size, size)

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 9.
    """
    x, y = _grid(size, extent)
    rx = x * math.cos(theta) + y * math.sin(theta)
    ry = -x * math.sin(theta) + y * math.cos(theta)
    envelope = np.exp(-(rx**2 + ry**2) / (2 * sigma**2))
    phase = 2 * math.pi * rx / wavelength
    return envelope * np.cos(phase), envelope * np.sin(phase)


def center_surround_kernel(sigma: float, wavelength: float, phase: float, size: int,
                           extent: float = 1.0) -> np.ndarray:
    """Antagonistic centre-surround kernel g_CS (paper eq. 11 [1]_).

    ``g_CS = 1 - exp(-r^2 / (2 sigma^2)) cos(2 pi r^2 / lambda + psi)``; with psi = 0 the centre
    weight is 0 and the surround approaches 1.

    Parameters
    ----------
    sigma, wavelength, phase : float
        sigma_CS, lambda_CS and psi_CS, in the sampled coordinates.
    size, extent
        As in :func:`gabor_pair`.

    Returns
    -------
    g_CS : ndarray (size, size)

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 11.
    """
    x, y = _grid(size, extent)
    r2 = x * x + y * y
    return 1.0 - np.exp(-r2 / (2 * sigma**2)) * np.cos(2 * math.pi * r2 / wavelength + phase)


def _orientation_energy(slow: np.ndarray, fast: np.ndarray, even: np.ndarray,
                        odd: np.ndarray) -> np.ndarray:
    """E^theta = SA^1 SB^2 - SA^2 SB^1 for one channel and one orientation (paper eqs. 10, 15)."""
    sa1, sb1 = correlate(slow, even), correlate(slow, odd)
    sa2, sb2 = correlate(fast, even), correlate(fast, odd)
    return sa1 * sb2 - sa2 * sb1


def motion_energy(slow_on: np.ndarray, fast_on: np.ndarray, slow_off: np.ndarray,
                  fast_off: np.ndarray, pairs: list[tuple[np.ndarray, np.ndarray]],
                  v_on: float, v_off: float) -> np.ndarray:
    """Ganglion motion energy R^theta = v+ E+^theta + v- E-^theta (paper eqs. 10, 15, 16 [1]_).

    Parameters
    ----------
    slow_on, fast_on, slow_off, fast_off : ndarray (H, W)
        Bipolar responses B+^s, B+^f, B-^s, B-^f.
    pairs : list of (even, odd) kernels
        Gabor pairs for the orientations theta_k = k pi / n, k = 0..n-1 (half the circle).
    v_on, v_off : float
        Channel weights v+ and v-.

    Returns
    -------
    R : ndarray (2 n, H, W)
        R^theta for theta_k = k pi / n, k = 0..2n-1. The second half is the negation of the
        first: the even kernel is symmetric and the odd one antisymmetric under theta -> theta + pi,
        so R^{theta + pi} = -R^theta exactly.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eqs. 10, 15, 16.
    """
    n = len(pairs)
    h, w = slow_on.shape
    r = np.empty((2 * n, h, w), dtype=slow_on.dtype)
    for k, (even, odd) in enumerate(pairs):
        r[k] = v_on * _orientation_energy(slow_on, fast_on, even, odd)
        r[k] += v_off * _orientation_energy(slow_off, fast_off, even, odd)
        np.negative(r[k], out=r[k + n])
    return r


def motion_strength(r: np.ndarray) -> np.ndarray:
    """Motion energy V = max_theta R^theta (paper eq. 17 [1]_), over the orientations of ``r``
    (:func:`motion_energy`'s, the whole circle).

    Parameters
    ----------
    r : ndarray (2 n, H, W)
        R^theta for the orientations theta_k = k pi / n, k = 0..2n-1 (:func:`motion_energy`).

    Returns
    -------
    V : ndarray (H, W)
        In ``r``'s dtype. Never negative: with R^{theta + pi} = -R^theta in ``r``, the maximum
        over the circle is the largest |R^theta| over half of it.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 17.
    """
    return r.max(axis=0)


def motion_direction(r: np.ndarray) -> np.ndarray:
    """Motion direction phi = atan2(R^{pi/2}, R^0) (paper eq. 18 [1]_), in image coordinates (x
    right, y down: +pi/2 points down the image), from :func:`motion_energy`'s ``r`` (any number
    of orientations divisible by 4, the whole circle).

    Parameters
    ----------
    r : ndarray (n_theta, H, W)
        R^theta for theta_k = 2 pi k / n_theta (:func:`motion_energy`): ``r[0]`` is R^0 and
        ``r[n_theta // 4]`` is R^{pi/2}.

    Returns
    -------
    phi : ndarray (H, W)
        Radians in [-pi, pi], in ``r``'s dtype; 0 where R^0 and R^{pi/2} are both 0.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 18.
    """
    return np.arctan2(r[len(r) // 4], r[0])


def motion_components(v: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The motion vectors V_x = V cos(phi), V_y = V sin(phi) (paper eq. 29 [1]_) that the targets'
    directions and energies average.

    Parameters
    ----------
    v : ndarray (H, W)
        The motion energy V (:func:`motion_strength`).
    phi : ndarray (H, W)
        The motion direction, radians, image coordinates (:func:`motion_direction`).

    Returns
    -------
    dx, dy : ndarray (H, W)
        V_x and V_y, in image coordinates (V_y > 0 points down the image): what
        :func:`asnn.targets.extract_targets` averages over a target's pixels (eqs. 30, 31).

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 29.
    """
    return v * np.cos(phi), v * np.sin(phi)


def center_surround_inhibition(response: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """SAC inhibition S = relu(B (*) g_CS) (paper eqs. 12-14 [1]_).

    Parameters
    ----------
    response : ndarray (H, W)
        The inhibiting bipolar response B.
    kernel : ndarray (k, k)
        g_CS (:func:`center_surround_kernel`).

    Returns
    -------
    S : ndarray (H, W)

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eqs. 12-14.
    """
    return np.maximum(correlate(response, kernel), 0.0)


def approach_map(slow_on: np.ndarray, fast_on: np.ndarray, slow_off: np.ndarray,
                 fast_off: np.ndarray, cs_kernel: np.ndarray,
                 weights: tuple[float, float, float, float]) -> np.ndarray:
    """Approach-sensitive map G of the ganglion cells (paper eqs. 19, 20 [1]_).

    ``G1+ = relu(relu(B+s) - S1-)``, ``G2+ = relu(relu(B+f) - S2-)``,
    ``G1- = relu(relu(B-s) - S1+)``, ``G2- = relu(relu(B-f) - S2+)``, where
    ``S1± = relu(B±f (*) g_CS)`` and ``S2± = relu(B±s (*) g_CS)``; then
    ``G = w1+ G1+ - w2- G2- + w1- G1- - w2+ G2+``.

    Parameters
    ----------
    slow_on, fast_on : ndarray (H, W)
        The ON pathway's slow and fast temporal filter outputs, B+s and B+f.
    slow_off, fast_off : ndarray (H, W)
        The OFF pathway's, B-s and B-f.
    cs_kernel : ndarray (k, k)
        g_CS, the starburst amacrine cells' centre-surround kernel (eq. 11).
    weights : (w1_on, w2_off, w1_off, w2_on)
        Signed as in the fusion equation; a zero weight skips its term's filtering.

    Returns
    -------
    g : ndarray (H, W)
        G, positive where the approach is seen.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eqs. 19, 20.
    """
    w1_on, w2_off, w1_off, w2_on = weights
    g = np.zeros_like(slow_on)

    def term(excitation: np.ndarray, inhibitor: np.ndarray) -> np.ndarray:
        inhibition = center_surround_inhibition(inhibitor, cs_kernel)
        return np.maximum(np.maximum(excitation, 0.0) - inhibition, 0.0)

    if w1_on:
        g += w1_on * term(slow_on, fast_off)     # G1+, inhibited by S1-
    if w2_off:
        g -= w2_off * term(fast_off, slow_on)    # G2-, inhibited by S2+
    if w1_off:
        g += w1_off * term(slow_off, fast_on)    # G1-, inhibited by S1+
    if w2_on:
        g -= w2_on * term(fast_on, slow_off)     # G2+, inhibited by S2-
    return g


def group(g: np.ndarray) -> np.ndarray:
    """Grouping of the published implementation: ``G (G (*) ones(3, 3) / 9)``.

    Not in the paper (SPEC.md section 3, "Grouping"; ``ASNNParams.grouping``): each pixel of G
    is multiplied by the mean of G over its 3 x 3 neighbourhood (reflect-101 border), so that
    G is weighted by the activity around it: an isolated pixel keeps a ninth of its square, a
    pixel inside an evenly active region about its square.

    Parameters
    ----------
    g : ndarray (H, W)
        The approach map G (:func:`approach_map`).

    Returns
    -------
    ndarray (H, W)
        In ``g``'s dtype. Where G can be negative (positive w2 weights), a negative pixel among
        negative neighbours reads positive.
    """
    return g * cv2.blur(g, (3, 3), borderType=_BORDER)


# --------------------------------------------------------------------------- attention


def attention_blur(image: np.ndarray, sigma: float, size: int, normalised: bool,
                   step: int = 1) -> np.ndarray:
    """Smoothing with the attention Gaussian g_sigma (paper eqs. 21, 22 [1]_).

    ``normalised=False`` uses the printed ``exp(-r^2/2 sigma^2) / (2 pi sigma^2)`` on a
    size x size window; ``True`` uses OpenCV's GaussianBlur (sampled, normalised to sum 1),
    as the published implementation does. With ``step`` > 1 the image is area-averaged onto a
    grid ``step`` times coarser, blurred there with ``sigma / step`` and interpolated back
    (bilinear): the blurred map is smooth at that scale, and the blur costs ``step**2`` less.

    Parameters
    ----------
    image : ndarray (H, W)
    sigma : float
        sigma_g, pixels.
    size : int
        The window's side (odd).
    normalised : bool
    step : int

    Returns
    -------
    ndarray (H, W)

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eqs. 21, 22.
    """
    if step > 1:
        return coarse_attention_blur(coarse_grid(image, step), image.shape, sigma, size,
                                     normalised, step)
    if normalised:
        return cv2.GaussianBlur(image, (size, size), sigma, borderType=_BORDER)
    r = size // 2
    axis = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-axis**2 / (2 * sigma**2)) / (math.sqrt(2 * math.pi) * sigma)
    depth = cv2.CV_32F if image.dtype == np.float32 else cv2.CV_64F
    return cv2.sepFilter2D(image, depth, k, k, borderType=_BORDER)


def coarse_grid(image: np.ndarray, step: int) -> np.ndarray:
    """The area average of an image on the grid ``step`` times coarser of
    :func:`attention_blur`: ``ceil(W / step) x ceil(H / step)`` cells, each the average of
    ``W / ceil(W / step)`` (by ``H / ceil(H / step)``) pixels, so where ``step`` does not divide
    the size every cell is a little narrower than ``step`` (OpenCV's area resampling)."""
    h, w = image.shape
    return cv2.resize(image, (-(-w // step), -(-h // step)), interpolation=cv2.INTER_AREA)


def coarse_attention_blur(coarse: np.ndarray, shape: tuple[int, int], sigma: float, size: int,
                          normalised: bool, step: int) -> np.ndarray:
    """:func:`attention_blur` with ``step`` > 1 of an image of this shape, given its area
    average on the coarse grid."""
    blurred = coarse_grid_blur(coarse, sigma, size, normalised, step)
    return cv2.resize(blurred, shape[::-1], interpolation=cv2.INTER_LINEAR)


def coarse_grid_blur(coarse: np.ndarray, sigma: float, size: int, normalised: bool,
                     step: int) -> np.ndarray:
    """The blur of :func:`attention_blur` with ``step`` > 1 on its coarse grid, before the
    bilinear interpolation back."""
    return attention_blur(coarse, sigma / step, (size // step) | 1, normalised)


def approach_attention(g: np.ndarray, sigma: float, size: int, normalised: bool,
                       gamma_a: float, step: int = 1) -> np.ndarray:
    """Approach-sensitive attention mask M_a = B(G (*) g_sigma, gamma_a) (paper eqs. 22, 23 [1]_).

    Parameters
    ----------
    g : ndarray (H, W)
        The approach map G.
    sigma, size, normalised, step
        The attention blur's, as in :func:`attention_blur`.
    gamma_a : float
        The mask's threshold.

    Returns
    -------
    m_a : ndarray of bool (H, W)

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eqs. 22, 23.
    """
    return attention_blur(g, sigma, size, normalised, step) > gamma_a


def direction_attention(r: np.ndarray, v: np.ndarray, top_k: int, sigma: float, size: int,
                        normalised: bool, gamma_d: float, step: int = 1) -> np.ndarray:
    """Directionally selective attention M_d (paper eqs. 24-26 [1]_).

    The top-k orientations by ``R_sum(theta) = sum_xy R^theta`` form Theta_I;
    ``V' = V - max_{Theta_I} R`` and ``M_d = B(V' (*) g_sigma, gamma_d)``.

    Parameters
    ----------
    r : ndarray (n_theta, H, W)
        Motion energy per orientation.
    v : ndarray (H, W)
        Its maximum over orientations.
    top_k : int
        k, the orientations inhibited; 0 inhibits none.
    sigma, size, normalised, step
        The attention blur's, as in :func:`attention_blur`.
    gamma_d : float
        The mask's threshold.

    Returns
    -------
    m_d : ndarray of bool (H, W)

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eqs. 24-26.
    """
    if top_k:
        totals = r.sum(axis=(1, 2))
        inhibited = np.argsort(-totals, kind="stable")[:top_k]
        v = v - r[inhibited].max(axis=0)
    return attention_blur(v, sigma, size, normalised, step) > gamma_d


# --------------------------------------------------------------------------- output


def attended_response(g: np.ndarray, m_a: np.ndarray, m_d: np.ndarray) -> np.ndarray:
    """The attended approach response G' = G M_a M_d (paper eq. 27 [1]_).

    Parameters
    ----------
    g : ndarray (H, W)
        The approach map G (after grouping, where the preset groups).
    m_a, m_d : ndarray of bool (H, W)
        The attention masks M_a (:func:`approach_attention`) and M_d
        (:func:`direction_attention`).

    Returns
    -------
    G' : ndarray (H, W)
        G where both masks hold, 0 elsewhere, in ``g``'s dtype.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 27.
    """
    return g * (m_a & m_d)


def membrane_potential(g_prime: np.ndarray, scale: float, absolute: bool) -> float:
    """u(t) = sum_xy G'(x, y, t) (paper eq. 28 [1]_), scaled; ``absolute`` sums |G'| instead.

    Parameters
    ----------
    g_prime : ndarray (H, W)
        The attended response G' (:func:`attended_response`).
    scale : float
        The factor applied to the sum (``ASNNParams.u_scale``: 255 measures u on the 0..255
        intensity scale of the published implementation, 1 on the [0, 1] scale of the input).
    absolute : bool
        Sum |G'| (``ASNNParams.u_abs``, the published implementation) instead of G', which can
        be negative where the preset subtracts the w2 terms.

    Returns
    -------
    u : float
        ``scale * sum(G')`` (or of |G'|).

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 28.
    """
    total = np.abs(g_prime).sum() if absolute else g_prime.sum()
    return float(scale * total)


def sigmoid_output(u: float, n_cells: int) -> float:
    """out(t) = 1 / (1 + exp(-|u| / N)), in [0.5, 1) (SPEC ruling on paper eq. 32 [1]_); in
    floating point it rounds to exactly 1.0 once |u| / N passes about 37.

    The paper prints exp(+|u| / N), which maps into (0, 0.5]; its text says [0.5, 1), and
    SPEC.md section 2 rules for the sign used here.

    Parameters
    ----------
    u : float
        The membrane potential u(t) (:func:`membrane_potential`); only |u| counts.
    n_cells : int
        N, the number of cells: the pixels of the model's grid (the frame's, or those of the
        size ``max_width`` or ``min_width`` resizes it to).

    Returns
    -------
    out : float
        0.5 for u = 0, rising towards 1 with |u| / N.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 32.
    """
    return 1.0 / (1.0 + math.exp(-abs(u) / n_cells))


def potential_for_output(out: float) -> float:
    """|u| / N at which :func:`sigmoid_output` reads ``out`` (in (0.5, 1)): eq. 32 inverted,
    log(out / (1 - out)).

    Parameters
    ----------
    out : float
        An output of :func:`sigmoid_output`, in [0.5, 1) (1 itself divides by zero).

    Returns
    -------
    float
        |u| / N, 0 for ``out`` = 0.5.
    """
    return math.log(out / (1.0 - out))


MAX_SPIKES = 2**31 - 1  # the spike count saturates here (eq. 33 grows without bound)


def spike_count(out: float, k_sp: float, t_sp: float) -> int:
    """spike(t) = floor(exp(K_sp (out - T_sp))) (paper eq. 33 [1]_), at most :data:`MAX_SPIKES`:
    capped so that exp never overflows a float (it would from an exponent of 710); past the
    cap no warning changes.

    Parameters
    ----------
    out : float
        The output out(t) (:func:`sigmoid_output`).
    k_sp : float
        K_sp, the spike gain (``ASNNParams.k_sp``).
    t_sp : float
        T_sp, the spike threshold on out(t) (``ASNNParams.t_sp``).

    Returns
    -------
    spikes : int
        0 while out < T_sp, at least 1 from out = T_sp on; :data:`MAX_SPIKES` from an
        exponent K_sp (out - T_sp) of ln(MAX_SPIKES) (about 21.5) on.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 33.
    """
    exponent = k_sp * (out - t_sp)
    if exponent >= math.log(MAX_SPIKES):
        return MAX_SPIKES
    return int(math.floor(math.exp(exponent)))


def spike_rate(spikes: Iterable[int], n_t: int, dt: float) -> float:
    """The spike rate of the warning, (1 / (N_t dt)) sum of the last N_t frames' spikes (paper
    eq. 34 [1]_), spikes per second; ``spikes`` holds at most N_t frames' (fewer at a stream's
    start, still divided by N_t: SPEC ruling).

    Parameters
    ----------
    spikes : iterable of int
        The spikes of the last N_t frames at most (:func:`spike_count`; the model's
        ``spike_window``).
    n_t : int
        N_t, the window's length in frames (``ASNNParams.n_t``).
    dt : float
        Delta t, the window's frame period, seconds: ``ASNNParams.window_dt`` (``spike_dt``,
        else ``dt``), not the frames' own timestamps.

    Returns
    -------
    rate : float
        Spikes per second of frames ``dt`` apart.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 34.
    """
    return sum(spikes) / (n_t * dt)


def collision_warning(rate: float, t_c: float) -> bool:
    """Col(t): the collision warning, a spike rate of at least T_c (paper eq. 34 [1]_).

    Parameters
    ----------
    rate : float
        The spike rate, spikes per second (:func:`spike_rate`).
    t_c : float
        T_c, the warning's threshold, Hz (``ASNNParams.t_c``).

    Returns
    -------
    bool
        Whether ``rate >= t_c``.

    References
    ----------
    .. [1] Huang, Qiao, Li, Jiang, "A Bioinspired Approach-Sensitive Neural Network for Collision
       Detection in Cluttered and Dynamic Backgrounds", eq. 34.
    """
    return rate >= t_c
