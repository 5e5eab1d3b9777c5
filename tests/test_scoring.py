"""Scoring rules of SPEC.md section 5 on hand-made results."""

from __future__ import annotations

import json
import math

import pytest

from asnn.evaluation import scoring, stats

# fps 20: the 0.5 s tolerance is 10 frames, so the hit window of onset 20, contact 40 is [10, 42]
COLLISION = {"file": "c.mp4", "fps": 20.0, "frames": 60, "collision": True, "onset_frame": 20,
             "contact_frame": 40, "center": [30.0, 40.0]}
QUIET = {"file": "nc.mp4", "fps": 20.0, "frames": 60, "collision": False, "onset_frame": None,
         "contact_frame": None, "center": None}


def records(warnings=(), frames=60, targets=None):
    """Per-frame records with warnings at the given frames; ``targets``: {frame: [(x, y)]} or
    {frame: [(x, y, fields)]}, fields a dict of further target fields (``ttc``, ``id``)."""
    targets = targets or {}
    return [{"frame": i, "collision": i in warnings,
             "targets": [{"x": t[0], "y": t[1], **(t[2] if len(t) > 2 else {})}
                         for t in targets.get(i, [])]} for i in range(frames)]


@pytest.mark.parametrize("warnings, outcome", [
    ((), "miss"),
    ((0, 4), "miss"),            # inside the warm-up only
    ((9,), "early"),
    ((10,), "hit"),              # onset - 0.5 s
    ((20, 21), "hit"),
    ((42,), "hit"),              # contact + 2
    ((43,), "late"),
    ((3, 43), "late"),           # the warm-up warning is ignored
    ((9, 30), "early"),          # only the first warning counts
])
def test_collision_outcomes(warnings, outcome):
    score = scoring.score_clip(records(warnings), COLLISION)
    assert score.outcome == outcome
    assert score.false_alarm == (outcome == "early")
    assert score.window == (10, 42)


def test_lead_time_in_frames_and_seconds():
    early = scoring.score_clip(records((9, 10, 11)), COLLISION)
    assert (early.first_warning, early.warning_frames) == (9, 3)
    assert early.lead_frames == 31 and early.lead_s == pytest.approx(1.55)
    late = scoring.score_clip(records((45,)), COLLISION)
    assert late.lead_frames == -5 and late.lead_s == pytest.approx(-0.25)
    miss = scoring.score_clip(records(()), COLLISION)
    assert miss.lead_frames is None and miss.first_warning is None


def test_tolerance_and_warmup_are_parameters():
    assert scoring.score_clip(records((15,)), COLLISION).outcome == "hit"
    assert scoring.score_clip(records((15,)), COLLISION, early_tolerance_s=0).outcome == "early"
    assert scoring.score_clip(records((19,)), COLLISION, early_tolerance_s=0).outcome == "early"
    assert scoring.score_clip(records((20,)), COLLISION, early_tolerance_s=0).outcome == "hit"
    assert scoring.score_clip(records((8, 30)), COLLISION, warmup=9).outcome == "hit"
    # a label built in code without fps or collision (the label format requires both): the
    # tolerance was 0, the lead and the minutes unknown; a clip without collision scored as none
    for broken in ({**COLLISION, "fps": None}, {k: v for k, v in COLLISION.items() if k != "fps"},
                   {k: v for k, v in COLLISION.items() if k != "collision"}):
        with pytest.raises(ValueError, match="a label needs"):
            scoring.score_clip(records((15,)), broken)
    # "up to 0.5 s before onset": whole frames within it, at 15 fps 7 (8 would be 0.53 s)
    for fps, earliest in ((15.0, 13), (29.97, 6), (30.0, 5), (20.0, 10)):
        label = {**COLLISION, "fps": fps}
        assert scoring.score_clip(records((earliest,)), label, warmup=0).outcome == "hit", fps
        assert scoring.score_clip(records((earliest - 1,)), label, warmup=0).outcome == "early"


def test_warning_frames_inside_the_hit_window_are_counted():
    score = scoring.score_clip(records((3, 9, 10, 11, 42, 43, 50)), COLLISION)
    assert (score.warning_frames, score.window_warning_frames) == (6, 3)  # 10, 11, 42
    assert scoring.score_clip(records((5, 6, 50)), QUIET).window_warning_frames == 0
    summary = scoring.summarize([score, scoring.score_clip(records((5, 6, 50)), QUIET)])
    assert (summary["warning_frames"], summary["window_warning_frames"]) == (9, 3)


def test_noncollision_clip():
    assert scoring.score_clip(records((1, 4)), QUIET).outcome == "quiet"
    score = scoring.score_clip(records((5, 6, 50)), QUIET)
    assert (score.outcome, score.false_alarm, score.first_warning, score.warning_frames) == \
        ("false", True, 5, 3)
    assert score.lead_frames is None


def test_localisation_error_uses_the_nearest_target_at_the_first_warning():
    targets = {25: [(100.0, 100.0), (33.0, 44.0)], 26: [(30.0, 40.0)]}
    score = scoring.score_clip(records((25, 26), targets=targets), COLLISION)
    assert score.localisation_px == pytest.approx(5.0)
    no_targets = scoring.score_clip(records((24, 25), targets=targets), COLLISION)
    assert no_targets.localisation_px is None


def test_unordered_records_and_missing_onset():
    shuffled = list(reversed(records((30, 12))))
    assert scoring.score_clip(shuffled, COLLISION).first_warning == 12
    with pytest.raises(ValueError):
        scoring.score_clip(records(), {**COLLISION, "onset_frame": None})


def test_summary_counts_rates_and_lead():
    scores = [
        scoring.score_clip(records((20,)), {**COLLISION, "file": "a"}),   # hit, lead 20 fr
        scoring.score_clip(records((40,)), {**COLLISION, "file": "b"}),   # hit, lead 0
        scoring.score_clip(records((6,)), {**COLLISION, "file": "c"}),    # early
        scoring.score_clip(records(()), {**COLLISION, "file": "d"}),      # miss
        scoring.score_clip(records((7,)), {**QUIET, "file": "e"}),        # false alarm
        scoring.score_clip(records(()), {**QUIET, "file": "f"}),          # quiet
        scoring.missing_clip({**COLLISION, "file": "g"}),
    ]
    s = scoring.summarize(scores)
    assert (s["clips"], s["scored"], s["missing"]) == (7, 6, 1)
    assert (s["collision_clips"], s["noncollision_clips"]) == (4, 2)
    assert (s["hit"], s["early"], s["late"], s["miss"], s["false"], s["quiet"]) == (2, 1, 0, 1, 1, 1)
    assert s["false_alarms"] == 2
    assert s["hit_rate"] == pytest.approx(0.5)
    assert s["false_alarm_rate"] == pytest.approx(2 / 6)
    assert s["specificity"] == pytest.approx(0.5)
    assert s["mean_lead_frames"] == pytest.approx(10.0)
    assert s["mean_lead_s"] == pytest.approx(0.5)
    assert s["median_localisation_px"] is None
    # non-collision video: 2 clips of 55 scored frames at 20 fps, one warning frame in all
    assert s["noncollision_minutes"] == pytest.approx(2 * 55 / 20 / 60)
    assert s["warning_frames_per_minute"] == pytest.approx(1 / (2 * 55 / 20 / 60))
    empty = scoring.summarize([])
    assert empty["hit_rate"] is None and empty["false_alarm_rate"] is None
    assert empty["warning_frames_per_minute"] is None


def test_score_directory_with_hand_made_files_and_a_missing_clip(tmp_path):
    labels = [COLLISION, QUIET, {**COLLISION, "file": "absent.mp4"}]
    (tmp_path / "c.jsonl").write_text(
        "\n".join(json.dumps(r) for r in records((12,), frames=50)) + "\n")
    (tmp_path / "nc.json").write_text(json.dumps(records((30,), frames=50)))  # a JSON list
    scores = scoring.score_directory(tmp_path, labels, early_tolerance_s=0.0)
    assert [s.outcome for s in scores] == ["early", "false", "missing"]
    summary = scoring.summarize(scores)
    assert summary["missing"] == 1 and summary["collision_clips"] == 1
    assert summary["false_alarms"] == 2


def test_load_records_rejects_records_without_frames(tmp_path):
    path = tmp_path / "bad.jsonl"
    path.write_text('{"collision": true}\n')
    with pytest.raises(ValueError):
        scoring.load_records(path)


def test_load_records_names_the_line_that_is_not_json_and_reads_a_byte_order_mark(tmp_path):
    path = tmp_path / "edited.jsonl"
    path.write_text('{"frame": 1}\n\n{"frame": 2,}\n')
    with pytest.raises(ValueError, match=r"edited.jsonl: not JSON at line 3, column 13"):
        scoring.load_records(path)
    path.write_text('\n[{"frame": 1},\n {"frame": 2},]\n')
    with pytest.raises(ValueError, match="not JSON at line 3, column 15"):
        scoring.load_records(path)
    path.write_bytes('\ufeff{"frame": 1, "collision": true}\n'.encode())  # Notepad's UTF-8
    assert scoring.load_records(path) == [{"frame": 1, "collision": True}]


def test_localisation_follows_the_labelled_track_where_there_is_one():
    track = [[float(i), 2.0 * i] for i in range(60)]
    track[26] = None  # no target in this frame
    label = {**COLLISION, "track": track}
    targets = {25: [(28.0, 50.0)], 26: [(30.0, 40.0)]}
    score = scoring.score_clip(records((25,), targets=targets), label)
    assert score.localisation_px == pytest.approx(math.hypot(3.0, 0.0))  # track at 25: (25, 50)
    assert scoring.score_clip(records((26,), targets=targets), label).localisation_px is None
    # without a track, the fixed centre
    assert scoring.score_clip(records((26,), targets=targets), COLLISION).localisation_px == 0.0


def test_warnings_after_the_approach_are_counted_apart():
    score = scoring.score_clip(records((3, 30, 41, 42, 43, 50)), COLLISION)
    assert (score.warning_frames, score.window_warning_frames, score.after_warning_frames) == \
        (5, 3, 2)                                   # 43 and 50 come after contact + 2
    quiet_after = scoring.score_clip(records((30, 42)), COLLISION)
    assert quiet_after.after_warning_frames == 0
    assert scoring.score_clip(records((50,)), QUIET).after_warning_frames == 0
    summary = scoring.summarize([score, quiet_after])
    assert (summary["after_warning_frames"], summary["after_warning_clips"]) == (2, 1)


def test_summary_gives_the_median_lead_of_the_hits():
    leads = [(20,), (30,), (39,)]  # leads 20, 10, 1 frames
    scores = [scoring.score_clip(records(w), COLLISION) for w in leads]
    scores.append(scoring.score_clip(records((45,)), COLLISION))  # late: not a hit
    s = scoring.summarize(scores)
    assert s["median_lead_frames"] == 10 and s["median_lead_s"] == pytest.approx(0.5)
    assert s["mean_lead_frames"] == pytest.approx(31 / 3)


def test_time_to_contact_and_ids_of_the_warned_targets():
    # the label's time to contact falls 0.1 s per frame to 0 at contact (frame 40)
    label = {**COLLISION, "ttc": [(40 - i) / 10 if i < 40 else None for i in range(60)]}
    targets = {
        # frame 30 (true 1.0 s): the nearer target counts, the far one (another object) not
        30: [(30.0, 40.0, {"ttc": 1.2, "id": 7}), (200.0, 40.0, {"ttc": 9.0, "id": 8})],
        32: [(31.0, 41.0, {"ttc": 0.8, "id": 7})],      # true 0.8 s: exact
        34: [(31.0, 41.0, {"ttc": 0.3, "id": 9})],      # true 0.6 s: half, another id
        36: [(31.0, 41.0, {"id": 9})],                  # no ttc: counts for the ids only
        41: [(31.0, 41.0, {"ttc": 5.0, "id": 10})],     # after contact: not counted
    }
    score = scoring.score_clip(records((5, 30, 32, 34, 36, 41), targets=targets), label)
    assert score.outcome == "early"  # frame 5; the frames before the hit window do not count
    # errors 0.2, 0, 0.5 -> median 0.2; ratios 1.2, 1, 0.5 -> median 1
    assert score.ttc_error == pytest.approx(0.2)
    assert score.ttc_ratio == pytest.approx(1.0)
    assert score.target_ids == 2
    # a label without per-frame ttc: the time left to contact (1 s at frame 20 at 20 fps)
    plain = scoring.score_clip(records((20,), targets={20: [(30.0, 40.0, {"ttc": 1.5})]}),
                               COLLISION)
    assert (plain.ttc_error, plain.ttc_ratio, plain.target_ids) == \
        (pytest.approx(0.5), pytest.approx(1.5), None)
    # where the label says the object is not closing (ttc null), nothing is measured
    receding = {**COLLISION, "ttc": [None] * 60}
    assert scoring.score_clip(records((20,), targets={20: [(30.0, 40.0, {"ttc": 1.5})]}),
                              receding).ttc_error is None
    # targets without the fields (the published variant's) give None
    bare = scoring.score_clip(records((20, 21), targets={20: [(30.0, 40.0)]}), label)
    assert (bare.ttc_error, bare.ttc_ratio, bare.target_ids) == (None, None, None)


def test_summary_of_the_warned_targets_is_over_hits():
    label = {**COLLISION, "ttc": [(40 - i) / 10 if i < 40 else None for i in range(60)]}
    one = {30: [(30.0, 40.0, {"ttc": 1.1, "id": 1})], 31: [(30.0, 40.0, {"ttc": 0.9, "id": 1})]}
    two = {30: [(30.0, 40.0, {"ttc": 2.0, "id": 1})], 31: [(30.0, 40.0, {"ttc": 1.8, "id": 2})]}
    scores = [scoring.score_clip(records((30, 31), targets=one), {**label, "file": "a"}),
              scoring.score_clip(records((30, 31), targets=two), {**label, "file": "b"}),
              scoring.score_clip(records((5, 30), targets=two), {**label, "file": "c"})]  # early
    s = scoring.summarize(scores)
    assert (s["one_id_hits"], s["id_hits"]) == (1, 2)
    # hit a: ratios 1.1, 1 (errors 0.1, 0); hit b: ratios 2, 2 (errors 1, 1); the early
    # warning c is left out
    assert s["median_ttc_error"] == pytest.approx((0.05 + 1.0) / 2)
    assert s["median_ttc_ratio"] == pytest.approx((1.05 + 2.0) / 2)


def test_the_wilson_interval_of_a_rate():
    low, high = stats.wilson_interval(5, 9)
    assert low == pytest.approx(0.267, abs=1e-3) and high == pytest.approx(0.812, abs=1e-3)
    # at none or all of the trials the interval still has a width, within [0, 1]
    assert stats.wilson_interval(0, 12) == [0.0, pytest.approx(0.243, abs=1e-3)]
    assert stats.wilson_interval(12, 12) == [pytest.approx(0.757, abs=1e-3), 1.0]
    assert stats.wilson_interval(0, 0) is None
    with pytest.raises(ValueError, match="0..trials"):
        stats.wilson_interval(5, 3)
    # and it narrows as the sample grows
    assert stats.wilson_interval(50, 90)[1] - stats.wilson_interval(50, 90)[0] < high - low


def test_mcnemar_s_exact_test():
    assert stats.mcnemar_exact(0, 6) == pytest.approx(2 / 64)
    assert stats.mcnemar_exact(6, 0) == stats.mcnemar_exact(0, 6)
    assert stats.mcnemar_exact(1, 10) == pytest.approx(2 * 12 / 2048)
    assert stats.mcnemar_exact(3, 2) == 1.0 and stats.mcnemar_exact(0, 0) == 1.0
    with pytest.raises(ValueError, match="cannot be negative"):
        stats.mcnemar_exact(-1, 5)  # not a p-value of 0
    with pytest.raises(ValueError, match="cannot be negative"):
        stats.mcnemar_exact(5, -1)  # either count


def test_the_wilson_interval_stays_within_0_and_1_at_every_count():
    # the formula's ends at none or all of the trials are 0 and 1 only up to rounding
    # (-2.8e-17 at 0 of 5, 1.0000000000000002 at 5 of 5): the interval is clipped to them
    for trials in range(1, 60):
        for successes in range(trials + 1):
            low, high = stats.wilson_interval(successes, trials)
            assert 0.0 <= low < high <= 1.0, (successes, trials)
        assert stats.wilson_interval(0, trials)[0] == 0.0
        assert stats.wilson_interval(trials, trials)[1] == 1.0  # exactly


def test_a_label_built_in_code_with_its_onset_after_its_contact_is_refused():
    label = {"file": "a.mp4", "fps": 20.0, "collision": True, "onset_frame": 20,
             "contact_frame": 12}
    with pytest.raises(ValueError, match="onset_frame 20 is after contact_frame 12"):
        scoring.score_clip([{"frame": 15, "collision": True}], label)


def test_two_detectors_are_compared_clip_by_clip():
    def clip(name, collision, outcome):
        return scoring.ClipScore(clip=name, collision=collision, outcome=outcome,
                                 false_alarm=outcome in ("early", "false"),
                                 lead_frames=10.0 if outcome == "hit" else None)

    first = [clip("a", True, "hit"), clip("b", True, "hit"), clip("c", True, "miss"),
             clip("d", False, "quiet"), clip("e", False, "quiet"), clip("f", True, "missing")]
    second = [clip("a", True, "hit"), clip("b", True, "early"), clip("c", True, "hit"),
              clip("d", False, "false"), clip("e", False, "false"), clip("f", True, "hit")]
    paired = scoring.paired_comparison(first, second)
    # a clip one of them did not score does not count
    assert paired["hits"] == {"only_first": 1, "only_second": 1, "p": 1.0}
    assert paired["false_alarms"] == {"only_first": 0, "only_second": 3, "p": 0.25}
    with pytest.raises(ValueError):
        scoring.paired_comparison(first, second[::-1])
    summary = scoring.summarize(first)
    assert summary["hit_rate_ci"] == stats.wilson_interval(2, 3)
    assert summary["false_alarm_rate_ci"] == stats.wilson_interval(0, 5)
