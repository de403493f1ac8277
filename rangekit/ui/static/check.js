// rangekit ui: the Check page (rangekit check on the app's rig, its suggestions applied with one click). One check
// at a time, the same for every page open: shown as the server sends its state (events.js, /ws/jobs), no timer.
"use strict";

let checkShown = null;
function fmtPct(x) { return `${(100 * x).toFixed(2)} %`; }
function showCheck(c) {
  $("check-state").textContent = c.state === "idle" ? "" : c.state;
  $("check-run").disabled = c.state === "running";
  $("check-progress").innerHTML = "";
  showLines($("check-progress"), c.progress || []);
  if (c.state === "failed") $("check-error").textContent = c.error;
  else if (c.state === "running") $("check-error").textContent = "";
  if (c.state !== "done") { $("check-apply").disabled = true; checkShown = null; return; }
  if (checkShown === JSON.stringify(c.result)) return;
  checkShown = JSON.stringify(c.result);
  const res = c.result, rows = [["saturated", fmtPct(res.saturated_fraction)], ["too dark", fmtPct(res.dark_fraction)],
    ["exposure", `${res.exposure_us.toFixed(0)} us`], ["suggested", `${res.suggested_exposure_us.toFixed(0)} us`],
    ["pattern delay", `${(1000 * res.pattern_delay_s).toFixed(1)} ms`], ["test view", `${res.test_view.points} points` +
    (res.test_view.rms_m === null ? "" : `, RMS ${(1000 * res.test_view.rms_m).toFixed(3)} mm`)]];
  $("check-figures").innerHTML = "";
  for (const [k, v] of rows) { const tr = $("check-figures").insertRow(); tr.insertCell().outerHTML = `<th>${k}</th>`; tr.insertCell().textContent = v; }
  $("check-advice").innerHTML = "";
  showLines($("check-advice"), c.advice);
  $("check-suggested").innerHTML = "";
  for (const [k, v] of Object.entries(c.suggested)) { const tr = $("check-suggested").insertRow(); tr.insertCell().outerHTML = `<th>${k}</th>`; tr.insertCell().textContent = v; }
  showImage($("check-figure"), "/api/check/figure.png");
  $("check-apply").disabled = false;
}
$("check-run").onclick = () => send("/api/check/run", {}, { error: $("check-error") });   // its state: /ws/jobs
$("check-apply").onclick = async () => {
  const data = await send("/api/check/apply", {}, { error: $("check-error") });
  if (!data) return;
  $("check-error").textContent = "applied: " + data.rig.last_reply;
  controlsShown = false; showStatus(data.rig);
};
rangekitEvents.onJob("check", showCheck);
