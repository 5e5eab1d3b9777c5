"""Pictures of a detector's output: annotated frames (paper Fig. 12) and response plots."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from ..response import Response

__all__ = ["annotate_frame", "header_scale", "target_arrow", "target_label", "warning_intervals",
           "plot_responses"]

_ARROW_GAIN = 400.0  # pixels per unit of motion energy, clamped below


def target_arrow(x: float, y: float, direction: float, energy: float,
                 shape: tuple[int, ...]) -> tuple[float, float]:
    """Tip of a target's arrow: from (x, y) along ``direction``, longer for more motion energy
    (10 pixels plus 400 per unit, at most a quarter of the picture's larger side)."""
    length = min(10.0 + _ARROW_GAIN * energy, 0.25 * max(shape[:2]))
    return x + length * math.cos(direction), y + length * math.sin(direction)


def target_label(target: dict) -> str:
    """A target's optional identity and time to contact as a short text (``'#3 ttc 1.2 s'``),
    from its ``id`` and ``ttc`` keys where present; empty without either."""
    parts = []
    if target.get("id") is not None:
        parts.append(f"#{target['id']}")
    ttc = target.get("ttc")
    if ttc is not None and math.isfinite(ttc):
        parts.append(f"ttc {ttc:.1f} s")
    return " ".join(parts)


def annotate_frame(frame: np.ndarray, response: Response) -> np.ndarray:
    """Overlay a response on its input frame.

    The approach map G is drawn in red where positive, the attended region M_a M_d is outlined in
    green, the pixels the looming fits leave out as the camera's own rig (``Maps.rig``) are
    tinted cyan, and each target gets a blue dot and an arrow along its direction whose length
    grows with its energy (as in the paper's Fig. 12), labelled with its id and time to contact
    where the target has them. A red border marks a collision warning. Maps of a model that saw
    the frame scaled down (the input-scale stage) are scaled up to it.

    Parameters
    ----------
    frame : ndarray (H, W) or (H, W, 3), uint8
    response : Response
        With maps (``record_maps=True``) for the overlays; without, only the text and targets.

    Returns
    -------
    ndarray (H, W, 3), uint8, BGR
    """
    image = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR) if frame.ndim == 2 else frame.copy()
    maps = response.maps
    if maps is not None:
        size = image.shape[1::-1]
        if maps.rig is not None:
            rig = _to_frame(maps.rig.view(np.uint8), size, cv2.INTER_NEAREST).view(bool)
            image[rig] = (0.5 * image[rig] + (128, 128, 0)).astype(np.uint8)
        g = _to_frame(np.maximum(maps.G, 0.0).astype(np.float32), size, cv2.INTER_LINEAR)
        peak = float(g.max())
        if peak > 0:
            alpha = np.clip(g / peak, 0.0, 1.0)[..., None] * 0.8
            red = np.zeros_like(image)
            red[..., 2] = 255
            image = (image * (1 - alpha) + red * alpha).astype(np.uint8)
        attended = _to_frame((maps.M_a & maps.M_d).astype(np.uint8), size, cv2.INTER_NEAREST)
        contours, _ = cv2.findContours(attended, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(image, contours, -1, (0, 220, 0), 1)
    for t in response.targets:
        centre = (int(round(t.x)), int(round(t.y)))
        tip_x, tip_y = target_arrow(t.x, t.y, t.direction, t.energy, image.shape)
        tip = (int(round(tip_x)), int(round(tip_y)))
        cv2.circle(image, centre, 3, (255, 80, 0), -1)
        cv2.arrowedLine(image, centre, tip, (255, 80, 0), 2, tipLength=0.3)
        label = target_label(t.to_dict())
        if label:
            cv2.putText(image, label, (centre[0] + 5, centre[1] - 5), cv2.FONT_HERSHEY_SIMPLEX,
                        0.35, (255, 80, 0), 1, cv2.LINE_AA)
    if response.collision:
        cv2.rectangle(image, (0, 0), (image.shape[1] - 1, image.shape[0] - 1), (0, 0, 255), 3)
    text = (f"#{response.index} spike rate {response.spike_rate:.0f}"
            + (" WARNING" if response.collision else ""))
    scale = header_scale(text, image.shape[1])
    for colour, thickness in (((0, 0, 0), 3), ((255, 255, 255), 1)):  # white on a dark rim
        cv2.putText(image, text, (5, 14), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thickness,
                    cv2.LINE_AA)
    return image


def header_scale(text: str, width: int, largest: float = 0.4) -> float:
    """The font scale at which the annotated frame's header fits in ``width`` pixels with a
    5-px margin each side (at most ``largest``): a 128-px frame would cut off the warning."""
    (w, _), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, largest, 3)
    return largest * min(1.0, (width - 10) / w) if w > 0 else largest


def _to_frame(image: np.ndarray, size: tuple[int, int], interpolation: int) -> np.ndarray:
    """A map at the frame's ``(width, height)``: as it is where it has that size already."""
    if image.shape[1::-1] == size:
        return image
    return cv2.resize(image, size, interpolation=interpolation)


def warning_intervals(collision: Sequence[bool]) -> list[tuple[int, int]]:
    """Maximal runs of consecutive warnings as (first, last) frame indices."""
    runs, start = [], None
    for i, c in enumerate(collision):
        if c and start is None:
            start = i
        elif not c and start is not None:
            runs.append((start, i - 1))
            start = None
    if start is not None:
        runs.append((start, len(collision) - 1))
    return runs


def plot_responses(times: Sequence[float], u: Sequence[float], spike_rate: Sequence[float],
                   collision: Sequence[bool], path: str | Path, title: str = "") -> Path:
    """Plot u(t) and the spike rate over time, warning intervals shaded, to a PNG file."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    times = np.asarray(times, dtype=float)
    step = float(np.median(np.diff(times))) if len(times) > 1 else 1.0
    fig, (ax_u, ax_s) = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    ax_u.plot(times, u, color="tab:blue")
    ax_u.set_ylabel("u(t)")
    ax_s.step(times, spike_rate, where="post", color="tab:orange")
    ax_s.set_ylabel("spike rate (Hz)")
    ax_s.set_xlabel("time (s)")
    for first, last in warning_intervals(collision):
        for ax in (ax_u, ax_s):
            ax.axvspan(times[first], times[last] + step, color="red", alpha=0.15, lw=0)
    if title:
        ax_u.set_title(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
