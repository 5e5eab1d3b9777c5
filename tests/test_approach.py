"""The object stage on its own (asnn/approach/stage.py): attended masks in, approaching targets
out."""

import numpy as np
import pytest

from asnn.approach import ApproachStage, CameraRig, FramePair
from asnn.params import preset

DT = 0.05
H, W = 120, 160


def _disk(cx, cy, radius, background=0.8, level=0.2):
    """A frame with a dark disk (soft edge), and the disk's rim as the retina attends to it."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float32)
    distance = np.hypot(x - cx, y - cy)
    inside = np.clip(radius + 0.5 - distance, 0.0, 1.0)
    frame = (background + (level - background) * inside).astype(np.float32)
    rim = np.abs(distance - radius) <= 2.0
    return frame, rim


def _radial(cx, cy):
    def vectors(rows, cols):
        dx, dy = cols - cx, rows - cy
        norm = np.maximum(np.hypot(dx, dy), 1e-9)
        return dx / norm, dy / norm
    return vectors


def _run(path, frames=30, **params):
    """Step a stage over a disk whose centre and radius at frame k are ``path(k)``; the
    (total, targets) of every step after the first."""
    stage = ApproachStage(preset("robust", **params))
    previous, _ = _disk(*path(0))
    out = []
    for k in range(1, frames):
        cx, cy, radius = path(k)
        frame, rim = _disk(cx, cy, radius)
        g = rim.astype(np.float32)
        total, targets, reports = stage.step(rim, g, _radial(cx, cy),
                                             FramePair(previous, frame, None, DT),
                                             float(g.sum()), DT, (1.0, 1.0), record=True)
        assert len(reports) == len(stage.objects)
        out.append((total, targets))
        previous = frame
    return out


def test_a_looming_disk_becomes_one_target_with_its_time_to_contact():
    # an object 20 m away closing at 10 m/s: 2 s to contact at the first frame, 0.55 s at the last
    z0, speed = 20.0, 10.0

    def path(k):
        return W / 2, H / 2, 8.0 * z0 / (z0 - speed * k * DT)

    steps = _run(path)
    warned = [(k + 1, targets) for k, (total, targets) in enumerate(steps) if targets]
    assert warned, "the looming disk never became a target"
    first = warned[0][0]
    # a second or more ahead of contact, but not at once: the approach test needs a time to
    # contact within tau_max (1.5 s, as the stage measures it) over three frames in a row
    assert 1.0 <= (z0 - speed * first * DT) / speed < 1.95
    assert all(len(targets) == 1 for _, targets in warned)  # one target, not one per rim arc
    assert len({targets[0].id for _, targets in warned}) == 1  # the same id throughout
    for k, targets in warned:
        truth = (z0 - speed * k * DT) / speed
        assert targets[0].ttc == pytest.approx(truth, rel=0.3)
        assert targets[0].approaching
    assert all(steps[k - 1][0] > 0 for k, _ in warned)  # u sums the approaching object


def test_a_disk_crossing_the_view_is_no_target_and_no_potential():
    def path(k):
        return 30.0 + 3.0 * k, H / 2, 12.0

    assert all(total == 0.0 and not targets for total, targets in _run(path))
    # without the gate every object is a target, and u sums them all
    assert all(total > 0.0 and targets for total, targets in _run(path, approach_gate=False))


def test_a_disk_growing_while_it_drifts_fast_to_the_border_is_a_pass():
    # the same growth as the looming disk, its image sweeping sideways (and staying in view):
    # a near miss, which only the offset test tells from the collision course
    z0, speed = 20.0, 10.0

    def path(k):
        z = z0 - speed * k * DT
        return W / 2 - 20.0 + 2.0 * k, H / 2, 8.0 * z0 / z

    assert not any(targets for _, targets in _run(path, frames=26))
    assert any(targets for _, targets in _run(path, frames=26, offset_max=1000.0,
                                               partial_overlap=False))


def test_the_camera_rig_marks_still_edges_at_the_frame_s_bottom_only():
    rng = np.random.default_rng(3)
    rig = CameraRig()
    hood = np.zeros((H, W), np.float32)
    hood[100:, :] = 0.3  # a hood's edge at row 100, the same in every frame
    previous = None
    for _ in range(25):
        scene = rng.random((H, W), dtype=np.float32) * 0.5  # everything else changes
        frame = scene.copy()
        frame[95:] = 0.2 + hood[95:]
        if previous is not None:
            mask = rig.update(previous, frame)
        previous = frame
    assert mask is not None
    assert mask[96:104].any()  # the hood's edge
    assert not mask[:90].any()  # the moving scene, and the middle of the frame


def test_a_track_box_outside_the_frame_is_measured_as_empty():
    """A smoothed track box can trail its object past the frame's edge: its pixels are none,
    not a slice counted from the far side (a hand sweeping across a webcam, seen without the
    direction inhibition, once crashed the scene-relative measurement this way)."""
    from asnn.approach.stage import _pixel_box
    from asnn.model import ASNN
    from cached_cases import make_case

    assert _pixel_box((-198.3, 17.9, -158.0, 63.1), W, H) == (0, 17, 0, 64)
    assert _pixel_box((150.5, -4.0, 171.2, 9.5), W, H) == (150, 0, 160, 10)
    assert _pixel_box((170.0, 130.0, 180.0, 140.0), W, H) == (160, 120, 160, 120)
    model = ASNN(preset("robust", top_k=0))
    model.approach.measure_all_against_scene = True  # every growing track, as the trace does
    warned = [model.step(frame).collision for frame in make_case("handheld-desk-sweep").frames]
    assert not any(warned)


def test_compile_kernels_loads_the_rig_kernels_before_a_stream_needs_them():
    """The rig's edge test runs from a stream's twentieth frame and its mask's doubling from
    the first frame that marks a rig: a worker must not wait for numba there (a cold cache
    compiles for seconds, and the frames that come meanwhile go unanswered)."""
    import subprocess
    import sys

    loaded = subprocess.run(
        [sys.executable, "-c", "from asnn.warmup import compile_kernels; compile_kernels(); "
         "from asnn.approach.looming import _mark_still_edges; "
         "from asnn.approach.stage import _doubled; "
         "print(len(_mark_still_edges.signatures), len(_doubled.signatures))"],
        capture_output=True, text=True, check=True)
    assert [int(n) for n in loaded.stdout.split()] == [1, 1]
    # and a stream with a hood in view needs no other form of them
    from asnn.approach.looming import _mark_still_edges
    from asnn.approach.stage import _doubled
    from asnn.model import ASNN
    from asnn.warmup import compile_kernels

    compile_kernels()
    kernels = (_mark_still_edges, _doubled)
    before = [set(k.signatures) for k in kernels]
    rng = np.random.default_rng(8)
    model = ASNN("default")
    for _ in range(25):
        frame = rng.random((96, 128), dtype=np.float32) * 0.5
        frame[80:] = 0.9  # the hood
        model.step(frame)
    assert model.approach.rig.mask is not None
    assert [set(k.signatures) for k in kernels] == before


def test_compile_kernels_loads_the_area_averages_and_summed_motion_a_stream_needs():
    """The whole-factor area averages (the repeat test's blocks, the surface watch's and the
    scene fit's grids of a 320-pixel-wide frame), a rig's mask shrunk to that grid and the
    objects' summed motion vectors: loaded by compile_kernels, not compiled at a stream's
    first object (a library user's first frames waited for numba)."""
    import subprocess
    import sys

    names = ("_fast._block_means_of_five", "_fast._block_means_of_eight",
             "_fast._summed_motion_vectors", "approach.looming._over_a_quarter")
    loaded = subprocess.run(
        [sys.executable, "-c", "from asnn.warmup import compile_kernels; compile_kernels(); "
         "import asnn._fast, asnn.approach.looming; "
         f"print(*(len(eval('asnn.' + n).signatures) for n in {names!r}))"],
        capture_output=True, text=True, check=True)
    assert all(int(n) >= 1 for n in loaded.stdout.split()), loaded.stdout
    # and a 320 x 240 stream, a disk looming over a hood, needs no other form of them
    from asnn import _fast
    from asnn.approach import looming
    from asnn.model import ASNN
    from asnn.stimuli import make_scene
    from asnn.warmup import compile_kernels

    compile_kernels()
    kernels = (_fast._block_means_of_five, _fast._block_means_of_eight,
               _fast._summed_motion_vectors, looming._over_a_quarter)
    before = [set(k.signatures) for k in kernels]
    model = ASNN("default")
    for k, frame in enumerate(make_scene("looming", size=(320, 240), frames=30).frames):
        frame = frame.copy()
        frame[200:] = 230  # the hood
        model.step(frame, k / 20.0)
    assert [set(k.signatures) for k in kernels] == before
