"""Running the detectors over labelled clips and the paper's synthetic experiments.

Two entry points, both behind ``asnn eval``:

:func:`evaluate_clips`
    Runs each model over every clip of a ``labels.json``, keeps each run's per-frame results as
    ``results/<model>/<clip>.jsonl`` (the ``asnn detect --jsonl`` format), scores them with
    :mod:`asnn.scoring`, and writes ``results.json``, ``report.md`` and the plots.
:func:`synthetic_suite`
    Regenerates the paper's synthetic experiments from :mod:`asnn.stimuli` (Figs. 2, 4, 5, 6, 7):
    each figure as a PNG with the numbers behind it as JSON, plus ``results.json`` and
    ``report.md``.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from . import figures, retina, scoring
from .detectors import MODELS, make_detector
from .model import ASNN
from .params import preset
from .progress import Silent
from .stimuli import make_scene
from .video import VideoError, open_video

__all__ = [
    "run_detector",
    "evaluate_clips",
    "synthetic_suite",
    "temporal_filter_responses",
    "SYNTHETIC_SCENES",
    "CONTRAST_SWEEP",
    "SPEED_SWEEP",
]

SYNTHETIC_SCENES = (
    ("approach_recession", "approach-recession"),
    ("translation", "translation"),
    ("approach_recession_over_stripes", "approach-recession, translating background"),
)
CONTRAST_SWEEP = (0.1, 0.2, 0.4, 0.6, 0.8, 1.0)
SPEED_SWEEP = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)
MAPS_STEP = 32  # the step of paper Fig. 4
FILTER_ORDERS = (1, 2, 3, 4, 5)


# --------------------------------------------------------------------------- running


def run_detector(frames: Iterable[np.ndarray], model: str, preset_name: str | None = None,
                 fps: float = 20.0, on_frame: Callable[[], None] | None = None) -> list[dict]:
    """Run one fresh detector over frames and return its per-frame records.

    Parameters
    ----------
    frames : iterable of ndarray
    model : {'asnn', 'lgmd1', 'lgmd2'}
    preset_name : str, optional
        ASNN preset (ignored by the LGMD models).
    fps : float
        Frame rate, for the ``t`` field.
    on_frame : callable, optional
        Called after each frame (progress).

    Returns
    -------
    list of dict
        One record per frame in the ``asnn detect --jsonl`` format: ``frame``, ``t``, ``u``,
        ``out``, ``spikes``, ``spike_rate``, ``collision``, ``targets``.
    """
    detector = make_detector(model, preset_name)
    records = []
    for index, frame in enumerate(frames):
        response = detector.step(frame)
        records.append({"frame": index, "t": round(index / fps, 6), **response.to_dict()})
        if on_frame is not None:
            on_frame()
    return records


def _write_jsonl(path: Path, records: Sequence[Mapping]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        for r in records:
            fh.write(json.dumps(r) + "\n")


def _write_json(path: Path, data) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    return path


def _run_clip(video: str, model: str, preset_name: str | None, out_path: str) -> tuple[int, str | None]:
    """Worker: one model on one clip, results to ``out_path``. Returns (frames, error)."""
    try:
        clip = open_video(video)
        records = run_detector(clip, model, preset_name, clip.fps)
    except (VideoError, ValueError) as exc:
        return 0, str(exc)
    _write_jsonl(Path(out_path), records)
    return len(records), None


def _fmt(value, digits: int = 2, suffix: str = "") -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}f}{suffix}"
    return f"{value}{suffix}"


def _rate(value) -> str:
    return "–" if value is None else f"{100 * value:.0f}%"


def _clips_report(results: Mapping) -> str:
    settings = results["settings"]
    models = list(results["models"])
    lines = [
        "# Evaluation on labelled clips",
        "",
        f"Clips: `{settings['clips_dir']}` (labels `{settings['labels']}`), preset "
        f"`{settings['preset']}` for ASNN. Scoring (SPEC.md section 5): warm-up "
        f"{settings['warmup']} frames; hit when the first warning lies in "
        f"[onset - {settings['early_tolerance_s']:g} s, contact + {scoring.CONTACT_SLACK_FRAMES}"
        " frames]; an earlier first warning is an early warning (a false alarm); any warning on a"
        " non-collision clip is a false alarm.",
        "",
        "| model | hits | early | late | misses | false alarms (nc) | quiet (nc) | hit rate |"
        " false-alarm rate | mean lead (hits) | median loc. error | warning frames in / out of"
        " windows |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for m in models:
        s = results["models"][m]["summary"]
        lines.append(
            f"| {m} | {s['hit']}/{s['collision_clips']} | {s['early']} | {s['late']} | {s['miss']}"
            f" | {s['false']}/{s['noncollision_clips']} | {s['quiet']}/{s['noncollision_clips']}"
            f" | {_rate(s['hit_rate'])} | {_rate(s['false_alarm_rate'])}"
            f" | {_fmt(s['mean_lead_s'], 2, ' s')} | {_fmt(s['median_localisation_px'], 0, ' px')}"
            f" | {s['window_warning_frames']} / {s['warning_frames'] - s['window_warning_frames']} |")
        if s["missing"]:
            lines[-1] += f" ({s['missing']} clips without results)"
    lines += ["", "Per clip: outcome, first warning frame (lead time, s), warning frames.", "",
              "| clip | onset | contact | " + " | ".join(models) + " |",
              "| --- | --- | --- | " + " | ".join("---" for _ in models) + " |"]
    labels = {lab["file"]: lab for lab in results["labels"]}
    for index, clip in enumerate(results["models"][models[0]]["clips"]):
        lab = labels.get(clip["clip"], {})
        cells = []
        for m in models:
            c = results["models"][m]["clips"][index]
            cell = c["outcome"]
            if c["first_warning"] is not None:
                cell += f" @{c['first_warning']}"
                if c["lead_s"] is not None:
                    cell += f" ({c['lead_s']:+.2f} s)"
                cell += f", {c['warning_frames']} fr"
            cells.append(cell)
        lines.append(f"| {clip['clip']} | {_fmt(lab.get('onset_frame'))} | "
                     f"{_fmt(lab.get('contact_frame'))} | " + " | ".join(cells) + " |")
    if results.get("errors"):
        lines += ["", "Errors:", ""] + [f"- {e}" for e in results["errors"]]
    return "\n".join(lines) + "\n"


def evaluate_clips(clips_dir: str | Path, out_dir: str | Path, *,
                   labels_path: str | Path | None = None, models: Sequence[str] = MODELS,
                   preset_name: str | None = None,
                   early_tolerance_s: float = scoring.EARLY_TOLERANCE_S,
                   warmup: int = scoring.WARMUP_FRAMES, jobs: int = 1, plots: bool = True,
                   progress=None) -> dict:
    """Run, score and report every model on every labelled clip.

    Parameters
    ----------
    clips_dir : path
        Directory of the clips; each label's ``file`` is relative to it.
    out_dir : path
        Where ``results.json``, ``report.md``, ``results/<model>/<clip>.jsonl`` and
        ``plots/*.png`` go.
    labels_path : path, optional
        Default ``clips_dir / "labels.json"``.
    models : sequence of str
    preset_name : str, optional
        ASNN preset; None means ``default``.
    early_tolerance_s, warmup : scoring rules (see :func:`asnn.scoring.score_clip`).
    jobs : int
        Processes running (model, clip) pairs in parallel.
    plots : bool
        Draw the PNGs.
    progress : ProgressPrinter-like, optional

    Returns
    -------
    dict
        What ``results.json`` holds: ``settings``, ``labels``, ``models`` (per model a
        ``summary`` and per-clip ``clips`` scores) and ``errors``.

    Raises
    ------
    ValueError
        For an unknown model or preset, or an unreadable labels file.
    """
    clips_dir, out_dir = Path(clips_dir), Path(out_dir)
    labels_path = Path(labels_path) if labels_path else clips_dir / "labels.json"
    labels = scoring.load_labels(labels_path)
    for m in models:
        if m not in MODELS:
            raise ValueError(f"unknown model {m!r}; choose from {', '.join(MODELS)}")
    preset(preset_name or "default")  # fail early on an unknown preset
    progress = progress or Silent()

    tasks = [(str(clips_dir / lab["file"]), m, preset_name,
              str(out_dir / "results" / m / f"{Path(lab['file']).stem}.jsonl"))
             for m in models for lab in labels]
    for _, _, _, path in tasks:  # stale results of an earlier run must not be scored
        Path(path).unlink(missing_ok=True)
    expected = [int(lab.get("frames") or 1) for m in models for lab in labels]
    progress.start(sum(expected), "eval")
    errors = []

    def finished(index: int, frames: int, error: str | None) -> None:
        video, model = tasks[index][:2]
        name = f"{model} {Path(video).name}"
        progress.advance(expected[index], name)
        progress.note(name + (f": {error}" if error else f", {frames} frames"))
        if error:
            errors.append(f"{name}: {error}")

    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = {pool.submit(_run_clip, *task): index for index, task in enumerate(tasks)}
            for future in as_completed(futures):
                finished(futures[future], *future.result())
    else:
        for index, task in enumerate(tasks):
            finished(index, *_run_clip(*task))
    progress.finish()

    results = {
        "settings": {"clips_dir": str(clips_dir), "labels": str(labels_path),
                     "models": list(models), "preset": preset_name or "default",
                     "early_tolerance_s": early_tolerance_s, "warmup": warmup,
                     "contact_slack_frames": scoring.CONTACT_SLACK_FRAMES},
        "labels": labels,
        "models": {},
        "errors": errors,
    }
    for m in models:
        scores = scoring.score_directory(out_dir / "results" / m, labels, warmup=warmup,
                                         early_tolerance_s=early_tolerance_s)
        results["models"][m] = {"summary": scoring.summarize(scores),
                                "clips": [s.to_dict() for s in scores]}
    _write_json(out_dir / "results.json", results)
    (out_dir / "report.md").write_text(_clips_report(results), encoding="utf-8")
    if plots:
        _plot_clips(out_dir, labels, models, results, warmup)
    return results


def _plot_clips(out_dir: Path, labels: Sequence[Mapping], models: Sequence[str],
                results: Mapping, warmup: int) -> None:
    for index, lab in enumerate(labels):
        series = {}
        for m in models:
            path = scoring.results_path(out_dir / "results" / m, lab["file"])
            if path is None:
                continue
            records = scoring.load_records(path)
            series[m] = {"out": [r["out"] for r in records],
                         "spike_rate": [r["spike_rate"] for r in records],
                         "collision": [bool(r["collision"]) for r in records],
                         "outcome": results["models"][m]["clips"][index]["outcome"]}
        if not series:
            continue
        window = results["models"][models[0]]["clips"][index].get("window")
        figures.plot_clip_responses(
            out_dir / "plots" / f"{Path(lab['file']).stem}.png",
            {"name": lab["file"], "onset": lab.get("onset_frame"),
             "contact": lab.get("contact_frame"), "window": window, "warmup": warmup,
             "models": series})
    figures.plot_summary(out_dir / "plots" / "summary.png",
                         {m: results["models"][m]["summary"] for m in models})


# --------------------------------------------------------------------------- synthetic suite


def temporal_filter_responses(params, orders: Sequence[int] = FILTER_ORDERS,
                              steps: int = 30) -> dict:
    """Impulse and step responses of L(K, n, z0) = K (z_n - z_{n+1}) for several n (Fig. 2).

    Uses the cascade of :func:`asnn.retina.temporal_filter_step` with the parameters' dt, tau,
    A, C and input convention.

    Returns
    -------
    dict
        ``t`` (seconds of each step), ``impulse`` and ``step`` (``{str(n): list}``).
    """
    rate = params.dt / params.tau
    n_max = max(orders)
    out = {"t": [params.dt * i for i in range(steps)], "impulse": {}, "step": {},
           "dt": params.dt, "tau": params.tau, "A": params.decay, "C": params.c,
           "K": params.gain, "leaky_input": params.leaky_input}
    for kind in ("impulse", "step"):
        stages = np.zeros((n_max + 2, 1, 1))
        readouts = {n: [] for n in orders}
        for i in range(steps):
            x = np.full((1, 1), 1.0 if (kind == "step" or i == 0) else 0.0)
            retina.temporal_filter_step(stages, x, rate, params.c, params.decay,
                                        params.leaky_input)
            for n in orders:
                readouts[n].append(float(retina.temporal_readout(stages, params.gain, n)[0, 0]))
        out[kind] = {str(n): v for n, v in readouts.items()}
    return out


def _series(records: Sequence[Mapping]) -> dict:
    return {"u": [r["u"] for r in records], "out": [r["out"] for r in records],
            "spikes": [r["spikes"] for r in records],
            "spike_rate": [r["spike_rate"] for r in records],
            "collision": [bool(r["collision"]) for r in records]}


def _phase_warnings(collision: Sequence[bool], label: Mapping, warmup: int) -> tuple[int, int]:
    """Warnings inside the approach phase [onset, contact + 2] and elsewhere after warm-up."""
    onset, contact = label.get("onset_frame"), label.get("contact_frame")
    inside = other = 0
    for frame, warn in enumerate(collision):
        if not warn or frame < warmup:
            continue
        if onset is not None and onset <= frame <= contact + scoring.CONTACT_SLACK_FRAMES:
            inside += 1
        else:
            other += 1
    return inside, other


def _round_map(array: np.ndarray, digits: int = 5) -> list:
    if array.dtype == bool:
        return array.astype(int).tolist()
    return [[float(f"{v:.{digits}g}") for v in row] for row in array.tolist()]


def _synthetic_report(results: Mapping) -> str:
    lines = [
        "# Synthetic experiments",
        "",
        f"Scenes {results['size'][0]}x{results['size'][1]}, {results['frames']} steps; ASNN preset "
        f"`{results['preset']}`. Approach-recession: the disk grows over steps 10-55 and shrinks "
        "over 75-120; translation: the bar moves right over 10-55 and back over 75-120. Scored "
        "with no early tolerance (generated clips); `approach` counts warning frames in "
        "[onset, contact + 2], `other` the warning frames elsewhere after the warm-up.",
        "",
        "| scene | target | model | outcome | first warning | approach | other | peak out |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for row in results["table"]:
        lines.append(f"| {row['scene']} | {row['polarity']} | {row['model']} | {row['outcome']} | "
                     f"{_fmt(row['first_warning'])} | {row['approach_warnings']} | "
                     f"{row['other_warnings']} | {row['peak_out']:.3f} |")
    lines += ["", "Contrast sweep (dark disk, 1 px/step), ASNN peak u: " + ", ".join(
        f"c={c:g}: {p:.4g}" for c, p in zip(results["contrast"]["values"],
                                             results["contrast"]["peak"])),
              "", "Speed sweep (contrast 1), ASNN peak u: " + ", ".join(
        f"{s:g} px/step: {p:.4g}" for s, p in zip(results["speed"]["values"],
                                                   results["speed"]["peak"])),
              "", "Figures: " + ", ".join(f"`{f}`" for f in results["figures"]), ""]
    return "\n".join(lines)


def synthetic_suite(out_dir: str | Path, *, preset_name: str | None = None,
                    models: Sequence[str] = MODELS, size: tuple[int, int] = (128, 128),
                    warmup: int = scoring.WARMUP_FRAMES, progress=None) -> dict:
    """Regenerate the paper's synthetic experiments and write figures, JSON and a report.

    Writes to ``out_dir``: ``fig2_temporal_filter``, ``fig4_maps`` (step 32 of the dark
    approach-recession over stripes), ``fig5_dark_responses``, ``fig6_light_responses``,
    ``fig7_contrast_speed`` (each ``.png`` and ``.json``), ``results.json`` and ``report.md``.

    Parameters
    ----------
    out_dir : path
    preset_name : str, optional
        ASNN preset for every scene; None means ``default``.
    models : sequence of str
        Models of Figs. 5 and 6 (the sweeps and maps are ASNN's).
    size : (width, height)
        Frame size; the paper's is 128x128.
    warmup : int
    progress : ProgressPrinter-like, optional

    Returns
    -------
    dict
        What ``results.json`` holds.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    params = preset(preset_name or "default")
    progress = progress or Silent()
    n_runs = 2 * len(SYNTHETIC_SCENES) * len(models) + len(CONTRAST_SWEEP) + len(SPEED_SWEEP) + 2
    progress.start(n_runs, "eval --synthetic")
    written = []

    # Fig. 2: the temporal filter
    filt = temporal_filter_responses(params)
    filt["title"] = f"temporal filter L(K, n, z0), preset {preset_name or 'default'}"
    _write_json(out_dir / "fig2_temporal_filter.json", filt)
    written.append(figures.plot_temporal_filter(out_dir / "fig2_temporal_filter.png", filt).name)
    progress.advance(1, "fig. 2")

    # Figs. 5 and 6: three scenes, dark and light targets, every model
    table = []
    frames = None
    for polarity, fig_name in (("dark", "fig5_dark_responses"), ("light", "fig6_light_responses")):
        data = {"title": f"{polarity} target: responses of {', '.join(models)}"
                         f" (ASNN preset {preset_name or 'default'})", "scenes": []}
        for scene_name, title in SYNTHETIC_SCENES:
            scene = make_scene(scene_name, polarity=polarity, size=size)
            frames = len(scene.frames)
            label = scene.label(scene_name)
            snap = 40  # the disk is half grown, the bar on its way right
            entry = {"title": title, "scene": scene_name, "snapshot_frame": snap,
                     "snapshot": scene.frames[snap].tolist(), "onset": scene.onset_frame,
                     "contact": scene.contact_frame, "collision": scene.collision, "models": {}}
            for m in models:
                records = run_detector(scene.frames, m, preset_name, scene.fps)
                entry["models"][m] = _series(records)
                score = scoring.score_clip(records, label, warmup=warmup, early_tolerance_s=0.0)
                inside, other = _phase_warnings(entry["models"][m]["collision"], label, warmup)
                table.append({"scene": scene_name, "polarity": polarity, "model": m,
                              "outcome": score.outcome, "first_warning": score.first_warning,
                              "approach_warnings": inside, "other_warnings": other,
                              "peak_out": max(entry["models"][m]["out"])})
                progress.advance(1, f"{scene_name} {polarity} {m}")
            data["scenes"].append(entry)
        _write_json(out_dir / f"{fig_name}.json", data)
        written.append(figures.plot_synthetic_responses(out_dir / f"{fig_name}.png", data).name)

    # Fig. 7: contrast and speed sweeps of ASNN on the dark approach-recession
    sweeps = {"title": f"ASNN (preset {preset_name or 'default'}): contrast and speed",
              "onset": 10, "contact": 55}
    for key, values in (("contrast", CONTRAST_SWEEP), ("speed", SPEED_SWEEP)):
        sweep = {"values": list(values), "u": [], "peak": []}
        for value in values:
            kwargs = {"contrast": value} if key == "contrast" else {"speed": value}
            scene = make_scene("approach_recession", polarity="dark", size=size, **kwargs)
            u = [r["u"] for r in run_detector(scene.frames, "asnn", preset_name, scene.fps)]
            sweep["u"].append(u)
            sweep["peak"].append(max(u))
            progress.advance(1, f"{key} {value:g}")
        sweeps[key] = sweep
    _write_json(out_dir / "fig7_contrast_speed.json", sweeps)
    written.append(figures.plot_sweeps(out_dir / "fig7_contrast_speed.png", sweeps).name)

    # Fig. 4: intermediate maps at step 32 of the dark approach-recession over stripes
    scene = make_scene("approach_recession_over_stripes", polarity="dark", size=size)
    model = ASNN(params, record_maps=True)
    response = None
    for frame in scene.frames[:MAPS_STEP + 1]:
        response = model.step(frame)
    maps = response.maps
    data = {"title": f"ASNN maps at step {MAPS_STEP}, dark disk over translating stripes "
                     f"(preset {preset_name or 'default'})",
            "step": MAPS_STEP, "frame": scene.frames[MAPS_STEP].tolist(),
            "V": _round_map(maps.V), "phi": _round_map(maps.phi), "G": _round_map(maps.G),
            "M_a": _round_map(maps.M_a), "M_d": _round_map(maps.M_d),
            "G_prime": _round_map(maps.G_prime), "u": response.u,
            "targets": [t.to_dict() for t in response.targets]}
    _write_json(out_dir / "fig4_maps.json", data)
    written.append(figures.plot_maps(out_dir / "fig4_maps.png", data).name)
    progress.advance(1, "fig. 4")
    progress.finish()

    results = {"preset": preset_name or "default", "size": list(size), "frames": frames,
               "models": list(models), "warmup": warmup, "table": table,
               "contrast": {k: sweeps["contrast"][k] for k in ("values", "peak")},
               "speed": {k: sweeps["speed"][k] for k in ("values", "peak")},
               "figures": written}
    _write_json(out_dir / "results.json", results)
    (out_dir / "report.md").write_text(_synthetic_report(results), encoding="utf-8")
    return results
