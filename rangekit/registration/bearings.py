"""Localisation from bearings (Fusiello 14.3.3, after Brand et al.): the positions of n views or cameras from the
unit directions between them, their rotations being known, and the test of whether those directions fix them.

Each edge ``e = (i, j)`` gives the unit bearing ``u_e`` of ``c_j - c_i`` in the world frame (a relative
translation whose length is unknown: an essential matrix's, a GPS-less camera network's). The positions satisfy
``u_e x (c_j - c_i) = 0`` for every edge; stacked, ``A c = 0`` with ``A = S (B^T kron I_3)``, ``B`` the (n, m)
incidence matrix (``-1`` at i, ``+1`` at j) and ``S`` the block diagonal of the cross-product matrices ``[u_e]_x``.
With ``c_0 = 0`` (its columns dropped) the positions are the right singular vector of ``A``'s smallest singular
value, of unit norm: known up to scale, as bearings alone can only give. Its sign is fixed by the bearings,
``sum_e u_e . (c_j - c_i) > 0`` (the book's listing uses the first edge; the two agree unless that edge disagrees
with the others).

The solution is unique (up to scale) only when the graph is *parallel rigid*: every parallel redrawing of it
(positions whose edges keep their directions) is a translation and scaling of it. :func:`localisability` tests
this on the graph with generic positions (a property of the graph: random positions, seeded) through the null
space of ``A``: a node belongs to the rigid component of an edge ``(a, b)`` when every null vector moves it as
the translation and scaling that edge dictates. The nodes outside the largest component are named.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import InputError, RegistrationError

__all__ = ["BearingLocation", "Localisability", "locate_from_bearings", "localisability"]

_RANK_TOL = 1e-10       # eigenvalues of A^T A below this fraction of the largest count as zero (generic positions)
_MEMBER_TOL = 1e-7      # a node moves with its component when its null-vector residual is below this


@dataclass(frozen=True)
class Localisability:
    """Whether bearings on this graph fix every node (up to one global translation and scale).

    ``fixed``: the nodes of the largest parallel-rigid component; ``not_fixed``: the others (ascending)."""

    localisable: bool
    fixed: tuple[int, ...]
    not_fixed: tuple[int, ...]


@dataclass(frozen=True, eq=False)
class BearingLocation:
    """Positions from bearings: ``positions`` (n, 3), node 0 at the origin, ``sum |c_i|^2 = 1`` (the scale is not
    observable); ``edge_angle_error`` (m,) radians between each bearing and the fitted ``c_j - c_i``; lower is
    better; ``singular_values`` the two smallest of ``A`` (a gap between them: a well-fixed solution)."""

    positions: np.ndarray
    edge_angle_error: np.ndarray
    singular_values: tuple[float, float]


def _parse(bearings, edges, n: int | None) -> tuple[np.ndarray, np.ndarray, int]:
    u = np.asarray(bearings, dtype=np.float64)
    e = np.asarray(edges)
    if u.ndim != 2 or u.shape[1] != 3:
        raise InputError(f"bearings: expected an (m, 3) array of unit directions, found shape {u.shape}")
    if e.ndim != 2 or e.shape[1] != 2 or len(e) != len(u):
        raise InputError(f"edges: expected an ({len(u)}, 2) array of node pairs (i, j), one per bearing, found shape "
                         f"{e.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(u), axis=1))
    if len(bad):
        raise InputError(f"bearings: row {bad[0]} is {u[bad[0]].tolist()}; expected finite numbers "
                         f"({len(bad)} row(s) with NaN or infinity)")
    norms = np.linalg.norm(u, axis=1)
    if np.any(norms < 1e-12):
        k = int(np.argmin(norms))
        raise InputError(f"bearings: row {k} is the zero vector; expected a direction")
    if not np.issubdtype(e.dtype, np.integer) and not (np.all(np.isfinite(e)) and np.all(e == np.round(e))):
        raise InputError("edges: expected whole node numbers")
    e = e.astype(np.int64)
    n = int(e.max()) + 1 if n is None and len(e) else int(n or 0)
    if len(e) == 0 or e.min() < 0 or e.max() >= n:
        raise InputError(f"edges: node numbers must lie in 0..{n - 1}, found {e.min() if len(e) else 'none'}.."
                         f"{e.max() if len(e) else 'none'}")
    loops = np.flatnonzero(e[:, 0] == e[:, 1])
    if len(loops):
        raise InputError(f"edges: edge {loops[0]} joins node {e[loops[0], 0]} to itself")
    return u / norms[:, None], e, n


def _system(u: np.ndarray, e: np.ndarray, n: int) -> np.ndarray:
    """(3m, 3n) ``A``: rows 3k..3k+2 are ``[u_k]_x (c_j - c_i)`` for edge k = (i, j)."""
    m = len(u)
    skew = np.zeros((m, 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -u[:, 2], u[:, 1], -u[:, 0]
    skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = u[:, 2], -u[:, 1], u[:, 0]
    A = np.zeros((m, 3, n, 3))
    rows = np.arange(m)
    A[rows, :, e[:, 1], :] += skew
    A[rows, :, e[:, 0], :] -= skew
    return A.reshape(3 * m, 3 * n)


def localisability(n: int, edges, *, seed: int = 0) -> Localisability:
    """Whether bearings along ``edges`` ((m, 2) node pairs) fix all ``n`` nodes, generically (module doc); the nodes
    of the largest parallel-rigid component and the others. Isolated nodes are never fixed."""
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    rng = np.random.default_rng(seed)
    p = rng.standard_normal((n, 3))
    d = p[e[:, 1]] - p[e[:, 0]]
    A = _system(d / np.linalg.norm(d, axis=1)[:, None], e, n)
    w, vectors = np.linalg.eigh(A.T @ A)          # (3n, 3n): the null space of A is that of A^T A
    null = vectors[:, w <= _RANK_TOL * max(w.max(initial=0.0), 1e-300)].T      # (k, 3n): parallel redrawings
    V = null.reshape(len(null), n, 3)
    best: np.ndarray | None = None
    for a, b in {(int(min(i, j)), int(max(i, j))) for i, j in e}:
        dab = p[b] - p[a]
        lam = np.einsum("kx,x->k", V[:, b] - V[:, a], dab) / (dab @ dab)          # each redrawing's scale
        r = V - V[:, a:a + 1] - lam[:, None, None] * (p - p[a])[None]
        member = np.max(np.linalg.norm(r, axis=2), axis=0) < _MEMBER_TOL
        if best is None or member.sum() > best.sum():
            best = member
        if best.all():
            break
    if best is None:
        best = np.zeros(n, bool)
    fixed = tuple(int(i) for i in np.flatnonzero(best))
    return Localisability(bool(best.all()), fixed, tuple(int(i) for i in np.flatnonzero(~best)))


def locate_from_bearings(bearings, edges, n: int | None = None) -> BearingLocation:
    """Positions of ``n`` nodes (default: the largest node number + 1) from unit ``bearings`` (m, 3), world frame,
    of ``c_j - c_i`` for ``edges`` (m, 2) ``(i, j)`` (module doc). Node 0 at the origin, unit overall norm.

    Raises
    ------
    InputError
        Bearings with NaN or infinity or of zero length, edges out of range or joining a node to itself (named).
    RegistrationError
        The graph is not parallel rigid: the error names the nodes the bearings do not fix.
    """
    u, e, n = _parse(bearings, edges, n)
    test = localisability(n, e)
    if not test.localisable:
        shown = ", ".join(map(str, test.not_fixed[:20])) + (" ..." if len(test.not_fixed) > 20 else "")
        raise RegistrationError(f"bearings: node(s) {shown} not fixed by the bearings (the graph is not parallel "
                                f"rigid: {len(test.fixed)} of {n} nodes form its largest rigid part); add bearings "
                                "linking them to the rest")
    A = _system(u, e, n)[:, 3:]                     # c_0 = 0: node 0's columns dropped
    _, s, Vt = np.linalg.svd(A, full_matrices=False)
    c = np.vstack([np.zeros(3), Vt[-1].reshape(n - 1, 3)])
    diff = c[e[:, 1]] - c[e[:, 0]]
    if np.sum(u * diff) < 0:
        c, diff = -c, -diff
    cosine = np.sum(u * diff, axis=1) / np.maximum(np.linalg.norm(diff, axis=1), 1e-300)
    angle = np.arccos(np.clip(cosine, -1.0, 1.0))
    return BearingLocation(c, angle, (float(s[-1]), float(s[-2]) if len(s) > 1 else float("nan")))
