"""The unobserved part of a closed mesh filled by the thin-plate energy, held on the table top and out of carved
space (rangekit.surface.carve.fill_in_hull, close_in_hull) against analytic truths: a sphere whose bottom cap is
a hole, its rim bent as Poisson's surface bends at the edge of its data, and a sphere sunk under the table top."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from rangekit.errors import InputError
from rangekit.surface.carve import RIM_RINGS, CarvedSpace, close_in_hull, fill_in_hull
from rangekit.surface.thin_plate import ring_band

R = 0.05       # metres
VOXEL = 0.001


def _sphere(centre_z: float, cap_deg: float):
    """An icosphere of radius R about (0, 0, centre_z) (table frame = world), its bottom cap (``cap_deg`` from the
    bottom pole) free, and that cap's guess: flattened onto the plane of its rim (as far off as a guess goes)."""
    m = trimesh.creation.icosphere(subdivisions=5, radius=R)
    V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    free = V[:, 2] < -R * np.cos(np.radians(cap_deg))
    guess = V.copy()
    guess[free, 2] = -R * np.cos(np.radians(cap_deg))
    return V + [0, 0, centre_z], guess + [0, 0, centre_z], F, free


def _space(carved_above: float | None = None) -> CarvedSpace:
    """A grid around the sphere, carved under the table top (its two lowest layers, as :func:`carve` makes them)
    and, with ``carved_above``, everything above that height (metres, table frame)."""
    origin = np.array([-0.07, -0.07, -1.5 * VOXEL])
    shape = (141, 141, 130)
    carved = np.zeros(shape, dtype=bool)
    carved[:, :, :2] = True
    if carved_above is not None:
        carved[:, :, origin[2] + np.arange(shape[2]) * VOXEL > carved_above] = True
    return CarvedSpace(np.eye(4), origin, VOXEL, carved)


def _radial_error(V, free, centre_z):
    return np.abs(np.linalg.norm(V[free] - [0, 0, centre_z], axis=1) - R)


def test_a_flattened_cap_comes_back_onto_the_sphere():
    V, guess, F, free = _sphere(0.06, 40.0)
    assert _radial_error(guess, free, 0.06).max() > 0.2 * R * (1 - np.cos(np.radians(40)))   # the guess: mm off
    out = fill_in_hull(guess, F, free, _space())
    err = _radial_error(out, free, 0.06)
    # the slope of the rim continued over a 40-degree cap of the flat guess's metric: 1.5 mm at most, 0.65 mm RMS
    # (the flat guess 11.7 mm at most)
    assert err.max() < 0.002 and np.sqrt(np.mean(err ** 2)) < 0.0008, (err.max(), np.sqrt(np.mean(err ** 2)))
    assert np.array_equal(out[~free], guess[~free])          # the fixed vertices never move


def test_a_bent_rim_is_filled_again():
    """Poisson's surface at the edge of its data bends towards its guess; close_in_hull fills the rim's rings
    again, from where the surface is right."""
    V, guess, F, free = _sphere(0.06, 40.0)
    rim = ring_band(F, free, RIM_RINGS) & ~free
    bent = guess.copy()
    bent[rim, 2] -= 0.003 * (bent[rim, 2] < 0.06 - R * np.cos(np.radians(40)) + 0.004)   # the first rings pulled down
    alone = fill_in_hull(bent, F, free, _space())
    out, on_hull = close_in_hull(bent, F, free, _space())
    e_alone = _radial_error(alone, free, 0.06)
    e_rim = _radial_error(out, free | rim, 0.06)
    # the bent slope continued: 1.9 mm RMS; the rim filled again with the cap: 1.2 mm RMS over both
    assert np.sqrt(np.mean(e_alone ** 2)) > 0.0015
    assert np.sqrt(np.mean(e_rim ** 2)) < 0.7 * np.sqrt(np.mean(e_alone ** 2)), (e_alone.max(), e_rim.max())
    assert not on_hull[~free].any()


def test_the_fill_stays_on_the_table_top():
    """A sphere sunk 15 mm under the table top: the fill of its bottom lies on the table where the sphere is under
    it, and near the sphere elsewhere (1.7 mm RMS from the cut sphere, the flat guess's metric)."""
    V, guess, F, free = _sphere(R - 0.015, 60.0)
    out = fill_in_hull(guess, F, free, _space())
    z = out[free, 2]
    assert z.min() >= 0.0 and np.sum(z == 0.0) > 20
    # distance to the solid's boundary: the sphere cut by the table plane
    truth_z = np.maximum(V[free, 2], 0.0)
    assert np.sqrt(np.mean((z - truth_z) ** 2)) < 0.0025, np.sqrt(np.mean((z - truth_z) ** 2))


def test_the_fill_stays_out_of_carved_space():
    V, guess, F, free = _sphere(0.06, 40.0)
    space = _space(carved_above=0.06 - R * np.cos(np.radians(40)) - 0.003)   # nothing lower than 3 mm under the rim
    out, _ = close_in_hull(guess, F, free, space)
    assert space.depth_inside(out[free]).max() <= 0.5 * VOXEL


def test_observed_vertices_a_view_saw_through_are_held_out_onto_the_hull():
    """The sphere's top 2.5 mm lie in carved space (a view saw empty space there; the points put the surface 2.5
    voxels deep): those observed vertices go onto the hull (the plane the carving left), counted on it; the other
    observed vertices away from the cap's rim stay where they were."""
    V, guess, F, free = _sphere(0.06, 40.0)
    top = 0.06 + R - 0.0025
    space = _space(carved_above=top)
    deep = ~free & (space.depth_inside(guess) > VOXEL)
    assert deep.sum() > 50 and space.depth_inside(guess).max() > 1.5 * VOXEL
    out, on_hull = close_in_hull(guess, F, free, space)
    assert space.depth_inside(out).max() <= VOXEL, space.depth_inside(out).max()
    assert on_hull[deep].all()
    assert np.abs(out[deep, 2] - top).max() < VOXEL, np.abs(out[deep, 2] - top).max()
    kept = ~free & ~ring_band(F, free, RIM_RINGS) & (guess[:, 2] < top - 2 * VOXEL)
    assert np.array_equal(out[kept], guess[kept]) and not on_hull[kept].any()


def test_shapes_are_checked():
    with pytest.raises(InputError, match="fill_in_hull"):
        fill_in_hull(np.zeros((4, 3)), np.zeros((1, 3), np.int64), np.zeros(3, bool), _space())
