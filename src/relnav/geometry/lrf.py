"""Local reference frames (LRF) for local 3D descriptors.

Convention used by :func:`rops_lrf`: an LRF is a ``(3, 3)`` float64 matrix whose **rows** are the
unit axes ``x, y, z`` expressed in the cloud frame, so the local coordinates of a support point
``q`` around the keypoint ``p`` are ``q' = LRF @ (q - p)``. Frames are right-handed
(``det = +1``); an undefined frame is a matrix of NaN.

This module computes the RoPS LRF; the SHOT LRF lives in :mod:`relnav.geometry.shot_lrf` and the
grid radius search both use in :mod:`relnav.geometry.radius_grid` (re-exported here).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.errors import ConfigError, InputError
from relnav.geometry.local_mesh import local_mesh_triangles
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.radius_grid import _argsort_d2_idx as _argsort_d2_idx  # numba, old path
from relnav.geometry.radius_grid import _group_csr as _group_csr
from relnav.geometry.radius_grid import _radius_csr_kernel as _radius_csr_kernel
from relnav.geometry.radius_grid import check_points, radius_search, support_csr
from relnav.geometry.radius_grid import grid_build as grid_build
from relnav.geometry.radius_grid import grid_query as grid_query
from relnav.geometry.shot_lrf import SHOT_MIN_NEIGHBORS, shot_lrf
from relnav.geometry.shot_lrf import _shot_lrf_full as _shot_lrf_full
from relnav.geometry.shot_lrf import _shot_lrf_kernel as _shot_lrf_kernel
from relnav.geometry.shot_lrf import _shot_lrf_kernel_csr as _shot_lrf_kernel_csr
from relnav.geometry.shot_lrf import shot_lrf_one as shot_lrf_one

__all__ = ["SHOT_MIN_NEIGHBORS", "radius_search", "rops_local_mesh", "rops_lrf", "shot_lrf"]

ROPS_MIN_SUPPORT = 5
"""Minimum support points (keypoint included) for a RoPS LRF (same rule as descriptors)."""

ROPS_LRF_MODES = ("local_mesh", "points")
"""Frames of :func:`rops_lrf` without a given mesh: local triangulation (default) or points."""

ROPS_MAX_EDGE_FACTOR = 3.0
"""Default longest local-mesh edge in mean resolutions ``Tr`` (**[interpretation]**; PCL's
greedy projection uses ``mu = 2.5`` times each point's nearest-neighbour distance)."""


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
    """Mesh RoPS LRF on a local Delaunay triangulation (:func:`local_mesh_triangles`).

    ``flat``/``offsets``: CSR neighbourhoods of radius ``radius + max_edge`` (keypoint included).
    """
    K = kp.shape[0]
    out = np.full((K, 3, 3), np.nan)
    C = np.zeros((3, 3))
    m = np.zeros(3)
    frame = np.zeros((3, 3))
    vv = np.zeros((3, 3))
    for k in range(K):
        p = P[kp[k]]
        tris = local_mesh_triangles(
            P, p, flat[offsets[k] : offsets[k + 1]], radius, max_edge, min_support
        )
        nt = tris.shape[0]
        if nt == 0:
            continue
        ssum = _mesh_scatter(P, p, tris, np.arange(nt), nt, radius, C, m, vv)
        if not (ssum > 0.0):
            continue
        if _frame_from_scatter(C, m, ssum, tol, frame):
            out[k] = frame
    return out


@njit(cache=True)
def _local_mesh_csr_kernel(
    P: np.ndarray,
    kp: np.ndarray,
    flat: np.ndarray,
    offsets: np.ndarray,
    radius: float,
    max_edge: float,
    min_support: int,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`local_mesh_triangles` of every keypoint as CSR ``(tri_offsets, triangles)``."""
    K = kp.shape[0]
    tri_off = np.zeros(K + 1, dtype=np.int64)
    buf = np.empty((max(16, 2 * flat.shape[0]), 3), dtype=np.int64)
    for k in range(K):
        tris = local_mesh_triangles(
            P, P[kp[k]], flat[offsets[k] : offsets[k + 1]], radius, max_edge, min_support
        )
        s = tri_off[k]
        e = s + tris.shape[0]
        if e > buf.shape[0]:
            grown = np.empty((2 * e, 3), dtype=np.int64)
            grown[:s] = buf[:s]
            buf = grown
        buf[s:e] = tris
        tri_off[k + 1] = e
    return tri_off, buf[: tri_off[K]].copy()


def _local_mesh_support(
    P: np.ndarray, kp: np.ndarray, radius: float, max_edge: float | None, tree: cKDTree | None
) -> tuple[float, np.ndarray, np.ndarray] | None:
    """``(max_edge, flat, offsets)``: the local-mesh edge limit (default ``3·Tr``) and the CSR
    neighbourhoods of radius ``radius + max_edge``; None for fewer than two distinct points."""
    if max_edge is None:
        max_edge = ROPS_MAX_EDGE_FACTOR * mean_resolution(P, tree)
    if not np.isfinite(max_edge):
        return None
    flat, offsets = support_csr(P, kp, radius + float(max_edge), tree)
    return float(max_edge), flat, offsets


def rops_local_mesh(
    points: np.ndarray,
    keypoint_idx: np.ndarray,
    radius: float,
    *,
    max_edge: float | None = None,
    tree: cKDTree | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The local triangles the default RoPS LRF (``lrf="local_mesh"``) uses at each keypoint.

    Same code path as :func:`rops_lrf` (:func:`relnav.geometry.local_mesh.local_mesh_triangles`
    on the same neighbourhoods), so ``rops_lrf(points, [kp[k]], radius,
    triangles=triangles[tri_offsets[k]:tri_offsets[k + 1]])`` is the default frame of keypoint
    ``k`` (up to the summation order). Each keypoint has its own mesh: the meshes of nearby
    keypoints overlap and need not agree, so their union is not a mesh of the cloud.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres.
    keypoint_idx : (K,) int
        Keypoint indices into ``points``.
    radius : float
        Support radius ``r``, metres.
    max_edge : float, optional
        Longest local-mesh edge, metres (default ``3·Tr``, ``Tr`` the mean resolution).
    tree : scipy.spatial.cKDTree, optional
        Prebuilt tree of ``points`` (as passed to :func:`rops_lrf`).

    Returns
    -------
    tri_offsets : (K + 1,) int64
        Keypoint ``k``'s triangles are rows ``tri_offsets[k]:tri_offsets[k + 1]``; none when its
        support has fewer than 5 points (keypoint included).
    triangles : (M, 3) int64
        Vertex indices into ``points``; every triangle has a vertex within ``radius`` of its
        keypoint and no edge longer than ``max_edge``.
    """
    P, kp = check_points(points, keypoint_idx)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"local-mesh radius must be positive and finite, got {radius}")
    check_rops_lrf("local_mesh", max_edge)
    empty = (np.zeros(kp.size + 1, dtype=np.int64), np.zeros((0, 3), dtype=np.int64))
    if kp.size == 0:
        return empty
    sup = _local_mesh_support(P, kp, float(radius), max_edge, tree)
    if sup is None:
        return empty
    me, flat, offsets = sup
    return _local_mesh_csr_kernel(P, kp, flat, offsets, float(radius), me, ROPS_MIN_SUPPORT)


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
    (:mod:`relnav.geometry.local_mesh`); :func:`rops_local_mesh` returns these triangles.

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
    P, kp = check_points(points, keypoint_idx)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"LRF radius must be positive and finite, got {radius}")
    if kp.size == 0:
        return np.full((0, 3, 3), np.nan)
    check_rops_lrf(lrf, max_edge)
    flat, offsets = support_csr(P, kp, float(radius), tree)
    return rops_lrf_csr(
        P, kp, flat, offsets, float(radius), triangles, float(degenerate_tol), lrf, max_edge, tree
    )


def check_rops_lrf(lrf: str, max_edge: float | None) -> None:
    """Raise :class:`ConfigError` for an unknown RoPS frame or a bad ``max_edge``."""
    if lrf not in ROPS_LRF_MODES:
        raise ConfigError(f"RoPS lrf must be one of {ROPS_LRF_MODES}, got {lrf!r}")
    if max_edge is not None and not (np.isfinite(max_edge) and max_edge > 0):
        raise ConfigError(f"RoPS max_edge must be positive and finite, got {max_edge}")


def rops_lrf_csr(
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
    """:func:`rops_lrf` on precomputed support neighbourhoods (CSR from :func:`support_csr`)."""
    if triangles is None and lrf == "points":
        return _rops_lrf_points_kernel(P, kp, flat, offsets, radius, ROPS_MIN_SUPPORT, tol)
    if triangles is None:
        check_rops_lrf(lrf, max_edge)
        sup = _local_mesh_support(P, kp, radius, max_edge, tree)
        if sup is None:  # fewer than two distinct points: no frame
            return np.full((kp.shape[0], 3, 3), np.nan)
        me, ext_flat, ext_off = sup
        return _rops_lrf_local_mesh_kernel(
            P, kp, ext_flat, ext_off, radius, me, ROPS_MIN_SUPPORT, tol
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
