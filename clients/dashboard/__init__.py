"""The fleet dashboard: every robot seen on the wildcard keys, live in a browser.

Three parts, each usable alone:

- :class:`~clients.dashboard.store.FleetStore` keeps the per-robot state (latest response, a
  ten-second spike-rate history, the latest warning, the latest preview thumbnail) and the log
  of the latest warnings. It validates every inbound message (a bad one is counted per reason,
  never raised), is thread safe, and hands out *deltas*: what changed since a version number. It
  needs neither Zenoh nor a browser.
- :class:`clients.fleet.FleetSubscriber` (the Foxglove server's too) feeds a store from a Zenoh
  session: ``<prefix>/*/response``, ``<prefix>/*/preview`` and ``<prefix>/*/warning`` (an
  advanced subscriber asking the workers' caches for history, so the latest warning of each
  robot shows at once, as in ``asnn alerts``), and for the dashboard ``<prefix>/*/refused`` (a
  worker refuses a robot's frames: its tile says why until a response comes; a second
  publisher's for ``service.streams.CONTESTED_FOR_S`` whatever comes, and that camera's
  previews are not shown: docs/operations.md, "Two publishers on one key").
- :class:`~clients.dashboard.server.DashboardServer` serves the page (one HTML, two scripts, one
  style sheet, all from this package: nothing from the network) and Server-Sent Events from the
  standard library's ``ThreadingHTTPServer``. Each browser gets one full snapshot, then
  coalesced deltas, at most ``push_hz`` a second plus a heartbeat every second, so fifty robots
  at twenty responses a second stay cheap for the server and the page.

HTTP routes: ``/`` the page, ``/static/<name>`` its files (``STATIC_FILES``), ``/events``
(``text/event-stream``: event ``snapshot`` then ``update``), ``/state`` (the full snapshot as
JSON, for scripts); each state is stamped ``at``, the server's clock when it was taken
(docs/contract.md, "Dashboard HTTP interface").

Bounds (docs/operations.md, "Hostile input"): at most ``max_robots`` robots (when the table is
full, the one silent longest makes room if it is stale); per robot a preview of at most
``service.messages.MAX_PREVIEW_BYTES`` and at most ``clients.fleet.MAX_TARGETS`` targets per
response (:func:`clients.fleet.decode_fleet_sample`, shared with the Foxglove server and ``asnn
alerts``), at most MAX_POINTS spike-rate points; all previews together at most
``max_preview_total`` bytes (the oldest previews are forgotten first), taken at most one a robot
every PREVIEW_INTERVAL seconds and PREVIEW_RATE bytes a second in all (the others are counted as
``skipped``), so what a page is sent is bounded in bytes a second too. The server closes
connections idle for ``idle_timeout`` seconds (a request that does not arrive whole, a
kept-alive connection without a next request), reads a request's line and headers up to
MAX_REQUEST_BYTES, drops an event stream whose client has not taken an event within
``send_timeout`` seconds (at most SEND_BUFFER bytes wait in the kernel for each), holds at most
``max_streams`` event streams (``max_streams_per_address`` from one address) and ``max_streams +
spare_connections`` connections in all (``max_streams_per_address + spare_connections / 2`` from
one address), so that a browser can still load the page while another address holds what it may
(clients at three addresses can hold every connection: expose the dashboard to untrusted
networks only behind a proxy that authenticates), and sends at most MAX_FULL_SENDS full
snapshots (``/state``, a new stream's first event) at once, each the whole state encoded.
Invalid messages and dropped connections are logged rate-limited, without tracebacks.

Robot state as shown: **stale** when no response arrived for ``stale_after`` seconds (or none
ever did: a robot known only from a cached warning, or from its camera's previews): its camera
may still send previews, but no worker answers it, so nothing watches it; **collision**, unless
stale, when the latest response says so, or the robot's latest warning is at most ``hold``
seconds older (camera clock) than its latest response (or as much newer), so a warning that
lasts a few frames stays visible. A robot whose worker dies, or whose camera ends, mid-warning
turns stale, not held in collision.
"""

from ..fleet import FleetSubscriber
from .server import STATIC_FILES, DashboardServer
from .store import HOLD_S, FleetStore

__all__ = ["DashboardServer", "FleetStore", "FleetSubscriber", "HOLD_S", "STATIC_FILES"]
