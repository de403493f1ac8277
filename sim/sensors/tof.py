"""A simulated time-of-flight camera: continuous-wave correlation samples and pulsed round-trip times.

The emitter sits at the camera's optical centre. Every pixel is supersampled by ``s x s`` rays
(:func:`rangekit.sim.scene.raycast.cast_view` on the same lens at ``s`` times the resolution; with ``s`` odd
the central ray is the pixel centre, which gives the ground truth). A ray hitting a surface at radial
distance ``r`` with albedo ``rho`` (mean of RGB) and incidence cosine ``cos_i`` returns

    a = signal_e * rho * cos_i / r^2          electrons per sample of active light (1/r^2: emitter falloff)
    b = ambient_e * rho                       electrons per sample of ambient light

and at modulation frequency ``f`` the phasor ``contrast * a * exp(i phi)`` with ``phi = 4 pi f r / c``.
A pixel averages its rays' offsets and phasors (so a pixel straddling a depth edge mixes two surfaces:
a *flying pixel*) and records, for each phase step ``theta_k`` of the plan,

    S_k = B + A cos(phi_pixel - theta_k),   B = mean(a + b),   A exp(i phi_pixel) = mean(phasor)

Optional multipath adds, per pixel, a second return of ``multipath_strength`` times the direct light
(offset and phasor) that travelled ``multipath_extra_m`` metres further (round trip). Then shot noise
(Gaussian with variance ``S_k`` electrons), read noise (``read_noise_e`` RMS), clipping at
``full_well_e`` and quantisation to ``bits`` (``full_well_e / (2^bits - 1)`` electrons per DN).
Rays that miss every surface return nothing (no background wall at infinity).

Pulsed mode (:func:`render_pulsed`): one ray per pixel, round trip ``2 r / c`` plus Gaussian timing
jitter of ``jitter_s`` seconds.

Frames: ``T_world_cam`` of the camera; the default camera sits at the world origin (world = camera).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.geometry import axis_angle_to_R, make_T
from rangekit.io import atomic_save_npz, atomic_write_json, write_png
from rangekit.rig.rig_file import Rig, save_rig
from rangekit.sim.scene.objects import make_object
from rangekit.sim.scene.raycast import cast_view
from rangekit.sim.scene.scene import Scene
from rangekit.tof.plan import C_LIGHT, FrequencyPlan
from rangekit.tof.range_maps import range_to_points
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["ToFSensor", "ToFCapture", "PulsedCapture", "KINECT_V2_PLAN", "LUXONIS_PLAN", "tof_camera", "tof_scene",
           "render_tof", "render_pulsed", "write_tof_capture", "write_pulsed_capture"]

#: Kinect v2-like: 16, 80, 120 MHz, 3 steps each (combined unambiguous range 18.75 m).
KINECT_V2_PLAN = FrequencyPlan.uniform((16e6, 80e6, 120e6), 3)
#: Luxonis ToF-like: 80 and 100 MHz, 4 steps each (7.5 m).
LUXONIS_PLAN = FrequencyPlan.uniform((80e6, 100e6), 4)


@dataclass(frozen=True)
class ToFSensor:
    """Light and sensor parameters of the simulated ToF camera (electrons per sample).

    Defaults: at 15 m an albedo-0.8 surface facing the camera gives ``A / sigma_s`` = 7.3 per sample
    (phase noise 0.11 rad with 3 steps); below 0.6 m about 290, and the brightest sample (2.8e5 e-) stays
    below the full well.
    """

    signal_e: float = 5.0e4       # active light from albedo 1, facing, at 1 m (electrons per sample, DC part)
    contrast: float = 0.8         # modulation contrast: A = contrast * a
    ambient_e: float = 200.0      # ambient light from albedo 1 (electrons per sample)
    read_noise_e: float = 10.0    # electrons RMS
    full_well_e: float = 5.0e5    # clipping level (accumulated over the sub-frames of one sample)
    bits: int = 16                # ADC bits; electrons per DN = full_well_e / (2^bits - 1)
    multipath_strength: float = 0.0   # second return, as a fraction of the direct light
    multipath_extra_m: float = 0.0    # its extra round-trip path, metres

    def __post_init__(self) -> None:
        for name in ("signal_e", "contrast", "ambient_e", "read_noise_e", "full_well_e", "multipath_strength",
                     "multipath_extra_m"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise InputError(f"ToFSensor: {name} must be finite and >= 0, found {v!r}")
        if not 0 < self.contrast <= 1 or self.full_well_e <= 0:
            raise InputError(f"ToFSensor: need 0 < contrast <= 1 and full_well_e > 0, found contrast={self.contrast!r}, "
                             f"full_well_e={self.full_well_e!r}")
        if self.bits not in (8, 10, 12, 14, 16):
            raise InputError(f"ToFSensor: bits must be 8, 10, 12, 14 or 16, found {self.bits!r}")

    @property
    def electrons_per_dn(self) -> float:
        return self.full_well_e / ((1 << self.bits) - 1)


@dataclass(frozen=True, eq=False, repr=False)
class ToFCapture:
    """Raw CW samples and the exact truth.

    samples : (K, H, W) uint16 DN (or uint8 for 8 bits), frequency-major as ``plan`` orders them.
    expected : (K, H, W) float64 noise-free samples in electrons (before clipping and quantisation).
    amplitude_true, offset_true : (F, H, W) float64 the pixel's ``A`` and ``B`` in electrons (noise free).
    range_true : (H, W) float64 radial distance of the pixel centre's ray, metres; NaN where it misses.
    depth_true : (H, W) float64 camera-frame z of that hit; NaN where it misses.
    xyz_true : (H, W, 3) float64 world hit point; NaN where it misses.
    hit : (H, W) bool, the centre ray hits a surface.
    mixed : (H, W) bool, the pixel's rays disagree: some miss or their ranges spread more than
        ``mixed_tolerance`` (1% of the range): a flying pixel is expected there.
    subray_range : (H, W, s*s) float64 radial distance of each of the pixel's rays (NaN where it misses):
        a measurement near any of them lies on a surface the pixel sees; one far from all of them flies.
    """

    samples: np.ndarray
    expected: np.ndarray
    amplitude_true: np.ndarray
    offset_true: np.ndarray
    range_true: np.ndarray
    depth_true: np.ndarray
    xyz_true: np.ndarray
    hit: np.ndarray
    mixed: np.ndarray
    subray_range: np.ndarray
    plan: FrequencyPlan
    sensor: ToFSensor
    camera: PinholeCamera

    def __repr__(self) -> str:
        K, H, W = self.samples.shape
        return f"ToFCapture({self.plan.describe()}, {W}x{H}, hit={self.hit.mean():.1%}, mixed={self.mixed.mean():.1%})"

    def noise_sigma_e(self) -> np.ndarray:
        """(K, H, W) per-sample noise standard deviation in electrons: shot + read + quantisation."""
        q = self.sensor.electrons_per_dn
        return np.sqrt(np.maximum(self.expected, 0) + self.sensor.read_noise_e ** 2 + q * q / 12.0)


@dataclass(frozen=True, eq=False, repr=False)
class PulsedCapture:
    """Pulsed ToF: round_trip_s (H, W) float64 seconds (NaN where nothing returns), and the truth."""

    round_trip_s: np.ndarray
    range_true: np.ndarray
    depth_true: np.ndarray
    hit: np.ndarray
    jitter_s: float
    camera: PinholeCamera

    def __repr__(self) -> str:
        H, W = self.hit.shape
        return f"PulsedCapture({W}x{H}, jitter={self.jitter_s * 1e12:g} ps, hit={self.hit.mean():.1%})"


def tof_camera(width: int = 320, height: int = 240) -> PinholeCamera:
    """A ToF camera with a 70 x 55 degree field of view and barrel distortion, at the world origin."""
    fx = (width / 2) / np.tan(np.radians(35.0))
    K = np.array([[fx, 0.0, (width - 1) / 2 + 0.7], [0.0, fx, (height - 1) / 2 - 0.4], [0.0, 0.0, 1.0]])
    return PinholeCamera(K=K, width=width, height=height, dist=np.array([-0.12, 0.03, 0.0, 0.0, 0.0]),
                         T_world_cam=np.eye(4), name="tof")


_PANEL_MARGIN = 1.06 * 1.2  # panel size over the strip it covers


def tof_scene(near: float = 0.5, far: float = 15.0, *, columns: int = 12, albedo: float = 0.8) -> Scene:
    """Panels facing the camera (world = camera frame) at ranges from ``near`` to ``far`` metres.

    The top half of the view is ``columns`` vertical strips, each a panel perpendicular to the ray
    through its centre, at ranges spaced geometrically from ``near`` to ``far``; the bottom half is
    ``columns`` more panels in the reverse order, each tilted 30 degrees about its vertical axis (so
    ranges vary within it). Neighbouring strips overlap slightly, so every pixel sees a panel and every
    strip border is a depth edge (with flying pixels).
    """
    if not (0 < near < far) or columns < 2:
        raise InputError(f"tof_scene: need 0 < near < far and columns >= 2, found near={near!r}, far={far!r}, "
                         f"columns={columns!r}")
    half_w, half_h = np.tan(np.radians(40.0)), np.tan(np.radians(32.0))  # a little beyond the 70 x 55 deg view
    edges = np.linspace(-half_w, half_w, columns + 1)
    ranges = np.geomspace(near, far, 2 * columns)
    objects = []
    for row, (y0, y1) in enumerate(((-half_h, 0.0), (0.0, half_h))):
        for i in range(columns):
            k = i if row == 0 else 2 * columns - 1 - i
            r = ranges[k]
            x0, x1 = edges[i], edges[i + 1]
            xc, yc = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
            d = np.array([xc, yc, 1.0])
            d /= np.linalg.norm(d)
            centre = r * d
            # Panel size: the strip's extent in normalised coordinates times r, enlarged 27% so that
            # neighbouring strips overlap (also once tilted).
            w = _PANEL_MARGIN * r * (x1 - x0)
            h = _PANEL_MARGIN * r * (y1 - y0)
            tilt = 0.0 if row == 0 else np.radians(30.0)
            # Panel frame: z towards the camera (normal = -d), then tilted about the panel's y axis.
            z_axis = -d
            x_axis = np.cross([0.0, 1.0, 0.0], z_axis)
            x_axis /= np.linalg.norm(x_axis)
            y_axis = np.cross(z_axis, x_axis)
            R = np.column_stack([x_axis, y_axis, z_axis]) @ axis_angle_to_R([0.0, 1.0, 0.0], tilt)
            panel = make_object("plane", width=w, height=h, albedo=albedo, name=f"panel_{row}_{i}")
            objects.append(panel.with_pose(make_T(R, centre)))
    return Scene(tuple(objects))


def _supersampled_rays(scene: Scene, camera: PinholeCamera, s: int):
    """cast_view on the lens at s x s resolution: per-ray (range, albedo, cos_i) as (H, W, s*s) arrays."""
    big = camera.resized(camera.width * s, camera.height * s)
    g = cast_view(scene.world_mesh(), big, None)
    H, W = camera.height, camera.width

    def blocks(a: np.ndarray) -> np.ndarray:
        return a.reshape(H, s, W, s, *a.shape[2:]).swapaxes(1, 2).reshape(H, W, s * s, *a.shape[2:])

    o = big.center
    view = o[None, None, :] - g.xyz
    with np.errstate(invalid="ignore"):
        cos_i = np.clip(np.einsum("ijk,ijk->ij", g.normal, view) / g.range, 0.0, 1.0)
    return g, blocks(g.range), blocks(g.albedo.mean(axis=2)), blocks(cos_i), blocks(g.hit), blocks(g.depth), blocks(g.xyz)


def render_tof(scene: Scene, plan: FrequencyPlan = KINECT_V2_PLAN, *, camera: PinholeCamera | None = None,
               sensor: ToFSensor = ToFSensor(), supersample: int = 3, noise: bool = True,
               seed: int | np.random.Generator = 0, mixed_tolerance: float = 0.01) -> ToFCapture:
    """Render raw CW correlation samples of ``scene`` for every frequency and phase step of ``plan``.

    ``supersample`` (odd, >= 1) rays per pixel side; ``noise=False`` gives quantised expected samples.
    See the module docstring for the signal model.
    """
    if int(supersample) != supersample or supersample < 1 or supersample % 2 == 0:
        raise InputError(f"render_tof: supersample must be an odd integer >= 1, found {supersample!r}")
    if not isinstance(plan, FrequencyPlan):
        raise InputError(f"render_tof: plan must be a rangekit.tof.FrequencyPlan, found {type(plan).__name__}")
    camera = camera if camera is not None else tof_camera()
    s = int(supersample)
    _, r, rho, cos_i, hit, depth, xyz = _supersampled_rays(scene, camera, s)
    c = s * s // 2  # the central ray: the pixel centre
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(hit, sensor.signal_e * rho * cos_i / r ** 2, 0.0)        # (H, W, s*s)
    b = np.where(hit, sensor.ambient_e * rho, 0.0)
    r0 = np.where(hit, r, 0.0)
    m = sensor.multipath_strength
    offset = (a + b).mean(axis=2) + m * a.mean(axis=2)
    F = len(plan.frequencies)
    H, W = camera.height, camera.width
    amp, phase = np.empty((F, H, W)), np.empty((F, H, W))
    for j, f in enumerate(plan.frequencies):
        phasor = (sensor.contrast * a * np.exp(1j * 4 * np.pi * f * r0 / C_LIGHT)).mean(axis=2)
        if m > 0:
            direct = (sensor.contrast * a).mean(axis=2)
            r_c = np.where(hit[..., c], r[..., c], 0.0)
            phasor = phasor + m * direct * np.exp(1j * 2 * np.pi * f * (2 * r_c + sensor.multipath_extra_m) / C_LIGHT)
        amp[j], phase[j] = np.abs(phasor), np.angle(phasor)
    expected = np.concatenate([offset[None] + amp[j][None] * np.cos(phase[j][None] - np.asarray(t).reshape(-1, 1, 1))
                               for j, t in enumerate(plan.steps)])
    rng = np.random.default_rng(seed)
    e = expected
    if noise:
        e = e + np.sqrt(np.maximum(e, 0) + sensor.read_noise_e ** 2) * rng.standard_normal(e.shape)
    dtype = np.uint8 if sensor.bits == 8 else np.uint16
    dn = np.rint(np.clip(e, 0, sensor.full_well_e) / sensor.electrons_per_dn).astype(dtype)
    centre_hit = hit[..., c]
    spread = np.where(hit, r, np.nan)
    with np.errstate(invalid="ignore"):
        mixed = centre_hit & ((~hit).any(axis=2) |
                              (np.nanmax(spread, axis=2) - np.nanmin(spread, axis=2) > mixed_tolerance * r[..., c]))
    return ToFCapture(samples=dn, expected=expected, amplitude_true=amp, offset_true=np.broadcast_to(offset, (F, H, W)).copy(),
                      range_true=np.where(centre_hit, r[..., c], np.nan), depth_true=np.where(centre_hit, depth[..., c], np.nan),
                      xyz_true=np.where(centre_hit[..., None], xyz[:, :, c], np.nan), hit=centre_hit, mixed=mixed,
                      subray_range=np.where(hit, r, np.nan), plan=plan, sensor=sensor, camera=camera)


def render_pulsed(scene: Scene, *, camera: PinholeCamera | None = None, jitter_s: float = 50e-12,
                  seed: int | np.random.Generator = 0) -> PulsedCapture:
    """Round-trip times ``2 r / c + N(0, jitter_s^2)`` seconds of every pixel centre's ray."""
    if not (np.isfinite(jitter_s) and jitter_s >= 0):
        raise InputError(f"render_pulsed: jitter_s must be finite and >= 0 seconds, found {jitter_s!r}")
    camera = camera if camera is not None else tof_camera()
    g = cast_view(scene.world_mesh(), camera, None)
    rng = np.random.default_rng(seed)
    dt = 2 * g.range / C_LIGHT + jitter_s * rng.standard_normal(g.range.shape)
    return PulsedCapture(round_trip_s=np.where(g.hit, dt, np.nan), range_true=g.range, depth_true=g.depth,
                         hit=g.hit, jitter_s=float(jitter_s), camera=camera)


def _preview(values: np.ndarray) -> np.ndarray:
    """8-bit grey preview, scaled between the 1st and 99th percentiles of the finite values."""
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    if not ok.any():
        return np.zeros(v.shape, np.uint8)
    lo, hi = np.percentile(v[ok], [1, 99])
    out = np.clip((v - lo) / max(hi - lo, 1e-12), 0, 1)
    return np.rint(np.where(ok, out, 0) * 255).astype(np.uint8)


def _truth(out: Path, *, range_true, depth_true, xyz, hit, camera: PinholeCamera, **extra) -> None:
    atomic_save_npz(out / "ground_truth.npz", range=range_true, depth=depth_true, xyz=xyz, hit=hit,
                    T_world_cam=camera.T_world_cam, **extra)


def write_tof_capture(capture: ToFCapture, out_dir: str | Path, *, info: dict | None = None) -> list[Path]:
    """Write a CW capture folder: ``samples/000.png ...`` (16-bit), ``tof.json``, ``rig.json``,
    ``ground_truth.npz`` (range, depth, xyz, hit, valid = hit and not mixed, mixed, T_world_cam) and
    ``preview.png`` (amplitude of the first frequency). Returns the sample paths."""
    out = Path(out_dir)
    (out / "samples").mkdir(parents=True, exist_ok=True)
    paths = []
    for k, img in enumerate(capture.samples):
        path = out / "samples" / f"{k:03d}.png"
        write_png(path, img)
        paths.append(path)
    sensor = capture.sensor
    atomic_write_json(out / "tof.json", {
        "kind": "rangekit.tof.cw/1", "plan": capture.plan.to_dict(), "n_samples": capture.plan.n_samples,
        "sample_order": "frequency-major: samples/NNN.png, all steps of frequencies_hz[0] first",
        "sample_model": "S_k = B + A cos(phi - theta_k), phi = 4 pi f r / c",
        "electrons_per_dn": sensor.electrons_per_dn, "read_noise_e": sensor.read_noise_e,
        "saturation_dn": (1 << sensor.bits) - 1, "sensor": asdict(sensor), **(info or {})})
    save_rig(Rig(cameras=(capture.camera,), devices={"camera": {"type": "sim", "sensor": "tof"}}), out / RIG_FILE)
    _truth(out, range_true=capture.range_true, depth_true=capture.depth_true, hit=capture.hit, camera=capture.camera,
           xyz=capture.xyz_true, valid=capture.hit & ~capture.mixed, mixed=capture.mixed)
    sl = capture.plan.slices()[0]
    amp = np.hypot(*(np.tensordot(np.array([np.cos(capture.plan.steps[0]), np.sin(capture.plan.steps[0])]),
                                  capture.samples[sl].astype(np.float64), axes=(1, 0))))
    write_png(out / "preview.png", _preview(np.sqrt(amp)))  # sqrt: the 1/r^2 fall-off spans ~1000x
    return paths


def write_pulsed_capture(capture: PulsedCapture, out_dir: str | Path, *, info: dict | None = None) -> Path:
    """Write a pulsed capture folder: ``round_trip_s.npy`` (seconds, NaN where nothing returned),
    ``tof.json`` (kind ``rangekit.tof.pulsed/1``), ``rig.json``, ``ground_truth.npz`` and ``preview.png``."""
    from rangekit.io import atomic_save_npy

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "round_trip_s.npy"
    atomic_save_npy(path, capture.round_trip_s)
    atomic_write_json(out / "tof.json", {"kind": "rangekit.tof.pulsed/1", "jitter_s": capture.jitter_s, **(info or {})})
    save_rig(Rig(cameras=(capture.camera,), devices={"camera": {"type": "sim", "sensor": "tof-pulsed"}}),
             out / RIG_FILE)
    _truth(out, range_true=capture.range_true, depth_true=capture.depth_true,
           xyz=range_to_points(capture.range_true, capture.camera), hit=capture.hit, camera=capture.camera,
           valid=capture.hit)
    write_png(out / "preview.png", _preview(capture.round_trip_s))
    return path
