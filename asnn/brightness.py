"""Global brightness compensation: fast changes of the whole view's brightness divided out.

A lamp's flicker aliased at the frame rate (100 Hz mains light seen at 30 fps flickers at
10 Hz), an exposure step, the lights switched off or a tunnel's exit multiply every pixel of a
frame by about the same factor. The photoreceptors' frame difference (paper eq. 1) then covers
the whole view, and an approaching object's own change is lost in it. Photoreceptors adapt to
the mean light, so that what the retina passes on is contrast rather than light [1]_ [2]_, and a
film or video deflicker equalises each frame's mean brightness against a reference that moves
slowly [3]_.

This stage measures each frame's brightness against the previous frame's as the median ratio
of the two over a fixed random sample of their pixels (:func:`sampled`, :func:`global_change`):
an object covering a minority of the view does not move the median, and a change is taken only
where most of the pixels counted (``AGREEMENT``) changed the same way, as a change of the light
moves them all, while a pattern sliding by or an object's own motion brightens about as many
pixels as it darkens. The frame is then scaled by the running product of the inverse changes,
which leaks back to 1 with a time constant in seconds (:func:`compensation_step`): a fast change
is divided out at once and the level returns to the camera's own over a few time constants,
slowly enough that the retina sees no change; a slow ramp (dusk, a cloud) passes. The level
does not stay above the camera's own, so unlike a light-adapted gain it does not lift a night
scene's noise for good. Pixels near black (noise) or near white (clipped: a saturated sky does
not follow the light) are not counted, and where too few are left (a dark object filling the
view at contact) the frame's change is taken as none.

References
----------
.. [1] R. A. Normann, F. S. Werblin, "Control of retinal sensitivity. I. Light and dark
   adaptation of vertebrate rods and cones", J. Gen. Physiol. 63, 1974, pp. 37-61.
.. [2] D. A. Clark, R. Benichou, M. Meister, R. Azeredo da Silveira, "Dynamical adaptation in
   photoreceptors", PLoS Comput. Biol. 9(11), 2013, e1003289.
.. [3] P. M. B. van Roosmalen, R. L. Lagendijk, J. Biemond, "Correction of intensity flicker in
   old film sequences", IEEE Trans. Circuits Syst. Video Technol. 9(7), 1999, pp. 1013-1019.
"""

from __future__ import annotations

import functools
import math

import numpy as np

# pixels outside [DARK, BRIGHT] ([0, 1] intensity) are not counted: near black a ratio is the
# sensor's noise, near white the pixels are clipped and do not follow the light
DARK = 8.0 / 255
BRIGHT = 247.0 / 255
# the change is measured only where at least this fraction of the sampled pixels is counted
MIN_SHARE = 0.25
# ... and where at least this fraction of them changed in the median's direction: a change of
# the light moves every pixel one way, a pattern sliding by or an object's own motion moves about
# as many up as down
AGREEMENT = 0.75
# a gain within this of 1 (log) is 1: the compensation, once it has leaked away, leaves the frames
# as the camera gave them, bit for bit (0.001 is a quarter of a gray level at white)
NEGLIGIBLE = 1e-3
# the gain's log stays within this either way (31x): the largest change one frame can be
# measured to make, a pixel counted as dark scaled to white. A change taken at once and undone
# where no three quarters of the view agreed (darkened as a whole, then lit again part by part)
# ran it up without bound, e^22 with a 1 s time constant, and at 60 s math.exp overflowed
MAX_LOG_GAIN = math.log(BRIGHT / DARK)
# the pixels compared: this many, at fixed places drawn at random over the frame (a regular
# lattice aliases a periodic pattern: stripes whose period divides its step look the same at
# every sampled pixel, and their sliding would read as a change of the light)
SAMPLES = 2048


@functools.lru_cache(maxsize=8)
def _sample_places(size: int) -> np.ndarray:
    if size <= SAMPLES:
        return np.arange(size)
    places = np.random.default_rng(0).choice(size, SAMPLES, replace=False)
    places.sort()  # read in memory order
    places.flags.writeable = False
    return places


def sampled(lum: np.ndarray) -> np.ndarray:
    """The pixels of a frame that :func:`global_change` compares: ``SAMPLES`` of them at fixed
    places drawn at random (all of a smaller frame), so that its cost does not grow with the
    frame and no periodic pattern is seen at one phase only."""
    return lum.reshape(-1).take(_sample_places(lum.size))


def global_change(current: np.ndarray, previous: np.ndarray) -> float:
    """The change of the whole view's brightness from ``previous`` to ``current``, as a log
    ratio: ``log`` of the median over the pixels both frames hold between ``DARK`` and
    ``BRIGHT`` of ``current / previous``. 0.0 where fewer than ``MIN_SHARE`` of the pixels
    are counted, or fewer than ``AGREEMENT`` of them changed in the median's direction.

    Parameters
    ----------
    current, previous : ndarray
        Two frames' samples (:func:`sampled`), [0, 1] intensity, of one shape.

    Returns
    -------
    float
        ``log(s)``, where the frame is about ``s`` times as bright as the previous one.
    """
    ok = (current >= DARK) & (current <= BRIGHT) & (previous >= DARK) & (previous <= BRIGHT)
    count = int(np.count_nonzero(ok))
    if count == 0 or count < MIN_SHARE * current.size:
        return 0.0
    ratio = current[ok] / previous[ok]
    median = float(np.partition(ratio, count // 2)[count // 2])  # the upper one of an even count
    if median == 1.0:
        return 0.0
    agreeing = np.count_nonzero(ratio > 1.0 if median > 1.0 else ratio < 1.0)
    if agreeing < AGREEMENT * count:
        return 0.0
    return math.log(median)


def compensation_step(log_gain: float, change: float, elapsed: float, tau: float) -> float:
    """The compensating gain's log after a frame whose brightness changed by ``change`` (a log
    ratio, :func:`global_change`): the change divided out, and the gain leaked toward 1 by
    ``exp(-elapsed / tau)``, a first-order high-pass filter of the view's log brightness,
    bounded to ``MAX_LOG_GAIN`` either way.

    Parameters
    ----------
    log_gain : float
        The gain's log before the frame (0: the camera's own level).
    change : float
        The frame's brightness against the previous frame's, log ratio.
    elapsed : float
        Seconds since the previous frame.
    tau : float
        The time constant, seconds, with which the gain returns to 1.

    Returns
    -------
    float
        The log of the factor to scale the frame by, within ``MAX_LOG_GAIN`` of 0; 0.0
        within ``NEGLIGIBLE`` of it.
    """
    log_gain = (log_gain - change) * math.exp(-elapsed / tau)
    log_gain = min(max(log_gain, -MAX_LOG_GAIN), MAX_LOG_GAIN)
    return 0.0 if abs(log_gain) < NEGLIGIBLE else log_gain
