"""The labelled suite of generated scenes, scored for every detector (``asnn eval --synthetic``).

:func:`evaluate_suite` generates the cases of :mod:`asnn.stimuli.suite`, runs each detector (a
spec, see :mod:`asnn.evaluation.runs`) over each case, scores it with
:mod:`asnn.evaluation.scoring` (generated clips: no early tolerance, 5 warm-up frames), and writes

- ``labels.json``, the labels of the cases (``file`` is ``<case>.mp4``, what
  ``asnn scene --case`` writes), with their per-frame ``track``, ``target_size`` and ``ttc``;
- ``results/<detector>/<case>.jsonl``, the per-frame results (``asnn detect --jsonl`` format),
  so ``scoring.score_directory`` rescored them the same way;
- ``results.json`` and ``report.md``: per detector the outcome counts, hit and false-alarm
  rates, median lead, median localisation error and the warning frames after the approach ended;
  the same per category tag; each near miss against its collision-course twin; every case;
- ``plots/summary.png`` unless ``plots=False``, and ``plots/<case>.png`` (out(t), spike rate and
  warnings of every detector) with ``case_plots=True``.
"""

from __future__ import annotations

import fnmatch
import json
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from ..io.files import write_atomically
from ..stimuli.effects import scaled_size
from ..stimuli.suite import (CASES, DESIGN_INPUTS, DRIVING_SIZE, EXTRA_GROUPS, GROUPS,
                             PLANAR_SIZE,
                             SUITE_VERSION, check_driving_size, check_scale, check_variant,
                             make_case, suite_cases)
from . import scoring
from .perturb import check_perturbation, delivered_period, describe, perturb_label, perturbed
from .pool import run_tasks
from .progress import Silent
from .runs import (DEFAULT_DETECTORS, TARGET_QUALITY_HEADER, TARGET_QUALITY_NOTE, DetectorSpec,
                   at_rate, fmt, outcome_cell, paired_comparisons, paired_section,
                   parse_detectors, rate_interval, run_detector, target_quality_cells,
                   write_json, write_jsonl)

__all__ = ["EARLY_TOLERANCE_S", "evaluate_suite", "near_miss_pairs", "category_summaries",
           "suite_report"]

EARLY_TOLERANCE_S = 0.0  # generated clips: the onset is exact


def _run_case(name: str, specs: Sequence[DetectorSpec], out_dir: str, warmup: int,
              plots: bool, variant: int = 0, perturbation: str | None = None,
              driving_size: tuple[int, int] | None = None,
              scale: float | None = None) -> dict:
    # plots import matplotlib, and take longer than the runs: only where asked for
    """Worker: generate one case (its frames perturbed where ``perturbation`` names one), run
    and score every detector on it, write its results."""
    scene = make_case(name, variant, driving_size, scale)
    label = perturb_label(scene.label(f"{name}.mp4"), perturbation)
    try:  # a label that cannot be written must stop the run before its detectors, naming it
        json.dumps(label, allow_nan=False)
    except ValueError as error:
        raise ValueError(f"case {name}: its label is not valid JSON ({error})") from None
    entry = {"label": label, "scores": {}}
    series = {}
    for spec in specs:
        records = run_detector(perturbed(at_rate(scene.frames, scene.fps), perturbation), spec,
                               delivered_period(scene.fps, perturbation))
        write_jsonl(Path(out_dir) / "results" / spec.slug / f"{name}.jsonl", records)
        score = scoring.score_clip(records, label, warmup=warmup,
                                   early_tolerance_s=EARLY_TOLERANCE_S)
        entry["scores"][spec.name] = (score, max((r["out"] for r in records[warmup:]),
                                                 default=None))
        if plots:
            from . import figures

            series[spec.name] = figures.response_series(records, score.outcome)
    if plots:
        from . import figures

        figures.plot_clip_responses(
            Path(out_dir) / "plots" / f"{name}.png",
            {"name": name, "onset": label["onset_frame"], "contact": label["contact_frame"],
             "window": next(iter(entry["scores"].values()))[0].window, "warmup": warmup,
             "fps": label.get("fps"), "models": series})
    return entry


def category_summaries(cases: Sequence[Mapping], scores: Sequence[scoring.ClipScore]) -> dict:
    """Per category tag, the summary (:func:`asnn.evaluation.scoring.summarize`) of one
    detector's clip scores over the cases carrying that tag.

    Parameters
    ----------
    cases : sequence of dict
        ``name`` and ``category`` of each case, in the order of ``scores``.
    scores : sequence of ClipScore
        The detector's scores.

    Returns
    -------
    dict
        ``{tag: summary}``, the groups first (in suite order), then the other tags A-Z.
    """
    tags = list(dict.fromkeys(t for case in cases for t in case["category"]))
    ordered = [g for g in GROUPS if g in tags] + sorted(t for t in tags if t not in GROUPS)
    return {tag: scoring.summarize([s for case, s in zip(cases, scores) if tag in case["category"]])
            for tag in ordered}


def near_miss_pairs(cases: Sequence[Mapping], detectors: Mapping[str, Sequence[Mapping]]) -> list:
    """Each near miss against its collision-course twin, for every detector.

    A near miss *passes* for a detector when it raises no warning, or warns later than the twin
    does and with a lower peak ``out``: it must not warn earlier than, or as strongly as, the same
    object on a collision course.

    Parameters
    ----------
    cases : sequence of dict
        ``name`` and ``twin`` of each case, in the order of the clip scores.
    detectors : dict
        ``{detector: clip scores with peak_out}``.

    Returns
    -------
    list of dict
        ``nearmiss``, ``twin`` and per detector ``{"nearmiss_first", "twin_first",
        "nearmiss_peak", "twin_peak", "nearmiss_frames", "twin_frames", "passes"}``; only pairs
        whose twin is among the cases.
    """
    index = {case["name"]: i for i, case in enumerate(cases)}
    pairs = []
    for i, case in enumerate(cases):
        twin = case.get("twin")
        if twin is None or twin not in index:
            continue
        row = {"nearmiss": case["name"], "twin": twin, "detectors": {}}
        for name, clips in detectors.items():
            near, course = clips[i], clips[index[twin]]
            first, twin_first = near["first_warning"], course["first_warning"]
            passes = first is None or (twin_first is not None and first > twin_first
                                       and near["peak_out"] < course["peak_out"])
            row["detectors"][name] = {
                "nearmiss_first": first, "twin_first": twin_first,
                "nearmiss_peak": near["peak_out"], "twin_peak": course["peak_out"],
                "nearmiss_frames": near["warning_frames"], "twin_frames": course["warning_frames"],
                "passes": passes}
        pairs.append(row)
    return pairs


def evaluate_suite(out_dir: str | Path, *, detectors: Sequence[str] = DEFAULT_DETECTORS,
                   preset_name: str | None = None, cases: str | None = None, jobs: int = 1,
                   warmup: int = scoring.WARMUP_FRAMES, plots: bool = True,
                   case_plots: bool = False, variant: int = 0, perturbation: str | None = None,
                   driving_size: tuple[int, int] | None = None, scale: float | None = None,
                   progress=None) -> dict:
    """Generate, run, score and report the labelled suite.

    Parameters
    ----------
    out_dir : path
    detectors : sequence of str
        Detector specs (``asnn``, ``asnn:PRESET``, ``lgmd1``, ``lgmd2``).
    preset_name : str, optional
        The preset a bare ``asnn`` stands for; None means ``default``.
    cases : str, optional
        Comma-separated patterns of case names or groups (see
        :func:`asnn.stimuli.suite.suite_cases`); None runs every case.
    jobs : int
        Processes running cases in parallel.
    warmup : int
    plots : bool
        Draw ``plots/summary.png``.
    case_plots : bool
        Draw ``plots/<case>.png`` too (about half a second a case).
    variant : int
        0: the suite's cases as designed; K >= 1: the same cases with fresh scene seeds
        (:func:`asnn.stimuli.suite.make_case`).
    perturbation : str, optional
        Run on the cases' frames perturbed by one of
        :data:`~asnn.evaluation.perturb.PERTURBATIONS` or a family of
        :data:`~asnn.evaluation.perturb.FAMILIES` (``jpeg80``, ``gain1.04``; the labels follow a
        mirrored frame).
    driving_size : (width, height), optional
        Render the driving scenes at this size instead of 192x128 (the same drives seen with
        more or fewer pixels; :func:`asnn.stimuli.suite.make_case`); the planar scenes keep
        theirs.
    scale : float, optional
        Render every case with this many times its pixels (the planar scenes too; 0.5-8;
        :func:`asnn.stimuli.suite.make_case`). Not with ``driving_size``.
    progress : ProgressPrinter-like, optional

    Returns
    -------
    dict
        What ``results.json`` holds.

    Raises
    ------
    ValueError
        For an unknown detector, preset, variant, perturbation, driving size or scale, both a
        driving size and a scale, or a pattern that matches no case.
    """
    out_dir = Path(out_dir)
    names = suite_cases(cases)
    check_variant(variant)
    if driving_size is not None:
        driving_size = check_driving_size(driving_size)
    if scale is not None:
        if driving_size is not None:
            raise ValueError("give a driving size or a scale, not both")
        scale = check_scale(scale)
    check_perturbation(perturbation)
    specs = parse_detectors(detectors, preset_name)
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs}")
    progress = progress or Silent()
    for spec in specs:  # stale results of an earlier run must not be mistaken for these
        for name in names:
            (out_dir / "results" / spec.slug / f"{name}.jsonl").unlink(missing_ok=True)
    progress.start(len(names), "eval --synthetic")
    entries: dict[str, dict] = {}
    started = time.perf_counter()

    def finished(name: str, entry: dict) -> None:
        entries[name] = entry
        outcomes = ", ".join(f"{d} {s.outcome}" for d, (s, _) in entry["scores"].items())
        progress.advance(1, name)
        progress.note(f"{name}: {outcomes}")

    tasks = [(name, specs, str(out_dir), warmup, case_plots, variant, perturbation,
              driving_size, scale) for name in names]
    for index, entry in run_tasks(_run_case, tasks, jobs):
        finished(names[index], entry)
    progress.finish()
    elapsed = time.perf_counter() - started

    labels = [entries[name]["label"] for name in names]
    case_info = [{"name": name, "group": CASES[name].group,
                  "category": list(CASES[name].category), "twin": CASES[name].twin,
                  **{key: entries[name]["label"][key]
                     for key in ("collision", "onset_frame", "contact_frame", "frames", "fps")}}
                 for name in names]
    scores = {spec.name: [entries[name]["scores"][spec.name][0] for name in names]
              for spec in specs}
    clips = {spec.name: [{**entries[name]["scores"][spec.name][0].to_dict(),
                          "peak_out": entries[name]["scores"][spec.name][1]} for name in names]
             for spec in specs}
    results = {
        "settings": {"suite_version": SUITE_VERSION, "variant": variant,
                     "perturbation": perturbation,
                     "driving_size": list(driving_size) if driving_size else None,
                     "scale": scale,
                     "cases": cases or "all",
                     "detectors": [spec.name for spec in specs],
                     "parameters": {spec.name: spec.parameters for spec in specs},
                     "warmup": warmup,
                     "early_tolerance_s": EARLY_TOLERANCE_S,
                     "contact_slack_frames": scoring.CONTACT_SLACK_FRAMES, "jobs": jobs},
        "elapsed_s": round(elapsed, 1),
        "frames": sum(c["frames"] for c in case_info),
        "cases": case_info,
        "detectors": {name: {"summary": scoring.summarize(scores[name]),
                             "categories": category_summaries(case_info, scores[name]),
                             "clips": clips[name]}
                      for name in scores},
        "pairs": near_miss_pairs(case_info, clips),
        "paired": paired_comparisons(scores),
    }
    write_json(out_dir / "labels.json", labels)
    write_json(out_dir / "results.json", results)
    write_atomically(out_dir / "report.md", suite_report(results))
    if plots:
        from . import figures

        figures.plot_summary(out_dir / "plots" / "summary.png",
                             {d: results["detectors"][d]["summary"] for d in scores})
    return results


def _size(size: Sequence[int], scale: float) -> str:
    return "{}x{}".format(*scaled_size(size, scale))


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return (["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
            + ["| " + " | ".join(row) + " |" for row in rows])


def _category_cell(s: Mapping) -> str:
    parts = []
    if s["collision_clips"]:
        parts.append(f"{s['hit']}/{s['collision_clips']} hit")
    if s["scored"]:
        parts.append(f"{s['false_alarms']}/{s['scored']} FA")
    return ", ".join(parts)


def _extra_note(cases: list[dict]) -> str:
    """What the report says of the extra cases it holds: which the default preset's design
    looked at (:data:`asnn.stimuli.suite.DESIGN_INPUTS`: in-sample), and that the others were
    not."""
    extra = [c["name"] for c in cases if c["group"] in EXTRA_GROUPS]
    seen = {what: [n for n in extra if any(fnmatch.fnmatchcase(n, p) for p in patterns)]
            for what, patterns in DESIGN_INPUTS.items()}
    seen = {what: names for what, names in seen.items() if names}
    note = ("Extra cases outside the suite (`asnn.stimuli.suite.EXTRA_CASES`): not part of its "
            "version")
    if not seen:
        return note + ", and not looked at while the default preset was designed."
    looked = "; ".join(f"{what} on {', '.join(f'`{n}`' for n in names)}"
                       for what, names in seen.items())
    others = len(extra) - sum(map(len, seen.values()))
    return (f"{note}. The default preset's design looked at some of them, whose figures are "
            f"in-sample: {looked}" + (f"; the other {others} {'was' if others == 1 else 'were'}"
                                       " not looked at." if others else "."))


def suite_report(results: Mapping) -> str:
    """``report.md`` of a suite run (what :func:`evaluate_suite` returns)."""
    settings = results["settings"]
    names = list(results["detectors"])
    cases = results["cases"]
    n_col = sum(c["collision"] for c in cases)
    rates = "/".join(f"{fps:g}" for fps in sorted({c["fps"] for c in cases}))
    lines = [
        f"# Labelled suite of generated scenes (version {settings['suite_version']}"
        + (f", variant {settings['variant']}" if settings.get("variant") else "") + ")",
        "",
        *([f"Variant {settings['variant']}: the suite's cases with fresh scene seeds (other "
           "textures, sensor noise and roadside objects; the same geometry, motion and labels)."
           " The default preset was designed on the suite as it is (variant 0), its region"
           " persistence and motion layers on variants 1-5 (docs/evaluation.md, 'The same cases"
           " in fresh scenery').",
           ""] if settings.get("variant") else []),
        *([_extra_note(cases), ""] if any(c["group"] in EXTRA_GROUPS for c in cases) else []),
        *([f"Frames perturbed: {settings['perturbation']} "
           f"({describe(settings['perturbation'])}).", ""]
          if settings.get("perturbation") else []),
        *([f"Driving scenes rendered at {settings['driving_size'][0]}x"
           f"{settings['driving_size'][1]} (the suite's are {DRIVING_SIZE[0]}x{DRIVING_SIZE[1]}:"
           " the same drives seen with other pixels); planar scenes at their own size.", ""]
          if settings.get("driving_size") else []),
        *([f"Every case rendered with {settings['scale']:g} times its pixels (planar scenes at "
           f"{_size(PLANAR_SIZE, settings['scale'])}, driving scenes at "
           f"{_size(DRIVING_SIZE, settings['scale'])}): the same scenes drawn with more or "
           "fewer pixels, not resized.", ""]
          if settings.get("scale") else []),
        f"{len(cases)} cases ({n_col} collisions, {len(cases) - n_col} not; "
        f"{results['frames']} frames at {rates} fps), selection `{settings['cases']}`; detectors "
        f"{', '.join(f'`{n}`' for n in names)}; {results['elapsed_s']:.0f} s wall time with "
        f"{settings['jobs']} job(s). Scoring (SPEC.md section 5, generated clips): warm-up "
        f"{settings['warmup']} frames; hit when the first warning lies in [onset, contact + "
        f"{settings['contact_slack_frames']} frames], early (a false alarm) before, late after; "
        "any warning on a non-collision case is a false alarm. FA = early + warned non-collision"
        " cases; FA rate over all cases. Lead = contact - first warning (hits). Localisation: "
        "the nearest target at the first warning to the labelled track. " + TARGET_QUALITY_NOTE
        + " *After*: warning "
        "frames after contact + 2 (or after an approach stopped) on collision cases.",
        "",
    ]
    rows = []
    for n in names:
        s = results["detectors"][n]["summary"]
        rows.append([f"`{n}`", f"{s['hit']}/{s['collision_clips']}", str(s["early"]),
                     str(s["late"]), str(s["miss"]), f"{s['false']}/{s['noncollision_clips']}",
                     str(s["false_alarms"]), rate_interval(s["hit_rate"], s.get("hit_rate_ci")),
                     rate_interval(s["false_alarm_rate"], s.get("false_alarm_rate_ci")),
                     fmt(s["median_lead_s"], 2, " s"), fmt(s["median_localisation_px"], 1, " px"),
                     *target_quality_cells(s),
                     f"{s['after_warning_frames']} ({s['after_warning_clips']} cases)"])
    lines += _table(["detector", "hits", "early", "late", "misses", "warned non-collision",
                     "FA", "hit rate", "FA rate", "median lead", "median loc. error",
                     *TARGET_QUALITY_HEADER, "frames after"], rows)

    pairs = results["pairs"]
    if pairs:
        lines += ["", "## Near misses against their collision-course twins", "",
                  "Each cell: first warning of the near miss / of its twin (`–`: none), and peak "
                  "`out` of each; ✓ when the near miss stays quiet, or warns later and weaker "
                  "than its twin.", ""]
        passed = {n: sum(p["detectors"][n]["passes"] for p in pairs) for n in names}
        lines += ["Passed: " + ", ".join(f"`{n}` {passed[n]}/{len(pairs)}" for n in names), ""]
        rows = []
        for p in pairs:
            cells = []
            for n in names:
                d = p["detectors"][n]
                cells.append(f"{'✓' if d['passes'] else '✗'} {fmt(d['nearmiss_first'])} / "
                             f"{fmt(d['twin_first'])} ({fmt(d['nearmiss_peak'], 2)} / "
                             f"{fmt(d['twin_peak'], 2)})")
            rows.append([f"{p['nearmiss']}", *cells])
        lines += _table(["near miss", *names], rows)

    lines += paired_section(names[0], results.get("paired", {}), "cases")

    lines += ["", "## By category", "",
              "Hits over the collision cases and false alarms over all cases carrying the tag "
              "(the first rows are the groups; see `asnn/stimuli/suite.py`).", ""]
    tags = list(results["detectors"][names[0]]["categories"])
    rows = []
    for tag in tags:
        tagged = [c for c in cases if tag in c["category"]]
        col = sum(c["collision"] for c in tagged)
        rows.append([tag, f"{col}/{len(tagged) - col}",
                     *[_category_cell(results["detectors"][n]["categories"][tag]) for n in names]])
    lines += _table(["category", "cases (collision/not)", *names], rows)

    lines += ["", "## Every case", "",
              "Outcome, first warning frame (lead), warning frames (and those after the approach), "
              "and the nearest target's distance from the labelled track at the first warning.", ""]
    rows = []
    for index, c in enumerate(cases):
        cells = [outcome_cell(results["detectors"][n]["clips"][index]) for n in names]
        rows.append([c["name"], c["group"], "yes" if c["collision"] else "no",
                     f"{c['onset_frame']}–{c['contact_frame']}" if c["collision"] else "–",
                     *cells])
    lines += _table(["case", "group", "collision", "onset–contact", *names], rows)
    return "\n".join(lines) + "\n"
