"""Fused kernels of the optimised ASNN step (private; used by :class:`asnn.model.ASNN`).

Why a second module
-------------------
:mod:`asnn.retina` states every equation of the paper once, in its straightforward form: OpenCV
2-D correlations and NumPy expressions on float64 arrays, one stage at a time. That form is the
definition; ``ASNN(params, optimised=False)`` runs it, ``asnn bench`` times it, and the
equivalence tests (``tests/test_equivalence.py``) compare this module against it.

The functions here compute the expensive stages of the same equations with fewer passes over
memory. They define nothing new: every kernel they use is built by the retina functions
(:func:`~asnn.retina.dog_kernel`, :func:`~asnn.retina.center_surround_kernel`) or is a factor of
one (:func:`gabor_factors` of :func:`~asnn.retina.gabor_pair`), and each function names the
retina function whose result it reproduces. What changes is only the order of the arithmetic:

* Fusion. Rectification, the difference-of-Gaussians filter and the leaky-integrator cascade run
  in one pass per row; centre-surround inhibition, rectifications and the weighted sum of the
  approach map in another; thresholds, masks and the membrane potential in a third. No
  full-frame temporaries.
* Separability. On the [-1, 1] grid, the Gabor pair of orientation theta is one complex kernel,
  ``g^0 + i g^{pi/2} = e(y) e(x) exp(i a (x cos theta + y sin theta))``, with ``e`` the 1-D
  Gaussian envelope and ``a = 2 pi / lambda``: the product of a row kernel
  ``e(x) exp(i a cos(theta) x)`` and a column kernel ``e(y) exp(i a sin(theta) y)``. For the
  four orientations k pi / 4, five real row passes and eight real column passes replace 8
  two-dimensional 5x5 correlations per image (theta = pi/4 and 3 pi/4 share their passes:
  their row kernels are complex conjugates). ``E = A1 B2 - A2 B1 = Im(conj(Z_slow) Z_fast)``.
* Symmetry. The 5-tap kernels are symmetric or antisymmetric: pairs are added before they are
  multiplied.
* Precision. The arrays have the dtype of the preset's ``precision`` (float64 for ``reference``,
  whose outputs must match the published implementation; float32 elsewhere, where the
  equivalence tests bound the difference to 1e-5 relative on u(t)).

The fused kernels are written for the 5x5 kernels of Table I (every preset); other sizes fall
back to the straightforward functions (:func:`supported`). Numba compiles them on first use and
caches the machine code next to this file (or in ``NUMBA_CACHE_DIR``); no ``fastmath``, so
IEEE semantics are kept and float64 results differ from the straightforward form only by
rounding (about 1e-15 relative).

Scratch arrays live in a per-thread :class:`Workspace` shared by all models of that thread, so
a camera's own state is only its cascades and its previous frame.
"""

from __future__ import annotations

import math
import threading

import numpy as np
from numba import njit

__all__ = ["supported", "gabor_factors", "Workspace", "workspace", "bipolar_cascade",
           "gabor_energy", "approach_term", "group", "attend"]

RADIUS = 2  # the fused kernels are written for 5x5 kernels (Table I)

_jit = dict(cache=True, boundscheck=False, nogil=True)


def supported(params) -> bool:
    """Whether the fused kernels apply to a parameter set (5x5 g_I, g_DS, g_CS)."""
    return params.dog_size == 2 * RADIUS + 1 and params.kernel_size == 2 * RADIUS + 1


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


# --------------------------------------------------------------------------- workspace


class Workspace:
    """Scratch arrays for one frame size and dtype, reused from frame to frame."""

    def __init__(self, shape: tuple[int, int], dtype: np.dtype):
        h, w = shape
        self.shape, self.dtype = shape, dtype
        self.bipolar = np.empty((2, h, w), dtype)  # B+^0, B-^0
        self.readout = np.empty((4, h, w), dtype)  # fast_on, slow_on, fast_off, slow_off
        self.rows = np.empty((2, 5, h, w), dtype)  # Gabor row passes of slow and fast
        self.acc = np.empty((2, 8, w), dtype)  # their column passes, one row
        self.r = np.empty((4, h, w), dtype)  # R^theta, theta = k pi / 4, k = 0..3
        self.v = np.empty((h, w), dtype)
        self.g = np.empty((h, w), dtype)
        self.g_grouped = np.empty((h, w), dtype)
        self.pad = np.empty((h + 2 * RADIUS, w + 2 * RADIUS), dtype)
        self.line = np.empty((2, w + 2 * RADIUS), dtype)
        self.row2 = np.empty((2, w), dtype)
        self.mask = np.empty((h, w), np.bool_)


_local = threading.local()


def workspace(shape: tuple[int, int], dtype) -> Workspace:
    """This thread's workspace for a frame size and dtype (the last few are kept)."""
    cache = getattr(_local, "cache", None)
    if cache is None:
        cache = _local.cache = {}
    key = (shape, np.dtype(dtype).str)
    ws = cache.get(key)
    if ws is None:
        if len(cache) >= 4:
            cache.pop(next(iter(cache)))
        ws = cache[key] = Workspace(shape, np.dtype(dtype))
    return ws


# --------------------------------------------------------------------------- helpers


@njit(inline="always", **_jit)
def _reflect(i, n):
    """Reflect-101 index (OpenCV's default border) for |overshoot| < n."""
    if i < 0:
        return -i
    if i >= n:
        return 2 * n - 2 - i
    return i


@njit(**_jit)
def _pad_line(src, out):
    """A row padded by RADIUS on both sides with the reflect-101 border."""
    w = src.shape[0]
    for x in range(w):
        out[RADIUS + x] = src[x]
    for k in range(1, RADIUS + 1):
        out[RADIUS - k] = src[k]
        out[RADIUS + w - 1 + k] = src[w - 1 - k]


@njit(**_jit)
def _pad2d(src, out):
    """The image padded by RADIUS on every side with the reflect-101 border."""
    h = src.shape[0]
    for y in range(h + 2 * RADIUS):
        _pad_line(src[_reflect(y - RADIUS, h)], out[y])


# --------------------------------------------------------------------------- bipolar + cascade


@njit(**_jit)
def _bipolar(pad, dog, on, off):
    h, w = on.shape
    zero = on[0, 0] * 0
    for y in range(h):
        for x in range(w):
            s_on = zero
            s_off = zero
            for j in range(2 * RADIUS + 1):
                for i in range(2 * RADIUS + 1):
                    v = pad[y + j, x + i]
                    pos = v if v > zero else zero
                    s_on += dog[j, i] * pos
                    s_off += dog[j, i] * (pos - v)
            on[y, x] = s_on
            off[y, x] = s_off


@njit(**_jit)
def _cascade(stages, x0, rate, c, decay, leaky, gain, n_fast, n_slow, fast, slow):
    n, h, w = stages.shape
    for i in range(n):
        for y in range(h):
            cur = stages[i, y]
            prev = x0[y] if i == 0 else stages[i - 1, y]
            if i == 0 and not leaky:
                for x in range(w):
                    cur[x] = prev[x]
            else:
                for x in range(w):
                    cur[x] += rate * (c * prev[x] - decay * cur[x])
    for y in range(h):
        af, bf, as_, bs = stages[n_fast, y], stages[n_fast + 1, y], stages[n_slow, y], \
            stages[n_slow + 1, y]
        f, s = fast[y], slow[y]
        for x in range(w):
            f[x] = gain * (af[x] - bf[x])
            s[x] = gain * (as_[x] - bs[x])


def bipolar_cascade(p, ws, dog, swap, stages_on, stages_off, rate, c, decay, leaky, gain,
                    n_fast, n_slow):
    """Bipolar inputs, one cascade step and the four temporal read-outs.

    Reproduces :func:`~asnn.retina.bipolar`, :func:`~asnn.retina.temporal_filter_step` and
    :func:`~asnn.retina.temporal_readout`. ``swap`` exchanges the ON and OFF inputs
    (``target_polarity='light'``). Returns ``(fast_on, slow_on, fast_off, slow_off)``, views of
    the workspace.
    """
    t = ws.dtype.type
    _pad2d(p, ws.pad)
    on, off = ws.bipolar
    _bipolar(ws.pad, dog.astype(ws.dtype), on, off)
    if swap:
        on, off = off, on
    for ch, (stages, x0) in enumerate(((stages_on, on), (stages_off, off))):
        _cascade(stages, x0, t(rate), t(c), t(decay), bool(leaky), t(gain), int(n_fast),
                 int(n_slow), ws.readout[2 * ch], ws.readout[2 * ch + 1])
    return ws.readout[0], ws.readout[1], ws.readout[2], ws.readout[3]


# --------------------------------------------------------------------------- Gabor energy


@njit(**_jit)
def _gabor_rows(src, k, line, out):
    """Row passes of one image with the five 1-D factors (sym, sym, anti, sym, anti)."""
    h, w = src.shape
    k0, k1, k2, k3, k4 = k[0], k[1], k[2], k[3], k[4]
    for y in range(h):
        _pad_line(src[y], line)
        o0, o1, o2, o3, o4 = out[0, y], out[1, y], out[2, y], out[3, y], out[4, y]
        for x in range(w):
            m = line[x + 2]
            p1 = line[x + 3] + line[x + 1]
            p2 = line[x + 4] + line[x]
            d1 = line[x + 3] - line[x + 1]
            d2 = line[x + 4] - line[x]
            o0[x] = k0[2] * m + k0[3] * p1 + k0[4] * p2
            o1[x] = k1[2] * m + k1[3] * p1 + k1[4] * p2
            o2[x] = k2[3] * d1 + k2[4] * d2
            o3[x] = k3[2] * m + k3[3] * p1 + k3[4] * p2
            o4[x] = k4[3] * d1 + k4[4] * d2


@njit(inline="always", **_jit)
def _column_sym(src, y, ym1, yp1, ym2, yp2, k, out):
    """out = symmetric 5-tap column pass of ``src`` at row y (rows clamped by the caller)."""
    a0, a1, b1, a2, b2 = src[y], src[ym1], src[yp1], src[ym2], src[yp2]
    c0, c1, c2 = k[2], k[3], k[4]
    for x in range(out.shape[0]):
        out[x] = c0 * a0[x] + c1 * (b1[x] + a1[x]) + c2 * (b2[x] + a2[x])


@njit(inline="always", **_jit)
def _column_anti(src, ym1, yp1, ym2, yp2, k, out):
    """out = antisymmetric 5-tap column pass of ``src`` at row y."""
    a1, b1, a2, b2 = src[ym1], src[yp1], src[ym2], src[yp2]
    c1, c2 = k[3], k[4]
    for x in range(out.shape[0]):
        out[x] = c1 * (b1[x] - a1[x]) + c2 * (b2[x] - a2[x])


@njit(**_jit)
def _gabor_columns(rows, k, weight, first, last, acc, r, v):
    # Small loops with one output each: LLVM vectorises them (a single loop with all sixteen
    # outputs is left scalar by its alias analysis).
    h, w = r.shape[1], r.shape[2]
    for y in range(h):
        ym1, yp1 = _reflect(y - 1, h), _reflect(y + 1, h)
        ym2, yp2 = _reflect(y - 2, h), _reflect(y + 2, h)
        for im in range(2):
            a = acc[im]
            _column_sym(rows[im, 1], y, ym1, yp1, ym2, yp2, k[0], a[0])   # Re Z^0
            _column_sym(rows[im, 2], y, ym1, yp1, ym2, yp2, k[0], a[1])   # Im Z^0
            _column_sym(rows[im, 0], y, ym1, yp1, ym2, yp2, k[1], a[2])   # Re Z^{pi/2}
            _column_anti(rows[im, 0], ym1, yp1, ym2, yp2, k[2], a[3])     # Im Z^{pi/2}
            _column_sym(rows[im, 3], y, ym1, yp1, ym2, yp2, k[3], a[4])   # cb Cb
            _column_anti(rows[im, 3], ym1, yp1, ym2, yp2, k[4], a[5])     # cb Sb
            _column_anti(rows[im, 4], ym1, yp1, ym2, yp2, k[4], a[6])     # sb Sb
            _column_sym(rows[im, 4], y, ym1, yp1, ym2, yp2, k[3], a[7])   # sb Cb
        s, f = acc[0], acc[1]
        r0, r1, r2, r3 = r[0, y], r[1, y], r[2, y], r[3, y]
        # E = Re Z_slow Im Z_fast - Re Z_fast Im Z_slow, with (a[4], a[5], a[6], a[7]) =
        # (cb Cb, cb Sb, sb Sb, sb Cb): Z^{pi/4} = (cb Cb - sb Sb) + i (cb Sb + sb Cb) and
        # Z^{3 pi/4} = (cb Cb + sb Sb) + i (cb Sb - sb Cb)
        s0, s1, f0, f1 = s[0], s[1], f[0], f[1]
        if first:
            for x in range(w):
                r0[x] = weight * (s0[x] * f1[x] - f0[x] * s1[x])
        else:
            for x in range(w):
                r0[x] += weight * (s0[x] * f1[x] - f0[x] * s1[x])
        s0, s1, f0, f1 = s[2], s[3], f[2], f[3]
        if first:
            for x in range(w):
                r2[x] = weight * (s0[x] * f1[x] - f0[x] * s1[x])
        else:
            for x in range(w):
                r2[x] += weight * (s0[x] * f1[x] - f0[x] * s1[x])
        scc, scs, sss, ssc = s[4], s[5], s[6], s[7]
        fcc, fcs, fss, fsc = f[4], f[5], f[6], f[7]
        if first:
            for x in range(w):
                r1[x] = weight * ((scc[x] - sss[x]) * (fcs[x] + fsc[x])
                                  - (fcc[x] - fss[x]) * (scs[x] + ssc[x]))
            for x in range(w):
                r3[x] = weight * ((scc[x] + sss[x]) * (fcs[x] - fsc[x])
                                  - (fcc[x] + fss[x]) * (scs[x] - ssc[x]))
        else:
            for x in range(w):
                r1[x] += weight * ((scc[x] - sss[x]) * (fcs[x] + fsc[x])
                                   - (fcc[x] - fss[x]) * (scs[x] + ssc[x]))
            for x in range(w):
                r3[x] += weight * ((scc[x] + sss[x]) * (fcs[x] - fsc[x])
                                   - (fcc[x] + fss[x]) * (scs[x] - ssc[x]))
        if last:
            vv = v[y]
            for x in range(w):
                vv[x] = max(max(abs(r0[x]), abs(r1[x])), max(abs(r2[x]), abs(r3[x])))


def gabor_energy(slow, fast, ws, factors, weight, first, last):
    """Add ``weight E^theta`` of one channel to ``ws.r`` (or set it, ``first``).

    Reproduces one channel's share of :func:`~asnn.retina.motion_energy` for the four computed
    orientations; with ``last``, also ``V = max_theta R^theta = max_k |R^k|`` (R^{theta+pi} =
    -R^theta) into ``ws.v``.
    """
    k = factors.astype(ws.dtype)
    _gabor_rows(slow, k, ws.line[0], ws.rows[0])
    _gabor_rows(fast, k, ws.line[0], ws.rows[1])
    _gabor_columns(ws.rows, k, ws.dtype.type(weight), bool(first), bool(last), ws.acc, ws.r,
                   ws.v)


# --------------------------------------------------------------------------- approach map


@njit(**_jit)
def _approach_term(excitation, inhibitor, pad, kernel, weight, first, g):
    h, w = g.shape
    _pad2d(inhibitor, pad)
    zero = g[0, 0] * 0
    for y in range(h):
        ex = excitation[y]
        gy = g[y]
        for x in range(w):
            s = zero
            for j in range(2 * RADIUS + 1):
                prow = pad[y + j]
                for i in range(2 * RADIUS + 1):
                    s += kernel[j, i] * prow[x + i]
            t = max(max(ex[x], zero) - max(s, zero), zero)
            if first:
                gy[x] = zero + weight * t
            else:
                gy[x] += weight * t


def approach_term(excitation, inhibitor, ws, cs_kernel, weight, first):
    """``G (+)= weight relu(relu(excitation) - relu(inhibitor (*) g_CS))`` into ``ws.g``.

    One term of :func:`~asnn.retina.approach_map` (a subtracted term has a negative weight).
    """
    _approach_term(excitation, inhibitor, ws.pad, cs_kernel.astype(ws.dtype),
                   ws.dtype.type(weight), bool(first), ws.g)


@njit(**_jit)
def _group(g, out):
    h, w = g.shape
    ninth = g[0, 0] * 0 + 1.0 / 9.0
    for y in range(h):
        a, b, c = g[_reflect(y - 1, h)], g[y], g[_reflect(y + 1, h)]
        o = out[y]
        for x in range(w):
            xm, xp = _reflect(x - 1, w), _reflect(x + 1, w)
            s = (a[xm] + a[x] + a[xp]) + (b[xm] + b[x] + b[xp]) + (c[xm] + c[x] + c[xp])
            o[x] = b[x] * (s * ninth)


def group(g, ws):
    """:func:`~asnn.retina.group`: ``G (G (*) ones(3, 3) / 9)``, into ``ws.g_grouped``."""
    _group(g, ws.g_grouped)
    return ws.g_grouped


# --------------------------------------------------------------------------- attention, u(t)


@njit(**_jit)
def _attend(blur_g, gamma_a, blur_v, gamma_d, g, absolute, mask):
    h, w = g.shape
    total = 0.0
    count = 0
    for y in range(h):
        row = 0.0
        for x in range(w):
            m = blur_g[y, x] > gamma_a and blur_v[y, x] > gamma_d
            mask[y, x] = m
            if m:
                count += 1
                row += abs(g[y, x]) if absolute else g[y, x]
        total += row
    return total, count


def attend(blur_g, gamma_a, blur_v, gamma_d, g, absolute, ws):
    """``M_a M_d`` into ``ws.mask`` and ``sum G M_a M_d`` (or of ``|G|``), in float64.

    Reproduces :func:`~asnn.retina.approach_attention`, :func:`~asnn.retina.direction_attention`'s
    threshold and :func:`~asnn.retina.membrane_potential` (before its scale). Returns
    ``(sum, number of attended pixels)``.
    """
    total, count = _attend(blur_g, float(gamma_a), blur_v, float(gamma_d), g, bool(absolute),
                           ws.mask)
    return total, count
