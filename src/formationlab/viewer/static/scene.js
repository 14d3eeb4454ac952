// Drawing the formation on a 2-D canvas: obstacles (circles, polygons), robots (discs of
// their diameters, headings when the robot model has them), the graph's edges, the active
// restrictions and their switching lines s (eq. 26 of the paper: parallel to r_jk at
// distance theta / |r_jk|), the robots whose commands the safety filter changed (rings) and
// the marching reference velocity (an arrow from the centroid).
// Robot numbers in `info` and frames are 1-based; arrays here are 0-based.

const FLV_COLORS = {
  background: "#ffffff",
  grid: "#eef0f3",
  axis: "#d5d9df",
  tick: "#6b7480",
  axisTitle: "#333a42",
  bar: "#222222",
  edge: "#9aa3ad",
  robot: "#1f6fb5",
  pinned: "#d0342c",
  label: "#ffffff",
  line: "#e08a00",
  active: "rgba(224, 138, 0, 0.10)",
  heading: "#0b2e4f",
  obstacle: "rgba(90, 96, 105, 0.35)",
  obstacleEdge: "#5a6069",
  filtered: "#c2185b",
  reference: "#2e7d32",
};

// Static obstacles of `info.obstacles` (world coordinates); returns how many were drawn.
function flvDrawObstacles(ctx, view, obstacles) {
  if (!obstacles || !obstacles.length) return 0;
  const path = new Path2D();
  for (const o of obstacles) {
    if (o.kind === "circle") {
      const [x, y] = view.px(o.center[0], o.center[1]);
      const r = o.radius * view.scale;
      path.moveTo(x + r, y);
      path.arc(x, y, r, 0, 2 * Math.PI);
    } else {
      o.vertices.forEach(([vx, vy], k) => {
        const [x, y] = view.px(vx, vy);
        if (k === 0) path.moveTo(x, y);
        else path.lineTo(x, y);
      });
      path.closePath();
    }
  }
  ctx.fillStyle = FLV_COLORS.obstacle;
  ctx.fill(path);
  ctx.strokeStyle = FLV_COLORS.obstacleEdge;
  ctx.lineWidth = 1.2;
  ctx.stroke(path);
  return obstacles.length;
}

// The marching reference v_ref as an arrow from the robots' centroid, or (a velocity per
// leader: rows [vx, vy], `leaders` their 1-based numbers) one from each leader; true when drawn.
function flvDrawReference(ctx, view, pos, v, leaders) {
  const n = pos.length / 2;
  if (Array.isArray(v[0])) {
    let any = false;
    v.forEach((row, m) => {
      const i = leaders && leaders[m] ? leaders[m] - 1 : -1;
      if (i >= 0 && i < n) any = flvArrow(ctx, view, pos[2 * i], pos[2 * i + 1], row) || any;
    });
    return any;
  }
  if (!n) return false;
  let cx = 0, cy = 0;
  for (let i = 0; i < n; i++) {
    cx += pos[2 * i] / n;
    cy += pos[2 * i + 1] / n;
  }
  return flvArrow(ctx, view, cx, cy, v);
}

// An arrow for the velocity v from the point (cx, cy) (2 s of motion, clamped); true when drawn.
function flvArrow(ctx, view, cx, cy, v) {
  const speed = Math.hypot(v[0], v[1]);
  if (!(speed > 0)) return false;
  const [x0, y0] = view.px(cx, cy);
  const L = Math.min(80, Math.max(24, 2 * speed * view.scale)); // 2 s of motion, clamped
  const ux = v[0] / speed, uy = -v[1] / speed;
  const x1 = x0 + L * ux, y1 = y0 + L * uy;
  ctx.strokeStyle = FLV_COLORS.reference;
  ctx.fillStyle = FLV_COLORS.reference;
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x0, y0);
  ctx.lineTo(x1, y1);
  ctx.stroke();
  ctx.beginPath();
  ctx.moveTo(x1, y1);
  ctx.lineTo(x1 - 8 * ux + 4 * uy, y1 - 8 * uy - 4 * ux);
  ctx.lineTo(x1 - 8 * ux - 4 * uy, y1 - 8 * uy + 4 * ux);
  ctx.closePath();
  ctx.fill();
  return true;
}

// World (y up) <-> canvas pixels (y down).
class FlvView {
  constructor() {
    this.cx = 0;
    this.cy = 0;
    this.scale = 40; // pixels per unit
    this.w = 1;
    this.h = 1;
  }

  fit(bounds, w, h) {
    const [x0, x1, y0, y1] = bounds;
    this.w = w;
    this.h = h;
    this.cx = 0.5 * (x0 + x1);
    this.cy = 0.5 * (y0 + y1);
    const sx = (0.84 * w) / Math.max(x1 - x0, 1e-9);
    const sy = (0.84 * h) / Math.max(y1 - y0, 1e-9);
    this.scale = Math.min(sx, sy);
  }

  resize(w, h) {
    this.w = w;
    this.h = h;
  }

  px(x, y) {
    return [this.w / 2 + (x - this.cx) * this.scale, this.h / 2 - (y - this.cy) * this.scale];
  }

  world(px, py) {
    return [this.cx + (px - this.w / 2) / this.scale, this.cy - (py - this.h / 2) / this.scale];
  }

  // whether world point (x, y) is inside the view with a margin of `m` pixels
  contains(x, y, m) {
    const [px, py] = this.px(x, y);
    return px >= m && px <= this.w - m && py >= m && py <= this.h - m;
  }
}

// [xmin, xmax, ymin, ymax] of the positions, padded by the largest radius, at least minSpan wide.
function flvBounds(pos, diameters, minSpan) {
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  for (let i = 0; i < pos.length; i += 2) {
    const x = pos[i], y = pos[i + 1];
    if (x < x0) x0 = x;
    if (x > x1) x1 = x;
    if (y < y0) y0 = y;
    if (y > y1) y1 = y;
  }
  let r = 0;
  for (const d of diameters) r = Math.max(r, d / 2);
  if (!isFinite(x0)) return [-1, 1, -1, 1];
  const pad = Math.max(r, 0.05 * Math.max(x1 - x0, y1 - y0, 1));
  const bounds = [x0 - pad, x1 + pad, y0 - pad, y1 + pad];
  for (const k of [0, 2]) {
    const grow = (minSpan || 0) - (bounds[k + 1] - bounds[k]);
    if (grow > 0) {
      bounds[k] -= grow / 2;
      bounds[k + 1] += grow / 2;
    }
  }
  return bounds;
}

// The grid in metres, its tick labels along the left and bottom edges, the axis titles
// and a scale bar (bottom right); returns what was drawn: the ticks' values and pixels and
// the bar's length in metres and in pixels (for the tests).
function flvGrid(ctx, view) {
  const [wx0, wy1] = view.world(0, 0);
  const [wx1, wy0] = view.world(view.w, view.h);
  // about one line per 80 pixels
  const step = flvNiceStep(80 / view.scale);
  const axes = { step, x: [], y: [], bar: null };
  ctx.lineWidth = 1;
  ctx.strokeStyle = FLV_COLORS.grid;
  ctx.beginPath();
  for (let k = Math.ceil(wx0 / step); k * step <= wx1; k++) {
    const [px] = view.px(k * step, 0);
    ctx.moveTo(Math.round(px) + 0.5, 0);
    ctx.lineTo(Math.round(px) + 0.5, view.h);
    axes.x.push([k * step, px]);
  }
  for (let k = Math.ceil(wy0 / step); k * step <= wy1; k++) {
    const [, py] = view.px(0, k * step);
    ctx.moveTo(0, Math.round(py) + 0.5);
    ctx.lineTo(view.w, Math.round(py) + 0.5);
    axes.y.push([k * step, py]);
  }
  ctx.stroke();
  ctx.strokeStyle = FLV_COLORS.axis;
  ctx.beginPath();
  const [ox, oy] = view.px(0, 0);
  ctx.moveTo(ox, 0);
  ctx.lineTo(ox, view.h);
  ctx.moveTo(0, oy);
  ctx.lineTo(view.w, oy);
  ctx.stroke();
  // tick labels: numbers of metres at the edges (off the corners), the unit in the titles
  const label = (v) => flvFmt(Math.abs(v) < 1e-9 * step ? 0 : v);
  ctx.font = "11px sans-serif";
  ctx.fillStyle = FLV_COLORS.tick;
  ctx.textAlign = "center";
  ctx.textBaseline = "bottom";
  for (const [v, px] of axes.x) if (px > 30 && px < view.w - 60) ctx.fillText(label(v), px, view.h - 3);
  ctx.textAlign = "left";
  ctx.textBaseline = "middle";
  for (const [v, py] of axes.y) if (py > 20 && py < view.h - 20) ctx.fillText(label(v), 3, py);
  ctx.fillStyle = FLV_COLORS.axisTitle;
  ctx.textAlign = "right";
  ctx.textBaseline = "bottom";
  ctx.fillText("x (m)", view.w - 4, view.h - 3);
  ctx.textAlign = "left";
  ctx.textBaseline = "top";
  ctx.fillText("y (m)", 3, 3);
  // the scale bar: the nice length nearest below a fifth of the width
  let metres = flvNiceStep(view.w / 5 / view.scale);
  if (metres * view.scale > view.w / 4) metres /= 2;
  const px = metres * view.scale;
  const x1 = view.w - 12, x0 = x1 - px, y = view.h - 22;
  ctx.strokeStyle = FLV_COLORS.bar;
  ctx.lineWidth = 3;
  ctx.beginPath();
  ctx.moveTo(x0, y);
  ctx.lineTo(x1, y);
  ctx.moveTo(x0, y - 5);
  ctx.lineTo(x0, y + 5);
  ctx.moveTo(x1, y - 5);
  ctx.lineTo(x1, y + 5);
  ctx.stroke();
  ctx.fillStyle = FLV_COLORS.bar;
  ctx.textAlign = "center";
  ctx.textBaseline = "bottom";
  ctx.fillText(`${flvFmt(metres)} m`, (x0 + x1) / 2, y - 4);
  axes.bar = { metres, px };
  return axes;
}

// Line s of eq. (26) for the vertex `a` of a surface beta c_abc + theta = 0 (b, c the
// other two in cyclic order): the points a with beta (b - a) x (c - a) = -theta, a line
// parallel to r_bc at signed distance h = -theta / (beta |r_bc|) from the line through b, c.
function flvSwitchingLine(pos, a, b, c, beta, theta) {
  const bx = pos[2 * b], by = pos[2 * b + 1];
  const dx = pos[2 * c] - bx, dy = pos[2 * c + 1] - by;
  const L = Math.hypot(dx, dy);
  if (!(L > 0) || beta === 0) return null;
  const h = -theta / (beta * L); // eq. (26): distance theta / |r_bc| for |beta| = 1
  const nx = -dy / L, ny = dx / L, ux = dx / L, uy = dy / L;
  const ext = 0.6 * L;
  const px = bx + h * nx, py = by + h * ny;
  return [px - ext * ux, py - ext * uy, px + (L + ext) * ux, py + (L + ext) * uy];
}

// Draw one frame; returns the number of robots drawn. What else was drawn goes into
// `opts.drawn`: obstacles, headings, filtered (robots ringed), reference (arrow or not).
function flvDrawScene(ctx, view, info, frame, opts) {
  const pos = frame.pos;
  const n = pos.length / 2;
  const drawn = { obstacles: 0, headings: 0, filtered: 0, reference: false, lines: 0,
    active: 0, axes: null };
  opts.drawn = drawn;
  ctx.fillStyle = FLV_COLORS.background;
  ctx.fillRect(0, 0, view.w, view.h);
  if (opts.grid) drawn.axes = flvGrid(ctx, view);
  drawn.obstacles = flvDrawObstacles(ctx, view, info.obstacles);

  // graph
  const edges = info.edges;
  ctx.lineWidth = edges.length > 2000 ? 0.5 : 1.2;
  ctx.strokeStyle = FLV_COLORS.edge;
  ctx.beginPath();
  for (let e = 0; e < edges.length; e++) {
    const i = edges[e][0] - 1, j = edges[e][1] - 1;
    const [x0, y0] = view.px(pos[2 * i], pos[2 * i + 1]);
    const [x1, y1] = view.px(pos[2 * j], pos[2 * j + 1]);
    ctx.moveTo(x0, y0);
    ctx.lineTo(x1, y1);
  }
  ctx.stroke();

  // active restrictions and their switching lines
  const surf = info.surfaces;
  const active = frame.header.active;
  const theta = opts.theta;
  if (surf && active && active.length && opts.lines && theta !== null) {
    // one path for the triangles, one for the lines: a path per surface, or dashes on
    // many lines, cost more to rasterise than the rest of the frame
    const tris = new Path2D(), lines = new Path2D();
    for (const s1 of active) {
      const tri = surf.triangles[s1 - 1];
      const beta = surf.beta[s1 - 1];
      const [a, b, c] = [tri[0] - 1, tri[1] - 1, tri[2] - 1];
      const pa = view.px(pos[2 * a], pos[2 * a + 1]);
      const pb = view.px(pos[2 * b], pos[2 * b + 1]);
      const pc = view.px(pos[2 * c], pos[2 * c + 1]);
      tris.moveTo(pa[0], pa[1]);
      tris.lineTo(pb[0], pb[1]);
      tris.lineTo(pc[0], pc[1]);
      tris.closePath();
      drawn.active++;
      if (active.length > 60) continue; // beyond, the lines hide the formation
      drawn.lines++;
      for (const [v, w, u] of [[a, b, c], [b, c, a], [c, a, b]]) {
        const seg = flvSwitchingLine(pos, v, w, u, beta, theta);
        if (!seg) continue;
        const [x0, y0] = view.px(seg[0], seg[1]);
        const [x1, y1] = view.px(seg[2], seg[3]);
        lines.moveTo(x0, y0);
        lines.lineTo(x1, y1);
      }
    }
    ctx.fillStyle = FLV_COLORS.active;
    ctx.fill(tris);
    ctx.strokeStyle = FLV_COLORS.line;
    ctx.lineWidth = active.length > 12 ? 0.8 : 1.2;
    if (active.length <= 12) ctx.setLineDash([6, 4]);
    ctx.stroke(lines);
    ctx.setLineDash([]);
  }

  // robots
  const diam = info.diameters;
  const pinned = frame.header.pinned ? frame.header.pinned - 1 : -1;
  let minR = Infinity;
  for (const d of diam) minR = Math.min(minR, (d / 2) * view.scale);
  ctx.fillStyle = FLV_COLORS.robot;
  if (minR < 2.5 && n > 200) {
    // many small robots: squares are as legible and much cheaper than arcs
    const s = Math.max(2, 2 * minR);
    for (let i = 0; i < n; i++) {
      const [x, y] = view.px(pos[2 * i], pos[2 * i + 1]);
      ctx.fillRect(x - s / 2, y - s / 2, s, s);
    }
  } else {
    ctx.beginPath();
    for (let i = 0; i < n; i++) {
      const [x, y] = view.px(pos[2 * i], pos[2 * i + 1]);
      const r = Math.max(1.5, (diam[i] / 2) * view.scale);
      ctx.moveTo(x + r, y);
      ctx.arc(x, y, r, 0, 2 * Math.PI);
    }
    ctx.fill();
  }
  if (pinned >= 0) {
    const [x, y] = view.px(pos[2 * pinned], pos[2 * pinned + 1]);
    const r = Math.max(3, (diam[pinned] / 2) * view.scale);
    ctx.fillStyle = FLV_COLORS.pinned;
    ctx.beginPath();
    ctx.arc(x, y, r, 0, 2 * Math.PI);
    ctx.fill();
  }
  const filtered = frame.header.filtered;
  if (filtered && filtered.length) {
    ctx.strokeStyle = FLV_COLORS.filtered;
    ctx.lineWidth = 2;
    ctx.beginPath();
    for (const r1 of filtered) {
      const i = r1 - 1;
      const [x, y] = view.px(pos[2 * i], pos[2 * i + 1]);
      const r = Math.max(4, (diam[i] / 2) * view.scale) + 3;
      ctx.moveTo(x + r, y);
      ctx.arc(x, y, r, 0, 2 * Math.PI);
    }
    ctx.stroke();
    drawn.filtered = filtered.length;
  }
  if (frame.header.reference) {
    const lead = info.marching && info.marching.leader;
    const leaders = lead === null || lead === undefined ? [] : [].concat(lead);
    drawn.reference = flvDrawReference(ctx, view, pos, frame.header.reference, leaders);
  }
  if (frame.heading) {
    drawn.headings = n;
    ctx.strokeStyle = FLV_COLORS.heading;
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    for (let i = 0; i < n; i++) {
      const [x, y] = view.px(pos[2 * i], pos[2 * i + 1]);
      const r = Math.max(4, diam[i] * view.scale);
      ctx.moveTo(x, y);
      ctx.lineTo(x + r * Math.cos(frame.heading[i]), y - r * Math.sin(frame.heading[i]));
    }
    ctx.stroke();
  }
  if (opts.labels && n <= 40) {
    ctx.fillStyle = "#111";
    ctx.font = "12px sans-serif";
    ctx.textAlign = "left";
    ctx.textBaseline = "bottom";
    for (let i = 0; i < n; i++) {
      const [x, y] = view.px(pos[2 * i], pos[2 * i + 1]);
      const r = Math.max(1.5, (diam[i] / 2) * view.scale);
      ctx.fillText(String(i + 1), x + r + 2, y - r);
    }
  }
  return n;
}

// The robot (0-based) under pixel (px, py), or -1: the nearest within its radius plus 6 px.
function flvPick(view, info, pos, px, py) {
  let best = -1, bestD = Infinity;
  for (let i = 0; i < pos.length / 2; i++) {
    const [x, y] = view.px(pos[2 * i], pos[2 * i + 1]);
    const d = Math.hypot(x - px, y - py);
    const r = Math.max(1.5, (info.diameters[i] / 2) * view.scale) + 6;
    if (d <= r && d < bestD) {
      best = i;
      bestD = d;
    }
  }
  return best;
}
