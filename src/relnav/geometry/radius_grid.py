"""Fixed-radius neighbour search on a uniform grid (numba): CSR neighbourhoods of query points
(:func:`radius_search`), the keypoint support neighbourhoods of the LRFs and descriptors (grid or
kd-tree) and the grid kernels the local descriptors call directly.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.errors import InputError
from relnav.geometry.neighbors import build_tree

__all__ = [
    "radius_search",
]


@njit(cache=True)
def grid_build(pts: np.ndarray, cell: float):
    """Uniform grid over ``pts`` with cell edge ``≥ cell`` (grown so there are ≤ 4N+64 cells).

    Returns ``(lo, h, dims, start, sidx, spts)``: the grid origin ``(3,)``, the cell edge, the
    cell counts per axis ``(3,)``, the CSR cell starts ``(n_cells + 1,)`` (cells in x-major,
    z-minor order), the point indices sorted by cell and the points in that order ``(N, 3)``.
    """
    n = pts.shape[0]
    lo = np.zeros(3)
    hi = np.zeros(3)
    if n > 0:
        for d in range(3):
            lo[d] = pts[0, d]
            hi[d] = pts[0, d]
        for i in range(n):
            for d in range(3):
                v = pts[i, d]
                if v < lo[d]:
                    lo[d] = v
                if v > hi[d]:
                    hi[d] = v
    h = cell if cell > 0.0 else 1.0
    ext = 0.0
    for d in range(3):
        ext = max(ext, hi[d] - lo[d])
    if ext > 0.0 and h < ext * 1e-6:
        h = ext * 1e-6
    if ext == 0.0:
        h = max(h, 1.0)
    limit = 4.0 * n + 64.0
    dims = np.ones(3, dtype=np.int64)
    while True:
        total = 1.0
        for d in range(3):
            total *= np.floor((hi[d] - lo[d]) / h) + 1.0
        if total <= limit:
            break
        h *= max(1.1, (total / limit) ** (1.0 / 3.0))
    n_cells = 1
    for d in range(3):
        dims[d] = int(np.floor((hi[d] - lo[d]) / h)) + 1
        n_cells *= dims[d]
    cid = np.empty(n, dtype=np.int64)
    counts = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(n):
        c = 0
        for d in range(3):
            ci = int(np.floor((pts[i, d] - lo[d]) / h))
            ci = min(max(ci, 0), dims[d] - 1)
            c = c * dims[d] + ci
        cid[i] = c
        counts[c + 1] += 1
    start = np.cumsum(counts)
    fill = start[:-1].copy()
    sidx = np.empty(n, dtype=np.int64)
    for i in range(n):
        sidx[fill[cid[i]]] = i
        fill[cid[i]] += 1
    spts = np.empty((n, 3))
    for t in range(n):
        for d in range(3):
            spts[t, d] = pts[sidx[t], d]
    return lo, h, dims, start, sidx, spts


@njit(cache=True)
def grid_query(
    spts: np.ndarray,
    lo: np.ndarray,
    h: float,
    dims: np.ndarray,
    start: np.ndarray,
    sidx: np.ndarray,
    q: np.ndarray,
    r: float,
    out_idx: np.ndarray,
    out_d2: np.ndarray,
) -> int:
    """Indices (and squared distances) of the points with ``‖x − q‖² ≤ r²``; returns the count.

    ``spts``, ``lo`` ... ``sidx`` come from :func:`grid_build`; ``out_idx`` / ``out_d2`` must
    hold ``N`` entries. Order is by grid cell (not sorted).
    """
    r2 = r * r
    c0 = np.empty(3, dtype=np.int64)
    c1 = np.empty(3, dtype=np.int64)
    for d in range(3):
        a = np.floor((q[d] - r - lo[d]) / h)
        b = np.floor((q[d] + r - lo[d]) / h)
        c0[d] = int(max(a, 0.0)) if a < dims[d] else dims[d]
        c1[d] = int(min(b, dims[d] - 1.0)) if b >= 0.0 else -1
    if c1[2] < c0[2]:
        return 0
    n = 0
    qx = q[0]
    qy = q[1]
    qz = q[2]
    for ix in range(c0[0], c1[0] + 1):
        for iy in range(c0[1], c1[1] + 1):
            base = (ix * dims[1] + iy) * dims[2]
            # cells (ix, iy, c0z..c1z) are contiguous in the sorted order
            for t in range(start[base + c0[2]], start[base + c1[2] + 1]):
                dx = spts[t, 0] - qx
                dy = spts[t, 1] - qy
                dz = spts[t, 2] - qz
                d2 = dx * dx + dy * dy + dz * dz
                # branch-free append (the test is ~50/50 on dense supports)
                out_idx[n] = sidx[t]
                out_d2[n] = d2
                n += d2 <= r2
    return n


@njit(cache=True)
def _argsort_d2_idx(d2: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Order by squared distance, ties by point index (independent of the search order)."""
    o = np.argsort(d2)
    m = o.shape[0]
    i = 0
    while i < m:
        j = i + 1
        while j < m and d2[o[j]] == d2[o[i]]:
            j += 1
        # insertion sort of the equal-distance run o[i:j] by index
        for a in range(i + 1, j):
            cur = o[a]
            b = a - 1
            while b >= i and idx[o[b]] > idx[cur]:
                o[b + 1] = o[b]
                b -= 1
            o[b + 1] = cur
        i = j
    return o


@njit(cache=True)
def _radius_csr_kernel(pts: np.ndarray, queries: np.ndarray, r: float, sort: bool):
    n = pts.shape[0]
    nq = queries.shape[0]
    lo, h, dims, start, sidx, spts = grid_build(pts, r)
    offsets = np.zeros(nq + 1, dtype=np.int64)
    cap = max(16, nq * 16) + n
    idx = np.empty(cap, dtype=np.int64)
    d2 = np.empty(cap)
    tot = 0
    for k in range(nq):
        if tot + n > cap:  # room for a query returning every point
            cap = max(2 * cap, tot + n)
            idx2 = np.empty(cap, dtype=np.int64)
            d22 = np.empty(cap)
            idx2[:tot] = idx[:tot]
            d22[:tot] = d2[:tot]
            idx = idx2
            d2 = d22
        m = grid_query(spts, lo, h, dims, start, sidx, queries[k], r, idx[tot:], d2[tot:])
        if sort and m > 1:
            o = _argsort_d2_idx(d2[tot : tot + m], idx[tot : tot + m])
            idx[tot : tot + m] = idx[tot : tot + m][o]
            d2[tot : tot + m] = d2[tot : tot + m][o]
        tot += m
        offsets[k + 1] = tot
    return offsets, idx[:tot], d2[:tot]


def radius_search(
    points: np.ndarray, queries: np.ndarray, radius: float, *, sort: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All points within ``radius`` (inclusive) of each query, as CSR arrays (numba grid).

    Faster than ``cKDTree.query_ball_point`` for the dense neighbourhoods of local descriptors
    (no Python lists).

    Parameters
    ----------
    points : (N, 3) float64
        Searched cloud, metres.
    queries : (Q, 3) float64
        Query positions, metres (same frame).
    radius : float
        Search radius, metres (``‖q − x‖² ≤ r²``).
    sort : bool
        Sort each neighbourhood by distance (ties by index), as PCL's sorted radius search.

    Returns
    -------
    offsets : (Q + 1,) int64
        Neighbours of query ``k`` are ``indices[offsets[k]:offsets[k + 1]]``.
    indices : (M,) int64
        Point indices.
    dist2 : (M,) float64
        Squared distances, m².
    """
    P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    Q = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"search radius must be positive and finite, got {radius}")
    if not (np.isfinite(P).all() and np.isfinite(Q).all()):
        raise InputError("radius_search input contains NaN/inf")
    return _radius_csr_kernel(P, Q, float(radius), bool(sort))


def support_csr(
    points: np.ndarray, keypoint_idx: np.ndarray, radius: float, tree: cKDTree | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Radius neighbourhoods of the keypoints as CSR arrays ``(flat, offsets)``.

    ``flat[offsets[k]:offsets[k + 1]]`` are the indices of the points with
    ``‖q − p_k‖ ≤ radius`` (keypoint included), in a deterministic order. Without ``tree`` the
    numba grid search :func:`radius_search` is used; with ``tree`` (or when the grid would need
    more than 2⁶² cells) the kd-tree's ``sparse_distance_matrix``.
    """
    P = np.ascontiguousarray(points, dtype=np.float64)
    kp = np.ascontiguousarray(keypoint_idx, dtype=np.int64)
    K = kp.shape[0]
    if K == 0 or P.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(K + 1, dtype=np.int64)
    if tree is None:
        dims = np.floor((P.max(axis=0) - P.min(axis=0)) / radius) + 1.0
        if float(np.prod(dims)) < 2.0**62:
            offsets, flat, _ = radius_search(P, P[kp], float(radius))
            return flat, offsets
        tree = build_tree(P)
    kp_tree = tree if (K == P.shape[0] and np.array_equal(kp, np.arange(K))) else build_tree(P[kp])
    pairs = kp_tree.sparse_distance_matrix(tree, radius, output_type="ndarray")
    return _group_csr(pairs["i"].astype(np.int64), pairs["j"].astype(np.int64), K)


def check_points(points: np.ndarray, keypoint_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    P = np.ascontiguousarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {P.shape}")
    if not np.isfinite(P).all():
        raise InputError("points contain NaN/inf")
    kp = np.ascontiguousarray(keypoint_idx, dtype=np.int64).reshape(-1)
    if kp.size and (kp.min() < 0 or kp.max() >= P.shape[0]):
        raise InputError("keypoint index out of range")
    return P, kp


@njit(cache=True)
def _group_csr(owner: np.ndarray, idx: np.ndarray, K: int) -> tuple[np.ndarray, np.ndarray]:
    """Counting sort of ``idx`` by ``owner`` (stable) → ``(flat, offsets)``."""
    offsets = np.zeros(K + 1, dtype=np.int64)
    for t in range(owner.shape[0]):
        offsets[owner[t] + 1] += 1
    for k in range(K):
        offsets[k + 1] += offsets[k]
    fill = offsets[:-1].copy()
    flat = np.empty(owner.shape[0], dtype=np.int64)
    for t in range(owner.shape[0]):
        flat[fill[owner[t]]] = idx[t]
        fill[owner[t]] += 1
    return flat, offsets
