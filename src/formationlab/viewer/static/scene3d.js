// Drawing a formation in space (info.dim === 3) with three.js (WebGL, vendored in static/three/):
// robots as spheres of their diameters with their 1-based numbers, the graph's edges (grey as
// in the plane; those the error plot draws as lines in the plot's colours), trails, the
// active chirality restrictions (their tetrahedra shaded, as the plane's active triangles), a
// grid in metres under the formation with the x, y, z axes and their ticks, obstacles, and
// the marching reference. The camera orbits (left drag), zooms (wheel) and pans (right drag,
// or shift + left drag); a robot is dragged in the plane facing the camera through its
// centre: the pointer's ray meets that plane where the robot is sent. World z is up.
// Frames carry x0 y0 z0 x1 y1 z1 ...; arrays here are 0-based, robot numbers 1-based.

const FLV_TRAIL = 240; // positions kept per robot for its trail
const FLV_TRAIL_ROBOTS = 200; // beyond, no trails (their lines hide the formation)
const FLV_LABELS_MAX = 40; // robots beyond which no numbers are drawn (as in the plane)
const FLV_TRAIL_COLOR = "#9ec5e8";

// three.js, loaded once when a formation in space is first shown: from the server beside the
// page (model.threeUrl), or in a notebook from the widget's `_three` trait (module texts,
// imported from blobs with their relative imports pointed at each other).
let flvThreeLoading = null;
function flvLoadThree(model) {
  if (flvThreeLoading) return flvThreeLoading;
  flvThreeLoading = (async () => {
    let urls;
    if (model.threeUrl) {
      urls = [model.threeUrl("three.module.min.js"), model.threeUrl("OrbitControls.js")];
    } else {
      const src = model.get("_three") || {};
      if (!src["three.module.min.js"]) throw new Error("the widget sent no three.js modules");
      const blob = (text) => URL.createObjectURL(new Blob([text], { type: "text/javascript" }));
      const core = blob(src["three.core.min.js"]);
      const main = blob(src["three.module.min.js"].split("./three.core.min.js").join(core));
      urls = [main, blob(src["OrbitControls.js"].split("./three.module.min.js").join(main))];
    }
    const [THREE, controls] = await Promise.all(urls.map((u) => import(u)));
    return { THREE, OrbitControls: controls.OrbitControls };
  })();
  return flvThreeLoading;
}

// A sprite of `text` (`height` world units tall), drawn on a canvas.
function flvTextSprite(THREE, text, color, height) {
  const c = document.createElement("canvas");
  const ctx = c.getContext("2d");
  const font = "600 44px sans-serif";
  ctx.font = font;
  c.width = Math.ceil(ctx.measureText(text).width) + 12;
  c.height = 56;
  ctx.font = font;
  ctx.fillStyle = color;
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.fillText(text, c.width / 2, c.height / 2 + 2);
  const map = new THREE.CanvasTexture(c);
  map.colorSpace = THREE.SRGBColorSpace;
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map, depthTest: false,
    transparent: true }));
  sprite.scale.set((height * c.width) / c.height, height, 1);
  sprite.renderOrder = 10;
  return sprite;
}

function flvDispose(obj) {
  obj.traverse((o) => {
    if (o.geometry) o.geometry.dispose();
    if (o.material) {
      if (o.material.map) o.material.map.dispose();
      o.material.dispose();
    }
  });
}

class FlvScene3D {
  constructor(lib, canvas) {
    const { THREE, OrbitControls } = lib;
    this.THREE = THREE;
    this.canvas = canvas;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true,
      preserveDrawingBuffer: true }); // (the PNG button reads the canvas)
    this.renderer.setClearColor(FLV_COLORS.background);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 1e4);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(5, -8, 5);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x707c88, 2.0));
    const sun = new THREE.DirectionalLight(0xffffff, 1.5);
    sun.position.set(0.4, -0.6, 1);
    this.scene.add(sun);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.enableDamping = false;
    this.controls.zoomToCursor = true;
    this.lastOrbit = -1e9; // when the person last moved the camera (ms)
    this.controls.addEventListener("change", () => {
      this.lastOrbit = performance.now();
    });
    this.raycaster = new THREE.Raycaster();
    this.plane = new THREE.Plane();
    this.tmp = new THREE.Vector3();
    this.matrix = new THREE.Matrix4();
    this.colour = new THREE.Color();
    this.frameInfo = null;
    this.n = 0;
    this.reach = 1; // the radius of the sphere the camera was last fitted to, m
    this.w = 1;
    this.h = 1;
  }

  // Build what does not change from frame to frame: spheres, edges, labels, trails.
  setInfo(info) {
    const THREE = this.THREE;
    if (this.group) {
      this.scene.remove(this.group);
      flvDispose(this.group);
    }
    this.group = new THREE.Group();
    this.scene.add(this.group);
    this.info = info;
    const n = info.n;
    this.n = n;
    const detail = n > 200 ? [10, 8] : [24, 16];
    this.robots = new THREE.InstancedMesh(new THREE.SphereGeometry(1, ...detail),
      new THREE.MeshLambertMaterial({ color: 0xffffff }), n);
    this.robots.frustumCulled = false;
    for (let i = 0; i < n; i++) this.robots.setColorAt(i, this.colour.set(FLV_COLORS.robot));
    this.group.add(this.robots);
    const m = info.edges.length;
    const eg = new THREE.BufferGeometry();
    eg.setAttribute("position", new THREE.BufferAttribute(new Float32Array(6 * m), 3));
    eg.setAttribute("color", new THREE.BufferAttribute(new Float32Array(6 * m), 3));
    this.edges = new THREE.LineSegments(eg, new THREE.LineBasicMaterial({ vertexColors: true }));
    this.edges.frustumCulled = false;
    this.group.add(this.edges);
    this.edgeColours = "";
    // active restrictions: the faces of their tetrahedra
    const tg = new THREE.BufferGeometry();
    tg.setAttribute("position", new THREE.BufferAttribute(new Float32Array(36 * 60), 3));
    this.active = new THREE.Mesh(tg, new THREE.MeshBasicMaterial({ color: FLV_COLORS.line,
      transparent: true, opacity: 0.14, side: THREE.DoubleSide, depthWrite: false }));
    this.active.frustumCulled = false;
    this.group.add(this.active);
    // numbers
    this.labels = [];
    if (n <= FLV_LABELS_MAX) {
      let r = 0;
      for (const d of info.diameters) r = Math.max(r, d / 2);
      for (let i = 0; i < n; i++) {
        const s = flvTextSprite(THREE, String(i + 1), "#111111", Math.max(1.5 * r, 0.08));
        this.labels.push(s);
        this.group.add(s);
      }
    }
    // trails: a ring of the last FLV_TRAIL positions per robot
    this.trail = null;
    if (n <= FLV_TRAIL_ROBOTS) {
      const geo = new THREE.BufferGeometry();
      geo.setAttribute("position",
        new THREE.BufferAttribute(new Float32Array(n * (FLV_TRAIL - 1) * 6), 3));
      const lines = new THREE.LineSegments(geo, new THREE.LineBasicMaterial({
        color: FLV_TRAIL_COLOR }));
      lines.frustumCulled = false;
      this.group.add(lines);
      this.trail = { lines, ring: new Float32Array(n * FLV_TRAIL * 3), count: 0, head: 0, t: -1 };
    }
    // obstacles: spheres (circles with a centre in space) and axis-aligned boxes
    for (const o of info.obstacles || []) {
      if (o.center.length !== 3) continue;
      let geometry = null;
      if (o.kind === "circle") geometry = new THREE.SphereGeometry(o.radius, 24, 16);
      else if (o.kind === "box") geometry = new THREE.BoxGeometry(...o.size);
      else continue;
      const s = new THREE.Mesh(geometry,
        new THREE.MeshLambertMaterial({ color: 0x5a6069, transparent: true, opacity: 0.35 }));
      s.position.set(...o.center);
      this.group.add(s);
    }
    this.arrows = new THREE.Group();
    this.group.add(this.arrows);
    this.axes = null;
  }

  resize(w, h, dpr) {
    if (w === this.w && h === this.h && dpr === this.dpr) return;
    this.w = w;
    this.h = h;
    this.dpr = dpr;
    this.renderer.setPixelRatio(dpr);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
  }

  // Look at the robots `pos` (all of them, with their radii) from the camera's direction now.
  fit(pos) {
    const THREE = this.THREE;
    const n = pos.length / 3;
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < n; i++) {
      for (let k = 0; k < 3; k++) {
        lo[k] = Math.min(lo[k], pos[3 * i + k]);
        hi[k] = Math.max(hi[k], pos[3 * i + k]);
      }
    }
    if (!isFinite(lo[0])) return;
    const c = new THREE.Vector3((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
    let R = 0;
    for (let i = 0; i < n; i++) {
      const d = Math.hypot(pos[3 * i] - c.x, pos[3 * i + 1] - c.y, pos[3 * i + 2] - c.z);
      R = Math.max(R, d + this.info.diameters[i] / 2);
    }
    R = Math.max(R, (this.info.minSpan || 1) / 2);
    const dir = this.camera.position.clone().sub(this.controls.target);
    if (dir.lengthSq() < 1e-18) dir.set(0.5, -0.8, 0.5);
    dir.normalize();
    const half = THREE.MathUtils.degToRad(this.camera.fov / 2);
    const fov = Math.min(half, Math.atan(Math.tan(half) * this.camera.aspect));
    const dist = (1.3 * R) / Math.sin(fov);
    this.controls.target.copy(c);
    this.camera.position.copy(c).addScaledVector(dir, dist);
    this.camera.near = dist / 200;
    this.camera.far = dist * 200;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.reach = R;
    this.buildAxes(lo, hi, R);
  }

  // The grid in metres under the formation (on z = 0 when the formation is near it), with
  // the axes along its edges and their ticks; `this.axesInfo` says what was drawn.
  buildAxes(lo, hi, R) {
    const THREE = this.THREE;
    if (this.axes) {
      this.scene.remove(this.axes);
      flvDispose(this.axes);
    }
    const g = new THREE.Group();
    const step = flvNiceStep((2 * R) / 6);
    const x0 = step * Math.floor((lo[0] - 0.3 * R) / step), x1 = step * Math.ceil((hi[0] + 0.3 * R) / step);
    const y0 = step * Math.floor((lo[1] - 0.3 * R) / step), y1 = step * Math.ceil((hi[1] + 0.3 * R) / step);
    const zTop = step * Math.ceil((hi[2] + 0.25 * R) / step);
    let z0 = step * Math.floor((lo[2] - 0.25 * R) / step);
    if (z0 < 0 && lo[2] >= 0) z0 = 0; // the ground, when every robot is above it
    if (lo[2] > 0 && lo[2] < 4 * R) z0 = 0;
    const grid = [], axis = [];
    for (let x = x0; x <= x1 + 1e-9 * step; x += step) grid.push(x, y0, z0, x, y1, z0);
    for (let y = y0; y <= y1 + 1e-9 * step; y += step) grid.push(x0, y, z0, x1, y, z0);
    const lines = (arr, color) => {
      const geo = new THREE.BufferGeometry();
      geo.setAttribute("position", new THREE.Float32BufferAttribute(arr, 3));
      return new THREE.LineSegments(geo, new THREE.LineBasicMaterial({ color }));
    };
    g.add(lines(grid, "#dfe3e8"));
    axis.push(x0, y0, z0, x1, y0, z0, x0, y0, z0, x0, y1, z0, x0, y0, z0, x0, y0, zTop);
    g.add(lines(axis, "#6b7480"));
    const h = 0.32 * step;
    const label = (text, x, y, z, color) => {
      const s = flvTextSprite(THREE, text, color || FLV_COLORS.tick, h);
      s.position.set(x, y, z);
      g.add(s);
    };
    const ticks = { step, x: [], y: [], z: [] };
    const fmt = (v) => flvFmt(Math.abs(v) < 1e-9 * step ? 0 : v);
    for (let x = x0 + step; x < x1 - 1e-9 * step; x += step) {
      label(fmt(x), x, y0 - 0.45 * step, z0);
      ticks.x.push(x);
    }
    for (let y = y0 + step; y < y1 - 1e-9 * step; y += step) {
      label(fmt(y), x0 - 0.45 * step, y, z0);
      ticks.y.push(y);
    }
    for (let z = z0; z <= zTop + 1e-9 * step; z += step) {
      label(fmt(z), x0 - 0.35 * step, y0 - 0.35 * step, z);
      ticks.z.push(z);
    }
    label("x (m)", x1 + 0.6 * step, y0, z0, FLV_COLORS.axisTitle);
    label("y (m)", x0, y1 + 0.6 * step, z0, FLV_COLORS.axisTitle);
    label("z (m)", x0, y0, zTop + 0.6 * step, FLV_COLORS.axisTitle);
    this.scene.add(g);
    this.axes = g;
    this.axesInfo = { ...ticks, ground: z0, box: [x0, x1, y0, y1, z0, zTop] };
  }

  // Half the largest extent of the robots' centres along an axis, m (at least minSpan / 2).
  spread(pos) {
    let big = 0;
    for (let k = 0; k < 3; k++) {
      let lo = Infinity, hi = -Infinity;
      for (let i = k; i < pos.length; i += 3) {
        lo = Math.min(lo, pos[i]);
        hi = Math.max(hi, pos[i]);
      }
      big = Math.max(big, hi - lo);
    }
    return Math.max(big, this.info.minSpan || 1) / 2;
  }

  // Whether every robot's centre is inside the camera's view, off its edges.
  inView(pos) {
    const v = this.tmp;
    const every = Math.max(1, Math.floor(pos.length / 3 / 1000)); // a sample of many robots
    for (let i = 0; i < pos.length / 3; i += every) {
      v.set(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]).project(this.camera);
      if (Math.abs(v.x) > 0.85 || Math.abs(v.y) > 0.85 || v.z > 1) return false;
    }
    return true;
  }

  // The trails: push the frame's positions when time moved on; start afresh when it went back.
  pushTrail(t, pos) {
    const tr = this.trail;
    if (!tr) return 0;
    const n = this.n;
    if (t < tr.t) tr.count = tr.head = 0; // a reset, or a seek back in a replay
    if (t !== tr.t) {
      tr.ring.set(pos.subarray(0, 3 * n), tr.head * 3 * n);
      tr.head = (tr.head + 1) % FLV_TRAIL;
      tr.count = Math.min(tr.count + 1, FLV_TRAIL);
      tr.t = t;
    }
    const out = tr.lines.geometry.attributes.position;
    const a = out.array, k = tr.count;
    let o = 0;
    for (let s = 0; s + 1 < k; s++) {
      const p0 = ((tr.head - k + s + FLV_TRAIL) % FLV_TRAIL) * 3 * n;
      const p1 = ((tr.head - k + s + 1 + FLV_TRAIL) % FLV_TRAIL) * 3 * n;
      for (let i = 0; i < n; i++) {
        a[o++] = tr.ring[p0 + 3 * i];
        a[o++] = tr.ring[p0 + 3 * i + 1];
        a[o++] = tr.ring[p0 + 3 * i + 2];
        a[o++] = tr.ring[p1 + 3 * i];
        a[o++] = tr.ring[p1 + 3 * i + 1];
        a[o++] = tr.ring[p1 + 3 * i + 2];
      }
    }
    out.needsUpdate = true;
    tr.lines.geometry.setDrawRange(0, o / 3);
    return k;
  }

  // Draw one frame; returns the number of robots drawn, and what else into `opts.drawn`.
  // `opts.fit`: refit the camera to `opts.fitPos` first; `opts.follow`: refit when a robot
  // left the view (not while a robot is dragged, nor just after the person moved the camera).
  draw(info, frame, opts) {
    const pos = frame.pos;
    const n = Math.min(this.n, pos.length / 3);
    const hd = frame.header;
    const drawn = { obstacles: (info.obstacles || []).length, headings: 0, filtered: 0,
      reference: false, lines: 0, active: 0, axes: null, trails: 0, coloured: 0 };
    opts.drawn = drawn;
    if (opts.fit) this.fit(opts.fitPos || pos);
    else if (opts.follow && performance.now() - this.lastOrbit > 1500 &&
      (!this.inView(pos) || this.spread(pos) < 0.4 * this.reach)) {
      this.fit(pos); // a robot left the view, or the formation shrank to a corner of it
    }
    // robots
    const pinned = hd.pinned ? hd.pinned - 1 : -1;
    const filtered = new Set((hd.filtered || []).map((r) => r - 1));
    for (let i = 0; i < n; i++) {
      const r = info.diameters[i] / 2;
      this.matrix.makeScale(r, r, r).setPosition(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]);
      this.robots.setMatrixAt(i, this.matrix);
      const c = i === pinned ? FLV_COLORS.pinned : filtered.has(i) ? FLV_COLORS.filtered : FLV_COLORS.robot;
      this.robots.setColorAt(i, this.colour.set(c));
    }
    this.robots.instanceMatrix.needsUpdate = true;
    this.robots.instanceColor.needsUpdate = true;
    this.robots.boundingSphere = null;
    drawn.filtered = filtered.size;
    // edges: grey, those the error plot draws as lines in its colours
    const edges = info.edges, ea = this.edges.geometry.attributes;
    const shown = opts.plotted || [];
    const key = shown.join(",");
    for (let e = 0; e < edges.length; e++) {
      const i = edges[e][0] - 1, j = edges[e][1] - 1;
      ea.position.array.set([pos[3 * i], pos[3 * i + 1], pos[3 * i + 2],
        pos[3 * j], pos[3 * j + 1], pos[3 * j + 2]], 6 * e);
    }
    ea.position.needsUpdate = true;
    if (key !== this.edgeColours) {
      const grey = new this.THREE.Color(FLV_COLORS.edge);
      for (let e = 0; e < edges.length; e++) {
        const j = shown.indexOf(e + 1);
        const c = j >= 0 ? this.colour.set(FLV_PALETTE[j % FLV_PALETTE.length]) : grey;
        ea.color.array.set([c.r, c.g, c.b, c.r, c.g, c.b], 6 * e);
      }
      ea.color.needsUpdate = true;
      this.edgeColours = key;
    }
    drawn.coloured = shown.length;
    // active restrictions: the four faces of each active tetrahedron
    const surf = info.surfaces, active = hd.active;
    let faces = 0;
    if (surf && surf.tetrahedra && active && opts.lines) {
      const a = this.active.geometry.attributes.position;
      for (const s1 of active.slice(0, 60)) {
        const v = surf.tetrahedra[s1 - 1].map((r) => r - 1);
        for (const face of [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]) {
          face.forEach((c, corner) => {
            const k = v[c];
            a.array.set([pos[3 * k], pos[3 * k + 1], pos[3 * k + 2]], 9 * faces + 3 * corner);
          });
          faces++;
        }
        drawn.active++;
      }
      a.needsUpdate = true;
    }
    this.active.geometry.setDrawRange(0, 3 * faces);
    // numbers, above each robot
    const labels = opts.labels && this.labels.length;
    for (let i = 0; i < this.labels.length; i++) {
      const s = this.labels[i];
      s.visible = !!labels;
      const r = info.diameters[i] / 2;
      s.position.set(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2] + r + 0.6 * s.scale.y);
    }
    drawn.trails = opts.trails ? this.pushTrail(hd.t, pos) : 0;
    if (this.trail) this.trail.lines.visible = !!opts.trails;
    // the marching reference: an arrow from the centroid, or one from each leader
    for (const arrow of this.arrows.children) arrow.dispose();
    this.arrows.clear();
    if (hd.reference) {
      const rows = Array.isArray(hd.reference[0]) ? hd.reference : [hd.reference];
      const lead = info.marching && info.marching.leader;
      const leaders = lead === null || lead === undefined ? [] : [].concat(lead);
      rows.forEach((v, m) => {
        const speed = Math.hypot(...v);
        if (!(speed > 0)) return;
        const from = new this.THREE.Vector3();
        if (Array.isArray(hd.reference[0]) && leaders[m]) {
          const i = leaders[m] - 1;
          from.set(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]);
        } else {
          for (let i = 0; i < n; i++) from.add(this.tmp.set(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]));
          from.multiplyScalar(1 / Math.max(n, 1));
        }
        const dir = new this.THREE.Vector3(...v).normalize();
        const L = Math.min(0.6 * this.reach, Math.max(0.2 * this.reach, 2 * speed));
        this.arrows.add(new this.THREE.ArrowHelper(dir, from, L, FLV_COLORS.reference));
        drawn.reference = true;
      });
    }
    this.renderer.render(this.scene, this.camera);
    drawn.axes = this.axesInfo || null;
    return n;
  }

  // Page pixels (CSS, relative to the canvas) of the world point (x, y, z), and its depth.
  toPx(x, y, z) {
    const v = this.tmp.set(x, y, z).project(this.camera);
    return [(v.x + 1) * this.w / 2, (1 - v.y) * this.h / 2, v.z];
  }

  // The robot (0-based) under the pixel (px, py), or -1: of the robots whose drawn sphere
  // (plus 6 pixels) holds the pixel, the nearest to the camera.
  pick(pos, px, py) {
    const f = this.h / 2 / Math.tan(this.THREE.MathUtils.degToRad(this.camera.fov / 2));
    let best = -1, bestDepth = Infinity;
    for (let i = 0; i < pos.length / 3; i++) {
      const [x, y] = this.toPx(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]);
      const depth = this.tmp.set(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2])
        .applyMatrix4(this.camera.matrixWorldInverse).z * -1;
      if (!(depth > 0)) continue;
      const r = (this.info.diameters[i] / 2) * f / depth + 6;
      if (Math.hypot(x - px, y - py) <= r && depth < bestDepth) {
        best = i;
        bestDepth = depth;
      }
    }
    return best;
  }

  // Start dragging robot i: the plane facing the camera through its centre.
  grab(pos, i) {
    const normal = new this.THREE.Vector3();
    this.camera.getWorldDirection(normal);
    this.plane.setFromNormalAndCoplanarPoint(normal,
      new this.THREE.Vector3(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]));
    this.controls.enabled = false;
  }

  // Where the pointer's ray meets the drag plane, [x, y, z] (null if it does not).
  dragPoint(px, py) {
    const ndc = new this.THREE.Vector2((2 * px) / this.w - 1, 1 - (2 * py) / this.h);
    this.raycaster.setFromCamera(ndc, this.camera);
    const hit = this.raycaster.ray.intersectPlane(this.plane, new this.THREE.Vector3());
    return hit ? [hit.x, hit.y, hit.z] : null;
  }

  release() {
    this.controls.enabled = true;
  }

  cameraState() {
    const p = this.camera.position, t = this.controls.target, d = new this.THREE.Vector3();
    this.camera.getWorldDirection(d);
    return { position: [p.x, p.y, p.z], target: [t.x, t.y, t.z], direction: [d.x, d.y, d.z],
      fov: this.camera.fov, w: this.w, h: this.h };
  }
}
