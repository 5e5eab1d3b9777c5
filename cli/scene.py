"""``asnn scene NAME OUT``: write one of the paper's generated scenes as a video file or a
ROS 2 bag."""

from __future__ import annotations

import argparse
import json
import sys

from asnn.stimuli import SCENE_NAMES, make_scene, write_video

from .arguments import frame_size


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("scene", help="write a generated test scene as a video file",
                       description="Generate one of the paper's synthetic scenes (asnn.stimuli).")
    p.add_argument("name", choices=SCENE_NAMES)
    p.add_argument("out", metavar="OUT",
                   help="video file to write (.mp4 or .avi), or a ROS 2 bag (.mcap: "
                        "sensor_msgs/msg/Image mono8 on /camera/image_raw; the 'ros' extra)")
    p.add_argument("--size", type=frame_size, default=(128, 128), metavar="WxH")
    p.add_argument("--polarity", choices=("dark", "light"), default="dark")
    p.add_argument("--contrast", type=float, default=1.0)
    p.add_argument("--speed", type=float, help="edge speed, px/frame")
    p.add_argument("--fps", type=float, default=20.0)
    p.add_argument("--labels", metavar="FILE", help="also write a labels.json for asnn eval")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        scene = make_scene(args.name, size=args.size, polarity=args.polarity,
                           contrast=args.contrast, speed=args.speed, fps=args.fps)
        if args.out.lower().endswith(".mcap"):
            from asnn.io.rosbag import write_bag

            write_bag(scene.frames, args.out, fps=args.fps)
        else:
            write_video(scene.frames, args.out, fps=args.fps)
    except (ValueError, OSError, ImportError) as exc:
        print(f"asnn scene: {exc}", file=sys.stderr)
        return 2
    if args.labels:
        with open(args.labels, "w", encoding="utf-8") as fh:
            json.dump([scene.label(args.out)], fh, indent=1)
    print(f"asnn scene: wrote {len(scene.frames)} frames to {args.out}", file=sys.stderr)
    return 0
