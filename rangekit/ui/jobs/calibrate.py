"""The Calibrate page's wizard: ``rangekit calibrate`` on the app's rig, one board pose at a time.

The calibration itself is :func:`rangekit.calib.procedure.calibrate_rig`, run on a thread holding the rig; the
wizard is its two callbacks. Before each pose (``place_board``) the job waits in ``placing``: the live stream runs,
with the board's corners found in each frame (:func:`rangekit.ui.board_live.live_corners`) drawn on the page,
until the person presses *capture*. After each capture (``on_pose``) it waits in ``review``, with the pose's
verdict and reprojection error, the coverage of the image and of the tilts so far and a hint of where to put the
board next (:mod:`rangekit.calib.pose_advice`), until the person keeps it or retakes it. On the simulator the app
moves the board: each pose starts at the next of a pool of hand-held poses
(:func:`rangekit.sim.writers.calibration.board_poses`), *next pose* draws another, and a drag shifts it across
the view. The result is written to the app's rig file (atomically) and shown per parameter, with each one's
deviation from the simulator's truth.
"""

from __future__ import annotations

import threading
from enum import Enum

import cv2
import numpy as np

from rangekit._runtime.memory import forget_caches
from rangekit.boards import Board
from rangekit.errors import RangekitError
from rangekit.ui.board_live import live_corners
from rangekit.ui.jobs.base import Job, JobState, failed
from rangekit.ui.jobs.notifier import Topic
from rangekit.ui.rig_holder import RigHolder, test_pattern

__all__ = ["CalibrateJob", "Step"]


class Step(str, Enum):
    """Where a running calibration is (its value is the page's ``"state"`` while it runs)."""

    STARTING = "starting"
    PLACING = "placing"          # waiting for *capture*, the live stream on
    CAPTURING = "capturing"
    REVIEW = "review"            # waiting for *keep* or *retake*
    MOVING = "moving"            # a retake: the board moved back
    TURNTABLE = "turntable"      # the board on the turntable


class _Cancelled(Exception):
    pass


def _png(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))
    return buf.tobytes() if ok else b""


class CalibrateJob(Job):
    """The calibration of ``holder``'s rig (at most one at a time); ``stream`` (a
    :class:`rangekit.ui.stream.LiveStream`) gets the board-corner annotation while a pose is placed."""

    WHAT, LINES, TOPIC = "calibration", "progress", Topic.CALIBRATE

    def __init__(self, holder: RigHolder, stream=None, notifier=None) -> None:
        self.holder, self.stream = holder, stream
        super().__init__(notifier)
        self.step = Step.STARTING
        self.poses: list[dict] = []
        self.pictures: dict[str, bytes] = {}
        self._go = False
        self._decision: bool | None = None
        self._cancel = False
        self._uv: dict[int, np.ndarray] = {}      # pose index -> its corners (camera px), for the hint
        self._pool: list[np.ndarray] = []
        self._cursor, self._placements = 0, 0
        self._shift = np.zeros(2)
        self._board = Board()

    # -- what the page calls ----------------------------------------------------------------------------
    def start(self, n_poses: int = 12, seed: int = 0) -> dict:
        """Start a calibration of ``n_poses`` board poses (3-60) on a thread; refused while one runs or the rig
        is busy. On the simulator ``seed`` chooses the pool of poses the app offers."""
        if isinstance(n_poses, bool) or not isinstance(n_poses, int) or not 3 <= n_poses <= 60:
            raise RangekitError(f"poses: expected a whole number 3-60, found {n_poses!r}")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise RangekitError(f"seed: expected a whole number >= 0, found {seed!r}")
        with self._cond:
            if self.running:
                raise RangekitError("a calibration is running already")
            if self.holder.busy is not None:
                raise RangekitError(f"the rig is busy: {self.holder.busy}; wait for it to finish")
            if self.holder.devices.camera is None or self.holder.devices.projector is None:
                raise RangekitError(f"not connected: {self.holder.fault}" if self.holder.fault else
                                    "calibrating needs a camera and a projector; this rig lacks one")
            self.state, self.step, self.fields = JobState.RUNNING, Step.STARTING, {"n": n_poses}
            self.poses, self.lines, self.pictures, self._uv = [], [], {}, {}
            self._placements = 0
            self._go, self._decision, self._cancel = False, None, False
        self.changed()
        threading.Thread(target=self._run, args=(n_poses, seed), name="rangekit-calibrate", daemon=True).start()
        return self.snapshot()

    def capture(self) -> dict:
        """The board is placed: capture this pose."""
        with self._cond:
            self._expect("placing", "capture")
            self._go = True
            self.step = Step.CAPTURING
            self._cond.notify_all()
        self.changed()
        return self.snapshot()

    def decide(self, keep: bool) -> dict:
        """After a pose's capture: keep it (a rejected pose is then skipped) or retake it."""
        with self._cond:
            self._expect("review", "keep or retake")
            self._decision = not keep
            self.step = Step.CAPTURING if keep else Step.MOVING
            self._cond.notify_all()
        self.changed()
        return self.snapshot()

    def next_pose(self) -> dict:
        """Simulator: move the board to another hand-held pose."""
        self._move(advance=True, shift=(0.0, 0.0))
        return self.snapshot()

    def drag(self, dx: float, dy: float) -> dict:
        """Simulator: shift the board across the view by (dx, dy) camera pixels (at its centre's depth)."""
        for name, v in (("dx", dx), ("dy", dy)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or abs(v) > 5000:
                raise RangekitError(f"{name}: expected a number of pixels (-5000 to 5000), found {v!r}")
        self._move(advance=False, shift=(float(dx), float(dy)))
        return self.snapshot()

    def cancel(self) -> dict:
        with self._cond:
            if not self.running:
                raise RangekitError("no calibration is running")
            self._cancel = True
            self._cond.notify_all()
        return self.snapshot()

    def snapshot(self) -> dict:
        with self._cond:
            return {"state": self._shown(), **self.fields, "poses": list(self.poses),
                    "progress": list(self.lines[-12:]),
                    "simulated": self.holder.simulated_rig, "pictures": sorted(self.pictures)}

    # -- the thread -------------------------------------------------------------------------------------------
    def _expect(self, state: str, action: str) -> None:
        if self._shown() != state:
            raise RangekitError(f"{action}: the calibration is {self._shown()}, not {state}")

    def _shown(self) -> str:
        return self.step.value if self.running else self.state.value

    def _set(self, state: str | None = None, **fields) -> None:
        """The wizard's step (a :class:`Step`'s value) or its end (``done``, ``failed``, ``cancelled``), and the
        fields the page shows with it."""
        with self._cond:
            if state in (JobState.DONE, JobState.FAILED, JobState.CANCELLED):
                self.state = JobState(state)
            elif state is not None:
                self.step = Step(state)
            self.fields = {**self.fields, **fields}
            self._cond.notify_all()
        self.changed()

    def _wait(self, ready) -> None:
        with self._cond:
            self._cond.wait_for(lambda: self._cancel or ready())
            if self._cancel:
                raise _Cancelled()

    def _run(self, n_poses: int, seed: int) -> None:
        from rangekit.calib.procedure import CalibrationSettings, calibrate_rig, compare_rigs, comparison_lines

        holder, board = self.holder, self._board
        truth = holder.devices.rig if holder.simulated_rig else None
        try:
            if truth is not None:
                from rangekit.sim.writers.calibration import board_poses

                self._pool, self._cursor = board_poses(truth, board, 3 * n_poses, seed=seed), 0
            with holder.hold("calibration") as devices:
                saved = devices.scene if truth is not None else None
                try:
                    res = calibrate_rig(devices, settings=CalibrationSettings(board=board, n_poses=n_poses),
                                        place_board=self._place, place_on_turntable=self._on_turntable,
                                        template=holder.rig, progress=self.say, on_pose=self._on_pose)
                finally:
                    if self.stream is not None:
                        self.stream.annotate = None
                    if saved is not None:
                        devices.set_scene(saved)
                    if devices.projector is not None:
                        devices.projector.show(test_pattern(holder.pattern, *devices.projector.resolution))
            holder.replace_rig(res.rig)
            deviation = compare_rigs(res.rig, truth) if truth is not None else None
            self._set(state="done", summary=res.summary_lines(), rig_file=str(holder.rig_file),
                      parameters=_parameters(res.rig), deviation=deviation,
                      deviation_lines=comparison_lines(deviation) if deviation is not None else [])
        except _Cancelled:
            self._set(state="cancelled")
        except Exception as exc:  # noqa: BLE001 - the page gets one line, the log the details
            self._set("failed", error=failed(exc, "calibration"))
        forget_caches()     # as every job's end (Job.finish): the board's textures, the rays, the freed heap

    def _scene_now(self) -> None:
        """Simulator: put the board at the pool's current pose, shifted by the drag."""
        from rangekit.geometry import make_T
        from rangekit.sim.writers.calibration import board_scene

        T_world_board = self._pool[self._cursor % len(self._pool)]
        if np.any(self._shift):
            cam = self.holder.devices.rig.camera
            depth = float((cam.T_cam_world @ T_world_board[:, 3])[2])
            t_cam = np.array([self._shift[0] * depth / cam.K[0, 0], self._shift[1] * depth / cam.K[1, 1], 0.0])
            T_world_board = make_T(t=cam.T_world_cam[:3, :3] @ t_cam) @ T_world_board
        self.holder.devices.set_scene(board_scene(self._board, T_world_board))

    def _move(self, *, advance: bool, shift: tuple[float, float]) -> None:
        if not self.holder.simulated_rig:
            raise RangekitError("only the simulated board is moved by the app; move your board by hand")
        with self._cond:
            self._expect("placing", "move the board")
            if advance:
                self._cursor, self._shift = self._cursor + 1, np.zeros(2)
            else:
                self._shift = self._shift + np.asarray(shift)
            with self.holder.locked():
                self._scene_now()

    def _annotate(self, image: np.ndarray) -> dict:
        corners = live_corners(image, self._board)
        return {"board": {"found": bool(len(corners)), "corners": np.round(corners, 1).tolist()}}

    def _place(self, i: int, n: int) -> None:
        devices = self.holder.devices
        with self.holder.locked():
            if self.holder.simulated_rig:
                if self._placements:
                    self._cursor, self._shift = self._cursor + 1, np.zeros(2)
                self._scene_now()
            self._placements += 1
            if devices.projector is not None:
                devices.projector.show(test_pattern("white", *devices.projector.resolution))
        with self._cond:
            self._go = False
        if self.stream is not None:
            self.stream.annotate = self._annotate
        self.holder.allow_live(True)
        self._set(state="placing", pose=i, n=n)
        try:
            self._wait(lambda: self._go)
        finally:
            self.holder.allow_live(False)
            if self.stream is not None:
                self.stream.annotate = None
        self._set(state="capturing")

    def _on_pose(self, check, coverage: np.ndarray) -> bool:
        from rangekit.calib.pose_advice import next_pose_hint, tilt_image

        row = {"index": check.index, "kept": check.accepted, "line": check.line(), "reason": check.reason,
               "corners": check.n_corners, "reprojection_px": _finite(check.reprojection_px),
               "tilt_deg": _finite(check.tilt_deg), "area_percent": _finite(100 * check.area_fraction),
               "normal": [_finite(x) for x in check.normal]}
        with self._cond:
            rows = [r for r in self.poses if r["index"] != check.index] + [row]
            self._uv[check.index] = np.zeros((0, 2)) if check.corners is None else check.corners
            kept = [r for r in rows if r["kept"]]
            normals = [[np.nan if x is None else x for x in r["normal"]] for r in rows]
            hint = next_pose_hint([(None, self._uv[r["index"]]) for r in kept],
                                  [n for n, r in zip(normals, rows) if r["kept"]],
                                  self.holder.devices.camera.calibration.size)
            self.pictures = {"coverage": _png(coverage),
                             "tilts": _png(tilt_image(normals, [r["kept"] for r in rows]))}
            self.poses, self._decision = rows, None
        self._set(state="review", pose=check.index, hint=hint, last=row["line"])
        self.holder.allow_live(True)
        try:
            self._wait(lambda: self._decision is not None)
        finally:
            self.holder.allow_live(False)
        retake = bool(self._decision)
        if retake:
            with self._cond:
                self.poses = [r for r in self.poses if r["index"] != check.index]
        self._set(state="capturing" if not retake else "moving")
        return retake

    def _on_turntable(self) -> None:
        if self.holder.simulated_rig:
            from rangekit.sim.writers.calibration import turntable_board_scene

            self.holder.devices.set_scene(turntable_board_scene(self.holder.devices.rig, self._board))
            self.say("turntable: the app stood the board on the turntable")
            self._set(state="turntable")
            return
        self._set(state="placing", pose="turntable")
        self.holder.allow_live(True)
        try:
            with self._cond:
                self._go = False
            self._wait(lambda: self._go)
        finally:
            self.holder.allow_live(False)
        self._set(state="turntable")


def _finite(x: float) -> float | None:
    return round(float(x), 4) if np.isfinite(x) else None


def _parameters(rig) -> list[dict]:
    """Per device: its intrinsics and lens as written to the rig file (the page's result table)."""
    out = []
    for name, dev in (("camera", rig.camera), ("projector", rig.projector)):
        if dev is None:
            continue
        K = dev.K
        out.append({"device": name, "fx": round(float(K[0, 0]), 3), "fy": round(float(K[1, 1]), 3),
                    "cx": round(float(K[0, 2]), 3), "cy": round(float(K[1, 2]), 3),
                    "dist": [round(float(d), 6) for d in dev.dist]})
    return out
