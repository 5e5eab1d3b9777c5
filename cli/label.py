"""``asnn label``: start or check the labels of a folder of clips for ``asnn eval``.

``asnn label CLIPS_DIR [--labels FILE]`` decodes every video in the folder (not its subfolders:
their clips are entered by hand, as ``sub/clip.mp4``, and then checked like the others) as
``asnn eval`` will, adds an entry for each video without one (its ``frames``, ``fps`` and size
filled in, the rest to fill in by hand: :func:`asnn.evaluation.labels.unlabelled`), and lists
what is left to do: entries to finish or mend, clips that decode to other frames, another frame
rate or another size than their labels say, a centre outside the clip's frames, labels whose clip
is not there, and bags (``.mcap``) no entry names (entered by hand, with their topic). Exit
status 0 when every entry is ready for
``asnn eval``, 1 when something is listed, 2 for unusable input.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from asnn.io.files import folder_lock, folder_problem, path_problem
from asnn.params import preset
from cli.arguments import nonempty_path



def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "label", help="start or check the labels.json of a folder of clips",
        description="Decode every video in CLIPS_DIR (not its subfolders) as asnn eval will, "
                    "add a labels.json entry for each video without one (frames, fps and size "
                    "filled in; collision, onset_frame, contact_frame and center left to fill "
                    "in by hand), and list "
                    "what is left to do. Exit status 0 when every entry is ready for asnn eval, "
                    "1 when something is listed.")
    p.add_argument("clips_dir", type=nonempty_path, metavar="CLIPS_DIR",
                   help="the folder of the clips")
    p.add_argument("--labels", type=nonempty_path, metavar="FILE",
                   help="the labels file to start or check (default: CLIPS_DIR/labels.json)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # the evaluation's labels and the decoders (OpenCV): when it runs, not with the parser
    from asnn.evaluation.labels import (RAW_STREAM_SUFFIXES, VIDEO_SUFFIXES, center_outside,
                                        check_labels, clip_hint, label_problem, meant_clip,
                                        mismatches, read_entries, same_name, unlabelled,
                                        unlabelled_bags, unlabelled_videos, write_entries)
    from asnn.evaluation.scoring import unscored
    from asnn.io.sources import SourceError

    folder = Path(args.clips_dir)
    path = Path(args.labels) if args.labels else folder / "labels.json"
    for named in (folder, path):  # before is_dir and exists, which raise for it
        problem = path_problem(named)
        if problem:
            print(f"asnn label: {named}: {problem}", file=sys.stderr)
            return 2
    if not folder.is_dir():
        print(f"asnn label: {folder}: not a folder", file=sys.stderr)
        return 2
    try:
        entries = read_entries(path) if path.exists() else []
    except (OSError, ValueError) as exc:
        print(f"asnn label: {exc}", file=sys.stderr)
        return 2
    todo = []
    # the videos no entry names (as ./clip.mp4 or sub/../clip.mp4 too): the ones to add, and
    # the names a missing clip's file may be a typo of
    new_names = unlabelled_videos(folder, entries)
    for index, entry in enumerate(entries):  # the entries there are, each on its own
        problem = label_problem(entry)
        if problem is not None:
            name = entry.get("file") if isinstance(entry, dict) else None
            todo.append(f"{name or f'entry {index}'}: {problem}")
            continue
        clip = folder / entry["file"]
        if not clip.is_file():
            todo.append(f"{entry['file']}: no such clip in {folder}"
                        + clip_hint(entry["file"], new_names))
            meant = meant_clip(entry["file"], new_names)
            if meant is not None and same_name(meant, clip.name):
                # the entry's own clip, its name composed otherwise: not a second entry
                new_names.remove(meant)
        elif clip.suffix.lower() in VIDEO_SUFFIXES:
            try:
                frames, fps, (height, width) = _decode(clip, todo)
            except SourceError as exc:
                todo.append(str(exc))
                continue
            todo += mismatches(entry, frames, fps, size=(width, height))
            todo += unscored(entry, frames)  # as asnn eval warns of it
            outside = center_outside(entry, width, height)
            if outside is not None:
                todo.append(outside)
    if not todo:
        try:  # across the entries: two clips whose results would share a file
            check_labels(entries, str(path))
        except ValueError as exc:
            todo.append(str(exc))
    new_videos = [folder / name for name in new_names]
    # entries to add: the labels' folder is tried before their clips decode, not after (a
    # check alone writes nothing, and may read a folder it cannot write)
    problem = folder_problem(path.parent) if new_videos else None
    if problem:
        print(f"asnn label: cannot write {path}: {problem}", file=sys.stderr)
        return 2
    for bag in unlabelled_bags(folder, entries):  # entered by hand: the topic is the user's
        todo.append(f"{bag}: a bag no entry names: enter it by hand, with its image topic "
                    f'where it has several ({{"file": "{bag}", "topic": "/camera/image_raw", '
                    '"fps": ..., "collision": ...}, docs/foxglove.md)')
    if not entries and not new_videos and not todo:
        print(f"asnn label: {folder} holds no video ({', '.join(VIDEO_SUFFIXES)}; subfolders "
              "are not searched: enter their clips by hand, as sub/clip.mp4, and bags with "
              "their topic)")
        return 1
    added = []
    for video in new_videos:
        try:
            frames, fps, (height, width) = _decode(video, todo)
        except SourceError as exc:
            todo.append(str(exc))
            continue
        entries.append(unlabelled(video.name, frames, fps, width, height))
        added.append(entries[-1])
        todo += unscored(entries[-1], frames)
        todo.append(f"{video.name}: {label_problem(entries[-1])}")
        if video.suffix.lower() in RAW_STREAM_SUFFIXES:
            todo.append(f"{video.name}: a raw stream states no frame rate: OpenCV reads it, "
                        f"and asnn eval steps the model, at {fps:g} fps; where the camera ran "
                        "at another, put the stream in a container that states it (ffmpeg -r "
                        f"RATE -i {video.name} -c copy {video.stem}.mkv) and label that instead")
    if added:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)  # as asnn scene --labels makes it
            # read again under a lock on the folder: what another process entered meanwhile
            # (asnn scene --labels) stays; replaced whole, the file is never left half written
            with folder_lock(path):
                current = read_entries(path) if path.exists() else []
                named = {e.get("file") for e in current if isinstance(e, dict)}
                write_entries(path, current + [e for e in added if e["file"] not in named],
                              indent=2)
        except (OSError, ValueError) as exc:
            print(f"asnn label: cannot write {path}: {exc.strerror or exc}", file=sys.stderr)
            return 2
        names = ", ".join(e["file"] for e in added)
        print(f"{path}: {len(added)} {'entry' if len(added) == 1 else 'entries'} added "
              f"({names}): fill in collision, and for a collision onset_frame and "
              "contact_frame (and center, the object's [x, y] at contact, for the scores of "
              "the targets)")
    for line in todo:
        print(line)
    if not todo:
        print(f"{path}: {len(entries)} entr{'y' if len(entries) == 1 else 'ies'}, every one "
              "ready for asnn eval")
    return 1 if todo else 0


def _decode(video: Path, todo: list[str]) -> tuple[int, float, tuple[int, int]]:
    """Frames, frame rate and (height, width) of a video, decoded as ``asnn eval`` does; what
    makes it unfit to score goes to ``todo`` (frames smaller than the model takes, a clip that
    decodes to fewer frames than it states)."""
    from asnn.io.sources import open_source
    from asnn.io.video import cut_short

    clip = open_source(str(video))
    frames, shape = 0, (0, 0)
    for image in clip.frames():
        frames, shape = frames + 1, image.shape[:2]
    smallest = preset("default").min_side
    if min(shape) < smallest:
        todo.append(f"{video.name}: its {shape[1]}x{shape[0]} frames are smaller than the "
                    f"model's {smallest}x{smallest} kernels: asnn eval cannot score it")
    short = cut_short(clip.frame_count, frames)
    if short:
        todo.append(f"{video.name}: {short}")
    return frames, clip.fps, shape
