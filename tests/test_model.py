"""Behaviour of the ASNN object: input handling, direction estimates, per-stream state."""

import math

import numpy as np
import pytest

from asnn import ASNN, FrameError
from asnn.stimuli import make_scene


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
    for k in range(8):
        theta = k * math.pi / 4  # image coordinates: y down, so pi/2 moves down the screen
        model = ASNN(preset, record_maps=True)
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


@pytest.mark.parametrize("frame, message", [
    ([[1, 2], [3, 4]], "numpy array"),
    (np.zeros((64, 64, 4), np.uint8), "gray"),
    (np.zeros((64,), np.uint8), "gray"),
    (np.zeros((64, 64), np.int32), "dtype"),
    (np.full((64, 64), np.nan), "NaN"),
    (np.full((64, 64), 2.0), r"\[0, 1\]"),
    (np.zeros((20, 64), np.uint8), "smaller"),
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
        a, b = clean.step(frame), disturbed.step(frame)
    assert (a.u, a.index) == (b.u, b.index)


def test_maps_are_recorded_on_request_only():
    frames = make_scene("looming", size=(48, 48), start=2, stop=8).frames
    plain, recorded = ASNN(), ASNN(record_maps=True)
    for f in frames:
        a, b = plain.step(f), recorded.step(f)
    assert a.maps is None
    m = b.maps
    assert m.R.shape == (8, 48, 48) and m.G.shape == m.V.shape == m.phi.shape == (48, 48)
    np.testing.assert_array_equal(m.G_prime, m.G * (m.M_a & m.M_d))
    np.testing.assert_allclose(m.R[4:], -m.R[:4])


def test_model_runs_where_numba_can_write_no_cache():
    """A read-only install without a writable home (a locked-down container): numba finds no
    cache locator; the kernels must still import and compile."""
    import os
    import subprocess
    import sys

    code = ("from asnn import ASNN; from asnn.stimuli import make_scene; m = ASNN(); "
            "print(max(m.step(f).u for f in make_scene('looming', size=(64, 64), start=2, "
            "stop=12).frames))")
    env = {**os.environ, "NUMBA_CACHE_LOCATOR_CLASSES": "ZipCacheLocator"}  # never applies
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert float(proc.stdout) > 0


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
