// The live view's page: one WebSocket to the node (/ws). Text messages are the state (JSON),
// binary messages camera frames (JPEG). Requests go back as {"id", "op", ...} and each gets a
// reply. Plain JavaScript and canvas, nothing loaded from elsewhere.
"use strict";

const PLATE_HALF_M = 0.2285, MARKER_CENTRE_M = 0.1835, MARKER_SIDE_M = 0.04, BALL_RADIUS_M = 0.02;
const $ = (id) => document.getElementById(id);
let ws = null, nextId = 1, state = null, frame = null, gainsBuilt = "";
const waiting = new Map();

function mm(v) { return v === null || v === undefined ? "-" : (1000 * v).toFixed(1); }

function connect() {
  ws = new WebSocket(`ws://${location.host}/ws`);
  ws.binaryType = "blob";
  ws.onopen = () => setBadge($("connection"), "connected", "ok");
  ws.onclose = () => {
    setBadge($("connection"), "disconnected: reconnecting", "bad");
    for (const [id, what] of waiting) showReply({id, ok: false, message: `${what}: connection lost`});
    waiting.clear();
    setTimeout(connect, 1000);
  };
  ws.onmessage = (event) => {
    if (typeof event.data === "string") {
      const msg = JSON.parse(event.data);
      if (msg.type === "state") { state = msg; render(); }
      else if (msg.type === "reply") showReply(msg);
    } else {
      createImageBitmap(event.data).then((bitmap) => { if (frame) frame.close(); frame = bitmap; drawCamera(); });
    }
  };
}

function send(request, what) {
  if (!ws || ws.readyState !== WebSocket.OPEN) { showReply({ok: false, message: `${what}: not connected`}); return; }
  request.id = nextId++;
  waiting.set(request.id, what);
  $("status-line").textContent = `${what}: waiting for the answer ...`;
  ws.send(JSON.stringify(request));
}

function showReply(msg) {
  waiting.delete(msg.id);
  const line = $("status-line");
  line.textContent = `${msg.ok ? "OK" : "FAILED"}: ${msg.message}`;
  line.className = msg.ok ? "" : "failed";
  line.dataset.ok = String(msg.ok);
}

function setBadge(el, text, cls) { el.textContent = text; el.className = "badge " + cls; }

function render() {
  const s = state, b = s.ball;
  $("ball-x").textContent = b ? mm(b.x) : "-";
  $("ball-y").textContent = b ? mm(b.y) : "-";
  $("ball-count").textContent = b ? b.count : 0;
  $("markers").textContent = b ? b.markers_found : "-";
  $("tracking").textContent = !b ? "no ball state" : !s.fresh.ball ? "stale (no ball state)" :
    b.tracking_valid ? (b.ball_found ? "tracking" : "coasting") : "lost";
  $("ref-x").textContent = s.reference ? mm(s.reference[0]) : "-";
  $("ref-y").textContent = s.reference ? mm(s.reference[1]) : "-";
  $("arm-speed").textContent = s.arm.speed_rad_s === null || !s.fresh.joints ? "-" : s.arm.speed_rad_s.toFixed(4);
  const rm = s.robot_manager;
  $("rm-state").textContent = rm.present ? rm.lifecycle_state : `absent (${rm.lifecycle_state})`;
  const estop = $("estop-state");
  if (rm.emergency_stop_active === null) setBadge(estop, "unknown", "warn");
  else if (rm.emergency_stop_active) setBadge(estop, "ACTIVE", "bad");
  else setBadge(estop, "released", "ok");
  $("events").innerHTML = "";
  for (const e of rm.events) {
    const li = document.createElement("li");
    li.textContent = `${new Date(e.t * 1000).toLocaleTimeString()} [${["OK", "WARN", "ERROR", "STALE"][e.level] || e.level}] ` +
      `${e.event} ${e.source ? "(" + e.source + ")" : ""}: ${e.message}`;
    $("events").appendChild(li);
  }
  const c = s.controller;
  $("controller-node").textContent = c.node;
  $("controller-state").textContent = !c.present ? "absent" : c.engaged ? "engaged (tracking the reference)" : "not engaged";
  $("plant").textContent = c.plant || "-";
  buildGains(s.gain_names, c.parameters);
  $("error-window").textContent = `last ${s.error_window_s} s (reference - ball)`;
  const last = s.errors.length ? s.errors[s.errors.length - 1] : null;
  $("error-now").textContent = last ? (1000 * Math.hypot(last[1], last[2])).toFixed(1) : "-";
  $("image-info").textContent = `${s.image.topic}, ${s.image.width}x${s.image.height}, at most ${s.image.rate_hz} frames/s, ${s.image.frames_sent} sent`;
  drawPlate(); drawError(); drawCamera();
}

function buildGains(names, params) {
  const form = $("gains");
  const key = names.join(",");
  if (gainsBuilt !== key) {
    form.innerHTML = "";
    for (const name of names) {
      const label = document.createElement("label");
      label.innerHTML = `${name} <input id="gain-${name}" type="number" step="0.05" min="0"> <small id="gain-now-${name}"></small>`;
      form.appendChild(label);
    }
    const button = document.createElement("button");
    button.type = "submit"; button.id = "btn-gains"; button.textContent = "Set gains";
    form.appendChild(button);
    gainsBuilt = key;
  }
  for (const name of names) {
    const value = params ? params[name] : undefined;
    $(`gain-now-${name}`).textContent = value === undefined || value === null ? "(unknown)" : `now ${value}`;
    const input = $(`gain-${name}`);
    if (input.value === "" && typeof value === "number") input.value = value;
  }
}

function drawCamera() {
  const canvas = $("camera"), ctx = canvas.getContext("2d");
  if (!frame) {
    ctx.fillStyle = "#111"; ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.fillStyle = "#aaa"; ctx.font = "16px sans-serif"; ctx.fillText("no camera frame yet", 20, 30);
    return;
  }
  if (canvas.width !== frame.width || canvas.height !== frame.height) { canvas.width = frame.width; canvas.height = frame.height; }
  ctx.drawImage(frame, 0, 0);
  const b = state && state.ball;
  if (!b) return;
  // the tracker's detection, scaled to the frame as sent (the state's pixels are the camera's)
  const k = state.image.scale || 1;
  ctx.lineWidth = 2;
  if (b.ball_found) {
    ctx.strokeStyle = b.tracking_valid ? "#00e676" : "#ffeb3b";
    ctx.beginPath(); ctx.arc(b.pixel_u * k, b.pixel_v * k, 14 * k, 0, 2 * Math.PI); ctx.stroke();
    ctx.beginPath(); ctx.moveTo(b.pixel_u * k - 20 * k, b.pixel_v * k); ctx.lineTo(b.pixel_u * k + 20 * k, b.pixel_v * k);
    ctx.moveTo(b.pixel_u * k, b.pixel_v * k - 20 * k); ctx.lineTo(b.pixel_u * k, b.pixel_v * k + 20 * k); ctx.stroke();
  }
  ctx.fillStyle = "rgba(0,0,0,0.55)"; ctx.fillRect(0, 0, 330, 26);
  ctx.fillStyle = "#fff"; ctx.font = "15px monospace";
  ctx.fillText(`markers ${b.markers_found}/4  x ${mm(b.x)}  y ${mm(b.y)} mm`, 6, 18);
}

function drawPlate() {
  const canvas = $("plate"), ctx = canvas.getContext("2d"), w = canvas.width, h = canvas.height;
  const k = (Math.min(w, h) / 2 - 10) / PLATE_HALF_M;
  const px = (x) => w / 2 + k * x, py = (y) => h / 2 - k * y;   // plate +y is up on the page
  ctx.fillStyle = "#ddd"; ctx.fillRect(0, 0, w, h);
  ctx.fillStyle = "#f7f7f4"; ctx.fillRect(px(-PLATE_HALF_M), py(PLATE_HALF_M), 2 * k * PLATE_HALF_M, 2 * k * PLATE_HALF_M);
  ctx.fillStyle = "#222";
  for (const sx of [-1, 1]) for (const sy of [-1, 1]) {
    const cx = sx * MARKER_CENTRE_M, cy = sy * MARKER_CENTRE_M, half = MARKER_SIDE_M / 2;
    ctx.fillRect(px(cx - half), py(cy + half), k * MARKER_SIDE_M, k * MARKER_SIDE_M);
  }
  ctx.strokeStyle = "#bbb"; ctx.lineWidth = 1;
  ctx.beginPath(); ctx.moveTo(px(-PLATE_HALF_M), py(0)); ctx.lineTo(px(PLATE_HALF_M), py(0));
  ctx.moveTo(px(0), py(-PLATE_HALF_M)); ctx.lineTo(px(0), py(PLATE_HALF_M)); ctx.stroke();
  const s = state;
  if (!s) return;
  if (s.path.length > 1) {
    ctx.strokeStyle = "rgba(230,120,20,0.7)"; ctx.lineWidth = 2; ctx.beginPath();
    s.path.forEach(([x, y], i) => (i ? ctx.lineTo(px(x), py(y)) : ctx.moveTo(px(x), py(y))));
    ctx.stroke();
  }
  if (s.reference) {
    const [rx, ry] = s.reference;
    ctx.strokeStyle = "#2e7d32"; ctx.lineWidth = 3; ctx.beginPath();
    ctx.moveTo(px(rx) - 10, py(ry) - 10); ctx.lineTo(px(rx) + 10, py(ry) + 10);
    ctx.moveTo(px(rx) + 10, py(ry) - 10); ctx.lineTo(px(rx) - 10, py(ry) + 10); ctx.stroke();
  }
  const b = s.ball;
  if (b) {
    ctx.fillStyle = b.tracking_valid && s.fresh.ball ? "#ff7300" : "#888";
    ctx.beginPath(); ctx.arc(px(b.x), py(b.y), k * BALL_RADIUS_M, 0, 2 * Math.PI); ctx.fill();
  }
}

function drawError() {
  const canvas = $("error"), ctx = canvas.getContext("2d"), w = canvas.width, h = canvas.height;
  ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, w, h);
  const s = state, window_s = s.error_window_s;
  let peak = 0.01;
  for (const [, ex, ey] of s.errors) peak = Math.max(peak, Math.abs(ex), Math.abs(ey));
  const px = (t) => w * (1 + t / window_s), py = (e) => h / 2 - (h / 2 - 12) * e / peak;
  ctx.strokeStyle = "#ccc"; ctx.beginPath(); ctx.moveTo(0, h / 2); ctx.lineTo(w, h / 2); ctx.stroke();
  ctx.fillStyle = "#666"; ctx.font = "12px sans-serif";
  ctx.fillText(`±${(1000 * peak).toFixed(0)} mm`, 4, 12); ctx.fillText(`-${window_s} s`, 4, h - 4); ctx.fillText("now", w - 28, h - 4);
  for (const [index, color] of [[1, "#d84315"], [2, "#1565c0"]]) {
    ctx.strokeStyle = color; ctx.lineWidth = 1.5; ctx.beginPath();
    s.errors.forEach((e, i) => (i ? ctx.lineTo(px(e[0]), py(e[index])) : ctx.moveTo(px(e[0]), py(e[index]))));
    ctx.stroke();
  }
}

function number(id) { const v = parseFloat($(id).value); return Number.isFinite(v) ? v : null; }

document.querySelectorAll("button[data-transition]").forEach((button) => {
  button.addEventListener("click", () => send({op: "lifecycle", transition: button.dataset.transition}, button.dataset.transition));
});
$("btn-estop").addEventListener("click", () => send({op: "emergency_stop"}, "emergency stop"));
$("btn-reset").addEventListener("click", () => send({op: "reset_emergency_stop"}, "reset emergency stop"));
$("gains").addEventListener("submit", (event) => {
  event.preventDefault();
  const values = {};
  for (const name of state ? state.gain_names : []) { const v = number(`gain-${name}`); if (v !== null) values[name] = v; }
  send({op: "set_parameters", values}, "set gains");
});
$("reference").addEventListener("submit", (event) => {
  event.preventDefault();
  send({op: "reference", kind: $("ref-kind").value, centre_m: [number("ref-cx"), number("ref-cy")],
        radius_m: number("ref-radius"), period_s: number("ref-period")}, "set reference");
});
drawCamera(); drawPlate();
connect();
