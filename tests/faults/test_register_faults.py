"""``register`` refuses or flags pairs whose overlap does not fix the pose: two caps of one
sphere, two patches of a plane, of a cylinder or of a surface of revolution slide on each other, so any
pose along the free motions fits; with ``--init none`` that is an error naming the views and the free
motion (no poses written), with a prior the prior is kept along the free motions and the edge is flagged.
Good pairs (the lumpy test object) still register to the truth.

The scans are sampled on analytic surfaces with exact normals and a known pose, so every case is fast.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.errors import RegistrationError
from rangekit.formats.clouds import save_cloud
from rangekit.formats.poses import load_poses, save_poses
from rangekit.geometry import apply_T, axis_angle_to_R, invert_T, make_T, rotation_angle
from rangekit.registration.multiview import register_views
from rangekit.registration.stability import MIN_CONSTRAINT, pose_constraint
from rangekit.surface.cloud import PointCloud

# The true pose of scan b in scan a's frame (p_a = T_TRUE @ p_b): 20 degrees and a few mm.
T_TRUE = make_T(axis_angle_to_R([0.2, 1.0, 0.3], np.radians(20)), [0.01, -0.02, 0.005])
CENTRE = np.array([0.01, 0.02, 0.3])


def _unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _surface(kind: str, n: int, rng):
    """(points, normals) on an analytic surface about CENTRE, z its axis, metres."""
    if kind == "sphere":
        nn = _unit(rng.normal(size=(n, 3)))
        return CENTRE + 0.05 * nn, nn
    if kind == "plane":
        p = np.c_[rng.uniform(-0.08, 0.08, (n, 2)), np.zeros(n)]
        return CENTRE + p, np.tile([0.0, 0.0, 1.0], (n, 1))
    a, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(-0.06, 0.06, n)
    if kind == "cylinder":
        r, dr = np.full(n, 0.03), np.zeros(n)
    else:  # a vase: radius 30 mm + 10 mm sin(30 z)
        r, dr = 0.03 + 0.01 * np.sin(30 * z), 0.3 * np.cos(30 * z)
    return CENTRE + np.c_[r * np.cos(a), r * np.sin(a), z], _unit(np.c_[np.cos(a), np.sin(a), -dr])


def _lumpy(n: int, rng):
    import trimesh

    from rangekit.sim.scene.objects import lumpy

    tm = lumpy().to_trimesh()
    p, f = trimesh.sample.sample_surface(tm, n, seed=int(rng.integers(1 << 30)))
    return CENTRE + p, tm.face_normals[f]


def _pair(kind: str, n: int = 6000, seed: int = 0):
    """Two overlapping scans a, b of one surface; b in its own frame (p_a = T_TRUE @ p_b)."""
    rng = np.random.default_rng(seed)
    p, nn = _lumpy(2 * n, rng) if kind == "lumpy" else _surface(kind, 2 * n, rng)
    # Split along x with an overlap of about a third of the extent.
    x = (p[:, 0] - CENTRE[0]) / np.ptp(p[:, 0])
    a, b = x > -0.2, x < 0.2
    inv = invert_T(T_TRUE)
    return (PointCloud(p[a], normals=nn[a]),
            PointCloud(apply_T(inv, p[b]), normals=nn[b] @ inv[:3, :3].T))


def _write(tmp_path, clouds):
    paths = []
    for k, c in enumerate(clouds):
        paths.append(tmp_path / f"scan{k}.ply")
        save_cloud(paths[-1], c)
    return paths


def _errors(T, T_true):
    return np.degrees(rotation_angle(T[:3, :3] @ T_true[:3, :3].T)), float(np.linalg.norm(T[:3, 3] - T_true[:3, 3]))


# --------------------------------------------------------------------------- the constraint analysis
@pytest.mark.parametrize("kind, n_free, words", [
    ("sphere", 3, "rotation about any axis through (10.0, 20.0, 300.0) mm"),
    ("plane", 3, "translation in the plane normal to (0.00, 0.00, 1.00)"),
    ("cylinder", 2, "translation along (0.00, 0.00, 1.00)"),
    ("revolution", 1, "rotation about (0.00, 0.00, 1.00) through (10.0, 20.0,"),
    ("lumpy", 0, ""),
])
def test_the_constraint_matrix_names_the_free_motions(kind, n_free, words):
    rng = np.random.default_rng(1)
    p, n = _lumpy(20000, rng) if kind == "lumpy" else _surface(kind, 20000, rng)
    c = pose_constraint(p, n)
    assert len(c.unconstrained()) == n_free, c.eigenvalues
    assert words in c.describe()
    if n_free == 0:
        assert c.ratio > 20 * MIN_CONSTRAINT and c.describe() == ""
    else:
        assert c.eigenvalues[n_free] > 0.05  # the constrained ones are well above the threshold


# --------------------------------------------------------------------------- --init none: refused
@pytest.mark.parametrize("kind, mentions", [
    ("sphere", ["ambiguous", "rotation about any axis through (10.0, 20.0, 300.0) mm", "unconstrained"]),
    ("plane", ["ambiguous", "translation in the plane normal to (0.00, 0.00, 1.00)"]),
    ("cylinder", ["ambiguous", "rotation about (0.00, 0.00, 1.00)", "translation along (0.00, 0.00, 1.00)"]),
    ("revolution", ["ambiguous", "rotation about (0.00, 0.00, 1.00)"]),
])
def test_an_ambiguous_pair_is_an_error_and_writes_no_poses(cli, tmp_path, kind, mentions):
    paths = _write(tmp_path, _pair(kind))
    out = tmp_path / "reg"
    run = cli("register", *paths, "--init", "none", "--no-mesh", "--out", out)
    assert_error(run, 1, "views [[1]]", "scan1.ply", "--init", *mentions)
    assert not out.exists()
    assert sorted(q.name for q in tmp_path.iterdir()) == ["scan0.ply", "scan1.ply"]  # nothing half-written


def test_sphere_halves_library_error_names_the_views():
    a, b = _pair("sphere")
    with pytest.raises(RegistrationError, match=r"views \[\[1\]\] \(left.ply\).*edge 0-1 ambiguous: rotation about any"):
        register_views([a, b], names=["right.ply", "left.ply"])


def test_scans_that_do_not_overlap_are_an_error(cli, tmp_path):
    # Two disjoint thirds of the lumpy object: nothing to register.
    rng = np.random.default_rng(2)
    p, nn = _lumpy(12000, rng)
    x = (p[:, 0] - CENTRE[0]) / np.ptp(p[:, 0])
    a, b = x > 0.15, x < -0.15
    inv = invert_T(T_TRUE)
    paths = _write(tmp_path, [PointCloud(p[a], normals=nn[a]),
                              PointCloud(apply_T(inv, p[b]), normals=nn[b] @ inv[:3, :3].T)])
    run = cli("register", *paths, "--no-mesh", "--out", tmp_path / "reg")
    assert_error(run, 1, "do not all overlap", "views [[1]]", "scan1.ply")
    assert not (tmp_path / "reg").exists()


def test_a_view_that_cannot_be_registered_is_named_and_the_others_are_written(cli, tmp_path):
    """Giving up on one view keeps the rest: 3 overlapping scans and a sphere cap that matches none of them."""
    a, b = _pair("lumpy")
    rng = np.random.default_rng(5)
    p, nn = _lumpy(6000, rng)
    T_c = make_T(axis_angle_to_R([1.0, 0.2, 0.0], np.radians(15)), [0.0, 0.01, -0.01])   # p_a = T_c @ p_c
    inv = invert_T(T_c)
    c = PointCloud(apply_T(inv, p), normals=nn @ inv[:3, :3].T)
    sp, sn = _surface("sphere", 4000, rng)
    paths = _write(tmp_path, [a, b, c, PointCloud(sp + [0.3, 0.0, 0.0], normals=sn)])
    out = tmp_path / "reg"
    run = cli("register", *paths, "--init", "none", "--no-mesh", "--out", out)
    assert_error(run, 1, "views [[3]]", "scan3.ply", "Wrote the other 3 views", f"--neighbours 0 --out {out}-all")
    sources, T = load_poses(out / "poses.json")
    assert [s.rsplit("/", 1)[-1] for s in sources] == ["scan0.ply", "scan1.ply", "scan2.ply"]
    for k, truth in ((1, T_TRUE), (2, T_c)):
        rot, tr = _errors(T[k], truth)
        assert rot < 0.05 and tr < 1e-4, (k, rot, tr)
    assert (out / "merged.ply").is_file() and not (out / "mesh.ply").exists()


def test_too_few_points_after_downsampling_is_an_error(cli, tmp_path):
    paths = _write(tmp_path, _pair("lumpy", n=3000))
    run = cli("register", *paths, "--no-mesh", "--voxel-mm", "60", "--out", tmp_path / "reg")
    assert_error(run, 1, "scan0.ply", "60 mm voxels", "expected at least 30", "--voxel-mm")
    assert not (tmp_path / "reg").exists()


# --------------------------------------------------------------------------- good pairs still register
def test_a_lumpy_pair_registers_to_the_truth(cli, tmp_path):
    paths = _write(tmp_path, _pair("lumpy"))
    out = tmp_path / "reg"
    run = cli("register", *paths, "--no-mesh", "--out", out)
    assert run.code == 0, run.err
    sources, T = load_poses(out / "poses.json")
    rot, tr = _errors(T[1], T_TRUE)
    assert rot < 0.05 and tr < 1e-4, (rot, tr)
    views = json.loads((out / "poses.json").read_text())["views"]
    assert views[1]["prior_kept"] == [] and "ambiguous" not in run.out


# --------------------------------------------------------------------------- a prior is kept along the free motions
def _prior(T_err):
    """Poses prior: view 1 at the truth composed with ``T_err`` (applied in view 0's frame)."""
    return np.stack([np.eye(4), T_err @ T_TRUE])


def _about_centre(axis, deg, shift=(0.0, 0.0, 0.0)):
    R = axis_angle_to_R(np.asarray(axis, float), np.radians(deg))
    return make_T(R, CENTRE - R @ CENTRE + np.asarray(shift))


def test_sphere_prior_keeps_the_rotation_and_fixes_the_translation():
    a, b = _pair("sphere")
    # The prior is 7 deg off about the sphere's centre (the data cannot tell) and 3 mm off (it can).
    err = _about_centre([0.3, -0.5, 0.8], 7.0, shift=[0.003, -0.002, 0.001])
    res = register_views([a, b], init_T_world_view=_prior(err))
    expected = _about_centre([0.3, -0.5, 0.8], 7.0) @ T_TRUE  # the prior's rotation, the true centre
    rot, tr = _errors(res.T_world_view[1], expected)
    assert rot < 0.01 and tr < 5e-5, (rot, tr)
    assert _errors(res.T_world_view[1], T_TRUE)[0] > 6.9  # the ambiguity stays visible: not the truth
    (edge,) = res.edges
    assert edge.accepted and edge.reason.startswith("prior kept along: rotation about any axis through")


def test_cylinder_prior_keeps_the_free_motions_and_fixes_the_rest():
    a, b = _pair("cylinder")
    # Off by 5 deg about the axis and 4 mm along it (free), and 2 deg / 2 mm across it (constrained).
    free = _about_centre([0, 0, 1], 5.0, shift=[0.0, 0.0, 0.004])
    fixed = _about_centre([1, 0, 0], 2.0, shift=[0.002, 0.0, 0.0])
    res = register_views([a, b], init_T_world_view=_prior(fixed @ free))
    rot, tr = _errors(res.T_world_view[1], free @ T_TRUE)
    # Kept to second order: the 2 deg correction times the 4 mm free offset is 0.14 mm (not kept: 4 mm, 5 deg).
    assert rot < 0.02 and tr < 3e-4, (rot, tr)
    assert _errors(res.T_world_view[1], T_TRUE)[0] > 4.9
    (edge,) = res.edges
    assert "rotation about (0.00, 0.00, 1.00)" in edge.unconstrained and "translation along (0.00, 0.00, 1.00)" \
        in edge.unconstrained


def test_a_lumpy_prior_is_corrected_in_every_direction():
    a, b = _pair("lumpy")
    err = _about_centre([0.3, -0.5, 0.8], 3.0, shift=[0.002, -0.001, 0.001])
    res = register_views([a, b], init_T_world_view=_prior(err))
    rot, tr = _errors(res.T_world_view[1], T_TRUE)
    assert rot < 0.05 and tr < 1e-4, (rot, tr)
    assert all(not e.unconstrained for e in res.edges)


def test_cli_with_a_prior_flags_the_ambiguous_edge(cli, tmp_path):
    paths = _write(tmp_path, _pair("revolution"))
    save_poses(tmp_path / "prior.json", [p.name for p in paths], _prior(_about_centre([0, 0, 1], 4.0)))
    out = tmp_path / "reg"
    run = cli("register", *paths, "--init", tmp_path / "prior.json", "--no-mesh", "--out", out)
    assert run.code == 0, run.err
    assert "1 accepted edges are ambiguous" in run.out and "prior kept along: rotation about (0.00, 0.00, 1.00)" in run.out
    views = json.loads((out / "poses.json").read_text())["views"]
    assert views[1]["prior_kept"] and "rotation about (0.00, 0.00, 1.00)" in views[1]["prior_kept"][0]
    _, T = load_poses(out / "poses.json")
    rot, tr = _errors(T[1], _about_centre([0, 0, 1], 4.0) @ T_TRUE)
    assert rot < 0.02 and tr < 1e-4, (rot, tr)


def test_three_sphere_caps_with_a_prior_keep_every_orientation():
    """The joint refinement holds each view's free rotations (the intersection over its pairs)."""
    rng = np.random.default_rng(3)
    p, nn = _surface("sphere", 18000, rng)
    dirs = [np.array([np.cos(a), np.sin(a), 0.0]) for a in (0.0, 2.1, 4.2)]
    Ts = [np.eye(4), T_TRUE, _about_centre([1, 1, 0], 30.0, shift=[0.01, 0, 0])]
    clouds = []
    for d, T in zip(dirs, Ts):
        m = nn @ d > -0.35
        inv = invert_T(T)
        clouds.append(PointCloud(apply_T(inv, p[m]), normals=nn[m] @ inv[:3, :3].T))
    errs = [np.eye(4), _about_centre([0, 0, 1], 6.0, shift=[0.002, 0, 0]), _about_centre([1, 0, 0], -4.0)]
    res = register_views(clouds, init_T_world_view=np.stack([E @ T for E, T in zip(errs, Ts)]))
    for k in (1, 2):
        R_kept = _about_centre(*(([0, 0, 1], 6.0) if k == 1 else ([1, 0, 0], -4.0))) @ Ts[k]
        rot, tr = _errors(res.T_world_view[k], R_kept)
        assert rot < 0.01 and tr < 5e-5, (k, rot, tr)
    assert all(e.accepted and e.unconstrained for e in res.edges)


def test_a_view_holds_only_the_motions_all_its_pairs_leave_free():
    from rangekit.registration.joint import _held_basis
    from rangekit.registration.stability import HeldMotions

    rot = np.hstack([np.eye(3) * 0.05, np.zeros((3, 3))])        # rotations about CENTRE (L = 50 mm)
    three, two = HeldMotions(rot, CENTRE, 0.05), HeldMotions(rot[:2], CENTRE, 0.05)
    B = _held_basis(2, {1: [three, two]}, CENTRE, 0.05)
    assert B.shape == (6, 4)                                   # rotations about x and y held, z kept free
    assert np.allclose(B[:2], 0) and np.linalg.matrix_rank(B[2:]) == 4
    assert _held_basis(2, {1: [HeldMotions(rot[:1], CENTRE, 0.05), HeldMotions(rot[1:2], CENTRE, 0.05)]},
                       CENTRE, 0.05) is None                   # no motion is free for both pairs
