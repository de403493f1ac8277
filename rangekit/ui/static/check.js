// rangekit ui: the Check page (rangekit check on the app's rig, its suggestions applied with one click).
"use strict";

// One check at a time, the same for every page open; read while its page shows or it runs.
let checkShown = null;
function fmtPct(x) { return `${(100 * x).toFixed(2)} %`; }
let checkRunning = false;
async function pollCheck() {
  if (location.hash !== "#check" && !checkRunning && checkShown !== null) return;   // hidden and idle: nothing new
  const c = await getJson("/api/check");
  if (!c) return;
  checkRunning = c.state === "running";
  $("check-state").textContent = c.state === "idle" ? "" : c.state;
  $("check-run").disabled = c.state === "running";
  $("check-progress").innerHTML = "";
  showLines($("check-progress"), c.progress || []);
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
    showLines($("check-advice"), c.advice);
    $("check-suggested").innerHTML = "";
    for (const [k, v] of Object.entries(c.suggested)) { const tr = $("check-suggested").insertRow(); tr.insertCell().outerHTML = `<th>${k}</th>`; tr.insertCell().textContent = v; }
    showImage($("check-figure"), "/api/check/figure.png");
    $("check-apply").disabled = false;
  }
}
$("check-run").onclick = async () => {
  if (await send("/api/check/run", {}, { error: $("check-error") })) checkRunning = true;
  pollCheck();
};
$("check-apply").onclick = async () => {
  const data = await send("/api/check/apply", {}, { error: $("check-error") });
  if (!data) return;
  $("check-error").textContent = "applied: " + data.rig.last_reply;
  controlsShown = false; showStatus(data.rig);
};
setInterval(pollCheck, 700);
pollCheck();

