"""Render one frame of an ``asnn detect --mcap`` file roughly as Foxglove's Image panel shows it:
the ``/asnn/image`` picture with the ``/asnn/annotations`` of the same time drawn on it.

    python docs/render_foxglove_frame.py OUT.mcap FRAME OUT.png [--scale 4]

Reads the file with the MCAP project's reader and decodes the messages with the schemas they
carry (``mcap`` and ``mcap-protobuf-support``, in the dev extra). Used for docs/foxglove-frame.png.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory


def _bgr(color) -> tuple[int, int, int]:
    return int(color.b * 255), int(color.g * 255), int(color.r * 255)


def render(path: str, frame: int, scale: float) -> np.ndarray:
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        images, annotations = [], []
        for _, channel, _, message in reader.iter_decoded_messages(
                topics=["/asnn/image", "/asnn/annotations"]):
            (images if channel.topic == "/asnn/image" else annotations).append(message)
    image = cv2.imdecode(np.frombuffer(images[frame].data, np.uint8), cv2.IMREAD_COLOR)
    image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    overlay = image.copy()
    marks = annotations[frame]
    for circle in marks.circles:
        centre = (round(circle.position.x * scale), round(circle.position.y * scale))
        radius = round(circle.diameter * scale / 2)
        cv2.circle(overlay, centre, radius, _bgr(circle.fill_color), -1, cv2.LINE_AA)
    image = cv2.addWeighted(overlay, 0.2, image, 0.8, 0)
    for circle in marks.circles:
        centre = (round(circle.position.x * scale), round(circle.position.y * scale))
        cv2.circle(image, centre, round(circle.diameter * scale / 2),
                   _bgr(circle.outline_color), max(1, round(circle.thickness)), cv2.LINE_AA)
    for points in marks.points:
        xy = np.array([[p.x * scale, p.y * scale] for p in points.points]).round().astype(int)
        thickness = max(1, round(points.thickness))
        if points.type == 2:  # LineLoop
            cv2.polylines(image, [xy], True, _bgr(points.outline_color), thickness, cv2.LINE_AA)
        else:  # LineList: pairs
            for a, b in zip(xy[0::2], xy[1::2]):
                cv2.line(image, tuple(a), tuple(b), _bgr(points.outline_color), thickness,
                         cv2.LINE_AA)
    for text in marks.texts:
        cv2.putText(image, text.text, (round(text.position.x * scale),
                                       round(text.position.y * scale)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.5, _bgr(text.text_color), 1, cv2.LINE_AA)
    return image


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mcap")
    parser.add_argument("frame", type=int)
    parser.add_argument("out")
    parser.add_argument("--scale", type=float, default=4.0)
    args = parser.parse_args()
    cv2.imwrite(args.out, render(args.mcap, args.frame, args.scale))


if __name__ == "__main__":
    main()
