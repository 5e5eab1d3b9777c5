"""Smoke test of ``asnn bench`` (output shape only; no timing assertions)."""

import dataclasses
import json
import types

import numpy as np
import pytest

from asnn.detectors import MODELS
from asnn.evaluation.bench import THREAD_VARIABLES
from cli.main import main
from netutil import wait_for


def test_bench_json_report_shape(capsys, monkeypatch):
    for name in THREAD_VARIABLES:  # the bench pins threads for the process: restore afterwards
        monkeypatch.delenv(name, raising=False)
    assert main(["bench", "--frames", "3", "--size", "64x64", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert "setNumThreads(1)" in report["threads"] and report["machine"]["cores"] >= 1
    rows = report["results"]
    assert {r["model"] for r in rows} == set(MODELS)  # every model, a new baseline too
    for r in rows:
        assert r["size"] == "64x64" and r["frames"] == 3
        assert 0 < r["median_ms"] <= r["p90_ms"]
    slow = [r for r in rows if r["form"] == "straightforward"]
    assert len(slow) == 1 and slow[0]["preset"] == report["default_preset"]
    assert slow[0]["speedup"] > 0
    assert all(r["state_mb"] > 0 for r in rows if r["model"] == "asnn")


def test_the_state_counts_the_temporal_summations_average_once():
    # in a dim, noisy view the running average is the model's previous frame itself
    from asnn import ASNN
    from asnn.evaluation.bench import _state_bytes

    rng = np.random.default_rng(0)
    model = ASNN()
    for k in range(20):  # 1 s at 20 fps of a still view at a tenth of the light, noisy
        model.step(np.clip(25 + rng.normal(0, 6, (120, 160)), 0, 255).astype(np.uint8), k / 20)
    assert model._summation.average is model.previous
    cascades = model.stages_on.nbytes + model.stages_off.nbytes
    assert _state_bytes(model) == cascades + model.previous.nbytes

def test_bench_times_a_case_of_the_suite_at_its_own_size(capsys, monkeypatch):
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert main(["bench", "--case", "drive-day-brake", "--model", "asnn", "--preset", "default",
                 "--no-straightforward", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["scene"] == "drive-day-brake"
    from cached_cases import make_case

    frames = make_case("drive-day-brake").frames
    size = f"{frames.shape[2]}x{frames.shape[1]}"
    rows = report["results"]
    assert {r["preset"] for r in rows} == {"robust", "reference32"}
    assert all(r["size"] == size and r["frames"] == len(frames) - report["warmup"] for r in rows)
    for bad in (["--case", "drive-day-brake", "--size", "64x64"],
                ["--case", "drive-day-brake", "--detect"], ["--case", "no-such-case"]):
        assert main(["bench", *bad]) == 2
        assert "asnn bench:" in capsys.readouterr().err


def test_service_report_format():
    from service.bench import format_report

    step = {"cameras": 2, "frames": 200, "responses": 199, "answered": 0.995,
            "latency_p50_ms": 3.0, "latency_p99_ms": 6.0, "added_p50_ms": 1.0,
            "added_p99_ms": 4.0, "start_added_p99_ms": 12.5, "keeps_up": True}
    report = {"size": "320x240", "fps": 25.0, "seconds": 4.0, "preset": "reference32",
              "worker": "separate process", "transport": "tcp/127.0.0.1",
              "model_ms": {"median_ms": 2.0, "p99_ms": 3.0}, "steps": [step],
              "max_cameras": 2, "added_p99_ms_at_max": 4.0}
    text = format_report(report)
    assert "| 2 | 200 | 99.5 % | 3.0 | 6.0 | 4.0 | 12.5 | yes |" in text
    assert "keeps up: 2 (steady-state p99 added latency 4.0 ms)" in text
    assert "first 1 s" in text


def test_service_summary_separates_the_start_from_the_steady_state():
    from service.bench import START_S, summarise

    fps, t0 = 25.0, 1000.0
    records = []
    for k in range(100):  # 4 s of one camera: slow answers in the first second only
        stamp = t0 + k / fps
        latency = 0.030 if stamp < t0 + START_S else 0.004
        records.append(("r", k, stamp + latency, stamp, 2.0 if k % 2 else None))
    out = summarise(records, sent=100, fps=fps, model_ms=1.0)
    assert out["answered"] == 1.0 and out["keeps_up"]
    # steady state: 4 ms end to end, minus 2 ms (reported) or 1 ms (the fallback)
    assert out["latency_p99_ms"] == pytest.approx(4.0)
    assert round(out["added_p50_ms"], 6) in (2.0, 3.0)
    assert out["added_p99_ms"] == pytest.approx(3.0)
    assert out["start_added_p99_ms"] == pytest.approx(29.0)


def test_service_summary_flags_a_growing_backlog_and_missing_answers():
    from service.bench import summarise

    fps, t0 = 25.0, 1000.0
    growing = [("r", k, t0 + k / fps + 0.002 + k * 0.004, t0 + k / fps, 1.0) for k in range(100)]
    assert not summarise(growing, sent=100, fps=fps, model_ms=1.0)["keeps_up"]
    steady = [("r", k, t0 + k / fps + 0.002, t0 + k / fps, 1.0) for k in range(90)]
    out = summarise(steady, sent=100, fps=fps, model_ms=1.0)
    assert out["answered"] == 0.9 and not out["keeps_up"]
    assert summarise([], sent=10, fps=fps, model_ms=1.0) == {
        "frames": 10, "responses": 0, "answered": 0.0, "keeps_up": False}


def test_service_summary_counts_a_worker_that_answered_no_robot():
    """A review: with two workers, one answering both cameras, the split read "2", not 2/0."""
    from service.bench import summarise

    fps, t0 = 25.0, 1000.0
    records = [(robot, k, t0 + k / fps + 0.002, t0 + k / fps, 1.0, "w1")
               for robot in ("a", "b") for k in range(50)]
    out = summarise(records, sent=100, fps=fps, model_ms=1.0, workers=["w1", "w2"])
    assert out["robots_per_worker"] == {"w1": 2, "w2": 0}


def test_camera_phases():
    from service.bench import camera_phases

    assert camera_phases(4, "spread").tolist() == [0.0, 0.25, 0.5, 0.75]
    a, b = camera_phases(16, "random", seed=3), camera_phases(16, "random", seed=3)
    assert (a == b).all() and ((a >= 0) & (a < 1)).all() and len(set(a)) == 16
    with pytest.raises(ValueError, match="spread"):
        camera_phases(2, "bunched")


def test_cameras_play_their_own_streams_from_their_own_point_of_the_loop(zenoh_net):
    import threading

    import numpy as np

    from service import keys
    from service.bench import publish_cameras
    from service.messages import decode_frame

    frames = np.stack([np.full((24, 32), v, np.uint8) for v in (10, 20, 30, 40)])
    got, lock = {}, threading.Lock()

    def on_frame(sample):
        frame = decode_frame(sample.payload.to_bytes())
        robot = str(sample.key_expr).split("/")[1]
        with lock:
            got.setdefault(robot, []).append((frame.seq, int(frame.image()[0, 0])))

    sub = zenoh_net.hub.declare_subscriber(keys.frames(), on_frame)
    try:
        sent = publish_cameras(zenoh_net.spoke(), ["c0", "c1"], frames, fps=50.0, seconds=0.3,
                               phases=np.array([0.0, 0.5]), prefix=keys.DEFAULT_PREFIX)
        wait_for(lambda: all(len(got.get(r, [])) == sent[r] for r in sent),
                 what="every published frame")
    finally:
        sub.undeclare()
    for robot, start in (("c0", 0), ("c1", 2)):  # camera i starts at frame i * 4 // 2
        seqs, values = zip(*sorted(got[robot]))
        assert sent[robot] >= 2 and list(seqs) == list(range(sent[robot]))
        assert list(values) == [frames[(start + k) % 4, 0, 0] for k in range(sent[robot])]


@pytest.mark.parametrize("bad", [["--phases", "bunched"], ["--seed", "-1"], ["--seed", "x"],
                                 ["--worker-threads", "0"]])
def test_service_bench_options_are_checked(bad):
    from cli.main import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "--service", *bad])
    args = build_parser().parse_args(["bench", "--service", "--phases", "random", "--seed", "7"])
    assert (args.phases, args.seed, args.worker_threads) == ("random", 7, None)


@pytest.mark.parametrize("presets, timed", [
    (["default"], {"robust", "reference32"}),
    (["reference"], {"reference", "robust", "reference32"}),
    (["paper", "paper"], {"paper", "robust", "reference32"}),
    (["reference32"], {"reference32", "robust"})])
def test_bench_times_the_default_preset_for_the_ratio(presets, timed):
    from asnn.evaluation.bench import run

    report = run(sizes=[(48, 48)], frames=2, presets=presets, models=("asnn",))
    rows = report["results"]
    assert {r["preset"] for r in rows if r["form"] == "optimised"} == timed
    assert len([r for r in rows if r["form"] == "optimised"]) == len(timed)
    assert [r["speedup"] > 0 for r in rows if r["form"] == "straightforward"] == [True]
    # the default's cost against the published variant, timed in the same run
    assert [r["vs_published"] > 0 for r in rows if "vs_published" in r] == [True]
    default = next(r for r in rows if "vs_published" in r)
    assert default["preset"] == "robust"
    published = next(r for r in rows if r["preset"] == "reference32")
    assert default["vs_published_apart"] == default["median_ms"] / published["median_ms"]


def test_detectors_stepped_in_turn_take_each_frame_together_first_by_turns():
    from asnn.evaluation.bench import time_in_turn

    calls = []

    class Recorder:
        def __init__(self, name):
            self.name = name

        def step(self, frame):
            calls.append((self.name, int(frame[0, 0])))

    frames = np.arange(5, dtype=np.uint8)[:, None, None] * np.ones((1, 2, 2), np.uint8)
    times = time_in_turn([lambda: Recorder("a"), lambda: Recorder("b")], frames, warmup=2)
    # both take frame i before either takes i + 1, and who goes first alternates
    assert calls == [("a", 0), ("b", 0), ("b", 1), ("a", 1), ("a", 2), ("b", 2),
                     ("b", 3), ("a", 3), ("a", 4), ("b", 4)]
    assert [len(t) for t in times] == [3, 3] and all((t >= 0).all() for t in times)


def test_the_default_is_timed_against_the_published_variant_in_turn(monkeypatch):
    """``vs_published`` comes from the two stepped in turn, not from the rows' medians."""
    from asnn.evaluation import bench

    rounds = []

    def in_turn(makes, frames, warmup=2):
        names = [make().params for make in makes]
        rounds.append(names)
        return [np.full(len(frames) - warmup, 3.0), np.full(len(frames) - warmup, 2.0)]

    monkeypatch.setattr(bench, "time_in_turn", in_turn)
    report = bench.run(sizes=[(48, 48)], frames=2, presets=["default"], models=("asnn",),
                       straightforward=False)
    from asnn.params import preset

    assert rounds == [[preset("robust"), preset("reference32")]] * bench.TURN_ROUNDS
    row = next(r for r in report["results"] if "vs_published" in r)
    assert row["vs_published"] == 1.5
    assert "1.50x the time of reference32 stepped in turn" in bench.format_table(report)


def test_bench_rejects_an_unknown_preset(capsys, monkeypatch):
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(SystemExit) as refused:  # refused as the arguments are read
        main(["bench", "--preset", "nope", "--size", "48x48", "--frames", "2"])
    assert refused.value.code == 2
    assert "unknown preset 'nope'" in capsys.readouterr().err


def test_kernels_are_loaded_before_anything_is_timed(monkeypatch):
    """A kernel first called on a later frame (the clustering) must not be timed as a step."""
    import numpy as np

    import asnn.evaluation.bench
    import asnn.warmup
    from service.bench import model_time

    calls = []
    loaded = []

    def compile_kernels(presets=("default", "reference"), threads=1, straightforward=False):
        calls.append("compile")
        loaded.append(list(presets))

    monkeypatch.setattr(asnn.warmup, "compile_kernels", compile_kernels)
    timed = asnn.evaluation.bench.time_detector

    def time_detector(*args, **kwargs):
        calls.append("time")
        return timed(*args, **kwargs)

    monkeypatch.setattr(asnn.evaluation.bench, "time_detector", time_detector)
    asnn.evaluation.bench.run(sizes=[(32, 32)], frames=2, presets=["paper"], models=("asnn",),
                              straightforward=False)
    assert calls == ["compile", "time"]
    assert "paper" in loaded[-1]  # timed: some of its float32 kernels are not the default's
    calls.clear()
    frames = np.zeros((4, 32, 32), np.uint8)
    assert model_time(None, frames)["median_ms"] > 0
    assert calls == ["compile", "time"]
    calls.clear()
    assert model_time("paper", frames)["median_ms"] > 0  # the service bench's preset too
    assert calls == ["compile", "time"] and "paper" in loaded[-1]


def test_warmup_after_a_handover():
    from asnn.evaluation.handover import covered, warmup_after

    assert warmup_after([True, True, False], [True, True, False]) == 0
    assert warmup_after([True, True, True, False], [False, False, True, False]) == 2
    assert warmup_after([False, True, False, True], [True, True, False, True]) == 1
    with pytest.raises(ValueError):
        warmup_after([True], [True, False])
    assert covered({0: 8, 3: 1, 12: 1}, 3) == 0.9 and covered({}, 0) == 1.0


class _HoldingDetector:
    """Warns from frame 20 of the stream on, once it has stepped 6 frames; holds every second
    frame as a fast camera's frame-rate ceiling does."""

    def __init__(self):
        self.index = self.ceiling_held = 0

    def step(self, frame, t=None):
        from asnn.response import Response

        self.index += 1
        self.ceiling_held += self.index % 2 == 0
        response = Response.silent(self.index - 1)
        return dataclasses.replace(response, collision=t >= 20 and self.index >= 12)


def test_the_handover_warmup_counts_the_frames_the_model_stepped():
    """A hand-over's warm-up is what the worker's --warmup-frames counts: frames stepped, not
    the frames a frame-rate ceiling held."""
    from asnn.evaluation.handover import handover_warmups

    class Spec:
        make = _HoldingDetector

    scene = types.SimpleNamespace(frames=np.zeros((40, 8, 8), np.uint8), fps=1.0)
    rows = handover_warmups([("s", scene)], Spec(), every=4)
    # from frame k > 9 the fresh model agrees after j = 11 frames (where the scene is that
    # long), of which it stepped j - j // 2; from k <= 9 at once
    frames = {k: 0 if k <= 9 else min(11, 40 - k) for k in range(1, 39, 4)}
    assert {(r["frame"], r["warmup"]) for r in rows} == {
        (k, j - j // 2) for k, j in frames.items()}
    assert {r["warmup"] for r in rows} == {0, 6, 4, 2}



class _PlainDetector:
    """Warns from frame 20 of the stream on, once it has stepped 12 frames; holds none (no
    ceiling_held, as the LGMD baselines)."""

    def __init__(self):
        self.index = 0

    def step(self, frame, t=None):
        from asnn.response import Response

        self.index += 1
        return dataclasses.replace(Response.silent(self.index - 1),
                                   collision=t >= 20 and self.index >= 12)


def test_the_handover_warmup_of_a_model_that_holds_no_frame_is_the_frames_it_took():
    """Without a frame-rate ceiling every frame is stepped: the warm-up is the j frames after
    which the fresh model agrees for good, to the frame (an even j as much as an odd one)."""
    from asnn.evaluation.handover import handover_warmups

    class Spec:
        make = _PlainDetector

    scene = types.SimpleNamespace(frames=np.zeros((40, 8, 8), np.uint8), fps=1.0)
    rows = handover_warmups([("s", scene)], Spec(), every=1)
    assert {(r["frame"], r["warmup"]) for r in rows} == {
        (k, 0 if k <= 9 else min(11, 40 - k)) for k in range(1, 39)}


def test_the_handover_bench_runs_every_approach_at_the_rate_asked(monkeypatch):
    """--looms FPS: each of the design's approaches once, at FPS alone, counted in the report
    (not the design's other rates)."""
    from asnn.evaluation import handover, ttc

    monkeypatch.setattr(ttc, "DEFAULT_DESIGN", ttc.Design(
        polarities=("dark", "light"), heights=(12.0,), taus=(2.0,), positions=(None,)))
    names = []
    monkeypatch.setattr(handover, "handover_warmups",
                        lambda scenes, *a, **k: names.extend(name for name, _ in scenes) or [])
    report = handover.run(looms=60.0)
    assert report["cases"] == len(names) == 2 and report["source"] == "approaches at 60 fps"
    assert all(name.endswith("-60fps") for name in names)


def test_the_handover_report_names_the_suite_when_it_ran_over_it():
    from asnn.evaluation.handover import format_report, summarise_warmups

    rows = [{"scene": "a", "frame": 1, "warmup": 3, "approach": True}]
    text = format_report({"detector": "asnn", "preset": "robust", "cases": 4, "source": None,
                          "every": 3, **summarise_warmups(rows)})
    assert text.startswith("# asnn (preset robust): 4 cases of the labelled suite, a hand-over "
                           "every 3 frames")

def test_handover_bench_over_the_approaches_of_a_fast_camera(capsys, monkeypatch):
    """--looms FPS: the hand-overs of eval --ttc's approaches at that rate (the suite is
    20 fps); not with the suite's cases or labelled clips."""
    from asnn.evaluation import ttc

    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(ttc, "DEFAULT_DESIGN", ttc.Design(
        polarities=("dark",), heights=(12.0,), taus=(2.0,), positions=(None,)))
    assert main(["bench", "--handover", "--looms", "60", "--every", "25", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["cases"] == 1 and report["source"] == "approaches at 60 fps"
    assert {w["scene"] for w in report["worst"]} == {"loom-dark-d12-tau2s-centre-60fps"}
    assert report["all"]["handovers"] >= 5
    assert main(["bench", "--handover", "--looms", "60", "--cases", "loom-*"]) == 2
    assert "one of them" in capsys.readouterr().err
    assert main(["bench", "--looms", "60"]) == 2


def test_handover_bench_takes_labelled_clips(tmp_path, capsys, monkeypatch):
    """The warm-up measured on real video (a fleet trial found hand-overs on the real clips
    that lose a warning after the worker's 30 frames, where the suite said 99 % are covered):
    a labelled clip as asnn eval reads it, its hand-overs within its approach marked."""
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    labels = tmp_path / "labels.json"
    assert main(["scene", "--case", "loom-dark-c0.6-d6-center", str(tmp_path / "loom.avi"),
                 "--labels", str(labels)]) == 0
    capsys.readouterr()
    assert main(["bench", "--handover", "--clips", str(tmp_path), "--every", "15",
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["cases"] == 1 and report["source"] == f"labelled clips of {tmp_path}"
    frames = json.loads(labels.read_text())[0]["frames"]
    assert report["all"]["handovers"] == len(range(1, frames - 1, 15))
    assert 0 < report["approach"]["handovers"] < report["all"]["handovers"]
    assert {w["scene"] for w in report["worst"]} == {"loom.avi"}


def test_handover_bench_says_a_clips_folder_it_cannot_read_as_asnn_eval_does(
        tmp_path, capsys, monkeypatch):
    """`--clips nosuch` printed `[Errno 2] No such file or directory: 'nosuch/labels.json'`,
    and `--clips clip.mp4` `[Errno 20] Not a directory: 'clip.mp4/labels.json'`."""
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    clip = tmp_path / "clip.mp4"
    clip.write_bytes(b"")
    for folder, says in ((tmp_path / "nosuch", "not a folder"), (clip, "not a folder"),
                         (tmp_path, "no labels file")):
        assert main(["bench", "--handover", "--clips", str(folder)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"asnn bench: --clips {folder}: {says}"), err
        assert "Errno" not in err


def test_handover_bench_reports_the_warmup_distribution(capsys, monkeypatch):
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert main(["bench", "--handover", "--cases", "loom-dark-c0.6-*", "--every", "9",
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["cases"] > 1 and report["preset"] == "robust"
    rows = report["all"]
    assert rows["handovers"] == sum(rows["counts"].values()) > 0
    assert 0 <= rows["quantile"] <= rows["max"]
    # a fresh model on a looming disk needs a few frames of approach before it warns: some
    # hand-overs need a few frames, and the worker's default covers nearly all of those during
    # approaches (99.3 % over the whole suite, README; 88 of these 89)
    from service.core import HANDOVER_WARMUP_FRAMES

    counts = {int(k): v for k, v in report["approach"]["counts"].items()}
    covered = sum(v for k, v in counts.items() if k <= HANDOVER_WARMUP_FRAMES)
    assert rows["max"] > 0 and covered >= 0.95 * sum(counts.values())


def test_detect_bench_reports_the_whole_process_and_its_stages(capsys, monkeypatch):
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert main(["bench", "--detect", "--size", "64x48", "--frames", "12", "--repeat", "1",
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["threads"] == "as asnn detect: not pinned"
    (row,) = report["results"]
    assert row["size"] == "64x48" and row["identical"] is True
    assert set(row["stages_ms"]) == {"decode", "model", "targets", "output", "stream"}
    assert all(v >= 0 for v in row["stages_ms"].values()) and row["straightforward_ms"] > 0
    assert row["stages_ms"]["targets"] > 0  # the default's objects stage, timed on its own
    # 12 frames may be too few to tell from the start-up's noise: then not measured
    if row["detect_ms"] is None:
        assert row["ratio"] is None
    else:
        assert row["ratio"] == pytest.approx(row["straightforward_ms"] / row["detect_ms"])
    from asnn.evaluation.bench_detect import format_table

    assert "| 64x48 |" in format_table(report) and "| yes |" in format_table(report)


def test_a_per_frame_cost_within_the_start_ups_noise_is_not_measured():
    """asnn bench --detect's per-frame cost is a difference of two processes' medians: with
    few frames the start-up's noise can make it come out negative (a user trial printed
    -157 ms a frame); it is reported only where it is above the short runs' spread."""
    from asnn.evaluation.bench_detect import format_table, per_frame_ms

    assert per_frame_ms([2.0, 2.1, 2.2], [1.0, 1.2, 1.1], 102) == pytest.approx(10.0)
    assert per_frame_ms([1.9, 2.0], [2.1, 2.0], 102) is None  # negative
    assert per_frame_ms([1.45], [1.3, 1.0, 1.5], 102) is None  # within the spread (0.5 s)
    row = {"size": "128x128", "detect_ms": None, "ratio": None, "loop_ms": 1.0,
           "straightforward_ms": 20.0, "identical": True,
           "stages_ms": dict.fromkeys(("decode", "model", "targets", "output", "stream"), 0.1)}
    table = format_table({"results": [row]})
    assert "| 128x128 | n/a |" in table and "| n/a | yes |" in table and "more --frames" in table


@pytest.mark.parametrize("per_run, median, note", [
    ([1.2, 1.8, 1.3], 1.3, "1.30x the time of reference32 stepped in turn, median of 3 runs, "
                           "1.20-1.80x"),
    ([1.5, 1.5, 1.5], 1.5, "median of 3 runs, 1.50-1.50x")])
def test_the_comparison_in_turn_is_repeated_and_its_median_and_range_reported(
        monkeypatch, per_run, median, note):
    """``repeat``: fresh comparisons in turn, each run's ratio (its TURN_ROUNDS passes pooled)
    kept and their median taken, so that the cost bound's margin is measured in one command."""
    from asnn.evaluation import bench

    ratios = iter([r for r in per_run for _ in range(bench.TURN_ROUNDS)])

    def in_turn(makes, frames, warmup=2):
        assert len(makes) == 2
        n = len(frames) - warmup
        return [np.full(n, next(ratios)), np.ones(n)]

    monkeypatch.setattr(bench, "time_in_turn", in_turn)
    report = bench.run(sizes=[(48, 48)], frames=2, presets=["default"], models=("asnn",),
                       straightforward=False, repeat=3)
    assert next(ratios, None) is None  # every run made its passes
    row = next(r for r in report["results"] if "vs_published" in r)
    assert row["vs_published_runs"] == pytest.approx(per_run)
    assert row["vs_published"] == pytest.approx(median)
    assert note in bench.format_table(report)


@pytest.mark.parametrize("extra", [["--handover"], ["--service"]])
def test_bench_refuses_repeat_where_it_means_nothing(capsys, monkeypatch, extra):
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert main(["bench", "--repeat", "3", *extra]) == 2
    assert "--repeat" in capsys.readouterr().err


@pytest.mark.parametrize("bad, says", [
    (["--frames", "10001"], "argument --frames: must be at most 10000"),
    (["--size", "3000x3000"], "argument --size: frames must be at most 1920x1080"),
    (["--fps", "inf"], "argument --fps: not a finite number"),
    (["--worker-threads", "257"], "argument --worker-threads: must be at most 256")])
def test_bench_refuses_sizes_and_counts_without_bound(capsys, bad, says):
    with pytest.raises(SystemExit):
        main(["bench", *bad])
    assert says in capsys.readouterr().err


def test_bench_refuses_a_clip_too_large_to_draw_at_once(capsys, monkeypatch):
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert main(["bench", "--size", "1920x1080", "--frames", "1000"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["asnn bench: 1000 frames at 1920x1080 are more than the bench draws at once: "
                   "at most 58 at that size"]


def test_bench_times_a_preset_with_changed_fields_beside_the_preset(monkeypatch):
    """``robust/top_k=0`` is timed with its fields changed, in its own row of the same run: a
    stage's cost without a second run at another time."""
    from asnn.evaluation import bench
    from asnn.params import preset

    built = {}

    def timed(make, clip, warmup):
        model = make()
        built.setdefault(model.params, 0)
        built[model.params] += 1
        return np.full(len(clip) - warmup, 1.0)

    monkeypatch.setattr(bench, "time_detector", timed)
    report = bench.run(sizes=[(48, 48)], frames=2, presets=["robust", "robust/top_k=0"],
                       models=("asnn",), straightforward=False, repeat=1)
    rows = {r["preset"]: r for r in report["results"]}
    assert set(rows) == {"robust", "robust/top_k=0", "reference32"}
    assert preset("robust", top_k=0) in built and preset("robust") in built
    assert "vs_published" in rows["robust"] and "vs_published" not in rows["robust/top_k=0"]


def test_bench_names_a_changed_default_by_its_preset_once(monkeypatch):
    """``default/top_k=0`` is ``robust/top_k=0``, as ``default`` is ``robust``: one row, named
    by the preset, not two rows timing the same parameters under two names."""
    from asnn.evaluation import bench
    from asnn.params import DEFAULT_PRESET

    monkeypatch.setattr(bench, "time_detector",
                        lambda make, clip, warmup: np.full(len(clip) - warmup, 1.0))
    report = bench.run(sizes=[(48, 48)], frames=2,
                       presets=["default/top_k=0", f"{DEFAULT_PRESET}/top_k=0", "/top_k=0"],
                       models=("asnn",), straightforward=False, repeat=1)
    assert [r["preset"] for r in report["results"]] == [f"{DEFAULT_PRESET}/top_k=0"]


@pytest.mark.parametrize("argv, says", [
    (["--preset", "robust/nope=1"], "nope"),
    (["--detect", "--preset", "robust/top_k=0"], "take a preset's name"),
    (["--service", "--preset", "robust/top_k=0"], "take a preset's name")])
def test_bench_refuses_changed_fields_it_cannot_time(capsys, monkeypatch, argv, says):
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    try:
        status = main(["bench", *argv])
    except SystemExit as exc:  # argparse's own refusal
        status = exc.code
    assert status == 2
    assert says in capsys.readouterr().err


def test_the_straightforward_forms_kernels_are_loaded_too_when_it_is_timed():
    """A review: the straightforward form runs the objects' kernels in float64, which the
    float32 default's optimised form never calls: the bench timed their compiling in its
    frames (a p90 of 204 ms against a median of 3 ms on a fresh install)."""
    import subprocess
    import sys

    code = ("from asnn.warmup import compile_kernels\n"
            "from asnn import targets\n"
            "compile_kernels(straightforward={})\n"
            "print(any('float64' in str(s) for s in targets._region_moments.signatures))")
    loaded = [subprocess.run([sys.executable, "-c", code.format(flag)], capture_output=True,
                             text=True, timeout=300, check=True).stdout.strip()
              for flag in (False, True)]
    assert loaded == ["False", "True"]


@pytest.mark.parametrize("args, says", [
    (["--service", "--handover"], "--handover and --service: one bench at a time"),
    (["--detect", "--model", "lgmd2"], "--detect times the ASNN model"),
    (["--service", "--model", "lgmd1"], "--service times the ASNN model"),
    (["--service", "--seconds", "1"], "--seconds must be at least 2 with --service"),
    # a CLI sweep: another mode's options were ignored without a word
    (["--model", "lgmd1", "--cameras", "5", "--every", "2"],
     "--cameras, --every do not go with the per-frame bench"),
    (["--service", "--frames", "3"], "--frames does not go with --service"),
    (["--handover", "--size", "64x64"], "--size does not go with --handover"),
    (["--detect", "--workers", "2"], "--workers does not go with --detect"),
    (["--every", "3"], "--every does not go with the per-frame bench"),  # its default, given
    (["--clips", "."], "--clips does not go with the per-frame bench"),
    (["--handover", "--clips", ".", "--cases", "loom-*"],
     "labelled clips or generated approaches: one of them"),
])
def test_bench_refuses_options_that_would_be_ignored(capsys, monkeypatch, args, says):
    """A review: these ran another bench than asked, or a step too short to measure reported
    as keeping up, with exit status 0."""
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert main(["bench", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0]


def test_the_service_bench_starts_workers_with_options_the_cli_takes(tmp_path):
    """The service bench spells `asnn worker`'s command line itself: a renamed or removed flag
    would break the benchmark with nothing else to say so."""
    from cli.main import build_parser
    from service.bench import _worker_args

    config = tmp_path / "zenoh.json5"
    args = build_parser().parse_args(_worker_args("w1", config, "robust/top_k=0", 3))
    assert args.func.__name__ == "cmd_worker"
    assert (args.config, args.log_level, args.id, args.threads) == (str(config), "warning",
                                                                   "w1", 3)
    assert args.preset is not None and "top_k" in str(args.preset)


def test_the_benches_processes_run_this_asnn_not_the_working_folders(tmp_path):
    """A packaging trial: the service and detect benches started ``python -m cli.main``, which
    puts the working folder first on the path: run from a checkout of another version, the
    benches timed its code."""
    import os
    import shutil
    import subprocess

    from cli.bench import ASNN_COMMAND

    shadow = tmp_path / "cli"
    shadow.mkdir()
    (shadow / "__init__.py").write_text("")
    (shadow / "main.py").write_text("import sys\ndef main():\n    print('SHADOW')\n    return 0\n"
                                    "if __name__ == '__main__':\n    sys.exit(main())\n")
    # nor a module of any other name there (-P), nor a copy on PYTHONPATH or installed
    # (an editable install of another checkout): this one is first (a mutation probe)
    (tmp_path / "argparse.py").write_text("raise ImportError('SHADOW argparse')\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copytree(shadow, elsewhere / "cli")
    env = {**os.environ, "PYTHONPATH": str(elsewhere)}
    done = subprocess.run([*ASNN_COMMAND, "router", "--help"], cwd=tmp_path, text=True,
                          capture_output=True, timeout=120, env=env)
    assert done.returncode == 0 and "SHADOW" not in done.stdout, done.stdout + done.stderr
    assert done.stdout.startswith("usage: ")  # the real parser's help
