"""The view graph of a synchronisation problem: edges ``(i, j, T_i_j)`` checked and stored as arrays, and
the graph questions the robust scheme asks (connectivity to view 0, bridges, triangles).

See :mod:`rangekit.registration.sync` for the conventions (``T_i_j`` maps view j's points into view i's
frame).
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from rangekit.errors import InputError, RegistrationError
from rangekit.geometry import nearest_rotation

__all__ = ["ViewGraph", "ViewsCutOff", "EdgesDisagree", "parse_view_graph", "check_connected", "check_rejection",
           "triangles", "edges_connect_views", "cut_off_message"]


class ViewsCutOff(RegistrationError):
    """The robust scheme rejected edges until ``views`` (sorted view indices) lost every confirmed link to
    view 0. Callers that can measure more edges (more pairs, a finer level) catch it and try again."""

    def __init__(self, message: str, views: list[int]):
        super().__init__(message)
        self.views = list(views)


class EdgesDisagree(ViewsCutOff):
    """The views were connected, but the robust scheme found their edges inconsistent and rejected them."""


class ViewGraph(NamedTuple):
    """n views and E measured edges (view indices ``I[e]``, ``J[e]``)."""

    n: int
    I: np.ndarray   # (E,) int
    J: np.ndarray   # (E,) int
    R: np.ndarray   # (E, 3, 3) measured R_ij
    t: np.ndarray   # (E, 3) measured t_ij
    w: np.ndarray   # (E,) user weights


def parse_view_graph(n, edges, weights, max_iterations: int = 1) -> ViewGraph:
    """Check the arguments of the synchronise functions (``edges``: sequence of ``(i, j, T_i_j)`` or a dict
    ``{(i, j): T_i_j}``; ``weights``: (E,) non-negative or None) and return the graph."""
    if not (isinstance(max_iterations, (int, np.integer)) and max_iterations >= 1):
        raise InputError(f"sync: max_iterations must be an integer >= 1, found {max_iterations!r}")
    if not (isinstance(n, (int, np.integer)) and n >= 2):
        raise InputError(f"sync: n must be an integer number of views >= 2, found {n!r}")
    n = int(n)
    items = [(k[0], k[1], v) for k, v in edges.items()] if isinstance(edges, dict) else list(edges)
    if not items:
        raise InputError("sync: no edges given; pass a sequence of (i, j, T_i_j)")
    I, J, Ts = [], [], []
    seen: dict[tuple[int, int], int] = {}
    for e, item in enumerate(items):
        try:
            i, j, T = item
            i, j = int(i), int(j)
            T = np.asarray(T, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(f"sync: edge {e} must be (i, j, T_i_j) with a (4, 4) T_i_j ({exc})") from exc
        if not (0 <= i < n and 0 <= j < n) or i == j:
            raise InputError(f"sync: edge {e} joins views ({i}, {j}); both must be distinct and in [0, {n})")
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise InputError(f"sync: edge {e} ({i}, {j}): T_i_j must be a finite (4, 4) array, found shape "
                             f"{T.shape}")
        A = T[:3, :3]
        if np.abs(A.T @ A - np.eye(3)).max() > 1e-6 or np.linalg.det(A) <= 0:
            raise InputError(f"sync: edge {e} ({i}, {j}): the 3x3 block of T_i_j is not a rotation "
                             f"(|R^T R - I| = {np.abs(A.T @ A - np.eye(3)).max():.1e}, det = "
                             f"{np.linalg.det(A):.4f}); relative poses must be rigid")
        key = (min(i, j), max(i, j))
        if key in seen:
            raise InputError(f"sync: edges {seen[key]} and {e} both join views {key}; give one measurement "
                             f"per pair (average them first)")
        seen[key] = e
        I.append(i)
        J.append(j)
        Ts.append(T)
    Ts = np.stack(Ts)
    E = len(Ts)
    if weights is None:
        w = np.ones(E)
    else:
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if w.shape != (E,) or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise InputError(f"sync: weights must be {E} finite non-negative numbers (one per edge), found "
                             f"shape {w.shape}")
    R = np.stack([nearest_rotation(A) for A in Ts[:, :3, :3]])
    return ViewGraph(n, np.array(I), np.array(J), R, Ts[:, :3, 3].copy(), w)


def _unreached(n: int, I: np.ndarray, J: np.ndarray, active: np.ndarray) -> list[int]:
    """Views not connected to view 0 through active edges."""
    A = sp.coo_matrix((np.ones(int(active.sum())), (I[active], J[active])), shape=(n, n))
    _, labels = connected_components(A, directed=False)
    return np.flatnonzero(labels != labels[0]).tolist()


def check_connected(g: ViewGraph, active: np.ndarray) -> None:
    """InputError unless every view reaches view 0 through ``active`` edges."""
    cut = _unreached(g.n, g.I, g.J, active)
    if cut:
        raise InputError(f"sync: views {cut} are not connected to view 0 by edges with positive weight; "
                         f"their poses are not determined. Add edges to them or drop them")


def _bridges(n: int, I: np.ndarray, J: np.ndarray, active: np.ndarray) -> np.ndarray:
    """(E,) bool: active edges whose removal disconnects the active graph (iterative Tarjan)."""
    adj: list[list[tuple[int, int]]] = [[] for _ in range(n)]
    for e in np.flatnonzero(active).tolist():
        adj[I[e]].append((int(J[e]), e))
        adj[J[e]].append((int(I[e]), e))
    disc = [-1] * n
    low = [0] * n
    bridge = np.zeros(len(I), dtype=bool)
    timer = 0
    for root in range(n):
        if disc[root] >= 0:
            continue
        disc[root] = low[root] = timer
        timer += 1
        stack = [(root, -1, 0)]
        while stack:
            v, parent_edge, k = stack[-1]
            if k < len(adj[v]):
                stack[-1] = (v, parent_edge, k + 1)
                u, e = adj[v][k]
                if e == parent_edge:
                    continue
                if disc[u] < 0:
                    disc[u] = low[u] = timer
                    timer += 1
                    stack.append((u, e, 0))
                else:
                    low[v] = min(low[v], disc[u])
            else:
                stack.pop()
                if stack:
                    p = stack[-1][0]
                    low[p] = min(low[p], low[v])
                    if low[v] > disc[p]:
                        bridge[parent_edge] = True
    return bridge


def check_rejection(g: ViewGraph, active: np.ndarray, inlier: np.ndarray) -> None:
    """After the inlier test every view must still reach view 0 through edges confirmed by a cycle.

    An edge that closed a cycle in the input but is a bridge among the inliers has a zero residual
    whatever its value: nothing confirms it any more (e.g. a view whose two edges disagree keeps one of
    them at random). Such edges do not count as a connection.
    """
    unconfirmed = _bridges(g.n, g.I, g.J, inlier) & ~_bridges(g.n, g.I, g.J, active)
    cut = _unreached(g.n, g.I, g.J, inlier & ~unconfirmed)
    if cut:
        raise EdgesDisagree(
            f"sync: after rejecting {int((active & ~inlier).sum())} outlier edges, views {cut} are no longer "
            f"connected to view 0 by edges that a cycle confirms; their measurements disagree with each "
            f"other and with the rest. Add edges to them, or use robust=False", cut)


def triangles(g: ViewGraph) -> np.ndarray:
    """(K, 3) edge indices (ab, bc, ac) of every triangle a < b < c in the graph."""
    key = {(min(i, j), max(i, j)): e for e, (i, j) in enumerate(zip(g.I.tolist(), g.J.tolist()))}
    nbrs: list[set[int]] = [set() for _ in range(g.n)]
    for a, b in key:
        nbrs[a].add(b)
        nbrs[b].add(a)
    tri = [(key[a, b], key[b, c], key[a, c])
           for (a, b) in key for c in nbrs[a] & nbrs[b] if c > b]
    return np.array(tri, dtype=np.int64).reshape(-1, 3)


def edges_connect_views(n: int, edges: Sequence, names: Sequence[str] | None = None) -> None:
    """ViewsCutOff (its views: those outside the largest connected part) unless the accepted ``edges``
    (:class:`rangekit.registration.pair_refine.EdgeResult`) connect every view; the message names the views cut
    off and why the edges to them were refused (an ambiguous overlap names the motion it leaves free)."""
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for e in edges:
        if e.accepted:
            parent[find(e.i)] = find(e.j)
    groups: dict[int, list[int]] = {}
    for k in range(n):
        groups.setdefault(find(k), []).append(k)
    if len(groups) > 1:
        parts = sorted(groups.values(), key=len, reverse=True)
        main = set(parts[0])
        cut = [e for e in edges if (e.i in main) != (e.j in main) and e.reason]
        ambiguous = [e for e in cut if e.unconstrained]
        why = "; ".join(f"edge {e.i}-{e.j} {e.reason}" for e in (ambiguous or cut)[:3])
        named = f" ({', '.join(names[k] for p in parts[1:] for k in p)})" if names is not None else ""
        hint = ("the overlap does not fix the pose (a plane, sphere, cylinder or surface of revolution slides "
                "on itself): give a prior (--init turntable:... or a poses file) or scan more shape in the "
                "overlap" if ambiguous else "scan more views in between or register those separately")
        raise ViewsCutOff(f"the scans do not all overlap: views {parts[1:]}{named} have no reliable link to "
                          f"views {parts[0]}{' (' + why + ')' if why else ''}; {hint}",
                          sorted(k for p in parts[1:] for k in p))


def cut_off_message(views: list[int], names: Sequence[str] | None, voxel: float) -> str:
    """What to say of ``views`` whose pairwise alignments still disagree (measured again at a finer level)."""
    named = f" ({', '.join(names[k] for k in views)})" if names is not None else ""
    return (f"views {views}{named} could not be registered: their pairwise alignments disagree with each other "
            f"and with the rest, even measured again at a finer voxel. Give a prior (--init turntable:AX,AY,AZ:STEP "
            f"or a poses file), try every pair (--neighbours 0) or a finer voxel (--voxel-mm "
            f"{voxel * 1e3 / 2:.3g}), or scan more views next to them")
