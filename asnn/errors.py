"""The model's errors, in a module of their own (no OpenCV, no numba), so that a process that
only catches them (the service's worker core, imported by the command line's parser) need not
load the model to name them."""

from __future__ import annotations

__all__ = ["FrameError"]


class FrameError(ValueError):
    """A frame the model cannot take: wrong type, shape, range or size.

    Raised by a detector's ``step`` (:meth:`asnn.ASNN.step`, the LGMD baselines') before its
    state changes, for a frame that is not a numpy array (or is a masked one), is neither gray
    nor BGR, is smaller than the model's kernels or not the stream's size, is neither uint8 nor
    float, or holds floats outside [0, 1], NaN or infinities (:func:`asnn.frames.check_frame`);
    and for a frame time ``t`` that is not a number of seconds (a str, a bool) or is beyond a
    float's range (``10**400``), as :func:`asnn.frames.frame_time` refuses it. A ValueError:
    code that catches those catches it too.
    """
