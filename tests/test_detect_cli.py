"""``asnn detect``: the JSONL contract of CONTRACT.md, outputs and errors."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from asnn.io.video import write_video
from asnn.stimuli import make_scene
from cli.main import main

FIELDS = {"frame": int, "t": float, "u": float, "out": float, "spikes": int,
          "spike_rate": float, "collision": bool, "targets": list}
TARGET_FIELDS = {"x": float, "y": float, "direction": float, "energy": float, "pixels": int}
# the default (tracked) preset's optional fields, docs/contract.md
TRACKED_FIELDS = {"id": int, "expansion": float, "ttc": float, "offset": float,
                  "approaching": bool}


@pytest.fixture(scope="module")
def looming_video(tmp_path_factory):
    scene = make_scene("looming", size=(96, 96), start=5, stop=30)
    path = tmp_path_factory.mktemp("clips") / "looming.avi"  # MJPG: decodable everywhere
    write_video(scene.frames, path, fps=20.0)
    return path, scene


def test_jsonl_has_one_object_per_frame_with_the_contract_fields(looming_video, capsys):
    path, scene = looming_video
    assert main(["detect", str(path), "--jsonl", "-"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(scene.frames)
    records = [json.loads(line) for line in lines]
    for i, rec in enumerate(records):
        assert set(rec) == set(FIELDS)
        for key, kind in FIELDS.items():
            assert isinstance(rec[key], kind) or (kind is float and isinstance(rec[key], int)), key
        assert rec["frame"] == i and rec["t"] == pytest.approx(i / 20.0)
        for target in rec["targets"]:
            assert set(target) == set(TARGET_FIELDS) | set(TRACKED_FIELDS)
            for key, kind in {**TARGET_FIELDS, **TRACKED_FIELDS}.items():
                assert isinstance(target[key], kind) or (kind is float and isinstance(
                    target[key], int)), key
            assert 0 <= target["x"] < 96 and 0 <= target["y"] < 96
            # the default reports the approaching objects: growing, with a time to contact
            assert target["approaching"] and target["expansion"] > 0 and target["ttc"] > 0
    warned = [r for r in records if r["collision"]]
    assert warned and any(r["targets"] for r in warned)
    assert all(r["frame"] >= scene.onset_frame for r in warned)


def test_a_slow_video_gets_a_note_on_stderr_and_a_fast_one_none(looming_video, tmp_path,
                                                                  capsys):
    path, scene = looming_video
    assert main(["detect", str(path), "--jsonl", str(tmp_path / "fast.jsonl")]) == 0
    assert "frames a second" not in capsys.readouterr().err
    slow = tmp_path / "slow.avi"
    write_video(scene.frames, slow, fps=10.0)
    assert main(["detect", str(slow), "--jsonl", "-"]) == 0
    captured = capsys.readouterr()
    assert "runs at 10 frames a second" in captured.err and "below 18" in captured.err
    assert len(captured.out.splitlines()) == len(scene.frames)  # stdout stays JSON


def test_a_video_stating_a_rate_no_camera_runs_at_is_timed_at_20_fps_with_a_note(
        looming_video, tmp_path, capsys):
    from asnn.io.sources import open_source

    path, scene = looming_video
    assert open_source(str(path)).fps_stated
    base = tmp_path / "base.avi"  # a container's time base read as its frame rate
    write_video(scene.frames, base, fps=500.0)
    source = open_source(str(base))
    assert (source.fps, source.fps_stated) == (20.0, False)
    assert main(["detect", str(base), "--jsonl", "-"]) == 0
    captured = capsys.readouterr()
    # what the file states, and the rates taken: it said the file "states no frame rate"
    assert f"{base} states 500 frames a second, more than a camera runs at (a stated rate is " \
           "taken up to 240); its frames are timed at 20 a second" in captured.err
    records = [json.loads(line) for line in captured.out.splitlines()]
    assert [r["t"] for r in records[:3]] == [0.0, 0.05, 0.1]


def test_a_preset_with_a_field_changed_runs_as_the_python_model_does(looming_video, capsys):
    from asnn import ASNN
    from asnn.io.sources import open_source
    from asnn.params import preset

    path, scene = looming_video
    assert main(["detect", str(path), "--preset", "robust/top_k=0/u_scale=1000",
                 "--jsonl", "-"]) == 0
    out = [json.loads(line)["u"] for line in capsys.readouterr().out.splitlines()]
    model = ASNN(preset("robust", top_k=0, u_scale=1000))
    assert out == [model.step(f, t).u for t, f in open_source(str(path)).timed_frames()]
    assert out != [r["u"] for r in map(json.loads, _detect_lines(path, capsys))]
    with pytest.raises(SystemExit):
        main(["detect", str(path), "--preset", "robust/nope=1"])
    assert "argument --preset: 'robust/nope=1': nope: Extra inputs" in capsys.readouterr().err


def _detect_lines(path, capsys) -> list[str]:
    assert main(["detect", str(path), "--jsonl", "-"]) == 0
    return capsys.readouterr().out.splitlines()


def test_lgmd_models_are_selectable_and_report_no_targets(looming_video, capsys):
    path, scene = looming_video
    assert main(["detect", str(path), "--model", "lgmd2", "--jsonl", "-"]) == 0
    records = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert len(records) == len(scene.frames)
    assert all(r["targets"] == [] for r in records)
    # a preset is the ASNN model's: given with an LGMD model it was ignored without a word
    for spec in ("robust", "default"):  # the default's name too: it was taken for no --preset
        assert main(["detect", str(path), "--model", "lgmd1", "--preset", spec]) == 2
        assert "--preset applies to the ASNN model only" in capsys.readouterr().err
    # and so are its threads: an LGMD model steps on the main thread whatever --threads says
    for model in ("lgmd1", "lgmd2"):
        assert main(["detect", str(path), "--model", model, "--threads", "4"]) == 2
        assert capsys.readouterr().err.strip() == \
            f"asnn detect: --threads applies to the ASNN model only, not {model}"


def test_a_camera_given_an_empty_source_is_refused_before_it_starts(capsys):
    with pytest.raises(SystemExit):  # it read '' as the current folder
        main(["camera", "--robot", "r1", "--source", ""])
    assert "argument --source: an empty path" in capsys.readouterr().err


TRACK_FIELDS = {"id", "object_id", "x", "y", "size", "box", "expansion", "ttc", "offset", "fit",
                "own_expansion", "layers", "streak", "test", "counts", "share"}
TEST_FIELDS = {"seen", "course", "overlap", "scene", "layers", "passes"}


@pytest.mark.parametrize("threads", ["1", "2"])
def test_tracks_file_gives_every_object_with_its_approach_test(looming_video, tmp_path, threads):
    path, scene = looming_video
    jsonl, tracks = tmp_path / "out.jsonl", tmp_path / "tracks.jsonl"
    assert main(["detect", str(path), "--jsonl", str(jsonl), "--tracks", str(tracks),
                 "--threads", threads]) == 0
    records = [json.loads(line) for line in jsonl.read_text().splitlines()]
    traced = [json.loads(line) for line in tracks.read_text().splitlines()]
    assert [(t["frame"], t["t"], t["collision"]) for t in traced] == [
        (r["frame"], r["t"], r["collision"]) for r in records]
    for record, frame in zip(records, traced):
        for track in frame["tracks"]:
            assert set(track) == TRACK_FIELDS and set(track["test"]) == TEST_FIELDS
        # the warning's targets are the objects that count, and only they
        counting = [t for t in frame["tracks"] if t["counts"]]
        assert {t["object_id"] for t in counting} == {t["id"] for t in record["targets"]}
        assert all(t["test"]["passes"] for t in counting)
    assert sum(1 for f in traced for t in f["tracks"] if t["counts"]) >= 10
    # the same with any number of model threads
    if threads == "2":
        single = tmp_path / "single.jsonl"
        assert main(["detect", str(path), "--tracks", str(single), "--threads", "1"]) == 0
        assert single.read_text() == tracks.read_text()


@pytest.mark.parametrize("extra", [["--preset", "reference"], ["--model", "lgmd1"],
                                   ["--jsonl", "-"]])
def test_tracks_that_cannot_be_written_are_one_error_line(looming_video, capsys, extra):
    path, _ = looming_video
    assert main(["detect", str(path), "--tracks", "-", *extra]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1
    assert "--tracks" in captured.err


def test_annotate_and_plot_write_files(looming_video, tmp_path):
    path, scene = looming_video
    video, plot = tmp_path / "ann.mp4", tmp_path / "plot.png"
    assert main(["detect", str(path), "--annotate", str(video), "--plot", str(plot)]) == 0
    import cv2

    cap = cv2.VideoCapture(str(video))
    count = 0
    while cap.read()[0]:
        count += 1
    assert count == len(scene.frames)
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("content", [None, b"not a video at all\n" * 20, "folder"])
def test_missing_or_undecodable_file_exits_2_with_one_line(tmp_path, content):
    path = tmp_path / "clip.mp4"
    if content == "folder":
        path.mkdir()
    elif content is not None:
        path.write_bytes(content)
    proc = subprocess.run([sys.executable, "-m", "cli.main", "detect", str(path), "--jsonl", "-"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert len(proc.stderr.strip().splitlines()) == 1 and str(path) in proc.stderr


def test_a_video_with_no_frame_is_told_from_a_file_that_is_not_one(tmp_path):
    """A container OpenCV opens that holds no frame (an empty AVI) was "not a video OpenCV can
    decode", as a file of junk is (an own-data user trial)."""
    import cv2

    from asnn.io.video import VideoClip, VideoError

    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"not a video at all\n" * 20)
    # an empty MP4 or MKV does not even open in OpenCV: told by its first bytes (a review)
    for name, fourcc in (("empty.avi", "MJPG"), ("empty.mp4", "mp4v"), ("empty.mkv", "MJPG")):
        empty = tmp_path / name
        cv2.VideoWriter(str(empty), cv2.VideoWriter_fourcc(*fourcc), 20, (64, 48)).release()
        with pytest.raises(VideoError, match="a video without a frame OpenCV can decode"):
            VideoClip(empty)
    with pytest.raises(VideoError, match="not a video OpenCV can decode"):
        VideoClip(junk)


@pytest.mark.parametrize("what", ["--jsonl", "--tracks"])
def test_a_reader_that_stops_early_ends_detect_quietly(tmp_path, what):
    """``asnn detect VIDEO --jsonl - | head -1``: no traceback, the status of SIGPIPE."""
    path = tmp_path / "long.avi"  # its records fill the pipe, so detect is still writing
    write_video(np.tile(make_scene("looming", size=(64, 64)).frames, (25, 1, 1)), path)
    proc = subprocess.Popen([sys.executable, "-m", "cli.main", "detect", str(path), what, "-"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = proc.stdout.readline()
    proc.stdout.close()  # as head does after its line
    assert proc.wait(timeout=120) == 141
    assert json.loads(first)["frame"] == 0
    assert proc.stderr.read() == b""  # no traceback, no second complaint at exit


@pytest.mark.parametrize("flag, path, says", [
    ("--jsonl", "{tmp}/a-file/a.jsonl", "a-file is not a folder"),
    ("--tracks", "{tmp}", "is a folder"),
    ("--plot", "{tmp}/p.notanimage", "name the format by its extension"),
    ("--plot", "{tmp}", "is a folder"),
    ("--annotate", "{tmp}/a-file/more/a.mp4", "a-file is not a folder"),
    ("--jsonl", "/dev/full", "No space left on device"),  # found while writing
    # names longer than a file system takes: Path.is_dir raised for them (a traceback)
    pytest.param("--jsonl", "{tmp}/" + "a" * 300 + ".jsonl", "File name too long",
                 id="jsonl-name-too-long"),
    pytest.param("--annotate", "{tmp}/" + "a" * 300 + "/a.mp4", "File name too long",
                 id="annotate-folder-name-too-long"),
])
def test_an_output_that_cannot_be_written_is_a_one_line_error(looming_video, tmp_path, capsys,
                                                              flag, path, says):
    if path == "/dev/full" and not Path(path).exists():
        pytest.skip("no /dev/full here")
    video, _ = looming_video
    (tmp_path / "a-file").write_text("")  # where a folder would have to be made
    assert main(["detect", str(video), flag, path.format(tmp=tmp_path)]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize("flag", ["--jsonl", "--tracks"])
def test_a_short_runs_output_on_a_full_disk_is_a_one_line_error(tmp_path, capsys, flag):
    """A probe: a run short enough for its lines to stay buffered met the full disk when the
    file was closed, after every handler: a traceback, exit 1."""
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full here")
    video = write_video(make_scene("looming", size=(64, 48), frames=4).frames,
                        tmp_path / "short.avi")
    assert main(["detect", str(video), flag, "/dev/full", "--threads", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"asnn detect: {flag} /dev/full: cannot write: No space left on device"]


def test_an_output_folder_that_cannot_be_made_is_refused_before_the_run(looming_video, tmp_path,
                                                                        capsys, monkeypatch):
    # the tests run as root, who may write anywhere: the folder's refusal is simulated
    import os

    video, _ = looming_video
    locked = tmp_path / "locked"
    locked.mkdir()
    access = os.access
    monkeypatch.setattr(os, "access", lambda path, mode: Path(path) != locked
                        and access(path, mode))
    out = locked / "new" / "out.jsonl"
    assert main(["detect", str(video), "--jsonl", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"cannot make {out.parent} in {locked} (no write access)" in err[0]
    assert list(locked.iterdir()) == []  # refused before anything was made


@pytest.mark.parametrize("flag, path", [
    ("--annotate", "/proc/self/a.mp4"), ("--plot", "/proc/self/a.png"),
    ("--mcap", "/proc/self/a.mcap"), ("--jsonl", "/proc/asnn-none/a.jsonl")])
def test_an_output_no_file_can_be_made_for_is_refused_before_the_run(looming_video, capsys,
                                                                     flag, path):
    """Permissions do not tell it (root may write anywhere by them; /proc takes no new file
    whatever they say): --annotate, --plot and --mcap failed at their first frame or at the end
    of the run, and a folder that could not be made once the kernels had compiled, without
    naming the option or why."""
    if not Path("/proc/self").is_dir():
        pytest.skip("no /proc here")
    video, _ = looming_video
    assert main(["detect", str(video), flag, path]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"asnn detect: {flag} {path}: cannot "), err


@pytest.mark.parametrize("flag", ["--jsonl", "--tracks"])
def test_an_existing_output_in_a_folder_that_takes_no_new_file_is_written(looming_video,
                                                                          tmp_path, capsys,
                                                                          flag):
    """A review's trial: trying the output's folder with a new file there refused
    ``--jsonl /proc/self/fd/N`` (and, for a user not root, ``/dev/null`` and a file of one's own
    in a read-only folder), which an existing file, written where it is, does not need."""
    if not Path("/proc/self/fd").is_dir():
        pytest.skip("no /proc here")
    video, scene = looming_video
    with open(tmp_path / "out.jsonl", "w") as held:
        assert main(["detect", str(video), flag, f"/proc/self/fd/{held.fileno()}"]) == 0, \
            capsys.readouterr().err
    lines = (tmp_path / "out.jsonl").read_text().splitlines()
    assert lines and all(json.loads(line) for line in lines)
    if flag == "--jsonl":
        assert len(lines) == len(scene.frames)


@pytest.mark.parametrize("flag", ["--jsonl", "--tracks"])
def test_a_named_pipe_output_is_not_opened_by_the_check(tmp_path, flag):
    """A review's trial: ``mkfifo p; cat p & asnn detect clip --jsonl p``: the check opened
    the pipe (waiting for its reader) and closed it, which ended cat's input, and the run then
    waited for ever, SIGTERM or not, for a reader at its first line."""
    import os
    import threading

    from cli.detect import _output_problem

    pipe = tmp_path / "p"
    os.mkfifo(pipe)
    found = []
    check = threading.Thread(target=lambda: found.append(_output_problem(str(pipe), flag)),
                             daemon=True)
    check.start()
    check.join(timeout=10)
    if check.is_alive():  # the check opened it: a reader lets it go
        os.close(os.open(pipe, os.O_RDONLY | os.O_NONBLOCK))
        check.join(timeout=10)
        pytest.fail("the check opened the named pipe, and waited for a reader")
    assert found == [None]


def test_outputs_in_folders_that_do_not_exist_yet_are_written_there(looming_video, tmp_path,
                                                                     capsys):
    """As ``asnn scene OUT`` does, detect makes the folders its outputs go into."""
    pytest.importorskip("mcap_ros2", reason="--mcap needs the 'ros' extra")
    video, scene = looming_video
    outputs = {"--jsonl": "a/b/out.jsonl", "--tracks": "t/tracks.jsonl",
               "--annotate": "v/w/out.mp4", "--plot": "p/out.png", "--mcap": "m/out.mcap"}
    args = [arg for flag, name in outputs.items() for arg in (flag, str(tmp_path / name))]
    assert main(["detect", str(video), *args]) == 0, capsys.readouterr().err
    for name in outputs.values():
        assert (tmp_path / name).stat().st_size > 0, name
    records = (tmp_path / "a/b/out.jsonl").read_text().splitlines()
    assert len(records) == len(scene.frames)


def test_an_output_folder_is_made_only_once_the_input_opens(tmp_path, capsys):
    assert main(["detect", str(tmp_path / "none.avi"), "--jsonl",
                 str(tmp_path / "new" / "out.jsonl")]) == 2
    assert "none.avi" in capsys.readouterr().err and not (tmp_path / "new").exists()


@pytest.mark.parametrize("flag", ["--jsonl", "--tracks"])
def test_a_run_refused_at_start_leaves_no_new_output_file(tmp_path, capsys, flag):
    # the check of the path made the file, and a run refused after it left it there, empty
    out = tmp_path / "out.jsonl"
    assert main(["detect", str(tmp_path / "none.avi"), flag, str(out)]) == 2
    assert "none.avi" in capsys.readouterr().err and not out.exists()


def test_an_output_over_the_input_or_another_output_is_refused_before_it_is_opened(
        looming_video, tmp_path, capsys):
    video, _ = looming_video
    copy = tmp_path / "clip.avi"
    copy.write_bytes(Path(video).read_bytes())
    before = copy.read_bytes()
    link = tmp_path / "link.avi"
    os.link(copy, link)
    for args, says in [(["--annotate", str(copy)], f"--annotate {copy}: is the input"),
                       (["--jsonl", str(link)], "is the input"),  # the same file by another name
                       (["--jsonl", str(tmp_path / "a"), "--tracks", str(tmp_path / "a")],
                        "--tracks and --jsonl both write"),
                       # a hard link to another output: the two interleaved, exit 0
                       (["--jsonl", str(tmp_path / "b"), "--tracks", str(tmp_path / "b2")],
                        "--tracks and --jsonl both write"),
                       # - is standard output, for the JSON lines: these wrote a file named -
                       # (or -.png), or failed once the run had truncated the other outputs
                       (["--mcap", "-"], "--mcap -: writes a file"),
                       (["--plot", "-"], "--plot -: writes a file"),
                       (["--jsonl", str(tmp_path / "keep"), "--annotate", "-"],
                        "--annotate -: writes a file")]:
        (tmp_path / "b").write_text("")
        if not (tmp_path / "b2").exists():
            os.link(tmp_path / "b", tmp_path / "b2")
        (tmp_path / "keep").write_text("mine")
        assert main(["detect", str(copy), *args]) == 2
        assert says in capsys.readouterr().err
        assert (tmp_path / "keep").read_text() == "mine"
    assert copy.read_bytes() == before  # the recording is intact


@pytest.mark.parametrize("listed", ["link", "outside"])
def test_an_output_over_a_file_of_the_input_bag_is_refused_wherever_the_file_lies(
        tmp_path, capsys, listed):
    """An integrator's trial: a bag folder whose metadata.yaml lists a file by a link, or by
    a path out of the folder, had that recording overwritten by --jsonl naming it (exit 0)."""
    from asnn.io.rosbag import write_bag

    store, bag = tmp_path / "store", tmp_path / "bag"
    store.mkdir(), bag.mkdir()
    part = write_bag(make_scene("looming", size=(64, 64), frames=12).frames,
                     store / "rec_0.mcap")
    if listed == "link":
        (bag / "rec_0.mcap").symlink_to(part)
    name = "rec_0.mcap" if listed == "link" else "../store/rec_0.mcap"
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  storage_identifier: "
                                       f"mcap\n  relative_file_paths:\n    - {name}\n")
    before = part.read_bytes()
    for flag in ("--jsonl", "--mcap"):
        assert main(["detect", str(bag), flag, str(part)]) == 2
        assert f"{flag} {part}: is " in capsys.readouterr().err
    assert part.read_bytes() == before
    assert main(["detect", str(bag), "--jsonl", str(tmp_path / "out.jsonl")]) == 0
    # an output not yet made (--mcap is not created before the run) is no file of the bag
    assert main(["detect", str(bag), "--mcap", str(tmp_path / "out.mcap")]) == 0


def test_a_clip_cut_partway_is_run_as_far_as_it_decodes_with_a_note(tmp_path, capsys):
    whole = tmp_path / "whole.avi"
    write_video(make_scene("looming", size=(64, 64), frames=40).frames, whole)
    cut = tmp_path / "cut.avi"
    cut.write_bytes(whole.read_bytes()[:whole.stat().st_size // 2])
    assert main(["detect", str(whole)]) == 0
    assert "note" not in capsys.readouterr().err
    assert main(["detect", str(cut)]) == 0  # what decodes is the clip's result
    err = capsys.readouterr().err
    assert "frames decoded where the file states 40: it may be cut or damaged partway" in err


@pytest.mark.parametrize("threads", [None, "1", "2", "3"])
def test_output_equals_one_loop_over_the_frames(looming_video, tmp_path, threads):
    """The model's threads, and decoding ahead and writing behind on threads of their own (with
    fewer model threads than cores), change nothing: the records are those of a plain loop over
    the same frames, in order."""
    import cv2

    from asnn.evaluation.runs import run_detector
    from asnn.io.sources import open_source

    path, _ = looming_video
    out = tmp_path / "out.jsonl"
    cv_threads = cv2.getNumThreads()
    assert main(["detect", str(path), "--jsonl", str(out)]
                + (["--threads", threads] if threads else [])) == 0
    assert cv2.getNumThreads() == cv_threads  # the process's settings are restored
    got = [json.loads(line) for line in out.read_text().splitlines()]
    expected = json.loads(json.dumps(run_detector(open_source(str(path)).timed_frames())))
    assert got == expected


def test_read_ahead_keeps_order_and_raises_where_the_source_failed():
    import threading

    from asnn.io.pipeline import read_ahead

    def items():
        yield from range(5)
        raise OSError("cut")

    got = []
    with pytest.raises(OSError, match="cut"):
        for item in read_ahead(items(), depth=2):
            got.append(item)
    assert got == [0, 1, 2, 3, 4]
    # a consumer that stops early stops the reading thread
    before = threading.active_count()
    for item in read_ahead(iter(range(10**9)), depth=2):
        if item == 3:
            break
    assert threading.active_count() == before
    with pytest.raises(ValueError):
        next(read_ahead([], depth=0))


def test_write_behind_writes_in_order_and_reports_a_failed_write():
    import time

    from asnn.io.pipeline import WriteBehind

    written = []

    def slow(item):
        time.sleep(0.001)
        written.append(item)

    with WriteBehind(slow, depth=2) as out:
        for i in range(50):
            out.put(i)
    assert written == list(range(50))

    def fails_at_3(item):
        if item == 3:
            raise OSError("disk full")
        written.append(item)

    written.clear()
    out = WriteBehind(fails_at_3, depth=1)
    with pytest.raises(OSError, match="disk full"):
        for i in range(1000):  # put() raises once the writer has failed
            out.put(i)
        out.close()
    assert written == [0, 1, 2]
    with pytest.raises(OSError, match="disk full"):
        out.close()


@pytest.mark.parametrize("threads", ["1", "2"])
def test_an_annotated_video_that_cannot_be_written_is_one_error_line(looming_video, tmp_path,
                                                                     capsys, threads):
    path, _ = looming_video
    target = tmp_path / "ann.txt"  # a folder that is there, a container OpenCV cannot write
    assert main(["detect", str(path), "--annotate", str(target), "--threads", threads]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"asnn detect: --annotate {target}: name the format by its extension "
                   "(.avi, .m4v, .mkv, .mov, .mp4)"]


def test_wide_vectors_only_where_the_processor_has_them():
    from cli.main import wide_vector_features

    host = "+64bit,+avx,+avx2,+avx512f,+fma"
    assert wide_vector_features(host) == host + ",-prefer-256-bit"
    assert wide_vector_features("+64bit,+avx,+avx2,-avx512f,+fma") is None
    assert wide_vector_features("+64bit,+avx,+avx2,+avx512fp16") is None


def test_the_detect_process_equals_a_loop_in_this_process(looming_video):
    """``asnn detect`` as its own process has numba use 512-bit vectors where the processor
    has them (this process: the default width); its records are still those of the loop."""
    from asnn.evaluation.runs import run_detector
    from asnn.io.sources import open_source

    path, _ = looming_video
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CPU_FEATURES"}
    proc = subprocess.run([sys.executable, "-m", "cli.main", "detect", str(path), "--jsonl", "-"],
                          capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stderr
    got = [json.loads(line) for line in proc.stdout.splitlines()]
    expected = json.loads(json.dumps(run_detector(open_source(str(path)).timed_frames())))
    assert any(record["targets"] for record in expected)
    assert got == expected


class _WriterThatStops:
    """An OpenCV video writer that stops writing after ``keep`` frames with no error, as
    OpenCV's own does when the disk fills (its ``write`` returns None whatever happens)."""

    def __init__(self, real, keep: int):
        self._real, self._keep = real, keep

    def __getattr__(self, name):
        return getattr(self._real, name)

    def write(self, image) -> None:
        if self._keep > 0:
            self._keep -= 1
            self._real.write(image)


@pytest.mark.parametrize("threads", ["1", "2"])
def test_an_annotated_video_that_loses_frames_is_one_error_line(looming_video, tmp_path,
                                                                capsys, monkeypatch, threads):
    import cv2

    import asnn.io.video

    real = cv2.VideoWriter
    monkeypatch.setattr(asnn.io.video.cv2, "VideoWriter",
                        lambda *args, **kwargs: _WriterThatStops(real(*args, **kwargs), keep=3))
    path, scene = looming_video
    target = tmp_path / "ann.mp4"
    assert main(["detect", str(path), "--annotate", str(target), "--threads", threads]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"asnn detect: cannot write {target}: the video written holds 3 of "
                   f"{len(scene.frames)} frames"]


def test_a_written_video_is_checked_by_reading_it_back(looming_video, tmp_path):
    from asnn.io.video import VideoError, check_written

    path, scene = looming_video
    check_written(path, len(scene.frames))  # whole
    n = len(scene.frames)
    with pytest.raises(VideoError, match=f"holds {n} of {n + 1} frames"):
        check_written(path, n + 1)
    cut = tmp_path / "cut.mp4"  # an MP4 whose index, written last, did not fit
    write_video(scene.frames, cut)
    cut.write_bytes(cut.read_bytes()[:-200])
    with pytest.raises(VideoError, match=f"cannot write {cut}: the video written does not open"):
        check_written(cut, len(scene.frames))


@pytest.mark.parametrize("value, says", [("99999", "must be at most 256"),
                                         ("0", "must be at least 1")])
def test_threads_are_bounded(looming_video, capsys, value, says):
    path, _ = looming_video  # 99999 could not be started, 3000 stalled the machine
    with pytest.raises(SystemExit) as exit_:
        main(["detect", str(path), "--threads", value])
    assert exit_.value.code == 2 and f"argument --threads: {says}" in capsys.readouterr().err


@pytest.mark.parametrize("args, says", [
    (["{video}", "--jsonl", ""], "argument --jsonl: an empty path"),  # was ignored
    (["{video}", "--annotate", ""], "argument --annotate: an empty path"),
    ([""], "argument VIDEO: an empty path")])  # was '.: is a folder'
def test_an_empty_path_is_refused(looming_video, capsys, args, says):
    video, _ = looming_video
    with pytest.raises(SystemExit) as exit_:
        main(["detect", *(a.format(video=video) for a in args)])
    assert exit_.value.code == 2 and says in capsys.readouterr().err


def test_perturb_runs_on_the_frames_as_another_camera_would_give_them(tmp_path, capsys):
    # an off-centre approach: mirrored, its targets come out mirrored, frame for frame
    scene = make_scene("looming", size=(96, 96), start=5, stop=30, center=(30.0, 40.0))
    path = tmp_path / "left.avi"
    write_video(scene.frames, path, fps=20.0)
    plain = [json.loads(x) for x in _detect_lines(path, capsys)]
    assert main(["detect", str(path), "--jsonl", "-", "--perturb", "mirror"]) == 0
    out = capsys.readouterr()
    mirrored = [json.loads(x) for x in out.out.splitlines()]
    assert "on frames perturbed: every frame flipped left to right" in out.err
    assert len(mirrored) == len(plain) == len(scene.frames)
    assert [r["collision"] for r in mirrored] == [r["collision"] for r in plain]
    both = [(a["targets"], b["targets"]) for a, b in zip(plain, mirrored) if a["targets"]]
    assert both and all(len(a) == len(b) for a, b in both)
    for a, b in both:
        assert b[0]["x"] == pytest.approx(95 - a[0]["x"], abs=0.5)
        assert b[0]["y"] == pytest.approx(a[0]["y"], abs=0.5)
    # a family's member with its strength: the frames change, so do the numbers
    assert main(["detect", str(path), "--jsonl", "-", "--perturb", "gain0.5"]) == 0
    darker = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert len(darker) == len(plain) and [r["u"] for r in darker] != [r["u"] for r in plain]


@pytest.mark.parametrize("name", ["half-rate", "half-size", "double-size", "jpeg0", "blur"])
def test_perturb_refuses_what_would_change_the_frames_number_or_size(looming_video, capsys,
                                                                      name):
    path, _ = looming_video
    with pytest.raises(SystemExit) as exit_:
        main(["detect", str(path), "--perturb", name])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "argument --perturb" in err
    if name in ("half-rate", "half-size", "double-size"):
        assert "changes the frames' number or size" in err
        assert "asnn detect takes those that keep every frame (noise, jpeg, jpeg90," in err
    else:  # what it may be instead: only those asnn detect takes
        assert "unknown perturbation" in err and "noise, jpeg, jpeg90," in err
        assert not any(n in err for n in ("half-rate", "half-size", "double-size"))


def _shown_numbers(text: str) -> dict[str, str]:
    """``"key": number`` pairs of a JSON line as written (top level and first target)."""
    import re

    return dict(re.findall(r'"(\w+)": (-?[\d.]+(?:e-?\d+)?)', text))


def test_readmes_offline_examples_are_what_the_commands_print(tmp_path, monkeypatch, capsys):
    """README's looming and translating-bar transcripts, rerun: the warning counts, and every
    number shown, to the digits shown (README rounds them)."""
    import re

    readme = (Path(__file__).parents[1] / "README.md").read_text(encoding="utf-8")
    start = readme.index("On the generated looming clip")
    blocks = re.findall(r"```text\n(.*?)```", readme[start:], re.S)[:2]
    monkeypatch.chdir(tmp_path)
    for block in blocks:
        lines = block.splitlines()
        commands = [line[2:] for line in lines if line.startswith("$ ")]
        printed = []
        for command in commands:
            for part in command.split(" && "):
                words = part.split(" | ")[0].split()
                if words[0] == "asnn":
                    assert main(words[1:]) == 0, part
                    out = capsys.readouterr()
                    printed += out.err.splitlines() + out.out.splitlines()
                else:  # sed -n 'Np;Mp' FILE: the lines asked for (a pipe into sed: all)
                    rows = [int(n) for n in re.findall(r"(\d+)p", part)]
                    records = Path(words[-1]).read_text().splitlines()
                    printed += [records[n - 1] for n in rows]
        for expected in (line for line in lines if not line.startswith("$ ")):
            if not expected.startswith("{"):
                assert expected in printed, expected
                continue
            frame = json.loads(expected)["frame"]
            actual = next(line for line in printed if line.startswith(f'{{"frame": {frame},'))
            got = _shown_numbers(actual)
            for key, shown in _shown_numbers(expected).items():
                digits = len(shown.split(".")[1]) if "." in shown and "e" not in shown else 0
                tolerance = 0.5 * 10.0 ** -digits if "e" not in shown else abs(float(shown)) / 10
                assert abs(float(got[key]) - float(shown)) <= tolerance * 1.0001, \
                    (frame, key, shown, got[key])


@pytest.mark.parametrize("argv", [["detect", "clip.mp4", "--threads", "257"], ["detect"],
                                  ["camera", "--robot", "r1", "--source", "x", "--fps", "0"],
                                  ["eval", "--jobs", "0"], ["bogus"]])
def test_a_command_line_error_is_one_line(argv, capsys):
    """README: an option out of its range (or missing) is a one-line error and exit status 2,
    as a missing file is; argparse's usage block would come first."""
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("asnn") and "--help" in err, err


def test_frames_larger_than_the_wire_takes_are_refused_in_a_file_and_a_live_capture(
        tmp_path, capsys):
    """An 8192x8192 clip took 6.5 GB in asnn detect, and asnn camera died on it with a
    traceback: video frames are bounded as the wire's and the bags' are (4096 a side)."""
    import cv2

    from asnn.io.video import VideoError, read_frames

    path = tmp_path / "wide.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 20, (4100, 32))
    for _ in range(2):
        writer.write(np.zeros((32, 4100, 3), np.uint8))
    writer.release()
    assert main(["detect", str(path)]) == 2
    assert "frames of 4100x32; at most 4096 px a side" in capsys.readouterr().err

    class Capture:  # a live source whose second frame is too large
        frames = [np.zeros((8, 8, 3), np.uint8), np.zeros((8, 5000, 3), np.uint8)]

        def read(self):
            return True, self.frames.pop(0)

        def release(self):
            pass

    frames = read_frames(Capture(), "cam0")
    assert next(frames).shape == (8, 8, 3)
    with pytest.raises(VideoError, match="cam0: frames of 5000x8"):
        next(frames)


@pytest.mark.parametrize("argv, says", [
    (["status", "--timeout", "1e20"], "argument --timeout: must lie in (0, 1e+06] seconds"),
    (["worker", "--handover-timeout", "1e20"], "must lie in [0, 1e+06] seconds"),
    (["camera", "--robot", "r1", "--source", "x", "--wait", "1e10"], "must lie in [0, 1e+06]"),
    (["dashboard", "--stale-after", "0"], "must lie in (0, 1e+06] seconds")])
def test_durations_are_bounded_where_waits_would_overflow(argv, says, capsys):
    """Python's waits overflow past 9.2e9 s, and Zenoh took a 1e20 s query timeout for a
    negative one (a traceback in asnn status): every duration given by hand is bounded."""
    with pytest.raises(SystemExit):
        main(argv)
    assert says in capsys.readouterr().err


def test_a_pipe_given_as_a_video_is_named_as_such(tmp_path, capsys):
    fifo = tmp_path / "clip.mp4"
    os.mkfifo(fifo)  # was "no such file": it is there, and reading it would block
    assert main(["detect", str(fifo)]) == 2
    assert "clip.mp4: not a regular file (a pipe or a device)" in capsys.readouterr().err


@pytest.mark.parametrize("fps, apart", [(0.5, True), (10.0, False)])
def test_a_slow_clip_is_noted_and_one_whose_frames_the_model_times_by_default_says_so(
        tmp_path, capsys, fps, apart):
    """Frames more than 1 s apart are timed by the model at its nominal 0.05 s (a stalled
    clock looks the same): its times to contact would read 40 times short without a word."""
    import cv2

    path = tmp_path / "slow.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (64, 64))
    for _ in range(3):
        writer.write(np.full((64, 64, 3), 100, np.uint8))
    writer.release()
    assert main(["detect", str(path)]) == 0
    err = capsys.readouterr().err
    assert f"runs at {fps:g} frames a second; ASNN loses hits below 18" in err
    assert ("frames are more than 1 s apart, so the targets' expansion and ttc are computed "
            "for 0.05 s a frame" in err) == apart


def test_a_file_name_that_is_not_utf8_is_refused_where_opencv_would_crash(tmp_path, capsys):
    """OpenCV 5 crashes (SIGSEGV) on a path holding bytes of another encoding: asnn label,
    scene and detect died with status 139 on such a name (a user trial)."""
    from asnn.io.video import VideoError, open_video

    name = os.fsdecode(b"x\xff.mp4")
    assert main(["scene", "looming", str(tmp_path / name)]) == 2
    assert "is not UTF-8 text" in capsys.readouterr().err
    (tmp_path / name).write_bytes(b"\0" * 10)
    with pytest.raises(VideoError, match="a file name that is not UTF-8"):
        open_video(tmp_path / name)


def test_a_closed_or_full_standard_output_is_one_error_line_not_lost_output(tmp_path):
    """A CLI trial: with stdout closed (>&-) asnn detect --jsonl - wrote nothing and exited 0;
    to a full disk asnn status, bench --json and label printed a traceback."""
    root = Path(__file__).resolve().parents[1]
    command = [sys.executable, "-m", "cli.main", "label", str(tmp_path)]
    closed = subprocess.run(command, cwd=root, capture_output=False, stderr=subprocess.PIPE,
                            text=True, timeout=120, preexec_fn=lambda: os.close(1))
    assert closed.returncode == 2 and "standard output is closed" in closed.stderr
    with open("/dev/full", "w") as full:
        failed = subprocess.run(command, cwd=root, stdout=full, stderr=subprocess.PIPE,
                                text=True, timeout=120)
    assert failed.returncode == 2, failed.stderr
    assert failed.stderr.strip().splitlines() == [
        "asnn label: a write failed: No space left on device"]


def test_a_video_or_bag_is_not_written_to_a_pipe_and_a_bag_is_named_mcap(tmp_path, capsys):
    # a CLI trial: OpenCV's writer waited without a word for the pipe's reader (and a video is
    # written with seeks anyway); --mcap out.txt was taken
    scene = make_scene("looming", size=(64, 64), frames=8, start=2, stop=7)
    clip = write_video(scene.frames, tmp_path / "c.mp4", scene.fps)
    pipe = tmp_path / "pipe.mp4"
    os.mkfifo(pipe)
    assert main(["detect", str(clip), "--annotate", str(pipe)]) == 2
    assert "--annotate" in capsys.readouterr().err
    assert main(["detect", str(clip), "--mcap", str(tmp_path / "out.txt")]) == 2
    assert "--mcap " in capsys.readouterr().err and not (tmp_path / "out.txt").exists()
    assert main(["scene", "looming", "--size", "64x64", str(pipe)]) == 2
    assert "not a regular file" in capsys.readouterr().err


def test_a_run_that_stops_before_its_first_frame_leaves_an_existing_output_as_it_was(tmp_path,
                                                                                     capsys):
    # a CLI trial: frames smaller than the model takes, or an MCAP that cannot be written,
    # emptied the --jsonl file of an earlier run before saying so
    kept = tmp_path / "kept.jsonl"
    kept.write_text('{"frame": 0}\n')
    tiny = write_video(np.zeros((10, 16, 16), np.uint8), tmp_path / "tiny.mp4")
    assert main(["detect", str(tiny), "--jsonl", str(kept)]) == 2
    assert "smaller than the model's" in capsys.readouterr().err
    if os.path.isdir("/proc"):  # a folder no file can be made in, whoever runs the test
        scene = make_scene("looming", size=(64, 64), frames=8, start=2, stop=7)
        clip = write_video(scene.frames, tmp_path / "c.mp4", scene.fps)
        assert main(["detect", str(clip), "--jsonl", str(kept), "--mcap", "/proc/x.mcap"]) == 2
        assert "--mcap /proc/x.mcap: cannot write in /proc" in capsys.readouterr().err
    assert kept.read_text() == '{"frame": 0}\n'


def test_signals_held_in_a_block_are_given_after_it_sigterm_first():
    """A Ctrl-C then a SIGTERM within a frame's writing ended the command as interrupted (130),
    not terminated (143); each handler in place before the block is back after it."""
    import os
    import signal

    from cli.session import signals_held

    got = []
    handlers = {sig: signal.signal(sig, lambda signum, frame: got.append(signum))
                for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        with signals_held():
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGTERM)
            assert got == []  # held
        assert got == [signal.SIGTERM]
        with signals_held():
            os.kill(os.getpid(), signal.SIGINT)
        assert got == [signal.SIGTERM, signal.SIGINT]
        os.kill(os.getpid(), signal.SIGINT)  # the handler before the block is back
        assert got[-1] == signal.SIGINT and len(got) == 3
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)


@pytest.mark.parametrize("where", [
    # the handler ran Event.set on the main thread: a SIGTERM that came while stop.wait(...)
    # held the event's lock deadlocked the camera for ever (a CI run's camera killed after
    # 30 s), unkillable by SIGTERM
    "with stop._cond:  # where the main thread is, inside stop.wait(...)\n"
    "    signal.raise_signal(signal.SIGTERM)\n",
    # a handler that started a thread to set it raised, from Python 3.12, where the signal came
    # during the interpreter's shutdown (the exit's log drain, an atexit callback): "can't
    # create new thread at interpreter shutdown", and the event was never set; simulated on
    # any Python by refusing new threads
    "def refused(self):\n"
    "    raise RuntimeError(\"can't create new thread at interpreter shutdown\")\n"
    "threading.Thread.start = refused\n"
    "signal.raise_signal(signal.SIGTERM)\n",
], ids=["inside-its-wait", "at-shutdown"])
def test_the_stop_handler_sets_its_event_wherever_the_signal_lands(where):
    """The handler of every networked command (``stop_on_signals``), run apart."""
    import subprocess
    import sys

    script = ("import signal, threading\n"
              "from cli.session import stop_on_signals\n"
              "stop = stop_on_signals()\n" + where + "print(stop.wait(10))\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=60)
    assert (done.returncode, done.stdout) == (0, "True\n"), done.stderr


def test_a_signal_that_lands_inside_a_write_to_a_stream_still_ends_a_compile():
    """``exit_on_interrupt``'s handler (a worker compiling its kernels) printed its line: where
    the main thread was inside a write to the same stream, the print raised (a buffered
    stream's reentrant call) and the process went on instead of ending."""
    import subprocess
    import sys

    script = ("import signal, sys\n"
              "from cli.session import exit_on_interrupt\n"
              "class Busy:  # a stream the interrupted thread is writing to\n"
              "    def write(self, text): raise RuntimeError('reentrant call')\n"
              "    def flush(self): raise RuntimeError('reentrant call')\n"
              "with exit_on_interrupt():\n"
              "    sys.stdout = sys.stderr = Busy()\n"
              "    signal.raise_signal(signal.SIGTERM)\n"
              "sys.__stdout__.write('went on')\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=60)
    assert (done.returncode, done.stdout, done.stderr) == (143, "", "\nasnn: terminated\n")


def test_an_interrupted_compile_ends_though_its_output_goes_to_a_pipe_nobody_reads():
    """A review: ``exit_on_interrupt``'s handler flushed standard output before it exited; into
    a full pipe nobody reads (``asnn worker | slow-reader``) the flush blocked, and SIGTERM
    ended nothing. It now has ``FLUSH_GRACE`` seconds."""
    import subprocess
    import sys

    script = ("import os, signal, sys, time\n"
              "from cli.session import exit_on_interrupt\n"
              "sys.stdout = open(1, 'w', buffering=1 << 20)  # held, more than a pipe takes\n"
              "with exit_on_interrupt():\n"
              "    sys.stdout.write('x' * 300000)\n"
              "    os.kill(os.getpid(), signal.SIGTERM)\n"
              "    time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, cwd=Path(__file__).resolve().parents[1])
    try:
        assert proc.wait(timeout=40) == 143  # nobody reads its output meanwhile
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()


@pytest.mark.parametrize("after", [100, 0], ids=["command-goes-on", "command-ends-at-once"])
def test_a_sigterm_that_lands_where_python_ignores_exceptions_still_ends_the_command(after):
    """A full run's flaky failure: an evaluation sent SIGTERM ran to its end with status 0. The
    signal's _Terminated was raised inside an ``os.fork`` callback (logging's _releaseLock, as
    the pool forked), where Python prints "Exception ignored" and goes on. A command that ends
    before the signal is sent again takes it at its end (a review: it was lost)."""
    import subprocess
    import sys

    script = ("import os, signal, time\n"
              "from cli.main import _Terminated, _sigterm_interrupts\n"
              "os.register_at_fork(after_in_parent=lambda: os.kill(os.getpid(), "
              "signal.SIGTERM))  # the signal lands in the fork's callback\n"
              "try:\n"
              "    with _sigterm_interrupts():\n"
              "        pid = os.fork()\n"
              "        if pid == 0:\n"
              "            os._exit(0)\n"
              "        os.waitpid(pid, 0)\n"
              f"        for _ in range({after}):\n"
              "            time.sleep(0.01)\n"
              "    print('ran on')\n"
              "except _Terminated:\n"
              "    print('terminated')\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=60, cwd=Path(__file__).resolve().parents[1])
    assert done.stdout == "terminated\n", done.stderr


def test_a_sigterm_held_under_the_default_handler_still_ends_the_process():
    import signal
    import subprocess
    import sys

    code = ("import os, signal\nfrom cli.session import signals_held\n"
            "signal.signal(signal.SIGTERM, signal.SIG_DFL)\n"
            "with signals_held():\n    os.kill(os.getpid(), signal.SIGTERM)\n"
            "    print('held', flush=True)\nprint('alive', flush=True)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == -signal.SIGTERM and done.stdout.split() == ["held"]


def test_videos_are_written_with_the_opencv_4_log_calls_where_cv2_utils_has_no_logging(
        tmp_path, monkeypatch):
    """A packaging trial: cv2.utils.logging exists from OpenCV 4.13 only, and with 4.12 (which
    pyproject.toml accepts) every video written raised an AttributeError: asnn scene, asnn
    detect --annotate, eval's perturbed clips."""
    import cv2

    from asnn.io.video import open_video

    levels = []  # OpenCV 4.12's calls, on whatever OpenCV runs the test
    monkeypatch.delattr(cv2.utils, "logging", raising=False)
    monkeypatch.setattr(cv2, "setLogLevel", levels.append, raising=False)
    monkeypatch.setattr(cv2, "getLogLevel", lambda: 3, raising=False)
    scene = make_scene("looming", size=(48, 48), frames=6)
    write_video(scene.frames, tmp_path / "loom.mp4", scene.fps)
    assert levels == [2, 3]  # held at ERROR while writing, then back
    assert len(list(open_video(tmp_path / "loom.mp4"))) == 6


def test_frame_times_the_model_cannot_time_by_are_one_note_of_detect_s_own(tmp_path, capsys):
    """The model's TimingWarning came out in Python's form (asnn's file and line, and the line
    of code), read as a fault; where the note on the source's rate said it, it came twice."""
    from asnn.io.rosbag import write_bag
    from asnn.stimuli import make_scene

    frames = make_scene("looming", size=(96, 96), frames=12).frames
    for fps, said, not_said in (
            (20000.0, "asnn detect: note: 5 frames in a row came at times", "TimingWarning"),
            (0.5, "its frames are more than 1 s apart", "5 frames in a row")):
        path = write_bag(frames, tmp_path / f"at-{fps:g}.mcap", fps=fps)
        assert main(["detect", str(path), "--jsonl", str(tmp_path / "out.jsonl")]) == 0
        err = capsys.readouterr().err
        assert said in err and not_said not in err and "TimingWarning" not in err, err
    # a note of the command's, where warnings are errors too (a review: a traceback midway)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["detect", str(tmp_path / "at-20000.mcap"), "--jsonl", "-"]) == 0
    printed = capsys.readouterr()
    assert len(printed.out.splitlines()) == len(frames) and "5 frames in a row" in printed.err


def test_an_lgmd_model_takes_a_bag_s_rate_as_its_dt_only_where_it_is_a_frame_period(
        tmp_path, capsys):
    """A trial: a bag stamped in another unit read 2e7 fps, and LGMD1-2 ran at dt = 5e-8 s
    without a word (twice the warning frames of the same bag in seconds)."""
    from asnn.baselines import LGMD2
    from asnn.io.rosbag import write_bag
    from asnn.stimuli import make_scene

    frames = make_scene("looming", size=(96, 96), frames=30).frames
    for fps, dt in ((2e7, 0.05), (20.0, 0.05), (30.0, 1 / 30)):
        path = write_bag(frames, tmp_path / f"at-{fps:g}.mcap", fps=fps)
        assert main(["detect", str(path), "--model", "lgmd2", "--jsonl", "-"]) == 0
        printed = capsys.readouterr()
        model = LGMD2(dt=dt)
        assert [json.loads(x)["u"] for x in printed.out.splitlines()] == pytest.approx(
            [model.step(f).u for f in frames], rel=1e-6)  # the bag's ns stamps: 1/30 or so
        assert ("no frame period a model can time by" in printed.err) == (fps == 2e7)


def test_a_raw_stream_and_a_y4m_without_its_rate_are_timed_at_a_guess_and_say_so(
        tmp_path, capsys):
    """A trial: a raw MJPEG stream and a y4m without its F field took OpenCV's 25 fps as stated:
    asnn detect (and asnn camera) said nothing of the guess that timed them."""
    import cv2

    from asnn.io.sources import open_source
    from asnn.stimuli import make_scene

    frames = make_scene("looming", size=(64, 48), frames=12).frames
    raw = tmp_path / "cam.mjpeg"
    raw.write_bytes(b"".join(cv2.imencode(".jpg", f)[1].tobytes() for f in frames))
    y4m, rated = tmp_path / "noF.y4m", tmp_path / "F30.y4m"
    for path, header in ((y4m, b"YUV4MPEG2 W64 H48 Ip A1:1 Cmono\n"),
                         (rated, b"YUV4MPEG2 W64 H48 F30:1 Ip A1:1 Cmono\n")):
        path.write_bytes(header + b"".join(b"FRAME\n" + f.tobytes() for f in frames))
    for path, stated in ((raw, False), (y4m, False), (rated, True)):
        assert open_source(str(path)).fps_stated == stated, path
        assert main(["detect", str(path), "--jsonl", str(tmp_path / "o.jsonl")]) == 0
        said = "states no frame rate a camera runs at" in capsys.readouterr().err
        assert said == (not stated), path


@pytest.mark.parametrize("command", [
    ["detect", "{long}.mp4"], ["detect", "{long}.mcap"], ["eval", "{long}"],
    ["eval", "{tmp}", "--labels", "{long}.json"], ["label", "{long}"],
    ["bench", "--handover", "--clips", "{long}"], ["detect", "{loop}"], ["detect", "{long}#/cam"],
], ids=["detect-video", "detect-bag", "eval-clips", "eval-labels", "label-clips",
        "bench-clips", "detect-link-loop", "detect-topic-suffix"])
def test_an_input_path_that_cannot_be_looked_up_is_a_one_line_error(tmp_path, capsys, command):
    """A contributor's trial: an input named too long for the file system, or a loop of links,
    ended every reading command in a traceback (Path.is_dir and exists raise for them)."""
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    names = {"tmp": str(tmp_path), "long": str(tmp_path / ("a" * 300)),
             "loop": str(tmp_path / "loop")}
    argv = [part.format(**names) for part in command]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"asnn {command[0]}: "), err
    assert err[0].endswith(("File name too long", "(a loop of links)")), err
