"""Running the detectors over labelled clips (``asnn eval CLIPS_DIR``).

:func:`evaluate_clips` runs each model over every clip of a ``labels.json``, keeps each run's
per-frame results as ``results/<model>/<clip>.jsonl`` (the ``asnn detect --jsonl`` format),
scores them with :mod:`asnn.evaluation.scoring`, and writes ``results.json``, ``report.md`` and
the plots.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from ..detectors import MODELS, make_detector
from ..io.sources import SourceError, open_source
from ..params import preset
from . import figures, scoring
from .progress import Silent

__all__ = ["run_detector", "evaluate_clips"]



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


def _run_clip(video: str, model: str, preset_name: str | None, out_path: str,
              topic: str | None = None) -> tuple[int, str | None]:
    """Worker: one model on one clip (a bag's ``topic``), results to ``out_path``.
    Returns (frames, error)."""
    try:
        clip = open_source(video, topic=topic)
        records = run_detector(clip.frames(), model, preset_name, clip.fps)
    except (SourceError, ValueError) as exc:
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
        Directory of the clips; each label's ``file`` is relative to it: a video, or a ROS 2
        bag whose image topic the label's ``topic`` names (needed when it has several).
    out_dir : path
        Where ``results.json``, ``report.md``, ``results/<model>/<clip>.jsonl`` and
        ``plots/*.png`` go.
    labels_path : path, optional
        Default ``clips_dir / "labels.json"``.
    models : sequence of str
    preset_name : str, optional
        ASNN preset; None means ``default``.
    early_tolerance_s, warmup : scoring rules (see :func:`asnn.evaluation.scoring.score_clip`).
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
              str(out_dir / "results" / m / f"{Path(lab['file']).stem}.jsonl"), lab.get("topic"))
             for m in models for lab in labels]
    for task in tasks:  # stale results of an earlier run must not be scored
        Path(task[3]).unlink(missing_ok=True)
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
