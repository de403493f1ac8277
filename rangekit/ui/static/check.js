// rangekit ui: the Check page (rangekit check on the app's rig, its suggestions applied with one click).
"use strict";

// -- Check: one check at a time, the same for every page open
let checkShown = null;
function fmtPct(x) { return `${(100 * x).toFixed(2)} %`; }
async function pollCheck() {
  const r = await api("/api/check");
  if (!r.ok) return;
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
    showImage($("check-figure"), "/api/check/figure.png");
    $("check-apply").disabled = false;
  }
}
$("check-run").onclick = async () => {
  const r = await api("/api/check/run", {});
  if (!r.ok) $("check-error").textContent = (await r.json()).error;
  pollCheck();
};
$("check-apply").onclick = async () => {
  const r = await api("/api/check/apply", {});
  const data = await r.json();
  if (!r.ok) { $("check-error").textContent = data.error; return; }
  $("check-error").textContent = "applied: " + data.rig.last_reply;
  controlsShown = false; showStatus(data.rig);
};
setInterval(pollCheck, 700);
pollCheck();

