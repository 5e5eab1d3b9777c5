"""A surface that fills the view and closes in (a wall): the generated scenes, the measurement
and the default's surface-ahead pathway (asnn.approach.surface)."""

import math

import numpy as np
import pytest

from asnn import ASNN, preset
from asnn.approach.surface import SurfaceWatch, corridor, shrunk, surface_expansion
from asnn.stimuli import make_scene
from asnn.stimuli.suite import make_case
from asnn.stimuli.surface import corridor_scene, surface_scene

FPS = 20.0


def _run(case, variant=0, **overrides):
    scene = make_case(case, variant)
    model = ASNN(preset("robust", **overrides))
    return scene, [model.step(f, i / scene.fps) for i, f in enumerate(scene.frames)]


def _warned(responses, warmup=5):
    return [r.index for r in responses if r.collision and r.index >= warmup]


def _pair(scene, k):
    return (scene.frames[k - 1].astype(np.float64) / 255, scene.frames[k].astype(np.float64) / 255)


# the scenes

def test_an_approach_touches_the_plane_after_tau_and_the_focus_lies_along_the_heading():
    scene = surface_scene("approach", tau=2.0, heading_deg=10.0, size=(160, 120), onset=10)
    assert scene.collision and scene.onset_frame == 10 and scene.contact_frame == 10 + 40
    assert scene.ttc[10] == pytest.approx(2.0) and scene.ttc[50] == pytest.approx(0.0)
    f = 80 / math.tan(math.radians(30))  # 60 degrees across 160 px
    assert scene.center == pytest.approx((79.5 + f * math.tan(math.radians(10)), 59.5))
    # still before the onset and against the plane after contact; moving in between
    still = np.abs(np.diff(scene.frames.astype(int), axis=0)).mean(axis=(1, 2))
    assert still[:9].max() < 0.5 and still[-2:].max() < 0.5 and still[20:40].min() > 1


def test_the_image_grows_as_the_inverse_of_the_lens_distance():
    # with its front 0.12 ahead of the lens, the lens is 0.12 + 0.88 (1 - t / tau) from the plane
    scene = surface_scene("approach", tau=3.0, onset=0, noise=0.0)
    k = 40  # t = 2 s: the lens at 0.12 + 0.88 / 3
    expected = (0.88 / 3.0) / (0.12 + 0.88 / 3.0)  # the image's expansion rate, per second
    surface, _ = surface_expansion(*_pair(scene, k), 1 / FPS, 1.5, 1.0)
    assert surface.rate == pytest.approx(expected, rel=0.15)


def test_receding_and_passing_alongside_are_not_collisions():
    assert not surface_scene("recede").collision
    scene = surface_scene("alongside", slant_deg=90.0, offset=0.25)
    assert not scene.collision and scene.contact_frame is None
    # the plane fills the right of the view only, the backdrop the left
    assert scene.frames[-1][:, :60].std() < 3 and scene.frames[-1][:, -40:].std() > 5


@pytest.mark.parametrize("kwargs, message", [
    (dict(motion="fly"), "unknown motion"),
    (dict(motion="alongside"), "slant_deg must be 90"),
    (dict(slant_deg=85.0), "must face the plane"),
    (dict(contrast=1.0), "does not fit"),
    (dict(standoff=1.0), "standoff"),
])
def test_impossible_scenes_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        surface_scene(**kwargs)


def test_a_scene_drawn_at_twice_the_scale_has_twice_the_pixels_and_the_same_label():
    one, two = make_case("extra-wall-approach"), make_case("extra-wall-approach", scale=2)
    assert two.frames.shape[1:] == (240, 320)
    assert (one.onset_frame, one.contact_frame) == (two.onset_frame, two.contact_frame)


# the measurement

def test_a_wall_closing_in_is_a_surface_ahead_at_its_focus():
    scene = make_case("extra-wall-approach-heading")
    k = scene.contact_frame - 10  # 0.5 s before the front touches
    surface, ahead = surface_expansion(*_pair(scene, k), 1 / FPS, 1.5, 1.0)
    assert ahead and surface.tiles >= 8
    assert surface.x == pytest.approx(scene.center[0], abs=12)
    assert surface.y == pytest.approx(scene.center[1], abs=12)
    assert 1 / surface.rate < 1.5


@pytest.mark.parametrize("case, frame", [
    ("drive-day-straight", 60),      # the road expands below a still sky
    ("drive-day-bumps", 40),         # the road, pitching
    ("loom-dark-c0.6-d24-center", 60),  # an object looming in the middle of a still view
    ("pan-texture-h2px", 40),        # a texture sliding past
    ("extra-wall-recede", 50),       # a wall backed away from
])
def test_other_motions_are_not_a_surface_ahead(case, frame):
    scene = make_case(case)
    _, ahead = surface_expansion(*_pair(scene, frame), 1 / FPS, 1.5, 1.0)
    assert not ahead


def test_the_tiles_are_what_refuse_the_road():
    # over bumps the whole frame's fit passes in most frames; the tiles agree in a few single
    # frames or pairs, never in the three in a row that the pathway asks for
    scene = make_case("drive-day-bumps")
    whole_passes = tiles_pass = run = longest = 0
    for k in range(1, len(scene.frames)):
        surface, ahead = surface_expansion(*_pair(scene, k), 1 / FPS, 1.5, 1.0)
        whole_passes += surface is not None and surface.tiles > 0
        tiles_pass += ahead
        run = run + 1 if ahead else 0
        longest = max(longest, run)
    assert whole_passes >= 40 and tiles_pass <= 8 and longest < 3


def test_the_camera_s_rig_is_left_out_and_shrunk_with_the_frames():
    scene = make_case("extra-wall-approach")
    before, after = _pair(scene, scene.contact_frame - 10)
    # a still hood over the bottom quarter: as still pixels it holds the fit back unless left out
    hood = np.zeros(after.shape, bool)
    hood[90:] = True
    before, after = before.copy(), after.copy()
    before[90:] = after[90:] = 0.2 + 0.1 * (np.arange(after.shape[1]) % 7 == 0)
    kept, _ = surface_expansion(before, after, 1 / FPS, 1.5, 1.0)
    left_out, _ = surface_expansion(before, after, 1 / FPS, 1.5, 1.0, exclude=hood)
    assert left_out.fit > kept.fit
    assert shrunk(after).shape == (48, 64)


def test_a_watch_counts_frames_in_a_row_and_forgets_its_id_when_they_end():
    scene = make_case("extra-wall-approach")
    frames = list(scene.frames.astype(np.float64) / 255)  # one object per frame, as a stream's
    watch, streaks = SurfaceWatch(), []
    for k in range(1, len(frames)):
        watch.step(frames[k - 1], frames[k], 1 / FPS, 1.5, 1.0)
        if watch.streak:
            watch.id = 7
        streaks.append(watch.streak)
        if not watch.streak:
            assert watch.id is None
    assert max(streaks) >= 10


# the default's pathway

@pytest.mark.parametrize("case", ["extra-wall-approach", "extra-wall-approach-slant",
                                  "extra-wall-approach-heading", "extra-wall-approach-fast",
                                  "extra-wall-approach-faint"])
def test_a_wall_filling_the_view_warns_before_contact_and_only_with_the_pathway(case):
    scene, responses = _run(case)
    warned = _warned(responses)
    assert warned and scene.onset_frame <= warned[0] <= scene.contact_frame - 8  # 0.4 s ahead
    _, without = _run(case, surface_ahead=False)
    assert not _warned(without)


def test_the_surface_is_one_target_with_one_id_its_time_to_contact_and_its_focus():
    scene, responses = _run("extra-wall-approach-heading")
    warned = [r for r in responses if r.collision and r.targets]
    assert warned
    ids = {t.id for r in warned for t in r.targets}
    assert len(ids) == 1 and all(len(r.targets) == 1 for r in warned)
    for r in warned:
        t = r.targets[0]
        truth = scene.ttc[r.index]
        if math.isfinite(truth):  # before contact: the lens is behind the front, so longer
            assert truth <= t.ttc <= truth + 0.7
        assert t.x == pytest.approx(scene.center[0], abs=15) and t.approaching
        assert t.pixels == 160 * 120


@pytest.mark.parametrize("case", ["extra-wall-recede", "extra-wall-alongside",
                                  "extra-wall-alongside-near"])
def test_a_wall_backed_away_from_or_passed_alongside_stays_quiet(case):
    _, responses = _run(case)
    assert not _warned(responses)


def test_a_faint_wall_is_seen_over_a_tenth_of_a_second_not_over_one_frame(monkeypatch):
    # contrast 0.2 under 2 grey levels of noise: one frame's change is too small against the
    # noise for the tiles to agree in 7 frames in a row; two frames' change is twice as large
    import asnn.approach.surface as surface

    scene, responses = _run("extra-wall-approach-faint")
    warned = _warned(responses)
    assert warned and warned[0] <= scene.contact_frame - 6  # 0.3 s ahead
    monkeypatch.setattr(surface, "BASELINE", 0.05)
    _, one_frame = _run("extra-wall-approach-faint")
    assert not _warned(one_frame)


@pytest.mark.parametrize("fps", [10.0, 30.0])
def test_a_faint_wall_warns_at_other_frame_rates_too(fps):
    # the baseline and the duration are in seconds: 1 and 4 frames at 10 fps, 3 and 10 at 30
    scene = surface_scene(contrast=0.2, noise=2.0, fps=fps, onset=round(fps))
    model = ASNN()
    warned = [i for i, f in enumerate(scene.frames) if model.step(f, i / fps).collision]
    assert warned and scene.contact_frame - 0.3 * fps >= warned[0] >= scene.onset_frame


class _Recorded:
    """Stands in for the measurement: the frames and the seconds a watch compares."""

    def __init__(self):
        self.calls = []

    def __call__(self, before, after, shape, elapsed, *args):
        self.calls.append((float(before[0, 0]), float(after[0, 0]), round(elapsed, 6)))
        return None, False


@pytest.mark.parametrize("fps, back", [(20.0, 2), (30.0, 3), (10.0, 1), (25.0, 3)])
def test_a_watch_compares_each_frame_with_the_one_a_tenth_of_a_second_before(monkeypatch, fps,
                                                                            back):
    import asnn.approach.surface as surface

    recorded = _Recorded()
    monkeypatch.setattr(surface, "_measure", recorded)
    frames = [np.full((48, 64), float(k)) for k in range(12)]
    watch = SurfaceWatch()
    for k in range(1, 12):
        watch.step(frames[k - 1], frames[k], 1 / fps, 1.5, 1.0)
    # at the stream's start, the oldest frame it has; where that is more than a frame back, the
    # frame before too (a fast corridor's walls, over one frame)
    expected = []
    for k in range(1, 12):
        j = max(k - back, 0)
        expected.append((float(j), float(k), round((k - j) / fps, 6)))
        if k - j > 1:
            expected.append((float(k - 1), float(k), round(1 / fps, 6)))
    assert recorded.calls == expected
    assert len(watch._history) == back + 1  # no more frames kept than the baseline needs


def test_a_watch_starts_again_where_the_stream_does_not_follow_on(monkeypatch):
    import asnn.approach.surface as surface

    recorded = _Recorded()
    monkeypatch.setattr(surface, "_measure", recorded)
    a = [np.full((48, 64), float(k)) for k in range(4)]
    b = [np.full((48, 64), 10.0 + k) for k in range(3)]
    watch = SurfaceWatch()
    for k in range(1, 4):
        watch.step(a[k - 1], a[k], 0.05, 1.5, 1.0)
    watch.step(b[0], b[1], 0.05, 1.5, 1.0)  # not the frame it was last given: a new stream
    watch.step(b[1], b[2], 0.05, 1.5, 1.0)
    # a stamp gap as long as the baseline: the frame just before
    watch.step(b[2], a[0], 0.2, 1.5, 1.0)
    assert recorded.calls[5:] == [(10.0, 11.0, 0.05), (10.0, 12.0, 0.1), (11.0, 12.0, 0.05),
                                  (12.0, 0.0, 0.2)]


def test_a_wall_seen_over_a_still_hood_band_warns_with_the_band_left_out():
    # the camera's rig (a hood band and a timestamp, still in every frame) is learned by the rig
    # stage and left out of the surface's fits, at the kept frames' size
    from asnn.evaluation.perturb import perturb_frame

    scene = make_case("extra-wall-approach")
    model = ASNN()
    responses = [model.step(perturb_frame(f, "hood", i), i / scene.fps)
                 for i, f in enumerate(scene.frames)]
    warned = _warned(responses)
    assert warned and warned[0] <= scene.contact_frame - 8
    rig = model.approach.rig.mask  # the band along the bottom, nothing of the wall above it
    assert rig is not None and rig[90:].mean() > 0.3 and not rig[:60].any()


# a corridor: the whole view expands, the walls around the faster, and nothing is ahead

def test_a_corridor_is_a_collision_only_where_the_clip_reaches_its_end_wall():
    long = corridor_scene(speed=2.0, seconds=2.0, end=60.0)
    assert not long.collision and long.contact_frame is None and len(long.frames) == 41
    short = corridor_scene(speed=2.0, seconds=2.0, end=3.3, standoff=0.3)
    assert short.collision and short.contact_frame == 30 and short.ttc[0] == pytest.approx(1.5)
    # moving up to contact, then standing at the wall
    change = np.abs(np.diff(short.frames.astype(int), axis=0)).mean(axis=(1, 2))
    assert change[:30].min() > 1 and change[30:].max() == 0
    with pytest.raises(ValueError, match="inside the corridor"):
        corridor_scene(half_width=0.0)


def test_a_corridor_drawn_at_twice_the_scale_is_the_same_corridor():
    import cv2

    one = corridor_scene(seconds=1.0)
    two = corridor_scene(seconds=1.0, scale=2.0)
    assert two.frames.shape[1:] == (240, 320)
    averaged = cv2.resize(two.frames[-1].astype(np.float32), (160, 120),
                          interpolation=cv2.INTER_AREA)
    # the same texture in metres, magnified with the frame: alike to within the resampling
    assert np.abs(averaged - one.frames[-1]).mean() < 0.2 * one.frames[-1].std()


def test_a_board_standing_in_a_corridor_is_the_collision_and_grows_about_the_middle():
    board = corridor_scene(speed=2.0, seconds=2.5, obstacle=4.3, obstacle_shade=0.55, seed=3)
    assert board.collision and board.contact_frame == 40
    assert board.ttc[0] == pytest.approx(2.0) and board.center == (79.5, 59.5)
    plain = corridor_scene(speed=2.0, seconds=2.5, seed=3)  # the same walls, nothing ahead
    differs = [np.nonzero(np.abs(board.frames[k].astype(int) - plain.frames[k]) > 0)
               for k in (0, 30)]
    # the board hides the corridor in the middle, and its image grows as we close in
    assert differs[1][0].size > 4 * differs[0][0].size > 0
    for rows, cols in differs:
        assert cols.mean() == pytest.approx(79.5, abs=3.0)
    with pytest.raises(ValueError, match="between the camera's front and the end wall"):
        corridor_scene(obstacle=70.0)
    with pytest.raises(ValueError, match="across the lens's height"):
        corridor_scene(obstacle=5.0, obstacle_size=(0.5, 0.3))


def test_the_tiles_around_the_middle_expand_faster_in_a_corridor_not_on_a_wall():
    scene = make_case("extra-corridor")
    frames = scene.frames.astype(np.float64) / 255
    surface, _ = surface_expansion(frames[39], frames[40], 0.05, 1.5, 1.0)
    assert surface.tiles and corridor(surface.tile_rates)
    wall = make_case("extra-wall-approach")
    frames = wall.frames.astype(np.float64) / 255
    k = wall.contact_frame - 10
    surface, ahead = surface_expansion(frames[k - 2], frames[k], 0.1, 1.5, 1.0)
    assert ahead and not corridor(surface.tile_rates)


def _surface_frames(responses, size=(160.0, 120.0)):
    return [r.index for r in responses
            if any(t.box == (0.0, 0.0, *size) for t in r.tracks or [])]


def test_driving_down_a_corridor_is_not_a_surface_ahead(monkeypatch):
    # its whole view passes the surface test frame after frame; summed over 0.3 s, its tiles
    # read walls passing around the camera, and the pathway adds nothing
    import asnn.approach.surface as surface

    scene = make_case("extra-corridor")
    model = ASNN(record_tracks=True)
    responses = [model.step(f, i / scene.fps) for i, f in enumerate(scene.frames)]
    assert not _surface_frames(responses)
    monkeypatch.setattr(surface, "CORRIDOR_RATIO", float("inf"))
    model = ASNN(record_tracks=True)
    responses = [model.step(f, i / scene.fps) for i, f in enumerate(scene.frames)]
    assert len(_surface_frames(responses)) > 50


def test_a_fast_corridor_is_read_over_one_frame():
    # at 3 m/s the walls at the frame's edge move beyond the fit's range over 0.1 s: compared
    # over it alone the view fails the surface test in most frames, and the pathway warned (its
    # tiles then read the walls short, no corridor); over one frame too, the watch holds its
    # streak and reads a corridor throughout
    scene = make_case("extra-corridor-fast")
    frames = scene.frames.astype(np.float64) / 255
    over_baseline = [surface_expansion(frames[k - 2], frames[k], 0.1, 1.5, 1.0)[1]
                     for k in range(2, len(frames))]
    assert sum(over_baseline) < 0.5 * len(over_baseline)
    watch, read = SurfaceWatch(), []
    for k in range(1, len(frames)):
        watch.step(frames[k - 1], frames[k], 1 / FPS, 1.5, 1.0)
        read.append(watch.view_streak >= 7 and watch.corridor)
    assert sum(read) > 0.9 * len(read)
    _, responses = _run("extra-corridor-fast")
    assert not _warned(responses)


def test_a_corridor_s_walls_tracked_as_objects_do_not_count_while_it_reads_as_a_corridor():
    # pieces of the walls around our heading expand about it as a stopped object would, and
    # the object stage warns on them; the whole view reads as a corridor, and they do not count
    _, responses = _run("extra-corridor")
    assert not _warned(responses)
    _, ungated = _run("extra-corridor", corridor_gate=False)
    assert len(_warned(ungated)) > 5
    # the gate reads the whole view's watch without the surface pathway too
    _, pathway_off = _run("extra-corridor", surface_ahead=False)
    assert not _warned(pathway_off)


@pytest.mark.parametrize("case", ["extra-corridor-board", "extra-corridor-board-light",
                                  "extra-corridor-end"])
def test_a_board_standing_in_a_corridor_warns_once_it_ends_the_corridor_reading(case):
    # without the gate the walls warn 2.5 s and more before contact; with it, the board (or the
    # corridor's end wall) is warned about in the last 1.5 s before contact, and nothing earlier
    scene, responses = _run(case)
    warned = _warned(responses)
    assert warned and scene.contact_frame - 1.5 * FPS <= warned[0] < scene.contact_frame - 10
    _, ungated = _run(case, corridor_gate=False)
    assert _warned(ungated)[0] < scene.contact_frame - 2.5 * FPS


def test_the_warning_ends_once_the_camera_stands_at_the_wall():
    scene = surface_scene("approach", tau=2.0, tail=30, noise=2.0, seed=4)
    model = ASNN()
    responses = [model.step(f, i / FPS) for i, f in enumerate(scene.frames)]
    assert any(r.collision for r in responses[:scene.contact_frame + 1])
    assert not any(r.collision for r in responses[scene.contact_frame + 6:])


def test_the_surface_must_last_a_third_of_a_second_whatever_the_frame_rate():
    from asnn.approach.surface import surface_frames

    assert [surface_frames(p) for p in (0.05, 1 / 30, 0.1, 0.0)] == [7, 10, 4, 7]


def test_a_drive_whose_whole_view_agrees_in_one_frame_stays_quiet_by_the_duration(monkeypatch):
    # over bumps the whole view reads as a surface ahead in a single frame; asked for one, the
    # pathway would warn
    import asnn.approach.surface as surface

    _, responses = _run("drive-day-bumps")
    assert not _warned(responses)
    monkeypatch.setattr(surface, "SECONDS", 0.0)
    _, one = _run("drive-day-bumps")
    assert _warned(one)


def test_over_one_frame_a_drive_agrees_for_longer(monkeypatch):
    # a truck overtaking on the right, in fresh scenery: compared frame to frame the whole view
    # reads as a surface ahead in runs of up to 4 frames, and 3 would warn (without the
    # corridor test, which refuses them too); over 0.1 s in none
    import asnn.approach.surface as surface

    case = ("drive-day-overtake-truck-right", 2)
    monkeypatch.setattr(surface, "SECONDS", 0.1)
    monkeypatch.setattr(surface, "CORRIDOR_RATIO", float("inf"))
    _, responses = _run(*case)
    assert not _warned(responses)
    monkeypatch.setattr(surface, "BASELINE", 0.05)
    _, one_frame = _run(*case)
    assert _warned(one_frame)


def test_the_tracks_report_the_surface_in_the_frames_it_counts():
    scene = make_case("extra-wall-approach")
    model = ASNN(record_tracks=True)
    responses = [model.step(f, i / scene.fps) for i, f in enumerate(scene.frames)]
    warned = [r for r in responses if r.collision and r.targets]
    assert warned
    for r in warned:
        (surface,) = [t for t in r.tracks if t.box == (0.0, 0.0, 160.0, 120.0)]
        assert surface.counts and surface.test.passes and surface.streak >= 7
        assert surface.id == r.targets[0].id and surface.share > 0
    quiet = [r for r in responses if not r.targets]
    assert quiet and not any(t.box == (0.0, 0.0, 160.0, 120.0) for r in quiet for t in r.tracks)


@pytest.mark.filterwarnings("ignore::asnn.errors.TimingWarning")  # the 1 us clock is meant
def test_the_watch_keeps_a_bounded_number_of_frames_whatever_the_clock():
    """A probe: stamps a microsecond apart kept every frame of the last 0.1 s in the watch's
    history (100,000 frames, 1.3 GB, and the step slowed threefold)."""
    from asnn.approach.surface import MAX_KEPT

    model = ASNN("robust")
    frames = make_scene("looming", size=(96, 96), frames=40).frames
    for k in range(3 * MAX_KEPT):
        model.step(frames[k % len(frames)], k * 1e-6)
    watch = model.approach.surface
    assert 0 < len(watch._history) <= MAX_KEPT and len(watch._rates) <= MAX_KEPT
