"""Fused kernels of the optimised ASNN step (private; used by :class:`asnn.model.ASNN`).

Why a second module
-------------------
:mod:`asnn.retina` states every equation of the paper once, in its straightforward form: OpenCV
2-D correlations and NumPy expressions on float64 arrays, one stage at a time. That form is the
definition; ``ASNN(params, optimised=False)`` runs it, ``asnn bench`` times it, and the
equivalence tests (``tests/test_equivalence.py``) compare this module against it.

The functions here compute the same equations with fewer operations and fewer passes over
memory. They define nothing new: every kernel they use is built by the retina functions or is a
factor of one (:func:`dog_factors` of :func:`~asnn.retina.dog_kernel`, :func:`gabor_factors` of
:func:`~asnn.retina.gabor_pair`, :func:`cs_classes` of
:func:`~asnn.retina.center_surround_kernel`), and each function names the retina functions
whose results it reproduces. What changes is only the order of the arithmetic:

* One pass, row by row. :func:`front` runs rectification, the difference of Gaussians, the
  leaky-integrator cascade, the Gabor pairs, centre-surround inhibition, the approach map and
  grouping as a pipeline over the rows of the frame: row y enters the cascade while row y - 2
  leaves the 5x5 filters and row y - 3 the grouping, so the intermediate rows live in small
  ring buffers that stay in the CPU cache. Only the cascades (the state), R^theta, V and G are
  whole images.
* Separability. g_I is a difference of two Gaussians, two separable kernels. On the [-1, 1]
  grid, the Gabor pair of orientation theta is one complex kernel,
  ``g^0 + i g^{pi/2} = e(y) e(x) exp(i a (x cos theta + y sin theta))``, with ``e`` the 1-D
  Gaussian envelope and ``a = 2 pi / lambda``: the product of a row kernel
  ``e(x) exp(i a cos(theta) x)`` and a column kernel ``e(y) exp(i a sin(theta) y)``. For the
  four orientations k pi / 4, five real column passes and eight real row passes replace 8
  two-dimensional 5x5 correlations per image (theta = pi/4 and 3 pi/4 share their passes:
  their column kernels are equal, their row kernels complex conjugates). The column passes
  come first, on the read-out rows that the cascade has just produced, so that the passes of
  one output row only touch a few rows held in the L1 cache.
  ``E = A1 B2 - A2 B1 = Im(conj(Z_slow) Z_fast)``.
* Symmetry. The 5-tap kernels are symmetric or antisymmetric, and g_CS is radially symmetric
  (six distinct weights): pairs are added before they are multiplied.
* Differences. The temporal read-outs are differences of nearly equal integrator stages. The
  cascade keeps its first integrating stage and the differences of consecutive stages instead
  of the stages (:func:`to_differences`); they obey the same recursion, and the read-outs need
  no subtraction.
* Precision. Maps and cascades have the dtype of the preset's ``precision`` (float64 for
  ``reference``, whose outputs must match the published implementation; float32 elsewhere,
  within 1e-5 relative of float64 on u(t), ``tests/test_equivalence.py``; that needs the
  difference form: stages kept in float32 lose up to 1e-5 on their own).
* Less work where nothing is attended. The direction attention M_d is only needed where M_a is
  set: :func:`attention` blurs V' only in M_a's bounding box (plus the blur's radius), and not
  at all when M_a is empty. With the attention blur on a grid twice coarser (the robust
  preset), V' goes straight onto that grid: :func:`_v_prime_halved` takes the 2x2 averages in
  the order OpenCV's INTER_AREA does, so the blur is the same.
* Bands. :func:`front` can compute any band of rows on its own: it advances the band's rows of
  the cascades from one pair of arrays into another, and the few rows beyond the band that its
  filters read into scratch rows that it drops. Every pixel is computed the same way whatever
  the bands, so bands computed on threads of their own (:mod:`asnn._parallel`) give the maps
  of one pass, bit for bit; the column sums of R^theta are completed band after band in row
  order (:func:`add_column_sums`) for the same reason.

The fused kernels are written for the 5x5 kernels of Table I (every preset); other sizes fall
back to the straightforward functions (:func:`supported`). Numba compiles them on first use and
caches the machine code next to this file (or in ``NUMBA_CACHE_DIR``; without a writable place,
it compiles at first use, see :mod:`asnn._jit`); no ``fastmath``, so
IEEE semantics are kept and float64 results differ from the straightforward form only by
rounding (about 1e-15 relative). The kernels release the GIL (``nogil``) and use no threads
of their own: a model with ``threads`` > 1 runs them on its worker threads
(:mod:`asnn._parallel`), any other model on the thread that steps it.

Scratch arrays live in per-thread :class:`Workspace` and :class:`Scratch` objects shared by all
models of that thread, so a camera's own state is only its cascades and its previous frame (a
model with threads of its own keeps its maps and a second pair of cascades as well).
"""

from __future__ import annotations

import functools
import math
import threading
from typing import NamedTuple

import cv2
import numpy as np

from . import retina
from ._jit import kernel

__all__ = ["supported", "dog_factors", "gabor_factors", "cs_classes", "Scratch", "FrontMaps",
           "Workspace", "workspace", "scratch", "FrontCoefficients", "front", "add_column_sums",
           "to_differences", "shrunk_luminance", "contrast_gain_control",
           "gain_controlled_change", "attention", "AttentionBlur", "MotionVectors",
           "motion_vectors", "block_means"]

RADIUS = 2  # the fused kernels are written for 5x5 kernels (Table I)
DEPTH = 2 * RADIUS + 1  # rows kept by the ring buffers of the 5x5 filters

# (excitation, inhibitor) read-outs of the four approach terms, in the order of
# retina.approach_map; read-outs are numbered fast_on, slow_on, fast_off, slow_off
_TERMS = np.array([[1, 2], [2, 1], [3, 0], [0, 3]], np.int64)

_jit = dict(boundscheck=False)
_TINY = 1e-18  # float32 cascade values below this are flushed to 0: their products stay normal


def supported(params) -> bool:
    """Whether the fused kernels apply to a parameter set (5x5 g_I, g_DS, g_CS)."""
    return params.dog_size == DEPTH and params.kernel_size == DEPTH


def dog_factors(gain: float, sigma1: float, sigma2: float, size: int,
                normalisation: str = "paper") -> tuple[np.ndarray, np.ndarray]:
    """Separable factors of :func:`asnn.retina.dog_kernel`.

    Returns
    -------
    envelopes : ndarray (2, size)
        ``exp(-t^2 / (2 sigma_i^2))`` on the integer offsets t.
    scales : ndarray (2,)
        ``F / norm_1`` and ``F / norm_2``: the kernel is
        ``scales[0] outer(e1, e1) - scales[1] outer(e2, e2)``.
    """
    t = np.arange(size, dtype=np.float64) - size // 2
    norm1, norm2 = retina.dog_norms(sigma1, sigma2, normalisation)
    envelopes = np.array([np.exp(-t * t / (2 * sigma1**2)), np.exp(-t * t / (2 * sigma2**2))])
    return envelopes, np.array([gain / norm1, gain / norm2])


def gabor_factors(sigma: float, wavelength: float, size: int, extent: float = 1.0) -> np.ndarray:
    """1-D factors of the Gabor pairs at theta = k pi / 4, k = 0..3 (see the module notes).

    Returns
    -------
    ndarray (5, size)
        ``e``, ``e cos(a t)``, ``e sin(a t)``, ``e cos(b t)``, ``e sin(b t)`` on the sample
        coordinates t of :func:`asnn.retina.gabor_pair`, with ``e = exp(-t^2 / (2 sigma^2))``,
        ``a = 2 pi / lambda`` and ``b = a cos(pi / 4)``. Symmetric, symmetric, antisymmetric,
        symmetric, antisymmetric. Orientation k's complex kernel is ``col_k (x) row_k`` with
        rows (ca + i sa, cb + i sb, e, cb - i sb) and columns (e, Cb + i Sb, Ca + i Sa, Cb + i Sb).
    """
    t = np.linspace(-extent, extent, size)
    e = np.exp(-t * t / (2 * sigma**2))
    a = 2 * math.pi / wavelength
    b = a * math.cos(math.pi / 4)
    return np.array([e, e * np.cos(a * t), e * np.sin(a * t), e * np.cos(b * t), e * np.sin(b * t)])


def cs_classes(kernel: np.ndarray) -> np.ndarray:
    """The distinct weights of a radially symmetric 5x5 kernel: ``out[|dy|, |dx|]`` (3, 3)."""
    if kernel.shape != (DEPTH, DEPTH) or not (
            np.array_equal(kernel, kernel[::-1]) and np.array_equal(kernel, kernel[:, ::-1])):
        raise ValueError("the fused centre-surround filter needs a symmetric 5x5 kernel")
    return np.ascontiguousarray(kernel[RADIUS:, RADIUS:])


# --------------------------------------------------------------------------- workspace


class Scratch:
    """The ring buffers of one pass of :func:`front` over a band of rows (a few rows each)."""

    def __init__(self, width: int, dtype: np.dtype):
        w, pw = width, width + 2 * RADIUS
        self.col = np.empty((4, pw), dtype)  # vertical g_I passes of B+ and B- (two Gaussians)
        self.x0 = np.empty((2, w), dtype)  # B+^0, B-^0 of one row
        self.ro = np.empty((4, DEPTH, pw), dtype)  # read-outs: fast_on, slow_on, fast_off, slow_off
        self.gabor = np.empty((2, 5, pw), dtype)  # five Gabor column passes of slow and fast
        self.acc = np.empty((2, 8, w), dtype)  # Z^theta parts of one channel's slow and fast
        self.csl = np.empty((2, pw), dtype)  # vertical pairs of the centre-surround filter
        self.gring = np.empty((3, w + 2), dtype)  # G before grouping
        self.gline = np.empty(w + 2, dtype)
        self.done = np.zeros(1, np.int64)  # front()'s flag when no one waits for it
        self._in_place: np.ndarray | None = None  # made for the first frame height asked
        self._spare: tuple[np.ndarray, np.ndarray] | None = None

    def buffers(self) -> tuple:
        return self.col, self.x0, self.ro, self.gabor, self.acc, self.csl, self.gring, self.gline

    def in_place(self, height: int) -> np.ndarray:
        """Zeros for every row: the versions of :func:`front` in place."""
        if self._in_place is None or len(self._in_place) != height:
            self._in_place = np.zeros(height, np.int8)
        return self._in_place

    def spare(self, depth: int) -> tuple[np.ndarray, np.ndarray]:
        """One row of each cascade (``depth`` stages), for rows advanced and dropped."""
        if self._spare is None or self._spare[0].shape[0] != depth:
            self._spare = (np.zeros((depth, 1, self.x0.shape[1]), self.x0.dtype),
                           np.zeros((depth, 1, self.x0.shape[1]), self.x0.dtype))
        return self._spare


class FrontMaps:
    """What :func:`front` computes for one frame."""

    def __init__(self, shape: tuple[int, int], dtype: np.dtype):
        h, w = self.shape = shape
        self.r = np.empty((4, h, w), dtype)  # R^theta, theta = k pi / 4, k = 0..3
        self.v = np.empty((h, w), dtype)
        self.g = np.empty((h, w), dtype)
        self.colsum = np.empty((4, w), np.float64)  # column sums of R^theta

    def sums(self) -> np.ndarray:
        """The sums of R^theta (float64)."""
        return self.colsum.sum(axis=1)

    @classmethod
    def slots(cls, n: int, shape: tuple[int, int], dtype: np.dtype
              ) -> tuple[list["FrontMaps"], tuple[np.ndarray, ...]]:
        """``n`` maps that are the slices of four stacked arrays, and those arrays
        (``r``, ``v``, ``g``, ``colsum``, each with a first axis of ``n``): a kernel given the
        stacks reaches every slot."""
        h, w = shape
        stacked = (np.empty((n, 4, h, w), dtype), np.empty((n, h, w), dtype),
                   np.empty((n, h, w), dtype), np.empty((n, 4, w), np.float64))
        maps = []
        for k in range(n):
            m = cls.__new__(cls)
            m.shape = shape
            m.r, m.v, m.g, m.colsum = (a[k] for a in stacked)
            maps.append(m)
        return maps, stacked


class Workspace:
    """Outputs and scratch arrays for one frame size and dtype, reused from frame to frame."""

    def __init__(self, shape: tuple[int, int], dtype: np.dtype):
        h, w = shape
        self.shape, self.dtype = shape, dtype
        self.attended_sums = np.empty(w, np.float64)  # column sums of G M_a M_d
        self.v_prime = np.empty((h, w), dtype)
        self.mask = np.zeros((h, w), np.bool_)
        self.rows = np.empty(h * w, np.int64)  # the attended pixels
        self.cols = np.empty(h * w, np.int64)

    @functools.cached_property
    def maps(self) -> FrontMaps:
        """Outputs of :func:`front` (models that keep their own do not need these)."""
        return FrontMaps(self.shape, self.dtype)


_local = threading.local()


def _cached(name: str, key, make):
    """This thread's object ``make()`` for a key, of the last few kept under ``name``."""
    cache = getattr(_local, name, None)
    if cache is None:
        cache = {}
        setattr(_local, name, cache)
    value = cache.get(key)
    if value is None:
        if len(cache) >= 4:
            cache.pop(next(iter(cache)))
        value = cache[key] = make()
    return value


def workspace(shape: tuple[int, int], dtype) -> Workspace:
    """This thread's workspace for a frame size and dtype (the last few are kept)."""
    dtype = np.dtype(dtype)
    return _cached("workspaces", (shape, dtype.str), lambda: Workspace(shape, dtype))


def scratch(width: int, dtype) -> Scratch:
    """This thread's ring buffers of :func:`front` for a frame width and dtype."""
    dtype = np.dtype(dtype)
    return _cached("scratch", (width, dtype.str), lambda: Scratch(width, dtype))


# --------------------------------------------------------------------------- helpers


@kernel(inline="always", **_jit)
def _reflect(i, n):
    """Reflect-101 index (OpenCV's default border) for |overshoot| < n, or 0 for n = 1 (a
    looming fit's box shrunk to one pixel across)."""
    if n == 1:
        return 0
    if i < 0:
        return -i
    if i >= n:
        return 2 * n - 2 - i
    return i


@kernel(inline="always", **_jit)
def _pad(line, w, r):
    """Fill the r-wide reflect-101 borders of a padded line whose middle holds w values."""
    for k in range(1, r + 1):
        line[r - k] = line[r + k]
        line[r + w - 1 + k] = line[r + w - 1 - k]


# --------------------------------------------------------------------------- stage 1: row y


@kernel(inline="always", **_jit)
def _dog_row(p, y, env, sc, zero, col, on, off):
    """B+^0 and B-^0 of row y (eqs. 2-4, :func:`~asnn.retina.bipolar`): relu(+-P) (*) g_I
    with g_I = s1 e1 e1' - s2 e2 e2'."""
    h, w = p.shape
    a0, a1, b1 = p[y], p[_reflect(y - 1, h)], p[_reflect(y + 1, h)]
    a2, b2 = p[_reflect(y - 2, h)], p[_reflect(y + 2, h)]
    # the vertical passes of relu(P) and relu(-P) with e1 and e2, in one loop that loads the
    # five rows once
    p1, p2, n1, n2 = col[0], col[1], col[2], col[3]
    e10, e11, e12 = env[0, 2], env[0, 3], env[0, 4]
    e20, e21, e22 = env[1, 2], env[1, 3], env[1, 4]
    for x in range(w):
        u0, u1, v1, u2, v2 = a0[x], a1[x], b1[x], a2[x], b2[x]
        m0, m1, m2 = max(u0, zero), max(u1, zero) + max(v1, zero), max(u2, zero) + max(v2, zero)
        p1[x + 2] = e10 * m0 + e11 * m1 + e12 * m2
        p2[x + 2] = e20 * m0 + e21 * m1 + e22 * m2
        m0, m1 = max(-u0, zero), max(-u1, zero) + max(-v1, zero)
        m2 = max(-u2, zero) + max(-v2, zero)
        n1[x + 2] = e10 * m0 + e11 * m1 + e12 * m2
        n2[x + 2] = e20 * m0 + e21 * m1 + e22 * m2
    for m in range(4):
        _pad(col[m], w, 2)
    e1, e2 = env[0], env[1]
    s1, s2 = sc[0], sc[1]
    for ch in range(2):
        c1, c2 = col[2 * ch], col[2 * ch + 1]
        out = on if ch == 0 else off
        for x in range(w):
            out[x] = s1 * (e1[2] * c1[x + 2] + e1[3] * (c1[x + 1] + c1[x + 3])
                           + e1[4] * (c1[x] + c1[x + 4])) \
                - s2 * (e2[2] * c2[x + 2] + e2[3] * (c2[x + 1] + c2[x + 3])
                        + e2[4] * (c2[x] + c2[x + 4]))


@kernel(inline="always", **_jit)
def _cascade_row(old, y_old, new, y_new, x0, a, b, e_x, j, line, tiny):
    """One frame of the cascade (eq. 5, :func:`~asnn.retina.temporal_filter_step`) at a row,
    in difference form (see :func:`to_differences`):
    row ``y_old`` of the stages ``old`` advanced into row ``y_new`` of ``new`` (the same
    array and row to advance in place).

    With ``a = 1 - r A``, ``b = r C`` and z'_{j-1} = B^0 (z_{j-1} = the input), every stage
    is ``z'_i = a z_i + b z'_{i-1}``, so the differences ``d_i = z_i - z_{i+1}`` follow the
    same recursion, ``d'_i = a d_i + b d'_{i-1}``, started by
    ``d'_{j-1} = B^0 - z'_j = a (B^0 - z_j) + (r A - r C) B^0``. The read-outs are ``K d_n``
    (:func:`_readout_row`).
    Stored values below ``tiny`` in magnitude become 0: where the picture stands still the
    stages decay geometrically, and in float32 they would pass through the subnormal numbers,
    which some CPUs compute many times slower.
    """
    w = old.shape[2]
    s, s_new = old[j, y_old], new[j, y_new]
    if e_x == 0:
        for x in range(w):
            line[x] = a * (x0[x] - s[x])
    else:
        for x in range(w):
            line[x] = a * (x0[x] - s[x]) + e_x * x0[x]
    # in place, the loops write what they read: written as such, they vectorise (rows that may
    # overlap would make the vectoriser check, and fall back to one value at a time)
    in_place = s_new.ctypes.data == s.ctypes.data
    if in_place:
        for x in range(w):
            v = a * s[x] + b * x0[x]
            s[x] = v if abs(v) >= tiny else v - v
    else:
        for x in range(w):
            v = a * s[x] + b * x0[x]
            s_new[x] = v if abs(v) >= tiny else v - v
    prev = line
    for i in range(j, old.shape[0] - 1):
        d, d_new = old[i + 1, y_old], new[i + 1, y_new]
        if in_place:
            for x in range(w):
                v = a * d[x] + b * prev[x]
                d[x] = v if abs(v) >= tiny else v - v
            prev = d
        else:
            for x in range(w):
                v = a * d[x] + b * prev[x]
                d_new[x] = v if abs(v) >= tiny else v - v
            prev = d_new


@kernel(inline="always", **_jit)
def _readout_row(stages, y, gain, n_fast, n_slow, fast, slow):
    """The fast and slow read-outs ``K d_n`` of row y of an advanced cascade, padded (eqs. 6,
    7, :func:`~asnn.retina.temporal_readout`)."""
    w = stages.shape[2]
    df, ds = stages[n_fast + 1, y], stages[n_slow + 1, y]
    for x in range(w):
        fast[x + 2] = gain * df[x]
    for x in range(w):
        slow[x + 2] = gain * ds[x]
    _pad(fast, w, 2)
    _pad(slow, w, 2)


@kernel(inline="always", **_jit)
def _advance_row(p, y, env, sc, zero, swap, old_on, old_off, y_old, new_on, new_off, y_new, a,
                 b, e_x, j, tiny, col, x0, line):
    """Row y of both cascades advanced by one frame of P (see :func:`_cascade_row`)."""
    if swap:
        _dog_row(p, y, env, sc, zero, col, x0[1], x0[0])
    else:
        _dog_row(p, y, env, sc, zero, col, x0[0], x0[1])
    _cascade_row(old_on, y_old, new_on, y_new, x0[0], a, b, e_x, j, line, tiny)
    _cascade_row(old_off, y_old, new_off, y_new, x0[1], a, b, e_x, j, line, tiny)


# --------------------------------------------------------------------------- stage 2: row y - 2


@kernel(inline="always", **_jit)
def _gabor_columns(src, s0, sm1, sp1, sm2, sp2, k, out):
    """The five Gabor column passes of one read-out row (``e``, ``Ca``, ``Sa``, ``Cb``,
    ``Sb``: symmetric, symmetric, antisymmetric, symmetric, antisymmetric) in one loop, which
    loads the five rows once. Each output is ``c0 a0 + c1 (b1 + a1) + c2 (b2 + a2)``, or
    ``c1 (b1 - a1) + c2 (b2 - a2)``, as one pass per kernel computes it."""
    a0, a1, b1, a2, b2 = src[s0], src[sm1], src[sp1], src[sm2], src[sp2]
    e, ca, sa, cb, sb = out[0], out[1], out[2], out[3], out[4]
    e0, e1, e2 = k[0, 2], k[0, 3], k[0, 4]
    ca0, ca1, ca2 = k[1, 2], k[1, 3], k[1, 4]
    sa1, sa2 = k[2, 3], k[2, 4]
    cb0, cb1, cb2 = k[3, 2], k[3, 3], k[3, 4]
    sb1, sb2 = k[4, 3], k[4, 4]
    for x in range(e.shape[0]):
        m = a0[x]
        s1, s2 = b1[x] + a1[x], b2[x] + a2[x]
        d1, d2 = b1[x] - a1[x], b2[x] - a2[x]
        e[x] = e0 * m + e1 * s1 + e2 * s2
        ca[x] = ca0 * m + ca1 * s1 + ca2 * s2
        sa[x] = sa1 * d1 + sa2 * d2
        cb[x] = cb0 * m + cb1 * s1 + cb2 * s2
        sb[x] = sb1 * d1 + sb2 * d2


@kernel(inline="always", **_jit)
def _gabor_rows(c, k, a):
    """The eight Gabor row passes of the five column passes ``c`` into ``a``, in two loops:
    Re, Im Z^0 = e (x) (ca, sa) and Re, Im Z^{pi/2} = (Ca, Sa) (x) e; then Cb (x) (cb, sb) and
    Sb (x) (cb, sb) into (a[4], a[7]) and (a[5], a[6]). Each is
    ``c0 l2 + c1 (l3 + l1) + c2 (l4 + l0)`` or ``c1 (l3 - l1) + c2 (l4 - l0)``, as one pass per
    output computes it. (One loop for all eight stops vectorising: LLVM gives up on the
    runtime checks that its rows do not overlap; one per pass loads each line again.)"""
    e0, e1, e2 = k[0, 2], k[0, 3], k[0, 4]
    ca0, ca1, ca2 = k[1, 2], k[1, 3], k[1, 4]
    sa1, sa2 = k[2, 3], k[2, 4]
    cb0, cb1, cb2 = k[3, 2], k[3, 3], k[3, 4]
    sb1, sb2 = k[4, 3], k[4, 4]
    le, lca, lsa, lcb, lsb = c[0], c[1], c[2], c[3], c[4]
    a0, a1, a2, a3, a4, a5, a6, a7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    for x in range(a0.shape[0]):
        l0, l1, l2, l3, l4 = le[x], le[x + 1], le[x + 2], le[x + 3], le[x + 4]
        a0[x] = ca0 * l2 + ca1 * (l3 + l1) + ca2 * (l4 + l0)
        a1[x] = sa1 * (l3 - l1) + sa2 * (l4 - l0)
        a2[x] = e0 * lca[x + 2] + e1 * (lca[x + 3] + lca[x + 1]) + e2 * (lca[x + 4] + lca[x])
        a3[x] = e0 * lsa[x + 2] + e1 * (lsa[x + 3] + lsa[x + 1]) + e2 * (lsa[x + 4] + lsa[x])
    for x in range(a0.shape[0]):
        l0, l1, l2, l3, l4 = lcb[x], lcb[x + 1], lcb[x + 2], lcb[x + 3], lcb[x + 4]
        a4[x] = cb0 * l2 + cb1 * (l3 + l1) + cb2 * (l4 + l0)
        a7[x] = sb1 * (l3 - l1) + sb2 * (l4 - l0)
        l0, l1, l2, l3, l4 = lsb[x], lsb[x + 1], lsb[x + 2], lsb[x + 3], lsb[x + 4]
        a5[x] = cb0 * l2 + cb1 * (l3 + l1) + cb2 * (l4 + l0)
        a6[x] = sb1 * (l3 - l1) + sb2 * (l4 - l0)


@kernel(inline="always", **_jit)
def _gabor_channel(ro, slow, fast, s0, sm1, sp1, sm2, sp2, k, weight, first, gabor, acc,
                   r0, r1, r2, r3):
    """One channel's ``weight E^theta`` at one row, set (``first``) or added into R^theta
    (eqs. 10, 15, 16, :func:`~asnn.retina.motion_energy`).

    Column passes first, over the padded read-out rows of the ring (so their output keeps the
    padding), then the row passes: every buffer involved is a few rows long and stays in the L1
    cache.
    """
    for im in range(2):
        src = ro[slow] if im == 0 else ro[fast]
        c, a = gabor[im], acc[im]
        _gabor_columns(src, s0, sm1, sp1, sm2, sp2, k, c)  # e, Ca, Sa, Cb, Sb
        _gabor_rows(c, k, a)
    w = r0.shape[0]
    s, f = acc[0], acc[1]
    # E = Re Z_slow Im Z_fast - Re Z_fast Im Z_slow, with (a[4], a[5], a[6], a[7]) =
    # (Cb cb, Sb cb, Sb sb, Cb sb): Z^{pi/4} = (cb Cb - sb Sb) + i (cb Sb + sb Cb) and
    # Z^{3 pi/4} = (cb Cb + sb Sb) + i (cb Sb - sb Cb)
    s0_, s1_, s2_, s3_ = s[0], s[1], s[2], s[3]
    f0_, f1_, f2_, f3_ = f[0], f[1], f[2], f[3]
    scc, scs, sss, ssc = s[4], s[5], s[6], s[7]
    fcc, fcs, fss, fsc = f[4], f[5], f[6], f[7]
    if first:
        for x in range(w):
            r0[x] = weight * (s0_[x] * f1_[x] - f0_[x] * s1_[x])
            r2[x] = weight * (s2_[x] * f3_[x] - f2_[x] * s3_[x])
        for x in range(w):
            r1[x] = weight * ((scc[x] - sss[x]) * (fcs[x] + fsc[x])
                              - (fcc[x] - fss[x]) * (scs[x] + ssc[x]))
            r3[x] = weight * ((scc[x] + sss[x]) * (fcs[x] - fsc[x])
                              - (fcc[x] + fss[x]) * (scs[x] - ssc[x]))
    else:
        for x in range(w):
            r0[x] += weight * (s0_[x] * f1_[x] - f0_[x] * s1_[x])
            r2[x] += weight * (s2_[x] * f3_[x] - f2_[x] * s3_[x])
        for x in range(w):
            r1[x] += weight * ((scc[x] - sss[x]) * (fcs[x] + fsc[x])
                               - (fcc[x] - fss[x]) * (scs[x] + ssc[x]))
            r3[x] += weight * ((scc[x] + sss[x]) * (fcs[x] - fsc[x])
                               - (fcc[x] + fss[x]) * (scs[x] - ssc[x]))


@kernel(inline="always", **_jit)
def _approach_row(ro, s0, sm1, sp1, sm2, sp2, kc, weights, terms, zero, csl, gl):
    """G of one row, ``sum_i weight_i relu(relu(ex_i) - relu(inh_i (*) g_CS))``, into gl[1:w+1]
    (eqs. 12-14, 19, 20, :func:`~asnn.retina.approach_map`)."""
    w = gl.shape[0] - 2
    first = True
    for t in range(4):
        wt = weights[t]
        if wt == 0:
            continue
        ex, inh = ro[terms[t, 0], s0], ro[terms[t, 1]]
        c0 = inh[s0]
        u1, d1, u2, d2 = inh[sm1], inh[sp1], inh[sm2], inh[sp2]
        c1, c2 = csl[0], csl[1]
        for x in range(w + 4):
            c1[x] = u1[x] + d1[x]
            c2[x] = u2[x] + d2[x]
        k00, k01, k02 = kc[0, 0], kc[0, 1], kc[0, 2]
        k10, k11, k12 = kc[1, 0], kc[1, 1], kc[1, 2]
        k20, k21, k22 = kc[2, 0], kc[2, 1], kc[2, 2]
        for x in range(w):
            s = (k00 * c0[x + 2] + k01 * (c0[x + 1] + c0[x + 3]) + k02 * (c0[x] + c0[x + 4])) \
                + (k10 * c1[x + 2] + k11 * (c1[x + 1] + c1[x + 3]) + k12 * (c1[x] + c1[x + 4])) \
                + (k20 * c2[x + 2] + k21 * (c2[x + 1] + c2[x + 3]) + k22 * (c2[x] + c2[x + 4]))
            term = max(max(ex[x + 2], zero) - max(s, zero), zero)
            if first:
                gl[x + 1] = zero + wt * term
            else:
                gl[x + 1] += wt * term
        first = False
    if first:
        for x in range(w + 2):
            gl[x] = zero
    _pad(gl, w, 1)


@kernel(inline="always", **_jit)
def _group_row(a, b, c, ninth, line, out):
    """``G (G (*) ones(3, 3) / 9)`` of one row from the padded rows above, at and below it
    (the published implementation's grouping, :func:`~asnn.retina.group`)."""
    w = out.shape[0]
    for x in range(w + 2):
        line[x] = a[x] + b[x] + c[x]
    for x in range(w):
        out[x] = b[x + 1] * ((line[x] + line[x + 1] + line[x + 2]) * ninth)


@kernel(**_jit)
def _front(p, env, sc, stages_on, stages_off, other_on, other_off, read, write, a, b, e_x, j,
           gain, n_fast, n_slow, swap, gk, vw, kc, aw, terms, grouping, zero, tiny, ninth, col, x0,
           ro, gabor, acc, csl, gring, gline, spare_on, spare_off, r, v, g, colsum, y0, y1, sums,
           done):
    """Rows [y0, y1) of R, V and G. Cascade row y is read from the ``stages`` or the
    ``other`` arrays (``read[y]`` 0 or 1) and, for the rows [y0, y1), advanced into those
    ``write[y]`` says (in place where they are the same); the rows beyond the band that the
    filters read are advanced into the spare rows and dropped. ``done[0]`` is set to 1 at the
    end (another thread can see that without the GIL)."""
    h, w = p.shape
    if sums:
        for k in range(4):
            for x in range(w):
                colsum[k, x] = 0.0
    # G is needed one row beyond the band for the grouping; the 5x5 filters read two more
    g0, g1 = (max(y0 - 1, 0), min(y1 + 1, h)) if grouping else (y0, y1)
    t0, t1 = max(g0 - RADIUS, 0), min(g1 + RADIUS, h)
    for t in range(t0, y1 + RADIUS + 1):
        if t < t1:  # stage 1: row t through g_I and the cascade, into the ring
            slot = t % DEPTH
            old_on, old_off = (stages_on, stages_off) if read[t] == 0 else (other_on, other_off)
            if y0 <= t < y1:
                new_on, new_off = (stages_on, stages_off) if write[t] == 0 else \
                    (other_on, other_off)
                y_new = t
            else:
                new_on, new_off, y_new = spare_on, spare_off, 0
            # one call site each: numba copies an inlined function into every call site, and
            # the two copies of this stage made this kernel the slowest of all to compile
            _advance_row(p, t, env, sc, zero, swap, old_on, old_off, t, new_on, new_off, y_new,
                         a, b, e_x, j, tiny, col, x0, csl[0])
            for ch in range(2):
                _readout_row(new_on if ch == 0 else new_off, y_new, gain, n_fast, n_slow,
                             ro[2 * ch, slot], ro[2 * ch + 1, slot])
        y = t - RADIUS
        if g0 <= y < g1:  # stage 2: row t - 2 through the 5x5 filters
            s0 = y % DEPTH
            sm1, sp1 = _reflect(y - 1, h) % DEPTH, _reflect(y + 1, h) % DEPTH
            sm2, sp2 = _reflect(y - 2, h) % DEPTH, _reflect(y + 2, h) % DEPTH
            if y0 <= y < y1:
                r0, r1, r2, r3 = r[0, y], r[1, y], r[2, y], r[3, y]
                _gabor_channel(ro, 1, 0, s0, sm1, sp1, sm2, sp2, gk, vw[0], True, gabor, acc,
                               r0, r1, r2, r3)
                _gabor_channel(ro, 3, 2, s0, sm1, sp1, sm2, sp2, gk, vw[1], False, gabor, acc,
                               r0, r1, r2, r3)
                vv = v[y]
                for x in range(w):
                    vv[x] = max(max(abs(r0[x]), abs(r1[x])), max(abs(r2[x]), abs(r3[x])))
                if sums:
                    for k in range(4):
                        rk, ck = r[k, y], colsum[k]
                        for x in range(w):
                            ck[x] += rk[x]
            gl = gring[y % 3]
            _approach_row(ro, s0, sm1, sp1, sm2, sp2, kc, aw, terms, zero, csl, gl)
            if not grouping:
                gy = g[y]
                for x in range(w):
                    gy[x] = gl[x + 1]
        y = t - RADIUS - 1
        if grouping and y0 <= y < y1:  # stage 3: row t - 3 through the grouping
            _group_row(gring[_reflect(y - 1, h) % 3], gring[y % 3], gring[_reflect(y + 1, h) % 3],
                       ninth, gline, g[y])
    done[0] = 1


@kernel(**_jit)
def _add_column_sums(r, y0, y1, colsum):
    for k in range(r.shape[0]):
        ck = colsum[k]
        for y in range(y0, y1):
            rk = r[k, y]
            for x in range(r.shape[2]):
                ck[x] += rk[x]


class FrontCoefficients(NamedTuple):
    """The coefficients of :func:`front`, in the order of its kernel's arguments."""

    env: np.ndarray
    scales: np.ndarray
    a: float  # 1 - r A
    b: float  # r C
    e_x: float  # r A - r C, the extra input of a leaky input stage
    j: int  # first integrating stage
    gain: float
    n_fast: int
    n_slow: int
    swap: bool
    gk: np.ndarray
    v_weights: np.ndarray
    kc: np.ndarray
    a_weights: np.ndarray
    terms: np.ndarray
    grouping: bool
    zero: float
    tiny: float
    ninth: float

    @classmethod
    def make(cls, env, scales, rate, c, decay, leaky, gain, n_fast, n_slow, swap, gk, v_weights,
             kc, a_weights, grouping) -> "FrontCoefficients":
        """From the model's parameters, in the dtype of ``env`` (every array must have it).

        ``swap`` exchanges the ON and OFF inputs (``target_polarity='light'``); ``a_weights``
        are the signed weights ``(w1+, -w2-, w1-, -w2+)``.
        """
        t = env.dtype.type
        return cls(env, scales, t(1 - rate * decay), t(rate * c), t(rate * decay - rate * c),
                   0 if leaky else 1, t(gain), int(n_fast), int(n_slow), bool(swap), gk,
                   v_weights, kc, a_weights, _TERMS, bool(grouping), t(0),
                   t(_TINY if t is np.float32 else 0.0), t(1 / 9))

    @property
    def halo(self) -> int:
        """Rows beyond a band whose read-outs :func:`front` reads (5x5 filters, grouping)."""
        return RADIUS + 1 if self.grouping else RADIUS


def front(p, stages, coefficients, maps, scratch, rows=None, other=None, versions=None,
          sums=True, done=None):
    """Everything from the photoreceptor output P to R^theta, V and G, in one pass.

    Reproduces :func:`~asnn.retina.bipolar`, :func:`~asnn.retina.temporal_filter_step` (on the
    cascades in difference form, :func:`to_differences`), :func:`~asnn.retina.temporal_readout`,
    :func:`~asnn.retina.motion_energy` (the four computed orientations;
    R^{theta+pi} = -R^theta), ``V = max_theta R^theta = max_k |R^k|``,
    :func:`~asnn.retina.approach_map` and (``grouping``) :func:`~asnn.retina.group`, with the
    coefficients of :class:`FrontCoefficients`, into ``maps`` (a :class:`FrontMaps`), using the
    ring buffers of ``scratch`` (a :class:`Scratch`).

    Parameters
    ----------
    p : ndarray (H, W)
        The photoreceptor output P of the frame (eq. 1; after the contrast gain control where
        the preset has it).
    stages : (ndarray, ndarray)
        The ON and OFF cascades, advanced by one frame in place.
    coefficients : FrontCoefficients
        The kernels and constants of the preset (:class:`FrontCoefficients`).
    maps : FrontMaps
        Where R^theta, V and G (and the column sums) are written.
    scratch : Scratch
        The ring buffers of the row stage, one per thread.
    rows : (y0, y1), optional
        Compute these rows only (default: all). Every pixel of a row is computed the same way
        whatever the band, so bands computed separately, on threads of their own, give the
        maps of one pass. A band's filters read ``coefficients.halo`` rows of read-outs beyond
        it, whose cascade rows it advances again and drops: those rows must still hold their
        state before this frame, so the rows of a band that a neighbouring band reads go to a
        second pair of arrays instead (see ``versions``).
    other : (ndarray, ndarray), optional
        The second pair of arrays, like ``stages``.
    versions : (ndarray, ndarray) of int8 (H,), optional
        Where each cascade row is read from and advanced into: 0 the ``stages``, 1 ``other``
        (default: all in place in the ``stages``).
    sums : bool
        Set ``maps.colsum`` to the band's column sums of R^theta. With bands, the first band
        (from row 0) sets them and :func:`add_column_sums` adds the others' rows in order: the
        sums are then those of one pass.
    done : ndarray of int64 (1,), optional
        Set to 1 once the band is computed, from within the kernel: a thread that waits for
        the band can see it before this call returns (which needs the GIL).
    """
    h = p.shape[0]
    y0, y1 = rows or (0, h)
    if versions is None:
        if (y0, y1) != (0, h):
            raise ValueError("a band of rows needs versions of the cascade rows")
        read = write = scratch.in_place(h)
        other = stages
    else:
        read, write = versions
    spare_on, spare_off = scratch.spare(stages[0].shape[0])
    _front(p, coefficients.env, coefficients.scales, *stages, *other, read, write,
           *coefficients[2:], *scratch.buffers(), spare_on, spare_off, maps.r, maps.v, maps.g,
           maps.colsum, y0, y1, bool(sums), scratch.done if done is None else done)


def add_column_sums(maps, y0, y1) -> None:
    """Add rows [y0, y1) of R^theta to ``maps.colsum``, in row order (see :func:`front`)."""
    _add_column_sums(maps.r, y0, y1, maps.colsum)


def to_differences(stages: np.ndarray, leaky: bool) -> np.ndarray:
    """A cascade z_0..z_{n-1} (as :func:`~asnn.retina.temporal_filter_step` keeps it) in the
    difference form of :func:`front`: ``z_j`` and ``d_i = z_i - z_{i+1}`` in slot i + 1, with
    j = 0 for a leaky input stage and 1 otherwise (slot 0 then unused, zero).

    The read-outs ``K (z_n - z_{n+1})`` are differences of nearly equal stages; kept as such,
    they need no subtraction and float32 keeps their relative precision (1e-6 on u(t) instead of
    1e-5 for stages in float32).
    """
    out = np.zeros_like(stages)
    j = 0 if leaky else 1
    out[j] = stages[j]
    out[j + 1:] = stages[j:-1] - stages[j + 1:]
    return out


# --------------------------------------------------------------------------- luminance


def _area_fast(size: tuple[int, int], shrunk: tuple[int, int]) -> bool:
    """Whether ``cv2.resize`` with INTER_AREA shrinks an image of ``size`` to ``shrunk`` by
    whole factors (its blockwise averages, whose order of additions depends on OpenCV's
    vector width), rather than with its weighted tables (:func:`_area_table`)."""
    scales = [1.0 / (d / s) for s, d in zip(size, shrunk)]
    return all(abs(f - round(f)) < np.finfo(np.float64).eps for f in scales)


def block_means(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``cv2.resize(image, size, interpolation=cv2.INTER_AREA)``, bit for bit, in a kernel
    where it shrinks a C-contiguous float image by 5 or 8 both ways (the looming fits' and the
    surface watch's grid of a 320-pixel-wide frame, and the repeat test's blocks): about half
    OpenCV's time there (18 -> 10 us for a 320 x 240 frame to 64 x 48, 15 -> 9 us to
    40 x 30), where OpenCV adds each block through a table of offsets. Other shrinks are
    OpenCV's.

    OpenCV's blockwise average (``resizeAreaFast``; its vector form is for a factor of 2 only)
    adds a block's pixels row after row, four at a time, ``sum += ((a + b) + c) + d`` from 0
    (the last ``k * k % 4`` one by one), in the image's precision, and multiplies the sum by
    ``1.f / (k * k)``, a float32: so do :func:`_block_means_of_five` and
    :func:`_block_means_of_eight` (``tests/test_equivalence.py`` checks them against
    ``cv2.resize``).
    """
    h, w = image.shape
    k = w // size[0]
    if (k not in (5, 8) or (w, h) != (k * size[0], k * size[1])
            or image.dtype not in (np.float32, np.float64) or not image.flags.c_contiguous):
        return cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    out = np.empty((size[1], size[0]), image.dtype)
    inverse = image.dtype.type(np.float32(1) / np.float32(k * k))  # OpenCV's 1.f / area
    (_block_means_of_five if k == 5 else _block_means_of_eight)(image, inverse, out)
    return out


@kernel(**_jit)
def _block_means_of_five(image, inverse, out):
    """:func:`block_means` by 5: a block's 25 pixels in six fours across its rows (OpenCV's
    order) and the last one alone."""
    zero = out.dtype.type(0)
    for by in range(out.shape[0]):
        y = 5 * by
        r0, r1, r2, r3, r4 = image[y], image[y + 1], image[y + 2], image[y + 3], image[y + 4]
        o = out[by]
        for bx in range(out.shape[1]):
            x = 5 * bx
            total = zero
            total += ((r0[x] + r0[x + 1]) + r0[x + 2]) + r0[x + 3]
            total += ((r0[x + 4] + r1[x]) + r1[x + 1]) + r1[x + 2]
            total += ((r1[x + 3] + r1[x + 4]) + r2[x]) + r2[x + 1]
            total += ((r2[x + 2] + r2[x + 3]) + r2[x + 4]) + r3[x]
            total += ((r3[x + 1] + r3[x + 2]) + r3[x + 3]) + r3[x + 4]
            total += ((r4[x] + r4[x + 1]) + r4[x + 2]) + r4[x + 3]
            total += r4[x + 4]
            o[bx] = total * inverse


@kernel(**_jit)
def _block_means_of_eight(image, inverse, out):
    """:func:`block_means` by 8: each row of a block is two fours."""
    zero = out.dtype.type(0)
    for by in range(out.shape[0]):
        o = out[by]
        for bx in range(out.shape[1]):
            x = 8 * bx
            total = zero
            for y in range(8 * by, 8 * by + 8):
                r = image[y]
                total += ((r[x] + r[x + 1]) + r[x + 2]) + r[x + 3]
                total += ((r[x + 4] + r[x + 5]) + r[x + 6]) + r[x + 7]
            o[bx] = total * inverse


@kernel(inline="always")
def _area_table(size, shrunk):
    """OpenCV's table of INTER_AREA weights (``computeResizeAreaTab``) from ``size`` samples to
    ``shrunk``, in its order: the source sample and the weight (float32, as OpenCV keeps it) of
    each entry, and where each destination sample's entries start (``shrunk + 1`` offsets)."""
    scale = 1.0 / (shrunk / size)
    source = np.empty(2 * size, np.int64)
    weight = np.empty(2 * size, np.float32)
    start = np.empty(shrunk + 1, np.int64)
    k = 0
    for dx in range(shrunk):
        start[dx] = k
        fsx1 = dx * scale
        fsx2 = fsx1 + scale
        cell = min(scale, size - fsx1)
        sx2 = min(int(math.floor(fsx2)), size - 1)
        sx1 = min(int(math.ceil(fsx1)), sx2)
        if sx1 - fsx1 > 1e-3:
            source[k], weight[k] = sx1 - 1, np.float32((sx1 - fsx1) / cell)
            k += 1
        for sx in range(sx1, sx2):
            source[k], weight[k] = sx, np.float32(1.0 / cell)
            k += 1
        if fsx2 - sx2 > 1e-3:
            source[k] = sx2
            weight[k] = np.float32(min(min(fsx2 - sx2, 1.0), cell) / cell)
            k += 1
    start[shrunk] = k
    return source, weight, start


def _area_taps(size: int, shrunk: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_area_table` as taps: ``index[t, i]`` and ``weight[t, i]`` of destination
    sample ``i``'s ``t``-th entry, padded with weight 0 (adding ``0 * v`` changes no sum), so
    that a row's sums are a few passes along it."""
    source, weight, start = _area_table(size, shrunk)
    counts = np.diff(start)
    index = np.repeat(source[start[:-1]][None], counts.max(), axis=0)
    padded = np.zeros(index.shape)
    for t in range(index.shape[0]):
        has = counts > t
        index[t, has] = source[start[:-1][has] + t]
        padded[t, has] = weight[start[:-1][has] + t]
    return index, padded


@kernel(**_jit)
def _shrink_levels(gray, levels, x_index, x_weight, y_index, y_weight, out):
    """``out = INTER_AREA shrink of levels[gray]``: each source row's horizontal sums once
    (looked up through ``levels`` where they are read, and kept for the next output rows that
    share the row), then each output row the weighted sum of its source rows' sums, in OpenCV's
    order and float64, rounded to ``out``'s dtype."""
    rows, width = out.shape
    x_taps, y_taps = x_index.shape[0], y_index.shape[0]
    sums = np.empty((y_taps, width))  # consecutive source rows fall in different slots
    held = np.full(y_taps, -1)  # the source row whose sums each slot holds
    acc = np.empty(width)
    for y in range(rows):
        for t in range(y_taps):
            if t > 0 and y_weight[t, y] == 0.0:
                continue  # padding
            sy = y_index[t, y]
            slot = sy % y_taps
            if held[slot] != sy:
                row_sums, source = sums[slot], gray[sy]
                index, weight = x_index[0], x_weight[0]
                if x_taps == 2:  # the commonest shrink (by less than 2): one pass
                    index2, weight2 = x_index[1], x_weight[1]
                    for x in range(width):
                        row_sums[x] = (levels[source[index[x]]] * weight[x]
                                       + levels[source[index2[x]]] * weight2[x])
                else:
                    for x in range(width):
                        row_sums[x] = levels[source[index[x]]] * weight[x]
                    for k in range(1, x_taps):
                        index, weight = x_index[k], x_weight[k]
                        for x in range(width):
                            row_sums[x] += levels[source[index[x]]] * weight[x]
                held[slot] = sy
        o, beta = out[y], y_weight[:, y]
        first = sums[y_index[0, y] % y_taps]
        if y_taps == 1 or beta[1] == 0.0:
            for x in range(width):
                o[x] = beta[0] * first[x]
        elif y_taps == 2:  # the commonest shrink (by less than 2): no running sum
            second = sums[y_index[1, y] % y_taps]
            for x in range(width):
                o[x] = beta[0] * first[x] + beta[1] * second[x]
        else:
            for x in range(width):
                acc[x] = beta[0] * first[x]
            for t in range(1, y_taps):
                if beta[t] != 0.0:
                    row_sums = sums[y_index[t, y] % y_taps]
                    for x in range(width):
                        acc[x] += beta[t] * row_sums[x]
            for x in range(width):
                o[x] = acc[x]


def shrunk_luminance(gray: np.ndarray, size: tuple[int, int], levels: np.ndarray,
                     dtype) -> np.ndarray:
    """``cv2.resize(cv2.LUT(gray, levels), size, interpolation=cv2.INTER_AREA)`` rounded to
    ``dtype``, bit for bit, for a uint8 ``gray`` image larger than ``size`` (W, H) along the
    width and not smaller along the height; in a third of its time on one thread (the look-up
    is done where a source pixel is read, and no float64 image is made). Shrinking by whole
    factors both ways, OpenCV sums the blocks in another order, and its own fast path is
    used."""
    h, w = gray.shape
    width, height = size
    if _area_fast((w, h), size):
        return cv2.resize(cv2.LUT(gray, levels), size,
                          interpolation=cv2.INTER_AREA).astype(dtype, copy=False)
    x_index, x_weight = _cached("area_taps", (w, width), lambda: _area_taps(w, width))
    y_index, y_weight = _cached("area_taps", (h, height), lambda: _area_taps(h, height))
    out = np.empty((height, width), dtype)
    _shrink_levels(gray, levels, x_index, x_weight, y_index, y_weight, out)
    return out


# --------------------------------------------------------------------------- gain control


@kernel(error_model="numpy", **_jit)  # IEEE division, as NumPy's: no check, so it vectorises
def _divide_by_pool(p, pool, semi, scale, out):
    h, w = p.shape
    for y in range(h):
        py, qy, oy = p[y], pool[y], out[y]
        for x in range(w):
            oy[x] = py[x] * (scale / (semi + qy[x]))


def contrast_gain_control(p, semi_saturation, sigma, scale, out=None):
    """:func:`~asnn.retina.contrast_gain_control`, its division in one pass over the image,
    into ``out`` (default: a new array)."""
    t = p.dtype.type
    out = np.empty_like(p) if out is None else out
    _divide_by_pool(p, retina.contrast_pool(p, sigma), t(semi_saturation), t(scale), out)
    return out


@kernel(**_jit)
def _change_and_averages(current, previous, photo, coarse):
    """``P = current - previous`` into ``photo``, and the averages of ``|P|`` over 4x4 blocks
    into ``coarse``, as ``cv2.resize`` (INTER_AREA) takes them when it shrinks by 4 both ways:
    per block the sum of its rows' sums ``((a + b) + c) + d``, times 1/16."""
    sixteenth = coarse.dtype.type(1 / 16)
    for cy in range(coarse.shape[0]):
        for y in range(4 * cy, 4 * cy + 4):
            a, b, o = current[y], previous[y], photo[y]
            for x in range(o.shape[0]):
                o[x] = a[x] - b[x]
        r0, r1, r2, r3 = photo[4 * cy], photo[4 * cy + 1], photo[4 * cy + 2], photo[4 * cy + 3]
        c = coarse[cy]
        for cx in range(c.shape[0]):
            x = 4 * cx
            total = c.dtype.type(0)
            for r in (r0, r1, r2, r3):
                total += ((abs(r[x]) + abs(r[x + 1])) + abs(r[x + 2])) + abs(r[x + 3])
            c[cx] = total * sixteenth


def gain_controlled_change(current, previous, semi_saturation, sigma, scale, out=None):
    """:func:`~asnn.retina.contrast_gain_control` of ``P = current - previous`` (eq. 1 without
    photoreceptor history) into ``out`` (default: a new array).

    Where the pool's grid divides the frame (4 x 4 pixels per cell), P and the pool's area
    averages are computed in one pass (:func:`_change_and_averages`); elsewhere as
    :func:`contrast_gain_control` does.
    """
    h, w = current.shape
    if h % 4 or w % 4 or retina._POOL_STEP != 4:
        return contrast_gain_control(current - previous, semi_saturation, sigma, scale, out)
    t = current.dtype.type
    # P and the averages are consumed here: this thread's buffers serve every frame of a size
    photo, coarse = _cached("change", (h, w, current.dtype.str), lambda: (
        np.empty_like(current), np.empty((h // 4, w // 4), current.dtype)))
    _change_and_averages(current, previous, photo, coarse)
    out = np.empty_like(current) if out is None else out
    _divide_by_pool(photo, retina.contrast_pool_spread(coarse, sigma, (h, w)),
                    t(semi_saturation), t(scale), out)
    return out


# --------------------------------------------------------------------------- motion vectors


def motion_vectors(r, v, rows, cols):
    """The motion vectors ``(V cos phi, V sin phi)`` (eq. 29) at the pixels ``(rows, cols)``,
    float64, from the four computed orientations ``r`` (R^0, R^{pi/4}, R^{pi/2}, R^{3pi/4})
    and ``V``, with ``phi = atan2(R^{pi/2}, R^0)`` (eq. 18).

    ``cos phi`` and ``sin phi`` are ``R^0 / |(R^0, R^{pi/2})|`` and ``R^{pi/2} / |...|``: the
    same to rounding (about 1e-16 relative), in one pass without the arc tangent, cosine and
    sine per pixel, which took most of the time of a frame's targets.
    """
    dx, dy = np.empty(rows.shape[0]), np.empty(rows.shape[0])
    _motion_vectors(r, v, rows, cols, dx, dy)
    return dx, dy


class MotionVectors:
    """A frame's motion vectors (eq. 29) from its maps ``r`` and ``v``
    (:func:`motion_vectors`): ``vectors(rows, cols) -> (dx, dy)`` at those pixels, and
    :meth:`sums`, their sums per region, which the objects' population-coded motion reads
    (:class:`asnn.targets.ObjectRegions`)."""

    __slots__ = ("r", "v")

    def __init__(self, r: np.ndarray, v: np.ndarray):
        self.r, self.v = r, v

    def __call__(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return motion_vectors(self.r, self.v, rows, cols)

    def sums(self, rows: np.ndarray, cols: np.ndarray, labels: np.ndarray,
             n: int) -> tuple[np.ndarray, np.ndarray]:
        """``np.bincount(labels, dx, n)`` and ``np.bincount(labels, dy, n)`` of the vectors
        ``(dx, dy)`` at the pixels ``(rows, cols)``, bit for bit (each region's sum from 0, in
        the pixels' order, as NumPy adds them), in one pass and without the vectors' arrays:
        the vectors and the two counts took about 80 us on a 6,600-pixel object."""
        sum_dx, sum_dy = np.zeros(n), np.zeros(n)
        _summed_motion_vectors(self.r, self.v, rows, cols, labels, sum_dx, sum_dy)
        return sum_dx, sum_dy


@kernel(error_model="numpy", **_jit)
def _motion_vectors(r, v, rows, cols, dx, dy):
    for i in range(rows.shape[0]):
        dx[i], dy[i] = _motion_vector(r, v, rows[i], cols[i])


@kernel(error_model="numpy", **_jit)
def _summed_motion_vectors(r, v, rows, cols, labels, sum_dx, sum_dy):
    """:meth:`MotionVectors.sums` into ``sum_dx`` and ``sum_dy`` (zeros). A region's sums are
    carried in locals along a run of its pixels (as in :func:`asnn.targets._region_moments`):
    the same additions in the same order, without a store and a load between two of them."""
    k0, a, b = -1, 0.0, 0.0
    for i in range(rows.shape[0]):
        k = labels[i]
        if k != k0:
            if k0 >= 0:
                sum_dx[k0], sum_dy[k0] = a, b
            k0, a, b = k, sum_dx[k], sum_dy[k]
        dx, dy = _motion_vector(r, v, rows[i], cols[i])
        a += dx
        b += dy
    if k0 >= 0:
        sum_dx[k0], sum_dy[k0] = a, b


@kernel(error_model="numpy", inline="always", **_jit)
def _motion_vector(r, v, y, x):
    """The motion vector ``(dx, dy)`` at pixel ``(y, x)`` (:func:`motion_vectors`)."""
    c, s, vv = np.float64(r[0, y, x]), np.float64(r[2, y, x]), np.float64(v[y, x])
    norm = math.sqrt(c * c + s * s)  # exact squares of float32 maps: no overflow
    if norm > 0.0:
        return vv * (c / norm), vv * (s / norm)
    phi = math.atan2(s, c)  # atan2 of zeros: 0 or pi by their signs
    return vv * math.cos(phi), vv * math.sin(phi)


# --------------------------------------------------------------------------- attention, u(t)


@kernel(**_jit)
def _box(blur, gamma, r0, r1, c0, c1):
    """Bounding box (y0, y1, x0, x1), exclusive ends, of ``blur > gamma`` in the rows
    ``[r0, r1)`` and columns ``[c0, c1)`` of ``blur``, in its indices; y0 = r1 if empty."""
    y0, y1, x0, x1 = r1, r0, c1, c0
    for y in range(r0, r1):
        row = blur[y, c0:c1]
        n = 0
        for x in range(c1 - c0):  # a count vectorises; the ends are then searched in the few
            n += row[x] > gamma  # rows set
        if n == 0:
            continue
        first = 0
        while not row[first] > gamma:
            first += 1
        last = c1 - c0 - 1
        while not row[last] > gamma:
            last -= 1
        if y0 == r1:
            y0 = y
        y1 = y + 1
        x0 = min(x0, c0 + first)
        x1 = max(x1, c0 + last + 1)
    return y0, y1, x0, x1


@kernel(**_jit)
def _v_prime(v, r, ks, signs, y0, y1, x0, x1, out):
    """V' = ``V - max_j signs_j R^{ks_j}`` (eq. 25) in the window, into ``out``."""
    for y in range(y0, y1):
        vv, o = v[y], out[y]
        if ks.shape[0] == 1:
            rk, sg = r[ks[0], y], signs[0]
            for x in range(x0, x1):
                o[x] = vv[x] - sg * rk[x]
            continue
        for x in range(x0, x1):
            m = signs[0] * r[ks[0], y, x]
            for j in range(1, ks.shape[0]):
                m = max(m, signs[j] * r[ks[j], y, x])
            o[x] = vv[x] - m


@kernel(**_jit)
def _v_prime_halved(v, r, k, sign, out):
    """The 2x2 area averages of ``V - sign R^k``, as OpenCV's INTER_AREA halves an image of
    even size: ``((a + b) + (c + d)) / 4`` of each block."""
    quarter = v.dtype.type(0.25)
    for y in range(out.shape[0]):
        v0, v1, r0, r1, o = v[2 * y], v[2 * y + 1], r[k, 2 * y], r[k, 2 * y + 1], out[y]
        for x in range(out.shape[1]):
            a, b = v0[2 * x] - sign * r0[2 * x], v0[2 * x + 1] - sign * r0[2 * x + 1]
            c, d = v1[2 * x] - sign * r1[2 * x], v1[2 * x + 1] - sign * r1[2 * x + 1]
            o[x] = ((a + b) + (c + d)) * quarter


@kernel(**_jit)
def _attend(blur_g, gy0, gx0, gamma_a, blur_v, vy0, vx0, gamma_d, g, absolute, y0, y1, x0, x1,
            mask, colsum, rows, cols):
    """M_a M_d (eqs. 23, 26) in the window ``y0:y1, x0:x1`` into ``mask``, the attended pixels
    into ``rows``, ``cols`` (row-major), and sum G M_a M_d (eqs. 27, 28; in float64).
    ``blur_g`` and ``blur_v`` are C-contiguous blurs whose first pixels lie at ``(gy0, gx0)``
    and ``(vy0, vx0)`` of the frame: whole arrays rather than slices from the window's origin,
    whose layout (contiguous or not) would depend on where the window lies, and numba would
    compile the kernel again for each (seconds, the first time a stream's window touches the
    frame's corner)."""
    for x in range(x0, x1):
        colsum[x] = 0.0
    count = 0
    bits = mask.view(np.uint8)  # as bytes, and on slices from x0, the loop vectorises
    for y in range(y0, y1):
        bg, bv, gy, my = blur_g[y - gy0], blur_v[y - vy0], g[y], mask[y]
        a, b, m = bg[x0 - gx0:x1 - gx0], bv[x0 - vx0:x1 - vx0], bits[y, x0:x1]
        n = 0
        for x in range(x1 - x0):
            set_ = np.uint8(a[x] > gamma_a) & np.uint8(b[x] > gamma_d)
            m[x] = set_
            n += set_
        if n == 0:  # the column sums never hold -0.0: adding +0.0 would change nothing
            continue
        if absolute:
            for x in range(x0, x1):
                colsum[x] += abs(gy[x]) if my[x] else 0.0
        else:
            for x in range(x0, x1):
                colsum[x] += gy[x] if my[x] else 0.0
        for x in range(x0, x1):
            if my[x]:
                rows[count] = y
                cols[count] = x
                count += 1
    total = 0.0
    for x in range(x0, x1):
        total += colsum[x]
    return total, count


def attention(g, r, v, sums, ws, blur, gamma_a, gamma_d, top_k, absolute, full=False):
    """M_a, M_d and ``sum G M_a M_d`` (or of ``|G|``), in float64 (eqs. 22-28).

    Reproduces :func:`~asnn.retina.approach_attention`, :func:`~asnn.retina.direction_attention`
    and :func:`~asnn.retina.membrane_potential` (before its scale). ``blur`` is the
    attention blur (:class:`AttentionBlur`), ``sums`` the sums of R^theta.
    Unless ``full``, M_d is computed only in M_a's bounding box (V' is blurred there plus the
    blur's radius, or over the whole frame for a blur on a coarser grid), and a blur on a grid
    twice coarser is interpolated back only in a window around the cells above the threshold
    (:meth:`AttentionBlur.window`). Returns ``(sum, number of attended pixels, blurred G or
    None, blurred V' or None, window)``: the blurs cover the window; ``ws.mask`` holds M_a M_d
    (zero outside the window), ``ws.rows[:count]``, ``ws.cols[:count]`` the attended pixels in
    row-major order.
    """
    h, w = g.shape
    ws.mask.fill(False)
    halved = blur.step == 2 and h % 2 == 0 and w % 2 == 0 and not full
    if halved:
        # interpolation is a convex combination of the four nearest cells: a pixel is above
        # gamma_a only next to a cell that is
        coarse_g = blur.coarse(retina.coarse_grid(g, 2))
        y0, y1, x0, x1 = _box(coarse_g, float(gamma_a), 0, coarse_g.shape[0], 0,
                              coarse_g.shape[1])
        if y0 >= y1:
            return 0.0, 0, None, None, (0, 0, 0, 0)
        wy0, wy1, wx0, wx1 = max(2 * y0 - 1, 0), min(2 * y1 + 2, h), max(2 * x0 - 1, 0), \
            min(2 * x1 + 2, w)
        # the kernels read the interpolation in the window where it lies (no copy of it)
        around_g, gy, gx = blur.around(coarse_g, wy0, wy1, wx0, wx1)
        blur_g = around_g[wy0 - gy:wy1 - gy, wx0 - gx:wx1 - gx]
        y0, y1, x0, x1 = _box(around_g, float(gamma_a), wy0 - gy, wy1 - gy, wx0 - gx,
                              wx1 - gx)
        if y0 >= y1:
            return 0.0, 0, blur_g, None, (wy0, wy1, wx0, wx1)
        y0, y1, x0, x1 = y0 + gy, y1 + gy, x0 + gx, x1 + gx
        g_origin = (gy, gx)
    else:
        blur_g = around_g = blur(g)
        if full:
            y0, y1, x0, x1 = 0, h, 0, w
        else:
            y0, y1, x0, x1 = _box(blur_g, float(gamma_a), 0, h, 0, w)
            if y0 >= y1:
                return 0.0, 0, blur_g, None, (0, 0, 0, 0)
        g_origin = (0, 0)
    if top_k:
        half = r.shape[0]
        totals = np.concatenate([sums, -sums])
        chosen = np.argsort(-totals, kind="stable")[:top_k]
        ks = np.array([k % half for k in chosen], np.int64)
        signs = np.array([1 if k < half else -1 for k in chosen], dtype=g.dtype)
    if halved and top_k == 1:
        # V' straight onto the coarse grid, blurred there, interpolated back in the window
        coarse = np.empty((h // 2, w // 2), g.dtype)
        _v_prime_halved(v, r, ks[0], signs[0], coarse)
        around_v, vy, vx = blur.around(blur.coarse(coarse), y0, y1, x0, x1)
        blur_v = around_v[y0 - vy:y1 - vy, x0 - vx:x1 - vx]
        window = (y0, y1, x0, x1)
    else:
        # the blur of V' is exact inside the window when the window extends by its radius
        # (or reaches the frame's edge, where the border rule applies as in the whole frame)
        margin = blur.radius
        wy0, wy1, wx0, wx1 = max(y0 - margin, 0), min(y1 + margin, h), max(x0 - margin, 0), \
            min(x1 + margin, w)
        if blur.step > 1:  # a blur on a coarser grid is only exact over the whole frame
            wy0, wy1, wx0, wx1 = 0, h, 0, w
        if top_k:
            _v_prime(v, r, ks, signs, wy0, wy1, wx0, wx1, ws.v_prime)
            source = ws.v_prime[wy0:wy1, wx0:wx1]
        else:
            source = v[wy0:wy1, wx0:wx1]
        blur_v = around_v = blur(np.ascontiguousarray(source))
        window = (wy0, wy1, wx0, wx1)
        vy, vx = wy0, wx0
    total, count = _attend(around_g, *g_origin, float(gamma_a), around_v, vy, vx,
                           float(gamma_d), g, bool(absolute), y0, y1, x0, x1, ws.mask,
                           ws.attended_sums, ws.rows, ws.cols)
    return total, count, blur_g, blur_v, window


class AttentionBlur:
    """The attention blur g_sigma as a callable with its radius and grid step (see
    :func:`attention`)."""

    def __init__(self, sigma: float, size: int, normalised: bool, step: int = 1):
        self.radius = size // 2
        self.step = step
        self._args = (sigma, size, normalised)

    def __call__(self, image: np.ndarray) -> np.ndarray:
        return retina.attention_blur(image, *self._args, self.step)

    def coarse(self, coarse: np.ndarray) -> np.ndarray:
        """The blur on the coarse grid (``step`` > 1) of an image's area average there
        (:func:`~asnn.retina.coarse_grid_blur`)."""
        return retina.coarse_grid_blur(coarse, *self._args, self.step)

    def window(self, blurred: np.ndarray, y0: int, y1: int, x0: int, x1: int) -> np.ndarray:
        """Rows ``y0:y1``, columns ``x0:x1`` of the bilinear interpolation back of a blur on
        the grid twice coarser (``step`` = 2, an image of even size), bit for bit those of
        :func:`~asnn.retina.coarse_attention_blur` (:meth:`around`, cut to the window)."""
        up, oy, ox = self.around(blurred, y0, y1, x0, x1)
        return up[y0 - oy:y1 - oy, x0 - ox:x1 - ox]

    def around(self, blurred: np.ndarray, y0: int, y1: int, x0: int, x1: int
               ) -> tuple[np.ndarray, int, int]:
        """The bilinear interpolation back (:meth:`window`) over the cells around the window
        rows ``y0:y1``, columns ``x0:x1``, and the frame's row and column of its first pixel:
        the cells around the window are interpolated, with a margin of cells that keeps the
        border rule of their own edges out of the window (each pixel reads the two nearest
        cells in each direction), so only the window is exact. Contiguous, whatever the
        window: the kernels it goes to keep one compiled form."""
        h, w = blurred.shape
        a, b = max((y0 - 1) // 2 - 1, 0), min((y1 - 1) // 2 + 3, h)
        c, d = max((x0 - 1) // 2 - 1, 0), min((x1 - 1) // 2 + 3, w)
        up = cv2.resize(blurred[a:b, c:d], (2 * (d - c), 2 * (b - a)),
                        interpolation=cv2.INTER_LINEAR)
        return up, 2 * a, 2 * c
