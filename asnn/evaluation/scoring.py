"""Scoring of per-frame detector results against clip labels (SPEC.md section 5).

The per-frame results of one detector on one clip are the records ``asnn detect --jsonl`` writes
(CONTRACT.md): dicts with at least ``frame`` and ``collision``, and ``targets`` (a list of dicts
with ``x`` and ``y``) where the detector reports them. A label is an entry of ``labels.json``
(see ``data/real/README.md``; read and checked by :mod:`asnn.evaluation.labels`): ``file``,
``fps``, ``collision``, ``onset_frame``, ``contact_frame``, ``center``, and optionally ``track``
(the target's centre ``[x, y]`` in every frame, or null where it has none; generated clips have
it).

Rules, with W the warm-up, T the early tolerance in whole frames
(``floor(tolerance_s * fps)``: 7 at 15 fps, 14 at 29.97), and ``first`` the first frame at or
after W whose record has ``collision`` true:

=========  ===================================================================================
outcome    when
=========  ===================================================================================
hit        collision clip, ``onset - T <= first <= contact + 2``
early      collision clip, ``first < onset - T``: an early warning, counted as a false alarm
late       collision clip, ``first > contact + 2``
miss       collision clip, no warning at or after W
false      non-collision clip, any warning at or after W (a false alarm)
quiet      non-collision clip, no warning at or after W (a correct rejection)
missing    no results for the clip: excluded from every rate, counted on its own
=========  ===================================================================================

Lead time is ``contact - first`` (frames, and seconds at the clip's fps) for every first warning
on a collision clip (negative when late). The localisation error is the distance from the
nearest target of the first warning's frame to the labelled centre (the track's centre at that
frame where the label has a track), where that frame has targets. Warning frames after
``contact + 2`` on a collision clip are counted apart: the warning should end when the approach
does (for an approach that stops short, ``contact_frame`` is the frame it stops).

What a warning's targets are worth to someone who acts on them is measured over the warning
frames of the hit window before contact, on the target nearest the labelled centre in each:
the time-to-contact error ``|ttc - true| / true`` and ratio ``ttc / true`` (medians over those
frames; the true time to contact is the label's per-frame ``ttc`` where it has one, else the
time left to ``contact_frame``), and how many distinct ``id`` those targets carry (1: one track
followed the object through the warning). Detectors whose targets lack ``ttc`` or ``id`` get
None.

A rate over a dozen clips is a small sample: each summary gives the hit and false-alarm rates'
95 % Wilson score intervals [1]_, and :func:`paired_comparison` compares two detectors clip by
clip on the same clips with McNemar's exact test [2]_: of the clips where exactly one of them
hits (or raises a false alarm), how unlikely so lopsided a split is if neither were better.

References
----------
.. [1] E. B. Wilson, "Probable inference, the law of succession, and statistical inference",
   Journal of the American Statistical Association 22, 1927, pp. 209-212.
.. [2] Q. McNemar, "Note on the sampling error of the difference between correlated
   proportions or percentages", Psychometrika 12, 1947, pp. 153-157.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from .labels import check_labels, result_name
from .options import EARLY_TOLERANCE_S, WARMUP_FRAMES
from .stats import mcnemar_exact, wilson_interval

__all__ = [
    "OUTCOMES",
    "WARMUP_FRAMES",
    "CONTACT_SLACK_FRAMES",
    "EARLY_TOLERANCE_S",
    "MAX_EARLY_TOLERANCE_S",
    "ClipScore",
    "unscored",
    "first_warning",
    "score_clip",
    "missing_clip",
    "summarize",
    "paired_comparison",
    "load_records",
    "results_path",
    "clip_name",
    "score_directory",
]

CONTACT_SLACK_FRAMES = 2
MAX_EARLY_TOLERANCE_S = 60.0  # an onset judged by eye is off by a second or two, not a minute
OUTCOMES = ("hit", "early", "late", "miss", "false", "quiet", "missing")


def unscored(label: Mapping, frames: int, warmup: int = WARMUP_FRAMES) -> list[str]:
    """Why a clip's score would say nothing of a detector: too few frames decoded to score any
    after the warm-up, or a collision whose hit window ends inside the warm-up, which no
    detector can hit (each was scored as any other clip without a word).

    Parameters
    ----------
    label : mapping
        The clip's label (``file``, ``collision``, ``contact_frame``).
    frames : int
        The frames decoded.
    warmup : int
        The first frames the scoring ignores.

    Returns
    -------
    list of str
        One sentence per reason, naming the clip; empty where it can be scored.
    """
    name = label.get("file", "?")
    found = []
    if frames <= warmup:
        found.append(f"{name}: {frames} frame{'' if frames == 1 else 's'} decoded: the scoring "
                     f"ignores the first {warmup}, so nothing of it is scored")
    contact = label.get("contact_frame")
    if label.get("collision") and contact is not None \
            and int(contact) + CONTACT_SLACK_FRAMES < warmup:
        found.append(f"{name}: its hit window ends at frame {int(contact) + CONTACT_SLACK_FRAMES}"
                     f", inside the first {warmup} frames the scoring ignores: no detector can "
                     "hit it")
    return found


@dataclass(frozen=True)
class ClipScore:
    """The score of one detector on one clip.

    Attributes
    ----------
    clip : str
        The label's ``file``.
    collision : bool
        Whether the clip is labelled as a collision.
    outcome : str
        One of :data:`OUTCOMES`.
    first_warning : int or None
        First warning frame at or after the warm-up.
    warning_frames : int
        Frames with a warning at or after the warm-up.
    window_warning_frames : int
        Of those, the frames inside the hit window (always 0 on a non-collision clip): how much
        of a detector's warning falls where a warning is due.
    after_warning_frames : int
        Of those, the frames after ``contact + 2`` on a collision clip: warnings that outlast the
        approach.
    false_alarm : bool
        An early warning on a collision clip, or any warning on a non-collision clip.
    lead_frames, lead_s : float or None
        ``contact - first_warning``, in frames and seconds (collision clips with a warning).
    localisation_px : float or None
        Distance from the nearest target at the first warning to the labelled centre (or the
        track's centre at that frame).
    window : (int, int) or None
        The frames a first warning must lie in to be a hit.
    ttc_error, ttc_ratio : float or None
        Median over the warning frames of the hit window before contact of the nearest target's
        ``|ttc - true| / true`` and ``ttc / true``.
    target_ids : int or None
        Distinct ``id`` of the nearest targets over those frames.
    duration_s : float or None
        The clip's length after the warm-up, seconds (frames scored / the label's fps).
    """

    clip: str
    collision: bool
    outcome: str
    first_warning: int | None = None
    warning_frames: int = 0
    window_warning_frames: int = 0
    after_warning_frames: int = 0
    false_alarm: bool = False
    lead_frames: float | None = None
    lead_s: float | None = None
    localisation_px: float | None = None
    window: tuple[int, int] | None = None
    ttc_error: float | None = None
    ttc_ratio: float | None = None
    target_ids: int | None = None
    duration_s: float | None = None

    def to_dict(self) -> dict:
        d = asdict(self)
        d["window"] = list(self.window) if self.window else None
        return d


def first_warning(records: Iterable[Mapping], warmup: int = WARMUP_FRAMES) -> tuple[int | None, int]:
    """The first warning frame at or after ``warmup``, and the number of such warning frames.

    Parameters
    ----------
    records : iterable of dict
        Per-frame results with ``frame`` (0-based) and ``collision``.
    warmup : int
        Frames ``0 .. warmup - 1`` are ignored.

    Returns
    -------
    first : int or None
    count : int
    """
    frames = sorted(int(r["frame"]) for r in records
                    if r.get("collision") and int(r["frame"]) >= warmup)
    return (frames[0] if frames else None), len(frames)


def _labelled_center(label: Mapping, frame: int) -> Sequence[float] | None:
    """The target's centre at ``frame``: from the label's track where it has one."""
    track = label.get("track")
    if track is not None:
        return track[frame] if 0 <= frame < len(track) else None
    return label.get("center")


def _nearest_target(record: Mapping, center: Sequence[float] | None) -> tuple[Mapping, float] | None:
    """The record's target nearest ``center``, and its distance."""
    targets = record.get("targets") or []
    if center is None or not targets:
        return None
    cx, cy = float(center[0]), float(center[1])
    return min(((t, math.hypot(float(t["x"]) - cx, float(t["y"]) - cy)) for t in targets),
               key=lambda pair: pair[1])


def _nearest_target_distance(records: Sequence[Mapping], frame: int,
                             center: Sequence[float] | None) -> float | None:
    for r in records:
        if int(r["frame"]) == frame:
            nearest = _nearest_target(r, center)
            return None if nearest is None else nearest[1]
    return None


def _true_ttc(label: Mapping, frame: int, fps: float) -> float | None:
    """The labelled time to contact at ``frame``, seconds: the label's ``ttc`` where it has one
    (None where it says the object is not closing), else the time left to contact."""
    ttc = label.get("ttc")
    if ttc is not None:
        value = ttc[frame] if 0 <= frame < len(ttc) else None
        return float(value) if value is not None and value > 0 else None
    left = int(label["contact_frame"]) - frame
    return left / fps if fps > 0 and left > 0 else None


def _warned_targets(records: Sequence[Mapping], label: Mapping, frames: range,
                    fps: float) -> tuple[float | None, float | None, int | None]:
    """Time-to-contact error, ratio and distinct ids of the nearest targets over the warning
    frames in ``frames`` (the module's docstring)."""
    errors, ratios, ids = [], [], set()
    for r in records:
        frame = int(r["frame"])
        if not r.get("collision") or frame not in frames:
            continue
        nearest = _nearest_target(r, _labelled_center(label, frame))
        if nearest is None:
            continue
        target = nearest[0]
        if target.get("id") is not None:
            ids.add(target["id"])
        true = _true_ttc(label, frame, fps)
        if target.get("ttc") is not None and true is not None:
            ratios.append(float(target["ttc"]) / true)
            errors.append(abs(ratios[-1] - 1.0))
    return _median(errors), _median(ratios), (len(ids) if ids else None)


def score_clip(records: Sequence[Mapping], label: Mapping, *, warmup: int = WARMUP_FRAMES,
               early_tolerance_s: float = EARLY_TOLERANCE_S,
               contact_slack: int = CONTACT_SLACK_FRAMES) -> ClipScore:
    """Score one detector's per-frame results on one clip (SPEC.md section 5).

    Parameters
    ----------
    records : sequence of dict
        Per-frame results (``frame``, ``collision``, optionally ``targets``).
    label : dict
        The clip's entry in ``labels.json``.
    warmup : int
        Frames ignored at the start of the clip (5).
    early_tolerance_s : float
        How long before the labelled onset a first warning still counts as a hit, in seconds
        (0.5 for the real clips, whose onsets were judged by eye; 0 for generated clips).
    contact_slack : int
        Frames after contact a first warning still counts as a hit (2).

    Returns
    -------
    ClipScore

    Raises
    ------
    ValueError
        If a label lacks ``collision`` or a positive ``fps``, a collision label its onset or
        contact frame, or its onset is after its
        contact (labels read from a file are checked in full before: :mod:`.labels`; this
        check is the one a label built in code needs for a meaningful window), or the
        tolerance is outside 0 to :data:`MAX_EARLY_TOLERANCE_S`.
    """
    if not 0 <= early_tolerance_s <= MAX_EARLY_TOLERANCE_S:  # 1e308 s overflow an int
        raise ValueError(f"early_tolerance_s must be 0 to {MAX_EARLY_TOLERANCE_S:g}, got "
                         f"{early_tolerance_s!r}")
    clip = clip_name(label)
    if not isinstance(label.get("collision"), bool):  # a missing one was scored as none
        raise ValueError(f"{clip}: a label needs collision, true or false")
    fps = label.get("fps")
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not fps > 0:
        # without it the tolerance was 0, the lead and the minutes of video unknown
        raise ValueError(f"{clip}: a label needs fps, a positive number, got {fps!r}")
    collision, fps = label["collision"], float(fps)
    first, count = first_warning(records, warmup)
    scored = sum(1 for r in records if int(r["frame"]) >= warmup)
    duration = scored / fps
    if not collision:
        return ClipScore(clip=clip, collision=False, outcome="false" if count else "quiet",
                         first_warning=first, warning_frames=count, false_alarm=bool(count),
                         duration_s=duration)

    onset, contact = label.get("onset_frame"), label.get("contact_frame")
    if onset is None or contact is None:
        raise ValueError(f"{clip}: a collision label needs onset_frame and contact_frame")
    if int(onset) > int(contact):
        raise ValueError(f"{clip}: onset_frame {onset} is after contact_frame {contact}")
    # whole frames within the tolerance (SPEC: "up to 0.5 s"): at 15 fps 7 frames, not 8
    tolerance = math.floor(early_tolerance_s * fps + 1e-9)
    window = (int(onset) - tolerance, int(contact) + contact_slack)
    if first is None:
        return ClipScore(clip=clip, collision=True, outcome="miss", window=window,
                         duration_s=duration)
    if first < window[0]:
        outcome = "early"
    elif first <= window[1]:
        outcome = "hit"
    else:
        outcome = "late"
    lead = float(int(contact) - first)
    warned = [int(r["frame"]) for r in records if r.get("collision") and int(r["frame"]) >= warmup]
    in_window = sum(1 for f in warned if window[0] <= f <= window[1])
    ttc_error, ttc_ratio, target_ids = _warned_targets(
        records, label, range(max(window[0], warmup), int(contact)), fps)
    return ClipScore(clip=clip, collision=True, outcome=outcome, first_warning=first,
                     warning_frames=count, window_warning_frames=in_window,
                     after_warning_frames=sum(1 for f in warned if f > window[1]),
                     false_alarm=outcome == "early",
                     lead_frames=lead, lead_s=lead / fps,
                     localisation_px=_nearest_target_distance(records, first,
                                                              _labelled_center(label, first)),
                     ttc_error=ttc_error, ttc_ratio=ttc_ratio, target_ids=target_ids,
                     duration_s=duration,
                     window=window)


def missing_clip(label: Mapping) -> ClipScore:
    """The score of a clip the detector has no results for (outcome ``missing``)."""
    return ClipScore(clip=clip_name(label), collision=bool(label.get("collision")),
                     outcome="missing")


def _mean(values: list[float]) -> float | None:
    return sum(values) / len(values) if values else None


def _median(values: list[float]) -> float | None:
    if not values:
        return None
    v = sorted(values)
    mid = len(v) // 2
    return v[mid] if len(v) % 2 else (v[mid - 1] + v[mid]) / 2


def summarize(scores: Iterable[ClipScore]) -> dict:
    """Aggregate clip scores of one detector.

    Returns
    -------
    dict
        ``clips``, ``scored`` and ``missing`` counts; ``collision_clips``,
        ``noncollision_clips`` (scored only); the count of each outcome; ``false_alarms``
        (early warnings plus warned non-collision clips); ``hit_rate`` (hits over scored collision
        clips), ``false_alarm_rate`` (false alarms over scored clips), ``specificity`` (quiet over
        scored non-collision clips), each None without a denominator; ``warning_frames``,
        ``window_warning_frames`` and ``after_warning_frames`` summed over the scored clips, and
        ``after_warning_clips``, the collision clips with warnings after the approach;
        ``mean_lead_s``, ``mean_lead_frames``, ``median_lead_s`` and ``median_lead_frames`` over
        hits; ``median_localisation_px`` over hits with targets; ``median_ttc_error`` and
        ``median_ttc_ratio`` over the hits' own medians; ``one_id_hits`` (hits whose warning
        followed one target id) of ``id_hits`` (hits whose targets carry ids);
        ``noncollision_minutes`` (of scored non-collision video, where the labels give the fps) and
        ``warning_frames_per_minute`` of it (SPEC.md section 5: a detector that fires once per
        clip and one that fires all the time are not equally useful); ``hit_rate_ci`` and
        ``false_alarm_rate_ci``, the rates' 95 %
        :func:`~asnn.evaluation.stats.wilson_interval` as ``[low, high]`` (None without a
        denominator).
    """
    scores = list(scores)
    scored = [s for s in scores if s.outcome != "missing"]
    quiet_minutes = sum(s.duration_s for s in scored
                        if not s.collision and s.duration_s is not None) / 60.0
    counts = {o: sum(s.outcome == o for s in scores) for o in OUTCOMES}
    n_col = sum(s.collision for s in scored)
    n_non = len(scored) - n_col
    false_alarms = counts["early"] + counts["false"]
    hits = [s for s in scored if s.outcome == "hit"]
    return {
        "clips": len(scores),
        "scored": len(scored),
        "missing": counts["missing"],
        "collision_clips": n_col,
        "noncollision_clips": n_non,
        **{o: counts[o] for o in OUTCOMES if o != "missing"},
        "false_alarms": false_alarms,
        "hit_rate": counts["hit"] / n_col if n_col else None,
        "hit_rate_ci": wilson_interval(counts["hit"], n_col),
        "false_alarm_rate": false_alarms / len(scored) if scored else None,
        "false_alarm_rate_ci": wilson_interval(false_alarms, len(scored)),
        "specificity": counts["quiet"] / n_non if n_non else None,
        "warning_frames": sum(s.warning_frames for s in scored),
        "window_warning_frames": sum(s.window_warning_frames for s in scored),
        "after_warning_frames": sum(s.after_warning_frames for s in scored),
        "noncollision_minutes": quiet_minutes,
        "warning_frames_per_minute": (sum(s.warning_frames for s in scored if not s.collision)
                                      / quiet_minutes if quiet_minutes else None),
        "after_warning_clips": sum(s.after_warning_frames > 0 for s in scored),
        "mean_lead_frames": _mean([s.lead_frames for s in hits]),
        "mean_lead_s": _mean([s.lead_s for s in hits if s.lead_s is not None]),
        "median_lead_frames": _median([s.lead_frames for s in hits]),
        "median_lead_s": _median([s.lead_s for s in hits if s.lead_s is not None]),
        "median_localisation_px": _median([s.localisation_px for s in hits
                                           if s.localisation_px is not None]),
        "median_ttc_error": _median([s.ttc_error for s in hits if s.ttc_error is not None]),
        "median_ttc_ratio": _median([s.ttc_ratio for s in hits if s.ttc_ratio is not None]),
        "one_id_hits": sum(s.target_ids == 1 for s in hits),
        "id_hits": sum(s.target_ids is not None for s in hits),
    }


def paired_comparison(first: Sequence[ClipScore], second: Sequence[ClipScore]) -> dict:
    """Two detectors' scores on the same clips, compared clip by clip.

    Hits are compared over the collision clips both scored, false alarms (an early warning, or
    any warning on a non-collision clip) over every clip both scored.

    Returns
    -------
    dict
        ``hits`` and ``false_alarms``, each ``{"only_first", "only_second", "p"}``: the clips
        where only the first or only the second has the outcome, and :func:`mcnemar_exact`'s
        p-value (:mod:`asnn.evaluation.stats`).

    Raises
    ------
    ValueError
        If the two lists are not scores of the same clips in the same order.
    """
    if [s.clip for s in first] != [s.clip for s in second]:
        raise ValueError("paired_comparison needs the same clips in the same order")
    both = [(a, b) for a, b in zip(first, second)
            if a.outcome != "missing" and b.outcome != "missing"]

    def split(pairs, has) -> dict:
        only_first = sum(has(a) and not has(b) for a, b in pairs)
        only_second = sum(has(b) and not has(a) for a, b in pairs)
        return {"only_first": only_first, "only_second": only_second,
                "p": mcnemar_exact(only_first, only_second)}

    return {"hits": split([(a, b) for a, b in both if a.collision], lambda s: s.outcome == "hit"),
            "false_alarms": split(both, lambda s: s.false_alarm)}


def load_records(path: str | Path) -> list[dict]:
    """Read per-frame results: a JSON-lines file (``asnn detect --jsonl``) or a JSON list.

    Raises
    ------
    ValueError
        If the file is not JSON (the message names the line), or a record is not a JSON
        object with a whole ``frame`` and, where it has one, a ``collision`` of true or false
        (the string "false" counted as a warning).
    """
    # utf-8-sig: a file saved by an editor that writes a byte-order mark reads as any other
    text = Path(path).read_text(encoding="utf-8-sig")
    if text.lstrip().startswith("["):
        records = _parse_json(text, path)
    else:
        records = [_parse_json(line, path, number)
                   for number, line in enumerate(text.splitlines(), 1) if line.strip()]
    for r in records:
        if not isinstance(r, dict) or "frame" not in r:
            raise ValueError(f"{path}: every record must be a JSON object with a 'frame'")
        if isinstance(r["frame"], bool) or not isinstance(r["frame"], int):
            raise ValueError(f"{path}: a record's frame must be a whole number, got "
                             f"{r['frame']!r}")
        if not isinstance(r.get("collision", False), bool):
            raise ValueError(f"{path}: frame {r['frame']}: collision must be true or false, "
                             f"got {r['collision']!r}")
    return records


def clip_name(label: Mapping) -> str:
    """How scores and reports name a clip: its label's ``file``, and for a bag's camera
    ``file#topic`` (as ``asnn detect`` takes it)."""
    name = str(label.get("file", "?"))
    return f"{name}#{label['topic']}" if label.get("topic") else name


def _parse_json(text: str, path, line: int | None = None):
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        # in a JSON-lines file the decoder counts lines within one line: name the file's line
        line = error.lineno if line is None else line
        raise ValueError(f"{path}: not JSON at line {line}, column {error.colno}: "
                         f"{error.msg}") from None


def results_path(results_dir: str | Path, clip: str | Mapping) -> Path | None:
    """The results file of a clip in a directory, if any: ``<name>.jsonl`` or ``<name>.json``,
    the name its label's (:func:`~asnn.evaluation.labels.result_name`; for a file name alone,
    its stem)."""
    stem = result_name(clip) if isinstance(clip, Mapping) else Path(clip).stem
    for suffix in (".jsonl", ".json"):
        candidate = Path(results_dir) / f"{stem}{suffix}"
        if candidate.is_file():
            return candidate
    return None


def score_directory(results_dir: str | Path, labels: Sequence[Mapping], **options) -> list[ClipScore]:
    """Score every labelled clip from its results file in ``results_dir``.

    A clip without a results file scores ``missing``. ``options`` go to :func:`score_clip`.

    Raises
    ------
    ValueError
        If a label is refused (:func:`~asnn.evaluation.labels.check_labels`): checked here
        too, for labels that did not come through :func:`~asnn.evaluation.labels.load_labels`.
    """
    check_labels(labels)
    scores = []
    for label in labels:
        path = results_path(results_dir, label)
        scores.append(missing_clip(label) if path is None
                      else score_clip(load_records(path), label, **options))
    return scores
