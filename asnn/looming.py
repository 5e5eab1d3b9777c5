"""Direct estimate of a region's expansion and drift from brightness derivatives.

The ASNN's approach map says *where* something changes like an approaching edge; it cannot tell
a dark object growing from a light one shrinking (both darken the same pixels), and it does not
say *how soon* the object arrives. Both follow from the image motion of the whole region: an
approaching object's image expands about a point, a receding one contracts, a passing one
drifts. For a surface roughly facing the camera, moving relative to it with velocity
``(U, V, W)`` at depth ``Z``, the image motion about a point ``(c_x, c_y)`` of the region is

    u = A + C (x - c_x),    v = B + C (y - c_y),

with the expansion rate ``C = W / Z`` (the inverse of the time to contact, Lee's tau) and the
drift ``(A, B)`` of that point. With the brightness-constancy constraint
``E_x u + E_y v + E_t = 0`` this is linear in ``(A, B, C)``, so a least-squares fit over the
region's pixels gives them directly from the spatial derivatives ``E_x, E_y`` and the temporal
derivative ``E_t`` (the photoreceptor signal): Horn, Fang and Masaki's direct time-to-contact
method, their case of arbitrary translation relative to a frontal plane [1]_. A fourth unknown
``D``, a uniform brightness change of the region, keeps global lighting changes (exposure,
flicker, headlights) out of ``C``. No features, no optical flow field and no tracking of edges
are needed, and the result does not depend on the object's contrast or polarity.

References
----------
.. [1] B. K. P. Horn, Y. Fang, I. Masaki, "Time to contact relative to a planar surface",
   IEEE Intelligent Vehicles Symposium, 2007, pp. 68-74.
.. [2] D. N. Lee, "A theory of visual control of braking based on information about
   time-to-collision", Perception 5, 1976, pp. 437-459.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

__all__ = ["Expansion", "region_expansion"]

_MIN_SIDE = 5  # pixels: a smaller box has too few gradients for four unknowns
_MAX_SIDE = 64
_RIDGE = 1e-6  # relative regularisation of the normal equations (no texture: C -> 0)
_GRADIENT_FLOOR = 1e-3  # intensity per pixel: below it a pixel's normal flow means nothing
_RESIDUAL_SCALE = 0.5  # pixels per frame: a pixel the background motion misses by this moves
_OWN_FRACTION = 0.05  # of the box's gradient energy that must move otherwise than the ring


class Expansion(NamedTuple):
    """Image motion of a region between two frames, per frame interval.

    Attributes
    ----------
    drift_x, drift_y : float
        Translation ``(A, B)`` of the box centre, pixels per frame.
    rate : float
        Expansion rate ``C`` about the box centre, per frame: > 0 expanding (approaching),
        < 0 contracting (receding). Time to contact is ``1 / rate`` frames.
    brightness : float
        Uniform brightness change ``D`` of the region, intensity units per frame.
    """

    drift_x: float
    drift_y: float
    rate: float
    brightness: float


def region_expansion(previous: np.ndarray, current: np.ndarray, box: tuple[int, int, int, int],
                     weights: np.ndarray | None = None,
                     surround: float = 0.0) -> Expansion | None:
    """Expansion and drift of a box of the image between two frames (Horn et al. [1]_).

    Solves ``E_x A + E_y B + g C + D = -E_t`` in the least-squares sense over the box, with
    ``g = (x - c_x) E_x + (y - c_y) E_y`` the radial gradient about the box centre. Spatial
    derivatives are Sobel derivatives of the mean of the two frames (centred in time), the
    temporal one their difference.

    With ``surround``, the motion of the background is fitted first on a ring around the box
    (the box widened by ``surround`` times its larger side), and the box's pixels that this
    motion explains (a normal-flow residual well under a pixel per frame) are left out of the
    fit: a background moving otherwise behind the object, or with the camera, then does not
    pull the object's estimate towards its own motion. This is the dominant-motion
    segmentation of Irani, Rousso and Peleg [3]_ in its simplest form. When the background
    motion explains nearly the whole box, the box moves with it and the plain fit is returned.

    Parameters
    ----------
    previous, current : ndarray (H, W)
        Luminance of two frames, float.
    box : (x0, y0, x1, y1)
        Pixels ``x0 <= x < x1``, ``y0 <= y < y1``.
    weights : ndarray (H, W), optional
        Non-negative weight of each pixel's constraint; uniform by default.
    surround : float
        Width of the background ring in units of the box's larger side; 0: no ring.

    Returns
    -------
    Expansion or None
        None when the box is smaller than 5x5 pixels or holds no gradient to measure.

    References
    ----------
    .. [3] M. Irani, B. Rousso, S. Peleg, "Computing occluding and transparent motions",
       International Journal of Computer Vision 12, 1994, pp. 5-16.
    """
    x0, y0, x1, y1 = box
    if x1 - x0 < _MIN_SIDE or y1 - y0 < _MIN_SIDE:
        return None
    h, w = previous.shape
    pad = int(round(surround * max(x1 - x0, y1 - y0)))
    ox0, oy0, ox1, oy1 = max(x0 - pad, 0), max(y0 - pad, 0), min(x1 + pad, w), min(y1 + pad, h)
    before = previous[oy0:oy1, ox0:ox1]
    after = current[oy0:oy1, ox0:ox1]
    wt = None if weights is None else weights[oy0:oy1, ox0:ox1]
    # a large box is fitted at a coarser scale: fewer pixels, and an edge that moves several
    # pixels per frame stays within the linear range of the brightness-constancy equation
    step = max(ox1 - ox0, oy1 - oy0) / _MAX_SIDE
    if step > 1.0:
        size = (max(round((ox1 - ox0) / step), 1), max(round((oy1 - oy0) / step), 1))
        before, after = (cv2.resize(np.ascontiguousarray(a), size, interpolation=cv2.INTER_AREA)
                         for a in (before, after))
        if wt is not None:
            wt = cv2.resize(np.ascontiguousarray(wt, np.float32), size,
                            interpolation=cv2.INTER_AREA)
    else:
        step = 1.0
    mean = 0.5 * (before + after)
    ex = cv2.Sobel(mean, cv2.CV_64F, 1, 0, ksize=3) / 8.0
    ey = cv2.Sobel(mean, cv2.CV_64F, 0, 1, ksize=3) / 8.0
    et = (after - before).astype(np.float64)
    # coordinates about the box's centre, in pixels of the fitting scale
    oh, ow = ex.shape
    xs = (np.arange(ow, dtype=np.float64) + 0.5) * step + ox0 - 0.5 * (x0 + x1)
    ys = (np.arange(oh, dtype=np.float64) + 0.5) * step + oy0 - 0.5 * (y0 + y1)
    xs /= step
    ys /= step
    radial = xs[None, :] * ex + ys[:, None] * ey
    wt = np.ones(ex.shape) if wt is None else np.maximum(wt, 0.0).astype(np.float64)
    inner = (np.abs(xs)[None, :] <= 0.5 * (x1 - x0) / step) & \
        (np.abs(ys)[:, None] <= 0.5 * (y1 - y0) / step)
    fit = _fit(ex, ey, radial, et, np.where(inner, wt, 0.0))
    if pad and fit is not None and not inner.all():
        fit = _without_background(ex, ey, radial, et, wt, inner, fit)
    if fit is None:
        return None
    return Expansion(fit.drift_x * step, fit.drift_y * step, fit.rate, -fit.brightness)


def _without_background(ex, ey, radial, et, wt, inner, plain):
    """The fit of the box's pixels that the ring's motion does not explain (see
    :func:`region_expansion`); ``plain`` when there are too few of them."""
    background = _fit(ex, ey, radial, et, np.where(inner, 0.0, 1.0))
    if background is None:
        return plain
    a, b, c, d = background
    grad = np.sqrt(ex * ex + ey * ey) + _GRADIENT_FLOOR
    residual = (et + a * ex + b * ey + c * radial + d) / grad  # pixels per frame
    moving = 1.0 - np.exp(-(residual / _RESIDUAL_SCALE) ** 2)
    own = np.where(inner, wt * moving, 0.0)
    energy = ex * ex + ey * ey
    if float((own * energy).sum()) < _OWN_FRACTION * float((np.where(inner, wt, 0.0) * energy).sum()):
        return plain  # the background's motion explains the box: it moves with it
    return _fit(ex, ey, radial, et, own) or plain


def _fit(ex: np.ndarray, ey: np.ndarray, radial: np.ndarray, et: np.ndarray,
         wt: np.ndarray) -> Expansion | None:
    """Weighted least squares of ``E_x A + E_y B + g C + D = -E_t``."""
    basis = np.stack([ex.ravel(), ey.ravel(), radial.ravel(), np.ones(ex.size)])
    weighted = basis * wt.ravel()
    normal = weighted @ basis.T
    rhs = -(weighted @ et.ravel())
    scale = np.trace(normal[:3, :3])
    if not scale > 0 or not normal[3, 3] > 0:
        return None
    # the gradient terms are regularised relative to their own size; D is well posed by n
    normal[np.arange(3), np.arange(3)] += _RIDGE * scale
    a, b, c, d = np.linalg.solve(normal, rhs)
    return Expansion(float(a), float(b), float(c), float(d))
