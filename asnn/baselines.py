"""The two LGMD models the paper compares ASNN against (SPEC.md section 4).

``LGMD1`` is LGMD1-1, the single-pathway model with feature enhancement of Yue & Rind [1]_;
``LGMD2`` is LGMD1-2, the model with parallel ON/OFF pathways and spike frequency adaptation of
Fu, Hu, Peng & Yue [2]_. Both offer the per-stream interface of :class:`asnn.model.ASNN`:
``step(frame) -> Response`` and ``reset()``; their responses never carry targets.

Both work on raw 0..255 luminance (a uint8 frame as is, a [0, 1] float frame times 255; colour
frames through OpenCV's luma). Public implementations of these models differ in their
parameters, so every one is a field of :class:`LGMD1Params` / :class:`LGMD2Params`, whose
descriptions give the source of each default. What a :class:`~asnn.response.Response` field
means for these models:

``u``
    The summed excitation of the LGMD cell: ``K_f = sum |G~_f|`` (LGMD1-1) or
    ``k(t) = sum G(t)`` (LGMD1-2), before any feed-forward inhibition.
``out``
    The membrane potential in [0.5, 1]: ``kappa_f`` (LGMD1-1) or the adapted ``K^(t)``
    (LGMD1-2); 0.5 in a frame the feed-forward inhibition suppresses.
``spikes``
    Spikes of the frame (LGMD1-1 fires at most one).
``spike_rate``
    Spikes of the last ``rate_window`` frames per second (informational; the warning follows
    each model's own rule).
``collision``
    LGMD1-1: ``n_sp`` successive frames with a spike; LGMD1-2: the running spike count (reset by
    a frame without spikes) reaches ``n_ts``.

As for ASNN, the first frame of a stream only primes the state, and the models integrate with the
fixed step ``dt`` whatever the frames' timestamps.

References
----------
.. [1] S. Yue and F. C. Rind, "Collision detection in complex dynamic scenes using an LGMD-based
   visual neural network with feature enhancement", IEEE Trans. Neural Networks 17(3), 2006.
.. [2] Q. Fu, C. Hu, J. Peng and S. Yue, "Shaping the collision selectivity in a looming sensitive
   neuron model with parallel ON and OFF pathways and spike frequency adaptation",
   Neural Networks 106, 2018.
"""

from __future__ import annotations

import math
import threading
from collections import deque

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from .frames import frame_time, to_luminance
from .params import check_photoreceptor_history, fields_section
from .retina import photoreceptor_weights, spike_count, spike_rate
from .response import Response

__all__ = [
    "LGMD1Params",
    "LGMD2Params",
    "LGMD1",
    "LGMD2",
    "lateral_inhibition_kernel",
    "group_excitation",
    "sigmoid_membrane",
    "spike_frequency_adaptation",
]

_BORDER = cv2.BORDER_REFLECT_101
_MIN_SIDE = 3


# --------------------------------------------------------------------------- parameters


class _LGMDParams(BaseModel):
    """What both models' parameters share: no NaN, and no infinity but where it switches the
    feed-forward inhibition off (``t_ffi``): either would silence a model, or crash its spike
    count, without a word."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    @model_validator(mode="after")
    def _finite(self) -> "_LGMDParams":
        for name, value in self:
            if isinstance(value, float) and (math.isnan(value) or (math.isinf(value)
                                                                   and name != "t_ffi")):
                raise ValueError(f"{name} must be a finite number, got {value}")
        return self


class LGMD1Params(_LGMDParams):
    """Parameters of LGMD1-1 (Yue & Rind 2006), with the source of each default."""

    n_p: int = Field(0, ge=0, le=16, description=(
        "n_p, frames of photoreceptor persistence in P_f = L_f - L_{f-1} + sum p_i P_{f-i}; "
        "default 0, the plain frame difference (SPEC section 4 leaves n_p open)"))
    p_u: float = Field(1.0, description="u in p_i = 1/(1+exp(u i)); 1 as in the ASNN model")
    w_i: float = Field(0.4, ge=0, description=(
        "w_I, weight of the delayed lateral inhibition in S_f = E_f - w_I I_f; "
        "0.3-0.6 in use, 0.4 the common value (SPEC section 4)"))
    c_w: float = Field(4.0, gt=0, description=(
        "C_w in omega_f = delta_c + max|Ce_f| / C_w; 4 (Yue & Rind 2006, SPEC section 4)"))
    delta_c: float = Field(0.01, gt=0, description="delta_c in omega_f; 0.01 (SPEC section 4)")
    c_de: float = Field(0.5, description="C_de, decay coefficient of the grouping threshold; 0.5")
    t_de: float = Field(15.0, description="T_de, grouping threshold on G_f C_de; 15")
    t_s: float = Field(0.88, gt=0.5, le=1, description=(
        "T_s, spike threshold on kappa_f; 0.88, the upper end of the 0.78-0.88 in use "
        "(the stricter value, since LGMD1-1 has no other defence against translation); 0.5 "
        "or less would fire a spike every frame: kappa_f is never below 0.5"))
    n_sp: int = Field(5, ge=1, description="n_sp, successive spikes that make a warning; 5")
    t_ffi: float = Field(10.0, description=(
        "threshold of the feed-forward inhibition F_f = sum|P_{f-1}| / n_cell; 10 "
        "(SPEC section 4); math.inf disables it"))
    dt: float = Field(0.05, gt=0, description="frame period in seconds, as the ASNN model's dt")
    rate_window: int = Field(4, ge=1, description="frames of the reported spike rate (ASNN's N_t)")

    @model_validator(mode="after")
    def _bounded_history(self) -> "LGMD1Params":
        check_photoreceptor_history(self.n_p, self.p_u)
        return self


class LGMD2Params(_LGMDParams):
    """Parameters of LGMD1-2 (Fu, Hu, Peng & Yue 2018), with the source of each default."""

    persistence: float = Field(0.1, ge=0, lt=1, description=(
        "decay of the ON/OFF channels, ON(t) = [P >= 0] P + 0.1 ON(t-1); 0.1 (SPEC section 4)"))
    tau_near: float = Field(0.03, gt=0, description=(
        "tau of the nearest neighbours' delayed inhibition, s; 30 ms (Fu et al. 2018)"))
    tau_diagonal: float = Field(0.06, gt=0, description=(
        "tau of the diagonal neighbours' delayed inhibition, s; 60 ms (Fu et al. 2018)"))
    w_on: float = Field(0.3, ge=0, description="w_on, ON-channel inhibition weight; 0.3")
    w_off: float = Field(0.6, ge=0, description="w_off, OFF-channel inhibition weight; 0.6")
    theta1: float = Field(1.0, description="theta_1, weight of S_on in S; 1")
    theta2: float = Field(1.0, description="theta_2, weight of S_off in S; 1")
    theta3: float = Field(0.1, description="theta_3, weight of S_on S_off in S; 0.1")
    c_w: float = Field(4.0, gt=0, description="C_w of the grouping layer, as LGMD1-1; 4")
    delta_c: float = Field(0.01, gt=0, description="delta_c of the grouping layer; 0.01")
    c_de: float = Field(0.5, description="C_de of the grouping layer; 0.5")
    t_de: float = Field(15.0, description="T_de of the grouping layer; 15")
    tau_sfa: float = Field(0.8, gt=0, description=(
        "tau_sfa of the spike frequency adaptation, s; 800 ms (Fu et al. 2018)"))
    t_sfa: float = Field(0.003, description=(
        "T_sfa, rise of K(t) per frame above which adaptation restarts from K(t); 0.003"))
    sfa: bool = Field(True, description="apply spike frequency adaptation (False: K^ = K)")
    k_sp: float = Field(4.0, gt=0, le=100, description=(
        "gain of the spike mapping n(t) = floor(exp(4 (K^ - T_sp))); 4 (0 would fire a spike "
        "every frame, a negative gain spike below the threshold)"))
    t_sp: float = Field(0.76, gt=0.5, le=1, description=(
        "T_sp, spike threshold; 0.76, the middle of 0.74-0.78 (0.5 or less would fire a spike "
        "every frame: K^ is never below 0.5)"))
    n_ts: int = Field(6, ge=1, description=(
        "N_ts, running spike count that makes a warning; 6, within the 5-8 in use"))
    tau_ffi: float = Field(0.09, gt=0, description="tau of the low-passed FFI, s; 90 ms")
    t_ffi: float = Field(10.0, description=(
        "threshold of the feed-forward inhibition on the low-passed mean |P|; 10, the lower "
        "end of 10-15 in use; math.inf disables it"))
    dt: float = Field(0.05, gt=0, description=(
        "frame period in seconds, used in every a = dt/(dt + tau); 0.05 as the ASNN model's dt"))
    rate_window: int = Field(4, ge=1, description="frames of the reported spike rate (ASNN's N_t)")


for _params in (LGMD1Params, LGMD2Params):  # help() shows what each field means
    if _params.__doc__:  # None under python -OO
        _params.__doc__ += fields_section(_params)
del _params


# --------------------------------------------------------------------------- layers


def _correlate(image: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    return cv2.filter2D(image, cv2.CV_64F, kernel, borderType=_BORDER)


def lateral_inhibition_kernel(near: float = 0.25, diagonal: float = 0.125) -> np.ndarray:
    """3x3 lateral-inhibition weights W: centre 0, nearest ``near``, diagonal ``diagonal``.

    With the defaults this is Yue & Rind's ``W_I = [[1/8, 1/4, 1/8], [1/4, 0, 1/4],
    [1/8, 1/4, 1/8]]``, also the W of LGMD1-2's delayed inhibition.
    """
    return np.array([[diagonal, near, diagonal],
                     [near, 0.0, near],
                     [diagonal, near, diagonal]])


def group_excitation(s: np.ndarray, c_w: float, delta_c: float, c_de: float,
                     t_de: float) -> np.ndarray:
    """Grouping layer with feature enhancement (Yue & Rind 2006, eqs. of the G layer).

    ``Ce_f = S_f (*) ones(3, 3) / 9``, ``omega_f = delta_c + max|Ce_f| / C_w``,
    ``G_f = S_f Ce_f / omega_f``, and ``G~_f = G_f`` where ``G_f C_de >= T_de``, else 0.

    Parameters
    ----------
    s : ndarray (H, W)
        Summing-layer excitation S_f.
    c_w : float
        C_w, the divisor of the largest grouped excitation in omega_f.
    delta_c : float
        delta_c, omega_f's floor.
    c_de, t_de : float
        C_de and T_de: a grouped cell is kept where ``G_f C_de >= T_de``.

    Returns
    -------
    G~ : ndarray (H, W)
    """
    ce = cv2.blur(s, (3, 3), borderType=_BORDER)
    omega = delta_c + np.abs(ce).max() / c_w
    g = s * ce / omega
    g[g * c_de < t_de] = 0.0
    return g


def sigmoid_membrane(excitation: float, n_cells: int) -> float:
    """Sigmoid membrane potential ``1 / (1 + exp(-k / n_cell))`` (kappa_f, K(t)), in [0.5, 1]
    (1.0 where it saturates in floating point)."""
    return 1.0 / (1.0 + math.exp(-excitation / n_cells))


def spike_frequency_adaptation(adapted: float, previous: float, current: float,
                               coefficient: float, threshold: float) -> float:
    """One step of LGMD1-2's spike frequency adaptation (Fu et al. 2018).

    ``d = K(t) - K(t-1)``; ``K^(t) = a3 (K^(t-1) + d)`` when ``d <= T_sfa``, else ``a3 K(t)``;
    then ``K^(t) >= 0.5``.

    Parameters
    ----------
    adapted : float
        K^(t-1).
    previous, current : float
        K(t-1) and K(t).
    coefficient : float
        ``a3 = tau_sfa / (tau_sfa + dt)``.
    threshold : float
        T_sfa.

    Returns
    -------
    K^(t) : float
    """
    d = current - previous
    value = coefficient * (adapted + d) if d <= threshold else coefficient * current
    return max(value, 0.5)


# --------------------------------------------------------------------------- models


class _LGMDBase:
    """State shared by both models: the previous frame, the frame counter, the spike window."""

    params: LGMD1Params | LGMD2Params
    min_side = _MIN_SIDE  # the smallest height and width of a frame the models take
    _in_use: threading.Lock

    def __getstate__(self) -> dict:
        """For copy and pickle: without the lock; RuntimeError while the model steps."""
        if self._lock().locked():
            raise RuntimeError(f"this {type(self).__name__} model is stepping (on another "
                               "thread): copy it between steps")
        state = dict(self.__dict__)
        state.pop("_in_use", None)
        return state

    def __copy__(self):
        """A copy is a snapshot: a deep copy (a shallow one shared the state's arrays and
        deques with the model, so that stepping either changed the other), as the ASNN's."""
        import copy

        return copy.deepcopy(self)

    def _lock(self) -> threading.Lock:
        """The lock a step holds (one model serves one stream from one thread at a time, as
        :class:`asnn.ASNN`: two threads at once mixed their states without a word)."""
        lock = self.__dict__.get("_in_use")
        if lock is None:  # made with the model's first use, or after a copy
            lock = self.__dict__.setdefault("_in_use", threading.Lock())
        return lock

    def _luminance(self, frame: np.ndarray) -> np.ndarray:
        lum = to_luminance(frame, self.min_side, self.shape) * 255.0
        return lum

    def reset(self) -> None:
        """Forget the stream: the next frame starts a new one (of any size)."""
        self.shape: tuple[int, int] | None = None
        self.previous: np.ndarray | None = None
        self.spike_window: deque[int] = deque(maxlen=self.params.rate_window)
        self.index = 0
        self._reset_state()

    def _reset_state(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def step(self, frame: np.ndarray, t: float | None = None) -> Response:
        """Process one frame and return the model's response to it (targets always empty).

        ``t``, the frame's time, is accepted for a common interface with :class:`asnn.ASNN`
        and not used: the LGMD models count frames.

        Returns
        -------
        Response
            The frame's ``index``; ``u``, the grouping layer's sum (``K_f``, ``k(t)``); ``out``,
            the membrane potential the spikes are read from (``kappa_f``; LGMD1-2's adapted
            ``K^(t)``), 0.5 where feed-forward inhibition suppresses the frame; ``spikes``, the
            frame's spike count (0 or 1 for LGMD1-1); the spike rate over the last
            ``rate_window`` frames; and ``collision``, the warning. ``targets`` is always empty.
            A stream's first frame only primes the photoreceptors: a silent response.

        Raises
        ------
        FrameError
            If the frame is not an image the model accepts, its size differs from the stream's,
            or ``t`` is not a number (a str, a bool); the model's state is then as it was.
        RuntimeError
            If another thread is stepping the model (the refused step changes nothing).
        """
        lock = self._lock()
        if not lock.acquire(blocking=False):
            raise RuntimeError(f"this {type(self).__name__} model is stepping already (on "
                               "another thread): one model serves one stream, from one thread "
                               "at a time")
        try:
            return self._step(frame, t)
        finally:
            lock.release()

    def _step(self, frame: np.ndarray, t: float | None) -> Response:
        if t is not None:
            frame_time(t)  # checked as ASNN checks it, though not used
        lum = self._luminance(frame)
        index = self.index
        self.index += 1
        if self.previous is None:
            self.shape = lum.shape
            self.previous = lum
            return Response.silent(index)
        p = lum - self.previous
        self.previous = lum
        u, out, spikes, collision = self._respond(p)
        self.spike_window.append(spikes)
        rate = spike_rate(self.spike_window, self.params.rate_window, self.params.dt)
        return Response(index=index, u=float(u), out=float(out), spikes=int(spikes),
                        spike_rate=float(rate), collision=bool(collision))


class LGMD1(_LGMDBase):
    """LGMD1-1: single-pathway LGMD with feature enhancement (Yue & Rind 2006).

    Per frame f (SPEC.md section 4):

    - photoreceptors ``P_f = (L_f - L_{f-1}) + sum_{i=1..n_p} p_i P_{f-i}``, excitation ``E_f = P_f``;
    - delayed lateral inhibition ``I_f = P_{f-1} (*) W_I``;
    - summing layer ``S_f = E_f - w_I I_f``;
    - grouping layer ``G~_f`` (:func:`group_excitation`);
    - LGMD cell ``K_f = sum |G~_f|``, ``kappa_f = 1 / (1 + exp(-K_f / n_cell))``;
    - a spike when ``kappa_f >= T_s``, a warning after ``n_sp`` successive spikes;
    - feed-forward inhibition ``F_f = sum |P_{f-1}| / n_cell``: when ``F_f >= T_FFI`` the frame's
      output is suppressed (no spike, ``out`` = 0.5).

    Parameters
    ----------
    params : LGMD1Params, optional
    **overrides
        Individual parameters, e.g. ``LGMD1(w_i=0.6)``.
    """

    def __init__(self, params: LGMD1Params | None = None, **overrides):
        base = params or LGMD1Params()
        # validated again, overrides or not: pydantic's model_copy(update=...) skips the checks
        self.params = LGMD1Params(**{**base.model_dump(), **overrides})
        # the photoreceptors' persistence is the ASNN's (paper eq. 1, p_i = 1/(1+exp(u i)))
        self._p_weights = photoreceptor_weights(self.params.n_p, self.params.p_u)
        self._w_i = lateral_inhibition_kernel()
        self.reset()

    def _reset_state(self) -> None:
        self.history: deque[np.ndarray] = deque(maxlen=max(self.params.n_p, 1))
        self.successive = 0

    def _respond(self, diff: np.ndarray) -> tuple[float, float, int, bool]:
        prm = self.params
        photo = diff.copy()
        for w, past in zip(self._p_weights, self.history):
            photo += w * past
        previous = self.history[0] if self.history else None
        self.history.appendleft(photo)

        n_cell = photo.size
        if previous is None:
            inhibition = np.zeros_like(photo)
            ffi = 0.0
        else:
            inhibition = _correlate(previous, self._w_i)
            ffi = float(np.abs(previous).sum()) / n_cell
        s = photo - prm.w_i * inhibition
        g = group_excitation(s, prm.c_w, prm.delta_c, prm.c_de, prm.t_de)
        k = float(np.abs(g).sum())
        kappa = sigmoid_membrane(k, n_cell)
        if ffi >= prm.t_ffi:
            kappa_out, spikes = 0.5, 0
        else:
            kappa_out, spikes = kappa, int(kappa >= prm.t_s)
        self.successive = self.successive + 1 if spikes else 0
        return k, kappa_out, spikes, self.successive >= prm.n_sp


class LGMD2(_LGMDBase):
    """LGMD1-2: parallel ON/OFF pathways with spike frequency adaptation (Fu et al. 2018).

    Per frame t (SPEC.md section 4):

    - photoreceptors ``P = L(t) - L(t-1)``;
    - ON/OFF channels ``ON(t) = [P >= 0] P + 0.1 ON(t-1)``, ``OFF(t) = [P < 0] |P| + 0.1 OFF(t-1)``;
    - delayed lateral inhibition per channel
      ``I(x, y) = sum_ij W(i, j) [a_ij X(x+i, y+j, t) + (1 - a_ij) X(x+i, y+j, t-1)]``,
      ``a_ij = dt / (dt + tau_ij)``;
    - ``S_on = relu(ON - w_on I_on)``, ``S_off = relu(OFF - w_off I_off)``,
      ``S = theta1 S_on + theta2 S_off + theta3 S_on S_off``;
    - grouping as LGMD1-1 (:func:`group_excitation`), ``k(t) = sum G``,
      ``K(t) = 1 / (1 + exp(-k / n_cell))``;
    - spike frequency adaptation ``K^(t)`` (:func:`spike_frequency_adaptation`);
    - spikes ``n(t) = floor(exp(k_sp (K^(t) - T_sp)))``; a warning when the running spike count
      (reset by a frame without spikes) reaches ``N_ts``;
    - feed-forward inhibition: ``F(t)``, the mean |P| low-passed with ``tau_ffi``; when
      ``F >= T_FFI`` the frame's output is suppressed (no spikes, ``out`` = 0.5). The model's
      internal state (channels, adaptation) runs on regardless.

    Parameters
    ----------
    params : LGMD2Params, optional
    **overrides
        Individual parameters, e.g. ``LGMD2(sfa=False)``.
    """

    def __init__(self, params: LGMD2Params | None = None, **overrides):
        base = params or LGMD2Params()
        # validated again, overrides or not: pydantic's model_copy(update=...) skips the checks
        self.params = LGMD2Params(**{**base.model_dump(), **overrides})
        prm = self.params
        a_near = prm.dt / (prm.dt + prm.tau_near)
        a_diag = prm.dt / (prm.dt + prm.tau_diagonal)
        w = lateral_inhibition_kernel()
        a = lateral_inhibition_kernel(a_near, a_diag)
        self._kernel_now = w * a
        self._kernel_before = w * np.where(w > 0, 1.0 - a, 0.0)
        self._a_sfa = prm.tau_sfa / (prm.tau_sfa + prm.dt)
        self._a_ffi = prm.dt / (prm.dt + prm.tau_ffi)
        self.reset()

    def _reset_state(self) -> None:
        self.on: np.ndarray | None = None
        self.off: np.ndarray | None = None
        self.membrane = 0.5     # K(t-1)
        self.adapted = 0.5      # K^(t-1)
        self.ffi = 0.0          # F(t-1)
        self.running = 0

    def _inhibition(self, now: np.ndarray, before: np.ndarray) -> np.ndarray:
        return _correlate(now, self._kernel_now) + _correlate(before, self._kernel_before)

    def _respond(self, diff: np.ndarray) -> tuple[float, float, int, bool]:
        prm = self.params
        on_before = self.on if self.on is not None else np.zeros_like(diff)
        off_before = self.off if self.off is not None else np.zeros_like(diff)
        self.on = np.where(diff >= 0, diff, 0.0) + prm.persistence * on_before
        self.off = np.where(diff < 0, -diff, 0.0) + prm.persistence * off_before

        s_on = np.maximum(self.on - prm.w_on * self._inhibition(self.on, on_before), 0.0)
        s_off = np.maximum(self.off - prm.w_off * self._inhibition(self.off, off_before), 0.0)
        s = prm.theta1 * s_on + prm.theta2 * s_off + prm.theta3 * s_on * s_off
        g = group_excitation(s, prm.c_w, prm.delta_c, prm.c_de, prm.t_de)
        k = float(g.sum())
        membrane = sigmoid_membrane(k, diff.size)
        if prm.sfa:
            adapted = spike_frequency_adaptation(self.adapted, self.membrane, membrane,
                                                 self._a_sfa, prm.t_sfa)
        else:
            adapted = membrane
        self.membrane, self.adapted = membrane, adapted

        self.ffi = self._a_ffi * float(np.abs(diff).mean()) + (1.0 - self._a_ffi) * self.ffi
        if self.ffi >= prm.t_ffi:
            out, spikes = 0.5, 0
        else:
            out, spikes = adapted, spike_count(adapted, prm.k_sp, prm.t_sp)
        self.running = self.running + spikes if spikes else 0
        return k, out, spikes, self.running >= prm.n_ts
