// The viewer's page: controls, the render loop, and the transport.
// `render({ model, el })` is the anywidget entry point; the stand-alone page passes a
// `socketModel(url)` that speaks the same protocol over a websocket. The page asks for
// a frame once per display frame (a "tick"), so states arrive at the display's rate.

// Decode one binary websocket message: uint32 header length, JSON header, padding, buffers.
function flvDecode(buf) {
  const dv = new DataView(buf);
  const h = dv.getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, h)));
  let off = 4 + h + ((4 - ((4 + h) % 4)) % 4);
  const buffers = [];
  for (const nb of header.buffers || []) {
    buffers.push(new DataView(buf, off, nb));
    off += nb;
  }
  return [header, buffers];
}

function flvFloats(view) {
  if (view instanceof ArrayBuffer) return new Float32Array(view);
  if (view.byteOffset % 4 === 0) {
    return new Float32Array(view.buffer, view.byteOffset, view.byteLength / 4);
  }
  return new Float32Array(view.buffer.slice(view.byteOffset, view.byteOffset + view.byteLength));
}

// A model with anywidget's interface (send, on/off "msg:custom") over a websocket.
function socketModel(url) {
  const handlers = new Set();
  const emit = (msg, buffers) => handlers.forEach((h) => h(msg, buffers || []));
  const ws = new WebSocket(url);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => emit({ type: "_open" });
  ws.onclose = (e) => emit({ type: "_closed", code: e.code, reason: e.reason });
  ws.onmessage = (e) => {
    if (typeof e.data === "string") emit(JSON.parse(e.data));
    else {
      const [header, buffers] = flvDecode(e.data);
      emit(header, buffers);
    }
  };
  return {
    socket: ws,
    send(msg) {
      if (ws.readyState === 1) ws.send(JSON.stringify(msg));
    },
    on(event, cb) {
      if (event === "msg:custom") handlers.add(cb);
    },
    off(event, cb) {
      if (event === "msg:custom") handlers.delete(cb);
    },
    get() {
      return undefined;
    },
    // where the vendored three.js modules are served (a formation in space)
    threeUrl(name) {
      return new URL(`three/${name}`, window.location.href).href;
    },
  };
}

function flvEl(tag, attrs, children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "text") e.textContent = v;
    else e.setAttribute(k, v);
  }
  for (const c of children || []) e.appendChild(typeof c === "string" ? document.createTextNode(c) : c);
  return e;
}

function flvDownload(name, blob) {
  const a = flvEl("a", { href: URL.createObjectURL(blob), download: name });
  document.body.appendChild(a);
  a.click();
  setTimeout(() => {
    URL.revokeObjectURL(a.href);
    a.remove();
  }, 2000);
}

function flvLayout(el) {
  const B = (role, text, title) => flvEl("button", { "data-role": role, title: title || "", text });
  const root = flvEl("div", { class: "flv-root", "data-robots": "0", "data-fps": "0",
    "data-frames": "0", "data-errors": "0", "data-state": "connecting" });
  const scene = flvEl("canvas", { class: "flv-scene", "data-role": "scene", tabindex: "0" });
  // a formation in space: a WebGL canvas of its own (the plane's keeps its 2-D context)
  const scene3d = flvEl("canvas", { class: "flv-scene flv-scene3d", "data-role": "scene3d",
    tabindex: "0" });
  scene3d.style.display = "none";
  const status = flvEl("div", { class: "flv-status", "data-role": "status" });
  const legend = flvEl("div", { class: "flv-legend", "data-role": "legend" });
  const speed = flvEl("input", { type: "range", min: "-2", max: "2", step: "0.1", value: "0",
    "data-role": "speed" });
  const speedLabel = flvEl("span", { class: "flv-speed", text: "x1" });
  const stepCount = flvEl("input", { type: "number", min: "1", max: "10000", value: "10",
    "data-role": "step-count", class: "flv-num" });
  const scale = flvEl("input", { type: "number", min: "0.01", max: "100", step: "0.05",
    value: "0.3", "data-role": "perturb-scale", class: "flv-num" });
  const law = flvEl("select", { "data-role": "law" });
  const params = flvEl("div", { class: "flv-params", "data-role": "params" });
  const integrator = flvEl("select", { "data-role": "integrator" });
  const dt = flvEl("input", { type: "number", min: "1e-6", max: "1", step: "0.0005",
    "data-role": "dt", class: "flv-num" });
  const model = flvEl("select", { "data-role": "model" });
  const slider = flvEl("input", { type: "range", min: "0", max: "0", step: "1", value: "0",
    "data-role": "slider" });
  const lines = flvEl("input", { type: "checkbox", "data-role": "lines", checked: "" });
  const labels = flvEl("input", { type: "checkbox", "data-role": "labels", checked: "" });
  const plotV = flvEl("canvas", { class: "flv-plot", "data-role": "plot-v" });
  const plotE = flvEl("canvas", { class: "flv-plot", "data-role": "plot-e" });
  const logBox = flvEl("div", { class: "flv-log", "data-role": "log" });
  const Row = (label, ...kids) => flvEl("div", { class: "flv-row" },
    [flvEl("span", { class: "flv-label", text: label }), ...kids]);
  const live = flvEl("div", { class: "flv-live" }, [
    Row("law", law), params,
    Row("integrator", integrator, flvEl("span", { text: " dt" }), dt),
    Row("model", model),
    Row("perturb", scale, B("perturb", "Perturb", "add a random displacement to every robot")),
  ]);
  const replay = flvEl("div", { class: "flv-replay" }, [Row("time", slider)]);
  const side = flvEl("div", { class: "flv-side" }, [
    flvEl("div", { class: "flv-title", "data-role": "title" }),
    flvEl("div", { class: "flv-row" }, [B("pause", "Pause"), B("step", "Step", "take N steps"),
      stepCount, B("reset", "Reset", "back to the initial state")]),
    Row("speed", speed, speedLabel),
    live, replay,
    flvEl("div", { class: "flv-row" }, [B("export", "Export TOML", "download the state as a scenario"),
      B("png", "PNG", "download a snapshot")]),
    flvEl("div", { class: "flv-row" }, [
      B("fit", "Fit", "fit the view to the formation now (key f; it follows the formation)"),
      B("fit-start", "Fit start", "fit the view to the start (key s; it stays until f)")]),
    flvEl("div", { class: "flv-row" }, [flvEl("label", {}, [lines, " switching lines"]),
      flvEl("label", {}, [labels, " numbers"])]),
    plotV, plotE, logBox,
  ]);
  root.append(flvEl("div", { class: "flv-main" }, [scene, scene3d, legend, status]), side);
  el.appendChild(root);
  return { root, scene, scene3d, status, legend, speed, speedLabel, stepCount, scale, law, params, integrator,
    dt, model, slider, lines, labels, plotV, plotE, logBox, live, replay,
    title: side.querySelector("[data-role=title]"),
    button: (role) => root.querySelector(`button[data-role=${role}]`) };
}

// The legend of what the drawing shows now: an entry per layer drawn.
function flvLegend(box, info, frame, drawn) {
  const hd = frame.header;
  const layers = [["robots", "robots (diameters to scale)"]];
  if (info.edges.length) layers.push(["edges", "graph edges"]);
  if (drawn.coloured) layers.push(["plotted", "edges of the error plot, in its colours"]);
  if (drawn.trails) layers.push(["trails", "trails"]);
  if (drawn.active) layers.push(["active", "active restriction (σ ≥ 0)"]);
  if (drawn.lines) layers.push(["lines", "switching lines s (eq. 26)"]);
  if (drawn.obstacles) layers.push(["obstacles", "obstacles"]);
  if (info.safety) layers.push(["filtered", `filter ${info.safety} acting on the robot`]);
  if (drawn.reference) layers.push(["reference", "marching reference v_ref"]);
  if (drawn.headings) layers.push(["headings", "headings"]);
  if (hd.pinned) layers.push(["pinned", "dragged robot"]);
  const key = layers.map((l) => l[0]).join(",");
  if (box.dataset.key === key) return; // unchanged: nothing to rebuild
  box.dataset.key = key;
  box.replaceChildren(...layers.map(([layer, text]) => flvEl("span", { class: "flv-key",
    "data-layer": layer }, [flvEl("span", { class: `flv-sw flv-sw-${layer}` }), text])));
}

function render({ model, el }) {
  const ui = flvLayout(el);
  const view = new FlvView();
  const ctx = ui.scene.getContext("2d");
  let info = null, latest = null, drawn = null, pending = false, pendingSince = 0;
  let alive = true, needFit = true, drag = null, dragSend = null;
  // the view follows the formation's extent ("now"), or stays on the start ("start")
  let fitMode = "now", startBounds = null, lastActive = null, switches = [];
  let plotInfo = { v: null, e: null };
  // a formation in space (info.dim === 3): three.js's scene, once loaded, and the start
  let space = false, scene3d = null, startPos = null;
  let drawMs = 0, frames = 0, fpsCount = 0, fpsStart = performance.now();
  let seriesV = new FlvSeries(1), seriesE = new FlvEdgeSeries();
  const dpr = () => window.devicePixelRatio || 1;

  function log(text, kind) {
    const line = flvEl("div", { class: `flv-msg flv-${kind}`, text });
    ui.logBox.prepend(line);
    while (ui.logBox.childNodes.length > 6) ui.logBox.lastChild.remove();
  }

  function sizeCanvas(c) {
    const w = Math.max(50, c.clientWidth), h = Math.max(50, c.clientHeight);
    if (c.width !== Math.round(w * dpr()) || c.height !== Math.round(h * dpr())) {
      c.width = Math.round(w * dpr());
      c.height = Math.round(h * dpr());
    }
    return [w, h];
  }

  function fillLaw() {
    ui.params.replaceChildren();
    const params = info.law ? info.law.params : {};
    for (const [k, v] of Object.entries(params)) {
      const input = flvEl("input", { type: "number", step: "0.1", min: "0", value: String(v),
        "data-role": `param-${k}`, class: "flv-num" });
      input.addEventListener("change", () => {
        const x = Number(input.value);
        if (isFinite(x)) model.send({ type: "set_params", params: { [k]: x } });
      });
      ui.params.append(flvEl("label", { class: "flv-param" }, [`${k} `, input]));
    }
    if (info.law) ui.law.value = info.law.name;
    if (info.integrator) {
      ui.integrator.value = info.integrator.name;
      ui.dt.value = String(info.integrator.dt);
    }
  }

  function onInfo(msg) {
    info = msg;
    space = info.dim === 3;
    ui.root.dataset.dim = String(info.dim || 2);
    ui.scene.style.display = space ? "none" : "";
    ui.scene3d.style.display = space ? "" : "none";
    ui.lines.parentElement.lastChild.textContent = space ? " active tetrahedra" : " switching lines";
    let longest = 0, widest = 0;
    for (const d of info.distances) longest = Math.max(longest, d);
    for (const d of info.diameters) widest = Math.max(widest, d);
    // the least span the view fits: a little more than the formation's longest edge
    info.minSpan = Math.max(1.2 * longest, 4 * widest);
    ui.title.textContent = `${info.name} — ${info.n} robots (${info.mode})`;
    ui.live.style.display = info.mode === "live" ? "" : "none";
    ui.replay.style.display = info.mode === "replay" ? "" : "none";
    ui.law.replaceChildren(...Object.keys(info.laws || {}).map((k) => flvEl("option", { value: k, text: k })));
    ui.integrator.replaceChildren(...(info.integrators || []).map((k) => flvEl("option", { value: k, text: k })));
    ui.model.replaceChildren(...(info.models || []).map((k) => flvEl("option", { value: k, text: k })));
    ui.model.disabled = (info.models || []).length < 2;
    fillLaw();
    seriesV = new FlvSeries(1);
    seriesE = new FlvEdgeSeries();
    switches = [];
    lastActive = null;
    startBounds = null;
    startPos = null;
    if (info.mode === "replay") {
      ui.slider.max = String(info.frames - 1);
      const s = info.series;
      seriesV.set(s.t, [s.V]);
      if (s.errors) seriesE.set(s.t, s.band, s.errors.map((_, j) => j + 1), s.errors);
      else if (s.worst) seriesE.set(s.t, s.band, s.worst.edges, s.worst.values);
      if (s.worst) seriesE.latest = s.worst.edges.slice();
      switches = (s.switches || []).slice();
    }
    for (const n of info.notices || []) log(n, "notice");
    needFit = true;
    if (!space) {
      ui.root.dataset.state = "ready";
      return;
    }
    ui.root.dataset.state = "loading";
    flvLoadThree(model).then((lib) => {
      if (!scene3d) scene3d = new FlvScene3D(lib, ui.scene3d);
      scene3d.setInfo(info);
      needFit = true;
      drawn = null;
      ui.root.dataset.state = "ready";
    }).catch((e) => {
      ui.root.dataset.state = "failed";
      log(`the view in space cannot start (three.js or WebGL): ${e.message || e}`, "error");
    });
  }

  function onFrame(msg, buffers) {
    const pos = flvFloats(buffers[0]);
    const heading = msg.heading && buffers[1] ? flvFloats(buffers[1]) : null;
    latest = { header: msg, pos, heading };
    pending = false;
    if (info && info.mode === "live") {
      const values = new Map();
      if (msg.errors) msg.errors.forEach((v, j) => values.set(j + 1, v));
      else if (msg.worst) msg.worst.edges.forEach((e, j) => values.set(e, msg.worst.values[j]));
      const worst = msg.worst ? msg.worst.edges : [];
      if (seriesV.t.length && msg.t < seriesV.t[seriesV.t.length - 1]) {
        switches = []; // a reset
        lastActive = null;
      }
      seriesE.push(msg.t, msg.band, values, worst);
      seriesV.push(msg.t, [msg.V]);
      // a switching event: the set of active restrictions changed since the last frame
      const active = msg.active ? msg.active.join(",") : null;
      if (active !== null && lastActive !== null && active !== lastActive) {
        switches.push(msg.t);
        if (switches.length > 500) switches = switches.slice(-500);
      }
      lastActive = active;
    }
    if (space) {
      if (!startPos || (msg.t === 0 && !msg.index)) startPos = pos.slice();
    } else if (!startBounds || (msg.t === 0 && !msg.index)) {
      startBounds = info ? flvBounds(pos, info.diameters, info.minSpan) : null;
    }
    ui.button("pause").textContent = msg.paused ? "Run" : "Pause";
    if (info && info.mode === "replay" && document.activeElement !== ui.slider) {
      ui.slider.value = String(msg.index);
    }
    if (msg.status !== "running" && msg.status !== "replay" && msg.message) {
      if (ui.root.dataset.lastStatus !== msg.message) log(msg.message, "error");
    }
    ui.root.dataset.lastStatus = msg.message || "";
  }

  function onMessage(msg, buffers) {
    switch (msg.type) {
      case "_open":
        model.send({ type: "hello" });
        break;
      case "_closed":
        ui.root.dataset.state = "closed";
        log(`connection closed (${msg.code}${msg.reason ? ": " + msg.reason : ""})`, "error");
        break;
      case "info":
        onInfo(msg);
        break;
      case "settings":
        Object.assign(info, msg);
        fillLaw();
        for (const n of msg.notices || []) log(n, "notice");
        break;
      case "frame":
        onFrame(msg, buffers);
        break;
      case "error":
        ui.root.dataset.errors = String(Number(ui.root.dataset.errors) + 1);
        ui.root.dataset.lastError = msg.message;
        if (msg.code === "refused" && info) fillLaw(); // show the values in force again
        log(msg.message, "error");
        break;
      case "export":
        flvDownload(msg.filename, new Blob([msg.text], { type: "application/toml" }));
        log(`exported ${msg.filename}`, "notice");
        break;
      default:
        break;
    }
  }
  model.on("msg:custom", onMessage);

  function draw2d() {
    const [w, h] = sizeCanvas(ui.scene);
    ctx.setTransform(dpr(), 0, 0, dpr(), 0, 0);
    view.resize(w, h);
    const pos = latest.pos;
    const minSpan = info.minSpan;
    if (needFit) {
      view.fit(fitMode === "start" && startBounds ? startBounds : flvBounds(pos, info.diameters, minSpan), w, h);
      needFit = false;
    } else if (!drag && pos.length <= 20000) {
      // follow the formation: refit when a robot leaves the view, or (fitting the formation
      // now) when it fills less than 40 % of the view both ways
      const b = flvBounds(pos, info.diameters, minSpan);
      const small = fitMode === "now" && (b[1] - b[0]) * view.scale < 0.4 * w &&
        (b[3] - b[2]) * view.scale < 0.4 * h;
      let out = false;
      const every = Math.max(2, 2 * Math.floor(pos.length / 2000)); // a sample of many robots
      for (let i = 0; i < pos.length && !out; i += every) out = !view.contains(pos[i], pos[i + 1], 4);
      if (out || small) view.fit(b, w, h);
    }
    const theta = info.law && info.law.params && "theta" in info.law.params ? info.law.params.theta : null;
    const opts = { grid: true, lines: ui.lines.checked, labels: ui.labels.checked, theta };
    return [flvDrawScene(ctx, view, info, latest, opts), opts];
  }

  function draw3d() {
    const c = ui.scene3d;
    scene3d.resize(Math.max(50, c.clientWidth), Math.max(50, c.clientHeight), dpr());
    const opts = { lines: ui.lines.checked, labels: ui.labels.checked, trails: true,
      fit: needFit, fitPos: fitMode === "start" ? startPos : null,
      follow: drag === null && fitMode === "now", plotted: plotInfo.e && plotInfo.e.edges };
    needFit = false;
    return [scene3d.draw(info, latest, opts), opts];
  }

  function draw() {
    const [count, opts] = space ? draw3d() : draw2d();
    ui.root.flvAxes = opts.drawn.axes;
    flvLegend(ui.legend, info, latest, opts.drawn);
    const hd = latest.header;
    const V = hd.V === null ? "—" : flvFmt(hd.V);
    const parts = [];
    if (info.safety) {
      parts.push(`filter ${info.safety}: ` + (hd.filtered && hd.filtered.length
        ? `changed robot${hd.filtered.length > 1 ? "s" : ""} ${hd.filtered.join(", ")}` : "idle"));
    }
    if (hd.reference) {
      const rows = Array.isArray(hd.reference[0]) ? hd.reference : [hd.reference];
      const txt = rows.map((v) => `(${v.map(flvFmt).join(", ")})`).join(" ");
      parts.push(rows.length > 1 ? `leaders' v_ref = ${txt}` : `v_ref = ${txt}`);
    }
    // a formation judged by its bearings (the bearing law) plots its bearing errors
    const bearing = (hd.errors_kind || info.errors_kind) === "bearing";
    const errWord = bearing ? "max|g-g*|" : "max|r-d|";
    const unit = bearing ? "" : " m";
    // the speed asked for and, while running, the one reached (simulated s per wall s)
    const asked = `x${flvFmt(hd.speed)}`;
    const reached = hd.reached === null || hd.reached === undefined || hd.paused
      ? "" : ` (reached x${flvFmt(hd.reached)}${hd.compiled ? ", compiled loop" : ""})`;
    ui.speedLabel.textContent = asked + reached;
    ui.root.dataset.reached = reached ? String(hd.reached) : "";
    ui.status.textContent = `t = ${hd.t.toFixed(3)} s   V = ${V}   ${errWord} = ${flvFmt(hd.err_max)}${unit}` +
      (parts.length ? "   " + parts.join("   ") : "") +
      `   ${ui.root.dataset.fps} fps` + (hd.status !== "running" && hd.status !== "replay" ? `   [${hd.status}]` : "");
    ui.root.dataset.robots = String(count);
    ui.root.dataset.obstacles = String(opts.drawn.obstacles);
    ui.root.dataset.headings = String(opts.drawn.headings);
    ui.root.dataset.filtered = (hd.filtered || []).join(",");
    ui.root.dataset.reference = opts.drawn.reference ? hd.reference.join(",") : "";
    ui.root.dataset.t = String(hd.t);
    const cursor = info.mode === "replay" ? hd.t : null;
    const plot = (c) => {
      const [pw, ph] = sizeCanvas(c);
      const pc = c.getContext("2d");
      pc.setTransform(dpr(), 0, 0, dpr(), 0, 0);
      return [pc, pw, ph];
    };
    plotInfo.v = flvDrawV(...plot(ui.plotV), seriesV, { title: "Lyapunov function V (eq. 15)",
      yTitle: "V", switches, cursor });
    plotInfo.e = flvDrawErrors(...plot(ui.plotE), seriesE, {
      title: bearing ? "bearing errors ‖g_ij − g*_ij‖" : "distance errors r_ij − d_ij (m)",
      yTitle: bearing ? "‖g − g*‖" : "r − d (m)", switches, cursor, top: 5,
      edges: info.edges.length, labels: info.edges.map((e) => `${e[0]}-${e[1]}`) });
    ui.root.dataset.switches = String(switches.length);
  }

  function loop() {
    if (!alive) return;
    const now = performance.now();
    if (latest && info && latest !== drawn && (!space || scene3d)) {
      const d0 = performance.now();
      draw();
      drawMs = 0.9 * drawMs + 0.1 * (performance.now() - d0);
      ui.root.dataset.drawMs = drawMs.toFixed(2);
      drawn = latest;
      frames++;
      fpsCount++;
      ui.root.dataset.frames = String(frames);
    }
    if (now - fpsStart >= 1000) {
      ui.root.dataset.fps = (fpsCount * 1000 / (now - fpsStart)).toFixed(1);
      fpsCount = 0;
      fpsStart = now;
    }
    if (dragSend) {
      model.send(dragSend);
      dragSend = null;
    }
    if (info && (!pending || now - pendingSince > 2000)) {
      model.send({ type: "tick" });
      pending = true;
      pendingSince = now;
    }
    requestAnimationFrame(loop);
  }
  requestAnimationFrame(loop);

  // ---- interaction
  function pointer(e) {
    const r = e.currentTarget.getBoundingClientRect(); // the plane's canvas or the space's
    return [e.clientX - r.left, e.clientY - r.top];
  }
  ui.scene.addEventListener("pointerdown", (e) => {
    if (!latest || !info || info.mode !== "live") return;
    const [px, py] = pointer(e);
    const i = flvPick(view, info, latest.pos, px, py);
    if (i < 0) return;
    drag = i;
    ui.scene.setPointerCapture(e.pointerId);
    const [x, y] = view.world(px, py);
    dragSend = { type: "drag", robot: i + 1, x, y };
  });
  ui.scene.addEventListener("pointermove", (e) => {
    if (drag === null) return;
    const [x, y] = view.world(...pointer(e));
    dragSend = { type: "drag", robot: drag + 1, x, y };
  });
  // in space: a robot is dragged in the plane facing the camera through its centre; a
  // press elsewhere (or with shift, or another button) moves the camera (capture: before
  // three.js's OrbitControls, which a grabbed robot switches off until the release)
  ui.scene3d.addEventListener("pointerdown", (e) => {
    ui.scene3d.focus({ preventScroll: true });
    if (!scene3d || !latest || !info || info.mode !== "live" || e.button !== 0 || e.shiftKey) return;
    const [px, py] = pointer(e);
    const i = scene3d.pick(latest.pos, px, py);
    if (i < 0) return;
    drag = i;
    scene3d.grab(latest.pos, i);
    ui.scene3d.setPointerCapture(e.pointerId);
    const p = scene3d.dragPoint(px, py);
    if (p) dragSend = { type: "drag", robot: i + 1, x: p[0], y: p[1], z: p[2] };
  }, { capture: true });
  ui.scene3d.addEventListener("pointermove", (e) => {
    if (drag === null || !scene3d) return;
    const p = scene3d.dragPoint(...pointer(e));
    if (p) dragSend = { type: "drag", robot: drag + 1, x: p[0], y: p[1], z: p[2] };
  });
  const endDrag = () => {
    if (scene3d) scene3d.release();
    if (drag === null) return;
    if (dragSend) model.send(dragSend);
    dragSend = null;
    drag = null;
    model.send({ type: "release" });
  };
  for (const c of [ui.scene, ui.scene3d]) {
    c.addEventListener("pointerup", endDrag);
    c.addEventListener("pointercancel", endDrag);
  }

  ui.button("pause").addEventListener("click", () =>
    model.send({ type: "pause", paused: !(latest && latest.header.paused) }));
  ui.button("step").addEventListener("click", () =>
    model.send({ type: "step", count: Math.max(1, Math.min(10000, Math.round(Number(ui.stepCount.value)) || 1)) }));
  ui.button("reset").addEventListener("click", () => {
    model.send({ type: "reset" });
    needFit = true;
  });
  const fit = (mode) => {
    fitMode = mode;
    needFit = true;
    ui.root.dataset.fit = mode;
  };
  ui.button("fit").addEventListener("click", () => fit("now"));
  ui.button("fit-start").addEventListener("click", () => fit("start"));
  // keys on the drawing (click it first): f fits the formation now, s the start
  const onKey = (e) => {
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    if (e.key === "f" || e.key === "s") {
      fit(e.key === "f" ? "now" : "start");
      e.preventDefault();
    }
  };
  ui.scene.addEventListener("keydown", onKey);
  ui.scene3d.addEventListener("keydown", onKey);
  ui.scene.addEventListener("pointerdown", () => ui.scene.focus({ preventScroll: true }));
  ui.speed.addEventListener("input", () => {
    const v = Math.pow(10, Number(ui.speed.value));
    ui.speedLabel.textContent = `x${flvFmt(v)}`;
    model.send({ type: "speed", value: v });
  });
  ui.law.addEventListener("change", () => model.send({ type: "set_law", name: ui.law.value }));
  const sendIntegrator = () => {
    const dt = Number(ui.dt.value);
    if (isFinite(dt) && dt > 0) model.send({ type: "set_integrator", name: ui.integrator.value, dt });
  };
  ui.integrator.addEventListener("change", sendIntegrator);
  ui.dt.addEventListener("change", sendIntegrator);
  ui.button("perturb").addEventListener("click", () => {
    const s = Number(ui.scale.value);
    if (isFinite(s) && s > 0) model.send({ type: "perturb", scale: s });
  });
  ui.button("export").addEventListener("click", () => model.send({ type: "export_scenario" }));
  ui.button("png").addEventListener("click", () => {
    const t = latest ? latest.header.t.toFixed(3) : "0";
    (space ? ui.scene3d : ui.scene).toBlob((blob) => flvDownload(`${info ? info.name : "formation"}-t${t}.png`, blob), "image/png");
  });
  ui.slider.addEventListener("input", () => model.send({ type: "seek", index: Number(ui.slider.value) }));

  // for tests and scripts: where robot i (1-based) is drawn, in page pixels
  ui.root.flv = {
    switchingLine: flvSwitchingLine,
    robotPx(i) {
      if (space) return this.worldToPage(...latest.pos.slice(3 * (i - 1), 3 * i));
      const r = ui.scene.getBoundingClientRect();
      const [x, y] = view.px(latest.pos[2 * (i - 1)], latest.pos[2 * (i - 1) + 1]);
      return [r.left + x, r.top + y];
    },
    worldToPage(x, y, z) {
      if (space) {
        const r = ui.scene3d.getBoundingClientRect();
        const [px, py] = scene3d.toPx(x, y, z);
        return [r.left + px, r.top + py];
      }
      const r = ui.scene.getBoundingClientRect();
      const [px, py] = view.px(x, y);
      return [r.left + px, r.top + py];
    },
    // what the last frame drew: the grid's ticks and scale bar, the view, the plots
    axes: () => ui.root.flvAxes,
    view: () => ({ scale: view.scale, w: view.w, h: view.h, mode: fitMode,
      start: startBounds, world: [...view.world(0, 0), ...view.world(view.w, view.h)] }),
    plots: () => plotInfo,
    // in space: the camera (position, target, viewing direction, field of view, size)
    camera: () => (scene3d && space ? scene3d.cameraState() : null),
    legend: () => [...ui.legend.querySelectorAll("[data-layer]")].map((e) => e.dataset.layer),
  };

  if (!model.socket) model.send({ type: "hello" }); // a notebook widget is connected already
  return () => {
    alive = false;
    model.off("msg:custom", onMessage);
  };
}
