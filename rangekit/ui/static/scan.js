// rangekit ui: the Scan page (a rangekit scan child of the server, its views' points as they are decoded).
"use strict";

// -- Scan: a rangekit scan child of the server; its views' points fetched as they are decoded
let scanName = null, scanMesh = null;
const loading = new Set();
async function pollScan() {
  const r = await api("/api/scan");
  if (!r.ok) return;
  const s = await r.json();
  $("scan-stop").disabled = $("scan-pause").disabled = !s.running;
  $("scan-pause").textContent = s.paused ? "continue" : "pause";
  $("scan-start").disabled = $("scan-resume").disabled = s.running;
  if (!s.name) { $("scan-state").textContent = "no scan yet"; return; }
  const done = s.views.filter((v) => v.done).length, decoded = s.views.filter((v) => v.decoded).length;
  $("scan-state").textContent = `${s.name}: ${s.paused ? "paused" : s.running ? "running" : (s.exit_code === null ? "" : `ended (exit ${s.exit_code})`)}, ` +
    `${done} of ${s.views.length} views taken, ${decoded} decoded`;
  $("scan-views").innerHTML = "";
  for (const v of s.views) {
    const tr = $("scan-views").insertRow(); tr.insertCell().outerHTML = `<th>${v.name}</th>`;
    tr.insertCell().textContent = v.decoded ? "decoded" : (v.done ? "taken" : "to take");
  }
  $("scan-files").textContent = s.files.length ? "files: " + s.files.join(", ") : "";
  $("scan-log").innerHTML = "";
  for (const line of s.log.slice(-8)) { const li = document.createElement("li"); li.textContent = line; $("scan-log").appendChild(li); }
  if (scanName !== s.name) { scanName = s.name; scanMesh = null; loading.clear(); if (window.rangekitScan3d) window.rangekitScan3d.clear(); }
  if (!window.rangekitScan3d) return;
  // Done: the mesh replaces the points, and the report is a click away (the Sessions page opens it).
  const finished = !s.running && s.exit_code === 0 && s.files.includes("mesh.ply");
  $("scan-done").hidden = !finished;
  if (finished && scanMesh !== s.name) { scanMesh = s.name; window.rangekitScan3d.showMesh(`/api/sessions/${encodeURIComponent(s.name)}/files/mesh.ply`); }
  for (const v of s.views) {
    if (!v.decoded || loading.has(v.index) || window.rangekitScan3d.has(v.index)) continue;
    loading.add(v.index);
    const p = await api(`/api/sessions/${encodeURIComponent(s.name)}/views/${v.index}/points`);
    if (p.ok) window.rangekitScan3d.addView(v.index, new Float32Array(await p.arrayBuffer()));
    loading.delete(v.index);
  }
}
async function scanPost(path, body) {
  for (const e of document.querySelectorAll("#scan-form .field-error")) e.textContent = "";
  const r = await api(path, body);
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
$("scan-pause").onclick = () => scanPost("/api/scan/pause", { paused: $("scan-pause").textContent === "pause" });
$("scan-report").onclick = () => { if (scanName) openSession(scanName); };
$("scan-resume").onclick = () => scanPost("/api/scan/start", { name: $("scan-form").name.value.trim(), resume: true });
// The form's ranges and defaults: the server's, read from the options' dataclasses (as rangekit scan's flags are).
async function loadOptions() {
  const r = await api("/api/options");
  if (!r.ok) return;
  const views = (await r.json()).scan.views, input = $("scan-form").views;
  input.min = views.min; input.max = views.max; input.title = `${views.min} to ${views.max} views`;
  if (!input.value) input.value = views.default;
}
loadOptions();
setInterval(pollScan, 700);
pollScan();

