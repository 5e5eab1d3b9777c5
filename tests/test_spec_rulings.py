"""The rulings of SPEC.md section 2, one test each where no other file holds one.

Elsewhere: the kernels' grids ([-1, 1] for g_DS and g_CS, pixels for g_I) and the [0, 1] scale
in ``test_transcriptions.py``; out(t)'s sign in ``test_retina.py::test_spike_count_and_output``;
R^{theta+pi} = -R^theta in ``test_retina.py::test_gabor_pair_is_antisymmetric_under_half_turn``;
the first frame in ``test_model.py::test_first_frame_primes_and_responds_with_zeros``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from asnn import ASNN, preset, retina
from asnn.stimuli import make_scene
from asnn.targets import extract_targets


@pytest.fixture(scope="module")
def looming():
    return make_scene("looming", size=(64, 64), frames=14).frames


def test_intensities_are_scaled_to_0_1_before_the_photoreceptors(looming):
    model = ASNN("paper", optimised=False, record_maps=True)
    model.step(looming[0])
    for before, frame in zip(looming, looming[1:]):
        p = model.step(frame).maps.P
        np.testing.assert_array_equal(p, frame / 255.0 - before / 255.0)


def test_c_is_a_each_integrator_stage_has_unit_dc_gain():
    p = preset("paper")
    assert p.transmission is None and p.c == p.decay == 60.0
    stages = np.zeros((p.n_slow + 2, 1, 1))
    for _ in range(2000):
        retina.temporal_filter_step(stages, np.full((1, 1), 0.7), p.dt / p.tau, p.c, p.decay,
                                    leaky_input=False)
    np.testing.assert_allclose(stages[:, 0, 0], 0.7, rtol=1e-12)


def test_n_p_is_a_parameter_default_0_and_its_history_is_eq_1(looming):
    """P(t) = I(t) - I(t-1) + sum_{i=1..N_p} p_i P(t-i), p_i = 1/(1+e^i), in both forms."""
    assert preset("paper").n_p == 0
    n_p = 3
    for optimised, atol in ((False, 1e-15), (True, 1e-6)):
        model = ASNN(preset("paper", n_p=n_p), optimised=optimised, record_maps=True)
        model.step(looming[0])
        history: list[np.ndarray] = []  # P(t-1), P(t-2), ...
        for before, frame in zip(looming, looming[1:]):
            want = frame / 255.0 - before / 255.0
            for i, past in enumerate(history[:n_p], start=1):
                want = want + past / (1 + math.exp(i))
            history.insert(0, want)
            got = model.step(frame).maps.P
            np.testing.assert_allclose(got, want, rtol=0, atol=atol)


def test_the_spike_rate_divides_by_n_t_dt_from_the_first_frames():
    """Fewer than N_t frames seen: still (sum of their spikes) / (N_t dt)."""
    assert retina.spike_rate([3], 4, 0.05) == pytest.approx(3 / (4 * 0.05))
    assert retina.spike_rate([3, 1], 4, 0.05) == pytest.approx(4 / (4 * 0.05))
    p = preset("vehicle", t_sp=0.0, k_sp=1.0)  # a spike every frame from the second
    model = ASNN(p)
    frame = np.full((48, 48), 100, np.uint8)
    model.step(frame)
    r = model.step(frame)
    assert r.spikes == 1 and r.spike_rate == pytest.approx(1 / (p.n_t * p.dt))  # not 1 / dt


def test_a_clusters_direction_is_atan2_of_v_y_and_v_x_in_image_coordinates():
    """SPEC: atan2(V_Y, V_X), not the printed atan2(V_X, V_Y); x right, y down."""
    mask = np.zeros((20, 20), bool)
    mask[4:8, 10:16] = True  # off the diagonal: a centre with x and y swapped would not pass
    for angle in (0.0, math.pi / 2, 3 * math.pi / 4, -math.pi / 3):
        dx = np.full(mask.shape, 2.0 * math.cos(angle))
        dy = np.full(mask.shape, 2.0 * math.sin(angle))
        (target,) = extract_targets(mask, dx, dy, 5.0, 2)
        assert target.direction == pytest.approx(angle)
        assert target.energy == pytest.approx(2.0)
        assert (target.x, target.y) == (12.5, 5.5)


def test_the_retina_integrates_with_the_fixed_dt_whatever_the_timestamps(looming):
    plain, stamped = ASNN("paper"), ASNN("paper")
    times = np.cumsum(np.r_[0.0, np.random.default_rng(1).uniform(0.01, 0.2, len(looming) - 1)])
    for t, frame in zip(times, looming):
        assert stamped.step(frame, float(t)).u == plain.step(frame).u
