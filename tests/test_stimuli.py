"""Generated scenes and their labels: drawing, planar and driving scenes, the labelled suite."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from asnn.evaluation.pool import run_tasks
from asnn.stimuli import make_scene, render
from asnn.stimuli.driving import LANE_WIDTH, Vehicle, driving_scene, path_pose, road_coordinates
from asnn.stimuli.effects import Pan, Ramp, Shake, Step
from asnn.stimuli.planar import Background, Gait, Prop, planar_scene
from asnn.stimuli.suite import (EXTRA_CASES, EXTRA_GROUPS, GROUPS, SUITE_CASES, make_case,
                                suite_cases)
from asnn.stimuli.surface import corridor_scene, surface_scene

CENTER = (79.5, 59.5)  # of a 160x120 frame
# processes that render the cases for the module's fixtures (rendering them is most of the
# module's time, and each case is rendered on its own)
RENDER_JOBS = 2


def _each_case(function, names):
    """``{name: function(name)}`` for every case name in their order, computed in RENDER_JOBS
    processes."""
    names = list(names)
    results = dict(run_tasks(function, [(name,) for name in names], RENDER_JOBS))
    return {name: results[index] for index, name in enumerate(names)}


@pytest.fixture(scope="module")
def suite():
    """Every case of the suite, generated once."""
    return _each_case(make_case, SUITE_CASES)


# --------------------------------------------------------------------------- drawing


def test_anti_aliased_shapes_cover_their_exact_area_and_move_smoothly():
    image = np.zeros((40, 40))
    render.paint_disk(image, 19.3, 20.6, 7.0, 1.0)
    assert image.sum() == pytest.approx(math.pi * 49, rel=5e-3)  # radial ramp: near exact
    image = np.zeros((40, 40))
    render.paint_box(image, 20.25, 10.0, 6.5, 3.0, 1.0)
    assert image.sum() == pytest.approx(6.5 * 3.0)
    xs = np.arange(40)
    centroids = []
    for shift in np.linspace(0.0, 1.0, 5):  # sub-pixel steps move the centroid by as much
        image = np.zeros((40, 40))
        render.paint_disk(image, 15.0 + shift, 20.0, 5.0, 1.0)
        centroids.append((image.sum(axis=0) * xs).sum() / image.sum())
    assert np.diff(centroids) == pytest.approx(np.full(4, 0.25), abs=0.015)
    assert centroids[-1] - centroids[0] == pytest.approx(1.0)


def test_ellipse_covers_its_area_and_is_a_disk_when_round():
    image = np.zeros((60, 60))
    render.paint_ellipse(image, 30.4, 29.8, 14.0, 40.0, 1.0)
    assert image.sum() == pytest.approx(math.pi * 7.0 * 20.0, rel=5e-3)
    assert image[29:31, 23].max() < 0.6 < image[29:31, 25].min()     # 7 px to the sides
    assert image[9, 29:31].max() < 0.6 < image[11, 29:31].min()      # 20 px up
    disk = np.zeros((60, 60))
    render.paint_disk(disk, 30.4, 29.8, 10.0, 1.0)
    round_ = np.zeros((60, 60))
    render.paint_object(round_, "ellipse", 30.4, 29.8, 20.0, 1.0, aspect=1.0)
    assert round_ == pytest.approx(disk)


def test_car_shape_has_a_darker_window_and_lighter_lamps():
    image = np.full((60, 80), 200.0)
    render.paint_object(image, "car", 40.0, 30.0, 30.0, 60.0, aspect=1.4)
    window, lamps = render.car_levels(60.0)
    assert window < 60.0 < lamps
    assert image.min() == pytest.approx(window) and image.max() == 200.0
    assert np.any(np.isclose(image, lamps))
    with pytest.raises(ValueError):
        render.paint_object(image, "star", 40.0, 30.0, 30.0, 60.0)


@pytest.mark.parametrize("kind, mean", [("stripes", 0.25), ("grating", 0.5), ("checker", 0.5)])
def test_patterns_have_their_duty_and_move_with_the_offset(kind, mean):
    a = render.pattern((64, 64), kind, 16.0, 0.0, (0.0, 0.0), duty=0.25)
    b = render.pattern((64, 64), kind, 16.0, 0.0, (3.0, 0.0), duty=0.25)
    assert a.mean() == pytest.approx(mean, abs=1e-6)
    assert np.allclose(b[:, 3:], a[:, :-3])
    assert 0.0 <= a.min() and a.max() <= 1.0


def test_levels_and_noise_tile():
    assert render.levels(0.4, "dark") == (178.5, 76.5)
    assert render.levels(0.4, "light", mid=100.0) == (49.0, 151.0)
    with pytest.raises(ValueError):
        render.levels(0.4, "light", mid=40.0)
    tile = render.noise_tile(3, 1.5, size=64)
    assert np.abs(tile).max() == pytest.approx(1.0) and abs(tile.mean()) < 1e-6
    assert np.array_equal(tile, render.noise_tile(3, 1.5, size=64))
    # periodic: the texture sampled one tile further on is the same
    assert np.allclose(render.sample_tile(tile, (32, 32), (64.0, 0.0)),
                       render.sample_tile(tile, (32, 32)), atol=1e-6)
    # zoomed: the same texture with twice the pixels, every second one the original's
    zoomed = render.noise_tile(3, 1.5, size=64, zoom=2.0)
    assert zoomed.shape == (128, 128)
    assert np.allclose(zoomed[::2, ::2], tile, atol=1e-5)
    assert not np.allclose(zoomed[1::2, 1::2], tile, atol=1e-2)
    with pytest.raises(ValueError):
        render.noise_tile(3, 1.5, zoom=0.0)


# --------------------------------------------------------------------------- planar scenes


def test_collision_course_keeps_its_centre_and_grows_until_it_fills_the_frame():
    scene = planar_scene("loom", position=(40.0, 30.0), height=12.0, tau=3.0, onset=10)
    assert scene.collision and scene.onset_frame == 10
    assert np.all(scene.track == (40.0, 30.0))
    size, ttc, contact = scene.target_size, scene.ttc, scene.contact_frame
    assert size[contact] >= 120 > size[contact - 1]          # the contact rule
    assert np.all(size[:11] == 12.0) and np.all(np.diff(size[10:]) > 0)
    assert np.isnan(ttc[:10]).all() and ttc[10] == pytest.approx(3.0)
    approach = slice(10, contact + 1)  # ttc = Z / v: ttc * size stays tau * size0
    assert ttc[approach] * size[approach] == pytest.approx(np.full(contact - 9, 36.0))
    assert np.diff(ttc[approach]) == pytest.approx(np.full(contact - 10, -0.05))
    assert len(scene.frames) == contact + 3


def test_a_textured_mover_carries_its_texture_as_it_grows():
    options = dict(shape="ellipse", aspect=0.7, height=20.0, tau=2.0, onset=5, seed=4)
    plain = planar_scene("loom", **options)
    textured = planar_scene("loom", texture=0.2, **options)
    assert textured.params["texture"] == 0.2
    added = textured.frames.astype(np.float32) - plain.frames
    background = plain.frames == plain.frames[0, 0, 0]
    assert np.all(added[background] == 0)                     # on the mover only
    inside = np.zeros(plain.frames.shape[1:], bool)
    inside[54:66, 76:84] = True  # within the ellipse from the first frame on
    for k in (0, 20):
        assert 1.0 < added[k][inside].std() and np.abs(added[k]).max() <= 26  # +-25.5 levels
    # the texture grows with the mover: frame 20's, sampled where frame 0's pixels have moved
    # to (magnified about the centre by the mover's growth), is frame 0's
    scale = textured.target_size[20] / textured.target_size[0]
    ys, xs = np.nonzero(inside)
    moved_x = (79.5 + (xs - 79.5) * scale).astype(np.float32)[None, :]
    moved_y = (59.5 + (ys - 59.5) * scale).astype(np.float32)[None, :]
    grown = cv2.remap(added[20], moved_x, moved_y, cv2.INTER_LINEAR)[0]
    assert np.corrcoef(added[0][ys, xs], grown)[0, 1] > 0.95
    assert np.corrcoef(added[0][ys, xs], added[20][ys, xs])[0, 1] < 0.9  # not painted on
    with pytest.raises(ValueError, match="texture"):
        planar_scene("loom", shape="car", texture=0.1)
    with pytest.raises(ValueError, match="does not fit"):
        planar_scene("loom", contrast=1.0, texture=0.1)


def test_a_gait_sways_the_mover_about_its_bearing():
    gait = Gait(sway=0.1, bob=0.05, frequency=2.0)
    still = planar_scene("loom", height=10.0, tau=3.0, onset=10)
    walking = planar_scene("loom", height=10.0, tau=3.0, onset=10, gait=gait)
    assert walking.params["gait"] == {"type": "Gait", "sway": 0.1, "bob": 0.05,
                                      "frequency": 2.0}
    assert walking.contact_frame == still.contact_frame
    offset = walking.track - still.track
    size = still.target_size
    assert np.all(offset[:11] == 0.0)                                # still before the onset
    t = (np.arange(len(size)) - 10) / 20.0
    assert offset[10:, 0] == pytest.approx(0.1 * size[10:] * np.sin(4 * math.pi * t[10:]))
    assert offset[10:, 1] == pytest.approx(0.05 * size[10:] * np.abs(np.sin(4 * math.pi * t[10:])))
    # a stride is 10 frames at 20 fps: the sway is back at zero every 5 frames
    assert np.abs(offset[10::5, 0]).max() < 1e-9
    # the image follows the label: its darkest pixels' centroid moves with the sway
    k = 15
    dark = walking.frames[k] < walking.frames[k].max() - 20
    ys, xs = np.nonzero(dark)
    assert xs.mean() == pytest.approx(walking.track[k, 0], abs=0.3)


def test_near_miss_is_its_twin_drifting_out_of_the_frame():
    common = dict(position=(CENTER[0] + 20, CENTER[1]), height=12.0, tau=3.0, onset=10)
    twin = planar_scene("loom", **common)
    near = planar_scene("nearmiss", **common, twin="twin")
    assert not near.collision and near.twin == "twin" and near.contact_frame is None
    assert np.array_equal(near.frames[:11], twin.frames[:11])  # same object, same place
    n = min(len(near.frames), len(twin.frames))
    assert np.array_equal(near.target_size[:n], twin.target_size[:n])  # same distance
    offset = near.track[:, 0] - CENTER[0]
    assert np.all(near.track[:, 1] == CENTER[1])
    assert np.all(np.diff(offset[10:]) > 0) and np.all(np.diff(offset[10:], 2) > 0)  # faster
    last = near.track[-1, 0] - near.target_size[-1] / 2
    assert last > 159.5                                        # wholly past the right edge
    assert np.all(near.frames[-1] == near.frames[0][0, 0])     # nothing left in the image
    assert near.params["clearance"] == pytest.approx((20 - 6) / 12, abs=1e-3)
    with pytest.raises(ValueError, match="off-centre"):
        planar_scene("nearmiss", position=(CENTER[0] + 5, CENTER[1]), height=12.0)


def test_recession_halt_and_approach_recede():
    recede = planar_scene("recede", height=48.0, tau=3.0)
    assert not recede.collision and np.isnan(recede.ttc).all()
    assert np.all(np.diff(recede.target_size[10:]) < 0)
    assert recede.target_size[-1] < 0.55 * 48
    halt = planar_scene("halt", stop_height=72.0)
    c = halt.contact_frame
    assert halt.collision and halt.target_size[c] == pytest.approx(72.0)
    assert np.all(halt.target_size[c:] == halt.target_size[c]) and len(halt.frames) == c + 30
    assert np.isnan(halt.ttc[c:]).all() and np.isfinite(halt.ttc[10:c]).all()
    back = planar_scene("approach-recede", stop_height=72.0, hold=10)
    assert back.contact_frame == c
    assert np.all(back.target_size[c:c + 11] == pytest.approx(72.0))
    assert back.target_size[-1] == pytest.approx(12.0) and np.all(np.diff(back.target_size[c + 11:]) <= 0)


def test_translation_keeps_its_size_and_moves_at_its_velocity():
    scene = planar_scene("translate", shape="car", aspect=1.4, height=20.0, onset=0,
                         position=(-10.0, 70.0), velocity=(4.0, 0.5), frames=40)
    assert not scene.collision and np.all(scene.target_size == 20.0)
    assert np.diff(scene.track, axis=0) == pytest.approx(np.tile([4.0, 0.5], (39, 1)))
    assert np.isnan(scene.ttc).all()


def test_camera_motion_moves_the_image_and_the_label_together():
    still = Background("texture", 0.3, 1.5)
    shaken = planar_scene("loom", background=still, camera=Shake(3.0, 1.0, seed=2))
    plain = planar_scene("loom", background=still)
    offsets = shaken.track - plain.track
    assert 0 < np.abs(offsets).max() <= 3.0 + 60 * math.radians(1.0) + 1e-9
    assert shaken.contact_frame == plain.contact_frame
    panned = planar_scene("loom", background=still, position=(100.0, 60.0),
                          camera=Pan((-1.0, 0.0), start=0))
    assert np.diff(panned.track[:, 0]) == pytest.approx(np.full(len(panned.frames) - 1, -1.0))
    # the textured background moved with the pan: frame t+1 is frame t shifted left by 1 px
    assert np.abs(panned.frames[1][:, :100].astype(float) - panned.frames[0][:, 1:101]).mean() < 1.0


def test_props_nearer_than_the_background_move_more_under_the_camera():
    # a far and a near prop on a uniform wall, the camera panning 1 px per frame: the wall and
    # the far prop move 1 px, the near one (parallax 2.5) 2.5 px; a rotation moves both alike
    props = (Prop("square", 40.0, 60.0, 12.0, 20.0), Prop("square", 110.0, 60.0, 12.0, 20.0,
                                                         parallax=2.5))
    scene = planar_scene("none", props=props, frames=12, camera=Pan((-1.0, 0.0), start=0))

    def centre(frame, x0, x1):
        dark = (255.0 - frame[:, x0:x1].astype(float)).clip(0) * (frame[:, x0:x1] < 100)
        return x0 + (dark.sum(axis=0) * np.arange(x1 - x0)).sum() / dark.sum()

    far = [centre(f, 10, 70) for f in scene.frames]
    near = [centre(f, 75, 150) for f in scene.frames]
    assert np.diff(far) == pytest.approx(np.full(11, -1.0), abs=0.02)
    assert np.diff(near) == pytest.approx(np.full(11, -2.5), abs=0.02)
    still = planar_scene("none", props=props, frames=3)
    assert np.array_equal(still.frames[0], still.frames[2])  # no camera: nothing moves


def test_lighting_changes_the_mean_brightness_as_stated():
    scene = planar_scene("none", background=Background("texture", 0.3, 1.5, mean=110.0),
                         lighting=(Step(30, 1.4),), frames=40)
    means = scene.frames.reshape(40, -1).mean(axis=1)
    assert np.allclose(means[:30], means[0], rtol=1e-3)
    assert means[30:] / means[0] == pytest.approx(np.full(10, 1.4), rel=0.01)
    with pytest.raises(ValueError):
        planar_scene("none", background=Background("stripes", 1.0, mean=200.0))


def test_sensor_noise_and_jpeg_degrade_the_clean_clip_as_intended():
    options = dict(motion="none", background=Background("texture", 0.3, 1.5, mean=110.0),
                   frames=8, seed=5)
    clean = planar_scene(**options).frames.astype(float)
    noisy = planar_scene(**options, noise=6.0).frames.astype(float)
    residual = noisy - clean
    assert residual.std() == pytest.approx(6.0, rel=0.05) and abs(residual.mean()) < 0.2
    assert not np.array_equal(residual[0], residual[1])  # fresh noise every frame
    assert np.array_equal(noisy, planar_scene(**options, noise=6.0).frames)  # seeded
    errors = [np.abs(planar_scene(**options, jpeg_quality=q).frames - clean).mean()
              for q in (60, 20, 8)]
    assert 0 < errors[0] < errors[1] < errors[2] < 10


# --------------------------------------------------------------------------- driving


def test_road_coordinates_invert_the_path():
    for curvature in (0.0, 1 / 60, -1 / 80):
        s = np.array([0.0, 10.0, 45.0])
        x, z, heading = path_pose(s, curvature)
        d = 2.0
        s_back, d_back = road_coordinates(x + d * np.cos(heading), z - d * np.sin(heading),
                                          curvature)
        assert s_back == pytest.approx(s) and d_back == pytest.approx(np.full(3, d))


def test_driving_collision_course_keeps_its_bearing_and_ends_at_the_bumper():
    scene = driving_scene(vehicles=(Vehicle(0.0, 40.0, 0.0),), target=0, speed=12.0,
                          frames=80, roadside=0.5)
    c = scene.contact_frame
    assert scene.collision and c == math.ceil((40.0 - 2.0) / 12.0 * 20)
    assert np.allclose(scene.track[:, 0], (192 - 1) / 2)   # straight ahead all along
    assert scene.target_size[c] > 0.75 * 128                # it fills most of the view
    assert scene.ttc[0] == pytest.approx(40.0 / 12.0, rel=0.02)
    assert np.all(np.diff(scene.target_size[:c + 1]) > 0)
    assert len(scene.frames) == c + 3
    assert np.array_equal(scene.frames[-1], scene.frames[-2])  # the crash stops the motion


@pytest.mark.parametrize("front, speed, oncoming", [(0.5, 3.0, 0.0), (0.3, 3.0, 0.0),
                                                    (2.0, 20.0, -20.0)])
def test_a_short_bumper_or_a_fast_closing_keeps_the_target_drawn_and_labelled_to_contact(
        front, speed, oncoming):
    """A stress trial: nothing nearer than 0.5 m was drawn nor labelled, but a robot's bumper
    (0.3-0.5 m ahead of its camera) or a frame's travel at 40 m/s closing puts the target
    nearer at contact: its centre was NaN (its label no JSON, asnn eval's end a crash) and it
    vanished from the picture."""
    box = Vehicle(0.0, 9.0 if speed < 10 else 80.5, oncoming, width=0.8, height=1.0,
                  shape="rect", albedo=0.3)
    scene = driving_scene(speed=speed, frames=80, front=front, camera_height=0.6,
                          vehicles=(box,), target=0)
    c = scene.contact_frame
    assert scene.collision and all(map(math.isfinite, scene.center))
    json.dumps(scene.label("robot.mp4"), allow_nan=False)
    road = driving_scene(speed=speed, frames=c + 1, front=front, camera_height=0.6)
    assert np.abs(scene.frames[c].astype(float) - road.frames[c]).mean() > 20  # still there


def test_driving_pass_in_the_next_lane_drifts_out_and_is_no_collision():
    scene = driving_scene(vehicles=(Vehicle(-LANE_WIDTH, 84.0, -12.0),), target=0, frames=90)
    assert not scene.collision
    seen = np.isfinite(scene.track[:, 0])
    assert seen[0] and not seen[-1]                         # it passed us
    x = scene.track[seen, 0]
    assert np.all(np.diff(x) < 0) and x[-1] < 0             # out over the left edge
    follow = driving_scene(vehicles=(Vehicle(0.0, 15.0, 12.0),), target=0, frames=30)
    assert not follow.collision and np.isnan(follow.ttc).all()
    assert np.ptp(follow.target_size) < 1e-6


def test_a_braking_robot_stands_short_of_what_it_would_have_hit():
    # 1.5 m/s, braking at 0.5 m/s^2 from frame 10: 0.75 + 2.25 m travelled, then standing
    box = Vehicle(0.0, 4.5, 0.0, width=1.8, height=1.45, shape="rect", albedo=0.3)
    robot = dict(speed=1.5, frames=90, front=0.3, camera_height=0.6, roadside=0.0,
                 vehicles=(box,), target=0)
    stops = driving_scene(**robot, brake=0.5, brake_frame=10)
    assert not stops.collision and len(stops.frames) == 90
    assert stops.params["brake"] == 0.5
    # still from the stop (frame 70) on, moving before it, the box as big as 1.5 m away
    assert np.array_equal(stops.frames[71], stops.frames[89])
    assert not np.array_equal(stops.frames[60], stops.frames[70])
    assert np.isnan(stops.ttc[75:]).all() and np.isfinite(stops.ttc[:60]).all()
    assert stops.target_size[89] == pytest.approx(stops.target_size[0] * 4.5 / 1.5, rel=0.02)
    # without braking the same robot runs into it; a brake of 0 is the drive as it was
    hits = driving_scene(**robot)
    assert hits.collision and hits.contact_frame == 56  # 4.2 m to the bumper at 1.5 m/s
    assert np.array_equal(driving_scene(**robot, brake=0.0, brake_frame=10).frames, hits.frames)
    assert "brake" not in hits.params
    # a braking that would accelerate, or start before the clip, is refused (it moved frame 0)
    for bad in (dict(brake=-0.5), dict(brake=0.5, brake_frame=-10), dict(brake=float("nan"))):
        with pytest.raises(ValueError, match="brake"):
            driving_scene(**robot, **bad)
        with pytest.raises(ValueError, match="brake"):
            Vehicle(0.0, 4.5, 1.0, **bad)


def test_crossing_vehicle_hits_our_path_or_clears_it_before_we_arrive():
    crossing = dict(speed=0.0, lateral_speed=6.0, width=4.5, height=1.45)
    # 36 m ahead, from 18 m left at 6 m/s while we close at 12 m/s: constant bearing, and at
    # contact its centre is 1 m left of ours, well inside the overlap
    tbone = driving_scene(vehicles=(Vehicle(-18.0, 36.0, **crossing),), target=0, speed=12.0,
                          frames=90, roadside=0.0)
    c = tbone.contact_frame
    assert tbone.collision and c == math.ceil((36.0 - 2.0) / 12.0 * 20)
    x = tbone.track[:c + 1, 0]
    assert np.ptp(x) < 2.0 and x[0] < (192 - 1) / 2 - 40    # constant bearing, to our left
    assert np.all(np.diff(tbone.target_size[:c + 1]) > 0)
    assert tbone.ttc[0] == pytest.approx(36.0 / 12.0, rel=0.02)
    # its near face is its side: 4.5 m wide in the image (the empty road subtracted)
    k = c - 25  # (later, its left end is out of the view)
    road = driving_scene(speed=12.0, frames=k + 1, roadside=0.0).frames[k].astype(float)
    x, y = tbone.track[k]
    rows = np.abs(tbone.frames[k].astype(float) - road)[int(y) - 4:int(y) + 5]
    focal = (192 / 2) / math.tan(math.radians(35.0))
    width = np.count_nonzero((rows > 10).any(axis=0))
    assert width == pytest.approx(focal * 4.5 / (36.0 - 12.0 * k / 20), rel=0.15)
    # 7 m further right at the same moment: it has left our lane when we get there
    clears = driving_scene(vehicles=(Vehicle(-11.0, 36.0, **crossing),), target=0, speed=12.0,
                           frames=90, roadside=0.0)
    assert not clears.collision and clears.contact_frame is None
    seen = np.isfinite(clears.track[:, 0])
    assert not seen[-1] and np.all(np.diff(clears.track[seen, 0]) > 0)  # out to the right


def test_rear_camera_sees_a_car_catch_up_or_overtake():
    # the camera moves away from the scene at 5 m/s (a cyclist's rear camera); a car 30 m
    # behind closes at 9 m/s: in our lane its front meets our rear, 1 m behind the camera
    rear = dict(speed=-5.0, front=1.0, frames=90)
    catchup = driving_scene(vehicles=(Vehicle(0.0, 30.0, -14.0),), target=0, **rear)
    c = catchup.contact_frame
    assert catchup.collision and c == math.ceil((30.0 - 1.0) / 9.0 * 20)
    assert np.ptp(catchup.track[:c + 1, 0]) < 1.0  # constant bearing
    assert np.all(np.diff(catchup.target_size[:c + 1]) > 0)
    assert catchup.ttc[0] == pytest.approx(30.0 / 9.0, rel=0.02)
    # the scene recedes: a parked car's image shrinks, and it never closes in
    parked = driving_scene(vehicles=(Vehicle(LANE_WIDTH, 10.0, 0.0),), target=0, **rear)
    assert np.all(np.diff(parked.target_size) < 0) and np.isnan(parked.ttc).all()
    # 3 m to the right it overtakes with 1.2 m to spare: it drifts out of the view
    overtake = driving_scene(vehicles=(Vehicle(3.0, 30.0, -14.0),), target=0, **rear)
    assert not overtake.collision and overtake.contact_frame is None
    seen = np.isfinite(overtake.track[:, 0])
    assert not seen[-1] and np.all(np.diff(overtake.track[seen, 0]) > 0)


def test_car_cutting_in_ahead_recedes_and_is_no_collision():
    # a faster car from the right lane, 2 m ahead, moves into our lane while it pulls away
    car = Vehicle(LANE_WIDTH, 2.0, 16.0, lateral_speed=-0.8)
    scene = driving_scene(vehicles=(car,), target=0, speed=12.0, frames=90)
    assert not scene.collision and scene.contact_frame is None and np.isnan(scene.ttc).all()
    seen = np.isfinite(scene.track[:, 0])
    assert seen[-1]                                          # still ahead at the end
    x, size = scene.track[seen, 0], scene.target_size[seen]
    assert np.all(np.diff(size) < 0)                         # it recedes all along
    assert np.all(np.diff(x) < 0) and abs(x[-1] - (192 - 1) / 2) < 0.1 * 192  # into our lane
    lanes = car.lateral(np.arange(90), 20.0)                 # next lane -> our lane's centre
    assert lanes[0] == LANE_WIDTH and abs(lanes[-1]) < 0.1


@pytest.mark.parametrize("lane", [1.2, -1.2])
def test_a_car_offset_within_our_width_is_a_partial_overlap_collision(lane):
    # a stopped car whose centre is 1.2 m to the side of ours: it overlaps our car's width
    # (both 1.8 m), so it is hit at a corner; 3.5 m to the side (the next lane) it is passed
    hit = driving_scene(vehicles=(Vehicle(lane, 40.0, 0.0),), target=0, frames=90)
    passed = driving_scene(vehicles=(Vehicle(3.5 * np.sign(lane), 40.0, 0.0),), target=0,
                           frames=90)
    assert hit.collision and hit.contact_frame is not None and not passed.collision
    x = hit.track[:hit.contact_frame + 1, 0]
    centre = (192 - 1) / 2
    # its image drifts away from our heading as it nears (to the side it is on), yet less than
    # the passed car's: drift over expansion reads the 1.2 m against 3.5 m
    assert np.all(np.sign(x[1:] - centre) == np.sign(lane))
    assert np.all(np.diff(np.abs(x - centre)) > 0)
    assert abs(x[-1] - centre) < abs(passed.track[hit.contact_frame, 0] - centre)


def test_night_scenes_are_dark_with_bright_lamps():
    day = driving_scene(frames=3, vehicles=(Vehicle(0.0, 15.0, 12.0),), target=0)
    night = driving_scene(frames=3, night=True, vehicles=(Vehicle(0.0, 15.0, 12.0),), target=0)
    assert night.frames.mean() < 0.5 * day.frames.mean()
    x, y = night.track[0]
    lamps = night.frames[0][int(y) - 6:int(y) + 6, int(x) - 12:int(x) + 12]
    assert lamps.max() >= 200 and np.median(night.frames[0]) < 60


# --------------------------------------------------------------------------- the suite


def test_suite_is_balanced_and_covers_every_group(suite):
    assert 100 <= len(suite) <= 200
    collisions = sum(s.collision for s in suite.values())
    assert 0.4 <= collisions / len(suite) <= 0.6
    assert {case.group for case in SUITE_CASES.values()} == set(GROUPS)
    for name, case in SUITE_CASES.items():
        assert suite[name].category == case.category and suite[name].name == name
    tags = {t for case in SUITE_CASES.values() for t in case.category}
    assert {"dark", "light", "contrast", "size", "speed", "position", "shape", "texture",
            "shake", "pan", "flicker", "ramp", "step", "headlights", "gauss", "jpeg", "night",
            "turn", "bumps", "halt", "gait"} <= tags
    contrasts = {case.options.get("contrast") for case in SUITE_CASES.values()
                 if case.group == "approach" and "contrast" in case.category}
    assert min(contrasts) == 0.2 and max(contrasts) == 1.0


def test_every_label_is_consistent(suite):
    for name, scene in suite.items():
        t, h, w = scene.frames.shape
        assert scene.frames.dtype == np.uint8 and scene.fps == 20.0, name
        label = json.loads(json.dumps(scene.label(f"{name}.mp4"), allow_nan=False))
        assert label["frames"] == t and len(label.get("track", [None] * t)) == t, name
        if not scene.collision:
            assert scene.onset_frame is None and scene.contact_frame is None, name
            continue
        onset, contact = scene.onset_frame, scene.contact_frame
        assert 0 <= onset < contact <= t - 3, name            # contact + 2 lies in the clip
        size = scene.target_size[contact]
        if scene.name.startswith(("halt", "approach-recede")):
            assert size == pytest.approx(72.0), name
        else:
            assert size >= (h if SUITE_CASES[name].generator is planar_scene else 0.75 * h), name
        # time to contact at onset (or once closing in) lies in 2-4 s, falling to contact
        ttc = scene.ttc[onset:contact + 1]
        finite = ttc[np.isfinite(ttc)]
        if "brake" not in scene.category:
            assert 2.0 <= finite[0] <= 4.0 + 1e-9, name
        assert finite[-1] < 1.0 and np.all(np.diff(finite[-10:]) < 0), name
        assert label["center"] == pytest.approx(list(scene.track[contact]), abs=1e-3), name


def test_near_misses_pair_with_their_collision_course_twins(suite):
    twins = {name: case.twin for name, case in SUITE_CASES.items() if case.twin}
    assert len(twins) >= 12
    assert all(SUITE_CASES[n].group in ("nearmiss", "driving-pass") for n in twins)
    for near, twin in twins.items():
        a, b = suite[near], suite[twin]
        assert not a.collision and b.collision and "twin" in b.category
        options = {k: v for k, v in SUITE_CASES[near].options.items() if k != "motion"}
        twin_options = dict(SUITE_CASES[twin].options)
        if "vehicles" in options:  # the same vehicles, speeds and distances, other lanes
            near_v, twin_v = options.pop("vehicles"), list(twin_options.pop("vehicles"))
            assert [replace(v, lane=t.lane) for v, t in zip(near_v, twin_v)] == twin_v
            # the twin in our lane, or crossing on a course that meets our bumper
            assert all(t.lane == 0.0 for t in twin_v if t.lateral_speed == 0.0)
        assert options == twin_options
        n = min(len(a.frames), len(b.frames), 20)
        assert np.allclose(a.target_size[:n], b.target_size[:n], rtol=0.02, equal_nan=True)


def test_suite_cases_are_deterministic_and_selectable(suite):
    for name in ("noise-gauss-10", "shake-texture-4px-rot1deg", "flicker-random-10pct",
                 "drive-night-bumps", "loom-light-c0.5-jpeg-q20"):
        again = make_case(name)
        assert np.array_equal(again.frames, suite[name].frames)
        assert again.label("x") == suite[name].label("x")
    assert suite_cases("driving-pass") == [n for n, c in SUITE_CASES.items()
                                           if c.group == "driving-pass"]
    picked = suite_cases("nearmiss-disk-dark-right,course-*")
    assert picked[0] == "course-disk-dark-right" and "nearmiss-disk-dark-right" in picked
    assert suite_cases() == suite_cases("all") == list(SUITE_CASES)
    with pytest.raises(ValueError):
        suite_cases("no-such-*")
    for empty in ("", " , ,"):  # ',' selected no case: an eval of nothing, which exited 0
        with pytest.raises(ValueError, match="no case pattern"):
            suite_cases(empty)
    with pytest.raises(ValueError):
        make_case("no-such-case")


def test_post_scene_lights_or_rains_on_any_generator_and_keeps_its_label():
    from asnn.stimuli.effects import Step
    from asnn.stimuli.heldout import post_scene

    options = dict(vehicles=(Vehicle(0.0, 30.0, 0.0),), target=0, speed=10.0, frames=40,
                   seed=5)
    plain = driving_scene(**options)
    lit = post_scene(base=driving_scene, lighting=(Step(10, 0.5),), **options)
    assert lit.frames[:10].mean() == pytest.approx(plain.frames[:10].mean(), abs=0.5)
    assert lit.frames[10:].mean() == pytest.approx(0.5 * plain.frames[10:].mean(), abs=0.5)
    rain = post_scene(base=driving_scene, rain=True, **options)
    again = post_scene(base=driving_scene, rain=True, **options)
    assert np.array_equal(rain.frames, again.frames)  # seeded
    assert (rain.frames.astype(int) - plain.frames > 30).mean() > 0.005  # bright streaks
    same = {k: v for k, v in plain.label("x").items() if k != "description"}
    assert {k: v for k, v in rain.label("x").items() if k in same} == same
    assert rain.params["rain"] is True and "'rain': True" in rain.label("x")["description"]
    # each case's seed its own rain: the streaks of another seed lie elsewhere
    other = {**options, "seed": 6}
    streaks = (rain.frames.astype(int) - plain.frames) > 30
    others = (post_scene(base=driving_scene, rain=True, **other).frames.astype(int)
              - driving_scene(**other).frames) > 30
    assert (streaks & others).sum() < 0.2 * (streaks | others).sum()


def test_post_scene_adds_a_cameras_noise_after_the_dimming():
    # the noise is the sensor's, not the scene's: its deviation the same at a tenth of the light
    from asnn.stimuli.heldout import post_scene

    options = dict(vehicles=(Vehicle(0.0, 30.0, 0.0),), target=0, speed=10.0, frames=20,
                   seed=5)
    dim = post_scene(base=driving_scene, lighting=(Ramp(0, 1, 0.4, 0.4),), **options)
    noisy = post_scene(base=driving_scene, lighting=(Ramp(0, 1, 0.4, 0.4),), post_noise=5.0,
                       **options)
    assert np.std(noisy.frames.astype(float) - dim.frames) == pytest.approx(5.0, abs=0.2)
    assert np.array_equal(noisy.frames, post_scene(base=driving_scene, post_noise=5.0,
                                                   lighting=(Ramp(0, 1, 0.4, 0.4),),
                                                   **options).frames)  # seeded
    assert noisy.params["post_noise"] == 5.0 and "post_noise" not in dim.params
    assert noisy.contact_frame == dim.contact_frame

def test_rain_streaks_are_laid_over_the_frame_at_their_level():
    """A mutation probe: a streak blends the pixel toward its level, it does not add light: a
    frame at the level is unchanged, a white one is darkened, a black one lit."""
    from asnn.stimuli.heldout import rain_streaks

    for value in (230.0, 255.0, 0.0):
        frames = np.full((3, 40, 160), value)
        out = rain_streaks(frames, seed=1, level=230.0)
        assert out.min() >= min(value, 230.0) - 1e-3 and out.max() <= max(value, 230.0) + 1e-3
        assert value == 230.0 or (out != value).mean() > 0.01


def _extra_label(name):
    """Extra case ``name`` rendered, kept as its labels and frame count (not its frames)."""
    scene = make_case(name)
    return SimpleNamespace(
        category=scene.category, collision=scene.collision, fps=scene.fps,
        onset_frame=scene.onset_frame, contact_frame=scene.contact_frame,
        target_size=scene.target_size, ttc=scene.ttc, frames=len(scene.frames),
        height=scene.frames.shape[1])


@pytest.fixture(scope="module")
def extra_labels():
    """Every extra case rendered once, kept as its labels and frame count (not its frames):
    the extra cases' tests read them, and rendering them all takes about a minute."""
    return _each_case(_extra_label, EXTRA_CASES)


def test_the_extra_drives_stay_outside_the_suite_and_pair_with_their_twins(extra_labels):
    # the suite's selections (every case, its groups and name patterns) never take them in
    assert not set(EXTRA_CASES) & set(SUITE_CASES)
    for pattern in (None, "all", "driving-*", "drive-*,rear-*"):
        assert set(suite_cases(pattern)) <= set(SUITE_CASES)
    assert suite_cases("extra-*") == list(EXTRA_CASES)
    # 'all' within a list is every suite case ('--cases all --cases extra-*' found no 'all')
    assert suite_cases("all,extra-*") == list(SUITE_CASES) + list(EXTRA_CASES)
    assert suite_cases(" all , halt-*") == list(SUITE_CASES)
    assert suite_cases("extra-pass") == [n for n, c in EXTRA_CASES.items()
                                         if c.group == "extra-pass"]
    assert {case.group for case in EXTRA_CASES.values()} == set(EXTRA_GROUPS)
    for name, case in EXTRA_CASES.items():
        scene = extra_labels[name]
        assert name.startswith("extra-") and scene.category == case.category, name
        assert scene.collision == (case.group == "extra-threat"), name
        if scene.collision and ("surface" in case.category
                                or case.generator in (surface_scene, corridor_scene)):
            # a plane filling the view, or a corridor's wall or board reached
            assert scene.target_size is None and scene.ttc[scene.contact_frame] == 0.0, name
        elif scene.collision:
            # an object lower than the lens (the indoor set's pallet) is at contact as tall as
            # it looks from the bumper, not the frame's height
            options = case.options
            low = (case.generator is driving_scene and options["vehicles"][
                options["target"]].height < options.get("camera_height", 1.3))
            assert scene.target_size[scene.contact_frame] >= (
                0.5 if low else 0.75) * scene.height, name
        if case.twin:  # the same vehicle, distance and speed, on a course that misses us
            twin = EXTRA_CASES[case.twin]
            assert twin.group == "extra-threat" and "twin" in twin.category
            (near,), (hit,) = case.options["vehicles"], twin.options["vehicles"]
            assert replace(near, lane=hit.lane, lateral_speed=hit.lateral_speed) == hit
            assert near != hit and not scene.collision


# the indoor set as its trial wrote it down before any detector ran on it (docs/evaluation.md,
# "An indoor held-out set"): (fps, onset, contact) of each collision, (fps, None, None) of
# each other case
INDOOR_LABELS = {
    "extra-in-person-walks-at-robot": (20, 0, 64),
    "extra-in-person-walks-at-still-robot": (20, 0, 68),
    "extra-in-walker-gait-30fps": (30, 20, 95),
    "extra-in-person-crosses-into-path": (20, 0, 50),
    "extra-in-door-ahead": (20, 0, 95),
    "extra-in-cabinet-offset": (20, 0, 94),
    "extra-in-corridor-end-slow": (20, 0, 108),
    "extra-in-box-on-floor": (20, 0, 94),
    "extra-in-pallet-low-camera-bumps": (20, 0, 77),
    "extra-in-ball-rolls-at-robot": (20, 0, 44),
    "extra-in-cart-pushed-into-path": (20, 0, 74),
    "extra-in-agv-headon": (20, 0, 65),
    "extra-in-grey-box-lowcontrast": (20, 0, 94),
    "extra-in-person-lowcontrast-15fps": (15, 20, 59),
    "extra-in-glass-panel-corridor": (20, 0, 94),
    "extra-in-frosted-glass-wall": (20, 20, 80),
    "extra-in-person-flicker-100hz-30fps": (30, 0, 96),
    "extra-in-person-lights-off-on": (20, 0, 64),
    "extra-in-walker-vibration-15fps": (15, 20, 60),
    "extra-in-person-passes-alongside": (20, None, None),
    "extra-in-walker-passes-close-30fps": (30, None, None),
    "extra-in-person-crosses-clears": (20, None, None),
    "extra-in-person-crosses-still-robot": (20, None, None),
    "extra-in-person-recedes": (20, None, None),
    "extra-in-follow-person": (20, None, None),
    "extra-in-person-overtakes-robot": (20, None, None),
    "extra-in-corridor-wide": (20, None, None),
    "extra-in-aisle-narrow": (20, None, None),
    "extra-in-turn-in-place": (20, None, None),
    "extra-in-scan-sweep-15fps": (15, None, None),
    "extra-in-low-camera-bumps-clear": (20, None, None),
    "extra-in-door-passed-alongside": (20, None, None),
    "extra-in-ball-rolls-across": (20, None, None),
    "extra-in-corridor-flicker-100hz-30fps": (30, None, None),
    "extra-in-still-flicker-120hz-25fps": (25, None, None),
    "extra-in-corridor-lights-off-on": (20, None, None),
    "extra-in-sunlight-patch": (20, None, None),
}


# the sidewalk set as its trial wrote it down before any detector ran on it (docs/evaluation.md,
# "A sidewalk held-out set"): (fps, onset, contact) of each collision, (fps, None, None) of
# each other case
SIDEWALK_LABELS = {
    "extra-sw-person-walks-at-robot": (20, 0, 67),
    "extra-sw-person-walks-at-still-robot-15fps": (15, 0, 66),
    "extra-sw-walker-gait-25fps": (25, 20, 85),
    "extra-sw-person-steps-from-doorway": (20, 0, 45),
    "extra-sw-person-from-behind-parked-car": (20, 0, 42),
    "extra-sw-cyclist-headon": (20, 0, 76),
    "extra-sw-scooter-headon-30fps": (30, 0, 102),
    "extra-sw-cyclist-crosses-into-path": (20, 0, 57),
    "extra-sw-pole-ahead": (20, 0, 103),
    "extra-sw-bollard-ahead-10fps": (10, 0, 48),
    "extra-sw-bin-ahead": (20, 0, 90),
    "extra-sw-hydrant-low-camera-15fps": (15, 0, 71),
    "extra-sw-kerb-step-ahead": (20, 0, 76),
    "extra-sw-parked-car-side-ahead": (20, 0, 77),
    "extra-sw-pole-paving-bumps-25fps": (25, 0, 112),
    "extra-sw-bin-loom-shake-slabs-15fps": (15, 20, 61),
    "extra-sw-person-crosses-into-path-dusk": (20, 0, 63),
    "extra-sw-scooter-headon-dusk-10fps": (10, 0, 38),
    "extra-sw-bollard-dusk": (20, 0, 90),
    "extra-sw-person-passes-alongside": (20, None, None),
    "extra-sw-person-passes-still-robot-15fps": (15, None, None),
    "extra-sw-walker-passes-close-25fps": (25, None, None),
    "extra-sw-person-crosses-clears": (20, None, None),
    "extra-sw-follow-pedestrian": (20, None, None),
    "extra-sw-cyclist-passes-oncoming": (20, None, None),
    "extra-sw-scooter-overtakes-robot": (20, None, None),
    "extra-sw-cyclist-crosses-clears": (20, None, None),
    "extra-sw-bollards-alongside": (20, None, None),
    "extra-sw-street-trees-alongside": (20, None, None),
    "extra-sw-parked-cars-alongside": (20, None, None),
    "extra-sw-stops-at-kerb-short-of-car": (20, None, None),
    "extra-sw-turn-at-corner": (20, None, None),
    "extra-sw-turn-in-place-15fps": (15, None, None),
    "extra-sw-paving-bumps-15fps": (15, None, None),
    "extra-sw-paving-slabs-jolts": (20, None, None),
    "extra-sw-tree-shadows-sway": (20, None, None),
    "extra-sw-tree-shadows-sweep-moving": (20, None, None),
    "extra-sw-dusk-clear-10fps": (10, None, None),
    "extra-sw-person-passes-dusk": (20, None, None),
}


# the dusk set as its trial wrote it down before any detector ran on it (docs/evaluation.md,
# "A dusk held-out set"), in the same form
DUSK_LABELS = {
    "extra-dk-person-walks-at-robot": (20, 0, 70),
    "extra-dk-bin-ahead-darker": (20, 0, 90),
    "extra-dk-cyclist-headon-15fps": (15, 0, 55),
    "extra-dk-person-crosses-from-right-25fps": (25, 0, 88),
    "extra-dk-parked-car-side-night": (20, 0, 90),
    "extra-dk-hydrant-low-camera-10fps": (10, 0, 42),
    "extra-dk-cyclist-crosses-clears": (20, None, None),
    "extra-dk-scooter-passes-oncoming-10fps": (10, None, None),
    "extra-dk-bollards-alongside-15fps": (15, None, None),
    "extra-dk-person-headlamp-passes": (20, None, None),
}


# the second dusk set as its trial wrote it down before any detector ran on it
# (docs/evaluation.md, "A dusk held-out set"), in the same form
DUSK2_LABELS = {
    "extra-dk2-car-brakes-ahead-road": (20, 10, 59),
    "extra-dk2-white-van-stands-in-lane-10fps": (10, 0, 35),
    "extra-dk2-car-crosses-into-path-30fps": (30, 0, 68),
    "extra-dk2-person-corridor-lights-off-30fps": (30, 0, 101),
    "extra-dk2-dark-cyclist-headon-25fps": (25, 0, 103),
    "extra-dk2-child-runs-at-low-robot": (20, 0, 50),
    "extra-dk2-walker-underpass-noise-15fps": (15, 20, 59),
    "extra-dk2-follow-car-with-car-alongside-30fps": (30, None, None),
    "extra-dk2-car-passes-oncoming-night": (20, None, None),
    "extra-dk2-dim-corridor-nothing-ahead-15fps": (15, None, None),
    "extra-dk2-street-lamps-pass": (20, None, None),
    "extra-dk2-lit-shop-window-passes-15fps": (15, None, None),
}


# the third low-light set (a camera's noise drawn into its frames) as its trial wrote it down
# before any detector ran on it (docs/evaluation.md, "A dusk held-out set", its third set),
# in the same form
DUSK3_LABELS = {
    "extra-dk3-car-stopped-in-lane-noise5": (20, 0, 66),
    "extra-dk3-car-oncoming-in-lane-15fps": (15, 0, 55),
    "extra-dk3-slow-car-caught-up-light0.1": (20, 0, 77),
    "extra-dk3-cyclist-headon-robot-30fps": (30, 0, 99),
    "extra-dk3-people-walk-at-robot-10fps": (10, 0, 37),
    "extra-dk3-box-ahead-sidewalk-robot-noise7": (20, 0, 95),
    "extra-dk3-dark-disk-dim-ground-noise8": (20, 20, 74),
    "extra-dk3-light-disk-dim-ground-25fps": (25, 20, 88),
    "extra-dk3-car-passes-oncoming-next-lane": (20, None, None),
    "extra-dk3-follow-car-15fps": (15, None, None),
    "extra-dk3-robot-clear-path-30fps": (30, None, None),
    "extra-dk3-bins-alongside-robot": (20, None, None),
    "extra-dk3-cyclist-passes-robot-25fps": (25, None, None),
    "extra-dk3-still-view-lamp-flickers": (20, None, None),
    "extra-dk3-still-view-headlight-sweeps-15fps": (15, None, None),
}


# the fourth low-light set (lighter noise, 1.0-2.8 gray levels) as its trial wrote it down before
# any detector ran on it (docs/evaluation.md, "A dusk held-out set", its fourth set), in the same
# form
DUSK4_LABELS = {
    "extra-dk4-van-reverses-at-stopped-car-noise1": (20, 0, 94),
    "extra-dk4-car-cuts-in-ahead-25fps": (25, 0, 90),
    "extra-dk4-cyclist-wrong-way-in-lane-light0.1": (20, 0, 76),
    "extra-dk4-pedestrian-steps-out-left-robot-15fps": (15, 0, 43),
    "extra-dk4-dog-runs-at-low-robot-30fps": (30, 0, 88),
    "extra-dk4-post-ahead-robot-10fps": (10, 0, 56),
    "extra-dk4-faint-dark-disk-off-centre-noise2.5": (20, 20, 66),
    "extra-dk4-light-coat-walker-car-park-15fps": (15, 20, 67),
    "extra-dk4-car-overtakes-close-left": (20, None, None),
    "extra-dk4-child-passes-close-robot-25fps": (25, None, None),
    "extra-dk4-van-pulls-away-ahead-30fps": (30, None, None),
    "extra-dk4-left-bend-car-oncoming-10fps": (10, None, None),
    "extra-dk4-boxes-alongside-bumpy-robot-15fps": (15, None, None),
    "extra-dk4-still-view-lamp-stutters-25fps": (25, None, None),
    "extra-dk4-still-view-two-headlight-sweeps-light0.1": (20, None, None),
    "extra-dk4-still-dim-view-noise1-10fps": (10, None, None),
}


@pytest.mark.parametrize("pattern, labels, tag, collisions", [
    ("extra-in-*", INDOOR_LABELS, "indoor", 19), ("extra-sw-*", SIDEWALK_LABELS, "sidewalk", 19),
    ("extra-dk-*", DUSK_LABELS, "dusk", 6), ("extra-dk2-*", DUSK2_LABELS, "dusk", 7),
    ("extra-dk3-*", DUSK3_LABELS, "dusk", 8), ("extra-dk4-*", DUSK4_LABELS, "dusk", 8)])
def test_a_held_out_set_is_selected_by_its_pattern_and_carries_its_written_labels(
        extra_labels, pattern, labels, tag, collisions):
    # its pattern selects it, in the order written down, and nothing else; the suite's own
    # selections and the other held-out sets' patterns never take it in
    assert suite_cases(pattern) == list(labels)
    others = {"extra-ho-*", "extra-in-*", "extra-sw-*", "extra-dk-*", "extra-dk2-*",
              "extra-dk3-*", "extra-dk4-*"} - {pattern}
    assert not set(labels) & set().union(suite_cases("all"), *map(suite_cases, others))
    assert sum(contact is not None for _, _, contact in labels.values()) == collisions
    for name, (fps, onset, contact) in labels.items():
        case = EXTRA_CASES[name]
        assert case.category[2] == tag, name
        assert (case.group == "extra-threat") == (contact is not None), name
        scene = extra_labels[name]
        assert (scene.fps, scene.onset_frame, scene.contact_frame) == (fps, onset, contact), name
        assert scene.collision == (contact is not None), name
        if contact is not None:  # the clip holds its contact frame
            assert contact < scene.frames, name


def _without_seeds(value):
    if isinstance(value, dict):
        return {k: _without_seeds(v) for k, v in value.items() if k != "seed"}
    if isinstance(value, (list, tuple)):
        return [_without_seeds(v) for v in value]
    return value


def test_a_variant_is_the_same_case_with_a_fresh_scene_seed(suite):
    for name in ("drive-day-oncoming-headon", "loom-dark-c0.3-d12-texture", "noise-gauss-10",
                 "shake-texture-4px-rot1deg", "flicker-random-10pct"):
        base, fresh = suite[name], make_case(name, 2)
        assert not np.array_equal(fresh.frames, base.frames)  # other textures, noise, roadside
        same = ("description",)  # which names the seed
        assert {k: v for k, v in fresh.label("x").items() if k not in same} == \
            {k: v for k, v in base.label("x").items() if k not in same}  # the same label
        assert _without_seeds(fresh.params) == _without_seeds(base.params)
        assert fresh.params != base.params
        assert np.array_equal(make_case(name, 2).frames, fresh.frames)  # deterministic
    assert np.array_equal(make_case("drive-day-follow", 0).frames,
                          suite["drive-day-follow"].frames)
    assert make_case("drive-day-follow", 1).params["seed"] != \
        make_case("drive-day-follow", 2).params["seed"]
    # a near miss and its collision-course twin keep sharing their textures and noise
    near = SUITE_CASES["nearmiss-disk-dark-right"]
    assert make_case(near.name, 3).params["seed"] == make_case(near.twin, 3).params["seed"]
    for bad in (-1, 1.5, True, "1"):
        with pytest.raises(ValueError):
            make_case("drive-day-follow", bad)


def test_a_drive_rendered_with_more_pixels_is_the_same_drive(suite):
    base, large = suite["drive-day-brake"], make_case("drive-day-brake", 0, (432, 288))
    assert large.frames.shape[1:3] == (288, 432)
    small, big = base.label("x"), large.label("x")
    assert (big["onset_frame"], big["contact_frame"], big["ttc"]) == (
        small["onset_frame"], small["contact_frame"], small["ttc"])
    # the car is where it was, in the larger frame's pixels (pixel centres: x 2.25 about -0.5)
    frame = small["onset_frame"] + 10
    for a, b in zip(small["track"][frame], big["track"][frame]):
        assert b + 0.5 == pytest.approx(2.25 * (a + 0.5), abs=0.5)
    assert big["target_size"][frame] == pytest.approx(2.25 * small["target_size"][frame], rel=0.05)
    # a planar scene, given in pixels, keeps its size
    planar = make_case("loom-dark-c1.0-d12-center", 0, (432, 288))
    assert np.array_equal(planar.frames, suite["loom-dark-c1.0-d12-center"].frames)
    for bad in ((32, 32), (4000, 2000), (432,), "432x288"):
        with pytest.raises(ValueError):
            make_case("drive-day-brake", 0, bad)


@pytest.mark.parametrize("name", [
    "loom-light-c0.6-d12-bottomleft",       # a mover off the centre
    "loom-dark-c0.5-over-checker-diag2px",  # a pattern sliding under it
    "loom-dark-c0.3-over-texture-h1px",     # a texture sliding under it
    "loom-dark-c0.6-handheld-desk",         # props nearer than the wall, a swaying camera
    "walk-dark-c0.4-gait",                  # a textured walker with a gait
    "headlights-sweep-day",                 # props and a glow sweeping across
    "translate-car-dark-c0.6-h4px",         # a car crossing at a speed in pixels
    "sweep-scene-20px",                     # a camera sweep in pixels
])
def test_a_planar_case_rendered_with_more_pixels_is_the_same_scene(suite, name):
    # every size, position and speed in pixels scales with the frame: averaged back down to
    # the suite's pixels, the frames are the suite's own but for their noise and edges
    base, large = suite[name], make_case(name, scale=2.0)
    assert large.frames.shape == (base.frames.shape[0], 240, 320)
    assert large.params["scale"] == 2.0 and "scale" not in base.params
    small, big = base.label("x"), large.label("x")
    for key in ("onset_frame", "contact_frame", "ttc", "frames", "collision"):
        assert big.get(key) == small.get(key)
    if small.get("track"):  # labels keep 3 decimals
        assert np.allclose(np.asarray(big["track"]) + 0.5,
                           2.0 * (np.asarray(small["track"]) + 0.5), atol=0.01)
        assert np.allclose(big["target_size"], 2.0 * np.asarray(small["target_size"]), atol=0.01)
    error = max(np.abs(cv2.resize(frame, (160, 120), interpolation=cv2.INTER_AREA).astype(float)
                       - original).mean() for frame, original in zip(large.frames, base.frames))
    noisy = base.params["noise"] > 0  # the sensor's noise is drawn anew at every pixel
    assert error < (2.5 if noisy else 1.2)


def test_the_whole_suite_can_be_rendered_at_another_scale(suite):
    # a drive at a scale is the drive at the scaled size; scale 1 is the suite itself
    drive = make_case("drive-day-brake", scale=2.25)
    assert np.array_equal(drive.frames, make_case("drive-day-brake", 0, (432, 288)).frames)
    assert np.array_equal(make_case("loom-dark-c1.0-d12-center", scale=1.0).frames,
                          suite["loom-dark-c1.0-d12-center"].frames)
    half = make_case("loom-dark-c1.0-d12-center", scale=0.5)
    assert half.frames.shape[1:] == (60, 80)
    for bad in (0.4, 9.0, 0, -1.0, True, "2", float("nan")):
        with pytest.raises(ValueError):
            make_case("loom-dark-c1.0-d12-center", scale=bad)
    with pytest.raises(ValueError):
        make_case("drive-day-brake", 0, (432, 288), scale=2.0)
    with pytest.raises(ValueError):
        planar_scene(scale=0.0)


@pytest.mark.parametrize("name, sized", [("extra-sw-dusk-clear-10fps", (256, 384)),
                                         ("extra-ho-rain-still-scene", (120, 160))])
def test_a_case_lit_or_rained_on_after_drawing_is_drawn_at_a_scale_by_its_base(name, sized):
    # post_scene's drive took the planar scenes' 'scale' (a TypeError); its planar scene did not
    plain, scaled = make_case(name), make_case(name, scale=2.0)
    assert scaled.frames.shape == (len(plain.frames), *(2 * n for n in plain.frames.shape[1:]))
    assert (scaled.collision, scaled.contact_frame) == (plain.collision, plain.contact_frame)
    assert scaled.params["post_lighting"] == plain.params["post_lighting"]
    # a driving size reaches its drive too (it was dropped without a word); the planar scene
    # keeps its own size, as every planar case does
    assert make_case(name, 0, (384, 256)).frames.shape[1:] == sized


def test_brightness_and_noise_cases_of_the_suite_do_what_their_names_say(suite):
    def means(name):
        return suite[name].frames.reshape(len(suite[name].frames), -1).mean(axis=1)

    assert means("exposure-step-up-1.4")[40] / means("exposure-step-up-1.4")[20] == \
        pytest.approx(1.4, rel=0.01)
    assert means("exposure-step-down-0.6")[40] / means("exposure-step-down-0.6")[20] == \
        pytest.approx(0.6, rel=0.01)
    ramp = means("brightness-ramp-down")
    assert ramp[60] / ramp[5] == pytest.approx(0.5, rel=0.01)
    assert np.all(np.diff(ramp[10:51]) < 0)
    flicker = means("flicker-sine-4hz-15pct")
    assert flicker.max() / flicker.min() == pytest.approx(1.15 / 0.85, rel=0.02)
    sweep = means("headlights-sweep-night")
    assert sweep[27] > sweep[5] + 5 and sweep[60] == pytest.approx(sweep[5], abs=0.5)
    # the still scene of the noise cases is the same scene as the lighting cases'
    clean = suite["jpeg-q20"].frames.astype(float) - suite["jpeg-q8"].frames
    assert 0 < np.abs(clean).mean() < 10


def test_write_video_takes_frames_one_by_one_as_it_takes_an_array(tmp_path):
    """A clip written from a generator of frames (not held at once) decodes to the frames of
    the same clip written from an array; a generator without frames is refused."""
    from asnn.io.video import write_video

    frames = make_scene("looming", size=(64, 48), frames=12, start=2, stop=10).frames
    whole = write_video(frames, tmp_path / "whole.avi", fps=20.0)
    lazy = write_video((f for f in frames), tmp_path / "lazy.avi", fps=20.0)

    def decoded(path):
        cap = cv2.VideoCapture(str(path))
        out = []
        while True:
            ok, image = cap.read()
            if not ok:
                return out
            out.append(image)

    a, b = decoded(whole), decoded(lazy)
    assert len(a) == len(b) == 12
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    with pytest.raises(ValueError, match="no frames"):
        write_video(iter(()), tmp_path / "empty.avi")


def test_write_video_raises_where_the_file_lost_frames(tmp_path, monkeypatch):
    """OpenCV's writer fails silently (a full disk): the file is read back."""
    from asnn.io import video
    from asnn.io.video import write_video
    from asnn.stimuli import make_scene

    real = cv2.VideoWriter

    class Stops:  # writes the first frame only, as a writer on a disk that filled up
        def __init__(self, *args, **kwargs):
            self._real, self._left = real(*args, **kwargs), 1

        def __getattr__(self, name):
            return getattr(self._real, name)

        def write(self, image):
            if self._left:
                self._left -= 1
                self._real.write(image)

    monkeypatch.setattr(video.cv2, "VideoWriter", Stops)
    frames = make_scene("looming", size=(64, 64), frames=5).frames
    with pytest.raises(OSError, match="the video written holds 1 of 5 frames"):
        write_video(frames, tmp_path / "clip.avi")


@pytest.mark.parametrize("option, value, says", [
    ("--fps", "inf", "not a finite number: 'inf'"),  # hung in the video writer
    ("--fps", "nan", "not a finite number: 'nan'"),
    ("--fps", "500", "a frame rate is 1 to 240 frames a second, got '500'"),
    ("--fps", "0.5", "a frame rate is 1 to 240 frames a second, got '0.5'"),
    ("--contrast", "inf", "not a finite number: 'inf'"),
    ("--speed", "inf", "not a finite number: 'inf'"),
    ("--size", "3000x3000", "frames must be at most 1920x1080, got '3000x3000'"),
])
def test_scene_refuses_a_value_no_camera_has_with_one_line(tmp_path, capsys, option, value,
                                                           says):
    from cli.main import main

    out = tmp_path / "clip.mp4"
    with pytest.raises(SystemExit) as exit_:
        main(["scene", "looming", str(out), option, value])
    assert exit_.value.code == 2
    assert f"argument {option}: {says}" in capsys.readouterr().err
    assert not out.exists()


def test_scene_writes_at_the_bounds_of_its_frame_rate(tmp_path):
    from cli.main import main

    from asnn.io.video import VideoClip

    for fps in ("1", "240"):  # and each reads back at its own rate
        out = tmp_path / f"{fps}.avi"
        assert main(["scene", "looming", str(out), "--fps", fps, "--size", "32x32"]) == 0
        assert VideoClip(out).fps == float(fps)


def test_scene_names_the_extensions_it_writes_before_drawing(tmp_path, capsys):
    from cli.main import main

    out = tmp_path / "x.txt"  # was an OpenCV dump
    assert main(["scene", "looming", str(out)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"asnn scene: {out}: name the format by its extension: a video (.avi, .m4v, .mkv, .mov, "
        ".mp4) or a bag (.mcap)"]
    assert not out.exists()


@pytest.mark.parametrize("out, says", [
    ("{tmp}/a-file/x.mp4", "{tmp}/a-file is not a folder"),  # was "[Errno 17] File exists"
    ("{tmp}/" + "a" * 300 + "/x.mcap", "File name too long"),  # was a bare errno
    ("/proc/asnn-none/x.mp4", "cannot make /proc/asnn-none: "),  # root's permissions say yes
    ("/proc/self/x.mcap", "cannot write in /proc/self: "),
])
def test_scene_names_an_out_it_cannot_write_in_one_line(tmp_path, capsys, out, says):
    from cli.main import main

    if out.startswith("/proc/") and not Path("/proc/self").is_dir():
        pytest.skip("no /proc here")
    (tmp_path / "a-file").write_text("")
    out = out.format(tmp=tmp_path)
    assert main(["scene", "looming", out, "--size", "32x32"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"asnn scene: {out}: ") \
        and says.format(tmp=tmp_path) in err[0], err


def test_scene_names_a_labels_file_whose_name_is_too_long_in_one_line(tmp_path, capsys):
    from cli.main import main

    labels = tmp_path / ("a" * 300 + ".json")
    assert main(["scene", "looming", str(tmp_path / "x.mp4"), "--labels", str(labels)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"asnn scene: --labels {labels}: File name too long"]


def test_a_paper_scene_refuses_a_rate_or_speed_it_cannot_draw_and_records_its_arguments():
    from asnn.stimuli import make_scene

    with pytest.raises(ValueError, match="fps must be a positive number"):
        make_scene("looming", fps=0)  # its label was then refused by the label check
    with pytest.raises(ValueError, match="speed must be a positive number"):
        make_scene("looming", speed=-1)
    scene = make_scene("looming_over_stripes", radius=4.0, stripe_speed=3.0, fps=25.0)
    assert (scene.params["radius"], scene.params["stripe_speed"], scene.params["fps"]) == \
        (4.0, 3.0, 25.0)


def test_a_clip_the_encoder_would_write_at_another_size_is_refused(tmp_path):
    """OpenCV's encoders wrote a 161x121 scene as 160x120 without a word, its label still in
    the 161x121 frames' pixels (an output trial)."""
    from asnn.io.video import write_video
    from asnn.stimuli import make_scene

    frames = make_scene("looming", size=(161, 121), frames=4).frames
    with pytest.raises(OSError, match="at 161x121: OpenCV's encoder writes even sizes only"):
        write_video(frames, tmp_path / "odd.mp4")
    assert not (tmp_path / "odd.mp4").exists()
    assert write_video(frames[:, :120, :160], tmp_path / "even.mp4").exists()


def test_a_disk_that_fills_the_view_before_it_stops_growing_has_reached_contact():
    # a CLI trial: at 100 px a step the disk covered the frame from step 11, and the label
    # still put contact at 55 (asnn scene --labels)
    assert make_scene("looming").contact_frame == 55  # the paper's: grows 6 -> 51 px
    fast = make_scene("looming", speed=10.0)
    assert fast.onset_frame == 10 and 10 < fast.contact_frame < 55
    full = fast.frames[fast.contact_frame]
    assert (full == full[0, 0]).all()  # the disk covers every pixel at contact
    before = fast.frames[fast.contact_frame - 1]
    assert not (before == before[0, 0]).all()


def test_scene_writes_over_an_existing_out_in_a_folder_that_takes_no_new_file(tmp_path,
                                                                              monkeypatch):
    """A review's trial: trying OUT's folder with a new file there refused an existing OUT in
    a folder one may not write (as a user, not root); the file is written where it is. The
    folder's refusal is simulated: root may write anywhere."""
    import asnn.io.files
    import cli.scene
    from cli.main import main

    out = tmp_path / "x.mp4"
    out.write_bytes(b"")

    def refused(folder):
        return f"cannot write in {folder}: Permission denied"

    for module in (asnn.io.files, cli.scene):  # wherever the check looks it up
        monkeypatch.setattr(module, "folder_problem", refused, raising=False)
    assert main(["scene", "looming", str(out), "--size", "32x32"]) == 0
    assert out.stat().st_size > 0
    out.unlink()  # a new one still needs its folder
    assert main(["scene", "looming", str(out), "--size", "32x32"]) == 2
    assert not out.exists()
