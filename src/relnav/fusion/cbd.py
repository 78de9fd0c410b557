"""CBD baseline of paper 2: curvature-based descriptor coarse alignment in CGA (§G.7).

Kleppe, Tingelstad & Egeland (IEEE T-ASE 16, 811, 2018) align point clouds with a
curvature-based descriptor built from CGA sphere fits. The original is not available here;
this is **[interpretation]** of the summary in paper 2 §1/§2.2.1 (ALGORITHMS §G.7):

1. **Curvature** of every point: algebraic CGA sphere fit to its ``k`` (20) nearest neighbours,
   minimising ``Σ (Xᵢ·S)²`` over IPNS spheres ``S = s + s∞ e∞ + s0 e0`` subject to
   ``S·S = ‖s‖² − 2 s∞ s0 = 1`` (Pratt's normalisation, a 5×5 generalised eigenproblem; planes
   are the spheres with ``s0 = 0``); ``ρ = 1/|s0|``, curvature ``κ = |s0|`` (0 for flat
   neighbourhoods).
2. **Feature points**: points whose curvature is at or above the ``feature_quantile`` (0.5)
   quantile of the cloud's curvature distribution (the "selected part of the distribution"),
   thinned by farthest point sampling to ``max_features`` (300).
3. **Descriptor** of feature ``i``: over the feature points ``j`` within ``radius``, the
   normalised histograms (``n_bins`` = 12 each) of the point-to-sphere distances
   ``‖xᵢ − c_j‖ − ρ_j`` (clipped to ``±radius``), of the point-to-point distances
   ``‖xᵢ − x_j‖ = sqrt(−2 Xᵢ·X_j)`` — both CGA inner products — and a joint histogram of
   (distance shell, curvature rank of ``j`` within its cloud). Default radius
   ``radius_factor = 1.5`` × the LIDAR RMS radius (chosen on li-rotating: smaller radii were
   not discriminative).
   **[interpretation]** the camera cloud is described after voxel-downsampling to the LIDAR's
   resolution (``match_density``), so that both clouds' k-NN neighbourhoods have a similar
   metric size.
4. **Matching**: the ``n_matches`` (5) nearest camera descriptors of each LIDAR feature;
   RANSAC (seeded, ``ransac_iter`` = 20000 minimal 3-point Kabsch hypotheses whose triangles are
   congruent within ``2·inlier_tol``), each scored by the fraction of 200 random LIDAR points
   landing within ``inlier_tol`` of a camera point (default ``2·max(Tr_cam, Tr_lidar)``); the
   motor of the best hypothesis' inlier pairs by the Valkenburg–Dorst eigenproblem
   (:func:`relnav.geometry.cga.estimate_motor`, conformal points on both sides).

``register(source=LIDAR, target=camera)`` returns ``T_camera_lidar`` like ``cga-sphere``.
Fields: ``fitness``/``inlier_rmse`` as ``cga-sphere`` (LIDAR points within ``3·inlier_tol`` of a
camera point after alignment), ``n_correspondences`` = descriptor matches, ``n_inliers`` =
RANSAC inliers. Bad input → ``degenerate``/``failed`` result, never an exception.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from relnav.errors import ConfigError
from relnav.geometry import cga
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.se3 import from_rt
from relnav.registration.base import register_method
from relnav.registration.result import RegistrationResult

__all__ = ["CBDRegistration", "cbd_descriptors", "sphere_fit_curvature"]

log = logging.getLogger(__name__)


def sphere_fit_curvature(
    points: np.ndarray, *, k: int = 20, tree: cKDTree | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-point CGA sphere fit (Pratt normalisation ``S·S = 1``) of the ``k`` nearest neighbours.

    Parameters
    ----------
    points : (N, 3) float64
        Cloud (m).
    k : int
        Neighbourhood size (including the point).

    Returns
    -------
    curvature : (N,) float64
        ``1/ρ`` (1/m); 0 where the fit is flat/degenerate.
    centres : (N, 3) float64
        Sphere centres (m; NaN where degenerate).
    radii : (N,) float64
        Sphere radii (m; ``inf`` where degenerate).
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = P.shape[0]
    if n < 4:
        return np.zeros(n), np.full((n, 3), np.nan), np.full(n, np.inf)
    tree = tree if tree is not None else cKDTree(P)
    kk = int(min(k, n))
    _, idx = tree.query(P, k=kk)
    nb = P[idx.reshape(n, kk)]
    mu = nb.mean(axis=1, keepdims=True)
    scale = np.sqrt(np.mean(np.sum((nb - mu) ** 2, axis=2), axis=1))
    scale = np.where(scale > 0, scale, 1.0)
    X = (nb - mu) / scale[:, None, None]  # conditioned local coordinates
    # X·S = x·s − s∞ − ½‖x‖² s0 for S = s + s∞ e∞ + s0 e0; rows [x, −1, −½‖x‖²]
    D = np.concatenate([X, -np.ones((n, kk, 1)), -0.5 * np.sum(X * X, axis=2)[..., None]], 2)
    A = np.einsum("nki,nkj->nij", D, D)
    Nm = np.zeros((5, 5))
    Nm[:3, :3] = np.eye(3)
    Nm[3, 4] = Nm[4, 3] = -1.0  # S·S = ‖s‖² − 2 s∞ s0 (Pratt)
    vals, vecs = np.linalg.eig(Nm @ A)  # Nm⁻¹ = Nm
    vals, vecs = vals.real, vecs.real
    q = np.einsum("nai,ab,nbi->ni", vecs, Nm, vecs)
    cand = np.where(q > 1e-12, vals, np.inf)
    j = np.argmin(cand, axis=1)
    v = vecs[np.arange(n), :, j] / np.sqrt(np.maximum(q[np.arange(n), j], 1e-300))[:, None]
    s0 = np.abs(v[:, 4])
    ok = np.isfinite(cand[np.arange(n), j]) & (s0 > 1e-6)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = v[:, :3] / v[:, 4:5]
    curv = np.where(ok, s0 / scale, 0.0)  # ρ = 1/|s0| in conditioned units
    centres = np.where(ok[:, None], mu[:, 0, :] + c * scale[:, None], np.nan)
    radii = np.where(ok, scale / np.where(ok, s0, 1.0), np.inf)
    return curv, centres, radii


def _fps(P: np.ndarray, n: int) -> np.ndarray:
    from relnav.fusion.cross_source import fps_from_centroid

    return fps_from_centroid(P, n)


def cbd_descriptors(
    points: np.ndarray,
    *,
    k: int = 20,
    feature_quantile: float = 0.5,
    max_features: int = 300,
    radius: float,
    n_bins: int = 12,
) -> tuple[np.ndarray, np.ndarray]:
    """Feature points and their curvature-based descriptors (module docstring, steps 1–3).

    Returns
    -------
    feature_idx : (F,) int64
        Indices of the feature points.
    descriptors : (F, 3·n_bins) float32
        L1-normalised histograms (zero rows for isolated features).
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tree = cKDTree(P)
    curv, centres, radii = sphere_fit_curvature(P, k=k, tree=tree)
    thr = np.quantile(curv, feature_quantile) if P.shape[0] else 0.0
    cand = np.flatnonzero((curv >= thr) & np.isfinite(radii))
    if cand.size > max_features:
        cand = np.sort(cand[_fps(P[cand], max_features)])
    F = cand.size
    D = np.zeros((F, 3 * n_bins), dtype=np.float32)
    if F == 0:
        return cand, D
    X = P[cand]
    Cf, Rf = centres[cand], radii[cand]
    # curvature rank within the cloud (robust to the sources' different noise levels)
    crank = np.searchsorted(np.sort(curv[cand]), curv[cand], side="right") / F
    lists = cKDTree(X).query_ball_point(X, r=radius)
    edges_s = np.linspace(-radius, radius, n_bins + 1)
    edges_d = np.linspace(0.0, radius, n_bins + 1)
    nd = max(n_bins // 3, 1)
    for i, li in enumerate(lists):
        j = np.asarray([x for x in li if x != i], dtype=np.int64)
        if j.size == 0:
            continue
        s = np.clip(np.linalg.norm(X[i] - Cf[j], axis=1) - Rf[j], -radius, radius)
        dd = np.sqrt(-2.0 * cga.point_point_inner(X[i], X[j]))
        hs, _ = np.histogram(s, bins=edges_s)
        hd, _ = np.histogram(dd, bins=edges_d)
        # joint (distance, curvature rank) histogram: 3 distance shells x n_bins/3 ranks
        ic = np.minimum((crank[j] * (n_bins // nd)).astype(np.int64), n_bins // nd - 1)
        idd = np.minimum((dd / radius * nd).astype(np.int64), nd - 1)
        hj = np.bincount(idd * (n_bins // nd) + ic, minlength=n_bins)[:n_bins]
        D[i, :n_bins] = hs / j.size
        D[i, n_bins : 2 * n_bins] = hd / j.size
        D[i, 2 * n_bins :] = hj / j.size
    return cand, D


class CBDRegistration:
    """Curvature-based-descriptor coarse alignment (paper 2's CBD baseline).

    Parameters
    ----------
    k : int
        Neighbours of the curvature sphere fit.
    feature_quantile : float
        Curvature quantile above which points are features.
    max_features : int
        Features kept per cloud (FPS).
    radius : float, optional
        Descriptor radius (m); default ``radius_factor`` × the LIDAR RMS radius.
    radius_factor : float
        See ``radius``.
    n_bins : int
        Bins per histogram.
    ransac_iter : int
        RANSAC hypotheses.
    inlier_tol : float, optional
        RANSAC inlier distance (m); default ``2·max(Tr_camera, Tr_lidar)``.
    n_matches : int
        Nearest camera descriptors matched to each LIDAR feature.
    match_density : bool
        Describe the camera cloud voxel-downsampled to the LIDAR's resolution.
    seed : int
        RANSAC seed (recorded in ``info``).
    min_fitness : float
        Final fitness below this → ``failed``.
    """

    name = "cbd"

    def __init__(
        self,
        *,
        k: int = 20,
        feature_quantile: float = 0.5,
        max_features: int = 300,
        radius: float | None = None,
        radius_factor: float = 1.5,
        n_bins: int = 12,
        ransac_iter: int = 20000,
        inlier_tol: float | None = None,
        n_matches: int = 5,
        match_density: bool = True,
        seed: int = 0,
        min_fitness: float = 0.2,
    ) -> None:
        if int(k) != k or k < 5:
            raise ConfigError(f"k must be an integer >= 5, got {k}")
        if not 0 <= feature_quantile < 1:
            raise ConfigError(f"feature_quantile must be in [0, 1), got {feature_quantile}")
        for nm, v in (
            ("max_features", max_features),
            ("n_bins", n_bins),
            ("ransac_iter", ransac_iter),
        ):
            if int(v) != v or v < 1:
                raise ConfigError(f"{nm} must be a positive integer, got {v}")
        for nm, v in (("radius", radius), ("inlier_tol", inlier_tol)):
            if v is not None and not (float(v) > 0 and math.isfinite(float(v))):
                raise ConfigError(f"{nm} must be a positive number of metres, got {v}")
        if not float(radius_factor) > 0:
            raise ConfigError(f"radius_factor must be > 0, got {radius_factor}")
        self.k = int(k)
        self.feature_quantile = float(feature_quantile)
        self.max_features = int(max_features)
        self.radius = None if radius is None else float(radius)
        self.radius_factor = float(radius_factor)
        self.n_bins = int(n_bins)
        self.ransac_iter = int(ransac_iter)
        self.inlier_tol = None if inlier_tol is None else float(inlier_tol)
        if int(n_matches) != n_matches or n_matches < 1:
            raise ConfigError(f"n_matches must be a positive integer, got {n_matches}")
        self.n_matches = int(n_matches)
        self.match_density = bool(match_density)
        self.seed = int(seed)
        self.min_fitness = float(min_fitness)

    def __repr__(self) -> str:
        return f"CBDRegistration(k={self.k}, seed={self.seed})"

    def register(
        self, source: np.ndarray, target: np.ndarray, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register the LIDAR cloud ``source`` onto the camera cloud ``target`` (``init`` unused).

        Returns
        -------
        RegistrationResult
            ``T_target_source = T_camera_lidar``.
        """
        from relnav.fusion.cross_source import _clean

        t_start = time.perf_counter()
        timings: dict[str, float] = {}
        info: dict[str, Any] = {"seed": self.seed}
        P, _, msg_p = _clean(source, "source (LIDAR)")
        Q, _, msg_q = _clean(target, "target (camera)")

        def flagged(status: str, message: str) -> RegistrationResult:
            timings["total"] = time.perf_counter() - t_start
            return RegistrationResult(
                status=status,  # type: ignore[arg-type]
                message=message,
                timings=timings,
                info=info,
            )

        if msg_p or msg_q:
            return flagged("failed", msg_p or msg_q)
        if P.shape[0] < self.k or Q.shape[0] < self.k:
            return flagged("degenerate", f"too few points: LIDAR {P.shape[0]}, camera {Q.shape[0]}")
        tr = max(mean_resolution(P), mean_resolution(Q))
        if not math.isfinite(tr):
            return flagged("degenerate", "a cloud has fewer than 2 distinct points")
        tol = self.inlier_tol if self.inlier_tol is not None else 2.0 * tr
        rms = float(np.sqrt(np.mean(np.sum((P - P.mean(0)) ** 2, axis=1))))
        radius = self.radius if self.radius is not None else self.radius_factor * rms
        info.update(inlier_tol=tol, radius=radius)
        t0 = time.perf_counter()
        kw = dict(
            k=self.k,
            feature_quantile=self.feature_quantile,
            max_features=self.max_features,
            radius=radius,
            n_bins=self.n_bins,
        )
        # describe the camera cloud at the LIDAR's density (comparable k-NN scales)
        Qd = Q
        tr_p = mean_resolution(P)
        if self.match_density and mean_resolution(Q) < tr_p:
            from relnav.features.keypoints import voxel_downsample

            Qd = voxel_downsample(Q, tr_p)
        fp, Dp = cbd_descriptors(P, **kw)
        fq, Dq = cbd_descriptors(Qd, **kw)
        timings["describe"] = time.perf_counter() - t0
        info.update(n_features_lidar=int(fp.size), n_features_camera=int(fq.size))
        if fp.size < 3 or fq.size < 3:
            return flagged("degenerate", "fewer than 3 feature points in a cloud")
        t0 = time.perf_counter()
        kn = int(min(self.n_matches, fq.size))
        _, nn = cKDTree(Dq.astype(np.float64)).query(Dp.astype(np.float64), k=kn)
        nn = nn.reshape(fp.size, kn)
        src = np.repeat(P[fp], kn, axis=0)
        dst = Qd[fq[nn.ravel()]]
        timings["match"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        rng = np.random.default_rng(self.seed)
        probe = P[rng.choice(P.shape[0], min(200, P.shape[0]), replace=False)]
        T = self._ransac(src, dst, probe, cKDTree(Q), tol, rng)
        timings["ransac"] = time.perf_counter() - t0
        if T is None:
            return flagged("failed", "RANSAC found no consistent 3-point hypothesis")
        res = src @ T[:3, :3].T + T[:3, 3] - dst
        best = np.sum(res * res, axis=1) < tol * tol
        if best.sum() >= 3:
            motor, _ = cga.estimate_motor(cga.up(src[best]), cga.up(dst[best]))
            R, t = cga.motor_to_rt(motor)
            T = from_rt(R, t)
        R, t = T[:3, :3], T[:3, 3]
        d, _ = cKDTree(Q).query(P @ R.T + t, distance_upper_bound=3.0 * tol)
        inl = np.isfinite(d)
        fitness = float(inl.mean())
        rmse = float(np.sqrt(np.mean(d[inl] ** 2))) if inl.any() else float("nan")
        timings["total"] = time.perf_counter() - t_start
        ok = fitness >= self.min_fitness
        return RegistrationResult(
            T_target_source=T if ok else np.eye(4),
            fitness=fitness,
            inlier_rmse=rmse,
            n_correspondences=int(src.shape[0]),
            n_inliers=int(best.sum()),
            converged=ok,
            status="ok" if ok else "failed",
            timings=timings,
            message="" if ok else f"fitness {fitness:.3f} < min_fitness {self.min_fitness}",
            info=info,
        )

    def _ransac(
        self,
        src: np.ndarray,
        dst: np.ndarray,
        probe: np.ndarray,
        tree_q: cKDTree,
        tol: float,
        rng: np.random.Generator,
    ) -> np.ndarray | None:
        """Best 3-point hypothesis by the fraction of ``probe`` points near the camera cloud."""
        n = src.shape[0]
        H = self.ransac_iter
        idx = rng.integers(0, n, size=(H, 3))
        idx = idx[(idx[:, 0] != idx[:, 1]) & (idx[:, 0] != idx[:, 2]) & (idx[:, 1] != idx[:, 2])]
        A, B = src[idx], dst[idx]  # (H, 3, 3)
        # reject hypotheses whose triangles are not congruent (cheap pre-test)
        ea = np.linalg.norm(A - np.roll(A, 1, axis=1), axis=2)
        eb = np.linalg.norm(B - np.roll(B, 1, axis=1), axis=2)
        good = np.all(np.abs(ea - eb) < 2.0 * tol, axis=1) & (ea.min(axis=1) > 2.0 * tol)
        if not good.any():
            return None
        A, B = A[good], B[good]
        H = A.shape[0]
        ma, mb = A.mean(axis=1, keepdims=True), B.mean(axis=1, keepdims=True)
        M = np.einsum("hki,hkj->hij", A - ma, B - mb)
        U, _, Vt = np.linalg.svd(M)
        dt = np.sign(np.linalg.det(np.einsum("hij,hjk->hik", U, Vt)))
        D = np.tile(np.eye(3), (H, 1, 1))
        D[:, 2, 2] = dt
        R = np.einsum("hji,hjk,hlk->hil", Vt, D, U)  # V D Uᵀ
        t = mb[:, 0] - np.einsum("hij,hj->hi", R, ma[:, 0])
        best_score, best_T = -1.0, None
        for s in range(0, H, 128):
            Rs, ts = R[s : s + 128], t[s : s + 128]
            X = np.einsum("hij,nj->hni", Rs, probe) + ts[:, None, :]
            d, _ = tree_q.query(X.reshape(-1, 3), distance_upper_bound=tol)
            score = np.isfinite(d).reshape(Rs.shape[0], -1).mean(axis=1)
            j = int(np.argmax(score))
            if score[j] > best_score:
                best_score, best_T = float(score[j]), from_rt(Rs[j], ts[j])
        return best_T


@register_method(
    "cbd",
    "Paper 2 baseline: curvature-based descriptor (CGA sphere fits) + RANSAC (Kleppe et al. 2018)",
    examples=["cbd"],
)
def _make_cbd(spec: str | None, **options: Any) -> CBDRegistration:
    if spec:
        raise ConfigError(f"cbd takes no spec, got {spec!r}")
    return CBDRegistration(**options)
