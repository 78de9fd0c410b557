"""Input side of Paper 1's estimators: checked, ordered correspondences (:class:`Prepared`), the
degeneracy test of their geometry and the adaptive factor ``M_u`` (ALGORITHMS §D.1–D.5).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Literal

import numpy as np

from relnav.errors import ConfigError, InputError
from relnav.matching.correspondences import Correspondences

__all__ = [
    "AdaptiveMode",
    "Prepared",
    "adaptive_factors",
    "check_geometry",
    "prepare_correspondences",
]

log = logging.getLogger(__name__)


AdaptiveMode = Literal["per_match", "sum", "none"]


@dataclass(frozen=True)
class Prepared:
    """Correspondences in processing order (ascending descriptor distance, ties broken by index).

    Attributes
    ----------
    a : (n, 3) float64
        Target points (``P_k``) — they build ``H_u``.
    b : (n, 3) float64
        Source points (``P_{k+1}``) — the measurements ``ψ_u``.
    d : (n,) float64
        Descriptor distances.
    order : (n,) int64
        Positions in the input ``Correspondences`` in processing order.
    """

    a: np.ndarray
    b: np.ndarray
    d: np.ndarray
    order: np.ndarray


def _as_points(P: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(P, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"{name} must be an (N, 3) array, got shape {arr.shape}")
    return arr


def prepare_correspondences(
    src_pts: np.ndarray, tgt_pts: np.ndarray, corr: Correspondences
) -> tuple[Prepared | None, str]:
    """Gather and order the correspondences (§D.3).

    Order: ascending descriptor distance; equal distances are ordered by ``tgt_idx`` then
    ``src_idx``, so the result does not depend on the input order (deterministic under
    shuffling).

    Returns
    -------
    prepared : Prepared or None
        None when the data are unusable.
    problem : str
        ``""`` on success, ``"failed: ..."`` (non-finite values) or ``"degenerate: ..."``.

    Raises
    ------
    InputError
        Wrong array shapes or correspondence indices out of range (caller errors, not data
        problems).
    """
    src = _as_points(src_pts, "src_pts")
    tgt = _as_points(tgt_pts, "tgt_pts")
    if not isinstance(corr, Correspondences):
        raise InputError(f"corr must be a Correspondences, got {type(corr).__name__}")
    n = len(corr)
    if n == 0:
        return None, "degenerate: no correspondences"
    si, ti = corr.src_idx, corr.tgt_idx
    if si.min() < 0 or si.max() >= src.shape[0]:
        raise InputError(f"corr.src_idx out of range for {src.shape[0]} source points")
    if ti.min() < 0 or ti.max() >= tgt.shape[0]:
        raise InputError(f"corr.tgt_idx out of range for {tgt.shape[0]} target points")
    d = corr.distance
    if not np.isfinite(d).all():
        return None, "failed: non-finite descriptor distance"
    order = np.lexsort((si, ti, d)).astype(np.int64)
    a = np.ascontiguousarray(tgt[ti[order]])
    b = np.ascontiguousarray(src[si[order]])
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        return None, "failed: non-finite point coordinates in the correspondences"
    return Prepared(a=a, b=b, d=np.ascontiguousarray(d[order]), order=order), ""


def check_geometry(
    points: np.ndarray,
    *,
    min_count: int = 4,
    collinear_tol: float = 1e-3,
    coplanar_tol: float | None = 1e-3,
) -> str:
    """Degeneracy test of a set of used points (§D.3).

    With ``σ1 ≥ σ2 ≥ σ3`` the singular values of the centred points: degenerate when
    fewer than ``min_count`` points, ``σ1 ≈ 0`` (all points coincide), ``σ2/σ1 < collinear_tol``
    (collinear) or ``σ3/σ1 < coplanar_tol`` (coplanar; skipped when ``coplanar_tol`` is None).
    Coplanar points leave the 12-state affine model unobservable in the out-of-plane column of
    ``R`` (§D.3), so they are degenerate for the filters; Kabsch only needs non-collinear points.

    Returns
    -------
    str
        ``""`` when fine, otherwise a short reason.
    """
    n = points.shape[0]
    if n < min_count:
        return f"{n} correspondences < {min_count} needed"
    c = points - points.mean(axis=0)
    # singular values of the centred points = sqrt of the eigenvalues of cᵀc (3x3, cheap)
    s = np.sqrt(np.clip(np.linalg.eigvalsh(c.T @ c)[::-1], 0.0, None))
    scale = float(np.abs(points).max()) + 1.0
    if s[0] <= 1e-12 * scale:
        return "all correspondence points coincide"
    if s[1] / s[0] < collinear_tol:
        return f"correspondence points collinear (σ2/σ1 = {s[1] / s[0]:.2e})"
    if coplanar_tol is not None and s[2] / s[0] < coplanar_tol:
        return f"correspondence points coplanar (σ3/σ1 = {s[2] / s[0]:.2e})"
    return ""


def adaptive_factors(
    d: np.ndarray, mode: AdaptiveMode, *, scale: float = 10.0, m_min: float = 1e-3
) -> np.ndarray:
    """Adaptive factor ``M_u`` per correspondence (eq. 11, §D.3).

    ``per_match`` (default, **[interpretation]**): ``M_u = scale·d_u``; ``sum`` (eq. 11 read
    literally): ``M = scale·Σ d_u`` for every match; ``none``: ``M = 1``. The first two are
    clamped to ``≥ m_min``.
    """
    d = np.asarray(d, dtype=np.float64)
    if mode == "per_match":
        m = scale * d
    elif mode == "sum":
        m = np.full(d.shape, scale * float(d.sum()))
    elif mode == "none":
        return np.ones(d.shape)
    else:  # pragma: no cover - validated in the constructor
        raise ConfigError(f"adaptive must be 'per_match', 'sum' or 'none', got {mode!r}")
    return np.maximum(m, m_min)
