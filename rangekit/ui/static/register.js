// rangekit ui: the Registration page (clouds picked under --sessions registered as rangekit register does; each
// pair's residual, the clouds placed in 3D, then saved under a name). The registration is shown as the server sends
// its state (events.js, /ws/jobs), no timer; the cloud list is read when the page is shown.
"use strict";

let registerShown = null;

async function loadClouds() {
  const box = $("register-clouds");
  if (location.hash !== "#register" || box.dataset.loaded) return;
  box.dataset.loaded = "1";
  const r = await api("/api/register/clouds");
  if (!r.ok) { box.dataset.loaded = ""; return; }
  const clouds = (await r.json()).clouds;
  box.innerHTML = "";
  for (const c of clouds) {
    const label = document.createElement("label"), input = document.createElement("input");
    input.type = "checkbox"; input.value = c; label.append(input, " " + c); box.appendChild(label);
  }
  if (!clouds.length) box.textContent = "no cloud files under the sessions folder yet";
}

async function showRegister(s) {
  $("register-state").textContent = s.state === "idle" ? "" : s.state + (s.rmse_mm !== undefined ? `: RMS ${s.rmse_mm} mm over all pairs` : "") +
    (s.saved ? `; saved as ${s.saved}` : "");
  $("register-error").textContent = s.state === "failed" ? s.error : "";
  $("register-start").disabled = s.state === "running";
  $("register-save-button").disabled = s.state !== "done" || !!s.saved;
  showLines($("register-lines"), s.lines.slice(-8));
  const key = JSON.stringify([s.state, s.files, s.rmse_mm]);
  if (key === registerShown) return;
  registerShown = key;
  $("register-pairs").innerHTML = ""; window.rangekitRegister3d?.clear();
  if (s.state !== "done") return;
  const head = $("register-pairs").insertRow();
  for (const h of ["pair", "residual RMS", "overlap", ""]) head.insertCell().outerHTML = `<th>${h}</th>`;
  for (const p of s.pairs) {
    const tr = $("register-pairs").insertRow(); tr.className = p.accepted ? "" : "bad";
    for (const v of [`${p.a} - ${p.b}`, `${p.rmse_mm} mm`, `${p.overlap_percent} %`, p.accepted ? "kept" : `refused: ${p.reason}`]) tr.insertCell().textContent = v;
  }
  await registerViewer;
  for (let k = 0; k < s.files.length; k++) {
    const r = await api(`/api/register/points/${k}`);
    if (r.ok && registerShown === key) window.rangekitRegister3d.addView(k, new Float32Array(await r.arrayBuffer()));
  }
}
const registerViewer = new Promise((ready) => {
  if (window.rangekitRegister3d) ready(); else window.addEventListener("rangekit3d", ready, { once: true });
});

$("register-form").onsubmit = async (ev) => {
  ev.preventDefault();
  const files = [...document.querySelectorAll("#register-clouds input:checked")].map((i) => i.value);
  const text = $("register-form").neighbours.value.trim();
  for (const e of document.querySelectorAll("#register-save .field-error")) e.textContent = "";
  await send("/api/register/start", { files, neighbours: text === "" ? null : typed(text) },
             { form: $("register-form"), error: $("register-error") });
};
$("register-save").onsubmit = async (ev) => {
  ev.preventDefault();
  const data = await send("/api/register/save", { name: $("register-save").name.value.trim() },
                          { form: $("register-save"), error: $("register-error") });
  if (data) { $("register-clouds").dataset.loaded = ""; loadClouds(); }
};
window.addEventListener("hashchange", loadClouds);
// A scan or a processing that ended may have written clouds: the list is read again when the page is next shown.
rangekitEvents.listen((m) => {
  if (m.kind === "event" && m.current && m.event.type === "JobExited") { $("register-clouds").dataset.loaded = ""; loadClouds(); }
});
loadClouds();
rangekitEvents.onJob("register", showRegister);
