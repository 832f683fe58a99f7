// The built-in map viewer: a client of irs-planner's public HTTP API, like any user's script.
// It draws the map on a canvas (viridis colours, axes in metres, a colour bar in the map's unit,
// obstacles, APs, IRSs and SRUs) with zoom and pan, dims cells below the threshold, asks the API
// for coverage, paths and sweeps, follows jobs (map builds, placements), lets the user move,
// add and remove devices on the map (each edit registers the scenario and rebuilds the map),
// ranks placements and applies one, compares two maps, and imports a ROS map. No framework, no
// build step: every number shown comes from the API.
"use strict";

const $ = (id) => document.getElementById(id);

// Viridis at 5 stops, interpolated into a 256-entry table (the PNG renderer uses the same stops).
const STOPS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
const table = (stops) =>
  Array.from({ length: 256 }, (_, k) => {
    const x = (k / 255) * (stops.length - 1);
    const i = Math.min(Math.floor(x), stops.length - 2);
    const f = x - i;
    return stops[i].map((c, n) => Math.round(c * (1 - f) + stops[i + 1][n] * f));
  });
const VIRIDIS = table(STOPS);
// Differences: blue (the other map is better) through white (equal) to red (this one is).
const DIVERGING = table([[33, 102, 172], [146, 197, 222], [247, 247, 247], [244, 165, 130], [178, 24, 43]]);
// Serving APs: one colour each (up to the 8 APs a scenario may have).
const CATEGORICAL = [[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189], [140, 86, 75], [227, 119, 194], [188, 189, 34]];
// Cells below the threshold keep 30 % of their colour, as in the PNG.
const DIM = 0.3;
// Margins around the plot (px): tick labels left and below, the colour bar right; narrower on
// a phone, where every pixel of width is the map's.
const margins = (width) => (width < 520 ? { left: 40, top: 24, right: 76, bottom: 40 } : { left: 58, top: 24, right: 96, bottom: 44 });
// Largest zoom: a cell at most this many pixels.
const MAX_CELL_PX = 96;
// Pointer travel (px) below which a press is a click, not a drag.
const CLICK_SLOP_PX = 4;

const state = {
  scenarioId: null,
  scenario: null, // the scenario document (obstacles, APs, IRSs, SRUs)
  scenarioName: "",
  map: null, // GET /v1/maps/{id}[?unit=]
  unit: "", // the query unit ("" = the map's own)
  job: null, // the job building the requested map
  building: false, // a new map is on its way: the one shown is stale
  threshold: null,
  start: null,
  goal: null,
  path: null, // POST /v1/paths answer
  layer: "value",
  compare: null, // { label, map } the difference layer subtracts
  history: [], // maps shown this session: { mapId, label }
  view: { zoom: 1, cc: null, rc: null }, // zoom and the image point (columns, rows) at the plot's centre
  layout: null,
  cursor: null, // the keyboard's cell [i, j]
  selected: null, // { kind, index } of a device
  adding: null, // "ap" | "irs" | "sru": the next click places one
  drag: null, // a device being dragged: { kind, index, x, y }
  candidates: [], // placement answer's candidates
  image: null, // the rendered cells (an offscreen canvas, one pixel per cell) and what it shows
  layerCache: null, // what the cells show (values, gap, serving AP or difference) and its key
  request: 0, // the latest map request: an answer to an earlier one is dropped
};

// ------------------------------------------------------------------ API

async function api(method, path, body) {
  const init = { method, headers: {} };
  const token = $("token").value.trim();
  if (token) init.headers.authorization = `Bearer ${token}`;
  if (body !== undefined) {
    init.headers["content-type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const response = await fetch(path, init);
  const text = await response.text();
  let data = null;
  try {
    data = text ? JSON.parse(text) : null;
  } catch {
    data = null;
  }
  if (!response.ok) {
    const problem = data || {};
    const error = new Error(`${problem.title || response.status}${problem.field ? ` (${problem.field})` : ""}: ${problem.detail || text}`);
    error.field = problem.field;
    error.status = response.status;
    throw error;
  }
  return { status: response.status, data };
}

// Polls a job until it ends; `onProgress(job)` sees each state. Returns the last view.
async function waitJob(job, onProgress) {
  let current = job;
  for (;;) {
    onProgress(current);
    if (["done", "failed", "cancelled"].includes(current.state)) return current;
    await new Promise((resolve) => setTimeout(resolve, 250));
    current = (await api("GET", `/v1/jobs/${current.job_id}`)).data;
  }
}

// A download link is a plain GET, which carries no header: with tokens on, a map is its
// tenants' only (anybody else gets 404), so with a token set the file is fetched with it and
// handed to the browser as a blob.
async function downloadWithToken(event) {
  const token = $("token").value.trim();
  const link = event.currentTarget;
  if (!token || !link.href || link.href.startsWith("blob:")) return;
  event.preventDefault();
  try {
    const response = await fetch(link.href, { headers: { authorization: `Bearer ${token}` } });
    if (!response.ok) {
      const problem = await response.json().catch(() => ({}));
      throw new Error(`${problem.title || response.status}: ${problem.detail || ""}`);
    }
    saveBlob(await response.blob(), link.download);
  } catch (error) {
    say(`Download failed: ${error.message}`, true);
  }
}

function saveBlob(blob, name) {
  const url = URL.createObjectURL(blob);
  const save = document.createElement("a");
  save.href = url;
  save.download = name;
  document.body.appendChild(save);
  save.click();
  save.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10_000);
}

// A link that downloads `text` (replacing the object URL it held).
function linkBlob(id, text, type) {
  const link = $(id);
  if (link.href.startsWith("blob:")) URL.revokeObjectURL(link.href);
  link.href = URL.createObjectURL(new Blob([text], { type }));
}

function say(message, isError = false) {
  const status = $("status");
  status.textContent = message;
  status.classList.toggle("error", isError);
}

// A message next to an input (empty clears it); the input is marked invalid meanwhile.
function fieldError(inputId, message) {
  const input = $(inputId);
  const note = $(`${inputId}-error`);
  if (note) note.textContent = message || "";
  if (message) input.setAttribute("aria-invalid", "true");
  else input.removeAttribute("aria-invalid");
}

// ------------------------------------------------------------------ scenarios

async function loadScenarios(select) {
  await loadScenarioList(select);
  await chooseScenario($("scenario").value);
}

// Lists every scenario (all pages, in name order) in the selector, `select` (or the paper's
// single-user floor) chosen; the caller shows it.
async function loadScenarioList(select) {
  const scenarios = [];
  let cursor = null;
  do {
    const query = cursor ? `?limit=1000&cursor=${encodeURIComponent(cursor)}` : "?limit=1000";
    const { data } = await api("GET", `/v1/scenarios${query}`);
    scenarios.push(...data.scenarios);
    cursor = data.next_cursor;
  } while (cursor);
  scenarios.sort((a, b) => (a.name || "").localeCompare(b.name || "") || a.id.localeCompare(b.id));
  const list = $("scenario");
  list.replaceChildren(
    ...scenarios.map((s) => new Option(`${s.name || "(unnamed)"} — ${s.id.slice(0, 8)}`, s.id)),
  );
  const preferred = select || scenarios.find((s) => s.name === "paper-single-user")?.id;
  if (preferred) list.value = preferred;
}

async function chooseScenario(id, { keepPath = false } = {}) {
  if (!id) return;
  const { data } = await api("GET", `/v1/scenarios/${id}`);
  state.scenarioId = id;
  state.scenario = data.scenario;
  state.scenarioName = data.scenario.name || id.slice(0, 8);
  $("scenario").value = id;
  const hasIrs = surfaces().length > 0;
  $("phases").value = hasIrs ? ($("phases").value === "none" ? "continuous" : $("phases").value) : "none";
  for (const option of $("phases").options) option.disabled = !hasIrs && option.value !== "none";
  const hasSrus = (data.scenario.srus || []).length > 0;
  $("kind").options[1].disabled = !hasSrus || accessPoints().length > 1;
  if ($("kind").options[1].disabled) $("kind").value = "gain";
  state.selected = null;
  state.candidates = [];
  $("candidates").replaceChildren();
  showSelection();
  linkBlob("download-scenario", JSON.stringify(state.scenario, null, 2), "application/json");
  $("download-scenario").download = `${state.scenarioName.replace(/[^\w.-]+/g, "_")}.json`;
  if (!keepPath) clearPath();
  await buildMap();
}

async function registerScenario() {
  let text = $("scenario-json").value.trim();
  const file = $("scenario-file").files[0];
  if (!text && file) text = await file.text();
  if (!text) return say("Paste a scenario or choose a file first.", true);
  let document;
  try {
    document = JSON.parse(text);
  } catch (e) {
    return say(`Not JSON: ${e.message}`, true);
  }
  const { data } = await api("POST", "/v1/scenarios", document);
  say(`Registered scenario ${data.id}.`);
  await loadScenarios(data.id);
}

// The scenario's devices in canonical lists (a single one is written `ap`/`irs`).
const accessPoints = (s = state.scenario) => (s.ap ? [s.ap] : s.aps || []);
const surfaces = (s = state.scenario) => (s.irs ? [s.irs] : s.irss || []);

// A copy of the scenario with its device lists replaced (one device written singly, as the
// built-in scenarios are; several as `aps`/`irss`).
function withDevices(aps, irss, srus) {
  const doc = structuredClone(state.scenario);
  delete doc.ap;
  delete doc.aps;
  delete doc.irs;
  delete doc.irss;
  if (aps.length === 1) doc.ap = aps[0];
  else doc.aps = aps;
  if (irss.length === 1) doc.irs = irss[0];
  else if (irss.length > 1) doc.irss = irss;
  if (srus.length) doc.srus = srus;
  else delete doc.srus;
  const base = (state.scenario.name || "scenario").replace(/ \(edited\)$/, "");
  doc.name = `${base} (edited)`;
  return doc;
}

// Registers an edited scenario and shows it (its map rebuilt); the path's ends are kept.
async function applyScenario(doc, what) {
  const started = performance.now();
  const data = await registerMounting(doc);
  await loadScenarioList(data.id);
  await chooseScenario(data.id, { keepPath: true });
  if (state.start && state.goal) await planPath();
  $("map").dataset.editMs = String(Math.round(performance.now() - started));
  say(`${what}: scenario ${data.id.slice(0, 8)} registered and its map shown.`);
}

// Registers `doc`. A surface with `mount_within_m` is mounted by the service on the nearest
// face that faces the way its normal does; where none does (a floor plan's walls face
// anywhere), the other three axis directions are tried in turn.
async function registerMounting(doc) {
  const tried = new Map();
  for (;;) {
    try {
      return (await api("POST", "/v1/scenarios", doc)).data;
    } catch (error) {
      const m = /^(irs|irss\[(\d+)\])\.mount_within_m$/.exec(error.field || "");
      if (!m) throw error;
      const irs = m[2] === undefined ? doc.irs : doc.irss[Number(m[2])];
      const seen = tried.get(irs) || [];
      seen.push(irs.normal.join());
      tried.set(irs, seen);
      const next = [[0, 1, 0], [-1, 0, 0], [0, -1, 0], [1, 0, 0]].find((n) => !seen.includes(n.join()));
      if (!next) throw error;
      irs.normal = next;
    }
  }
}

// ------------------------------------------------------------------ editing devices

// The wall faces an IRS can hang on: the room's walls (facing in) and the faces of obstacles
// at least as tall as the surface (facing out), as segments with their normals.
function wallFaces(z) {
  const r = state.scenario.room;
  const faces = [
    { a: [r.x_min, r.y_min], b: [r.x_max, r.y_min], n: [0, 1] },
    { a: [r.x_min, r.y_max], b: [r.x_max, r.y_max], n: [0, -1] },
    { a: [r.x_min, r.y_min], b: [r.x_min, r.y_max], n: [1, 0] },
    { a: [r.x_max, r.y_min], b: [r.x_max, r.y_max], n: [-1, 0] },
  ];
  for (const o of state.scenario.obstacles || []) {
    if ((o.height_m ?? Infinity) < z) continue;
    const [cx, cy] = o.center;
    const [hx, hy] = [o.size[0] / 2, o.size[1] / 2];
    faces.push(
      { a: [cx - hx, cy - hy], b: [cx + hx, cy - hy], n: [0, -1] },
      { a: [cx - hx, cy + hy], b: [cx + hx, cy + hy], n: [0, 1] },
      { a: [cx - hx, cy - hy], b: [cx - hx, cy + hy], n: [-1, 0] },
      { a: [cx + hx, cy - hy], b: [cx + hx, cy + hy], n: [1, 0] },
    );
  }
  return faces;
}

// The nearest point of a wall face to (x, y), and the face's normal.
function snapToWall(x, y, z) {
  let best = null;
  for (const f of wallFaces(z)) {
    const [dx, dy] = [f.b[0] - f.a[0], f.b[1] - f.a[1]];
    const t = Math.min(1, Math.max(0, ((x - f.a[0]) * dx + (y - f.a[1]) * dy) / (dx * dx + dy * dy)));
    const p = [f.a[0] + t * dx, f.a[1] + t * dy];
    const d = Math.hypot(p[0] - x, p[1] - y);
    if (!best || d < best.d) best = { d, p, n: f.n };
  }
  return { center: [round6(best.p[0]), round6(best.p[1]), z], normal: [best.n[0], best.n[1], 0] };
}

const round6 = (v) => +v.toFixed(6);

// Moves (or, with index null, adds) a device to (x, y) and registers the result.
async function placeDevice(kind, index, x, y) {
  const aps = structuredClone(accessPoints());
  const irss = structuredClone(surfaces());
  const srus = structuredClone(state.scenario.srus || []);
  const adding = index === null;
  if (kind === "ap") {
    const template = aps[0] || { tx_power_dbm: 20, noise_dbm: -90, carrier_ghz: 2, position: [0, 0, 2] };
    const ap = adding ? structuredClone(template) : aps[index];
    ap.position = [round6(x), round6(y), ap.position[2]];
    if (adding) aps.push(ap);
  } else if (kind === "irs") {
    const template = irss[0] || { center: [0, 0, 2], normal: [0, 1, 0], nx_sub: 10, nz_sub: 6, elements_per_sub: 20, sub_pitch_m: 0.0075, grouping: "coherent" };
    const irs = adding ? structuredClone(template) : irss[index];
    Object.assign(irs, snapToWall(x, y, irs.center[2]));
    // On a floor plan the walls are pixels the viewer does not know: the service mounts the
    // surface on the nearest face (the room's and the boxes' faces are exact already).
    if (state.scenario.floor_plan) Object.assign(irs, { center: [round6(x), round6(y), irs.center[2]], mount_within_m: 5 });
    if (adding) irss.push(irs);
  } else {
    const template = srus[0] || { position: [0, 0, 1], min_rate_bps_hz: 1 };
    const sru = adding ? structuredClone(template) : srus[index];
    sru.position = [round6(x), round6(y), sru.position[2]];
    if (adding) srus.push(sru);
  }
  const name = { ap: "AP", irs: "IRS", sru: "SRU" }[kind];
  await applyScenario(withDevices(aps, irss, srus), adding ? `${name} added` : `${name} ${index} moved`);
}

async function removeSelected() {
  if (!state.selected) return;
  const { kind, index } = state.selected;
  const aps = structuredClone(accessPoints());
  const irss = structuredClone(surfaces());
  const srus = structuredClone(state.scenario.srus || []);
  const list = { ap: aps, irs: irss, sru: srus }[kind];
  if (kind === "ap" && aps.length === 1) throw new Error("A scenario needs an AP: add another before removing this one.");
  list.splice(index, 1);
  state.selected = null;
  await applyScenario(withDevices(aps, irss, srus), `${kind.toUpperCase()} ${index} removed`);
}

function showSelection() {
  const s = state.selected;
  $("remove").disabled = !s;
  $("selected").textContent = s ? `Selected: ${s.kind.toUpperCase()} ${s.index} (Delete removes it).` : "Nothing selected (click a device).";
  draw();
}

// Every device as a point on the map.
function devices() {
  if (!state.scenario) return [];
  const out = [];
  accessPoints().forEach((ap, index) => out.push({ kind: "ap", index, x: ap.position[0], y: ap.position[1] }));
  surfaces().forEach((irs, index) => out.push({ kind: "irs", index, x: irs.center[0], y: irs.center[1] }));
  (state.scenario.srus || []).forEach((sru, index) => out.push({ kind: "sru", index, x: sru.position[0], y: sru.position[1] }));
  return out;
}

function deviceAt(px, py) {
  let best = null;
  for (const d of devices()) {
    const [dx, dy] = toPixel(d.x, d.y);
    const dist = Math.hypot(dx - px, dy - py);
    if (dist <= markerRadius() + 4 && (!best || dist < best.dist)) best = { ...d, dist };
  }
  return best;
}

// ------------------------------------------------------------------ ROS map import

// The map_server keys a map.yaml holds (image, resolution, origin, negate, occupied_thresh,
// free_thresh, mode), read as the flat `key: value` lines map_server writes; anything nested
// is refused with the line named.
function readMapYaml(text) {
  const out = {};
  text.split(/\r?\n/).forEach((raw, k) => {
    const line = raw.replace(/\s+#.*$/, "").trim();
    if (!line || line.startsWith("#")) return;
    const m = /^([A-Za-z_]+)\s*:\s*(.*)$/.exec(line);
    if (!m) throw new Error(`map.yaml line ${k + 1}: expected "key: value", got ${JSON.stringify(raw)}`);
    let value = m[2].trim().replace(/^["']|["']$/g, "");
    if (value.startsWith("[")) {
      value = value.replace(/[[\]]/g, "").split(",").map((v) => Number(v.trim()));
      if (!value.every(Number.isFinite)) throw new Error(`map.yaml line ${k + 1}: ${m[1]} must be numbers`);
    } else if (m[1] !== "image" && m[1] !== "mode") {
      const n = Number(value);
      value = value === "true" ? 1 : value === "false" ? 0 : n;
      if (!Number.isFinite(value)) throw new Error(`map.yaml line ${k + 1}: ${m[1]} must be a number`);
    }
    out[m[1]] = value;
  });
  for (const key of ["image", "resolution", "origin"]) {
    if (out[key] === undefined) throw new Error(`map.yaml: ${key} is missing`);
  }
  return out;
}

// The grey pixels of a PGM (P2/P5, 8-bit) or PNG image, row 0 the top, as map_server reads
// them: { width, height, grey }.
async function greyPixels(bytes, file) {
  if (bytes[0] === 0x89 && bytes[1] === 0x50) {
    const bitmap = await createImageBitmap(file);
    const canvas = Object.assign(document.createElement("canvas"), { width: bitmap.width, height: bitmap.height });
    const ctx = canvas.getContext("2d");
    ctx.drawImage(bitmap, 0, 0);
    const rgba = ctx.getImageData(0, 0, bitmap.width, bitmap.height).data;
    const grey = new Uint8Array(bitmap.width * bitmap.height);
    for (let k = 0; k < grey.length; k++) grey[k] = rgba[4 * k];
    return { width: bitmap.width, height: bitmap.height, grey };
  }
  // The header: magic, width, height, maxval, each after whitespace and comments.
  let at = 0;
  const token = () => {
    for (;;) {
      while (at < bytes.length && /\s/.test(String.fromCharCode(bytes[at]))) at++;
      if (bytes[at] !== 0x23) break;
      while (at < bytes.length && bytes[at] !== 0x0a) at++;
    }
    const from = at;
    while (at < bytes.length && !/\s/.test(String.fromCharCode(bytes[at]))) at++;
    return new TextDecoder("latin1").decode(bytes.subarray(from, at));
  };
  const magic = token();
  if (magic !== "P5" && magic !== "P2") throw new Error("the image is neither a PGM (P2/P5) nor a PNG");
  const [width, height, maxval] = [token(), token(), token()].map(Number);
  if (!(width > 0 && height > 0 && maxval > 0 && maxval < 256)) throw new Error("the PGM's header is not that of an 8-bit image");
  const grey = new Uint8Array(width * height);
  if (magic === "P5") {
    if (bytes.length < at + 1 + grey.length) throw new Error(`the PGM holds ${bytes.length - at - 1} of its ${grey.length} pixels`);
    grey.set(bytes.subarray(at + 1, at + 1 + grey.length));
  } else {
    for (let k = 0; k < grey.length; k++) grey[k] = Number(token());
  }
  if (maxval !== 255) for (let k = 0; k < grey.length; k++) grey[k] = Math.round((grey[k] * 255) / maxval);
  return { width, height, grey };
}

function base64(bytes) {
  let text = "";
  for (let k = 0; k < bytes.length; k += 0x8000) text += String.fromCharCode(...bytes.subarray(k, k + 0x8000));
  return btoa(text);
}

// Where a device can stand on a ROS map: free pixels (Nav2's reading: occ = (255 − p)/255, or
// p/255 negated, free below free_thresh; `raw` maps are free where the value is 0) with free
// pixels within `clearance` all around (so the service's own occupancy, which inflates cells by
// the robot's radius, finds the place free too). One pass along rows and one along columns.
function standingMask(image, meta, clearance) {
  const { width, height, grey } = image;
  const freeBelow = meta.free_thresh ?? 0.196;
  const free = new Uint8Array(width * height);
  for (let k = 0; k < free.length; k++) {
    const p = grey[k];
    free[k] = meta.mode === "raw" ? p === 0 : (meta.negate ? p / 255 : 1 - p / 255) < freeBelow;
  }
  // A pixel is kept when the window of ±clearance around it, along a row, then along a column,
  // lies inside the image and holds no blocked pixel: prefix counts of blocked pixels per line.
  const pass = (src, length, lines, at) => {
    const out = new Uint8Array(src.length);
    const blocked = new Int32Array(length + 1);
    for (let line = 0; line < lines; line++) {
      for (let k = 0; k < length; k++) blocked[k + 1] = blocked[k] + (src[at(line, k)] ? 0 : 1);
      for (let k = clearance; k < length - clearance; k++) {
        out[at(line, k)] = blocked[k + clearance + 1] === blocked[k - clearance] ? 1 : 0;
      }
    }
    return out;
  };
  const rows = pass(free, width, height, (v, u) => v * width + u);
  return pass(rows, height, width, (u, v) => v * width + u);
}

// The standing pixel nearest (x, y) in metres (Euclidean), as the point at its centre.
function nearestFree(image, meta, mask, x, y) {
  const { width, height } = image;
  const [ox, oy] = meta.origin;
  const u0 = Math.floor((x - ox) / meta.resolution);
  const v0 = height - 1 - Math.floor((y - oy) / meta.resolution);
  let best = null;
  // Square rings outwards; once one holds a candidate at distance d, rings up to d still may
  // hold a nearer one (a ring r is at least r away).
  for (let ring = 0; ring < Math.max(width, height) && (!best || ring <= best.d); ring++) {
    for (let du = -ring; du <= ring; du++) {
      for (const dv of Math.abs(du) === ring ? range(-ring, ring) : [-ring, ring]) {
        const [u, v] = [u0 + du, v0 + dv];
        if (u < 0 || v < 0 || u >= width || v >= height || !mask[v * width + u]) continue;
        const d = Math.hypot(du, dv);
        if (!best || d < best.d) best = { d, u, v };
      }
    }
  }
  if (!best) throw new Error("the map has no free space to put a device in");
  return [round6(ox + (best.u + 0.5) * meta.resolution), round6(oy + (height - best.v - 0.5) * meta.resolution)];
}

const range = (a, b) => Array.from({ length: b - a + 1 }, (_, k) => a + k);

// A new scenario on the ROS map: the room is the map's extent, the grid and channel this
// scenario's; its devices keep their place relative to the room, each AP and SRU moved to the
// nearest free space and each IRS mounted by the service on the nearest wall face.
async function importRosMap(files) {
  fieldError("ros-files", "");
  const list = Array.from(files);
  const yamlFile = list.find((f) => /\.ya?ml$/i.test(f.name));
  if (!yamlFile) throw Object.assign(new Error("Choose the map.yaml too."), { input: "ros-files" });
  const meta = readMapYaml(await yamlFile.text());
  const wanted = String(meta.image).split(/[\\/]/).pop();
  const imageFile = list.find((f) => f.name === wanted) || list.find((f) => f !== yamlFile);
  if (!imageFile) throw Object.assign(new Error(`Choose the image map.yaml names (${wanted}) too.`), { input: "ros-files" });
  say(`Reading ${imageFile.name}…`);
  const bytes = new Uint8Array(await imageFile.arrayBuffer());
  const image = await greyPixels(bytes, imageFile);
  const [ox, oy] = meta.origin;
  const old = state.scenario.room;
  const room = {
    x_min: ox, x_max: round6(ox + image.width * meta.resolution),
    y_min: oy, y_max: round6(oy + image.height * meta.resolution),
    ceiling_m: old.ceiling_m,
  };
  const floorPlan = { image: base64(bytes), resolution: meta.resolution, origin: meta.origin };
  for (const key of ["negate", "occupied_thresh", "free_thresh", "mode"]) {
    if (meta[key] !== undefined) floorPlan[key] = meta[key];
  }
  const scale = ([x, y]) => [
    room.x_min + ((x - old.x_min) / (old.x_max - old.x_min)) * (room.x_max - room.x_min),
    room.y_min + ((y - old.y_min) / (old.y_max - old.y_min)) * (room.y_max - room.y_min),
  ];
  const previous = state.scenario;
  const doc = structuredClone(previous);
  doc.room = room;
  doc.floor_plan = floorPlan;
  delete doc.obstacles;
  delete doc.walls;
  delete doc.route_graph;
  state.scenario = doc;
  try {
    // Clear by the robot's radius and half a cell, at least a pixel.
    const clearance = Math.max(1, Math.ceil(((previous.mru?.radius_m ?? 0) + previous.grid.resolution_m / 2) / meta.resolution));
    const mask = standingMask(image, meta, Math.min(clearance, 64));
    const free = (p) => [...nearestFree(image, meta, mask, ...scale(p)), p[2]];
    const aps = accessPoints(previous).map((ap) => ({ ...ap, position: free(ap.position) }));
    const srus = (previous.srus || []).map((sru) => ({ ...sru, position: free(sru.position) }));
    const irss = surfaces(previous).map((irs) => {
      const [x, y] = scale(irs.center);
      const { normal } = snapToWall(x, y, irs.center[2]);
      return { ...irs, center: [round6(x), round6(y), irs.center[2]], normal, mount_within_m: 5 };
    });
    const edited = withDevices(aps, irss, srus);
    edited.name = `${imageFile.name.replace(/\.\w+$/, "")} (imported)`;
    state.scenario = previous;
    await applyScenario(edited, `ROS map ${imageFile.name} imported (${image.width} × ${image.height} px)`);
  } finally {
    state.scenario = state.scenario === doc ? previous : state.scenario;
  }
}

// ------------------------------------------------------------------ maps and jobs

function mapRequest(phases = $("phases").value) {
  const kind = $("kind").value;
  const request = {
    scenario_id: state.scenarioId,
    kind,
    phases: /^\d+$/.test(phases) ? Number(phases) : phases,
  };
  if (kind === "rate") request.access = $("access").value;
  return request;
}

function setBuilding(building) {
  state.building = building;
  $("map").dataset.stale = building ? "1" : "0";
  draw();
}

async function buildMap() {
  if (!state.scenarioId) return;
  $("access").disabled = $("kind").value !== "rate";
  say("Requesting the map…");
  const request = ++state.request;
  // A build still followed is superseded: its map is not this request's.
  state.job = null;
  $("job").hidden = true;
  setBuilding(true);
  try {
    const { status, data } = await api("POST", "/v1/maps", mapRequest());
    if (request !== state.request) return;
    if (status === 202) {
      state.job = data;
      await followJob(request);
    } else {
      await showMap(data.map_id);
    }
  } finally {
    if (request === state.request && !state.job) setBuilding(false);
  }
}

async function followJob(request) {
  $("job").hidden = false;
  const mine = state.job;
  const current = () => request === state.request && state.job && state.job.job_id === mine.job_id;
  try {
    const job = await waitJob(mine, (job) => {
      if (!current()) return;
      state.job = job;
      $("job-progress").value = job.progress;
      $("job-text").textContent = `${job.cells_done} / ${job.cells_total} cells (${job.state})`;
    });
    if (!current()) return;
    state.job = null;
    if (job.state === "done") return showMap(job.map_id);
    setBuilding(false);
    say(`The build ${job.state}${job.error ? ": " + job.error : ""}.`, job.state === "failed");
  } finally {
    if (request === state.request && !state.job) $("job").hidden = true;
  }
}

async function cancelJob() {
  if (!state.job) return;
  const { data } = await api("DELETE", `/v1/jobs/${state.job.job_id}`);
  state.job = data;
  say("Cancelling the build…");
}

const unitQuery = () => (state.unit ? `?unit=${encodeURIComponent(state.unit)}` : "");

async function showMap(mapId) {
  let data;
  try {
    ({ data } = await api("GET", `/v1/maps/${mapId}${unitQuery()}`));
    fieldError("unit", "");
  } catch (error) {
    if (error.field !== "unit") throw error;
    // This map has no such unit (a rate map in dBm, Mbit/s without a bandwidth): its own.
    fieldError("unit", `${$("unit").selectedOptions[0].text}: ${error.message.replace(/^.*?: /, "")}`);
    state.unit = "";
    $("unit").value = "";
    ({ data } = await api("GET", `/v1/maps/${mapId}`));
  }
  const sameGrid = state.map && sameGrids(state.map.grid, data.grid);
  state.map = data;
  state.image = null;
  state.layerCache = null;
  // The comparison is fetched again for this map (its unit, its grid) below.
  state.compare = null;
  if (state.layer === "difference") state.layer = "value";
  setBuilding(false);
  if (!sameGrid) fitView();
  for (const option of $("unit").options) {
    option.disabled = data.key.kind === "rate" && !["", "bps_hz", "mbps"].includes(option.value);
  }
  // A map with no value anywhere (a rate map whose SRUs no cell serves) still shows.
  const min = data.stats.min ?? 0;
  const max = data.stats.max ?? 1;
  const range = $("threshold-range");
  range.min = Math.floor(min * 10) / 10;
  range.max = Math.ceil(max * 10) / 10;
  const keep = state.threshold !== null && state.threshold >= range.min && state.threshold <= range.max;
  setThreshold(keep ? state.threshold : Math.round(((min + max) / 2) * 10) / 10, false);
  document.querySelectorAll(".unit").forEach((el) => (el.textContent = data.unit));
  $("layer-gap").disabled = !data.upper_bound;
  $("layer-serving").disabled = !data.serving_ap;
  if ((state.layer === "gap" && !data.upper_bound) || (state.layer === "serving" && !data.serving_ap)) setLayer("value");
  $("map").setAttribute(
    "aria-label",
    `${data.key.kind} map of ${data.grid.nx} × ${data.grid.ny} cells, ${min.toFixed(2)} to ${max.toFixed(2)} ${data.unit}`,
  );
  $("download-map").href = `/v1/maps/${mapId}${unitQuery()}`;
  $("download-map").download = `map-${mapId}.json`;
  const label = `${state.scenarioName} · ${data.key.kind} · ${data.key.phases}`;
  if (!state.history.some((h) => h.mapId === mapId)) state.history.push({ mapId, label });
  updateCompareOptions();
  if ($("compare").value) await refreshComparison();
  else $("layer-difference").disabled = true;
  say(`Map ${mapId.slice(0, 8)}: ${data.stats.valued_cells} cells with a value, built in the API's cache.`);
  await refresh();
}

const sameGrids = (a, b) =>
  a.nx === b.nx && a.ny === b.ny && a.x_min === b.x_min && a.y_min === b.y_min && a.resolution_m === b.resolution_m;

// ------------------------------------------------------------------ comparison

function updateCompareOptions() {
  const select = $("compare");
  const chosen = select.value;
  const options = [new Option("nothing", ""), new Option("this scenario without IRS", "no-irs")];
  for (const h of state.history) {
    if (state.map && h.mapId === state.map.map_id) continue;
    options.push(new Option(`${h.label} — ${h.mapId.slice(0, 8)}`, h.mapId));
  }
  select.replaceChildren(...options);
  select.value = [...select.options].some((o) => o.value === chosen) ? chosen : "";
}

// The map the difference layer subtracts, fetched in this map's unit on this map's grid.
async function refreshComparison() {
  const choice = $("compare").value;
  fieldError("compare", "");
  const drop = (message) => {
    state.compare = null;
    state.layerCache = null;
    $("layer-difference").disabled = true;
    if (state.layer === "difference") setLayer("value");
    if (message) fieldError("compare", message);
  };
  if (!choice) return drop();
  let mapId = choice;
  let label = $("compare").selectedOptions[0].text;
  if (choice === "no-irs") {
    if (state.map.key.kind !== "gain") return drop("Without IRS compares gain maps: show a gain map first.");
    try {
      const { status, data } = await api("POST", "/v1/maps", mapRequest("none"));
      if (status === 202) {
        const job = await waitJob(data, () => {});
        if (job.state !== "done") return drop(`The map without IRS ${job.state}.`);
        mapId = job.map_id;
      } else {
        mapId = data.map_id;
      }
    } catch (error) {
      return drop(error.message);
    }
    label = "without IRS";
  }
  let other;
  try {
    other = (await api("GET", `/v1/maps/${mapId}${unitQuery()}`)).data;
  } catch (error) {
    return drop(error.message);
  }
  if (!sameGrids(other.grid, state.map.grid)) return drop("That map has another grid: only maps of one floor and grid compare.");
  if (other.unit !== state.map.unit) return drop(`That map is in ${other.unit}, this one in ${state.map.unit}: only maps of one unit compare.`);
  state.compare = { label, map: other };
  state.image = null;
  state.layerCache = null;
  $("layer-difference").disabled = false;
  setLayer("difference");
  say(`Difference: this map − ${label} (${other.unit}).`);
}

// ------------------------------------------------------------------ threshold, coverage, paths

let coverageTimer = null;
function setThreshold(value, replan = true) {
  state.threshold = value;
  $("threshold-range").value = value;
  $("threshold").value = value;
  fieldError("threshold", "");
  state.image = null;
  draw();
  clearTimeout(coverageTimer);
  coverageTimer = setTimeout(() => {
    updateCoverage().catch(report);
    if (replan && state.start && state.goal) planPath().catch(report);
  }, 150);
  updateDownloads();
}

async function updateCoverage() {
  if (!state.map) return;
  const unit = state.unit ? `&unit=${encodeURIComponent(state.unit)}` : "";
  const { data } = await api(
    "GET",
    `/v1/maps/${state.map.map_id}/coverage?threshold=${encodeURIComponent(state.threshold)}${unit}`,
  );
  $("coverage").textContent = `${(100 * data.coverage).toFixed(1)} % (${data.covered_cells} of ${data.free_cells} free cells)`;
}

// "x,y" in metres, or an error saying what is wrong.
function parsePoint(text, field) {
  const parts = text.split(",").map((t) => t.trim());
  const numbers = parts.map(Number);
  if (parts.length !== 2 || parts.some((p) => p === "") || !numbers.every(Number.isFinite)) {
    throw Object.assign(new Error(`${field}: write x,y in metres, e.g. -10,0`), { input: field.toLowerCase() });
  }
  const r = state.scenario.room;
  if (numbers[0] < r.x_min || numbers[0] > r.x_max || numbers[1] < r.y_min || numbers[1] > r.y_max) {
    throw Object.assign(new Error(`${field}: (${numbers}) lies outside the room (x ${r.x_min}…${r.x_max}, y ${r.y_min}…${r.y_max})`), { input: field.toLowerCase() });
  }
  return numbers;
}

function formatPoint(p) {
  return `${+p[0].toFixed(3)},${+p[1].toFixed(3)}`;
}

function pathQuery(threshold) {
  const query = {
    map_id: state.map.map_id,
    start: state.start,
    goal: state.goal,
    threshold,
    path_shape: $("path-shape").value,
  };
  if (state.unit) query.unit = state.unit;
  return query;
}

async function planPath(threshold = state.threshold) {
  if (!state.map || !state.start || !state.goal) return;
  const { data } = await api("POST", "/v1/paths", pathQuery(threshold));
  showPath(data);
}

// "Largest feasible": the threshold set to the largest a path between the ends meets.
async function largestFeasible() {
  if (!state.start || !state.goal) throw new Error("Set a start and a goal first (click the map twice).");
  const { data } = await api("POST", "/v1/paths", pathQuery("max"));
  if (data.max_feasible_threshold === null) return showPath(data);
  const widest = data.max_feasible_threshold;
  state.threshold = widest;
  $("threshold-range").value = widest;
  $("threshold").value = widest;
  fieldError("threshold", "");
  state.image = null;
  showPath(data);
  updateCoverage().catch(report);
}

function showPath(data) {
  state.path = data;
  const set = (id, text, value) => {
    $(id).textContent = text;
    if (value === undefined || value === null) $(id).removeAttribute("data-value");
    else $(id).dataset.value = value;
  };
  set("feasible", data.feasible ? "yes" : `no — ${data.reason.replaceAll("_", " ")}`);
  set("distance", data.feasible ? `${data.distance_m.toFixed(2)} m` : "–", data.distance_m);
  set("travel-time", data.feasible ? `${data.travel_time_s.toFixed(1)} s` : "–", data.travel_time_s);
  const widest = data.max_feasible_threshold;
  set("max-threshold", widest === null ? "none" : `${widest.toFixed(2)} ${data.unit}`, widest);
  const handovers = data.handovers || [];
  set("handovers", data.feasible ? (handovers.length ? handovers.map((h) => `AP ${h.from}→${h.to} at (${h.x}, ${h.y})`).join("; ") : "none") : "–", handovers.length);
  const phaseText = (w) => (w.irs_phases_rad || []).map((p) => p.map((t) => t.toFixed(3)).join(" ")).join(" | ");
  const rows = data.waypoints.map((w, k) => {
    const row = document.createElement("tr");
    const powers = w.power_w ? w.power_w.map((p) => p.toExponential(2)).join(", ") : "–";
    const order = w.decoding_order ? w.decoding_order.join("→") : "–";
    const cells = [k, w.x, w.y, w.time_s.toFixed(1), w.ap, w.value.toFixed(3), powers, order, phaseText(w) || "–"];
    cells.forEach((cell, n) => {
      const td = document.createElement("td");
      td.textContent = cell;
      if (n === cells.length - 1) {
        td.className = "phases";
        td.title = td.textContent;
      }
      row.append(td);
    });
    return row;
  });
  $("waypoints").tBodies[0].replaceChildren(...rows);
  linkBlob("download-path", JSON.stringify(data, null, 2), "application/json");
  // One line per waypoint: its pose, AP, value, powers and order, then every phase (rad) of
  // every IRS in scenario order.
  const header = "index,x,y,time_s,ap,value,power_w,decoding_order,irs_phases_rad";
  const lines = data.waypoints.map((w, k) =>
    [k, w.x, w.y, w.time_s, w.ap, w.value, (w.power_w || []).join(" "), (w.decoding_order || []).join(" "), (w.irs_phases_rad || []).map((p) => p.join(" ")).join(" | ")].join(","),
  );
  linkBlob("download-phases", [header, ...lines].join("\n") + "\n", "text/csv");
  updateDownloads();
  say(data.feasible ? `Path of ${data.waypoints.length} waypoints.` : `No path: ${data.reason.replaceAll("_", " ")}.`);
  draw();
}

function clearPath() {
  state.start = state.goal = state.path = null;
  $("start").value = $("goal").value = "";
  fieldError("start", "");
  fieldError("goal", "");
  for (const id of ["feasible", "distance", "travel-time", "max-threshold", "handovers"]) {
    $(id).textContent = "–";
    $(id).removeAttribute("data-value");
  }
  $("waypoints").tBodies[0].replaceChildren();
  $("sweep-plot").hidden = true;
  updateDownloads();
  draw();
}

function updateDownloads() {
  if (!state.map) return;
  const query = new URLSearchParams({ threshold: state.threshold });
  if (state.unit) query.set("unit", state.unit);
  if (state.start && state.goal) {
    query.set("start", formatPoint(state.start));
    query.set("goal", formatPoint(state.goal));
    query.set("path_shape", $("path-shape").value);
  }
  $("download-png").href = `/v1/maps/${state.map.map_id}/image.png?${query}`;
  $("download-png").download = `map-${state.map.map_id}.png`;
}

// ------------------------------------------------------------------ sweep

// Coverage η and path length against the threshold, 24 thresholds across the map's range:
// the lengths from one sweep, each η from the coverage endpoint.
async function sweep() {
  if (!state.start || !state.goal) throw new Error("Set a start and a goal first: the sweep plans between them.");
  const { min, max } = state.map.stats;
  const n = 24;
  const thresholds = Array.from({ length: n }, (_, k) => +(min + ((max - min) * k) / (n - 1)).toFixed(4));
  const body = { map_id: state.map.map_id, start: state.start, goal: state.goal, thresholds };
  if (state.unit) body.unit = state.unit;
  say("Sweeping the threshold…");
  const { data } = await api("POST", "/v1/sweeps", body);
  const unit = state.unit ? `&unit=${encodeURIComponent(state.unit)}` : "";
  const coverage = await Promise.all(
    thresholds.map((t) => api("GET", `/v1/maps/${state.map.map_id}/coverage?threshold=${t}${unit}`).then((r) => r.data.coverage)),
  );
  const points = data.points;
  drawSweep(thresholds, coverage, thresholds.map((t, k) => (points[k] && points[k].feasible ? points[k].distance_m : null)));
  say(`Sweep of ${n} thresholds from ${min.toFixed(1)} to ${max.toFixed(1)} ${state.map.unit}.`);
}

function drawSweep(thresholds, coverage, lengths) {
  const canvas = $("sweep-plot");
  canvas.hidden = false;
  const ctx = canvas.getContext("2d");
  const [w, h] = [canvas.width, canvas.height];
  const pad = { l: 34, r: 40, t: 10, b: 28 };
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, w, h);
  const lo = thresholds[0];
  const hi = thresholds[thresholds.length - 1];
  const longest = Math.max(1e-9, ...lengths.filter((v) => v !== null));
  const x = (t) => pad.l + ((t - lo) / (hi - lo || 1)) * (w - pad.l - pad.r);
  const y = (f) => h - pad.b - f * (h - pad.t - pad.b);
  ctx.strokeStyle = "#000";
  ctx.strokeRect(pad.l, pad.t, w - pad.l - pad.r, h - pad.t - pad.b);
  const line = (values, colour, scale) => {
    ctx.strokeStyle = colour;
    ctx.lineWidth = 2;
    ctx.beginPath();
    let open = false;
    values.forEach((v, k) => {
      if (v === null) {
        open = false;
        return;
      }
      const [px, py] = [x(thresholds[k]), y(v / scale)];
      if (open) ctx.lineTo(px, py);
      else ctx.moveTo(px, py);
      open = true;
    });
    ctx.stroke();
  };
  line(coverage, "#1a5fb4", 1);
  line(lengths, "#c01c28", longest);
  ctx.fillStyle = "#000";
  ctx.font = "10px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.fillText(`γ (${state.map.unit})`, w / 2, h - 4);
  ctx.fillText(lo.toFixed(0), x(lo), h - pad.b + 11);
  ctx.fillText(hi.toFixed(0), x(hi), h - pad.b + 11);
  ctx.textAlign = "left";
  ctx.fillStyle = "#1a5fb4";
  ctx.fillText("η 1", 2, y(1) + 4);
  ctx.fillText("0", 2, y(0));
  ctx.fillStyle = "#c01c28";
  ctx.textAlign = "right";
  ctx.fillText(`${longest.toFixed(0)} m`, w - 2, y(1) + 4);
  ctx.fillText("length", w - 2, y(0.5));
  canvas.dataset.points = JSON.stringify({ thresholds, coverage, lengths });
}

// ------------------------------------------------------------------ placement

async function runPlacement() {
  fieldError("place-step", "");
  const step = Number($("place-step").value);
  if (!(step > 0)) return fieldError("place-step", "The spacing is a positive number of metres.");
  const what = $("place-what").value;
  const kind = $("place-objective").value;
  const objective = { kind };
  if (kind !== "max_threshold") objective.threshold = state.threshold;
  if (kind !== "coverage") {
    if (!state.start || !state.goal) return fieldError("place-step", "This objective needs a start and a goal: click the map twice first.");
    Object.assign(objective, { start: state.start, goal: state.goal });
  }
  if (state.unit && state.unit !== "gain_db") return fieldError("place-step", "Placements score gain maps in dB: set the unit to the map's own.");
  const r = state.scenario.room;
  const corners = [[r.x_min, r.y_min], [r.x_max, r.y_min], [r.x_max, r.y_max], [r.x_min, r.y_max]];
  const walls = corners.map((from, k) => ({ from, to: corners[(k + 1) % 4] }));
  const request = { scenario_id: state.scenarioId, what, candidates: { walls, step_m: step }, objective };
  $("place-job").hidden = false;
  $("place-progress").value = 0;
  $("place-text").textContent = "ranking…";
  try {
    let { status, data } = await api("POST", "/v1/placements", request);
    if (status === 202) {
      const job = await waitJob(data, (j) => {
        $("place-progress").value = j.progress;
        $("place-text").textContent = `${j.cells_done} / ${j.cells_total} (${j.state})`;
      });
      if (job.state !== "done") throw new Error(`The placement ${job.state}${job.error ? ": " + job.error : ""}.`);
      data = (await api("GET", job.result_href)).data;
    }
    showCandidates(data);
  } catch (error) {
    fieldError("place-step", error.message);
  } finally {
    $("place-job").hidden = true;
  }
}

function showCandidates(answer) {
  state.candidates = answer.candidates.slice(0, 10).map((c) => ({ ...c, what: answer.what, index: answer.index }));
  const unit = answer.unit === "fraction" ? "" : ` ${answer.unit}`;
  const items = state.candidates.map((c) => {
    const li = document.createElement("li");
    const score = c.score === null ? "infeasible" : answer.unit === "fraction" ? `${(100 * c.score).toFixed(1)} %` : `${c.score.toFixed(2)}${unit}`;
    li.textContent = `(${c.center[0]}, ${c.center[1]}): ${score}`;
    const apply = document.createElement("button");
    apply.type = "button";
    apply.textContent = "Apply";
    apply.dataset.rank = c.rank;
    apply.addEventListener("click", () => applyCandidate(c).catch(report));
    li.append(apply);
    return li;
  });
  $("candidates").replaceChildren(...items);
  say(`${answer.candidates.length} positions ranked; the best ${state.candidates.length} are on the map by rank.`);
  draw();
}

async function applyCandidate(c) {
  const aps = structuredClone(accessPoints());
  const irss = structuredClone(surfaces());
  const srus = structuredClone(state.scenario.srus || []);
  if (c.what === "ap") aps[c.index].position = c.center;
  else Object.assign(irss[c.index], { center: c.center, normal: c.normal });
  await applyScenario(withDevices(aps, irss, srus), `Candidate ${c.rank} applied`);
}

// ------------------------------------------------------------------ view: zoom and pan

function plotArea() {
  const canvas = $("map");
  const m = margins(canvas.width);
  return {
    x: m.left,
    y: m.top,
    w: Math.max(40, canvas.width - m.left - m.right),
    h: Math.max(40, canvas.height - m.top - m.bottom),
  };
}

function fitView() {
  if (!state.map) return;
  state.view = { zoom: 1, cc: state.map.grid.nx / 2, rc: state.map.grid.ny / 2 };
}

function computeLayout() {
  const { nx, ny } = state.map.grid;
  const area = plotArea();
  const fit = Math.min(area.w / nx, area.h / ny);
  const cell = fit * state.view.zoom;
  return {
    cell,
    fit,
    area,
    left: area.x + area.w / 2 - state.view.cc * cell,
    top: area.y + area.h / 2 - state.view.rc * cell,
  };
}

// Zooms by `factor` keeping the image point under (px, py) where it is.
function zoomAt(factor, px, py) {
  if (!state.map) return;
  const L = state.layout || computeLayout();
  const maxZoom = Math.max(1, MAX_CELL_PX / L.fit);
  const zoom = Math.min(maxZoom, Math.max(1, state.view.zoom * factor));
  const pc = (px - L.left) / L.cell;
  const pr = (py - L.top) / L.cell;
  const cell = L.fit * zoom;
  const left = px - pc * cell;
  const top = py - pr * cell;
  state.view.zoom = zoom;
  state.view.cc = (L.area.x + L.area.w / 2 - left) / cell;
  state.view.rc = (L.area.y + L.area.h / 2 - top) / cell;
  if (zoom === 1) fitView();
  clampView();
  draw();
}

function panBy(dx, dy) {
  const L = state.layout;
  state.view.cc -= dx / L.cell;
  state.view.rc -= dy / L.cell;
  clampView();
  draw();
}

function clampView() {
  const { nx, ny } = state.map.grid;
  state.view.cc = Math.min(nx, Math.max(0, state.view.cc));
  state.view.rc = Math.min(ny, Math.max(0, state.view.rc));
}

// ------------------------------------------------------------------ drawing

// Pixel of a point in metres (cell centres are the centres of the drawn squares).
function toPixel(x, y) {
  const g = state.map.grid;
  const L = state.layout;
  return [
    L.left + ((x - g.x_min) / g.resolution_m + 0.5) * L.cell,
    L.top + (g.ny - 1 - (y - g.y_min) / g.resolution_m + 0.5) * L.cell,
  ];
}

// The point in metres at a pixel.
function toPoint(px, py) {
  const g = state.map.grid;
  const L = state.layout;
  return [g.x_min + ((px - L.left) / L.cell - 0.5) * g.resolution_m, g.y_min + (g.ny - 1 - ((py - L.top) / L.cell - 0.5)) * g.resolution_m];
}

function cellAt(px, py) {
  const g = state.map.grid;
  const L = state.layout;
  const A = L.area;
  if (px < A.x || py < A.y || px >= A.x + A.w || py >= A.y + A.h) return null;
  const i = Math.floor((px - L.left) / L.cell);
  const j = g.ny - 1 - Math.floor((py - L.top) / L.cell);
  return i >= 0 && j >= 0 && i < g.nx && j < g.ny ? [i, j] : null;
}

const cellCentre = ([i, j]) => {
  const g = state.map.grid;
  return [g.x_min + i * g.resolution_m, g.y_min + j * g.resolution_m].map((v) => +v.toFixed(6));
};

function niceTicks(low, high, target) {
  const raw = Math.max((high - low) / target, Number.MIN_VALUE);
  const magnitude = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 5, 10].map((m) => m * magnitude).find((s) => s >= raw);
  const ticks = [];
  for (let k = Math.ceil(low / step); k <= Math.floor(high / step); k++) ticks.push(+(k * step).toFixed(10));
  return ticks;
}

// What the cells show: values, the certificate gap, the serving AP or the difference against
// another map, with the colour table and range of the colour bar.
function layerValues() {
  const key = `${state.map.map_id}|${state.unit}|${state.layer}|${state.compare ? state.compare.map.map_id : ""}`;
  if (state.layerCache && state.layerCache.key === key) return state.layerCache.layer;
  const layer = computeLayer();
  state.layerCache = { key, layer };
  return layer;
}

function computeLayer() {
  const map = state.map;
  const grid = (f) => {
    let low = Infinity;
    let high = -Infinity;
    const values = map.values.map((row, i) =>
      row.map((v, j) => {
        const out = v === null ? null : f(v, i, j);
        if (out !== null) {
          low = Math.min(low, out);
          high = Math.max(high, out);
        }
        return out;
      }),
    );
    return { values, low: Number.isFinite(low) ? low : 0, high: Number.isFinite(high) ? high : 1 };
  };
  if (state.layer === "gap" && map.upper_bound) {
    const g = grid((v, i, j) => (map.upper_bound[i][j] === null ? null : map.upper_bound[i][j] - v));
    return { ...g, low: 0, high: g.high || 1e-12, unit: `gap, ${map.unit}`, colours: VIRIDIS };
  }
  if (state.layer === "serving" && map.serving_ap) {
    let high = 1;
    for (const row of map.serving_ap) for (const v of row) if (v !== null && v > high) high = v;
    return { values: map.serving_ap, low: 0, high, unit: "serving AP", categorical: true };
  }
  if (state.layer === "difference" && state.compare) {
    const other = state.compare.map.values;
    const g = grid((v, i, j) => (other[i][j] === null ? null : v - other[i][j]));
    const reach = Math.max(Math.abs(g.low), Math.abs(g.high), 1e-9);
    return { ...g, low: -reach, high: reach, unit: `Δ ${map.unit}`, colours: DIVERGING };
  }
  return { values: map.values, low: map.stats.min, high: map.stats.max, unit: map.unit, colours: VIRIDIS };
}

// The cells as an image of one pixel per cell, redrawn only when what it shows changes.
function cellImage(layer) {
  const key = `${state.map.map_id}|${state.unit}|${state.layer}|${state.threshold}|${state.compare ? state.compare.map.map_id : ""}`;
  if (state.image && state.image.key === key) return state.image.canvas;
  const { nx, ny } = state.map.grid;
  const canvas = (state.image && state.image.canvas.width === nx && state.image.canvas.height === ny)
    ? state.image.canvas
    : Object.assign(document.createElement("canvas"), { width: nx, height: ny });
  const ctx = canvas.getContext("2d");
  const image = ctx.createImageData(nx, ny);
  const { values, low, high, colours, categorical } = layer;
  const span = high > low ? high - low : 1;
  const dimming = state.layer === "value" && state.threshold !== null;
  // A gain map has a value in every free cell, so its nulls are exactly the occupied cells
  // (boxes, walls, floor-plan pixels): grey. On rate maps a null may also be a cell where no
  // configuration serves every SRU: black.
  const empty = state.map.key.kind === "gain" ? [128, 128, 128] : [0, 0, 0];
  const own = state.map.values;
  for (let i = 0; i < nx; i++) {
    for (let j = 0; j < ny; j++) {
      const v = values[i][j];
      let rgb;
      if (v === null) rgb = own[i][j] === null ? empty : [255, 255, 255];
      else if (categorical) rgb = CATEGORICAL[v % CATEGORICAL.length];
      else rgb = colours[Math.round(Math.min(Math.max((v - low) / span, 0), 1) * 255)];
      if (v !== null && dimming && v < state.threshold) rgb = rgb.map((c) => Math.floor(c * DIM));
      const at = ((ny - 1 - j) * nx + i) * 4;
      image.data[at] = rgb[0];
      image.data[at + 1] = rgb[1];
      image.data[at + 2] = rgb[2];
      image.data[at + 3] = 255;
    }
  }
  ctx.putImageData(image, 0, 0);
  state.image = { key, canvas };
  return canvas;
}

function sizeCanvas() {
  const canvas = $("map");
  const wrap = $("canvas-wrap");
  const [w, h] = [Math.max(200, Math.floor(wrap.clientWidth)), Math.max(160, Math.floor(wrap.clientHeight))];
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
}

function draw() {
  const canvas = $("map");
  if (!state.map) return;
  sizeCanvas();
  if (state.view.cc === null) fitView();
  const L = (state.layout = computeLayout());
  const ctx = canvas.getContext("2d");
  Object.assign(canvas.dataset, { left: L.left, top: L.top, cell: L.cell, zoom: state.view.zoom, layer: state.layer });
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  const { nx, ny } = state.map.grid;
  const layer = layerValues();
  ctx.save();
  ctx.beginPath();
  ctx.rect(L.area.x, L.area.y, L.area.w, L.area.h);
  ctx.clip();
  ctx.imageSmoothingEnabled = false;
  ctx.drawImage(cellImage(layer), L.left, L.top, nx * L.cell, ny * L.cell);
  drawObstacles(ctx);
  drawDevices(ctx);
  drawCandidates(ctx);
  drawPath(ctx);
  drawCursor(ctx);
  if (state.building) drawStale(ctx);
  ctx.restore();
  drawAxes(ctx);
  drawColourBar(ctx, layer, state.layer === "value" ? state.threshold : null);
}

// The old map under a hatched veil while a new one builds.
function drawStale(ctx) {
  const A = state.layout.area;
  ctx.fillStyle = "rgba(255, 255, 255, 0.55)";
  ctx.fillRect(A.x, A.y, A.w, A.h);
  ctx.strokeStyle = "rgba(120, 120, 120, 0.5)";
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (let d = -A.h; d < A.w; d += 12) {
    ctx.moveTo(A.x + d, A.y + A.h);
    ctx.lineTo(A.x + d + A.h, A.y);
  }
  ctx.stroke();
  ctx.font = "bold 16px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.lineWidth = 4;
  ctx.strokeStyle = "#fff";
  const text = "stale — a new map is building…";
  ctx.strokeText(text, A.x + A.w / 2, A.y + A.h / 2);
  ctx.fillStyle = "#000";
  ctx.fillText(text, A.x + A.w / 2, A.y + A.h / 2);
}

// The cells an obstacle occupies, grey: those whose centre lies in or on its footprint
// (docs/model.md §1), i.e. the index ranges the footprint's edges round inwards to.
function drawObstacles(ctx) {
  const g = state.map.grid;
  const L = state.layout;
  const eps = 1e-9;
  const cells = (lo, hi, min, n) => [
    Math.max(0, Math.ceil((lo - min) / g.resolution_m - eps)),
    Math.min(n - 1, Math.floor((hi - min) / g.resolution_m + eps)),
  ];
  ctx.fillStyle = "#808080";
  for (const o of state.scenario.obstacles || []) {
    const [i0, i1] = cells(o.center[0] - o.size[0] / 2, o.center[0] + o.size[0] / 2, g.x_min, g.nx);
    const [j0, j1] = cells(o.center[1] - o.size[1] / 2, o.center[1] + o.size[1] / 2, g.y_min, g.ny);
    if (i0 > i1 || j0 > j1) continue;
    ctx.fillRect(L.left + i0 * L.cell, L.top + (g.ny - 1 - j1) * L.cell, (i1 - i0 + 1) * L.cell, (j1 - j0 + 1) * L.cell);
  }
}

function drawAxes(ctx) {
  const L = state.layout;
  const A = L.area;
  const g = state.map.grid;
  ctx.strokeStyle = "#000";
  ctx.fillStyle = "#000";
  ctx.lineWidth = 1;
  ctx.strokeRect(A.x - 0.5, A.y - 0.5, A.w + 1, A.h + 1);
  ctx.font = "12px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "top";
  // The visible extent in metres.
  const [x0, y1] = toPoint(A.x, A.y);
  const [x1, y0] = toPoint(A.x + A.w, A.y + A.h);
  const xMax = g.x_min + (g.nx - 1) * g.resolution_m;
  const yMax = g.y_min + (g.ny - 1) * g.resolution_m;
  const [xl, xh] = [Math.max(g.x_min, x0), Math.min(xMax, x1)];
  const [yl, yh] = [Math.max(g.y_min, y0), Math.min(yMax, y1)];
  for (const x of niceTicks(xl, xh, 8)) {
    const [px] = toPixel(x, g.y_min);
    ctx.fillRect(Math.round(px), A.y + A.h, 1, 5);
    ctx.fillText(String(x), px, A.y + A.h + 7);
  }
  ctx.fillText("x (m)", A.x + A.w / 2, A.y + A.h + 24);
  ctx.textAlign = "right";
  ctx.textBaseline = "middle";
  for (const y of niceTicks(yl, yh, 8)) {
    const [, py] = toPixel(g.x_min, y);
    ctx.fillRect(A.x - 5, Math.round(py), 5, 1);
    ctx.fillText(String(y), A.x - 8, py);
  }
  ctx.textAlign = "left";
  ctx.fillText("y (m)", 4, 10);
}

function drawColourBar(ctx, layer, threshold) {
  const A = state.layout.area;
  const x0 = A.x + A.w + (A.x < 50 ? 10 : 18);
  const h = A.h;
  const { low, high, unit } = layer;
  ctx.fillStyle = "#000";
  ctx.textAlign = "left";
  ctx.textBaseline = "bottom";
  ctx.font = "12px system-ui, sans-serif";
  ctx.fillText(unit, x0 - 4, A.y - 6);
  if (layer.categorical) {
    // One swatch per AP.
    ctx.textBaseline = "middle";
    for (let k = 0; k <= high; k++) {
      ctx.fillStyle = `rgb(${CATEGORICAL[k % CATEGORICAL.length]})`;
      ctx.fillRect(x0, A.y + k * 22, 16, 16);
      ctx.fillStyle = "#000";
      ctx.fillText(`AP ${k}`, x0 + 22, A.y + k * 22 + 8);
    }
    return;
  }
  for (let row = 0; row < h; row++) {
    const rgb = layer.colours[Math.round((1 - row / Math.max(h - 1, 1)) * 255)];
    ctx.fillStyle = `rgb(${rgb})`;
    ctx.fillRect(x0, A.y + row, 16, 1);
  }
  ctx.strokeStyle = "#000";
  ctx.strokeRect(x0 - 0.5, A.y - 0.5, 17, h + 1);
  ctx.fillStyle = "#000";
  ctx.textBaseline = "middle";
  const span = high > low ? high - low : 1;
  const yOf = (v) => A.y + ((high - v) / span) * (h - 1);
  const marks = [low, high, ...niceTicks(low, high, 5).filter((t) => t - low > span * 0.08 && high - t > span * 0.08)];
  for (const v of marks) {
    ctx.fillRect(x0 + 16, Math.round(yOf(v)), 4, 1);
    ctx.fillText(+v.toPrecision(4) + "", x0 + 23, yOf(v));
  }
  if (threshold !== null && threshold >= low && threshold <= high) {
    ctx.fillRect(x0 - 4, Math.round(yOf(threshold)) - 1, 24, 3);
  }
}

const markerRadius = () => Math.max(5, Math.min(14, state.layout.cell * 0.35));

function drawMarker(ctx, x, y, shape, fill, label, highlight = false) {
  const [px, py] = toPixel(x, y);
  const r = markerRadius();
  ctx.fillStyle = fill;
  ctx.strokeStyle = "#000";
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  if (shape === "square") ctx.rect(px - r, py - r, 2 * r, 2 * r);
  else if (shape === "diamond") {
    ctx.moveTo(px, py - r);
    ctx.lineTo(px + r, py);
    ctx.lineTo(px, py + r);
    ctx.lineTo(px - r, py);
    ctx.closePath();
  } else ctx.arc(px, py, r, 0, 2 * Math.PI);
  ctx.fill();
  ctx.stroke();
  if (highlight) {
    ctx.strokeStyle = "#1a5fb4";
    ctx.lineWidth = 3;
    ctx.beginPath();
    ctx.arc(px, py, r + 5, 0, 2 * Math.PI);
    ctx.stroke();
  }
  if (label) {
    ctx.font = "bold 12px system-ui, sans-serif";
    ctx.textAlign = "left";
    ctx.textBaseline = "middle";
    ctx.lineWidth = 3;
    ctx.strokeStyle = "#fff";
    ctx.strokeText(label, px + r + 3, py);
    ctx.fillStyle = "#000";
    ctx.fillText(label, px + r + 3, py);
  }
}

function drawDevices(ctx) {
  const isSelected = (kind, index) => state.selected && state.selected.kind === kind && state.selected.index === index;
  const at = (kind, index, x, y) => (state.drag && state.drag.kind === kind && state.drag.index === index ? [state.drag.x, state.drag.y] : [x, y]);
  const list = surfaces();
  list.forEach((irs, k) => {
    let [cx, cy] = at("irs", k, irs.center[0], irs.center[1]);
    let normal = irs.normal;
    if (state.drag && state.drag.kind === "irs" && state.drag.index === k) {
      // Dragged: shown where it would snap.
      const snapped = snapToWall(cx, cy, irs.center[2]);
      [cx, cy] = snapped.center;
      normal = snapped.normal;
    }
    const along = [-normal[1], normal[0]];
    const norm = Math.hypot(...along) || 1;
    const half = Math.max((irs.nx_sub * (irs.sub_pitch_m || 0)) / 2, 1.5 * state.map.grid.resolution_m);
    const [ax, ay] = toPixel(cx - (half * along[0]) / norm, cy - (half * along[1]) / norm);
    const [bx, by] = toPixel(cx + (half * along[0]) / norm, cy + (half * along[1]) / norm);
    ctx.strokeStyle = "#e600e6";
    ctx.lineWidth = Math.max(4, Math.min(12, state.layout.cell * 0.4));
    ctx.lineCap = "round";
    ctx.beginPath();
    ctx.moveTo(ax, ay);
    ctx.lineTo(bx, by);
    ctx.stroke();
    // Its facing: an arrow along the normal.
    const [px, py] = toPixel(cx, cy);
    const reach = markerRadius() * 2.6;
    const [ex, ey] = [px + normal[0] * reach, py - normal[1] * reach];
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(px, py);
    ctx.lineTo(ex, ey);
    ctx.stroke();
    drawMarker(ctx, cx, cy, "circle", "#e600e6", list.length > 1 ? `IRS ${k}` : "IRS", isSelected("irs", k));
  });
  const aps = accessPoints();
  aps.forEach((ap, k) => {
    const [x, y] = at("ap", k, ap.position[0], ap.position[1]);
    drawMarker(ctx, x, y, "square", "#fff", aps.length > 1 ? `AP ${k}` : "AP", isSelected("ap", k));
  });
  (state.scenario.srus || []).forEach((sru, k) => {
    const [x, y] = at("sru", k, sru.position[0], sru.position[1]);
    drawMarker(ctx, x, y, "circle", "#fff", `SRU${k}`, isSelected("sru", k));
  });
}

function drawCandidates(ctx) {
  for (const c of state.candidates) {
    drawMarker(ctx, c.center[0], c.center[1], "circle", c.rank === 1 ? "#ffd700" : "#ddd", `#${c.rank}`);
  }
}

function drawPath(ctx) {
  const path = state.path;
  if (path && path.feasible) {
    ctx.lineJoin = ctx.lineCap = "round";
    for (const [colour, width] of [["#000", 6], ["#fff", 3]]) {
      ctx.strokeStyle = colour;
      ctx.lineWidth = width;
      ctx.beginPath();
      path.waypoints.forEach((w, k) => {
        const [px, py] = toPixel(w.x, w.y);
        if (k === 0) ctx.moveTo(px, py);
        else ctx.lineTo(px, py);
      });
      ctx.stroke();
    }
    for (const h of path.handovers || []) drawMarker(ctx, h.x, h.y, "diamond", "#ffb000", `AP ${h.from}→${h.to}`);
  }
  if (state.start) drawMarker(ctx, state.start[0], state.start[1], "circle", "#00c800", "start");
  if (state.goal) drawMarker(ctx, state.goal[0], state.goal[1], "circle", "#e60000", "goal");
}

function drawCursor(ctx) {
  if (!state.cursor) return;
  const [px, py] = toPixel(...cellCentre(state.cursor));
  const half = Math.max(state.layout.cell / 2, 4);
  ctx.strokeStyle = "#1a5fb4";
  ctx.lineWidth = 2;
  ctx.strokeRect(px - half, py - half, 2 * half, 2 * half);
}

// ------------------------------------------------------------------ pointer and keyboard

function nearestWaypoint(px, py) {
  if (!state.path || !state.path.feasible) return null;
  let best = null;
  for (const w of state.path.waypoints) {
    const [wx, wy] = toPixel(w.x, w.y);
    const d = Math.hypot(wx - px, wy - py);
    if (d <= Math.max(6, state.layout.cell / 2) && (!best || d < best.d)) best = { w, d };
  }
  return best && best.w;
}

function showTooltip(w, px, py) {
  const tip = $("tooltip");
  const unit = state.path.unit;
  const lines = [`(${w.x}, ${w.y}) m: ${w.value.toFixed(3)} ${unit}, AP ${w.ap}, t = ${w.time_s.toFixed(1)} s`];
  if (w.power_w) lines.push(`powers (W): ${w.power_w.map((p) => p.toExponential(2)).join(", ")}`);
  if (w.decoding_order) lines.push(`decoding order: ${w.decoding_order.join(" → ")}`);
  // One phase vector per IRS, in scenario order.
  const surfaces = w.irs_phases_rad || [];
  const sizes = surfaces.map((phases) => phases.length);
  lines.push(surfaces.length ? `IRS phases: ${sizes.join(" + ")} values in [0, 2π)` : "IRS phases: none");
  tip.replaceChildren(...lines.map((t) => Object.assign(document.createElement("div"), { textContent: t })));
  for (const phases of surfaces.filter((p) => p.length)) {
    // The phases as a small bar plot, one bar per sub-surface (height θ_n / 2π).
    const plot = document.createElement("canvas");
    const n = phases.length;
    plot.width = Math.min(240, Math.max(60, n * 4));
    plot.height = 40;
    const c = plot.getContext("2d");
    c.fillStyle = "#f3f3f3";
    c.fillRect(0, 0, plot.width, plot.height);
    c.fillStyle = "#3b528b";
    const barWidth = plot.width / n;
    phases.forEach((theta, k) => {
      const h = (theta / (2 * Math.PI)) * plot.height;
      c.fillRect(k * barWidth, plot.height - h, Math.max(1, barWidth - 1), h);
    });
    plot.setAttribute("aria-hidden", "true");
    tip.append(plot);
  }
  const wrap = $("canvas-wrap");
  tip.style.left = `${Math.min(px + 14, wrap.clientWidth - 260)}px`;
  tip.style.top = `${Math.min(py + 14, wrap.clientHeight - 120)}px`;
  tip.hidden = false;
}

// The pointer's position in canvas pixels.
function pointer(event) {
  const rect = $("map").getBoundingClientRect();
  return [event.clientX - rect.left, event.clientY - rect.top];
}

function readCell(cell) {
  const [i, j] = cell;
  const layer = layerValues();
  const v = layer.values[i][j];
  const [x, y] = cellCentre(cell);
  const text = v === null ? "no value (occupied or unserviceable)" : layer.categorical ? `AP ${v}` : `${v.toFixed(3)} ${layer.unit}`;
  $("cursor").textContent = `Cell (${i}, ${j}) at (${x}, ${y}) m: ${text}`;
}

let press = null; // the pointer press in progress: { x, y, device, panning }

function onPointerDown(event) {
  if (!state.map || event.button > 0) return;
  const [px, py] = pointer(event);
  $("map").setPointerCapture(event.pointerId);
  press = { x: px, y: py, last: [px, py], device: deviceAt(px, py), moved: false };
}

function onPointerMove(event) {
  if (!state.map) return;
  const [px, py] = pointer(event);
  if (press) {
    if (Math.hypot(px - press.x, py - press.y) > CLICK_SLOP_PX) press.moved = true;
    if (press.moved && press.device) {
      const [x, y] = toPoint(px, py);
      state.drag = { kind: press.device.kind, index: press.device.index, x, y };
      $("map").classList.add("dragging");
      draw();
    } else if (press.moved) {
      panBy(px - press.last[0], py - press.last[1]);
    }
    press.last = [px, py];
    return;
  }
  const cell = cellAt(px, py);
  if (cell) readCell(cell);
  const w = nearestWaypoint(px, py);
  if (w) showTooltip(w, px, py);
  else $("tooltip").hidden = true;
}

function onPointerUp(event) {
  if (!press) return;
  const done = press;
  press = null;
  $("map").classList.remove("dragging");
  const [px, py] = pointer(event);
  if (done.device && done.moved) {
    const cell = cellAt(px, py);
    state.drag = null;
    if (!cell) return draw();
    const [x, y] = done.device.kind === "irs" ? toPoint(px, py) : cellCentre(cell);
    placeDevice(done.device.kind, done.device.index, x, y).catch((e) => {
      report(e);
      draw();
    });
    return;
  }
  if (done.moved) return;
  if (done.device && !state.adding) {
    state.selected = { kind: done.device.kind, index: done.device.index };
    return showSelection();
  }
  const cell = cellAt(px, py);
  if (cell) choose(cell, toPoint(px, py));
}

// A cell chosen by click, tap or Enter: a device being added goes there, else the path's ends.
function choose(cell, exact = cellCentre(cell)) {
  if (state.adding) {
    const kind = state.adding;
    state.adding = null;
    const [x, y] = kind === "irs" ? exact : cellCentre(cell);
    return placeDevice(kind, null, x, y).catch(report);
  }
  // A click means "this cell": use its centre, as the planner would snap it anyway.
  const point = cellCentre(cell);
  if (!state.start || state.goal) {
    clearPath();
    state.start = point;
    $("start").value = formatPoint(point);
    say("Start set; choose the goal.");
    draw();
  } else {
    state.goal = point;
    $("goal").value = formatPoint(point);
    planPath().catch(report);
  }
}

function onWheel(event) {
  if (!state.map) return;
  event.preventDefault();
  if (event.deltaY === 0) return;
  const [px, py] = pointer(event);
  zoomAt(event.deltaY < 0 ? 1.25 : 0.8, px, py);
}

function onKey(event) {
  if (!state.map) return;
  const g = state.map.grid;
  const steps = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, 1], ArrowDown: [0, -1] };
  const A = state.layout.area;
  if (steps[event.key]) {
    event.preventDefault();
    const [di, dj] = steps[event.key];
    if (event.shiftKey) return panBy(-di * A.w * 0.2, dj * A.h * 0.2);
    const [i, j] = state.cursor || [Math.floor(g.nx / 2), Math.floor(g.ny / 2)];
    state.cursor = [Math.min(g.nx - 1, Math.max(0, i + di)), Math.min(g.ny - 1, Math.max(0, j + dj))];
    // Keep the cursor in view.
    const [px, py] = toPixel(...cellCentre(state.cursor));
    if (px < A.x || px > A.x + A.w || py < A.y || py > A.y + A.h) panBy(A.x + A.w / 2 - px, A.y + A.h / 2 - py);
    readCell(state.cursor);
    return draw();
  }
  if (event.key === "Enter" || event.key === " ") {
    event.preventDefault();
    if (state.cursor) choose(state.cursor);
    else say("Move the cursor with the arrow keys first.", true);
    return;
  }
  const centre = [A.x + A.w / 2, A.y + A.h / 2];
  if (event.key === "+" || event.key === "=") return zoomAt(1.25, ...centre);
  if (event.key === "-") return zoomAt(0.8, ...centre);
  if (event.key === "0") {
    fitView();
    return draw();
  }
  if (event.key === "Escape") {
    state.adding = null;
    state.selected = null;
    return showSelection();
  }
  if ((event.key === "Delete" || event.key === "Backspace") && state.selected) {
    event.preventDefault();
    removeSelected().catch(report);
  }
}

function setLayer(layer) {
  state.layer = layer;
  document.querySelector(`input[name=layer][value=${layer}]`).checked = true;
  state.image = null;
  state.layerCache = null;
  draw();
}

function report(error) {
  if (error && error.input) fieldError(error.input, error.message);
  say(error.message || String(error), true);
}

function refresh() {
  draw();
  updateDownloads();
  return updateCoverage();
}

function readThreshold() {
  const text = $("threshold").value.trim();
  const v = Number(text);
  if (text === "" || !Number.isFinite(v)) {
    fieldError("threshold", "Enter the threshold as a number (the map keeps the last one).");
    return;
  }
  setThreshold(v);
}

function readEnds() {
  fieldError("start", "");
  fieldError("goal", "");
  const start = parsePoint($("start").value, "Start");
  const goal = parsePoint($("goal").value, "Goal");
  state.start = start;
  state.goal = goal;
  return planPath();
}

function wire() {
  const guard = (f) => (...args) => Promise.resolve().then(() => f(...args)).catch(report);
  $("scenario").addEventListener("change", guard((e) => chooseScenario(e.target.value)));
  $("token").value = sessionStorage.getItem("irs-planner-token") || "";
  for (const id of ["download-map", "download-png"]) $(id).addEventListener("click", downloadWithToken);
  $("token").addEventListener("change", () => sessionStorage.setItem("irs-planner-token", $("token").value.trim()));
  $("register").addEventListener("click", guard(registerScenario));
  for (const id of ["kind", "phases", "access"]) $(id).addEventListener("change", guard(buildMap));
  $("build").addEventListener("click", guard(buildMap));
  $("cancel").addEventListener("click", guard(cancelJob));
  $("unit").addEventListener("change", guard(async (e) => {
    const before = { unit: state.unit, threshold: state.threshold };
    state.unit = e.target.value;
    state.threshold = null;
    try {
      if (state.map) await showMap(state.map.map_id);
    } catch (error) {
      Object.assign(state, before);
      e.target.value = before.unit;
      throw error;
    }
    if (state.start && state.goal) await planPath();
  }));
  $("threshold-range").addEventListener("input", (e) => setThreshold(Number(e.target.value)));
  $("threshold").addEventListener("change", readThreshold);
  $("threshold").addEventListener("keydown", (e) => {
    if (e.key === "Enter") {
      e.preventDefault();
      readThreshold();
    }
  });
  $("largest").addEventListener("click", guard(largestFeasible));
  document.querySelectorAll("input[name=layer]").forEach((r) => r.addEventListener("change", (e) => setLayer(e.target.value)));
  $("compare").addEventListener("change", guard(refreshComparison));
  $("plan").addEventListener("click", guard(readEnds));
  for (const id of ["start", "goal"]) {
    $(id).addEventListener("keydown", (e) => {
      if (e.key === "Enter") {
        e.preventDefault();
        guard(readEnds)();
      }
    });
  }
  $("clear").addEventListener("click", clearPath);
  $("sweep").addEventListener("click", guard(sweep));
  $("path-shape").addEventListener("change", guard(() => (state.start && state.goal ? planPath() : null)));
  for (const kind of ["ap", "irs", "sru"]) {
    $(`add-${kind}`).addEventListener("click", () => {
      state.adding = kind;
      say(`Click the map (or press Enter on the map) where the new ${kind.toUpperCase()} goes${kind === "irs" ? "; it snaps to the nearest wall" : ""}.`);
    });
  }
  $("remove").addEventListener("click", guard(removeSelected));
  $("place").addEventListener("click", guard(runPlacement));
  $("ros-import").addEventListener("click", guard(() => importRosMap($("ros-files").files)));
  const canvas = $("map");
  canvas.addEventListener("pointerdown", onPointerDown);
  canvas.addEventListener("pointermove", onPointerMove);
  canvas.addEventListener("pointerup", onPointerUp);
  canvas.addEventListener("pointercancel", () => {
    press = null;
    state.drag = null;
    draw();
  });
  canvas.addEventListener("pointerleave", () => ($("tooltip").hidden = true));
  canvas.addEventListener("wheel", onWheel, { passive: false });
  canvas.addEventListener("keydown", onKey);
  $("zoom-in").addEventListener("click", () => zoomAt(1.25, ...centreOfPlot()));
  $("zoom-out").addEventListener("click", () => zoomAt(0.8, ...centreOfPlot()));
  $("zoom-fit").addEventListener("click", () => {
    fitView();
    draw();
  });
  // A map.yaml and its image dropped on the map.
  const wrap = $("canvas-wrap");
  wrap.addEventListener("dragover", (e) => {
    if (![...e.dataTransfer.types].includes("Files")) return;
    e.preventDefault();
    $("drop-hint").hidden = false;
  });
  wrap.addEventListener("dragleave", () => ($("drop-hint").hidden = true));
  wrap.addEventListener("drop", (e) => {
    e.preventDefault();
    $("drop-hint").hidden = true;
    guard(() => importRosMap(e.dataTransfer.files))();
  });
  new ResizeObserver(() => draw()).observe(wrap);
}

const centreOfPlot = () => {
  const A = plotArea();
  return [A.x + A.w / 2, A.y + A.h / 2];
};

wire();
loadScenarios().catch(report);
