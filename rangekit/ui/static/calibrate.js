// rangekit ui: the Calibrate page (rangekit calibrate pose by pose: place, capture, keep or retake; the result
// per parameter, written to the rig file), and a calibration from recorded capture folders.
"use strict";

function calError(text) { $("calibrate-error").textContent = text || ""; }

async function calPost(action, body) {
  const r = await api(`/api/calibrate/${action}`, body || {});
  const data = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
  for (const e of document.querySelectorAll("#calibrate-form .field-error")) e.textContent = "";
  if (!r.ok) {
    if (/^poses:/.test(data.error)) document.querySelector("#calibrate-form .field-error[data-for=poses]").textContent = data.error;
    else calError(data.error);
    return null;
  }
  calError(""); showCalibration(data); return data;
}

let calPictures = "";
function showCalibration(c) {
  const waiting = { placing: "place the board, then capture", review: "keep this pose, or retake it",
                    capturing: "capturing (coded light on the board)", moving: "moving to the retake",
                    turntable: "the board on the turntable: turning it", starting: "starting",
                    done: "done: the rig file is written", failed: "failed", cancelled: "cancelled", idle: "" };
  const pose = typeof c.pose === "number" ? ` - pose ${c.pose + 1} of ${c.n}` : (c.pose ? ` - ${c.pose}` : "");
  $("calibrate-state").textContent = (waiting[c.state] ?? c.state) + (c.state === "placing" || c.state === "review" ? pose : "");
  window.rangekitCalibrate = c;
  const running = !["idle", "done", "failed", "cancelled"].includes(c.state);
  $("calibrate-start").disabled = running; $("calibrate-cancel").disabled = !running;
  $("calibrate-capture").disabled = c.state !== "placing";
  $("calibrate-keep").disabled = $("calibrate-retake").disabled = c.state !== "review";
  $("calibrate-next").disabled = !(c.state === "placing" && c.simulated);
  $("calibrate-last").textContent = c.last || "";
  $("calibrate-hint").textContent = running ? (c.hint || "") : "";
  $("calibrate-poses").innerHTML = "";
  for (const p of c.poses) {
    const tr = $("calibrate-poses").insertRow(); tr.insertCell().outerHTML = `<th>pose ${p.index + 1}</th>`;
    tr.insertCell().textContent = p.kept ? `kept, ${p.reprojection_px?.toFixed(3)} px, tilt ${p.tilt_deg?.toFixed(0)} deg`
                                         : `rejected: ${p.reason}`;
    tr.className = p.kept ? "" : "bad";
  }
  const key = c.pictures.join() + c.poses.length + c.state;
  if (c.pictures.length && key !== calPictures) {
    calPictures = key;
    for (const name of c.pictures) showImage($(`calibrate-${name}`), `/api/calibrate/picture/${name}.png`);
  }
  $("calibrate-progress").innerHTML = "";
  for (const line of c.progress || []) { const li = document.createElement("li"); li.textContent = line; $("calibrate-progress").appendChild(li); }
  if (c.state === "failed") calError(c.error);
  $("calibrate-result").innerHTML = ""; $("calibrate-deviation").innerHTML = "";
  if (c.state === "done") {
    const head = $("calibrate-result").insertRow();
    for (const h of ["device", "fx", "fy", "cx", "cy"]) head.insertCell().outerHTML = `<th>${h}</th>`;
    for (const p of c.parameters) {
      const tr = $("calibrate-result").insertRow();
      for (const v of [p.device, p.fx, p.fy, p.cx, p.cy]) tr.insertCell().textContent = v;
      const lens = $("calibrate-result").insertRow().insertCell();
      lens.colSpan = 5; lens.className = "note"; lens.textContent = `distortion ${p.dist.join(" ")}`;
    }
    const lines = [`written to ${c.rig_file}`, ...(c.deviation_lines.length ? ["against the simulator's truth:", ...c.deviation_lines] : [])];
    for (const line of lines) { const li = document.createElement("li"); li.textContent = line; $("calibrate-deviation").appendChild(li); }
  }
}

async function pollCalibrate() {
  if (location.hash !== "#calibrate" && window.rangekitCalibrate) return;
  const r = await api("/api/calibrate");
  if (r.ok) showCalibration(await r.json());
}

$("calibrate-form").onsubmit = (ev) => {
  ev.preventDefault();
  const text = $("calibrate-form").poses.value.trim();
  calPost("start", { poses: /^[0-9]+$/.test(text) ? Number(text) : text });
};
$("calibrate-cancel").onclick = () => calPost("cancel");
$("calibrate-capture").onclick = () => calPost("capture");
$("calibrate-keep").onclick = () => calPost("keep");
$("calibrate-retake").onclick = () => calPost("retake");
$("calibrate-next").onclick = () => calPost("next");

// Simulator: drag the picture to move the board across the view (the shift in camera pixels).
(() => {
  const canvas = $("calibrate-canvas");
  let from = null;
  const at = (ev) => { const b = canvas.getBoundingClientRect(); return [(ev.clientX - b.left) * canvas.width / b.width, (ev.clientY - b.top) * canvas.height / b.height]; };
  canvas.onpointerdown = (ev) => { from = at(ev); };
  canvas.onpointerup = (ev) => {
    if (!from) return;
    const to = at(ev), dx = to[0] - from[0], dy = to[1] - from[1]; from = null;
    if (Math.hypot(dx, dy) > 3 && window.rangekitCalibrate?.state === "placing") calPost("drag", { dx, dy });
  };
})();

// -- from recorded capture folders (under --sessions), as rangekit calibrate --captures
async function showRecorded(c) {
  $("recorded-state").textContent = c.state === "idle" ? "" : c.state + (c.error ? `: ${c.error}` : c.rig_file ? `: wrote ${c.rig_file}` : "");
  $("recorded-start").disabled = c.state === "running";
  $("recorded-lines").innerHTML = "";
  for (const line of c.lines || []) { const li = document.createElement("li"); li.textContent = line; $("recorded-lines").appendChild(li); }
  const select = $("recorded-form").pattern;
  if (!select.options.length) for (const name of c.layouts || []) select.add(new Option(name, name));
}
async function pollRecorded() {
  if (location.hash !== "#calibrate" && $("recorded-form").pattern.options.length) return;
  const r = await api("/api/calibrate-recorded");
  if (r.ok) showRecorded(await r.json());
}
$("recorded-form").onsubmit = async (ev) => {
  ev.preventDefault();
  const f = $("recorded-form");
  for (const e of f.querySelectorAll(".field-error")) e.textContent = "";
  const num = (t) => (/^[0-9.]+$/.test(t.trim()) ? Number(t) : t);
  const body = { captures: f.captures.value.trim(), pattern: f.pattern.value, projector: f.projector.value.trim(), out: f.out.value.trim(),
                 cols: num(f.cols.value), rows: num(f.rows.value), square_mm: num(f.square_mm.value),
                 replace: f.replace.checked };
  const r = await api("/api/calibrate-recorded/start", body);
  const data = await r.json();
  if (!r.ok) {
    const field = ["captures", "projector", "out", "cols", "rows", "square_mm"].find((k) => data.error.startsWith(`${k}:`));
    if (field) f.querySelector(`.field-error[data-for=${field}]`).textContent = data.error; else $("recorded-state").textContent = data.error;
    return;
  }
  showRecorded(data);
};

setInterval(() => { pollCalibrate(); pollRecorded(); }, 600);
pollCalibrate(); pollRecorded();
