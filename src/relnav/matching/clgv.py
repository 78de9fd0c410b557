"""Correspondence selection by Local and Global Voting (CLGV; Buch et al., CVPR 2014).

**[interpretation — the original paper is not in the project's corpora]** This is the brief
version of ALGORITHMS §B.4, used as Paper 1's CLGV baseline (Paper 1 §4.5 describes CLGV as
descriptor matching → refinement by geometric consistency and RANSAC → SVD):

1. **Local voting.** For each correspondence ``c = (s_c, m_c)`` take the ``k`` other
   correspondences whose target (model) points are nearest to ``m_c``;
   ``L_c`` = fraction of them consistent with ``c`` under the distance-preservation test of
   GCC, ``| ‖s_c − s_j‖ − ‖m_c − m_j‖ | ≤ ε``.
2. **Global voting.** ``n_hypotheses`` RANSAC hypotheses, each from 3 distinct correspondences
   drawn with probability ∝ ``L_c`` (degenerate triangles skipped), fitted by Kabsch. Every
   hypothesis gives each correspondence a binary vote ``‖R s + t − m‖ < ε``. ``G_c`` = fraction
   of the best ``top_fraction`` of the valid hypotheses (ranked by inlier count) that vote for
   ``c`` (``top_fraction = 1`` counts every hypothesis).
3. **Selection.** Score ``L_c · G_c``; keep the correspondences whose score is at least
   ``keep_ratio`` times the maximum score. The caller estimates ``(R, t)`` by SVD/Kabsch.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from relnav.errors import ConfigError
from relnav.matching.correspondences import Correspondences
from relnav.matching.gcc import _check_epsilon, _gather_points
from relnav.matching.ransac import _kabsch_triangle, _rng_and_seed, _tri_area

__all__ = ["ClgvResult", "clgv_select", "clgv_vote"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ClgvResult:
    """Outcome of :func:`clgv_vote`.

    Attributes
    ----------
    selected : Correspondences
        Kept correspondences, input order (empty on failure).
    local_score, global_score, score : (n,) float64
        ``L_c``, ``G_c`` and ``L_c · G_c`` per input correspondence.
    n_valid_hypotheses : int
        Non-degenerate hypotheses.
    seed : int or None
        Sampling seed (``None`` when a Generator was passed).
    info : dict
        Parameters and failure message.
    """

    selected: Correspondences
    local_score: np.ndarray
    global_score: np.ndarray
    score: np.ndarray
    n_valid_hypotheses: int
    seed: int | None
    info: dict = field(default_factory=dict)


@njit(cache=True)
def _local_votes(s, m, nbr, eps):
    n, k = nbr.shape
    out = np.zeros(n)
    for c in range(n):
        good = 0
        valid = 0
        for a in range(k):
            j = nbr[c, a]
            if j < 0:
                continue
            valid += 1
            dx = s[c, 0] - s[j, 0]
            dy = s[c, 1] - s[j, 1]
            dz = s[c, 2] - s[j, 2]
            ds = np.sqrt(dx * dx + dy * dy + dz * dz)
            dx = m[c, 0] - m[j, 0]
            dy = m[c, 1] - m[j, 1]
            dz = m[c, 2] - m[j, 2]
            dm = np.sqrt(dx * dx + dy * dy + dz * dz)
            if abs(ds - dm) <= eps:
                good += 1
        out[c] = good / valid if valid > 0 else 0.0
    return out


@njit(cache=True)
def _global_votes(s, m, samples, thr2, min_area):
    """Inlier mask per hypothesis ``(H, n)`` and counts ``(H,)`` (``-1`` when degenerate)."""
    H = samples.shape[0]
    n = s.shape[0]
    votes = np.zeros((H, n), dtype=np.bool_)
    counts = np.full(H, -1, dtype=np.int64)
    R = np.empty((3, 3))
    t = np.empty(3)
    for h in range(H):
        a0 = samples[h, 0]
        a1 = samples[h, 1]
        a2 = samples[h, 2]
        if _tri_area(s, a0, a1, a2) < min_area or _tri_area(m, a0, a1, a2) < min_area:
            continue
        _kabsch_triangle(s, m, a0, a1, a2, R, t)
        cnt = 0
        for i in range(n):
            ex = R[0, 0] * s[i, 0] + R[0, 1] * s[i, 1] + R[0, 2] * s[i, 2] + t[0] - m[i, 0]
            ey = R[1, 0] * s[i, 0] + R[1, 1] * s[i, 1] + R[1, 2] * s[i, 2] + t[1] - m[i, 1]
            ez = R[2, 0] * s[i, 0] + R[2, 1] * s[i, 1] + R[2, 2] * s[i, 2] + t[2] - m[i, 2]
            if ex * ex + ey * ey + ez * ez < thr2:
                votes[h, i] = True
                cnt += 1
        counts[h] = cnt
    return votes, counts


def _weighted_triplets(rng: np.random.Generator, p: np.ndarray, size: int) -> np.ndarray:
    """``size`` draws of 3 distinct indices, successive sampling ∝ ``p`` (Gumbel top-3)."""
    with np.errstate(divide="ignore"):
        logp = np.log(p)  # -inf for zero weights: never drawn while 3 positive weights exist
    out = np.empty((size, 3), dtype=np.int64)
    chunk = max(1, (8 * 1024 * 1024) // max(p.size, 1))
    for start in range(0, size, chunk):
        b = min(chunk, size - start)
        keys = logp[None, :] + rng.gumbel(size=(b, p.size))
        top = np.argpartition(-keys, 2, axis=1)[:, :3]
        out[start : start + b] = top
    return out


def clgv_vote(
    src_pts: np.ndarray,
    tgt_pts: np.ndarray,
    corr: Correspondences,
    *,
    epsilon: float,
    k: int = 10,
    n_hypotheses: int = 1000,
    top_fraction: float = 0.1,
    keep_ratio: float = 0.5,
    min_area: float = 1e-6,
    seed: int | np.random.Generator | None = 0,
) -> ClgvResult:
    """CLGV scores and selection with diagnostics (see :func:`clgv_select`)."""
    who = "clgv_select"
    eps = _check_epsilon(epsilon, who)
    if int(k) != k or k < 1:
        raise ConfigError(f"{who}: k must be an integer >= 1 (got {k})")
    if int(n_hypotheses) != n_hypotheses or n_hypotheses < 1:
        raise ConfigError(f"{who}: n_hypotheses must be an integer >= 1 (got {n_hypotheses})")
    if not 0.0 < top_fraction <= 1.0:
        raise ConfigError(f"{who}: top_fraction must be in (0, 1] (got {top_fraction})")
    if not 0.0 < keep_ratio <= 1.0:
        raise ConfigError(f"{who}: keep_ratio must be in (0, 1] (got {keep_ratio})")
    rng, seed_used = _rng_and_seed(seed)
    s, m = _gather_points(src_pts, tgt_pts, corr, who)
    n = len(corr)
    info: dict = {
        "epsilon": eps,
        "k": int(k),
        "n_hypotheses": int(n_hypotheses),
        "top_fraction": top_fraction,
        "keep_ratio": keep_ratio,
    }
    zeros = np.zeros(n)

    def failure(L: np.ndarray, G: np.ndarray, n_valid: int, why: str) -> ClgvResult:
        logger.debug("CLGV failed: %s", why)
        info["message"] = why
        return ClgvResult(Correspondences.empty(), L, G, L * G, n_valid, seed_used, info)

    if n < 4:
        return failure(zeros, zeros, 0, f"{n} correspondences < 4")

    # 1. local voting over the k nearest correspondences in the target (model) cloud
    kk = min(int(k), n - 1)
    _, nbr = cKDTree(m).query(m, k=kk + 1)
    nbr = np.asarray(nbr, dtype=np.int64).reshape(n, kk + 1)
    # drop self (it is not necessarily in column 0 when target points repeat)
    own = nbr == np.arange(n)[:, None]
    has_self = own.any(axis=1)
    own[~has_self, -1] = True  # self missing (ties): drop the farthest instead
    nbr = nbr[~own].reshape(n, kk)
    L = _local_votes(s, m, nbr, eps)
    if np.count_nonzero(L > 0) < 3:
        return failure(L, zeros, 0, "fewer than 3 locally consistent correspondences")

    # 2. global voting: RANSAC with samples drawn ∝ L
    samples = _weighted_triplets(rng, L / L.sum(), int(n_hypotheses))
    votes, counts = _global_votes(s, m, samples, eps * eps, float(min_area))
    valid = np.flatnonzero(counts >= 0)
    if valid.size == 0:
        return failure(L, zeros, 0, "all hypotheses degenerate")
    n_top = max(1, int(np.ceil(top_fraction * valid.size)))
    order = valid[np.argsort(-counts[valid], kind="stable")]
    G = votes[order[:n_top]].mean(axis=0).astype(np.float64)

    # 3. selection
    score = L * G
    smax = float(score.max())
    if not smax > 0:
        return failure(L, G, int(valid.size), "no correspondence has a positive score")
    keep = score >= keep_ratio * smax
    if np.count_nonzero(keep) < 3:
        return failure(L, G, int(valid.size), "fewer than 3 correspondences selected")
    logger.debug("CLGV: kept %d/%d (max score %.3f)", int(keep.sum()), n, smax)
    return ClgvResult(corr.subset(keep), L, G, score, int(valid.size), seed_used, info)


def clgv_select(
    src_pts: np.ndarray,
    tgt_pts: np.ndarray,
    corr: Correspondences,
    *,
    epsilon: float,
    k: int = 10,
    n_hypotheses: int = 1000,
    keep_ratio: float = 0.5,
    top_fraction: float = 0.1,
    seed: int | np.random.Generator | None = 0,
) -> Correspondences:
    """Correspondences kept by local and global voting **[interpretation]** (module docstring).

    Parameters
    ----------
    src_pts : (N, 3) float64
        Source cloud (odometry: scan ``k+1``), metres.
    tgt_pts : (M, 3) float64
        Target cloud (odometry: scan ``k``), metres.
    corr : Correspondences
        Putative matches.
    epsilon : float
        Consistency tolerance and inlier distance in metres (Paper 1 setting: ``2·Tr``).
    k : int
        Neighbouring correspondences (in the target cloud) used for local voting.
    n_hypotheses : int
        RANSAC hypotheses of the global vote.
    keep_ratio : float
        Keep scores ``≥ keep_ratio · max score``.
    top_fraction : float
        Fraction of the valid hypotheses (best inlier counts) whose votes form ``G_c``.
    seed : int, Generator or None
        Sampling seed (same seed → same result).

    Returns
    -------
    Correspondences
        The selected correspondences (input order); empty when fewer than 4 are given or fewer
        than 3 survive.

    References
    ----------
    A. G. Buch, Y. Yang, N. Krüger, H. G. Petersen, "In search of inliers: 3D correspondence by
    local and global voting", CVPR 2014, doi:10.1109/CVPR.2014.266.
    """
    return clgv_vote(
        src_pts,
        tgt_pts,
        corr,
        epsilon=epsilon,
        k=k,
        n_hypotheses=n_hypotheses,
        top_fraction=top_fraction,
        keep_ratio=keep_ratio,
        seed=seed,
    ).selected
