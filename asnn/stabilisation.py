"""Background stabilisation: the frame-to-frame translation of the whole scene, taken out.

When the camera pans or shakes, or a textured background slides past (a train, a fence, moving
stripes), every edge of the scene moves, and the retina's motion and approach maps fill with it;
the direction-selective inhibition (paper eqs. 24-26) then removes the background's direction
everywhere, and with it an approaching object's rims wherever the two overlap. Retinas face the
same problem with their own eye movements: object-motion-sensitive ganglion cells respond to
local motion only where it differs from the motion of the surround, which the eye's global
shifts move as a whole [1]_, and the eye's own movements are compensated so that the world
holds still [2]_.

This stage does the same at the photoreceptors. :func:`background_shift` finds the whole-pixel
translation, within a few pixels (searched again farther where the best lies at the search's
edge: a shaken camera's jolts), that best maps the previous frame onto the current one, and
accepts it only when it explains most of the frame's change, and part of it in at least half
of the frame's tiles: a pan, a shake or a sliding background, not an approaching object or the
camera's own forward motion, whose images expand, nor an object drifting over a plain
background, which moves only where it is. The photoreceptors then measure each frame's change against the previous frame moved by that
translation (:func:`shift_image`): the background's motion leaves them nearly silent, while an
object that does not move with it changes as if it moved against it, which is the motion the
rest of the retina sees. The temporal filter's state is not moved: it stays where the frame's
pixels are, with the object, and what the background left in it decays. The looming fit, which
measures the object's own image motion on the raw frames, leaves out the pixels that the
background's translation explains (:func:`asnn.approach.looming.region_expansion`).

References
----------
.. [1] B. P. Ölveczky, S. A. Baccus, M. Meister, "Segregation of object and background motion
   in the retina", Nature 423, 2003, pp. 401-408.
.. [2] R. H. S. Carpenter, *Movements of the Eyes*, 2nd ed., Pion, 1988 (gaze stabilisation).
"""

from __future__ import annotations

import math

import numpy as np

from ._jit import kernel

__all__ = ["background_shift", "search_radius", "shift_image"]

_SAMPLES = 4096  # about this many pixels are compared per candidate translation
_LEVELS = 4096  # the frames are compared in steps of 1/4096 of their [0, 1] scale
_MAX_RADIUS = 16  # pixels per frame: the search costs (2 r + 1)^2 comparisons per sample
_TILES = 4  # the frame is also judged in 4 x 4 tiles (background_shift's spread)
_WIDER_GAIN = 0.9  # a wider search's best is taken where it leaves a tenth less difference


def background_shift(previous: np.ndarray, current: np.ndarray, radius: int,
                     share: float, spread: float = 0.0, wider: int = 0) -> tuple[int, int]:
    """The background's translation between two frames, in whole pixels, or ``(0, 0)``.

    For every translation ``(dx, dy)`` with ``|dx|, |dy| <= radius``, the mean absolute
    difference between ``current[y, x]`` and ``previous[y - dy, x - dx]`` over about 4096
    pixels (whole rows, evenly spaced, away from the borders). The best
    translation is accepted when it removes at least ``share`` of the difference without
    translation: one motion then explains most of what changed. With ``spread``, it must also
    remove half that share of the difference in at least that fraction of the frame's 4 x 4
    tiles, each on its own: a pan, a shake or a sliding background moves across the frame,
    while an object drifting over a plain or still background moves only where it is, and there
    its own motion can explain most of the frame's change (a near miss drifting over a plain
    wall would otherwise be taken out, drift and all, and look as if it came straight at the
    camera). Half the share, because a tile also holds what moves otherwise: a prop nearer the
    camera, which a hand-held camera's sway moves farther than the wall behind it.

    With ``wider``, where the best translation lies on the search's edge, the search is made
    again up to ``wider`` pixels, and its best is taken where it leaves clearly less of the
    difference (a tenth less) than the best within ``radius``. A shaken camera's image jumps by
    up to twice the shake's amplitude from one frame to the next, beyond a radius that serves
    pans and sliding backgrounds; the margin keeps the first search's choice where costs are
    about equal along a line (stripes, whose motion along them is free), so that the wider
    search changes nothing but the jumps beyond the radius.

    Parameters
    ----------
    previous, current : ndarray (H, W)
        Luminance of two consecutive frames, float.
    radius : int
        Largest translation searched, pixels per frame.
    share : float
        Smallest fraction of the frame's difference the translation must explain, in (0, 1].
    spread : float, optional
        Smallest fraction of the 16 tiles in which it must explain ``share / 2`` of the tile's
        difference, in [0, 1]; a tile without change or without a sampled row never counts.
        0 (the default): the whole frame's difference only.
    wider : int, optional
        Radius of the second search, pixels per frame, made where the first one's best lies on
        its edge; at most ``radius`` (the default, 0): one search.

    Returns
    -------
    (dx, dy) : (int, int)
        The content moved by ``dx`` pixels right and ``dy`` down; ``(0, 0)`` when no
        translation is accepted (or the frames are too small to search).
    """
    h, w = current.shape
    if h <= 2 * radius or w <= 2 * radius:
        return 0, 0
    tile_costs, costs = _search(previous, current, radius)
    if wider > radius and h > 2 * wider and w > 2 * wider and _on_edge(costs):
        wide_tile_costs, wide_costs = _search(previous, current, wider)
        inner = wide_costs[wider - radius:wider + radius + 1, wider - radius:wider + radius + 1]
        if wide_costs.min() < _WIDER_GAIN * inner.min():
            tile_costs, costs = wide_tile_costs, wide_costs
    return _accepted(tile_costs, costs, share, spread)


def _search(previous, current, radius):
    """The per-tile costs of every translation up to ``radius`` (:func:`_translation_costs`),
    on every ``stride``-th row so that about 4096 pixels are compared, and the tiles' sums."""
    h, w = current.shape
    stride = max(1, round(h * (w - 2 * radius) / _SAMPLES))
    return _translation_costs(previous, current, radius, stride, _TILES)


@kernel(inline="always")
def _best(costs):
    """Index ``(dy + radius, dx + radius)`` of the smallest cost, the first of equal ones in
    row-major order."""
    dy = dx = 0
    for j in range(costs.shape[0]):
        for i in range(costs.shape[1]):
            if costs[j, i] < costs[dy, dx]:
                dy, dx = j, i
    return dy, dx


@kernel()
def _on_edge(costs):
    """Whether the best translation of a search (its whole-frame costs) lies on its edge."""
    n = costs.shape[-1]
    dy, dx = _best(costs)
    return dy == 0 or dy == n - 1 or dx == 0 or dx == n - 1


@kernel()
def _accepted(tile_costs, costs, share, spread):
    """The best translation of a search, ``(dx, dy)``, if it explains ``share`` of the frame's
    change and ``share / 2`` of the change in ``spread`` of its tiles, else ``(0, 0)``
    (:func:`background_shift`); ``costs`` are the tiles' summed. In numba: NumPy's calls on
    these few integers took half as long as the search itself."""
    radius = costs.shape[-1] // 2
    dy, dx = _best(costs)
    still = costs[radius, radius]
    if still == 0 or costs[dy, dx] > (1.0 - share) * still:  # nothing changed, or too little
        return 0, 0
    if spread > 0.0:
        explained = 0
        for row in range(tile_costs.shape[0]):
            for column in range(tile_costs.shape[1]):
                before = tile_costs[row, column, radius, radius]
                if before > 0 and tile_costs[row, column, dy, dx] <= (1.0 - 0.5 * share) * before:
                    explained += 1
        if explained < spread * _TILES * _TILES:  # seen in too few places: an object's own
            return 0, 0
    return dx - radius, dy - radius


def search_radius(width: int, radius: int, reach: float | None = None,
                  factor: float = 1.0) -> int:
    """The translation :func:`background_shift` searches, pixels per frame, for frames
    ``width`` pixels wide: ``radius``, or more where ``reach`` asks for a fraction of the width.

    The same scene seen with twice the pixels moves twice as many pixels per frame, so a radius
    fixed in pixels covers half the motion: a shake of 3 px at 192 px wide is a shake of 5 at
    320. With ``reach`` the search covers the same share of the view at any size.

    Parameters
    ----------
    width : int
        Width of the frames, pixels.
    radius : int
        The smallest radius, pixels per frame (at most 16).
    reach : float, optional
        The radius as a fraction of ``width``, rounded up, at most 16 px (the search's cost
        grows with the radius squared); None: ``radius`` at any width.
    factor : float, optional
        That radius multiplied by this, rounded up, at most 16 px: the wider search's
        (``background_shift``'s ``wider``).

    Returns
    -------
    int
    """
    if reach is not None:
        radius = max(radius, min(math.ceil(reach * width - 1e-9), _MAX_RADIUS))
    return min(math.ceil(factor * radius - 1e-9), _MAX_RADIUS)


@kernel()
def _translation_costs(previous, current, radius, stride, tiles):
    """Sum of ``|current[y, x] - previous[y - dy, x - dx]|`` over every ``stride``-th row (all
    of its columns away from the borders), per tile and translation, indexed ``[tile row,
    tile column, dy + radius, dx + radius]``, in units of 1/4096 of the intensity scale, and
    the tiles' sums, indexed ``[dy + radius, dx + radius]``. The compared part of the frame
    is cut into ``tiles`` x ``tiles`` tiles of about equal size.

    The frames are rounded to those units first: integer sums do not depend on the order
    they are added in, so the loop is vectorised and the result is the same on every machine.
    """
    h, w = current.shape
    n = 2 * radius + 1
    m = w - 2 * radius  # the columns compared
    costs = np.zeros((tiles, tiles, n, n), np.int64)
    here = np.empty(w, np.int32)
    around = np.empty((n, w), np.int32)
    for y in range(radius, h - radius, stride):
        row = (y - radius) * tiles // (h - 2 * radius)
        _levels(current[y], here)
        for j in range(n):
            _levels(previous[y + radius - j], around[j])
        for column in range(tiles):
            start, stop = column * m // tiles, (column + 1) * m // tiles
            middle = here[radius + start:radius + stop]
            for j in range(n):
                for i in range(n):
                    # sliced so that the loop's indices start at zero: it is then vectorised
                    source = around[j, n - 1 - i + start:n - 1 - i + stop]
                    # in int32 (twice the lanes of int64): levels of frames on [0, 1] differ by
                    # at most 4096, so a row's sum fits by far
                    total = np.int32(0)
                    for x in range(stop - start):
                        total = np.int32(total + abs(np.int32(middle[x] - source[x])))
                    costs[row, column, j, i] += total
    summed = np.zeros((n, n), np.int64)
    for row in range(tiles):
        for column in range(tiles):
            summed += costs[row, column]
    return costs, summed


@kernel()
def _levels(row, out):
    """A row of intensities in units of 1/4096, rounded to the nearest."""
    for x in range(row.shape[0]):
        out[x] = np.int32(np.floor(row[x] * _LEVELS + 0.5))


def shift_image(image: np.ndarray, dx: int, dy: int,
                border: np.ndarray | float = 0.0) -> np.ndarray:
    """A copy of ``image`` moved by ``dx`` pixels right and ``dy`` down over its last two axes.

    Pixels with no source in ``image`` take ``border``: a scalar, or an array of the image's
    shape whose values there are used.
    """
    out = np.empty_like(image)
    h, w = image.shape[-2:]
    dst_y, src_y = _span(dy, h)
    dst_x, src_x = _span(dx, w)
    out[..., dst_y, dst_x] = image[..., src_y, src_x]
    uncovered = []  # the rows, then the columns, that nothing moved into
    if dy:
        uncovered.append((slice(0, dy) if dy > 0 else slice(h + dy, h), slice(None)))
    if dx:
        uncovered.append((slice(None), slice(0, dx) if dx > 0 else slice(w + dx, w)))
    for rows, cols in uncovered:
        out[..., rows, cols] = border[..., rows, cols] if isinstance(border, np.ndarray) \
            else border
    return out


def _span(shift: int, n: int) -> tuple[slice, slice]:
    """Destination and source slices of one axis moved by ``shift``."""
    if shift >= 0:
        return slice(shift, n), slice(0, n - shift)
    return slice(0, n + shift), slice(-shift, n)
