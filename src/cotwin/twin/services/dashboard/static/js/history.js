// The history tab: the runs of the history store, and one run drawn like the live plot (every side's
// mapping variables, alarms as bands, commands as markers) with its commands, states and alarms.

import { TimePlot, PALETTE, legend } from "./plot.js";

function li(text, cls = "") {
  const e = document.createElement("li");
  e.textContent = text;
  if (cls) e.className = cls;
  return e;
}

export class HistoryView {
  constructor() {
    this.table = document.querySelector("#runs tbody");
    this.caption = document.getElementById("history-caption");
    this.plot = null;
  }

  async refresh() {
    const r = await fetch("/api/history");
    const data = await r.json();
    this.caption.textContent = data.error ? data.error : `${data.runs.length} run(s)`;
    this.table.replaceChildren();
    for (const run of data.runs.slice().reverse()) {
      const tr = document.createElement("tr");
      tr.dataset.run = run.id;
      const started = new Date(run.started * 1000).toLocaleString();
      for (const cell of [run.id, started, run.kind, run.status, `${run.step} s`, run.samples, run.alarms, run.project]) {
        const td = document.createElement("td");
        td.textContent = cell;
        tr.append(td);
      }
      if (run.message) tr.title = run.message; // e.g. why a run is shown as interrupted
      tr.addEventListener("click", () => this.open(run.id, tr));
      this.table.append(tr);
    }
  }

  async open(id, row) {
    for (const tr of this.table.children) tr.classList.toggle("selected", tr === row);
    const r = await fetch(`/api/history/${id}`);
    const data = await r.json();
    const panel = document.getElementById("run-panel");
    panel.hidden = false;
    if (!r.ok) { document.getElementById("run-title").textContent = data.error; return; }
    const run = data.run;
    document.getElementById("run-title").textContent =
      `Run ${run.id}: ${run.kind}, ${run.status}, step ${run.step} s, ${run.algorithm} — ${run.project}` +
      (run.message ? ` (${run.message})` : "");
    const sides = Object.keys(data.sides);
    const names = sides.length ? Object.keys(data.sides[sides[0]].values) : [];
    const vars = names.map((name, i) => ({ name, color: PALETTE[i % PALETTE.length], visible: /^q\d+$/.test(name) }));
    const series = [];
    sides.forEach((side, s) => vars.forEach((v) => series.push({ label: `${side} ${v.name}`, color: v.color,
      dash: sides.length > 1 && s === 0 ? [5, 3] : [], visible: v.visible })));
    const canvas = document.getElementById("run-plot");
    this.plot = new TimePlot(canvas, series, { fps: 10 });
    this.plot.setWindow(0);
    // merge the sides' samples on time (they share the clock)
    const base = data.sides[sides[0]] || { time: [] };
    base.time.forEach((t, k) => {
      const row = [];
      for (const side of sides) for (const v of vars) row.push(data.sides[side].values[v.name]?.[k] ?? null);
      this.plot.push(t, row);
    });
    legend(document.getElementById("run-legend"), vars, sides, (i, on) => {
      sides.forEach((_, s) => this.plot.setVisible(s * vars.length + i, on));
    });
    const open = {};
    for (const a of data.alarms) {
      if (a.state === "raised") { open[a.variable] = { start: a.time, end: null, label: a.variable, color: vars.find((v) => v.name === a.variable)?.color }; this.plot.bands.push(open[a.variable]); }
      else if (open[a.variable]) { open[a.variable].end = a.time; delete open[a.variable]; }
    }
    const fired = data.commands.filter((c) => c.value === "true");
    for (const c of fired) this.plot.markers.push({ time: c.time, label: c.port });
    for (const c of data.corrections || []) this.plot.markers.push({ time: c.time, label: c.kind, color: "#2b8a3e" }); // the DT corrected
    this.plot.invalidate();
    const list = (id, items) => document.getElementById(id).replaceChildren(...items);
    list("run-commands", data.commands.map((c) => li(`t = ${c.time.toFixed(2)} s  ${c.port} = ${c.value}`)));
    list("run-states", data.states.map((s) => li(`t = ${s.time.toFixed(2)} s  ${s.side}  ${s.machine}: ${s.name}`)));
    list("run-alarms", [...data.alarms.map((a) => li(`t = ${a.time.toFixed(2)} s  ${a.variable} ${a.state}` +
      (a.deviation !== undefined ? `  |Δ| = ${Number(a.deviation).toFixed(3)}` : ""), a.state)),
      ...(data.corrections || []).map((c) => li(`t = ${c.time.toFixed(2)} s  DT ${c.kind}: ${c.reason} (size ${Number(c.size).toFixed(4)})`, "correction"))]);
  }
}
