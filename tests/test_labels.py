"""Clip labels are checked when they are read, before any detector runs; ``asnn label``
starts and checks them."""

from __future__ import annotations

import json
import re

import pytest

from asnn.evaluation import scoring
from asnn.evaluation.labels import check_labels, load_labels, mismatches
from asnn.io.video import write_video
from asnn.stimuli import make_scene
from cli.main import main
from shared_data import SHARED

DATA = SHARED / "data"

COLLISION = {"file": "c.mp4", "fps": 30.0, "frames": 60, "collision": True, "onset_frame": 20,
             "contact_frame": 40, "center": [10, 12], "description": "kept as it is"}
QUIET = {"file": "nc.mp4", "fps": 30.0, "frames": 60, "collision": False, "onset_frame": None,
         "contact_frame": None, "center": None}


@pytest.mark.parametrize("folder", ["real", "real-extra"])
def test_the_shared_labels_pass_and_score(folder):
    path = DATA / folder / "labels.json"
    if not path.is_file():
        pytest.skip(f"../shared/data/{folder} is absent")
    labels = load_labels(path)
    assert labels == json.loads(path.read_text())  # unchanged
    for label in labels:
        score = scoring.score_clip([], label)
        assert score.outcome == ("miss" if label["collision"] else "quiet")


def test_good_labels_come_back_unchanged_in_either_form(tmp_path):
    generated = {**COLLISION, "file": "g.avi", "track": [None] * 20 + [[1.5, 2.0]] * 40,
                 "ttc": [None] * 59 + [0.0], "target_size": [3.0] * 60, "category": ["loom"]}
    labels = [COLLISION, QUIET, generated, {**QUIET, "file": "bag.mcap", "topic": "/cam"}]
    path = tmp_path / "labels.json"
    path.write_text(json.dumps(labels))
    assert load_labels(path) == labels
    path.write_text(json.dumps({"clips": labels}))
    assert load_labels(path) == labels


@pytest.mark.parametrize("change, reason", [
    ({"onset_frame": None}, "needs onset_frame and contact_frame"),
    ({"contact_frame": None}, "needs onset_frame and contact_frame"),
    ({"onset_frame": 41}, "onset_frame 41 is after contact_frame 40"),
    ({"onset_frame": 60, "contact_frame": 70}, "beyond the clip's 60 frames"),
    ({"contact_frame": 60}, "contact_frame 60 is beyond the clip's 60 frames (0 to 59)"),
    ({"centre": [10, 12]}, "unknown field 'centre': did you mean 'center'?"),
    ({"colision": True}, "did you mean 'collision'?"),
    ({"onset_frme": 3}, "did you mean 'onset_frame'?"),
    ({"onset_frame": -1}, "onset_frame"),
    ({"onset_frame": 20.5}, "onset_frame"),
    ({"fps": None}, "fps"),
    ({"fps": 0}, "fps"),
    ({"fps": float("nan")}, "fps"),
    ({"collision": "yes"}, "collision"),
    ({"collision": None}, "collision"),
    ({"file": ""}, "file"),
    ({"frames": 0}, "frames"),
    ({"center": [1, 2, 3]}, "center"),
    ({"center": "middle"}, "center"),
    ({"track": [[1.0, 2.0]] * 59}, "track has 59 entries for the clip's 60 frames"),
    ({"track": [[1.0]] * 60}, "track.0.1: Field required; track.1.1: Field required; "
                              "track.2.1: Field required; and 57 more"),
    ({"ttc": [1.0] * 59 + [-0.5]}, "never negative"),
    ({"topic": ""}, "topic"),
    # an evaluation review: a field in capitals was kept and never read; a topic on a video
    # file passed asnn label, which said the entry was ready, and asnn eval refused it
    ({"TTC": [1.0] * 60}, "unknown field 'TTC': did you mean 'ttc'?"),
    ({"CENTER": [1, 2]}, "unknown field 'CENTER': did you mean 'center'?"),
    ({"topic": "/camera/image_raw"}, "a topic applies to ROS 2 bags only, not to the video c.mp4"),
    # taken quietly before the hostile-input trial: a bool or a string for a number, a frame
    # rate no camera has, a centre outside the frame the label gives
    ({"onset_frame": True}, "onset_frame: Input should be a valid integer"),
    ({"contact_frame": "40"}, "contact_frame: Input should be a valid integer"),
    ({"frames": 60.0}, "frames: Input should be a valid integer"),
    ({"fps": "20"}, "fps: Input should be a valid number"),
    ({"fps": True}, "fps: Input should be a valid number"),
    ({"fps": 1e308}, "fps: Input should be less than or equal to 240"),
    ({"fps": 1e-300}, "fps: Input should be greater than or equal to 1"),
    ({"width": 64, "height": 48, "center": [70.0, 20.0]},
     "center (70, 20) is outside the 64x48 frame"),
    ({"width": 64, "height": 48, "center": [10.0, -1.0]}, "outside the 64x48 frame"),
])
def test_a_refused_entry_is_named_with_its_field(change, reason):
    # a None in the change leaves the field out
    label = {key: value for key, value in {**COLLISION, **change}.items() if value is not None}
    with pytest.raises(ValueError) as refused:
        check_labels([QUIET, label], "labels.json")
    message = str(refused.value)
    assert message.startswith("labels.json: entry 1")
    assert reason in message


def test_a_topic_names_a_bags_camera_whether_the_bag_is_a_file_or_a_rosbag2_folder():
    # the topic rule refused rosbag2 folders once (a review): only a video file has no topic
    for file in ("drive.mcap", "rosbag2_2026_01_01", "bags/front"):
        assert check_labels([{**QUIET, "file": file, "topic": "/cam/image_raw"}], "l.json")


def test_a_missing_field_and_a_quiet_clip_with_an_onset_are_refused():
    for label, reason in [({k: v for k, v in QUIET.items() if k != "fps"}, "fps: Field required"),
                          ({k: v for k, v in QUIET.items() if k != "collision"}, "collision"),
                          ({**QUIET, "onset_frame": 10}, "without a collision"),
                          ("c.mp4", "expected an object")]:
        with pytest.raises(ValueError, match=reason):
            check_labels([label])


def test_two_clips_whose_results_would_share_a_file_are_refused():
    check_labels([COLLISION, {**QUIET, "file": "c2.mp4"}, {**QUIET, "file": "y" * 249 + ".mp4"}])
    with pytest.raises(ValueError, match="too long for its results file"):  # not mid-run
        check_labels([COLLISION, {**QUIET, "file": "y" * 250 + ".mp4"}])
    for other in ("c.avi", "night/c.mp4", "C.mp4"):  # C.jsonl is c.jsonl where case is ignored
        with pytest.raises(ValueError, match=r"entry 1 .*overwrite those of entry 0 \(c\.mp4\)"):
            check_labels([COLLISION, {**QUIET, "file": other}])
    # one clip entered twice is told so (it read as two clips' results colliding: a user trial)
    for same in ("c.mp4", "./c.mp4", "sub/../c.mp4"):
        with pytest.raises(ValueError, match=r"entry 1 \(.*c\.mp4\): names the same clip as "
                           "entry 0: one entry a clip"):
            check_labels([COLLISION, {**QUIET, "file": same}])
    # a bag's camera written both ways is one camera too (a review)
    with pytest.raises(ValueError, match="names the same clip as entry 0"):
        check_labels([{**QUIET, "file": "drive.mcap#/front/image_raw"},
                      {**QUIET, "file": "drive.mcap", "topic": "/front/image_raw"}])


@pytest.mark.parametrize("text", ["not json", '{"clips": 3}', '"c.mp4"', '[{"nofile": 1}]'])
def test_a_labels_file_that_is_not_a_list_of_labels_is_refused(tmp_path, text):
    path = tmp_path / "labels.json"
    path.write_text(text)
    with pytest.raises(ValueError, match="labels.json"):
        load_labels(path)
    path.write_text(json.dumps([COLLISION]), encoding="utf-16")
    with pytest.raises(ValueError, match="labels.json: not UTF-8 text"):
        load_labels(path)


@pytest.mark.parametrize("mode", [[], ["--held-out"]])
def test_eval_refuses_a_bad_label_before_running_anything(tmp_path, capsys, mode):
    (tmp_path / "c.mp4").write_bytes(b"")  # never opened: the labels are refused first
    (tmp_path / "labels.json").write_text(json.dumps([{**COLLISION, "onset_frame": 50}]))
    out = tmp_path / "out"
    assert main(["eval", str(tmp_path), *mode, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "entry 0 (c.mp4)" in err and "onset_frame 50 is after contact_frame 40" in err
    assert not out.exists()


def test_scoring_a_folder_checks_labels_that_were_not_read_from_a_file(tmp_path):
    assert [s.outcome for s in scoring.score_directory(tmp_path, [COLLISION])] == ["missing"]
    with pytest.raises(ValueError, match=r"labels: entry 0 \(c\.mp4\): fps"):
        scoring.score_directory(tmp_path, [{**COLLISION, "fps": 0}])


def test_a_clip_that_disagrees_with_its_label_is_named():
    assert mismatches(COLLISION, 60, 30.2) == []  # within 1 %
    assert mismatches({**COLLISION, "frames": None}, 59, 30.0) == []  # no length to compare
    assert mismatches(COLLISION, 59, 30.0) == [
        "c.mp4: 59 frames decoded where its label counts 60: its onset and contact may be off"]
    assert mismatches(COLLISION, 60, 25.0) == [
        "c.mp4: the clip runs at 25 fps where its label says 30: the model's timing and the "
        "scoring's disagree"]
    # without the label's frames, the clip's own: a contact after them, per-frame lists too short
    unsized = {**COLLISION, "frames": None, "track": [[1.0, 2.0]] * 60}
    assert mismatches(unsized, 60, 30.0) == []
    assert mismatches(unsized, 40, 30.0) == [
        "c.mp4: its contact_frame 40 is beyond the 40 frames decoded: the scoring's window "
        "ends after the clip",
        "c.mp4: its track has 60 entries for the 40 frames decoded (one per frame): its target "
        "scores are left out"]


def test_eval_reports_clips_that_disagree_with_their_labels(tmp_path):
    scene = make_scene("looming", size=(64, 64), frames=24, start=4, stop=20)
    write_video(scene.frames, tmp_path / "loom.mp4", scene.fps)
    write_video(scene.frames, tmp_path / "same.mp4", scene.fps)
    label = scene.label("loom.mp4")
    (tmp_path / "labels.json").write_text(json.dumps(
        [{**label, "frames": 30, "fps": 2 * scene.fps}, {**label, "file": "same.mp4"}]))
    out = tmp_path / "out"
    assert main(["eval", str(tmp_path), "--detectors", "lgmd1,lgmd2", "--out", str(out),
                 "--no-plots"]) == 0
    warnings = json.loads((out / "results.json").read_text())["warnings"]
    assert warnings == [  # once for the clip, not once a detector; none for the clip that fits
        "loom.mp4: 24 frames decoded where its label counts 30: its onset and contact may be off",
        f"loom.mp4: the clip runs at {scene.fps:g} fps where its label says {2 * scene.fps:g}: "
        "the model's timing and the scoring's disagree"]
    report = (out / "report.md").read_text()
    assert ("Warnings (clips that disagree with their labels, run slower than ASNN was made "
            "for, or are bags with frames stamped out of order):\n\n- loom.mp4: 24 frames") in report


def test_label_starts_the_labels_of_a_folder_and_lists_what_is_left(tmp_path, capsys):
    loom = make_scene("looming", size=(64, 48), frames=24, start=4, stop=20)
    write_video(loom.frames, tmp_path / "loom.mp4", loom.fps)
    write_video(loom.frames[:10], tmp_path / "still.avi", 25.0)
    (tmp_path / "notes.txt").write_text("not a clip")
    path = tmp_path / "labels.json"

    assert main(["label", str(tmp_path)]) == 1  # two entries to finish
    entries = json.loads(path.read_text())
    assert [(e["file"], e["frames"], e["fps"], e["width"], e["height"], e["collision"])
            for e in entries] == [("loom.mp4", 24, loom.fps, 64, 48, None),
                                  ("still.avi", 10, 25.0, 64, 48, None)]
    out = capsys.readouterr().out
    assert "2 entries added (loom.mp4, still.avi)" in out
    assert "still.avi: collision is not filled in (true or false)" in out
    assert main(["eval", str(tmp_path), "--out", str(tmp_path / "out")]) == 2  # not scored yet

    entries[0] = loom.label("loom.mp4")
    entries[1].update(collision=False)
    path.write_text(json.dumps(entries))
    assert main(["label", str(tmp_path)]) == 0
    assert "2 entries, every one ready for asnn eval" in capsys.readouterr().out
    assert json.loads(path.read_text()) == entries  # nothing added, nothing rewritten

    entries[1]["fps"] = 30.0
    path.write_text(json.dumps(entries + [{**entries[1], "file": "gone.mp4"}]))
    assert main(["label", str(tmp_path)]) == 1
    assert capsys.readouterr().out.splitlines() == [
        "still.avi: the clip runs at 25 fps where its label says 30: the model's timing and "
        "the scoring's disagree",
        f"gone.mp4: no such clip in {tmp_path}"]


def test_label_and_eval_take_a_raw_camera_stream_and_say_it_states_no_rate(tmp_path, capsys):
    """A raw MJPEG stream (an IP or USB camera's .mjpeg) decodes, but was neither labelled nor
    named as unscored: asnn label said "1 entries, every one ready" beside it (a user trial)."""
    import cv2

    loom = make_scene("looming", size=(64, 48), frames=12, start=2, stop=10)
    write_video(loom.frames, tmp_path / "loom.avi", loom.fps)
    (tmp_path / "cam.mjpeg").write_bytes(b"".join(
        cv2.imencode(".jpg", frame)[1].tobytes() for frame in loom.frames))
    (tmp_path / "labels.json").write_text(json.dumps([{**loom.label("loom.avi"),
                                                       "frames": 12}]))
    assert main(["label", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "1 entry added (cam.mjpeg)" in out
    assert re.search(r"cam\.mjpeg: a raw stream states no frame rate: OpenCV reads it, and "
                     r"asnn eval steps the model, at [\d.]+ fps; where the camera ran at another, "
                     r"put the stream in a container that states it \(ffmpeg -r RATE -i "
                     r"cam\.mjpeg -c copy cam\.mkv\)", out)
    entries = json.loads((tmp_path / "labels.json").read_text())
    assert entries[1]["file"] == "cam.mjpeg" and entries[1]["frames"] == 12
    (tmp_path / "solo").mkdir()  # one entry, ready: "1 entry", not "1 entries"
    write_video(loom.frames, tmp_path / "solo" / "loom.avi", loom.fps)
    (tmp_path / "solo" / "labels.json").write_text(json.dumps([{**loom.label("loom.avi"),
                                                               "frames": 12}]))
    assert main(["label", str(tmp_path / "solo")]) == 0
    assert "labels.json: 1 entry, every one ready for asnn eval" in capsys.readouterr().out
    # a bag beside it: entered by hand (its topic is the user's), and said so, not "ready"
    (tmp_path / "solo" / "run.mcap").write_bytes(b"")
    assert main(["label", str(tmp_path / "solo")]) == 1
    assert capsys.readouterr().out.startswith("run.mcap: a bag no entry names: enter it by hand")
    entries = [{**loom.label("loom.avi"), "frames": 12},
               {**loom.label("run.mcap"), "topic": "/c", "frames": 12}]
    (tmp_path / "solo" / "labels.json").write_text(json.dumps(entries))
    assert main(["label", str(tmp_path / "solo")]) == 0  # named: the bag is not listed
    capsys.readouterr()
    # a review: named by its name only, a bag in a subfolder hid one of the same name; an
    # .MCAP, a rosbag2 folder and a link to a bag that is gone were not listed
    (tmp_path / "solo" / "sub").mkdir()
    (tmp_path / "solo" / "sub" / "run.mcap").write_bytes(b"")
    (tmp_path / "solo" / "labels.json").write_text(json.dumps(
        [entries[0], {**entries[1], "file": "sub/run.mcap"}]))
    (tmp_path / "solo" / "OTHER.MCAP").write_bytes(b"")
    (tmp_path / "solo" / "drive").mkdir()
    (tmp_path / "solo" / "drive" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}")
    (tmp_path / "solo" / "gone.mcap").symlink_to(tmp_path / "nowhere.mcap")
    assert main(["label", str(tmp_path / "solo")]) == 1
    listed = [line.split(":")[0] for line in capsys.readouterr().out.splitlines()]
    assert listed == ["OTHER.MCAP", "drive", "gone.mcap", "run.mcap"]
    capsys.readouterr()
    # a mutation probe: a folder of a bag alone lists the bag, not "holds no video"; and an
    # entry naming it by another spelling of its path names it
    (tmp_path / "bags").mkdir()
    (tmp_path / "bags" / "run.mcap").write_bytes(b"")
    assert main(["label", str(tmp_path / "bags")]) == 1
    out = capsys.readouterr().out
    assert out.startswith("run.mcap: a bag no entry names") and "holds no video" not in out
    (tmp_path / "bags" / "labels.json").write_text(json.dumps([{**entries[1],
                                                                 "file": "./run.mcap"}]))
    assert main(["label", str(tmp_path / "bags")]) == 0


def test_a_link_to_a_clip_that_is_gone_is_named_not_skipped(tmp_path, capsys):
    """A symbolic link whose clip was moved: asnn label skipped it without a word (an own-data
    user trial); it is named, with what its decoding says."""
    (tmp_path / "moved.mp4").symlink_to(tmp_path / "nowhere" / "moved.mp4")
    assert main(["label", str(tmp_path)]) == 1
    assert (f"{tmp_path / 'moved.mp4'}: a link to {tmp_path / 'nowhere' / 'moved.mp4'}, which "
            "is not there") in capsys.readouterr().out
    assert not (tmp_path / "labels.json").exists()


def test_a_loop_of_links_is_named_not_a_traceback(tmp_path, capsys):
    """a.mp4 -> b.mp4 -> a.mp4 beside a clip: asnn label and eval ended in a RuntimeError's
    traceback once links were listed (a review)."""
    loom = make_scene("looming", size=(64, 48), frames=12, start=2, stop=10)
    write_video(loom.frames, tmp_path / "c.avi", loom.fps)
    (tmp_path / "a.mp4").symlink_to(tmp_path / "b.mp4")
    (tmp_path / "b.mp4").symlink_to(tmp_path / "a.mp4")
    assert main(["label", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "leads back to itself (a loop of links)" in out
    assert [e["file"] for e in json.loads((tmp_path / "labels.json").read_text())] == ["c.avi"]
    assert main(["detect", str(tmp_path / "a.mp4")]) == 2
    assert "a loop of links" in capsys.readouterr().err
    (tmp_path / "labels.json").write_text(json.dumps([{**loom.label("c.avi"), "frames": 12}]))
    assert main(["eval", str(tmp_path), "--detectors", "lgmd1", "--no-plots", "--out",
                 str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err  # named as links to no clip, not as videos to label
    assert "links in the folder that lead to no clip (not scored): a.mp4, b.mp4" in err
    assert "asnn label" not in err


def test_labels_saved_with_a_byte_order_mark_are_read(tmp_path):
    """Windows Notepad saves UTF-8 with a byte-order mark: the labels were refused as not
    JSON (a user trial)."""
    from asnn.evaluation.labels import read_entries

    path = tmp_path / "labels.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps([{"file": "a.mp4"}]).encode())
    assert read_entries(path) == [{"file": "a.mp4"}]


def test_a_missing_clip_s_name_composed_otherwise_is_named_so():
    """A label written on macOS names a clip in Unicode NFD; the folder holds it in NFC: the
    hint read "did you mean trottoir vide é.mp4?", the same name to the eye (a user trial)."""
    import unicodedata

    from asnn.evaluation.labels import clip_hint

    on_disk = unicodedata.normalize("NFC", "trottoir vide é.mp4")
    hint = clip_hint(unicodedata.normalize("NFD", on_disk), [on_disk, "other.mp4"])
    assert hint == (" (the folder has 'trottoir vide \\xe9.mp4', the same name with its "
                    "accents composed otherwise, Unicode NFC: write it as the file's name is)")
    assert clip_hint("loon.mp4", ["loom.mp4"]) == " (did you mean loom.mp4?)"


def test_label_adds_no_second_entry_for_a_clip_named_in_another_unicode_form(tmp_path,
                                                                              capsys):
    """The entry's own clip, named in NFD: asnn label added the file on disk as a blank second
    entry beside the hint to rename the first (two entries for one video: a review)."""
    import unicodedata

    loom = make_scene("looming", size=(64, 48), frames=12, start=2, stop=10)
    name = unicodedata.normalize("NFC", "café.avi")
    write_video(loom.frames, tmp_path / name, loom.fps)
    entry = {**loom.label(unicodedata.normalize("NFD", name)), "frames": 12}
    (tmp_path / "labels.json").write_text(json.dumps([entry]))
    assert main(["label", str(tmp_path)]) == 1
    assert "Unicode NFC: write it as the file's name is" in capsys.readouterr().out
    assert json.loads((tmp_path / "labels.json").read_text()) == [entry]


def test_label_refuses_labels_it_cannot_write_before_it_decodes_the_clips(tmp_path, capsys,
                                                                         monkeypatch):
    """A file where the labels' folder goes was said as "File exists" once every clip had
    decoded, and a name too long as a bare errno: said first, in words."""
    import cli.label

    write_video(make_scene("looming", size=(64, 48), frames=3).frames, tmp_path / "a.avi")
    (tmp_path / "a-file").write_text("")
    monkeypatch.setattr(cli.label, "_decode", lambda *args: pytest.fail("decoded first"))
    labels = tmp_path / "a-file" / "labels.json"
    assert main(["label", str(tmp_path), "--labels", str(labels)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"asnn label: cannot write {labels}: {tmp_path / 'a-file'} is not a folder"]
    labels = tmp_path / ("a" * 300 + ".json")
    assert main(["label", str(tmp_path), "--labels", str(labels)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"asnn label: {labels}: File name too long"]


def test_label_refuses_what_it_cannot_use(tmp_path, capsys):
    assert main(["label", str(tmp_path / "nowhere")]) == 2
    write_video(make_scene("looming", size=(64, 48), frames=3).frames, tmp_path / "a.avi")
    (tmp_path / "a-file").write_text("")
    assert main(["label", str(tmp_path), "--labels", str(tmp_path / "a-file" / "labels.json")]) == 2
    assert "cannot write" in capsys.readouterr().err  # one line, no traceback
    # a folder that is not there yet is made, as asnn scene --labels and asnn detect make theirs
    assert main(["label", str(tmp_path), "--labels", str(tmp_path / "no" / "labels.json")]) == 1
    assert [e["file"] for e in json.loads((tmp_path / "no" / "labels.json").read_text())] == [
        "a.avi"]
    (tmp_path / "labels.json").write_text("{not json")
    assert main(["label", str(tmp_path)]) == 2
    assert "not JSON" in capsys.readouterr().err


def test_scene_builds_a_labelled_folder_one_clip_at_a_time(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # OUT as typed, relative to here; the labels name it from theirs
    folder = tmp_path / "mine"
    labels = folder / "labels.json"
    # options between NAME and OUT, OUT in a folder that is not there yet
    assert main(["scene", "looming", "--polarity", "light", "mine/deep/light.mp4",
                 "--labels", str(labels)]) == 0
    assert main(["scene", "--case", "nearmiss-disk-dark-right", str(folder / "nm.avi"),
                 "--labels", "mine/labels.json"]) == 0
    assert main(["scene", "looming", "mine/deep/light.mp4", "--contrast", "0.5",
                 "--labels", str(labels)]) == 0  # the same clip again: its entry replaced
    entries = json.loads(labels.read_text())
    assert [(e["file"], e["collision"]) for e in entries] == [("nm.avi", False),
                                                              ("deep/light.mp4", True)]
    assert "'contrast': 0.5" in entries[1]["description"]
    assert main(["label", str(folder)]) == 0  # every entry ready, every clip where it says
    assert main(["scene", "--case", "nearmiss-disk-dark-right", "x.avi", "--size", "64x64"]) == 2
    assert "--size set a paper scene" in capsys.readouterr().err


def test_label_takes_every_video_suffix_and_names_an_empty_folder(tmp_path, capsys):
    assert main(["label", str(tmp_path)]) == 1  # nothing to label is something to say
    assert "holds no video" in capsys.readouterr().out
    assert not (tmp_path / "labels.json").exists()
    write_video(make_scene("looming", size=(64, 48), frames=12).frames, tmp_path / "a.avi")
    (tmp_path / "a.avi").rename(tmp_path / "dash0001.MTS")  # a dashcam's name; FFmpeg sniffs
    (tmp_path / "labels.json").write_text(json.dumps([{**QUIET, "file": "./other.mp4"}]))
    write_video(make_scene("looming", size=(64, 48), frames=12).frames, tmp_path / "other.mp4")
    assert main(["label", str(tmp_path)]) == 1
    entries = json.loads((tmp_path / "labels.json").read_text())
    assert [e["file"] for e in entries] == ["./other.mp4", "dash0001.MTS"]  # ./ is the same clip


def test_scene_refuses_a_labels_file_it_cannot_enter_the_clip_in_before_writing_it(tmp_path,
                                                                                 capsys):
    (tmp_path / "labels").mkdir()
    (tmp_path / "bad.json").write_text("{not json")
    for labels, reason in [(tmp_path / "labels", "a folder; give the labels file"),
                           (tmp_path / "labels" / "labels.json", "is not in the folder of"),
                           (tmp_path / "bad.json", "not JSON")]:
        assert main(["scene", "looming", str(tmp_path / "clip.avi"), "--labels",
                     str(labels)]) == 2
        assert reason in capsys.readouterr().err
        assert not (tmp_path / "clip.avi").exists()  # no clip left without its label


def test_label_flags_clips_asnn_eval_cannot_score_as_they_are(tmp_path, capsys):
    write_video(make_scene("looming", size=(64, 64), frames=3).frames[:, :30, :30],
                tmp_path / "tiny.avi")
    whole = tmp_path / "whole.avi"
    write_video(make_scene("looming", size=(64, 64), frames=40).frames, whole)
    data = whole.read_bytes()
    whole.unlink()
    (tmp_path / "cut.avi").write_bytes(data[:len(data) // 2])
    assert main(["label", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "tiny.avi: its 30x30 frames are smaller than the model's 31x31 kernels" in out
    assert "tiny.avi: 3 frames decoded: the scoring ignores the first 5" in out
    assert "cut.avi:" in out and "where the file states 40: it may be cut" in out


@pytest.mark.parametrize("text, says", [
    # named: a test's id made of its text (64 MiB) took seconds of pytest's own time
    pytest.param("[" * 100000 + "]" * 100000, "labels.json: not JSON (nested too deeply)",
                 id="nested-too-deeply"),
    pytest.param('[{"fps": ' + "9" * 5000 + "}]",
                 "labels.json: not JSON this reads (Exceeds the limit", id="a-5000-digit-number"),
    pytest.param(" " * (64 << 20) + "[]", "labels.json: larger than 64 MiB", id="64-MiB"),
    # accepted, then the evaluation stopped once it had run (NaN), or a rewrite lost a value
    ('[{"file": "a.mp4", "fps": 20.0, "note": NaN}]', "labels.json: NaN is not a JSON number"),
    ('[{"file": "a.mp4", "fps": 1e400}]', "labels.json: 1e400 is beyond a float's range"),
    ('[{"file": "a.mp4", "collision": true, "collision": false}]',
     "labels.json: an entry gives 'collision' twice"),
    ("[]", "labels.json: no clip labels in it"),
    ('{"clips": []}', "labels.json: no clip labels in it")])
def test_a_labels_file_nested_too_deeply_or_empty_is_one_error_line(tmp_path, capsys, text,
                                                                    says):
    (tmp_path / "labels.json").write_text(text)
    with pytest.raises(ValueError, match=re.escape(says)):
        load_labels(tmp_path / "labels.json")
    assert main(["eval", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0]
    if text.startswith("[["):  # asnn label reads it too (an empty list is a folder to start)
        assert main(["label", str(tmp_path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and says in err[0]


def test_a_center_outside_the_clips_own_frames_is_refused_before_anything_runs(tmp_path, capsys):
    # a portrait clip: its label's size swapped (width and height mixed up), or left out, must
    # not let a centre outside the frames through to the localisation scores
    scene = make_scene("looming", size=(48, 96), frames=24, start=4, stop=20)
    write_video(scene.frames, tmp_path / "tall.mp4", scene.fps)
    label = {**scene.label("tall.mp4"), "center": [70.0, 30.0]}
    out = tmp_path / "out"
    for entry in ({**label, "width": 96, "height": 48}, {k: v for k, v in label.items()
                                                         if k not in ("width", "height")}):
        (tmp_path / "labels.json").write_text(json.dumps([entry]))
        assert main(["eval", str(tmp_path), "--detectors", "lgmd2", "--out", str(out)]) == 2
        assert ("tall.mp4: center (70, 30) is outside its 48x96 frames"
                in capsys.readouterr().err)
        assert not out.exists()
        assert main(["label", str(tmp_path)]) == 1
        listed = capsys.readouterr().out
        assert "tall.mp4: center (70, 30) is outside its 48x96 frames" in listed
        if "width" in entry:
            assert "tall.mp4: its frames are 48x96 where its label says 96x48" in listed


def test_a_clip_whose_size_disagrees_with_its_label_is_named():
    assert mismatches({**COLLISION, "width": 64, "height": 48}, 60, 30.0, size=(64, 48)) == []
    assert mismatches(COLLISION, 60, 30.0, size=(64, 48)) == []  # no size to compare
    assert mismatches({**COLLISION, "width": 48, "height": 64}, 60, 30.0, size=(64, 48)) == [
        "c.mp4: its frames are 64x48 where its label says 48x64: its center and track may "
        "not be in the clip's pixels"]


def test_eval_names_unlabelled_videos_and_label_disagreements_on_the_terminal(tmp_path, capsys):
    # a video in the folder without an entry is not scored: said before anything runs, not
    # left for the reader to notice a clip short in the counts; a clip that disagrees with its
    # label is said on stderr too, not only at the end of report.md
    scene = make_scene("looming", size=(64, 64), frames=24, start=4, stop=20)
    write_video(scene.frames, tmp_path / "loom.mp4", scene.fps)
    write_video(scene.frames, tmp_path / "forgotten.mp4", scene.fps)
    (tmp_path / "labels.json").write_text(json.dumps(
        [{**scene.label("loom.mp4"), "fps": 2 * scene.fps}]))
    out = tmp_path / "out"
    assert main(["eval", str(tmp_path), "--detectors", "lgmd2", "--out", str(out),
                 "--no-plots"]) == 0
    err = capsys.readouterr().err
    assert ("asnn eval: 1 video in the folder has no label and is not scored (asnn label "
            f"{tmp_path} adds its entry): forgotten.mp4") in err
    assert f"loom.mp4: the clip runs at {scene.fps:g} fps where its label says" in err
    results = json.loads((out / "results.json").read_text())
    assert results["unlabelled"] == ["forgotten.mp4"]
    report = (out / "report.md").read_text()
    assert "Videos in the folder without a label (not scored): forgotten.mp4" in report


def test_clips_no_detector_can_be_scored_on_are_said_in_eval_and_held_out(tmp_path, capsys):
    """An evaluation review: a 3-frame clip scored 'quiet' (a correct rejection) and a hit
    window inside the warm-up, without a word; --held-out said nothing of a label's fps or
    frames that disagree with its clip, as the plain run does."""
    scene = make_scene("looming", size=(64, 64), frames=24, start=4, stop=20)
    write_video(scene.frames[:3], tmp_path / "tiny.mp4", scene.fps)
    write_video(scene.frames, tmp_path / "loom.mp4", scene.fps)
    labels = [{"file": "tiny.mp4", "fps": scene.fps, "collision": False},
              {"file": "loom.mp4", "fps": 2 * scene.fps, "collision": True, "onset_frame": 0,
               "contact_frame": 1}]
    (tmp_path / "labels.json").write_text(json.dumps(labels))
    assert main(["eval", str(tmp_path), "--detectors", "lgmd2", "--out", str(tmp_path / "a"),
                 "--no-plots"]) == 0
    err = capsys.readouterr().err
    said = ["tiny.mp4: 3 frames decoded: the scoring ignores the first 5, so nothing of it is "
            "scored",
            "loom.mp4: its hit window ends at frame 3, inside the first 5 frames the scoring "
            "ignores: no detector can hit it",
            f"loom.mp4: the clip runs at {scene.fps:g} fps where its label says"]
    assert all(line in err for line in said), err
    (tmp_path / "labels.json").write_text(json.dumps(labels[1:]))
    out = tmp_path / "b"
    assert main(["eval", str(tmp_path), "--held-out", "--cases", "nearmiss-disk-dark-right",
                 "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert all(line in err for line in said[1:]), err
    assert "one clip: its fold's thresholds are chosen on no clip" in err
    report = (out / "held_out.md").read_text()
    assert "Warnings (clips that disagree with their labels" in report and said[1] in report


def test_scored_records_say_collision_with_true_or_false(tmp_path):
    # "false" (a string) counted as a warning: asnn detect's output edited by hand, say
    path = tmp_path / "c.jsonl"
    for record, said in [({"frame": 3, "collision": "false"}, "collision must be true or false"),
                         ({"frame": "3", "collision": False}, "frame must be a whole number"),
                         ({"frame": 3.0}, "frame must be a whole number")]:
        path.write_text(json.dumps(record) + "\n")
        with pytest.raises(ValueError, match=said):
            scoring.load_records(path)
    path.write_text('{"frame": 3, "collision": true}\n{"frame": 4}\n')
    assert len(scoring.load_records(path)) == 2


def test_a_misspelt_clip_name_is_answered_with_the_unlabelled_video_it_likely_means(tmp_path,
                                                                                   capsys):
    scene = make_scene("looming", size=(64, 64), frames=24, start=4, stop=20)
    write_video(scene.frames, tmp_path / "loom25.mp4", scene.fps)
    (tmp_path / "labels.json").write_text(json.dumps([scene.label("loom_25.mp4")]))
    assert main(["eval", str(tmp_path), "--detectors", "lgmd2", "--out",
                 str(tmp_path / "out")]) == 2
    assert "loom_25.mp4: no such file (did you mean loom25.mp4?)" in capsys.readouterr().err
    (tmp_path / "labels.json").write_text(json.dumps([scene.label("loom_25.mp4")]))
    assert main(["label", str(tmp_path)]) == 1
    assert (f"loom_25.mp4: no such clip in {tmp_path} (did you mean loom25.mp4?)"
            in capsys.readouterr().out)


def test_a_labels_path_that_is_a_pipe_is_refused_not_read_without_end(tmp_path):
    import os

    from asnn.evaluation.labels import read_entries

    os.mkfifo(tmp_path / "labels.json")
    with pytest.raises(ValueError, match="labels.json: not a regular file"):
        read_entries(tmp_path / "labels.json")


def test_labels_are_written_whole_in_their_form_and_writers_at_once_keep_each_others(
        tmp_path, monkeypatch):
    """asnn label and asnn scene --labels rewrote an object-form labels.json as a bare list
    (its other fields lost), in place (a SIGKILL mid-write left 0 bytes), and four scenes
    entered at once kept three entries (a user trial)."""
    import json
    import os
    import threading

    from asnn.io import files
    from asnn.io.video import write_video
    from asnn.stimuli import make_scene

    folder = tmp_path / "clips"
    folder.mkdir()
    write_video(make_scene("looming", size=(64, 64), frames=8).frames, folder / "a.mp4", 20.0)
    labels = folder / "labels.json"
    labels.write_text(json.dumps({"version": 3, "author": "me", "clips": []}))
    main(["label", str(folder)])
    document = json.loads(labels.read_text())
    assert document["author"] == "me" and [e["file"] for e in document["clips"]] == ["a.mp4"]
    threads = [threading.Thread(target=main, args=(["scene", "looming", str(folder / f"s{i}.mp4"),
                                                    "--size", "64x64", "--labels", str(labels)],))
               for i in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    document = json.loads(labels.read_text())
    assert sorted(e["file"] for e in document["clips"]) == ["a.mp4", "s0.mp4", "s1.mp4",
                                                           "s2.mp4", "s3.mp4"]
    assert document["version"] == 3
    # a write that fails leaves the file as it was, and no temporary file; a link stays a link
    before = labels.read_text()
    monkeypatch.setattr(files.os, "replace", lambda *a: (_ for _ in ()).throw(OSError("full")))
    with pytest.raises(OSError):
        files.write_atomically(labels, "[]")
    monkeypatch.undo()
    assert labels.read_text() == before and sorted(os.listdir(folder)) == sorted(
        ["a.mp4", "labels.json", *(f"s{i}.mp4" for i in range(4))])
    link = tmp_path / "link.json"
    link.symlink_to(labels)
    files.write_atomically(link, "[]\n")
    assert link.is_symlink() and labels.read_text() == "[]\n"


def test_a_scene_is_named_from_the_labels_folder_given_and_replaces_its_own_entry(tmp_path):
    """scene --labels named the clip from a linked labels file's target folder (refused, or
    a name asnn label could not find), and added a second entry where one said ./s.mp4."""
    import json

    (tmp_path / "store").mkdir()
    (tmp_path / "clips").mkdir()
    (tmp_path / "store" / "real.json").write_text(
        '[{"file": "./s.mp4", "fps": 20.0, "collision": false}]')
    labels = tmp_path / "clips" / "labels.json"
    labels.symlink_to(tmp_path / "store" / "real.json")
    assert main(["scene", "looming", str(tmp_path / "clips" / "s.mp4"), "--size", "64x64",
                 "--labels", str(labels)]) == 0
    entries = json.loads(labels.read_text())
    assert [e["file"] for e in entries] == ["s.mp4"] and entries[0]["collision"] is True
    assert labels.is_symlink()


def test_a_bags_camera_written_into_the_file_is_named_as_with_its_topic():
    """``drive.mcap#/front/image`` in ``file`` (as the command line takes a camera) names its
    results as ``file: drive.mcap, topic: /front/image`` does: two cameras written so were
    refused as one name ("image"); a video with '#' in its name keeps its own."""
    from asnn.evaluation.labels import result_name

    base = {"fps": 20.0, "collision": False}
    assert result_name({**base, "file": "d/drive.mcap#/front/image"}) == \
        result_name({**base, "file": "d/drive.mcap", "topic": "/front/image"}) == \
        "drive.front_image"
    assert result_name({**base, "file": "rosbag2_run#/rear/image"}) == "rosbag2_run.rear_image"
    assert result_name({**base, "file": "clip#2.mp4"}) == "clip#2"
    # the bag's suffix in any case, as the command line takes it
    assert result_name({**base, "file": "d/DRIVE.MCAP#/front/image"}) == "DRIVE.front_image"
    labels = [{**base, "file": f"drive.mcap#/{side}/image"} for side in ("front", "rear")]
    assert len(check_labels(labels)) == 2
    # the topic given both ways, as a source takes it where they agree: one camera (it was named
    # after the topic's last part, and two bags' cameras collided)
    both = [{**base, "file": f"{bag}.mcap#/front/image", "topic": "/front/image"}
            for bag in ("a", "b")]
    assert [result_name(label) for label in both] == ["a.front_image", "b.front_image"]
    assert len(check_labels(both)) == 2


def test_every_video_kind_named_is_one_to_label_whatever_its_suffix_s_case(tmp_path, capsys):
    """The kinds added for a user trial (.y4m, .mxf, .vob and the raw streams): each is found
    by asnn label and eval, in either case, and a raw stream is named as one in any case."""
    import cv2

    from asnn.evaluation.labels import RAW_STREAM_SUFFIXES, VIDEO_SUFFIXES, unlabelled_videos

    assert set(RAW_STREAM_SUFFIXES) <= set(VIDEO_SUFFIXES)
    names = [f"clip{k}{suffix.upper() if k % 2 else suffix}" for k, suffix in enumerate(
        (".y4m", ".mxf", ".vob", *RAW_STREAM_SUFFIXES))]
    for name in names:
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "notes.txt").write_bytes(b"")
    assert unlabelled_videos(tmp_path, []) == sorted(names)
    # an upper-case raw stream (a camera's CAM.MJPG) is told to state its rate too
    folder = tmp_path / "camera"
    folder.mkdir()
    loom = make_scene("looming", size=(64, 48), frames=6, start=1, stop=5)
    (folder / "CAM.MJPG").write_bytes(b"".join(
        cv2.imencode(".jpg", frame)[1].tobytes() for frame in loom.frames))
    assert main(["label", str(folder)]) == 1
    assert "CAM.MJPG: a raw stream states no frame rate" in capsys.readouterr().out
