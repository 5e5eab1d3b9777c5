"""Generated test video with its ground truth (no video files are shipped).

:mod:`~asnn.stimuli.paper`
    The paper's scenes (``make_scene``, :data:`SCENE_NAMES`): looming, receding and translating
    disks and bars, over translating stripes (Figs. 6, 7 and 9).
:mod:`~asnn.stimuli.planar`
    Composable scenes on the image plane: objects approaching on a collision course, passing
    close, receding, stopping or translating (an animal walking up with its gait), over moving
    patterns and textures, with camera shake and pans, brightness changes, sensor noise and JPEG
    artefacts.
:mod:`~asnn.stimuli.driving`
    Perspective driving scenes: a camera moving over a textured road with roadside objects and
    other vehicles, turns and bumps, by day and by night.
:mod:`~asnn.stimuli.suite`
    The named, versioned, labelled suite of such scenes (``make_case``, :data:`SUITE_CASES`)
    that ``asnn eval --synthetic`` scores.
:mod:`~asnn.stimuli.heldout`
    Any generator's scene under a lighting change or rain (the held-out cases').
:mod:`~asnn.stimuli.render`, :mod:`~asnn.stimuli.effects`, :mod:`~asnn.stimuli.scene`
    Anti-aliased drawing; camera and image effects; the :class:`Scene` (written to a video file by
    :func:`asnn.io.video.write_video`).
"""

from .paper import SCENE_NAMES, make_scene
from .scene import Scene

__all__ = ["Scene", "SCENE_NAMES", "make_scene"]
