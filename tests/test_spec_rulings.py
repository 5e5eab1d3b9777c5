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
    from collections import deque

    from asnn.model import spike_step

    p = preset("vehicle")  # the model's output stage, on its first frame: out(t) = 1
    out, spikes, rate = spike_step(1e9, 100, deque(maxlen=p.n_t), p)
    assert out == 1.0 and spikes == 20  # floor(exp(10 (1 - 0.7)))
    assert rate == pytest.approx(20 / (p.n_t * p.dt))  # not 20 / dt


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


def test_the_origin_seed_counts_in_the_cluster_it_joins():
    """The published variant adds the point (0, 0) to DBSCAN: where it is a core sample it
    belongs to a cluster, whose size, centre and mean motion count it (its motion is the
    pixel's at (0, 0))."""
    mask = np.zeros((20, 20), bool)
    mask[0:5, 0:5] = True  # a blob at the corner, (0, 0) in it
    dx, dy = np.full(mask.shape, 1.0), np.zeros(mask.shape)
    dx[0, 0] = 3.5  # the seed's motion: 26 vectors of mean (25 + 3.5) / 26, with (0, 0)'s twice
    (target,) = extract_targets(mask, dx, dy, 2.0, 3, origin_seed=True)
    assert target.pixels == 26  # 25 core pixels and the seed
    assert (target.x, target.y) == (pytest.approx(50 / 26), pytest.approx(50 / 26))
    assert target.energy == pytest.approx((24 + 3.5 * 2) / 26)
    (plain,) = extract_targets(mask, dx, dy, 2.0, 3)
    assert plain.pixels == 25 and (plain.x, plain.y) == (2.0, 2.0)


def test_only_a_cluster_centred_within_a_pixel_of_the_origin_is_dropped():
    dx, dy = np.ones((20, 20)), np.zeros((20, 20))
    near = np.zeros((20, 20), bool)
    near[0:3, 0:3] = True  # with the seed: centred at (0.9, 0.9), 1.27 px from the origin
    (target,) = extract_targets(near, dx, dy, 2.0, 3, origin_seed=True)
    assert (target.x, target.y) == (pytest.approx(0.9), pytest.approx(0.9))
    on = np.zeros((20, 20), bool)
    on[0:2, 0:2] = True  # centred at (0.4, 0.4): the seed's own cluster, dropped
    assert extract_targets(on, dx, dy, 1.5, 3, origin_seed=True) == []


def test_a_seed_that_is_a_cluster_of_its_own_is_dropped_beside_the_others():
    """Two pixels 2 px from the origin make the seed a core sample but are not core samples
    themselves: the seed is a cluster alone (numbered after the pixels' clusters), centred on
    the origin and dropped."""
    mask = np.zeros((20, 20), bool)
    mask[0, 2] = mask[2, 0] = True
    mask[10:13, 10:13] = True
    dx, dy = np.ones(mask.shape), np.zeros(mask.shape)
    (target,) = extract_targets(mask, dx, dy, 2.0, 3, origin_seed=True)
    assert (target.x, target.y, target.pixels) == (11.0, 11.0, 9)
