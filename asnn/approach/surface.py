"""A surface ahead: the whole view expanding as one plane, as when the camera drives at a wall.

The retina's layers answer an object's edges moving against its surround; where one textured
surface fills the view and the camera closes on it (a wall, a door, the back of a lorry at a
metre), every part of the view moves alike, the centre-surround and direction-selective
filtering cancel it, and the attention finds nothing: the published model, both LGMD
baselines and the object stage all stay silent up to contact. Flies have a separate pathway for
this, the landing response to wide-field expansion, apart from collision avoidance of a small
looming object (Tammero & Dickinson 2002 [1]_).

:func:`surface_expansion` measures it with the looming model of the object stage
(:func:`asnn.approach.looming.region_expansion`, Horn et al.'s time to contact relative to a
planar surface [2]_) on the two frames area-averaged to 64 pixels, over the whole frame and
over each of its 3x3 tiles; :class:`SurfaceWatch` keeps a stream's verdicts, comparing each
frame with the one :data:`BASELINE` seconds before it. The view is a surface ahead when the
whole frame's fit explains at least :data:`FIT_MIN` of its change with a time to contact of at
most ``tau_max`` and a focus of expansion within ``offset_max`` of the frame's centre (in the
frame's RMS radius), and the tiles agree: at least :data:`TILES_MIN` of them expand, each
fitted with at least :data:`TILE_FIT_MIN`, at a median rate of at least
:data:`TILE_RATE_SHARE` of the whole frame's; in every frame of :data:`SECONDS` in a row, the
tiles around the middle one not expanding much faster than it over those frames, each measured
over one frame (a corridor's walls do: :func:`corridor`; at speed its walls at the frame's edge
move beyond the fit's range over the baseline, so the watch measures each frame over the frame
before it too, and the view counts as one surface expanding, a corridor included, where either
passes: :attr:`SurfaceWatch.view_streak`). The tiles tell a wall from a looming object in a
still view, which expands in its middle tile alone. From a road they tell it only in part:
under forward motion the sky does not move and the road's expansion grows toward the frame's
bottom, yet where roadside things fill the view the tiles agree in runs of a few frames; the
drives' runs are short, a wall's last, and the duration is what tells them apart
(docs/design-notes.md, "A surface ahead, adopted", where the numbers were set on generated
walls against every other generated scene; "A surface ahead over a tenth of a second", where
the baseline was; "A corridor is not a surface ahead"; and "A fast corridor, read over one
frame").

References
----------
.. [1] L. F. Tammero, M. H. Dickinson, "Collision-avoidance and landing responses are mediated
   by separate pathways in the fruit fly, Drosophila melanogaster", Journal of Experimental
   Biology 205, 2002, pp. 2785-2798.
.. [2] B. K. P. Horn, Y. Fang, I. Masaki, "Time to contact relative to a planar surface",
   IEEE Intelligent Vehicles Symposium, 2007, pp. 68-74.
"""

from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

import numpy as np

from .._fast import block_means
from .looming import region_expansion, shrink_step, shrunk_mask, shrunk_size

__all__ = ["BASELINE", "CORRIDOR_RATIO", "FIT_MIN", "SECONDS", "SIDE", "TILES", "TILES_MIN",
           "TILE_FIT_MIN", "TILE_RATE_SHARE", "Surface", "SurfaceWatch", "corridor", "shrunk",
           "surface_expansion", "surface_frames"]

SIDE = 64  # pixels on the frames' larger side for the fits
# how long the view must read as a surface ahead: 7 frames at 20 fps. Set where the generated
# drives' whole frame passed in runs of up to 5 frames compared frame to frame (a truck
# overtaking, turns past oncoming cars), a wall's in runs of 11 or more from about a second before
# contact; compared over BASELINE, the drives' runs are 2 frames at most, a wall's 15 or more
SECONDS = 0.3
# seconds between the two frames compared (2 frames at 20 fps, 3 at 30, 1 at 10): a faint wall's
# change over one frame at 20 fps is small against sensor noise (fits of 0.25-0.45, the faint wall
# caught in 3 of 11 variants); over two it doubles while the noise does not, and a drive's view,
# which is not one plane, fits worse, so that its runs shorten (the longest from 5 frames to 2)
BASELINE = 0.1
# frames the watch keeps for its baseline and its corridor's rates at most (0.3 s at 850 fps): the
# spans above count seconds, and a clock stepping a microsecond a frame kept 100,000 of them
MAX_KEPT = 256
FIT_MIN = 0.3
TILES = 3  # tiles a side
TILES_MIN = 8  # of 9
TILE_FIT_MIN = 0.1
TILE_RATE_SHARE = 0.5  # the tiles' median rate against the whole frame's: not a looming object
# a corridor or a tunnel: its walls expand faster the nearer they pass, so the tiles around the
# middle one expand faster than it, where a wall's are alike or rise on one side only (slanted).
# Their median above this many times its rate, each over one frame and summed over SECONDS, is
# not a surface ahead: in the generated corridors at 2 and 3 m/s 2.3 and more, on the generated
# walls 1.65 at most (variants 0-3, in the frames the wall counts), and this between them
CORRIDOR_RATIO = 2.0


class Surface(NamedTuple):
    """The whole view's expansion in one frame.

    Attributes
    ----------
    rate : float
        Expansion rate of the whole frame, per second (> 0: closing in).
    x, y : float
        The focus of expansion, model pixels (the frame's centre less drift over rate).
    offset : float
        The focus's distance from the frame's centre over the frame's RMS radius
        ``sqrt((w^2 + h^2) / 12)``: 0 heading at the frame's centre.
    fit : float
        The share of the frame's change the whole-frame fit explains.
    tiles : int
        Tiles of the 3x3 grid that expand with a fit of at least :data:`TILE_FIT_MIN`
        (0 where not measured: the whole frame failed first).
    tile_rate : float
        The median of the tiles' expansion rates, per second (0 where not measured).
    tile_rates : ndarray (3, 3) or None
        Each tile's expansion rate, per second (NaN where a tile holds nothing to fit; None
        where not measured).
    """

    rate: float
    x: float
    y: float
    offset: float
    fit: float
    tiles: int
    tile_rate: float
    tile_rates: np.ndarray | None = None


def shrunk(image: np.ndarray) -> np.ndarray:
    """``image`` area-averaged to at most :data:`SIDE` pixels on its larger side (as it is)."""
    h, w = image.shape
    step = shrink_step(w, h, SIDE)
    if step == 1.0:
        return image
    return block_means(image, shrunk_size(w, h, step))  # cv2.resize's INTER_AREA


def surface_expansion(previous: np.ndarray, current: np.ndarray, elapsed: float,
                      tau_max: float, offset_max: float, exclude: np.ndarray | None = None
                      ) -> tuple[Surface | None, bool]:
    """The whole view's expansion between two frames, and whether it is a surface ahead.

    Both frames are area-averaged to at most :data:`SIDE` pixels a side first (:func:`shrunk`),
    so that each tile is fitted, as the whole frame is, on averages in which sensor noise
    does not hide the change.

    Parameters
    ----------
    previous, current : ndarray (H, W)
        Luminance of two frames, float.
    elapsed : float
        Seconds between them.
    tau_max, offset_max : float
        The approach test's longest time to contact (s) and largest offset, here of the focus
        of expansion in the frame's RMS radius.
    exclude : ndarray (H, W) of bool, optional
        Pixels to leave out (the camera's rig); a shrunk pixel is left out when a quarter of
        its area is.

    Returns
    -------
    surface : Surface or None
        In the frames' pixels; None where the frame holds nothing to fit.
    ahead : bool
        Whether this frame passes the test (module text); the tiles are fitted only where the
        whole frame passes.
    """
    return _measure(shrunk(previous), shrunk(current), current.shape, elapsed, tau_max,
                    offset_max, exclude)


def _measure(before: np.ndarray, after: np.ndarray, shape: tuple[int, int], elapsed: float,
             tau_max: float, offset_max: float, exclude: np.ndarray | None
             ) -> tuple[Surface | None, bool]:
    """:func:`surface_expansion` of two frames already :func:`shrunk` from frames of
    ``shape`` (H, W), the shape ``exclude`` has."""
    h, w = shape
    sh, sw = after.shape
    exclude = _shrunk_mask(exclude, (sh, sw))
    whole = region_expansion(before, after, (0, 0, sw, sh), None, exclude)
    if whole is None or not elapsed > 0 or whole.rate <= 0:
        return None, False
    rate = whole.rate / elapsed
    offset = (math.hypot(whole.drift_x, whole.drift_y)
              / (whole.rate * math.sqrt((sw * sw + sh * sh) / 12.0)))
    # the focus of expansion, back in the frames' pixels
    x = (0.5 * (sw - 1) - whole.drift_x / whole.rate + 0.5) * w / sw - 0.5
    y = (0.5 * (sh - 1) - whole.drift_y / whole.rate + 0.5) * h / sh - 0.5
    if not (rate * tau_max >= 1.0 and offset <= offset_max and whole.fit >= FIT_MIN):
        return Surface(rate, x, y, offset, whole.fit, 0, 0.0), False
    grid, expanding = _tile_rates(before, after, elapsed, exclude)
    measured = grid[np.isfinite(grid)]
    tile_rate = float(np.median(measured)) if measured.size else 0.0
    ahead = expanding >= TILES_MIN and tile_rate >= TILE_RATE_SHARE * rate
    return Surface(rate, x, y, offset, whole.fit, expanding, tile_rate, grid), ahead


def _shrunk_mask(exclude: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray | None:
    """``exclude`` at the shrunk frames' ``shape`` (h, w): a shrunk pixel is left out when a
    quarter of its area is."""
    if exclude is None or exclude.shape == shape:
        return exclude
    return shrunk_mask(exclude, shape[::-1])


def _tile_rates(before: np.ndarray, after: np.ndarray, elapsed: float,
                exclude: np.ndarray | None) -> tuple[np.ndarray, int]:
    """Each of the 3x3 tiles' expansion rate per second between two shrunk frames ``elapsed``
    seconds apart (NaN where a tile holds nothing to fit), and how many expand with a fit of
    at least :data:`TILE_FIT_MIN`."""
    sh, sw = after.shape
    grid, expanding = np.full((TILES, TILES), np.nan), 0
    for i in range(TILES):
        for j in range(TILES):
            box = (j * sw // TILES, i * sh // TILES, (j + 1) * sw // TILES,
                   (i + 1) * sh // TILES)
            tile = region_expansion(before, after, box, None, exclude)
            if tile is None:
                continue
            grid[i, j] = tile.rate / elapsed
            expanding += tile.rate > 0 and tile.fit >= TILE_FIT_MIN
    return grid, expanding


def corridor(tile_rates: np.ndarray) -> bool:
    """Whether the tiles around the middle one expand, at their median, more than
    :data:`CORRIDOR_RATIO` times faster than it (``tile_rates`` as :attr:`Surface.tile_rates`,
    or their sum over frames): walls, floor and ceiling passing around the camera, not one
    surface ahead. A middle tile not measured refuses nothing."""
    middle = tile_rates[TILES // 2, TILES // 2]
    around = np.delete(tile_rates.ravel(), tile_rates.size // 2)
    around = around[np.isfinite(around)]
    return bool(around.size and np.median(around) > CORRIDOR_RATIO * middle)


def surface_frames(period: float) -> int:
    """Frames in a row the surface test must pass at the frame ``period`` (s): as many as span
    :data:`SECONDS` (7 at 20 fps, 10 at 30, 4 at 10); a period not known yet (0) is taken as
    20 fps's, the rate the rule was set at."""
    if not period > 0.0:
        period = 0.05
    # a thousandth of a frame's slack, as for the tracks' persistence: 0.05 s stamps read 0.0499...
    return 1 + math.ceil(SECONDS / period - 1e-3)


class SurfaceWatch:
    """One stream's surface-ahead verdicts: the frames in a row that passed, and the id the
    surface is reported under while it persists. Each frame is compared with the one
    :data:`BASELINE` seconds before it (or the oldest the stream has, at its start), whose
    shrunk form it keeps, and, where that is more than a frame back, with the frame before it
    too: at speed a corridor's walls at the frame's edge move beyond the fit's range over the
    baseline, and read slower than they are.

    Attributes
    ----------
    streak : int
        Frames in a row that passed :func:`surface_expansion`'s test over the baseline: the
        surface pathway's.
    view_streak : int
        Frames in a row that passed it over the baseline or over the latest frame: how long
        the view has read as one surface expanding, a corridor included.
    surface : Surface or None
        The latest frame's measurement over the baseline.
    corridor : bool
        Whether the tiles' expansion rates over one frame, summed over the view streak's latest
        :data:`SECONDS`, read as a corridor (:func:`corridor`): the view is then walls passing
        around the camera, not a surface ahead. Judged over frames, not in each, since the
        middle tile's rate is the noisiest (the motion vanishes at the focus).
    id : int or None
        The target id of the current run of passing frames (a new one for each run).
    """

    def __init__(self) -> None:
        self.streak = 0
        self.view_streak = 0
        self.surface: Surface | None = None
        self.id: int | None = None
        self.corridor = False
        # the view streak's latest tile rates over one frame, each with the seconds since the
        # frame before
        self._rates: deque[tuple[np.ndarray, float]] = deque()
        self._latest: np.ndarray | None = None  # the frame last given as ``current``
        self._before: np.ndarray | None = None  # the frame last given as ``previous``
        # the shrunk frames back to the baseline's, oldest first, each with the seconds since
        # the one before it
        self._history: deque[tuple[np.ndarray, float]] = deque()

    def averages(self) -> tuple:
        """The last step's two frames with their :func:`shrunk` forms, ``((previous, shrunk),
        (current, shrunk))`` (empty before the first step): the scene's fit over the same
        frames takes them instead of averaging the frames again
        (:func:`asnn.approach.looming.scene_expansion`'s ``averaged``)."""
        history = self._history
        if self._latest is None or len(history) < 2:
            return ()
        # the last two kept are the step's frames: the history restarts from ``previous`` where
        # it was not the frame before, and is never trimmed below two
        return (self._before, history[-2][0]), (self._latest, history[-1][0])

    def step(self, previous: np.ndarray, current: np.ndarray, elapsed: float, tau_max: float,
             offset_max: float, exclude: np.ndarray | None = None) -> Surface | None:
        """Measure one frame (``elapsed`` seconds after ``previous``); the surface where it has
        passed in enough frames is for the caller to judge from :attr:`streak`. Where
        ``previous`` is not the frame the last step was given as ``current`` (the stream
        restarted), the frames kept are dropped."""
        history = self._history
        if self._latest is not previous or not history:
            history.clear()
            history.append((shrunk(previous), 0.0))
        history.append((shrunk(current), elapsed))
        if len(history) > MAX_KEPT:  # frames a hair apart (a clock in microseconds' steps)
            history.popleft()
        self._latest, self._before = current, previous
        # back to the frame BASELINE before (a thousandth of a frame's slack, as for the
        # persistence: 0.05 s stamps read 0.0499...), or the oldest kept
        span, k = 0.0, len(history) - 1
        while k > 0 and span < BASELINE - 1e-3:
            span += history[k][1]
            k -= 1
        for _ in range(k):
            history.popleft()
        after = history[-1][0]
        exclude = _shrunk_mask(exclude, after.shape)
        self.surface, ahead = _measure(history[0][0], after, current.shape, span, tau_max,
                                       offset_max, exclude)
        one, one_ahead = self.surface, ahead  # over the latest frame
        if len(history) > 2 and elapsed > 0:
            one, one_ahead = _measure(history[-2][0], after, current.shape, elapsed, tau_max,
                                      offset_max, exclude)
        self.streak = self.streak + 1 if ahead else 0
        if not ahead:
            self.id = None
        self.view_streak = self.view_streak + 1 if ahead or one_ahead else 0
        if self.view_streak:
            grid = (one.tile_rates if one_ahead
                    else _tile_rates(history[-2][0], after, elapsed, exclude)[0])
            kept = self._rates
            kept.append((grid, elapsed))
            if len(kept) > MAX_KEPT:
                kept.popleft()
            span = sum(dt for _, dt in kept) - kept[0][1]  # from the oldest kept to this one
            while span > SECONDS + 1e-3:
                kept.popleft()
                span -= kept[0][1]
            self.corridor = corridor(sum(r for r, _ in kept))
        else:
            self.corridor = False
            self._rates.clear()
        return self.surface
