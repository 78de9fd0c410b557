"""Local reference frames (LRF) for local 3D descriptors.

Convention used by :func:`rops_lrf`: an LRF is a ``(3, 3)`` float64 matrix whose **rows** are the
unit axes ``x, y, z`` expressed in the cloud frame, so the local coordinates of a support point
``q`` around the keypoint ``p`` are ``q' = LRF @ (q - p)``. Frames are right-handed
(``det = +1``); an undefined frame is a matrix of NaN.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.errors import ConfigError, InputError
from relnav.geometry.local_mesh import delaunay_2d
from relnav.geometry.neighbors import build_tree, mean_resolution

__all__ = ["rops_lrf"]

ROPS_MIN_SUPPORT = 5
"""Minimum support points (keypoint included) for a RoPS LRF (same rule as descriptors)."""

ROPS_LRF_MODES = ("local_mesh", "points")
"""Frames of :func:`rops_lrf` without a given mesh: local triangulation (default) or points."""

ROPS_MAX_EDGE_FACTOR = 3.0
"""Default longest local-mesh edge in mean resolutions ``Tr`` (**[interpretation]**; PCL's
greedy projection uses ``mu = 2.5`` times each point's nearest-neighbour distance)."""


def _support_csr(
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


@njit(cache=True)
def _frame_from_scatter(
    C: np.ndarray, m: np.ndarray, s: float, tol: float, out: np.ndarray
) -> bool:
    """Fill ``out`` (3, 3) rows x, y, z from scatter ``C`` and the weighted offset sum ``m``.

    ``x``/``z`` are the eigenvectors of the largest/smallest eigenvalue, oriented so that
    ``m·x ≥ 0`` and ``m·z ≥ 0``; ``y = z × x``. Returns False (frame undefined) when the largest
    eigenvalue is not positive, when two eigenvalues are closer than ``tol·λ1`` or when a sign
    sum is smaller than ``tol·s`` in magnitude.
    """
    w, V = np.linalg.eigh(C)  # ascending
    l1 = w[2]
    if not (l1 > 0.0):
        return False
    if (w[2] - w[1]) <= tol * l1 or (w[1] - w[0]) <= tol * l1:
        return False
    x = V[:, 2].copy()
    z = V[:, 0].copy()
    hx = m[0] * x[0] + m[1] * x[1] + m[2] * x[2]
    hz = m[0] * z[0] + m[1] * z[1] + m[2] * z[2]
    if abs(hx) <= tol * s or abs(hz) <= tol * s:
        return False
    if hx < 0.0:
        x = -x
    if hz < 0.0:
        z = -z
    out[0, :] = x
    out[1, 0] = z[1] * x[2] - z[2] * x[1]
    out[1, 1] = z[2] * x[0] - z[0] * x[2]
    out[1, 2] = z[0] * x[1] - z[1] * x[0]
    out[2, :] = z
    return True


@njit(cache=True)
def _rops_lrf_points_kernel(
    P: np.ndarray,
    kp: np.ndarray,
    flat: np.ndarray,
    offsets: np.ndarray,
    radius: float,
    min_support: int,
    tol: float,
) -> np.ndarray:
    K = kp.shape[0]
    out = np.full((K, 3, 3), np.nan)
    C = np.zeros((3, 3))
    m = np.zeros(3)
    frame = np.zeros((3, 3))
    for k in range(K):
        s0 = offsets[k]
        s1 = offsets[k + 1]
        if s1 - s0 < min_support:
            continue
        p = P[kp[k]]
        C[:, :] = 0.0
        m[:] = 0.0
        ssum = 0.0
        for t in range(s0, s1):
            q = P[flat[t]]
            v0 = q[0] - p[0]
            v1 = q[1] - p[1]
            v2 = q[2] - p[2]
            d = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
            w = (radius - d) * (radius - d)
            C[0, 0] += w * v0 * v0
            C[0, 1] += w * v0 * v1
            C[0, 2] += w * v0 * v2
            C[1, 1] += w * v1 * v1
            C[1, 2] += w * v1 * v2
            C[2, 2] += w * v2 * v2
            m[0] += w * v0
            m[1] += w * v1
            m[2] += w * v2
            ssum += w * d
        C[1, 0] = C[0, 1]
        C[2, 0] = C[0, 2]
        C[2, 1] = C[1, 2]
        if _frame_from_scatter(C, m, ssum, tol, frame):
            out[k] = frame
    return out


@njit(cache=True)
def _mesh_scatter(
    P: np.ndarray,
    p: np.ndarray,
    tris: np.ndarray,
    sel: np.ndarray,
    nt: int,
    radius: float,
    C: np.ndarray,
    m: np.ndarray,
    vv: np.ndarray,
) -> float:
    """Mesh RoPS scatter ``C`` (3, 3) and sign vector ``m`` (3,) of triangles ``tris[sel[:nt]]``.

    Returns the sign-test scale ``Σ W Σ_a ‖v_a‖`` (0 when the triangles have no area).
    """
    C[:, :] = 0.0
    m[:] = 0.0
    total_area = 0.0
    for j in range(nt):
        a = P[tris[sel[j], 0]]
        b = P[tris[sel[j], 1]]
        c = P[tris[sel[j], 2]]
        e1 = b - a
        e2 = c - a
        cx = e1[1] * e2[2] - e1[2] * e2[1]
        cy = e1[2] * e2[0] - e1[0] * e2[2]
        cz = e1[0] * e2[1] - e1[1] * e2[0]
        total_area += 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)
    if not (total_area > 0.0):
        return 0.0
    ssum = 0.0
    for j in range(nt):
        for a in range(3):
            q = P[tris[sel[j], a]]
            for i in range(3):
                vv[a, i] = q[i] - p[i]
        e1 = vv[1] - vv[0]
        e2 = vv[2] - vv[0]
        cx = e1[1] * e2[2] - e1[2] * e2[1]
        cy = e1[2] * e2[0] - e1[0] * e2[2]
        cz = e1[0] * e2[1] - e1[1] * e2[0]
        area = 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)
        g0 = (vv[0, 0] + vv[1, 0] + vv[2, 0]) / 3.0
        g1 = (vv[0, 1] + vv[1, 1] + vv[2, 1]) / 3.0
        g2 = (vv[0, 2] + vv[1, 2] + vv[2, 2]) / 3.0
        dc = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        W = (area / total_area) * (radius - dc) * (radius - dc)
        # C_j = (1/12) [ (Σ_a v_a)(Σ_b v_b)ᵀ + Σ_a v_a v_aᵀ ]
        for i in range(3):
            si = vv[0, i] + vv[1, i] + vv[2, i]
            for jj in range(3):
                sj = vv[0, jj] + vv[1, jj] + vv[2, jj]
                acc = si * sj
                for a in range(3):
                    acc += vv[a, i] * vv[a, jj]
                C[i, jj] += W * acc / 12.0
        for a in range(3):
            for i in range(3):
                m[i] += W * vv[a, i]
            ssum += W * np.sqrt(vv[a, 0] ** 2 + vv[a, 1] ** 2 + vv[a, 2] ** 2)
    return ssum


@njit(cache=True)
def _rops_lrf_mesh_kernel(
    P: np.ndarray,
    kp: np.ndarray,
    flat: np.ndarray,
    offsets: np.ndarray,
    tris: np.ndarray,
    v2t_flat: np.ndarray,
    v2t_off: np.ndarray,
    radius: float,
    min_support: int,
    tol: float,
) -> np.ndarray:
    K = kp.shape[0]
    M = tris.shape[0]
    out = np.full((K, 3, 3), np.nan)
    stamp = np.full(M, -1, dtype=np.int64)
    buf = np.empty(M, dtype=np.int64)
    C = np.zeros((3, 3))
    m = np.zeros(3)
    frame = np.zeros((3, 3))
    vv = np.zeros((3, 3))
    for k in range(K):
        s0 = offsets[k]
        s1 = offsets[k + 1]
        if s1 - s0 < min_support:
            continue
        p = P[kp[k]]
        nt = 0
        for t in range(s0, s1):
            vi = flat[t]
            for u in range(v2t_off[vi], v2t_off[vi + 1]):
                tri = v2t_flat[u]
                if stamp[tri] != k:
                    stamp[tri] = k
                    buf[nt] = tri
                    nt += 1
        ssum = _mesh_scatter(P, p, tris, buf, nt, radius, C, m, vv)
        if not (ssum > 0.0):
            continue
        if _frame_from_scatter(C, m, ssum, tol, frame):
            out[k] = frame
    return out


@njit(cache=True)
def _rops_lrf_local_mesh_kernel(
    P: np.ndarray,
    kp: np.ndarray,
    flat: np.ndarray,
    offsets: np.ndarray,
    radius: float,
    max_edge: float,
    min_support: int,
    tol: float,
) -> np.ndarray:
    """Mesh RoPS LRF on a local Delaunay triangulation (see :mod:`relnav.geometry.local_mesh`).

    ``flat``/``offsets``: CSR neighbourhoods of radius ``radius + max_edge`` (keypoint included).
    """
    K = kp.shape[0]
    out = np.full((K, 3, 3), np.nan)
    C = np.zeros((3, 3))
    m = np.zeros(3)
    frame = np.zeros((3, 3))
    vv = np.zeros((3, 3))
    me2 = max_edge * max_edge
    for k in range(K):
        s0 = offsets[k]
        n = offsets[k + 1] - s0
        if n < min_support:
            continue
        p = P[kp[k]]
        idx = flat[s0 : s0 + n]
        rel = np.empty((n, 3))
        inside = np.empty(n, dtype=np.bool_)
        n_in = 0
        C[:, :] = 0.0
        for t in range(n):
            d2 = 0.0
            for i in range(3):
                rel[t, i] = P[idx[t], i] - p[i]
                d2 += rel[t, i] * rel[t, i]
            d = np.sqrt(d2)
            inside[t] = d <= radius
            if inside[t]:
                n_in += 1
                w = (radius - d) * (radius - d)
                for i in range(3):
                    for j in range(3):
                        C[i, j] += w * rel[t, i] * rel[t, j]
        if n_in < min_support:
            continue
        _, V = np.linalg.eigh(C)  # tangent plane: the two largest axes of the support scatter
        uv = np.empty((n, 2))
        for t in range(n):
            uv[t, 0] = rel[t, 0] * V[0, 2] + rel[t, 1] * V[1, 2] + rel[t, 2] * V[2, 2]
            uv[t, 1] = rel[t, 0] * V[0, 1] + rel[t, 1] * V[1, 1] + rel[t, 2] * V[2, 1]
        loc = delaunay_2d(uv)
        tris = np.empty((loc.shape[0], 3), dtype=np.int64)
        nt = 0
        for j in range(loc.shape[0]):
            a = loc[j, 0]
            b = loc[j, 1]
            c = loc[j, 2]
            if not (inside[a] or inside[b] or inside[c]):
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
                tris[nt, 0] = idx[a]
                tris[nt, 1] = idx[b]
                tris[nt, 2] = idx[c]
                nt += 1
        if nt == 0:
            continue
        sel = np.arange(nt)
        ssum = _mesh_scatter(P, p, tris, sel, nt, radius, C, m, vv)
        if not (ssum > 0.0):
            continue
        if _frame_from_scatter(C, m, ssum, tol, frame):
            out[k] = frame
    return out


def _check_points(points: np.ndarray, keypoint_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    P = np.ascontiguousarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {P.shape}")
    if not np.isfinite(P).all():
        raise InputError("points contain NaN/inf")
    kp = np.ascontiguousarray(keypoint_idx, dtype=np.int64).reshape(-1)
    if kp.size and (kp.min() < 0 or kp.max() >= P.shape[0]):
        raise InputError("keypoint index out of range")
    return P, kp


def rops_lrf(
    points: np.ndarray,
    keypoint_idx: np.ndarray,
    radius: float,
    *,
    tree: cKDTree | None = None,
    triangles: np.ndarray | None = None,
    lrf: str = "local_mesh",
    max_edge: float | None = None,
    degenerate_tol: float = 1e-10,
) -> np.ndarray:
    """RoPS local reference frames (Guo et al. 2013): mesh-based, on a local mesh, or point-based.

    Local-mesh version (default, ``lrf="local_mesh"``, **[interpretation]** of ALGORITHMS §A.4
    for point clouds): the mesh version below on a Delaunay triangulation of the keypoint's
    neighbourhood projected onto its tangent plane, edges ``≤ max_edge``
    (:mod:`relnav.geometry.local_mesh`).

    Point-based version (``lrf="points"``):
    with ``v_i = q_i − p`` over the support ``{q_i : ‖q_i − p‖ ≤ r}`` and ``d_i = ‖v_i‖``,
    ``C = Σ_i (r − d_i)² v_i v_iᵀ``; ``x`` / ``z`` are the eigenvectors of the largest /
    smallest eigenvalue, each flipped so that the weighted sum ``Σ_i (r − d_i)² v_i · axis`` is
    non-negative, and ``y = z × x``.

    Mesh version (``triangles`` given): every triangle with at least one vertex in the support
    contributes ``C_j = (1/12)[(Σ_a v_a)(Σ_b v_b)ᵀ + Σ_a v_a v_aᵀ]`` weighted by
    ``(area_j / Σ area) · (r − ‖p − centroid_j‖)²``; signs from the same weights times
    ``Σ_a v_a · axis`` (as PCL, but with the area normalisation done the documented way).

    Parameters
    ----------
    points : (N, 3) float64
        Cloud (mesh vertices for the mesh version), metres.
    keypoint_idx : (K,) int
        Keypoint indices into ``points``.
    radius : float
        Support radius ``r``, metres.
    tree : scipy.spatial.cKDTree, optional
        Prebuilt tree of ``points`` (built when omitted).
    triangles : (M, 3) int, optional
        Triangle vertex indices into ``points``; switches to the mesh version (``lrf`` ignored).
    lrf : {"local_mesh", "points"}
        Frame without ``triangles``.
    max_edge : float, optional
        Longest local-mesh edge, metres (default ``3·Tr``, ``Tr`` the mean resolution).
    degenerate_tol : float
        The frame is undefined (NaN) when two eigenvalues differ by ``≤ tol·λ_max`` (e.g.
        collinear or isotropic support) or a sign sum is ``≤ tol·Σ w‖v‖`` in magnitude (e.g. an
        exactly planar patch, whose normal sign is then arbitrary).

    Returns
    -------
    (K, 3, 3) float64
        Rows are the axes ``x, y, z`` in the cloud frame (``q' = LRF @ (q − p)``); NaN for
        keypoints with fewer than 5 support points (keypoint included) or an undefined frame.

    References
    ----------
    Y. Guo, F. Sohel, M. Bennamoun, M. Lu, J. Wan, "Rotational projection statistics for 3D
    local surface description and object recognition", IJCV 105 (2013).
    doi:10.1007/s11263-013-0627-y
    """
    P, kp = _check_points(points, keypoint_idx)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"LRF radius must be positive and finite, got {radius}")
    if kp.size == 0:
        return np.full((0, 3, 3), np.nan)
    check_rops_lrf(lrf, max_edge)
    flat, offsets = _support_csr(P, kp, float(radius), tree)
    return _rops_lrf_csr(
        P, kp, flat, offsets, float(radius), triangles, float(degenerate_tol), lrf, max_edge, tree
    )


def check_rops_lrf(lrf: str, max_edge: float | None) -> None:
    """Raise :class:`ConfigError` for an unknown RoPS frame or a bad ``max_edge``."""
    if lrf not in ROPS_LRF_MODES:
        raise ConfigError(f"RoPS lrf must be one of {ROPS_LRF_MODES}, got {lrf!r}")
    if max_edge is not None and not (np.isfinite(max_edge) and max_edge > 0):
        raise ConfigError(f"RoPS max_edge must be positive and finite, got {max_edge}")


def _rops_lrf_csr(
    P: np.ndarray,
    kp: np.ndarray,
    flat: np.ndarray,
    offsets: np.ndarray,
    radius: float,
    triangles: np.ndarray | None,
    tol: float,
    lrf: str = "points",
    max_edge: float | None = None,
    tree: cKDTree | None = None,
) -> np.ndarray:
    """:func:`rops_lrf` on precomputed support neighbourhoods (CSR from :func:`_support_csr`)."""
    if triangles is None and lrf == "points":
        return _rops_lrf_points_kernel(P, kp, flat, offsets, radius, ROPS_MIN_SUPPORT, tol)
    if triangles is None:
        check_rops_lrf(lrf, max_edge)
        if max_edge is None:
            max_edge = ROPS_MAX_EDGE_FACTOR * mean_resolution(P, tree)
        if not np.isfinite(max_edge):  # fewer than two distinct points: no frame
            return np.full((kp.shape[0], 3, 3), np.nan)
        ext_flat, ext_off = _support_csr(P, kp, radius + float(max_edge), tree)
        return _rops_lrf_local_mesh_kernel(
            P, kp, ext_flat, ext_off, radius, float(max_edge), ROPS_MIN_SUPPORT, tol
        )
    tris = np.ascontiguousarray(triangles, dtype=np.int64)
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise InputError(f"triangles must have shape (M, 3), got {tris.shape}")
    if tris.size and (tris.min() < 0 or tris.max() >= P.shape[0]):
        raise InputError("triangle vertex index out of range")
    # vertex -> triangles CSR
    owner = np.repeat(np.arange(tris.shape[0], dtype=np.int64), 3)
    verts = tris.reshape(-1)
    order = np.argsort(verts, kind="stable")
    v2t_flat = np.ascontiguousarray(owner[order])
    v2t_off = np.zeros(P.shape[0] + 1, dtype=np.int64)
    np.cumsum(np.bincount(verts, minlength=P.shape[0]), out=v2t_off[1:])
    return _rops_lrf_mesh_kernel(
        P, kp, flat, offsets, tris, v2t_flat, v2t_off, radius, ROPS_MIN_SUPPORT, tol
    )


# --------------------------------------------------------------------------------------------
# Radius search on a uniform grid (numba) and the SHOT local reference frame (task D).
# --------------------------------------------------------------------------------------------

SHOT_MIN_NEIGHBORS = 5
"""Minimum neighbours *other than the keypoint* for a SHOT LRF (PCL ``getLocalRF`` rule)."""


@njit(cache=True)
def _grid_build(pts: np.ndarray, cell: float):
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
def _grid_query(
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

    ``spts``, ``lo`` ... ``sidx`` come from :func:`_grid_build`; ``out_idx`` / ``out_d2`` must
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
    lo, h, dims, start, sidx, spts = _grid_build(pts, r)
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
        m = _grid_query(spts, lo, h, dims, start, sidx, queries[k], r, idx[tot:], d2[tot:])
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


@njit(cache=True)
def _shot_lrf_one(
    P: np.ndarray,
    p: np.ndarray,
    nbr: np.ndarray,
    d2: np.ndarray,
    m: int,
    radius: float,
    min_nb: int,
    V: np.ndarray,
    vd2: np.ndarray,
    vid: np.ndarray,
    frame: np.ndarray,
    ties: np.ndarray,
) -> bool:
    """SHOT LRF of keypoint ``p`` from its ``m`` neighbours ``nbr[:m]`` (squared distances
    ``d2[:m]``, any order). Fills ``frame`` (rows x, y, z) and ``ties`` (whether the sign of
    ``x`` / ``z`` came from the median tie-break); returns False when the frame is undefined.
    ``V`` (N, 3), ``vd2`` (N,), ``vid`` (N,) are scratch buffers.
    """
    ties[0] = False
    ties[1] = False
    nv = 0
    c00 = 0.0
    c01 = 0.0
    c02 = 0.0
    c11 = 0.0
    c12 = 0.0
    c22 = 0.0
    wsum = 0.0
    for t in range(m):
        if d2[t] == 0.0:  # the keypoint itself and its exact duplicates
            continue
        j = nbr[t]
        v0 = P[j, 0] - p[0]
        v1 = P[j, 1] - p[1]
        v2 = P[j, 2] - p[2]
        w = radius - np.sqrt(d2[t])
        V[nv, 0] = v0
        V[nv, 1] = v1
        V[nv, 2] = v2
        vd2[nv] = d2[t]
        vid[nv] = j
        c00 += w * v0 * v0
        c01 += w * v0 * v1
        c02 += w * v0 * v2
        c11 += w * v1 * v1
        c12 += w * v1 * v2
        c22 += w * v2 * v2
        wsum += w
        nv += 1
    if nv < min_nb or not (wsum > 0.0):
        return False
    C = np.empty((3, 3))
    C[0, 0] = c00 / wsum
    C[0, 1] = c01 / wsum
    C[0, 2] = c02 / wsum
    C[1, 1] = c11 / wsum
    C[1, 2] = c12 / wsum
    C[2, 2] = c22 / wsum
    C[1, 0] = C[0, 1]
    C[2, 0] = C[0, 2]
    C[2, 1] = C[1, 2]
    if not np.isfinite(C).all():
        return False
    evals, evecs = np.linalg.eigh(C)  # ascending
    if not np.isfinite(evals).all():
        return False
    axes = np.empty((2, 3))
    axes[0] = evecs[:, 2]  # x: largest eigenvalue
    axes[1] = evecs[:, 0]  # z: smallest eigenvalue
    for a in range(2):
        ax0 = axes[a, 0]
        ax1 = axes[a, 1]
        ax2 = axes[a, 2]
        plus = 0
        for i in range(nv):
            plus += V[i, 0] * ax0 + V[i, 1] * ax1 + V[i, 2] * ax2 >= 0.0
        D = 2 * plus - nv
        if D == 0:
            # PCL: the 5 neighbours around the median of the distance-sorted list decide
            ties[a] = True
            o = _argsort_d2_idx(vd2[:nv], vid[:nv])
            med = nv // 2
            cnt = 0
            for i in range(-2, 3):
                r_ = o[med - i]
                if V[r_, 0] * ax0 + V[r_, 1] * ax1 + V[r_, 2] * ax2 > 0.0:
                    cnt += 1
            if cnt < 3:
                axes[a] = -axes[a]
        elif D < 0:
            axes[a] = -axes[a]
    x = axes[0]
    z = axes[1]
    frame[0] = x
    frame[1, 0] = z[1] * x[2] - z[2] * x[1]
    frame[1, 1] = z[2] * x[0] - z[0] * x[2]
    frame[1, 2] = z[0] * x[1] - z[1] * x[0]
    frame[2] = z
    return True


@njit(cache=True)
def _shot_lrf_kernel(P: np.ndarray, kp: np.ndarray, radius: float, min_nb: int):
    """SHOT LRFs ``(K, 3, 3)`` and tie flags ``(K, 2)`` with a grid radius search."""
    n = P.shape[0]
    K = kp.shape[0]
    out = np.full((K, 3, 3), np.nan)
    ties = np.zeros((K, 2), dtype=np.bool_)
    lo, h, dims, start, sidx, spts = _grid_build(P, radius)
    bi = np.empty(n, dtype=np.int64)
    bd = np.empty(n)
    V = np.empty((n, 3))
    vd2 = np.empty(n)
    vid = np.empty(n, dtype=np.int64)
    frame = np.empty((3, 3))
    tie = np.zeros(2, dtype=np.bool_)
    for k in range(K):
        p = P[kp[k]]
        m = _grid_query(spts, lo, h, dims, start, sidx, p, radius, bi, bd)
        if _shot_lrf_one(P, p, bi, bd, m, radius, min_nb, V, vd2, vid, frame, tie):
            out[k] = frame
            ties[k, 0] = tie[0]
            ties[k, 1] = tie[1]
    return out, ties


@njit(cache=True)
def _shot_lrf_kernel_csr(
    P: np.ndarray,
    kp: np.ndarray,
    offsets: np.ndarray,
    nbr: np.ndarray,
    d2: np.ndarray,
    radius: float,
    min_nb: int,
):
    """As :func:`_shot_lrf_kernel` on precomputed CSR neighbourhoods."""
    n = P.shape[0]
    K = kp.shape[0]
    out = np.full((K, 3, 3), np.nan)
    ties = np.zeros((K, 2), dtype=np.bool_)
    V = np.empty((n, 3))
    vd2 = np.empty(n)
    vid = np.empty(n, dtype=np.int64)
    frame = np.empty((3, 3))
    tie = np.zeros(2, dtype=np.bool_)
    for k in range(K):
        s0 = offsets[k]
        m = offsets[k + 1] - s0
        if _shot_lrf_one(
            P, P[kp[k]], nbr[s0:], d2[s0:], m, radius, min_nb, V, vd2, vid, frame, tie
        ):
            out[k] = frame
            ties[k, 0] = tie[0]
            ties[k, 1] = tie[1]
    return out, ties


def _shot_lrf_full(
    P: np.ndarray, kp: np.ndarray, radius: float, tree: cKDTree | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`shot_lrf` returning ``(lrf, ties)``; ``ties[k]`` flags median tie-breaks."""
    if tree is None:
        return _shot_lrf_kernel(P, kp, radius, SHOT_MIN_NEIGHBORS)
    nbr, offsets = _support_csr(P, kp, radius, tree)
    owner = np.repeat(np.arange(kp.size), np.diff(offsets))
    d2 = np.sum((P[nbr] - P[kp][owner]) ** 2, axis=1)
    return _shot_lrf_kernel_csr(P, kp, offsets, nbr, d2, radius, SHOT_MIN_NEIGHBORS)


def shot_lrf(
    points: np.ndarray, keypoint_idx: np.ndarray, radius: float, tree: cKDTree | None = None
) -> np.ndarray:
    """SHOT local reference frames as in PCL's ``SHOTLocalReferenceFrameEstimation``.

    For the neighbours ``q_i ≠ p`` within ``radius`` (exact duplicates of ``p`` excluded),
    ``v_i = q_i − p`` (centred on the **keypoint**), ``M = Σ w_i v_i v_iᵀ / Σ w_i`` with
    ``w_i = r − ‖v_i‖``. ``x`` / ``z`` are the eigenvectors of the largest / smallest
    eigenvalue; each sign is chosen so that the majority of ``v_i`` has ``v_i·axis ≥ 0``; on a
    tie, the 5 neighbours around the median of the distance-sorted list decide (flip when fewer
    than 3 have ``v·axis > 0``); ``y = z × x`` (right-handed).

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres.
    keypoint_idx : (K,) int
        Keypoint indices into ``points``.
    radius : float
        LRF radius ``r``, metres.
    tree : scipy.spatial.cKDTree, optional
        Prebuilt tree of ``points``; when given it is used for the radius search (otherwise a
        numba uniform grid is used, which is faster).

    Returns
    -------
    (K, 3, 3) float64
        Rows are the axes ``x, y, z`` in the cloud frame (``q' = LRF @ (q − p)``); NaN when
        fewer than 5 neighbours besides the keypoint lie within ``radius`` or the covariance is
        not finite.

    References
    ----------
    S. Salti, F. Tombari, L. Di Stefano, "SHOT: Unique signatures of histograms for surface and
    texture description", CVIU 125 (2014). doi:10.1016/j.cviu.2014.04.011
    """
    P, kp = _check_points(points, keypoint_idx)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"LRF radius must be positive and finite, got {radius}")
    if kp.size == 0:
        return np.full((0, 3, 3), np.nan)
    return _shot_lrf_full(P, kp, float(radius), tree)[0]


__all__ += ["radius_search", "shot_lrf"]
