"""Correspondences prepared for an estimator: gathered and ordered (§D.3), checked for a
degenerate geometry, and the flagged identity estimate every estimator returns for unusable
ones. Shared by the recursive filters (:mod:`relnav.estimation._recursive`), ``svd`` and ``icp``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from relnav.errors import InputError
from relnav.estimation.base import Estimate, EstimateStatus
from relnav.matching.correspondences import Correspondences

__all__ = [
    "Prepared",
    "check_geometry",
    "flagged_estimate",
    "prepare_correspondences",
    "usable_correspondences",
]

log = logging.getLogger(__name__)


# Correspondence preparation, adaptive factor and degeneracy
# ---------------------------------------------------------------------------------------------


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


def usable_correspondences(
    estimator: Any,
    src_pts: np.ndarray,
    tgt_pts: np.ndarray,
    corr: Correspondences,
    coplanar_tol: float | None,
) -> tuple[Prepared, None] | tuple[None, Estimate]:
    """:func:`prepare_correspondences` then :func:`check_geometry` of both point sets with the
    ``estimator``'s ``min_correspondences`` and ``collinear_tol``.

    Returns ``(prepared, None)``, or ``(None, flagged estimate)`` when the correspondences are
    unusable (too few, non-finite, coincident/collinear/coplanar points).
    """
    name = estimator.name
    prep, problem = prepare_correspondences(src_pts, tgt_pts, corr)
    if prep is None:
        return None, flagged_estimate(name, problem, len(corr))
    geo = {
        "min_count": estimator.min_correspondences,
        "collinear_tol": estimator.collinear_tol,
        "coplanar_tol": coplanar_tol,
    }
    reason = check_geometry(prep.a, **geo) or check_geometry(prep.b, **geo)
    if reason:
        return None, flagged_estimate(name, "degenerate: " + reason, prep.a.shape[0])
    return prep, None


def flagged_estimate(
    name: str, problem: str, n: int, info: dict[str, Any] | None = None
) -> Estimate:
    """The identity with status ``failed`` (``problem`` starts with "failed") or ``degenerate``.

    ``problem`` is ``"<status>: <message>"`` (or the message alone); ``info`` gets the
    estimator ``name``, the message, ``info`` and ``n_correspondences = n``.
    """
    status: EstimateStatus = "failed" if problem.startswith("failed") else "degenerate"
    msg = problem.split(": ", 1)[1] if ": " in problem else problem
    log.debug("%s: %s (%s)", name, status, msg)
    full = {"estimator": name, "message": msg}
    if info:
        full.update(info)
    full["n_correspondences"] = n
    return Estimate(
        T_target_source=np.eye(4),
        covariance=None,
        n_used=0,
        status=status,
        converged=False,
        info=full,
    )
