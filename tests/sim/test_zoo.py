"""The simulator's object zoo against its analytic truth: fin, pin, slot and step sizes by exact
ray casts, the bowl's spheres, watertight outward meshes standing on the plate, the bunny upright, and
``rangekit sim objects`` / ``rangekit sim render --object thin``."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from rangekit.app.commands.sim_objects import list_objects
from rangekit.cli import main
from rangekit.errors import InputError, SceneError
from rangekit.geometry import R_up_to_z
from rangekit.rig.rig_file import save_rig
from rangekit.sim import default_scene, make_object
from rangekit.sim.scene import zoo
from rangekit.sim.scene.objects import BUILTIN_OBJECTS, OBJECT_NOTES, lumpy
from support.small_rigs import small_rig

MM = 1e-3
ZOO = ("thin", "bowl", "steps", "shiny", "dark")


def hits(obj, origin, direction) -> np.ndarray:
    """Sorted distances along the ray at which it crosses the object's triangles (exact, float64
    Moller-Trumbore over every triangle; a hit on a shared edge counts once)."""
    v = obj.vertices[obj.triangles]
    o, d = np.asarray(origin, float), np.asarray(direction, float) / np.linalg.norm(direction)
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-18
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - v[:, 0]
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    w = (q @ d) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    good = ok & (u >= -1e-12) & (w >= -1e-12) & (u + w <= 1 + 1e-12) & (t > 0)
    t = np.sort(t[good])
    return t[np.r_[True, np.diff(t) > 1e-9]] if len(t) else t


@pytest.mark.parametrize("name", ZOO)
def test_zoo_meshes_are_watertight_outward_and_stand_on_the_plate(name):
    obj = make_object(name)
    m = trimesh.Trimesh(obj.vertices, obj.triangles)   # vertices merged: the topology, not the file order
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume > 0                                 # outward normals: positive signed volume
    if name in ("thin", "bowl", "steps"):
        assert obj.vertices[:, 2].min() == 0.0         # built standing on z = 0
    placed = default_scene(name).objects[0]
    assert placed.world_vertices()[:, 2].min() == pytest.approx(0.0, abs=1e-15)


def test_thin_fins_pins_and_slot_by_ray_casts():
    obj = zoo.thin()
    # Along +x at mid height through the comb: fin 1 (1 mm), fin 2 (2 mm), block, slot (2 mm), block.
    t = hits(obj, [-0.01, 0.0, 0.02], [1, 0, 0]) - 0.01
    np.testing.assert_allclose(t, np.array([10, 11, 20, 22, 40, 46, 48, 54]) * MM, atol=1e-12)
    assert t[1] - t[0] == pytest.approx(zoo.THIN_FINS[0], abs=1e-12)
    assert t[3] - t[2] == pytest.approx(zoo.THIN_FINS[1], abs=1e-12)
    assert t[6] - t[5] == pytest.approx(zoo.THIN_SLOT[0], abs=1e-12)
    # Down into the slot: its floor is 22 mm below the blocks' tops (30 mm).
    assert 0.1 - hits(obj, [0.047, 0.0, 0.1], [0, 0, -1])[0] == pytest.approx(0.030 - zoo.THIN_SLOT[1], abs=1e-12)
    # Fins 40 mm, base 8 mm tall; the comb 30 mm deep.
    assert 0.1 - hits(obj, [0.0105, 0.0, 0.1], [0, 0, -1])[0] == pytest.approx(0.040, abs=1e-12)
    assert 0.1 - hits(obj, [0.005, 0.0, 0.1], [0, 0, -1])[0] == pytest.approx(0.008, abs=1e-12)
    np.testing.assert_allclose(hits(obj, [0.03, -0.1, 0.004], [0, 1, 0]) - 0.1,
                               [-0.022 - 0.001, -0.022 + 0.001, -0.015, 0.015], atol=1e-12)
    # Each pin: 2 mm across through its axis, every side vertex on the 1 mm circle, 30 mm tall.
    for x in (0.010, 0.030, 0.050):
        t = hits(obj, [x - 0.01, -0.022, 0.015], [1, 0, 0])[:2] - 0.01     # the nearest pin
        np.testing.assert_allclose(t, [-zoo.THIN_PIN_DIAMETER / 2, zoo.THIN_PIN_DIAMETER / 2], atol=1e-12)
        assert 0.1 - hits(obj, [x, -0.022, 0.1], [0, 0, -1])[0] == pytest.approx(0.030, abs=1e-12)
        near = np.hypot(obj.vertices[:, 0] - x, obj.vertices[:, 1] + 0.022) < 0.0015
        r = np.hypot(obj.vertices[near, 0] - x, obj.vertices[near, 1] + 0.022)
        np.testing.assert_allclose(r[r > 0], zoo.THIN_PIN_DIAMETER / 2, atol=1e-15)
    # Volume: the comb's profile (840 mm^2 x 30 mm) and three 48-gon pins.
    pins = 3 * 0.5 * 48 * (0.001**2) * np.sin(2 * np.pi / 48) * 0.030
    assert trimesh.Trimesh(obj.vertices, obj.triangles).volume == pytest.approx(840e-6 * 0.030 + pins, rel=1e-12)


def test_steps_heights_are_exact_and_edges_sharp():
    obj = zoo.steps()
    for k, h in enumerate(zoo.STEP_HEIGHTS):
        x = (k + 0.5) * 0.015
        assert 0.1 - hits(obj, [x, 0.0, 0.1], [0, 0, -1])[0] == pytest.approx(h, abs=1e-15)
    assert np.diff(zoo.STEP_HEIGHTS) == pytest.approx([0.005] * 3)
    assert not obj.smooth                      # flat shading: the edges stay sharp in the images
    normals = obj.face_normals()
    assert np.all(np.isclose(np.abs(normals).max(axis=1), 1.0))   # every face axis-aligned: 90 degree edges
    assert trimesh.Trimesh(obj.vertices, obj.triangles).volume == pytest.approx(0.015 * 0.050 * 0.040, rel=1e-12)


def test_bowl_inner_and_outer_spheres():
    obj = zoo.bowl()
    ro, ri, zc = 0.06, 0.05, 0.056
    r = np.linalg.norm(obj.vertices - [0, 0, zc], axis=1)
    on_axis = np.hypot(obj.vertices[:, 0], obj.vertices[:, 1]) < 1e-12
    outer, inner = np.isclose(r, ro, atol=1e-12), np.isclose(r, ri, atol=1e-12)
    foot = obj.vertices[:, 2] == 0
    assert np.all(outer | inner | (foot & on_axis)) and outer.sum() > 1000 and inner.sum() > 1000
    # Ray casts: across the top through the axis, the wall is 10 mm thick on each side; the inside floor
    # is 6 mm above the plate; horizontally 20 mm below the rim it meets both spheres (profile chords
    # sag at most 0.007 mm).
    np.testing.assert_allclose(hits(obj, [-0.1, 0, zc - 1e-4], [1, 0, 0]) - 0.1,
                               [-np.sqrt(ro**2 - 1e-8), -np.sqrt(ri**2 - 1e-8), np.sqrt(ri**2 - 1e-8),
                                np.sqrt(ro**2 - 1e-8)], atol=1e-5)
    assert 0.1 - hits(obj, [0, 0, 0.1], [0, 0, -1])[0] == pytest.approx(zc - ri, abs=1e-12)
    np.testing.assert_allclose(hits(obj, [0, 0, zc - 0.02], [1, 0, 0]),
                               [np.sqrt(ri**2 - 0.02**2), np.sqrt(ro**2 - 0.02**2)], atol=1e-5)
    # Volume: the outer sphere below its centre less its bottom 4 mm, minus the inner hemisphere.
    truth = np.pi * (ro**2 * zc - zc**3 / 3) - 2 / 3 * np.pi * ri**3
    assert trimesh.Trimesh(obj.vertices, obj.triangles).volume == pytest.approx(truth, rel=2e-3)
    with pytest.raises(SceneError, match="inner_radius"):
        zoo.bowl(inner_radius=0.06)


def test_shiny_and_dark_are_lumpy_materials():
    blob, shiny, dark = lumpy(), make_object("shiny"), make_object("dark")
    for obj in (shiny, dark):
        assert np.array_equal(obj.vertices, blob.vertices) and np.array_equal(obj.triangles, blob.triangles)
    # The lobe's peak (k_s) is above full scale: highlights saturate; dark's albedo is 0.05.
    assert shiny.specular >= 1.0 and shiny.specular > 2 * shiny.vertex_albedo.max()
    assert np.all(dark.vertex_albedo == 0.05)


def test_every_builtin_has_a_note_and_the_listing():
    assert set(OBJECT_NOTES) == set(BUILTIN_OBJECTS)
    rows = {r.name: r for r in list_objects()}
    assert rows["steps"].size_mm == pytest.approx((60, 40, 20)) and rows["steps"].triangles == 48
    assert rows["bowl"].size_mm == pytest.approx((120, 120, 56))
    assert rows["thin"].size_mm == pytest.approx((60, 38, 40))


def test_sim_objects_command_prints_each_object(capsys):
    assert main(["sim", "objects"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert "triangles" in out[0]
    for name in BUILTIN_OBJECTS:
        line = next(line for line in out if line.split()[0] == name)
        assert OBJECT_NOTES[name] in line
    assert "60 x 40 x 20" in next(line for line in out if line.startswith("steps"))


def test_sim_render_object_thin(tmp_path):
    rig_file = tmp_path / "rig.json"
    save_rig(small_rig(), rig_file)
    out = tmp_path / "cap"
    assert main(["sim", "render", "--object", "thin", "--rig", str(rig_file), "--patterns", "white",
                 "--out", str(out)]) == 0
    assert (out / "000.png").is_file() and (out / "preview.png").is_file()
    gt = np.load(out / "ground_truth.npz")
    assert gt["valid"].shape == (256, 320)
    z = gt["xyz"][gt["valid"]][:, 2]
    assert z.max() == pytest.approx(0.040, abs=1e-9)   # the fins' tops are seen and lit
    assert np.count_nonzero(z > 0.001) > 300


def test_R_up_to_z_turns_up_onto_z():
    for up in ([0, 1, 0], [0, 0, 1], [0, 0, -2], [1, 2, 3], [1e-9, 0, -1]):
        R = R_up_to_z(up)
        np.testing.assert_allclose(R @ (np.array(up, float) / np.linalg.norm(up)), [0, 0, 1], atol=1e-12)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R_up_to_z([0, 1, 0]) @ [0, 0, 1], [0, -1, 0], atol=1e-15)
    with pytest.raises(InputError, match="up"):
        R_up_to_z([0, 0, 0])


def test_bunny_missing_is_a_scene_error_naming_the_path(tmp_path, monkeypatch):
    monkeypatch.setattr(zoo, "data_folders", lambda: [tmp_path])
    with pytest.raises(SceneError, match=str(tmp_path / zoo.BUNNY_FILE)):
        make_object("bunny")
    row = next(r for r in list_objects() if r.name == "bunny")
    assert row.size_mm is None and str(tmp_path) in row.unavailable


def test_bunny_stands_upright_on_the_plate():
    path = zoo.bunny_path()
    if not path.is_file():
        pytest.skip(f"{path} not found (the shared data folder)")
    from rangekit.formats.meshes import load_mesh

    raw = load_mesh(path)
    obj = make_object("bunny")
    assert len(obj.triangles) == len(raw.triangles) == 69451
    # +y became +z: the upright z extent is the file's y extent, the file's z runs along -y.
    assert np.ptp(obj.vertices[:, 2]) == pytest.approx(np.ptp(raw.vertices[:, 1]), abs=1e-12)
    np.testing.assert_allclose(obj.vertices[:, 1], -raw.vertices[:, 2], atol=1e-12)
    np.testing.assert_allclose(obj.vertices[:, 0], raw.vertices[:, 0], atol=1e-12)
    assert obj.vertices[:, 2].min() == 0.0
    # The ears (the file's top in y) are at the top.
    assert np.argmax(obj.vertices[:, 2]) == np.argmax(raw.vertices[:, 1])
    assert default_scene("bunny").objects[0].world_vertices()[:, 2].min() == pytest.approx(0.0, abs=1e-15)
