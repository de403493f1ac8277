"""The report's uncertainty section: what a scan says about its own quality, without any truth.

- **View agreement**: the observed mesh coloured by the quality map
  (:func:`rangekit.surface.quality.view_disagreement`): per vertex, the standard deviation of the offsets
  along the normal of the registered views that see it. Noise, registration and calibration errors between
  views show up as views that put the surface at different heights; grey where fewer than two views see it.
- **Coverage**: the observed mesh coloured by how many views see each part (the quality map's ``n_views``),
  with a legend per count.
- **Predicted sigma**: each view's map of the predicted standard deviation of its points along the camera
  ray (:mod:`rangekit.coded.uncertainty`), one colour scale for all views, in the views' rows.

Units in the pictures and text are mm; the computation is in metres in the session world.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["QUALITY_VERTICES", "count_colours", "coverage_section", "mesh_quality", "quality_section", "sigma_scale"]

#: The quality map is computed on at most this many mesh vertices (evenly taken) and shown by nearest
#: vertex: its structure is smooth at that density and the report stays a few seconds.
QUALITY_VERTICES = 60_000
#: A view sees a vertex when its 4 nearest points lie within this many median point spacings of a view.
SEEN_SPACINGS = 3.0


def mesh_quality(vertices: np.ndarray, triangles: np.ndarray, clouds_world: Sequence[np.ndarray], *,
                 normal_sums: np.ndarray | None = None):
    """``(vertices used (M, 3), QualityMap)``: the views' disagreement on up to :data:`QUALITY_VERTICES`
    vertices of the mesh; ``clouds_world`` each view's points (N_i, 3) in the mesh's frame, metres;
    ``normal_sums`` the mesh's :attr:`~rangekit.surface.mesh.TriangleMesh.normal_sums` when computed already."""
    from rangekit.surface.quality import vertex_normals, view_disagreement, view_trees

    normals = vertex_normals(vertices, triangles, sums=normal_sums)
    step = max(1, len(vertices) // QUALITY_VERTICES)
    V, N = vertices[::step], normals[::step]
    trees = view_trees(clouds_world)   # one tree per view: the spacing and the disagreement query it
    # Each view's point spacing: the median distance from a tenth of its points to their nearest other point.
    spacing = [float(np.median(t.query(t.data[::10], k=2)[0][:, 1])) for t in trees if t is not None and t.n > 20]
    radius = SEEN_SPACINGS * float(np.median(spacing))
    return V, view_disagreement(V, N, radius=radius, trees=trees)


def sigma_scale(sigma_maps: Sequence[np.ndarray]) -> float:
    """Metres: the common top of the views' sigma colour scale (99th percentile over all views)."""
    finite = np.concatenate([s[np.isfinite(s)].ravel() for s in sigma_maps] or [np.zeros(0)])
    return float(np.percentile(finite, 99)) if finite.size else 1e-3


def quality_section(mesh, V: np.ndarray, q, *, up: np.ndarray, sides, side_names, size: tuple[int, int]
                    ) -> list[str]:
    """HTML of the view-agreement pictures of ``mesh`` (observed surface, session world) from ``sides``
    (list of (azimuth, elevation) radians), with a colour bar and the figures in the text; ``V, q`` from
    :func:`mesh_quality`."""
    from rangekit.app.report.figures import crop as _crop, figure as _img
    from rangekit.rendering.snapshot import colour_bar

    d = q.disagreement
    seen = np.isfinite(d)
    if not seen.any():
        return ["<h2>Views' agreement</h2><p>No part of the mesh is seen by two views: nothing to compare.</p>"]
    vmax = float(np.percentile(d[seen], 99))
    figs = []
    for name, img in _renders(mesh, V, d, vmax, up=up, sides=sides, side_names=side_names, size=size):
        figs.append(_img(_crop(img), name, alt=f"{name}: disagreement between the views"))
    bar = colour_bar(0.0, vmax * 1e3, label="views' disagreement (std along the normal), mm", cmap="turbo")
    rms = float(np.sqrt(np.mean(d[seen] ** 2)))
    return ["<h2>Views' agreement (no truth needed)</h2>",
            f"<p>Per vertex of the observed mesh, the standard deviation of the heights at which the registered "
            f"views that see it put the surface: RMS {rms * 1e3:.4f} mm, 95th percentile "
            f"{np.percentile(d[seen], 95) * 1e3:.4f} mm, over the {seen.mean():.1%} of the mesh seen by two or "
            "more views (grey: fewer). Noise, registration and calibration errors between views all raise it; "
            "compare with the views' predicted sigma below.</p>",
            f"<div class='row'>{''.join(figs)}</div>", _img(bar, "colour scale")]


def count_colours(counts: np.ndarray, top: int) -> np.ndarray:
    """(..., 3) uint8 RGB of view counts 0..``top`` (``turbo``, 0 dark blue): the coverage map's colours."""
    from rangekit.colour import colourise

    return colourise(np.asarray(counts, dtype=np.float64), 0.0, max(1, top), cmap="turbo")


def coverage_section(mesh, V: np.ndarray, q, *, up: np.ndarray, sides, side_names, size: tuple[int, int]
                     ) -> list[str]:
    """HTML of the coverage-count map: ``mesh`` coloured by how many views see each part (``q.n_views`` on
    the vertices ``V``, :func:`mesh_quality`), from ``sides``, with a legend per count."""
    from rangekit.app.report.figures import crop as _crop, figure as _img
    from rangekit.app.report.viewer import swatch_legend

    counts = q.n_views.astype(np.float64)
    top = max(1, int(counts.max()) if counts.size else 1)
    figs = [_img(_crop(img), name, alt=f"{name}: number of views that see the surface")
            for name, img in _renders(mesh, V, counts, float(top), up=up, sides=sides, side_names=side_names,
                                      size=size, grey_nan=False)]
    shares = np.bincount(q.n_views, minlength=top + 1) / max(1, len(q.n_views))
    legend = swatch_legend(count_colours(np.arange(top + 1), top),
                           [f"{k}: {s:.0%}" for k, s in enumerate(shares)], title="views (share of the mesh):")
    return ["<h2>Coverage (no truth needed)</h2>",
            f"<p>How many views see each part of the observed mesh (a view sees a vertex when its points lie "
            f"within {SEEN_SPACINGS:g} point spacings): {np.mean(q.n_views >= 2):.1%} of the mesh is seen by two or "
            "more views, the rest rests on one view alone (no cross-check).</p>",
            f"<div class='row'>{''.join(figs)}</div>", legend]


def _renders(mesh, V: np.ndarray, values: np.ndarray, vmax: float, *, up, sides, side_names, size, grey_nan=True):
    """(name, image) of ``mesh`` coloured by ``values`` on its vertices ``V`` (nearest), 0 to ``vmax``."""
    from scipy.spatial import cKDTree

    from rangekit.rendering.snapshot import fit_camera, render_values_on_mesh

    tree = cKDTree(V)

    def value(X: np.ndarray) -> np.ndarray:
        return values[tree.query(X, k=1)[1]]

    for (az, el), name in zip(sides, side_names):
        cam = fit_camera(mesh.vertices, azimuth=az, elevation=el, size=size, up=up, tight=True)
        img, vals = render_values_on_mesh(mesh, cam, value, vmin=0.0, vmax=vmax, cmap="turbo", smooth=True)
        if grey_nan:
            img[np.isnan(vals) & np.any(img != 255, axis=2)] = 160   # seen by fewer than two views: grey
        yield name, img
