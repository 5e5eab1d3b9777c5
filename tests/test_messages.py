"""Wire formats (Frame, Response), key expressions and the Zenoh configuration."""

import json
import math
import pathlib

import msgpack
import numpy as np
import pytest

from asnn import ASNN
from asnn.stimuli import make_scene
from service import keys
from service.config import ConfigError, ZenohOptions, make_config
from service.messages import (FORMATS, MAX_PAYLOAD, REASONS, Frame, MessageError, Refusal,
                              Response, decode_frame, decode_refusal, decode_response, encode,
                              encode_image, encoded_size, response_from, track_id_base)

RNG = np.random.default_rng(4)
IMAGE = RNG.integers(0, 256, size=(40, 56, 3), dtype=np.uint8)


def frame_dict(**changes):
    base = {"v": 1, "seq": 3, "stamp": 12.5, "width": 4, "height": 2, "format": "gray8",
            "data": bytes(range(8))}
    base.update(changes)
    return {k: v for k, v in base.items() if v is not ...}


def reason(payload: bytes, decoder=decode_frame) -> str:
    with pytest.raises(MessageError) as err:
        message = decoder(payload)
        if isinstance(message, Frame):
            message.image()
    return err.value.reason


@pytest.mark.parametrize("fmt", FORMATS)
def test_frames_round_trip_in_every_format(fmt):
    frame = Frame.from_image(IMAGE, seq=7, stamp=1.25, format=fmt)
    back = decode_frame(encode(frame))
    assert (back.seq, back.stamp, back.width, back.height, back.format) == (7, 1.25, 56, 40, fmt)
    image = back.image()
    assert image.dtype == np.uint8 and image.shape[:2] == (40, 56)
    if fmt == "bgr8" or fmt == "png":
        assert np.array_equal(image, IMAGE)
    if fmt == "gray8":
        assert image.shape == (40, 56)


def test_gray_frames_keep_their_pixels():
    gray = IMAGE[:, :, 1].copy()
    assert np.array_equal(decode_frame(encode(Frame.from_image(gray, seq=0, stamp=0))).image(),
                          gray)


def test_wire_format_is_a_msgpack_map_with_the_contract_fields():
    raw = msgpack.unpackb(encode(Frame.from_image(IMAGE, seq=1, stamp=2.0)))
    assert set(raw) == {"v", "seq", "stamp", "width", "height", "format", "data"}
    assert raw["v"] == 1 and isinstance(raw["data"], bytes)


def test_unknown_fields_are_ignored():
    frame = decode_frame(msgpack.packb(frame_dict(extra="hello", nested={"a": 1})))
    assert frame.seq == 3 and frame.image().shape == (2, 4)


@pytest.mark.parametrize("payload, expected", [
    (b"\xc1\x00garbage", "undecodable"),
    (b"", "undecodable"),
    (msgpack.packb([1, 2, 3]), "not-a-map"),
    # keys written as bin (a packer's raw strings) were read as a frame without 'v'
    (msgpack.packb({k.encode(): v for k, v in frame_dict().items()}), "invalid-field"),
    (msgpack.packb({**frame_dict(), 7: "seven"}), "invalid-field"),
    (msgpack.packb({**frame_dict(), None: "nil"}), "invalid-field"),  # a review: let through
    (msgpack.packb({**frame_dict(), 0: "zero"}), "invalid-field"),  # a falsy key is one too
    (msgpack.packb(frame_dict(v=2)), "unsupported-version"),
    (msgpack.packb(frame_dict(v=True)), "unsupported-version"),
    (msgpack.packb(frame_dict(seq=...)), "missing-field"),
    (msgpack.packb(frame_dict(data=...)), "missing-field"),
    (msgpack.packb(frame_dict(format=...)), "missing-field"),
    (msgpack.packb(frame_dict(seq="3")), "invalid-field"),
    (msgpack.packb(frame_dict(seq=3.5)), "invalid-field"),
    (msgpack.packb(frame_dict(seq=True)), "invalid-field"),
    (msgpack.packb(frame_dict(seq=-1)), "invalid-field"),
    (msgpack.packb(frame_dict(stamp=math.nan)), "bad-stamp"),
    (msgpack.packb(frame_dict(stamp=math.inf)), "bad-stamp"),
    (msgpack.packb(frame_dict(stamp=-math.inf)), "bad-stamp"),
    (msgpack.packb(frame_dict(stamp="now")), "bad-stamp"),
    (msgpack.packb(frame_dict(width=0)), "bad-size"),
    (msgpack.packb(frame_dict(height=-2)), "bad-size"),
    (msgpack.packb(frame_dict(width=4097)), "bad-size"),
    (msgpack.packb(frame_dict(height=2 ** 40)), "bad-size"),
    (msgpack.packb(frame_dict(width=4.0)), "bad-size"),
    (msgpack.packb(frame_dict(format="yuv")), "bad-format"),
    (msgpack.packb(frame_dict(format=3)), "bad-format"),
    (msgpack.packb(frame_dict(data="text, not bytes")), "invalid-field"),
    (msgpack.packb(frame_dict(data=b"short")), "bad-pixels"),
    (msgpack.packb(frame_dict(data=bytes(9))), "bad-pixels"),
    (msgpack.packb(frame_dict(format="bgr8")), "bad-pixels"),  # 8 bytes for 4x2x3
    (msgpack.packb(frame_dict(format="jpeg", data=b"not a jpeg")), "bad-image"),
    (msgpack.packb(frame_dict(format="png", data=b"\x89PNG\r\n\x1a\n" + bytes(30))),
     "bad-image"),
], ids=lambda v: v if isinstance(v, str) else "")
def test_invalid_frames_are_rejected_with_a_reason(payload, expected):
    assert expected in REASONS
    assert reason(payload) == expected


def test_oversized_payloads_are_refused_before_unpacking():
    assert reason(b"\x80" + bytes(MAX_PAYLOAD)) == "oversized"


def test_the_largest_frame_is_accepted_and_one_pixel_more_is_not():
    big = frame_dict(width=4096, height=4096, format="gray8", data=bytes(4096 * 4096))
    assert decode_frame(msgpack.packb(big)).image().shape == (4096, 4096)
    assert len(msgpack.packb({**big, "format": "bgr8", "data": bytes(4096 * 4096 * 3)})) \
        <= MAX_PAYLOAD
    assert reason(msgpack.packb({**big, "width": 4097})) == "bad-size"


@pytest.mark.parametrize("fmt", ["jpeg", "png"])
def test_encoded_size_reads_the_header_without_decoding(fmt):
    data = encode_image(IMAGE, fmt)
    assert encoded_size(data, fmt) == (56, 40)
    assert encoded_size(data[:5], fmt) is None
    assert encoded_size(b"GIF89a" + data, fmt) is None
    # a header promising a huge image is refused before decoding (no allocation)
    if fmt == "png":
        bomb = data[:16] + (60000).to_bytes(4, "big") + (60000).to_bytes(4, "big") + data[24:]
        frame = frame_dict(width=56, height=40, format="png", data=bomb)
        assert reason(msgpack.packb(frame)) == "bad-pixels"


def test_an_encoded_image_of_another_size_is_rejected():
    frame = Frame.from_image(IMAGE, seq=0, stamp=0, format="png")
    lying = msgpack.packb({**msgpack.unpackb(encode(frame)), "width": 20})
    assert reason(lying) == "bad-pixels"


def test_response_from_a_model_step_round_trips_with_targets():
    scene = make_scene("looming")
    model = ASNN("default")
    result = None
    for image in scene.frames[:30]:
        result = model.step(image)
    assert result.collision and result.targets
    frame = Frame.from_image(scene.frames[29], seq=29, stamp=100.0)
    response = response_from(result, robot="r1", frame=frame, model="asnn", preset="reference",
                             worker="w", latency_ms=3.0, dropped=2, model_ms=1.25,
                             stream_frames=30)
    back = decode_response(encode(response))
    assert back == response
    assert back.seq == 29 and back.stamp == 100.0 and back.dropped == 2 and back.collision
    assert back.targets[0].pixels == result.targets[0].pixels
    assert set(back.model_dump()) == {"v", "robot", "seq", "stamp", "model", "preset", "u", "out",
                                      "spikes", "spike_rate", "collision", "targets", "worker",
                                      "latency_ms", "dropped", "model_ms", "stream_frames"}
    assert back.model_ms == 1.25 and back.stream_frames == 30
    json.dumps(back.model_dump())  # JSON-ready for `asnn alerts --json`


def test_a_model_s_non_finite_or_numpy_values_go_out_as_plain_finite_numbers():
    """The wire's models refuse inf and NaN, and numpy scalars: a degenerate fit's ttc or
    energy must not cost the frame its response (a mutation probe: nothing tested it)."""
    from types import SimpleNamespace

    result = SimpleNamespace(to_dict=lambda: {
        "u": math.inf, "out": np.float32(0.75), "spikes": np.int64(3),
        "spike_rate": np.float64(60.0), "collision": np.bool_(True),
        "targets": [{"x": 1.0, "y": 2.0, "direction": math.nan, "energy": math.nan,
                     "pixels": np.int32(40), "id": 4, "ttc": math.inf, "expansion": -math.inf,
                     "offset": 0.5, "approaching": np.bool_(True)}]})
    frame = Frame.from_image(np.zeros((32, 32), np.uint8), seq=7, stamp=1.0)
    back = decode_response(encode(response_from(result, robot="r1", frame=frame, model="asnn",
                                                preset="p", worker="w", latency_ms=1.0,
                                                dropped=0)))
    assert (back.u, back.out, back.spikes, back.spike_rate, back.collision) == (
        0.0, 0.75, 3, 60.0, True)
    target = back.targets[0]
    assert (target.direction, target.energy) == (0.0, 0.0)  # required: 0
    assert (target.ttc, target.expansion, target.offset) == (None, None, 0.5)  # optional: absent
    assert type(target.pixels) is int and target.approaching is True and target.id == 4


def test_target_ids_on_the_wire_start_at_the_models_first_seq():
    """A model's target ids go out offset by track_id_base of the seq it started at, so that the
    models of one stream (before and after a hand-over or a reset) number apart; the base stays
    below 2^53 whatever the seq, and ids without a tracker stay absent."""
    scene = make_scene("looming")
    model = ASNN("default")
    for image in scene.frames[:30]:
        result = model.step(image)
    ids = [t.id for t in result.targets]
    assert ids and all(i is not None for i in ids)
    frame = Frame.from_image(scene.frames[29], seq=1029, stamp=0.0)
    base = track_id_base(1000)
    response = response_from(result, robot="r1", frame=frame, model="asnn", preset="default",
                             worker="w", latency_ms=1.0, dropped=0, id_base=base)
    assert [t.id for t in decode_response(encode(response)).targets] == [i + base for i in ids]
    assert track_id_base(0) == 0 and track_id_base(1000) == 1000 * 2**16
    assert all(track_id_base(seq) + 2**16 <= 2**53 for seq in (2**37 - 1, 2**63, 2**64 - 1))
    untracked = ASNN("reference")
    for image in scene.frames[:30]:
        plain = untracked.step(image)
    assert plain.targets
    wire = response_from(plain, robot="r1", frame=frame, model="asnn", preset="reference",
                         worker="w", latency_ms=1.0, dropped=0, id_base=base)
    assert all(t.id is None for t in wire.targets)


def test_invalid_responses_are_rejected():
    good = msgpack.unpackb(encode(Response(
        robot="r", seq=1, stamp=1.0, model="asnn", preset="p", u=1.0, out=0.5, spikes=0,
        spike_rate=0.0, collision=True, targets=[], worker="w", latency_ms=1.0, dropped=0)))
    assert decode_response(msgpack.packb(good)).collision
    # CONTRACT.md lists v and targets in every response: one without them is invalid
    for field in ("v", "targets"):
        short = {k: v for k, v in good.items() if k != field}
        assert reason(msgpack.packb(short), decode_response) == "missing-field"
    assert decode_response(msgpack.packb(good)).model_ms is None  # optional: older workers
    assert reason(msgpack.packb({**good, "model_ms": -1.0}), decode_response) == "invalid-field"
    assert decode_response(msgpack.packb(good)).stream_frames is None
    assert reason(msgpack.packb({**good, "stream_frames": 0}), decode_response) == "invalid-field"
    assert reason(msgpack.packb({**good, "collision": "yes"}), decode_response) == "invalid-field"
    # CONTRACT.md bounds no name's length: a long worker id is valid (viewers shorten it)
    assert decode_response(msgpack.packb({**good, "worker": "w" * 1000})).worker == "w" * 1000
    # a hostile review: negative spike counts and rates were shown as they came
    assert reason(msgpack.packb({**good, "spikes": -2**63}), decode_response) == "invalid-field"
    assert reason(msgpack.packb({**good, "spike_rate": -1.0}), decode_response) == \
        "invalid-field"
    assert reason(msgpack.packb({**good, "targets": [{"x": 1}]}), decode_response) == \
        "invalid-field"  # a nested field: the reason is about the field that holds it
    assert reason(msgpack.packb({k: v for k, v in good.items() if k != "robot"}),
                  decode_response) == "missing-field"


def test_keys_follow_the_contract():
    assert keys.frame_key("r1") == "asnn/r1/frame"
    assert keys.warning_key("robot_2-b", "fleet/a") == "fleet/a/robot_2-b/warning"
    assert keys.frames() == "asnn/*/frame" and keys.warnings(robot="r1") == "asnn/r1/warning"
    assert keys.parse_key("asnn/r1/frame") == ("r1", "frame")
    assert keys.parse_key("x/y/r1/response", "x/y") == ("r1", "response")
    for bad in ("asnn/r1/frame/extra", "other/r1/frame", "asnn/r 1/frame", "asnn/r1/video",
                "asnn/" + "r" * 65 + "/frame"):
        with pytest.raises(keys.KeySchemeError):
            keys.parse_key(bad)
    for bad in ("", "a b", "a/*", "a//b", "r/1/../**"):
        with pytest.raises(keys.KeySchemeError):
            keys.check_prefix(bad)


def test_a_refusal_notice_round_trips_and_bad_ones_are_refused():
    notice = Refusal(robot="r1", worker="w1", reason="bad-size", detail="width 0", count=3)
    assert keys.refusal_key("r1") == "asnn/r1/refused"
    assert keys.parse_key("asnn/r1/refused") == ("r1", "refused")
    assert decode_refusal(encode(notice)) == notice
    good = msgpack.unpackb(encode(notice))
    for change, expected in [({"robot": "r/1"}, "invalid-field"),
                             ({"count": 0}, "invalid-field"),
                             ({"detail": "x" * 201}, "invalid-field"),
                             ({"v": 2}, "unsupported-version"),
                             ({"reason": None}, "invalid-field")]:
        with pytest.raises(MessageError) as err:
            decode_refusal(msgpack.packb({**good, **change}))
        assert err.value.reason == expected, change
    with pytest.raises(MessageError, match="missing-field"):
        decode_refusal(msgpack.packb({k: v for k, v in good.items() if k != "worker"}))
    with pytest.raises(MessageError, match="oversized"):  # a bounded notice, whatever it holds
        decode_refusal(msgpack.packb({**good, "padding": "x" * 5000}))


def test_config_options_override_the_file(tmp_path):
    path = tmp_path / "z.json5"
    path.write_text('{ mode: "client", connect: { endpoints: ["tcp/10.0.0.1:7447"] },'
                    ' scouting: { multicast: { enabled: false } } }')
    conf = make_config(ZenohOptions(config_file=path))
    assert json.loads(conf.get_json("mode")) == "client"
    assert json.loads(conf.get_json("timestamping/enabled")) is True
    conf = make_config(ZenohOptions(config_file=path, mode="peer",
                                    connect=("tcp/127.0.0.1:1234",)))
    assert json.loads(conf.get_json("mode")) == "peer"
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:1234"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False


def test_no_message_above_the_cap_is_taken_off_a_link_and_the_largest_frame_is(zenoh_net,
                                                                                  tmp_path):
    """A soak: one 300 MB frame cost the worker, the dashboard and the router twice its size
    before the payload check refused it, and they kept it (Zenoh takes up to 1 GiB)."""
    import time

    import zenoh

    from service.config import MAX_MESSAGE, MAX_MESSAGE_BYTES

    root = pathlib.Path(__file__).resolve().parents[1]
    assert MAX_PAYLOAD + 64 * 1024 < MAX_MESSAGE_BYTES <= 2 * MAX_PAYLOAD
    assert json.loads(make_config().get_json(MAX_MESSAGE)) == MAX_MESSAGE_BYTES
    own = tmp_path / "own.json5"
    own.write_text("{ transport: { link: { rx: { max_message_size: 1000000 } } } }")
    assert json.loads(make_config(ZenohOptions(config_file=own)).get_json(MAX_MESSAGE)) == 1000000
    for name in ("client.json5", "router.json5", "secure/router.json5"):  # zenohd's too
        deployed = root / "deploy" / "zenoh" / name
        assert json.loads(zenoh.Config.from_file(str(deployed)).get_json(MAX_MESSAGE)) \
            == MAX_MESSAGE_BYTES, name
    got = []
    zenoh_net.spoke().declare_subscriber("big/*", lambda s: got.append(
        (str(s.key_expr), len(s.payload))))
    publisher = zenoh_net.hub  # the spoke's link takes it off: the spoke's cap is the test
    time.sleep(0.5)
    block = zenoh.CongestionControl.BLOCK
    publisher.put("big/over", bytes(MAX_MESSAGE_BYTES + (1 << 20)), congestion_control=block)
    publisher.put("big/largest", bytes(MAX_PAYLOAD), congestion_control=block)
    publisher.put("big/after", b"x", congestion_control=block)
    deadline = time.monotonic() + 30
    while len(got) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    assert got == [("big/largest", MAX_PAYLOAD), ("big/after", 1)]


def test_zenohs_shared_memory_is_off_unless_a_config_file_chooses_it(tmp_path):
    """Zenoh 1.10.2 turns it on by default, and each closed session's 16 MiB pool then stays
    mapped in the router and the worker (docs/operations.md)."""
    import zenoh

    from service.config import SHARED_MEMORY

    root = pathlib.Path(__file__).resolve().parents[1]

    assert json.loads(make_config().get_json(SHARED_MEMORY)) is False
    plain = tmp_path / "plain.json5"
    plain.write_text('{ mode: "client", // we let asnn turn shared_memory off\n'
                     '  /* shared_memory: { enabled: true } */ }')
    assert json.loads(make_config(ZenohOptions(config_file=plain)).get_json(SHARED_MEMORY)) \
        is False
    chosen = tmp_path / "shm.json5"
    chosen.write_text('{ transport: { shared_memory: { enabled: true } } }')
    assert json.loads(make_config(ZenohOptions(config_file=chosen)).get_json(SHARED_MEMORY)) \
        is True
    for name in ("client.json5", "router.json5", "secure/router.json5"):
        deployed = root / "deploy" / "zenoh" / name
        assert json.loads(zenoh.Config.from_file(str(deployed)).get_json(SHARED_MEMORY)) \
            is False, name


@pytest.mark.parametrize("options", [ZenohOptions(mode="hub"), ZenohOptions(connect=("nope",)),
                                     ZenohOptions(config_file="/does/not/exist.json5")])
def test_bad_config_is_a_clear_error(options):
    with pytest.raises(ConfigError):
        make_config(options)


def test_a_config_file_zenoh_would_choke_on_is_refused_before_it_reads_it(tmp_path):
    """Zenoh parses a config file whole and recursively: 50,000 nested objects crashed the
    process (SIGSEGV), and /dev/zero took 4 GB before failing."""
    deep = tmp_path / "deep.json5"
    deep.write_text("{a:" * 50_000 + "1" + "}" * 50_000)
    with pytest.raises(ConfigError, match="nested more than 64 deep"):
        make_config(ZenohOptions(config_file=deep))
    with pytest.raises(ConfigError, match="not a regular file"):
        make_config(ZenohOptions(config_file="/dev/zero"))
    big = tmp_path / "big.json5"
    big.write_text("{ mode: 'peer' }" + " " * (1 << 20))
    with pytest.raises(ConfigError, match="larger than 1 MiB"):
        make_config(ZenohOptions(config_file=big))
    # brackets in strings and comments are not nesting; the deployed configs pass
    quoted = tmp_path / "quoted.json5"
    quoted.write_text("{ // " + "{" * 100 + "\n /* " + "[" * 100 + " */ id: '" + "{" * 100 + "' }")
    with pytest.raises(ConfigError, match="id"):  # Zenoh's own complaint: the id's form
        make_config(ZenohOptions(config_file=quoted))
    root = pathlib.Path(__file__).parents[1]
    for deployed in (root / "deploy" / "zenoh").glob("*.json5"):
        make_config(ZenohOptions(config_file=deployed))


def test_a_config_zenoh_refuses_is_named_without_the_rust_source_location(tmp_path):
    bad = tmp_path / "bad.json5"
    bad.write_text('{ mode: "client", bogus_key: 1 }')
    with pytest.raises(ConfigError, match="bogus_key") as caught:
        make_config(ZenohOptions(config_file=bad))
    assert ".rs:" not in str(caught.value)
    from service.config import zenoh_error  # an inner error's location too

    assert zenoh_error(Exception("bad at /a/b.rs:3. rule repeated at /c/d.rs:395.")) \
        == "bad rule repeated"
    # two refused values in one error: the first message alone, not both and what lies between
    two = ('Json5Err(Message { msg: "a \\"x\\" is bad", location: Some(Location { line: 1, '
           'column: 2 }) }) and Message { msg: "second", location: None }')
    assert zenoh_error(Exception(two)) == 'line 1, column 2: a "x" is bad'
    # a file Zenoh's parser cannot read: its drawing of the line at fault took six lines
    broken = tmp_path / "broken.json5"
    broken.write_text('{ mode: "client", connect: { endpoints: [ }\n')
    with pytest.raises(ConfigError) as caught:
        make_config(ZenohOptions(config_file=broken))
    assert "\n" not in str(caught.value)
    assert "broken.json5: line 1, column 43: expected array" in str(caught.value)


def test_an_endpoint_zenoh_refuses_is_named_without_the_rust_structure(tmp_path):
    """`--connect foo` printed Zenoh's whole Rust error: `Json5Err(Message { msg: ...` with two
    `/root/.cargo/...rs` source paths; a config file's bad value printed the `Message { ... }`."""
    for options in (ZenohOptions(connect=("foo",)), ZenohOptions(listen=("foo",))):
        with pytest.raises(ConfigError) as caught:
            make_config(options)
        text = str(caught.value)
        assert ".rs:" not in text and "Json5Err" not in text and "Message {" not in text, text
        assert text.endswith("endpoints = [\"foo\"]: Endpoints must be of the form "
                             "<protocol>/<address>[?<metadata>][#<config>]: foo"), text
    bad = tmp_path / "bad.json5"
    bad.write_text('{ mode: "client", connect: { endpoints: ["foo"] } }')
    with pytest.raises(ConfigError) as caught:
        make_config(ZenohOptions(config_file=bad))
    assert str(caught.value) == (
        f"cannot load Zenoh config {bad}: line 1, column 42: Endpoints must be of the form "
        "<protocol>/<address>[?<metadata>][#<config>]: foo")


def test_an_endpoint_zenoh_refuses_is_quoted_as_given_with_no_rust_escapes():
    """Zenoh's message carries the endpoint in Rust's debug form: a backslash in it was said
    doubled, and one before a quote as two backslashes and the quote. A newline stays the two
    characters backslash and n: the message is one line."""
    form = "Endpoints must be of the form <protocol>/<address>[?<metadata>][#<config>]: "
    for endpoint, said in (("fo\\o", "fo\\o"), ('a"b', 'a"b'), ('c\\"d', 'c\\"d'),
                           ("e\nf", "e\\nf")):
        with pytest.raises(ConfigError) as caught:
            make_config(ZenohOptions(connect=(endpoint,)))
        assert str(caught.value).endswith(form + said), (endpoint, str(caught.value))


def test_tracked_target_fields_cross_the_wire_and_are_left_out_where_unset():
    import msgpack

    from cached_cases import make_case

    scene = make_case("loom-dark-c0.6-d12-topleft")
    frame = Frame.from_image(scene.frames[0], seq=0, stamp=0.0)
    for name, tracked in (("robust", True), ("reference32", False)):
        model = ASNN(name)
        results = [model.step(image, i / scene.fps) for i, image in enumerate(scene.frames)]
        result = next(r for r in reversed(results) if r.targets)
        wire = encode(response_from(result, robot="r1", frame=frame, model="asnn", preset=name,
                                    worker="w", latency_ms=1.0, dropped=0))
        raw = msgpack.unpackb(wire)["targets"]
        back = decode_response(wire).targets
        if tracked:
            assert {"id", "expansion", "ttc", "offset", "approaching"} <= set(raw[0])
            assert back[0].id == result.targets[0].id and back[0].ttc == result.targets[0].ttc
        else:
            assert set(raw[0]) == {"x", "y", "direction", "energy", "pixels"}
            assert back[0].id is None and back[0].ttc is None
    bad = msgpack.unpackb(wire)
    bad["targets"][0]["ttc"] = -1.0  # a time to contact is positive
    with pytest.raises(MessageError):
        decode_response(msgpack.packb(bad))


def test_alert_lines_lead_tracked_targets_with_their_id_and_time_to_contact():
    from clients.alerts import format_warning
    from service.messages import TargetMsg

    common = dict(robot="r1", seq=7, stamp=12.0, model="asnn", preset="p", u=1.0, out=0.9,
                  spikes=3, spike_rate=60.0, collision=True, worker="w", latency_ms=1.0,
                  dropped=0)
    place = dict(x=10.0, y=20.0, direction=0.0, energy=0.1, pixels=40)
    tracked = format_warning(Response(**common, targets=[
        TargetMsg(**place, id=3, expansion=2.0, ttc=0.5, offset=0.1, approaching=True)]))
    assert "#3 contact in 0.50 s, path offset 0.10 at (10, 20) 40 px" in tracked
    assert "heading" not in tracked  # a collision course's motion has no direction to read
    handed = format_warning(Response(**common, targets=[
        TargetMsg(**place, id=25 * 2**16 + 3, expansion=2.0, ttc=0.5, approaching=True)]))
    assert "#25:3 contact in 0.50 s" in handed  # track 3 of the model that started at seq 25
    plain = format_warning(Response(**common, targets=[TargetMsg(**place)]))
    assert "#" not in plain and "(10, 20) heading +0 deg energy 0.1 40 px" in plain


def test_a_status_map_is_read_within_bounds_of_its_own():
    from service.messages import (STATUS_MAX_MAP_LEN, MessageError, decode_status,
                                  encode_status)

    robots = {f"r{k}": {"processed": k, "warm": True} for k in range(1000)}  # > a message's 256
    status = {"v": 1, "worker": "w1", "robots": robots}
    assert decode_status(encode_status(status)) == status
    for hostile in (msgpack.packb({"worker": "w", "robots": dict.fromkeys(
                        map(str, range(STATUS_MAX_MAP_LEN + 1)), 0)}),  # refused at its header
                    msgpack.packb([1, 2]), msgpack.packb({"robots": {}}), b"\xc1"):
        with pytest.raises(MessageError):
            decode_status(hostile)
