"""The direct looming estimate (asnn/approach/looming.py) and the target tracker
(asnn/approach/tracking.py)."""

import math

import cv2
import numpy as np
import pytest

from asnn.approach.looming import (FIT_SIDE, RIG_WEIGHT, Expansion, moved_by_expansion,
                                  refine_grid, refined_expansion, region_and_rim_expansion,
                                  region_expansion, rig_pixels, rim_scaled, scene_expansion,
                                  shrunk_mask)
from asnn.approach.tracking import Observation, TargetTracker, Track, approaching
from imageutil import texture, warp


_MIN_GRID_SIDE = 5  # pixels across a refinement grid keeps


def _texture(size=400):
    return texture((size, size), blur=3.0)


@pytest.mark.parametrize("box", [(170, 170, 230, 230), (150, 150, 250, 250),
                                 (100, 100, 300, 300)])
def test_expansion_about_the_box_centre_is_measured_at_every_box_size(box):
    # a large box is fitted on a coarser grid, where fine texture reads a little faster
    tex = _texture()
    est = region_expansion(tex, warp(tex, 1.02), box)
    assert est.rate == pytest.approx(0.02, rel=0.4)
    assert abs(est.drift_x) < 0.1 and abs(est.drift_y) < 0.1
    shrink = region_expansion(tex, warp(tex, 1 / 1.02), box)
    assert shrink.rate == pytest.approx(-0.02, rel=0.4)  # receding: contraction


def test_the_refined_expansion_is_the_scale_between_the_frames_where_the_fit_is_off():
    tex, box = _texture(), (150, 150, 250, 250)
    # 10 % a frame: the first-order fit about the mean frame reads 14 % fast, two steps exact
    after = warp(tex, 1.1)
    est = region_expansion(tex, after, box)
    assert est.rate > 0.11
    assert refined_expansion(tex, after, box, est).rate == pytest.approx(0.1, rel=0.01)
    # 25 % a frame and 3 px of drift: the fit saturates at half of it; from a guess near the
    # answer (the track's prediction) the steps reach it, drift and all
    after = warp(tex, 1.25, dx=3.0)
    est = region_expansion(tex, after, box)
    assert est.rate < 0.1
    refined = refined_expansion(tex, after, box, est, est._replace(rate=0.22, drift_x=0.0))
    assert refined.rate == pytest.approx(0.25, rel=0.01)
    assert refined.drift_x == pytest.approx(3.0, abs=0.1)
    assert (refined.brightness, refined.fit) == (est.brightness, est.fit)
    # without one the steps go as far as the bound lets them: twice the fit's rate
    bounded = refined_expansion(tex, after, box, est)
    assert bounded.rate == pytest.approx(2 * est.rate)
    assert bounded.drift_x == pytest.approx(2 * est.drift_x)
    # a box too small to fit, or a start that does not expand, is left as it was
    assert refined_expansion(tex, after, (10, 10, 14, 14), est) is est
    still = est._replace(rate=-0.01)
    assert refined_expansion(tex, after, box, still) is still


@pytest.mark.parametrize("side", [60, 100, 150, 200])
def test_the_refined_expansion_on_the_shrunk_grid_is_the_scale_at_every_box_size(side):
    # a box above 64 px is stepped on its grid area-averaged by a whole factor (2, 3 and 4
    # here, trimmed to its multiples), the previous frame's average warped: the scale and the
    # drift about the box centre as at full resolution (the 60 px box), centred or not. Fine
    # texture on a coarse grid slows the steps: the 200 px box (a grid of 50) reads 2 % short
    # after two steps from a start 10 % short (the full-resolution warp averaged to 64 px,
    # before: 1.5 %); more steps reach the scale
    tex = _texture()
    after = warp(tex, 1.2, dx=2.0, dy=-1.0)
    for x0 in (200 - side // 2, 120):
        box = (x0, 200 - side // 2, x0 + side, 200 - side // 2 + side)
        est = region_expansion(tex, after, box)
        start = est._replace(rate=0.18)
        refined = refined_expansion(tex, after, box, est, start)
        assert refined.rate == pytest.approx(0.2, rel=0.025)
        # the image motion at the box centre: the drift plus the expansion about the frame's
        centre_x, centre_y = 0.5 * (box[0] + box[2] - 1), 0.5 * (box[1] + box[3] - 1)
        assert refined.drift_x == pytest.approx(2.0 + 0.2 * (centre_x - 199.5), abs=side / 200)
        assert refined.drift_y == pytest.approx(-1.0 + 0.2 * (centre_y - 199.5), abs=side / 200)
        converged = refined_expansion(tex, after, box, est, start, iterations=4, settled=0.0)
        assert converged.rate == pytest.approx(0.2, rel=0.003)


def test_a_long_thin_box_is_refined_on_a_grid_that_keeps_its_short_side():
    """A box clipped by the frame's edge to a few rows of a long side (a trailing box): its
    grid's factor is held to what leaves 5 pixels across (the long side's factor left it 0
    rows wide, and the area average raised), and the refinement runs or leaves it alone."""
    from asnn.approach.looming import refine_grid

    tex = _texture()
    after = warp(tex, 1.1)
    for box in ((100, 20, 105, 380), (10, 200, 390, 206), (100, 20, 112, 380)):
        factor, (gx0, gy0, gx1, gy1) = refine_grid(box)
        assert min(gx1 - gx0, gy1 - gy0) // factor >= 5, box
        est = region_expansion(tex, after, box)
        assert est is not None
        refined = refined_expansion(tex, after, box, est, est._replace(rate=0.1))
        assert math.isfinite(refined.rate) and refined.rate > 0, box
    assert refine_grid((0, 0, 200, 200))[0] == 4  # a box of usual shape keeps its factor


def test_the_refinement_grid_is_the_smallest_whole_factor_about_the_box_centre():
    """refine_grid: the smallest whole factor that brings the box to 64 px a side, held to what
    leaves 5 px across; the box trimmed to its multiples by less than the factor, evenly."""
    for width in range(5, 400, 7):
        for height in (5, 12, 64, 65, 129, 255, 300):
            box = (11, 3, 11 + width, 3 + height)
            factor, (x0, y0, x1, y1) = refine_grid(box)
            short = min(width, height) // _MIN_GRID_SIDE
            assert factor == max(1, min(math.ceil(max(width, height) / FIT_SIDE), short)), box
            assert (x1 - x0) % factor == (y1 - y0) % factor == 0
            assert 0 <= width - (x1 - x0) < factor and 0 <= height - (y1 - y0) < factor
            assert abs((x0 + x1) - (11 + 11 + width)) <= 1 and \
                abs((y0 + y1) - (3 + 3 + height)) <= 1, box


def test_the_refined_drift_is_about_the_box_centre_where_the_grid_trims_the_box():
    # boxes whose sides are no whole multiple of their factor (127: 2, 130: 3, 255: 4) are
    # stepped on a grid half a pixel off their centre: the drift is brought back to the box's
    # centre (the 0.2 px of the rate times that half pixel, twice, were within the tolerance
    # of the test above)
    tex = _texture()
    after = warp(tex, 1.2, dx=2.0, dy=-1.0)
    for side in (127, 130, 255):
        box = (120, 200 - side // 2, 120 + side, 200 - side // 2 + side)
        est = region_expansion(tex, after, box)
        refined = refined_expansion(tex, after, box, est, est._replace(rate=0.18),
                                    iterations=6, settled=0.0)
        centre_x, centre_y = 0.5 * (box[0] + box[2] - 1), 0.5 * (box[1] + box[3] - 1)
        assert refined.rate == pytest.approx(0.2, rel=0.003)
        assert refined.drift_x == pytest.approx(2.0 + 0.2 * (centre_x - 199.5), abs=0.05), side
        assert refined.drift_y == pytest.approx(-1.0 + 0.2 * (centre_y - 199.5), abs=0.05), side


def test_the_refinement_s_bound_settle_and_start_as_documented():
    tex, box = _texture(), (150, 150, 250, 250)
    after = warp(tex, 1.25, dx=3.0)
    est = region_expansion(tex, after, box)
    # a guess below the answer: the bound is twice the larger of the guess and the fit, and
    # the result the guess's motion scaled to it
    guess = est._replace(rate=0.75 * est.rate)
    bounded = refined_expansion(tex, after, box, est, guess)
    assert bounded.rate == pytest.approx(2 * est.rate)
    assert bounded.drift_x == pytest.approx(guess.drift_x * bounded.rate / guess.rate)
    # a step that moves the edge by less than 'settled' is the last: with a settled no step
    # can pass, one step is all, however many are allowed
    start = est._replace(rate=0.22)
    assert refined_expansion(tex, after, box, est, start, iterations=5, settled=1e9) == \
        refined_expansion(tex, after, box, est, start, iterations=1)
    # a start that does not expand (exactly 0 too) is left as it was
    zero = est._replace(rate=0.0)
    assert refined_expansion(tex, after, box, zero) is zero
    # frames that shrink, from a guess of slight growth: the fit's contraction, widened by
    # the bound, lets the steps find the shrink (5 % a frame: a rate of -0.048)
    after = warp(tex, 1 / 1.05)
    est = region_expansion(tex, after, box)
    assert est.rate < 0
    shrink = refined_expansion(tex, after, box, est, est._replace(rate=0.01))
    assert shrink.rate == pytest.approx(1 / 1.05 - 1, rel=0.1)


def test_translation_is_drift_not_expansion():
    tex = _texture()
    est = region_expansion(tex, warp(tex, dx=0.6, dy=-0.4), (150, 150, 250, 250))
    assert abs(est.rate) < 0.002
    assert est.drift_x == pytest.approx(0.6, abs=0.1) and est.drift_y == pytest.approx(-0.4,
                                                                                        abs=0.1)


def test_an_off_centre_box_of_an_expanding_surface_drifts_outwards():
    # the expansion centre (focus of expansion) at the image centre, the box to its right: the
    # box's centre moves right at rate * distance, which is what makes a passing object's
    # offset large
    tex = _texture()
    est = region_expansion(tex, warp(tex, 1.02), (250, 170, 310, 230))
    assert est.rate == pytest.approx(0.02, rel=0.3)
    assert est.drift_x == pytest.approx(0.02 * 80, rel=0.35)


def test_a_brightness_change_is_not_read_as_motion():
    tex = _texture()
    est = region_expansion(tex, tex + 0.05, (150, 150, 250, 250))
    assert abs(est.rate) < 1e-3 and abs(est.drift_x) < 0.05 and abs(est.drift_y) < 0.05
    assert est.brightness == pytest.approx(0.05, rel=0.05)


def test_the_fit_tells_one_expanding_surface_from_two_sliding_apart():
    # two halves of a box moving apart, as a car and the verge do behind it, read as expansion
    # by least squares; the fit says the motion does not explain them as one surface
    tex = _texture()
    box = (150, 150, 250, 250)
    apart = np.hstack([warp(tex, dx=-1.0)[:, :200], warp(tex, dx=1.0)[:, 200:]])
    split = region_expansion(tex, apart, box)
    assert split.rate > 0.01 and split.fit < 0.4
    for moved in (warp(tex, 1.02), warp(tex, 1 / 1.02), warp(tex, dx=0.6, dy=-0.4)):
        assert region_expansion(tex, moved, box).fit > 0.8
    assert region_expansion(tex, warp(tex, 1.02), (100, 100, 300, 300)).fit > 0.6  # averaged


def test_the_scene_is_fitted_without_the_objects_boxes():
    # the scene expands about the frame's centre; inside a box right of it an object recedes
    tex = texture((400, 400), blur=8.0)
    current = warp(tex, 1.02)
    box = (230, 160, 330, 240)
    x0, y0, x1, y1 = box
    current[y0:y1, x0:x1] = warp(tex, 1 / 1.03)[y0:y1, x0:x1]
    scene = scene_expansion(tex, current, [box])
    assert scene.rate == pytest.approx(0.02, rel=0.3)
    assert abs(scene.drift_x) < 0.05 and abs(scene.drift_y) < 0.05
    # with the object counted as scene, its inward motion drags the scene's drift
    assert scene_expansion(tex, current, []).drift_x < -0.2
    # what the scene's motion predicts for pixels outside the box: the scenery's motion
    moved = moved_by_expansion(tex, scene, (100, 60, 180, 120))
    assert (np.abs(moved - current[60:120, 100:180]).mean()
            < 0.3 * np.abs(tex[60:120, 100:180] - current[60:120, 100:180]).mean())
    assert moved_by_expansion(tex, scene, box).shape == (y1 - y0, x1 - x0)


def test_the_scene_fit_takes_its_last_frame_s_average_from_its_memo():
    # three frames of a scene expanding about the centre, shrunk by whole factors (320 x 240 to
    # 64 x 48): the second fit reads the first one's average of the frame they share
    tex = texture((240, 320), blur=4.0)
    frames = [tex, warp(tex, 1.02), warp(tex, 1.04)]
    box = [(140, 100, 180, 140)]
    kept = [None, None]
    for before, after in zip(frames, frames[1:]):
        assert scene_expansion(before, after, box, kept=kept) == scene_expansion(before, after, box)
        assert kept[0] is after and kept[1].shape == (48, 64)
    # a memo of another frame is not read
    kept[1] = kept[1] + 1.0
    assert scene_expansion(frames[0], frames[1], box, kept=kept) == scene_expansion(
        frames[0], frames[1], box)


def test_the_scene_fit_takes_the_surface_watch_s_averages():
    # the surface watch has both frames shrunk (320 x 240 to 64 x 48, as the scene's fit
    # shrinks them): the scene's fit reads them instead of averaging the frames again
    from asnn.approach.surface import SurfaceWatch

    tex = texture((240, 320), blur=4.0)
    frames = [tex, warp(tex, 1.02), warp(tex, 1.04)]
    box = [(140, 100, 180, 140)]
    watch = SurfaceWatch()
    assert watch.averages() == ()
    for before, after in zip(frames, frames[1:]):
        watch.step(before, after, 0.05, 2.0, 0.5)
        averaged = watch.averages()
        assert [frame is image for (frame, _), image in zip(averaged, (before, after))] == [
            True, True]
        assert scene_expansion(before, after, box, averaged=averaged) == scene_expansion(
            before, after, box)
    # they are read (an average changed changes the fit), for those very frames only
    (before, low), (after, high) = averaged
    changed = ((before, low), (after, high + 0.1))
    assert scene_expansion(before, after, box, averaged=changed) != scene_expansion(
        before, after, box)
    assert scene_expansion(frames[0], frames[1], box, averaged=changed) == scene_expansion(
        frames[0], frames[1], box)


def test_the_scene_fit_reads_an_average_given_for_its_frame_at_its_own_size_only():
    # averaged pairs are (frame, its area average): one of another size (a watch on another
    # grid) is not the fit's 64 x 48 grid, and is not read in its place
    tex = texture((240, 320), blur=4.0)
    before, after = tex, warp(tex, 1.02)
    box = [(140, 100, 180, 140)]
    other = tuple((frame, cv2.resize(frame, (32, 24), interpolation=cv2.INTER_AREA))
                  for frame in (before, after))
    assert scene_expansion(before, after, box, averaged=other) == scene_expansion(
        before, after, box)


def test_a_mask_shrunk_by_whole_factors_is_opencvs_area_average_over_a_quarter():
    # counted in a kernel where the frame shrinks by a whole factor, by OpenCV elsewhere (a
    # view, a fractional factor): the same pixels either way
    rng = np.random.default_rng(6)
    for h, w, size in ((240, 320, (64, 48)), (240, 320, (160, 120)), (128, 192, (64, 43)),
                       (60, 80, (20, 15)), (100, 90, (30, 33))):
        for share in (0.05, 0.2, 0.3, 0.6):
            mask = rng.random((h, w)) < share
            mask[: h // 3, : w // 3] = True  # whole blocks set, and blocks a quarter set
            mask[h // 2: h // 2 + 3, :] = False
            want = cv2.resize(mask.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.25
            assert np.array_equal(shrunk_mask(mask, size), want)
            assert np.array_equal(shrunk_mask(mask[:, :w - 5], size), cv2.resize(
                mask[:, :w - 5].astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.25)


def test_an_empty_box_moved_by_the_scene_is_empty():
    # a track's box clipped to the frame is empty once the track has moved out of it (seen on a
    # real clip: the scene-relative refit then failed to broadcast the whole frame into it)
    tex = _texture(100)
    scene = Expansion(0.5, -0.2, 0.01, 0.0, 0.9)
    assert moved_by_expansion(tex, scene, (100, 10, 100, 40)).shape == (30, 0)
    assert moved_by_expansion(tex, scene, (104, 10, 100, 40)).shape == (30, 0)
    assert moved_by_expansion(tex, scene, (10, 50, 40, 50)).shape == (0, 30)

def test_excluded_pixels_are_left_out_of_the_fit():
    # an expanding surface behind a still, textured band along the bottom (a camera's hood):
    # fitted with the band, the box reads a slower expansion; without it, the surface's own
    base = texture(seed=3)
    previous, current = base, warp(base, 1.03)
    band = np.zeros(base.shape, bool)
    band[90:] = True
    hood = texture(seed=4)
    previous, current = (np.where(band, hood, image) for image in (previous, current))
    box = (10, 10, 150, 115)
    diluted = region_expansion(previous, current, box).rate
    kept = region_expansion(previous, current, box, exclude=band).rate
    assert diluted < 0.8 * kept
    assert kept == pytest.approx(region_expansion(base, warp(base, 1.03), box).rate, rel=0.1)
    # a box large enough to be area-averaged leaves them out too
    assert region_expansion(previous, current, (0, 0, 160, 120), exclude=band).rate == \
        pytest.approx(kept, rel=0.2)
    # for a box the mask does not reach, nothing changes
    assert region_expansion(previous, current, (10, 10, 150, 80), exclude=band) == \
        region_expansion(previous, current, (10, 10, 150, 80))



def test_the_rim_scales_a_diluted_expansion_up_and_keeps_the_box_s_offset():
    box = Expansion(drift_x=0.3, drift_y=-0.4, rate=0.02, brightness=0.01, fit=0.5)
    scaled = rim_scaled(box, Expansion(9.0, 9.0, 0.05, 0.0, 0.9))
    # the rim's rate, the box's drift scaled alike: drift / rate (the offset) stays
    assert scaled.rate == 0.05
    assert (scaled.drift_x, scaled.drift_y) == pytest.approx((0.75, -1.0))
    assert (scaled.brightness, scaled.fit) == (box.brightness, box.fit)
    # never a longer time to contact, never an expansion the box does not read
    assert rim_scaled(box, Expansion(0.0, 0.0, 0.01, 0.0, 0.9)) is box
    assert rim_scaled(box, None) is box
    receding = box._replace(rate=-0.02)
    assert rim_scaled(receding, Expansion(0.0, 0.0, 0.05, 0.0, 0.9)) is receding
    assert rim_scaled(None, box) is None


def test_the_rim_counts_only_within_the_fit_s_small_motion_range():
    box = Expansion(drift_x=0.3, drift_y=-0.4, rate=0.02, brightness=0.01, fit=0.5)
    rim = Expansion(0.0, 0.0, 0.2, 0.0, 0.9)
    # a 40-px box: 0.2 * 40 / 2 = 4 px at its edge, at the limit; past it the box stands
    assert rim_scaled(box, rim, 40, 4.0).rate == 0.2
    assert rim_scaled(box, rim, 41, 4.0) is box
    assert rim_scaled(box, rim, 41, None).rate == 0.2
    # a box larger than 64 px is fitted on a 64-px grid: its motion there is what counts
    assert rim_scaled(box, rim, 300, 6.4).rate == 0.2
    assert rim_scaled(box, rim, 300, 6.3) is box


def _rig_means(frames):
    change, mean = np.zeros_like(frames[0]), frames[0].copy()
    for before, now in zip(frames, frames[1:]):
        change += RIG_WEIGHT * (np.abs(now - before) - change)
        mean += RIG_WEIGHT * (now - mean)
    return change, mean


def test_the_rig_is_the_still_edges_at_the_top_and_bottom_of_the_frame():
    # a textured scene sliding a pixel a frame; along the bottom, a hood with a bright rim and
    # lettering, the same in every frame, and lettering at the top; the same still lettering in
    # the middle of the frame
    rng = np.random.default_rng(5)
    scene = rng.random((80, 200)).astype(np.float32)
    still = rng.random((6, 30)).astype(np.float32)
    frames = []
    for k in range(30):
        frame = scene[:, k:k + 120].copy()
        frame[66:] = 0.15  # the hood: uniform, so no edge to mark inside it
        frame[64:66] = 0.8  # its rim
        frame[70:76, 10:40] = still  # the recorder's timestamp
        frame[2:8, 80:110] = still  # another, at the top
        frame[37:43, 60:90] = still  # the same, where the scene ahead is
        frames.append(frame)
    change, mean = _rig_means(frames)
    rig = rig_pixels(change, mean, len(frames))
    assert rig[64:67].all()  # the rim and the hood edge beneath it
    assert rig[71:75, 12:38].mean() > 0.5 and rig[3:7, 82:108].mean() > 0.5  # the letters
    assert not rig[10:60].any()  # the moving scene, and the middle of the frame
    assert not rig[:10, :70].any()  # the moving scene at the top
    assert not rig[68:, 50:].any()  # the hood's uniform inside
    assert rig_pixels(change, mean, 15) is None  # too few frames to tell


def test_a_flat_or_tiny_box_has_no_estimate():
    flat = np.full((100, 100), 0.5, np.float32)
    assert region_expansion(flat, flat, (10, 10, 60, 60)) is None
    tex = _texture(100)
    assert region_expansion(tex, tex, (10, 10, 13, 40)) is None


def _random_boxes(rng, count):
    """Frames and boxes of every kind the looming fit meets: float32 and float64, boxes from
    5 pixels across to the whole frame, touching its borders, thin ones (one side not shrunk
    or shrunk to one sample), and whole shrink factors."""
    for i in range(count):
        dtype = np.float64 if i % 3 == 0 else np.float32
        h, w = rng.integers(5, 420, 2)
        if i % 11 == 0:
            h, w = 2 * rng.integers(33, 100), 128  # by a factor of 2 (or more) both ways
        x0, y0 = int(rng.integers(0, w - 4)), int(rng.integers(0, h - 4))
        x1, y1 = int(rng.integers(x0 + 5, w + 1)), int(rng.integers(y0 + 5, h + 1))
        if i % 5 == 0:
            x0, y0, x1, y1 = 0, 0, int(w), int(h)
        elif i % 7 == 0:
            y1 = y0 + 5  # one side far shorter
        previous = rng.random((h, w)).astype(dtype)
        current = (previous + 0.1 * rng.standard_normal((h, w))).astype(dtype)
        background = (previous + 0.05 * rng.standard_normal((h, w))).astype(dtype)
        yield previous, current, background, (x0, y0, x1, y1)


def test_the_fits_area_averages_are_opencvs():
    """The looming fit's area averages (looming._area_averages, in numba with the fit) are
    cv2.resize's INTER_AREA, bit for bit, wherever it does not shrink by whole factors."""
    import cv2

    from asnn._fast import _area_fast, _area_table
    from asnn.approach.looming import _area_averages

    rng = np.random.default_rng(16)
    checked = 0
    for previous, current, background, (x0, y0, x1, y1) in _random_boxes(rng, 600):
        w = int(rng.integers(1, x1 - x0 + 1))
        h = int(rng.integers(1, y1 - y0 + 1))
        if _area_fast((x1 - x0, y1 - y0), (w, h)):
            continue
        images = (previous, current, background)
        rows = np.empty((3, y1 - y0, w), previous.dtype)
        out = np.empty((3, h, w), previous.dtype)
        _area_averages(images, y0, x0, _area_table(x1 - x0, w), _area_table(y1 - y0, h), rows,
                       out)
        for image, got in zip(images, out):
            want = cv2.resize(np.ascontiguousarray(image[y0:y1, x0:x1]), (w, h),
                              interpolation=cv2.INTER_AREA)
            np.testing.assert_array_equal(got, want)
        checked += 1
    assert checked > 500


def test_the_fit_of_a_large_box_is_that_of_opencvs_area_averages():
    """region_expansion, which area-averages a large box in numba with the fit, gives the
    estimate of the fit over cv2.resize's area averages (how it was computed before), bit for
    bit, with and without a background."""
    import cv2

    from asnn.approach.looming import _NO_SKIP, _RIDGE, _solve_expansion

    def with_opencv(previous, current, box, background):
        x0, y0, x1, y1 = box
        images = [a[y0:y1, x0:x1] for a in (previous, current, background)]
        step = max(x1 - x0, y1 - y0) / 64
        if step > 1.0:
            size = (max(round((x1 - x0) / step), 1), max(round((y1 - y0) / step), 1))
            images = [cv2.resize(np.ascontiguousarray(a), size, interpolation=cv2.INTER_AREA)
                      for a in images]
        else:
            step = 1.0
        solved, a, b, c, d, fit = _solve_expansion(*images, _NO_SKIP, _NO_SKIP, _RIDGE)[:6]
        return (a * step, b * step, c, d, fit) if solved else None

    rng = np.random.default_rng(17)
    for i, (previous, current, background, box) in enumerate(_random_boxes(rng, 400)):
        if i % 4 == 0:
            current = previous.copy()  # no change: no gradient of time to fit
        got = region_expansion(previous, current, box, background)
        assert (None if got is None else tuple(got)) == with_opencv(previous, current, box,
                                                                    background)
        got = region_expansion(previous, current, box)
        assert (None if got is None else tuple(got)) == with_opencv(previous, current, box,
                                                                    previous)



def test_the_box_and_its_rim_in_one_pass_are_the_two_fits_bit_for_bit():
    """region_and_rim_expansion gives the box's fit and the fit with every pixel off the rim
    left out too, as two calls of region_expansion would, bit for bit, with and without pixels
    to exclude and a background; where the box is area-averaged, with the rim sampled at the
    centres of the smaller box's pixels: a rim over the whole box is the box, a rim off every
    centre leaves nothing to fit."""
    from asnn.approach.looming import FIT_SIDE

    rng = np.random.default_rng(18)
    averaged = 0
    for i, (previous, current, background, box) in enumerate(_random_boxes(rng, 300)):
        h, w = previous.shape
        rim = rng.random((h, w)) < (0.2, 0.6)[i % 2]
        exclude = None if i % 3 else rng.random((h, w)) < 0.1
        reference = background if i % 4 else None
        x0, y0, x1, y1 = box
        whole = region_expansion(previous, current, box, reference, exclude)
        got = region_and_rim_expansion(previous, current, box, rim, reference, exclude)
        assert got[0] == whole
        if max(x1 - x0, y1 - y0) <= FIT_SIDE:
            off = ~rim if exclude is None else ~rim | exclude
            assert got[1] == region_expansion(previous, current, box, reference, off)
            continue
        averaged += 1
        everywhere = np.ones_like(rim)
        assert region_and_rim_expansion(previous, current, box, everywhere, reference,
                                        exclude) == (whole, whole)
        assert region_and_rim_expansion(previous, current, box, ~everywhere, reference,
                                        exclude)[1] is None
    assert averaged > 50

def _obs(x, y, size=10.0, mass=1.0):
    return Observation(x, y, size, mass, (x - size, y - size, x + size, y + size))


def test_tracks_keep_their_ids_and_new_objects_get_new_ones():
    tracker = TargetTracker()
    first = tracker.update([_obs(50, 50), _obs(150, 60)], 0.05)
    ids = [tr.id for tr in first]
    assert ids == [0, 1]
    second = tracker.update([_obs(153, 61), _obs(52, 49), _obs(300, 300)], 0.05)
    assert [tr.id for tr in second] == [1, 0, 2]
    for _ in range(4):  # unseen for longer than max_missed (3): forgotten
        tracker.update([], 0.05)
    assert tracker.tracks == []
    assert tracker.update([_obs(50, 50)], 0.05)[0].id == 3


def test_time_to_contact_and_offset_follow_from_expansion_and_drift():
    track = Track(0, 100.0, 100.0, 20.0, 1.0, (80, 80, 120, 120))
    track.measure(2.0, 30.0, 40.0)  # grows by 200 % per second, drifts 50 px/s
    assert track.ttc == pytest.approx(0.5)
    assert track.offset == pytest.approx(50.0 / (2.0 * 20.0))
    track.measure(-1.0, 0.0, 0.0)  # smoothed: (2 + -1) / 2
    assert track.expansion == pytest.approx(0.5)
    shrinking = Track(1, 0.0, 0.0, 5.0, 1.0, (0, 0, 10, 10))
    shrinking.measure(-0.5, 0.0, 0.0)
    assert shrinking.ttc is None and shrinking.offset is None


def test_the_reported_expansion_follows_a_constant_speed_approach_and_lets_a_halt_go():
    dt, tau = 0.1, 2.0
    track, lagging = (Track(i, 0.0, 0.0, 10.0, 1.0, (0, 0, 20, 20)) for i in range(2))
    for k in range(15):  # the exact rate each frame: tau falls by dt
        rate = 1.0 / (tau - k * dt)
        track.measure_reported(rate, dt)
        lagging.measure(rate, 0.0, 0.0)
        assert track.reported_ttc == pytest.approx(tau - k * dt, rel=1e-9)
    assert lagging.ttc > 1.1 * track.reported_ttc  # the gate's average trails it (0.68 s)
    assert track.expansion is None  # the gate's own estimate is not touched
    # a prediction runs to infinity within a frame of contact: the rate at most doubles
    assert track.predicted_expansion(1.0) == pytest.approx(2 * track.reported_expansion)
    # an object that stops: its time to contact lengthens from the first frame
    ttcs = [track.reported_ttc]
    for _ in range(4):
        track.measure_reported(0.0, dt)
        ttcs.append(track.reported_ttc)
    assert all(b > 1.5 * a for a, b in zip(ttcs, ttcs[1:]))
    fresh = Track(2, 0.0, 0.0, 10.0, 1.0, (0, 0, 20, 20))
    assert fresh.predicted_expansion(dt) is None and fresh.reported_ttc is None
    fresh.measure_reported(-0.5, dt)  # the first measure as it is; a shrinking target: no ttc
    assert fresh.reported_expansion == -0.5 and fresh.reported_ttc is None
    assert fresh.predicted_expansion(dt) == -0.5


def test_the_reported_expansion_weighs_a_new_measure_by_the_track_smoothing():
    # track_smoothing is the new measure's weight, against the prediction from the frames
    # before (only at its default, 0.5, are the two interchangeable)
    dt = 0.1
    for smoothing in (1.0, 0.25):
        track = Track(0, 0.0, 0.0, 10.0, 1.0, (0, 0, 20, 20), _smoothing=smoothing)
        track.measure_reported(0.5, dt)
        predicted = track.predicted_expansion(dt)
        track.measure_reported(0.8, dt)
        assert track.reported_expansion == pytest.approx(
            predicted + smoothing * (0.8 - predicted))
    assert track.reported_expansion != pytest.approx(0.8)
    # a rate of exactly 0 (an object that stopped dead, or a first measure of none) has no
    # time to contact rather than an infinite one
    still = Track(1, 0.0, 0.0, 10.0, 1.0, (0, 0, 20, 20))
    still.measure_reported(0.0, dt)
    assert still.reported_expansion == 0.0 and still.reported_ttc is None


def test_the_approach_test_needs_growth_a_collision_course_and_consecutive_frames():
    coming = Track(0, 0.0, 0.0, 20.0, 1.0, (0, 0, 40, 40))
    coming.measure(1.0, 5.0, 0.0)  # ttc 1 s, offset 0.25
    assert approaching(coming, tau_max=1.5, offset_max=1.0)
    assert not approaching(coming, tau_max=0.8, offset_max=1.0)
    assert not approaching(coming, tau_max=1.5, offset_max=0.2)
    assert [coming.judge(1.5, 1.0, 3) for _ in range(4)] == [False, False, True, True]
    passing = Track(1, 0.0, 0.0, 20.0, 1.0, (0, 0, 40, 40))
    passing.measure(1.0, 60.0, 0.0)  # drifts 3 sizes per unit of growth: it will pass
    assert not any(passing.judge(1.5, 1.0, 1) for _ in range(3))


def test_a_partial_overlap_passes_later_and_only_from_a_box_that_moves_as_one():
    overlap = (1.0, 2.0, 0.4)  # ttc <= 1 s, offset <= 2, fit >= 0.4
    corner = Track(0, 0.0, 0.0, 20.0, 1.0, (0, 0, 40, 40))
    corner.measure(1.25, 40.0, 0.0, fit=0.6)  # ttc 0.8 s, offset 1.6: a corner strike
    assert not approaching(corner, tau_max=1.5, offset_max=1.0)
    assert approaching(corner, tau_max=1.5, offset_max=1.0, overlap=overlap)
    early = Track(1, 0.0, 0.0, 20.0, 1.0, (0, 0, 40, 40))
    early.measure(0.8, 25.6, 0.0, fit=0.6)  # the same offset, 1.25 s away: not yet
    assert not approaching(early, tau_max=1.5, offset_max=1.0, overlap=overlap)
    mixed = Track(2, 0.0, 0.0, 20.0, 1.0, (0, 0, 40, 40))
    mixed.measure(1.25, 40.0, 0.0, fit=0.2)  # two motions in one box
    assert not approaching(mixed, tau_max=1.5, offset_max=1.0, overlap=overlap)
    mixed.measure(1.25, 40.0, 0.0, fit=0.8)  # the fit is smoothed: (0.2 + 0.8) / 2
    assert mixed.fit == pytest.approx(0.5)
    assert approaching(mixed, tau_max=1.5, offset_max=1.0, overlap=overlap)
    wide = Track(3, 0.0, 0.0, 20.0, 1.0, (0, 0, 40, 40))
    wide.measure(1.25, 75.0, 0.0, fit=0.9)  # offset 3: the next lane
    assert not approaching(wide, tau_max=1.5, offset_max=1.0, overlap=overlap)


def test_a_slow_stream_needs_fewer_frames_of_approach():
    from asnn.approach.tracking import persistence_frames

    # 3 frames span 0.1 s at 20 fps; at 30 fps they span less, and 3 stay the most asked for
    assert [persistence_frames(3, 0.1, period) for period in (1 / 30, 0.05, 1 / 15, 0.1, 0.2)] \
        == [3, 3, 3, 2, 2]
    assert persistence_frames(3, 0.1, 2 / 20) == 2  # timestamps that read 0.0999... apart
    assert persistence_frames(4, 0.1, 0.04) == 4 and persistence_frames(1, 0.1, 0.01) == 1
    assert persistence_frames(3, None, 0.2) == 3  # without approach_seconds: always frames


def test_the_frame_period_is_the_median_of_the_last_frames():
    from asnn import ASNN

    model = ASNN("robust")
    frame = np.zeros((48, 64), np.uint8)
    assert model.frame_period == pytest.approx(0.05)  # before any period is measured
    for t in (0.0, 0.1, 0.2, 0.3, 0.5, 0.6):  # 10 fps with one frame lost on the way
        model.step(frame + int(t * 100), t)
    assert list(model.periods) == pytest.approx([0.1, 0.1, 0.1, 0.2, 0.1])
    assert model.frame_period == pytest.approx(0.1)
    for t in (0.65, 0.7, 0.75):  # the camera speeds up to 20 fps
        model.step(frame + int(t * 100), t)
    assert model.frame_period == pytest.approx(0.05)


def test_stamps_too_close_to_time_a_stream_by_read_as_the_nominal_period():
    """Stamps a subnormal number apart (k * 5e-324 s) gave a period whose inverse is infinite:
    every step of an approach raised OverflowError (a hostile-wire round)."""
    from asnn import ASNN, TimingWarning
    from asnn.stimuli import make_scene

    scene = make_scene("looming")
    model, untimed = ASNN("robust"), ASNN("robust")
    with pytest.warns(TimingWarning, match="e-324 s after the frame before"):
        warned = [model.step(frame, k * 5e-324).collision for k, frame in enumerate(scene.frames)]
    assert warned == [untimed.step(frame, None).collision for frame in scene.frames]
    assert any(warned) and model.frame_period == pytest.approx(0.05)


def test_an_approach_persists_in_its_region_across_tracks():
    from asnn.approach.tracking import Observation, boxes_overlap, persists_in_region

    box = (10.0, 10.0, 30.0, 30.0)
    inside, beside, apart = (20.0, 0.0, 40.0, 15.0), (30.0, 10.0, 50.0, 30.0), (60, 60, 80, 80)
    assert persists_in_region(box, [[inside], [apart, inside]], 3)
    assert not persists_in_region(box, [[inside], [apart]], 3)
    assert not persists_in_region(box, [[beside], [beside]], 3)  # touching is not overlapping
    assert persists_in_region(box, [], 1)
    assert boxes_overlap(box, inside) and not boxes_overlap(box, beside)

    def frame(tracker, observations, passes):
        """One frame: observations, each track's measurement (passing or drifting past)."""
        tracks = tracker.update(observations, 0.05)
        for track, ok in zip(tracks, passes):
            track.measure(1.0, 5.0 if ok else 60.0, 0.0)  # ttc 1 s; offset 0.25 or 3
        return tracker.judge(tracks, 1.5, 1.0, 3)

    # a walker's fragments: its head, its feet, its head again, each a new track (far apart
    # in the frame, so they do not link), boxes overlapping the walker's region
    head, feet = Observation(50, 20, 5, 1, (30, 0, 70, 60)), Observation(50, 95, 5, 1, (30, 50, 70, 110))
    region = TargetTracker(max_missed=0, region_frames=3)
    per_track = TargetTracker(max_missed=0)
    for tracker, expected in ((region, [False, False, True]), (per_track, [False, False, False])):
        seen = [frame(tracker, [head], [True]), frame(tracker, [feet], [True]),
                frame(tracker, [head], [True])]
        assert [any(s) for s in seen] == expected
    # a track that does not pass now never counts, whatever passed around it
    quiet = TargetTracker(max_missed=0, region_frames=3)
    frame(quiet, [head], [True])
    frame(quiet, [feet], [True])
    assert frame(quiet, [head], [False]) == [False]
    # a fragment overlapping a track that counts by its own frames is that object's: not a
    # second target
    both = TargetTracker(max_missed=0, region_frames=3)
    assert frame(both, [head], [True]) == [False]
    assert frame(both, [head, feet], [True, True]) == [False, False]
    assert frame(both, [head, feet], [True, True]) == [True, False]
    # on a slow stream two frames suffice, and the region looks back as many frames
    slow = TargetTracker(max_missed=0, region_frames=3)
    for observation, expected in ((head, [False]), (feet, [True]), (head, [True])):
        tracks = slow.update([observation], 0.1)
        tracks[0].measure(1.0, 5.0, 0.0)
        assert slow.judge(tracks, 1.5, 1.0, 2) == expected
    # a frame with nothing in it is a frame of the window too
    gap = TargetTracker(max_missed=0, region_frames=3)
    frame(gap, [head], [True])
    frame(gap, [], [])
    frame(gap, [], [])
    assert frame(gap, [feet], [True]) == [False]
    with pytest.raises(ValueError):
        TargetTracker(region_frames=-1)


def test_a_large_track_over_small_passing_ones_has_not_persisted():
    from asnn.approach.tracking import Observation, box_cover, persists_in_region

    large, small, half = (0.0, 0.0, 100.0, 60.0), (40.0, 20.0, 55.0, 30.0), (0.0, 0.0, 50.0, 60.0)
    assert box_cover(large, small) == pytest.approx(150 / 6000)
    assert box_cover(small, large) == 1.0 and box_cover(large, half) == 0.5
    assert box_cover(large, (200.0, 200.0, 210.0, 210.0)) == 0.0
    assert box_cover((5.0, 5.0, 5.0, 9.0), large) == 0.0  # an empty box
    assert persists_in_region(large, [[small], [small]], 3)  # any overlap
    assert not persists_in_region(large, [[small], [small]], 3, 0.2)
    assert persists_in_region(large, [[small, half], [half]], 3, 0.2)
    assert persists_in_region(small, [[large], [large]], 3, 1.0)

    def run(cover, earlier):
        """Two frames of a small passing track (a new one each frame), then a large track that
        takes it in: whether the large one counts."""
        tracker = TargetTracker(max_missed=0, region_frames=3, region_cover=cover)
        # centres far apart, so the tracks do not link: only their boxes meet
        for y, box in ((20.0, earlier), (95.0, earlier), (170.0, large)):
            tracks = tracker.update([Observation(50.0, y, 5.0, 1.0, box)], 0.05)
            tracks[0].measure(1.0, 5.0, 0.0)  # ttc 1 s, offset 0.25: passing
            coming = tracker.judge(tracks, 1.5, 1.0, 3)
        return coming == [True]

    assert run(0.0, small) and not run(0.2, small)  # a few reflections taken in with the road
    assert run(0.2, half)  # fragments of one object, each a fair part of it
    for cover in (-0.1, 1.5):
        with pytest.raises(ValueError):
            TargetTracker(region_frames=3, region_cover=cover)


def test_a_fragment_is_named_after_the_object_it_appears_over():
    from asnn.approach.tracking import Observation, fragment_of

    assert fragment_of((0, 0, 10, 10), 5, [(3, (5, 5, 20, 20)), (1, (8, 0, 30, 9))]) == 1
    assert fragment_of((0, 0, 10, 10), 5, [(7, (5, 5, 20, 20))]) is None  # younger
    assert fragment_of((0, 0, 10, 10), 5, [(3, (10, 0, 20, 10))]) is None  # touching

    def frame(tracker, observations, passes):
        tracks = tracker.update(observations, 0.05)
        for track, ok in zip(tracks, passes):
            track.measure(1.0, 5.0 if ok else 60.0, 0.0)  # ttc 1 s; offset 0.25 or 3
        coming = tracker.judge(tracks, 1.5, 1.0, 3)
        return [(tracker.object_id(track), ok) for track, ok in zip(tracks, coming)]

    # an object's track counts; a fragment appears over it (far enough from its centre not to
    # link), and the object's own track is lost while the fragment goes on counting
    body = Observation(50, 20, 5, 1, (30, 0, 70, 60))
    rim = Observation(50, 55, 5, 1, (30, 40, 70, 70))
    named = TargetTracker(max_missed=0, region_frames=3, object_ids=True)
    plain = TargetTracker(max_missed=0, region_frames=3)
    for tracker in (named, plain):
        for _ in range(3):
            frame(tracker, [body], [True])
    assert frame(named, [body, rim], [True, True]) == [(0, True), (0, False)]
    assert frame(plain, [body, rim], [True, True]) == [(0, True), (1, False)]
    assert frame(named, [rim], [True]) == [(0, True)]  # by region persistence, as the object
    assert frame(plain, [rim], [True]) == [(1, True)]
    # a fragment of a fragment takes the object's name; the object's own track has died
    far = Observation(50, 90, 5, 1, (30, 65, 70, 110))
    assert frame(named, [far], [True]) == [(0, True)]
    # a track that counted under its own id keeps it, whatever it overlaps later
    own = TargetTracker(max_missed=0, object_ids=True)
    ahead = Observation(150, 20, 5, 1, (130, 0, 170, 40))
    for _ in range(3):
        frame(own, [body, ahead], [True, True])
    assert frame(own, [body, ahead], [True, True]) == [(0, True), (1, True)]
    moved = Observation(150, 20, 5, 1, (60, 0, 170, 40))  # its box now reaches the other's
    assert frame(own, [body, moved], [True, True]) == [(0, True), (1, True)]
    # the names live as long as the tracks: a long stream does not accumulate them
    for _ in range(3):
        frame(named, [], [])
    assert named.tracks == [] and named._object_of == {} and not named._named


def test_the_scene_relative_test_tolerates_a_fraction_of_the_tracks_expansion():
    from asnn.approach.tracking import against_scene

    assert against_scene(None) and against_scene(0.0) and not against_scene(-0.01)
    assert against_scene(-0.2, expansion=2.5, tolerance=0.1)
    assert not against_scene(-0.3, expansion=2.5, tolerance=0.1)
    assert not against_scene(-0.01, expansion=-1.0, tolerance=0.1)  # a shrinking track: none


def test_an_object_approaching_by_its_own_motion_counts_more():
    from asnn.approach.tracking import own_motion_weight

    # a parked car we drive at: its expansion is the scene's, left out of its own
    assert own_motion_weight(0.2, 2.0, 2.0, 0.75) == 1.0
    # a car turning across our path: the scene explains little of its expansion
    assert own_motion_weight(1.9, 2.0, 2.0, 0.75) == 2.0
    assert own_motion_weight(1.5, 2.0, 2.0, 0.75) == 2.0  # the ratio itself passes
    assert own_motion_weight(1.9, 2.0, 1.0, 0.75) == 1.0  # weight 1: the stage is off
    # not measured, or not growing: as any object
    assert own_motion_weight(None, 2.0, 2.0, 0.75) == 1.0
    assert own_motion_weight(1.0, None, 2.0, 0.75) == 1.0
    assert own_motion_weight(-1.0, -0.5, 2.0, 0.75) == 1.0


def test_tracker_rejects_a_smoothing_outside_its_range():
    with pytest.raises(ValueError):
        TargetTracker(smoothing=0.0)
    with pytest.raises(ValueError):
        TargetTracker(box_weight=1.5)
    assert math.isfinite(TargetTracker(smoothing=1.0).smoothing)


def test_objects_are_those_of_the_components_of_the_whole_mask():
    """extract_objects labels the attended pixels by runs: the regions, and their order, are
    those of OpenCV's components of the whole mask."""
    import cv2

    from asnn.targets import extract_objects

    rng = np.random.default_rng(5)
    for _ in range(200):
        h, w = rng.integers(31, 120, 2)
        mask = np.zeros((h, w), bool)
        y0, x0 = rng.integers(0, h - 4), rng.integers(0, w - 4)
        y1, x1 = rng.integers(y0 + 1, h + 1), rng.integers(x0 + 1, w + 1)
        mask[y0:y1, x0:x1] = rng.random((y1 - y0, x1 - x0)) < rng.random()
        if not mask.any():
            continue
        g = rng.random((h, w)).astype(np.float32)
        regions = extract_objects(mask, g, lambda r, c: (r * 0.0, c * 0.0), 3, True)
        count, labels, stats, _ = cv2.connectedComponentsWithStats(
            mask.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
        kept = stats[1:][stats[1:, cv2.CC_STAT_AREA] >= 3]
        np.testing.assert_array_equal(regions.pixels, kept[:, cv2.CC_STAT_AREA])
        np.testing.assert_array_equal(regions.boxes[:, 0], kept[:, cv2.CC_STAT_LEFT])
        np.testing.assert_array_equal(regions.boxes[:, 1], kept[:, cv2.CC_STAT_TOP])
        rows, cols = np.nonzero(mask)
        lab = labels[rows, cols]
        for k, label in enumerate(np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= 3) + 1):
            inside = lab == label
            want = np.abs(g[rows[inside], cols[inside]].astype(float)).sum()
            assert regions.share[k] == pytest.approx(want, rel=1e-12)


def _random_masks(rng, count):
    """Masks of every kind the objects' labelling meets: empty, full, single pixels, noise,
    blobs touching the border, diagonal chains; odd and even sizes down to one pixel."""
    yield np.zeros((7, 9), bool)
    yield np.ones((1, 1), bool)
    yield np.ones((5, 8), bool)
    chain = np.zeros((9, 9), bool)
    chain[np.arange(9), np.arange(9)] = True  # one component through diagonals only
    chain[0, 8] = chain[8, 0] = True  # single pixels in the corners
    yield chain
    for i in range(count):
        h, w = rng.integers(1, 140, 2)
        mask = np.zeros((h, w), bool)
        kind = i % 4
        if kind == 0:
            mask[:] = rng.random((h, w)) < rng.random()
        elif kind == 1:
            y0, x0 = rng.integers(0, h), rng.integers(0, w)
            y1, x1 = rng.integers(y0 + 1, h + 1), rng.integers(x0 + 1, w + 1)
            mask[y0:y1, x0:x1] = rng.random((y1 - y0, x1 - x0)) < rng.random()
        elif kind == 2:
            yy, xx = np.ogrid[:h, :w]
            for _ in range(rng.integers(0, 8)):
                cy, cx, r = rng.integers(-5, h + 5), rng.integers(-5, w + 5), rng.integers(0, 20)
                mask |= (yy - cy) ** 2 + (xx - cx) ** 2 <= r * r
            mask &= rng.random((h, w)) < 0.97
        else:
            mask.flat[rng.integers(0, h * w, rng.integers(0, 30))] = True
        yield mask


@pytest.mark.parametrize("threads", [1, 2])
def test_the_objects_components_are_opencvs(threads):
    """The labelling by runs (targets._components) gives OpenCV's 8-connected components of
    the mask, in OpenCV's order, with its statistics (with one OpenCV thread or more: the
    parallel labelling numbers them the same way)."""
    import cv2

    from asnn.targets import _components

    saved = cv2.getNumThreads()
    cv2.setNumThreads(threads)
    try:
        for mask in _random_masks(np.random.default_rng(14), 1500):
            rows, cols = np.nonzero(mask)
            labels, stats = _components(rows, cols)
            count, want, want_stats, _ = cv2.connectedComponentsWithStats(
                mask.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
            np.testing.assert_array_equal(labels, want[rows, cols] - 1)
            np.testing.assert_array_equal(stats, want_stats[1:, [
                cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP, cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT,
                cv2.CC_STAT_AREA]].reshape(count - 1, 5))
    finally:
        cv2.setNumThreads(saved)


def test_the_objects_moments_are_those_of_numpy_sums_over_opencvs_components():
    """extract_objects' regions, bit for bit: OpenCV's components of at least min_pixels
    pixels, their boxes and pixel counts, and the G-weighted moments as ``np.bincount`` sums
    them, in the pixels' row-major order (how the labelling was done before the runs)."""
    import cv2

    from asnn.targets import extract_objects

    rng = np.random.default_rng(15)
    for i, mask in enumerate(_random_masks(rng, 600)):
        g = rng.standard_normal(mask.shape).astype(np.float32)
        if i % 5 == 0:
            g = -np.abs(g)  # regions without positive G: equal weights
        min_pixels, absolute = int(rng.integers(1, 6)), bool(i % 2)
        regions = extract_objects(mask, g, None, min_pixels, absolute)
        count, labels, stats, _ = cv2.connectedComponentsWithStats(
            mask.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
        keep = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= min_pixels)
        n = len(keep)
        lut = np.full(count, -1)
        lut[keep + 1] = np.arange(n)
        kept = stats[keep + 1]
        rows, cols = np.nonzero(mask)
        lab = lut[labels[rows, cols]]
        rows, cols, lab = rows[lab >= 0], cols[lab >= 0], lab[lab >= 0]
        values = g[rows, cols].astype(np.float64)
        share = np.bincount(lab, np.abs(values) if absolute else values, n)
        mass = np.bincount(lab, np.maximum(values, 0.0), n)
        weight = np.where(mass[lab] > 0, np.maximum(values, 0.0), 1.0)
        total = np.bincount(lab, weight, n)
        x = np.bincount(lab, weight * cols, n) / total
        y = np.bincount(lab, weight * rows, n) / total
        var = np.bincount(lab, weight * ((cols - x[lab]) ** 2 + (rows - y[lab]) ** 2), n) / total
        left, top = kept[:, cv2.CC_STAT_LEFT], kept[:, cv2.CC_STAT_TOP]
        for got, want in [
                (regions.boxes, np.stack([left, top, left + kept[:, cv2.CC_STAT_WIDTH],
                                          top + kept[:, cv2.CC_STAT_HEIGHT]], 1).reshape(n, 4)),
                (regions.pixels, kept[:, cv2.CC_STAT_AREA]), (regions.share, share),
                (regions.mass, mass), (regions.x, x), (regions.y, y),
                (regions.size, np.sqrt(var + 1.0)),
                *zip(regions.members, (rows, cols, lab))]:
            np.testing.assert_array_equal(got, want)


def test_the_objects_motion_is_computed_when_first_read_and_only_then():
    """extract_objects leaves the regions' mean motion (direction, energy) until it is read:
    the model reads it only for the objects it reports, and a frame without an approaching
    object reports none. Read, it is the mean of the vectors over each region's pixels."""
    from asnn.targets import extract_objects

    rng = np.random.default_rng(8)
    mask = np.zeros((60, 80), bool)
    mask[5:20, 10:30] = True
    mask[30:55, 40:75] = rng.random((25, 35)) < 0.9
    g = rng.random(mask.shape).astype(np.float32)
    dx_map, dy_map = rng.standard_normal((2, *mask.shape))
    calls = []

    def vectors(rows, cols):
        calls.append(len(rows))
        return dx_map[rows, cols], dy_map[rows, cols]

    regions = extract_objects(mask, g, vectors, 30, False)
    assert len(regions) == 2 and calls == []
    direction, energy = regions.direction, regions.energy
    assert calls == [int(regions.pixels.sum())]  # once, for both
    assert regions.direction is direction and regions.energy is energy
    for k, (y0, y1, x0, x1) in enumerate([(5, 20, 10, 30), (30, 55, 40, 75)]):
        inside = mask[y0:y1, x0:x1]
        vx, vy = dx_map[y0:y1, x0:x1][inside].mean(), dy_map[y0:y1, x0:x1][inside].mean()
        assert direction[k] == pytest.approx(math.atan2(vy, vx), rel=1e-12)
        assert energy[k] == pytest.approx(math.hypot(vx, vy), rel=1e-12)


def test_the_rig_s_edge_test_is_opencv_s_sobel_pair_bit_for_bit():
    """The kernel of ``rig_pixels`` computes the 3x3 Sobel pair in OpenCV's float32 order (each
    separable pass summing its outer taps first): where an edge or a change lies right at a
    threshold, another order would mark another pixel."""
    import cv2

    from asnn.approach.looming import _RIG_BAND, _RIG_EDGE, _RIG_SPEED

    def edge_of(mean):
        mean = mean.astype(np.float32)
        return 0.125 * (np.abs(cv2.Sobel(mean, cv2.CV_32F, 1, 0, ksize=3))
                        + np.abs(cv2.Sobel(mean, cv2.CV_32F, 0, 1, ksize=3)))

    def with_opencv(change, mean):
        edge = edge_of(mean)
        rig = (edge > _RIG_EDGE) & (change < _RIG_SPEED * edge)
        band = int(_RIG_BAND * mean.shape[0])
        rig[band:mean.shape[0] - band] = False
        return rig

    rng = np.random.default_rng(11)
    marked = 0
    for h, w in [(4, 1), (5, 2), (9, 3), (48, 64), (61, 97), (120, 160)]:
        for dtype in (np.float32, np.float64):
            mean = (rng.random((h, w)) * 0.05).astype(dtype)
            change = (rng.random((h, w)) * 0.004).astype(dtype)
            # half the pixels changing exactly at the threshold OpenCV's edge gives: an edge one
            # rounding away from it flips them
            at = rng.random((h, w)) < 0.5
            change[at] = (_RIG_SPEED * edge_of(mean))[at]
            want = with_opencv(change, mean)
            got = rig_pixels(change, mean, 20)
            assert np.array_equal(np.zeros_like(want) if got is None else got, want), (h, w)
            marked += int(want.sum())
    assert marked > 100  # the thresholds were reached: the comparison tells something


def test_the_rig_mask_is_doubled_as_opencv_s_nearest_resize_doubles_it():
    import cv2

    from asnn.approach.stage import _nearest

    rng = np.random.default_rng(12)
    for hh, ww in [(1, 1), (3, 5), (60, 80), (120, 216)]:
        mask = rng.random((hh, ww)) < 0.3
        for h, w in [(2 * hh, 2 * ww), (2 * hh + 1, 2 * ww), (2 * hh, 2 * ww + 1)]:
            want = cv2.resize(mask.view(np.uint8), (w, h),
                              interpolation=cv2.INTER_NEAREST).view(bool)
            assert np.array_equal(_nearest(mask, h, w), want), (hh, ww, h, w)


def test_an_object_whose_track_misses_the_test_for_a_frame_keeps_its_id():
    """At 60 fps the disk's track failed the approach test for one frame and a track counted
    through its region took over under an id of its own: one object, two ids (a targets
    audit)."""
    from asnn import ASNN
    from asnn.stimuli.planar import planar_scene

    scene = planar_scene("loom", fps=60, height=24, tau=2.0, contrast=1.0, polarity="dark",
                         onset=30)
    model = ASNN("default")
    ids = {target.id for k, frame in enumerate(scene.frames)
           for target in model.step(frame, k / 60).targets if k <= scene.contact_frame}
    assert len(ids) == 1


def test_a_stream_is_timed_by_gaps_from_a_10_khz_camera_to_a_second():
    from asnn.params import MAX_FRAME_GAP_S, MIN_FRAME_GAP_S, timed_gap

    assert timed_gap(MIN_FRAME_GAP_S) and timed_gap(MAX_FRAME_GAP_S) and timed_gap(1 / 240)
    assert not timed_gap(MIN_FRAME_GAP_S / 2) and not timed_gap(1.5) and not timed_gap(0.0)
    assert not timed_gap(float("nan"))


def test_without_region_persistence_a_fragment_is_named_after_the_frame_before():
    from asnn.approach.tracking import Observation, TargetTracker

    tracker = TargetTracker(max_missed=0, region_frames=0, object_ids=True)
    body = Observation(50, 20, 5, 1, (30, 0, 70, 60))
    rim = Observation(50, 55, 5, 1, (30, 40, 70, 70))

    def frame(observations):
        tracks = tracker.update(observations, 0.05)
        for track in tracks:
            track.measure(1.0, 5.0, 0.0)  # ttc 1 s, offset 0.25: passes
        coming = tracker.judge(tracks, 1.5, 1.0, 3)
        return [(tracker.object_id(track), ok) for track, ok in zip(tracks, coming)]

    for _ in range(3):
        frame([body])
    assert frame([body, rim]) == [(0, True), (0, False)]  # over the counting body: its id


def test_a_shrunk_mask_leaves_out_a_pixel_a_quarter_of_which_it_covers():
    from asnn.approach.looming import shrink_step, shrunk_mask, shrunk_size

    assert shrink_step(128, 64) == 2.0 and shrink_step(60, 40) == 1.0
    assert shrunk_size(128, 64, 2.0) == (64, 32) and shrunk_size(3, 1, 4.0) == (1, 1)
    mask = np.zeros((128, 128), bool)
    mask[0, :2] = True  # half of the shrunk pixel (0, 0)
    mask[0, 4] = True  # a quarter of (0, 2)
    shrunk = shrunk_mask(mask, (64, 64))
    assert shrunk[0, 0] and not shrunk[0, 2] and shrunk.sum() == 1


# ---------------------------------------------------------------- mutation-probe additions


def test_a_target_that_neither_grows_nor_shrinks_has_no_time_to_contact():
    still = Track(0, 50.0, 50.0, 10.0, 1.0, (40, 40, 60, 60))
    still.measure(0.0, 3.0, 4.0)  # an expansion of exactly 0 (a still camera, a still object)
    assert still.ttc is None and still.offset is None
    assert not approaching(still, tau_max=1.5, offset_max=1.0)


def test_frames_of_approach_must_be_in_a_row_a_frame_that_fails_starts_the_count_again():
    track = Track(0, 0.0, 0.0, 20.0, 1.0, (0, 0, 40, 40))
    track.measure(1.0, 5.0, 0.0)  # ttc 1 s, offset 0.25: passes
    assert [track.judge(1.5, 1.0, 3) for _ in range(2)] == [False, False]
    track.missed = 1  # unseen for a frame: fails the test
    assert track.judge(1.5, 1.0, 3) is False and track.streak == 0
    track.missed = 0
    assert [track.judge(1.5, 1.0, 3) for _ in range(3)] == [False, False, True]


def test_a_10_fps_stream_timed_by_float_stamps_needs_two_frames_of_approach():
    from asnn.approach.tracking import persistence_frames

    period = 0.3 - 0.2  # 0.09999999999999998: stamps 0.1 s apart, as floats subtract
    assert period < 0.1 and persistence_frames(3, 0.1, period) == 2
    assert persistence_frames(3, 0.1, 0.05) == 3


def test_the_strongest_track_takes_an_observation_two_tracks_compete_for():
    tracker = TargetTracker()
    strong = Observation(0.0, 0.0, 5.0, 10.0, (-5, -5, 5, 5))
    weak = Observation(20.0, 0.0, 5.0, 1.0, (15, -5, 25, 5))
    a, b = tracker.update([strong, weak], 0.05)
    between = Observation(10.0, 0.0, 5.0, 5.0, (5, -5, 15, 5))  # within reach of both
    (seen,) = tracker.update([between], 0.05)
    assert seen.id == a.id and a.missed == 0 and b.missed == 1


def test_region_persistence_looks_back_over_the_frames_the_stream_needs_now():
    """At a slow rate a track needs fewer frames (persistence_frames): 2 of a tracker built for
    3. Its region's history is then the previous frame only (2 - 1 of the previous 2), not
    three frames back."""

    def run(passing_at):
        tracker = TargetTracker(max_missed=0, region_frames=3)
        first = Observation(50.0, 50.0, 1.0, 1.0, (0, 0, 100, 100))
        for frame in (1, 2, 3):
            tracks = tracker.update([first] if frame == passing_at else [], 0.1)
            for track in tracks:
                track.measure(1.0, 0.0, 0.0)  # ttc 1 s, offset 0: passes
            assert tracker.judge(tracks, 1.5, 1.0, 2) == [False] * len(tracks)
        other = Observation(90.0, 50.0, 1.0, 1.0, (50, 0, 150, 100))  # a new track, overlapping
        (track,) = tracker.update([other], 0.1)
        track.measure(1.0, 0.0, 0.0)
        return tracker.judge([track], 1.5, 1.0, 2)

    assert run(passing_at=3) == [True]  # the frame before: persisted in its region
    assert run(passing_at=1) == [False]  # three frames back: outside the 2 frames it needs


def test_a_tracks_box_carries_the_previous_box_grown_by_its_expansion():
    track = Track(0, 5.0, 5.0, 5.0, 1.0, (0.0, 0.0, 10.0, 10.0))
    track.measure(1.0, 0.0, 0.0)  # grows 100 % per second, no drift
    track.observe(Observation(5.0, 5.0, 5.0, 1.0, (0.0, 0.0, 10.0, 10.0)), elapsed=1.0,
                  box_weight=0.5)
    # the previous box carried over 1 s: (-5, -5, 15, 15); half of it, half the observation's
    assert track.box == pytest.approx((-2.5, -2.5, 12.5, 12.5))


def test_a_trackers_memory_of_earlier_frames_stays_within_its_window():
    tracker = TargetTracker(region_frames=3, object_ids=True)
    obs = Observation(50.0, 50.0, 5.0, 1.0, (40, 40, 60, 60))
    for _ in range(200):
        tracks = tracker.update([obs], 0.05)
        for track in tracks:
            track.measure(1.0, 0.0, 0.0)
        tracker.judge(tracks, 1.5, 1.0, 3)
    assert len(tracker._passed) <= 4 and len(tracker._counted) <= 3


def test_a_motion_layer_that_does_not_expand_has_no_time_to_contact():
    from asnn.approach.tracking import layer_estimates

    assert layer_estimates([(0.5, 0.0, 3.0, 4.0), (0.5, 2.0, 3.0, 4.0)], 10.0) == (
        (0.5, None, None), (0.5, 0.5, pytest.approx(5.0 / 20.0)))


def test_the_partial_overlap_regime_takes_the_better_of_the_box_s_two_fits():
    overlap = (1.0, 2.0, 0.4)  # ttc <= 1 s, offset <= 2, fit >= 0.4
    for fit, own_fit in [(0.2, 0.6), (0.6, 0.2)]:
        track = Track(0, 0.0, 0.0, 20.0, 1.0, (0, 0, 40, 40))
        track.measure(1.25, 37.5, 0.0, fit=fit)  # ttc 0.8 s, offset 1.5: an overlap
        track.measure_own(1.0, own_fit)
        assert approaching(track, tau_max=0.5, offset_max=1.0, overlap=overlap), (fit, own_fit)


def test_a_uniform_disk_with_a_one_pixel_edge_approaching_at_constant_speed_reads_its_ttc():
    """The reported time to contact of the simplest object, a uniform dark disk whose edge is
    one pixel wide, approaching at constant speed (radius R tau_end / (T - t)): within a few
    per cent of T - t. (The paper's looming disk grows linearly instead, which no approach at
    constant speed does, and reads short against its own r / (dr/dt): the track's smoothing
    predicts the time to contact falling with the frames' time, where that disk's rises.)"""
    from asnn import ASNN
    from asnn.stimuli.paper import _disk_coverage

    fps, contact, (w, h) = 20.0, 3.0, (160, 120)
    frames = 58
    reach = 0.45 * h * (contact - (frames - 1) / fps)  # radius x time to contact: 2.7-54 px
    model, errors = ASNN("default"), []
    for k in range(frames):
        radius = reach / (contact - k / fps)
        image = 200.0 - 160.0 * _disk_coverage(h, w, w / 2, h / 2, radius)
        response = model.step(np.rint(image).astype(np.uint8), k / fps)
        errors += [t.ttc / (contact - k / fps) - 1 for t in response.targets
                   if t.ttc is not None]
    assert len(errors) >= 15
    assert abs(np.median(errors)) < 0.03 and np.percentile(np.abs(errors), 90) < 0.06
