"""Validation and conversion of input frames to the luminance the retina works on."""

from __future__ import annotations

import numbers

import cv2
import numpy as np

from .errors import FrameError

__all__ = ["FrameError", "LEVELS", "check_frame", "frame_time", "luma", "to_luminance"]

_LUMA = np.array([0.114, 0.587, 0.299])  # B, G, R weights of OpenCV's BGR -> gray
# how far outside [0, 1] a float frame may stray by its own rounding (cv2.normalize to [0, 1]
# in float32 gives up to 1e-5 out), clipped back; a frame on 0..255 is still refused
FLOAT_SLACK = 1e-4
LEVELS = np.arange(256) / 255.0  # uint8 value -> luminance: one table look-up per pixel


def to_luminance(frame: np.ndarray, min_side: int,
                 stream_shape: tuple[int, int] | None = None, dtype=np.float64) -> np.ndarray:
    """Validate a frame and return its luminance on the [0, 1] scale.

    Parameters
    ----------
    frame : ndarray
        Gray (H, W) or (H, W, 1), or BGR (H, W, 3). uint8 frames are on 0..255; float frames
        must lie in [0, 1]. A BGR uint8 frame is converted with OpenCV's rounded luma
        (0.299 R + 0.587 G + 0.114 B) before scaling, as the published implementation does.
    min_side : int
        Smallest accepted height and width (the largest kernel of the model).
    stream_shape : (H, W), optional
        The stream's frame size, which the frame must have.
    dtype : float dtype
        Of the result: the float64 luminance rounded to it.

    Raises
    ------
    FrameError
        For anything but the above.
    """
    frame = check_frame(frame, min_side, stream_shape)
    if frame.dtype == np.uint8:
        return cv2.LUT(luma(frame), LEVELS.astype(dtype, copy=False))
    gray = frame.astype(np.float64)
    gray = gray @ _LUMA if gray.ndim == 3 else gray
    np.clip(gray, 0.0, 1.0, out=gray)  # a rounding's overshoot (FLOAT_SLACK) taken back
    return gray.astype(dtype, copy=False)


def check_frame(frame: np.ndarray, min_side: int,
                stream_shape: tuple[int, int] | None = None) -> np.ndarray:
    """The frame, (H, W, 1) taken as (H, W), once it passes :func:`to_luminance`'s checks.

    Parameters
    ----------
    frame : ndarray
        Gray (H, W) or (H, W, 1), or BGR (H, W, 3): uint8, or floats in [0, 1].
    min_side : int
        The smallest height and width the detector takes (its kernels' size).
    stream_shape : (int, int), optional
        The stream's (H, W), fixed by its first frame: a frame of another size is refused.

    Returns
    -------
    ndarray
        ``frame``, or its (H, W) view.

    Raises
    ------
    FrameError
        For a frame :func:`to_luminance` does not take.
    """
    if not isinstance(frame, np.ndarray):
        raise FrameError(f"a frame must be a numpy array, got {type(frame).__name__}")
    if isinstance(frame, np.ma.MaskedArray):  # its checks below would skip the masked values
        raise FrameError("a frame must be a plain numpy array, not a masked array: fill it "
                         "(frame.filled(value)) first")
    if frame.ndim == 3 and frame.shape[2] == 1:
        frame = frame[:, :, 0]
    if frame.ndim not in (2, 3) or (frame.ndim == 3 and frame.shape[2] != 3):
        raise FrameError(f"a frame must be gray (H, W) or BGR (H, W, 3), got shape {frame.shape}")
    h, w = frame.shape[:2]
    if stream_shape is not None and (h, w) != tuple(stream_shape):
        sh, sw = stream_shape
        raise FrameError(f"frame {w}x{h} differs from the stream's {sw}x{sh} (one size a "
                         "stream: for another, reset() the model or start a new one)")
    if h < min_side or w < min_side:
        raise FrameError(f"frame {w}x{h} is smaller than the model's {min_side}x{min_side} kernels")
    if frame.dtype == np.uint8:
        return frame
    if frame.dtype.kind != "f":
        raise FrameError(f"frame dtype must be uint8 or float, got {frame.dtype}")
    if not np.isfinite(frame).all():
        raise FrameError("frame contains NaN or infinite values")
    lo, hi = float(frame.min()), float(frame.max())
    if lo < -FLOAT_SLACK or hi > 1.0 + FLOAT_SLACK:
        raise FrameError(f"float frames must lie in [0, 1], got values in [{lo!r}, {hi!r}]")
    return frame


def luma(frame: np.ndarray) -> np.ndarray:
    """The uint8 gray image of a checked uint8 frame: itself, or OpenCV's rounded luma of BGR."""
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame


def frame_time(t: object) -> float:
    """A frame's time ``t`` (seconds) as a float; FrameError for one that is not a real number
    (a str, a bool), before a detector's step changes any state. NaN or infinite times are
    taken: the detectors read them as no usable time."""
    if isinstance(t, bool) or not isinstance(t, numbers.Real):
        raise FrameError(f"a frame's time t must be a number of seconds or None, got {t!r}")
    try:
        return float(t)
    except OverflowError:  # an int beyond any float (10**400)
        raise FrameError("a frame's time t is beyond a float's range (a number of seconds "
                         "or None)") from None
