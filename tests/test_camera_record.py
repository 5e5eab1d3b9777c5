"""``asnn camera --record OUT.mcap``: the frames a camera publishes, recorded as a ROS 2 bag that
``asnn detect`` and ``asnn camera --source`` replay (asnn.io.bag_recording, service.camera)."""

from __future__ import annotations

import errno
import itertools
import json
import os
import random
import string
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mcap_ros2", reason="the 'ros' extra is not installed")

from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402

from asnn.io.rosbag import ros_time_ns as stamp_ns  # noqa: E402
from cli.main import main  # noqa: E402
from service import keys  # noqa: E402
from service.camera import (Source, open_recording, open_source, publish_frames,  # noqa: E402
                            recording_topic)
from service.messages import decode_frame  # noqa: E402
from diskutil import fill_disk_after  # noqa: E402
from netutil import wait_for  # noqa: E402

PEER = "{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }"


def camera_args(tmp_path, *args) -> list[str]:
    """``asnn camera`` in a peer session of its own on a free loopback port, scouting off."""
    from service.demo import free_port

    config = tmp_path / "peer.json5"
    config.write_text(PEER)
    return ["camera", *args, "--wait", "0", "--preview-hz", "0", "--mode", "peer", "--listen",
            f"tcp/127.0.0.1:{free_port()}", "--config", str(config)]


def collect(net, robot: str) -> tuple[list, object]:
    """The frames published for ``robot``, as a subscriber on the hub receives them, and the
    subscriber (undeclared when let go: keep it)."""
    got = []
    subscriber = net.hub.declare_subscriber(
        keys.frame_key(robot), lambda sample: got.append(decode_frame(sample.payload.to_bytes())))
    return got, subscriber


def recorded(path) -> list:
    """(topic, schema, decoded message, log time) of every message of a bag, in file order."""
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        return [(channel.topic, schema.name, decoded, message.log_time)
                for schema, channel, message, decoded in reader.iter_decoded_messages()]


def noise_source(frames: int, side: int = 256) -> Source:
    """Frames of noise: they do not compress, so a recording grows by their size."""
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (side, side), np.uint8) for _ in range(frames)]
    return Source("noise", 20.0, False, lambda: iter(images))


def test_a_recorded_camera_replays_through_detect_as_the_scene_itself(tmp_path):
    """The round trip: a generated scene published at its own rate and recorded, then detected
    from the recording, answers every frame as ``asnn detect`` on the scene directly does. The
    stamps went over the wire as float seconds since the epoch (some 2e-7 s apart from the
    scene's exact times), so the targets' expansion and ttc agree to that, not bit for bit."""
    out = tmp_path / "looming.mcap"
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(out))) == 0
    replayed, direct = tmp_path / "replayed.jsonl", tmp_path / "direct.jsonl"
    assert main(["detect", str(out), "--jsonl", str(replayed)]) == 0
    assert main(["detect", "synthetic:looming", "--jsonl", str(direct)]) == 0
    ours = [json.loads(line) for line in replayed.read_text().splitlines()]
    theirs = [json.loads(line) for line in direct.read_text().splitlines()]
    assert len(ours) == len(theirs) == 60
    assert sum(r["collision"] for r in theirs) > 0  # a run with warnings to compare
    for mine, reference in zip(ours, theirs):
        assert mine["frame"] == reference["frame"]
        assert mine["collision"] == reference["collision"]
        assert mine["spikes"] == reference["spikes"]
        assert mine["t"] == pytest.approx(reference["t"], abs=1e-6)
        assert mine["u"] == pytest.approx(reference["u"], rel=1e-6, abs=1e-12)
        assert len(mine["targets"]) == len(reference["targets"])
        for a, b in zip(mine["targets"], reference["targets"]):
            assert a.keys() == b.keys()
            assert a == pytest.approx(b, rel=1e-4, abs=1e-9)


@pytest.mark.parametrize("format", ["gray8", "jpeg"])
def test_the_recording_holds_each_published_frame_as_sent_with_its_stamp(zenoh_net, tmp_path,
                                                                         format):
    got, held = collect(zenoh_net, "r1")
    path = tmp_path / "r1.mcap"
    recording = open_recording(path, "r1", format=format)
    source = open_source("synthetic:looming")
    published = publish_frames(zenoh_net.spoke(), "r1", source, fps=100, format=format,
                               wait=10.0, preview_hz=0, recording=recording)
    assert recording.close() is None
    assert published == recording.frames == 60
    wait_for(lambda: len(got) == published, what="every frame")
    messages = recorded(path)
    assert len(messages) == published
    schema = "sensor_msgs/msg/Image" if format == "gray8" else "sensor_msgs/msg/CompressedImage"
    for frame, (topic, name, message, log_time) in zip(sorted(got, key=lambda f: f.seq),
                                                      messages):
        assert (topic, name) == (recording_topic("r1"), schema) == ("/asnn/r1/frame", schema)
        assert bytes(message.data) == frame.data  # the very pixels, or jpeg bytes, sent
        stamp = message.header.stamp.sec * 10**9 + message.header.stamp.nanosec
        assert stamp == log_time == stamp_ns(frame.stamp)
        if format == "gray8":
            assert (message.encoding, message.width, message.height) == ("mono8", 128, 128)
        else:
            assert message.format == "jpeg"
    # and asnn camera --source replays it: the same pixels at the recorded times
    again, held_again = collect(zenoh_net, "r2")
    assert publish_frames(zenoh_net.spoke(), "r2", open_source(str(path)), wait=10.0,
                          preview_hz=0) == published
    wait_for(lambda: len(again) == published, what="every frame replayed")
    again.sort(key=lambda f: f.seq)
    for first, second in zip(sorted(got, key=lambda f: f.seq), again):
        assert np.array_equal(first.image(), second.image())
    steps = np.diff([f.stamp for f in sorted(got, key=lambda f: f.seq)])
    assert np.diff([f.stamp for f in again]) == pytest.approx(steps, abs=1e-6)


def ros2_topic_problem(name: str) -> str | None:
    """What makes ``name`` no fully qualified ROS 2 topic name, or None: the rules of
    design.ros2.org, "Topic and Service name mapping to DDS" (written from them, not from
    recording_topic's mapping)."""
    if not name.startswith("/"):
        return "not absolute"  # fully qualified names start with a forward slash
    tokens = name[1:].split("/")
    for token in tokens:
        if not token:
            return "an empty token"  # "//", or a trailing "/"
        if any(c not in string.ascii_letters + string.digits + "_" for c in token):
            return f"a character not alphanumeric nor underscore in {token!r}"
        if token[0] in string.digits:
            return f"{token!r} starts with a digit"
        if "__" in token:
            return f"{token!r} repeats an underscore"  # "single underscores"
        if token.endswith("_"):
            return f"{token!r} ends with an underscore"  # "foo_/bar" is invalid
    if len(name) + len(tokens) + 8 > 255:  # C + N + P <= 255, P = 8
        return "too long"
    return None


def test_the_ros2_rules_as_written_accept_and_refuse_the_design_articles_examples():
    """The checker above against the article's own examples, so it is no straw man."""
    valid = ["/foo", "/bar/baz", "/_private/thing", "/public_namespace/_private/thing",
             "/abc123", "/_foo", "/Foo", "/BAR", "/foo/_bar", "/" + "a" * 245]
    invalid = ["foo", "/123abc", "/123", "/foo bar", "/", "/foo//bar", "/foo/", "/foo_/bar",
               "/foo~", "/foo/~bar", "/a-b", "/a__b", "/" + "a" * 246]
    assert [n for n in valid if ros2_topic_problem(n)] == []
    assert [n for n in invalid if ros2_topic_problem(n) is None] == []


def robot_ids_of_every_class() -> list[str]:
    """Robot ids the service accepts (``[A-Za-z0-9_-]{1,64}``): every string of up to four
    characters over one of each class (lower, upper, digit, ``_``, ``-``), so each class at the
    start, the end, alone, repeated and next to each other; the longest of each class; and
    random ones over the whole alphabet."""
    ids = ["".join(p) for n in range(1, 5) for p in itertools.product("aZ7_-", repeat=n)]
    ids += [c * 64 for c in "aZ7_-"] + ["7" + "-" * 62 + "_", "-" * 63 + "7"]
    alphabet = string.ascii_letters + string.digits + "_-"
    rng = random.Random(0)
    ids += ["".join(rng.choice(alphabet) for _ in range(rng.randint(1, 64)))
            for _ in range(2000)]
    return [keys.check_robot(robot) for robot in ids]


@pytest.mark.parametrize("prefix", ["asnn", "site-3/fleet_a", "2024/é.b@c/-"])
def test_the_recording_topic_is_a_valid_ros2_name_for_every_robot_id(prefix):
    """A robot id with a '-' (valid for the service) made a topic ROS 2 refuses; so did a
    prefix chunk or a robot id starting with a digit, or one with '__' or ending with '_'."""
    bad = {robot: problem for robot in robot_ids_of_every_class()
           if (problem := ros2_topic_problem(recording_topic(robot, prefix)))}
    assert bad == {}
    keys.check_prefix(prefix)  # one the service accepts


def test_the_recording_topic_maps_what_ros2_refuses_and_keeps_the_rest():
    assert recording_topic("r1") == "/asnn/r1/frame"  # unchanged where valid already
    assert recording_topic("Cam_2b") == "/asnn/Cam_2b/frame"
    assert recording_topic("cam-2") == "/asnn/cam_2/frame"
    assert recording_topic("7") == "/asnn/r7/frame"
    assert recording_topic("_x--y_", prefix="site-3") == "/site_3/x_y/frame"
    assert recording_topic("-") == "/asnn/r/frame"
    # not one to one (docs/foxglove.md): a recording holds one robot's frames
    assert len({recording_topic(r) for r in ("cam-2", "cam_2", "cam--2", "-cam-2-")}) == 1
    with pytest.raises(keys.KeySchemeError):
        recording_topic("r.1")
    with pytest.raises(ValueError, match="longer than ROS 2 allows"):
        recording_topic("r" * 64, prefix="p" * 180)


def test_a_camera_records_a_robot_id_with_a_dash_on_a_valid_topic_and_replays_it(tmp_path):
    path = tmp_path / "cam-2.mcap"
    recording = open_recording(path, "cam-2")
    for i in range(3):
        recording.write(64, 64, bytes([i]) * 64 * 64, 10**18 + i * 50_000_000)
    assert recording.close() is None
    assert {topic for topic, *_ in recorded(path)} == {"/asnn/cam_2/frame"}
    assert len(list(open_source(str(path)).frames())) == 3


def test_a_camera_whose_topic_ros2_refuses_fails_at_start_without_a_file(tmp_path, capsys):
    out = tmp_path / "long.mcap"
    assert main(camera_args(tmp_path, "--robot", "r" * 64, "--prefix", "p" * 180, "--source",
                            "synthetic:looming", "--record", str(out))) == 2
    assert "longer than ROS 2 allows" in capsys.readouterr().err
    assert not out.exists()


def test_a_recording_never_overwrites_a_file_and_an_unwritable_one_fails_at_start(tmp_path,
                                                                                capsys):
    path = tmp_path / "run.mcap"
    path.write_bytes(b"an earlier run")
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(path))) == 2
    assert capsys.readouterr().err.strip() == \
        f"asnn camera: {path}: exists; a recording goes to a new file"
    assert path.read_bytes() == b"an earlier run"
    (tmp_path / "a-file").write_text("")  # where a folder would have to be made
    unwritable = tmp_path / "a-file" / "run.mcap"
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(unwritable))) == 2
    assert capsys.readouterr().err.strip() == \
        f"asnn camera: --record {unwritable}: {tmp_path / 'a-file'} is not a folder"
    too_long = tmp_path / ("a" * 300)  # Path.exists raised for its folder: a traceback
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(too_long / "run.mcap"))) == 2
    assert capsys.readouterr().err.strip() == \
        f"asnn camera: --record {too_long / 'run.mcap'}: {too_long}: File name too long"


def test_a_recording_s_missing_folders_are_made_once_the_camera_starts(tmp_path, capsys,
                                                                      monkeypatch):
    """As ``asnn detect`` makes its outputs' folders: a new user's --record rec/x.mcap failed
    with "No such file or directory". A camera that cannot start, or records no frame, leaves
    no folder behind."""
    import asnn.io.bag_recording as bag_recording

    path = tmp_path / "rec" / "day1" / "run.mcap"
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(path))) == 0, capsys.readouterr().err
    assert len(recorded(path)) == 60
    for source in ("synthetic:nope", str(tmp_path / "none.avi")):  # the source does not open
        assert main(camera_args(tmp_path, "--robot", "r1", "--source", source,
                                "--record", str(tmp_path / "new" / "run.mcap"))) == 2
        assert not (tmp_path / "new").exists()
    import service.camera

    with monkeypatch.context() as patch:  # stopped before its first frame: no file, no folder
        patch.setattr(service.camera, "publish_frames", lambda *args, **kwargs: 0)
        assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                                "--record", str(tmp_path / "new" / "run.mcap"))) == 0
    assert not (tmp_path / "new").exists()

    class Usage:  # the recording does not open: the folders made for it are removed
        free = 1_000_000

    monkeypatch.setattr(bag_recording.shutil, "disk_usage", lambda path: Usage)
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(tmp_path / "new" / "more" / "run.mcap"))) == 2
    assert "its disk is full" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def test_a_recording_removes_only_the_folders_it_made(tmp_path, capsys, monkeypatch):
    """The folders removed after a camera that recorded no frame are the ones it made: not a
    folder that was there, named through one that was not (``new/../kept``), nor one another
    process made while the camera made its own; and a folder it cannot make leaves none of
    those it made before."""
    import service.camera

    kept = tmp_path / "kept"
    kept.mkdir()  # there before, and empty
    monkeypatch.setattr(service.camera, "publish_frames", lambda *args, **kwargs: 0)
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(tmp_path / "new" / ".." / "kept" / "run.mcap"))) \
        == 0, capsys.readouterr().err
    assert kept.is_dir() and not (tmp_path / "new").exists()

    real_mkdir = os.mkdir
    other = tmp_path / "other"

    def racing_mkdir(path, *args, **kwargs):  # another process makes the folder first
        if Path(path) == other:
            real_mkdir(path)
        return real_mkdir(path, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", racing_mkdir)
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(other / "day" / "run.mcap"))) == 0
    assert other.is_dir() and not (other / "day").exists()

    def failing_mkdir(path, *args, **kwargs):  # the deepest folder cannot be made
        if Path(path).name == "day":
            raise PermissionError(13, "Permission denied", str(path))
        return real_mkdir(path, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", failing_mkdir)
    target = tmp_path / "made" / "day" / "run.mcap"
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(target))) == 2
    assert capsys.readouterr().err.strip().endswith(
        f"asnn camera: --record {target}: cannot make {target.parent}: Permission denied")
    assert not (tmp_path / "made").exists()


def test_a_full_disk_is_an_error_at_start_and_leaves_no_file(tmp_path, monkeypatch, capsys):
    import asnn.io.bag_recording as bag_recording

    class Usage:
        free = 1_000_000

    monkeypatch.setattr(bag_recording.shutil, "disk_usage", lambda path: Usage)
    path = tmp_path / "run.mcap"
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(path))) == 2
    assert capsys.readouterr().err.strip() == \
        f"asnn camera: cannot record to {path}: its disk is full (1.0 MB free)"
    assert not path.exists()


def test_the_bound_stops_the_recording_and_the_camera_publishes_on(zenoh_net, tmp_path,
                                                                   caplog):
    got, held = collect(zenoh_net, "r1")
    path = tmp_path / "r1.mcap"
    with caplog.at_level("WARNING", logger="asnn.camera"):
        recording = open_recording(path, "r1", max_bytes=1.5e6)
        # 64 kB frames: the writer writes a chunk of 16 of them (1 MiB) at a time
        published = publish_frames(zenoh_net.spoke(), "r1", noise_source(80), fps=100,
                                   wait=10.0, preview_hz=0, recording=recording)
        assert recording.close() is None
    assert published == 80
    # frames are best effort: of 64 kB ones some may be dropped under load, not all after it
    wait_for(lambda: any(f.seq >= recording.frames for f in got),
             what="frames published after the recording stopped")
    assert recording.stopped == "bound"
    assert 16 <= recording.frames < 80
    assert len(recorded(path)) == recording.frames  # a finished file, read to its end
    lines = [r.getMessage() for r in caplog.records if "recording to" in r.getMessage()]
    assert lines == [f"camera r1: recording to {path} stopped at 2 MB, its bound "
                     "(--record-max-mb): the frames are published on"]


def test_a_failed_write_stops_the_recording_and_the_camera_publishes_on(zenoh_net, tmp_path,
                                                                        monkeypatch, caplog):
    fill_disk_after(monkeypatch, 1_500_000)
    got, held = collect(zenoh_net, "r1")
    path = tmp_path / "r1.mcap"
    with caplog.at_level("WARNING", logger="asnn.camera"):
        recording = open_recording(path, "r1")
        published = publish_frames(zenoh_net.spoke(), "r1", noise_source(80), fps=100,
                                   wait=10.0, preview_hz=0, recording=recording)
        assert recording.close().errno == errno.ENOSPC
    assert published == 80
    # frames are best effort: of 64 kB ones some may be dropped under load, not all after it
    wait_for(lambda: any(f.seq >= recording.frames for f in got),
             what="frames published after the recording stopped")
    assert recording.stopped == "failed"
    lines = [r.getMessage() for r in caplog.records if "recording to" in r.getMessage()]
    assert lines == [f"camera r1: recording to {path} stopped: No space left on device (the "
                     f"file holds the {recording.frames} frames before, cut there, unfinished "
                     "(`mcap recover` repairs it)); the frames are published on"]
    # what reached the disk reads back as far as it goes (a cut bag: `mcap recover` repairs it)
    frames = list(open_source(str(path), on_error=lambda reason, message: None).frames())
    assert 0 < len(frames) == recording.frames < 80


def test_after_a_failed_write_the_frames_said_recorded_are_those_the_file_holds(
        tmp_path, monkeypatch):
    """A review: the writer holds the frames of the chunk it fills, and the failed write of
    that chunk loses them, but the stop line and the camera's exit counted them as in the file
    (31 frames said where the file held 16)."""
    from asnn.io.bag_recording import BagRecording

    fill_disk_after(monkeypatch, 1_500_000)
    stops = []
    path = tmp_path / "full.mcap"
    recording = BagRecording(path, "/asnn/r1/frame", on_stop=lambda *stop: stops.append(stop))
    rng = np.random.default_rng(0)
    for i in range(80):  # 64 kB frames of noise: a chunk (1 MiB) holds 16
        recording.write(256, 256, rng.integers(0, 256, 256 * 256, np.uint8).tobytes(),
                        10**18 + i * 50_000_000)
    assert recording.close().errno == errno.ENOSPC
    held = list(open_source(str(path), on_error=lambda reason, message: None).frames())
    assert len(held) == recording.frames == 16
    assert [(reason, f"holds the {len(held)} frames before" in detail)
            for reason, detail in stops] == [("failed", True)]


def test_a_disk_that_does_not_keep_up_stops_the_recording_not_the_camera(tmp_path, caplog):
    """A writer held up (a stalled disk): the frames wait in memory up to the backlog's bound,
    then the recording stops with the frames before, and ``write`` never blocked."""
    import threading

    from asnn.io.bag_recording import BagRecording

    stops = []
    recording = BagRecording(tmp_path / "slow.mcap", "/asnn/r1/frame",
                             backlog_bytes=5 * 64 * 64,
                             on_stop=lambda reason, detail: stops.append((reason, detail)))
    held = threading.Event()
    write = recording._write
    recording._write = lambda *args: (held.wait(), write(*args))
    data = bytes(64 * 64)
    accepted = [recording.write(64, 64, data, 10**18 + i) for i in range(8)]
    # the first is being written (or about to be) and five wait: the next ones find no room
    assert accepted[:5] == [True] * 5 and accepted[-1] is False
    assert stops == [("behind", "the disk does not keep up (0 MB of frames waiting to be "
                      "written: the file is finished once they are)")]
    held.set()
    assert recording.close() is None
    assert recording.stopped == "behind"
    assert len(recorded(tmp_path / "slow.mcap")) == recording.frames == accepted.count(True)


def test_without_the_ros_extra_record_is_a_clear_error_at_start(tmp_path, monkeypatch, capsys):
    import asnn.io

    # as if the extra were not installed: mcap cannot be imported, the bag modules not loaded
    for name in [n for n in sys.modules if n.split(".")[0] in ("mcap", "mcap_ros2")]:
        monkeypatch.setitem(sys.modules, name, None)
    for name in ("rosbag", "bag_recording"):
        monkeypatch.delitem(sys.modules, f"asnn.io.{name}", raising=False)
        monkeypatch.delattr(asnn.io, name, raising=False)
    path = tmp_path / "run.mcap"
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record", str(path))) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "asnn[ros]" in err
    assert not path.exists()


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_camera_stopped_by_a_signal_leaves_a_finished_recording(procs, tmp_path, sig):
    """Ctrl-C or ``docker stop``: the recording is finished (its summary written) with every
    frame published, and the camera exits as it always does."""
    import signal

    path = tmp_path / "run.mcap"
    camera = procs(*camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                                "--loop", "--fps", "100", "--record", str(path)))
    camera.wait_line("synthetic:looming at 100.0 fps")
    header = path.stat().st_size  # the file's start, written when it opened
    wait_for(lambda: path.stat().st_size > header, what="a chunk of frames on disk")
    assert camera.stop(getattr(signal, sig)) == 0, "\n".join(camera.err[-20:])
    (line,) = [line for line in camera.err if "recorded" in line]
    count = int(line.split("recorded ")[1].split()[0])
    (published,) = [line for line in camera.err if "frames published" in line]
    assert f"camera r1: {count} frames published" in published
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None and summary.statistics.message_count == count >= 64  # a chunk and more
    assert len(recorded(path)) == count


def test_a_bound_without_its_recording_is_a_clear_error(tmp_path, capsys):
    assert main(camera_args(tmp_path, "--robot", "r1", "--source", "synthetic:looming",
                            "--record-max-mb", "5")) == 2
    assert capsys.readouterr().err.strip() == \
        "asnn camera: --record-max-mb bounds a recording: give it with --record OUT.mcap"
    assert main(["foxglove", "--port", "0", "--mcap-max-mb", "5"]) == 2
    assert capsys.readouterr().err.strip() == \
        "asnn foxglove: --mcap-max-mb bounds a recording: give it with --mcap OUT.mcap"


def test_a_disk_that_hangs_leaves_the_recording_unfinished_and_the_camera_exits(
        tmp_path, monkeypatch, caplog):
    """The camera's exit waits for its recording a bounded time: a writer that never returns
    (a hung network disk) is said and left, the file unfinished."""
    import logging
    import threading

    import cli.net
    from asnn.io.bag_recording import BagRecording

    monkeypatch.setattr(cli.net, "RECORD_CLOSE_TIMEOUT", 0.2)
    recording = BagRecording(tmp_path / "hung.mcap", "/asnn/r1/frame")
    held = threading.Event()
    recording._write = lambda *args: held.wait()
    assert recording.write(64, 64, bytes(64 * 64), 10**18)
    with caplog.at_level(logging.INFO, logger="asnn"):
        cli.net._close_recording(recording, "r1")
    assert recording.writing
    assert [r.getMessage() for r in caplog.records if "recording to" in r.getMessage()] == [
        f"camera r1: recording to {recording.path}: still writing after 0 s; left unfinished "
        "(`mcap recover` repairs it)"]
    held.set()  # the writer returns: the file is finished
    recording._thread.join(10)
    assert not recording.writing


def test_a_camera_stopped_before_its_first_frame_leaves_no_recording(tmp_path, caplog):
    """A review: a camera stopped while it waited for a worker (Ctrl-C during --wait) left a
    bag with no frame, which asnn detect reads as one without an image topic, and over which
    the same command, run again, failed: the file exists."""
    import logging

    import cli.net
    from asnn.io.bag_recording import BagRecording

    recording = BagRecording(tmp_path / "none.mcap", "/asnn/r1/frame")
    with caplog.at_level(logging.INFO, logger="asnn"):
        cli.net._close_recording(recording, "r1")
    assert not recording.path.exists()
    assert [r.getMessage() for r in caplog.records if "record" in r.getMessage()] == [
        f"camera r1: recorded no frame; {recording.path} not kept"]
    kept = BagRecording(tmp_path / "one.mcap", "/asnn/r1/frame")  # one frame: kept
    assert kept.write(64, 64, bytes(64 * 64), 10**18)
    cli.net._close_recording(kept, "r1")
    assert len(recorded(kept.path)) == kept.frames == 1
