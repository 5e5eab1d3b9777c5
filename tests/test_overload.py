"""Overload: four times more frames than the worker can process.

The worker holds at most two frames per robot (the pending one and the one being processed)
whatever the input rate, the newest frame of each robot wins, every skipped frame is counted in
the next response's ``dropped``, and no response or warning is lost on the way to subscribers.
"""

import threading
import time

import pytest

from asnn.stimuli import make_scene
from service import keys
from service.core import WorkerCore
from service.messages import Frame, decode_response, encode
from service.worker import Worker

from netutil import Responses, wait_for

STEP_S = 0.025  # the slowed worker manages 40 frames/s
ROBOTS = ["a", "b", "c", "d"]
FPS = 40.0  # per robot: 160 frames/s offered, 4x the capacity
SECONDS = 4.0


class SlowCore(WorkerCore):
    """A worker core that takes STEP_S per frame, whatever the model costs."""

    def process(self, job, publish=None):
        time.sleep(STEP_S)
        return super().process(job, publish)


@pytest.fixture
def overloaded(zenoh_net):
    core = SlowCore(idle_timeout=600)
    with Worker(zenoh_net.hub, core, stats_every=0) as worker:
        yield zenoh_net, core, worker


def test_four_times_overload_keeps_memory_bounded_and_loses_no_response(overloaded):
    net, core, worker = overloaded
    scene = make_scene("looming")  # looping it makes warnings every pass
    responses = Responses(net.spoke())
    warnings = []
    lock = threading.Lock()

    def on_warning(sample):
        with lock:
            warnings.append(decode_response(sample.payload.to_bytes()))

    net.spoke().declare_subscriber(keys.warnings(), on_warning)
    camera = net.spoke()
    publishers = {r: camera.declare_publisher(keys.frame_key(r)) for r in ROBOTS}
    wait_for(lambda: all(p.matching_status.matching for p in publishers.values()),
             what="the worker's subscription")
    sent = dict.fromkeys(ROBOTS, 0)
    peak_backlog = 0
    start = time.monotonic()
    seq = 0
    while time.monotonic() - start < SECONDS:
        for robot in ROBOTS:
            frame = Frame.from_image(scene.frames[seq % len(scene.frames)], seq=seq,
                                     stamp=seq / FPS)
            publishers[robot].put(encode(frame))
            sent[robot] += 1
        seq += 1
        peak_backlog = max(peak_backlog, core.backlog())
        time.sleep(max(0.0, start + seq / FPS - time.monotonic()))
    last_seq = seq - 1
    wait_for(lambda: worker.idle(), what="the worker to catch up")
    stats = core.stats()
    wait_for(lambda: responses.count() == stats["processed"], what="every response")
    wait_for(lambda: len(warnings) == stats["warnings"], what="every warning")

    offered = sum(sent.values())
    assert offered >= 3.5 * SECONDS * len(ROBOTS) * FPS / 4  # the load really was there
    # bounded: never more than two frames per robot held, however many arrive
    assert peak_backlog <= 2 * len(ROBOTS)
    # most frames had to be skipped: the worker processed about a quarter of them
    assert stats["processed"] < 0.5 * stats["received"]
    assert stats["invalid"] == {}
    # every skipped frame is accounted for in the responses' dropped counts
    got = responses.since(0)
    assert sum(r.dropped for r in got) == stats["dropped"]
    assert stats["processed"] + stats["dropped"] == stats["received"]
    for robot in ROBOTS:
        mine = [r for r in got if r.robot == robot]
        seqs = [r.seq for r in mine]
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
        assert seqs[-1] == last_seq  # the newest frame wins: the last one is answered
        assert sum(r.dropped for r in mine) + len(mine) <= sent[robot]
    # responses and warnings are never dropped on the way out
    assert stats["warnings"] > 0
    assert sorted((w.robot, w.seq) for w in warnings) == \
        sorted((r.robot, r.seq) for r in got if r.collision)
