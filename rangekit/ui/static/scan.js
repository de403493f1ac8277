// rangekit ui: the Scan page. A rangekit scan (or process) child of the server, followed only through its events
// (events.js): each view's row as it is taken and decoded, its points drawn as it is decoded, the files as they
// are written, the end with its exit code. No timer: the page changes when an event comes.
"use strict";

const scanView = {
  name: null, start: 0, total: 0, views: new Map(), files: [], exitCode: null, paused: false, error: null,
  lines: [], launched: false, launch: null,
};
window.rangekitScanView = scanView;
const viewerReady = new Promise((ready) => {
  if (window.rangekitScan3d) ready(); else window.addEventListener("rangekit3d", ready, { once: true });
});
const loading = new Set();
let scanMeshShown = null, renderPending = false;

function scanViewRow(k, name) {
  if (!scanView.views.has(k)) scanView.views.set(k, { index: k, name: `view_${String(k).padStart(3, "0")}`, done: false, decoded: false });
  const v = scanView.views.get(k);
  if (name) v.name = name;
  scanView.total = Math.max(scanView.total, k + 1);
  return v;
}
const baseName = (path) => String(path).split("/").pop();
function addFile(name) { if (!scanView.files.includes(name)) scanView.files.push(name); }
function addLines(lines) { scanView.lines = scanView.lines.concat(lines).slice(-30); }

// One event folded into the view (the server's ScanView does the same: rangekit/ui/jobs/scan_view.py).
function foldScanEvent(e, current) {
  switch (e.type) {
    case "ScanStarted": {
      scanView.total = e.total;
      for (let k = 0; k < e.total; k++) scanViewRow(k);
      const taken = [...scanView.views.values()].filter((v) => v.done).length;
      if (taken !== e.done) for (const v of scanView.views.values()) v.done = v.index < e.done;
      break;
    }
    case "ViewAcquired": scanViewRow(e.index, baseName(e.folder)).done = true; break;
    case "ViewDecoded": case "ViewPlaced": {
      const v = scanViewRow(e.index, e.name); v.done = v.decoded = true; drawView(e.index); break;
    }
    case "MeshReady": addFile(baseName(e.path)); break;
    case "StageFinished": if (e.stage === "report") addFile("report.html"); break;
    case "Progress": addLines([e.message]); break;
    case "JobFailed": if (current) { scanView.error = e.error; addLines([`failed: ${e.error}`]); } break;
    case "JobPaused": if (current) scanView.paused = e.paused; break;
    case "JobExited":
      if (!current) break;
      scanView.exitCode = e.exit_code; scanView.paused = false;
      if (e.exit_code === 0 && scanView.files.includes("mesh.ply")) addFile("summary.json");
      addLines(e.last_lines);
      break;
  }
}

// A decoded view's points, fetched once (its cloud cache, placed by the turntable) and drawn.
async function drawView(k) {
  const name = scanView.name;
  await viewerReady;
  if (loading.has(k) || window.rangekitScan3d.has(k)) return;
  loading.add(k);
  const r = await api(`/api/sessions/${encodeURIComponent(name)}/views/${k}/points`);
  if (r.ok && name === scanView.name) window.rangekitScan3d.addView(k, new Float32Array(await r.arrayBuffer()));
  loading.delete(k);
}

function renderScan() {
  renderPending = false;
  const s = scanView, running = s.launched && s.exitCode === null;
  $("scan-stop").disabled = $("scan-pause").disabled = !running;
  $("scan-pause").textContent = s.paused && running ? "continue" : "pause";
  $("scan-start").disabled = $("scan-resume").disabled = running;
  if (!s.name) { $("scan-state").textContent = "no scan yet"; return; }
  const views = [...s.views.values()].sort((a, b) => a.index - b.index);
  const done = views.filter((v) => v.done).length, decoded = views.filter((v) => v.decoded).length;
  const state = s.paused && running ? "paused" : running ? "running" : s.exitCode === null ? "" : `ended (exit ${s.exitCode})`;
  $("scan-state").textContent = `${s.name}: ${state}, ${done} of ${s.total} views taken, ${decoded} decoded`;
  $("scan-views").innerHTML = "";
  for (const v of views) {
    const tr = $("scan-views").insertRow(); tr.insertCell().outerHTML = `<th>${v.name}</th>`;
    tr.insertCell().textContent = v.decoded ? "decoded" : (v.done ? "taken" : "to take");
  }
  $("scan-files").textContent = s.files.length ? "files: " + s.files.join(", ") : "";
  showLines($("scan-log"), s.lines.slice(-8));
  // Done: the mesh replaces the points, and the report is a click away (the Sessions page opens it).
  const finished = !running && s.exitCode === 0 && s.files.includes("mesh.ply");
  $("scan-done").hidden = !finished;
  if (finished && scanMeshShown !== s.name) {
    scanMeshShown = s.name;
    viewerReady.then(() => window.rangekitScan3d.showMesh(`/api/sessions/${encodeURIComponent(s.name)}/files/mesh.ply`));
  }
}
function scanChanged() { if (!renderPending) { renderPending = true; setTimeout(renderScan, 30); } }

rangekitEvents.listen((m) => {
  if (m.kind === "job") {
    if (m.fresh) {     // another session: start over
      Object.assign(scanView, { name: m.session, total: 0, views: new Map(), files: [], error: null, lines: [] });
      scanMeshShown = null; loading.clear();
      viewerReady.then(() => window.rangekitScan3d.clear());
    }
    if (m.fresh || m.launch !== scanView.launch) {     // another launch (not this socket reconnecting)
      Object.assign(scanView, { launch: m.launch, start: m.start, launched: m.session !== null, exitCode: null,
                                paused: false });
    }
  } else foldScanEvent(m.event, m.current);
  scanChanged();
});

async function scanPost(path, body) {
  const data = await send(path, body, { form: $("scan-form"), error: $("scan-error") });
  if (data && data.name === scanView.name) { scanView.paused = data.paused; scanChanged(); }
}
$("scan-form").onsubmit = (ev) => {
  ev.preventDefault();
  const f = $("scan-form");
  scanPost("/api/scan/start", { name: f.name.value.trim(), views: typed(f.views.value) });
};
$("scan-stop").onclick = () => scanPost("/api/scan/stop", {});
$("scan-pause").onclick = () => scanPost("/api/scan/pause", { paused: $("scan-pause").textContent === "pause" });
$("scan-report").onclick = () => { if (scanView.name) openSession(scanView.name); };
$("scan-resume").onclick = () => scanPost("/api/scan/start", { name: $("scan-form").name.value.trim(), resume: true });
// The form's ranges and defaults: the server's, read from the options' dataclasses (as rangekit scan's flags are).
getJson("/api/options").then((options) => {
  if (!options) return;
  const views = options.scan.views, input = $("scan-form").views;
  input.min = views.min; input.max = views.max; input.title = `${views.min} to ${views.max} views`;
  if (!input.value) input.value = views.default;
});
renderScan();
