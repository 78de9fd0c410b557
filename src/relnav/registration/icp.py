"""Paper 1's ICP baselines: point-to-point, point-to-plane and X84 ICP (ALGORITHMS §C.1–C.3).

Method strings (spec ``paper`` / ``scale`` picks the threshold preset, see below):

============ =================================================================================
``icp-point`` Point-to-point ICP (Besl & McKay 1992), closed-form rigid fit per iteration,
              distance gate + standard-deviation outlier rule; ``max_iter = 20`` (paper 1).
``icp-plane`` Point-to-plane ICP (Chen & Medioni 1992), linearised 6×6 solve, target normals
              by PCA (k = 10); ``max_iter = 1000`` (paper 1).
``icp-x84``   Point-to-point ICP with Hampel's X84 rule (Fusiello et al. 2002):
              inlier iff ``|d − median(d)| ≤ 5.2·MAD``; ``max_iter = 20`` (paper 1).
============ =================================================================================

Each iteration (``source`` moves onto the fixed ``target``; the result is ``T_target_source``):

1. nearest target point of every transformed source point (KD-tree), kept when closer than the
   gate;
2. outlier rule on the kept distances ``d``: ``d ≤ mean(d) + std_factor·std(d)`` (``icp-point``,
   ``icp-plane``) or the X84 rule (``icp-x84``);
3. solve the increment (closed-form rigid fit, or the 6×6 normal equations) and compose it on
   the left: ``T ← ΔT · T``;
4. stop when the change of the estimated translation is below ``translation_tol`` *and* the
   change of the rotation below ``rotation_tol`` for ``stop_window = 3`` consecutive
   iterations, or after ``max_iter``.

**Thresholds: scale-aware by default.** Paper 1 used absolute values tuned on its real data
(gate 0.01 m, translation change 0.01 m, rotation change 0.009 rad). The simulated scenarios
span targets from 1 m to 800 m, where one absolute gate is either far too tight (no
correspondence at all) or far too loose, so the default (``thresholds="scale"``) ties them to
the source resolution ``Tr`` (:func:`relnav.geometry.neighbors.mean_resolution`):
``gate = gate_factor·Tr`` (10 Tr), ``translation_tol = translation_tol_factor·Tr`` (0.01 Tr)
and ``rotation_tol = translation_tol / ρ`` with ``ρ`` the RMS distance of the source points to
their centroid (the rotation that moves a typical point by ``translation_tol``).
``thresholds="paper"`` (method spec ``icp-point:paper``) uses paper 1's absolute values.
Explicit ``max_correspondence_distance`` / ``translation_tol`` / ``rotation_tol`` override both.

**[interpretation]** (ALGORITHMS §C.1, §I.6): the paper's units are taken as metres and
radians; the "standard deviation" rule factor is 2.5; the stop rule compares the change of the
estimate between consecutive iterations (Euclidean norm of the translation change, geodesic
angle of the rotation change); X84 keeps the distance gate as well (``gate=inf`` disables it).
Point-to-plane centres the linearisation on the source centroid and rebuilds the rotation by
Rodrigues (``rotation_update="rodrigues"``); ``"euler-zyx"`` is Open3D's ``Rz·Ry·Rx``.

**Open3D compatibility** (``open3d_compatible=True``): no outlier rule, no centring, Euler-ZYX
update, Open3D's determinant check (``|det JᵀJ| ≤ 1e-6`` → identity update) and Open3D's stop
rule (change of fitness < ``relative_fitness`` and of RMSE < ``relative_rmse``). With the same
gate, normals and iteration count the result equals
``open3d.pipelines.registration.registration_icp`` to ~1e-13 (tested to 1e-6).

**Implementation.** The whole loop runs in one numba function (:func:`_icp_loop`) over a numba
KD-tree (:class:`KDTree`, exact NN, queries transformed on the fly); the rigid fit uses Horn's
quaternion method (the same least-squares minimiser as Arun/Umeyama SVD with the reflection
guard) and small symmetric eigenproblems use Jacobi rotations, so no LAPACK call is compiled
(cold numba compilation stays a few seconds; the cache makes later imports instant).
``timings``: ``prepare`` (KD-tree, resolution, normals), ``iterate`` (the loop: NN + outlier
rule + solve), ``evaluate`` (final statistics and covariance). The 6×6 solve is a
pseudo-inverse; a rank-deficient system (e.g. point-to-plane on one plane) is flagged.

**Result fields.** ``fitness`` = inliers / finite source points (Open3D's definition, divides
by the SOURCE count); ``inlier_rmse`` = RMS point-to-point distance of the inliers (m);
``n_correspondences`` = pairs within the gate; ``n_inliers`` = pairs kept by the outlier rule;
both at the final estimate. ``covariance`` = ``σ² (JᵀJ)⁻¹`` of a LEFT perturbation
``T_true = exp_se3(δ) · T`` with ``δ = [ρ (m), φ (rad)]`` in the target frame, where ``J`` is
the residual Jacobian at the final inliers (point-to-plane: rows ``[nᵀ, (p×n)ᵀ]``;
point-to-point: blocks ``[I, −[p]×]``) and ``σ²`` the residual variance (``Σr²/(m − 6)``).
Inputs with non-finite points have those points dropped (counted in ``info``); empty, tiny,
coincident or collinear clouds, a bad ``init`` or no correspondence within the gate give a
``degenerate``/``failed`` result with a ``message``, never an exception.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numba import njit

from relnav.errors import ConfigError
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.normals import estimate_normals
from relnav.geometry.rotations import hat
from relnav.registration.base import register_method
from relnav.registration.result import RegistrationResult

__all__ = [
    "ICP",
    "KDTree",
    "PAPER_GATE",
    "PAPER_ROTATION_TOL",
    "PAPER_TRANSLATION_TOL",
    "PreparedCloud",
    "check_init",
    "information_ratio",
    "prepare_cloud",
    "reject_outliers",
]

log = logging.getLogger(__name__)

PAPER_GATE = 0.01
"""Paper 1's correspondence gate (m, [interpretation] of the unit)."""
PAPER_TRANSLATION_TOL = 0.01
"""Paper 1's translation-change stop threshold (m)."""
PAPER_ROTATION_TOL = 0.009
"""Paper 1's rotation-change stop threshold (rad, [interpretation] of the unit)."""

Thresholds = Literal["scale", "paper"]


# --------------------------------------------------------------------------- KD-tree (numba)


@njit(cache=True)
def _kd_build(
    P: np.ndarray, leaf_size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Implicit balanced KD-tree: node ``k`` covers ``[s, e)`` of the permuted points, children
    ``2k+1`` (``[s, m)``) and ``2k+2`` (``[m, e)``) with ``m = (s + e) // 2``; split on the axis
    of largest spread at the median. Returns ``(points_permuted, perm, split_dim, split_val)``
    (``split_dim = -1`` marks leaves)."""
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
        sub = perm[s:e].copy()
        order = np.argsort(P[sub, best_d])
        for k in range(e - s):
            perm[s + k] = sub[order[k]]
        m = (s + e) // 2
        split_dim[node] = best_d
        split_val[node] = P[perm[m], best_d]
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
def _kd_query(
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
            mid = (s + e) // 2
            qv = q0 if dim == 0 else (q1 if dim == 1 else q2)
            diff = qv - split_val[node]
            if diff < 0.0:
                near_n, near_s, near_e = 2 * node + 1, s, mid
                far_n, far_s, far_e = 2 * node + 2, mid, e
            else:
                near_n, near_s, near_e = 2 * node + 2, mid, e
                far_n, far_s, far_e = 2 * node + 1, s, mid
            st_n[top], st_s[top], st_e[top], st_lb[top] = far_n, far_s, far_e, diff * diff
            top += 1
            st_n[top], st_s[top], st_e[top], st_lb[top] = near_n, near_s, near_e, 0.0
            top += 1
        if bi >= 0:
            out_i[qi] = perm[bi]
            out_d[qi] = math.sqrt(best)
    return X, out_i, out_d


class KDTree:
    """Static 3-D KD-tree in numba: exact nearest neighbour within an optional distance bound.

    About 3–7× faster per query than :class:`scipy.spatial.cKDTree` for the single-NN queries
    of ICP, and :meth:`nn` transforms the queries on the fly (one pass per iteration).
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
        self._Pp, self._perm, self._dim, self._val = _kd_build(P, int(leaf_size))
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
        return _kd_query(
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


# --------------------------------------------------------------------------- cloud preparation


@dataclass
class PreparedCloud:
    """Per-cloud data shared by the ICP family (reusable across pairs, e.g. in odometry).

    Attributes
    ----------
    points : (N, 3) float64
        Finite points of the cloud (its own frame, m).
    tree : KDTree or None
        KD-tree of ``points`` (None when the cloud is unusable).
    resolution : float
        Mean resolution ``Tr`` (m); NaN when not computed or fewer than 2 distinct points.
    radius : float
        RMS distance of the points to their centroid (m).
    normals : (N, 3) float64 or None
        Unit normals (NaN rows where undefined), when requested.
    status : {"ok", "degenerate", "failed"}
        ``degenerate`` for empty/tiny/coincident/collinear clouds; ``failed`` for bad shapes.
    message : str
        Reason for a non-``ok`` status.
    n_dropped : int
        Non-finite input points that were dropped.
    timings : dict[str, float]
        Seconds spent preparing the cloud.
    """

    points: np.ndarray
    tree: KDTree | None = None
    resolution: float = float("nan")
    radius: float = float("nan")
    normals: np.ndarray | None = None
    status: str = "ok"
    message: str = ""
    n_dropped: int = 0
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """``status == "ok"``."""
        return self.status == "ok"


def prepare_cloud(
    points: Any,
    *,
    min_points: int = 6,
    normals: Literal["none", "pca"] | np.ndarray = "none",
    normal_k: int = 10,
    resolution: bool = True,
    name: str = "cloud",
) -> PreparedCloud:
    """Validate a cloud and precompute its KD-tree, resolution and (optionally) normals.

    Parameters
    ----------
    points : array-like, (N, 3)
        Points in metres; non-finite rows are dropped.
    min_points : int
        Fewer finite points → ``degenerate``.
    normals : {"none", "pca"} or (N, 3) array
        ``"pca"``: PCA normals from ``normal_k`` nearest neighbours (oriented to the origin);
        an array: given normals (rows matching ``points``; non-finite rows become NaN).
    normal_k : int
        Neighbours for PCA normals (ALGORITHMS §C.2: 10).
    resolution : bool
        Compute ``Tr`` (skipped when the caller uses absolute thresholds only).
    name : str
        Used in messages (``"source"``/``"target"``).

    Returns
    -------
    PreparedCloud
        Never raises for bad data: the status says what is wrong.
    """
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    try:
        P = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as e:
        return PreparedCloud(np.zeros((0, 3)), status="failed", message=f"{name}: {e}")
    if P.size == 0:
        return PreparedCloud(np.zeros((0, 3)), status="degenerate", message=f"{name} is empty")
    if P.ndim != 2 or P.shape[1] != 3:
        return PreparedCloud(
            np.zeros((0, 3)),
            status="failed",
            message=f"{name} must have shape (N, 3), got {P.shape}",
        )
    finite = np.isfinite(P).all(axis=1)
    n_dropped = int((~finite).sum())
    given_normals = None
    if isinstance(normals, np.ndarray) or (not isinstance(normals, str) and normals is not None):
        given_normals = np.asarray(normals, dtype=np.float64)
        if given_normals.shape != P.shape:
            return PreparedCloud(
                np.zeros((0, 3)),
                status="failed",
                message=f"{name} normals shape {given_normals.shape} != points {P.shape}",
            )
        given_normals = given_normals[finite]
    if n_dropped:
        P = P[finite]
        log.debug("%s: dropped %d non-finite points", name, n_dropped)
    P = np.ascontiguousarray(P)
    base = {"n_dropped": n_dropped, "timings": timings}
    n = P.shape[0]
    if n < min_points:
        msg = f"{name} has {n} finite points (< {min_points})"
        return PreparedCloud(P, status="degenerate", message=msg, **base)
    c = P.mean(axis=0)
    Q = P - c
    ev = np.linalg.eigvalsh(Q.T @ Q / n)
    radius = float(math.sqrt(max(ev.sum(), 0.0)))
    scale = max(1.0, float(np.abs(c).max()))
    if ev[2] <= (1e-9 * scale) ** 2:
        msg = f"{name}: all points coincide"
        return PreparedCloud(P, radius=radius, status="degenerate", message=msg, **base)
    if ev[1] <= 1e-10 * ev[2]:
        msg = f"{name}: points are collinear"
        return PreparedCloud(P, radius=radius, status="degenerate", message=msg, **base)
    tree = KDTree(P)
    timings["tree"] = time.perf_counter() - t0
    tr = float("nan")
    if resolution:
        t1 = time.perf_counter()
        _, _, dd = tree.nn(P, exclude_self=True)
        if not (dd > 0).all():  # duplicates: fall back to the distinct-point definition
            tr = mean_resolution(P)
        else:
            tr = float(dd.mean())
        timings["resolution"] = time.perf_counter() - t1
    N = None
    if given_normals is not None:
        nrm = np.linalg.norm(given_normals, axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            N = given_normals / nrm
        N[~np.isfinite(N).all(axis=1)] = np.nan
    elif normals == "pca":
        t1 = time.perf_counter()
        N = estimate_normals(P, k=int(normal_k))
        timings["normals"] = time.perf_counter() - t1
    elif normals != "none":
        raise ConfigError(f"normals must be 'none', 'pca' or an array, got {normals!r}")
    return PreparedCloud(P, tree, tr, radius, N, **base)


def check_init(init: Any) -> tuple[np.ndarray | None, str]:
    """Validate an initial guess: returns ``(T, "")`` or ``(None, reason)``.

    ``None`` means identity. A valid guess is a finite ``4x4`` rigid transform (rotation
    orthonormal to 1e-6, determinant +1, last row ``[0, 0, 0, 1]``).
    """
    if init is None:
        return np.eye(4), ""
    try:
        T = np.array(init, dtype=np.float64)
    except (TypeError, ValueError) as e:
        return None, f"init is not a numeric array: {e}"
    if T.shape != (4, 4):
        return None, f"init must be 4x4, got shape {T.shape}"
    if not np.isfinite(T).all():
        return None, "init has non-finite entries"
    R = T[:3, :3]
    if (
        np.abs(R.T @ R - np.eye(3)).max() > 1e-6
        or np.linalg.det(R) < 0
        or np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-12
    ):
        return None, "init is not a rigid transform"
    return T, ""


def _failed(status: str, message: str, T: np.ndarray, timings: dict, info: dict):
    log.debug("registration %s: %s", status, message)
    return RegistrationResult(
        T_target_source=T.copy(), status=status, message=message, timings=timings, info=info
    )


# --------------------------------------------------------------------------- numba kernels


@njit(cache=True)
def _transform(P: np.ndarray, T: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    n = P.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        x, y, z = P[i, 0], P[i, 1], P[i, 2]
        for a in range(3):
            out[i, a] = T[a, 0] * x + T[a, 1] * y + T[a, 2] * z + T[a, 3]
    return out


@njit(cache=True)
def _jacobi_eigh(A_in: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Eigen-decomposition of a small symmetric matrix by cyclic Jacobi rotations.

    Returns ``(w, V)`` with ``A = V diag(w) Vᵀ`` (unsorted). Plain loops, no LAPACK: numba
    compiles it in a fraction of the time ``np.linalg`` needs, and it is exact to rounding.
    """
    n = A_in.shape[0]
    A = A_in.copy()
    V = np.eye(n)
    for _sweep in range(60):
        off = 0.0
        scale = 0.0
        for p in range(n):
            scale += A[p, p] * A[p, p]
            for q in range(p + 1, n):
                off += A[p, q] * A[p, q]
        if off <= 1e-32 * scale or off == 0.0:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = A[p, q]
                if apq == 0.0:
                    continue
                theta = (A[q, q] - A[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                sn = t * c
                for k in range(n):
                    akp = A[k, p]
                    akq = A[k, q]
                    A[k, p] = c * akp - sn * akq
                    A[k, q] = sn * akp + c * akq
                for k in range(n):
                    apk = A[p, k]
                    aqk = A[q, k]
                    A[p, k] = c * apk - sn * aqk
                    A[q, k] = sn * apk + c * aqk
                for k in range(n):
                    vkp = V[k, p]
                    vkq = V[k, q]
                    V[k, p] = c * vkp - sn * vkq
                    V[k, q] = sn * vkp + c * vkq
    w = np.empty(n)
    for p in range(n):
        w[p] = A[p, p]
    return w, V


@njit(cache=True)
def _horn_rotation(H: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Proper rotation ``R`` maximising ``tr(R H)`` for ``H = Σ (x − x̄)(y − ȳ)ᵀ`` (Horn 1987).

    Same minimiser as Arun/Umeyama SVD with the reflection guard; ``y ≈ R x``.
    """
    sxx, sxy, sxz = H[0, 0], H[0, 1], H[0, 2]
    syx, syy, syz = H[1, 0], H[1, 1], H[1, 2]
    szx, szy, szz = H[2, 0], H[2, 1], H[2, 2]
    N = np.empty((4, 4))
    N[0, 0] = sxx + syy + szz
    N[0, 1] = syz - szy
    N[0, 2] = szx - sxz
    N[0, 3] = sxy - syx
    N[1, 1] = sxx - syy - szz
    N[1, 2] = sxy + syx
    N[1, 3] = szx + sxz
    N[2, 2] = -sxx + syy - szz
    N[2, 3] = syz + szy
    N[3, 3] = -sxx - syy + szz
    for a in range(4):
        for b in range(a):
            N[a, b] = N[b, a]
    w, V = _jacobi_eigh(N)
    k = 0
    for a in range(1, 4):
        if w[a] > w[k]:
            k = a
    qw, qx, qy, qz = V[0, k], V[1, k], V[2, k], V[3, k]
    nq = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
    qw, qx, qy, qz = qw / nq, qx / nq, qy / nq, qz / nq
    R = np.empty((3, 3))
    R[0, 0] = qw * qw + qx * qx - qy * qy - qz * qz
    R[0, 1] = 2.0 * (qx * qy - qw * qz)
    R[0, 2] = 2.0 * (qx * qz + qw * qy)
    R[1, 0] = 2.0 * (qx * qy + qw * qz)
    R[1, 1] = qw * qw - qx * qx + qy * qy - qz * qz
    R[1, 2] = 2.0 * (qy * qz - qw * qx)
    R[2, 0] = 2.0 * (qx * qz - qw * qy)
    R[2, 1] = 2.0 * (qy * qz + qw * qx)
    R[2, 2] = qw * qw - qx * qx - qy * qy + qz * qz
    return R


@njit(cache=True)
def _kabsch_pairs(
    X: np.ndarray, Y: np.ndarray, src_idx: np.ndarray, tgt_idx: np.ndarray
) -> np.ndarray:  # pragma: no cover - numba
    """Rigid transform ``T`` (4x4) with ``Y[tgt] ≈ R X[src] + t`` (least squares, Horn)."""
    m = src_idx.shape[0]
    mx = np.zeros(3)
    my = np.zeros(3)
    for k in range(m):
        i = src_idx[k]
        j = tgt_idx[k]
        for a in range(3):
            mx[a] += X[i, a]
            my[a] += Y[j, a]
    mx /= m
    my /= m
    H = np.zeros((3, 3))
    for k in range(m):
        i = src_idx[k]
        j = tgt_idx[k]
        for a in range(3):
            xa = X[i, a] - mx[a]
            for b in range(3):
                H[a, b] += xa * (Y[j, b] - my[b])
    R = _horn_rotation(H)
    T = np.eye(4)
    for a in range(3):
        ta = my[a]
        for b in range(3):
            T[a, b] = R[a, b]
            ta -= R[a, b] * mx[b]
        T[a, 3] = ta
    return T


@njit(cache=True)
def _plane_system(
    X: np.ndarray,
    Y: np.ndarray,
    N: np.ndarray,
    src_idx: np.ndarray,
    tgt_idx: np.ndarray,
    c: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, float]:  # pragma: no cover - numba
    """Normal equations of linearised point-to-plane ICP about centre ``c``.

    Unknowns ``[ω (3), t (3)]``; row ``a = [(x − c) × n, n]``, residual ``r = (x − y)·n``.
    Returns ``(AᵀA, Aᵀr, Σr²)``.
    """
    JTJ = np.zeros((6, 6))
    JTr = np.zeros(6)
    r2 = 0.0
    a = np.empty(6)
    for k in range(src_idx.shape[0]):
        i = src_idx[k]
        j = tgt_idx[k]
        nx, ny, nz = N[j, 0], N[j, 1], N[j, 2]
        x0, x1, x2 = X[i, 0] - c[0], X[i, 1] - c[1], X[i, 2] - c[2]
        r = (X[i, 0] - Y[j, 0]) * nx + (X[i, 1] - Y[j, 1]) * ny + (X[i, 2] - Y[j, 2]) * nz
        a[0] = x1 * nz - x2 * ny
        a[1] = x2 * nx - x0 * nz
        a[2] = x0 * ny - x1 * nx
        a[3] = nx
        a[4] = ny
        a[5] = nz
        for p in range(6):
            JTr[p] += a[p] * r
            for q in range(p, 6):
                JTJ[p, q] += a[p] * a[q]
        r2 += r * r
    for p in range(6):
        for q in range(p):
            JTJ[p, q] = JTJ[q, p]
    return JTJ, JTr, r2


@njit(cache=True)
def _point_information(
    X: np.ndarray, Y: np.ndarray, src_idx: np.ndarray, tgt_idx: np.ndarray
) -> tuple[np.ndarray, float]:  # pragma: no cover - numba
    """``Σ JᵀJ`` (6x6, order [ρ, φ]) with ``J = [I, −[p]×]``, and ``Σ|p − y|²``.

    ``JᵀJ = [[m I, −Σ[p]×], [Σ[p]×, Σ(|p|² I − p pᵀ)]]``.
    """
    A = np.zeros((6, 6))
    r2 = 0.0
    s0 = s1 = s2 = 0.0
    for k in range(src_idx.shape[0]):
        i = src_idx[k]
        j = tgt_idx[k]
        p0, p1, p2 = X[i, 0], X[i, 1], X[i, 2]
        for a in range(3):
            d = X[i, a] - Y[j, a]
            r2 += d * d
        s0 += p0
        s1 += p1
        s2 += p2
        pp = p0 * p0 + p1 * p1 + p2 * p2
        A[3, 3] += pp - p0 * p0
        A[4, 4] += pp - p1 * p1
        A[5, 5] += pp - p2 * p2
        A[3, 4] -= p0 * p1
        A[3, 5] -= p0 * p2
        A[4, 5] -= p1 * p2
    m = float(src_idx.shape[0])
    A[0, 0] = A[1, 1] = A[2, 2] = m
    # upper-right block −Σ[p]×, with [p]× = [[0, −p2, p1], [p2, 0, −p0], [−p1, p0, 0]]
    A[0, 4] = s2
    A[0, 5] = -s1
    A[1, 3] = -s2
    A[1, 5] = s0
    A[2, 3] = s1
    A[2, 4] = -s0
    A[4, 3] = A[3, 4]
    A[5, 3] = A[3, 5]
    A[5, 4] = A[4, 5]
    for a in range(3):
        for b in range(3):
            A[3 + b, a] = A[a, 3 + b]
    return A, r2


# --------------------------------------------------------------------------- the fused ICP loop


@njit(cache=True)
def _rodrigues_nb(w: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Rotation matrix of the rotation vector ``w`` (plain loops)."""
    th = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    K = np.zeros((3, 3))
    if th < 1e-12:
        K[0, 1], K[0, 2], K[1, 2] = -w[2], w[1], -w[0]
        K[1, 0], K[2, 0], K[2, 1] = w[2], -w[1], w[0]
        return np.eye(3) + K
    k0, k1, k2 = w[0] / th, w[1] / th, w[2] / th
    K[0, 1], K[0, 2], K[1, 2] = -k2, k1, -k0
    K[1, 0], K[2, 0], K[2, 1] = k2, -k1, k0
    sn, c1 = math.sin(th), 1.0 - math.cos(th)
    R = np.eye(3)
    for a in range(3):
        for b in range(3):
            kk = K[a, 0] * K[0, b] + K[a, 1] * K[1, b] + K[a, 2] * K[2, b]
            R[a, b] += sn * K[a, b] + c1 * kk
    return R


@njit(cache=True)
def _euler_zyx(w: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Open3D's ``TransformVector6dToMatrix4d`` rotation: ``Rz(w2) · Ry(w1) · Rx(w0)``."""
    ca, sa = math.cos(w[0]), math.sin(w[0])
    cb, sb = math.cos(w[1]), math.sin(w[1])
    cg, sg = math.cos(w[2]), math.sin(w[2])
    R = np.empty((3, 3))
    R[0, 0] = cg * cb
    R[0, 1] = cg * sb * sa - sg * ca
    R[0, 2] = cg * sb * ca + sg * sa
    R[1, 0] = sg * cb
    R[1, 1] = sg * sb * sa + cg * ca
    R[1, 2] = sg * sb * ca - cg * sa
    R[2, 0] = -sb
    R[2, 1] = cb * sa
    R[2, 2] = cb * ca
    return R


@njit(cache=True)
def _valid_pairs(
    j: np.ndarray, d: np.ndarray, N: np.ndarray, has_normals: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Source indices, target indices and distances of the gated pairs (finite target normal)."""
    m = j.shape[0]
    si = np.empty(m, np.int64)
    cnt = 0
    for i in range(m):
        if j[i] >= 0 and (not has_normals or np.isfinite(N[j[i], 0])):
            si[cnt] = i
            cnt += 1
    si = si[:cnt]
    ti = np.empty(cnt, np.int64)
    dd = np.empty(cnt)
    for k in range(cnt):
        ti[k] = j[si[k]]
        dd[k] = d[si[k]]
    return si, ti, dd


@njit(cache=True)
def _reject_nb(d: np.ndarray, rule: int, factor: float) -> np.ndarray:  # pragma: no cover
    """Numba twin of :func:`reject_outliers` (rule 0 none, 1 std, 2 x84)."""
    keep = np.ones(d.shape[0], dtype=np.bool_)
    if rule == 0 or d.shape[0] == 0:
        return keep
    if rule == 1:
        lim = d.mean() + factor * d.std()
        for i in range(d.shape[0]):
            keep[i] = d[i] <= lim
        return keep
    med = np.median(d)
    dev = np.abs(d - med)
    mad = np.median(dev)
    for i in range(d.shape[0]):
        keep[i] = dev[i] <= factor * mad
    return keep


@njit(cache=True)
def _icp_loop(
    P: np.ndarray,
    Pp: np.ndarray,
    perm: np.ndarray,
    sdim: np.ndarray,
    sval: np.ndarray,
    Y: np.ndarray,
    N: np.ndarray,
    plane: bool,
    T0: np.ndarray,
    gate: float,
    max_iter: int,
    rule: int,
    factor: float,
    center: bool,
    euler: bool,
    o3d: bool,
    rel_fit: float,
    rel_rmse: float,
    ttol: float,
    rtol: float,
    stop_window: int,
    min_corr: int,
):  # pragma: no cover - numba
    """The whole ICP iteration (module docstring) in one compiled loop.

    Returns ``(T, n_iter, status, converged, deficient, X, si, ti, d)`` with status 0 ok,
    1 too few correspondences, 2 singular system; ``X, si, ti, d`` are the transformed source
    and the gated pairs at the returned ``T`` (before the outlier rule).
    """
    n = P.shape[0]
    T = T0.copy()
    X, j, d = _kd_query(Pp, perm, sdim, sval, P, T, gate, False)
    si, ti, dd = _valid_pairs(j, d, N, plane)
    fit_prev = si.shape[0] / n
    rmse_prev = math.sqrt(np.mean(dd**2)) if dd.shape[0] else 0.0
    below = 0
    converged = False
    deficient = False
    status = 0
    n_iter = 0
    for it in range(1, max_iter + 1):
        keep = _reject_nb(dd, rule, factor)
        sk = si[keep]
        tk = ti[keep]
        if sk.shape[0] < min_corr:
            status = 1
            break
        if plane:
            c = np.zeros(3)
            if center:
                for k in range(sk.shape[0]):
                    for a in range(3):
                        c[a] += X[sk[k], a]
                c /= sk.shape[0]
            JTJ, JTr, _ = _plane_system(X, Y, N, sk, tk, c)
            w, V = _jacobi_eigh(JTJ)
            wmax = w.max()
            x = np.zeros(6)
            if o3d:
                det = 1.0
                for a in range(6):
                    det *= w[a]
                if not abs(det) > 1e-6:  # Open3D: failed solve → identity update
                    deficient = True
                    wmax = -1.0
            elif not wmax > 0.0:
                status = 2
                break
            if wmax > 0.0:
                for k in range(6):
                    if w[k] > wmax * 1e-12 or (o3d and w[k] != 0.0):
                        coef = 0.0
                        for p in range(6):
                            coef += V[p, k] * JTr[p]
                        for p in range(6):
                            x[p] -= V[p, k] * coef / w[k]
                    else:
                        deficient = True
            R = _euler_zyx(x[:3]) if euler else _rodrigues_nb(x[:3])
            inc = np.eye(4)
            for a in range(3):
                ta = c[a] + x[3 + a]
                for b in range(3):
                    inc[a, b] = R[a, b]
                    ta -= R[a, b] * c[b]
                inc[a, 3] = ta
        else:
            inc = _kabsch_pairs(X, Y, sk, tk)
        T_old = T
        T = np.eye(4)
        for a in range(3):
            for b in range(4):
                T[a, b] = (
                    inc[a, 0] * T_old[0, b] + inc[a, 1] * T_old[1, b] + inc[a, 2] * T_old[2, b]
                )
            T[a, 3] += inc[a, 3]
        X, j, d = _kd_query(Pp, perm, sdim, sval, P, T, gate, False)
        si, ti, dd = _valid_pairs(j, d, N, plane)
        n_iter = it
        if o3d:
            fit = si.shape[0] / n
            rmse = math.sqrt(np.mean(dd**2)) if dd.shape[0] else 0.0
            if abs(fit - fit_prev) < rel_fit and abs(rmse - rmse_prev) < rel_rmse:
                converged = True
                break
            fit_prev = fit
            rmse_prev = rmse
        else:
            dt = 0.0
            tr = 0.0
            for a in range(3):
                dt += (T[a, 3] - T_old[a, 3]) ** 2
                for b in range(3):
                    tr += T[a, b] * T_old[a, b]  # trace(R Rold^T)
            cosang = min(1.0, max(-1.0, (tr - 1.0) / 2.0))
            if math.sqrt(dt) < ttol and math.acos(cosang) < rtol:
                below += 1
            else:
                below = 0
            if below >= stop_window:
                converged = True
                break
    return T, n_iter, status, converged, deficient, X, si, ti, dd


def reject_outliers(
    d: np.ndarray, rule: Literal["none", "std", "x84"], factor: float
) -> np.ndarray:
    """Boolean mask of the distances kept by an outlier rule.

    ``std``: ``d ≤ mean(d) + factor·std(d)`` (paper 1's ICP, factor 2.5 [interpretation]);
    ``x84``: ``|d − median(d)| ≤ factor·MAD`` (Hampel's X84, factor 5.2); ``none``: all.
    """
    if rule == "none" or d.size == 0:
        return np.ones(d.shape, dtype=bool)
    if rule == "std":
        return d <= d.mean() + factor * d.std()
    med = float(np.median(d))
    dev = np.abs(d - med)
    mad = float(np.median(dev))
    return dev <= factor * mad


# --------------------------------------------------------------------------- the method


class ICP:
    """Paper 1's ICP baselines (point-to-point, point-to-plane, X84); see the module docstring.

    Parameters
    ----------
    variant : {"point", "plane", "x84"}
        Error metric / outlier rule.
    max_iter : int, optional
        Maximum iterations (paper 1: 20 for point and x84, 1000 for plane).
    thresholds : {"scale", "paper"}
        Default thresholds: scale-aware (``k·Tr``, default) or paper 1's absolute values.
    max_correspondence_distance : float, optional
        Correspondence gate in metres (overrides ``thresholds``; ``inf`` disables it).
    gate_factor : float
        Gate in multiples of the source resolution ``Tr`` (scale mode).
    translation_tol : float, optional
        Translation-change stop threshold (m), overrides ``thresholds``.
    translation_tol_factor : float
        Translation-change threshold in multiples of ``Tr`` (scale mode).
    rotation_tol : float, optional
        Rotation-change stop threshold (rad), overrides ``thresholds``.
    stop_window : int
        Consecutive iterations that must all be below the thresholds (paper 1: 3).
    std_factor : float
        Factor of the standard-deviation rule (``icp-point``/``icp-plane``; 0 or inf disables).
    x84_factor : float
        Factor of the X84 rule (``icp-x84``): ``|d − med| ≤ x84_factor·MAD``.
    normal_k : int
        Neighbours for the target's PCA normals (``icp-plane``).
    rotation_update : {"rodrigues", "euler-zyx"}
        How the point-to-plane rotation increment is rebuilt from ``ω``.
    center : bool
        Linearise point-to-plane about the source centroid (conditioning).
    open3d_compatible : bool
        Reproduce Open3D's ``registration_icp`` exactly (see the module docstring).
    relative_fitness, relative_rmse : float
        Open3D's stop rule (only used with ``open3d_compatible``; 0 forces ``max_iter``).
    min_points : int
        Clouds with fewer finite points are ``degenerate``.
    degeneracy_ratio : float
        Final information matrix (rotations scaled by the cloud radius) with
        ``λmin/λmax`` below this → ``degenerate`` (e.g. point-to-plane on a single plane).
    """

    def __init__(
        self,
        variant: Literal["point", "plane", "x84"] = "point",
        *,
        max_iter: int | None = None,
        thresholds: Thresholds = "scale",
        max_correspondence_distance: float | None = None,
        gate_factor: float = 10.0,
        translation_tol: float | None = None,
        translation_tol_factor: float = 0.01,
        rotation_tol: float | None = None,
        stop_window: int = 3,
        std_factor: float = 2.5,
        x84_factor: float = 5.2,
        normal_k: int = 10,
        rotation_update: Literal["rodrigues", "euler-zyx"] = "rodrigues",
        center: bool = True,
        open3d_compatible: bool = False,
        relative_fitness: float = 1e-6,
        relative_rmse: float = 1e-6,
        min_points: int = 6,
        degeneracy_ratio: float = 1e-9,
    ) -> None:
        if variant not in ("point", "plane", "x84"):
            raise ConfigError(f"ICP variant must be 'point', 'plane' or 'x84', got {variant!r}")
        if thresholds not in ("scale", "paper"):
            raise ConfigError(f"thresholds must be 'scale' or 'paper', got {thresholds!r}")
        if rotation_update not in ("rodrigues", "euler-zyx"):
            raise ConfigError(
                f"rotation_update must be 'rodrigues' or 'euler-zyx', got {rotation_update!r}"
            )
        self.variant = variant
        self.max_iter = int(
            max_iter if max_iter is not None else (1000 if variant == "plane" else 20)
        )
        if self.max_iter < 0:
            raise ConfigError(f"max_iter must be >= 0, got {max_iter}")
        self.thresholds = thresholds
        for nm, v in (
            ("max_correspondence_distance", max_correspondence_distance),
            ("translation_tol", translation_tol),
            ("rotation_tol", rotation_tol),
        ):
            if v is not None and not (float(v) > 0):
                raise ConfigError(f"{nm} must be > 0, got {v}")
        for nm, v in (
            ("gate_factor", gate_factor),
            ("translation_tol_factor", translation_tol_factor),
        ):
            if not (float(v) > 0 and math.isfinite(float(v))):
                raise ConfigError(f"{nm} must be a positive number, got {v}")
        self.max_correspondence_distance = (
            None if max_correspondence_distance is None else float(max_correspondence_distance)
        )
        self.gate_factor = float(gate_factor)
        self.translation_tol = None if translation_tol is None else float(translation_tol)
        self.translation_tol_factor = float(translation_tol_factor)
        self.rotation_tol = None if rotation_tol is None else float(rotation_tol)
        self.stop_window = max(1, int(stop_window))
        self.std_factor = float(std_factor)
        self.x84_factor = float(x84_factor)
        if self.x84_factor <= 0:
            raise ConfigError(f"x84_factor must be > 0, got {x84_factor}")
        self.normal_k = int(normal_k)
        self.open3d_compatible = bool(open3d_compatible)
        self.rotation_update = "euler-zyx" if self.open3d_compatible else rotation_update
        self.center = False if self.open3d_compatible else bool(center)
        self.relative_fitness = float(relative_fitness)
        self.relative_rmse = float(relative_rmse)
        self.min_points = max(3, int(min_points))
        self.degeneracy_ratio = float(degeneracy_ratio)
        if self.open3d_compatible or variant == "x84":
            self.rule = "none" if self.open3d_compatible else "x84"
        else:
            self.rule = "std" if 0 < self.std_factor < math.inf else "none"
        self.name = f"icp-{variant}"
        if thresholds == "paper":
            self.name += ":paper"

    # ------------------------------------------------------------------ configuration helpers
    @property
    def _needs_resolution(self) -> bool:
        if self.thresholds == "paper":
            return False
        if self.max_correspondence_distance is None:
            return True
        return not self.open3d_compatible and self.translation_tol is None

    def _resolve_thresholds(self, src: PreparedCloud) -> tuple[float, float, float]:
        tr = src.resolution
        if self.max_correspondence_distance is not None:
            gate = self.max_correspondence_distance
        elif self.thresholds == "paper":
            gate = PAPER_GATE
        else:
            gate = self.gate_factor * tr
        if self.translation_tol is not None:
            ttol = self.translation_tol
        elif self.thresholds == "paper":
            ttol = PAPER_TRANSLATION_TOL
        else:
            ttol = self.translation_tol_factor * tr
        if self.rotation_tol is not None:
            rtol = self.rotation_tol
        elif self.thresholds == "paper":
            rtol = PAPER_ROTATION_TOL
        else:
            rtol = ttol / src.radius if src.radius > 0 else PAPER_ROTATION_TOL
        return float(gate), float(ttol), float(rtol)

    # ------------------------------------------------------------------ public API
    def prepare(
        self, points: np.ndarray, *, normals: np.ndarray | None = None, name: str = "cloud"
    ) -> PreparedCloud:
        """Validate a cloud and build its KD-tree, resolution and normals (``icp-plane``).

        ``normals`` (N, 3) replaces the PCA normals (only used for the target side).
        """
        nm: Any = normals if normals is not None else ("pca" if self.variant == "plane" else "none")
        return prepare_cloud(
            points,
            min_points=self.min_points,
            normals=nm,
            normal_k=self.normal_k,
            resolution=self._needs_resolution,
            name=name,
        )

    def register(
        self,
        source: np.ndarray,
        target: np.ndarray,
        *,
        init: np.ndarray | None = None,
        target_normals: np.ndarray | None = None,
    ) -> RegistrationResult:
        """Register ``source`` onto ``target``: ``target ≈ T_target_source @ source``.

        Parameters
        ----------
        source, target : (N, 3), (M, 3) float64
            Clouds in metres (source = scan ``k+1``, target = scan ``k`` in odometry).
        init : (4, 4) float64, optional
            Initial guess of ``T_target_source`` (identity by default).
        target_normals : (M, 3) float64, optional
            Target normals for ``icp-plane`` (PCA, k = ``normal_k``, when omitted).
        """
        src = prepare_cloud(
            source, min_points=self.min_points, resolution=self._needs_resolution, name="source"
        )
        tgt = self.prepare(target, normals=target_normals, name="target")
        result = self.register_prepared(src, tgt, init=init)
        result.timings["prepare"] = result.timings.get("prepare", 0.0) + _total(tgt.timings)
        return result

    def register_prepared(
        self, source: PreparedCloud, target: PreparedCloud, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register two prepared clouds (see :meth:`prepare`); source timings are counted."""
        timings: dict[str, float] = {"prepare": _total(source.timings)}
        info: dict[str, Any] = {
            "variant": self.variant,
            "thresholds": self.thresholds,
            "open3d_compatible": self.open3d_compatible,
            "outlier_rule": self.rule,
            "n_source": int(source.points.shape[0]),
            "n_target": int(target.points.shape[0]),
            "n_dropped_source": source.n_dropped,
            "n_dropped_target": target.n_dropped,
            "n_iterations": 0,
        }
        T0, msg = check_init(init)
        if T0 is None:
            return _failed("failed", msg, np.eye(4), timings, info)
        for cloud, nm in ((source, "source"), (target, "target")):
            if not cloud.ok:
                m = cloud.message if cloud.message.startswith(nm) else f"{nm}: {cloud.message}"
                return _failed(cloud.status, m, T0, timings, info)  # type: ignore[arg-type]
        if self.variant == "plane" and target.normals is None:
            target = prepare_cloud(
                target.points,
                min_points=self.min_points,
                normals="pca",
                normal_k=self.normal_k,
                resolution=False,
                name="target",
            )
        if self._needs_resolution and not np.isfinite(source.resolution):
            source = prepare_cloud(source.points, min_points=self.min_points, name="source")
        gate, ttol, rtol = self._resolve_thresholds(source)
        info.update(
            gate=gate, translation_tol=ttol, rotation_tol=rtol, resolution=source.resolution
        )
        if not (gate > 0):
            return _failed("degenerate", f"invalid gate {gate} m", T0, timings, info)
        return self._iterate(source, target, T0, gate, ttol, rtol, timings, info)

    # ------------------------------------------------------------------ core loop
    def _iterate(
        self,
        source: PreparedCloud,
        target: PreparedCloud,
        T0: np.ndarray,
        gate: float,
        ttol: float,
        rtol: float,
        timings: dict[str, float],
        info: dict[str, Any],
    ) -> RegistrationResult:
        tree = target.tree
        assert tree is not None
        n_src = source.points.shape[0]
        plane = self.variant == "plane"
        min_corr = 6 if plane else 3
        rule = {"none": 0, "std": 1, "x84": 2}[self.rule]
        factor = self.x84_factor if self.rule == "x84" else self.std_factor
        N = target.normals if (plane and target.normals is not None) else np.zeros((0, 3))
        tc = time.perf_counter()
        T, it, code, converged, deficient, X, si, ti, d = _icp_loop(
            source.points,
            tree._Pp,
            tree._perm,
            tree._dim,
            tree._val,
            target.points,
            np.ascontiguousarray(N),
            plane,
            np.ascontiguousarray(T0),
            float(gate),
            self.max_iter,
            rule,
            float(factor),
            self.center,
            self.rotation_update == "euler-zyx",
            self.open3d_compatible,
            self.relative_fitness,
            self.relative_rmse,
            float(ttol),
            float(rtol),
            self.stop_window,
            min_corr,
        )
        timings["iterate"] = time.perf_counter() - tc
        info["n_iterations"] = int(it)
        info["T_estimate"] = T
        if code == 1:
            n_keep = int(reject_outliers(d, self.rule, factor).sum())
            msg = (
                f"iteration {it + 1}: {n_keep} correspondences within the gate "
                f"({gate:.4g} m; need {min_corr}) — initial guess too far or gate too small"
            )
            return _failed("failed", msg, T0, timings, info)
        if code == 2:
            return _failed(
                "degenerate", f"iteration {it + 1}: singular normal equations", T0, timings, info
            )
        # final statistics at the returned estimate
        tc = time.perf_counter()
        keep = reject_outliers(d, self.rule, factor)
        si_k, ti_k, d_k = si[keep], ti[keep], d[keep]
        n_in = int(si_k.size)
        rmse = float(np.sqrt(np.mean(d_k**2))) if n_in else float("nan")
        cov, ratio = self._covariance(X, target, si_k, ti_k, source.radius)
        timings["evaluate"] = time.perf_counter() - tc
        info["information_ratio"] = ratio
        status, message = "ok", ""
        if n_in < min_corr:
            status, message = "failed", f"{n_in} inliers at the final estimate (need {min_corr})"
        elif deficient or not (ratio > self.degeneracy_ratio):
            status = "degenerate"
            message = (
                f"{self.name}: geometry does not constrain 6 DoF "
                f"(information eigenvalue ratio {ratio:.3g})"
            )
        return RegistrationResult(
            T_target_source=T if status == "ok" else T0.copy(),
            covariance=cov,
            fitness=n_in / n_src,
            inlier_rmse=rmse,
            n_correspondences=int(si.size),
            n_inliers=n_in,
            converged=converged,
            status=status,  # type: ignore[arg-type]
            timings=timings,
            message=message,
            info=info,
        )

    def _covariance(
        self, X: np.ndarray, target: PreparedCloud, si: np.ndarray, ti: np.ndarray, radius: float
    ) -> tuple[np.ndarray | None, float]:
        """Twist covariance ``[ρ, φ]`` (left perturbation, target frame) and the degeneracy
        ratio of :func:`information_ratio`."""
        m = si.size
        if m < 6:
            return None, 0.0
        if self.variant == "plane":
            assert target.normals is not None
            JTJ, _, r2 = _plane_system(X, target.points, target.normals, si, ti, np.zeros(3))
            # reorder [φ, ρ] -> [ρ, φ]
            perm = np.array([3, 4, 5, 0, 1, 2])
            A = JTJ[np.ix_(perm, perm)]
            dof = m - 6
        else:
            A, r2 = _point_information(X, target.points, si, ti)
            dof = 3 * m - 6
        ratio = information_ratio(A, X[si].mean(axis=0), radius)
        if not ratio > self.degeneracy_ratio or dof <= 0:
            return None, ratio
        sigma2 = r2 / dof
        try:
            cov = sigma2 * np.linalg.inv(A)
        except np.linalg.LinAlgError:
            return None, ratio
        return 0.5 * (cov + cov.T), ratio


def information_ratio(A: np.ndarray, centre: np.ndarray, radius: float) -> float:
    """``λmin/λmax`` of a twist information matrix, made unit- and origin-free.

    ``A`` (6x6, order ``[ρ, φ]``, left perturbation about the frame origin) is re-expressed
    about ``centre`` (``ρ' = ρ + φ × c``: a cloud far from the sensor no longer couples
    rotation and translation) and the rotation block is scaled by ``radius`` (m) so that both
    blocks are in metres. 0 means a direction the geometry does not constrain.
    """
    G = np.eye(6)
    G[:3, 3:] = hat(np.asarray(centre, dtype=np.float64))
    L = radius if radius > 0 else 1.0
    S = np.diag([1.0, 1.0, 1.0, 1.0 / L, 1.0 / L, 1.0 / L])
    M = S @ G.T @ A @ G @ S
    w = np.linalg.eigvalsh(0.5 * (M + M.T))
    return float(w[0] / w[-1]) if w[-1] > 0 else 0.0


def _total(t: dict[str, float]) -> float:
    return float(sum(t.values()))


def _make(variant: str, spec: str | None, options: dict[str, Any]) -> ICP:
    if spec:
        s = spec.strip().lower()
        if s not in ("paper", "scale"):
            raise ConfigError(f"icp-{variant}: spec must be 'paper' or 'scale', got {spec!r}")
        options = {**options, "thresholds": s}
    return ICP(variant, **options)  # type: ignore[arg-type]


@register_method(
    "icp-point",
    "Point-to-point ICP (Besl & McKay), std-dev outlier rule, 20 iterations (paper 1 baseline)",
    examples=["icp-point", "icp-point:paper"],
)
def _make_icp_point(spec: str | None, **options: Any) -> ICP:
    return _make("point", spec, options)


@register_method(
    "icp-plane",
    "Point-to-plane ICP (Chen & Medioni), PCA normals k=10, 1000 iterations (paper 1 baseline)",
    examples=["icp-plane", "icp-plane:paper"],
)
def _make_icp_plane(spec: str | None, **options: Any) -> ICP:
    return _make("plane", spec, options)


@register_method(
    "icp-x84",
    "Point-to-point ICP with X84 (median ± 5.2·MAD) outlier rejection, 20 iterations (paper 1)",
    examples=["icp-x84", "icp-x84:paper"],
)
def _make_icp_x84(spec: str | None, **options: Any) -> ICP:
    return _make("x84", spec, options)
