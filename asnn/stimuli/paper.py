"""The synthetic scenes of the paper's experiments (Figs. 6, 7 and 9), generated in code.

Every scene is a :class:`~asnn.stimuli.scene.Scene`: uint8 gray frames plus the ground truth a
scorer needs. Targets are drawn anti-aliased (pixel coverage of the exact disk or bar), so
sub-pixel growth and motion change the image smoothly, as a camera would see them. The drawing
here is kept as it was first written (pixel ``i`` spans ``[i, i + 1)`` for the bar), so these
scenes, and the fixtures made from them, stay the same to the byte.

Scenes (``make_scene(name, ...)``):

``approach_recession``
    A disk expands from ``start`` to ``stop`` and shrinks back from ``stop + hold`` (paper Fig. 6a:
    expands over steps 10-55, shrinks over 75-120 of 130).
``looming`` / ``receding``
    Only the expansion (ends at contact) / only the shrinking.
``translation``
    A bar moves right from ``start`` to ``stop`` and back left after ``hold`` (Fig. 6b).
``translating_bar``
    A bar moving right for the whole clip.
``stripes``
    Vertical stripes translating right for the whole clip, nothing looming.
``looming_over_stripes`` / ``approach_recession_over_stripes``
    The disk scenes in front of translating stripes (Fig. 6c).

Contrast is Weber contrast ``c = |I_target - I_background| / 255``; ``polarity='dark'`` draws a
dark target on a light background, ``'light'`` the reverse.
"""

from __future__ import annotations

import math

import numpy as np

from .render import levels
from .scene import Scene

__all__ = ["SCENE_NAMES", "make_scene"]


def _disk_coverage(h: int, w: int, cx: float, cy: float, radius: float) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w]
    d = np.hypot(x - cx, y - cy)
    return np.clip(radius - d + 0.5, 0.0, 1.0)


def _bar_coverage(h: int, w: int, left: float, width: float, top: float,
                  height: float) -> np.ndarray:
    x = np.arange(w) + 0.5
    y = np.arange(h) + 0.5
    cov_x = np.clip(np.minimum(x + 0.5, left + width) - np.maximum(x - 0.5, left), 0.0, 1.0)
    cov_y = np.clip(np.minimum(y + 0.5, top + height) - np.maximum(y - 0.5, top), 0.0, 1.0)
    return cov_y[:, None] * cov_x[None, :]


def _stripe_coverage(h: int, w: int, offset: float, period: float, width: float) -> np.ndarray:
    x = np.arange(w, dtype=np.float64)
    # coverage of [x, x+1) by stripes [offset + k period, offset + k period + width)
    phase = np.mod(x - offset, period)
    cov = np.clip(width - phase, 0.0, 1.0) + np.clip(phase + 1.0 - period, 0.0, 1.0)
    return np.broadcast_to(np.clip(cov, 0.0, 1.0)[None, :], (h, w))


def _radii(frames: int, start: int, stop: int, hold: int, r0: float, speed: float,
           recede: bool, expand: bool) -> np.ndarray:
    """Disk radius per frame: grows by speed * exp(0.001 t) px/step on [start, stop) (paper)."""
    r = np.full(frames, r0 if expand else np.nan)
    radius = r0
    for t in range(frames):
        if expand and start <= t < stop:
            radius += speed * math.exp(0.001 * t)
        if recede and stop + hold <= t < stop + hold + (stop - start):
            radius -= speed * math.exp(0.001 * (t - hold - (stop - start)))
        r[t] = max(radius, 0.0)
    return r


def make_scene(name: str, *, size: tuple[int, int] = (128, 128), frames: int | None = None,
               contrast: float = 1.0, polarity: str = "dark", speed: float | None = None,
               start: int = 10, stop: int = 55, hold: int = 20, radius: float = 6.0,
               center: tuple[float, float] | None = None, bar: tuple[float, float] = (12.0, 48.0),
               stripe_period: float = 16.0, stripe_width: float = 4.0,
               stripe_speed: float = 2.0, fps: float = 20.0) -> Scene:
    """Generate one of the paper's synthetic scenes.

    Parameters
    ----------
    name : str
        One of :data:`SCENE_NAMES`.
    size : (width, height)
    frames : int, optional
        Clip length; defaults to 130 for the two-phase scenes (the paper's T), ``stop + 5`` for
        ``looming``, and 70 otherwise.
    contrast : float
        Weber contrast of the target (and of the stripes), in [0, 1].
    polarity : {'dark', 'light'}
    speed : float, optional
        Edge speed in px/step: the disk's radius growth rate (default 1) or the bar's speed
        (default 2).
    start, stop, hold : int
        The motion runs over frames [start, stop); two-phase scenes reverse after ``hold`` frames.
        A collision's onset is ``start`` and its contact ``stop``, or the first frame the disk
        fills the view where it does so sooner (a fast ``speed``).
    radius : float
        Initial disk radius.
    center : (x, y), optional
        Disk centre or the bar's starting centre; defaults to the image centre (for the bar, the
        left quarter).
    bar : (width, height)
    stripe_period, stripe_width, stripe_speed : float
        Background stripes (px, px, px/step to the right).
    fps : float

    Returns
    -------
    Scene
    """
    if name not in SCENE_NAMES:
        raise ValueError(f"unknown scene {name!r}; choose one of {', '.join(SCENE_NAMES)}")
    w, h = size
    if w < 8 or h < 8:
        raise ValueError(f"scene size must be at least 8x8, got {w}x{h}")
    if not 0 <= start < stop:
        raise ValueError("need 0 <= start < stop")
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps}")
    if speed is not None and not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be a positive number of px a step, got {speed}")
    two_phase = name in ("approach_recession", "translation", "approach_recession_over_stripes")
    if frames is None:
        frames = 130 if two_phase else (stop + 5 if name in ("looming", "looming_over_stripes")
                                        else 70)
    background, target = levels(contrast, polarity)
    cx, cy = center if center is not None else (w / 2.0, h / 2.0)
    params = dict(size=size, frames=frames, contrast=contrast, polarity=polarity, speed=speed,
                  start=start, stop=stop, hold=hold, radius=radius, center=center, bar=bar,
                  stripe_period=stripe_period, stripe_width=stripe_width,
                  stripe_speed=stripe_speed, fps=fps)

    images = np.empty((frames, h, w), dtype=np.float64)
    stripes = name in ("stripes", "looming_over_stripes", "approach_recession_over_stripes")
    disk = name in ("approach_recession", "looming", "receding", "looming_over_stripes",
                    "approach_recession_over_stripes")
    if disk:
        rate = 1.0 if speed is None else speed
        radii = _radii(frames, start, stop, hold, radius, rate, two_phase, True)
        if name == "receding":  # shrinks from the fully grown size by the same steps
            radii = radii[-1] - (radii - radius)
    for t in range(frames):
        img = np.full((h, w), background)
        if stripes:
            cov = _stripe_coverage(h, w, stripe_speed * t, stripe_period, stripe_width)
            img += cov * (target - background)
        if disk:
            cov = _disk_coverage(h, w, cx, cy, radii[t])
            img += cov * (target - img)
        if name in ("translation", "translating_bar"):
            bw, bh = bar
            v = 2.0 if speed is None else speed
            x0 = (center[0] if center else w / 4.0) - bw / 2
            steps = min(max(t - start, 0), stop - start)
            left = x0 + v * steps
            if name == "translation" and t >= stop + hold:
                left -= v * min(t - stop - hold, stop - start)
            if name == "translating_bar":
                left = x0 + v * t
            cov = _bar_coverage(h, w, left, bw, cy - bh / 2, bh)
            img += cov * (target - img)
        images[t] = img
    clip = np.clip(np.rint(images), 0, 255).astype(np.uint8)

    collision = disk and name != "receding"
    contact = stop
    if collision:  # a disk that fills the view before it stops growing has reached the camera
        reach = max(math.hypot(x - cx, y - cy) for x in (0, w) for y in (0, h))
        full = np.flatnonzero(radii[:stop + 1] >= reach)
        if len(full):
            contact = max(int(full[0]), start)
    return Scene(name=name, frames=clip, fps=fps, collision=collision,
                 onset_frame=start if collision else None,
                 contact_frame=contact if collision else None,
                 center=(cx, cy) if collision else None, params=params)


SCENE_NAMES = ("approach_recession", "looming", "receding", "translation", "translating_bar",
               "stripes", "looming_over_stripes", "approach_recession_over_stripes")
