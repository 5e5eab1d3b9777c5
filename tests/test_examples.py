"""The stand-alone clients of examples/ (a camera and a warning subscriber written from
docs/contract.md alone) run as an integrator would run them, against ``asnn router`` and
``asnn worker`` processes on a free loopback port, multicast scouting and gossip off.

Waits are generous timeouts on what the processes print, never timing assertions.
"""

import json
import re

import pytest

from asnn.io.video import write_video
from asnn.stimuli import make_scene

from netutil import TIMEOUT, Fleet, wait_for
from test_layers import LAYERS, ROOT, imported_modules

EXAMPLES = ROOT / "examples"
CONSUMER, PUBLISHER = EXAMPLES / "warning_consumer.py", EXAMPLES / "frame_publisher.py"
NO_SCOUTING = "{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }"
# the consumer's line: kind robot=R seq=N stamp=S collision=B targets=K [id=I x=X y=Y ttc=T] ...
LINE = re.compile(r"(\w+) robot=(\S+) seq=(\d+) stamp=\S+ collision=(True|False) targets=(\d+)")
TARGET = re.compile(r"\[id=(\S+) x=(\S+) y=(\S+) ttc=(\S+)\]")


def printed(consumer, kind):
    """The consumer's lines of one kind: (robot, seq, collision, targets) with each target's
    (id, x, y, ttc) as printed."""
    found = []
    for line in list(consumer.out):
        m = LINE.match(line)
        if m and m[1] == kind:
            targets = TARGET.findall(line[m.end():])
            assert len(targets) == int(m[5]), line
            found.append((m[2], int(m[3]), m[4] == "True", targets))
    return found


@pytest.mark.parametrize("example", [CONSUMER, PUBLISHER], ids=lambda p: p.name)
def test_an_example_imports_none_of_the_project_s_packages(example):
    modules = imported_modules(example)
    assert {"zenoh", "msgpack"} <= modules  # the file was read
    assert sorted(m for m in modules if m.split(".")[0] in (*LAYERS, "tests", "netutil")) == []


def test_the_example_camera_s_clip_warns_in_the_example_subscriber(procs, tmp_path):
    scene = make_scene("looming")
    clip = write_video(scene.frames, tmp_path / "looming.mp4", fps=scene.fps)
    fleet = Fleet(procs, tmp_path, NO_SCOUTING)  # a router, worker w1 and asnn alerts --json
    connect = ["--connect", fleet.endpoint]
    consumer = procs(str(CONSUMER), *connect, "--responses", program=())
    consumer.wait_line("listening on")
    cameras = {"gray": procs(str(PUBLISHER), str(clip), "--robot", "gray", *connect,
                             "--wait", str(TIMEOUT), program=()),
               "jpeg": procs(str(PUBLISHER), str(clip), "--robot", "jpeg", "--jpeg", *connect,
                             "--wait", str(TIMEOUT), program=())}
    for robot, camera in cameras.items():
        assert camera.popen.wait(timeout=60) == 0, "\n".join(camera.err)
        camera.wait_line(f"publishing on asnn/{robot}/frame at 20 fps (a worker)")
        camera.wait_line(f"sent {len(scene.frames)} frames")

    def warned_with_a_target():
        return {robot for robot, _, collision, targets in printed(consumer, "warning")
                if collision and targets} == set(cameras)

    wait_for(warned_with_a_target, what="a warning with a target for each camera")

    def warned(kind="warning"):
        return {(robot, seq) for robot, seq, collision, _ in printed(consumer, kind) if collision}

    # the warnings asnn alerts received, and no other; each one among the responses too
    wait_for(lambda: warned() == {(w["robot"], w["seq"]) for w in map(json.loads,
                                                                        list(fleet.alerts.out))},
             what="the warnings asnn alerts received")
    wait_for(lambda: warned() <= warned("response"), what="the warnings' responses")
    assert consumer.stop() == 0  # Ctrl-C
    assert not [line for line in consumer.err if "Traceback" in line or "invalid" in line]
    assert [line for line in consumer.out if not LINE.match(line)] == []  # one line a message
    height, width = scene.frames.shape[1:]
    for robot in cameras:
        warnings = [w for w in printed(consumer, "warning") if w[0] == robot]
        assert all(collision for _, _, collision, _ in warnings)
        assert min(seq for _, seq, _, _ in warnings) >= scene.onset_frame  # seq counts frames
        # the default preset's targets carry an id and a time to contact; x, y in the frame
        for target_id, x, y, ttc in (t for _, _, _, targets in warnings for t in targets):
            assert int(target_id) >= 0 and float(ttc) > 0
            assert 0 <= float(x) < width and 0 <= float(y) < height
        # the frames before the approach answered, and quiet
        early = [collision for r, seq, collision, _ in printed(consumer, "response")
                 if r == robot and seq < scene.onset_frame]
        assert early and not any(early)
