// A time plot on a canvas for fast streams: samples go into typed arrays (oldest half dropped past a
// cap); drawing is decimated to the canvas width (each pixel column draws the min and max of its
// samples, so peaks survive) and happens at most `fps` times a second, only when something changed.

const MAX_POINTS = 1 << 20;

export class TimePlot {
  constructor(canvas, series, { fps = 10, unit = "rad" } = {}) {
    this.canvas = canvas;
    this.series = series.map((s) => ({ visible: true, ...s }));
    this.unit = unit;
    this.n = 0;
    this.capacity = 4096;
    this.time = new Float64Array(this.capacity);
    this.columns = this.series.map(() => new Float32Array(this.capacity));
    this.bands = []; // {start, end|null, label}
    this.markers = []; // {time, label, color?}
    this.overlay = null; // a prediction: {time: [...], columns: [[...] | null per variable]}, drawn dotted
    this.window = 30;
    this.minInterval = 1000 / fps;
    this.lastDraw = 0;
    this.dirty = true;
    this.frames = 0;
    this._scheduled = false;
    new ResizeObserver(() => this.invalidate()).observe(canvas);
  }

  push(t, values) {
    if (this.n === this.capacity) this._grow();
    this.time[this.n] = t;
    for (let i = 0; i < this.columns.length; i++) {
      const v = values[i];
      this.columns[i][this.n] = v === null || v === undefined ? NaN : v;
    }
    this.n++;
    this.invalidate();
  }

  _grow() {
    if (this.capacity >= MAX_POINTS) { // keep the newest half
      const half = this.capacity >> 1;
      this.time.copyWithin(0, half);
      for (const c of this.columns) c.copyWithin(0, half);
      this.n -= half;
      return;
    }
    this.capacity *= 2;
    const time = new Float64Array(this.capacity);
    time.set(this.time);
    this.time = time;
    this.columns = this.columns.map((c) => { const d = new Float32Array(this.capacity); d.set(c); return d; });
  }

  clear() { this.n = 0; this.bands = []; this.markers = []; this.invalidate(); }
  setWindow(seconds) { this.window = seconds; this.invalidate(); }
  setVisible(index, visible) { this.series[index].visible = visible; this.invalidate(); }

  invalidate() {
    this.dirty = true;
    if (this._scheduled) return;
    this._scheduled = true;
    requestAnimationFrame((now) => this._frame(now));
  }

  _frame(now) {
    this._scheduled = false;
    if (!this.dirty) return;
    const wait = this.minInterval - (now - this.lastDraw);
    if (wait > 0) { // throttle: come back when allowed
      this._scheduled = true;
      setTimeout(() => requestAnimationFrame((t) => this._frame(t)), wait);
      return;
    }
    this.lastDraw = now;
    this.dirty = false;
    this.draw();
  }

  _lowerBound(t) {
    let lo = 0, hi = this.n;
    while (lo < hi) { const mid = (lo + hi) >> 1; if (this.time[mid] < t) lo = mid + 1; else hi = mid; }
    return lo;
  }

  draw() {
    const canvas = this.canvas;
    const dpr = window.devicePixelRatio || 1;
    const cw = Math.max(1, Math.round(canvas.clientWidth * dpr)), ch = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== cw || canvas.height !== ch) { canvas.width = cw; canvas.height = ch; }
    const g = canvas.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    const W = canvas.clientWidth, H = canvas.clientHeight;
    g.clearRect(0, 0, W, H);
    const left = 46, right = 8, top = 8, bottom = 20;
    const pw = W - left - right, ph = H - top - bottom;
    if (pw < 10 || ph < 10) return;
    this.frames++;
    const n = this.n;
    const tEnd = n ? this.time[n - 1] : 0;
    const t0 = this.window > 0 ? Math.max(n ? this.time[0] : 0, tEnd - this.window) : (n ? this.time[0] : 0);
    const ahead = this.overlay ? this.overlay.time[this.overlay.time.length - 1] : tEnd; // a prediction's end
    const t1 = Math.max(tEnd, ahead, t0 + (this.window > 0 ? this.window : 1e-9));
    const first = Math.max(0, this._lowerBound(t0) - 1);
    // y range over the visible samples
    let lo = Infinity, hi = -Infinity;
    this.series.forEach((s, i) => {
      if (!s.visible) return;
      const c = this.columns[i];
      for (let k = first; k < n; k++) { const v = c[k]; if (v < lo) lo = v; if (v > hi) hi = v; }
    });
    if (!isFinite(lo)) { lo = -1; hi = 1; }
    if (hi - lo < 1e-6) { lo -= 0.5; hi += 0.5; }
    const pad = (hi - lo) * 0.06; lo -= pad; hi += pad;
    const lanes = [];
    for (const b of this.bands) if (!lanes.includes(b.label)) lanes.push(b.label);
    const room = lanes.length ? lanes.length * 9 + 4 : 0; // alarm lanes above the curves
    const X = (t) => left + ((t - t0) / (t1 - t0)) * pw;
    const Y = (v) => top + room + (1 - (v - lo) / (hi - lo)) * (ph - room);
    // axes and grid
    g.strokeStyle = "#e3e6eb"; g.fillStyle = "#6b7280"; g.lineWidth = 1; g.font = "10px system-ui, sans-serif";
    for (const v of ticks(lo, hi, 5)) {
      const y = Math.round(Y(v)) + 0.5;
      g.beginPath(); g.moveTo(left, y); g.lineTo(left + pw, y); g.stroke();
      g.textAlign = "right"; g.textBaseline = "middle"; g.fillText(fmt(v), left - 4, y);
    }
    for (const t of ticks(t0, t1, 8)) {
      const x = Math.round(X(t)) + 0.5;
      g.beginPath(); g.moveTo(x, top); g.lineTo(x, top + ph); g.stroke();
      g.textAlign = "center"; g.textBaseline = "top"; g.fillText(fmt(t) + " s", x, top + ph + 4);
    }
    g.save();
    g.beginPath(); g.rect(left, top, pw, ph); g.clip();
    g.font = "10px system-ui, sans-serif";
    // alarms: a faint band from raised to cleared (or to now), and a lane per variable along the top
    const spans = this.bands.map((b) => [b.start, b.end === null ? tEnd : b.end]).sort((a, b) => a[0] - b[0]);
    const union = [];
    for (const [a, b] of spans) {
      if (union.length && a <= union[union.length - 1][1]) union[union.length - 1][1] = Math.max(union[union.length - 1][1], b);
      else union.push([a, b]);
    }
    g.fillStyle = "rgba(201, 42, 42, 0.08)"; // while any alarm is open
    for (const [a, b] of union) g.fillRect(X(a), top, Math.max(1, X(b) - X(a)), ph);
    for (const b of this.bands) {
      const x0 = X(b.start), x1 = X(b.end === null ? tEnd : b.end);
      if (x1 < left || x0 > left + pw) continue;
      const lane = lanes.indexOf(b.label);
      g.fillStyle = b.color || "#c92a2a"; g.fillRect(x0, top + 3 + lane * 9, Math.max(2, x1 - x0), 5);
      g.fillStyle = "#c92a2a"; g.fillRect(x0 - 0.5, top, 1, ph);
    }
    g.font = "9px system-ui, sans-serif"; g.textAlign = "right"; g.textBaseline = "middle";
    lanes.forEach((name, lane) => {
      const open = this.bands.some((b) => b.label === name && b.end === null);
      g.fillStyle = open ? "#c92a2a" : "#6b7280";
      g.fillText(`${name}${open ? " ⚠" : ""}`, left + pw - 2, top + 5.5 + lane * 9);
    });
    for (const m of this.markers) {
      const x = Math.round(X(m.time)) + 0.5;
      if (x < left || x > left + pw) continue;
      g.strokeStyle = m.color || "#1f6feb"; g.setLineDash([2, 3]);
      g.beginPath(); g.moveTo(x, top); g.lineTo(x, top + ph); g.stroke(); g.setLineDash([]);
      g.fillStyle = m.color || "#1f6feb"; g.textAlign = "left"; g.textBaseline = "bottom"; g.fillText(m.label, x + 3, top + ph - 2);
    }
    // series, decimated to min/max per pixel column
    const px = (t1 - t0) / pw;
    this.series.forEach((s, i) => {
      if (!s.visible) return;
      const c = this.columns[i];
      g.strokeStyle = s.color; g.lineWidth = s.width || 1.4; g.setLineDash(s.dash || []);
      g.beginPath();
      let pen = false, col = -1, cmin = 0, cmax = 0, cfirst = 0, clast = 0;
      const flush = () => {
        const x = left + col + 0.5;
        if (!pen) { g.moveTo(x, Y(cfirst)); pen = true; } else g.lineTo(x, Y(cfirst));
        if (cmin !== cmax) { g.lineTo(x, Y(cmin)); g.lineTo(x, Y(cmax)); }
        g.lineTo(x, Y(clast));
      };
      for (let k = first; k < n; k++) {
        const v = c[k];
        if (Number.isNaN(v)) { if (col >= 0) flush(); col = -1; pen = false; continue; }
        const kc = Math.floor((this.time[k] - t0) / px);
        if (kc !== col) {
          if (col >= 0) flush();
          col = kc; cmin = cmax = cfirst = clast = v;
        } else { if (v < cmin) cmin = v; if (v > cmax) cmax = v; clast = v; }
      }
      if (col >= 0) flush();
      g.stroke();
    });
    const o = this.overlay;
    if (o) { // a prediction, per variable whose curves are shown
      const perSide = o.columns.length;
      o.columns.forEach((col, i) => {
        if (!col || !this.series.some((s, k) => k % perSide === i && s.visible)) return;
        g.strokeStyle = this.series[i].color; g.lineWidth = 2.4; g.setLineDash([1.5, 3]);
        g.beginPath();
        col.forEach((v, k) => { if (k === 0) g.moveTo(X(o.time[k]), Y(v)); else g.lineTo(X(o.time[k]), Y(v)); });
        g.stroke();
      });
      const x = X(o.time[0]);
      g.setLineDash([]); g.fillStyle = "#495057"; g.textAlign = "left"; g.textBaseline = "top";
      g.fillText("what if ⋯", x + 3, top + ph - 28);
    }
    g.setLineDash([]);
    g.restore();
    g.strokeStyle = "#9aa3b0"; g.strokeRect(left + 0.5, top + 0.5, pw, ph);
    g.save(); g.translate(10, top + ph / 2); g.rotate(-Math.PI / 2);
    g.fillStyle = "#6b7280"; g.textAlign = "center"; g.textBaseline = "middle"; g.fillText(this.unit, 0, 0); g.restore();
  }
}

export function ticks(lo, hi, count) {
  const span = hi - lo;
  if (!(span > 0)) return [];
  const step0 = span / count, mag = Math.pow(10, Math.floor(Math.log10(step0)));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= step0) || 10 * mag;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-12; v += step) out.push(Math.abs(v) < step * 1e-9 ? 0 : v);
  return out;
}

export function fmt(v) {
  const a = Math.abs(v);
  if (a === 0) return "0";
  if (a >= 100) return v.toFixed(0);
  if (a >= 10) return v.toFixed(1);
  return String(+v.toFixed(a >= 1 ? 2 : 3));
}

export const PALETTE = ["#1f6feb", "#2b8a3e", "#9c36b5", "#e67700", "#0c8599", "#c2255c", "#5c940d", "#364fc7",
  "#862e9c", "#a61e4d", "#087f5b", "#d9480f"];

// legend with a checkbox per variable (both sides of a variable toggle together)
export function legend(container, variables, sides, onToggle) {
  container.replaceChildren();
  variables.forEach((v, i) => {
    const label = document.createElement("label");
    const box = document.createElement("input");
    box.type = "checkbox"; box.checked = v.visible;
    box.addEventListener("change", () => onToggle(i, box.checked));
    const swatch = document.createElement("i");
    swatch.style.background = v.color;
    label.append(box, swatch, document.createTextNode(v.name));
    container.append(label);
  });
  if (sides.length > 1) {
    const note = document.createElement("span");
    note.className = "muted";
    note.textContent = `${sides[0].toUpperCase()} dashed, ${sides[1].toUpperCase()} solid`;
    container.append(note);
  }
}
