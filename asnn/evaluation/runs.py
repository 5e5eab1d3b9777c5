"""Running detectors named by a spec over frames, and writing what the runs produce.

A detector spec names one detector to compare: ``asnn`` (the default preset), ``asnn:PRESET``
(for example ``asnn:reference``, the published variant), ``lgmd1`` or ``lgmd2``. Results of a spec
go to a directory named by :attr:`DetectorSpec.slug` (``asnn-reference``: no colon in paths).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..detectors import MODELS, Detector, make_detector
from ..params import preset_key

__all__ = ["DEFAULT_DETECTORS", "DetectorSpec", "parse_detector", "parse_detectors",
           "run_detector", "at_rate", "write_json", "write_jsonl", "fmt", "rate", "outcome_cell"]

DEFAULT_DETECTORS = ("asnn", "asnn:reference", "lgmd1", "lgmd2")


@dataclass(frozen=True)
class DetectorSpec:
    """One detector to run: a model and, for ASNN, a preset (None: the default)."""

    model: str
    preset: str | None = None

    @property
    def name(self) -> str:
        """``asnn``, ``asnn:PRESET``, ``lgmd1`` or ``lgmd2``."""
        return f"{self.model}:{self.preset}" if self.preset else self.model

    @property
    def slug(self) -> str:
        """The name as a directory name (``:`` becomes ``-``)."""
        return self.name.replace(":", "-")

    def make(self) -> Detector:
        """A fresh detector."""
        return make_detector(self.model, self.preset)


def parse_detector(spec: str, default_preset: str | None = None) -> DetectorSpec:
    """Read a detector spec.

    Parameters
    ----------
    spec : str
        ``asnn``, ``asnn:PRESET``, ``lgmd1`` or ``lgmd2``.
    default_preset : str, optional
        The preset a bare ``asnn`` stands for (None or ``default``: the default preset).

    Raises
    ------
    ValueError
        For an unknown model or preset, or a preset given to an LGMD model.
    """
    model, _, preset_name = spec.strip().partition(":")
    if model not in MODELS:
        raise ValueError(f"unknown detector {spec!r}; use asnn, asnn:PRESET, lgmd1 or lgmd2")
    if model != "asnn":
        if preset_name:
            raise ValueError(f"{model} has no presets: {spec!r}")
        return DetectorSpec(model)
    if not preset_name:
        preset_name = default_preset or "default"
    preset_key(preset_name)  # raises for an unknown preset
    return DetectorSpec("asnn", None if preset_name == "default" else preset_name)


def parse_detectors(specs: str | Iterable[str],
                    default_preset: str | None = None) -> list[DetectorSpec]:
    """Read a comma-separated list (or sequence) of specs, dropping repeats.

    Raises
    ------
    ValueError
        For an empty list or a bad spec.
    """
    items = specs.split(",") if isinstance(specs, str) else list(specs)
    parsed = [parse_detector(s, default_preset) for s in items if s.strip()]
    if not parsed:
        raise ValueError("no detector given")
    return list({p.name: p for p in parsed}.values())


def at_rate(frames: Iterable[np.ndarray], fps: float) -> Iterator[tuple[float, np.ndarray]]:
    """``(index / fps, frame)`` for frames without their own times."""
    for index, frame in enumerate(frames):
        yield index / fps, frame


def run_detector(timed_frames: Iterable[tuple[float, np.ndarray]],
                 detector: DetectorSpec | str = "asnn",
                 on_frame: Callable[[], None] | None = None) -> list[dict]:
    """Run one fresh detector over frames and return its per-frame records.

    Parameters
    ----------
    timed_frames : iterable of (float, ndarray)
        Each frame with its time in seconds (``Source.timed_frames()``, or :func:`at_rate`).
    detector : DetectorSpec or str
        A spec (see :func:`parse_detector`).
    on_frame : callable, optional
        Called after each frame (progress).

    Returns
    -------
    list of dict
        One record per frame in the ``asnn detect --jsonl`` format: ``frame``, ``t``, ``u``,
        ``out``, ``spikes``, ``spike_rate``, ``collision``, ``targets``.
    """
    spec = parse_detector(detector) if isinstance(detector, str) else detector
    model = spec.make()
    records = []
    for index, (t, frame) in enumerate(timed_frames):
        response = model.step(frame, t)
        records.append({"frame": index, "t": round(t, 6), **response.to_dict()})
        if on_frame is not None:
            on_frame()
    return records


def write_jsonl(path: Path, records: Sequence[Mapping]) -> Path:
    """Write records as JSON lines (the ``asnn detect --jsonl`` format)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        for r in records:
            fh.write(json.dumps(r) + "\n")
    return path


def write_json(path: Path, data) -> Path:
    """Write JSON (indented, no NaN)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    return path


def fmt(value, digits: int = 2, suffix: str = "") -> str:
    """A number for a report table (``–`` for None)."""
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}f}{suffix}"
    return f"{value}{suffix}"


def rate(value) -> str:
    """A fraction as a percentage for a report table (``–`` for None)."""
    return "–" if value is None else f"{100 * value:.0f}%"


def outcome_cell(score: Mapping) -> str:
    """One clip's score for a report table: outcome, first warning frame (lead), warning frames
    (and those after the approach)."""
    cell = score["outcome"]
    if score["first_warning"] is not None:
        cell += f" @{score['first_warning']}"
        if score["lead_s"] is not None:
            cell += f" ({score['lead_s']:+.2f} s)"
        cell += f", {score['warning_frames']} fr"
        if score.get("after_warning_frames"):
            cell += f" ({score['after_warning_frames']} after)"
    return cell
