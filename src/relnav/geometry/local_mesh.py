"""Local triangulation of a keypoint's neighbourhood (2D Delaunay of its tangent-plane projection).

RoPS (Guo et al. 2013) is defined on a triangle mesh. For a point cloud, relnav triangulates each
keypoint's neighbourhood on its own: the points are projected onto the tangent plane (the two
major axes of the ``(r − d)²``-weighted scatter of the support), triangulated by an incremental
Bowyer–Watson Delaunay, and triangles with an edge longer than ``max_edge`` (3D length) are
dropped, so holes, silhouettes and gaps between separate parts stay open (the role of PCL's
``GreedyProjectionTriangulation`` edge limit ``mu``). **[interpretation]** of ALGORITHMS §A.4
("triangulate"): PCL triangulates the whole cloud greedily; a different triangulation of the same
points gives a different mesh LRF where the two largest scatter eigenvalues are close.

All functions here are numba kernels working on one neighbourhood at a time.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["delaunay_2d"]


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
    """Delaunay triangles of 2D points (incremental Bowyer–Watson, ``O(n²)``; for small sets).

    Parameters
    ----------
    uv : (n, 2) float64
        Points; exact duplicates are skipped (only the first is a vertex).

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
    # normalised coordinates + a super triangle far outside
    pts = np.empty((n + 3, 2))
    for i in range(n):
        pts[i, 0] = (uv[i, 0] - lo0) / span
        pts[i, 1] = (uv[i, 1] - lo1) / span
    pts[n, 0] = -100.0
    pts[n, 1] = -100.0
    pts[n + 1, 0] = 100.0
    pts[n + 1, 1] = -100.0
    pts[n + 2, 0] = 0.5
    pts[n + 2, 1] = 100.0
    cap = 2 * (n + 3) + 16
    tri = np.empty((cap * 2, 3), dtype=np.int64)
    cc = np.empty((cap * 2, 3))
    alive = np.zeros(cap * 2, dtype=np.bool_)
    tri[0, 0] = n
    tri[0, 1] = n + 1
    tri[0, 2] = n + 2
    _circum(pts[n, 0], pts[n, 1], pts[n + 1, 0], pts[n + 1, 1], pts[n + 2, 0], pts[n + 2, 1], cc, 0)
    alive[0] = True
    nt = 1
    bad = np.empty(cap * 2, dtype=np.int64)
    edges = np.empty((cap * 6, 2), dtype=np.int64)
    for i in range(n):
        x = pts[i, 0]
        y = pts[i, 1]
        dup = False
        for j in range(i):
            if pts[j, 0] == x and pts[j, 1] == y:
                dup = True
                break
        if dup:
            continue
        nb = 0
        for t in range(nt):
            if alive[t]:
                dx = x - cc[t, 0]
                dy = y - cc[t, 1]
                if dx * dx + dy * dy < cc[t, 2]:
                    bad[nb] = t
                    nb += 1
        if nb == 0:
            continue  # numerically on a circumcircle of every neighbour: skip the point
        ne = 0
        for b in range(nb):
            t = bad[b]
            for e in range(3):
                u = tri[t, e]
                v = tri[t, (e + 1) % 3]
                shared = False
                for b2 in range(nb):
                    if b2 == b:
                        continue
                    t2 = bad[b2]
                    for e2 in range(3):
                        if tri[t2, e2] == v and tri[t2, (e2 + 1) % 3] == u:
                            shared = True
                            break
                    if shared:
                        break
                if not shared:
                    edges[ne, 0] = u
                    edges[ne, 1] = v
                    ne += 1
        for b in range(nb):
            alive[bad[b]] = False
        # compact when the buffer would overflow
        if nt + ne > tri.shape[0]:
            m = 0
            for t in range(nt):
                if alive[t]:
                    tri[m] = tri[t]
                    cc[m] = cc[t]
                    alive[m] = True
                    m += 1
            for t in range(m, nt):
                alive[t] = False
            nt = m
            if nt + ne > tri.shape[0]:
                grow = max(tri.shape[0], ne) * 2
                tri2 = np.empty((grow, 3), dtype=np.int64)
                cc2 = np.empty((grow, 3))
                al2 = np.zeros(grow, dtype=np.bool_)
                tri2[:nt] = tri[:nt]
                cc2[:nt] = cc[:nt]
                al2[:nt] = alive[:nt]
                tri, cc, alive = tri2, cc2, al2
                bad = np.empty(grow, dtype=np.int64)
                edges = np.empty((grow * 3, 2), dtype=np.int64)
        for e in range(ne):
            u = edges[e, 0]
            v = edges[e, 1]
            tri[nt, 0] = u
            tri[nt, 1] = v
            tri[nt, 2] = i
            _circum(pts[u, 0], pts[u, 1], pts[v, 0], pts[v, 1], x, y, cc, nt)
            alive[nt] = True
            nt += 1
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
