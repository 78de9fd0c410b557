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

import numpy as np
from numba import njit

from relnav.geometry.icp_kernels import _rodrigues_nb
from relnav.geometry.kdtree import _kd_query
from relnav.geometry.lie import _rot_log
from relnav.geometry.se3 import adjoint

__all__ = ["ScanToMapFit", "left_information", "normal_information", "solve_scan_to_map"]


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
    w = _rot_log(Rd)
    xi[3], xi[4], xi[5] = w[0], w[1], w[2]
    return xi


@njit(cache=True)
def _solve6(A: np.ndarray, b: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Solve the SPD system ``A x = b`` (6×6) by Cholesky with a tiny ridge."""
    n = 6
    L = np.zeros((n, n))
    ridge = 1e-12 * (abs(A[0, 0]) + abs(A[3, 3]) + 1.0)
    for i in range(n):
        for j in range(i + 1):
            s = A[i, j] + (ridge if i == j else 0.0)
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                L[i, i] = math.sqrt(s) if s > 0.0 else 1e-300
            else:
                L[i, j] = s / L[j, j]
    y = np.zeros(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    x = np.zeros(n)
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    return x


@njit(cache=True)
def _accumulate(
    X: np.ndarray,
    idx: np.ndarray,
    M: np.ndarray,
    Om: np.ndarray,
    c2: float,
) -> tuple[np.ndarray, np.ndarray, int, float, float, np.ndarray]:  # pragma: no cover - numba
    """Weighted normal equations at the current correspondences.

    Returns ``(H, g, n_pairs, Σw, Σw·d², d2)`` with ``d2`` the squared Mahalanobis distance of
    each point (``-1`` for points without a neighbour).
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
def _nearest(
    P: np.ndarray, T: np.ndarray, trees: tuple, gate: float
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Transformed points and the nearest map point of each (two trees; -1: none in the gate)."""
    mp, mperm, mdim, mval, rp, rperm, rdim, rval, rids = trees
    X, i_main, d_main = _kd_query(mp, mperm, mdim, mval, P, T, gate, False)
    _, i_rec, d_rec = _kd_query(rp, rperm, rdim, rval, P, T, gate, False)
    idx = i_main.copy()
    for i in range(P.shape[0]):
        if i_rec[i] >= 0 and d_rec[i] < d_main[i]:
            idx[i] = rids[i_rec[i]]
    return X, idx


@njit(cache=True)
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
) -> tuple:  # pragma: no cover - numba
    T = T0.copy()
    scale = max(c0, c)
    iters = 0
    for it in range(max_iter):
        iters = it + 1
        X, idx = _nearest(P, T, trees, gate)
        H, g, _, _, _, _ = _accumulate(X, idx, M, Om, scale * scale)
        xi = _prior_twist(T, T_pred)
        A = H + Lam
        b = np.zeros(6)
        for p in range(6):
            s = g[p]
            for q in range(6):
                s += Lam[p, q] * xi[q]
            b[p] = -s
        delta = _solve6(A, b)
        R = _rodrigues_nb(delta[3:].copy())
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
    X, idx = _nearest(P, T, trees, gate)
    H, g, n_pairs, sw, swd, d2 = _accumulate(X, idx, M, Om, c * c)
    return T, H, n_pairs, iters, sw, swd, d2, idx


def solve_scan_to_map(
    P: np.ndarray,
    trees: tuple,
    M: np.ndarray,
    Om: np.ndarray,
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
) -> ScanToMapFit:
    """Register the scan ``P`` (sensor frame, ``(N, 3)``) onto the map from ``T0``.

    Parameters
    ----------
    P : (N, 3) float64
        Scan points, sensor frame, m.
    trees : tuple
        :attr:`relnav.navigation.voxel_map.VoxelMap.search_trees` (over the map points ``M``).
    M, Om : (K, 3), (K, 3, 3) float64
        Map points (m, target frame) and their information matrices (1/m²).
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
    """
    T, H, n_pairs, iters, sw, swd, d2, idx = _solve_loop(
        np.ascontiguousarray(P, dtype=np.float64),
        trees,
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


def left_information(T: np.ndarray, S_body: np.ndarray) -> np.ndarray:
    """Information of a pose at ``T`` whose body-frame covariance is ``S_body`` (6×6), in the
    left twist of the target frame the solver uses (``S_left = Ad S Adᵀ``)."""
    Ad = adjoint(T)
    S = Ad @ S_body @ Ad.T
    L = np.linalg.pinv(0.5 * (S + S.T))
    return 0.5 * (L + L.T)


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
