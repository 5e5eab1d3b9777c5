"""The labels of evaluation clips (``labels.json``), checked where they are read.

A label is one clip's entry (the format of ``data/real/README.md``, SPEC.md section 5): the
clip's ``file``, its ``fps``, whether it ends in a ``collision``, and for a collision the
``onset_frame`` (the object is clearly on a collision course) and the ``contact_frame``;
optionally its ``frames``, ``width`` and ``height``, the object's ``center`` at contact, and
per frame its centre (``track``), size (``target_size``) and time to contact (``ttc``), where a
generated clip knows them. Other fields (``description``, ``category``, ...) are kept as they
are.

Labels are written by hand, and a mistake in one costs most when it is found late: a collision
without its onset fails only after every detector has run over every clip, an onset after the
contact scores every warning as early, a label without ``fps`` silently loses the scoring
rule's early tolerance (half a second, in frames) and the clip's minutes of video, and two
clips with the same name but for the extension write their results to one file, so one clip's
results are scored for both. So :func:`load_labels` checks every entry before anything runs
and names the entry and the field it refuses.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import re
import unicodedata
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from pydantic import (BaseModel, ConfigDict, Field, StrictBool, StrictInt, ValidationError,
                      field_validator, model_validator)

from ..io.files import resolved, write_atomically
# FPS_RANGE: frame rates a clip's camera runs at (outside, a mistake); RAW_STREAM_SUFFIXES:
# the raw streams, which state none
from ..io.video import FPS_RANGE, RAW_STREAM_SUFFIXES

# what OpenCV's FFmpeg backend commonly reads (dashcams write .ts and .mts too); bags (.mcap)
# need a topic and are labelled by hand
VIDEO_SUFFIXES = tuple(sorted((".3gp", ".avi", ".flv", ".m2ts", ".m4v", ".mkv", ".mov", ".mp4",
                               ".mpeg", ".mpg", ".mts", ".mxf", ".ogv", ".ts", ".vob", ".webm",
                               ".wmv", ".y4m", *RAW_STREAM_SUFFIXES)))

__all__ = ["RAW_STREAM_SUFFIXES", "VIDEO_SUFFIXES", "ClipLabel", "center_outside",
           "check_labels", "clip_hint", "label_problem", "load_labels", "meant_clip",
           "mismatches", "read_entries", "result_name", "same_name", "unlabelled",
           "unlabelled_videos", "write_entries"]


class ClipLabel(BaseModel):
    """One clip's label: the fields the scoring reads, checked; any others kept as given.

    Numbers are taken as JSON writes them, not converted: ``true`` or ``"20"`` for a frame is
    a mistake to name, not the frame 1 or 20.
    """

    model_config = ConfigDict(extra="allow", allow_inf_nan=False, frozen=True)

    file: str = Field(min_length=1, description="the clip, relative to the clips' folder")
    fps: float = Field(strict=True, ge=FPS_RANGE[0], le=FPS_RANGE[1],
                       description="the clip's frame rate: the early tolerance's frames and the "
                       "clip's duration come from it")
    collision: StrictBool | None = Field(None, description="whether the clip ends in a "
                                         "collision (required: null only in an unfinished entry)")
    onset_frame: StrictInt | None = Field(None, ge=0, description="collision: the first frame "
                                          "on a collision course")
    contact_frame: StrictInt | None = Field(None, ge=0, description="collision: the frame of "
                                            "contact (or of the closest approach)")
    frames: StrictInt | None = Field(None, ge=1, description="the clip's length, frames")
    width: StrictInt | None = Field(None, ge=1)
    height: StrictInt | None = Field(None, ge=1)
    center: tuple[float, float] | None = Field(None, description="the object's centre at "
                                               "contact, pixels")
    track: list[tuple[float, float] | None] | None = Field(None, description="the object's "
                                                           "centre in every frame, or null")
    target_size: list[float | None] | None = None
    ttc: list[float | None] | None = Field(None, description="the true time to contact in "
                                           "every frame, seconds, or null")
    topic: str | None = Field(None, min_length=1, description="a ROS 2 bag's image topic")

    @field_validator("ttc")
    @classmethod
    def _positive_ttc(cls, values: list[float | None] | None) -> list[float | None] | None:
        if values is not None and any(v is not None and v < 0 for v in values):
            raise ValueError("a time to contact is never negative")
        return values

    @model_validator(mode="after")
    def _consistent(self) -> "ClipLabel":
        onset, contact = self.onset_frame, self.contact_frame
        if self.collision is None:
            raise ValueError("collision is not filled in (true or false)")
        if self.collision:
            if onset is None or contact is None:
                raise ValueError("a collision label needs onset_frame and contact_frame")
            if onset > contact:
                raise ValueError(f"onset_frame {onset} is after contact_frame {contact}")
            if self.frames is not None and contact >= self.frames:
                raise ValueError(f"contact_frame {contact} is beyond the clip's {self.frames} "
                                 f"frames (0 to {self.frames - 1})")
        elif onset is not None or contact is not None:
            raise ValueError("a label without a collision has no onset_frame or contact_frame "
                             "(null)")
        if self.center is not None and self.width is not None and self.height is not None:
            x, y = self.center
            if not (0 <= x <= self.width and 0 <= y <= self.height):
                raise ValueError(f"center ({x:g}, {y:g}) is outside the {self.width}x"
                                 f"{self.height} frame")
        for key in self.model_extra or {}:  # a misspelt field would be kept and never read
            # (TTC and CENTER too: a field's name in capitals was kept)
            near = difflib.get_close_matches(key.lower(), _FIELDS, n=1, cutoff=0.75)
            if near:
                raise ValueError(f"unknown field {key!r}: did you mean {near[0]!r}?")
        if self.topic is not None and self.file.lower().endswith(VIDEO_SUFFIXES):
            # asnn eval refuses to open it so; asnn label said it was ready (a bag is a .mcap
            # file or a rosbag2 folder)
            raise ValueError(f"a topic applies to ROS 2 bags only, not to the video {self.file}")
        if self.frames is not None:
            for name in ("track", "target_size", "ttc"):
                values = getattr(self, name)
                if values is not None and len(values) != self.frames:
                    raise ValueError(f"{name} has {len(values)} entries for the clip's "
                                     f"{self.frames} frames (one per frame)")
        return self


_FIELDS = tuple(ClipLabel.model_fields)
MAX_NAME_BYTES = 255  # a file name's longest on the usual file systems (ext4, APFS, NTFS)


def check_labels(labels: Sequence[Mapping], source: str = "labels") -> list[dict]:
    """Check clip labels (:class:`ClipLabel`) and that no two write their results to one file.

    Parameters
    ----------
    labels : sequence of mapping
        The entries of a ``labels.json``.
    source : str
        What the entries came from, for the error message.

    Returns
    -------
    list of dict
        The entries, unchanged.

    Raises
    ------
    ValueError
        Naming the first entry refused (its index and ``file``) and why.
    """
    names: dict[str, int] = {}
    for index, label in enumerate(labels):
        where = f"{source}: entry {index}"
        if isinstance(label, Mapping) and isinstance(label.get("file"), str):
            where += f" ({label['file']})"
        problem = label_problem(label)
        if problem is not None:
            raise ValueError(f"{where}: {problem}")
        # each clip's results are <result_name>.jsonl in a detector's folder: two names alike
        # would share one file, and one clip's results would be scored for both
        stem = result_name(label)
        if len(f"{stem}.jsonl".encode()) > MAX_NAME_BYTES:
            raise ValueError(f"{where}: its name is too long for its results file "
                             f"({stem[:20]}....jsonl: at most {MAX_NAME_BYTES} bytes); "
                             "shorten it")
        stem = stem.casefold()  # on a file system that ignores case, C.jsonl is c.jsonl
        if stem in names and _same_clip(label, labels[names[stem]]):
            raise ValueError(f"{where}: names the same clip as entry {names[stem]}: one entry "
                             "a clip (remove one)")
        if stem in names:
            raise ValueError(f"{where}: its results would overwrite those of entry {names[stem]} "
                             f"({labels[names[stem]]['file']}): clip names must differ by more "
                             "than their folder, extension and case (a bag's cameras by their "
                             "topic)")
        names[stem] = index
    return [dict(label) for label in labels]


def _same_clip(a: Mapping, b: Mapping) -> bool:
    """Whether two entries name one clip: the same file (``./c.mp4`` and ``sub/../c.mp4`` are
    ``c.mp4``) and the same camera of a bag, however written (:func:`_camera`)."""
    (file_a, topic_a), (file_b, topic_b) = _camera(a), _camera(b)
    return os.path.normpath(file_a) == os.path.normpath(file_b) and topic_a == topic_b


def result_name(label: Mapping) -> str:
    """The name of a clip's results and plot files: its file's stem, and for a bag's camera
    its topic too (``drive.front_image_raw`` for ``drive.mcap`` and ``/front/image_raw``), so
    that two cameras of one bag are two clips. A ``file`` written as the command line takes a
    bag's camera (``drive.mcap#/front/image_raw``, or a rosbag2 folder's) is named alike."""
    file, topic = _camera(label)
    stem = Path(file).stem
    if not topic:
        return stem
    return f"{stem}.{re.sub(r'[^A-Za-z0-9_-]+', '_', str(topic)).strip('_')}"


def _camera(label: Mapping) -> tuple[str, str | None]:
    """An entry's ``(file, topic)``, a bag's camera written as ``drive.mcap#/front/image_raw``
    split (the topic given twice, as open_source accepts it, is one camera too); no topic:
    None."""
    file, topic = str(label["file"]), label.get("topic")
    head, sep, suffix = file.rpartition("#")
    if sep and suffix.startswith("/") and topic in (None, "", suffix) and (
            head.lower().endswith(".mcap") or not Path(head).suffix):
        file, topic = head, suffix
    return file, topic or None


def label_problem(label: object) -> str | None:
    """Why one entry is not a clip label (:class:`ClipLabel`), or None where it is one."""
    if not isinstance(label, Mapping):
        return f"expected an object, got {type(label).__name__}"
    try:
        ClipLabel.model_validate(label)
    except ValidationError as exc:
        return _reasons(exc)
    return None


def unlabelled(file: str, frames: int, fps: float, width: int, height: int) -> dict:
    """An entry for a clip that has none yet, with what its decoding tells (its ``frames``,
    ``fps`` and size) and the rest to fill in by hand: ``collision``, and for a collision
    ``onset_frame``, ``contact_frame`` and ``center``. Until then :func:`check_labels`
    refuses it, so an unfinished entry is never scored."""
    return {"file": file, "width": width, "height": height, "fps": fps, "frames": frames,
            "collision": None, "onset_frame": None, "contact_frame": None, "center": None,
            "description": ""}


def _unnamed(folder: Path, labels: Sequence, wanted: Callable[[Path], bool]) -> list[str]:
    """The names of the entries directly in ``folder`` that are ``wanted`` and no entry of
    ``labels`` names, by any path to them (``clip.mp4``, ``./clip.mp4``, ``sub/../clip.mp4``).
    Sorted by name."""
    labelled = {resolved(folder / e["file"]) for e in labels
                if isinstance(e, Mapping) and isinstance(e.get("file"), str)}
    try:
        found = sorted(p for p in folder.iterdir() if wanted(p))
    except OSError:
        return []
    return [p.name for p in found if resolved(p) not in labelled]


def unlabelled_videos(clips_dir: str | Path, labels: Sequence) -> list[str]:
    """The videos (:data:`VIDEO_SUFFIXES`) directly in ``clips_dir`` that no entry of
    ``labels`` names: clips ``asnn eval`` does not score, and ``asnn label`` would add; a link
    to a clip that is gone too (its decoding then says so), not skipped. Sorted by name."""
    return _unnamed(Path(clips_dir), labels, lambda p: (p.is_file() or p.is_symlink())
                    and p.suffix.lower() in VIDEO_SUFFIXES)


def unlabelled_bags(clips_dir: str | Path, labels: Sequence) -> list[str]:
    """The ROS 2 bags directly in ``clips_dir`` (an ``.mcap`` file, any case, or a link to
    one, gone too; a rosbag2 folder, one holding a ``metadata.yaml``) that no entry of
    ``labels`` names, by any path to it: entered by hand, with their topic. Sorted by name."""
    return _unnamed(Path(clips_dir), labels, lambda p: (
        (p.is_file() or p.is_symlink()) and p.suffix.lower() == ".mcap")
        or (p.is_dir() and (p / "metadata.yaml").is_file()))


def clip_hint(file: str, candidates: Sequence[str]) -> str:
    """For a label whose clip is missing: `` (did you mean NAME?)`` naming the one of
    ``candidates`` (videos no label names) its ``file`` is most likely meant for
    (:func:`meant_clip`), or ''."""
    meant = meant_clip(file, candidates)
    if meant is None:
        return ""
    if meant != Path(file).name and same_name(meant, Path(file).name):
        form = "NFC" if unicodedata.is_normalized("NFC", meant) else "NFD"
        # ascii(): the two names print alike, but for their escapes
        return (f" (the folder has {ascii(meant)}, the same name with its accents composed "
                f"otherwise, Unicode {form}: write it as the file's name is)")
    return f" (did you mean {meant}?)"


def meant_clip(file: str, candidates: Sequence[str]) -> str | None:
    """The one of ``candidates`` a label's missing ``file`` is most likely meant for: the same
    name composed otherwise in Unicode (macOS writes NFD), or its closest spelling; None."""
    name = Path(file).name
    for candidate in candidates:
        if same_name(candidate, name):
            return candidate
    near = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.75)
    return near[0] if near else None


def same_name(a: str, b: str) -> bool:
    """Whether two file names are the same characters, however composed in Unicode (an accent
    on its letter, NFC, or after it, NFD)."""
    return unicodedata.normalize("NFC", a) == unicodedata.normalize("NFC", b)


def load_labels(path: str | Path) -> list[dict]:
    """Read and check ``labels.json``: a list of clip labels, or an object with a ``clips`` list.

    Raises
    ------
    OSError
        If the file cannot be read.
    ValueError
        If it is not JSON, holds neither form, holds no entry (nothing to evaluate), or an
        entry is refused (:func:`check_labels`).
    """
    entries = read_entries(path)
    if not entries:
        raise ValueError(f"{path}: no clip labels in it")
    return check_labels(entries, str(path))


# the largest labels.json read: a label with per-frame tracks for 10,000 frames is about 1 MB
MAX_LABELS_BYTES = 64 << 20


class _LabelsError(ValueError):
    """What the JSON reader's hooks find (a ValueError of json.loads' own is a syntax error)."""


def _no_constant(name: str):
    """NaN and Infinity are not JSON: a label holding one passed every check and stopped the
    evaluation once it had run, when its results were written as JSON."""
    raise _LabelsError(f"{name} is not a JSON number")


def _finite(text: str) -> float:
    """A JSON number as a float; one beyond float's range (1e400) would be infinite."""
    value = float(text)
    if not math.isfinite(value):
        raise _LabelsError(f"{text} is beyond a float's range")
    return value


def _unique_keys(pairs: list[tuple[str, object]]) -> dict:
    """A JSON object whose keys are given once: a second ``collision`` silently replaced the
    first, and a rewrite of the file lost it."""
    seen = {}
    for key, value in pairs:
        if key in seen:
            raise _LabelsError(f"an entry gives {key!r} twice")
        seen[key] = value
    return seen


def _read_document(path: str | Path):
    """A ``labels.json``'s JSON as it is (a list, or an object with ``clips``), unchecked.

    Raises
    ------
    OSError
        If the file cannot be read.
    ValueError
        If it is not a regular file of at most :data:`MAX_LABELS_BYTES` of JSON (NaN, a
        number beyond a float's range or a key given twice in an object is not JSON here).
    """
    path = Path(path)
    if path.exists() and not path.is_file():  # a pipe or /dev/zero would be read without end
        raise ValueError(f"{path}: not a regular file")
    with path.open("rb") as f:
        raw = f.read(MAX_LABELS_BYTES + 1)
    if len(raw) > MAX_LABELS_BYTES:
        raise ValueError(f"{path}: larger than {MAX_LABELS_BYTES >> 20} MiB")
    try:
        # utf-8-sig: a byte-order mark (Windows Notepad writes one) is not the JSON's
        data = json.loads(raw.decode("utf-8-sig"), parse_constant=_no_constant,
                          parse_float=_finite, object_pairs_hook=_unique_keys)
    except _LabelsError as exc:
        raise ValueError(f"{path}: {exc}") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc})") from None
    except RecursionError:  # lists in lists, thousands deep: Python's parser gives up
        raise ValueError(f"{path}: not JSON (nested too deeply)") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not UTF-8 text (save it as UTF-8)") from None
    except ValueError as exc:  # an integer of thousands of digits, which Python refuses
        raise ValueError(f"{path}: not JSON this reads ({exc})") from None
    return data


def read_entries(path: str | Path) -> list:
    """The entries of a ``labels.json`` (a list, or an object's ``clips`` list), unchecked.

    Raises
    ------
    OSError
        If the file cannot be read.
    ValueError
        If it is not JSON (:func:`_read_document`) or holds neither form.
    """
    data = _read_document(path)
    if isinstance(data, dict):
        data = data.get("clips")
    if not isinstance(data, list):
        raise ValueError(f"{path}: expected a list of clip labels (or an object with 'clips')")
    return data


def write_entries(path: str | Path, entries: list, indent: int = 2) -> None:
    """Write the entries of a ``labels.json``, keeping the file's form: where it holds an object,
    the object with its other fields and ``clips`` replaced; otherwise a list. The file is
    replaced whole (:func:`asnn.io.files.write_atomically`): a process killed meanwhile leaves
    the old labels or the new ones. Hold :func:`asnn.io.files.folder_lock` from the read that
    chose ``entries`` to this write, so that processes adding clips at once keep each other's.

    Raises
    ------
    OSError
        If it cannot be written (the file is then as it was).
    """
    document = entries
    if Path(path).exists():
        try:
            existing = _read_document(path)
        except ValueError:  # entries read from it were checked; a file replaced by junk since
            existing = None
        if isinstance(existing, dict):
            document = {**existing, "clips": entries}
    write_atomically(path, json.dumps(document, indent=indent, allow_nan=False) + "\n")


def center_outside(label: Mapping, width: int, height: int) -> str | None:
    """Why a label's ``center`` cannot be in its clip's own ``width`` x ``height`` frames (a
    portrait clip labelled with its size swapped, or a label without a size), or None.

    :class:`ClipLabel` checks the centre against the label's own ``width`` and ``height`` only;
    this checks it against the frames decoded, so that a centre no target can be near is
    refused instead of scored as a localisation error."""
    center = label.get("center")
    if center is None:
        return None
    x, y = (float(v) for v in center)
    if 0 <= x <= width and 0 <= y <= height:
        return None
    return (f"{label.get('file', '?')}: center ({x:g}, {y:g}) is outside its {width}x{height} "
            "frames (center is [x, y] in the clip's pixels)")


def mismatches(label: Mapping, frames: int, fps: float, tolerance: float = 0.01,
               size: tuple[int, int] | None = None) -> list[str]:
    """Where a clip as it was decoded disagrees with its label: its number of frames (where the
    label gives ``frames``; else the per-frame ``track``, ``target_size`` and ``ttc``'s
    lengths), a ``contact_frame`` beyond the frames decoded, its frame rate (by more than
    ``tolerance``, relative), and its frames' ``size`` (width, height), where given, against
    the label's ``width`` and ``height``.

    A label's frames are counted as one decoder saw them (OpenCV reads 68 of a clip whose
    header claims 444, another decoder may read more), and the scoring takes its early
    tolerance and lead times from the label's ``fps``: where either disagrees with the clip
    the model was run on, its onset and contact may not point at the frames that were meant.

    Returns
    -------
    list of str
        One sentence per disagreement, naming the clip; empty where there is none.
    """
    found = []
    name = label.get("file", "?")
    if label.get("frames") is not None and int(label["frames"]) != frames:
        found.append(f"{name}: {frames} frames decoded where its label counts "
                     f"{int(label['frames'])}: its onset and contact may be off")
    if label.get("contact_frame") is not None and int(label["contact_frame"]) >= frames:
        found.append(f"{name}: its contact_frame {int(label['contact_frame'])} is beyond the "
                     f"{frames} frames decoded: the scoring's window ends after the clip")
    for field in ("track", "target_size", "ttc"):
        values = label.get(field)
        if values is not None and len(values) != frames and label.get("frames") is None:
            found.append(f"{name}: its {field} has {len(values)} entries for the {frames} "
                         "frames decoded (one per frame): its target scores are left out")
    if size is not None and label.get("width") is not None and label.get("height") is not None:
        labelled = (int(label["width"]), int(label["height"]))
        if tuple(size) != labelled:
            found.append(f"{name}: its frames are {size[0]}x{size[1]} where its label says "
                         f"{labelled[0]}x{labelled[1]}: its center and track may not be in the "
                         "clip's pixels")
    if abs(fps - float(label["fps"])) > tolerance * float(label["fps"]):
        found.append(f"{name}: the clip runs at {fps:g} fps where its label says "
                     f"{float(label['fps']):g}: the model's timing and the scoring's disagree")
    return found


def _reasons(exc: ValidationError, most: int = 3) -> str:
    """A validation error's first ``most`` reasons on one line, each with the field it
    concerns (``track.4.1``: the second coordinate of the fifth frame's entry)."""
    reasons = []
    for error in exc.errors():
        field = ".".join(str(part) for part in error["loc"])
        message = error["msg"].removeprefix("Value error, ")
        reasons.append(f"{field}: {message}" if field else message)
    more = f"; and {len(reasons) - most} more" if len(reasons) > most else ""
    return "; ".join(reasons[:most]) + more
