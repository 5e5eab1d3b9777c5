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


_BLOCKED_STDERR = r"""
import argparse, logging, os, sys, threading, time
r, w = os.pipe()
sys.stderr = os.fdopen(w, "w")  # nobody reads it yet: a full pipe blocks its writer
from cli.session import LOG_QUEUE_RECORDS, setup_logging
setup_logging(argparse.Namespace(log_level="info"))
log = logging.getLogger("asnn.worker")
for i in range(3 * LOG_QUEUE_RECORDS):
    log.info("rec %d", i)
print("logged", flush=True)
chunks = []
threading.Thread(target=lambda: [chunks.append(c) for c in iter(lambda: os.read(r, 65536), b"")],
                 daemon=True).start()
waiting = logging.getLogger().handlers[0].queue
deadline = time.monotonic() + 60
while waiting.qsize() and time.monotonic() < deadline:  # "after" finds room: not dropped
    time.sleep(0.01)
log.warning("after")
deadline = time.monotonic() + 60
while b"after" not in b"".join(chunks) and time.monotonic() < deadline:
    time.sleep(0.05)
sys.stdout.write(b"".join(chunks).decode())
sys.stdout.flush()
os._exit(0)
"""


def test_logging_never_waits_for_a_blocked_stderr_and_counts_what_it_drops():
    """The worker logs from Zenoh's receiving thread: a stderr nobody reads (a full pipe) must
    not stall it. The records beyond the queue's bound are dropped, and their number said."""
    import re
    import subprocess
    import sys

    from cli.session import LOG_QUEUE_RECORDS

    done = subprocess.run([sys.executable, "-c", _BLOCKED_STDERR], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "logged"  # every logging call returned while stderr was blocked
    kept = sum(1 for line in lines if re.search(r" INFO rec \d+$", line))
    dropped = [int(m.group(1)) for line in lines
               if (m := re.search(r"WARNING (\d+) log records dropped", line))]
    assert dropped and kept + sum(dropped) == 3 * LOG_QUEUE_RECORDS
    assert kept <= LOG_QUEUE_RECORDS + 2000  # the queue, and the 64 KiB the pipe held
    assert lines[-1].endswith("WARNING after")


_EXIT_WITH_STDERR_BLOCKED = r"""
import argparse, logging, os, sys
r, w = os.pipe()
sys.stderr = os.fdopen(w, "w")  # nobody reads it, ever
from cli.session import LOG_QUEUE_RECORDS, setup_logging
setup_logging(argparse.Namespace(log_level="info"))
log = logging.getLogger("asnn.worker")
for i in range(2 * LOG_QUEUE_RECORDS):  # the queue full at exit, its writer blocked
    log.info("rec %d", i)
print("logged", flush=True)
sys.exit(0)
"""


def test_a_process_whose_stderr_is_blocked_still_exits():
    """A review: the exit joined the writer thread blocked on the pipe and hung (a systemd stop
    waited for its SIGKILL), or with the queue full printed a traceback and wrote nothing more.
    The exit now waits a bounded time for what is queued."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _EXIT_WITH_STDERR_BLOCKED],
                          capture_output=True, text=True, timeout=60)
    assert (done.returncode, done.stdout) == (0, "logged\n"), done
