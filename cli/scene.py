"""``asnn scene``: write a generated scene as a video file or a ROS 2 bag.

``asnn scene NAME OUT`` writes one of the paper's scenes; ``asnn scene --case CASE OUT`` one case of
the labelled suite (:mod:`asnn.stimuli.suite`); ``asnn scene --list [PATTERN]`` lists the suite's
cases with their groups. ``OUT`` ending in ``.mcap`` writes a ROS 2 bag instead of a video.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from asnn.io.files import folder_lock, output_problem, path_problem
from asnn.io.rates import FPS_RANGE
from asnn.stimuli import SCENE_NAMES, make_scene

from .arguments import contrast, edge_speed, finite, frame_rate, frame_size, nonempty_path, whole


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("scene", help="write a generated test scene as a video file or a bag",
                       description="Generate one of the paper's synthetic scenes, or a case of "
                                   "the labelled suite (--case), as a video file or a ROS 2 "
                                   "bag. Options may come before, between or after NAME and "
                                   "OUT.")
    p.add_argument("args", nargs="*", type=nonempty_path, metavar="[NAME] OUT",
                   help=f"a paper scene ({', '.join(SCENE_NAMES)}) and the file to write: a "
                        "video (.mp4, .avi, .mkv, .mov or .m4v) or a ROS 2 bag (.mcap: sensor_msgs/msg/Image mono8 "
                        "on /camera/image_raw; the 'ros' extra); with --case only OUT. Its "
                        "folder is made where it is missing")
    p.add_argument("--case", metavar="CASE", help="a case of the labelled suite instead")
    p.add_argument("--variant", type=whole, default=0, metavar="K",
                   help="with --case: the case with a fresh scene seed K >= 1 (asnn eval "
                        "--synthetic --variant K; default: 0, the case as the suite has it)")
    p.add_argument("--scale", type=finite, metavar="S",
                   help="with --case: the case drawn with S times its pixels (0.5-8; asnn eval "
                        "--synthetic --scale S; default: 1)")
    p.add_argument("--list", nargs="?", const="all", metavar="PATTERN",
                   help="list the suite's cases (matching PATTERN; 'extra-*' lists the extra "
                        "drives outside it) and exit")
    for flag, options, default, what in _PAPER_OPTIONS:
        p.add_argument(flag, **options, help=f"paper scenes only: {what} (default: {default})")
    p.add_argument("--labels", type=nonempty_path, metavar="FILE",
                   help="also enter the clip's label in FILE, a labels.json for asnn eval: added, "
                        "or replacing the entry of the same file, named relative to FILE's folder "
                        "(OUT must be in that folder or below it)")
    p.set_defaults(func=run, intermixed=True)


# options of the paper's scenes, unset (None) unless given: (flag, argparse options, default,
# what); a suite case has its own
_PAPER_OPTIONS = (
    ("--size", {"type": frame_size, "metavar": "WxH"}, "128x128", "frame size"),
    ("--polarity", {"choices": ("dark", "light")}, "dark",
     "dark (the object darker than its ground) or light"),
    ("--contrast", {"type": contrast}, 1.0, "Weber contrast, more than 0 and at most 1"),
    ("--speed", {"type": edge_speed}, "the scene's own", "edge speed, px/frame, at most 1024"),
    ("--fps", {"type": frame_rate}, 20.0, f"frame rate, {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g}"))


def run(args: argparse.Namespace) -> int:
    from asnn.io.video import WRITABLE_SUFFIXES, write_video  # OpenCV: when it runs
    from asnn.stimuli.suite import CASES, make_case, suite_cases

    try:
        if args.list is not None:
            given = [flag for flag, value in (("--case", args.case), ("NAME/OUT", args.args),
                                              ("--variant", args.variant),
                                              ("--scale", args.scale), ("--labels", args.labels))
                     if value] + [flag for flag, *_ in _PAPER_OPTIONS
                                  if getattr(args, flag[2:]) is not None]
            if given:
                print(f"asnn scene: --list lists the suite's cases and exits; not with "
                      f"{', '.join(given)}", file=sys.stderr)
                return 2
            for name in suite_cases(args.list):
                case = CASES[name]
                print(f"{name}\t{' '.join(case.category)}")
            return 0
        if args.case is not None:
            if len(args.args) != 1:
                print("asnn scene: --case takes one OUT file", file=sys.stderr)
                return 2
            given = [flag for flag, *_ in _PAPER_OPTIONS if getattr(args, flag[2:]) is not None]
            if given:
                print(f"asnn scene: {', '.join(given)} set a paper scene; a suite case has its "
                      "own (--scale draws it larger)", file=sys.stderr)
                return 2
            out = args.args[0]
            scene = make_case(args.case, args.variant, scale=args.scale)
        else:
            if args.variant or args.scale is not None:
                print("asnn scene: --variant and --scale go with --case", file=sys.stderr)
                return 2
            if len(args.args) != 2:
                print("asnn scene: give NAME OUT, or --case CASE OUT", file=sys.stderr)
                return 2
            name, out = args.args
            if name not in SCENE_NAMES:
                print(f"asnn scene: unknown scene {name!r}; choose one of "
                      f"{', '.join(SCENE_NAMES)} (or --case for the suite)", file=sys.stderr)
                return 2
            given = {flag[2:]: getattr(args, flag[2:]) for flag, *_ in _PAPER_OPTIONS}
            scene = make_scene(name, **{k: v for k, v in given.items() if v is not None})
        if Path(out).suffix.lower() not in (*WRITABLE_SUFFIXES, ".mcap"):  # before drawing
            raise ValueError(f"{out}: name the format by its extension: a video "
                             f"({', '.join(WRITABLE_SUFFIXES)}) or a bag (.mcap)")
        problem = output_problem(out)
        if problem:  # said as the other commands say theirs, not as a bare errno at the write
            raise ValueError(f"{out}: {problem}")
        if args.labels:  # a labels file that cannot take the clip stops the command first
            _check_labels_file(Path(args.labels), Path(out))
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        if out.lower().endswith(".mcap"):
            from asnn.io.rosbag import write_bag

            write_bag(scene.frames, out, fps=scene.fps)
        else:
            write_video(scene.frames, out, fps=scene.fps)
        if args.labels:
            _enter_label(Path(args.labels), Path(out), scene)
    except BrokenPipeError:  # stdout's reader went away: cli.main handles it
        raise
    except (ValueError, OSError, ImportError) as exc:
        print(f"asnn scene: {exc}", file=sys.stderr)
        return 2
    print(f"asnn scene: wrote {len(scene.frames)} frames to {out}", file=sys.stderr)
    return 0


def _label_name(labels: Path, out: Path) -> str:
    """The clip's ``file`` in ``labels``: its path relative to the labels' folder."""
    # the folder of the labels path as given, not of a link's target: asnn label and asnn
    # eval read the names relative to the folder the file is found in
    return Path(os.path.relpath(os.path.abspath(out), os.path.abspath(labels.parent))).as_posix()


def _check_labels_file(labels: Path, out: Path) -> None:
    """Check, before the clip is written, that ``labels`` can take it (read where it exists:
    :func:`_enter_label` reads it again when it enters the clip), so that a labels file that
    cannot stops the command first.

    Raises
    ------
    ValueError
        If the clip is not in the labels' folder or below it (``asnn eval CLIPS_DIR`` and
        ``asnn label`` read a labels file's names relative to CLIPS_DIR, the labels' folder
        when it is ``CLIPS_DIR/labels.json``), or the file is not a labels file.
    OSError
        If it cannot be read.
    """
    problem = path_problem(labels)
    if problem:
        raise ValueError(f"--labels {labels}: {problem}")
    if labels.is_dir():
        raise ValueError(f"--labels {labels}: a folder; give the labels file "
                         f"({labels / 'labels.json'})")
    if _label_name(labels, out).startswith("../"):
        raise ValueError(f"{out} is not in the folder of {labels} or below it: asnn eval and "
                         "asnn label read the names in a labels file relative to the clips' "
                         "folder, so keep the labels beside their clips")
    if labels.exists():
        from asnn.evaluation.labels import read_entries

        read_entries(labels)


def _enter_label(labels: Path, out: Path, scene) -> None:
    """Enter the clip's label in ``labels`` (a labels.json, made where it is missing): its
    ``file`` named relative to the labels' folder, as ``asnn eval`` reads it, replacing an
    entry of the same file and keeping the others, so that one call per clip builds a
    folder's labels. The file is read again under a lock on its folder and replaced whole
    (:func:`asnn.evaluation.labels.write_entries`): scenes drawn at once for one labels file
    keep each other's entries, and a process killed while it writes leaves the old file."""
    from asnn.evaluation.labels import read_entries, write_entries

    file = _label_name(labels, out)
    labels.parent.mkdir(parents=True, exist_ok=True)
    with folder_lock(labels):
        entries = read_entries(labels) if labels.exists() else []
        entries = [e for e in entries  # ./clip.mp4 names the same clip as clip.mp4
                   if not (isinstance(e, dict) and isinstance(e.get("file"), str)
                           and os.path.normpath(e["file"]) == os.path.normpath(file))]
        write_entries(labels, entries + [scene.label(file)], indent=1)
