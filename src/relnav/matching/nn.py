"""τ-gated exact nearest-neighbour matching of local descriptors (ALGORITHMS §B.1, Paper 1 eq. 5).

Descriptors are scaled to unit L2 norm (by default), so the Euclidean distance is
``d = sqrt(2 − 2 a·b)`` and the nearest neighbour of a row is the row with the largest dot
product; unscaled (``normalize=False``), the row with the largest ``2 a·b − |b|²``. The dot products
are one float32 matrix product per chunk of source rows (exact, and faster than KD-trees at
33–352 dimensions); the distance of each chosen pair is then recomputed in float64 so that
near-zero distances are not swamped by float32 cancellation.
"""

from __future__ import annotations

import logging

import numpy as np

from relnav.errors import ConfigError, InputError
from relnav.matching.correspondences import Correspondences

__all__ = ["match_descriptors", "normalize_descriptors"]

logger = logging.getLogger(__name__)

_DEFAULT_CHUNK_BYTES = 64 * 1024 * 1024


def normalize_descriptors(F: np.ndarray) -> np.ndarray:
    """Scale every descriptor row to unit L2 norm.

    Parameters
    ----------
    F : (K, D) array_like
        Descriptors (any float dtype). Rows containing a NaN/inf are invalid.

    Returns
    -------
    (K, D) float32
        Unit-norm rows. Invalid rows, and rows whose norm is zero (no direction to keep),
        are all-NaN so that matching skips them.

    Raises
    ------
    InputError
        ``F`` is not two-dimensional.
    """
    F = np.asarray(F)
    if F.ndim != 2:
        raise InputError(f"descriptors must be a (K, D) array, got shape {F.shape}")
    if F.dtype not in (np.float32, np.float64):
        F = F.astype(np.float64)
    if F.shape[1] == 0:
        return np.full(F.shape, np.nan, dtype=np.float32)
    valid = np.isfinite(F).all(axis=1)
    with np.errstate(invalid="ignore", over="ignore"):
        sq = np.einsum("ij,ij->i", F, F, dtype=np.float64)  # squared norms in float64
        ok = valid & (sq > 0)
        finite = np.isfinite(sq)
        scale = np.zeros(F.shape[0])
        sel = ok & finite
        scale[sel] = 1.0 / np.sqrt(sq[sel])
        out = (F * scale[:, None]).astype(np.float32, copy=False)
    over = ok & ~finite  # finite rows whose squared norm overflows float64
    if over.any():
        G = F[over].astype(np.float64)
        G /= np.abs(G).max(axis=1, keepdims=True)
        out[over] = (G / np.linalg.norm(G, axis=1, keepdims=True)).astype(np.float32)
    out[~ok] = np.nan
    return out


def _raw_descriptors(F: np.ndarray) -> np.ndarray:
    """Descriptors as float32 rows, unscaled; rows holding a NaN/inf all-NaN (skipped)."""
    F = np.asarray(F)
    if F.ndim != 2:
        raise InputError(f"descriptors must be a (K, D) array, got shape {F.shape}")
    out = F.astype(np.float32)
    out[~np.isfinite(out).all(axis=1)] = np.nan
    return out


def _check_keypoints(kp: np.ndarray | None, n_rows: int, name: str) -> np.ndarray:
    if kp is None:
        return np.arange(n_rows, dtype=np.int64)
    arr = np.asarray(kp)
    if arr.ndim != 1 or arr.shape[0] != n_rows:
        raise InputError(
            f"{name} must be a ({n_rows},) index array (one per descriptor row), "
            f"got shape {arr.shape}"
        )
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise InputError(f"{name} must hold integer point indices, got dtype {arr.dtype}")
    if arr.size and arr.min() < 0:
        raise InputError(f"{name} holds negative point indices")
    return arr.astype(np.int64, copy=False)


def match_descriptors(
    src_desc: np.ndarray,
    tgt_desc: np.ndarray,
    *,
    tau: float = 1.0,
    mutual: bool = False,
    src_keypoints: np.ndarray | None = None,
    tgt_keypoints: np.ndarray | None = None,
    chunk_bytes: int = _DEFAULT_CHUNK_BYTES,
    normalize: bool = True,
) -> Correspondences:
    """Exact nearest neighbour of every valid source descriptor among the target descriptors.

    Each valid source row ``i`` is matched to ``j = argmin_n ‖f_i − g_n‖₂`` over the valid
    target rows (ties → lowest target row), after unit-L2 normalisation of both sets (unless
    ``normalize=False``), and the
    pair is accepted when ``‖f_i − g_j‖ < tau``. One correspondence per source descriptor
    (Paper 1 eq. 5; no ratio test).

    Parameters
    ----------
    src_desc : (Ks, D) array_like
        Source descriptors (odometry: current scan ``k+1``). NaN rows are skipped.
    tgt_desc : (Kt, D) array_like
        Target descriptors (odometry: previous scan ``k``). NaN rows are skipped.
    tau : float
        Acceptance gate on the distance between unit-norm descriptors (Paper 1: 1.0, a loose
        gate: ``d < 1 ⇔ cosine > 0.5``). ``inf`` disables it.
    mutual : bool
        Also require ``i`` to be the nearest source descriptor of ``j`` (not in Paper 1).
    src_keypoints, tgt_keypoints : (Ks,) / (Kt,) int, optional
        Point index of each descriptor row; the identity when ``None``.
    chunk_bytes : int
        Memory budget of one block of the ``(chunk, Kt)`` float32 similarity matrix.
    normalize : bool
        Scale both sets to unit L2 norm first (default; relnav's reading of paper 1's "τ is set
        to 1 to reduce the dependency between the threshold value and the metric used"). With
        ``False`` the nearest neighbour and ``tau`` apply to the raw descriptors' L2 distance
        (the literal reading: τ = 1 in each descriptor's own units).

    Returns
    -------
    Correspondences
        ``src_idx``/``tgt_idx`` are point indices (through the keypoint maps), ``distance`` the
        float64 descriptor distance; ordered by source row.

    Raises
    ------
    InputError
        Non-2-D descriptors, mismatched dimensions, or keypoint maps of the wrong length.
    ConfigError
        ``tau`` is NaN or not positive.
    """
    A, B = (
        (normalize_descriptors(src_desc), normalize_descriptors(tgt_desc))
        if normalize
        else (_raw_descriptors(src_desc), _raw_descriptors(tgt_desc))
    )
    if A.shape[1] != B.shape[1]:
        raise InputError(
            f"descriptor dimensions differ: source D={A.shape[1]}, target D={B.shape[1]}"
        )
    tau = float(tau)
    if not tau > 0:
        raise ConfigError(f"tau must be > 0 (got {tau})")
    if chunk_bytes <= 0:
        raise ConfigError(f"chunk_bytes must be > 0 (got {chunk_bytes})")
    src_kp = _check_keypoints(src_keypoints, A.shape[0], "src_keypoints")
    tgt_kp = _check_keypoints(tgt_keypoints, B.shape[0], "tgt_keypoints")

    src_rows = np.flatnonzero(np.isfinite(A[:, 0])) if A.shape[1] else np.zeros(0, np.int64)
    tgt_rows = np.flatnonzero(np.isfinite(B[:, 0])) if B.shape[1] else np.zeros(0, np.int64)
    if src_rows.size == 0 or tgt_rows.size == 0:
        logger.debug(
            "match_descriptors: no valid descriptors (source %d, target %d)",
            src_rows.size,
            tgt_rows.size,
        )
        return Correspondences.empty()
    Av = np.ascontiguousarray(A[src_rows])
    Bv = np.ascontiguousarray(B[tgt_rows])
    ns, nt = Av.shape[0], Bv.shape[0]

    best_t = np.empty(ns, dtype=np.int64)  # per source row: best valid-target position
    col_best = np.full(nt, -np.inf, dtype=np.float32)  # per target: best similarity
    col_arg = np.zeros(nt, dtype=np.int64)  # per target: best valid-source position
    chunk = max(1, int(chunk_bytes // (4 * nt)))
    BvT = Bv.T
    # unit rows: the largest dot product is the nearest; raw rows: the largest 2a·b − |b|²
    # (for a source row) and 2a·b − |a|² (for a target column)
    aa = np.einsum("ij,ij->i", Av, Av) if not normalize and mutual else None
    bb = np.einsum("ij,ij->i", Bv, Bv) if not normalize else None
    for start in range(0, ns, chunk):
        S = Av[start : start + chunk] @ BvT  # (c, nt) cosine similarities (unit rows)
        best_t[start : start + chunk] = np.argmax(S if normalize else 2 * S - bb, axis=1)
        if mutual:
            if not normalize:
                S = 2 * S - aa[start : start + chunk, None]
            arg = np.argmax(S, axis=0)
            val = S[arg, np.arange(nt)]
            better = val > col_best  # strict: earlier (lower) source rows win ties
            col_best[better] = val[better]
            col_arg[better] = arg[better] + start

    # Exact float64 distance of the chosen pairs.
    diff = Av.astype(np.float64) - Bv[best_t].astype(np.float64)
    dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
    keep = dist < tau
    if mutual:
        keep &= col_arg[best_t] == np.arange(ns)
    sel = np.flatnonzero(keep)
    logger.debug(
        "match_descriptors: %d/%d valid source rows matched (tau=%g, mutual=%s)",
        sel.size,
        ns,
        tau,
        mutual,
    )
    return Correspondences(src_kp[src_rows[sel]], tgt_kp[tgt_rows[best_t[sel]]], dist[sel])
