"""Zenoh fixtures: in-process sessions on TCP loopback, free ports, no multicast, no gossip."""

from __future__ import annotations

import contextlib

import pytest


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
