"""Scale-out and failover with OS processes: a router, several workers, frames of eight robots.

Each robot is served by exactly one worker, the one rendezvous hashing picks over the live set;
a worker killed with SIGKILL has its robots served by the others within seconds (the contract
asks for 2 s; the test allows 5 s for a loaded machine and prints the measured time); a new
worker takes its share; SIGTERM hands over at once.
"""

import contextlib
import json
import signal
import time

import pytest
import zenoh

from service.config import ZenohOptions, make_config
from service.demo import free_port
from service.ownership import owner
from service.worker import live_workers, query_status

from netutil import SHORT_LEASE, Procs, FramePump, Responses, wait_for

ROBOTS = [f"r{i}" for i in range(8)]
FAILOVER_LIMIT = 5.0  # seconds; the requirement is 2 s, the margin is for loaded CI machines


@pytest.fixture
def net(tmp_path, procs):
    config = tmp_path / "zenoh.json5"
    config.write_text(SHORT_LEASE)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = procs("router", "--listen", endpoint, "--config", str(config))
    router.wait_line("listening on")
    common = ["--config", str(config), "--connect", endpoint, "--mode", "client"]

    class Net:
        pass

    Net.common, Net.router = common, router
    Net.options = ZenohOptions(mode="client", connect=(endpoint,), config_file=config)

    def worker(worker_id, *options):
        proc = procs("worker", "--id", worker_id, "--idle-timeout", "600", *options, *common)
        proc.wait_line("ready", timeout=60)
        return proc

    Net.worker = worker
    return Net


def served_by(responses, t0):
    """robot -> set of workers that answered it since t0."""
    out: dict[str, set] = {}
    for r in responses.since(t0):
        out.setdefault(r.robot, set()).add(r.worker)
    return out


def settle(responses, workers, window=1.5, timeout=30.0):
    """Wait until, over ``window`` seconds, every robot was answered by its owner only."""
    expected = {robot: {owner(robot, workers)} for robot in ROBOTS}
    deadline = time.monotonic() + timeout
    while True:
        t0 = time.monotonic()
        time.sleep(window)
        got = served_by(responses, t0)
        if got == expected:
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"robots not settled on {workers}: {got} != {expected}")


def handover_time(responses, t0, robots, to_workers):
    """Seconds from t0 until each of ``robots`` was answered by its new owner."""
    def done():
        return all(responses.first_after(t0, r, owner(r, to_workers)) for r in robots)

    wait_for(done, timeout=20, what=f"{robots} to move to {to_workers}")
    return max(responses.first_after(t0, r, owner(r, to_workers)) for r in robots) - t0


@contextlib.contextmanager
def two_workers_serving(net):
    """Workers w1 and w2 sharing ROBOTS, whose frames keep flowing: (w1, w2, session, responses)
    once every robot is answered by its owner."""
    w1, w2 = net.worker("w1"), net.worker("w2")
    with zenoh.open(make_config(net.options)) as session:
        wait_for(lambda: live_workers(session) == ["w1", "w2"], what="both workers live")
        responses = Responses(session)
        with FramePump(session, ROBOTS, fps=20):
            settle(responses, ["w1", "w2"])
            yield w1, w2, session, responses


def test_workers_share_robots_and_fail_over(net, capsys):
    with two_workers_serving(net) as (w1, w2, session, responses):
        mine = {w: [r for r in ROBOTS if owner(r, ["w1", "w2"]) == w] for w in ("w1", "w2")}
        assert mine["w1"] and mine["w2"], mine

        # the status queryable of each worker tells its robots and the live set
        status = query_status(session)
        assert set(status) == {"w1", "w2"}
        assert sorted(status["w1"]["robots"]) == mine["w1"]
        assert status["w2"]["workers"] == ["w1", "w2"]
        # each worker receives its own robots' frames (and the scanner a few more)
        for w in ("w1", "w2"):
            assert all(status[w]["robots"][r]["frames"] > 0 for r in mine[w])
            assert status[w]["traffic"]["frames"] >= sum(status[w]["robots"][r]["frames"]
                                                         for r in mine[w])

        # SIGKILL: no goodbye; the router drops the session and its liveliness token
        t_kill = time.monotonic()
        w1.popen.send_signal(signal.SIGKILL)
        killed = handover_time(responses, t_kill, mine["w1"], ["w2"])
        settle(responses, ["w2"])

        # a new worker takes its share
        w3 = net.worker("w3")
        t_join = time.monotonic()
        moved = [r for r in ROBOTS if owner(r, ["w2", "w3"]) == "w3"]
        assert moved
        joined = handover_time(responses, t_join, moved, ["w2", "w3"])
        settle(responses, ["w2", "w3"])

        # SIGTERM: the token goes first, the other worker takes over at once
        t_term = time.monotonic()
        w3.popen.send_signal(signal.SIGTERM)
        terminated = handover_time(responses, t_term, moved, ["w2"])
        assert w3.stop() == 0
        settle(responses, ["w2"])
        assert "worker stopped" in "\n".join(w3.err)
        assert responses.invalid == 0
    with capsys.disabled():
        print(f"\nfailover: SIGKILL {killed:.2f} s, join {joined:.2f} s, "
              f"SIGTERM {terminated:.2f} s (limit {FAILOVER_LIMIT} s, requirement 2 s)")
    assert killed < FAILOVER_LIMIT and terminated < FAILOVER_LIMIT and joined < FAILOVER_LIMIT
    assert w2.stop(signal.SIGTERM) == 0


def test_a_hung_worker_loses_its_robots_after_the_lease_and_takes_them_back(net, capsys):
    """SIGSTOP: the connection stays open but silent; the router drops the session when the
    1 s lease expires. After SIGCONT the worker reconnects and rejoins."""
    with two_workers_serving(net) as (w1, w2, session, responses):
        lost = [r for r in ROBOTS if owner(r, ["w1", "w2"]) == "w1"]
        t_stop = time.monotonic()
        w1.popen.send_signal(signal.SIGSTOP)
        try:
            hung = handover_time(responses, t_stop, lost, ["w2"])
            settle(responses, ["w2"])
        finally:
            w1.popen.send_signal(signal.SIGCONT)
        t_cont = time.monotonic()
        back = handover_time(responses, t_cont, lost, ["w1", "w2"])
        settle(responses, ["w1", "w2"])
    with capsys.disabled():
        print(f"\nhung worker (SIGSTOP): robots moved after {hung:.2f} s (lease 1 s), "
              f"back {back:.2f} s after SIGCONT")
    assert hung < FAILOVER_LIMIT
    assert w1.stop(signal.SIGTERM) == 0 and w2.stop(signal.SIGTERM) == 0


def test_a_second_worker_with_the_same_id_is_refused_and_status_lists_the_first(net):
    net.worker("same")
    more = Procs()
    try:
        dup = more("worker", "--id", "same", *net.common)
        assert dup.popen.wait(timeout=60) == 2
        dup.stop()
        assert "already live" in "\n".join(dup.err)
        # before it loads the model's kernels (a minute of compiling on a fresh install: an
        # audit)
        assert not any("loading the model's kernels" in line for line in dup.err)
        status = more("status", "--json", *net.common)
        assert status.popen.wait(timeout=60) == 0
        status.stop()
        (line,) = status.out
        answer = json.loads(line)
        assert answer["worker"] == "same" and answer["workers"] == ["same"]
        assert answer["limits"]["max_side"] == 4096 and "invalid" in answer["stats"]
        nobody = more("status", "--worker", "other", "--timeout", "1", *net.common)
        assert nobody.popen.wait(timeout=60) == 1
        nobody.stop()
    finally:
        more.cleanup()


def test_status_local_answers_for_the_workers_of_this_host_with_the_default_id(net, procs):
    """``asnn status --local``, the worker's health check in a container: a worker whose id is
    the default, <host>-<pid>, of this host answers it; a worker named otherwise does not."""
    from service.core import worker_host

    net.worker("named")
    more = Procs()
    try:
        nobody = more("status", "--local", "--timeout", "1", *net.common)
        assert nobody.popen.wait(timeout=60) == 1
        nobody.stop()
        assert f"no worker of this host ({worker_host()}-<pid>)" in "\n".join(nobody.err)
        here = procs("worker", "--idle-timeout", "600", *net.common)
        here.wait_line("ready", timeout=60)
        status = more("status", "--local", "--json", *net.common)
        assert status.popen.wait(timeout=60) == 0
        status.stop()
        assert [json.loads(line)["worker"] for line in status.out] == [
            f"{worker_host()}-{here.popen.pid}"]
    finally:
        more.cleanup()


def test_each_frame_reaches_exactly_the_worker_of_its_robot(net, capsys):
    """Three workers and nine cameras that announce themselves (no scan: --scan-interval 0): in
    steady state every frame is delivered to one worker, its robot's owner, and answered once;
    the workers' status counts the frames and bytes they received."""
    from cli.net import format_status
    from netutil import AnnouncedCameras

    workers = ["w1", "w2", "w3"]
    for worker in workers:
        net.worker(worker, "--scan-interval", "0")
    cameras = [f"cam{i}" for i in range(9)]
    owners = {camera: owner(camera, workers) for camera in cameras}
    assert len(set(owners.values())) == 3
    with zenoh.open(make_config(net.options)) as session:
        wait_for(lambda: live_workers(session) == workers, what="three live workers")
        responses = Responses(session)
        with AnnouncedCameras(session, cameras) as pump:
            wait_for(pump.matched, what="every camera's worker to subscribe")
            pump.burst(20)
            wait_for(lambda: pump.answered(responses), what="the first frames' responses")
            before, sent_before = query_status(session), pump.sent_bytes
            t0 = time.monotonic()
            pump.burst(50)
            wait_for(lambda: pump.answered(responses), what="the burst's responses")
            after = query_status(session)
    delta = {w: {k: after[w]["traffic"][k] - before[w]["traffic"][k] for k in after[w]["traffic"]}
             for w in workers}
    with capsys.disabled():
        print(f"\nframes received per worker for 9 x 50 published: "
              f"{ {w: d['frames'] for w, d in delta.items()} }")
    assert sum(d["frames"] for d in delta.values()) == len(cameras) * 50
    assert sum(d["bytes"] for d in delta.values()) == pump.sent_bytes - sent_before
    assert all(d["scanned_frames"] == 0 for d in delta.values())
    for camera in cameras:
        for w in workers:
            got = (after[w]["robots"].get(camera, {}).get("frames", 0)
                   - before[w]["robots"].get(camera, {}).get("frames", 0))
            assert got == (50 if w == owners[camera] else 0), (camera, w, got)
        assert after[owners[camera]]["robots"][camera]["route"] == "serving"
    burst = [(r.robot, r.seq, r.worker) for r in responses.since(t0)]
    assert len({(robot, seq) for robot, seq, _ in burst}) == len(burst)  # answered once
    assert all(worker == owners[robot] for robot, _, worker in burst)
    line = format_status(after["w1"])
    assert f"frames in {after['w1']['traffic']['frames']}" in line
