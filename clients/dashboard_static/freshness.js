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
//
// Until its first event a stream is *waiting* (the page says so rather than "live": what it
// shows is older than the stream), and one still waiting `firstEventS` seconds after it was
// asked for is *overdue*: taken for cut after its headers and replaced.
// A plain script, not a module: dashboard.js uses StreamLag; the tests run it in node.
"use strict";

// seconds a new stream may take to send its first event (the server makes a snapshot wait for
// a send slot up to its send timeout, 10 s) before it is taken for cut and replaced
const FIRST_EVENT_S = 30;

class StreamLag {
  constructor(firstEventS = FIRST_EVENT_S) {
    this.firstEventS = firstEventS;
    this.asked = null; // when the page asked for the stream (its clock, seconds)
    this.first = null; // the `at` of the stream's first event
    this.heard = false; // whether an event of the stream arrived
  }

  // The page asks for a stream (or the browser is about to ask again), at `now`, seconds.
  ask(now) {
    this.asked = now;
    this.first = null;
    this.heard = false;
  }

  // Seconds an event stamped `at` (server clock) is behind, handled at `now` (page clock).
  // Every event goes through here: one without a stamp (not a number) counts as 0 behind.
  lag(at, now) {
    if (this.asked === null) this.asked = now; // not asked: from its first event on
    this.heard = true;
    if (typeof at !== "number") return 0;
    if (this.first === null) this.first = at;
    // at least 0 whatever the two clocks' drift
    return Math.max(0, now - this.asked - (at - this.first));
  }

  // Whether the stream asked for has sent no event yet.
  waiting() {
    return this.asked !== null && !this.heard;
  }

  // Whether, at `now` (page clock, seconds), the stream has been waiting for its first event
  // for more than `firstEventS` seconds.
  overdue(now) {
    return this.waiting() && now - this.asked > this.firstEventS;
  }
}

if (typeof module === "object") module.exports = { FIRST_EVENT_S, StreamLag };
