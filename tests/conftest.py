"""Session set-up (compiled kernels) and Zenoh fixtures: in-process sessions on TCP loopback,
free ports, no multicast, no gossip."""

from __future__ import annotations

import contextlib

import pytest


#: The test that runs ``asnn demo`` on an empty numba cache (tests/test_service.py), whose
#: command the session starts first (:func:`fresh_install_demo`).
FRESH_INSTALL_TEST = "test_demo_on_a_fresh_install_warns"


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels(request):
    """Compile the numba kernels once (numba caches them on disk) before any test starts worker
    processes: on a fresh checkout a worker's first frame would otherwise wait seconds for the
    compiler, which time-bounded service tests mistake for a failure.

    Where the fresh-install demo's test is selected, its command starts first. On a cache that
    holds none of the kernels yet (a fresh checkout, as in CI) it runs in that cache, and this
    compile waits for it: the default preset's kernels, which its worker compiled, then load
    here instead of being compiled a second time.
    On a cache that holds some, it runs in an empty cache of its own while the tests go on."""
    from asnn.warmup import compile_kernels

    # each of pytest-xdist's processes collects every test, so each starts the demo: whichever
    # runs the test finds it done (started later, it had a minute's compile of its own). On an
    # empty cache the two compile into it at once, which numba allows (each file written
    # aside, then moved into place): no slower than one, since the other core was idle
    if any(getattr(item, "originalname", None) == FRESH_INSTALL_TEST
           for item in request.session.items):
        demo = request.getfixturevalue("fresh_install_demo")
        if demo.in_the_session_cache:
            demo.wait()
    compile_kernels()


def _kernels_cached() -> bool:
    """Whether numba's cache, where this session keeps it, holds any of asnn's kernels (an index
    file in the place of one of the package's folders)."""
    from pathlib import Path

    import asnn
    from asnn._jit import _cache_place

    package = Path(asnn.__file__).parent
    place = _cache_place()
    folders = [package, *(p for p in package.glob("**/") if p.name != "__pycache__")]
    return any(next(place(folder).glob("*.nbi"), None) is not None for folder in folders)


class BackgroundCommand:
    """An ``asnn`` command run in a process of its own while the session goes on, its output kept
    in files (a pipe that nobody reads would stop it once full)."""

    def __init__(self, args, env, folder, timeout):
        import subprocess
        import sys
        import time

        self.args, self.timeout, self.timed_out = args, timeout, False
        self.deadline = time.monotonic() + timeout
        self.stdout, self.stderr = folder / "stdout", folder / "stderr"
        with open(self.stdout, "w") as out, open(self.stderr, "w") as err:
            self.popen = subprocess.Popen([sys.executable, "-m", "cli.main", *args], env=env,
                                          stdout=out, stderr=err)

    def wait(self):
        """Wait until it ends, or kill it ``timeout`` seconds after it started."""
        import subprocess
        import time

        try:
            self.popen.wait(timeout=max(self.deadline - time.monotonic(), 0.0))
        except subprocess.TimeoutExpired:
            self.timed_out = True
            self.kill()

    def result(self):
        """The ended command, as ``subprocess.run(..., capture_output=True, text=True)`` gives
        it, or its ``subprocess.TimeoutExpired``."""
        import subprocess

        self.wait()
        if self.timed_out:
            raise subprocess.TimeoutExpired(self.args, self.timeout)
        return subprocess.CompletedProcess(self.args, self.popen.returncode,
                                           self.stdout.read_text(), self.stderr.read_text())

    def kill(self):
        if self.popen.poll() is None:
            self.popen.kill()
        self.popen.wait()


@pytest.fixture(scope="session")
def fresh_install_demo(tmp_path_factory):
    """README's first command on a new machine, ``asnn demo`` on a numba cache that holds none of
    the kernels, started in the background (a :class:`BackgroundCommand`, killed at the end of
    the session if it still runs): in the session's own cache where that holds none yet (its
    ``in_the_session_cache``), else in an empty one of its own."""
    import os

    folder = tmp_path_factory.mktemp("fresh-install")
    env = {**os.environ}
    env.pop("RUST_LOG", None)
    in_the_session_cache = not _kernels_cached()
    if not in_the_session_cache:
        env["NUMBA_CACHE_DIR"] = str(folder / "numba-cache")
    demo = BackgroundCommand(["demo"], env, folder, timeout=600)
    demo.in_the_session_cache = in_the_session_cache
    yield demo
    demo.kill()


@pytest.fixture(autouse=True)
def _signal_handlers_restored():
    """SIGINT's and SIGTERM's handlers as they were before each test: a command run in-process
    (``args.func(args)``, ``main([...])``) installs ``stop_on_signals``'s, which outlived it and
    swallowed the test process's Ctrl-C and SIGTERM, and which later tests in the same process
    (whichever pytest-xdist gives it) found in place of Python's own."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    yield
    for sig, handler in before.items():
        if signal.getsignal(sig) is not handler and handler is not None:
            signal.signal(sig, handler)


@pytest.fixture
def zenoh_net():
    """A small loopback network: ``hub`` (a peer session) listens on a free port and ``spoke()``
    opens a session connected to it. Everything opened is closed at the end of the test."""
    import zenoh

    from service.config import make_config
    from service.demo import free_port, loopback_options

    with contextlib.ExitStack() as stack:
        port = free_port()
        hub_options, spoke_options = loopback_options(port)

        class Net:
            endpoint = f"tcp/127.0.0.1:{port}"
            hub = stack.enter_context(zenoh.open(make_config(hub_options)))

            @staticmethod
            def spoke():
                return stack.enter_context(zenoh.open(make_config(spoke_options)))

        yield Net


@pytest.fixture
def procs():
    """Starts child ``asnn`` processes (``procs("worker", ...)``) and kills what still runs."""
    from netutil import Procs

    started = Procs()
    yield started
    started.cleanup()
