"""ASNN: the Approach-Sensitive Neural Network for collision detection (numerical core, no I/O)."""

from .frames import FrameError
from .model import ASNN
from .params import ASNNParams, preset, preset_names
from .response import Maps, Response, TrackReport
from .targets import Target

__all__ = ["ASNN", "ASNNParams", "FrameError", "Maps", "Response", "Target", "TrackReport",
           "preset", "preset_names"]
__version__ = "0.1.0"
