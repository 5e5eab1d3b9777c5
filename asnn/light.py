"""Light adaptation of the contrast gain control's semi-saturation (this project; in the default
preset since 2026-12-01 with ``contrast_light`` 0.3 and ``contrast_light_spread`` 3, off in the
others: ``ASNNParams.contrast_light``).

The contrast gain control (:func:`asnn.retina.contrast_gain_control`) divides each change by
``c + g_pool * |P|``. Its ``c`` is fixed in intensity units, so a view at a third of the day's
light, whose changes are a third as large, meets a ``c`` three times as large: the faint parts
of an approach are cut off and the attention masks lose the object. Scaling ``c`` by the light
makes the stage invariant to a camera's overall light (``P' = s k P / (k c + g * k |P|)``), which
is the photoreceptors' light adaptation [1]_ in the form of a Weber law. The view's light is
read as the median of a sample of its pixels (a lamp or a headlight in view moves a mean, not a
median), relative to ``reference``, a lit view's median; it is smoothed over a time constant
and bounded below by ``floor``. A view lit in pools (the upper decile of the sample more than
``spread`` times its median: a night lit by headlights and lamps) keeps the fixed ``c``, where a
lower one lifted the night's noise rather than its signal (docs/design-notes.md, "Light
adaptation of the contrast gain control", and "..., again" for this form).

References
----------
.. [1] F. Rieke, M. E. Rudd, "The challenges natural images pose for visual adaptation",
   Neuron 64, 2009, pp. 605-616.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["LightAdaptation"]


class LightAdaptation:
    """The light-adapted semi-saturation of a stream, frame by frame.

    Parameters
    ----------
    semi_saturation : float
        The fixed ``c`` (``contrast_gain``), the value in a lit view.
    reference : float
        The median luminance ([0, 1]) of a lit view, at and above which ``c`` is fixed.
    floor : float
        The least fraction of ``c`` the light takes it to.
    tau : float
        The time constant, seconds, of the light's smoothing (in log units).
    spread : float or None
        The upper decile's ratio to the median above which the view counts as lit in pools
        (the fixed ``c``); None: no such gate.
    """

    def __init__(self, semi_saturation: float, reference: float, floor: float, tau: float,
                 spread: float | None):
        self.semi_saturation, self.reference, self.floor = semi_saturation, reference, floor
        self.tau, self.spread = tau, spread
        self._log_light: float | None = None

    def light(self, sample: np.ndarray) -> float:
        """The fraction of a lit view's light one frame's sample shows.

        Parameters
        ----------
        sample : ndarray (n,)
            Luminance in [0, 1] at the sampled places.

        Returns
        -------
        float
            The sample's median over ``reference``, in [``floor``, 1]; 1 for a view lit in
            pools.
        """
        n = sample.size
        ordered = np.partition(sample, (n // 2, (9 * n) // 10))
        median, decile = float(ordered[n // 2]), float(ordered[(9 * n) // 10])
        if self.spread is not None and decile > self.spread * max(median, 1e-6):
            return 1.0
        return min(max(median / self.reference, self.floor), 1.0)

    def step(self, sample: np.ndarray, elapsed: float) -> float:
        """The semi-saturation for one frame; the first frame it is given sets the light
        the stream starts adapted to.

        Parameters
        ----------
        sample : ndarray (n,)
            The frame's luminance in [0, 1] at the sampled places.
        elapsed : float
            Seconds since the previous frame stepped.

        Returns
        -------
        float
            ``c`` for this frame: the fixed value times the smoothed light.
        """
        target = math.log(self.light(sample))
        if self._log_light is None:  # a stream starts adapted to its first view
            self._log_light = target
        else:
            keep = math.exp(-elapsed / self.tau)
            self._log_light = keep * self._log_light + (1.0 - keep) * target
        return self.semi_saturation * math.exp(self._log_light)
