"""Typed parameter set of the ASNN model and its named presets.

Defaults are Table I of the paper plus the rulings of SPEC.md section 2. The presets are:

``paper``
    Table I, the rulings of SPEC section 2, the weights of the approach experiment and the
    warning parameters of the vehicle experiment, read literally. On the [0, 1] intensity scale
    of the rulings, ``out(t) = 1/(1+exp(-|u|/N))`` stays near 0.5 (at most about 0.53 on any
    input measured, flicker and noise included), so with T_sp = 0.7 this preset never fires a
    spike: it is kept for studying the maps and u(t).
``approach``, ``translation``, ``robot``
    The weight vector of the corresponding experiment; ``robot`` with its warning parameters.
``vehicle``
    The vehicle experiment: approach weights, K_sp=10, T_sp=0.7, N_t=4, T_c=1.
    These four scale u by 255 before the sigmoid (``u_scale``), i.e. measure it in the 0..255
    units the paper's warning thresholds were evidently tuned for (as the published
    implementation does); without it they could never warn.
``reference``
    The published Python implementation (SPEC section 3), reproduced to float64 precision.
``reference32``
    ``reference``'s parameters computed in float32.
``light``
    ``reference32`` for light objects on a dark background (ON and OFF swapped).
``robust``
    ``reference32`` plus the robust additions (README, "The robust preset"): repeated frames
    held, input scale, background stabilisation, contrast gain control, both polarities,
    objects with a direct looming estimate, a tracker and the approach gate. Each addition has
    the field that switches it off.
``default``
    The preset :command:`asnn detect` uses when none is named: ``robust`` (README, "Why
    robust is the default").

Every preset but ``reference`` runs its optimised step in float32 (``precision``); see
:mod:`asnn._fast`.

Weights are signed as they enter the paper's fusion equation
``G = w1+ G1+ - w2- G2- + w1- G1- - w2+ G2+``; the published implementation *adds* its fast-ON
term, which is ``w2+ = -0.3`` here.
"""

from __future__ import annotations

import textwrap
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

__all__ = ["ASNNParams", "PRESETS", "DEFAULT_PRESET", "MAX_KERNEL", "check_fields",
           "check_overrides", "parse_preset_spec", "preset", "preset_from_spec", "preset_key",
           "preset_names", "split_preset_spec"]

# Upper bounds of the sizes and counts, far above what the presets and the paper use (kernels
# of 5 and 31 px, 2 and 4 filter stages, windows of a few frames) but below what allocates
# gigabytes or stalls a frame (a kernel of 10001 px, 20000 filter stages of a frame each):
MAX_KERNEL = 255  # px of a kernel's side (the frame must be at least as large)
MAX_STAGES = 32  # stages of the temporal filters, each a frame of state
MAX_FRAMES = 1000  # frames of a window or a track's memory (50 s at 20 fps)
# threads of a model (ASNN(..., threads=N)): it splits each frame into bands, one for each
# thread, and threads beyond the cores only take turns; 256 is more cores than a machine
# running it has, where thousands of threads stall the machine (3,000: 0.6 s a frame on 2
# cores, 10,000 not two frames in ten minutes)
MAX_THREADS = 256
# Bounds of the real-valued parameters: the presets use magnitudes of at most 255, and gains of
# 1e20 made the float32 state overflow to inf and the model silently blind; a sigma or a
# wavelength of 1e-300 px divides by zero in its kernel.
MAX_MAGNITUDE = 1e4
MIN_SCALE = 0.05  # px, the least sigma or wavelength of a kernel
_SCALES = ("dog_sigma1", "dog_sigma2", "ds_sigma", "ds_wavelength", "cs_sigma", "cs_wavelength",
           "attention_sigma", "contrast_pool", "kernel_extent")


def check_photoreceptor_history(n_p: int, p_u: float) -> None:
    """Refuse photoreceptor history weights (paper eq. 1) that make P grow without bound.

    ``P(t) = I(t) - I(t-1) + sum_i p_i P(t-i)`` with every p_i > 0 (defined after eq. 1) holds
    a constant input's response only while ``sum_i p_i < 1``: at 1 or more a still camera's
    noise grows until it warns, then P overflows and the model is blind for good.

    Parameters
    ----------
    n_p : int
        N_p, frames of photoreceptor history.
    p_u : float
        u in ``p_i = 1 / (1 + exp(u i))``.

    Raises
    ------
    ValueError
        If the weights sum to 1 or more.
    """
    if n_p == 0:
        return
    from .retina import photoreceptor_weights  # here: the parameters load without OpenCV

    total = float(photoreceptor_weights(n_p, p_u).sum())
    if total >= 1.0:
        raise ValueError(f"n_p={n_p}, p_u={p_u:g}: the photoreceptors' history weights p_i "
                         f"sum to {total:.3g}, and P (eq. 1) grows without bound at 1 or more; "
                         "raise p_u or lower n_p")


class ASNNParams(BaseModel):
    """Every parameter of the ASNN model, with the paper's symbol in each description.

    The fields' own defaults are the paper's settings (the ``paper`` preset, which never warns:
    SPEC.md); build parameters from a preset with :func:`preset` (``preset("default",
    top_k=0)``), not as ``ASNNParams(top_k=0)``.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    # --- repeated frames (robust addition) ---
    skip_repeats: bool = Field(
        False,
        description="treat a frame that hardly differs from the previous one, compared with the "
        "difference of the last frame that was not a repeat, as a repeat: the state is held and "
        "the previous response repeated, its targets' ttc shortened by the time since "
        "(asnn.model.aged_targets; video converted to a higher frame rate repeats frames)",
    )
    repeat_fraction: float = Field(
        0.2, gt=0, description="a repeat differs from the previous frame by less than this "
        "fraction of the mean absolute difference of the last frame that was not a repeat ...")
    repeat_level: float = Field(
        1.0 / 255, gt=0, description="... and by less than this mean absolute difference "
        "([0, 1] intensity; of the block means, repeat_block)")
    repeat_block: int = Field(
        8, ge=1, le=MAX_KERNEL,
        description="the repeat test compares the frames' means over blocks of this "
        "many pixels square: a camera's sensor noise, which differs between two copies of a "
        "repeated frame, averages out over a block; 1: every pixel")
    repeat_run: int = Field(
        1, ge=1, le=MAX_FRAMES,
        description="at most this many repeats in a row: after that the scene has "
        "stopped moving, and the model sees it")

    max_step_rate: float | None = Field(
        None, ge=1.0, le=1000.0,
        description="frame-rate ceiling, frames a second: a camera faster than 1.2 times this "
        "(its last 15 frames' times: their mean gap and the median span of two gaps, halved; "
        "36 fps at 30) is stepped at about this rate. Its frames are taken on a grid of "
        "1 / max_step_rate seconds of its own clock, the first frame in each cell; the others "
        "are held (the state kept, the previous response repeated, its targets' ttc shortened by "
        "the time since: asnn.model.aged_targets). The retina steps once per "
        "frame whatever the time between frames, and at 60 fps a far object's change per frame "
        "is a third of what the added stages were set on (20-30 fps). The grid is fixed by the "
        "stamps alone, so two models given the same frames from different starts step the same "
        "frames once both have judged the rate (a hand-over). Untimed frames, and slower "
        "cameras, are all stepped. None: every frame")

    # --- input scale (robust addition) ---
    max_width: int | None = Field(
        None, ge=32, le=4096, description="frames wider than this are averaged down to this width "
        "(aspect kept) before the retina, whose kernels have a fixed size in pixels, and no "
        "frame is worked on at more pixels than a 3:4 portrait this wide (a taller one is "
        "averaged down both ways: the model's state stays bounded); targets stay in the "
        "frame's pixels. None: every frame at its own size",
    )
    min_width: int | None = Field(
        None, ge=32, le=1024, description="frames narrower than this are enlarged to this width "
        "(bilinear, aspect kept) before the retina: a small camera's objects and motions then "
        "meet the added stages' sizes in pixels (the smallest box, the linking margin, the "
        "gain control's pool) at the scale they were made for; it adds no detail. Targets stay "
        "in the frame's pixels. None: every frame at its own size",
    )

    # --- global brightness compensation (robust addition) ---
    global_gain: float | None = Field(
        None, gt=0, le=60.0, description="time constant, seconds, of the global brightness "
        "compensation: each frame is scaled by a gain that divides out its brightness change "
        "against the previous frame (the median ratio of 2,048 pixels, counted where three "
        "quarters of them change the same way) and returns to 1 with this time constant, so "
        "that a lamp's flicker, an exposure step or the lights switched leave the "
        "photoreceptors quiet and a slow ramp passes (asnn.brightness, ASNN._compensated). "
        "None: every frame at the camera's level")

    # --- background stabilisation (robust addition) ---
    stabilise: bool = Field(
        False, description="photoreceptors: difference each frame against the previous one "
        "moved by the background's translation, when one translation explains most of the "
        "change; the looming fit leaves out what it explains (asnn.stabilisation)")
    stabilise_radius: int = Field(
        3, ge=1, le=16, description="largest translation searched, pixels per frame of the "
        "model's grid (at least: see stabilise_reach)")
    stabilise_reach: float | None = Field(
        None, gt=0, le=0.1, description="the search radius grows with the grid: at least this "
        "fraction of its width, rounded up, so that a camera with more pixels searches as far "
        "across the scene per frame (1/64: 3 px at 192 px, 5 at 320, 8 at 480; at most 16); "
        "None: stabilise_radius at any size")
    stabilise_share: float = Field(
        0.5, gt=0, le=1, description="smallest fraction of the frame's mean absolute difference "
        "the translation must explain")
    stabilise_spread: float = Field(
        0.5, ge=0, le=1, description="smallest fraction of the frame's 4x4 tiles in each of "
        "which the translation must also explain half of stabilise_share of the change (a tile "
        "also holds what moves otherwise: a prop nearer the camera): a pan, a shake "
        "or a sliding background moves across the frame, an object drifting over a plain or "
        "still background only where it is (asnn.stabilisation.background_shift); 0: the whole "
        "frame's change only")
    stabilise_wider: float | None = Field(
        None, gt=1, le=16, description="where the best translation lies on the search's edge, "
        "search again up to this many times the radius (at most 16 px) and take the wider "
        "search's best where it leaves a tenth less of the change: a shaken camera's image "
        "jumps by up to twice the shake from frame to frame (asnn.stabilisation."
        "background_shift); None: one search")

    # --- input and photoreceptors (paper eq. 1) ---
    target_polarity: Literal["dark", "light"] = Field(
        "dark",
        description="'light' negates P, which swaps the ON and OFF pathways: the model then "
        "treats light objects on dark backgrounds as the weights treat dark ones",
    )
    input_blur: bool = Field(
        False, description="3x3, sigma 1 Gaussian blur of each frame before differencing (reference)"
    )
    noise_summation: float | None = Field(
        None, gt=0, le=50.0, description="spatial summation in low light: in a view the light "
        "adaptation reads as dim (contrast_light; c below 0.99 of its fixed value), the input "
        "blur widened, where input_blur's 3x3 kernel would leave more than this many gray "
        "levels of the frame's measured white noise, to a Gaussian of at least input_blur's "
        "sigma that leaves about this many (asnn.summation.NoiseSummation); inert without "
        "input_blur and contrast_light. None: the fixed blur")
    temporal_summation: float | None = Field(
        None, gt=0, le=10.0, description="temporal summation in low light: where noise_summation "
        "widens the input blur, each pixel averaged over its frames with this time constant, "
        "seconds, while its change stays within asnn.summation.CHANGE times the blurred noise "
        "(a larger change, something moving, is taken at once) "
        "(asnn.summation.NoiseSummation.integrated); inert without noise_summation. None: off")
    n_p: int = Field(0, ge=0, le=16, description="N_p: frames of photoreceptor history (paper eq. 1)")
    p_u: float = Field(1.0, description="u in p_i = 1/(1+exp(u i))")

    # --- contrast gain control (robust addition) ---
    contrast_gain: float | None = Field(
        None, gt=0,
        description="semi-saturation of the contrast gain control: P <- s P / (this + "
        "g_pool * |P|); None switches the stage off (retina.contrast_gain_control)",
    )
    contrast_light: float | None = Field(
        None, gt=0, le=1.0,
        description="light adaptation of the contrast gain control: its "
        "semi-saturation scaled by the view's median luminance over this (a lit view's median, "
        "[0, 1]), bounded below by contrast_light_floor, smoothed over contrast_light_tau, "
        "kept fixed in a view lit in pools (contrast_light_spread) "
        "(asnn.light.LightAdaptation); inert without contrast_gain. None: the fixed constant")
    contrast_light_floor: float = Field(0.25, gt=0, le=1.0,
                                        description="least fraction of contrast_gain the "
                                        "light adaptation takes it to")
    contrast_light_tau: float = Field(0.5, gt=0, le=60.0,
                                      description="time constant, seconds, of the light "
                                      "adaptation's smoothing")
    contrast_light_spread: float | None = Field(
        None, gt=1.0, le=100.0, description="upper decile over median of the view above which "
        "it counts as lit in pools (a night) and keeps the fixed constant; None: no such gate")
    contrast_pool: float = Field(8.0, gt=0, le=MAX_KERNEL / 4,
                                 description="sigma of the pooling Gaussian, px")
    contrast_scale: float = Field(0.05, gt=0, description="s, the output scale")

    # --- bipolar cells (eqs. 2-4) ---
    dog_gain: float = Field(5.0, description="F, gain of the difference of Gaussians g_I")
    dog_sigma1: float = Field(1.0, gt=0, description="sigma_1 of g_I")
    dog_sigma2: float = Field(3.0, gt=0, description="sigma_2 of g_I")
    dog_size: int = Field(5, ge=3, le=MAX_KERNEL,
                          description="size of the square kernel g_I (odd)")
    dog_normalisation: Literal["paper", "2d"] = Field(
        "paper",
        description="'paper': F/(sqrt(2 pi) sigma) as printed in eq. 3; "
        "'2d': F/(2 pi sigma^2) as in the published implementation",
    )

    # --- temporal filter L(K, n, z0) (eqs. 5-7) ---
    gain: float = Field(5.0, description="K, gain of the temporal filter")
    decay: float = Field(60.0, gt=0, description="A, decay coefficient")
    transmission: float | None = Field(
        None, gt=0, description="C, transmission coefficient; None means C = A (SPEC ruling)"
    )
    tau: float = Field(5.0, gt=0, description="tau, integration time constant")
    leaky_input: bool = Field(
        False, description="z_0 integrates the input instead of being it (reference: six integrators)"
    )
    n_fast: int = Field(2, ge=1, le=MAX_STAGES - 1, description="n_f, stages of the fast filter")
    n_slow: int = Field(4, ge=2, le=MAX_STAGES, description="n_s, stages of the slow filter")
    dt: float = Field(0.05, gt=0, description=(
        "integration step of the temporal filter, seconds per frame (dt A / tau below 1), "
        "and the period of frames given without a time"))

    # --- amacrine cells (eqs. 9-14) ---
    ds_sigma: float = Field(0.3, gt=0, description="sigma_DS of the Gabor pair")
    ds_wavelength: float = Field(4.0, gt=0, description="lambda_DS of the Gabor pair")
    cs_sigma: float = Field(0.3, gt=0, description="sigma_CS of the centre-surround kernel")
    cs_wavelength: float = Field(4.0, gt=0, description="lambda_CS of the centre-surround kernel")
    cs_phase: float = Field(0.0, description="psi_CS")
    kernel_size: int = Field(5, ge=3, le=MAX_KERNEL, description="size of g_DS and g_CS (odd)")
    kernel_extent: float = Field(
        1.0, gt=0, description="g_DS and g_CS are sampled on [-extent, extent] (SPEC ruling)"
    )

    # --- ganglion cells (eqs. 15-20) ---
    v_on: float = Field(1.0, description="v+, weight of ON motion energy")
    v_off: float = Field(1.0, description="v-, weight of OFF motion energy")
    w1_on: float = Field(1.0, description="w^1_+, weight of G^1_+ (slow ON)")
    w2_off: float = Field(0.0, description="w^2_-, weight of G^2_- (fast OFF), subtracted")
    w1_off: float = Field(0.5, description="w^1_-, weight of G^1_- (slow OFF)")
    w2_on: float = Field(0.0, description="w^2_+, weight of G^2_+ (fast ON), subtracted")
    grouping: bool = Field(
        False, description="G <- G (G * ones(3,3)/9) before attention (reference)"
    )

    # --- attention (eqs. 21-28) ---
    attention_sigma: float = Field(8.0, gt=0, description="sigma_g of g_sigma")
    attention_size: int = Field(31, ge=3, le=MAX_KERNEL, description="size of g_sigma (odd)")
    attention_normalised: bool = Field(
        False,
        description="False: g_sigma = exp(-r^2/2s^2)/(2 pi s^2) as printed (eq. 21); "
        "True: normalised to sum 1 (OpenCV GaussianBlur, reference)",
    )
    attention_step: int = Field(
        1, ge=1, le=4, description="g_sigma applied on a grid this many times coarser "
        "(area-averaged, interpolated back): the blurred maps are smooth at that scale")
    gamma_a: float = Field(0.005, ge=0,
                           description="gamma_a, threshold of the approach attention M_a")
    gamma_d: float = Field(0.005, ge=0,
                           description="gamma_d, threshold of the direction attention M_d")
    top_k: int = Field(1, ge=0, le=7, description="k of the top-k inhibited orientations "
                       "(eq. 24); 1, the top-1 direction of the paper's robot tests (the paper "
                       "gives no other k)")

    # --- output and warning (eqs. 32-34) ---
    u_scale: float = Field(
        1.0, gt=0, description="u = u_scale * sum(G'); 255 undoes the [0,1] input scaling"
    )
    u_abs: bool = Field(False, description="sum |G'| instead of G' (reference)")
    # out(t) is a sigmoid, in [0, 1]: a threshold outside it, or a gain past 100 (e^100
    # spikes a frame), only overflows the spike count (eq. 33)
    k_sp: float = Field(10.0, gt=0, le=100, description="K_sp, spike gain (0 would fire a "
                       "spike every frame whatever u(t))")
    t_sp: float = Field(0.7, gt=0.5, le=1, description="T_sp, spike threshold on out(t) (0.5 "
                        "or less would fire a spike every frame: out(t) is never below 0.5)")
    n_t: int = Field(4, ge=1, le=MAX_FRAMES, description="N_t, spike window in frames")
    t_c: float = Field(1.0, gt=0, description="T_c, spike-rate threshold of the warning, Hz "
                       "(0 would warn on every frame)")
    spike_dt: float | None = Field(
        None, gt=0, description="frame period used in the spike rate; None means dt"
    )

    # --- targets (SPEC section 1 item 10) ---
    targets: Literal["clusters", "objects"] = Field(
        "clusters",
        description="'clusters': DBSCAN of the attended pixels (paper eqs. 29-31); 'objects': "
        "connected regions of the attended mask, tracked across frames (robust)",
    )
    min_object_pixels: int = Field(30, ge=1, le=4096 * 4096,
                                   description="smallest region kept as an object")
    cluster_eps: float = Field(5.0, gt=0, le=MAX_KERNEL, description="DBSCAN eps, pixels of the "
                               "model's grid (at most 255, as the kernels' sizes)")
    cluster_min_samples: int = Field(2, ge=1, le=4096 * 4096,
                                     description="DBSCAN min_samples (a point counts itself)")
    origin_seed: bool = Field(
        False, description="add the pixel (0, 0) to the clustered points, as the reference does"
    )

    # --- looming and tracking of objects (robust additions; targets='objects') ---
    looming_margin: float = Field(
        0.25, ge=0, description="the expansion of an object is measured over its bounding box "
        "widened by this fraction of its larger side (plus 4 px) on every side")
    rim_expansion: bool = Field(
        False, description="where the stabilisation takes a background translation out, a "
        "track's box is fitted again over its attended pixels alone (its rim, without the "
        "pattern sliding past it), and where that reads the faster expansion the box's rate "
        "and drift are scaled up to it (asnn.approach.looming.rim_scaled): the time to contact the "
        "rim's, the offset the box's; inert without stabilise")
    rim_motion_max: float | None = Field(
        None, gt=0, description="with rim_expansion, the rim's rate counts only where the "
        "motion it implies at the box's edge, in the looming fit's grid (at most 64 px a side), "
        "is at most this many pixels a frame: the gradient fit's small-motion range "
        "(asnn.approach.looming.rim_scaled); None: at any motion")
    track_link: float = Field(1.0, gt=0, description="linking distance, in summed object sizes")
    track_missed: int = Field(3, ge=0, le=MAX_FRAMES,
                              description="frames a track survives unseen")
    track_smoothing: float = Field(
        0.5, gt=0, le=1, description="weight of a new expansion estimate in a track's average")
    track_box: float = Field(
        1.0, gt=0, le=1, description="weight of a new observation's box in a track's box, the "
        "region its expansion is measured over (1: each frame's own box)")
    approach_gate: bool = Field(
        False,
        description="u(t) sums G' only over objects coming at the camera (approaching tracks: "
        "time to contact <= tau_max, offset <= offset_max, in approach_frames frames in a "
        "row); needs targets='objects'",
    )
    scene_relative: bool = Field(
        False, description="an approaching track must not contract against the scene: its box "
        "fitted again without the pixels the scene's own expansion (the frame outside the "
        "tracks' boxes) explains (asnn.approach.tracking.against_scene); needs targets='objects'")
    scene_tolerance: float = Field(
        0.0, ge=0, description="the scene-relative test passes a rate against the scene down "
        "to -scene_tolerance times the track's own expansion rate (zero within the second "
        "fit's noise)")
    own_motion_weight: float = Field(
        1.0, ge=1, le=10, description="a counting object whose expansion against the scene is "
        "at least own_motion_ratio of its own (it closes on us by its own motion, not only "
        "because we drive at it) adds this many times its share to u(t): a car turning across "
        "our path at night, dim and small, reaches the warning with less energy "
        "(asnn.approach.tracking.own_motion_weight); 1: every object alike; inert without "
        "scene_relative and approach_gate")
    own_motion_ratio: float = Field(
        0.75, gt=0, le=1, description="the share of a track's own expansion that its expansion "
        "against the scene must keep for own_motion_weight")
    receding_scene: bool = Field(
        False, description="where the scene contracts (the camera moves away from it: a rear "
        "camera, reversing), a track that passes the partial-overlap regime but for its fit is "
        "fitted against the scene too, and the regime's fit test takes the better of its box's "
        "fit and that one (asnn.approach.tracking.Track.own_fit): the scenery receding behind "
        "an object coming at a rear camera lowers its box's fit; inert without scene_relative and "
        "partial_overlap")
    receding_edge_rule: bool = Field(
        False, description="the fit against a receding scene counts 0 while the frame's edge "
        "cuts the object, as its box's own fit does (and enters the track's smoothed own_fit so) "
        "(asnn.approach.stage.ApproachStage._measure_against_scene): a car overtaking into view "
        "at the frame's side does not pass the partial-overlap regime on that fit; applied when "
        "the fit is measured, so the held-out replay takes it as traced; inert without "
        "receding_scene")
    tau_max: float = Field(1.5, gt=0, description="longest time to contact that warns, s")
    offset_max: float = Field(
        1.0, gt=0, description="largest drift/expansion offset of an approaching object, in "
        "object sizes (its RMS radius, about 0.4 of a whole object's width): 0 dead ahead; 1 a "
        "path that crosses the camera's own line of sight; a car whose path overlaps that of a "
        "car as wide (a partial-overlap collision) up to about 2.4; a car in the next lane 4 "
        "or more")
    approach_frames: int = Field(3, ge=1, le=MAX_FRAMES,
                                 description="consecutive frames a track must pass "
                                 "the approach test (ttc, offset) before it counts")
    approach_seconds: float | None = Field(
        None, gt=0, description="fewer than approach_frames frames suffice where they already "
        "span this long at the stream's frame period (the median of the last 5): at 0.1 s, a "
        "camera at 10 fps, or a stream that loses every second frame of 20, needs 2 frames in a "
        "row, while 20-30 fps streams keep approach_frames "
        "(asnn.approach.tracking.persistence_frames). None: always approach_frames")
    region_persistence: bool = Field(
        False, description="a track that passes the approach test now also counts where "
        "passing tracks overlapped its box in approach_frames - 1 of the previous "
        "approach_frames frames: an object seen in fragments that change tracks from frame to "
        "frame (a walker whose sway splits its outline) persists where it is seen; not where "
        "a track that counts by its own frames overlaps it (a fragment of that object) "
        "(asnn.approach.tracking.TargetTracker.judge); a part of the approach gate")
    region_cover: float = Field(
        0.0, ge=0, le=1, description="with region_persistence, an earlier frame's passing "
        "track speaks for the region only where the overlap of its box covers at least this "
        "share of the box of the track that passes now: fragments of one object overlap each "
        "other by a fair part, while a large new track that takes in a few small passing ones "
        "around it (a wet road's headlight reflections, re-encoded) has to persist by its own "
        "frames (asnn.approach.tracking.persists_in_region); 0: any overlap")
    surface_ahead: bool = Field(
        False, description="a second pathway for a surface that fills the view and closes in "
        "(a wall, a door, a lorry's back at a metre), which the retina's filtering cancels: "
        "where the whole frame expands as one plane over 0.1 s, its tiles alike (not faster "
        "around the middle over one frame, as a corridor's walls), with a time to contact of "
        "at most tau_max and its focus within offset_max of the centre, for 0.3 s of frames in "
        "a row (7 at 20 fps), u(t) gains the potential of one spike a frame and the view is a "
        "target (asnn.approach.surface); needs targets='objects'")
    corridor_gate: bool = Field(
        False, description="where the whole view has passed surface_ahead's test (over 0.1 s "
        "or over one frame) for 0.3 s but its tiles read a corridor (the walls around the "
        "middle expanding faster than it), no object counts either: the object stage's boxes "
        "there are pieces of the walls around our heading, which expand about it as a stopped "
        "object would; an object standing ahead ends the corridor reading by expanding the "
        "middle tile (asnn.approach.surface.SurfaceWatch.corridor; the view is measured with "
        "either switch on); needs targets='objects'")
    ignore_rig: bool = Field(
        False, description="leave out of the looming fits the edges that stay still at the "
        "frame's top and bottom (asnn.approach.looming.rig_pixels): the camera's own hood or "
        "dashboard and a recorder's overlay, whose static edges would read as part of a box not "
        "expanding")
    motion_layers: bool = Field(
        False, description="where the scene expands (our own forward motion), a track that "
        "passes the approach test must also have, among the motions its box holds (dense "
        "optical flow split by random sample consensus, asnn.approach.motion_layers), one that is "
        "itself an approach (asnn.approach.tracking.layers_approach): a car pulling away seen in "
        "one box with the roadside expanding behind it is two motions, neither coming at us; inert "
        "without scene_relative (whose scene fit tells where the scene expands)")
    object_ids: bool = Field(
        False, description="targets are named after their object: a track that appears over "
        "an object already counted (its box overlapping a counting track's, this frame or one "
        "of the approach_frames before it with region_persistence, else the one before) is a "
        "fragment of that object and reports that track's id, and an object "
        "seen as several fragments is one target (asnn.approach.tracking.TargetTracker.object_id); "
        "changes ids and targets, never the warning; needs targets='objects'")
    refined_ttc: bool = Field(
        False, description="a target reports its own estimate of the expansion rate and time "
        "to contact: smoothed under a constant-speed approach (asnn.approach.tracking."
        "Track.measure_reported), from the box's fit refined by Gauss-Newton steps on the warped "
        "previous frame where the target counts and its motion moves the box's edge by more "
        "than a pixel a frame at the fit's grid (asnn.approach.looming.refined_expansion); the "
        "approach test reads the tracks' own estimate, so this changes the targets' ttc and "
        "expansion, never the warning; needs targets='objects'")
    partial_overlap: bool = Field(
        False, description="the approach test also passes a partial overlap: ttc <= "
        "overlap_tau_max, offset <= overlap_offset_max, from a box the expansion fit explains "
        "(fit >= overlap_fit_min): a car whose path overlaps ours only in part "
        "(asnn.approach.tracking.approach_test); a part of the approach gate, inert without it")
    overlap_tau_max: float = Field(1.0, gt=0, description="longest time to contact that warns "
                                   "on a partial overlap, s")
    overlap_offset_max: float = Field(
        2.0, gt=0, description="largest offset of a partial overlap, object sizes (see "
        "offset_max: a car-width overlap with a car as wide reads up to about 2.4)")
    overlap_fit_min: float = Field(
        0.4, le=1, description="least share of the box's change the expansion fit must explain "
        "on a partial overlap (asnn.approach.looming.Expansion.fit; an object the frame's edge "
        "cuts counts 0); -1 switches the test off")

    # --- computation ---
    precision: Literal["float32", "float64"] = Field(
        "float32",
        description="floating-point type of the optimised step (ASNN(optimised=True)); the "
        "straightforward form always computes in float64. 'reference' keeps float64 to match "
        "the published implementation; elsewhere float32 stays within 1e-5 of float64 on u(t) "
        "(tests/test_equivalence.py), except where the orientations' summed energies R_sum "
        "(eq. 24) tie, as for a disk looming at the frame's exact centre: rounding then picks "
        "the orientation the top-k inhibition removes: on the paper's looming scene u(t) is "
        "up to 2 % apart for 'reference32', up to 39 % for 'paper', 'vehicle', 'approach' "
        "and 'robot' (the same warnings in every frame); the straightforward form and "
        "another input type tie differently too",
    )

    @model_validator(mode="after")
    def _check(self) -> "ASNNParams":
        for name, value in self:
            if isinstance(value, float) and abs(value) > MAX_MAGNITUDE:
                raise ValueError(f"{name} is {value:g}: at most {MAX_MAGNITUDE:g} in magnitude")
        for name in _SCALES:
            if getattr(self, name) < MIN_SCALE:
                raise ValueError(f"{name} is {getattr(self, name):g}: at least {MIN_SCALE:g} px")
        for name in ("dog_size", "kernel_size", "attention_size"):
            if getattr(self, name) % 2 == 0:
                raise ValueError(f"{name} must be odd, got {getattr(self, name)}")
        if self.n_fast >= self.n_slow:
            raise ValueError("n_fast must be smaller than n_slow")
        check_photoreceptor_history(self.n_p, self.p_u)
        # the temporal filter's forward-Euler step (eq. 5) multiplies each stage by
        # 1 - dt A / tau per frame: above 1 a stage flips its sign every frame instead of
        # decaying (the reference warned on receding and translating stimuli at 1.2; at 0.96,
        # still allowed, it missed a looming disk), and at 2 it grows without bound
        step = self.dt * self.decay / self.tau
        if step >= 1.0:
            raise ValueError(
                f"dt * decay / tau is {step:g}: the temporal filter (eq. 5) stepped by forward "
                "Euler decays only below 1 (at 1 a stage keeps nothing of its past, above it "
                "flips sign every frame, at 2 it grows without bound); lower dt or decay, or "
                "raise tau. dt is the "
                "filter's integration step, not the camera's frame period: give frames their "
                "times, step(frame, t)")
        needing = [name for name in ("approach_gate", "scene_relative", "object_ids",
                                     "refined_ttc", "ignore_rig", "surface_ahead",
                                     "corridor_gate")
                   if getattr(self, name)]
        if (self.min_width is not None and self.max_width is not None
                and self.min_width > self.max_width):
            raise ValueError(f"min_width ({self.min_width}) must not exceed max_width "
                             f"({self.max_width})")
        if needing and self.targets != "objects":  # every stage that works on the objects
            off = ", ".join(f"{name}={type(self).model_fields[name].default}" for name in needing)
            raise ValueError(f"{', '.join(needing)} need{'s' if len(needing) == 1 else ''} "
                             f"targets='objects': set {off} too")
        return self

    @property
    def c(self) -> float:
        """C, the transmission coefficient (C = A unless set)."""
        return self.decay if self.transmission is None else self.transmission

    @property
    def min_side(self) -> int:
        """The smallest frame side, in pixels, the model takes: its largest kernel's."""
        return max(self.dog_size, self.kernel_size, self.attention_size)

    @property
    def overlap(self) -> tuple[float, float, float] | None:
        """The partial-overlap regime of the approach test, ``(overlap_tau_max,
        overlap_offset_max, overlap_fit_min)``, or None without ``partial_overlap`` (or without
        the gate it is a part of)."""
        if not (self.partial_overlap and self.approach_gate):
            return None
        return self.overlap_tau_max, self.overlap_offset_max, self.overlap_fit_min

    @property
    def window_dt(self) -> float:
        """Frame period of the spike-rate window."""
        return self.dt if self.spike_dt is None else self.spike_dt


# [v+, v-, w1+, w2-, w1-, w2+] as the paper prints them for its experiments (adopted by SPEC
# section 1). The approach experiment's text says the OFF channel's weights are the larger, but
# its printed vector weights the slow ON term G1+ (1.0) above the slow OFF term G1- (0.5); the
# presets keep the printed numbers: docs/evaluation.md, "The presets read from the paper's
# text", measures both readings.
_WEIGHTS = {
    "approach": (1.0, 1.0, 1.0, 0.0, 0.5, 0.0),
    "translation": (1.0, 1.0, 0.4, 1.0, 0.0, 0.0),
    "robot": (1.0, 1.0, 1.0, 0.4, 1.0, 0.4),
}


def _weights(name: str) -> dict:
    keys = ("v_on", "v_off", "w1_on", "w2_off", "w1_off", "w2_on")
    return dict(zip(keys, _WEIGHTS[name]))


def fields_section(model: type[BaseModel]) -> str:
    """A numpydoc Attributes section from a model's field descriptions, so that ``help()``
    shows what each field means (pydantic keeps them in ``model_fields`` only)."""
    lines = ["", "", "    Attributes", "    ----------"]
    for name, info in model.model_fields.items():
        kind = info.annotation
        kind = kind.__name__ if isinstance(kind, type) else str(kind).replace("typing.", "")
        lines.append(f"    {name} : {kind} = {info.default!r}")
        lines.append(textwrap.fill(info.description or "", 92, initial_indent=" " * 8,
                                   subsequent_indent=" " * 8))
    return "\n".join(lines) + "\n"


if ASNNParams.__doc__:  # None under python -OO
    ASNNParams.__doc__ += fields_section(ASNNParams)


def _derived(base: ASNNParams, **update) -> ASNNParams:
    """``base`` with ``update``'s fields, validated as a new set would be (``model_copy``'s
    update is not: a preset could hold a value out of bounds, found only when someone
    overrode one of its fields)."""
    return ASNNParams.model_validate({**base.model_dump(), **update})


_PAPER = ASNNParams()

PRESETS: dict[str, ASNNParams] = {
    "paper": _PAPER,
    "approach": _derived(_PAPER, **_weights("approach"), u_scale=255.0),
    "translation": _derived(_PAPER, **_weights("translation"), u_scale=255.0),
    "vehicle": _derived(_PAPER, k_sp=10.0, t_sp=0.7, n_t=4, t_c=1.0, u_scale=255.0),
    "robot": _derived(_PAPER, **_weights("robot"), k_sp=20.0, t_sp=0.52, n_t=4, t_c=1.0,
                      u_scale=255.0),
    "reference": ASNNParams(
        input_blur=True,
        n_p=0,
        leaky_input=True,
        dog_normalisation="2d",
        v_on=1.0, v_off=1.0,
        w1_on=0.0, w2_off=0.0, w1_off=1.0, w2_on=-0.3,
        grouping=True,
        attention_normalised=True,
        gamma_a=0.01, gamma_d=0.008, top_k=1,
        u_scale=255.0, u_abs=True,
        k_sp=10.0, t_sp=0.51, n_t=4, t_c=1.0, spike_dt=0.025,
        origin_seed=True,
        precision="float64",
    ),
}

# reference's parameters computed in float32: within 2e-6 of float64 on u(t), same warnings
# (tests/test_equivalence.py), about twice as fast; reference itself stays exact in float64
PRESETS["reference32"] = _derived(PRESETS["reference"], precision="float32")
PRESETS["light"] = _derived(PRESETS["reference32"], target_polarity="light")
# the published variant plus the robust additions (README, "The robust preset"): each addition
# has the parameter that switches it off
PRESETS["robust"] = _derived(
    PRESETS["reference32"],
    skip_repeats=True, max_step_rate=30.0, global_gain=0.5,
    stabilise=True, stabilise_reach=1 / 64, stabilise_wider=2.0, rim_expansion=True,
    rim_motion_max=8.0,
    contrast_gain=0.005, contrast_light=0.3, contrast_light_spread=3.0, noise_summation=1.0,
    temporal_summation=0.5,
    w1_on=1.0, w2_off=-0.3, w1_off=1.0, w2_on=-0.3,  # both polarities: OFF-led + ON-led maps
    gamma_a=0.003, gamma_d=0.002,  # on the contrast-normalised scale
    targets="objects", approach_gate=True, origin_seed=False,
    max_width=480, min_width=160, track_box=0.3, approach_frames=3, approach_seconds=0.1,
    attention_step=2,
    scene_relative=True, partial_overlap=True, scene_tolerance=0.1, receding_scene=True,
    receding_edge_rule=True, region_persistence=True, region_cover=0.2, object_ids=True,
    refined_ttc=True, motion_layers=True, ignore_rig=True,
    surface_ahead=True, corridor_gate=True, own_motion_weight=2.0,
)
DEFAULT_PRESET = "robust"
# frames a second below which the default preset loses hits (docs/evaluation.md, "At half the
# frame rate"): it is made for 20 or more, and a 20 fps camera's timestamps jitter
SLOW_FPS = 18.0
# what the evaluation and asnn detect say of a slower clip
SLOW_NOTE = (f"ASNN loses hits below {SLOW_FPS:g} "
             "(docs/evaluation.md, 'At half the frame rate')")
# a stream's frame period: the median of the last PERIOD_FRAMES gaps between its frames' times
# (one lost frame does not move it), each believed only from MIN_FRAME_GAP_S (a camera at 10
# kHz) up to MAX_FRAME_GAP_S seconds (outside, a clock in other units, one that never moves, or
# a stall: the nominal period instead; stamps a subnormal number apart made frame counts of
# seconds over the period infinite)
PERIOD_FRAMES = 5
# the frame-rate ceiling (max_step_rate, r) holds frames of a camera whose mean gap over the
# last CEILING_GAPS frames (from CEILING_MIN_GAPS on) is below 1 / (CEILING_MARGIN r): 36 fps at
# 30, so that a 30 fps camera whose stamps jitter by 5 ms, or come in pairs, has none held, and
# a 40 fps one is stepped near 30; a fresh model (a worker taking a robot over) judges the rate
# within a few frames, and from then on steps the frames the old owner steps
CEILING_GAPS = 15
CEILING_MIN_GAPS = 3
CEILING_MARGIN = 1.2
MIN_FRAME_GAP_S = 1e-4
MAX_FRAME_GAP_S = 1.0


def timed_gap(gap: float) -> bool:
    """Whether the time between two frames, seconds, is one a stream's timing believes:
    ``MIN_FRAME_GAP_S <= gap <= MAX_FRAME_GAP_S`` (NaN is not)."""
    return MIN_FRAME_GAP_S <= gap <= MAX_FRAME_GAP_S


def preset_names() -> list[str]:
    """Names accepted by :func:`preset`, ``default`` included.

    Returns
    -------
    list of str
        ``"default"`` first (another name for :data:`DEFAULT_PRESET`, ``robust``), then the
        keys of :data:`PRESETS` in their order: ``paper``, ``approach``, ..., ``robust``. A
        new list on every call.
    """
    return ["default", *PRESETS]


def _baseline_names() -> tuple[str, ...]:
    """The baselines' names (asnn.detectors imports this module: read at call time)."""
    from .detectors import BASELINES

    return tuple(BASELINES)


def preset_key(name: str) -> str:
    """The key in :data:`PRESETS` of a name :func:`preset` accepts (``default``: the default's).

    Raises
    ------
    ValueError
        If the name is unknown.
    """
    key = DEFAULT_PRESET if name == "default" else name
    if key not in PRESETS:
        head = name.split("/")[0] if isinstance(name, str) else None
        hint = ("" if head is None or "/" not in name else
                f" (the command line's NAME/FIELD=VALUE; in Python: make_detector({head!r}, "
                "FIELD=VALUE))" if head in _baseline_names() else
                f" (the command line's NAME/FIELD=VALUE; in Python: preset({head!r}"
                ", FIELD=VALUE))")
        raise ValueError(f"unknown preset {name!r}{hint}; choose one of "
                         f"{', '.join(preset_names())}")
    return key


def parse_preset_spec(spec: str, label: str | None = None
                      ) -> tuple[str, tuple[tuple[str, object], ...]]:
    """Read a preset spec of the command line, ``NAME[/FIELD=VALUE...]`` (``robust/top_k=0``;
    an empty name is the default's): the name and the overrides, in their order.

    A value reads as none, true, false, an int, a float or else the word itself, and is
    checked strictly (:func:`check_overrides`): ``true`` is no ``top_k`` of 1, nor ``1`` a
    ``stabilise`` of true.

    Raises
    ------
    ValueError
        For an override that is not ``FIELD=VALUE``, a field given twice, an unknown preset
        or field, or a value the preset does not take; the message names ``label`` (the spec
        as the user gave it: ``asnn:robust/top_k=x``), else the spec.
    """
    label = spec if label is None else label
    name, overrides = split_preset_spec(spec, label)
    check_overrides(name, overrides, label)
    return name, overrides


def split_preset_spec(spec: str, label: str | None = None
                      ) -> tuple[str, tuple[tuple[str, object], ...]]:
    """:func:`parse_preset_spec` without the check of the values against the preset (for
    overrides that apply over others: a detector spec's over the default preset's)."""
    label = spec if label is None else label
    name, *items = spec.strip().split("/")
    name = name.strip() or "default"
    overrides, named = [], set()
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"{label!r}: an override is name=value, got {item!r}")
        if key in named:
            raise ValueError(f"{label!r}: {key} is given twice")
        named.add(key)
        overrides.append((key, _spec_value(value)))
    return name, tuple(overrides)


def check_overrides(name: str, overrides, label: str) -> None:
    """Check a preset's overrides ``(field, value)`` as :func:`preset` does, but strictly (no
    conversion of a value's type); ValueError naming ``label`` and the field."""
    check_fields(preset(name), overrides, label)  # preset() raises for an unknown preset


def check_fields(base: BaseModel, overrides, label: str) -> None:
    """Check changes ``(field, value)`` to a set of parameters (a preset's, or an LGMD model's:
    ``asnn.baselines.LGMD1Params``) strictly, with the set's own validation; ValueError naming
    ``label`` and the field."""
    try:
        type(base).model_validate({**base.model_dump(), **dict(overrides)}, strict=True)
    except ValidationError as exc:
        error = exc.errors()[0]
        where = f"{error['loc'][0]}: " if error["loc"] else ""  # a check of the whole set
        raise ValueError(f"{label!r}: {where}{error['msg']}") from None


def preset_from_spec(spec: str) -> ASNNParams:
    """The parameters a preset spec (:func:`parse_preset_spec`) names."""
    name, overrides = parse_preset_spec(spec)
    return preset(name, **dict(overrides))


def _spec_value(text: str):
    """A spec's override value: none, true, false, a number, or the word itself."""
    word = text.strip()
    lowered = word.lower()
    if lowered in ("none", "true", "false"):
        return {"none": None, "true": True, "false": False}[lowered]
    for kind in (int, float):
        try:
            return kind(word)
        except ValueError:
            pass
    return word


def preset(name: str, **overrides) -> ASNNParams:
    """Return the named preset, optionally with some parameters overridden.

    Parameters
    ----------
    name : str
        A preset's name (:func:`preset_names`; ``"default"`` is the default's, ``robust``).
    **overrides
        Fields of :class:`ASNNParams` to change, by name (``top_k=0``); validated with the
        rest, so that a value out of range or a combination the model does not run is refused.

    Returns
    -------
    ASNNParams
        The preset itself without overrides (presets are immutable), else a new parameter set.

    Raises
    ------
    ValueError
        If the name is unknown or an override is invalid.
    """
    base = PRESETS[preset_key(name)]
    if not overrides:
        return base
    return ASNNParams(**{**base.model_dump(), **overrides})
