"""Textured test images and their motion, shared by the looming and the stabilisation tests."""

from __future__ import annotations

import cv2
import numpy as np


def texture(shape: tuple[int, int] = (120, 160), seed: int = 0, blur: float = 2.0) -> np.ndarray:
    """Uniform noise smoothed by a Gaussian of ``blur`` pixels, float32: gradients everywhere."""
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.random(shape).astype(np.float32), (0, 0), blur)


def warp(image: np.ndarray, scale: float = 1.0, dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    """The image scaled about its centre and shifted, as a camera would see it move (the border
    reflected)."""
    h, w = image.shape
    m = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), 0.0, scale)
    m[:, 2] += (dx, dy)
    return cv2.warpAffine(image, m, (w, h), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REFLECT_101)
