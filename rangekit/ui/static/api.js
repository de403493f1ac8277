// rangekit ui: the one API client. Every request of the page goes through api(): the token in its header, a body
// (POST) as JSON; send() is a POST whose refusal is shown by the field it names ({"error", "field"}).
// The token: read once from the URL rangekit ui printed (?token=), kept in this tab's sessionStorage (this origin
// only), and the address replaced so it leaves the address bar and the history. No cookie (every port of
// 127.0.0.1 would see one); what cannot carry a header (a WebSocket, a report's iframe) opens with a single-use
// ticket, images are fetched and shown as blob URLs.
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
// Whether the page may go on trying (the server gone comes back; another token never does).
function serverMayAnswer() { return serverState !== "stale" && serverState !== "no-token"; }

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

// A GET's JSON, or null.
async function getJson(path) {
  const r = await api(path);
  return r.ok ? r.json() : null;
}

// A POST of the page: its answer's data, or null after showing the refusal next to its field in `form` (the
// answer's "field"), else in the element `error`. The form's earlier errors are cleared first.
async function send(path, body, { form = null, error = null } = {}) {
  const r = await api(path, body ?? {});
  const data = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
  if (form) for (const e of form.querySelectorAll(".field-error")) e.textContent = "";
  // On success only a refusal this call showed is cleared: the slot may already show the job's own state, pushed
  // by the jobs socket before this response arrived (a job that failed at once).
  if (r.ok) {
    if (error && error.textContent === error.dataset.refusal) error.textContent = "";
    if (error) delete error.dataset.refusal;
    return data;
  }
  const slot = form && data.field ? form.querySelector(`.field-error[data-for="${data.field}"]`) : null;
  if (slot) slot.textContent = data.error;
  else if (error) error.textContent = error.dataset.refusal = data.error || `HTTP ${r.status}`;
  return null;
}

// A single-use ticket for what the page opens without a header (a WebSocket, a report), or null.
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

// A list element's items: the lines given.
function showLines(list, lines) {
  list.innerHTML = "";
  for (const line of lines) { const li = document.createElement("li"); li.textContent = line; list.appendChild(li); }
}

// A number typed into a field as a number, anything else as typed (the server names what it expected).
function typed(text, pattern = /^[0-9]+$/) { const t = text.trim(); return pattern.test(t) ? Number(t) : t; }
