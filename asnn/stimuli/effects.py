"""Camera motion and image effects for generated clips.

Camera motions (:class:`Shake`, :class:`Pan`, :class:`Sweep`) give each frame a rigid
displacement of the whole image, ``(dx, dy, angle)``: the content seen at rest is rotated by
``angle`` about the frame centre and shifted by ``(dx, dy)`` (:func:`camera_matrix`).
Lighting (:class:`Ramp`, :class:`Flicker`, :class:`Step`) scales each frame's brightness by a gain,
as exposure or the light on the scene changes; :class:`Headlights` adds a bright soft blob that
sweeps across. :func:`sensor_noise` and :func:`jpeg` model the sensor and the codec, and
:func:`camera_rig` what a dashcam shows of its own car and its overlay.

Every effect is deterministic: random ones take a ``seed``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache

import cv2
import numpy as np

__all__ = [
    "Shake",
    "Pan",
    "Sweep",
    "Ramp",
    "Flicker",
    "Step",
    "Headlights",
    "scaled_point",
    "scaled_size",
    "camera_path",
    "camera_matrix",
    "canvas_margins",
    "transform_points",
    "gains",
    "sensor_noise",
    "jpeg",
    "camera_rig",
    "wiper",
    "WIPER_PERIOD",
]


# --------------------------------------------------------------------------- camera motion


@dataclass(frozen=True)
class Shake:
    """Camera shake: a random displacement and rotation in every frame.

    Attributes
    ----------
    amplitude : float
        Largest displacement along x and along y, pixels.
    rotation_deg : float
        Largest rotation, degrees.
    smooth : int
        Frames over which the random path is averaged: 1 is an independent jitter every frame
        (vibration), larger values a slower sway (a hand-held camera). The path is rescaled so
        ``amplitude`` and ``rotation_deg`` stay the largest values.
    seed : int
    """

    amplitude: float
    rotation_deg: float = 0.0
    smooth: int = 1
    seed: int = 0

    def scaled(self, scale: float) -> "Shake":
        """The same shake seen with ``scale`` times the pixels."""
        return replace(self, amplitude=self.amplitude * scale)

    def path(self, frames: int, fps: float) -> np.ndarray:
        rng = np.random.default_rng(self.seed)
        raw = rng.uniform(-1.0, 1.0, size=(frames + self.smooth - 1, 3))
        kernel = np.ones(self.smooth) / self.smooth
        path = np.stack([np.convolve(raw[:, i], kernel, mode="valid") for i in range(3)], axis=1)
        path /= np.maximum(np.abs(path).max(axis=0), 1e-12)
        return path * [self.amplitude, self.amplitude, math.radians(self.rotation_deg)]


@dataclass(frozen=True)
class Pan:
    """A pan or tilt: the image content moves at a constant velocity from ``start``.

    Attributes
    ----------
    velocity : (vx, vy)
        Pixels per frame (a camera turning right moves the content left: ``vx < 0``).
    start : int
    """

    velocity: tuple[float, float]
    start: int = 0

    def scaled(self, scale: float) -> "Pan":
        """The same pan seen with ``scale`` times the pixels."""
        return replace(self, velocity=(self.velocity[0] * scale, self.velocity[1] * scale))

    def path(self, frames: int, fps: float) -> np.ndarray:
        steps = np.clip(np.arange(frames) - self.start, 0, None)[:, None]
        return np.hstack([steps * np.asarray(self.velocity, float), np.zeros((frames, 1))])


@dataclass(frozen=True)
class Sweep:
    """A camera sweeping back and forth: sinusoidal displacement.

    Attributes
    ----------
    amplitude : (ax, ay)
        Pixels.
    period_s : float
        Seconds per cycle.
    """

    amplitude: tuple[float, float]
    period_s: float

    def scaled(self, scale: float) -> "Sweep":
        """The same sweep seen with ``scale`` times the pixels."""
        return replace(self, amplitude=(self.amplitude[0] * scale, self.amplitude[1] * scale))

    def path(self, frames: int, fps: float) -> np.ndarray:
        phase = np.sin(2.0 * math.pi * np.arange(frames) / (fps * self.period_s))[:, None]
        return np.hstack([phase * np.asarray(self.amplitude, float), np.zeros((frames, 1))])


def scaled_point(point: Sequence[float], scale: float) -> tuple[float, float]:
    """An image position ``(x, y)`` in pixels, seen with ``scale`` times the pixels: pixel
    centres sit at whole coordinates, so the frame centre ``(w - 1) / 2`` goes to
    ``(scale w - 1) / 2``."""
    return tuple((float(v) + 0.5) * scale - 0.5 for v in point)


def scaled_size(size: Sequence[int], scale: float) -> tuple[int, int]:
    """A frame size ``(width, height)`` seen with ``scale`` times the pixels, rounded."""
    return round(size[0] * scale), round(size[1] * scale)


def camera_path(motion, frames: int, fps: float) -> np.ndarray:
    """Per-frame ``(dx, dy, angle)`` of a camera motion (zeros for None), shape (T, 3)."""
    if motion is None:
        return np.zeros((frames, 3))
    return np.asarray(motion.path(frames, fps), dtype=np.float64)


def _center(size: tuple[int, int]) -> np.ndarray:
    w, h = size
    return np.array([(w - 1) / 2.0, (h - 1) / 2.0])


def canvas_margins(path: np.ndarray, size: tuple[int, int]) -> tuple[int, int, int, int]:
    """(left, top, right, bottom) pixels the rest view must extend by so the moving frame never
    sees past its edge (plus 2 for the interpolation)."""
    w, h = size
    slack = float(np.abs(path[:, 2]).max()) * math.hypot(w, h) / 2.0 + 2.0
    dx, dy = path[:, 0], path[:, 1]
    return tuple(int(math.ceil(max(v, 0.0) + slack))
                 for v in (dx.max(), dy.max(), -dx.min(), -dy.min()))


def camera_matrix(dx: float, dy: float, angle: float, size: tuple[int, int],
                  origin: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """The 2x3 affine map from canvas pixels to frame pixels.

    ``p = R(angle) (q - origin - c) + c + (dx, dy)``, with ``c`` the frame centre and ``origin``
    the position of the frame's rest view on the canvas.
    """
    c = _center(size)
    cos, sin = math.cos(angle), math.sin(angle)
    rot = np.array([[cos, -sin], [sin, cos]])
    shift = c + np.array([dx, dy]) - rot @ (np.asarray(origin, float) + c)
    return np.hstack([rot, shift[:, None]])


def transform_points(points: np.ndarray, path: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Where points of the rest view (T, 2) appear in each frame of a camera path (T, 3)."""
    c = _center(size)
    rel = points - c
    cos, sin = np.cos(path[:, 2]), np.sin(path[:, 2])
    x = cos * rel[:, 0] - sin * rel[:, 1] + c[0] + path[:, 0]
    y = sin * rel[:, 0] + cos * rel[:, 1] + c[1] + path[:, 1]
    return np.stack([x, y], axis=1)


# --------------------------------------------------------------------------- lighting


@dataclass(frozen=True)
class Ramp:
    """Brightness changing linearly from ``gain0`` (until ``start``) to ``gain1`` (from ``stop``)."""

    start: int
    stop: int
    gain0: float
    gain1: float

    def gains(self, frames: int, fps: float) -> np.ndarray:
        t = np.clip((np.arange(frames) - self.start) / max(self.stop - self.start, 1), 0.0, 1.0)
        return self.gain0 + (self.gain1 - self.gain0) * t


@dataclass(frozen=True)
class Flicker:
    """Brightness flickering by ``depth`` (gain ``1 +- depth``).

    Attributes
    ----------
    frequency_hz : float
        Of the sinusoid (``waveform='sine'``); ignored for ``'random'``, where each frame draws
        its own gain (an unstable light or auto-exposure hunting).
    depth : float
    waveform : {'sine', 'random'}
    seed : int
    """

    frequency_hz: float
    depth: float
    waveform: str = "sine"
    seed: int = 0

    def gains(self, frames: int, fps: float) -> np.ndarray:
        if self.waveform == "random":
            return 1.0 + self.depth * np.random.default_rng(self.seed).uniform(-1, 1, frames)
        if self.waveform != "sine":
            raise ValueError(f"unknown flicker waveform {self.waveform!r}")
        return 1.0 + self.depth * np.sin(2.0 * math.pi * self.frequency_hz * np.arange(frames) / fps)


@dataclass(frozen=True)
class Step:
    """An exposure step: the gain jumps from 1 to ``gain`` at ``frame``."""

    frame: int
    gain: float

    def gains(self, frames: int, fps: float) -> np.ndarray:
        return np.where(np.arange(frames) < self.frame, 1.0, self.gain)


@dataclass(frozen=True)
class Headlights:
    """A bright soft blob (light of a passing car's headlights) sweeping across the image.

    The blob ``amplitude * exp(-d^2 / (2 sigma^2))`` is added to the image, its centre moving
    linearly from ``start_xy`` (at frame ``start``) to ``stop_xy`` (at ``stop``); absent outside.
    """

    start: int
    stop: int
    start_xy: tuple[float, float]
    stop_xy: tuple[float, float]
    sigma: float = 25.0
    amplitude: float = 120.0

    def scaled(self, scale: float) -> "Headlights":
        """The same headlights seen with ``scale`` times the pixels."""
        return replace(self, start_xy=scaled_point(self.start_xy, scale),
                       stop_xy=scaled_point(self.stop_xy, scale), sigma=self.sigma * scale)

    def glow(self, index: int, shape: tuple[int, int]) -> np.ndarray | None:
        if not self.start <= index <= self.stop:
            return None
        a = (index - self.start) / max(self.stop - self.start, 1)
        cx = self.start_xy[0] + a * (self.stop_xy[0] - self.start_xy[0])
        cy = self.start_xy[1] + a * (self.stop_xy[1] - self.start_xy[1])
        h, w = shape
        gx = np.exp(-0.5 * ((np.arange(w) - cx) / self.sigma) ** 2)
        gy = np.exp(-0.5 * ((np.arange(h) - cy) / self.sigma) ** 2)
        return self.amplitude * gy[:, None] * gx[None, :]


def gains(lighting: Sequence, frames: int, fps: float) -> np.ndarray:
    """The product of the gains of every lighting change (ones where there is none), (T,)."""
    total = np.ones(frames)
    for change in lighting:
        if hasattr(change, "gains"):
            total = total * change.gains(frames, fps)
    return total


# --------------------------------------------------------------------------- sensor and codec


def sensor_noise(clip: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """Add independent Gaussian noise of ``sigma`` gray levels to every pixel of a float clip."""
    if sigma < 0:
        raise ValueError(f"noise sigma must be >= 0, got {sigma}")
    if sigma == 0:
        return clip
    return clip + np.random.default_rng(seed).normal(0.0, sigma, clip.shape)


def jpeg(clip: np.ndarray, quality: int) -> np.ndarray:
    """Re-encode every uint8 frame (gray or colour) as JPEG at ``quality`` (1-100) and decode it
    again.

    Raises
    ------
    ValueError
        For a quality outside 1..100.
    """
    if not 1 <= quality <= 100:
        raise ValueError(f"JPEG quality must lie in 1..100, got {quality}")
    out = np.empty_like(clip)
    for i, frame in enumerate(clip):
        ok, data = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        if not ok:
            raise ValueError("JPEG encoding failed")
        out[i] = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    return out


# --------------------------------------------------------------------------- the camera's rig

@lru_cache(maxsize=8)
def camera_rig(size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """What a dashcam shows of its own car and its recorder, the same in every frame: the hood
    along the bottom, a dark surface under an arc (16 % of the height at the middle, 9 % at
    the sides) with a bright rim where it meets the road, and a white timestamp in the bottom
    right corner.

    Parameters
    ----------
    size : (width, height)

    Returns
    -------
    covered : ndarray (height, width) bool
        The pixels the rig covers.
    values : ndarray (height, width) float
        Their gray levels (0..255; meaningless elsewhere).

    Both are made once per size (every frame of a clip shares them) and are read-only.
    """
    w, h = size
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    u = (xs - 0.5 * (w - 1)) / (0.5 * w)
    edge = h * (1.0 - 0.09 - 0.07 * (1.0 - u * u))
    rim = np.abs(ys - edge) < 1.0
    covered = (ys >= edge) | rim
    values = 38.0 + 14.0 * (ys - edge) / (0.16 * h)  # shaded toward the camera
    values[rim] = 120.0
    text = np.zeros((h, w), np.uint8)
    cv2.putText(text, "2026/11/24 08:00", (int(0.55 * w), int(0.97 * h)),
                cv2.FONT_HERSHEY_SIMPLEX, max(0.25, h / 600), 255, 1, cv2.LINE_AA)
    lettered = text > 0
    values[lettered] = 235.0
    covered = covered | lettered
    covered.setflags(write=False)
    values.setflags(write=False)
    return covered, values


# --------------------------------------------------------------------------- a windscreen wiper

WIPER_PERIOD = 40  # frames of one wipe: up in 10, back in 10, parked for 20 (2 s at 20 fps)
_WIPER_SWEEP = 10  # frames each way
_WIPER_ARC = math.radians(150.0)  # from parked along the bottom to up and to the left


def wiper(size: tuple[int, int], index: int) -> np.ndarray:
    """A windscreen wiper's blade in front of a dashcam in frame ``index``: its opacity.

    The blade pivots below the frame's bottom edge, a fifth of the width from the left, and is
    1.3 times the frame's diagonal long. In each :data:`WIPER_PERIOD` frames it sweeps up
    through 150 degrees in 10 frames and back in 10 (eased at both ends, as a wiper's crank
    moves it), then rests below the frame for 20. Close to the lens it is out of focus: a dark
    band 6 % of the width thick, its edges blurred over a fortieth of the width.

    Parameters
    ----------
    size : (width, height)
    index : int
        The frame's index in its clip.

    Returns
    -------
    ndarray (height, width) float32
        The blade's opacity, 0..0.9 (0 where the blade is parked below the frame); made once
        per size and position (every wipe repeats them) and read-only.
    """
    phase = index % WIPER_PERIOD
    # the way back passes the way up's positions: one blade per step of the sweep
    return _blade(tuple(size), min(phase, 2 * _WIPER_SWEEP - phase)
                  if phase < 2 * _WIPER_SWEEP else _WIPER_SWEEP + 1)


@lru_cache(maxsize=64)
def _blade(size: tuple[int, int], step: int) -> np.ndarray:
    """The blade's opacity ``step`` frames into its sweep (beyond the sweep: parked)."""
    w, h = size
    if step > _WIPER_SWEEP:
        blade = np.zeros((h, w), np.float32)
        blade.setflags(write=False)
        return blade
    s = step / _WIPER_SWEEP
    angle = _WIPER_ARC * 0.5 * (1.0 - math.cos(math.pi * s))  # 0: along the bottom, to the right
    pivot = np.array([0.2 * w, 1.15 * h])
    tip = pivot + 1.3 * math.hypot(w, h) * np.array([math.cos(angle), -math.sin(angle)])
    blade = np.zeros((h, w), np.float32)
    thickness = max(1, round(0.06 * w))
    cv2.line(blade, tuple(int(round(v)) for v in pivot), tuple(int(round(v)) for v in tip),
             0.9, thickness, cv2.LINE_AA)
    blade = cv2.GaussianBlur(blade, (0, 0), max(0.5, w / 40 / 2))
    blade.setflags(write=False)
    return blade
