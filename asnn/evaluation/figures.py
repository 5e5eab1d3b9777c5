"""Figures of the evaluation, drawn with Matplotlib's object API on the Agg canvas.

Every function takes the JSON-ready data :mod:`asnn.evaluation` computes (and saves next to the
figure), draws one PNG and returns its path. No pyplot: nothing touches Matplotlib's global state,
so the functions are safe in servers and tests.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..retina import motion_components

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "MODEL_COLOURS",
    "response_series",
    "plot_clip_responses",
    "plot_summary",
    "plot_synthetic_responses",
    "plot_sweeps",
    "plot_maps",
    "plot_temporal_filter",
]

MODEL_COLOURS = {"asnn": "tab:red", "asnn:reference": "tab:orange", "lgmd1": "tab:blue",
                 "lgmd2": "tab:green"}
_OTHER_COLOURS = ("tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "black")
_OUTCOME_COLOURS = {"hit": "tab:green", "early": "tab:orange", "late": "tab:purple",
                    "miss": "tab:gray", "false": "tab:red", "quiet": "tab:cyan"}


def _figure(width: float, height: float) -> Figure:
    # matplotlib (0.2-0.6 s, and a writable cache folder) is loaded for a plot only: every
    # ``asnn`` command imports the evaluation's modules through its parser
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def _colour(detector: str) -> str:
    if detector in MODEL_COLOURS:
        return MODEL_COLOURS[detector]
    return _OTHER_COLOURS[sum(detector.encode()) % len(_OTHER_COLOURS)]


def response_series(records: Sequence[Mapping], outcome: str | None = None) -> dict:
    """The per-frame series the response plots draw, from a detector's records.

    Returns
    -------
    dict
        ``u``, ``out``, ``spikes``, ``spike_rate`` and ``collision`` lists, and ``outcome``
        when given.
    """
    series = {key: [r[key] for r in records] for key in ("u", "out", "spikes", "spike_rate")}
    series["collision"] = [bool(r["collision"]) for r in records]
    if outcome is not None:
        series["outcome"] = outcome
    return series


def _mark_events(ax, onset: int | None, contact: int | None, window: Sequence[int] | None = None,
                 legend: bool = False):
    if window is not None:
        ax.axvspan(window[0], window[1], color="tab:green", alpha=0.08, lw=0)
    if onset is not None:
        ax.axvline(onset, color="black", ls="--", lw=0.8, label="onset" if legend else None)
    if contact is not None:
        ax.axvline(contact, color="black", ls="-", lw=1.0, label="contact" if legend else None)


def plot_clip_responses(path: str | Path, clip: Mapping) -> Path:
    """One clip: each model's output over time, its warnings, onset and contact.

    Parameters
    ----------
    path : str or Path
        The PNG to write.
    clip : dict
        ``name``, ``onset``, ``contact`` (frames or None), ``window`` (the hit window or None),
        ``warmup`` and ``models``: ``{model: {"out": [...], "spike_rate": [...],
        "collision": [...], "outcome": str}}``; optionally ``fps``, which adds a time axis in
        seconds over the frames (labels count frames, ``asnn detect --plot`` seconds).
    """
    models = clip["models"]
    # a row of warnings per model: the ablation's 31 overlapped in a fixed height (and
    # matplotlib gave up its layout), its legend over the curves
    rows = max(len(models), 3)
    fig = _figure(8.0 if rows <= 6 else 11.0, 5.6 + 0.16 * (rows - 3))
    top, middle, bottom = fig.subplots(3, 1, sharex=True, height_ratios=[3, 2, rows / 3])
    for model, series in models.items():
        frames = np.arange(len(series["out"]))
        top.plot(frames, series["out"], color=_colour(model), lw=1.2,
                 label=f"{model} ({series.get('outcome', '?')})")
        if "spike_rate" in series:
            middle.plot(frames, series["spike_rate"], color=_colour(model), lw=1.0)
    for row, (model, series) in enumerate(models.items()):
        warn = np.flatnonzero(np.asarray(series["collision"], dtype=bool))
        bottom.scatter(warn, np.full(len(warn), row), marker="|", s=80, color=_colour(model))
    for ax in (top, middle, bottom):
        _mark_events(ax, clip.get("onset"), clip.get("contact"), clip.get("window"))
        ax.axvspan(0, clip.get("warmup", 0) - 0.5, color="0.85", lw=0)
    top.set_ylabel("out(t)")
    top.set_title(f"{clip['name']}: responses (dashed onset, solid contact, green hit window)")
    if rows <= 6:
        top.legend(loc="upper left", fontsize=8)
    else:  # beside the axes
        top.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=6,
                   ncol=1 + len(models) // 16)
    middle.set_yscale("symlog", linthresh=10.0)
    middle.set_ylabel("spike rate, Hz")
    bottom.set_yticks(range(len(models)), list(models), fontsize=8 if rows <= 6 else 6)
    bottom.set_ylim(-0.7, len(models) - 0.3)
    bottom.set_ylabel("warnings")
    bottom.set_xlabel("frame")
    fps = clip.get("fps")
    if fps:
        seconds = top.secondary_xaxis("top", functions=(lambda f: f / fps, lambda s: s * fps))
        seconds.set_xlabel("time (s)")
    return _save(fig, path)


def plot_summary(path: str | Path, summaries: Mapping[str, Mapping]) -> Path:
    """Stacked bars of the outcomes per detector, and the median lead time of the hits.

    Parameters
    ----------
    path : str or Path
        The PNG to write.
    summaries : dict
        ``{model: scoring.summarize(...)}``.
    """
    models = list(summaries)
    # detector specs can be long (asnn:robust/ignore_rig=false): stand them upright where they
    # would run into each other, and give them room below
    tilt = sum(len(m) for m in models) > 24
    fig = _figure(8.0, 3.6 + (0.07 * max(len(m) for m in models) if tilt else 0.0))
    counts_ax, lead_ax = fig.subplots(1, 2, width_ratios=[2, 1])
    x = np.arange(len(models))
    bottom = np.zeros(len(models))
    for outcome, colour in _OUTCOME_COLOURS.items():
        values = np.array([summaries[m].get(outcome, 0) for m in models], dtype=float)
        counts_ax.bar(x, values, bottom=bottom, color=colour, label=outcome, width=0.6)
        bottom += values
    counts_ax.set_xticks(x, models)
    counts_ax.set_ylabel("clips")
    counts_ax.set_title("outcomes (early and false are false alarms)")
    counts_ax.legend(fontsize=8, ncol=3, loc="upper right")
    counts_ax.set_ylim(0, max(bottom.max(), 1) * 1.35)
    lead = [summaries[m].get("median_lead_s") for m in models]
    # one neutral colour: the detectors' own colours would clash with the outcomes' beside them
    # (asnn's red is the false alarms' red); the ticks name the bars
    lead_ax.bar(x, [v if v is not None else 0.0 for v in lead], color="0.45", width=0.6)
    lead_ax.set_xticks(x, models)
    for i, value in enumerate(lead):
        if value is None:  # no hits: no lead, not a lead of 0 s
            lead_ax.text(i, 0.0, "no hits", ha="center", va="bottom", rotation=90, fontsize=8)
    lead_ax.set_ylabel("seconds")
    lead_ax.set_title("median lead time of hits")
    if tilt:
        for ax in (counts_ax, lead_ax):
            ax.tick_params(axis="x", labelrotation=90)
    return _save(fig, path)


_TICK_ROW, _TICK_STEP = 1.015, 0.02  # where the synthetic figures' warning ticks are drawn


def plot_synthetic_responses(path: str | Path, data: Mapping) -> Path:
    """Paper Figs. 6 and 7: a stimulus frame and the models' outputs, one column per scene.

    Parameters
    ----------
    path : str or Path
        The PNG to write.
    data : dict
        ``title`` and ``scenes``: a list of ``{"title", "snapshot" (2-D list, uint8),
        "snapshot_frame", "onset", "contact", "models": {model: {"out": [...],
        "collision": [...]}}}``.
    """
    scenes = data["scenes"]
    fig = _figure(4.0 * len(scenes), 5.8)
    axes = fig.subplots(2, len(scenes), squeeze=False, height_ratios=[1, 1.1])
    for col, scene in enumerate(scenes):
        img_ax, ax = axes[0, col], axes[1, col]
        img_ax.imshow(np.asarray(scene["snapshot"]), cmap="gray", vmin=0, vmax=255)
        img_ax.set_title(f"{scene['title']}\n(frame {scene['snapshot_frame']})", fontsize=9)
        img_ax.set_axis_off()
        for row, (model, series) in enumerate(scene["models"].items()):
            out = np.asarray(series["out"])
            ax.plot(np.arange(len(out)), out, color=_colour(model), lw=1.2, label=model)
            # a row of ticks per model, above out's range: on one row the last drawn hid the
            # others' warnings
            warn = np.flatnonzero(np.asarray(series["collision"], dtype=bool))
            ax.scatter(warn, np.full(len(warn), _TICK_ROW + _TICK_STEP * row), marker="|",
                       s=20, color=_colour(model))
        _mark_events(ax, scene.get("onset"), scene.get("contact"), legend=True)
        ax.set_ylim(0.48, _TICK_ROW + _TICK_STEP * len(scene["models"]))
        ax.set_xlabel("step")
        if col == 0:
            ax.set_ylabel("out(t); ticks above 1: warnings, a row per model")
            ax.legend(fontsize=8, loc="center right")
    fig.suptitle(data.get("title", ""))
    return _save(fig, path)


def plot_sweeps(path: str | Path, data: Mapping) -> Path:
    """Paper Fig. 9: ASNN's u(t) and its peak for a contrast sweep and a speed sweep.

    Parameters
    ----------
    path : str or Path
        The PNG to write.
    data : dict
        ``contrast`` and ``speed``, each ``{"values": [...], "u": [[...], ...], "peak": [...]}``,
        plus ``onset`` and ``contact``.
    """
    fig = _figure(9.0, 6.0)
    axes = fig.subplots(2, 2, width_ratios=[2, 1])
    for row, (key, unit) in enumerate((("contrast", "Weber contrast"),
                                       ("speed", "edge speed, px/step"))):
        sweep = data[key]
        series_ax, peak_ax = axes[row]
        colours = [f"C{i}" for i in range(len(sweep["values"]))]
        for value, u, colour in zip(sweep["values"], sweep["u"], colours):
            series_ax.plot(np.arange(len(u)), u, color=colour, lw=1.0, label=f"{value:g}")
        _mark_events(series_ax, data.get("onset"), data.get("contact"))
        series_ax.set_ylabel("u(t)")
        series_ax.set_xlabel("step")
        series_ax.legend(title=unit, fontsize=7, title_fontsize=8, ncol=2)
        peak_ax.plot(sweep["values"], sweep["peak"], "o-", color="tab:red")
        peak_ax.set_xlabel(unit)
        peak_ax.set_ylabel("peak u")
    fig.suptitle(data.get("title", "contrast and speed sensitivity"))
    return _save(fig, path)


def plot_maps(path: str | Path, data: Mapping) -> Path:
    """Paper Fig. 8: motion-energy flow, V, G, M_a, M_d and G' at one step.

    Parameters
    ----------
    path : str or Path
        The PNG to write.
    data : dict
        ``frame`` (2-D gray), ``V``, ``phi``, ``G``, ``M_a``, ``M_d``, ``G_prime`` (2-D lists),
        ``step`` and ``title``.
    """
    return _save(_maps_figure(data), path)


def _maps_figure(data: Mapping) -> Figure:
    frame = np.asarray(data["frame"], dtype=float)
    v, phi = np.asarray(data["V"], dtype=float), np.asarray(data["phi"], dtype=float)
    fig = _figure(12.0, 7.6)
    axes = fig.subplots(2, 3)
    ax = axes[0, 0]
    # the maps are on the model's grid, which the input-scale stage may make larger or smaller
    # than the frame (a 128-px frame is seen at 160): the frame is drawn over the maps' pixels
    # and the arrows sampled there, or they stand off the objects they belong to
    h, w = v.shape
    ax.imshow(frame, cmap="gray", vmin=0, vmax=255, extent=(-0.5, w - 0.5, h - 0.5, -0.5))
    stride = max(min(h, w) // 24, 1)
    ys, xs = np.mgrid[stride // 2:h:stride, stride // 2:w:stride]
    vv = np.clip(v[ys, xs], 0.0, None)
    scale = vv.max() if vv.max() > 0 else 1.0
    # lengths by the square root of V: the stripes' energy, a hundredth of the disk's rim,
    # would be dots drawn in proportion
    vx, vy = motion_components(np.sqrt(vv / scale), phi[ys, xs])  # eq. 29's direction
    # phi is in image coordinates (y down), and so are the axes imshow sets up: angles="xy"
    # draws the vector in them as it is
    ax.quiver(xs, ys, vx, vy,
              color="tab:red", angles="xy", scale_units="xy", scale=1.0 / (1.5 * stride))
    ax.set_title("(a) flow of motion energy (~ sqrt V)", fontsize=10)
    panels = [("V", "(b) maximal motion energy V", "magma"),
              ("G", "(c) approach-sensitive map G", "magma"),
              ("M_a", "(d) approach-sensitive attention M_a", "gray"),
              ("M_d", "(e) directionally selective attention M_d", "gray"),
              ("G_prime", "(f) approach-sensitive response G'", "magma")]
    for ax, (key, title, cmap) in zip(axes.ravel()[1:], panels):
        image = ax.imshow(np.asarray(data[key], dtype=float), cmap=cmap)
        ax.set_title(title)
        fig.colorbar(image, ax=ax, shrink=0.8)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    title = data.get("title", f"intermediate maps at step {data.get('step')}")
    if (h, w) != frame.shape[:2]:
        title += f" (the model's grid: {w}x{h}, the frame {frame.shape[1]}x{frame.shape[0]})"
    fig.suptitle(title)
    return fig


def plot_temporal_filter(path: str | Path, data: Mapping) -> Path:
    """Paper Fig. 3: impulse and step responses of L(K, n, z0) for several n.

    Parameters
    ----------
    path : str or Path
        The PNG to write.
    data : dict
        ``t`` (seconds), ``impulse`` and ``step`` (``{str(n): [...]}``), ``title``.
    """
    t = np.asarray(data["t"])
    fig = _figure(10.0, 3.8)
    axes = fig.subplots(1, 2)
    for ax, key, title in ((axes[0], "impulse", "impulse response"),
                           (axes[1], "step", "step response")):
        for n, values in data[key].items():
            ax.plot(t, values, lw=1.2, label=f"n = {n}")
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_xlabel("t, s")
        ax.set_title(title)
        ax.legend(fontsize=8)
    axes[0].set_ylabel("$K\\,(z_n - z_{n+1})$")
    axes[1].set_ylabel("$K\\,(z_n - z_{n+1})$ for a unit step")
    fig.suptitle(data.get("title", "temporal filter L(K, n, z0)"))
    return _save(fig, path)
