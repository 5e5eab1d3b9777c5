"""Running detectors named by a spec over frames, and writing what the runs produce.

A detector spec names one detector to compare: ``asnn`` (the default preset), ``asnn:PRESET``
(for example ``asnn:reference``, the published variant), ``lgmd1`` or ``lgmd2``. An ASNN spec may
override parameters after slashes, ``asnn:robust/contrast_gain=none/approach_frames=1`` (values
``none``, ``true``, ``false``, numbers or words): :data:`ABLATIONS` switches off each addition of
the robust preset that way. Results of a spec go to a directory named by
:attr:`DetectorSpec.slug` (``asnn-reference``: no colons or slashes in paths).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import scoring
from .options import DEFAULT_DETECTORS
from ..detectors import BASELINES, Detector, baseline_classes, make_detector
from ..io.files import write_atomically
from ..params import (DEFAULT_PRESET, ASNNParams, check_fields, check_overrides,
                      parse_preset_spec, preset, split_preset_spec, timed_gap)

__all__ = ["DEFAULT_DETECTORS", "ABLATIONS", "DetectorSpec", "parse_detector", "parse_detectors",
           "run_detector", "at_rate", "write_json", "write_jsonl", "fmt", "rate", "outcome_cell"]


# each addition of the robust preset switched off in turn (README, "Ablation")
ABLATIONS = {
    "robust (all additions)": "asnn:robust",
    "no repeated-frame hold": "asnn:robust/skip_repeats=false",
    "every frame of a fast camera stepped (no frame-rate ceiling)": (
        "asnn:robust/max_step_rate=none"),
    "the input blur fixed in a dim, noisy view (no summation by the noise)": (
        "asnn:robust/noise_summation=none"),
    "a dim, noisy view not summed in time (no temporal summation)": (
        "asnn:robust/temporal_summation=none"),
    "no global brightness compensation (flicker, exposure steps)": (
        "asnn:robust/global_gain=none"),
    "no background stabilisation": "asnn:robust/stabilise=false",
    "the stabilisation's search fixed at 3 px at any width": "asnn:robust/stabilise_reach=none",
    "the stabilisation's translation judged on the whole frame only": (
        "asnn:robust/stabilise_spread=0"),
    "the stabilisation's search made once (no wider search at its edge)": (
        "asnn:robust/stabilise_wider=none"),
    "the box's expansion over a sliding background (no rim fit)": (
        "asnn:robust/rim_expansion=false"),
    "the rim's expansion at any motion (no small-motion limit)": (
        "asnn:robust/rim_motion_max=none"),
    "no contrast gain control": "asnn:robust/contrast_gain=none",
    "no light adaptation of the contrast gain control (dusk)": (
        "asnn:robust/contrast_light=none"),
    "the light adaptation at night too (no spread gate)": (
        "asnn:robust/contrast_light_spread=none"),
    "OFF-led map only (no ON-led mirror)": "asnn:robust/w1_on=0/w2_off=0",
    "no approach gate (u sums every object)": "asnn:robust/approach_gate=false",
    "no offset test (near misses)": "asnn:robust/offset_max=1000",
    "no scene-relative test (cut-ins)": "asnn:robust/scene_relative=false",
    "no motion layers (mixed boxes)": "asnn:robust/motion_layers=false",
    "the camera's rig kept in the fits (hood, overlay)": "asnn:robust/ignore_rig=false",
    "no surface-ahead pathway (a wall filling the view)": "asnn:robust/surface_ahead=false",
    "objects counted in a corridor (no corridor gate)": "asnn:robust/corridor_gate=false",
    "scene-relative test without its tolerance": "asnn:robust/scene_tolerance=0",
    "objects closing by their own motion counted once (no own-motion weight)": (
        "asnn:robust/own_motion_weight=1"),
    "no partial-overlap regime": "asnn:robust/partial_overlap=false",
    "partial overlaps without the fit test": "asnn:robust/overlap_fit_min=-1",
    "no fit against a receding scene": "asnn:robust/receding_scene=false",
    "the fit against a receding scene where the frame's edge cuts the object (no edge rule)": (
        "asnn:robust/receding_edge_rule=false"),
    "no persistence (one frame of approach)": "asnn:robust/approach_frames=1",
    "persistence per track only (no region persistence)": "asnn:robust/region_persistence=false",
    "region persistence from any overlap (no region_cover)": "asnn:robust/region_cover=0",
    "as many frames of approach at any frame rate": "asnn:robust/approach_seconds=none",
    "each track its own id (no object ids)": "asnn:robust/object_ids=false",
    "no input scale (frames at their own size)": "asnn:robust/max_width=none",
    "small frames at their own size (no min_width)": "asnn:robust/min_width=none",
    "attention blur at full resolution": "asnn:robust/attention_step=1",
}


@dataclass(frozen=True)
class DetectorSpec:
    """One detector to run: a model, for ASNN a preset (None: the default), and parameter
    overrides (``(name, value)`` pairs: of the preset, or of an LGMD model's parameters)."""

    model: str
    preset: str | None = None
    overrides: tuple[tuple[str, object], ...] = ()

    @property
    def name(self) -> str:
        """``asnn``, ``asnn:PRESET[/name=value...]``, ``lgmd1[/name=value...]`` or
        ``lgmd2[/name=value...]``."""
        extra = "".join(f"/{k}={_spell(v)}" for k, v in self.overrides)
        if self.model != "asnn":
            return self.model + extra
        if not (self.preset or self.overrides):
            return self.model
        return f"asnn:{self.preset or 'default'}{extra}"

    @property
    def description(self) -> str:
        """What the name stands for, for a report's reader: the model, and for ASNN its preset
        (the default's own name) and overrides."""
        if self.model in BASELINES:
            entry = BASELINES[self.model]
            text = f"{entry.description}, {entry.module}.{entry.cls}"
        else:
            text = (f"ASNN, the default preset (`{DEFAULT_PRESET}`)" if self.preset is None
                    else f"ASNN, preset `{self.preset}`")
        if self.overrides:
            text += " with " + ", ".join(f"{k}={_spell(v)}" for k, v in self.overrides)
        return text

    @property
    def slug(self) -> str:
        """The name as a directory name (``:``, ``/`` and ``=`` become ``-``)."""
        return self.name.replace(":", "-").replace("/", "-").replace("=", "-")

    @property
    def params(self) -> ASNNParams:
        """The ASNN parameters: the preset with the overrides."""
        return preset(self.preset or "default", **dict(self.overrides))

    @property
    def parameters(self) -> dict:
        """Every parameter the detector runs with, JSON-ready (an infinity as ``"inf"``), for a
        run's ``results.json``: a named preset edited between two runs leaves two results that
        tell it. ASNN's add ``preset``, the one its name stands for; an LGMD model's ``dt`` is
        ``"frame period"`` unless the spec sets it (:meth:`make`)."""
        if self.model == "asnn":
            values = {"preset": self.preset or DEFAULT_PRESET, **self.params.model_dump()}
        else:
            fields = baseline_classes(self.model)[1](**dict(self.overrides)).model_dump()
            values = {**fields, "dt": fields["dt"] if "dt" in dict(self.overrides)
                      else "frame period"}
        return {k: _json_ready(v) for k, v in values.items()}

    def make(self, frame_period: float | None = None) -> Detector:
        """A fresh detector for a stream whose frames come ``frame_period`` seconds apart.

        An LGMD model's ``dt`` is that period (where it is one the model believes,
        :func:`asnn.params.timed_gap`) unless the spec sets ``dt``: LGMD1-2's time
        constants are in seconds (``a = dt / (dt + tau)``, SPEC section 4), and at its default
        0.05 s a 30 fps clip ran them 1.5 times slow (its `real` hits 1/9, against 3/9 at the
        clips' own period). The ASNN takes the frames' times as they come (``step(frame, t)``);
        its retina's ``dt`` is the published implementation's fixed step.
        """
        if self.model != "asnn":  # the LGMD models take their overrides as keywords
            options = dict(self.overrides)
            # a period no stream has (a bag's stamps in another unit: 5e-8 s, or 50 s) is no dt
            if frame_period is not None and timed_gap(frame_period) and "dt" not in options:
                options["dt"] = frame_period
            return make_detector(self.model, None, **options)
        return make_detector(self.model, self.params)


def _json_ready(value):
    """A parameter's value as strict JSON holds it: an infinity as ``"inf"`` or ``"-inf"``
    (the spelling the specs take), tuples as lists."""
    if isinstance(value, float) and np.isinf(value):
        return "inf" if value > 0 else "-inf"
    if isinstance(value, (tuple, list)):
        return [_json_ready(v) for v in value]
    return value


def _spell(value) -> str:
    return "none" if value is None else str(value).lower() if isinstance(value, bool) else \
        str(value)


def parse_detector(spec: str, default_preset: str | None = None) -> DetectorSpec:
    """Read a detector spec.

    Parameters
    ----------
    spec : str
        ``asnn``, ``asnn:PRESET``, ``lgmd1`` or ``lgmd2``, each with parameters changed after
        slashes (``asnn:robust/top_k=0``, ``lgmd1/w_i=0.6``: SPEC section 4's ranges for the
        baselines, :class:`asnn.baselines.LGMD1Params`, :class:`~asnn.baselines.LGMD2Params`).
    default_preset : str, optional
        The preset a bare ``asnn`` stands for (None or ``default``: the default preset), with
        any overrides after slashes as a spec has them (``robust/top_k=0``); a spec's own
        overrides come after these.

    Raises
    ------
    ValueError
        For an unknown model, preset or parameter, a value the parameter does not take, or a
        preset given to an LGMD model.
    """
    model, _, rest = spec.strip().partition(":")
    model, slash, changed = model.partition("/")
    if model != "asnn" and model not in BASELINES:
        raise ValueError(f"unknown detector {spec!r}; use asnn, asnn:PRESET, "
                         f"{', '.join(BASELINES)} (each with /FIELD=VALUE changes)")
    if model != "asnn":
        if rest:
            raise ValueError(f"{model} has no presets: {spec!r}")
        overrides = split_preset_spec(model + slash + changed, spec)[1]
        check_fields(baseline_classes(model)[1](), overrides, spec)
        return DetectorSpec(model, None, overrides)
    if slash:  # asnn/FIELD=VALUE: the default preset's fields after the slashes
        rest = f"{rest}/{changed}" if rest else f"/{changed}"
    if rest.split("/", 1)[0].strip():
        preset_name, overrides = parse_preset_spec(rest, spec)
    else:  # the default preset's, then the spec's own (which may change the default's)
        preset_name, base = parse_preset_spec(default_preset or "default", spec)
        overrides = base + split_preset_spec(preset_name + rest, spec)[1]
        check_overrides(preset_name, overrides, spec)
    return DetectorSpec("asnn", None if preset_name == "default" else preset_name,
                        tuple(overrides))


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
                 frame_period: float | None = None) -> list[dict]:
    """Run one fresh detector over frames and return its per-frame records.

    Parameters
    ----------
    timed_frames : iterable of (float, ndarray)
        Each frame with its time in seconds (``Source.timed_frames()``, or :func:`at_rate`).
    detector : DetectorSpec or str
        A spec (see :func:`parse_detector`).
    frame_period : float, optional
        The stream's frame period in seconds, an LGMD model's ``dt``
        (:meth:`DetectorSpec.make`); None: its default, 0.05 s.

    Returns
    -------
    list of dict
        One record per frame in the ``asnn detect --jsonl`` format: ``frame``, ``t``, ``u``,
        ``out``, ``spikes``, ``spike_rate``, ``collision``, ``targets``.
    """
    spec = parse_detector(detector) if isinstance(detector, str) else detector
    model = spec.make(frame_period)
    records = []
    for index, (t, frame) in enumerate(timed_frames):
        records.append(model.step(frame, t).record(index, t))
    return records


def write_jsonl(path: Path, records: Sequence[Mapping]) -> Path:
    """Write records as JSON lines (the ``asnn detect --jsonl`` format), replacing the file
    whole (:func:`asnn.io.files.write_atomically`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, "".join(json.dumps(r) + "\n" for r in records))
    return path


def write_json(path: Path, data) -> Path:
    """Write JSON (indented, no NaN), replacing the file whole: a run stopped meanwhile leaves
    the previous file or the new one, never a part (:func:`asnn.io.files.write_atomically`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, json.dumps(data, indent=1, allow_nan=False) + "\n")
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


def rate_interval(value, interval) -> str:
    """A rate with its 95 % interval for a report table: ``56% (27-81%)``."""
    if value is None:
        return "–"
    if not interval:
        return rate(value)
    return f"{rate(value)} ({100 * interval[0]:.0f}-{100 * interval[1]:.0f}%)"


def paired_comparisons(scores: Mapping[str, Sequence]) -> dict:
    """Every detector after the first compared with the first, clip by clip
    (:func:`asnn.evaluation.scoring.paired_comparison`), by name; empty with one detector."""
    names = list(scores)
    return {name: scoring.paired_comparison(scores[names[0]], scores[name])
            for name in names[1:]}


def paired_section(first: str, paired: Mapping[str, Mapping], unit: str = "clips") -> list[str]:
    """The report's lines on :func:`paired_comparisons`: per detector, the hits and false
    alarms only the first detector has and only it has, with McNemar's exact p-value."""
    if not paired:
        return []
    lines = ["", f"## Paired with `{first}`", "",
             f"The same {unit}, one by one: where only one of the two hits (over the collision "
             f"{unit}) or raises a false alarm (over all), and McNemar's exact two-sided p-value "
             "(how likely a split at least this lopsided is if neither were better; the "
             f"{unit} where both agree do not count). The rates' 95 % intervals (Wilson) are "
             "in brackets above.", "",
             f"| detector | hits only `{first}` / only it | p | false alarms only `{first}` / "
             "only it | p |", "| --- | --- | --- | --- | --- |"]
    for name, c in paired.items():
        hits, fas = c["hits"], c["false_alarms"]
        lines.append(f"| `{name}` | {hits['only_first']} / {hits['only_second']} | "
                     f"{hits['p']:.3g} | {fas['only_first']} / {fas['only_second']} | "
                     f"{fas['p']:.3g} |")
    return lines


TARGET_QUALITY_HEADER = ["median ttc error (ratio)", "one id (hits)"]
TARGET_QUALITY_NOTE = (
    "Ttc error: over the warning frames of the hit window before contact, the nearest target's "
    "|ttc - true| / true against the label's per-frame time to contact, else the time left to "
    "the contact frame (median per hit, then over hits; the ratio ttc / true likewise: below 1 "
    "the target says contact is nearer than it is); one id: hits whose warning frames followed "
    "one target id.")


def target_quality_cells(summary: Mapping) -> list[str]:
    """A detector's summary cells for the targets of its warnings: the median time-to-contact
    error (and ratio), and the hits whose warning followed one target id."""
    ttc = "–"
    if summary.get("median_ttc_error") is not None:
        ttc = (f"{100 * summary['median_ttc_error']:.0f}% "
               f"(x{summary['median_ttc_ratio']:.2f})")
    ids = f"{summary['one_id_hits']}/{summary['id_hits']}" if summary.get("id_hits") else "–"
    return [ttc, ids]


def outcome_cell(score: Mapping) -> str:
    """One clip's score for a report table: outcome, first warning frame (lead), warning frames
    (and those after the approach), and the nearest target's distance from the labelled centre
    at the first warning, where it is measured (the scoring counts a warning anywhere in the
    frame: the distance shows whether it was on the labelled object)."""
    cell = score["outcome"]
    if score["first_warning"] is not None:
        cell += f" @{score['first_warning']}"
        if score["lead_s"] is not None:
            cell += f" ({score['lead_s']:+.2f} s)"
        cell += f", {score['warning_frames']} fr"
        if score.get("after_warning_frames"):
            cell += f" ({score['after_warning_frames']} after)"
        if score.get("localisation_px") is not None:
            cell += f", target {score['localisation_px']:.0f} px off"
    return cell
