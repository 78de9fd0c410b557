"""Paper 1's ICP baselines: point-to-point, point-to-plane and X84 ICP (ALGORITHMS §C.1–C.3).

Method strings (spec ``paper`` / ``scale`` picks the threshold preset, see below):

============ =================================================================================
``icp-point`` Point-to-point ICP (Besl & McKay 1992), Arun/Umeyama SVD per iteration,
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
3. solve the increment (SVD or 6×6 normal equations) and compose it on the left:
   ``T ← ΔT · T``;
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
``open3d.pipelines.registration.registration_icp`` to ~1e-9 (tested).

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
from scipy.spatial import cKDTree

from relnav.errors import ConfigError
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.normals import estimate_normals
from relnav.registration.base import register_method
from relnav.registration.result import RegistrationResult

__all__ = [
    "ICP",
    "PAPER_GATE",
    "PAPER_ROTATION_TOL",
    "PAPER_TRANSLATION_TOL",
    "PreparedCloud",
    "check_init",
    "prepare_cloud",
]

log = logging.getLogger(__name__)

PAPER_GATE = 0.01
"""Paper 1's correspondence gate (m, [interpretation] of the unit)."""
PAPER_TRANSLATION_TOL = 0.01
"""Paper 1's translation-change stop threshold (m)."""
PAPER_ROTATION_TOL = 0.009
"""Paper 1's rotation-change stop threshold (rad, [interpretation] of the unit)."""

Thresholds = Literal["scale", "paper"]


# --------------------------------------------------------------------------- cloud preparation


@dataclass
class PreparedCloud:
    """Per-cloud data shared by the ICP family (reusable across pairs, e.g. in odometry).

    Attributes
    ----------
    points : (N, 3) float64
        Finite points of the cloud (its own frame, m).
    tree : scipy.spatial.cKDTree or None
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
    tree: cKDTree | None = None
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
    tree = cKDTree(P)
    timings["tree"] = time.perf_counter() - t0
    tr = float("nan")
    if resolution:
        t1 = time.perf_counter()
        d, _ = tree.query(P, k=2)
        dd = d[:, 1]
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


# --------------------------------------------------------------------------- small helpers


def _rodrigues(w: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(w))
    if th < 1e-12:
        K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
        return np.eye(3) + K
    k = w / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * (K @ K)


def _euler_zyx(w: np.ndarray) -> np.ndarray:
    """Open3D's ``TransformVector6dToMatrix4d``: ``Rz(w2) · Ry(w1) · Rx(w0)``."""
    ca, sa = math.cos(w[0]), math.sin(w[0])
    cb, sb = math.cos(w[1]), math.sin(w[1])
    cg, sg = math.cos(w[2]), math.sin(w[2])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    Ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    Rz = np.array([[cg, -sg, 0.0], [sg, cg, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Ry @ Rx


def _rot_angle(R: np.ndarray) -> float:
    return float(math.acos(min(1.0, max(-1.0, (np.trace(R) - 1.0) / 2.0))))


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
    workers : int
        Threads for the KD-tree queries (``-1``: all cores).
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
        workers: int = 1,
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
        self.workers = int(workers)
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
    def _correspond(
        self, tree: cKDTree, X: np.ndarray, gate: float, normals: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d, j = tree.query(X, k=1, distance_upper_bound=gate, workers=self.workers)
        ok = np.isfinite(d)
        if normals is not None:
            ok[ok] = np.isfinite(normals[j[ok], 0])
        src_idx = np.flatnonzero(ok)
        return src_idx, j[src_idx].astype(np.int64), d[src_idx]

    def _increment(
        self, X: np.ndarray, target: PreparedCloud, si: np.ndarray, ti: np.ndarray
    ) -> tuple[np.ndarray | None, bool]:
        """Increment ``ΔT`` from the selected pairs; ``(None, _)`` when singular.

        Second value: the system was rank-deficient (solved by pseudo-inverse).
        """
        if self.variant != "plane":
            return _kabsch_pairs(X, target.points, si, ti), False
        assert target.normals is not None
        c = X[si].mean(axis=0) if self.center else np.zeros(3)
        JTJ, JTr, _ = _plane_system(X, target.points, target.normals, si, ti, c)
        deficient = False
        if self.open3d_compatible:
            if not abs(np.linalg.det(JTJ)) > 1e-6:
                return np.eye(4), True
            x = np.linalg.solve(JTJ, -JTr)
        else:
            w, V = np.linalg.eigh(JTJ)
            if not (w[-1] > 0):
                return None, True
            keep = w > w[-1] * 1e-12
            deficient = not keep.all()
            x = -(V[:, keep] @ ((V[:, keep].T @ JTr) / w[keep]))
        if self.rotation_update == "euler-zyx":
            R = _euler_zyx(x[:3])
        else:
            R = _rodrigues(x[:3])
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = c + x[3:] - R @ c
        return T, deficient

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
        assert target.tree is not None
        n_src = source.points.shape[0]
        min_corr = 6 if self.variant == "plane" else 3
        t_nn = t_solve = t_rej = 0.0
        T = T0.copy()
        tc = time.perf_counter()
        X = _transform(source.points, T)
        si, ti, d = self._correspond(target.tree, X, gate, target.normals)
        t_nn += time.perf_counter() - tc
        fit_prev = si.size / n_src
        rmse_prev = float(np.sqrt(np.mean(d**2))) if d.size else 0.0
        below = 0
        converged = False
        deficient = False
        status, message = "ok", ""
        it = 0
        for it in range(1, self.max_iter + 1):
            tc = time.perf_counter()
            keep = reject_outliers(
                d, self.rule, self.x84_factor if self.rule == "x84" else self.std_factor
            )
            t_rej += time.perf_counter() - tc
            n_keep = int(keep.sum())
            if n_keep < min_corr:
                status = "failed"
                message = (
                    f"iteration {it}: {n_keep} correspondences within the gate "
                    f"({gate:.4g} m; need {min_corr}) — initial guess too far or gate too small"
                )
                it -= 1
                break
            tc = time.perf_counter()
            inc, defic = self._increment(X, target, si[keep], ti[keep])
            t_solve += time.perf_counter() - tc
            if inc is None:
                status, message = "degenerate", f"iteration {it}: singular normal equations"
                it -= 1
                break
            deficient |= defic
            T_old = T
            T = inc @ T
            tc = time.perf_counter()
            X = _transform(source.points, T)
            si, ti, d = self._correspond(target.tree, X, gate, target.normals)
            t_nn += time.perf_counter() - tc
            if self.open3d_compatible:
                fit = si.size / n_src
                rmse = float(np.sqrt(np.mean(d**2))) if d.size else 0.0
                if (
                    abs(fit - fit_prev) < self.relative_fitness
                    and abs(rmse - rmse_prev) < self.relative_rmse
                ):
                    converged = True
                    break
                fit_prev, rmse_prev = fit, rmse
            else:
                dt = float(np.linalg.norm(T[:3, 3] - T_old[:3, 3]))
                dr = _rot_angle(T[:3, :3] @ T_old[:3, :3].T)
                below = below + 1 if (dt < ttol and dr < rtol) else 0
                if below >= self.stop_window:
                    converged = True
                    break
        info["n_iterations"] = int(it)
        timings["nn"] = t_nn
        timings["reject"] = t_rej
        timings["solve"] = t_solve
        if status != "ok":
            info["T_estimate"] = T
            return _failed(status, message, T0, timings, info)
        # final statistics at the returned estimate
        tc = time.perf_counter()
        keep = reject_outliers(
            d, self.rule, self.x84_factor if self.rule == "x84" else self.std_factor
        )
        si_k, ti_k, d_k = si[keep], ti[keep], d[keep]
        n_in = int(si_k.size)
        rmse = float(np.sqrt(np.mean(d_k**2))) if n_in else float("nan")
        cov, ratio = self._covariance(X, target, si_k, ti_k, source.radius)
        timings["covariance"] = time.perf_counter() - tc
        info["information_ratio"] = ratio
        if n_in < min_corr:
            status, message = "failed", f"{n_in} inliers at the final estimate (need {min_corr})"
        elif deficient or not (ratio > self.degeneracy_ratio):
            status = "degenerate"
            message = (
                f"{self.name}: geometry does not constrain 6 DoF "
                f"(information eigenvalue ratio {ratio:.3g})"
            )
        info["T_estimate"] = T
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
        """Twist covariance ``[ρ, φ]`` (left perturbation, target frame) and eigenvalue ratio."""
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
        L = radius if radius > 0 else 1.0
        S = np.diag([1.0, 1.0, 1.0, 1.0 / L, 1.0 / L, 1.0 / L])
        w = np.linalg.eigvalsh(S @ A @ S)
        ratio = float(w[0] / w[-1]) if w[-1] > 0 else 0.0
        if not ratio > self.degeneracy_ratio or dof <= 0:
            return None, ratio
        sigma2 = r2 / dof
        try:
            cov = sigma2 * np.linalg.inv(A)
        except np.linalg.LinAlgError:
            return None, ratio
        return 0.5 * (cov + cov.T), ratio


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
