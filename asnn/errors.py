"""The model's errors, in a module of their own (no OpenCV, no numba), so that a process that
only catches them (the service's worker core, imported by the command line's parser) need not
load the model to name them."""

from __future__ import annotations

__all__ = ["FrameError"]


class FrameError(ValueError):
    """A frame the model cannot take: wrong type, shape, range or size."""
