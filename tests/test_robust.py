"""The default (robust) preset on generated clips: one test group per point of issue 12, each
showing what the corresponding stage does by switching it off (the ablation specs of
asnn.evaluation.runs)."""

import dataclasses
import json
import math

import numpy as np
import pytest

from asnn import ASNN, FrameError, preset
from cached_cases import make_case

OFF_LED_ONLY = dict(w1_on=0.0, w2_off=0.0)  # the published variant's OFF-led map alone
NO_GATE = dict(approach_gate=False)
NO_OFFSET_TEST = dict(offset_max=1000.0)
NO_CONTRAST_GAIN = dict(contrast_gain=None)
NO_LIGHT_ADAPTATION = dict(contrast_light=None)
NO_NIGHT_GATE = dict(contrast_light_spread=None)
NO_STABILISATION = dict(stabilise=False)
NO_SCENE_RELATIVE = dict(scene_relative=False)
NO_PARTIAL_OVERLAP = dict(partial_overlap=False)
NO_FIT_TEST = dict(overlap_fit_min=-1.0)
NO_MOTION_LAYERS = dict(motion_layers=False)
NO_RIG = dict(ignore_rig=False)
NO_RIM = dict(rim_expansion=False)
NO_RIM_LIMIT = dict(rim_motion_max=None)
NO_OWN_MOTION_WEIGHT = dict(own_motion_weight=1.0)
NO_GLOBAL_GAIN = dict(global_gain=None)
NO_EDGE_RULE = dict(receding_edge_rule=False)
NO_NOISE_SUMMATION = dict(noise_summation=None)
NO_TEMPORAL_SUMMATION = dict(temporal_summation=None)


def _run(case, variant=0, perturbation=None, scale=None, every=1, **overrides):
    """The robust preset's responses to a case, on every ``every``-th frame (at its times)."""
    from asnn.evaluation.perturb import perturb_frame

    scene = make_case(case, variant, scale=scale)
    model = ASNN(preset("robust", **overrides))
    frames = (scene.frames if perturbation is None
              else [perturb_frame(f, perturbation, i) for i, f in enumerate(scene.frames)])
    # each response indexed by its frame's number in the case, as the labels count
    responses = [dataclasses.replace(model.step(f, i / scene.fps), index=i)
                 for i, f in enumerate(frames) if i % every == 0]
    return scene, responses


def _first(responses, warmup=5):
    return next((r.index for r in responses if r.collision and r.index >= warmup), None)


def _hit(scene, responses):
    first = _first(responses)
    return first is not None and scene.onset_frame <= first <= scene.contact_frame + 2


def _quiet(responses):
    return _first(responses) is None


def _real_clip(name):
    """A clip of ``../shared/data/real``: its frames (a fresh iterator each call) and its label;
    the test is skipped where the clip is absent."""
    from asnn.io.video import open_video
    from shared_data import SHARED

    folder = SHARED / "data" / "real"
    if not (folder / name).exists():
        pytest.skip(f"{folder / name} is absent")
    label = next(entry for entry in json.loads((folder / "labels.json").read_text())
                 if entry["file"] == name)
    return (lambda: open_video(folder / name)), label


def test_the_default_preset_is_robust():
    assert ASNN().params == preset("robust")


# 1. both polarities: one preset for dark and light objects, silent while either recedes

@pytest.mark.parametrize("case", ["loom-light-c0.3-d12-center", "loom-light-c0.6-d12-bottomleft",
                                  "loom-dark-c0.3-d12-center"])
def test_dark_and_light_approaches_warn_with_one_preset(case):
    assert _hit(*_run(case))


def test_light_approaches_need_the_on_led_map():
    assert not _hit(*_run("loom-light-c0.3-d12-center", **OFF_LED_ONLY))


@pytest.mark.parametrize("case", ["recede-dark-c0.6-d48", "recede-light-c0.6-d48"])
def test_receding_objects_of_either_polarity_stay_silent(case):
    assert _quiet(_run(case)[1])


def test_recession_is_silenced_by_the_approach_gate():
    # without the gate the approach map's activity of a receding object reaches the spikes
    assert not _quiet(_run("recede-dark-c0.6-d48", **NO_GATE)[1])


# 2. contrast: Weber 0.2 and up detected, the response growing with contrast

@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_low_contrast_approaches_warn_as_early_as_high_contrast_ones(polarity):
    low = _first(_run(f"loom-{polarity}-c0.2-d12-center")[1])
    high = _first(_run(f"loom-{polarity}-c1.0-d12-center")[1])
    assert low is not None and high is not None and low - high <= 2


def test_the_contrast_gain_control_is_what_makes_low_contrast_warn_early():
    low = _first(_run("loom-dark-c0.2-d12-center", **NO_CONTRAST_GAIN)[1])
    high = _first(_run("loom-dark-c1.0-d12-center", **NO_CONTRAST_GAIN)[1])
    assert low is not None and high is not None and low - high >= 8


def test_the_response_grows_with_contrast_instead_of_being_cut_off():
    peaks = [max(r.u for r in _run(f"loom-dark-c{c}-d12-center")[1])
             for c in ("0.2", "0.5", "1.0")]
    assert peaks[0] > 0 and peaks[0] < peaks[1] < peaks[2]


# 3. backgrounds and the camera: silent for translation, patterns, camera motion, lighting and
#    noise; approaches over them still detected; the warning ends with the approach

@pytest.mark.parametrize("case", ["translate-disk-dark-c0.6-h2px", "translate-square-dark-c0.6-diag3px",
                                  "translate-car-light-c0.6-h4px-left", "bar-dark-c1.0-h3px",
                                  "stripes-diagonal-c1.0-3px", "checker-c1.0-diag2px",
                                  "texture-c0.5-diag3px", "shake-texture-4px-rot1deg",
                                  "pan-scene-h3px", "flicker-sine-8hz-30pct",
                                  "exposure-step-up-2.0", "headlights-sweep-night", "noise-gauss-10",
                                  "jpeg-q8", "drive-day-straight", "drive-day-turn-left",
                                  "handheld-desk-sweep"])
def test_translation_patterns_camera_lighting_and_noise_stay_silent(case):
    assert _quiet(_run(case)[1])


@pytest.mark.parametrize("case", ["translate-disk-dark-c0.6-h2px", "drive-day-straight",
                                  "handheld-desk-sweep"])
def test_translation_and_driving_are_silenced_by_the_approach_gate(case):
    # what the stabilisation leaves of them is the gate's: a lone object's drift is its own
    # motion (tests/test_stabilisation.py), forward motion expands, the desk's props slide over
    # the wall the stabilisation holds still
    assert not _quiet(_run(case, **NO_GATE)[1])


@pytest.mark.parametrize("case", ["loom-dark-c0.3-over-texture-h1px",
                                  "loom-dark-c0.5-over-texture-diag2px", "loom-dark-c0.6-pan-h1px",
                                  "loom-dark-c0.6-flicker-4hz", "loom-dark-c0.6-headlights",
                                  "loom-dark-c0.3-noise-6", "loom-light-c0.5-jpeg-q20"])
def test_approaches_over_moving_backgrounds_lighting_and_noise_are_detected(case):
    assert _hit(*_run(case))


@pytest.mark.parametrize("case", ["loom-light-c0.5-over-stripes-h2px",
                                  "loom-dark-c0.5-over-checker-diag2px"])
def test_approaches_over_a_fast_sliding_background_need_stabilisation(case):
    # the stripes and the checkerboard slide 2 px per frame: their edges carry several times
    # the motion energy of the object's rims, and the direction inhibition removes both
    assert _hit(*_run(case))
    assert not _hit(*_run(case, **NO_STABILISATION))


@pytest.mark.parametrize("case", ["loom-dark-c0.5-over-checker-diag2px",
                                  "loom-dark-c0.6-shake-3px"])
def test_a_camera_with_more_pixels_searches_as_far_for_the_background_s_motion(case):
    # at twice the size (320x240) the checkerboard slides 4 px a frame and the shake jolts the
    # image by 5.6 px or less in half of its frames: beyond the 3 px the search covers at
    # 160 px wide, much of it within the 5 it covers at 320 (both without the wider search at
    # the edge, which from 3 px would reach 6)
    assert _hit(*_run(case, perturbation="double-size", stabilise_wider=None))
    assert not _hit(*_run(case, perturbation="double-size", stabilise_reach=None,
                          stabilise_wider=None))
    # at the suite's own size the search is the same 3 px, warning for warning
    assert ([r.collision for r in _run(case)[1]]
            == [r.collision for r in _run(case, stabilise_reach=None)[1]])


def test_a_shaken_camera_s_jolts_beyond_the_radius_are_searched_for():
    # drawn at 320x240 the shake jolts the image by up to 10.7 px from one frame to the next,
    # beyond the 5 px the search covers there: searched again up to 10 where the best lies on
    # the edge, those frames are stabilised too
    assert preset("default").stabilise_wider == 2.0
    assert _hit(*_run("loom-dark-c0.6-shake-3px", scale=2))
    assert not _hit(*_run("loom-dark-c0.6-shake-3px", scale=2, stabilise_wider=None))



def test_an_approach_over_a_sliding_pattern_is_timed_by_its_rim():
    # drawn at 320x240 the checkerboard slides 4 px a frame: where the disk's outline occludes
    # it, the pattern's pixels stay in the box's fit and read as a surface that does not
    # expand, so the box reads 1.5-3 s to contact where 0.4-1.2 s are left, and the disk never
    # passes the approach test for long; its rim alone reads the faster expansion
    assert preset("default").rim_expansion
    assert _hit(*_run("loom-dark-c0.5-over-checker-diag2px", scale=2))
    assert not _hit(*_run("loom-dark-c0.5-over-checker-diag2px", scale=2, **NO_RIM))


def test_the_rim_counts_only_within_the_fit_s_small_motion_range():
    # a hand-held camera swaying over props, nothing approaching, seen 10 times a second: a
    # prop's rim read an expansion of 0.76 a frame (13 px at its box's edge, far beyond the
    # first-order fit's range) where its box read 0.26, and warned
    assert preset("default").rim_motion_max == 8.0
    assert _quiet(_run("handheld-desk-sway", variant=9, every=2)[1])
    assert not _quiet(_run("handheld-desk-sway", variant=9, every=2, **NO_RIM_LIMIT)[1])
    # the approaches the rim wins at 10 frames a second keep it
    for case in ("loom-dark-c0.5-over-checker-diag2px", "loom-dark-c0.5-over-stripes-h2px"):
        assert _hit(*_run(case, every=2))
        assert not _hit(*_run(case, every=2, **NO_RIM))


def test_the_rim_warns_earlier_over_sliding_stripes_and_is_inert_where_nothing_slides():
    case = "loom-light-c0.5-over-stripes-h2px"
    assert _first(_run(case)[1]) < _first(_run(case, **NO_RIM)[1])
    # no background translation taken out (a still background; a drive): response for
    # response as without it
    for case in ("loom-light-c0.6-d12-top", "drive-day-stopped-car"):
        assert ([r.to_dict() for r in _run(case)[1]]
                == [r.to_dict() for r in _run(case, **NO_RIM)[1]])

def _under_lamps(flicker: bool):
    """A dark disk (Weber -0.6) looming over the suite's still texture at 30 fps, under 100 Hz
    lamps aliased at the frame rate (a 10 Hz, +-12 % flicker of the whole view) or not."""
    from asnn.stimuli.effects import Flicker
    from asnn.stimuli.planar import planar_scene
    from asnn.stimuli.suite import _STILL_TEXTURE, PLANAR_SIZE

    return planar_scene(size=PLANAR_SIZE, onset=20, fps=30.0, background=_STILL_TEXTURE,
                        lighting=(Flicker(100.0, 0.12),) if flicker else ())


def _stepped_scene(scene, **overrides):
    model = ASNN(preset("robust", **overrides))
    return [model.step(f, i / scene.fps) for i, f in enumerate(scene.frames)]


def test_a_lamp_s_flicker_at_the_frame_rate_is_divided_out_before_the_retina():
    # the flicker changes every pixel by up to 20 % from frame to frame: the frame difference
    # covers the whole view, G is positive nearly everywhere and the attention finds nothing,
    # so the approach is missed; with the view's brightness change divided out it warns within
    # a few frames of the same approach under a steady light
    assert preset("default").global_gain == 0.5
    flickering, steady = _under_lamps(True), _under_lamps(False)
    lit = _first(_stepped_scene(flickering))
    assert lit is not None and flickering.onset_frame <= lit <= flickering.contact_frame
    assert abs(lit - _first(_stepped_scene(steady))) <= 4
    assert not _hit(flickering, _stepped_scene(flickering, **NO_GLOBAL_GAIN))


def test_a_dusk_approach_warns_by_the_light_adaptation_of_the_contrast_gain_control():
    # at a third of the day's light a drive's changes are a third as large: with the gain
    # control's constant fixed, the attention keeps fragments of the hydrant, whose offsets
    # fail the approach test; scaled by the view's median light, it keeps the hydrant whole
    assert _hit(*_run("extra-dk-hydrant-low-camera-10fps"))
    assert _first(_run("extra-dk-hydrant-low-camera-10fps", **NO_LIGHT_ADAPTATION)[1]) is None


@pytest.mark.parametrize("case", ["extra-dk2-white-van-stands-in-lane-10fps",
                                  "extra-dk-cyclist-headon-15fps"])
def test_a_dusk_approach_under_sensor_noise_warns_by_the_noise_summation(case):
    # 4 gray levels of noise on a view at a third of the day's light are as large as the
    # object's changes: through the fixed 3x3 blur the approach test passes in single frames
    # apart and never persists; blurred as wide as the measured noise asks, it does
    assert _hit(*_run(case, perturbation="noise"))
    assert _first(_run(case, perturbation="noise", **NO_NOISE_SUMMATION)[1]) is None


@pytest.mark.parametrize("case", ["extra-dk-hydrant-low-camera-10fps",
                                  "extra-dk-person-walks-at-robot"])
def test_a_dusk_approach_under_sensor_noise_warns_by_the_temporal_summation(case):
    # blurred as wide as the noise asks, the attention masks keep a part of the object (traced
    # on the person: its tracks are fragments whose offsets fail the approach test); averaged
    # over time where the view is still, it is kept whole enough to pass
    assert _hit(*_run(case, perturbation="noise"))
    assert _first(_run(case, perturbation="noise", **NO_TEMPORAL_SUMMATION)[1]) is None


@pytest.mark.parametrize("case", ["extra-dk-hydrant-low-camera-10fps",
                                  "extra-dk2-child-runs-at-low-robot"])
def test_a_dusk_approach_under_noise_the_fixed_blur_leaves_over_its_target_warns(case):
    # 3 gray levels of noise: the fixed 3x3 blur leaves 1.06 of them, over the summation's
    # target of 1, so the blur widens and the view is summed in time; until 2026-12-02 the blur
    # widened from 3.5 gray levels only (the Gaussian's formula, which the 3x3 kernel does not
    # follow), and these were missed under 3 gray levels though caught under 4
    assert _hit(*_run(case, perturbation="noise3"))
    assert _first(_run(case, perturbation="noise3", **NO_NOISE_SUMMATION)[1]) is None


def test_a_lit_view_under_sensor_noise_keeps_the_fixed_blur():
    # the suite's looms under noise on a light ground: the light adaptation reads the view as
    # lit, and the stage leaves every response as the fixed blur gives it
    with_stage = _run("loom-dark-c0.5-d12-center", perturbation="noise")[1]
    without = _run("loom-dark-c0.5-d12-center", perturbation="noise", **NO_NOISE_SUMMATION)[1]
    assert [r.u for r in with_stage] == [r.u for r in without]
    assert _first(with_stage) is not None


def test_a_night_view_lit_in_pools_keeps_the_gain_control_s_fixed_constant():
    # a night drive's median is as low as a dusk's, but its headlights' pool on the road puts
    # its upper decile at 4-5 times the median: adapted as a dusk, the constant falls, and a
    # car crossing ahead and clearing our path warns
    assert _quiet(_run("drive-night-cross-clears")[1])
    assert not _quiet(_run("drive-night-cross-clears", **NO_NIGHT_GATE)[1])


def test_the_compensating_gain_is_state_a_copy_and_worker_threads_carry():
    """The gain is the model's state: stepped with worker threads, as a stream, or copied
    mid-stream (pickled, as a worker hands a model on), a flickering approach, where the gain
    is not 1 in most frames, gets the responses of one model stepped on one thread."""
    import pickle

    scene = _under_lamps(True)
    times = [i / scene.fps for i in range(len(scene.frames))]
    one = ASNN(preset("robust"))
    gains, expected = [], []
    for frame, t in zip(scene.frames, times):
        expected.append(one.step(frame, t).to_dict())
        gains.append(one._log_gain)
    assert sum(g != 0.0 for g in gains) > len(gains) // 2  # the stage acts in most frames
    threaded = ASNN(preset("robust"), threads=2)
    assert [threaded.step(f, t).to_dict() for f, t in zip(scene.frames, times)] == expected
    streamed = ASNN(preset("robust"), threads=2)
    assert [r.to_dict() for r in streamed.stream(zip(times, scene.frames))] == expected
    half = len(times) // 2
    first = ASNN(preset("robust"))
    head = [first.step(f, t).to_dict() for f, t in zip(scene.frames[:half], times[:half])]
    copy = pickle.loads(pickle.dumps(first))
    assert copy._log_gain == gains[half - 1]
    assert head + [copy.step(f, t).to_dict() for f, t in
                   zip(scene.frames[half:], times[half:])] == expected


def test_the_brightness_compensation_is_inert_where_the_light_is_steady():
    # an approach over a sliding pattern, a drive and a headlight sweep change no pixel's light
    # as a whole: response for response as without the stage
    for case in ("loom-light-c0.5-over-stripes-h2px", "drive-day-stopped-car",
                 "headlights-sweep-night"):
        assert ([r.to_dict() for r in _run(case)[1]]
                == [r.to_dict() for r in _run(case, **NO_GLOBAL_GAIN)[1]])


def test_the_view_s_brightness_change_is_measured_where_the_light_changes_it():
    from asnn import brightness

    rng = np.random.default_rng(5)
    scene = rng.uniform(0.1, 0.8, (120, 160)).astype(np.float32)
    before = brightness.sampled(scene)
    # a change of the light: every pixel by one factor, also under sensor noise
    noisy = scene * np.float32(0.8) + rng.normal(0, 2 / 255, scene.shape).astype(np.float32)
    assert brightness.global_change(brightness.sampled(scene * np.float32(1.1)), before) == \
        pytest.approx(math.log(1.1), abs=1e-4)
    assert brightness.global_change(brightness.sampled(noisy), before) == \
        pytest.approx(math.log(0.8), abs=0.01)
    # clipped white does not follow the light: the rest of the view tells the change
    sky = scene.copy()
    sky[:60] = 1.0
    assert brightness.global_change(brightness.sampled(np.minimum(sky * 0.9, 1.0)),
                                    brightness.sampled(sky)) == pytest.approx(math.log(0.9),
                                                                               abs=1e-4)
    # stripes sliding by, or a dark object covering a third of the view, are no change of
    # the light: about as many pixels brighten as darken, or most stay as they were
    stripes = np.tile((0.3 + 0.4 * (np.arange(160) // 4 % 2)).astype(np.float32), (120, 1))
    assert brightness.global_change(brightness.sampled(np.roll(stripes, 2, axis=1)),
                                    brightness.sampled(stripes)) == 0.0
    dark = scene.copy()
    dark[30:90, 50:110] = 0.05
    assert brightness.global_change(brightness.sampled(dark), before) == 0.0


def test_the_compensation_divides_a_step_out_and_returns_to_the_camera_s_level():
    from asnn import brightness

    # the lights dimmed to 0.45 at once: the next frame is scaled back by 1 / 0.45, and the
    # gain returns to 1 with the time constant, gone after a few of them
    gain = brightness.compensation_step(0.0, math.log(0.45), 1 / 30, 1.0)
    assert math.exp(gain) == pytest.approx(1 / 0.45, rel=0.04)
    for _ in range(29):
        gain = brightness.compensation_step(gain, 0.0, 1 / 30, 1.0)
    assert gain == pytest.approx(-math.log(0.45) / math.e)  # a second: one time constant
    for _ in range(210):
        gain = brightness.compensation_step(gain, 0.0, 1 / 30, 1.0)
    assert gain == 0.0  # the frames as the camera gives them, bit for bit


def test_the_compensating_gain_stays_within_what_one_frame_can_measure():
    """A review: a darkening taken at once and undone where no three quarters of the view
    agree (darkened as a whole, then lit again part by part) is divided out each time and never
    taken back, so the gain ran up without bound: e^22 with a 1 s time constant, and at 60 s
    math.exp overflowed mid-step (OverflowError at frame 1373, the model then refusing every
    frame until reset)."""
    from asnn import brightness

    rng = np.random.default_rng(0)
    lit = (rng.uniform(0.7, 0.95, (120, 160)) * 255).astype(np.uint8)
    dark = (lit / 9).astype(np.uint8)  # every pixel: a change of the light, taken
    part = lit.copy()
    part[66:] = dark[66:]  # 55 % lit again: no three quarters agree either way, no change
    bound = math.log(brightness.BRIGHT / brightness.DARK)
    model = ASNN(preset("robust"))
    for i in range(60):
        model.step((lit, dark, part)[i % 3], i / 30)
        assert abs(model._log_gain) <= bound
    gain = 0.0
    for _ in range(2000):  # at the longest time constant, as far as math.exp overflowed
        for change in (math.log(1 / 9), 0.0, 0.0):
            gain = brightness.compensation_step(gain, change, 1 / 30, 60.0)
            assert abs(gain) <= bound


@pytest.mark.parametrize("case", ["halt-dark-c0.6", "approach-recede-light-c0.6"])
def test_the_warning_ends_when_the_approach_ends(case):
    scene, responses = _run(case)
    assert _hit(scene, responses)
    # the spike-rate window (N_t = 4 frames) is all that outlasts the approach
    after = [r.index for r in responses if r.collision and r.index > scene.contact_frame + 2]
    assert len(after) <= 4 and (not after or after[-1] <= scene.contact_frame + 6)


def test_without_the_gate_the_warning_outlasts_the_approach():
    # the object turns back at the contact frame: its recession keeps the approach map active
    scene, responses = _run("approach-recede-dark-c0.6", **NO_GATE)
    after = [r.index for r in responses if r.collision and r.index > scene.contact_frame + 2]
    assert len(after) > 4


# 4. near misses: a pass is not a collision

@pytest.mark.parametrize("case", ["nearmiss-disk-dark-right", "nearmiss-car-dark-left-nextlane",
                                  "nearmiss-truck-dark-right-close", "drive-day-oncoming-nextlane",
                                  "rear-day-overtake"])
def test_near_misses_stay_quiet_while_their_collision_twin_warns(case):
    scene, responses = _run(case)
    assert _quiet(responses)
    if scene.twin:
        assert _hit(*_run(scene.twin))


@pytest.mark.parametrize("case", ["nearmiss-disk-dark-right", "nearmiss-car-dark-left-nextlane",
                                  "rear-day-overtake"])
def test_near_misses_are_told_apart_by_the_offset_test(case):
    assert not _quiet(_run(case, **NO_OFFSET_TEST)[1])


def test_a_near_miss_keeps_its_drift_through_the_stabilisation():
    # drawn at 480x360 and enlarged twice (a 960x720 camera): where the disk's drift past us
    # explained most of the frame's change, the stabilisation took it out as the background's
    # and the disk grew as if it came at us; the tile test leaves that drift in the maps
    case = dict(case="nearmiss-disk-dark-right", perturbation="double-size", scale=3)
    assert _quiet(_run(**case)[1])
    # the rim's expansion off in both arms: in the frames whose drift the stabilisation takes
    # out it scales the disk's estimates, and without the tile test the smoothed track then
    # passes the approach test only from frame 65 on (60 without the rim), too late to warn:
    # that would hide what the tile test does
    assert _quiet(_run(**case, **NO_RIM)[1])
    assert not _quiet(_run(**case, stabilise_spread=0.0, **NO_RIM)[1])


@pytest.mark.parametrize("case", ["drive-day-cut-in-dark", "drive-day-turn-cut-in"])
def test_a_car_cutting_in_ahead_is_told_apart_by_its_motion_against_the_scene(case):
    # its box holds the roadside behind it, which expands with our motion; the car recedes
    assert _quiet(_run(case)[1])
    assert not _quiet(_run(case, **NO_SCENE_RELATIVE)[1])


@pytest.mark.parametrize("case", ["drive-day-cut-in-dark", "drive-day-passed-by-right"])
def test_a_box_holding_motions_none_of_which_comes_at_us_does_not_warn(case):
    # in fresh scenery (variant 2) both pass the scene-relative test: the dark car cutting in,
    # and a car passing us on the right, seen in one box with the roadside; split into its
    # motions, the box holds none that is itself an approach
    assert _quiet(_run(case, 2)[1])
    assert not _quiet(_run(case, 2, **NO_MOTION_LAYERS)[1])


def test_collision_courses_under_our_own_motion_keep_an_approaching_motion():
    # the box of a car we close on holds the road too: one of its motions is the car's
    for case in ("drive-day-stopped-car", "drive-day-brake", "drive-day-truck-ahead",
                 "drive-day-oncoming-headon", "drive-day-cross-tbone"):
        scene, responses = _run(case)
        assert _hit(scene, responses)
        assert _first(responses) - _first(_run(case, **NO_MOTION_LAYERS)[1]) <= 3


@pytest.mark.parametrize("case", ["drive-day-stopped-car", "drive-day-truck-ahead"])
def test_the_camera_s_own_hood_in_view_is_left_out_of_the_looming_fits(case):
    # a dashcam's hood and timestamp, still in every frame: a box that reaches their edges
    # reads as partly still, and the car's expansion too slow, unless they are left out
    assert _hit(*_run(case, perturbation="hood"))
    assert _quiet(_run(case, perturbation="hood", **NO_RIG)[1])


def test_a_drive_without_a_rig_in_view_is_judged_as_without_the_stage():
    # the scenery at the top and bottom of the frame moves: nothing there is taken for rig
    _, responses = _run("drive-day-stopped-car")
    _, plain = _run("drive-day-stopped-car", **NO_RIG)
    assert [r.collision for r in responses] == [r.collision for r in plain]


@pytest.mark.parametrize("case", ["drive-day-stopped-car-offset", "drive-night-brake-offset"])
def test_a_car_that_strikes_a_corner_of_ours_warns_by_the_partial_overlap_regime(case):
    # its centre 1.2 m to the side: the offset test's 1 (a path through the camera) refuses it
    assert _hit(*_run(case))
    assert _quiet(_run(case, **NO_PARTIAL_OVERLAP)[1])


# the motions of two real collisions the default misses (c06: an oncoming pickup turning across
# our path; c25: a car from the next lane swerving in front of us), generated (extra drives
# outside the suite): caught here, so those motions alone do not explain the misses

@pytest.mark.parametrize("time", ["day", "night"])
def test_an_oncoming_car_turning_across_our_path_warns_and_one_keeping_its_lane_does_not(time):
    # its centre 0.1 m from ours when it reaches our bumper; or passing in the next lane
    assert _hit(*_run(f"extra-{time}-turn-across"))
    assert _quiet(_run(f"extra-{time}-turn-across-keeps-lane")[1])
    assert not _quiet(_run(f"extra-{time}-turn-across-keeps-lane", **NO_OFFSET_TEST)[1])


@pytest.mark.parametrize("time", ["day", "night"])
def test_a_car_moving_into_our_lane_ahead_of_us_warns_and_one_staying_beside_does_not(time):
    # a slower car in the right lane: in front of us when we reach it, or passing beside us
    # with its centre 2.3 m from ours
    assert _hit(*_run(f"extra-{time}-moves-in"))
    assert _quiet(_run(f"extra-{time}-moves-in-stays-beside")[1])
    assert not _quiet(_run(f"extra-{time}-moves-in-stays-beside", **NO_OFFSET_TEST)[1])


@pytest.mark.parametrize("case", ["drive-night-cut-in", "drive-day-overtake-truck-right",
                                  "drive-day-turn-left"])
def test_the_partial_overlap_regime_needs_a_whole_object_the_fit_explains(case):
    # a car cutting in at night, merged with the roadside (a low fit); the near roadside in the
    # drive's first frames and in a bend, cut by the frame's edge
    assert _quiet(_run(case)[1])
    assert not _quiet(_run(case, **NO_FIT_TEST)[1])


def test_a_rate_against_the_scene_that_is_zero_within_noise_does_not_break_an_approach():
    # the night catch-up with a rear camera: one frame reads the car contracting against the
    # scene at -0.04 per second while it expands at 2.5, which broke its run of frames (region
    # persistence bridges that one frame too, so without the tolerance it is switched off here)
    assert _hit(*_run("rear-night-catchup-offset"))
    assert _hit(*_run("rear-night-catchup-offset", region_persistence=False))
    assert _quiet(_run("rear-night-catchup-offset", scene_tolerance=0.0,
                       region_persistence=False)[1])


def test_an_object_closing_by_its_own_motion_counts_twice_and_one_we_drive_at_once():
    # a disk looming at a still camera closes on it by its own motion: every frame it counts
    # in, its share of u is doubled, and the warning comes a frame sooner
    _, weighted = _run("loom-dark-c0.6-d6-center")
    _, plain = _run("loom-dark-c0.6-d6-center", **NO_OWN_MOTION_WEIGHT)
    counted = [(w.u, p.u) for w, p in zip(weighted, plain) if p.u > 0]
    assert len(counted) >= 10 and all(w == pytest.approx(2 * p) for w, p in counted)
    assert _first(weighted) < _first(plain)
    # a stopped car we drive at expands because we do: the scene explains it, and until it
    # fills the view its share is as before, the warning no sooner
    _, weighted = _run("drive-day-stopped-car")
    _, plain = _run("drive-day-stopped-car", **NO_OWN_MOTION_WEIGHT)
    counted = [(w.u, p.u) for w, p in zip(weighted, plain) if p.u > 0]
    assert len(counted) >= 10 and all(w == p for w, p in counted[:10])
    assert _first(weighted) == _first(plain)


def test_a_car_catching_up_off_axis_with_a_rear_camera_is_fitted_against_the_receding_scene():
    # its box holds the road receding behind it: the box's fit stays at 0.2-0.4, below the
    # partial-overlap regime's 0.4, while the fit against the contracting scene passes
    assert _hit(*_run("rear-day-catchup-offset"))
    assert _quiet(_run("rear-day-catchup-offset", receding_scene=False)[1])


def test_an_object_the_frame_s_edge_cuts_is_not_judged_on_its_fit_against_a_receding_scene():
    # the rule is for real nc03's car overtaking into view at the frame's edge, which passed
    # the partial-overlap regime on that fit under looser limits; no generated clip warns that
    # way, so this shows the rule acting where it costs: the night crossing car's front lamp,
    # cut by the frame's left edge, no longer passes the regime on it, and the car warns once
    # more of it is in view (still in its hit window)
    scene, ruled = _run("drive-night-cross-tbone", variant=8)
    _, unruled = _run("drive-night-cross-tbone", variant=8, **NO_EDGE_RULE)
    assert _hit(scene, ruled) and _hit(scene, unruled)
    assert _first(ruled) > _first(unruled)


def test_a_car_overtaking_into_view_at_the_frame_s_edge_does_not_pass_on_its_fit_against_the_scene():
    # real nc03 (no collision): a car overtaking us enters large at the frame's right edge.
    # At the limits its held-out fold takes, its track passed the partial-overlap regime in
    # frame 87 on its fit against a scene read as receding (the box's own fit 0.016, counted
    # 0 at the edge; offset 2.04) and the model warned from frame 90; with the rule, quiet
    frames, label = _real_clip("nc03.mp4")
    fold = dict(approach_frames=2, overlap_tau_max=0.8, scene_tolerance=0.0,
                overlap_offset_max=2.5)

    def warned(**overrides):
        model = ASNN(preset("robust", **fold, **overrides))
        return any(model.step(frame, i / label["fps"]).collision
                   for i, frame in enumerate(frames()))

    assert not warned()
    assert warned(**NO_EDGE_RULE)


@pytest.mark.parametrize("case", ["walk-light-c0.4-gait", "walk-dark-c0.4-gait"])
def test_a_walker_seen_in_fragments_warns_by_region_persistence(case):
    # its gait's sway splits its outline: its parts pass the approach test as different tracks
    # in turn, none of them three frames in a row; without region persistence the light one is
    # missed (the dark one, since the camera-rig stage, is caught by one track's frames too)
    scene, responses = _run(case)
    assert _hit(scene, responses) and _first(responses) < scene.contact_frame
    if case.startswith("walk-light"):
        scene, without = _run(case, region_persistence=False)
        assert not _hit(scene, without) or _first(without) >= scene.contact_frame


def _twinkling_blobs(dark: bool, frames: int = 50) -> list[np.ndarray]:
    """Short-lived blobs (a wet road's reflections, drops catching the light) at 160x120, 20
    fps: from frame 16 one at a time, each growing from a radius of 2 to 4 px over two frames and
    gone, in turn at four places 80 and 50 px apart, whose tracks' boxes touch at their edges.
    The light blobs lie on a ground of 90 gray levels, above the light adaptation's reference
    (77), where the gain control's constant is the fixed one: on a dimmer ground (60, blobs of
    200) the adapted constant lets their region persist and the default warns (21 frames; none
    without region persistence), as the fixed constant does on that clip 1.28 times brighter
    (docs/design-notes.md, "Light adaptation of the contrast gain control, again", its last
    part)."""
    background, blob = (200.0, 60.0) if dark else (90.0, 230.0)
    spots = ((40, 35), (120, 85), (120, 35), (40, 85))
    yy, xx = np.mgrid[0:120, 0:160]
    clip = []
    for k in range(frames):
        image = np.full((120, 160), background)
        if k >= 16:
            turn, age = divmod(k - 16, 2)
            cx, cy = spots[turn % len(spots)]
            cover = np.clip(2.5 + 2.0 * age - np.hypot(xx - cx, yy - cy), 0.0, 1.0)
            image += (blob - background) * cover
        clip.append(image.astype(np.uint8))
    return clip


@pytest.mark.parametrize("dark", [True, False])
def test_blobs_that_twinkle_around_the_frame_do_not_make_a_region_persist(dark):
    # each blob passes the approach test for two frames as its own track, never three; from any
    # overlap (region_cover=0) a blob's box inherits its neighbours' passing frames, which
    # touch it at their edges (covering a few per cent of it), and the model warned with
    # nothing coming at the camera; a fifth of the box is what speaks for the region
    clip = _twinkling_blobs(dark)

    def warnings(**overrides):
        model = ASNN(preset("robust", **overrides))
        return sum(model.step(frame, i / 20).collision for i, frame in enumerate(clip))

    assert warnings(region_cover=0.0) > 0
    assert warnings() == 0 and warnings(region_persistence=False) == 0


def test_a_large_track_over_a_wet_roads_reflections_does_not_inherit_their_persistence():
    # real c06 (night, wet road) re-encoded as `asnn camera --format jpeg` sends it: at frame
    # 27, 1.5 s before the oncoming pickup's onset, a new track four times the size of the
    # small reflections passing the approach test around it takes them in (their boxes cover
    # 2-14 % of its box) and, by region persistence from any overlap, warned at once. With the
    # fixed constant of the gain control, as it was chosen: the light adaptation alone keeps
    # that early warning away (the first warning from any overlap is then the hit's, frame 81)
    from asnn.evaluation.perturb import perturb_frame

    frames, label = _real_clip("c06.mp4")

    def first_warning(**overrides):
        model = ASNN(preset("robust", **overrides))
        for i, frame in enumerate(frames()):
            if model.step(perturb_frame(frame, "jpeg90", i), i / label["fps"]).collision:
                return i
        return None

    onset = label["onset_frame"]
    assert first_warning(region_cover=0.0, **NO_LIGHT_ADAPTATION) < onset
    for overrides in (NO_LIGHT_ADAPTATION, {}):  # the constant fixed, and the default
        warned = first_warning(**overrides)
        assert warned is None or warned >= onset


def _run_half_rate(case, **overrides):
    """The case at half its frame rate (10 fps), scored against its label at that rate."""
    from asnn.evaluation.perturb import perturb_label, perturbed
    from asnn.evaluation.runs import at_rate

    scene = make_case(case)
    label = perturb_label(scene.label(f"{case}.mp4"), "half-rate")
    model = ASNN(preset("robust", **overrides))
    responses = [model.step(f, t)
                 for t, f in perturbed(at_rate(scene.frames, scene.fps), "half-rate")]
    first = _first(responses)
    return first is not None and label["onset_frame"] <= first <= label["contact_frame"] + 2


@pytest.mark.parametrize("case", ["walk-dark-c0.4-gait", "drive-day-brake-bumps"])
def test_a_slow_stream_needs_fewer_frames_of_approach(case):
    # at 10 fps the walker's sway and the bumping car's jolts break every run of three frames
    # of approach; two frames span the 0.1 s that three span at 20 fps
    assert _run_half_rate(case)
    assert not _run_half_rate(case, approach_seconds=None)
    # at the suite's own 20 fps it warns as with three frames, frame for frame
    assert ([r.collision for r in _run(case)[1]]
            == [r.collision for r in _run(case, approach_seconds=None)[1]])


def test_collision_courses_under_our_own_motion_survive_the_scene_relative_test():
    for case in ("drive-day-stopped-car", "drive-day-brake", "drive-day-oncoming-headon"):
        assert _hit(*_run(case))


# 5. targets: one per approaching object, a stable id, expansion and time to contact

def test_an_object_seen_in_fragments_keeps_the_id_it_was_first_warned_under():
    # under a horizontal pan the direction inhibition keeps the disk's top and bottom rims: two
    # fragments, and the bottom one takes over from the top one 0.4 s before contact
    scene, responses = _run("loom-dark-c0.6-pan-h1px")
    _, plain = _run("loom-dark-c0.6-pan-h1px", object_ids=False)
    assert [r.collision for r in responses] == [r.collision for r in plain]
    warned = [r for r in responses if r.collision and r.index <= scene.contact_frame]
    assert len(warned) >= 8 and all(len(r.targets) == 1 for r in warned)
    assert len({r.targets[0].id for r in warned}) == 1
    ids = {t.id for r in plain if r.collision and r.index <= scene.contact_frame
           for t in r.targets}
    assert len(ids) == 2


def test_one_target_per_object_with_a_stable_id_and_a_time_to_contact():
    scene, responses = _run("loom-dark-c0.6-d6-center")
    warned = [r for r in responses if r.collision and r.targets]
    assert len(warned) >= 10
    assert all(len(r.targets) == 1 for r in warned)
    assert len({r.targets[0].id for r in warned}) == 1
    cx, cy = scene.center
    height = scene.frames.shape[1]
    checked = 0
    for r in warned:
        t = r.targets[0]
        assert t.approaching and t.expansion > 0 and t.offset < 1.0
        # on the object: within half its radius of its centre, or 4 px while it is small (the
        # first warning, at 14 px across, centres on the rim attended so far: 3.7 px off)
        assert np.hypot(t.x - cx, t.y - cy) < max(4.0, 0.25 * scene.target_size[r.index])
        if scene.target_size[r.index] < 0.5 * height:  # while the whole object is in view
            assert t.ttc == pytest.approx(scene.ttc[r.index], rel=0.25)
            checked += 1
    assert checked >= 10


def _traced(case, variant=0, **overrides):
    scene = make_case(case, variant)
    model = ASNN(preset("robust", **overrides), record_tracks=True)
    return scene, [model.step(f, i / scene.fps) for i, f in enumerate(scene.frames)]


def test_every_tracked_object_reports_the_approach_test_that_decided_the_warning():
    scene, responses = _traced("loom-dark-c0.6-d6-center")
    tau_max, u_scale = preset("robust").tau_max, preset("robust").u_scale
    warned = [r for r in responses if r.collision and r.index > 0]
    assert len(warned) >= 10
    for r in responses[1:]:
        counting = [t for t in r.tracks if t.counts]
        # only counting objects drive u(t), and the warning's targets are theirs
        assert (r.u > 0) == bool(counting)
        # their shares make up u: each object's, counted twice where it closes on us by its own
        # motion (a disk looming at a still camera does)
        assert r.u == pytest.approx(u_scale * sum(t.share for t in counting), rel=1e-9)
        assert {t.object_id for t in counting} == {t.id for t in r.targets}
        for t in r.tracks:
            assert (t.streak > 0) == t.test.passes
            assert t.test.passes == (t.test.seen and (t.test.course or t.test.overlap)
                                     and t.test.scene and t.test.layers)
            assert t.share > 0 if t.counts else t.share == 0
    for r in warned[:-3]:  # before contact: on a collision course, in the frame's pixels
        (t,) = [t for t in r.tracks if t.counts]
        assert t.test.course and t.ttc <= tau_max and t.streak >= 3
        x0, y0, x1, y1 = t.box
        assert x0 < scene.center[0] < x1 and y0 < scene.center[1] < y1


def test_a_near_miss_reports_the_offset_that_keeps_it_quiet():
    # the disk grows as fast as its collision twin, but its path points past the camera
    scene, responses = _traced("nearmiss-disk-dark-right")
    p = preset("robust")
    assert _quiet(responses)
    refused = [t for r in responses for t in r.tracks
               if t.ttc is not None and t.ttc <= p.tau_max and t.offset > p.offset_max]
    assert len(refused) >= 10
    assert all(not t.test.course and not t.counts for t in refused)


def test_a_refusal_by_the_scene_or_the_motion_layers_is_reported_as_such():
    # the dark car cutting in ahead (variant 2): a box on a collision course by its own fit,
    # which the motion against the scene or the box's motion layers refuse
    _, responses = _traced("drive-day-cut-in-dark", 2)
    assert _quiet(responses)
    refused = [t for r in responses for t in r.tracks
               if t.test.course and not (t.test.scene and t.test.layers)]
    assert refused and not any(t.counts for t in refused)


def test_tracks_are_recorded_only_for_presets_that_track_objects():
    with pytest.raises(ValueError, match="record_tracks"):
        ASNN("reference32", record_tracks=True)
    scene = make_case("loom-dark-c0.6-d6-center")
    assert all(ASNN("robust").step(f).tracks is None for f in scene.frames[:5])


def test_the_published_variant_reports_rim_segments_without_ids():
    scene = make_case("loom-dark-c0.6-d6-center")
    model = ASNN("reference32")
    counts = [len(model.step(f).targets) for f in scene.frames]
    assert max(counts) > 1  # several clusters on one object
    model = ASNN("reference32")
    assert all(t.id is None for f in scene.frames for t in model.step(f).targets)


# the stages that matter on real video: repeated frames, input scale, persistence

def _with_repeats(frames, every=3):
    """Frames as a frame-rate conversion delivers them: every ``every``-th frame shown twice."""
    out = []
    for i, frame in enumerate(frames):
        out.append(frame)
        if i % every == every - 1:
            out.append(frame)
    return out


def test_repeated_frames_are_held_rather_than_read_as_a_stop():
    scene = make_case("loom-dark-c0.3-d12-center")
    frames = _with_repeats(scene.frames)
    held = ASNN("robust")
    plain = ASNN(preset("robust", skip_repeats=False))
    fps = scene.fps * 4 / 3
    held_warn = [held.step(f, i / fps).collision for i, f in enumerate(frames)]
    plain_warn = [plain.step(f, i / fps).collision for i, f in enumerate(frames)]
    assert any(held_warn)
    assert held_warn.index(True) < (plain_warn.index(True) if any(plain_warn) else len(frames))


def test_a_repeated_frames_targets_are_aged_as_a_held_frames():
    """A repeat answers with the last response, its targets' ttc shortened by the time since the
    frame stepped, as a frame the ceiling holds does (a repeat between held frames read the
    ttc back up: 1.097, 1.081 held, 1.097 repeated, 1.047 held)."""
    scene = make_case("loom-dark-c0.3-d12-center")
    frames = _with_repeats(scene.frames)
    model = ASNN("robust")
    fps = scene.fps * 4 / 3
    before, aged = None, 0
    for i, frame in enumerate(frames):
        response = model.step(frame, i / fps)
        if model.repeated and before is not None and model.ceiling_held == 0:
            assert (response.u, response.collision) == (before.u, before.collision)
            for now, then in zip(response.targets, before.targets):
                assert (now.id, now.x, now.y) == (then.id, then.x, then.y)
                if then.ttc is not None and then.ttc > 1 / fps:
                    assert now.ttc == pytest.approx(then.ttc - 1 / fps)
                    aged += 1
        before = response
    assert aged >= 3


def test_a_repeated_frame_is_held_under_sensor_noise():
    # a scene moving across the view (a checkerboard sliding 2 px per frame), converted to a
    # higher frame rate (every third frame shown twice), every copy with noise of its own (4
    # gray levels, as a camera adds): per pixel the two copies of a frame differ by more than
    # the repeat test's level, their block means do not
    scene = make_case("loom-dark-c0.5-over-checker-diag2px")
    frames, copies = [], []
    for i, frame in enumerate(scene.frames):
        frames.append(frame)
        if i % 3 == 2:
            copies.append(len(frames))
            frames.append(frame)
    rng = np.random.default_rng(0)
    noisy = [np.clip(np.rint(f + rng.normal(0.0, 4.0, f.shape)), 0, 255).astype(np.uint8)
             for f in frames]
    fps = scene.fps * 4 / 3
    held = {}
    for block in (8, 1):
        model = ASNN(preset("robust", repeat_block=block))
        held[block] = []
        for i, frame in enumerate(noisy):
            model.step(frame, i / fps)
            if model.repeated:
                held[block].append(i)
    assert held[8] == copies
    assert not held[1]


def test_a_still_scene_is_not_a_run_of_repeats():
    model = ASNN("robust")
    scene = make_case("halt-dark-c0.6")
    for i, frame in enumerate(scene.frames):
        model.step(frame, i / scene.fps)
    # the scene stopped 18 frames before the end: one frame held, then seen as it is
    assert not model.repeated and not model.approach.objects


def test_large_frames_are_seen_at_the_scale_of_the_kernels_and_targets_stay_in_their_pixels():
    import cv2

    scene = make_case("loom-dark-c0.6-d6-center")
    big = [cv2.resize(f, None, fx=4, fy=4, interpolation=cv2.INTER_NEAREST) for f in scene.frames]
    small, large = ASNN(preset("robust", max_width=None)), ASNN(preset("robust", max_width=160))
    pairs = [(small.step(f, i / 20), large.step(g, i / 20))
             for i, (f, g) in enumerate(zip(scene.frames, big))]
    assert [a.collision for a, _ in pairs] == [b.collision for _, b in pairs]
    assert any(a.targets for a, _ in pairs)
    for a, b in pairs:
        assert len(a.targets) == len(b.targets)
        for ta, tb in zip(a.targets, b.targets):
            assert (tb.x, tb.y) == pytest.approx((4 * ta.x + 1.5, 4 * ta.y + 1.5), abs=0.5)


def test_small_frames_are_enlarged_to_the_scale_the_added_stages_were_made_for():
    # a truck passing close, seen by a camera of half the suite's resolution (80x60): at its own
    # size its outline is a few of the stages' pixels and it warns; enlarged to 160 px, not
    case = "nearmiss-truck-dark-right-close"
    assert not _quiet(_run(case, perturbation="half-size", min_width=None)[1])
    assert _quiet(_run(case, perturbation="half-size")[1])
    # an approach at that size is still caught, its targets in the frame's own pixels
    scene, responses = _run("loom-light-c0.6-d12-bottomleft", perturbation="half-size")
    assert _hit(scene, responses)
    first = next(r for r in responses if r.collision and r.index >= 5)
    x, y = scene.track[first.index]
    assert min(math.hypot(t.x - x / 2, t.y - y / 2) for t in first.targets) < 6
    # bounded: a tall, narrow frame is enlarged to at most four times 160 px high
    model = ASNN()
    assert model._retina_size(60, 80) == (160, 120)
    assert model._retina_size(400, 40) == (64, 640)
    assert model._retina_size(4096, 32) == (32, 4096)
    assert model._retina_size(120, 160) == (160, 120)  # from 160 px on, as it is
    # and no frame is worked on at more than 480 x 640 pixels: a 480 x 4096 frame, at most 480
    # wide, was worked on whole (8.5 times the state of a 4096 x 4096 one shrunk to 480 x 480:
    # an audit of the documented memory bound); 480 x 640 and anything landscape as before
    assert model._retina_size(640, 480) == (480, 640)
    assert model._retina_size(1080, 1920) == (480, 270)
    w, h = model._retina_size(4096, 480)
    assert w * h <= 480 * 640 and abs(h / w - 4096 / 480) < 0.1
    tall = ASNN()
    tall.step(np.zeros((4096, 480), np.uint8))
    assert tall.previous.size <= 480 * 640
    w, h = ASNN(preset("default", min_width=None))._retina_size(4096, 480)  # min_width off
    assert w * h <= 480 * 640
    for side in ((0, 0), (100, 0), (0, 100)):  # sized only once it could pass: a FrameError
        with pytest.raises(FrameError, match="smaller than the model's"):
            ASNN().step(np.zeros(side, np.uint8))
    with pytest.raises(ValueError, match="min_width"):
        preset("robust", min_width=600)


def test_the_partial_overlap_regime_is_a_part_of_the_gate():
    from asnn.params import ASNNParams

    assert preset("default").overlap == (1.0, 2.0, 0.4)
    assert preset("default", approach_gate=False).overlap is None  # the gate off: all of it
    assert preset("default", partial_overlap=False).overlap is None
    with pytest.raises(ValueError, match="approach_gate needs targets='objects'"):
        ASNNParams(approach_gate=True)
    # every stage on the objects named at once, so one try finds them all
    with pytest.raises(ValueError, match="approach_gate, scene_relative, object_ids, refined_ttc, "
                                         "ignore_rig, surface_ahead, corridor_gate need "
                                         "targets='objects': set approach_gate=False, "
                                         "scene_relative=False, object_ids=False, "
                                         "refined_ttc=False, ignore_rig=False, "
                                         "surface_ahead=False, corridor_gate=False too"):
        preset("default", targets="clusters")



def test_a_warning_without_a_target_only_outlasts_its_objects_by_the_spike_window():
    """docs/contract.md: a frame that warns may list no target (the object the frame's edge
    cuts is lost for a frame), but only for up to n_t - 1 frames after a frame whose targets
    counted: the warning is the spike rate over the last n_t frames."""
    from asnn.stimuli.planar import planar_scene

    model = ASNN("default")
    window = model.params.n_t
    scene = planar_scene("loom", fps=20.0, onset=10, height=24, tau=4.0, position=(40.0, 30.0),
                         contrast=0.6, noise=2.0, seed=0)
    since_target, bare = None, 0
    for k, frame in enumerate(scene.frames):
        response = model.step(frame, k / scene.fps)
        if response.targets:
            since_target = 0
        elif since_target is not None:
            since_target += 1
        if response.collision and not response.targets:
            bare += 1
            assert since_target is not None and since_target <= window - 1, k
    assert bare  # the case the document describes does occur here


def test_every_preset_holds_values_its_own_validation_accepts():
    """The presets are built from one another: an update that pydantic does not check
    (model_copy) could hold a value out of bounds, found only when someone overrode another
    field of the preset, with an error naming the wrong field (a contributor trial)."""
    from asnn.params import PRESETS, ASNNParams, _derived

    for name, params in PRESETS.items():
        assert ASNNParams.model_validate(params.model_dump()) == params, name
    with pytest.raises(ValueError, match="tau_max"):
        _derived(PRESETS["robust"], tau_max=-1.0)


# the default's fields that differ from the published variant's and that no ablation row
# switches, each with why: a new addition goes in ABLATIONS (README, "Ablation"), not here
NOT_ABLATED = {
    "gamma_a": "the attention thresholds on the contrast gain control's scale: part of it",
    "gamma_d": "the attention thresholds on the contrast gain control's scale: part of it",
    "targets": "objects, what the approach gate and the stages after it read (their rows)",
    "origin_seed": "the published variant's DBSCAN seed: clusters only",
    "track_box": "the tracker's box smoothing, part of the tracker the approach gate reads",
    "refined_ttc": "the targets' reported ttc and expansion only, never a warning: measured by "
                   "asnn eval --ttc (docs/design-notes.md, \"The reported time to contact late "
                   "in an approach\")",
}


def test_every_addition_of_the_default_has_an_ablation_row():
    """A contributor trial: nothing tied a new switch to `asnn eval --ablation` or to the
    README's table, and five fields of the default differed from the published variant's
    unexplained."""
    import itertools
    from pathlib import Path

    from asnn.evaluation.runs import ABLATIONS
    from asnn.params import PRESETS

    robust, published = PRESETS["robust"], PRESETS["reference32"]
    differ = {name for name in type(robust).model_fields
              if getattr(robust, name) != getattr(published, name)}
    switched = {part.split("=")[0] for spec in ABLATIONS.values() for part in spec.split("/")[1:]}
    assert differ - switched == set(NOT_ABLATED)
    # one row of the README's table per row of the ablation (after its header and rule)
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    lines = readme[readme.index("#### Ablation: each addition switched off"):].splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith("| preset |"))
    rows = list(itertools.takewhile(lambda line: line.startswith("| "), lines[start + 2:]))
    assert len(rows) == len(ABLATIONS)


@pytest.fixture(scope="module")
def loom_60fps():
    """A small, far object coming at a 60 fps camera (6 px tall 4 s before contact)."""
    from asnn.stimuli.planar import planar_scene

    return planar_scene("loom", fps=60.0, onset=30, polarity="dark", height=6, tau=4.0,
                        contrast=0.6, noise=2.0, seed=1)


def _stepped(model: ASNN, frames, times) -> tuple[list, list[int]]:
    """The responses, and the indices (into ``frames``) of the frames the model stepped."""
    responses, stepped = [], []
    for k, (frame, t) in enumerate(zip(frames, times)):
        responses.append(model.step(frame, t))
        if not model.repeated:
            stepped.append(k)
    return responses, stepped


def _key(response):
    return (response.u, response.collision, [(t.x, t.y, t.ttc) for t in response.targets])


def test_a_fast_camera_is_stepped_on_a_grid_its_stamps_fix(loom_60fps):
    """max_step_rate (30): a 60 fps stream is stepped at 30 fps, each held frame answered as
    the one before, its targets' time to contact a frame on (a constant-speed approach: it
    repeated it a frame old, reading long late in an approach); and a model started on an odd
    frame (a worker taking the robot over) steps the same frames as one that saw the whole stream, once it has judged the rate. A hold
    counted from the last frame stepped kept such a model on the other half of the frames."""
    frames = loom_60fps.frames
    times = [1000.0 + k / 60.0 for k in range(len(frames))]
    model = ASNN("default")
    responses, stepped = _stepped(model, frames, times)
    assert model.ceiling_held == len(frames) - len(stepped) >= len(frames) // 2 - 2
    assert set(range(4, len(frames), 2)) <= set(stepped)  # the even frames, from the 4th on
    aged = 0
    for k in range(4, len(frames)):
        if k not in stepped:
            held, before = responses[k], responses[k - 1]
            assert (held.u, held.collision) == (before.u, before.collision), k
            assert [(t.id, t.x, t.y, t.offset) for t in held.targets] == \
                [(t.id, t.x, t.y, t.offset) for t in before.targets], k
            for now, then in zip(held.targets, before.targets):
                if then.ttc is not None:
                    assert now.ttc == pytest.approx(then.ttc - 1 / 60) and \
                        now.expansion == pytest.approx(1 / now.ttc), k
                    aged += 1
    assert aged > 10  # the approach's held frames carry a ttc
    assert len(model.periods) and model.frame_period == pytest.approx(1 / 30)
    for start in (7, 8):
        _, cold = _stepped(ASNN("default"), frames[start:], times[start:])
        cold = [start + k for k in cold]
        assert [k for k in cold if k >= start + 4] == [k for k in stepped if k >= start + 4]
    # frames stamped exactly on the grid's lines (k / 60 from 0: a file's frame times) fall in
    # the cell they begin, however the product rounds (frame 246's lies a hair below its line)
    rng = np.random.default_rng(0)
    noise = [rng.integers(0, 256, (120, 160), dtype=np.uint8) for _ in range(4)]
    _, stepped = _stepped(ASNN("default"), [noise[k % 4] for k in range(500)],
                          [k / 60.0 for k in range(500)])
    assert [k for k in stepped if k >= 4] == list(range(4, 500, 2))
    # untimed frames are all stepped (their period is the nominal one)
    untimed = ASNN("default")
    for frame in frames[:8]:
        untimed.step(frame)
    assert untimed.ceiling_held == 0 and len(untimed.periods) == 5


def test_frames_held_in_a_row_are_each_aged_from_the_frame_stepped(loom_60fps):
    """At 90 fps two frames in three are held: each held frame's targets are the stepped
    frame's aged by the time since it (not the previous held frame's aged again)."""
    frames = loom_60fps.frames
    times = [1000.0 + k / 90.0 for k in range(len(frames))]
    responses, stepped = _stepped(ASNN("default"), frames, times)
    last, second = None, 0
    for k in range(len(frames)):
        if k in stepped:
            last = k
            continue
        if last is None or k < 4:
            continue
        since = times[k] - times[last]
        for now, then in zip(responses[k].targets, responses[last].targets):
            if then.ttc is not None and then.ttc > since:
                assert now.ttc == pytest.approx(then.ttc - since), k
                second += k - last == 2
    assert second > 5


def test_a_target_that_would_reach_the_camera_while_held_keeps_its_own_ttc():
    from asnn.model import aged_targets
    from asnn.targets import Target

    targets = [Target(1.0, 2.0, 0.0, 1.0, 10, id=k, expansion=1 / ttc, ttc=ttc)
               for k, ttc in enumerate((0.01, 1 / 60, 0.5))] + [Target(1.0, 2.0, 0.0, 1.0, 10)]
    aged = aged_targets(targets, 1 / 60)
    assert aged[:2] == targets[:2] and aged[3] == targets[3]
    assert aged[2].ttc == pytest.approx(0.5 - 1 / 60)
    assert aged[2].expansion == pytest.approx(1 / (0.5 - 1 / 60))


@pytest.mark.parametrize("fps", [25.0, 30.0])
def test_a_camera_at_or_below_30_fps_whose_stamps_jitter_has_no_frame_held(fps):
    """The ceiling judges a camera's rate over many gaps: a 30 fps camera whose
    stamps jitter by 5 ms, with a read 15 ms late now and then (the next on time, 18 ms after
    it), has every frame stepped; a hold decided on one short gap answered distinct frames of
    such a camera as repeats. A 40 fps camera is stepped near 30 fps (a frame in four held)."""
    rng = np.random.default_rng(3)
    frames = [rng.integers(0, 256, (120, 160), dtype=np.uint8) for _ in range(4)]
    times = 5000.0 + np.arange(300) / fps + rng.normal(0.0, 0.005, 300)
    times[::20] += 0.015
    model = ASNN("default")
    for k, t in enumerate(times):
        model.step(frames[k % 4], float(t))
    assert model.ceiling_held == 0
    faster = ASNN("default")
    for k in range(300):
        faster.step(frames[k % 4], 5000.0 + k / 40.0)
    assert 300 // 4 - 3 <= faster.ceiling_held <= 300 // 4 + 3


def test_the_ceiling_warns_of_a_small_far_object_earlier_at_60_fps(loom_60fps):
    """At 60 fps a far object's image changes by a third of what it does at 20 fps from frame
    to frame: stepped at every frame, the default warned 0.35 s later than at 20-30 fps."""
    def lead(params):
        model = ASNN(params)
        first = next((k for k, frame in enumerate(loom_60fps.frames)
                      if model.step(frame, k / 60.0).collision), None)
        return None if first is None else (loom_60fps.contact_frame - first) / 60.0

    with_ceiling, without = lead(preset("default")), lead(preset("default", max_step_rate=None))
    assert with_ceiling is not None and without is not None
    assert with_ceiling >= without + 0.25  # 1.02 s against 0.65 s


def _noise_frames(count: int = 4) -> list:
    rng = np.random.default_rng(0)
    return [rng.integers(0, 256, (120, 160), dtype=np.uint8) for _ in range(count)]


def test_the_ceiling_judges_the_rate_from_the_third_gap():
    """CEILING_MIN_GAPS: the first three frames of a 60 fps stream are all stepped (the rate
    not judged yet), the fourth, in the third frame's cell, is the first held; then one in two.
    A model that judged later stepped more of a new owner's first frames than it counts."""
    noise = _noise_frames()
    model = ASNN("default")
    _, stepped = _stepped(model, [noise[k % 4] for k in range(12)],
                          [1000.0 + k / 60.0 for k in range(12)])
    assert stepped == [0, 1, 2, 4, 6, 8, 10]
    assert model.ceiling_held == 5


def test_a_fast_camera_that_drops_a_frame_now_and_then_keeps_its_ceiling():
    """The rate is judged over the last gaps: a 60 fps camera that loses one frame in ten
    (a 33 ms gap among 17 ms ones) is still stepped near 30 fps; a rate judged on the longest
    gap lifted the ceiling for 15 frames after each loss, that is for good."""
    noise = _noise_frames()
    times = [1000.0 + k / 60.0 for k in range(300) if k % 10 != 5]
    model = ASNN("default")
    _stepped(model, [noise[k % 4] for k in range(len(times))], times)
    assert model.ceiling_held >= 0.4 * len(times)


def test_untimed_frames_are_never_held_whatever_the_nominal_period():
    """Untimed frames are all stepped (params.max_step_rate): even where the preset's
    nominal period (dt) is that of a camera above the ceiling."""
    noise = _noise_frames()
    model = ASNN(preset("default", dt=1 / 60))
    for k in range(30):
        model.step(noise[k % 4])
    assert model.ceiling_held == 0 and not model.repeated


def test_untimed_frames_amid_timed_ones_are_stepped():
    """A stream whose times come and go (an untimed frame among timed ones, step(frame) then
    step(frame, t)) is stepped, not broken: the untimed frame is not held and the timed ones
    after it are judged from the times they have."""
    noise = _noise_frames()
    model = ASNN("default")
    for k in range(10):
        model.step(noise[k % 4], 1000.0 + k / 60.0)
    model.step(noise[2])
    assert not model.repeated
    for k in range(11, 20):
        model.step(noise[k % 4], 1000.0 + k / 60.0)
    assert model.ceiling_held >= 7


def test_a_reset_or_a_stalled_clock_judges_the_rate_afresh_as_a_new_model_does():
    """After reset(), and after a gap the model cannot time (a stall over MAX_FRAME_GAP_S, a
    clock that jumped), the ceiling judges the camera's rate anew: the model steps and holds
    the frames a model started there does, and counts its held frames from the new stream
    (what the worker's warm-up reads after a reset). Gaps or a count kept across them made a
    model reset for a new stream hold frames a fresh one steps, and read its warm-up short."""
    noise = _noise_frames()
    frames = [noise[k % 4] for k in range(40)]
    times = [1000.0 + k / 60.0 for k in range(40)]
    fresh = ASNN("default")
    _, expected = _stepped(fresh, frames[1:], times[1:])
    model = ASNN("default")
    _stepped(model, frames, [t - 50.0 for t in times])  # an earlier stream
    model.reset()
    _, stepped = _stepped(model, frames[1:], times[1:])
    assert stepped == expected and model.ceiling_held == fresh.ceiling_held
    stalled = ASNN("default")
    _stepped(stalled, frames[:20], [t - 5.0 for t in times[:20]])  # 5 s before the others
    _, stepped = _stepped(stalled, frames[1:], times[1:])
    assert stepped == expected



def test_a_fast_camera_s_clock_that_stood_still_and_runs_again_judges_the_rate_afresh():
    """Past the frames at one instant the ceiling holds as sent twice, a clock that stopped
    leaves the rate unknown: once it runs again, the model steps and holds the frames a model
    started on the stall's last frame does (gaps kept from before the stall held frames at
    once)."""
    noise = _noise_frames()
    frames = [noise[k % 4] for k in range(60)]
    times = [1000.0 + k / 60.0 for k in range(30)]
    times += [times[-1]] * 5  # the clock stands still for five frames
    times += [times[-1] + k / 60.0 for k in range(1, 60 - len(times) + 1)]
    fresh = ASNN("default")
    _, expected = _stepped(fresh, frames[34:], times[34:])
    model = ASNN("default")
    _, stepped = _stepped(model, frames, times)
    assert [k - 34 for k in stepped if k >= 34] == expected
    assert expected[:3] == [0, 1, 2]  # the rate judged from the third gap, as a new model's

def test_a_fast_camera_s_repeated_frames_held_by_the_ceiling_count_as_held():
    """A 30 fps video up-sampled to 60 fps (each frame sent twice): the ceiling holds every
    second frame before the repeat test sees it, so the copies count among the frames held and
    the warm-up counts the frames stepped (half of them); as repeats they counted as steps."""
    noise = _noise_frames()
    model = ASNN("default")
    _stepped(model, [noise[(k // 2) % 4] for k in range(100)],
             [1000.0 + k / 60.0 for k in range(100)])
    assert model.ceiling_held >= 100 // 2 - 2


@pytest.mark.parametrize("fps", [20.0, 25.0, 30.0])
def test_a_camera_read_two_frames_at_a_time_has_no_frame_held(fps):
    """A 60 fps trial: a camera stamped as its frames are read, two at a time (gaps of 4 ms
    and 2 / fps - 4 ms), had a median gap of 4 ms: half its frames were held and a 20 fps
    camera was stepped at 10, below what the default is made for. The ceiling judges the rate
    on the mean gap, the camera's own."""
    rng = np.random.default_rng(5)
    frames = [rng.integers(0, 256, (120, 160), dtype=np.uint8) for _ in range(4)]
    model = ASNN("default")
    t = 100.0
    for k in range(120):
        model.step(frames[k % 4], t)
        t += 0.004 if k % 2 == 0 else 2.0 / fps - 0.004
    assert model.ceiling_held == 0


def test_frames_delivered_twice_keep_a_fast_camera_s_ceiling(loom_60fps):
    """A 60 fps trial: every frame delivered twice with its stamp (a bag's stamp that went back
    is retimed to the latest, too) cleared the rate's history at each zero gap, so the ceiling
    never held a frame and the default warned as late as stepped at every frame. A frame at the
    same instant is held while the camera is fast, and the distinct frames are stepped as
    without the copies."""
    frames = loom_60fps.frames
    once, twice = ASNN("default"), ASNN("default")
    _, stepped = _stepped(once, frames, [k / 60.0 for k in range(len(frames))])
    doubled = [f for f in frames for _ in range(2)]
    _, stepped_twice = _stepped(twice, doubled, [k // 2 / 60.0 for k in range(len(doubled))])
    assert [k // 2 for k in stepped_twice if k >= 12] == [k for k in stepped if k >= 6]
    assert twice.ceiling_held >= len(doubled) * 3 // 4 - 4
