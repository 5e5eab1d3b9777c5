"""Motion layers of a box (asnn/approach/motion_layers.py) and the approach test's use of them
(asnn.approach.tracking.layers_approach, layers_pass)."""

import subprocess
import sys

import numpy as np
import pytest

from asnn.approach.motion_layers import Layer, motion_layers
from asnn.approach.tracking import (LAYER_OFFSET_FACTOR, LAYER_SHARE, LAYER_TAU_FACTOR, Track,
                           approaching, layer_estimates, layers_approach, layers_pass)
from imageutil import texture, warp

BOX = (150, 150, 250, 250)


def _texture():
    return texture((400, 400), blur=3.0)


def test_one_surface_is_one_motion():
    tex = _texture()
    grow = motion_layers(tex, warp(tex, 1.03), BOX)
    assert grow[0].share > 0.6 and grow[0].rate == pytest.approx(0.03, rel=0.35)
    assert abs(grow[0].drift_x) < 0.3 and abs(grow[0].drift_y) < 0.3
    slide = motion_layers(tex, warp(tex, dx=1.5), BOX)
    assert slide[0].share > 0.6 and abs(slide[0].rate) < 0.005
    assert slide[0].drift_x == pytest.approx(1.5, abs=0.3) and abs(slide[0].drift_y) < 0.3


def test_two_surfaces_moving_apart_are_two_motions_neither_expanding():
    # the left half slides left, the right half right: one least-squares expansion (what
    # region_expansion reads), but two translations
    tex = _texture()
    apart = np.hstack([warp(tex, dx=-1.5)[:, :200], warp(tex, dx=1.5)[:, 200:]])
    layers = motion_layers(tex, apart, BOX)
    assert len(layers) == 2 and all(layer.share > 0.25 for layer in layers)
    assert all(abs(layer.rate) < 0.01 for layer in layers)
    left, right = sorted(layers, key=lambda layer: layer.drift_x)
    assert left.drift_x == pytest.approx(-1.5, abs=0.3) and right.drift_x == pytest.approx(1.5, abs=0.3)


def test_motion_layers_are_deterministic_and_need_a_textured_box():
    tex = _texture()
    moved = warp(tex, 1.02, dx=0.5)
    assert motion_layers(tex, moved, BOX) == motion_layers(tex, moved, BOX)
    assert all(isinstance(layer, Layer) for layer in motion_layers(tex, moved, BOX))
    assert motion_layers(tex, moved, (10, 10, 16, 40)) == []  # too small to split
    flat = np.full((400, 400), 0.5, np.float32)
    assert motion_layers(flat, flat, BOX) == []


def test_a_box_passes_when_one_of_its_motions_is_an_approach():
    tau, limit = 1.5, 1.0
    coming = (0.5, 1.0, 0.3)  # share, ttc, offset
    assert layers_approach([coming], tau, limit)
    assert not layers_approach([(LAYER_SHARE / 2, 1.0, 0.3)], tau, limit)  # too small a part
    assert not layers_approach([(0.5, None, None)], tau, limit)  # contracting
    assert not layers_approach([(0.5, 1.01 * LAYER_TAU_FACTOR * tau, 0.3)], tau, limit)
    assert not layers_approach([(0.5, 1.0, 1.01 * LAYER_OFFSET_FACTOR * limit)], tau, limit)
    # a receding car and the roadside behind it: neither part is coming at us
    assert not layers_approach([(0.6, None, None), (0.3, 2.0, 4.0)], tau, limit)
    assert layers_approach([(0.6, None, None), (0.3, 1.0, 0.5)], tau, limit)
    # the limits are those of the test the track passes: the regime's wider offset
    assert layers_pass(((0.5, 0.9, 4.0),), 0.8, 1.6, tau, limit, (1.0, 2.0, 0.4))
    assert not layers_pass(((0.5, 0.9, 4.0),), 0.8, 0.6, tau, limit, (1.0, 2.0, 0.4))
    assert layers_pass(None, 0.8, 0.6, tau, limit)  # not measured


def test_layer_estimates_are_in_the_tracks_terms():
    # rate 2 per second, drift 30 px/s at the box centre, an object of size 10: ttc 0.5 s,
    # offset 30 / (2 * 10)
    assert layer_estimates([(0.7, 2.0, 18.0, 24.0), (0.2, -1.0, 5.0, 0.0)], 10.0) == (
        (0.7, 0.5, pytest.approx(1.5)), (0.2, None, None))
    assert layer_estimates([], 10.0) is None and layer_estimates(None, 10.0) is None
    track = Track(0, 0.0, 0.0, 20.0, 1.0, (0, 0, 40, 40))
    track.measure(1.0, 5.0, 0.0)  # ttc 1 s, offset 0.25: passes the test
    assert approaching(track, 1.5, 1.0)
    track.measure_layers([(0.6, -0.5, 0.0, 0.0), (0.3, 0.3, 40.0, 0.0)])  # neither comes at us
    assert not approaching(track, 1.5, 1.0)
    track.measure_layers([(0.6, 1.0, 5.0, 0.0)])
    assert approaching(track, 1.5, 1.0)
    track.measure_layers(None)
    assert track.layers is None and approaching(track, 1.5, 1.0)


def test_compile_kernels_loads_the_motion_layers_kernel_before_a_drive_needs_it():
    # a worker's first frame with a candidate in an expanding scene must not wait for numba
    from asnn import ASNN
    from asnn.warmup import compile_kernels
    from asnn.approach.motion_layers import _best_hypothesis
    from cached_cases import make_case

    # in a fresh process (here other tests may have compiled it already)
    loaded = subprocess.run(
        [sys.executable, "-c", "from asnn.warmup import compile_kernels; compile_kernels(); "
         "from asnn.approach.motion_layers import _best_hypothesis; "
         "print(len(_best_hypothesis.signatures))"],
        capture_output=True, text=True, check=True)
    assert int(loaded.stdout) >= 1
    compile_kernels()
    before = set(_best_hypothesis.signatures)
    scene = make_case("drive-day-cut-in-dark", 2)  # its cut-in is split into layers
    model = ASNN()
    layered = False
    for i, frame in enumerate(scene.frames):
        model.step(frame, i / scene.fps)
        layered = layered or bool(model.approach.layers)
    assert layered and set(_best_hypothesis.signatures) == before
