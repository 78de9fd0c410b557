"""Surface normals by neighbourhood PCA, oriented towards a viewpoint.

The normal of point ``p`` is the eigenvector of the smallest eigenvalue of the covariance of its
neighbours (radius or k-NN), flipped so that ``n · (viewpoint − p) ≥ 0`` (sensor at the origin
of the sensor frame by default, as PCL's ``flipNormalTowardsViewpoint``).
"""

from __future__ import annotations

import numpy as np

from relnav.geometry.neighbors import build_tree

__all__ = ["estimate_normals", "local_covariances"]


def local_covariances(
    points: np.ndarray,
    *,
    radius: float | None = None,
    k: int | None = None,
    min_neighbors: int = 3,
) -> tuple[np.ndarray, np.ndarray]:
    """Covariance matrices of each point's neighbourhood.

    Parameters
    ----------
    points : (N, 3) float64
    radius : float, optional
        Neighbourhood radius (m). Exactly one of ``radius`` / ``k`` must be given.
    k : int, optional
        Number of nearest neighbours (including the point itself).
    min_neighbors : int
        Neighbourhoods with fewer points get a NaN covariance.

    Returns
    -------
    cov : (N, 3, 3) float64
    counts : (N,) int64
        Neighbour counts.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = P.shape[0]
    cov = np.full((n, 3, 3), np.nan)
    counts = np.zeros(n, dtype=np.int64)
    if n == 0:
        return cov, counts
    if (radius is None) == (k is None):
        raise ValueError("give exactly one of radius or k")
    tree = build_tree(P)
    if k is not None:
        kk = int(min(k, n))
        _, idx = tree.query(P, k=kk)
        idx = idx.reshape(n, kk)
        nb = P[idx]  # (n, k, 3)
        mu = nb.mean(axis=1, keepdims=True)
        d = nb - mu
        cov = np.einsum("nki,nkj->nij", d, d) / kk
        counts[:] = kk
        if kk < min_neighbors:
            cov[:] = np.nan
        return cov, counts
    lists = tree.query_ball_point(P, r=radius)
    lens = np.fromiter((len(li) for li in lists), dtype=np.int64, count=n)
    counts[:] = lens
    flat = np.fromiter((j for li in lists for j in li), dtype=np.int64, count=int(lens.sum()))
    owner = np.repeat(np.arange(n), lens)
    q = P[flat]
    s1 = np.zeros((n, 3))
    np.add.at(s1, owner, q)
    s2 = np.zeros((n, 3, 3))
    outer = q[:, :, None] * q[:, None, :]
    for a in range(3):
        for b in range(a, 3):
            s2[:, a, b] = np.bincount(owner, weights=outer[:, a, b], minlength=n)
            s2[:, b, a] = s2[:, a, b]
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = s1 / lens[:, None]
        cov = s2 / lens[:, None, None] - mu[:, :, None] * mu[:, None, :]
    cov[lens < min_neighbors] = np.nan
    return cov, counts


def estimate_normals(
    points: np.ndarray,
    *,
    radius: float | None = None,
    k: int | None = None,
    viewpoint: np.ndarray | None = None,
) -> np.ndarray:
    """Unit normals ``(N, 3)`` by PCA, oriented towards ``viewpoint`` (default origin).

    Points with fewer than 3 neighbours get NaN normals. With neither ``radius`` nor ``k``
    given, ``k = 10`` is used.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if radius is None and k is None:
        k = 10
    cov, _ = local_covariances(P, radius=radius, k=k)
    normals = np.full(P.shape, np.nan)
    ok = np.isfinite(cov).all(axis=(1, 2))
    if ok.any():
        _, vecs = np.linalg.eigh(cov[ok])
        normals[ok] = vecs[:, :, 0]
    vp = np.zeros(3) if viewpoint is None else np.asarray(viewpoint, dtype=np.float64)
    flip = np.einsum("ij,ij->i", normals, vp - P) < 0
    normals[flip] *= -1.0
    return normals
