// Live plots: the Lyapunov function V and the distance errors r_ij - d_ij over time.

const FLV_PALETTE = [
  "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b",
  "#e377c2", "#7f7f7f", "#bcbd22", "#17becf",
];

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
    else if (t === last) return;
    this.t.push(t);
    for (let j = 0; j < this.k; j++) this.y[j].push(values[j] === null ? NaN : values[j]);
    if (this.t.length > this.cap) {
      this.t = this.t.filter((_, i) => i % 2 === 0);
      this.y = this.y.map((col) => col.filter((_, i) => i % 2 === 0));
    }
  }

  // a series given whole (a replay)
  set(t, columns) {
    this.t = t.slice();
    this.y = columns.map((c) => c.map((v) => (v === null ? NaN : v)));
    this.k = columns.length;
  }
}

function flvNiceTicks(lo, hi, count) {
  const span = hi - lo;
  if (!(span > 0)) return [lo];
  const raw = span / count;
  const mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const r = raw / mag;
  const step = (r <= 1 ? 1 : r <= 2 ? 2 : r <= 5 ? 5 : 10) * mag;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-12 * span; v += step) out.push(v);
  return out;
}

function flvFmt(v) {
  if (v === 0) return "0";
  const a = Math.abs(v);
  if (a >= 1e4 || a < 1e-3) return v.toExponential(1);
  return Number(v.toPrecision(3)).toString();
}

// Draw `series` in a canvas of w x h pixels; `cursor` marks a time (replay), `zero` a y = 0 line.
function flvDrawPlot(ctx, w, h, series, opts) {
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, w, h);
  const left = 46, right = 8, top = 18, bottom = 20;
  ctx.fillStyle = "#333";
  ctx.font = "12px sans-serif";
  ctx.textBaseline = "top";
  ctx.textAlign = "left";
  ctx.fillText(opts.title, left, 2);
  const t = series.t;
  if (t.length < 1) return;
  let y0 = Infinity, y1 = -Infinity;
  for (const col of series.y) {
    for (const v of col) {
      if (isFinite(v)) {
        if (v < y0) y0 = v;
        if (v > y1) y1 = v;
      }
    }
  }
  if (!isFinite(y0)) return;
  if (opts.zero) {
    y0 = Math.min(y0, 0);
    y1 = Math.max(y1, 0);
  }
  if (y1 - y0 < 1e-12) {
    y0 -= 0.5;
    y1 += 0.5;
  }
  const t0 = t[0], t1 = Math.max(t[t.length - 1], t0 + 1);
  const X = (v) => left + ((v - t0) / (t1 - t0)) * (w - left - right);
  const Y = (v) => top + (1 - (v - y0) / (y1 - y0)) * (h - top - bottom);
  ctx.strokeStyle = "#ccc";
  ctx.lineWidth = 1;
  ctx.strokeRect(left, top, w - left - right, h - top - bottom);
  ctx.fillStyle = "#555";
  ctx.textAlign = "right";
  ctx.textBaseline = "middle";
  for (const v of flvNiceTicks(y0, y1, 4)) {
    ctx.fillText(flvFmt(v), left - 4, Y(v));
    ctx.strokeStyle = "#eee";
    ctx.beginPath();
    ctx.moveTo(left, Y(v));
    ctx.lineTo(w - right, Y(v));
    ctx.stroke();
  }
  ctx.textAlign = "center";
  ctx.textBaseline = "top";
  for (const v of flvNiceTicks(t0, t1, 5)) ctx.fillText(flvFmt(v), X(v), h - bottom + 4);
  if (opts.zero && y0 < 0 && y1 > 0) {
    ctx.strokeStyle = "#999";
    ctx.beginPath();
    ctx.moveTo(left, Y(0));
    ctx.lineTo(w - right, Y(0));
    ctx.stroke();
  }
  ctx.lineWidth = 1.4;
  series.y.forEach((col, j) => {
    ctx.strokeStyle = FLV_PALETTE[j % FLV_PALETTE.length];
    ctx.beginPath();
    let pen = false;
    for (let i = 0; i < t.length; i++) {
      const v = col[i];
      if (!isFinite(v)) {
        pen = false;
        continue;
      }
      if (pen) ctx.lineTo(X(t[i]), Y(v));
      else ctx.moveTo(X(t[i]), Y(v));
      pen = true;
    }
    ctx.stroke();
  });
  if (opts.labels && opts.labels.length <= 10) {
    ctx.font = "11px sans-serif";
    ctx.textAlign = "right";
    ctx.textBaseline = "top";
    opts.labels.forEach((lab, j) => {
      ctx.fillStyle = FLV_PALETTE[j % FLV_PALETTE.length];
      ctx.fillText(lab, w - right - 2 - 44 * (opts.labels.length - 1 - j), 2);
    });
  }
  if (opts.cursor !== undefined && opts.cursor !== null) {
    ctx.strokeStyle = "#d0342c";
    ctx.beginPath();
    ctx.moveTo(X(opts.cursor), top);
    ctx.lineTo(X(opts.cursor), h - bottom);
    ctx.stroke();
  }
}
