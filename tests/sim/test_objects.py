"""Numeric checks of the procedurally built scene objects (rangekit.sim.scene.objects)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from rangekit.errors import FileFormatError, SceneError
from rangekit.geometry import apply_T, axis_angle_to_R, make_T
from rangekit.sim.scene.objects import (BUILTIN_OBJECTS, board_corners, box, calibration_board, cylinder, load_scene_object,
                                  lumpy, make_object, plane, sphere, torus, turntable_disc)
from rangekit.sim.scene.scene_object import SceneObject


def signed_volume(obj: SceneObject) -> float:
    """Divergence theorem: sum of signed tetrahedra (origin, triangle); > 0 when normals point out."""
    v = obj.vertices[obj.triangles]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def albedo_at(obj: SceneObject, xy: np.ndarray) -> np.ndarray:
    """(N,) grey albedo of a flat z=0 object at (N, 2) points (barycentric point-in-triangle test)."""
    if len(xy) > 2048:
        return np.concatenate([albedo_at(obj, xy[k:k + 2048]) for k in range(0, len(xy), 2048)])
    tri = obj.vertices[obj.triangles][:, :, :2]                         # (F, 3, 2)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    det = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]  # (F,)
    d = xy[:, None, :] - a[None]                                         # (N, F, 2)
    l1 = (d[..., 0] * (c - a)[:, 1] - d[..., 1] * (c - a)[:, 0]) / det
    l2 = ((b - a)[:, 0] * d[..., 1] - (b - a)[:, 1] * d[..., 0]) / det
    inside = (l1 >= 0) & (l2 >= 0) & (l1 + l2 <= 1)
    assert np.all(inside.any(axis=1)), "a sample point is off the board"
    face = np.argmax(inside, axis=1)
    colours = obj.vertex_albedo[obj.triangles[face]]                     # (N, 3 corners, RGB)
    assert np.all(colours == colours[:, :1, :1])                         # constant over the triangle, grey
    return colours[:, 0, 0]


# --- shapes ---------------------------------------------------------------------------------------

def test_sphere_on_radius_watertight_outward_volume():
    r = 0.05
    s = sphere(r)
    assert np.abs(np.linalg.norm(s.vertices, axis=1) - r).max() < 1e-12
    assert s.to_trimesh().is_watertight
    centroids = s.vertices[s.triangles].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", s.face_normals(), centroids) > 0)
    # documented chordal error for subdivisions=5, r=5 cm: 0.0142 mm; the facets lie inside the sphere
    n, v0 = s.face_normals(), s.vertices[s.triangles[:, 0]]
    chordal = r - np.einsum("ij,ij->i", n, v0).min()
    assert 0.0140e-3 < chordal < 0.0144e-3
    vol, e = signed_volume(s), 0.0144e-3
    assert 4 / 3 * np.pi * (r - e) ** 3 < vol < 4 / 3 * np.pi * r**3
    assert np.allclose(np.linalg.norm(s.vertex_normals(), axis=1), 1.0)
    cos = np.einsum("ij,ij->i", s.vertex_normals(), s.vertices / r)   # area-weighted vs true normal
    assert np.degrees(np.arccos(cos.min())) < 0.2


def test_box_volume_exact_and_flat_vertex_normals():
    b = box((0.1, 0.08, 0.06))
    assert b.vertices.shape == (24, 3) and b.triangles.shape == (12, 3) and not b.smooth
    assert signed_volume(b) == pytest.approx(0.1 * 0.08 * 0.06, rel=1e-12)
    assert np.allclose(np.abs(b.vertices), [0.05, 0.04, 0.03])
    fn, vn = b.face_normals(), b.vertex_normals()
    assert np.allclose(vn[b.triangles], fn[:, None, :], atol=1e-15)     # each corner has its face's normal
    assert np.allclose(np.abs(fn).max(axis=1), 1.0)                     # axis-aligned
    assert np.allclose(np.einsum("ij,ij->i", fn, b.vertices[b.triangles].mean(1)) > 0, True)


def test_cylinder_volume_flat_caps_smooth_side():
    r, h, n = 0.04, 0.1, 128
    c = cylinder(r, h, sections=n)
    vol = signed_volume(c)
    assert vol == pytest.approx(np.pi * r**2 * h, rel=5e-3)
    assert vol == pytest.approx(n / 2 * r**2 * np.sin(2 * np.pi / n) * h, rel=1e-12)  # inscribed prism
    vn = c.vertex_normals()
    cap = np.zeros(len(c.vertices), bool)
    cap[np.unique(c.triangles[2 * n:])] = True
    assert np.allclose(vn[cap], np.sign(c.vertices[cap, 2:3]) * [0, 0, 1], atol=1e-12)
    radial = np.c_[c.vertices[~cap, :2] / r, np.zeros((~cap).sum())]
    assert np.abs(vn[~cap] - radial).max() < 1e-12
    assert c.smooth and np.allclose(np.linalg.norm(c.vertices[~cap, :2], axis=1), r)
    m = c.to_trimesh()
    m.merge_vertices()
    assert m.is_watertight                                              # closed once the cap rims are welded


def test_torus_volume_and_watertight():
    R, r = 0.06, 0.02
    t = torus(R, r)
    assert signed_volume(t) == pytest.approx(2 * np.pi**2 * R * r**2, rel=5e-3)
    assert t.to_trimesh().is_watertight
    rho = np.hypot(np.linalg.norm(t.vertices[:, :2], axis=1) - R, t.vertices[:, 2])
    assert np.abs(rho - r).max() < 1e-15


def test_plane_and_turntable():
    p = plane(0.4, 0.3, subdivisions=3)
    assert np.allclose(p.face_normals(), [0, 0, 1]) and len(p.triangles) == 18
    assert p.to_trimesh().area == pytest.approx(0.12, rel=1e-12)
    d = turntable_disc(0.15, 0.02)
    assert d.name == "turntable" and d.vertices[:, 2].max() == 0.0
    assert d.vertices[:, 2].min() == pytest.approx(-0.02, abs=1e-15)
    top = d.vertices[:, 2] == 0.0
    assert np.allclose(np.linalg.norm(d.vertices[top, :2], axis=1).max(), 0.15)


# --- lumpy ----------------------------------------------------------------------------------------

def _mean_nn(a: np.ndarray, b: np.ndarray) -> float:
    return 0.5 * (cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lumpy_watertight_star_shaped_and_not_symmetric(seed):
    radius = 0.06
    obj = lumpy(radius, subdivisions=4, seed=seed)
    m = obj.to_trimesh()
    assert m.is_watertight and m.is_winding_consistent
    assert signed_volume(obj) > 0
    v = obj.vertices[obj.triangles]
    assert np.all(np.linalg.det(v) > 0)                                  # every face sees the origin inside
    r = np.linalg.norm(obj.vertices, axis=1)
    assert r.min() >= 0.4 * 0.8 * radius and r.max() > 1.2 * radius      # factor >= 0.4, smallest scale 0.8
    images = [np.diag([-1.0, 1, 1]), np.diag([1.0, -1, 1]), np.diag([1.0, 1, -1]),
              axis_angle_to_R([0, 0, 1], np.pi), axis_angle_to_R([1, 0, 0], np.pi),
              axis_angle_to_R([0, 1, 0], np.pi)]
    for M in images:
        assert _mean_nn(obj.vertices, obj.vertices @ M.T) > 0.05 * radius, M


def test_lumpy_deterministic_per_seed():
    a, b, c = lumpy(seed=3, subdivisions=3), lumpy(seed=3, subdivisions=3), lumpy(seed=4, subdivisions=3)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.triangles, b.triangles)
    assert np.abs(a.vertices - c.vertices).max() > 0.005


# --- calibration board ----------------------------------------------------------------------------

def test_board_corners_layout():
    k = board_corners(7, 9, 0.02)
    assert k.shape == (48, 3) and np.all(k[:, 2] == 0)
    assert np.allclose(k[:3], [[0, 0, 0], [0.02, 0, 0], [0.04, 0, 0]])  # x (columns) fastest
    assert np.allclose(k[8], [0, 0.02, 0]) and np.allclose(k[-1], [0.14, 0.10, 0])


def texture_at(obj: SceneObject, xy: np.ndarray) -> np.ndarray:
    """(N,) albedo of a textured z=0 object's texture at (N, 2) object-frame points."""
    img, (x0, y0, x1, y1) = obj.texture.image, obj.texture.extent
    h, w = img.shape
    assert np.all((xy >= [x0, y0]) & (xy < [x1, y1])), "a sample point is off the board"
    c = np.floor((xy[:, 0] - x0) / (x1 - x0) * w).astype(int)
    r = np.floor((xy[:, 1] - y0) / (y1 - y0) * h).astype(int)
    return img[r, c].astype(np.float64)


def test_board_checker_alternates_around_every_corner():
    rows, cols, s, m = 7, 9, 0.02, 0.01
    b = calibration_board(rows, cols, s, margin=m, dark=0.05, light=0.9)
    # one textured quad, printed side (triangle normals) towards -z, flat shaded
    assert np.allclose(b.face_normals(), [0, 0, -1]) and not b.smooth and b.texture is not None
    k = board_corners(rows, cols, s)[:, :2]
    d = s / 4
    pp, mm = texture_at(b, k + [d, d]), texture_at(b, k - [d, d])
    pm, mp = texture_at(b, k + [d, -d]), texture_at(b, k + [-d, d])
    i, j = np.divmod(np.arange(len(k)), cols - 1)
    dark_pp = (i + j) % 2 == 0                                           # square (i+1, j+1) dark iff even
    assert np.allclose(pp, np.where(dark_pp, 0.05, 0.9)) and np.all(mm == pp)
    assert np.all(pm == mp) and np.all(pm != pp)
    # exactly sharp: a point 1 um either side of a square edge changes colour (edges on texel boundaries)
    e = 1e-6
    assert np.all(texture_at(b, k + [e, d]) != texture_at(b, k + [-e, d]))
    # the light margin all round, and the board's extent
    lo, hi = b.vertices.min(0), b.vertices.max(0)
    assert np.allclose(lo, [-s - m, -s - m, 0]) and np.allclose(hi, [(cols - 1) * s + m, (rows - 1) * s + m, 0])
    assert np.allclose(b.texture.extent, [lo[0], lo[1], hi[0], hi[1]])
    border = np.array([[lo[0] + m / 2, 0.05], [hi[0] - m / 2, 0.05], [0.07, lo[1] + m / 2], [0.07, hi[1] - m / 2]])
    assert np.allclose(texture_at(b, border), 0.9)
    assert np.allclose(b.vertex_albedo, b.texture.image.mean(dtype=np.float64))  # plain grey seen from behind


def test_board_found_by_opencv_at_board_corners():
    rows, cols, s, m = 6, 9, 0.02, 0.02
    b = calibration_board(rows, cols, s, margin=m)
    px = 1e-3                                                            # orthographic view from -z, 1 mm/px
    lo, hi = b.vertices.min(0), b.vertices.max(0)
    u, v = np.meshgrid(np.arange(int((hi[0] - lo[0]) / px)), np.arange(int((hi[1] - lo[1]) / px)))
    xy = np.c_[lo[0] + (u.ravel() + 0.5) * px, lo[1] + (v.ravel() + 0.5) * px]
    img = (texture_at(b, xy).reshape(u.shape) * 255).astype(np.uint8)
    found, corners = cv2.findChessboardCorners(img, (cols - 1, rows - 1))
    assert found
    corners = cv2.cornerSubPix(img, corners, (5, 5), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3))
    uv_true = (board_corners(rows, cols, s)[:, :2] - lo[:2]) / px - 0.5
    err = np.linalg.norm(corners.reshape(-1, 2) - uv_true, axis=1)
    err_rev = np.linalg.norm(corners.reshape(-1, 2)[::-1] - uv_true, axis=1)  # OpenCV may start either end
    assert min(err.max(), err_rev.max()) < 0.2


# --- SceneObject ----------------------------------------------------------------------------------

def test_placed_on_table_and_poses():
    obj = lumpy(subdivisions=3)
    placed = obj.placed_on_table(xy=(0.1, -0.05), yaw=0.7)
    w = placed.world_vertices()
    assert w[:, 2].min() == 0.0
    assert np.allclose((w.min(0)[:2] + w.max(0)[:2]) / 2, (0.1, -0.05), atol=0.01)  # bbox rotated
    lo, hi = obj.vertices.min(0), obj.vertices.max(0)
    centre = apply_T(placed.T_world_obj, [[(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.0]])[0]
    assert np.allclose(centre[:2], (0.1, -0.05), atol=1e-15)
    R = placed.T_world_obj[:3, :3]
    assert np.allclose(R, axis_angle_to_R([0, 0, 1], 0.7), atol=1e-15)
    bx = box((0.1, 0.08, 0.06)).placed_on_table((0.2, 0.3), yaw=np.pi / 2)
    wb = bx.world_vertices()
    assert np.allclose(wb.min(0), [0.16, 0.25, 0.0]) and np.allclose(wb.max(0), [0.24, 0.35, 0.06])
    T = make_T(axis_angle_to_R([1, 2, 3], 0.4), [0.1, 0.2, 0.3])
    posed = obj.with_pose(T)
    assert np.allclose(posed.world_vertices(), apply_T(T, obj.vertices))
    tm = posed.to_trimesh()
    assert np.allclose(tm.vertices, posed.world_vertices()) and np.array_equal(tm.faces, obj.triangles)
    assert obj.T_world_obj is not posed.T_world_obj and np.array_equal(obj.T_world_obj, np.eye(4))


def test_sceneobject_copies_readonly_and_broadcasts():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    F = np.array([[0, 1, 2]], dtype=np.int32)
    obj = SceneObject("tri", V, F, (0.2, 0.4, 0.6))
    V[0, 0] = 5.0
    assert obj.vertices[0, 0] == 0.0 and obj.triangles.dtype == np.int64
    assert obj.vertex_albedo.shape == (3, 3) and np.all(obj.vertex_albedo[:, 1] == 0.4)
    with pytest.raises(ValueError):
        obj.vertices[0, 0] = 1.0
    assert SceneObject("tri", V, F, 0.5).vertex_albedo.shape == (3, 3)
    assert np.allclose(obj.face_normals(), [[0, 0, 1]]) and np.allclose(obj.vertex_normals(), [0, 0, 1])


@pytest.mark.parametrize("kwargs, found", [
    (dict(vertices=np.zeros((3, 2))), "(3, 2)"),
    (dict(vertices=np.array([[0.0, 0, 0], [1, 0, np.nan], [0, 1, 0]])), "not finite"),
    (dict(triangles=np.array([[0, 1, 3]])), "[0, 3]"),
    (dict(triangles=np.array([[0.0, 1, 2]])), "float64"),
    (dict(triangles=np.zeros((0, 3), int)), "(0, 3)"),
    (dict(vertex_albedo=1.5), "1.5"),
    (dict(vertex_albedo=np.full((4, 3), 0.5)), "(4, 3)"),
    (dict(specular=-1.0), "specular=-1.0"),
    (dict(T_world_obj=np.diag([2.0, 1, 1, 1])), "det 2"),
    (dict(T_world_obj=np.eye(3)), "(3, 3)"),
])
def test_sceneobject_validation(kwargs, found):
    args = dict(name="widget", vertices=np.eye(3), triangles=np.array([[0, 1, 2]]), vertex_albedo=0.5)
    args.update(kwargs)
    with pytest.raises(SceneError, match="widget") as info:
        SceneObject(**args)
    assert found in str(info.value)


# --- files and the registry -----------------------------------------------------------------------

def test_load_mesh_round_trip_with_colours(tmp_path):
    obj = lumpy(subdivisions=3, seed=1)
    rgb = np.random.default_rng(0).integers(0, 256, (len(obj.vertices), 3))
    src = trimesh.Trimesh(obj.vertices, obj.triangles, vertex_colors=np.c_[rgb, np.full(len(rgb), 255)],
                          process=False)
    path = tmp_path / "blob.ply"
    src.export(path)
    back = load_scene_object(path, scale=2.0)
    assert back.name == "blob" and back.triangles.shape == obj.triangles.shape
    dist, idx = cKDTree(obj.vertices * 2.0).query(back.vertices)
    assert dist.max() < 1e-7                                              # float32 in the file
    assert np.allclose(back.vertex_albedo, rgb[idx] / 255.0)
    assert signed_volume(back) == pytest.approx(8 * signed_volume(obj), rel=1e-5)
    plain = tmp_path / "plain.ply"
    trimesh.Trimesh(obj.vertices, obj.triangles, process=False).export(plain)
    assert np.all(make_object(str(plain), albedo=0.3).vertex_albedo == 0.3)
    quad = tmp_path / "quad.obj"                                          # polygons are triangulated
    quad.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    q = load_scene_object(quad, scale=0.1)
    assert q.triangles.shape == (2, 3) and np.allclose(q.face_normals(), [0, 0, 1])
    assert q.to_trimesh().area == pytest.approx(0.01)


def test_load_mesh_bad_files(tmp_path):
    with pytest.raises(FileFormatError, match="missing.ply: no such file"):
        load_scene_object(tmp_path / "missing.ply")
    garbage = tmp_path / "garbage.ply"
    garbage.write_bytes(np.random.default_rng(0).bytes(300))
    with pytest.raises(FileFormatError, match="garbage.ply: trimesh cannot read"):
        load_scene_object(garbage)
    empty = tmp_path / "empty.ply"
    trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int)).export(empty)
    with pytest.raises(FileFormatError, match="empty.ply: the mesh has 0 triangles"):
        load_scene_object(empty)
    points = tmp_path / "points.ply"
    trimesh.PointCloud(np.random.default_rng(0).random((10, 3))).export(points)
    with pytest.raises(FileFormatError, match="points.ply: the mesh has 0 triangles"):
        load_scene_object(points)


def test_make_object_builtins_and_unknown():
    assert set(BUILTIN_OBJECTS) == {"plane", "sphere", "box", "cylinder", "torus", "board", "lumpy",
                                    "bunny", "thin", "bowl", "shiny", "dark", "steps"}
    s = make_object("sphere", radius=0.03, subdivisions=2)
    assert np.allclose(np.linalg.norm(s.vertices, axis=1), 0.03)
    assert make_object("board").name == "board"
    with pytest.raises(SceneError, match="teapot") as info:
        make_object("teapot")
    assert all(k in str(info.value) for k in BUILTIN_OBJECTS)
    with pytest.raises(SceneError, match="radius must be a finite number > 0, found -1"):
        sphere(-1)
