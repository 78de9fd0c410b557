"""The target model of relnav's navigator: a fine voxel map of surface points in the target frame.

Each occupied voxel (edge ``voxel_size`` metres, fixed in the target frame) keeps the running mean
of the scan points that fell into it (weights saturate at ``max_weight``, so a patch built during
drift follows where new scans put it); with a voxel a fraction of the scan spacing, the map is a
density-capped accumulation of all accepted scans: much denser than one sparse scan.

Each map point carries a plane-like information matrix (:func:`plane_information`) from its
``k`` nearest map neighbours: strong along the local normal, weak along the surface, so that a scan
point is pulled onto the surface, not onto the sample positions of earlier scans. With
``map.surface="quadric"`` each point also carries the second-order surface of its neighbours
(:func:`quadric_surface`, :attr:`VoxelMap.surface`), from which the registration measures a scan
point's offset instead of from the plane (:func:`relnav.navigation.gicp.solve_scan_to_map`).

**Search structure.** A KD-tree over all points is rebuilt only when the points added since the
last rebuild exceed a fraction of the map (``rebuild_fraction``); the recent points have a small
tree of their own, rebuilt each frame, and a query takes the closer of the two answers. Only the
points of the voxels an update touched get their information recomputed, their ``k`` neighbours
found in the same two numba trees (:func:`relnav.geometry.kdtree.kd_knn`: the same neighbours and
distances as ``cKDTree``, without building a second pair of trees). The cost of a frame is
therefore about linear in the scan size, not in the map size.

The map is bounded: above ``max_voxels`` the least recently seen voxels are dropped.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numba import njit

from relnav.geometry.eigen import jacobi_eigh as _jacobi_eigh
from relnav.geometry.eigen import solve_spd6
from relnav.geometry.kdtree import kd_build_select, kd_knn, kd_knn_within

log = logging.getLogger(__name__)

__all__ = ["VoxelMap", "even_subset", "plane_information", "quadric_surface"]


@njit(cache=True)
def _plane_info_kernel(
    M: np.ndarray,
    nb: np.ndarray,
    inplane_var: float,
    noise_var: float,
    gain: float,
    centers: np.ndarray,
    max_reach: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Information and normal of each row's neighbourhood ``M[nb[i]]`` (-1 entries skipped);
    ``gain``: the non-planarity gain ``γ`` of :func:`plane_information`. With ``centers``
    ``(q, 3)`` (else ``(0, 3)``) also the signed distance of each centre from the plane through
    its neighbours' centroid (0 with fewer than 3 neighbours or where one of them lies farther
    than ``max_reach`` along that plane)."""
    q = nb.shape[0]
    info = np.zeros((q, 3, 3))
    nrm = np.zeros((q, 3))
    off = np.zeros(q)
    with_offsets = centers.shape[0] == q
    C = np.zeros((3, 3))
    for i in range(q):
        m = 0
        c0 = c1 = c2 = 0.0
        for j in range(nb.shape[1]):
            k = nb[i, j]
            if k < 0:
                continue
            c0 += M[k, 0]
            c1 += M[k, 1]
            c2 += M[k, 2]
            m += 1
        if m < 3:
            for a in range(3):
                info[i, a, a] = 1.0 / inplane_var
            nrm[i, 2] = 1.0
            continue
        c0 /= m
        c1 /= m
        c2 /= m
        for a in range(3):
            for b in range(3):
                C[a, b] = 0.0
        for j in range(nb.shape[1]):
            k = nb[i, j]
            if k < 0:
                continue
            d0, d1, d2 = M[k, 0] - c0, M[k, 1] - c1, M[k, 2] - c2
            C[0, 0] += d0 * d0
            C[0, 1] += d0 * d1
            C[0, 2] += d0 * d2
            C[1, 1] += d1 * d1
            C[1, 2] += d1 * d2
            C[2, 2] += d2 * d2
        C[1, 0], C[2, 0], C[2, 1] = C[0, 1], C[0, 2], C[1, 2]
        for a in range(3):
            for b in range(3):
                C[a, b] /= m
        w, V = _jacobi_eigh(C)
        s = 0
        for a in range(1, 3):
            if w[a] < w[s]:
                s = a
        n0, n1, n2 = V[0, s], V[1, s], V[2, s]
        lam0 = max(w[s], 0.0)
        if gain > 0.0:
            lam1 = max(w[0] + w[1] + w[2] - w[s] - max(w[0], max(w[1], w[2])), 1e-300)
            lam0 *= 1.0 + gain * lam0 / lam1
        l0 = lam0 + noise_var
        nrm[i, 0], nrm[i, 1], nrm[i, 2] = n0, n1, n2
        nv = (n0, n1, n2)
        for a in range(3):
            for b in range(3):
                nn = nv[a] * nv[b]
                info[i, a, b] = nn / l0 + ((1.0 if a == b else 0.0) - nn) / inplane_var
        if with_offsets:
            p0, p1, p2 = centers[i, 0], centers[i, 1], centers[i, 2]
            reach2 = 0.0
            for j in range(nb.shape[1]):
                k = nb[i, j]
                if k < 0:
                    continue
                d0, d1, d2 = M[k, 0] - p0, M[k, 1] - p1, M[k, 2] - p2
                h = d0 * n0 + d1 * n1 + d2 * n2
                reach2 = max(reach2, d0 * d0 + d1 * d1 + d2 * d2 - h * h)
            if reach2 <= max_reach * max_reach:
                off[i] = n0 * (p0 - c0) + n1 * (p1 - c1) + n2 * (p2 - c2)
    return info, nrm, off


@njit(cache=True)
def _merge_knn(
    d_a: np.ndarray, i_a: np.ndarray, d_b: np.ndarray, i_b: np.ndarray, k: int
) -> np.ndarray:  # pragma: no cover - numba
    """Indices of the ``k`` nearest of two sorted k-NN answers (``-1``: fewer than ``k``)."""
    q = d_a.shape[0]
    out = np.full((q, k), -1, np.int64)
    for i in range(q):
        a = 0
        b = 0
        for j in range(k):
            da = d_a[i, a] if a < d_a.shape[1] else np.inf
            db = d_b[i, b] if b < d_b.shape[1] else np.inf
            if not (np.isfinite(da) or np.isfinite(db)):
                break
            if da <= db:
                out[i, j] = i_a[i, a]
                a += 1
            else:
                out[i, j] = i_b[i, b]
                b += 1
    return out


@njit(cache=True)
def _map_knn(
    main: tuple, recent: tuple, Q: np.ndarray, k: int, n_main: int, n_recent: int
) -> np.ndarray:  # pragma: no cover - numba
    """Map indices of the ``k`` nearest map points of each ``Q[i]`` over the main and the recent
    search trees (:attr:`VoxelMap.search_trees`; ``n_main``, ``n_recent``: their point counts),
    nearest first (``-1``: fewer than ``k``). The recent tree is searched only closer than the
    main tree's ``k``-th (a point there as far or farther would not be kept)."""
    mp, mperm, mdim, mval = main
    rp, rperm, rdim, rval, rids = recent
    d_a, i_a = kd_knn(mp, mperm, mdim, mval, Q, min(k, n_main))
    if n_recent > 0:
        bound2 = np.full(Q.shape[0], np.inf)
        if d_a.shape[1] == k:
            for i in range(Q.shape[0]):
                if i_a[i, k - 1] >= 0:
                    # a hair above d²: the merge, not the bound, decides at a tie
                    bound2[i] = d_a[i, k - 1] * d_a[i, k - 1] * (1.0 + 1e-12)
        d_b, i_b = kd_knn_within(rp, rperm, rdim, rval, Q, min(k, n_recent), bound2)
        for i in range(i_b.shape[0]):
            for j in range(i_b.shape[1]):
                if i_b[i, j] >= 0:
                    i_b[i, j] = rids[i_b[i, j]]
    else:
        d_b = np.full((Q.shape[0], 1), np.inf)
        i_b = np.full((Q.shape[0], 1), -1, np.int64)
    return _merge_knn(d_a, i_a, d_b, i_b, k)


@njit(cache=True)
def _quadric_kernel(
    M: np.ndarray,
    centers: np.ndarray,
    nb: np.ndarray,
    nrm: np.ndarray,
    noise_var: float,
    curv_sigma: float,
    max_reach: float,
) -> np.ndarray:  # pragma: no cover - numba
    """Second-order surface of each neighbourhood about its centre (see :func:`quadric_surface`)."""
    q = nb.shape[0]
    out = np.zeros((q, 11))
    A = np.zeros((6, 6))
    b = np.zeros(6)
    row = np.zeros(6)
    for i in range(q):
        n0, n1, n2 = nrm[i, 0], nrm[i, 1], nrm[i, 2]
        # a tangent basis (t1, t2) orthonormal to n
        if abs(n0) < 0.9:
            a0, a1, a2 = 0.0, -n2, n1  # e_x × n
        else:
            a0, a1, a2 = n2, 0.0, -n0  # e_y × n
        na = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        t10, t11, t12 = a0 / na, a1 / na, a2 / na
        t20 = n1 * t12 - n2 * t11
        t21 = n2 * t10 - n0 * t12
        t22 = n0 * t11 - n1 * t10
        for r in range(6):
            b[r] = 0.0
            for cc in range(6):
                A[r, cc] = 0.0
        m = 0
        reach = 0.0
        for j in range(nb.shape[1]):
            k = nb[i, j]
            if k < 0:
                continue
            d0 = M[k, 0] - centers[i, 0]
            d1 = M[k, 1] - centers[i, 1]
            d2 = M[k, 2] - centers[i, 2]
            u = t10 * d0 + t11 * d1 + t12 * d2
            v = t20 * d0 + t21 * d1 + t22 * d2
            h = n0 * d0 + n1 * d1 + n2 * d2
            reach = max(reach, math.sqrt(u * u + v * v))
            row[0], row[1], row[2] = 1.0, u, v
            row[3], row[4], row[5] = 0.5 * u * u, u * v, 0.5 * v * v
            for r in range(6):
                b[r] += row[r] * h / noise_var
                for cc in range(6):
                    A[r, cc] += row[r] * row[cc] / noise_var
            m += 1
        if m < 3 or reach > max_reach:
            continue  # a plane
        # priors: offset ~ N(0, σ_n²), slope ~ N(0, 1), curvature ~ N(0, curv_sigma²)
        A[0, 0] += 1.0 / noise_var
        A[1, 1] += 1.0
        A[2, 2] += 1.0
        for r in range(3, 6):
            A[r, r] += 1.0 / (curv_sigma * curv_sigma)
        c = solve_spd6(A, b)
        t1 = (t10, t11, t12)
        t2 = (t20, t21, t22)
        out[i, 0] = c[0]
        out[i, 10] = reach
        for a in range(3):
            out[i, 1 + a] = c[1] * t1[a] + c[2] * t2[a]
        s = 4
        for a in range(3):
            for bb in range(a, 3):
                out[i, s] = (
                    c[3] * t1[a] * t1[bb]
                    + c[4] * (t1[a] * t2[bb] + t2[a] * t1[bb])
                    + c[5] * t2[a] * t2[bb]
                )
                s += 1
    return out


def quadric_surface(
    points: np.ndarray,
    centers: np.ndarray,
    neighbors: np.ndarray,
    normals: np.ndarray,
    noise_floor: float,
    curvature_sigma: float = 0.3,
    max_reach: float = np.inf,
) -> np.ndarray:
    """Second-order surface of each neighbourhood about its centre.

    In the tangent frame ``(t₁, t₂, n)`` of ``centers[i]`` (``n``: its patch normal) the
    heights ``h = n·(p − c)`` of the neighbours are fitted by
    ``h = c₀ + g·d + ½ dᵀ S d`` (``d``: the tangential offset), least squares with Gaussian
    priors ``c₀ ~ N(0, σ_n²)``, slopes ``~ N(0, 1)`` and curvatures ``~ N(0, κ_σ²)``.
    **[interpretation]** A plane through a map sample is exact only at the sample: on a curved
    surface a scan point between samples is off the plane by ``d²/2R``, so a point-to-plane
    cost is lowest where the scan repeats the map's sample positions ("no motion" along a
    surface that slides along itself, such as a body of revolution turning about its axis).
    The curved patch removes that pull. A neighbourhood that reaches farther than
    ``max_reach`` (a sparse map: one scan, a thin part) stays a plane (a zero row): there the
    neighbours are too far apart for their curvature to be the surface's.

    Parameters
    ----------
    points : (M, 3) float64
        Map points, m.
    centers : (Q, 3) float64
        Patch centres (the map points whose patches these are), m.
    neighbors : (Q, k) int
        Indices of each neighbourhood in ``points`` (``-1`` = none).
    normals : (Q, 3) float64
        Unit patch normals.
    noise_floor : float
        ``σ_n``, m.
    curvature_sigma : float
        ``κ_σ``, 1/m.
    max_reach : float
        Largest tangential distance of a neighbour for a curved patch, m.

    Returns
    -------
    (Q, 11) float64
        ``[c₀, g (3, target frame), S (upper triangle: xx, xy, xz, yy, yz, zz), r]``; ``g``
        and ``S`` lie in the tangent plane, so ``h(e) = c₀ + g·e + ½ eᵀ S e`` for any offset
        ``e``; ``r`` (m) is the largest tangential distance of a neighbour: the fit holds
        within it, and an offset beyond is evaluated at ``r`` in its direction (the surface
        continues along its tangent there, not along the parabola).
    """
    return _quadric_kernel(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(centers, dtype=np.float64),
        np.ascontiguousarray(neighbors, dtype=np.int64),
        np.ascontiguousarray(normals, dtype=np.float64),
        float(noise_floor) ** 2,
        float(curvature_sigma),
        float(max_reach),
    )


def plane_information(
    points: np.ndarray,
    neighbors: np.ndarray,
    inplane_sigma: float,
    noise_floor: float,
    nonplanar_gain: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Plane-like information matrices of neighbourhoods.

    For the neighbourhood ``points[neighbors[i]]`` with covariance ``C``, normal ``n`` (the
    eigenvector of the smallest eigenvalue ``λ₀``):
    ``Ω = n nᵀ / (λ₀ + σ_n²) + (I − n nᵀ) / σ_p²`` — strong along the normal, weak along the
    surface **[interpretation: GICP's plane regularisation with physical scales]**. Fewer than 3
    neighbours give ``Ω = I / σ_p²``.

    With a non-planarity gain ``γ > 0`` the variance along the normal becomes
    ``λ₀ (1 + γ λ₀/λ₁) + σ_n²`` (``λ₁``: the middle eigenvalue): a neighbourhood that is not a
    plane (an edge, a corner, a rim, a small detail) gets less information along its fitted
    normal, a plane or a gently curved surface keeps it. **[interpretation]** At such a patch
    the plane model is wrong between the map's samples, so a scan point that falls between
    them has a residual that depends on where the samples are, not on the pose; on sparse
    scans of near-symmetric or small targets those residuals are what "constrains" the weak
    directions (see :class:`relnav.navigation.navigator.NavigatorConfig`, ``nonplanar_gain``).

    Parameters
    ----------
    points : (M, 3) float64
        Map points, m.
    neighbors : (Q, k) int
        Indices of each neighbourhood (``-1`` = none).
    inplane_sigma, noise_floor : float
        ``σ_p`` and ``σ_n`` in metres.
    nonplanar_gain : float
        ``γ`` (dimensionless, ``≥ 0``; 0: the plain plane model).

    Returns
    -------
    info : (Q, 3, 3) float64
        Information matrices, 1/m².
    normals : (Q, 3) float64
        Unit normals (sign arbitrary).
    """
    info, normals, _ = _plane_patches(points, neighbors, inplane_sigma, noise_floor, nonplanar_gain)
    return info, normals


def _plane_patches(
    points: np.ndarray,
    neighbors: np.ndarray,
    inplane_sigma: float,
    noise_floor: float,
    nonplanar_gain: float = 0.0,
    centers: np.ndarray | None = None,
    max_reach: float = np.inf,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`plane_information`'s ``(info, normals)`` and, for the patches' ``centers``
    ``(Q, 3)``, their signed distances ``(Q,)`` (m, along the normal) from the plane through
    their neighbours' centroid (0 with fewer than 3 neighbours or where the neighbourhood reaches
    farther than ``max_reach`` (m) along that plane: a sparse map, a thin part; zeros without
    ``centers``)."""
    C = np.zeros((0, 3)) if centers is None else centers
    return _plane_info_kernel(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(neighbors, dtype=np.int64),
        float(inplane_sigma) ** 2,
        float(noise_floor) ** 2,
        float(nonplanar_gain),
        np.ascontiguousarray(C, dtype=np.float64),
        float(max_reach),
    )


_FAR = np.full((1, 3), 1e18)
_HALF = 1 << 20  # cells per axis on each side of the origin that a packed code can hold


@njit(cache=True)
def _pack(keys: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """One int64 per voxel cell (21 bits per axis), ordered as the cells lexicographically."""
    k = keys.astype(np.int64) + _HALF
    return (k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2]


@njit(cache=True)
def _cell_keys(P: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    """Each point's cell ``⌊p / voxel⌋`` (int64; 0 on an axis out of range) and whether the
    cell is within :func:`_pack`'s range (``|key| < 2²⁰`` per axis; not for a NaN)."""
    n = P.shape[0]
    keys = np.empty((n, 3), np.int64)
    inside = np.ones(n, np.bool_)
    for i in range(n):
        for d in range(3):
            k = np.floor(P[i, d] / voxel)
            if not abs(k) < _HALF:  # also NaN
                inside[i] = False
                k = 0.0
            keys[i, d] = np.int64(k)
    return keys, inside


@njit(cache=True)
def _cells(codes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    """``np.unique(codes, return_index=True, return_inverse=True)``: the sorted distinct cell
    codes, the first point of each and each point's cell."""
    n = len(codes)
    order = np.argsort(codes, kind="mergesort")
    uniq, first, inv = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    m = -1
    for r in range(n):
        i = order[r]
        if m < 0 or codes[i] != uniq[m]:
            m += 1
            uniq[m], first[m] = codes[i], i
        inv[i] = m
    return uniq[: m + 1].copy(), first[: m + 1].copy(), inv


@njit(cache=True)
def _lookup_sorted(
    codes: np.ndarray, slots: np.ndarray, query: np.ndarray
) -> np.ndarray:  # pragma: no cover - numba
    """Storage slot of each cell code ``query`` in the sorted index ``(codes, slots)`` (-1: not
    in the map)."""
    out = np.full(len(query), -1, np.int64)
    if len(codes) == 0:
        return out
    pos = np.searchsorted(codes, query)
    for i in range(len(query)):
        p = min(pos[i], len(codes) - 1)
        if codes[p] == query[i]:
            out[i] = slots[p]
    return out


@njit(cache=True)
def _merge_sorted(
    codes: np.ndarray, slots: np.ndarray, new_codes: np.ndarray, new_slots: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """The sorted index ``(codes, slots)`` with the new cells (sorted, none already in it)."""
    n, m = len(codes), len(new_codes)
    out_c, out_s = np.empty(n + m, np.int64), np.empty(n + m, np.int64)
    i = j = 0
    for k in range(n + m):
        if j >= m or (i < n and codes[i] < new_codes[j]):
            out_c[k], out_s[k] = codes[i], slots[i]
            i += 1
        else:
            out_c[k], out_s[k] = new_codes[j], new_slots[j]
            j += 1
    return out_c, out_s


@njit(cache=True)
def _accumulate(
    P: np.ndarray,
    inv: np.ndarray,
    slots: np.ndarray,
    w: np.ndarray,
    s1: np.ndarray,
    seen: np.ndarray,
    frame: int,
    max_weight: float,
) -> None:  # pragma: no cover - numba
    """Add the points ``P`` to their voxels (``slots[inv]``): counts and sums, the old ones
    forgotten geometrically beyond ``max_weight`` observations (see :meth:`VoxelMap.insert`)."""
    m = len(slots)
    w_add, s1_add = np.zeros(m), np.zeros((m, 3))
    for i in range(len(P)):
        u = inv[i]
        w_add[u] += 1.0
        for d in range(3):
            s1_add[u, d] += P[i, d]
    for u in range(m):
        k = slots[u]
        w_old = w[k]
        scale = 1.0
        if w_old + w_add[u] > max_weight:
            scale = max(max_weight - w_add[u], 0.0) / max(w_old, 1e-12)
        w_new = w_old * scale + w_add[u]
        cap = min(1.0, max_weight / max(w_new, 1e-12))  # one big batch
        w[k] = w_new * cap
        for d in range(3):
            s1[k, d] = (s1[k, d] * scale + s1_add[u, d]) * cap
        seen[k] = frame


class VoxelMap:
    """Voxel map of surface points in the target frame (see the module doc).

    Parameters
    ----------
    voxel_size : float
        Voxel edge, metres.
    max_weight : float
        Observations after which a voxel's running mean forgets geometrically.
    max_voxels : int
        Bound on the number of voxels; the least recently updated ones go first.
    noise_floor : float
        Smallest standard deviation (m) along a patch's normal (sensor noise and map blur).
    inplane_sigma : float, optional
        Standard deviation (m) along a patch's plane (default ``2 · voxel_size``).
    k_neighbors : int
        Map points per patch.
    rebuild_fraction : float
        Rebuild the main search tree when the points added since the last rebuild exceed this
        fraction of the map.
    nonplanar_gain : float
        Non-planarity gain ``γ`` of the patches' information (:func:`plane_information`; 0 =
        off).
    surface : {"plane", "quadric"}
        The patch model used by the registration: the plane through each map point, or the
        second-order surface of its neighbourhood (:func:`quadric_surface`, :attr:`surface`).
    curvature_sigma : float
        Prior 1σ of a quadric patch's curvatures, 1/m.
    quadric_reach : float
        A patch whose neighbours reach farther than this (m) stays a plane.
    patch_point : {"mean", "plane"}
        Where a plane patch's residuals are measured from (:attr:`patch_points`): the voxel's mean,
        or that mean moved along the patch's normal toward the plane through its neighbours'
        centroid (not where they reach farther than ``patch_point_reach``, m).
    """

    def __init__(
        self,
        voxel_size: float,
        *,
        max_weight: float = 20.0,
        max_voxels: int = 200_000,
        noise_floor: float = 0.02,
        inplane_sigma: float | None = None,
        k_neighbors: int = 10,
        rebuild_fraction: float = 0.1,
        nonplanar_gain: float = 0.0,
        surface: str = "plane",
        curvature_sigma: float = 0.3,
        quadric_reach: float = np.inf,
        patch_point: str = "mean",
        patch_point_reach: float = np.inf,
    ) -> None:
        if not (np.isfinite(voxel_size) and voxel_size > 0):
            raise ValueError(f"voxel_size must be a positive number of metres, got {voxel_size}")
        self.voxel_size = float(voxel_size)
        self.max_weight = float(max_weight)
        self.max_voxels = int(max_voxels)
        self.noise_floor = float(noise_floor)
        self.inplane_sigma = float(inplane_sigma) if inplane_sigma else 2.0 * self.voxel_size
        self.k_neighbors = int(k_neighbors)
        self.rebuild_fraction = float(rebuild_fraction)
        if not (np.isfinite(nonplanar_gain) and nonplanar_gain >= 0):
            raise ValueError(f"nonplanar_gain must be a number >= 0, got {nonplanar_gain}")
        self.nonplanar_gain = float(nonplanar_gain)
        if surface not in ("plane", "quadric"):
            raise ValueError(f"surface must be 'plane' or 'quadric', got {surface!r}")
        if not (np.isfinite(curvature_sigma) and curvature_sigma > 0):
            raise ValueError(f"curvature_sigma must be a number > 0, got {curvature_sigma}")
        if not quadric_reach >= 0:
            raise ValueError(f"quadric_reach must be >= 0 metres, got {quadric_reach}")
        if patch_point not in ("mean", "plane"):
            raise ValueError(f"patch_point must be 'mean' or 'plane', got {patch_point!r}")
        self.patch_point = patch_point
        if not patch_point_reach >= 0:
            raise ValueError(f"patch_point_reach must be >= 0 metres, got {patch_point_reach}")
        self.patch_point_reach = float(patch_point_reach)
        self.surface_model = surface
        self.curvature_sigma = float(curvature_sigma)
        self.quadric_reach = float(quadric_reach)
        # voxel index: packed cell codes, sorted, and the storage slot of each
        self._codes = np.zeros(0, dtype=np.int64)
        self._code_slots = np.zeros(0, dtype=np.int64)
        cap = 1024
        self._w = np.zeros(cap)
        self._s1 = np.zeros((cap, 3))
        self._seen = np.zeros(cap, dtype=np.int64)
        self._keys = np.zeros((cap, 3), dtype=np.int64)
        self._info_all = np.zeros((cap, 3, 3))
        self._normal_all = np.zeros((cap, 3))
        self._quad_all = np.zeros((cap, 11))
        self._patch_all = np.zeros((cap, 3))
        self.n = 0
        self._touched: set[int] = set()
        self._n_main = 0  # points [0, n_main) are in the main trees
        self._main_nb: tuple[np.ndarray, ...] | None = None
        self._recent_nb: tuple[np.ndarray, ...] | None = None
        self._mean: np.ndarray | None = None
        self._dirty = True

    def __len__(self) -> int:
        return self.n

    # ------------------------------------------------------------------ update
    def insert(self, points: np.ndarray, frame: int) -> None:
        """Add points (target frame, m) observed at ``frame``."""
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if not len(P):
            return
        keys, inside = _cell_keys(np.ascontiguousarray(P), self.voxel_size)
        if not inside.all():
            log.warning("%d points beyond the map's cell range dropped", int((~inside).sum()))
            P, keys = P[inside], keys[inside]
            if not len(P):
                return
        uniq, first, inv = _cells(_pack(keys))
        slots = _lookup_sorted(self._codes, self._code_slots, uniq)
        new = slots < 0
        if new.any():
            slots[new] = self._append(keys[first[new]])
            self._codes, self._code_slots = _merge_sorted(
                self._codes, self._code_slots, uniq[new], slots[new]
            )
        _accumulate(
            np.ascontiguousarray(P),
            inv,
            slots,
            self._w,
            self._s1,
            self._seen,
            frame,
            self.max_weight,
        )
        self._touched.update(slots.tolist())
        if self.n > self.max_voxels:
            self._evict()
        self._dirty = True

    def _append(self, keys: np.ndarray) -> np.ndarray:
        """New empty voxels for the cells ``keys`` (``(m, 3)`` int64); their slots."""
        m = len(keys)
        if self.n + m > len(self._w):
            cap = max(2 * len(self._w), self.n + m)
            self._w = np.resize(self._w, cap)
            self._s1 = np.resize(self._s1, (cap, 3))
            self._seen = np.resize(self._seen, cap)
            self._keys = np.resize(self._keys, (cap, 3))
            self._info_all = np.resize(self._info_all, (cap, 3, 3))
            self._normal_all = np.resize(self._normal_all, (cap, 3))
            self._quad_all = np.resize(self._quad_all, (cap, 11))
            self._patch_all = np.resize(self._patch_all, (cap, 3))
        i = np.arange(self.n, self.n + m, dtype=np.int64)
        self._w[i] = 0.0
        self._s1[i] = 0.0
        self._keys[i] = keys
        self.n += m
        return i

    def _evict(self) -> None:
        keep = np.sort(np.argsort(-self._seen[: self.n], kind="stable")[: self.max_voxels])
        for name in (
            "_w",
            "_s1",
            "_seen",
            "_keys",
            "_info_all",
            "_normal_all",
            "_quad_all",
            "_patch_all",
        ):
            setattr(self, name, getattr(self, name)[keep].copy())
        self.n = len(keep)
        codes = _pack(self._keys[: self.n])
        order = np.argsort(codes, kind="stable")
        self._codes, self._code_slots = codes[order], order.astype(np.int64)
        self._touched = set(range(self.n))
        self._n_main = 0  # force a rebuild

    # ------------------------------------------------------------------ queries
    @property
    def weights(self) -> np.ndarray:
        """``(M,)`` observations per voxel (after forgetting)."""
        return self._w[: self.n]

    @property
    def last_seen(self) -> np.ndarray:
        """``(M,)`` frame index of each voxel's last update."""
        return self._seen[: self.n]

    @property
    def means(self) -> np.ndarray:
        """``(M, 3)`` voxel means in the target frame, m."""
        self._refresh()
        assert self._mean is not None
        return self._mean

    @property
    def patch_points(self) -> np.ndarray:
        """``(M, 3)`` the points a plane patch's residuals are measured from, target frame, m:
        the voxel means (``patch_point="mean"``) or, with ``"plane"``, each mean moved along its
        patch's normal toward the plane through its ``k`` neighbours' centroid.

        **[interpretation]** A voxel holds a few noisy observations, so its mean is off the
        surface by about the sensor's noise; the patch's plane is fitted to ``k`` of them and is
        off by about ``1/√k`` of it, but biased where the surface curves. The point moves along
        the normal by the precision-weighted share of the distance ``d`` from the mean to the
        plane, ``d / (1 + w)``: the mean of ``w`` observations has variance ``σ²/w``, the plane
        is counted at ``σ²`` (its curvature bias taken as one observation's noise). A voxel seen
        once moves half-way, one seen 20 times (a hold point's repeated rays) by 5 %. It keeps
        its normal and its in-plane position (the nearest-point search still uses the means). A
        neighbourhood that reaches farther than ``patch_point_reach`` along its plane keeps its
        mean: on a sparse map the plane of ``k`` far neighbours cuts through a curved surface.
        """
        self._refresh()
        if self.patch_point == "plane":
            return self._patch_all[: self.n]
        assert self._mean is not None
        return self._mean

    @property
    def information(self) -> np.ndarray:
        """``(M, 3, 3)`` information matrices of the map points, 1/m²."""
        self._refresh()
        return self._info_all[: self.n]

    @property
    def normals(self) -> np.ndarray:
        """``(M, 3)`` unit normals (sign arbitrary)."""
        self._refresh()
        return self._normal_all[: self.n]

    @property
    def surface(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(normals (M, 3), quadric (M, 11))`` of the map points when the patch model is
        ``"quadric"`` (:func:`quadric_surface`), else ``None`` (plane patches)."""
        if self.surface_model != "quadric":
            return None
        self._refresh()
        return self._normal_all[: self.n], self._quad_all[: self.n]

    @property
    def search_trees(self) -> tuple[np.ndarray, ...]:
        """Numba KD-tree arrays for nearest-map-point queries.

        ``(main_pts, main_perm, main_dim, main_val, recent_pts, recent_perm, recent_dim,
        recent_val, recent_ids)``: the main tree indexes map points ``[0, n_main)``, the recent
        tree the others (``recent_ids`` maps its indices to map indices).
        """
        self._refresh()
        assert self._main_nb is not None and self._recent_nb is not None
        return (*self._main_nb, *self._recent_nb)

    def _refresh(self) -> None:
        if not self._dirty:
            return
        n = self.n
        mu = np.ascontiguousarray(self._s1[:n] / np.maximum(self._w[:n], 1e-12)[:, None])
        n_recent = n - self._n_main
        if self._main_nb is None or self._n_main == 0 or n_recent > self.rebuild_fraction * n:
            self._n_main = n
            self._main_nb = kd_build_select(mu, 8)
        start = self._n_main
        recent = np.ascontiguousarray(mu[start:]) if n > start else _FAR
        ids = np.arange(start, n, dtype=np.int64) if n > start else np.array([-1], np.int64)
        self._recent_nb = (*kd_build_select(recent, 8), ids)
        touched = np.fromiter(self._touched, dtype=np.int64, count=len(self._touched))
        if len(touched):
            k = min(self.k_neighbors, n)
            nb = _map_knn(self._main_nb, self._recent_nb, mu[touched], k, start, n - start)
            plane = self.patch_point == "plane"
            info, nrm, off = _plane_patches(
                mu,
                nb,
                self.inplane_sigma,
                self.noise_floor,
                self.nonplanar_gain,
                centers=mu[touched] if plane else None,
                max_reach=self.patch_point_reach,
            )
            self._info_all[touched] = info
            self._normal_all[touched] = nrm
            if plane:  # the shift toward the plane, weighed against the voxel's observations
                shift = off / (1.0 + np.maximum(self._w[touched], 1.0))
                self._patch_all[touched] = mu[touched] - nrm * shift[:, None]
            if self.surface_model == "quadric":
                self._quad_all[touched] = quadric_surface(
                    mu,
                    mu[touched],
                    nb,
                    nrm,
                    self.noise_floor,
                    self.curvature_sigma,
                    self.quadric_reach,
                )
        self._touched = set()
        self._mean = mu
        self._dirty = False


def even_subset(P: np.ndarray, budget: int) -> np.ndarray:
    """At most ``budget`` points, evenly spaced in scan order (all when there are fewer)."""
    if len(P) <= budget:
        return P
    return P[np.linspace(0, len(P) - 1, budget).astype(np.int64)]
