"""``asnn eval --ttc``: the targets' time to contact against approaches of known contact time."""

from __future__ import annotations

import contextlib
import io
import json
import math

import pytest

from asnn import ASNN
from asnn.evaluation import ttc
from asnn.params import preset
from cli.main import main

# two approaches, 10 and 60 fps: a time base ignored reads half or three times the truth
SMALL = ttc.Design(frame_rates=(10.0, 60.0), polarities=("dark",), heights=(12.0,), taus=(2.0,),
                   positions=(None,))


@pytest.fixture(scope="module")
def scene():
    return ttc.loom_scene(ttc.looms(SMALL)[0])  # 10 fps


def _targets(scene, ttc_of):
    """One target per frame at the labelled centre, with ``ttc_of(true)`` (a far one too)."""
    out = []
    for (x, y), true in zip(scene.track, scene.ttc):
        value = ttc_of(float(true)) if math.isfinite(true) and true > 0 else None
        out.append([{"x": 150.0, "y": 110.0, "ttc": 0.01},  # elsewhere: never the object's
                    {"x": float(x) + 2.0, "y": float(y), "ttc": value}])
    return out


def test_the_samples_are_the_approach_frames_with_their_growth_and_error(scene):
    exact = ttc.scene_samples(scene, _targets(scene, lambda true: true))
    assert [s["frame"] for s in exact] == list(range(scene.onset_frame, scene.contact_frame + 1))
    assert all(s["error"] == pytest.approx(0.0) for s in exact)
    first, last = exact[0], exact[-1]
    assert first["true"] == pytest.approx(2.0) and first["growth"] == pytest.approx(0.0)
    k = last["frame"]
    assert last["growth"] == pytest.approx(scene.target_size[k] / scene.target_size[k - 1] - 1)
    assert last["growth"] > 0.2  # the last frames at 10 fps grow by more than a fifth

    doubled = ttc.scene_samples(scene, _targets(scene, lambda true: 2 * true))
    assert all(s["error"] == pytest.approx(1.0) for s in doubled)
    none = ttc.scene_samples(scene, _targets(scene, lambda true: None))
    assert all(s["ttc"] is None and s["error"] is None for s in none)
    far = [[{"x": 150.0, "y": 110.0, "ttc": 1.0}] for _ in scene.frames]
    assert all(s["ttc"] is None for s in ttc.scene_samples(scene, far))
    with pytest.raises(ValueError):
        ttc.scene_samples(scene, far[:-1])


def test_summaries_and_rows_by_frame_rate_and_growth():
    samples = [{"fps": 10.0, "true": 1.0, "growth": 0.01, "error": e, "ttc": None}
               for e in (None, None)]
    samples += [{"fps": 10.0, "true": 0.5, "growth": 0.3, "error": e / 10, "ttc": 1.0}
                for e in range(11)]  # errors 0, 0.1, ... 1.0
    samples += [{"fps": 30.0, "true": 2.0, "growth": 0.03, "error": -0.1, "ttc": 1.8}]
    s = ttc.summarise(samples[2:13])
    assert (s["frames"], s["with_ttc"], s["share"]) == (11, 11, 1.0)
    assert s["median"] == pytest.approx(0.5) and s["median_abs"] == pytest.approx(0.5)
    assert s["p10"] == pytest.approx(0.1) and s["p90"] == pytest.approx(0.9)
    assert s["long"] == pytest.approx(8 / 11)  # 0.3 ... 1.0
    assert ttc.summarise(samples[:2])["median"] is None
    assert ttc.summarise(samples, horizon=0.8)["share_within"] == 1.0
    assert ttc.summarise(samples, horizon=1.5)["share_within"] == pytest.approx(11 / 13)
    rows = ttc.ttc_rows(samples, horizon=1.5)
    assert [(r["fps"], r["growth"], r["frames"]) for r in rows] == [
        (10.0, "< 2 %", 2), (10.0, "20-50 %", 11), (10.0, "all", 13),
        (30.0, "2-5 %", 1), (30.0, "all", 1),
        (None, "< 2 %", 2), (None, "2-5 %", 1), (None, "20-50 %", 11), (None, "all", 14)]
    assert [ttc.growth_bin(g) for g in (0.0, 0.019, 0.02, 0.5, 3.0)] == [0, 0, 1, 5, 5]


def test_the_design_is_every_combination_each_with_its_own_seed():
    assert ttc.DEFAULT_DESIGN == ttc.Design()
    looms = ttc.looms(ttc.Design(seed=7))
    assert len(looms) == 96 and len({loom.seed for loom in looms}) == 96
    assert looms[0].seed == 7 and {loom.onset for loom in looms} == {10, 15, 30}
    for empty in (ttc.Design(frame_rates=()), ttc.Design(heights=(0.0,))):
        with pytest.raises(ValueError):
            ttc.looms(empty)


@pytest.fixture(scope="module")
def measured():
    return ttc.evaluate_ttc("asnn", SMALL)


def _row(results, fps, growth):
    return next(r for r in results["rows"] if r["fps"] == fps and r["growth"] == growth)


def test_the_default_preset_s_ttc_is_near_the_truth_while_the_image_grows_slowly(measured):
    """A ttc doubled, or timed without the frames' times (at 0.05 s a frame: half the truth at
    10 fps, three times it at 60), fails this; the saturation in the last frames (more than a
    fifth of growth per frame) is left out."""
    assert measured["horizon_s"] == 1.5
    for fps in (10.0, 60.0):
        slow = [r for r in measured["rows"] if r["fps"] == fps
                and r["growth"] in ("< 2 %", "2-5 %", "5-10 %", "10-20 %") and r["with_ttc"] >= 3]
        assert sum(r["with_ttc"] for r in slow) >= 5
        for row in slow:
            assert -0.25 <= row["median"] <= 0.15, (fps, row)
        assert _row(measured, fps, "all")["share_within"] >= 0.3
    assert json.loads(json.dumps(measured, allow_nan=False)) == measured  # ttc.json as it is


def test_the_reported_ttc_holds_late_in_a_fast_approach_and_nothing_else_changes():
    """The 10 fps approach's last frames grow by a fifth to a half a frame: the track's own
    estimate, which the approach test reads, reads them long (+33 % to +420 %); the targets
    report their own (``refined_ttc``: a refined fit, smoothed under a constant-speed
    approach), within 5 % there, and every warning and every target's other field is as it
    was."""
    loom = ttc.looms(SMALL)[0]
    scene = ttc.loom_scene(loom)
    runs = {}
    for refined in (True, False):
        model = ASNN(preset("robust", refined_ttc=refined))
        runs[refined] = [model.step(frame, k / loom.fps) for k, frame in enumerate(scene.frames)]

    def late(responses):
        samples = ttc.scene_samples(scene, [list(r.targets) for r in responses])
        return [s["error"] for s in samples if s["growth"] >= 0.2]

    assert len(late(runs[True])) >= 3 and all(e is not None and abs(e) < 0.05
                                              for e in late(runs[True]))
    assert max(e for e in late(runs[False]) if e is not None) > 0.4
    targets = 0
    for new, old in zip(runs[True], runs[False]):
        new, old = new.to_dict(), old.to_dict()
        for response in (new, old):
            for target in response["targets"]:
                assert (target["ttc"] is None) == (target["expansion"] is None
                                                   or target["expansion"] <= 0)
                if target["ttc"] is not None:
                    assert target["ttc"] * target["expansion"] == pytest.approx(1.0)
                targets += 1
                del target["ttc"], target["expansion"]
        assert new == old
    assert targets >= 20


class _Untimed:
    """A detector stepped without the frames' times (what a broken time base amounts to)."""

    def __init__(self):
        self.model = ASNN("default")

    def step(self, frame, t=None):
        return self.model.step(frame, None)


def test_a_detector_that_ignores_the_frames_times_is_caught():
    loom = ttc.looms(SMALL)[0]  # 10 fps: timed at 20 fps, the ttc halves
    errors = [s["error"] for s in ttc.loom_samples(loom, _Untimed)
              if s["error"] is not None and s["growth"] < 0.2]
    assert errors and sorted(errors)[len(errors) // 2] < -0.3


def test_eval_ttc_prints_the_table_and_writes_it(tmp_path, monkeypatch):
    monkeypatch.setattr(ttc, "DEFAULT_DESIGN", SMALL)
    out, stdout = tmp_path / "o", io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(io.StringIO()):
        assert main(["eval", "--ttc", "--out", str(out)]) == 0
    text = stdout.getvalue()
    assert "| fps | growth per frame | frames | with ttc |" in text
    assert "| 10 | **all** |" in text and "| all | **all** |" in text
    assert "| fps | approaches | warned | median lead | p10 lead |" in text
    assert text.rstrip().endswith(f"{out}/ttc.md")
    assert (out / "ttc.md").read_text() in text
    results = json.loads((out / "ttc.json").read_text())
    assert results["detector"] == "asnn" and len(results["looms"]) == 2


def test_eval_ttc_runs_the_frame_rates_asked(tmp_path, monkeypatch, capsys):
    """--frame-rates: the same approaches at other rates (a camera faster than the default's
    frame-rate ceiling); only with --ttc, each rate once."""
    monkeypatch.setattr(ttc, "DEFAULT_DESIGN", SMALL)
    out = tmp_path / "o"
    assert main(["eval", "--ttc", "--frame-rates", "45,120", "--out", str(out)]) == 0
    results = json.loads((out / "ttc.json").read_text())
    assert results["design"]["frame_rates"] == [45.0, 120.0]
    assert [loom["fps"] for loom in results["looms"]] == [45.0, 120.0]
    assert "at 45/120 fps" in capsys.readouterr().out
    for wrong in (["--ttc", "--frame-rates", "30,30"], ["--ttc", "--frame-rates", "0"]):
        with pytest.raises(SystemExit) as exc:
            main(["eval", *wrong, "--out", str(tmp_path / "x")])
        assert exc.value.code == 2
    assert main(["eval", "--synthetic", "--frame-rates", "40", "--out", str(tmp_path / "x")]) == 2
    assert "--frame-rates does not go with this mode" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_eval_ttc_refuses_what_does_not_go_with_it(tmp_path, capsys):
    for misplaced in (["--detectors", "lgmd1"], ["--cases", "loom-*"], ["--warmup", "3"],
                      ["--perturb", "noise"], [str(tmp_path)]):
        assert main(["eval", "--ttc", *misplaced, "--out", str(tmp_path / "o")]) == 2
    assert not (tmp_path / "o").exists()


def test_the_lead_runs_from_the_first_warning_to_contact():
    samples = [{"frame": k, "fps": 20.0, "warned": k in (12, 13, 16)} for k in range(10, 21)]
    assert ttc.lead(samples) == pytest.approx(0.4)  # frame 12 to 20 at 20 fps
    assert ttc.lead([{**s, "warned": False} for s in samples]) is None
    quiet = [{**s, "fps": 10.0, "warned": False} for s in samples]
    rows = ttc.lead_rows([samples, quiet])
    assert [(r["fps"], r["approaches"], r["warned"]) for r in rows] == [
        (10.0, 1, 0), (20.0, 1, 1), (None, 2, 1)]
    assert rows[0]["median"] is None and rows[1]["median"] == pytest.approx(0.4)


def test_the_default_warns_as_early_at_60_fps_as_at_10(measured):
    """The frame-rate ceiling (max_step_rate): stepped at every frame of a 60 fps camera, the
    default warned of the small design's approach 1.2 s ahead at 10 fps and 0.67 s at 60."""
    leads = {row["fps"]: row["median"] for row in measured["leads"]}
    assert leads[10.0] is not None and leads[60.0] is not None
    assert leads[60.0] >= 0.75 * leads[10.0]
