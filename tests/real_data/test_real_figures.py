"""Guard rails on real data (issue 34): today's figures on the real scans in ../shared/data, pinned.

Each figure below is what the code measured when it was pinned; a change that makes one worse by more
than its noise (``MARGIN``: the computations are deterministic, the margin covers another machine's
floating point) fails ``make test-slow``. Better figures pass: pin them again here and add a row to the
history in docs/benchmarks.md ("Real-data figures"). Every test skips cleanly without the data.

- Stanford bunny (10 scans) and dragon (15 scans on a turntable), registered with no initial guess,
  against the authors' ``.conf`` alignment (poses in the first scan's frame).
- DiLiGenT ball: robust photometric stereo's mean angular error against the true normals.
- SLStudio's skull (issue 35): ``rangekit rig import`` of its calibration.xml, ``rangekit reconstruct`` of its
  Gray-code and 2x3 folders, against the authors' own cloud (pointCloud.mat): the share of their points
  farther than 0.5 mm from rangekit's cloud, the median distance, the roughness, and the Gray-code cloud's
  distance to the 2x3's.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from rangekit.formats.poses import load_poses
from rangekit.formats.stanford_conf import load_stanford_conf
from rangekit.metrology.pose_errors import pose_errors
from rangekit.sim.scene.zoo import data_folders

pytestmark = pytest.mark.slow

MARGIN = 1.10   # a pinned figure may grow by 10% (plus TINY) before the suite fails
TINY = 1e-3     # degrees or mm: below what any of these figures can resolve

# figure: (pinned value, unit). Registration: worst and mean rotation error (deg), worst translation (mm).
PINNED = {
    "bunny": {"worst_deg": 0.341, "mean_deg": 0.172, "worst_mm": 0.798},
    "dragon": {"worst_deg": 0.637, "mean_deg": 0.329, "worst_mm": 2.702},
    "diligent_ball": {"robust_mean_deg": 1.969},
    "skull_graycode": {"missed_share": 0.0393, "median_mm": 0.0228, "roughness_mm": 0.0612},
    "skull_2x3": {"missed_share": 0.0380, "median_mm": 0.0505},
    "skull_modulated": {"missed_share": 0.1354, "median_mm": 0.0505},
    "skull_3ps": {"missed_share": 0.6420, "median_mm": 0.7225},
    "skull_agreement": {"graycode_to_2x3_mm": 0.0619},
}


def _folder(name: str, marker: str):
    folder = next((f / name for f in data_folders() if (f / name / marker).is_file()), None)
    if folder is None:
        pytest.skip(f"{name}/{marker} is not in {[str(f) for f in data_folders()]}")
    return folder


def check_pinned(set_name: str, measured: dict) -> None:
    """Every figure of ``set_name`` at most its pinned value times MARGIN (plus TINY); lower is better."""
    print(f"\n{set_name}: " + ", ".join(f"{k} {v:.4f} (pinned {PINNED[set_name][k]:.4f})" for k, v in measured.items()))
    worse = {k: v for k, v in measured.items() if v > PINNED[set_name][k] * MARGIN + TINY}
    assert not worse, f"{set_name} got worse than its pinned figures {PINNED[set_name]}: {worse}"


def _register_against_conf(cli, tmp_path, folder, conf_name: str) -> dict:
    """``rangekit register FOLDER/*.ply --init none`` (shell order), then the poses against the .conf."""
    names, T_conf = load_stanford_conf(folder / conf_name)
    scans = sorted(folder.glob("*.ply"), key=lambda p: p.name)
    scans = [p for p in scans if p.name in names]
    run = cli("register", *scans, "--init", "none", "--no-mesh", "--out", tmp_path / "reg")
    assert run.code == 0, run.err
    sources, T = load_poses(tmp_path / "reg" / "poses.json")
    truth = T_conf[[names.index(p.name) for p in scans]]
    rot, tr = pose_errors(T, truth)
    views = json.loads((tmp_path / "reg" / "poses.json").read_text())["views"]
    assert all(v["edges"] >= 1 for v in views)
    return {"worst_deg": float(rot.max()), "mean_deg": float(rot.mean()), "worst_mm": float(tr.max() * 1e3)}


def test_bunny_registers_without_a_guess_as_well_as_pinned(cli, tmp_path):
    folder = _folder("stanford-bunny", "bun.conf")
    check_pinned("bunny", _register_against_conf(cli, tmp_path, folder, "bun.conf"))


def test_dragon_registers_without_a_guess_as_well_as_pinned(cli, tmp_path):
    """Issue 34's command: 15 turntable scans, no guess; acceptance worst <= 1 deg and 4 mm, mean <= 0.5 deg."""
    folder = _folder("stanford-dragon", "dragonStandRight.conf")
    measured = _register_against_conf(cli, tmp_path, folder, "dragonStandRight.conf")
    assert measured["worst_deg"] <= 1.0 and measured["worst_mm"] <= 4.0 and measured["mean_deg"] <= 0.5, measured
    check_pinned("dragon", measured)


def test_diligent_ball_robust_error_as_pinned():
    from rangekit.photometric import angular_error, photometric_stereo
    from rangekit.photometric.diligent import load_diligent

    ball = load_diligent(_folder("diligent-ball", "filenames.txt"))
    rob = photometric_stereo(ball.images, ball.lights, ball.mask, method="robust")
    error = angular_error(rob.normals, ball.normals_gt, ball.mask).mean_deg
    assert error <= 2.0, error   # issue 34's acceptance
    check_pinned("diligent_ball", {"robust_mean_deg": float(error)})


def _peer_cloud(tmp_path, codec: str, folder, calibration):
    """SLStudio's own decoder and triangulator, ported (../shared/peers/slstudio_decode.py: run, never copied),
    on the same capture and calibration: its points in millimetres; None without the peers folder."""
    import subprocess
    import sys

    from rangekit.formats.clouds import load_cloud

    peer = next((f.parent / "peers" / "slstudio_decode.py" for f in data_folders()
                 if (f.parent / "peers" / "slstudio_decode.py").is_file()), None)
    if peer is None:
        return None
    out = tmp_path / f"peer_{codec}.ply"
    subprocess.run([sys.executable, str(peer), codec, str(folder), str(calibration), str(out)], check=True,
                   capture_output=True, timeout=300)
    return np.asarray(load_cloud(out).points, dtype=np.float64)


#: SLStudio's capture folders, their presets and SLStudio's name of the codec (the peer's argument).
SKULL_CODECS = {"skull_gray": ("slstudio:graycode", "gray"), "skull_2x3": ("slstudio:2x3", None),
                "skull_modulatedps": ("slstudio:modulated", "modulated"), "skull_3ps": ("slstudio:3ps", "3ps")}


def test_slstudio_skull_agrees_with_the_authors_cloud(cli, tmp_path):
    """Issues 35 and 47 on SLStudio's own data: ``rangekit rig import`` of its calibration.xml (the projector's
    distortion left out, as SLStudio triangulates) and ``rangekit reconstruct`` of its four codecs' folders,
    against the authors' cloud (pointCloud.mat), each measured as SLStudio's own decoder (ported) is, by one
    rule: each of the authors' points to the plane of its 8 nearest points of a cloud (missed where the 8th is
    over 1 mm away, or the plane over 0.5 mm). Roughness: the RMS residual of a plane through all of a cloud's
    points within 2 mm of the same 4000 of the authors' points (no cap: the same patch for every cloud).

    Issue 47's goals: Gray code 95% within 0.5 mm, median <= 0.035 mm, 3x their points, no rougher than theirs;
    modulated 77% and 0.10 mm; 3-step 35% and 0.75 mm. Measured (and the port's): Gray 96.1%, 0.023 mm, 3.96x,
    roughness 0.0612 mm against their 0.0627 (96.0%, 0.031 mm, 4.37x, 0.206 mm);
    modulated 86.5%, 0.051 mm (74.9%, 0.065); 3-step 35.8%, 0.72 mm (35.9%, 0.72); 2x3 96.2%, 0.051 mm."""
    import scipy.io

    from rangekit.formats.clouds import load_cloud
    from rangekit.metrology.cloud_compare import distances_to_local_planes, distances_to_nearest_planes, roughness

    skull = _folder("slstudio-skull", "calibration/calibration.xml")
    calibration = skull / "calibration" / "calibration.xml"
    run = cli("rig", "import", calibration, "--out", tmp_path / "rig.json")
    assert run.code == 0, run.err
    clouds, peers = {}, {}
    for folder, (preset, codec) in SKULL_CODECS.items():
        if not (skull / folder).is_dir():
            continue
        run = cli("reconstruct", skull / folder, "--pattern", preset, "--rig", tmp_path / "rig.json",
                  "--out", tmp_path / f"{folder}.ply")
        assert run.code == 0, run.err
        clouds[folder] = np.asarray(load_cloud(tmp_path / f"{folder}.ply").points) * 1000     # millimetres
        if codec is not None:
            peers[folder] = _peer_cloud(tmp_path, codec, skull / folder, calibration)
    ref = scipy.io.loadmat(skull / "skull_gray" / "pointCloud.mat")["xyz"].reshape(-1, 3)
    ref = ref[np.isfinite(ref).all(axis=1)]
    at = ref[np.random.default_rng(0).choice(len(ref), 4000, replace=False)]
    theirs = float(np.nanmedian(roughness(ref, at, 2.0)))

    def measure(cloud):
        d = distances_to_nearest_planes(ref, cloud, k=8, max_radius=1.0)
        return {"missed_share": float(np.mean(~(d < 0.5))), "median_mm": float(np.median(np.where(np.isnan(d), np.inf, d))),
                "roughness_mm": float(np.nanmedian(roughness(cloud, at, 2.0))), "density": len(cloud) / len(ref)}

    figures = {folder: measure(cloud) for folder, cloud in clouds.items()}
    peer_figures = {folder: measure(cloud) for folder, cloud in peers.items() if cloud is not None}
    gray, phase = clouds["skull_gray"], clouds["skull_2x3"]
    sample = gray[np.random.default_rng(1).choice(len(gray), 50000, replace=False)]
    agree = float(np.nanmedian(distances_to_local_planes(sample, phase, 1.0)))
    print(f"\nskull: {figures}\nSLStudio's decoder, ported: {peer_figures}\nthe authors' roughness {theirs:.4f} mm")
    g, p = figures["skull_gray"], figures["skull_2x3"]
    assert g["density"] >= 3 and g["missed_share"] <= 0.05 and g["median_mm"] <= 0.035
    assert g["roughness_mm"] <= 1.00 * theirs        # issue 47: no rougher than theirs (0.98x)
    assert p["missed_share"] <= 0.05 and p["median_mm"] <= 0.15 and agree <= 0.10
    if "skull_modulatedps" in figures:
        m = figures["skull_modulatedps"]
        assert m["missed_share"] <= 0.23 and m["median_mm"] <= 0.10
        check_pinned("skull_modulated", {k: m[k] for k in PINNED["skull_modulated"]})
    if "skull_3ps" in figures:
        t = figures["skull_3ps"]
        assert t["missed_share"] <= 0.65 and t["median_mm"] <= 0.75
        check_pinned("skull_3ps", {k: t[k] for k in PINNED["skull_3ps"]})
    if "skull_gray" in peer_figures:                  # closer to the authors' than SLStudio's own decoder (0.74x)
        assert g["median_mm"] <= 0.85 * peer_figures["skull_gray"]["median_mm"]
    check_pinned("skull_graycode", {k: g[k] for k in PINNED["skull_graycode"]})
    check_pinned("skull_2x3", {k: p[k] for k in PINNED["skull_2x3"]})
    check_pinned("skull_agreement", {"graycode_to_2x3_mm": agree})
