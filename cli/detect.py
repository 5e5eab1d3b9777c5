"""``asnn detect VIDEO``: offline detection on a video file or a ROS 2 bag (CONTRACT.md)."""

from __future__ import annotations

import argparse
import json
import sys
from contextlib import ExitStack
from pathlib import Path

import cv2

from asnn import FrameError
from asnn.detectors import MODELS, make_detector
from asnn.params import preset_names
from asnn.evaluation.progress import ProgressPrinter
from asnn.io.pipeline import WriteBehind, read_ahead
from asnn.io.sources import SourceError, open_source
from asnn.io.visualize import annotate_frame, plot_responses


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("detect", help="offline detection on a video file or a ROS 2 bag",
                       description="Run a detector over a video file or an image topic of a "
                                   "ROS 2 bag (MCAP); one JSON object per frame.")
    p.add_argument("video", metavar="VIDEO",
                   help="any video OpenCV reads, or a ROS 2 bag: BAG.mcap[#TOPIC] (the 'ros' "
                        "extra)")
    p.add_argument("--topic", metavar="NAME",
                   help="image topic of a bag (sensor_msgs/msg/Image or CompressedImage); "
                        "needed when it has several")
    p.add_argument("--model", choices=MODELS, default="asnn")
    p.add_argument("--preset", choices=preset_names(), default="default",
                   help="ASNN parameter preset (default: %(default)s)")
    p.add_argument("--jsonl", metavar="PATH|-", help="write one JSON object per frame ('-': stdout)")
    p.add_argument("--annotate", metavar="OUT.mp4", help="write the input with overlays")
    p.add_argument("--plot", metavar="OUT.png", help="plot u(t) and the spike rate")
    p.add_argument("--mcap", metavar="OUT.mcap",
                   help="write the frames, targets, warnings and response numbers as an MCAP "
                        "for Foxglove (docs/foxglove.md; the 'ros' extra)")
    p.set_defaults(func=run)


def _record(index: int, t: float, response) -> dict:
    return {"frame": index, "t": round(t, 6), **response.to_dict()}


def _fail(message: str) -> int:
    print(f"asnn detect: {message}", file=sys.stderr)
    return 2


class _OutputError(Exception):
    """An output that cannot be written (the message names it)."""


READ_AHEAD = 8  # decoded frames waiting for the model
WRITE_BEHIND = 4  # responses waiting to be written (with --annotate each holds its maps)


def run(args: argparse.Namespace) -> int:
    """Decode ahead and write behind on threads of their own while the model steps on this one
    (:mod:`asnn.io.pipeline`): the output is that of one loop, in frame order."""
    try:
        source = open_source(args.video, topic=args.topic)
    except SourceError as exc:
        return _fail(str(exc))
    detector = make_detector(args.model, args.preset,
                             **({"record_maps": True} if args.annotate and args.model == "asnn" else {}))
    records = []
    with ExitStack() as stack:
        jsonl = None
        if args.jsonl == "-":
            jsonl = sys.stdout
        elif args.jsonl:
            jsonl = stack.enter_context(open(args.jsonl, "w", encoding="utf-8"))
        mcap = None
        if args.mcap:
            try:
                from asnn.io.foxglove_mcap import FoxgloveMcapWriter

                mcap = stack.enter_context(FoxgloveMcapWriter(args.mcap,
                                                              frame_id=source.frame_id))
            except (ImportError, OSError) as exc:
                return _fail(str(exc))
        progress = ProgressPrinter()
        progress.start(source.frame_count, "detect")
        stack.callback(progress.finish)
        video = []  # the annotated video's writer, opened with the first frame

        def write(item) -> None:
            index, t, frame, response = item
            record = _record(index, t, response)
            records.append(record)
            if jsonl is not None:
                jsonl.write(json.dumps(record) + "\n")
            if mcap is not None:
                mcap.write(frame, record, (source.start_ns or 0) + round(t * 1e9))
            if args.annotate:
                if not video:
                    writer = cv2.VideoWriter(args.annotate, cv2.VideoWriter_fourcc(*"mp4v"),
                                             source.fps, frame.shape[1::-1])
                    if not writer.isOpened():
                        raise _OutputError(f"cannot write {args.annotate}")
                    stack.callback(writer.release)
                    video.append(writer)
                video[0].write(annotate_frame(frame, response))
            progress.advance()

        output = WriteBehind(write, depth=WRITE_BEHIND)
        failure = None
        index = 0
        try:
            for t, frame in read_ahead(source.timed_frames(), depth=READ_AHEAD):
                try:
                    response = detector.step(frame, t)
                except FrameError as exc:  # e.g. a bag whose camera changed its resolution
                    failure = f"{args.video}: frame {index}: {exc}"
                    break
                output.put((index, t, frame, response))
                index += 1
        except SourceError as exc:  # a cut or corrupt bag: what was read is written
            failure = f"{exc} (results written for the {index} frames before)"
        except _OutputError as exc:
            output.close(raise_error=False)
            return _fail(str(exc))
        try:
            output.close()
        except _OutputError as exc:
            return _fail(str(exc))
        if failure is not None:
            progress.finish()
            return _fail(failure)
    if not records:
        return _fail(f"{args.video}: no frames decoded")
    if args.plot:
        plot_responses([r["t"] for r in records], [r["u"] for r in records],
                       [r["spike_rate"] for r in records], [r["collision"] for r in records],
                       args.plot, title=f"{Path(args.video).name} ({args.model}, {args.preset})")
    warned = sum(r["collision"] for r in records)
    print(f"asnn detect: {len(records)} frames, {warned} with a collision warning",
          file=sys.stderr)
    return 0
