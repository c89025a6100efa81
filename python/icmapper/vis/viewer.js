/* icmapper viewer: a small program in three parts — state, draw, events.
 *
 * Data: the JSON in <script id="icmapper-data"> (format "icmapper-viewer", version 1; written by
 * icmapper.vis.viewer). World coordinates in metres; the canvas shows them north up.
 *
 * The map at a frame is the final map's instances whose first frame (bookkeeping) is at or
 * before that frame's source index, drawn with their final shapes (icmapper.vis.replay). A city
 * (kind "city") holds its drives in D.drives ({name, index, frames, dets} each): a drive selector
 * picks the drive whose frames the slider moves through; the city map and the city's ground truth
 * are drawn whole at every frame (bookkeeping frames do not compare across drives). A city with
 * an update holds its latest change report in D.changes (icmapper.vis.viewer.changes_block): the
 * "changes" layer draws them over the map, removed red, added green, moved orange (a move's
 * stored part thin and dashed), map errors (cause "map", reported, not applied) in short dashes;
 * while it is on, the map is drawn grey (unchanged), as in the report's picture.
 *
 * window.icmapperViewer (for tests and scripts):
 *   ready            true once the first frame is drawn
 *   numFrames        frames of the run (the slider's max + 1); of the drive in a city
 *   drive            the selected drive's position in D.drives (city), else null
 *   setDrive(k)      selects drive k of a city (its frames, predictions and path) and draws
 *   frame            the current frame (slider position, 0-based)
 *   frameIndex       its index in the source sequence
 *   drawn            {class name: map instances drawn} (layer and class toggles, frame applied)
 *   drawnInView      map instances stroked in the last draw (zoomed in, those off the view
 *                    are skipped; `drawn` counts them all)
 *   drawnGt          {class name: ground-truth instances drawn}
 *   drawnDetections  {class name: predictions of the current frame drawn}
 *   drawnChanges     {added, removed, moved: changes drawn} (the "changes" layer, classes
 *                    applied; all 0 without a change report)
 *   selected         null, or {id, cls, className, observations, firstFrame, lastFrame,
 *                    cdToGt (m or null), points}
 *   lastDrawMs       duration of the last draw (JavaScript time of issuing it)
 *   drawTimes        durations of the last 240 draws (ms)
 *   setFrame(t)      moves the slider to frame t and draws
 *   select(id)       selects the map instance with this id (null: none); returns `selected`
 *   toggle(name, on) layer "map" | "gt" | "dets" | "path" | "labels" | "follow" | "changes", or
 *                    a class name
 *   anchor(id)       a world point [x, y] on the instance (its middle vertex)
 *   toClient(x, y)   page (client) coordinates [px, py] of a world point
 *   fit()            fits the view to the map, ground truth and path
 *   zoom(f, px, py)  zooms by f around the client point (default: the centre)
 *   pan(dx, dy)      pans by (dx, dy) pixels
 *   redraw()         draws now; returns the draw's duration (ms)
 *   measure(n)       Promise: n animation frames, each panning, zooming and moving the slider;
 *                    resolves to {frames, medianMs, p95Ms, meanDrawMs} of the frame intervals
 */
(function () {
  "use strict";

  // ------------------------------------------------------------------ data
  const D = JSON.parse(document.getElementById("icmapper-data").textContent);
  if (D.format !== "icmapper-viewer" || D.version !== 1) {
    throw new Error("icmapper viewer: unknown data format " + D.format + " v" + D.version);
  }
  const NC = D.classes.length;
  const CITY = D.kind === "city" && D.drives && D.drives.length > 0;
  if (CITY) { D.frames = D.drives[0].frames; D.dets = D.drives[0].dets; }
  let T = Math.max(1, D.frames.count);
  const M = D.map;
  const NM = M.id.length;
  let frameIndex = D.frames.index && D.frames.index.length ? D.frames.index : [0];
  // The bookkeeping frame up to which map instances are drawn at slider position t: a city's
  // map is drawn whole (its instances' frames belong to different drives).
  function mapLimit(t) { return CITY ? Infinity : frameIndex[t]; }
  // Levels of detail: vertex spacing (m) of simplified paths, built on first use. A draw uses the
  // coarsest level whose spacing stays under LOD_PX pixels: a chord of c pixels on a curve of
  // radius R metres at s pixels per metre strays c^2 / (8 R s) pixels, under 0.5 px for R >= 10 m.
  const LOD_STEPS = [0, 3, 10, 30, 100];
  const LOD_PX = 4;

  function addPolyline(path, xy, s, e, closed, minStep) {
    if (e - s < 1) return;
    let lx = xy[2 * s], ly = xy[2 * s + 1];
    path.moveTo(lx, ly);
    for (let k = s + 1; k < e; k++) {
      const x = xy[2 * k], y = xy[2 * k + 1];
      if (minStep > 0 && k < e - 1) {
        const dx = x - lx, dy = y - ly;
        if (dx * dx + dy * dy < minStep * minStep) continue;
      }
      path.lineTo(x, y);
      lx = x; ly = y;
    }
    if (closed) path.closePath();
  }

  // Map instances grouped per class into buckets of equal first frame: drawing frame t strokes
  // the buckets with first <= index(t), so moving the slider never rebuilds geometry.
  const buckets = []; // per class: [{first, members: [instance], paths: [Path2D per level]}]
  for (let c = 0; c < NC; c++) buckets.push([]);
  (function buildBuckets() {
    const order = Array.from({ length: NM }, (_, i) => i);
    order.sort((a, b) => M.first[a] - M.first[b]);
    for (const i of order) {
      const list = buckets[M.cls[i]];
      let b = list[list.length - 1];
      if (!b || b.first !== M.first[i]) {
        b = { first: M.first[i], members: [], paths: new Array(LOD_STEPS.length).fill(null) };
        list.push(b);
      }
      b.members.push(i);
    }
  })();

  function bucketPath(b, level) {
    if (!b.paths[level]) {
      const p = new Path2D();
      for (const i of b.members) {
        addPolyline(p, M.xy, M.start[i], M.start[i + 1], M.closed[i], LOD_STEPS[level]);
      }
      b.paths[level] = p;
    }
    return b.paths[level];
  }

  function lodLevel(scale) {
    let level = 0;
    for (let k = 1; k < LOD_STEPS.length; k++) if (LOD_STEPS[k] * scale <= LOD_PX) level = k;
    return level;
  }

  const gtPaths = [];
  const gtCount = new Array(NC).fill(0);
  for (let c = 0; c < NC; c++) gtPaths.push(new Path2D());
  if (D.gt) {
    for (let i = 0; i < D.gt.cls.length; i++) {
      addPolyline(gtPaths[D.gt.cls[i]], D.gt.xy, D.gt.start[i], D.gt.start[i + 1], D.gt.closed[i], 0);
      gtCount[D.gt.cls[i]]++;
    }
  }

  let poses = D.frames.pose; // [[x, y, yaw]] or null
  let pathAll = null;
  function buildPath() {
    pathAll = null;
    if (poses && poses.length > 1) {
      pathAll = new Path2D();
      pathAll.moveTo(poses[0][0], poses[0][1]);
      for (let t = 1; t < poses.length; t++) pathAll.lineTo(poses[t][0], poses[t][1]);
    }
  }
  buildPath();

  // Spatial grid of instance bounding boxes for picking.
  const CELL = 25.0;
  const grid = new Map();
  const bbox = new Float64Array(4 * NM);
  for (let i = 0; i < NM; i++) {
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    for (let k = M.start[i]; k < M.start[i + 1]; k++) {
      const x = M.xy[2 * k], y = M.xy[2 * k + 1];
      if (x < x0) x0 = x; if (x > x1) x1 = x; if (y < y0) y0 = y; if (y > y1) y1 = y;
    }
    bbox.set([x0, y0, x1, y1], 4 * i);
    for (let gx = Math.floor(x0 / CELL); gx <= Math.floor(x1 / CELL); gx++) {
      for (let gy = Math.floor(y0 / CELL); gy <= Math.floor(y1 / CELL); gy++) {
        const key = gx + "," + gy;
        let cell = grid.get(key);
        if (!cell) { cell = []; grid.set(key, cell); }
        cell.push(i);
      }
    }
  }
  let mapArea = 1;
  if (NM) {
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    for (let i = 0; i < NM; i++) {
      x0 = Math.min(x0, bbox[4 * i]); y0 = Math.min(y0, bbox[4 * i + 1]);
      x1 = Math.max(x1, bbox[4 * i + 2]); y1 = Math.max(y1, bbox[4 * i + 3]);
    }
    mapArea = Math.max((x1 - x0) * (y1 - y0), 1);
  }
  const indexOfId = new Map();
  for (let i = 0; i < NM; i++) indexOfId.set(M.id[i], i);

  // The latest update's changes (a city): per change type and cause, per class, one path of
  // the geometry after the change and one of a move's stored part.
  const CH = D.changes || null;
  const CHANGE_TYPES = ["removed", "added", "moved"];
  const UNCHANGED = "#b8b8b8"; // the map's colour while the changes are shown
  const changePaths = {}; // type -> {road: [Path2D per class], map: [...], before: [...]}
  const changeCount = {}; // type -> [count per class]
  if (CH) {
    CHANGE_TYPES.forEach((t) => {
      changePaths[t] = { road: [], map: [], before: [] };
      changeCount[t] = [];
      for (let c = 0; c < NC; c++) {
        changePaths[t].road.push(new Path2D());
        changePaths[t].map.push(new Path2D());
        changePaths[t].before.push(new Path2D());
        changeCount[t].push(0);
      }
    });
    for (let k = 0; k < CH.change.length; k++) {
      const t = CH.change[k], c = CH.cls[k];
      if (!(t in changePaths)) continue;
      const road = CH.cause[k] === "road";
      addPolyline(changePaths[t][road ? "road" : "map"][c], CH.xy, CH.start[k], CH.start[k + 1],
        CH.closed[k] === 1, 0);
      addPolyline(changePaths[t].before[c], CH.beforeXy, CH.beforeStart[k],
        CH.beforeStart[k + 1], false, 0);
      changeCount[t][c]++;
    }
  }

  // ------------------------------------------------------------------ state
  const state = {
    frame: T - 1,
    classOn: D.classes.map(() => true),
    layers: { map: true, gt: !!D.gt, dets: !!D.dets, path: !!poses, labels: true, follow: false,
      changes: !!CH },
    view: { cx: 0, cy: 0, scale: 1 }, // world point at the canvas centre, pixels per metre
    selected: -1,
    playing: null,
  };
  const api = {
    ready: false, numFrames: T, frame: state.frame, frameIndex: frameIndex[state.frame] || 0,
    drive: CITY ? 0 : null,
    drawn: {}, drawnGt: {}, drawnDetections: {}, drawnChanges: {}, selected: null, lastDrawMs: 0,
    drawTimes: [],
  };
  window.icmapperViewer = api;

  // ------------------------------------------------------------------ elements
  const $ = (id) => document.getElementById(id);
  const canvas = $("map");
  const ctx = canvas.getContext("2d");
  const slider = $("frame");
  slider.max = String(T - 1);
  slider.value = String(state.frame);
  $("title").textContent = D.title || "icmapper viewer";
  function showSubtitle() {
    $("subtitle").textContent = [D.source && "source " + D.source, NM + " map instances",
      D.kind === "map" ? "map file (no run)" : CITY ? D.drives.length + " drives" : T + " frames"]
      .filter(Boolean).join(" · ");
  }
  showSubtitle();

  function cssSize() { return [canvas.clientWidth || 1, canvas.clientHeight || 1]; }

  function toScreen(x, y) {
    const [w, h] = cssSize(), v = state.view;
    return [(x - v.cx) * v.scale + w / 2, h / 2 - (y - v.cy) * v.scale];
  }
  function toWorld(px, py) {
    const [w, h] = cssSize(), v = state.view;
    return [(px - w / 2) / v.scale + v.cx, v.cy - (py - h / 2) / v.scale];
  }

  // ------------------------------------------------------------------ draw
  function poseAt(t) { return poses ? poses[Math.min(t, poses.length - 1)] : null; }

  function drawEgo(p, dpr) {
    const v = state.view;
    if (D.range) { // perception range, oriented with the ego
      const [hx, hy] = D.range, c = Math.cos(p[2]), s = Math.sin(p[2]);
      ctx.beginPath();
      [[hx, hy], [hx, -hy], [-hx, -hy], [-hx, hy]].forEach(([a, b], k) => {
        const x = p[0] + c * a - s * b, y = p[1] + s * a + c * b;
        if (k === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
      });
      ctx.closePath();
      ctx.strokeStyle = "rgba(90,90,90,.8)";
      ctx.lineWidth = 1 / v.scale;
      ctx.setLineDash([4 / v.scale, 3 / v.scale]);
      ctx.stroke();
      ctx.setLineDash([]);
    }
    // the ego: an arrow of at least 14 px
    const len = Math.max(4.8, 14 / v.scale), wid = len * 0.45;
    const c = Math.cos(p[2]), s = Math.sin(p[2]);
    const pts = [[len * 0.6, 0], [-len * 0.4, wid / 2], [-len * 0.2, 0], [-len * 0.4, -wid / 2]];
    ctx.beginPath();
    pts.forEach(([a, b], k) => {
      const x = p[0] + c * a - s * b, y = p[1] + s * a + c * b;
      if (k === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
    });
    ctx.closePath();
    ctx.fillStyle = "#222";
    ctx.fill();
  }

  let detCache = { frame: -1, paths: null, counts: null };
  function framePredictions(t) {
    if (detCache.frame === t) return detCache;
    const paths = [], counts = new Array(NC).fill(0), labels = [];
    for (let c = 0; c < NC; c++) paths.push({ tracked: new Path2D(), other: new Path2D() });
    const d = D.dets;
    for (let j = d.frameStart[t]; j < d.frameStart[t + 1]; j++) {
      const c = d.cls[j], tracked = d.tid[j] < d.untrackedFrom;
      addPolyline(tracked ? paths[c].tracked : paths[c].other, d.xy, d.start[j], d.start[j + 1],
        c === 0, 0);
      counts[c]++;
      if (tracked) {
        const mid = d.start[j] + ((d.start[j + 1] - d.start[j]) >> 1);
        labels.push([d.xy[2 * mid], d.xy[2 * mid + 1], String(d.tid[j]), c]);
      }
    }
    detCache = { frame: t, paths, counts, labels };
    return detCache;
  }

  function instancePath(i) {
    const p = new Path2D();
    addPolyline(p, M.xy, M.start[i], M.start[i + 1], M.closed[i], 0);
    return p;
  }

  // Zoomed in (the view covers less than CULL_BELOW of the map's box), only the instances in
  // the grid cells under the view are stroked, in paths built for this draw.
  const CULL_BELOW = 0.25;
  const seenAt = new Int32Array(NM);
  let drawStamp = 0;
  function viewPaths(x0, y0, x1, y1, fIdx, level) {
    drawStamp++;
    const paths = [], counts = new Array(NC).fill(0);
    for (let c = 0; c < NC; c++) paths.push(new Path2D());
    for (let gx = Math.floor(x0 / CELL); gx <= Math.floor(x1 / CELL); gx++) {
      for (let gy = Math.floor(y0 / CELL); gy <= Math.floor(y1 / CELL); gy++) {
        const cell = grid.get(gx + "," + gy);
        if (!cell) continue;
        for (const i of cell) {
          if (seenAt[i] === drawStamp) continue;
          seenAt[i] = drawStamp;
          const c = M.cls[i];
          if (!state.classOn[c] || M.first[i] > fIdx) continue;
          addPolyline(paths[c], M.xy, M.start[i], M.start[i + 1], M.closed[i], LOD_STEPS[level]);
          counts[c]++;
        }
      }
    }
    return { paths, counts };
  }

  function visibleInstance(i) {
    return state.layers.map && state.classOn[M.cls[i]] && M.first[i] <= mapLimit(state.frame);
  }

  function draw() {
    const t0 = performance.now();
    const dpr = window.devicePixelRatio || 1;
    const [w, h] = cssSize();
    if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
      canvas.width = Math.round(w * dpr);
      canvas.height = Math.round(h * dpr);
    }
    const v = state.view;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#fff";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.setTransform(dpr * v.scale, 0, 0, -dpr * v.scale,
      dpr * (w / 2 - v.cx * v.scale), dpr * (h / 2 + v.cy * v.scale));
    ctx.lineJoin = "round";
    ctx.lineCap = "round";
    const px = 1 / v.scale; // one CSS pixel in metres
    const fIdx = frameIndex[state.frame];
    const limit = mapLimit(state.frame);
    const drawn = {}, drawnGt = {}, drawnDet = {};

    if (state.layers.gt && D.gt) {
      ctx.globalAlpha = 0.28;
      ctx.lineWidth = Math.max(5 * px, 1.2);
      for (let c = 0; c < NC; c++) {
        drawnGt[D.classes[c]] = state.classOn[c] ? gtCount[c] : 0;
        if (!state.classOn[c]) continue;
        ctx.strokeStyle = D.colours[c];
        ctx.stroke(gtPaths[c]);
      }
      ctx.globalAlpha = 1;
    } else D.classes.forEach((n) => { drawnGt[n] = 0; });

    if (state.layers.path && pathAll) {
      ctx.lineWidth = 1.2 * px;
      ctx.strokeStyle = "#bbb";
      ctx.stroke(pathAll);
      ctx.beginPath();
      ctx.moveTo(poses[0][0], poses[0][1]);
      for (let t = 1; t <= state.frame && t < poses.length; t++) ctx.lineTo(poses[t][0], poses[t][1]);
      ctx.strokeStyle = "#444";
      ctx.lineWidth = 1.6 * px;
      ctx.stroke();
    }

    const level = lodLevel(v.scale);
    ctx.lineWidth = 1.5 * px;
    const [vx0, vy1] = toWorld(0, 0), [vx1, vy0] = toWorld(w, h);
    const culled = (vx1 - vx0) * (vy1 - vy0) < CULL_BELOW * mapArea;
    const inView = culled ? viewPaths(vx0, vy0, vx1, vy1, limit, level) : null;
    let nInView = 0;
    const changesOn = state.layers.changes && CH; // the map grey under the changes
    for (let c = 0; c < NC; c++) {
      let n = 0;
      if (state.layers.map && state.classOn[c]) {
        ctx.strokeStyle = changesOn ? UNCHANGED : D.colours[c];
        for (const b of buckets[c]) {
          if (b.first > limit) break;
          if (!culled) ctx.stroke(bucketPath(b, level));
          n += b.members.length;
        }
        if (culled) { ctx.stroke(inView.paths[c]); nInView += inView.counts[c]; } else nInView += n;
      }
      drawn[D.classes[c]] = n;
    }
    api.level = LOD_STEPS[level];
    api.drawnInView = nInView;

    const drawnCh = { removed: 0, added: 0, moved: 0 };
    if (state.layers.changes && CH) {
      for (const t of CHANGE_TYPES) {
        const colour = CH.colours[t];
        for (let c = 0; c < NC; c++) {
          if (!state.classOn[c] || !changeCount[t][c]) continue;
          drawnCh[t] += changeCount[t][c];
          ctx.strokeStyle = colour;
          if (t === "moved") { // the stored part it replaced: thin, dashed
            ctx.lineWidth = 1.5 * px;
            ctx.setLineDash([4 * px, 3 * px]);
            ctx.stroke(changePaths[t].before[c]);
          }
          ctx.lineWidth = 3.5 * px;
          ctx.setLineDash([]);
          ctx.stroke(changePaths[t].road[c]);
          ctx.setLineDash([1.5 * px, 3 * px]); // map errors: reported, not applied
          ctx.stroke(changePaths[t].map[c]);
          ctx.setLineDash([]);
        }
      }
    }
    api.drawnChanges = drawnCh;

    if (state.selected >= 0 && visibleInstance(state.selected)) {
      const p = instancePath(state.selected);
      ctx.strokeStyle = "#000";
      ctx.lineWidth = 6 * px;
      ctx.stroke(p);
      ctx.strokeStyle = D.colours[M.cls[state.selected]];
      ctx.lineWidth = 3.5 * px;
      ctx.stroke(p);
    }

    let labels = [];
    if (state.layers.dets && D.dets) {
      const fp = framePredictions(state.frame);
      for (let c = 0; c < NC; c++) {
        drawnDet[D.classes[c]] = state.classOn[c] ? fp.counts[c] : 0;
        if (!state.classOn[c]) continue;
        ctx.strokeStyle = D.colours[c];
        ctx.globalAlpha = 0.45;
        ctx.lineWidth = 1 * px;
        ctx.setLineDash([3 * px, 3 * px]);
        ctx.stroke(fp.paths[c].other);
        ctx.setLineDash([]);
        ctx.globalAlpha = 1;
        ctx.strokeStyle = "#fff";
        ctx.lineWidth = 5 * px;
        ctx.stroke(fp.paths[c].tracked);
        ctx.strokeStyle = D.colours[c];
        ctx.lineWidth = 2.6 * px;
        ctx.stroke(fp.paths[c].tracked);
      }
      labels = fp.labels.filter((l) => state.classOn[l[3]]);
    } else D.classes.forEach((n) => { drawnDet[n] = 0; });

    const pose = poseAt(state.frame);
    if (pose) drawEgo(pose, dpr);

    // screen-space text: track ids of the frame's predictions
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    if (state.layers.labels && labels.length) {
      ctx.font = "11px system-ui, sans-serif";
      ctx.textAlign = "center";
      ctx.textBaseline = "middle";
      for (const [x, y, text, c] of labels) {
        const [sx, sy] = toScreen(x, y);
        if (sx < -20 || sy < -20 || sx > w + 20 || sy > h + 20) continue;
        const tw = ctx.measureText(text).width + 6;
        ctx.fillStyle = "rgba(255,255,255,.9)";
        ctx.fillRect(sx - tw / 2, sy - 8, tw, 16);
        ctx.strokeStyle = D.colours[c];
        ctx.lineWidth = 1;
        ctx.strokeRect(sx - tw / 2, sy - 8, tw, 16);
        ctx.fillStyle = D.colours[c];
        ctx.fillText(text, sx, sy);
      }
    }
    updateScaleBar();

    const ms = performance.now() - t0;
    api.drawn = drawn;
    api.drawnGt = drawnGt;
    api.drawnDetections = drawnDet;
    api.frame = state.frame;
    api.frameIndex = fIdx;
    api.lastDrawMs = ms;
    api.drawTimes.push(ms);
    if (api.drawTimes.length > 240) api.drawTimes.shift();
    return ms;
  }

  let pending = false;
  function requestDraw() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; draw(); });
  }

  function updateScaleBar() {
    const target = 120 / state.view.scale; // metres in ~120 px
    const p = Math.pow(10, Math.floor(Math.log10(target)));
    const nice = [1, 2, 5, 10].map((k) => k * p).filter((m) => m <= target).pop() || p;
    const bar = $("scale");
    bar.firstElementChild.style.width = nice * state.view.scale + "px";
    bar.lastElementChild.textContent = nice >= 1000 ? nice / 1000 + " km" : nice + " m";
  }

  // ------------------------------------------------------------------ panels
  function fmt(v, digits) { return v === null || v === undefined ? "-" : v.toFixed(digits); }

  function buildLayers() {
    const box = $("layers");
    const add = (key, text, swatch, checked, attrs) => {
      const label = document.createElement("label");
      const input = document.createElement("input");
      input.type = "checkbox";
      input.checked = checked;
      Object.entries(attrs).forEach(([k, val]) => input.setAttribute(k, val));
      input.addEventListener("change", () => api.toggle(key, input.checked));
      label.appendChild(input);
      if (swatch) {
        const s = document.createElement("span");
        s.className = "swatch";
        s.style.background = swatch;
        label.appendChild(s);
      }
      label.appendChild(document.createTextNode(text));
      box.appendChild(label);
    };
    D.classes.forEach((name, c) => {
      const n = M.cls.filter((k) => k === c).length;
      add(name, name + " (" + n + ")", D.colours[c], true, { "data-class": name });
    });
    add("map", "global map (predicted)", null, true, { "data-layer": "map" });
    if (D.gt) add("gt", "ground truth (pale bands)", null, true, { "data-layer": "gt" });
    if (D.dets) add("dets", "predictions of the frame", null, true, { "data-layer": "dets" });
    if (D.dets) add("labels", "track ids", null, true, { "data-layer": "labels" });
    if (poses) add("path", "ego path", null, true, { "data-layer": "path" });
    if (poses) add("follow", "follow the ego", null, false, { "data-layer": "follow" });
    if (CH) {
      add("changes", "changes of update " + CH.update + " (" + CH.change.length + ")", null, true,
        { "data-layer": "changes" });
      CHANGE_TYPES.forEach((t) => {
        const road = CH.change.filter((x, k) => x === t && CH.cause[k] === "road").length;
        const all = CH.change.filter((x) => x === t).length;
        const row = document.createElement("div");
        row.className = "muted";
        row.setAttribute("data-change", t);
        row.style.marginLeft = "24px";
        const s = document.createElement("span");
        s.className = "swatch";
        s.style.background = CH.colours[t];
        row.appendChild(s);
        row.appendChild(document.createTextNode(" " + t + ": " + road + " applied" +
          (all > road ? ", " + (all - road) + " map error(s)" : "")));
        box.appendChild(row);
      });
    }
  }

  function buildMetrics() {
    const box = $("metrics");
    if (!D.metrics) { box.innerHTML = '<span class="muted">no ground truth</span>'; return; }
    const m = D.metrics;
    let html = "<table><tr><th>class</th><th>CD (m)</th><th>GAP</th></tr>";
    D.classes.forEach((name) => {
      const gap = m.GAP[name];
      html += "<tr data-class=\"" + name + "\"><td>" + name + "</td><td>" + fmt(m.CD[name], 2) +
        "</td><td>" + (gap === null ? "-" : (100 * gap).toFixed(1)) + "</td></tr>";
    });
    html += "<tr><td><b>mean</b></td><td><b>" + fmt(m.mCD, 2) + "</b></td><td><b>" +
      (m.mGAP === null ? "-" : (100 * m.mGAP).toFixed(1)) + "</b></td></tr></table>";
    html += '<div class="muted">GAP x100 at ' + m.thresholds.join(" / ") + " m</div>";
    box.innerHTML = html;
  }

  function showSelection() {
    const box = $("selection");
    const i = state.selected;
    if (i < 0) {
      api.selected = null;
      box.className = "muted";
      box.textContent = "click an instance of the map";
      return;
    }
    const sel = {
      id: M.id[i], cls: M.cls[i], className: D.classes[M.cls[i]], observations: M.obs[i],
      firstFrame: M.first[i], lastFrame: M.last[i], cdToGt: M.cd[i],
      points: M.start[i + 1] - M.start[i],
    };
    api.selected = sel;
    box.className = "";
    const cd = sel.cdToGt === null ? (D.gt ? "none within 10 m" : "no ground truth")
      : sel.cdToGt.toFixed(2) + " m";
    const rows = [["id", sel.id], ["class", sel.className], ["observations", sel.observations],
      ["first frame", sel.firstFrame], ["last frame", sel.lastFrame],
      ["CD to nearest GT", cd], ["points", sel.points]];
    box.innerHTML = "<dl>" + rows.map(([k, val]) =>
      "<dt>" + k + "</dt><dd data-field=\"" + k.replace(/ /g, "-") + "\">" + val + "</dd>")
      .join("") + "</dl>";
  }

  const camImgs = [];
  function buildCameras() {
    const box = $("cameras");
    if (!D.cameras) { box.style.display = "none"; return; }
    const cols = D.cameras.columns, [h, w] = D.cameras.size;
    const width = Math.min(w, 220);
    box.style.gridTemplateColumns = "repeat(" + cols + ", " + width + "px)";
    D.cameras.names.forEach((name) => {
      const fig = document.createElement("figure");
      const img = document.createElement("img");
      img.alt = name;
      img.width = width;
      img.height = Math.round((width * h) / w);
      const cap = document.createElement("figcaption");
      cap.textContent = name;
      fig.appendChild(img);
      fig.appendChild(cap);
      box.appendChild(fig);
      camImgs.push(img);
    });
  }

  function showFrame() {
    const t = state.frame;
    slider.value = String(t);
    const time = D.frames.time ? " · t = " + D.frames.time[t].toFixed(1) + " s" : "";
    $("framelabel").textContent = "frame " + t + " / " + (T - 1) + time;
    if (D.cameras) D.cameras.frames[t].forEach((src, k) => { camImgs[k].src = src; });
    const fIdx = frameIndex[t];
    let nMap = 0;
    for (let i = 0; i < NM; i++) if (M.first[i] <= mapLimit(t)) nMap++;
    let info = "<dl>";
    if (CITY) info += "<dt>drive</dt><dd>" + D.drives[api.drive].name + "</dd>";
    info += "<dt>frame</dt><dd>" + t + " / " + (T - 1) + " (source index " + fIdx + ")</dd>";
    info += "<dt>" + (CITY ? "city map" : "map so far") + "</dt><dd>" + nMap + " instances</dd>";
    if (D.dets) {
      const n = D.dets.frameStart[t + 1] - D.dets.frameStart[t];
      let tracked = 0;
      for (let j = D.dets.frameStart[t]; j < D.dets.frameStart[t + 1]; j++) {
        if (D.dets.tid[j] < D.dets.untrackedFrom) tracked++;
      }
      info += "<dt>predictions</dt><dd>" + n + " (" + tracked + " tracked)</dd>";
    }
    info += "</dl><div class=\"muted\">" + (CITY ? "the city map of every drive, " +
      "the city's ground truth; the drive's frames and predictions"
      : "map so far: instances first seen by this frame, final shapes") + "</div>";
    $("frameinfo").innerHTML = info;
    if (state.layers.follow && poses) {
      const p = poseAt(t);
      state.view.cx = p[0];
      state.view.cy = p[1];
    }
  }

  // ------------------------------------------------------------------ actions (the API)
  function bounds() {
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    const take = (xy) => {
      for (let k = 0; k < xy.length; k += 2) {
        const x = xy[k], y = xy[k + 1];
        if (x < x0) x0 = x; if (x > x1) x1 = x; if (y < y0) y0 = y; if (y > y1) y1 = y;
      }
    };
    take(M.xy);
    if (D.gt) take(D.gt.xy);
    if (CH) take(CH.xy);
    if (poses) take(poses.flatMap((p) => [p[0], p[1]]));
    if (!isFinite(x0)) { x0 = -50; y0 = -50; x1 = 50; y1 = 50; }
    return [x0, y0, x1, y1];
  }

  api.fit = function () {
    const [x0, y0, x1, y1] = bounds();
    const [w, h] = cssSize();
    state.view.cx = (x0 + x1) / 2;
    state.view.cy = (y0 + y1) / 2;
    state.view.scale = 0.92 * Math.min(w / Math.max(x1 - x0, 1), h / Math.max(y1 - y0, 1));
    draw();
  };
  api.setDrive = function (k) {
    if (!CITY) throw new Error("icmapperViewer.setDrive: not a city");
    k = Math.max(0, Math.min(D.drives.length - 1, Math.round(Number(k))));
    const d = D.drives[k];
    D.frames = d.frames;
    D.dets = d.dets;
    T = Math.max(1, d.frames.count);
    frameIndex = d.frames.index && d.frames.index.length ? d.frames.index : [0];
    poses = d.frames.pose;
    buildPath();
    detCache = { frame: -1, paths: null, counts: null };
    api.drive = k;
    api.numFrames = T;
    slider.max = String(T - 1);
    $("drive").value = String(k);
    state.frame = T - 1;
    showFrame();
    draw();
    return k;
  };
  api.setFrame = function (t) {
    state.frame = Math.max(0, Math.min(T - 1, Math.round(Number(t))));
    showFrame();
    draw();
    return state.frame;
  };
  api.select = function (id) {
    state.selected = id === null || id === undefined ? -1 : (indexOfId.has(id) ? indexOfId.get(id) : -1);
    showSelection();
    draw();
    return api.selected;
  };
  api.toggle = function (name, on) {
    const c = D.classes.indexOf(name);
    if (c >= 0) state.classOn[c] = !!on;
    else if (name in state.layers) state.layers[name] = !!on;
    else throw new Error("icmapperViewer.toggle: unknown layer or class " + name);
    const input = document.querySelector(c >= 0 ? 'input[data-class="' + name + '"]'
      : 'input[data-layer="' + name + '"]');
    if (input) input.checked = !!on;
    if (name === "follow" && on) showFrame();
    draw();
  };
  api.anchor = function (id) {
    const i = indexOfId.get(id);
    if (i === undefined) return null;
    const k = M.start[i] + ((M.start[i + 1] - M.start[i]) >> 1);
    return [M.xy[2 * k], M.xy[2 * k + 1]];
  };
  api.toClient = function (x, y) {
    const r = canvas.getBoundingClientRect();
    const [sx, sy] = toScreen(x, y);
    return [r.left + sx, r.top + sy];
  };
  api.zoom = function (f, cx, cy) {
    const r = canvas.getBoundingClientRect();
    const px = cx === undefined ? r.width / 2 : cx - r.left;
    const py = cy === undefined ? r.height / 2 : cy - r.top;
    const [wx, wy] = toWorld(px, py);
    state.view.scale = Math.max(1e-4, Math.min(500, state.view.scale * f));
    const [nx, ny] = toWorld(px, py);
    state.view.cx += wx - nx;
    state.view.cy += wy - ny;
    requestDraw();
  };
  api.pan = function (dx, dy) {
    state.view.cx -= dx / state.view.scale;
    state.view.cy += dy / state.view.scale;
    requestDraw();
  };
  api.redraw = draw;
  api.measure = function (n) {
    n = n || 60;
    return new Promise((resolve) => {
      const stamps = [], draws = [];
      let k = 0;
      const step = (now) => {
        stamps.push(now);
        if (k >= n) {
          const d = stamps.slice(1).map((s, j) => s - stamps[j]).sort((a, b) => a - b);
          const q = (p) => d[Math.min(d.length - 1, Math.floor(p * d.length))];
          resolve({ frames: d.length, medianMs: q(0.5), p95Ms: q(0.95),
            meanDrawMs: draws.reduce((a, b) => a + b, 0) / draws.length });
          return;
        }
        // each frame: pan, zoom in or out, and move the slider
        state.view.cx += 3 / state.view.scale;
        state.view.scale *= k % 20 < 10 ? 1.03 : 1 / 1.03;
        state.frame = (state.frame + 1) % T;
        showFrame();
        draws.push(draw());
        k++;
        requestAnimationFrame(step);
      };
      requestAnimationFrame(step);
    });
  };

  // ------------------------------------------------------------------ events
  function pick(px, py) {
    const [x, y] = toWorld(px, py);
    const tol = 6 / state.view.scale;
    let best = -1, bestD = tol;
    const seen = new Set();
    for (let gx = Math.floor((x - tol) / CELL); gx <= Math.floor((x + tol) / CELL); gx++) {
      for (let gy = Math.floor((y - tol) / CELL); gy <= Math.floor((y + tol) / CELL); gy++) {
        for (const i of grid.get(gx + "," + gy) || []) {
          if (seen.has(i)) continue;
          seen.add(i);
          if (!visibleInstance(i)) continue;
          const b = 4 * i;
          if (x < bbox[b] - tol || x > bbox[b + 2] + tol || y < bbox[b + 1] - tol ||
            y > bbox[b + 3] + tol) continue;
          const d = distToInstance(i, x, y);
          if (d < bestD) { bestD = d; best = i; }
        }
      }
    }
    return best;
  }

  function distToInstance(i, x, y) {
    const s = M.start[i], e = M.start[i + 1], xy = M.xy;
    let best = Infinity;
    const n = e - s, segs = M.closed[i] ? n : n - 1;
    if (n === 1) return Math.hypot(xy[2 * s] - x, xy[2 * s + 1] - y);
    for (let k = 0; k < segs; k++) {
      const a = s + k, b = s + ((k + 1) % n);
      const ax = xy[2 * a], ay = xy[2 * a + 1], bx = xy[2 * b], by = xy[2 * b + 1];
      const dx = bx - ax, dy = by - ay, L = dx * dx + dy * dy;
      let u = L > 0 ? ((x - ax) * dx + (y - ay) * dy) / L : 0;
      u = Math.max(0, Math.min(1, u));
      const d = Math.hypot(ax + u * dx - x, ay + u * dy - y);
      if (d < best) best = d;
    }
    return best;
  }

  let drag = null;
  canvas.addEventListener("pointerdown", (ev) => {
    drag = { x: ev.clientX, y: ev.clientY, moved: 0 };
    canvas.setPointerCapture(ev.pointerId);
  });
  canvas.addEventListener("pointermove", (ev) => {
    if (!drag) return;
    const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
    drag.moved += Math.abs(dx) + Math.abs(dy);
    drag.x = ev.clientX;
    drag.y = ev.clientY;
    if (drag.moved > 3) {
      canvas.classList.add("dragging");
      api.pan(dx, dy);
    }
  });
  canvas.addEventListener("pointerup", (ev) => {
    canvas.classList.remove("dragging");
    if (drag && drag.moved <= 3) {
      const r = canvas.getBoundingClientRect();
      state.selected = pick(ev.clientX - r.left, ev.clientY - r.top);
      showSelection();
      draw();
    }
    drag = null;
  });
  canvas.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    api.zoom(Math.exp(-ev.deltaY * 0.0015), ev.clientX, ev.clientY);
  }, { passive: false });
  slider.addEventListener("input", () => api.setFrame(slider.value));
  $("fit").addEventListener("click", () => api.fit());
  $("play").addEventListener("click", () => {
    if (state.playing) {
      clearInterval(state.playing);
      state.playing = null;
      $("play").innerHTML = "&#9654;";
      return;
    }
    if (state.frame >= T - 1) api.setFrame(0);
    $("play").innerHTML = "&#10074;&#10074;";
    state.playing = setInterval(() => {
      if (state.frame >= T - 1) { $("play").click(); return; }
      api.setFrame(state.frame + 1);
    }, 500);
  });
  document.addEventListener("keydown", (ev) => {
    if (ev.target && ev.target.tagName === "INPUT" && ev.target.type !== "checkbox") return;
    if (ev.target && ev.target.tagName === "SELECT") return;
    if (ev.key === "ArrowRight") api.setFrame(state.frame + 1);
    else if (ev.key === "ArrowLeft") api.setFrame(state.frame - 1);
    else if (ev.key === "f") api.fit();
  });
  new ResizeObserver(() => requestDraw()).observe(canvas);

  function buildDrives() {
    const sel = $("drive");
    if (!CITY) return;
    D.drives.forEach((d, k) => {
      const opt = document.createElement("option");
      opt.value = String(k);
      opt.textContent = "drive " + d.index + ": " + d.name + " (" + d.frames.count + " frames)";
      sel.appendChild(opt);
    });
    sel.hidden = false;
    sel.addEventListener("change", () => api.setDrive(sel.value));
  }

  // ------------------------------------------------------------------ start
  buildDrives();
  buildLayers();
  buildMetrics();
  buildCameras();
  showSelection();
  showFrame();
  api.fit();
  api.ready = true;
})();
