"""The light adaptation of the contrast gain control (``contrast_light``, a prototype off by
default: asnn.light)."""
import numpy as np
import pytest

from asnn import ASNN
from asnn.light import LightAdaptation
from asnn.params import preset_from_spec
from asnn.stimuli.suite import make_case

SPEC = "robust/contrast_light=0.45/contrast_light_spread=3/contrast_light_noise=0.5"


def _adaptation(**changes):
    options = dict(semi_saturation=0.005, reference=0.45, floor=0.25, tau=0.5, spread=3.0,
                   noise=0.5)
    return LightAdaptation(**{**options, **changes})


def test_a_dim_view_lowers_the_constant_by_its_light_down_to_the_floor():
    rng = np.random.default_rng(0)
    day = rng.uniform(0.35, 0.55, 2048)
    for light, expected in ((1.0, 0.005), (0.3, 0.005 * 0.3), (0.1, 0.005 * 0.25)):
        semi = _adaptation().step(day * light, None, 0.05)
        assert semi == pytest.approx(expected, rel=0.1)


def test_a_view_lit_in_pools_keeps_the_fixed_constant():
    view = np.full(2048, 0.04)
    view[-300:] = 0.35  # the headlights' beam over a seventh of the view
    assert _adaptation().step(view, None, 0.05) == 0.005
    assert _adaptation(spread=None).step(view, None, 0.05) == pytest.approx(0.005 * 0.25)


def test_noise_holds_the_constant_up_and_never_above_its_fixed_value():
    rng = np.random.default_rng(1)
    dim = rng.uniform(0.1, 0.16, 2048)
    previous = dim + rng.normal(0.0, 3 / 255, dim.size)
    clean = _adaptation().step(dim, dim, 0.05)
    noisy = _adaptation().step(dim, previous, 0.05)
    assert clean == pytest.approx(0.005 * 0.13 / 0.45, rel=0.1)
    assert clean < noisy <= 0.005


def test_the_light_is_followed_with_its_time_constant():
    adaptation = _adaptation(spread=None, noise=0.0)
    day = np.full(2048, 0.45)
    assert adaptation.step(day, None, 0.05) == 0.005
    semi = [adaptation.step(day * 0.3, None, 0.05) for _ in range(30)]  # 1.5 s
    assert semi[0] > 0.004 and semi[-1] == pytest.approx(0.0015, rel=0.1)


@pytest.mark.parametrize("name", ["extra-sw-bollard-dusk"])
def test_both_forms_adapt_alike(name):
    frames = make_case(name).frames[:40]
    params = preset_from_spec(SPEC)
    fast, slow = ASNN(params), ASNN(params, optimised=False)
    for index, frame in enumerate(frames):
        a, b = fast.step(frame), slow.step(frame)
        # the optimised form samples float32 luminance, the straightforward one float64
        assert fast._semi_saturation == pytest.approx(slow._semi_saturation, rel=1e-6)
        assert index == 0 or slow._semi_saturation < 0.005  # from the first change on
        assert abs(a.u - b.u) <= max(1e-9, 1e-5 * abs(b.u))
        assert (a.spikes, a.collision) == (b.spikes, b.collision)
