// Live plots: the Lyapunov function V (a log axis while V > 0) and the per-edge errors over
// time (the worst edges as lines, every edge as a band), with the switching events marked.

const FLV_PALETTE = [
  "#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b",
  "#e377c2", "#17becf", "#bcbd22", "#7f7f7f", "#d62728",
];
const FLV_CURSOR = "#111111"; // the replay cursor: black dashes, no edge's colour
const FLV_SWITCH = "rgba(224, 138, 0, 0.55)"; // a switching event (the lines' orange)
const FLV_BAND = "rgba(120, 130, 140, 0.22)";

// A bounded history of (t, y_1..y_k); halves its resolution when full.
class FlvSeries {
  constructor(k, cap) {
    this.k = k;
    this.cap = cap || 1500;
    this.clear();
  }

  clear() {
    this.t = [];
    this.y = Array.from({ length: this.k }, () => []);
  }

  push(t, values) {
    const last = this.t.length ? this.t[this.t.length - 1] : -Infinity;
    if (t < last) this.clear(); // a reset: start again
    else if (t === last) return false;
    this.t.push(t);
    for (let j = 0; j < this.k; j++) this.y[j].push(values[j] === null ? NaN : values[j]);
    if (this.t.length > this.cap) {
      this.t = this.t.filter((_, i) => i % 2 === 0);
      this.y = this.y.map((col) => col.filter((_, i) => i % 2 === 0));
    }
    return true;
  }

  // a series given whole (a replay)
  set(t, columns) {
    this.t = t.slice();
    this.y = columns.map((c) => c.map((v) => (v === null ? NaN : v)));
    this.k = columns.length;
  }
}

// The errors over time: the band [least, largest] of every edge, and a line for each edge
// whose value is known (every edge for few edges, else those that were among the worst).
class FlvEdgeSeries {
  constructor(cap) {
    this.cap = cap || 1500;
    this.clear();
  }

  clear() {
    this.t = [];
    this.lo = [];
    this.hi = [];
    this.cols = new Map(); // 1-based edge -> values aligned with t (NaN where unknown)
    this.last = new Map(); // 1-based edge -> |value| at the latest sample that has it
    this.latest = []; // the worst edges at the latest sample, worst first
  }

  // `values`: Map of 1-based edge -> error; `band`: [least, largest] or null
  push(t, band, values, worst) {
    const prev = this.t.length ? this.t[this.t.length - 1] : -Infinity;
    if (t < prev) this.clear();
    else if (t === prev) return;
    const i = this.t.length;
    this.t.push(t);
    this.lo.push(band ? band[0] : NaN);
    this.hi.push(band ? band[1] : NaN);
    for (const col of this.cols.values()) col.push(NaN);
    for (const [e, v] of values) {
      if (!this.cols.has(e)) this.cols.set(e, new Array(i + 1).fill(NaN));
      this.cols.get(e)[i] = v === null ? NaN : v;
    }
    this.latest = worst.slice();
    if (this.t.length > this.cap) {
      const keep = (_, k) => k % 2 === 0;
      this.t = this.t.filter(keep);
      this.lo = this.lo.filter(keep);
      this.hi = this.hi.filter(keep);
      for (const [e, col] of this.cols) {
        const kept = col.filter(keep);
        if (kept.every((v) => !isFinite(v))) this.cols.delete(e); // none left to draw
        else this.cols.set(e, kept);
      }
    }
  }

  // a replay: the band and the given edges' whole columns
  set(t, band, edges, columns) {
    this.clear();
    this.t = t.slice();
    const nan = (c) => c.map((v) => (v === null ? NaN : v));
    this.lo = band ? nan(band[0]) : t.map(() => NaN);
    this.hi = band ? nan(band[1]) : t.map(() => NaN);
    edges.forEach((e, j) => this.cols.set(e, nan(columns[j])));
    this.latest = edges.slice();
  }
}

function flvNiceTicks(lo, hi, count) {
  const span = hi - lo;
  if (!(span > 0)) return [lo];
  const step = flvNiceStep(span / count);
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-12 * span; v += step) out.push(v);
  return out;
}

// The 1, 2 or 5 times a power of ten nearest above `raw` (> 0).
function flvNiceStep(raw) {
  const mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const r = raw / mag;
  return (r <= 1 ? 1 : r <= 2 ? 2 : r <= 5 ? 5 : 10) * mag;
}

// Ticks of a log axis from 10^p0 to 10^p1: the decades (every few when there are many),
// or, within less than two decades, nice values between.
function flvLogTicks(p0, p1) {
  const first = Math.ceil(p0 - 1e-9), last = Math.floor(p1 + 1e-9);
  if (last - first >= 1) {
    const every = Math.max(1, Math.ceil((last - first + 1) / 5));
    const out = [];
    for (let p = first; p <= last; p += every) out.push(Math.pow(10, p));
    return out;
  }
  return flvNiceTicks(Math.pow(10, p0), Math.pow(10, p1), 3).filter((v) => v > 0);
}

function flvFmt(v) {
  if (v === 0) return "0";
  if (v === null || v === undefined || !isFinite(v)) return "—";
  const a = Math.abs(v);
  if (a >= 1e4 || a < 1e-3) return v.toExponential(1);
  return Number(v.toPrecision(3)).toString();
}

// The plot's frame: margins, title, axis titles; returns the pixel maps of (t0..t1, y0..y1).
function flvPlotFrame(ctx, w, h, opts, t0, t1, y0, y1, log) {
  const left = 52, right = 8, top = 18 + 14 * (opts.legendRows || 0), bottom = 30;
  const X = (v) => left + ((v - t0) / (t1 - t0)) * (w - left - right);
  const Y = log
    ? (v) => top + (1 - (Math.log10(v) - y0) / (y1 - y0)) * (h - top - bottom)
    : (v) => top + (1 - (v - y0) / (y1 - y0)) * (h - top - bottom);
  ctx.strokeStyle = "#ccc";
  ctx.lineWidth = 1;
  ctx.strokeRect(left, top, w - left - right, h - top - bottom);
  ctx.font = "11px sans-serif";
  ctx.fillStyle = "#555";
  ctx.textAlign = "right";
  ctx.textBaseline = "middle";
  const ticks = log ? flvLogTicks(y0, y1) : flvNiceTicks(y0, y1, 4);
  for (const v of ticks) {
    ctx.fillText(flvFmt(v), left - 4, Y(v));
    ctx.strokeStyle = "#eee";
    ctx.beginPath();
    ctx.moveTo(left, Y(v));
    ctx.lineTo(w - right, Y(v));
    ctx.stroke();
  }
  ctx.textAlign = "center";
  ctx.textBaseline = "top";
  for (const v of flvNiceTicks(t0, t1, 5)) ctx.fillText(flvFmt(v), X(v), h - bottom + 3);
  ctx.fillStyle = "#333";
  ctx.textAlign = "right";
  ctx.fillText("t (s)", w - right, h - 13);
  ctx.save();
  ctx.translate(11, top + (h - top - bottom) / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.fillText(opts.yTitle + (log ? " (log)" : ""), 0, 0);
  ctx.restore();
  return { X, Y, left, right, top, bottom };
}

function flvPlotTitle(ctx, opts) {
  ctx.fillStyle = "#333";
  ctx.font = "12px sans-serif";
  ctx.textBaseline = "top";
  ctx.textAlign = "left";
  ctx.fillText(opts.title, 52, 2);
}

// The switching events (vertical ticks) and the replay cursor, within the frame.
function flvPlotMarks(ctx, m, h, opts, t0, t1) {
  const inside = (v) => v >= t0 && v <= t1;
  const events = (opts.switches || []).filter(inside);
  if (events.length) {
    ctx.strokeStyle = FLV_SWITCH;
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (const v of events) {
      const x = Math.round(m.X(v)) + 0.5;
      ctx.moveTo(x, m.top);
      ctx.lineTo(x, h - m.bottom);
    }
    ctx.stroke();
  }
  if (opts.cursor !== undefined && opts.cursor !== null && inside(opts.cursor)) {
    ctx.strokeStyle = FLV_CURSOR;
    ctx.setLineDash([3, 3]);
    ctx.beginPath();
    ctx.moveTo(m.X(opts.cursor), m.top);
    ctx.lineTo(m.X(opts.cursor), h - m.bottom);
    ctx.stroke();
    ctx.setLineDash([]);
  }
  return events.length;
}

function flvZeroLine(ctx, m, w) {
  ctx.strokeStyle = "#999";
  ctx.beginPath();
  ctx.moveTo(m.left, m.Y(0));
  ctx.lineTo(w - m.right, m.Y(0));
  ctx.stroke();
}

function flvPolyline(ctx, t, col, X, Y, ok) {
  ctx.beginPath();
  let pen = false;
  for (let i = 0; i < t.length; i++) {
    const v = col[i];
    if (!ok(v)) {
      pen = false;
      continue;
    }
    if (pen) ctx.lineTo(X(t[i]), Y(v));
    else ctx.moveTo(X(t[i]), Y(v));
    pen = true;
  }
  ctx.stroke();
}

function flvTimeSpan(t) {
  const t0 = t[0];
  return [t0, Math.max(t[t.length - 1], t0 + 1)];
}

// V over time: a log axis while every V shown is > 0, else a linear one with a note (V_n of
// eq. 15 can be negative: its restriction term reaches -6 theta near a switching surface,
// where a dragged robot takes it easily). Returns what was drawn.
function flvDrawV(ctx, w, h, series, opts) {
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, w, h);
  flvPlotTitle(ctx, opts);
  const t = series.t, col = series.y[0] || [];
  const out = { log: false, negative: false, switches: 0 };
  if (t.length < 1) return out;
  let lo = Infinity, hi = -Infinity;
  for (const v of col) {
    if (isFinite(v)) {
      lo = Math.min(lo, v);
      hi = Math.max(hi, v);
    }
  }
  if (!isFinite(lo)) return out;
  const [t0, t1] = flvTimeSpan(t);
  const log = lo > 0;
  out.log = log;
  out.negative = lo < 0;
  let y0, y1;
  if (log) {
    y0 = Math.log10(lo);
    y1 = Math.log10(hi);
    if (y1 - y0 < 0.5) {
      const mid = 0.5 * (y0 + y1);
      y0 = mid - 0.25;
      y1 = mid + 0.25;
    }
  } else {
    y0 = Math.min(lo, 0);
    y1 = Math.max(hi, 0);
    if (y1 - y0 < 1e-12) {
      y0 -= 0.5;
      y1 += 0.5;
    }
  }
  const m = flvPlotFrame(ctx, w, h, opts, t0, t1, y0, y1, log);
  if (!log && y0 < 0 && y1 > 0) flvZeroLine(ctx, m, w);
  out.switches = flvPlotMarks(ctx, m, h, opts, t0, t1);
  ctx.strokeStyle = FLV_PALETTE[0];
  ctx.lineWidth = 1.4;
  flvPolyline(ctx, t, col, m.X, m.Y, log ? (v) => v > 0 : (v) => isFinite(v));
  if (out.negative || (!log && lo === 0)) {
    ctx.fillStyle = "#b3261e";
    ctx.font = "11px sans-serif";
    ctx.textAlign = "right";
    ctx.textBaseline = "top";
    ctx.fillText("V ≤ 0 (eq. 15 can be negative, e.g. on a drag): linear axis",
      w - m.right - 2, m.top + 2);
  }
  return out;
}

// The errors over time: the band of every edge and lines for the worst `opts.top` edges
// (those worst at the latest sample), with a legend row under the title.
function flvDrawErrors(ctx, w, h, series, opts) {
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, w, h);
  flvPlotTitle(ctx, opts);
  const t = series.t;
  const out = { lines: [], legend: [], band: false, switches: 0 };
  if (t.length < 1) return out;
  const shown = [];
  for (const e of series.latest) if (series.cols.has(e) && shown.length < opts.top) shown.push(e);
  let y0 = 0, y1 = 0;
  const grow = (v) => {
    if (isFinite(v)) {
      y0 = Math.min(y0, v);
      y1 = Math.max(y1, v);
    }
  };
  series.lo.forEach(grow);
  series.hi.forEach(grow);
  for (const e of shown) series.cols.get(e).forEach(grow);
  if (y1 - y0 < 1e-12) {
    y0 -= 0.5;
    y1 += 0.5;
  }
  const [t0, t1] = flvTimeSpan(t);
  const band = opts.edges > shown.length;
  // the legend: rows under the title (at most two), entries left to right while they fit
  ctx.font = "11px sans-serif";
  const entries = [];
  if (band) entries.push([`all ${opts.edges} edges (band); worst ${shown.length}:`, FLV_BAND]);
  shown.forEach((e, j) => entries.push([opts.labels[e - 1] || `edge ${e}`, FLV_PALETTE[j % FLV_PALETTE.length]]));
  const placed = [];
  let x = 52, row = 0;
  for (const [label, colour] of entries) {
    const width = 14 + ctx.measureText(label).width + 8;
    if (x + width > w - 8 && x > 52) {
      row++;
      x = 52;
    }
    if (row > 1) break; // no room left: never overprinted
    placed.push([label, colour, x, row]);
    x += width;
  }
  const m = flvPlotFrame(ctx, w, h, { ...opts, legendRows: row + 1 }, t0, t1, y0, y1, false);
  if (band) {
    ctx.fillStyle = FLV_BAND;
    ctx.beginPath();
    let open = false;
    const close = (k) => {
      for (let i = k; i >= 0 && isFinite(series.lo[i]); i--) ctx.lineTo(m.X(t[i]), m.Y(series.lo[i]));
      ctx.closePath();
    };
    for (let i = 0; i < t.length; i++) {
      const ok = isFinite(series.lo[i]) && isFinite(series.hi[i]);
      if (ok && !open) {
        ctx.moveTo(m.X(t[i]), m.Y(series.hi[i]));
        open = true;
      } else if (ok) ctx.lineTo(m.X(t[i]), m.Y(series.hi[i]));
      if (open && (!ok || i === t.length - 1)) {
        close(ok ? i : i - 1);
        open = false;
      }
    }
    ctx.fill();
    out.band = true;
  }
  flvZeroLine(ctx, m, w);
  out.switches = flvPlotMarks(ctx, m, h, opts, t0, t1);
  ctx.lineWidth = 1.4;
  out.lines = shown.map((e) => opts.labels[e - 1] || `edge ${e}`);
  out.edges = shown.slice(); // their 1-based edges, in the colours' order
  shown.forEach((e, j) => {
    ctx.strokeStyle = FLV_PALETTE[j % FLV_PALETTE.length];
    flvPolyline(ctx, t, series.cols.get(e), m.X, m.Y, (v) => isFinite(v));
  });
  ctx.textBaseline = "top";
  ctx.textAlign = "left";
  for (const [label, colour, lx, r] of placed) {
    ctx.fillStyle = colour;
    ctx.fillRect(lx, 21 + 14 * r, 10, colour === FLV_BAND ? 8 : 4);
    ctx.fillStyle = colour === FLV_BAND ? "#555" : colour;
    ctx.fillText(label, lx + 13, 17 + 14 * r);
    out.legend.push(label);
  }
  return out;
}
