"""``rangekit scan --artefact vdi2634``: the VDI/VDE 2634 part 2 figures of the simulated rig.

Each artefact position (:func:`rangekit.sim.scene.artefacts.vdi2634_artefacts`) is captured once (one view,
the default hybrid coded light, the simulator's default imaging) and the same images are reconstructed
twice: with the rig file from ``rangekit calibrate`` (what a user has) and with the simulator's true rig
(what the calibration costs is the difference). Points are taken from the pixels the evaluation region
selects (:func:`evaluation_masks`, from the simulator's truth, the same pixels for both rigs: the figures
compare geometry, not segmentation), fitted, and the figures computed by :mod:`rangekit.metrology.vdi2634`
with the guideline's 0.3 % outlier rule.

Evaluation regions: a sphere's central cap, the pixels whose true point lies within 0.8 R of the axis
from the sphere's centre to the camera (80 % of its apparent diameter: the grazing rim is left out); a
plate's pixels, less a 2-pixel border (the silhouette's mixed pixels). Every pixel must be lit by the
projector and triangulated.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.errors import ConfigError
from rangekit.io import atomic_write_json
from rangekit.progress import call_progress
from rangekit.rig.rig_file import Rig, load_rig

__all__ = ["CAP_FRACTION", "OUTLIER_FRACTION", "Vdi2634Result", "run_vdi2634", "evaluation_masks", "figure_lines"]

#: A sphere's evaluation cap: the points within this fraction of R of its axis towards the camera.
CAP_FRACTION = 0.8
#: The share of each measurement's points dropped as outliers (the guideline's largest, 0.3 %).
OUTLIER_FRACTION = 0.003
_BORDER_PX = 2
RIGS = ("calibrated", "true")


@dataclass(frozen=True, eq=False)
class Vdi2634Result:
    """``report``: the dict written to vdi2634.json (figures in mm, per rig and per position)."""

    report: dict

    def figure(self, name: str, rig: str) -> float:
        """A figure in mm: ``name`` in PF, PS, SD, F; ``rig`` "calibrated" or "true"."""
        return self.report[f"{name}_mm"][rig]


def evaluation_masks(artefact, truth, camera_centre: np.ndarray) -> list[np.ndarray]:
    """(H, W) bool masks of the evaluated pixels: one per sphere of ``artefact`` (its centres' order) or
    one for a plate. ``truth`` is the view's :class:`rangekit.sim.scene.raycast.ViewGeometry` (true world frame)."""
    import cv2

    masks = []
    names = truth.object_names
    if artefact.kind == "plane":
        m = (truth.object_id == names.index("plate")) & truth.lit
        m = cv2.erode(m.astype(np.uint8), np.ones((2 * _BORDER_PX + 1,) * 2, np.uint8)).astype(bool)
        return [m]
    for name, c in zip(("sphere",) if artefact.kind == "sphere" else ("ball_a", "ball_b"), artefact.centres):
        a = camera_centre - c
        a = a / np.linalg.norm(a)
        d = truth.xyz - c
        lateral = np.linalg.norm(d - (d @ a)[..., None] * a, axis=-1)
        m = (truth.object_id == names.index(name)) & truth.lit
        masks.append(m & (lateral <= CAP_FRACTION * artefact.diameter / 2))
    return masks


def _measure(artefact, xyz: np.ndarray, masks: list[np.ndarray]) -> dict:
    """The figures of one artefact position from organised points ``xyz`` (H, W, 3) of one rig (mm)."""
    from rangekit.metrology.vdi2634 import flatness, probing, sphere_spacing

    pts = [xyz[m] for m in masks]
    pts = [p[np.isfinite(p).all(axis=1)] for p in pts]
    if artefact.kind == "plane":
        f = flatness(pts[0], outlier_fraction=OUTLIER_FRACTION, what=artefact.label)
        return {"F_mm": f.F * 1e3, "rms_mm": f.fit.rms * 1e3, "points": f.n_points, "excluded": f.n_excluded}
    res = [probing(p, artefact.diameter, outlier_fraction=OUTLIER_FRACTION, what=f"{artefact.label} sphere {i + 1}")
           for i, p in enumerate(pts)]
    if artefact.kind == "sphere":
        r = res[0]
        return {"PF_mm": r.PF * 1e3, "PS_mm": r.PS * 1e3, "rms_mm": r.fit.rms * 1e3, "points": r.n_points,
                "excluded": r.n_excluded}
    sd = sphere_spacing(res[0].fit.centre, res[1].fit.centre, artefact.length)
    return {"SD_mm": sd * 1e3, "points": [r.n_points for r in res], "excluded": [r.n_excluded for r in res]}


def _worst(values: list[float], signed: bool) -> float | None:
    """The figure over positions: the largest (PF, F), or the value of largest magnitude, sign kept (PS, SD)."""
    if not values:
        return None
    return float(max(values, key=abs)) if signed else float(max(values))


def _checked_rig(rig_file: str, true_rig: Rig) -> Rig:
    """The rig file, refused unless it has a projector and the simulated camera's size."""
    rig = load_rig(rig_file)
    if rig.projector is None or rig.camera.size != true_rig.camera.size:
        found = "no projector" if rig.projector is None else f"a {rig.camera.width}x{rig.camera.height} camera"
        raise ConfigError(f"{rig_file}: expected the simulated rig calibrated by 'rangekit calibrate' (a projector and "
                          f"a {true_rig.camera.width}x{true_rig.camera.height} camera), found {found}")
    return rig


def run_vdi2634(out: str | Path, *, rig_file: str | None = None, n_spheres: int = 10, n_bars: int = 7,
                n_planes: int = 6, seed: int = 0, progress: Callable | None = None) -> Vdi2634Result:
    """Scan the artefacts on the simulator and write ``out/vdi2634.json`` (module doc).

    ``rig_file``: a rig file from ``rangekit calibrate`` (on the simulator); None calibrates one first
    (about 4 minutes) into ``out/rig_calibrated.json``. ``n_*``: positions of each kind (the guideline's
    10, 7 and 6 by default; fewer for a quick check).
    """
    from rangekit.coded.reconstruct import reconstruct_view
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.sim import SimRig, default_rig
    from rangekit.sim.scene.artefacts import MEASURING_VOLUME, L0, artefact_sizes, vdi2634_artefacts

    out = Path(out)
    true_rig = default_rig()
    if rig_file is not None:
        cal_rig = _checked_rig(rig_file, true_rig)     # before the folder is made
    out.mkdir(parents=True, exist_ok=True)
    if rig_file is None:
        from rangekit.app.calibrate import calibrate
        from rangekit.boards import Board

        rig_file = str(out / "rig_calibrated.json")
        call_progress(progress, f"calibrating the simulated rig (rangekit calibrate) into {rig_file}")
        calibrate(rig_file, rig="sim", board=Board(kind="checkerboard", cols=10, rows=7, square=0.02), seed=seed,
                  force=True, progress=progress)
        cal_rig = _checked_rig(rig_file, true_rig)
    rigs = {"calibrated": cal_rig, "true": true_rig}
    same = json.dumps(cal_rig.to_dict(), sort_keys=True) == json.dumps(true_rig.to_dict(), sort_keys=True)
    spec = make_pattern_spec("hybrid", (true_rig.projector.width, true_rig.projector.height))
    sim = None
    artefacts = vdi2634_artefacts(true_rig, n_spheres=n_spheres, n_bars=n_bars, n_planes=n_planes)
    positions = []
    for i, art in enumerate(artefacts):
        call_progress(progress, f"{art.label} ({i + 1}/{len(artefacts)})")
        if sim is None:
            sim = SimRig(art.scene(), true_rig, seed=seed)
        else:
            sim.set_scene(art.scene())
        images = sim.capture_sequence(list(spec.frames()))
        full_scale = float((1 << sim.imaging.bits) - 1)
        masks = evaluation_masks(art, sim.ground_truth(), true_rig.camera.center)
        entry = {"label": art.label, "kind": art.kind}
        for name, rig in rigs.items():
            if name == "true" and same:
                entry[name] = entry["calibrated"]      # the rig file is the true rig: one reconstruction
                continue
            rec = reconstruct_view(images, spec, rig.camera, rig.projector, full_scale=full_scale,
                                   response=rig.projector_response)
            entry[name] = _measure(art, rec.triangulated.xyz, masks)
        positions.append(entry)
    report = _report(positions, rig_file, seed)
    sz = artefact_sizes()
    report["measuring_volume"] = {"lo_mm": (MEASURING_VOLUME[0] * 1e3).tolist(),
                                  "hi_mm": (MEASURING_VOLUME[1] * 1e3).tolist(), "L0_mm": L0 * 1e3,
                                  "frame": "world (turntable) frame of the simulated rig"}
    report["artefacts_mm"] = {k: v * 1e3 for k, v in sz.__dict__.items()}
    atomic_write_json(out / "vdi2634.json", report)
    return Vdi2634Result(report)


def _report(positions: list[dict], rig_file: str, seed: int) -> dict:
    figures = {}
    for fig, signed in (("PF", False), ("PS", True), ("SD", True), ("F", False)):
        figures[f"{fig}_mm"] = {rig: _worst([p[rig][f"{fig}_mm"] for p in positions if f"{fig}_mm" in p[rig]], signed)
                                for rig in RIGS}
    return {"kind": "rangekit.vdi2634/1", "guideline": "VDI/VDE 2634 part 2", **figures,
            "rules": {"PF": "largest over the sphere positions", "PS": "largest |PS| over the sphere positions, signed",
                      "SD": "largest |SD| over the ball bar positions, signed",
                      "F": "largest over the plane positions", "outlier_fraction": OUTLIER_FRACTION,
                      "sphere_cap": f"points within {CAP_FRACTION} R of the sphere's axis towards the camera",
                      "plate_border_px": _BORDER_PX},
            "calibrated_rig": str(rig_file), "seed": seed, "positions": positions}


def figure_lines(res: Vdi2634Result) -> list[str]:
    """The figures as a datasheet prints them, with the measuring volume and the artefacts."""
    r = res.report
    mv, a = r["measuring_volume"], r["artefacts_mm"]
    size = [h - lo for lo, h in zip(mv["lo_mm"], mv["hi_mm"])]
    lines = ["VDI/VDE 2634 part 2, simulated rig, single view, hybrid coded light",
             f"measuring volume  {size[0]:.0f} x {size[1]:.0f} x {size[2]:.0f} mm (L0 = {mv['L0_mm']:.0f} mm)",
             f"artefacts         sphere {a['sphere_diameter']:.1f} mm; ball bar {a['bar_length']:.1f} mm, balls "
             f"{a['ball_diameter']:.1f} mm; plane {a['plate_length']:.0f} x {a['plate_width']:.0f} mm",
             f"{'':34s}{'calibrated rig':>16s}{'true rig':>12s}"]
    counts = {k: sum(p["kind"] == k for p in r["positions"]) for k in ("sphere", "ballbar", "plane")}
    for key, text, n in (("PF", "probing error form PF", counts["sphere"]),
                         ("PS", "probing error size PS", counts["sphere"]),
                         ("SD", "sphere-spacing error SD", counts["ballbar"]),
                         ("F", "flatness measurement error F", counts["plane"])):
        v = r[f"{key}_mm"]
        if v["true"] is None:
            continue
        lines.append(f"{text + f' ({n} pos.)':34s}{v['calibrated']:>13.4f} mm{v['true']:>9.4f} mm")
    return lines
