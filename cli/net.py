"""The networked commands: camera, worker, alerts, status, router and the one-process demo."""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
from pathlib import Path

from asnn.io.files import folder_problem, make_folders, remove_folders
from asnn.params import preset_names
from service import keys
from service.config import ConfigError, zenoh_error

from .arguments import (count, fleet_size, frame_rate, mcap_output, megabytes, non_negative,
                        nonempty_path, preset_spec, robot_id, seconds, seconds_or_zero, threads,
                        warmup_frames, worker_id)
from .session import EXIT_NO_ROUTER, add_zenoh_options, exit_on_interrupt, fail, open_session, \
    router_watch, setup_logging, stop_on_signals, zenoh_config, zenoh_options

__all__ = ["register"]

log = logging.getLogger("asnn")
RECORD_CLOSE_TIMEOUT = 30.0  # seconds the camera's exit waits for its recording to be finished


# ---------------------------------------------------------------- commands

def cmd_camera(args: argparse.Namespace) -> int:
    from service.camera import (RECORD_MAX_BYTES, RefusalNotices, SourceError, SourceRejections,
                                SubscriberWatch, open_recording, open_source, publish_frames,
                                recording_topic)

    setup_logging(args)
    if args.record_max_mb is not None and args.record is None:
        return fail(args.command,
                    "--record-max-mb bounds a recording: give it with --record OUT.mcap")
    if args.record:
        try:  # the 'ros' extra, said before anything opens
            import asnn.io.bag_recording  # noqa: F401
        except ImportError as exc:  # the message names the extra to install
            return fail(args.command, str(exc))
        try:  # a topic ROS 2 would refuse (a long --prefix), said before anything opens too
            recording_topic(args.robot, args.prefix)
        except ValueError as exc:
            return fail(args.command, str(exc))
        problem = folder_problem(Path(args.record).parent)  # made later, where it is missing
        if problem:
            return fail(args.command, f"--record {args.record}: {problem}")
    rejections, refusals = SourceRejections(args.robot), RefusalNotices(args.robot)
    subscribers = SubscriberWatch(args.robot, keys.frame_key(args.robot, args.prefix))
    try:
        source = open_source(args.source, on_error=rejections)
        config = zenoh_config(args)
        session = open_session(config)
    except (SourceError, ConfigError) as exc:
        return fail(args.command, str(exc))
    stop = stop_on_signals()
    with session, router_watch(session, f"camera {args.robot}", config, args=args,
                               stop=stop) as watch:
        recording = None
        if args.record:  # made last: a camera that cannot start leaves no file behind
            bound = RECORD_MAX_BYTES if args.record_max_mb is None else args.record_max_mb * 1e6
            try:  # its folders too, as asnn detect makes its outputs'
                made = make_folders(Path(args.record).parent)
            except OSError as exc:
                return fail(args.command,
                            f"cannot make the folder {exc.filename}: {exc.strerror or exc}")
            try:
                recording = open_recording(args.record, args.robot, prefix=args.prefix,
                                           format=args.format, frame_id=source.frame_id,
                                           max_bytes=bound)
            except OSError as exc:  # nor the folders it made for the file (a full disk)
                remove_folders(made)
                return fail(args.command, str(exc))
        try:
            count = publish_frames(session, args.robot, source, prefix=args.prefix,
                                   fps=args.fps, loop=args.loop, format=args.format,
                                   wait=args.wait, stop=stop, preview_hz=args.preview_hz,
                                   refusals=refusals, subscribers=subscribers,
                                   recording=recording)
        except OSError as exc:  # a live source's frame the wire cannot carry (VideoError)
            return fail(args.command, str(exc))
        finally:  # finished (its index and summary) however the camera stops
            if recording is not None:
                _close_recording(recording, args.robot)
                if not recording.path.exists():  # no frame recorded: nor its new folders
                    remove_folders(made)
    unheard = (f" ({subscribers.unheard} while no subscriber took them: lost)"
               if subscribers.unheard else "")
    log.info("camera %s: %d frames published%s; %s; workers' refusals on its key "
             "(of any publisher's frames): %s",
             args.robot, count, unheard, rejections.summary(), refusals.summary())
    return EXIT_NO_ROUTER if watch.gave_up else 0


def _close_recording(recording, robot: str) -> None:
    """Finish the camera's recording and say what it holds (or why it could not be finished)."""
    error = recording.close(timeout=RECORD_CLOSE_TIMEOUT)
    if recording.writing:  # a disk that hangs must not hang the camera's exit
        log.error("camera %s: recording to %s: still writing after %.0f s; left unfinished "
                  "(`mcap recover` repairs it)", robot, recording.path, RECORD_CLOSE_TIMEOUT)
        return
    if error is not None and recording.stopped != "failed":  # a stop said it already
        log.error("camera %s: recording to %s: %s", robot, recording.path,
                  error.strerror or error)
    if recording.frames == 0:  # stopped before its first frame (Ctrl-C while it waited for a
        # worker): kept, a bag that replays nothing made the same command's rerun fail (exists)
        try:
            os.unlink(recording.path)
        except OSError as exc:
            log.warning("camera %s: recorded no frame; %s could not be removed: %s", robot,
                        recording.path, exc.strerror or exc)
            return
        log.info("camera %s: recorded no frame; %s not kept", robot, recording.path)
        return
    log.info("camera %s: recorded %d frames (%.1f MB) to %s", robot, recording.frames,
             recording.size / 1e6, recording.path)


def cmd_worker(args: argparse.Namespace) -> int:
    from service.core import WorkerCore
    from service.worker import Worker, WorkerIdTaken, check_scan, tune_process

    setup_logging(args)
    try:
        check_scan(args.scan_interval)
        core = WorkerCore(args.model, args.preset, worker_id=args.id, prefix=args.prefix,
                          idle_timeout=args.idle_timeout, max_gap=args.max_gap,
                          max_robots=args.max_robots, takeover_after=args.takeover_after,
                          warmup_frames=args.warmup_frames)
        config = zenoh_config(args)
        session = open_session(config)
    except (ValueError, ImportError) as exc:  # ConfigError is a ValueError
        return fail(args.command, str(exc))
    tune_process()
    with session, router_watch(session, f"worker {core.worker_id}", config,
                               args=args) as watch:
        worker = Worker(session, core, threads=args.threads, scan_interval=args.scan_interval,
                        handover_timeout=args.handover_timeout)
        try:
            worker.check_id()  # before the kernels, which a refused worker need not load
            with exit_on_interrupt():  # a cold compile takes under a minute
                worker.load_kernels()
            stop = stop_on_signals()
            worker.start()
        except WorkerIdTaken as exc:
            worker.close()
            return fail(args.command, f"{exc}; give each worker its own --id")
        try:
            print(f"worker {core.worker_id} ready", file=sys.stderr, flush=True)
            while not stop.wait(0.2) and not watch.gave_up:
                pass
        finally:
            worker.close()  # hands the robots over, warm
    log.info("worker stopped: %s", core.stats())
    return EXIT_NO_ROUTER if watch.gave_up else 0


def cmd_status(args: argparse.Namespace) -> int:
    import json

    from collections import Counter

    from service.worker import status_replies

    setup_logging(args)
    try:
        session = open_session(zenoh_config(args))
    except ConfigError as exc:
        return fail(args.command, str(exc))
    keep = None
    if args.local:
        from service.core import started_here as keep
    with session:
        statuses = status_replies(session, args.prefix, args.worker, timeout=args.timeout,
                                  keep=keep)
    readable = 0
    for status in sorted(statuses, key=lambda s: s["worker"]):
        worker = status["worker"]
        # anything on the prefix may answer: a map this asnn cannot read is said on stderr, and
        # neither hides the others' nor passes a health check
        try:
            line = format_status(status)
            if args.json:
                line = json.dumps(status, separators=(", ", ": "), allow_nan=False)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            print(_printable(f"worker {worker}: a status this asnn cannot read "
                             f"({type(exc).__name__}: {exc})"), file=sys.stderr)
            continue
        readable += 1
        print(_printable(line), flush=True)
    # one id answered by processes of different instances (a map without one says nothing)
    instances = Counter((s["worker"], s["instance"]) for s in statuses
                        if isinstance(s.get("instance"), str))
    twins = sorted(w for w, n in Counter(w for w, _ in instances).items() if n > 1)
    for worker in twins:  # a health check fails on them: every frame answered twice
        print(_printable(f"worker {worker}: answered by more than one process (two workers "
                         "with one id both serve its robots; stop one)"), file=sys.stderr)
    # workers that run different detectors: a robot handed over between them is answered by
    # another model from then on (warnings, ids and ttc change at the hand-over); a rolling
    # change of preset passes through this, so it is said, not failed
    detectors = {}
    for status in statuses:
        if isinstance(status.get("model"), str) and isinstance(status.get("preset"), str):
            detectors.setdefault(f"{status['model']}/{status['preset'] or '-'}",
                                 []).append(str(status["worker"]))
    if len(detectors) > 1:
        kinds = "; ".join(f"{kind} on {', '.join(sorted(workers))}"
                          for kind, workers in sorted(detectors.items()))
        print(_printable(f"workers run different detectors ({kinds}): a robot handed over "
                         "between them is answered by another model"), file=sys.stderr)
    if twins:
        return 1
    if not readable:
        key = (keys.worker_status_key(args.worker, args.prefix) if args.worker
               else keys.worker_statuses(args.prefix))
        if args.local:
            from service.core import worker_host

            print(f"no worker of this host ({worker_host()}-<pid>) answered on {key}",
                  file=sys.stderr)
        else:
            print(f"no worker answered on {key}", file=sys.stderr)
        return 1
    return 0


def _printable(text: str) -> str:
    """``text`` with its control characters escaped (a worker's id or a robot's can carry
    none, but a status from anything else on the prefix can carry a terminal's commands)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _clipped(text: str, length: int) -> str:
    """``text`` cut to ``length`` characters, ending in an ellipsis where it was cut."""
    return text if len(text) <= length else text[:length - 1] + "…"


def format_status(status: dict) -> str:
    """One line of ``asnn status``: a worker's identity, robots, counters and what it refused.

    Robots on whose key a second publisher was seen are listed under ``contested`` with the
    number of intrusions (docs/operations.md); the frames and bytes Zenoh delivered to the
    worker follow ``frames in`` (those of the discovery scan in brackets); robots whose frames
    are detected at fewer than ``SLOW_FPS`` a second are listed under ``slow`` (and those whose
    stamps tell the model no rate, a camera slower than a frame a second among them, under
    ``untimed``), those from which no frame has come for more than ``STALE_S`` (the
    dashboard's stale) under ``silent``, and those with a frame refused in the last minute
    under ``refused lately``, with the latest reason; fields an older worker does not report
    are left out.
    """
    from asnn.params import SLOW_FPS
    from clients.fleet import STALE_S

    stats = status["stats"]
    traffic = status.get("traffic")
    received = "" if traffic is None else (
        f"frames in {traffic['frames']} ({traffic['bytes'] / 1e6:.1f} MB; scanned "
        f"{traffic['scanned_frames']}, {traffic['scanned_bytes'] / 1e6:.1f} MB); ")
    robots = status.get("robots", {})
    invalid = ", ".join(f"{k} {v}" for k, v in sorted(stats["invalid"].items())) or "none"
    tracked = [r for r, s in robots.items() if not s.get("candidate")]
    contested = ", ".join(f"{r} ({s.get('intrusions', 0)} intrusions)"
                          for r, s in robots.items() if s.get("contested")) or "none"
    slow = ", ".join(f"{r} ({s['fps']:g} fps)" for r, s in robots.items()
                     if s.get("fps") is not None and s["fps"] < SLOW_FPS)
    untimed = ", ".join(r for r, s in robots.items() if s.get("untimed"))
    silent = ", ".join(f"{r} ({s['idle_s']:.0f} s)" for r, s in robots.items()
                       if s.get("idle_s", 0) > STALE_S)
    # robots refused in the last minute, the latest first: why a camera gets no response (not a
    # robot refused for want of a place that has one now)
    # (``count`` is every refusal of the robot's, for any reason: the latest reason is one)
    refused = ", ".join(f"{r} ({e['count']} refused, the latest {e['reason']}: "
                        f"{_clipped(e['detail'], 60)})"
                        for r, e in reversed(status.get("refused", {}).items())
                        if e.get("seconds_ago", 0) <= 60
                        and not (e["reason"] == "too-many-robots" and r in tracked))
    return (f"worker {status['worker']}: {status['model']}/{status['preset'] or '-'}, up "
            f"{status['uptime_s']:.0f} s, robots {', '.join(tracked) or 'none'}"
            f" (+{stats.get('candidates', 0)} waiting for a valid frame); "
            f"processed {stats['processed']}, dropped {stats['dropped']}, warnings "
            f"{stats['warnings']}, foreign {stats['foreign']}; {received}invalid: {invalid}; "
            f"second publishers: {stats.get('intrusions', 0)}, contested: {contested}; "
            + (f"slow: {slow}; " if slow else "")
            + (f"untimed (stamps no frame period: under 1 fps, or not seconds): {untimed}; "
               if untimed else "")
            + (f"silent (no frame for over {STALE_S:g} s): {silent}; " if silent else "")
            + (f"refused lately: {refused}; " if refused else "")
            + f"live workers {', '.join(status.get('workers', []))}")


def cmd_alerts(args: argparse.Namespace) -> int:
    from clients.alerts import LinePrinter, WarningListener

    setup_logging(args)
    try:
        config = zenoh_config(args)
        session = open_session(config)
    except ConfigError as exc:
        return fail(args.command, str(exc))
    stop = stop_on_signals()
    show = LinePrinter(args.json, sys.stdout, on_error=stop.set)
    with session, router_watch(session, "alerts", config, args=args, stop=stop) as watch, \
            WarningListener(session, show, prefix=args.prefix, robot=args.robot) as listener:
        print(f"listening on {listener.key}", file=sys.stderr, flush=True)
        while not stop.wait(0.5):
            pass
    return _printed(show, args.command) or (EXIT_NO_ROUTER if watch.gave_up else 0)


def _printed(show, command: str) -> int:
    """The exit status once ``command``'s warnings are printed (or could not be): 141 when the
    reader of standard output went away (as ``cli.main`` ends a command on a broken pipe), 1
    when a write failed otherwise or the output still blocks after two seconds."""
    flushed = show.close()
    if isinstance(show.error, BrokenPipeError):
        raise BrokenPipeError  # cli.main: quietly, with the status of the pipe's signal
    if show.error is not None:
        return fail(command, f"cannot write the warnings: {show.error.strerror or show.error}",
                    1)
    if not flushed:
        # the writing thread holds standard output: Python's own flush at exit would wait on it
        os._exit(fail(command, f"the output is not read: {show.unprinted} warnings not printed",
                      1))
    return 0


def cmd_router(args: argparse.Namespace) -> int:
    import zenoh

    from service.diagnosis import expiring_certificates
    from service.link import CertificateCheck
    from service.router import listen_endpoints, router_config

    setup_logging(args)
    stop = stop_on_signals()
    try:
        config = router_config(zenoh_options(args))
        session = zenoh.open(config)
    except ConfigError as exc:
        return fail(args.command, str(exc))
    except Exception as exc:  # zenoh.ZError: e.g. the port is taken, a file it cannot read
        from service.diagnosis import unreadable_files

        why = unreadable_files(config)
        return fail(args.command, f"cannot start the router: {zenoh_error(exc)}"
                    + (f" ({why})" if why else ""))
    with session:
        listen = ", ".join(listen_endpoints(config))
        print(f"router {session.zid()} listening on {listen}", file=sys.stderr, flush=True)
        # its certificate's end locks every client out at its next connection: said ahead
        certificates = CertificateCheck("router", lambda: expiring_certificates(config),
                                        logger=logging.getLogger("asnn.router"))
        while True:
            certificates.tick()
            if stop.wait(0.5):
                break
    print("router stopped", file=sys.stderr, flush=True)  # the clients now lose it: say when
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from clients.alerts import LinePrinter, WarningListener
    from service.camera import open_source
    from service.core import WorkerCore
    from service.demo import run_pipeline

    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="%(name)s %(levelname)s %(message)s")
    try:
        core = WorkerCore(args.model, args.preset)
        source = open_source(f"synthetic:{args.scene}")
    except (ValueError, ImportError, OSError) as exc:
        return fail(args.command, str(exc))
    info = sys.stderr if args.json else sys.stdout
    print(f"asnn demo: camera -> worker ({core.model}, preset {core.preset or '-'}) -> alerts, "
          f"scene {args.scene!r}, {source.fps:g} fps, over Zenoh on 127.0.0.1", file=info,
          flush=True)
    stop = threading.Event()  # set when the warnings can no longer be printed (| head)
    show = LinePrinter(args.json, sys.stdout, on_error=stop.set)
    result = run_pipeline(source, core, lambda s: WarningListener(s, show), fps=args.fps,
                          stop=stop)
    status = _printed(show, args.command)
    print(f"{result['published']} frames published, {result['responses']} responses, "
          f"{result['received']} warnings received", file=info, flush=True)
    return status


# ---------------------------------------------------------------- registration

def _add_preset_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", type=preset_spec, default=None, metavar="NAME[/FIELD=VALUE...]",
                   help=f"ASNN parameter preset ({', '.join(preset_names())}), with any fields "
                        "changed after slashes (robust/ignore_rig=false; default: the default "
                        "preset)")


def register(subparsers) -> None:
    from asnn.detectors import MODELS
    from asnn.stimuli import SCENE_NAMES
    from service.camera import PREVIEW_HZ
    from service.core import (HANDOVER_WARMUP_FRAMES, IDLE_TIMEOUT_S, MAX_GAP, MAX_ROBOTS,
                              TAKEOVER_AFTER_S, default_threads)
    from service.demo import DEMO_SCENE
    from service.messages import FORMATS
    from service.worker import HANDOVER_TIMEOUT, SCAN_INTERVAL, SCAN_WINDOW

    p = subparsers.add_parser("camera", help="publish a camera's frames",
                              description="Publish frames of a video file, a capture device, "
                              "a stream URL, a generated scene or a ROS 2 bag on "
                              "<prefix>/<robot>/frame.")
    p.add_argument("--robot", required=True, type=robot_id, help="robot id ([A-Za-z0-9_-]{1,64})")
    p.add_argument("--source", required=True, type=nonempty_path,
                   help="FILE, DEVICE_INDEX, URL, synthetic:SCENE "
                        f"(SCENE: {', '.join(SCENE_NAMES)}, or a case of the labelled suite: "
                        "asnn scene --list) or a ROS 2 bag BAG.mcap[#TOPIC], replayed at its "
                        "recorded pace")
    p.add_argument("--fps", type=frame_rate, default=None,
                   help="publishing rate (default: the source's frame rate). A replayed file, "
                        "scene or bag is played and stamped at it: at another rate than its "
                        "own the detector sees the scene sped up or slowed down (a 30 fps clip "
                        "at 20 is slow motion, and warns later or not at all); a live source "
                        "is thinned out to it")
    p.add_argument("--loop", action="store_true", help="replay a file, scene or bag forever")
    p.add_argument("--format", choices=FORMATS, default="gray8",
                   help="frame encoding on the wire (default: %(default)s)")
    p.add_argument("--wait", type=seconds_or_zero, default=2.0, metavar="SECONDS",
                   help="wait up to SECONDS for a subscriber before the first frame "
                        "(default: %(default)s)")
    p.add_argument("--preview-hz", type=non_negative, default=PREVIEW_HZ, metavar="HZ",
                   help="thumbnails per second on <prefix>/<robot>/preview for dashboards "
                        "(docs/contract.md; default: %(default)s; 0: none)")
    p.add_argument("--record", type=mcap_output, default=None, metavar="OUT.mcap",
                   help="also record every frame published, as sent and with its stamp, to this "
                        "new file: a ROS 2 bag (topic /<prefix>/<robot>/frame, a robot id's - "
                        "as _) that asnn detect and asnn camera --source replay "
                        "(docs/foxglove.md; the 'ros' extra); its folder is made where "
                        "missing, once the source and the session open; finished when the "
                        "camera stops")
    p.add_argument("--record-max-mb", type=megabytes, default=None, metavar="MB",
                   help="stop recording once the file reaches this size; the camera publishes "
                        "on (default: 1000)")
    add_zenoh_options(p, watched=True)
    p.set_defaults(func=cmd_camera)

    p = subparsers.add_parser("worker", help="run the detector on every robot's frames",
                              description="Subscribe to the frames of the robots this worker "
                              "serves (<prefix>/<robot>/frame; with several workers on a prefix, "
                              "each serves its share) and publish a response per processed frame "
                              "and a warning per collision.")
    p.add_argument("--model", choices=MODELS, default="asnn", help="detector (default: asnn)")
    _add_preset_option(p)
    p.add_argument("--id", type=worker_id, default=None,
                   help="worker id reported in responses (default: <host>-<pid>)")
    p.add_argument("--idle-timeout", type=seconds, default=IDLE_TIMEOUT_S, metavar="SECONDS",
                   help="forget a robot after SECONDS without frames (default: %(default)s)")
    p.add_argument("--max-gap", type=count, default=MAX_GAP, metavar="N",
                   help="reset a robot's state when seq jumps ahead by more than N of the "
                        "robot's steps (1, or the growth of its seq that three frames in a row "
                        "agree on; 1: any frame lost resets; default: %(default)s)")
    p.add_argument("--max-robots", type=fleet_size, default=MAX_ROBOTS, metavar="N",
                   help="robots tracked at once; frames of more are rejected. A robot takes "
                        "a place once one of its frames is valid (default: %(default)s)")
    p.add_argument("--takeover-after", type=seconds, default=TAKEOVER_AFTER_S,
                   metavar="SECONDS",
                   help="once a second publisher was seen on a robot's key, refuse frames that "
                        "do not continue the robot's stream until it has been silent for "
                        "SECONDS (default: %(default)s)")
    p.add_argument("--threads", type=threads, default=default_threads(), metavar="N",
                   help="processing threads (default: the cores available, here %(default)s; "
                        "one robot is never processed by two at once)")
    p.add_argument("--warmup-frames", type=warmup_frames, default=HANDOVER_WARMUP_FRAMES,
                   metavar="N",
                   help="frames a worker taking a robot over steps silently before it answers, "
                        "while the previous owner still answers (default: %(default)s, "
                        "measured for the default preset: asnn bench --handover)")
    p.add_argument("--handover-timeout", type=seconds_or_zero, default=HANDOVER_TIMEOUT,
                   metavar="SECONDS", help="when stopping, answer the robots until their new "
                   "owners are warm, at most SECONDS (default: %(default)s)")
    p.add_argument("--scan-interval", type=seconds_or_zero, default=SCAN_INTERVAL,
                   metavar="SECONDS", help="with several workers, one of them looks for cameras "
                   "that do not announce themselves every SECONDS, receiving every frame for "
                   f"{SCAN_WINDOW:g} s (default: %(default)s; 0: serve only announced robots, "
                   "as asnn camera's are, so that each frame reaches one worker)")
    add_zenoh_options(p, watched=True)
    p.set_defaults(func=cmd_worker)

    p = subparsers.add_parser("status", help="ask the workers for their status",
                              description="Query <prefix>/@worker/<id>/status: each worker's "
                              "counters (rejected frames per reason, dropped frames), robots "
                              "and the live workers. Exit status 1 when no worker answers, or when "
                              "two processes answer for one worker id.")
    only = p.add_mutually_exclusive_group()
    only.add_argument("--worker", type=worker_id, default=None,
                      help="only this worker (default: all)")
    only.add_argument("--local", action="store_true",
                      help="only the workers of this host that have the default id, "
                           "<host>-<pid>: in a container, whose host name is its own, its "
                           "worker (a health check)")
    p.add_argument("--json", action="store_true", help="one JSON object per worker")
    p.add_argument("--timeout", type=seconds, default=2.0, metavar="SECONDS",
                   help="how long to wait for answers (default: %(default)s)")
    add_zenoh_options(p)
    p.set_defaults(func=cmd_status)

    p = subparsers.add_parser("alerts", help="print the fleet's collision warnings",
                              description="Subscribe to <prefix>/<robot>/warning; one line per "
                              "warning. A late subscriber first receives each robot's latest.")
    p.add_argument("--robot", type=robot_id, default=None, help="only this robot (default: all)")
    p.add_argument("--json", action="store_true", help="JSON lines (the Response fields)")
    add_zenoh_options(p, watched=True)
    p.set_defaults(func=cmd_alerts)

    p = subparsers.add_parser("router", help="run a Zenoh router (for machines without zenohd)",
                              description="A Zenoh router from the Python package; robots, "
                              "workers and subscribers --connect to it. It routes every key: "
                              "--prefix, common to the networked commands (CONTRACT.md), "
                              "changes nothing here.")
    add_zenoh_options(p, modes=("router",))
    p.set_defaults(func=cmd_router)

    p = subparsers.add_parser("demo", help="camera, worker and alerts in one process",
                              description="Play a generated scene through the whole pipeline "
                              "over in-process Zenoh sessions and print the warnings.")
    p.add_argument("--scene", default=DEMO_SCENE,
                   help="generated scene: one of the paper's (" + ", ".join(SCENE_NAMES) + ") "
                   "or a case of the labelled suite (asnn scene --list); default "
                   "%(default)s, a dark disk coming at the camera at constant speed, so the "
                   "warnings' time to contact counts down as it nears")
    p.add_argument("--fps", type=frame_rate, default=None,
                   help="playback rate (default: the scene's, 20)")
    p.add_argument("--model", choices=MODELS, default="asnn", help="detector (default: asnn)")
    _add_preset_option(p)
    p.add_argument("--json", action="store_true", help="print the warnings as JSON lines")
    p.set_defaults(func=cmd_demo)
