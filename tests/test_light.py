"""The light adaptation of the contrast gain control (``contrast_light``, in the default preset
since 2026-12-01: asnn.light)."""
import pickle

import numpy as np
import pytest

from asnn import ASNN
from asnn.light import LightAdaptation
from asnn.params import preset_from_spec
from cached_cases import make_case

FIXED = "robust/contrast_light=none/contrast_light_spread=none"  # the default before the stage


def _adaptation(**changes):
    options = dict(semi_saturation=0.005, reference=0.45, floor=0.25, tau=0.5, spread=3.0)
    return LightAdaptation(**{**options, **changes})


def test_a_dim_view_lowers_the_constant_by_its_light_down_to_the_floor():
    rng = np.random.default_rng(0)
    day = rng.uniform(0.35, 0.55, 2048)
    for light, expected in ((1.0, 0.005), (0.3, 0.005 * 0.3), (0.1, 0.005 * 0.25)):
        semi = _adaptation().step(day * light, 0.05)
        assert semi == pytest.approx(expected, rel=0.1)


def test_a_view_lit_in_pools_keeps_the_fixed_constant():
    view = np.full(2048, 0.04)
    view[-300:] = 0.35  # the headlights' beam over a seventh of the view
    assert _adaptation().step(view, 0.05) == 0.005
    assert _adaptation(spread=None).step(view, 0.05) == pytest.approx(0.005 * 0.25)


def test_the_light_is_followed_with_its_time_constant():
    adaptation = _adaptation(spread=None)
    day = np.full(2048, 0.45)
    assert adaptation.step(day, 0.05) == 0.005
    semi = [adaptation.step(day * 0.3, 0.05) for _ in range(30)]  # 1.5 s
    assert semi[0] > 0.004 and semi[-1] == pytest.approx(0.0015, rel=0.1)


@pytest.mark.parametrize("name", ["extra-sw-bollard-dusk"])
def test_both_forms_adapt_alike(name):
    frames = make_case(name).frames[:40]
    params = preset_from_spec("robust")
    fast, slow = ASNN(params), ASNN(params, optimised=False)
    for index, frame in enumerate(frames):
        a, b = fast.step(frame), slow.step(frame)
        # the optimised form samples float32 luminance, the straightforward one float64
        assert fast._semi_saturation == pytest.approx(slow._semi_saturation, rel=1e-6)
        assert index == 0 or slow._semi_saturation < 0.005  # from the first change on
        assert abs(a.u - b.u) <= max(1e-9, 1e-5 * abs(b.u))
        assert (a.spikes, a.collision) == (b.spikes, b.collision)


def test_a_dim_approach_the_fixed_constant_misses_is_warned_of_with_the_light_adapted_one():
    """The dusk held-out set's hydrant (0.35 of the day's light, a 0.4 m lens at 10 fps): with
    the fixed constant the attention keeps fragments and the default never warns; adapted to
    the light, it warns before contact."""
    scene = make_case("extra-dk-hydrant-low-camera-10fps")
    first = {}
    for spec in (FIXED, "robust"):
        model = ASNN(preset_from_spec(spec))
        warned = [model.step(frame, index / scene.fps).collision
                  for index, frame in enumerate(scene.frames)]
        first[spec] = warned.index(True) if any(warned) else None
    assert first[FIXED] is None
    assert first["robust"] is not None and first["robust"] < scene.contact_frame


def test_a_model_pickled_before_the_light_adaptation_steps_with_the_fixed_constant():
    frames = make_case("extra-sw-bollard-dusk").frames[:6]
    model = ASNN(preset_from_spec(FIXED))
    for frame in frames[:3]:
        model.step(frame)
    state = pickle.loads(pickle.dumps(model.__getstate__()))
    del state["_light"], state["_semi_saturation"]  # as a model pickled before the stage,
    for name in [n for n in vars(state["params"]) if n.startswith("contrast_light")]:
        del vars(state["params"])[name]  # with parameters that had no such fields
    old = ASNN.__new__(ASNN)
    old.__setstate__(state)
    assert old._semi_saturation == model.params.contrast_gain
    assert old.params.contrast_light is None
    for frame in frames[3:]:
        assert old.step(frame).u == model.step(frame).u
    old.reset()  # a new stream builds the stage from the parameters' defaults
    assert old._light is None
