"""Static 3-D KD-tree compiled with numba: exact nearest neighbour within a distance bound.

The flat arrays of :func:`kd_build` are what the numba loops take (the ICP loop in
:mod:`relnav.geometry.icp_kernels`, the navigator's voxel map and GICP); :class:`KDTree` wraps
them for Python callers. ``benchmarks/speed/bench_kdtree.py`` compares it with scipy's ``cKDTree``
and ``pykdtree`` on the ICP loop's query (transform + nearest neighbour within the gate): it is
kept because it is the faster one there.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

__all__ = ["KDTree"]


@njit(cache=True)
def _kd_build_impl(
    P: np.ndarray, leaf_size: int, select: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """The tree of :func:`kd_build`; each node's points are ordered about its median by a sort
    (``select=False``) or by a quickselect (``select=True``, :func:`kd_build_select`)."""
    n = P.shape[0]
    perm = np.arange(n)
    depth = 0
    sz = n
    while sz > leaf_size:
        sz = (sz + 1) // 2
        depth += 1
    n_nodes = (1 << (depth + 1)) - 1
    split_dim = np.full(n_nodes, -1, np.int64)
    split_val = np.zeros(n_nodes)
    cap = 2 * depth + 8
    st_n = np.empty(cap, np.int64)
    st_s = np.empty(cap, np.int64)
    st_e = np.empty(cap, np.int64)
    key = np.empty(n)
    st_n[0], st_s[0], st_e[0] = 0, 0, n
    top = 1
    while top > 0:
        top -= 1
        node, s, e = st_n[top], st_s[top], st_e[top]
        if e - s <= leaf_size:
            continue
        best_d = 0
        best_sp = -1.0
        for d in range(3):
            lo = np.inf
            hi = -np.inf
            for k in range(s, e):
                v = P[perm[k], d]
                lo = min(lo, v)
                hi = max(hi, v)
            if hi - lo > best_sp:
                best_sp = hi - lo
                best_d = d
        m = (s + e) // 2
        if select:
            for k in range(s, e):
                key[k] = P[perm[k], best_d]
            _quickselect(key, perm, s, e, m)
            split_val[node] = key[m]
        else:
            sub = perm[s:e].copy()
            order = np.argsort(P[sub, best_d])
            for k in range(e - s):
                perm[s + k] = sub[order[k]]
            split_val[node] = P[perm[m], best_d]
        split_dim[node] = best_d
        st_n[top], st_s[top], st_e[top] = 2 * node + 1, s, m
        top += 1
        st_n[top], st_s[top], st_e[top] = 2 * node + 2, m, e
        top += 1
    Pp = np.empty((n, 3))
    for k in range(n):
        for d in range(3):
            Pp[k, d] = P[perm[k], d]
    return Pp, perm, split_dim, split_val


@njit(cache=True)
def _quickselect(
    key: np.ndarray, perm: np.ndarray, s: int, e: int, m: int
) -> None:  # pragma: no cover - numba
    """Hoare quickselect of ``key[s:e]`` (``perm`` moved alike) so that
    ``key[s:m] <= key[m] <= key[m+1:e]``."""
    lo_i, hi_i = s, e - 1
    while hi_i > lo_i:
        a, b, c = key[lo_i], key[(lo_i + hi_i) // 2], key[hi_i]
        pivot = max(min(a, b), min(max(a, b), c))
        i, j = lo_i, hi_i
        while i <= j:
            while key[i] < pivot:
                i += 1
            while key[j] > pivot:
                j -= 1
            if i <= j:
                key[i], key[j] = key[j], key[i]
                perm[i], perm[j] = perm[j], perm[i]
                i += 1
                j -= 1
        if m <= j:
            hi_i = j
        elif m >= i:
            lo_i = i
        else:
            break


def kd_build(
    P: np.ndarray, leaf_size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Implicit balanced KD-tree: node ``k`` covers ``[s, e)`` of the permuted points, children
    ``2k+1`` (``[s, m)``) and ``2k+2`` (``[m, e)``) with ``m = (s + e) // 2``; split on the axis
    of largest spread at the median. Returns ``(points_permuted, perm, split_dim, split_val)``
    (``split_dim = -1`` marks leaves).

    Called from Python (not compiled): ``select`` then reaches the kernel as a run-time bool,
    so both builds share one compiled :func:`_kd_build_impl`."""
    return _kd_build_impl(P, leaf_size, False)


def kd_build_select(
    P: np.ndarray, leaf_size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`kd_build`'s tree (the same nodes, splits and arrays) in ``O(n log n)``: each node
    is split by a quickselect of its median instead of a sort.

    A node holds the same points and gets the same split as with :func:`kd_build` (when the
    split coordinates are distinct); only the order of the points inside a leaf differs, so a
    search returns the same neighbours, except that among points at exactly the same distance
    another may come first.
    """
    return _kd_build_impl(P, leaf_size, True)


@njit(cache=True, inline="always")
def kd_children(
    node: int, s: int, e: int, diff: float
) -> tuple[int, int, int, int, int, int]:  # pragma: no cover - numba
    """The near and far child of ``node`` (covering ``[s, e)``) for a query ``diff`` from its
    split: ``(near_node, near_s, near_e, far_node, far_s, far_e)`` (the tree of
    :func:`kd_build`)."""
    mid = (s + e) // 2
    if diff < 0.0:
        return 2 * node + 1, s, mid, 2 * node + 2, mid, e
    return 2 * node + 2, mid, e, 2 * node + 1, s, mid


@njit(cache=True)
def kd_query(
    Pp: np.ndarray,
    perm: np.ndarray,
    split_dim: np.ndarray,
    split_val: np.ndarray,
    Q: np.ndarray,
    T: np.ndarray,
    r: float,
    exclude_self: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Nearest neighbour of every ``T @ Q[i]`` closer than ``r`` (exact; strict bound).

    Returns ``(X, idx, dist)``: transformed queries, original indices (-1: none within ``r``)
    and distances (inf: none). ``exclude_self`` skips index ``i`` for query ``i``.
    """
    n = Pp.shape[0]
    m = Q.shape[0]
    X = np.empty((m, 3))
    out_i = np.full(m, -1, np.int64)
    out_d = np.full(m, np.inf)
    st_n = np.empty(128, np.int64)
    st_s = np.empty(128, np.int64)
    st_e = np.empty(128, np.int64)
    st_lb = np.empty(128)
    r2 = r * r if r < np.inf else np.inf
    n_nodes = split_dim.shape[0]
    for qi in range(m):
        a0, a1, a2 = Q[qi, 0], Q[qi, 1], Q[qi, 2]
        q0 = T[0, 0] * a0 + T[0, 1] * a1 + T[0, 2] * a2 + T[0, 3]
        q1 = T[1, 0] * a0 + T[1, 1] * a1 + T[1, 2] * a2 + T[1, 3]
        q2 = T[2, 0] * a0 + T[2, 1] * a1 + T[2, 2] * a2 + T[2, 3]
        X[qi, 0], X[qi, 1], X[qi, 2] = q0, q1, q2
        best = r2
        bi = -1
        st_n[0], st_s[0], st_e[0], st_lb[0] = 0, 0, n, 0.0
        top = 1
        while top > 0:
            top -= 1
            if st_lb[top] >= best:
                continue
            node, s, e = st_n[top], st_s[top], st_e[top]
            dim = split_dim[node] if node < n_nodes else -1
            if dim < 0:
                for k in range(s, e):
                    d0 = Pp[k, 0] - q0
                    d1 = Pp[k, 1] - q1
                    d2 = Pp[k, 2] - q2
                    dd = d0 * d0 + d1 * d1 + d2 * d2
                    if dd < best and not (exclude_self and perm[k] == qi):
                        best = dd
                        bi = k
                continue
            qv = q0 if dim == 0 else (q1 if dim == 1 else q2)
            diff = qv - split_val[node]
            near_n, near_s, near_e, far_n, far_s, far_e = kd_children(node, s, e, diff)
            st_n[top], st_s[top], st_e[top], st_lb[top] = far_n, far_s, far_e, diff * diff
            top += 1
            st_n[top], st_s[top], st_e[top], st_lb[top] = near_n, near_s, near_e, 0.0
            top += 1
        if bi >= 0:
            out_i[qi] = perm[bi]
            out_d[qi] = math.sqrt(best)
    return X, out_i, out_d


@njit(cache=True)
def kd_knn(
    Pp: np.ndarray,
    perm: np.ndarray,
    split_dim: np.ndarray,
    split_val: np.ndarray,
    Q: np.ndarray,
    k: int,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """The ``k`` nearest points of every ``Q[i]`` (exact), nearest first.

    Returns ``(dist, idx)``, both ``(len(Q), k)``: distances (inf: fewer than ``k`` points) and
    original indices (-1: none). Squared distances are summed over the axes in order and the
    root taken last, as :class:`scipy.spatial.cKDTree` does, so the distances are the same
    numbers. A node is skipped when its cell is farther than the ``k``-th best so far (the
    cell's distance is kept per axis as the search descends).
    """
    return kd_knn_within(Pp, perm, split_dim, split_val, Q, k, np.full(Q.shape[0], np.inf))


@njit(cache=True)
def kd_knn_within(
    Pp: np.ndarray,
    perm: np.ndarray,
    split_dim: np.ndarray,
    split_val: np.ndarray,
    Q: np.ndarray,
    k: int,
    bound2: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """:func:`kd_knn` among the points strictly closer to ``Q[i]`` than ``√bound2[i]``."""
    n = Pp.shape[0]
    m = Q.shape[0]
    out_d = np.full((m, k), np.inf)
    out_i = np.full((m, k), -1, np.int64)
    if k <= 0:
        return out_d, out_i
    cap = 128
    st_n = np.empty(cap, np.int64)
    st_s = np.empty(cap, np.int64)
    st_e = np.empty(cap, np.int64)
    st_lb = np.empty(cap)
    st_off = np.empty((cap, 3))
    bd = np.empty(k)
    bk = np.empty(k, np.int64)
    n_nodes = split_dim.shape[0]
    for qi in range(m):
        q0, q1, q2 = Q[qi, 0], Q[qi, 1], Q[qi, 2]
        found = 0
        bound = bound2[qi]  # squared distance of the k-th best so far
        st_n[0], st_s[0], st_e[0], st_lb[0] = 0, 0, n, 0.0
        st_off[0, 0] = st_off[0, 1] = st_off[0, 2] = 0.0
        top = 1
        while top > 0:
            top -= 1
            lb = st_lb[top]
            if lb >= bound:
                continue
            node, s, e = st_n[top], st_s[top], st_e[top]
            dim = split_dim[node] if node < n_nodes else -1
            if dim < 0:
                for kk in range(s, e):
                    d0 = Pp[kk, 0] - q0
                    d1 = Pp[kk, 1] - q1
                    d2 = Pp[kk, 2] - q2
                    dd = d0 * d0 + d1 * d1 + d2 * d2
                    if dd >= bound:
                        continue
                    # insert into the sorted list (a later equal distance goes after)
                    j = found if found < k else k - 1
                    while j > 0 and bd[j - 1] > dd:
                        bd[j] = bd[j - 1]
                        bk[j] = bk[j - 1]
                        j -= 1
                    bd[j] = dd
                    bk[j] = kk
                    if found < k:
                        found += 1
                    if found == k:
                        bound = bd[k - 1]
                continue
            qv = q0 if dim == 0 else (q1 if dim == 1 else q2)
            diff = qv - split_val[node]
            o0, o1, o2 = st_off[top, 0], st_off[top, 1], st_off[top, 2]
            old = o0 if dim == 0 else (o1 if dim == 1 else o2)
            far_lb = lb - old * old + diff * diff
            near_n, near_s, near_e, far_n, far_s, far_e = kd_children(node, s, e, diff)
            if far_lb < bound:
                st_n[top], st_s[top], st_e[top], st_lb[top] = far_n, far_s, far_e, far_lb
                st_off[top, 0], st_off[top, 1], st_off[top, 2] = o0, o1, o2
                st_off[top, dim] = diff
                top += 1
            st_n[top], st_s[top], st_e[top], st_lb[top] = near_n, near_s, near_e, lb
            st_off[top, 0], st_off[top, 1], st_off[top, 2] = o0, o1, o2
            top += 1
        for j in range(found):
            out_d[qi, j] = math.sqrt(bd[j])
            out_i[qi, j] = perm[bk[j]]
    return out_d, out_i


class KDTree:
    """Static 3-D KD-tree in numba: exact nearest neighbour within an optional distance bound.

    About 3× faster per query than :class:`scipy.spatial.cKDTree` and 1.1–1.8× faster than
    ``pykdtree`` for the single-NN queries of ICP (``benchmarks/speed/bench_kdtree.py``; its build
    is slower, but one build serves every iteration), and :meth:`nn` transforms the queries on the
    fly (one pass per iteration).
    :meth:`query` mirrors ``cKDTree.query`` (``k > 1`` falls back to a cKDTree built lazily).

    Parameters
    ----------
    points : (N, 3) float64
        Finite points (m).
    leaf_size : int
        Points per leaf.
    """

    def __init__(self, points: np.ndarray, leaf_size: int = 16) -> None:
        P = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        self.data = P
        self.n = int(P.shape[0])
        self._Pp, self._perm, self._dim, self._val = kd_build(P, int(leaf_size))
        self._ckd: Any = None

    def nn(
        self,
        queries: np.ndarray,
        max_distance: float = math.inf,
        *,
        T: np.ndarray | None = None,
        exclude_self: bool = False,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest neighbour of each (optionally transformed) query point.

        Parameters
        ----------
        queries : (M, 3) float64
            Query points.
        max_distance : float
            Only neighbours strictly closer than this (m) are returned.
        T : (4, 4) float64, optional
            Transform applied to the queries first.
        exclude_self : bool
            Skip point ``i`` for query ``i`` (queries = the tree's own points).

        Returns
        -------
        X : (M, 3) float64
            The (transformed) queries.
        idx : (M,) int64
            Index of the nearest point, ``-1`` when none is within ``max_distance``.
        dist : (M,) float64
            Its distance (m), ``inf`` when none.
        """
        Q = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
        TT = np.eye(4) if T is None else np.ascontiguousarray(T, dtype=np.float64)
        return kd_query(
            self._Pp, self._perm, self._dim, self._val, Q, TT, float(max_distance), exclude_self
        )

    def query(
        self,
        x: np.ndarray,
        k: int = 1,
        distance_upper_bound: float = math.inf,
        **kwargs: Any,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``cKDTree.query`` semantics: ``(d, i)``; missing neighbours give ``inf`` and ``n``."""
        if k != 1 or kwargs.get("p", 2) != 2 or kwargs.get("eps", 0) != 0:
            if self._ckd is None:
                from scipy.spatial import cKDTree

                self._ckd = cKDTree(self.data)
            return self._ckd.query(x, k=k, distance_upper_bound=distance_upper_bound, **kwargs)
        xa = np.asarray(x, dtype=np.float64)
        _, i, d = self.nn(xa.reshape(-1, 3), distance_upper_bound)
        i = np.where(i < 0, self.n, i)
        if xa.ndim == 1:
            return d[0], i[0]
        return d, i
