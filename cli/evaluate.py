"""``asnn eval``: the paper's comparisons as numbers and figures.

``asnn eval CLIPS_DIR [--labels FILE] [--models asnn,lgmd1,lgmd2] [--preset P] [--out DIR]``
scores every model on labelled clips (SPEC.md section 5); ``asnn eval --synthetic --out DIR``
regenerates the paper's synthetic experiments. Exit status 2 for unusable input.
"""

from __future__ import annotations

import argparse
import sys

from asnn.evaluation import scoring
from asnn.detectors import MODELS
from asnn.params import preset_names
from asnn.evaluation.progress import ProgressPrinter

from .arguments import frame_size


def _models(text: str) -> list[str]:
    models = [m.strip() for m in text.split(",") if m.strip()]
    unknown = [m for m in models if m not in MODELS]
    if not models or unknown:
        raise argparse.ArgumentTypeError(
            f"expected a comma-separated subset of {','.join(MODELS)}, got {text!r}")
    return list(dict.fromkeys(models))


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "eval", help="score the models on labelled clips, or rerun the synthetic experiments",
        description="Run ASNN and the LGMD baselines over labelled clips and score them "
                    "(hit / early / late / miss, false alarms, lead time, localisation), or "
                    "regenerate the paper's synthetic figures with --synthetic.")
    p.add_argument("clips_dir", nargs="?", metavar="CLIPS_DIR",
                   help="directory of the clips (not with --synthetic)")
    p.add_argument("--labels", metavar="FILE", help="labels file (default: CLIPS_DIR/labels.json)")
    p.add_argument("--models", type=_models, default=list(MODELS), metavar="LIST",
                   help="comma-separated models (default: %(default)s)")
    p.add_argument("--preset", choices=preset_names(), default="default",
                   help="ASNN parameter preset (default: %(default)s)")
    p.add_argument("--out", metavar="DIR", default="eval-out",
                   help="output directory (default: %(default)s)")
    p.add_argument("--synthetic", action="store_true",
                   help="regenerate the synthetic experiments (Figs. 2, 4-7) instead")
    p.add_argument("--early-tolerance", type=float, default=scoring.EARLY_TOLERANCE_S,
                   metavar="SECONDS",
                   help="a first warning up to this long before the labelled onset still counts "
                        "as a hit (default: %(default)s, for onsets judged by eye; use 0 for "
                        "generated clips)")
    p.add_argument("--warmup", type=int, default=scoring.WARMUP_FRAMES, metavar="FRAMES",
                   help="frames ignored at the start of each clip (default: %(default)s)")
    p.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="clips evaluated in parallel processes (default: %(default)s)")
    p.add_argument("--size", type=frame_size, default=(128, 128), metavar="WxH",
                   help="frame size of the synthetic scenes (default: 128x128, the paper's)")
    p.add_argument("--no-plots", action="store_true", help="skip the per-clip PNGs")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from asnn.evaluation import clips, paper  # import matplotlib: only when the command runs

    progress = ProgressPrinter(sys.stderr)
    if args.synthetic:
        if args.clips_dir:
            print("asnn eval: give either CLIPS_DIR or --synthetic", file=sys.stderr)
            return 2
        paper.synthetic_suite(args.out, preset_name=args.preset, models=args.models,
                                   size=args.size, warmup=args.warmup, progress=progress)
        print(f"{args.out}/report.md")
        return 0
    if not args.clips_dir:
        print("asnn eval: CLIPS_DIR is required (or --synthetic)", file=sys.stderr)
        return 2
    if args.early_tolerance < 0 or args.warmup < 0 or args.jobs < 1:
        print("asnn eval: --early-tolerance and --warmup must be >= 0, --jobs >= 1",
              file=sys.stderr)
        return 2
    try:
        results = clips.evaluate_clips(
            args.clips_dir, args.out, labels_path=args.labels, models=args.models,
            preset_name=args.preset, early_tolerance_s=args.early_tolerance,
            warmup=args.warmup, jobs=args.jobs, plots=not args.no_plots, progress=progress)
    except (OSError, ValueError) as exc:
        print(f"asnn eval: {exc}", file=sys.stderr)
        return 2
    print(f"{args.out}/report.md")
    return 2 if results["errors"] and len(results["errors"]) == sum(
        len(m["clips"]) for m in results["models"].values()) else 0
