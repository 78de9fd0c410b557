"""Hidden point removal (Katz, Tal, Basri 2007): which points of a cloud a viewpoint sees.

Used by paper 1 to turn complete target models into self-occluded, viewpoint-dependent clouds.

References
----------
S. Katz, A. Tal, R. Basri, "Direct visibility of point sets", ACM TOG 26(3), 2007.
doi:10.1145/1276377.1276407
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from relnav.errors import InputError

__all__ = ["hidden_point_removal", "spherical_flip"]

log = logging.getLogger(__name__)


def spherical_flip(points: np.ndarray, radius: float) -> np.ndarray:
    """Spherical flipping ``p̂ = p + 2 (R − ‖p‖) p / ‖p‖`` about the origin.

    Parameters
    ----------
    points : (N, 3) float64
        Points relative to the viewpoint (no zero vectors), metres.
    radius : float
        Flipping radius ``R > max ‖p‖``, metres.
    """
    n = np.linalg.norm(points, axis=1, keepdims=True)
    return points + 2.0 * (radius - n) * points / n


def hidden_point_removal(
    points: np.ndarray,
    viewpoint: np.ndarray,
    radius_factor: float = 100.0,
    *,
    gamma: float | None = None,
) -> np.ndarray:
    """Indices of the points visible from ``viewpoint`` (Katz–Tal–Basri HPR).

    1. Translate so the viewpoint ``C`` is the origin (points at ``C`` are dropped).
    2. Spherically flip with radius ``R = radius_factor · max‖p − C‖``.
    3. Convex hull (qhull) of the flipped points plus the origin; the points whose flipped
       images are hull vertices are visible.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, any frame, metres.
    viewpoint : (3,) float64
        Viewpoint in the same frame, metres.
    radius_factor : float
        ``R / max‖p − C‖ = 10**γ`` (> 1). Larger keeps more points (also some that are
        occluded); smaller removes more (sparser, more aggressive). Default 100 (``γ = 2``)
        **[interpretation]**: the papers give no value; common implementations use
        ``γ ∈ [1, 3]`` and Open3D users ``R ≈ 100 × diameter``.
    gamma : float, optional
        Alternative to ``radius_factor``: ``radius_factor = 10**gamma``.

    Returns
    -------
    (M,) int64
        Sorted indices into ``points`` of the visible points.

    Raises
    ------
    InputError
        Bad shapes, non-finite values or ``radius_factor <= 1``.

    Notes
    -----
    Fewer than 4 usable points are all returned as visible (no hull to test against). A
    degenerate (e.g. coplanar) input is retried with qhull's joggle option ``QJ``.
    """
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"hidden_point_removal: points must be (N, 3), got {P.shape}")
    C = np.asarray(viewpoint, dtype=np.float64).reshape(-1)
    if C.shape != (3,):
        raise InputError(f"hidden_point_removal: viewpoint must be (3,), got {C.shape}")
    if gamma is not None:
        radius_factor = 10.0 ** float(gamma)
    if not (np.isfinite(radius_factor) and radius_factor > 1.0):
        raise InputError(f"hidden_point_removal: radius_factor must be > 1, got {radius_factor}")
    if not (np.isfinite(P).all() and np.isfinite(C).all()):
        raise InputError("hidden_point_removal: non-finite points or viewpoint")
    Q = P - C
    norms = np.linalg.norm(Q, axis=1)
    keep = np.flatnonzero(norms > 0.0)
    if keep.size < 4:
        return keep.astype(np.int64)
    Q = Q[keep]
    R = float(radius_factor) * float(norms[keep].max())
    flipped = np.vstack([spherical_flip(Q, R), np.zeros((1, 3))])
    try:
        hull = ConvexHull(flipped)
    except QhullError:
        log.debug("HPR: degenerate input, retrying qhull with joggle (QJ)")
        try:
            hull = ConvexHull(flipped, qhull_options="QJ")
        except QhullError:
            return keep.astype(np.int64)
    v = hull.vertices
    v = v[v < Q.shape[0]]  # drop the viewpoint itself
    return np.sort(keep[v]).astype(np.int64)
