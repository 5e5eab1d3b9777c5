"""Background stabilisation (asnn.stabilisation): the translation found, when it is refused,
the shifted images, the looming fit that leaves the background out, and the model's threads."""

import numpy as np
import pytest

from asnn import ASNN, preset
from asnn.approach.looming import region_expansion
from asnn.stabilisation import _accepted, _on_edge, background_shift, search_radius, shift_image
from cached_cases import make_case
from imageutil import texture, warp


@pytest.mark.parametrize("dx", range(-3, 4))
@pytest.mark.parametrize("dy", [-3, -1, 0, 2])
def test_the_translation_of_a_textured_frame_is_found(dx, dy):
    before = texture()
    after = shift_image(before, dx, dy, border=texture(seed=1))
    assert background_shift(before, after, 3, 0.5) == (dx, dy)


def test_no_translation_beyond_the_radius_or_for_an_expanding_frame():
    before = texture()
    assert background_shift(before, shift_image(before, 5, 0, border=0.5), 3, 0.5) == (0, 0)
    assert background_shift(before, warp(before, 1.04), 3, 0.5) == (0, 0)
    assert background_shift(before, before, 3, 0.5) == (0, 0)
    assert background_shift(before[:6, :6], before[:6, :6], 3, 0.5) == (0, 0)


def test_an_object_moving_over_a_still_textured_scene_is_not_the_background():
    scene = texture()
    patch = texture((30, 30), seed=2, blur=1.0)
    before, after = scene.copy(), scene.copy()
    before[40:70, 50:80] = patch
    after[40:70, 52:82] = patch
    assert background_shift(before, after, 3, 0.5) == (0, 0)
    # ... while the same scene panned is
    assert background_shift(before, shift_image(before, 2, 0, border=before), 3, 0.5) == (2, 0)


def test_an_object_drifting_over_a_plain_scene_is_not_the_background():
    # over a plain wall the drifting patch is all that changes, so its own translation explains
    # the whole frame's change: only the tiles tell that nothing else moved with it
    before = np.full((120, 160), 0.5)
    after = before.copy()
    patch = texture((30, 30), seed=2, blur=1.0)
    before[40:70, 50:80] = patch
    after[40:70, 52:82] = patch
    assert background_shift(before, after, 3, 0.5) == (2, 0)
    assert background_shift(before, after, 3, 0.5, spread=0.5) == (0, 0)
    # a pan moves in every tile, and is still found
    scene = texture()
    assert background_shift(scene, shift_image(scene, 2, -1, border=scene), 3, 0.5,
                            spread=0.5) == (2, -1)


def _shifts(case, scale=None):
    """Frames of a suite case in which the default's search accepts a translation, without and
    with its tile test."""
    scene, p = make_case(case, scale=scale), preset("default")
    frames = [f.astype(np.float64) / 255.0 for f in scene.frames]
    radius = search_radius(frames[0].shape[1], p.stabilise_radius, p.stabilise_reach)
    return tuple(sum(background_shift(a, b, radius, p.stabilise_share, spread) != (0, 0)
                     for a, b in zip(frames, frames[1:]))
                 for spread in (0.0, p.stabilise_spread))


def test_near_misses_keep_their_drift_and_shaken_cameras_their_stabilisation():
    assert preset("default").stabilise_spread == 0.5
    # a disk growing as it drifts past over a plain background: in a third of the frames its
    # drift explained most of the frame's change, and was taken out there, so that the disk
    # grew as if it came straight at us
    without, with_tiles = _shifts("nearmiss-disk-dark-right")
    assert without > 20 and with_tiles == 0
    # drawn at 480x360, a disk growing at the centre: along the few rows the search compares,
    # its top and bottom edges looked like a vertical translation
    without, with_tiles = _shifts("loom-dark-c0.5-d12-center", scale=3)
    assert without > 20 and with_tiles == 0
    for case in ("loom-dark-c0.6-shake-3px", "loom-dark-c0.5-over-stripes-h2px"):
        without, with_tiles = _shifts(case)
        assert with_tiles == without > 50


def test_the_search_radius_grows_with_the_frame_s_width():
    assert [search_radius(w, 3, 1 / 64) for w in (80, 160, 192, 216, 320, 432, 480)] == [
        3, 3, 3, 4, 5, 7, 8]
    assert search_radius(480, 3, None) == 3
    # without the input scale a wide frame would search far: the cost is bounded
    assert search_radius(3840, 3, 1 / 64) == 16
    # the radius found that way takes out a translation the fixed one cannot
    before = texture((120, 320))
    after = shift_image(before, 5, 0, border=0.5)
    assert background_shift(before, after, search_radius(320, 3, 1 / 64), 0.5) == (5, 0)
    assert background_shift(before, after, 3, 0.5) == (0, 0)


def test_a_jump_beyond_the_radius_is_found_by_the_wider_search():
    assert search_radius(320, 3, 1 / 64, 2.0) == 10
    assert search_radius(480, 3, 1 / 64, 2.0) == 16  # at most 16 px
    before = texture()
    after = shift_image(before, 5, -4, border=texture(seed=1))
    # within 3 px the best lies on the search's edge, and explains too little
    assert background_shift(before, after, 3, 0.5) == (0, 0)
    assert background_shift(before, after, 3, 0.5, wider=6) == (5, -4)
    # within the radius the wider search changes nothing, not even where it is made
    for dx, dy in ((3, 0), (-2, 3), (1, 1)):
        after = shift_image(before, dx, dy, border=texture(seed=1))
        assert background_shift(before, after, 3, 0.5, wider=6) == (dx, dy)


def test_the_wider_search_keeps_the_first_choice_where_costs_tie_along_stripes():
    # vertical stripes sliding sideways: every vertical shift costs the same, and the first
    # search takes the first of them, on its edge; the wider search finds no clearly better one
    x = np.arange(160)
    before = np.tile(0.5 + 0.4 * np.sin(2 * np.pi * x / 16.0), (120, 1)).astype(np.float32)
    after = shift_image(before, 2, 0, border=before)
    first = background_shift(before, after, 3, 0.5)
    assert first[0] == 2 and abs(first[1]) == 3
    assert background_shift(before, after, 3, 0.5, wider=6) == first


def test_the_share_a_translation_must_explain():
    # the upper half pans, the lower half changes into another texture: the pan explains a
    # part of the frame's change (about a third), not most of it
    before = texture()
    after = shift_image(before, 2, 0, border=before)
    after[60:] = texture(seed=3)[60:]
    assert background_shift(before, after, 3, 0.1) == (2, 0)
    assert background_shift(before, after, 3, 0.5) == (0, 0)


def _accepted_in_numpy(tile_costs, costs, share, spread):
    """The acceptance test as NumPy computed it before its kernel (asnn.stabilisation)."""
    radius = costs.shape[-1] // 2
    dy, dx = divmod(int(np.argmin(costs)), costs.shape[1])
    still = costs[radius, radius]
    if still == 0 or costs[dy, dx] > (1.0 - share) * still:
        return 0, 0
    if spread > 0.0:
        before, after = tile_costs[:, :, radius, radius], tile_costs[:, :, dy, dx]
        explained = np.count_nonzero((before > 0) & (after <= (1.0 - 0.5 * share) * before))
        if explained < spread * 16:
            return 0, 0
    return dx - radius, dy - radius


def test_the_acceptance_kernels_decide_as_numpy_did():
    # few distinct costs, so that the best ties and the thresholds are met exactly
    rng = np.random.default_rng(0)
    decided = set()
    for trial in range(3000):
        radius = int(rng.integers(1, 6))
        n = 2 * radius + 1
        tile_costs = rng.integers(0, 6, (4, 4, n, n)) * int(rng.choice([1, 1000]))
        share, spread = float(rng.choice([0.1, 0.5, 0.75])), float(rng.choice([0.0, 0.5, 1.0]))
        if trial % 2:
            # a translation that explains all of some tiles' change and, at share 0.5, just
            # the tile test's half of the others' (or one unit less)
            share, spread = 0.5, float(rng.choice([0.25, 0.5, 0.75]))
            tile_costs += 40
            still = rng.choice([0, 4, 8], (4, 4))
            tile_costs[:, :, radius, radius] = still
            tile_costs[:, :, rng.integers(n), rng.integers(n)] = np.where(
                rng.random((4, 4)) < 0.5, 0, still * 3 // 4 + rng.integers(0, 2, (4, 4)))
        costs = tile_costs.sum(axis=(0, 1))
        expected = _accepted_in_numpy(tile_costs, costs, share, spread)
        assert _accepted(tile_costs, costs, share, spread) == expected, trial
        dy, dx = divmod(int(np.argmin(costs)), n)
        assert _on_edge(costs) == (dy in (0, n - 1) or dx in (0, n - 1)), trial
        decided.add(expected != (0, 0))
    assert decided == {True, False}


def test_shift_image_moves_the_last_two_axes_and_fills_what_nothing_moved_into():
    image = np.arange(2 * 5 * 6, dtype=np.float64).reshape(2, 5, 6)
    moved = shift_image(image, 2, -1, border=-1.0)
    np.testing.assert_array_equal(moved[:, :4, 2:], image[:, 1:, :4])
    assert (moved[:, 4, :] == -1).all() and (moved[:, :, :2] == -1).all()
    fill = np.full_like(image, 7.0)
    assert (shift_image(image, -1, 2, border=fill)[:, :2, :] == 7).all()
    np.testing.assert_array_equal(shift_image(image, 0, 0), image)


def test_the_looming_fit_leaves_out_the_background_that_slides_past():
    # a textured disk grows by 4 % at the centre of a texture sliding 2 px to the right
    ground, disk = texture(seed=4), texture(seed=5, blur=1.5)
    y, x = np.mgrid[0:120, 0:160]
    inside = (x - 80.0) ** 2 + (y - 60.0) ** 2 < 24.0 ** 2
    grown = warp(inside.astype(np.float32), 1.04) > 0.5
    before = np.where(inside, disk, ground).astype(np.float32)
    after = np.where(grown, warp(disk, 1.04), shift_image(ground, 2, 0, border=ground))
    after = after.astype(np.float32)
    box = (46, 26, 114, 94)
    plain = region_expansion(before, after, box)
    steady = region_expansion(before, after, box, shift_image(before, 2, 0, border=after))
    assert abs(steady.drift_x) < 0.2 and abs(steady.drift_y) < 0.2
    assert abs(plain.drift_x) > 3 * abs(steady.drift_x)
    assert 0.02 < steady.rate < 0.06
    # without a background the result is that of the fit over every pixel
    assert region_expansion(before, after, box, None) == plain


def test_threads_change_nothing_while_the_background_is_taken_out():
    scene = make_case("loom-dark-c0.5-over-stripes-h2px")
    params = preset("default", approach_gate=False)  # every object's activity in u and targets
    lum = [ASNN(params)._luminance(f) for f in scene.frames]
    assert sum(background_shift(a, b, 3, 0.5) != (0, 0) for a, b in zip(lum, lum[1:])) > 60
    one = ASNN(params)
    expected = [one.step(f, i / scene.fps) for i, f in enumerate(scene.frames)]
    assert sum(r.u > 0 for r in expected) > 30
    for threads in (2, 3):
        with ASNN(params, threads=threads) as model:
            got = list(model.stream((i / scene.fps, f) for i, f in enumerate(scene.frames)))
        assert got == expected, threads


def test_stabilisation_is_off_in_the_published_variant():
    assert not preset("reference").stabilise and not preset("reference32").stabilise
    assert preset("default").stabilise


def test_both_forms_take_the_background_out_alike():
    # with a photoreceptor history (n_p > 0) too
    scene = make_case("loom-light-c0.5-over-stripes-h2px")
    params = preset("default", n_p=2, approach_gate=False)
    fast, slow = ASNN(params), ASNN(params, optimised=False)
    for i, frame in enumerate(scene.frames):
        a, b = fast.step(frame, i / scene.fps), slow.step(frame, i / scene.fps)
        assert abs(a.u - b.u) <= 1e-4 * max(abs(b.u), 1e-6), i
        assert (a.spikes, a.collision) == (b.spikes, b.collision), i
