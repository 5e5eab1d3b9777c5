"""Running the detectors over labelled clips (``asnn eval CLIPS_DIR``).

:func:`evaluate_clips` runs each detector (a spec, see :mod:`asnn.evaluation.runs`) over every
clip of a ``labels.json``, keeps each run's per-frame results as
``results/<detector>/<clip>.jsonl`` (the ``asnn detect --jsonl`` format), scores them with
:mod:`asnn.evaluation.scoring`, and writes ``results.json``, ``report.md`` and the plots.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from ..errors import timing_warnings_to
from ..io.files import write_atomically
from ..io.sources import BackwardStamps, SourceError, open_source
from ..params import SLOW_FPS, SLOW_NOTE
from . import figures, scoring
from .labels import (center_outside, clip_hint, load_labels, mismatches, result_name,
                     unlabelled_videos)
from .perturb import check_perturbation, delivered_period, describe, perturb_label, perturbed
from .pool import run_tasks
from .progress import Silent
from .runs import (DEFAULT_DETECTORS, TARGET_QUALITY_HEADER, TARGET_QUALITY_NOTE, DetectorSpec,
                   fmt, outcome_cell, paired_comparisons, paired_section, parse_detector,
                   parse_detectors,
                   rate_interval, run_detector, target_quality_cells, write_json, write_jsonl)

__all__ = ["check_clips", "clip_warnings", "evaluate_clips", "probe_clips",
           "open_labelled_clip"]


def probe_clips(clips_dir: str | Path, labels: Sequence[Mapping]
               ) -> tuple[list[int], list[str], list[tuple[int, int] | None]]:
    """Open every labelled clip (:func:`~asnn.io.sources.open_source`, which decodes its first
    frame): the frames each states (0 where unknown or unreadable), one line per clip that
    cannot be opened, naming it (missing, not a video OpenCV decodes, a bag without its image
    topic), and each clip's frame size (width, height; None where it cannot be opened).
    Checked before anything runs, so that a clip that cannot be scored stops the
    evaluation instead of leaving the rates without it."""
    counts, problems, sizes = [], [], []
    candidates = None  # the folder's videos no label names, listed once if a clip is missing
    for lab in labels:
        try:
            source = open_source(str(Path(clips_dir) / lab["file"]), topic=lab.get("topic"))
        except SourceError as exc:
            # the command line's way to choose a topic is not a label's
            hint = "; in labels.json, the entry's topic names it" if (
                exc.reason == "several-topics") else ""
            if exc.reason == "missing" and not (Path(clips_dir) / lab["file"]).exists():
                if candidates is None:
                    candidates = unlabelled_videos(clips_dir, labels)
                hint = clip_hint(lab["file"], candidates)
            problems.append(str(exc) + hint)
            counts.append(0)
            sizes.append(None)
        else:
            counts.append(int(source.frame_count or 0))
            first = next(iter(source.frames()), None)
            sizes.append(None if first is None else (first.shape[1], first.shape[0]))
    return counts, problems, sizes


def open_labelled_clip(spec: str, topic: str | None = None):
    """A labelled clip opened as ``asnn eval`` reads it: a bag's frames whose header stamp goes
    back taken at the latest frame's time and its clock resets re-based (and one whose stamp is
    unset held there too), so that each frame keeps its place for the labels. Returns the
    :class:`~asnn.io.sources.Source` and the :class:`~asnn.io.sources.BackwardStamps` that
    counts them as the frames are read (for :func:`clip_warnings`)."""
    stamps = BackwardStamps()
    return open_source(spec, topic=topic, on_error=stamps, hold_backwards=True), stamps


def clip_warnings(label: Mapping, frames: int, fps: float, size: tuple[int, int] | None,
                  warmup: int = scoring.WARMUP_FRAMES, *, slow: bool = True,
                  stamps: tuple[int, int, str | None, int] = (0, 0, None, 0)) -> list[str]:
    """What ``asnn eval`` (and ``--held-out``) says of a clip as it was decoded: where it
    disagrees with its label (:func:`~asnn.evaluation.labels.mismatches`), why it cannot be
    scored (:func:`~asnn.evaluation.scoring.unscored`), with ``slow`` a frame rate below
    :data:`~asnn.params.SLOW_FPS`, and a bag's ``stamps`` as :func:`open_labelled_clip` counted
    them (frames whose header stamp goes back, clock resets, the first reset's message, frames
    whose header stamp is unset held at the latest frame's time). One sentence each, naming
    the clip."""
    found = mismatches(label, frames, fps, size=size) + scoring.unscored(label, frames, warmup)
    if slow and fps and fps < SLOW_FPS:
        found.append(f"{label['file']}: {fps:g} frames a second; {SLOW_NOTE}")
    backwards, resets, first_reset, unset = stamps
    if backwards:
        found.append(f"{label['file']}: {backwards} frame{'' if backwards == 1 else 's'} whose "
                     "header stamp goes back, taken at the latest frame's time")
    if resets:
        found.append(f"{label['file']}: {resets} clock reset{'' if resets == 1 else 's'}, "
                     f"timed on from the latest frame's time; the first: {first_reset}")
    if unset:
        found.append(f"{label['file']}: {unset} frame{'' if unset == 1 else 's'} whose header "
                     "stamp is unset (0), its log time not the camera's clock, taken at the "
                     "latest frame's time")
    return found


def check_clips(clips_dir: str | Path, labels: Sequence[Mapping], most: int = 5) -> list[int]:
    """The frames each labelled clip states (:func:`probe_clips`); ValueError naming the clips
    that cannot be opened, the first ``most`` of them, or else the labels whose ``center`` is
    outside their clip's frames (:func:`~asnn.evaluation.labels.center_outside`)."""
    counts, problems, sizes = probe_clips(clips_dir, labels)
    if problems:
        more = f"; and {len(problems) - most} more" if len(problems) > most else ""
        raise ValueError(f"{len(problems)} of the {len(labels)} labelled clips cannot be read "
                         f"(mend or remove their entries): {'; '.join(problems[:most])}{more}")
    outside = [problem for lab, size in zip(labels, sizes) if size is not None
               for problem in [center_outside(lab, *size)] if problem is not None]
    if outside:
        more = f"; and {len(outside) - most} more" if len(outside) > most else ""
        raise ValueError(f"{len(outside)} of the {len(labels)} labels put the object outside "
                         f"their clip: {'; '.join(outside[:most])}{more}")
    return counts


def _run_clip(video: str, detector: DetectorSpec, out_path: str, topic: str | None = None,
              perturbation: str | None = None
              ) -> tuple[int, str | None, tuple | None]:
    """Worker: one detector on one clip (a bag's ``topic``), its frames perturbed where
    ``perturbation`` names one, results to ``out_path``. Returns the frames run, the error
    (or None) and the clip as decoded, before any perturbation: its frames, frame rate, frame
    size (width, height) and stamps (:func:`clip_warnings`'s), with the detector's own
    warnings of the clip's frame times (:class:`~asnn.errors.TimingWarning`)."""
    decoded, size = 0, None

    def counted(frames):
        nonlocal decoded, size
        for item in frames:
            decoded += 1
            if size is None:
                size = (item[1].shape[1], item[1].shape[0])  # (t, image): width, height
            yield item

    timing: list[str] = []  # the model's TimingWarning, a line of the run's warnings
    try:
        clip, stamps = open_labelled_clip(video, topic)
        with timing_warnings_to(timing.append):
            records = run_detector(perturbed(counted(clip.timed_frames()), perturbation),
                                   detector, delivered_period(clip.fps, perturbation))
    except (SourceError, ValueError) as exc:
        return 0, str(exc), None
    write_jsonl(Path(out_path), records)
    return len(records), None, (decoded, clip.fps, size, stamps.tally, tuple(timing))


def _clips_report(results: Mapping) -> str:
    settings = results["settings"]
    names = list(results["detectors"])
    lines = [
        "# Evaluation on labelled clips",
        "",
        f"Clips: `{settings['clips_dir']}` (labels `{settings['labels']}`), detectors "
        f"{', '.join(f'`{m}`' for m in names)}. Scoring (SPEC.md section 5): warm-up "
        f"{settings['warmup']} frames; hit when the first warning lies in "
        f"[onset - {settings['early_tolerance_s']:g} s, contact + {scoring.CONTACT_SLACK_FRAMES}"
        " frames]; an earlier first warning is an early warning (a false alarm); any warning on a"
        " non-collision clip is a false alarm. " + TARGET_QUALITY_NOTE + (
            f" Frames perturbed: {settings['perturbation']}"
            f" ({describe(settings['perturbation'])})."
            if settings.get("perturbation") else ""),
        "",
        "| detector | hits | early | late | misses | false alarms (nc) | quiet (nc) | hit rate |"
        " false-alarm rate | mean / median lead (hits) | median loc. error | "
        + " | ".join(TARGET_QUALITY_HEADER) + " | warning frames in /"
        " out of windows | warning frames per minute of non-collision video |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for m in names:
        s = results["detectors"][m]["summary"]
        lines.append(
            f"| {m} | {s['hit']}/{s['collision_clips']} | {s['early']} | {s['late']} | {s['miss']}"
            f" | {s['false']}/{s['noncollision_clips']} | {s['quiet']}/{s['noncollision_clips']}"
            f" | {rate_interval(s['hit_rate'], s.get('hit_rate_ci'))}"
            f" | {rate_interval(s['false_alarm_rate'], s.get('false_alarm_rate_ci'))}"
            f" | {fmt(s['mean_lead_s'], 2, ' s')} / {fmt(s['median_lead_s'], 2, ' s')}"
            f" | {fmt(s['median_localisation_px'], 0, ' px')}"
            f" | {' | '.join(target_quality_cells(s))}"
            f" | {s['window_warning_frames']} / {s['warning_frames'] - s['window_warning_frames']}"
            f" | {fmt(s['warning_frames_per_minute'], 1)} |")
        if s["missing"]:
            lines[-1] += (f" ({s['missing']} clip{'' if s['missing'] == 1 else 's'} without "
                          "results)")
    lines += ["", "Detectors:", ""] + [
        f"- `{m}`: {parse_detector(m).description}" for m in names]
    lines += ["", "Columns: hits, early, late and misses count the collision clips (a *late* "
              "first warning comes after the hit window, a *miss* has none after the warm-up); "
              "(nc): of the clips without a collision, those with any warning (false alarms) "
              "and those without (quiet); hit rate: hits over collision clips; false-alarm "
              "rate: early warnings and false alarms over all clips scored, with 95 % Wilson "
              "intervals in brackets; lead: contact frame - first "
              "warning, in seconds at the label's fps; loc. error: distance from the nearest "
              "target at the first warning to the labelled centre (ASNN only); warning frames "
              "in / out of windows: frames with a warning after the warm-up inside the hit "
              "windows, and elsewhere (on clips without a collision, before the window, and "
              "after contact + "
              f"{scoring.CONTACT_SLACK_FRAMES} frames); warning frames per minute: over the "
              "clips without a collision, after the warm-up."]
    lines += ["", "Per clip: the hit window's first and last frames (a first warning before it is "
              "early, after it late); each detector's outcome, first warning frame (lead time, "
              "s), warning frames, and the distance from the nearest target to the labelled "
              "centre at the first warning.", "",
              "| clip | onset | contact | hit window | " + " | ".join(names) + " |",
              "| --- | --- | --- | --- | " + " | ".join("---" for _ in names) + " |"]
    for index, clip in enumerate(results["detectors"][names[0]]["clips"]):
        lab = results["labels"][index]  # the scores come in the labels' order
        cells = []
        for m in names:
            cells.append(outcome_cell(results["detectors"][m]["clips"][index]))
        # the label's, the same for every detector that scored the clip
        window = next((results["detectors"][m]["clips"][index]["window"] for m in names
                       if results["detectors"][m]["clips"][index].get("window")), None)
        lines.append(f"| {clip['clip']} | {fmt(lab.get('onset_frame'))} | "
                     f"{fmt(lab.get('contact_frame'))} | "
                     f"{fmt(None) if window is None else f'{window[0]}-{window[1]}'} | "
                     + " | ".join(cells) + " |")
    lines += paired_section(names[0], results.get("paired", {}))
    if results.get("errors"):
        lines += ["", "Errors:", ""] + [f"- {e}" for e in results["errors"]]
    if results.get("unlabelled"):
        lines += ["", "Videos in the folder without a label (not scored): "
                  + ", ".join(results["unlabelled"])]
    if results.get("warnings"):
        # mismatches with the labels, clips slower than ASNN was made for (not a mismatch),
        # bags whose stamps go back (a clock reset among them)
        lines += ["", "Warnings (clips that disagree with their labels, run slower than ASNN "
                  "was made for, or are bags with frames stamped out of order):", ""] + [
            f"- {w}" for w in results["warnings"]]
    return "\n".join(lines) + "\n"


def evaluate_clips(clips_dir: str | Path, out_dir: str | Path, *,
                   labels_path: str | Path | None = None,
                   detectors: Sequence[str] = DEFAULT_DETECTORS, preset_name: str | None = None,
                   early_tolerance_s: float = scoring.EARLY_TOLERANCE_S,
                   warmup: int = scoring.WARMUP_FRAMES, jobs: int = 1, plots: bool = True,
                   perturbation: str | None = None, progress=None) -> dict:
    """Run, score and report every detector on every labelled clip.

    Parameters
    ----------
    clips_dir : path
        Directory of the clips; each label's ``file`` is relative to it: a video, or a ROS 2
        bag whose image topic the label's ``topic`` names (needed when it has several).
    out_dir : path
        Where ``results.json``, ``report.md``, ``results/<detector>/<clip>.jsonl`` and
        ``plots/*.png`` go (``<detector>`` is the spec with ``:`` replaced by ``-``).
    labels_path : path, optional
        Default ``clips_dir / "labels.json"``.
    detectors : sequence of str
        Detector specs (``asnn``, ``asnn:PRESET``, ``lgmd1``, ``lgmd2``).
    preset_name : str, optional
        The preset a bare ``asnn`` stands for; None means ``default``.
    early_tolerance_s, warmup : scoring rules (see :func:`asnn.evaluation.scoring.score_clip`).
    jobs : int
        Processes running (detector, clip) pairs in parallel.
    plots : bool
        Draw the PNGs.
    perturbation : str, optional
        Run on the clips' frames perturbed by one of
        :data:`~asnn.evaluation.perturb.PERTURBATIONS` or a family of
        :data:`~asnn.evaluation.perturb.FAMILIES` (``jpeg80``, ``gain1.04``; the labels follow a
        mirrored frame).
    progress : ProgressPrinter-like, optional

    Returns
    -------
    dict
        What ``results.json`` holds: ``settings``, ``labels``, ``detectors`` (per detector a
        ``summary`` and per-clip ``clips`` scores), ``errors``, ``warnings`` (clips whose
        decoded frames, frame rate or size disagree with their labels:
        :func:`~asnn.evaluation.labels.mismatches`; and, where ASNN is scored unperturbed,
        clips slower than :data:`~asnn.params.SLOW_FPS`; bags with frames whose header stamp
        goes back, taken at the latest frame's time) and ``unlabelled`` (the videos in
        ``clips_dir`` no label names, not scored:
        :func:`~asnn.evaluation.labels.unlabelled_videos`).

    Raises
    ------
    ValueError
        For an unknown detector, preset or perturbation, a labels file that cannot be read or
        has an entry :func:`~asnn.evaluation.labels.check_labels` refuses, or a labelled clip
        that cannot be opened (:func:`check_clips`), all before anything runs. A clip that
        fails later (a frame size that changes mid-clip, say) is named in ``errors`` and scored
        as ``missing``.
    """
    clips_dir, out_dir = Path(clips_dir), Path(out_dir)
    labels_path = Path(labels_path) if labels_path else clips_dir / "labels.json"
    check_perturbation(perturbation)
    given = load_labels(labels_path)
    labels = [perturb_label(lab, perturbation) for lab in given]
    specs = parse_detectors(detectors, preset_name)
    stated = check_clips(clips_dir, given)
    progress = progress or Silent()

    tasks = [(str(clips_dir / lab["file"]), spec,
              str(out_dir / "results" / spec.slug / f"{result_name(lab)}.jsonl"),
              lab.get("topic"), perturbation)
             for spec in specs for lab in labels]
    for task in tasks:  # stale results of an earlier run must not be scored
        Path(task[2]).unlink(missing_ok=True)
    expected = [int(lab.get("frames") or count or 1) for _ in specs
                for lab, count in zip(labels, stated)]
    clip_of = [k for _ in specs for k in range(len(labels))]  # each task's label
    progress.start(sum(expected), "eval")
    errors, warnings, checked = [], [], set()
    # a slow camera's clip is scored as any other, but the default was made for 20 fps or more
    # (a perturbation that halves the rate is that experiment, and says so itself)
    slow = perturbation is None and any(spec.model == "asnn" for spec in specs)

    def finished(index: int, frames: int, error: str | None,
                 decoded: tuple | None) -> None:
        spec, clip = tasks[index][1], clip_of[index]
        # as labelled (sub/clip.mp4, not clip.mp4), a bag's camera with its topic
        name = f"{spec.name} {scoring.clip_name(labels[clip])}"
        progress.advance(expected[index], name)
        progress.note(name + (f": {error}" if error else
                              f", {frames} frame{'' if frames == 1 else 's'}"))
        if error:
            errors.append(f"{name}: {error}")
        if decoded is None:
            return
        frames, fps, size, stamps, timing = decoded
        if clip not in checked:  # once a clip, by its first run
            checked.add(clip)
            warnings.extend(clip_warnings(given[clip], frames, fps, size, warmup, slow=slow,
                                          stamps=stamps))
        warnings.extend(f"{name}: {message}" for message in timing)  # the detector's own

    for index, result in run_tasks(_run_clip, tasks, jobs):
        finished(index, *result)
    progress.finish()

    results = {
        "settings": {"clips_dir": str(clips_dir), "labels": str(labels_path),
                     "detectors": [spec.name for spec in specs],
                     "parameters": {spec.name: spec.parameters for spec in specs},
                     "early_tolerance_s": early_tolerance_s, "warmup": warmup,
                     "perturbation": perturbation,
                     "contact_slack_frames": scoring.CONTACT_SLACK_FRAMES},
        "labels": labels,
        "detectors": {},
        "errors": errors,
        "warnings": warnings,
        "unlabelled": unlabelled_videos(clips_dir, given),
    }
    scores = {spec.name: scoring.score_directory(out_dir / "results" / spec.slug, labels,
                                                 warmup=warmup,
                                                 early_tolerance_s=early_tolerance_s)
              for spec in specs}
    for name, clip_scores in scores.items():
        results["detectors"][name] = {"summary": scoring.summarize(clip_scores),
                                      "clips": [s.to_dict() for s in clip_scores]}
    results["paired"] = paired_comparisons(scores)
    write_json(out_dir / "results.json", results)
    write_atomically(out_dir / "report.md", _clips_report(results))
    if plots:
        _plot_clips(out_dir, labels, specs, results, warmup)
    return results


def _plot_clips(out_dir: Path, labels: Sequence[Mapping], specs: Sequence[DetectorSpec],
                results: Mapping, warmup: int) -> None:
    for index, lab in enumerate(labels):
        series = {}
        for spec in specs:
            path = scoring.results_path(out_dir / "results" / spec.slug, lab)
            if path is None:
                continue
            records = scoring.load_records(path)
            series[spec.name] = figures.response_series(
                records, results["detectors"][spec.name]["clips"][index]["outcome"])
        if not series:
            continue
        window = results["detectors"][specs[0].name]["clips"][index].get("window")
        figures.plot_clip_responses(
            out_dir / "plots" / f"{result_name(lab)}.png",
            {"name": lab["file"], "onset": lab.get("onset_frame"),
             "contact": lab.get("contact_frame"), "window": window, "warmup": warmup,
             "fps": lab.get("fps"), "models": series})
    figures.plot_summary(out_dir / "plots" / "summary.png",
                         {spec.name: results["detectors"][spec.name]["summary"] for spec in specs})
