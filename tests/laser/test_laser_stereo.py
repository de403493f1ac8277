"""Laser-sheet stereo (issue 38 item 2; rangekit.laser.sheet_stereo, sim/laser/stereo.py): a laser sheet seen by two
calibrated cameras, each left peak met with the right line on its epipolar line and triangulated by the pair,
without the laser's plane.

Against exact truth: a synthetic sheet projected without noise (the geometry alone: exact to 1e-7 m), and the
simulator's frames of the bunny (the error against the true lit curve at each left row, the distance from the
true laser plane). Then the simulated pair, the folder format's one-line errors, and the command line.
"""

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from rangekit.errors import FileFormatError, InputError
from rangekit.laser import detect_peaks, triangulate_peaks
from rangekit.laser.sheet_stereo import fit_sheet, match_sheet, sheet_stereo
from rangekit.sim import ImagingModel, default_scene
from rangekit.sim.laser.frames import LaserView
from rangekit.sim.laser.rig import laser_rig
from rangekit.sim.laser.stereo import LaserStereoView, laser_stereo_rig
from rangekit.sim.laser.truth import curve_at_rows
from rangekit.stereo.rectify import rectify

W, H = 640, 512


def _small(rig, width=W, height=H):
    return replace(rig, cameras=tuple(c.resized(width, height) for c in rig.cameras))


@pytest.fixture(scope="module")
def rig():
    return _small(laser_stereo_rig())


# ------------------------------------------------------------------ the geometry alone, exact
def _sheet_curve(rig, k=0, n=20001):
    """Dense samples of a wavy curve on laser ``k``'s plane in front of the cameras (world, metres)."""
    laser = rig.lasers[k]
    n_l = laser.plane[:3]
    up = np.array([0.0, 0.0, 1.0])
    radial = np.cross(up, n_l)
    radial *= np.sign(radial @ (laser.origin - rig.T_world_table[:3, 3]))   # towards the emitter's side
    t = np.linspace(0.01, 0.16, n)
    r = 0.04 + 0.012 * np.sin(40 * t) + 0.1 * (t - 0.08) ** 2
    P = t[:, None] * up + r[:, None] * radial
    assert np.abs(P @ n_l + laser.plane[3]).max() < 1e-12
    return P


def _row_peaks(camera, P):
    """Perfect row peaks of the curve ``P`` in ``camera``: where its projection crosses each whole row (the curve
    runs monotonically down the image), and the true 3D point there."""
    uv = camera.project(P)
    order = np.argsort(uv[:, 1])
    uv, P = uv[order], P[order]
    rows = np.arange(np.ceil(uv[0, 1]), np.floor(uv[-1, 1]) + 1).astype(np.int64)
    u = np.interp(rows, uv[:, 1], uv[:, 0])
    X = np.column_stack([np.interp(rows, uv[:, 1], P[:, j]) for j in range(3)])
    return np.column_stack([u, rows.astype(np.float64)]), rows, X


def test_perfect_peaks_give_the_true_points(rig):
    """Noise-free peaks of a known curve on the sheet, both lenses distorted: every left row whose point the right
    camera sees is matched, to 1 um of the true point (measured 0.41 um: the right line is a polyline between its
    rows, the wavy curve's chord). A wrong baseline (the right camera 1 mm off) or a right camera whose principal
    point is 0.3 px off put the points 2.6 and 0.40 mm away (medians)."""
    left, right = rig.cameras[:2]
    P = _sheet_curve(rig)
    uv_l, _, truth = _row_peaks(left, P)
    uv_r, rows_r, _ = _row_peaks(right, P)
    res = match_sheet(uv_l, uv_r, rows_r, left, right)
    ok = res.valid
    assert ok.mean() > 0.97 and res.n_ambiguous == 0 and res.n_off_sheet == 0, res
    err = np.linalg.norm(res.xyz[ok] - truth[ok], axis=1)
    assert err.max() < 1e-6, err.max()
    plane = rig.lasers[0].plane
    assert np.abs(res.xyz[ok] @ plane[:3] + plane[3]).max() < 1e-6
    for bad in (replace(right, T_world_cam=right.T_world_cam @ np.array(
            [[1, 0, 0, 1e-3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])),
            replace(right, K=right.K + np.array([[0, 0, 0.3], [0, 0, 0], [0, 0, 0]]))):
        wrong = match_sheet(uv_l, uv_r, rows_r, left, bad, check_sheet=False)
        e = np.linalg.norm(wrong.xyz[wrong.valid] - truth[wrong.valid], axis=1)
        assert np.median(e) > 1.5e-4, np.median(e)


def test_a_gap_or_a_fold_in_the_right_line_is_not_matched(rig):
    """A gap in the right line (rows without a peak) leaves the left rows there unmatched, never interpolated
    across; a right line that crosses a left row twice (the other stretch shifted along the row) is refused as
    ambiguous."""
    left, right = rig.cameras[:2]
    P = _sheet_curve(rig)
    uv_l, _, _ = _row_peaks(left, P)
    uv_r, rows_r, _ = _row_peaks(right, P)
    full = match_sheet(uv_l, uv_r, rows_r, left, right).valid.sum()
    gap = (rows_r >= rows_r[100]) & (rows_r < rows_r[110])
    res = match_sheet(uv_l, uv_r[~gap], rows_r[~gap], left, right)
    assert full - res.valid.sum() >= 9 and res.n_unmatched >= 9
    # A second stretch 40 px to the left (nearer points) on rows of its own: doubles the crossings it spans.
    extra = uv_r[200:260] - [40.0, 0.0]
    rows2 = rows_r[200:260] + 10_000          # other raw rows (not joined to the first stretch), same positions
    res = match_sheet(uv_l, np.vstack([uv_r, extra]), np.concatenate([rows_r, rows2]), left, right,
                      check_sheet=False)
    assert res.n_ambiguous >= 50, res


def test_fit_sheet_refuses_points_off_the_plane(rig):
    rng = np.random.default_rng(0)
    P = _sheet_curve(rig, n=600) + rng.normal(0, 3e-5, (600, 3))
    P[::100] += 5e-3 * rig.lasers[0].plane[:3]                    # six wrong matches, 5 mm off the sheet
    sheet = fit_sheet(P, rig.cameras[0])
    assert sheet.n_off == 6 and not sheet.on[::100].any() and sheet.on.sum() == 594
    assert abs(sheet.plane[:3] @ rig.lasers[0].plane[:3]) > 1 - 1e-6
    assert 2e-5 < sheet.sigma < 4e-5
    line = np.outer(np.linspace(0, 0.1, 50), [0, 0, 1.0]) + [0.01, 0.02, 0.0]   # one straight line: no plane
    assert fit_sheet(line, rig.cameras[0]).plane is None


# ------------------------------------------------------------------ the simulator's frames
@pytest.fixture(scope="module")
def bunny_views(rig):
    return [LaserStereoView(default_scene("bunny"), rig, np.radians(a), imaging=ImagingModel(), seed=3,
                            ambient_scale=2) for a in (30.0, 200.0)]


def test_the_left_camera_renders_the_single_camera_frames(rig):
    """The pair's left camera is the single-camera laser rig's: same frames, byte for byte."""
    mono = _small(laser_rig())
    one = LaserView(default_scene("lumpy"), mono, 0.4, imaging=ImagingModel(), seed=5, ambient_scale=4)
    two = LaserStereoView(default_scene("lumpy"), rig, 0.4, imaging=ImagingModel(), seed=5, ambient_scale=4)
    assert np.array_equal(one.frame(1).image, two.left.frame(1).image)
    assert np.array_equal(one.off(), two.left.off())
    assert not np.array_equal(two.left.off(), two.right.off())


def test_simulated_bunny_against_the_true_curve(rig, bunny_views):
    """Gaussian peaks in both cameras at 640x512 (a pixel is 0.55 mm at 0.5 m), two angles, two lasers: the points
    are on the true lit curve at their left row to 0.16 mm RMS and 0.08 mm median (measured 0.125 and 0.055; the
    single camera on the true plane, same left peaks: 0.066 and 0.033), 0.09 mm RMS from the true laser plane
    (measured 0.064), and a point for more than 90% of the rows where both cameras see the line (measured 96.6%).
    A right camera 1 mm off or its principal point 0.3 px off gives median errors of 2.6 and 0.40 mm (first test)."""
    left, right = rig.cameras[:2]
    rect = rectify(left, right)
    errors, planes, got, possible, mono = [], [], 0, 0, []
    for view in bunny_views:
        offs = view.left.off(), view.right.off()
        for k, laser in enumerate(rig.lasers):
            pl = detect_peaks(view.left.frame(k).image, offs[0])
            pr = detect_peaks(view.right.frame(k).image, offs[1])
            res = sheet_stereo(pl, pr, left, right, rect=rect)
            c = view.left.curve(k)
            true = curve_at_rows(pl.points, c.uv, c.xyz)
            ok = res.valid & np.isfinite(true[:, 0])
            errors.append(np.linalg.norm(res.xyz[ok] - true[ok], axis=1))
            one = triangulate_peaks(pl.points, left, laser).xyz
            ok = np.isfinite(one[:, 0]) & np.isfinite(true[:, 0])
            mono.append(np.linalg.norm(one[ok] - true[ok], axis=1))
            planes.append(res.points @ laser.plane[:3] + laser.plane[3])
            rows = np.unique(np.rint(c.uv[view.both(k), 1]))
            possible += len(rows)
            got += np.isin(pl.rows[res.valid], rows).sum()
    e, d, m = np.concatenate(errors), np.concatenate(planes), np.concatenate(mono)
    rms, plane_rms, share = np.sqrt(np.mean(e ** 2)), np.sqrt(np.mean(d ** 2)), got / possible
    print(f"\n{len(e)} points: RMS {rms * 1e3:.3f} mm, median {np.median(e) * 1e3:.3f} mm, off the plane RMS "
          f"{plane_rms * 1e3:.3f} mm, rows covered {share:.1%}; one camera on the true plane: RMS "
          f"{np.sqrt(np.mean(m ** 2)) * 1e3:.3f} mm, median {np.median(m) * 1e3:.3f} mm")
    assert rms < 1.6e-4 and np.median(e) < 8e-5 and plane_rms < 9e-5 and share > 0.90


def test_ridge_peaks_and_a_wrong_size_are_refused(rig, bunny_views):
    view = bunny_views[0]
    pl = detect_peaks(view.left.frame(0).image, view.left.off(), method="ridge")
    pr = detect_peaks(view.right.frame(0).image, view.right.off())
    with pytest.raises(InputError, match="ridge.*use a row method"):
        sheet_stereo(pl, pr, *rig.cameras[:2])
    with pytest.raises(InputError, match=r"right peaks were found in a 640x512 image but camera 'right' is 1280x1024"):
        sheet_stereo(pr, pr, rig.cameras[0], laser_stereo_rig().cameras[1])


# ------------------------------------------------------------------ the folder and the command line
@pytest.fixture(scope="module")
def capture(tmp_path_factory, rig):
    """``rangekit sim render --sensor laser-stereo`` of the bunny with the small rig (its rig file as --rig)."""
    from support.shared_data import require_bunny
    from rangekit.cli import main
    from rangekit.rig.rig_file import save_rig

    require_bunny()
    tmp = tmp_path_factory.mktemp("laser_stereo")
    save_rig(rig, tmp / "rig.json")
    out = tmp / "cap"
    assert main(["sim", "render", "--sensor", "laser-stereo", "--object", "bunny", "--angle-deg", "30",
                 "--rig", str(tmp / "rig.json"), "--out", str(out)]) == 0
    return out


def test_cli_render_and_reconstruct_without_laser_planes(capture, tmp_path, capsys):
    """The folder's rig file without its lasers (nothing about the planes): reconstruct triangulates by the pair,
    prints the error against the truth; the cloud is near the true curve."""
    from rangekit.cli import main
    from rangekit.formats.clouds import load_cloud

    cap = tmp_path / "cap"
    shutil.copytree(capture, cap)
    spec = json.loads((cap / "rig.json").read_text())
    spec.pop("lasers", None)
    (cap / "rig.json").write_text(json.dumps(spec))
    assert sorted(p.name for p in (cap / "right").iterdir()) == ["laser0.png", "laser1.png", "off.png"]
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "c.ply")]) == 0
    out = capsys.readouterr().out
    assert "against ground_truth.npz" in out and "laser 1:" in out, out
    P = load_cloud(tmp_path / "c.ply").points
    truth = np.load(cap / "ground_truth.npz")
    both = sum(int(truth[f"left_laser{k}_both"].any()) for k in range(2))
    assert both == 2 and len(P) > 500
    rms = float(out.split("left row RMS ")[1].split(" mm")[0])
    assert rms < 0.15, out


def test_bad_folders_are_named(capture, tmp_path, capsys):
    import cv2

    from rangekit.cli import main
    from rangekit.formats.laser_capture import load_laser_stereo_capture

    cap = tmp_path / "cap"
    shutil.copytree(capture, cap)
    img = cv2.imread(str(cap / "right" / "laser1.png"), cv2.IMREAD_UNCHANGED)
    for name in ("off.png", "laser0.png", "laser1.png"):
        cv2.imwrite(str(cap / "right" / name), cv2.resize(img, (320, 256)))
    with pytest.raises(FileFormatError, match=r"right/off.png: image is 320x256 but camera 'right' in .*rig.json is "
                                              r"640x512 \(width x height\)"):
        load_laser_stereo_capture(cap)
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "c.ply")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "right/off.png: image is 320x256" in err[0]
    shutil.rmtree(cap / "right")
    shutil.copytree(capture / "right", cap / "right")
    (cap / "right" / "laser1.png").unlink()
    with pytest.raises(FileFormatError, match=r"capture.json says 2 laser\(s\).*; missing right/laser1.png$"):
        load_laser_stereo_capture(cap)
    shutil.copy(cap / "right" / "off.png", cap / "right" / "laser1.png")   # laser 1 not seen by the right camera
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "c.ply")]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "right/laser1.png: found 0 line peaks" in err and "no laser line visible" in err, err
    (cap / "right" / "laser1.png").unlink()
    info = json.loads((cap / "capture.json").read_text())
    (cap / "capture.json").write_text(json.dumps({**info, "n_lasers": 0}))
    with pytest.raises(FileFormatError, match=r"capture.json: n_lasers: expected the number of laser frames per "
                                              r"camera, 1 to 8, found 0"):
        load_laser_stereo_capture(cap)
    spec = json.loads((capture / "rig.json").read_text())
    (cap / "capture.json").write_text(json.dumps(info))
    shutil.copy(capture / "right" / "laser1.png", cap / "right" / "laser1.png")
    (cap / "rig.json").write_text(json.dumps({**spec, "cameras": spec["cameras"][::-1]}))   # left and right swapped
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "c.ply")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("rangekit: error: ") and "rig.json: " in err[-1] and "swap left and right" in err[-1], err
    (cap / "rig.json").write_text(json.dumps({**spec, "cameras": spec["cameras"][:1]}))
    with pytest.raises(FileFormatError, match=r"rig.json: cameras: a two-camera laser capture needs the calibrated "
                                              r"pair .* found 1 camera"):
        load_laser_stereo_capture(cap)


def test_cli_render_refuses_a_rig_without_a_pair(tmp_path, capsys):
    from rangekit.cli import main
    from rangekit.rig.rig_file import save_rig

    save_rig(_small(laser_rig()), tmp_path / "one.json")
    assert main(["sim", "render", "--sensor", "laser-stereo", "--rig", str(tmp_path / "one.json"),
                 "--out", str(tmp_path / "a")]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "one.json: a two-camera laser capture needs two cameras" in err and "found 1 camera(s)" in err
    assert main(["sim", "render", "--sensor", "laser-stereo", "--patterns", "white", "--out", str(tmp_path / "b")]) == 2
    assert "--patterns: only for --sensor projector" in capsys.readouterr().err
    assert main(["reconstruct", str(tmp_path), "--pair-only", "--out", str(tmp_path / "c.ply")]) == 2
    assert "--pair-only: only for a two-camera laser capture" in capsys.readouterr().err


def test_exchanged_folders_are_caught_and_named(rig, tmp_path, capsys):
    """left/ and right/ exchanged (issue 48: 17.9 mm RMS, exit 0): the pair matches the line only the other way
    round, so the folders are taken exchanged, said in one line, and the cloud is as near the true curve."""
    from rangekit.cli import main
    from rangekit.rig.rig_file import save_rig

    save_rig(rig, tmp_path / "rig.json")
    cap = tmp_path / "cap"
    assert main(["sim", "render", "--sensor", "laser-stereo", "--angle-deg", "30", "--rig", str(tmp_path / "rig.json"),
                 "--out", str(cap)]) == 0
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "a.ply")]) == 0
    given = capsys.readouterr()
    assert "EXCHANGED" not in given.out + given.err
    (cap / "left").rename(cap / "was_left")
    (cap / "right").rename(cap / "left")
    (cap / "was_left").rename(cap / "right")
    assert main(["reconstruct", str(cap), "--out", str(tmp_path / "b.ply")]) == 0
    said = capsys.readouterr()
    assert "cameras EXCHANGED: left/ holds the rig's right camera's frames" in said.out + said.err
    rms = float(said.out.split("left row RMS ")[1].split(" mm")[0])
    assert rms < 0.15, said.out
