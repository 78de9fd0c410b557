"""SHOT local reference frame (PCL ``SHOTLocalReferenceFrameEstimation``): weighted covariance of
the radius neighbourhood, sign disambiguation; rows are the unit axes in the cloud frame (the
convention of :mod:`relnav.geometry.lrf`).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.errors import InputError
from relnav.geometry.radius_grid import (
    _argsort_d2_idx,
    check_points,
    grid_build,
    grid_query,
    support_csr,
)

__all__ = [
    "SHOT_MIN_NEIGHBORS",
    "shot_lrf",
]


SHOT_MIN_NEIGHBORS = 5
"""Minimum neighbours *other than the keypoint* for a SHOT LRF (PCL ``getLocalRF`` rule)."""


@njit(cache=True)
def shot_lrf_one(
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
    lo, h, dims, start, sidx, spts = grid_build(P, radius)
    bi = np.empty(n, dtype=np.int64)
    bd = np.empty(n)
    V = np.empty((n, 3))
    vd2 = np.empty(n)
    vid = np.empty(n, dtype=np.int64)
    frame = np.empty((3, 3))
    tie = np.zeros(2, dtype=np.bool_)
    for k in range(K):
        p = P[kp[k]]
        m = grid_query(spts, lo, h, dims, start, sidx, p, radius, bi, bd)
        if shot_lrf_one(P, p, bi, bd, m, radius, min_nb, V, vd2, vid, frame, tie):
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
        if shot_lrf_one(P, P[kp[k]], nbr[s0:], d2[s0:], m, radius, min_nb, V, vd2, vid, frame, tie):
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
    nbr, offsets = support_csr(P, kp, radius, tree)
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
    P, kp = check_points(points, keypoint_idx)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"LRF radius must be positive and finite, got {radius}")
    if kp.size == 0:
        return np.full((0, 3, 3), np.nan)
    return _shot_lrf_full(P, kp, float(radius), tree)[0]
