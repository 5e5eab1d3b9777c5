"""Looming-target extraction: grouping of the attended pixels and population-coded motion.

Implements SPEC.md section 1 item 10 (paper eqs. 29-31) with the cluster direction ruling
``direction = atan2(V_Y, V_X)`` in image coordinates (x right, y down, so a positive angle turns
clockwise on screen). Two groupings:

:func:`extract_targets`
    DBSCAN of the attended pixels (the paper, the published variant): one target per dense
    cluster, which on a looming object is often one per segment of its rim.
:func:`extract_objects`
    Connected regions of the attended mask, each with its approach-weighted centre and size
    (the ``robust`` preset): the input of the tracker of :mod:`asnn.approach.tracking`, which adds
    the optional fields ``id``, ``expansion``, ``ttc``, ``offset`` and ``approaching``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import math

import numpy as np

from ._jit import kernel

__all__ = ["Target", "ObjectRegions", "dbscan_points", "extract_targets",
           "extract_objects"]


@dataclass(frozen=True, slots=True)
class Target:
    """One looming region.

    Attributes
    ----------
    x, y : float
        Centre in input-frame pixels (x = column, y = row).
    direction : float
        Radians, ``atan2(V_Y, V_X)`` in image coordinates.
    energy : float
        ``sqrt(V_X^2 + V_Y^2)``, the mean motion vector's length.
    pixels : int
        The target's size in input-frame pixels (where ``max_width`` shrinks the frame or
        ``min_width`` enlarges it, the model's grid's count scaled back): a cluster's core
        samples (and the origin seed, where ``origin_seed`` adds it and it is a core sample),
        an object's attended pixels.
    id : int or None
        Stable identifier of the object across the stream's frames (tracked presets).
    expansion : float or None
        Relative growth rate of the object's image, per second: (1/size) d(size)/dt; negative
        while it shrinks (tracked presets).
    ttc : float or None
        Time to contact ``1 / expansion``, seconds; None while the object does not grow.
    offset : float or None
        Lateral drift over expansion, in object sizes: near 0 on a collision course, large for
        an object that will pass (:mod:`asnn.approach.tracking`); None while it does not grow.
    approaching : bool or None
        Whether the object passes the approach test that drives the warning.
    """

    x: float
    y: float
    direction: float
    energy: float
    pixels: int
    id: int | None = None
    expansion: float | None = None
    ttc: float | None = None
    offset: float | None = None
    approaching: bool | None = None

    def to_dict(self) -> dict:
        """JSON-ready fields; the optional ones only where the model sets them.

        Returns
        -------
        dict
            ``x``, ``y``, ``direction``, ``energy`` and ``pixels``; for a tracked object (``id``
            set) also ``id``, ``expansion``, ``ttc``, ``offset`` (each None where unknown) and
            ``approaching`` (a bool).
        """
        d = {"x": self.x, "y": self.y, "direction": self.direction, "energy": self.energy,
             "pixels": self.pixels}
        if self.id is not None:
            d.update(id=self.id, expansion=self.expansion, ttc=self.ttc, offset=self.offset,
                     approaching=bool(self.approaching))
        return d


@kernel()
def _find(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@kernel()
def _union(parent, i, j):
    a, b = _find(parent, i), _find(parent, j)
    if a < b:
        parent[b] = a
    elif b < a:
        parent[a] = b


@kernel()
def _dbscan_points(rows, cols, eps, min_samples, has_seed, seed_row, seed_col):
    """DBSCAN of pixels given in row-major order; see :func:`dbscan_points`."""
    n = rows.shape[0]
    labels = np.full(n, -1, np.int64)
    r = int(math.floor(eps))
    eps2 = eps * eps
    half = np.zeros(r + 1, np.int64)  # the disk's half-width in each row offset
    for dy in range(r + 1):
        while (half[dy] + 1) ** 2 + dy * dy <= eps2:
            half[dy] += 1
    r0, r1 = rows[0], rows[n - 1]
    c0, c1 = cols[0], cols[0]
    for i in range(n):
        c0 = min(c0, cols[i])
        c1 = max(c1, cols[i])
    bh, bw = r1 - r0 + 1, c1 - c0 + 1
    index = np.full((bh, bw), -1, np.int64)
    prefix = np.zeros((bh, bw + 1), np.int64)  # pixels left of column x in each row
    for i in range(n):
        index[rows[i] - r0, cols[i] - c0] = i
    for y in range(bh):
        row, pre = index[y], prefix[y]
        for x in range(bw):
            pre[x + 1] = pre[x] + (1 if row[x] >= 0 else 0)
    # core samples: neighbours within eps, the point itself and the seed included
    core = np.zeros(n, np.bool_)
    seed_count = 1
    for i in range(n):
        y, x = rows[i] - r0, cols[i] - c0
        count = 0
        for dy in range(-r, r + 1):
            yy = y + dy
            if 0 <= yy < bh:
                hw = half[abs(dy)]
                count += prefix[yy, min(x + hw, bw - 1) + 1] - prefix[yy, max(x - hw, 0)]
        if has_seed and (rows[i] - seed_row) ** 2 + (cols[i] - seed_col) ** 2 <= eps2:
            count += 1
            seed_count += 1
        core[i] = count >= min_samples
    seed_core = has_seed and seed_count >= min_samples
    # core samples within eps of each other share a cluster: union-find over the grid
    parent = np.arange(n + 1)  # n: the seed
    for i in range(n):
        if not core[i]:
            continue
        y, x = rows[i] - r0, cols[i] - c0
        left = x > 0 and index[y, x - 1] >= 0 and core[index[y, x - 1]] and half[0] >= 1
        for dy in range(0, r + 1):
            yy = y + dy
            if yy >= bh:
                break
            hw = half[dy]
            # with a linked core pixel on the left, only the disk's new right edge is new
            lo = x + hw if left else (x + 1 if dy == 0 else x - hw)
            for xx in range(max(lo, 0), min(x + hw, bw - 1) + 1):
                j = index[yy, xx]
                if j >= 0 and core[j]:
                    _union(parent, i, j)
        if seed_core and (rows[i] - seed_row) ** 2 + (cols[i] - seed_col) ** 2 <= eps2:
            _union(parent, i, n)
    # clusters numbered by their first core sample (the seed comes after every pixel)
    cluster = np.full(n + 1, -1, np.int64)
    count = 0
    for i in range(n):
        if core[i]:
            root = _find(parent, i)
            if cluster[root] < 0:
                cluster[root] = count
                count += 1
            labels[i] = cluster[root]
    seed_label = -1
    if seed_core:
        root = _find(parent, n)
        if cluster[root] < 0:
            cluster[root] = count
        seed_label = cluster[root]
    return labels, seed_core, seed_label


def dbscan_points(rows: np.ndarray, cols: np.ndarray, eps: float, min_samples: int,
                  seed: tuple[int, int] | None = None) -> tuple[np.ndarray, bool, int]:
    """DBSCAN of pixels (``rows``, ``cols`` in row-major order), with scikit-learn's semantics.

    A pixel is a core sample when at least ``min_samples`` points (itself included) lie within
    Euclidean distance ``eps``; core samples within ``eps`` of each other share a cluster.
    Clusters are numbered in the order of their first core sample, as
    ``sklearn.cluster.DBSCAN`` numbers them when given the pixels in that order. The search uses
    the grid of the pixels' bounding box: neighbour counts from row prefix sums over the disk's
    rows, clusters by union-find over the disk (a core pixel whose left neighbour is a core pixel
    only looks at the disk's right edge: the rest was joined through that neighbour).

    Parameters
    ----------
    rows, cols : ndarray of int
    eps : float
    min_samples : int
    seed : (row, col), optional
        An extra point appended after the pixels (the published implementation adds (0, 0)).

    Returns
    -------
    labels : ndarray of int (n,)
        Cluster number of each *core* pixel, -1 for the others.
    seed_core : bool
        Whether the seed point is a core sample.
    seed_label : int
        The seed's cluster when it is a core sample, else -1.
    """
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    cols = np.ascontiguousarray(cols, dtype=np.int64)
    if len(rows) == 0:
        return np.empty(0, np.int64), False, -1
    sr, sc = seed if seed is not None else (0, 0)
    labels, seed_core, seed_label = _dbscan_points(rows, cols, float(eps), int(min_samples),
                                                   seed is not None, int(sr), int(sc))
    return labels, bool(seed_core), int(seed_label)


def extract_targets(mask: np.ndarray, dx: np.ndarray | None, dy: np.ndarray | None, eps: float,
                    min_samples: int, origin_seed: bool = False, *,
                    vectors: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
                    | None = None, points: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> list[Target]:
    """Targets of the attended pixels ``M_a M_d = 1`` (paper eqs. 29-31).

    Parameters
    ----------
    mask : ndarray of bool (H, W)
        ``M_a M_d``.
    dx, dy : ndarray (H, W) or None
        Motion vector per pixel, ``V cos(phi)`` and ``V sin(phi)`` (eq. 29).
    eps, min_samples : DBSCAN parameters.
    vectors : callable, optional
        Instead of ``dx`` and ``dy``: ``vectors(rows, cols) -> (dx, dy)`` at the given pixels,
        so that the motion vectors are computed for the core samples only.
    origin_seed : bool
        Add the point (0, 0) and drop clusters centred within 1 px of it (published variant).
    points : (rows, cols), optional
        The set pixels of ``mask`` in row-major order, when the caller has them.

    Returns
    -------
    list of Target, in cluster order; centre and motion are means over the core samples.
    """
    rows, cols = np.nonzero(mask) if points is None else points
    if not len(rows):
        return []
    seed = (0, 0) if origin_seed else None
    labels, seed_core, seed_label = dbscan_points(rows, cols, eps, min_samples, seed)
    core = labels >= 0
    if not core.any():
        return []
    lab = labels[core]
    rows, cols = rows[core], cols[core]
    if vectors is None:
        vx, vy = dx[rows, cols], dy[rows, cols]
        vx0, vy0 = (dx[0, 0], dy[0, 0]) if seed_core else (0.0, 0.0)
    else:
        if seed_core:
            rows0, cols0 = np.append(rows, 0), np.append(cols, 0)
            vx, vy = vectors(rows0, cols0)
            vx, vy, vx0, vy0 = vx[:-1], vy[:-1], vx[-1], vy[-1]
        else:
            vx, vy = vectors(rows, cols)
    n = max(int(lab.max()), seed_label) + 1
    count = np.bincount(lab, minlength=n).astype(np.float64)
    sum_x = np.bincount(lab, cols, n)
    sum_y = np.bincount(lab, rows, n)
    sum_dx = np.bincount(lab, vx, n)
    sum_dy = np.bincount(lab, vy, n)
    if seed_core:
        count[seed_label] += 1
        sum_dx[seed_label] += vx0
        sum_dy[seed_label] += vy0
    direction, energy = _population_motion(sum_dx, sum_dy, count)
    targets = []
    for k in range(n):
        cx, cy = sum_x[k] / count[k], sum_y[k] / count[k]
        if origin_seed and cx * cx + cy * cy <= 1.0:
            continue
        targets.append(Target(x=float(cx), y=float(cy), direction=float(direction[k]),
                              energy=float(energy[k]), pixels=int(count[k])))
    return targets


def _population_motion(sum_dx: np.ndarray, sum_dy: np.ndarray, count: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Each cluster's population-coded motion from its summed motion vectors: the mean
    ``(V_X, V_Y)`` (paper eq. 30) as a direction and an energy (eq. 31), the direction
    ``atan2(V_Y, V_X)`` (SPEC.md section 2's ruling: the paper prints atan2(V_X, V_Y))."""
    vx, vy = sum_dx / count, sum_dy / count
    return np.arctan2(vy, vx), np.hypot(vx, vy)


@dataclass(frozen=True)
class ObjectRegions:
    """Connected regions of an attended mask and their statistics (see :func:`extract_objects`).

    Attributes
    ----------
    x, y, size, mass : ndarray (n,)
        Per region: centre and RMS radius of the approach activity ``G`` over the region, and
        ``sum max(G, 0)``.
    share : ndarray (n,)
        The region's share of the membrane potential: ``sum G`` over it, or ``sum |G|``.
    boxes : ndarray of int (n, 4)
        ``(x0, y0, x1, y1)`` bounding box (exclusive ends).
    pixels : ndarray of int (n,)
    members : (rows, cols, region) of ndarray of int
        The regions' pixels, in the mask's row-major order, and the region of each.
    vectors : callable
        ``vectors(rows, cols) -> (dx, dy)``, as given to :func:`extract_objects`; where it
        has a ``sums(rows, cols, labels, n)`` method (:class:`asnn._fast.MotionVectors`), the
        regions' summed vectors come from it, as ``np.bincount`` of the vectors would give
        them.
    direction, energy : ndarray (n,)
        Population-coded motion of each region (paper eqs. 29-31): the mean of
        ``(V cos(phi), V sin(phi))`` over its pixels, as an angle and a length. Computed when
        first read, from ``vectors`` at every pixel of the regions: a frame whose objects are
        not reported as targets (none approaches) needs none of them. ``vectors`` must still
        give the frame's values then (the model reads them while it finishes the frame).
    """

    x: np.ndarray
    y: np.ndarray
    size: np.ndarray
    mass: np.ndarray
    share: np.ndarray
    boxes: np.ndarray
    pixels: np.ndarray
    members: tuple[np.ndarray, np.ndarray, np.ndarray] = field(repr=False, compare=False)
    vectors: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] = field(
        repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.x)

    @cached_property
    def _motion(self) -> tuple[np.ndarray, np.ndarray]:
        """The direction and energy of each region's mean motion vector (eqs. 30-31)."""
        rows, cols, lab = self.members
        n = len(self)
        sums = getattr(self.vectors, "sums", None)  # the optimised model's, in one pass
        if sums is not None:
            sum_dx, sum_dy = sums(rows, cols, lab, n)
        else:
            dx, dy = self.vectors(rows, cols) if len(rows) else (np.zeros(0), np.zeros(0))
            sum_dx, sum_dy = np.bincount(lab, dx, n), np.bincount(lab, dy, n)
        return _population_motion(sum_dx, sum_dy, np.maximum(self.pixels, 1))

    @cached_property
    def direction(self) -> np.ndarray:
        return self._motion[0]

    @cached_property
    def energy(self) -> np.ndarray:
        return self._motion[1]


@kernel()
def _components(rows, cols):
    """8-connected components of pixels given in row-major order, numbered as OpenCV's
    ``connectedComponentsWithStats`` numbers them (from 0 here, without the background).

    The pixels are taken as runs (consecutive pixels of a row); a run joins every run of the
    row above that it touches, diagonals included (union-find). OpenCV labels 2x2 blocks of
    the image in raster order, so its components come in the order of their first block: the
    least ``(y // 2, x // 2)`` over their pixels, a run's being ``(y // 2, x0 // 2)``. Returns
    each pixel's component and per component ``(left, top, width, height, area)``.
    """
    n = rows.shape[0]
    run_row = np.empty(n, np.int64)
    run_x0 = np.empty(n, np.int64)
    run_x1 = np.empty(n, np.int64)  # inclusive
    m = 0
    for i in range(n):
        if m and rows[i] == run_row[m - 1] and cols[i] == run_x1[m - 1] + 1:
            run_x1[m - 1] = cols[i]
        else:
            run_row[m], run_x0[m], run_x1[m] = rows[i], cols[i], cols[i]
            m += 1
    parent = np.arange(m)
    above0 = above1 = row_start = q = 0  # the runs of the row above: [above0, above1)
    for k in range(m):
        if k == 0 or run_row[k] != run_row[k - 1]:
            if k and run_row[k - 1] == run_row[k] - 1:
                above0, above1 = row_start, k
            else:
                above0 = above1 = k
            row_start, q = k, above0
        # runs above that end left of this one's reach cannot touch the ones right of it
        while q < above1 and run_x1[q] < run_x0[k] - 1:
            q += 1
        j = q
        while j < above1 and run_x0[j] <= run_x1[k] + 1:
            _union(parent, k, j)
            j += 1
    width = 1
    for k in range(m):
        width = max(width, (run_x1[k] >> 1) + 2)
    first = np.full(m, -1, np.int64)  # per root: its first block, y // 2 * width + x // 2
    for k in range(m):
        root = _find(parent, k)
        key = (run_row[k] >> 1) * width + (run_x0[k] >> 1)
        if first[root] < 0 or key < first[root]:
            first[root] = key
    roots = np.flatnonzero(first >= 0)
    order = roots[np.argsort(first[roots])]
    number = np.empty(m, np.int64)
    number[order] = np.arange(order.shape[0])
    stats = np.zeros((order.shape[0], 5), np.int64)
    right = np.zeros(order.shape[0], np.int64)
    bottom = np.zeros(order.shape[0], np.int64)
    labels = np.empty(n, np.int64)
    i = 0
    for k in range(m):
        c = number[_find(parent, k)]
        s = stats[c]
        length = run_x1[k] - run_x0[k] + 1
        if s[4] == 0:
            s[0], s[1] = run_x0[k], run_row[k]
        else:
            s[0] = min(s[0], run_x0[k])
        right[c] = max(right[c], run_x1[k])
        bottom[c] = run_row[k]  # the runs come in row order
        s[4] += length
        for _ in range(length):
            labels[i] = c
            i += 1
    for c in range(order.shape[0]):
        stats[c, 2] = right[c] - stats[c, 0] + 1
        stats[c, 3] = bottom[c] - stats[c, 1] + 1
    return labels, stats


@kernel()
def _region_moments(rows, cols, g, min_pixels, absolute):
    """The kept regions' boxes and pixel counts, their pixels (rows, columns and region
    numbers) and each region's G-weighted centre, variance, mass and share (see
    :func:`extract_objects`), summed in the pixels' order as ``np.bincount`` sums."""
    labels, stats = _components(rows, cols)
    lut = np.full(stats.shape[0], -1, np.int64)  # component -> kept region, or -1
    n = 0
    for c in range(stats.shape[0]):
        if stats[c, 4] >= min_pixels:
            lut[c] = n
            n += 1
    boxes = np.empty((n, 4), np.int64)
    pixels = np.empty(n, np.int64)
    for c in range(stats.shape[0]):
        k = lut[c]
        if k >= 0:
            boxes[k, 0], boxes[k, 1] = stats[c, 0], stats[c, 1]
            boxes[k, 2], boxes[k, 3] = stats[c, 0] + stats[c, 2], stats[c, 1] + stats[c, 3]
            pixels[k] = stats[c, 4]
    m = 0
    lab = np.empty(rows.shape[0], np.int64)
    kept_rows = np.empty_like(lab)
    kept_cols = np.empty_like(lab)
    values = np.empty(rows.shape[0], np.float64)
    share = np.zeros(n)
    mass = np.zeros(n)
    # Each region's sums are carried in locals along a run of its pixels and stored when the
    # run ends: the same additions in the same order, without a store and a load between two
    # additions to one sum (which made these loops wait on memory).
    k0, a, b = -1, 0.0, 0.0
    for i in range(rows.shape[0]):
        k = lut[labels[i]]
        if k < 0:
            continue
        if k != k0:
            if k0 >= 0:
                share[k0], mass[k0] = a, b
            k0, a, b = k, share[k], mass[k]
        value = np.float64(g[rows[i], cols[i]])
        lab[m], kept_rows[m], kept_cols[m], values[m] = k, rows[i], cols[i], value
        m += 1
        a += abs(value) if absolute else value
        b += max(value, 0.0)
    if k0 >= 0:
        share[k0], mass[k0] = a, b
    total, sum_x, sum_y = np.zeros(n), np.zeros(n), np.zeros(n)
    k0, a, b, c = -1, 0.0, 0.0, 0.0
    for i in range(m):
        k = lab[i]
        if k != k0:
            if k0 >= 0:
                total[k0], sum_x[k0], sum_y[k0] = a, b, c
            k0, a, b, c = k, total[k], sum_x[k], sum_y[k]
        wt = max(values[i], 0.0) if mass[k] > 0 else 1.0  # no positive G: equal weights
        values[i] = wt
        a += wt
        b += wt * kept_cols[i]
        c += wt * kept_rows[i]
    if k0 >= 0:
        total[k0], sum_x[k0], sum_y[k0] = a, b, c
    x, y = sum_x / total, sum_y / total
    var = np.zeros(n)
    k0, a = -1, 0.0
    for i in range(m):
        k = lab[i]
        if k != k0:
            if k0 >= 0:
                var[k0] = a
            k0, a = k, var[k]
        ddx, ddy = kept_cols[i] - x[k], kept_rows[i] - y[k]
        a += values[i] * (ddx * ddx + ddy * ddy)
    if k0 >= 0:
        var[k0] = a
    return (boxes, pixels, kept_rows[:m], kept_cols[:m], lab[:m], x, y, var / total, mass,
            share)


def extract_objects(mask: np.ndarray, g: np.ndarray,
                    vectors: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
                    min_pixels: int, absolute: bool, *,
                    points: tuple[np.ndarray, np.ndarray] | None = None) -> ObjectRegions:
    """Objects of the attended mask ``M_a M_d``: its 8-connected regions of at least
    ``min_pixels`` pixels.

    The attention blur (31x31) already joins nearby edges of one object into one region, so a
    region stands for an object rather than for one segment of its rim. The centre and size are
    weighted by the approach map ``G``: the thresholded mask's outline moves with the signal's
    strength, the weighted moments move with the object.

    Parameters
    ----------
    mask : ndarray of bool (H, W)
    g : ndarray (H, W)
        The approach map G (weights; negative values count as 0).
    vectors : callable
        ``vectors(rows, cols) -> (dx, dy)``: the motion vector ``V cos(phi)``, ``V sin(phi)``
        at the given pixels; called when the regions' direction or energy is first read.
    min_pixels : int
    absolute : bool
        Whether the membrane potential sums ``|G'|`` (the regions' ``share``).
    points : (rows, cols), optional
        The set pixels of ``mask`` in row-major order, when the caller has them.

    Returns
    -------
    ObjectRegions
    """
    rows, cols = np.nonzero(mask) if points is None else points
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    cols = np.ascontiguousarray(cols, dtype=np.int64)
    boxes, pixels, rows, cols, lab, x, y, var, mass, share = _region_moments(
        rows, cols, g, min_pixels, bool(absolute))
    return ObjectRegions(x=x, y=y, size=np.sqrt(var + 1.0), mass=mass, share=share, boxes=boxes,
                         pixels=pixels, members=(rows, cols, lab), vectors=vectors)
