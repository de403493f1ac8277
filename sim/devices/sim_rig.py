"""Simulated camera, projector and turntable implementing :mod:`rangekit.rig.devices`, and the default rig.

The default rig (world frame = turntable frame: origin at the centre of the table top, z up):
camera 1280x1024 at 0.5 m from the object, 25 degrees above the table; projector 1280x800 with a 0.2 m
baseline along the camera's x axis, both aimed at a point 6 cm above the table centre; mild lens
distortion on both. ``default_rig()`` is the truth the calibration issue is measured against.

Noise is reproducible per capture *state*: the generator for a capture is seeded from the rig's seed,
the turntable angle, a hash of the projected image, how many times that state was captured before and
how many times :meth:`SimRig.set_scene` replaced the scene. So a scan that is interrupted and resumed
records the same bytes as one that ran through, and a calibration run (one scene per board pose)
records the same bytes for the same sequence of ``set_scene`` and capture calls.
"""

from __future__ import annotations

import zlib
from dataclasses import replace

import numpy as np

from rangekit.camera import PinholeCamera, world_pixel_rays
from rangekit.rig.checks import camera_triggered
from rangekit.rig.devices import check_pattern
from rangekit.errors import DeviceDisconnected, SceneError
from rangekit.geometry import look_at, make_T
from rangekit.rig.rig_file import Rig
from rangekit._runtime.threads import one_blas_thread
from rangekit.sim.scene.raycast import ViewGeometry, cast_view, pixel_corners
from rangekit.sim.devices.clock import TICK_EPS_S, SimClock
from rangekit.sim.imaging.render import ImagingModel, ViewRenderer
from rangekit.sim.devices.camera import SimCamera
from rangekit.sim.devices.trigger import DEFAULT_REFRESH_HZ, VsyncTrigger
from rangekit.sim.scene.scene import Scene

__all__ = ["default_rig", "SimCamera", "SimProjector", "SimTurntable", "SimRig"]


def default_rig() -> Rig:
    """The simulator's true rig (see the module docstring); its projector response is ImagingModel's
    default gamma (2.2)."""
    from rangekit.rig.projector_response import ProjectorResponse

    target = np.array([0.0, 0.0, 0.06])
    elev = np.radians(25.0)
    eye = target + 0.5 * np.array([0.0, -np.cos(elev), np.sin(elev)])
    T_world_cam = look_at(eye, target)
    cam = PinholeCamera(K=np.array([[1800.0, 0.0, 645.3], [0.0, 1801.5, 508.7], [0.0, 0.0, 1.0]]),
                        width=1280, height=1024, dist=np.array([-0.08, 0.12, 2e-4, -1e-4, 0.0]),
                        T_world_cam=T_world_cam, name="camera")
    proj_eye = eye + 0.2 * T_world_cam[:3, 0]
    proj = PinholeCamera(K=np.array([[1500.0, 0.0, 640.0], [0.0, 1500.0, 520.0], [0.0, 0.0, 1.0]]),
                         width=1280, height=800, dist=np.array([-0.02, 0.01, 0.0, 0.0, 0.0]),
                         T_world_cam=look_at(proj_eye, target), name="projector")
    return Rig(cameras=(cam,), projector=proj, T_world_table=make_T(),
               devices={"camera": {"type": "sim"}, "projector": {"type": "sim"}, "turntable": {"type": "sim"}},
               capture={"bits": 8}, projector_response=ProjectorResponse(gamma=ImagingModel.gamma))


class _Faults:
    """Simulated unplugging: ``arm(device, after)`` makes the device's (after + 1)-th call fail."""

    def __init__(self) -> None:
        self.left: dict[str, int] = {}

    def arm(self, device: str, after: int) -> None:
        self.left[device] = int(after)

    def tick(self, device: str) -> None:
        if device in self.left:
            if self.left[device] <= 0:
                del self.left[device]
                raise DeviceDisconnected(f"{device} (simulated): unplugged")
            self.left[device] -= 1


class SimTurntable:
    """A turntable; ``angle`` in radians. It moves instantly, or at ``speed_rad_s`` on the shared ``clock``
    (:meth:`rotate_to` then takes ``|angle - before| / speed``, as a stepper board does). Like the Horus and
    FabScan boards it also switches the rig's line lasers (``laser(n, on)``, n = the laser's ``switch``
    number)."""

    def __init__(self, faults: _Faults | None = None, *, speed_rad_s: float | None = None, clock=None) -> None:
        self._angle = 0.0
        self._faults = faults or _Faults()
        self.lasers_on: set[int] = set()
        if speed_rad_s is not None and not (np.isfinite(speed_rad_s) and speed_rad_s > 0):
            raise SceneError(f"SimTurntable: speed_rad_s must be a finite number > 0 or None, found {speed_rad_s!r}")
        self.speed_rad_s = speed_rad_s
        self.clock = clock if clock is not None else SimClock()

    def laser(self, n: int, on: bool) -> None:
        self._faults.tick("turntable")
        if on:
            self.lasers_on.add(int(n))
        else:
            self.lasers_on.discard(int(n))

    @property
    def angle(self) -> float:
        return self._angle

    def rotate_to(self, angle: float) -> None:
        self._faults.tick("turntable")
        if self.speed_rad_s is not None:
            self.clock.sleep(abs(float(angle) - self._angle) / self.speed_rad_s)
        self._angle = float(angle)


class SimProjector:
    """Holds the image being shown; black until the first :meth:`show`.

    ``latency_s``: the display's latency (seconds, >= 0). A pattern shown at time t (``clock.now()``)
    is seen by camera frames exposed at or after t + latency_s; frames before see the previous pattern
    (:meth:`image_at`). ``clock``: the clock shared with the camera (:mod:`rangekit.sim.devices.clock`).
    ``trigger``: the VSYNC line to a triggered camera (:mod:`rangekit.sim.devices.trigger`): :meth:`show` is then
    a flip at the projector's refresh, which sends the camera a pulse once the pattern is shown.
    """

    def __init__(self, model: PinholeCamera, faults: _Faults | None = None, *, latency_s: float = 0.0,
                 clock=None, trigger: VsyncTrigger | None = None) -> None:
        self._model = model
        self._image = np.zeros((model.height, model.width), np.uint8)
        self._faults = faults or _Faults()
        latency = float(latency_s)
        if not np.isfinite(latency) or latency < 0:
            raise SceneError(f"SimProjector: latency_s must be a finite number of seconds >= 0, found {latency_s!r}")
        self.latency_s = latency
        self.clock = clock if clock is not None else SimClock()
        self.trigger = trigger
        self._shown: list[tuple[float, np.ndarray]] = []    # (time shown, image), oldest first
        self._seen = self._image                              # what the light showed before self._shown

    @property
    def calibration(self) -> PinholeCamera:
        return self._model

    @property
    def resolution(self) -> tuple[int, int]:
        return self._model.width, self._model.height

    @property
    def image(self) -> np.ndarray:
        """The image last passed to :meth:`show` (what the projector will show once its latency passed)."""
        return self._image

    def show(self, image: np.ndarray) -> None:
        self._faults.tick("projector")
        img = check_pattern(image, self.resolution, self._model.name)
        if self.trigger is not None:
            self.trigger.flip(img)
        self._image = img
        self._shown.append((self.clock.now(), img))

    def image_at(self, t: float) -> np.ndarray:
        """The image on the object at time ``t`` (seconds; times only move forwards): the last one shown
        at or before ``t - latency_s``."""
        while self._shown and self._shown[0][0] + self.latency_s <= t + TICK_EPS_S:
            self._seen = self._shown.pop(0)[1]
        return self._seen


class SimRig:
    """A simulated projector-camera-turntable rig with exact ground truth.

    Parameters
    ----------
    scene : Scene, in the rig's world frame.
    rig : Rig, default :func:`default_rig`.
    imaging : ImagingModel (noise, blur, gamma, bit depth...).
    seed : int, base seed of every capture's noise.
    light : "projector" (the camera sees the projected pattern) or "laser" (the rig's line lasers,
        switched by the turntable; :class:`rangekit.sim.laser.frames.LaserView` with ``laser_ambient_scale``).
    latency_s : the projector's display latency, seconds (:class:`SimProjector`); a simulator setting, not
        a rig file field (a real rig's is measured, and written as ``capture.pattern_delay_s``).
    clock : the clock the devices share (:mod:`rangekit.sim.devices.clock`); default a virtual :class:`SimClock`.
        ``sim.sleep`` waits on it (acquisition and calibration wait through ``devices.sleep``).
    turntable_speed_deg_s : the turntable's speed on ``clock`` (None: it moves instantly).

    A rig whose ``capture.trigger`` is "projector" has its camera triggered by the projector's VSYNC
    (``trigger``, :mod:`rangekit.sim.devices.trigger`; the refresh rate ``devices.projector.refresh_hz``, else
    60 Hz); :meth:`inject_missed_trigger` makes the camera miss a pulse.
    pass_motions : (passes, 4, 4) a multi-pass scan's motion of the object in each pass
        (:func:`rangekit.sim.scene.passes.pass_motions`); :meth:`start_pass` turns it over between passes.
    """

    def __init__(self, scene: Scene, rig: Rig | None = None, *, imaging: ImagingModel | None = None,
                 seed: int = 0, light: str = "projector", laser_ambient_scale: int = 4, latency_s: float = 0.0,
                 clock=None, pass_motions=None, turntable_speed_deg_s: float | None = None) -> None:
        if not isinstance(scene, Scene):
            raise SceneError(f"SimRig: scene must be a rangekit.sim.Scene, found {type(scene).__name__}")
        self._scene = scene
        self._scene_index = 0
        self.imaging = imaging if imaging is not None else ImagingModel()
        rig = rig if rig is not None else default_rig()
        if rig.capture.get("bits") != self.imaging.bits:
            # The rig file states the camera's bit depth (capture.bits), as a real rig's does.
            rig = replace(rig, capture={**rig.capture, "bits": self.imaging.bits})
        self.rig = rig
        self.seed = int(seed)
        if light not in ("projector", "laser"):
            raise SceneError(f"SimRig: light must be 'projector' or 'laser', found {light!r}")
        if light == "laser" and not self.rig.lasers:
            raise SceneError("SimRig(light='laser'): the rig has no lasers (rig file 'lasers'); use "
                             "rangekit.sim.laser.rig.laser_rig()")
        self.light, self.laser_ambient_scale = light, int(laser_ambient_scale)
        self._laser_key, self._laser_view = None, None
        self._faults = _Faults()
        self.clock = clock if clock is not None else SimClock()
        self.sleep = self.clock.sleep
        self.camera = SimCamera(self)
        refresh_hz = ((self.rig.devices or {}).get("projector") or {}).get("refresh_hz", DEFAULT_REFRESH_HZ)
        self.trigger = VsyncTrigger(self.clock, refresh_hz, latency_s) if (
            camera_triggered(self.rig.capture) and self.rig.projector is not None) else None
        self.projector = None if self.rig.projector is None else SimProjector(
            self.rig.projector, self._faults, latency_s=latency_s, clock=self.clock, trigger=self.trigger)
        speed = None if turntable_speed_deg_s is None else np.radians(float(turntable_speed_deg_s))
        self.turntable = SimTurntable(self._faults, speed_rad_s=speed, clock=self.clock) \
            if self.rig.T_world_table is not None else None
        self._cam_rays = None
        self._corner_rays = None
        self._cache_key = None
        self._cache = None
        self._counts: dict[tuple[int, int, int], int] = {}
        self._knock, self._knocked_key, self._knocked = None, None, None   # inject_motion
        self.pass_motions = None if pass_motions is None else np.asarray(pass_motions, dtype=np.float64)
        self._pass, self._pass0_scene = 0, scene

    def start_pass(self, p: int) -> None:
        """Put the object in its pose of pass ``p`` (acquisition calls it before each view): the first scene
        moved by ``pass_motions[p]``, set (:meth:`set_scene`) only when the pass changes, so a scan resumed
        in a later pass records the same bytes as one that ran through."""
        if p == self._pass:
            return
        if self.pass_motions is None or not 0 <= p < len(self.pass_motions):
            raise SceneError(f"SimRig.start_pass: pass {p} has no motion (pass_motions has "
                             f"{0 if self.pass_motions is None else len(self.pass_motions)})")
        from rangekit.sim.scene.passes import pass_scene

        self.set_scene(pass_scene(self._pass0_scene, self.pass_motions[p]))
        self._pass = p

    # ---------------------------------------------------------------- scene
    @property
    def scene(self) -> Scene:
        """The scene being imaged; assigning to it is :meth:`set_scene`."""
        return self._scene

    @scene.setter
    def scene(self, scene: Scene) -> None:
        self.set_scene(scene)

    def set_scene(self, scene: Scene) -> None:
        """Replace the scene (e.g. move the calibration board to its next pose).

        Drops the cached ground truth and starts a new noise stream: captures after the n-th
        ``set_scene`` are seeded with n as well, so the same sequence of ``set_scene`` and capture calls
        gives the same bytes, and two scenes never share noise. The turntable angle is kept.
        """
        if not isinstance(scene, Scene):
            raise SceneError(f"SimRig.set_scene: expected a rangekit.sim.Scene, found {type(scene).__name__}")
        self._scene = scene
        self._scene_index += 1
        self._cache_key = None
        self._cache = None

    def inject_fault(self, device: str, after: int = 0) -> None:
        """Unplug ``device`` ("camera", "projector" or "turntable") at its (after + 1)-th call from now:
        that call raises DeviceDisconnected. For testing crash safety."""
        if device not in ("camera", "projector", "turntable"):
            raise ValueError(f"inject_fault: device must be camera, projector or turntable, found {device!r}")
        self._faults.arm(device, after)

    def inject_missed_trigger(self, after: int = 0) -> None:
        """The triggered camera misses the (after + 1)-th projector pulse it takes from now: it counts the pulse
        and exposes no frame for it (:meth:`rangekit.sim.devices.trigger.VsyncTrigger.miss`). For testing that a
        missed trigger is named and the view taken again."""
        if self.trigger is None or int(after) < 0:
            raise SceneError(f"inject_missed_trigger: needs a rig whose capture.trigger is 'projector' and after >= 0, "
                             f"found trigger {self.rig.capture.get('trigger', 'none')!r}, after={after!r}")
        self.trigger.miss(int(after))

    def inject_motion(self, T_move: np.ndarray, after: int = 0, frames: int = 1) -> None:
        """Knock the object: from the camera's (after + 1)-th capture from now, for ``frames`` captures, the object
        is displaced by ``T_move`` ((4, 4), world), then back in place (a bump during a view: the frames taken
        while it lasts see the moved object, a view taken again afterwards a still one). For testing the motion
        check (:mod:`rangekit.coded.motion`)."""
        T = np.asarray(T_move, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)) or int(after) < 0 or int(frames) < 1:
            raise SceneError(f"inject_motion: expected a finite (4, 4) motion, after >= 0 and frames >= 1, found "
                             f"{T.shape}, after={after!r}, frames={frames!r}")
        self._knock = [int(after), int(frames), T]

    def capture_renderer(self) -> ViewRenderer:
        """The renderer of the camera's next capture: :meth:`renderer`, or the knocked object's while an
        :meth:`inject_motion` lasts."""
        knock = self._knock
        if knock is None:
            return self.renderer()
        if knock[0] > 0:
            knock[0] -= 1
            return self.renderer()
        knock[1] -= 1
        if knock[1] == 0:
            self._knock = None
        from rangekit.sim.scene.passes import pass_scene

        angle = self._state_angle()
        motion = self.rig.T_world_rotated(angle) if self.turntable is not None else None
        key = (self._scene_index, angle, knock[2].tobytes())
        if self._knocked_key != key:
            self._view()                   # the camera's rays, made once
            with one_blas_thread():
                geom = cast_view(pass_scene(self._scene, knock[2]).world_mesh(motion), self.rig.camera,
                                 self.rig.projector, cam_rays=self._cam_rays, corner_rays=self._corner_rays)
                self._knocked = ViewRenderer(geom, self.imaging, self.projector.resolution)
            self._knocked_key = key
        return self._knocked

    # ---------------------------------------------------------------- ground truth
    def _state_angle(self) -> float:
        return 0.0 if self.turntable is None else self.turntable.angle

    def _view(self) -> tuple[ViewGeometry, ViewRenderer]:
        angle = self._state_angle()
        key = (self._scene_index, angle)
        if self._cache_key != key:
            cam = self.rig.camera
            if self._cam_rays is None:
                self._cam_rays = world_pixel_rays(cam)
            if self._corner_rays is None and any(o.texture is not None for o in self._scene.objects):
                self._corner_rays = cam.rays(pixel_corners(cam))
            motion = self.rig.T_world_rotated(angle) if self.turntable is not None else None
            with one_blas_thread():     # thin products; frames render on the other core
                geom = cast_view(self._scene.world_mesh(motion), cam, self.rig.projector,
                                 cam_rays=self._cam_rays, corner_rays=self._corner_rays)
                self._cache = (geom, ViewRenderer(geom, self.imaging, self.projector.resolution))
            self._cache_key = key
        return self._cache

    def ground_truth(self) -> ViewGeometry:
        """Exact per-pixel truth for the current turntable angle."""
        return self._view()[0]

    def renderer(self) -> ViewRenderer:
        return self._view()[1]

    # ---------------------------------------------------------------- line lasers
    def laser_view(self):
        """The :class:`rangekit.sim.laser.frames.LaserView` of the current scene and angle (cached)."""
        from rangekit.sim.laser.frames import LaserView

        key = (self._scene_index, self._state_angle())
        if self._laser_key != key:
            seed = self.seed + self._scene_index * 1_000_003
            self._laser_view = LaserView(self._scene, self.rig, self._state_angle(), imaging=self.imaging, seed=seed,
                                         ambient_scale=self.laser_ambient_scale)
            self._laser_key = key
        return self._laser_view

    def laser_index(self, n: int) -> int:
        """Index in ``rig.lasers`` of the laser the board switches as number ``n`` (its ``switch``, else
        its position + 1)."""
        for k, laser in enumerate(self.rig.lasers):
            if (laser.switch if laser.switch is not None else k + 1) == n:
                return k
        raise SceneError(f"simulated turntable: laser {n} is not in the rig file's lasers (switch numbers "
                         f"{[laser.switch or k + 1 for k, laser in enumerate(self.rig.lasers)]})")

    def laser_image(self) -> np.ndarray:
        """What the camera sees now: the laser that is on, or the ambient image when all are off. The same
        state gives the same bytes (the noise is seeded by the seed, the angle and the laser)."""
        on = sorted(self.turntable.lasers_on) if self.turntable is not None else []
        if len(on) > 1:
            raise SceneError(f"the simulator renders one laser at a time; lasers {on} are on")
        view = self.laser_view()
        return view.off() if not on else view.frame(self.laser_index(on[0])).image

    # ---------------------------------------------------------------- reproducible noise
    def rng_for(self, image: np.ndarray) -> np.random.Generator:
        """The generator for the next capture of ``image`` at the current angle (see module docstring).

        Its spawn key is ``(angle, image CRC, repeat count)``, plus the scene index after the first
        :meth:`set_scene` (so the initial scene keeps the bytes it had before scenes could change).
        """
        angle_key = int(round((self._state_angle() % (2 * np.pi)) * 1e9))
        img = np.ascontiguousarray(image)
        key = (angle_key, zlib.crc32(img.tobytes()) ^ zlib.crc32(repr((img.shape, img.dtype.str)).encode()))
        count = self._counts.get((self._scene_index, *key), 0)
        self._counts[(self._scene_index, *key)] = count + 1
        scene_key = (self._scene_index,) if self._scene_index else ()
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(*key, count, *scene_key)))

    def restart_noise(self) -> None:
        """Forget how often each state was captured: the next capture of a state draws the noise of its
        first capture. A view taken again (after a device came back mid-view) then records the bytes an
        uninterrupted scan records; call it when the turntable arrives for a view (tests' hardware fakes
        do, on each move command the simulated board receives)."""
        self._counts.clear()

    def capture_sequence(self, patterns, delay_s: float = 0.0) -> list[np.ndarray]:
        """Show each pattern, wait ``delay_s`` on the clock and capture it: the same bytes as show(),
        sleep() and capture() in turn. Renders on two threads when no frame depends on the one before
        (no projector latency, no auto-exposure, no :meth:`inject_motion` pending)."""
        if self.camera.auto_exposure or self.projector.latency_s > 0 or self._knock is not None:
            out = []
            for p in patterns:
                self.projector.show(p)
                self.sleep(delay_s)
                out.append(self.camera.capture())
            return out
        images, rngs, exposures = [], [], []
        for p in patterns:
            self.projector.show(p)
            self.sleep(delay_s)
            exposures.append(self.camera.exposure())
            images.append(self.projector.image_at(self.camera.next_frame()))
            self.camera.last_exposure = exposures[-1]
            rngs.append(self.rng_for(images[-1]))
        return self.renderer().render_many(images, rngs, exposures=exposures)
