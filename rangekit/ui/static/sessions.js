// rangekit ui: the Sessions page (every session under --sessions: state, figures, files; one opened shows its
// mesh in 3D and its report, and can be processed again or exported). The list is read when the page is shown, when a
// job that writes sessions ends (a scan or a processing: its JobExited on /ws/events; a registration: its state on
// /ws/jobs) and after an export; no timer.
"use strict";

let sessionOpen = null, sessionMeshShown = null;

async function loadSessions() {
  if (location.hash !== "#sessions") return;
  const got = await api("/api/sessions");
  if (!got.ok) return;
  const { sessions: list, skipped } = await got.json();
  $("sessions-skipped").textContent = skipped.join("; ");
  const body = $("sessions-table").tBodies[0];
  body.innerHTML = "";
  for (const s of list) {
    const tr = body.insertRow();
    const cells = [s.name, s.state + (s.error ? `: ${s.error}` : ""), s.views === undefined ? "" : `${s.views_done} / ${s.views}`,
      s.points ?? "", s.vertices ?? "", s.rms_mm === null || s.rms_mm === undefined ? "" : `${s.rms_mm} mm`];
    for (const c of cells) tr.insertCell().textContent = c;
    const files = tr.insertCell();
    for (const f of s.files) {
      const a = document.createElement("a"); a.textContent = f; a.href = "#sessions";
      a.onclick = (ev) => { ev.preventDefault(); download(`/api/sessions/${encodeURIComponent(s.name)}/files/${f}`, f); };
      files.appendChild(a); files.append(" ");
    }
    const open = document.createElement("button"); open.textContent = "open"; open.dataset.session = s.name;
    open.onclick = () => openSession(s.name); tr.insertCell().appendChild(open);
  }
  const current = list.find((s) => s.name === sessionOpen);
  if (current) showSession(current);
}

// A session's file saved (fetched with the header, handed to the browser as a download: never opened here, where
// a report received from someone else would run as the app).
async function download(path, name) {
  const r = await api(path);
  if (!r.ok) { $("session-error").textContent = (await r.json().catch(() => ({}))).error || `HTTP ${r.status}`; return; }
  const a = document.createElement("a"); a.href = URL.createObjectURL(await r.blob()); a.download = name;
  a.click(); setTimeout(() => URL.revokeObjectURL(a.href), 60000);
}

// The report in its sandboxed iframe (sandbox="allow-scripts": its own origin, never the app's), opened once with
// a single-use ticket.
async function showReport(path) {
  const frame = $("session-report");
  frame.dataset.path = path;
  const t = await ticket(path);
  if (t && frame.dataset.path === path) frame.src = `${path}?ticket=${encodeURIComponent(t)}`;
}

function clearReport() { $("session-report").removeAttribute("src"); delete $("session-report").dataset.path; }
function openSession(name) { sessionOpen = name; sessionMeshShown = null; clearReport(); loadSessions(); }

async function showSession(s) {
  $("session-detail").hidden = false;
  $("session-title").textContent = `${s.name}: ${s.state}`;
  const base = `/api/sessions/${encodeURIComponent(s.name)}/files/`;
  if (s.files.includes("report.html") && !$("session-report").dataset.path) showReport(base + "report.html");
  const key = s.name + (s.vertices ?? "");
  if (s.files.includes("mesh.ply") && sessionMeshShown !== key) {
    sessionMeshShown = key;
    $("session-mesh-note").textContent = "loading the mesh";
    const n = await window.rangekitSession3d.showMesh(base + "mesh.ply");
    $("session-mesh-note").textContent = `mesh.ply: ${n} vertices (drag to turn, wheel to zoom)`;
  } else if (!s.files.includes("mesh.ply")) $("session-mesh-note").textContent = "no mesh yet: process the session";
  showSessionBusy();
}

// Whether the open session is being processed, with the job's last line (the scan job as its events tell it, scan.js).
function showSessionBusy() {
  const job = window.rangekitScanView;
  const busy = sessionOpen !== null && job.name === sessionOpen && job.launched && job.exitCode === null;
  $("session-state").textContent = busy ? `processing: ${job.lines.slice(-1)[0] || ""}` : "";
}

function sessionPost(path, body) {
  return send(`/api/sessions/${encodeURIComponent(sessionOpen)}/${path}`, body, { error: $("session-error") });
}
$("session-process").onsubmit = async (ev) => {
  ev.preventDefault();
  const f = $("session-process");
  if (await sessionPost("process", { fusion: f.fusion.value, format: f.format.value, report: f.report.checked })) {
    sessionMeshShown = null; clearReport();
  }
};
for (const b of document.querySelectorAll("#session-export button")) {
  b.onclick = async () => {
    const data = await sessionPost("export", { format: b.dataset.format });
    if (data) $("session-state").textContent = `written: ${data.files.join(", ")}`;
    loadSessions();
  };
}
window.addEventListener("hashchange", loadSessions);
rangekitEvents.listen((m) => {
  if (m.kind === "event" && !m.current) return;
  if (m.kind === "event" && m.event.type === "JobExited") loadSessions();
  else if (location.hash === "#sessions") showSessionBusy();
});
let sessionsRegistered = null;       // the registration's last state and name saved: a change may be a new folder
rangekitEvents.onJob("register", (r) => {
  const key = `${r.state} ${r.saved || ""}`;
  if (sessionsRegistered !== null && key !== sessionsRegistered && r.state !== "running") loadSessions();
  sessionsRegistered = key;
});
loadSessions();
