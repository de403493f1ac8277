"""The Check page's job: ``rangekit check`` on the app's rig, its figures and picture, and the rig-file changes it
suggests (the exposure that puts the object's 99th percentile at 90% of full scale, the measured pattern delay),
applied with one click.

One check runs at a time; its state (running, done with the result, or failed with the one-line error) is kept
here, so every page open sees the same one.
"""

from __future__ import annotations

import threading

import cv2

from rangekit.errors import RangekitError
from rangekit.ui.job_state import failed
from rangekit.ui.rig_holder import RigHolder

__all__ = ["CheckJob"]


class CheckJob:
    """The latest check of ``holder``'s rig."""

    def __init__(self, holder: RigHolder) -> None:
        self.holder = holder
        self._lock = threading.Lock()
        self.state: dict = {"state": "idle"}
        self.figure_png: bytes | None = None
        self.progress: list[str] = []

    def start(self) -> dict:
        """Start a check on a thread (refused while one runs or the rig is busy); the state."""
        with self._lock:
            if self.state["state"] == "running":
                raise RangekitError("a check is running already")
            if self.holder.busy is not None:
                raise RangekitError(f"the rig is busy: {self.holder.busy}; wait for it to finish")
            self.state, self.progress = {"state": "running"}, []
        threading.Thread(target=self._run, name="rangekit-check", daemon=True).start()
        return self.snapshot()

    def snapshot(self) -> dict:
        return {**self.state, "progress": list(self.progress[-20:])}

    def _run(self) -> None:
        from rangekit.app.check.run import check_simulated
        from rangekit.app.check.stats import check_figure
        from rangekit.app.check.steps import MIN_CONFIDENCE, run_check
        from rangekit.rig.camera_controls import controls_from_capture

        try:
            with self.holder.hold("check") as devices:
                if self.holder.simulated_rig:
                    result, images = check_simulated(devices, rig=self.holder.rig, progress=self.progress.append)
                else:      # the opened hardware, as rangekit check --rig does with its own
                    if devices.camera is None:
                        raise RangekitError(f"not connected: {self.holder.fault}")
                    controls = controls_from_capture(self.holder.rig.capture, where=str(self.holder.rig_file))
                    result, images = run_check(devices, self.holder.rig, controls, full_scale=self.holder.full_scale,
                                               progress=self.progress.append)
            figure = check_figure(images["white"], images["black"], self.holder.full_scale, images["mask"],
                                  MIN_CONFIDENCE, result.stats)
            ok, png = cv2.imencode(".png", cv2.cvtColor(figure, cv2.COLOR_RGB2BGR))
            self.figure_png = png.tobytes() if ok else None
            suggested = {"capture.camera.exposure_us": round(result.suggested_exposure_us),
                         "capture.pattern_delay_s": round(result.pattern_delay_s, 4)}
            state = {"state": "done", "result": result.to_dict(), "advice": result.advice(),
                     "suggested": suggested}
        except Exception as exc:  # noqa: BLE001 - the page gets one line, the log the details
            state = failed(exc, "check")
        with self._lock:
            self.state = state

    def apply(self) -> dict:
        """Write the last check's suggested changes into the rig file and onto the devices; the rig's status."""
        with self._lock:
            if self.state.get("state") != "done":
                raise RangekitError("no finished check to apply: run the check first")
            suggested = dict(self.state["suggested"])
        self.holder.apply_capture({"pattern_delay_s": suggested["capture.pattern_delay_s"]},
                                  {"exposure_us": suggested["capture.camera.exposure_us"]})
        return self.holder.status()
