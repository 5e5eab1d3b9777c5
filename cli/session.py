"""What every networked command shares: the common Zenoh options, logging, signals, errors."""

from __future__ import annotations

import argparse
import atexit
import contextlib
import logging
import logging.handlers
import os
import queue
import signal
import sys
import threading

from service import keys
from service.config import ConfigError, ZenohOptions, zenoh_error

from .arguments import key_prefix, seconds

__all__ = ["add_zenoh_options", "zenoh_options", "setup_logging", "stop_on_signals",
           "open_session", "zenoh_config", "fail"]


def add_zenoh_options(parser: argparse.ArgumentParser, *, modes=("peer", "client"),
                      watched: bool = False) -> None:
    """The common Zenoh options of every networked command (CONTRACT.md); a command that can
    run in one mode only (the router) takes ``--mode`` with that mode alone, and a
    long-running one that watches its router (``watched``: :func:`router_watch`) takes
    ``--exit-without-router``."""
    group = parser.add_argument_group("Zenoh")
    group.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                       help="endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable)")
    group.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                       help="endpoint to listen on, e.g. tcp/0.0.0.0:7448 (repeatable)")
    group.add_argument("--mode", choices=modes, default=None,
                       help="Zenoh session mode (default: the config's, else peer)"
                       if len(modes) > 1 else f"{modes[0]} only: taken for the contract's "
                       "common options")
    group.add_argument("--config", metavar="FILE", default=None,
                       help="Zenoh JSON5 configuration file (options above override it)")
    group.add_argument("--prefix", default=keys.DEFAULT_PREFIX, type=key_prefix,
                       help="key expression prefix (default: %(default)s)")
    group.add_argument("--log-level", default="info",
                       choices=("debug", "info", "warning", "error"),
                       help="log level on stderr (default: %(default)s)")
    if watched:
        group.add_argument(
            "--exit-without-router", type=seconds, default=None, metavar="SECONDS",
            help=f"exit with status {EXIT_NO_ROUTER} once no router (nor a peer) has been "
                 "reached for SECONDS, from the start or a lost link, so that a supervisor "
                 "(systemd, compose) starts the process again and it reads its configuration "
                 "and credentials again: a router that rotated its CA or password refuses the "
                 "running process for ever (default: retry for ever)")


def zenoh_options(args: argparse.Namespace) -> ZenohOptions:
    """The parsed common options, for :func:`service.config.make_config`."""
    return ZenohOptions(mode=getattr(args, "mode", None), connect=tuple(args.connect),
                        listen=tuple(args.listen), config_file=args.config)


LOG_QUEUE_RECORDS = 10_000
"""Log records a long-running command holds while stderr is slow; beyond them, dropped and
counted."""


class _DroppingQueueHandler(logging.handlers.QueueHandler):
    """Hands each record to the writer thread, and drops it (counted) when that thread is
    :data:`LOG_QUEUE_RECORDS` behind: a logging call never waits for stderr."""

    def __init__(self, records: queue.Queue) -> None:
        super().__init__(records)
        self._lock = threading.Lock()
        self._dropped = 0

    def enqueue(self, record: logging.LogRecord) -> None:
        try:
            self.queue.put_nowait(record)
        except queue.Full:
            with self._lock:
                self._dropped += 1

    def take_dropped(self) -> int:
        with self._lock:
            dropped, self._dropped = self._dropped, 0
        return dropped


LOG_DRAIN_S = 2.0
"""Seconds a process's exit waits, at most, for the records still queued to be written."""
# the Zenoh log target whose DEBUG lines hold the session's configuration, secrets included
QUIET_CONFIG_TARGET = "zenoh::api::session=info"
# the levels of tracing's EnvFilter at INFO or quieter (its numbers: 0 off to 5 trace)
_QUIET_LEVELS = {"off", "error", "warn", "info", "0", "1", "2", "3"}


def _asks_debug(rust_log: str) -> bool:
    """Whether a directive of ``rust_log`` (tracing's EnvFilter: ``target=level``, a bare
    ``level``, or a bare ``target``, which enables every level of it) may enable DEBUG."""
    for directive in filter(None, (d.strip() for d in rust_log.split(","))):
        level = directive.rpartition("=")[2].strip().lower()
        if level not in _QUIET_LEVELS:  # debug, trace, 4, 5, or a bare target
            return True
    return False


class _LogWriter:
    """The thread that writes the queued records to stderr, through a descriptor of its own
    (a copy of stderr's) with plain ``os.write``: a write blocked on a stderr nobody reads holds
    no lock that the exit, logging's shutdown or another thread's print would wait for. Says
    how many records were dropped before the next one it writes."""

    def __init__(self, records: queue.Queue, dropped_by: _DroppingQueueHandler,
                 formatter: logging.Formatter) -> None:
        self.records, self.dropped_by, self.formatter = records, dropped_by, formatter
        try:
            self.fd: int | None = os.dup(sys.stderr.fileno())
        except (AttributeError, OSError, ValueError):  # a stream without a descriptor
            self.fd = None
        self.thread = threading.Thread(target=self._run, daemon=True, name="asnn-log-writer")
        self.thread.start()

    def _run(self) -> None:
        while True:
            record = self.records.get()
            self._say_dropped()
            if record is None:  # the exit's: what was queued before it is written
                return
            self._write(self.formatter.format(record))

    def _say_dropped(self) -> None:
        dropped = self.dropped_by.take_dropped()
        if dropped:
            self._write(self.formatter.format(logging.makeLogRecord({
                "name": "asnn.logging", "levelno": logging.WARNING, "levelname": "WARNING",
                "msg": f"{dropped} log records dropped: stderr was too slow"})))

    def _write(self, text: str) -> None:
        data = (text + "\n").encode("utf-8", "backslashreplace")
        try:
            if self.fd is None:
                sys.stderr.write(data.decode("utf-8"))
                sys.stderr.flush()
                return
            while data:
                data = data[os.write(self.fd, data):]
        except (OSError, ValueError):  # stderr closed, or a pipe nobody reads any more
            pass

    def close(self) -> None:
        """At exit: let the writer finish what is queued, for at most :data:`LOG_DRAIN_S`
        seconds (a stderr nobody reads must not hold the process; the thread is a daemon)."""
        try:
            self.records.put(None, timeout=LOG_DRAIN_S)
        except queue.Full:
            return
        self.thread.join(LOG_DRAIN_S)


def setup_logging(args: argparse.Namespace) -> None:
    """Log at ``--log-level`` on stderr, written by a thread of its own: the worker logs from
    Zenoh's receiving thread and its processing threads, and a stderr that blocks (a full
    pipe, a stalled journal) must not stall them. At most :data:`LOG_QUEUE_RECORDS` records
    wait; beyond them records are dropped and the count is logged when writing resumes. At exit
    what waits is written, for at most :data:`LOG_DRAIN_S` seconds (a process ended at once by
    :func:`exit_on_interrupt` loses what waits). Does nothing when the root logger is already
    configured (as :func:`logging.basicConfig`)."""
    import zenoh

    root = logging.getLogger()
    if not root.handlers:
        records = queue.Queue(LOG_QUEUE_RECORDS)
        handler = _DroppingQueueHandler(records)
        writer = _LogWriter(records, handler, logging.Formatter(
            "%(asctime)s %(name)s %(levelname)s %(message)s"))
        atexit.register(writer.close)
        root.addHandler(handler)
        root.setLevel(args.log_level.upper())
    rust_log = os.environ.get("RUST_LOG", "")
    if _asks_debug(rust_log):
        # Zenoh (1.10) logs the session's whole configuration at DEBUG, a usrpwd password with
        # it, into the journal: that one target stays at INFO, whatever else RUST_LOG asks
        os.environ["RUST_LOG"] = rust_log + "," + QUIET_CONFIG_TARGET
    zenoh.try_init_log_from_env()  # Zenoh's own logs only when RUST_LOG is set


# seconds an interrupted compile's exit waits for its buffered output to be taken
FLUSH_GRACE = 2


@contextlib.contextmanager
def exit_on_interrupt():
    """Within the block, Ctrl-C ends the process at once, with the status and line of an
    interrupt (130), and SIGTERM with its own (143). For work before anything needs an orderly
    close (a worker compiling its kernels before it joins the fleet): a KeyboardInterrupt
    raised there can be lost, since
    numba's compiler calls back from C through ctypes, which prints and ignores an exception
    raised in the callback, and the compile would go on for up to a minute."""
    def handler(signum, frame):
        term = signum == signal.SIGTERM  # docker stop's grace is 10 s: not a minute's compile
        status = 143 if term else 130
        # a flush into a full pipe nobody reads blocks for ever (and so would the line after
        # it, into the same pipe): it has FLUSH_GRACE seconds, then the process ends unsaid
        signal.signal(signal.SIGALRM, lambda *_: os._exit(status))
        signal.alarm(FLUSH_GRACE)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        # written past Python's buffered streams: the handler runs between two bytecodes of
        # the main thread, which may be inside a write to one (a reentrant call raises there)
        with contextlib.suppress(OSError):
            os.write(2, f"\nasnn: {'terminated' if term else 'interrupted'}\n".encode())
        os._exit(status)

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


@contextlib.contextmanager
def signals_held():
    """Ctrl-C and SIGTERM held for the block, then given to the handlers in place before it:
    for a step whose parts must all be done or none (a frame's lines in every output). On the
    main thread only (the only one Python's handlers run on); elsewhere, the block as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held, previous = {}, {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):  # each restored below once installed
            previous[sig] = signal.signal(
                sig, lambda signum, frame: held.setdefault(signum, frame))
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
        if held:  # SIGTERM before Ctrl-C where both came: the process is to end terminated
            signum = signal.SIGTERM if signal.SIGTERM in held else signal.SIGINT
            handler = previous[signum]
            if callable(handler):
                handler(signum, held[signum])
            elif handler == signal.SIG_DFL:
                signal.raise_signal(signum)


def stop_on_signals() -> threading.Event:
    """An event set by SIGINT or SIGTERM (docker stop), for a clean shutdown.

    The event is set by a thread started here, which the handler wakes through a
    ``queue.SimpleQueue`` (whose ``put`` is reentrant and never blocks): a handler runs on the
    main thread between two of its bytecodes, and ``Event.set`` there deadlocked (now and then,
    for ever) where the signal came while the main thread held the event's lock, inside its
    ``stop.wait(...)``. The handler starts no thread either: from Python 3.12 that raises
    (``can't create new thread at interpreter shutdown``) for a signal that comes during the
    exit's log drain, out of the ``atexit`` callback it interrupted."""
    stop = threading.Event()
    signals: queue.SimpleQueue = queue.SimpleQueue()

    def set_on_signal() -> None:
        signals.get()
        stop.set()

    threading.Thread(target=set_on_signal, name="stop-on-signal", daemon=True).start()

    def handler(signum, frame):
        signals.put(signum)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, handler)
    return stop


def open_session(config):
    """zenoh.open, with Zenoh's failures (no router reachable, port taken) as one clear line;
    where it could not connect, why (:func:`service.diagnosis.connect_failure`)."""
    import zenoh

    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        message = f"cannot open a Zenoh session: {zenoh_error(exc)}"
        if "Unable to connect" in str(exc):
            from service.diagnosis import connect_failure

            why = connect_failure(config)
            if why:
                message += f" ({why})"
        raise ConfigError(message) from None


def zenoh_config(args: argparse.Namespace):
    """The Zenoh configuration a command's common options describe (raises ConfigError): made
    once, for its session (:func:`open_session`) and its :func:`router_watch`, so that the
    watch diagnoses the configuration the session was opened with, not the config file as it
    reads later."""
    from service.config import make_config

    return make_config(zenoh_options(args))


EXIT_NO_ROUTER = 3
"""The exit status of a command whose ``--exit-without-router`` time passed."""


def router_watch(session, name: str, config, on_change=None, args=None, stop=None):
    """A :class:`service.link.RouterWatch` of a command's session that, while its router stays
    lost, logs why a session of the command's options could not connect
    (:func:`service.diagnosis.connect_failure`: the router back with another CA, certificate
    or password, which Zenoh retries silently for ever), and at start and once a day which of
    its certificates expire soon (:func:`service.diagnosis.expiring_certificates`); ``config``
    is the one the session was opened with (:func:`zenoh_config`). With the command's ``args``
    holding ``--exit-without-router``, the watch gives up after it (:attr:`RouterWatch.
    gave_up`) and sets ``stop``; the command then ends with :data:`EXIT_NO_ROUTER`."""
    from service.diagnosis import connect_failure, expiring_certificates
    from service.link import RouterWatch

    return RouterWatch(session, name, on_change=on_change,
                       diagnose=lambda: connect_failure(config),
                       certificates=lambda: expiring_certificates(config),
                       give_up_after=getattr(args, "exit_without_router", None),
                       on_give_up=None if stop is None else stop.set)


def fail(command: str | None, message: str, status: int = 2) -> int:
    """Print a one-line error naming the command that failed, ``asnn COMMAND: MESSAGE`` (as
    ``asnn detect``, ``asnn eval`` and the other commands say theirs: among several commands'
    lines in one journal or ``docker compose logs``, the one that failed), and return the exit
    status. ``command`` is the sub-command's name (``args.command``); None for an error of
    ``asnn`` itself, before a command is known: ``asnn: error: MESSAGE``, as argparse says
    its own."""
    lead = "asnn: error" if command is None else f"asnn {command}"
    print(f"{lead}: {message}", file=sys.stderr, flush=True)
    return status
