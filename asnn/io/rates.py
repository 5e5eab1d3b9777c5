"""The frame rates a camera runs at, data only (no OpenCV): the command line's parser quotes
them (``asnn scene -h``); :mod:`asnn.io.video` reads and writes by them."""

from __future__ import annotations

__all__ = ["FPS_RANGE", "MAX_FPS"]

MAX_FPS = 240.0  # above this a stated rate is a container's time base, not a camera's
# the frame rates a camera runs at, for every rate given by hand (a clip's label, --fps): a clip
# written at another would read back at asnn.io.video.DEFAULT_FPS
FPS_RANGE = (1.0, MAX_FPS)
