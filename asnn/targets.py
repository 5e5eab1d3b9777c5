"""Looming-target extraction: clustering of the attended pixels and population-coded motion.

Implements SPEC.md section 1 item 10 (paper eqs. 30-32) with the cluster direction ruling
``direction = atan2(V_Y, V_X)`` in image coordinates (x right, y down, so a positive angle turns
clockwise on screen).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

__all__ = ["Target", "dbscan_grid", "extract_targets"]


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
        Number of pixels in the cluster.
    """

    x: float
    y: float
    direction: float
    energy: float
    pixels: int

    def to_dict(self) -> dict:
        return {"x": self.x, "y": self.y, "direction": self.direction, "energy": self.energy,
                "pixels": self.pixels}


def _disk(eps: float) -> np.ndarray:
    r = int(np.floor(eps))
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    return ((x * x + y * y) <= eps * eps).astype(np.float32)


def dbscan_grid(mask: np.ndarray, eps: float, min_samples: int,
                seed: tuple[int, int] | None = None) -> tuple[np.ndarray, bool, int]:
    """DBSCAN of the set pixels of a binary mask, with scikit-learn's semantics.

    A pixel is a core sample when at least ``min_samples`` points (itself included) lie within
    Euclidean distance ``eps``; core samples within ``eps`` of each other share a cluster.
    Clusters are numbered in the order of their first core sample in row-major order, as
    ``sklearn.cluster.DBSCAN`` numbers them when given the pixels in that order. The search uses
    the grid: 8-connected core pixels are joined directly, and only the boundary pixels of the
    resulting components are compared in a k-d tree (the closest pair of two pixel sets always
    lies on their boundaries).

    Parameters
    ----------
    mask : ndarray of bool (H, W)
    eps : float
    min_samples : int
    seed : (row, col), optional
        An extra point appended after the pixels (the published implementation adds (0, 0)).

    Returns
    -------
    labels : ndarray of int (H, W)
        Cluster number of each *core* pixel, -1 elsewhere.
    seed_core : bool
        Whether the seed point is a core sample.
    seed_label : int
        The seed's cluster when it is a core sample, else -1.
    """
    h, w = mask.shape
    disk = _disk(eps)
    counts = cv2.filter2D(mask.astype(np.float32), cv2.CV_32F, disk,
                          borderType=cv2.BORDER_CONSTANT)
    seed_count = 0
    if seed is not None:
        near_seed = np.zeros((h, w), np.float32)
        near_seed[seed] = 1.0
        near_seed = cv2.filter2D(near_seed, cv2.CV_32F, disk, borderType=cv2.BORDER_CONSTANT)
        counts += near_seed
        seed_count = 1 + int(round(float(counts[seed] - near_seed[seed])))  # itself + pixels
    core = mask & (counts >= min_samples - 0.5)
    seed_core = seed is not None and seed_count >= min_samples

    n_comp, comp = cv2.connectedComponents(core.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    labels = np.full((h, w), -1, dtype=np.int64)
    if n_comp <= 1:
        return labels, seed_core, -1
    comp = comp.astype(np.int64) - 1  # background -> -1, components 0..n_comp-2
    n = n_comp - 1

    # Merge components whose boundary pixels lie within eps of each other.
    interior = cv2.erode(core.view(np.uint8), cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3)),
                         borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
    rows, cols = np.nonzero(core & ~interior)
    edges_a, edges_b = [], []
    if n > 1:
        points = np.column_stack([rows, cols]).astype(np.float64)
        pairs = cKDTree(points).query_pairs(eps + 1e-9, output_type="ndarray")
        if len(pairs):
            ca, cb = comp[rows[pairs[:, 0]], cols[pairs[:, 0]]], comp[rows[pairs[:, 1]], cols[pairs[:, 1]]]
            keep = ca != cb
            edges_a.append(ca[keep])
            edges_b.append(cb[keep])
    if seed_core:
        # the seed links every core pixel within eps of it
        sr, sc = seed
        r = int(np.floor(eps))
        window = core[max(sr - r, 0):sr + r + 1, max(sc - r, 0):sc + r + 1]
        wr, wc = np.nonzero(window)
        wr, wc = wr + max(sr - r, 0), wc + max(sc - r, 0)
        close = (wr - sr) ** 2 + (wc - sc) ** 2 <= eps * eps
        linked = np.unique(comp[wr[close], wc[close]])
        if len(linked) > 1:
            edges_a.append(np.full(len(linked) - 1, linked[0]))
            edges_b.append(linked[1:])
    if edges_a:
        a, b = np.concatenate(edges_a), np.concatenate(edges_b)
        graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
        _, merged = connected_components(graph, directed=False)
    else:
        merged = np.arange(n)

    # Renumber clusters by their first core pixel in row-major order.
    flat = comp.ravel()
    core_idx = np.flatnonzero(flat >= 0)
    cluster_of_pixel = merged[flat[core_idx]]
    first = np.full(merged.max() + 1, np.iinfo(np.int64).max)
    np.minimum.at(first, cluster_of_pixel, core_idx)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    labels.ravel()[core_idx] = rank[cluster_of_pixel]

    seed_label = -1
    if seed_core:
        sr, sc = seed
        r = int(np.floor(eps))
        sub = labels[max(sr - r, 0):sr + r + 1, max(sc - r, 0):sc + r + 1]
        seed_label = int(sub.max())  # all linked core pixels share one label after merging
    return labels, seed_core, seed_label


def extract_targets(mask: np.ndarray, dx: np.ndarray | None, dy: np.ndarray | None, eps: float,
                    min_samples: int, origin_seed: bool = False, *,
                    vectors: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
                    | None = None) -> list[Target]:
    """Targets of the attended pixels ``M_a M_d = 1`` (paper eqs. 30-32).

    Parameters
    ----------
    mask : ndarray of bool (H, W)
        ``M_a M_d``.
    dx, dy : ndarray (H, W) or None
        Motion vector per pixel, ``V cos(phi)`` and ``V sin(phi)`` (eq. 30).
    eps, min_samples : DBSCAN parameters.
    vectors : callable, optional
        Instead of ``dx`` and ``dy``: ``vectors(rows, cols) -> (dx, dy)`` at the given pixels,
        so that the motion vectors are computed for the core samples only.
    origin_seed : bool
        Add the point (0, 0) and drop clusters centred within 1 px of it (published variant).

    Returns
    -------
    list of Target, in cluster order; centre and motion are means over the core samples.
    """
    if not mask.any():
        return []
    seed = (0, 0) if origin_seed else None
    labels, seed_core, seed_label = dbscan_grid(mask, eps, min_samples, seed)
    core = labels >= 0
    if not core.any():
        return []
    lab = labels[core]
    rows, cols = np.nonzero(core)
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
    n = int(lab.max()) + 1
    count = np.bincount(lab, minlength=n).astype(np.float64)
    sum_x = np.bincount(lab, cols, n)
    sum_y = np.bincount(lab, rows, n)
    sum_dx = np.bincount(lab, vx, n)
    sum_dy = np.bincount(lab, vy, n)
    if seed_core:
        count[seed_label] += 1
        sum_dx[seed_label] += vx0
        sum_dy[seed_label] += vy0
    targets = []
    for k in range(n):
        cx, cy = sum_x[k] / count[k], sum_y[k] / count[k]
        if origin_seed and cx * cx + cy * cy <= 1.0:
            continue
        vx, vy = sum_dx[k] / count[k], sum_dy[k] / count[k]
        targets.append(Target(x=float(cx), y=float(cy),
                              direction=float(np.arctan2(vy, vx)),
                              energy=float(np.hypot(vx, vy)), pixels=int(count[k])))
    return targets
