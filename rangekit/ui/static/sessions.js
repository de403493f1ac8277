// rangekit ui: the Sessions page (every session under --sessions: state, figures, files; one opened shows its
// mesh in 3D and its report, and can be processed again or exported).
"use strict";

let sessionOpen = null, sessionMeshShown = null;

async function pollSessions() {
  if (location.hash !== "#sessions") return;
  const list = (await (await fetch("/api/sessions")).json()).sessions;
  const body = $("sessions-table").tBodies[0];
  body.innerHTML = "";
  for (const s of list) {
    const tr = body.insertRow();
    const cells = [s.name, s.state + (s.error ? `: ${s.error}` : ""), s.views === undefined ? "" : `${s.views_done} / ${s.views}`,
      s.points ?? "", s.vertices ?? "", s.rms_mm === null || s.rms_mm === undefined ? "" : `${s.rms_mm} mm`];
    for (const c of cells) tr.insertCell().textContent = c;
    const files = tr.insertCell();
    for (const f of s.files) {
      const a = document.createElement("a"); a.textContent = f; a.target = "_blank";
      a.href = `/api/sessions/${encodeURIComponent(s.name)}/files/${f}`; files.appendChild(a); files.append(" ");
    }
    const open = document.createElement("button"); open.textContent = "open"; open.dataset.session = s.name;
    open.onclick = () => openSession(s.name); tr.insertCell().appendChild(open);
  }
  const current = list.find((s) => s.name === sessionOpen);
  if (current) showSession(current);
}

function openSession(name) { sessionOpen = name; sessionMeshShown = null; $("session-report").removeAttribute("src"); pollSessions(); }

async function showSession(s) {
  $("session-detail").hidden = false;
  $("session-title").textContent = `${s.name}: ${s.state}`;
  const base = `/api/sessions/${encodeURIComponent(s.name)}/files/`;
  if (s.files.includes("report.html") && !$("session-report").getAttribute("src")) $("session-report").src = base + "report.html";
  const key = s.name + (s.vertices ?? "");
  if (s.files.includes("mesh.ply") && sessionMeshShown !== key) {
    sessionMeshShown = key;
    $("session-mesh-note").textContent = "loading the mesh";
    const n = await window.rangekitSession3d.showMesh(base + "mesh.ply");
    $("session-mesh-note").textContent = `mesh.ply: ${n} vertices (drag to turn, wheel to zoom)`;
  } else if (!s.files.includes("mesh.ply")) $("session-mesh-note").textContent = "no mesh yet: process the session";
  const job = await (await fetch("/api/scan")).json();
  $("session-state").textContent = job.name === s.name && job.running ? `processing: ${job.log.slice(-1)[0] || ""}` : "";
}

async function sessionPost(path, body) {
  const r = await fetch(`/api/sessions/${encodeURIComponent(sessionOpen)}/${path}`, { method: "POST",
    headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) });
  const data = await r.json();
  $("session-error").textContent = r.ok ? "" : data.error;
  return r.ok ? data : null;
}
$("session-process").onsubmit = async (ev) => {
  ev.preventDefault();
  const f = $("session-process");
  if (await sessionPost("process", { fusion: f.fusion.value, format: f.format.value, report: f.report.checked })) {
    sessionMeshShown = null; $("session-report").removeAttribute("src");
  }
};
for (const b of document.querySelectorAll("#session-export button")) {
  b.onclick = async () => {
    const data = await sessionPost("export", { format: b.dataset.format });
    if (data) $("session-state").textContent = `written: ${data.files.join(", ")}`;
    pollSessions();
  };
}
window.addEventListener("hashchange", pollSessions);
setInterval(pollSessions, 2000);
pollSessions();
