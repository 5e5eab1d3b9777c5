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

A camera on a vehicle sees parts of its own rig in every frame: the hood or the dashboard, a
recorder's timestamp. Their edges never move, so a fit over a box that reaches them reads part
of the box as still and the expansion as slower than the object's. :func:`rig_pixels` finds
those edges, and the fits leave them out.

References
----------
.. [1] B. K. P. Horn, Y. Fang, I. Masaki, "Time to contact relative to a planar surface",
   IEEE Intelligent Vehicles Symposium, 2007, pp. 68-74.
.. [2] D. N. Lee, "A theory of visual control of braking based on information about
   time-to-collision", Perception 5, 1976, pp. 437-459.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np

from .._fast import _area_fast, _area_table, _reflect, block_means
from .._jit import kernel

__all__ = ["Expansion", "region_expansion", "region_and_rim_expansion", "rim_scaled",
           "refined_expansion", "refine_grid", "scene_expansion", "moved_by_expansion",
           "rig_pixels", "rig_rows", "shrunk_mask", "shrink_step", "shrunk_size", "FIT_SIDE",
           "REFINE_SETTLED", "RIG_WEIGHT"]

_MIN_SIDE = 5  # pixels: a smaller box has too few gradients for four unknowns
FIT_SIDE = 64  # pixels: a larger box is area-averaged down to this before a fit (every fit's)
_RIDGE = 1e-6  # relative regularisation of the normal equations (no texture: C -> 0)
_NO_SKIP = np.zeros((0, 0), np.bool_)  # no pixel left out by a mask
_NO_SUMS = (0.0,) * 14  # a fit's sums before its first pixel (_add_pixel)
# pixels of the refinement's grid: a Gauss-Newton step that moves the box's edge by less is
# the last (refined_expansion)
REFINE_SETTLED = 0.05


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
    fit : float
        The share of the fitted pixels' temporal change, about its mean, that the motion
        explains (the fit's coefficient of determination, at most 1): near 1 where the box
        moves as one surface, low where it holds surfaces moving apart (a car and the verge
        sliding past each other, which least squares can read as expansion).
    """

    drift_x: float
    drift_y: float
    rate: float
    brightness: float
    fit: float


def region_expansion(previous: np.ndarray, current: np.ndarray,
                     box: tuple[int, int, int, int],
                     background: np.ndarray | None = None,
                     exclude: np.ndarray | None = None) -> Expansion | None:
    """Expansion and drift of a box of the image between two frames (Horn et al. [1]_).

    Solves ``E_x A + E_y B + g C - D = -E_t`` in the least-squares sense over the box, with
    ``g = (x - c_x) E_x + (y - c_y) E_y`` the radial gradient about the box centre. Spatial
    derivatives are Sobel derivatives of the mean of the two frames (centred in time), the
    temporal one their difference. A box larger than 64 pixels is area-averaged down to that
    first: fewer pixels to fit, and an edge that moves several pixels per frame stays within
    the linear range of the brightness-constancy equation (Horn, Fang and Masaki's hierarchical
    form does the same [2]_). The area averages are ``cv2.resize``'s (INTER_AREA), computed with
    the fit in one numba kernel, bit for bit (OpenCV's own where it shrinks by whole factors).

    With ``background``, the previous frame moved by the background's translation
    (:mod:`asnn.stabilisation`), a pixel whose change that translation explains better than
    no motion (``|current - background| < |current - previous|``) is left out of the fit: the
    box's background sliding past is not the object's own motion. With ``exclude``, the pixels
    it marks are left out too (the camera's own hood, dashboard or overlay: :func:`rig_pixels`);
    where the box is area-averaged, a pixel of the smaller box is left out when a quarter of
    its area is.

    Parameters
    ----------
    previous, current : ndarray (H, W)
        Luminance of two frames, float.
    box : (x0, y0, x1, y1)
        Pixels ``x0 <= x < x1``, ``y0 <= y < y1``.
    background : ndarray (H, W), optional
        ``previous`` moved by the background's translation.
    exclude : ndarray (H, W) of bool, optional
        Pixels to leave out.

    Returns
    -------
    Expansion or None
        None when the box is smaller than 5x5 pixels or holds no gradient to measure.

    References
    ----------
    .. [1] B. K. P. Horn, Y. Fang, I. Masaki, "Time to contact relative to a planar surface",
       IEEE Intelligent Vehicles Symposium, 2007, pp. 68-74.
    .. [2] B. K. P. Horn, Y. Fang, I. Masaki, "Hierarchical framework for direct gradient-based
       time-to-contact estimation", IEEE Intelligent Vehicles Symposium, 2009, pp. 1394-1400.
    """
    return region_and_rim_expansion(previous, current, box, None, background, exclude)[0]


def shrink_step(width: int, height: int, side: int = FIT_SIDE) -> float:
    """The pixels of a box that make one pixel of the box area-averaged before a fit, at most
    ``side`` on its larger side: 1 where it is no larger (:func:`shrunk_size`)."""
    return max(1.0, max(width, height) / side)


def shrunk_size(width: int, height: int, step: float) -> tuple[int, int]:
    """The (width, height) a box is area-averaged to at a :func:`shrink_step`, its shape
    kept."""
    return max(round(width / step), 1), max(round(height / step), 1)


def shrunk_mask(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A mask (bool) area-averaged to ``size`` (W, H): a shrunk pixel is in it where a quarter
    of its area is (a mask of pixels left out leaves out what they would sway).

    The average is ``cv2.resize``'s (INTER_AREA) of the mask as float32; where a C-contiguous
    mask shrinks by the same whole factor both ways (the whole frame to the surface watch's
    grid), its blocks' pixels are counted in a kernel instead (:func:`_over_a_quarter`), with
    the same outcome: a sum of zeros and ones is exact in any order."""
    h, w = mask.shape
    k = w // size[0]
    if k > 1 and (w, h) == (k * size[0], k * size[1]) and mask.flags.c_contiguous:
        out = np.empty((size[1], size[0]), np.bool_)
        _over_a_quarter(mask, k, np.float32(1) / np.float32(k * k), out)
        return out
    return cv2.resize(mask.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.25


@kernel()
def _over_a_quarter(mask, k, inverse, out):
    """Whether each ``k`` x ``k`` block of ``mask`` has more than a quarter of its pixels set,
    as :func:`shrunk_mask` decides it: the count times ``inverse`` (``1 / k^2`` in float32, as
    OpenCV scales its sums) above 0.25, in float32."""
    quarter = np.float32(0.25)
    for by in range(out.shape[0]):
        for bx in range(out.shape[1]):
            count = 0
            for y in range(k * by, k * by + k):
                row = mask[y]
                for x in range(k * bx, k * bx + k):
                    count += row[x]
            out[by, bx] = np.float32(count) * inverse > quarter


def _rim_sampled(rim: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``rim`` (bool) sampled at the centres of a grid of ``size`` (W, H) pixels."""
    return cv2.resize(rim.view(np.uint8), size, interpolation=cv2.INTER_NEAREST_EXACT).view(
        np.bool_)


def region_and_rim_expansion(previous: np.ndarray, current: np.ndarray,
                             box: tuple[int, int, int, int], rim: np.ndarray | None,
                             background: np.ndarray | None = None,
                             exclude: np.ndarray | None = None
                             ) -> tuple[Expansion | None, Expansion | None]:
    """:func:`region_expansion` of a box, and of the same box over its object's rim alone, in
    one pass over its pixels.

    The second fit leaves out, besides what the first leaves out, every pixel of the box that
    ``rim`` does not mark: it is ``region_expansion(previous, current, box, background, ~rim |
    exclude)`` bit for bit where the box is fitted at full resolution. Where it is
    area-averaged, a pixel of the smaller box counts for the rim where the pixel at its centre
    is ``rim`` (the rim is a smooth region, the attention's: its share of each pixel's area
    would cost the fit half its time again). :func:`rim_scaled` combines the two.

    Parameters
    ----------
    previous, current, box, background, exclude
        As for :func:`region_expansion`.
    rim : ndarray (H, W) of bool, or None
        The object's pixels (the model's attended mask ``M_a M_d``); None: the box's fit only.

    Returns
    -------
    (Expansion or None, Expansion or None)
        The box's fit and the rim's; each None as :func:`region_expansion` gives None (the
        rim's also without ``rim``).
    """
    return _fits(previous, current, box, rim, background, exclude)


def _fits(previous, current, box, rim, background, exclude, kept=None, averaged=()):
    """:func:`region_and_rim_expansion`; with ``kept``, a one-slot memo ``[frame, average]``
    of :func:`scene_expansion`, and with ``averaged``, ``(frame, average)`` pairs the caller
    has already (both used only where the box is a whole frame shrunk by whole factors:
    OpenCV's averages, which are the same whoever computes them)."""
    x0, y0, x1, y1 = box
    if x1 - x0 < _MIN_SIDE or y1 - y0 < _MIN_SIDE:
        return None, None
    # without a background every pixel counts: |after - before| < itself is never true
    reference = previous if background is None else background
    skip = _NO_SKIP if exclude is None or not exclude[y0:y1, x0:x1].any() else None
    step = shrink_step(x1 - x0, y1 - y0)
    if step == 1.0:
        if skip is None:
            skip = np.ascontiguousarray(exclude[y0:y1, x0:x1])
        # the rim's pixels: also kept by the box (the kernel asks both)
        keep = _NO_SKIP if rim is None else np.ascontiguousarray(rim[y0:y1, x0:x1])
        # contiguous, as the resized boxes are: one compiled kernel for both (the views'
        # own took numba 3 s more to compile), for a copy of at most 64x64 pixels each
        fits = _solve_expansion(*(np.ascontiguousarray(image[y0:y1, x0:x1])
                                  for image in (previous, current, reference)),
                                skip, keep, _RIDGE)
    else:
        size = shrunk_size(x1 - x0, y1 - y0, step)
        if skip is None:
            skip = shrunk_mask(exclude[y0:y1, x0:x1], size)
        keep = _NO_SKIP if rim is None else _rim_sampled(rim[y0:y1, x0:x1], size)
        if _area_fast((x1 - x0, y1 - y0), size):
            # OpenCV reads the box's rows where they are: no copy of the box
            known = ()
            if (x0, y0, x1, y1) == (0, 0, current.shape[1], current.shape[0]):
                known = (averaged if kept is None or kept[0] is None
                         else ((kept[0], kept[1]),) + tuple(averaged))
            before, after, reference = (_known_average(image, image[y0:y1, x0:x1], known, size)
                                        for image in (previous, current, reference))
            if kept is not None:
                kept[:] = current, after
            fits = _solve_expansion(before, after, reference, skip, keep, _RIDGE)
        else:
            fits = _solve_area_averaged(previous, current, reference, x0, y0, x1, y1, *size,
                                        skip, keep, _RIDGE)
    solved, a, b, c, d, fit, rim_solved, ra, rb, rc, rd, rim_fit = fits
    return (Expansion(a * step, b * step, c, d, fit) if solved else None,
            Expansion(ra * step, rb * step, rc, rd, rim_fit) if rim_solved else None)


def _known_average(image: np.ndarray, part: np.ndarray, known,
                   size: tuple[int, int]) -> np.ndarray:
    """``part`` of ``image`` area-averaged to ``size`` (W, H) by whole factors
    (``cv2.resize``, INTER_AREA); where ``part`` is the whole frame, taken from ``known``,
    ``(frame, average)`` pairs of whole frames, if it holds that very frame averaged to that
    size: the same numbers, without averaging the frame again (a 320 x 240 frame to 64 x 48
    takes OpenCV about 18 us, its slowest path)."""
    for frame, average in known:
        if frame is image and average.shape == (size[1], size[0]):
            return average
    return block_means(part, size)  # cv2.resize's INTER_AREA


def rim_scaled(box: Expansion | None, rim: Expansion | None, side: int = 0,
               motion_max: float | None = None) -> Expansion | None:
    """A box's expansion scaled up to the rate its object's rim alone reads.

    Where the background slides (a translation the stabilisation takes out), a box fitted by
    :func:`region_expansion` holds the pattern sliding past its object besides the object. The
    pattern's pixels that the translation explains are left out, but those it cannot (where
    the object's outline occludes the pattern) stay in, and they read as a surface that does
    not expand: the box's rate comes out short (0.4-0.5 of the object's over the suite's
    patterns drawn at 320x240, sliding 4 px a frame). Its drift is diluted alike, so the ratio of drift to
    expansion, the path's offset, stays. Fitted over the object's attended pixels alone (its
    rim, where the approach map sees it), the rate is not diluted. Where the rim reads the
    faster expansion, this takes the rim's rate and scales the box's drift by as much: the
    time to contact the rim's, the offset the box's. It never lengthens a time to contact, and
    it never turns a box that does not expand into one that does.

    With ``motion_max``, the rim's rate counts only where the motion it implies at the box's
    edge, ``rate * min(side, 64) / 2`` pixels of the fit's grid a frame, is at most
    ``motion_max``. The fit solves the brightness-constancy equation to first order, which
    holds for small image motions only [1]_; a rim of a few hundred pixels on a prop that a
    hand-held camera sways past, seen 10 times a second, read an expansion of 0.76 a frame
    (13 px at its edge) where its box read 0.26, and warned.

    Parameters
    ----------
    box : Expansion or None
        The box's fit.
    rim : Expansion or None
        The fit of the same box over the object's attended pixels only.
    side : int, optional
        The box's larger side, pixels (with ``motion_max``).
    motion_max : float, optional
        The largest motion at the box's edge, pixels of the fit's grid a frame, at which the
        rim's rate counts; None: at any.

    Returns
    -------
    Expansion or None
        ``box`` with ``rate`` and ``drift_x``, ``drift_y`` scaled by ``rim.rate / box.rate``
        where ``rim.rate > box.rate > 0`` (and the rim's motion is within ``motion_max``);
        ``box`` itself otherwise (its brightness and fit as they are).

    References
    ----------
    .. [1] B. K. P. Horn, B. G. Schunck, "Determining optical flow", Artificial Intelligence 17,
       1981, pp. 185-203 (the constraint equation from the first-order expansion of the
       brightness, valid while the motion is small against the image's smoothness).
    """
    if box is None or rim is None or not rim.rate > box.rate > 0.0:
        return box
    if motion_max is not None and rim.rate * min(side, FIT_SIDE) / 2 > motion_max:
        return box
    k = rim.rate / box.rate
    return Expansion(box.drift_x * k, box.drift_y * k, rim.rate, box.brightness, box.fit)


# the camera's rig: running means of each frame and of each pixel's frame-to-frame change with
# this weight per frame (about a second at 20 frames/s)
RIG_WEIGHT = 0.05
_RIG_FRAMES = 20  # one time constant of the running means: before it they hold the first frames
_RIG_SPEED = 0.2  # pixels a frame: the speed below which an edge is still
_RIG_EDGE = 0.01  # gray level a pixel ([0, 1] scale): a weaker edge tells nothing
_RIG_BAND = 0.25  # of the height: the rig is looked for in this band at the top and bottom


def rig_pixels(change: np.ndarray, mean: np.ndarray, frames: int) -> np.ndarray | None:
    """The edges of the camera's own rig: its hood or dashboard, a recorder's overlay, the
    same in every frame, which the looming fits leave out (:func:`region_expansion`'s
    ``exclude``).

    An edge of the running mean image is still when the running mean of its pixels' change is
    below what a speed of 0.2 pixels a frame would make (the change of an edge moving ``v``
    pixels a frame is about ``v`` times its gradient: brightness constancy). The rig's edges
    move with the camera, so never; the scene's move with every motion of the camera or of
    the scene, and a uniform surface (no edge) is never marked. Only the top and bottom
    quarters of the frame are searched: that is where a camera's rig is seen, while the
    scenery at the horizon ahead or to the sides, nearly still under forward motion (the focus
    of expansion and the far distance), is not rig. Where the camera stands still, its still
    background there is marked too: background, not part of an approaching object.

    Parameters
    ----------
    change : ndarray (h, w)
        Running mean of ``|current - previous|`` (weight :data:`RIG_WEIGHT` per frame).
    mean : ndarray (h, w)
        Running mean of the frames (the same weight).
    frames : int
        Frames averaged; fewer than 20 mark nothing.

    Returns
    -------
    ndarray (h, w) of bool, or None where nothing is marked.
    """
    if frames < _RIG_FRAMES:
        return None
    band = _rig_band(mean.shape[0])
    if band < 1:
        return None
    mean = np.ascontiguousarray(mean, np.float32)
    rig = np.zeros(mean.shape, np.bool_)  # the middle of the frame is never marked
    return rig if _mark_still_edges(change, mean, band, rig) else None


def rig_rows(h: int) -> tuple[slice, ...]:
    """The rows of an ``h``-row grid that :func:`rig_pixels` reads: its top and bottom bands,
    each with the row beyond it that the edge filter reaches (none where the bands are empty;
    the two never overlap)."""
    band = _rig_band(h)
    if band < 1:
        return ()
    return slice(0, band + 1), slice(h - band - 1, h)


def _rig_band(h: int) -> int:
    """Rows of each of the bands at the top and bottom of an ``h``-row grid where the rig is
    looked for."""
    return int(_RIG_BAND * h)


@kernel()
def _mark_still_edges(change, mean, band, rig):
    """:func:`rig_pixels`' test on the ``band`` rows at the top and at the bottom, into
    ``rig``; whether it marked any.

    The edge is OpenCV's 3x3 Sobel pair on ``mean`` (float32) with its reflect-101 border, bit
    for bit: each separable pass sums its outer taps first, as ``cv2.Sobel`` does; the
    thresholds are float32 too, as NumPy compares a float32 array with a Python float.
    """
    h, w = mean.shape
    marked = False
    for i in range(2 * band):
        y = i if i < band else h - 2 * band + i
        up, here, down = mean[_reflect(y - 1, h)], mean[y], mean[_reflect(y + 1, h)]
        still, rig_y = change[y], rig[y]
        # the columns at the border apart: the loop over the others has no branch to vectorise
        for x in (0, w - 1):
            marked |= _still_edge(up, here, down, still, rig_y, _reflect(x - 1, w), x,
                                  _reflect(x + 1, w))
        for x in range(1, w - 1):
            marked |= _still_edge(up, here, down, still, rig_y, x - 1, x, x + 1)
    return marked


@kernel(inline="always")
def _still_edge(up, here, down, still, rig, left, x, right):
    """One pixel of :func:`_mark_still_edges`."""
    two, eighth = np.float32(2.0), np.float32(0.125)
    ex = ((up[right] - up[left]) + (down[right] - down[left])) + two * (here[right] - here[left])
    ey = ((down[left] + down[right]) + two * down[x]) - ((up[left] + up[right]) + two * up[x])
    edge = eighth * (abs(ex) + abs(ey))
    marked = (edge > np.float32(_RIG_EDGE)) & (still[x] < np.float32(_RIG_SPEED) * edge)
    rig[x] = marked
    return marked


def scene_expansion(previous: np.ndarray, current: np.ndarray,
                    boxes: list[tuple[int, int, int, int]],
                    background: np.ndarray | None = None,
                    exclude: np.ndarray | None = None, kept: list | None = None,
                    averaged: tuple = ()) -> Expansion | None:
    """Expansion and drift of the scene around the objects: the fit of :func:`region_expansion`
    over the whole frame, leaving out ``boxes``.

    Under the camera's own forward motion the static scene expands about the heading; one
    expansion about the frame's centre is the simplest account of it (depth varies, so it is an
    average). The boxes of the tracked objects are left out, so that an object does not count
    as scene, and, with ``background``, so are the pixels the background's translation explains
    (as in :func:`region_expansion`). A pixel is left out by giving it the current frame as its
    background: the fit leaves out a pixel its background explains better than no motion.

    Parameters
    ----------
    previous, current : ndarray (H, W)
        Luminance of two frames, float.
    boxes : list of (x0, y0, x1, y1)
        Integer pixel boxes to leave out, within the frame.
    background : ndarray (H, W), optional
        ``previous`` moved by the background's translation.
    exclude : ndarray (H, W) of bool, optional
        Pixels to leave out as well (:func:`region_expansion`).
    kept : list, optional
        A stream's memo of its last scene fit, ``[current, its area average]`` (start with
        ``[None, None]``), where the frame is shrunk by whole factors: the next frame's fit
        takes that average as its previous frame's instead of averaging the frame again (the
        frames must not change in between).
    averaged : tuple of (ndarray, ndarray), optional
        ``(frame, its area average)`` pairs the caller has already (the surface watch's shrunk
        frames: :meth:`asnn.approach.surface.SurfaceWatch.averages`): a frame found there
        (the same object, averaged to the fit's size) is not averaged again.

    Returns
    -------
    Expansion or None
        About the frame's centre; None as :func:`region_expansion`.

    References
    ----------
    .. [1] B. P. Ölveczky, S. A. Baccus, M. Meister, "Segregation of object and background
       motion in the retina", Nature 423, 2003, pp. 401-408 (object-motion-sensitive cells:
       an object's motion against the global motion, which :class:`asnn.model.ASNN`'s
       scene-relative test uses).
    """
    h, w = current.shape
    reference = (previous if background is None else background).copy()
    for x0, y0, x1, y1 in boxes:
        reference[y0:y1, x0:x1] = current[y0:y1, x0:x1]
    return _fits(previous, current, (0, 0, w, h), None, reference, exclude, kept, averaged)[0]


def moved_by_expansion(previous: np.ndarray, scene: Expansion,
                       box: tuple[int, int, int, int]) -> np.ndarray:
    """The box of the previous frame as the scene's expansion moves it into the current one.

    The scene's image motion ``p -> c + A + (1 + C)(p - c)`` about the frame's centre ``c``
    (:func:`scene_expansion`), inverted and sampled bilinearly (edges replicated) at the box's
    pixels: what each pixel of the box would show now if it were scenery.

    Parameters
    ----------
    previous : ndarray (H, W)
    scene : Expansion
        Per frame, about the frame's centre.
    box : (x0, y0, x1, y1)

    Returns
    -------
    ndarray (y1 - y0, x1 - x0), the dtype of ``previous`` (empty for an empty box: a track's
    box clipped to the frame has none when the track has moved out of it)
    """
    h, w = previous.shape
    x0, y0, x1, y1 = box
    if x1 <= x0 or y1 <= y0:  # OpenCV would read an empty size as the source's
        return np.empty((max(y1 - y0, 0), max(x1 - x0, 0)), previous.dtype)
    s = 1.0 + scene.rate
    cx, cy = 0.5 * (w - 1), 0.5 * (h - 1)
    inverse = np.array([[1.0 / s, 0.0, cx + (x0 - cx - scene.drift_x) / s],
                        [0.0, 1.0 / s, cy + (y0 - cy - scene.drift_y) / s]])
    return cv2.warpAffine(previous, inverse, (x1 - x0, y1 - y0),
                          flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)


def refined_expansion(previous: np.ndarray, current: np.ndarray,
                      box: tuple[int, int, int, int], estimate: Expansion,
                      guess: Expansion | None = None, background: np.ndarray | None = None,
                      exclude: np.ndarray | None = None, iterations: int = 2,
                      bound: float = 2.0, settled: float = REFINE_SETTLED) -> Expansion:
    """A box's expansion and drift refined past the gradient fit's small-motion range.

    :func:`region_expansion` solves the brightness-constancy equation to first order, so it
    reads an image motion of more than a pixel or two at its grid's edge short (it saturates:
    the last frames before contact) and, about the mean of the two frames, a growth ``s - 1``
    as ``2 (s - 1) / (s + 1)``. Here the previous frame is moved by the motion found so far
    (scaled by ``1 + rate`` about the box centre and shifted by the drift, bilinearly, edges
    replicated) and what is left between it and the current frame is fitted again (as
    :func:`region_expansion` fits) and composed with it: Gauss-Newton steps on the warp, as
    Horn, Fang and Masaki's iterative form [1]_. It converges on the scale that maps the
    previous frame's box onto the current one, ``1 + rate``, so ``1 / rate`` frames is the time
    to contact at the current frame.

    The steps run on the box's grid of :func:`refine_grid`: a box larger than 64 pixels is
    area-averaged by a whole factor once, the current frame's box and the previous frame's
    about it (the margin the warp reads), and the warps and fits are made on those small images
    (the previous frame's average warped rather than the warped frame averaged, bilinearly on
    a grid of 32-64 pixels: on the generated approaches the same scale in the median, within a
    few tenths of a percent, a little more spread: design notes, "The steps on the shrunk grid,
    adopted"). A step that moves the box's edge by less than ``settled`` pixels of that grid is
    the last.

    The model uses it only for the time to contact it reports (``refined_ttc``; the approach
    test reads the first fit, on which its limits were set): a reported target whose motion
    moves its box's edge by more than a pixel a frame at the fit's grid.

    Parameters
    ----------
    previous, current : ndarray (H, W)
        Luminance of two frames, float.
    box : (x0, y0, x1, y1)
        Pixels ``x0 <= x < x1``, ``y0 <= y < y1``.
    estimate : Expansion
        The box's fit (:func:`region_expansion`).
    guess : Expansion, optional
        Where to start instead of ``estimate`` (a prediction from the frames before: a fit
        that saturated can be too far from the answer for a few steps to reach it).
    background : ndarray (H, W), optional
        ``previous`` moved by the background's translation: a pixel it explains better than
        the warp is left out (:func:`region_expansion`'s rule, the warp as its previous frame).
    exclude : ndarray (H, W) of bool, optional
        Pixels to leave out (:func:`region_expansion`).
    iterations : int
        Gauss-Newton steps, at most.
    bound : float
        The refined rate is kept within the range ``estimate`` and ``guess`` span, widened by
        the factor ``bound`` (beyond it, the start's motion scaled to the nearer limit): where
        the box holds too little of the object's outline to fix its motion (the corner of an
        object larger than it), the steps can wander.
    settled : float
        Pixels of the grid: a step whose correction moves the box's edge by less is the last.

    Returns
    -------
    Expansion
        Per frame interval about the box centre, ``brightness`` and ``fit`` the estimate's;
        ``estimate`` itself where the box is smaller than 5x5 pixels or the start does not
        expand.

    References
    ----------
    .. [1] B. K. P. Horn, Y. Fang, I. Masaki, "Hierarchical framework for direct gradient-based
       time-to-contact estimation", IEEE Intelligent Vehicles Symposium, 2009, pp. 1394-1400.
    """
    x0, y0, x1, y1 = box
    start = estimate if guess is None else guess
    if x1 - x0 < _MIN_SIDE or y1 - y0 < _MIN_SIDE or not start.rate > 0.0:
        return estimate
    factor, (gx0, gy0, gx1, gy1) = refine_grid(box)
    width, height = (gx1 - gx0) // factor, (gy1 - gy0) // factor  # the grid's pixels
    # the grid's box centre less the box's: the drift about one from the drift about the other
    off_x, off_y = 0.5 * (gx0 + gx1 - x0 - x1), 0.5 * (gy0 + gy1 - y0 - y1)
    scale = 1.0 + start.rate
    # drift of the grid's centre, pixels of the grid: p = c + A + scale (q - c) about either
    ax = (start.drift_x + start.rate * off_x) / factor
    ay = (start.drift_y + start.rate * off_y) / factor
    # the previous frame's box with the margin the start's warp reads, and two grid pixels
    # more, in whole grid pixels within the frame
    frame_h, frame_w = previous.shape
    mx, my = math.ceil(abs(ax)) + 2, math.ceil(abs(ay)) + 2
    left, top = min(mx, gx0 // factor), min(my, gy0 // factor)
    right, bottom = min(mx, (frame_w - gx1) // factor), min(my, (frame_h - gy1) // factor)
    before = _grid_average(previous, gx0 - left * factor, gy0 - top * factor,
                           gx1 + right * factor, gy1 + bottom * factor, factor)
    now = _grid_average(current, gx0, gy0, gx1, gy1, factor)
    slid = (np.zeros((0, 0), now.dtype) if background is None  # none: every pixel counts
            else _grid_average(background, gx0, gy0, gx1, gy1, factor))
    skip = _NO_SKIP
    if exclude is not None and exclude[gy0:gy1, gx0:gx1].any():
        skip = (np.ascontiguousarray(exclude[gy0:gy1, gx0:gx1]) if factor == 1
                else shrunk_mask(exclude[gy0:gy1, gx0:gx1], (width, height)))
    scale, ax, ay = _warped_steps(before, now, slid, skip, left, top, scale, ax, ay,
                                  iterations, settled, _RIDGE)
    rate = scale - 1.0
    low, high = min(estimate.rate, start.rate), max(estimate.rate, start.rate) * bound
    low = low / bound if low > 0.0 else low * bound
    if not low <= rate <= high:  # the start's motion scaled to the bound
        k = min(max(rate, low), high) / start.rate
        return Expansion(start.drift_x * k, start.drift_y * k, start.rate * k,
                         estimate.brightness, estimate.fit)
    return Expansion(ax * factor - rate * off_x, ay * factor - rate * off_y, rate,
                     estimate.brightness, estimate.fit)


def refine_grid(box: tuple[int, int, int, int]) -> tuple[int, tuple[int, int, int, int]]:
    """The grid :func:`refined_expansion` steps on: the whole factor a box is area-averaged by,
    the smallest that brings it to at most 64 pixels a side (:data:`FIT_SIDE`; 1 where it is no
    larger), and the box trimmed about its centre to whole multiples of it (at most
    ``factor - 1`` pixels less a side). A whole factor is OpenCV's fast area average, a tenth
    of the time of a fractional one."""
    x0, y0, x1, y1 = box
    # at most the factor that leaves _MIN_SIDE grid pixels on the shorter side (a box clipped by
    # the frame's edge to a few rows of a long side: a larger factor left it 0 or 1 rows)
    factor = max(1, min(math.ceil(shrink_step(x1 - x0, y1 - y0)),
                        min(x1 - x0, y1 - y0) // _MIN_SIDE))
    trim_x, trim_y = (x1 - x0) % factor, (y1 - y0) % factor
    x0, y0 = x0 + trim_x // 2, y0 + trim_y // 2
    return factor, (x0, y0, x1 - trim_x + trim_x // 2, y1 - trim_y + trim_y // 2)


def _grid_average(image: np.ndarray, x0: int, y0: int, x1: int, y1: int,
                  factor: int) -> np.ndarray:
    """The box of ``image`` area-averaged by the whole ``factor`` its sides are multiples of
    (``cv2.resize``, INTER_AREA), or copied where it is 1: contiguous either way."""
    part = image[y0:y1, x0:x1]
    if factor == 1:
        return np.ascontiguousarray(part)
    return cv2.resize(part, ((x1 - x0) // factor, (y1 - y0) // factor),
                      interpolation=cv2.INTER_AREA)


@kernel(error_model="numpy")
def _warped_steps(before, now, slid, skip, left, top, scale, drift_x, drift_y, iterations,
                  settled, ridge):
    """The Gauss-Newton steps of :func:`refined_expansion` on its grid: ``(scale, drift_x,
    drift_y)`` after them, the drift in pixels of the grid about its centre.

    Each step samples ``before`` (the previous frame's grid, ``left`` and ``top`` pixels
    larger than ``now``'s on those sides) at ``q = c + (p - c - A) / scale`` for each pixel
    ``p`` of ``now`` (bilinearly, edges replicated: ``cv2.warpAffine``'s, in float64 rather than
    its 1/32 pixel steps), fits what is left between the two as :func:`_solve_expansion` does
    (``slid``, the background's translation on ``now``'s grid, or empty: none; ``skip`` as
    there) and composes it with the motion so far. It stops early where the box is not fitted,
    where the scale falls below a tenth, or where a step moves the box's edge by less than
    ``settled`` pixels; ``iterations`` at most.
    """
    h, w = now.shape
    moved = np.empty_like(now)
    reference = slid if slid.size > 0 else moved  # without a background every pixel counts
    keep = np.zeros((0, 0), np.bool_)  # no second fit
    cx, cy = 0.5 * (w - 1), 0.5 * (h - 1)
    edge = 0.5 * max(w, h)
    columns, rows = np.empty((2, w), np.int64), np.empty((2, h), np.int64)
    column_weights, row_weights = np.empty(w), np.empty(h)
    for _ in range(iterations):
        inverse = 1.0 / scale
        _linear_taps(inverse, left + cx - (cx + drift_x) * inverse, before.shape[1], columns,
                     column_weights)
        _linear_taps(inverse, top + cy - (cy + drift_y) * inverse, before.shape[0], rows,
                     row_weights)
        for y in range(h):
            upper, lower, fy = before[rows[0, y]], before[rows[1, y]], row_weights[y]
            for x in range(w):
                x0, x1, fx = columns[0, x], columns[1, x], column_weights[x]
                top_value = upper[x0] + fx * (upper[x1] - upper[x0])
                bottom_value = lower[x0] + fx * (lower[x1] - lower[x0])
                moved[y, x] = top_value + fy * (bottom_value - top_value)
        fits = _solve_expansion(moved, now, reference, skip, keep, ridge)
        if not fits[0]:
            break
        a, b, c = fits[1], fits[2], fits[3]
        # the rest's motion about the same centre, after the motion so far
        drift_x, drift_y = a + (1.0 + c) * drift_x, b + (1.0 + c) * drift_y
        scale *= 1.0 + c
        if not scale > 0.1:  # shrunk to a tenth: no warp to sample (the caller's bound holds it)
            break
        if abs(c) * edge < settled:
            break
    return scale, drift_x, drift_y


@kernel(inline="always")
def _linear_taps(step, origin, size, taps, weights):
    """Bilinear sampling along one axis at ``origin + step * i`` for each ``i`` of ``taps``'
    columns, from a line of ``size`` pixels with its edges replicated: the two pixels read
    (``taps[0]``, ``taps[1]``) and the second's weight."""
    for i in range(taps.shape[1]):
        at = origin + step * i
        first = int(np.floor(at))
        weights[i] = at - first
        taps[0, i] = min(max(first, 0), size - 1)
        taps[1, i] = min(max(first + 1, 0), size - 1)


@kernel(error_model="numpy")
def _solve_expansion(before, after, background, skip, keep, ridge):
    """``(solved, A, B, C, D, fit)`` of :func:`region_expansion` over two equal images,
    leaving out the pixels where ``after`` is nearer ``background`` than ``before``, and those
    ``skip`` marks (an array of the images' shape, or empty: none); followed by the same six
    of the fit over those of its pixels ``keep`` marks (an array of the images' shape; empty:
    no second fit, ``solved`` False).

    One pass over the rows: the Sobel derivatives of the mean (OpenCV's 3x3 kernels, scaled
    by 1/8, reflect-101 border) and the temporal difference, in the images' precision as the
    NumPy expressions would compute them; the normal equations accumulated in float64 (the
    second fit's over its pixels in the same order, so it is what a fit of those pixels alone
    gives, bit for bit), in local sums (:func:`_add_pixel`) rather than in an array, where
    each addition waited on the store of the one before; then solved by :func:`_solve_normal`.
    Each row's derivatives are computed first, for all its pixels (:func:`_row_gradients`, a
    loop the compiler vectorises), and the sums then read them: the sums' additions, one
    after the other in the pixels' order, are what takes the time.
    """
    h, w = before.shape
    mean = np.empty((h, w), np.float64)  # exact: the float32 mean, widened
    half = before.dtype.type(0.5)
    for y in range(h):
        for x in range(w):
            mean[y, x] = half * (before[y, x] + after[y, x])
    box = rim = _NO_SUMS  # each fit's sums (_add_pixel): the box's, and its rim's
    box_count = rim_count = 0  # and their pixels
    masked = skip.size > 0
    second = keep.size > 0
    ex, ey, radial = np.empty(w), np.empty(w), np.empty(w)
    for y in range(h):
        _row_gradients(mean, y, ex, ey, radial)
        for x in range(w):
            if masked and skip[y, x]:
                continue  # left out by the caller (the camera's own rig)
            et = np.float64(after[y, x] - before[y, x])
            if abs(after[y, x] - background[y, x]) < abs(et):
                continue  # the background's translation explains this pixel
            box = _add_pixel(box, ex[x], ey[x], radial[x], et)
            box_count += 1
            if second and keep[y, x]:
                rim = _add_pixel(rim, ex[x], ey[x], radial[x], et)
                rim_count += 1
    normal = np.zeros((2, 4, 5))  # [N | rhs] of each fit, the upper triangle
    sums = np.zeros((2, 3))  # count, sum and sum of squares of each fit's E_t
    _store_sums(box, box_count, normal[0], sums[0])
    _store_sums(rim, rim_count, normal[1], sums[1])
    first = _solve_normal(normal[0], sums[0], ridge)
    if not second:
        return first + (False, 0.0, 0.0, 0.0, 0.0, 0.0)
    return first + _solve_normal(normal[1], sums[1], ridge)


@kernel()
def _row_gradients(mean, y, ex, ey, radial):
    """Row ``y``'s Sobel derivatives of ``mean`` and its radial gradient about the image's
    centre (:func:`_solve_expansion`), into ``ex``, ``ey`` and ``radial``: the inner columns
    without the border's reflection (a loop without branches), then the two edge columns. A
    function of its own, not inlined: inlined into the fit's loop, its loop was not vectorised
    (the fit of 64 x 48 pixels took 14 us instead of 10)."""
    h, w = mean.shape
    up, here, down = mean[_reflect(y - 1, h)], mean[y], mean[_reflect(y + 1, h)]
    cx, ry = 0.5 * (w - 1), y - 0.5 * (h - 1)
    for x in range(1, w - 1):
        _gradient(up, here, down, x - 1, x, x + 1, cx, ry, ex, ey, radial)
    for x in (0, w - 1):
        _gradient(up, here, down, _reflect(x - 1, w), x, _reflect(x + 1, w), cx, ry, ex, ey,
                  radial)


@kernel(inline="always")
def _gradient(up, here, down, left, x, right, cx, ry, ex, ey, radial):
    """One pixel of :func:`_row_gradients`: sums of a few float32 values in float64, exact, as
    OpenCV's float64 Sobel."""
    gx = ((up[right] - up[left]) + 2.0 * (here[right] - here[left])
          + (down[right] - down[left])) / 8.0
    gy = ((down[left] - up[left]) + 2.0 * (down[x] - up[x])
          + (down[right] - up[right])) / 8.0
    ex[x], ey[x] = gx, gy
    radial[x] = (x - cx) * gx + ry * gy


@kernel(inline="always")
def _add_pixel(sums, ex, ey, radial, et):
    """A fit's sums with one more pixel: the sum and sum of squares of ``E_t``, the upper
    triangle of ``N = X'X`` row by row and the right-hand side ``-X'E_t``, for the pixel's
    basis ``(E_x, E_y, g, -1)`` (:func:`_solve_expansion`), but for the two that the pixels'
    count and the sum of ``E_t`` are (``N[3, 3]`` sums ``(-1)^2``, ``rhs[3]`` sums ``E_t``, from
    0 in the same order: bit for bit; :func:`_store_sums` fills them in). The basis' ``-1``
    terms are subtractions: ``a + x * -1`` is ``a - x`` exactly. Fewer sums than registers
    the processor has for them: the sums are additions that each wait on the one before, and
    17 of them, one of which counted, left some in memory between pixels."""
    (total, squares, n00, n01, n02, n03, n11, n12, n13, n22, n23, r0, r1, r2) = sums
    return (total + et, squares + et * et,
            n00 + ex * ex, n01 + ex * ey, n02 + ex * radial, n03 - ex,
            n11 + ey * ey, n12 + ey * radial, n13 - ey,
            n22 + radial * radial, n23 - radial,
            r0 - ex * et, r1 - ey * et, r2 - radial * et)


@kernel(inline="always")
def _store_sums(sums, count, normal, moments):
    """A fit's sums (:func:`_add_pixel`) over ``count`` pixels into ``normal`` (4x5, the upper
    triangle and the right-hand side) and ``moments`` (count, sum and sum of squares of
    E_t)."""
    (total, squares, n00, n01, n02, n03, n11, n12, n13, n22, n23, r0, r1, r2) = sums
    moments[0], moments[1], moments[2] = float(count), total, squares
    normal[0, 0], normal[0, 1], normal[0, 2], normal[0, 3], normal[0, 4] = n00, n01, n02, n03, r0
    normal[1, 1], normal[1, 2], normal[1, 3], normal[1, 4] = n11, n12, n13, r1
    normal[2, 2], normal[2, 3], normal[2, 4] = n22, n23, r2
    normal[3, 3], normal[3, 4] = float(count), total


@kernel(error_model="numpy", inline="always")
def _solve_normal(normal, sums, ridge):
    """``(solved, A, B, C, D, fit)`` from the accumulated normal equations ``normal`` (4x5,
    upper triangle) and ``sums`` (count, sum and sum of squares of E_t): Gaussian elimination
    with partial pivoting. ``solved`` is False without a gradient to measure. ``fit`` is
    ``1 - RSS / TSS``: the residual sum of squares of the solution over the fitted pixels
    (from the unregularised normal equations), against the sum of squares of ``-E_t`` about
    its mean (0 where that is 0)."""
    count, total, squares = sums[0], sums[1], sums[2]
    for i in range(4):
        for j in range(i):
            normal[i, j] = normal[j, i]
    scale = normal[0, 0] + normal[1, 1] + normal[2, 2]
    if not scale > 0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0
    gram = normal.copy()  # unregularised, for the residual
    # the gradient terms are regularised relative to their own size (no texture: C -> 0);
    # the brightness term is well posed by the pixel count
    for i in range(3):
        normal[i, i] += ridge * scale
    for k in range(4):
        pivot = k
        for i in range(k + 1, 4):
            if abs(normal[i, k]) > abs(normal[pivot, k]):
                pivot = i
        if not normal[pivot, k] != 0.0:
            return False, 0.0, 0.0, 0.0, 0.0, 0.0
        for j in range(5):
            normal[k, j], normal[pivot, j] = normal[pivot, j], normal[k, j]
        for i in range(k + 1, 4):
            factor = normal[i, k] / normal[k, k]
            for j in range(k, 5):
                normal[i, j] -= factor * normal[k, j]
    solution = np.zeros(4)
    for i in range(3, -1, -1):
        acc = normal[i, 4]
        for j in range(i + 1, 4):
            acc -= normal[i, j] * solution[j]
        solution[i] = acc / normal[i, i]
    # RSS = y'y - 2 s'X'y + s'X'X s, with y = -E_t; TSS about y's mean
    rss = squares
    for i in range(4):
        rss -= 2.0 * solution[i] * gram[i, 4]
        for j in range(4):
            rss += solution[i] * gram[i, j] * solution[j]
    tss = squares - total * total / count
    fit = 1.0 - max(rss, 0.0) / tss if tss > 0 else 0.0
    return True, solution[0], solution[1], solution[2], solution[3], fit


@kernel(inline="always")
def _area_averages(images, y0, x0, xtab, ytab, rows, out):
    """``cv2.resize(image[y0:, x0:], ..., interpolation=cv2.INTER_AREA)`` of three images into
    ``out`` with the tables of :func:`_area_table`, summed in OpenCV's order and the images'
    precision (its ``ResizeArea_Invoker`` on one thread), so bit for bit the same.

    ``rows`` holds the horizontal sums of every source row. Each of them is one chain of
    additions from 0, as OpenCV's into its row buffer, but the chains of two source rows of
    the three images are computed side by side: six independent chains, which the processor
    overlaps (with one row's three, each addition waited on the one before it).
    """
    xs, xw, xstart = xtab
    ys, yw, ystart = ytab
    a, b, c = images
    h, w = out.shape[1:]
    zero = rows.dtype.type(0)
    n = rows.shape[1]
    for sy in range(0, n, 2):
        ty = min(sy + 1, n - 1)  # the pair's second row (the last row twice where n is odd)
        ra, rb, rc = a[y0 + sy], b[y0 + sy], c[y0 + sy]
        qa, qb, qc = a[y0 + ty], b[y0 + ty], c[y0 + ty]
        la, lb, lc = rows[0, sy], rows[1, sy], rows[2, sy]
        ma, mb, mc = rows[0, ty], rows[1, ty], rows[2, ty]
        for dx in range(w):
            sa = sb = sc = ta = tb = tc = zero
            for k in range(xstart[dx], xstart[dx + 1]):
                x, wt = x0 + xs[k], xw[k]
                sa += ra[x] * wt
                sb += rb[x] * wt
                sc += rc[x] * wt
                ta += qa[x] * wt
                tb += qb[x] * wt
                tc += qc[x] * wt
            la[dx], lb[dx], lc[dx] = sa, sb, sc
            ma[dx], mb[dx], mc[dx] = ta, tb, tc
    for i in range(3):
        for dy in range(h):
            o = out[i, dy]
            j = ystart[dy]
            line, beta = rows[i, ys[j]], yw[j]
            if dy == 0:  # OpenCV's first sum starts from 0, the others from their first term
                for dx in range(w):
                    o[dx] = zero + beta * line[dx]
            else:
                for dx in range(w):
                    o[dx] = beta * line[dx]
            for j in range(ystart[dy] + 1, ystart[dy + 1]):
                line, beta = rows[i, ys[j]], yw[j]
                for dx in range(w):
                    o[dx] += beta * line[dx]


@kernel(error_model="numpy")
def _solve_area_averaged(previous, current, background, x0, y0, x1, y1, w, h, skip, keep,
                         ridge):
    """:func:`_solve_expansion` over the box ``(x0, y0, x1, y1)`` of the three images
    area-averaged down to ``w`` x ``h`` as ``cv2.resize`` does (:func:`_area_averages`),
    in one call, the tables made once; ``skip`` and ``keep`` at the smaller size."""
    rows = np.empty((3, y1 - y0, w), previous.dtype)
    out = np.empty((3, h, w), previous.dtype)
    _area_averages((previous, current, background), y0, x0, _area_table(x1 - x0, w),
                   _area_table(y1 - y0, h), rows, out)
    return _solve_expansion(out[0], out[1], out[2], skip, keep, ridge)
