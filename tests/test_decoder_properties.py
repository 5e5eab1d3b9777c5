"""Property-based tests of the frame decoder and the worker core: whatever the bytes, decoding
either gives a valid frame or raises MessageError with a known reason, and the core never raises,
never tracks a robot for an invalid frame and counts every rejection."""

import math

import msgpack
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.core import WorkerCore
from service.messages import (FORMATS, MAX_SIDE, REASONS, Frame, MessageError, decode_frame,
                              encode, encode_image, encoded_size)

SETTINGS = settings(max_examples=300, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

scalars = st.one_of(st.none(), st.booleans(), st.integers(-2 ** 63, 2 ** 64 - 1),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=20),
                    st.binary(max_size=64))
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)),
    max_leaves=12)
FIELDS = ("v", "seq", "stamp", "width", "height", "format", "data")


@st.composite
def frame_maps(draw):
    """Maps close to a frame: each field valid, missing, or replaced by an arbitrary value."""
    width = draw(st.integers(1, 24))
    height = draw(st.integers(1, 24))
    fmt = draw(st.sampled_from(FORMATS))
    channels = 3 if fmt == "bgr8" else 1
    pixels = draw(st.binary(min_size=width * height * channels,
                            max_size=width * height * channels))
    if fmt in ("jpeg", "png"):
        image = np.frombuffer(pixels, np.uint8).reshape(height, width)
        pixels = encode_image(image, fmt)
    base = {"v": 1, "seq": draw(st.integers(0, 2 ** 40)),
            "stamp": draw(st.floats(-1e9, 1e9, allow_nan=False)), "width": width,
            "height": height, "format": fmt, "data": pixels}
    for name in draw(st.lists(st.sampled_from(FIELDS), max_size=3, unique=True)):
        if draw(st.booleans()):
            del base[name]
        else:
            base[name] = draw(values)
    if draw(st.booleans()):  # truncate or corrupt the data
        data = base.get("data")
        if isinstance(data, bytes) and data:
            cut = draw(st.integers(0, len(data) - 1))
            base["data"] = data[:cut] + draw(st.binary(max_size=8))
    return base


def check(payload: bytes) -> str | None:
    """Decode fully (pixels included); None for a valid frame, else the reason."""
    try:
        frame = decode_frame(payload)
        image = frame.image()
    except MessageError as exc:
        assert exc.reason in REASONS, exc.reason
        assert str(exc)
        return exc.reason
    assert 1 <= frame.width <= MAX_SIDE and 1 <= frame.height <= MAX_SIDE
    assert math.isfinite(frame.stamp) and frame.seq >= 0 and frame.format in FORMATS
    assert image.dtype == np.uint8 and image.shape[:2] == (frame.height, frame.width)
    assert image.ndim == 2 or image.shape[2] == 3
    return None


@SETTINGS
@given(st.binary(max_size=512))
def test_arbitrary_bytes_never_escape_as_another_exception(payload):
    check(payload)


@SETTINGS
@given(values)
def test_arbitrary_msgpack_values_are_rejected_with_a_reason(value):
    reason = check(msgpack.packb(value, use_bin_type=True))
    assert reason is not None  # nothing but a complete frame is a frame


@SETTINGS
@given(frame_maps())
def test_almost_frames_are_either_valid_or_rejected_with_a_reason(frame):
    check(msgpack.packb(frame, use_bin_type=True))


@SETTINGS
@given(st.integers(1, 40), st.integers(1, 40), st.sampled_from(FORMATS), st.integers(0, 2 ** 31),
       st.floats(-1e12, 1e12, allow_nan=False))
def test_valid_frames_round_trip(width, height, fmt, seq, stamp):
    image = np.random.default_rng(seq).integers(0, 256, size=(height, width, 3), dtype=np.uint8)
    frame = Frame.from_image(image, seq=seq, stamp=stamp, format=fmt)
    back = decode_frame(encode(frame))
    assert check(encode(frame)) is None
    assert (back.seq, back.stamp, back.width, back.height) == (seq, stamp, width, height)


@SETTINGS
@given(st.sampled_from(["jpeg", "png"]), st.binary(max_size=256))
def test_encoded_size_never_raises(fmt, data):
    size = encoded_size(data, fmt)
    assert size is None or (isinstance(size[0], int) and isinstance(size[1], int))


@SETTINGS
@given(st.lists(st.tuples(st.sampled_from(["asnn/r1/frame", "asnn/r2/frame", "asnn/r 3/frame",
                                           "asnn/r1/warning", "other/r1/frame"]),
                          st.one_of(st.binary(max_size=64), frame_maps().map(msgpack.packb))),
                max_size=20))
def test_the_core_never_raises_and_counts_every_rejection(messages):
    core = WorkerCore(model="lgmd1", log_interval=1e9)

    def invalid():
        return sum(core.stats()["invalid"].values())

    def refused():  # rejections, and a frame delivered twice (counted apart, not invalid)
        return invalid() + core.stats()["duplicates"]

    for key, payload in messages:
        before = refused()
        accepted = core.offer(key, payload) is not None
        assert refused() == before + (not accepted)  # every refusal counted, once
        job = core.take()
        if job is not None:
            before = invalid()
            response = core.process(job)
            assert invalid() == before + (response is None)
    assert core.take() is None  # nothing left over: one pending slot, taken each time
    assert set(core.robots()) <= {"r1", "r2"}
