"""The Check page's job: ``rangekit check`` on the app's rig, its figures and picture, and the rig-file changes it
suggests (the exposure that puts the object's 99th percentile at 90% of full scale, the measured pattern delay),
applied with one click.

One check runs at a time; its state (running, done with the result, or failed with the one-line error) is kept
here, so every page open sees the same one.
"""

from __future__ import annotations

import cv2

from rangekit.errors import RangekitError
from rangekit.ui.jobs.base import Job
from rangekit.ui.jobs.notifier import Topic
from rangekit.ui.rig_holder import RigHolder

__all__ = ["CheckJob"]


class CheckJob(Job):
    """The latest check of ``holder``'s rig."""

    WHAT, LINES, SHOWN_LINES, TOPIC = "check", "progress", 20, Topic.CHECK

    def __init__(self, holder: RigHolder, notifier=None) -> None:
        super().__init__(notifier)
        self.holder = holder
        self.figure_png: bytes | None = None

    def start(self) -> dict:
        """Start a check on a thread (refused while one runs or the rig is busy); the state."""
        if self.holder.busy is not None and not self.running:
            raise RangekitError(f"the rig is busy: {self.holder.busy}; wait for it to finish")
        self.begin()
        self.launch(self._run)
        return self.snapshot()

    def _run(self) -> dict:
        from rangekit.app.check.run import check_simulated
        from rangekit.app.check.stats import check_figure
        from rangekit.app.check.steps import MIN_CONFIDENCE, run_check
        from rangekit.rig.camera_controls import controls_from_capture

        with self.holder.hold("check") as devices:
            if self.holder.simulated_rig:
                result, images = check_simulated(devices, rig=self.holder.rig, progress=self.say)
            else:      # the opened hardware, as rangekit check --rig does with its own
                if devices.camera is None:
                    raise RangekitError(f"not connected: {self.holder.fault}")
                controls = controls_from_capture(self.holder.rig.capture, where=str(self.holder.rig_file))
                result, images = run_check(devices, self.holder.rig, controls, full_scale=self.holder.full_scale,
                                           progress=self.say)
        figure = check_figure(images["white"], images["black"], self.holder.full_scale, images["mask"],
                              MIN_CONFIDENCE, result.stats)
        ok, png = cv2.imencode(".png", cv2.cvtColor(figure, cv2.COLOR_RGB2BGR))
        self.figure_png = png.tobytes() if ok else None
        suggested = {"capture.camera.exposure_us": round(result.suggested_exposure_us),
                     "capture.pattern_delay_s": round(result.pattern_delay_s, 4)}
        return {"result": result.to_dict(), "advice": result.advice(), "suggested": suggested}

    def apply(self) -> dict:
        """Write the last check's suggested changes into the rig file and onto the devices; the rig's status."""
        with self._cond:
            if self.state.value != "done":
                raise RangekitError("no finished check to apply: run the check first")
            suggested = dict(self.fields["suggested"])
        self.holder.apply_capture({"pattern_delay_s": suggested["capture.pattern_delay_s"]},
                                  {"exposure_us": suggested["capture.camera.exposure_us"]})
        return self.holder.status()
