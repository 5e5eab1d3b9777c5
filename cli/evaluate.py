"""``asnn eval``: the detectors compared on labelled clips, the generated suite and the paper.

``asnn eval CLIPS_DIR [--labels FILE] [--detectors LIST] [--preset P] [--out DIR]`` scores every
detector on labelled clips (SPEC.md section 5), with ``--perturb NAME`` on their frames
perturbed; ``asnn eval --synthetic [--cases PATTERN] [--variant K] [--perturb NAME]
[--size WxH | --scale S]`` generates the labelled suite of :mod:`asnn.stimuli.suite` and scores
it; ``asnn eval --paper`` regenerates the paper's synthetic figures (Figs. 3, 6-9); ``asnn eval
--ttc [--preset P]`` measures the targets' time to contact on approaches of known contact time
(:mod:`asnn.evaluation.ttc`). Detectors
are specs: ``asnn`` (the default preset, or ``--preset``), ``asnn:PRESET``, ``lgmd1``,
``lgmd2``, each with parameters changed after slashes. Exit status 2 for unusable input (found before anything runs: labels, clips that
cannot be opened, options), 1 when some runs failed after it started (their clips scored as
missing, named in the report's errors), 130 when interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path, PurePosixPath

from asnn.detectors import BASELINES
from asnn.evaluation.options import (DEFAULT_DETECTORS, EARLY_TOLERANCE_S, FAMILIES,
                                     PERTURBATIONS, TIE_BREAKS, WARMUP_FRAMES)
from asnn.io.files import folder_problem, path_problem
from asnn.params import preset_names

from .arguments import (Joined, clips_problem, finite, frame_rates, frame_size, nonempty_path,
                        perturbation, preset_spec, processes, tolerance_seconds, warmup_frames, whole)


# the files of the latest run in an --out folder: "mtime_ns<TAB>path relative to it" per line
MANIFEST = ".asnn-eval-files"
# what eval writes at the top of --out (besides --paper's fig*.png and fig*.json)
OUTPUT_FILES = ("report.md", "results.json", "labels.json", "held_out.md", "held_out.json",
                "ttc.md", "ttc.json")


def _detectors(text: str) -> list[str]:
    from asnn.evaluation.runs import parse_detectors  # the model's: when the option is given

    try:
        return [spec.name for spec in parse_detectors(text)]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _summary_line(name: str, s: dict) -> str:
    """One detector's scores on labelled clips, as report.md's first table has them."""
    line = (f"{name}: {s['hit']}/{s['collision_clips']} hits ({s['early']} early, "
            f"{s['late']} late), false alarms on {s['false']}/{s['noncollision_clips']} clips "
            "without a collision")
    return line + (f", {s['missing']} clips without results" if s["missing"] else "")


def _say_unlabelled(clips_dir: str, labels: Path) -> None:
    """Name on stderr, before anything runs, the videos in the clips' folder that no label
    names: they are not scored (``asnn label`` adds their entries). A labels file that cannot
    be read is left to the evaluation to refuse."""
    from asnn.evaluation.labels import read_entries, unlabelled_videos

    try:
        names = unlabelled_videos(clips_dir, read_entries(labels))
    except (OSError, ValueError):
        return
    # a link whose clip is gone (or that loops) has nothing asnn label could enter
    broken = [name for name in names if not (Path(clips_dir) / name).is_file()]
    names = [name for name in names if name not in broken]
    if names:
        one = len(names) == 1
        print(f"asnn eval: {len(names)} video{'' if one else 's'} in the folder "
              f"{'has' if one else 'have'} no label and {'is' if one else 'are'} not scored "
              f"(asnn label {clips_dir} adds {'its entry' if one else 'their entries'}): "
              + ", ".join(names), file=sys.stderr)
    if broken:
        print("asnn eval: links in the folder that lead to no clip (not scored): "
              + ", ".join(broken), file=sys.stderr)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval", help="score the detectors on labelled clips, the generated suite or the paper's "
                     "experiments",
        description="Run ASNN and the LGMD baselines over labelled clips (CLIPS_DIR) or the "
                    "labelled suite of generated scenes (--synthetic) and score them (hit / "
                    "early / late / miss, false alarms, lead time, localisation), or regenerate "
                    "the paper's synthetic figures (--paper).")
    p.add_argument("clips_dir", nargs="?", type=nonempty_path, metavar="CLIPS_DIR",
                   help="directory of the clips (not with --synthetic or --paper)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--synthetic", action="store_true",
                      help="score the labelled suite of generated scenes instead")
    mode.add_argument("--paper", action="store_true",
                      help="regenerate the paper's synthetic figures (Figs. 3, 6-9) instead")
    mode.add_argument("--held-out", action="store_true",
                      help="with CLIPS_DIR: the in-sample and leave-one-clip-out figures of the "
                           "default preset's approach-gate thresholds (printed, and in full in "
                           "held_out.md and held_out.json); of another "
                           "preset's with --preset, or of one ASNN spec's with --detectors "
                           "(asnn:robust/stabilise=false: an addition switched off, its gate "
                           "chosen again). The thresholds were tuned on ../shared/data/real: on "
                           "other clips (your own) the preset's row is not in-sample but "
                           "already held out, and the leave-one-clip-out row shows what "
                           "choosing them on your clips would give. Runs the generated suite "
                           "too (minutes; its progress printed as it traces the clips and cases "
                           "and as it replays the gate)")
    mode.add_argument("--ttc", action="store_true",
                      help="instead, how right the targets' time to contact is: the default "
                           "preset (or --preset) over 96 generated constant-speed approaches of "
                           "known contact time at 10, 20, 30 and 60 fps, the relative error of "
                           "ttc per frame rate and per growth of the image per frame (printed, "
                           "and in ttc.md and ttc.json; under 30 s with --jobs 2)")
    p.add_argument("--frame-rates", type=frame_rates, metavar="R,R,...",
                   help="with --ttc: the approaches' frame rates instead of 10, 20, 30 and 60 "
                        "(24 approaches each; e.g. 40,50,120 for cameras faster than the "
                        "default's frame-rate ceiling)")
    p.add_argument("--tie-break", choices=list(TIE_BREAKS), default="warning-frames",
                   help="with --held-out: how thresholds that tie on hits and false alarms are "
                        "told apart: " + "; ".join(f"{k}: {v}" for k, v in TIE_BREAKS.items())
                        + " (default: %(default)s)")
    p.add_argument("--labels", type=nonempty_path, metavar="FILE",
                   help="labels file (default: CLIPS_DIR/labels.json)")
    p.add_argument("--detectors", "--models", dest="detectors", type=_detectors, action=Joined,
                   default=list(DEFAULT_DETECTORS), metavar="LIST",
                   help="comma-separated detector specs (repeatable: the uses add up): asnn, "
                        f"asnn:PRESET, {', '.join(BASELINES)}, each with fields changed after "
                        "slashes "
                        "(asnn:robust/top_k=0, lgmd1/w_i=0.6) "
                        f"(default: {','.join(DEFAULT_DETECTORS)})")
    p.add_argument("--ablation", action="store_true",
                   help="run the robust preset with each of its additions switched off in turn "
                        "instead of --detectors (asnn.evaluation.runs.ABLATIONS)")
    p.add_argument("--preset", type=preset_spec, default="default",
                   metavar="NAME[/FIELD=VALUE...]",
                   help=f"the ASNN preset a bare 'asnn' stands for ({', '.join(preset_names())}; "
                        "default: %(default)s), with fields of asnn.params.ASNNParams changed "
                        "after slashes as in the detector specs (robust/top_k=0); with --paper "
                        "also the preset of the maps and the sweeps")
    p.add_argument("--cases", metavar="PATTERN", action=Joined,
                   help="with --synthetic (or --held-out: the cases that decide which "
                        "thresholds are admissible): comma-separated patterns of case names or "
                        "groups, e.g. 'loom-*,nearmiss-*' or 'driving-*' (repeatable: the uses add "
                        "up; default: every case, also written 'all'); "
                        "'extra-*' runs the extra drives outside the suite ('all,extra-*': "
                        "both)")
    p.add_argument("--variant", type=whole, default=0, metavar="K",
                   help="with --synthetic: K >= 1 scores the same cases with fresh scene seeds "
                        "(other textures, sensor noise and roadside objects; the same geometry, "
                        "motion and labels; docs/evaluation.md, 'The same cases in fresh "
                        "scenery') (default: 0, the suite as it is)")
    p.add_argument("--out", type=nonempty_path, metavar="DIR", default="eval-out",
                   help="output directory (default: %(default)s); it then holds this run's "
                        "results: the reports, results, plots and figures an earlier run wrote "
                        "there, unchanged since, and this one did not write again are removed "
                        f"(each run's are listed in DIR/{MANIFEST}); nothing else is touched, "
                        "and a labels.json or report.md there that no eval wrote stops the "
                        "run before it starts")
    p.add_argument("--early-tolerance", type=tolerance_seconds, metavar="SECONDS",
                   help="with CLIPS_DIR (not --held-out, which scores by SPEC's rule): a first "
                        "warning up to this long before the labelled "
                        f"onset still counts as a hit (0 to 60; default: "
                        f"{EARLY_TOLERANCE_S}, for onsets judged by eye; the suite's "
                        "onsets are exact and use 0)")
    p.add_argument("--warmup", type=warmup_frames, metavar="FRAMES",
                   help="frames ignored at the start of each clip (default: "
                        f"{WARMUP_FRAMES}; not with --held-out, which scores by SPEC's)")
    p.add_argument("--jobs", type=processes, default=1, metavar="N",
                   help="clips or cases evaluated in parallel processes, at most 64 "
                        "(default: %(default)s)")
    p.add_argument("--size", type=frame_size, metavar="WxH",
                   help="with --paper: frame size of the scenes (default: 128x128, the paper's); "
                        "with --synthetic: render the driving scenes at this size, the same "
                        "drives seen with other pixels (64x48 to 1920x1080; default 192x128; "
                        "the planar scenes keep theirs)")
    p.add_argument("--scale", type=finite, metavar="S",
                   help="with --synthetic: render every case with S times its pixels (0.5-8): "
                        "the planar scenes at S times 160x120 with their sizes, positions and "
                        "speeds in pixels scaled alike, the driving scenes at S times 192x128 "
                        "(default: 1; not with --size)")
    p.add_argument("--perturb", type=perturbation, metavar="NAME",
                   help="with CLIPS_DIR or --synthetic: score the detectors on the frames "
                        "perturbed, "
                        "to see whether their scores hold on another camera: "
                        + "; ".join(f"{name}: {what}" for name, what in
                                    {**PERTURBATIONS, **FAMILIES}.items()))
    p.add_argument("--no-plots", action="store_true", help="skip the PNGs")
    p.add_argument("--case-plots", action="store_true",
                   help="with --synthetic: also plot every case's responses (slower)")
    p.set_defaults(func=run)


def _eval_output(relative: PurePosixPath) -> bool:
    """Whether a path in an --out folder is of a kind eval writes there (the only files the
    manifest may list): the reports and results at its top, ``fig*`` of --paper, the plots and
    the per-clip results."""
    parts, suffix = relative.parts, relative.suffix
    if len(parts) == 1:
        return parts[0] in OUTPUT_FILES or (parts[0].startswith("fig")
                                            and suffix in (".png", ".json"))
    return ((len(parts) == 2 and parts[0] == "plots" and suffix == ".png")
            or (len(parts) == 3 and parts[0] == "results" and suffix == ".jsonl"))


def _listed(out: Path) -> dict[str, int]:
    """The files the last eval into ``out`` listed in its manifest, with their times (none
    where it has no readable manifest)."""
    listed: dict[str, int] = {}
    try:
        for line in (out / MANIFEST).read_text(encoding="utf-8").splitlines():
            mtime, _, name = line.partition("\t")
            listed[name] = int(mtime)
    except (OSError, UnicodeDecodeError, ValueError):
        pass
    return listed


def _replace_previous_run(out: Path, since: float, read: Path | None = None) -> None:
    """Leave ``out`` holding this run's files only: remove those the previous run listed in
    the manifest, if unchanged since (their time as listed) and not written again by this run,
    and list this run's: the files of eval's kinds (:func:`_eval_output`) written since
    ``since``. A file of another kind, one edited since it was listed, the labels file this run
    read (``read``: a suite's labels.json scored as a clips folder in place), and anything
    outside ``out`` are never removed."""
    kept = None if read is None else read.resolve()
    if not out.is_dir():
        return
    previous = _listed(out)
    root = out.resolve()
    written = _written_since(out, since)
    for name, mtime in previous.items():
        path = out / name
        if (name in written or not _eval_output(PurePosixPath(name)) or path.is_symlink()
                or not path.is_file() or root not in path.resolve().parents
                or path.resolve() == kept
                or path.stat().st_mtime_ns != mtime):
            continue
        path.unlink()
        parent = path.parent
        while parent.resolve() != root and not any(parent.iterdir()):
            parent.rmdir()
            parent = parent.parent
    _write_manifest(out, written)


def _written_since(out: Path, since: float) -> dict[str, int]:
    """The files of eval's kinds in ``out`` written since ``since`` (s), with their times."""
    written = {}
    # only where eval writes: a whole tree (--out .) is not walked
    for path in [*out.glob("*"), *out.glob("plots/*"), *out.glob("results/*/*")]:
        relative = PurePosixPath(path.relative_to(out).as_posix())
        if path.is_symlink() or not path.is_file() or not _eval_output(relative):
            continue
        mtime = path.stat().st_mtime_ns
        if mtime >= since * 1e9:
            written[str(relative)] = mtime
    return written


def _write_manifest(out: Path, listed: dict[str, int]) -> None:
    (out / MANIFEST).write_text("".join(f"{mtime}\t{name}\n" for name, mtime
                                        in sorted(listed.items())), encoding="utf-8")


def _present(out: Path) -> set[str]:
    """The files the last eval into ``out`` listed that are there now (before a run starts)."""
    return {name for name in _listed(out) if (out / name).is_file()}


def _keep_unfinished_run(out: Path, since: float, present: set[str],
                         read: Path | None = None) -> None:
    """After a run that stopped before its report (Ctrl-C, SIGTERM, an error): where it wrote
    or replaced files, the manifest lists them beside the previous run's (which are kept), so
    that the next run removes what this one left; and the previous run's top-level reports,
    which no longer describe the folder, are removed (an interrupted run left results no later
    run removed, and the earlier report beside results it had deleted: a user trial)."""
    if not os.path.isdir(out):  # False for an --out refused as too long a name: Path's raises
        return
    previous = _listed(out)
    written = _written_since(out, since)
    # the files it removed: listed and there when it started (``present``; one the user had
    # removed before it is not its doing)
    if not written and all((out / name).is_file() for name in present):
        return  # it stopped before it touched the folder: the previous run's stands
    kept = None if read is None else read.resolve()
    listed = dict(written)
    for name, mtime in previous.items():
        path = out / name
        if name in written or path.is_symlink() or not path.is_file():
            continue
        if (name in OUTPUT_FILES and path.stat().st_mtime_ns == mtime
                and path.resolve() != kept):
            path.unlink()  # one of the previous run's reports (the labels it read excepted)
        else:
            listed[name] = mtime
    _write_manifest(out, listed)


def _out_problem(out: Path, writes: Sequence[str] = (),
                 folders: Sequence[str] = ()) -> str | None:
    """Why ``--out`` cannot be the results' folder, found before anything runs, or None: a file
    there, a file or a folder without write access where it would be made, a folder no file
    can be made in (:func:`asnn.io.files.folder_problem`), the same for the ``folders`` this
    run makes in it, or a file of the names this run ``writes`` there that no asnn eval wrote
    (not in its manifest: a user's labels.json or report.md, which the run would replace)."""
    problem = path_problem(out)
    if problem:
        return f"--out {out}: {problem}"
    if out.exists():
        if not out.is_dir():
            return f"--out {out}: not a folder"
        listed = _listed(out)
        foreign = [name for name in writes if (out / name).exists() and name not in listed]
        if foreign:
            verb, them = ("was", "it") if len(foreign) == 1 else ("were", "them")
            return (f"--out {out}: {', '.join(foreign)} there {verb} not written by asnn eval "
                    f"(not in {MANIFEST}), and this run would replace {them}: move {them}, or "
                    "choose another --out")
    for folder in (out, *(out / name for name in folders)):
        problem = folder_problem(folder)
        if problem:
            return f"--out {out}: {problem}"
    return None


def run(args: argparse.Namespace) -> int:
    """``asnn eval``; the --out folder then holds this run's files only (its earlier runs'
    others are removed, :func:`_replace_previous_run`)."""
    since = time.time()
    present = _present(Path(args.out))  # what a run stopped early is judged against
    read = None
    if args.clips_dir and not (args.synthetic or args.paper):
        read = Path(args.labels) if args.labels else Path(args.clips_dir) / "labels.json"
    try:
        status = _evaluate(args)
    except BaseException:  # Ctrl-C, SIGTERM (cli.main's _Terminated) or a failure
        with contextlib.suppress(OSError):  # what stopped the run is what to report
            _keep_unfinished_run(Path(args.out), since, present, read)
        raise
    if status in (0, 1):  # a report was written
        _replace_previous_run(Path(args.out), since, read)
    else:
        _keep_unfinished_run(Path(args.out), since, present, read)
    return status


def _evaluate(args: argparse.Namespace) -> int:
    # the tooling (numba, OpenCV, matplotlib): only when it runs
    from asnn.evaluation import clips, heldout, paper, suite
    from asnn.evaluation.progress import ProgressPrinter
    from asnn.evaluation.runs import ABLATIONS, parse_detector

    progress = ProgressPrinter(sys.stderr)
    preset_name = None if args.preset == "default" else args.preset
    if (args.synthetic or args.paper or args.ttc) and args.clips_dir:
        print("asnn eval: give either CLIPS_DIR, --synthetic, --paper or --ttc", file=sys.stderr)
        return 2
    misplaced = [flag for flag, given, mode in (
        ("--cases", args.cases, args.synthetic or args.held_out),
        ("--case-plots", args.case_plots, args.synthetic),
        ("--variant", args.variant, args.synthetic),
        ("--size", args.size, args.paper or args.synthetic),
        ("--scale", args.scale is not None, args.synthetic),
        ("--ablation", args.ablation, not (args.paper or args.held_out or args.ttc)),
        ("--labels", args.labels, not (args.synthetic or args.paper or args.ttc)),
        ("--early-tolerance", args.early_tolerance is not None,
         not (args.synthetic or args.paper or args.held_out or args.ttc)),
        # the held-out figures are scored by SPEC's rule, as the grid's choices were made
        ("--warmup", args.warmup is not None, not (args.held_out or args.ttc)),
        ("--perturb", args.perturb, not (args.paper or args.held_out or args.ttc)),
        # --ttc measures one preset's targets (--preset)
        ("--detectors", args.detectors != list(DEFAULT_DETECTORS), not args.ttc),
        # --ablation's rows are the robust preset's, each addition switched off: a preset or
        # detectors given with it were dropped without a word
        ("--preset", args.preset != "default", not args.ablation),
        ("--detectors", args.detectors != list(DEFAULT_DETECTORS), not args.ablation),
        ("--no-plots", args.no_plots, not args.ttc),
        ("--tie-break", args.tie_break != "warning-frames", args.held_out),
        ("--frame-rates", args.frame_rates is not None, args.ttc),
        ("--jobs", args.jobs != 1, not args.paper),  # the paper's runs take seconds, in turn
    ) if given and not mode]
    if misplaced:
        print(f"asnn eval: {', '.join(dict.fromkeys(misplaced))} does not go with this mode "
              "(see asnn eval -h)", file=sys.stderr)
        return 2
    if args.ablation:
        args.detectors = list(ABLATIONS.values())
    writes = (("held_out.md", "held_out.json") if args.held_out else
              ("ttc.md", "ttc.json") if args.ttc else
              ("labels.json", "report.md", "results.json") if args.synthetic else
              ("report.md", "results.json"))
    # a scored run's per-clip results and plots (a file named plots there failed it at its end)
    folders = () if args.paper or args.held_out or args.ttc else ("results", "plots")
    problem = _out_problem(Path(args.out), writes, folders)
    if problem is not None:  # before the first clip runs, not when its results are written
        print(f"asnn eval: {problem}", file=sys.stderr)
        return 2
    tolerance = (EARLY_TOLERANCE_S if args.early_tolerance is None
                 else args.early_tolerance)  # its type bounds it
    warmup = WARMUP_FRAMES if args.warmup is None else args.warmup
    if args.clips_dir and not (args.synthetic or args.paper or args.ttc):
        labels = Path(args.labels) if args.labels else Path(args.clips_dir) / "labels.json"
        problem = clips_problem(args.clips_dir, labels)
        if problem:
            print(f"asnn eval: {problem[0]}: {problem[1]}", file=sys.stderr)
            return 2
    try:
        if args.paper:
            paper.paper_figures(args.out, preset_name=preset_name, detectors=args.detectors,
                                size=args.size or (128, 128), warmup=warmup,
                                plots=not args.no_plots, progress=progress)
        elif args.synthetic:
            suite.evaluate_suite(args.out, detectors=args.detectors, preset_name=preset_name,
                                 cases=args.cases, jobs=args.jobs, warmup=warmup,
                                 plots=not args.no_plots, case_plots=args.case_plots,
                                 variant=args.variant, perturbation=args.perturb,
                                 driving_size=args.size, scale=args.scale, progress=progress)
        elif args.ttc:
            from asnn.evaluation import ttc
            from asnn.evaluation.runs import write_json
            from asnn.io.files import write_atomically

            design = (ttc.DEFAULT_DESIGN if args.frame_rates is None else
                      dataclasses.replace(ttc.DEFAULT_DESIGN, frame_rates=args.frame_rates))
            results = ttc.evaluate_ttc(parse_detector("asnn", args.preset), design,
                                       jobs=args.jobs, progress=progress)
            report = ttc.format_report(results)
            write_json(Path(args.out) / "ttc.json", results)
            write_atomically(Path(args.out) / "ttc.md", report)
            print(report, end="")
            print(f"{args.out}/ttc.md")
            return 0
        elif not args.clips_dir:
            print("asnn eval: CLIPS_DIR is required (or --synthetic, --paper or --ttc)",
                  file=sys.stderr)
            return 2
        elif args.held_out:
            held = parse_detector("asnn", args.preset)
            if args.detectors != list(DEFAULT_DETECTORS):  # one ASNN spec: its preset, changed
                specs = [parse_detector(name, args.preset) for name in args.detectors]
                if len(specs) != 1 or specs[0].model != "asnn":
                    print("asnn eval: --held-out holds out one ASNN detector's gate "
                          "(--detectors asnn:PRESET[/name=value...])", file=sys.stderr)
                    return 2
                held = specs[0]
            held_preset, overrides = held.preset or "default", dict(held.overrides)
            _say_unlabelled(args.clips_dir, labels)
            results = heldout.evaluate_held_out(
                args.clips_dir, args.out, labels_path=args.labels, preset_name=held_preset,
                cases=args.cases, jobs=args.jobs, progress=progress, tie_break=args.tie_break,
                overrides=overrides)
            for line in heldout.summary_lines(results):
                print(line)
            for warning in results["warnings"]:  # as the plain run says them
                print(f"asnn eval: {warning}", file=sys.stderr)
            print(f"{args.out}/held_out.md")
            return 0
        else:
            _say_unlabelled(args.clips_dir, labels)
            results = clips.evaluate_clips(
                args.clips_dir, args.out, labels_path=args.labels, detectors=args.detectors,
                preset_name=preset_name, early_tolerance_s=tolerance,
                warmup=warmup, jobs=args.jobs, plots=not args.no_plots,
                perturbation=args.perturb, progress=progress)
            for name, entry in results["detectors"].items():
                print(_summary_line(name, entry["summary"]))
            for warning in results["warnings"]:  # also in report.md, but easy to miss there
                print(f"asnn eval: {warning}", file=sys.stderr)
            if results["errors"]:
                print(f"{args.out}/report.md")
                print(f"asnn eval: {len(results['errors'])} of the runs failed, their clips "
                      "scored as missing (the report's errors name them)", file=sys.stderr)
                return 1
    except BrokenPipeError:  # stdout's reader went away: cli.main handles it
        raise
    except (OSError, ValueError) as exc:
        print(f"asnn eval: {exc}", file=sys.stderr)
        return 2
    print(f"{args.out}/report.md")
    return 0
