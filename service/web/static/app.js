// soakcal dashboard: a small static app, plain JavaScript, no build step, no CDN.
// Talks to the REST API with the HttpOnly session cookie (sign-in exchanges a token for it);
// every state-changing call carries the X-Soakcal-CSRF header the service demands.
"use strict";

const ROLES = ["viewer", "operator", "admin"];
const TERMINAL = ["completed", "failed", "aborted"];
const me = { role: null, name: null };
let stream = null; // the open EventSource, closed on every navigation
let refresh = null; // the list view's re-read timer, cleared on every navigation
const LIST_REFRESH_MS = 5000;

// --- small helpers -------------------------------------------------------------------
function h(tag, attrs, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else if (v === true) el.setAttribute(k, "");
    else if (v !== false && v !== null && v !== undefined) el.setAttribute(k, v);
  }
  for (const c of children.flat()) {
    if (c !== null && c !== undefined) el.append(c instanceof Node ? c : String(c));
  }
  return el;
}
const main = () => document.getElementById("main");
function show(...nodes) { main().replaceChildren(...nodes); }
// Each navigation starts a view; a view still loading when the next one starts must not draw
// over it (nor start timers or streams): it checks its number against the current one.
let viewSeq = 0;
function showView(seq, ...nodes) {
  if (seq !== viewSeq) return false;
  show(...nodes);
  return true;
}
function atLeast(role) { return me.role && ROLES.indexOf(me.role) >= ROLES.indexOf(role); }
function fmt(v, digits, unit) {
  return v === null || v === undefined ? "–" : `${Number(v).toFixed(digits)}${unit ? " " + unit : ""}`;
}
// a duration in words a person reads at a glance: "20 s", "3 min 05 s", "9 h 25 min"
function duration(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "unknown";
  s = Math.max(0, Math.round(s));
  if (s < 60) return `${s} s`;
  const m = Math.floor(s / 60);
  return m >= 60 ? `${Math.floor(m / 60)} h ${String(m % 60).padStart(2, "0")} min`
    : `${m} min ${String(s % 60).padStart(2, "0")} s`;
}
// How much faster than the wall the rig's clock runs (a sped-up sim rig), from the progress's
// two ETAs: {speed, wall_s}, the wall ETA it was read from (longer: its 0.1 s rounding matters
// less; the page keeps the best reading it has seen).
function rigSpeed(p, best) {
  if (!p || !(p.eta_wall_s >= 1) || !(p.eta_s > 0)) return best || null;
  if (best && best.wall_s >= p.eta_wall_s) return best;
  const ratio = p.eta_s / p.eta_wall_s;
  return { speed: ratio > 1.05 ? Number(ratio.toPrecision(2)) : 1, wall_s: p.eta_wall_s };
}
// The ETA on the wall clock, with the rig's own time beside it when the rig is sped up.
function etaText(p, speed) {
  if (p.eta_s === null || p.eta_s === undefined) return "unknown";
  const wall = p.eta_wall_s ?? p.eta_s;
  const text = `ends in ${duration(wall)}`;
  return speed && speed.speed > 1 ? `${text} (rig time ${duration(p.eta_s)} at ${speed.speed}×)` : text;
}
function when(iso) { return iso ? new Date(iso).toLocaleString() : "–"; }
function error(message) {
  const el = document.getElementById("error");
  el.textContent = message || "";
  el.hidden = !message;
}

class ApiError extends Error {
  constructor(status, message, detail) { super(message); this.status = status; this.detail = detail; }
}
// The sign-in page's own words for the service's 401 reasons (service/api/auth.py).
const REFUSED = {
  "unknown token": "this token is not known to this service (mistyped, or from another service)",
  "token revoked": "this token has been revoked; ask an admin for a new one",
  "token expired": "this token has expired; ask an admin for a new one",
};
function refusal(detail) { return REFUSED[detail] || detail; }

async function api(method, path, body) {
  const init = { method, credentials: "same-origin", headers: { "X-Soakcal-CSRF": "1" } };
  if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const r = await fetch(path, init);
  if (!r.ok) {
    let detail = r.statusText, raw = null;
    try {
      raw = (await r.json()).detail;
      detail = Array.isArray(raw) ? raw.map((e) => `${(e.loc || []).join(".")}: ${e.msg}`).join("; ") : String(raw);
    } catch (_) { /* not JSON */ }
    if (r.status === 401 && path !== "/web/session") {
      // the session's token was revoked or expired while the page was open: say so
      signedOut(`Signed out: ${refusal(detail)}.`);
      throw new ApiError(401, "signed out", raw);
    }
    throw new ApiError(r.status, `HTTP ${r.status}: ${detail}`, raw);
  }
  return r.status === 204 ? null : r.json();
}

// A user's action: the last refusal is cleared, a new one shown until the next action.
async function guarded(fn) {
  try { error(""); await fn(); } catch (e) { if (!(e instanceof ApiError && e.message === "signed out")) error(e.message); }
}
// A background re-read: leaves a refusal on screen (the user has not acted since).
async function quietly(fn) {
  try { await fn(); } catch (e) { if (!(e instanceof ApiError && e.message === "signed out")) error(e.message); }
}

// --- sign-in ---------------------------------------------------------------------------
function signedOut(why) {
  me.role = null;
  if (refresh) { clearInterval(refresh); refresh = null; }
  error(why || "");
  document.getElementById("nav").hidden = true;
  document.getElementById("signout").hidden = true;
  document.getElementById("who").textContent = "";
  if (stream) { stream.close(); stream = null; }
  const token = h("input", { id: "token", type: "password", size: 50, autocomplete: "off",
    placeholder: "sct_…", required: true });
  show(h("h2", {}, "Sign in"),
    h("p", { class: "muted" }, "Paste an API token (soakcal token create --role viewer|operator|admin). ",
      "It is kept in an HttpOnly cookie for this browser session."),
    h("form", { class: "inline", id: "signin", onsubmit: (ev) => { ev.preventDefault(); error(""); (async () => {
      try {
        signedIn(await api("POST", "/web/session", { token: token.value.trim() }));
      } catch (e) {
        error(e.status === 401 ? `Sign-in refused: ${refusal(e.detail)}.` : `Sign-in failed: ${e.message}`);
      }
    })(); } }, h("label", {}, "Token", token), h("button", { class: "primary", type: "submit" }, "Sign in")));
}

function signedIn(who) {
  Object.assign(me, who);
  document.getElementById("nav").hidden = false;
  document.getElementById("signout").hidden = false;
  document.getElementById("who").textContent = `${who.name || "token " + who.token_id} (${who.role})`;
  for (const a of document.querySelectorAll("[data-role]")) a.hidden = !atLeast(a.dataset.role);
  route();
}

// --- campaigns -------------------------------------------------------------------------
async function campaignsView() {
  const seq = viewSeq;
  const table = h("table", { id: "campaigns" });
  async function fill() {
    const list = await api("GET", "/api/v1/campaigns");
    window.__listReads = (window.__listReads || 0) + 1; // the browser test counts re-reads
    // replaceChildren takes nodes, not an array: spread the rows
    table.replaceChildren(h("tr", {}, ...["id", "state", "rig", "sensor", "step", "done",
      "suspended", "created"].map((t) => h("th", {}, t))), ...campaignRows(list));
    empty.hidden = list.length > 0;
  }
  const empty = h("p", { class: "muted", id: "no-campaigns" }, "no campaigns yet");
  await fill();
  showView(seq, h("h2", {}, "Campaigns"), atLeast("operator") ? startForm() : "", table, empty,
    h("p", { class: "muted" }, `re-read every ${LIST_REFRESH_MS / 1000} s; open a campaign for live progress`));
  if (seq === viewSeq) refresh = setInterval(() => quietly(fill), LIST_REFRESH_MS);
}

function campaignRows(list) {
  return list.map((c) => h("tr", {},
    h("td", { class: "num" }, h("a", { href: `#/campaigns/${c.id}` }, c.id)),
    h("td", {}, h("span", { class: `state ${c.state}` }, c.state)),
    h("td", {}, c.rig), h("td", {}, c.sensor),
    h("td", { class: "num" }, stepText(c)),
    h("td", { class: "num" }, `${Math.round(c.progress.fraction * 100)} %`),
    h("td", {}, c.suspended_reason ? h("span", { class: "warn" }, c.suspended_reason) : ""),
    h("td", {}, when(c.created_at))));
}

// The campaign's method from its spec (the API's progress carries no method).
function isRamp(c) { return (c.spec || {}).method === "ramp"; }

// Where a campaign is, in words that stay true after it has ended (no stale "step 2 (ramp)").
function stepText(c) {
  const p = c.progress, last = p.steps - 1;
  if (isRamp(c)) {  // a ramp has sweeps (one step index each), not setpoint steps
    if (c.state === "completed") return `all ${p.step + 1} sweeps`;
    if (c.state === "failed" || c.state === "aborted") return `stopped in sweep ${p.step}`;
    return `sweep ${p.step}`;
  }
  if (c.state === "completed") return `all ${p.steps} steps`;
  if (c.state === "failed" || c.state === "aborted") return `stopped at step ${Math.min(p.step, last)} of 0..${last}`;
  return `${Math.min(p.step, last)} of 0..${last}`;
}

function startForm() {
  const field = (name, label, value, attrs) => h("label", {}, label,
    h("input", Object.assign({ name, value }, attrs || {})));
  const form = h("form", { class: "inline", id: "start" },
    field("rig", "Rig", "sim", { required: true }),
    field("sensor", "Sensor serial", "", { required: true, placeholder: "SN-0001" }),
    h("label", {}, "Method", h("select", { name: "method", title:
      "soak: each setpoint held until the die is stable; ramp: the chamber ramps through the " +
      "setpoints' range and back while the table sweeps, each capture at its die's own temperature" },
      h("option", { value: "soak" }, "soak"), h("option", { value: "ramp" }, "ramp"))),
    field("setpoints_c", "Setpoints (°C, comma-separated)", "-40,-20,0,20,40,60"),
    field("soak_min", "Soak per step (min)", "60", { type: "number", step: "any", min: "0" }),
    field("ramp_c_per_min", "Chamber ramp (°C/min)", "1", { type: "number", step: "any", min: "0" }),
    field("positions", "Position schedule", "table1"),
    field("samples_per_position", "Samples per position", "200", { type: "number", min: "1" }),
    h("button", { class: "primary", type: "submit" }, "Start campaign"));
  // The chamber ramp's default follows the method (soak 1, ramp 2 °C/min: the API's
  // defaults) until the operator types a rate of their own.
  const rampRate = form.elements.namedItem("ramp_c_per_min");
  rampRate.addEventListener("input", () => { rampRate.dataset.edited = "1"; });
  form.elements.namedItem("method").addEventListener("change", (ev) => {
    if (!rampRate.dataset.edited) rampRate.value = ev.target.value === "ramp" ? "2" : "1";
  });
  form.addEventListener("submit", (ev) => { ev.preventDefault(); guarded(async () => {
    const f = new FormData(form);
    const body = { rig: f.get("rig"), sensor: f.get("sensor"), positions: f.get("positions"),
      setpoints_c: String(f.get("setpoints_c")).split(",").filter((s) => s.trim()).map(Number),
      soak_min: Number(f.get("soak_min")), samples_per_position: Number(f.get("samples_per_position")),
      method: f.get("method"), ramp_c_per_min: Number(f.get("ramp_c_per_min")) };
    const c = await api("POST", "/api/v1/campaigns", body);
    location.hash = `#/campaigns/${c.id}`;
  }); });
  return form;
}

// Series of the temperature chart: [history key, legend label, css class].
const DIE_COLOURS = ["#2a9d8f", "#e9c46a", "#8d5fd3", "#f4a261", "#264653", "#6a994e"];

function chart(hist) {
  // chamber air, setpoint and each sensor's die (°C) against time since the campaign started
  const W = 760, H = 280, L = 56, B = 34, T = 12, R = 150;
  const NS = "http://www.w3.org/2000/svg";
  const svg = document.createElementNS(NS, "svg");
  svg.setAttribute("class", "chart"); svg.setAttribute("id", "temp-chart");
  svg.setAttribute("width", W); svg.setAttribute("height", H);
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  const el = (tag, attrs, text) => {
    const e = document.createElementNS(NS, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    svg.append(e); return e;
  };
  const series = [{ key: "chamber", label: "chamber air", cls: "temp", pts: hist ? hist.chamber_c : [] },
    { key: "setpoint", label: "setpoint", cls: "setpoint", pts: hist ? hist.setpoint_c : [] }];
  Object.entries(hist ? hist.die_c : {}).forEach(([serial, pts], i) => series.push(
    { key: `die:${serial}`, label: `die ${serial}`, cls: "die", colour: DIE_COLOURS[i % DIE_COLOURS.length], pts }));
  const all = series.flatMap((s) => s.pts);
  if (!all.length) {
    el("text", { x: L, y: H / 2 }, hist ? "no temperature stored yet: waiting for the chamber…" : "reading the stored history…");
    return svg;
  }
  let lo = Math.min(...all.map((p) => p[1])), hi = Math.max(...all.map((p) => p[1]));
  if (hi - lo < 1) { lo -= 0.5; hi += 0.5; }
  const t1 = Math.max(...all.map((p) => p[0]), 1);
  // hours when the campaign is long, minutes otherwise
  const [unit, per] = t1 >= 3 * 3600 ? ["h", 3600] : ["min", 60];
  const x = (t) => L + (W - L - R) * (t / t1);
  const y = (c) => T + (H - T - B) * (1 - (c - lo) / (hi - lo));
  for (let i = 0; i <= 4; i++) {
    const c = lo + (hi - lo) * i / 4;
    el("line", { class: "grid", x1: L, x2: W - R, y1: y(c), y2: y(c) });
    el("text", { x: 4, y: y(c) + 4 }, `${c.toFixed(1)} °C`);
  }
  // time ticks at round numbers of the unit (0, 30, 60 min; 0, 2, 4 h), at most 7
  const span = t1 / per;
  const step = [0.1, 0.2, 0.25, 0.5, 1, 2, 5, 10, 15, 20, 30, 60, 120, 240, 480].find((s) => span / s <= 6) || span;
  for (let v = 0; v <= span + 1e-9; v += step) {
    el("line", { class: "grid", x1: x(v * per), x2: x(v * per), y1: T, y2: H - B });
    el("text", { x: x(v * per) - 6, y: H - B + 14, class: "tick" }, String(Number(v.toFixed(2))));
  }
  el("line", { class: "axis", x1: L, x2: W - R, y1: H - B, y2: H - B });
  el("text", { x: L, y: H - 4, id: "x-label" }, `time since the campaign started (${unit}, rig clock)`);
  series.forEach((s, i) => {
    if (!s.pts.length) return;
    const line = el("polyline", { class: s.cls, "data-series": s.key, "data-n": s.pts.length,
      points: s.pts.map((p) => `${x(p[0]).toFixed(1)},${y(p[1]).toFixed(1)}`).join(" ") });
    if (s.colour) line.setAttribute("stroke", s.colour);
    const ly = T + 14 + 18 * i;
    const key = el("line", { class: s.cls, x1: W - R + 12, x2: W - R + 34, y1: ly - 4, y2: ly - 4 });
    if (s.colour) key.setAttribute("stroke", s.colour);
    el("text", { x: W - R + 40, y: ly, class: "legend" }, `${s.label} (°C)`);
  });
  return svg;
}

async function campaignView(id) {
  const seq = viewSeq;
  let c = await api("GET", `/api/v1/campaigns/${id}`);
  let hist = null;
  let speed = rigSpeed(c.progress, null);
  const facts = h("dl", { class: "facts", id: "facts" });
  const chartBox = h("div", { id: "chart-box" });
  const buttons = h("p", { id: "controls" });
  const links = h("p", { id: "links" });
  // What the buttons and links were last drawn from: a progress event (several a second at
  // a fast rig) redraws the facts, not these, unless they change. A button replaced under
  // the pointer between mousedown and mouseup never fires its click: an operator's pause
  // was lost (and the live pause test's dialog answered by a stale handler).
  let buttonsKey = null, linksKey = null;
  let events = 0;
  const journal = h("ul", { id: "journal" });
  let prev = null;
  // what changed between two snapshots, as lines for the page's event list
  function changes(a, b) {
    if (!a) return [`${b.state}, step ${b.progress.step} (${b.progress.phase})`];
    const out = [];
    if (a.state !== b.state) out.push(`state ${a.state} → ${b.state}`);
    if (a.progress.step !== b.progress.step || a.progress.phase !== b.progress.phase) {
      if (a.progress.phase === "soak" && b.progress.phase !== "soak") out.push(`soak ended at step ${a.progress.step}`);
      out.push(`step ${b.progress.step} ${b.progress.phase}, setpoint ${fmt(b.progress.setpoint_c, 1, "°C")}`);
    }
    if (a.suspended_reason !== b.suspended_reason) {
      out.push(b.suspended_reason ? `suspended: ${b.suspended_reason}` : "device answers again: unsuspended");
    }
    if (a.requested_action !== b.requested_action && b.requested_action) out.push(`${b.requested_action} requested`);
    if (b.error && a.error !== b.error) out.push(`error: ${b.error}`);
    return out;
  }
  function note(next) {
    for (const line of changes(prev, next)) {
      journal.prepend(h("li", {}, `${new Date().toLocaleTimeString()}  ${line}`));
    }
    prev = next;
  }

  // pause and abort change a night's run: ask first (resume does not)
  const ASK = {
    pause: () => `Pause campaign ${id}? It stops at the next safe point and waits for resume.`,
    abort: () => `Abort campaign ${id}? The chamber goes to its safe temperature; the campaign cannot be resumed.`,
  };
  const control = (action) => h("button", { id: `${action}-btn`, onclick: () => guarded(async () => {
    if (ASK[action] && !confirm(ASK[action]())) return;
    c = await api("POST", `/api/v1/campaigns/${id}/${action}`); note(c); render();
    // The answer was read when the request was stored; the stream may already have shown
    // a later state (the runner's checkpoint), and it sends only changes, so it would never
    // correct this older one: follow a new stream, whose first event is read after it.
    follow();
  }) }, action);

  function render() {
    const p = c.progress;
    const done = TERMINAL.includes(c.state);
    speed = rigSpeed(p, speed);
    const rows = [
      h("dt", {}, "state"), h("dd", {}, h("span", { class: `state ${c.state}`, id: "state" }, c.state),
        c.requested_action ? h("span", { class: "warn" }, ` (${c.requested_action} requested: at the next safe point)`) : ""),
      h("dt", {}, "rig / sensor"), h("dd", {}, `${c.rig} / ${c.sensors.join(", ")}`),
      h("dt", {}, "started"), h("dd", { id: "started" }, when(c.started_at))];
    if (done) {
      // a finished campaign: what happened, not the last progress snapshot
      const took = c.started_at && c.finished_at ? (new Date(c.finished_at) - new Date(c.started_at)) / 1000 : null;
      rows.push(h("dt", {}, "finished"), h("dd", { id: "finished" }, `${when(c.finished_at)} (took ${duration(took)} wall clock)`),
        h("dt", {}, "steps"), h("dd", { id: "step" }, stepText(c)),
        h("dt", {}, "result"), h("dd", { id: "result" }, c.state === "completed"
          ? (c.sensors.length > 1 ? `${Object.keys(c.calibration_ids || {}).length} of ${c.sensors.length} sensors calibrated`
            : c.calibration_id ? `calibration ${c.calibration_id}` : "no calibration stored")
          : (c.error || `${c.state}, no calibration`)));
    } else {
      rows.push(
        h("dt", {}, "step"), h("dd", { id: "step" }, isRamp(c)
          ? `sweep ${p.step} of about ${p.steps}` + (p.leg_target_c == null ? "" :
            `, chamber heading to ${fmt(p.leg_target_c, 1, "°C")}`) + " (ramp)"
          : `${p.step} of 0..${p.steps - 1} (${p.phase})`),
        h("dt", {}, "position"), h("dd", { id: "position" }, p.positions === null ? `${p.position}` : `${p.position} of 0..${p.positions - 1}`),
        h("dt", {}, "chamber"), h("dd", { id: "chamber" }, `${fmt(p.chamber_c, 2, "°C")} → setpoint ${fmt(p.setpoint_c, 1, "°C")}`),
        h("dt", {}, "done"), h("dd", {}, h("progress", { max: 1, value: p.fraction }), ` ${(p.fraction * 100).toFixed(1)} %`),
        h("dt", {}, "ETA (wall clock)"), h("dd", { id: "eta" }, etaText(p, speed)),
        h("dt", {}, "suspended"), h("dd", { id: "suspended" }, c.suspended_reason ? h("span", { class: "warn" }, c.suspended_reason) : "no"),
        h("dt", {}, "error"), h("dd", {}, c.error || "–"),
        h("dt", {}, "progress events"), h("dd", { id: "events" }, String(events)));
    }
    facts.replaceChildren(...rows);
    const actions = [];
    if (atLeast("operator") && !done) {
      if (["queued", "running"].includes(c.state)) actions.push("pause");
      if (c.state === "paused") actions.push("resume");
      actions.push("abort");
    }
    if (actions.join(",") !== buttonsKey) {
      buttonsKey = actions.join(",");
      buttons.replaceChildren(...actions.flatMap((a, i) => (i ? [" ", control(a)] : [control(a)])));
    }
    const several = c.sensors.length > 1;
    const linksNow = JSON.stringify([c.sensors, c.calibration_ids || null,
      c.sensors_dropped || null, c.calibration_id || null]);
    if (linksNow === linksKey) return;
    linksKey = linksNow;
    links.replaceChildren(...(several
      ? c.sensors.map((sn, i) => [i ? " · " : "", h("a", { href: `/api/v1/campaigns/${id}/recording.csv?sensor=${encodeURIComponent(sn)}` }, `recording ${sn} (CSV)`)]).flat()
      : [h("a", { href: `/api/v1/campaigns/${id}/recording.csv`, id: "recording" }, "recording (CSV, format v1)")]));
    if (several) {
      for (const [sn, cal] of Object.entries(c.calibration_ids || {})) links.append(" · ", h("a", { href: `#/calibrations/${cal}` }, `calibration ${cal} (${sn})`));
      for (const [sn, why] of Object.entries(c.sensors_dropped || {})) links.append(" · ", h("span", { class: "warn" }, `${sn} dropped: ${why}`));
    } else if (c.calibration_id) {
      links.append(" · ", h("a", { href: `#/calibrations/${c.calibration_id}`, id: "calibration-link" }, `calibration ${c.calibration_id} and its figures`));
    }
  }
  // The chart is re-read from the database (at most every 2 s while the campaign runs).
  let histAt = 0, histBusy = false;
  async function readHistory(force) {
    if (histBusy || (!force && performance.now() - histAt < 2000)) return;
    histBusy = true;
    try {
      hist = await api("GET", `/web/campaigns/${id}/temperatures`);
      histAt = performance.now();
      chartBox.replaceChildren(chart(hist));
    } finally { histBusy = false; }
  }
  chartBox.replaceChildren(chart(null));
  showView(seq, h("h2", {}, `Campaign ${id}`), facts,
    h("h3", {}, "Temperatures"), chartBox, buttons, links,
    h("h3", {}, "Seen on this page"), journal);
  note(c);
  render();
  await readHistory(true);
  follow();

  // the campaign's progress stream (while it is not finished), replacing this view's last one
  function follow() {
    if (seq !== viewSeq) return; // another view owns the stream now
    if (stream) { stream.close(); stream = null; }
    if (TERMINAL.includes(c.state)) return;
    const mine = stream = new EventSource(`/api/v1/campaigns/${id}/events`);
    mine.addEventListener("progress", (ev) => {
      if (stream !== mine) return;
      c = JSON.parse(ev.data); events += 1; note(c); render();
      quietly(() => readHistory(false));
    });
    mine.addEventListener("end", () => { mine.close(); if (stream !== mine) return; stream = null;
      quietly(async () => { c = await api("GET", `/api/v1/campaigns/${id}`); note(c); render(); await readHistory(true); }); });
    mine.onerror = () => { if (stream === mine && mine.readyState === EventSource.CLOSED) error("progress stream closed"); };
  }
}

// --- calibrations and coefficients --------------------------------------------------
async function sensorsView(serial) {
  const seq = viewSeq;
  const input = h("input", { name: "serial", value: serial || "", required: true, placeholder: "SN-0001" });
  const form = h("form", { class: "inline", id: "sensor-form", onsubmit: (ev) => {
    ev.preventDefault(); location.hash = `#/sensors/${encodeURIComponent(input.value.trim())}`; } },
  h("label", {}, "Sensor serial", input), h("button", { type: "submit" }, "Show calibrations"));
  const nodes = [h("h2", {}, "Calibrations per sensor"), form];
  if (serial) {
    const list = await api("GET", `/api/v1/sensors/${encodeURIComponent(serial)}/calibrations`);
    nodes.push(h("table", {}, h("tr", {}, ...["id", "campaign", "created", "valid range", "RMSE"].map((t) => h("th", {}, t))),
      list.map((k) => h("tr", {}, h("td", {}, h("a", { href: `#/calibrations/${k.id}` }, k.id)),
        h("td", {}, k.campaign_id ? h("a", { href: `#/campaigns/${k.campaign_id}` }, k.campaign_id) : "–"),
        h("td", {}, when(k.created_at)), h("td", {}, `${fmt(k.valid_c[0], 1)} … ${fmt(k.valid_c[1], 1)} °C`),
        h("td", { class: "num" }, fmt(k.rmse_ug, 1, "µg"))))));
    if (!list.length) nodes.push(h("p", { class: "muted" }, "no calibration for this serial"));
    else nodes.push(coefficientForm(serial, list[0]));
  }
  showView(seq, ...nodes);
}

function coefficientForm(serial, latest) {
  const t = h("input", { name: "temperature_c", type: "number", step: "any", value: "25", required: true });
  const extrapolate = h("input", { name: "extrapolate", type: "checkbox", id: "extrapolate" });
  const out = h("div", { id: "coefficients" });
  const [lo, hi] = latest.valid_c;
  const form = h("form", { class: "inline", onsubmit: (ev) => { ev.preventDefault(); guarded(async () => {
    out.replaceChildren();
    const query = `temperature_c=${encodeURIComponent(t.value)}${extrapolate.checked ? "&extrapolate=true" : ""}`;
    let k;
    try {
      k = await api("GET", `/api/v1/sensors/${encodeURIComponent(serial)}/coefficients?${query}`);
    } catch (e) {
      const outside = e.status === 422 && Array.isArray(e.detail) && e.detail.some((d) => /outside/.test(d.msg || ""));
      if (!outside) throw e;
      // the service's words are for API users (raw floats, a query parameter): say it with
      // this page's control
      throw new Error(`${fmt(Number(t.value), 1, "°C")} is outside calibration ${latest.id}'s valid range ` +
        `${fmt(lo, 1)} … ${fmt(hi, 1)} °C, where the model was not measured. Tick ` +
        `"extrapolate outside the valid range" to evaluate it there anyway.`);
    }
    out.replaceChildren(h("p", {}, `calibration ${k.calibration_id} at ${fmt(k.temperature_c, 2, "°C")}`,
      k.extrapolated ? h("span", { class: "warn", id: "extrapolated" }, " (extrapolated: outside the valid range)") : "", ": calibrated = M · (raw − bias)"),
    h("table", {}, h("tr", {}, h("th", {}, "M (row)"), h("th", {}, "x"), h("th", {}, "y"), h("th", {}, "z"), h("th", {}, "bias (mg)")),
      k.matrix.map((row, i) => h("tr", {}, h("th", {}, "xyz"[i]), row.map((v) => h("td", { class: "num" }, v.toFixed(6))),
        h("td", { class: "num" }, (k.bias_g[i] * 1e3).toFixed(4))))));
  }); } }, h("label", {}, "Temperature (°C)", t),
  h("label", { class: "check" }, h("span", {}, extrapolate, " extrapolate outside the valid range")),
  h("button", { type: "submit", id: "coef-btn" }, "Coefficients"));
  return h("div", {}, h("h3", {}, "Coefficients at a temperature (latest calibration)"),
    h("p", { class: "muted" }, `valid ${fmt(lo, 1)} … ${fmt(hi, 1)} °C`), form, out);
}

// |g| errors: µg below 1 mg, mg above (a raw sensor is off by mg, a calibrated one by µg)
function gErr(ug) {
  if (ug === null || ug === undefined) return "–";
  return Math.abs(ug) >= 1000 ? `${(ug / 1000).toFixed(2)} mg` : `${ug.toFixed(1)} µg`;
}
const words = (s) => (s ? String(s).replaceAll("_", " ") : "–");

async function calibrationView(id) {
  const seq = viewSeq;
  const [doc, sum] = await Promise.all([api("GET", `/api/v1/calibrations/${id}`),
    api("GET", `/web/calibrations/${id}/summary`)]);
  const prov = doc.provenance || {};
  const figs = h("div", { id: "figures" }, h("p", { class: "muted" }, "drawing the figures (the fit is redone from the stored measurements)…"));
  const heldOut = h("dd", { id: "loo" }, "computing (the fit is redone from the stored measurements)…");
  const lotCheck = h("dd", { id: "lot" }, "…");
  quietly(async () => {
    const k = await api("GET", `/api/v1/fleet/calibrations/${id}`);
    lotCheck.replaceChildren(k.flags.length
      ? h("span", { class: "warn" }, `OUTSIDE its lot (${k.model}, ${k.sensors} sensors): ` +
        k.flags.map((f) => `${f.name} ${f.z > 0 ? "+" : ""}${f.z.toFixed(1)}σ`).join(", "))
      : k.note ? `no verdict: ${k.note}` : `within ±4σ of its lot (${k.model}, ${k.sensors} sensors)`,
    " · ", h("a", { href: "#/fleet" }, "fleet"));
  });
  const degree = sum.degree === null ? "–" : `${sum.degree}` +
    (sum.degree_requested !== null && sum.degree_requested !== sum.degree ? ` (${sum.degree_requested} asked; see notes)` : "");
  const all12 = sum.held.length === 0 && sum.fitted.length === 12;
  const jf = sum.joint_fit;
  const stepTable = h("table", { id: "cal-steps" },
    h("tr", {}, ...["step", "setpoint", "die temperature", "positions", "|g| RMSE raw", "after step fit",
      "after thermal model", "χ²red", "soak (rig clock)", "soak ended because"].map((t) => h("th", {}, t))),
    sum.steps.map((st) => h("tr", {}, h("td", { class: "num" }, st.step),
      h("td", { class: "num" }, fmt(st.setpoint_c, 1, "°C")), h("td", { class: "num" }, fmt(st.temperature_c, 2, "°C")),
      h("td", { class: "num" }, st.positions ?? "–"), h("td", { class: "num" }, gErr(st.rmse_before_ug)),
      h("td", { class: "num" }, gErr(st.rmse_step_fit_ug)), h("td", { class: "num" }, gErr(st.rmse_after_ug)),
      h("td", { class: "num" }, fmt(st.chi2_red, 2)), h("td", { class: "num" }, duration(st.soak_s)),
      h("td", {}, words(st.soak_reason)))));
  // a continuous (ramp) or warm-up fit: Table 6 per temperature band, heating and cooling legs
  const legsText = (l) => (!l ? "one leg only" : l.difference_ug.map((d, i) =>
    `${d >= 0 ? "+" : ""}${d.toFixed(1)} ± ${l.difference_se_ug[i].toFixed(1)}`).join(" / ") +
    (l.agree ? " (agree)" : " (DISAGREE)"));
  const bandTable = h("table", { id: "cal-bands" },
    h("tr", {}, ...["band", "rows", "positions", "|g| RMSE raw", "after", "heating − cooling residual (µg)"].map((t) => h("th", {}, t))),
    sum.bands.map((b) => h("tr", {}, h("td", { class: "num" }, `${fmt(b.lo_c, 0)} … ${fmt(b.hi_c, 0)} °C`),
      h("td", { class: "num" }, b.rows), h("td", { class: "num" }, b.positions),
      h("td", { class: "num" }, gErr(b.rmse_before_ug)), h("td", { class: "num" }, gErr(b.rmse_after_ug)),
      h("td", {}, legsText(b.legs)))));
  const warmup = sum.method === "warmup";
  const ho = sum.heldout_mg_xyz;
  const stepsTitle = sum.method === "continuous" ? "Plateaus (fitted with every other row)" : "Per step";
  if (!showView(seq, h("h2", {}, `Calibration ${id}`),
    h("p", {}, h("a", { href: `/api/v1/calibrations/${id}`, download: `calibration-${id}.json` }, "model document (JSON)"),
      " · ", h("a", { href: `/api/v1/calibrations/${id}/export?format=c`, id: "export-c" }, "firmware header (C99)"),
      " · ", h("a", { href: `/api/v1/calibrations/${id}/export?format=json-flat` }, "flat JSON for other languages")),
    h("dl", { class: "facts", id: "cal-facts" },
      h("dt", {}, "sensor / campaign"), h("dd", {}, h("a", { href: `#/sensors/${encodeURIComponent(sum.sensor)}` }, sum.sensor), " / ",
        sum.campaign_id ? h("a", { href: `#/campaigns/${sum.campaign_id}` }, sum.campaign_id) : "–"),
      h("dt", {}, "|g| RMSE before (raw)"), h("dd", { id: "rmse-before" }, gErr(sum.rmse_before_ug)),
      h("dt", {}, warmup ? "|g| RMSE after (warm-up model: only what it fitted)" : "|g| RMSE after (thermal model)"),
      h("dd", { id: "rmse-after" }, gErr(sum.rmse_after_ug)),
      sum.rmse_caveat ? h("dd", { id: "rmse-caveat" }, sum.rmse_caveat) : "",
      warmup ? h("dt", {}, "scatter about each orientation's mean (per axis)") : "",
      warmup ? h("dd", { id: "scatter" }, `${gErr(sum.scatter_ug)} after; held out x/y/z: ` +
        `${ho.uncompensated.map((v) => v.toFixed(3)).join(" / ")} → ${ho.compensated.map((v) => v.toFixed(3)).join(" / ")} mg`) : "",
      h("dt", {}, "held out (leave one position out)"), heldOut,
      h("dt", {}, "valid range"), h("dd", { id: "valid" }, `${fmt(sum.valid_c[0], 1)} … ${fmt(sum.valid_c[1], 1)} °C (${words(sum.temperature_source)})`),
      h("dt", {}, "drift at fixed orientation"), h("dd", { id: "drift" }, sum.drift_ug_per_k.before === null && sum.drift_ug_per_k.after === null
        ? `not computed for a ${sum.method} fit` : `${fmt(sum.drift_ug_per_k.before, 1)} → ${fmt(sum.drift_ug_per_k.after, 2)} µg/K`),
      h("dt", {}, "model"), h("dd", {}, `${sum.model_version}, ${sum.mode} mode, ${sum.method} fit, thermal polynomial degree ${degree}`),
      h("dt", {}, "fitted"), h("dd", { id: "fitted" }, all12 ? "all 12 SFEM parameters (Eq. 1)" : (sum.fitted.join(", ") || "none") +
        (warmup && sum.fitted.length ? " (their change with temperature, or absolutely where the notes say so)" : "")),
      h("dt", {}, "held at nominal"), h("dd", { id: "held" }, sum.held.length ? `${sum.held.join(", ")} (the positions cannot identify them)` : "none"),
      h("dt", {}, "against its lot"), lotCheck,
      h("dt", {}, "joint fit"), h("dd", { id: "joint" }, jf ? `${jf.success ? "converged" : "DID NOT CONVERGE"}, χ²red ${fmt(jf.chi2_red, 2)}`
        : sum.chi2_red !== null ? `none (continuous fit: χ²red ${fmt(sum.chi2_red, 2)})` : "–"),
      h("dt", {}, "created"), h("dd", {}, when(prov.created_utc))),
    sum.bands.length ? h("div", {}, h("h3", {}, "Per temperature band"), bandTable) : "",
    sum.steps.length || !sum.bands.length ? h("div", {}, h("h3", {}, stepsTitle), stepTable) : "",
    sum.notes.length ? h("div", {}, h("h3", {}, "Notes"), h("ul", { id: "cal-notes" }, sum.notes.map((n) => h("li", {}, n)))) : "",
    h("h3", {}, "Figures"), figs,
    prov.steps_log ? h("details", {}, h("summary", {}, "steps log (soak ends and their reasons)"),
      h("pre", {}, JSON.stringify(prov.steps_log, null, 1))) : "")) return;
  try {
    const names = await api("GET", `/web/calibrations/${id}/figures`);
    if (!names.length) figs.replaceChildren(h("p", { class: "muted", id: "no-figures" }, `none: figures are drawn for step fits; this is a ${sum.method} fit (its table per temperature band is above)`));
    else figs.replaceChildren(...names.map((n) => h("figure", {}, h("img", { class: "figure", alt: n, src: `/web/calibrations/${id}/figures/${n}.png` }), h("figcaption", {}, n))));
    const ho = await api("GET", `/web/calibrations/${id}/holdout`);
    heldOut.replaceChildren(ho.loo_rmse_ug === null
      ? h("span", { class: "warn" }, `not given: ${(ho.warnings || []).join("; ") || "too few spare degrees of freedom"}`)
      : `${gErr(ho.loo_rmse_ug)} (in-sample ${gErr(ho.rmse_ug)}; ${ho.dof.spare} spare degrees of freedom in the worst step)`);
  } catch (e) {
    figs.replaceChildren(h("p", { class: "muted" }, e.message));
    heldOut.replaceChildren(`not available: ${e.message}`);
  }
}

// --- fleet: lot statistics -------------------------------------------------------------
// A parameter's value in the unit a person reads: biases in mg, gains and angles in ppm /
// mrad, their tempcos per °C.
function lotValue(v, unit) {
  const base = unit.split("/")[0];
  if (unit.includes("/")) {  // a tempco: µg, ppm, µrad per °C
    const name = { g: "µg", 1: "ppm", rad: "µrad" }[base];
    return name ? `${(v * 1e6).toPrecision(4)} ${name}/°C` : `${v.toPrecision(4)} ${unit}`;
  }
  if (base === "g") return `${(v * 1e3).toPrecision(4)} mg`;
  if (base === "1") return v.toFixed(6);  // a gain: near 1
  if (base === "rad") return `${(v * 1e3).toPrecision(4)} mrad`;
  return `${v.toPrecision(4)} ${unit}`;
}

function zChart(lot, names, id, title) {
  // every sensor's distance from its lot's median in σ, one column per parameter
  const W = 760, H = 230, L = 40, B = 40, T = 20, R = 10, ZMAX = 8;
  const NS = "http://www.w3.org/2000/svg";
  const svg = document.createElementNS(NS, "svg");
  svg.setAttribute("class", "chart"); svg.setAttribute("id", id);
  svg.setAttribute("width", W); svg.setAttribute("height", H); svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  const el = (tag, attrs, text) => {
    const e = document.createElementNS(NS, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    svg.append(e); return e;
  };
  const y = (z) => T + (H - T - B) * (1 - (Math.max(-ZMAX, Math.min(ZMAX, z)) + ZMAX) / (2 * ZMAX));
  const x = (i) => L + (W - L - R) * (i + 0.5) / names.length;
  el("text", { x: L, y: 13, class: "legend" }, title);
  for (const z of [-4, 0, 4]) {
    el("line", { class: z ? "limit" : "grid", x1: L, x2: W - R, y1: y(z), y2: y(z) });
    el("text", { x: 4, y: y(z) + 4 }, `${z > 0 ? "+" : ""}${z}σ`);
  }
  const spread = Object.fromEntries(lot.spreads.map((s) => [s.name, s]));
  names.forEach((name, i) => {
    el("text", { x: x(i) - 12, y: H - B + 16, class: "tick" }, name.replace(/^d(.*)\/dT$/, "$1′"));
    const sp = spread[name];
    for (const [serial, cal, v] of lot.values[name] || []) {
      const z = sp && sp.sigma > 0 ? (v - sp.median) / sp.sigma : 0;
      const out = Math.abs(z) > 4 && lot.flags.some((f) => f.calibration_id === cal && f.name === name);
      const dot = el("circle", { cx: x(i), cy: y(z), r: out ? 4 : 2.5, class: out ? "outlier" : "member",
        "data-sensor": serial, "data-name": name });
      const t = document.createElementNS(NS, "title");
      t.textContent = `${serial}: ${lotValue(v, sp.unit)} (${z.toFixed(1)}σ)`;
      dot.append(t);
    }
  });
  el("text", { x: L, y: H - 6 }, `distance from the lot's median in σ = 1.4826 × MAD (clipped at ±${ZMAX}σ); red: beyond ±4σ`);
  return svg;
}

async function fleetView() {
  const seq = viewSeq;
  const t = h("input", { name: "reference_c", type: "number", step: "any", value: fleetView.reference_c ?? 25, required: true });
  const stats = await api("GET", `/api/v1/fleet/lots?reference_c=${encodeURIComponent(t.value)}`);
  const form = h("form", { class: "inline", id: "fleet-form", onsubmit: (ev) => {
    ev.preventDefault(); fleetView.reference_c = t.value; route(); } },
  h("label", {}, "Parameters at (°C)", t), h("button", { type: "submit" }, "Show"));
  const params = ["bx", "by", "bz", "sx", "sy", "sz", "ayx", "azx", "azy", "mx", "my", "mz"];
  const lots = stats.lots.map((lot) => h("section", { class: "lot", "data-model": lot.model },
    h("h3", {}, `${lot.model}: ${lot.sensors} sensor(s) at ${stats.reference_c} °C`),
    lot.note ? h("p", { class: "warn lot-note" }, lot.note) : "",
    lot.left_out.length ? h("p", { class: "muted" }, `left out (${stats.reference_c} °C outside their valid range): ${lot.left_out.join(", ")}`) : "",
    lot.flags.length
      ? h("table", { class: "lot-flags" }, h("tr", {}, ...["sensor", "calibration", "parameter", "value", "lot median", "distance"].map((x) => h("th", {}, x))),
        lot.flags.map((f) => {
          const sp = lot.spreads.find((x) => x.name === f.name);
          return h("tr", { class: "fail" }, h("td", {}, h("a", { href: `#/sensors/${encodeURIComponent(f.sensor)}` }, f.sensor)),
            h("td", {}, h("a", { href: `#/calibrations/${f.calibration_id}` }, f.calibration_id)), h("td", {}, f.name),
            h("td", { class: "num" }, lotValue(f.value, sp.unit)), h("td", { class: "num" }, lotValue(sp.median, sp.unit)),
            h("td", { class: "num" }, `${f.z > 0 ? "+" : ""}${f.z.toFixed(1)}σ`));
        }))
      : h("p", { class: "lot-ok" }, lot.note ? "no sensor flagged (too few to judge)" : `every sensor within ±${stats.flag_sigma}σ of its lot`),
    lot.plotted < lot.sensors ? h("p", { class: "muted" }, `plotted: every flagged sensor and an even sample of the rest, ${lot.plotted} of ${lot.sensors}`) : "",
    zChart(lot, params, `z-${lot.model}`, "SFEM parameters (Eq. 1)"),
    zChart(lot, params.map((p) => `d${p}/dT`), `zt-${lot.model}`, "their temperature coefficients (′ = d/dT)"),
    h("details", {}, h("summary", {}, "median and σ per parameter"),
      h("table", { class: "lot-spreads" }, h("tr", {}, ...["parameter", "n", "median", "σ"].map((x) => h("th", {}, x))),
        lot.spreads.map((sp) => h("tr", {}, h("td", {}, sp.name), h("td", { class: "num" }, sp.n),
          h("td", { class: "num" }, lotValue(sp.median, sp.unit)), h("td", { class: "num" }, lotValue(sp.sigma, sp.unit))))))));
  showView(seq, h("h2", {}, "Fleet: lot statistics"),
    h("p", { class: "muted" }, "The latest calibration of each sensor, grouped by sensor model; a sensor more than 4σ from its lot's median is flagged (a bad mount or a damaged part more often than a real outlier)."),
    form, ...lots, stats.lots.length ? "" : h("p", { class: "muted" }, "no calibrations yet"));
}

// --- schedules, rigs, tokens ----------------------------------------------------------
function scheduleForm() {
  const field = (name, label, value, attrs) => h("label", {}, label,
    h("input", Object.assign({ name, value }, attrs || {})));
  const form = h("form", { class: "inline", id: "schedule-form" },
    field("cron", "Cron (min hour dom mon dow)", "0 20 * * 1-5"),
    field("timezone", "Time zone (IANA)", "UTC"),
    field("at", "or once at (ISO-8601, UTC)", "", { placeholder: "2026-12-01T20:00:00Z" }),
    field("rig", "Rig", "sim", { required: true }),
    field("sensor", "Sensor serial", "", { required: true, placeholder: "SN-0001" }),
    field("setpoints_c", "Setpoints (°C)", "-40,-20,0,20,40,60"),
    field("soak_min", "Soak (min)", "60", { type: "number", step: "any", min: "0" }),
    h("button", { class: "primary", type: "submit" }, "Add schedule"));
  form.addEventListener("submit", (ev) => { ev.preventDefault(); guarded(async () => {
    const f = new FormData(form);
    const at = String(f.get("at")).trim();
    const body = { campaign: { rig: f.get("rig"), sensor: f.get("sensor"), soak_min: Number(f.get("soak_min")),
      setpoints_c: String(f.get("setpoints_c")).split(",").filter((x) => x.trim()).map(Number) } };
    if (at) body.at = at;
    else { body.cron = String(f.get("cron")).trim(); body.timezone = String(f.get("timezone")).trim() || null; }
    await api("POST", "/api/v1/schedules", body);
    route();
  }); });
  return h("details", {}, h("summary", {}, "Add a schedule (the at field, when filled, wins over cron)"), form);
}

async function schedulesView() {
  const seq = viewSeq;
  const list = await api("GET", "/api/v1/schedules");
  showView(seq, h("h2", {}, "Schedules"), atLeast("operator") ? scheduleForm() : "", h("table", { id: "schedules" },
    h("tr", {}, ...["id", "when", "next run", "last run", "last campaign", "campaign", ""].map((t) => h("th", {}, t))),
    list.map((s) => h("tr", {}, h("td", {}, s.id), h("td", {}, s.cron ? `cron ${s.cron} (${s.timezone || "UTC"})` : when(s.at)),
      h("td", {}, when(s.next_run_at)), h("td", {}, when(s.last_run_at)),
      h("td", {}, s.last_campaign_id ? h("a", { href: `#/campaigns/${s.last_campaign_id}` }, s.last_campaign_id) : "–"),
      h("td", {}, `${s.campaign.rig} / ${s.campaign.sensor}`),
      h("td", {}, atLeast("operator") ? h("button", { onclick: () => guarded(async () => {
        if (!confirm(`Remove schedule ${s.id} (${s.campaign.rig} / ${s.campaign.sensor})? No further campaigns start from it.`)) return;
        await api("DELETE", `/api/v1/schedules/${s.id}`); route(); }) }, "remove") : "")))),
  list.length ? "" : h("p", { class: "muted" }, "no schedules (soakcal schedule add)"));
}

async function rigsView() {
  const seq = viewSeq;
  const list = await api("GET", "/api/v1/rigs");
  const out = h("div", { id: "rig-check" });
  // The connection check of `soakcal rig check` (POST /rigs/{name}/check): reads only, moves nothing.
  const check = (name) => guarded(async () => {
    out.replaceChildren(h("p", { class: "muted" }, `checking rig ${name}…`));
    const r = await api("POST", `/api/v1/rigs/${encodeURIComponent(name)}/check`, { move: false });
    out.replaceChildren(h("h3", {}, `Rig ${r.rig}: ${r.passed ? "every check passed" : "NOT READY"}`),
      h("table", {}, h("tr", {}, ...["device", "check", "status", "detail", "what to fix"].map((t) => h("th", {}, t))),
        r.checks.map((c) => h("tr", { class: c.status }, h("td", {}, c.device), h("td", {}, c.check),
          h("td", {}, c.status), h("td", {}, c.detail), h("td", {}, c.fix || "")))));
  });
  showView(seq, h("h2", {}, "Rigs"), h("table", { id: "rigs" },
    h("tr", {}, ...["name", "busy", "chamber", "turntable", ""].map((t) => h("th", {}, t))),
    list.map((r) => h("tr", {}, h("td", {}, r.name), h("td", {}, r.busy ? "busy" : "idle"),
      h("td", {}, h("code", {}, JSON.stringify(r.chamber))), h("td", {}, h("code", {}, JSON.stringify(r.turntable))),
      h("td", {}, atLeast("operator") && !r.busy ? h("button", { onclick: () => check(r.name) }, "check") : "")))),
    out);
}

async function tokensView() {
  const seq = viewSeq;
  const list = await api("GET", "/api/v1/tokens");
  showView(seq, h("h2", {}, "Tokens"), h("table", { id: "tokens" },
    h("tr", {}, ...["id", "name", "role", "status", "created", "last used", "expires", ""].map((t) => h("th", {}, t))),
    list.map((t) => h("tr", {}, h("td", {}, t.id), h("td", {}, t.name || "–"), h("td", {}, t.role), h("td", {}, t.status),
      h("td", {}, when(t.created_at)), h("td", {}, when(t.last_used_at)), h("td", {}, when(t.expires_at)),
      h("td", {}, t.status === "active" ? h("button", { onclick: () => guarded(async () => {
        if (confirm(`Revoke token ${t.id}?`)) { await api("DELETE", `/api/v1/tokens/${t.id}`); route(); } }) }, "revoke") : "")))));
}

// --- routing -----------------------------------------------------------------------------
function route() {
  viewSeq += 1;
  if (stream) { stream.close(); stream = null; }
  if (refresh) { clearInterval(refresh); refresh = null; }
  if (!me.role) return;
  const parts = location.hash.replace(/^#\/?/, "").split("/").map(decodeURIComponent);
  const views = {
    campaigns: () => (parts[1] ? campaignView(Number(parts[1])) : campaignsView()),
    sensors: () => sensorsView(parts[1]),
    calibrations: () => calibrationView(Number(parts[1])),
    schedules: schedulesView, rigs: rigsView, tokens: tokensView, fleet: fleetView,
  };
  guarded(views[parts[0]] || views.campaigns);
}

window.addEventListener("hashchange", route);
document.addEventListener("DOMContentLoaded", () => {
  document.getElementById("signout").addEventListener("click", () => guarded(async () => {
    await api("DELETE", "/web/session"); signedOut();
  }));
  fetch("/web/session", { credentials: "same-origin" })
    .then((r) => (r.ok ? r.json().then(signedIn) : r.json().then((d) => signedOut(
      REFUSED[d.detail] ? `Your session ended: ${refusal(d.detail)}.` : "")).catch(() => signedOut())))
    .catch(() => signedOut());
});
