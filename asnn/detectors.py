"""One factory for every detector: the ASNN model and the LGMD baselines."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from .model import ASNN
from .params import preset
from .response import Response

__all__ = ["Detector", "MODELS", "make_detector"]

MODELS = ("asnn", "lgmd1", "lgmd2")


class Detector(Protocol):
    """What every model offers: one object per stream."""

    def step(self, frame: np.ndarray, t: float | None = None) -> Response: ...

    def reset(self) -> None: ...


def make_detector(model: str = "asnn", preset_name: str | None = None, **options) -> Detector:
    """Build a detector by name.

    Parameters
    ----------
    model : {'asnn', 'lgmd1', 'lgmd2'}
    preset_name : str, optional
        ASNN preset (ignored by the LGMD models); None means ``default``.
    **options
        Passed to the detector's constructor (for ASNN, e.g. ``record_maps``).

    Raises
    ------
    ValueError
        For an unknown model or preset.
    """
    if model == "asnn":
        return ASNN(preset(preset_name or "default"), **options)
    if model in ("lgmd1", "lgmd2"):
        from . import baselines

        return (baselines.LGMD1 if model == "lgmd1" else baselines.LGMD2)(**options)
    raise ValueError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
