"""Publish a video file's frames to the asnn workers, as a camera of your own would.

Shows a camera written from docs/contract.md alone (zenoh, msgpack and OpenCV, nothing of
asnn): the Frame map on `<prefix>/<robot>/frame`, gray8 or jpeg, `seq` counting 0, 1, 2, ...
and `stamp` in float seconds, sent best effort at the file's frame rate.

    python examples/frame_publisher.py clip.mp4 --robot r1 --connect tcp/127.0.0.1:7447 [--jpeg]

Run a worker first: the frames of a robot nobody subscribes to are lost.
"""
import argparse
import json
import sys
import time

import cv2
import msgpack
import zenoh


def make_config(endpoints):
    """A client of the router(s) at `endpoints`, without multicast scouting (for a fleet,
    start from deploy/zenoh/client.json5 instead: zenoh.Config.from_file)."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps(endpoints))
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


def main():
    parser = argparse.ArgumentParser(prog="frame_publisher", description=__doc__.split("\n")[0])
    parser.add_argument("video", help="a video file OpenCV reads")
    parser.add_argument("--robot", default="r1", help="robot id: 1-64 of A-Z a-z 0-9 _ -")
    parser.add_argument("--connect", metavar="ENDPOINT", action="append",
                        help="router endpoint, repeatable (default: tcp/127.0.0.1:7447)")
    parser.add_argument("--prefix", default="asnn", help="key prefix (default: asnn)")
    parser.add_argument("--jpeg", action="store_true", help="send jpeg files, not gray8 pixels")
    parser.add_argument("--wait", type=float, default=10.0, metavar="SECONDS",
                        help="wait at most this long for a worker (default: 10)")
    args = parser.parse_args()
    config = make_config(args.connect or ["tcp/127.0.0.1:7447"])

    video = cv2.VideoCapture(args.video)
    if not video.isOpened():
        sys.exit(f"frame_publisher: cannot open {args.video}")
    fps = video.get(cv2.CAP_PROP_FPS)
    fps = fps if 1 <= fps <= 240 else 20.0  # a file without a usable rate: 20 fps, as asnn's

    zenoh.init_log_from_env_or("error")
    with zenoh.open(config) as session:
        key = f"{args.prefix}/{args.robot}/frame"
        # frames are best effort: a late frame is worth less than the next one
        publisher = session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.DATA_LOW, reliability=zenoh.Reliability.BEST_EFFORT)
        deadline = time.monotonic() + args.wait
        while not publisher.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.05)
        heard = "a worker" if publisher.matching_status.matching else "no worker yet"
        print(f"publishing on {key} at {fps:g} fps ({heard})", file=sys.stderr, flush=True)
        seq, start, wall_start = 0, time.monotonic(), time.time()
        try:
            while True:
                ok, image = video.read()  # BGR
                if not ok:
                    break
                height, width = image.shape[:2]
                if args.jpeg:
                    data = cv2.imencode(".jpg", image)[1].tobytes()  # colour is read as gray
                else:
                    data = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).tobytes()
                publisher.put(msgpack.packb({
                    "v": 1, "seq": seq, "stamp": wall_start + seq / fps,  # float64 seconds
                    "width": width, "height": height, "format": "jpeg" if args.jpeg else "gray8",
                    "data": data}, use_bin_type=True))  # data as msgpack bin, keys as str
                seq += 1
                time.sleep(max(0.0, start + seq / fps - time.monotonic()))
        except KeyboardInterrupt:
            pass
        publisher.undeclare()
    print(f"sent {seq} frames", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
