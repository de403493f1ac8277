// rangekit ui: the Calibrate page (rangekit calibrate pose by pose: place, capture, keep or retake; the result
// per parameter, written to the rig file), and a calibration from recorded capture folders. Both shown as the
// server sends their state (events.js, /ws/jobs), no timer.
"use strict";

function calError(text) { $("calibrate-error").textContent = text || ""; }

// An action of the wizard; its refusal shown by its field. The state it leads to comes over /ws/jobs (an answer
// could arrive after a newer state there).
function calPost(action, body) {
  return send(`/api/calibrate/${action}`, body || {}, { form: $("calibrate-form"), error: $("calibrate-error") });
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
  showLines($("calibrate-progress"), c.progress || []);
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
    showLines($("calibrate-deviation"), lines);
  }
}

$("calibrate-form").onsubmit = (ev) => {
  ev.preventDefault();
  calPost("start", { poses: typed($("calibrate-form").poses.value) });
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
function showRecorded(c) {
  $("recorded-state").textContent = c.state === "idle" ? "" : c.state + (c.error ? `: ${c.error}` : c.rig_file ? `: wrote ${c.rig_file}` : "");
  $("recorded-start").disabled = c.state === "running";
  $("recorded-lines").innerHTML = "";
  showLines($("recorded-lines"), c.lines || []);
  const select = $("recorded-form").pattern;
  if (!select.options.length) for (const name of c.layouts || []) select.add(new Option(name, name));
}
$("recorded-form").onsubmit = async (ev) => {
  ev.preventDefault();
  const f = $("recorded-form"), num = (t) => typed(t, /^[0-9.]+$/);
  const body = { captures: f.captures.value.trim(), pattern: f.pattern.value, projector: f.projector.value.trim(), out: f.out.value.trim(),
                 cols: num(f.cols.value), rows: num(f.rows.value), square_mm: num(f.square_mm.value),
                 replace: f.replace.checked };
  await send("/api/calibrate-recorded/start", body, { form: f, error: $("recorded-state") });
};

rangekitEvents.onJob("calibrate", showCalibration);
rangekitEvents.onJob("recorded", showRecorded);
