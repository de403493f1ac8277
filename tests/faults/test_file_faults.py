"""Bad cloud and mesh files (truncated, lying headers, unknown types, text where numbers go, wrong shapes,
empty files, folders) end in one ``rangekit: error:`` line naming the file, the expected and the found
value, and nothing is written."""

from __future__ import annotations

import io
import struct

import numpy as np
import pytest

from support.cli_runs import assert_error

_XYZ = np.arange(12, dtype="<f4").reshape(4, 3)
_TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()


def _ply(n, fmt="binary_little_endian", props=("float x", "float y", "float z"), extra=""):
    return (f"ply\nformat {fmt} 1.0\nelement vertex {n}\n" + "".join(f"property {p}\n" for p in props) + extra
            + "end_header\n").encode()


def _npy(a) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def _pcd(fields="x y z", size="4 4 4", type_="F F F", count="1 1 1", points=1, data="ascii", body=b"1 2 3\n"):
    return (f"VERSION .7\nFIELDS {fields}\nSIZE {size}\nTYPE {type_}\nCOUNT {count}\nWIDTH {points}\nHEIGHT 1\n"
            f"POINTS {points}\nDATA {data}\n").encode() + body


_FACE = "element face 1\nproperty list uchar {} vertex_indices\n"

# name: (bytes, mentions in the error after the file name)
FILES = {
    "truncated.ply": (_ply(4) + _XYZ.tobytes()[:20], ["header declares 4 vertices", "ends after 1"]),
    "more_than_data.ply": (_ply(100) + _XYZ.tobytes(), ["header declares 100 vertices", "ends after 4"]),
    "unknown_type.ply": (_ply(4, props=("float128 x", "float y", "float z")) + _XYZ.tobytes(),
                         ["header line 4", "float128 x"]),
    "zero_vertices.ply": (_ply(0), ["expected at least one point", "empty cloud"]),
    "text_for_number.ply": (_ply(2, "ascii") + b"1 2 3\n4 five 6\n", ["line 9", "expected a number", "'five'"]),
    "short_row.ply": (_ply(2, "ascii") + b"1 2 3\n4 5\n", ["line 9", "property 'z'", "found 2 numbers"]),
    "list_for_x.ply": (_ply(1, "ascii", props=("list uchar float x", "float y", "float z")) + b"1 1 2 3\n",
                       ["expected vertex properties x, y, z (one number each)", "x (a list)"]),
    "no_end_header.ply": (b"ply\nformat ascii 1.0\nelement vertex 1\n", ["'end_header'", "found none"]),
    "empty.ply": (b"", ["starting with the line 'ply'", "found b''"]),
    "float_indices.ply": (_ply(3, extra=_FACE.format("float")) + _TRI + struct.pack("<B3f", 3, 0, 1, 2),
                          ["whole-number vertex indices", "float32"]),
    "negative_list.ply": (_ply(3, extra=_FACE.replace("uchar", "int").format("int")) + _TRI
                          + struct.pack("<i3i", -1, 0, 1, 2), ["binary PLY body", "list lengths >= 0",
                                                                 "a list of negative length"]),
    "index_out_of_range.ply": (_ply(3, extra=_FACE.format("int")) + _TRI + struct.pack("<B3i", 3, 0, 1, 7),
                               ["face indices in [0, 3)", "[0, 7]"]),
    "ragged.xyz": (b"1 2 3\n4 5\n", ["rows of 3 (x y z) or 6", "changed from 3 to 2 at row 2"]),
    "text.xyz": (b"1 2 3\na b c\n", ["rows of 3", "'a'"]),
    "four_columns.xyz": (b"1 2 3 4\n", ["found 4 columns"]),
    "empty.xyz": (b"", ["empty cloud"]),
    "wrong_shape.npy": (_npy(np.zeros((5, 4))), ["(N, 3), (N, 6)", "float64 (5, 4)"]),
    "strings.npy": (_npy(np.array([["a", "b", "c"]])), ["<U1 (1, 3)"]),
    "one_dim.npy": (_npy(np.zeros(3)), ["float64 (3,)"]),
    "truncated.npy": (_npy(np.zeros((100, 3)))[:300], ["cannot read it", "expected 2400 bytes"]),
    "empty.npy": (b"", ["no .npy header"]),
    "two_fields.pcd": (_pcd("x y", "4 4", "F F", "1 1", body=b"1 2\n"), ["fields x, y, z", "found x y"]),
    "count_zero.pcd": (_pcd(count="0 1 1", data="binary", body=b"\0" * 8), ["COUNT entries >= 1", "COUNT 0 1 1"]),
    "count_negative.pcd": (_pcd(count="-1 1 1", data="binary", body=b"\0" * 8), ["COUNT -1 1 1"]),
    "size_16.pcd": (_pcd(size="16 4 4", data="binary", body=b"\0" * 24), ["1, 2, 4 or 8 bytes", "SIZE 16 4 4"]),
    "points_negative.pcd": (_pcd(points=-5, data="binary", body=b""), ["POINTS >= 0", "-5 points"]),
    "bad_type.pcd": (_pcd(type_="F F Q"), ["TYPE (F, I or U)"]),
    "truncated.pcd": (_pcd(points=2, data="binary", body=b"\0" * 8), ["header declares 2 points", "ends after 0"]),
    "compressed.pcd": (_pcd(data="binary_compressed", body=b""), ["1 points", "binary_compressed", "truncated or corrupt"]),
    "empty.pcd": (b"", ["'DATA ascii|binary'", "found none"]),
    "nan_vertex.obj": (b"v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ["expected finite vertices", "1 that are not"]),
    "bad_index.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", ["cannot read OBJ mesh"]),
    "vertices_only.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", ["expected a triangle mesh, found no triangles"]),
    "empty.stl": (b"", ["found no triangles"]),
}


@pytest.mark.parametrize("name", list(FILES))
def test_a_bad_cloud_or_mesh_file_is_a_clear_error(cli, tmp_path, name):
    data, mentions = FILES[name]
    src = tmp_path / name
    src.write_bytes(data)
    run = cli("render", src, "--out", tmp_path / "r.png", "--size", "64x48")
    assert_error(run, 1, name, *mentions)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # no picture, no temporary file


@pytest.mark.parametrize("command, name, what", [
    ("render", "scans.ply", "a mesh or a point cloud file"),
    ("render", "scans.obj", "a mesh or a point cloud file"),
    ("mesh", "scans.xyz", "a point cloud file"),
    ("mesh", "scans", "a point cloud file"),
])
def test_a_folder_given_for_a_file_is_named(cli, tmp_path, command, name, what):
    (tmp_path / name).mkdir()
    out = tmp_path / ("out.png" if command == "render" else "out.ply")   # an extension the command writes
    run = cli(command, tmp_path / name, "--out", out)
    assert_error(run, 1, name, f"is a folder, expected {what}")
    assert not out.exists()


def test_register_names_the_bad_scan(cli, tmp_path):
    good = tmp_path / "a.xyz"
    np.savetxt(good, np.random.default_rng(0).normal(size=(50, 3)))
    bad = tmp_path / "b.pcd"
    bad.write_bytes(FILES["count_zero.pcd"][0])
    run = cli("register", good, bad, "--out", tmp_path / "reg")
    assert_error(run, 1, "b.pcd", "COUNT 0 1 1")
    assert not (tmp_path / "reg").exists()
