// rangekit ui: the Live page (the camera stream with its figures, the camera controls written into the rig file,
// the projector's patterns, the turntable) and the devices' status in the header. The status is shown from the answer
// to a request that changes it and whenever the server sends it (events.js, /ws/jobs: a jog, a pattern, a job taking
// or freeing the rig, from this page or any other); no timer.
"use strict";

function showError(text) { $("error").textContent = text || ""; }

// A POST of the Live page: the rig's status it answers shown, a refusal in the page's error line.
async function post(path, body) {
  const data = await send(path, body, { error: $("error") });
  if (data?.rig) showStatus(data.rig);
  return data;
}

let controlsShown = false;

function showStatus(rig) {
  $("rig-source").textContent = `${rig.source} - ${rig.rig_file}`;
  if (!controlsShown) {   // the rig file's values, else the defaults in force, once: the user's typing stays
    for (const input of $("controls").querySelectorAll("input")) {
      const v = rig.controls[input.name] ?? rig.controls_in_force?.[input.name];
      input.value = v === undefined || v === null ? "" : v;
      input.title = rig.controls[input.name] === undefined ? "the default (the rig file does not set it)" : "";
    }
    controlsShown = true;
  }
  const rows = [
    ["camera", rig.camera.connected ? `${rig.camera.width}x${rig.camera.height}` : "not connected"],
    ["projector", rig.projector.connected ? `pattern ${rig.pattern}` : "not connected"],
    ["turntable", rig.turntable.connected ? `${rig.turntable.angle_deg} deg${rig.turntable.turning ? " (turning)" : ""}` : "not connected"],
    ["busy", rig.busy || "no"], ["fault", rig.fault || "none"], ["last reply", rig.last_reply]];
  $("status").innerHTML = "";
  for (const [k, v] of rows) {
    const tr = $("status").insertRow(); tr.insertCell().outerHTML = `<th>${k}</th>`; tr.insertCell().textContent = v;
  }
  for (const b of document.querySelectorAll("#patterns button")) b.classList.toggle("on", b.dataset.name === rig.pattern);
  $("reconnect").hidden = rig.source !== "hardware";
}

// GET /api/status's body, as /ws/jobs sends it: the pattern buttons (once), the status.
function showRigStatus(data) {
  const box = $("patterns");
  if (!box.children.length) {
    for (const name of data.patterns) {
      const b = document.createElement("button"); b.textContent = name; b.dataset.name = name;
      b.onclick = () => post("/api/pattern", { name }); box.appendChild(b);
    }
  }
  showStatus(data.rig);
}

// The board's corners found in the live frame: green dots when it is found whole.
function drawCorners(ctx, board) {
  ctx.fillStyle = "#3c3"; ctx.strokeStyle = "#3c3"; ctx.lineWidth = 2;
  const r = Math.max(3, ctx.canvas.width / 300);
  for (const [u, v] of board.corners) { ctx.beginPath(); ctx.arc(u + 0.5, v + 0.5, r, 0, 2 * Math.PI); ctx.fill(); }
  if (board.corners.length) { const [u, v] = board.corners[0]; ctx.strokeRect(u - 3 * r, v - 3 * r, 6 * r, 6 * r); }
}

function liveWaiting(text) { $("live-waiting").hidden = false; $("live-waiting").textContent = text; }

async function startLive() {
  const t = await ticket("/ws/live");
  if (!t) {     // the server gone (try again), or another token (stale: the banner says so; no retry)
    if (serverMayAnswer()) { liveWaiting("reconnecting"); setTimeout(startLive, 1000); }
    else liveWaiting("the server restarted: open the new URL it printed");
    return;
  }
  const ws = new WebSocket(`ws://${location.host}/ws/live?ticket=${encodeURIComponent(t)}`);
  ws.binaryType = "blob";
  let figures = null, shown = [];
  ws.onmessage = async (ev) => {
    if (typeof ev.data === "string") {
      const msg = JSON.parse(ev.data);
      if (msg.waiting) { $("live-waiting").hidden = false; $("live-waiting").textContent = msg.waiting; return; }
      figures = msg; return;
    }
    // The visible page's live canvas (Live, or Calibrate with the board's corners found in the frame).
    const canvas = document.querySelector("main > section:not([hidden]) canvas.live") || $("live-canvas");
    const ctx = canvas.getContext("2d");
    const bitmap = await createImageBitmap(ev.data);
    if (canvas.width !== bitmap.width) { canvas.width = bitmap.width; canvas.height = bitmap.height; }
    ctx.drawImage(bitmap, 0, 0);
    bitmap.close();
    if (figures && figures.board && canvas.id !== "live-canvas") drawCorners(ctx, figures.board);
    $("live-waiting").hidden = true;
    const now = performance.now(); shown.push(now); shown = shown.filter((t) => now - t < 2000);
    window.rangekitLive = { frames: (window.rangekitLive?.frames || 0) + 1, figures };
    if (figures) {
      $("fig-fps").textContent = `${(shown.length / 2).toFixed(1)} /s`;
      $("fig-sat").textContent = `${figures.saturated_percent} %`;
      $("fig-dark").textContent = `${figures.dark_percent} %`;
      $("fig-focus").textContent = figures.focus.toFixed(1);
    }
  };
  ws.onclose = () => { liveWaiting("reconnecting"); setTimeout(startLive, 1000); };
}

// Each field's error next to it (the rig file's own words name the field: capture.camera.<name>).
$("controls").onsubmit = async (ev) => {
  ev.preventDefault();
  const changes = {};
  for (const input of $("controls").querySelectorAll("input")) {
    const text = input.value.trim();
    if (text === "") continue;
    changes[input.name] = /^-?[0-9.]+(e-?[0-9]+)?$/i.test(text) ? Number(text) : text;
  }
  const data = await send("/api/camera", changes, { form: $("controls"), error: $("error") });
  if (data) showStatus(data.rig);
};

for (const b of document.querySelectorAll("[data-jog]")) b.onclick = () => post("/api/turntable", { degrees: Number(b.dataset.jog) });
$("home").onclick = () => post("/api/turntable", { home: true });
$("reconnect").onclick = () => post("/api/reconnect", {});
rangekitEvents.onRig(showRigStatus);
startLive();

