"""Held-out figures of the approach gate (asnn/evaluation/heldout.py, its replay
gate_replay.py), detector specs with parameter overrides, and the robust preset's two forms."""

import json
from pathlib import Path

import numpy as np
import pytest

from asnn import ASNN, preset
from asnn.evaluation import gate_replay, heldout, scoring
from asnn.evaluation.runs import ABLATIONS, at_rate, parse_detector, parse_detectors
from asnn.io.video import write_video
from cached_cases import make_case
from cli.main import main

CASES = ("loom-dark-c0.6-d6-center", "nearmiss-disk-dark-right", "course-disk-dark-right",
         "translate-disk-dark-c0.6-h2px", "drive-day-cut-in-dark")


@pytest.fixture(scope="module")
def traced():
    base = preset("robust")
    scenes = [make_case(name) for name in CASES]
    traces = [gate_replay.trace_clip(at_rate(s.frames, s.fps), base, s.name) for s in scenes]
    return base, scenes, traces


_REPLAYED: dict = {}


@pytest.fixture
def replayed_once(monkeypatch):
    """The whole grid replayed once per traces, labels and scoring, for the tests that choose
    thresholds on the same clips several times (each choice replays every grid point: some
    ten seconds); the figures are those of the replay itself."""
    replay_grid = heldout._grid_scores

    def once(traces, labels, points, warmup, early_tolerance_s, jobs, progress=None):
        key = (tuple(map(id, traces)), json.dumps(labels, sort_keys=True), len(points),
               points[0].model_dump_json(), warmup, early_tolerance_s)
        if key not in _REPLAYED:
            _REPLAYED[key] = replay_grid(traces, labels, points, warmup, early_tolerance_s,
                                         jobs, progress)
        return _REPLAYED[key]

    monkeypatch.setattr(heldout, "_grid_scores", once)


def test_the_replay_reproduces_the_models_warnings_frame_by_frame(traced):
    base, scenes, traces = traced
    for scene, trace in zip(scenes, traces):
        model = ASNN(base)
        own = [model.step(f, t).collision for t, f in at_rate(scene.frames, scene.fps)]
        assert [r["collision"] for r in gate_replay.replay(trace, base)] == own
        assert trace.warnings == own  # what check_replay holds the replay to


def test_a_replay_that_misses_a_stage_of_the_gate_is_refused(traced):
    # a stage added to the gate but not to the replay: the model quiet where the replay warns;
    # the held-out figures would leave the stage out without a word
    import dataclasses

    base, _, traces = traced
    trace = traces[0]  # the loom: it warns
    gate_replay.check_replay(trace, base)
    assert any(trace.warnings)
    silenced = dataclasses.replace(trace, warnings=[False] * len(trace.warnings))
    with pytest.raises(ValueError, match="does not reproduce the model's warnings on "
                                         "'loom-dark-c0.6-d6-center'"):
        gate_replay.check_replay(silenced, base)


def test_the_replay_follows_other_thresholds(traced):
    base, scenes, traces = traced
    # a near miss the offset test keeps quiet warns once the test is loosened
    miss = traces[CASES.index("nearmiss-disk-dark-right")]
    assert not any(r["collision"] for r in gate_replay.replay(miss, base))
    loose = base.model_copy(update={"offset_max": 1000.0})
    assert any(r["collision"] for r in gate_replay.replay(miss, loose))
    # a car cutting in ahead, quiet with the scene-relative test, warns without it
    cut_in = traces[CASES.index("drive-day-cut-in-dark")]
    assert not any(r["collision"] for r in gate_replay.replay(cut_in, base))
    plain = base.model_copy(update={"scene_relative": False})
    assert any(r["collision"] for r in gate_replay.replay(cut_in, plain))
    # a later time to contact threshold warns later
    loom = traces[0]
    first = lambda params: next(r["frame"] for r in gate_replay.replay(loom, params) if r["collision"])
    assert first(base.model_copy(update={"tau_max": 0.5})) > first(base)


def test_own_motion_ratios_replayed_in_one_pass_are_each_ones_replay(traced):
    # the ratio weighs what counts, not which counts: the grid's ratios share one pass, whose
    # warnings are those of each ratio replayed alone
    base, scenes, traces = traced
    ratios = (0.75, 1.0, 2.0)
    for trace in traces:
        assert gate_replay.replays(trace, base, ratios) == [
            gate_replay.replay(trace, base.model_copy(update={"own_motion_ratio": r}))
            for r in ratios]
    # ... and the ratio matters: the looming disk on a still background closes by its own
    # motion only as far as a ratio of 1 (its expansion against the scene is its own)
    first = [next(r["frame"] for r in run if r["collision"])
             for run in gate_replay.replays(traces[0], base, ratios)]
    assert first[0] == first[1] < first[2]


def test_the_replay_reproduces_the_partial_overlap_regime():
    # a car 1.2 m to the side of ours, stopped ahead: a partial overlap, caught only with the
    # regime; a car cutting in at night, whose box holds the roadside too: quiet with the fit
    # test, warned about without it; a car catching up with a rear camera off its axis, whose
    # box holds the receding road: caught with its fit against the receding scene; a walker
    # whose sway splits its outline into fragments: caught with region persistence; a car
    # cutting in, in fresh scenery, whose box holds no motion coming at us: quiet with the
    # motion layers
    base = preset("robust")
    for name, variant, warned, without in (
            ("drive-day-stopped-car-offset", 0, True, {"partial_overlap": False}),
            ("drive-night-cut-in", 0, False, {"overlap_fit_min": -1.0}),
            ("rear-day-catchup-offset", 0, True, {"receding_scene": False}),
            ("walk-light-c0.4-gait", 0, True, {"region_persistence": False}),
            ("drive-day-cut-in-dark", 2, False, {"motion_layers": False})):
        scene = make_case(name, variant)
        trace = gate_replay.trace_clip(at_rate(scene.frames, scene.fps), base, name)
        model = ASNN(base)
        own = [model.step(f, t).collision for t, f in at_rate(scene.frames, scene.fps)]
        assert [r["collision"] for r in gate_replay.replay(trace, base)] == own
        assert any(own) == warned
        assert any(r["collision"] for r in gate_replay.replay(trace, base.model_copy(
            update=without))) != warned


def test_the_replay_reproduces_the_frame_s_edge_rule():
    # the night crossing car of fresh-scenery variant 8: its front lamp, cut by the frame's left
    # edge, passes the partial-overlap regime on its fit against the receding night scene
    # unless that fit counts 0 at the edge (receding_edge_rule); the trace records the fit as
    # the rule leaves it, so the replay warns as the model does with the rule and without it
    scene = make_case("drive-night-cross-tbone", 8)
    first = []
    for rule in (True, False):
        params = preset("robust", receding_edge_rule=rule)
        trace = gate_replay.trace_clip(at_rate(scene.frames, scene.fps), params, "tbone")
        replayed = [r["collision"] for r in gate_replay.replay(trace, params)]
        assert replayed == trace.warnings
        first.append(replayed.index(True))
    assert first[0] > first[1]


def test_the_replay_asks_a_slow_stream_for_as_few_frames_as_the_model():
    # the dark walker at 10 fps: caught with two frames of approach, missed with three
    base = preset("robust")
    scene = make_case("walk-dark-c0.4-gait")
    frames = list(at_rate(scene.frames, scene.fps))[::2]
    trace = gate_replay.trace_clip(frames, base, scene.name)
    model = ASNN(base)
    own = [model.step(f, t).collision for t, f in frames]
    assert [r["collision"] for r in gate_replay.replay(trace, base)] == own and any(own)
    fixed = base.model_copy(update={"approach_seconds": None})
    assert not any(r["collision"] for r in gate_replay.replay(trace, fixed))


@pytest.mark.usefixtures("replayed_once")
def test_leave_one_out_chooses_without_the_clip_it_scores(traced):
    base, scenes, traces = traced
    labels = [s.label(f"{s.name}.mp4") for s in scenes]
    result = heldout.leave_one_out(traces, labels, base, early_tolerance_s=0.0)
    assert len(result["held_out"]["clips"]) == len(CASES)
    assert all(set(c["chosen"]) == set(heldout.GATE_GRID) for c in result["held_out"]["clips"])
    assert result["in_sample"]["summary"]["hit"] == 2  # the looming disk and the course
    # only admissible points are chosen
    grid = heldout.grid(base)
    admissible = [g.offset_max <= 1.0 and g.tau_max == 1.5 for g in grid]
    picked = heldout.leave_one_out(traces, labels, base, admissible, early_tolerance_s=0.0)
    assert all(c["chosen"]["offset_max"] <= 1.0 and c["chosen"]["tau_max"] == 1.5
               for c in picked["held_out"]["clips"])
    with pytest.raises(ValueError):
        heldout.leave_one_out(traces, labels, base, [False] * len(grid))


def test_the_grid_replayed_in_processes_scores_as_in_one(traced):
    # the grid's points go out in runs to worker processes: every point's figures come back,
    # in grid order, and the progress counts each point once
    class Count:
        done = 0

        def advance(self, n=1, note=""):
            self.done += n

    base, scenes, traces = traced
    labels = [s.label(s.name) for s in scenes]
    pick = [CASES.index("nearmiss-disk-dark-right"), CASES.index("drive-day-cut-in-dark")]
    traces, labels = [traces[k] for k in pick], [labels[k] for k in pick]
    alone, spread = Count(), Count()
    one = heldout.suite_summaries(traces, labels, base, progress=alone)
    two = heldout.suite_summaries(traces, labels, base, jobs=2, progress=spread)
    assert one == two and alone.done == spread.done == len(heldout.grid(base))
    # the points tell the two clips apart: a wrong order would show
    assert len({(s["hit"], s["false_alarms"]) for s in one}) > 1


def test_the_selection_prefers_hits_minus_false_alarms_then_fewer_false_alarms():
    summary = lambda hit, fa, inside, frames: {"hit": hit, "false_alarms": fa,
                                               "window_warning_frames": inside,
                                               "warning_frames": frames}
    assert heldout.selection_key(summary(5, 1, 10, 12)) > heldout.selection_key(
        summary(5, 2, 10, 12))
    assert heldout.selection_key(summary(4, 0, 10, 12)) > heldout.selection_key(
        summary(5, 1, 10, 12))
    assert heldout.selection_key(summary(4, 0, 10, 12)) > heldout.selection_key(
        summary(4, 0, 10, 30))
    # by grid order instead, warning frames do not count: the two tie, and the first wins
    assert heldout.selection_key(summary(4, 0, 10, 12), "grid") == heldout.selection_key(
        summary(4, 0, 10, 30), "grid")
    with pytest.raises(ValueError, match="tie-break"):
        heldout.selection_key(summary(4, 0, 10, 12), "luck")
    # by the generated suite: the point with more suite hits minus false alarms, whatever the
    # clips' warning frames
    assert heldout.selection_key(summary(4, 0, 10, 30), "suite", summary(80, 1, 0, 0)) > \
        heldout.selection_key(summary(4, 0, 10, 12), "suite", summary(79, 1, 0, 0))
    assert heldout.selection_key(summary(4, 0, 10, 12), "suite", summary(79, 0, 0, 0)) > \
        heldout.selection_key(summary(4, 0, 10, 12), "suite", summary(80, 1, 0, 0))
    with pytest.raises(ValueError, match="suite summary"):
        heldout.selection_key(summary(4, 0, 10, 12), "suite")


@pytest.mark.usefixtures("replayed_once")
def test_the_tie_break_decides_between_thresholds_that_score_alike(traced):
    base, scenes, traces = traced
    labels = [scene.label(f"{scene.name}.mp4") for scene in scenes]
    frames = heldout.leave_one_out(traces, labels, base, early_tolerance_s=0.0)
    ordered = heldout.leave_one_out(traces, labels, base, early_tolerance_s=0.0,
                                    tie_break="grid")
    assert (frames["tie_break"], ordered["tie_break"]) == ("warning-frames", "grid")
    # on these clips many thresholds score alike: by grid order the smallest are taken, by
    # warning frames those that warn longest inside the windows
    assert ordered["chosen_all"]["tau_max"] == 1.0 < frames["chosen_all"]["tau_max"]
    with pytest.raises(ValueError, match="tie-break"):
        heldout.leave_one_out(traces, labels, base, tie_break="luck")


@pytest.mark.usefixtures("replayed_once")
def test_the_suite_breaks_ties_by_the_generated_scenes(traced):
    base, scenes, traces = traced
    labels = [scene.label(f"{scene.name}.mp4") for scene in scenes]
    # a suite of one case the clips do not hold: a partial overlap, which only the regime
    # catches; among the points that tie on the clips, the choice takes one that hits it
    case = make_case("rear-day-catchup-offset")
    suite = heldout.suite_summaries([gate_replay.trace_clip(at_rate(case.frames, case.fps), base)],
                                    [case.label(case.name)], base)
    by_suite = heldout.leave_one_out(traces, labels, base, early_tolerance_s=0.0,
                                     tie_break="suite", suite=suite)
    by_grid = heldout.leave_one_out(traces, labels, base, early_tolerance_s=0.0,
                                    tie_break="grid")
    assert by_grid["chosen_all"]["partial_overlap"] is False  # the first tied point
    chosen = by_suite["chosen_all"]
    assert chosen["partial_overlap"] is True
    k = next(k for k, g in enumerate(heldout.grid(base))
             if all(getattr(g, n) == v for n, v in chosen.items()))
    assert suite[k]["hit"] == 1
    # ... and it still ties with the grid's choice on the clips themselves
    in_sample = [heldout.scoring.summarize(
        scoring.score_clip(gate_replay.replay(tr, g), lab, early_tolerance_s=0.0)
        for tr, lab in zip(traces, labels))
        for g in (base.model_copy(update=chosen), base.model_copy(update=by_grid["chosen_all"]))]
    assert heldout.selection_key(in_sample[0], "grid") == heldout.selection_key(in_sample[1],
                                                                                "grid")
    with pytest.raises(ValueError, match="suite summary"):
        heldout.leave_one_out(traces, labels, base, tie_break="suite")


@pytest.mark.usefixtures("replayed_once")
def test_the_figures_over_ties_do_not_depend_on_the_tie_break(traced):
    base, scenes, traces = traced
    labels = [scene.label(f"{scene.name}.mp4") for scene in scenes]
    suite = heldout.suite_summaries(traces, labels, base)
    runs = [heldout.leave_one_out(traces, labels, base, early_tolerance_s=0.0, tie_break=t,
                                  suite=suite)
            for t in heldout.TIE_BREAKS]
    assert all(run["over_ties"] == runs[0]["over_ties"] for run in runs)
    ties = runs[0]["over_ties"]
    hits, alarms = ties["summary"]["hits"], ties["summary"]["false_alarms"]
    assert hits["fewest"] <= hits["expected"] <= hits["most"] <= len(
        [label for label in labels if label["collision"]])
    for run in runs:
        # whichever tie-break: its held-out figures lie within the range over the ties
        summary = run["held_out"]["summary"]
        assert hits["fewest"] <= summary["hit"] <= hits["most"]
        assert alarms["fewest"] <= summary["false_alarms"] <= alarms["most"]
        for chosen, tied in zip(run["held_out"]["clips"], ties["clips"]):
            assert chosen["clip"] == tied["clip"] and tied["outcomes"].get(chosen["outcome"])
    # on these clips many thresholds score alike: the tie-breaks differ somewhere
    assert max(t["tied"] for t in ties["clips"]) > 1


def test_the_figures_over_ties_count_shares_and_ranges():
    def score(clip, collision, outcome):
        return scoring.ClipScore(clip=clip, collision=collision, outcome=outcome,
                                 false_alarm=outcome in ("early", "false"))

    ties = [heldout._over_ties([score("a", True, o) for o in ("hit", "hit", "miss", "early")]),
            heldout._over_ties([score("b", True, "hit")] * 3),
            heldout._over_ties([score("c", True, "miss")] * 2),
            heldout._over_ties([score("d", False, o) for o in ("quiet", "quiet", "quiet",
                                                               "false")])]
    assert [t["tied"] for t in ties] == [4, 3, 2, 4]
    assert ties[0]["outcomes"] == {"hit": 2, "miss": 1, "early": 1}
    summary = heldout._summarize_ties(ties)
    assert summary["hits"] == {"expected": 1.5, "fewest": 1, "most": 2}
    assert summary["false_alarms"] == {"expected": 0.5, "fewest": 0, "most": 2}
    assert (summary["collision_clips"], summary["noncollision_clips"]) == (3, 1)


def test_the_report_names_each_folds_thresholds(traced, tmp_path, monkeypatch):
    # a grid of four points, quick to score: the preset's thresholds but for tau_max, and
    # scene_tolerance 0, with which two frames of approach warn falsely on the car cutting in
    # and four do not: the fold without that car chooses two (they warn longer on the
    # others), the other folds four
    base, scenes, traces = traced
    monkeypatch.setattr(heldout, "GATE_GRID", {
        **{n: (getattr(base, n),) for n in heldout.GATE_GRID},
        "tau_max": (1.0, 1.5), "approach_frames": (2, 4), "scene_tolerance": (0.0,)})
    labels = [scene.label(f"{scene.name}.mp4") for scene in scenes]
    results = heldout.leave_one_out(traces, labels, base, early_tolerance_s=0.0)
    report = heldout.held_out_report(results, tmp_path).read_text()
    names = list(heldout.GATE_GRID)
    assert results["grid"] == {n: list(v) for n, v in heldout.GATE_GRID.items()}
    assert "| clip left out | preset | held out | " + " | ".join(names) + " |" in report
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in report.splitlines()
            if line.startswith("| ") and line.count("|") == len(names) + 4]
    fold_rows = rows[2:]  # after the header and its rule: one row per fold, in the clips' order
    assert [cells[0] for cells in fold_rows] == [lab["file"] for lab in labels]
    for cells, a, b in zip(fold_rows, results["in_sample"]["clips"],
                           results["held_out"]["clips"]):
        assert cells[0] == a["clip"] == b["clip"]
        for cell, score in ((cells[1], a), (cells[2], b)):
            first = score["first_warning"]
            assert cell == score["outcome"] + ("" if first is None else f" @{first}")
        assert cells[3:] == [str(b["chosen"][n]) for n in names]
    # the folds do not all choose alike here: the rows tell them apart by name
    assert [c["chosen"]["approach_frames"] for c in results["held_out"]["clips"]] == [
        2 if name == "drive-day-cut-in-dark" else 4 for name in CASES]
    assert "the thresholds by their `ASNNParams` names" in report
    # the preset's row, in the report as in the printed lines: its thresholds are in-sample on
    # the real clips that chose them only (on a user's own clips it read 'in-sample')
    assert "held out on others" in heldout.PRESET_ROW
    assert f"| {heldout.PRESET_ROW} | " in report
    # the lines the command prints: the same figures, the thresholds named
    lines = heldout.summary_lines(results)
    ins, held = results["in_sample"]["summary"], results["held_out"]["summary"]
    assert lines[0].startswith(f"{heldout.PRESET_ROW}: {ins['hit']}/"
                               f"{ins['collision_clips']} hits ({ins['early']} early, ")
    assert lines[1].startswith("held out (leave one clip out; ties by warning-frames): "
                               f"{held['hit']}/{held['collision_clips']} hits")
    ties = results["over_ties"]["summary"]
    assert lines[2].startswith(f"held out over every tie: {ties['hits']['expected']:.1f}/"
                               f"{ties['collision_clips']} hits expected")
    assert lines[-1] == "chosen on every clip: " + ", ".join(
        f"{n} = {results['chosen_all'][n]}" for n in names)
    # which preset is held out, in both (a researcher's preset read as the default's)
    name = results.get("preset", "default")
    named = f"`{name}`" + (" (`robust`)" if name == "default" else "")
    assert f"Preset {named}." in report and lines[-2].startswith(f"preset thresholds ({named}): ")


def test_asnn_eval_held_out_end_to_end(tmp_path, capsys):
    labels = []
    for name in ("loom-dark-c0.6-d6-center", "translate-disk-dark-c0.6-h2px"):
        scene = make_case(name)
        write_video(scene.frames, tmp_path / f"{name}.avi", scene.fps)
        labels.append(scene.label(f"{name}.avi"))
    (tmp_path / "labels.json").write_text(json.dumps(labels))
    out = tmp_path / "out"
    assert main(["eval", str(tmp_path), "--held-out", "--cases", "nearmiss-disk-dark-right",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr()
    err = printed.err  # off a terminal: a line per traced clip or case
    for name in (*(lab["file"] for lab in labels), "nearmiss-disk-dark-right"):
        assert f"eval --held-out: {name} (" in err
    # and the replay after them (--help said it "prints nothing", stale since it reports)
    assert "eval --held-out: replaying the grid" in err
    with pytest.raises(SystemExit):
        main(["eval", "--help"])
    said = " ".join(capsys.readouterr().out.split())
    assert "prints nothing" not in said and "as it replays the gate" in said
    results = json.loads((out / "held_out.json").read_text())
    # stdout: the figures (heldout.summary_lines), the thresholds named, then the report's path
    assert printed.out.splitlines() == [*heldout.summary_lines(results), f"{out}/held_out.md"]
    assert printed.out.startswith(f"{heldout.PRESET_ROW}: 1/1 hits (0 early, 0 late)")
    assert "chosen on every clip: tau_max = " in printed.out
    assert set(results["held_out"]["clips"][0]["chosen"]) == set(heldout.GATE_GRID)
    # the README says what each key of held_out.json holds
    readme = (Path(__file__).parents[1] / "README.md").read_text(encoding="utf-8")
    keys = {*results, *results["over_ties"]["clips"][0], *results["over_ties"]["summary"],
            *results["suite"], "chosen"}
    assert not [key for key in sorted(keys) if f"`{key}`" not in readme]
    assert results["in_sample"]["summary"]["hit"] == 1
    assert results["in_sample"]["summary"]["false_alarms"] == 0
    report = (out / "held_out.md").read_text()
    assert "held out (leave one clip out)" in report and "Whatever breaks the ties" in report
    assert len(results["over_ties"]["clips"]) == 2
    # the suite's figures (here one near miss, which the preset keeps quiet)
    assert results["suite"]["preset"] == {"hit": 0, "collision_clips": 0, "false_alarms": 0,
                                          "clips": 1}
    assert "On the generated suite (the preset's thresholds: 0/0 hits, 0 false alarms" in report
    with pytest.raises(SystemExit):  # one mode at a time
        main(["eval", str(tmp_path), "--synthetic", "--held-out"])
    # an addition switched off: its gate's limits chosen again
    changed = tmp_path / "changed"
    assert main(["eval", str(tmp_path), "--held-out", "--cases", "nearmiss-disk-dark-right",
                 "--detectors", "asnn:robust/region_persistence=false",
                 "--out", str(changed)]) == 0
    results = json.loads((changed / "held_out.json").read_text())
    assert (results["preset"], results["overrides"]) == ("robust", {"region_persistence": False})
    # every parameter held out, as a plain run's results.json keeps them (a review)
    assert results["parameters"]["preset"] == "robust"
    assert results["parameters"]["region_persistence"] is False
    assert "Preset `robust` with region_persistence = False." in (
        changed / "held_out.md").read_text()
    for detectors in ("lgmd1", "asnn,asnn:reference"):  # one ASNN detector only
        assert main(["eval", str(tmp_path), "--held-out", "--detectors", detectors,
                     "--out", str(tmp_path / "refused")]) == 2
    assert not (tmp_path / "refused").exists()


def test_detector_specs_override_parameters():
    spec = parse_detector("asnn:robust/contrast_gain=none/approach_frames=1")
    model = spec.make()
    assert model.params.contrast_gain is None and model.params.approach_frames == 1
    assert spec.name == "asnn:robust/contrast_gain=none/approach_frames=1"
    assert "/" not in spec.slug and ":" not in spec.slug
    assert [s.name for s in parse_detectors(list(ABLATIONS.values()))] == list(ABLATIONS.values())
    for bad in ("asnn:robust/nope=1", "asnn:robust/tau_max=-1", "asnn:robust/x", "lgmd1:robust"):
        with pytest.raises(ValueError):
            parse_detector(bad)
    # a check of the parameters as a whole (no one parameter to name) reads as clearly
    with pytest.raises(ValueError, match="n_fast must be smaller than n_slow"):
        parse_detector("asnn:robust/n_fast=9/n_slow=3")


@pytest.mark.parametrize("case", ["loom-dark-c0.6-d12-topleft", "drive-day-brake",
                                  "course-car-dark-left-nextlane"])
def test_the_robust_presets_two_forms_warn_alike(case):
    # float32 fused kernels against float64 stage by stage: thresholds may flip a pixel, the
    # warnings and targets agree
    scene = make_case(case)
    fast, slow = ASNN("robust"), ASNN("robust", optimised=False)
    for t, frame in at_rate(scene.frames, scene.fps):
        a, b = fast.step(frame, t), slow.step(frame, t)
        assert a.collision == b.collision
        assert a.u == pytest.approx(b.u, rel=0.05, abs=1.0)
        assert [t.id for t in a.targets] == [t.id for t in b.targets]
        for ta, tb in zip(a.targets, b.targets):
            assert np.hypot(ta.x - tb.x, ta.y - tb.y) < 1.0


def test_a_clip_s_frame_times_the_model_cannot_time_by_are_a_warning_of_the_held_out_run(
        tmp_path):
    """A trial: --held-out let the model's TimingWarning out in Python's form (a traceback where
    warnings are errors), and left it out of held_out.json, where a plain run names it."""
    import warnings

    from asnn.io.rosbag import write_bag
    from asnn.stimuli import make_scene

    scene = make_scene("looming", size=(96, 96))
    path = write_bag(scene.frames, tmp_path / "loom.mcap", fps=20000.0)  # 50 us apart
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        trace = gate_replay.trace_item("clip", str(path), None, preset("robust"))
    assert len(trace.timing) == 1 and "5 frames in a row" in trace.timing[0]
    said = heldout._label_warnings([scene.label("loom.mcap")], [trace])
    assert f"asnn loom.mcap: {trace.timing[0]}" in said
