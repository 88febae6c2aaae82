// parknss simulator page: pick or edit a scene, plan it, run it through plants, play back.
// Talks to the JSON API of parknss.web.app; no external libraries. Units: m, rad, s in the
// API; the plots show km/h, deg/s, m/s², deg.
"use strict";

const KMH_PER_MS = 3.6;
const DEG_PER_RAD = 180 / Math.PI;
const OBSTACLE_FILL = { car: "#a9b4c0", curb: "#7f8c8d", barrier: "#c0392b" };
const HANDLE_AHEAD_M = 0.9; // rotation handle ahead of the front bumper, m
const HANDLE_RADIUS_PX = 8;
const COLLISION_COLOUR = "#e60000";

const PLOTS = {
  vx: { label: "vx [km/h] · dashed: speed request", scale: KMH_PER_MS, command: "speed_req" },
  yaw_rate: { label: "yaw rate [°/s]", scale: DEG_PER_RAD },
  ax: { label: "ax [m/s²]", scale: 1, smooth: true },
  ay: { label: "ay [m/s²]", scale: 1, smooth: true },
  steer: { label: "steering-wheel angle [°] · dashed: command", scale: 1, command: "steer_cmd" },
  gear: {
    label: "gear · dashed: command",
    scale: 1,
    step: true,
    command: "gear_cmd",
    ticks: [[-1, "R"], [0, "P/N"], [1, "D"]],
  },
};

const state = {
  health: null,
  grid: "36",
  index: 0,
  cells: [],
  scene: null, // scene JSON being shown
  custom: false, // true when the scene came from a file
  baseStart: null, // the scene's own start pose
  start: null, // the start pose used (edited or not)
  plan: null,
  runs: [], // {plant, colour, outcome, series} in request order
  t: 0,
  tmax: 0,
  playing: false,
  speed: 1,
  smooth: false, // show ax, ay through a moving average
  drag: null,
  token: 0, // newest request; older answers are dropped
  abort: null, // AbortController of the request in flight (the Cancel button)
  busyTimer: null,
  cancelled: false,
  fileScene: null, // {scene, name, notes} of the last scene file opened
  view: null, // world -> canvas transform
};

const $ = (id) => document.getElementById(id);

// ---------------------------------------------------------------------------------------
// API

async function api(path, body, signal) {
  const opts = body === undefined ? { signal } : {
    method: "POST",
    headers: { "Content-Type": "application/json" },
    body: JSON.stringify(body),
    signal,
  };
  let res;
  try {
    res = await fetch(path, opts);
  } catch (err) {
    if (err.name === "AbortError") {
      const e = new Error("cancelled");
      e.cancelled = true;
      throw e;
    }
    throw new Error(`cannot reach the server (${err.message})`);
  }
  let doc = null;
  try {
    doc = await res.json();
  } catch (err) {
    doc = null;
  }
  if (!res.ok) {
    const msg = doc && doc.error ? doc.error : `HTTP ${res.status}`;
    const e = new Error(msg);
    e.status = res.status;
    throw e;
  }
  return doc;
}

function sceneRequest() {
  const req = state.custom ? { scene: state.scene } : { grid: state.grid, index: state.index };
  if (state.start && !samePose(state.start, state.baseStart)) req.start = state.start;
  return req;
}

function samePose(a, b) {
  return !!a && !!b && a.every((v, i) => Math.abs(v - b[i]) < 1e-9);
}

function showError(msg, info = false) {
  const box = $("error");
  box.textContent = msg;
  box.classList.toggle("info", info);
  box.hidden = false;
}

function clearError() {
  $("error").hidden = true;
  $("error").textContent = "";
}

// The busy badge: what runs, for how long (s) against the server's budget, and Cancel.
function setBusy(text, budgetS) {
  clearInterval(state.busyTimer);
  state.busyTimer = null;
  $("busy").hidden = !text;
  $("plan-btn").disabled = !!text;
  $("run-btn").disabled = !!text;
  if (!text) return;
  const t0 = performance.now();
  const show = () => {
    const s = ((performance.now() - t0) / 1000).toFixed(0);
    $("busy-text").textContent = `${text} ${s} s` + (budgetS ? ` of at most ${budgetS} s` : "");
  };
  show();
  state.busyTimer = setInterval(show, 500);
}

// A new AbortController for the request about to start (aborts the one before).
function newRequest() {
  if (state.abort) state.abort.abort();
  state.abort = new AbortController();
  return state.abort.signal;
}

// Cancel: stop waiting for the answer in flight and drop it. Server threads cannot be
// interrupted, so the server finishes the computation in the background (a plan is then
// cached: planning the same scene again answers at once).
function cancelRequest() {
  if (state.abort) state.abort.abort();
  state.abort = null;
  state.token++;
  if (state.planning) state.plan = null; // the plan shown was for the scene before the edit
  state.planning = false;
  state.cancelled = true;
  setBusy("");
  renderPlanInfo();
  render();
  showError("cancelled: the server finishes the computation in the background " +
    "(a plan is then cached, so planning this scene again answers at once)", true);
}

function budget(kind) {
  return state.health ? state.health[`${kind}_budget_s`] : null;
}

// ---------------------------------------------------------------------------------------
// Loading scenes and cells

async function loadHealth() {
  try {
    state.health = await api("/api/health");
    const h = state.health;
    const ready = h.plants.filter((p) => p.available).map((p) => p.kind);
    $("server-status").textContent = `parknss ${h.version} · plants ready: ${ready.join(", ")}`;
    $("smooth-label").textContent = `smooth ax, ay (${h.accel_smoothing_s} s)`;
    renderPlants();
  } catch (err) {
    $("server-status").textContent = "server unreachable";
    $("server-status").classList.add("bad");
    showError(`health check failed: ${err.message}`);
  }
}

function renderPlants() {
  const box = $("plants");
  box.textContent = "";
  const chainReady = state.health.plants.some((p) => p.kind === "chain" && p.available);
  for (const p of state.health.plants) {
    const row = document.createElement("div");
    row.className = "plant";
    const cb = document.createElement("input");
    cb.type = "checkbox";
    cb.id = `plant-${p.kind}`;
    cb.value = p.kind;
    cb.checked = p.kind === "kinematic" || (p.kind === "chain" && chainReady);
    const sw = document.createElement("span");
    sw.className = "swatch";
    sw.style.background = p.colour;
    const lab = document.createElement("label");
    lab.htmlFor = cb.id;
    lab.textContent = p.kind === "chain" ? "chain (learned)" : p.kind;
    row.append(cb, sw, lab);
    if (!p.available) {
      const note = document.createElement("span");
      note.className = "note";
      note.textContent = "unavailable";
      note.title = p.reason;
      row.append(note);
    }
    box.append(row);
  }
}

function plantColour(kind) {
  const p = state.health && state.health.plants.find((q) => q.kind === kind);
  return p ? p.colour : "#34495e";
}

async function loadCells() {
  const doc = await api(`/api/cells?grid=${state.grid}`);
  state.cells = doc.cells;
  const sel = $("cell");
  sel.textContent = "";
  for (const c of doc.cells) {
    const o = document.createElement("option");
    o.value = String(c.index);
    o.textContent = `${c.index} · ${c.name}`;
    sel.append(o);
  }
  if (state.index >= doc.cells.length) state.index = 0;
  sel.value = String(state.index);
}

async function loadCell() {
  clearError();
  const tok = ++state.token;
  state.plan = null;
  state.planning = true;
  renderPlanInfo();
  try {
    const doc = await api(`/api/scene?grid=${state.grid}&index=${state.index}`);
    if (tok !== state.token) return;
    writeAddress();
    setScene(doc.scene, false);
    await plan();
  } catch (err) {
    if (tok !== state.token) return;
    state.planning = false;
    renderPlanInfo();
    showError(err.message);
  }
}

function setScene(scene, custom) {
  if (!custom) showNotes(null, []);
  state.scene = scene;
  state.custom = custom;
  state.baseStart = scene.start.slice();
  state.start = scene.start.slice();
  state.plan = null;
  clearRuns();
  fitView();
  updateStartReadout();
  renderPlanInfo();
  render();
}

// ---------------------------------------------------------------------------------------
// Plan and run

async function plan() {
  clearError();
  const tok = ++state.token;
  const signal = newRequest();
  setBusy("planning…", budget("plan"));
  state.planning = true;
  state.cancelled = false;
  renderPlanInfo();
  try {
    const doc = await api("/api/plan", sceneRequest(), signal);
    if (tok !== state.token) return;
    state.plan = doc;
    if (!doc.plannable) showError(`no plan: ${doc.reason}`);
  } catch (err) {
    if (tok !== state.token) return;
    state.plan = null;
    showError(err.message);
  } finally {
    if (tok === state.token) {
      setBusy("");
      state.planning = false;
    }
  }
  renderPlanInfo();
  render();
}

function selectedPlants() {
  return [...document.querySelectorAll("#plants input:checked")].map((cb) => cb.value);
}

// The seed box: null when empty, undefined (an error shown) when not a whole number.
function readSeed() {
  const seedText = $("seed").value.trim();
  const seed = seedText === "" ? null : Number(seedText);
  if (seed !== null && !Number.isInteger(seed)) {
    showError("the seed must be a whole number");
    return undefined;
  }
  return seed;
}

// A new batch of runs: the request token and abort signal, the previous runs cleared.
function startRuns() {
  const tok = ++state.token;
  const signal = newRequest();
  state.cancelled = false;
  clearRuns();
  return { tok, signal };
}

async function runSelected() {
  clearError();
  const plants = selectedPlants();
  if (!plants.length) {
    showError("select at least one plant");
    return;
  }
  const seed = readSeed();
  if (seed === undefined) return;
  const { tok, signal } = startRuns();
  const errors = [];
  for (const [i, plant] of plants.entries()) {
    const of = plants.length > 1 ? ` (${i + 1} of ${plants.length})` : "";
    setBusy(`running ${plant}${of}…`, budget("simulate"));
    const req = { ...sceneRequest(), plant };
    if (seed !== null) req.seed = seed;
    try {
      const doc = await api("/api/simulate", req, signal);
      if (tok !== state.token) return;
      state.plan = doc.plan;
      renderPlanInfo();
      if (doc.series) {
        // a playback that reached the end of the shorter runs goes on to the new end
        const ended = state.runs.length > 0 && !state.playing && state.t >= state.tmax;
        state.runs.push({ plant, colour: plantColour(plant), outcome: doc.outcome, series: doc.series });
        state.tmax = Math.max(state.tmax, ...doc.series.t.filter((v) => v !== null));
        if (state.runs.length === 1) startPlayback();
        else if (ended) {
          state.playing = true;
          state.lastFrame = null;
        }
        updatePlayer();
      } else {
        errors.push(`${plant}: not plannable (${doc.plan.reason})`);
      }
      addOutcomeRow(plant, doc.outcome, null);
    } catch (err) {
      if (tok !== state.token) return;
      errors.push(`${plant}: ${err.message}`);
      addOutcomeRow(plant, null, err.message);
    }
    renderPlots();
    render();
  }
  setBusy("");
  if (errors.length) showError(errors.join(" · "));
}

// ---------------------------------------------------------------------------------------
// Fidelity: the plan under the chain and the truth, scored as parknss fidelity scores a cell

async function runFidelity() {
  clearError();
  const seed = readSeed();
  if (seed === undefined) return;
  const { tok, signal } = startRuns();
  setBusy("running the chain and the truth…", budget("simulate"));
  const req = sceneRequest();
  if (seed !== null) req.seed = seed;
  try {
    const doc = await api("/api/fidelity", req, signal);
    if (tok !== state.token) return;
    state.plan = doc.plan;
    renderPlanInfo();
    for (const [plant, run] of [["chain", doc.chain], ["reference", doc.truth]]) {
      if (run.series) {
        state.runs.push({ plant, colour: plantColour(plant), outcome: run.outcome, series: run.series });
        state.tmax = Math.max(state.tmax, ...run.series.t.filter((v) => v !== null));
      }
      addOutcomeRow(plant, run.outcome, null);
    }
    if (state.runs.length) startPlayback();
    updatePlayer();
    if (doc.fidelity) renderFidelity(doc);
    else showError(`not plannable (${doc.plan.reason})`);
  } catch (err) {
    if (tok !== state.token) return;
    showError(err.message);
  }
  setBusy("");
  renderPlots();
  render();
}

function tableRow(texts, title) {
  const tr = document.createElement("tr");
  for (const text of texts) {
    const td = document.createElement("td");
    td.textContent = text;
    tr.append(td);
  }
  if (title) tr.title = title;
  return tr;
}

function fidelityRow(label, chain, truth, diff, title) {
  return tableRow([label, chain, truth, diff], title);
}

function renderFidelity(doc) {
  const f = doc.fidelity;
  const body = $("fidelity").querySelector("tbody");
  body.textContent = "";
  const pm = (v, d) => (v === null || v === undefined ? "–" : (v > 0 ? "+" : "") + fmt(v, d));
  body.append(
    fidelityRow("outcome", f.chain_reason, f.truth_reason, f.outcome_agree ? "same" : "differs"),
    fidelityRow("time [s]", fmt(f.chain_duration_s, 1), fmt(f.truth_duration_s, 1),
      `× ${fmt(f.duration_ratio, 3)}`),
    fidelityRow("goal err [cm]", fmt(f.chain_goal_cm, 2), fmt(f.truth_goal_cm, 2),
      pm(f.goal_diff_cm, 2)),
    fidelityRow("heading [°]", "", "", pm(f.heading_diff_deg, 2), "heading error, chain - truth"),
    fidelityRow("clearance [cm]", fmt(f.chain_clearance_cm, 1), fmt(f.truth_clearance_cm, 1),
      pm(f.clearance_diff_cm, 1)),
    fidelityRow("forward / reverse [s]",
      `${fmt(f.chain_forward_s, 1)} / ${fmt(f.chain_reverse_s, 1)}`,
      `${fmt(f.truth_forward_s, 1)} / ${fmt(f.truth_reverse_s, 1)}`, "",
      "time with the tracker requesting forward / reverse"),
    fidelityRow("gear changes", String(f.chain_gear_changes), String(f.truth_gear_changes),
      f.gear_sequence_agree ? `same, |Δt| ${fmt(f.gear_timing_mean_s, 2)} s` : "differ"),
    fidelityRow("ISO vx / ω_z", "", "", `${fmt(f.iso_vx, 3)} / ${fmt(f.iso_yaw_rate, 3)}`,
      "ISO/TS 18571 rating of the chain's trace against the truth's (1 = identical)"),
  );
  const targets = $("fidelity-targets").querySelector("tbody");
  targets.textContent = "";
  for (const t of doc.targets) {
    const tr = document.createElement("tr");
    const verdict = document.createElement("td");
    verdict.textContent = t.passed ? "PASS" : "FAIL";
    verdict.className = t.passed ? "result-completed" : "result-failed";
    const what = document.createElement("td");
    what.textContent = `${t.label}: ${fmt(t.measured, 3)} (target ${t.limit})`;
    tr.append(verdict, what);
    targets.append(tr);
  }
  const cells = $("fidelity-cells").querySelector("tbody");
  const iso = f.iso_vx === null || f.iso_yaw_rate === null ? null : (f.iso_vx + f.iso_yaw_rate) / 2;
  const abs = (v) => (v === null || v === undefined ? null : Math.abs(v));
  cells.append(tableRow([f.cell, f.outcome_agree ? "yes" : "no", fmt(f.duration_ratio, 3),
    fmt(abs(f.goal_diff_cm), 2), fmt(abs(f.clearance_diff_cm), 1), fmt(iso, 3)],
  `noise seed ${doc.seed}`));
  $("fidelity-section").hidden = false;
}

function clearRuns() {
  for (const id of ["fidelity", "fidelity-targets"]) $(id).querySelector("tbody").textContent = "";
  state.runs = [];
  state.t = 0;
  state.tmax = 0;
  state.playing = false;
  $("outcome").querySelector("tbody").textContent = "";
  updatePlayer();
  renderPlots();
}

function planTime(seconds) {
  return seconds < 1 ? `${fmt(seconds * 1000, 0)} ms` : `${fmt(seconds, 1)} s`;
}

function fmt(v, digits) {
  return v === null || v === undefined ? "–" : Number(v).toFixed(digits);
}

function addOutcomeRow(plant, o, error) {
  const tr = document.createElement("tr");
  const name = document.createElement("td");
  const dot = document.createElement("span");
  dot.className = "dot";
  dot.style.background = plantColour(plant);
  name.append(dot, plant);
  tr.append(name);
  if (error) {
    const td = document.createElement("td");
    td.colSpan = 5;
    td.className = "err";
    td.textContent = error;
    tr.append(td);
  } else {
    const cells = [
      [o.reason, o.completed ? "result-completed" : "result-failed"],
      [fmt(o.goal_error_cm, 1)],
      [fmt(o.heading_error_deg, 1)],
      [fmt(o.clearance_cm, 1)],
      [fmt(o.duration_s, 1)],
    ];
    for (const [text, cls] of cells) {
      const td = document.createElement("td");
      td.textContent = text;
      if (cls) td.className = cls;
      tr.append(td);
    }
    tr.title = `driven ${fmt(o.driven_length_m, 2)} m, ${o.gear_changes} gear changes, ` +
      `simulated ${fmt(o.realtime_factor, 0)}× real time`;
  }
  $("outcome").querySelector("tbody").append(tr);
}

function renderPlanInfo() {
  const dl = $("plan-info");
  dl.textContent = "";
  const p = state.plan;
  const idle = state.scene ? "not planned" : "–";
  const status = state.planning ? "planning…" : state.cancelled ? "cancelled" : idle;
  const rows = !p ? [["status", status]] : [
    ["scene", p.name],
    ["status", p.plannable ? "planned" : `no plan: ${p.reason}`],
    ["path", p.plannable ? `${fmt(p.length_m, 2)} m, ${p.cusps} cusp${p.cusps === 1 ? "" : "s"}` : "–"],
    ["clearance", p.min_clearance_cm === null ? "–" : `${fmt(p.min_clearance_cm, 1)} cm`],
    ["stage", p.plannable ? (p.refined ? "Hybrid A* + refinement" : "Hybrid A* + Reeds-Shepp") : "–"],
    ["plan time", `${planTime(p.plan_s)}${p.cached ? " (cached)" : ""}`],
  ];
  for (const [k, v] of rows) {
    const dt = document.createElement("dt");
    dt.textContent = k;
    const dd = document.createElement("dd");
    dd.textContent = v;
    dl.append(dt, dd);
  }
}

// ---------------------------------------------------------------------------------------
// Playback

function startPlayback() {
  state.t = 0;
  state.playing = true;
  state.lastFrame = null;
  updatePlayer();
}

// The time label: playback time / end of the longest run; its tooltip has each run's end.
function updatePlayer() {
  $("play").textContent = state.playing ? "❚❚" : "▶";
  $("scrub").value = state.tmax > 0 ? String(Math.round((state.t / state.tmax) * 1000)) : "0";
  $("time").textContent = `${state.t.toFixed(1)} / ${state.tmax.toFixed(1)} s`;
  $("time").title = state.runs.map((r) => `${r.plant} ${runEnd(r).toFixed(1)} s`).join(" · ");
}

function runEnd(run) {
  const ts = run.series.t;
  return ts[ts.length - 1];
}

function frame(now) {
  if (state.playing) {
    if (state.lastFrame !== null && state.lastFrame !== undefined) {
      state.t += ((now - state.lastFrame) / 1000) * state.speed;
    }
    state.lastFrame = now;
    if (state.t >= state.tmax) {
      state.t = state.tmax;
      state.playing = false;
    }
    updatePlayer();
    render();
    drawPlotCursors();
  } else {
    state.lastFrame = null;
  }
  requestAnimationFrame(frame);
}

// Index i with t[i] <= t < t[i+1] (binary search), and the fraction between them.
function locate(ts, t) {
  let lo = 0;
  let hi = ts.length - 1;
  if (t <= ts[0]) return [0, 0];
  if (t >= ts[hi]) return [hi, 0];
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (ts[mid] <= t) lo = mid;
    else hi = mid;
  }
  return [lo, (t - ts[lo]) / (ts[lo + 1] - ts[lo])];
}

function sampleAt(series, name, i, f) {
  const a = series[name][i];
  const b = series[name][Math.min(i + 1, series[name].length - 1)];
  return a + (b - a) * f;
}

function poseAt(run, t) {
  const s = run.series;
  const [i, f] = locate(s.t, t);
  return {
    x: sampleAt(s, "x", i, f),
    y: sampleAt(s, "y", i, f),
    h: sampleAt(s, "heading", i, f),
    steer: sampleAt(s, "steer", i, f),
    index: i,
  };
}

// ---------------------------------------------------------------------------------------
// Top view

function canvasSize(canvas, cssHeight) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth;
  if (cssHeight !== undefined) canvas.style.height = `${cssHeight}px`;
  const h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  return { ctx, w, h };
}

// The box shown: the map, or on a map larger than health.view_zoom_above_m (a CommonRoad
// scenario of a whole car park) the problem's region: start and goal grown by a car length
// and health.view_zoom_pad_m, within the map (the plan figures zoom the same way).
function viewBox() {
  const b = state.scene.bounds;
  const hz = state.health || {};
  const above = hz.view_zoom_above_m ?? Infinity;
  if (Math.max(b[2] - b[0], b[3] - b[1]) <= above) return b;
  const grow = (hz.view_zoom_pad_m ?? 10) + (hz.vehicle ? hz.vehicle.length_m : 5);
  const xs = [state.scene.start[0], state.scene.goal[0]];
  const ys = [state.scene.start[1], state.scene.goal[1]];
  return [
    Math.max(b[0], Math.min(...xs) - grow),
    Math.max(b[1], Math.min(...ys) - grow),
    Math.min(b[2], Math.max(...xs) + grow),
    Math.min(b[3], Math.max(...ys) + grow),
  ];
}

function fitView() {
  if (!state.scene) return;
  const canvas = $("view");
  const [xmin, ymin, xmax, ymax] = viewBox();
  const w = canvas.clientWidth || 800;
  const pad = 24;
  const k = (w - 2 * pad) / (xmax - xmin);
  const h = Math.min(Math.max((ymax - ymin) * k + 2 * pad, 240), window.innerHeight * 0.62);
  const kk = Math.min(k, (h - 2 * pad) / (ymax - ymin));
  state.view = {
    k: kk,
    ox: (w - (xmax - xmin) * kk) / 2 - xmin * kk,
    oy: (h - (ymax - ymin) * kk) / 2 + ymax * kk,
    h,
  };
}

const sx = (x) => state.view.ox + x * state.view.k;
const sy = (y) => state.view.oy - y * state.view.k;
const wx = (px) => (px - state.view.ox) / state.view.k;
const wy = (py) => (state.view.oy - py) / state.view.k;

function carCorners(x, y, h, grow = 0) {
  const v = state.health.vehicle;
  const rear = -v.rear_overhang_m - grow;
  const front = v.length_m - v.rear_overhang_m + grow;
  const hw = v.width_m / 2 + grow;
  const c = Math.cos(h);
  const s = Math.sin(h);
  return [[rear, -hw], [front, -hw], [front, hw], [rear, hw]].map(([a, b]) => [
    x + c * a - s * b,
    y + s * a + c * b,
  ]);
}

function polyPath(ctx, pts) {
  ctx.beginPath();
  pts.forEach(([x, y], i) => (i ? ctx.lineTo(sx(x), sy(y)) : ctx.moveTo(sx(x), sy(y))));
  ctx.closePath();
}

function drawGrid(ctx) {
  const [xmin, ymin, xmax, ymax] = state.scene.bounds;
  ctx.fillStyle = "#fbfcfd";
  ctx.fillRect(sx(xmin), sy(ymax), (xmax - xmin) * state.view.k, (ymax - ymin) * state.view.k);
  ctx.lineWidth = 1;
  for (let gx = Math.ceil(xmin); gx <= xmax; gx++) {
    ctx.strokeStyle = gx % 5 === 0 ? "#dfe5ec" : "#eef1f5";
    ctx.beginPath();
    ctx.moveTo(sx(gx), sy(ymin));
    ctx.lineTo(sx(gx), sy(ymax));
    ctx.stroke();
  }
  for (let gy = Math.ceil(ymin); gy <= ymax; gy++) {
    ctx.strokeStyle = gy % 5 === 0 ? "#dfe5ec" : "#eef1f5";
    ctx.beginPath();
    ctx.moveTo(sx(xmin), sy(gy));
    ctx.lineTo(sx(xmax), sy(gy));
    ctx.stroke();
  }
  ctx.strokeStyle = "#9aa7b5";
  ctx.strokeRect(sx(xmin), sy(ymax), (xmax - xmin) * state.view.k, (ymax - ymin) * state.view.k);
  ctx.fillStyle = "#8593a3";
  ctx.font = "10px system-ui, sans-serif";
  for (let gx = Math.ceil(xmin / 5) * 5; gx <= xmax; gx += 5) {
    ctx.fillText(`${gx}`, sx(gx) + 2, sy(ymin) + 11);
  }
  for (let gy = Math.ceil(ymin / 5) * 5; gy <= ymax; gy += 5) {
    ctx.fillText(`${gy}`, sx(xmin) - 18, sy(gy) + 3);
  }
  // 1 m / 5 m scale bar
  const x0 = sx(xmin) + 10;
  const y0 = sy(ymax) + 14;
  ctx.strokeStyle = "#5b6b7c";
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x0, y0);
  ctx.lineTo(x0 + 5 * state.view.k, y0);
  ctx.stroke();
  ctx.fillStyle = "#5b6b7c";
  ctx.fillText("5 m", x0 + 5 * state.view.k + 4, y0 + 3);
}

function drawPath(ctx, segments, colour, width, alpha) {
  ctx.save();
  ctx.globalAlpha = alpha;
  ctx.strokeStyle = colour;
  ctx.lineWidth = width;
  for (const seg of segments) {
    ctx.setLineDash(seg.direction > 0 ? [] : [7, 5]);
    ctx.beginPath();
    seg.poses.forEach(([x, y], i) => (i ? ctx.lineTo(sx(x), sy(y)) : ctx.moveTo(sx(x), sy(y))));
    ctx.stroke();
  }
  ctx.restore();
}

function drawCar(ctx, x, y, h, colour, opts = {}) {
  const pts = carCorners(x, y, h);
  ctx.save();
  polyPath(ctx, pts);
  if (opts.fill) {
    ctx.globalAlpha = opts.fillAlpha ?? 0.35;
    ctx.fillStyle = colour;
    ctx.fill();
    ctx.globalAlpha = 1;
  }
  ctx.strokeStyle = colour;
  ctx.lineWidth = opts.width ?? 2;
  if (opts.dash) ctx.setLineDash(opts.dash);
  ctx.stroke();
  ctx.setLineDash([]);
  // windscreen line marks the front
  const v = state.health.vehicle;
  const c = Math.cos(h);
  const s = Math.sin(h);
  const fx = v.length_m - v.rear_overhang_m - 1.2;
  const hw = v.width_m / 2 - 0.15;
  ctx.beginPath();
  ctx.moveTo(sx(x + c * fx + s * hw), sy(y + s * fx - c * hw));
  ctx.lineTo(sx(x + c * fx - s * hw), sy(y + s * fx + c * hw));
  ctx.stroke();
  if (opts.wheels) drawWheels(ctx, x, y, h, opts.steer || 0, colour);
  // rear-axle reference point
  ctx.fillStyle = colour;
  ctx.beginPath();
  ctx.arc(sx(x), sy(y), 2.5, 0, 2 * Math.PI);
  ctx.fill();
  ctx.restore();
}

function drawWheels(ctx, x, y, h, steerDeg, colour) {
  const v = state.health.vehicle;
  const delta = (steerDeg / v.steer_ratio) * (Math.PI / 180);
  const r = 0.36; // half wheel length, m
  ctx.strokeStyle = colour;
  ctx.lineWidth = Math.max(2, 0.2 * state.view.k);
  for (const [ax, turn] of [[0, 0], [v.wheelbase_m, delta]]) {
    for (const side of [-1, 1]) {
      const lx = ax;
      const ly = (side * v.track_m) / 2;
      const cx = x + Math.cos(h) * lx - Math.sin(h) * ly;
      const cy = y + Math.sin(h) * lx + Math.cos(h) * ly;
      const a = h + turn;
      ctx.beginPath();
      ctx.moveTo(sx(cx - r * Math.cos(a)), sy(cy - r * Math.sin(a)));
      ctx.lineTo(sx(cx + r * Math.cos(a)), sy(cy + r * Math.sin(a)));
      ctx.stroke();
    }
  }
}

function handlePoint() {
  const v = state.health.vehicle;
  const [x, y, h] = state.start;
  const d = v.length_m - v.rear_overhang_m + HANDLE_AHEAD_M;
  return [x + d * Math.cos(h), y + d * Math.sin(h)];
}

function render() {
  const canvas = $("view");
  if (!state.scene || !state.health) return;
  if (!state.view) fitView();
  const { ctx, w, h } = canvasSize(canvas, state.view.h);
  ctx.clearRect(0, 0, w, h);
  drawGrid(ctx);
  // obstacles inside the map frame only: beyond the bounds the car cannot go anyway (a
  // TPCAP case's obstacles reach past its map)
  const [bx0, by0, bx1, by1] = state.scene.bounds;
  ctx.save();
  ctx.beginPath();
  ctx.rect(sx(bx0), sy(by1), sx(bx1) - sx(bx0), sy(by0) - sy(by1));
  ctx.clip();
  for (const ob of state.scene.obstacles) {
    polyPath(ctx, ob.vertices);
    ctx.fillStyle = OBSTACLE_FILL[ob.kind] || "#bdc3c7";
    ctx.fill();
  }
  ctx.restore();
  const planned = state.health.planned_colour;
  const [gx, gy, gh] = state.scene.goal;
  drawCar(ctx, gx, gy, gh, "#4a5a6a", { dash: [4, 4], width: 1.5 });
  label(ctx, "goal", gx, gy);
  const p = state.plan;
  if (p && p.plannable) {
    ctx.save();
    ctx.globalAlpha = 0.18;
    ctx.strokeStyle = planned;
    ctx.lineWidth = 1;
    for (const fp of p.footprints) {
      polyPath(ctx, fp);
      ctx.stroke();
    }
    ctx.restore();
    drawPath(ctx, p.coarse, "#7f8c8d", 1.2, 0.5);
    drawPath(ctx, p.path, planned, 2.5, 0.95);
    ctx.fillStyle = planned;
    for (const [cx, cy] of p.cusp_poses) {
      ctx.beginPath();
      ctx.arc(sx(cx), sy(cy), 4, 0, 2 * Math.PI);
      ctx.fill();
    }
  }
  for (const run of state.runs) {
    const pose = poseAt(run, state.t);
    const s = run.series;
    ctx.save();
    ctx.strokeStyle = run.colour;
    ctx.lineWidth = 1.5;
    ctx.globalAlpha = 0.35;
    strokeSeries(ctx, s, 0, s.t.length - 1);
    ctx.globalAlpha = 1;
    ctx.lineWidth = 2.5;
    strokeSeries(ctx, s, 0, pose.index, pose);
    ctx.restore();
  }
  const startColour = state.drag ? "#1f7a8c" : planned;
  const [x0, y0, h0] = state.start;
  drawCar(ctx, x0, y0, h0, startColour, { width: 1.5, dash: state.runs.length ? [3, 3] : null });
  label(ctx, "start", x0, y0);
  if (!state.runs.length || !state.playing) {
    const [hx, hy] = handlePoint();
    ctx.strokeStyle = startColour;
    ctx.setLineDash([2, 3]);
    ctx.beginPath();
    ctx.moveTo(sx(x0), sy(y0));
    ctx.lineTo(sx(hx), sy(hy));
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.fillStyle = "#fff";
    ctx.beginPath();
    ctx.arc(sx(hx), sy(hy), HANDLE_RADIUS_PX, 0, 2 * Math.PI);
    ctx.fill();
    ctx.lineWidth = 2;
    ctx.stroke();
  }
  for (const run of state.runs) {
    const pose = poseAt(run, state.t);
    drawCar(ctx, pose.x, pose.y, pose.h, run.colour, {
      fill: true, wheels: true, steer: pose.steer, width: 2,
    });
  }
  for (const run of state.runs) {
    if (run.outcome.reason === "collision") drawCollision(ctx, run);
  }
  drawLegend(ctx, w);
}

// Where a run hit: the car outline at its last pose (the first pose in contact) in red,
// and a ring with a cross on the contact (the mean of the outline/obstacle crossings).
function drawCollision(ctx, run) {
  const s = run.series;
  const n = s.t.length - 1;
  const car = carCorners(s.x[n], s.y[n], s.heading[n]);
  const [cx, cy] = contactPoint(car, state.scene.obstacles) || [s.x[n], s.y[n]];
  ctx.save();
  ctx.strokeStyle = COLLISION_COLOUR;
  ctx.lineWidth = 2;
  polyPath(ctx, car);
  ctx.stroke();
  const X = sx(cx);
  const Y = sy(cy);
  ctx.lineWidth = 3;
  ctx.beginPath();
  ctx.arc(X, Y, 9, 0, 2 * Math.PI);
  ctx.moveTo(X - 6, Y - 6);
  ctx.lineTo(X + 6, Y + 6);
  ctx.moveTo(X + 6, Y - 6);
  ctx.lineTo(X - 6, Y + 6);
  ctx.stroke();
  ctx.fillStyle = COLLISION_COLOUR;
  ctx.font = "bold 12px system-ui, sans-serif";
  ctx.strokeStyle = "#fff";
  ctx.lineWidth = 3;
  ctx.strokeText(`${run.plant}: collision`, X + 12, Y - 10); // a halo over the car fill
  ctx.fillText(`${run.plant}: collision`, X + 12, Y - 10);
  ctx.restore();
  run.contact = [cx, cy];
}

function segmentCrossing(p, p2, q, q2) {
  const rx = p2[0] - p[0];
  const ry = p2[1] - p[1];
  const qx = q2[0] - q[0];
  const qy = q2[1] - q[1];
  const den = rx * qy - ry * qx;
  if (Math.abs(den) < 1e-12) return null;
  const t = ((q[0] - p[0]) * qy - (q[1] - p[1]) * qx) / den;
  const u = ((q[0] - p[0]) * ry - (q[1] - p[1]) * rx) / den;
  return t >= 0 && t <= 1 && u >= 0 && u <= 1 ? [p[0] + t * rx, p[1] + t * ry] : null;
}

function insidePolygon([x, y], poly) {
  let inside = false;
  for (let i = 0, j = poly.length - 1; i < poly.length; j = i++) {
    const [xi, yi] = poly[i];
    const [xj, yj] = poly[j];
    if ((yi > y) !== (yj > y) && x < ((xj - xi) * (y - yi)) / (yj - yi) + xi) inside = !inside;
  }
  return inside;
}

// The middle of the overlap of a car outline with the obstacles: the mean of the edge
// crossings and of the corners inside the other polygon (null when they do not touch).
function contactPoint(car, obstacles) {
  const pts = [];
  for (const ob of obstacles) {
    const v = ob.vertices;
    for (let i = 0; i < car.length; i++) {
      for (let j = 0; j < v.length; j++) {
        const hit = segmentCrossing(car[i], car[(i + 1) % car.length], v[j], v[(j + 1) % v.length]);
        if (hit) pts.push(hit);
      }
    }
    for (const c of car) if (insidePolygon(c, v)) pts.push(c);
    for (const q of v) if (insidePolygon(q, car)) pts.push(q);
  }
  if (!pts.length) return null;
  return [pts.reduce((a, p) => a + p[0], 0) / pts.length, pts.reduce((a, p) => a + p[1], 0) / pts.length];
}

function strokeSeries(ctx, s, i0, i1, tail) {
  ctx.beginPath();
  for (let i = i0; i <= i1; i++) {
    const X = sx(s.x[i]);
    const Y = sy(s.y[i]);
    if (i === i0) ctx.moveTo(X, Y);
    else ctx.lineTo(X, Y);
  }
  if (tail) ctx.lineTo(sx(tail.x), sy(tail.y));
  ctx.stroke();
}

function label(ctx, text, x, y) {
  ctx.fillStyle = "#34495e";
  ctx.font = "11px system-ui, sans-serif";
  ctx.fillText(text, sx(x) + 5, sy(y) - 5);
}

function drawLegend(ctx, w) {
  const items = [["planned", state.health.planned_colour, []]];
  for (const run of state.runs) items.push([`driven: ${run.plant}`, run.colour, []]);
  items.push(["reverse", "#5b6b7c", [7, 5]]);
  ctx.font = "12px system-ui, sans-serif";
  let x = w - 12;
  for (const [text, colour, dash] of items.reverse()) {
    const tw = ctx.measureText(text).width;
    x -= tw + 34;
    ctx.strokeStyle = colour;
    ctx.lineWidth = 2.5;
    ctx.setLineDash(dash);
    ctx.beginPath();
    ctx.moveTo(x, 14);
    ctx.lineTo(x + 24, 14);
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.fillStyle = "#34495e";
    ctx.fillText(text, x + 28, 18);
  }
}

// ---------------------------------------------------------------------------------------
// Dragging the start pose

function pointerWorld(ev) {
  const r = $("view").getBoundingClientRect();
  return [wx(ev.clientX - r.left), wy(ev.clientY - r.top), ev.clientX - r.left, ev.clientY - r.top];
}

function insideCar(px, py) {
  const [x, y, h] = state.start;
  const pts = carCorners(x, y, h);
  let inside = true;
  for (let i = 0; i < 4; i++) {
    const [ax, ay] = pts[i];
    const [bx, by] = pts[(i + 1) % 4];
    if ((bx - ax) * (py - ay) - (by - ay) * (px - ax) < 0) inside = false;
  }
  return inside;
}

function onPointerDown(ev) {
  if (!state.scene || !state.health) return;
  const [px, py, cx, cy] = pointerWorld(ev);
  const [hx, hy] = handlePoint();
  if (Math.hypot(sx(hx) - cx, sy(hy) - cy) <= HANDLE_RADIUS_PX + 4) {
    state.drag = { mode: "turn" };
  } else if (insideCar(px, py)) {
    state.drag = { mode: "move", dx: px - state.start[0], dy: py - state.start[1] };
  } else {
    return;
  }
  state.playing = false;
  $("view").setPointerCapture(ev.pointerId);
  ev.preventDefault();
}

function onPointerMove(ev) {
  const canvas = $("view");
  if (!state.drag) {
    if (!state.scene || !state.health || !state.view) return;
    const [px, py, cx, cy] = pointerWorld(ev);
    const [hx, hy] = handlePoint();
    const onHandle = Math.hypot(sx(hx) - cx, sy(hy) - cy) <= HANDLE_RADIUS_PX + 4;
    canvas.style.cursor = onHandle ? "grab" : insideCar(px, py) ? "move" : "default";
    return;
  }
  const [px, py] = pointerWorld(ev);
  const [x, y] = state.start;
  if (state.drag.mode === "move") {
    state.start = [px - state.drag.dx, py - state.drag.dy, state.start[2]];
  } else {
    state.start = [x, y, Math.atan2(py - y, px - x)];
  }
  if (state.runs.length) clearRuns();
  state.plan = null;
  updateStartReadout();
  render();
}

function onPointerUp() {
  if (!state.drag) return;
  state.drag = null;
  renderPlanInfo();
  render();
  plan();
}

function updateStartReadout() {
  if (!state.start) return;
  const [x, y, h] = state.start;
  const edited = samePose(state.start, state.baseStart) ? "" : " (edited)";
  $("start-readout").textContent =
    `start x ${x.toFixed(2)} m, y ${y.toFixed(2)} m, heading ${(h * DEG_PER_RAD).toFixed(1)}°${edited}`;
}

// ---------------------------------------------------------------------------------------
// State plots

function niceStep(span, n) {
  const raw = span / n;
  const mag = 10 ** Math.floor(Math.log10(raw));
  for (const m of [1, 2, 2.5, 5, 10]) if (m * mag >= raw) return m * mag;
  return 10 * mag;
}

function plotFrame(canvas) {
  const { ctx, w, h } = canvasSize(canvas);
  return { ctx, w, h, left: 44, right: w - 8, top: 20, bottom: h - 20 };
}

function renderPlots() {
  for (const canvas of document.querySelectorAll(".plot")) {
    const spec = PLOTS[canvas.dataset.channel];
    const f = plotFrame(canvas);
    const { ctx } = f;
    ctx.clearRect(0, 0, f.w, f.h);
    ctx.font = "11px system-ui, sans-serif";
    ctx.fillStyle = "#1f2d3d";
    ctx.fillText(spec.label, f.left, 13);
    const tmax = Math.max(state.tmax, 1);
    let lo = spec.ticks ? -1.3 : 0;
    let hi = spec.ticks ? 1.3 : 0;
    if (!spec.ticks) {
      for (const run of state.runs) {
        for (const v of channelValues(run, canvas.dataset.channel, spec)) {
          if (v === null) continue;
          lo = Math.min(lo, v * spec.scale);
          hi = Math.max(hi, v * spec.scale);
        }
      }
      if (hi - lo < 1e-6) { lo -= 1; hi += 1; }
      const padv = 0.08 * (hi - lo);
      lo -= padv;
      hi += padv;
    }
    const X = (t) => f.left + (t / tmax) * (f.right - f.left);
    const Y = (v) => f.bottom - ((v - lo) / (hi - lo)) * (f.bottom - f.top);
    // axes and ticks
    ctx.strokeStyle = "#e3e8ee";
    ctx.fillStyle = "#6b7a8c";
    ctx.lineWidth = 1;
    const yt = spec.ticks || (() => {
      const st = niceStep(hi - lo, 4);
      const out = [];
      for (let v = Math.ceil(lo / st) * st; v <= hi; v += st) out.push([v, formatTick(v, st)]);
      return out;
    })();
    for (const [v, text] of yt) {
      ctx.beginPath();
      ctx.moveTo(f.left, Y(v));
      ctx.lineTo(f.right, Y(v));
      ctx.stroke();
      ctx.fillText(text, 4, Y(v) + 4);
    }
    const tst = niceStep(tmax, 6);
    ctx.textAlign = "center";
    for (let t = 0; t <= tmax + 1e-9; t += tst) {
      ctx.beginPath();
      ctx.moveTo(X(t), f.top);
      ctx.lineTo(X(t), f.bottom);
      ctx.stroke();
      ctx.fillText(`${formatTick(t, tst)}`, Math.min(X(t), f.w - 10), f.h - 5);
    }
    ctx.textAlign = "left";
    ctx.textAlign = "right";
    ctx.fillText("t [s]", f.right, 13);
    ctx.textAlign = "left";
    ctx.strokeStyle = "#9aa7b5";
    ctx.strokeRect(f.left, f.top, f.right - f.left, f.bottom - f.top);
    if (!state.runs.length) {
      ctx.fillStyle = "#9aa7b5";
      ctx.fillText("run a plant to see this channel", f.left + 10, (f.top + f.bottom) / 2);
    }
    for (const run of state.runs) {
      if (spec.command) {
        const cmd = run.series[spec.command];
        drawLine(ctx, run.series.t, cmd, spec, X, Y, run.colour, [4, 3], 1, 0.7);
      }
      const values = channelValues(run, canvas.dataset.channel, spec);
      drawLine(ctx, run.series.t, values, spec, X, Y, run.colour, [], 1.6, 1);
    }
    canvas._plot = { f, X, Y };
    const copy = canvas._cache || document.createElement("canvas");
    copy.width = canvas.width;
    copy.height = canvas.height;
    copy.getContext("2d").drawImage(canvas, 0, 0);
    canvas._cache = copy;
  }
  drawPlotCursors();
}

function formatTick(v, step) {
  const digits = step >= 1 ? 0 : Math.min(3, Math.ceil(-Math.log10(step)));
  return Number(v).toFixed(digits);
}

// A channel of a run, through the centred moving average when smoothing is on.
function channelValues(run, name, spec) {
  const raw = run.series[name];
  if (!spec.smooth || !state.smooth) return raw;
  run.smoothed = run.smoothed || {};
  if (!run.smoothed[name]) {
    const half = Math.max(0, Math.round((state.health.accel_smoothing_s * run.series.rate_hz) / 2));
    run.smoothed[name] = raw.map((_, i) => {
      let sum = 0;
      let n = 0;
      for (let j = Math.max(0, i - half); j <= Math.min(raw.length - 1, i + half); j++) {
        if (raw[j] !== null) { sum += raw[j]; n++; }
      }
      return n ? sum / n : null;
    });
  }
  return run.smoothed[name];
}

function drawLine(ctx, ts, vals, spec, X, Y, colour, dash, width, alpha) {
  ctx.save();
  ctx.strokeStyle = colour;
  ctx.setLineDash(dash);
  ctx.lineWidth = width;
  ctx.globalAlpha = alpha;
  ctx.beginPath();
  let pen = false;
  let prev = null;
  for (let i = 0; i < ts.length; i++) {
    const v = vals[i];
    if (v === null) { pen = false; continue; }
    const px = X(ts[i]);
    const py = Y(v * spec.scale);
    if (!pen) ctx.moveTo(px, py);
    else if (spec.step) ctx.lineTo(px, Y(prev * spec.scale));
    if (pen) ctx.lineTo(px, py);
    pen = true;
    prev = v;
  }
  ctx.stroke();
  ctx.restore();
}

function drawPlotCursors() {
  for (const canvas of document.querySelectorAll(".plot")) {
    if (!canvas._plot || !canvas._cache) continue;
    const ctx = canvas.getContext("2d");
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    ctx.drawImage(canvas._cache, 0, 0);
    const dpr = window.devicePixelRatio || 1;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    if (!state.runs.length) continue;
    const { f, X } = canvas._plot;
    ctx.strokeStyle = "#1f2d3d";
    ctx.lineWidth = 1;
    ctx.beginPath();
    ctx.moveTo(X(state.t), f.top);
    ctx.lineTo(X(state.t), f.bottom);
    ctx.stroke();
  }
}

// ---------------------------------------------------------------------------------------
// Scene files

function openSceneFile(file) {
  const reader = new FileReader();
  reader.onload = async () => {
    let scene;
    let notes = [];
    if (/\.(csv|xml)$/i.test(file.name)) {
      // a TPCAP case or a CommonRoad scenario: the server turns it into scene JSON
      let doc;
      try {
        doc = await api("/api/import", { filename: file.name, text: reader.result });
      } catch (err) {
        showError(err.message);
        return;
      }
      scene = doc.scene;
      notes = doc.notes;
    } else {
      try {
        scene = JSON.parse(reader.result);
      } catch (err) {
        showError(`${file.name}: not valid JSON (${err.message})`);
        return;
      }
    }
    const ok = scene && Array.isArray(scene.bounds) && Array.isArray(scene.obstacles) &&
      Array.isArray(scene.start) && Array.isArray(scene.goal);
    if (!ok) {
      showError(`${file.name}: a scene needs bounds, obstacles, start and goal`);
      return;
    }
    state.fileScene = { scene, name: file.name, notes };
    await showFileScene();
  };
  reader.readAsText(file);
}

// The scene file opened last: the grid selector and the cell selector name it, its import
// notes are listed, and it is planned.
async function showFileScene() {
  const f = state.fileScene;
  setScene(f.scene, true);
  showNotes(f.name, f.notes);
  const grid = $("grid");
  let gopt = grid.querySelector("option[value='file']");
  if (!gopt) {
    gopt = document.createElement("option");
    gopt.value = "file";
    grid.append(gopt);
  }
  gopt.textContent = `Scene file: ${f.name}`;
  grid.value = "file";
  const sel = $("cell");
  for (const o of [...sel.options]) if (o.value === "custom") o.remove();
  const opt = document.createElement("option");
  opt.value = "custom";
  opt.textContent = `custom · ${f.name}`;
  sel.append(opt);
  sel.value = "custom";
  await plan();
}

// What loading a file normalised (the import's notes), under the scene selectors.
function showNotes(name, notes) {
  const box = $("scene-notes");
  box.textContent = "";
  box.hidden = !notes.length;
  if (!notes.length) return;
  const head = document.createElement("div");
  head.textContent = `${name}: loading normalised`;
  const ul = document.createElement("ul");
  for (const n of notes) {
    const li = document.createElement("li");
    li.textContent = n.startsWith(`${name}: `) ? n.slice(name.length + 2) : n;
    ul.append(li);
  }
  box.append(head, ul);
}

function saveScene() {
  if (!state.scene) return;
  const scene = { ...state.scene, start: state.start.slice() };
  const blob = new Blob([JSON.stringify(scene, null, 1)], { type: "application/json" });
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = `${(scene.meta && scene.meta.name) || "scene"}.json`;
  a.click();
  URL.revokeObjectURL(a.href);
}

// ---------------------------------------------------------------------------------------
// Wiring

function wire() {
  $("grid").addEventListener("change", async (ev) => {
    // keep the base cell: robust index = 36 · variant + cell, so cell i <-> variant 0 of i.
    // Custom or not is read from the selector: state.custom stays true until a cell picked
    // a moment ago has loaded, and reading it here reset that cell to 0.
    if (ev.target.value === "file") {
      if (state.fileScene) await showFileScene();
      return;
    }
    state.grid = ev.target.value;
    const custom = $("cell").value === "custom";
    state.index = custom ? 0 : state.index % state.health.grids["36"];
    try {
      await loadCells();
      await loadCell();
    } catch (err) {
      showError(err.message);
    }
  });
  $("cell").addEventListener("change", (ev) => {
    if (ev.target.value === "custom") return;
    for (const o of [...ev.target.options]) if (o.value === "custom") o.remove();
    $("grid").value = state.grid;
    state.index = Number(ev.target.value);
    loadCell();
  });
  $("open-scene").addEventListener("click", () => $("scene-file").click());
  $("scene-file").addEventListener("change", (ev) => {
    if (ev.target.files.length) openSceneFile(ev.target.files[0]);
    ev.target.value = "";
  });
  $("save-scene").addEventListener("click", saveScene);
  $("reset-start").addEventListener("click", () => {
    if (!state.baseStart) return;
    state.start = state.baseStart.slice();
    clearRuns();
    updateStartReadout();
    plan();
  });
  $("plan-btn").addEventListener("click", () => { clearRuns(); plan(); });
  $("run-btn").addEventListener("click", runSelected);
  $("fidelity-btn").addEventListener("click", runFidelity);
  $("play").addEventListener("click", togglePlay);
  $("cancel").addEventListener("click", cancelRequest);
  $("speed").addEventListener("change", (ev) => { state.speed = Number(ev.target.value); });
  $("smooth").addEventListener("change", (ev) => {
    state.smooth = ev.target.checked;
    renderPlots();
  });
  $("scrub").addEventListener("input", (ev) => {
    state.playing = false;
    state.t = (Number(ev.target.value) / 1000) * state.tmax;
    updatePlayer();
    render();
    drawPlotCursors();
  });
  document.addEventListener("keydown", (ev) => {
    if (ev.code === "Space" && !["INPUT", "SELECT", "BUTTON"].includes(ev.target.tagName)) {
      ev.preventDefault();
      togglePlay();
    }
  });
  const view = $("view");
  view.addEventListener("pointerdown", onPointerDown);
  view.addEventListener("pointermove", onPointerMove);
  view.addEventListener("pointerup", onPointerUp);
  view.addEventListener("pointercancel", onPointerUp);
  window.addEventListener("resize", () => {
    fitView();
    render();
    renderPlots();
  });
}

function togglePlay() {
  if (!state.runs.length) return;
  if (!state.playing && state.t >= state.tmax) state.t = 0;
  state.playing = !state.playing;
  updatePlayer();
}

// ?grid=36&cell=26 in the address picks the first scene; the address follows the choice.
function readAddress() {
  const q = new URLSearchParams(window.location.search);
  const grid = q.get("grid");
  if (grid === "36" || grid === "252") state.grid = grid;
  const cell = Number(q.get("cell"));
  if (q.has("cell") && Number.isInteger(cell) && cell >= 0) state.index = cell;
  $("grid").value = state.grid;
}

function writeAddress() {
  const q = new URLSearchParams({ grid: state.grid, cell: String(state.index) });
  window.history.replaceState(null, "", `?${q}`);
}

async function main() {
  wire();
  readAddress();
  renderPlots();
  await loadHealth();
  if (!state.health) return;
  try {
    await loadCells();
    await loadCell();
  } catch (err) {
    showError(err.message);
  }
  requestAnimationFrame(frame);
}

main();
