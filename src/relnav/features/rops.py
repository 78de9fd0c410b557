"""RoPS — Rotational Projection Statistics (Guo et al. 2013), as PCL's ``ROPSEstimation``.

RoPS is defined on a triangle mesh; PCL builds the LRF from the mesh triangles touching the
support and projects the *support points*. relnav does the same. The mesh is (``lrf``):

* ``triangles`` given: that mesh. With PCL's own greedy-projection mesh the descriptors equal
  PCL's (median correlation 1.0000 on the ``tests/data/pcl`` fixture).
* default ``lrf="local_mesh"`` (**[interpretation]**, ALGORITHMS §A.4 "triangulate"): each
  keypoint's neighbourhood triangulated on its own (2D Delaunay of the tangent-plane projection,
  edges ≤ ``max_edge``; :mod:`relnav.geometry.local_mesh`), as Paper 1's RoPS ran on
  triangulated clouds.
* ``lrf="points"``: the point-based RoPS LRF (ALGORITHMS §A.4 fallback), relnav's former default.

Given the same triangles, the default is PCL's RoPS: PCL's ``ROPSEstimation`` at each keypoint
with that keypoint's local triangles (:func:`relnav.geometry.lrf.rops_local_mesh`) as its mesh
correlates 1.0000 with the default on every keypoint of the fixture. Against PCL's RoPS on PCL's
own greedy-projection mesh, the default and ``lrf="points"`` correlate 0.93-0.95 (median): the
x axis (largest scatter eigenvalue) depends on which triangles cover the support, and PCL's
greedy mesh leaves holes; PCL against itself with greedy-projection ``mu`` 4 instead of 2.5
gives the same 0.94-0.95 (``benchmarks/paper1/pcl_reference``).

For each keypoint ``p`` the support points (``‖q − p‖ ≤ r``, keypoint included) are expressed in
the LRF, ``q' = LRF (q − p)``. For each axis ``a ∈ (x, y, z)`` and each angle
``θ_t = t·90°/(T+1)``, ``t = 1..T`` (``T = 3`` → 22.5°, 45°, 67.5°, angle set of PCL), the
local points are rotated by ``θ_t`` about ``a`` and projected onto the xy, xz and yz planes. Each
projection is binned on an ``L × L`` grid (``L = 5``) spanning the **3D bounding box of the
rotated points** (as PCL; the last bin is closed), giving a distribution matrix ``D`` that sums
to 1. From ``D`` (1-based cell indices ``i, j``) the central moments ``μ11, μ21, μ12, μ22`` and
the Shannon entropy ``−Σ D log D`` (**natural log**, as PCL; Guo's paper uses log2 — option
``entropy_base``) are taken. Layout (axis-major, then rotation, projection, statistic):
``3 axes × T × 3 projections × 5 = 135`` for ``T = 3``; the whole vector is divided by its L1 norm.

References
----------
Y. Guo, F. Sohel, M. Bennamoun, M. Lu, J. Wan, "Rotational projection statistics for 3D local
surface description and object recognition", IJCV 105 (2013). doi:10.1007/s11263-013-0627-y
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.errors import ConfigError, InputError
from relnav.features.base import MIN_SUPPORT, register_descriptor
from relnav.geometry.lrf import check_points, check_rops_lrf, rops_lrf_csr, support_csr
from relnav.geometry.rotations import rotvec_to_matrix

__all__ = ["rops", "rops_rotations"]

log = logging.getLogger(__name__)

_PROJ = np.array([[0, 1], [0, 2], [1, 2]], dtype=np.int64)
"""Coordinate pairs of the xy, xz and yz projections (PCL order)."""


def rops_rotations(n_rotations: int = 3) -> np.ndarray:
    """The ``3·T`` rotation matrices of RoPS, axis-major (x then y then z), ``(3T, 3, 3)``.

    Angles ``θ_t = t·90°/(T+1)``, ``t = 1..T`` (right-handed rotation about each LRF axis).
    """
    T = int(n_rotations)
    if T < 1:
        raise ConfigError(f"RoPS n_rotations must be ≥ 1, got {n_rotations}")
    theta = np.deg2rad(90.0 / (T + 1)) * np.arange(1, T + 1)
    rv = np.concatenate([np.outer(theta, e) for e in np.eye(3)])
    return np.ascontiguousarray(rotvec_to_matrix(rv).reshape(-1, 3, 3))


@njit(cache=True, error_model="numpy")
def _rops_kernel(
    P: np.ndarray,
    kp: np.ndarray,
    flat: np.ndarray,
    offsets: np.ndarray,
    lrfs: np.ndarray,
    rots: np.ndarray,
    proj: np.ndarray,
    n_bins: int,
    inv_log_base: float,
    zero_extent: float,
    min_support: int,
) -> np.ndarray:
    K = kp.shape[0]
    R = rots.shape[0]
    D = R * 3 * 5
    out = np.full((K, D), np.nan)
    B = n_bins
    dist = np.zeros((3, B, B))
    for k in range(K):
        s0 = offsets[k]
        n = offsets[k + 1] - s0
        if n < min_support or np.isnan(lrfs[k, 0, 0]):
            continue
        p = P[kp[k]]
        L = lrfs[k]
        loc = np.empty((n, 3))
        for t in range(n):
            q = P[flat[s0 + t]]
            v0 = q[0] - p[0]
            v1 = q[1] - p[1]
            v2 = q[2] - p[2]
            for i in range(3):
                loc[t, i] = L[i, 0] * v0 + L[i, 1] * v1 + L[i, 2] * v2
        rot = np.empty((n, 3))
        cell = np.empty((n, 3), dtype=np.int64)
        lo = np.empty(3)
        hi = np.empty(3)
        col = 0
        for r in range(R):
            Rm = rots[r]
            lo[:] = np.inf
            hi[:] = -np.inf
            for t in range(n):
                for i in range(3):
                    c = Rm[i, 0] * loc[t, 0] + Rm[i, 1] * loc[t, 1] + Rm[i, 2] * loc[t, 2]
                    rot[t, i] = c
                    if c < lo[i]:
                        lo[i] = c
                    if c > hi[i]:
                        hi[i] = c
            # bin index of every point along each axis of the 3D bounding box (PCL: bin length
            # = extent / L, last bin closed); a zero extent puts everything in bin 0
            for i in range(3):
                ext = hi[i] - lo[i]
                if ext > zero_extent:
                    blen = ext / B
                    for t in range(n):
                        c = int((rot[t, i] - lo[i]) / blen)
                        cell[t, i] = B - 1 if c > B - 1 else (0 if c < 0 else c)
                else:
                    cell[:, i] = 0
            dist[:, :, :] = 0.0
            for t in range(n):
                for pj in range(3):
                    dist[pj, cell[t, proj[pj, 0]], cell[t, proj[pj, 1]]] += 1.0
            for pj in range(3):
                mean_i = 0.0
                mean_j = 0.0
                for i in range(B):
                    for j in range(B):
                        dist[pj, i, j] /= n
                        mean_i += (i + 1) * dist[pj, i, j]
                        mean_j += (j + 1) * dist[pj, i, j]
                m11 = 0.0
                m21 = 0.0
                m12 = 0.0
                m22 = 0.0
                ent = 0.0
                for i in range(B):
                    fi = (i + 1) - mean_i
                    for j in range(B):
                        d = dist[pj, i, j]
                        if d > 0.0:
                            fj = (j + 1) - mean_j
                            m11 += fi * fj * d
                            m21 += fi * fi * fj * d
                            m12 += fi * fj * fj * d
                            m22 += fi * fi * fj * fj * d
                            ent -= d * np.log(d)
                out[k, col] = m11
                out[k, col + 1] = m21
                out[k, col + 2] = m12
                out[k, col + 3] = m22
                out[k, col + 4] = ent * inv_log_base
                col += 5
        norm = 0.0
        for c in range(D):
            norm += abs(out[k, c])
        if norm > 0.0 and np.isfinite(norm):
            for c in range(D):
                out[k, c] /= norm
        else:
            out[k, :] = np.nan
    return out


@register_descriptor(
    "rops",
    dim=135,
    radius_factor=20.0,
    needs_normals=False,
    description="RoPS rotational projection statistics (local-mesh LRF), 3x3x3x5 = 135",
)
def rops(
    points: np.ndarray,
    keypoint_idx: np.ndarray,
    *,
    radius: float,
    normals: np.ndarray | None = None,
    n_bins: int = 5,
    n_rotations: int = 3,
    entropy_base: float | None = None,
    triangles: np.ndarray | None = None,
    lrf: str = "local_mesh",
    max_edge: float | None = None,
    tree: cKDTree | None = None,
    degenerate_tol: float = 1e-10,
) -> np.ndarray:
    """RoPS descriptors at the keypoints.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres (any frame; the descriptor is rigid-motion invariant).
    keypoint_idx : (K,) int
        Keypoint indices into ``points``.
    radius : float
        Support radius ``r``, metres (Paper 1: ``20·Tr``).
    normals : ignored
        RoPS needs no normals (accepted for the registry signature).
    n_bins : int
        Grid size ``L`` of each projection (PCL default 5).
    n_rotations : int
        Rotations ``T`` per axis (default 3 → 22.5°, 45°, 67.5°); the length is ``45·T``, so
        values other than 3 only work when calling this function directly (the registry
        declares 135).
    entropy_base : float, optional
        Logarithm base of the entropy; natural log when omitted (PCL), 2 for Guo's paper.
    triangles : (M, 3) int, optional
        Mesh triangles over ``points``: the mesh RoPS LRF on this mesh (``lrf`` ignored); with
        PCL's mesh the result equals PCL's ``ROPSEstimation``.
    lrf : {"local_mesh", "points"}
        Frame without ``triangles``: mesh LRF on a local Delaunay triangulation of each
        neighbourhood (default) or the point-based LRF (:func:`relnav.geometry.lrf.rops_lrf`).
    max_edge : float, optional
        Longest local-mesh edge, metres (default ``3·Tr``).
    tree : scipy.spatial.cKDTree, optional
        Prebuilt tree of ``points``.
    degenerate_tol : float
        As in :func:`relnav.geometry.lrf.rops_lrf` (undefined-frame test).

    Returns
    -------
    (K, 45·T) float32
        L1-normalised descriptors; NaN rows for fewer than 5 support points (keypoint included)
        or an undefined LRF.
    """
    P, kp = check_points(points, keypoint_idx)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"RoPS radius must be positive and finite, got {radius}")
    if int(n_bins) < 1:
        raise ConfigError(f"RoPS n_bins must be ≥ 1, got {n_bins}")
    rots = rops_rotations(n_rotations)
    check_rops_lrf(lrf, max_edge)
    if entropy_base is None:
        inv_log_base = 1.0
    elif entropy_base > 0 and entropy_base != 1:
        inv_log_base = 1.0 / np.log(float(entropy_base))
    else:
        raise ConfigError(f"RoPS entropy_base must be positive and != 1, got {entropy_base}")
    dim = rots.shape[0] * 15
    if kp.size == 0:
        return np.zeros((0, dim), dtype=np.float32)
    radius = float(radius)
    flat, offsets = support_csr(P, kp, radius, tree)
    lrfs = rops_lrf_csr(
        P, kp, flat, offsets, radius, triangles, float(degenerate_tol), lrf, max_edge, tree
    )
    out = _rops_kernel(
        P,
        kp,
        flat,
        offsets,
        np.ascontiguousarray(lrfs),
        rots,
        _PROJ,
        int(n_bins),
        float(inv_log_base),
        1e-12 * radius,
        MIN_SUPPORT,
    )
    n_bad = int(np.isnan(out[:, 0]).sum())
    if n_bad:
        log.debug("rops: %d of %d keypoints invalid (support < 5 or undefined LRF)", n_bad, kp.size)
    return out.astype(np.float32)
