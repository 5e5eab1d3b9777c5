"""LGMD1-1 and LGMD1-2 baselines: interface and characteristic behaviour (SPEC.md section 4)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from asnn.baselines import (LGMD1, LGMD2, LGMD1Params, LGMD2Params, group_excitation,
                            spike_frequency_adaptation)
from asnn.detectors import make_detector
from asnn.frames import FrameError
from asnn.stimuli import make_scene

SIZE = (96, 96)


def _run(model, frames):
    return [model.step(f) for f in frames]


def _flash(levels, size=64):
    """A uniform field whose brightness follows ``levels`` (a whole-field change)."""
    return [np.full((size, size), level, dtype=np.uint8) for level in levels]


@pytest.fixture(scope="module")
def looming():
    return make_scene("looming", size=SIZE, start=8, stop=40)


@pytest.fixture(scope="module")
def translating():
    return make_scene("translating_bar", size=SIZE, speed=2.0, frames=40,
                      center=(10.0, 48.0), bar=(8.0, 40.0))


@pytest.mark.parametrize("cls", [LGMD1, LGMD2])
def test_interface_first_frame_targets_and_reset(cls, looming):
    model = cls()
    responses = _run(model, looming.frames[:20])
    first = responses[0]
    assert (first.index, first.u, first.out, first.spikes, first.collision) == (0, 0.0, 0.5, 0, False)
    assert [r.index for r in responses] == list(range(20))
    assert all(r.targets == [] and r.maps is None for r in responses)
    assert all(0.5 <= r.out < 1.0 for r in responses)
    model.reset()
    again = _run(model, looming.frames[:20])
    assert [r.u for r in again] == [r.u for r in responses]
    with pytest.raises(FrameError):
        model.step(np.zeros((50, 60), np.uint8))


@pytest.mark.parametrize("cls", [LGMD1, LGMD2])
def test_float_and_uint8_frames_agree(cls, looming):
    a = _run(cls(), looming.frames[:15])
    b = _run(cls(), [f / 255.0 for f in looming.frames[:15]])
    np.testing.assert_allclose([r.u for r in a], [r.u for r in b], rtol=1e-9)


def test_parameters_are_typed_and_overridable():
    assert LGMD1(w_i=0.6).params.w_i == 0.6
    assert LGMD2(LGMD2Params(n_ts=8)).params.n_ts == 8
    with pytest.raises(ValidationError):
        LGMD1Params(not_a_parameter=1)
    with pytest.raises(ValidationError):
        LGMD2Params(persistence=1.5)
    for params, changes in ((LGMD1Params, {"t_de": math.nan}), (LGMD2Params, {"theta1": math.nan}),
                            (LGMD2Params, {"tau_sfa": math.inf}),
                            (LGMD1Params, {"c_de": -math.inf})):
        with pytest.raises(ValidationError, match="must be a finite number"):
            params(**changes)  # a model that would never warn, or crash in its spike count
    assert LGMD1Params(t_ffi=math.inf).t_ffi == math.inf  # infinity switches the FFI off
    # the membrane potential is never below 0.5: a threshold there spikes every frame, as does
    # a gain of 0 (a negative one spikes below the threshold): a warning on every frame
    for params, changes, said in ((LGMD1Params, {"t_s": 0.5}, "greater than 0.5"),
                                  (LGMD2Params, {"t_sp": 0.4}, "greater than 0.5"),
                                  (LGMD2Params, {"k_sp": 0.0}, "greater than 0"),
                                  (LGMD2Params, {"k_sp": -4.0}, "greater than 0"),
                                  (LGMD2Params, {"t_sp": 0.5}, "greater than 0.5"),
                                  # and past 1 never (a threshold K^ cannot reach), or past a
                                  # gain of 100 math.exp can overflow in the spike count
                                  (LGMD1Params, {"t_s": 1.5}, "less than or equal to 1"),
                                  (LGMD2Params, {"t_sp": 1.5}, "less than or equal to 1"),
                                  (LGMD2Params, {"k_sp": 2000.0}, "less than or equal to 100")):
        with pytest.raises(ValidationError, match=said):
            params(**changes)
    # persistence weights summing to 1 or more: P_f grew to 5e50 on a still, noisy scene
    with pytest.raises(ValidationError, match="grows without bound"):
        LGMD1Params(n_p=8, p_u=0.0)
    for params in (LGMD1Params(), LGMD2Params()):  # every default documents its source
        assert all(f.description for f in type(params).model_fields.values())


def test_the_longest_photoreceptor_history_allowed_stays_bounded_on_a_still_noisy_scene():
    # n_p = 16 at the paper's u = 1 sums its weights to 0.46: P_f stays within 4 / (1 - 0.46)
    # gray levels of 4-level noise over 300 frames (weights summing to 1.15 made it 1.5e6, and
    # such weights are refused)
    rng = np.random.default_rng(0)
    still = rng.integers(100, 110, (48, 64)).astype(np.uint8)
    model = LGMD1(n_p=16)
    for _ in range(300):
        frame = np.clip(still + rng.integers(-2, 3, still.shape), 0, 255).astype(np.uint8)
        response = model.step(frame)
    assert np.isfinite(response.u) and not response.collision
    assert np.abs(model.history[-1]).max() < 4 / (1 - 0.46)


def test_factory_builds_the_baselines():
    assert isinstance(make_detector("lgmd1"), LGMD1)
    assert isinstance(make_detector("lgmd2", "paper"), LGMD2)
    with pytest.raises(ValueError, match="nopreset"):  # ignored by the LGMDs, still checked
        make_detector("lgmd1", "nopreset")
    with pytest.raises(ValueError, match="record_maps apply to the ASNN model only"):
        make_detector("lgmd1", record_maps=True)
    # a baseline's own parameters in the preset's place were dropped without a word (a user
    # trial): they are its parameters; another model's are refused
    assert make_detector("lgmd1", LGMD1Params(w_i=0.6)).params.w_i == 0.6
    assert make_detector("lgmd2", LGMD2Params(t_ffi=0.2)).params.t_ffi == 0.2
    with pytest.raises(TypeError, match="lgmd2 takes LGMD2Params .or params=...., not "
                       "LGMD1Params"):
        make_detector("lgmd2", LGMD1Params())
    with pytest.raises(TypeError, match="asnn takes a preset's name or ASNNParams, not "
                       "LGMD1Params"):  # it read "unknown preset LGMD1Params(n_p=0, ...)"
        make_detector("asnn", LGMD1Params())
    with pytest.raises(ValueError, match="given twice"):
        make_detector("lgmd1", LGMD1Params(), params=LGMD1Params())
    with pytest.raises(ValueError, match=r"in Python: make_detector\('lgmd1', FIELD=VALUE\)"):
        make_detector("lgmd1", "lgmd1/w_i=0.6")


def test_grouping_keeps_only_clustered_excitation():
    s = np.zeros((20, 20))
    s[2:7, 2:7] = 100.0      # a strong cluster sets omega = 0.01 + 100 / 4
    s[12:17, 2:7] = 30.0     # a weak cluster: Ce = 30, G = 30 * 30 / 25 = 36, kept
    s[15, 15] = 30.0         # an isolated pixel as strong: Ce = 30 / 9, G = 4, dropped
    g = group_excitation(s, c_w=4.0, delta_c=0.01, c_de=0.5, t_de=15.0)
    assert g[4, 4] > 0 and g[14, 4] > 0 and g[15, 15] == 0.0
    assert (g >= 0).all()


def test_spike_frequency_adaptation_rule():
    a3 = 0.8 / 0.85
    # a rise above T_sfa restarts from K(t)
    assert spike_frequency_adaptation(0.6, 0.7, 0.9, a3, 0.003) == pytest.approx(a3 * 0.9)
    # a steady K(t) decays the adapted potential, down to 0.5
    assert spike_frequency_adaptation(0.9, 0.9, 0.9, a3, 0.003) == pytest.approx(a3 * 0.9)
    assert spike_frequency_adaptation(0.51, 0.9, 0.9, a3, 0.003) == 0.5


def test_lgmd1_fires_on_approach(looming):
    responses = _run(LGMD1(), looming.frames)
    warned = [r.index for r in responses if r.collision]
    assert warned and looming.onset_frame <= warned[0] <= looming.contact_frame
    assert not any(r.spikes for r in responses[:looming.onset_frame])


def test_lgmd1_also_fires_on_fast_translation():
    # a small bar, so that the whole-field feed-forward inhibition stays below its threshold
    scene = make_scene("translating_bar", size=SIZE, speed=4.0, frames=20, center=(10.0, 48.0),
                       bar=(8.0, 24.0))
    responses = _run(LGMD1(), scene.frames)
    assert any(r.collision for r in responses)
    assert sum(r.spikes for r in responses[5:]) >= 10


def test_lgmd2_fires_on_approach(looming):
    responses = _run(LGMD2(), looming.frames)
    warned = [r.index for r in responses if r.collision]
    assert warned and looming.onset_frame <= warned[0] <= looming.contact_frame


def test_lgmd2_adaptation_quiets_a_steady_translation(translating):
    adapted = _run(LGMD2(), translating.frames)
    unadapted = _run(LGMD2(sfa=False), translating.frames)
    late = slice(20, None)  # the bar has been moving at a constant speed for 19 frames
    assert sum(r.spikes for r in adapted[late]) == 0
    assert not any(r.collision for r in adapted)
    # without adaptation the same stimulus keeps the cell firing and warning
    assert sum(r.spikes for r in unadapted[late]) >= 10
    assert any(r.collision for r in unadapted)
    # the excitation itself is the same: adaptation acts on the output only
    np.testing.assert_allclose([r.u for r in adapted], [r.u for r in unadapted])


@pytest.mark.parametrize("spikes, warns", [((0, 0, 3, 0, 3, 0, 3), False), ((0, 0, 3, 3), True)])
def test_lgmd2_counts_spikes_in_a_run_that_a_frame_without_spikes_ends(monkeypatch, looming,
                                                                        spikes, warns):
    # SPEC section 4: a running count of spikes, reset when a frame has none, reaches N_ts;
    # without the reset, scattered single spikes added up to a warning (a mutation probe)
    import asnn.baselines as baselines

    counts = iter(spikes)
    monkeypatch.setattr(baselines, "spike_count", lambda *args: next(counts))
    model = LGMD2(LGMD2Params(sfa=False, n_ts=5, t_ffi=1e9))
    responses = [model.step(frame) for frame in looming.frames[:len(spikes) + 1]]
    assert any(r.collision for r in responses) is warns
    assert responses[-1].collision is warns


@pytest.mark.parametrize("cls, options", [(LGMD1, {}), (LGMD2, {"sfa": False})])
def test_feed_forward_inhibition_suppresses_a_whole_field_flash(cls, options):
    # LGMD1-2 without adaptation, which on its own would quiet a steady flash after a few frames
    frames = _flash([40] * 4 + [40 + 30 * k for k in range(1, 7)] + [220] * 3)
    on = _run(cls(**options), frames)
    off = _run(cls(t_ffi=math.inf, **options), frames)
    flash = slice(5, 10)
    # without FFI the brightening field drives the cell to spike every frame
    assert all(r.spikes for r in off[flash])
    # with FFI at most the flash's first frame escapes (LGMD1-1's F_f looks one frame back)
    assert sum(bool(r.spikes) for r in on[flash]) <= 1
    assert not any(r.collision for r in on)
    assert all(r.out == 0.5 for r in on[6:10])
    assert any(r.collision for r in off)


@pytest.mark.parametrize("make", [LGMD1, LGMD2])
def test_a_frame_time_that_is_not_a_number_is_refused_as_asnn_refuses_it(make):
    model = make()
    model.step(np.zeros((64, 64), np.uint8))
    with pytest.raises(FrameError, match="must be a number of seconds"):
        model.step(np.zeros((64, 64), np.uint8), "abc")  # was taken without a word
    assert model.step(np.zeros((64, 64), np.uint8), 0.1).index == 1  # nothing counted before


@pytest.mark.parametrize("params", [LGMD1Params, LGMD2Params])
def test_the_parameters_docstring_describes_every_field(params):
    for name, info in params.model_fields.items():  # help() shows them
        assert f"    {name} : " in params.__doc__
        assert info.description.split(";")[0][:40] in params.__doc__


def test_factory_ignores_an_asnn_preset_for_the_baselines_and_hints_each_by_name():
    # an evaluation builds every detector with the same preset, as a name or as ASNNParams:
    # the baselines ignore both (make_detector's docstring); the slash hint names the model
    from asnn.params import preset

    for model, params_class in (("lgmd1", LGMD1Params), ("lgmd2", LGMD2Params)):
        assert make_detector(model, preset("robust")).params == params_class()
        assert make_detector(model, "robust").params == params_class()
        with pytest.raises(ValueError, match=rf"in Python: make_detector\('{model}', FIELD="):
            make_detector(model, f"{model}/dt=0.1")


@pytest.mark.parametrize("name", ["lgmd1", "lgmd2"])
def test_an_lgmd_model_stepped_from_two_threads_at_once_says_so(name):
    """As the ASNN: one baseline stepped from two threads mixed their states without a word."""
    import copy
    import pickle

    from threadutil import step_held_inside

    frames = make_scene("looming", size=(64, 64), frames=4).frames
    model = make_detector(name)
    with step_held_inside(model, "_luminance", frames[0]):  # the first thread's step
        with pytest.raises(RuntimeError, match="stepping already"):
            model.step(frames[1])
        with pytest.raises(RuntimeError, match="copy it between steps"):
            copy.deepcopy(model)
    assert model.step(frames[1]).index == 1  # the refused step changed nothing
    looming = make_scene("looming", size=(64, 64)).frames
    for snapshot in (copy.deepcopy, copy.copy):  # a snapshot, stepped, leaves the model be
        model.reset()
        for f in looming[:20]:
            model.step(f)
        reference, twin = pickle.loads(pickle.dumps(model)), snapshot(model)
        for f in looming[20:30]:
            twin.step(f)
        assert model.step(looming[20]).to_dict() == reference.step(looming[20]).to_dict()
