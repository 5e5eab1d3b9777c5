"""``asnn detect VIDEO``: offline detection on a video file or a ROS 2 bag (CONTRACT.md)."""

from __future__ import annotations

import argparse
import gc
import json
import os
import sys
from collections import deque
from contextlib import ExitStack, contextmanager, suppress
from pathlib import Path

from asnn.detectors import (MODELS, available_cores, baseline_classes, make_detector,
                            responses)
from asnn.errors import timing_warnings_to
from asnn.io.files import output_problem, resolved, seekable_target
from asnn.io.pipeline import WriteBehind, read_ahead
from asnn.io.sources import (CLOCK_RESET_FRAMES, BackwardStamps, SourceError, open_source,
                              split_topic)
from asnn.params import (MAX_FRAME_GAP_S, MIN_FRAME_GAP_S, SLOW_FPS, SLOW_NOTE, preset_from_spec,
                         preset_names, timed_gap)
from cli.arguments import frame_perturbation, nonempty_path, preset_spec, threads
from cli.session import exit_on_interrupt, fail, signals_held


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("detect", help="offline detection on a video file or a ROS 2 bag",
                       description="Run a detector over a video file or an image topic of a "
                                   "ROS 2 bag (MCAP): one JSON object per frame with --jsonl, "
                                   "and a summary line on stderr.")
    p.add_argument("video", type=nonempty_path, metavar="VIDEO",
                   help="any video OpenCV reads, or a ROS 2 bag: BAG.mcap[#TOPIC] (the 'ros' "
                        "extra)")
    p.add_argument("--topic", metavar="NAME",
                   help="image topic of a bag (sensor_msgs/msg/Image or CompressedImage, "
                        "foxglove.RawImage or CompressedImage); needed when it has several")
    p.add_argument("--model", choices=MODELS, default="asnn",
                   help="detector: ASNN or a baseline it is compared with (default: %(default)s)")
    # None where not given, so that an LGMD model refuses a --preset default too
    p.add_argument("--preset", type=preset_spec, default=None, metavar="NAME[/FIELD=VALUE...]",
                   help=f"ASNN parameter preset ({', '.join(preset_names())}; default: "
                        "default), with any fields of asnn.params.ASNNParams changed after "
                        "slashes, as asnn eval's specs take them: robust/top_k=0")
    p.add_argument("--jsonl", type=nonempty_path, metavar="PATH|-",
                   help="write one JSON object per frame ('-': stdout)")
    p.add_argument("--annotate", type=nonempty_path, metavar="OUT.mp4",
                   help="write the input with overlays")
    p.add_argument("--plot", type=nonempty_path, metavar="OUT.png",
                   help="plot u(t) and the spike rate")
    p.add_argument("--threads", type=threads, default=None, metavar="N",
                   help="threads the ASNN model uses for the stream, besides decoding and "
                        "output (default: the cores available; the results are the same "
                        "whatever the number; at most 256: more than the cores only take "
                        "turns, and thousands stall the machine); the LGMD models step on one "
                        "thread and refuse it")
    p.add_argument("--tracks", type=nonempty_path, metavar="PATH|-",
                   help="write every tracked object with its approach test, one JSON object per "
                        "frame ('-': stdout): why the model warned, or did not (presets that "
                        "track objects, e.g. default)")
    p.add_argument("--mcap", type=nonempty_path, metavar="OUT.mcap",
                   help="write the frames, targets, warnings and response numbers as an MCAP "
                        "for Foxglove (docs/foxglove.md; the 'ros' extra)")
    p.add_argument("--perturb", type=frame_perturbation, metavar="NAME",
                   help="run on the frames perturbed as another camera would give them, to see "
                        "what the detector does and why (with --tracks) under that camera: "
                        "asnn eval's perturbations that keep every frame at its size and in "
                        "its place, e.g. jpeg80 (JPEG at quality 80), gain1.04 (4 %% brighter), "
                        "noise, mpeg4 (the outputs show the perturbed frames)")
    p.set_defaults(func=run)


def _tracks_record(index: int, t: float, response) -> dict:
    return {"frame": index, "t": round(t, 6), "collision": response.collision,
            "tracks": [track.to_dict() for track in response.tracks]}


def _fail(message: str) -> int:
    return fail("detect", message)


class _OutputError(Exception):
    """An output that cannot be written (the message names it)."""


READ_AHEAD = 8  # decoded frames waiting for the model
# A bag's frame whose header stamp goes back is taken at the latest frame's time (the odd stamp
# out of order) until STAMP_LIMIT of them fall within STAMP_WINDOW frames read: stamps going back
# that often, and not as a clock reset (which the bag reader re-bases on,
# CLOCK_RESET_FRAMES in a row advancing among themselves), are no timeline to go by: the run
# stops.
STAMP_WINDOW = 100
STAMP_LIMIT = 5
STAMP_LINES = 5  # such frames named on stderr one by one; the rest are counted at the end
WRITE_BEHIND = 4  # responses waiting to be written (with --annotate each holds its maps)


class _WriteNow:
    """:class:`~asnn.io.pipeline.WriteBehind` on the calling thread."""

    def __init__(self, write):
        self.put = write

    def close(self, raise_error: bool = True) -> None:
        pass


@contextmanager
def _settings(busy: bool):
    """The process's settings for the loop, restored after it (``run`` may be called in-process).

    The loop makes objects by the thousand, and the garbage collector's full passes would go over
    the hundred thousand that the imports made (numba, OpenCV) every time: they are kept out.
    With a model thread for every core (``busy``), OpenCV's own threads would only take turns
    with them (its results do not depend on how it splits its work).
    """
    import cv2

    from asnn.io.video import quiet_opencv

    threads = cv2.getNumThreads()
    if busy:
        cv2.setNumThreads(1)
    gc.freeze()
    try:
        with quiet_opencv():  # a failed --annotate is one line (:func:`_check_annotated`)
            yield
    finally:
        gc.unfreeze()
        cv2.setNumThreads(threads)


# what matplotlib writes (--plot): it takes the format from the file's extension
PLOT_FORMATS = (".eps", ".jpeg", ".jpg", ".pdf", ".png", ".ps", ".svg", ".tif", ".tiff",
                ".webp")


def _output_problem(path: str | None, flag: str) -> str | None:
    """Why an output path cannot be written, found before the run, or None. Its folder need
    not exist: the folders missing are made once the input opens (as ``asnn scene`` makes
    them), where the nearest existing one is a folder this process may write."""
    from asnn.io.video import WRITABLE_SUFFIXES

    if not path:
        return None
    if path == "-":  # standard output: the JSON lines' outputs only; the others write files
        return None if flag in ("--jsonl", "--tracks") else \
            f"{flag} -: writes a file (- is standard output, for --jsonl and --tracks)"
    target = Path(path)
    # before is_dir, which raises for a name too long; a new one's folders are made as scene
    # makes them, and an existing one is written where it is (/dev/null, /proc/self/fd/1)
    problem = output_problem(target)
    if problem:
        return f"{flag} {path}: {problem}"
    if target.is_dir():
        return f"{flag} {path}: is a folder"
    if flag == "--plot" and target.suffix.lower() not in PLOT_FORMATS:
        return f"--plot {path}: name the format by its extension ({', '.join(PLOT_FORMATS)})"
    if flag in ("--annotate", "--mcap"):
        try:
            seekable_target(target)
        except ValueError as exc:
            return f"{flag} {exc}"
    elif flag in ("--jsonl", "--tracks") and target.exists() and not target.is_fifo():
        try:  # opened now without emptying it (that waits for its first line), so that a file
            # that cannot be written is said before the kernels compile, not after; a new one
            # is not made here (a run refused after it left it empty): its folder was tried.
            # Not a named pipe: opening one waits for its reader, and closing it ends the
            # reader's input (`cat PIPE` quit, and the run waited for ever at its first line)
            open(target, "a").close()  # noqa: SIM115
        except OSError as exc:
            return f"{flag} {path}: cannot write: {exc.strerror or exc}"
    if flag == "--mcap" and target.suffix.lower() != ".mcap":
        return f"--mcap {path}: name it .mcap"
    if flag == "--annotate" and target.suffix.lower() not in WRITABLE_SUFFIXES:
        return (f"--annotate {path}: name the format by its extension "
                f"({', '.join(WRITABLE_SUFFIXES)})")
    return None


def _bag_parts(folder: Path) -> list[Path]:
    """The files a rosbag2 folder's metadata.yaml lists (none where the bag cannot be read:
    opening it says why)."""
    try:
        from asnn.io.rosbag import bag_files  # the 'ros' extra: without it, no bag is read

        return bag_files(folder)
    except (ImportError, SourceError):
        return []


def _overwrites(outputs: list[tuple[str, str]], video: str) -> str | None:
    """Why the outputs would overwrite the input or each other, or None: an output that is the
    input file (or lies in the input's bag folder) would be truncated before a frame is read."""
    source = resolved(split_topic(video)[0])  # a loop of links: opening it says so
    seen: dict[object, str] = {}
    try:
        stdout = os.fstat(sys.stdout.fileno())
        stdout = (stdout.st_dev, stdout.st_ino)
    except (OSError, ValueError, AttributeError):  # no real standard output (in-process)
        stdout = None
    for flag, path in outputs:
        if not path:
            continue
        target = resolved(path)
        if path != "-" and target.exists() and source.exists() and \
                os.path.samefile(target, source):
            return f"{flag} {path}: is the input {video}"  # by any name or link
        if path != "-" and source.is_dir() and source in target.parents:
            return f"{flag} {path}: inside the input bag's folder {video}"
        if path != "-" and target.exists() and source.is_dir():
            # the bag's files may lie elsewhere (its metadata.yaml may list a link, a ../ or
            # an absolute path): an output that is one of them would truncate the recording
            for part in _bag_parts(source):
                if os.path.samefile(target, part):
                    return f"{flag} {path}: is {part}, a file of the input bag {video}"
        # the same file by any name: a hard link, /dev/stdout beside -
        key = target
        if path == "-":
            key = stdout or "-"
        elif target.exists():
            stat = target.stat()
            key = (stat.st_dev, stat.st_ino)
        if key in seen:
            return f"{flag} and {seen[key]} both write {path}"
        seen[key] = flag
    return None


class _BackwardStamps(BackwardStamps):
    """A bag's frames whose header stamp goes back, each taken at the latest frame's time (the
    model then steps it by the nominal period), so that every message still gets its result
    (CONTRACT.md: one per input frame): the first :data:`STAMP_LINES` named on stderr, and
    :data:`STAMP_LIMIT` within :data:`STAMP_WINDOW` frames read raised: stamps that keep going
    back. A clock reset (the reader re-bases on it) is named on stderr, the first
    :data:`STAMP_LINES` of them, and counts toward no limit, nor do its frames held before it.
    Those frames are known only when the reset completes, so the last
    ``CLOCK_RESET_FRAMES - 1`` frames read count toward the limit only once the frame after
    them is read (or the bag ends): odd frames before a reset do not stop the run. Wrap the
    source's ``timed_frames()`` in :meth:`frames`, which counts the frames read and raises.
    A frame whose header stamp is unset (zero), held at the latest frame's time (its log time
    cannot stand for a stamp), is named on stderr, the first :data:`STAMP_LINES` of them, and
    counts toward no limit either.
    """

    def __init__(self, window: int = STAMP_WINDOW, limit: int = STAMP_LIMIT,
                 lines: int = STAMP_LINES):
        super().__init__()
        self.window, self.limit, self.lines = window, limit, lines
        self.read = 0  # frames read so far
        # the numbers and messages of such frames within the window
        self._recent: deque[tuple[int, str]] = deque()

    def held(self, message: str) -> None:
        number = self.read  # the frame the reader yields next
        self._recent.append((number, message))
        while self._recent[0][0] <= number - self.window:
            self._recent.popleft()
        self._say(self.count, f"{message}; taken at the latest frame's time",
                  "frames whose stamp goes back are taken at the latest frame's time and")

    def rebased(self, message: str) -> None:
        # the frames of the reset held before it were the new clock's first, not stamps out of
        # order: they leave the window
        number = self.read  # the re-based frame, which the reader yields next
        while self._recent and self._recent[-1][0] >= number - (CLOCK_RESET_FRAMES - 1):
            self._recent.pop()
        self._say(self.resets, message, "clock resets are")

    def held_unset(self, message: str) -> None:
        self._say(self.unset, message,
                  "frames whose stamp is unset are taken at the latest frame's time and")

    def _say(self, count: int, message: str, further: str) -> None:
        """The ``count``-th such message on stderr, the first :attr:`lines` of them, then one
        line saying the ``further`` ones ("further ... counted in the summary")."""
        if count <= self.lines:
            _warn(message)
            if count == self.lines:
                print(f"asnn detect: warning: further {further} counted in the summary",
                      file=sys.stderr, flush=True)

    def _check(self, settled: int) -> None:
        """Raise where the frames before number ``settled`` that went back, which no clock
        reset can take back any more, reach the limit."""
        confirmed = [entry for entry in self._recent if entry[0] < settled]
        if len(confirmed) >= self.limit:
            raise SourceError(
                f"{confirmed[-1][1]}. {len(confirmed)} of the last {self.window} frames read "
                "went back: neither the odd stamp out of order nor a clock reset (stamps that "
                "advance again from an earlier time)", "stamps-backwards")

    def frames(self, timed):
        """``timed``'s ``(t, image)``, counted; raises SourceError where stamps keep going
        back."""
        for item in timed:
            self.read += 1
            # a reset completing at the next frame would take back the frames from this one's
            # predecessor on (CLOCK_RESET_FRAMES - 1 of them)
            self._check(self.read - (CLOCK_RESET_FRAMES - 1))
            yield item
        self._check(self.read)


def _warn(message: str, kind: str = "warning") -> None:
    """A warning (or note) line on stderr; on a terminal, over the progress bar's line (it is
    drawn again below)."""
    lead = "\r\033[K" if sys.stderr.isatty() else ""
    print(f"{lead}asnn detect: {kind}: {message}", file=sys.stderr, flush=True)


def _check_annotated(video: list, path: str | None, frames: int) -> None:
    """Close the annotated video's writer (``video``: it and the frames' size (width, height),
    once the first frame opened it) and check the file holds its ``frames`` frames: OpenCV's
    writer fails silently on a full disk, leaving a file that does not play. A size the encoder
    rounded down (an odd width or height) is a warning: the picture lacks its last column or row.

    Raises
    ------
    _OutputError
        If it does not.
    """
    from asnn.io.video import VideoError, check_written

    if not video:
        return
    writer, size = video
    writer.release()
    try:
        written = check_written(path, frames)
    except VideoError as exc:
        raise _OutputError(str(exc)) from None
    if written != size:
        _warn(f"--annotate {path}: written {written[0]}x{written[1]}, the frames' {size[0]}x"
              f"{size[1]} rounded down by the encoder (it takes even sizes only): the last "
              "column or row is left out")


class _OpenedAtFirstLine:
    """A JSON-lines output opened, and so emptied, when its first line is written: a run that
    stops before its first frame (frames smaller than the model takes, an MCAP that cannot be
    written) leaves a file already there as it was, where it used to empty it."""

    def __init__(self, path: str, stack: ExitStack):
        self.path, self._file = path, None
        stack.callback(self.close)

    def write(self, text: str) -> None:
        if self._file is None:
            self._file = open(self.path, "w", encoding="utf-8")  # noqa: SIM115 (close())
        self._file.write(text)

    def flush(self) -> None:
        if self._file is not None:
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()


def run(args: argparse.Namespace) -> int:
    """Decode ahead and write behind on threads of their own while the model steps on this one
    (:mod:`asnn.io.pipeline`), or, when the model has threads of its own for every core,
    decode and write between its steps (:meth:`asnn.model.ASNN.stream`): the output is that of
    one loop, in frame order."""
    # the model, OpenCV and the evaluation's perturbations: when it runs, not with the parser
    from asnn.evaluation.perturb import describe, perturbed
    from asnn.evaluation.progress import ProgressPrinter
    from asnn.frames import FrameError
    from asnn.io.video import cut_short, open_writer, writable_fps
    from asnn.io.visualize import annotate_frame, plot_responses
    from asnn.warmup import compile_kernels

    outputs = [("--jsonl", args.jsonl), ("--tracks", args.tracks), ("--annotate", args.annotate),
               ("--plot", args.plot), ("--mcap", args.mcap)]
    for flag, path in outputs:
        problem = _output_problem(path, flag)
        if problem is not None:  # before decoding a frame, not after the whole run
            return _fail(problem)
    problem = _overwrites(outputs, args.video)
    if problem is not None:
        return _fail(problem)
    options = {}
    model_threads = 1
    if args.model != "asnn" and args.preset is not None:
        return _fail(f"--preset applies to the ASNN model only, not {args.model}")
    if args.model != "asnn" and args.threads is not None:  # a baseline steps on this thread
        return _fail(f"--threads applies to the ASNN model only, not {args.model}")
    preset = args.preset or "default"
    params = preset_from_spec(preset)
    if args.tracks:
        if args.model != "asnn" or params.targets != "objects":
            return _fail("--tracks needs the ASNN model with a preset that tracks objects "
                         "(targets='objects', e.g. default)")
        if args.tracks == "-" and args.jsonl == "-":
            return _fail("--jsonl and --tracks cannot both write to stdout")
        options["record_tracks"] = True
    if args.model == "asnn":
        model_threads = options["threads"] = args.threads or available_cores()
        if args.annotate:
            options["record_maps"] = True
    # With a model thread for every core, more threads would only take turns with them, and
    # the machine's switching between threads costs more than decoding or writing on this one.
    busy = model_threads >= available_cores() > 1
    backwards = _BackwardStamps()  # a bag's frames whose header stamp goes back
    try:
        source = open_source(args.video, topic=args.topic, on_error=backwards,
                             hold_backwards=True, decoder_threads=1 if busy else None)
    except SourceError as exc:
        return _fail(str(exc))
    slow = ""  # said: the frames are too far apart for the model to time them by
    if not source.fps_stated:
        print(f"asnn detect: note: {args.video} {source.rate_problem()}; its frames are timed "
              f"at {source.fps:g} a second, so the targets' expansion and ttc are only as right "
              "as that guess", file=sys.stderr)
    elif args.model == "asnn" and source.fps < SLOW_FPS:
        # frames further apart than the model believes a gap (MAX_FRAME_GAP_S): it takes the
        # nominal period instead, and its times to contact would read short without a word
        slow = (f"; its frames are more than {MAX_FRAME_GAP_S:g} s apart, so the targets' "
                f"expansion and ttc are computed for {params.dt:g} s a frame"
                if 1.0 / source.fps > MAX_FRAME_GAP_S else "")
        print(f"asnn detect: note: {args.video} runs at {source.fps:g} frames a second; "
              f"{SLOW_NOTE}{slow}", file=sys.stderr)
    if args.model != "asnn":  # LGMD1-2's time constants are in seconds: as asnn eval runs it
        if timed_gap(1.0 / source.fps):
            options["dt"] = 1.0 / source.fps
        else:  # a bag's stamps in another unit: 5e-8 s or 50 s a frame is no dt
            print(f"asnn detect: note: {args.video} runs at {source.fps:g} frames a second by "
                  f"its stamps, no frame period a model can time by ({MIN_FRAME_GAP_S:g} to "
                  f"{MAX_FRAME_GAP_S:g} s): the {args.model} model runs at its default dt, "
                  f"{baseline_classes(args.model)[1]().dt:g} s a frame", file=sys.stderr)
    detector = make_detector(args.model, params, **options)
    if args.model == "asnn":
        # numba loads a kernel from its cache when it is first called: all of them now, before
        # the first frame, rather than on the frames where a stage first has work; nothing is
        # written yet, so Ctrl-C may end the process at once
        with exit_on_interrupt():
            compile_kernels((params,), threads=model_threads)
    records = []
    for _, path in outputs:  # their folders, made as asnn scene makes them (checked above)
        if path and path != "-":
            try:
                Path(path).parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                return _fail(f"cannot make the folder {exc.filename}: {exc.strerror or exc}")
    with ExitStack() as stack:
        stack.enter_context(_settings(busy))
        # the model's TimingWarning as a note, where the note on the source's rate did not say it
        stack.enter_context(timing_warnings_to(
            (lambda message: None) if slow else (lambda message: _warn(message, "note"))))
        jsonl, tracks = (sys.stdout if path == "-" else _OpenedAtFirstLine(path, stack)
                         if path else None for path in (args.jsonl, args.tracks))
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
            # every output takes the frame, or none does: a Ctrl-C or SIGTERM that came between
            # two of them left the MCAP's frame without its response, the JSON lines with it
            with signals_held():
                record = response.record(index, t)
                records.append(record)
                try:
                    if jsonl is not None:
                        jsonl.write(json.dumps(record) + "\n")
                    if tracks is not None:
                        tracks.write(json.dumps(_tracks_record(index, t, response)) + "\n")
                    if mcap is not None:
                        mcap.write(frame, record, (source.start_ns or 0) + round(t * 1e9))
                except BrokenPipeError:  # stdout's reader went away: cli.main ends quietly
                    raise
                except (OSError, RuntimeError) as exc:  # a full disk; the MCAP writer's errors
                    raise _OutputError(f"cannot write the output at frame {index}: {exc}") from None
                if args.annotate:
                    if not video:
                        try:
                            writer = open_writer(args.annotate, writable_fps(source.fps),
                                                 frame.shape[1::-1])
                        except OSError:
                            raise _OutputError(f"cannot write {args.annotate}") from None
                        stack.callback(writer.release)
                        video.extend((writer, frame.shape[1::-1]))
                    video[0].write(annotate_frame(frame, response))
            progress.advance()

        output = _WriteNow(write) if busy else WriteBehind(write, depth=WRITE_BEHIND)
        failure = None
        index = 0  # frames answered
        taken = deque()  # the frames the detector has taken and not answered yet

        def frames():
            decoded = perturbed(backwards.frames(source.timed_frames()), args.perturb)
            for t, frame in decoded if busy else read_ahead(decoded, depth=READ_AHEAD):
                taken.append((t, frame))
                yield t, frame

        answers = responses(detector, frames())
        try:
            for response in answers:
                t, frame = taken.popleft()
                output.put((index, t, frame, response))
                index += 1
        except FrameError as exc:  # e.g. a bag whose camera changed its resolution
            failure = f"{args.video}: frame {index}: {exc}; results written for the {index} " \
                      "frames before"
        except SourceError as exc:  # a cut or corrupt bag: what was read is written
            failure = f"{exc} (results written for the {index} frames before)"
        except _OutputError as exc:
            output.close(raise_error=False)
            return _fail(str(exc))
        finally:
            answers.close()
            getattr(detector, "close", lambda: None)()
        try:
            output.close()
            _check_annotated(video, args.annotate, len(records))
            if mcap is not None:
                mcap.close()  # its index, written last: a full disk may show only here
        except _OutputError as exc:
            return _fail(str(exc))
        except OSError as exc:
            return _fail(str(exc))
        for flag, path, fh in (("--jsonl", args.jsonl, jsonl), ("--tracks", args.tracks, tracks)):
            try:  # a short run's lines are all still buffered: a full disk shows here
                if fh is not None:
                    fh.flush()
            except BrokenPipeError:  # stdout's reader went away: cli.main ends quietly
                raise
            except OSError as exc:
                with suppress(OSError):  # closed now, its lines dropped: not again at exit
                    fh.close()
                return _fail(f"{flag} {path}: cannot write: {exc.strerror or exc}")
        if failure is not None:
            progress.finish()
            return _fail(failure)
    if not records:
        return _fail(f"{args.video}: no frames decoded")
    if args.plot:
        try:
            plot_responses([r["t"] for r in records], [r["u"] for r in records],
                           [r["spike_rate"] for r in records], [r["collision"] for r in records],
                           args.plot,
                           title=f"{Path(args.video).name} ({args.model}"
                                 + (f", {preset})" if args.model == "asnn" else ")"))
        except (OSError, ValueError) as exc:
            return _fail(f"cannot write {args.plot}: {exc}")
    short = cut_short(source.frame_count, len(records))
    if short:
        print(f"asnn detect: note: {args.video}: {short}", file=sys.stderr)
    warned = sum(r["collision"] for r in records)
    held = (f", {backwards.count} taken at the latest frame's time (header stamp before an "
            "earlier frame's)" if backwards.count else "")
    if backwards.resets:
        held += (f", {backwards.resets} clock reset{'' if backwards.resets == 1 else 's'} "
                 "(timed on from the latest frame's time)")
    if backwards.unset:
        held += (f", {backwards.unset} taken at the latest frame's time (header stamp "
                 "unset)")
    if args.perturb:
        held += f", on frames perturbed: {describe(args.perturb)}"
    print(f"asnn detect: {len(records)} frames, {warned} with a collision warning{held}",
          file=sys.stderr)
    return 0
