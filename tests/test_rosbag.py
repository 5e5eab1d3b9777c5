"""ROS 2 bags (MCAP) as a source: decoding every supported encoding, detect on bags against the
same frames from a lossless video, eval and camera on bags, and every kind of bad bag."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import subprocess
import sys
import time
import warnings

import cv2
import numpy as np
import pytest

pytest.importorskip("mcap_ros2", reason="the 'ros' extra is not installed")

from mcap_ros2.writer import Writer as Ros2Writer  # noqa: E402  (the third-party writer)

from asnn.evaluation.clips import evaluate_clips  # noqa: E402
from asnn.io import mcap_reader, rosbag  # noqa: E402
from asnn.io.images import ImageError  # noqa: E402
from asnn.io.sources import BackwardStamps, SourceError, open_source  # noqa: E402
from asnn.stimuli import make_scene  # noqa: E402
from cli.main import main  # noqa: E402

START_NS = 1_700_000_000_000_000_000


def header(index: int, fps: float = 20.0, frame_id: str = "cam") -> dict:
    ns = START_NS + round(index * 1e9 / fps)
    return {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": frame_id}


def raw_message(image: np.ndarray, encoding: str, index: int = 0, *, pad: int = 0,
                bigendian: bool = False, fps: float = 20.0) -> dict:
    """A sensor_msgs/msg/Image dict of ``image`` (already in ``encoding``'s layout), each row
    padded with ``pad`` bytes."""
    h, w = image.shape[:2]
    pixels = image.astype(image.dtype.newbyteorder(">" if bigendian else "<"))
    rows = pixels.reshape(h, -1).view(np.uint8)
    step = rows.shape[1] + pad
    data = np.zeros((h, step), np.uint8)
    data[:, :rows.shape[1]] = rows
    return {"header": header(index, fps), "height": h, "width": w, "encoding": encoding,
            "is_bigendian": int(bigendian), "step": step, "data": data.tobytes()}


def write_messages(path, topics: dict[str, tuple[str, list[dict]]], fps: float = 20.0,
                   chunk_size: int = 1024 * 1024, **options):
    """A bag with the third-party writer: {topic: (schema name, messages)}; ``options`` go to
    the writer (``compression``)."""
    definitions = {rosbag.IMAGE: rosbag.IMAGE_MSGDEF,
                   rosbag.COMPRESSED_IMAGE: rosbag.COMPRESSED_IMAGE_MSGDEF,
                   "std_msgs/msg/String": "string data"}
    with open(path, "wb") as fh, Ros2Writer(fh, chunk_size=chunk_size, **options) as writer:
        schemas = {name: writer.register_msgdef(name, text) for name, text in definitions.items()}
        for topic, (schema, messages) in topics.items():
            for index, message in enumerate(messages):
                ns = START_NS + round(index * 1e9 / fps)
                writer.write_message(topic, schemas[schema], message, log_time=ns,
                                     publish_time=ns, sequence=index)
    return path


@pytest.fixture(scope="module")
def looming():
    return make_scene("looming", size=(96, 96), start=5, stop=30)


def run_detect(*args, process: bool = False) -> tuple[int, str, str]:
    """``asnn detect ARGS``: its exit status, standard output and standard error.

    Run in this process (``cli.main.main``) unless ``process``: the bag is read, and its
    errors said, by the same code either way, without a new interpreter's start-up (a second or
    more each, for some fifty runs in this module); a few tests run ``asnn detect`` as its own
    process, as a user does. A warning raised here is added to the standard error, where a
    process prints it."""
    args = ["detect", *map(str, args)]
    if process:
        proc = subprocess.run([sys.executable, "-m", "cli.main", *args], capture_output=True,
                              text=True, timeout=300)
        return proc.returncode, proc.stdout, proc.stderr
    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(out), \
            contextlib.redirect_stderr(err):
        code = main(args)
    printed = "".join(warnings.formatwarning(w.message, w.category, w.filename, w.lineno, w.line)
                      for w in caught)
    return code, out.getvalue(), err.getvalue() + printed


def detect_records(*args, process: bool = False) -> list[dict]:
    code, out, err = run_detect(*args, "--jsonl", "-", process=process)
    assert code == 0, err
    return [json.loads(line) for line in out.splitlines()]


def write_ffv1(frames, path, fps=20.0):
    """A lossless video (FFV1) of gray or BGR frames."""
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, (w, h))
    assert writer.isOpened()
    for frame in frames:
        writer.write(frame if frame.ndim == 3 else cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR))
    writer.release()
    return path


# --------------------------------------------------------------------------- decoding

@pytest.mark.parametrize("pad", [0, 3])
def test_raw_encodings_decode_to_gray_or_bgr_with_row_padding(pad):
    rng = np.random.default_rng(0)
    bgr = rng.integers(0, 256, (5, 7, 3), dtype=np.uint8)
    gray = bgr[..., 0].copy()
    rgb = bgr[..., ::-1].copy()
    cases = {"mono8": gray, "8UC1": gray, "bgr8": bgr, "8UC3": bgr, "rgb8": rgb,
             "rgba8": np.dstack([rgb, np.full((5, 7), 9, np.uint8)]),
             "bgra8": np.dstack([bgr, np.full((5, 7), 9, np.uint8)])}
    for encoding, pixels in cases.items():
        m = raw_message(pixels, encoding, pad=pad)
        out = rosbag.image_from_raw(m["width"], m["height"], encoding, 0, m["step"], m["data"])
        expected = gray if encoding in ("mono8", "8UC1") else bgr
        assert out.dtype == np.uint8 and np.array_equal(out, expected), encoding


@pytest.mark.parametrize("bigendian", [False, True])
def test_mono16_takes_the_high_byte_in_either_byte_order(bigendian):
    values = np.array([[0, 255, 256, 65535], [4660, 32768, 1, 51966]], dtype=np.uint16)
    m = raw_message(values, "mono16", pad=2, bigendian=bigendian)
    out = rosbag.image_from_raw(4, 2, "mono16", int(bigendian), m["step"], m["data"])
    assert np.array_equal(out, (values >> 8).astype(np.uint8))


def test_bayer_and_yuv_decode_a_uniform_colour_to_itself():
    b, g, r = 40, 120, 200
    mosaic = np.zeros((8, 8), np.uint8)  # rggb: R at (even, even), B at (odd, odd)
    mosaic[0::2, 0::2], mosaic[0::2, 1::2], mosaic[1::2, 0::2], mosaic[1::2, 1::2] = r, g, g, b
    out = rosbag.image_from_raw(8, 8, "bayer_rggb8", 0, 8, mosaic.tobytes())
    assert np.abs(out[2:-2, 2:-2].astype(int) - [b, g, r]).max() <= 1
    uyvy = np.tile(np.array([128, 90, 128, 90], np.uint8), (4, 2))  # gray: Y 90, U = V = 128
    out = rosbag.image_from_raw(4, 4, "yuv422", 0, 8, uyvy.tobytes())
    assert np.abs(out.astype(int) - 1.164 * (90 - 16)).max() <= 1  # BT.601, video range
    out = rosbag.image_from_raw(4, 4, "yuv422_yuy2", 0, 8, uyvy.tobytes())  # read as YUYV
    assert np.ptp(out[0, 0]) > 50  # U = V = 90: not gray


def test_compressed_images_decode_jpeg_and_png_of_any_depth():
    rng = np.random.default_rng(1)
    bgr = rng.integers(0, 256, (6, 9, 3), dtype=np.uint8)
    png = cv2.imencode(".png", bgr)[1].tobytes()
    assert np.array_equal(rosbag.image_from_compressed("png", png), bgr)
    assert np.array_equal(rosbag.image_from_compressed("bgr8; png compressed bgr8", png), bgr)
    deep = cv2.imencode(".png", np.full((4, 4), 0x1234, np.uint16))[1].tobytes()
    assert np.array_equal(rosbag.image_from_compressed("mono16; png", deep),
                          np.full((4, 4), 0x12, np.uint8))
    jpeg = cv2.imencode(".jpg", bgr)[1].tobytes()
    assert rosbag.image_from_compressed("rgb8; jpeg compressed bgr8", jpeg).shape == (6, 9, 3)


@pytest.mark.parametrize("args, reason", [
    ((4, 4, "32FC1", 0, 16, bytes(64)), "unknown-encoding"),
    ((4, 4, "mono8", 0, 3, bytes(16)), "bad-size"),           # step shorter than a row
    ((4, 4, "mono8", 0, 4, bytes(15)), "bad-pixels"),         # data too short
    ((4, 4, "mono8", 0, 4, bytes(17)), "bad-pixels"),         # data too long
    ((5000, 1, "mono8", 0, 5000, bytes(5000)), "bad-size"),   # wider than MAX_SIDE
    ((0, 4, "mono8", 0, 0, b""), "bad-size"),
    ((2**31, 2**31, "bgr8", 0, 3 * 2**31, bytes(10)), "bad-size"),  # nothing allocated
    ((3, 2, "yuv422", 0, 6, bytes(12)), "bad-size"),          # odd width
])
def test_bad_raw_images_are_refused_with_a_reason(args, reason):
    with pytest.raises(ImageError) as info:
        rosbag.image_from_raw(*args)
    assert info.value.reason == reason


@pytest.mark.parametrize("format, data, reason", [
    ("16UC1; compressedDepth png", b"\x89PNG", "unknown-encoding"),
    ("tiff", b"II*\x00", "unknown-encoding"),
    ("jpeg", b"not a jpeg", "bad-image"),
    ("png", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x01\x00\x00\x00\x01\x00\x00"
     b"\x08\x00\x00\x00\x00" + bytes(4),
     "bad-size"),  # a header claiming 65536 x 65536: refused before decoding
    ("png", cv2.imencode(".png", np.zeros((4, 4), np.uint8))[1].tobytes()[:20],
     "bad-image"),  # a header cut short
])
def test_bad_compressed_images_are_refused_with_a_reason(format, data, reason):
    with pytest.raises(ImageError) as info:
        rosbag.image_from_compressed(format, data)
    assert info.value.reason == reason


def test_names_read_from_a_bag_are_shortened_in_error_lines(tmp_path, looming):
    """A probe: a 20 MB encoding string made a 20 MB "one-line" error, and so did 5000 image
    topics or three topic names of a megabyte."""
    with pytest.raises(ImageError) as info:
        rosbag.image_from_raw(4, 4, "x" * 10**6, 0, 4, bytes(16))
    assert len(str(info.value)) < 1000 and "1000000 characters" in str(info.value)
    with pytest.raises(ImageError) as info:
        rosbag.image_from_compressed("y" * 10**6, b"\xff\xd8")
    assert len(str(info.value)) < 1000
    frame = raw_message(looming.frames[0], "mono8")
    names = [f"/cam{k:03d}/" + "z" * 5000 for k in range(30)]
    bag = write_messages(tmp_path / "many.mcap", {n: (rosbag.IMAGE, [frame]) for n in names})
    line = detect_fails(bag)
    assert "several image topics" in line and len(line) < 3000 and "and 10 more" in line
    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    assert "not a regular file" in detect_fails(fifo)


def lying_jpeg(width: int = 4096, height: int = 4096) -> bytes:
    """A whole jpeg of an 8x8 black image (a few hundred bytes), its header edited to declare
    width x height: a decoder pads the missing pixels into a huge picture."""
    data = bytearray(cv2.imencode(".jpg", np.zeros((8, 8), np.uint8))[1].tobytes())
    sof = data.index(b"\xff\xc0")
    data[sof + 5:sof + 7] = height.to_bytes(2, "big")
    data[sof + 7:sof + 9] = width.to_bytes(2, "big")
    return bytes(data)


def test_a_truncated_jpeg_declaring_4096x4096_is_refused_before_decoding(tmp_path, monkeypatch):
    """The service's protection against amplification (docs/operations.md, "Hostile input")
    holds for compressed images in bags: the header must describe a whole image its data can
    hold, and a lying one never reaches the decoder."""
    decoded = []  # the sizes the decoder made

    def imdecode(*args):
        image = real_imdecode(*args)
        decoded.append(None if image is None else image.shape)
        return image

    real_imdecode = cv2.imdecode
    monkeypatch.setattr(cv2, "imdecode", imdecode)
    with pytest.raises(ImageError) as info:
        rosbag.image_from_compressed("jpeg", lying_jpeg())
    assert info.value.reason == "bad-image" and "truncated" in info.value.detail
    assert not decoded
    good = cv2.imencode(".jpg", np.full((8, 8), 128, np.uint8))[1].tobytes()
    bag = write_messages(tmp_path / "lying.mcap", {"/cam": (rosbag.COMPRESSED_IMAGE, [
        {"header": header(i), "format": "jpeg", "data": data}
        for i, data in enumerate([good, lying_jpeg(), good])])})
    rejected = []
    frames = list(open_source(str(bag), on_error=lambda reason, _: rejected.append(reason))
                  .frames())
    assert [f.shape for f in frames] == [(8, 8), (8, 8)] and rejected == ["bad-image"]
    assert decoded and set(decoded) == {(8, 8)}  # only the whole pictures were decoded


# --------------------------------------------------------------------------- detect

def test_detect_on_a_mono8_bag_equals_detect_on_the_same_frames_in_a_lossless_video(
        tmp_path, looming):
    frames = list(looming.frames)
    bag = write_messages(tmp_path / "run.mcap", {"/camera/image_raw": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(frames)])})
    video = write_ffv1(frames, tmp_path / "run.avi")
    from_bag, from_video = detect_records(bag, process=True), detect_records(video, process=True)
    assert len(from_bag) == len(frames) and from_bag == from_video
    assert any(r["collision"] and r["targets"] for r in from_bag)  # the comparison is not empty


def test_an_odd_sized_bag_annotates_with_a_warning_for_the_column_the_encoder_drops(
        tmp_path, looming, capsys):
    frames = [f[:95, :95] for f in looming.frames][:6]  # the encoders take even sizes only
    bag = write_messages(tmp_path / "odd.mcap", {"/camera/image_raw": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(frames)])})
    video = tmp_path / "odd.mp4"
    assert main(["detect", str(bag), "--annotate", str(video), "--threads", "1"]) == 0
    capture = cv2.VideoCapture(str(video))
    assert (capture.get(cv2.CAP_PROP_FRAME_WIDTH), capture.get(cv2.CAP_PROP_FRAME_HEIGHT)) == (94, 94)
    capture.release()
    warnings = [line for line in capsys.readouterr().err.splitlines() if ": warning:" in line]
    assert warnings == [f"asnn detect: warning: --annotate {video}: written 94x94, the frames' "
                        "95x95 rounded down by the encoder (it takes even sizes only): the last "
                        "column or row is left out"]


def test_detect_on_colour_and_compressed_bags_equals_the_lossless_video(tmp_path, looming):
    rng = np.random.default_rng(2)
    tint = rng.integers(0, 30, 3)  # colour frames whose channels differ
    frames = [np.clip(np.dstack([f, f, f]).astype(int) - tint, 0, 255).astype(np.uint8)
              for f in looming.frames]
    rgb = [raw_message(f[..., ::-1].copy(), "rgb8", i, pad=4) for i, f in enumerate(frames)]
    png = [{"header": header(i), "format": "bgr8; png compressed bgr8",
            "data": cv2.imencode(".png", f)[1].tobytes()} for i, f in enumerate(frames)]
    bag = write_messages(tmp_path / "two.mcap", {"/cam/rgb": (rosbag.IMAGE, rgb),
                                                 "/cam/png": (rosbag.COMPRESSED_IMAGE, png)})
    expected = detect_records(write_ffv1(frames, tmp_path / "colour.avi"))
    assert detect_records(bag, "--topic", "/cam/rgb") == expected
    assert detect_records(f"{bag}#/cam/png") == expected


def test_t_is_the_header_stamp_relative_to_the_first_frame(tmp_path, looming):
    frames = list(looming.frames[:6])
    stamps = [0.0, 0.1, 0.25, 0.3, 0.5, 0.55]  # jittery: not frame / fps
    messages = []
    for f, s in zip(frames, stamps):
        m = raw_message(f, "mono8")
        ns = START_NS + round(s * 1e9)
        m["header"]["stamp"] = {"sec": ns // 10**9, "nanosec": ns % 10**9}
        messages.append(m)
    bag = write_messages(tmp_path / "jitter.mcap", {"/c": (rosbag.IMAGE, messages)})
    assert [r["t"] for r in detect_records(bag)] == stamps
    source = open_source(str(bag))
    assert source.timed and source.start_ns == START_NS and source.frame_id == "cam"
    assert source.frame_count == 6 and source.fps == pytest.approx(10.0)  # median step 0.1 s
    # a driver that stops stamping partway: those frames take their log time (the recorder's
    # clock: here 0.05 s apart), not 1970, and never one before the latest frame's t
    for m in messages[3:]:
        m["header"]["stamp"] = {"sec": 0, "nanosec": 0}
    bag = write_messages(tmp_path / "unstamped.mcap", {"/c": (rosbag.IMAGE, messages)})
    assert [r["t"] for r in detect_records(bag)] == [0.0, 0.1, 0.25, 0.25, 0.25, 0.25]
    for m, s in zip(messages[:3], [0.0, 0.05, 0.1]):  # stamped as the recorder logs them
        ns = START_NS + round(s * 1e9)
        m["header"]["stamp"] = {"sec": ns // 10**9, "nanosec": ns % 10**9}
    bag = write_messages(tmp_path / "unstamped2.mcap", {"/c": (rosbag.IMAGE, messages)})
    assert [r["t"] for r in detect_records(bag)] == [0.0, 0.05, 0.1, 0.15, 0.2, 0.25]
    for m, s in zip(messages[:3], [5.0, 5.05, 5.1]):  # simulated time: not the recorder's
        m["header"]["stamp"] = {"sec": int(s), "nanosec": round(s % 1 * 1e9)}
    bag = write_messages(tmp_path / "simulated.mcap", {"/c": (rosbag.IMAGE, messages)})
    assert [r["t"] for r in detect_records(bag)] == pytest.approx([0.0, 0.05, 0.1, 0.1, 0.1,
                                                                   0.1])
    # a bag timed by the recorder whose log times came swapped: never back either
    for m in messages:
        m["header"]["stamp"] = {"sec": 0, "nanosec": 0}
    path = tmp_path / "logged.mcap"
    with open(path, "wb") as fh, Ros2Writer(fh) as writer:
        schema = writer.register_msgdef(rosbag.IMAGE, rosbag.IMAGE_MSGDEF)
        for i, (m, ms) in enumerate(zip(messages, [0, 50, 150, 100, 200, 250])):
            ns = START_NS + ms * 1_000_000
            writer.write_message("/c", schema, m, log_time=ns, publish_time=ns, sequence=i)
    assert [r["t"] for r in detect_records(path)] == [0.0, 0.05, 0.15, 0.15, 0.2, 0.25]


def test_a_rosbag2_directory_and_asnn_scene_bags_open(tmp_path, looming):
    directory = tmp_path / "rosbag2_run"
    directory.mkdir()
    (directory / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    rosbag.write_bag(looming.frames, directory / "rosbag2_run_0.mcap")
    assert len(list(open_source(str(directory)).frames())) == len(looming.frames)
    assert main(["scene", "receding", str(tmp_path / "scene.mcap"), "--size", "64x48"]) == 0
    frames = list(open_source(str(tmp_path / "scene.mcap")).frames())
    assert len(frames) == len(make_scene("receding").frames) and frames[0].shape == (48, 64)


def test_a_split_rosbag2_directory_is_read_part_after_part_in_numeric_order(tmp_path, looming):
    """A bag split by size (ros2 bag record --max-bag-size): run_0.mcap ... run_10.mcap, read
    as one clip, the same as the unsplit bag (run_10 after run_9, not after run_1)."""
    directory = tmp_path / "run"
    directory.mkdir()
    (directory / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    frames = looming.frames[:22]
    start = 1_700_000_000_000_000_000
    for part in range(11):  # two frames a file, each file's stamps continuing the last
        rosbag.write_bag(frames[2 * part:2 * part + 2], directory / f"run_{part}.mcap",
                         start_ns=start + part * 2 * 50_000_000)
    whole = rosbag.write_bag(frames, tmp_path / "whole.mcap", start_ns=start)
    assert open_source(str(directory)).name == f"{directory}#/camera/image_raw"
    read = [image for _, image in rosbag.open_bag(directory).frames()]
    assert len(read) == len(frames)
    assert all(np.array_equal(a, b) for a, b in zip(read, frames))
    assert rosbag.open_bag(directory).frame_count == len(frames)
    assert detect_records(directory) == detect_records(whole)


def test_a_split_bag_whose_topic_changes_its_image_type_stops_at_the_change(tmp_path, looming):
    """The first part's type decodes the topic: a later part that records it as another image
    type is a type change (each of its frames read as the first type was "not an Image")."""
    directory = tmp_path / "run"
    directory.mkdir()
    (directory / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    start = 1_700_000_000_000_000_000
    rosbag.write_bag(looming.frames[:3], directory / "run_0.mcap", start_ns=start)
    rosbag.write_bag(looming.frames[3:6], directory / "run_1.mcap", format="png",
                     start_ns=start + 3 * 50_000_000)
    errors = []
    read = list(open_source(str(directory), on_error=lambda reason, message: errors.append(
        (reason, message))).frames())
    assert len(read) == 3 and len(errors) == 1
    assert errors[0][0] == "no-topic" and "changed its type to sensor_msgs/msg/CompressedImage" \
        in errors[0][1]


def test_a_rosbag2_directory_is_the_files_its_metadata_lists(tmp_path, looming):
    """A copy, a recovered file or results written beside the bag are not part of it; a split
    bag's camera may start in a later part."""
    directory = tmp_path / "run"
    directory.mkdir()
    (directory / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  storage_identifier: mcap\n"
        "  relative_file_paths:\n    - run_0.mcap\n    - run_1.mcap\n")
    status = [{"data": "up"}]
    write_messages(directory / "run_0.mcap", {"/status": ("std_msgs/msg/String", status)})
    rosbag.write_bag(looming.frames[:10], directory / "run_1.mcap")  # the camera started late
    rosbag.write_bag(looming.frames, directory / "run_0 (copy).mcap")
    assert len(list(open_source(str(directory)).frames())) == 10
    assert rosbag.open_bag(directory).frame_count == 10
    (directory / "run_1.mcap").unlink()
    assert "metadata.yaml lists run_1.mcap, which is not there" in detect_fails(directory)
    (directory / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  storage_identifier: sqlite3\n")
    assert "only MCAP bags are read" in detect_fails(directory)
    for value in ("[1, 2]", "hello"):  # one line, not a traceback (a bag reader's round)
        (directory / "metadata.yaml").write_text(f"rosbag2_bagfile_information: {value}\n")
        assert "not a rosbag2 metadata file" in detect_fails(directory)
    (directory / "metadata.yaml").unlink()  # a recording killed before it wrote its metadata
    assert "without the metadata.yaml of a rosbag2 directory" in detect_fails(directory)


def test_bags_in_formats_not_read_are_named_as_such(tmp_path):
    """A rosbag2 SQLite file (alone or in its folder without metadata) or a ROS 1 bag is
    refused as the bag it is, with the way out, not as a video OpenCV cannot decode."""
    sqlite = tmp_path / "run" / "run_0.db3"
    sqlite.parent.mkdir()
    sqlite.write_bytes(b"SQLite format 3\x00" + bytes(100))
    ros1 = tmp_path / "drive.bag"
    ros1.write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
    for path, said in ((sqlite, "stored in SQLite"), (sqlite.parent, "stored in SQLite"),
                       (ros1, "a ROS 1 bag")):
        with pytest.raises(SourceError, match=said) as refused:
            open_source(str(path))
        assert refused.value.reason == "not-a-bag"
        assert said in detect_fails(path)


def test_a_summary_whose_statistics_give_no_message_counts_does_not_empty_the_topic(
        tmp_path, looming):
    """An empty channel_message_counts means the statistic is not available (the MCAP
    specification), not that every topic is empty: the bag was refused, "holds no message"."""
    path = tmp_path / "nocounts.mcap"
    with open(path, "wb") as fh, Ros2Writer(fh) as writer:
        schema = writer.register_msgdef(rosbag.IMAGE, rosbag.IMAGE_MSGDEF)
        for index, frame in enumerate(looming.frames[:10]):
            ns = START_NS + index * 50_000_000
            writer.write_message("/c", schema, raw_message(frame, "mono8", index), log_time=ns,
                                 publish_time=ns, sequence=index)
        writer._writer._Writer__statistics.channel_message_counts.clear()  # the writer's own
    assert rosbag.bag_topics(path)["/c"].count is None
    assert len(detect_records(path)) == 10


# --------------------------------------------------------------------------- Foxglove's images

def write_foxglove(path, topics: dict[str, list], fps: float = 20.0):
    """An MCAP as Foxglove's SDK writes one: {topic: [foxglove.RawImage or CompressedImage]},
    each message logged at its frame's time."""
    foxglove = pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    from foxglove.channels import CompressedImageChannel, RawImageChannel

    context = foxglove.Context()  # only these channels reach this file
    with foxglove.open_mcap(str(path), allow_overwrite=True, context=context):
        for topic, messages in topics.items():
            kind = RawImageChannel if type(messages[0]).__name__ == "RawImage" else \
                CompressedImageChannel
            channel = kind(topic, context=context)
            for index, message in enumerate(messages):
                channel.log(message, log_time=START_NS + round(index * 1e9 / fps))
            channel.close()
    return path


def write_channels(path, channels: list[tuple], fps: float = 20.0, **options):
    """An MCAP written channel by channel: ``(topic, schema name, schema encoding, message
    encoding, [payload bytes])`` each, declared in that order (several may share a topic), each
    channel's messages timed on from the previous channel's; ``options`` go to mcap's Writer."""
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        writer = Writer(fh, **options)
        writer.start(profile="", library="test")
        index = 0
        for topic, schema, encoding, message_encoding, payloads in channels:
            sid = writer.register_schema(schema, encoding, b"") if schema else 0  # 0: none
            cid = writer.register_channel(topic, message_encoding, sid)
            for payload in payloads:
                ns = START_NS + round(index * 1e9 / fps)
                writer.add_message(cid, log_time=ns, data=payload, publish_time=ns)
                index += 1
        writer.finish()
    return path


def fox_stamp(index: int, fps: float = 20.0):
    from foxglove.messages import Timestamp

    ns = START_NS + round(index * 1e9 / fps)
    return Timestamp(sec=ns // 10**9, nsec=ns % 10**9)


def test_foxglove_raw_and_compressed_images_equal_the_lossless_video(tmp_path, looming):
    """Foxglove's recorders (and detect --mcap) write foxglove.RawImage / CompressedImage in
    protobuf: read by their field numbers, rows padded, timed by their timestamps."""
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    from foxglove.messages import CompressedImage, RawImage

    tint = np.array([5, 17, 29])
    frames = [np.clip(np.dstack([f, f, f]).astype(int) - tint, 0, 255).astype(np.uint8)
              for f in looming.frames]
    h, w = frames[0].shape[:2]
    raw = []
    for i, f in enumerate(frames):
        rows = np.zeros((h, w * 3 + 4), np.uint8)  # rgb, each row padded by 4 bytes
        rows[:, :w * 3] = f[..., ::-1].reshape(h, -1)
        raw.append(RawImage(timestamp=fox_stamp(i), frame_id="front", width=w, height=h,
                            encoding="rgb8", step=w * 3 + 4, data=rows.tobytes()))
    png = [CompressedImage(timestamp=fox_stamp(i), frame_id="front", format="png",
                           data=cv2.imencode(".png", f)[1].tobytes())
           for i, f in enumerate(frames)]
    bag = write_foxglove(tmp_path / "fox.mcap", {"/fox/raw": raw, "/fox/png": png})
    expected = detect_records(write_ffv1(frames, tmp_path / "colour.avi"))
    assert detect_records(bag, "--topic", "/fox/raw") == expected
    assert detect_records(f"{bag}#/fox/png") == expected
    assert any(r["collision"] for r in expected)  # the comparison is not empty
    source = open_source(f"{bag}#/fox/raw")
    assert source.frame_id == "front" and source.start_ns == START_NS


def test_detect_reads_back_the_mcap_it_wrote(tmp_path, looming):
    """detect --mcap writes the frames as foxglove.CompressedImage (jpeg): its own output is a
    source again, at the same times, warning where the first run warned (give or take a frame:
    jpeg)."""
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    frames = list(looming.frames)
    bag = write_messages(tmp_path / "run.mcap", {"/camera/image_raw": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(frames)])})
    out = tmp_path / "out.mcap"
    first = detect_records(bag, "--mcap", out)
    again = detect_records(out)
    assert [r["t"] for r in again] == [r["t"] for r in first]
    warned = [r["frame"] for r in first if r["collision"]]
    rewarned = [r["frame"] for r in again if r["collision"]]
    assert warned and rewarned and abs(rewarned[0] - warned[0]) <= 1
    assert abs(len(rewarned) - len(warned)) <= 2


def test_a_foxglove_image_without_a_timestamp_is_timed_by_its_log_time(tmp_path, looming):
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    from foxglove.messages import RawImage

    h, w = looming.frames[0].shape
    messages = [RawImage(width=w, height=h, encoding="mono8", step=w, data=f.tobytes())
                for f in looming.frames[:4]]  # no timestamp: protobuf's zero
    bag = write_foxglove(tmp_path / "unstamped.mcap", {"/c": messages}, fps=10.0)
    assert [r["t"] for r in detect_records(bag)] == [0.0, 0.1, 0.2, 0.3]


def test_frames_timed_by_log_times_that_go_back_are_held_reported_and_not_the_rate(
        tmp_path, looming):
    """An integrator's trial: a bag timed by its recorder (no header stamps) whose log times
    go back (frames that arrived swapped, a file not in log-time order) had those frames held
    at the latest frame's time without a word, and its frame rate read from the gaps in file
    order (2.9 fps for a 20 fps file, shuffled)."""
    foxglove = pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    from foxglove.channels import RawImageChannel
    from foxglove.messages import RawImage

    h, w = looming.frames[0].shape
    order = [0, 1, 3, 2, 4, 5, 7, 6, 8, 9]  # two pairs arrived swapped
    bag = tmp_path / "swapped.mcap"
    context = foxglove.Context()
    with foxglove.open_mcap(str(bag), allow_overwrite=True, context=context):
        channel = RawImageChannel("/c", context=context)
        for i in order:
            channel.log(RawImage(width=w, height=h, encoding="mono8", step=w,
                                 data=looming.frames[i].tobytes()),
                        log_time=START_NS + i * 100_000_000)
    reports = []
    clip = open_source(str(bag), on_error=lambda r, m: reports.append((r, m)))
    times = [t for t, _ in clip.timed_frames()]
    assert times == pytest.approx([0.0, 0.1, 0.3, 0.3, 0.4, 0.5, 0.7, 0.7, 0.8, 0.9])
    assert [r for r, _ in reports] == ["stamp-unset"] * 2
    assert "message 3: timed by its log time (the topic's first frame has no header stamp), " \
           "and its log time is 0.1 s before the latest frame's time: held" in reports[0][1]
    assert rosbag.open_bag(bag).fps == pytest.approx(10.0)


def test_a_header_clock_that_steps_back_a_little_early_on_leaves_the_frame_rate(tmp_path,
                                                                               looming):
    """A review: the frame rate read from the stamps sorted (right for a recorder's log times
    of swapped frames) read a 20 fps bag whose clock stepped back 0.587 s at frame 12 (an NTP
    step at boot) as 27 fps, its two timelines interleaved."""
    stamps = [START_NS + 50_000_000 * i for i in range(len(looming.frames))]
    stamps[12:] = [ns - 587_000_000 for ns in stamps[12:]]
    bag = ns_bag(tmp_path / "step.mcap", looming.frames, stamps)
    assert rosbag.open_bag(bag).fps == pytest.approx(20.0)


def fox_raw(frames, start: int = 0) -> list[bytes]:
    """foxglove.RawImage (mono8) messages of ``frames``, stamped from frame ``start`` at 20 fps."""
    from foxglove.messages import RawImage

    return [RawImage(timestamp=fox_stamp(start + i), frame_id="cam", width=f.shape[1],
                     height=f.shape[0], encoding="mono8", step=f.shape[1],
                     data=f.tobytes()).encode() for i, f in enumerate(frames)]


@pytest.mark.parametrize("repeat_channels", [True, False])
def test_a_bag_whose_summary_does_not_repeat_its_schemas_is_read(tmp_path, looming,
                                                                 repeat_channels):
    """A valid MCAP (mcap's repeat_schemas=False, the Foxglove SDK's option too) keeps its
    schemas in the data section only: its summary's channels pointed at no schema and the bag
    was refused, "topics: /cam (no schema)"."""
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    frames = looming.frames[:10]
    bag = write_channels(tmp_path / "norepeat.mcap", [
        ("/cam", "foxglove.RawImage", "protobuf", "protobuf", fox_raw(frames))],
        repeat_schemas=False, repeat_channels=repeat_channels)
    assert rosbag.bag_topics(bag)["/cam"].schema == "foxglove.RawImage"
    assert len(detect_records(bag)) == len(frames)


def test_a_bag_with_a_schemaless_channel_whose_summary_does_not_repeat_its_schemas_is_read(
        tmp_path, looming):
    """A mutation probe: beside a channel without a schema (schema id 0: a JSON log), the
    image channel whose schema the summary does not repeat was still refused as 'no schema'."""
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    frames = looming.frames[:10]
    bag = write_channels(tmp_path / "norepeat.mcap", [
        ("/log", None, "", "json", [b"{}"] * 3),
        ("/cam", "foxglove.RawImage", "protobuf", "protobuf", fox_raw(frames))],
        repeat_schemas=False)
    assert rosbag.bag_topics(bag)["/cam"].schema == "foxglove.RawImage"
    assert len(detect_records(bag, "--topic", "/cam")) == len(frames)

def test_a_topic_recorded_on_several_channels_is_one_topic(tmp_path, looming):
    """Recordings merged, or a publisher that advertised again: the topic's count is its
    channels' sum and its type the first's (the last channel alone said "holds no message"
    of a topic whose idle channel came last, and undercounted the frames)."""
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    frames = looming.frames
    fox = ("foxglove.RawImage", "protobuf", "protobuf")
    for counts in ((len(frames), 0), (10, len(frames) - 10), (0, len(frames))):
        bag = write_channels(tmp_path / "merged.mcap", [
            ("/cam", *fox, fox_raw(frames[:counts[0]])),
            ("/cam", *fox, fox_raw(frames[counts[0]:], start=counts[0]))])
        assert rosbag.bag_topics(bag)["/cam"].count == len(frames), counts
        clip = rosbag.open_bag(bag)
        read = [image for _, image in clip.frames()]
        assert clip.frame_count == len(read) == len(frames), counts
        assert all(np.array_equal(a, b) for a, b in zip(read, frames))
    # a channel of another image type declared first and never used decides nothing
    bag = write_channels(tmp_path / "idle-first.mcap", [
        ("/cam", "foxglove.CompressedImage", "protobuf", "protobuf", []),
        ("/cam", *fox, fox_raw(frames[:5]))])
    assert rosbag.bag_topics(bag)["/cam"] == rosbag.TopicInfo("/cam", "foxglove.RawImage", 5)
    assert len(list(rosbag.open_bag(bag).frames())) == 5
    # a later channel of another image type: never used (a recorder's idle subscription), it
    # stops nothing; used, it is the type change (not an empty topic)
    bag = write_channels(tmp_path / "mixed.mcap", [
        ("/cam", *fox, fox_raw(frames[:5])),
        ("/cam", "foxglove.CompressedImage", "protobuf", "protobuf", [])])
    assert rosbag.bag_topics(bag)["/cam"] == rosbag.TopicInfo("/cam", "foxglove.RawImage", 5)
    errors = []
    read = list(rosbag.open_bag(bag).frames(lambda reason, message: errors.append(message)))
    assert len(read) == 5 and not errors
    bag = write_channels(tmp_path / "mixed2.mcap", [
        ("/cam", *fox, fox_raw(frames[:5])),
        ("/cam", "foxglove.CompressedImage", "protobuf", "protobuf", [b"\x12\x01x"])])
    assert "changed its type to foxglove.CompressedImage" in detect_fails(bag)
    with pytest.raises(rosbag.SourceError, match="changed its type"):  # read without a handler
        list(rosbag.open_bag(bag).frames())


def test_messages_are_named_by_their_place_in_the_topic_after_one_that_does_not_decode(
        tmp_path, looming):
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    from foxglove.messages import RawImage

    payloads = fox_raw(looming.frames[:8])
    payloads[2] = b"\xff"  # no message
    h, w = looming.frames[5].shape
    payloads[5] = RawImage(timestamp=fox_stamp(5), width=w, height=h, encoding="mono8", step=w,
                           data=looming.frames[5].tobytes()[:-w]).encode()  # a row short
    bag = write_channels(tmp_path / "bad.mcap", [("/c", "foxglove.RawImage", "protobuf",
                                                  "protobuf", payloads)])
    errors = []
    read = list(rosbag.open_bag(bag).frames(lambda reason, message: errors.append(message)))
    assert len(read) == 6 and len(errors) == 2
    assert "message 2 does not decode" in errors[0], errors
    assert "message 5:" in errors[1] and "needs" in errors[1], errors  # it said message 4


def test_raw_colour_frames_are_arrays_of_their_own():
    """Every encoding gives a new, writable array (bgr8 without padding was a read-only view of
    the message's bytes: drawing on it raised)."""
    for encoding, step in (("bgr8", 12), ("bgr8", 16), ("8UC3", 12), ("rgb8", 12),
                           ("mono8", 4), ("bgra8", 16)):
        data = bytes(range(2 * step))
        image = rosbag.image_from_raw(4, 2, encoding, 0, step, data)
        assert image.flags.writeable and not np.shares_memory(image, np.frombuffer(
            data, np.uint8)), encoding


def test_the_protobuf_reader_skips_unknown_fields_and_refuses_what_is_no_message():
    from asnn.io.foxglove_images import (ProtobufError, decode_compressed_image,
                                         decode_raw_image)

    def key(number, wire):
        return bytes([number << 3 | wire])

    def text(number, value: bytes):
        return key(number, 2) + bytes([len(value)]) + value

    stamp = key(1, 0) + bytes([7]) + key(2, 0) + bytes([9])  # 7 s, 9 ns
    message = (text(1, stamp) + key(15, 0) + bytes([0x96, 0x01])  # an unknown varint
               + key(14, 1) + bytes(8) + key(13, 5) + bytes(4)  # unknown fixed64, fixed32
               + text(3, b"jpeg") + text(3, b"png") + text(2, b"\x89PNG") + text(4, b"cam"))
    decoded = decode_compressed_image(message)
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (7, 9)
    assert decoded.format == "png" and bytes(decoded.data) == b"\x89PNG"  # the last one wins
    assert decoded.header.frame_id == "cam"
    raw = decode_raw_image(key(2, 5) + (640).to_bytes(4, "little") + key(3, 5)
                           + (480).to_bytes(4, "little") + text(4, b"mono8"))
    assert (raw.width, raw.height, raw.step, raw.encoding, bytes(raw.data)) == (
        640, 480, 0, "mono8", b"")  # absent fields: protobuf's defaults
    negative = key(2, 0) + bytes([0xFF] * 9 + [0x01])  # nanos -1, as int32 goes on the wire
    refused = {
        "group": key(3, 3), "cut varint": key(15, 0) + b"\x80",
        "endless varint": key(15, 0) + b"\x80" * 11, "cut bytes": key(2, 2) + b"\x05abc",
        "not utf-8": text(3, b"\xff\xfe"), "nanos out of range": text(1, negative),
        "wire type": key(2, 0) + b"\x01",
        # 10**10 s, past int64 nanoseconds (the year 2262): the bag's times overflowed
        "seconds too large": text(1, key(1, 0) + bytes([0x80, 0xC8, 0xAF, 0xA0, 0x25])),
        # millions of tiny unknown fields in a 135 MB message took minutes of Python each
        "too many fields": b"\x78\x00" * 300}
    for what, data in refused.items():
        with pytest.raises(ProtobufError):
            decode_compressed_image(data)
            pytest.fail(what)
    # a name of 20 001 bytes: its first 4096 characters kept, read from its first 16 384
    # bytes, which cut a two-byte character in half (left out, not an error)
    long = "a" + "\u00e9" * 10000
    length = bytes([0xA1, 0x9C, 0x01])  # 20 001 as a varint
    assert decode_compressed_image(key(3, 2) + length + long.encode()).format == long[:4096]


def test_the_protobuf_reader_s_edges():
    """Protobuf's own rules at their limits: an int64 second (negative, before 1970: refused
    by its value), nanos up to 999 999 999, ten bytes at most to a varint, eight to a fixed64;
    absent text is empty."""
    from asnn.io.foxglove_images import (ProtobufError, decode_compressed_image,
                                         decode_raw_image)

    def key(number, wire):
        return bytes([number << 3 | wire])

    def varint(value):
        value &= (1 << 64) - 1  # a negative int64 as the wire carries it
        out = bytearray()
        while True:
            out.append(value & 0x7F | (0x80 if value >> 7 else 0))
            value >>= 7
            if not value:
                return bytes(out)

    def text(number, value: bytes):
        return key(number, 2) + varint(len(value)) + value

    def stamp(seconds, nanos):
        return text(1, key(1, 0) + varint(seconds) + key(2, 0) + varint(nanos))

    with pytest.raises(ProtobufError, match="seconds -2 is outside"):  # as int64, not 2**64 - 2
        decode_compressed_image(stamp(-2, 500_000_000))
    assert decode_compressed_image(stamp(7, 999_999_999)).header.stamp.nanosec == 999_999_999
    with pytest.raises(ProtobufError, match="nanos"):
        decode_compressed_image(stamp(7, 1_000_000_000))
    with pytest.raises(ProtobufError, match="longer than"):  # eleven bytes, however it ends
        decode_compressed_image(key(15, 0) + b"\x80" * 10 + b"\x01")
    # an unknown fixed64 is eight bytes, whatever they hold (here what would read as a format)
    hidden = bytes(4) + text(3, b"xy")
    assert decode_compressed_image(text(3, b"png") + key(14, 1) + hidden).format == "png"
    # a text whose every byte is there must be UTF-8, at the reading limit too (16 384 bytes)
    with pytest.raises(ProtobufError, match="UTF-8"):
        decode_compressed_image(text(3, b"a" * 16383 + b"\xc3"))
    raw = decode_raw_image(key(2, 5) + (4).to_bytes(4, "little"))
    assert (raw.header.frame_id, raw.encoding, raw.header.stamp.sec) == ("", "", 0)
    assert decode_compressed_image(b"").format == ""


def test_foxglove_16_bit_images_are_little_endian(tmp_path, looming):
    """Foxglove's 16UC1 and mono16 are little-endian (its schema says so; RawImage has no
    is_bigendian): read by their high byte, as a ROS 2 Image with is_bigendian 0."""
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    from foxglove.messages import RawImage

    frames = looming.frames[:3]
    h, w = frames[0].shape
    payloads = [RawImage(timestamp=fox_stamp(i), width=w, height=h, encoding=encoding,
                         step=2 * w, data=(f.astype("<u2") * 256 + 3).tobytes()).encode()
                for i, (f, encoding) in enumerate(zip(frames, ("16UC1", "mono16", "16UC1")))]
    bag = write_channels(tmp_path / "deep.mcap", [("/depth", "foxglove.RawImage", "protobuf",
                                                   "protobuf", payloads)])
    read = [image for _, image in rosbag.open_bag(bag).frames()]
    assert len(read) == 3 and all(np.array_equal(a, b) for a, b in zip(read, frames))


def test_foxglove_images_need_protobuf_in_both_the_schema_and_the_channel(tmp_path, looming):
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    good = fox_raw(looming.frames[:1])
    for schema_encoding, message_encoding in (("protobuf", "json"), ("jsonschema", "protobuf")):
        bag = write_channels(tmp_path / f"{schema_encoding}.mcap", [
            ("/c", "foxglove.RawImage", schema_encoding, message_encoding, good)])
        assert "Foxglove's images are read in protobuf" in detect_fails(bag)


def test_a_first_frame_that_does_not_decode_is_named_by_its_place_in_the_topic(tmp_path,
                                                                              looming):
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    from foxglove.messages import RawImage

    h, w = looming.frames[1].shape
    payloads = [b"\xff", RawImage(timestamp=fox_stamp(1), width=w, height=h, encoding="mono8",
                                  step=w, data=looming.frames[1].tobytes()[:-w]).encode()]
    bag = write_channels(tmp_path / "first.mcap", [("/c", "foxglove.RawImage", "protobuf",
                                                    "protobuf", payloads)])
    message = detect_fails(bag)
    assert "message 1:" in message and "needs" in message, message


def test_a_split_bag_whose_part_gives_no_message_counts_has_no_partial_count(tmp_path,
                                                                            looming):
    """A part without the statistic makes the topic's count unknown (0), not the other
    parts' alone."""
    directory = tmp_path / "run"
    directory.mkdir()
    (directory / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    first = directory / "run_0.mcap"
    with open(first, "wb") as fh, Ros2Writer(fh) as writer:
        schema = writer.register_msgdef(rosbag.IMAGE, rosbag.IMAGE_MSGDEF)
        for index, frame in enumerate(looming.frames[:5]):
            ns = START_NS + index * 50_000_000
            writer.write_message("/camera/image_raw", schema, raw_message(frame, "mono8", index),
                                 log_time=ns, publish_time=ns, sequence=index)
        writer._writer._Writer__statistics.channel_message_counts.clear()
    rosbag.write_bag(looming.frames[5:10], directory / "run_1.mcap",
                     start_ns=START_NS + 5 * 50_000_000)
    clip = rosbag.open_bag(directory)
    assert clip.frame_count in (0, 10)
    assert len(list(clip.frames())) == 10


def test_bad_foxglove_messages_are_one_line_errors(tmp_path, looming):
    """Bytes that are no foxglove message of the type, or Foxglove's images in another
    encoding than protobuf: refused in one line, exit 2, the reason named."""
    pytest.importorskip("foxglove", reason="the 'ros' extra is not installed")
    from foxglove.messages import CompressedImage, RawImage

    h, w = looming.frames[0].shape
    good = RawImage(timestamp=fox_stamp(0), width=w, height=h, encoding="mono8", step=w,
                    data=looming.frames[0].tobytes()).encode()

    def bag(name, schema, encoding, message_encoding, payloads):
        return write_channels(tmp_path / name, [("/c", schema, encoding, message_encoding,
                                                 payloads)])

    cut = bag("cut.mcap", "foxglove.RawImage", "protobuf", "protobuf", [good[:-10]])
    assert "does not decode (ProtobufError" in detect_fails(cut)
    wrong = bytearray(good)
    wrong[0] = (1 << 3) | 5  # the timestamp as a fixed32: not a RawImage
    assert "wire type 5" in detect_fails(
        bag("wrong.mcap", "foxglove.RawImage", "protobuf", "protobuf", [bytes(wrong)]))
    short = RawImage(timestamp=fox_stamp(0), width=w, height=h, encoding="mono8", step=w,
                     data=looming.frames[0].tobytes()[:-w]).encode()
    assert "needs" in detect_fails(
        bag("short.mcap", "foxglove.RawImage", "protobuf", "protobuf", [short]))
    as_json = bag("json.mcap", "foxglove.CompressedImage", "jsonschema", "json",
                  [json.dumps({"format": "png", "data": ""}).encode()])
    assert "Foxglove's images are read in protobuf" in detect_fails(as_json)
    depth = CompressedImage(timestamp=fox_stamp(0), format="16UC1; compressedDepth png",
                            data=b"x").encode()
    assert "compressedDepth" in detect_fails(
        bag("depth.mcap", "foxglove.CompressedImage", "protobuf", "protobuf", [depth]))


# --------------------------------------------------------------------------- bad bags


def test_a_chunk_overwritten_in_place_is_found_by_its_crc(tmp_path, looming):
    from mcap.writer import CompressionType

    messages = [raw_message(f, "mono8", i) for i, f in enumerate(looming.frames)]
    bag = write_messages(tmp_path / "plain.mcap", {"/c": (rosbag.IMAGE, messages)},
                         compression=CompressionType.NONE)
    data = bytearray(bag.read_bytes())
    middle = len(data) // 3
    data[middle:middle + 200] = bytes(b ^ 0x5A for b in data[middle:middle + 200])  # pixels
    bag.write_bytes(bytes(data))
    assert "does not match its CRC" in detect_fails(bag)  # not a run on damaged pixels
    # a hand-over bench over the clip: one line and status 2, not a traceback (a review)
    (tmp_path / "labels.json").write_text(json.dumps([{
        "file": bag.name, "collision": False, "fps": 20.0, "frames": len(messages),
        "width": looming.frames[0].shape[1], "height": looming.frames[0].shape[0]}]))
    bench = subprocess.run([sys.executable, "-m", "cli.main", "bench", "--handover", "--clips",
                            str(tmp_path), "--every", "50"], capture_output=True, text=True,
                           timeout=300)
    assert bench.returncode == 2 and "Traceback" not in bench.stderr, bench.stderr
    assert "does not match its CRC" in bench.stderr.strip().splitlines()[-1]

def crafted_bag(path, looming, *chunks, before=()):
    """A bag of one good frame (its schema, channel and message as the third-party writer
    made them) followed by the given chunk records, written record by record (``before``:
    records between the channel and the message)."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import DataEnd, Footer, Header
    from mcap.stream_reader import StreamReader

    good = write_messages(path.with_suffix(".good.mcap"), {"/c": (rosbag.IMAGE, [
        raw_message(looming.frames[0], "mono8")])})
    with open(good, "rb") as fh:
        kept = [r for r in StreamReader(fh).records
                if type(r).__name__ in ("Schema", "Channel", "Message")]
    builder = RecordBuilder()
    Header(profile="ros2", library="test").write(builder)
    message = next(i for i, r in enumerate(kept) if type(r).__name__ == "Message")
    for record in [*kept[:message], *before, *kept[message:], *chunks]:
        record.write(builder)
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    magic = b"\x89MCAP0\r\n"
    path.write_bytes(magic + builder.end() + magic)
    return path


def test_chunks_that_would_fill_the_memory_or_hold_the_reader_are_refused(tmp_path, looming,
                                                                           monkeypatch):
    """A probe: an lz4 chunk without a content size that inflated 13 MB to 3 GiB, a chunk of
    millions of tiny records (5 GB of objects), a chunk of zeros read as millions of empty
    records (minutes); here at a small scale, each refused after the good frame."""
    import lz4.frame
    import zstandard
    from mcap.records import Chunk

    def chunk(compression, data, size):
        return Chunk(compression=compression, data=data, message_start_time=0,
                     message_end_time=0, uncompressed_crc=0, uncompressed_size=size)

    inflating = chunk("lz4", lz4.frame.compress(b"\0" * 2**20, store_size=False), 1000)
    zeros = chunk("zstd", zstandard.ZstdCompressor().compress(b"\0" * 2**20), 2**20)
    tiny = b"\x80" + (4).to_bytes(8, "little") + b"junk"  # a user record of 4 bytes, 13 in all
    many = chunk("", tiny * 200, 13 * 200)
    monkeypatch.setattr(mcap_reader, "MAX_CHUNK_RECORDS", 100)
    for name, bad, says in [("inflating", inflating, "decompresses to more"),
                            ("zeros", zeros, "opcode 0"),
                            ("many", many, "more than 100 records")]:
        bag = crafted_bag(tmp_path / f"{name}.mcap", looming, bad)
        clip = rosbag.BagClip(bag)
        errors = []
        frames = list(clip.frames(lambda reason, message: errors.append(message)))
        assert len(frames) == 1 and len(errors) == 1 and says in errors[0], (name, errors)


def traced_peak(work) -> int:
    """The most memory ``work()`` held at once, in bytes (tracemalloc)."""
    import tracemalloc

    tracemalloc.start()
    try:
        work()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def errors_and_peak(bag) -> tuple[list[str], int]:
    """The messages of what reading ``bag``'s ``/c`` frames reported, and the most memory the
    reading held at once (:func:`traced_peak`)."""
    errors = []

    def read():
        list(rosbag.BagClip(bag, "/c").frames(lambda reason, message: errors.append(message)))

    return errors, traced_peak(read)


def records_chunk(*records):
    """A zstd chunk of the given MCAP records."""
    import zlib

    import zstandard
    from mcap.data_stream import RecordBuilder
    from mcap.records import Chunk

    builder = RecordBuilder()
    for record in records:
        record.write(builder)
    data = builder.end()
    return Chunk(compression="zstd", data=zstandard.ZstdCompressor().compress(data),
                 message_start_time=0, message_end_time=0, uncompressed_crc=zlib.crc32(data),
                 uncompressed_size=len(data))


def test_a_message_larger_than_any_picture_is_refused_before_it_is_copied(tmp_path, looming,
                                                                          monkeypatch):
    """A probe: an 18 KB bag whose "64x64" Image held 500 MiB of zeros took 1.67 GB, the chunk
    and two copies of the message at once (the record's, the decoder's). Here at a small scale
    (the bound lowered to 1 MiB, a message of 8 MiB): one copy, the chunk's, and the message is
    a bad one, skipped."""
    monkeypatch.setattr(mcap_reader, "MAX_MESSAGE_BYTES", 2**20, raising=False)
    size = 8 * 2**20
    bomb = {**raw_message(looming.frames[1][:64, :64], "mono8", 1), "data": bytes(size)}
    messages = [raw_message(f, "mono8", i) for i, f in enumerate(looming.frames[:10])]
    bag = write_messages(tmp_path / "bomb.mcap", {"/c": (rosbag.IMAGE, [
        messages[0], bomb, *messages[2:]])})
    errors, frames = [], []

    def read():
        clip = rosbag.BagClip(bag)
        frames.extend(clip.frames(lambda reason, message: errors.append((reason, message))))

    peak = traced_peak(read)
    assert peak < 1.5 * size, peak  # the decompressed chunk; the old reader held three copies
    assert len(frames) == 9 and len(errors) == 1, errors
    assert errors[0][0] == "bad-message" and f"message 1 is {size + 48} bytes" in errors[0][1]


def test_a_chunk_of_more_records_than_its_compressed_bytes_can_hold_is_refused(tmp_path,
                                                                               looming):
    """A probe: a 15 KB bag of five chunks of a million empty messages each, on another topic,
    took 68 s to read (three passes of 5 million records). A chunk holds at most
    RECORDS_PER_COMPRESSED_BYTE records per compressed byte (and a thousand)."""
    from mcap.records import Message

    empty = Message(channel_id=99, log_time=START_NS, publish_time=START_NS, sequence=0,
                    data=b"")
    junk = records_chunk(*[empty] * 50_000)  # 1.5 MB of records, some 200 bytes compressed
    assert len(junk.data) * 4 + 1000 < 50_000
    assert mcap_reader._chunk_record_limit(junk) == 4 * len(junk.data) + 1000  # not looser
    bag = crafted_bag(tmp_path / "junk.mcap", looming, junk)
    errors = []
    frames = list(rosbag.BagClip(bag).frames(lambda reason, message: errors.append(message)))
    assert len(frames) == 1 and len(errors) == 1 and "bytes compressed" in errors[0], errors
    # before the topic's first message: the damage is named, not "holds no message"
    bag = crafted_bag(tmp_path / "junk_first.mcap", looming, before=[junk])
    assert rosbag.bag_topics(bag)["/c"].count is None  # not known: the damage came first
    line = detect_fails(bag)
    assert "truncated or corrupt bag after 0 messages" in line and "bytes compressed" in line


def test_index_records_are_skipped_unparsed_in_a_read_through(tmp_path, looming):
    """A probe: a bag without a summary holding a 64 MiB MessageIndex record took 534 MB and
    16 s (the mcap library makes a tuple of each of its 4 million entries). A read-through
    parses only the records it uses."""
    from mcap.records import MessageIndex

    index = MessageIndex(channel_id=1, records=[(START_NS, 0)] * 2**19)  # 8 MiB
    bag = crafted_bag(tmp_path / "index.mcap", looming, index)
    frames = []
    peak = traced_peak(lambda: frames.extend(rosbag.BagClip(bag).frames()))
    assert len(frames) == 1 and peak < 4 * 2**20, peak  # the old reader: 70 MB


def test_a_summary_of_many_chunk_indexes_is_read_once_and_kept_small(tmp_path, looming,
                                                                    monkeypatch):
    """A probe: a 60 MB summary of 723k chunk indexes became 605 MB of objects, read on each of
    the three passes over the bag (47 s). The chunk indexes are kept as offsets per channel,
    the summary read once."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import Chunk, ChunkIndex, DataEnd, Footer, Header
    from mcap.stream_reader import StreamReader

    good = write_messages(tmp_path / "good.mcap", {"/c": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(looming.frames[:5])])})
    with open(good, "rb") as fh:
        records = list(StreamReader(fh, emit_chunks=True).records)
    schemas = [r for r in records if type(r).__name__ == "Schema"][:3]
    channel = next(r for r in records if type(r).__name__ == "Channel")
    chunk = next(r for r in records if isinstance(r, Chunk))
    builder = RecordBuilder()
    Header(profile="ros2", library="test").write(builder)
    for record in schemas + [channel]:
        record.write(builder)
    start = 8 + builder.count  # after the magic
    chunk.write(builder)
    DataEnd(data_section_crc=0).write(builder)
    summary_start = 8 + builder.count
    for record in schemas + [channel]:
        record.write(builder)
    for _ in range(50_000):  # 3.6 MB, all pointing at the one chunk
        ChunkIndex(message_start_time=0, message_end_time=0, chunk_start_offset=start,
                   chunk_length=0, message_index_offsets={channel.id: 0},
                   message_index_length=0, compression="zstd", compressed_size=0,
                   uncompressed_size=0).write(builder)
    Footer(summary_start=summary_start, summary_offset_start=0, summary_crc=0).write(builder)
    bag = tmp_path / "indexes.mcap"
    bag.write_bytes(b"\x89MCAP0\r\n" + builder.end() + b"\x89MCAP0\r\n")
    parsed = []
    original = getattr(mcap_reader, "_parse_summary", None)
    monkeypatch.setattr(mcap_reader, "_parse_summary",
                        lambda *a: parsed.append(1) or original(*a), raising=False)
    frames = []
    peak = traced_peak(lambda: frames.extend(rosbag.BagClip(bag).frames()))
    assert peak < 8 * 2**20, peak  # the section read, its offsets; the old reader: 40 MB
    assert len(frames) == 5 and len(parsed) == 1


def test_a_file_of_zeros_after_its_records_is_refused_at_once(tmp_path, looming):
    bag = crafted_bag(tmp_path / "zeros.mcap", looming)
    data = bag.read_bytes()
    bag.write_bytes(data[:-len(b"\x89MCAP0\r\n") - 40] + b"\0" * 2**24)  # cut, then 16 MiB
    errors = []
    frames = list(rosbag.BagClip(bag).frames(lambda reason, message: errors.append(message)))
    assert len(frames) == 1 and "opcode 0" in errors[0]


def test_images_are_decoded_by_the_types_own_definition_not_the_bags_text(tmp_path, looming):
    """The bag's schema text is not trusted (a probe's 1.9 KB bag whose "Image" declared an
    array of a million one-byte structures took 4.9 GB to decode): an Image whose text names
    its fields otherwise, on the same bytes, reads as the Image it is."""
    renamed = rosbag.IMAGE_MSGDEF.replace("uint32 height\nuint32 width", "uint32 rows\nuint32 cols")
    messages = []
    for i, frame in enumerate(looming.frames[:5]):
        m = raw_message(frame, "mono8", i)
        m["rows"], m["cols"] = m.pop("height"), m.pop("width")
        messages.append(m)
    path = tmp_path / "renamed.mcap"
    with open(path, "wb") as fh, Ros2Writer(fh) as writer:
        schema = writer.register_msgdef(rosbag.IMAGE, renamed)
        for i, m in enumerate(messages):
            ns = START_NS + i * 50_000_000
            writer.write_message("/c", schema, m, log_time=ns, publish_time=ns, sequence=i)
    frames = [image for _, image in rosbag.BagClip(path).frames()]
    assert len(frames) == 5 and all(np.array_equal(a, b) for a, b in zip(frames, looming.frames))


def detect_fails(*args, process: bool = False) -> str:
    code, _, err = run_detect(*args, process=process)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="module")
def two_topics(tmp_path_factory, looming):
    path = tmp_path_factory.mktemp("bags") / "two.mcap"
    messages = [raw_message(f, "mono8", i) for i, f in enumerate(looming.frames)]
    return write_messages(path, {"/front/image": (rosbag.IMAGE, messages),
                                 "/rear/image": (rosbag.IMAGE, messages),
                                 "/chatter": ("std_msgs/msg/String", [{"data": "hi"}])})


def test_several_image_topics_without_a_topic_is_an_error_listing_them(two_topics):
    line = detect_fails(two_topics, process=True)
    assert "/front/image" in line and "/rear/image" in line and "--topic" in line
    assert "/chatter" not in line


@pytest.mark.parametrize("topic, words", [("/side/image", "no topic"),
                                          ("/chatter", "std_msgs/msg/String")])
def test_a_missing_or_non_image_topic_is_an_error(two_topics, topic, words):
    assert words in detect_fails(two_topics, "--topic", topic)


def test_a_topic_named_twice_two_ways_must_agree(two_topics):
    """``BAG#/front/image --topic /rear/image`` read the rear camera without a word (a bag
    reader's round)."""
    line = detect_fails(f"{two_topics}#/front/image", "--topic", "/rear/image")
    assert "names the topic /front/image, and the topic given is /rear/image" in line
    assert len(detect_records(f"{two_topics}#/front/image", "--topic", "/front/image")) == len(
        detect_records(two_topics, "--topic", "/front/image"))


def test_an_empty_topic_and_a_bag_without_images_are_errors(tmp_path):
    with open(tmp_path / "empty.mcap", "wb") as fh, Ros2Writer(fh) as writer:
        schema = writer.register_msgdef(rosbag.IMAGE, rosbag.IMAGE_MSGDEF)
        writer._writer.register_channel("/camera/image_raw", "cdr", schema.id)
    assert "holds no message" in detect_fails(tmp_path / "empty.mcap")
    bag = write_messages(tmp_path / "text.mcap", {"/chatter": ("std_msgs/msg/String",
                                                               [{"data": "hi"}])})
    assert "no image topic" in detect_fails(bag)


def test_an_unknown_encoding_is_an_error_for_detect(tmp_path):
    bag = write_messages(tmp_path / "float.mcap", {"/depth": (rosbag.IMAGE, [
        raw_message(np.zeros((40, 40), np.float32), "32FC1")])})
    line = detect_fails(bag)
    assert "32FC1" in line and "/depth" in line


def test_only_the_chunks_holding_the_image_topic_are_decompressed(tmp_path, looming,
                                                                    monkeypatch):
    """A camera beside a bulkier sensor: the other topic's chunks are skipped through the
    summary's chunk index, and the frames are those of the topic alone."""
    path = tmp_path / "sensors.mcap"
    definitions = {rosbag.IMAGE: rosbag.IMAGE_MSGDEF, "std_msgs/msg/String": "string data"}
    frames = looming.frames[:12]
    with open(path, "wb") as fh, Ros2Writer(fh, chunk_size=20_000) as writer:
        schemas = {name: writer.register_msgdef(name, text) for name, text in definitions.items()}
        for index, frame in enumerate(frames):  # in time order, as a recorder writes them
            ns = START_NS + index * 50_000_000
            writer.write_message("/camera", schemas[rosbag.IMAGE],
                                 raw_message(frame, "mono8", index), log_time=ns, publish_time=ns)
            for k in range(4):  # a "scan" of 30 kB, four per frame
                writer.write_message("/scan", schemas["std_msgs/msg/String"],
                                     {"data": "x" * 30_000}, log_time=ns + k, publish_time=ns + k)
    opened = []
    original = mcap_reader._chunk_records
    monkeypatch.setattr(mcap_reader, "_chunk_records",
                        lambda chunk, *rest: opened.append(chunk) or original(chunk, *rest))
    clip = rosbag.BagClip(path, "/camera")
    opened.clear()
    read = [image for _, image in clip.frames()]
    assert len(read) == len(frames)
    assert all(np.array_equal(a, b) for a, b in zip(read, frames))
    with open(path, "rb") as fh:
        total = sum(1 for _ in _all_chunks(fh))
    assert 0 < len(opened) <= len(frames) < total  # at most one chunk per frame (of 48 in all)


def test_a_chunk_index_pointing_at_no_chunk_is_a_corrupt_bag_error(tmp_path, looming):
    import struct

    from mcap.reader import SeekingReader

    bag = write_messages(tmp_path / "ok.mcap", {"/c": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(looming.frames[:12])])},
        chunk_size=20_000)
    data = bytearray(bag.read_bytes())
    with open(bag, "rb") as fh:
        summary = SeekingReader(fh).get_summary()
        footer_start = len(data) - 8 - 20  # footer record: opcode, length, 20 bytes; magic
    last = summary.chunk_indexes[-1].chunk_start_offset
    field = struct.pack("<Q", last)
    at = data.rindex(field, 0, footer_start)  # the last chunk index's chunk_start_offset
    data[at:at + 8] = struct.pack("<Q", last + 100)  # inside the chunk, not at its start
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    with open(broken, "rb") as fh:  # the index now points 100 bytes into the chunk
        assert SeekingReader(fh).get_summary().chunk_indexes[-1].chunk_start_offset == last + 100
    with pytest.raises(SourceError, match="truncated or corrupt"):
        list(rosbag.open_bag(broken).frames())
    line = detect_fails(broken)
    assert "truncated or corrupt" in line


def test_a_summary_over_the_bound_is_not_loaded_and_the_bag_is_read_through(tmp_path, looming,
                                                                            monkeypatch):
    bag = write_messages(tmp_path / "ok.mcap", {"/c": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(looming.frames[:12])])},
        chunk_size=20_000)
    loaded = []
    original = mcap_reader._parse_summary
    monkeypatch.setattr(mcap_reader, "_parse_summary",
                        lambda *a, **k: loaded.append(1) or original(*a, **k))
    monkeypatch.setattr(mcap_reader, "MAX_SUMMARY_BYTES", 64)  # smaller than this bag's summary
    read = [image for _, image in rosbag.open_bag(bag).frames()]
    assert not loaded and len(read) == 12
    assert all(np.array_equal(a, b) for a, b in zip(read, looming.frames[:12]))
    monkeypatch.setattr(mcap_reader, "MAX_SUMMARY_BYTES", 2**20)  # the control
    rosbag.open_bag(bag)
    assert loaded


def test_a_chunk_the_index_lists_twice_is_read_once(tmp_path, looming, monkeypatch):
    bag = write_messages(tmp_path / "ok.mcap", {"/c": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(looming.frames[:12])])},
        chunk_size=20_000)
    original = mcap_reader.bag_summary

    def doubled(fh):
        summary = original(fh)
        if summary is not None:  # the first chunk of each channel listed twice
            summary = dataclasses.replace(summary, chunks={
                channel: offsets + offsets[:1] for channel, offsets in summary.chunks.items()})
        return summary

    monkeypatch.setattr(mcap_reader, "bag_summary", doubled)
    read = [image for _, image in rosbag.open_bag(bag).frames()]
    assert len(read) == 12
    assert all(np.array_equal(a, b) for a, b in zip(read, looming.frames[:12]))


def _all_chunks(fh):
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    return (r for r in StreamReader(fh, emit_chunks=True).records if isinstance(r, Chunk))


@pytest.mark.parametrize("cut", [0.4, 0.97])  # in the messages; in the summary after them
def test_a_cut_bag_is_a_one_line_error_after_the_frames_before_the_cut(tmp_path, looming, cut):
    whole = write_messages(tmp_path / "whole.mcap", {"/c": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(looming.frames)])},
        chunk_size=20_000)  # a few frames per chunk, as a recorder's 768 KiB for larger ones
    data = whole.read_bytes()
    cut_bag = tmp_path / "cut.mcap"
    cut_bag.write_bytes(data[:int(len(data) * cut)])
    jsonl = tmp_path / "out.jsonl"
    line = detect_fails(cut_bag, "--jsonl", jsonl)
    assert "truncated or corrupt" in line and "mcap recover" in line
    records = [json.loads(x) for x in jsonl.read_text().splitlines()]
    assert 0 < len(records) <= len(looming.frames)
    assert (len(records) < len(looming.frames)) == (cut < 0.9)
    assert f"{len(records)} frames before" in line


def test_corrupt_bytes_and_random_files_never_give_a_traceback(tmp_path, looming):
    bag = write_messages(tmp_path / "ok.mcap", {"/c": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(looming.frames[:8])])})
    data = bytearray(bag.read_bytes())
    rng = np.random.default_rng(3)
    for trial in range(6):
        damaged = bytearray(data)
        for offset in rng.integers(8, len(data) - 8, size=20):
            damaged[offset] ^= 0xFF
        path = tmp_path / f"damaged{trial}.mcap"
        path.write_bytes(bytes(damaged))
        try:
            source = open_source(str(path))
            list(source.frames())
        except SourceError as exc:
            assert "\n" not in str(exc) and str(path) in str(exc)
    (tmp_path / "random.mcap").write_bytes(rng.integers(0, 256, 4000, dtype=np.uint8).tobytes())
    assert "not an MCAP file" in detect_fails(tmp_path / "random.mcap")
    assert "no such file" in detect_fails(tmp_path / "missing.mcap")


def test_a_huge_length_field_is_refused_before_it_is_allocated(tmp_path):
    # magic, then a Header record claiming 2**62 bytes
    path = tmp_path / "huge.mcap"
    path.write_bytes(b"\x89MCAP0\r\n" + b"\x01" + (2**62).to_bytes(8, "little") + bytes(64))
    line = detect_fails(path)
    assert "truncated or corrupt" in line


def test_a_missing_extra_is_named_in_one_line(tmp_path, monkeypatch, capsys):
    import asnn.io

    # as if the extra were not installed: mcap cannot be imported, asnn.io.rosbag not yet loaded
    for name in [n for n in sys.modules if n.split(".")[0] in ("mcap", "mcap_ros2")]:
        monkeypatch.setitem(sys.modules, name, None)
    monkeypatch.delitem(sys.modules, "asnn.io.rosbag")
    monkeypatch.delattr(asnn.io, "rosbag")
    write_messages(tmp_path / "run.mcap", {})
    assert main(["detect", str(tmp_path / "run.mcap")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "asnn[ros]" in err
    # a bag folder with an output: its files, looked for before the bag opens, did not say so
    (tmp_path / "bag").mkdir()
    (tmp_path / "run.mcap").rename(tmp_path / "bag" / "run.mcap")
    (tmp_path / "bag" / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  relative_file_paths: [run.mcap]\n")
    assert main(["detect", str(tmp_path / "bag"), "--jsonl", str(tmp_path / "out.jsonl")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "asnn[ros]" in err


# --------------------------------------------------------------------------- eval, camera

def test_eval_reads_bags_in_a_labelled_folder_and_a_label_names_the_topic(tmp_path, looming,
                                                                          two_topics, capsys):
    clips = tmp_path / "clips"
    clips.mkdir()
    (clips / "two.mcap").write_bytes(two_topics.read_bytes())
    label = looming.label("two.mcap")
    (clips / "labels.json").write_text(json.dumps([{**label, "topic": "/rear/image"}]))
    out = tmp_path / "out"
    assert main(["eval", str(clips), "--models", "asnn", "--out", str(out), "--no-plots",
                 "--early-tolerance", "0"]) == 0
    # its progress line names the camera, as the report does (it named the file alone)
    assert f"eval: asnn two.mcap#/rear/image, {len(looming.frames)} frames" in \
        capsys.readouterr().err
    results = json.loads((out / "results.json").read_text())
    assert not results["errors"]
    assert results["detectors"]["asnn"]["clips"][0]["outcome"] == "hit"
    assert len((out / "results" / "asnn" / "two.rear_image.jsonl").read_text().splitlines()) \
        == len(looming.frames)
    # two cameras of one bag are two clips: their own results files, rows and outcomes
    quiet = {**label, "topic": "/front/image", "collision": False, "onset_frame": None,
             "contact_frame": None}
    (clips / "labels.json").write_text(json.dumps([{**label, "topic": "/rear/image"}, quiet]))
    results = evaluate_clips(clips, tmp_path / "both", detectors=["asnn"], plots=False,
                             early_tolerance_s=0.0)
    scores = results["detectors"]["asnn"]["clips"]
    assert [(c["clip"], c["outcome"]) for c in scores] == [("two.mcap#/rear/image", "hit"),
                                                          ("two.mcap#/front/image", "false")]
    assert sorted(p.name for p in (tmp_path / "both" / "results" / "asnn").iterdir()) == [
        "two.front_image.jsonl", "two.rear_image.jsonl"]
    (clips / "labels.json").write_text(json.dumps([label]))  # two image topics, none named
    with pytest.raises(ValueError, match="/front/image.*the entry's topic names it"):
        evaluate_clips(clips, tmp_path / "out2", detectors=["asnn"], plots=False)
    assert not (tmp_path / "out2").exists()  # refused before anything ran


def test_eval_scores_a_bag_whose_stamps_go_back_with_each_frame_in_its_place(tmp_path, looming):
    """A label counts a bag's frames in the topic: a frame whose stamp goes back keeps its place
    (taken at the latest frame's time), and the clip is scored with a warning, not refused."""
    clips = tmp_path / "clips"
    clips.mkdir()
    seconds = [0.05 * i for i in range(len(looming.frames))]
    seconds[5] = seconds[8] = 0.01  # two frames stamped out of order, well before the onset
    stamped_bag(clips / "back.mcap", looming.frames, seconds)
    (clips / "labels.json").write_text(json.dumps([looming.label("back.mcap")]))
    out = tmp_path / "out"
    assert main(["eval", str(clips), "--models", "asnn", "--out", str(out), "--no-plots",
                 "--early-tolerance", "0"]) == 0
    results = json.loads((out / "results.json").read_text())
    assert not results["errors"]
    assert results["warnings"] == ["back.mcap: 2 frames whose header stamp goes back, taken at "
                                   "the latest frame's time"]
    assert results["detectors"]["asnn"]["clips"][0]["outcome"] == "hit"
    records = (out / "results" / "asnn" / "back.jsonl").read_text().splitlines()
    assert len(records) == len(looming.frames)
    assert "stamped out of order" in (out / "report.md").read_text()
    # the held-out evaluation reads the clip the same way, and says so too
    held = tmp_path / "held"
    assert main(["eval", str(clips), "--held-out", "--cases", "nearmiss-disk-dark-right",
                 "--out", str(held)]) == 0
    assert results["warnings"][0] in json.loads((held / "held_out.json").read_text())["warnings"]


def test_camera_skips_and_counts_bad_messages_and_a_cut_without_stopping(tmp_path, looming):
    from service.camera import SourceRejections

    messages = [raw_message(f, "mono8", i) for i, f in enumerate(looming.frames[:10])]
    messages[3] = raw_message(np.zeros((4, 4), np.float32), "32FC1", 3)
    messages[6]["data"] = messages[6]["data"][:-5]  # short data
    bag = write_messages(tmp_path / "bad.mcap", {"/c": (rosbag.IMAGE, messages)},
                         chunk_size=20_000)
    rejections = SourceRejections("r1")
    frames = list(open_source(str(bag), on_error=rejections).timed_frames())
    assert [round(t, 2) for t, _ in frames] == [0.0, 0.05, 0.1, 0.2, 0.25, 0.35, 0.4, 0.45]
    assert rejections.counts == {"unknown-encoding": 1, "bad-pixels": 1}
    data = bag.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[:int(len(data) * 0.8)])
    cut = SourceRejections("r1")
    list(open_source(str(tmp_path / "cut.mcap"), on_error=cut).frames())
    assert cut.counts["corrupt-bag"] == 1


def test_camera_replays_a_bag_at_its_recorded_pace(zenoh_net, tmp_path, looming):
    from service.camera import publish_frames

    stamps = [0.0, 0.05, 0.35, 0.4, 0.45]  # a 0.3 s pause in the recording
    messages = []
    for i, s in enumerate(stamps):
        m = raw_message(looming.frames[i], "mono8")
        ns = START_NS + round(s * 1e9)
        m["header"]["stamp"] = {"sec": ns // 10**9, "nanosec": ns % 10**9}
        messages.append(m)
    bag = write_messages(tmp_path / "pace.mcap", {"/c": (rosbag.IMAGE, messages)})
    source = open_source(f"{bag}#/c")
    start = time.monotonic()
    published = publish_frames(zenoh_net.spoke(), "r1", source, wait=0.0, preview_hz=0)
    # a lower bound only (a busy machine adds delay): 5 frames at the nominal 20 fps would take
    # 0.2 s; the recorded pace, pause included, takes 0.45 s
    assert published == len(stamps) and time.monotonic() - start >= 0.44


def stamped_bag(path, frames, seconds) -> str:
    """A bag of mono8 ``frames`` whose header stamps are ``seconds`` after START_NS."""
    return ns_bag(path, frames, [START_NS + round(s * 1e9) for s in seconds])


def ns_bag(path, frames, stamps) -> str:
    """A bag of mono8 ``frames`` whose header stamps are ``stamps`` (ns since the epoch)."""
    messages = []
    for frame, ns in zip(frames, stamps):
        m = raw_message(frame, "mono8")
        m["header"]["stamp"] = {"sec": ns // 10**9, "nanosec": ns % 10**9}
        messages.append(m)
    return str(write_messages(path, {"/c": (rosbag.IMAGE, messages)}))


@pytest.mark.parametrize("threads", [[], ["--threads", "1"]])  # in turn; reading ahead
def test_a_header_stamp_that_goes_back_is_taken_at_the_latest_time_with_a_warning(
        tmp_path, looming, capsys, threads):
    """A real robot's bag carries the odd frame out of order: detect takes it at the latest
    frame's time, says so, and goes on, with a result for every frame (CONTRACT.md); the
    reader alone (without a handler) still refuses it."""
    bag = stamped_bag(tmp_path / "back.mcap", looming.frames,
                      [0.0, 0.05, 0.1, 0.02, *(0.15 + 0.05 * i for i in range(21))])
    with pytest.raises(SourceError, match="message 3: its header stamp is 0.08 s before"):
        list(rosbag.open_bag(bag).frames())
    out = tmp_path / "out.jsonl"
    assert main(["detect", bag, "--jsonl", str(out), *threads]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2, err
    assert "message 3: its header stamp is 0.08 s" in err[0]
    assert err[0].endswith("taken at the latest frame's time")
    assert err[1].startswith("asnn detect: 25 frames, ")
    assert err[1].endswith(", 1 taken at the latest frame's time (header stamp before an "
                           "earlier frame's)")
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["frame"] for r in records] == list(range(25))
    assert [r["t"] for r in records[:5]] == [0.0, 0.05, 0.1, 0.1, 0.15]  # never back


def test_stamps_that_go_back_now_and_then_are_named_five_times_then_counted(tmp_path, looming,
                                                                            capsys):
    frames = [looming.frames[i % len(looming.frames)] for i in range(160)]
    seconds = [0.05 * i for i in range(160)]
    late = range(20, 160, 26)  # one frame in 26 stamped 0.2 s early: 6 of them, 4 in 100
    for i in late:
        seconds[i] -= 0.2
    bag = stamped_bag(tmp_path / "jitter.mcap", frames, seconds)
    out = tmp_path / "out.jsonl"
    assert main(["detect", bag, "--model", "lgmd1", "--jsonl", str(out)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert all("taken at the latest frame's time" in line for line in err[:5])
    assert "further frames whose stamp goes back are taken" in err[5]
    assert len(err) == 7 and err[-1].startswith("asnn detect: 160 frames, ")
    assert err[-1].endswith(", 6 taken at the latest frame's time (header stamp before an "
                            "earlier frame's)")
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["frame"] for r in records] == list(range(160))
    assert all(b["t"] >= a["t"] for a, b in zip(records, records[1:]))
    assert [records[i]["t"] for i in late] == [records[i - 1]["t"] for i in late]


@pytest.mark.parametrize("threads", [[], ["--threads", "1"]])  # in turn; reading ahead
def test_stamps_that_keep_going_back_stop_detect_with_one_error(tmp_path, looming, capsys,
                                                                threads):
    """Stamps that keep going back, yet never as a clock reset (two clocks interleaved on one
    topic: each frame going back alone), are no odd frame out of order: holding them all at
    the last good time would stop the clock. The run stops once the fifth within 100 frames
    can no longer be the start of a clock reset (two frames on), the frames before written."""
    seconds = [0.05 * i - (10 if i > 10 and i % 2 else 0) for i in range(25)]
    bag = stamped_bag(tmp_path / "interleaved.mcap", looming.frames, seconds)
    out = tmp_path / "out.jsonl"
    assert main(["detect", bag, "--jsonl", str(out), *threads]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 7
    assert all("taken at the latest frame's time" in line for line in err[:5])
    assert "message 19" in err[4] and "further frames whose stamp goes back" in err[5]
    assert "message 19" in err[6] and "5 of the last 100 frames read went back" in err[6]
    assert "neither the odd stamp out of order nor a clock reset" in err[6]
    assert "results written for the 21 frames before" in err[6]
    assert len(out.read_text().splitlines()) == 21


def test_odd_stamps_then_a_clock_reset_do_not_stop_detect(tmp_path, looming, capsys):
    """Three odd frames out of order, then a camera's clock reset: its first two frames go
    back too, which made five within 100 frames and stopped the run before the reset's third
    frame showed what they were (until 2026-11-30)."""
    seconds = reset_seconds(30, 20, 3600.0)
    for i in (5, 9, 13):
        seconds[i] -= 0.2
    bag = stamped_bag(tmp_path / "odd-then-reset.mcap", looming.frames, seconds)
    out = tmp_path / "out.jsonl"
    assert main(["detect", bag, "--jsonl", str(out)]) == 0
    err = capsys.readouterr().err
    assert "message 22: clock reset" in err and "frames read went back" not in err
    assert err.strip().splitlines()[-1].endswith(
        ", 5 taken at the latest frame's time (header stamp before an earlier frame's), "
        "1 clock reset (timed on from the latest frame's time)")
    assert len(out.read_text().splitlines()) == 30
    # without the reset, the same five frames going back within 100 frames stop the run,
    # at the end of the bag at the latest
    seconds = [0.05 * i for i in range(22)]
    for i in (5, 9, 13, 20, 21):
        seconds[i] -= 0.2 if i < 20 else 10.0
    bag = stamped_bag(tmp_path / "odd.mcap", looming.frames, seconds)
    assert main(["detect", bag, "--jsonl", str(out)]) == 2
    assert "5 of the last 100 frames read went back" in capsys.readouterr().err


# --------------------------------------------------------------------------- clock resets

def reset_seconds(count: int, at: int, jump: float) -> list[float]:
    """Stamps 0.05 s apart whose clock goes back ``jump`` seconds at frame ``at``."""
    return [0.05 * i - (jump if i >= at else 0.0) for i in range(count)]


@pytest.mark.parametrize("threads", [[], ["--threads", "1"]])  # in turn; reading ahead
@pytest.mark.parametrize("to_zero", [False, True])
def test_a_camera_clock_reset_mid_bag_is_re_based_and_detect_goes_on(tmp_path, looming, capsys,
                                                                     threads, to_zero):
    """A driver restart resets the camera's clock (back an hour, or to near zero) and its
    stamps advance from there: the rest of the bag is a new timeline. Detect gives every frame
    its record, ``t`` going on from the latest frame's with the recorded spacing, and warns of
    the reset once; no stop."""
    stamps = [START_NS + round(s * 1e9) for s in reset_seconds(25, 12, 0.0)]
    jump = stamps[12] - 1_000_000_000 if to_zero else 3600 * 10**9  # to 1 s after the epoch
    stamps[12:] = [ns - jump for ns in stamps[12:]]
    bag = ns_bag(tmp_path / "reset.mcap", looming.frames, stamps)
    out = tmp_path / "out.jsonl"
    assert main(["detect", bag, "--jsonl", str(out), *threads]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    back = f"{(jump - 50_000_000) / 1e9:.3f}".rstrip("0").rstrip(".")  # from 0.55 to 0.6 - jump
    assert len(err) == 4, err
    assert all("taken at the latest frame's time" in line for line in err[:2])
    assert "message 14: clock reset: the header stamps went back " + back + " s" in err[2]
    assert err[3].endswith(", 2 taken at the latest frame's time (header stamp before an "
                           "earlier frame's), 1 clock reset (timed on from the latest frame's "
                           "time)")
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["frame"] for r in records] == list(range(25))
    times = [r["t"] for r in records]
    assert all(b >= a for a, b in zip(times, times[1:]))
    # the two frames before the reset held at the latest time; from the third, the new stamps'
    # spacing, going on from there (the run's first stamp at the latest frame's time)
    assert times[:14] == pytest.approx([0.05 * i for i in range(12)] + [0.55, 0.55])
    assert times[14:] == pytest.approx([0.55 + 0.05 * k for k in range(2, 13)])


def test_a_stamp_far_ahead_then_normal_frames_is_re_based_on_them(tmp_path, looming, capsys):
    """One frame stamped an hour ahead makes every later frame look late: they are a new
    timeline after CLOCK_RESET_FRAMES of them, timed on their own spacing from the latest
    frame's time (that frame's own, which was taken before the ones after it showed it wrong)."""
    seconds = reset_seconds(25, 99, 0.0)
    seconds[10] = 3600.0
    bag = stamped_bag(tmp_path / "ahead.mcap", looming.frames, seconds)
    out = tmp_path / "out.jsonl"
    assert main(["detect", bag, "--jsonl", str(out)]) == 0
    err = capsys.readouterr().err
    assert "message 13: clock reset: the header stamps went back 3599.45 s" in err
    assert "frames read went back" not in err
    times = [json.loads(line)["t"] for line in out.read_text().splitlines()]
    assert len(times) == 25 and all(b >= a for a, b in zip(times, times[1:]))
    assert times[10:13] == [3600.0] * 3  # the frame ahead, then two held at its time
    assert times[13:] == pytest.approx([3600.0 + 0.05 * k for k in range(2, 14)])


def test_the_reader_re_bases_only_on_frames_in_a_row_that_advance(tmp_path, looming):
    """Two frames in a row out of order (CLOCK_RESET_FRAMES - 1), or frames going back that do
    not advance among themselves, are held as today, each reported; the reader alone (without
    a handler) still refuses the first frame going back, a reset's included."""
    assert rosbag.CLOCK_RESET_FRAMES == 3  # the bags below are written for it
    seconds = reset_seconds(20, 99, 0.0)
    seconds[5], seconds[6] = 0.1, 0.15  # two in a row, advancing, then past the latest again
    seconds[10], seconds[11], seconds[12] = 0.3, 0.25, 0.2  # three in a row, going back
    bag = stamped_bag(tmp_path / "odd.mcap", looming.frames, seconds)
    reasons = []
    frames = list(open_source(bag, on_error=lambda r, m: reasons.append(r),
                              hold_backwards=True).timed_frames())
    assert reasons == ["stamp-backwards"] * 5
    assert [t for t, _ in frames] == pytest.approx(
        [0.0, 0.05, 0.1, 0.15, 0.2, 0.2, 0.2, 0.35, 0.4, 0.45, 0.45, 0.45, 0.45,
         *(0.05 * i for i in range(13, 20))])
    reset = stamped_bag(tmp_path / "reset.mcap", looming.frames, reset_seconds(25, 12, 3600))
    with pytest.raises(SourceError, match="message 12: its header stamp is 3599.95 s before"):
        list(rosbag.open_bag(reset).frames())


def test_after_a_reset_stamps_are_checked_against_the_new_timeline(tmp_path, looming):
    """The odd frame out of order after a reset goes back from the new clock's latest stamp:
    held there, and the frames after it go on."""
    seconds = reset_seconds(25, 10, 3600)
    seconds[18] = seconds[15]  # before the new latest (seconds[17])
    bag = stamped_bag(tmp_path / "reset.mcap", looming.frames, seconds)
    reasons = []
    frames = list(open_source(bag, on_error=lambda r, m: reasons.append(r),
                              hold_backwards=True).timed_frames())
    assert reasons == ["stamp-backwards", "stamp-backwards", "clock-reset", "stamp-backwards"]
    times = [t for t, _ in frames]
    assert times[10:13] == pytest.approx([0.45, 0.45, 0.55])
    assert times[17:20] == pytest.approx([0.8, 0.8, 0.9])  # 18 held at 17's time
    assert times[-1] == pytest.approx(0.45 + 0.05 * 14)


def test_eval_lists_a_bag_s_clock_reset_in_its_warnings(tmp_path, looming):
    clips = tmp_path / "clips"
    clips.mkdir()
    count = len(looming.frames)
    stamped_bag(clips / "reset.mcap", looming.frames, reset_seconds(count, 12, 3600))
    (clips / "labels.json").write_text(json.dumps([looming.label("reset.mcap")]))
    out = tmp_path / "out"
    assert main(["eval", str(clips), "--models", "lgmd1", "--out", str(out), "--no-plots"]) == 0
    results = json.loads((out / "results.json").read_text())
    assert not results["errors"]
    first, reset = results["warnings"]
    assert first == "reset.mcap: 2 frames whose header stamp goes back, taken at the latest " \
                    "frame's time"
    assert reset.startswith("reset.mcap: 1 clock reset, timed on from the latest frame's time; "
                            "the first: ")
    assert "message 14: clock reset: the header stamps went back 3599.95 s" in reset
    assert len((out / "results" / "lgmd1" / "reset.jsonl").read_text().splitlines()) == count


def test_the_camera_skips_at_most_the_frames_before_a_reset_and_logs_it(tmp_path, looming,
                                                                      caplog):
    """The camera's source: the frames of the run before the reset are skipped as rejections,
    the reset is logged but not counted as rejected, and every frame after it is yielded."""
    from service.camera import SourceRejections

    bag = stamped_bag(tmp_path / "reset.mcap", looming.frames, reset_seconds(25, 12, 3600))
    rejections = SourceRejections("r1")
    with caplog.at_level("WARNING", logger="asnn.camera"):
        frames = list(open_source(bag, on_error=rejections).timed_frames())
    assert len(frames) == 25 - (rosbag.CLOCK_RESET_FRAMES - 1)
    assert rejections.counts == {"stamp-backwards": rosbag.CLOCK_RESET_FRAMES - 1}
    assert rejections.resets == 1
    assert rejections.summary() == (f"rejected: stamp-backwards {rosbag.CLOCK_RESET_FRAMES - 1}"
                                    "; clock resets (re-based): 1")
    assert any("camera r1: " in r.message and "message 14: clock reset" in r.message
               and "rejected" not in r.message for r in caplog.records)
    times = [t for t, _ in frames]
    assert times == pytest.approx([0.05 * i for i in range(12)]
                                  + [0.55 + 0.05 * k for k in range(2, 13)])


def test_the_camera_publishes_past_a_reset_at_the_recorded_pace(zenoh_net, tmp_path, looming,
                                                               monkeypatch):
    """After a reset the camera publishes the rest of the bag at the new stamps' pace: its
    waits between frames (on a clock of the test's, so no real time passes) are the recorded
    spacing, neither the jump (a long sleep) nor none (a burst)."""
    import threading
    import types

    from service import camera

    clock = [1000.0]

    class Stop(threading.Event):
        waits: list = []

        def wait(self, timeout=None):
            self.waits.append(timeout)
            clock[0] += timeout
            return False

    monkeypatch.setattr(camera, "time", types.SimpleNamespace(
        monotonic=lambda: clock[0], time=time.time, sleep=time.sleep))
    bag = stamped_bag(tmp_path / "reset.mcap", looming.frames, reset_seconds(25, 12, 3600))
    source = open_source(bag, on_error=camera.SourceRejections("r1"))
    stop = Stop()
    published = camera.publish_frames(zenoh_net.spoke(), "r1", source, wait=0.0, preview_hz=0,
                                      stop=stop)
    assert published == 25 - (rosbag.CLOCK_RESET_FRAMES - 1)
    # 0.1 s to the frame after the reset: from the latest frame's stamp to the new clock's
    # third (its first at the latest frame's time)
    assert stop.waits == pytest.approx([0.05] * 11 + [0.1] + [0.05] * 10)


def test_after_a_reset_a_frame_with_an_unset_stamp_is_held_at_the_latest_time(tmp_path,
                                                                               looming):
    """A stamp left unset (zero) takes the recorder's log time, which is not the new clock's
    after a reset: such a frame is held at the latest frame's time, and the frames after it go
    on the new timeline."""
    stamps = [START_NS + round(s * 1e9) for s in reset_seconds(25, 10, 3600)]
    stamps[20] = 0
    bag = ns_bag(tmp_path / "reset.mcap", looming.frames, stamps)
    reasons = []
    times = [t for t, _ in open_source(bag, on_error=lambda r, m: reasons.append(r),
                                       hold_backwards=True).timed_frames()]
    assert reasons == ["stamp-backwards", "stamp-backwards", "clock-reset", "stamp-unset"]
    assert times[20] == pytest.approx(times[19])
    assert times[21] == pytest.approx(times[19] + 0.1)


def unset_stamps_bag(path, frames, unset=range(10, 13)) -> str:
    """``frames`` stamped 100 s after their log time (another clock, as in simulated time) but
    for those numbered in ``unset``, left unset (zero): their log time is no stand-in."""
    stamps = [START_NS + round((100 + 0.05 * i) * 1e9) for i in range(len(frames))]
    for i in unset:
        stamps[i] = 0
    return ns_bag(path, frames, stamps)


def test_a_frame_with_an_unset_stamp_held_at_the_latest_time_is_reported(tmp_path, looming):
    """A trial with odd stamps: a stamp left unset among header stamps, whose log time is far
    from the frames' times, was held at the latest frame's time without a word (the stamps
    going back and the clock resets are reported). It is reported as ``stamp-unset``, kept,
    counted by BackwardStamps; without a handler every frame is still read."""
    bag = unset_stamps_bag(tmp_path / "unset.mcap", looming.frames)
    reports = []
    frames = list(open_source(bag, on_error=lambda r, m: reports.append((r, m)),
                              hold_backwards=True).timed_frames())
    assert [r for r, _ in reports] == ["stamp-unset"] * 3
    assert "message 10: its header stamp is unset (0) and its log time is 99.95 s before the " \
           "latest frame's time: held at the latest frame's time" in reports[0][1]
    times = [t for t, _ in frames]
    assert times[9:14] == pytest.approx([0.45, 0.45, 0.45, 0.45, 0.65])
    alone = [t for t, _ in rosbag.open_bag(bag).frames()]  # a report, no error
    assert alone == pytest.approx(times)
    stamps = BackwardStamps()
    read = list(open_source(bag, on_error=stamps, hold_backwards=True).timed_frames())
    assert len(read) == len(looming.frames)
    assert stamps.tally == (0, 0, None, 3)


def test_the_camera_publishes_a_frame_with_an_unset_stamp_and_says_how_many(tmp_path, looming,
                                                                           caplog):
    """The camera's exit line says how many frames it held at the latest frame's time, apart
    from its rejections (there are none: every frame is published)."""
    from service.camera import SourceRejections

    bag = unset_stamps_bag(tmp_path / "unset.mcap", looming.frames)
    rejections = SourceRejections("r1")
    with caplog.at_level("WARNING", logger="asnn.camera"):
        frames = list(open_source(bag, on_error=rejections).timed_frames())
    assert len(frames) == len(looming.frames)
    assert rejections.summary() == ("rejected: none; held at the latest frame's time "
                                    "(header stamp unset): 3")
    # the first notice is logged; the other two fall in its 10 s
    assert ["message 10: its header stamp is unset" in r.message for r in caplog.records] == [True]
    # and asnn camera's exit line says so (a mutation probe: the line's wiring was untested)
    from service.demo import free_port

    config = tmp_path / "peer.json5"
    config.write_text("{ scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }")
    caplog.clear()
    with caplog.at_level("INFO", logger="asnn"):
        assert main(["camera", "--robot", "r1", "--source", str(bag), "--fps", "240", "--mode",
                     "peer", "--listen", f"tcp/127.0.0.1:{free_port()}", "--config",
                     str(config)]) == 0
    (line,) = [r.getMessage() for r in caplog.records if "frames published" in r.getMessage()]
    assert "; rejected: none; held at the latest frame's time (header stamp unset): 3; " in line


def test_detect_names_the_frames_with_an_unset_stamp_it_holds(tmp_path, looming, capsys):
    bag = unset_stamps_bag(tmp_path / "unset.mcap", looming.frames)
    out = tmp_path / "out.jsonl"
    assert main(["detect", bag, "--jsonl", str(out)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 4, err
    for line, number in zip(err, (10, 11, 12)):
        assert f"warning: {bag}: /c message {number}: its header stamp is unset (0)" in line
    assert err[3].startswith(f"asnn detect: {len(looming.frames)} frames, ")
    assert err[3].endswith(", 3 taken at the latest frame's time (header stamp unset)")
    assert len(out.read_text().splitlines()) == len(looming.frames)


def test_eval_lists_a_bag_s_frames_with_an_unset_stamp_in_its_warnings(tmp_path, looming):
    clips = tmp_path / "clips"
    clips.mkdir()
    unset_stamps_bag(clips / "unset.mcap", looming.frames)
    (clips / "labels.json").write_text(json.dumps([looming.label("unset.mcap")]))
    out = tmp_path / "out"
    assert main(["eval", str(clips), "--models", "lgmd1", "--out", str(out), "--no-plots"]) == 0
    results = json.loads((out / "results.json").read_text())
    assert not results["errors"]
    assert results["warnings"] == [
        "unset.mcap: 3 frames whose header stamp is unset (0), its log time not the camera's "
        "clock, taken at the latest frame's time"]


def test_the_camera_publishes_a_frame_with_an_unset_stamp_and_logs_it(tmp_path, looming,
                                                                      caplog):
    from service.camera import SourceRejections

    bag = unset_stamps_bag(tmp_path / "unset.mcap", looming.frames)
    rejections = SourceRejections("r1")
    with caplog.at_level("WARNING", logger="asnn.camera"):
        frames = list(open_source(bag, on_error=rejections).timed_frames())
    assert len(frames) == len(looming.frames)
    assert not rejections.counts and rejections.unset == 3
    assert any("camera r1: " in r.message and "message 10: its header stamp is unset" in r.message
               and "rejected" not in r.message for r in caplog.records)


@pytest.mark.parametrize("gap", [1e-6, 2000.0])
def test_a_bag_whose_stamps_no_video_rate_can_hold_is_annotated_at_the_default_rate(
        tmp_path, looming, gap):
    """Stamps microseconds or half an hour apart: the mpeg4 writer takes no such rate, and
    ``--annotate`` failed with OpenCV's own error lines (a bag reader's round)."""
    from asnn.io.video import DEFAULT_FPS, open_video

    bag = stamped_bag(tmp_path / "odd.mcap", looming.frames[:8], [k * gap for k in range(8)])
    out = tmp_path / "odd.mp4"
    assert main(["detect", bag, "--annotate", str(out)]) == 0
    clip = open_video(out)
    assert clip.fps == DEFAULT_FPS and len(list(clip)) == 8


def test_a_summary_too_large_to_keep_is_read_again_rather_than_kept(tmp_path, looming):
    """The summaries of the latest files are kept for the passes over a bag, but one of many
    channels (60,000: some 75 MB) kept four files' for the life of the process (a review)."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Header
    from mcap.stream_reader import StreamReader

    good = write_messages(tmp_path / "good.mcap", {"/c": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(looming.frames[:3])])})
    with open(good, "rb") as fh:
        records = list(StreamReader(fh, emit_chunks=True).records)
    kept = [r for r in records if type(r).__name__ in ("Schema", "Channel")]
    channel = next(r for r in kept if isinstance(r, Channel))
    chunk = next(r for r in records if isinstance(r, Chunk))

    def bag(name, extra_channels):
        builder = RecordBuilder()
        Header(profile="ros2", library="test").write(builder)
        for record in kept:
            record.write(builder)
        start = 8 + builder.count
        chunk.write(builder)
        DataEnd(data_section_crc=0).write(builder)
        summary_start = 8 + builder.count
        for record in kept:
            record.write(builder)
        for i in range(extra_channels):
            Channel(id=1000 + i, schema_id=channel.schema_id, topic=f"/x{i}",
                    message_encoding="cdr", metadata={}).write(builder)
        ChunkIndex(message_start_time=0, message_end_time=0, chunk_start_offset=start,
                   chunk_length=0, message_index_offsets={channel.id: 0},
                   message_index_length=0, compression="zstd", compressed_size=0,
                   uncompressed_size=0).write(builder)
        Footer(summary_start=summary_start, summary_offset_start=0, summary_crc=0).write(builder)
        path = tmp_path / name
        path.write_bytes(b"\x89MCAP0\r\n" + builder.end() + b"\x89MCAP0\r\n")
        return path

    mcap_reader._summaries.clear()
    assert len(list(rosbag.BagClip(bag("small.mcap", 10), "/c").frames())) == 3
    assert len(mcap_reader._summaries) == 1  # kept for the passes over it
    assert len(list(rosbag.BagClip(bag("many.mcap", 10_000), "/c").frames())) == 3
    assert len(mcap_reader._summaries) == 1  # 10 MB of channels: read on each pass instead


def test_a_summary_s_weight_counts_its_chunk_offsets_too():
    from array import array

    offsets = mcap_reader._Summary({}, {}, None, {1: array("Q", range(2**20 + 1))})
    assert offsets.weight() > mcap_reader._SUMMARY_KEPT_BYTES  # 8 MiB of offsets and one
    assert mcap_reader._Summary({}, {}, None, {1: array("Q", range(10))}).weight() == 80


# ---------------------------------------------------------------- mutation-probe additions


def test_a_channel_id_declared_again_for_another_topic_no_longer_gives_the_topics_frames(
        tmp_path, looming):
    """A read-through (no summary) learns the topic's channels from the Channel records as they
    come: an id declared again for another topic stops being the topic's."""
    from mcap.records import Channel, Message

    good = crafted_bag(tmp_path / "probe.mcap", looming)
    with open(good, "rb") as fh:
        channel = next(r for r in mcap_reader.bag_records(fh, "/c") if isinstance(r, Channel))
    frame = raw_message(looming.frames[1], "mono8", 1)
    with open(write_messages(tmp_path / "one.mcap", {"/c": (rosbag.IMAGE, [frame])}), "rb") as fh:
        data = next(r for r in mcap_reader.bag_records(fh, "/c") if isinstance(r, Message)).data
    other = Channel(id=channel.id, schema_id=0, topic="/other", message_encoding="cdr",
                    metadata={})
    message = Message(channel_id=channel.id, sequence=1, log_time=START_NS + 50_000_000,
                      publish_time=START_NS + 50_000_000, data=data)

    def messages(bag):
        with open(bag, "rb") as fh:
            return [r for r in mcap_reader.bag_records(fh, "/c") if isinstance(r, Message)]

    counts = {}
    bag = crafted_bag(tmp_path / "redeclared.mcap", looming, other, message)
    with open(bag, "rb") as fh:
        assert len([r for r in mcap_reader.bag_records(fh, "/c", counts)
                    if isinstance(r, Message)]) == 1
    assert counts == {channel.id: 1}  # the second message is /other's: counted, not read
    control = crafted_bag(tmp_path / "control.mcap", looming, message)
    assert len(messages(control)) == 2


def test_an_oversized_message_outside_chunks_is_skipped_a_piece_at_a_time(tmp_path, looming,
                                                                          monkeypatch):
    """In a read-through, a message of the topic longer than MAX_MESSAGE_BYTES is read past in
    pieces, never whole (as in a chunk, it comes as a bad message)."""
    from mcap.records import Channel, Message

    monkeypatch.setattr(mcap_reader, "MAX_MESSAGE_BYTES", 2**20)
    probe = crafted_bag(tmp_path / "probe.mcap", looming)
    with open(probe, "rb") as fh:
        channel = next(r for r in mcap_reader.bag_records(fh, "/c") if isinstance(r, Channel))
    size = 16 * 2**20
    bomb = Message(channel_id=channel.id, sequence=1, log_time=START_NS + 50_000_000,
                   publish_time=START_NS + 50_000_000, data=bytes(size))
    bag = crafted_bag(tmp_path / "bomb.mcap", looming, bomb)
    del bomb
    records = []

    def read():
        with open(bag, "rb") as fh:
            records.extend(type(r).__name__ for r in mcap_reader.bag_records(fh, "/c"))

    peak = traced_peak(read)
    assert records.count("TooLarge") == 1 and records.count("Message") == 1, records
    assert peak < 4 * 2**20, peak  # a piece of _SKIP_BYTES at a time, not the 16 MiB


def test_a_bag_whose_chunk_indexes_have_no_message_indexes_is_read_through(tmp_path, looming):
    """A writer that stores chunk indexes without message indexes (mcap's IndexType.CHUNK):
    the indexes do not say which channels a chunk holds, so every chunk is read."""
    from mcap.writer import IndexType, Writer

    frames = looming.frames[:12]
    path = tmp_path / "chunk_index_only.mcap"
    with open(path, "wb") as fh:
        writer = Writer(fh, chunk_size=20_000, index_types=IndexType.CHUNK)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(rosbag.IMAGE, "ros2msg",
                                        rosbag.IMAGE_MSGDEF.encode())
        channel = writer.register_channel("/c", "cdr", schema)
        from mcap_ros2._dynamic import serialize_dynamic

        encode = serialize_dynamic(rosbag.IMAGE, rosbag.IMAGE_MSGDEF)[rosbag.IMAGE]
        for index, frame in enumerate(frames):
            ns = START_NS + index * 50_000_000
            writer.add_message(channel, log_time=ns, publish_time=ns,
                               data=encode(raw_message(frame, "mono8", index)), sequence=index)
        writer.finish()
    with open(path, "rb") as fh:
        summary = mcap_reader.bag_summary(fh)
    assert summary.chunk_count > 1 and not summary.indexed
    read = [image for _, image in rosbag.open_bag(path).frames()]
    assert len(read) == len(frames)
    assert all(np.array_equal(a, b) for a, b in zip(read, frames))


def test_a_chunk_that_decompresses_to_less_than_it_declares_is_refused(tmp_path, looming):
    import dataclasses as dc

    from mcap.records import Channel, Message

    probe = crafted_bag(tmp_path / "probe.mcap", looming)
    with open(probe, "rb") as fh:
        records = list(mcap_reader.bag_records(fh, "/c"))
    channel = next(r for r in records if isinstance(r, Channel))
    message = next(r for r in records if isinstance(r, Message))
    later = dc.replace(message, sequence=1, log_time=message.log_time + 50_000_000)
    chunk = records_chunk(later)
    short = dc.replace(chunk, uncompressed_size=chunk.uncompressed_size + 100)  # its CRC holds
    errors = []
    bag = crafted_bag(tmp_path / "short.mcap", looming, short)
    frames = list(rosbag.BagClip(bag, "/c").frames(lambda reason, msg: errors.append(msg)))
    assert len(frames) == 1 and len(errors) == 1 and "decompresses to" in errors[0], errors
    assert channel.topic == "/c"
    good = crafted_bag(tmp_path / "whole.mcap", looming, chunk)  # the control
    assert len(list(rosbag.BagClip(good, "/c").frames())) == 2


def test_a_chunk_index_pointing_at_another_record_is_a_corrupt_bag_error(tmp_path, looming):
    """A chunk index whose offset lands on a record that is not a chunk (here the message index
    after it): a corrupt bag, said in one line, never a traceback."""
    import struct

    from mcap.reader import SeekingReader

    bag = write_messages(tmp_path / "ok.mcap", {"/c": (rosbag.IMAGE, [
        raw_message(f, "mono8", i) for i, f in enumerate(looming.frames[:12])])},
        chunk_size=20_000)
    data = bytearray(bag.read_bytes())
    with open(bag, "rb") as fh:
        index = SeekingReader(fh).get_summary().chunk_indexes[-1]
    start, after = index.chunk_start_offset, index.chunk_start_offset + index.chunk_length
    assert data[after] == 0x07  # the chunk's message index follows it
    at = data.rindex(struct.pack("<Q", start), 0, len(data) - 28)
    data[at:at + 8] = struct.pack("<Q", after)
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    with pytest.raises(SourceError, match="truncated or corrupt"):
        list(rosbag.open_bag(broken).frames())


def test_a_length_field_inside_a_record_is_bounded_too(tmp_path, looming):
    """A chunk record of a few bytes whose data length field claims 8 GiB: refused at that
    field (the record's own length is small: only the bounded file sees it), not read to the
    end of the file, however large the file."""
    import struct

    data = crafted_bag(tmp_path / "probe.mcap", looming).read_bytes()
    tail = 8 + 29 + 13  # magic, footer, data end
    fields = struct.pack("<QQQII", 0, 0, 16, 0, 0) + struct.pack("<Q", 2**33) + b"\0" * 16
    chunk = struct.pack("<BQ", 0x06, len(fields)) + fields
    bag = tmp_path / "field.mcap"
    bag.write_bytes(data[:-tail] + chunk + data[-tail:])
    errors = []
    frames = list(rosbag.BagClip(bag, "/c").frames(lambda reason, message: errors.append(message)))
    assert len(frames) == 1 and len(errors) == 1, errors
    assert f"a record field of {2**33} bytes" in errors[0], errors


def test_an_lz4_chunk_is_decompressed_no_further_than_it_declares(tmp_path, looming):
    """An lz4 frame without a content size decompresses to what its data says: the reader stops
    one byte past the declared size (here 64 MiB of zeros declared as 1000 bytes)."""
    import lz4.frame
    from mcap.records import Chunk

    bomb = Chunk(compression="lz4", data=lz4.frame.compress(bytes(64 * 2**20), store_size=False),
                 message_start_time=0, message_end_time=0, uncompressed_crc=0,
                 uncompressed_size=1000)
    errors, peak = errors_and_peak(crafted_bag(tmp_path / "lz4.mcap", looming, bomb))
    assert len(errors) == 1 and "decompresses to more" in errors[0], errors
    assert peak < 16 * 2**20, peak


def test_a_record_that_runs_past_the_end_of_its_chunk_is_refused(tmp_path, looming):
    import struct
    import zlib

    import zstandard
    from mcap.data_stream import RecordBuilder
    from mcap.records import Chunk, Message

    probe = crafted_bag(tmp_path / "probe.mcap", looming)
    with open(probe, "rb") as fh:
        message = next(r for r in mcap_reader.bag_records(fh, "/c") if isinstance(r, Message))
    builder = RecordBuilder()
    Message(channel_id=message.channel_id, sequence=1, log_time=message.log_time + 50_000_000,
            publish_time=message.log_time + 50_000_000, data=message.data).write(builder)
    data = bytearray(builder.end())
    (length,) = struct.unpack_from("<Q", data, 1)
    struct.pack_into("<Q", data, 1, length + 100)  # the record says it is longer than the chunk
    data = bytes(data)
    chunk = Chunk(compression="zstd", data=zstandard.ZstdCompressor().compress(data),
                  message_start_time=0, message_end_time=0, uncompressed_crc=zlib.crc32(data),
                  uncompressed_size=len(data))
    bag = crafted_bag(tmp_path / "past.mcap", looming, chunk)
    errors = []
    frames = list(rosbag.BagClip(bag, "/c").frames(lambda reason, msg: errors.append(msg)))
    assert len(frames) == 1 and len(errors) == 1 and "runs past its end" in errors[0], errors


def test_a_chunk_declaring_more_than_the_record_bound_uncompressed_is_refused_unread(
        tmp_path, looming):
    import zstandard
    from mcap.records import Chunk

    huge = Chunk(compression="zstd", data=zstandard.ZstdCompressor().compress(b"x" * 1000),
                 message_start_time=0, message_end_time=0, uncompressed_crc=0,
                 uncompressed_size=mcap_reader.MAX_RECORD_BYTES + 1)
    errors, peak = errors_and_peak(crafted_bag(tmp_path / "huge.mcap", looming, huge))
    assert len(errors) == 1 and "uncompressed, more than" in errors[0], errors
    assert peak < 64 * 2**20, peak


def test_the_summaries_kept_are_those_of_the_latest_few_files(tmp_path, looming):
    messages = [raw_message(looming.frames[0], "mono8")]
    for k in range(mcap_reader._SUMMARIES_KEPT + 3):
        bag = write_messages(tmp_path / f"bag{k}.mcap", {"/c": (rosbag.IMAGE, messages)})
        with open(bag, "rb") as fh:
            assert mcap_reader.bag_summary(fh) is not None
    assert len(mcap_reader._summaries) <= mcap_reader._SUMMARIES_KEPT
