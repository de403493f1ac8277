"""Accuracy of a scanned mesh against the simulator's true surface.

Two figures, both on uniform (area-weighted) samples of a surface, so a dense patch does not count more:

- **accuracy**: distance from the mesh to the true surface (RMS, 95th percentile, max), sampled on the
  observed part of the mesh: where the closest true-surface point is one the views can see. It
  includes everything: decoding, triangulation, registration drift and fusion. The rest of a watertight
  mesh (under the object, where no view looks) is invented by the fusion; its share of the mesh area
  and its RMS are reported apart.
- **completeness**: the fraction of the *true surface the views can see* that lies within ``tolerance``
  of the mesh. "Can see" is exact: a true-surface sample counts when, in at least one view, it faces
  the camera and the projector, is inside both images, and nothing occludes it from either (rays cast
  from both centres), faces both within ``max_incidence_deg`` (80 degrees: coded light at more
  grazing angles loses pixels to the flying-pixel filter), and it is more than ``table_margin`` above the turntable top (the pipeline drops
  that band so the table does not fuse with the object).

Frames: the mesh is in the session's world, the first view's frame, i.e. the rig's world with the
table at the first view's angle; the truth is moved there with the rig's turntable motion.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from rangekit.errors import InputError
from rangekit.formats.sessions.summary import Accuracy
from rangekit.formats.sessions.view_errors import ViewErrors
from rangekit.geometry import apply_T, cross_rows, invert_T
from rangekit.surface.mesh import TriangleMesh
from rangekit.surface.raycast import mesh_scene, query_scene, raycasting_scene
from rangekit.rig.rig_file import Rig
from rangekit.sim.truth.evaluate_laser import in_image as _inside, laser_visible_samples
from rangekit.sim.scene.raycast import _cast
from rangekit.sim.scene.passes import pass_scene, split_views, view_motions
from rangekit.sim.scene.scene import Scene, default_scene

__all__ = ["Accuracy", "TruthEvaluation", "TruthSamples", "sample_surface", "visible_samples", "truth_samples",
           "mesh_accuracy", "truth_evaluator", "TruthEvaluator"]


def sample_surface(V: np.ndarray, F: np.ndarray, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` area-uniform random points on a triangle mesh: (points (n, 3), face index (n,))."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area = 0.5 * np.linalg.norm(cross_rows(b - a, c - a), axis=1)
    if area.sum() <= 0:
        raise InputError("sample_surface: the mesh has no area")
    face = rng.choice(len(F), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w0, w1, w2 = 1 - s, s * (1 - r2), s * r2
    P = w0[:, None] * a[face] + w1[:, None] * b[face] + w2[:, None] * c[face]
    return P, face


def _seen_from(centre: np.ndarray, P: np.ndarray, N: np.ndarray, cast_scene, eps: float,
               min_cos: float) -> np.ndarray:
    """(n,) bool: P faces ``centre`` (cosine above ``min_cos``) and the first hit along the ray from the
    centre in ``cast_scene`` (an Open3D scene in P's coordinates) is P itself."""
    to_c = centre - P
    dist = np.linalg.norm(to_c, axis=1)
    facing = np.einsum("ij,ij->i", N, to_c) > min_cos * dist
    out = np.zeros(len(P), dtype=bool)
    idx = np.flatnonzero(facing)
    if idx.size:
        t, _ = _cast(cast_scene, np.broadcast_to(centre, (idx.size, 3)), -to_c[idx] / dist[idx, None])
        out[idx] = t >= dist[idx] - eps
    return out


def visible_samples(truth: TriangleMesh, scene: Scene, rig: Rig, angles: np.ndarray, P: np.ndarray,
                    face: np.ndarray, *, eps: float = 1e-5, min_cos: float = 0.0, light: str = "projector") -> np.ndarray:
    """(n,) bool: which true-surface samples ``P`` (frame of the table at angle 0) some view sees lit.

    ``eps`` metres: how much closer than the sample a hit must be to occlude it (float32 ray casting).
    ``min_cos``: the surface must face the camera and the light at least this much (cosine of the
    incidence angle; 0 = any angle short of grazing). ``light``: "projector", or "laser" (the rig's line
    lasers, :func:`rangekit.sim.truth.evaluate_laser.laser_visible_samples`).

    When every object of the scene turns with the table, one ray-casting scene (the table at angle 0)
    serves every view: the camera and projector centres are moved into it instead of the scene to them.
    """
    a, b, c = (truth.vertices[truth.triangles[face, k]] for k in range(3))
    N = cross_rows(b - a, c - a)
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    if light == "laser":
        return laser_visible_samples(scene.world_mesh(np.eye(4)), rig, angles, P, N, eps=eps, min_cos=min_cos)
    seen = np.zeros(len(P), dtype=bool)
    rigid = all(o.on_turntable for o in scene.objects)
    if rigid:
        still = scene.world_mesh(np.eye(4))
        cast_scene = raycasting_scene(still.vertices, still.triangles)
    for angle in angles:
        M = rig.T_world_rotated(float(angle)) if rig.T_world_table is not None else np.eye(4)
        Pk = apply_T(M, P)
        todo = np.flatnonzero(~seen)     # only samples no earlier view saw are projected and cast
        todo = todo[_inside(rig.camera, Pk[todo])]
        todo = todo[_inside(rig.projector, Pk[todo])]
        if todo.size == 0:
            continue
        if rigid:      # cast in the table's frame at angle 0: the samples as given, the centres moved back
            M_inv = invert_T(M)
            Pq, Nq = P[todo], N[todo]
            centres = apply_T(M_inv, np.stack([rig.camera.center, rig.projector.center]))
        else:
            world = scene.world_mesh(M)
            cast_scene = raycasting_scene(world.vertices, world.triangles)
            Pq, Nq = Pk[todo], N[todo] @ M[:3, :3].T
            centres = np.stack([rig.camera.center, rig.projector.center])
        ok = _seen_from(centres[0], Pq, Nq, cast_scene, eps, min_cos)
        todo, Pq, Nq = todo[ok], Pq[ok], Nq[ok]
        ok = _seen_from(centres[1], Pq, Nq, cast_scene, eps, min_cos)
        seen[todo[ok]] = True
    return seen


def _closest_on(mesh: TriangleMesh, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest point of ``mesh`` to each of ``P``: (distance (n,), point (n, 3), face (n,)); Open3D, float32
    inside, relative to the mesh's centre (its scene built once per mesh object)."""
    scene, c = mesh_scene(mesh)
    ans = query_scene(scene, "compute_closest_points", (P - c).astype(np.float32))
    Q = ans["points"].astype(np.float64) + c
    return np.linalg.norm(P - Q, axis=1), Q, ans["primitive_ids"].astype(np.int64)


#: :func:`_within` takes a sample as within the tolerance without asking Open3D when a vertex of the mesh is this
#: much nearer than the tolerance: far more than the float32 query's error (about 1e-8 m), so the answer is the same.
_SURE_MARGIN = 1e-6


def _within(mesh: TriangleMesh, P: np.ndarray, tolerance: float) -> np.ndarray:
    """(n,) bool: ``_closest_on(mesh, P)[0] <= tolerance``, the same answers for less CPU. A point with a vertex of
    the mesh (one of its triangles') within ``tolerance - _SURE_MARGIN`` is within the tolerance (the vertex is
    on the surface): a k-d tree of the vertices answers most of them (79-85% of the 12-view scan's truth samples,
    0.70 + 0.53 -> 0.36 + 0.28 CPU-s, loaded); Open3D's closest-point query answers the rest."""
    from scipy.spatial import cKDTree

    used = np.zeros(len(mesh.vertices), dtype=bool)
    used[mesh.triangles.ravel()] = True
    bound = tolerance - _SURE_MARGIN
    out = np.zeros(len(P), dtype=bool)
    if bound > 0:
        d_vertex, _ = cKDTree(mesh.vertices[used], balanced_tree=False, compact_nodes=False).query(
            P, distance_upper_bound=bound)
        out = d_vertex <= bound
    rest = np.flatnonzero(~out)
    if rest.size:
        out[rest] = _closest_on(mesh, P[rest])[0] <= tolerance
    return out


def _identity(T: np.ndarray) -> bool:
    """``T`` is exactly the identity: moving points by it would change no bit."""
    return bool(np.array_equal(T, np.eye(4)))


@dataclass(frozen=True, eq=False)
class TruthSamples:
    """The mesh-independent half of :func:`mesh_accuracy`, the same for every mesh of one scan: the true
    surface at table angle 0, its uniform samples and which of them the views see."""

    truth: TriangleMesh     # the scene's first object, table at angle 0
    M0: np.ndarray          # (4, 4) the table's motion to the first view's angle (session world)
    samples: np.ndarray     # (n, 3) true-surface samples, table at angle 0
    seen: np.ndarray        # (n,) bool: some view sees the sample (see :func:`mesh_accuracy`)
    observed: Callable      # (P (m, 3), face (m,)) -> (m,) bool, the same rule for any true-surface points


def truth_samples(scene: Scene, rig: Rig, angles, *, table_margin: float = 0.002, max_incidence_deg: float = 80.0,
                  n_samples: int = 200_000, seed: int = 0, light: str = "projector",
                  pass_motions=None) -> TruthSamples:
    """The true surface's samples and their visibility for :func:`mesh_accuracy` (keywords as there).
    A multi-pass scan (``pass_motions`` (P, 4, 4), :mod:`rangekit.sim.scene.passes`; ``angles`` then
    ``(angle, pass)`` pairs): a sample is seen when some pass's views see it with the object turned over
    as in that pass, and above the table margin there."""
    a, vp, F = split_views(angles, pass_motions)
    obj = scene.objects[0]
    M0 = view_motions(rig, angles, pass_motions)[0]
    truth = TriangleMesh(obj.world_vertices(), obj.triangles)
    T_table_world = invert_T(rig.T_world_table) if rig.T_world_table is not None else None

    def observed(P: np.ndarray, face: np.ndarray) -> np.ndarray:
        seen = np.zeros(len(P), dtype=bool)
        for p in np.unique(vp):
            one = p == 0 and _identity(F[p])
            truth_p = truth if one else TriangleMesh(apply_T(F[p], truth.vertices), truth.triangles)
            P_p = P if one else apply_T(F[p], P)
            s = visible_samples(truth_p, scene if one else pass_scene(scene, F[p]), rig, a[vp == p], P_p, face,
                                min_cos=float(np.cos(np.radians(max_incidence_deg))), light=light)
            if T_table_world is not None:
                s &= apply_T(T_table_world, P_p)[:, 2] > table_margin
            seen |= s
        return seen

    rng = np.random.default_rng(seed)
    rng.random(3 * n_samples)   # the mesh's samples come first in the stream (3 n doubles, any mesh)
    Pt, face = sample_surface(truth.vertices, truth.triangles, n_samples, rng)
    return TruthSamples(truth, M0, Pt, observed(Pt, face), observed)


def mesh_accuracy(mesh: TriangleMesh, scene: Scene, rig: Rig, angles, *, tolerance: float = 1e-3,
                  table_margin: float = 0.002, max_incidence_deg: float = 80.0, n_samples: int = 200_000,
                  seed: int = 0, light: str = "projector", cloud: np.ndarray | None = None,
                  truth: TruthSamples | None = None) -> Accuracy:
    """Compare ``mesh`` (session world = the first view's frame) with the scene's first object.

    ``angles``: the turntable angles of the views (radians); the first is the world's angle.
    Accuracy is taken over the *observed* part of the mesh: the samples whose closest true-surface point
    the views can see (the rest of a watertight mesh is filled in where no view looked, under the
    object, and is reported as ``unobserved_area``, with its own RMS). "Can see" means facing the
    camera and the projector within ``max_incidence_deg`` in at least one view, nothing in the way:
    beyond about 80 degrees coded light still decodes but the flying-pixel filter drops part of the
    pixels (docs/tutorial.md gives the measured fractions). ``light="laser"``: lit by one of the rig's
    line lasers instead of the projector. ``cloud`` (N, 3) session world: the scan's merged points, whose
    distances to the true surface give ``cloud_rms`` and ``cloud_p95``. ``truth``: the
    :func:`truth_samples` of the same scene, rig, angles and keywords, computed once for several meshes.
    """
    if truth is None:
        truth = truth_samples(scene, rig, angles, table_margin=table_margin, max_incidence_deg=max_incidence_deg,
                              n_samples=n_samples, seed=seed, light=light)
    rng = np.random.default_rng(seed)
    # The mesh is brought to the truth's frame (table at angle 0) by inv(M0). When that is the identity (the
    # first view at table angle 0, the usual case) the mesh object itself is used: the same coordinates, and
    # the ray-casting scene built here (rangekit.surface.raycast.mesh_scene, when some sample needs Open3D's query
    # in _within) serves the report's renders.
    mesh0 = mesh if _identity(truth.M0) else TriangleMesh(apply_T(invert_T(truth.M0), mesh.vertices), mesh.triangles)
    Pm, _ = sample_surface(mesh0.vertices, mesh0.triangles, n_samples, rng)
    d_mesh, Q, q_face = _closest_on(truth.truth, Pm)
    on_seen = truth.observed(Q, q_face)
    seen = truth.seen
    if not seen.any() or not on_seen.any():
        raise InputError("mesh_accuracy: no view sees the object")
    near = _within(mesh0, truth.samples, tolerance)     # every sample: the whole surface's completeness
    d = d_mesh[on_seen]
    diag = float(np.linalg.norm(np.ptp(truth.truth.vertices, axis=0)))
    d_fill = d_mesh[~on_seen]
    cloud_figures = {}
    if cloud is not None and len(cloud):
        cloud = np.asarray(cloud, dtype=np.float64)
        d_cloud = _closest_on(truth.truth, cloud if _identity(truth.M0) else apply_T(invert_T(truth.M0), cloud))[0]
        cloud_figures = {"cloud_rms": float(np.sqrt(np.mean(d_cloud ** 2))),
                         "cloud_p95": float(np.percentile(d_cloud, 95)), "n_cloud": int(len(d_cloud))}
    return Accuracy(rms=float(np.sqrt(np.mean(d ** 2))), p95=float(np.percentile(d, 95)), max=float(d.max()),
                    completeness=float(np.mean(near[seen])), tolerance=tolerance, diagonal=diag,
                    visible_fraction=float(seen.mean()), unobserved_area=float(np.mean(~on_seen)),
                    unobserved_rms=float(np.sqrt(np.mean(d_fill ** 2))) if d_fill.size else 0.0,
                    rms_all=float(np.sqrt(np.mean(d_mesh ** 2))), max_incidence=float(np.radians(max_incidence_deg)),
                    n_mesh_samples=int(on_seen.sum()), n_truth_samples=int(seen.sum()),
                    completeness_whole=float(np.mean(near)), **cloud_figures)


_TRUTH_OPTIONS = ("table_margin", "max_incidence_deg", "n_samples", "seed", "light", "pass_motions")


@dataclass(frozen=True, eq=False)
class TruthEvaluation:
    """A mesh measured against the simulator's truth."""

    accuracy: Accuracy
    truth: TriangleMesh   # the true surface in the session world (the table at the first view's angle)
    view_errors: ViewErrors | None = None   # per view, where the error comes from (rangekit.sim.truth.view_errors)


def truth_evaluator(obj: str, rig: Rig, **options) -> "TruthEvaluator":
    """The evaluator a simulated session passes to :func:`rangekit.app.process.process.process_session`:
    ``evaluate(mesh, angles)`` measures ``mesh`` (session world) against object ``obj`` (built-in name or
    mesh file, as in :func:`default_scene`) scanned on ``rig`` at turntable ``angles`` (radians), with
    :func:`mesh_accuracy` (``options`` are its keywords)."""
    return TruthEvaluator(default_scene(obj), rig, options)


def _angles_key(angles) -> tuple:
    return tuple(np.asarray(angles, dtype=np.float64).reshape(-1).tolist())


class TruthEvaluator:
    """``evaluate(mesh, angles, cloud=None, views=None)`` -> :class:`TruthEvaluation` (see
    :func:`truth_evaluator`); ``evaluate.prepare(angles, views)`` computes the half that does not depend on
    the mesh ahead: the truth's samples and their visibility, and the per-view errors. Processing runs it
    beside the fusion; a later call with the same angles (and the same ``views`` object) reuses it.

    ``views``: the registered views' ``clouds``, ``T_world_view``, decoded ``proj_cols`` and ``names``
    (:class:`rangekit.app.process.evaluate.RegisteredViewsLike`; :func:`rangekit.sim.truth.view_errors.view_errors`),
    for the per-view error breakdown.
    """

    #: A :class:`rangekit.app.process.evaluate.Truth` that measures (the simulator knows the true surface).
    measures = True

    def __init__(self, scene: Scene, rig: Rig, options: dict) -> None:
        self.scene, self.rig, self.options = scene, rig, dict(options)
        self._key, self._truth, self._views, self._view_errors = None, None, None, None
        self._measured: dict = {}    # view index -> (angles key, cloud, proj_col, its pose-free errors)
        self.views_taken = 0         # views whose errors prepare() took from prepare_view()

    def prepare(self, angles: Sequence[float], views=None) -> None:
        key = _angles_key(angles)
        if self._key != key:
            self._truth = truth_samples(self.scene, self.rig, angles,
                                        **{k: v for k, v in self.options.items() if k in _TRUTH_OPTIONS})
            self._key, self._views, self._view_errors = key, None, None
        if views is not None and views is not self._views:
            from rangekit.sim.truth.view_errors import view_errors

            measured = {k: m[3] for k, m in self._measured.items()
                        if k < len(views.clouds) and m[0] == key and m[1] is views.clouds[k]
                        and m[2] is (views.proj_cols[k] if views.proj_cols else None)}
            errors = view_errors(self.scene, self.rig, angles, views.clouds, views.T_world_view, views.proj_cols,
                                 views.names, pass_motions=self.options.get("pass_motions"), measured=measured)
            self._views, self._view_errors, self._measured = views, errors, {}
            self.views_taken += len(measured)

    def prepare_view(self, angles: Sequence[float], k: int, cloud, proj_col: np.ndarray | None = None) -> None:
        """View ``k``'s errors that its registered pose does not change, measured now (a scan's streaming
        processor, as the view is decoded): :meth:`prepare` with ``views`` holding this very ``cloud`` and
        ``proj_col`` (the same objects) at index ``k`` takes them instead of measuring again."""
        from rangekit.sim.truth.view_errors import view_surface_errors

        errors = view_surface_errors(self.scene, self.rig, angles, k, cloud, proj_col,
                                     pass_motions=self.options.get("pass_motions"))
        self._measured[k] = (_angles_key(angles), cloud, proj_col, errors)

    def __call__(self, mesh: TriangleMesh, angles: Sequence[float], cloud: np.ndarray | None = None,
                 views=None) -> TruthEvaluation:
        self.prepare(angles, views)
        options = {k: v for k, v in self.options.items() if k != "pass_motions"}
        accuracy = mesh_accuracy(mesh, self.scene, self.rig, angles, cloud=cloud, truth=self._truth, **options)
        ob, M0 = self.scene.objects[0], self._truth.M0
        # At the identity, the truth's own mesh object: its scene (built for the accuracy) serves the report.
        truth = self._truth.truth if _identity(M0) else TriangleMesh(apply_T(M0, ob.world_vertices()), ob.triangles)
        return TruthEvaluation(accuracy, truth, self._view_errors if views is not None else None)
