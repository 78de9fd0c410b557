"""ICP's compiled kernels: rigid fits (Horn), point-to-plane normal equations, information
matrices, outlier rules and the whole fused ICP loop (:func:`_icp_loop`).

Shared by :class:`relnav.geometry.icp_solver.ICPSolver` (the ICP family of
:mod:`relnav.registration.icp`, the ``icp`` estimator of :mod:`relnav.estimation.icp_refine`),
Sparse ICP, Super4PCS and the navigator. Plain loops, no LAPACK: cold numba compilation stays
a few seconds and the cache makes later imports instant.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numba import njit

from relnav.geometry.eigen import jacobi_eigh
from relnav.geometry.kdtree import kd_query
from relnav.geometry.rotations import hat

__all__ = ["information_ratio", "reject_outliers"]


@njit(cache=True)
def transform_nb(P: np.ndarray, T: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    n = P.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        x, y, z = P[i, 0], P[i, 1], P[i, 2]
        for a in range(3):
            out[i, a] = T[a, 0] * x + T[a, 1] * y + T[a, 2] * z + T[a, 3]
    return out


@njit(cache=True)
def horn_rotation(H: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Proper rotation ``R`` maximising ``tr(R H)`` for ``H = Σ (x − x̄)(y − ȳ)ᵀ`` (Horn 1987).

    Same minimiser as Arun/Umeyama SVD with the reflection guard; ``y ≈ R x``.
    """
    sxx, sxy, sxz = H[0, 0], H[0, 1], H[0, 2]
    syx, syy, syz = H[1, 0], H[1, 1], H[1, 2]
    szx, szy, szz = H[2, 0], H[2, 1], H[2, 2]
    N = np.empty((4, 4))
    N[0, 0] = sxx + syy + szz
    N[0, 1] = syz - szy
    N[0, 2] = szx - sxz
    N[0, 3] = sxy - syx
    N[1, 1] = sxx - syy - szz
    N[1, 2] = sxy + syx
    N[1, 3] = szx + sxz
    N[2, 2] = -sxx + syy - szz
    N[2, 3] = syz + szy
    N[3, 3] = -sxx - syy + szz
    for a in range(4):
        for b in range(a):
            N[a, b] = N[b, a]
    w, V = jacobi_eigh(N)
    k = 0
    for a in range(1, 4):
        if w[a] > w[k]:
            k = a
    qw, qx, qy, qz = V[0, k], V[1, k], V[2, k], V[3, k]
    nq = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    qw, qx, qy, qz = qw / nq, qx / nq, qy / nq, qz / nq
    R = np.empty((3, 3))
    R[0, 0] = qw * qw + qx * qx - qy * qy - qz * qz
    R[0, 1] = 2.0 * (qx * qy - qw * qz)
    R[0, 2] = 2.0 * (qx * qz + qw * qy)
    R[1, 0] = 2.0 * (qx * qy + qw * qz)
    R[1, 1] = qw * qw - qx * qx + qy * qy - qz * qz
    R[1, 2] = 2.0 * (qy * qz - qw * qx)
    R[2, 0] = 2.0 * (qx * qz - qw * qy)
    R[2, 1] = 2.0 * (qy * qz + qw * qx)
    R[2, 2] = qw * qw - qx * qx - qy * qy + qz * qz
    return R


@njit(cache=True)
def kabsch_pairs(
    X: np.ndarray, Y: np.ndarray, src_idx: np.ndarray, tgt_idx: np.ndarray
) -> np.ndarray:  # pragma: no cover - numba
    """Rigid transform ``T`` (4x4) with ``Y[tgt] ≈ R X[src] + t`` (least squares, Horn)."""
    m = src_idx.shape[0]
    mx = np.zeros(3)
    my = np.zeros(3)
    for k in range(m):
        i = src_idx[k]
        j = tgt_idx[k]
        for a in range(3):
            mx[a] += X[i, a]
            my[a] += Y[j, a]
    mx /= m
    my /= m
    H = np.zeros((3, 3))
    for k in range(m):
        i = src_idx[k]
        j = tgt_idx[k]
        for a in range(3):
            xa = X[i, a] - mx[a]
            for b in range(3):
                H[a, b] += xa * (Y[j, b] - my[b])
    R = horn_rotation(H)
    T = np.eye(4)
    for a in range(3):
        ta = my[a]
        for b in range(3):
            T[a, b] = R[a, b]
            ta -= R[a, b] * mx[b]
        T[a, 3] = ta
    return T


@njit(cache=True)
def _plane_system(
    X: np.ndarray,
    Y: np.ndarray,
    N: np.ndarray,
    src_idx: np.ndarray,
    tgt_idx: np.ndarray,
    c: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, float]:  # pragma: no cover - numba
    """Normal equations of linearised point-to-plane ICP about centre ``c``.

    Unknowns ``[ω (3), t (3)]``; row ``a = [(x − c) × n, n]``, residual ``r = (x − y)·n``.
    Returns ``(AᵀA, Aᵀr, Σr²)``.
    """
    JTJ = np.zeros((6, 6))
    JTr = np.zeros(6)
    r2 = 0.0
    a = np.empty(6)
    for k in range(src_idx.shape[0]):
        i = src_idx[k]
        j = tgt_idx[k]
        nx, ny, nz = N[j, 0], N[j, 1], N[j, 2]
        x0, x1, x2 = X[i, 0] - c[0], X[i, 1] - c[1], X[i, 2] - c[2]
        r = (X[i, 0] - Y[j, 0]) * nx + (X[i, 1] - Y[j, 1]) * ny + (X[i, 2] - Y[j, 2]) * nz
        a[0] = x1 * nz - x2 * ny
        a[1] = x2 * nx - x0 * nz
        a[2] = x0 * ny - x1 * nx
        a[3] = nx
        a[4] = ny
        a[5] = nz
        for p in range(6):
            JTr[p] += a[p] * r
            for q in range(p, 6):
                JTJ[p, q] += a[p] * a[q]
        r2 += r * r
    for p in range(6):
        for q in range(p):
            JTJ[p, q] = JTJ[q, p]
    return JTJ, JTr, r2


@njit(cache=True)
def point_information(
    X: np.ndarray, Y: np.ndarray, src_idx: np.ndarray, tgt_idx: np.ndarray
) -> tuple[np.ndarray, float]:  # pragma: no cover - numba
    """``Σ JᵀJ`` (6x6, order [ρ, φ]) with ``J = [I, −[p]×]``, and ``Σ|p − y|²``.

    ``JᵀJ = [[m I, −Σ[p]×], [Σ[p]×, Σ(|p|² I − p pᵀ)]]``.
    """
    A = np.zeros((6, 6))
    r2 = 0.0
    s0 = s1 = s2 = 0.0
    for k in range(src_idx.shape[0]):
        i = src_idx[k]
        j = tgt_idx[k]
        p0, p1, p2 = X[i, 0], X[i, 1], X[i, 2]
        for a in range(3):
            d = X[i, a] - Y[j, a]
            r2 += d * d
        s0 += p0
        s1 += p1
        s2 += p2
        pp = p0 * p0 + p1 * p1 + p2 * p2
        A[3, 3] += pp - p0 * p0
        A[4, 4] += pp - p1 * p1
        A[5, 5] += pp - p2 * p2
        A[3, 4] -= p0 * p1
        A[3, 5] -= p0 * p2
        A[4, 5] -= p1 * p2
    m = float(src_idx.shape[0])
    A[0, 0] = A[1, 1] = A[2, 2] = m
    # upper-right block −Σ[p]×, with [p]× = [[0, −p2, p1], [p2, 0, −p0], [−p1, p0, 0]]
    A[0, 4] = s2
    A[0, 5] = -s1
    A[1, 3] = -s2
    A[1, 5] = s0
    A[2, 3] = s1
    A[2, 4] = -s0
    A[4, 3] = A[3, 4]
    A[5, 3] = A[3, 5]
    A[5, 4] = A[4, 5]
    for a in range(3):
        for b in range(3):
            A[3 + b, a] = A[a, 3 + b]
    return A, r2


# --------------------------------------------------------------------------- the fused ICP loop


@njit(cache=True)
def rodrigues_nb(w: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Rotation matrix of the rotation vector ``w`` (plain loops)."""
    th = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    K = np.zeros((3, 3))
    if th < 1e-12:
        K[0, 1], K[0, 2], K[1, 2] = -w[2], w[1], -w[0]
        K[1, 0], K[2, 0], K[2, 1] = w[2], -w[1], w[0]
        return np.eye(3) + K
    k0, k1, k2 = w[0] / th, w[1] / th, w[2] / th
    K[0, 1], K[0, 2], K[1, 2] = -k2, k1, -k0
    K[1, 0], K[2, 0], K[2, 1] = k2, -k1, k0
    sn, c1 = math.sin(th), 1.0 - math.cos(th)
    R = np.eye(3)
    for a in range(3):
        for b in range(3):
            kk = K[a, 0] * K[0, b] + K[a, 1] * K[1, b] + K[a, 2] * K[2, b]
            R[a, b] += sn * K[a, b] + c1 * kk
    return R


@njit(cache=True)
def _euler_zyx(w: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Open3D's ``TransformVector6dToMatrix4d`` rotation: ``Rz(w2) · Ry(w1) · Rx(w0)``."""
    ca, sa = math.cos(w[0]), math.sin(w[0])
    cb, sb = math.cos(w[1]), math.sin(w[1])
    cg, sg = math.cos(w[2]), math.sin(w[2])
    R = np.empty((3, 3))
    R[0, 0] = cg * cb
    R[0, 1] = cg * sb * sa - sg * ca
    R[0, 2] = cg * sb * ca + sg * sa
    R[1, 0] = sg * cb
    R[1, 1] = sg * sb * sa + cg * ca
    R[1, 2] = sg * sb * ca - cg * sa
    R[2, 0] = -sb
    R[2, 1] = cb * sa
    R[2, 2] = cb * ca
    return R


@njit(cache=True)
def _valid_pairs(
    j: np.ndarray, d: np.ndarray, N: np.ndarray, has_normals: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Source indices, target indices and distances of the gated pairs (finite target normal)."""
    m = j.shape[0]
    si = np.empty(m, np.int64)
    cnt = 0
    for i in range(m):
        if j[i] >= 0 and (not has_normals or np.isfinite(N[j[i], 0])):
            si[cnt] = i
            cnt += 1
    si = si[:cnt]
    ti = np.empty(cnt, np.int64)
    dd = np.empty(cnt)
    for k in range(cnt):
        ti[k] = j[si[k]]
        dd[k] = d[si[k]]
    return si, ti, dd


@njit(cache=True)
def reject_nb(d: np.ndarray, rule: int, factor: float) -> np.ndarray:  # pragma: no cover
    """Numba twin of :func:`reject_outliers` (rule 0 none, 1 std, 2 x84)."""
    keep = np.ones(d.shape[0], dtype=np.bool_)
    if rule == 0 or d.shape[0] == 0:
        return keep
    if rule == 1:
        lim = d.mean() + factor * d.std()
        for i in range(d.shape[0]):
            keep[i] = d[i] <= lim
        return keep
    med = np.median(d)
    dev = np.abs(d - med)
    mad = np.median(dev)
    for i in range(d.shape[0]):
        keep[i] = dev[i] <= factor * mad
    return keep


@njit(cache=True)
def _icp_loop(
    P: np.ndarray,
    Pp: np.ndarray,
    perm: np.ndarray,
    sdim: np.ndarray,
    sval: np.ndarray,
    Y: np.ndarray,
    N: np.ndarray,
    plane: bool,
    T0: np.ndarray,
    gate: float,
    max_iter: int,
    rule: int,
    factor: float,
    center: bool,
    euler: bool,
    o3d: bool,
    rel_fit: float,
    rel_rmse: float,
    ttol: float,
    rtol: float,
    stop_window: int,
    min_corr: int,
):  # pragma: no cover - numba
    """The whole ICP iteration (module docstring) in one compiled loop.

    Returns ``(T, n_iter, status, converged, deficient, X, si, ti, d)`` with status 0 ok,
    1 too few correspondences, 2 singular system; ``X, si, ti, d`` are the transformed source
    and the gated pairs at the returned ``T`` (before the outlier rule).
    """
    n = P.shape[0]
    T = T0.copy()
    X, j, d = kd_query(Pp, perm, sdim, sval, P, T, gate, False)
    si, ti, dd = _valid_pairs(j, d, N, plane)
    fit_prev = si.shape[0] / n
    rmse_prev = math.sqrt(np.mean(dd**2)) if dd.shape[0] else 0.0
    below = 0
    converged = False
    deficient = False
    status = 0
    n_iter = 0
    for it in range(1, max_iter + 1):
        keep = reject_nb(dd, rule, factor)
        sk = si[keep]
        tk = ti[keep]
        if sk.shape[0] < min_corr:
            status = 1
            break
        if plane:
            c = np.zeros(3)
            if center:
                for k in range(sk.shape[0]):
                    for a in range(3):
                        c[a] += X[sk[k], a]
                c /= sk.shape[0]
            JTJ, JTr, _ = _plane_system(X, Y, N, sk, tk, c)
            w, V = jacobi_eigh(JTJ)
            wmax = w.max()
            x = np.zeros(6)
            if o3d:
                det = 1.0
                for a in range(6):
                    det *= w[a]
                if not abs(det) > 1e-6:  # Open3D: failed solve → identity update
                    deficient = True
                    wmax = -1.0
            elif not wmax > 0.0:
                status = 2
                break
            if wmax > 0.0:
                for k in range(6):
                    if w[k] > wmax * 1e-12 or (o3d and w[k] != 0.0):
                        coef = 0.0
                        for p in range(6):
                            coef += V[p, k] * JTr[p]
                        for p in range(6):
                            x[p] -= V[p, k] * coef / w[k]
                    else:
                        deficient = True
            R = _euler_zyx(x[:3]) if euler else rodrigues_nb(x[:3])
            inc = np.eye(4)
            for a in range(3):
                ta = c[a] + x[3 + a]
                for b in range(3):
                    inc[a, b] = R[a, b]
                    ta -= R[a, b] * c[b]
                inc[a, 3] = ta
        else:
            inc = kabsch_pairs(X, Y, sk, tk)
        T_old = T
        T = np.eye(4)
        for a in range(3):
            for b in range(4):
                T[a, b] = (
                    inc[a, 0] * T_old[0, b] + inc[a, 1] * T_old[1, b] + inc[a, 2] * T_old[2, b]
                )
            T[a, 3] += inc[a, 3]
        X, j, d = kd_query(Pp, perm, sdim, sval, P, T, gate, False)
        si, ti, dd = _valid_pairs(j, d, N, plane)
        n_iter = it
        if o3d:
            fit = si.shape[0] / n
            rmse = math.sqrt(np.mean(dd**2)) if dd.shape[0] else 0.0
            if abs(fit - fit_prev) < rel_fit and abs(rmse - rmse_prev) < rel_rmse:
                converged = True
                break
            fit_prev = fit
            rmse_prev = rmse
        else:
            dt = 0.0
            tr = 0.0
            for a in range(3):
                dt += (T[a, 3] - T_old[a, 3]) ** 2
                for b in range(3):
                    tr += T[a, b] * T_old[a, b]  # trace(R Rold^T)
            cosang = min(1.0, max(-1.0, (tr - 1.0) / 2.0))
            if math.sqrt(dt) < ttol and math.acos(cosang) < rtol:
                below += 1
            else:
                below = 0
            if below >= stop_window:
                converged = True
                break
    return T, n_iter, status, converged, deficient, X, si, ti, dd


def reject_outliers(
    d: np.ndarray, rule: Literal["none", "std", "x84"], factor: float
) -> np.ndarray:
    """Boolean mask of the distances kept by an outlier rule.

    ``std``: ``d ≤ mean(d) + factor·std(d)`` (paper 1's ICP, factor 2.5 [interpretation]);
    ``x84``: ``|d − median(d)| ≤ factor·MAD`` (Hampel's X84, factor 5.2); ``none``: all.
    """
    if rule == "none" or d.size == 0:
        return np.ones(d.shape, dtype=bool)
    if rule == "std":
        return d <= d.mean() + factor * d.std()
    med = float(np.median(d))
    dev = np.abs(d - med)
    mad = float(np.median(dev))
    return dev <= factor * mad


def information_ratio(A: np.ndarray, centre: np.ndarray, radius: float) -> float:
    """``λmin/λmax`` of a twist information matrix, made unit- and origin-free.

    ``A`` (6x6, order ``[ρ, φ]``, left perturbation about the frame origin) is re-expressed
    about ``centre`` (``ρ' = ρ + φ × c``: a cloud far from the sensor no longer couples
    rotation and translation) and the rotation block is scaled by ``radius`` (m) so that both
    blocks are in metres. 0 means a direction the geometry does not constrain.
    """
    G = np.eye(6)
    G[:3, 3:] = hat(np.asarray(centre, dtype=np.float64))
    L = radius if radius > 0 else 1.0
    S = np.diag([1.0, 1.0, 1.0, 1.0 / L, 1.0 / L, 1.0 / L])
    M = S @ G.T @ A @ G @ S
    w = np.linalg.eigvalsh(0.5 * (M + M.T))
    return float(w[0] / w[-1]) if w[-1] > 0 else 0.0
