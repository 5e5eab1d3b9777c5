"""Held-out figures for the parameters chosen by looking at real clips (``asnn eval --held-out``).

The approach gate's thresholds (``tau_max``, ``offset_max``, ``approach_frames``, the
partial-overlap regime with its ``overlap_tau_max``, ``overlap_offset_max`` and
``overlap_fit_min``, the scene-relative test's ``scene_tolerance``, and the share of its own
expansion an object must keep against the scene to count ``own_motion_weight`` times,
``own_motion_ratio``) were set by looking at labelled real clips. A score of those thresholds on
the clips that chose them is not evidence, so this module reports, beside it,
leave-one-clip-out figures: for each clip, the thresholds are chosen again from
:data:`GATE_GRID` on the *other* clips only (by :func:`selection_key`, among the grid points
that keep the generated suite within its aims: :func:`suite_admissible`), and that clip is
scored with the thresholds it did not help choose.
The preset's own thresholds agree with what this procedure picks on every clip of the design
set wherever those clips tell the values apart by hits and false alarms; among values the clips
tie on, the preset keeps those the generated suite favoured (the all-clip choice, by either
tie-break, can differ there: ``held_out.md`` gives both, and the README says where).
Since the tie-break decides part of the held-out figures, they are also given whatever breaks
the ties: expected over every tied point of each fold, and the fewest and the most that any
choice among them gives.

Running the model once per grid point would cost the grid's size in model runs: each clip is
run once instead, and the gate replayed for each grid point (:mod:`asnn.evaluation.gate_replay`).
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path

from ..io.files import write_atomically
from ..params import DEFAULT_PRESET, ASNNParams
from . import scoring
from .clips import check_clips, clip_warnings
from .gate_replay import ClipTrace, check_replay, replay, replays, trace_item
from .labels import load_labels
from .options import TIE_BREAKS
from .pool import run_tasks
from .runs import DetectorSpec, write_json

# the preset's row: its thresholds were tuned on ../shared/data/real, so on a user's own clips
# they are already held out
PRESET_ROW = ("preset thresholds (in-sample on the real clips that chose them, held out on "
              "others)")

__all__ = ["GATE_GRID", "SUITE_AIMS", "grid", "suite_summaries", "suite_admissible",
           "selection_key",
           "TIE_BREAKS", "leave_one_out", "held_out_report", "summary_lines",
           "evaluate_held_out"]

# the thresholds chosen by looking at real clips, and the values tried for each
GATE_GRID: dict[str, tuple] = {
    "tau_max": (1.0, 1.5, 2.0, 2.5),
    "offset_max": (0.75, 1.0, 1.5, 2.0),
    "approach_frames": (2, 3, 4),
    "partial_overlap": (False, True),  # the overlap_* values count only with it
    "overlap_tau_max": (0.8, 1.0, 1.2),
    "overlap_offset_max": (1.5, 2.0, 2.5),
    "overlap_fit_min": (0.2, 0.4, 0.6),
    "scene_tolerance": (0.0, 0.1),
    # 0.25 and 0.5 are not tried: each adds two false alarms over the fresh-scenery variants 1-5
    # (a night cut-in, a left turn), which no real clip decides
    "own_motion_ratio": (0.75, 1.0),
}
# a grid point is admissible when the generated suite keeps at least this hit rate and at most
# this false-alarm rate with it: near misses and passing traffic, the generated cases a fleet
# would see every day, must stay quiet (one case in a hundred)
SUITE_AIMS = {"hit_rate": 0.90, "false_alarm_rate": 0.01}


def grid(base: ASNNParams) -> list[ASNNParams]:
    """``base`` with each combination of :data:`GATE_GRID`'s values, in grid order; without
    ``partial_overlap`` only the first value of each ``overlap_*`` (they would not count)."""
    names = list(GATE_GRID)
    inert = [n.startswith("overlap_") for n in names]
    points = []
    for values in itertools.product(*(GATE_GRID[n] for n in names)):
        point = dict(zip(names, values))
        if not point["partial_overlap"] and any(
                dead and value != GATE_GRID[n][0] for n, value, dead in zip(names, values, inert)):
            continue
        points.append(base.model_copy(update=point))
    return points


def suite_summaries(traces: Sequence[ClipTrace], labels: Sequence[Mapping],
                    base: ASNNParams, warmup: int = scoring.WARMUP_FRAMES,
                    jobs: int = 1, progress=None) -> list[dict]:
    """For each grid point, its summary (:func:`~asnn.evaluation.scoring.summarize`) on the
    generated suite, from the suite's traces and labels (scored as generated clips: no early
    tolerance); the grid's points replayed in ``jobs`` processes, ``progress`` advanced by
    each point."""
    return [scoring.summarize(scores) for scores in
            _grid_scores(traces, labels, grid(base), warmup, 0.0, jobs, progress)]


def _grid_scores(traces: Sequence[ClipTrace], labels: Sequence[Mapping],
                 points: Sequence[ASNNParams], warmup: int, early_tolerance_s: float,
                 jobs: int, progress=None) -> list[list[scoring.ClipScore]]:
    """Per grid point, each clip's score under it, replayed in ``jobs`` processes. The points
    go out in runs of consecutive points, eight per process (a replay takes milliseconds: one
    task per point would spend more on sending the traces than on replaying them), and
    ``progress`` advances by each run's points."""
    chunks = max(1, min(8 * max(jobs, 1), len(points)))
    bounds = [len(points) * k // chunks for k in range(chunks + 1)]
    tasks = [(traces, labels, points[a:b], warmup, early_tolerance_s)
             for a, b in zip(bounds, bounds[1:])]
    found = {}
    for index, scores in run_tasks(_score_points, tasks, jobs):
        found[index] = scores
        if progress is not None:
            progress.advance(len(scores))
    return [scores for k in range(chunks) for scores in found[k]]


def _score_points(traces: Sequence[ClipTrace], labels: Sequence[Mapping],
                  points: Sequence[ASNNParams], warmup: int,
                  early_tolerance_s: float) -> list[list[scoring.ClipScore]]:
    """Each point's scores on the clips; consecutive points that differ in
    ``own_motion_ratio`` alone (the grid's last name) are replayed together
    (:func:`~asnn.evaluation.gate_replay.replays`)."""
    scores = []
    for _, group in itertools.groupby(points, key=lambda g: g.model_dump(
            exclude={"own_motion_ratio"})):
        group = list(group)
        ratios = [g.own_motion_ratio for g in group]
        # each clip's records scored at once: kept for every clip, they survived into the
        # garbage collector's older generations, whose passes over the traces slowed the
        # replay by a third
        per_clip = [[scoring.score_clip(records, lab, warmup=warmup,
                                        early_tolerance_s=early_tolerance_s)
                     for records in replays(tr, group[0], ratios)]
                    for tr, lab in zip(traces, labels)]
        scores += [[clip[k] for clip in per_clip] for k in range(len(group))]
    return scores


def suite_admissible(summaries: Sequence[Mapping]) -> list[bool]:
    """For each grid point's suite summary (:func:`suite_summaries`), whether the suite stays
    within :data:`SUITE_AIMS`."""
    verdicts = []
    for s in summaries:
        hits, alarms = s["hit_rate"], s["false_alarm_rate"]  # None: no such case selected
        verdicts.append((hits is None or hits >= SUITE_AIMS["hit_rate"])
                        and (alarms is None or alarms <= SUITE_AIMS["false_alarm_rate"]))
    return verdicts


def selection_key(summary: Mapping, tie_break: str = "warning-frames",
                  suite: Mapping | None = None) -> tuple:
    """How a grid point is ranked on the clips that choose it (larger is better): hits minus
    false alarms (early warnings and warned non-collision clips count alike), then fewer false
    alarms, then by ``tie_break`` (:data:`TIE_BREAKS`; what still ties goes by grid order):
    ``warning-frames``, more warning frames inside the hit windows than outside them;
    ``suite``, the same two keys on the generated suite (``suite``, the point's summary
    there), which does not hold the clips being chosen on or held out; ``grid``, nothing more.

    Raises
    ------
    ValueError
        For a tie-break not in :data:`TIE_BREAKS`, or ``suite`` without its summary.
    """
    _check_tie_break(tie_break)
    key = (summary["hit"] - summary["false_alarms"], -summary["false_alarms"])
    if tie_break == "grid":
        return key
    if tie_break == "suite":
        if suite is None:
            raise ValueError("the suite tie-break needs the grid point's suite summary")
        return key + (suite["hit"] - suite["false_alarms"], -suite["false_alarms"])
    inside = summary["window_warning_frames"]
    return key + (inside - (summary["warning_frames"] - inside),)


def _check_tie_break(name: str) -> None:
    if name not in TIE_BREAKS:
        raise ValueError(f"unknown tie-break {name!r}; choose one of {', '.join(TIE_BREAKS)}")


def _gate(params: ASNNParams) -> dict:
    return {n: getattr(params, n) for n in GATE_GRID}


def leave_one_out(traces: Sequence[ClipTrace], labels: Sequence[Mapping], base: ASNNParams,
                  admissible: Sequence[bool] | None = None,
                  warmup: int = scoring.WARMUP_FRAMES,
                  early_tolerance_s: float = scoring.EARLY_TOLERANCE_S,
                  tie_break: str = "warning-frames",
                  suite: Sequence[Mapping] | None = None, jobs: int = 1,
                  progress=None) -> dict:
    """In-sample and leave-one-clip-out scores of the gate thresholds.

    Parameters
    ----------
    traces, labels : sequences of the same length, in the same order
    base : ASNNParams
        The preset the traces were made with; its own thresholds give the in-sample scores.
    admissible : sequence of bool, optional
        Per grid point (:func:`grid`), whether it may be chosen (:func:`suite_admissible`);
        all by default.
    warmup : int
        Frames at the start of each clip whose warnings are not scored (SPEC section 5).
    early_tolerance_s : float
        Seconds before the onset a first warning still counts as a hit.
    tie_break : str
        How grid points that tie on hits and false alarms are told apart (:data:`TIE_BREAKS`).
    suite : sequence of dict, optional
        Per grid point, its summary on the generated suite (:func:`suite_summaries`); needed
        by the ``suite`` tie-break.
    jobs : int
        Processes the grid's points are replayed in.
    progress : optional
        Advanced by each grid point replayed (:mod:`asnn.evaluation.progress`).

    Returns
    -------
    dict
        ``grid`` (the tried values), ``tie_break``, ``base`` (the preset's thresholds),
        ``admissible`` (the grid points that may be chosen; None when all may),
        ``chosen_all`` (the thresholds :func:`selection_key` picks on every clip),
        ``in_sample`` and ``held_out`` (per clip a score dict; ``held_out`` adds the ``chosen``
        thresholds), with their ``summary``; ``over_ties``: per clip, its held-out outcomes
        under every point that ties for the choice made without it (on hits and false
        alarms: what the tie-break decides between), and their ``summary``, the held-out
        hits and false alarms expected over those ties and their range whatever breaks them;
        with ``suite``, ``suite``: the suite's hits and false alarms under the preset's
        thresholds (``preset``, where the grid holds them) and under ``chosen_all``.
    """
    _check_tie_break(tie_break)
    points = grid(base)
    if tie_break == "suite" and (suite is None or len(suite) != len(points)):
        raise ValueError("the suite tie-break needs each grid point's suite summary")
    allowed = [k for k in range(len(points)) if admissible is None or admissible[k]]
    if not allowed:
        raise ValueError("no grid point keeps the generated suite within its aims")
    scores = _grid_scores(traces, labels, points, warmup, early_tolerance_s, jobs, progress)

    def ranked(exclude: int | None) -> tuple[int, list[int]]:
        """The point chosen without clip ``exclude``, and every point that ties with it on
        hits and false alarms (grid order)."""
        summaries = {k: scoring.summarize(s for i, s in enumerate(scores[k]) if i != exclude)
                     for k in allowed}
        primary = {k: selection_key(summaries[k], "grid") for k in allowed}  # hits, alarms
        keys = primary if tie_break == "grid" else {
            k: selection_key(summaries[k], tie_break, None if suite is None else suite[k])
            for k in allowed}
        # ties: the first in grid order (smaller thresholds first)
        chosen = max(allowed, key=lambda k: (keys[k], -k))
        return chosen, [k for k in allowed if primary[k] == primary[chosen]]

    base_scores = [scoring.score_clip(replay(tr, base), lab, warmup=warmup,
                                      early_tolerance_s=early_tolerance_s)
                   for tr, lab in zip(traces, labels)]
    held, ties = [], []
    for i in range(len(traces)):
        k, tied = ranked(i)
        held.append({**scores[k][i].to_dict(), "chosen": _gate(points[k])})
        ties.append(_over_ties([scores[t][i] for t in tied]))
    chosen_all = ranked(None)[0]
    results = {
        "grid": {n: list(v) for n, v in GATE_GRID.items()},
        "tie_break": tie_break,
        "base": _gate(base),
        "admissible": None if admissible is None else [_gate(points[k]) for k in allowed],
        "chosen_all": _gate(points[chosen_all]),
        "in_sample": {"clips": [s.to_dict() for s in base_scores],
                      "summary": scoring.summarize(base_scores)},
        "held_out": {"clips": held, "summary": scoring.summarize(
            scoring.ClipScore(**{k: v for k, v in c.items() if k != "chosen"}) for c in held)},
        "over_ties": {"clips": ties, "summary": _summarize_ties(ties)},
    }
    if suite is not None:
        # what the preset's thresholds (where the grid holds them) and the choice on every clip
        # score on the suite
        figures = ("hit", "collision_clips", "false_alarms", "clips")
        at = {"chosen_all": chosen_all, "preset": next(
            (k for k, g in enumerate(points) if _gate(g) == results["base"]), None)}
        results["suite"] = {name: {f: suite[k][f] for f in figures}
                            for name, k in at.items() if k is not None}
    return results


def _over_ties(scores: Sequence[scoring.ClipScore]) -> dict:
    """A held-out clip's outcomes under every grid point that ties for the choice made without
    it: how many tie, and the shares of them that hit it and that warn falsely on it."""
    n = len(scores)
    outcomes = dict(Counter(s.outcome for s in scores))
    return {"clip": scores[0].clip, "collision": scores[0].collision, "tied": n,
            "hit": outcomes.get("hit", 0) / n,
            "false_alarm": sum(s.false_alarm for s in scores) / n, "outcomes": outcomes}


def _summarize_ties(ties: Sequence[Mapping]) -> dict:
    """The held-out hits and false alarms whatever breaks the ties: their expected count when
    each fold takes one of its tied points at random (each alike), and the fewest and the most
    that any choice gives (the folds choose independently, so every combination can happen)."""
    collisions = [t for t in ties if t["collision"]]

    def spread(key: str, clips: Sequence[Mapping]) -> dict:
        return {"expected": sum(t[key] for t in clips),
                "fewest": sum(t[key] == 1.0 for t in clips),
                "most": sum(t[key] > 0.0 for t in clips)}

    return {"collision_clips": len(collisions), "noncollision_clips": len(ties) - len(collisions),
            "hits": spread("hit", collisions), "false_alarms": spread("false_alarm", ties),
            "median_tied": sorted(t["tied"] for t in ties)[len(ties) // 2] if ties else 0}


def held_out_report(results: Mapping, out_dir: str | Path) -> Path:
    """Write ``held_out.json`` and ``held_out.md``; returns the Markdown's path."""
    out_dir = Path(out_dir)
    write_json(out_dir / "held_out.json", results)
    ins, held = results["in_sample"], results["held_out"]

    def row(name: str, s: Mapping) -> str:
        return (f"| {name} | {s['hit']}/{s['collision_clips']} | {s['early']} | {s['late']} | "
                f"{s['miss']} | {s['false']}/{s['noncollision_clips']} | {s['false_alarms']} | "
                f"{s['window_warning_frames']} / {s['warning_frames'] - s['window_warning_frames']}"
                " |")

    lines = [
        "# Held-out figures of the approach gate's thresholds",
        "",
        f"Preset {_preset_named(results)}.",
        "",
        f"Preset thresholds: {_named(results['base'])} (on every clip: "
        f"{_named(results['chosen_all'])}). "
        "Leave-one-clip-out: each clip scored with the thresholds chosen on the other clips "
        "from the grid " + "; ".join(f"{k} in {v}" for k, v in results["grid"].items())
        + f"; ties on hits and false alarms go to {TIE_BREAKS[results['tie_break']]} "
        f"(`--tie-break {results['tie_break']}`).",
        "",
        "| figures | hits | early | late | misses | false (nc) | false alarms | "
        "warning frames in / out of windows |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        row(PRESET_ROW, ins["summary"]),
        row("held out (leave one clip out)", held["summary"]),
        "",
        "Per fold: the clip left out, its outcome with the preset's thresholds (in-sample on "
        "the real clips that chose them, held out on others) and with those chosen on the other "
        "clips (held out), and the thresholds chosen without it.",
        "",
        "| clip left out | preset | held out | " + " | ".join(results["grid"]) + " |",
        "| --- | --- | --- | " + " | ".join("---" for _ in results["grid"]) + " |",
    ]
    for a, b in zip(ins["clips"], held["clips"]):
        lines.append(f"| {a['clip']} | {_outcome(a)} | {_outcome(b)} | "
                     + " | ".join(f"{b['chosen'][n]}" for n in results["grid"]) + " |")
    lines += ["", "Columns: hits, early, late and misses count the collision clips (a *late* "
              "first warning comes after the hit window, a *miss* has none after the warm-up); "
              "false (nc): the clips without a collision with any warning; false alarms: early "
              "warnings and those clips; warning frames in / out of windows: frames with a "
              "warning after the warm-up inside the hit windows, and elsewhere. Per fold: the "
              "outcome (hit, early, late, miss; quiet or false on a clip without a collision) "
              "and its first warning frame after @; the thresholds by their `ASNNParams` names "
              "(the `overlap_*` ones count only with `partial_overlap` True). How many grid "
              "points tied for each fold's choice, and what they give its clip: \"Whatever "
              "breaks the ties\" below."]
    on_suite = results.get("suite") or {}
    if on_suite:
        lines += ["", "On the generated suite (" + "; ".join(
            f"{what}: {on_suite[name]['hit']}/{on_suite[name]['collision_clips']} hits, "
            f"{_count(on_suite[name]['false_alarms'], 'false alarm')} in "
            f"{on_suite[name]['clips']} cases"
            for name, what in (("preset", "the preset's thresholds"),
                               ("chosen_all", "the choice on every clip"))
            if name in on_suite) + ")."]
    ties = results.get("over_ties")
    if ties is not None:
        lines += _ties_lines(ties)
    if results.get("warnings"):
        lines += ["", "Warnings (clips that disagree with their labels, cannot be scored, or run "
                  "slower than ASNN was made for):", ""] + [f"- {w}" for w in results["warnings"]]
    path = out_dir / "held_out.md"
    write_atomically(path, "\n".join(lines) + "\n")
    return path


def _preset_named(results: Mapping) -> str:
    """The preset the results hold out, as the reports name it: `robust`, `default`
    (`robust`), `robust` with region_persistence = False."""
    name = results.get("preset", "default")
    named = f"`{name}`" + (f" (`{DEFAULT_PRESET}`)" if name == "default" else "")
    changed = results.get("overrides") or {}
    if not changed:
        return named
    return named + " with " + ", ".join(f"{k} = {v}" for k, v in changed.items())


def summary_lines(results: Mapping) -> list[str]:
    """What ``asnn eval --held-out`` prints: the in-sample and held-out hits, early and late
    warnings and false alarms, as ``held_out.md``'s first table has them; the held-out hits and
    false alarms expected over the ties, with the fewest and the most (its "Whatever breaks the
    ties"); and the preset's thresholds and those chosen on every clip, by name."""
    def scores(name: str, s: Mapping) -> str:
        return (f"{name}: {s['hit']}/{s['collision_clips']} hits ({s['early']} early, "
                f"{s['late']} late), false alarms on {s['false']}/{s['noncollision_clips']} "
                "clips without a collision")

    lines = [scores(PRESET_ROW, results["in_sample"]["summary"]),
             scores(f"held out (leave one clip out; ties by {results['tie_break']})",
                    results["held_out"]["summary"])]
    ties = results.get("over_ties")
    if ties is not None:
        s = ties["summary"]
        hits, alarms = s["hits"], s["false_alarms"]
        lines.append(
            f"held out over every tie: {hits['expected']:.1f}/{s['collision_clips']} hits "
            f"expected ({hits['fewest']} to {hits['most']}), {alarms['expected']:.1f} false "
            f"alarms expected in {s['collision_clips'] + s['noncollision_clips']} clips "
            f"({alarms['fewest']} to {alarms['most']})")
    lines += [f"preset thresholds ({_preset_named(results)}): {_named(results['base'])}",
              f"chosen on every clip: {_named(results['chosen_all'])}"]
    return lines


def _named(gate: Mapping) -> str:
    return ", ".join(f"{k} = {v}" for k, v in gate.items())


def _outcome(score: Mapping) -> str:
    """A held-out report's cell: the outcome, and its first warning frame after ``@``."""
    first = score["first_warning"]
    return score["outcome"] + ("" if first is None else f" @{first}")


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _ties_lines(ties: Mapping) -> list[str]:
    """The report's section on the held-out figures whatever breaks the ties."""
    s = ties["summary"]
    hits, alarms = s["hits"], s["false_alarms"]
    lines = [
        "",
        "## Whatever breaks the ties",
        "",
        "Without each clip, many grid points can tie on hits and false alarms; the tie-break "
        "then decides what the held-out clip is scored with. Over every tied point of each "
        f"fold (a median of {s['median_tied']} per fold): the expected held-out figures if each "
        "fold took one of them at random, and the fewest and the most that any choice among "
        "them gives.",
        "",
        "| | expected | fewest | most |",
        "| --- | --- | --- | --- |",
        f"| hits (of {s['collision_clips']}) | {hits['expected']:.1f} | {hits['fewest']} | "
        f"{hits['most']} |",
        f"| false alarms (of {s['collision_clips'] + s['noncollision_clips']} clips) | "
        f"{alarms['expected']:.1f} | {alarms['fewest']} | {alarms['most']} |",
        "",
        "| clip | tied points | share that hit | share that warn falsely | outcomes |",
        "| --- | --- | --- | --- | --- |",
    ]
    for t in ties["clips"]:
        outcomes = ", ".join(f"{k} {v}" for k, v in sorted(t["outcomes"].items()))
        hit = f"{t['hit']:.0%}" if t["collision"] else "–"
        lines.append(f"| {t['clip']} | {t['tied']} | {hit} | {t['false_alarm']:.0%} | "
                     f"{outcomes} |")
    return lines


def _label_warnings(labels: Sequence[Mapping], traces: Sequence[ClipTrace]) -> list[str]:
    """What ``asnn eval`` warns of the clips (:func:`~asnn.evaluation.clips.clip_warnings`),
    and a fold chosen on no clip at all."""
    found = [warning for label, trace in zip(labels, traces)
             for warning in clip_warnings(label, len(trace.frames), trace.fps, trace.size,
                                          stamps=trace.stamps)
             + [f"asnn {trace.clip}: {message}" for message in trace.timing]]
    if len(labels) == 1:
        found.append("one clip: its fold's thresholds are chosen on no clip (the first grid "
                     "point the suite admits), so its held-out figure says nothing")
    return found


def evaluate_held_out(clips_dir: str | Path, out_dir: str | Path, *,
                      labels_path: str | Path | None = None, preset_name: str = "default",
                      cases: str | None = None, jobs: int = 1, progress=None,
                      tie_break: str = "warning-frames",
                      overrides: Mapping[str, object] | None = None) -> dict:
    """Trace a preset on labelled clips and on the generated suite, and write the in-sample and
    leave-one-clip-out figures of its gate thresholds (:func:`leave_one_out`) to ``out_dir``,
    with the suite's hits and false alarms under the preset's thresholds and under the choice
    made on every clip (``suite``).

    ``cases`` selects the suite cases that decide which grid points are admissible (a pattern
    of :func:`asnn.stimuli.suite.suite_cases`; every case by default); ``tie_break`` is
    :func:`leave_one_out`'s; ``overrides`` change the preset's parameters (an addition switched
    off, say: its gate's limits are then chosen again, held out).

    Returns
    -------
    dict
        :func:`leave_one_out`'s result, with the run's ``clips_dir``, ``preset``, ``overrides``,
        ``suite_cases`` (how many cases decided admissibility) and ``warnings`` (what
        :func:`_label_warnings` finds of the clips and their labels); written to
        ``held_out.json``, and as ``held_out.md`` (:func:`held_out_report`).

    Raises
    ------
    ValueError
        For an unknown preset, one without the approach gate, an unknown tie-break, or a
        labels file that cannot be read or has an entry
        :func:`~asnn.evaluation.labels.check_labels` refuses, or a labelled clip that cannot
        be opened (:func:`~asnn.evaluation.clips.check_clips`), all before anything runs; or
        a clip whose frame size changes while it is read.
    OSError
        For a clip that fails while it is read.
    """
    from ..params import preset
    from ..stimuli.suite import make_case, suite_cases
    from .progress import Silent

    _check_tie_break(tie_break)
    clips_dir, out_dir = Path(clips_dir), Path(out_dir)
    labels = load_labels(Path(labels_path) if labels_path else clips_dir / "labels.json")
    base = preset(preset_name, **dict(overrides or {}))
    if not base.approach_gate:
        raise ValueError(f"preset {preset_name!r} has no approach gate to hold out")
    check_clips(clips_dir, labels)
    cases = suite_cases(cases)
    progress = progress or Silent()
    progress.start(len(labels) + len(cases), "eval --held-out")
    # the clips and the cases in one queue, each traced where a worker is free
    tasks = ([("clip", str(clips_dir / lab["file"]), lab.get("topic"), base) for lab in labels]
             + [("case", name, None, base) for name in cases])
    names = [lab["file"] for lab in labels] + list(cases)
    found: dict[int, ClipTrace] = {}
    for index, trace in run_tasks(trace_item, tasks, jobs):
        found[index] = trace
        progress.advance(1, names[index])
        progress.note(names[index])
    traces = [found[k] for k in range(len(labels))]
    suite_traces = [found[len(labels) + k] for k in range(len(cases))]
    progress.finish()
    for trace in (*traces, *suite_traces):
        check_replay(trace, base)
    warnings = _label_warnings(labels, traces)
    suite_labels = [make_case(name).label(name) for name in cases]
    # every grid point replayed on the suite, then on the clips
    points = len(grid(base))
    progress.start(2 * points, "eval --held-out: replaying the grid")
    suite = suite_summaries(suite_traces, suite_labels, base, jobs=jobs, progress=progress)
    progress.note(f"{points} points on the suite")
    held = DetectorSpec("asnn", None if preset_name == "default" else preset_name,
                        tuple(dict(overrides or {}).items()))
    results = {"clips_dir": str(clips_dir), "preset": preset_name,
               "overrides": dict(overrides or {}), "parameters": held.parameters,
               "suite_cases": len(cases),
               "warnings": warnings,
               **leave_one_out(traces, labels, base, suite_admissible(suite),
                               tie_break=tie_break, suite=suite, jobs=jobs,
                               progress=progress)}
    progress.note(f"{points} points on the clips")
    progress.finish()
    held_out_report(results, out_dir)
    return results
