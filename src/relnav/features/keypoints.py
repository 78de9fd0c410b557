"""Keypoint selection (all, voxel, farthest point sampling, ISS, random) and voxel downsampling.

All selectors return sorted ``(K,)`` int64 indices into the input cloud, except FPS which returns
its indices in selection order (the first one is the seeded start point).

* ``"all"``: every point (Paper 1: "we describe all vertices").
* ``"voxel"``: one point per occupied voxel of a grid of size ``voxel_size`` anchored at the
  origin of the cloud frame (cell ``floor(p / voxel_size)``): the point nearest the centroid of
  its voxel (ties → lowest index).
* ``"fps"``: farthest point sampling of ``n`` points, seeded start.
* ``"iss"``: Intrinsic Shape Signatures (Zhong 2009), as Open3D / PCL (module function
  :func:`iss_keypoints`).
* ``"random"``: ``n`` distinct points drawn uniformly with a seeded generator.
"""

from __future__ import annotations

import itertools
import logging

import numpy as np
from numba import njit

from relnav.errors import ConfigError, InputError
from relnav.geometry.neighbors import build_tree, mean_resolution

__all__ = [
    "farthest_point_sampling",
    "iss_keypoints",
    "select_keypoints",
    "voxel_downsample",
    "voxel_groups",
    "voxel_keypoints",
]

log = logging.getLogger(__name__)

METHODS = ("all", "voxel", "fps", "iss", "random")


def _as_points(points: np.ndarray) -> np.ndarray:
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {P.shape}")
    if not np.isfinite(P).all():
        raise InputError("points contain NaN/inf")
    return P


def _check_voxel(voxel_size: float | None) -> float:
    if voxel_size is None:
        raise ConfigError("voxel keypoints/downsampling need voxel_size (metres)")
    v = float(voxel_size)
    if not (np.isfinite(v) and v > 0):
        raise ConfigError(f"voxel_size must be positive and finite, got {voxel_size}")
    return v


def voxel_groups(P: np.ndarray, voxel: float) -> tuple[np.ndarray, int]:
    """Voxel id of each point (``0..M-1``, ordered by voxel key) and the voxel count ``M``."""
    if P.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), 0
    keys = np.floor(P / voxel).astype(np.int64)
    c = keys - keys.min(axis=0)
    span = c.max(axis=0) + 1
    if float(span[0]) * float(span[1]) * float(span[2]) < 2.0**62:
        # one int64 key per cell, mixed radix: same (lexicographic) order as the rows, and a
        # 1-D sort instead of a row-wise one (several times faster on dense scans)
        _, inv = np.unique((c[:, 0] * span[1] + c[:, 1]) * span[2] + c[:, 2], return_inverse=True)
    else:
        _, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    return inv, int(inv.max()) + 1


def voxel_downsample(points: np.ndarray, voxel_size: float) -> np.ndarray:
    """Centroids of the points in each occupied voxel.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres.
    voxel_size : float
        Voxel edge, metres; grid anchored at the frame origin (cell ``floor(p / voxel_size)``).

    Returns
    -------
    (M, 3) float64
        One centroid per occupied voxel, ordered lexicographically by voxel cell.
    """
    P = _as_points(points)
    v = _check_voxel(voxel_size)
    if P.shape[0] == 0:
        return np.zeros((0, 3))
    inv, M = voxel_groups(P, v)
    counts = np.bincount(inv, minlength=M).astype(np.float64)
    return (
        np.stack([np.bincount(inv, weights=P[:, a], minlength=M) for a in range(3)], 1)
        / (counts[:, None])
    )


def voxel_keypoints(points: np.ndarray, voxel_size: float) -> np.ndarray:
    """Index of the point nearest its voxel centroid, one per occupied voxel (sorted, int64)."""
    P = _as_points(points)
    v = _check_voxel(voxel_size)
    if P.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    inv, M = voxel_groups(P, v)
    counts = np.bincount(inv, minlength=M).astype(np.float64)
    cen = np.stack([np.bincount(inv, weights=P[:, a], minlength=M) for a in range(3)], 1)
    cen /= counts[:, None]
    d2 = np.sum((P - cen[inv]) ** 2, axis=1)
    order = np.lexsort((np.arange(P.shape[0]), d2, inv))  # by voxel, then distance, then index
    first = np.ones(order.size, dtype=bool)
    first[1:] = inv[order[1:]] != inv[order[:-1]]
    return np.sort(order[first]).astype(np.int64)


@njit(cache=True)
def _fps_kernel(P: np.ndarray, n: int, start: int) -> np.ndarray:
    N = P.shape[0]
    out = np.empty(n, dtype=np.int64)
    d = np.full(N, np.inf)
    cur = start
    for s in range(n):
        out[s] = cur
        d[cur] = -1.0
        c0 = P[cur, 0]
        c1 = P[cur, 1]
        c2 = P[cur, 2]
        best = -1
        bestd = -np.inf
        for i in range(N):
            if d[i] < 0.0:
                continue
            e0 = P[i, 0] - c0
            e1 = P[i, 1] - c1
            e2 = P[i, 2] - c2
            dd = e0 * e0 + e1 * e1 + e2 * e2
            if dd < d[i]:
                d[i] = dd
            if d[i] > bestd:
                bestd = d[i]
                best = i
        cur = best
    return out


def farthest_point_sampling(
    points: np.ndarray, n: int, *, seed: int | np.random.Generator = 0
) -> np.ndarray:
    """Farthest point sampling: ``min(n, N)`` distinct indices in selection order.

    The start point is drawn with ``np.random.default_rng(seed)``; each next point is the one
    farthest (Euclidean) from all points selected so far (ties → lowest index). Cost ``O(n·N)``.
    """
    P = np.ascontiguousarray(_as_points(points))
    n = _check_n(n, "fps")
    N = P.shape[0]
    if n > N:
        log.warning("fps: n=%d > %d points; returning all points", n, N)
        n = N
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    rng = np.random.default_rng(seed)
    start = int(rng.integers(N))
    return _fps_kernel(P, n, start)


def _check_n(n: int | None, method: str) -> int:
    if n is None:
        raise ConfigError(f"keypoint method {method!r} needs n (number of keypoints)")
    if int(n) != n or n < 0:
        raise ConfigError(f"n must be a non-negative integer, got {n}")
    return int(n)


def iss_keypoints(
    points: np.ndarray,
    *,
    salient_radius: float | None = None,
    non_max_radius: float | None = None,
    gamma_21: float = 0.975,
    gamma_32: float = 0.975,
    min_neighbors: int = 5,
    salient_factor: float = 6.0,
    non_max_factor: float = 4.0,
    rel_eps: float = 1e-9,
) -> np.ndarray:
    """ISS keypoints (Zhong 2009) as in Open3D ``compute_iss_keypoints`` / PCL ``ISSKeypoint3D``.

    For every point with at least ``min_neighbors`` points (itself included) within
    ``salient_radius``, the eigenvalues ``λ1 ≥ λ2 ≥ λ3`` of the (unweighted) covariance of that
    neighbourhood are computed; the point is salient when ``λ2/λ1 < gamma_21`` and
    ``λ3/λ2 < gamma_32``, with saliency ``λ3``. A salient point is a keypoint when it has at least
    ``min_neighbors`` points within ``non_max_radius`` and no neighbour there has a larger
    saliency (ties kept, as Open3D).

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres.
    salient_radius, non_max_radius : float, optional
        Radii in metres; default ``salient_factor·Tr`` and ``non_max_factor·Tr`` (6·Tr and 4·Tr,
        Open3D's defaults), ``Tr`` the mean resolution.
    gamma_21, gamma_32 : float
        Eigenvalue-ratio upper bounds (Open3D/PCL default 0.975).
    min_neighbors : int
        Minimum neighbourhood size (Open3D/PCL default 5).
    salient_factor, non_max_factor : float
        Multiples of ``Tr`` used when the radii are not given.
    rel_eps : float
        **Deviation from Open3D**: a saliency ``λ3 ≤ rel_eps·λ1`` is treated as zero, so exactly
        planar (noise-free) patches, whose ``λ3`` is floating-point noise, yield no keypoints.
        Set 0 to reproduce Open3D exactly.

    Returns
    -------
    (K,) int64
        Sorted keypoint indices.

    References
    ----------
    Y. Zhong, "Intrinsic shape signatures: A shape descriptor for 3D object recognition",
    ICCV Workshops 2009. doi:10.1109/ICCVW.2009.5457637
    """
    P = _as_points(points)
    N = P.shape[0]
    if N == 0:
        return np.zeros(0, dtype=np.int64)
    if salient_radius is None or non_max_radius is None:
        tr = mean_resolution(P)
        if not np.isfinite(tr) or tr <= 0:
            return np.zeros(0, dtype=np.int64)
        salient_radius = salient_factor * tr if salient_radius is None else salient_radius
        non_max_radius = non_max_factor * tr if non_max_radius is None else non_max_radius
        log.debug(
            "iss: salient_radius=%g non_max_radius=%g (Tr=%g)", salient_radius, non_max_radius, tr
        )
    for name, val in (("salient_radius", salient_radius), ("non_max_radius", non_max_radius)):
        if not (np.isfinite(val) and val > 0):
            raise ConfigError(f"iss {name} must be positive and finite, got {val}")
    tree = build_tree(P)
    lists = tree.query_ball_point(P, r=float(salient_radius))
    lens = np.fromiter((len(li) for li in lists), dtype=np.int64, count=N)
    flat = np.fromiter(itertools.chain.from_iterable(lists), dtype=np.int64, count=int(lens.sum()))
    owner = np.repeat(np.arange(N), lens)
    # Covariance about the neighbourhood mean, accumulated relative to each query point
    # (numerically safer far from the origin).
    q = P[flat] - P[owner]
    s1 = np.stack([np.bincount(owner, weights=q[:, a], minlength=N) for a in range(3)], 1)
    cov = np.empty((N, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = np.bincount(owner, weights=q[:, a] * q[:, b], minlength=N)
            cov[:, b, a] = cov[:, a, b]
    nn = np.maximum(lens, 1).astype(np.float64)
    cov = cov / nn[:, None, None] - (s1[:, :, None] * s1[:, None, :]) / (nn**2)[:, None, None]
    ev = np.linalg.eigvalsh(cov)  # ascending: λ3, λ2, λ1
    l3, l2, l1 = ev[:, 0], ev[:, 1], ev[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        salient = (
            (lens >= min_neighbors)
            & (l1 > 0)
            & (l2 > 0)
            & (l2 / l1 < gamma_21)
            & (l3 / l2 < gamma_32)
            & (l3 > rel_eps * l1)
        )
    third = np.where(salient, l3, 0.0)
    cand = np.flatnonzero(third > 0)
    if cand.size == 0:
        return np.zeros(0, dtype=np.int64)
    nl = tree.query_ball_point(P[cand], r=float(non_max_radius))
    nlen = np.fromiter((len(li) for li in nl), dtype=np.int64, count=cand.size)
    nflat = np.fromiter(itertools.chain.from_iterable(nl), dtype=np.int64, count=int(nlen.sum()))
    starts = np.concatenate(([0], np.cumsum(nlen)[:-1]))
    nmax = np.maximum.reduceat(third[nflat], starts)  # every list holds the query itself
    keep = (nlen >= min_neighbors) & (third[cand] >= nmax)
    return np.sort(cand[keep]).astype(np.int64)


def select_keypoints(
    points: np.ndarray,
    method: str = "all",
    *,
    voxel_size: float | None = None,
    n: int | None = None,
    seed: int | np.random.Generator = 0,
    **iss_params: float | int,
) -> np.ndarray:
    """Keypoint indices by ``method`` (see the module docstring).

    Parameters
    ----------
    points : (N, 3) float64
        Cloud, metres.
    method : {"all", "voxel", "fps", "iss", "random"}
        Selector.
    voxel_size : float, optional
        Voxel edge in metres (``"voxel"``).
    n : int, optional
        Number of keypoints (``"fps"``, ``"random"``; capped at ``N``).
    seed : int or numpy.random.Generator
        Seed of the FPS start point / the random draw.
    **iss_params
        Keyword arguments of :func:`iss_keypoints` (``"iss"`` only).

    Returns
    -------
    (K,) int64
        Indices into ``points`` (sorted, except FPS which keeps selection order).
    """
    P = _as_points(points)
    if iss_params and method != "iss":
        raise ConfigError(f"options {sorted(iss_params)} only apply to method 'iss'")
    if method == "all":
        return np.arange(P.shape[0], dtype=np.int64)
    if method == "voxel":
        return voxel_keypoints(P, _check_voxel(voxel_size))
    if method == "fps":
        return farthest_point_sampling(P, _check_n(n, method), seed=seed)
    if method == "iss":
        return iss_keypoints(P, **iss_params)
    if method == "random":
        k = min(_check_n(n, method), P.shape[0])
        rng = np.random.default_rng(seed)
        return np.sort(rng.choice(P.shape[0], size=k, replace=False)).astype(np.int64)
    raise ConfigError(f"unknown keypoint method {method!r}; use one of {', '.join(METHODS)}")
