// The status page of `motorbench serve`: rigs and their state, the running
// test's progress with a live plot (current and speed from the test's
// event stream; for an induction-machine sweep also its operating points,
// line current and input power against slip), abort / emergency stop / reset, and the records with
// their reports, plots and downloads. Every call goes to the daemon's own
// API with the token, when one is set (asked for once, kept in this tab's
// session storage). No library but uPlot (vendored, served by the daemon).
"use strict";

const TOKEN_KEY = "motorbench-token";
const RIG_POLL_MS = 1000;
const RECORD_POLL_MS = 5000;

/** Rig name → its card's elements and live state. */
const cards = new Map();
let recordsShown = "";

function token() {
  return sessionStorage.getItem(TOKEN_KEY);
}

function authHeaders(extra) {
  const h = Object.assign({}, extra || {});
  const t = token();
  if (t) h.Authorization = "Bearer " + t;
  return h;
}

class Unauthorized extends Error {}

/** A fetch with the token; 401 asks for the token and throws. */
async function call(method, path, body) {
  const init = { method, headers: authHeaders(body ? { "Content-Type": "application/json" } : {}) };
  if (body !== undefined) init.body = JSON.stringify(body);
  const r = await fetch(path, init);
  if (r.status === 401) {
    askToken(token() ? "the token was refused" : null);
    throw new Unauthorized("the daemon needs its token");
  }
  return r;
}

/** JSON of a 2xx answer; else an Error with the daemon's message. */
async function api(method, path, body) {
  const r = await call(method, path, body);
  const text = await r.text();
  let v = null;
  try { v = JSON.parse(text); } catch (_) { /* not JSON */ }
  if (!r.ok) throw new Error((v && v.message) || `HTTP ${r.status}`);
  return v;
}

function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") e.className = v;
    else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v);
  }
  for (const c of children) e.append(c);
  return e;
}

function fmt(x, digits, unit) {
  return typeof x === "number" && isFinite(x) ? `${x.toFixed(digits)} ${unit}` : "—";
}

function showError(message) {
  const p = document.getElementById("error");
  p.textContent = message || "";
  p.hidden = !message;
}

function askToken(why) {
  const form = document.getElementById("token-form");
  form.hidden = false;
  if (why) showError(why);
  document.getElementById("token-input").focus();
}

function setupToken() {
  const form = document.getElementById("token-form");
  const forget = document.getElementById("forget-token");
  form.addEventListener("submit", (ev) => {
    ev.preventDefault();
    const input = document.getElementById("token-input");
    sessionStorage.setItem(TOKEN_KEY, input.value.trim());
    input.value = "";
    form.hidden = true;
    showError(null);
    forget.hidden = false;
    refresh();
  });
  forget.hidden = !token();
  forget.addEventListener("click", () => {
    sessionStorage.removeItem(TOKEN_KEY);
    forget.hidden = true;
    askToken(null);
  });
}

// ---- rigs -------------------------------------------------------------

const STATE_TEXT = { idle: "idle", running: "running", tripped: "latched" };

function rigCard(rig) {
  let card = cards.get(rig.name);
  if (card) return card;
  const root = el("article", { class: "rig", id: `rig-${rig.name}`, "data-rig": rig.name });
  card = {
    root,
    name: rig.name,
    state: el("span", { class: "state" }),
    facts: el("div", { class: "facts muted" }),
    trip: el("div", { class: "trip" }),
    test: el("div", { class: "test" }),
    segment: el("span", { class: "segment" }),
    time: el("span", { class: "time" }),
    eta: el("span", { class: "eta" }),
    values: el("div", { class: "values muted" }),
    bar: el("div"),
    plotBox: el("div", { class: "plot" }),
    sweepBox: el("div", { class: "plot sweep", hidden: "" }),
    message: el("div", { class: "message muted" }),
    abort: el("button", { type: "button", class: "abort" }, "Abort test"),
    estop: el("button", { type: "button", class: "estop" }, "EMERGENCY STOP"),
    reset: el("button", { type: "button", class: "reset" }, "Reset latch"),
    feedId: null,
    plotId: null,
    runningId: null,
    plot: null,
    data: [[], [], []],
    sweep: null,
    sweepShown: 0,
  };
  card.abort.addEventListener("click", () => act(card, "abort"));
  card.estop.addEventListener("click", () => act(card, "estop"));
  card.reset.addEventListener("click", () => act(card, "reset"));
  root.append(
    el("h2", {}, rig.name, card.state),
    card.facts,
    card.trip,
    el("div", { class: "progress" },
      card.test,
      el("div", { class: "line" }, card.segment, card.time, card.eta),
      el("div", { class: "bar" }, card.bar),
      card.values),
    card.plotBox,
    card.sweepBox,
    el("div", { class: "actions" }, card.abort, card.estop, card.reset),
    card.message,
  );
  document.getElementById("rigs").append(root);
  cards.set(rig.name, card);
  return card;
}

function showRig(rig) {
  const card = rigCard(rig);
  card.root.dataset.state = rig.state;
  card.state.className = `state ${rig.state}`;
  card.state.textContent = STATE_TEXT[rig.state] || rig.state;
  card.facts.textContent =
    `motor ${rig.motor_id} · ${rig.machine === "induction" ? "induction machine" : "DC machine"} · ` +
    `${rig.backend} · winding ≈ ${fmt(rig.winding_c, 1, "°C")}`;
  card.trip.textContent = rig.trip ? `Latched: ${rig.trip.message} (${rig.trip.at})` : "";
  card.runningId = rig.running_test;
  card.abort.disabled = !rig.running_test;
  card.reset.disabled = rig.state !== "tripped";
  // The running test, or the last one followed until it is seen to end:
  // after an abort the rig is idle while its test is still identifying.
  const id = rig.running_test || (card.plotId !== card.endedId ? card.plotId : null);
  if (id && card.feedId !== id) follow(card, id);
}

async function act(card, what) {
  const paths = {
    abort: card.runningId && `v1/tests/${encodeURIComponent(card.runningId)}/abort`,
    estop: `v1/rigs/${encodeURIComponent(card.name)}/estop`,
    reset: `v1/rigs/${encodeURIComponent(card.name)}/reset`,
  };
  if (!paths[what]) return;
  try {
    const v = await api("POST", paths[what]);
    card.message.textContent =
      what === "abort" ? `Aborted: ${v.stop.message}` :
      what === "estop" ? `Emergency stop: ${(v.trip && v.trip.message) || "latched"}` :
      "Latch cleared";
  } catch (e) {
    card.message.textContent = `${what} failed: ${e.message}`;
  }
  refreshRigs();
}

// ---- a test's live feed -------------------------------------------------

function newPlot(card, kind) {
  if (card.plot) card.plot.destroy();
  card.data = [[], [], []];
  const width = Math.max(320, card.plotBox.clientWidth || 560);
  const sweep = kind === "im_slip_sweep";
  card.plot = new uPlot({
    width,
    height: 240,
    scales: { x: { time: false }, A: {}, w: {} },
    axes: [
      { label: "test time, s" },
      { scale: "A", label: sweep ? "line current, A" : "current, A" },
      { scale: "w", side: 1, label: "speed, rad/s", grid: { show: false } },
    ],
    series: [
      { label: "t, s" },
      { label: "current, A", scale: "A", stroke: "#2f7de1", width: 1.5 },
      { label: "speed, rad/s", scale: "w", stroke: "#e5731b", width: 1.5 },
    ],
  }, card.data, card.plotBox);
}

/** A new plot of a sweep's operating points against slip. */
function newSweepPlot(card) {
  if (card.sweep) card.sweep.destroy();
  card.sweepBox.hidden = false;
  const width = Math.max(320, card.sweepBox.clientWidth || card.plotBox.clientWidth || 560);
  const dots = (stroke) => ({ stroke, width: 0, paths: () => null,
    points: { show: true, size: 8, stroke, fill: stroke } });
  card.sweep = new uPlot({
    width,
    height: 240,
    title: "sweep operating points",
    scales: { x: { time: false }, A: {}, W: {} },
    axes: [
      { label: "slip" },
      { scale: "A", label: "line current, A" },
      { scale: "W", side: 1, size: 70, label: "input power, W", grid: { show: false } },
    ],
    series: [
      { label: "slip" },
      Object.assign({ label: "line current, A", scale: "A" }, dots("#2f7de1")),
      Object.assign({ label: "input power, W", scale: "W" }, dots("#12a150")),
    ],
  }, [[], [], []], card.sweepBox);
  card.sweepShown = 0;
}

/** Plot the operating points a sweep has recorded so far. */
function showSweep(card, points) {
  if (!points || !points.length) return;
  if (!card.sweep) newSweepPlot(card);
  if (points.length === card.sweepShown) return;
  // uPlot wants x in ascending order; the points come in sweep order.
  const sorted = points.slice().sort((a, b) => a.slip - b.slip);
  card.sweep.setData([
    sorted.map((p) => p.slip),
    sorted.map((p) => p.line_current),
    sorted.map((p) => p.input_power),
  ]);
  card.sweepShown = points.length;
  card.root.dataset.sweepPoints = String(points.length);
}

function showProgress(card, s) {
  const seg = s.segment;
  card.test.textContent = `${s.id} · ${s.plan} · ${s.state}`;
  card.segment.textContent = seg ? `segment ${seg.index + 1}/${seg.total}: ${seg.label}` : "segment —";
  card.time.textContent = `t ${fmt(s.t_s, 1, "s")}`;
  card.eta.textContent = s.state === "finished"
    ? `${s.outcome}${s.reason ? ": " + s.reason : ""}`
    : `ETA ${fmt(s.eta_s, 1, "s")} (at most ${fmt(s.eta_max_s, 0, "s")})`;
  // Segments done: those before this one, and this one once completed.
  const done = seg ? (seg.index + (s.outcome === "completed" ? 1 : 0)) / seg.total : 0;
  card.bar.style.width = `${Math.round(Math.min(1, done) * 100)}%`;
  const v = s.values || {};
  card.values.textContent =
    `U ${fmt(v.voltage, 1, "V")} · I ${fmt(v.current, 3, "A")} · ω ${fmt(v.speed, 1, "rad/s")} · ` +
    `P ${fmt(v.power, 0, "W")} · winding ${fmt(v.winding_c, 1, "°C")}`;
  if (!card.plot) newPlot(card, seg && seg.kind);
  if (s.state === "running" && typeof v.t_s === "number") {
    const [t, i, w] = card.data;
    if (!t.length || v.t_s > t[t.length - 1]) {
      t.push(v.t_s);
      i.push(typeof v.current === "number" ? v.current : null);
      w.push(typeof v.speed === "number" ? v.speed : null);
      card.plot.setData(card.data);
    }
  }
  card.root.dataset.points = String(card.data[0].length);
  showSweep(card, s.operating_points);
}

/** Split a server-sent event stream into events; bytes are decoded as a
 * stream, so a character split across chunks comes out whole. */
async function* sseEvents(body) {
  const reader = body.getReader();
  const decoder = new TextDecoder("utf-8");
  let buffer = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buffer += decoder.decode(value, { stream: true }).replace(/\r\n/g, "\n");
    let end;
    while ((end = buffer.indexOf("\n\n")) >= 0) {
      const block = buffer.slice(0, end);
      buffer = buffer.slice(end + 2);
      let name = "message";
      const data = [];
      for (const line of block.split("\n")) {
        if (line.startsWith("event:")) name = line.slice(6).trim();
        else if (line.startsWith("data:")) data.push(line.slice(5).replace(/^ /, ""));
      }
      if (data.length) yield { name, data: data.join("\n") };
    }
  }
}

async function follow(card, id) {
  card.feedId = id;
  if (card.plotId !== id) {
    // A new test: a new plot (a feed picked up again keeps its points).
    if (card.plot) { card.plot.destroy(); card.plot = null; }
    if (card.sweep) { card.sweep.destroy(); card.sweep = null; }
    card.sweepBox.hidden = true;
    card.sweepShown = 0;
    delete card.root.dataset.sweepPoints;
    card.plotId = id;
    card.message.textContent = "";
  }
  let done = false;
  try {
    const r = await call("GET", `v1/tests/${encodeURIComponent(id)}/events`);
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    for await (const ev of sseEvents(r.body)) {
      const s = JSON.parse(ev.data);
      showProgress(card, s);
      if (ev.name === "done") {
        done = true;
        break;
      }
    }
  } catch (e) {
    if (!(e instanceof Unauthorized)) card.message.textContent = `live feed: ${e.message}; the card follows the test's status instead`;
  }
  // A feed cut before its `done` (a dropped connection, a proxy that
  // closes long answers): the test's status instead, so the card shows
  // where it is, and how it ended once it has.
  if (!done) {
    try {
      const r = await call("GET", `v1/tests/${encodeURIComponent(id)}`);
      if (r.status === 404) {
        done = true; // no longer in the daemon's run: the records have it
      } else if (r.ok) {
        const s = await r.json();
        showProgress(card, s);
        done = s.state === "finished";
      }
    } catch (e) {
      if (!(e instanceof Unauthorized)) card.message.textContent = `test status: ${e.message}`;
    }
  }
  if (done) {
    card.endedId = id;
    refreshRecords();
  }
  // A test not seen to end is followed again from the next poll.
  if (!done && card.feedId === id) card.feedId = null;
}

// ---- records ------------------------------------------------------------

function keyResults(r) {
  const p = r.key_results && r.key_results.params;
  if (!p) return "";
  return Object.entries(p).map(([k, v]) => `${k}=${Number(v).toPrecision(4)}`).join(" ");
}

/** Fetch `path` with the token and hand the browser the file. */
async function download(path, filename) {
  try {
    const r = await call("GET", path);
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    const url = URL.createObjectURL(await r.blob());
    const a = el("a", { href: url, download: filename });
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 60000);
  } catch (e) {
    if (!(e instanceof Unauthorized)) showError(`${filename}: ${e.message}`);
  }
}

async function showRecord(r) {
  const view = document.getElementById("record-view");
  view.hidden = false;
  view.replaceChildren(el("h3", {}, r.name), el("p", { class: "muted" },
    `${r.plan} · ${r.outcome}${r.reason ? ": " + r.reason : ""} · started ${r.started_at}`));
  const base = `v1/records/${encodeURIComponent(r.name)}`;
  if (r.report) {
    try {
      const rep = await api("GET", `${base}/report`);
      const best = rep.best && rep.methods[rep.best];
      const rows = best && best.params ? Object.entries(best.params).map(([k, p]) =>
        el("tr", {}, el("td", {}, k), el("td", {}, Number(p.value).toPrecision(5)),
          el("td", {}, p.ci95 ? `${Number(p.ci95[0]).toPrecision(4)} … ${Number(p.ci95[1]).toPrecision(4)}` : "—"),
          el("td", {}, p.unit))) : [];
      view.append(el("p", {}, `best method: ${rep.best || "none"}`),
        el("table", { class: "report" },
          el("thead", {}, el("tr", {}, el("th", {}, "parameter"), el("th", {}, "value"),
            el("th", {}, "95 % interval"), el("th", {}, "unit"))),
          el("tbody", {}, ...rows)));
      if (rep.warnings && rep.warnings.length) view.append(el("p", { class: "muted" }, rep.warnings.join("; ")));
      if (rep.test_warnings && rep.test_warnings.length) {
        view.append(el("p", { class: "muted test-warnings" }, `during the test: ${rep.test_warnings.join("; ")}`));
      }
    } catch (e) {
      if (!(e instanceof Unauthorized)) view.append(el("p", { class: "error" }, `report: ${e.message}`));
    }
  }
  const plots = [[r.svg, "svg", "plot"], [r.residuals_svg, "residuals", "residual plot"]];
  for (const [file, path, what] of plots) {
    if (!file) continue;
    try {
      const resp = await call("GET", `${base}/${path}`);
      if (!resp.ok) throw new Error(`HTTP ${resp.status}`);
      const url = URL.createObjectURL(await resp.blob());
      view.append(el("img", { src: url, alt: `${what} of ${r.name}`, class: `record-${path}` }));
    } catch (e) {
      if (!(e instanceof Unauthorized)) view.append(el("p", { class: "error" }, `${what}: ${e.message}`));
    }
  }
}

function showRecords(list) {
  const key = JSON.stringify(list);
  if (key === recordsShown) return;
  recordsShown = key;
  const rows = list.map((r) => {
    const base = `v1/records/${encodeURIComponent(r.name)}`;
    const actions = el("td", {});
    if (r.report || r.svg) actions.append(el("button", { type: "button", class: "show", onclick: () => showRecord(r) }, "report"), " ");
    actions.append(el("button", { type: "button", class: "download", onclick: () => download(`${base}/mcap`, r.mcap) }, "MCAP"));
    if (r.report) actions.append(" ", el("button", { type: "button", onclick: () => download(`${base}/report`, r.report) }, "JSON"));
    return el("tr", { "data-record": r.name },
      el("td", {}, r.name),
      el("td", { class: `outcome-${r.outcome}` }, r.outcome),
      el("td", {}, r.started_at),
      el("td", {}, r.plan),
      el("td", {}, keyResults(r)),
      actions);
  });
  document.querySelector("#records tbody").replaceChildren(...rows);
}

// ---- polling -------------------------------------------------------------

async function refreshRigs() {
  try {
    const v = await api("GET", "v1/rigs");
    for (const rig of v.rigs) showRig(rig);
    showError(null);
  } catch (e) {
    if (!(e instanceof Unauthorized)) showError(`rigs: ${e.message}`);
  }
}

async function refreshRecords() {
  try {
    showRecords((await api("GET", "v1/records")).records);
  } catch (e) {
    if (!(e instanceof Unauthorized)) showError(`records: ${e.message}`);
  }
}

async function refreshHealth() {
  const span = document.getElementById("daemon");
  try {
    const r = await call("GET", "v1/health");
    const v = await r.json();
    span.textContent = `daemon ${v.version} · ${v.healthy ? "healthy" : "UNHEALTHY"}`;
    span.className = v.healthy ? "muted" : "error";
  } catch (e) {
    span.textContent = e instanceof Unauthorized ? "token needed" : `unreachable: ${e.message}`;
  }
}

function refresh() {
  refreshHealth();
  refreshRigs();
  refreshRecords();
}

setupToken();
refresh();
setInterval(refreshRigs, RIG_POLL_MS);
setInterval(refreshRecords, RECORD_POLL_MS);
setInterval(refreshHealth, RECORD_POLL_MS);
