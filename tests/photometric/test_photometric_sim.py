"""Photometric stereo on the simulated light stage, against its exact normals and depth."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from rangekit.photometric import (angular_error, integrate_normals, photometric_stereo,
                                  uncalibrated_photometric_stereo)
from rangekit.sim.sensors.lightstage import LIGHT_STAGE_MODEL, light_stage_lights, light_stage_scene, render_light_stage


def _inner(mask: np.ndarray, px: float) -> np.ndarray:
    """Pixels more than ``px`` from the silhouette: the lens blur (0.5 px) mixes the rim with the background."""
    return mask & (cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 3) > px)


@pytest.fixture(scope="module")
def lights():
    return light_stage_lights(96, rng=0)


def test_noiseless_lambertian_sphere(lights):
    clean = replace(LIGHT_STAGE_MODEL, full_well=0.0, read_noise=0.0, camera_blur=0.0)
    cap = render_light_stage(light_stage_scene("sphere"), lights, model=clean, specular=False, shadows=False)
    robust = photometric_stereo(cap.images, cap.lights, cap.mask, method="robust")
    e = angular_error(robust.normals, cap.normals_true, cap.mask)
    assert e.mean_deg <= 0.05, e.mean_deg                        # measured 0.0001 deg
    # Plain least squares is exact where no light is behind the surface (attached shadows clip to 0).
    lit_by_all = cap.mask & np.all(np.einsum("hwc,fc->fhw", np.nan_to_num(cap.normals_true), cap.lights) > 0, axis=0)
    ls = photometric_stereo(cap.images, cap.lights, cap.mask, method="ls")
    e_ls = angular_error(ls.normals, cap.normals_true, lit_by_all)
    assert lit_by_all.sum() > 0.5 * cap.mask.sum() and e_ls.mean_deg <= 0.05, e_ls.mean_deg
    alb = robust.albedo[cap.mask] / cap.albedo_true[cap.mask]
    assert np.abs(alb - 1).max() < 1e-3


def test_robust_beats_least_squares_with_highlights_and_cast_shadows(lights):
    scene_alone = light_stage_scene("sphere", specular=0.5, shininess=50)
    alone = render_light_stage(scene_alone, lights)
    cap = render_light_stage(light_stage_scene("sphere", occluder=True, specular=0.5, shininess=50), lights)
    sphere = alone.mask & cap.mask & (np.abs(alone.depth_true - cap.depth_true) < 1e-9)
    assert cap.cast_shadow[:, sphere].any(axis=0).mean() > 0.2      # the box shadows a good part of it
    inner = _inner(sphere, 3)
    ls = angular_error(photometric_stereo(cap.images, cap.lights, cap.mask, method="ls").normals,
                       cap.normals_true, inner).mean_deg
    rob = angular_error(photometric_stereo(cap.images, cap.lights, cap.mask, method="robust").normals,
                        cap.normals_true, inner).mean_deg
    assert ls > 3.0, ls                                            # measured 6.93 deg: the effect is there
    # measured 2.32 deg: the box's reflected light is not a cavity's, so it is no longer subtracted (issue 34;
    # subtracting it anyway gave 2.24, by chance: on the real objects it costs up to 2 deg)
    assert rob <= 0.35 * ls, (rob, ls)


def test_uncalibrated_sphere_after_the_bas_relief_ambiguity(lights):
    cap = render_light_stage(light_stage_scene("sphere"), light_stage_lights(24, rng=1), specular=False)
    res = uncalibrated_photometric_stereo(cap.images, cap.mask)
    e = angular_error(res.normals, cap.normals_true, cap.mask)
    assert e.mean_deg <= 2.0, e.mean_deg                           # measured 1.26 deg
    assert np.nanmean(res.normals[..., 2]) < 0                    # convex, facing the camera


def test_perspective_integration_of_exact_normals(lights):
    cap = render_light_stage(light_stage_scene("sphere"), lights[:3], specular=False)
    mask = _inner(cap.mask, 2)
    v, u = np.nonzero(mask)
    cut = (v < np.median(v)) & (u > np.median(u))
    mask[v[cut], u[cut]] = False                                   # a disc without a quadrant: not convex
    Z = integrate_normals(cap.normals_true, mask, camera=cap.camera,
                          median_depth=float(np.median(cap.depth_true[mask])))
    err = Z[mask] - cap.depth_true[mask]
    rms = np.sqrt(np.mean((err - err.mean()) ** 2))
    assert rms <= 0.005 * np.ptp(cap.depth_true[mask]), (rms, np.ptp(cap.depth_true[mask]))


def _write_diligent_folder(folder, cap) -> None:
    """A DiLiGenT-layout folder from a light-stage capture (DiLiGenT frame: x right, y up, z to the viewer)."""
    import scipy.io

    from rangekit.io import write_png

    folder.mkdir()
    names = []
    for i, img in enumerate(cap.images):
        names.append(f"{i + 1:03d}.png")
        grey = np.rint(np.clip(img, 0, 1) * 65535).astype(np.uint16)
        write_png(folder / names[-1], np.repeat(grey[:, :, None], 3, axis=2))
    (folder / "filenames.txt").write_text("\n".join(names) + "\n")
    flip = np.array([1.0, -1.0, -1.0])
    np.savetxt(folder / "light_directions.txt", cap.lights * flip, fmt="%.9f")
    np.savetxt(folder / "light_intensities.txt", np.ones((len(names), 3)), fmt="%.3f")
    write_png(folder / "mask.png", (cap.mask * 255).astype(np.uint8))
    scipy.io.savemat(folder / "Normal_gt.mat", {"Normal_gt": np.nan_to_num(cap.normals_true) * flip})


@pytest.mark.parametrize("method, limit", [("robust", 1.0), ("uncalibrated", 2.0)])
def test_photometric_command_on_a_simulated_folder(tmp_path, capsys, method, limit):
    from rangekit.cli import main

    cap = render_light_stage(light_stage_scene("sphere"), light_stage_lights(24, rng=2), specular=False)
    _write_diligent_folder(tmp_path / "sphere", cap)
    assert main(["photometric", str(tmp_path / "sphere"), "--method", method, "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    mean = float(out.split("angular error against Normal_gt.mat: mean ")[1].split(" deg")[0])
    assert mean <= limit, out
    n = np.load(tmp_path / "out" / "normals.npy")
    e = angular_error(n, cap.normals_true, cap.mask)
    assert abs(e.mean_deg - mean) < 1e-3          # the normals written are those measured, in our frame
    for name in ("normals.png", "albedo.png", "depth.npy", "mesh.ply"):
        assert (tmp_path / "out" / name).stat().st_size > 0
    header = (tmp_path / "out" / "mesh.ply").read_bytes().split(b"end_header")[0]
    assert b"comment rangekit mesh, pixels" in header and b"metres" not in header   # no camera: pixel units


def test_photometric_command_bad_input(tmp_path, capsys):
    from rangekit.cli import main

    (tmp_path / "empty").mkdir()
    assert main(["photometric", str(tmp_path / "empty"), "--out", str(tmp_path / "o")]) == 1
    assert "filenames.txt" in capsys.readouterr().err
