"""Approach selectivity of the published variant on the paper's generated scenes (Figs. 6, 7).

The published variant answers dark objects; ``light`` swaps ON and OFF for light ones. The
default (robust) preset answers both polarities itself: tests/test_robust.py.
"""

import numpy as np
import pytest

from asnn import ASNN
from asnn.stimuli import make_scene

PRESET_FOR = {"dark": "reference32", "light": "light"}


def _run(scene_name: str, polarity: str, **kw):
    scene = make_scene(scene_name, polarity=polarity, **kw)
    model = ASNN(PRESET_FOR[polarity])
    responses = [model.step(frame) for frame in scene.frames]
    return scene, responses


def _peak(responses) -> float:
    return max(abs(r.u) for r in responses)


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_approach_beats_recession_and_translation_fivefold(polarity):
    scene, looming = _run("looming", polarity)
    _, receding = _run("receding", polarity)
    _, bar = _run("translating_bar", polarity)
    assert _peak(looming) > 0
    assert _peak(looming) >= 5 * _peak(receding)
    assert _peak(looming) >= 5 * _peak(bar)
    warned = [r.index for r in looming if r.collision]
    assert warned and scene.onset_frame <= warned[0] <= scene.contact_frame
    assert not any(r.collision for r in receding + bar)


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_approach_and_recession_in_one_clip_warns_only_on_approach(polarity):
    scene, responses = _run("approach_recession", polarity)
    warned = [r.index for r in responses if r.collision]
    assert warned
    # warnings start during the approach and end within the spike window after it
    assert scene.onset_frame <= warned[0] and warned[-1] <= scene.contact_frame + 4


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_approach_detected_over_translating_stripes(polarity):
    scene, responses = _run("looming_over_stripes", polarity)
    warned = [r.index for r in responses if r.collision]
    assert warned
    assert scene.onset_frame <= warned[0] <= scene.contact_frame
    assert any(r.targets for r in responses if r.collision)


@pytest.mark.parametrize("polarity", ["dark", "light"])
def test_translating_stripes_alone_raise_no_warning(polarity):
    _, responses = _run("stripes", polarity)
    assert not any(r.collision for r in responses)


def test_targets_locate_the_looming_disk():
    scene, responses = _run("looming", "dark", center=(40.0, 70.0))
    hits = [r for r in responses if r.collision and r.targets]
    assert hits
    for r in hits:
        radius = 6.0 + max(0, min(r.index, scene.contact_frame) - scene.onset_frame) * 1.05
        nearest = min(np.hypot(t.x - 40.0, t.y - 70.0) for t in r.targets)
        assert nearest <= radius  # on the disk, whose edge is where it looms
    early = [r for r in hits if r.index < scene.onset_frame + 15]
    assert early and all(min(np.hypot(t.x - 40.0, t.y - 70.0) for t in r.targets) < 8
                         for r in early)
