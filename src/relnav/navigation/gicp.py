"""Robust scan-to-map registration with a motion prior (the navigator's inner solver).

One Gauss–Newton problem per frame, solved in a single numba function:

.. math::

    \\min_T \\sum_i \\rho\\big(e_i^T \\Omega_{j(i)} e_i\\big)
    + \\xi(T)^T \\Lambda\\, \\xi(T), \\qquad e_i = T p_i - \\mu_{j(i)},

where ``p_i`` are the scan points (sensor frame), ``μ_j`` / ``Ω_j`` the mean and information of
the nearest voxel of the map (target frame; :class:`relnav.navigation.voxel_map.VoxelMap`),
``ρ`` the Geman–McClure kernel with scale ``c`` (in units of the Mahalanobis distance), and
``ξ(T) = log(T T_pred⁻¹)`` the left twist from the motion model's prediction with information
``Λ``. Directions the scan does not constrain (a symmetric target seen along its axis, a flat
panel) are taken from the prior instead of drifting: the prior is part of the least squares, not
a gate applied afterwards.

Perturbations are on the left, ``T ← exp(δ) T`` with ``δ = [ρ (m), φ (rad)]`` in the target
frame, so ``∂e/∂δ = [I, −[Tp]×]``. The solver returns the registration's own information
``H = Σ w JᵀΩJ`` (without the prior) for covariance and degeneracy checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from relnav.geometry.eigen import matmul, matmul_t, pinv_sym, solve_spd6, sym_eigvals, symmetrize
from relnav.geometry.icp_kernels import rodrigues_nb
from relnav.geometry.kdtree import kd_children
from relnav.geometry.lie import adjoint_nb, invert_nb, log_se3_nb, rot_log_nb

if TYPE_CHECKING:
    from relnav.navigation.voxel_map import VoxelMap

__all__ = [
    "ScanToMapFit",
    "degeneracy",
    "left_information",
    "normal_information",
    "solve_scan_to_map",
    "variance_factor",
]


@njit(cache=True)
def _prior_twist(T: np.ndarray, Tp: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """First-order left twist ``log(T Tp⁻¹)`` = ``[t − R_d t_p, log R_d]``."""
    Rd = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            Rd[a, b] = T[a, 0] * Tp[b, 0] + T[a, 1] * Tp[b, 1] + T[a, 2] * Tp[b, 2]
    xi = np.empty(6)
    for a in range(3):
        xi[a] = T[a, 3] - (Rd[a, 0] * Tp[0, 3] + Rd[a, 1] * Tp[1, 3] + Rd[a, 2] * Tp[2, 3])
    w = rot_log_nb(Rd)
    xi[3], xi[4], xi[5] = w[0], w[1], w[2]
    return xi


@njit(cache=True)
def _curved_offset(
    e0: float, e1: float, e2: float, O: np.ndarray, n: np.ndarray, q: np.ndarray
) -> tuple:  # pragma: no cover - numba
    """Offset of a point from a curved map patch and its information (see :func:`_accumulate`):
    ``(e', AᵀΩA (row-major 9), AᵀΩe', e'ᵀΩe')``."""
    S00, S01, S02, S11, S12, S22 = q[4], q[5], q[6], q[7], q[8], q[9]
    n0, n1, n2 = n[0], n[1], n[2]
    # the tangential offset, clamped to the patch's reach (see quadric_surface)
    en = n0 * e0 + n1 * e1 + n2 * e2
    u0, u1, u2 = e0 - n0 * en, e1 - n1 * en, e2 - n2 * en
    ut = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    f = q[10] / ut if ut > q[10] else 1.0
    c0, c1, c2 = u0 * f, u1 * f, u2 * f
    Se0 = S00 * c0 + S01 * c1 + S02 * c2
    Se1 = S01 * c0 + S11 * c1 + S12 * c2
    Se2 = S02 * c0 + S12 * c1 + S22 * c2
    h = q[0] + q[1] * c0 + q[2] * c1 + q[3] * c2 + 0.5 * (c0 * Se0 + c1 * Se1 + c2 * Se2)
    g0, g1, g2 = q[1] + Se0, q[2] + Se1, q[3] + Se2
    if f < 1.0:
        # beyond the reach the patch continues along its tangent plane at the rim; the
        # rim point moves with the offset's direction, which adds to the gradient
        # (r/|u|)(|u| − r) (I − ûûᵀ) S û
        h += g0 * (u0 - c0) + g1 * (u1 - c1) + g2 * (u2 - c2)
        a0, a1, a2 = u0 / ut, u1 / ut, u2 / ut
        s0 = S00 * a0 + S01 * a1 + S02 * a2
        s1 = S01 * a0 + S11 * a1 + S12 * a2
        s2 = S02 * a0 + S12 * a1 + S22 * a2
        sa = s0 * a0 + s1 * a1 + s2 * a2
        k = f * (ut - q[10])
        g0 += k * (s0 - sa * a0)
        g1 += k * (s1 - sa * a1)
        g2 += k * (s2 - sa * a2)
    f0, f1, f2 = e0 - n0 * h, e1 - n1 * h, e2 - n2 * h
    # A = I − n gᵀ: AᵀΩA = Ω − g vᵀ − v gᵀ + α g gᵀ and AᵀΩf = Ωf − g (v·f), v = Ωn, α = nᵀΩn
    v0 = O[0, 0] * n0 + O[0, 1] * n1 + O[0, 2] * n2
    v1 = O[1, 0] * n0 + O[1, 1] * n1 + O[1, 2] * n2
    v2 = O[2, 0] * n0 + O[2, 1] * n1 + O[2, 2] * n2
    al = n0 * v0 + n1 * v1 + n2 * v2
    Of0 = O[0, 0] * f0 + O[0, 1] * f1 + O[0, 2] * f2
    Of1 = O[1, 0] * f0 + O[1, 1] * f1 + O[1, 2] * f2
    Of2 = O[2, 0] * f0 + O[2, 1] * f1 + O[2, 2] * f2
    d2 = f0 * Of0 + f1 * Of1 + f2 * Of2
    vf = v0 * f0 + v1 * f1 + v2 * f2
    return (
        f0, f1, f2,
        O[0, 0] - 2.0 * g0 * v0 + al * g0 * g0,
        O[0, 1] - g0 * v1 - v0 * g1 + al * g0 * g1,
        O[0, 2] - g0 * v2 - v0 * g2 + al * g0 * g2,
        O[1, 0] - g1 * v0 - v1 * g0 + al * g1 * g0,
        O[1, 1] - 2.0 * g1 * v1 + al * g1 * g1,
        O[1, 2] - g1 * v2 - v1 * g2 + al * g1 * g2,
        O[2, 0] - g2 * v0 - v2 * g0 + al * g2 * g0,
        O[2, 1] - g2 * v1 - v2 * g1 + al * g2 * g1,
        O[2, 2] - 2.0 * g2 * v2 + al * g2 * g2,
        Of0 - g0 * vf, Of1 - g1 * vf, Of2 - g2 * vf, d2,
    )  # fmt: skip


@njit(cache=True)
def _accumulate(
    X: np.ndarray,
    idx: np.ndarray,
    M: np.ndarray,
    Om: np.ndarray,
    c2: float,
    Nrm: np.ndarray,
    Qd: np.ndarray,
    use_quad: bool,
) -> tuple[np.ndarray, np.ndarray, int, float, float, np.ndarray]:  # pragma: no cover - numba
    """Weighted normal equations at the current correspondences.

    Returns ``(H, g, n_pairs, Σw, Σw·d², d2)`` with ``d2`` the squared Mahalanobis distance of
    each point (``-1`` for points without a neighbour). With ``use_quad`` the offset from the
    map point is measured from its curved patch (``Nrm``, ``Qd``:
    :attr:`relnav.navigation.voxel_map.VoxelMap.surface`): ``e' = e − n h(e)`` with Jacobian
    ``A = I − n ∇h(e)ᵀ``, so ``Ω`` becomes ``AᵀΩA`` and ``Ωe`` becomes ``AᵀΩe'``.
    """
    H = np.zeros((6, 6))
    g = np.zeros(6)
    n_pairs = 0
    sw = 0.0
    swd = 0.0
    d2_out = np.full(X.shape[0], -1.0)
    OJ = np.zeros((3, 6))
    # J = [I, -[x]x] has zeros and ones: its products are written out, in the order of the
    # full 3x6 products, so that every sum is the same number (a term 0·y or 1·y is exact)
    for i in range(X.shape[0]):
        j = idx[i]
        if j < 0:
            continue
        e0 = X[i, 0] - M[j, 0]
        e1 = X[i, 1] - M[j, 1]
        e2 = X[i, 2] - M[j, 2]
        O00, O01, O02 = Om[j, 0, 0], Om[j, 0, 1], Om[j, 0, 2]
        O10, O11, O12 = Om[j, 1, 0], Om[j, 1, 1], Om[j, 1, 2]
        O20, O21, O22 = Om[j, 2, 0], Om[j, 2, 1], Om[j, 2, 2]
        if use_quad and Qd[j, 10] > 0.0:  # a plane patch (reach 0) takes the plane's path
            e0, e1, e2, O00, O01, O02, O10, O11, O12, O20, O21, O22, Oe0, Oe1, Oe2, d2 = (
                _curved_offset(e0, e1, e2, Om[j], Nrm[j], Qd[j])
            )
        else:
            Oe0 = O00 * e0 + O01 * e1 + O02 * e2
            Oe1 = O10 * e0 + O11 * e1 + O12 * e2
            Oe2 = O20 * e0 + O21 * e1 + O22 * e2
            d2 = e0 * Oe0 + e1 * Oe1 + e2 * Oe2
        d2_out[i] = d2
        q = c2 / (c2 + d2)
        w = q * q
        n_pairs += 1
        sw += w
        swd += w * d2
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        # OJ = Ω J, columns [I | (0, -x2, x1), (x2, 0, -x0), (-x1, x0, 0)]
        for a, (oa0, oa1, oa2) in enumerate(((O00, O01, O02), (O10, O11, O12), (O20, O21, O22))):
            OJ[a, 0] = oa0
            OJ[a, 1] = oa1
            OJ[a, 2] = oa2
            OJ[a, 3] = oa1 * (-x2) + oa2 * x1
            OJ[a, 4] = oa0 * x2 + oa2 * (-x0)
            OJ[a, 5] = oa0 * (-x1) + oa1 * x0
        g[0] += w * Oe0
        g[1] += w * Oe1
        g[2] += w * Oe2
        g[3] += w * ((-x2) * Oe1 + x1 * Oe2)
        g[4] += w * (x2 * Oe0 + (-x0) * Oe2)
        g[5] += w * ((-x1) * Oe0 + x0 * Oe1)
        for r in range(6):
            c0, c1, c2_ = OJ[0, r], OJ[1, r], OJ[2, r]
            H[0, r] += w * c0
            if r >= 1:
                H[1, r] += w * c1
            if r >= 2:
                H[2, r] += w * c2_
            if r >= 3:
                H[3, r] += w * ((-x2) * c1 + x1 * c2_)
            if r >= 4:
                H[4, r] += w * (x2 * c0 + (-x0) * c2_)
            if r >= 5:
                H[5, r] += w * ((-x1) * c0 + x0 * c1)
    for p in range(6):
        for r in range(p):
            H[p, r] = H[r, p]
    return H, g, n_pairs, sw, swd, d2_out


@njit(cache=True)
def _two_nearest(
    Pp: np.ndarray,
    split_dim: np.ndarray,
    split_val: np.ndarray,
    q0: float,
    q1: float,
    q2: float,
    bound: float,
    st_n: np.ndarray,
    st_s: np.ndarray,
    st_e: np.ndarray,
    st_lb: np.ndarray,
) -> tuple[float, int, float]:  # pragma: no cover - numba
    """The two nearest points of ``q`` strictly closer than ``√bound`` in a tree of
    :func:`relnav.geometry.kdtree.kd_build`: ``(dd1, k1, dd2)``, squared distances summed as
    :func:`relnav.geometry.kdtree.kd_query` sums them and the permuted index of the nearest
    (``bound`` and ``-1`` when not found). ``st_*``: the search stack (128 entries)."""
    b1, b2, k1 = bound, bound, -1
    n_nodes = split_dim.shape[0]
    st_n[0], st_s[0], st_e[0], st_lb[0] = 0, 0, Pp.shape[0], 0.0
    top = 1
    while top > 0:
        top -= 1
        if st_lb[top] >= b2:
            continue
        node, s, e = st_n[top], st_s[top], st_e[top]
        dim = split_dim[node] if node < n_nodes else -1
        if dim < 0:
            for k in range(s, e):
                d0 = Pp[k, 0] - q0
                d1 = Pp[k, 1] - q1
                d2 = Pp[k, 2] - q2
                dd = d0 * d0 + d1 * d1 + d2 * d2
                if dd < b1:
                    b2 = b1
                    b1, k1 = dd, k
                elif dd < b2:
                    b2 = dd
            continue
        qv = q0 if dim == 0 else (q1 if dim == 1 else q2)
        diff = qv - split_val[node]
        near_n, near_s, near_e, far_n, far_s, far_e = kd_children(node, s, e, diff)
        st_n[top], st_s[top], st_e[top], st_lb[top] = far_n, far_s, far_e, diff * diff
        top += 1
        st_n[top], st_s[top], st_e[top], st_lb[top] = near_n, near_s, near_e, 0.0
        top += 1
    return b1, k1, b2


@njit(cache=True)
def _nearest(
    P: np.ndarray, T: np.ndarray, trees: tuple, gate: float, cache: tuple
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Transformed points and the nearest map point of each (two trees; -1: none in the gate).

    The answer is that of two independent nearest-point searches of the trees, the recent
    tree's point taken only when strictly closer. Each search also finds the distance beyond
    which every other map point lies (``cache``: :func:`_new_cache`, updated in place), so that
    a point that moved by ``Δ`` since its last search keeps its neighbour ``c`` without a search
    when ``|q - c| + Δ`` stays below that distance (by a relative margin of 1e-9, far above
    rounding): then ``c`` is the unique nearest point, as the searches would find it.
    """
    mp, mperm, mdim, mval, rp, rperm, rdim, rval, rids = trees
    q_ref, c_pt, lb_other, c_idx = cache
    m = P.shape[0]
    X = np.empty((m, 3))
    idx = np.full(m, -1, np.int64)
    r2 = gate * gate if gate < np.inf else np.inf
    st_n = np.empty(128, np.int64)
    st_s = np.empty(128, np.int64)
    st_e = np.empty(128, np.int64)
    st_lb = np.empty(128)
    for i in range(m):
        a0, a1, a2 = P[i, 0], P[i, 1], P[i, 2]
        q0 = T[0, 0] * a0 + T[0, 1] * a1 + T[0, 2] * a2 + T[0, 3]
        q1 = T[1, 0] * a0 + T[1, 1] * a1 + T[1, 2] * a2 + T[1, 3]
        q2 = T[2, 0] * a0 + T[2, 1] * a1 + T[2, 2] * a2 + T[2, 3]
        X[i, 0], X[i, 1], X[i, 2] = q0, q1, q2
        if c_idx[i] >= 0:
            d0 = c_pt[i, 0] - q0
            d1 = c_pt[i, 1] - q1
            d2 = c_pt[i, 2] - q2
            dd = d0 * d0 + d1 * d1 + d2 * d2
            m0, m1, m2 = q0 - q_ref[i, 0], q1 - q_ref[i, 1], q2 - q_ref[i, 2]
            moved = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            slack = 1e-12 * (1.0 + abs(q0) + abs(q1) + abs(q2))
            if dd < r2 and (math.sqrt(dd) + moved + slack < math.sqrt(lb_other[i]) * (1.0 - 1e-9)):
                idx[i] = c_idx[i]
                continue
        a_1, ka, a_2 = _two_nearest(mp, mdim, mval, q0, q1, q2, r2, st_n, st_s, st_e, st_lb)
        b_1, kb, b_2 = _two_nearest(rp, rdim, rval, q0, q1, q2, a_2, st_n, st_s, st_e, st_lb)
        c_idx[i] = -1
        if kb >= 0 and (ka < 0 or math.sqrt(b_1) < math.sqrt(a_1)):
            idx[i] = rids[rperm[kb]]
            c_pt[i, 0], c_pt[i, 1], c_pt[i, 2] = rp[kb, 0], rp[kb, 1], rp[kb, 2]
            lb_other[i] = min(a_1, b_2)
        elif ka >= 0:
            idx[i] = mperm[ka]
            c_pt[i, 0], c_pt[i, 1], c_pt[i, 2] = mp[ka, 0], mp[ka, 1], mp[ka, 2]
            lb_other[i] = min(a_2, b_1)
        else:
            continue
        if idx[i] >= 0:
            c_idx[i] = idx[i]
            q_ref[i, 0], q_ref[i, 1], q_ref[i, 2] = q0, q1, q2
    return X, idx


@njit(cache=True)
def _new_cache(m: int) -> tuple:  # pragma: no cover - numba
    """Per-point state of :func:`_nearest` for ``m`` scan points: the query position at the
    last search, the neighbour's coordinates in its tree, the squared distance below which no
    other map point lay, the neighbour's map index (-1: search again)."""
    return (np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m), np.full(m, -1, np.int64))


@njit(cache=True, nogil=True)
def _solve_loop(
    P: np.ndarray,
    trees: tuple,
    M: np.ndarray,
    Om: np.ndarray,
    T0: np.ndarray,
    T_pred: np.ndarray,
    Lam: np.ndarray,
    gate: float,
    c: float,
    c0: float,
    decay: float,
    max_iter: int,
    tol_t: float,
    tol_r: float,
    Nrm: np.ndarray,
    Qd: np.ndarray,
    use_quad: bool,
) -> tuple:  # pragma: no cover - numba
    T = T0.copy()
    scale = max(c0, c)
    iters = 0
    cache = _new_cache(P.shape[0])
    for it in range(max_iter):
        iters = it + 1
        X, idx = _nearest(P, T, trees, gate, cache)
        H, g, _, _, _, _ = _accumulate(X, idx, M, Om, scale * scale, Nrm, Qd, use_quad)
        xi = _prior_twist(T, T_pred)
        A = H + Lam
        b = np.zeros(6)
        for p in range(6):
            s = g[p]
            for q in range(6):
                s += Lam[p, q] * xi[q]
            b[p] = -s
        delta = solve_spd6(A, b)
        R = rodrigues_nb(delta[3:].copy())
        Tn = np.eye(4)
        for a in range(3):
            for bb in range(3):
                Tn[a, bb] = R[a, 0] * T[0, bb] + R[a, 1] * T[1, bb] + R[a, 2] * T[2, bb]
            Tn[a, 3] = R[a, 0] * T[0, 3] + R[a, 1] * T[1, 3] + R[a, 2] * T[2, 3] + delta[a]
        T = Tn
        annealed = scale <= c
        scale = max(c, scale * decay)
        dt = math.sqrt(delta[0] ** 2 + delta[1] ** 2 + delta[2] ** 2)
        dr = math.sqrt(delta[3] ** 2 + delta[4] ** 2 + delta[5] ** 2)
        if annealed and dt < tol_t and dr < tol_r:
            break
    X, idx = _nearest(P, T, trees, gate, cache)
    H, g, n_pairs, sw, swd, d2 = _accumulate(X, idx, M, Om, c * c, Nrm, Qd, use_quad)
    return T, H, n_pairs, iters, sw, swd, d2, idx


def solve_scan_to_map(
    P: np.ndarray,
    target: VoxelMap,
    T0: np.ndarray,
    T_pred: np.ndarray,
    Lam: np.ndarray,
    gate: float,
    c: float,
    max_iter: int,
    tol_t: float,
    tol_r: float,
    c0: float = 100.0,
    decay: float = 0.6,
    information: np.ndarray | None = None,
    from_means: bool = False,
) -> ScanToMapFit:
    """Register the scan ``P`` (sensor frame, ``(N, 3)``) onto the map ``target`` from ``T0``.

    Parameters
    ----------
    P : (N, 3) float64
        Scan points, sensor frame, m.
    target : relnav.navigation.voxel_map.VoxelMap
        The map: its points (m, target frame), search trees, per-point information (1/m²) and,
        with ``map.surface="quadric"``, its curved patches
        (:attr:`~relnav.navigation.voxel_map.VoxelMap.surface`; otherwise the plane through
        each map point).
    T0, T_pred : (4, 4) float64
        Initial guess and motion-model prediction of ``T_target_sensor``.
    Lam : (6, 6) float64
        Information of the prediction, left twist ``[ρ, φ]`` in the target frame.
    gate : float
        Largest point-to-map distance of a pair, m.
    c : float
        Geman–McClure scale on the Mahalanobis distance.
    max_iter : int
        Gauss–Newton iterations at most.
    tol_t, tol_r : float
        Stop when the update is below these (m, rad).
    c0, decay : float
        Graduated non-convexity: the kernel scale starts at ``c0`` and shrinks by ``decay`` per
        iteration down to ``c``, so that a prediction far from the truth still converges (a
        tight kernel from the start locks onto the nearest wrong pairs).
    information : (K, 3, 3) float64, optional
        Per-point information used instead of the map's (the navigator's point-to-point
        refinement on repeated points).
    from_means : bool
        Measure the residuals from the voxel means, not from the map's
        :attr:`~relnav.navigation.voxel_map.VoxelMap.patch_points` (always so with curved patches).
    """
    surface = target.surface
    if surface is None:
        Nrm, Qd, use_quad = np.zeros((1, 3)), np.zeros((1, 11)), False
    else:
        Nrm = np.ascontiguousarray(surface[0], dtype=np.float64)
        Qd = np.ascontiguousarray(surface[1], dtype=np.float64)
        use_quad = True
    Om = target.information if information is None else information
    M = target.means if from_means or surface is not None else target.patch_points
    T, H, n_pairs, iters, sw, swd, d2, idx = _solve_loop(
        np.ascontiguousarray(P, dtype=np.float64),
        target.search_trees,
        M,
        Om,
        np.ascontiguousarray(T0, dtype=np.float64),
        np.ascontiguousarray(T_pred, dtype=np.float64),
        np.ascontiguousarray(Lam, dtype=np.float64),
        float(gate),
        float(c),
        float(c0),
        float(decay),
        int(max_iter),
        float(tol_t),
        float(tol_r),
        Nrm,
        Qd,
        use_quad,
    )
    return ScanToMapFit(T, H, int(n_pairs), int(iters), float(sw), float(swd), d2, idx)


@dataclass
class ScanToMapFit:
    """Outcome of :func:`solve_scan_to_map`.

    Attributes
    ----------
    T : (4, 4) float64
        ``T_target_sensor``.
    H : (6, 6) float64
        The scan's own information (no prior) at the final pairs, left twist ``[ρ, φ]``.
    n_pairs : int
        Scan points with a map point within the gate.
    iterations : int
        Gauss–Newton iterations run.
    sw, swd : float
        Sum of robust weights and of weighted squared Mahalanobis distances.
    d2 : (N,) float64
        Squared Mahalanobis distance of each point (-1: no map point within the gate).
    idx : (N,) int64
        Map index paired with each point (-1: none).
    """

    T: np.ndarray
    H: np.ndarray
    n_pairs: int
    iterations: int
    sw: float
    swd: float
    d2: np.ndarray
    idx: np.ndarray

    @property
    def rms(self) -> float:
        """Robust RMS of the pairs' Mahalanobis distances, ``√(swd / sw)`` (inf without a
        pair)."""
        return math.sqrt(self.swd / self.sw) if self.sw > 0 else math.inf


def robust_cost(d2: np.ndarray, c: float) -> float:
    """The registration's robust cost at its final pairs: ``Σ c² d²/(c² + d²)`` (Geman–McClure
    on the squared Mahalanobis distances ``d2``, ``(N,)``), a point without a pair (``d2 < 0``)
    counted at the kernel's ceiling ``c²``."""
    c2 = c * c
    has = d2 >= 0
    d = d2[has]
    return float(np.sum(c2 * d / (c2 + d)) + c2 * np.count_nonzero(~has))


def variance_factor(rms: float) -> float:
    """**[interpretation]** The factor dividing a registration's information: residuals larger
    than the map's noise model (resampled surfaces, map blur) scale it down, ``σ̂² = max(1,
    rms²)`` with ``rms`` the robust RMS of the pairs' Mahalanobis distances (1 when not finite:
    no pair)."""
    return max(1.0, rms**2) if math.isfinite(rms) else 1.0


@njit(cache=True)
def _degeneracy_nb(H: np.ndarray, radius: float) -> float:  # pragma: no cover - numba
    Hs = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            si = 1.0 if i < 3 else 1.0 / radius
            sj = 1.0 if j < 3 else 1.0 / radius
            Hs[i, j] = 0.5 * (H[i, j] + H[j, i]) * si * sj
    ev = sym_eigvals(Hs)
    return ev[0] / ev[5] if ev[5] > 0 else 0.0


def degeneracy(H: np.ndarray, radius: float) -> float:
    """Ratio of the smallest to the largest eigenvalue of a registration's information ``H``
    (6×6, left twist ``[ρ (m), φ (rad)]``) with its rotations scaled by the lever arm ``radius``
    (m), so that metres and radians weigh alike; 0 when ``H`` carries no information (or is
    not finite)."""
    H = np.ascontiguousarray(H, dtype=np.float64)
    if not np.all(np.isfinite(H)):
        return 0.0
    return float(_degeneracy_nb(H, float(radius)))


@njit(cache=True)
def _motion_chi2_nb(
    T: np.ndarray, T_pred: np.ndarray, Lam: np.ndarray
) -> float:  # pragma: no cover
    xi = log_se3_nb(matmul(T, invert_nb(T_pred)))
    q = 0.0
    for i in range(6):
        for j in range(6):
            q += xi[i] * Lam[i, j] * xi[j]
    return q


def motion_chi2(T: np.ndarray, T_pred: np.ndarray, Lam: np.ndarray) -> float:
    """χ² of a registered pose ``T`` against the prediction ``T_pred`` under its information
    ``Lam`` (6×6, left twist of the target frame): ``ξᵀ Λ ξ`` with ``ξ = log(T T_pred⁻¹)``."""
    return float(
        _motion_chi2_nb(
            np.ascontiguousarray(T, dtype=np.float64),
            np.ascontiguousarray(T_pred, dtype=np.float64),
            np.ascontiguousarray(Lam, dtype=np.float64),
        )
    )


@njit(cache=True)
def _left_information_nb(T: np.ndarray, S_body: np.ndarray) -> np.ndarray:  # pragma: no cover
    Ad = adjoint_nb(T)
    S = matmul_t(matmul(Ad, S_body), Ad)
    return symmetrize(pinv_sym(symmetrize(S)))


def left_information(T: np.ndarray, S_body: np.ndarray) -> np.ndarray:
    """Information of a pose at ``T`` whose body-frame covariance is ``S_body`` (6×6), in the
    left twist of the target frame the solver uses (``S_left = Ad S Adᵀ``, pseudo-inverted)."""
    return _left_information_nb(
        np.ascontiguousarray(T, dtype=np.float64), np.ascontiguousarray(S_body, dtype=np.float64)
    )


def normal_information(
    P: np.ndarray,
    T: np.ndarray,
    idx: np.ndarray,
    d2: np.ndarray,
    normals: np.ndarray,
    Om: np.ndarray,
    inplane_var: float,
    c2: float,
) -> np.ndarray:
    """The scan's information about the pose from the map's surface normals only (6×6, left
    twist ``[ρ, φ]``, target frame).

    **[interpretation]** The solver also pulls points weakly along the surface (``inplane_sigma``)
    so that it converges, but that pull is only information when consecutive scans sample the
    same surface points; a resampled surface (every real sensor) can slide along itself. The
    information that goes to the filter, the degeneracy test and the covariances keeps the
    normal part ``Ω − (I − n nᵀ)/σ_p²`` of each map patch, with the solver's robust weights.
    """
    ok = idx >= 0
    if not ok.any():
        return np.zeros((6, 6))
    j = idx[ok]
    X = P[ok] @ T[:3, :3].T + T[:3, 3]
    n = normals[j]
    On = Om[j] - (np.eye(3)[None] - n[:, :, None] * n[:, None, :]) / inplane_var
    w = (c2 / (c2 + d2[ok])) ** 2
    J = np.zeros((len(X), 3, 6))
    J[:, 0, 0] = J[:, 1, 1] = J[:, 2, 2] = 1.0
    J[:, 0, 4], J[:, 0, 5] = X[:, 2], -X[:, 1]
    J[:, 1, 3], J[:, 1, 5] = -X[:, 2], X[:, 0]
    J[:, 2, 3], J[:, 2, 4] = X[:, 1], -X[:, 0]
    H = np.einsum("n,nai,nab,nbj->ij", w, J, On, J, optimize=True)
    return 0.5 * (H + H.T)
