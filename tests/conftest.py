"""Session set-up (compiled kernels) and Zenoh fixtures: in-process sessions on TCP loopback,
free ports, no multicast, no gossip."""

from __future__ import annotations

import contextlib

import pytest


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels():
    """Compile the numba kernels once (numba caches them on disk) before any test starts worker
    processes: on a fresh checkout a worker's first frame would otherwise wait seconds for the
    compiler, which time-bounded service tests mistake for a failure."""
    from asnn.warmup import compile_kernels

    compile_kernels()


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
