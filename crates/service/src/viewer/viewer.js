// The built-in map viewer: a client of irs-planner's public HTTP API, like any user's script.
// It draws the map on a canvas (viridis colours, axes in metres, a colour bar in the map's unit,
// obstacles, AP, IRS and SRUs), dims cells below the threshold, asks the API for coverage and
// paths, follows build jobs, and offers the PNG and JSON downloads. No framework, no build step.
"use strict";

const $ = (id) => document.getElementById(id);

// Viridis at 5 stops, interpolated into a 256-entry table (the PNG renderer uses the same stops).
const STOPS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
const VIRIDIS = Array.from({ length: 256 }, (_, k) => {
  const x = (k / 255) * (STOPS.length - 1);
  const i = Math.min(Math.floor(x), STOPS.length - 2);
  const f = x - i;
  return STOPS[i].map((c, n) => Math.round(c * (1 - f) + STOPS[i + 1][n] * f));
});
// Cells below the threshold keep 30 % of their colour, as in the PNG.
const DIM = 0.3;
// Margins around the plot (px): tick labels left and below, the colour bar right.
const MARGIN = { left: 58, top: 24, right: 96, bottom: 44 };

const state = {
  scenarioId: null,
  scenario: null, // the scenario document (obstacles, AP, IRS, SRUs)
  map: null, // GET /v1/maps/{id}
  job: null, // the job building the requested map
  threshold: null,
  start: null,
  goal: null,
  path: null, // POST /v1/paths answer
  layer: "value",
  layout: null,
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
  const data = text ? JSON.parse(text) : null;
  if (!response.ok) {
    const problem = data || {};
    const where = problem.field ? ` (${problem.field})` : "";
    throw new Error(`${problem.title || response.status}${where}: ${problem.detail || text}`);
  }
  return { status: response.status, data };
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
    const url = URL.createObjectURL(await response.blob());
    const save = document.createElement("a");
    save.href = url;
    save.download = link.download;
    document.body.appendChild(save);
    save.click();
    save.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10_000);
  } catch (error) {
    say(`Download failed: ${error.message}`, true);
  }
}

function say(message, isError = false) {
  const status = $("status");
  status.textContent = message;
  status.classList.toggle("error", isError);
}

// ------------------------------------------------------------------ scenarios

async function loadScenarios(select) {
  // Every page of the listing, in name order.
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
  await chooseScenario(list.value);
}

async function chooseScenario(id) {
  if (!id) return;
  const { data } = await api("GET", `/v1/scenarios/${id}`);
  state.scenarioId = id;
  state.scenario = data.scenario;
  const hasIrs = Boolean(data.scenario.irs || (data.scenario.irss || []).length);
  $("phases").value = hasIrs ? $("phases").value : "none";
  for (const option of $("phases").options) option.disabled = !hasIrs && option.value !== "none";
  const hasSrus = (data.scenario.srus || []).length > 0;
  $("kind").options[1].disabled = !hasSrus;
  if (!hasSrus) $("kind").value = "gain";
  clearPath();
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

// ------------------------------------------------------------------ maps and jobs

function mapRequest() {
  const kind = $("kind").value;
  const phases = $("phases").value;
  const request = {
    scenario_id: state.scenarioId,
    kind,
    phases: /^\d+$/.test(phases) ? Number(phases) : phases,
  };
  if (kind === "rate") request.access = $("access").value;
  return request;
}

async function buildMap() {
  if (!state.scenarioId) return;
  $("access").disabled = $("kind").value !== "rate";
  say("Requesting the map…");
  const { status, data } = await api("POST", "/v1/maps", mapRequest());
  if (status === 202) {
    state.job = data;
    await followJob();
  } else {
    await showMap(data.map_id);
  }
}

async function followJob() {
  $("job").hidden = false;
  while (state.job) {
    const job = state.job;
    $("job-progress").value = job.progress;
    $("job-text").textContent = `${job.cells_done} / ${job.cells_total} cells (${job.state})`;
    if (job.state === "done") {
      state.job = null;
      $("job").hidden = true;
      return showMap(job.map_id);
    }
    if (job.state === "failed" || job.state === "cancelled") {
      state.job = null;
      $("job").hidden = true;
      return say(`The build ${job.state}${job.error ? ": " + job.error : ""}.`, job.state === "failed");
    }
    await new Promise((resolve) => setTimeout(resolve, 300));
    if (state.job && state.job.job_id === job.job_id) {
      state.job = (await api("GET", `/v1/jobs/${job.job_id}`)).data;
    }
  }
}

async function cancelJob() {
  if (!state.job) return;
  const { data } = await api("DELETE", `/v1/jobs/${state.job.job_id}`);
  state.job = data;
  say("Cancelling the build…");
}

async function showMap(mapId) {
  const { data } = await api("GET", `/v1/maps/${mapId}`);
  state.map = data;
  const { min, max } = data.stats;
  const range = $("threshold-range");
  range.min = Math.floor(min * 10) / 10;
  range.max = Math.ceil(max * 10) / 10;
  const keep = state.threshold !== null && state.threshold >= range.min && state.threshold <= range.max;
  setThreshold(keep ? state.threshold : Math.round(((min + max) / 2) * 10) / 10, false);
  document.querySelectorAll(".unit").forEach((el) => (el.textContent = data.unit));
  $("layer-gap").disabled = !data.upper_bound;
  if (!data.upper_bound) setLayer("value");
  $("map").setAttribute(
    "aria-label",
    `${data.key.kind} map of ${data.grid.nx} × ${data.grid.ny} cells, ${min.toFixed(2)} to ${max.toFixed(2)} ${data.unit}`,
  );
  $("download-map").href = `/v1/maps/${mapId}`;
  $("download-map").download = `map-${mapId}.json`;
  say(`Map ${mapId.slice(0, 8)}: ${data.stats.valued_cells} cells with a value, built in the API's cache.`);
  await refresh();
}

// ------------------------------------------------------------------ threshold, coverage, paths

let coverageTimer = null;
function setThreshold(value, replan = true) {
  state.threshold = value;
  $("threshold-range").value = value;
  $("threshold").value = value;
  draw();
  clearTimeout(coverageTimer);
  coverageTimer = setTimeout(() => {
    updateCoverage();
    if (replan && state.start && state.goal) planPath();
  }, 150);
  updateDownloads();
}

async function updateCoverage() {
  if (!state.map) return;
  const { data } = await api(
    "GET",
    `/v1/maps/${state.map.map_id}/coverage?threshold=${encodeURIComponent(state.threshold)}`,
  );
  $("coverage").textContent = `${(100 * data.coverage).toFixed(1)} % (${data.covered_cells} of ${data.free_cells} free cells)`;
}

function parsePoint(text) {
  const parts = text.split(",").map((t) => Number(t.trim()));
  return parts.length === 2 && parts.every(Number.isFinite) ? parts : null;
}

function formatPoint(p) {
  return `${+p[0].toFixed(3)},${+p[1].toFixed(3)}`;
}

async function planPath() {
  if (!state.map || !state.start || !state.goal) return;
  const { data } = await api("POST", "/v1/paths", {
    map_id: state.map.map_id,
    start: state.start,
    goal: state.goal,
    threshold: state.threshold,
    path_shape: $("path-shape").value,
  });
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
  const rows = data.waypoints.map((w, k) => {
    const row = document.createElement("tr");
    const powers = w.power_w ? w.power_w.map((p) => p.toExponential(2)).join(", ") : "–";
    for (const cell of [k, w.x, w.y, w.value.toFixed(3), powers]) {
      const td = document.createElement("td");
      td.textContent = cell;
      row.append(td);
    }
    return row;
  });
  $("waypoints").tBodies[0].replaceChildren(...rows);
  const blob = new Blob([JSON.stringify(data, null, 2)], { type: "application/json" });
  $("download-path").href = URL.createObjectURL(blob);
  updateDownloads();
  say(data.feasible ? `Path of ${data.waypoints.length} waypoints.` : `No path: ${data.reason.replaceAll("_", " ")}.`);
  draw();
}

function clearPath() {
  state.start = state.goal = state.path = null;
  $("start").value = $("goal").value = "";
  for (const id of ["feasible", "distance", "travel-time", "max-threshold"]) {
    $(id).textContent = "–";
    $(id).removeAttribute("data-value");
  }
  $("waypoints").tBodies[0].replaceChildren();
  updateDownloads();
  draw();
}

function updateDownloads() {
  if (!state.map) return;
  const query = new URLSearchParams({ threshold: state.threshold });
  if (state.start && state.goal) {
    query.set("start", formatPoint(state.start));
    query.set("goal", formatPoint(state.goal));
    query.set("path_shape", $("path-shape").value);
  }
  $("download-png").href = `/v1/maps/${state.map.map_id}/image.png?${query}`;
  $("download-png").download = `map-${state.map.map_id}.png`;
}

// ------------------------------------------------------------------ drawing

function computeLayout() {
  const { nx, ny } = state.map.grid;
  const available = Math.max(320, Math.min(window.innerWidth - 380, 1100));
  const cell = Math.max(2, Math.floor(Math.min((available - MARGIN.left - MARGIN.right) / nx, 760 / ny)));
  return {
    cell,
    left: MARGIN.left,
    top: MARGIN.top,
    width: MARGIN.left + nx * cell + MARGIN.right,
    height: MARGIN.top + ny * cell + MARGIN.bottom,
  };
}

// Pixel of a point in metres (cell centres are the centres of the drawn squares).
function toPixel(x, y) {
  const g = state.map.grid;
  const L = state.layout;
  return [
    L.left + ((x - g.x_min) / g.resolution_m + 0.5) * L.cell,
    L.top + (g.ny - 1 - (y - g.y_min) / g.resolution_m + 0.5) * L.cell,
  ];
}

function cellAt(px, py) {
  const g = state.map.grid;
  const L = state.layout;
  const i = Math.floor((px - L.left) / L.cell);
  const j = g.ny - 1 - Math.floor((py - L.top) / L.cell);
  return i >= 0 && j >= 0 && i < g.nx && j < g.ny ? [i, j] : null;
}

function niceTicks(low, high, target) {
  const raw = Math.max((high - low) / target, Number.MIN_VALUE);
  const magnitude = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 5, 10].map((m) => m * magnitude).find((s) => s >= raw);
  const ticks = [];
  for (let k = Math.ceil(low / step); k <= Math.floor(high / step); k++) ticks.push(+(k * step).toFixed(10));
  return ticks;
}

function layerValues() {
  const map = state.map;
  if (state.layer !== "gap" || !map.upper_bound) return { values: map.values, low: map.stats.min, high: map.stats.max, unit: map.unit };
  let high = 0;
  const values = map.values.map((row, i) =>
    row.map((v, j) => {
      const u = map.upper_bound[i][j];
      if (v === null || u === null) return null;
      high = Math.max(high, u - v);
      return u - v;
    }),
  );
  return { values, low: 0, high: high || 1e-12, unit: `gap, ${map.unit}` };
}

function draw() {
  const canvas = $("map");
  const ctx = canvas.getContext("2d");
  if (!state.map) return;
  const L = (state.layout = computeLayout());
  if (canvas.width !== L.width || canvas.height !== L.height) {
    canvas.width = L.width;
    canvas.height = L.height;
  }
  Object.assign(canvas.dataset, { left: L.left, top: L.top, cell: L.cell });
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, L.width, L.height);
  const { nx, ny } = state.map.grid;
  const { values, low, high, unit } = layerValues();
  const span = high > low ? high - low : 1;
  const image = ctx.createImageData(nx * L.cell, ny * L.cell);
  const dimming = state.layer === "value" && state.threshold !== null;
  // A gain map has a value in every free cell, so its nulls are exactly the occupied cells
  // (boxes, walls, floor-plan pixels): grey. On rate maps a null may also be a cell where no
  // configuration serves every SRU: black.
  const empty = state.map.key.kind === "gain" ? [128, 128, 128] : [0, 0, 0];
  for (let i = 0; i < nx; i++) {
    for (let j = 0; j < ny; j++) {
      const v = values[i][j];
      let rgb = v === null ? empty : VIRIDIS[Math.round(Math.min(Math.max((v - low) / span, 0), 1) * 255)];
      if (v !== null && dimming && v < state.threshold) rgb = rgb.map((c) => Math.floor(c * DIM));
      const x0 = i * L.cell;
      const y0 = (ny - 1 - j) * L.cell;
      for (let y = y0; y < y0 + L.cell; y++) {
        let at = (y * nx * L.cell + x0) * 4;
        for (let x = 0; x < L.cell; x++, at += 4) {
          image.data[at] = rgb[0];
          image.data[at + 1] = rgb[1];
          image.data[at + 2] = rgb[2];
          image.data[at + 3] = 255;
        }
      }
    }
  }
  ctx.putImageData(image, L.left, L.top);
  drawObstacles(ctx);
  drawAxes(ctx, nx, ny);
  drawColourBar(ctx, low, high, unit, dimming ? state.threshold : null);
  drawDevices(ctx);
  drawPath(ctx);
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

function drawAxes(ctx, nx, ny) {
  const L = state.layout;
  const g = state.map.grid;
  ctx.strokeStyle = "#000";
  ctx.fillStyle = "#000";
  ctx.lineWidth = 1;
  ctx.strokeRect(L.left - 0.5, L.top - 0.5, nx * L.cell + 1, ny * L.cell + 1);
  ctx.font = "12px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "top";
  const xMax = g.x_min + (nx - 1) * g.resolution_m;
  const yMax = g.y_min + (ny - 1) * g.resolution_m;
  for (const x of niceTicks(g.x_min, xMax, 8)) {
    const [px] = toPixel(x, g.y_min);
    ctx.fillRect(Math.round(px), L.top + ny * L.cell, 1, 5);
    ctx.fillText(String(x), px, L.top + ny * L.cell + 7);
  }
  ctx.fillText("x (m)", L.left + (nx * L.cell) / 2, L.top + ny * L.cell + 24);
  ctx.textAlign = "right";
  ctx.textBaseline = "middle";
  for (const y of niceTicks(g.y_min, yMax, 8)) {
    const [, py] = toPixel(g.x_min, y);
    ctx.fillRect(L.left - 5, Math.round(py), 5, 1);
    ctx.fillText(String(y), L.left - 8, py);
  }
  ctx.textAlign = "left";
  ctx.fillText("y (m)", 4, 10);
}

function drawColourBar(ctx, low, high, unit, threshold) {
  const L = state.layout;
  const { ny } = state.map.grid;
  const x0 = L.left + state.map.grid.nx * L.cell + 18;
  const h = ny * L.cell;
  for (let row = 0; row < h; row++) {
    const rgb = VIRIDIS[Math.round((1 - row / Math.max(h - 1, 1)) * 255)];
    ctx.fillStyle = `rgb(${rgb})`;
    ctx.fillRect(x0, L.top + row, 16, 1);
  }
  ctx.strokeStyle = "#000";
  ctx.strokeRect(x0 - 0.5, L.top - 0.5, 17, h + 1);
  ctx.fillStyle = "#000";
  ctx.textAlign = "left";
  ctx.textBaseline = "middle";
  const span = high > low ? high - low : 1;
  const yOf = (v) => L.top + ((high - v) / span) * (h - 1);
  const marks = [low, high, ...niceTicks(low, high, 5).filter((t) => t - low > span * 0.08 && high - t > span * 0.08)];
  for (const v of marks) {
    ctx.fillRect(x0 + 16, Math.round(yOf(v)), 4, 1);
    ctx.fillText(+v.toPrecision(4) + "", x0 + 23, yOf(v));
  }
  if (threshold !== null && threshold >= low && threshold <= high) {
    ctx.fillRect(x0 - 4, Math.round(yOf(threshold)) - 1, 24, 3);
  }
  ctx.textBaseline = "bottom";
  ctx.fillText(unit, x0 - 4, L.top - 6);
}

function drawMarker(ctx, x, y, shape, fill, label) {
  const [px, py] = toPixel(x, y);
  const r = Math.max(5, state.layout.cell * 0.35);
  ctx.fillStyle = fill;
  ctx.strokeStyle = "#000";
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  if (shape === "square") ctx.rect(px - r, py - r, 2 * r, 2 * r);
  else ctx.arc(px, py, r, 0, 2 * Math.PI);
  ctx.fill();
  ctx.stroke();
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
  const s = state.scenario;
  // One surface is written `irs`, several `irss` (the canonical form).
  const surfaces = s.irs ? [s.irs] : s.irss || [];
  surfaces.forEach((irs, k) => {
    const along = [-irs.normal[1], irs.normal[0]];
    const norm = Math.hypot(...along) || 1;
    const half = Math.max((irs.nx_sub * (irs.sub_pitch_m || 0)) / 2, 1.5 * state.map.grid.resolution_m);
    const [ax, ay] = toPixel(irs.center[0] - (half * along[0]) / norm, irs.center[1] - (half * along[1]) / norm);
    const [bx, by] = toPixel(irs.center[0] + (half * along[0]) / norm, irs.center[1] + (half * along[1]) / norm);
    ctx.strokeStyle = "#e600e6";
    ctx.lineWidth = Math.max(4, state.layout.cell * 0.4);
    ctx.lineCap = "round";
    ctx.beginPath();
    ctx.moveTo(ax, ay);
    ctx.lineTo(bx, by);
    ctx.stroke();
    drawMarker(ctx, irs.center[0], irs.center[1], "circle", "#e600e6", surfaces.length > 1 ? `IRS ${k}` : "IRS");
  });
  const aps = s.ap ? [s.ap] : s.aps || [];
  aps.forEach((ap, k) => drawMarker(ctx, ap.position[0], ap.position[1], "square", "#fff", aps.length > 1 ? `AP ${k}` : "AP"));
  (s.srus || []).forEach((sru, k) => drawMarker(ctx, sru.position[0], sru.position[1], "circle", "#fff", `SRU${k}`));
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
  }
  if (state.start) drawMarker(ctx, state.start[0], state.start[1], "circle", "#00c800", "start");
  if (state.goal) drawMarker(ctx, state.goal[0], state.goal[1], "circle", "#e60000", "goal");
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
  const lines = [`(${w.x}, ${w.y}) m: ${w.value.toFixed(3)} ${unit}`];
  if (w.power_w) lines.push(`powers (W): ${w.power_w.map((p) => p.toExponential(2)).join(", ")}`);
  if (w.decoding_order) lines.push(`decoding order: ${w.decoding_order.join(" → ")}`);
  // One phase vector per IRS, in scenario order.
  const surfaces = w.irs_phases_rad;
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
  tip.style.left = `${px + 14}px`;
  tip.style.top = `${py + 14}px`;
  tip.hidden = false;
}

// The pointer's position in canvas pixels.
function pointer(event) {
  const rect = $("map").getBoundingClientRect();
  return [event.clientX - rect.left, event.clientY - rect.top];
}

function onPointerMove(event) {
  if (!state.map) return;
  const [px, py] = pointer(event);
  const cell = cellAt(px, py);
  if (cell) {
    const [i, j] = cell;
    const v = state.map.values[i][j];
    const [x, y] = [state.map.grid.x_min + i * state.map.grid.resolution_m, state.map.grid.y_min + j * state.map.grid.resolution_m];
    $("cursor").textContent = `Cell (${i}, ${j}) at (${+x.toFixed(3)}, ${+y.toFixed(3)}) m: ${v === null ? "no value (occupied or unserviceable)" : `${v.toFixed(3)} ${state.map.unit}`}`;
  }
  const w = nearestWaypoint(px, py);
  if (w) showTooltip(w, px, py);
  else $("tooltip").hidden = true;
}

function onClick(event) {
  if (!state.map) return;
  const cell = cellAt(...pointer(event));
  if (!cell) return;
  // A click means "this cell": use its centre, as the planner would snap it anyway.
  const g = state.map.grid;
  const point = [g.x_min + cell[0] * g.resolution_m, g.y_min + cell[1] * g.resolution_m].map((v) => +v.toFixed(6));
  if (!state.start || state.goal) {
    clearPath();
    state.start = point;
    $("start").value = formatPoint(point);
    say("Start set; click the goal.");
    draw();
  } else {
    state.goal = point;
    $("goal").value = formatPoint(point);
    planPath().catch(report);
  }
}

function setLayer(layer) {
  state.layer = layer;
  document.querySelector(`input[name=layer][value=${layer}]`).checked = true;
  draw();
}

function report(error) {
  say(error.message || String(error), true);
}

function refresh() {
  draw();
  updateDownloads();
  return updateCoverage();
}

function wire() {
  const guard = (f) => (...args) => Promise.resolve(f(...args)).catch(report);
  $("scenario").addEventListener("change", guard((e) => chooseScenario(e.target.value)));
  $("token").value = sessionStorage.getItem("irs-planner-token") || "";
  for (const id of ["download-map", "download-png"]) $(id).addEventListener("click", downloadWithToken);
  $("token").addEventListener("change", () => sessionStorage.setItem("irs-planner-token", $("token").value.trim()));
  $("register").addEventListener("click", guard(registerScenario));
  for (const id of ["kind", "phases", "access"]) $(id).addEventListener("change", guard(buildMap));
  $("build").addEventListener("click", guard(buildMap));
  $("cancel").addEventListener("click", guard(cancelJob));
  $("threshold-range").addEventListener("input", (e) => setThreshold(Number(e.target.value)));
  $("threshold").addEventListener("change", (e) => {
    const v = Number(e.target.value);
    if (Number.isFinite(v)) setThreshold(v);
  });
  document.querySelectorAll("input[name=layer]").forEach((r) => r.addEventListener("change", (e) => setLayer(e.target.value)));
  $("plan").addEventListener("click", guard(() => {
    state.start = parsePoint($("start").value);
    state.goal = parsePoint($("goal").value);
    if (!state.start || !state.goal) throw new Error('Start and goal are "x,y" in metres, e.g. -10,0.');
    return planPath();
  }));
  $("clear").addEventListener("click", clearPath);
  $("path-shape").addEventListener("change", guard(() => (state.start && state.goal ? planPath() : null)));
  const canvas = $("map");
  canvas.addEventListener("mousemove", onPointerMove);
  canvas.addEventListener("mouseleave", () => ($("tooltip").hidden = true));
  canvas.addEventListener("click", onClick);
  window.addEventListener("resize", draw);
}

wire();
loadScenarios().catch(report);
