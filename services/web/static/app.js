// The operator's page: draws /events (Server-Sent Events of the live state) on a top view of
// the crater, a time plot, the cameras' previews and tables. No framework, no build step.
// Every canvas says what it waits for until its first data: the page is never blank.
"use strict";

const map = document.getElementById("map");
const ctx = map.getContext("2d");
const plot = document.getElementById("plot");
const mapImage = new Image();
let mapInfo = {extent_mm: [-3000, 3000, -3000, 3000], image: false};
let view = mapInfo.extent_mm;  // what the map shows: the crater and every camera, square
let mapReady = false;
let latest = null;  // the last state drawn
// The map's drawing area inside its canvas: axes left and below, the colour scale right.
const AREA = {left: 62, top: 10, size: 640};

function loadMap() {
  // The sim may write the height map after the page started: ask again until there is one.
  fetch("map.json").then((r) => r.json()).then((info) => {
    mapInfo = info;
    if (info.image) {
      mapImage.onload = () => { mapReady = true; draw(latest); };
      mapImage.src = "map.png";
    } else {
      setTimeout(loadMap, 3000);
    }
  }).catch(() => setTimeout(loadMap, 3000));
}

function fitView(state) {
  let [x0, x1, y0, y1] = mapInfo.extent_mm;
  for (const cam of Object.values(state ? state.cameras : {})) {
    if (!cam.position) continue;
    x0 = Math.min(x0, cam.position[0] - 300); x1 = Math.max(x1, cam.position[0] + 300);
    y0 = Math.min(y0, cam.position[1] - 300); y1 = Math.max(y1, cam.position[1] + 300);
  }
  const half = Math.max(x1 - x0, y1 - y0) / 2, cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  view = [cx - half, cx + half, cy - half, cy + half];
}

function toCanvas(x, y) {
  const [x0, x1, y0, y1] = view;
  return [AREA.left + (x - x0) / (x1 - x0) * AREA.size,
          AREA.top + (1 - (y - y0) / (y1 - y0)) * AREA.size];
}

function mmToPx(mm) {
  return mm / (view[1] - view[0]) * AREA.size;
}

function fmt(value, digits = 0, unit = "") {
  return value === null || value === undefined ? "—" : `${value.toFixed(digits)}${unit}`;
}

function clock(seconds) {
  return new Date(seconds * 1000).toLocaleTimeString([], {hour12: false});
}

function niceStep(span, most) {
  // The smallest of 1, 2, 5 × 10^k that gives at most `most` intervals over `span`.
  const raw = span / most, power = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const m of [1, 2, 5, 10]) if (m * power >= raw) return m * power;
  return 10 * power;
}

function waitingText(c, canvas, text) {
  canvas.dataset.waiting = text;  // what the canvas says, for people reading the DOM and tests
  c.fillStyle = "#aab4be"; c.font = "24px sans-serif"; c.textAlign = "center";
  c.fillText(text, canvas.width / 2, canvas.height / 2);
  c.textAlign = "left";
}

function drawAxes() {
  // mm along the bottom and the left, with a faint grid over the crater.
  const step = niceStep(view[1] - view[0], 8);
  ctx.font = "19px sans-serif"; ctx.fillStyle = "#c8d0d8"; ctx.lineWidth = 1;
  const bottom = AREA.top + AREA.size, right = AREA.left + AREA.size;
  for (let v = Math.ceil(view[0] / step) * step; v <= view[1]; v += step) {
    const [px] = toCanvas(v, 0);
    ctx.strokeStyle = "rgba(255,255,255,0.12)";
    ctx.beginPath(); ctx.moveTo(px, AREA.top); ctx.lineTo(px, bottom); ctx.stroke();
    ctx.strokeStyle = "#c8d0d8";
    ctx.beginPath(); ctx.moveTo(px, bottom); ctx.lineTo(px, bottom + 6); ctx.stroke();
    ctx.textAlign = "center"; ctx.fillText(String(Math.round(v)), px, bottom + 24);
  }
  for (let v = Math.ceil(view[2] / step) * step; v <= view[3]; v += step) {
    const [, py] = toCanvas(0, v);
    ctx.strokeStyle = "rgba(255,255,255,0.12)";
    ctx.beginPath(); ctx.moveTo(AREA.left, py); ctx.lineTo(right, py); ctx.stroke();
    ctx.strokeStyle = "#c8d0d8";
    ctx.beginPath(); ctx.moveTo(AREA.left - 6, py); ctx.lineTo(AREA.left, py); ctx.stroke();
    ctx.textAlign = "right"; ctx.fillText(String(Math.round(v)), AREA.left - 8, py + 5);
  }
  ctx.textAlign = "left";
  ctx.strokeStyle = "#5a636d"; ctx.strokeRect(AREA.left, AREA.top, AREA.size, AREA.size);
}

function drawColourScale() {
  const x = AREA.left + AREA.size + 16, w = 18, top = AREA.top + 20, h = AREA.size - 40;
  ctx.font = "19px sans-serif"; ctx.fillStyle = "#c8d0d8"; ctx.textAlign = "left";
  if (!mapReady || !mapInfo.colours) {
    ctx.save(); ctx.translate(x + 12, AREA.top + AREA.size / 2); ctx.rotate(-Math.PI / 2);
    ctx.textAlign = "center"; ctx.fillText("no height map yet", 0, 0); ctx.restore();
    return;
  }
  const gradient = ctx.createLinearGradient(0, top + h, 0, top);
  mapInfo.colours.forEach((c, i) => gradient.addColorStop(i / (mapInfo.colours.length - 1), c));
  ctx.globalAlpha = 0.85; ctx.fillStyle = gradient; ctx.fillRect(x, top, w, h);
  ctx.globalAlpha = 1; ctx.strokeStyle = "#5a636d"; ctx.strokeRect(x, top, w, h);
  const [low, high] = mapInfo.height_mm;
  ctx.fillStyle = "#c8d0d8";
  ctx.fillText(`${Math.round(high)}`, x - 4, top - 6);
  ctx.fillText(`${Math.round(low)}`, x - 4, top + h + 18);
  ctx.save(); ctx.translate(x + w + 16, top + h / 2); ctx.rotate(-Math.PI / 2);
  ctx.textAlign = "center"; ctx.fillText("height mm", 0, 0); ctx.restore();
}

function drawMap(state) {
  fitView(state);
  ctx.clearRect(0, 0, map.width, map.height);
  ctx.fillStyle = "#2f353c"; ctx.fillRect(AREA.left, AREA.top, AREA.size, AREA.size);
  if (mapReady) {
    const e = mapInfo.extent_mm;
    const [left, top] = toCanvas(e[0], e[3]);
    const [right, bottom] = toCanvas(e[1], e[2]);
    ctx.globalAlpha = 0.85;
    ctx.drawImage(mapImage, left, top, right - left, bottom - top);
    ctx.globalAlpha = 1;
  }
  drawAxes();
  drawColourScale();
  map.dataset.waiting = "";
  if (!state || (!state.robot && !state.crane)) {
    map.dataset.waiting = state ? "waiting for the robot (tracker) and the crane (gantry)…"
                                : "connecting to the web service…";
    ctx.save(); ctx.beginPath(); ctx.rect(AREA.left, AREA.top, AREA.size, AREA.size); ctx.clip();
    ctx.fillStyle = "rgba(29,33,38,0.75)";
    ctx.fillRect(AREA.left + 40, AREA.top + AREA.size / 2 - 40, AREA.size - 80, 64);
    ctx.fillStyle = "#e6e6e6"; ctx.font = "19px sans-serif"; ctx.textAlign = "center";
    ctx.fillText(map.dataset.waiting, AREA.left + AREA.size / 2, AREA.top + AREA.size / 2);
    ctx.textAlign = "left"; ctx.restore();
    if (!state) return;
  }
  ctx.save(); ctx.beginPath(); ctx.rect(AREA.left, AREA.top, AREA.size, AREA.size); ctx.clip();
  for (const [name, cam] of Object.entries(state.cameras)) {
    if (!cam.position) continue;
    const [cx, cy] = toCanvas(cam.position[0], cam.position[1]);
    if (cam.looking_at) {
      const [lx, ly] = toCanvas(cam.looking_at[0], cam.looking_at[1]);
      ctx.strokeStyle = "#ffd84d"; ctx.setLineDash([6, 4]); ctx.lineWidth = 1.5;
      ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(lx, ly); ctx.stroke(); ctx.setLineDash([]);
    }
    ctx.fillStyle = "#ffd84d";
    ctx.beginPath(); ctx.moveTo(cx, cy - 9); ctx.lineTo(cx - 8, cy + 6); ctx.lineTo(cx + 8, cy + 6);
    ctx.closePath(); ctx.fill();
    ctx.font = "20px sans-serif";
    const labelLeft = cx + 10 + ctx.measureText(name).width > AREA.left + AREA.size;
    ctx.textAlign = labelLeft ? "right" : "left";
    ctx.fillText(name, labelLeft ? cx - 10 : cx + 10, cy - 6);
    ctx.textAlign = "left";
  }
  if (state.track.length > 1) {
    ctx.strokeStyle = "rgba(255, 80, 80, 0.85)"; ctx.lineWidth = 2.5;
    ctx.beginPath();
    state.track.forEach(([x, y], i) => {
      const [px, py] = toCanvas(x, y);
      if (i === 0) ctx.moveTo(px, py); else ctx.lineTo(px, py);
    });
    ctx.stroke();
  }
  if (state.estimate && state.estimate.valid) {
    const [ex, ey] = toCanvas(state.estimate.x_mm, state.estimate.y_mm);
    ctx.strokeStyle = "#ddd"; ctx.lineWidth = 1.5;
    ctx.beginPath(); ctx.arc(ex, ey, 7, 0, 2 * Math.PI); ctx.stroke();
  }
  if (state.robot) {
    const [rx, ry] = toCanvas(state.robot.x_mm, state.robot.y_mm);
    ctx.fillStyle = "#ff5050";
    ctx.beginPath(); ctx.arc(rx, ry, 6, 0, 2 * Math.PI); ctx.fill();
    map.dataset.robotPx = `${rx.toFixed(1)},${ry.toFixed(1)}`;
  }
  if (state.crane) {
    const [kx, ky] = toCanvas(state.crane.x_mm, state.crane.y_mm);
    ctx.strokeStyle = "#4da3ff"; ctx.lineWidth = 2.5;
    ctx.beginPath(); ctx.moveTo(kx - 10, ky); ctx.lineTo(kx + 10, ky);
    ctx.moveTo(kx, ky - 10); ctx.lineTo(kx, ky + 10); ctx.stroke();
    if (state.offload) {
      ctx.strokeStyle = state.offload.warning ? "#ff7b6b" : "#4da3ff";
      ctx.beginPath();
      ctx.arc(kx, ky, Math.max(3, mmToPx(state.offload.horizontal_error_mm)), 0, 2 * Math.PI);
      ctx.stroke();
    }
  }
  ctx.restore();
}

function drawPlot(state) {
  // The crane's error (mm, left axis) and the sideways pull (%, right axis, with its limit)
  // over the last history.span_s: the largest of each second.
  const c = plot.getContext("2d"), W = plot.width, H = plot.height;
  const L = 62, R = 70, T = 28, B = 28, w = W - L - R, h = H - T - B;
  c.clearRect(0, 0, W, H);
  const hist = state ? state.history : null;
  const points = hist ? hist.points : [];
  plot.dataset.points = String(points.length);
  plot.dataset.waiting = "";
  if (!points.length) {
    waitingText(c, plot, state ? "waiting for the gantry's offload figures (stb/gantry/offload)…"
                               : "connecting to the web service…");
    return;
  }
  const span = hist.span_s, limit = hist.limit_pct;
  const maxError = Math.max(100, ...points.map((p) => p[1])) * 1.1;
  const maxPull = Math.max(limit ? limit * 1.5 : 1, ...points.map((p) => p[2])) * 1.1;
  const X = (t) => L + (1 + t / span) * w;
  const Ye = (e) => T + h - e / maxError * h, Yp = (p) => T + h - p / maxPull * h;
  c.font = "18px sans-serif"; c.lineWidth = 1;
  c.strokeStyle = "#5a636d"; c.strokeRect(L, T, w, h);
  const tStep = span >= 180 ? 60 * niceStep(span / 60, 6) : niceStep(span, 6);
  c.fillStyle = "#c8d0d8"; c.textAlign = "center";
  for (let t = 0; t >= -span; t -= tStep) {
    c.strokeStyle = "rgba(255,255,255,0.1)";
    c.beginPath(); c.moveTo(X(t), T); c.lineTo(X(t), T + h); c.stroke();
    c.fillText(t === 0 ? "now" : (tStep >= 60 ? `${t / 60} min` : `${t} s`), X(t), H - 6);
  }
  const eStep = niceStep(maxError, 4), pStep = niceStep(maxPull, 4);
  c.textAlign = "right"; c.fillStyle = "#4da3ff";
  for (let e = 0; e <= maxError; e += eStep) c.fillText(String(Math.round(e)), L - 6, Ye(e) + 5);
  c.textAlign = "left"; c.fillStyle = "#ffa64d";
  for (let p = 0; p <= maxPull; p += pStep) c.fillText(`${+p.toFixed(1)} %`, L + w + 6, Yp(p) + 5);
  if (limit) {
    c.strokeStyle = "#ff5050"; c.setLineDash([6, 4]);
    c.beginPath(); c.moveTo(L, Yp(limit)); c.lineTo(L + w, Yp(limit)); c.stroke();
    c.setLineDash([]);
  }
  const line = (colour, y) => {
    c.strokeStyle = colour; c.lineWidth = 2; c.beginPath();
    let gap = true, last = null;
    for (const p of points) {
      // A missing second (no offload figure: the gantry idle or gone) breaks the line.
      if (last !== null && p[0] - last > 2.5 * hist.step_s) gap = true;
      if (gap) c.moveTo(X(p[0]), y(p)); else c.lineTo(X(p[0]), y(p));
      gap = false; last = p[0];
    }
    c.stroke();
  };
  line("#4da3ff", (p) => Ye(p[1]));
  line("#ffa64d", (p) => Yp(p[2]));
  c.font = "18px sans-serif"; c.textAlign = "left";
  let x = L + 4;
  for (const [colour, text] of [["#4da3ff", "crane error, mm (largest each second)"],
                                ["#ffa64d", "sideways pull, %"],
                                ["#ff5050", limit ? `- - limit ${limit} %` : ""]]) {
    c.fillStyle = colour; c.fillText(text, x, 20); x += c.measureText(text).width + 24;
  }
}

function row(cells, cls = "") {
  const tr = document.createElement("tr");
  if (cls) tr.className = cls;
  for (const cell of cells) {
    const td = document.createElement("td");
    td.textContent = cell;
    td.title = cell;
    tr.appendChild(td);
  }
  return tr;
}

function drawAlarms(state) {
  const banner = document.getElementById("alarms");
  if (!state) return;
  const active = state.alarms.active, ended = state.alarms.ended;
  banner.replaceChildren();
  if (active.length) {
    banner.className = "on";
    for (const a of active) {
      const line = document.createElement("span");
      line.className = "alarm"; line.dataset.cause = a.cause;
      line.textContent = `⚠ ${clock(a.since_s)} ${a.cause} — ${a.detail}` +
        ` (for ${fmt(state.now_s - a.since_s)} s)`;
      banner.appendChild(line);
    }
  } else {
    banner.className = "none";
    banner.textContent = "no alarm" + (ended.length
      ? ` · last: ${ended[0].cause}, ${clock(ended[0].since_s)}–${clock(ended[0].until_s)}` : "");
  }
  const list = document.getElementById("ended");
  list.replaceChildren();
  for (const a of ended) {
    const div = document.createElement("div");
    div.textContent = `${clock(a.since_s)}–${clock(a.until_s)} ${a.cause}: ${a.detail}`;
    div.title = div.textContent;
    list.appendChild(div);
  }
  if (!ended.length) list.innerHTML = "<div>none yet</div>";
}

function drawServices(state) {
  const table = document.getElementById("services");
  table.replaceChildren();
  if (!state.services.length) table.appendChild(row(["waiting for the services' health…"]));
  for (const s of state.services) {
    const status = s.alive ? (s.status || "alive") : "gone";
    const tr = row([`${s.alive ? "●" : "○"} ${s.service}/${s.instance}`, status, s.detail],
                   s.alive ? (s.status === "degraded" ? "degraded" : "alive") : "dead");
    tr.dataset.service = `${s.service}/${s.instance}`;
    tr.dataset.alive = String(s.alive);
    table.appendChild(tr);
  }
}

function drawOffload(state) {
  const table = document.getElementById("offload");
  table.replaceChildren();
  const o = state.offload, c = state.crane;
  table.appendChild(row(["crane", c ? `${c.status}${c.enabled ? "" : " (disabled)"}` : "—"]));
  if (state.estimate) table.appendChild(row(["filter", state.estimate.algorithm]));
  if (!o) { table.appendChild(row(["offload", "waiting for the gantry…"])); return; }
  table.appendChild(row(["horizontal error", fmt(o.horizontal_error_mm, 0, " mm")]));
  table.appendChild(row(["cable length", fmt(o.cable_length_mm, 0, " mm")]));
  table.appendChild(row(["vertical pull lost", fmt(o.vertical_loss_pct, 3, " %")]));
  table.appendChild(row(["sideways pull", `${fmt(o.horizontal_share_pct, 2, " %")} ` +
                         `(limit ${o.warn_above_pct} %)`], o.warning ? "warn" : ""));
}

const previewDrawn = {};  // per camera: the picture and overlay last drawn

function calibrationText(cal) {
  // "12 of 20 passpoints · 35 snapshots passed over (no marker 30) · about 40 s left"
  const skipped = Object.entries(cal.skipped || {}).map(([why, n]) => `${why} ${n}`).join(", ");
  return `calibrating: ${cal.passpoints} of ${cal.target} passpoints` +
    (cal.state === "solving" ? ", solving…" : "") +
    (skipped ? ` · passed over: ${skipped}` : "") +
    (cal.time_left_s !== null && cal.time_left_s !== undefined
      ? ` · about ${fmt(cal.time_left_s)} s left` : "");
}

function cameraBox(box, name) {
  let div = document.getElementById(`camera-${name}`);
  if (!div) {
    div = document.createElement("section");
    div.id = `camera-${name}`;
    div.className = "preview";
    div.innerHTML = `<div class="caption"></div><div class="progress-text"></div>` +
      `<div class="bar"><div></div></div>` + cameraControls(name) +
      `<canvas width="704" height="576"></canvas>`;
    box.appendChild(div);
    wireCameraControls(div, name);
    applyRole(div);
    const canvas = div.querySelector("canvas"), c = canvas.getContext("2d");
    c.fillStyle = "#000"; c.fillRect(0, 0, canvas.width, canvas.height);
    waitingText(c, canvas, `waiting for ${name}'s first preview…`);
  }
  return div;
}

// An operator's hands on a camera: calibrate it (start, cancel; accept or discard the solved
// pose), hold it and steer it (arrows, zoom, its presets), let it follow again.
function cameraControls(name) {
  const b = (action, label, extra = "") =>
    `<button data-command="${action}" data-camera="${esc(name)}" ${extra}>${label}</button>`;
  return `<div class="camera-controls">` +
    b("calib-start", "Calibrate") + b("calib-cancel", "Cancel") +
    b("calib-accept", "Accept pose", 'hidden') + b("calib-discard", "Discard", 'hidden') +
    `<span class="sep"></span>` + b("ptz-hold", "Hold") +
    b("ptz-left", "◀", 'title="pan left 5°"') + b("ptz-right", "▶", 'title="pan right 5°"') +
    b("ptz-up", "▲", 'title="tilt up 5°"') + b("ptz-down", "▼", 'title="tilt down 5°"') +
    b("ptz-in", "＋", 'title="zoom in"') + b("ptz-out", "－", 'title="zoom out"') +
    `<select class="presets" data-command="ptz-preset-name"></select>` +
    b("ptz-preset", "Go") + b("ptz-follow", "Follow") +
    `<span class="answer"></span></div>`;
}

const STEP_DEG = 5, ZOOM_STEP = 1000;  // VAPIX zoom steps of 1–9999

function wireCameraControls(div, name) {
  for (const button of div.querySelectorAll("button[data-command]")) {
    button.addEventListener("click", () => cameraAction(div, name, button.dataset.command));
  }
}

async function cameraAction(div, name, action) {
  const answer = div.querySelector(".answer");
  let path, body = null;
  if (action.startsWith("calib-")) {
    path = `calib/${encodeURIComponent(name)}/${action.slice(6)}`;
  } else if (["ptz-hold", "ptz-follow"].includes(action)) {
    path = `ptz/${encodeURIComponent(name)}/${action.slice(4)}`;
  } else if (action === "ptz-preset") {
    path = `ptz/${encodeURIComponent(name)}/preset`;
    body = {preset: div.querySelector("select.presets").value};
  } else {  // ◀ ▶ ▲ ▼ ＋ －: by a step from wherever the camera is (it adds them itself)
    const step = {"ptz-left": [-STEP_DEG, 0, 0], "ptz-right": [STEP_DEG, 0, 0],
                  "ptz-up": [0, STEP_DEG, 0], "ptz-down": [0, -STEP_DEG, 0],
                  "ptz-in": [0, 0, ZOOM_STEP], "ptz-out": [0, 0, -ZOOM_STEP]}[action];
    path = `ptz/${encodeURIComponent(name)}/nudge`;
    body = {pan_deg: step[0], tilt_deg: step[1], zoom: step[2]};
  }
  const reply = await post(path, body);
  answer.textContent = `${action.replace("-", " ")}: ${reply.accepted ? "sent" : "refused — " + reply.detail}`;
  answer.className = reply.accepted ? "answer" : "answer warn";
}

async function post(path, body) {
  try {
    const reply = await fetch(path, {method: "POST", headers: {
      "X-CSRF-Token": me ? me.csrf : "", "Content-Type": "application/json"},
      body: body === null ? null : JSON.stringify(body)});
    if (reply.status === 401) { signedOut(); return {accepted: false, detail: "signed out"}; }
    return await reply.json();
  } catch (err) {
    return {accepted: false, detail: `no answer (${err})`};
  }
}

function drawCameraControls(div, cam) {
  const cal = cam.calibration;
  const review = cal && cal.state === "review";
  const collecting = cal && ["collecting", "solving", "review"].includes(cal.state);
  div.querySelector("[data-command='calib-accept']").hidden = !review;
  div.querySelector("[data-command='calib-discard']").hidden = !review;
  div.querySelector("[data-command='calib-cancel']").hidden = !collecting || review;
  div.querySelector("[data-command='calib-start']").hidden = collecting;
  div.dataset.held = cam.held_by || "";
  const select = div.querySelector("select.presets");
  const names = (cam.presets || []).join("|");
  if (select.dataset.names !== names) {
    select.dataset.names = names;
    select.innerHTML = (cam.presets || []).map((p) => `<option>${esc(p)}</option>`).join("");
  }
}

function applyRole(root) {
  if (!me) return;
  for (const control of root.querySelectorAll("[data-command]")) {
    control.disabled = !me.may_command;
    control.title = me.may_command ? control.title : "viewers do not command: sign in as an operator";
  }
}

function drawCameras(state) {
  const box = document.getElementById("cameras");
  const waiting = document.getElementById("cameras-waiting");
  if (waiting && Object.keys(state.cameras).length) waiting.remove();
  for (const [name, cam] of Object.entries(state.cameras)) {
    const div = cameraBox(box, name);
    const cal = cam.calibration;
    const collecting = cal && (cal.state === "collecting" || cal.state === "solving");
    const calFailed = cal && cal.state === "failed" && !cam.position;
    div.querySelector(".caption").textContent =
      `${name}: ${cam.status || "—"}, pan ${fmt(cam.pan_deg, 1, "°")}, tilt ${fmt(cam.tilt_deg, 1, "°")}` +
      (collecting ? "" : `, aim error ${fmt(cam.aim_error_deg, 2, "°")}, ` +
                         `seen ${fmt(cam.pointing_error_deg, 1, "°")} off`);
    const progress = div.querySelector(".progress-text"), bar = div.querySelector(".bar");
    progress.textContent = collecting ? calibrationText(cal)
      : cal && cal.state === "review" ? `calibrated: ${fmt(cal.mean_error_px, 2, " px")} — ${cal.message}`
      : cal && cal.state === "discarded" ? cal.message
      : cam.held_by ? `held by ${cam.held_by}: it does not follow until released (Follow)`
      : calFailed ? `uncalibrated: ${cal.message}`
      : cam.pointing_problem ? cam.pointing_problem : "";
    progress.title = progress.textContent;
    bar.style.display = collecting ? "block" : "none";
    if (collecting) {
      bar.firstChild.style.width = `${Math.min(100, 100 * cal.passpoints / Math.max(1, cal.target))}%`;
    }
    div.classList.toggle("alarm", Boolean(cam.pointing_problem) || Boolean(calFailed));
    drawCameraControls(div, cam);
    const p = cam.preview;
    // a snapshot's markers may arrive after the snapshot itself: redraw when they do
    const drawn = p && `${p.seq}|${JSON.stringify(p.markers)}`;
    if (p && previewDrawn[name] !== drawn) {
      previewDrawn[name] = drawn;
      const img = new Image();
      img.onload = () => {  // a later picture may have loaded first: draw only the latest
        if (previewDrawn[name] === drawn) drawPreview(div.querySelector("canvas"), img, p);
      };
      img.src = `preview/${encodeURIComponent(name)}.jpg?seq=${p.seq}`;
    }
  }
}

function drawPreview(canvas, img, p) {
  canvas.width = p.width_px; canvas.height = p.height_px;
  const c = canvas.getContext("2d");
  c.drawImage(img, 0, 0);
  c.strokeStyle = "rgba(255,255,255,0.5)"; c.lineWidth = 1;
  c.beginPath(); c.moveTo(p.width_px / 2 - 15, p.height_px / 2); c.lineTo(p.width_px / 2 + 15, p.height_px / 2);
  c.moveTo(p.width_px / 2, p.height_px / 2 - 15); c.lineTo(p.width_px / 2, p.height_px / 2 + 15); c.stroke();
  c.strokeStyle = "#8fd18f"; c.lineWidth = 2;
  for (const [u, v, r] of p.markers) {
    c.beginPath(); c.arc(u, v, Math.max(6, r * 2), 0, 2 * Math.PI); c.stroke();
  }
  if (p.robot_px) {
    const [u, v] = p.robot_px;
    c.strokeStyle = "#ff5050"; c.lineWidth = 2;
    c.beginPath(); c.moveTo(u - 12, v - 12); c.lineTo(u + 12, v + 12);
    c.moveTo(u + 12, v - 12); c.lineTo(u - 12, v + 12); c.stroke();
  }
  if (p.kind !== "preview") {  // calibration mode: say what the picture is
    c.fillStyle = "rgba(0,0,0,0.6)"; c.fillRect(0, 0, 330, 30);
    c.fillStyle = "#ffd84d"; c.font = "20px sans-serif"; c.fillText(p.kind, 8, 22);
  }
  canvas.dataset.seq = String(p.seq);
  canvas.dataset.kind = p.kind;
  canvas.dataset.waiting = "";
  canvas.dataset.markers = String(p.markers.length);
}

function drawGantry(state) {
  const line = document.getElementById("gantry-mode"), pill = document.getElementById("gantry-pill");
  const c = state.crane;
  if (!c) {
    line.textContent = "mode: — (waiting for the gantry)"; line.className = "";
    pill.textContent = "gantry: —"; pill.className = "";
    return;
  }
  line.textContent = `mode: ${c.mode} — ${c.mode_reason} (${c.mode_by})` +
    (c.safety_ok ? "" : " — safety circuit OPEN");
  line.className = c.mode;
  pill.textContent = `gantry: ${c.mode}, ${c.status}`;
  pill.className = c.mode;
}

// Who is signed in (session.json): their name and role, and the CSRF token every command
// carries. A viewer's controls stay disabled; the server refuses their commands too (403).
let me = null;

function signedOut() { window.location.reload(); }  // the server answers with the sign-in form

async function loadSession() {
  const reply = await fetch("session.json");
  if (reply.status === 401) return signedOut();
  me = await reply.json();
  document.getElementById("who").textContent = me.open
    ? "open page: no users file, everyone on this machine is operator"
    : `${me.user} (${me.role})`;
  document.getElementById("who").className = me.open ? "warn" : "";
  document.getElementById("signout").hidden = me.open;
  applyRole(document);
}

function drawCommands(state) {
  const table = document.getElementById("commands");
  const rows = (state.commands || []).slice(0, 8).map((c) => {
    const answer = c.accepted === null ? "…" : (c.accepted ? "done" : "refused");
    return `<tr data-command-row="${esc(c.command)}" data-by="${esc(c.by)}">` +
      `<td>${clock(c.at_s)}</td><td>${esc(c.command)}</td><td>${esc(c.by)}</td>` +
      `<td class="${c.accepted === false ? "warn" : ""}" title="${esc(c.detail)}">` +
      `${answer}</td></tr>`;
  });
  table.innerHTML = rows.length ? rows.join("") : "<tr><td>none yet</td></tr>";
}

function esc(text) {
  return String(text).replace(/[&<>"']/g, (ch) => `&#${ch.charCodeAt(0)};`);
}

async function command(name) {
  const answer = document.getElementById("gantry-answer");
  answer.textContent = `${name}…`;
  try {
    const reply = await fetch(`gantry/${name}`, {method: "POST",
                                                 headers: {"X-CSRF-Token": me ? me.csrf : ""}});
    if (reply.status === 401) return signedOut();
    const body = await reply.json();
    answer.textContent = `${name}: ${body.accepted ? "done" : "refused"} — ${body.detail}`;
    answer.className = body.accepted ? "" : "warn";
  } catch (err) {
    answer.textContent = `${name}: no answer (${err})`;
    answer.className = "warn";
  }
}

for (const button of document.querySelectorAll("#gantry-buttons button[data-command]")) {
  button.addEventListener("click", () => command(button.dataset.command));
}

// Recording: one at a time, on the page's host; past ones with their reports.
async function recordAction(action) {
  const seconds = Number(document.getElementById("record-seconds").value) || null;
  const reply = await post(`record/${action}`, action === "start" ? {seconds} : null);
  document.getElementById("record-answer").textContent =
    `${action}: ${reply.accepted ? "done" : "refused — " + reply.detail}`;
  loadRecordings();
}

async function loadRecordings() {
  try {
    const reply = await fetch("recordings.json");
    if (reply.status === 401) return signedOut();
    const view = await reply.json();
    const now = document.getElementById("record-now");
    now.textContent = !view.current ? "not recording"
      : view.current.starting ? `starting ${view.current.name} (${view.current.by}) …`
      : `recording ${view.current.name}: ${fmt(view.current.elapsed_s, 0, " s")}, ${fmt(view.current.size_mb, 1, " MB")} (${view.current.by})`;
    now.dataset.recording = view.current ? view.current.name : "";
    now.dataset.elapsed = view.current ? String(view.current.elapsed_s) : "";
    document.getElementById("recordings").innerHTML = view.past.length ? view.past.map((r) =>
      `<tr data-recording="${esc(r.name)}"><td>${esc(r.name)}</td><td>${fmt(r.size_mb, 1, " MB")}</td>` +
      `<td>${r.report ? `<a href="${esc(r.report)}" target="_blank">report</a>` : esc(r.state || "")}</td></tr>`
    ).join("") : "<tr><td>none yet</td></tr>";
  } catch (err) { /* the next poll tries again */ }
}
document.getElementById("record-start").addEventListener("click", () => recordAction("start"));
document.getElementById("record-stop").addEventListener("click", () => recordAction("stop"));
setInterval(loadRecordings, 2000);
loadRecordings();
// The lab check (stb doctor on the page's host): an operator starts it; everyone sees the
// latest table, each row's verdict and, when it failed, the fix.
async function loadDoctor() {
  try {
    const reply = await fetch("doctor.json");
    if (reply.status === 401) return signedOut();
    const view = await reply.json();
    const now = document.getElementById("doctor-now");
    const failures = (view.rows || []).filter((r) => r.verdict === "fail").length;
    now.textContent = view.running ? `checking (started by ${view.by}) …`
      : view.error ? `the check failed: ${view.error}`
      : view.finished_s ? `${failures ? failures + " failed" : "all passed"} — ${clock(view.finished_s)}, by ${view.by}`
      : "not checked yet";
    now.className = failures || view.error ? "warn" : "";
    document.getElementById("doctor").innerHTML = (view.rows || []).map((r) =>
      `<tr data-check="${esc(r.name)}" class="${r.verdict === "fail" ? "warn" : ""}">` +
      `<td>${esc(r.name)}</td><td>${esc(r.verdict)}</td>` +
      `<td>${esc(r.found)}${r.fix ? `<br>fix: ${esc(r.fix)}` : ""}</td></tr>`).join("");
    if (view.running) setTimeout(loadDoctor, 1000);
  } catch (err) { /* the next look tries again */ }
}
document.getElementById("doctor-run").addEventListener("click", async () => {
  const reply = await post("doctor/run", null);
  if (!reply.accepted) document.getElementById("doctor-now").textContent = `refused — ${reply.detail}`;
  loadDoctor();
});
loadDoctor();
// Stop from the keyboard at any moment: Escape.
document.addEventListener("keydown", (event) => {
  if (event.key === "Escape") {
    event.preventDefault();
    if (me && me.may_command) command("stop");
  }
});
document.getElementById("signout").addEventListener("click", async () => {
  await fetch("signout", {method: "POST"});
  signedOut();
});

// The crane's observation camera (stb/video/observation): its latest picture, loaded when a
// new one has come; how old it is under it.
const BIRDSEYE = "observation";
let birdseyeSeq = null;
function drawBirdseye(state) {
  const v = (state.videos || {})[BIRDSEYE], img = document.getElementById("birdseye");
  const age = document.getElementById("birdseye-age");
  if (!v) { age.textContent = "no picture yet (stb camera --set role=observation)"; return; }
  age.textContent = `${v.width_px}×${v.height_px}, ${fmt(v.age_s, 1)} s old`;
  age.classList.toggle("warn", v.age_s > 2);
  if (v.seq !== birdseyeSeq) {
    birdseyeSeq = v.seq;
    img.src = `video/${BIRDSEYE}.jpg?seq=${v.seq}`;
  }
}

function draw(state) {
  latest = state;
  drawMap(state);
  drawPlot(state);
  if (!state) return;
  drawAlarms(state);
  drawGantry(state);
  drawCommands(state);
  drawServices(state);
  drawOffload(state);
  drawCameras(state);
  drawBirdseye(state);
  document.getElementById("robot-xy").textContent = state.robot
    ? `robot: ${fmt(state.robot.x_mm)}, ${fmt(state.robot.y_mm)} mm, ${fmt(state.robot.speed_mm_s)} mm/s`
    : "robot: —";
  document.getElementById("crane-xy").textContent = state.crane
    ? `crane: ${fmt(state.crane.x_mm)}, ${fmt(state.crane.y_mm)} mm` : "crane: —";
}

function connect() {
  const status = document.getElementById("connection");
  const events = new EventSource("events");
  events.onopen = () => { status.textContent = "live"; status.className = "up"; };
  events.onmessage = (event) => draw(JSON.parse(event.data));
  events.onerror = () => {
    status.textContent = "reconnecting…"; status.className = "down";
    loadSession().catch(() => {});  // signed out (expired, or the service restarted)?
    const banner = document.getElementById("alarms");
    banner.className = "on";
    banner.textContent = "⚠ no connection to the web service: what you see may be old";
  };
}

draw(null);  // the waiting texts, before anything arrives
loadSession().catch(() => {});
loadMap();
fetch("state.json").then((r) => r.json()).then((state) => { if (!latest) draw(state); })
  .catch(() => {});
connect();
