"""Annotated frames: the maps drawn over the input frame, at its size."""

import numpy as np

from asnn import ASNN
from asnn.evaluation.perturb import perturb_frame
from asnn.io.visualize import annotate_frame
from asnn.response import Maps, Response
from asnn.stimuli import make_scene
from asnn.stimuli.suite import make_case


def _maps(shape, rig=None):
    zeros = np.zeros(shape, np.float32)
    none = np.zeros(shape, bool)
    return Maps(P=zeros, R=np.zeros((8, *shape), np.float32), V=zeros, phi=zeros, G=zeros,
                M_a=none, M_d=none, G_prime=zeros, rig=rig)


def test_maps_of_a_scaled_down_frame_are_drawn_at_the_frame_s_size():
    # a frame wider than the input-scale stage's 480 px: the model's maps are smaller
    scene = make_scene("looming", size=(640, 120), start=5, stop=30)
    model = ASNN(record_maps=True)
    warned = red = 0
    for i, frame in enumerate(scene.frames):
        response = model.step(frame, i / 20)
        image = annotate_frame(frame, response)  # the first response has no maps: no frame before
        assert image.shape == (*frame.shape, 3)
        warned += response.collision
        inner = image[20:-5, 5:-5]  # inside the warning's border, below the text
        red += bool((inner[..., 2] > inner[..., 1] + 50).any())  # G in red where the disk grows
    assert response.maps.G.shape != frame.shape
    assert warned and red


def test_the_camera_s_rig_is_tinted_where_the_fits_leave_it_out():
    frame = np.full((40, 60), 100, np.uint8)
    rig = np.zeros((20, 30), bool)  # the model saw the frame at half its size
    rig[15:] = True
    image = annotate_frame(frame, Response(0, 0.0, 0.0, 0, 0.0, False, maps=_maps((20, 30), rig)))
    assert (image[30:, :, 0] > image[30:, :, 2]).all()  # cyan: more blue than red
    assert (image[20:30] == 100).all()  # (the frame's text is at the top)
    plain = annotate_frame(frame, Response(0, 0.0, 0.0, 0, 0.0, False, maps=_maps((20, 30))))
    assert (plain[20:] == 100).all()


def test_a_dashcam_s_hood_is_in_the_maps_as_rig():
    scene = make_case("drive-day-stopped-car", 0)
    model = ASNN(record_maps=True)
    for i, frame in enumerate(scene.frames[:30]):
        response = model.step(perturb_frame(frame, "hood", i), i / scene.fps)
    h = response.maps.rig.shape[0]
    # the rim of the hood and the timestamp: in the bottom band only
    assert response.maps.rig[int(0.8 * h):].any() and not response.maps.rig[:int(0.75 * h)].any()
    reference = ASNN("reference", record_maps=True)
    assert [reference.step(f, i / scene.fps) for i, f in enumerate(scene.frames[:2])][1].maps.rig \
        is None


def test_the_header_fits_a_small_frame_and_keeps_its_size_on_a_large_one():
    import cv2

    from asnn.io.visualize import header_scale

    text = "#30 spike rate 1110 WARNING"
    assert header_scale(text, 640) == 0.4
    scale = header_scale(text, 128)
    assert scale < 0.4
    (w, _), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 3)
    assert w <= 128 - 10


def test_an_avi_is_written_as_motion_jpeg_and_an_mp4_as_mpeg4(tmp_path):
    import cv2

    from asnn.io.video import write_video

    def codec(path):  # as OpenCV reads it back
        capture = cv2.VideoCapture(str(path))
        fourcc = int(capture.get(cv2.CAP_PROP_FOURCC))
        capture.release()
        return "".join(chr((fourcc >> 8 * i) & 0xFF) for i in range(4)).lower()

    frames = np.zeros((3, 32, 48), np.uint8)
    assert codec(write_video(frames, tmp_path / "x.avi")) == "mjpg"
    assert codec(write_video(frames, tmp_path / "x.mp4")) in ("mp4v", "fmp4")
