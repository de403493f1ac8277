// rangekit ui: what every page shares (requests, the page switch, the device status) and the Live page.
// The token: read once from the URL rangekit ui printed (?token=), kept in this tab's sessionStorage (this origin
// only), and the address replaced so it leaves the address bar and the history. Every request carries it in the
// X-Rangekit-Token header (no cookie: every port of 127.0.0.1 would see one); what cannot carry a header (the
// WebSocket, a report's iframe) opens with a single-use ticket, images are fetched and shown as blob URLs.
"use strict";

const $ = (id) => document.getElementById(id);

const TOKEN = (() => {
  const given = new URLSearchParams(location.search).get("token");
  if (given) {
    sessionStorage.setItem("rangekit-token", given);
    history.replaceState(null, "", location.pathname + location.hash);
  }
  return sessionStorage.getItem("rangekit-token") || "";
})();

// The banner over every page: the server gone, or back with another token (it restarted: its new URL holds it).
let serverState = TOKEN ? "ok" : "no-token";
function showServerState(state) {
  if (serverState === "stale" || serverState === "no-token") return;    // final: only the new URL helps
  serverState = state;
  const words = { gone: "The server does not answer: reconnecting.",
                  stale: "The server restarted: this page's token is no longer valid. Open the new URL rangekit ui printed.",
                  "no-token": "This page has no token: open the URL rangekit ui printed (it holds the token)." };
  $("banner").textContent = words[state] || ""; $("banner").hidden = state === "ok";
}
if (!TOKEN) { serverState = "ok"; showServerState("no-token"); }

// Every request of the page: the token in its header; a body (POST) as JSON. The Response, or a refusal's.
async function api(path, body) {
  const init = { headers: { "X-Rangekit-Token": TOKEN }, cache: "no-store" };
  if (body !== undefined) {
    init.method = "POST"; init.headers["Content-Type"] = "application/json"; init.body = JSON.stringify(body);
  }
  let r;
  try { r = await fetch(path, init); } catch (e) {
    showServerState("gone");
    return new Response(JSON.stringify({ error: "the server does not answer" }), { status: 503 });
  }
  if (r.status === 403 && (await r.clone().text()).includes("token missing or wrong")) showServerState("stale");
  else if (serverState === "gone") showServerState("ok");
  return r;
}

// A single-use ticket for what the page opens without a header (the WebSocket, a report), or null.
async function ticket(path) {
  const r = await api("/api/ticket", { path });
  return r.ok ? (await r.json()).ticket : null;
}

// An image of the API shown in img (fetched with the header, shown as a blob URL).
async function showImage(img, path) {
  const r = await api(path);
  if (!r.ok) return false;
  const old = img.src;
  img.src = URL.createObjectURL(await r.blob());
  if (old.startsWith("blob:")) URL.revokeObjectURL(old);
  img.hidden = false;
  return true;
}

function showError(text) { $("error").textContent = text || ""; }

async function post(path, body) {
  const r = await api(path, body);
  const data = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
  if (!r.ok) { showError(data.error || `HTTP ${r.status}`); return null; }
  showError("");
  if (data.rig) showStatus(data.rig);
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

async function loadStatus() {
  const r = await api("/api/status");
  if (!r.ok) return;
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
    if (serverState !== "stale" && serverState !== "no-token") { liveWaiting("reconnecting"); setTimeout(startLive, 1000); }
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
  for (const e of document.querySelectorAll(".field-error")) e.textContent = "";
  const r = await api("/api/camera", changes);
  const data = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
  if (r.ok) { showError(""); showStatus(data.rig); return; }
  const field = Object.keys(changes).find((k) => (data.error || "").includes(`camera.${k}`) ||
                                                  (data.error || "").includes(`camera: ${k}`));
  if (field) document.querySelector(`.field-error[data-for=${field}]`).textContent = data.error;
  else showError(data.error);
};

for (const b of document.querySelectorAll("[data-jog]")) b.onclick = () => post("/api/turntable", { degrees: Number(b.dataset.jog) });
$("home").onclick = () => post("/api/turntable", { home: true });
$("reconnect").onclick = () => post("/api/reconnect", {});
loadStatus();
setInterval(loadStatus, 2000);
startLive();

// -- pages: the hash names the section shown (one that names none: the first page)
function showPage() {
  const pages = [...document.querySelectorAll("main > section")].map((sec) => sec.id);
  const asked = location.hash.slice(1), name = pages.includes(asked) ? asked : pages[0];
  for (const sec of document.querySelectorAll("main > section")) sec.hidden = sec.id !== name;
  for (const a of document.querySelectorAll("header nav a")) a.classList.toggle("on", a.getAttribute("href") === `#${name}`);
}
window.addEventListener("hashchange", showPage);
showPage();

