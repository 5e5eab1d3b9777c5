"""Routes without Zenoh: which robots a worker subscribes to, answers and claims, and the warm
hand-over between two workers (service/routing.py, the worker core's warm-up)."""

import pytest

from asnn import ASNN
from asnn.stimuli import make_scene
from service import keys
from service.core import HANDOVER_WARMUP_FRAMES, RobotView, WorkerCore
from service.messages import track_id_base
from service.ownership import owner
from service.routing import SCAN_KEY, Routes

from test_worker import FakeClock, payload


def robot_of(owner_id, workers, prefix="r"):
    """A robot id whose rendezvous owner over ``workers`` is ``owner_id``."""
    return next(f"{prefix}{i}" for i in range(1000) if owner(f"{prefix}{i}", workers) == owner_id)


WARM = {"proven": True, "warm": True, "last_seen": 0.0}
COLD = {"proven": True, "warm": False, "last_seen": 0.0}


def roles(routes, tracked=()):
    return {r: (route.role, route.claim) for r, route in routes.plan(
        {r: RobotView(**view) for r, view in dict(tracked).items()}).items()}


def test_a_robot_moves_warm_from_its_old_owner_to_a_newcomer():
    old, new = Routes("w1"), Routes("w2")
    robot = robot_of("w2", ["w1", "w2"])
    # w1 alone serves the robot and claims it
    old.camera(robot, True)
    assert roles(old) == {robot: ("serving", False)}  # no valid frame yet: no claim
    assert roles(old, {robot: COLD}) == {robot: ("serving", True)}
    # w2 joins: it reads w1's claim; w1 sees w2 and keeps answering until w2 claims
    new.membership.add("w1")
    new.claim("w1", robot, True)
    new.camera(robot, True)
    old.membership.add("w2")
    assert roles(old, {robot: WARM}) == {robot: ("releasing", True)}
    assert old.answers(robot) and not new.answers(robot)
    assert roles(new) == {robot: ("warming", False)}  # subscribes, steps silently
    assert roles(new, {robot: COLD}) == {robot: ("warming", False)}
    assert roles(new, {robot: WARM}) == {robot: ("warming", True)}  # warm: claims...
    assert new.answers(robot)  # ... and answers
    assert roles(new, {robot: WARM}) == {robot: ("serving", True)}
    old.claim("w2", robot, True)
    assert roles(old, {robot: WARM}) == {}  # w1 lets go (and forgets the state)
    assert old.known(robot) and not old.takes(robot) and not old.answers(robot)
    new.claim("w1", robot, False)
    assert roles(new, {robot: WARM}) == {robot: ("serving", True)}


def test_a_leaving_worker_answers_until_the_heir_claims():
    routes = Routes("w1")
    routes.membership.add("w2")
    robot = robot_of("w1", ["w1", "w2"])
    assert roles(routes, {robot: WARM}) == {robot: ("serving", True)}
    routes.membership.leave()
    assert routes.membership.owner(robot) == "w2"
    assert roles(routes, {robot: WARM}) == {robot: ("releasing", True)}
    assert not routes.scanner() and not routes.alone()
    routes.claim("w2", robot, True)
    assert roles(routes, {robot: WARM}) == {}


def test_after_a_crash_the_heir_serves_at_once_and_remembers_the_robot():
    clock = FakeClock()
    routes = Routes("w2", remember=10.0, clock=clock)
    routes.membership.add("w1")
    robot = robot_of("w1", ["w1", "w2"])  # served by w1; no camera announcement
    routes.claim("w1", robot, True)
    assert roles(routes) == {}
    # w1 dies: its token and claims vanish together
    routes.claim("w1", robot, False)
    routes.membership.remove("w1")
    assert roles(routes) == {robot: ("serving", False)}  # cold, but at once
    clock.now += 9.0
    assert robot in roles(routes)
    clock.now += 2.0  # no frame, no claim, no camera for longer than remember: forgotten
    assert roles(routes) == {} and not routes.known(robot)


def test_the_scan_adopts_unknown_robots_until_their_owners_take_them():
    scanner = next(w for w in ("w1", "w2") if owner(SCAN_KEY, ["w1", "w2"]) == w)
    other = "w2" if scanner == "w1" else "w1"
    routes = Routes(scanner)
    routes.membership.add(other)
    assert routes.scanner() and not routes.alone()
    theirs = robot_of(other, ["w1", "w2"])
    assert routes.takes(theirs)  # unknown: its scanned frame is taken, to be adopted
    assert routes.adopt(theirs) and not routes.adopt(theirs)
    assert roles(routes, {theirs: COLD}) == {theirs: ("releasing", True)}  # answers meanwhile
    routes.claim(other, theirs, True)
    assert roles(routes, {theirs: WARM}) == {}
    # an adopted robot whose frame failed in the core is let go (remembered a while)
    lost = robot_of(other, ["w1", "w2"], prefix="x")
    routes.adopt(lost)
    assert roles(routes, {}) == {} and routes.known(lost)


def test_known_robots_are_bounded():
    routes = Routes("w1", max_known=3)
    assert routes.camera("a", True) and routes.claim("w2", "b", True) and routes.adopt("c")
    assert not routes.camera("d", True) and not routes.claim("w2", "e", True)
    assert not routes.adopt("f")
    assert routes.claim("w3", "b", True)  # a robot already known takes no room
    assert routes.counts() == {"claimed": 0, "claimed_by_others": 1, "announced": 1,
                               "adopted": 1, "remembered": 0}
    # a robot whose evidence went gives its place to one with live evidence, the robot
    # remembered longest first
    assert routes.camera("a", False) and routes.claim("w2", "b", False)
    assert routes.claim("w3", "b", False)
    assert routes.counts()["remembered"] == 2
    assert routes.camera("d", True) and not routes.known("a") and routes.known("b")
    assert routes.claim("w2", "e", True) and not routes.known("b")
    assert not routes.adopt("f")  # full again, with nothing remembered to forget
    assert routes.counts() == {"claimed": 0, "claimed_by_others": 1, "announced": 1,
                               "adopted": 1, "remembered": 0}


def test_a_new_owner_answers_as_a_model_that_saw_the_whole_stream():
    """The core's side of a warm hand-over: frames are stepped silently until the routes let the
    worker answer; warm after warmup_frames; the answers then equal an uninterrupted model's."""
    scene = make_scene("looming")
    reference = ASNN()
    expected = [reference.step(f, i / 20) for i, f in enumerate(scene.frames)]
    answering = set()
    warmup = HANDOVER_WARMUP_FRAMES
    core = WorkerCore(answers=answering.__contains__)
    # the new owner's first frame as the disk starts to grow: it answers from frame 40, in the
    # middle of the warning (frames 13-46)
    start = 10
    answered = []
    for seq in range(start, len(scene.frames)):
        assert core.offer("asnn/r1/frame", payload(scene.frames[seq], seq, seq / 20)) == "r1"
        response = core.process(core.take())
        if seq - start + 1 == warmup:
            assert core.warm("r1")
            answering.add("r1")  # the previous owner let go
        elif seq - start + 1 < warmup:
            assert response is None and not core.warm("r1")
        if response is not None:
            answered.append(response)
    assert core.stats()["warmup"] == warmup
    assert core.stats()["processed"] == len(scene.frames) - start - warmup
    assert answered[0].seq == start + warmup
    assert [r.collision for r in answered] == [e.collision for e in expected[start + warmup:]]
    assert answered[0].collision and answered[0].u > 0
    # its tracks are numbered from the seq its model started at: no id the previous owner
    # gave (numbered from the stream's start) names another object now
    ids = {t.id for r in answered for t in r.targets}
    assert ids and all(track_id_base(start) <= i < track_id_base(start + 1) for i in ids)
    # a cold start (what a crash gives) answers u = 0 at once
    cold = WorkerCore()
    cold.offer("asnn/r1/frame", payload(scene.frames[start], start))
    assert cold.process(cold.take()).u == 0.0


def test_a_reset_makes_a_warm_robot_cold_again():
    scene = make_scene("looming")
    core = WorkerCore(warmup_frames=3)
    for seq in range(4):
        core.offer("asnn/r1/frame", payload(scene.frames[seq], seq))
        core.process(core.take())
    assert core.warm("r1")
    core.offer("asnn/r1/frame", payload(scene.frames[0], 0))  # the camera restarted
    assert not core.warm("r1")  # a reset is pending
    core.process(core.take())
    assert not core.warm("r1") and core.views()["r1"].proven


def test_the_same_frame_delivered_twice_is_taken_once():
    scene = make_scene("looming")
    core = WorkerCore()
    data = payload(scene.frames[0], 0)
    assert core.offer("asnn/r1/frame", data) == "r1"
    assert core.offer("asnn/r1/frame", data) is None  # two subscriptions matched it
    core.process(core.take())
    assert core.offer("asnn/r1/frame", data) is None
    assert core.stats()["duplicates"] == 2 and core.stats()["resets"] == {}
    assert core.stats()["received"] == 1


@pytest.mark.parametrize("key, parsed", [
    ("asnn/@worker/w1/robot/r1", ("w1", "r1")),
])
def test_claim_and_camera_keys(key, parsed):
    assert keys.parse_claim(key) == parsed and keys.claim_key(*parsed) == key
    assert keys.claims() == "asnn/@worker/*/robot/*"
    assert keys.parse_camera_token(keys.camera_token_key("r1")) == "r1"
    for bad in ("asnn/@worker/w1/status", "asnn/@worker/w1", "asnn/@worker/w1/robot/r 1",
                "other/@worker/w1/robot/r1"):
        with pytest.raises(keys.KeySchemeError):
            keys.parse_claim(bad)
    with pytest.raises(keys.KeySchemeError):
        keys.parse_camera_token("asnn/@camera/r1/x")


def test_a_flood_of_robot_ids_leaves_a_bounded_number_of_robots_planned():
    """A hostile review: 1,800 robot ids, each tracked for a moment (a frame, a slot made for
    it), stayed in a lone worker's plan for --idle-timeout: a subscription each, and the thread
    Zenoh runs its Python callback on (1,200 threads, more with every new id)."""
    clock = FakeClock()
    routes = Routes("w1", remember=60.0, max_known=16, clock=clock)
    for i in range(200):
        clock.now += 0.01
        robot = f"flood{i}"
        routes.adopt(robot)
        assert roles(routes, {robot: COLD})[robot] == ("serving", True)
        # the core forgot it: remembered a while, with at most 15 others (and the robot
        # let go in this pass)
        assert len(routes.plan({})) <= 16 + 1 and routes.counts()["remembered"] <= 16
    assert routes.counts()["remembered"] <= 16
    # the latest ids are the ones remembered, and a robot that comes back is served
    assert routes.known("flood199") and not routes.known("flood0")
    assert roles(routes, {"flood0": COLD})["flood0"] == ("serving", True)
    # the remembered ids fill the table, yet a robot whose camera announces itself is let in
    # at once (it took the place of the id remembered longest), not after --idle-timeout
    assert routes.counts()["remembered"] == 16
    assert routes.camera("real", True) and routes.counts()["remembered"] == 15
    assert roles(routes, {})["real"] == ("serving", False)


def test_a_fast_camera_s_new_owner_warms_up_on_the_frames_its_model_steps():
    """At 60 fps the default's frame-rate ceiling holds every second frame: the warm-up counts
    the frames the model stepped, so a new owner that started on an odd frame is warm after
    about twice the frames, and then answers as a model that saw the whole stream."""
    from asnn.stimuli.planar import planar_scene

    frames = planar_scene("loom", fps=60.0, onset=30, polarity="dark", height=12, tau=2.0,
                          contrast=0.6, noise=2.0, seed=1).frames
    reference = ASNN()
    expected = [reference.step(f, 10.0 + i / 60) for i, f in enumerate(frames)]
    answering = set()
    core = WorkerCore(answers=answering.__contains__, warmup_frames=10)
    start, warm_at = 7, None
    for seq in range(start, len(frames)):
        core.offer("asnn/r1/frame", payload(frames[seq], seq, 10.0 + seq / 60))
        response = core.process(core.take())
        if warm_at is None and core.warm("r1"):
            warm_at = seq - start + 1
            answering.add("r1")
        elif response is not None:
            assert response.collision == expected[seq].collision, seq
    # 10 steps: the first frames all stepped while the rate is judged, then one in two
    assert warm_at is not None and 15 <= warm_at <= 20
    assert core.stats()["warmup"] == warm_at
    assert any(expected[seq].collision for seq in range(start + warm_at, len(frames)))
