"""Point cloud readers: round trips through the writers, files written by Open3D, the Stanford range
grids, and clean errors on bad files."""

from pathlib import Path

import numpy as np
import pytest

from rangekit.errors import FileFormatError
from rangekit.formats.clouds import CLOUD_READERS, CLOUD_WRITERS, load_cloud, load_range_grid, save_cloud
from rangekit.surface.cloud import PointCloud



def _cloud(n=50, *, normals=True, colours=True, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-0.3, 0.3, (n, 3))
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    rgb = rng.random((n, 3))
    return PointCloud(points, colours=rgb if colours else None, normals=nrm if normals else None)


def _quantised(colours):
    return np.rint(np.asarray(colours, dtype=np.float64) * 255) / 255


# ------------------------------------------------------------------------------------ round trips

# (suffix, points atol, normals atol, keeps colours): .ply stores float64 points, float32 normals and
# uint8 colours; .xyz is text with 9 significant digits and no colours; .npy stores float64.
FORMATS = [(".ply", 1e-12, 1e-7, True), (".xyz", 1e-9, 1e-8, False), (".npy", 1e-12, 1e-12, True)]


@pytest.mark.parametrize("suffix, tol_points, tol_normals, keeps_colours", FORMATS)
@pytest.mark.parametrize("normals, colours", [(False, False), (True, False), (False, True), (True, True)])
def test_round_trip(tmp_path, suffix, tol_points, tol_normals, keeps_colours, normals, colours):
    cloud = _cloud(normals=normals, colours=colours)
    path = tmp_path / f"cloud{suffix}"
    save_cloud(path, cloud)
    back = load_cloud(path)
    assert len(back) == len(cloud)
    np.testing.assert_allclose(back.points, cloud.points, rtol=0, atol=tol_points)
    if normals:
        np.testing.assert_allclose(back.normals, cloud.normals, rtol=0, atol=tol_normals)
    else:
        assert back.normals is None
    if colours and keeps_colours:
        expected = _quantised(cloud.colours) if suffix == ".ply" else cloud.colours
        np.testing.assert_allclose(back.colours, expected, rtol=0, atol=1e-6)
    else:
        assert back.colours is None


def test_ply_written_a_chunk_at_a_time_is_the_whole_cloud_written_at_once(tmp_path):
    """save_cloud writes a PLY's records a chunk at a time (a merged cloud is 86 MB of records): the bytes
    must be those of one structured array of every point, whatever the chunk, fields and sigma included."""
    import io

    from rangekit.formats.ply_write import _ply_header, _vertex_records, write_cloud_ply

    cloud = _cloud(normals=True, colours=True)
    cloud = PointCloud(cloud.points, cloud.colours, cloud.normals, np.linspace(1e-5, 2e-5, len(cloud)))
    view = (np.arange(len(cloud)) % 5).astype(np.uint16)
    rec = _vertex_records(cloud.points, cloud.normals, cloud.colours, cloud.sigma, extra={"view": view})
    whole = _ply_header("rangekit point cloud, metres", rec.dtype, len(rec)) + rec.tobytes()
    for chunk in (1, 7, len(cloud) - 1, len(cloud), 1 << 18):
        out = io.BytesIO()
        write_cloud_ply(out, cloud, {"view": view}, chunk=chunk)
        assert out.getvalue() == whole, chunk
    save_cloud(tmp_path / "c.ply", cloud, fields={"view": view})
    assert (tmp_path / "c.ply").read_bytes() == whole


def test_every_writer_has_a_reader():
    assert set(CLOUD_WRITERS) <= set(CLOUD_READERS)


def test_non_finite_points_are_dropped(tmp_path):
    cloud = _cloud(10)
    points = cloud.points.copy()
    points[[2, 7], [0, 2]] = [np.nan, np.inf]
    for suffix in (".ply", ".npy", ".xyz"):
        save_cloud(tmp_path / f"c{suffix}", PointCloud(points, normals=cloud.normals))
        back = load_cloud(tmp_path / f"c{suffix}")
        keep = np.ones(10, bool)
        keep[[2, 7]] = False
        np.testing.assert_allclose(back.points, points[keep], atol=1e-9)
        np.testing.assert_allclose(back.normals, cloud.normals[keep], atol=1e-7)


def test_xyz_and_txt_with_comments(tmp_path):
    text = "# scan 3, metres\n0.1 0.2 0.3\n\n  # another comment\n-1 2e-3 4\n"
    for name in ("a.xyz", "a.TXT"):
        (tmp_path / name).write_text(text)
        np.testing.assert_array_equal(load_cloud(tmp_path / name).points, [[0.1, 0.2, 0.3], [-1, 2e-3, 4]])


# ------------------------------------------------------------------------------ Open3D-written files


@pytest.fixture(scope="module")
def o3d_cloud():
    o3d = pytest.importorskip("open3d")
    cloud = _cloud(200, seed=3)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points))
    pc.normals = o3d.utility.Vector3dVector(cloud.normals)
    pc.colors = o3d.utility.Vector3dVector(cloud.colours.astype(np.float64))
    return o3d, pc, cloud


@pytest.mark.parametrize("ascii", [True, False])
def test_ply_written_by_open3d(tmp_path, o3d_cloud, ascii):
    o3d, pc, cloud = o3d_cloud
    path = tmp_path / "o3d.ply"
    assert o3d.io.write_point_cloud(str(path), pc, write_ascii=ascii)
    back = load_cloud(path)
    # Open3D's ASCII PLY keeps 6 significant digits; its binary PLY stores doubles.
    tol = 1e-6 if ascii else 1e-12
    np.testing.assert_allclose(back.points, cloud.points, rtol=tol, atol=tol)
    np.testing.assert_allclose(back.normals, cloud.normals, rtol=tol, atol=tol)
    np.testing.assert_allclose(back.colours, _quantised(cloud.colours), atol=1e-6)


@pytest.mark.parametrize("ascii", [True, False])
def test_pcd_written_by_open3d(tmp_path, o3d_cloud, ascii):
    o3d, pc, cloud = o3d_cloud
    path = tmp_path / "o3d.pcd"
    assert o3d.io.write_point_cloud(str(path), pc, write_ascii=ascii)
    back = load_cloud(path)
    # Open3D's PCD stores float32 coordinates and a packed uint32 rgb.
    np.testing.assert_allclose(back.points, cloud.points, rtol=0, atol=1e-7)
    np.testing.assert_allclose(back.normals, cloud.normals, rtol=0, atol=1e-7)
    np.testing.assert_allclose(back.colours, _quantised(cloud.colours), atol=1e-6)


def test_pcd_binary_compressed_written_by_open3d(tmp_path, o3d_cloud):
    o3d, pc, cloud = o3d_cloud
    path = tmp_path / "packed.pcd"
    assert o3d.io.write_point_cloud(str(path), pc, write_ascii=False, compressed=True)
    assert b"DATA binary_compressed" in path.read_bytes()[:400]
    back = load_cloud(path)  # LZF body read through open3d.io; float32 coordinates as Open3D writes them
    np.testing.assert_allclose(back.points, cloud.points, rtol=0, atol=1e-7)
    np.testing.assert_allclose(back.normals, cloud.normals, rtol=0, atol=1e-7)
    np.testing.assert_allclose(back.colours, _quantised(cloud.colours), atol=1e-6)
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    with pytest.raises(FileFormatError, match=r"packed\.pcd: header declares \d+ points but Open3D read 0"):
        load_cloud(path)


def test_pcd_ascii_float_rgb_and_nan_rows(tmp_path):
    # PCL's classic layout: rgb as a float holding the bits of 0x00RRGGBB; NaN rows of an organised cloud.
    rgb = np.array([0x00FF8000, 0x000000FF], dtype=np.uint32).view(np.float32)
    text = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
            "WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n"
            f"0.5 0.25 1 {rgb[0]:.9g}\nnan nan nan 0\n-1 2 3 {rgb[1]:.9g}\n")
    (tmp_path / "pcl.pcd").write_text(text)
    back = load_cloud(tmp_path / "pcl.pcd")
    np.testing.assert_array_equal(back.points, [[0.5, 0.25, 1], [-1, 2, 3]])
    np.testing.assert_allclose(back.colours, [[1, 128 / 255, 0], [0, 0, 1]], atol=1e-7)


# ------------------------------------------------------------------------- PLY layouts and elements


def _ply_bytes(fmt, elements, *, obj_info=()):
    """A PLY file from [(name, [(type or 'list <ct> <it>', prop name)], rows)] (rows: list of tuples)."""
    head = ["ply", f"format {fmt} 1.0", *[f"obj_info {k} {v}" for k, v in obj_info]]
    body = b""
    bo = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    codes = {"uchar": "u1", "int": "i4", "float": "f4", "double": "f8", "ushort": "u2"}
    for name, props, rows in elements:
        head.append(f"element {name} {len(rows)}")
        head += [f"property {t} {p}" for t, p in props]
        for row in rows:
            if bo is None:
                body += (" ".join(str(v) for v in _flatten(row)) + "\n").encode()
                continue
            for (t, _), v in zip(props, row):
                if t.startswith("list"):
                    _, ct, it = t.split()
                    body += np.array(len(v), bo + codes[ct]).tobytes() + np.array(v, bo + codes[it]).tobytes()
                else:
                    body += np.array(v, bo + codes[t]).tobytes()
    return ("\n".join(head + ["end_header"]) + "\n").encode() + body


def _flatten(row):
    for v in row:
        if isinstance(v, (list, tuple)):
            yield len(v)
            yield from v
        else:
            yield v


VERTS = [(0.1, 0.2, 0.3, 255, 0, 10), (-0.5, 1e-3, 2.0, 0, 128, 255), (1.0, -1.0, 0.25, 1, 2, 3),
         (0.0, 0.0, 0.0, 9, 9, 9)]
VERTEX_PROPS = [("double", "x"), ("double", "y"), ("double", "z"), ("uchar", "red"), ("uchar", "green"),
                ("uchar", "blue")]


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("faces", [[(0, 1, 2), (0, 2, 3)], [(0, 1, 2), (0, 1, 2, 3), ()]],
                         ids=["triangles", "mixed"])
def test_ply_elements_before_and_after_vertices_are_skipped(tmp_path, fmt, faces):
    face_rows = [(f, 7) for f in faces]  # a list property followed by a scalar one
    face = ("face", [("list uchar int", "vertex_indices"), ("ushort", "flags")], face_rows)
    camera = ("camera", [("float", "fx"), ("float", "fy")], [(500.0, 501.0)])
    path = tmp_path / "mesh.ply"
    edge = ("edge", face[1], face_rows)  # element names are unique in a PLY file (plyfile refuses repeats)
    path.write_bytes(_ply_bytes(fmt, [camera, face, ("vertex", VERTEX_PROPS, VERTS), edge]))
    back = load_cloud(path)
    np.testing.assert_allclose(back.points, np.array(VERTS)[:, :3], rtol=0, atol=1e-15)
    np.testing.assert_allclose(back.colours, np.array(VERTS)[:, 3:] / 255, atol=1e-7)
    assert back.normals is None


def test_ascii_ply_with_crlf_blank_lines_and_normals(tmp_path):
    text = ("ply\r\nformat ascii 1.0\r\ncomment normals\r\nelement vertex 3\r\nproperty float x\r\n"
            "property float y\r\nproperty float z\r\nproperty float nx\r\nproperty float ny\r\n"
            "property float nz\r\nend_header\r\n1 2 3 0 0 1 \r\n\r\n4 5 6 0 1 0\r\n  7 8 9 1 0 0\r\n")
    (tmp_path / "n.ply").write_bytes(text.encode())
    back = load_cloud(tmp_path / "n.ply")
    np.testing.assert_array_equal(back.points, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    np.testing.assert_array_equal(back.normals, [[0, 0, 1], [0, 1, 0], [1, 0, 0]])


def _synthetic_grid(fmt, *, with_nan=False):
    rows, cols = 3, 4
    cells = [5, -1, 0, 1, -1, -1, 2, 3, 4, -1, -1, 6]  # vertex index per cell, row-major
    verts = [(0.01 * i, -0.02 * i, 0.5 + 0.001 * i) for i in range(7)]
    if with_nan:
        verts[2] = (float("nan"), 0.0, 0.0)
    grid_rows = [([c] if c >= 0 else [],) for c in cells]
    data = _ply_bytes(fmt, [("vertex", [("float", "x"), ("float", "y"), ("float", "z")], verts),
                            ("range_grid", [("list uchar int", "vertex_indices")], grid_rows)],
                      obj_info=[("is_cyberware_data", 1), ("num_cols", cols), ("num_rows", rows)])
    return data, np.array(cells).reshape(rows, cols), np.array(verts)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_range_grid_synthetic(tmp_path, fmt):
    data, cells, verts = _synthetic_grid(fmt)
    (tmp_path / "scan.ply").write_bytes(data)
    points, grid = load_range_grid(tmp_path / "scan.ply")
    np.testing.assert_array_equal(grid, cells)
    np.testing.assert_allclose(points, verts, atol=1e-7)
    assert len(load_cloud(tmp_path / "scan.ply")) == 7


def test_range_grid_drops_non_finite_vertices_and_renumbers(tmp_path):
    data, cells, verts = _synthetic_grid("binary_little_endian", with_nan=True)
    (tmp_path / "scan.ply").write_bytes(data)
    points, grid = load_range_grid(tmp_path / "scan.ply")
    assert len(points) == 6 and grid[0, 2] == 0 and grid[1, 2] == -1
    valid = grid >= 0
    old = cells[valid]
    np.testing.assert_allclose(points[grid[valid]], verts[old], atol=1e-7)


def test_range_grid_needs_grid_size(tmp_path):
    path = tmp_path / "plain.ply"
    save_cloud(path, _cloud(5))
    with pytest.raises(FileFormatError, match=r"plain\.ply.*'range_grid'"):
        load_range_grid(path)


# ----------------------------------------------------------------------------- the Stanford bunny


@pytest.fixture(scope="module")
def bunny():
    from support.shared_data import require_shared

    return require_shared("stanford-bunny", "bun000.ply")


def test_stanford_bun000(bunny):
    cloud = load_cloud(bunny)  # its load time is measured by benchmarks/formats/bench_cloud_io.py
    assert len(cloud) == 40256 and cloud.normals is None and cloud.colours is None
    assert np.all(np.abs(cloud.points) < 0.2)
    assert np.ptp(cloud.points, axis=0).min() > 0.05  # a bunny-sized object, in metres
    np.testing.assert_array_equal(cloud.points[0], [-0.06325, 0.0359793, 0.0420873])
    np.testing.assert_array_equal(cloud.points[-1], [-0.018, 0.18794, -0.0197253])


def test_stanford_bun000_range_grid(bunny):
    points, grid = load_range_grid(bunny)
    np.testing.assert_array_equal(points, load_cloud(bunny).points)
    assert grid.shape == (400, 512) and grid.dtype == np.int64
    valid = grid[grid >= 0]
    assert np.all(grid[grid < 0] == -1)
    np.testing.assert_array_equal(np.sort(valid), np.arange(len(points)))  # one cell per point, each once


# ------------------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("suffix", sorted(CLOUD_READERS))
def test_missing_file(tmp_path, suffix):
    with pytest.raises(FileFormatError, match=rf"nothing{suffix}: point cloud file not found"):
        load_cloud(tmp_path / f"nothing{suffix}")


@pytest.mark.parametrize("suffix", sorted(CLOUD_READERS))
def test_garbage(tmp_path, suffix):
    path = tmp_path / f"garbage{suffix}"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    with pytest.raises(FileFormatError, match=rf"garbage{suffix}: .*expected"):
        load_cloud(path)


def test_truncated_binary_ply(tmp_path):
    path = tmp_path / "scan.ply"
    save_cloud(path, _cloud(1000, normals=False, colours=False))
    data = path.read_bytes()
    path.write_bytes(data[:len(data) - 1000 * 24 + 12 * 24 + 5])  # 12 whole rows and a bit
    with pytest.raises(FileFormatError, match=r"scan\.ply: header declares 1000 vertices but the file ends after 12$"):
        load_cloud(path)


def test_truncated_lists_in_binary_ply(tmp_path):
    data, _, _ = _synthetic_grid("binary_big_endian")
    (tmp_path / "grid.ply").write_bytes(data[:-3])
    with pytest.raises(FileFormatError, match=r"grid\.ply: header declares 12 'range_grid' entries but the file "
                                              r"ends after 11"):
        load_range_grid(tmp_path / "grid.ply")


def test_truncated_ascii_ply(tmp_path):
    text = "ply\nformat ascii 1.0\nelement vertex 1000\nproperty float x\nproperty float y\nproperty float z\n" \
           "end_header\n" + "0 1 2\n" * 12
    (tmp_path / "scan.ply").write_text(text)
    with pytest.raises(FileFormatError, match=r"scan\.ply: header declares 1000 vertices but the file ends after 12"):
        load_cloud(tmp_path / "scan.ply")


def test_bad_number_in_ascii_ply_names_the_line(tmp_path):
    text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n" \
           "end_header\n0 1 2\n3 oops 5\n"
    (tmp_path / "scan.ply").write_text(text)
    with pytest.raises(FileFormatError, match=r"scan\.ply: line 9: expected a number, found 'oops'"):
        load_cloud(tmp_path / "scan.ply")


def test_bad_ply_header(tmp_path):
    (tmp_path / "h.ply").write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float32x x\nend_header\n1\n")
    with pytest.raises(FileFormatError, match=r"h\.ply: PLY header line 4: expected 'property"):
        load_cloud(tmp_path / "h.ply")


@pytest.mark.parametrize("kind", ["ascii.ply", "binary_little_endian.ply", ".npy", ".xyz"])
def test_empty_cloud(tmp_path, kind):
    fmt, suffix = kind.split(".")
    path = tmp_path / f"empty.{suffix}"
    if suffix == "ply":
        path.write_text(f"ply\nformat {fmt} 1.0\nelement vertex 0\nproperty double x\n"
                        "property double y\nproperty double z\nend_header\n")
    elif suffix == "npy":
        np.save(path, np.empty((0, 3)))
    else:
        path.write_text("# nothing here\n")
    with pytest.raises(FileFormatError, match=rf"empty\.{suffix}: expected at least one point, found an empty cloud"):
        load_cloud(path)


def test_all_points_non_finite(tmp_path):
    save_cloud(tmp_path / "nan.npy", PointCloud(np.full((4, 3), np.nan)))
    with pytest.raises(FileFormatError, match=r"nan\.npy: expected at least one point, found 4 points, none"):
        load_cloud(tmp_path / "nan.npy")


def test_wrong_columns(tmp_path):
    (tmp_path / "four.xyz").write_text("1 2 3 4\n5 6 7 8\n")
    with pytest.raises(FileFormatError, match=r"four\.xyz: expected rows of 3 .* found 4 columns"):
        load_cloud(tmp_path / "four.xyz")
    np.save(tmp_path / "four.npy", np.zeros((5, 4)))
    with pytest.raises(FileFormatError, match=r"four\.npy: expected .* found float64 \(5, 4\)"):
        load_cloud(tmp_path / "four.npy")


def test_unknown_suffix_lists_known_ones(tmp_path):
    (tmp_path / "scan.obj").write_text("v 0 0 0\n")
    with pytest.raises(FileFormatError, match=r"scan\.obj: unknown point cloud format '\.obj'; known: "
                                              r"\.ply, \.pcd, \.xyz, \.txt, \.npy, \.e57"):
        load_cloud(tmp_path / "scan.obj")
