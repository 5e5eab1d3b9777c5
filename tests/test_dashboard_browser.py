"""The dashboard end to end in headless Chromium (Debian's ``chromium``; ``.ci/run`` installs it).

Two generated streams run through a real worker over Zenoh (TCP loopback, free ports, scouting
off): one looming, one translating. The page is loaded in headless Chromium, driven through the
DevTools protocol over ``--remote-debugging-pipe`` (no WebSocket client, no downloads), and must
show both robots with their previews, only the looming one in the collision state, fetch nothing
but its own server's files, and throw no script error. Robots fed straight into a store test the
rest: fifty robots, refused and silent ones, events that arrive late (read stale), a stream
behind or silent (replaced by the page). A screenshot is kept in
``test-artifacts/dashboard.png``. Skipped when no Chromium binary is installed.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import re
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import pytest

from asnn.stimuli import make_scene
from clients.dashboard import DashboardServer, FleetStore, FleetSubscriber
from service.camera import Source, publish_frames
from service.core import WorkerCore
from service.messages import Refusal, Response, encode
from service.worker import Worker

ROOT = Path(__file__).resolve().parents[1]
ARTIFACTS = ROOT / "test-artifacts"
TIMEOUT = 30.0
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium() -> str | None:
    for name in (os.environ.get("CHROMIUM"), *BROWSERS):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _above_nine(fd: int) -> int:
    """``fd`` duplicated to a descriptor above 9 (the original closed)."""
    import fcntl

    moved = fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
    os.close(fd)
    return moved


class Chromium:
    """Headless Chromium driven over the DevTools protocol on a pipe (fds 3 and 4)."""

    def __init__(self, exe: str, url: str, profile: str, size=(1400, 1000)):
        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()
        # the child's ends moved above 9, so that the redirections below never close one
        # another (an end that is already descriptor 3 or 4 was closed by its own move)
        to_browser_r, from_browser_w = (_above_nine(fd) for fd in (to_browser_r, from_browser_w))
        # bash moves the pipe ends to the descriptors Chromium expects, then becomes Chromium
        script = f'exec "$0" "$@" 3<&{to_browser_r} 4>&{from_browser_w} {to_browser_r}<&- ' \
                 f'{from_browser_w}>&-'
        args = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--disable-background-networking", "--disable-component-update",
                "--disable-sync", "--disable-extensions", "--no-first-run",
                "--no-default-browser-check", "--hide-scrollbars", "--mute-audio",
                f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}",
                "--remote-debugging-pipe", "about:blank"]
        self.proc = subprocess.Popen(["bash", "-c", script, *args],
                                     pass_fds=(to_browser_r, from_browser_w),
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._next_id = 0
        self._replies: dict[int, dict] = {}
        self.events: list[dict] = []
        self._cond = threading.Condition()
        self._stderr: list[bytes] = []
        threading.Thread(target=self._read, daemon=True).start()
        threading.Thread(target=lambda: self._stderr.extend(self.proc.stderr), daemon=True).start()
        self.session = None
        self.session = self._attach(url)

    def _read(self) -> None:
        buffer = b""
        with os.fdopen(self._from_browser, "rb", buffering=0) as pipe:
            while True:
                chunk = pipe.read(1 << 16)
                if not chunk:
                    break
                buffer += chunk
                *messages, buffer = buffer.split(b"\0")
                with self._cond:
                    for raw in messages:
                        message = json.loads(raw)
                        if "id" in message:
                            self._replies[message["id"]] = message
                        else:
                            self.events.append(message)
                    self._cond.notify_all()

    def send(self, method: str, params: dict | None = None, *, session=True,
             timeout: float = TIMEOUT) -> dict:
        self._next_id += 1
        call = {"id": self._next_id, "method": method, "params": params or {}}
        if session and self.session:
            call["sessionId"] = self.session
        os.write(self._to_browser, json.dumps(call).encode() + b"\0")
        with self._cond:
            if not self._cond.wait_for(lambda: call["id"] in self._replies, timeout):
                raise AssertionError(f"no reply to {method}; chromium stderr:\n{self.stderr()}")
            reply = self._replies.pop(call["id"])
        if "error" in reply:
            raise AssertionError(f"{method}: {reply['error']}")
        return reply["result"]

    def _attach(self, url: str) -> str:
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})[
            "sessionId"]
        for domain in ("Page", "Runtime", "Log", "Network"):
            self.send(f"{domain}.enable")
        self.send("Page.navigate", {"url": url})
        return self.session

    def evaluate(self, expression: str):
        result = self.send("Runtime.evaluate", {"expression": expression,
                                                "returnByValue": True})
        if "exceptionDetails" in result:
            raise AssertionError(f"page script failed: {result['exceptionDetails']}")
        return result["result"].get("value")

    def wait_for(self, expression: str, what: str, timeout: float = TIMEOUT):
        deadline = time.monotonic() + timeout
        value = None
        while time.monotonic() < deadline:
            value = self.evaluate(expression)
            if value:
                return value
            time.sleep(0.2)
        raise AssertionError(f"timed out waiting for {what}; last value {value!r}")

    def screenshot(self, path: Path) -> None:
        data = self.send("Page.captureScreenshot", {"format": "png"})["data"]
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(base64.b64decode(data))

    def stderr(self) -> str:
        return b"".join(self._stderr).decode(errors="replace")[-3000:]

    def close(self) -> None:
        try:
            self.send("Browser.close", session=False, timeout=5)
        except (AssertionError, OSError):
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._to_browser)


@pytest.fixture
def chromium_exe():
    exe = find_chromium()
    if exe is None:
        pytest.skip("no chromium binary found (apt-get install chromium; .ci/run does)")
    return exe


@pytest.fixture
def browser(chromium_exe):
    opened = []

    def open_page(url):
        profile = tempfile.mkdtemp(prefix="asnn-chromium-")
        opened.append((Chromium(chromium_exe, url, profile), profile))
        return opened[-1][0]

    yield open_page
    for chrome, profile in opened:
        chrome.close()
        shutil.rmtree(profile, ignore_errors=True)


TILES = """JSON.stringify([...document.querySelectorAll('#fleet .tile')].map(t => ({
  robot: t.dataset.robot, collision: t.dataset.collision, stale: t.dataset.stale,
  preview: t.dataset.preview || null, responses: Number(t.dataset.responses || 0),
  contact: t.dataset.contact || null, stats: t.querySelector('.stats').textContent,
  badge: getComputedStyle(t.querySelector('.collision-badge')).display,
  staleBadge: t.querySelector('.stale-badge').textContent})))"""


def tiles(chrome) -> dict:
    return {t["robot"]: t for t in json.loads(chrome.evaluate(TILES))}


def wait_for_tiles(chrome, ready, what: str, timeout: float = TIMEOUT) -> dict:
    """Poll the tiles until ``ready(tiles)`` holds and return that same reading, so nothing
    can change between the check and what the test asserts on."""
    deadline = time.monotonic() + timeout
    shown = {}
    while time.monotonic() < deadline:
        shown = tiles(chrome)
        if ready(shown):
            return shown
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {what}; last tiles {shown!r}")


def check_page_health(chrome, server_url: str) -> None:
    """No script error, no console error, and nothing fetched but the server's own files."""
    errors = [e["params"] for e in chrome.events if e["method"] == "Runtime.exceptionThrown"]
    assert not errors, errors
    logged = [e["params"]["entry"] for e in chrome.events if e["method"] == "Log.entryAdded"
              and e["params"]["entry"]["level"] == "error"]
    assert not logged, logged
    urls = {e["params"]["request"]["url"] for e in chrome.events
            if e["method"] == "Network.requestWillBeSent"}
    assert urls and all(u.startswith(server_url) or u.startswith("data:") for u in urls), urls
    fetched = {u[len(server_url) - 1:].split("?")[0] for u in urls if u.startswith(server_url)}
    assert {"/", "/static/dashboard.js", "/static/dashboard.css", "/events"} <= fetched


def scene_source(name):
    scene = make_scene(name)
    return Source(f"synthetic:{name}", scene.fps, False, lambda: iter(scene.frames))


def test_browser_shows_both_robots_and_only_the_looming_one_colliding(zenoh_net, browser):
    stop = threading.Event()
    cameras = [threading.Thread(target=publish_frames, daemon=True,
                                args=(zenoh_net.spoke(), robot, scene_source(scene)),
                                kwargs=dict(loop=True, stop=stop, wait=TIMEOUT, preview_hz=2.0))
               for robot, scene in (("loom", "looming"), ("bar", "translating_bar"))]
    store = FleetStore()
    # peers do not route for each other: the dashboard shares the hub with the worker, so it
    # hears the cameras' previews (spokes -> hub) and the worker's responses (local)
    try:
        with Worker(zenoh_net.hub, WorkerCore(), stats_every=0), \
                FleetSubscriber(zenoh_net.hub, store), \
                DashboardServer(store, "127.0.0.1", 0) as server:
            for camera in cameras:
                camera.start()
            chrome = browser(server.url)
            chrome.wait_for(
                "(() => { const t = [...document.querySelectorAll('#fleet .tile')];"
                " const loom = t.find(e => e.dataset.robot === 'loom');"
                " const bar = t.find(e => e.dataset.robot === 'bar');"
                " return loom && bar && loom.dataset.collision === 'true'"
                " && loom.dataset.preview === 'true' && bar.dataset.preview === 'true'"
                " && !!loom.dataset.contact"
                " && Number(bar.dataset.responses) >= 60"
                " && document.querySelectorAll('#warnings tbody tr').length > 0; })()",
                "both robots with previews, the looming one colliding, a bar cycle answered")
            time.sleep(0.6)  # let the next animation frame draw the latest state
            # a reading with the time to contact shown: the looping scene restarts far away,
            # its warning held a while after with no approaching target (a CI run read that)
            shown = wait_for_tiles(
                chrome, lambda t: {"loom", "bar"} <= set(t)
                and t["loom"]["collision"] == "true" and t["loom"]["contact"] is not None,
                "the looming robot colliding with its time to contact shown")
            chrome.screenshot(ARTIFACTS / "dashboard.png")
            log_robots = set(json.loads(chrome.evaluate(
                "JSON.stringify([...document.querySelectorAll('#warnings tbody tr')]"
                ".map(r => r.dataset.robot))")))
            check_page_health(chrome, server.url)
    finally:
        stop.set()
        for camera in cameras:
            camera.join(timeout=TIMEOUT)
    assert set(shown) == {"loom", "bar"}
    assert shown["loom"]["collision"] == "true" and shown["loom"]["badge"] != "none"
    assert shown["bar"]["collision"] == "false" and shown["bar"]["badge"] == "none"
    assert shown["loom"]["stale"] == shown["bar"]["stale"] == "false"
    # the robust default's targets carry a time to contact, shown on the tile
    assert 0 < float(shown["loom"]["contact"]) < 5 and "contact in" in shown["loom"]["stats"]
    assert shown["bar"]["contact"] is None and "contact in" not in shown["bar"]["stats"]
    # the rate each robot is answered at (20 fps cameras; fewer where the worker skipped frames)
    assert all(re.search(r" · \d+ fps", shown[r]["stats"]) for r in ("loom", "bar")), shown
    assert log_robots == {"loom"}
    assert store.invalid == {}
    assert (ARTIFACTS / "dashboard.png").stat().st_size > 10_000


def fake_response(robot: str, seq: int, stamp: float, collision: bool) -> bytes:
    return encode(Response(robot=robot, seq=seq, stamp=stamp, model="asnn", preset="default",
                           u=1.0, out=0.9 if collision else 0.1, spikes=2 if collision else 0,
                           spike_rate=40.0 if collision else 0.0, collision=collision,
                           targets=[], worker="w", latency_ms=1.0, dropped=0))


def test_browser_shows_fifty_robots_and_marks_a_silent_one_stale(browser):
    """Fifty robots fed straight into the store (no Zenoh): fifty tiles, the colliding ones
    marked; robots that stop reporting turn stale on the page; robots answered at 10 fps are
    marked slow, and one answered every 2 s too."""
    store = FleetStore(stale_after=1.0)
    names = [f"robot{i:02d}" for i in range(50)]
    stop = threading.Event()
    silent = {"robot07", "robot33"}
    slow = set(names[5::10])  # their frames 0.1 s apart: detected at 10 fps
    crawling = {"robot12"}  # its frames 2 s apart: no rate the worker believes, and slow

    def feed():
        seq = 0
        while not stop.is_set():
            for i, name in enumerate(names):
                if name in silent and seq > 5:
                    continue
                key = f"asnn/{name}/response"
                period = 0.1 if name in slow else 2.0 if name in crawling else 0.05
                store.offer(key, fake_response(name, seq, 1000.0 + seq * period, i % 10 == 0))
            if seq == 10:  # a worker refuses one silent robot's frames and says why
                store.offer("asnn/robot33/refused", encode(Refusal(
                    robot="robot33", worker="w2", reason="too-many-robots",
                    detail="already tracking 256 robots", count=4)))
            seq += 1
            stop.wait(0.05)

    def stale(shown):
        return {n for n, t in shown.items() if t["stale"] == "true"}

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    try:
        with DashboardServer(store, "127.0.0.1", 0) as server:
            chrome = browser(server.url)
            # Waiting for exactly the silent robots to be stale, in one reading: on a loaded
            # machine the feeder thread can stall past ``stale_after``, and the robots it had
            # not reached yet are then stale for a moment too (most likely what failed in CI:
            # two tiles stale by count, none of them stale a moment later).
            shown = wait_for_tiles(
                chrome, lambda shown: len(shown) == 50 and stale(shown) == silent
                and "refused" in shown["robot33"]["stats"],
                "fifty tiles, exactly the silent robots stale, one of them refused")
            chrome.screenshot(ARTIFACTS / "dashboard-fifty.png")
            check_page_health(chrome, server.url)
    finally:
        stop.set()
        feeder.join(timeout=TIMEOUT)
    assert set(shown) == set(names)
    # a stale tile says for how long no worker has answered it (the silent robots stopped
    # after seq 5, over 1 s before they read stale)
    assert all(re.fullmatch(r"STALE \d+ s", shown[n]["staleBadge"]) for n in silent), shown
    assert {n for n, t in shown.items() if t["collision"] == "true"} == set(names[::10])
    assert {n for n, t in shown.items() if "10 fps (slow)" in t["stats"]} == slow
    assert {n for n, t in shown.items() if "under 1 fps (slow)" in t["stats"]} == crawling
    assert all("20 fps" in t["stats"] for n, t in shown.items()
               if n not in slow | silent | crawling)
    assert shown["robot33"]["stats"] == ("refused by w2: too-many-robots (4 frames) · already "
                                         "tracking 256 robots")
    assert "refused" not in shown["robot07"]["stats"]


def test_browser_recovers_a_refused_stream_forgets_any_name_and_shows_no_stale_collision(
        browser):
    """Found by a probe: a page whose event stream was refused (503, every stream taken) never
    opened another; tiles of robots named after an object's own properties (``constructor``)
    were never removed; and a tile whose server went away turned stale but kept its COLLISION
    badge."""
    import socket

    store = FleetStore(stale_after=1.0, forget_after=2.0)
    stop = threading.Event()
    quiet = threading.Event()  # the oddly named robots stop reporting

    def feed():
        seq = 0
        while not stop.is_set():
            names = ["warn", "plain"] + ([] if quiet.is_set() else ["constructor", "toString"])
            for name in names:
                store.offer(f"asnn/{name}/response",
                            fake_response(name, seq, 1000.0 + seq * 0.05, name == "warn"))
            seq += 1
            stop.wait(0.05)

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    try:
        with DashboardServer(store, "127.0.0.1", 0, max_streams=1) as server:
            host, port = server.address
            holder = socket.create_connection((host, port), timeout=TIMEOUT)
            holder.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
            assert b"200" in holder.recv(64)  # it holds the one stream
            chrome = browser(server.url)
            chrome.wait_for("document.getElementById('conn')?.dataset.state === 'lost'",
                            "the page refused its stream")
            holder.close()
            chrome.wait_for("document.getElementById('conn')?.dataset.state === 'live'",
                            "the page opening a new stream once one is free")
            wait_for_tiles(chrome, lambda s: set(s) == {"warn", "plain", "constructor",
                                                        "toString"}, "four tiles")
            # the server's router lost: the page says so (a dashboard operator read "live" and
            # every robot stale, and went looking for failed workers and cameras)
            store.router_changed(False)
            chrome.wait_for("document.getElementById('conn')?.textContent === "
                            "'no router: robots unknown'", "the page told of the lost router")
            store.router_changed(True)
            chrome.wait_for("document.getElementById('conn')?.textContent === 'live'",
                            "the page told of the router again")
            quiet.set()
            shown = wait_for_tiles(chrome, lambda s: set(s) == {"warn", "plain"},
                                   "the silent robots forgotten, whatever their names")
            assert shown["warn"]["collision"] == "true"
        stop.set()  # the server is gone: every tile turns stale, none stays in collision
        shown = wait_for_tiles(chrome, lambda s: all(t["stale"] == "true" for t in s.values()),
                               "every tile stale after the server went away")
    finally:
        stop.set()
        feeder.join(timeout=TIMEOUT)
    assert shown["warn"]["collision"] == "false" and shown["warn"]["badge"] == "none"


# what the page showed at each change of its DOM: the indicator and every tile's flags (a
# MutationObserver, so a state shown for a moment between two polls is not missed)
RECORD_SHOWN = """window.shown = [];
new MutationObserver(() => window.shown.push({
  conn: document.getElementById('conn').textContent,
  tiles: Object.fromEntries([...document.querySelectorAll('#fleet .tile')].map(t =>
    [t.dataset.robot, {stale: t.dataset.stale, collision: t.dataset.collision}]))}))
  .observe(document.body, {subtree: true, childList: true, attributes: true,
                           characterData: true});
true"""


def streams_asked(chrome) -> int:
    """The event streams the page asked for so far."""
    return sum(1 for e in chrome.events if e["method"] == "Network.requestWillBeSent"
               and e["params"]["request"]["url"].endswith("/events"))


def feed_warn_and_plain(store, stop):
    """``warn`` in collision and ``plain`` not, twenty responses a second, until ``stop``."""
    seq = 0
    while not stop.is_set():
        for name in ("warn", "plain"):
            store.offer(f"asnn/{name}/response",
                        fake_response(name, seq, 1000.0 + seq * 0.05, name == "warn"))
        seq += 1
        stop.wait(0.05)


def live_and_warning(shown) -> bool:
    return (set(shown) == {"warn", "plain"} and shown["warn"]["collision"] == "true"
            and all(t["stale"] == "false" for t in shown.values()))


@contextlib.contextmanager
def page_on_a_late_clock(browser):
    """A page showing ``warn`` live in collision and ``plain`` (fed twenty times a second),
    recording what it shows (``RECORD_SHOWN``), from a server whose clock stamps its events
    ``late[0]`` seconds before they are sent: yields ``(server, chrome, late)``."""
    store = FleetStore()
    stop = threading.Event()
    late = [0.0]
    feeder = threading.Thread(target=feed_warn_and_plain, args=(store, stop), daemon=True)
    feeder.start()
    try:
        with DashboardServer(store, "127.0.0.1", 0,
                             clock=lambda: time.monotonic() - late[0]) as server:
            chrome = browser(server.url)
            wait_for_tiles(chrome, live_and_warning, "warn live in collision")
            assert chrome.evaluate(RECORD_SHOWN)
            yield server, chrome, late
    finally:
        stop.set()
        feeder.join(timeout=TIMEOUT)


def test_browser_shows_events_that_arrive_late_as_stale_and_takes_a_new_stream(browser):
    """A control-room trial: after the server dropped a slow page's stream, the events its
    kernel had buffered still arrived, and the page showed them as current (a warning over for
    tens of seconds). Here the server's clock says its events were taken 20 s before they
    arrive: the page must show them stale (so in no collision), say it is behind, and take a
    new stream by itself, whose state is live again."""
    with page_on_a_late_clock(browser) as (server, chrome, late):
        asked = streams_asked(chrome)
        late[0] = 20.0
        chrome.wait_for("window.shown.some(s => /^2\\d s behind: reconnecting$/"
                        ".test(s.conn))", "the page saying it is 20 s behind")
        shown = wait_for_tiles(chrome, lambda s: live_and_warning(s) and streams_asked(
            chrome) > asked and chrome.evaluate(
            "document.getElementById('conn').textContent") == "live",
            "a new stream, live again")
        seen = chrome.evaluate("window.shown")
        check_page_health(chrome, server.url)
    behind = [i for i, s in enumerate(seen) if s["conn"].endswith("behind: reconnecting")]
    # what arrived 20 s late was shown stale, in no collision; nothing live until a new stream
    assert seen[behind[0]]["tiles"]["warn"] == {"stale": "true", "collision": "false"}, seen
    assert all(s["tiles"]["warn"]["collision"] == "false" for s in seen[behind[0]:]
               if s["conn"] != "live"), seen
    assert shown["warn"]["collision"] == "true" and shown["warn"]["stale"] == "false"


def test_browser_keeps_a_stream_that_catches_up(browser):
    """Updates that arrive late and then on time again (a slow link draining what queued behind
    a large snapshot) are shown as old as they are, and the stream is kept: replaced at its
    first late update, a page on a slow link would download the snapshot again and again,
    never live (a review of the freshness rule)."""
    with page_on_a_late_clock(browser) as (server, chrome, late):
        asked = streams_asked(chrome)
        late[0] = 20.0
        chrome.wait_for("window.shown.some(s => /^2\\d s behind$/.test(s.conn))",
                        "the page saying it is 20 s behind")
        late[0] = 0.0  # caught up
        shown = wait_for_tiles(chrome, lambda s: live_and_warning(s) and chrome.evaluate(
            "document.getElementById('conn').textContent") == "live", "live again")
        seen = chrome.evaluate("window.shown")
        kept = streams_asked(chrome) == asked
        check_page_health(chrome, server.url)
    assert kept, "the page replaced a stream that caught up"
    behind = [i for i, s in enumerate(seen) if s["conn"].endswith("s behind")]
    # while behind, what arrived late was shown stale, in no collision
    assert all(s["tiles"]["warn"]["collision"] == "false" for s in seen[behind[0]:]
               if s["conn"] != "live"), seen
    assert shown["warn"]["collision"] == "true" and shown["warn"]["stale"] == "false"


def test_browser_takes_a_new_stream_when_its_stream_falls_silent(browser):
    """A stream that stops without ending (a connection cut on the way: no end ever arrives)
    is replaced by the page once silent for longer than the staleness limit (at least 3 s):
    the server sends an event at least every second."""
    store = FleetStore()
    stop, hold, held, release = (threading.Event() for _ in range(4))
    feeder = threading.Thread(target=feed_warn_and_plain, args=(store, stop), daemon=True)
    feeder.start()
    try:
        with DashboardServer(store, "127.0.0.1", 0) as server:
            taken = server.state

            def state(since=0):
                if since and hold.is_set() and not held.is_set():  # the one stream open now
                    held.set()
                    release.wait(TIMEOUT)
                return taken(since)

            server.state = state
            chrome = browser(server.url)
            wait_for_tiles(chrome, live_and_warning, "warn live in collision")
            assert chrome.evaluate(RECORD_SHOWN)
            asked = streams_asked(chrome)
            hold.set()
            chrome.wait_for("window.shown.some(s => s.conn.endsWith('behind: reconnecting'))",
                            "the page saying its stream is silent")
            wait_for_tiles(chrome, lambda s: live_and_warning(s) and streams_asked(
                chrome) > asked, "a new stream, live again")
            assert held.is_set() and not release.is_set()  # the first is still open, silent
            release.set()
            check_page_health(chrome, server.url)
    finally:
        release.set()
        stop.set()
        feeder.join(timeout=TIMEOUT)


def test_browser_says_it_waits_for_a_streams_first_event_not_live(browser):
    """An earlier session: a stream open but with no first event yet (its snapshot waiting for
    a send slot) read "live" in the header, while the tiles shown were older than it. Here the
    first snapshot is held: the page says it waits, then "live" once the snapshot comes."""
    store = FleetStore()
    stop, held, release = (threading.Event() for _ in range(3))
    feeder = threading.Thread(target=feed_warn_and_plain, args=(store, stop), daemon=True)
    feeder.start()
    try:
        with DashboardServer(store, "127.0.0.1", 0) as server:
            taken = server.state

            def state(since=0):
                if since == 0 and not held.is_set():  # the first stream's snapshot
                    held.set()
                    release.wait(TIMEOUT)
                return taken(since)

            server.state = state
            chrome = browser(server.url)
            chrome.wait_for("document.getElementById('conn')?.dataset.state === 'connecting'"
                            " && document.getElementById('conn').textContent === "
                            "'waiting for the first event'", "the page saying it waits")
            assert held.is_set() and not release.is_set()
            assert chrome.evaluate("document.querySelectorAll('#fleet .tile').length") == 0
            release.set()
            wait_for_tiles(chrome, lambda s: live_and_warning(s) and chrome.evaluate(
                "document.getElementById('conn').textContent") == "live", "live at last")
            assert streams_asked(chrome) == 1  # the stream that waited, kept
            check_page_health(chrome, server.url)
    finally:
        release.set()
        stop.set()
        feeder.join(timeout=TIMEOUT)
