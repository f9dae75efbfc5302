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
function atLeast(role) { return me.role && ROLES.indexOf(me.role) >= ROLES.indexOf(role); }
function fmt(v, digits, unit) {
  return v === null || v === undefined ? "–" : `${Number(v).toFixed(digits)}${unit ? " " + unit : ""}`;
}
function eta(s) {
  if (s === null || s === undefined) return "?";
  const m = Math.floor(s / 60);
  return m >= 60 ? `${Math.floor(m / 60)} h ${String(m % 60).padStart(2, "0")} min`
    : `${m} min ${String(Math.floor(s % 60)).padStart(2, "0")} s`;
}
function when(iso) { return iso ? new Date(iso).toLocaleString() : "–"; }
function error(message) {
  const el = document.getElementById("error");
  el.textContent = message || "";
  el.hidden = !message;
}

class ApiError extends Error {
  constructor(status, message) { super(message); this.status = status; }
}

async function api(method, path, body) {
  const init = { method, credentials: "same-origin", headers: { "X-Soakcal-CSRF": "1" } };
  if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const r = await fetch(path, init);
  if (r.status === 401 && path !== "/web/session") { signedOut(); throw new ApiError(401, "signed out"); }
  if (!r.ok) {
    let detail = r.statusText;
    try {
      const d = (await r.json()).detail;
      detail = Array.isArray(d) ? d.map((e) => `${(e.loc || []).join(".")}: ${e.msg}`).join("; ") : String(d);
    } catch (_) { /* not JSON */ }
    throw new ApiError(r.status, `HTTP ${r.status}: ${detail}`);
  }
  return r.status === 204 ? null : r.json();
}

async function guarded(fn) {
  try { error(""); await fn(); } catch (e) { if (!(e instanceof ApiError && e.status === 401)) error(e.message); }
}

// --- sign-in ---------------------------------------------------------------------------
function signedOut() {
  me.role = null;
  document.getElementById("nav").hidden = true;
  document.getElementById("signout").hidden = true;
  document.getElementById("who").textContent = "";
  if (stream) { stream.close(); stream = null; }
  const token = h("input", { id: "token", type: "password", size: 50, autocomplete: "off",
    placeholder: "sct_…", required: true });
  show(h("h2", {}, "Sign in"),
    h("p", { class: "muted" }, "Paste an API token (soakcal token create --role viewer|operator|admin). ",
      "It is kept in an HttpOnly cookie for this browser session."),
    h("form", { class: "inline", id: "signin", onsubmit: (ev) => { ev.preventDefault(); guarded(async () => {
      signedIn(await api("POST", "/web/session", { token: token.value.trim() }));
    }); } }, h("label", {}, "Token", token), h("button", { class: "primary", type: "submit" }, "Sign in")));
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
  const table = h("table", { id: "campaigns" });
  async function fill() {
    const list = await api("GET", "/api/v1/campaigns");
    table.replaceChildren(h("tr", {}, ...["id", "state", "rig", "sensor", "step", "done",
      "suspended", "created"].map((t) => h("th", {}, t))), campaignRows(list));
  }
  await fill();
  show(h("h2", {}, "Campaigns"), atLeast("operator") ? startForm() : "", table,
    h("p", { class: "muted" }, `re-read every ${LIST_REFRESH_MS / 1000} s; open a campaign for live progress`));
  refresh = setInterval(() => guarded(fill), LIST_REFRESH_MS);
}

function campaignRows(list) {
  return list.map((c) => h("tr", {},
    h("td", { class: "num" }, h("a", { href: `#/campaigns/${c.id}` }, c.id)),
    h("td", {}, h("span", { class: `state ${c.state}` }, c.state)),
    h("td", {}, c.rig), h("td", {}, c.sensor),
    h("td", { class: "num" }, `${Math.min(c.progress.step, c.progress.steps - 1)} of 0..${c.progress.steps - 1}`),
    h("td", { class: "num" }, `${Math.round(c.progress.fraction * 100)} %`),
    h("td", {}, c.suspended_reason ? h("span", { class: "warn" }, c.suspended_reason) : ""),
    h("td", {}, when(c.created_at))));
}

function startForm() {
  const field = (name, label, value, attrs) => h("label", {}, label,
    h("input", Object.assign({ name, value }, attrs || {})));
  const form = h("form", { class: "inline", id: "start" },
    field("rig", "Rig", "sim", { required: true }),
    field("sensor", "Sensor serial", "", { required: true, placeholder: "SN-0001" }),
    field("setpoints_c", "Setpoints (°C, comma-separated)", "-40,-20,0,20,40,60"),
    field("soak_min", "Soak per step (min)", "60", { type: "number", step: "any", min: "0" }),
    field("positions", "Position schedule", "table1"),
    field("samples_per_position", "Samples per position", "200", { type: "number", min: "1" }),
    h("button", { class: "primary", type: "submit" }, "Start campaign"));
  form.addEventListener("submit", (ev) => { ev.preventDefault(); guarded(async () => {
    const f = new FormData(form);
    const body = { rig: f.get("rig"), sensor: f.get("sensor"), positions: f.get("positions"),
      setpoints_c: String(f.get("setpoints_c")).split(",").filter((s) => s.trim()).map(Number),
      soak_min: Number(f.get("soak_min")), samples_per_position: Number(f.get("samples_per_position")) };
    const c = await api("POST", "/api/v1/campaigns", body);
    location.hash = `#/campaigns/${c.id}`;
  }); });
  return form;
}

function chart(points) {
  // chamber temperature (°C) against wall-clock time since this page opened the stream
  const W = 640, H = 240, L = 48, B = 28, T = 10, R = 10;
  const svg = document.createElementNS("http://www.w3.org/2000/svg", "svg");
  svg.setAttribute("class", "chart"); svg.setAttribute("id", "temp-chart");
  svg.setAttribute("width", W); svg.setAttribute("height", H);
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  const el = (tag, attrs, text) => {
    const e = document.createElementNS("http://www.w3.org/2000/svg", tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    svg.append(e); return e;
  };
  const temps = points.flatMap((p) => [p.c, p.set]).filter((v) => v !== null && v !== undefined);
  if (!points.length || !temps.length) { el("text", { x: L, y: H / 2 }, "waiting for the chamber…"); return svg; }
  let lo = Math.min(...temps), hi = Math.max(...temps);
  if (hi - lo < 1) { lo -= 0.5; hi += 0.5; }
  const t1 = Math.max(points[points.length - 1].t, 1);
  const x = (t) => L + (W - L - R) * (t / t1);
  const y = (c) => T + (H - T - B) * (1 - (c - lo) / (hi - lo));
  for (let i = 0; i <= 4; i++) {
    const c = lo + (hi - lo) * i / 4;
    el("line", { class: "grid", x1: L, x2: W - R, y1: y(c), y2: y(c) });
    el("text", { x: 4, y: y(c) + 4 }, `${c.toFixed(1)} °C`);
  }
  el("line", { class: "axis", x1: L, x2: W - R, y1: H - B, y2: H - B });
  el("text", { x: L, y: H - 8 }, "0 s");
  el("text", { x: W - R - 90, y: H - 8 }, `${t1.toFixed(0)} s (wall clock)`);
  const line = (key, cls) => {
    const pts = points.filter((p) => p[key] !== null && p[key] !== undefined)
      .map((p) => `${x(p.t).toFixed(1)},${y(p[key]).toFixed(1)}`);
    if (pts.length) el("polyline", { class: cls, points: pts.join(" ") });
  };
  line("set", "setpoint"); line("c", "temp");
  return svg;
}

async function campaignView(id) {
  let c = await api("GET", `/api/v1/campaigns/${id}`);
  const points = [];
  const t0 = performance.now();
  const facts = h("dl", { class: "facts", id: "facts" });
  const chartBox = h("div", {});
  const buttons = h("p", { id: "controls" });
  const links = h("p", { id: "links" });
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

  const control = (action) => h("button", { id: `${action}-btn`, onclick: () => guarded(async () => {
    c = await api("POST", `/api/v1/campaigns/${id}/${action}`); note(c); render();
  }) }, action);

  function render() {
    const p = c.progress;
    facts.replaceChildren(
      h("dt", {}, "state"), h("dd", {}, h("span", { class: `state ${c.state}`, id: "state" }, c.state),
        c.requested_action ? h("span", { class: "warn" }, ` (${c.requested_action} requested: at the next safe point)`) : ""),
      h("dt", {}, "rig / sensor"), h("dd", {}, `${c.rig} / ${c.sensor}`),
      h("dt", {}, "step"), h("dd", { id: "step" }, `${p.step} of 0..${p.steps - 1} (${p.phase})`),
      h("dt", {}, "position"), h("dd", { id: "position" }, p.positions === null ? `${p.position}` : `${p.position} of 0..${p.positions - 1}`),
      h("dt", {}, "chamber"), h("dd", { id: "chamber" }, `${fmt(p.chamber_c, 2, "°C")} → setpoint ${fmt(p.setpoint_c, 1, "°C")}`),
      h("dt", {}, "done"), h("dd", {}, h("progress", { max: 1, value: p.fraction }), ` ${(p.fraction * 100).toFixed(1)} %`),
      h("dt", {}, "ETA"), h("dd", { id: "eta" }, eta(p.eta_s)),
      h("dt", {}, "suspended"), h("dd", { id: "suspended" }, c.suspended_reason ? h("span", { class: "warn" }, c.suspended_reason) : "no"),
      h("dt", {}, "error"), h("dd", {}, c.error || "–"),
      h("dt", {}, "progress events"), h("dd", { id: "events" }, String(events)));
    chartBox.replaceChildren(chart(points));
    buttons.replaceChildren();
    if (atLeast("operator") && !TERMINAL.includes(c.state)) {
      if (["queued", "running"].includes(c.state)) buttons.append(control("pause"), " ");
      if (c.state === "paused") buttons.append(control("resume"), " ");
      buttons.append(control("abort"));
    }
    links.replaceChildren(h("a", { href: `/api/v1/campaigns/${id}/recording.csv`, id: "recording" }, "recording (CSV, format v1)"));
    if (c.calibration_id) links.append(" · ", h("a", { href: `#/calibrations/${c.calibration_id}`, id: "calibration-link" }, `calibration ${c.calibration_id} and its figures`));
  }
  show(h("h2", {}, `Campaign ${id}`), facts, chartBox, buttons, links,
    h("h3", {}, "Seen on this page"), journal);
  note(c);
  render();
  if (!TERMINAL.includes(c.state)) {
    stream = new EventSource(`/api/v1/campaigns/${id}/events`);
    stream.addEventListener("progress", (ev) => {
      c = JSON.parse(ev.data); events += 1; note(c);
      points.push({ t: (performance.now() - t0) / 1000, c: c.progress.chamber_c, set: c.progress.setpoint_c });
      render();
    });
    stream.addEventListener("end", () => { stream.close(); stream = null;
      guarded(async () => { c = await api("GET", `/api/v1/campaigns/${id}`); note(c); render(); }); });
    stream.onerror = () => { if (stream && stream.readyState === EventSource.CLOSED) error("progress stream closed"); };
  }
}

// --- calibrations and coefficients --------------------------------------------------
async function sensorsView(serial) {
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
        h("td", {}, when(k.created_at)), h("td", {}, `${fmt(k.valid_c[0], 1)} .. ${fmt(k.valid_c[1], 1)} °C`),
        h("td", { class: "num" }, fmt(k.rmse_ug, 1, "µg"))))));
    if (!list.length) nodes.push(h("p", { class: "muted" }, "no calibration for this serial"));
    else nodes.push(coefficientForm(serial));
  }
  show(...nodes);
}

function coefficientForm(serial) {
  const t = h("input", { name: "temperature_c", type: "number", step: "any", value: "25", required: true });
  const out = h("div", { id: "coefficients" });
  const form = h("form", { class: "inline", onsubmit: (ev) => { ev.preventDefault(); guarded(async () => {
    const k = await api("GET", `/api/v1/sensors/${encodeURIComponent(serial)}/coefficients?temperature_c=${encodeURIComponent(t.value)}`);
    out.replaceChildren(h("p", {}, `calibration ${k.calibration_id} at ${fmt(k.temperature_c, 2, "°C")}`,
      k.extrapolated ? h("span", { class: "warn" }, " (extrapolated)") : "", ": calibrated = M · (raw − bias)"),
    h("table", {}, h("tr", {}, h("th", {}, "M (row)"), h("th", {}, "x"), h("th", {}, "y"), h("th", {}, "z"), h("th", {}, "bias (mg)")),
      k.matrix.map((row, i) => h("tr", {}, h("th", {}, "xyz"[i]), row.map((v) => h("td", { class: "num" }, v.toFixed(6))),
        h("td", { class: "num" }, (k.bias_g[i] * 1e3).toFixed(4))))));
  }); } }, h("label", {}, "Temperature (°C)", t), h("button", { type: "submit", id: "coef-btn" }, "Coefficients"));
  return h("div", {}, h("h3", {}, "Coefficients at a temperature (latest calibration)"), form, out);
}

async function calibrationView(id) {
  const doc = await api("GET", `/api/v1/calibrations/${id}`);
  const prov = doc.provenance || {};
  const figs = h("div", { id: "figures" }, h("p", { class: "muted" }, "drawing the figures (the fit is redone from the stored measurements)…"));
  show(h("h2", {}, `Calibration ${id}`),
    h("p", {}, h("a", { href: `/api/v1/calibrations/${id}`, download: `calibration-${id}.json` }, "model document (JSON)"),
      " · ", h("a", { href: `/api/v1/calibrations/${id}/export?format=c`, id: "export-c" }, "firmware header (C99)"),
      " · ", h("a", { href: `/api/v1/calibrations/${id}/export?format=json-flat` }, "flat JSON for other languages")),
    h("dl", { class: "facts" },
      h("dt", {}, "model"), h("dd", {}, `${doc.model_version} (${doc.mode} mode, ${doc.method} fit)`),
      h("dt", {}, "sensor / campaign"), h("dd", {}, `${prov.sensor || "–"} / ${prov.campaign_id || "–"}`),
      h("dt", {}, "rows"), h("dd", {}, prov.rows === undefined ? "–" : String(prov.rows)),
      h("dt", {}, "created"), h("dd", {}, when(prov.created_utc))),
    figs,
    prov.steps_log ? h("details", {}, h("summary", {}, "steps log (soak ends and their reasons)"),
      h("pre", {}, JSON.stringify(prov.steps_log, null, 1))) : "");
  try {
    const names = await api("GET", `/web/calibrations/${id}/figures`);
    figs.replaceChildren(...names.map((n) => h("figure", {}, h("img", { class: "figure", alt: n, src: `/web/calibrations/${id}/figures/${n}.png` }), h("figcaption", {}, n))));
  } catch (e) { figs.replaceChildren(h("p", { class: "muted" }, e.message)); }
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
  const list = await api("GET", "/api/v1/schedules");
  show(h("h2", {}, "Schedules"), atLeast("operator") ? scheduleForm() : "", h("table", { id: "schedules" },
    h("tr", {}, ...["id", "when", "next run", "last run", "last campaign", "campaign", ""].map((t) => h("th", {}, t))),
    list.map((s) => h("tr", {}, h("td", {}, s.id), h("td", {}, s.cron ? `cron ${s.cron} (${s.timezone || "UTC"})` : when(s.at)),
      h("td", {}, when(s.next_run_at)), h("td", {}, when(s.last_run_at)),
      h("td", {}, s.last_campaign_id ? h("a", { href: `#/campaigns/${s.last_campaign_id}` }, s.last_campaign_id) : "–"),
      h("td", {}, `${s.campaign.rig} / ${s.campaign.sensor}`),
      h("td", {}, atLeast("operator") ? h("button", { onclick: () => guarded(async () => {
        await api("DELETE", `/api/v1/schedules/${s.id}`); route(); }) }, "remove") : "")))),
  list.length ? "" : h("p", { class: "muted" }, "no schedules (soakcal schedule add)"));
}

async function rigsView() {
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
  show(h("h2", {}, "Rigs"), h("table", { id: "rigs" },
    h("tr", {}, ...["name", "busy", "chamber", "turntable", ""].map((t) => h("th", {}, t))),
    list.map((r) => h("tr", {}, h("td", {}, r.name), h("td", {}, r.busy ? "busy" : "idle"),
      h("td", {}, h("code", {}, JSON.stringify(r.chamber))), h("td", {}, h("code", {}, JSON.stringify(r.turntable))),
      h("td", {}, atLeast("operator") && !r.busy ? h("button", { onclick: () => check(r.name) }, "check") : "")))),
    out);
}

async function tokensView() {
  const list = await api("GET", "/api/v1/tokens");
  show(h("h2", {}, "Tokens"), h("table", { id: "tokens" },
    h("tr", {}, ...["id", "name", "role", "status", "created", "last used", "expires", ""].map((t) => h("th", {}, t))),
    list.map((t) => h("tr", {}, h("td", {}, t.id), h("td", {}, t.name || "–"), h("td", {}, t.role), h("td", {}, t.status),
      h("td", {}, when(t.created_at)), h("td", {}, when(t.last_used_at)), h("td", {}, when(t.expires_at)),
      h("td", {}, t.status === "active" ? h("button", { onclick: () => guarded(async () => {
        if (confirm(`Revoke token ${t.id}?`)) { await api("DELETE", `/api/v1/tokens/${t.id}`); route(); } }) }, "revoke") : "")))));
}

// --- routing -----------------------------------------------------------------------------
function route() {
  if (stream) { stream.close(); stream = null; }
  if (refresh) { clearInterval(refresh); refresh = null; }
  if (!me.role) return;
  const parts = location.hash.replace(/^#\/?/, "").split("/").map(decodeURIComponent);
  const views = {
    campaigns: () => (parts[1] ? campaignView(Number(parts[1])) : campaignsView()),
    sensors: () => sensorsView(parts[1]),
    calibrations: () => calibrationView(Number(parts[1])),
    schedules: schedulesView, rigs: rigsView, tokens: tokensView,
  };
  guarded(views[parts[0]] || views.campaigns);
}

window.addEventListener("hashchange", route);
document.addEventListener("DOMContentLoaded", () => {
  document.getElementById("signout").addEventListener("click", () => guarded(async () => {
    await api("DELETE", "/web/session"); signedOut();
  }));
  fetch("/web/session", { credentials: "same-origin" })
    .then((r) => (r.ok ? r.json().then(signedIn) : signedOut()))
    .catch(() => signedOut());
});
