"""The fleet dashboard without a browser: the store (no Zenoh), the HTTP server and its event
stream, the preview message and the camera's preview publishing, and the ``asnn dashboard``
command as a process, and the page's freshness rule in node. The page itself is tested in
headless Chromium (test_dashboard_browser).
"""

from __future__ import annotations

import http.client
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import pytest

from asnn.stimuli import make_scene
from cli.main import build_parser
from clients.dashboard import STATIC_FILES, DashboardServer, FleetStore, FleetSubscriber
from service import keys
from service.camera import Source, publish_frames
from service.demo import free_port
from service.messages import Preview, Refusal, Response, TargetMsg, decode_preview, encode
from service.streams import CONTESTED_FOR_S

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 20.0


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def response(robot="r1", seq=0, stamp=None, collision=False, rate=0.0, targets=()):
    return Response(robot=robot, seq=seq, stamp=1000.0 + seq * 0.05 if stamp is None else stamp,
                    model="asnn", preset="default", u=1.0, out=0.9 if collision else 0.1,
                    spikes=1, spike_rate=rate, collision=collision, worker="w1",
                    latency_ms=2.0, dropped=0,
                    targets=[TargetMsg(x=x, y=y, direction=0.0, energy=1.0, pixels=50)
                             for x, y in targets])


def preview(seq=0, size=(64, 48), stamp=None):
    """A thumbnail of the frame ``response(seq=seq)`` answers (its stamp, unless given)."""
    image = np.zeros(size[::-1], np.uint8)
    image[10:30, 20:40] = 255
    return Preview.from_frame_image(image, seq=seq, width=32,
                                    stamp=1000.0 + seq * 0.05 if stamp is None else stamp)


def offer_response(store, r, kind="response"):
    return store.offer(f"asnn/{r.robot}/{kind}", encode(r))


# ---------------------------------------------------------------- the store

def test_responses_make_a_tile_with_a_ten_second_spike_history():
    clock = Clock()
    store = FleetStore(clock=clock)
    for seq in range(300):  # 15 s of camera time at 20 fps
        assert offer_response(store, response(seq=seq, rate=float(seq))) == "r1"
    delta = store.delta(0)
    tile = delta["robots"]["r1"]
    assert delta["full"] and tile["responses"] == 300 and tile["response"]["seq"] == 299
    stamps = [t for t, _ in tile["points"]]
    assert stamps[-1] - stamps[0] <= 10.0 and len(stamps) >= 199
    assert tile["points"][-1] == [1000.0 + 299 * 0.05, 299.0]
    assert delta["live"]["r1"] == [0.0, False, False]
    assert delta["counts"]["received"] == {"response": 300}


def test_deltas_carry_only_what_changed_since_a_version():
    store = FleetStore(clock=Clock())
    for robot in ("a", "b"):
        offer_response(store, response(robot, 0))
    version = store.delta(0)["version"]
    offer_response(store, response("b", 1, rate=7.0))
    delta = store.delta(version)
    assert not delta["full"] and set(delta["robots"]) == {"b"}
    assert delta["robots"]["b"]["points"] == [[1000.05, 7.0]]
    assert not delta["robots"]["b"]["points_reset"]
    assert set(delta["live"]) == {"a", "b"}  # every robot's flags, every time
    assert store.delta(delta["version"])["robots"] == {}


def test_a_camera_restart_starts_a_new_spike_history():
    store = FleetStore(clock=Clock())
    for seq in range(5):
        offer_response(store, response(seq=seq))
    version = store.version
    offer_response(store, response(seq=0, stamp=900.0))  # the clock went back
    tile = store.delta(version)["robots"]["r1"]
    assert tile["points_reset"] and tile["points"] == [[900.0, 0.0]]


def test_a_late_answer_is_not_taken_for_a_camera_restart():
    """An operations trial: a worker stopped for 5 s (SIGSTOP), whose robot another took over,
    resumed and published answers to frames seconds old; the dashboard took them for a
    camera's clock going back and dropped the robot's history."""
    store = FleetStore(clock=Clock())
    for seq in range(100, 120):
        offer_response(store, response(seq=seq))
    for seq in (60, 70):  # late: before the latest, not a restart at seq 0
        offer_response(store, response(seq=seq))
    tile = store.delta(0)["robots"]["r1"]
    assert tile["response"]["seq"] == 119 and len(tile["points"]) == 20
    assert tile["responses"] == 22
    offer_response(store, response(seq=120))
    for seq in (5, 6, 7):  # a third in a row behind: the clock went back after all
        offer_response(store, response(seq=seq, stamp=500.0 + seq))
    tile = store.delta(0)["robots"]["r1"]
    assert tile["response"]["seq"] == 7 and [p[0] for p in tile["points"]] == [507.0]


def test_a_second_answer_to_a_frame_shown_is_no_restart():
    store = FleetStore(clock=Clock())
    for seq in range(5):
        offer_response(store, response(seq=seq, rate=float(seq)))
    version = store.version
    # around a hand-over the old owner answers frame 3 again, after the new owner's frame 4
    offer_response(store, response(seq=3, rate=3.0).model_copy(update={"worker": "w2"}))
    tile = store.delta(0)["robots"]["r1"]
    assert tile["response"]["seq"] == 4 and len(tile["points"]) == 5
    assert tile["responses"] == 6 and not store.delta(version)["robots"]
    offer_response(store, response(seq=5, rate=5.0))
    tile = store.delta(version)["robots"]["r1"]
    assert not tile["points_reset"] and tile["points"] == [[1000.25, 5.0]]


def test_collision_is_held_for_a_while_after_the_latest_warning_camera_clock():
    store = FleetStore(hold=3.0, clock=Clock())
    offer_response(store, response(seq=10, collision=True))
    offer_response(store, response(seq=10, collision=True), "warning")
    assert store.delta(0)["live"]["r1"][2] is True
    offer_response(store, response(seq=11, stamp=1000.0 + 10 * 0.05 + 2.9))
    assert store.delta(0)["live"]["r1"][2] is True  # 2.9 s after the warning: held
    offer_response(store, response(seq=12, stamp=1000.0 + 10 * 0.05 + 3.1))
    assert store.delta(0)["live"]["r1"][2] is False
    assert store.delta(0)["robots"]["r1"]["last_warning"]["seq"] == 10


def test_a_warning_from_before_the_camera_clock_went_back_is_not_held_for_ever():
    """A hostile review: a camera that restarted (its clock back to 0) right after a warning,
    or one warning forged with a stamp of 1e300, kept the robot in the collision state for as
    long as responses came, all saying no collision; the camera's next warnings were not
    taken as its latest."""
    clock = Clock()
    store = FleetStore(hold=3.0, clock=clock)
    for seq in range(10):
        offer_response(store, response(seq=seq, stamp=5000.0 + seq * 0.05))
    offer_response(store, response(seq=10, stamp=5000.5, collision=True), "warning")
    assert store.delta(0)["live"]["r1"][2] is True
    for seq in range(100):  # the camera restarts: its clock counts from 0
        clock.now += 0.05
        offer_response(store, response(seq=seq, stamp=seq * 0.05))
    assert store.delta(0)["live"]["r1"][2] is False
    offer_response(store, response(seq=100, stamp=5.0, collision=True), "warning")
    assert store.delta(0)["robots"]["r1"]["last_warning"] == {"seq": 100, "stamp": 5.0}
    offer_response(store, response(seq=101, stamp=5.05))
    assert store.delta(0)["live"]["r1"][2] is True  # held, on the camera's new clock
    offer_response(store, response(seq=102, stamp=1e300, collision=True), "warning")  # forged
    offer_response(store, response(seq=103, stamp=9.0))
    assert store.delta(0)["live"]["r1"][2] is False


def test_stale_when_no_response_arrives_whatever_its_camera_sends_and_then_no_collision():
    clock = Clock()
    store = FleetStore(stale_after=3.0, hold=3.0, clock=clock)
    offer_response(store, response("live", 0, collision=True))
    offer_response(store, response("old", collision=True), "warning")  # a cached warning
    live = store.delta(0)["live"]
    assert live["live"] == [0.0, False, True]
    assert live["old"] == [None, True, False]  # known only from its warning: stale, not held
    clock.now += 2.0
    store.offer("asnn/live/preview", encode(preview()))
    clock.now += 2.0
    # its camera still sends previews, but no worker answers it (it died mid-warning): the
    # previews do not make it live, and its last warning is not held on
    assert store.delta(0)["live"]["live"] == [4.0, True, False]
    assert store.delta(0)["counts"]["collision"] == 0
    offer_response(store, response("live", 80, collision=False))  # a worker answers again
    assert store.delta(0)["live"]["live"] == [0.0, False, False]


def test_a_workers_refusal_shows_on_the_tile_until_a_response_comes():
    clock = Clock()
    store = FleetStore(clock=clock)
    notice = Refusal(robot="r1", worker="w2", reason="bad-size", detail="width 5000", count=7)
    assert store.offer("asnn/r1/refused", encode(notice)) == "r1"
    tile = store.delta(0)["robots"]["r1"]
    assert tile["refused"] == {"worker": "w2", "reason": "bad-size", "detail": "width 5000",
                               "count": 7}
    assert tile["stale"] is True and tile["response"] is None  # nothing answers it
    clock.now += 1.0
    offer_response(store, response("r1", 1))
    assert store.delta(0)["robots"]["r1"]["refused"] is None  # answered since
    clock.now += 1.0
    store.offer("asnn/r1/refused", encode(notice))
    assert store.delta(0)["robots"]["r1"]["refused"]["count"] == 7
    # a notice naming another robot than its key's is refused itself
    assert store.offer("asnn/r2/refused", encode(notice)) is None
    assert store.invalid == {"bad-key": 1} and store.robots() == ["r1"]


def test_silent_robots_are_forgotten_and_the_number_of_robots_is_bounded():
    clock = Clock()
    store = FleetStore(forget_after=60.0, max_robots=3, clock=clock)
    for robot in ("a", "b", "c", "d"):
        offer_response(store, response(robot))
    assert store.robots() == ["a", "b", "c"] and store.invalid == {"too-many-robots": 1}
    clock.now += 30.0
    offer_response(store, response("a", 1))
    clock.now += 31.0
    assert list(store.delta(0)["live"]) == ["a"]


def test_previews_are_sent_once_and_targets_match_the_previewed_frame():
    store = FleetStore(clock=Clock())
    offer_response(store, response(seq=3, targets=[(5.0, 6.0)]))
    offer_response(store, response(seq=4, targets=[(50.0, 40.0)]))
    store.offer("asnn/r1/preview", encode(preview(seq=3)))
    tile = store.delta(0)["robots"]["r1"]
    p = tile["preview"]
    assert (p["width"], p["height"], p["frame_width"], p["frame_height"]) == (32, 24, 64, 48)
    assert p["src"].startswith("data:image/jpeg;base64,")
    assert [(t["x"], t["y"]) for t in tile["targets"]] == [(5.0, 6.0)]  # seq 3's, not 4's
    version = store.version
    offer_response(store, response(seq=5))
    tile = store.delta(version)["robots"]["r1"]
    assert "src" not in tile["preview"] and tile["preview"]["seq"] == 3  # not sent again


def test_a_second_cameras_previews_are_not_shown_under_the_robots_answers():
    """A dashboard operator's trial: with a second camera on a robot's key (its frames refused
    by the worker), the thumbnail was the intruder's picture, drawn with the robot's targets.
    A preview is shown where its stamp lies between those of the answered frames around its
    seq (CONTRACT: a preview carries its frame's seq and stamp)."""
    clock = Clock()
    store = FleetStore(clock=clock)
    for seq in (100, 101, 103, 104):  # the worker skipped 102 under load
        offer_response(store, response(seq=seq, targets=[(5.0, 6.0)]))
    shown = []
    for seq, stamp in [(102, None),  # a skipped frame's: between its neighbours
                       (104, None),  # an answered frame's
                       (106, None),  # a frame not answered yet
                       (102, 1000.0 + 120 * 0.05),  # the second camera: seq 18 behind
                       (20, 1000.0 + 104 * 0.05),  # seq far behind, stamped now
                       (104, 1000.0 + 104 * 0.05 + 0.5)]:  # the same seq, half a second on
        clock.now += 0.45  # one preview a robot every PREVIEW_INTERVAL, all within stale_after
        store.offer("asnn/r1/preview", encode(preview(seq=seq, stamp=stamp)))
        shown.append(store.delta(0)["robots"]["r1"]["preview"]["seq"])
    assert shown == [102, 104, 106, 106, 106, 106]
    assert store.skipped["foreign-preview"] == 3
    # a second camera counting its own seq far ahead, stamped now (a preview above every
    # answer had no bound: a review)
    store.offer("asnn/r1/preview", encode(preview(seq=5000, stamp=1000.0 + 106 * 0.05)))
    assert store.skipped["foreign-preview"] == 4
    clock.now += 3.5  # no worker answers any more: the camera alone is heard, all are shown
    store.offer("asnn/r1/preview", encode(preview(seq=20, stamp=1000.0 + 130 * 0.05)))
    assert store.delta(0)["robots"]["r1"]["preview"]["seq"] == 20


@pytest.mark.parametrize("gaps, answered_every", [
    ([0.004, 0.063], 1),  # a camera read two frames at a time
    ([0.004, 0.063], 3),  # the same, its worker answering every third frame
    ([0.030, 0.036, 0.020, 0.047], 1),  # a jittery 30 fps
])
def test_a_cameras_own_previews_ahead_of_its_answers_are_its_own(gaps, answered_every):
    """A review: the 'ahead of every answer' check took the median of single steps, which
    flipped between 4 and 63 ms for a camera read two frames at a time, and refused 267 of its
    300 own previews (each arrives before its frame's answer) as another camera's."""
    from collections import deque

    from clients.fleet import ANSWERED_FRAMES, answered_frame, remember_answer

    shown, t, refused = deque(maxlen=ANSWERED_FRAMES), 100.0, []
    for seq in range(300):
        t += gaps[seq % len(gaps)]
        if seq and not answered_frame(shown, seq, t):
            refused.append(seq)
        if seq % answered_every == 0:
            remember_answer(shown, seq, t)  # the answer comes after the preview
    assert refused == []
    assert not answered_frame(shown, 5000, t + 0.03)  # a second camera's own count still is


def test_a_restarted_cameras_previews_are_shown_at_its_first_answers():
    """A review: after a camera restart (seq back to 0, its clock going on), the old stream's
    answers of greater seq bounded the new previews from above until 32 answers had come."""
    clock = Clock()
    store = FleetStore(clock=clock)
    for seq in range(200, 232):
        offer_response(store, response(seq=seq))
    restart = 1000.0 + 240 * 0.05  # the camera's clock goes on
    for seq in range(3):
        offer_response(store, response(seq=seq, stamp=restart + seq * 0.05))
    clock.now += 0.5  # a preview of a frame not answered yet, as the camera sends it
    store.offer("asnn/r1/preview", encode(preview(seq=4, stamp=restart + 4 * 0.05)))
    assert store.delta(0)["robots"]["r1"]["preview"]["seq"] == 4
    assert store.skipped["foreign-preview"] == 0


def test_a_second_publisher_stays_on_the_tile_while_the_robot_is_answered():
    """The worker answers the robot's own frames and refuses the second camera's: a response
    after the refusal hid it, and the tile looked normal while asnn status said contested."""
    clock = Clock()
    store = FleetStore(clock=clock)
    notice = Refusal(robot="r1", worker="w1", reason="second-publisher",
                     detail="frame 17 does not continue the stream of r1", count=22)
    store.offer("asnn/r1/refused", encode(notice))
    for seq in range(1, 70):
        clock.now += 0.5
        offer_response(store, response(seq=seq))
        refused = store.delta(0)["robots"]["r1"]["refused"]
        assert (refused is not None) == (seq * 0.5 <= CONTESTED_FOR_S), seq
    assert refused is None  # the worker's contested window (no notice for 30 s) is over


def test_targets_carry_the_trackers_id_and_time_to_contact_when_the_model_gives_them():
    store = FleetStore(clock=Clock())
    tracked = TargetMsg(x=5.0, y=6.0, direction=0.0, energy=1.0, pixels=50, id=7, ttc=0.8,
                        expansion=1.25, offset=0.2, approaching=True)
    plain = TargetMsg(x=50.0, y=40.0, direction=0.0, energy=1.0, pixels=50)
    r = response(seq=3, collision=True).model_copy(update={"targets": [tracked, plain]})
    offer_response(store, r)
    shown = store.delta(0)["robots"]["r1"]["targets"]
    assert shown[0]["id"] == 7 and shown[0]["ttc"] == 0.8 and shown[0]["label"] == "7"
    assert "id" not in shown[1] and "ttc" not in shown[1] and "label" not in shown[1]
    # a new owner's track 3 from frame 25 reads as asnn alerts shows it
    handed = tracked.model_copy(update={"id": 25 * 2**16 + 3})
    offer_response(store, r.model_copy(update={"seq": 4, "targets": [handed]}))
    assert store.delta(0)["robots"]["r1"]["targets"][0]["label"] == "25:3"


def test_consecutive_warnings_make_one_log_entry_per_episode():
    store = FleetStore(clock=Clock())
    for seq in range(10, 20):
        offer_response(store, response("a", seq, collision=True, rate=seq), "warning")
    offer_response(store, response("b", 5, collision=True), "warning")
    version = store.version
    offer_response(store, response("a", 25, collision=True, rate=1.0), "warning")  # same episode
    offer_response(store, response("a", 80, collision=True), "warning")  # a new one
    log = store.delta(0)["warnings"]
    assert [(e["robot"], e["first_seq"], e["seq"], e["count"]) for e in log] == [
        ("b", 5, 5, 1), ("a", 10, 25, 11), ("a", 80, 80, 1)]
    assert log[1]["peak_rate"] == 19.0 and log[1]["peak_out"] == 0.9
    assert [e["seq"] for e in store.delta(version)["warnings"]] == [25, 80]


def test_the_state_says_whether_the_dashboard_reaches_its_router():
    store = FleetStore(clock=Clock())
    assert store.delta(0)["router"] is None  # not known yet (or peers without a router)
    store.router_changed(True)
    version = store.version
    store.router_changed(True)  # no change, no update
    assert store.version == version and store.delta(0)["router"] is True
    store.router_changed(False)  # an update goes out to every page
    assert store.version == version + 1 and store.delta(version)["router"] is False


def test_two_robots_warning_on_keep_one_log_entry_each_past_a_newer_one():
    """A dashboard operator's trial: the log is ordered by last change, and an episode behind
    a newer robot's was taken for one that had left the log: a and b each got a second row,
    the first frozen, and the duplicates pushed other robots' warnings out sooner."""
    store = FleetStore(clock=Clock())
    for robot in ("a", "b", "c"):  # c's one-frame episode is the newest entry
        offer_response(store, response(robot, 10, collision=True), "warning")
    for seq in range(11, 16):  # a and b go on warning, frame after frame
        for robot in ("a", "b"):
            offer_response(store, response(robot, seq, collision=True), "warning")
    log = store.delta(0)["warnings"]
    assert sorted((e["robot"], e["first_seq"], e["seq"], e["count"]) for e in log) == [
        ("a", 10, 15, 6), ("b", 10, 15, 6), ("c", 10, 10, 1)]


def test_a_warning_after_the_camera_restarted_is_a_new_log_entry():
    """A probe: warnings at seq 100-130, then, after a restart, seq 110-125 an hour later on
    the camera's clock were counted into the first row, shown with its old time."""
    store = FleetStore(clock=Clock())
    for seq in range(100, 131):
        offer_response(store, response(seq=seq, collision=True), "warning")
    for seq in range(110, 126):
        offer_response(store, response(seq=seq, stamp=4600.0 + seq * 0.05, collision=True),
                       "warning")
    log = store.delta(0)["warnings"]
    assert [(e["first_seq"], e["seq"], e["count"]) for e in log] == [(100, 130, 31),
                                                                      (110, 125, 16)]
    assert log[1]["stamp"] == pytest.approx(4600.0 + 125 * 0.05)


def test_the_spike_history_ends_at_the_latest_response_whatever_a_warning_says():
    """A probe: one warning forged with a stamp of 1e300 (or one from before the camera's
    clock went back) made the page drop every point of the history, until the next warning."""
    store = FleetStore(clock=Clock())
    for seq in range(20):
        offer_response(store, response(seq=seq, rate=10.0))
    offer_response(store, response(seq=20, stamp=1e300, collision=True), "warning")
    tile = store.delta(0)["robots"]["r1"]
    assert tile["latest_stamp"] == pytest.approx(1000.0 + 19 * 0.05)
    assert len(tile["points"]) == 20
    assert store.delta(0)["config"]["max_points"] == 400  # the page keeps no more either


def test_invalid_messages_are_counted_never_raised():
    store = FleetStore(clock=Clock())
    good = encode(response())
    bad_jpeg = msgpack.packb({**preview().model_dump(), "data": b"\xff\xd8 not a jpeg"})
    wrong_size = msgpack.packb({**preview().model_dump(), "width": 31})
    raw_preview = msgpack.packb({**preview().model_dump(), "format": "gray8"})
    huge = msgpack.packb({**preview().model_dump(), "data": b"\0" * 300_000})
    cases = [
        ("asnn/r1/response", b"\xc1"), ("asnn/r1/response", msgpack.packb([1])),
        ("asnn/r1/response", msgpack.packb({"v": 1, "robot": "r1", "seq": "1"})),
        ("asnn/r1/response", msgpack.packb({**response().model_dump(), "v": 2})),
        ("asnn/r2/response", good),  # the message names another robot
        ("asnn/r1/warning", good),  # a warning without a collision
        ("asnn/r 1/response", good), ("other/r1/response", good), ("asnn/r1/frame", good),
        ("asnn/r1/preview", bad_jpeg), ("asnn/r1/preview", wrong_size),
        ("asnn/r1/preview", raw_preview), ("asnn/r1/preview", huge),
    ]
    for key, payload in cases:
        assert store.offer(key, payload) is None
    assert store.invalid == {"undecodable": 1, "not-a-map": 1, "invalid-field": 2,
                             "unsupported-version": 1, "bad-key": 4, "bad-image": 1,
                             "bad-pixels": 1, "bad-format": 1, "oversized": 1}
    assert store.robots() == [] and store.delta(0)["counts"]["invalid"] == store.invalid
    assert store.offer("asnn/r1/response", good) == "r1"


def test_the_store_is_safe_from_many_threads():
    store = FleetStore(clock=time.monotonic)
    names = [f"robot{i:02d}" for i in range(50)]

    def feed(name):
        for seq in range(40):
            offer_response(store, response(name, seq, collision=seq % 7 == 0), "response")

    seen = 0
    threads = [threading.Thread(target=feed, args=(n,)) for n in names]
    for t in threads:
        t.start()
    while any(t.is_alive() for t in threads):
        seen = store.delta(seen)["version"]
    for t in threads:
        t.join()
    delta = store.delta(0)
    assert set(delta["robots"]) == set(names)
    assert all(t["responses"] == 40 for t in delta["robots"].values())
    assert store.version == 50 * 40


# ---------------------------------------------------------------- preview message and camera

def test_preview_is_a_small_jpeg_of_the_frame_never_scaled_up():
    image = (np.arange(200 * 120) % 251).astype(np.uint8).reshape(120, 200)
    p = decode_preview(encode(Preview.from_frame_image(image, seq=7, stamp=1.5)))
    assert (p.seq, p.stamp, p.width, p.height, p.format) == (7, 1.5, 160, 96, "jpeg")
    assert (p.frame_width, p.frame_height) == (200, 120) and p.image().shape == (96, 160)
    small = Preview.from_frame_image(np.zeros((20, 30, 3), np.uint8), seq=0, stamp=0.0)
    assert (small.width, small.height) == (30, 20)


def test_camera_publishes_previews_at_a_low_rate_and_none_when_disabled(zenoh_net):
    scene = make_scene("looming")
    source = Source("synthetic:looming", scene.fps, False, lambda: iter(scene.frames))
    got: dict[str, list] = {"frame": [], "preview": []}

    def on(sample):
        robot, kind = keys.parse_key(str(sample.key_expr))
        got[kind].append((robot, sample.payload.to_bytes()))

    zenoh_net.hub.declare_subscriber("asnn/*/*", on)
    camera = zenoh_net.spoke()
    # 60 frames in 1.5 s at 40 fps, previews at 2 Hz: 3 or 4 of them
    assert publish_frames(camera, "cam", source, fps=40, wait=TIMEOUT, preview_hz=2.0) == 60
    assert publish_frames(camera, "nopv", source, fps=200, wait=TIMEOUT, preview_hz=0) == 60
    deadline = time.monotonic() + TIMEOUT
    while len(got["frame"]) < 100 and time.monotonic() < deadline:
        time.sleep(0.05)
    previews = [decode_preview(p) for robot, p in got["preview"]]
    assert {robot for robot, _ in got["preview"]} == {"cam"}
    assert 2 <= len(previews) <= 5 and previews[0].seq == 0
    assert all(p.width == 128 and p.frame_width == 128 for p in previews)  # 128 px: as is


# ---------------------------------------------------------------- the HTTP server

def get(server, path, method="GET"):
    host, port = server.address
    conn = http.client.HTTPConnection(host, port, timeout=TIMEOUT)
    try:
        conn.request(method, path)
        reply = conn.getresponse()
        return reply.status, dict(reply.getheaders()), reply.read()
    finally:
        conn.close()


def test_server_serves_the_packaged_page_and_nothing_else():
    store = FleetStore(clock=Clock())
    offer_response(store, response())
    with DashboardServer(store, "127.0.0.1", 0) as server:
        status, headers, body = get(server, "/")
        assert status == 200 and headers["Content-Type"].startswith("text/html")
        assert b"/static/dashboard.js" in body and b"/static/dashboard.css" in body
        assert "default-src 'self'" in headers["Content-Security-Policy"]
        for name, ctype in STATIC_FILES.items():
            status, headers, body = get(server, f"/static/{name}")
            assert status == 200 and headers["Content-Type"] == ctype and body
            assert b"http://" not in body and b"https://" not in body  # no CDN, works offline
        status, headers, body = get(server, "/state")
        assert status == 200 and json.loads(body)["robots"]["r1"]["responses"] == 1
        for path in ("/static/../dashboard.py", "/static/", "/nothing", "/../pyproject.toml"):
            assert get(server, path)[0] == 404
        assert get(server, "/", "HEAD")[0] == 200
        # a health check's HEAD on the stream: its headers at once, and no stream held open
        status, headers, body = get(server, "/events", "HEAD")
        assert status == 200 and headers["Content-Type"].startswith("text/event-stream")
        assert body == b"" and server.clients == 0
        # the standard library's own error pages carry the security headers too
        status, headers, _ = get(server, "/", "DELETE")
        assert status == 501 and "default-src 'self'" in headers["Content-Security-Policy"]
        with socket.create_connection(server.address, timeout=TIMEOUT) as sock:
            sock.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")  # the event stream
            head = b""
            while b"\r\n\r\n" not in head:
                head += sock.recv(4096)
        lines = head.split(b"\r\n\r\n")[0].split(b"\r\n")
        assert lines[0].startswith(b"HTTP/1.1 200")
        assert sum(line.startswith(b"Content-Security-Policy:") for line in lines) == 1


class EventReader:
    """Reads Server-Sent Events from /events on a raw socket."""

    def __init__(self, server):
        self.sock = socket.create_connection(server.address, timeout=TIMEOUT)
        self.sock.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\nAccept: text/event-stream\r\n\r\n")
        self.file = self.sock.makefile("rb")
        self.status = self.file.readline()
        while self.file.readline() not in (b"\r\n", b""):
            pass

    def next(self):
        event, data = None, None
        for raw in self.file:
            line = raw.decode().rstrip("\n")
            if line.startswith("event: "):
                event = line[7:]
            elif line.startswith("data: "):
                data = json.loads(line[6:])
            elif line == "" and event:
                return event, data
        return None, None

    def close(self):
        self.file.close()
        self.sock.close()


def test_event_stream_sends_a_snapshot_then_coalesced_deltas_losing_nothing():
    store = FleetStore()
    names = [f"robot{i:02d}" for i in range(50)]
    offer_response(store, response(names[0], 0))
    sent = 20
    with DashboardServer(store, "127.0.0.1", 0, push_hz=5.0) as server:
        reader = EventReader(server)
        try:
            assert b"200" in reader.status
            event, snapshot = reader.next()
            assert event == "snapshot" and snapshot["full"] and list(snapshot["robots"]) == [
                names[0]]
            start = time.monotonic()
            for seq in range(1, sent):  # 50 robots x 20 responses, as fast as possible
                for name in names:
                    offer_response(store, response(name, seq, rate=float(seq)))
            points = {name: len(snapshot["robots"].get(name, {"points": []})["points"])
                      for name in names}
            updates, deadline = 0, time.monotonic() + TIMEOUT
            while sum(points.values()) < 50 * (sent - 1) + 1:
                assert time.monotonic() < deadline, f"timed out, {points}"
                event, delta = reader.next()
                assert event == "update" and not delta["full"]
                updates += 1
                for name, tile in delta["robots"].items():
                    points[name] += len(tile["points"])
            elapsed = time.monotonic() - start
        finally:
            reader.close()
    assert points == {name: sent if name == names[0] else sent - 1 for name in names}
    # coalesced: 1000 messages arrived in a handful of deltas, at most 5 a second
    assert updates <= elapsed * 5.0 + 2


STREAM_LAG = ROOT / "clients" / "dashboard_static" / "freshness.js"


def _stream_lag_in_node(loop: str, *args):
    """Run ``loop`` in node after ``const s = new StreamLag(...)`` (freshness.js, the limit
    ``argv[3]`` where given, else its default) with ``out = []``, over the steps
    ``JSON.parse(argv[2])``; ``out`` as JSON, read back."""
    node = shutil.which("node") or shutil.which("nodejs")
    if node is None:
        pytest.skip("no node to run the page's script in")
    script = ("const {StreamLag} = require(process.argv[1]);"
              "const limit = process.argv.length > 3 ? JSON.parse(process.argv[3]) : null;"
              "const s = limit === null ? new StreamLag() : new StreamLag(limit);"
              "const out = []; const steps = JSON.parse(process.argv[2]);"
              + loop + "console.log(JSON.stringify(out));")
    done = subprocess.run([node, "-e", script, str(STREAM_LAG), *map(json.dumps, args)],
                          capture_output=True, text=True, timeout=TIMEOUT, check=True)
    return json.loads(done.stdout)


def page_lags(steps) -> list[float]:
    """The page's StreamLag (freshness.js, run in node) through ``steps``: ``("ask", now)``
    or ``("event", at, now)``; the lag it gives each event."""
    return _stream_lag_in_node(
        "for (const [kind, ...args] of steps) {"
        "  if (kind === 'ask') s.ask(...args); else out.push(s.lag(...args)); }", steps)


def test_the_page_never_takes_an_event_for_fresher_than_it_is():
    """The page's clock and the server's are not set alike (here 5,000 s apart, and a restarted
    server's another 6,000 s), yet the lag it takes every event to have is never less than the
    truth, and is small for events that are not behind: what a dropped stream's buffers still
    deliver 20 s late, and a snapshot received 8 s after it was taken, read as that old."""
    steps, truth = [], []

    def stream(offset, asked, events):
        """Asked at ``asked`` (page clock); ``(taken, received)`` events, page clock; the
        server's clock is the page's minus ``offset``."""
        steps.append(("ask", asked))
        for taken, received in events:
            steps.append(("event", taken - offset, received))
            truth.append(received - taken)

    fresh = [(10.05 + 0.2 * i, 10.1 + 0.2 * i) for i in range(10)]
    backlog = [(12.0 + 0.2 * i, 32.0 + 0.2 * i) for i in range(5)]  # sent, arriving 20 s late
    stream(-5000.0, 10.0, fresh + backlog)
    stream(1000.0, 40.0, [(40.02 + 0.2 * i, 40.03 + 0.2 * i) for i in range(5)])  # restarted
    stream(1000.0, 50.0, [(50.01, 58.0), (50.2, 58.05), (58.2, 58.21)])  # a slow snapshot
    lags = page_lags(steps)
    assert len(lags) == len(truth)
    assert all(lag >= true - 1e-9 for lag, true in zip(lags, truth)), list(zip(lags, truth))
    # over by no more than the server took to take a stream's first state
    assert all(lag <= true + 0.05 + 1e-9 for lag, true in zip(lags, truth)), lags
    assert max(lags[:10]) < 0.2 and min(lags[10:15]) >= 20.0
    assert max(lags[15:20]) < 0.1  # a restarted server, its clock elsewhere: fresh at once
    assert lags[20] >= 7.99 and lags[22] < 0.1
    # a first event with no stream asked for: counted from its arrival
    assert page_lags([("event", 7.0, 100.0), ("event", 8.0, 101.5)]) == [0.0, 0.5]


def page_waits(steps, first_event_s=None) -> list[list[bool]]:
    """A StreamLag (freshness.js, run in node; ``first_event_s``: its limit, else the
    default) through ``steps``: ``("ask", now)``, ``("event", at, now)`` or ``("check", now)``;
    ``[waiting, overdue]`` at each check."""
    return _stream_lag_in_node(
        "for (const [kind, ...args] of steps) {"
        "  if (kind === 'ask') s.ask(...args); else if (kind === 'event') s.lag(...args);"
        "  else out.push([s.waiting(), s.overdue(...args)]); }", steps, first_event_s)


def test_a_stream_waits_for_its_first_event_and_is_overdue_past_the_limit():
    """A new stream is waiting (the page says so, not "live") until its first event, and one
    with none more than 30 s (the default) after it was asked for is taken for cut and
    replaced; the limit is the rule's parameter, so a fake clock checks it here."""
    WAITING, OVERDUE, HEARD = [True, False], [True, True], [False, False]
    assert page_waits([("check", 1e6)]) == [HEARD]  # no stream asked for: nothing to wait for
    assert page_waits([("ask", 100.0), ("check", 100.0), ("check", 129.9), ("check", 130.1),
                       ("event", 5000.0, 131.0), ("check", 131.0), ("check", 1e6),
                       ("ask", 2000.0), ("check", 2029.0), ("check", 2031.0)]) == [
        WAITING, WAITING, OVERDUE, HEARD, HEARD, WAITING, OVERDUE]
    # a short limit; an event without a stamp counts as the first all the same
    assert page_waits([("ask", 10.0), ("check", 10.4), ("check", 10.6), ("ask", 11.0),
                       ("check", 11.4), ("event", None, 11.45), ("check", 20.0)],
                      first_event_s=0.5) == [WAITING, OVERDUE, WAITING, HEARD]


def test_closing_the_server_ends_open_event_streams():
    with DashboardServer(FleetStore(), "127.0.0.1", 0, heartbeat=0.2) as server:
        reader = EventReader(server)
        assert reader.next()[0] == "snapshot"
        assert server.clients == 1
    assert reader.next() == (None, None)  # the stream ended
    reader.close()


def test_a_server_started_then_entered_serves_on_one_thread_and_stops():
    before = {t for t in threading.enumerate() if t.name == "asnn-dashboard-http"}
    with DashboardServer(FleetStore(), "127.0.0.1", 0).start() as server:
        serving = {t for t in threading.enumerate() if t.name == "asnn-dashboard-http"}
        assert len(serving - before) == 1
        _, port = server.address
        page = http.client.HTTPConnection("127.0.0.1", port, timeout=TIMEOUT)
        page.request("GET", "/")
        assert page.getresponse().status == 200
        page.close()
    time.sleep(0.5)
    assert not {t for t in threading.enumerate()
                if t.name == "asnn-dashboard-http" and t.is_alive()} - before


def test_subscriber_feeds_the_store_over_zenoh(zenoh_net):
    store = FleetStore()
    with FleetSubscriber(zenoh_net.hub, store, refusals=True) as subscriber:
        spoke = zenoh_net.spoke()
        time.sleep(0.3)  # let the subscriptions reach the spoke
        spoke.put("asnn/r2/refused", encode(Refusal(robot="r2", worker="w", reason="late",
                                                    detail="", count=1)))
        spoke.put("asnn/r1/response", encode(response(seq=1)))
        spoke.put("asnn/r1/preview", encode(preview(seq=1)))
        spoke.put("asnn/r1/response", b"garbage")
        deadline = time.monotonic() + TIMEOUT
        while (store.delta(0)["counts"]["received"].get("preview") is None
               or not store.invalid) and time.monotonic() < deadline:
            time.sleep(0.05)
    assert subscriber.keys == ["asnn/*/response", "asnn/*/warning", "asnn/*/preview",
                               "asnn/*/refused"]
    assert store.delta(0)["counts"]["received"] == {"refused": 1, "response": 1, "preview": 1}
    assert store.invalid == {"undecodable": 1}


def test_a_store_that_fails_on_every_sample_logs_a_traceback_rate_limited(zenoh_net, caplog):
    """A concurrency review: a store whose offer raised (a bug) had a traceback logged for
    every sample, so one broken store flooded the log; it is fed on, and the failures counted."""
    import logging

    class Broken:
        prefix = "asnn"
        offered = 0

        def offer(self, key, payload):
            self.offered += 1
            raise ValueError("a bug in the store")

    class Sample:  # what the subscriber reads of a Zenoh sample
        key_expr = "asnn/r1/response"
        payload = type("Payload", (), {"to_bytes": staticmethod(lambda: b"{}")})

    now, store = [0.0], Broken()
    with caplog.at_level(logging.ERROR, logger="asnn.fleet"), \
            FleetSubscriber(zenoh_net.hub, store, log_interval=10.0,
                            clock=lambda: now[0]) as subscriber:
        for _ in range(100):
            subscriber._on_sample(Sample)
        now[0] = 10.0
        subscriber._on_sample(Sample)
    lines = [r for r in caplog.records if r.name == "asnn.fleet"]
    assert store.offered == 101
    assert len(lines) == 2
    assert all(r.exc_info and "a bug in the store" in str(r.exc_info[1]) for r in lines)
    assert lines[0].getMessage() == "unexpected error on asnn/r1/response"
    assert "(99 more since the last line)" in lines[1].getMessage()


def test_slow_previews_hold_up_no_response_and_the_oldest_are_dropped(procs, tmp_path):
    """A control-room trial: checking a preview decodes it (20 ms for a 5 kB png declaring a
    megapixel), and on the subscriber's callback that held up the session's other ones: a
    flood of them through the router delayed every robot's responses and warnings by
    20-30 s."""
    import zenoh

    from clients.fleet import PREVIEW_RING
    from service.config import ZenohOptions, make_config
    from service.demo import free_port

    class Slow:
        prefix = "asnn"

        def __init__(self):
            self.previews, self.response_after = 0, None

        def offer(self, key, payload):
            if key.endswith("/preview"):
                time.sleep(0.02)  # an expensive one
                self.previews += 1
            elif self.response_after is None:
                self.response_after = self.previews

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config = tmp_path / "router.json5"
    config.write_text("{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }")
    procs("router", "--listen", endpoint, "--config", str(config)).wait_line("listening on")
    client = make_config(ZenohOptions(mode="client", connect=(endpoint,),
                                      multicast_scouting=False, gossip=False))
    store = Slow()
    with zenoh.open(client) as viewer, zenoh.open(client) as camera, \
            FleetSubscriber(viewer, store) as subscriber:
        time.sleep(0.5)  # let the subscriptions reach the router
        for _ in range(450):  # 150 a second for 3 s, to a store that takes 50
            camera.put("asnn/r1/preview", b"x" * 4800)
            time.sleep(1 / 150)
        camera.put("asnn/r1/response", encode(response(seq=1)))
        published = store.previews
        deadline = time.monotonic() + 3 * TIMEOUT
        while store.response_after is None and time.monotonic() < deadline:
            time.sleep(0.01)
        # taken at once, not after the previews waiting
        assert store.response_after is not None and store.response_after <= published + 2
    assert not subscriber._previews.is_alive()  # its thread ends with the subscriber
    assert store.previews <= published + PREVIEW_RING + 2  # the rest dropped, not queued


# ---------------------------------------------------------------- the command

def test_dashboard_command_parses_with_the_common_zenoh_options():
    args = build_parser().parse_args(["dashboard", "--port", "9000", "--host", "0.0.0.0",
                                      "--connect", "tcp/router:7447", "--mode", "client",
                                      "--prefix", "fleet/a"])
    assert (args.port, args.host, args.connect, args.mode, args.prefix) == (
        9000, "0.0.0.0", ["tcp/router:7447"], "client", "fleet/a")
    assert build_parser().parse_args(["dashboard"]).port == 8080
    with pytest.raises(SystemExit):
        build_parser().parse_args(["dashboard", "--port", "70000"])


@pytest.mark.parametrize("flag, expected", [([], 2.0), (["--preview-hz", "0"], 0.0),
                                            (["--preview-hz", "0.5"], 0.5)])
def test_camera_command_passes_its_preview_rate_on(monkeypatch, flag, expected):
    import contextlib

    import cli.net
    import service.camera

    calls = []
    monkeypatch.setattr(cli.net, "open_session", lambda config: contextlib.nullcontext())
    monkeypatch.setattr(service.camera, "publish_frames",
                        lambda *a, **kw: calls.append(kw) or 0)
    args = build_parser().parse_args(["camera", "--robot", "r1", "--source",
                                      "synthetic:looming", *flag])
    assert args.func(args) == 0
    assert calls[0]["preview_hz"] == expected


def test_a_command_makes_its_zenoh_config_once(monkeypatch, tmp_path):
    """The session and its router watch (which says why a lost router refuses us) take the
    same configuration: it was made a second time for the watch, from the config file read
    again, which a file edited or removed in between would have made another, or an error
    out of the command."""
    import contextlib

    import cli.net
    import service.camera
    import service.config

    config = tmp_path / "zenoh.json5"
    config.write_text("{}")
    made = []
    make = service.config.make_config
    monkeypatch.setattr(service.config, "make_config",
                        lambda options: made.append(options.config_file) or make(options))
    monkeypatch.setattr(cli.net, "open_session", lambda config: contextlib.nullcontext())
    monkeypatch.setattr(service.camera, "publish_frames", lambda *a, **kw: 0)
    args = build_parser().parse_args(["camera", "--robot", "r1", "--source",
                                      "synthetic:looming", "--config", str(config)])
    assert args.func(args) == 0
    assert made == [str(config)]


def test_camera_command_refuses_a_negative_preview_rate(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["camera", "--robot", "r1", "--source", "synthetic:looming",
                                   "--preview-hz", "-1"])
    assert "zero or more" in capsys.readouterr().err


def run_dashboard(*args):
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env.pop("RUST_LOG", None)
    return subprocess.Popen([sys.executable, "-m", "cli.main", "dashboard", *args], cwd=ROOT,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_dashboard_command_serves_and_stops_on_sigint(tmp_path):
    config = tmp_path / "zenoh.json5"
    config.write_text("{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }")
    proc = run_dashboard("--port", "0", "--config", str(config),
                         "--listen", f"tcp/127.0.0.1:{free_port()}")
    try:
        lines = []
        for line in proc.stderr:
            lines.append(line)
            if "dashboard on http://" in line:
                break
        url = next(line for line in lines if "dashboard on" in line).split()[2]
        host, port = url[len("http://"):].rstrip("/").split(":")
        conn = http.client.HTTPConnection(host, int(port), timeout=TIMEOUT)
        conn.request("GET", "/static/dashboard.js")
        assert conn.getresponse().status == 200
        conn.close()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=TIMEOUT) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stderr.close()
        proc.stdout.close()


def test_dashboard_command_fails_clearly_when_the_port_is_taken():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        proc = run_dashboard("--port", str(taken.getsockname()[1]))
        out, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 2
    assert err.startswith("asnn dashboard: cannot serve on 127.0.0.1:") and err.count("\n") == 1


def test_the_preview_rule_at_its_edges():
    """clients.fleet.answered_frame and remember_answer case by case (a mutation probe: the
    trials pinned a second camera's previews refused and a restarted camera's shown, not the
    stamp's slack, the answered frame before a preview, the bound of one far ahead, nor an
    answer that arrives after a later one)."""
    from collections import deque

    from clients.fleet import ANSWERED_FRAMES, answered_frame, remember_answer

    shown = deque(maxlen=ANSWERED_FRAMES)
    for seq in range(10, 20):  # answered at 20 fps
        remember_answer(shown, seq, 1.0 + (seq - 10) * 0.05)
    # the answered frame's own preview, its stamp rounded by the camera: a millisecond's slack
    assert answered_frame(shown, 12, 1.1 + 0.0009) and answered_frame(shown, 12, 1.1 - 0.0009)
    assert not answered_frame(shown, 12, 1.1 + 0.002)
    # between two answers in seq, between them in time; before the one before it: not its
    assert answered_frame(shown, 12, 1.1) and not answered_frame(shown, 12, 1.04)
    # ahead of every answer: as far ahead in time as in seq, a period's slack either way
    latest = 1.45  # seq 19's
    assert answered_frame(shown, 20, latest + 0.05)
    assert answered_frame(shown, 20, latest + 2 * 0.05 + 0.05 - 0.002)
    assert not answered_frame(shown, 20, latest + 0.2)
    assert not answered_frame(shown, 21, latest + 10.0)  # a second camera's own clock
    # an answer arriving after a later one (two workers around a hand-over): both kept
    remember_answer(shown, 30, 2.0)
    remember_answer(shown, 29, 1.95)
    assert {(29, 1.95), (30, 2.0)} <= set(shown)
    # a restart: seq back, the clock going on: the answers it contradicts go
    remember_answer(shown, 0, 3.0)
    assert list(shown) == [(0, 3.0)]
    # a coarse clock (answers stamped alike): no period to judge by, ahead is taken
    coarse = deque([(0, 5.0), (1, 5.0), (2, 5.0)], maxlen=ANSWERED_FRAMES)
    assert answered_frame(coarse, 3, 5.02)
