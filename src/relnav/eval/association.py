"""One-to-one nearest-timestamp association of two trajectories (TUM ``associate.py`` / evo
style), with a numba greedy pairing kernel.
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit

from relnav.errors import InputError
from relnav.eval.pose_errors import _as_times

__all__ = [
    "associate",
]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------------
# association
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def _greedy_pairs(ci: np.ndarray, cj: np.ndarray, n_i: int, n_j: int) -> np.ndarray:
    """Accept candidate pairs in the given order when both ends are still free."""
    used_i = np.zeros(n_i, dtype=np.bool_)
    used_j = np.zeros(n_j, dtype=np.bool_)
    keep = np.zeros(ci.shape[0], dtype=np.bool_)
    for k in range(ci.shape[0]):
        i = ci[k]
        j = cj[k]
        if not used_i[i] and not used_j[j]:
            used_i[i] = True
            used_j[j] = True
            keep[k] = True
    return keep


def associate(
    t_est: np.ndarray,
    t_gt: np.ndarray,
    *,
    max_diff: float = 0.01,
    offset: float = 0.0,
    n_candidates: int = 4,
) -> tuple[np.ndarray, np.ndarray]:
    """Associate estimated and ground-truth timestamps one-to-one by nearest time.

    Candidate pairs ``(i, j)`` with ``|t_est[i] + offset − t_gt[j]| <= max_diff`` are accepted
    greedily in order of increasing time difference, each timestamp being used at most once
    (the TUM benchmark's ``associate.py``). Neither input needs to be sorted.

    Parameters
    ----------
    t_est : (N,) float64
        Timestamps of the estimated poses, seconds.
    t_gt : (M,) float64
        Timestamps of the ground-truth poses, seconds.
    max_diff : float
        Largest accepted time difference, seconds (evo's default 0.01).
    offset : float
        Constant added to ``t_est`` before matching, seconds (evo ``--t_offset``, TUM
        ``--offset``).
    n_candidates : int
        Ground-truth neighbours considered on each side of every estimated stamp
        **[interpretation]**: bounds the work to ``O(N log M)``; it only matters when many
        ground-truth stamps fall inside one ``max_diff`` window.

    Returns
    -------
    idx_est, idx_gt : (K,) int64
        Matched indices into ``t_est`` and ``t_gt``, sorted by ``idx_est``.

    Raises
    ------
    InputError
        Non-1-D or non-finite timestamps, negative or non-finite ``max_diff``/``offset``.
    """
    te = _as_times("t_est", t_est) + float(offset)
    tg = _as_times("t_gt", t_gt)
    if not (np.isfinite(max_diff) and max_diff >= 0):
        raise InputError(f"max_diff must be a finite number >= 0 s, got {max_diff}")
    if not np.isfinite(offset):
        raise InputError(f"offset must be finite, got {offset}")
    if n_candidates < 1:
        raise InputError(f"n_candidates must be >= 1, got {n_candidates}")
    empty = np.zeros(0, dtype=np.int64)
    if te.size == 0 or tg.size == 0:
        return empty, empty.copy()
    order = np.argsort(tg, kind="stable")
    tg_sorted = tg[order]
    pos = np.searchsorted(tg_sorted, te)
    shifts = np.arange(-n_candidates, n_candidates)
    ci = np.repeat(np.arange(te.size), shifts.size)
    cj = (pos[:, None] + shifts[None, :]).ravel()
    ok = (cj >= 0) & (cj < tg.size)
    ci, cj = ci[ok], cj[ok]
    diff = np.abs(te[ci] - tg_sorted[cj])
    ok = diff <= max_diff
    ci, cj, diff = ci[ok], cj[ok], diff[ok]
    # smallest |Δt| first; ties broken by estimate index, then ground-truth index
    srt = np.lexsort((cj, ci, diff))
    ci, cj = ci[srt].astype(np.int64), cj[srt].astype(np.int64)
    keep = _greedy_pairs(ci, cj, te.size, tg.size)
    idx_est = ci[keep]
    idx_gt = order[cj[keep]].astype(np.int64)
    srt = np.argsort(idx_est, kind="stable")
    return idx_est[srt], idx_gt[srt]
