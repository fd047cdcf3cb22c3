// The d-model's state machines as SVG, from the server's layout (describe.py): states, initial and
// junction nodes, nested states around their children, transitions as arrows. `show(side, index)`
// highlights the active leaf state of a side (the DT filled, the PT outlined).

const NS = "http://www.w3.org/2000/svg";

function el(name, attrs = {}, parent = null) {
  const e = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (parent) parent.append(e);
  return e;
}

// where the segment from the node's centre towards (tx, ty) leaves its outline
function border(n, tx, ty) {
  const dx = tx - n.x, dy = ty - n.y;
  if (n.kind === "initial" || n.kind === "junction" || n.kind === "final") {
    const r = n.w / 2, d = Math.hypot(dx, dy) || 1;
    return [n.x + (dx / d) * r, n.y + (dy / d) * r];
  }
  const hw = n.w / 2, hh = n.h / 2;
  const s = Math.min(dx ? hw / Math.abs(dx) : Infinity, dy ? hh / Math.abs(dy) : Infinity);
  return [n.x + dx * s, n.y + dy * s];
}

export class MachineView {
  constructor(container, machine, sides) {
    this.machine = machine;
    this.sides = sides;
    this.active = {};
    const side = 90; // room for transitions that go back up round the outside
    const svg = el("svg", { viewBox: `${-side} 0 ${machine.width + 2 * side} ${machine.height + 4}`,
      width: machine.width + 2 * side, height: machine.height + 4, role: "img", "aria-label": `state machine ${machine.machine}` });
    const defs = el("defs", {}, svg);
    const marker = el("marker", { id: `arrow-${machine.name}`, viewBox: "0 0 10 10", refX: 9, refY: 5,
      markerWidth: 7, markerHeight: 7, orient: "auto-start-reverse" }, defs);
    el("path", { d: "M 0 0 L 10 5 L 0 10 z", fill: "#9aa3b0" }, marker);
    this.nodes = {};
    const byId = Object.fromEntries(machine.nodes.map((n) => [n.id, n]));
    const nodeLayer = el("g", {}, svg);
    const edgeLayer = el("g", {}, svg);
    for (const n of machine.nodes) {
      const g = el("g", { class: `node ${n.kind}`, "data-id": n.id }, nodeLayer);
      el("title", {}, g).textContent = n.id;
      if (n.kind === "initial" || n.kind === "junction") {
        el("circle", { cx: n.x, cy: n.y, r: n.kind === "initial" ? 6 : 7 }, g);
      } else if (n.kind === "final") {
        el("circle", { cx: n.x, cy: n.y, r: 8 }, g);
        el("circle", { cx: n.x, cy: n.y, r: 4, fill: "#1d2330" }, g);
      } else {
        el("rect", { x: n.x - n.w / 2, y: n.y - n.h / 2, width: n.w, height: n.h, rx: 7 }, g);
        const label = el("text", { x: n.x, y: n.kind === "composite" ? n.y - n.h / 2 + 5 : n.y }, g);
        label.textContent = n.name;
      }
      this.nodes[n.id] = g;
    }
    // several transitions between one pair bend apart; self loops go round the right side
    const pairs = {};
    const centre = machine.width / 2;
    this.edges = machine.edges.map((e) => {
      const a = byId[e.from], b = byId[e.to];
      const key = [e.from, e.to].sort().join("|");
      const k = (pairs[key] = (pairs[key] ?? -1) + 1);
      const g = el("g", { class: "edge", "data-name": e.name }, edgeLayer);
      el("title", {}, g).textContent = `${e.name}: ${e.from} → ${e.to}`;
      let d, lx, ly;
      if (a === b) {
        const x = a.x + a.w / 2, y = a.y;
        d = `M ${x} ${y - 6} C ${x + 34} ${y - 26}, ${x + 34} ${y + 26}, ${x} ${y + 6}`;
        lx = x + 30; ly = y;
      } else if (b.y < a.y - 1) { // back up the rows: round the outside, on the source's side
        const dir = a.x >= centre ? 1 : -1;
        const rows = Math.max(1, Math.round((a.y - b.y) / 60));
        const off = 26 + 14 * rows + 10 * k;
        const [sx, sy] = border(a, a.x + dir * 1e3, a.y), [tx, ty] = border(b, b.x + dir * 1e3, b.y + 6 * dir);
        d = `M ${sx} ${sy} C ${sx + dir * off} ${sy}, ${tx + dir * off} ${ty}, ${tx} ${ty}`;
        lx = (sx + tx) / 2 + dir * off * 0.75; ly = (sy + ty) / 2;
      } else {
        const bend = k ? 22 * Math.ceil(k / 2) * (k % 2 ? 1 : -1) * (e.from < e.to ? 1 : -1) : 0;
        const mx = (a.x + b.x) / 2, my = (a.y + b.y) / 2;
        const len = Math.hypot(b.x - a.x, b.y - a.y) || 1;
        const cx = mx + (-(b.y - a.y) / len) * bend, cy = my + ((b.x - a.x) / len) * bend;
        const [sx, sy] = border(a, cx, cy), [tx, ty] = border(b, cx, cy);
        d = `M ${sx} ${sy} Q ${cx} ${cy} ${tx} ${ty}`;
        lx = (sx + 2 * cx + tx) / 4; ly = (sy + 2 * cy + ty) / 4;
      }
      const path = el("path", { d, "marker-end": `url(#arrow-${machine.name})` }, g);
      const label = el("text", { x: lx, y: ly }, g);
      label.textContent = e.name;
      return { ...e, g, path, label };
    });
    const caption = document.createElement("div");
    caption.className = "muted";
    caption.textContent = `${machine.machine} (${machine.name})`;
    container.append(caption, svg);
    this.bounds = { x0: -side, y0: 0, x1: machine.width + side, y1: machine.height + 4 };
    this.placeLabels();
  }

  // Transition names placed where no other label and no state is: along the arrow (its middle first),
  // then beside it; each name placed is an obstacle for the next. Sizes are measured once drawn (an
  // estimate while the drawing is hidden), in the drawing's own units.
  placeLabels() {
    const boxOf = (e, estimate) => {
      const b = e.getBBox();
      return b.width > 0 ? { x: b.x, y: b.y, w: b.width, h: b.height } : estimate;
    };
    const overlap = (a, b) => Math.max(0, Math.min(a.x + a.w, b.x + b.w) - Math.max(a.x, b.x) + 2) *
      Math.max(0, Math.min(a.y + a.h, b.y + b.h) - Math.max(a.y, b.y) + 1);
    const taken = [];
    for (const n of this.machine.nodes) {
      const g = this.nodes[n.id];
      const text = g.querySelector(":scope > text");
      if (text) taken.push(boxOf(text, { x: n.x - 3.5 * n.name.length, y: n.y - 7, w: 7 * n.name.length, h: 14 }));
      if (n.kind !== "composite") taken.push({ x: n.x - n.w / 2, y: n.y - n.h / 2, w: n.w, h: n.h });
    }
    const { x0, y0, x1, y1 } = this.bounds;
    for (const e of this.edges) {
      const size = boxOf(e.label, { w: 5.4 * e.name.length, h: 11 });
      const w = size.w, h = size.h;
      const length = e.path.getTotalLength ? e.path.getTotalLength() : 0;
      let best = null;
      search: for (const f of [0.5, 0.4, 0.6, 0.3, 0.7, 0.2, 0.8, 0.1, 0.9]) {
        const p = e.path.getPointAtLength(length * f), q = e.path.getPointAtLength(Math.min(length, length * f + 1));
        const d = Math.hypot(q.x - p.x, q.y - p.y) || 1;
        const nx = -(q.y - p.y) / d, ny = (q.x - p.x) / d;
        for (const off of [0, 8, -8, 14, -14, 22, -22, 32, -32, 44, -44]) {
          const cx = p.x + nx * off, cy = p.y + ny * off;
          const box = { x: cx - w / 2, y: cy - h / 2, w, h };
          let cost = taken.reduce((c, b) => c + overlap(box, b), 0) + Math.abs(off) * 0.01 + Math.abs(f - 0.5) * 0.01;
          if (box.x < x0 || box.x + w > x1 || box.y < y0 || box.y + h > y1) cost += 1e6;
          if (!best || cost < best.cost) best = { box, cost };
          if (cost < 1) break search;
        }
      }
      if (!best) continue;
      e.label.setAttribute("x", best.box.x + w / 2);
      e.label.setAttribute("y", best.box.y + h / 2);
      taken.push(best.box);
    }
  }

  // index: the value of the machine's state port (a leaf's index, -1 = none)
  show(side, index) {
    if (this.active[side] === index) return;
    const cls = side === this.sides[this.sides.length - 1] ? "active" : "active-pt";
    const before = this.active[side];
    if (before !== undefined) this._mark(before, cls, false);
    this.active[side] = index;
    this._mark(index, cls, true);
  }

  _mark(index, cls, on) {
    const leaf = this.machine.leaves[index];
    if (leaf === undefined) return;
    const node = this.nodes[leaf];
    if (node) node.classList.toggle(cls, on);
  }

  activeName(side) {
    return this.machine.leaves[this.active[side]] ?? null;
  }
}
