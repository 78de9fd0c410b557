"""SHOT — Signature of Histograms of OrienTations (Salti, Tombari, Di Stefano 2014), PCL flavour.

Shape-only SHOT (352 values) following PCL's ``SHOTEstimation`` (ALGORITHMS §A.2):

* LRF: :func:`relnav.geometry.lrf.shot_lrf` (PCL ``SHOTLocalReferenceFrameEstimation``, same
  radius as the descriptor unless ``lrf_radius`` is given).
* Grid: 8 azimuth sectors × 2 elevations (sign of local ``z``) × 2 radial shells (split at
  ``r/2``) = 32 volumes, each with an 11-slot histogram of ``cos θ = n_q · z_LRF`` (the normal
  of the *neighbour* against the keypoint's LRF ``z``): ``bin_pos = (1 + cos θ)·10/2``.
* Interpolation ``interp="pcl"`` (default): PCL's **additive** scheme — the own bin receives the
  sum of the four per-dimension own-weights, each neighbouring bin its own share, including
  PCL's cosine wrap-around quirk (``(step ± 1) mod 10``) **[interpretation: follow PCL]**.
  ``interp="product"``: the quadrilinear interpolation of the SHOT paper (a point's unit mass
  split over the 16 combinations of own/neighbouring bins by products of ``1 − d`` factors,
  no wrap-around on the cosine axis, none beyond the outermost bin centres).
* Normalisation: whole vector divided by its L2 norm.
* Layout ``layout="spec"`` (default, ALGORITHMS §A.2 **[interpretation]**):
  ``index = ((sector·2 + elevation)·2 + shell)·11 + cos_bin``; ``layout="pcl"`` gives PCL's
  order ``((sector·2 + shell)·2 + elevation)·11 + cos_bin`` for comparison with PCL output.

Invalid rows (NaN): LRF undefined (fewer than 5 neighbours besides the keypoint), or no
neighbour with a finite normal (zero histogram). Neighbours with non-finite normals are skipped.

References
----------
S. Salti, F. Tombari, L. Di Stefano, "SHOT: Unique signatures of histograms for surface and
texture description", CVIU 125 (2014). doi:10.1016/j.cviu.2014.04.011
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit

from relnav.errors import ConfigError, InputError
from relnav.features.base import register_descriptor
from relnav.geometry.lrf import SHOT_MIN_NEIGHBORS, grid_build, grid_query, shot_lrf_one

__all__ = ["SHOT_DIM", "shot"]

log = logging.getLogger(__name__)

NR_SHAPE_BINS = 10
"""PCL ``nr_shape_bins_``; each volume has ``NR_SHAPE_BINS + 1`` slots."""
N_VOLUMES = 32
SHOT_DIM = N_VOLUMES * (NR_SHAPE_BINS + 1)  # 352

_PI = np.pi
_RAD_45 = np.pi / 4.0
_RAD_90 = np.pi / 2.0
_RAD_135 = 3.0 * np.pi / 4.0
_RAD_PI_7_8 = 7.0 * np.pi / 8.0


def _spec_permutation() -> np.ndarray:
    """Column permutation PCL layout → spec layout (swap the shell and elevation bits)."""
    nb = NR_SHAPE_BINS + 1
    perm = np.empty(SHOT_DIM, dtype=np.int64)
    for a in range(8):
        for e in range(2):
            for s in range(2):
                vol_spec = (a * 2 + e) * 2 + s
                vol_pcl = (a * 2 + s) * 2 + e
                perm[vol_spec * nb : (vol_spec + 1) * nb] = np.arange(
                    vol_pcl * nb, (vol_pcl + 1) * nb
                )
    return perm


_SPEC_FROM_PCL = _spec_permutation()


@njit(cache=True)
def _volume_pcl(x: float, y: float, z: float, dist: float, r_half: float) -> tuple[int, int]:
    """PCL's volume index ``sector·4 + shell·2 + elevation`` and the azimuth sector."""
    bit4 = 1 if (y > 0.0 or (y == 0.0 and x < 0.0)) else 0
    if x > 0.0 or (x == 0.0 and y > 0.0):
        bit3 = 1 - bit4
    else:
        bit3 = bit4
    desc = ((bit4 << 3) + (bit3 << 2)) << 1
    if x * y > 0.0 or x == 0.0:
        desc += 0 if abs(x) >= abs(y) else 4
    else:
        desc += 4 if abs(x) > abs(y) else 0
    desc += 1 if z > 0.0 else 0
    desc += 2 if dist > r_half else 0
    return desc, desc >> 2


@njit(cache=True)
def _accumulate_pcl(
    hist: np.ndarray,
    desc: int,
    sel: int,
    bin_pos: float,
    x: float,
    y: float,
    z: float,
    dist: float,
    radius: float,
) -> None:
    """PCL ``interpolateSingleChannel`` for one neighbour (additive interpolation)."""
    nb = NR_SHAPE_BINS
    r12 = radius / 2.0
    r14 = radius / 4.0
    r34 = 3.0 * radius / 4.0
    step = int(np.floor(bin_pos + 0.5))
    vol = desc * (nb + 1)
    dc = bin_pos - step
    w_own = 1.0 - abs(dc)
    if dc > 0.0:
        hist[vol + (step + 1) % nb] += dc
    else:
        hist[vol + (step - 1 + nb) % nb] += -dc
    # radial shells
    if dist > r12:
        rd = (dist - r34) / r12
        if dist > r34:
            w_own += 1.0 - rd
        else:
            w_own += 1.0 + rd
            hist[(desc - 2) * (nb + 1) + step] -= rd
    else:
        rd = (dist - r14) / r12
        if dist < r14:
            w_own += 1.0 + rd
        else:
            w_own += 1.0 - rd
            hist[(desc + 2) * (nb + 1) + step] += rd
    # elevation
    ic = z / dist
    ic = min(max(ic, -1.0), 1.0)
    incl = np.arccos(ic)
    if incl > _RAD_90 or (abs(incl - _RAD_90) < 1e-30 and z <= 0.0):
        idist = (incl - _RAD_135) / _RAD_90
        if incl > _RAD_135:
            w_own += 1.0 - idist
        else:
            w_own += 1.0 + idist
            hist[(desc + 1) * (nb + 1) + step] -= idist
    else:
        idist = (incl - _RAD_45) / _RAD_90
        if incl < _RAD_45:
            w_own += 1.0 + idist
        else:
            w_own += 1.0 - idist
            hist[(desc - 1) * (nb + 1) + step] += idist
    # azimuth
    if y != 0.0 or x != 0.0:
        az = np.arctan2(y, x)
        adist = (az - (-_RAD_PI_7_8 + _RAD_45 * sel)) / _RAD_45
        adist = max(-0.5, min(adist, 0.5))
        if adist > 0.0:
            w_own += 1.0 - adist
            hist[((desc + 4) % N_VOLUMES) * (nb + 1) + step] += adist
        else:
            w_own += 1.0 + adist
            hist[((desc - 4 + N_VOLUMES) % N_VOLUMES) * (nb + 1) + step] -= adist
    hist[vol + step] += w_own


@njit(cache=True)
def _accumulate_product(
    hist: np.ndarray,
    desc: int,
    sel: int,
    bin_pos: float,
    x: float,
    y: float,
    z: float,
    dist: float,
    radius: float,
) -> None:
    """Quadrilinear interpolation of the SHOT paper: unit mass, products of ``1 − d``."""
    nb = NR_SHAPE_BINS
    e_own = desc & 1
    s_own = (desc >> 1) & 1
    # cosine axis: bin centres at integer bin_pos 0..10, no wrap-around
    step = int(np.floor(bin_pos + 0.5))
    dc = bin_pos - step
    c_idx = np.array([step, step + 1 if dc > 0.0 else step - 1])
    c_w = np.array([1.0 - abs(dc), abs(dc)])
    if c_idx[1] < 0 or c_idx[1] > nb:
        c_w[0] = 1.0
        c_w[1] = 0.0
        c_idx[1] = step
    # radial axis: shell centres r/4 (inner) and 3r/4 (outer)
    t = (dist - radius / 4.0) / (radius / 2.0)
    t = min(max(t, 0.0), 1.0)  # weight of the outer shell
    s_idx = np.array([s_own, 1 - s_own])
    s_w = np.array([t if s_own == 1 else 1.0 - t, 1.0 - t if s_own == 1 else t])
    # elevation axis: centres at 45° (upper, e=1) and 135° (lower, e=0) inclination
    ic = min(max(z / dist, -1.0), 1.0)
    incl = np.arccos(ic)
    u = (incl - _RAD_45) / _RAD_90
    u = min(max(u, 0.0), 1.0)  # weight of the lower half
    e_idx = np.array([e_own, 1 - e_own])
    e_w = np.array([1.0 - u if e_own == 1 else u, u if e_own == 1 else 1.0 - u])
    # azimuth axis (circular)
    a_idx = np.array([sel, sel])
    a_w = np.array([1.0, 0.0])
    if y != 0.0 or x != 0.0:
        az = np.arctan2(y, x)
        adist = (az - (-_RAD_PI_7_8 + _RAD_45 * sel)) / _RAD_45
        adist = max(-0.5, min(adist, 0.5))
        a_idx[1] = (sel + 1) % 8 if adist > 0.0 else (sel + 7) % 8
        a_w[0] = 1.0 - abs(adist)
        a_w[1] = abs(adist)
    for ia in range(2):
        if a_w[ia] == 0.0:
            continue
        for ie in range(2):
            if e_w[ie] == 0.0:
                continue
            for is_ in range(2):
                if s_w[is_] == 0.0:
                    continue
                w3 = a_w[ia] * e_w[ie] * s_w[is_]
                vol = a_idx[ia] * 4 + s_idx[is_] * 2 + e_idx[ie]
                for ic_ in range(2):
                    if c_w[ic_] != 0.0:
                        hist[vol * (nb + 1) + c_idx[ic_]] += w3 * c_w[ic_]


@njit(cache=True)
def _shot_kernel(
    P: np.ndarray,
    N: np.ndarray,
    kp: np.ndarray,
    radius: float,
    lrf_radius: float,
    product: bool,
    min_nb: int,
) -> np.ndarray:
    n = P.shape[0]
    K = kp.shape[0]
    out = np.full((K, SHOT_DIM), np.nan, dtype=np.float32)
    lo, h, dims, start, sidx, spts = grid_build(P, max(radius, lrf_radius))
    bi = np.empty(n, dtype=np.int64)
    bd = np.empty(n)
    V = np.empty((n, 3))
    vd2 = np.empty(n)
    vid = np.empty(n, dtype=np.int64)
    frame = np.empty((3, 3))
    tie = np.zeros(2, dtype=np.bool_)
    hist = np.zeros(SHOT_DIM)
    same = lrf_radius == radius
    r_half = radius / 2.0
    for k in range(K):
        p = P[kp[k]]
        m = grid_query(spts, lo, h, dims, start, sidx, p, lrf_radius, bi, bd)
        if not shot_lrf_one(P, p, bi, bd, m, lrf_radius, min_nb, V, vd2, vid, frame, tie):
            continue
        if not same:
            m = grid_query(spts, lo, h, dims, start, sidx, p, radius, bi, bd)
        hist[:] = 0.0
        for t in range(m):
            d2 = bd[t]
            if d2 == 0.0:
                continue
            j = bi[t]
            nx = N[j, 0]
            ny = N[j, 1]
            nz = N[j, 2]
            if not (np.isfinite(nx) and np.isfinite(ny) and np.isfinite(nz)):
                continue
            cosd = nx * frame[2, 0] + ny * frame[2, 1] + nz * frame[2, 2]
            cosd = min(max(cosd, -1.0), 1.0)
            bin_pos = (1.0 + cosd) * NR_SHAPE_BINS / 2.0
            v0 = P[j, 0] - p[0]
            v1 = P[j, 1] - p[1]
            v2 = P[j, 2] - p[2]
            x = v0 * frame[0, 0] + v1 * frame[0, 1] + v2 * frame[0, 2]
            y = v0 * frame[1, 0] + v1 * frame[1, 1] + v2 * frame[1, 2]
            z = v0 * frame[2, 0] + v1 * frame[2, 1] + v2 * frame[2, 2]
            if abs(x) < 1e-30:
                x = 0.0
            if abs(y) < 1e-30:
                y = 0.0
            if abs(z) < 1e-30:
                z = 0.0
            dist = np.sqrt(d2)
            desc, sel = _volume_pcl(x, y, z, dist, r_half)
            if product:
                _accumulate_product(hist, desc, sel, bin_pos, x, y, z, dist, radius)
            else:
                _accumulate_pcl(hist, desc, sel, bin_pos, x, y, z, dist, radius)
        nrm = 0.0
        for i in range(SHOT_DIM):
            nrm += hist[i] * hist[i]
        nrm = np.sqrt(nrm)
        if not (nrm > 0.0 and np.isfinite(nrm)):
            continue
        for i in range(SHOT_DIM):
            out[k, i] = hist[i] / nrm
    return out


@register_descriptor(
    "shot",
    dim=SHOT_DIM,
    radius_factor=20.0,
    needs_normals=True,
    description="SHOT shape histograms in the SHOT LRF (PCL, 352)",
)
def shot(
    points: np.ndarray,
    keypoint_idx: np.ndarray,
    *,
    radius: float,
    normals: np.ndarray | None,
    interp: str = "pcl",
    layout: str = "spec",
    lrf_radius: float | None = None,
    **unknown: object,
) -> np.ndarray:
    """SHOT descriptors (shape only, 352 values) at the keypoints.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres (sensor frame).
    keypoint_idx : (K,) int
        Keypoint indices into ``points``.
    radius : float
        Support radius ``r``, metres (default ``20·Tr`` via the registry).
    normals : (N, 3) float64
        Unit normals of ``points`` (the neighbours' normals are binned); NaN rows are skipped.
    interp : {"pcl", "product"}
        PCL's additive interpolation (default) or the paper's quadrilinear product.
    layout : {"spec", "pcl"}
        Bin order (see module docstring).
    lrf_radius : float, optional
        Radius of the SHOT LRF; defaults to ``radius`` (PCL default).

    Returns
    -------
    (K, 352) float32
        Unit-L2 rows; NaN rows for invalid keypoints.
    """
    if unknown:
        raise ConfigError(
            f"unknown SHOT option(s) {sorted(unknown)}; valid: interp, layout, lrf_radius"
        )
    if interp not in ("pcl", "product"):
        raise ConfigError(f"SHOT interp must be 'pcl' or 'product', got {interp!r}")
    if layout not in ("spec", "pcl"):
        raise ConfigError(f"SHOT layout must be 'spec' or 'pcl', got {layout!r}")
    P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    kp = np.ascontiguousarray(keypoint_idx, dtype=np.int64).reshape(-1)
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"SHOT radius must be positive and finite, got {radius}")
    lr = float(radius) if lrf_radius is None else float(lrf_radius)
    if not (np.isfinite(lr) and lr > 0):
        raise ConfigError(f"SHOT lrf_radius must be positive and finite, got {lrf_radius}")
    if normals is None:
        raise InputError("SHOT needs per-point normals")
    Nrm = np.ascontiguousarray(normals, dtype=np.float64)
    if Nrm.shape != P.shape:
        raise InputError(f"normals must have shape {P.shape}, got {Nrm.shape}")
    if kp.size == 0:
        return np.zeros((0, SHOT_DIM), dtype=np.float32)
    out = _shot_kernel(P, Nrm, kp, float(radius), lr, interp == "product", SHOT_MIN_NEIGHBORS)
    if layout == "spec":
        out = np.ascontiguousarray(out[:, _SPEC_FROM_PCL])
    n_bad = int(np.isnan(out[:, 0]).sum())
    if n_bad:
        log.debug("SHOT: %d of %d keypoints invalid (NaN)", n_bad, kp.size)
    return out
