"""Anti-aliased drawing on float gray images: objects, periodic patterns and noise textures.

Every function draws by area coverage (the fraction of each pixel an edge covers), so sub-pixel
growth and motion change the image smoothly, as a camera would see them. Pixel ``i`` is centred
on coordinate ``i`` (the OpenCV and target convention: x = column, y = row).

Gray levels are floats on the 0..255 scale; a Weber contrast ``c`` between a target and its
background means ``|I_target - I_background| = 255 c``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "SHAPES",
    "levels",
    "car_levels",
    "car_lamps",
    "paint_disk",
    "paint_box",
    "paint_ellipse",
    "paint_object",
    "square_wave",
    "pattern",
    "noise_tile",
    "sample_tile",
]

SHAPES = ("disk", "ellipse", "square", "rect", "car")

# a car seen from behind or the front, as fractions of its image height h and width w: the window
# band (dark glass) and the two lamps (light)
_WINDOW = dict(dy=-0.2, width=0.76, height=0.3)
_LAMP = dict(dx=0.36, dy=0.15, width=0.16, height=0.12)


def levels(contrast: float, polarity: str, mid: float = 127.5) -> tuple[float, float]:
    """(background, target) gray levels for a Weber contrast, centred on ``mid``.

    Parameters
    ----------
    contrast : float
        ``|I_target - I_background| / 255``, in [0, 1].
    polarity : {'dark', 'light'}
        A dark target on a light background, or the reverse.
    mid : float
        The level halfway between the two.

    Raises
    ------
    ValueError
        For a contrast outside [0, 1], an unknown polarity, or levels outside 0..255.
    """
    if not 0.0 <= contrast <= 1.0:
        raise ValueError(f"contrast must lie in [0, 1], got {contrast}")
    if polarity not in ("dark", "light"):
        raise ValueError(f"polarity must be 'dark' or 'light', got {polarity!r}")
    delta = contrast * 255.0
    light, dark = mid + delta / 2, mid - delta / 2
    if dark < 0.0 or light > 255.0:
        raise ValueError(f"contrast {contrast} around mid level {mid} leaves 0..255")
    return (light, dark) if polarity == "dark" else (dark, light)


def car_levels(body: float) -> tuple[float, float]:
    """(window, lamps) gray levels of a car whose body has level ``body``.

    The window band is darker than the body (glass reflecting little), the lamps lighter (tail
    lights by day, head or tail lights at night), so a car has internal edges of both signs.
    """
    return 0.45 * body, body + 0.6 * (255.0 - body)


def car_lamps(cx: float, cy: float, width: float, height: float) -> list[tuple[float, float]]:
    """Image centres of the two lamps of a car drawn at (cx, cy) with this width and height."""
    y = cy + _LAMP["dy"] * height
    return [(cx - _LAMP["dx"] * width, y), (cx + _LAMP["dx"] * width, y)]


def _pixel_range(lo: float, hi: float, n: int) -> slice:
    """The pixels (centred on integers) whose centres may lie in the interval (lo, hi)."""
    return slice(min(max(int(math.floor(lo)), 0), n), max(min(int(math.ceil(hi)) + 1, n), 0))


def _blend(image: np.ndarray, rows: slice, cols: slice, coverage: np.ndarray, level: float) -> None:
    region = image[rows, cols]
    region += coverage * (level - region)


def paint_disk(image: np.ndarray, cx: float, cy: float, radius: float, level: float) -> None:
    """Paint a disk in place, anti-aliased (coverage ``clip(radius - d + 0.5, 0, 1)``).

    Parameters
    ----------
    image : ndarray (H, W), float
    cx, cy : float
        Centre, pixels (may lie outside the image).
    radius : float
    level : float
        Gray level of the disk.
    """
    if not radius > 0:
        return
    h, w = image.shape
    rows = _pixel_range(cy - radius - 0.5, cy + radius + 0.5, h)
    cols = _pixel_range(cx - radius - 0.5, cx + radius + 0.5, w)
    if rows.start >= rows.stop or cols.start >= cols.stop:
        return
    y = np.arange(rows.start, rows.stop, dtype=np.float64)[:, None]
    x = np.arange(cols.start, cols.stop, dtype=np.float64)[None, :]
    coverage = np.clip(radius - np.hypot(x - cx, y - cy) + 0.5, 0.0, 1.0)
    _blend(image, rows, cols, coverage, level)


def _interval_coverage(start: int, stop: int, lo: float, hi: float) -> np.ndarray:
    centres = np.arange(start, stop, dtype=np.float64)
    return np.clip(np.minimum(centres + 0.5, hi) - np.maximum(centres - 0.5, lo), 0.0, 1.0)


def paint_box(image: np.ndarray, cx: float, cy: float, width: float, height: float,
              level: float) -> None:
    """Paint an axis-aligned rectangle in place, anti-aliased (exact pixel coverage).

    Parameters
    ----------
    image : ndarray (H, W), float
    cx, cy : float
        Centre, pixels.
    width, height : float
    level : float
    """
    if not (width > 0 and height > 0):
        return
    h, w = image.shape
    left, right, top, bottom = cx - width / 2, cx + width / 2, cy - height / 2, cy + height / 2
    rows, cols = _pixel_range(top - 0.5, bottom + 0.5, h), _pixel_range(left - 0.5, right + 0.5, w)
    if rows.start >= rows.stop or cols.start >= cols.stop:
        return
    coverage = (_interval_coverage(rows.start, rows.stop, top, bottom)[:, None]
                * _interval_coverage(cols.start, cols.stop, left, right)[None, :])
    _blend(image, rows, cols, coverage, level)


def paint_ellipse(image: np.ndarray, cx: float, cy: float, width: float, height: float,
                  level: float) -> None:
    """Paint an axis-aligned ellipse in place, anti-aliased.

    The coverage is ``clip(0.5 - d, 0, 1)`` with ``d`` the distance to the outline estimated as
    ``(r - 1) * |grad r|^-1`` (``r`` the normalised radius), exact for a disk.

    Parameters
    ----------
    image : ndarray (H, W), float
    cx, cy : float
        Centre, pixels.
    width, height : float
        Its axes, pixels.
    level : float
    """
    if not (width > 0 and height > 0):
        return
    h, w = image.shape
    a, b = width / 2, height / 2
    rows = _pixel_range(cy - b - 0.5, cy + b + 0.5, h)
    cols = _pixel_range(cx - a - 0.5, cx + a + 0.5, w)
    if rows.start >= rows.stop or cols.start >= cols.stop:
        return
    dy = (np.arange(rows.start, rows.stop, dtype=np.float64)[:, None] - cy) / b
    dx = (np.arange(cols.start, cols.stop, dtype=np.float64)[None, :] - cx) / a
    r = np.hypot(dx, dy)
    gradient = np.hypot(dx / a, dy / b) / np.maximum(r, 1e-12)  # |grad r|
    coverage = np.clip(0.5 - (r - 1.0) / np.maximum(gradient, 1e-12), 0.0, 1.0)
    _blend(image, rows, cols, coverage, level)


def paint_object(image: np.ndarray, shape: str, cx: float, cy: float, height: float,
                 level: float, aspect: float = 1.0) -> None:
    """Paint one object in place: its image height (a disk's diameter) and centre.

    Parameters
    ----------
    image : ndarray (H, W), float
    shape : {'disk', 'ellipse', 'square', 'rect', 'car'}
        ``ellipse`` and ``rect`` are ``aspect * height`` wide; ``car`` is a box as wide with a
        darker window band and two lighter lamps (:func:`car_levels`).
    cx, cy, height : float
        Centre and image height, pixels.
    level : float
        Gray level of the object (the car's body).
    aspect : float
        Width over height, for ``ellipse``, ``rect`` and ``car``.

    Raises
    ------
    ValueError
        For an unknown shape.
    """
    if shape == "disk":
        paint_disk(image, cx, cy, height / 2, level)
    elif shape == "ellipse":
        paint_ellipse(image, cx, cy, aspect * height, height, level)
    elif shape == "square":
        paint_box(image, cx, cy, height, height, level)
    elif shape in ("rect", "car"):
        width = aspect * height
        paint_box(image, cx, cy, width, height, level)
        if shape == "car":
            window, lamps = car_levels(level)
            paint_box(image, cx, cy + _WINDOW["dy"] * height, _WINDOW["width"] * width,
                      _WINDOW["height"] * height, window)
            for x, y in car_lamps(cx, cy, width, height):
                paint_box(image, x, y, _LAMP["width"] * width, _LAMP["height"] * height, lamps)
    else:
        raise ValueError(f"unknown shape {shape!r}; choose one of {', '.join(SHAPES)}")


def square_wave(s: np.ndarray, period: float, duty: float) -> np.ndarray:
    """Box-filtered periodic stripes along a coordinate ``s``.

    The stripes cover ``[k period, k period + duty period)``; each sample is the fraction of the
    unit window ``[s - 1/2, s + 1/2]`` they cover (exact for stripes across a pixel row, and the
    same variance as the true footprint for oblique ones).
    """
    width = duty * period

    def integral(x):  # length of stripe in [0, x]
        k = np.floor(x / period)
        return k * width + np.clip(x - k * period, 0.0, width)

    return integral(s + 0.5) - integral(s - 0.5)


def pattern(shape: tuple[int, int], kind: str, period: float, angle_deg: float = 0.0,
            offset: tuple[float, float] = (0.0, 0.0), duty: float = 0.5) -> np.ndarray:
    """A periodic pattern in [0, 1], translated by ``offset``.

    Parameters
    ----------
    shape : (H, W)
    kind : {'stripes', 'grating', 'checker'}
        Square-wave stripes (anti-aliased), a sinusoidal grating, or a checkerboard (two stripe
        patterns at right angles, combined by exclusive or).
    period : float
        Pixels per cycle along the pattern's normal.
    angle_deg : float
        Direction of the normal, degrees from the x axis (0: vertical stripes; 90: horizontal).
    offset : (dx, dy)
        The pattern's displacement, pixels.
    duty : float
        Fraction of a period the stripes cover (``stripes``; ``checker`` uses 0.5).

    Raises
    ------
    ValueError
        For an unknown kind or a period below 2 pixels.
    """
    if period < 2.0:
        raise ValueError(f"a pattern period must be at least 2 px, got {period}")
    h, w = shape
    a = math.radians(angle_deg)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    x -= offset[0]
    y -= offset[1]
    s = x * math.cos(a) + y * math.sin(a)
    if kind == "stripes":
        return square_wave(s, period, duty)
    if kind == "grating":
        return 0.5 + 0.5 * np.cos(2.0 * math.pi * s / period)
    if kind == "checker":
        t = -x * math.sin(a) + y * math.cos(a)
        p, q = square_wave(s, period, 0.5), square_wave(t, period, 0.5)
        return p * (1.0 - q) + (1.0 - p) * q
    raise ValueError(f"unknown pattern {kind!r}; choose stripes, grating or checker")


def noise_tile(seed: int, scale: float, size: int = 256, zoom: float = 1.0) -> np.ndarray:
    """A periodic random texture in [-1, 1] (seamless when tiled), from filtered white noise.

    The amplitude spectrum falls as 1/f (natural images) above ``1 / (size / 4)`` and is cut off
    with a Gaussian of ``scale`` pixels, so the texture is smooth at that scale and has coarser
    structure too.

    Parameters
    ----------
    seed : int
    scale : float
        Smallest structure, pixels (at least 0.5).
    size : int
        Side of the square tile.
    zoom : float
        The same texture drawn with ``zoom`` times the pixels: its spectrum is zero-padded to a
        tile ``round(zoom * size)`` pixels wide, so every structure, and the tile's period, is
        ``zoom`` times larger (band-limited interpolation; what the cut-off leaves above the
        original tile's Nyquist frequency is below 1 % at ``scale`` >= 1).
    """
    if scale < 0.5:
        raise ValueError(f"texture scale must be at least 0.5 px, got {scale}")
    if not zoom > 0:
        raise ValueError(f"texture zoom must be positive, got {zoom!r}")
    rng = np.random.default_rng(seed)
    spectrum = np.fft.fft2(rng.standard_normal((size, size)))
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(size), np.fft.fftfreq(size), indexing="ij"))
    spectrum *= np.exp(-0.5 * (2.0 * math.pi * f * scale) ** 2) / np.maximum(f, 4.0 / size)
    tile = np.real(np.fft.ifft2(spectrum))
    tile -= tile.mean()
    peak = np.abs(tile).max()
    zoomed = round(zoom * size)
    if zoomed != size:
        # the same values at the original pixels (ifft2 divides by the number of pixels); the
        # interpolation's few overshoots past the original's peak are clipped
        tile = np.real(np.fft.ifft2(_resized_spectrum(spectrum, zoomed))) * (zoomed / size) ** 2
        tile = np.clip(tile - tile.mean(), -peak, peak)
    return (tile / peak).astype(np.float32)


def _resized_spectrum(spectrum: np.ndarray, n: int) -> np.ndarray:
    """A square FFT's frequencies kept at their indices in an ``n`` x ``n`` one: zeros above
    the smaller side's Nyquist frequency (a larger ``n``), or those frequencies dropped."""
    m = min(spectrum.shape[0], n)
    low, high = (m + 1) // 2, m // 2  # indices 0..low-1 and the last ``high``
    rows = np.r_[0:low, -high:0]
    out = np.zeros((n, n), dtype=spectrum.dtype)
    out[np.ix_(rows, rows)] = spectrum[np.ix_(rows, rows)]
    return out


def sample_tile(tile: np.ndarray, shape: tuple[int, int],
                offset: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """The periodic ``tile`` repeated over ``shape`` and translated by ``offset`` (bilinear)."""
    import cv2  # here: the parser's scene names come from this package

    h, w = shape
    shift = np.float32([[1, 0, offset[0]], [0, 1, offset[1]]])
    return cv2.warpAffine(tile, shift, (w, h), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_WRAP).astype(np.float64)
