"""VDI/VDE 2634-2 on the simulator: the artefacts and their measuring volume, the evaluation regions against
the exact truth, and ``rangekit scan --artefact vdi2634`` (fast: one ball bar position with the true rig;
slow: the guideline's positions with a rig from ``rangekit calibrate``)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from rangekit.app.scan.vdi2634 import evaluation_masks
from rangekit.cli.run import main
from rangekit.metrology import fit_plane_lsq, fit_sphere, flatness, probing, sphere_spacing
from rangekit.rig.rig_file import save_rig
from rangekit.sim import cast_view, default_rig
from rangekit.sim.scene.objects import sphere
from rangekit.sim.scene.artefacts import (GUIDELINE_POSITIONS, L0, MEASURING_VOLUME, SPHERE_SUBDIVISIONS, artefact_sizes,
                                    vdi2634_artefacts)


def _corners(lo, hi) -> np.ndarray:
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def test_measuring_volume_is_seen_by_camera_and_projector():
    rig = default_rig()
    C = _corners(*MEASURING_VOLUME)
    for cam in (rig.camera, rig.projector):
        uv = cam.project(C)
        assert uv.min() >= 20 and np.all(uv[:, 0] <= cam.width - 20) and np.all(uv[:, 1] <= cam.height - 20), cam.name
    assert L0 == pytest.approx(0.3)


def test_artefacts_follow_the_guideline_sizes_and_lie_in_the_volume():
    sz = artefact_sizes()
    assert 0.1 * L0 <= sz.sphere_diameter <= 0.2 * L0 and 0.1 * L0 <= sz.ball_diameter <= 0.2 * L0
    assert sz.bar_length >= 0.3 * L0 and sz.plate_length >= 0.5 * L0
    arts = vdi2634_artefacts(default_rig())
    counts = tuple(sum(a.kind == k for a in arts) for k in ("sphere", "ballbar", "plane"))
    assert counts == GUIDELINE_POSITIONS == (10, 7, 6)
    lo, hi = MEASURING_VOLUME
    for a in arts:
        V = np.concatenate([o.world_vertices() for o in a.objects])
        assert np.all(V >= lo - 1e-12) and np.all(V <= hi + 1e-12), a.label
        if a.kind == "ballbar":
            assert np.linalg.norm(a.centres[1] - a.centres[0]) == pytest.approx(sz.bar_length, abs=1e-12)
        if a.kind == "plane":
            # Every vertex of the plate on the plane of its corners, and the corners 180 x 45 mm apart.
            n = fit_plane_lsq(a.corners).plane
            assert np.abs(V @ n[:3] + n[3]).max() < 1e-12
            assert np.linalg.norm(a.corners[1] - a.corners[0]) == pytest.approx(sz.plate_length, abs=1e-12)
    # The sphere positions are distinct (corners, centre, bottom centre).
    c = np.array([a.centres[0] for a in arts if a.kind == "sphere"])
    assert len(np.unique(np.round(c, 6), axis=0)) == 10


def _facet_depth(radius: float) -> float:
    """The largest distance of the simulator's sphere facets inside the true sphere (the foot of the
    perpendicular from the centre to each facet's plane lies in the facet of a near-equilateral mesh)."""
    s = sphere(1.0, subdivisions=SPHERE_SUBDIVISIONS)
    V = s.vertices[s.triangles]
    n = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return radius * (1.0 - np.abs(np.einsum("ij,ij->i", n, V[:, 0])).min())


def test_evaluation_regions_give_the_truth_on_exact_points():
    """The true surface points of each region fitted: sphere diameter, form and ball bar length within the
    tessellation's facet depth (1.6 um on the 45 mm sphere), a flat plate F ~ 0. A 320 x 256 camera (the
    same lens) keeps it fast."""
    rig = default_rig()
    cam = rig.camera.resized(320, 256)
    for a in vdi2634_artefacts(rig, n_spheres=1, n_bars=1, n_planes=1):
        truth = cast_view(a.scene().world_mesh(), cam, rig.projector)
        masks = evaluation_masks(a, truth, cam.center)
        depth = _facet_depth(a.diameter / 2) if a.diameter else 0.0
        if a.kind == "sphere":
            assert 1.0e-6 < depth < 2.0e-6
            res = probing(truth.xyz[masks[0]], a.diameter)
            assert masks[0].sum() > 500
            assert -2 * depth <= res.PS <= 0.0 and res.PF <= depth
            assert np.linalg.norm(res.fit.centre - a.centres[0]) < depth
            # The cap: no point farther than 0.8 R from the axis towards the camera.
            ax = cam.center - a.centres[0]
            ax /= np.linalg.norm(ax)
            d = truth.xyz[masks[0]] - a.centres[0]
            assert np.linalg.norm(d - (d @ ax)[:, None] * ax, axis=1).max() <= 0.8 * a.diameter / 2
        elif a.kind == "ballbar":
            fits = [fit_sphere(truth.xyz[m]) for m in masks]
            assert abs(sphere_spacing(fits[0].centre, fits[1].centre, a.length)) < depth
        else:
            assert masks[0].sum() > 500 and flatness(truth.xyz[masks[0]]).F < 1e-9


def test_scan_artefact_cli_one_ball_bar_with_the_true_rig(tmp_path):
    rig_file = tmp_path / "true_rig.json"
    save_rig(default_rig(), rig_file)
    out = tmp_path / "vdi"
    assert main(["scan", "--artefact", "vdi2634", "--out", str(out), "--rig", str(rig_file),
                 "--positions", "0", "1", "0"]) == 0
    rep = json.loads((out / "vdi2634.json").read_text())
    assert rep["PF_mm"] == {"calibrated": None, "true": None} and rep["F_mm"]["true"] is None
    sd = rep["SD_mm"]
    # The rig file is the true rig: both columns are the same reconstruction; SD within the 0.05 mm.
    assert sd["calibrated"] == sd["true"] and abs(sd["true"]) <= 0.05
    assert rep["measuring_volume"]["L0_mm"] == pytest.approx(300.0)
    assert len(rep["positions"]) == 1 and rep["positions"][0]["kind"] == "ballbar"


@pytest.mark.parametrize("argv, message", [
    (["--views", "3"], "--views: not used by --artefact"),
    (["--positions", "11", "0", "0"], "sphere positions must be in 0..10"),
    (["--positions", "0", "0", "0"], "at least one artefact position"),
    (["--rig", "NOPE.json"], "no such file"),
])
def test_scan_artefact_usage_errors(tmp_path, capsys, argv, message):
    assert main(["scan", "--artefact", "vdi2634", "--out", str(tmp_path / "o"), *argv]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_scan_artefact_refuses_a_rig_without_projector(tmp_path, capsys):
    rig_file = tmp_path / "no_projector.json"
    save_rig(replace(default_rig(), projector=None), rig_file)
    assert main(["scan", "--artefact", "vdi2634", "--out", str(tmp_path / "o"), "--rig", str(rig_file)]) == 1
    assert "found no projector" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_positions_without_artefact_is_refused(tmp_path, capsys):
    assert main(["scan", "--out", str(tmp_path / "o"), "--positions", "1", "1", "1"]) == 2
    assert "--artefact vdi2634" in capsys.readouterr().err


@pytest.mark.slow
def test_vdi2634_with_a_calibrated_rig(tmp_path):
    """The issue's run: calibrate (about 4 min), the guideline's 23 positions; SD <= 0.05 mm calibrated."""
    out = tmp_path / "vdi"
    assert main(["scan", "--artefact", "vdi2634", "--out", str(out)]) == 0
    rep = json.loads((out / "vdi2634.json").read_text())
    assert (out / "rig_calibrated.json").is_file()
    assert abs(rep["SD_mm"]["calibrated"]) <= 0.05 and abs(rep["SD_mm"]["true"]) <= 0.05
    for key in ("PF_mm", "PS_mm", "F_mm"):
        assert rep[key]["calibrated"] is not None and rep[key]["true"] is not None
    assert rep["PF_mm"]["true"] < 0.2 and abs(rep["PS_mm"]["true"]) < 0.05 and rep["F_mm"]["true"] < 0.2
