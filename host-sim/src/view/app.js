// The live view's page: fetches /state once, then follows /events (Server-Sent Events).
// Everything it draws comes from the server's event stream; it sends only pause, resume,
// step and speed, and only where the source allows them.
"use strict";

const KEEP = 3000;      // events kept for the timeline and the log
const KEEP_LIST = 200;  // entries kept in each list
const WINDOW_MS = 30000; // the timeline's span

const S = { mission: null, seq: 0, errSeq: 0, events: [], runs: [], snapshot: null, on: [],
  changes: [], incidents: [], errors: [], changedAt: {}, status: {}, ended: null };

const $ = (id) => document.getElementById(id);
function el(tag, attrs, ...kids) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") e.className = v; else e.setAttribute(k, v);
  }
  for (const k of kids) e.append(k instanceof Node ? k : document.createTextNode(String(k)));
  return e;
}
const secs = (ms) => (ms / 1000).toFixed(3);
const keep = (list, n) => { if (list.length > n) list.splice(0, list.length - n); };

function apply(u) {
  S.snapshot = u.snapshot;
  S.runs = u.runs || S.runs;
  S.on = u.on || [];
  S.ended = u.ended;
  if (u.status) S.status = u.status;
  if (typeof u.seq === "number") S.seq = u.seq;
  if (typeof u.error_seq === "number") S.errSeq = u.error_seq;
  for (const e of u.events || []) {
    S.events.push(e);
    if (e.kind === "fact") {
      S.changes.push(e);
      S.changedAt[e.fact] = e.t;
    }
    if (["violated", "restored", "plan_failed", "plan_generated", "sensor_failed", "goal"].includes(e.kind)
        || (e.kind === "state_left" && e.outcome !== "success")) {
      S.incidents.push(e);
    }
  }
  for (const line of u.errors || []) S.errors.push(line);
  keep(S.events, KEEP); keep(S.changes, KEEP_LIST); keep(S.incidents, KEEP_LIST); keep(S.errors, 20);
  if (u.coalesced) $("coalesced").textContent = "(samples thinned to keep up)";
}

function renderHeader() {
  const st = S.status || {};
  $("time").textContent = secs(S.snapshot ? S.snapshot.time_ms : 0);
  let text = S.ended ? "ended: " + S.ended : (st.paused ? "paused" : "running");
  if (st.controllable && !S.ended) text += " at " + st.speed + "×";
  $("status").textContent = text;
  $("controls").hidden = !st.controllable || !!S.ended;
  const errors = $("errors");
  errors.replaceChildren(...S.errors.map((l) => el("li", { class: "error" }, "error: " + l)));
}

// The plans that ran, in order: consecutive states of one plan make one group.
function planGroups() {
  const groups = [];
  for (const r of S.runs) {
    const last = groups[groups.length - 1];
    if (last && last.plan === r.plan && !last.closed) last.runs.push(r);
    else groups.push({ plan: r.plan, runs: [r] });
    const g = groups[groups.length - 1];
    if (r.outcome && r.outcome !== "success") g.closed = true;
  }
  const plan = S.snapshot && S.snapshot.plan;
  if (plan && (!groups.length || groups[groups.length - 1].plan !== plan)) {
    groups.push({ plan, runs: [] });
  }
  return groups;
}

function statesOf(group) {
  const lib = (S.mission.plans || []).find((p) => p.name === group.plan);
  if (lib) return lib.states;
  // A generated plan: its states as they were entered.
  const states = [];
  for (const r of group.runs) {
    states[r.state] = { action: r.action, sensors: r.sensors, parallel: r.sensors.length > 0,
      success: r.state + 1, failure: "failed" };
  }
  return states.filter(Boolean);
}

function renderFsm() {
  const fsm = $("fsm");
  const groups = planGroups();
  const plan = S.snapshot && S.snapshot.plan;
  $("plan").textContent = plan || "none yet";
  fsm.replaceChildren();
  groups.forEach((g, gi) => {
    const latest = gi === groups.length - 1;
    const row = el("div", { class: "fsm-plan", "data-plan": g.plan });
    row.append(el("span", { class: "fsm-title" }, g.plan + (latest ? "" : " (ended)") + ": "));
    const states = statesOf(g);
    states.forEach((s, i) => {
      const runs = g.runs.filter((r) => r.state === i);
      const last = runs[runs.length - 1];
      let cls = "node" + (s.parallel ? " parallel" : "");
      if (last && last.left_ms === null && latest && S.snapshot.state === s.action) cls += " current";
      else if (last && last.outcome === "success") cls += " passed";
      else if (last && last.outcome) cls += " failed";
      const chips = (s.sensors || []).map((n) =>
        el("span", { class: "chip" + (S.on.includes(n) && cls.includes("current") ? " on" : "") }, n));
      const node = el("div", { class: cls, "data-action": s.action, "data-state": i },
        el("div", { class: "name" }, (s.parallel ? "δ'" : "δ") + i + " " + s.action),
        el("div", {}, ...chips),
        el("div", { class: "edges" }, "success → " + s.success + ", failure → " + s.failure));
      if (i > 0) row.append(el("span", { class: "arrow" }, "→"));
      row.append(node);
    });
    const done = g.runs.length && g.runs[g.runs.length - 1].outcome;
    row.append(el("span", { class: "arrow" }, "→"),
      el("div", { class: "node end" + (done && done !== "success" ? " failed" : "") },
        done && done !== "success" ? "failed" : "done"));
    fsm.append(row);
  });
}

function renderRuns() {
  $("runs").replaceChildren(...S.runs.map((r) => el("li",
    { "data-plan": r.plan, "data-action": r.action, "data-outcome": r.outcome || "running" },
    r.plan + ": ", el("b", {}, r.action),
    r.sensors.length ? " ∥ {" + r.sensors.join(", ") + "}" : "",
    " from " + secs(r.entered_ms) + " s",
    r.left_ms === null ? " (running)" : " to " + secs(r.left_ms) + " s, ",
    el("span", { class: "outcome-" + (r.outcome || "running").split(" ")[0] }, r.outcome || ""))));
}

function renderFacts() {
  const snap = S.snapshot;
  if (!snap) return;
  const now = snap.time_ms;
  $("facts").tBodies[0].replaceChildren(...Object.entries(snap.facts).map(([name, v]) => {
    const at = S.changedAt[name];
    const recent = at !== undefined && now - at < 2000;
    return el("tr", { class: recent ? "changed" : "", "data-fact": name, "data-value": v },
      el("td", {}, name), el("td", { class: String(v) }, String(v)),
      el("td", {}, at !== undefined ? "changed at " + secs(at) + " s" : ""));
  }));
  $("changes").replaceChildren(...S.changes.map((e) => el("li",
    { "data-fact": e.fact, "data-value": e.value },
    secs(e.t) + " s: " + e.fact + " → ", el("span", { class: String(e.value) }, String(e.value)))));
}

function renderSensors() {
  const snap = S.snapshot;
  if (!snap || !S.mission) return;
  $("sensors").tBodies[0].replaceChildren(...S.mission.sensors.map((s) => {
    const last = snap.sensors[s.name];
    return el("tr", { "data-sensor": s.name },
      el("td", {}, s.name), el("td", {}, el("span", { class: "chip" + (S.on.includes(s.name) ? " on" : "") },
        S.on.includes(s.name) ? "on" : "off")),
      el("td", {}, !last ? "–" : last.value === null ? "no echo" : JSON.stringify(last.value)),
      el("td", {}, last ? secs(last.at_ms) + " s" : ""));
  }));
  $("incidents").replaceChildren(...S.incidents.map((e) =>
    el("li", { "data-kind": e.kind }, secs(e.t) + " s: " + e.text)));
}

function renderMission() {
  const m = S.mission;
  const d = $("mission");
  if (d.dataset.done || !m) return;
  d.dataset.done = "1";
  const set = (xs) => "{" + xs.join(", ") + "}";
  d.append(el("p", {}, "task: " + m.task.event + " from " + set(m.task.init) + " to " + set(m.task.goal)));
  d.append(el("h3", {}, "plans"));
  d.append(el("ul", {}, ...m.plans.map((p) => el("li", {}, el("b", {}, p.name),
    " trigger " + p.trigger + ", context " + set(p.context) + ", body " + p.body.join(" → ")))));
  d.append(el("h3", {}, "actions"));
  d.append(el("table", {}, el("tbody", {},
    el("tr", {}, el("th", {}, "action"), el("th", {}, "pre"), el("th", {}, "add"), el("th", {}, "del")),
    ...m.actions.map((a) => el("tr", {}, el("td", {}, a.name), el("td", {}, set(a.pre)),
      el("td", {}, set(a.add)), el("td", {}, set(a.del)))))));
}

function renderLog() {
  const shown = S.events.filter((e) => e.kind !== "sample" && e.kind !== "fact").slice(-KEEP_LIST);
  $("log").replaceChildren(...shown.map((e) => el("li", { "data-kind": e.kind }, secs(e.t) + " s: " + e.text)));
}

function renderTimeline() {
  const c = $("timeline");
  const g = c.getContext("2d");
  if (!g || !S.mission) return;
  const w = c.width, h = c.height, now = S.snapshot ? S.snapshot.time_ms : 0;
  const from = Math.max(0, now - WINDOW_MS);
  const x = (t) => 90 + (w - 100) * (t - from) / WINDOW_MS;
  const rows = [...S.mission.sensors.map((s) => s.name), "actions", "violations"];
  const rh = (h - 20) / rows.length;
  g.clearRect(0, 0, w, h);
  g.font = "12px sans-serif";
  rows.forEach((r, i) => { g.fillStyle = "#1d2433"; g.fillText(r, 4, 14 + i * rh + rh / 2); });
  for (const e of S.events) {
    if (e.t < from) continue;
    const i = e.kind === "sample" ? rows.indexOf(e.sensor)
      : e.kind === "violated" || e.kind === "restored" ? rows.length - 1 : -1;
    if (i < 0) continue;
    g.fillStyle = e.kind === "violated" ? "#b91c1c" : e.kind === "restored" ? "#15803d" : "#0f766e";
    g.fillRect(x(e.t), 4 + i * rh + (e.kind === "sample" ? rh / 3 : 0), 2, rh / 2);
  }
  const ai = rows.length - 2;
  for (const r of S.runs) {
    const end = r.left_ms === null ? now : r.left_ms;
    if (end < from) continue;
    const a = x(Math.max(r.entered_ms, from)), b = x(end);
    g.fillStyle = r.outcome && r.outcome !== "success" ? "#fca5a5" : "#bfdbfe";
    g.fillRect(a, 6 + ai * rh, Math.max(2, b - a), rh - 4);
    g.fillStyle = "#1d2433";
    g.fillText(r.action, a + 3, 4 + ai * rh + rh / 2 + 4);
  }
  g.fillStyle = "#6b7280";
  g.fillText(secs(from) + " s", 90, h - 4);
  g.fillText(secs(now) + " s", w - 70, h - 4);
}

function render() {
  renderHeader(); renderFsm(); renderRuns(); renderFacts(); renderSensors(); renderLog();
  renderTimeline(); renderMission();
}

let pending = false;
function schedule() {
  if (pending) return;
  pending = true;
  requestAnimationFrame(() => { pending = false; render(); });
}

function control(what, x) {
  const q = "do=" + what + (x !== undefined ? "&x=" + x : "");
  fetch("/control?" + q, { method: "POST" }).catch(() => {});
}

function follow() {
  const src = new EventSource("/events?since=" + S.seq + "&errors=" + S.errSeq);
  src.addEventListener("update", (m) => { apply(JSON.parse(m.data)); schedule(); });
  src.onerror = () => { $("status").textContent = "reconnecting"; };
}

function start(state) {
  S.mission = state.mission;
  $("mission-name").textContent = state.mission.name;
  $("source").textContent = state.source;
  if (state.status && state.status.speed) $("speed").value = String(state.status.speed);
  apply(state);
  render();
  follow();
}

$("pause").onclick = () => control("pause");
$("resume").onclick = () => control("resume");
$("step").onclick = () => control("step");
$("speed").onchange = (e) => control("speed", e.target.value);
// The state the page was served with draws at once; /state when it came without one.
const initial = document.getElementById("initial");
if (initial) {
  start(JSON.parse(initial.textContent));
} else {
  fetch("/state").then((r) => r.json()).then(start).catch((e) => {
    S.errors.push("the page could not load the view: " + e);
    renderHeader();
  });
}
