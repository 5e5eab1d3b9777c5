"""The dashboard under load and abuse (issue 13, item 8): state bounded in bytes, new robots not
hidden by a burst of ids, slow, idle and half-open connections closed, a connection cap that
leaves room for a browser, and logs that do not grow with a flood."""

from __future__ import annotations

import json
import logging
import socket
import struct
import time

import cv2
import msgpack
import numpy as np

from clients.dashboard import DashboardServer, FleetStore
from clients.dashboard.store import MAX_PREVIEW_TOTAL
from clients.fleet import MAX_TARGETS
from service.messages import Preview, encode

from netutil import wait_for
from test_dashboard import Clock, get, offer_response, response


def big_preview(seq=0) -> bytes:
    """A valid preview of about 56 KiB (noise does not compress), under the per-robot bound."""
    noise = np.random.default_rng(seq).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    data = cv2.imencode(".png", noise)[1].tobytes()
    assert 50_000 < len(data) < 64 * 1024
    return encode(Preview(seq=seq, stamp=1000.0, width=160, height=120, format="png",
                          data=data))


def test_previews_and_state_are_bounded_in_bytes_per_robot_and_in_total():
    """1,000 robot ids with big previews made /state 335 MB."""
    clock = Clock()
    store = FleetStore(clock=clock)
    payload = big_preview()
    for i in range(1000):
        clock.now += 0.05  # within the thumbnails' rate (PREVIEW_RATE bytes a second)
        assert store.offer(f"asnn/r{i}/preview", payload) == f"r{i}"
    offer_response(store, response("r0", targets=[(i, i) for i in range(500)]))
    assert store.preview_bytes <= MAX_PREVIEW_TOTAL
    state = json.dumps(store.delta(0))
    assert len(state) < 2 * MAX_PREVIEW_TOTAL
    assert len(json.loads(state)["robots"]) == 1000  # every robot still shown
    assert len(json.loads(state)["robots"]["r0"]["targets"]) == MAX_TARGETS
    # the newest previews are the ones kept
    assert "src" in json.loads(state)["robots"]["r999"]["preview"]


def test_a_flood_of_previews_is_taken_at_a_bounded_rate_in_bytes_and_per_robot():
    """A probe: 1,000 ids sending 30 KB previews made every page receive 20-34 MB/s, and a
    browser that fell behind was dropped (its robots shown stale)."""
    from clients.dashboard.store import PREVIEW_INTERVAL, PREVIEW_RATE

    clock = Clock()
    store = FleetStore(clock=clock)
    payload = big_preview()
    size = len(msgpack.unpackb(payload)["data"])
    for second in range(3):
        for step in range(20):  # 20 a second from each of 100 robots
            clock.now += 0.05
            for i in range(100):
                store.offer(f"asnn/r{i}/preview", payload)
    taken = store.received["preview"] - store.skipped["preview"]
    assert taken * size <= PREVIEW_RATE * (3 + 1)  # the bucket starts full
    assert taken * size > PREVIEW_RATE * 2  # and the rate is used
    assert store.delta(0)["counts"]["skipped"]["preview"] == store.skipped["preview"]
    # one robot alone: at most one every PREVIEW_INTERVAL seconds
    lone = FleetStore(clock=clock)
    for step in range(16):
        clock.now += 0.125  # eight a second, exact in binary
        lone.offer("asnn/solo/preview", payload)
    assert lone.received["preview"] - lone.skipped["preview"] == 16 * 0.125 / PREVIEW_INTERVAL


def test_long_names_in_responses_are_shortened_not_held_per_robot():
    """A hostile review: responses and warnings whose model, preset and worker were 64 KiB
    strings (within the msgpack bounds), from 1,000 robot ids, held 380 MB in the store and
    made /state 190 MB. CONTRACT.md bounds none of these strings, so such a response (a
    warning above all) is taken, with at most MAX_NOTE_LEN characters of each kept."""
    import msgpack

    from service.messages import MAX_NOTE_LEN

    store = FleetStore(clock=Clock())
    fields = response("r0").model_dump()
    for i, name in enumerate(("model", "preset", "worker")):
        fields = {**fields, name: "x" * 65535}
        payload = msgpack.packb({**fields, "seq": 2 * i, "stamp": 1000.0 + 2 * i})
        assert store.offer("asnn/r0/response", payload) == "r0"
        assert store.offer("asnn/r0/warning", msgpack.packb(
            {**fields, "seq": 2 * i + 1, "stamp": 1001.0 + 2 * i, "collision": True})) == "r0"
    assert store.invalid == {}
    state = json.dumps(store.delta(0))
    tile = json.loads(state)["robots"]["r0"]
    assert tile["collision"] and tile["warnings"] == 3
    assert [len(tile["response"][name]) for name in ("model", "preset", "worker")] == \
        [MAX_NOTE_LEN] * 3
    assert len(state) < 16 * 1024


def test_the_targets_kept_to_match_previews_cost_little_per_robot():
    """A hostile review: 32 responses of 16 targets from each of 1,000 robot ids held 670 MB
    in the store (the targets kept to match a preview's seq, as Response objects)."""
    import tracemalloc

    store = FleetStore(clock=Clock())
    targets = [(i, i) for i in range(MAX_TARGETS)]
    payloads = [encode(response(f"r{i}", seq, targets=targets)) for i in range(100)
                for seq in range(32)]
    tracemalloc.start()
    try:
        for payload in payloads:
            store.offer(f"asnn/{msgpack.unpackb(payload)['robot']}/response", payload)
        held = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert held < 15 * 1024 * 1024, held  # 67 MB before
    # still drawn on the preview of the frame they belong to
    store.offer("asnn/r7/preview", encode(Preview.from_frame_image(
        np.zeros((48, 64), np.uint8), seq=20, stamp=1001.0, width=32)))
    drawn = store.delta(0)["robots"]["r7"]["targets"]
    assert [(t["x"], t["y"]) for t in drawn] == [(float(x), float(y)) for x, y in targets]


def png_of_zeros(width, height, colour_type=6, channels=4) -> bytes:
    """A png of width x height black pixels, written by hand: deflate packs a 4096x4096 RGBA
    one into 64 KiB."""
    import struct
    import zlib

    def chunk(kind, body):
        return (struct.pack(">I", len(body)) + kind + body
                + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    rows = (b"\0" * (1 + width * channels)) * height
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b""))


def test_a_preview_declaring_too_many_pixels_is_refused_before_it_is_decoded(monkeypatch):
    """A hostile review: a 64 KiB png preview of 4096x4096 RGBA took a viewer 0.36 s of CPU
    and 110 MB to decode (a thumbnail from asnn camera: 0.25 ms), so a few a second kept the
    dashboard and the Foxglove server busy."""
    import cv2

    from service.messages import MAX_PREVIEW_BYTES

    bomb = png_of_zeros(4096, 4096)
    assert len(bomb) <= MAX_PREVIEW_BYTES
    decoded = []
    real = cv2.imdecode
    monkeypatch.setattr(cv2, "imdecode", lambda *a: decoded.append(a) or real(*a))
    store = FleetStore(clock=Clock())
    payload = encode(Preview(seq=0, stamp=1.0, width=4096, height=4096, format="png",
                             data=bomb))
    assert store.offer("asnn/r1/preview", payload) is None
    assert store.invalid == {"oversized": 1} and not decoded
    # the tallest thumbnail asnn camera makes (a 160 x 4096 frame, never scaled up) is shown
    tall = png_of_zeros(160, 4096, colour_type=0, channels=1)
    assert store.offer("asnn/r1/preview", encode(Preview(
        seq=1, stamp=1.0, width=160, height=4096, format="png", data=tall))) == "r1"
    assert len(decoded) == 1


def test_a_burst_of_ids_does_not_hide_new_robots_once_it_is_stale():
    clock = Clock()
    store = FleetStore(clock=clock, max_robots=10, stale_after=3.0)
    for i in range(10):
        offer_response(store, response(f"junk{i}"))
    assert offer_response(store, response("real")) is None  # all ten are live: no room
    clock.now += 5.0
    assert offer_response(store, response("real")) == "real"
    assert "real" in store.robots() and len(store.robots()) == 10


def raw_client(server, source="127.0.0.1", rcvbuf=None):
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    if rcvbuf:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    sock.bind((source, 0))
    sock.settimeout(20)
    sock.connect(server.address)
    return sock


def closed_by_server(sock, timeout=20.0) -> bool:
    """True once the server has closed the connection (reads end), within ``timeout``."""
    sock.settimeout(timeout)
    try:
        while sock.recv(65536):
            pass
    except (TimeoutError, ConnectionResetError):
        return False
    return True


def test_an_event_stream_that_is_never_read_is_dropped():
    """A client that never reads held a full snapshot (330 MB) and a thread forever."""
    store = FleetStore()
    payload = big_preview()
    for i in range(40):  # about 3 MB of state: far more than the socket buffers
        store.offer(f"asnn/r{i}/preview", payload)
    with DashboardServer(store, "127.0.0.1", 0, send_timeout=1.0,
                         send_buffer=16 * 1024) as server:
        sock = raw_client(server, rcvbuf=4096)
        sock.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
        wait_for(lambda: server.clients == 1, what="the stream to start")
        wait_for(lambda: server.clients == 0, what="the unread stream to be dropped")
        assert server.dropped_streams == 1
        sock.close()


def read_until_closed(sock, timeout=20.0) -> bytes:
    """Everything the server sent, once it closed the connection (within ``timeout``)."""
    sock.settimeout(timeout)
    chunks = []
    while chunk := sock.recv(65536):
        chunks.append(chunk)
    return b"".join(chunks)


def sse_events(raw: bytes) -> list[tuple[str, dict]]:
    """The whole events in a stream's bytes (an event cut off by the end is not one)."""
    events = []
    for block in raw.split(b"\r\n\r\n", 1)[-1].split(b"\n\n")[:-1]:
        fields = dict(line.split(": ", 1) for line in block.decode().split("\n") if ": " in line)
        if "event" in fields:
            events.append((fields["event"], json.loads(fields["data"])))
    return events


def test_the_events_a_dropped_stream_still_delivers_say_when_their_state_was_taken():
    """A control-room trial: after the server dropped a slow client's stream, the events the
    kernel had buffered for it still reached the page, which showed a warning that had ended
    long before as current. Every event carries ``at``, the server's monotonic clock when its
    state was taken, by which the page judges how far behind it is (docs/contract.md)."""
    store = FleetStore()
    offer_response(store, response("warn", 0, collision=True))
    with DashboardServer(store, "127.0.0.1", 0, send_timeout=1.0, heartbeat=0.1,
                         send_buffer=16 * 1024) as server:
        sock = raw_client(server, rcvbuf=4096)
        asked = time.monotonic()
        sock.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
        wait_for(lambda: server.clients == 1, what="the stream to start")
        time.sleep(0.5)  # a few heartbeats, each a whole event in the buffers
        for i in range(10):  # far more than the sockets' buffers: the client is behind
            store.offer(f"asnn/r{i}/preview", big_preview(i))
        wait_for(lambda: server.clients == 0, what="the unread stream to be dropped")
        dropped = time.monotonic()
        offer_response(store, response("warn", 1))  # its warning is over
        raw = read_until_closed(sock)
        sock.close()
        now = store.delta(0)
    assert server.dropped_streams == 1
    events = sse_events(raw)
    assert [e for e, _ in events][:2] == ["snapshot", "update"], events
    # what still arrived after the drop is the state from before it: the warning as current
    assert all(delta["live"]["warn"][2] for _, delta in events)
    assert not now["live"]["warn"][2]
    # ... and each event says when it was taken, on the server's clock (here the test's own)
    stamps = [delta["at"] for _, delta in events]
    assert all(asked <= at <= dropped for at in stamps), (asked, stamps, dropped)
    assert stamps == sorted(stamps)


def test_idle_and_half_open_connections_are_closed():
    with DashboardServer(FleetStore(), "127.0.0.1", 0, idle_timeout=0.5) as server:
        half = raw_client(server)
        half.sendall(b"GET / HTTP/1.1\r\nHost:")  # and nothing more
        idle = raw_client(server)
        idle.sendall(b"GET /state HTTP/1.1\r\nHost: x\r\n\r\n")  # kept alive, then silent
        assert idle.recv(65536).startswith(b"HTTP/1.1 200")
        silent = raw_client(server)  # connects and never says anything
        drip = raw_client(server)  # a byte now and then, each within the timeout (slowloris)
        cut_off = False
        for byte in b"GET / HTTP/1.1\r\nHost: x\r\nX-Pad: " + b"a" * 40:  # 6 s of bytes
            try:
                drip.sendall(bytes([byte]))
            except OSError:  # the server closed it: the request did not arrive whole in time
                cut_off = True
                break
            time.sleep(0.1)
        assert cut_off
        for sock in (half, idle, silent, drip):
            assert closed_by_server(sock)
            sock.close()
        wait_for(lambda: server.connections == 0, what="the connections to be released")


def test_held_event_streams_leave_room_for_a_browser():
    """200 held event streams made a real browser get 503."""
    store = FleetStore()
    offer_response(store, response())
    with DashboardServer(store, "127.0.0.1", 0, max_streams=16, max_streams_per_address=4,
                         spare_connections=16) as server:
        held = []
        for _ in range(100):  # from another loopback address than the browser's
            sock = raw_client(server, source="127.0.0.2")
            try:
                sock.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
            except OSError:
                pass
            held.append(sock)
        wait_for(lambda: server.clients == 4, what="the attacker's streams")
        assert server.connections <= 32
        # the browser: the page, its assets, the state and its own event stream
        for path in ("/", "/static/dashboard.js", "/static/dashboard.css", "/state"):
            assert get(server, path)[0] == 200, path
        browser = raw_client(server)
        browser.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
        assert browser.recv(4096).startswith(b"HTTP/1.1 200")
        browser.close()
        for sock in held:
            sock.close()


def test_floods_of_invalid_messages_and_dropped_connections_log_a_few_lines(caplog, capfd):
    store = FleetStore()
    for i in range(40):
        store.offer(f"asnn/r{i}/preview", big_preview())
    with caplog.at_level(logging.DEBUG, logger="asnn.dashboard"):
        for _ in range(1000):
            store.offer("asnn/r1/response", b"\xc1")
        assert store.invalid["undecodable"] == 1000
        with DashboardServer(store, "127.0.0.1", 0) as server:
            for _ in range(20):  # ask for 3 MB and reset the connection at once
                sock = raw_client(server)
                sock.sendall(b"GET /state HTTP/1.1\r\nHost: x\r\n\r\n")
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                sock.close()
            time.sleep(0.5)
            assert get(server, "/")[0] == 200
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) <= 3, [r.getMessage() for r in warnings]
    assert "Traceback" not in capfd.readouterr().err


def test_full_snapshots_are_sent_a_few_at_a_time():
    """A probe: 63 connections asking for /state (24 MB) and reading slowly held 2.3 GB, each
    its own encoded copy. At most MAX_FULL_SENDS are encoded and sent at once; past the wait,
    /state is 503."""
    from clients.dashboard.server import MAX_FULL_SENDS

    store = FleetStore()
    offer_response(store, response("r0"))
    with DashboardServer(store, "127.0.0.1", 0, send_timeout=0.5) as server:
        for _ in range(MAX_FULL_SENDS):  # as many slow readers are being sent theirs
            assert server._full_sends.acquire(timeout=1)
        status, _, body = get(server, "/state")
        assert status == 503 and body == b"busy: try again\n"
        server._full_sends.release()
        status, _, body = get(server, "/state")
        assert status == 200 and "r0" in json.loads(body)["robots"]


def test_a_request_of_more_than_64_kib_of_headers_is_cut_off():
    """A probe: 99 headers of 64 KiB each (the standard library's limits) on 64 connections
    held 400 MB. A request line and headers are read up to MAX_REQUEST_BYTES."""
    from clients.dashboard.server import MAX_REQUEST_BYTES

    store = FleetStore()
    with DashboardServer(store, "127.0.0.1", 0) as server:
        host, port = server.address
        with socket.create_connection((host, port), timeout=10) as sock:
            header = b"X-Pad: " + b"a" * 8000 + b"\r\n"
            sent = b"GET / HTTP/1.1\r\nHost: x\r\n"
            try:
                sock.sendall(sent)
                while len(sent) < 4 * MAX_REQUEST_BYTES:
                    sock.sendall(header)
                    sent += header
                sock.sendall(b"\r\n")
                answer = sock.recv(4096)
            except (ConnectionResetError, BrokenPipeError):
                answer = b""
        assert answer == b""  # closed without an answer, before the request was read
        status, _, _ = get(server, "/")  # and the server serves on
        assert status == 200


def test_control_and_format_characters_of_names_are_left_out():
    """A probe: a right-to-left override in ``model`` reversed the rest of a tile's line; an
    escape sequence in ``worker`` would reach ``asnn alerts``' terminal."""
    from clients.fleet import decode_fleet_sample

    fields = response("r0").model_dump()
    payload = msgpack.packb({**fields, "model": "asnn\u202e tsubor", "worker": "w\x1b[31mred"})
    _, _, message = decode_fleet_sample("asnn/r0/response", payload, "asnn")
    assert (message.model, message.worker) == ("asnn tsubor", "w[31mred")
    assert message.preset == fields["preset"]  # printable names as they are
