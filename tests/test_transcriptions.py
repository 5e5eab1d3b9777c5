"""The paper's model and the baselines against transcriptions of their text, written here apart
from the package's code (straight from the paper's equations and SPEC.md sections 1, 2 and 4,
in the most direct form: true convolutions, loops over the stages, no fused kernels), so that a
changed constant, normaliser or sign in the package fails a test. Only ``reference`` is also
pinned to the published implementation's outputs (test_reference.py)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from asnn import ASNN, preset
from asnn.baselines import LGMD1, LGMD2, LGMD1Params, LGMD2Params
from asnn.frames import luma
from asnn.retina import photoreceptor_weights
from asnn.stimuli import make_scene

BORDER = cv2.BORDER_REFLECT_101


def correlate(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    return cv2.filter2D(x, cv2.CV_64F, k, borderType=BORDER)


def convolve(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """A true convolution (the paper's ⊗): the kernel flipped."""
    return correlate(x, k[::-1, ::-1])


def relu(z: np.ndarray) -> np.ndarray:
    return np.maximum(z, 0.0)


@pytest.fixture(scope="module")
def scenes():
    return {name: make_scene(name, size=(64, 64), frames=40).frames
            for name in ("looming", "approach_recession_over_stripes", "translation")}


# ---------------------------------------------------------------- the input and eq. 1

def test_photoreceptor_persistence_weights_are_eq_1s():
    u = 1.0
    assert photoreceptor_weights(3, u) == pytest.approx(
        [1 / (1 + math.exp(u * i)) for i in (1, 2, 3)], rel=1e-15)
    assert photoreceptor_weights(2, 0.5)[1] == pytest.approx(1 / (1 + math.exp(1.0)))


def test_a_colour_frame_is_seen_through_opencvs_luma_of_bgr():
    """SPEC section 3: 0.299 R + 0.587 G + 0.114 B, rounded to uint8, for BGR frames."""
    frame = np.zeros((4, 6, 3), np.uint8)
    frame[0, :, 0] = 255  # blue
    frame[1, :, 2] = 255  # red
    frame[2, :, 1] = 255  # green
    frame[3] = (10, 200, 90)
    expected = [round(0.114 * 255), round(0.299 * 255), round(0.587 * 255),
                round(0.114 * 10 + 0.587 * 200 + 0.299 * 90)]
    assert luma(frame)[:, 0].tolist() == expected


# ---------------------------------------------------------------- the paper's model

def paper_model_u(frames: np.ndarray, p) -> list[float]:
    """u(t) of the paper's ASNN (eqs. 1-7, 9-28; SPEC section 1 for the paper's gaps), with
    the ``paper`` preset's values: P the frame difference (N_p = 0), g_I the printed
    difference of Gaussians F (exp(-r²/2σ1²)/(√(2π)σ1) - exp(-r²/2σ2²)/(√(2π)σ2)) in pixels,
    the temporal filter's cascade (eqs. 5, 6) stepped stage by stage (SPEC's order), g_DS
    and g_CS on [-1, 1]² (5x5), the printed attention Gaussian exp(-r²/2σ²)/(2πσ²) on 31x31."""
    r = p.dog_size // 2
    y, x = np.mgrid[-r:r + 1, -r:r + 1].astype(float)
    r2 = x * x + y * y
    s1, s2 = p.dog_sigma1, p.dog_sigma2
    g_i = p.dog_gain * (np.exp(-r2 / (2 * s1**2)) / (math.sqrt(2 * math.pi) * s1)
                        - np.exp(-r2 / (2 * s2**2)) / (math.sqrt(2 * math.pi) * s2))
    axis = np.linspace(-1, 1, 5)
    gx, gy = np.meshgrid(axis, axis)

    def gabor(theta, psi):
        xr = gx * math.cos(theta) + gy * math.sin(theta)
        yr = -gx * math.sin(theta) + gy * math.cos(theta)
        return (np.exp(-(xr**2 + yr**2) / (2 * p.ds_sigma**2))
                * np.cos(2 * math.pi * xr / p.ds_wavelength + psi))

    rr = gx * gx + gy * gy
    g_cs = 1 - np.exp(-rr / (2 * p.cs_sigma**2)) * np.cos(2 * math.pi * rr / p.cs_wavelength)
    a = np.arange(-(p.attention_size // 2), p.attention_size // 2 + 1, dtype=float)
    g_sigma = (np.exp(-(a[:, None]**2 + a[None, :]**2) / (2 * p.attention_sigma**2))
               / (2 * math.pi * p.attention_sigma**2))
    c_coefficient = p.decay if p.transmission is None else p.transmission  # C = A (SPEC)
    stages = {c: np.zeros((p.n_slow + 2,) + frames[0].shape) for c in "+-"}
    previous, us = None, []
    for frame in frames:
        image = frame / 255.0
        if previous is None:
            previous = image
            us.append(0.0)
            continue
        diff, previous = image - previous, image
        bipolar = {"+": convolve(relu(diff), g_i), "-": convolve(relu(-diff), g_i)}
        fast_slow = {}
        for c in "+-":
            z = stages[c]
            z[0] = bipolar[c]
            for n in range(1, len(z)):  # tau dz_n/dt = C z_{n-1} - A z_n, eq. 5
                z[n] += p.dt / p.tau * (c_coefficient * z[n - 1] - p.decay * z[n])
            fast_slow[c] = (p.gain * (z[p.n_fast] - z[p.n_fast + 1]),  # eq. 6
                            p.gain * (z[p.n_slow] - z[p.n_slow + 1]))
        energies = []
        for k in range(8):
            even, odd = gabor(k * math.pi / 4, 0.0), gabor(k * math.pi / 4, math.pi / 2)
            e = {c: convolve(s, even) * convolve(f, odd) - convolve(f, even) * convolve(s, odd)
                 for c, (f, s) in fast_slow.items()}
            energies.append(p.v_on * e["+"] + p.v_off * e["-"])
        r_theta = np.array(energies)
        v = r_theta.max(axis=0)
        s_fast = {c: relu(convolve(fast_slow[c][0], g_cs)) for c in "+-"}
        s_slow = {c: relu(convolve(fast_slow[c][1], g_cs)) for c in "+-"}
        g1_on = relu(relu(fast_slow["+"][1]) - s_fast["-"])
        g2_on = relu(relu(fast_slow["+"][0]) - s_slow["-"])
        g1_off = relu(relu(fast_slow["-"][1]) - s_fast["+"])
        g2_off = relu(relu(fast_slow["-"][0]) - s_slow["+"])
        g = p.w1_on * g1_on - p.w2_off * g2_off + p.w1_off * g1_off - p.w2_on * g2_on
        m_a = correlate(g, g_sigma) > p.gamma_a
        top = np.argsort(-r_theta.sum(axis=(1, 2)), kind="stable")[:p.top_k]
        m_d = correlate(v - r_theta[top].max(axis=0), g_sigma) > p.gamma_d
        us.append(float((g * m_a * m_d).sum()) * p.u_scale)
    return us


@pytest.mark.parametrize("optimised, rtol", [(False, 1e-9), (True, 1e-4)])
def test_the_paper_preset_is_the_papers_equations(scenes, optimised, rtol):
    p = preset("paper")
    assert (p.n_p, p.dog_normalisation, p.attention_normalised, p.attention_step, p.cs_phase,
            p.kernel_size, p.kernel_extent, p.input_blur, p.leaky_input, p.u_abs) == \
        (0, "paper", False, 1, 0.0, 5, 1.0, False, False, False)  # what it transcribes
    for name in ("approach_recession_over_stripes", "translation"):
        # (not the centred looming disk: its orientations' energies tie, and which one M_d
        # takes out then rests on the order of a sum's terms)
        frames = scenes[name]
        want = paper_model_u(frames, p)
        model = ASNN("paper", optimised=optimised)
        got = [model.step(f).u for f in frames]
        assert max(want) > 0, name
        np.testing.assert_allclose(got, want, rtol=rtol, atol=1e-12 * max(want), err_msg=name)


@pytest.mark.parametrize("optimised, rtol", [(False, 1e-9), (True, 1e-4)])
def test_the_fast_terms_of_eq_19_enter_eq_20_as_printed(scenes, optimised, rtol):
    """The ``paper`` preset's weights (w2+ = w2- = 0) leave G2+ and G2- (eq. 19) and their
    minus signs in eq. 20 out of the test above: the robot experiment's weights
    [1, 1, 1, 0.4, 1, 0.4] have all four terms."""
    p = preset("robot")
    assert (p.w1_on, p.w2_off, p.w1_off, p.w2_on) == (1.0, 0.4, 1.0, 0.4)
    for name in ("approach_recession_over_stripes", "translation"):
        frames = scenes[name]
        want = paper_model_u(frames, p)
        model = ASNN(p, optimised=optimised)
        got = [model.step(f).u for f in frames]
        assert max(np.abs(want)) > 0, name
        np.testing.assert_allclose(got, want, rtol=rtol, atol=1e-12 * max(np.abs(want)),
                                   err_msg=name)
        # the fast terms are subtracted: without them u would be larger
        without = paper_model_u(frames, p.model_copy(update={"w2_off": 0.0, "w2_on": 0.0}))
        assert sum(without) > sum(want), name


# ---------------------------------------------------------------- the baselines

W_I = np.array([[1 / 8, 1 / 4, 1 / 8], [1 / 4, 0, 1 / 4], [1 / 8, 1 / 4, 1 / 8]])


def frame_differences(frames: np.ndarray):
    """None for the first frame, then L_f - L_{f-1} on the raw 0..255 values (SPEC section 4)."""
    previous = None
    for frame in frames:
        lum = frame.astype(float)
        yield None if previous is None else lum - previous
        previous = lum


def grouped(s: np.ndarray, p) -> np.ndarray:
    """Ce = S ⊗ ones(3,3)/9, ω = δ_C + max|Ce| / C_w, G = S Ce / ω, kept where G C_de >= T_de."""
    ce = correlate(s, np.full((3, 3), 1 / 9))
    g = s * ce / (p.delta_c + np.abs(ce).max() / p.c_w)
    return np.where(g * p.c_de >= p.t_de, g, 0.0)


def lgmd1_transcribed(frames: np.ndarray, p: LGMD1Params) -> list[tuple]:
    """SPEC section 4, LGMD1-1 (N_p = 0): (u = K_f, out, spikes, collision) per frame."""
    assert p.n_p == 0
    out, p_previous, successive = [], None, 0
    for e in frame_differences(frames):
        if e is None:
            out.append((0.0, 0.5, 0, False))  # the first frame: no output
            continue
        inhibition = correlate(p_previous, W_I) if p_previous is not None else 0.0 * e
        ffi = np.abs(p_previous).sum() / e.size if p_previous is not None else 0.0
        k = np.abs(grouped(e - p.w_i * inhibition, p)).sum()
        kappa = 1 / (1 + math.exp(-k / e.size))
        suppressed = ffi >= p.t_ffi
        spike = 0 if suppressed else int(kappa >= p.t_s)
        successive = successive + 1 if spike else 0
        out.append((k, 0.5 if suppressed else kappa, spike, successive >= p.n_sp))
        p_previous = e
    return out


def lgmd2_transcribed(frames: np.ndarray, p: LGMD2Params) -> list[tuple]:
    """SPEC section 4, LGMD1-2: (u = k(t), out, spikes, collision) per frame."""
    a_near, a_diag = p.dt / (p.dt + p.tau_near), p.dt / (p.dt + p.tau_diagonal)
    a = np.array([[a_diag, a_near, a_diag], [a_near, 0.0, a_near], [a_diag, a_near, a_diag]])
    a_sfa, a_ffi = p.tau_sfa / (p.tau_sfa + p.dt), p.dt / (p.dt + p.tau_ffi)
    out, on, off = [], None, None
    k_previous = k_adapted = 0.5
    ffi, count = 0.0, 0
    for diff in frame_differences(frames):
        if diff is None:
            out.append((0.0, 0.5, 0, False))  # the first frame: no output
            continue
        on_before = on if on is not None else 0.0 * diff
        off_before = off if off is not None else 0.0 * diff
        on = np.where(diff >= 0, diff, 0.0) + p.persistence * on_before
        off = np.where(diff < 0, -diff, 0.0) + p.persistence * off_before

        def inhibition(now, before):
            return correlate(now, W_I * a) + correlate(before, W_I * (1 - a) * (W_I > 0))

        s_on = relu(on - p.w_on * inhibition(on, on_before))
        s_off = relu(off - p.w_off * inhibition(off, off_before))
        s = p.theta1 * s_on + p.theta2 * s_off + p.theta3 * s_on * s_off
        k = grouped(s, p).sum()
        kk = 1 / (1 + math.exp(-k / diff.size))
        d = kk - k_previous
        k_adapted = max(a_sfa * (k_adapted + d) if d <= p.t_sfa else a_sfa * kk, 0.5)
        k_previous = kk
        ffi = a_ffi * np.abs(diff).mean() + (1 - a_ffi) * ffi
        if ffi >= p.t_ffi:
            result, spikes = 0.5, 0
        else:
            result, spikes = k_adapted, int(math.floor(math.exp(p.k_sp * (k_adapted - p.t_sp))))
        count = count + spikes if spikes else 0
        out.append((k, result, spikes, count >= p.n_ts))
    return out


@pytest.mark.parametrize("cls, params, transcribed", [
    (LGMD1, LGMD1Params(), lgmd1_transcribed),
    (LGMD2, LGMD2Params(), lgmd2_transcribed),
])
def test_the_baselines_are_spec_section_4(scenes, cls, params, transcribed):
    spiked = False
    for name, frames in scenes.items():
        want = transcribed(frames, params)
        model = cls(params)
        got = [model.step(f) for f in frames]
        spiked |= any(w[2] for w in want)
        np.testing.assert_allclose([r.u for r in got], [w[0] for w in want], rtol=1e-9,
                                   err_msg=name)
        np.testing.assert_allclose([r.out for r in got], [w[1] for w in want], rtol=1e-12,
                                   err_msg=name)
        assert [(r.spikes, r.collision) for r in got] == [(w[2], w[3]) for w in want], name
    assert spiked  # a scene makes it spike: the spike rule is checked too
