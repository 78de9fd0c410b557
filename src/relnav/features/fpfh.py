"""FPFH — Fast Point Feature Histograms (Rusu, Blodow, Beetz 2009), PCL flavour.

Pair features exactly as PCL's ``computePairFeatures`` (ALGORITHMS §A.3): for ``p1, p2`` with
normals ``n1, n2``, ``Δ = p2 − p1``, the source is the point whose normal makes the smaller angle
with the line; Darboux frame ``u = n1``, ``v = Δ × u / ‖Δ × u‖``, ``w = u × v``;
``f1 = atan2(w·n2, u·n2)``, ``f2 = v·n2``, ``f3 = ±n·Δ/‖Δ‖``. Degenerate pairs (coincident points,
``Δ ∥ n1``) give ``f = (0, 0, 0)`` and are binned, as PCL and Open3D do. Source-selection ties
(``| |n1·Δ| − |n2·Δ| | ≤ 1e-12·‖Δ‖``, e.g. identical PCA normals) keep ``p1`` as source, as PCL
does for exact ties **[interpretation: the tolerance makes the choice robust to rounding, so
the descriptor is rigid-motion invariant; PCL's f3 sign flips with rounding there]**.

SPFH(p): for each neighbour ``q ≠ p`` (by index) within ``r``, ``f1`` is binned into 11 bins over
``[−π, π]`` and ``f2, f3`` into 11 bins over ``[−1, 1]``, each increment ``100/(k − 1)`` (``k``
= neighbours incl. ``p``), so each 11-bin block sums to 100. Pairs involving a non-finite normal
are skipped (``k`` then counts only valid neighbours) **[interpretation; PCL is undefined there]**.

FPFH(p), ``variant="pcl"`` (default, what Paper 1 ran; also Open3D's implementation):
``Σ_{q: d>0} SPFH(q) / d²`` with ``d²`` the **squared** distance, the SPFH of ``p`` itself
skipped, then each 11-bin block rescaled to sum 100. ``variant="paper"`` (Rusu et al. 2009):
``SPFH(p) + (1/k') Σ_{q: d>0} SPFH(q) / d`` with ``d`` the distance and ``k'`` the number of those
neighbours (no rescaling). ``variant="open3d"``: Open3D's ``compute_fpfh_feature`` (checked
against 0.20): the PCL variant **plus** the keypoint's own SPFH after the rescaling (blocks sum
to 200) — Open3D's source re-enabled the paper's own-SPFH term on top of PCL's weighting.

Invalid rows (NaN): fewer than ``MIN_SUPPORT`` (5) support points incl. the keypoint, or an all-
zero histogram (no neighbour with a usable SPFH).

The SPFH is computed once for every point that is needed (all points when every point is a
keypoint, Paper 1's setting), then combined per keypoint.

References
----------
R. B. Rusu, N. Blodow, M. Beetz, "Fast Point Feature Histograms (FPFH) for 3D registration",
ICRA 2009. doi:10.1109/ROBOT.2009.5152473
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit

from relnav.errors import ConfigError, InputError
from relnav.features.base import MIN_SUPPORT, register_descriptor
from relnav.geometry.lrf import grid_build, grid_query

__all__ = ["FPFH_DIM", "fpfh", "pair_features"]

log = logging.getLogger(__name__)

NR_BINS = 11
FPFH_DIM = 3 * NR_BINS  # 33
_TIE = 1e-12
"""Source-selection tie tolerance on ``|n·Δ|/‖Δ‖`` (see :func:`_pair_features`)."""


@njit(cache=True)
def _pair_features(
    p1x: float,
    p1y: float,
    p1z: float,
    n1x: float,
    n1y: float,
    n1z: float,
    p2x: float,
    p2y: float,
    p2z: float,
    n2x: float,
    n2y: float,
    n2z: float,
) -> tuple[float, float, float, float]:
    """PCL ``computePairFeatures``: ``(f1, f2, f3, f4)``; zeros for degenerate pairs."""
    dx = p2x - p1x
    dy = p2y - p1y
    dz = p2z - p1z
    f4 = np.sqrt(dx * dx + dy * dy + dz * dz)
    if f4 == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    a1 = (n1x * dx + n1y * dy + n1z * dz) / f4
    a2 = (n2x * dx + n2y * dy + n2z * dz) / f4
    # PCL swaps when acos(|a1|) > acos(|a2|), i.e. |a1| < |a2|. A tie (e.g. two points with
    # identical PCA normals) keeps p1 as source in PCL; ties within _TIE are treated the same so
    # that rounding (e.g. after a rigid motion) cannot flip the sign of f3.
    if abs(a2) - abs(a1) > _TIE:
        ux, uy, uz = n2x, n2y, n2z
        mx, my, mz = n1x, n1y, n1z
        dx, dy, dz = -dx, -dy, -dz
        f3 = -a2
    else:
        ux, uy, uz = n1x, n1y, n1z
        mx, my, mz = n2x, n2y, n2z
        f3 = a1
    # v = Δ × u
    vx = dy * uz - dz * uy
    vy = dz * ux - dx * uz
    vz = dx * uy - dy * ux
    vn = np.sqrt(vx * vx + vy * vy + vz * vz)
    if vn == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    vx /= vn
    vy /= vn
    vz /= vn
    # w = u × v
    wx = uy * vz - uz * vy
    wy = uz * vx - ux * vz
    wz = ux * vy - uy * vx
    f2 = vx * mx + vy * my + vz * mz
    f1 = np.arctan2(wx * mx + wy * my + wz * mz, ux * mx + uy * my + uz * mz)
    return f1, f2, f3, f4


def pair_features(p1: np.ndarray, n1: np.ndarray, p2: np.ndarray, n2: np.ndarray) -> np.ndarray:
    """PCL pair features ``(f1, f2, f3, f4)`` of two oriented points (radians, -, -, metres)."""
    a = np.asarray(p1, dtype=np.float64)
    b = np.asarray(n1, dtype=np.float64)
    c = np.asarray(p2, dtype=np.float64)
    d = np.asarray(n2, dtype=np.float64)
    return np.array(_pair_features(*a, *b, *c, *d))


@njit(cache=True)
def _bin11(v: float, lo: float, span: float) -> int:
    i = int(np.floor(NR_BINS * ((v - lo) / span)))
    return min(max(i, 0), NR_BINS - 1)


@njit(cache=True)
def _fpfh_kernel(
    P: np.ndarray,
    Nrm: np.ndarray,
    kp: np.ndarray,
    need: np.ndarray,
    radius: float,
    variant: int,
    min_support: int,
) -> np.ndarray:
    """SPFH of the needed points, then FPFH per keypoint (variant 0 pcl, 1 paper, 2 open3d)."""
    n = P.shape[0]
    K = kp.shape[0]
    out = np.full((K, FPFH_DIM), np.nan, dtype=np.float32)
    lo, h, dims, start, sidx, spts = grid_build(P, radius)
    bi = np.empty(n, dtype=np.int64)
    bd = np.empty(n)
    valid_n = np.empty(n, dtype=np.bool_)
    for i in range(n):
        valid_n[i] = np.isfinite(Nrm[i, 0]) and np.isfinite(Nrm[i, 1]) and np.isfinite(Nrm[i, 2])
    # SPFH of every needed point
    row = np.full(n, -1, dtype=np.int64)
    n_need = 0
    for i in range(n):
        if need[i]:
            row[i] = n_need
            n_need += 1
    spfh = np.zeros((max(n_need, 1), FPFH_DIM))
    cnt = np.zeros(3 * NR_BINS, dtype=np.int64)
    for i in range(n):
        ri = row[i]
        if ri < 0 or not valid_n[i]:
            continue
        m = grid_query(spts, lo, h, dims, start, sidx, P[i], radius, bi, bd)
        cnt[:] = 0
        nvalid = 0
        for t in range(m):
            j = bi[t]
            if j == i or not valid_n[j]:
                continue
            f1, f2, f3, _ = _pair_features(
                P[i, 0],
                P[i, 1],
                P[i, 2],
                Nrm[i, 0],
                Nrm[i, 1],
                Nrm[i, 2],
                P[j, 0],
                P[j, 1],
                P[j, 2],
                Nrm[j, 0],
                Nrm[j, 1],
                Nrm[j, 2],
            )
            cnt[_bin11(f1, -np.pi, 2.0 * np.pi)] += 1
            cnt[NR_BINS + _bin11(f2, -1.0, 2.0)] += 1
            cnt[2 * NR_BINS + _bin11(f3, -1.0, 2.0)] += 1
            nvalid += 1
        if nvalid > 0:
            incr = 100.0 / nvalid
            for b in range(FPFH_DIM):
                spfh[ri, b] = cnt[b] * incr
    # combine per keypoint
    paper = variant == 1
    acc = np.zeros(FPFH_DIM)
    for k in range(K):
        i = kp[k]
        m = grid_query(spts, lo, h, dims, start, sidx, P[i], radius, bi, bd)
        if m < min_support:
            continue
        acc[:] = 0.0
        nw = 0
        for t in range(m):
            d2 = bd[t]
            if d2 == 0.0:
                continue
            w = 1.0 / np.sqrt(d2) if paper else 1.0 / d2
            rj = row[bi[t]]
            for b in range(FPFH_DIM):
                acc[b] += w * spfh[rj, b]
            nw += 1
        if paper:
            if nw > 0:
                for b in range(FPFH_DIM):
                    acc[b] /= nw
            for b in range(FPFH_DIM):
                acc[b] += spfh[row[i], b]
            tot = 0.0
            for b in range(FPFH_DIM):
                tot += acc[b]
            if not (tot > 0.0):
                continue
            for b in range(FPFH_DIM):
                out[k, b] = acc[b]
        else:
            ok = True
            for f in range(3):
                s = 0.0
                for b in range(f * NR_BINS, (f + 1) * NR_BINS):
                    s += acc[b]
                if not (s > 0.0):
                    ok = False
                    break
                sc = 100.0 / s
                for b in range(f * NR_BINS, (f + 1) * NR_BINS):
                    acc[b] *= sc
            if not ok:
                continue
            if variant == 2:  # Open3D adds the keypoint's own SPFH after the rescaling
                for b in range(FPFH_DIM):
                    acc[b] += spfh[row[i], b]
            for b in range(FPFH_DIM):
                out[k, b] = acc[b]
    return out


@njit(cache=True)
def _needed(P: np.ndarray, kp: np.ndarray, radius: float) -> np.ndarray:
    """Mask of the points whose SPFH is needed: the keypoints and their neighbours."""
    n = P.shape[0]
    need = np.zeros(n, dtype=np.bool_)
    lo, h, dims, start, sidx, spts = grid_build(P, radius)
    bi = np.empty(n, dtype=np.int64)
    bd = np.empty(n)
    for k in range(kp.shape[0]):
        need[kp[k]] = True
        m = grid_query(spts, lo, h, dims, start, sidx, P[kp[k]], radius, bi, bd)
        for t in range(m):
            need[bi[t]] = True
    return need


@register_descriptor(
    "fpfh",
    dim=FPFH_DIM,
    radius_factor=20.0,
    needs_normals=True,
    description="Fast Point Feature Histograms (PCL weighting, 33)",
)
def fpfh(
    points: np.ndarray,
    keypoint_idx: np.ndarray,
    *,
    radius: float,
    normals: np.ndarray | None,
    variant: str = "pcl",
    **unknown: object,
) -> np.ndarray:
    """FPFH descriptors (33 values) at the keypoints.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres (sensor frame).
    keypoint_idx : (K,) int
        Keypoint indices into ``points``.
    radius : float
        Support radius ``r`` (SPFH and FPFH), metres (default ``20·Tr`` via the registry).
    normals : (N, 3) float64
        Unit normals of ``points``.
    variant : {"pcl", "paper", "open3d"}
        Weighting (see module docstring); ``"pcl"`` matches PCL, ``"open3d"`` Open3D ≥ 0.1x.

    Returns
    -------
    (K, 33) float32
        ``[f1 | f2 | f3]`` 11-bin blocks; NaN rows for invalid keypoints.
    """
    if unknown:
        raise ConfigError(f"unknown FPFH option(s) {sorted(unknown)}; valid: variant")
    if variant not in ("pcl", "paper", "open3d"):
        raise ConfigError(f"FPFH variant must be 'pcl', 'paper' or 'open3d', got {variant!r}")
    P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    kp = np.ascontiguousarray(keypoint_idx, dtype=np.int64).reshape(-1)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"FPFH radius must be positive and finite, got {radius}")
    if normals is None:
        raise InputError("FPFH needs per-point normals")
    Nrm = np.ascontiguousarray(normals, dtype=np.float64)
    if Nrm.shape != P.shape:
        raise InputError(f"normals must have shape {P.shape}, got {Nrm.shape}")
    if kp.size == 0:
        return np.zeros((0, FPFH_DIM), dtype=np.float32)
    if kp.size >= P.shape[0]:
        need = np.ones(P.shape[0], dtype=bool)
    else:
        need = _needed(P, kp, float(radius))
    code = {"pcl": 0, "paper": 1, "open3d": 2}[variant]
    out = _fpfh_kernel(P, Nrm, kp, need, float(radius), code, MIN_SUPPORT)
    n_bad = int(np.isnan(out[:, 0]).sum())
    if n_bad:
        log.debug("FPFH: %d of %d keypoints invalid (NaN)", n_bad, kp.size)
    return out
