"""Issue 22, acceptance 1 and 2: every cloud and mesh format written and read back by rangekit and by the
library a user would open it with, and the public functions taking a cloud or a mesh fed each kind of
object a user already holds (arrays, rangekit, Open3D, trimesh)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import rangekit as rk
from rangekit.errors import FileFormatError, InputError
from rangekit.geometry import make_T, rotvec_to_R
from rangekit.surface.cloud import PointCloud
from rangekit.surface.mesh import TriangleMesh, distance_to_surface

o3d = pytest.importorskip("open3d")
trimesh = pytest.importorskip("trimesh")


def _lumpy(n: int = 3000, seed: int = 0) -> PointCloud:
    """Points on a lumpy sphere (radius ~0.1 m, centred away from the origin), outward unit normals and
    colours that are multiples of 1/255 (8-bit formats keep them exactly)."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = 0.1 * (1 + 0.15 * d[:, 0] * d[:, 1] + 0.1 * d[:, 2] ** 2)
    colours = rng.integers(0, 256, (n, 3)) / 255.0
    return PointCloud(d * r[:, None] + [0.3, -0.2, 0.05], colours, d, rng.random(n) * 1e-4)


def _sphere_mesh() -> TriangleMesh:
    s = o3d.geometry.TriangleMesh.create_sphere(radius=0.1, resolution=12)
    colours = np.random.default_rng(1).integers(0, 256, (len(s.vertices), 3)) / 255.0
    return TriangleMesh(np.asarray(s.vertices) + [0.3, -0.2, 0.05], np.asarray(s.triangles), colours)


# --------------------------------------------------------------------------------------- clouds

# suffix: (tolerance in metres, kept colours, kept normals, kept sigma)
CLOUD_FORMATS = {".ply": (0.0, True, True, True), ".pcd": (1e-6, True, True, True), ".npy": (0.0, True, True, False),
                 ".xyz": (1e-9, False, True, False), ".e57": (1e-6, True, False, False)}


@pytest.mark.parametrize("suffix", list(CLOUD_FORMATS))
def test_cloud_round_trip_by_rangekit(tmp_path, suffix):
    tol, colours, normals, sigma = CLOUD_FORMATS[suffix]
    cloud = _lumpy()
    path = tmp_path / f"cloud{suffix}"
    rk.save_cloud(path, cloud)
    back = rk.load_cloud(path)
    np.testing.assert_allclose(back.points, cloud.points, rtol=0, atol=max(tol, 1e-15))
    if colours:
        np.testing.assert_allclose(back.colours, cloud.colours, rtol=0, atol=1e-6)
    if normals:
        np.testing.assert_allclose(back.normals, cloud.normals, rtol=0, atol=1e-6 if suffix in (".ply", ".pcd") else 1e-9)
    if sigma:
        np.testing.assert_allclose(back.sigma, cloud.sigma, rtol=1e-6)
    assert not list(tmp_path.glob(".*.tmp"))


def _points_by_peer(path):
    """The points of ``path`` as the library a user opens that format with reads them."""
    suffix = path.suffix
    if suffix == ".ply":
        import plyfile

        v = plyfile.PlyData.read(str(path))["vertex"]
        return np.column_stack([v["x"], v["y"], v["z"]])
    if suffix in (".pcd", ".xyz"):
        return np.asarray(o3d.io.read_point_cloud(str(path)).points)
    if suffix == ".npy":
        return np.load(path)[:, :3]
    import pye57

    with pye57.E57(str(path)) as e57:
        scan = e57.read_scan(0)   # pye57's defaults: the pose applied
    return np.column_stack([scan["cartesianX"], scan["cartesianY"], scan["cartesianZ"]])


@pytest.mark.parametrize("suffix", list(CLOUD_FORMATS))
def test_cloud_written_by_rangekit_read_by_its_library(tmp_path, suffix):
    cloud = _lumpy()
    path = tmp_path / f"cloud{suffix}"
    rk.save_cloud(path, cloud)
    tol = CLOUD_FORMATS[suffix][0]
    np.testing.assert_allclose(_points_by_peer(path), cloud.points, rtol=0, atol=max(tol, 1e-15))


def test_ply_read_by_open3d_with_normals_and_colours(tmp_path):
    cloud = _lumpy()
    rk.save_cloud(tmp_path / "c.ply", cloud)
    pc = o3d.io.read_point_cloud(str(tmp_path / "c.ply"))
    np.testing.assert_array_equal(np.asarray(pc.points), cloud.points)
    np.testing.assert_allclose(np.asarray(pc.normals), cloud.normals, atol=1e-6)
    np.testing.assert_allclose(np.asarray(pc.colors), cloud.colours, atol=1e-6)


def test_pcd_and_e57_written_by_their_library_read_by_rangekit(tmp_path):
    import pye57

    cloud = _lumpy()
    pc = rk.to_open3d(cloud)
    assert o3d.io.write_point_cloud(str(tmp_path / "o3d.pcd"), pc)  # float32 coordinates
    np.testing.assert_allclose(rk.load_cloud(tmp_path / "o3d.pcd").points, cloud.points, rtol=0, atol=1e-6)
    with pye57.E57(str(tmp_path / "two.e57"), mode="w") as e57:  # two scans, the second placed by a pose
        half = len(cloud) // 2
        for part, t in ((cloud.points[:half], np.zeros(3)), (cloud.points[half:], np.array([1.0, 2.0, 3.0]))):
            e57.write_scan_raw({f"cartesian{c}": (part - t)[:, i].copy() for i, c in enumerate("XYZ")},
                               rotation=np.array([1.0, 0, 0, 0]), translation=t)
    np.testing.assert_allclose(rk.load_cloud(tmp_path / "two.e57").points, cloud.points, rtol=0, atol=1e-6)


def test_e57_error_names_the_file(tmp_path):
    (tmp_path / "bad.e57").write_bytes(b"not an e57 file")
    with pytest.raises(FileFormatError, match=r"bad\.e57: expected an E57 file"):
        rk.load_cloud(tmp_path / "bad.e57")


# --------------------------------------------------------------------------------------- meshes

@pytest.mark.parametrize("suffix", [".ply", ".obj", ".stl", ".glb"])
def test_mesh_round_trip_by_rangekit_and_trimesh(tmp_path, suffix):
    mesh = _sphere_mesh()
    path = tmp_path / f"mesh{suffix}"
    rk.save_mesh(path, mesh)
    tol = {".ply": 0.0, ".obj": 1e-9, ".stl": 1e-6, ".glb": 1e-6}[suffix]  # STL and GLB: float32
    truth = mesh.vertices[mesh.triangles]   # (F, 3, 3): STL keeps triangles, not shared vertices
    for back in (rk.load_mesh(path), rk.as_mesh(trimesh.load(path, process=False, force="mesh"))):
        np.testing.assert_allclose(back.vertices[back.triangles], truth, rtol=0, atol=max(tol, 1e-15))
        if suffix != ".stl":
            np.testing.assert_array_equal(back.triangles, mesh.triangles)
            np.testing.assert_allclose(back.vertex_colours, mesh.vertex_colours, atol=1e-6)


def test_mesh_ply_has_vertex_normals_open3d_reads(tmp_path):
    mesh = _sphere_mesh()
    rk.save_mesh(tmp_path / "m.ply", mesh)
    m = o3d.io.read_triangle_mesh(str(tmp_path / "m.ply"))
    assert m.has_vertex_normals()
    np.testing.assert_array_equal(np.asarray(m.vertices), mesh.vertices)
    outward = mesh.vertices - [0.3, -0.2, 0.05]
    outward /= np.linalg.norm(outward, axis=1, keepdims=True)
    assert np.all(np.sum(np.asarray(m.vertex_normals) * outward, axis=1) > 0.98)  # a sphere's normals


def test_off_mesh_written_by_trimesh_reads(tmp_path):
    mesh = _sphere_mesh()
    (tmp_path / "m.off").write_text(trimesh.exchange.off.export_off(mesh.to_trimesh(), digits=15))
    back = rk.load_mesh(tmp_path / "m.off")
    np.testing.assert_allclose(back.vertices, mesh.vertices, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(back.triangles, mesh.triangles)


# ------------------------------------------------------------------------- the objects users hold

def _cloud_kinds(cloud: PointCloud) -> dict:
    with_normals = np.hstack([cloud.points, cloud.normals]) if cloud.normals is not None else cloud.points
    return {"array": with_normals, "rangekit": cloud, "open3d": rk.to_open3d(cloud),
            "trimesh": trimesh.PointCloud(cloud.points)}


def _mesh_kinds(mesh: TriangleMesh) -> dict:
    return {"pair": (mesh.vertices, mesh.triangles), "rangekit": mesh, "open3d": mesh.to_open3d(),
            "trimesh": mesh.to_trimesh()}


@pytest.mark.parametrize("kind", ["array", "rangekit", "open3d", "trimesh"])
def test_icp_accepts_each_kind(kind):
    target = _lumpy(1500)
    T = make_T(rotvec_to_R(np.array([0.02, -0.01, 0.03])), np.array([0.003, -0.002, 0.001]))
    source = PointCloud((target.points - T[:3, 3]) @ T[:3, :3])   # target = T @ source exactly
    options = rk.IcpOptions(method="point_to_point", max_distance=0.02)
    src = _cloud_kinds(source)[kind]
    tgt = _cloud_kinds(PointCloud(target.points))[kind]
    res = rk.icp(src, tgt, options=options)
    np.testing.assert_allclose(res.T_target_source, T, atol=1e-6)


@pytest.mark.parametrize("kind", ["array", "rangekit", "open3d", "trimesh"])
def test_register_views_accepts_each_kind(kind):
    base = _lumpy(2000)
    poses = [np.eye(4), make_T(rotvec_to_R(np.array([0, 0, 0.5])), np.array([0.01, 0, 0])),
             make_T(rotvec_to_R(np.array([0.3, 0, 0])), np.array([0, 0.02, 0]))]
    # (the radial normals of _lumpy are not the surface's: leave them out, register_views estimates them)
    views = [PointCloud((base.points - T[:3, 3]) @ T[:3, :3]) for T in poses]
    prior = np.stack([T @ make_T(rotvec_to_R(np.array([0.01, -0.01, 0.005])), np.full(3, 0.001)) if i else T
                      for i, T in enumerate(poses)])
    res = rk.register_views([_cloud_kinds(v)[kind] for v in views], init_T_world_view=prior)
    for got, want in zip(res.T_world_view, poses):
        np.testing.assert_allclose(got, want, atol=1e-5)


@pytest.mark.parametrize("kind", ["array", "rangekit", "open3d", "trimesh_mesh"])
def test_poisson_mesh_accepts_each_kind(kind):
    cloud = _lumpy(4000)
    x = _mesh_kinds(_sphere_mesh())["trimesh"] if kind == "trimesh_mesh" else _cloud_kinds(cloud)[kind]
    mesh = rk.poisson_mesh(x, depth=5)
    centre = np.array([0.3, -0.2, 0.05])
    r = np.linalg.norm(mesh.vertices - centre, axis=1)
    assert mesh.is_watertight and 0.08 < r.min() and r.max() < 0.125   # the lumpy sphere's radii: 0.085-0.12


def test_poisson_mesh_trimesh_cloud_without_normals_is_a_clear_error():
    with pytest.raises(InputError, match="no normals"):  # trimesh.PointCloud carries no normals
        rk.poisson_mesh(trimesh.PointCloud(_lumpy().points))


@pytest.mark.parametrize("kind", ["array", "rangekit", "open3d", "trimesh"])
def test_render_accepts_each_cloud_kind(kind):
    cloud = PointCloud(_lumpy(2000).points)
    want = rk.render(cloud, size=(64, 48)).image
    got = rk.render(_cloud_kinds(cloud)[kind] if kind != "array" else cloud.points, size=(64, 48))
    assert not got.is_mesh and got.n_points == len(cloud)
    np.testing.assert_array_equal(got.image, want)


@pytest.mark.parametrize("kind", ["pair", "rangekit", "open3d", "trimesh"])
def test_render_accepts_each_mesh_kind(tmp_path, kind):
    mesh = TriangleMesh(_sphere_mesh().vertices, _sphere_mesh().triangles)
    rk.save_mesh(tmp_path / "m.ply", mesh)
    want = rk.render(tmp_path / "m.ply", size=(64, 48)).image   # the file, as `rangekit render` reads it
    got = rk.render(_mesh_kinds(mesh)[kind], size=(64, 48))
    assert got.is_mesh and got.n_points == len(mesh.vertices)
    np.testing.assert_array_equal(got.image, want)
    assert got.image.std() > 0   # not a blank picture


@pytest.mark.parametrize("bad, found", [("scan.ply", "builtins.str"), ({"points": 1}, "builtins.dict"),
                                        (np.zeros((5, 4)), r"shape \(5, 4\)")])
def test_anything_else_is_an_input_error_naming_the_type(bad, found):
    with pytest.raises(InputError, match=f"icp source: expected .* found .*{found}"):
        rk.icp(bad, _lumpy(100).points)
    with pytest.raises(InputError, match=f"register_views clouds\\[1\\]: expected .* found .*{found}"):
        rk.register_views([_lumpy(100), bad])
    with pytest.raises(InputError, match=f"poisson_mesh cloud: expected .* found .*{found}"):
        rk.poisson_mesh(bad)
    with pytest.raises(InputError, match="render x: expected"):
        rk.render(bad if not isinstance(bad, str) else 3.5)
    with pytest.raises(InputError, match="mesh: expected .* found .*PointCloud"):
        rk.as_mesh(rk.to_open3d(_lumpy(10)))


def test_conversions_both_ways():
    cloud, mesh = _lumpy(50), _sphere_mesh()
    back = rk.from_open3d(rk.to_open3d(cloud))
    np.testing.assert_array_equal(back.points, cloud.points)
    np.testing.assert_allclose(back.normals, cloud.normals)
    np.testing.assert_allclose(back.colours, cloud.colours, atol=1e-7)
    back = rk.from_trimesh(rk.to_trimesh(cloud))
    np.testing.assert_array_equal(back.points, cloud.points)
    np.testing.assert_allclose(back.colours, cloud.colours, atol=1e-6)
    for m in (rk.from_open3d(rk.to_open3d(mesh)), rk.from_trimesh(rk.to_trimesh(mesh)),
              rk.from_trimesh(trimesh.Scene([rk.to_trimesh(mesh)]))):
        np.testing.assert_array_equal(m.vertices, mesh.vertices)
        np.testing.assert_array_equal(m.triangles, mesh.triangles)
    assert distance_to_surface(mesh.vertices, mesh).max() == 0


def test_import_rangekit_stays_light():
    code = ("import sys, rangekit as rk; heavy = [m for m in ('open3d', 'trimesh', 'scipy', 'rangekit.formats', "
            "'rangekit.surface') if m in sys.modules]; assert not heavy, heavy; "
            "from rangekit.formats.clouds import load_cloud; assert rk.load_cloud is load_cloud; "
            "assert {'icp', 'register_views', 'poisson_mesh', 'render', 'load_mesh'} <= set(dir(rk))")
    subprocess.run([sys.executable, "-c", code], check=True)


# ------------------------------------------------- scan / process: --format and merged.ply's view field

def test_merged_ply_view_field_read_by_plyfile(tmp_path):
    import plyfile

    from rangekit.surface.cloud import merge_clouds, view_index

    views = [_lumpy(30, seed=k) for k in range(3)]
    merged = merge_clouds(views, np.stack([np.eye(4)] * 3))
    rk.save_cloud(tmp_path / "merged.ply", merged, fields={"view": view_index(views)})
    v = plyfile.PlyData.read(str(tmp_path / "merged.ply"))["vertex"].data
    assert v.dtype["view"] == np.dtype("<u2")
    np.testing.assert_array_equal(v["view"], np.repeat([0, 1, 2], 30))
    np.testing.assert_array_equal(rk.load_cloud(tmp_path / "merged.ply").points, merged.points)
    with pytest.raises(FileFormatError, match=r"merged\.pcd: extra point fields \(view\) are written to '\.ply' only"):
        rk.save_cloud(tmp_path / "merged.pcd", merged, fields={"view": view_index(views)})
    with pytest.raises(InputError, match=r"PLY field 'view': expected a \(90,\) array"):
        rk.save_cloud(tmp_path / "merged.ply", merged, fields={"view": np.zeros(5, np.uint16)})


@pytest.mark.parametrize("fmt", ["obj", "stl", "glb"])
def test_meshes_are_written_beside_the_ply_files_in_another_format(tmp_path, fmt):
    from rangekit.app.process.fused_outputs import save_one
    from rangekit.formats.sessions.files import MESH_FILE, WATERTIGHT_FILE

    mesh = _sphere_mesh()
    save_one(tmp_path, mesh, "poisson", MESH_FILE, fmt)
    info = save_one(tmp_path, mesh, "poisson", WATERTIGHT_FILE, fmt)
    assert info.file == WATERTIGHT_FILE and (tmp_path / MESH_FILE).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([MESH_FILE, WATERTIGHT_FILE, f"mesh.{fmt}",
                                                                 f"mesh_watertight.{fmt}"])
    back = trimesh.load(tmp_path / f"mesh_watertight.{fmt}", process=False, force="mesh")
    np.testing.assert_allclose(back.vertices[back.faces], mesh.vertices[mesh.triangles], rtol=0, atol=1e-6)
    (tmp_path / "ply").mkdir()
    save_one(tmp_path / "ply", mesh, "poisson", MESH_FILE)
    assert [p.name for p in (tmp_path / "ply").iterdir()] == [MESH_FILE]


def test_format_option_refuses_other_formats_before_any_work(tmp_path, capsys):
    from rangekit.cli import main

    with pytest.raises(SystemExit) as stop:   # argparse's choices: exit 2 before anything is read
        main(["process", str(tmp_path / "no-session"), "--format", "pcd"])
    assert stop.value.code == 2
    assert "--format: invalid choice: 'pcd' (choose from 'ply', 'obj', 'stl', 'glb')" in capsys.readouterr().err
