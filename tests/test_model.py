"""Behaviour of the ASNN object: input handling, direction estimates, per-stream state."""

import math
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from asnn import ASNN, FrameError, TimingWarning
from asnn import preset as asnn_preset
from asnn.stimuli import make_scene
from asnn.detectors import responses


def _grating(theta: float, frames: int = 20, size: int = 96, period: float = 12.0,
             speed: float = 1.0) -> list[np.ndarray]:
    y, x = np.mgrid[0:size, 0:size].astype(float)
    clip = []
    for t in range(frames):
        phase = (x * math.cos(theta) + y * math.sin(theta) - speed * t) * 2 * math.pi / period
        clip.append(((0.5 + 0.4 * np.sin(phase)) * 255).astype(np.uint8))
    return clip


def _bar(theta: float, frames: int = 20, size: int = 96, width: float = 6.0,
         speed: float = 1.5) -> list[np.ndarray]:
    y, x = np.mgrid[0:size, 0:size].astype(float)
    clip = []
    for t in range(frames):
        d = (x - size / 2) * math.cos(theta) + (y - size / 2) * math.sin(theta) - (speed * t - 15)
        clip.append(np.where(np.abs(d) < width / 2, 30, 220).astype(np.uint8))
    return clip


def _angle_error(a: float, b: float) -> float:
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


@pytest.mark.parametrize("preset", ["default", "paper"])
@pytest.mark.parametrize("stimulus", [_grating, _bar])
def test_direction_estimate_within_15_degrees_in_8_directions(preset, stimulus):
    # the retina's own direction estimates: the default's stabilisation would take out the
    # whole-field motion these stimuli are made of (tests/test_stabilisation.py)
    params = asnn_preset(preset, stabilise=False)
    for k in range(8):
        theta = k * math.pi / 4  # image coordinates: y down, so pi/2 moves down the screen
        model = ASNN(params, record_maps=True)
        for frame in stimulus(theta):
            response = model.step(frame)
        maps = response.maps
        estimate = math.atan2((maps.V * np.sin(maps.phi)).sum(), (maps.V * np.cos(maps.phi)).sum())
        assert _angle_error(estimate, theta) < math.radians(15), (k, math.degrees(estimate))


def test_first_frame_primes_and_responds_with_zeros():
    model = ASNN()
    r = model.step(np.full((64, 64), 128, np.uint8))
    assert (r.index, r.u, r.out, r.spikes, r.spike_rate, r.collision, r.targets) == \
        (0, 0.0, 0.5, 0, 0.0, False, [])
    assert model.step(np.full((64, 64), 128, np.uint8)).index == 1


def test_gray_bgr_and_float_frames_give_the_same_response():
    scene = make_scene("looming", size=(64, 64), stop=20, frames=20)
    gray, bgr, flt = ASNN(), ASNN(), ASNN()
    for frame in scene.frames:
        a = gray.step(frame)
        b = bgr.step(np.repeat(frame[:, :, None], 3, axis=2))
        c = flt.step(frame.astype(np.float64) / 255.0)
    assert a.u > 0
    assert b.u == a.u
    assert c.u == a.u


def test_a_float_frame_a_rounding_past_its_range_is_taken_clipped():
    """cv2.normalize(raw, None, 0, 1, NORM_MINMAX, CV_32F), the usual way to a float frame from
    a 16-bit camera, strays past [0, 1] by float32 rounding (1.0000001): 191 of 300 such
    frames were refused in a user's loop. A rounding's stray is clipped; a frame on 0..255 or
    past 1e-4 is still refused (test_bad_frames_get_a_clear_error)."""
    frames = [f.astype(np.float32) / np.float32(255) for f in
              make_scene("looming", size=(64, 64), frames=20).frames]
    strayed = [f.copy() for f in frames]
    for f in strayed:
        f[f >= 1.0] = np.nextafter(np.float32(1), np.float32(2))
        f[f <= 0.0] = -np.float32(1e-7)
    assert strayed[0].max() > 1.0 and strayed[0].min() < 0.0
    clean, clipped = ASNN("default"), ASNN("default")
    assert [clean.step(f).to_dict() for f in frames] == \
        [clipped.step(f).to_dict() for f in strayed]


def test_a_frame_without_a_time_in_a_timed_stream_comes_a_frame_period_after_the_latest():
    """A timed 30 fps stream with one frame given no time: that frame was placed at index * dt
    (1.5 s for the 30th, where the camera's clock read 1.0), a gap of 0.53 s that was believed,
    and the next timed frame's negative; every 5th frame untimed took the targets' median ttc
    error from 0.8 % to 13.7 % (a user trial)."""
    frames = make_scene("looming", size=(64, 64), frames=40).frames
    model = ASNN("default")
    for k, f in enumerate(frames[:30]):
        model.step(f, k / 30.0)
    model.step(frames[30])
    assert model.periods[-1] == pytest.approx(1 / 30.0)
    model.step(frames[31], 31 / 30.0)
    assert model.periods[-1] == pytest.approx(1 / 30.0)
    untimed = ASNN("default")  # a stream without times keeps dt a frame
    for f in frames[:5]:
        untimed.step(f)
    assert list(untimed.periods) == pytest.approx([untimed.params.dt] * 4)


def test_frames_lost_for_over_a_second_keep_their_time_and_give_no_false_warning():
    """A time-to-contact trial: a 10 fps camera losing 15 frames (1.6 s, within the worker's
    --max-gap) had the gap timed at dt, 0.05 s: the disk's growth over 1.6 s read as one
    frame's, a ttc 300 times short and six warnings for an object 5 s from contact."""
    from asnn.stimuli.render import levels, paint_disk

    background, level = levels(0.6, "dark")
    rng = np.random.default_rng(95)
    fps, tau, frames, left = 10, 8.0, [], []
    for k in range(55):  # a disk at constant speed, 8 s from contact at 0.5 s
        remaining = tau - max(k / fps - 0.5, 0.0)
        image = np.full((120, 160), background, float)
        paint_disk(image, 80, 60, 10.0 * tau / remaining, level)
        frames.append(np.clip(np.rint(image + rng.normal(0, 2.0, image.shape)), 0, 255))
        left.append(remaining)
    model, shortest = ASNN(), math.inf
    for k in [k for k in range(55) if not 15 <= k < 30]:  # frames 15-29 lost
        response = model.step(frames[k].astype(np.uint8), 100.0 + k / fps)
        assert not response.collision, k
        shortest = min([shortest] + [t.ttc / left[k] for t in response.targets if t.ttc])
        if k == 30:
            assert model.periods[-1] == pytest.approx(1.6)  # the gap as it was
    assert shortest > 0.5  # no target reads it closing twice as fast as it does


def test_a_millisecond_clock_with_one_gap_under_a_millisecond_is_still_timed_at_dt():
    """A review: one pair of frames 0.5 ms apart in a stream stamped in milliseconds (a
    camera read two frames at a time) was believed as a gap in seconds, and every later 33 ms
    gap as 33 s: no time to contact and no warning for the rest of the stream."""
    from asnn.stimuli.render import levels, paint_disk

    background, level = levels(0.6, "dark")
    rng = np.random.default_rng(1)
    frames = []
    for k in range(85):  # a disk 3 s from contact at 30 fps
        image = np.full((120, 160), background, float)
        paint_disk(image, 80, 60, 6.0 * 3.0 / (3.0 - k / 30), level)
        frames.append(np.clip(np.rint(image + rng.normal(0, 2.0, image.shape)), 0, 255))
    stamps, t = [], 1e5
    for k in range(85):
        t += 0.5 if k == 10 else 1000 / 30
        stamps.append(t)
    plain, paired = ASNN(), ASNN()
    warned = {"plain": [], "paired": []}
    with pytest.warns(TimingWarning) as told:  # each stream's clock said, once
        for k, image in enumerate(frames):
            image = image.astype(np.uint8)
            warned["plain"].append(plain.step(image, 1e5 + 1000 * k / 30).collision)
            warned["paired"].append(paired.step(image, stamps[k]).collision)
    assert any(warned["plain"]) and warned["paired"] == warned["plain"]
    assert paired.frame_period == plain.frame_period == paired.params.dt
    assert len(told) == 2 and all(w.filename == __file__ for w in told)  # the caller's line


def _timing_warnings(model, stamps, scene):
    """The TimingWarnings a stream of ``scene``'s frames at ``stamps`` raises, in order."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for stamp, frame in zip(stamps, scene.frames):
            model.step(frame, stamp)
    return [str(w.message) for w in caught if issubclass(w.category, TimingWarning)]


@pytest.mark.parametrize("stamps, told", [
    ([1000.0 * k / 20 for k in range(40)], "50 s"),  # a clock in milliseconds
    ([float(k) * 10**9 / 20 for k in range(40)], "5e+07 s"),  # nanoseconds
    ([3.0] * 40, "0 s"),  # a clock that stands still
    ([k / 20 for k in range(40)], None),  # seconds
    ([None] * 40, None),  # no times: the nominal period, as asked
    ([50.0 * k if k < 5 else 200.0 + (k - 4) / 20 for k in range(40)], None),  # 4 gaps only
])
def test_frame_times_the_model_cannot_time_by_are_warned_once_per_stream(stamps, told):
    """A library user's frames stamped in milliseconds were timed at dt without a word (the
    worker logs it; a script stepping the model saw times to contact off by the clock)."""
    scene, model = make_scene("looming", size=(64, 64)), ASNN()
    said = _timing_warnings(model, stamps, scene)
    if told is None:
        assert said == []
        return
    assert len(said) == 1 and f"the last {told} after the frame before" in said[0], said
    assert "timed at params.dt = 0.05 s" in said[0] and "time in seconds" in said[0]
    model.reset()  # a new stream is told again
    assert len(_timing_warnings(model, stamps, scene)) == 1


def test_a_fast_camera_whose_clock_stops_is_stepped_and_warned_of():
    """A review: a 60 fps camera whose stamp stopped was held by the frame-rate ceiling for
    good (each frame at the instant of the one before read as one sent twice): u froze, no
    warning, and the worker logged a timing at 20 fps that was not happening."""
    scene = make_scene("looming", size=(64, 64), frames=120)
    stamps = [k / 60 for k in range(30)] + [29 / 60] * 90
    model = ASNN()
    said = _timing_warnings(model, stamps[:30], scene)
    held = model.ceiling_held  # while the camera ran at 60 fps
    said += _timing_warnings(model, stamps[30:], make_scene("looming", size=(64, 64),
                                                            frames=120))
    assert len(said) == 1 and "a clock that stands still" in said[0]
    assert model.ceiling_held == held + 2  # the stall's first two, as frames sent twice
    # a frame sent twice, or twice more, is still held as one
    for twice in (1, 2):
        model = ASNN()
        stamps = [k / 60 for k in range(40)]
        for k in range(40):
            model.step(scene.frames[k], stamps[k])
            if k == 30:
                held = model.ceiling_held
                for _ in range(twice):
                    assert model.step(scene.frames[k], stamps[k]).index > 0
                assert model.ceiling_held == held + twice


def test_the_timing_warning_knows_asnn_s_frames_by_their_module_not_their_path():
    """A review: asnn's frames were told by their file's path, which is as imported: a script
    that put the package on sys.path by a path with ``..`` had the warning point into asnn."""
    import warnings

    from asnn.errors import _warn_at_caller

    ours = {"__name__": "asnn.elsewhere", "tell": _warn_at_caller, "Told": TimingWarning}
    exec(compile("def step():\n    tell('noted', Told)\n", "/x/../asnn/elsewhere.py", "exec"),
         ours)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ours["step"]()
    (told,) = caught
    assert told.filename == __file__


def test_the_timing_warning_skips_the_package_s_own_frames_only():
    """A mutation probe: the package's frames are ``asnn`` and ``asnn.*``; a user's module
    whose name merely starts with asnn (``asnn_scripts``), or whose file lies in a folder
    named asnn, is the caller the warning names."""
    import warnings

    from asnn.errors import _warn_at_caller

    def module(name: str, filename: str, source: str, **names) -> dict:
        namespace = {"__name__": name, **names}
        exec(compile(source, filename, "exec"), namespace)
        return namespace

    inner = module("asnn.elsewhere", "/x/asnn/elsewhere.py",
                   "def step():\n    tell('noted', Told)\n", tell=_warn_at_caller,
                   Told=TimingWarning)
    top = module("asnn", "/x/asnn/__init__.py", "def step():\n    inner()\n",
                 inner=inner["step"])
    for name, filename in (("asnn_scripts.run", "/x/asnn_scripts/run.py"),
                           ("__main__", "/home/me/asnn/run.py")):
        user = module(name, filename, "def run():\n    step()\n", step=top["step"])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            user["run"]()
        (told,) = caught
        assert (told.filename, told.lineno) == (filename, 2)


@pytest.mark.parametrize("threads", [1, 2])
def test_the_timing_warning_points_at_the_caller_s_line_and_comes_after_the_step(threads):
    """A review: raised inside the step, under warnings as errors it left the model half
    stepped (index and clock moved, the frame not stepped); from stream() it named the
    model's own line."""
    import warnings

    scene = make_scene("looming", size=(64, 64))
    model = ASNN(threads=threads)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in model.stream((50.0 * k, frame) for k, frame in enumerate(scene.frames)):
            pass
    (told,) = [w for w in caught if issubclass(w.category, TimingWarning)]
    assert told.filename == __file__
    model.close()
    # through asnn.detectors.responses, one more of asnn's frames, it named that one's line
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with ASNN(threads=threads) as model:
            for _ in responses(model, ((50.0 * k, f) for k, f in enumerate(scene.frames))):
                pass
    (told,) = [w for w in caught if issubclass(w.category, TimingWarning)]
    assert told.filename == __file__
    model = ASNN()
    with warnings.catch_warnings():
        warnings.simplefilter("error", TimingWarning)
        for k in range(5):
            model.step(scene.frames[k], 50.0 * k)
        with pytest.raises(TimingWarning):
            model.step(scene.frames[5], 250.0)
    twin = ASNN()
    with pytest.warns(TimingWarning):  # the model stepped the frame it warned on, as this one
        for k in range(6):
            expected = twin.step(scene.frames[k], 50.0 * k)
    assert model.index == 6 and model._in_use.acquire(blocking=False)
    model._in_use.release()
    assert model.step(scene.frames[6], 300.0).to_dict() == twin.step(
        scene.frames[6], 300.0).to_dict()
    assert expected.index == 5


def test_a_nan_frame_time_is_no_time_and_spoils_no_other_frame_s():
    """A trial: every other frame's time NaN (a driver's unset stamp) timed every frame at dt,
    the good ones too (the NaN kept as the latest time), and warned of a stalled clock."""
    scene = make_scene("looming", size=(64, 64))
    stamps = [k / 30 if k % 2 == 0 else math.nan for k in range(len(scene.frames))]
    nan, none = ASNN(), ASNN()
    assert _timing_warnings(nan, stamps, scene) == []
    _timing_warnings(none, [None if math.isnan(t) else t for t in stamps], scene)
    assert list(nan.periods) == pytest.approx([1 / 30] * 5) and nan.periods == none.periods


def test_the_timing_warning_comes_after_five_untimed_gaps_in_a_row():
    scene, model = make_scene("looming", size=(64, 64)), ASNN()
    stamps = [0.0, 0.05, 50.0, 50.05, 100.0, 100.05, 150.0, 150.05, 200.0, 200.05]  # 1 in 2
    assert _timing_warnings(model, stamps, scene) == []
    model.reset()
    stamps = [0.0, 0.05, 50.0, 100.0, 150.0, 200.0, 250.0]  # 5 in a row, from the third gap
    assert len(_timing_warnings(model, stamps[:6], scene)) == 0
    assert len(_timing_warnings(model, stamps[6:], make_scene("looming", size=(64, 64)))) == 1



def test_untimed_gaps_apart_are_not_warned_of_however_many():
    """Five in a row: a believed gap between them starts the count again (ten untimed gaps,
    each after a believed one, are a stream with a frame lost now and then, not a bad clock)."""
    scene, model = make_scene("looming", size=(64, 64)), ASNN()
    stamps = [50.0 * (k // 2) + 0.05 * (k % 2) for k in range(24)]  # 11 untimed, none in a row
    assert _timing_warnings(model, stamps, scene) == []


@pytest.mark.parametrize("stamps, told", [
    ([1000.0 * k / 20 for k in range(10)], "like a clock in milliseconds or nanoseconds"),
    ([3.0] * 10, "like a clock that stands still or goes back"),
    ([10.0 - k / 20 for k in range(10)], "like a clock that stands still or goes back"),
])
def test_the_timing_warning_tells_a_slow_clock_from_a_stalled_one(stamps, told):
    said = _timing_warnings(ASNN(), stamps, make_scene("looming", size=(64, 64)))
    assert len(said) == 1 and told in said[0] and "it believes 0.0001 to 1 s" in said[0]


def test_frames_without_times_are_not_warned_of_whatever_params_dt():
    """The warning asks for frame times in seconds: a stream given none is timed at dt as
    asked, even where dt is outside the gaps the model believes (here 10 us)."""
    scene = make_scene("looming", size=(64, 64))
    model = ASNN(asnn_preset("default", dt=1e-5))
    assert _timing_warnings(model, [None] * 20, scene) == []
    assert list(model.periods) == [1e-5] * 5


@pytest.mark.parametrize("threads", [1, 2])
def test_a_stream_left_on_the_frame_it_warns_on_has_warned(threads):
    """The warning comes with its frame's response: a consumer that stops there (islice, a
    break) has been told; raised on the next frame's request instead, it was never said."""
    import itertools
    import warnings

    scene = make_scene("looming", size=(64, 64))
    model = ASNN(threads=threads)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        taken = list(itertools.islice(
            model.stream((50.0 * k, frame) for k, frame in enumerate(scene.frames)), 6))
    assert [r.index for r in taken] == list(range(6))
    assert len([w for w in caught if issubclass(w.category, TimingWarning)]) == 1
    model.close()

def test_untimed_frames_in_a_row_in_a_timed_stream_each_come_a_frame_period_later():
    """Two or three frames in a row without a time (a camera's stamps dropped for a moment):
    each comes a frame period after the one before, not all at the same time (a gap of 0, a
    stall, and the next timed frame's gap believed as three periods' worth)."""
    frames = make_scene("looming", size=(64, 64), frames=40).frames
    model = ASNN("default")
    for k, f in enumerate(frames[:20]):
        model.step(f, k / 30.0)
    for f in frames[20:23]:
        model.step(f)
    model.step(frames[23], 23 / 30.0)
    assert list(model.periods)[-4:] == pytest.approx([1 / 30.0] * 4)


@pytest.mark.parametrize("frame, message", [
    ([[1, 2], [3, 4]], "numpy array"),
    (np.zeros((64, 64, 4), np.uint8), "gray"),
    (np.zeros((64,), np.uint8), "gray"),
    (np.zeros((64, 64), np.int32), "dtype"),
    (np.full((64, 64), np.nan), "NaN"),
    (np.full((64, 64), 2.0), r"\[0, 1\]"),
    (np.zeros((20, 64), np.uint8), "smaller"),
    (np.ma.masked_invalid(np.full((64, 64), np.nan)), "masked array"),  # its NaN hidden
    (np.full((64, 64), 1.001), r"\[1.001, 1.001\]"),  # bounds not rounded to 1
])
def test_bad_frames_get_a_clear_error(frame, message):
    with pytest.raises(FrameError, match=message):
        ASNN().step(frame)


def test_frame_size_change_is_an_error_until_reset():
    model = ASNN()
    model.step(np.zeros((64, 64), np.uint8))
    with pytest.raises(FrameError, match="differs"):
        model.step(np.zeros((64, 80), np.uint8))
    model.reset()
    assert model.step(np.zeros((64, 80), np.uint8)).index == 0


def test_a_rejected_frame_leaves_the_state_untouched():
    scene = make_scene("looming", size=(64, 64), stop=20)
    clean, disturbed = ASNN(), ASNN()
    for i, frame in enumerate(scene.frames):
        if i == 10:
            with pytest.raises(FrameError):
                disturbed.step(np.zeros((32, 32), np.uint8))
        if i in (0, 10):  # a bad time on the first frame does not fix the stream's size either
            for t in ("1.5", [1.0], True):
                with pytest.raises(FrameError, match="time t must be a number"):
                    disturbed.step(np.zeros((80, 80), np.uint8), t)
            with pytest.raises(FrameError, match="beyond a float's range"):  # not OverflowError
                disturbed.step(np.zeros((80, 80), np.uint8), 10**400)
        a, b = clean.step(frame), disturbed.step(frame)
    assert (a.u, a.index) == (b.u, b.index)


@pytest.mark.parametrize("params, threads, message", [
    (None, 1, "params must be a preset's name or an ASNNParams"),
    ({"top_k": 1}, 1, "got dict"),
    ("default", "2", "threads must be an int"),
    ("default", 2.7, "threads must be an int"),
])
def test_a_model_of_something_else_than_parameters_is_refused(params, threads, message):
    with pytest.raises(TypeError, match=message):
        ASNN(params, threads=threads)


@pytest.mark.parametrize("threads", [0, 257])
def test_a_model_of_more_threads_than_any_machine_has_is_refused(threads):
    """A probe: 10,000 threads did not step two frames in ten minutes on two cores."""
    with pytest.raises(ValueError, match="threads must be 1 to 256"):
        ASNN("default", threads=threads)


@pytest.mark.parametrize("changes, message", [
    ({"t_c": float("nan")}, "finite number"),
    ({"dog_gain": float("inf")}, "finite number"),
    ({"transmission": -5.0}, "greater than 0"),
    ({"tau": 1.0}, "dt \\* decay / tau is 3: the temporal filter \\(eq. 5\\) stepped by "
                   "forward Euler decays only below 1"),
    ({"dt": 0.5}, "grows without bound"),
    # a 10 fps camera's period as dt (1.2): each stage flips sign every frame
    ({"dt": 0.1}, "dt is the filter's integration step, not the camera's frame period"),
    ({"dt": 1 / 12}, "dt \\* decay / tau is 1: "),
    # eq. 1's history weights summing to 1 or more: P grows without bound
    ({"n_p": 16, "p_u": 0.5}, "p_i sum to 1.15, and P \\(eq. 1\\) grows without bound"),
    ({"n_p": 2, "p_u": 0.0}, "sum to 1,"),
    ({"cluster_eps": 4096}, "less than or equal to 255"),  # 100x slower a frame
    # sizes and counts that allocated gigabytes or stalled (hostile-input trial)
    ({"kernel_size": 10001}, "less than or equal to 255"),
    ({"dog_size": 1000000001}, "less than or equal to 255"),
    ({"attention_size": 257}, "less than or equal to 255"),
    ({"n_slow": 20000}, "less than or equal to 32"),
    ({"contrast_pool": 1e6}, "less than or equal to 63.75"),
    ({"n_t": 10**9}, "less than or equal to 1000"),
    ({"track_missed": 10**9}, "less than or equal to 1000"),
    ({"approach_frames": 10**9}, "less than or equal to 1000"),
    ({"repeat_block": 10**9}, "less than or equal to 255"),
    ({"k_sp": 2000}, "less than or equal to 100"),  # math.exp overflowed in the spike count
    # a spike every frame whatever u(t) (floor(e^0) = 1), or a ZeroDivisionError in the default
    ({"k_sp": 0}, "greater than 0"),
    # out(t) is never below 0.5, so a threshold there spikes, and T_c = 0 warns, every frame
    ({"t_sp": 0.5}, "greater than 0.5"),
    ({"t_c": 0}, "greater than 0"),
    ({"t_sp": -1000}, "greater than 0.5"),
    # accepted until a user trial: a traceback at the model's construction, gigabytes, or a
    # model blind on every frame
    ({"min_width": 20000}, "less than or equal to 1024"),  # 9 GiB
    ({"dog_sigma1": 1e-300}, "dog_sigma1 is 1e-300: at least 0.05 px"),  # 1/0
    ({"cs_sigma": 1e155}, "cs_sigma is 1e\\+155: at most 10000"),  # overflow
    ({"kernel_extent": 1e155}, "kernel_extent is 1e\\+155"),
    ({"min_object_pixels": 10**23}, "less than or equal to 16777216"),  # int64 in numba
    ({"gain": 1e30}, "gain is 1e\\+30: at most 10000"),  # float32 state: u = 0 every frame
    ({"v_on": -1e39}, "v_on is -1e\\+39"),
    ({"t_c": -1}, "greater than 0"),  # warned on every frame
])
def test_parameters_that_would_silence_or_blow_up_the_model_are_refused(changes, message):
    with pytest.raises(ValidationError, match=message):
        asnn_preset("default", **changes)


def test_parameters_changed_around_their_checks_are_refused_by_the_models():
    """pydantic's model_copy(update=...) skips validation; the optimised kernels index by the
    parameters without bounds checks (n_fast >= n_slow read past an array: finite garbage)."""
    from asnn.baselines import LGMD1, LGMD2, LGMD1Params, LGMD2Params

    for changes in ({"n_fast": 5}, {"t_c": float("nan")}):
        with pytest.raises(ValidationError):
            ASNN(asnn_preset("paper").model_copy(update=changes))
    with pytest.raises(ValidationError):
        LGMD1(LGMD1Params().model_copy(update={"t_s": float("nan")}))
    with pytest.raises(ValidationError):
        LGMD2(LGMD2Params().model_copy(update={"t_sp": float("nan")}))


def test_the_temporal_filter_stays_a_leaky_integrator_up_to_the_refused_step():
    # dt A / tau just under 1: each stage's own term decays without changing sign
    # (1 - 0.99 > 0), so a pulse of light (a step: one frame's difference) leaves stages that
    # are never negative and fade; above 1 they flipped sign every frame, and such steps are
    # refused (test_parameters_that_would_silence_or_blow_up_the_model_are_refused)
    model = ASNN(asnn_preset("default", tau=0.05 * 60 / 0.99), optimised=False)
    lowest, peak = 0.0, 0.0
    for k in range(60):
        model.step(np.full((64, 64), 0 if k < 5 else 200, np.uint8))
        lowest = min(lowest, model.stages_on.min(), model.stages_off.min())
        peak = max(peak, model.stages_on.max())
    assert lowest == 0.0 and peak > 0.0
    assert model.stages_on.max() < peak / 100


def test_maps_are_recorded_on_request_only():
    frames = make_scene("looming", size=(48, 48), start=2, stop=8).frames
    plain, recorded = ASNN(), ASNN(record_maps=True)
    for f in frames:
        a, b = plain.step(f), recorded.step(f)
    assert a.maps is None
    m = b.maps
    # on the model's grid: the default enlarges frames narrower than 160 px to 160
    assert m.R.shape == (8, 160, 160) and m.G.shape == m.V.shape == m.phi.shape == (160, 160)
    np.testing.assert_array_equal(m.G_prime, m.G * (m.M_a & m.M_d))
    np.testing.assert_allclose(m.R[4:], -m.R[:4])


def test_kernels_import_and_run_where_numba_can_write_no_cache():
    """A read-only install without a writable home (a locked-down container): numba finds no
    cache locator and refuses ``cache=True`` when a kernel is decorated, at import. Every module
    that defines kernels must still import (``asnn._jit.kernel`` falls back to no cache), and
    its kernels compile at first use: one looming fit, growing and shrinking, shows it. (The
    whole model compiled cold is what ``test_demo_on_a_fresh_install_warns`` runs; once is
    enough for the suite's time.)"""
    import os
    import subprocess
    import sys
    from pathlib import Path

    import asnn

    package = Path(asnn.__file__).parent
    modules = sorted(".".join(("asnn",) + path.relative_to(package).with_suffix("").parts)
                     for path in package.rglob("*.py") if "@kernel(" in path.read_text())
    assert {"asnn._fast", "asnn.approach.looming", "asnn.targets"} <= set(modules)
    code = (f"import importlib; [importlib.import_module(m) for m in {modules!r}]\n"
            "import numpy as np\n"
            "from asnn.approach.looming import region_expansion, _solve_expansion\n"
            "assert type(_solve_expansion._cache).__name__ == 'NullCache'\n"
            "y, x = np.mgrid[0:48, 0:48].astype(np.float32)\n"
            "disk = lambda r: (np.hypot(x - 24, y - 24) < r).astype(np.float32)\n"
            "box = (4, 4, 44, 44)\n"
            "print(region_expansion(disk(10), disk(11), box).rate,"
            " region_expansion(disk(11), disk(10), box).rate)\n")
    env = {**os.environ, "NUMBA_CACHE_LOCATOR_CLASSES": "ZipCacheLocator"}  # never applies
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    growing, shrinking = map(float, proc.stdout.split())
    assert growing > 0 > shrinking


def test_a_still_scene_leaves_no_subnormal_numbers_in_the_float32_state():
    """Where the picture stands still the cascades decay geometrically; in float32 they would
    pass through the subnormal numbers, which some CPUs compute many times slower (a step rose
    from 2 to 36 ms on one). The fused kernel flushes them."""
    import numpy as np

    from asnn.stimuli import make_scene

    scene = make_scene("looming", size=(64, 64), start=2, stop=20, frames=20)
    for name in ("robust", "reference32"):
        model = ASNN(name)
        for i, frame in enumerate(list(scene.frames) + [scene.frames[-1]] * 150):
            model.step(frame, i * 0.05)
            for stages in (model.stages_on, model.stages_off):
                magnitude = np.abs(stages)
                assert not np.any((magnitude > 0) & (magnitude < np.finfo(np.float32).tiny)), i
        assert model.stages_on.dtype == np.float32


def _responses(model, frames, stream):
    if stream:
        return [r.to_dict() for r in model.stream((None, f) for f in frames)]
    return [model.step(f).to_dict() for f in frames]


@pytest.mark.parametrize("preset", ["default", "reference", "paper"])
def test_threads_change_nothing_in_the_responses(preset):
    # off centre (no tie of the orientation sums), with repeated frames (the default preset
    # skips them) and a new stream of another size after a reset
    frames = make_scene("looming_over_stripes", size=(96, 72), frames=40, start=4, stop=36,
                        center=(40.3, 30.6)).frames
    frames = [f for i, f in enumerate(frames) for _ in range(1 + (i % 7 == 3))]
    other = make_scene("looming", size=(64, 80), frames=12, start=2, stop=10).frames
    want = ASNN(preset)
    expected = [_responses(want, frames, False)]
    want.reset()
    expected.append(_responses(want, other, False))
    for threads, stream in ((2, False), (2, True), (3, True)):
        with ASNN(preset, threads=threads) as model:
            assert model.threads == threads
            got = [_responses(model, frames, stream)]
            model.reset()
            got.append(_responses(model, other, stream))
        assert got == expected, (threads, stream)


@pytest.mark.parametrize("threads", [2, 3])
def test_an_empty_band_of_the_stepping_thread_changes_nothing(monkeypatch, threads):
    """The stepping thread's band may be empty (its other work outlasts the workers' whole
    pass): frames with and without it, in any alternation, give the responses of one thread."""
    from asnn import _parallel

    frames = make_scene("looming_over_stripes", size=(96, 72), frames=16, start=2, stop=14,
                        center=(40.3, 30.6)).frames
    calls = []

    def alternating(self, height):
        calls.append(height)
        inner = [round(i * height / threads) for i in range(1, threads - 1)]
        last = height if len(calls) % 3 else height - 20  # two empty bands, then one
        return [0, *inner, last, height]

    monkeypatch.setattr(_parallel.BandedFront, "borders", alternating)
    expected = _responses(ASNN("default"), frames, False)
    for stream in (False, True):
        with ASNN("default", threads=threads) as model:
            assert _responses(model, frames, stream) == expected, stream
    assert len(calls) >= 2 * (len(frames) - 1)


def test_the_stepping_thread_gets_no_band_when_its_other_work_outlasts_the_pass():
    """The borders (BandedFront._measure): with 1 ms of other work per frame and a worker that
    computes the whole frame in 0.8 ms, the stepping thread computes no rows; with 0.2 ms, it
    computes its share."""
    from asnn import _parallel

    coefficients = ASNN("default")._coefficients
    front = _parallel.BandedFront(coefficients, 1)
    try:
        h = 240
        for other, empty in ((1e-3, True), (0.2e-3, False)):
            front._cost, front._other, front._borders = [0.0, 0.0], [0.0, 0.0], None
            for _ in range(40):  # the running estimates settle
                borders = front.borders(h)
                rows = [borders[1], h - borders[1]]
                front._measure(borders, [0, 1], [(0.0, 0.8e-3 * rows[0] / h),
                                                 (other, 0.8e-3 * rows[1] / h)])
            borders = front.borders(h)
            assert (borders == [0, h, h]) == empty, (other, borders)
            if not empty:  # both done at about the same time
                assert 0.2e-3 + 0.8e-3 * (h - borders[1]) / h == pytest.approx(
                    0.05e-3 + 0.8e-3 * borders[1] / h, abs=0.02e-3)
    finally:
        front.close()


def test_threads_record_the_same_maps():
    frames = make_scene("looming", size=(64, 64), frames=10, start=2, stop=9,
                        center=(30.2, 33.7)).frames
    one, two = ASNN("default", record_maps=True), ASNN("default", record_maps=True, threads=2)
    for a, b in zip((one.step(f) for f in frames), two.stream((None, f) for f in frames)):
        assert (a.maps is None) == (b.maps is None)
        if a.maps is None:  # the first frame
            continue
        for name in ("P", "R", "V", "G", "M_a", "M_d", "G_prime"):
            np.testing.assert_array_equal(getattr(a.maps, name), getattr(b.maps, name))
    two.close()


def test_a_stream_raises_a_bad_frame_after_the_responses_before_it():
    frames = make_scene("looming", size=(64, 64), frames=8).frames
    bad = list(frames[:5]) + [np.zeros((64, 80), np.uint8)] + list(frames[5:])
    with ASNN("default", threads=2) as model:
        got = []
        with pytest.raises(FrameError, match="differs"):
            for response in model.stream((None, f) for f in bad):
                got.append(response.index)
    assert got == [0, 1, 2, 3, 4]


def test_a_stream_left_early_goes_on_as_a_step_by_step_run():
    frames = make_scene("looming_over_stripes", size=(160, 120)).frames
    one = ASNN()
    whole = [one.step(f, i / 20) for i, f in enumerate(frames)]
    with ASNN("default", threads=2) as model:
        for response in model.stream((i / 20, f) for i, f in enumerate(frames)):
            if response.index == 14:
                break  # frames 15 and 16 were taken already: they are finished, not lost
        assert model.index == 17
        rest = [model.step(f, i / 20) for i, f in enumerate(frames) if i >= model.index]
    # the whole response, targets and their tracks' ages and estimates too: a frame taken but
    # not finished would leave the tracker a frame short while u could still agree
    start = len(frames) - len(rest)
    assert ([r.record(start + k, (start + k) / 20) for k, r in enumerate(rest)]
            == [r.record(start + k, (start + k) / 20) for k, r in enumerate(whole[start:])])


def test_a_threaded_stream_is_not_reset_under_it():
    """A concurrency review: reset() at a response of a stream with worker threads, which has
    taken frames ahead, answered them with the reset model (indices 10, 11, 0, 1, ...), or
    failed on a frame of no size."""
    frames = make_scene("looming", size=(96, 72), frames=20).frames
    with ASNN("default", threads=2) as model:
        for response in model.stream((i / 20, f) for i, f in enumerate(frames)):
            if response.index == 9:
                with pytest.raises(RuntimeError, match="reset it between streams"):
                    model.reset()
        model.reset()  # between streams
        assert [r.index for r in model.stream((i / 20, f) for i, f in enumerate(frames))] \
            == list(range(len(frames)))


_LIFECYCLE = """
import faulthandler
import numpy as np
faulthandler.dump_traceback_later(90, exit=True)
from asnn import ASNN

rng = np.random.default_rng(0)
frames = [(i / 20, rng.integers(0, 255, (240, 320), dtype=np.uint8)) for i in range(30)]


def first_five():  # close() by the with block while the stream is suspended
    with ASNN("default", threads=2) as model:
        responses = model.stream(frames)
        for response in responses:
            if response.index == 5:
                return response.index
print("closed mid-stream:", first_five(), flush=True)

left = ASNN("default", threads=2).stream(frames)  # suspended at the interpreter's exit
for k, response in enumerate(left):
    if k == 5:
        break
print("exit", flush=True)
"""


def test_a_threaded_stream_closed_under_it_or_left_at_exit_does_not_hang(tmp_path):
    """A concurrency review: close() (a with block's) while a stream with worker threads was
    suspended hung it for good, and a stream left suspended when the interpreter exits hung
    the exit. Either would hang this child, which a fault handler ends after 90 s."""
    import subprocess
    import sys

    script = tmp_path / "lifecycle.py"
    script.write_text(_LIFECYCLE)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=180, cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.splitlines() == ["closed mid-stream: 5", "exit"]


def _raised_in_time(call, error):
    """What ``call`` raised of ``error``'s type (None if nothing), run on a thread of its own
    that must end within 60 s: a model that waits for ever fails the test, not the run."""
    import threading

    outcome = []

    def run():
        try:
            call()
        except error as exc:
            outcome.append(exc)

    runner = threading.Thread(target=run, daemon=True)
    runner.start()
    runner.join(timeout=60)
    assert not runner.is_alive(), "the model hung"
    return outcome[0] if outcome else None


@pytest.mark.parametrize("stream", [False, True])
def test_a_failure_on_a_worker_thread_is_raised_not_waited_for(monkeypatch, stream):
    from asnn import _parallel

    def failing(*args, **kwargs):  # the worker thread's kernel, which computes its bands
        raise MemoryError("no room on the worker")

    monkeypatch.setattr(_parallel, "_serve", failing)
    frames = make_scene("looming", size=(64, 64), frames=6).frames

    def run():
        with ASNN("default", threads=2) as model:
            _responses(model, frames, stream)

    raised = _raised_in_time(run, MemoryError)
    assert raised is not None and "no room on the worker" in str(raised)


@pytest.mark.parametrize("stream", [False, True])
def test_after_a_worker_s_failure_the_next_frames_get_fresh_workers(monkeypatch, stream):
    """A review: after a worker's failure was raised, the next step (or stream) raised it
    again, the failed workers kept (close() under the model's own use only marked them)."""
    import threading

    from asnn import _parallel

    serve, calls = _parallel._serve, []

    def failing_once(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise MemoryError("no room on the worker")
        return serve(*args, **kwargs)

    monkeypatch.setattr(_parallel, "_serve", failing_once)
    frames = make_scene("looming", size=(64, 64), frames=6).frames
    outcome = []

    def run():
        with ASNN("default", threads=2) as model:
            for attempt in range(2):
                try:
                    outcome.append(len(_responses(model, frames, stream)))
                except MemoryError:
                    outcome.append("failed")
                model.reset()

    runner = threading.Thread(target=run, daemon=True)
    runner.start()
    runner.join(timeout=60)
    assert not runner.is_alive(), "the model hung"
    assert outcome == ["failed", len(frames)]


def test_a_worker_thread_that_ended_is_raised_not_waited_for():
    """A review: the stepping thread waited for the workers' bands in a kernel that only a
    band done or a worker's recorded failure ended, so a worker thread that ended without
    either (died) left it waiting for ever; it now raises, and the model goes on after a
    reset with new worker threads."""
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (64, 64), np.uint8) for _ in range(6)]
    model = ASNN("default", threads=2)
    model.step(frames[0])
    model.step(frames[1])  # the worker is up
    server = model._banded._servers[0]
    server.wake(None)  # its thread ends as close() ends it, but unasked: as if it died
    server._thread.join(timeout=60)
    assert not server._thread.is_alive()
    raised = _raised_in_time(lambda: model.step(frames[2]), RuntimeError)
    assert raised is not None and "worker thread asnn-model-1 ended" in str(raised)
    # what the error tells to do is what the model takes: a step without reset() is refused
    assert "reset() the model" in str(raised)
    with pytest.raises(RuntimeError, match=r"interrupted part-way.*reset\(\)"):
        model.step(frames[2])
    model.reset()
    one = ASNN("default")
    assert [model.step(f).to_dict() for f in frames] == [one.step(f).to_dict() for f in frames]
    assert model._banded._servers[0]._thread.is_alive()  # a new worker
    model.close()


def test_a_worker_computes_its_band_while_the_stepping_thread_holds_the_gil():
    """A worker thread stays in its kernel between passes (asnn._parallel): it computes its
    band while the thread that steps the model runs Python and keeps the GIL (as finishing a
    frame does), instead of waiting until that thread lets go of it."""
    import sys
    import time

    frames = make_scene("looming", size=(64, 64), frames=4, start=0, stop=4).frames
    with ASNN("default", threads=2) as model:
        for _ in model.stream((None, f) for f in frames[:2]):  # the worker is up
            pass
        taken = model._take(frames[2], None)
        assert taken.photo is not None  # a new frame (not a repeat): it has a pass
        interval = sys.getswitchinterval()
        sys.setswitchinterval(10.0)  # Python hands the GIL over to no thread for 10 s
        try:
            model._start(taken, overlapped=True)
            number = taken.flight.number
            deadline = time.perf_counter() + 2.0
            while model._banded.served(0) < number and time.perf_counter() < deadline:
                pass
            served = model._banded.served(0)
        finally:
            sys.setswitchinterval(interval)
        model._banded.run_own(taken.flight)
        model._joined(taken)
        model._banded.settle((model.stages_on, model.stages_off))
    assert served >= number


def test_workers_that_left_their_kernel_come_back_with_the_same_responses():
    import threading
    import time

    frames = make_scene("looming", size=(64, 64), frames=9, start=2, stop=8,
                        center=(30.2, 33.7)).frames
    one = ASNN("default")
    expected = [one.step(f).to_dict() for f in frames]

    def slowly():  # pauses longer than a worker waits in its kernel for the next pass
        for i, f in enumerate(frames):
            if i % 3 == 2:
                time.sleep(0.08)
            yield None, f

    got = []

    def run():
        with ASNN("default", threads=2) as model:
            got.extend(r.to_dict() for r in model.stream(slowly()))

    runner = threading.Thread(target=run, daemon=True)
    runner.start()
    runner.join(timeout=60)
    assert not runner.is_alive(), "the model hung"
    assert got == expected


def test_threads_are_the_model_s_own_and_stop_with_it():
    import gc
    import threading

    # this model's worker threads: those alive now that were not before it (an earlier test's
    # model may still be winding its own down while this one runs)
    existing = {t for t in threading.enumerate() if t.name.startswith("asnn-model")}

    def workers():
        return sum(t.name.startswith("asnn-model") and t not in existing
                   for t in threading.enumerate())

    frames = make_scene("looming", size=(64, 64), frames=4).frames
    model = ASNN("default", threads=3)
    assert workers() == 0  # started with the first frame that needs them
    for f in frames:
        model.step(f)
    assert workers() == 2
    model.close()
    model.step(frames[0].copy())  # a closed model starts its threads again
    del model
    gc.collect()
    for _ in range(1000):  # the workers finish once told to stop (a loaded machine: be patient)
        if workers() == 0:
            break
        threading.Event().wait(0.01)
    assert workers() == 0
    with pytest.raises(ValueError, match="threads"):
        ASNN("default", threads=0)
    assert ASNN("default", optimised=False, threads=2).threads == 1


def test_where_the_attended_window_lies_compiles_no_second_form_of_a_kernel():
    """The attention kernels get arrays of one layout wherever the attended window lies (inside
    the frame, or from its corner once the object fills the view): numba compiles each once per
    precision, and compile_kernels has done so before a stream's first frame. A second compiled
    form, first needed at contact, stalled a service worker for seconds on a cold cache and
    the frames that came meanwhile went unanswered."""
    from asnn import _fast
    from asnn.warmup import compile_kernels
    from asnn.stimuli.planar import planar_scene

    compile_kernels()
    kernels = (_fast._attend, _fast._box)
    before = [set(k.signatures) for k in kernels]
    # a disk that grows from the middle until it fills the view (contact at frame 103)
    scene = planar_scene("loom", fps=25.0, size=(128, 128), tau=4.0, height=10.0,
                         position=(58.0, 66.0), onset=10)
    model = ASNN()
    for i, frame in enumerate(scene.frames):
        model.step(frame, i / 25.0)
    assert [set(k.signatures) for k in kernels] == before
    assert all(len({s[0].dtype for s in k.signatures}) == len(k.signatures) for k in kernels)


def test_the_spike_count_saturates_instead_of_overflowing():
    from asnn.retina import MAX_SPIKES, spike_count

    assert spike_count(0.9, 10.0, 0.7) == math.floor(math.exp(2.0))  # eq. 33 as it stands
    assert spike_count(1.0, 2000.0, -1000.0) == MAX_SPIKES  # exp(2e6) overflows a float
    assert spike_count(1.0, 21.0, 0.0) == math.floor(math.exp(21.0)) < MAX_SPIKES


def test_help_on_the_parameters_shows_what_each_field_means():
    from asnn.params import ASNNParams

    doc = ASNNParams.__doc__
    for name, info in ASNNParams.model_fields.items():
        assert f"    {name} : " in doc, name
    assert "treat a frame that hardly differs" in doc  # a description, not only the names


def test_kernels_are_compiled_for_a_preset_whose_kernels_are_larger_than_the_warmup_clip():
    # asnn detect --preset robust/attention_size=101 stopped here: the warm-up clip was 64x64
    from asnn.warmup import compile_kernels

    compile_kernels((asnn_preset("robust", attention_size=101),))


@pytest.mark.parametrize("optimised", [True, False])
def test_cluster_targets_of_a_resized_frame_are_in_the_frames_own_pixels(optimised):
    import cv2

    scene = make_scene("looming", size=(96, 96), start=2, stop=30, center=(60.0, 30.0))
    big = [cv2.resize(f, None, fx=4, fy=4, interpolation=cv2.INTER_NEAREST)
           for f in scene.frames]
    native = ASNN(asnn_preset("reference"), optimised=optimised)
    shrunk = ASNN(asnn_preset("reference", max_width=96), optimised=optimised)  # back to 96
    pairs = [(native.step(f), shrunk.step(g)) for f, g in zip(scene.frames, big)]
    assert sum(len(a.targets) for a, _ in pairs) > 5
    for a, b in pairs:
        assert len(a.targets) == len(b.targets)
        for ta, tb in zip(a.targets, b.targets):
            assert (tb.x, tb.y) == pytest.approx((4 * ta.x + 1.5, 4 * ta.y + 1.5), abs=1e-6)
            assert tb.pixels == 16 * ta.pixels


def test_a_model_stepped_from_two_threads_at_once_says_so():
    """A probe: one model stepped from two threads mixed their states without a word (threads=1)
    or stayed broken (threads=2)."""
    from threadutil import step_held_inside

    frames = make_scene("looming", size=(64, 64), frames=6).frames
    model = ASNN("default")
    with step_held_inside(model, "_take", frames[0]):  # the first thread's step
        with pytest.raises(RuntimeError, match="stepping already"):
            model.step(frames[1])
    assert model.step(frames[1]).index == 1  # the refused step changed nothing
    # a stream with worker threads holds the model until it is finished
    threaded = ASNN("default", threads=2)
    stream = threaded.stream((None, f) for f in frames)
    next(stream)
    with pytest.raises(RuntimeError, match="stepping already"):
        threaded.step(frames[0])
    stream.close()
    assert threaded.step(frames[0]).index == threaded.index - 1
    threaded.close()


def test_a_threaded_stream_that_fails_while_it_closes_frees_the_model(monkeypatch):
    """A review: a stream left early whose finishing of the frames it took raised (a worker's
    failure, a Ctrl-C) kept the model's lock: every later step said it was stepping already."""
    frames = make_scene("looming", size=(64, 64), frames=10).frames
    model = ASNN("default", threads=2)
    finish, calls = model._finish, []

    def failing(frame):
        calls.append(frame)
        if len(calls) == 2:
            raise KeyboardInterrupt("while the stream finished its taken frames")
        return finish(frame)

    monkeypatch.setattr(model, "_finish", failing)
    stream = model.stream((k / 20, f) for k, f in enumerate(frames))
    next(stream)
    with pytest.raises(KeyboardInterrupt):
        stream.close()
    monkeypatch.undo()
    # free, not stepping: it refuses the half-finished stream's frames until reset
    with pytest.raises(RuntimeError, match=r"interrupted part-way.*reset\(\)"):
        model.step(frames[5], 5 / 20)
    model.reset()
    assert model.step(frames[5], 5 / 20).index == model.index - 1 == 0
    model.close()


@pytest.mark.parametrize("threads", [1, 2])
def test_a_step_interrupted_part_way_is_refused_until_reset(monkeypatch, threads):
    """A review: a step that raised after its frame was taken (a stage's error, a Ctrl-C) left
    the model half-stepped, and stepped on without a word (a frame held as a repeat then got
    a response the model never finished; where none was, it raised AttributeError on None)."""
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (64, 64), np.uint8) for _ in range(4)]
    model = ASNN("default", threads=threads)
    model.step(frames[0], 0.0)

    def failing(frame):
        raise KeyboardInterrupt("in the output stage")

    monkeypatch.setattr(model, "_respond_optimised", failing)
    with pytest.raises(KeyboardInterrupt):
        model.step(frames[1], 0.05)
    monkeypatch.undo()
    for t, frame in ((0.1, frames[1]), (0.1, frames[2])):  # a repeat, a new frame
        with pytest.raises(RuntimeError, match=r"interrupted part-way.*reset\(\)"):
            model.step(frame, t)
    model.reset()
    expected = [r.to_dict() for r in ASNN("default").stream(
        (k / 20, f) for k, f in enumerate(frames))]
    assert [model.step(f, k / 20).to_dict() for k, f in enumerate(frames)] == expected
    model.close()


def test_a_threaded_stream_interrupted_in_its_frame_source_goes_on_as_one_thread_does():
    """A review: a Ctrl-C in the frame source of a stream with worker threads (a camera's
    read) left the frames it had taken unfinished, the first one's response never made: the
    next frame, a repeat, raised AttributeError on None. With one thread the model went on."""
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (64, 64), np.uint8) for _ in range(4)]

    def source():
        yield 0.0, frames[0]
        yield 0.05, frames[1]
        raise KeyboardInterrupt("while the camera was read")

    after = []
    for threads in (1, 2):
        model = ASNN("default", threads=threads)
        with pytest.raises(KeyboardInterrupt):
            for _ in model.stream(source()):
                pass
        # a repeat of the latest frame (the model's response held), then new ones
        after.append([model.step(f, t).to_dict() for t, f in
                      ((0.1, frames[1]), (0.15, frames[2]), (0.2, frames[3]))])
        assert model.index == 5
        model.close()
    assert after[1] == after[0]


def test_a_shallow_copy_is_a_snapshot_too():
    """copy.copy shared the state's arrays, deques and approach stage with the model (a user's
    snapshot): stepping the copy changed the original's later responses."""
    import copy

    frames = make_scene("looming", size=(64, 64), frames=30).frames
    model, twin = ASNN("default"), ASNN("default")
    for f in frames[:10]:
        model.step(f), twin.step(f)
    expected = [twin.step(f).to_dict() for f in frames[10:20]]
    snapshot = copy.copy(model)
    assert [snapshot.step(f).to_dict() for f in frames[10:20]] == expected
    assert [model.step(f).to_dict() for f in frames[10:20]] == expected  # untouched by it
    assert any(r["collision"] for r in expected)


def test_a_model_with_worker_threads_copies_and_pickles_mid_stream():
    """A probe: copy.deepcopy or pickle of a threads=2 model raised once its threads ran."""
    import copy
    import pickle

    frames = make_scene("looming", size=(64, 64), frames=30).frames
    model = ASNN("default", threads=2)
    for f in frames[:10]:
        model.step(f)
    copies = [copy.deepcopy(model), pickle.loads(pickle.dumps(model))]
    rest = [model.step(f).to_dict() for f in frames[10:]]
    for other in copies:
        assert [other.step(f).to_dict() for f in frames[10:]] == rest
        other.close()
    # inside a stream its worker threads hold frames under way: a copy then missed them and
    # answered u = 0 where the model warned (an integrator's probe)
    stream = model.stream((None, f) for f in frames)
    next(stream)
    for take in (copy.deepcopy, lambda m: pickle.loads(pickle.dumps(m))):
        with pytest.raises(RuntimeError, match="copy it between steps"):
            take(model)
    stream.close()
    copy.deepcopy(model).close()  # between steps again
    model.close()


@pytest.mark.parametrize("flag", ["optimised", "record_maps", "record_tracks"])
def test_the_model_s_switches_are_true_or_false(flag):
    # ASNN(optimised="no") built the optimised model: bool("no") is True
    for value in ("no", 0, None, "yes"):
        with pytest.raises(TypeError, match=f"{flag} must be True or False"):
            ASNN("default", **{flag: value})
    assert getattr(ASNN("default", **{flag: np.bool_(False)}), flag) is False


# ---------------------------------------------------------------- mutation-probe additions


@pytest.mark.parametrize("field", ["approach_gate", "scene_relative", "object_ids"])
def test_a_stage_that_works_on_the_objects_is_refused_without_them(field):
    with pytest.raises(ValidationError, match="targets='objects'"):
        asnn_preset("reference", **{field: True})
    asnn_preset("reference", targets="objects", **{field: True})  # the control


def test_a_spec_value_of_none_is_none():
    from asnn.params import parse_preset_spec, preset_from_spec

    assert parse_preset_spec("robust/max_width=none") == ("robust", (("max_width", None),))
    assert preset_from_spec("robust/max_width=None").max_width is None


@pytest.mark.parametrize("gaps, kept", [
    ([0.1, 0.1, 0.1, 1.6], 1.6),  # three believed in a row: frames lost, the gap as it was
    ([0.1, 0.1, 1.6], None),  # two: at dt (TIMED_RUN)
    ([0.1, 0.1, 0.1, 1.6, 1.6], None),  # once: the next must follow believed ones again
    ([0.1, 0.1, 0.1, 0.00005, 1.6], None),  # a gap not believed ends the run
    ([0.1, 0.1, 0.1, 0.00005], None),  # under MIN_FRAME_GAP_S: at dt whatever came before
])
def test_a_gap_over_a_second_keeps_its_time_only_right_after_three_believed(gaps, kept):
    """The rule of a stall (frames lost for over MAX_FRAME_GAP_S) gap by gap: the trials'
    streams pinned its effect on warnings, not which gaps it believes (a mutation probe)."""
    rng = np.random.default_rng(7)
    model, t = ASNN("default"), 50.0
    model.step(rng.integers(0, 256, (64, 64), dtype=np.uint8), t)
    for gap in gaps:
        t += gap
        model.step(rng.integers(0, 256, (64, 64), dtype=np.uint8), t)
    assert len(model.periods) == len(gaps) and not model.repeated
    assert model.periods[-1] == pytest.approx(model.params.dt if kept is None else kept)
