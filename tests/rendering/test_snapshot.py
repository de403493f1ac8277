"""Headless snapshots against exact ground truth: an icosphere vs the analytic sphere, planes of points."""

import base64

import cv2
import numpy as np
import pytest
import trimesh

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.surface.mesh import TriangleMesh
from rangekit.surface.cloud import PointCloud
from rangekit.colour import COLOUR_MAPS, colour_table
from rangekit.colour import colourise
from rangekit.rendering.snapshot import (colour_bar, data_uri, fit_camera, montage, raycast_mesh,
                               render_cloud, render_mesh, render_values_on_mesh, to_png_bytes)

R = 0.05
C = np.array([0.12, -0.07, 0.31])


@pytest.fixture(scope="module")
def sphere():
    """Icosphere (every vertex exactly on the sphere), its camera, and exact bounds of its tessellation error."""
    tm = trimesh.creation.icosphere(subdivisions=5, radius=R)
    mesh = TriangleMesh(tm.vertices + C, tm.faces)
    V = mesh.vertices[mesh.triangles]
    n = np.cross(V[:, 1] - V[:, 0], V[:, 2] - V[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    sag = R - np.min(np.abs(np.einsum("ij,ij->i", n, V[:, 0] - C)))  # deepest facet point below the sphere
    radial = (V - C) / R
    max_angle = np.max(np.arccos(np.clip(np.einsum("fj,fkj->fk", n, radial), -1, 1)))  # face normal vs vertex
    cam = fit_camera(mesh.vertices, azimuth=0.7, elevation=0.35, size=(320, 240))
    return dict(mesh=mesh, cam=cam, sag=sag, max_angle=max_angle, hits=raycast_mesh(mesh, cam))


def _analytic(cam):
    """Per-pixel ray-sphere geometry: (hit mask, distance ray-centre, near t, origins, directions)."""
    o, d = cam.rays(cam.pixel_grid())
    oc = o - C
    b = np.einsum("ij,ij->i", d, oc)
    rho = np.sqrt(np.maximum(np.einsum("ij,ij->i", oc, oc) - b * b, 0))
    t = -b - np.sqrt(np.maximum(R * R - rho * rho, 0))
    shape = (cam.height, cam.width)
    return rho.reshape(shape) <= R, rho.reshape(shape), t.reshape(shape), o, d


def test_raycast_sphere_matches_analytic(sphere):
    h, cam, sag = sphere["hits"], sphere["cam"], sphere["sag"]
    assert sag < 1e-3 * R
    hit, rho, _, _, d = _analytic(cam)
    assert h.hit.shape == (240, 320) and h.hit.sum() > 5000
    assert np.mean(h.hit == hit) >= 0.99
    # The polyhedron lies inside the sphere and contains the sphere shrunk by sag: mismatches only at the rim.
    wrong = h.hit != hit
    assert np.all(rho[wrong] >= R - sag - 1e-9) and np.all(rho[wrong] <= R + 1e-7)
    p = h.xyz[h.hit]
    dist = np.linalg.norm(p - C, axis=1)
    assert np.all(dist <= R + 1e-12) and np.all(dist >= R - sag - 1e-12)
    # Normals: the facet normal is within the facets' largest normal-vs-vertex angle of the radial direction.
    radial = (p - C) / dist[:, None]
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", h.normal[h.hit], radial), -1, 1))
    assert sphere["max_angle"] < np.radians(2) and np.all(angle <= sphere["max_angle"] + 1e-9)
    assert np.allclose(np.linalg.norm(h.normal[h.hit], axis=1), 1, atol=1e-12)
    assert np.all(np.einsum("ij,ij->i", h.normal[h.hit], d[h.hit.ravel()]) < 0)  # facing the camera
    # Off-mesh fill values, and triangle + barycentrics reproduce the hit point.
    assert np.all(np.isnan(h.xyz[~h.hit])) and np.all(np.isnan(h.normal[~h.hit]))
    assert np.all(h.triangle[~h.hit] == -1) and np.all(h.triangle[h.hit] >= 0)
    b = h.bary[h.hit]
    w = np.column_stack([1 - b.sum(axis=1), b])
    assert np.all(w >= -1e-6)
    V = sphere["mesh"].vertices[sphere["mesh"].triangles[h.triangle[h.hit]]]
    assert np.allclose(np.einsum("mk,mkj->mj", w, V), p, atol=1e-12, rtol=0)


@pytest.mark.parametrize("az, el, up", [(0.0, 0.0, (0, 0, 1)), (2.3, -0.6, (0, 0, 1)), (-1.0, 1.2, (0, 0, 1)),
                                        (0.4, 0.3, (0, 1, 0)), (5.0, 0.2, (1, 1, 1))])
def test_fit_camera_frames_the_box(az, el, up):
    lo, hi = np.array([-0.1, 0.2, 0.0]), np.array([0.3, 0.25, 0.15])
    cam = fit_camera(np.array([lo, hi]), azimuth=az, elevation=el, size=(400, 300), up=up)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    uv = cam.project(corners)
    assert np.all((uv >= -0.5) & (uv <= np.array([399.5, 299.5])))
    centre = (lo + hi) / 2
    uc = cam.project(centre[None])[0]
    assert np.allclose(uc, [199.5, 149.5], atol=1e-9)
    u = np.asarray(up, float) / np.linalg.norm(up)
    above = cam.project((centre + 0.01 * u)[None])[0]
    assert above[1] < uc[1] - 1 and abs(above[0] - uc[0]) < 1e-9  # straight up in the image
    # Elevation above the plane normal to up; with up = z, azimuth is measured from +x towards +y.
    view = (cam.center - centre) / np.linalg.norm(cam.center - centre)
    assert np.isclose(np.arcsin(view @ u), el, atol=1e-12)
    if up == (0, 0, 1):
        assert np.allclose(view, [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], atol=1e-12)
    # margin = 1: the bounding sphere touches the top and bottom edges (the smaller side).
    tight = fit_camera(np.array([lo, hi]), azimuth=az, elevation=el, size=(400, 300), up=up, margin=1.0)
    rad, half = np.linalg.norm(hi - lo) / 2, np.radians(15)
    z, y_up = tight.T_world_cam[:3, 2], -tight.T_world_cam[:3, 1]
    tangent = centre + rad * (-np.sin(half) * z + np.cos(half) * y_up)
    assert np.isclose(tight.project(tangent[None])[0, 1], -0.5, atol=1e-9)


def test_fit_camera_rejects_bad_input():
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        fit_camera(np.zeros((4, 2)), azimuth=0, elevation=0)
    with pytest.raises(InputError, match="elevation"):
        fit_camera(np.eye(3), azimuth=0, elevation=np.pi / 2)


def test_render_mesh_shading_and_background(sphere):
    mesh, cam, h = sphere["mesh"], sphere["cam"], sphere["hits"]
    img = render_mesh(mesh, cam, background=(10, 20, 30))
    assert img.shape == (240, 320, 3) and img.dtype == np.uint8
    assert np.all(img[~h.hit] == [10, 20, 30]) and not np.any(np.all(img[h.hit] == [10, 20, 30], axis=1))
    v = h.xyz[h.hit] - cam.center
    cos = np.abs(np.einsum("ij,ij->i", h.normal[h.hit], v / np.linalg.norm(v, axis=1, keepdims=True)))
    expected = np.array([0.75, 0.78, 0.82]) * (0.25 + 0.75 * cos)[:, None] * 255
    assert np.abs(img[h.hit] - expected).max() <= 0.5 + 1e-9
    # Vertex colours linear in position interpolate to the same linear function at the hit point.
    def lin(p):
        return np.clip(0.5 + (p - C) / (2 * R), 0, 1)
    img_c = render_mesh(mesh, cam, vertex_colours=lin(mesh.vertices))
    expected = lin(h.xyz[h.hit]) * (0.25 + 0.75 * cos)[:, None] * 255
    assert np.abs(img_c[h.hit] - expected).max() <= 0.5 + 1e-6
    img_u8 = render_mesh(mesh, cam, vertex_colours=np.rint(lin(mesh.vertices) * 255).astype(np.uint8))
    assert np.abs(img_u8.astype(int) - img_c).max() <= 1


def _plane_points(x0, x1, y0, y1, z, step):
    x, y = np.meshgrid(np.arange(x0, x1 + step / 2, step), np.arange(y0, y1 + step / 2, step))
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z)])


@pytest.fixture(scope="module")
def front_cam():
    """160 x 120, f = 200 px, world = camera frame."""
    return PinholeCamera(np.array([[200.0, 0, 79.5], [0, 200.0, 59.5], [0, 0, 1]]), 160, 120)


@pytest.mark.parametrize("near_first", [True, False])
def test_render_cloud_zbuffer_nearest_wins(front_cam, near_first):
    far = _plane_points(-0.3, 0.1, -0.2, 0.2, 1.0, 0.002)    # u in [19.5, 99.5], v in [19.5, 99.5]
    near = _plane_points(-0.05, 0.2, -0.1, 0.1, 0.5, 0.001)  # u in [59.5, 159.5], v in [19.5, 99.5]
    red, green = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    parts = [(near, green), (far, red)] if near_first else [(far, red), (near, green)]
    pts = np.concatenate([p for p, _ in parts])
    cols = np.concatenate([np.tile(c, (len(p), 1)) for p, c in parts])
    img = render_cloud(PointCloud(pts, cols), front_cam, point_px=1)
    assert np.all(img[22:98, 62:159] == [0, 255, 0])  # overlap and near only: the near plane
    assert np.all(img[22:98, 22:57] == [255, 0, 0])   # far plane only
    assert np.all(img[:17] == 255) and np.all(img[103:] == 255) and np.all(img[:, :17] == 255)


@pytest.mark.parametrize("near_first", [True, False])
def test_render_cloud_overlapping_splats(front_cam, near_first):
    """Squares of points in different pixels overlap: the nearer point wins the shared pixels."""
    near, far = [0.0025, 0.0025, 1.0], [0.0225, 0.0075, 3.0]  # pixels (u, v) = (80, 60) and (81, 60)
    pts, cols = np.array([near, far]), np.array([[0, 1.0, 0], [1.0, 0, 0]])
    if not near_first:
        pts, cols = pts[::-1], cols[::-1]
    img = render_cloud(PointCloud(pts, cols), front_cam, point_px=1)
    assert np.all(img[59:62, 79:82] == [0, 255, 0]) and np.all(img[59:62, 82] == [255, 0, 0])
    assert np.count_nonzero(np.any(img != 255, axis=2)) == 12


@pytest.mark.parametrize("point_px", [0, 1, 2])
def test_render_cloud_footprint_area(front_cam, point_px):
    x0, x1, y0, y1, z = -0.2013, 0.2777, -0.1731, 0.1922, 0.8  # about 120 x 91 px
    pts = _plane_points(x0, x1, y0, y1, z, 0.0015)  # 0.375 px apart
    img = render_cloud(pts, front_cam, point_px=point_px, background=(0, 0, 0))
    covered = np.any(img != 0, axis=2)
    u = np.rint(200 * pts[:, 0] / z + 79.5).astype(int)
    v = np.rint(200 * pts[:, 1] / z + 59.5).astype(int)
    r = point_px
    expected = np.zeros_like(covered)
    expected[v.min() - r:v.max() + r + 1, u.min() - r:u.max() + r + 1] = True
    assert np.array_equal(covered, expected)  # exactly the pixels the squares cover
    area = 200 * (x1 - x0) / z * 200 * (y1 - y0) / z
    if point_px == 0:
        assert abs(covered.sum() / area - 1) < 0.03
    assert np.all(img[covered] == np.rint(np.array([0.75, 0.78, 0.82]) * 255))  # uniform grey


def test_render_cloud_colour_priority(front_cam):
    p = np.array([[0.0, 0.0, 1.0]])  # projects to pixel centre (79.5, 59.5) -> rounds to (80, 60)
    n = np.array([[0.0, 0.6, -0.8]])
    col = np.array([[0.2, 0.4, 0.6]])
    px = (60, 80)
    assert np.all(render_cloud(PointCloud(p, col, n), front_cam, values=[3.0], vmin=0, vmax=3)[px]
                  == colour_table("turbo")[-1])
    assert np.all(render_cloud(PointCloud(p, col, n), front_cam)[px] == np.rint(col[0] * 255))
    assert np.all(render_cloud(PointCloud(p, None, n), front_cam)[px]
                  == np.rint(np.array([0.75, 0.78, 0.82]) * (0.25 + 0.75 * 0.8) * 255))
    assert np.all(render_cloud(p, front_cam)[px] == np.rint(np.array([0.75, 0.78, 0.82]) * 255))
    assert np.count_nonzero(np.any(render_cloud(p, front_cam) != 255, axis=2)) == 9
    with pytest.raises(InputError, match="values"):
        render_cloud(p, front_cam, values=[1.0, 2.0])


def test_colourise_anchors_nan_and_monotone_luminance():
    v = np.array([[-1.0, 0.0, 0.5], [1.0, 2.0, np.nan]])
    for name in COLOUR_MAPS:
        table = colour_table(name)
        out = colourise(v, 0.0, 1.0, cmap=name, nan_colour=(1, 2, 3))
        assert out.shape == (2, 3, 3) and out.dtype == np.uint8
        assert np.all(out[0, 0] == table[0]) and np.all(out[0, 1] == table[0])
        assert np.all(out[1, 0] == table[-1]) and np.all(out[1, 1] == table[-1])
        assert np.all(out[1, 2] == [1, 2, 3])
    assert np.all(colourise(np.array([0.5]), 0, 1, cmap="turbo")[0] == colour_table("turbo")[128])
    assert np.all(colourise(np.array([0.5]), 0, 1, cmap="grey")[0] == 128)
    ramp = np.linspace(-3, 7, 64)
    for name in ("viridis", "grey"):
        luma = colourise(ramp, -3, 7, cmap=name) @ np.array([0.299, 0.587, 0.114])
        assert np.all(np.diff(luma) > 0)
    assert np.all(colourise(np.array([1.0, 1.0]), 1.0, 1.0) == colour_table("turbo")[0])  # vmin == vmax
    with pytest.raises(InputError, match="cmap"):
        colourise(v, 0, 1, cmap="jet")


def test_render_values_on_mesh_plane_distance(sphere):
    mesh, cam, h = sphere["mesh"], sphere["cam"], sphere["hits"]
    n, d0 = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8]), -0.2
    calls = []

    def plane_distance(p):
        calls.append(p.shape)
        return p @ n + d0

    img, values = render_values_on_mesh(mesh, cam, plane_distance, vmin=-0.1, vmax=0.0, cmap="viridis")
    assert calls == [(h.hit.sum(), 3)]
    assert np.array_equal(np.isfinite(values), h.hit)
    assert np.allclose(values[h.hit], h.xyz[h.hit] @ n + d0, atol=1e-15, rtol=0)
    # Against the analytic sphere where the ray meets it at < 60 deg incidence: |dt| <= sag / cos.
    hit, _, t, o, d = _analytic(cam)
    p = o + t.reshape(-1)[:, None] * d
    cos_inc = np.abs(np.einsum("ij,ij->i", (p - C) / R, d)).reshape(hit.shape)
    good = hit & h.hit & (cos_inc > 0.5)
    assert good.sum() > 0.7 * hit.sum()  # 75 % of the disc is within 60 deg
    assert np.abs(values[good] - (p @ n + d0).reshape(hit.shape)[good]).max() <= 2 * sphere["sag"] + 1e-9
    assert np.all(img[~h.hit] == 255)
    v = h.xyz[h.hit] - cam.center
    lam = np.abs(np.einsum("ij,ij->i", h.normal[h.hit], v / np.linalg.norm(v, axis=1, keepdims=True)))
    expected = colourise(values[h.hit], -0.1, 0.0, cmap="viridis") * (0.6 + 0.4 * lam)[:, None]
    assert np.abs(img[h.hit] - expected).max() <= 0.5 + 1e-9
    with pytest.raises(InputError, match="value_fn"):
        render_values_on_mesh(mesh, cam, lambda p: p[:, :2], vmin=0, vmax=1)


def test_colour_bar():
    bar = colour_bar(-2.0, 5.0, label="error [mm]", size=(300, 50))
    assert bar.shape == (50, 300, 3) and bar.dtype == np.uint8
    assert np.all(bar[10, 6] == colour_table("turbo")[0]) and np.all(bar[10, 293] == colour_table("turbo")[-1])
    text = np.all(bar[25:] < 100, axis=2)
    assert text[:, :40].any() and text[:, 120:180].any() and text[:, 260:].any()  # vmin, label, vmax


def test_montage_layout():
    a = np.full((10, 20, 3), 1, np.uint8)
    b = np.full((30, 16, 3), 2, np.uint8)
    c = np.full((6, 6), 3, np.uint8)
    out = montage([a, b, c], 2, pad=4, background=200)
    assert out.shape == (2 * 30 + 3 * 4, 2 * 20 + 3 * 4, 3)
    assert np.all(out[4 + 10:4 + 20, 4:24] == 1)     # a centred vertically in a 30 x 20 cell
    assert np.all(out[4:34, 28 + 2:28 + 18] == 2)    # b centred horizontally
    assert np.all(out[38 + 12:38 + 18, 4 + 7:4 + 13] == 3)
    assert np.count_nonzero(np.all(out == 200, axis=2)) == out.shape[0] * out.shape[1] - 200 - 480 - 36
    with pytest.raises(InputError):
        montage([], 2)


def test_png_bytes_and_data_uri():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    png = to_png_bytes(img)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert np.array_equal(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1], img)
    uri = data_uri(img)
    assert uri.startswith("data:image/png;base64,") and base64.b64decode(uri.split(",", 1)[1]) == png
    with pytest.raises(InputError, match="uint8"):
        to_png_bytes(img.astype(np.float32))


def test_empty_mesh_is_an_input_error(front_cam):
    with pytest.raises(InputError, match="triangles"):
        raycast_mesh(TriangleMesh(np.zeros((3, 3)), np.zeros((0, 3), np.int64)), front_cam)
