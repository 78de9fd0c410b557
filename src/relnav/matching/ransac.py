"""RANSAC over putative correspondences (ALGORITHMS §B.3; Paper 1 §4.4 ablation).

Hypotheses are drawn from 3-correspondence minimal samples; each sample whose source or target
triangle is degenerate (area below ``min_area``) is rejected, the others give a rigid transform
by Kabsch/SVD, and the hypothesis with the most inliers ``‖R s + t − m‖ < θ`` wins (ties → the
earliest hypothesis). The winner is re-estimated by Kabsch on all its inliers.

Samples are drawn with NumPy's generator in fixed-size batches (so results depend only on
``seed``, not on timing), and each batch is scored by a numba kernel (closed-form 3-point
Kabsch + inlier count).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from relnav.errors import ConfigError
from relnav.geometry.se3 import kabsch
from relnav.matching.correspondences import Correspondences
from relnav.matching.gcc import _check_epsilon, _gather_points

__all__ = ["RansacResult", "ransac_correspondences", "ransac_search", "sample_triplets"]

logger = logging.getLogger(__name__)

BATCH = 2048
"""Hypotheses drawn and scored per batch (fixed: part of the seeded random stream)."""


@dataclass(frozen=True)
class RansacResult:
    """Outcome of :func:`ransac_search`.

    Attributes
    ----------
    inliers : Correspondences
        Inliers of the best hypothesis, in input order (empty on failure).
    T_target_source : (4, 4) float64
        Kabsch re-estimate on all inliers (identity on failure).
    inlier_mask : (n,) bool
        Which input correspondences are inliers.
    n_iterations : int
        Hypotheses drawn (including degenerate ones).
    n_degenerate : int
        Samples rejected as degenerate.
    best_count : int
        Inliers of the best hypothesis.
    success : bool
        A non-degenerate hypothesis with at least ``min_inliers`` inliers was found.
    seed : int or None
        Seed of the sampling generator (``None`` when a Generator was passed).
    info : dict
        Extra diagnostics (threshold, adaptive target iteration count, ...).
    """

    inliers: Correspondences
    T_target_source: np.ndarray
    inlier_mask: np.ndarray
    n_iterations: int
    n_degenerate: int
    best_count: int
    success: bool
    seed: int | None
    info: dict = field(default_factory=dict)


@njit(cache=True)
def _triangle_frame(p: np.ndarray, a: int, b: int, c: int, F: np.ndarray, cen: np.ndarray):
    """Centroid ``cen`` and orthonormal frame ``F = [e1 e2 n]`` (columns) of a triangle."""
    for d in range(3):
        cen[d] = (p[a, d] + p[b, d] + p[c, d]) / 3.0
    ux = p[b, 0] - p[a, 0]
    uy = p[b, 1] - p[a, 1]
    uz = p[b, 2] - p[a, 2]
    vx = p[c, 0] - p[a, 0]
    vy = p[c, 1] - p[a, 1]
    vz = p[c, 2] - p[a, 2]
    nx = uy * vz - uz * vy
    ny = uz * vx - ux * vz
    nz = ux * vy - uy * vx
    nn = np.sqrt(nx * nx + ny * ny + nz * nz)
    nx /= nn
    ny /= nn
    nz /= nn
    ex = p[a, 0] - cen[0]
    ey = p[a, 1] - cen[1]
    ez = p[a, 2] - cen[2]
    ee = np.sqrt(ex * ex + ey * ey + ez * ez)
    ex /= ee
    ey /= ee
    ez /= ee
    F[0, 0] = ex
    F[1, 0] = ey
    F[2, 0] = ez
    F[0, 1] = ny * ez - nz * ey
    F[1, 1] = nz * ex - nx * ez
    F[2, 1] = nx * ey - ny * ex
    F[0, 2] = nx
    F[1, 2] = ny
    F[2, 2] = nz


@njit(cache=True)
def _kabsch_triangle(s, m, a: int, b: int, c: int, R: np.ndarray, t: np.ndarray) -> None:
    """Closed-form Kabsch (least squares over SO(3)) for 3 non-collinear point pairs.

    Both centred triangles are planar, so ``H = Σ p qᵀ`` has rank 2 and the optimum is a 2-D
    Procrustes problem between the triangle planes: the best in-plane rotation (normal kept)
    or in-plane reflection (normal flipped, still a proper rotation in 3-D), whichever
    correlates more — the same solution as SVD-based Kabsch with its reflection correction,
    without a LAPACK call.
    """
    Fs = np.empty((3, 3))
    Fm = np.empty((3, 3))
    cs = np.empty(3)
    cm = np.empty(3)
    _triangle_frame(s, a, b, c, Fs, cs)
    _triangle_frame(m, a, b, c, Fm, cm)
    c_rot = 0.0
    s_rot = 0.0
    c_ref = 0.0
    s_ref = 0.0
    for k in (a, b, c):
        px = 0.0
        py = 0.0
        qx = 0.0
        qy = 0.0
        for d in range(3):
            ps = s[k, d] - cs[d]
            qm = m[k, d] - cm[d]
            px += ps * Fs[d, 0]
            py += ps * Fs[d, 1]
            qx += qm * Fm[d, 0]
            qy += qm * Fm[d, 1]
        c_rot += px * qx + py * qy
        s_rot += px * qy - py * qx
        c_ref += px * qx - py * qy
        s_ref += py * qx + px * qy
    r_rot = np.sqrt(c_rot * c_rot + s_rot * s_rot)
    r_ref = np.sqrt(c_ref * c_ref + s_ref * s_ref)
    M = np.zeros((3, 3))
    if r_rot >= r_ref:
        co = c_rot / r_rot if r_rot > 0 else 1.0
        si = s_rot / r_rot if r_rot > 0 else 0.0
        M[0, 0] = co
        M[0, 1] = -si
        M[1, 0] = si
        M[1, 1] = co
        M[2, 2] = 1.0
    else:
        co = c_ref / r_ref
        si = s_ref / r_ref
        M[0, 0] = co
        M[0, 1] = si
        M[1, 0] = si
        M[1, 1] = -co
        M[2, 2] = -1.0
    # R = Fm M Fsᵀ, t = cm − R cs
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for u in range(3):
                for v in range(3):
                    acc += Fm[i, u] * M[u, v] * Fs[j, v]
            R[i, j] = acc
    for i in range(3):
        t[i] = cm[i] - (R[i, 0] * cs[0] + R[i, 1] * cs[1] + R[i, 2] * cs[2])


@njit(cache=True)
def _tri_area(p: np.ndarray, a: int, b: int, c: int) -> float:
    ux = p[b, 0] - p[a, 0]
    uy = p[b, 1] - p[a, 1]
    uz = p[b, 2] - p[a, 2]
    vx = p[c, 0] - p[a, 0]
    vy = p[c, 1] - p[a, 1]
    vz = p[c, 2] - p[a, 2]
    cx = uy * vz - uz * vy
    cy = uz * vx - ux * vz
    cz = ux * vy - uy * vx
    return 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)


@njit(cache=True)
def _count_inliers(s, m, R, t, thr2, stop_at):
    """Inliers of ``(R, t)``; gives up (returning a count ``<= stop_at``) once the count
    can no longer exceed ``stop_at``."""
    n = s.shape[0]
    cnt = 0
    for i in range(n):
        ex = R[0, 0] * s[i, 0] + R[0, 1] * s[i, 1] + R[0, 2] * s[i, 2] + t[0] - m[i, 0]
        ey = R[1, 0] * s[i, 0] + R[1, 1] * s[i, 1] + R[1, 2] * s[i, 2] + t[1] - m[i, 1]
        ez = R[2, 0] * s[i, 0] + R[2, 1] * s[i, 1] + R[2, 2] * s[i, 2] + t[2] - m[i, 2]
        if ex * ex + ey * ey + ez * ez < thr2:
            cnt += 1
        elif cnt + (n - 1 - i) <= stop_at:
            return cnt
    return cnt


@njit(cache=True)
def _score_batch(s, m, samples, thr2, min_area, best_so_far):
    """Inlier count per hypothesis (``-1`` for degenerate samples).

    Counting stops early once a hypothesis cannot beat the best count so far (earlier
    batches included); such a truncated count is below that best, so the earliest
    hypothesis with the maximal count is still identified exactly.
    """
    B = samples.shape[0]
    counts = np.empty(B, dtype=np.int64)
    R = np.empty((3, 3))
    t = np.empty(3)
    best = best_so_far
    for b in range(B):
        a0 = samples[b, 0]
        a1 = samples[b, 1]
        a2 = samples[b, 2]
        if _tri_area(s, a0, a1, a2) < min_area or _tri_area(m, a0, a1, a2) < min_area:
            counts[b] = -1
            continue
        _kabsch_triangle(s, m, a0, a1, a2, R, t)
        c = _count_inliers(s, m, R, t, thr2, best)
        counts[b] = c
        if c > best:
            best = c
    return counts


def sample_triplets(rng: np.random.Generator, n: int, size: int) -> np.ndarray:
    """``size`` uniform samples of 3 distinct indices in ``[0, n)`` → ``(size, 3)`` int64."""
    i0 = rng.integers(0, n, size)
    i1 = rng.integers(0, n - 1, size)
    i1 = i1 + (i1 >= i0)
    i2 = rng.integers(0, n - 2, size)
    lo = np.minimum(i0, i1)
    hi = np.maximum(i0, i1)
    i2 = i2 + (i2 >= lo)
    i2 = i2 + (i2 >= hi)
    return np.stack([i0, i1, i2], axis=1).astype(np.int64)


def _adaptive_iterations(w: np.ndarray, confidence: float, cap: int) -> np.ndarray:
    """``log(1 − conf) / log(1 − w³)`` per inlier ratio ``w`` (capped at ``cap``)."""
    w3 = np.clip(w, 0.0, 1.0) ** 3
    out = np.full(w.shape, float(cap))
    full = w3 >= 1.0
    out[full] = 1.0
    mid = (w3 > 0.0) & ~full
    with np.errstate(divide="ignore"):
        out[mid] = np.log1p(-confidence) / np.log1p(-w3[mid])
    return np.minimum(np.ceil(out), cap)


def _rng_and_seed(
    seed: int | np.random.Generator | None,
) -> tuple[np.random.Generator, int | None]:
    if isinstance(seed, np.random.Generator):
        return seed, None
    return np.random.default_rng(seed), (None if seed is None else int(seed))


def ransac_search(
    src_pts: np.ndarray,
    tgt_pts: np.ndarray,
    corr: Correspondences,
    *,
    threshold: float,
    max_iter: int = 50_000,
    adaptive: bool = False,
    confidence: float = 0.99,
    min_area: float = 1e-6,
    min_inliers: int = 4,
    seed: int | np.random.Generator | None = 0,
) -> RansacResult:
    """RANSAC on correspondences with full diagnostics (see :func:`ransac_correspondences`).

    Parameters
    ----------
    src_pts, tgt_pts, corr, threshold, max_iter, adaptive, confidence, seed
        As in :func:`ransac_correspondences`.
    min_area : float
        Samples whose source or target triangle area is below this (m²) are degenerate.
    min_inliers : int
        Fewest inliers for success (default 4: a 3-point sample alone is always consistent,
        so at least one independent confirmation is required). Inputs with fewer
        correspondences give an empty result.

    Returns
    -------
    RansacResult
    """
    who = "ransac_correspondences"
    thr = _check_epsilon(threshold, who, "threshold")
    if int(max_iter) != max_iter or max_iter < 1:
        raise ConfigError(f"{who}: max_iter must be an integer >= 1 (got {max_iter})")
    if not 0.0 < confidence < 1.0:
        raise ConfigError(f"{who}: confidence must be in (0, 1) (got {confidence})")
    if not (np.isfinite(min_area) and min_area >= 0):
        raise ConfigError(f"{who}: min_area must be >= 0 m² (got {min_area})")
    min_inliers = max(int(min_inliers), 3)
    rng, seed_used = _rng_and_seed(seed)
    s, m = _gather_points(src_pts, tgt_pts, corr, who)
    n = len(corr)
    info: dict = {"threshold": thr, "adaptive": adaptive, "max_iter": int(max_iter)}

    def failure(n_it: int, n_deg: int, best: int, why: str) -> RansacResult:
        logger.debug("RANSAC failed: %s", why)
        info["message"] = why
        return RansacResult(
            Correspondences.empty(),
            np.eye(4),
            np.zeros(n, dtype=bool),
            n_it,
            n_deg,
            best,
            False,
            seed_used,
            info,
        )

    if n < min_inliers:
        return failure(0, 0, 0, f"{n} correspondences < min_inliers={min_inliers}")

    thr2 = thr * thr
    best_count = -1
    best_sample = np.zeros(3, dtype=np.int64)
    n_iter = 0
    n_deg = 0
    target_iter = int(max_iter)
    while n_iter < target_iter:
        size = min(BATCH, target_iter - n_iter)
        samples = sample_triplets(rng, n, size)
        counts = _score_batch(s, m, samples, thr2, float(min_area), best_count)
        if adaptive:
            # Sequential semantics: stop at the first hypothesis after which the running
            # best inlier ratio says enough iterations have been drawn.
            running = np.maximum.accumulate(np.maximum(counts, best_count))
            need = _adaptive_iterations(running / n, confidence, int(max_iter))
            done = n_iter + np.arange(1, size + 1)
            stop = np.flatnonzero(done >= need)
            if stop.size:
                size = int(stop[0]) + 1
                samples = samples[:size]
                counts = counts[:size]
                target_iter = n_iter + size
            info["adaptive_target"] = int(need[size - 1])
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best_count = int(counts[k])
            best_sample = samples[k].copy()
        n_deg += int(np.count_nonzero(counts < 0))
        n_iter += size

    if best_count < min_inliers:
        why = (
            "all samples degenerate"
            if best_count < 0
            else f"best hypothesis has {best_count} inliers < min_inliers={min_inliers}"
        )
        return failure(n_iter, n_deg, max(best_count, 0), why)

    T0 = kabsch(s[best_sample], m[best_sample])
    res = s @ T0[:3, :3].T + T0[:3, 3] - m
    mask = np.einsum("ij,ij->i", res, res) < thr2
    if mask.sum() < min_inliers:  # only on rounding differences at the threshold
        return failure(n_iter, n_deg, best_count, "best hypothesis lost its inliers on refit")
    T = kabsch(s[mask], m[mask])
    logger.debug(
        "RANSAC: %d/%d inliers after %d hypotheses (%d degenerate), threshold %g m",
        int(mask.sum()),
        n,
        n_iter,
        n_deg,
        thr,
    )
    return RansacResult(
        corr.subset(mask), T, mask, n_iter, n_deg, int(mask.sum()), True, seed_used, info
    )


def ransac_correspondences(
    src_pts: np.ndarray,
    tgt_pts: np.ndarray,
    corr: Correspondences,
    *,
    threshold: float,
    max_iter: int = 50_000,
    adaptive: bool = False,
    confidence: float = 0.99,
    seed: int | np.random.Generator | None = 0,
) -> tuple[Correspondences, np.ndarray]:
    """Inliers of the best 3-point RANSAC hypothesis and the transform re-fitted on them.

    Parameters
    ----------
    src_pts : (N, 3) float64
        Source cloud (odometry: scan ``k+1``), metres.
    tgt_pts : (M, 3) float64
        Target cloud (odometry: scan ``k``), metres.
    corr : Correspondences
        Putative matches.
    threshold : float
        Inlier distance θ in metres: ``‖R s + t − m‖ < θ`` (Paper 1 ablation: ``θ = ε = 2·Tr``
        **[interpretation]**).
    max_iter : int
        Hypotheses drawn. Paper 1's "at least 50 000 iterations" → 50 000, fixed, no early exit
        **[interpretation of the garbled wording]**.
    adaptive : bool
        Alternative: stop once ``log(1 − confidence) / log(1 − w³)`` hypotheses have been drawn,
        ``w`` the best inlier ratio so far (never more than ``max_iter``).
    confidence : float
        Success probability of the adaptive rule.
    seed : int, Generator or None
        Sampling seed (same seed → same result).

    Returns
    -------
    inliers : Correspondences
        Inliers of the best hypothesis (input order); empty when fewer than 4 correspondences
        are given, every sample is degenerate, or no hypothesis has 4 inliers.
    T_target_source : (4, 4) float64
        Kabsch re-estimate on all inliers (maps source points onto target points);
        identity when ``inliers`` is empty.

    See Also
    --------
    ransac_search : same, returning iteration counts and the seed.
    """
    r = ransac_search(
        src_pts,
        tgt_pts,
        corr,
        threshold=threshold,
        max_iter=max_iter,
        adaptive=adaptive,
        confidence=confidence,
        seed=seed,
    )
    return r.inliers, r.T_target_source
