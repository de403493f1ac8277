"""The thin-plate energy on a triangle mesh: the least-bending surface across free vertices with the rest held.

The energy is ``|M^-1/2 L x|^2`` (cotangent Laplacian ``L``, lumped vertex areas ``M``; Botsch & Kobbelt 2004):
minimising it over free vertices continues the fixed surface's position and slope across them.
:func:`fair` solves it once on given per-face corner positions (the hole patches of
:func:`rangekit.surface.watertight.make_watertight`, measured on their planar disk layout); :func:`thin_plate_band`
builds it on a mesh's own geometry around its free vertices, to be solved many times with other free sets (the
closed mesh's fill in carved space, :func:`rangekit.surface.carve.fill_in_hull`); :func:`ring_band` grows a vertex
set by rings. Units are metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from rangekit.errors import InputError

__all__ = ["cotan_laplacian", "fair", "ring_band", "ThinPlateBand", "thin_plate_band"]


def cotan_laplacian(corners: np.ndarray, F: np.ndarray, n: int, faces: np.ndarray | None = None):
    """Cotangent Laplacian ``Lc`` ((Lc x)_i = sum_j w_ij (x_j - x_i)) and lumped vertex areas of a mesh
    whose face f has corner positions ``corners[f]`` (F, 3, 3); cotangents clipped to [0, 20].

    ``faces`` (F,) bool: only these faces' cotangents enter ``Lc`` (its row of a vertex is exact when all
    the vertex's faces are among them; the other rows are partial). The areas always use every face.
    """
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    mass = np.bincount(F.ravel(), np.repeat(area / 3, 3), minlength=n)
    mass = np.maximum(mass, 1e-3 * np.median(mass[mass > 0]))
    if faces is not None:
        corners, F = corners[faces], F[faces]
    cots = []
    for k in range(3):
        e1 = corners[:, (k + 1) % 3] - corners[:, k]
        e2 = corners[:, (k + 2) % 3] - corners[:, k]
        cross = np.linalg.norm(np.cross(e1, e2), axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            cots.append(np.clip(np.einsum("ij,ij->i", e1, e2) / cross, 0.0, 20.0))
    rows, cols, w = [], [], []
    for k in range(3):  # the cotangent at corner k weighs the opposite edge
        i, j = F[:, (k + 1) % 3], F[:, (k + 2) % 3]
        c = 0.5 * np.nan_to_num(cots[k])
        rows += [i, j]
        cols += [j, i]
        w += [c, c]
    W = sp.coo_matrix((np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    Lc = W - sp.diags(np.asarray(W.sum(axis=1)).ravel())
    return Lc.tocsc(), mass


def fair(corners: np.ndarray, F: np.ndarray, free: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Solve for ``values[free]`` minimising the thin-plate energy ``(Lc x)^T M^-1 (Lc x)``, rest fixed.

    ``Lc``, ``M``: cotangent Laplacian and lumped areas from the per-face ``corners`` (F, 3, 3).
    """
    # Only the rows of the free vertices and their neighbours enter the solve: the cotangents of the faces
    # touching those (a band around the patches, not the whole mesh).
    band = np.zeros(len(values), bool)
    band[F[np.any(free[F], axis=1)]] = True
    Lc, mass = cotan_laplacian(corners, F, len(values), faces=np.any(band[F], axis=1))
    free_idx, fixed_idx = np.flatnonzero(free), np.flatnonzero(~free)
    s = sp.diags(1.0 / np.sqrt(mass))
    Au = (s @ Lc[:, free_idx]).tocsc()
    rhs = -(Au.T @ (s @ (Lc[:, fixed_idx] @ values[fixed_idx])))
    out = values.copy()
    out[free_idx] = splu((Au.T @ Au).tocsc()).solve(np.asarray(rhs))
    return out


def _rings(F: np.ndarray, start: np.ndarray, count: int) -> list[np.ndarray]:
    """``count`` successive (V,) bool rings of vertices around ``start`` (V,) bool, nearest first."""
    rings, seen = [], start.copy()
    for _ in range(count):
        grown = seen.copy()
        grown[F[np.any(seen[F], axis=1)]] = True
        rings.append(grown & ~seen)
        seen = grown
    return rings


def ring_band(triangles: np.ndarray, free: np.ndarray, rings: int) -> np.ndarray:
    """(V,) bool: the ``free`` (V,) bool vertices and the ``rings`` rings of vertices around them (edge-connected
    through ``triangles`` (F, 3))."""
    free = np.asarray(free, dtype=bool)
    return free | np.any(_rings(np.asarray(triangles, np.int64), free, int(rings)), axis=0) if rings > 0 else free


@dataclass(frozen=True, eq=False)
class ThinPlateBand:
    """The thin-plate energy ``|M^-1/2 L x|^2`` over the band of a mesh around its free vertices
    (:func:`thin_plate_band`): ``used`` (B,) the band's vertex ids, ``L`` (B, B) its cotangent Laplacian and
    ``mass`` (B,) its lumped areas (m^2) from the mesh as given, ``rows`` the rows of ``L`` the energy sums (the
    free vertices and their fixed neighbours), ``free`` (B,) bool."""

    used: np.ndarray
    L: sp.csc_matrix
    mass: np.ndarray
    rows: np.ndarray
    free: np.ndarray
    _last: dict = field(default_factory=dict, repr=False)   # the last free set's factorisation

    def solve(self, x: np.ndarray, free: np.ndarray | None = None) -> np.ndarray:
        """(B,) or (B, k) ``x`` (values on the band) with the ``free`` (B,) bool entries (default the band's
        free vertices) replaced by the values minimising the thin-plate energy, the others held."""
        fr = self.free if free is None else np.asarray(free, dtype=bool)
        out = np.array(x, dtype=np.float64)
        fi, fx = np.flatnonzero(fr), np.flatnonzero(~fr)
        if not len(fi):
            return out
        key = fr.tobytes()
        if self._last.get("key") != key:      # the same free set solved again (x, y then z): one factorisation
            w = sp.diags(1.0 / np.sqrt(self.mass[self.rows]))
            Lr = self.L[self.rows]
            A = (w @ Lr[:, fi]).tocsc()
            self._last.update(key=key, A=A, B=(w @ Lr[:, fx]).tocsc(), lu=splu((A.T @ A).tocsc()))
        A, B, lu = self._last["A"], self._last["B"], self._last["lu"]
        out[fi] = lu.solve(np.asarray(A.T @ -(B @ out[fx])))
        return out


def thin_plate_band(vertices: np.ndarray, triangles: np.ndarray, free: np.ndarray) -> ThinPlateBand:
    """The :class:`ThinPlateBand` of the mesh ``vertices`` (V, 3), ``triangles`` (F, 3) around its ``free`` (V,)
    bool vertices: the faces within three rings of them, whose cotangents and areas (the mesh as given) make the
    Laplacian exact on the free vertices and their fixed neighbours. Minimising ``|M^-1/2 L x|^2`` over the
    free vertices continues the fixed surface's position and slope across them (Botsch & Kobbelt 2004)."""
    V, F = np.asarray(vertices, np.float64), np.asarray(triangles, np.int64)
    free = np.asarray(free, dtype=bool)
    if V.ndim != 2 or V.shape[1] != 3 or free.shape != (len(V),):
        raise InputError(f"thin_plate_band: vertices must be (V, 3) and free (V,), found {V.shape} and {free.shape}")
    around = _rings(F, free, 3)
    band = free | np.any(around, axis=0)
    faces = np.any(band[F], axis=1)
    used = np.flatnonzero(np.bincount(F[faces].ravel(), minlength=len(V)) > 0)
    index = np.full(len(V), -1, np.int64)
    index[used] = np.arange(len(used))
    Fb = index[F[faces]]
    L, mass = cotan_laplacian(V[used][Fb], Fb, len(used))
    return ThinPlateBand(used, L, mass, np.flatnonzero(free[used] | around[0][used]), free[used])
