"""Per-view error breakdown against the simulator's truth: exact clouds and poses score
zero; a known pose error, a known offset of the depth-edge points and a known decoding bias each come out
where they belong."""

from __future__ import annotations

import numpy as np
import pytest

from rangekit.geometry import axis_angle_to_R, compose, make_T
from rangekit.rig.rig_file import turntable_prior
from rangekit.sim import default_rig, default_scene
from rangekit.sim.scene.raycast import cast_view
from rangekit.sim.truth.view_errors import depth_edges, view_errors
from rangekit.surface.cloud import PointCloud
from support.small_rigs import small_rig


@pytest.fixture(scope="module")
def exact():
    rig = small_rig()
    scene = default_scene("lumpy")
    angles = [0.0, np.pi / 2]
    clouds, cols, edges = [], [], []
    for a in angles:
        g = cast_view(scene.world_mesh(rig.T_world_rotated(a)), rig.camera, rig.projector)
        on = g.valid & (g.object_id == 0)
        clouds.append(PointCloud(g.xyz[on]))
        cols.append(np.where(on, g.proj_col, np.nan))
        e = depth_edges(g.depth)
        edges.append(e[on])
    return rig, scene, angles, clouds, cols, edges


def test_exact_views_score_zero(exact):
    rig, scene, angles, clouds, cols, _ = exact
    T = turntable_prior(rig.T_world_table, angles)
    ve = view_errors(scene, rig, angles, clouds, T, cols, ["a", "b"])
    for v in ve:     # metres and radians inside
        assert v.cloud.all.rms < 1e-7 and v.decoding.rms_px < 1e-9
        assert np.degrees(v.registration.rotation) < 1e-9 and v.registration.point_rms < 1e-12
        assert 0 < v.cloud.edge.n < v.cloud.all.n


def test_each_error_lands_in_its_part(exact):
    rig, scene, angles, clouds, cols, edges = exact
    T = turntable_prior(rig.T_world_table, angles)
    # view 1: posed 0.05 degrees off about the table axis; its edge points pushed 0.5 mm along the camera ray;
    # its decoded columns biased by 0.25 px.
    axis = rig.T_world_table[:3, 2]
    T_off = T.copy()
    T_off[1] = compose(make_T(axis_angle_to_R(axis, np.radians(0.05))), T[1])
    P = clouds[1].points.copy()
    ray = P - rig.camera.center
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    P[edges[1]] += 0.5e-3 * ray[edges[1]]
    moved = [clouds[0], PointCloud(P)]
    ve = view_errors(scene, rig, angles, moved, T_off, [cols[0], cols[1] + 0.25])
    v = ve[1]
    assert np.degrees(v.registration.rotation) == pytest.approx(0.05, abs=1e-9)
    assert v.decoding.rms_px == pytest.approx(0.25, abs=1e-9)
    assert v.cloud.inside.rms < 1e-7      # inside points untouched
    assert v.cloud.edge_share > 0.99
    # the distance to the surface of a point pushed 0.5 mm along its ray is at most 0.5 mm
    assert 0.05e-3 < v.cloud.edge.rms <= 0.5e-3 + 1e-9
    assert np.degrees(ve[0].registration.rotation) < 1e-9 and ve[0].cloud.all.rms < 1e-7
    # summary.json keeps its keys and units (mm, degrees) and reads back the same values
    from rangekit.formats.sessions.view_errors import ViewErrors

    listed = ve.to_list()
    assert listed[1]["cloud"]["edge"]["rms_mm"] == v.cloud.edge.rms * 1e3
    assert listed[1]["registration"]["rotation_deg"] == pytest.approx(0.05, abs=1e-9)
    assert ViewErrors.from_list(listed).to_list() == listed


@pytest.mark.parametrize("obj", ["lumpy", "shiny", "steps"])
def test_cast_codes_are_cast_views_maps_bit_for_bit(obj):
    """The truth the views are measured against (cast_codes, no shading) is cast_view's depth, projector column
    and object maps, to the bit: on a smooth object, a shiny one and one with shadows and depth jumps."""
    from rangekit.sim.scene.raycast import cast_codes, cast_view

    rig = default_rig()
    cam = rig.camera.resized(320, 256)
    world = default_scene(obj).world_mesh(rig.T_world_rotated(0.9))
    whole, codes = cast_view(world, cam, rig.projector), cast_codes(world, cam, rig.projector)
    assert np.isfinite(codes.proj_col).sum() > 1000 and (codes.object_id == 0).sum() > 1000
    for name in ("depth", "proj_col", "object_id"):
        assert np.array_equal(getattr(codes, name), getattr(whole, name), equal_nan=True), name
    none = cast_codes(world, cam, None)
    assert np.isnan(none.proj_col).all() and np.array_equal(none.depth, whole.depth, equal_nan=True)


def test_the_truth_cast_only_where_the_errors_read_it_is_the_whole_casts_bits():
    """The per-view errors cast only the box's pixels near a cloud point or decoded, and trace the projector's light
    only for the decoded pixels' hits on the object (view_errors._needed): there the depth, projector column and
    object are the whole cast's to the bit, and so are the depth edges at every cloud point's pixel."""
    from rangekit.sim.scene.raycast import cast_view
    from rangekit.sim.truth.view_errors import _EDGE_REACH, _box, _MARGIN, _needed, _truth_in_box

    rig = default_rig()
    cam = rig.camera.resized(320, 256)
    world = default_scene("steps").world_mesh(rig.T_world_rotated(0.9))
    whole = cast_view(world, cam, rig.projector)
    on = whole.lit & (whole.object_id == 0)
    rows, cols = np.nonzero(on)
    keep = (rows + cols) % 3 != 0            # a cloud with holes, and a decoded map with others
    uv = np.column_stack([cols[keep], rows[keep]])
    decoded = np.where(on & ((np.arange(on.size).reshape(on.shape) % 5) != 0), whole.proj_col, np.nan)
    box = _box(uv, cam, _MARGIN)
    cast, light_at = _needed(uv, box, decoded[box])
    assert 0 < cast.sum() < cast.size and light_at.sum() < cast.sum()
    part, edges = _truth_in_box(world, cam, rig.projector, box, cast, light_at)
    full, full_edges = _truth_in_box(world, cam, rig.projector, box)
    assert np.array_equal(part.depth[cast], full.depth[cast], equal_nan=True)
    assert np.array_equal(part.object_id[cast], full.object_id[cast])
    assert np.isnan(part.depth[~cast]).all()
    lit = light_at & (full.object_id == 0)
    assert np.array_equal(part.proj_col[lit], full.proj_col[lit], equal_nan=True)
    assert np.isnan(part.proj_col[~lit]).all() and np.isfinite(part.proj_col[lit]).sum() > 1000
    u, v = uv[:, 0] - box[1].start, uv[:, 1] - box[0].start
    assert np.array_equal(edges[v, u], full_edges[v, u]) and full_edges[v, u].any()
    assert _EDGE_REACH >= 3      # depth_edges looks 1 (3x3 filters) + EDGE_PX (dilations) pixels away
