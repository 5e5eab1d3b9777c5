"""Motion layers of a region: its image motion split into the few looming motions it holds.

:func:`asnn.approach.looming.region_expansion` fits one expansion and one drift to a whole box.
Where the box holds two surfaces moving differently, least squares returns a blend that neither
surface has: a car pulling away ahead of us (contracting, drifting sideways) seen in one box with
the roadside behind it (expanding outward from our heading under our own forward motion) can read as
something growing dead ahead, because the two drifts cancel. This module splits the box's motion
instead, in the way of a layered representation of image sequences [1]_: the dense optical flow of
the box [2]_, then the looming model ``u = A + C (x - c_x)``, ``v = B + C (y - c_y)`` (the model of
:mod:`asnn.approach.looming`) fitted by random sample consensus [3]_ to the largest set of pixels it
explains, then again to the rest. Each motion found is a :class:`Layer`; an object coming at the
camera is one of them (:func:`asnn.approach.tracking.layers_approach` tests that).

Deterministic: the samples come from a generator seeded the same way on every call, so the
same frames give the same layers.

References
----------
.. [1] J. Y. A. Wang, E. H. Adelson, "Representing moving images with layers", IEEE
   Transactions on Image Processing 3(5), 1994, pp. 625-638.
.. [2] G. Farnebäck, "Two-frame motion estimation based on polynomial expansion", Scandinavian
   Conference on Image Analysis, 2003, pp. 363-370 (OpenCV's ``calcOpticalFlowFarneback``).
.. [3] M. A. Fischler, R. C. Bolles, "Random sample consensus: a paradigm for model fitting
   with applications to image analysis and automated cartography", Communications of the ACM
   24(6), 1981, pp. 381-395.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from .._jit import kernel
from .looming import shrink_step, shrunk_size

__all__ = ["Layer", "motion_layers"]

_MIN_SIDE = 8  # pixels: a smaller box holds too little flow to split
_SAMPLES = 60  # hypotheses per layer: two points each
_MIN_SHARE = 0.15  # a rest smaller than this share of the textured pixels is not a motion
_MIN_PIXELS = 10  # nor one of fewer pixels than this
_MIN_TEXTURED = 20  # a box with fewer textured pixels is not split at all
_TOLERANCE = (0.5, 0.3)  # a pixel fits a motion within 0.5 px or 30 % of its own flow
# Farnebäck's parameters: pyramid scale, levels, window, iterations, polynomial size and sigma
_FLOW = (0.5, 2, 9, 3, 5, 1.1)


class Layer(NamedTuple):
    """One motion of a box between two frames, per frame interval.

    Attributes
    ----------
    share : float
        The share of the box's textured pixels (those whose gradient is above the box's
        median) that this motion explains.
    drift_x, drift_y : float
        Translation ``(A, B)`` at the box centre, pixels per frame.
    rate : float
        Expansion rate ``C`` per frame: > 0 expanding, < 0 contracting.
    """

    share: float
    drift_x: float
    drift_y: float
    rate: float


def motion_layers(previous: np.ndarray, current: np.ndarray,
                  box: tuple[int, int, int, int], layers: int = 2) -> list[Layer]:
    """The looming motions a box of the image holds between two frames (Wang & Adelson [1]_).

    The box is area-averaged to at most 64 pixels a side, its dense optical flow computed
    (Farnebäck [2]_), and at the pixels whose gradient is above the box's median (where flow is
    measured, not filled in) the looming model fitted by random sample consensus [3]_: 60
    hypotheses from two pixels each, the one that most pixels fit (within 0.5 px or 30 % of
    their flow) refitted by least squares over them. Those pixels are then left out and the
    next motion is sought in the rest, while at least 15 % of the pixels (and 10) remain.

    Parameters
    ----------
    previous, current : ndarray (H, W)
        Luminance of two frames, float.
    box : (x0, y0, x1, y1)
        Pixels ``x0 <= x < x1``, ``y0 <= y < y1``.
    layers : int
        Most motions to find.

    Returns
    -------
    list of Layer
        In the order found (the first explains the most pixels); empty when the box is
        smaller than 8x8 pixels or holds no texture.

    References
    ----------
    .. [1] J. Y. A. Wang, E. H. Adelson, "Representing moving images with layers", IEEE
       Transactions on Image Processing 3(5), 1994, pp. 625-638.
    .. [2] G. Farnebäck, "Two-frame motion estimation based on polynomial expansion", SCIA
       2003, pp. 363-370.
    .. [3] M. A. Fischler, R. C. Bolles, "Random sample consensus", Communications of the ACM
       24(6), 1981, pp. 381-395.
    """
    x0, y0, x1, y1 = box
    if x1 - x0 < _MIN_SIDE or y1 - y0 < _MIN_SIDE:
        return []
    before = np.ascontiguousarray(previous[y0:y1, x0:x1], np.float32)
    after = np.ascontiguousarray(current[y0:y1, x0:x1], np.float32)
    step = shrink_step(x1 - x0, y1 - y0)  # a larger box is area-averaged first, as for a fit
    if step > 1.0:
        size = shrunk_size(x1 - x0, y1 - y0, step)
        before = cv2.resize(before, size, interpolation=cv2.INTER_AREA)
        after = cv2.resize(after, size, interpolation=cv2.INTER_AREA)
    low, high = min(before.min(), after.min()), max(before.max(), after.max())
    span = high - low
    if not span > 1e-4 * max(abs(low), abs(high)):  # flat, but for rounding
        return []
    # Farnebäck takes 8-bit images: both frames on one scale, so brightness stays comparable
    before, after = (np.clip((image - low) * 255 / span, 0, 255).astype(np.uint8)
                     for image in (before, after))
    flow = cv2.calcOpticalFlowFarneback(before, after, None, *_FLOW, 0)
    gradient = np.hypot(cv2.Sobel(before, cv2.CV_32F, 1, 0), cv2.Sobel(before, cv2.CV_32F, 0, 1))
    textured = gradient > np.median(gradient)
    n = int(textured.sum())
    if n < _MIN_TEXTURED:
        return []
    h, w = before.shape
    rows, cols = np.nonzero(textured)
    x = cols - 0.5 * (w - 1)
    y = rows - 0.5 * (h - 1)
    u = flow[..., 0][textured].astype(np.float64)
    v = flow[..., 1][textured].astype(np.float64)
    tolerance = np.maximum(_TOLERANCE[0], _TOLERANCE[1] * np.hypot(u, v))
    rng = np.random.default_rng(0)
    found = []
    rest = np.ones(n, bool)
    while len(found) < layers:
        members = np.flatnonzero(rest)
        if members.size < max(_MIN_PIXELS, _MIN_SHARE * n):
            break
        # two distinct pixels per hypothesis, from the generator seeded anew for every box
        pairs = np.array([rng.choice(members, 2, replace=False) for _ in range(_SAMPLES)])
        a, b, c = _best_hypothesis(x, y, u, v, tolerance * tolerance, members, pairs)
        fits = members[np.hypot(u[members] - (a + c * x[members]),
                                v[members] - (b + c * y[members])) < tolerance[members]]
        if fits.size < 2:
            break
        a, b, c = _least_squares(x[fits], y[fits], u[fits], v[fits])
        rest[fits] = False
        found.append(Layer(fits.size / n, float(a * step), float(b * step), float(c)))
    return found


def _least_squares(x, y, u, v):
    """``(A, B, C)`` of ``u = A + C x``, ``v = B + C y`` by least squares: ``C`` from the
    centred data, ``A`` and ``B`` from the means."""
    xm, ym, um, vm = x.mean(), y.mean(), u.mean(), v.mean()
    dx, dy = x - xm, y - ym
    spread = float((dx * dx + dy * dy).sum())
    c = float(((u - um) * dx + (v - vm) * dy).sum()) / spread if spread > 0 else 0.0
    return float(um - c * xm), float(vm - c * ym), c


@kernel(error_model="numpy")
def _best_hypothesis(x, y, u, v, tolerance2, members, pairs):
    """Of the hypotheses through the pixel pairs ``pairs`` (each the least-squares fit of the
    model to its two pixels), the ``(A, B, C)`` that most of ``members`` fit within their
    tolerance (``tolerance2``: its square); the first in order among equals."""
    best_a, best_b, best_c, best_count = 0.0, 0.0, 0.0, -1
    for k in range(pairs.shape[0]):
        i, j = pairs[k, 0], pairs[k, 1]
        dx, dy = x[i] - x[j], y[i] - y[j]
        spread = dx * dx + dy * dy
        c = ((u[i] - u[j]) * dx + (v[i] - v[j]) * dy) / spread if spread > 0 else 0.0
        a = 0.5 * (u[i] + u[j]) - c * 0.5 * (x[i] + x[j])
        b = 0.5 * (v[i] + v[j]) - c * 0.5 * (y[i] + y[j])
        count = 0
        for m in members:
            du, dv = u[m] - (a + c * x[m]), v[m] - (b + c * y[m])
            if du * du + dv * dv < tolerance2[m]:
                count += 1
        if count > best_count:
            best_a, best_b, best_c, best_count = a, b, c, count
    return best_a, best_b, best_c
