"""Local triangulation of a keypoint's neighbourhood (2D Delaunay of its tangent-plane projection).

RoPS (Guo et al. 2013) is defined on a triangle mesh. For a point cloud, relnav triangulates each
keypoint's neighbourhood on its own: the points are projected onto the tangent plane (the two
major axes of the ``(r − d)²``-weighted scatter of the support), triangulated by an incremental
Bowyer–Watson Delaunay, and triangles with an edge longer than ``max_edge`` (3D length) are
dropped, so holes, silhouettes and gaps between separate parts stay open (the role of PCL's
``GreedyProjectionTriangulation`` edge limit ``mu``). **[interpretation]** of ALGORITHMS §A.4
("triangulate"): PCL triangulates the whole cloud greedily; a different triangulation of the same
points gives a different mesh LRF where the two largest scatter eigenvalues are close.

All functions here are numba kernels working on one neighbourhood at a time;
:func:`local_mesh_triangles` is the one the RoPS LRF kernel and
:func:`relnav.geometry.lrf.rops_local_mesh` (the same triangles as CSR arrays) both call.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["delaunay_2d", "local_mesh_triangles"]


@njit(cache=True)
def _circum(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float, out: np.ndarray, t: int
) -> None:
    """Circumcentre and squared radius of triangle ``t`` into ``out[t] = (ux, uy, r²)``."""
    d = 2.0 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    if d == 0.0:
        out[t, 0] = 0.0
        out[t, 1] = 0.0
        out[t, 2] = np.inf  # degenerate (collinear): contains every point
        return
    a2 = ax * ax + ay * ay
    b2 = bx * bx + by * by
    c2 = cx * cx + cy * cy
    ux = (a2 * (by - cy) + b2 * (cy - ay) + c2 * (ay - by)) / d
    uy = (a2 * (cx - bx) + b2 * (ax - cx) + c2 * (bx - ax)) / d
    out[t, 0] = ux
    out[t, 1] = uy
    out[t, 2] = (ax - ux) ** 2 + (ay - uy) ** 2


@njit(cache=True)
def delaunay_2d(uv: np.ndarray) -> np.ndarray:
    """Delaunay triangles of 2D points (incremental Bowyer–Watson with a walk; small sets).

    Parameters
    ----------
    uv : (n, 2) float64
        Points; exact duplicates are skipped (only one of them is a vertex).

    Returns
    -------
    (m, 3) int64
        Vertex indices into ``uv`` (counter-clockwise); empty for fewer than 3 distinct points.
    """
    n = uv.shape[0]
    if n < 3:
        return np.zeros((0, 3), dtype=np.int64)
    lo0 = uv[:, 0].min()
    lo1 = uv[:, 1].min()
    span = max(uv[:, 0].max() - lo0, uv[:, 1].max() - lo1)
    if not (span > 0.0):
        return np.zeros((0, 3), dtype=np.int64)
    pts = np.empty((n + 3, 2))
    for i in range(n):
        pts[i, 0] = (uv[i, 0] - lo0) / span
        pts[i, 1] = (uv[i, 1] - lo1) / span
    # super triangle (counter-clockwise) far outside the unit square; being finite, it can miss
    # a sliver triangle on the convex hull of large sets (1 of 1 980 for 1 000 random points)
    pts[n, 0] = -1e4
    pts[n, 1] = -1e4
    pts[n + 1, 0] = 1e4
    pts[n + 1, 1] = -1e4
    pts[n + 2, 0] = 0.5
    pts[n + 2, 1] = 1e4
    cap = 2 * (n + 3) + 16
    tri = np.empty((cap, 3), dtype=np.int64)
    nbr = np.full((cap, 3), -1, dtype=np.int64)  # nbr[t, e]: across edge tri[t, e] → tri[t, e+1]
    cc = np.empty((cap, 3))
    alive = np.zeros(cap, dtype=np.bool_)
    free = np.empty(cap, dtype=np.int64)  # recycled slots
    n_free = 0
    tri[0, 0] = n
    tri[0, 1] = n + 1
    tri[0, 2] = n + 2
    _circum(pts[n, 0], pts[n, 1], pts[n + 1, 0], pts[n + 1, 1], pts[n + 2, 0], pts[n + 2, 1], cc, 0)
    alive[0] = True
    nt = 1
    last = 0
    stack = np.empty(cap, dtype=np.int64)
    bad = np.empty(cap, dtype=np.int64)
    mark = np.full(cap, -1, dtype=np.int64)
    bu = np.empty(cap, dtype=np.int64)  # cavity boundary edges (u, v) and the triangle outside
    bv = np.empty(cap, dtype=np.int64)
    bo = np.empty(cap, dtype=np.int64)
    start_of = np.full(n + 3, -1, dtype=np.int64)
    newt = np.empty(cap, dtype=np.int64)
    # insertion in a scrambled (deterministic) order: spatially sorted input, as radius searches
    # return it, would put most new points outside the current hull (large cavities, long walks)
    step = 7919 if n % 7919 != 0 else 7907
    for jj in range(n):
        i = (jj * step) % n
        x = pts[i, 0]
        y = pts[i, 1]
        t = last
        # walk to the triangle containing (x, y)
        steps = 0
        while True:
            moved = False
            for e in range(3):
                a = tri[t, e]
                b = tri[t, (e + 1) % 3]
                o = (pts[b, 0] - pts[a, 0]) * (y - pts[a, 1]) - (pts[b, 1] - pts[a, 1]) * (
                    x - pts[a, 0]
                )
                if o < 0.0 and nbr[t, e] >= 0:
                    t = nbr[t, e]
                    moved = True
                    break
            steps += 1
            if not moved or steps > 4 * cap:
                break
        dup = False
        for e in range(3):
            a = tri[t, e]
            if pts[a, 0] == x and pts[a, 1] == y:
                dup = True
        dx = x - cc[t, 0]
        dy = y - cc[t, 1]
        if dup or not (dx * dx + dy * dy < cc[t, 2]):
            continue  # duplicate or numerically on the circumcircle: skip the point
        # cavity: flood fill of the triangles whose circumcircle contains the point
        nb = 0
        ns = 1
        stack[0] = t
        mark[t] = i
        while ns > 0:
            ns -= 1
            s = stack[ns]
            bad[nb] = s
            nb += 1
            for e in range(3):
                o = nbr[s, e]
                if o >= 0 and mark[o] != i:
                    dx = x - cc[o, 0]
                    dy = y - cc[o, 1]
                    if dx * dx + dy * dy < cc[o, 2]:
                        mark[o] = i
                        stack[ns] = o
                        ns += 1
        # boundary edges of the cavity (an edge whose neighbour is not bad)
        ne = 0
        for k in range(nb):
            s = bad[k]
            for e in range(3):
                o = nbr[s, e]
                if o < 0 or mark[o] != i:
                    bu[ne] = tri[s, e]
                    bv[ne] = tri[s, (e + 1) % 3]
                    bo[ne] = o
                    ne += 1
        for k in range(nb):
            alive[bad[k]] = False
            free[n_free] = bad[k]
            n_free += 1
        for k in range(ne):
            if n_free > 0:
                n_free -= 1
                s = free[n_free]
            else:
                s = nt
                nt += 1
            newt[k] = s
            u = bu[k]
            v = bv[k]
            tri[s, 0] = u
            tri[s, 1] = v
            tri[s, 2] = i
            _circum(pts[u, 0], pts[u, 1], pts[v, 0], pts[v, 1], x, y, cc, s)
            alive[s] = True
            mark[s] = -1
            o = bo[k]
            nbr[s, 0] = o
            if o >= 0:
                for e in range(3):
                    if tri[o, e] == v and tri[o, (e + 1) % 3] == u:
                        nbr[o, e] = s
                        break
            start_of[u] = s
        # new triangles (u, v, i): edge (v, i) borders the new triangle starting at v,
        # edge (i, u) the one ending at u (whose start_of is u's predecessor)
        for k in range(ne):
            s = newt[k]
            w = start_of[bv[k]]
            nbr[s, 1] = w
            nbr[w, 2] = s
        last = newt[0]
    m = 0
    for t in range(nt):
        if alive[t] and tri[t, 0] < n and tri[t, 1] < n and tri[t, 2] < n:
            m += 1
    out = np.empty((m, 3), dtype=np.int64)
    m = 0
    for t in range(nt):
        if alive[t] and tri[t, 0] < n and tri[t, 1] < n and tri[t, 2] < n:
            out[m] = tri[t]
            m += 1
    return out


@njit(cache=True)
def local_mesh_triangles(
    P: np.ndarray, p: np.ndarray, idx: np.ndarray, radius: float, max_edge: float, min_support: int
) -> np.ndarray:
    """Local triangle mesh of one keypoint's neighbourhood, as the RoPS LRF uses it.

    The support is ``{q : ‖q − p‖² ≤ radius²}`` (the same test as the radius search of
    :func:`relnav.geometry.radius_grid.radius_search`). The tangent plane is spanned by the two
    major axes of the support scatter ``Σ (r − d)² v vᵀ`` (``v = q − p``, ``d = ‖v‖``); all of
    ``idx`` is projected onto it and triangulated (:func:`delaunay_2d`; a point whose projection
    duplicates another's is not a vertex). A triangle is kept when at least one vertex is in the
    support (PCL's rule for the triangles of a RoPS support) and no edge is longer than
    ``max_edge`` (3D length).

    Parameters
    ----------
    P : (N, 3) float64
        Cloud, metres.
    p : (3,) float64
        Keypoint, metres.
    idx : (n,) int64
        Indices into ``P`` of the points within ``radius + max_edge`` of ``p`` (keypoint
        included): every vertex a kept triangle can have.
    radius : float
        Support radius, metres.
    max_edge : float
        Longest kept edge, metres.
    min_support : int
        Fewer points than this in ``idx`` or in the support: no triangles.

    Returns
    -------
    (m, 3) int64
        Vertex indices into ``P`` (counter-clockwise in the tangent plane); ``m = 0`` when the
        support is too small or no triangle is kept.
    """
    n = idx.shape[0]
    if n < min_support:
        return np.zeros((0, 3), dtype=np.int64)
    rel = np.empty((n, 3))
    inside = np.empty(n, dtype=np.bool_)
    n_in = 0
    r2 = radius * radius
    C = np.zeros((3, 3))
    for t in range(n):
        d2 = 0.0
        for i in range(3):
            rel[t, i] = P[idx[t], i] - p[i]
            d2 += rel[t, i] * rel[t, i]
        inside[t] = d2 <= r2
        if inside[t]:
            n_in += 1
            w = (radius - np.sqrt(d2)) ** 2
            for i in range(3):
                for j in range(3):
                    C[i, j] += w * rel[t, i] * rel[t, j]
    if n_in < min_support:
        return np.zeros((0, 3), dtype=np.int64)
    _, V = np.linalg.eigh(C)  # tangent plane: the two largest axes of the support scatter
    uv = np.empty((n, 2))
    for t in range(n):
        uv[t, 0] = rel[t, 0] * V[0, 2] + rel[t, 1] * V[1, 2] + rel[t, 2] * V[2, 2]
        uv[t, 1] = rel[t, 0] * V[0, 1] + rel[t, 1] * V[1, 1] + rel[t, 2] * V[2, 1]
    loc = delaunay_2d(uv)
    me2 = max_edge * max_edge
    tris = np.empty((loc.shape[0], 3), dtype=np.int64)
    nt = 0
    for j in range(loc.shape[0]):
        if not (inside[loc[j, 0]] or inside[loc[j, 1]] or inside[loc[j, 2]]):
            continue
        ok = True
        for e in range(3):
            u = loc[j, e]
            v = loc[j, (e + 1) % 3]
            l2 = 0.0
            for i in range(3):
                l2 += (rel[u, i] - rel[v, i]) ** 2
            if l2 > me2:
                ok = False
                break
        if ok:
            for e in range(3):
                tris[nt, e] = idx[loc[j, e]]
            nt += 1
    return tris[:nt].copy()
