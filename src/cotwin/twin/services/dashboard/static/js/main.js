// The dashboard page: reads the twin's description (/api/model), builds the views, then follows the
// live stream (/ws): samples feed the plot, the 3D view and the state machines; events (commands,
// operation calls, alarms) go to their lists and onto the plot. `window.cotwin` exposes counters
// (samples, frames) for tests and the curious.

import { TimePlot, PALETTE, legend } from "./plot.js";
import { MachineView } from "./machine.js";
import { buildPanel } from "./panel.js";
import { HistoryView } from "./history.js";

const $ = (id) => document.getElementById(id);
const page = (window.cotwin = { samples: 0, skipped: 0, batches: 0, events: [], status: {}, model: null });
const MAX_LOG = 200;

function li(html, cls = "") {
  const e = document.createElement("li");
  e.innerHTML = html;
  if (cls) e.className = cls;
  return e;
}

function esc(text) {
  return String(text).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
}

function prepend(list, item) {
  list.prepend(item);
  while (list.children.length > MAX_LOG) list.lastChild.remove();
}

function args(values) {
  if (values === null || typeof values !== "object") return esc(values);
  return Object.entries(values).map(([k, v]) => `${esc(k)}=${typeof v === "object" ? `{${args(v)}}` : esc(typeof v === "number" ? +v.toFixed(4) : v)}`).join(", ");
}

class Live {
  constructor(model) {
    this.model = model;
    this.sides = model.sides;
    const vars = (this.vars = model.variables.map((v, i) => ({ ...v, color: PALETTE[i % PALETTE.length],
      visible: v.kind === "position" })));
    const series = [];
    this.sides.forEach((side, s) => vars.forEach((v) => series.push({ label: `${side} ${v.name}`, color: v.color,
      dash: this.sides.length > 1 && s === 0 ? [5, 3] : [], visible: v.visible })));
    this.plot = new TimePlot($("plot"), series);
    legend($("plot-legend"), vars, this.sides, (i, on) => this.sides.forEach((_, s) => this.plot.setVisible(s * vars.length + i, on)));
    $("plot-window").addEventListener("change", (e) => this.plot.setWindow(Number(e.target.value)));
    $("plot-caption").textContent = this.sides.length > 1 ? "PT and DT" : "";
    this.machines = model.machines.map((m) => new MachineView($("machines"), m, this.sides));
    $("machine-caption").textContent = model.module;
    buildPanel($("commands"), $("command-caption"), $("sent"), model.commands);
    if (model.features.whatif) this.whatif(); // issue 9: shown when the twin answers what-if requests
    this.robot = null;
    this.openAlarms = {};
    this.opsSeen = new Map();
    this.last = null;
    import("./robot.js").then(({ RobotView }) => { // the 3D view loads beside the rest, never before it
      this.robot = new RobotView($("view"), model);
      page.robot = this.robot;
      const names = (model.robots || [model.robot]).map((r) => r.label || r.name).join(" and ");
      $("view-caption").textContent = names + (this.sides.length > 1 ? " (PT orange ghost, DT grey)" : "");
      if (this.last) this.robot.pose(this.last);
    }).catch((err) => { $("view").textContent = `3D view unavailable: ${err}`; });
  }

  // the what-if panel: a JSON plan (times from now), the prediction overlaid on the plot and summed up
  whatif() {
    $("whatif").hidden = false;
    const ev = this.model.commands.events[0];
    if (ev) {
      const args = Object.fromEntries(ev.values.map((v) => [v.label, v.type === "Boolean" ? false : 0]));
      $("whatif-plan").value = JSON.stringify([{ time: 0.5, event: ev.name, args }]);
    }
    $("whatif-run").addEventListener("click", async () => {
      const out = $("whatif-result");
      out.replaceChildren(li("predicting…"));
      let plan;
      try { plan = JSON.parse($("whatif-plan").value); } catch (err) { out.replaceChildren(li(`the plan is not JSON: ${esc(err.message)}`, "error")); return; }
      const r = await fetch("/api/whatif", { method: "POST", headers: { "Content-Type": "application/json" },
        body: JSON.stringify({ plan, horizon: Number($("whatif-horizon").value) }) });
      const answer = await r.json();
      if (!r.ok) { out.replaceChildren(li(esc(answer.error), "error")); return; }
      page.prediction = answer;
      const names = this.vars.map((v) => v.name);
      this.plot.overlay = { time: answer.trajectory.time,
        columns: names.map((n) => answer.trajectory[n] || null) };
      this.plot.invalidate();
      const items = answer.commands.map((c) => li(`t = ${c.time.toFixed(2)} s ${esc(c.event)}(${args(c.args)}): ` +
        (c.delivered === null ? "not delivered" : c.feasible === false ? "infeasible" : c.done !== null
          ? `done at ${c.done.toFixed(2)} s` : c.accepted ? "not done within the horizon" : "ignored"),
        c.feasible === false || c.done === null ? "error" : "ok"));
      items.push(li(answer.completion_time !== null ? `plan complete at t = ${answer.completion_time.toFixed(2)} s`
        : "plan not complete within the horizon"));
      if (answer.collisions.length) items.push(li(`${answer.collisions.length} collision(s)`, "error"));
      items.push(li(`fork from t = ${answer.start.toFixed(2)} s, computed in ${answer.wall_seconds.toFixed(2)} s`));
      out.replaceChildren(...items);
    });
  }

  colorOf(name) {
    return this.vars.find((v) => v.name === name)?.color;
  }

  samples(rows) {
    const width = this.vars.length;
    const flat = new Array(width * this.sides.length);
    for (const [t, row] of rows) {
      for (let s = 0; s < this.sides.length; s++) {
        const values = row[2 * s];
        for (let i = 0; i < width; i++) flat[s * width + i] = values[i];
      }
      this.plot.push(t, flat);
      this.last = row;
      this.time = t;
    }
    if (rows.length && page.firstSampleAt === undefined) page.firstSampleAt = performance.now();
    page.samples += rows.length;
    if (rows.length && this.last) {
      this.sides.forEach((side, s) => this.machines.forEach((m, k) => m.show(side, this.last[2 * s + 1][k])));
      if (this.robot) this.robot.pose(this.last);
    }
  }

  event(e) {
    page.events.push(e);
    if (e.kind === "alarm") {
      const raised = e.state === "raised";
      if (raised) { this.openAlarms[e.variable] = { start: e.time, end: null, label: e.variable, color: this.colorOf(e.variable) }; this.plot.bands.push(this.openAlarms[e.variable]); }
      else if (this.openAlarms[e.variable]) { this.openAlarms[e.variable].end = e.time; delete this.openAlarms[e.variable]; }
      this.plot.invalidate();
      const detail = e.deviation !== undefined ? ` |Δ| = ${Number(e.deviation).toFixed(3)} (threshold ${Number(e.threshold).toFixed(3)})` : "";
      prepend($("alarms"), li(`t = ${e.time.toFixed(2)} s <b>${esc(e.variable)}</b> ${esc(e.state)}${detail}`, `alarm ${e.state}`));
      $("alarm-caption").textContent = `${Object.keys(this.openAlarms).length} open`;
    } else if (e.kind === "op") {
      const key = `${e.time}|${e.name}|${JSON.stringify(e.args)}`;
      const seen = this.opsSeen.get(key);
      if (seen) { seen.querySelector(".side").textContent += ` ${e.side}`; return; }
      const item = li(`<span class="side">${esc(e.side)}</span> t = ${e.time.toFixed(2)} s ${esc(e.name)}(${args(e.args)})`, "op");
      this.opsSeen.set(key, item);
      if (this.opsSeen.size > 2 * MAX_LOG) this.opsSeen.delete(this.opsSeen.keys().next().value);
      prepend($("ops"), item);
    } else if (e.kind === "correction") { // the DT resynced to the PT, or given an estimate: a green marker
      const label = e.correction === "resync" ? "resync" : `${e.correction} ${Number(e.detail?.mass ?? e.size).toFixed(3)}`;
      this.plot.markers.push({ time: e.time, label, color: "#2b8a3e" });
      this.plot.invalidate();
      page.corrections = (page.corrections || 0) + 1;
      prepend($("alarms"), li(`t = ${e.time.toFixed(2)} s DT <b>${esc(e.correction)}</b> ${esc(e.reason)} (size ${Number(e.size).toFixed(4)})`, "correction"));
    } else if (e.kind === "command") {
      this.plot.markers.push({ time: e.time, label: e.name });
      this.plot.invalidate();
      prepend($("sent"), li(`t = ${e.time.toFixed(2)} s applied ${esc(e.name)} ${args(e.values)}`, "applied"));
    }
  }
}

function showStatus(status) {
  page.status = status;
  const state = $("state");
  state.dataset.state = status.state;
  state.textContent = status.state;
  if (status.time !== null && status.time !== undefined) {
    $("clock").textContent = `t = ${status.time.toFixed(2)}${status.end ? ` / ${status.end.toFixed(1)}` : ""} s`;
  }
  $("rate").textContent = status.rtf ? `real-time factor ${status.rtf.toFixed(2)}` : "";
  const samples = $("samples");
  samples.dataset.count = page.samples;
  samples.textContent = `${page.samples} samples` + (page.skipped ? ` (${page.skipped} skipped)` : "");
  if (status.message) state.title = status.message;
}

function connect(live) {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  ws.onmessage = (m) => {
    const msg = JSON.parse(m.data);
    page.batches++;
    page.skipped += msg.skipped || 0;
    if (live) {
      live.samples(msg.samples || []);
      for (const e of msg.events || []) live.event(e);
    }
    if (msg.status) showStatus(msg.status);
  };
  ws.onclose = (e) => {
    const state = $("state");
    if (!["done", "stopped", "failed"].includes(state.dataset.state)) {
      state.dataset.state = "disconnected";
      state.textContent = e.code === 1013 ? `refused: ${e.reason}` : "disconnected";
    } else state.textContent += " (server closed)";
    page.closed = true;
  };
  page.ws = ws;
}

function tabs(history) {
  for (const button of document.querySelectorAll("header nav button")) {
    button.addEventListener("click", () => {
      for (const b of document.querySelectorAll("header nav button")) b.classList.toggle("active", b === button);
      for (const tab of document.querySelectorAll("main.tab")) tab.hidden = tab.id !== button.dataset.tab;
      if (button.dataset.tab === "history") history.refresh();
    });
  }
}

async function main() {
  const info = await (await fetch("/api/model")).json();
  const model = (page.model = info.model);
  const history = new HistoryView();
  tabs(history);
  let live = null;
  if (model) {
    $("project").textContent = `${model.module} — ${model.project}` + (model.pt ? ` (PT: ${model.pt})` : "");
    live = page.live = new Live(model);
  } else {
    $("project").textContent = "history";
    document.querySelector('header nav button[data-tab="history"]').click();
    document.querySelector('header nav button[data-tab="live"]').hidden = true; // no live run to show
  }
  connect(live);
  page.readyAt = performance.now(); // ms since navigation started: the page is built
  document.body.dataset.ready = "true";
}

main().catch((err) => {
  document.body.dataset.ready = "error";
  $("state").textContent = `error: ${err}`;
  console.error(err);
});
