// rangekit ui: the Live page. Same-origin requests only; the token travels as the cookie the first load set.
"use strict";

const $ = (id) => document.getElementById(id);

function showError(text) { $("error").textContent = text || ""; }

async function post(path, body) {
  const r = await fetch(path, { method: "POST", headers: { "Content-Type": "application/json" },
                                body: JSON.stringify(body) });
  const data = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
  if (!r.ok) { showError(data.error || `HTTP ${r.status}`); return null; }
  showError("");
  if (data.rig) showStatus(data.rig);
  return data;
}

let controlsShown = false;

function showStatus(rig) {
  $("rig-source").textContent = `${rig.source} - ${rig.rig_file}`;
  if (!controlsShown) {   // the rig file's values, once: the user's typing is not overwritten
    for (const input of $("controls").querySelectorAll("input")) {
      const v = rig.controls[input.name]; input.value = v === undefined ? "" : v;
    }
    controlsShown = true;
  }
  const rows = [
    ["camera", rig.camera.connected ? `${rig.camera.width}x${rig.camera.height}` : "not connected"],
    ["projector", rig.projector.connected ? `pattern ${rig.pattern}` : "not connected"],
    ["turntable", rig.turntable.connected ? `${rig.turntable.angle_deg} deg` : "not connected"],
    ["busy", rig.busy || "no"], ["fault", rig.fault || "none"], ["last reply", rig.last_reply]];
  $("status").innerHTML = "";
  for (const [k, v] of rows) {
    const tr = $("status").insertRow(); tr.insertCell().outerHTML = `<th>${k}</th>`; tr.insertCell().textContent = v;
  }
  for (const b of document.querySelectorAll("#patterns button")) b.classList.toggle("on", b.dataset.name === rig.pattern);
}

async function loadStatus() {
  const r = await fetch("/api/status");
  const data = await r.json();
  const box = $("patterns");
  if (!box.children.length) {
    for (const name of data.patterns) {
      const b = document.createElement("button"); b.textContent = name; b.dataset.name = name;
      b.onclick = () => post("/api/pattern", { name }); box.appendChild(b);
    }
  }
  showStatus(data.rig);
}

function startLive() {
  const ws = new WebSocket(`ws://${location.host}/ws/live`);
  ws.binaryType = "blob";
  const canvas = $("live-canvas"), ctx = canvas.getContext("2d");
  let figures = null, shown = [];
  ws.onmessage = async (ev) => {
    if (typeof ev.data === "string") {
      const msg = JSON.parse(ev.data);
      if (msg.waiting) { $("live-waiting").hidden = false; $("live-waiting").textContent = msg.waiting; return; }
      figures = msg; return;
    }
    const bitmap = await createImageBitmap(ev.data);
    if (canvas.width !== bitmap.width) { canvas.width = bitmap.width; canvas.height = bitmap.height; }
    ctx.drawImage(bitmap, 0, 0);
    bitmap.close();
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
  ws.onclose = () => { $("live-waiting").hidden = false; $("live-waiting").textContent = "reconnecting"; setTimeout(startLive, 1000); };
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
  for (const e of document.querySelectorAll(".field-error")) e.textContent = "";
  const r = await fetch("/api/camera", { method: "POST", headers: { "Content-Type": "application/json" },
                                         body: JSON.stringify(changes) });
  const data = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
  if (r.ok) { showError(""); showStatus(data.rig); return; }
  const field = Object.keys(changes).find((k) => (data.error || "").includes(`camera.${k}`) ||
                                                  (data.error || "").includes(`camera: ${k}`));
  if (field) document.querySelector(`.field-error[data-for=${field}]`).textContent = data.error;
  else showError(data.error);
};

for (const b of document.querySelectorAll("[data-jog]")) b.onclick = () => post("/api/turntable", { degrees: Number(b.dataset.jog) });
$("home").onclick = () => post("/api/turntable", { home: true });
loadStatus();
setInterval(loadStatus, 2000);
startLive();

// -- pages: the hash names the section shown
function showPage() {
  const name = (location.hash || "#live").slice(1);
  for (const sec of document.querySelectorAll("main > section")) sec.hidden = sec.id !== name;
  for (const a of document.querySelectorAll("header nav a")) a.classList.toggle("on", a.getAttribute("href") === `#${name}`);
}
window.addEventListener("hashchange", showPage);
showPage();

// -- Check: one check at a time, the same for every page open
let checkShown = null;
function fmtPct(x) { return `${(100 * x).toFixed(2)} %`; }
async function pollCheck() {
  const r = await fetch("/api/check");
  const c = await r.json();
  $("check-state").textContent = c.state === "idle" ? "" : c.state;
  $("check-run").disabled = c.state === "running";
  $("check-progress").innerHTML = "";
  for (const line of c.progress || []) { const li = document.createElement("li"); li.textContent = line; $("check-progress").appendChild(li); }
  $("check-error").textContent = c.state === "failed" ? c.error : "";
  if (c.state === "done" && checkShown !== JSON.stringify(c.result)) {
    checkShown = JSON.stringify(c.result);
    const res = c.result, rows = [["saturated", fmtPct(res.saturated_fraction)], ["too dark", fmtPct(res.dark_fraction)],
      ["exposure", `${res.exposure_us.toFixed(0)} us`], ["suggested", `${res.suggested_exposure_us.toFixed(0)} us`],
      ["pattern delay", `${(1000 * res.pattern_delay_s).toFixed(1)} ms`], ["test view", `${res.test_view.points} points` +
      (res.test_view.rms_m === null ? "" : `, RMS ${(1000 * res.test_view.rms_m).toFixed(3)} mm`)]];
    $("check-figures").innerHTML = "";
    for (const [k, v] of rows) { const tr = $("check-figures").insertRow(); tr.insertCell().outerHTML = `<th>${k}</th>`; tr.insertCell().textContent = v; }
    $("check-advice").innerHTML = "";
    for (const line of c.advice) { const li = document.createElement("li"); li.textContent = line; $("check-advice").appendChild(li); }
    $("check-suggested").innerHTML = "";
    for (const [k, v] of Object.entries(c.suggested)) { const tr = $("check-suggested").insertRow(); tr.insertCell().outerHTML = `<th>${k}</th>`; tr.insertCell().textContent = v; }
    $("check-figure").src = `/api/check/figure.png?t=${Date.now()}`; $("check-figure").hidden = false;
    $("check-apply").disabled = false;
  }
}
$("check-run").onclick = async () => {
  const r = await fetch("/api/check/run", { method: "POST" });
  if (!r.ok) $("check-error").textContent = (await r.json()).error;
  pollCheck();
};
$("check-apply").onclick = async () => {
  const r = await fetch("/api/check/apply", { method: "POST" });
  const data = await r.json();
  if (!r.ok) { $("check-error").textContent = data.error; return; }
  $("check-error").textContent = "applied: " + data.last_reply;
  controlsShown = false; showStatus(data);
};
setInterval(pollCheck, 700);
pollCheck();

// -- Scan: a rangekit scan child of the server; its views' points fetched as they are decoded
let scanName = null;
const loading = new Set();
async function pollScan() {
  const r = await fetch("/api/scan");
  const s = await r.json();
  $("scan-stop").disabled = !s.running;
  $("scan-start").disabled = $("scan-resume").disabled = s.running;
  if (!s.name) { $("scan-state").textContent = "no scan yet"; return; }
  const done = s.views.filter((v) => v.done).length, decoded = s.views.filter((v) => v.decoded).length;
  $("scan-state").textContent = `${s.name}: ${s.running ? "running" : (s.exit_code === null ? "" : `ended (exit ${s.exit_code})`)}, ` +
    `${done} of ${s.views.length} views taken, ${decoded} decoded`;
  $("scan-views").innerHTML = "";
  for (const v of s.views) {
    const tr = $("scan-views").insertRow(); tr.insertCell().outerHTML = `<th>${v.name}</th>`;
    tr.insertCell().textContent = v.decoded ? "decoded" : (v.done ? "taken" : "to take");
  }
  $("scan-files").textContent = s.files.length ? "files: " + s.files.join(", ") : "";
  $("scan-log").innerHTML = "";
  for (const line of s.log.slice(-8)) { const li = document.createElement("li"); li.textContent = line; $("scan-log").appendChild(li); }
  if (scanName !== s.name) { scanName = s.name; loading.clear(); if (window.rangekitScan3d) window.rangekitScan3d.clear(); }
  if (!window.rangekitScan3d) return;
  for (const v of s.views) {
    if (!v.decoded || loading.has(v.index) || window.rangekitScan3d.has(v.index)) continue;
    loading.add(v.index);
    const p = await fetch(`/api/sessions/${encodeURIComponent(s.name)}/views/${v.index}/points`);
    if (p.ok) window.rangekitScan3d.addView(v.index, new Float32Array(await p.arrayBuffer()));
    loading.delete(v.index);
  }
}
async function scanPost(path, body) {
  for (const e of document.querySelectorAll("#scan-form .field-error")) e.textContent = "";
  const r = await fetch(path, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
  const data = await r.json();
  if (!r.ok) {
    const field = ["views", "name"].find((k) => data.error.startsWith(`${k}:`) || data.error.startsWith("session") && k === "name");
    if (field) document.querySelector(`#scan-form .field-error[data-for=${field}]`).textContent = data.error;
    else $("scan-error").textContent = data.error;
  } else $("scan-error").textContent = "";
  pollScan();
}
$("scan-form").onsubmit = (ev) => {
  ev.preventDefault();
  const f = $("scan-form"), views = f.views.value.trim();
  scanPost("/api/scan/start", { name: f.name.value.trim(), views: /^[0-9]+$/.test(views) ? Number(views) : views });
};
$("scan-stop").onclick = () => scanPost("/api/scan/stop", {});
$("scan-resume").onclick = () => scanPost("/api/scan/start", { name: $("scan-form").name.value.trim(), resume: true });
setInterval(pollScan, 700);
pollScan();

// -- Sessions: every session under --sessions, its figures and files (the report opens in a new tab)
async function pollSessions() {
  if (location.hash !== "#sessions") return;
  const r = await fetch("/api/sessions");
  const body = $("sessions-table").tBodies[0];
  body.innerHTML = "";
  for (const s of (await r.json()).sessions) {
    const tr = body.insertRow();
    const cells = [s.name, s.state + (s.error ? `: ${s.error}` : ""), s.views === undefined ? "" : `${s.views_done} / ${s.views}`,
      s.points ?? "", s.vertices ?? "", s.rms_mm === null || s.rms_mm === undefined ? "" : `${s.rms_mm} mm`];
    for (const c of cells) tr.insertCell().textContent = c;
    const files = tr.insertCell();
    for (const f of s.files) {
      const a = document.createElement("a"); a.textContent = f; a.target = "_blank";
      a.href = `/api/sessions/${encodeURIComponent(s.name)}/files/${f}`; files.appendChild(a); files.append(" ");
    }
  }
}
window.addEventListener("hashchange", pollSessions);
setInterval(pollSessions, 2000);
pollSessions();
