"""The robust preset's object stage: which of the attended pixels come at the camera.

:class:`ApproachStage` (``stage.py``) chains, once per frame, the modules of this package:

``looming.py``
    The direct estimate of a box's expansion and drift from the frames' brightness
    derivatives, the scene's own expansion, and the camera's rig left out of both.
``motion_layers.py``
    A box's dense motion split into its layers (a car and the scenery behind it).
``tracking.py``
    Objects linked across frames, their time to contact and offset, and the approach test.
``surface.py``
    The surface ahead: the whole view expanding as one plane (a wall filling it), which the
    retina's filtering cancels, measured on the frames beside the objects.

The retina (:mod:`asnn.retina`, :class:`asnn.model.ASNN`) hands it each frame's attended mask
and approach map; the paper's own presets do not use it.
"""

from .stage import ApproachStage, CameraRig, FramePair, frame_pixel

__all__ = ["ApproachStage", "CameraRig", "FramePair", "frame_pixel"]
