"""``asnn detect VIDEO``: offline detection on a video file (CONTRACT.md)."""

from __future__ import annotations

import argparse
import json
import sys
from contextlib import ExitStack
from pathlib import Path

import cv2

from asnn.detectors import MODELS, make_detector
from asnn.params import preset_names
from asnn.evaluation.progress import ProgressPrinter
from asnn.io.video import VideoError, open_video
from asnn.io.visualize import annotate_frame, plot_responses


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("detect", help="offline detection on a video file",
                       description="Run a detector over a video file; one JSON object per frame.")
    p.add_argument("video", metavar="VIDEO", help="any video OpenCV reads")
    p.add_argument("--model", choices=MODELS, default="asnn")
    p.add_argument("--preset", choices=preset_names(), default="default",
                   help="ASNN parameter preset (default: %(default)s)")
    p.add_argument("--jsonl", metavar="PATH|-", help="write one JSON object per frame ('-': stdout)")
    p.add_argument("--annotate", metavar="OUT.mp4", help="write the input with overlays")
    p.add_argument("--plot", metavar="OUT.png", help="plot u(t) and the spike rate")
    p.set_defaults(func=run)


def _record(index: int, fps: float, response) -> dict:
    return {"frame": index, "t": round(index / fps, 6), **response.to_dict()}


def run(args: argparse.Namespace) -> int:
    try:
        clip = open_video(args.video)
    except VideoError as exc:
        print(f"asnn detect: {exc}", file=sys.stderr)
        return 2
    detector = make_detector(args.model, args.preset,
                             **({"record_maps": True} if args.annotate and args.model == "asnn" else {}))
    records = []
    with ExitStack() as stack:
        jsonl = None
        if args.jsonl == "-":
            jsonl = sys.stdout
        elif args.jsonl:
            jsonl = stack.enter_context(open(args.jsonl, "w", encoding="utf-8"))
        writer = None
        progress = ProgressPrinter()
        progress.start(clip.frame_count, "detect")
        stack.callback(progress.finish)
        for index, frame in enumerate(clip):
            response = detector.step(frame)
            record = _record(index, clip.fps, response)
            records.append(record)
            if jsonl is not None:
                jsonl.write(json.dumps(record) + "\n")
            if args.annotate:
                if writer is None:
                    writer = cv2.VideoWriter(args.annotate, cv2.VideoWriter_fourcc(*"mp4v"),
                                             clip.fps, (clip.width, clip.height))
                    if not writer.isOpened():
                        print(f"asnn detect: cannot write {args.annotate}", file=sys.stderr)
                        return 2
                    stack.callback(writer.release)
                writer.write(annotate_frame(frame, response))
            progress.advance()
    if not records:
        print(f"asnn detect: {args.video}: no frames decoded", file=sys.stderr)
        return 2
    if args.plot:
        plot_responses([r["t"] for r in records], [r["u"] for r in records],
                       [r["spike_rate"] for r in records], [r["collision"] for r in records],
                       args.plot, title=f"{Path(args.video).name} ({args.model}, {args.preset})")
    warned = sum(r["collision"] for r in records)
    print(f"asnn detect: {len(records)} frames, {warned} with a collision warning",
          file=sys.stderr)
    return 0
