"""``asnn scene``: write a generated scene as a video file or a ROS 2 bag.

``asnn scene NAME OUT`` writes one of the paper's scenes; ``asnn scene --case CASE OUT`` one case of
the labelled suite (:mod:`asnn.stimuli.suite`); ``asnn scene --list [PATTERN]`` lists the suite's
cases with their groups. ``OUT`` ending in ``.mcap`` writes a ROS 2 bag instead of a video.
"""

from __future__ import annotations

import argparse
import json
import sys

from asnn.stimuli import SCENE_NAMES, make_scene, write_video
from asnn.stimuli.suite import CASES, make_case, suite_cases

from .arguments import frame_size, whole


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("scene", help="write a generated test scene as a video file",
                       description="Generate one of the paper's synthetic scenes, or a case of "
                                   "the labelled suite (--case), as a video file.")
    p.add_argument("args", nargs="*", metavar="[NAME] OUT",
                   help=f"a paper scene ({', '.join(SCENE_NAMES)}) and the file to write: a "
                        "video (.mp4 or .avi) or a ROS 2 bag (.mcap: sensor_msgs/msg/Image mono8 "
                        "on /camera/image_raw; the 'ros' extra); with --case only OUT")
    p.add_argument("--case", metavar="CASE", help="a case of the labelled suite instead")
    p.add_argument("--variant", type=whole, default=0, metavar="K",
                   help="with --case: the case with a fresh scene seed K >= 1 (asnn eval "
                        "--synthetic --variant K; default: 0, the case as the suite has it)")
    p.add_argument("--scale", type=float, metavar="S",
                   help="with --case: the case drawn with S times its pixels (0.5-8; asnn eval "
                        "--synthetic --scale S; default: 1)")
    p.add_argument("--list", nargs="?", const="all", metavar="PATTERN",
                   help="list the suite's cases (matching PATTERN; 'extra-*' lists the extra "
                        "drives outside it) and exit")
    p.add_argument("--size", type=frame_size, default=(128, 128), metavar="WxH",
                   help="paper scenes only (default: 128x128)")
    p.add_argument("--polarity", choices=("dark", "light"), default="dark",
                   help="paper scenes only")
    p.add_argument("--contrast", type=float, default=1.0, help="paper scenes only")
    p.add_argument("--speed", type=float, help="paper scenes only: edge speed, px/frame")
    p.add_argument("--fps", type=float, default=20.0, help="paper scenes only")
    p.add_argument("--labels", metavar="FILE", help="also write a labels.json for asnn eval")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        if args.list is not None:
            for name in suite_cases(args.list):
                case = CASES[name]
                print(f"{name}\t{' '.join(case.category)}")
            return 0
        if args.case is not None:
            if len(args.args) != 1:
                print("asnn scene: --case takes one OUT file", file=sys.stderr)
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
            scene = make_scene(name, size=args.size, polarity=args.polarity,
                               contrast=args.contrast, speed=args.speed, fps=args.fps)
        if out.lower().endswith(".mcap"):
            from asnn.io.rosbag import write_bag

            write_bag(scene.frames, out, fps=scene.fps)
        else:
            write_video(scene.frames, out, fps=scene.fps)
    except BrokenPipeError:  # stdout's reader went away: cli.main handles it
        raise
    except (ValueError, OSError, ImportError) as exc:
        print(f"asnn scene: {exc}", file=sys.stderr)
        return 2
    if args.labels:
        with open(args.labels, "w", encoding="utf-8") as fh:
            json.dump([scene.label(out)], fh, indent=1)
    print(f"asnn scene: wrote {len(scene.frames)} frames to {out}", file=sys.stderr)
    return 0
