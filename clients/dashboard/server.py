"""The dashboard's web server (:class:`DashboardServer`): the page, its script and style,
Server-Sent Events of a :class:`~clients.dashboard.store.FleetStore`'s deltas, and ``/state``;
its bounds: :mod:`clients.dashboard`."""

from __future__ import annotations

import contextlib
import http.server
import io
import json
import logging
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable
from importlib import resources

from service.logutil import RateLimitedLog

from .store import FleetStore

__all__ = ["DashboardServer", "STATIC_FILES"]

log = logging.getLogger("asnn.dashboard")

# full snapshots (a new event stream's first event, /state) encoded and being sent at once: each
# holds the whole state encoded (up to about 35 MB) until a slow client has taken it
MAX_FULL_SENDS = 4
IDLE_TIMEOUT = 10.0   # seconds a connection may wait for a whole request
SEND_TIMEOUT = 10.0   # seconds an event stream may wait for its client to take an event
SEND_BUFFER = 256 * 1024  # bytes the kernel may hold for one event stream
MAX_STREAMS = 32
MAX_STREAMS_PER_ADDRESS = 8
SPARE_CONNECTIONS = 32  # connections beyond the streams: page loads, /state
MAX_REQUEST_BYTES = 64 * 1024  # a request line and its headers (the pages send about 1 KB)

STATIC_FILES = {  # the only files served: name -> content type
    "index.html": "text/html; charset=utf-8",
    "dashboard.js": "text/javascript; charset=utf-8",
    "freshness.js": "text/javascript; charset=utf-8",
    "dashboard.css": "text/css; charset=utf-8",
}
SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; object-src 'none'; "
                               "base-uri 'none'; frame-ancestors 'none'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}



def load_static() -> dict[str, bytes]:
    """The page's files, from the installed package."""
    folder = resources.files("clients") / "dashboard_static"
    return {name: (folder / name).read_bytes() for name in STATIC_FILES}


class _RequestDeadline(io.RawIOBase):
    """A connection's bytes for the request reader, each request's to arrive whole by the
    handler's ``deadline``: a socket timeout alone bounds one wait, and a client sending a byte
    every few seconds would hold the connection for ever (a user trial held all of them)."""

    def __init__(self, sock: socket.socket, handler):
        super().__init__()
        self._sock, self._handler = sock, handler

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        remaining = self._handler.deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError("the request did not arrive whole in time")
        # the request line and headers in bytes: the standard library takes 100 headers of
        # 64 KiB each, 6.4 MB held per connection (a probe: 400 MB over 64 of them)
        if self._handler.request_bytes >= MAX_REQUEST_BYTES:
            raise ConnectionAbortedError(f"a request of more than {MAX_REQUEST_BYTES} bytes")
        self._sock.settimeout(remaining)
        received = self._sock.recv_into(buffer)
        self._handler.request_bytes += received
        return received


class _HTTPServer(http.server.ThreadingHTTPServer):
    """The standard threading server with a cap on connections and quiet error handling."""

    daemon_threads = True
    request_queue_size = 128  # the listen backlog (5 by default): bursts of page loads

    def __init__(self, address, handler, *, max_connections: int, max_per_address: int,
                 log_limited: RateLimitedLog):
        self.max_connections = max_connections
        self.max_per_address = max_per_address
        self.connections = 0
        self.refused = 0
        self._by_address: Counter = Counter()
        self._count_lock = threading.Lock()
        self._log_limited = log_limited
        super().__init__(address, handler)

    def process_request(self, request, client_address):
        address = client_address[0]
        with self._count_lock:
            full = (self.connections >= self.max_connections
                    or self._by_address[address] >= self.max_per_address)
            if full:
                self.refused += 1
            else:
                self.connections += 1
                self._by_address[address] += 1
        if full:  # answered here, on the accepting thread: no thread per refused connection
            self._log_limited.warning("connections", "refused a connection from %s: %d open "
                                      "(at most %d, %d from one address)", address,
                                      self.connections, self.max_connections,
                                      self.max_per_address)
            try:
                request.settimeout(0.5)
                request.sendall(b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\n"
                                b"Connection: close\r\n\r\n")
            except OSError:
                pass
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except Exception:
            self._release(address)
            raise

    def process_request_thread(self, request, client_address):
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._release(client_address[0])

    def _release(self, address: str) -> None:
        with self._count_lock:
            self.connections -= 1
            self._by_address[address] -= 1
            if not self._by_address[address]:
                del self._by_address[address]

    def handle_error(self, request, client_address):
        """A connection that failed (reset, timed out): one rate-limited line, no traceback."""
        import sys

        exc = sys.exc_info()[1]
        self._log_limited.warning("connection-error", "connection from %s ended: %s",
                                  client_address[0], f"{type(exc).__name__}: {exc}"[:200])


class DashboardServer:
    """The page and its event stream on ``host:port`` (``port=0``: a free one, see ``url``).

    Use as a context manager, or call ``start`` and ``close``. The limits are described in the
    module notes. ``clock`` (seconds, monotonic; injectable for tests) stamps each state sent
    as ``at`` (:meth:`state`).
    """

    def __init__(self, store: FleetStore, host: str = "127.0.0.1", port: int = 8080, *,
                 push_hz: float = 5.0, heartbeat: float = 1.0, max_streams: int = MAX_STREAMS,
                 max_streams_per_address: int = MAX_STREAMS_PER_ADDRESS,
                 spare_connections: int = SPARE_CONNECTIONS,
                 idle_timeout: float = IDLE_TIMEOUT, send_timeout: float = SEND_TIMEOUT,
                 send_buffer: int = SEND_BUFFER, log_interval: float = 10.0,
                 clock: Callable[[], float] = time.monotonic):
        self.store = store
        self.clock = clock
        self.min_interval = 1.0 / push_hz
        self.heartbeat = heartbeat
        self.max_streams = max_streams
        self.max_streams_per_address = max_streams_per_address
        self.idle_timeout = idle_timeout
        self.send_timeout = send_timeout
        self.send_buffer = send_buffer
        self.closing = threading.Event()
        self.clients = 0
        self.dropped_streams = 0  # event streams dropped because their client did not read
        self._streams_by_address: Counter = Counter()
        self._clients_lock = threading.Lock()
        self._full_sends = threading.BoundedSemaphore(MAX_FULL_SENDS)
        self._log_limited = RateLimitedLog(log, log_interval)
        self._static = load_static()
        self._httpd = _HTTPServer((host, port), self._handler_class(),
                                  max_connections=max_streams + spare_connections,
                                  max_per_address=max_streams_per_address
                                  + spare_connections // 2,
                                  log_limited=self._log_limited)
        self._thread: threading.Thread | None = None

    @property
    def connections(self) -> int:
        """Connections open now (event streams included)."""
        return self._httpd.connections

    @property
    def address(self) -> tuple[str, int]:
        return self._httpd.server_address[:2]

    @property
    def url(self) -> str:
        host, port = self.address
        return f"http://{'127.0.0.1' if host in ('0.0.0.0', '') else host}:{port}/"

    def start(self) -> DashboardServer:
        """Serve on a thread of its own; once (``with DashboardServer(...).start()`` starts it
        once, not twice)."""
        if self._thread is not None:
            return self
        self._thread = threading.Thread(target=self._httpd.serve_forever, kwargs={
            "poll_interval": 0.2}, name="asnn-dashboard-http", daemon=True)
        self._thread.start()
        return self

    def __enter__(self) -> DashboardServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop serving; open event streams end within a heartbeat."""
        self.closing.set()
        if self._thread is not None:
            self._httpd.shutdown()
            self._thread.join(timeout=10)
            self._thread = None
        self._httpd.server_close()

    def state(self, since: int = 0) -> dict:
        """The store's delta since ``since`` (0: the full state), stamped ``at``: this server's
        clock when it was taken. A page can only tell how far behind its event stream is from
        it: events a slow client's kernel still held, delivered after its stream was dropped,
        showed state tens of seconds old as current (a control-room trial)."""
        delta = self.store.delta(since)
        delta["at"] = self.clock()
        return delta

    # ------------------------------------------------------------------ requests

    def _handler_class(self):
        server = self

        class Handler(http.server.BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"
            server_version = "asnn-dashboard"
            sys_version = ""
            timeout = server.idle_timeout  # a request must arrive whole within it
            deadline = 0.0
            request_bytes = 0  # read for the request in hand (MAX_REQUEST_BYTES)

            def setup(self):
                super().setup()
                self.rfile = io.BufferedReader(_RequestDeadline(self.connection, self))

            def handle_one_request(self):
                # from the connection's start or the previous answer: idle time counts too
                self.deadline = time.monotonic() + self.timeout
                self.request_bytes = 0
                super().handle_one_request()

            def parse_request(self):
                parsed = super().parse_request()
                self.connection.settimeout(self.timeout)  # writing the answer: the full time
                return parsed

            def end_headers(self):
                # on every answer, the standard library's error pages (400, 431, 501) included
                for name, value in SECURITY_HEADERS.items():
                    self.send_header(name, value)
                super().end_headers()

            def log_message(self, format, *args):  # noqa: A002 (the base class's name)
                log.debug("%s %s", self.address_string(), format % args)

            def do_HEAD(self):
                self.do_GET(head=True)

            def do_GET(self, head: bool = False):
                path = self.path.split("?", 1)[0]
                if path in ("/", "/index.html"):
                    self._send(200, STATIC_FILES["index.html"], server._static["index.html"],
                               head)
                elif path.startswith("/static/") and path[8:] in STATIC_FILES:
                    name = path[8:]
                    self._send(200, STATIC_FILES[name], server._static[name], head)
                elif path == "/state":
                    with server._full_send() as taken:
                        if not taken:
                            self.close_connection = True
                            self._send(503, "text/plain; charset=utf-8", b"busy: try again\n",
                                       head, cache=False)
                            return
                        body = json.dumps(server.state()).encode()
                        self._send(200, "application/json", body, head, cache=False)
                elif path == "/events" and head:
                    # a health check's HEAD: the stream's headers, no stream held open
                    server._stream_headers(self)
                elif path == "/events":
                    server._stream(self)
                else:
                    self._send(404, "text/plain; charset=utf-8", b"not found\n", head)

            def _send(self, status, ctype, body, head, cache=True):
                self.send_response(status)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-cache" if cache else "no-store")
                self.end_headers()
                if not head:
                    self.wfile.write(body)

        return Handler

    @contextlib.contextmanager
    def _full_send(self):
        """One of the MAX_FULL_SENDS slots for a full snapshot, waited for up to
        ``send_timeout``: yields whether it was taken (each holds the whole state encoded)."""
        taken = self._full_sends.acquire(timeout=self.send_timeout)
        try:
            yield taken
        finally:
            if taken:
                self._full_sends.release()

    @staticmethod
    def _stream_headers(handler) -> None:
        handler.send_response(200)
        handler.send_header("Content-Type", "text/event-stream; charset=utf-8")
        handler.send_header("Cache-Control", "no-store")
        handler.send_header("X-Accel-Buffering", "no")
        handler.end_headers()

    def _stream(self, handler) -> None:
        """Server-Sent Events: a snapshot, then deltas at most every ``min_interval``."""
        address = handler.client_address[0]
        with self._clients_lock:
            full = (self.clients >= self.max_streams
                    or self._streams_by_address[address] >= self.max_streams_per_address)
            if not full:
                self.clients += 1
                self._streams_by_address[address] += 1
        if full:
            handler.close_connection = True
            handler._send(503, "text/plain; charset=utf-8", b"too many dashboards open\n",
                          False, cache=False)
            return
        try:
            sock = handler.connection
            # what a client that does not read can make us hold: the kernel's buffer, one event
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.send_buffer)
            sock.settimeout(self.send_timeout)
            self._stream_headers(handler)
            handler.close_connection = True
            out = handler.wfile
            out.write(b"retry: 2000\n\n")
            since, event, last = 0, "snapshot", 0.0
            while not self.closing.is_set():
                with self._full_send() if since == 0 else contextlib.nullcontext(True) as taken:
                    if not taken:
                        break  # closed: the page opens another stream
                    delta = self.state(since)
                    since = delta["version"]
                    out.write(f"event: {event}\ndata: {json.dumps(delta)}\n\n".encode())
                    out.flush()
                del delta  # not held while waiting: a snapshot is the whole state
                event, last = "update", time.monotonic()
                self.store.wait(since, self.heartbeat)
                # coalesce: everything that arrives within the interval goes in one delta
                pause = self.min_interval - (time.monotonic() - last)
                if pause > 0 and self.closing.wait(pause):
                    break
        except TimeoutError:  # the client took no event for send_timeout seconds
            with self._clients_lock:
                self.dropped_streams += 1
            self._log_limited.warning("slow-client", "dropped the event stream of %s: it took "
                                      "no event for %.0f s", address, self.send_timeout)
        except (BrokenPipeError, ConnectionResetError, ConnectionAbortedError):
            pass  # the browser went away
        finally:
            with self._clients_lock:
                self.clients -= 1
                self._streams_by_address[address] -= 1
                if not self._streams_by_address[address]:
                    del self._streams_by_address[address]
