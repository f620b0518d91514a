// The operator's page: draws /events (Server-Sent Events of the live state) on a top view of
// the crater and in tables. No framework, no build step.
"use strict";

const map = document.getElementById("map");
const ctx = map.getContext("2d");
const mapImage = new Image();
let mapExtent = [-3000, 3000, -3000, 3000];  // the height map's x_min, x_max, y_min, y_max (mm)
let view = mapExtent;  // what the canvas shows: the map and every camera, square
let mapReady = false;

function loadMap() {
  // The sim may write the height map after the page started: ask again until there is one.
  fetch("map.json").then((r) => r.json()).then((info) => {
    mapExtent = info.extent_mm;
    if (info.image) {
      mapImage.onload = () => { mapReady = true; };
      mapImage.src = "map.png";
    } else {
      setTimeout(loadMap, 3000);
    }
  }).catch(() => setTimeout(loadMap, 3000));
}
loadMap();

function fitView(state) {
  let [x0, x1, y0, y1] = mapExtent;
  for (const cam of Object.values(state.cameras)) {
    if (!cam.position) continue;
    x0 = Math.min(x0, cam.position[0] - 300); x1 = Math.max(x1, cam.position[0] + 300);
    y0 = Math.min(y0, cam.position[1] - 300); y1 = Math.max(y1, cam.position[1] + 300);
  }
  const half = Math.max(x1 - x0, y1 - y0) / 2, cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  view = [cx - half, cx + half, cy - half, cy + half];
}

function toCanvas(x, y) {
  const [x0, x1, y0, y1] = view;
  return [(x - x0) / (x1 - x0) * map.width, (1 - (y - y0) / (y1 - y0)) * map.height];
}

function mmToPx(mm) {
  return mm / (view[1] - view[0]) * map.width;
}

function fmt(value, digits = 0, unit = "") {
  return value === null || value === undefined ? "—" : `${value.toFixed(digits)}${unit}`;
}

function drawMap(state) {
  fitView(state);
  ctx.clearRect(0, 0, map.width, map.height);
  if (mapReady) {
    const [left, top] = toCanvas(mapExtent[0], mapExtent[3]);
    const [right, bottom] = toCanvas(mapExtent[1], mapExtent[2]);
    ctx.globalAlpha = 0.85;
    ctx.drawImage(mapImage, left, top, right - left, bottom - top);
    ctx.globalAlpha = 1;
  } else {
    ctx.strokeStyle = "#444";
    for (let i = 1; i < 10; i++) {
      ctx.beginPath(); ctx.moveTo(i * map.width / 10, 0); ctx.lineTo(i * map.width / 10, map.height);
      ctx.moveTo(0, i * map.height / 10); ctx.lineTo(map.width, i * map.height / 10); ctx.stroke();
    }
  }
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
    ctx.font = "14px sans-serif"; ctx.fillText(name, cx + 10, cy - 6);
  }
  if (state.track.length > 1) {
    ctx.strokeStyle = "rgba(255, 80, 80, 0.8)"; ctx.lineWidth = 2;
    ctx.beginPath();
    state.track.forEach(([x, y], i) => {
      const [px, py] = toCanvas(x, y);
      if (i === 0) ctx.moveTo(px, py); else ctx.lineTo(px, py);
    });
    ctx.stroke();
  }
  if (state.estimate && state.estimate.valid) {
    const [ex, ey] = toCanvas(state.estimate.x_mm, state.estimate.y_mm);
    ctx.strokeStyle = "#bbb"; ctx.lineWidth = 1.5;
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
    ctx.strokeStyle = "#4da3ff"; ctx.lineWidth = 2;
    ctx.beginPath(); ctx.moveTo(kx - 10, ky); ctx.lineTo(kx + 10, ky);
    ctx.moveTo(kx, ky - 10); ctx.lineTo(kx, ky + 10); ctx.stroke();
    if (state.offload) {
      ctx.strokeStyle = state.offload.warning ? "#ff7b6b" : "#4da3ff";
      ctx.beginPath();
      ctx.arc(kx, ky, Math.max(3, mmToPx(state.offload.horizontal_error_mm)), 0, 2 * Math.PI);
      ctx.stroke();
    }
  }
}

function row(cells, cls = "") {
  const tr = document.createElement("tr");
  if (cls) tr.className = cls;
  for (const cell of cells) {
    const td = document.createElement("td");
    td.textContent = cell;
    tr.appendChild(td);
  }
  return tr;
}

function drawServices(state) {
  const table = document.getElementById("services");
  table.replaceChildren();
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
  if (!o) { table.appendChild(row(["offload", "no data yet"])); return; }
  table.appendChild(row(["horizontal error", fmt(o.horizontal_error_mm, 0, " mm")]));
  table.appendChild(row(["cable length", fmt(o.cable_length_mm, 0, " mm")]));
  table.appendChild(row(["vertical pull lost", fmt(o.vertical_loss_pct, 3, " %")]));
  table.appendChild(row(["sideways pull", fmt(o.horizontal_share_pct, 2, " %")],
                        o.warning ? "warn" : ""));
}

const previewSeq = {};

function drawCameras(state) {
  const box = document.getElementById("cameras");
  for (const [name, cam] of Object.entries(state.cameras)) {
    let div = document.getElementById(`camera-${name}`);
    if (!div) {
      div = document.createElement("div");
      div.id = `camera-${name}`;
      div.className = "preview";
      div.innerHTML = `<div class="caption"></div><canvas width="352" height="288"></canvas>`;
      box.appendChild(div);
    }
    const cal = cam.calibration;
    const collecting = cal && (cal.state === "collecting" || cal.state === "solving");
    const calFailed = cal && cal.state === "failed" && !cam.position;
    div.querySelector(".caption").textContent =
      `${name}: ${cam.status || "—"}, pan ${fmt(cam.pan_deg, 1, "°")}, tilt ${fmt(cam.tilt_deg, 1, "°")}, ` +
      (collecting ? `calibrating: ${cal.passpoints} of ${cal.target} passpoints` +
        (cal.state === "solving" ? ", solving" : "")
       : `aim error ${fmt(cam.aim_error_deg, 2, "°")}, seen ${fmt(cam.pointing_error_deg, 1, "°")} off`) +
      (calFailed ? ` — uncalibrated: ${cal.message}` : "") +
      (cam.pointing_problem ? ` — ${cam.pointing_problem}` : "");
    div.classList.toggle("alarm", Boolean(cam.pointing_problem) || Boolean(calFailed));
    const p = cam.preview;
    if (p && previewSeq[name] !== p.seq) {
      previewSeq[name] = p.seq;
      const img = new Image();
      img.onload = () => drawPreview(div.querySelector("canvas"), img, p);
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
  canvas.dataset.seq = String(p.seq);
}

function drawGantry(state) {
  const line = document.getElementById("gantry-mode"), c = state.crane;
  if (!c) { line.textContent = "mode: —"; line.className = ""; return; }
  line.textContent = `mode: ${c.mode} — ${c.mode_reason} (${c.mode_by})` +
    (c.safety_ok ? "" : " — safety circuit OPEN");
  line.className = c.mode;
}

async function command(name) {
  const answer = document.getElementById("gantry-answer");
  answer.textContent = `${name}…`;
  try {
    const reply = await fetch(`gantry/${name}`, {method: "POST", headers: {"X-STB-Command": "1"}});
    const body = await reply.json();
    answer.textContent = `${name}: ${body.accepted ? "done" : "refused"} — ${body.detail}`;
  } catch (err) {
    answer.textContent = `${name}: no answer (${err})`;
  }
}

for (const button of document.querySelectorAll("button[data-command]")) {
  button.addEventListener("click", () => command(button.dataset.command));
}

function draw(state) {
  drawMap(state);
  drawGantry(state);
  drawServices(state);
  drawOffload(state);
  drawCameras(state);
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
  events.onerror = () => { status.textContent = "reconnecting…"; status.className = "down"; };
}

connect();
