"""Post-processing for the held-out cases (``extra-ho-*``): any generator's frames under a
lighting change, rain or a dim camera's noise.

:func:`post_scene` runs a generator (:func:`.planar.planar_scene`, :func:`.driving.driving_scene`)
and multiplies its frames by the gains of lighting changes (:func:`.effects.gains`: a drive has
no lighting option of its own) and/or adds rain streaks (:func:`rain_streaks`), leaving the
label as it is. The held-out cases of :mod:`.suite` that use it were designed by a trial on
2026-12-01, written down before any detector ran on them (docs/evaluation.md, "A held-out
generated set").
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import cv2
import numpy as np

from .effects import gains, sensor_noise
from .scene import Scene

__all__ = ["post_scene", "rain_streaks"]


def rain_streaks(frames: np.ndarray, seed: int, count: int = 70,
                 level: float = 230.0, opacity: float = 0.4) -> np.ndarray:
    """Float frames (T, H, W) with ``count`` new rain streaks a frame: 1-pixel lines slanted a
    quarter off vertical, 6-14 px long at 160 px wide (scaled with the width), blurred
    (sigma 0.7) and laid over the frame at ``opacity`` of ``level``. Deterministic in ``seed``.
    """
    rng = np.random.default_rng(seed)
    out = frames.astype(np.float64, copy=True)
    _, height, width = out.shape
    scale = width / 160.0
    for k in range(len(out)):
        layer = np.zeros((height, width), np.float32)
        xs = rng.uniform(-10, width + 10, count)
        ys = rng.uniform(-10, height, count)
        lengths = rng.uniform(6, 14, count) * scale
        for x, y, n in zip(xs, ys, lengths):
            cv2.line(layer, (int(x), int(y)), (int(x + 0.25 * n), int(y + n)), 1.0, 1,
                     cv2.LINE_AA)
        cover = np.clip(cv2.GaussianBlur(layer, (0, 0), 0.7), 0.0, 1.0) * opacity
        out[k] = out[k] * (1 - cover) + level * cover
    return out


def post_scene(*, base: Callable[..., Scene], lighting: Sequence = (), rain: bool = False,
               post_noise: float = 0.0, **options) -> Scene:
    """``base(**options)`` with its frames multiplied by the ``lighting`` changes' gains and,
    with ``rain``, rain streaks added (seeded from ``options["seed"]``), and with
    ``post_noise``, a camera's sensor noise after both; its label as it is.

    Parameters
    ----------
    base : callable
        A scene generator.
    lighting : sequence
        Lighting changes (:class:`.effects.Ramp`, :class:`.effects.Flicker`, ...).
    rain : bool
        Whether to add rain streaks (:func:`rain_streaks`).
    post_noise : float
        Standard deviation of the per-frame Gaussian sensor noise added after the lighting and
        the rain, before rounding, gray levels (seeded from ``options["seed"]``). Not
        ``noise``: that is a generator's own option (:func:`.surface.corridor_scene` draws its
        noise before the lighting dims it).
    **options
        The generator's options.
    """
    scene = base(**options)
    frames = scene.frames.astype(np.float64)
    if lighting:
        frames = frames * gains(lighting, len(frames), scene.fps)[:, None, None]
    if rain:
        frames = rain_streaks(frames, options.get("seed", 0) + 99)
    # a dim camera's noise is its sensor's, not dimmed with the scene
    frames = sensor_noise(frames, post_noise, options.get("seed", 0) + 101)
    # the key only where there is such noise: every scene without it keeps its parameters
    noise = {"post_noise": post_noise} if post_noise else {}
    return replace(scene, frames=np.clip(np.rint(frames), 0, 255).astype(np.uint8),
                   params={**scene.params, "post_lighting": [repr(g) for g in lighting],
                           "rain": rain, **noise})
