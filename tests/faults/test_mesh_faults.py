"""Meshing and rendering degenerate clouds and meshes ends in one ``rangekit: error:`` line naming the file,
how many points it has and what is needed, never a Qhull/Open3D traceback or crash; a one-point cloud still
renders."""

from __future__ import annotations

import numpy as np
import pytest

from support.cli_runs import assert_error

_RNG = np.random.default_rng(16)
_SPHERE = _RNG.normal(size=(200, 3))
_SPHERE /= np.linalg.norm(_SPHERE, axis=1, keepdims=True)
_PLANE = np.column_stack([_RNG.random((200, 2)), np.zeros(200)])
_UP = np.tile([0.0, 0.0, 1.0], (200, 1))

# name: (rows written to NAME.xyz, mentions in the error after the file name)
CLOUDS = {
    "one": (np.zeros((1, 3)), ["found 1 finite point"]),
    "two": (np.eye(3)[:2], ["found 2 finite points, all on one line"]),
    "three": (np.eye(3), ["found 3 finite points, all in one plane"]),
    "four": (np.vstack([np.zeros(3), np.eye(3)]), ["need at least 10 points", "found 4 finite points"]),
    "identical": (np.ones((50, 3)), ["found 50 finite points, all at one point"]),
    "collinear": (np.outer(np.linspace(0, 1, 50), [1, 2, 3]), ["all on one line"]),
    "coplanar": (_PLANE, ["found 200 finite points, all in one plane"]),
    "coplanar_with_normals": (np.hstack([_PLANE, _UP]), ["all in one plane"]),  # Poisson "succeeded" on this
    "identical_with_normals": (np.hstack([np.ones((50, 3)), _UP[:50]]), ["all at one point"]),  # segfault
    "collinear_with_normals": (np.hstack([np.outer(np.linspace(0, 1, 50), [1, 2, 3]), _UP[:50]]),
                               ["all on one line"]),
    "nan_normals": (np.hstack([_SPHERE, np.full_like(_SPHERE, np.nan)]),
                    ["found 0 points with a normal", "200 of them with a NaN"]),
    "zero_normals": (np.hstack([_SPHERE, np.zeros_like(_SPHERE)]), ["found 0 points with a normal"]),
    "mostly_nan": (np.vstack([np.full((30, 3), np.nan), _SPHERE[:5]]), ["found 5 finite points"]),
}


@pytest.mark.parametrize("name", list(CLOUDS))
def test_meshing_a_degenerate_cloud_is_a_clear_error(cli, tmp_path, name):
    rows, mentions = CLOUDS[name]
    src = tmp_path / f"{name}.xyz"
    np.savetxt(src, rows)
    out = tmp_path / "mesh.ply"
    run = cli("mesh", src, "--out", out)
    line = assert_error(run, 1, f"{name}.xyz", "need at least 10 points not all in one plane", *mentions)
    assert "Qhull" not in line and "Open3D" not in line
    assert list(tmp_path.iterdir()) == [src]  # no mesh, no temporary file


def test_a_cloud_of_nothing_but_nan_is_refused_when_read(cli, tmp_path):
    src = tmp_path / "nan.xyz"
    np.savetxt(src, np.full((20, 3), np.nan))
    assert_error(cli("mesh", src, "--out", tmp_path / "m.ply"), 1, "nan.xyz", "20 points, none of them finite")


def test_orienting_normals_of_a_flat_cloud_is_a_mesh_error():
    """The library call the CLI relies on refuses flat input itself (it was a Qhull RuntimeError)."""
    from rangekit.errors import MeshError
    from rangekit.surface.cloud import oriented_normals_cloud

    with pytest.raises(MeshError, match="need at least 4 points not all in one plane, found 200 finite points, "
                                        "all in one plane"):
        oriented_normals_cloud(_PLANE)
    with pytest.raises(MeshError, match="found 50 finite points, all at one point"):
        oriented_normals_cloud(np.ones((50, 3)))


def test_affine_dimension_of_exact_and_noisy_shapes():
    from rangekit.surface.cloud import affine_dimension

    assert [affine_dimension(a) for a in (np.zeros((0, 3)), np.ones((7, 3)), np.eye(3)[:2], _PLANE, _SPHERE)] \
        == [0, 0, 1, 2, 3]
    noisy = _PLANE + np.column_stack([np.zeros((200, 2)), 1e-4 * _RNG.normal(size=200)])
    assert affine_dimension(noisy) == 3  # a real flat scan with noise is a (thin) solid
    assert affine_dimension(_PLANE * 1e6 + 5e6) == 2  # far from the origin and large: still flat


def _ascii_ply(path, vertices, faces):
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    path.write_text(head + "".join(" ".join(map(str, v)) + "\n" for v in vertices)
                    + "".join("3 " + " ".join(map(str, f)) + "\n" for f in faces))
    return path


@pytest.mark.parametrize("name, vertices", [
    ("point", [[0, 0, 0]] * 3),
    ("line", [[0, 0, 0], [1, 0, 0], [2, 0, 0]]),
])
def test_rendering_a_mesh_of_zero_area_is_a_clear_error(cli, tmp_path, name, vertices):
    src = _ascii_ply(tmp_path / f"{name}.ply", vertices, [[0, 1, 2]])
    run = cli("render", src, "--out", tmp_path / "r.png", "--size", "64x48")
    assert_error(run, 1, f"{name}.ply", "1 triangle(s) all have zero area")
    assert not (tmp_path / "r.png").exists()


@pytest.mark.parametrize("rows", [np.zeros((1, 3)), np.full((50, 3), 0.25)], ids=["one_point", "identical"])
def test_rendering_a_one_point_cloud_draws_the_point(cli, tmp_path, rows):
    from rangekit.io import read_png

    src = tmp_path / "c.xyz"
    np.savetxt(src, rows)
    run = cli("render", src, "--out", tmp_path / "r.png", "--size", "64x48")
    assert run.code == 0, run.err
    img = read_png(tmp_path / "r.png")
    drawn = np.argwhere((img < 250).any(axis=2))
    assert len(drawn) > 0 and np.allclose(drawn.mean(axis=0), [23.5, 31.5], atol=1.5)  # in the centre


def test_rendering_a_mesh_with_no_faces_draws_its_vertices(cli, tmp_path):
    src = _ascii_ply(tmp_path / "noface.ply", [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [])
    run = cli("render", src, "--out", tmp_path / "r.png", "--size", "64x48")
    assert run.code == 0 and "cloud of 3 points" in run.out, run.err
