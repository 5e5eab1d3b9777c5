"""Hostile and unlucky input to the worker (issue 13): memory amplification by images and msgpack
containers, robot-slot lockout, unfair scheduling under overload and a second publisher on a
robot's key. Memory is measured (RSS of a child process, or tracemalloc), never time."""

import json
import logging
import signal
import struct
import subprocess
import sys
import time
import tracemalloc
import zlib

import msgpack
import numpy as np
import pytest

from asnn.io.images import ImageError, check_encoded, min_encoded_bytes
from asnn.stimuli import make_scene
from service.core import WorkerCore
from service.messages import MAX_ITEMS, MAX_PAYLOAD, Frame, MessageError, decode_frame, encode_image

from service.worker import Worker

from netutil import ROOT, FramePump, Responses, wait_for
from test_worker import FakeClock, feed, payload, undecodable_jpeg

MB = 1 << 20


def lying_jpeg(width=4096, height=4096) -> bytes:
    """The 333-byte jpeg of an 8x8 black image, its header edited to say width x height."""
    data = bytearray(encode_image(np.zeros((8, 8), np.uint8), "jpeg"))
    sof = data.index(b"\xff\xc0")
    data[sof + 5:sof + 7] = height.to_bytes(2, "big")
    data[sof + 7:sof + 9] = width.to_bytes(2, "big")
    return bytes(data)


def png_chunk(kind: bytes, body: bytes, crc: int | None = None) -> bytes:
    """A png chunk: length, type, body and its CRC (``crc`` where given: a wrong one)."""
    crc = zlib.crc32(kind + body) if crc is None else crc
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)


def frame_map(**fields) -> bytes:
    return msgpack.packb({"v": 1, "seq": 0, "stamp": 0.0, **fields})


# ---------------------------------------------------------------- 1. image amplification

def test_the_header_must_allow_a_whole_image_of_its_size():
    data = lying_jpeg()
    assert len(data) < 400
    with pytest.raises(ImageError) as err:
        check_encoded(data, "jpeg", (4096, 4096))
    assert err.value.reason == "bad-image" and "truncated" in err.value.detail
    frame = Frame(seq=0, stamp=0.0, width=4096, height=4096, format="jpeg", data=data)
    for check in (frame.check_size, frame.image):  # on the wire: a counted bad-image
        with pytest.raises(MessageError) as err:
            check()
        assert err.value.reason == "bad-image" and "truncated" in err.value.detail
    # what real encoders make of the worst case, a uniform image, is well above the bounds
    for fmt in ("jpeg", "png"):
        flat = encode_image(np.zeros((1024, 1024), np.uint8), fmt)
        check_encoded(flat, fmt, (1024, 1024))
        assert len(flat) > 1.3 * min_encoded_bytes(fmt, 1024, 1024)
    # 16-bit png, arithmetic-coded or lossless jpeg: refused from the header
    import cv2
    ok, deep = cv2.imencode(".png", np.zeros((64, 64), np.uint16))
    with pytest.raises(ImageError, match="8-bit"):
        check_encoded(deep.tobytes(), "png", (64, 64))
    arith = bytearray(encode_image(np.zeros((64, 64), np.uint8), "jpeg"))
    sof = arith.index(b"\xff\xc0")
    arith[sof + 1] = 0xC9
    with pytest.raises(ImageError, match="not supported"):
        check_encoded(bytes(arith), "jpeg", (64, 64))


def repeated_scans(copies: int) -> bytes:
    """A progressive 4096x4096 gray jpeg (66 KB) with its last scan (33 bytes) repeated."""
    import cv2

    data = cv2.imencode(".jpg", np.zeros((4096, 4096), np.uint8),
                        [cv2.IMWRITE_JPEG_QUALITY, 50, cv2.IMWRITE_JPEG_PROGRESSIVE, 1])[1]
    data = data.tobytes()
    start, end = data.rindex(b"\xff\xda"), data.rindex(b"\xff\xd9")
    return data[:end] + data[start:end] * copies + data[end:]


def test_a_jpeg_of_many_scans_is_refused_before_it_is_decoded(monkeypatch):
    """A hostile review: each scan of a progressive jpeg costs a pass over every block of the
    image, whatever its few bytes: 1,000 copies of one 33-byte scan made a 99 KB frame (or
    preview) that took 10.8 s to decode (0.08 s without them); a 48 MiB frame holds a million,
    hours of one processing thread."""
    import cv2  # its decoder watched: asnn.io.images imports it where it decodes

    decoded = []
    real = cv2.imdecode
    monkeypatch.setattr(cv2, "imdecode", lambda *a: decoded.append(a) or real(*a))
    bomb = repeated_scans(1000)
    assert len(bomb) < 100_000
    frame = Frame(seq=0, stamp=0.0, width=4096, height=4096, format="jpeg", data=bomb)
    for check in (frame.check_size, frame.image):
        with pytest.raises(MessageError) as err:
            check()
        assert err.value.reason == "bad-image" and "scans" in err.value.detail
    assert not decoded
    # what encoders write passes: baseline, and progressive colour (10 scans) and gray
    image = make_scene("looming").frames[5]
    for params in ([], [cv2.IMWRITE_JPEG_PROGRESSIVE, 1]):
        for picture in (image, cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)):
            data = cv2.imencode(".jpg", picture, params)[1].tobytes()
            h, w = picture.shape[:2]
            check_encoded(data, "jpeg", (w, h))
    assert check_encoded(repeated_scans(0), "jpeg", (4096, 4096)) == (4096, 4096)


def test_a_png_whose_data_inflates_past_its_image_is_refused_before_it_is_decoded(monkeypatch):
    """A hostile review: the decoder inflates whatever deflate data follows a png's rows: 1 MB
    that inflates to 1 GB after a 1024x1024 image took 0.97 s to decode (5 ms without it); a
    48 MiB frame, 45 s of a processing thread."""
    import cv2

    from asnn.io.images import decode_encoded

    def png(rows, extra):
        packer = zlib.compressobj(9)
        body = packer.compress(rows) + packer.compress(b"\0" * extra) + packer.flush()
        header = struct.pack(">IIBBBBB", 1024, 1024, 8, 0, 0, 0, 0)
        return (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", header) + png_chunk(b"IDAT", body)
                + png_chunk(b"IEND", b""))

    rows = b"\0" * (1025 * 1024)
    decoded = []
    real = cv2.imdecode
    monkeypatch.setattr(cv2, "imdecode", lambda *a: decoded.append(a) or real(*a))
    with pytest.raises(ImageError, match="inflates to more"):
        decode_encoded(png(rows, 64 << 20), "png", (1024, 1024))
    assert not decoded
    assert decode_encoded(png(rows, 0), "png", (1024, 1024)).shape == (1024, 1024)
    # what encoders write passes, at every depth
    from io import BytesIO

    from PIL import Image

    noise = np.random.default_rng(5).integers(0, 256, (61, 83, 3), dtype=np.uint8)
    for mode, picture in (("RGB", noise), ("L", noise[:, :, 0]), ("1", noise[:, :, 0] > 128)):
        out = BytesIO()
        Image.fromarray(picture).convert(mode).save(out, "png")
        assert decode_encoded(out.getvalue(), "png", (83, 61)).shape[:2] == (61, 83)


def test_a_jpeg_of_a_million_markers_is_refused_from_its_first_thousand():
    """4 MB of fill bytes (or a million empty APP0 segments) before a jpeg's frame header kept
    the reader 0.7 s on the thread that receives the worker's frames: each marker was read in
    turn. What encoders write, an ICC profile in 50 APP2 segments and a few fill bytes
    included, passes."""
    from asnn.io.images import MAX_JPEG_MARKERS

    jpeg = encode_image(np.zeros((64, 64), np.uint8), "jpeg")
    core = WorkerCore()
    for k, junk in enumerate((b"\xff" * 4_000_000, b"\xff\xe0\x00\x02" * 1_000_000)):
        bomb = jpeg[:2] + junk + jpeg[2:]
        with pytest.raises(ImageError, match="markers"):
            check_encoded(bomb, "jpeg", (64, 64))
        assert core.offer(f"asnn/r{k}/frame", frame_map(width=64, height=64, format="jpeg",
                                                         data=bomb)) is None
    assert core.stats()["invalid"] == {"bad-image": 2}
    profile = (b"\xff\xe2" + (2 + 1000).to_bytes(2, "big") + b"\0" * 1000) * 50
    legit = jpeg[:2] + b"\xff" * 7 + profile + jpeg[2:]
    assert check_encoded(legit, "jpeg", (64, 64)) == (64, 64)
    assert 50 + 20 < MAX_JPEG_MARKERS


def test_a_jpeg_cut_short_is_refused_from_its_end(capfd):
    """A jpeg that lost its tail on the way passed the size check and was refused by the
    decoder only, on the processing thread, after libjpeg's line on stderr. It is refused on
    arrival now, quietly. Padding after the end-of-image marker passes."""
    image = make_scene("looming").frames[40]
    jpeg = encode_image(image, "jpeg")
    for cut in (jpeg[:-2], jpeg[:-200]):
        frame = Frame(seq=0, stamp=0.0, width=128, height=128, format="jpeg", data=cut)
        with pytest.raises(MessageError) as err:
            frame.check_size()
        assert err.value.reason == "bad-image" and "truncated" in err.value.detail
    assert "JPEG" not in capfd.readouterr().err
    for padded in (jpeg + b"\0" * 100, jpeg + b"\xff" * 5):
        assert check_encoded(padded, "jpeg", (128, 128)) == (128, 128)


def test_png_chunks_libpng_would_warn_about_or_read_by_the_million_are_refused(capfd):
    """libpng writes two lines to stderr for each ancillary chunk whose CRC is wrong: 1,000 of
    them, 2,000 lines per frame, past every rate limit of the worker's log. Chunks with wrong
    CRCs, more than MAX_PNG_ANCILLARY ancillary ones, more chunks than two a row (300,000
    empty IDATs), pixels that are not deflate or a file cut short (libpng's and OpenCV's
    lines) are refused before the decoder sees them; a few text chunks pass."""
    from asnn.io.images import MAX_PNG_ANCILLARY, decode_encoded

    png = encode_image(np.zeros((64, 64), np.uint8), "png")
    at = png.index(b"IDAT") - 4
    text = png_chunk(b"tEXt", b"k\0v")
    for extra, why in ((png_chunk(b"tEXt", b"", crc=0) * 1000, "CRC"),
                       (text * (MAX_PNG_ANCILLARY + 1), "ancillary"),
                       (png_chunk(b"IDAT", b"") * 300_000, "in all"),
                       (png_chunk(b"IDAT", b"\xff" * 64), "inflate")):  # not deflate: one line
        with pytest.raises(ImageError, match=why):
            decode_encoded(png[:at] + extra + png[at:], "png", (64, 64))
    for cut in (png[:-40], png[:-12]):  # inside the pixels, or without IEND: two lines each
        with pytest.raises(ImageError, match="truncated"):
            decode_encoded(cut, "png", (64, 64))
    assert "libpng" not in capfd.readouterr().err
    assert decode_encoded(png[:at] + text * 10 + png[at:], "png", (64, 64)).shape == (64, 64)


CHILD = r"""
import json, os, resource, sys
import numpy as np, msgpack
from service.core import WorkerCore
from service.messages import encode_image
from asnn.stimuli import make_scene

def rss():
    return int(open("/proc/self/statm").read().split()[1]) * os.sysconf("SC_PAGE_SIZE")

data = bytes.fromhex(sys.argv[1])
core = WorkerCore(idle_timeout=600)
scene = make_scene("looming")
for seq in range(3):  # a real robot first: the kernels are loaded, the allocator warm
    core.offer("asnn/real/frame", msgpack.packb({"v": 1, "seq": seq, "stamp": seq * 0.05,
               "width": 128, "height": 128, "format": "jpeg",
               "data": encode_image(scene.frames[seq], "jpeg")}))
    core.process(core.take())
before, peak_before = rss(), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
for i in range(int(sys.argv[2])):
    for seq in range(2):
        core.offer(f"asnn/evil{i}/frame", msgpack.packb({"v": 1, "seq": seq, "stamp": 0.05 * seq,
                   "width": 4096, "height": 4096, "format": "jpeg", "data": data}))
        job = core.take()
        if job is not None:
            core.process(job)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps({"growth": rss() - before, "peak_growth": max(0, peak - max(before, peak_before)),
                  "stats": core.stats()}))
"""


def test_a_truncated_jpeg_declaring_4096_squared_costs_the_worker_no_memory():
    """Issue 13 (1): each such robot id used to cost ~0.9 GB (decoded padding + model state)."""
    out = subprocess.run([sys.executable, "-c", CHILD, lying_jpeg().hex(), "3"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["growth"] < 150 * MB and result["peak_growth"] < 150 * MB, result
    assert result["stats"]["invalid"] == {"bad-image": 6}
    assert result["stats"]["robots"] == 1 and result["stats"]["candidates"] == 0


# ---------------------------------------------------------------- 2. msgpack containers

def huge_map(entries: int) -> bytes:
    """A msgpack map of ``entries`` distinct uint32 keys to 0, built without Python objects."""
    body = np.zeros((entries, 6), np.uint8)
    body[:, 0] = 0xCE
    body[:, 1:5] = np.arange(entries, dtype=">u4").view(np.uint8).reshape(entries, 4)
    return b"\xdf" + entries.to_bytes(4, "big") + body.tobytes()


def allocated_peak(function, *args) -> int:
    tracemalloc.start()
    try:
        function(*args)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return peak


def rejected(payload: bytes) -> str:
    try:
        decode_frame(payload)
    except MessageError as exc:
        return exc.reason
    return "accepted"


@pytest.mark.parametrize("shape", ["wide map", "nested arrays", "nested maps"])
def test_huge_or_deep_containers_are_refused_without_building_them(shape):
    """Issue 13 (2): an 8-million-entry map under the payload cap took 0.45-0.9 GB."""
    if shape == "wide map":
        junk = huge_map(8_000_000)
    elif shape == "nested arrays":  # 4096 x 4096 small ints: every container within its limit
        inner = msgpack.packb([1] * 4096)
        junk = msgpack.packb({"v": 1, "seq": 0})[:-2] + b"\xa4junk" + b"\xdd" + (4096).to_bytes(
            4, "big") + inner * 4096
        junk = b"\x81" + junk[1:]
    else:
        junk = msgpack.packb({f"k{i}": {f"j{j}": j for j in range(200)} for i in range(200)})
    assert len(junk) <= MAX_PAYLOAD
    peak = allocated_peak(rejected, junk)
    assert rejected(junk) == "undecodable"
    assert peak < 300 * MB / 10, peak  # far below the 300 MB


def test_a_frame_with_every_field_and_some_unknown_ones_still_decodes():
    extra = {f"x{i}": list(range(20)) for i in range(100)}
    frame = decode_frame(frame_map(width=2, height=1, format="gray8", data=b"ab", **extra))
    assert frame.width == 2
    big = {f"x{i}": list(range(200)) for i in range(100)}  # 20,000 entries: over MAX_ITEMS
    assert 100 * 200 > MAX_ITEMS
    assert rejected(frame_map(width=2, height=1, format="gray8", data=b"ab", **big)) == \
        "undecodable"



@pytest.mark.parametrize("nested", [False, True])
def test_a_map_that_gives_a_key_twice_is_refused_not_read_as_its_last_value(nested):
    # the worker read the last "seq"; a dashboard or proxy reading the first would disagree
    def twice(key, first, second, **rest) -> bytes:
        fields = b"".join(msgpack.packb(k) + msgpack.packb(v) for k, v in rest.items())
        return (bytes([0x80 | (len(rest) + 2)]) + fields + msgpack.packb(key)
                + msgpack.packb(first) + msgpack.packb(key) + msgpack.packb(second))

    fields = {"v": 1, "seq": 0, "stamp": 0.0, "width": 2, "height": 1, "format": "gray8",
              "data": b"ab"}
    if nested:  # inside a field's value, where the frame's own model never looks
        junk = msgpack.packb({**fields, "extra": 0})[:-1] + twice("a", 1, 2)
    else:
        junk = twice("seq", 0, 7, **{k: v for k, v in fields.items() if k != "seq"})
    with pytest.raises(MessageError) as err:
        decode_frame(junk)
    assert err.value.reason == "undecodable" and "twice" in str(err.value)
    assert decode_frame(msgpack.packb(fields)).seq == 0  # the same fields once each decode

def test_maps_decode_where_msgpack_gives_their_pairs_as_a_generator(monkeypatch):
    """A packaging trial: msgpack 1.0.0 (pyproject.toml accepts it) unpacks in pure Python,
    handing object_pairs_hook a generator; the duplicate-key check took its len() and the
    worker refused every frame as 'not msgpack'."""
    import service.messages as messages

    unpackb = msgpack.unpackb

    def generating(payload, **options):
        hook = options.get("object_pairs_hook")
        if hook is not None:
            options["object_pairs_hook"] = lambda pairs: hook(iter(pairs))
        return unpackb(payload, **options)

    monkeypatch.setattr(messages.msgpack, "unpackb", generating)
    fields = {"v": 1, "seq": 4, "stamp": 0.0, "width": 2, "height": 1, "format": "gray8",
              "data": b"ab"}
    assert decode_frame(msgpack.packb(fields)).seq == 4
    # the seven fields and seq again: eight pairs
    junk = bytes([0x88]) + msgpack.packb(fields)[1:] + msgpack.packb("seq") + msgpack.packb(5)
    with pytest.raises(MessageError, match="twice"):
        decode_frame(junk)


def test_a_status_map_of_nested_repeated_pairs_is_read_without_keeping_them():
    """A status map is read with the status bounds (8,192 pairs a map, 262,144 entries): the
    duplicate-key check keeps every pair of the maps still being read, 64 bytes each, so 30
    nested maps of 8,192 repeated pairs (0.5 MiB, within the bounds) would hold 15 MiB. Read as
    a dict, each such map is one entry."""
    from service.messages import STATUS_MAX_ITEMS, STATUS_MAX_MAP_LEN, decode_status

    status = b"\x81\xa1x" + (b"\xde" + STATUS_MAX_MAP_LEN.to_bytes(2, "big")
                             + b"\x00\x00" * (STATUS_MAX_MAP_LEN - 1)) * 30 + b"\x00"
    assert len(status) < 0.6e6 and 30 * (STATUS_MAX_MAP_LEN + 1) < STATUS_MAX_ITEMS
    assert allocated_peak(lambda: pytest.raises(MessageError, decode_status, status)) < 4e6


@pytest.mark.parametrize("opened", [b"\xdc", b"\xde"], ids=["arrays", "maps"])
def test_containers_that_never_complete_are_refused_at_their_headers(opened):
    """1,023 nested headers of 4,096-item arrays, each within its own limit, and nothing after
    them (3 KB): msgpack allocates each array's slots at its header, so the frame took 32 MiB
    and 27 ms before it was found to end there. The entries are counted at the headers now."""
    from service.messages import MAX_ARRAY_LEN, MAX_MAP_LEN

    n = MAX_ARRAY_LEN if opened == b"\xdc" else MAX_MAP_LEN
    junk = b"\x81\xa1x" + (opened + n.to_bytes(2, "big")) * 1023
    assert len(junk) < 4 * 1024
    assert rejected(junk) == "undecodable"
    assert allocated_peak(rejected, junk) < MB / 4


def test_the_entries_are_counted_as_msgpack_builds_them():
    """The header count is exact: a message of MAX_ITEMS container entries (each container's
    entries plus one) is read, one more is refused, and random nestings of every msgpack type
    read as msgpack reads them."""
    from service.messages import unpack_map

    def fields(entries: int) -> bytes:
        # {"x": [160 rows of zeros]}: the map 1 + 1, the list 160 + 1, each row its k + 1
        rows = 160
        last = entries - 3 - 2 * rows - 100 * (rows - 1)
        return msgpack.packb({"x": [[0] * 100] * (rows - 1) + [[0] * last]})

    assert unpack_map(fields(MAX_ITEMS))["x"]
    with pytest.raises(MessageError, match="entries in all"):
        unpack_map(fields(MAX_ITEMS + 1))
    rng = np.random.default_rng(5)
    scalars = [None, True, False, 0, 127, -32, 255, -129, 70000, -70000, 2**40, -2**40, 2**63,
               0.5, "", "s" * 31, "t" * 300, "u" * 1000, b"", b"b" * 300,
               *(msgpack.ExtType(3, b"e" * n) for n in (1, 2, 4, 8, 16, 40))]

    def value(depth: int):
        if depth > 3 or rng.random() < 0.4:
            return scalars[rng.integers(len(scalars))]
        n = int(rng.choice([0, 3, 15, 16, 80]))
        if rng.random() < 0.5:
            return [value(depth + 1) for _ in range(n)]
        return {f"k{i}": value(depth + 1) for i in range(n)}

    def entries(v) -> int:
        inner = v.values() if isinstance(v, dict) else v if isinstance(v, list) else None
        return 0 if inner is None else len(v) + 1 + sum(map(entries, inner))

    read = refused = 0
    for i in range(120):
        message = {"a": value(1), "b": value(1), "c": b"b" * 70000}  # bin 32
        payload = msgpack.packb(message, use_bin_type=True, use_single_float=i % 2 == 1)
        if entries(message) <= MAX_ITEMS:
            assert unpack_map(payload) == msgpack.unpackb(payload, raw=False)
            read += 1
        else:
            with pytest.raises(MessageError, match="entries in all"):
                unpack_map(payload)
            refused += 1
    assert read > 80 and refused > 5  # both sides of the bound were tried


# ---------------------------------------------------------------- 3. robot-slot lockout

def test_ids_sending_only_undecodable_frames_cannot_lock_new_robots_out():
    """Issue 13 (3): 60 such ids used to take every --max-robots slot."""
    scene = make_scene("looming")
    core = WorkerCore(max_robots=60, idle_timeout=600)
    rng = np.random.default_rng(3)
    attackers = [f"evil{i}" for i in range(60)]
    answered, warned = [], []
    for seq, image in enumerate([None] * 5 + list(scene.frames)):  # the attackers come first
        arrivals = [(a, undecodable_jpeg(scene.frames[0], seq)) for a in attackers]
        if image is not None:
            arrivals.append(("newbie", payload(image, seq)))
        for i in rng.permutation(len(arrivals)):
            robot, data = arrivals[i]
            core.offer(f"asnn/{robot}/frame", data)
            if i % 2:  # the processing threads run meanwhile, at half the arrival rate
                job = core.take()
                if job is not None:
                    response = core.process(job)
                    if response is not None:
                        answered.append(response.seq)
                        warned += [response.seq] if response.collision else []
        while (job := core.take()) is not None:
            response = core.process(job)
            if response is not None:
                answered.append(response.seq)
                warned += [response.seq] if response.collision else []
    assert len(answered) >= 0.9 * len(scene.frames)
    assert warned
    stats = core.stats()
    assert core.robots() == ["newbie"] and stats["robots"] == 1
    assert stats["invalid"]["bad-image"] > 0


def test_a_candidate_takes_its_slot_when_its_frame_decodes():
    scene = make_scene("looming")
    core = WorkerCore(max_robots=2)
    for robot in ("a", "b"):
        assert core.offer(f"asnn/{robot}/frame", payload(scene.frames[0], 0)) == robot
    assert core.stats()["candidates"] == 2 and core.stats()["robots"] == 0
    assert core.offer("asnn/c/frame", payload(scene.frames[0], 0)) is None  # none may wait
    assert core.process(core.take()) is not None and core.process(core.take()) is not None
    assert core.stats()["candidates"] == 0 and core.stats()["robots"] == 2
    assert core.offer("asnn/c/frame", payload(scene.frames[0], 0)) is None  # no slot left
    assert core.stats()["invalid"] == {"too-many-robots": 2}
    assert core.stats()["received"] == 2


def test_frames_refused_for_too_many_robots_are_not_counted_as_received():
    scene = make_scene("looming")
    core = WorkerCore(max_robots=1)
    feed(core, "a", scene.frames[0], 0)
    assert core.offer("asnn/b/frame", payload(scene.frames[0], 0)) is None
    assert core.stats()["received"] == 1
    assert core.stats()["invalid"] == {"too-many-robots": 1}


def test_frames_taken_in_and_refused_when_processed_are_not_counted_as_received():
    scene = make_scene("looming")
    core = WorkerCore(max_robots=2)
    feed(core, "a", scene.frames[0], 0)
    # two new robots at once may both wait for the one place left; the second is refused when
    # it is processed
    for robot in ("b", "c"):
        assert core.offer(f"asnn/{robot}/frame", payload(scene.frames[0], 0)) == robot
    assert core.process(core.take()) is not None and core.process(core.take()) is None
    # a jpeg whose header is sound but that does not decode is refused when processed too
    assert core.offer("asnn/a/frame", undecodable_jpeg(scene.frames[1], 1)) == "a"
    assert core.process(core.take()) is None
    stats = core.stats()
    assert stats["invalid"] == {"too-many-robots": 1, "bad-image": 1}
    assert stats["received"] == stats["processed"] == 2


# ---------------------------------------------------------------- 4. scheduling

def gaps_between_responses(core, robots, ticks, arrivals_per_job):
    """Every robot offers one frame per tick, in a fixed order; a job is processed after every
    ``arrivals_per_job`` arrivals. The largest seq gap between two responses of each robot."""
    image = make_scene("looming", size=(48, 48)).frames[10]
    last = {}
    worst = dict.fromkeys(robots, 0)
    arrivals = 0
    for seq in range(ticks):
        for robot in robots:
            core.offer(f"asnn/{robot}/frame", payload(image, seq))
            arrivals += 1
            if arrivals % arrivals_per_job == 0 and (job := core.take()) is not None:
                response = core.process(job)
                if robot in last or response.robot in last:
                    worst[response.robot] = max(worst[response.robot],
                                                response.seq - last.get(response.robot, 0))
                last[response.robot] = response.seq
    return worst, last


def test_robots_are_served_in_turn_from_the_start_of_their_wait():
    """Issue 13 (4): the queue order came from a robot's newest frame, so robots whose frames
    arrive early in each period starved the others (gaps of 10 to 31 frames, seq-gap resets)."""
    robots = [f"cam{i:02d}" for i in range(30)]
    core = WorkerCore(max_gap=20)
    worst, last = gaps_between_responses(core, robots, ticks=60, arrivals_per_job=4)
    # 30 robots, 7.5 jobs per tick: in turn, each robot is served every 4 frames
    assert set(last) == set(robots)
    assert max(worst.values()) <= 6, worst
    assert core.stats()["resets"] == {}


def test_frames_the_worker_skips_itself_never_make_a_seq_gap_reset():
    scene = make_scene("looming", size=(48, 48))
    core = WorkerCore(max_gap=3)
    feed(core, "r1", scene.frames[0], 0)
    for seq in range(1, 30):  # the worker is busy: 29 frames arrive, one by one in sequence
        core.offer("asnn/r1/frame", payload(scene.frames[seq % 20], seq))
    response = core.process(core.take())
    assert response.seq == 29 and response.dropped == 28
    assert core.stats()["resets"] == {}
    # frames lost on the way (a gap in what arrives) still reset the state
    assert feed(core, "r1", scene.frames[0], 40).u == 0.0
    assert core.stats()["resets"] == {"seq-gap": 1}


# ---------------------------------------------------------------- 5. a second publisher

def victim_and_intruder(core, clock, scene, intruder_from, blank):
    warned = []
    for seq, image in enumerate(scene.frames):
        clock.now += 0.05
        response = feed(core, "r1", image, 500 + seq, stamp=1000 + seq * 0.05)
        warned += [response.seq] if response.collision else []
        if seq >= intruder_from:  # blank frames with seq 0, between the robot's own
            core.offer("asnn/r1/frame", payload(blank, 0, stamp=1.0))
            job = core.take()
            if job is not None:
                core.process(job)
    return warned


def test_a_second_publisher_cannot_reset_the_robot_over_and_over(caplog):
    """Issue 13 (5): blank frames with seq 0 on a victim's key reset it 106 times and took its
    warnings from 47 to 0."""
    scene = make_scene("looming")
    blank = np.zeros_like(scene.frames[0])
    clock = FakeClock()
    alone = victim_and_intruder(WorkerCore(clock=clock), clock, scene, len(scene.frames), blank)
    core = WorkerCore(clock=clock)
    with caplog.at_level("WARNING", logger="asnn.worker"):
        attacked = victim_and_intruder(core, clock, scene, 5, blank)
    stats = core.stats()
    assert stats["intrusions"] == 1
    assert sum(stats["resets"].values()) <= 2
    assert stats["invalid"]["second-publisher"] >= len(scene.frames) - 5 - 2
    assert attacked and len(attacked) >= len(alone) - 2
    assert core.status()["robots"]["r1"]["contested"] is True
    assert any("two publishers" in r.getMessage() for r in caplog.records)


def with_second_camera(first_seq, second):
    """The robot's camera (a looming scene at 20 fps, seq from ``first_seq``) seen by a worker
    alone and by one that also gets a second camera's frames on the key from the robot's frame
    5 on, ``second(scene, seq)`` giving each one's (image, seq, stamp): the second worker, the
    warnings of each and the scene's length."""
    scene = make_scene("looming")
    clock = FakeClock()
    alone, core = WorkerCore(clock=clock), WorkerCore(clock=clock)
    warned = {"alone": 0, "attacked": 0}
    for seq, image in enumerate(scene.frames):
        clock.now += 0.05
        for name, target in (("alone", alone), ("attacked", core)):
            warned[name] += bool(feed(target, "r1", image, first_seq + seq,
                                      stamp=seq * 0.05).collision)
        if seq >= 5:
            clock.now += 0.001
            core.offer("asnn/r1/frame", payload(*second(scene, seq)))
            job = core.take(timeout=0)
            if job is not None:
                core.process(job)
    return core, warned, len(scene.frames)


def test_an_intruder_with_a_seq_of_its_own_cannot_take_the_robot_over():
    """A second camera misconfigured with the robot's id, counting its own seq up: its frames
    continue its own stream, which must not win the robot back after the intrusion."""
    core, warned, frames = with_second_camera(1000, lambda scene, seq: (
        np.zeros_like(scene.frames[0]), seq - 5, (seq - 5) * 0.05))
    stats = core.stats()
    assert stats["intrusions"] == 1 and sum(stats["resets"].values()) <= 2
    assert stats["invalid"]["second-publisher"] >= frames - 5 - 2
    assert warned["attacked"] >= warned["alone"] - 2 > 0


@pytest.mark.parametrize("ahead", [-10, 5, 15])
def test_a_second_camera_a_few_frames_behind_or_ahead_on_the_robots_key_is_an_intrusion(ahead):
    """Two cameras given one robot id, started half a second apart: the later one's seq 10
    behind, its stamps between the first's. Each of its frames went back in seq (a new stream)
    and the first camera's next frame continued that new stream (ahead by 11, later), so the
    intrusion was never seen and the robot's model was reset every frame: no warning, a
    dashboard tile that looked live (a dashboard operator's trial). A second camera ahead
    continued the robot's stream itself, and then took the robot over (a review)."""
    # the second camera: its own view, its seq ``ahead`` of the robot's, stamped 25 ms later
    core, warned, frames = with_second_camera(20, lambda scene, seq: (
        scene.frames[seq - 5], 20 + seq + ahead, seq * 0.05 + 0.025))
    stats = core.stats()
    assert stats["intrusions"] == 1 and sum(stats["resets"].values()) <= 2, stats
    assert stats["invalid"]["second-publisher"] >= frames - 5 - 2
    assert core.status()["robots"]["r1"]["contested"] is True
    assert warned["attacked"] >= warned["alone"] - 2 > 0


@pytest.mark.parametrize("clock_s", [0.05, 0.0])
def test_one_cameras_first_frames_swapped_on_the_way_are_no_intrusion(clock_s):
    """A review: seq 1 arriving before seq 0 (frames travel best effort, reordered) made seq 2
    fit both streams, and the robot was taken for contested (a second publisher); a camera
    whose coarse clock stamps them alike neither (a mutation probe: '>=' for the stamps'
    '>' took it for one)."""
    scene = make_scene("looming")
    clock = FakeClock()
    core = WorkerCore(clock=clock)
    for seq in [1, 0, *range(2, 20)]:
        clock.now += 0.05
        core.offer("asnn/r1/frame", payload(scene.frames[seq], seq, stamp=seq * clock_s))
        job = core.take(timeout=0)
        if job is not None:
            core.process(job)
    assert core.stats()["intrusions"] == 0
    assert core.status()["robots"]["r1"]["contested"] is False


def test_after_an_intrusion_a_restarted_camera_is_followed_once_the_old_stream_is_silent():
    scene = make_scene("looming")
    clock = FakeClock()
    core = WorkerCore(clock=clock, takeover_after=3.0)
    for seq in range(10):
        clock.now += 0.05
        feed(core, "r1", scene.frames[seq], 100 + seq)
        if seq in (4, 5):  # an intruder's frame, then the robot's again: detected
            core.offer("asnn/r1/frame", payload(scene.frames[0], 0))
    assert core.stats()["intrusions"] == 1
    clock.now += 0.5  # the camera restarts quickly: its old stream is not silent long enough
    assert core.offer("asnn/r1/frame", payload(scene.frames[0], 0)) is None
    clock.now += 3.0
    response = feed(core, "r1", scene.frames[0], 0)
    assert response is not None and response.u == 0.0
    assert feed(core, "r1", scene.frames[1], 1) is not None


def test_a_camera_left_alone_after_an_intrusion_is_followed_once_the_first_is_silent(caplog):
    """A camera replaced while the old one still sent a frame or two: the new one publishes on,
    the old one is gone. Its frames were refused as a second publisher's for as long as they
    came (each refreshed its stream), until the robot was forgotten as idle (60 s blind); now
    until the stream there first has been silent for CONTESTED_FOR_S (not takeover_after: a
    camera that pauses for a few seconds must not hand its robot to an intruder)."""
    from service.streams import CONTESTED_FOR_S

    scene = make_scene("looming")
    clock = FakeClock()
    core = WorkerCore(clock=clock, takeover_after=3.0, idle_timeout=120.0)
    for seq in range(10):  # the old camera; the new one's first frames among its last ones
        clock.now += 0.05
        feed(core, "r1", scene.frames[seq], 100_000 + seq)
        if seq >= 8:
            core.offer("asnn/r1/frame", payload(scene.frames[seq - 8], seq - 8))
    assert core.stats()["intrusions"] == 1
    answered = []
    last = 2 + int((CONTESTED_FOR_S + 5) * 20)
    with caplog.at_level("WARNING", logger="asnn.worker"):
        for seq in range(2, last):  # the new camera alone, at 20 fps
            clock.now += 0.05
            core.offer("asnn/r1/frame", payload(scene.frames[seq % 20], seq))
            job = core.take()
            if job is not None and core.process(job) is not None:
                answered.append(seq)
    # refused while the old stream might only be pausing, followed from then on
    assert answered, "the new camera was never followed"
    assert answered == list(range(answered[0], last))
    assert CONTESTED_FOR_S <= (answered[0] - 2) * 0.05 <= CONTESTED_FOR_S + 0.2
    assert sum("following the other publisher's" in r.getMessage()
               for r in caplog.records) == 1  # the stream is the robot's from then on
    clock.now += 0.05  # the old camera back: the other publisher now, refused
    assert core.offer("asnn/r1/frame", payload(scene.frames[0], 100_010)) is None
    clock.now += 0.05
    assert feed(core, "r1", scene.frames[1], last) is not None


def test_an_intruder_does_not_take_the_robot_while_its_camera_pauses_or_restarts():
    """A review of the fix above: with the takeover after takeover_after, an intruder that kept
    publishing took the robot whenever its camera paused for 3 s, and kept it."""
    scene = make_scene("looming")
    clock = FakeClock()
    core = WorkerCore(clock=clock, takeover_after=3.0)
    for seq in range(10):  # the camera, with an intruder's frames among its last ones
        clock.now += 0.05
        feed(core, "r1", scene.frames[seq], 100_000 + seq)
        if seq >= 8:
            core.offer("asnn/r1/frame", payload(scene.frames[seq - 8], 50_000 + seq - 8))
    followed = {"camera": 0, "intruder": 0}
    for k in range(200):  # the camera silent 3.5 s then back from seq 0; the intruder on
        clock.now += 0.05
        sources = [("intruder", 50_002 + k)] + ([("camera", k - 70)] if k >= 70 else [])
        for who, seq in sources:
            core.offer("asnn/r1/frame", payload(scene.frames[seq % 20], seq))
            job = core.take()
            if job is not None and core.process(job) is not None:
                followed[who] += 1
    assert followed["intruder"] == 0 and followed["camera"] > 100


def test_a_robot_is_contested_no_longer_once_no_frame_is_refused_for_a_while():
    """A soak: contested for good, every later quick restart of the robot's own camera lost
    takeover_after seconds of frames, refused as a second publisher's."""
    from service.streams import CONTESTED_FOR_S

    scene = make_scene("looming")
    clock = FakeClock()
    core = WorkerCore(clock=clock, takeover_after=3.0)
    seq = 100
    for k in range(10):
        clock.now += 0.05
        feed(core, "r1", scene.frames[k], seq + k)
        if k in (4, 5):  # an intruder's frame, then the robot's again: detected
            core.offer("asnn/r1/frame", payload(scene.frames[0], 0))
    assert core.status()["robots"]["r1"]["contested"]
    seq += 9

    def run(frames):  # the robot's own stream, 20 fps
        nonlocal seq
        for k in range(frames):
            clock.now += 0.05
            seq += 1
            assert feed(core, "r1", scene.frames[k % 20], seq) is not None

    run(int(CONTESTED_FOR_S / 0.05) - 20)  # refused nothing since: still contested
    clock.now += 0.05
    assert core.offer("asnn/r1/frame", payload(scene.frames[0], 0)) is None  # a restart: refused
    assert core.status()["robots"]["r1"]["contested"]
    run(int(CONTESTED_FOR_S / 0.05) + 20)  # now nothing refused for longer than that
    assert not core.status()["robots"]["r1"]["contested"]
    clock.now += 0.05
    response = feed(core, "r1", scene.frames[0], 0)  # the camera restarts: followed at once
    assert response is not None and response.u == 0.0
    assert not core.status()["robots"]["r1"]["contested"]
    assert core.stats()["intrusions"] == 1


def test_an_intruder_that_keeps_publishing_keeps_the_robot_contested():
    from service.streams import CONTESTED_FOR_S

    scene = make_scene("looming", size=(64, 64))
    blank = np.zeros_like(scene.frames[0])
    clock = FakeClock()
    core = WorkerCore(clock=clock)
    for k in range(int(1.5 * CONTESTED_FOR_S / 0.05)):  # blank frames with seq 0 between
        clock.now += 0.05
        feed(core, "r1", scene.frames[k % 40], 100 + k)
        if k >= 5:
            core.offer("asnn/r1/frame", payload(blank, 0))
    assert core.stats()["intrusions"] == 1 and sum(core.stats()["resets"].values()) <= 2
    assert core.status()["robots"]["r1"]["contested"]


def test_a_camera_restart_without_an_intruder_is_followed_at_once():
    scene = make_scene("looming")
    core = WorkerCore()
    for seq in range(5):
        feed(core, "r1", scene.frames[seq], 100 + seq)
    assert feed(core, "r1", scene.frames[0], 0).u == 0.0
    for seq in range(1, 5):
        assert feed(core, "r1", scene.frames[seq], seq) is not None
    assert core.stats()["resets"] == {"seq-backwards": 1}
    assert core.stats()["intrusions"] == 0


class SlowCore(WorkerCore):
    """A worker core that takes STEP_S per frame, whatever the model costs."""

    STEP_S = 0.02

    def process(self, job, publish=None):
        time.sleep(self.STEP_S)
        return super().process(job, publish)


def test_overloaded_worker_over_zenoh_serves_every_camera_in_turn(zenoh_net):
    """Issue 13 (4) over the network, at a modest load: a worker slowed to 50 frames/s gets 10
    cameras at 20 fps, four times its capacity; in turn, each is answered every 4 frames."""
    robots = [f"cam{i}" for i in range(10)]
    core = SlowCore(idle_timeout=600, max_gap=20)
    with Worker(zenoh_net.hub, core, stats_every=0) as worker:
        responses = Responses(zenoh_net.spoke())
        with FramePump(zenoh_net.spoke(), robots, fps=20.0) as pump:
            wait_for(lambda: all(p.matching_status.matching for p in pump.publishers.values()),
                     what="the worker's subscription")
            wait_for(lambda: all(len(responses.since(0, r)) >= 12 for r in robots),
                     timeout=20, what="a dozen responses per camera")
        wait_for(worker.idle, what="the worker to catch up")
    offered = sum(pump.sent.values())
    stats = core.stats()
    assert stats["processed"] < 0.5 * stats["received"]  # the overload was real
    for robot in robots:
        seqs = [r.seq for r in responses.since(0, robot)]
        gaps = np.diff(seqs)
        # in turn: 4; scheduling jitter of a shared machine allowed for; 10 to 31 before
        print(robot, "largest gap", gaps.max())
        assert gaps.max() <= 8, (robot, seqs)
    assert stats["resets"] == {}, (stats, offered)


def test_status_shows_candidates_and_second_publishers():
    from cli.net import format_status

    scene = make_scene("looming")
    clock = FakeClock()
    core = WorkerCore(worker_id="w1", clock=clock)
    for seq in range(6):
        clock.now += 0.05
        feed(core, "r1", scene.frames[seq], 100 + seq)
        if seq in (3, 4):
            core.offer("asnn/r1/frame", payload(scene.frames[0], 0))
    core.offer("asnn/new/frame", payload(scene.frames[0], 0))
    line = format_status(msgpack.unpackb(msgpack.packb(core.status())))
    assert "robots r1 (+1 waiting for a valid frame)" in line
    assert "second publishers: 1, contested: r1 (1 intrusions)" in line
    assert "second-publisher 1" in line
    assert "refused lately: r1 (1 refused, the latest second-publisher: frame 0 does not continue" in line
    # a detail cut to fit ends in an ellipsis (its own brackets then do not look closed)
    status = core.status()
    status["refused"]["r1"]["detail"] = ("frame 369 does not continue the stream of r3 (last "
                                         "seq 18953)")
    assert "second-publisher: frame 369 does not continue the stream of r3 (last seq 1895…); " in \
        format_status(status)


def test_status_says_why_a_camera_none_of_whose_frames_is_taken_gets_no_response():
    from cli.net import format_status

    clock = FakeClock()
    core = WorkerCore(worker_id="w1", clock=clock)
    for seq in range(3):  # raw data one byte short: never a robot, never answered
        core.offer("asnn/cam7/frame", msgpack.packb({"v": 1, "seq": seq, "stamp": 0.0, "width": 64,
                                                     "height": 64, "format": "gray8",
                                                     "data": b"\x00" * 4095}))
    status = msgpack.unpackb(msgpack.packb(core.status()))
    assert "cam7" not in status["robots"]
    assert status["refused"]["cam7"]["reason"] == "bad-pixels"
    assert status["refused"]["cam7"]["count"] == 3
    assert "refused lately: cam7 (3 refused, the latest bad-pixels" in format_status(status)
    for seq in range(2):  # the count is the robot's, whatever the reason (it read "undecodable x5")
        core.offer("asnn/cam7/frame", b"\xc1")
    line = format_status(msgpack.unpackb(msgpack.packb(core.status())))
    assert "cam7 (5 refused, the latest undecodable" in line
    assert "invalid: bad-pixels 3, undecodable 2" in line
    status = msgpack.unpackb(msgpack.packb(core.status()))
    # refused for want of a place, then given one: no longer listed as refused (a trial)
    status["refused"]["r1"] = {"reason": "too-many-robots", "detail": "already tracking 2",
                               "count": 5, "seconds_ago": 1.0}
    assert "r1 (5 refused, the latest too-many-robots" in format_status(status)
    status["robots"]["r1"] = {"candidate": False}
    assert "r1 (5 refused" not in format_status(status)
    clock.now += 120  # a minute later the line no longer lists it; the status still does
    status = msgpack.unpackb(msgpack.packb(core.status()))
    assert "refused lately" not in format_status(status)
    assert status["refused"]["cam7"]["seconds_ago"] == 120.0
    for k in range(400):  # ids come and go: the status keeps the latest 256
        core.offer(f"asnn/x{k}/frame", b"\xc1")
    assert len(core.status()["refused"]) == 256 and "x399" in core.status()["refused"]


# ---------------------------------------------------------------- 7. alerts

@pytest.mark.parametrize("stamp, shown", [(1.7e18, "t=1.7e+18"), (1.7e15, "t=1.7e+15"),
                                          (-5.0, "t=-5.000"), (1e308, "t=1e+308"),
                                          (12.25, "t=12.250"), (0.0, "t=0.000")])
def test_every_warning_is_printed_whatever_its_stamp(stamp, shown):
    """Issue 13 (7): a stamp in nanoseconds made time.localtime raise for every warning."""
    import io

    from clients.alerts import LinePrinter
    from service.messages import Response

    out = io.StringIO()
    show = LinePrinter(False, out)
    show(Response(robot="r1", seq=7, stamp=stamp, model="asnn", preset="p", u=1.0, out=0.9,
                  spikes=3, spike_rate=60.0, collision=True, targets=[], worker="w",
                  latency_ms=1.0, dropped=0))
    assert show.close()
    line = out.getvalue()
    assert line.count("\n") == 1 and "WARNING robot r1 seq 7" in line
    assert line.split()[0] == shown


def test_a_plausible_epoch_stamp_is_a_time_of_day():
    from clients.alerts import format_stamp

    assert format_stamp(1_700_000_000.25).count(":") == 2
    assert format_stamp(1_700_000_000.25).endswith(".250")


# ---------------------------------------------------------------- 9. router endpoints

def test_router_prints_the_endpoints_of_its_config_file(procs, tmp_path):
    """Issue 13 (9): it printed tcp/[::]:7447 whatever the file said."""
    from service.demo import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config = tmp_path / "router.json5"
    config.write_text(f'{{ listen: {{ endpoints: ["{endpoint}"] }}, scouting: {{ multicast: '
                      '{ enabled: false }, gossip: { enabled: false } } }')
    router = procs("router", "--config", str(config))
    router.wait_line("listening on")
    line = next(line for line in router.err if "listening on" in line)
    assert line.endswith(f"listening on {endpoint}"), line
    assert router.stop(signal.SIGTERM) == 0 and router.err[-1] == "router stopped"


def test_a_worker_id_too_long_for_a_response_is_refused_at_start():
    """The viewers keep at most MAX_NOTE_LEN characters of a response's worker id: this
    project's workers start only with ids they show whole."""
    from service.messages import MAX_NOTE_LEN

    with pytest.raises(ValueError, match="at most"):
        WorkerCore(worker_id="w" * (MAX_NOTE_LEN + 1))
    assert WorkerCore(worker_id="w" * MAX_NOTE_LEN).worker_id == "w" * MAX_NOTE_LEN


def test_a_forged_sequence_number_cannot_silence_a_robots_warnings(zenoh_net):
    """A hostile review: on an open router, one warning sent with the worker's source id and a
    sequence number far ahead of its own (zenoh.SourceInfo) made the viewers' advanced
    subscribers drop every later warning of that robot: `asnn alerts` and the dashboard went
    silent while its responses went on."""
    import zenoh

    from clients.alerts import WarningListener
    from clients.dashboard import FleetStore, FleetSubscriber
    from service.messages import Response, encode
    from service.worker import _Outlets

    def warning(seq):
        return Response(robot="r1", seq=seq, stamp=1000.0 + seq, model="asnn", preset="p",
                        u=1.0, out=0.9, spikes=3, spike_rate=60.0, collision=True, targets=[],
                        worker="w1", latency_ms=1.0, dropped=0)

    # peers do not route for each other: the worker's and the attacker's puts leave from the
    # hub, the viewers and the attacker's ears are on spokes
    worker = attacker = zenoh_net.hub
    viewer = zenoh_net.spoke()
    outlets = _Outlets(worker, "r1", "asnn")
    printed, sniffed, store = [], [], FleetStore()
    sniffer = zenoh_net.spoke().declare_subscriber("asnn/r1/warning", sniffed.append)
    with WarningListener(viewer, printed.append), FleetSubscriber(viewer, store):
        seq = 0
        while not (printed and sniffed and store.robots()):  # until everyone hears the worker
            outlets.warning.put(encode(warning(seq)))
            seq += 1
            time.sleep(0.05)
            assert seq < 600, "no warning arrived"
        source = sniffed[-1].source_info
        # an old warning again (another payload), sent as the worker's sample a million ahead;
        # in the worker's priority, so that it arrives before the worker's next ones
        forged = warning(0).model_copy(update={"latency_ms": 2.0})
        attacker.put("asnn/r1/warning", encode(forged), priority=zenoh.Priority.INTERACTIVE_HIGH,
                     source_info=zenoh.SourceInfo(source.source_id, source.source_sn + 2**20))
        wait_for(lambda: any(w.latency_ms == 2.0 for w in printed), what="the forged warning")
        later = list(range(seq, seq + 5))
        for n in later:
            outlets.warning.put(encode(warning(n)))
        wait_for(lambda: {w.seq for w in printed} >= set(later), timeout=15,
                 what="the worker's warnings after the forged one")
        wait_for(lambda: store.delta(0)["robots"]["r1"]["last_warning"]["seq"] == later[-1],
                 timeout=15, what="the dashboard to show them")
        # each warning once, though two subscribers take it
        real = [w.seq for w in printed if w.latency_ms == 1.0]
        assert len(real) == len(set(real))
    sniffer.undeclare()
    outlets.undeclare()


def test_status_replies_from_anyone_are_bounded_and_a_health_check_reads_only_its_own(
        zenoh_net, monkeypatch):
    """Any process on the prefix may answer a status query, as often as it likes, with maps of
    up to 16 MiB: ``asnn status`` keeps at most MAX_STATUSES of them (and MAX_STATUS_BYTES_KEPT
    bytes), and its health check (``--local``, run in the worker's container) decodes only the
    replies whose key names a worker it asks about."""
    import service.worker as worker_module
    from service.messages import encode_status

    monkeypatch.setattr(worker_module, "MAX_STATUSES", 5)
    padding = "p" * 1000

    def flood(query):
        for i in range(40):
            query.reply(f"asnn/@worker/x{i}/status",
                        encode_status({"worker": f"x{i}", "padding": padding}))

    queryable = zenoh_net.hub.declare_queryable("asnn/@worker/*/status", flood)
    try:
        decoded = []
        real = worker_module.decode_status
        monkeypatch.setattr(worker_module, "decode_status",
                            lambda payload: decoded.append(1) or real(payload))
        asker = zenoh_net.spoke()
        wait_for(lambda: worker_module.query_status(asker, timeout=0.5),
                 what="the flood's queryable to answer")
        everyone = worker_module.query_status(asker, timeout=3.0)
        assert len(everyone) == 5 and all(k.startswith("x") for k in everyone)
        decoded.clear()
        mine = worker_module.query_status(asker, timeout=3.0, keep=lambda w: w == "x7")
        assert list(mine) == ["x7"] and len(decoded) == 1
        monkeypatch.setattr(worker_module, "MAX_STATUSES", 100)
        monkeypatch.setattr(worker_module, "MAX_STATUS_BYTES_KEPT", 10_500)
        assert len(worker_module.query_status(asker, timeout=3.0)) == 10  # ~1 KB each
    finally:
        queryable.undeclare()


@pytest.mark.parametrize("as_json", [False, True])
def test_a_status_asnn_cannot_read_is_said_and_hides_no_other(zenoh_net, tmp_path, capsys,
                                                               as_json):
    """Anything on the prefix may answer a status query: a map without the fields of a
    worker's (or with a NaN, or a terminal's escape sequences) made ``asnn status`` end in a
    traceback, the real worker's line unprinted, and a health check fail."""
    from cli.main import main
    from service.messages import encode_status

    whole = WorkerCore(worker_id="x").status()  # as a worker's, but for what it says
    readable = []

    def fake(query):
        query.reply("asnn/@worker/fake/status", encode_status({"worker": "fake\x1b[2J"}))
        query.reply("asnn/@worker/nan/status",
                    encode_status({"worker": "nan", "stats": float("nan")}))
        if not readable:
            return
        query.reply("asnn/@worker/nanstats/status", encode_status(
            {**whole, "worker": "nanstats", "uptime_s": float("nan")}))
        query.reply("asnn/@worker/esc/status",
                    encode_status({**whole, "worker": "esc\x1b]0;t\x07"}))

    config = tmp_path / "zenoh.json5"
    config.write_text('{"scouting": {"multicast": {"enabled": false}, '
                      '"gossip": {"enabled": false}}}')
    ask = ["status", "--config", str(config), "--connect", zenoh_net.endpoint, "--mode",
           "client", "--timeout", "1", *(["--json"] if as_json else [])]
    queryable = zenoh_net.hub.declare_queryable("asnn/@worker/*/status", fake)
    try:
        assert main(ask) == 1  # nothing readable: nobody answered
        readable.append(True)
        with Worker(zenoh_net.hub, WorkerCore(worker_id="w1"), stats_every=0):
            capsys.readouterr()
            assert main(ask) == 0
    finally:
        queryable.undeclare()
    out, err = capsys.readouterr()
    lines = sorted(out.splitlines())
    assert "worker fake\\x1b[2J: a status this asnn cannot read (KeyError" in err
    assert "worker nan: a status this asnn cannot read" in err and "\x1b" not in out + err
    if as_json:  # the NaN map refused, every line printed is JSON
        assert len(lines) == 2 and [json.loads(line)["worker"] for line in lines] == [
            "esc\x1b]0;t\x07", "w1"]
        assert "worker nanstats: a status this asnn cannot read" in err
    else:  # shown, escaped
        assert len(lines) == 3 and lines[0].startswith("worker esc\\x1b]0;t\\x07: ")
        assert lines[2].startswith("worker w1: ")


def test_a_second_process_answering_for_a_worker_id_is_found_and_said(zenoh_net, tmp_path,
                                                                      capsys, caplog,
                                                                      monkeypatch):
    """A worker that hung past the lease and was replaced comes back (or one --id is given on
    two hosts): the check at start cannot see it, and both answered every frame, status showing
    one of them. Each now logs an ERROR, and asnn status lists both and exits 1."""
    import service.worker as worker_module
    from cli.main import main

    monkeypatch.setattr(worker_module, "TWIN_CHECK_S", 1.0)
    config = tmp_path / "zenoh.json5"
    config.write_text('{"scouting": {"multicast": {"enabled": false}, '
                      '"gossip": {"enabled": false}}}')
    ask = ["status", "--config", str(config), "--connect", zenoh_net.endpoint, "--mode",
           "client", "--timeout", "1", "--json"]
    with caplog.at_level(logging.ERROR, logger="asnn.worker"):
        with Worker(zenoh_net.hub, WorkerCore(worker_id="w1"), stats_every=0, shared=False):
            time.sleep(1.5)  # two checks: alone, nobody else is said to answer
            assert not [r for r in caplog.records if "also answered" in r.getMessage()]
            capsys.readouterr()
            assert main(ask) == 0
            with Worker(zenoh_net.spoke(), WorkerCore(worker_id="w1"), stats_every=0,
                        shared=False):
                wait_for(lambda: [r for r in caplog.records
                                  if "also answered by another process" in r.getMessage()],
                         what="the twin to be found", timeout=20)
                capsys.readouterr()
                assert main(ask) == 1
                captured = capsys.readouterr()
                lines = [json.loads(line) for line in captured.out.splitlines()]
                assert [s["worker"] for s in lines] == ["w1", "w1"]
                assert len({s["instance"] for s in lines}) == 2
                assert "w1: answered by more than one process" in captured.err


def test_status_says_when_the_workers_run_different_detectors(zenoh_net, tmp_path, capsys):
    """Two workers on one prefix with different presets hand robots between them, each then
    answered by another model (its warnings, ids, ttc): asnn status says so, without failing
    (a rolling change of preset passes through it)."""
    from cli.main import main

    config = tmp_path / "zenoh.json5"
    config.write_text('{"scouting": {"multicast": {"enabled": false}, '
                      '"gossip": {"enabled": false}}}')
    ask = ["status", "--config", str(config), "--connect", zenoh_net.endpoint, "--mode",
           "client", "--timeout", "1"]
    with Worker(zenoh_net.hub, WorkerCore(worker_id="w1"), stats_every=0):
        capsys.readouterr()
        assert main(ask) == 0
        assert "different detectors" not in capsys.readouterr().err
        with Worker(zenoh_net.spoke(), WorkerCore(worker_id="w2", preset="reference"),
                    stats_every=0):
            capsys.readouterr()
            assert main(ask) == 0
            err = capsys.readouterr().err
            assert ("workers run different detectors (asnn/reference on w2; asnn/robust on w1)"
                    in err)


def test_answers_on_a_workers_status_key_make_at_most_one_line_a_check(zenoh_net, caplog,
                                                                      monkeypatch):
    """A review: any process on the prefix could answer a worker's own status key hundreds of
    times a query, with a newline in its instance: as many forged ERROR lines."""
    import service.worker as worker_module
    from service.messages import encode_status

    monkeypatch.setattr(worker_module, "TWIN_CHECK_S", 1.0)

    def flood(query):
        for _ in range(50):
            query.reply("asnn/@worker/w1/status", encode_status(
                {"worker": "w1", "instance": "x\n2026-11-30 asnn.worker INFO all clear",
                 "uptime_s": "soon"}))
        query.reply("asnn/@worker/w1/status", encode_status({"worker": "w2", "instance": "y"}))

    queryable = zenoh_net.spoke().declare_queryable("asnn/@worker/w1/status", flood)
    try:
        with caplog.at_level(logging.ERROR, logger="asnn.worker"):
            with Worker(zenoh_net.hub, WorkerCore(worker_id="w1"), stats_every=0, shared=False):
                wait_for(lambda: [r for r in caplog.records if "also answered" in r.getMessage()],
                         what="the forged twin", timeout=20)
                time.sleep(2.5)  # two or three more checks
    finally:
        queryable.undeclare()
    lines = [r.getMessage() for r in caplog.records if "also answered" in r.getMessage()]
    assert 1 <= len(lines) <= 5 and all("\n" not in line for line in lines), lines
    assert "instance x?2026" in lines[0] and "up " not in lines[0]


def test_a_restarted_camera_that_then_loses_frames_is_no_intrusion():
    """A mutation probe: a camera restarted (seq back to 0, its clock going on) whose frame
    then jumps over its old stream's latest seq fits both streams; only a one-frame stream is
    taken for interleaving (the rule without it counted an intrusion and refused the camera)."""
    scene = make_scene("looming", size=(64, 64))
    clock = FakeClock()
    core = WorkerCore(clock=clock)
    frames = [(k, k * 0.05) for k in range(10)] + [
        (k, 0.5 + k * 0.05) for k in (0, 1, 2, *range(12, 30))]  # 3-11 lost after the restart
    for seq, stamp in frames:
        clock.now += 0.05
        core.offer("asnn/r1/frame", payload(scene.frames[seq], seq, stamp=stamp))
        job = core.take(timeout=0)
        if job is not None:
            core.process(job)
    stats = core.stats()
    assert stats["intrusions"] == 0 and not stats["invalid"], stats
    assert core.status()["robots"]["r1"]["contested"] is False


def test_a_second_camera_ahead_for_longer_than_contested_for_s_is_one_intrusion():
    """A mutation probe: a second camera a few frames ahead keeps the robot contested for as
    long as it publishes (its frames, refused, refresh it), one intrusion and one reset in
    all; refreshed by nothing, the contest lapsed after CONTESTED_FOR_S and the camera's next
    frame was a second intrusion, and a second reset."""
    from service.streams import CONTESTED_FOR_S

    scene = make_scene("looming", size=(64, 64))
    clock = FakeClock()
    core = WorkerCore(clock=clock)
    frames = int((CONTESTED_FOR_S + 10) * 20)
    for k in range(frames):
        for seq, stamp, image in [(20 + k, k * 0.05, scene.frames[k % 40])] + (
                [(25 + k, k * 0.05 + 0.025, scene.frames[(k + 20) % 40])] if k >= 5 else []):
            clock.now += 0.025
            core.offer("asnn/r1/frame", payload(image, seq, stamp=stamp))
            job = core.take(timeout=0)
            if job is not None:
                core.process(job)
    stats = core.stats()
    assert stats["intrusions"] == 1 and sum(stats["resets"].values()) == 1, stats
    assert stats["invalid"]["second-publisher"] >= frames - 5 - 2
    assert core.status()["robots"]["r1"]["contested"] is True
