// How far behind its server the page's event stream is, from the stamp `at` the server puts on
// every event: its monotonic clock, in seconds, when the event's state was taken
// (docs/contract.md). Events can arrive long after that: a page that did not keep up still gets
// what the kernels buffered for it, even after the server dropped its stream (a control-room
// trial saw a warning over for tens of seconds shown as current).
//
// The server's clock and the page's are not set alike (another machine, and only differences of
// `at` mean anything), but both run at the rate of time. A stream's first state was taken after
// the page asked for the stream; so an event is at most as far behind as the page's time since
// it asked exceeds the server's since that first state:
//     lag = (received - asked) - (at - first at)
// never less than the truth: an event may be taken for older than it is, by as long as the
// server took to answer the stream (a snapshot waiting its turn: docs/operations.md), never for
// fresher. Each stream is measured on its own: no assumption holds from one to the next (a
// restarted server, another machine behind a proxy).
// A plain script, not a module: dashboard.js uses StreamLag; the tests run it in node.
"use strict";

class StreamLag {
  constructor() {
    this.asked = null; // when the page asked for the stream (its clock, seconds)
    this.first = null; // the `at` of the stream's first event
  }

  // The page asks for a stream (or the browser is about to ask again), at `now`, seconds.
  ask(now) {
    this.asked = now;
    this.first = null;
  }

  // Seconds an event stamped `at` (server clock) is behind, handled at `now` (page clock).
  lag(at, now) {
    if (this.asked === null) this.asked = now; // not asked: from its first event on
    if (this.first === null) this.first = at;
    // at least 0 whatever the two clocks' drift
    return Math.max(0, now - this.asked - (at - this.first));
  }
}

if (typeof module === "object") module.exports = { StreamLag };
