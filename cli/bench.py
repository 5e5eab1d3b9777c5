"""``asnn bench``: per-frame cost of every model and preset, one thread (see :mod:`asnn.evaluation.bench`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from asnn.detectors import MODELS
from cli.arguments import (Joined, cameras, clips_problem, count, frame_rate, frame_size, frames,
                           nonempty_path, preset_spec, processes, seconds, seed, threads)

# how the benches that time whole processes run asnn: this interpreter and the very packages
# this process runs (-P and the path given: ``-m cli.main`` put the working folder first on the
# children's path, and a checkout of another version there was timed in their place)
_PACKAGES = str(Path(__file__).resolve().parent.parent)
ASNN_COMMAND = (sys.executable, "-P", "-c",
                f"import sys; sys.path.insert(0, {_PACKAGES!r}); from cli.main import main; "
                "sys.exit(main())")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench", help="time the models per frame (one thread)",
        description="Median and p90 cost per frame of every model and ASNN preset on a generated "
        "scene, one thread, with the straightforward float64 form of the default preset as a "
        "ratio. --service instead measures cameras through Zenoh on loopback.")
    p.add_argument("--size", type=frame_size, action="append", metavar="WxH",
                   help="frame size (repeatable; default 128x128, 320x240 and 640x480)")
    p.add_argument("--frames", type=frames, default=None,
                   help="timed frames per run (default 40; --detect: frames of the clip, 1200; "
                        "at most 10000)")
    p.add_argument("--preset", action="append", type=preset_spec, metavar="NAME[/FIELD=VALUE...]",
                   help="ASNN preset to time (repeatable; default: all), per frame with fields "
                   "changed after slashes as asnn eval's specs (robust/top_k=0: a stage's cost "
                   "as the difference of two rows of one run); the default preset is "
                        "added for the straightforward form's ratio (unless "
                        "--no-straightforward), and with it reference32, its cost's reference")
    p.add_argument("--model", action="append", choices=MODELS,
                   help="model to time (repeatable; default: all, the LGMDs too)")
    p.add_argument("--no-straightforward", action="store_true",
                   help="skip the straightforward float64 form")
    p.add_argument("--json", action="store_true", help="print the report as JSON on stdout")
    p.add_argument("--service", action="store_true",
                   help="cameras at --fps through one worker process over Zenoh on loopback, "
                   "ramping the number of cameras (first --size, default 320x240; first --preset, "
                   "default the default preset)")
    # the options of one kind of bench default to None, their value set in run(): one given
    # to another kind is then told from one not given (_misplaced), whatever its value
    p.add_argument("--fps", type=frame_rate, default=None,
                   help=f"camera rate for --service (default: {MODE_DEFAULTS['fps']:g})")
    p.add_argument("--seconds", type=seconds, default=None,
                   help=f"duration of each --service step (default: "
                        f"{MODE_DEFAULTS['seconds']:g})")
    p.add_argument("--cameras", type=cameras, action="append", metavar="N",
                   help="camera counts for --service, at most 256 (repeatable; default 1, 2, 4, "
                        "8, 12, 16, 20, 24)")
    p.add_argument("--phases", choices=("spread", "random"), default=None,
                   help="when each --service camera publishes within a frame period: evenly "
                        f"spread, or at random (default: {MODE_DEFAULTS['phases']})")
    p.add_argument("--seed", type=seed, default=None,
                   help=f"seed of --phases random (default: {MODE_DEFAULTS['seed']})")
    p.add_argument("--case", metavar="NAME", default=None,
                   help="time on this case of the labelled suite (asnn scene --list), at its own "
                   "size and length, instead of the generated scene: e.g. a drive, where the "
                   "stages that act only under the camera's own forward motion have work")
    p.add_argument("--detect", action="store_true",
                   help="instead, the whole asnn detect process per frame (start-up excluded) "
                   "and its stages, against the straightforward float64 form (--size, default "
                   "320x240 and 640x480; first --preset)")
    p.add_argument("--repeat", type=count, default=None, metavar="N",
                   help="--detect: runs of asnn detect per clip (default: 4); otherwise: times "
                   "the default preset is stepped in turn with reference32, the ratio's median "
                   "and range reported (default: 1)")
    p.add_argument("--handover", action="store_true",
                   help="instead, how many frames a worker taking a robot over needs before it "
                   "warns as the previous owner would (the worker's --warmup-frames), over the "
                   "labelled suite (first --preset)")
    p.add_argument("--every", type=count, default=None, metavar="N",
                   help=f"--handover: try a hand-over every N frames (default: "
                        f"{MODE_DEFAULTS['every']})")
    p.add_argument("--cases", metavar="PATTERN", default=None, action=Joined,
                   help="--handover: suite cases or groups, comma-separated shell patterns "
                        "(repeatable: the uses add up; default: all)")
    p.add_argument("--clips", type=nonempty_path, metavar="DIR", default=None,
                   help="--handover: over the labelled clips of DIR (its labels.json, as asnn "
                        "eval reads them) instead of the suite, e.g. ../shared/data/real")
    p.add_argument("--looms", type=frame_rate, default=None, metavar="FPS",
                   help="--handover: over the 24 constant-speed approaches of asnn eval --ttc "
                        "at FPS frames a second instead of the suite (which is 20 fps): a "
                        "camera faster than 36 fps has frames held by the default's frame-rate "
                        "ceiling, and the warm-up counts the frames stepped")
    p.add_argument("--worker-threads", type=threads, default=None, metavar="N",
                   help="processing threads of each --service worker (asnn worker --threads; "
                        "default: the cores available, divided among the workers)")
    p.add_argument("--workers", type=processes, default=None, metavar="N",
                   help="--service: worker processes sharing the cameras, at most 64 "
                        f"(default: {MODE_DEFAULTS['workers']})")
    p.add_argument("--router", action="store_true",
                   help="--service: connect through an asnn router process even with one "
                        "worker (with several there always is one)")
    p.set_defaults(func=run, parser=p)


# the values of the options of one kind of bench that default to None (register)
MODE_DEFAULTS = {"fps": 25.0, "seconds": 4.0, "phases": "spread", "seed": 0, "workers": 1,
                 "every": 3}
# the options of one kind of bench (None: the per-frame one), by their parser's dest: given to
# another, they were ignored without a word
_MODE_OPTIONS = {
    "fps": ("--service",), "seconds": ("--service",), "cameras": ("--service",),
    "phases": ("--service",), "seed": ("--service",), "worker_threads": ("--service",),
    "workers": ("--service",), "router": ("--service",),
    "every": ("--handover",), "cases": ("--handover",), "clips": ("--handover",),
    "looms": ("--handover",),
    "no_straightforward": (None,), "frames": (None, "--detect"),
    "size": (None, "--detect", "--service"),
}


def _misplaced(args: argparse.Namespace, mode: str | None) -> list[str]:
    """The options given that the bench ``mode`` does not use (those set to other than their
    parser's default, which is None or False for each of another kind's)."""
    return ["--" + dest.replace("_", "-") for dest, modes in _MODE_OPTIONS.items()
            if mode not in modes and getattr(args, dest) != args.parser.get_default(dest)]


def run(args: argparse.Namespace) -> int:
    from asnn.evaluation.bench import pin_threads

    # asnn detect uses the cores: its bench leaves the threads alone
    pinning = "as asnn detect: not pinned" if args.detect else pin_threads()
    from asnn.evaluation import bench

    name = "asnn bench --service" if args.service else "asnn bench"
    try:
        if args.case is not None and (args.detect or args.handover or args.service):
            raise ValueError("--case times the models per frame only: not with --detect, "
                             "--handover or --service")
        if (args.detect or args.service) and any("/" in name for name in args.preset or ()):
            raise ValueError("--preset with changed fields is timed per frame (or with "
                             "--handover): --detect and --service take a preset's name")
        modes = [flag for flag in ("--detect", "--handover", "--service")
                 if getattr(args, flag[2:])]
        if len(modes) > 1:  # each would run alone, the others' options ignored
            raise ValueError(f"{' and '.join(modes)}: one bench at a time")
        misplaced = _misplaced(args, modes[0] if modes else None)
        if misplaced:
            raise ValueError(f"{', '.join(misplaced)} "
                             f"{'does' if len(misplaced) == 1 else 'do'} not go with "
                             f"{modes[0] if modes else 'the per-frame bench'} (see asnn bench -h)")
        for dest, value in MODE_DEFAULTS.items():  # what was not given
            if getattr(args, dest) is None:
                setattr(args, dest, value)
        if modes and args.model and set(args.model) != {"asnn"}:
            raise ValueError(f"{modes[0]} times the ASNN model: --model does not apply")
        if args.service:
            from service.bench import START_S

            if args.seconds < START_S + 1.0:  # the start is left out of each step's figures
                raise ValueError(f"--seconds must be at least {START_S + 1.0:g} with --service "
                                 f"(the first {START_S:g} s of each step are its start-up, "
                                 "not timed)")
        if args.repeat is not None and (args.handover or args.service):
            raise ValueError("--repeat repeats the per-frame comparison or --detect's runs: "
                             "not with --handover or --service")
        if args.detect:
            from asnn.evaluation import bench_detect

            report = bench_detect.run(ASNN_COMMAND, sizes=args.size or list(bench_detect.DEFAULT_SIZES),
                                      frames=args.frames or bench_detect.DEFAULT_FRAMES,
                                      repeat=args.repeat or 4,
                                      preset=args.preset[0] if args.preset else None,
                                      progress=_progress())
        elif args.handover:
            from asnn.evaluation import handover

            # said as asnn eval says it, not as an OSError's repr (with --cases or --looms
            # too, handover.run says the sources conflict)
            if args.clips is not None and args.cases is None and args.looms is None:
                problem = clips_problem(args.clips)
                if problem:
                    raise ValueError(f"--clips {args.clips}: {problem[1]}")
            preset = args.preset[0] if args.preset else None
            report = handover.run(f"asnn:{preset}" if preset else "asnn", cases=args.cases,
                                  every=args.every, progress=_progress(), clips_dir=args.clips,
                                  looms=args.looms)
        elif args.service:
            from service import bench as service_bench

            report = service_bench.run(ASNN_COMMAND, size=args.size[0] if args.size else (320, 240),
                                       fps=args.fps, seconds=args.seconds, counts=args.cameras,
                                       preset=args.preset[0] if args.preset else None,
                                       progress=_progress(),
                                       worker_threads=args.worker_threads,
                                       phases=args.phases, seed=args.seed,
                                       workers=args.workers, router=args.router or None)
        else:
            if args.case is not None and (args.size or args.frames):
                raise ValueError("--case times the case at its own size and length: "
                                 "leave out --size and --frames")
            report = bench.run(sizes=args.size or list(bench.DEFAULT_SIZES),
                               frames=args.frames or 40,
                               presets=args.preset,
                               models=tuple(args.model or MODELS),
                               straightforward=not args.no_straightforward,
                               progress=_progress(), case=args.case,
                               repeat=args.repeat or 1)
    except (RuntimeError, ValueError, OSError) as exc:  # OSError: a clip that fails as read
        print(f"{name}: {exc}", file=sys.stderr)
        return 2
    report["threads"] = pinning
    report["machine"] = bench.machine()
    if args.json:
        print(json.dumps(report, indent=1))
    elif args.detect:
        m = report["machine"]
        print(f"# asnn bench --detect: {m['cpu']}, {m['cores']} logical cores; scene "
              f"{report['scene']}, preset {report['preset']}; ms per frame; asnn detect as its "
              "own process, start-up excluded; stages of one loop in this process; model "
              "stream: the model alone with a thread per core; baseline "
              f"{report['baseline']}")
        print(bench_detect.format_table(report))
    elif args.handover:
        from service.core import HANDOVER_WARMUP_FRAMES

        print(handover.format_report(report, HANDOVER_WARMUP_FRAMES))
    elif args.service:
        print(f"# threads of the process that plays the cameras: {pinning}")
        print(service_bench.format_report(report))
    else:
        m = report["machine"]
        print(f"# asnn bench: {m['cpu']}, {m['cores']} logical cores; Python {m['python']}, "
              f"NumPy {m['numpy']}, OpenCV {m['opencv']}, numba {m['numba']}")
        print(f"# threads: {pinning}")
        print(f"# scene {report['scene']}, {report['frames']} timed frames after "
              f"{report['warmup']} warm-up frames, targets included")
        print(bench.format_table(report))
    return 0


def _progress():
    if not sys.stderr.isatty():
        return None
    return lambda text: print(f"\r\033[Kbench: {text}", end="", file=sys.stderr, flush=True)
