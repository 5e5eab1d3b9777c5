"""Entry point of the ``asnn`` command: one sub-command per module of this package."""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import os
import signal
import sys
import threading

# Each module defines ``register(subparsers)``, adding its sub-commands with ``func`` set.
COMMAND_MODULES = ["cli.detect", "cli.scene", "cli.net", "cli.evaluate", "cli.label", "cli.bench",
                   "cli.dashboard", "cli.foxglove"]


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose errors are one line, as the commands' own are: the option's
    message and where the usage is, not the usage itself (a long block for some commands)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)  # `detect --json X` was taken as --jsonl X
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The full parser (also used by tests to check docker-compose commands)."""
    from asnn import __version__

    parser = _Parser(
        prog="asnn", description="Approach-Sensitive Neural Network collision detection",
        # the help texts name documents (docs/*.md) that a wheel does not install
        epilog="The documents the commands' help names (README.md, docs/*.md, examples/) are in "
               "the source distribution and the repository, not in an installed wheel.")
    # the version to name when citing results (CITATION.cff) or reporting a bug
    parser.add_argument("--version", action="version", version=f"asnn {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    parser.commands = sub.choices  # each sub-command's own parser, by name
    return parser


def wide_vector_features(host_features: str) -> str | None:
    """Numba's CPU features for a process that prefers 512-bit vectors, or None where the
    processor has none (no AVX-512F).

    LLVM vectorises for 256-bit registers by default even where the processor has 512-bit ones
    ("prefer-256-bit"); numba only takes the other choice process-wide, from
    ``NUMBA_CPU_FEATURES`` read when it is imported. Without ``fastmath`` the width changes no
    result, only the time (``tests/test_detect_cli.py``).
    """
    if "+avx512f" not in host_features.split(","):
        return None
    return host_features + ",-prefer-256-bit"


def _prefer_wide_vectors() -> None:
    """Let numba use 512-bit vectors in this process (``asnn detect``: the fused pass is about
    9 % faster with them), unless the user set ``NUMBA_CPU_FEATURES`` or numba is already
    imported (``main`` called in-process), where it would not apply."""
    if "NUMBA_CPU_FEATURES" in os.environ or "numba" in sys.modules:
        return
    import llvmlite.binding as llvm

    features = wide_vector_features(llvm.get_host_cpu_features().flatten())
    if features is not None:
        os.environ["NUMBA_CPU_FEATURES"] = features


def _parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    """The command line's arguments. A sub-command that sets ``intermixed`` (several
    positionals, as ``asnn scene NAME OUT``) is parsed again with its options allowed between
    them, which argparse's one pass cannot do (``asnn scene looming --polarity light out.mp4``
    would leave ``out.mp4`` unrecognised)."""
    args, extras = parser.parse_known_args(argv)
    if not extras:
        return args
    if getattr(args, "intermixed", False):
        return parser.commands[args.command].parse_intermixed_args(argv[1:])
    return parser.parse_args(argv)  # the usual error for what is left


class _Terminated(KeyboardInterrupt):
    """SIGTERM (``timeout``, docker, systemd), raised as Ctrl-C's interrupt is, so that a command
    closes its outputs and ends its processes alike: by default SIGTERM killed it on the spot,
    leaving an unplayable video, an unreadable MCAP, and a benchmark's router and workers or
    an evaluation's pool running on. The networked commands set their own handlers."""


def _raise_terminated(signum, frame):
    raise _Terminated


INTERRUPT_AGAIN_S = 0.05  # the moment after which a lost interrupt is sent again


class _InterruptAgain:
    """A ``sys.unraisablehook`` that raises an interrupt Python ignored once more: raised where
    exceptions cannot propagate (an ``os.fork`` callback, logging's ``_releaseLock`` after a
    pool's fork) it was printed as "Exception ignored" and lost, and an evaluation sent SIGTERM
    ran to its end. Its signal is sent again by a timer's thread, a moment later: sent from
    here, its handler would run at once, here again (``signal.raise_signal``,
    ``_thread.interrupt_main`` and a thread's start, which waits for it, all do); from the
    timer, once this hook has returned, in the command's own code (or, should it land in such
    a place again, sent once more). A command that ends before the timer fires takes the
    interrupt at its end (:meth:`deliver`)."""

    def __init__(self, previous):
        self.previous = previous
        self.pending: tuple[threading.Timer, int] | None = None  # the timer, its signal
        self.sent = False  # whether the timer has sent it

    def __call__(self, unraisable):
        if isinstance(unraisable.exc_value, KeyboardInterrupt):  # _Terminated among them
            signum = (signal.SIGTERM if isinstance(unraisable.exc_value, _Terminated)
                      else signal.SIGINT)
            try:
                timer = threading.Timer(INTERRUPT_AGAIN_S, self._send, (signum,))
                timer.daemon = True
                self.pending, self.sent = (timer, signum), False
                timer.start()
                return
            except RuntimeError:  # no thread at interpreter shutdown: said, as it was
                pass
        self.previous(unraisable)

    def _send(self, signum: int) -> None:
        self.sent = True
        os.kill(os.getpid(), signum)

    def cancel(self) -> int | None:
        """Stop a timer that has not fired; the signal it would have sent, or None."""
        if self.pending is None:
            return None
        timer, signum = self.pending
        timer.cancel()
        timer.join()  # one sending now ends first
        self.pending = None
        return None if self.sent else signum

    def deliver(self) -> None:
        """Raise, at the command's end, an interrupt whose timer has not fired: it would be
        lost with the process, or come once the handlers are restored."""
        signum = self.cancel()
        if signum is not None:
            raise _Terminated if signum == signal.SIGTERM else KeyboardInterrupt


@contextlib.contextmanager
def _sigterm_interrupts():
    try:
        previous = signal.signal(signal.SIGTERM, _raise_terminated)
    except ValueError:  # not the main thread (main() called from a test's thread)
        yield
        return
    previous_hook = sys.unraisablehook
    sys.unraisablehook = again = _InterruptAgain(previous_hook)
    try:
        yield
        again.deliver()
    finally:
        again.cancel()  # a command ending in an error: no signal after its handlers
        signal.signal(signal.SIGTERM, previous)
        sys.unraisablehook = previous_hook


_WRITE_ERRORS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}
# the long-running parts, whose standard output is a line or two a supervisor may close
_SERVICES = {"camera", "worker", "router", "dashboard", "foxglove"}


def _stdout_failed() -> OSError | None:
    """The error standard output gives now, if it fails (a full disk: ``> /dev/full``)."""
    if sys.stdout is None:  # closed, for a service (main's check)
        return None
    try:
        sys.stdout.flush()
    except OSError as exc:
        return exc
    return None


def _quiet_stdout() -> None:
    if sys.stdout is None:
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())  # so that Python's flush at exit fails no more


def main(argv: list[str] | None = None) -> int:
    from cli.session import fail  # the error lines' one form (as the networked commands')

    argv = sys.argv[1:] if argv is None else argv
    if sys.stdout is None and argv[:1] and argv[0] not in _SERVICES:
        # started with standard output closed (>&-): a command's output would be lost
        return fail(None, "standard output is closed")
    for arg in argv:  # bytes of another encoding (a file name): OpenCV crashes on such a path
        try:
            arg.encode("utf-8")
        except UnicodeEncodeError:
            return fail(None, f"{arg!r} is not UTF-8 text (rename the file)")
    args = None  # the command's, once parsed: its name leads the errors said here
    try:
        with _sigterm_interrupts():
            # a command imports what it runs (the model: a second or two): Ctrl-C then is an
            # interrupt too
            args = _parse(build_parser(), argv)  # loads no numba (tests/test_layers.py)
            if argv[:1] == ["detect"]:
                _prefer_wide_vectors()  # before the command imports numba (not for --help)
            return int(args.func(args) or 0)
    except _Terminated:
        print("\nasnn: terminated", file=sys.stderr)
        return 143  # 128 + SIGTERM, as the signal's own end
    except KeyboardInterrupt:  # a progress bar may hold the line: start a new one
        print("\nasnn: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of our standard output went away (`asnn detect --jsonl - | head`): stop
        # quietly, with the status of a command the pipe's signal ends (128 + SIGPIPE)
        _quiet_stdout()
        return 141
    except OSError as exc:
        # a write that failed where the command expects none to (standard output on a full
        # disk: `> /dev/full`); an error naming a file is the command's own, to be said by it
        failed = _stdout_failed()
        if failed is None and (exc.filename is not None or exc.errno not in _WRITE_ERRORS):
            raise
        _quiet_stdout()
        if isinstance(failed, BrokenPipeError):
            return 141  # as above: the reader went away
        failed = failed or exc
        return fail(getattr(args, "command", None),
                    f"a write failed: {failed.strerror or failed}")


if __name__ == "__main__":
    sys.exit(main())
