"""Neighbourhood helpers on top of :class:`scipy.spatial.cKDTree`: resolution, radius/k-NN."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["build_tree", "knn", "mean_resolution", "radius_neighbors"]


def build_tree(points: np.ndarray) -> cKDTree:
    """KD-tree of ``(N, 3)`` points (balanced, compact)."""
    return cKDTree(np.asarray(points, dtype=np.float64).reshape(-1, 3))


def mean_resolution(
    points: np.ndarray, tree: cKDTree | None = None, statistic: str = "mean"
) -> float:
    """Mean cloud resolution ``Tr``: mean distance of each point to its nearest other point (m).

    Exact duplicates are ignored (a duplicate's nearest *distinct* neighbour is used), so a
    cloud with repeated points does not get a zero resolution. Returns ``nan`` for fewer than
    two distinct points. ``tree`` (a KD-tree of ``points``) is reused when given;
    ``statistic="median"`` takes the median of those distances instead.
    """
    reduce = {"mean": np.mean, "median": np.median}[statistic]
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if P.shape[0] >= 2:
        tree = tree if tree is not None else build_tree(P)
        d, _ = tree.query(P, k=2)
        if (d[:, 1] > 0).all():  # no duplicates: the common case, no sort needed
            return float(reduce(d[:, 1]))
    P = np.unique(P, axis=0) if P.shape[0] > 1 else P
    if P.shape[0] < 2:
        return float("nan")
    d, _ = build_tree(P).query(P, k=2)
    return float(reduce(d[:, 1]))


def knn(points: np.ndarray, queries: np.ndarray, k: int, tree: cKDTree | None = None):
    """``k`` nearest neighbours of each query: returns ``(distances (Q, k), indices (Q, k))``."""
    tree = tree if tree is not None else build_tree(points)
    k = int(min(k, tree.n))
    d, i = tree.query(np.asarray(queries, dtype=np.float64).reshape(-1, 3), k=k)
    if k == 1:
        d, i = d[:, None], i[:, None]
    return d, i


def radius_neighbors(
    points: np.ndarray, queries: np.ndarray, radius: float, tree: cKDTree | None = None
) -> list[list[int]]:
    """Indices of the points within ``radius`` (m, inclusive) of each query (unsorted lists)."""
    tree = tree if tree is not None else build_tree(points)
    return tree.query_ball_point(np.asarray(queries, dtype=np.float64).reshape(-1, 3), r=radius)
