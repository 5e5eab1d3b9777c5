// ASNN fleet dashboard: one tile per robot, fed by Server-Sent Events from /events.
// The server sends a full "snapshot", then "update" deltas (only the robots that changed, plus
// every robot's [age, stale, collision]), each stamped with the server's clock (`at`), by which
// the page knows how far behind the stream is (freshness.js). Drawing happens once per animation
// frame, only for the tiles that changed, so fifty robots stay cheap.
"use strict";

(() => {
  const LOG_SIZE = 50;
  // seconds behind (or silent) beyond which a stream is dropped for a new one, whatever the
  // staleness limit; the server sends an event at least every second
  const BEHIND_MIN_S = 3;
  const fleet = document.getElementById("fleet");
  const empty = document.getElementById("empty");
  const template = document.getElementById("tile-template");
  const logBody = document.querySelector("#warnings tbody");
  const summary = document.getElementById("summary");
  const conn = document.getElementById("conn");

  const robots = new Map(); // name -> view
  const dirty = new Set();
  let config = { history: 10, hold: 3, stale_after: 3, slow_fps: 18, max_points: 400 };
  let counts = null;
  let framePending = false;

  function clock(stamp) {
    const d = new Date(stamp * 1000);
    if (Number.isNaN(d.getTime())) return `${stamp} s`; // beyond what a Date holds
    const pad = (n, w = 2) => String(n).padStart(w, "0");
    return `${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}.` +
      pad(d.getMilliseconds(), 3);
  }

  // the shortest time to contact among the targets (seconds), or null
  function soonest(targets) {
    let best = null;
    for (const t of targets) {
      if (typeof t.ttc === "number" && (best === null || t.ttc < best)) best = t.ttc;
    }
    return best;
  }

  function fmt(x, digits = 2) {
    return x === null || x === undefined ? "-" : Number(x).toFixed(digits);
  }

  // ---------------------------------------------------------------- tiles

  function view(name) {
    let v = robots.get(name);
    if (v) return v;
    const el = template.content.firstElementChild.cloneNode(true);
    el.dataset.robot = name;
    el.querySelector(".name").textContent = name;
    v = {
      name, el, tile: null, contact: null, points: [], image: null, imageSrc: null,
      thumb: el.querySelector(".thumb"), spark: el.querySelector(".spark"),
      stats: el.querySelector(".stats"), staleBadge: el.querySelector(".stale-badge"),
      age: null, ageAt: 0, stale: true, collision: false,
    };
    robots.set(name, v);
    // keep tiles in name order, so a robot does not move around
    const after = [...robots.keys()].sort().find((other) => other > name);
    fleet.insertBefore(el, after ? robots.get(after).el : null);
    empty.hidden = true;
    return v;
  }

  function remove(name) {
    const v = robots.get(name);
    if (!v) return;
    v.el.remove();
    robots.delete(name);
    dirty.delete(name);
    empty.hidden = robots.size > 0;
  }

  function setFlags(v, stale, collision) {
    if (v.stale !== stale || v.el.dataset.stale !== String(stale)) {
      v.stale = stale;
      v.el.dataset.stale = String(stale);
      v.el.classList.toggle("stale", stale);
    }
    if (v.collision !== collision || v.el.dataset.collision !== String(collision)) {
      v.collision = collision;
      v.el.dataset.collision = String(collision);
      v.el.classList.toggle("collision", collision);
      dirty.add(v.name);
    }
  }

  function applyTile(tile) {
    const v = view(tile.robot);
    if (tile.points_reset) v.points = [];
    for (const p of tile.points) v.points.push(p);
    const latest = tile.latest_stamp;
    // the server's bounds: the history's span, and at most max_points (a clock that does not
    // advance keeps every point inside the span)
    let drop = Math.max(0, v.points.length - config.max_points);
    if (latest !== null) {
      const horizon = latest - config.history;
      while (drop < v.points.length && v.points[drop][0] < horizon) drop++;
    }
    if (drop) v.points.splice(0, drop);
    if (tile.preview && tile.preview.src && tile.preview.src !== v.imageSrc) {
      const img = new Image();
      const src = tile.preview.src;
      v.imageSrc = src;
      img.onload = () => {
        if (v.imageSrc === src) {
          v.image = img;
          v.el.dataset.preview = "true";
          dirty.add(v.name);
          schedule();
        }
      };
      img.src = src;
    }
    if (tile.preview && !tile.preview.src) {
      tile.preview.src = v.tile && v.tile.preview ? v.tile.preview.src : null;
    }
    v.tile = tile;
    v.el.dataset.responses = String(tile.responses);
    v.el.dataset.warnings = String(tile.warnings);
    v.el.dataset.targets = String(tile.targets.length);
    v.contact = soonest(tile.targets);
    v.el.dataset.contact = v.contact === null ? "" : v.contact.toFixed(2);
    dirty.add(v.name);
  }

  // ---------------------------------------------------------------- drawing

  function sized(canvas) {
    const ratio = window.devicePixelRatio || 1;
    const w = canvas.clientWidth || canvas.width, h = canvas.clientHeight || canvas.height;
    if (canvas.width !== Math.round(w * ratio) || canvas.height !== Math.round(h * ratio)) {
      canvas.width = Math.round(w * ratio);
      canvas.height = Math.round(h * ratio);
    }
    const ctx = canvas.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    return [ctx, w, h];
  }

  function drawThumb(v) {
    const [ctx, w, h] = sized(v.thumb);
    ctx.fillStyle = "#0b0f14";
    ctx.fillRect(0, 0, w, h);
    const preview = v.tile && v.tile.preview;
    if (!v.image || !preview) {
      ctx.fillStyle = "#5b6775";
      ctx.font = "12px sans-serif";
      ctx.textAlign = "center";
      ctx.fillText("no preview", w / 2, h / 2);
      return;
    }
    const scale = Math.min(w / preview.width, h / preview.height);
    const dw = preview.width * scale, dh = preview.height * scale;
    const ox = (w - dw) / 2, oy = (h - dh) / 2;
    ctx.imageSmoothingEnabled = true;
    ctx.drawImage(v.image, ox, oy, dw, dh);
    // targets are in pixels of the published frame
    const sx = dw / preview.frame_width, sy = dh / preview.frame_height;
    ctx.lineWidth = 2;
    for (const t of v.tile.targets) {
      const x = ox + t.x * sx, y = oy + t.y * sy;
      const r = Math.max(5, Math.sqrt(t.pixels / Math.PI) * Math.min(sx, sy));
      ctx.strokeStyle = "#ff3b30";
      ctx.beginPath();
      ctx.arc(x, y, r, 0, 2 * Math.PI);
      ctx.stroke();
      ctx.beginPath(); // heading, image coordinates (x right, y down)
      ctx.moveTo(x, y);
      ctx.lineTo(x + Math.cos(t.direction) * (r + 8), y + Math.sin(t.direction) * (r + 8));
      ctx.stroke();
      const label = (t.id !== undefined ? `#${t.label ?? t.id}` : "") +
        (typeof t.ttc === "number" ? ` ${t.ttc.toFixed(1)} s` : "");
      if (label) {
        ctx.fillStyle = "#ff3b30";
        ctx.font = "bold 11px sans-serif";
        ctx.textAlign = "left";
        ctx.fillText(label.trim(), Math.min(x + r + 2, w - 60), Math.max(y - r, 12));
      }
    }
  }

  function drawSpark(v) {
    const [ctx, w, h] = sized(v.spark);
    ctx.clearRect(0, 0, w, h);
    ctx.fillStyle = "#121820";
    ctx.fillRect(0, 0, w, h);
    const pts = v.points;
    if (!pts.length || !v.tile || v.tile.latest_stamp === null) return;
    const end = Math.max(v.tile.latest_stamp, pts[pts.length - 1][0]);
    const start = end - config.history;
    let top = 20;
    for (const p of pts) top = Math.max(top, p[1]);
    top *= 1.1;
    const X = (t) => ((t - start) / config.history) * (w - 2) + 1;
    const Y = (r) => h - 2 - (r / top) * (h - 4);
    ctx.beginPath();
    ctx.moveTo(X(pts[0][0]), h);
    for (const p of pts) ctx.lineTo(X(p[0]), Y(p[1]));
    ctx.lineTo(X(pts[pts.length - 1][0]), h);
    ctx.closePath();
    ctx.fillStyle = v.collision ? "rgba(255, 59, 48, 0.35)" : "rgba(90, 200, 250, 0.25)";
    ctx.fill();
    ctx.beginPath();
    pts.forEach((p, i) => (i ? ctx.lineTo(X(p[0]), Y(p[1])) : ctx.moveTo(X(p[0]), Y(p[1]))));
    ctx.strokeStyle = v.collision ? "#ff3b30" : "#5ac8fa";
    ctx.lineWidth = 1.5;
    ctx.stroke();
    ctx.fillStyle = "#9aa7b4";
    ctx.font = "10px sans-serif";
    ctx.textAlign = "right";
    ctx.fillText(`spike rate ${Math.round(pts[pts.length - 1][1])}`, w - 4, 11);
  }

  // the rate a robot's frames are answered at: the median of its last 5 response intervals
  // (the worker's own skips included), as the worker measures it (asnn.params.SLOW_FPS); with
  // an even count, the upper of the two middle intervals (the lower rate)
  function rateOf(points) {
    const gaps = [];
    let longer = 0;
    for (let i = Math.max(1, points.length - 5); i < points.length; i++) {
      const gap = points[i][0] - points[i - 1][0];
      if (gap > 0 && gap <= 1) gaps.push(gap);
      else if (gap > 1) longer++;
    }
    // frames over a second apart (the worker then gives no rate): 0, read "under 1 fps", slow
    if (!gaps.length) return longer ? 0 : null;
    gaps.sort((a, b) => a - b);
    const mid = gaps.length >> 1;  // the median as the worker takes it (statistics.median)
    return 1 / (gaps.length % 2 ? gaps[mid] : (gaps[mid - 1] + gaps[mid]) / 2);
  }

  function drawStats(v) {
    const refused = v.tile && v.tile.refused;
    v.el.dataset.refused = refused ? refused.reason : "";
    if (refused) {  // newer than any response: the worker says why it does not answer
      v.stats.textContent = `refused by ${refused.worker}: ${refused.reason} ` +
        `(${refused.count} frames) · ${refused.detail}`;
      v.stats.title = refused.detail;
      return;
    }
    const r = v.tile && v.tile.response;
    if (!r) {
      v.stats.textContent = v.tile && v.tile.last_warning
        ? `last warning seq ${v.tile.last_warning.seq} at ${clock(v.tile.last_warning.stamp)}`
        : "no response yet";
      return;
    }
    const fps = rateOf(v.points);
    const rate = fps === null ? "" : fps === 0 ? "under 1 fps" : `${Math.round(fps)} fps`;
    const slow = fps !== null && fps < config.slow_fps;
    // the time to contact first, then a slow rate (detection suffers): the line is cut to the
    // tile's width
    v.stats.textContent = (v.contact === null ? "" : `contact in ${v.contact.toFixed(1)} s · `) +
      (slow ? `${rate} (slow) · ` : "") +
      `seq ${r.seq} · out ${fmt(r.out)} · spike rate ${Math.round(r.spike_rate)} ` +
      `· ${fmt(r.latency_ms, 0)} ms` + (r.dropped ? ` · ${r.dropped} dropped` : "") +
      (rate && !slow ? ` · ${rate}` : "") + ` · ${r.model}${r.preset ? "/" + r.preset : ""}`;
    v.stats.title = `worker ${r.worker}, frame at ${clock(r.stamp)}`;
  }

  function draw() {
    framePending = false;
    for (const name of dirty) {
      const v = robots.get(name);
      if (!v) continue;
      drawThumb(v);
      drawSpark(v);
      drawStats(v);
    }
    dirty.clear();
  }

  function schedule() {
    if (!framePending && dirty.size) {
      framePending = true;
      requestAnimationFrame(draw);
    }
  }

  // ---------------------------------------------------------------- log and summary

  // One row per warning episode (consecutive warnings of a robot); an updated episode moves
  // to the top.
  function addWarnings(entries, full) {
    if (full) logBody.replaceChildren();
    for (const e of entries) {
      const old = logBody.querySelector(`tr[data-entry="${e.id}"]`);
      if (old) old.remove();
      const row = document.createElement("tr");
      row.dataset.entry = String(e.id);
      row.dataset.robot = e.robot;
      const frames = e.count > 1 ? `${e.first_seq}–${e.seq} (${e.count})` : String(e.seq);
      for (const text of [clock(e.stamp), e.robot, frames, fmt(e.peak_out),
                          Math.round(e.peak_rate), e.targets]) {
        const cell = document.createElement("td");
        cell.textContent = String(text);
        row.appendChild(cell);
      }
      row.title = `from ${clock(e.first_stamp)}, worker ${e.worker}`;
      logBody.insertBefore(row, logBody.firstChild);
    }
    while (logBody.rows.length > LOG_SIZE) logBody.deleteRow(-1);
  }

  function showSummary() {
    if (!counts) return;
    let stale = 0, collision = 0;
    for (const v of robots.values()) {
      stale += v.stale;
      collision += v.collision;
    }
    const invalid = Object.values(counts.invalid).reduce((a, b) => a + b, 0);
    summary.textContent = `${robots.size} robot${robots.size === 1 ? "" : "s"} · ` +
      `${collision} in collision · ${stale} stale` +
      (invalid ? ` · ${invalid} invalid message${invalid === 1 ? "" : "s"}` : "");
    summary.title = invalid ? JSON.stringify(counts.invalid) : "";
    summary.classList.toggle("alarm", collision > 0);
  }

  // ---------------------------------------------------------------- events

  // The indicator: the event stream (the page's link to its server), and the server's own link
  // to the Zenoh router, without which every robot reads stale for no fault of its own.
  let streamOpen = false;
  let routerLost = false;
  let lag = 0;           // seconds the latest event was behind its server (freshness.js)
  let behind = null;     // seconds the stream dropped for it was behind (or silent), until a
                         // fresh event

  function showConnection() {
    conn.dataset.lag = lag.toFixed(1);
    if (!streamOpen && behind !== null) {
      conn.dataset.state = "lost";
      conn.textContent = `${Math.round(behind)} s behind: reconnecting`;
      conn.title = "the page's event stream fell behind its server (state that old is shown " +
        "stale); a new stream starts from the server's state now";
    } else if (!streamOpen) {
      conn.dataset.state = "lost";
      conn.textContent = "reconnecting";
      conn.title = "the page lost its server; it reconnects";
    } else if (streamLag.waiting()) {
      // open, but nothing on it yet (the tiles, and `lag`, are the previous stream's)
      conn.dataset.state = "connecting";
      conn.textContent = "waiting for the first event";
      conn.title = "the page's event stream is open; the server's state has not arrived " +
        "yet (it may wait for a send slot): the tiles shown are older than that";
    } else if (lag > behindLimit()) {
      conn.dataset.state = "lost";
      conn.textContent = `${Math.round(lag)} s behind`;
      conn.title = "the page's event stream is behind its server (state that old is shown " +
        "stale); unless it catches up, a new stream starts from the server's state now";
    } else if (routerLost) {
      conn.dataset.state = "lost";
      conn.textContent = "no router: robots unknown";
      conn.title = "the dashboard's server lost its Zenoh router: no robot is heard until " +
        "Zenoh reconnects, so every robot reads stale whatever it is doing";
    } else {
      conn.dataset.state = "live";
      conn.textContent = "live";
      conn.title = `the latest event was ${lag.toFixed(1)} s behind its server`;
    }
  }

  // how far behind (or how long silent) a stream may be: state older than the staleness
  // limit reads stale, so such a stream can show nothing live, only replay the past
  function behindLimit() {
    return Math.max(config.stale_after, BEHIND_MIN_S);
  }

  function apply(delta) {
    if (routerLost !== (delta.router === false)) {
      routerLost = delta.router === false;
      showConnection();
    }
    config = delta.config || config;
    counts = delta.counts;
    if (delta.full) {
      for (const name of [...robots.keys()]) if (!Object.hasOwn(delta.live, name)) remove(name);
    }
    for (const tile of Object.values(delta.robots)) applyTile(tile);
    const now = performance.now();
    for (const [name, [age, stale, collision]] of Object.entries(delta.live)) {
      const v = view(name);
      // the ages are the server's when it took the state, `lag` seconds ago: a robot answered
      // then, but longer ago now than the staleness limit, is stale (showAge)
      v.age = age;
      v.ageAt = now - lag * 1000;
      setFlags(v, stale, collision);
      showAge(v, now);
    }
    for (const name of [...robots.keys()]) if (!Object.hasOwn(delta.live, name)) remove(name);
    addWarnings(delta.warnings, delta.full);
    showSummary();
    document.body.dataset.version = String(delta.version);
    schedule();
  }

  // A robot's age at `now` (page clock, ms), from the one it had when the server took the
  // state: past the staleness limit it is stale, and its badge says for how long. On an
  // event's arrival (it may arrive late) and between events (a dashboard whose server went
  // quiet must not show old tiles as live); at once, so no tile reads stale without its age.
  function showAge(v, now) {
    const age = v.age === null ? null : v.age + (now - v.ageAt) / 1000;
    // stale is never shown in collision (nothing watches the robot: as the server shows it)
    if (age === null || age > config.stale_after) setFlags(v, true, false);
    // how long no worker has answered it: a moment's gap or a camera gone for minutes
    const since = age === null ? "STALE" : `STALE ${age < 60 ? Math.floor(age) + " s"
      : Math.floor(age / 60) + " min"}`;
    if (v.staleBadge.textContent !== since) v.staleBadge.textContent = since;
  }

  // Ages advance between events too, and a stream silent for longer than behindLimit (a
  // connection cut without a word: no end ever arrives) is dropped for a new one.
  setInterval(() => {
    const now = performance.now();
    if (streamOpen && lastEvent !== null && (now - lastEvent) / 1000 > behindLimit()) {
      reopen((now - lastEvent) / 1000);
    } else if (streamOpen && streamLag.overdue(now / 1000)) {
      reopen();  // opened, and never a snapshot: cut after its headers (not behind: silent)
    }
    for (const v of robots.values()) showAge(v, now);
    showSummary();
    schedule();
  }, 500);

  let retry = 1000; // ms before a new stream, after one the server refused, closed or was behind
  let source = null;
  let lastEvent = null; // performance.now() of the stream's latest event
  let behindSince = null; // performance.now() of the first update behind, while behind
  const streamLag = new StreamLag();

  // the stream closed and a new one opened after `retry`, backing off until one keeps up;
  // `behindBy`: seconds it was behind, if that is why
  function reopen(behindBy = null) {
    source.close();
    streamOpen = false;
    behind = behindBy;
    showConnection();
    setTimeout(connect, retry);
    retry = Math.min(retry * 2, 30000);
  }

  function connect() {
    const current = source = new EventSource("/events");
    streamLag.ask(performance.now() / 1000);
    lastEvent = null;
    behindSince = null;
    const handle = (event) => {
      if (current !== source) return;  // a stream the page dropped has no say any more
      try {
        const delta = JSON.parse(event.data);
        lastEvent = performance.now();
        lag = streamLag.lag(delta.at, lastEvent / 1000);
        apply(delta);
        showConnection();
      } catch (err) {
        console.error("bad event", err);
        return;
      }
      if (lag <= behindLimit()) {
        retry = 1000;
        behind = null;
        behindSince = null;
      } else if (event.type === "update") {
        // the past, replayed (a stream that fell behind, or one the server already dropped
        // whose buffered events still arrive): shown as old as it is, and, unless the stream
        // catches up within behindLimit, a new one starts from the state now. Not at once: on
        // a slow link the updates queued behind a large snapshot arrive late, and a stream
        // replaced at its first late update would download the snapshot again, never live.
        // Not for a snapshot: it is the newest state there is, and its tiles read stale if old
        if (behindSince === null) behindSince = lastEvent;
        else if ((lastEvent - behindSince) / 1000 > behindLimit()) reopen(lag);
      }
    };
    source.addEventListener("snapshot", handle);
    source.addEventListener("update", handle);
    source.onopen = () => {
      streamOpen = true;
      showConnection();
    };
    // A stream that ended or failed is replaced by the page, backing off: the browser retries
    // one by itself, but gives up for good on an HTTP error status (503 while every stream is
    // taken), and its own retry would not say when it asked (freshness.js)
    source.onerror = () => reopen();
  }

  connect();
})();
