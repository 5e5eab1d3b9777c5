"""The service over real Zenoh sessions: in-process on TCP loopback, and as separate processes.

Every session uses a free port, multicast scouting and gossip are off, and everything started is
stopped at the end of its test. Waits are generous timeouts on messages, never timing assertions.
"""

import io
import json
import logging
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest
import zenoh

from asnn.params import DEFAULT_PRESET, preset
from asnn.io.video import write_video
from asnn.stimuli import make_scene
from clients.alerts import WarningListener
from cli.main import main
from service import keys
from service.camera import RefusalNotices, Source, SourceError, open_source, publish_frames
from service.core import HANDOVER_WARMUP_FRAMES, WorkerCore
from service.messages import Frame, Response, decode_frame, decode_response, encode
from service.worker import COMPUTE_NICENESS, Worker

from netutil import TIMEOUT, Fleet, wait_for

ROOT = Path(__file__).resolve().parents[1]




class Responses:
    """Collects the responses of every robot from a plain subscriber."""

    def __init__(self, session, prefix="asnn"):
        self.by_robot: dict[str, list] = {}
        self.lock = threading.Lock()
        self.sub = session.declare_subscriber(keys.responses(prefix), self._on)

    def _on(self, sample):
        response = decode_response(sample.payload.to_bytes())
        with self.lock:
            self.by_robot.setdefault(response.robot, []).append(response)

    def of(self, robot):
        with self.lock:
            return list(self.by_robot.get(robot, []))


def scene_source(name, **kwargs):
    scene = make_scene(name, **kwargs)
    return scene, Source(f"synthetic:{name}", scene.fps, False, lambda: iter(scene.frames))


def send_one(session, responses, robot, image, seq):
    """Put one frame and wait for its response (so that nothing is skipped). Put blocking, as
    the junk around it is: a frame the session itself dropped under load (the default
    congestion control) would never be answered, and the wait would blame the worker."""
    session.put(keys.frame_key(robot), encode(Frame.from_image(image, seq=seq, stamp=seq * 0.05)),
                congestion_control=zenoh.CongestionControl.BLOCK)
    wait_for(lambda: any(r.seq == seq for r in responses.of(robot)), what=f"{robot} seq {seq}")
    return next(r for r in responses.of(robot) if r.seq == seq)


@pytest.fixture
def service(zenoh_net):
    """A worker on the hub session, and a response collector on a spoke."""
    core = WorkerCore()
    with Worker(zenoh_net.hub, core, stats_every=0) as worker:
        zenoh_net.core, zenoh_net.worker = core, worker
        zenoh_net.responses = Responses(zenoh_net.spoke())
        yield zenoh_net


def test_a_robot_answered_while_the_publishers_are_pruned_keeps_its_publishers(zenoh_net,
                                                                               monkeypatch):
    """A concurrency review: the worker's pruning of its robots' publishers (_drop_outlets,
    on the routes' thread) read the robots tracked before it took the publishers' lock, so a
    robot tracked and answered in between had the publishers it had just declared undeclared,
    as one no longer tracked."""
    def answer(robot):
        return Response(robot=robot, seq=1, stamp=1.0, model="asnn", preset="p", u=0.0,
                        out=0.5, spikes=0, spike_rate=0.0, collision=False, targets=[],
                        worker="w1", latency_ms=1.0, dropped=0)

    core = WorkerCore()
    worker = Worker(zenoh_net.hub, core, stats_every=0)  # not started: no routes' thread
    tracked, answering = ["r1"], []

    def robots():
        before = list(tracked)
        if not answering:  # r2's first frame comes, is tracked and answered meanwhile
            tracked.append("r2")
            answering.append(threading.Thread(target=worker.publish, args=(answer("r2"),)))
            answering[0].start()
            answering[0].join(timeout=2)  # at once, unless the pruning holds the lock
        return before

    monkeypatch.setattr(core, "robots", robots)
    try:
        worker.publish(answer("r1"))
        worker._drop_outlets()
        answering[0].join(timeout=30)
        assert not answering[0].is_alive()
        assert sorted(worker._outlets) == ["r1", "r2"]
        worker.publish(answer("r2"))  # on publishers still declared
    finally:
        worker.close()


def test_a_frame_that_fails_every_time_logs_one_traceback_per_robot_per_interval(zenoh_net,
                                                                                  caplog):
    """Earlier sessions: a bug that failed every frame in the worker's processing threads (here
    the response's callback) or its frame callbacks logged a traceback per frame, flooding the
    log at the frame rate. Now one per kind (per robot for the processing) every
    log_interval by the core's clock, the next line counting those not shown."""
    now = [1000.0]
    core = WorkerCore(clock=lambda: now[0], log_interval=10.0)
    calls = []

    def broken(response):
        calls.append(response.seq)
        raise RuntimeError("a bug in the callback")

    worker = Worker(zenoh_net.hub, core, stats_every=0, on_response=broken)  # not started
    image = make_scene("looming").frames[0]

    def step(robot, seq):
        core.offer(keys.frame_key(robot), encode(Frame.from_image(image, seq=seq,
                                                                  stamp=seq * 0.05)))
        job = core.take()
        assert job is not None and job.robot == robot
        worker._step(job)  # never raises

    class Sample:  # what the frame callbacks read of a Zenoh sample
        key_expr = "asnn/r1/frame"
        payload = type("Payload", (), {"to_bytes": staticmethod(lambda: b"\x80")})

    def offer_fails(key, payload, received=None):
        raise RuntimeError("a bug in offer")

    try:
        with caplog.at_level(logging.ERROR, logger="asnn.worker"):
            for seq in range(30):
                step("r1", seq)
            step("r2", 0)  # another robot: its own first line
            now[0] += 10.0
            step("r1", 30)
            core.offer = offer_fails
            for _ in range(50):
                worker._on_frame(Sample)
                worker._on_scanned_frame(Sample)
            now[0] += 10.0
            worker._on_frame(Sample)
    finally:
        worker.close()
    assert calls == list(range(30)) + [0, 30]  # every frame processed and published
    lines = [(r.getMessage(), str(r.exc_info[1])) for r in caplog.records
             if r.name == "asnn.worker" and r.exc_info]
    assert lines == [
        ("robot r1: frame 0 failed", "a bug in the callback"),
        ("robot r2: frame 0 failed", "a bug in the callback"),
        ("robot r1: frame 30 failed (29 more since the last line)", "a bug in the callback"),
        ("unexpected error on a frame from asnn/r1/frame", "a bug in offer"),
        ("unexpected error on a frame from asnn/r1/frame", "a bug in offer"),  # the scan's
        ("unexpected error on a frame from asnn/r1/frame (49 more since the last line)",
         "a bug in offer"),
    ]


def test_two_cameras_at_once_looming_warns_with_targets_translating_does_not(service):
    warnings = []
    listener = WarningListener(service.spoke(), warnings.append)
    loom, loom_source = scene_source("looming")
    bar, bar_source = scene_source("translating_bar")
    cameras = [threading.Thread(target=publish_frames, args=(service.spoke(), robot, source),
                                kwargs=dict(fps=40, wait=TIMEOUT))
               for robot, source in (("loom", loom_source), ("bar", bar_source))]
    for camera in cameras:
        camera.start()
    for camera in cameras:
        camera.join(timeout=60)
    wait_for(lambda: service.worker.idle(), what="the worker to finish")
    # frames are best effort: both streams must have been answered to near their ends
    wait_for(lambda: service.responses.of("loom") and service.responses.of("bar")
             and service.responses.of("loom")[-1].seq >= len(loom.frames) - 5
             and service.responses.of("bar")[-1].seq >= len(bar.frames) - 5, what="responses")
    loom_responses, bar_responses = service.responses.of("loom"), service.responses.of("bar")
    sent = [r for r in loom_responses if r.collision]
    assert sent and loom.onset_frame <= sent[0].seq <= loom.contact_frame
    assert any(r.targets for r in sent)
    assert not any(r.collision for r in bar_responses)
    wait_for(lambda: len(warnings) >= len(sent), what="the warnings")
    listener.close()
    assert {(w.robot, w.seq) for w in warnings} == {("loom", r.seq) for r in sent}
    assert all(r.worker == service.core.worker_id and r.model == "asnn" for r in loom_responses)
    assert service.core.stats()["invalid"] == {}
    # a replayed source is stamped at its recorded spacing, however the publishing went
    stamps = {r.seq: r.stamp for r in loom_responses}
    first = min(stamps)
    assert all(stamps[s] - stamps[first] == pytest.approx((s - first) / 40, abs=1e-6)
               for s in stamps)


def test_two_processing_threads_keep_each_robot_exact(zenoh_net):
    from asnn import ASNN

    scenes = {"a": make_scene("looming", size=(96, 96), stop=30),
              "b": make_scene("looming", size=(96, 96), stop=30, polarity="light",
                              center=(40.0, 52.0))}
    expected = {}
    for robot, scene in scenes.items():
        model = ASNN()
        expected[robot] = [model.step(f, seq * 0.05).u for seq, f in enumerate(scene.frames)]
    core = WorkerCore()
    with Worker(zenoh_net.hub, core, stats_every=0, threads=2):
        processing = [t for t in threading.enumerate() if t.name.startswith("asnn-worker-")]
        assert len(processing) == 2
        if sys.platform.startswith("linux"):  # compute below the threads that move messages
            base = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
            wait_for(lambda: all(os.getpriority(os.PRIO_PROCESS, t.native_id)
                                 == min(base + COMPUTE_NICENESS, 19) for t in processing),
                     what="processing threads at a lower priority")
        responses = Responses(zenoh_net.spoke())
        session = zenoh_net.spoke()
        for seq in range(len(scenes["a"].frames)):
            for robot, scene in scenes.items():  # both robots' frames wait together
                session.put(keys.frame_key(robot),
                            encode(Frame.from_image(scene.frames[seq], seq=seq, stamp=seq * 0.05)))
            wait_for(lambda: all(any(r.seq == seq for r in responses.of(robot)) for robot in scenes),
                     what=f"responses to seq {seq}")
    for robot in scenes:
        got = {r.seq: r.u for r in responses.of(robot)}
        assert [got[seq] for seq in range(len(expected[robot]))] == expected[robot]
    assert max(expected["a"]) > 0 and max(expected["b"]) > 0


def _threads() -> int:
    """The process's threads, Zenoh's own among them (``threading`` sees only Python's)."""
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("Threads:"))


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="needs Linux's /proc")
def test_a_worker_serving_many_robots_keeps_no_thread_per_robot(service):
    """Each robot's frame subscription runs its callback where Zenoh receives the frame: with
    zenoh-python's default, each would keep a thread (and a queue with no bound) of its own."""
    session, image = service.spoke(), np.zeros((64, 64), np.uint8)
    send_one(session, service.responses, "r0", image, 0)
    wait_for(lambda: "r0" in service.worker._subscriptions, what="r0's subscription")
    before = _threads()
    robots = [f"r{i}" for i in range(1, 31)]
    for robot in robots:
        send_one(session, service.responses, robot, image, 0)
    wait_for(lambda: set(robots) <= service.worker._subscriptions.keys(),
             what="a subscription per robot")
    for robot in robots:  # and the subscriptions deliver
        send_one(session, service.responses, robot, image, 1)
    assert _threads() - before < 10


def test_frame_size_change_resets_the_robot_over_zenoh(service):
    session = service.spoke()
    big, small = make_scene("looming"), make_scene("looming", size=(80, 96))
    for seq in range(15):
        send_one(session, service.responses, "r1", big.frames[seq], seq)
    after = [send_one(session, service.responses, "r1", small.frames[seq], seq)
             for seq in range(15, 35)]
    assert after[0].u == 0.0 and any(r.collision for r in after)
    assert service.core.stats()["resets"] == {"size": 1}


def test_malformed_frames_are_counted_while_valid_frames_keep_flowing(service):
    session = service.spoke()
    scene = make_scene("looming")
    junk = [b"\xc1\xc1", msgpack.packb([1, 2]), msgpack.packb({"v": 1, "seq": "x"}),
            msgpack.packb({"v": 1, "seq": 1, "stamp": 0.0, "width": 64, "height": 64, "format": "gray8",
                           "data": b"\x00"})]
    for seq in range(25):
        for payload in junk:
            session.put(keys.frame_key("r1"), payload)
        session.put("asnn/not a robot/frame", encode(Frame.from_image(scene.frames[0], seq=0,
                                                                      stamp=0.0)))
        assert send_one(session, service.responses, "r1", scene.frames[seq], seq) is not None
    wait_for(lambda: sum(service.core.stats()["invalid"].values()) == 25 * 5,
             what="every invalid frame to be counted")
    assert service.core.stats()["invalid"] == {"undecodable": 25, "not-a-map": 25,
                                               "invalid-field": 25, "bad-pixels": 25,
                                               "bad-key": 25}
    assert any(r.collision for r in service.responses.of("r1"))


def junk_messages(scene):
    """(key, payload, reason) of every kind of bad input, cycled through by the live test."""
    good = msgpack.unpackb(encode(Frame.from_image(scene.frames[0], seq=0, stamp=0.0)))
    jpeg = msgpack.unpackb(encode(Frame.from_image(scene.frames[0], seq=0, stamp=0.0,
                                                   format="jpeg")))
    key = keys.frame_key("r1")
    return [
        (key, b"\xc1\xc1", "undecodable"),
        (key, msgpack.packb([1, 2]), "not-a-map"),
        (key, msgpack.packb({**good, "v": 7}), "unsupported-version"),
        (key, msgpack.packb({k: v for k, v in good.items() if k != "seq"}), "missing-field"),
        (key, msgpack.packb({**good, "seq": "x"}), "invalid-field"),
        (key, msgpack.packb({**good, "stamp": float("nan")}), "bad-stamp"),
        (key, msgpack.packb({**good, "stamp": float("-inf")}), "bad-stamp"),
        (key, msgpack.packb({**good, "width": 0}), "bad-size"),
        (key, msgpack.packb({**good, "height": 4097}), "bad-size"),
        (key, msgpack.packb({**good, "format": "h264"}), "bad-format"),
        (key, msgpack.packb({**good, "data": good["data"][:100]}), "bad-pixels"),
        (key, msgpack.packb({**jpeg, "data": jpeg["data"][:2] + b"junk" * 20}), "bad-image"),
        ("asnn/not a robot/frame", encode(Frame.from_image(scene.frames[0], seq=0, stamp=0.0)),
         "bad-key"),
        ("asnn/" + "x" * 65 + "/frame", msgpack.packb(good), "bad-key"),
    ]


def test_thousands_of_malformed_messages_never_stall_the_worker(service):
    """2000+ malformed messages of every kind interleaved with valid frames: every valid frame
    is answered, every bad one counted under its reason and visible in the status queryable."""
    from service.worker import query_status

    session = service.spoke()
    scene = make_scene("looming")
    junk = junk_messages(scene)
    expected: dict[str, int] = {}
    reliable = dict(congestion_control=zenoh.CongestionControl.BLOCK)
    sent = 0
    for seq in range(len(scene.frames)):
        for _ in range(36):
            key, payload, reason = junk[sent % len(junk)]
            session.put(key, payload, **reliable)
            expected[reason] = expected.get(reason, 0) + 1
            sent += 1
        assert send_one(session, service.responses, "good", scene.frames[seq], seq) is not None
    assert sent >= 2000

    def counted(stats):
        # a jpeg that does not decode passes the checks on arrival and fails when processed;
        # until then a newer frame of r1 may replace it (newest wins): it is counted as dropped
        invalid = dict(stats["invalid"])
        invalid["bad-image"] = invalid.get("bad-image", 0) + stats["dropped"]
        return invalid

    wait_for(lambda: counted(service.core.stats()) == expected and service.worker.idle(),
             what="every malformed message to be counted")
    status = query_status(session)[service.core.worker_id]
    assert counted(status["stats"]) == expected
    assert status["stats"]["processed"] == len(scene.frames)
    assert set(status["robots"]) - {"r1"} == {"good"}
    responses = service.responses.of("good")
    assert [r.seq for r in responses] == list(range(len(scene.frames)))
    assert any(r.collision for r in responses)


def test_a_late_subscriber_receives_the_last_warning_of_each_robot(service):
    session = service.spoke()
    scene = make_scene("looming")
    last = {"a": 25, "b": 30}
    for robot, stop in last.items():
        for seq in range(stop + 1):
            response = send_one(session, service.responses, robot, scene.frames[seq], seq)
        assert response.collision
    late, only_b = [], []
    late_session = service.spoke()
    with WarningListener(late_session, late.append), \
            WarningListener(late_session, only_b.append, robot="b"):
        wait_for(lambda: {w.robot for w in late} == set(last) and only_b,
                 what="the cached warnings")
        time.sleep(0.3)  # anything further would arrive now
    assert sorted((w.robot, w.seq) for w in late) == sorted(last.items())
    assert [(w.robot, w.seq) for w in only_b] == [("b", 30)]


def test_a_starting_worker_says_it_loads_the_model_s_kernels(zenoh_net, caplog):
    with caplog.at_level("INFO", logger="asnn.worker"):
        with Worker(zenoh_net.hub, WorkerCore(), stats_every=0):
            pass
    messages = [r.getMessage() for r in caplog.records if r.name == "asnn.worker"]
    loading = next(i for i, m in enumerate(messages) if "loading the model's kernels" in m)
    assert re.search(r"kernels ready in [0-9.]+ s", messages[loading + 1])


def test_a_starting_worker_loads_the_kernels_of_its_own_preset(zenoh_net, monkeypatch):
    # a worker runs one preset: it loads that one's kernels before its first frame (those of
    # another preset would leave its first frames waiting for the compiler), and no others
    import asnn.warmup  # the worker imports it when it loads the kernels

    loaded = []
    monkeypatch.setattr(asnn.warmup, "compile_kernels", loaded.append)
    for preset_name in ("translation", None):
        with Worker(zenoh_net.hub, WorkerCore(preset=preset_name), stats_every=0):
            pass
    assert loaded == [(preset("translation"),), (preset(DEFAULT_PRESET),)]


def test_camera_sources_open_files_scenes_and_fail_clearly(tmp_path):
    scene = make_scene("looming", size=(64, 48))
    path = tmp_path / "clip.avi"
    write_video(scene.frames, path, fps=25.0)
    source = open_source(str(path))
    frames = list(source.frames())
    assert source.fps == 25.0 and not source.live
    assert len(frames) == len(scene.frames) and frames[0].shape[:2] == (48, 64)
    assert len(list(open_source("synthetic:receding").frames())) == len(make_scene("receding")
                                                                          .frames)
    os.symlink(path, tmp_path / "0")  # a file named as a device index is the file
    cwd = os.getcwd()
    try:
        os.chdir(tmp_path)
        assert not open_source("0").live
    finally:
        os.chdir(cwd)
    for bad in (str(tmp_path / "missing.mp4"), "synthetic:nothing", "rtsp://127.0.0.1:1/none"):
        with pytest.raises(SourceError):
            open_source(bad)


def test_a_capture_devices_node_opens_the_device_not_a_file(monkeypatch):
    # /dev/video0 was opened as a video file, and a device is none: "no such file"
    import cv2

    from asnn.io import sources

    opened = []

    class Capture:
        def __init__(self, which):
            opened.append(which)

        def isOpened(self):
            return False

    monkeypatch.setattr(cv2, "VideoCapture", Capture)  # sources imports it where it opens one
    monkeypatch.setattr(sources, "_is_device", lambda path: path.startswith("/dev/"))
    for spec in ("/dev/video7", "/dev/null", "7"):
        with pytest.raises(SourceError, match="cannot open capture"):
            open_source(spec)
    assert opened == [7, "/dev/null", 7]  # a V4L2 node by its index, as every backend takes it


def test_a_camera_device_that_is_not_there_is_one_line_of_ours_not_opencv_s_warnings():
    """A new user's ``asnn camera --source 7`` printed two of OpenCV's ``[ WARN:0@...]`` lines
    (each backend it tried) before the camera's own error; its log level is restored after."""
    from asnn.io.video import _log_level_calls

    index = next(str(i) for i in range(7, 64) if not os.path.exists(f"/dev/video{i}"))
    done = subprocess.run([sys.executable, "-m", "cli.main", "camera", "--robot", "r1",
                           "--source", index, "--wait", "0"], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.splitlines() == [f"asnn camera: cannot open capture source '{index}'"]
    get, put, _ = _log_level_calls()
    level = get()
    put(level + 1)  # a level of the caller's own, not OpenCV's default
    try:
        with pytest.raises(SourceError, match="cannot open capture"):
            open_source(index)
        assert get() == level + 1
    finally:
        put(level)


def test_opencv_s_log_is_held_to_its_errors_in_a_block_and_never_made_louder():
    """quiet_opencv lowers OpenCV's level to ERROR for the block and restores it, also when the
    block raises; a level already quieter (a user's OPENCV_LOG_LEVEL=SILENT) stays as it is: it
    was raised to ERROR."""
    from asnn.io.video import _log_level_calls, quiet_opencv

    get, put, error = _log_level_calls()
    level = get()
    try:
        for before in (error + 1, error, 0):  # WARNING, ERROR, SILENT
            put(before)
            with pytest.raises(RuntimeError), quiet_opencv():
                assert get() == min(before, error)
                raise RuntimeError("the block fails")
            assert get() == before
        # two blocks that end out of order (two threads opening captures): the level comes
        # back once both end, not the one the second found, which was the first's ERROR
        put(error + 1)
        first, second = quiet_opencv(), quiet_opencv()
        first.__enter__()
        second.__enter__()
        first.__exit__(None, None, None)
        assert get() == error  # the second block still runs
        second.__exit__(None, None, None)
        assert get() == error + 1
    finally:
        put(level)


def test_demo_prints_warnings_and_exits_0(capsys):
    assert main(["demo", "--fps", "100"]) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if "WARNING robot demo" in line]
    assert "77 frames published" in out
    # the default scene is an approach at constant speed: the default tracks its target and
    # the time to contact it reports shrinks as the disk nears
    ttc = [float(re.search(r"contact in ([0-9.]+) s", line).group(1)) for line in lines
           if "contact in" in line]
    assert len(ttc) >= 10 and ttc[-1] < 0.6 * ttc[0]


def test_demo_plays_the_papers_scenes_and_rejects_unknown_ones(capsys):
    assert main(["demo", "--fps", "100", "--scene", "translating_bar"]) == 0
    out = capsys.readouterr().out
    assert "70 frames published" in out and "WARNING robot demo" not in out
    assert main(["demo", "--scene", "nothing"]) == 2
    assert "unknown scene 'nothing'" in capsys.readouterr().err


def test_each_networked_command_s_error_names_the_command(tmp_path, capsys):
    """A CLI trial: every networked command's error began `asnn: error:`, so that among a
    camera's and a status check's lines in one journal the failed one could not be told; each
    is now named as asnn detect names its own (`asnn detect: ...`), before any session opens."""
    missing = tmp_path / "none.mp4"
    assert main(["camera", "--robot", "r1", "--source", str(missing), "--wait", "0"]) == 2
    assert capsys.readouterr().err.splitlines() == [f"asnn camera: {missing}: no such file"]
    assert main(["status", "--connect", "foo"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith('asnn status: Zenoh rejects connect/endpoints = ["foo"]: '), line


def _warning(seq: int = 0) -> Response:
    return Response(robot="r1", seq=seq, stamp=1.0, model="asnn", preset="p", u=1.0, out=0.9,
                    spikes=3, spike_rate=60.0, collision=True, targets=[], worker="w",
                    latency_ms=1.0, dropped=0)


def test_a_reader_that_stops_reading_holds_no_zenoh_thread_and_loses_warnings_counted(caplog):
    """A write that blocks (a pager, a stalled journal) held Zenoh's callback threads, and with
    them Ctrl-C, until the reader went away (an integrator's trial)."""
    from clients.alerts import LinePrinter

    entered, release = threading.Event(), threading.Event()

    class Stalled(io.StringIO):
        def write(self, text):
            entered.set()
            release.wait()
            return super().write(text)

    show = LinePrinter(True, Stalled(), max_lines=5)
    show(_warning(0))
    assert entered.wait(30)  # the first line is in the write that blocks

    def more():
        for seq in range(1, 20):
            show(_warning(seq))

    with caplog.at_level(logging.WARNING, logger="asnn.alerts"):
        calls = threading.Thread(target=more, daemon=True)
        calls.start()
        calls.join(60)
    assert not calls.is_alive()  # the handler returned: it never waited on the output
    assert show.unprinted == 14  # the latest five lines wait, the fourteen before are dropped
    assert [json.loads(line)["seq"] for line in show._lines] == [15, 16, 17, 18, 19]
    assert "read slower than warnings come: 1 older warnings not printed" in caplog.text
    assert show.close(timeout=0.2) is False and show.unprinted == 20  # the blocked one too
    release.set()


def test_a_failed_write_stops_the_printing_and_says_so_once():
    from clients.alerts import LinePrinter

    class Gone(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

    stopped = threading.Event()
    show = LinePrinter(False, Gone(), on_error=stopped.set)
    show(_warning(0))
    assert stopped.wait(10)
    show(_warning(1))
    assert show.close() and isinstance(show.error, BrokenPipeError) and show.unprinted == 2


def test_demo_piped_into_head_ends_quietly_with_the_pipe_s_status():
    """`asnn demo | head -2` printed a BrokenPipe traceback for every later warning."""
    demo = subprocess.Popen([sys.executable, "-m", "cli.main", "demo", "--json", "--fps", "100"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    first = demo.stdout.readline()
    assert json.loads(first)["collision"] is True
    demo.stdout.close()
    _, err = demo.communicate(timeout=300)
    assert demo.returncode == 141, err.decode()
    assert b"Traceback" not in err and b"warning handler failed" not in err


# ---------------------------------------------------------------- separate processes

def test_router_worker_camera_alerts_as_separate_processes(procs, tmp_path):
    fleet = Fleet(procs, tmp_path,
                  "{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }")
    router, worker, alerts, common = fleet.router, fleet.worker, fleet.alerts, fleet.common
    loom = procs("camera", "--robot", "loom", "--source", "synthetic:looming", "--fps", "40",
                 "--wait", str(TIMEOUT), *common)
    bar = procs("camera", "--robot", "bar", "--source", "synthetic:translating_bar",
                "--format", "jpeg", "--fps", "40", "--wait", str(TIMEOUT), *common)
    assert loom.popen.wait(timeout=60) == 0 and bar.popen.wait(timeout=60) == 0
    scene = make_scene("looming")

    def warned_late_enough():  # the clip's warnings last to frame ~58 (see test_worker)
        return any(json.loads(line)["seq"] >= scene.contact_frame for line in alerts.out)

    wait_for(warned_late_enough, what="the warnings near the end of the clip")
    assert alerts.stop() == 0
    assert worker.stop(signal.SIGTERM) == 0
    assert router.stop() == 0
    warnings = [json.loads(line) for line in alerts.out]
    assert {w["robot"] for w in warnings} == {"loom"}
    first = min(w["seq"] for w in warnings)
    assert scene.onset_frame <= first <= scene.contact_frame
    assert all(w["collision"] and w["worker"] == "w1" for w in warnings)
    assert any(w["targets"] for w in warnings)
    assert "worker stopped" in "\n".join(worker.err)


def test_worker_threads_option():
    from cli.main import build_parser

    assert build_parser().parse_args(["worker", "--threads", "2"]).threads == 2
    # by default one per core this process may use
    assert build_parser().parse_args(["worker"]).threads == len(os.sched_getaffinity(0))
    with pytest.raises(SystemExit):
        build_parser().parse_args(["worker", "--threads", "0"])


@pytest.mark.parametrize("command", ["worker", "demo"])
def test_the_service_takes_a_preset_with_fields_changed_as_detect_does(command, capsys):
    """The README's advice for a camera (``robust/ignore_rig=false`` for a still one) could be
    followed offline only: the worker and the demo took preset names alone (a docs audit)."""
    from cli.main import build_parser

    spec = "robust/ignore_rig=false"
    assert build_parser().parse_args([command, "--preset", spec]).preset == spec
    with pytest.raises(SystemExit):
        build_parser().parse_args([command, "--preset", "robust/ignore_rig=maybe"])
    assert "'robust/ignore_rig=maybe': ignore_rig: Input should be a valid boolean" in \
        capsys.readouterr().err
    core = WorkerCore(preset=spec)
    looming = make_scene("looming")
    assert core.offer("asnn/r1/frame", encode(Frame.from_image(looming.frames[0], seq=0,
                                                                stamp=0.0))) == "r1"
    response = core.process(core.take())
    assert response.preset == spec and core._robots["r1"].detector.params.ignore_rig is False


def test_every_networked_command_takes_the_contract_s_common_options(capsys):
    # CONTRACT.md: --connect, --listen, --mode, --config, --prefix on every networked command;
    # the router is a router (--mode peer there was "unrecognized arguments", now a clear no)
    from cli.main import build_parser

    common = ["--connect", "tcp/127.0.0.1:7447", "--listen", "tcp/127.0.0.1:0",
              "--config", "zenoh.json5", "--prefix", "fleet/a"]
    for command, mode in (("camera --robot r1 --source scene:looming", "client"),
                          ("worker", "client"), ("alerts", "peer"), ("status", "client"),
                          ("dashboard", "client"), ("foxglove", "client"), ("router", "router")):
        args = build_parser().parse_args([*command.split(), *common, "--mode", mode])
        assert (args.connect, args.listen, args.mode, args.config, args.prefix) == (
            ["tcp/127.0.0.1:7447"], ["tcp/127.0.0.1:0"], mode, "zenoh.json5", "fleet/a")
    with pytest.raises(SystemExit):
        build_parser().parse_args(["router", "--mode", "peer"])
    assert "invalid choice: 'peer' (choose from 'router')" in capsys.readouterr().err


@pytest.mark.parametrize("args, says", [
    (["worker", "--max-robots", str(10**27)], "--max-robots: must be at most 4096"),
    (["foxglove", "--max-robots", str(10**20)], "--max-robots: must be at most 4096"),
    (["worker", "--warmup-frames", str(10**23)], "--warmup-frames: must be at most 10000"),
    (["alerts", "--prefix", "a" * 5000], "key prefix of 5000 characters: at most 256"),
])
def test_sizes_a_process_keeps_places_for_are_bounded(capsys, args, says):
    # a CLI sweep: each was taken (a worker's routing table is sized by --max-robots)
    from cli.main import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(args)
    assert says in capsys.readouterr().err


def test_tune_process_shortens_the_switch_interval():
    import sys

    import cv2

    from service.worker import SWITCH_INTERVAL, tune_process

    before = sys.getswitchinterval(), cv2.getNumThreads()
    try:
        tune_process()
        assert sys.getswitchinterval() == pytest.approx(SWITCH_INTERVAL)
        assert cv2.getNumThreads() == 1
    finally:
        sys.setswitchinterval(before[0])
        cv2.setNumThreads(before[1])


def test_demo_on_a_fresh_install_warns(fresh_install_demo):
    """README's first command on a new machine: nothing compiled yet (an empty numba cache).
    The worker compiles before it takes frames, so the looming clip still raises warnings.
    The command starts first in the session, in the session's own cache while that is still
    empty (tests/conftest.py, fresh_install_demo)."""
    proc = fresh_install_demo.result()
    assert proc.returncode == 0, proc.stderr[-2000:]
    summary = proc.stdout.strip().splitlines()[-1]  # "60 frames published, ..., N warnings received"
    assert summary.endswith("warnings received"), summary
    assert int(summary.split(",")[-1].split()[0]) > 10, summary


@pytest.mark.parametrize("rust_log", ["debug", "zenoh=trace", "warn,zenoh=DEBUG", "zenoh", "5",
                                      "zenoh::api=4", "zenoh::api::session"])
def test_zenoh_s_debug_log_keeps_a_client_s_password_out(tmp_path, rust_log):
    """A security review: RUST_LOG=debug (README: Zenoh's own logs) wrote the session's whole
    configuration, its usrpwd password with it, to stderr and so to the journal."""
    import os
    import subprocess
    import sys

    from service.demo import free_port

    config = tmp_path / "client.json5"
    config.write_text('{transport: {auth: {usrpwd: {user: "worker", password: "S3CRETPW"}}}}')
    env = {**os.environ, "RUST_LOG": rust_log}
    proc = subprocess.run([sys.executable, "-m", "cli.main", "status", "--config", str(config),
                           "--connect", f"tcp/127.0.0.1:{free_port()}", "--mode", "client",
                           "--timeout", "1"], env=env, timeout=120, capture_output=True,
                          text=True)
    assert proc.returncode == 2 and "cannot open a Zenoh session" in proc.stderr
    written = proc.stdout + proc.stderr  # Zenoh logs to stdout
    assert "zenoh::api::session" in written  # Zenoh's log is written, that target at INFO
    assert "S3CRETPW" not in written


def test_a_quiet_rust_log_is_left_as_it_is():
    from cli.session import _asks_debug

    for quiet in ("", "warn", "zenoh=info", "error,zenoh::net=3", " off , ", "zenoh=0", "OFF",
                  "zenoh=Info", "WARN,zenoh::net=Error"):  # tracing reads levels in any case
        assert not _asks_debug(quiet), quiet
    for loud in ("debug", "zenoh", "zenoh=5", "warn,zenoh::api=TRACE", "[span]=debug"):
        assert _asks_debug(loud), loud



@pytest.mark.parametrize("rust_log", [None, "", "off"])
def test_zenoh_s_log_stays_off_where_rust_log_does_not_ask_for_it(rust_log):
    """README: Zenoh's own logs only when RUST_LOG is set (the target kept at INFO is added
    only to a RUST_LOG that may enable DEBUG: added to none, it turned Zenoh's log on)."""
    import os
    import subprocess
    import sys

    from service.demo import free_port

    env = {k: v for k, v in os.environ.items() if k != "RUST_LOG"}
    if rust_log is not None:
        env["RUST_LOG"] = rust_log
    proc = subprocess.run([sys.executable, "-m", "cli.main", "status", "--connect",
                           f"tcp/127.0.0.1:{free_port()}", "--mode", "client", "--timeout", "1"],
                          env=env, timeout=120, capture_output=True, text=True)
    assert proc.returncode == 2 and "cannot open a Zenoh session" in proc.stderr
    assert "zenoh::" not in proc.stdout + proc.stderr

def test_worker_scan_and_handover_options_are_checked(capsys):
    from cli.main import build_parser

    args = build_parser().parse_args(["worker"])
    assert (args.warmup_frames, args.scan_interval, args.handover_timeout) == (
        HANDOVER_WARMUP_FRAMES, 1.0, 5.0)
    for bad in (["--warmup-frames", "-1"], ["--scan-interval", "-1"],
                ["--handover-timeout", "x"]):
        with pytest.raises(SystemExit):
            build_parser().parse_args(["worker", *bad])
    # a scan shorter than its window: one line, exit 2, before any session is opened
    assert main(["worker", "--scan-interval", "0.05"]) == 2
    assert "must be longer than its window" in capsys.readouterr().err


def test_a_camera_counts_the_frames_it_published_while_no_subscriber_took_them(zenoh_net):
    """A failover trial: locked out of its router, a camera's exit line said "4285 frames
    published; rejected: none", a quarter of them into nothing."""
    from service.camera import SubscriberWatch

    source = open_source("synthetic:looming")
    watch = SubscriberWatch("r8", keys.frame_key("r8"))
    assert publish_frames(zenoh_net.spoke(), "r8", source, fps=200, max_frames=5,
                          preview_hz=0, subscribers=watch) == 5
    assert watch.unheard == 5  # nobody subscribed
    sub = zenoh_net.hub.declare_subscriber(  # noqa: F841 (kept declared)
        keys.frame_key("r8"), lambda sample: None)
    watch = SubscriberWatch("r8", keys.frame_key("r8"))
    assert publish_frames(zenoh_net.spoke(), "r8", source, fps=200, max_frames=5, wait=5.0,
                          preview_hz=0, subscribers=watch) == 5
    assert watch.unheard == 0 and watch.matching is True


def test_a_file_without_a_camera_s_frame_rate_is_replayed_at_20_fps_with_a_warning(
        zenoh_net, tmp_path, caplog):
    path = tmp_path / "base.avi"  # a container's time base read as its frame rate
    write_video(make_scene("looming", size=(64, 48), frames=4).frames, path, fps=1000.0)
    source = open_source(str(path))
    with caplog.at_level("WARNING", logger="asnn.camera"):
        assert publish_frames(zenoh_net.spoke(), "r8", source, max_frames=2) == 2
    assert "states 1000 frames a second, more than a camera runs at (a stated rate is taken " \
           "up to 240)" in caplog.text
    assert "at 20.0 fps (set --fps)" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING", logger="asnn.camera"):
        assert publish_frames(zenoh_net.spoke(), "r8", source, fps=100, max_frames=2) == 2
    assert "frame rate" not in caplog.text  # --fps given: nothing guessed


def test_a_camera_stopped_while_it_waits_publishes_nothing_and_blames_no_subscriber(
        zenoh_net, caplog):
    _, source = scene_source("looming", start=2, stop=8, frames=10)
    stop = threading.Event()
    threading.Timer(0.3, stop.set).start()
    with caplog.at_level("INFO", logger="asnn.camera"):
        assert publish_frames(zenoh_net.spoke(), "r11", source, wait=30.0, stop=stop) == 0
    assert "no subscriber" not in caplog.text and "fps as" not in caplog.text
    with pytest.raises(SystemExit):  # a wait cannot be negative
        main(["camera", "--robot", "r11", "--source", "synthetic:looming", "--wait", "-5"])


def test_ctrl_c_while_the_commands_load_or_a_worker_compiles_is_an_interrupt(
        procs, tmp_path, monkeypatch, capsys):
    """The commands' modules take seconds to import, and a worker's first compile up to a
    minute: Ctrl-C then stops the process at once, as an interrupt (status 130, one line)."""
    import cli.main

    def importing(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli.main, "build_parser", importing)
    try:
        code = main(["status"])
    except KeyboardInterrupt:  # out of main: a traceback (pytest would stop here)
        code = "raised"
    assert code == 130
    assert capsys.readouterr().err.strip() == "asnn: interrupted"
    monkeypatch.undo()
    from service.demo import free_port

    config, endpoint = tmp_path / "zenoh.json5", f"tcp/127.0.0.1:{free_port()}"
    config.write_text("{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }")
    procs("router", "--listen", endpoint, "--config", str(config)).wait_line("listening on")
    worker = procs("worker", "--config", str(config), "--connect", endpoint, "--mode", "client",
                   env={"NUMBA_CACHE_DIR": str(tmp_path / "cold")})
    worker.wait_line("loading the model's kernels", timeout=60)
    assert worker.stop(signal.SIGINT) == 130, "\n".join(worker.err[-20:])
    assert "asnn: interrupted" in worker.err
    assert not any("kernels ready" in line or line.endswith(" ready") for line in worker.err)


def test_the_camera_waits_for_a_subscriber_that_comes_late_and_loses_no_frame(zenoh_net, caplog):
    got = []
    camera = zenoh_net.spoke()
    late = threading.Timer(0.5, lambda: got.append(zenoh_net.hub.declare_subscriber(
        keys.frame_key("r9"), lambda sample: got.append(sample.payload.to_bytes()))))
    late.start()
    scene, source = scene_source("looming", start=2, stop=8, frames=10)
    assert publish_frames(camera, "r9", source, fps=100, wait=30.0, preview_hz=0) == 10
    late.join()
    wait_for(lambda: len(got) == 1 + 10, what="every frame, the first ones included")
    assert [decode_frame(p).seq for p in got[1:]] == list(range(10))
    # nobody there: it says so, then publishes anyway
    with caplog.at_level("WARNING", logger="asnn.camera"):
        assert publish_frames(camera, "r10", source, fps=100, wait=0.3, preview_hz=0) == 10
    assert "no subscriber on asnn/r10/frame after 0.3 s; publishing anyway" in caplog.text


def test_a_camera_says_when_its_frames_lose_their_last_subscriber_and_get_one_again(
        zenoh_net, caplog):
    # a soak trial: with its worker killed, a camera published into nothing without a word
    camera, got = zenoh_net.spoke(), []
    take = lambda sample: got.append(sample)  # noqa: E731
    subscriber = zenoh_net.hub.declare_subscriber(keys.frame_key("r12"), take)
    _, source = scene_source("looming", start=2, stop=8, frames=10)
    stop = threading.Event()
    with caplog.at_level("INFO", logger="asnn.camera"):
        thread = threading.Thread(target=publish_frames, args=(camera, "r12", source),
                                  kwargs=dict(fps=50, loop=True, wait=30.0, stop=stop,
                                              preview_hz=0), daemon=True)
        thread.start()
        try:
            wait_for(lambda: len(got) >= 3, what="frames at the worker")
            subscriber.undeclare()  # the worker goes
            gone = "camera r12: no subscriber on asnn/r12/frame any more"
            wait_for(lambda: gone in caplog.text, what="the camera saying its frames go nowhere")
            subscriber = zenoh_net.hub.declare_subscriber(keys.frame_key("r12"), take)
            back = "camera r12: a subscriber (a worker) takes its frames on asnn/r12/frame"
            wait_for(lambda: back in caplog.text, what="the camera saying a worker is back")
        finally:
            stop.set()
            thread.join(timeout=TIMEOUT)
    assert caplog.text.count(gone) == 1 and caplog.text.count(back) == 1
    assert caplog.text.index(gone) < caplog.text.index(back)


def test_the_camera_announces_itself_while_it_publishes(zenoh_net):
    seen = []
    sub = zenoh_net.hub.liveliness().declare_subscriber(  # noqa: F841 (kept declared)
        keys.camera_tokens(), lambda s: seen.append((str(s.key_expr), s.kind)), history=True)
    scene, source = scene_source("looming", start=2, stop=8, frames=10)
    assert publish_frames(zenoh_net.spoke(), "r7", source, fps=100, preview_hz=0) == 10
    wait_for(lambda: len(seen) >= 2, what="the announcement and its end")
    assert seen == [("asnn/@camera/r7", zenoh.SampleKind.PUT),
                    ("asnn/@camera/r7", zenoh.SampleKind.DELETE)]


def test_a_camera_whose_frames_the_worker_refuses_is_told_why(zenoh_net, caplog):
    core = WorkerCore(max_robots=1)
    with Worker(zenoh_net.hub, core, stats_every=0):
        responses = Responses(zenoh_net.spoke())
        scene, source = scene_source("looming")
        send_one(zenoh_net.spoke(), responses, "first", scene.frames[0], 0)  # takes the slot
        refusals, stop = RefusalNotices("second"), threading.Event()
        camera = threading.Thread(target=publish_frames, args=(zenoh_net.spoke(), "second", source),
                                  kwargs=dict(fps=40, loop=True, stop=stop, refusals=refusals,
                                              wait=TIMEOUT))
        with caplog.at_level("WARNING", logger="asnn.camera"):
            camera.start()
            try:
                wait_for(lambda: refusals.latest, what="the worker's notice")
                # notices that are not valid refusals of this robot are counted and ignored
                zenoh_net.hub.put(keys.refusal_key("second"), b"junk")
                zenoh_net.hub.put(keys.refusal_key("second"), msgpack.packb(
                    {"v": 1, "robot": "other", "worker": "w", "reason": "r", "detail": "",
                     "count": 1}))
                wait_for(lambda: refusals.invalid == 2, what="the junk notices")
            finally:
                stop.set()
                camera.join(timeout=TIMEOUT)
    worker, (reason, count) = next(iter(refusals.latest.items()))
    assert (worker, reason) == (core.worker_id, "too-many-robots") and count >= 1
    assert refusals.summary() == f"{count} by {core.worker_id!r} (latest too-many-robots)"
    assert (f"camera second: worker '{core.worker_id}' refuses frames on this robot's key "
            "('too-many-robots', " in caplog.text) and "'already tracking 1 robots'" in caplog.text


def test_refusal_notices_keep_each_workers_latest_and_log_one_line_whatever_they_say(caplog):
    from types import SimpleNamespace

    def sample(**fields):
        fields = {"robot": "r1", "worker": "w1", "detail": "", **fields}
        payload = msgpack.packb({"v": 1, **fields})
        return SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda: payload))

    notices = RefusalNotices("r1")
    with caplog.at_level("WARNING", logger="asnn.camera"):
        notices(sample(reason="late", count=10, detail="a\nfake log line"))
        notices(sample(reason="second-publisher", count=11))  # the count is the worker's total
        for k in range(50):  # a flood of made-up reasons (an open router): one line, not 50
            notices(sample(reason=f"made-up-{k}", count=12 + k))
        notices(sample(reason="not\na label", count=99))  # not a Refusal: ignored
    assert notices.summary() == "61 by 'w1' (latest made-up-49)" and notices.invalid == 1
    lines = [r.getMessage() for r in caplog.records if "refuses frames" in r.getMessage()]
    assert len(lines) == 1 and "\n" not in lines[0]  # its text shown as data, on one line


def test_a_camera_says_once_when_the_refusals_are_over(caplog):
    """A refused camera later served logged nothing when the refusals stopped: its last line
    still read "refuses" (a fleet trial)."""
    from types import SimpleNamespace

    from service.camera import REFUSALS_OVER_S

    now = [100.0]
    payload = msgpack.packb({"v": 1, "robot": "r1", "worker": "w1", "detail": "",
                             "reason": "too-many-robots", "count": 3})
    notices = RefusalNotices("r1", clock=lambda: now[0])
    assert not notices.check_quiet()  # never refused: nothing to say
    with caplog.at_level("INFO", logger="asnn.camera"):
        notices(SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda: payload)))
        now[0] += REFUSALS_OVER_S - 1
        assert not notices.check_quiet()  # the worker's next notice may still come
        now[0] += 2
        assert notices.check_quiet() and not notices.check_quiet()  # said once
    over = [r for r in caplog.records if "no worker has refused" in r.getMessage()]
    assert len(over) == 1 and over[0].levelname == "INFO"


def test_the_alerts_take_a_warning_only_for_the_robot_of_its_key_and_with_collision(zenoh_net):
    from test_dashboard import response

    warnings = []
    with WarningListener(zenoh_net.spoke(), warnings.append) as listener:
        publisher = zenoh_net.hub.declare_publisher("asnn/r1/warning")
        wait_for(lambda: publisher.matching_status.matching, what="the listener")
        publisher.put(encode(response("r2", seq=1, collision=True)))  # another robot's
        publisher.put(encode(response("r1", seq=2, collision=False)))  # no collision
        publisher.put(encode(response("r1", seq=3, collision=True)))
        # one ordered publisher: the refused two were handled before the valid one arrived
        wait_for(lambda: warnings, what="the valid warning")
    assert [(w.robot, w.seq) for w in warnings] == [("r1", 3)]
    assert listener.invalid == {"bad-key": 1, "invalid-field": 1}


def test_warnings_missed_beyond_recovery_are_said_not_only_seen_as_a_gap(zenoh_net, caplog):
    """An integrator's trial: alerts stopped for 4 s (a lease of 1 s) lost 51 warnings, which
    Zenoh's advanced subscriber knew of, and said nothing."""
    with WarningListener(zenoh_net.spoke(), lambda r: None) as listener:
        # the plain subscriber, the advanced one and its miss listener, all closed with it
        from zenoh.ext import AdvancedSubscriber, SampleMissListener

        assert [type(s) for s in listener._subscribers[1:]] == [AdvancedSubscriber,
                                                               SampleMissListener]
        with caplog.at_level(logging.WARNING, logger="asnn.alerts"):
            listener._on_miss(51, "9c9e/17")
            listener._on_miss(3, "9c9e/17")  # within 10 s of the first: counted, not logged
    assert listener.missed == 54
    lines = [r.getMessage() for r in caplog.records if "missed" in r.getMessage()]
    assert lines == ["51 warnings of publisher 9c9e/17 were missed and could not be recovered "
                     "(51 in all): was this subscriber cut off from the router?"]


def test_a_camera_says_at_most_a_line_of_each_kind_when_its_subscriber_comes_and_goes(caplog):
    """A review: with several workers, the scanning one subscribes to every robot's frames for
    0.1 s every second, so a camera that no worker serves logged 'a subscriber takes its
    frames' and 'no subscriber any more' each second, for as long as it ran."""
    from types import SimpleNamespace

    from service.camera import SubscriberWatch

    now = [0.0]
    watch = SubscriberWatch("r1", "asnn/r1/frame", False, interval=10.0, clock=lambda: now[0])
    gone, back = "no subscriber on asnn/r1/frame any more", "a subscriber (a worker) takes"
    with caplog.at_level("INFO", logger="asnn.camera"):
        for _ in range(9):  # nine scans, a second apart
            watch(SimpleNamespace(matching=True))
            now[0] += 0.1
            watch(SimpleNamespace(matching=False))
            now[0] += 0.9
        assert caplog.text.count(back) == 1 and caplog.text.count(gone) == 1
        now[0] += 10.0
        watch(SimpleNamespace(matching=True))
        watch(SimpleNamespace(matching=True))  # no change: nothing to say
    assert caplog.text.count(back) == 2
    assert "(8 more times since the last such line" in caplog.text
    assert watch.matching is True


def test_the_camera_s_exit_line_counts_the_frames_no_subscriber_took(tmp_path, caplog):
    """A mutation probe: the exit line of ``asnn camera`` with nobody subscribed says how many
    of its frames went into nothing, and its rejections' summary, in order of reason."""
    from service.camera import SourceRejections
    from service.demo import free_port

    config = tmp_path / "peer.json5"
    config.write_text("{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }")
    with caplog.at_level("INFO", logger="asnn"):
        assert main(["camera", "--robot", "r9", "--source", "synthetic:looming", "--fps", "240",
                     "--mode", "peer", "--listen", f"tcp/127.0.0.1:{free_port()}",
                     "--config", str(config)]) == 0
    (line,) = [r.getMessage() for r in caplog.records if "frames published" in r.getMessage()]
    count = int(line.split("camera r9: ")[1].split()[0])
    assert count > 0
    assert f"{count} frames published ({count} while no subscriber took them: lost); " \
           "rejected: none; workers' refusals" in line
    rejections = SourceRejections("r9")
    rejections("undecodable", "frame 3")
    rejections("stamp-backwards", "frame 4")
    rejections("undecodable", "frame 5")
    assert rejections.summary() == "rejected: stamp-backwards 1, undecodable 2"
