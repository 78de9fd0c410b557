"""External baselines behind the relnav :class:`~relnav.registration.base.Registration` interface.

Method strings (optional extra ``[baselines]``: ``open3d-cpu``, ``kiss-icp``, ``small_gicp``):

==================== ===========================================================================
``o3d-fpfh-ransac``  Open3D global registration: voxel downsampling, normals, FPFH, RANSAC on
                     FPFH matches (seeded), then point-to-plane ICP refinement (``init`` ignored).
``o3d-icp-point``    Open3D point-to-point ICP from ``init``.
``o3d-icp-plane``    Open3D point-to-plane ICP from ``init`` (target normals by Open3D PCA).
``kiss-icp``         KISS-ICP (Vizzo et al. 2023) fed frame by frame; stateful, see below.
``small-gicp``       small_gicp ``align`` (spec: ``gicp`` default, ``icp``, ``plane_icp``,
                     ``vgicp``), e.g. ``small-gicp:vgicp``.
==================== ===========================================================================

The libraries are imported lazily when a method is constructed; a missing one raises
:class:`~relnav.errors.ConfigError` naming the ``[baselines]`` extra.

**Scale-aware parameters.** The libraries' defaults are tuned for cars and rooms (KISS-ICP: 1 m
voxels at 100 m range; small_gicp: 0.25 m downsampling, 1 m gate). Space targets span 1 m to
800 m, so every length is derived from the source resolution ``Tr`` (mean nearest-neighbour
distance, :func:`relnav.geometry.neighbors.mean_resolution`; KISS-ICP uses the target's ``Tr``
when it builds its pipeline) and from the clouds' ranges. Every factor is an option, and the
values actually used are recorded in ``result.info``.

**Dense scans** (more than ``dense_points`` points, default 5 000 as the point budget of relnav's
own methods: real sensors, not paper 1's clouds, which all have fewer): KISS-ICP and small_gicp
then use their own recommended, range-based downsampling, which is what makes them fast on such
scans — KISS-ICP's voxel ``max_range / 100`` (its default when no voxel is given), small_gicp's
``0.25 m`` downsampling and ``1 m`` gate of its 100 m-range examples scaled to the scan
(``max range / 400`` and ``4 ×`` that) **[interpretation]**. ``info["settings"]`` says which
(``"sparse"``: ``Tr``-based, ``"dense"``: range-based); ``relnav methods`` lists the rule.

**KISS-ICP statefulness.** KISS-ICP registers each new frame against a local voxel map of the
previous frames, with a constant-velocity prediction and an adaptive correspondence threshold.
Odometry calls ``register(source=scan k+1, target=scan k)`` in order, so the adapter keeps one
pipeline alive while the calls are consecutive — the ``target`` of a call is the cloud that was
the ``source`` of the previous call (same content, checked by a hash of the float64 bytes) — and
registers only the new source. Otherwise (first call, out-of-order pair, the source leaving the
configured range, ``stateful=False`` or a library error) it rebuilds a fresh pipeline from the
target, registers the target as its first frame (empty map: pose = identity) and then the source.
The result is the relative step between the two frames, ``T_target_source =
inv(pose_k) @ pose_{k+1}`` (KISS-ICP's ``last_delta``). A given ``init`` replaces KISS-ICP's own
constant-velocity prediction for that frame (``last_delta = init`` before ``register_frame``); with
``init=None`` KISS-ICP's own prediction is used (identity for a fresh pipeline). Deskewing is
off (relnav scans carry no per-point times).

**Result fields** (all methods, recomputed by relnav at the final estimate): ``fitness`` =
fraction of the source points (small_gicp: its downsampled source) with a target point within
the method's final gate (``info["gate"]``: the ICP gate; the refinement gate for
``o3d-fpfh-ransac``; ``3σ`` of KISS-ICP's adaptive threshold; small_gicp's
``max_correspondence_distance``) — Open3D's definition, divided by the SOURCE count;
``inlier_rmse`` = RMS distance of those pairs (m); ``n_inliers`` = their count;
``n_correspondences`` = putative pairs (the downsampled source points, each with one FPFH match,
for ``o3d-fpfh-ransac``; otherwise ``n_inliers``). ``covariance`` is the covariance of the twist
``δ = [ρ (m), φ (rad)]`` of a LEFT perturbation ``T_true = exp_se3(δ) · T`` (target frame, about
its origin), as relnav's own ICP: for small_gicp it is built from its Hessian ``H`` (see
:class:`SmallGICPRegistration`); for the others it is the Gauss–Newton covariance
``σ² (JᵀJ)⁻¹`` of the final nearest-neighbour pairs (point-to-plane rows ``[nᵀ, (p×n)ᵀ]`` when
the method used target normals, point-to-point blocks ``[I, −[p]×]`` otherwise) with ``σ²`` the
residual variance. ``info["degeneracy_ratio"]`` is ``λmin/λmax`` of that information matrix
re-expressed about the cloud centroid with the rotation block scaled by the cloud radius
(:func:`information_degeneracy`); below the ``degeneracy_ratio`` option (1e-9) the status is
``degenerate``. Empty, tiny, coincident or collinear clouds, a bad ``init``, fewer than 3 inliers
after alignment, or an exception inside the library give a ``degenerate``/``failed`` result with a
``message`` — never an exception.
"""

from __future__ import annotations

import hashlib
import importlib
import logging
import math
import time
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.geometry.rotations import hat, rotation_angle
from relnav.geometry.se3 import adjoint
from relnav.registration.base import register_method
from relnav.registration.icp import PreparedCloud, check_init, prepare_cloud
from relnav.registration.result import RegistrationResult, RegistrationStatus

__all__ = [
    "KissICPRegistration",
    "KissFrame",
    "Open3DFPFHRansac",
    "Open3DICP",
    "SmallGICPRegistration",
    "require",
    "information_degeneracy",
    "twist_covariance_from_hessian",
]

log = logging.getLogger(__name__)

_DISTRIBUTIONS = {
    "open3d": "open3d-cpu",
    "kiss_icp": "kiss-icp",
    "small_gicp": "small_gicp",
    "kiss_matcher": "kiss-matcher",
}


def require(module: str, method: str) -> ModuleType:
    """Import the optional dependency ``module`` needed by ``method``.

    Raises
    ------
    ConfigError
        The module is not installed (or cannot be imported); the message names the
        ``[baselines]`` extra.
    """
    try:
        return importlib.import_module(module)
    except ImportError as e:
        dist = _DISTRIBUTIONS.get(module, module)
        raise ConfigError(
            f"method {method!r} needs the optional dependency {dist}: "
            f"pip install 'relnav[baselines]' ({type(e).__name__}: {e})"
        ) from None


# --------------------------------------------------------------------------- shared helpers


def _positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    v = float(value)
    ok = math.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        raise ConfigError(
            f"{name} must be a {'non-negative' if allow_zero else 'positive'} number, got {value!r}"
        )
    return v


def _flag(
    status: RegistrationStatus, message: str, T: np.ndarray, timings: dict, info: dict
) -> RegistrationResult:
    log.debug("registration %s: %s", status, message)
    return RegistrationResult(
        T_target_source=np.array(T, dtype=np.float64),
        status=status,
        message=message,
        timings=timings,
        info=info,
    )


def _total(t: dict[str, float]) -> float:
    return float(sum(t.values()))


def twist_covariance_from_hessian(H: np.ndarray, T: np.ndarray) -> np.ndarray | None:
    """Covariance of relnav's twist from a small_gicp Hessian.

    small_gicp linearises ``T · exp(δ)`` (RIGHT perturbation, source frame) with
    ``δ = [φ (rotation), ρ (translation)]``. relnav uses a LEFT perturbation in the target frame
    ordered ``[ρ, φ]``: ``C = Ad_T P H⁻¹ Pᵀ Ad_Tᵀ`` with ``P`` the block swap.

    Parameters
    ----------
    H : (6, 6) float64
        small_gicp's ``RegistrationResult.H``.
    T : (4, 4) float64
        The estimate ``T_target_source``.

    Returns
    -------
    (6, 6) float64 or None
        None when ``H`` is not finite or not positive definite.
    """
    H = np.asarray(H, dtype=np.float64)
    if H.shape != (6, 6) or not np.isfinite(H).all():
        return None
    Hs = 0.5 * (H + H.T)
    lam, V = np.linalg.eigh(Hs)
    if not lam[0] > 1e-14 * max(lam[-1], 1e-300):
        return None
    C_rot_first = (V / lam) @ V.T
    perm = np.r_[3:6, 0:3]
    C_right = C_rot_first[np.ix_(perm, perm)]
    A = adjoint(T)
    C = A @ C_right @ A.T
    return 0.5 * (C + C.T)


def information_degeneracy(A: np.ndarray, centre: np.ndarray, radius: float) -> float:
    """``λmin/λmax`` of an information matrix re-expressed about ``centre``, rotation × radius.

    ``A`` (6×6) is the information of a twist ``[ρ, φ]`` about the frame origin. A cloud far
    from its frame origin (a target 20 m or 20 km ahead of the sensor) couples rotation and
    translation through the lever arm, so ``A`` is first moved to the cloud centre
    (``Ad_Cᵀ A Ad_C``, ``C`` the translation to ``centre``) and the rotation block scaled by the
    cloud radius (m); the ratio is then scale-free and ~0 only for real degeneracies (e.g. a
    single plane under point-to-plane). Returns 0 for non-finite input.
    """
    Ad = np.eye(6)
    Ad[:3, 3:] = hat(np.asarray(centre, dtype=np.float64))
    Ac = Ad.T @ A @ Ad
    scale = np.r_[np.ones(3), np.full(3, 1.0 / max(radius, 1e-12))]
    As = Ac * scale[:, None] * scale[None, :]
    if not np.isfinite(As).all():
        return 0.0
    ev = np.linalg.eigvalsh(0.5 * (As + As.T))
    return float(max(ev[0], 0.0) / ev[-1]) if ev[-1] > 0 else 0.0


def _information(
    moved: np.ndarray, normals: np.ndarray | None, radius: float
) -> tuple[np.ndarray, float]:
    """Gauss–Newton information ``JᵀJ`` (left perturbation, ``[ρ, φ]``) and degeneracy ratio."""
    if normals is None:
        n = moved.shape[0]
        s = moved.sum(axis=0)
        A = np.zeros((6, 6))
        A[:3, :3] = n * np.eye(3)
        A[:3, 3:] = -hat(s)
        A[3:, :3] = hat(s)
        A[3:, 3:] = np.sum(moved * moved) * np.eye(3) - moved.T @ moved
    else:
        J = np.hstack([normals, np.cross(moved, normals)])
        A = J.T @ J
    return A, information_degeneracy(A, moved.mean(axis=0), radius)


# --------------------------------------------------------------------------- dense scans

DENSE_POINTS = 5_000
"""Scans with more points get the peers' own range-based downsampling (module docstring)."""


def _dense_points(v: Any) -> int | None:
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
        raise ConfigError(f"dense_points must be a positive integer or None, got {v!r}")
    return int(v)


def _is_dense(n: int, threshold: int | None) -> bool:
    return threshold is not None and n > threshold


def _max_range(points: np.ndarray) -> float:
    return float(np.sqrt(np.einsum("ij,ij->i", points, points).max())) if points.size else 0.0


@dataclass
class _Fit:
    fitness: float = 0.0
    rmse: float = float("nan")
    n_inliers: int = 0
    covariance: np.ndarray | None = None
    degeneracy_ratio: float = float("nan")


def _evaluate(
    T: np.ndarray,
    source: np.ndarray,
    target: PreparedCloud,
    gate: float,
    *,
    normals: np.ndarray | None = None,
    radius: float,
    covariance: bool = True,
) -> _Fit:
    """Fitness, RMSE, covariance and degeneracy ratio at the final estimate (see module doc)."""
    if source.shape[0] == 0 or target.tree is None:
        return _Fit()
    moved = source @ T[:3, :3].T + T[:3, 3]
    d, j = target.tree.query(moved, k=1, distance_upper_bound=gate)
    keep = np.isfinite(d)
    n_in = int(keep.sum())
    fit = _Fit(fitness=n_in / source.shape[0], n_inliers=n_in)
    if n_in == 0:
        return fit
    fit.rmse = float(np.sqrt(np.mean(d[keep] ** 2)))
    p = moved[keep]
    q = target.points[j[keep]]
    nrm = None
    if normals is not None:
        nrm = normals[j[keep]]
        good = np.isfinite(nrm).all(axis=1)
        if good.sum() >= 6:
            p, q, nrm = p[good], q[good], nrm[good]
        else:
            nrm = None
    A, ratio = _information(p, nrm, radius)
    fit.degeneracy_ratio = ratio
    if covariance:
        if nrm is None:
            r2 = float(np.sum((p - q) ** 2))
            dof = 3 * p.shape[0] - 6
        else:
            r2 = float(np.sum(np.einsum("ij,ij->i", p - q, nrm) ** 2))
            dof = p.shape[0] - 6
        if dof > 0 and ratio > 1e-14:
            lam, V = np.linalg.eigh(0.5 * (A + A.T))
            if lam[0] > 0:
                C = (V / lam) @ V.T * (r2 / dof)
                fit.covariance = 0.5 * (C + C.T)
    return fit


def _fingerprint(points: np.ndarray) -> str:
    P = np.ascontiguousarray(points, dtype=np.float64)
    h = hashlib.blake2b(P.tobytes(), digest_size=16)
    h.update(str(P.shape).encode())
    return h.hexdigest()


class _ExternalBase:
    """Validation, timing and exception handling shared by the adapters."""

    name: str = ""
    #: the final status is "degenerate" below this λmin/λmax of the scaled information matrix
    degeneracy_ratio: float = 1e-9
    min_points: int = 6

    def _validate(
        self, source: Any, target: Any, init: Any, timings: dict, info: dict
    ) -> tuple[PreparedCloud, PreparedCloud, np.ndarray] | RegistrationResult:
        t0 = time.perf_counter()
        T0, msg = check_init(init)
        if T0 is None:
            return _flag("failed", msg, np.eye(4), timings, info)
        src = source if isinstance(source, PreparedCloud) else self._prepare(source, "source")
        tgt = target if isinstance(target, PreparedCloud) else self._prepare(target, "target")
        timings["prepare"] = time.perf_counter() - t0
        info.update(
            n_source=int(src.points.shape[0]),
            n_target=int(tgt.points.shape[0]),
            n_dropped_source=src.n_dropped,
            n_dropped_target=tgt.n_dropped,
        )
        for cloud, nm in ((src, "source"), (tgt, "target")):
            if not cloud.ok:
                m = cloud.message
                if m.startswith("cloud"):
                    m = nm + m[len("cloud") :]
                elif not m.startswith(nm):
                    m = f"{nm}: {m}"
                return _flag(cloud.status, m, T0, timings, info)  # type: ignore[arg-type]
        if not (np.isfinite(src.resolution) and src.resolution > 0):
            return _flag("degenerate", "source resolution is undefined", T0, timings, info)
        info["resolution"] = src.resolution
        return src, tgt, T0

    def _prepare(self, points: Any, name: str) -> PreparedCloud:
        return prepare_cloud(points, min_points=self.min_points, resolution=True, name=name)

    def _finish(
        self,
        T: np.ndarray,
        source_points: np.ndarray,
        target: PreparedCloud,
        gate: float,
        radius: float,
        *,
        converged: bool,
        timings: dict,
        info: dict,
        normals: np.ndarray | None = None,
        n_correspondences: int | None = None,
        covariance: np.ndarray | None = None,
        compute_covariance: bool = True,
        fallback: np.ndarray | None = None,
    ) -> RegistrationResult:
        """Evaluate ``T`` and build the result; a non-``ok`` result carries ``fallback``
        (the initial guess; identity by default) and keeps ``T`` in ``info["T_estimate"]``."""
        fallback = np.eye(4) if fallback is None else fallback
        t0 = time.perf_counter()
        if not np.isfinite(T).all():
            return _flag(
                "failed", "the library returned a non-finite transform", fallback, timings, info
            )
        fit = _evaluate(
            T,
            source_points,
            target,
            gate,
            normals=normals,
            radius=radius,
            covariance=compute_covariance and covariance is None,
        )
        timings["evaluate"] = time.perf_counter() - t0
        info["gate"] = gate
        info["degeneracy_ratio"] = fit.degeneracy_ratio
        status: RegistrationStatus = "ok"
        message = ""
        if fit.n_inliers < 3:
            status, message = (
                "failed",
                f"{fit.n_inliers} source points within {gate:.3g} m of the target after alignment",
            )
        elif fit.degeneracy_ratio < self.degeneracy_ratio:
            status = "degenerate"
            message = f"geometry does not fix 6 DoF (λmin/λmax = {fit.degeneracy_ratio:.2e})"
        cov = covariance if covariance is not None else fit.covariance
        if status != "ok":
            info["T_estimate"] = np.array(T, dtype=np.float64)
        return RegistrationResult(
            T_target_source=np.array(T if status == "ok" else fallback, dtype=np.float64),
            covariance=cov,
            fitness=fit.fitness,
            inlier_rmse=fit.rmse,
            n_correspondences=fit.n_inliers if n_correspondences is None else n_correspondences,
            n_inliers=fit.n_inliers,
            converged=bool(converged),
            status=status,
            timings=timings,
            message=message,
            info=info,
        )

    def register(
        self, source: np.ndarray, target: np.ndarray, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register ``source`` onto ``target``: ``target ≈ T_target_source @ source``.

        Parameters
        ----------
        source, target : (N, 3), (M, 3) float64
            Clouds in metres in their sensor frames (odometry: scan ``k+1`` and scan ``k``).
        init : (4, 4) float64, optional
            Initial guess of ``T_target_source`` (identity when omitted).
        """
        timings: dict[str, float] = {}
        info: dict[str, Any] = {"method": self.name}
        v = self._validate(source, target, init, timings, info)
        if isinstance(v, RegistrationResult):
            return v
        src, tgt, T0 = v
        try:
            return self._run(src, tgt, T0, timings, info)
        except Exception as e:  # library errors must not stop a run: flag them
            log.warning("%s raised %s: %s", self.name, type(e).__name__, e)
            self._on_error()
            return _flag("failed", f"{type(e).__name__}: {e}", T0, timings, info)

    def _on_error(self) -> None:
        """Reset internal state after a library error (stateful adapters)."""

    def _run(
        self, src: PreparedCloud, tgt: PreparedCloud, T0: np.ndarray, timings: dict, info: dict
    ) -> RegistrationResult:  # pragma: no cover - abstract
        raise NotImplementedError


def _o3d_cloud(o3d: ModuleType, points: np.ndarray) -> Any:
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64))
    return pcd


def _o3d_normals(o3d: ModuleType, pcd: Any, radius: float, max_nn: int) -> None:
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=max_nn))
    pcd.orient_normals_towards_camera_location(np.zeros(3))  # sensor at the scan origin


def _step_small(Ta: np.ndarray, Tb: np.ndarray, ttol: float, rtol: float) -> bool:
    D = np.linalg.inv(Ta) @ Tb
    return bool(np.linalg.norm(D[:3, 3]) < ttol and float(rotation_angle(D[:3, :3])) < rtol)


# --------------------------------------------------------------------------- Open3D ICP


class Open3DICP(_ExternalBase):
    """Open3D ``registration_icp`` (point-to-point or point-to-plane) from ``init``.

    Parameters
    ----------
    variant : {"point", "plane"}
        Error metric.
    max_iter : int
        Maximum iterations (default 30, Open3D's default).
    gate_factor : float
        Correspondence gate ``max_correspondence_distance`` in multiples of the source
        resolution ``Tr`` (default 10, as relnav's ICP).
    max_correspondence_distance : float, optional
        Absolute gate in metres (overrides ``gate_factor``).
    normal_radius_factor : float
        Target normal radius in multiples of ``Tr`` (``plane``; hybrid search with
        ``normal_max_nn`` neighbours), oriented towards the sensor (origin).
    normal_max_nn : int
        Maximum neighbours for the normals.
    relative_fitness, relative_rmse : float
        Open3D's stop rule.
    convergence_tol_factor : float
        ``converged`` is reported when one more ICP iteration moves the estimate by less than
        ``convergence_tol_factor · Tr`` and ``convergence_tol_factor · Tr / radius`` rad (Open3D
        does not report convergence itself).
    covariance : bool
        Compute the twist covariance (module docstring).
    min_points : int
        Clouds with fewer finite points are ``degenerate``.
    degeneracy_ratio : float
        ``λmin/λmax`` threshold of the scaled information matrix.
    """

    def __init__(
        self,
        variant: Literal["point", "plane"] = "point",
        *,
        max_iter: int = 30,
        gate_factor: float = 10.0,
        max_correspondence_distance: float | None = None,
        normal_radius_factor: float = 5.0,
        normal_max_nn: int = 30,
        relative_fitness: float = 1e-6,
        relative_rmse: float = 1e-6,
        convergence_tol_factor: float = 0.01,
        covariance: bool = True,
        min_points: int = 6,
        degeneracy_ratio: float = 1e-9,
    ) -> None:
        if variant not in ("point", "plane"):
            raise ConfigError(f"o3d-icp variant must be 'point' or 'plane', got {variant!r}")
        self.variant = variant
        self.name = f"o3d-icp-{variant}"
        self._o3d = require("open3d", self.name)
        if int(max_iter) < 1:
            raise ConfigError(f"max_iter must be >= 1, got {max_iter}")
        self.max_iter = int(max_iter)
        self.gate_factor = _positive("gate_factor", gate_factor)
        self.max_correspondence_distance = (
            None
            if max_correspondence_distance is None
            else _positive("max_correspondence_distance", max_correspondence_distance)
        )
        self.normal_radius_factor = _positive("normal_radius_factor", normal_radius_factor)
        self.normal_max_nn = int(normal_max_nn)
        self.relative_fitness = _positive("relative_fitness", relative_fitness, allow_zero=True)
        self.relative_rmse = _positive("relative_rmse", relative_rmse, allow_zero=True)
        self.convergence_tol_factor = _positive("convergence_tol_factor", convergence_tol_factor)
        self.covariance = bool(covariance)
        self.min_points = max(3, int(min_points))
        self.degeneracy_ratio = float(degeneracy_ratio)

    def _run(
        self, src: PreparedCloud, tgt: PreparedCloud, T0: np.ndarray, timings: dict, info: dict
    ) -> RegistrationResult:
        o3d = self._o3d
        reg = o3d.pipelines.registration
        tr = src.resolution
        gate = self.max_correspondence_distance or self.gate_factor * tr
        t0 = time.perf_counter()
        ps, pt = _o3d_cloud(o3d, src.points), _o3d_cloud(o3d, tgt.points)
        normals = None
        if self.variant == "plane":
            _o3d_normals(o3d, pt, self.normal_radius_factor * tr, self.normal_max_nn)
            normals = np.asarray(pt.normals)
            est = reg.TransformationEstimationPointToPlane()
        else:
            est = reg.TransformationEstimationPointToPoint(False)
        timings["normals"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        crit = reg.ICPConvergenceCriteria(
            relative_fitness=self.relative_fitness,
            relative_rmse=self.relative_rmse,
            max_iteration=self.max_iter,
        )
        res = reg.registration_icp(ps, pt, gate, T0, est, crit)
        T = np.array(res.transformation)
        timings["icp"] = time.perf_counter() - t0
        one = reg.registration_icp(
            ps, pt, gate, T, est, reg.ICPConvergenceCriteria(max_iteration=1)
        )
        ttol = self.convergence_tol_factor * tr
        converged = _step_small(
            T, np.array(one.transformation), ttol, ttol / max(src.radius, 1e-12)
        )
        info.update(variant=self.variant, max_iter=self.max_iter, o3d_fitness=float(res.fitness))
        return self._finish(
            T,
            src.points,
            tgt,
            gate,
            src.radius,
            converged=converged,
            timings=timings,
            info=info,
            normals=normals,
            compute_covariance=self.covariance,
            fallback=T0,
        )


# --------------------------------------------------------------------------- Open3D FPFH + RANSAC


class Open3DFPFHRansac(_ExternalBase):
    """Open3D global registration: FPFH + RANSAC on feature matches, then ICP refinement.

    All lengths are multiples of the source resolution ``Tr`` (module docstring); Open3D's
    tutorial values, expressed in its voxel size ``v``, are normals ``2v``, FPFH ``5v``, RANSAC
    distance ``1.5v``. The defaults here keep those ratios for ``v = 1.5 Tr`` but never go below
    a few ``Tr`` (sparse clouds need wider supports).

    Parameters
    ----------
    voxel_factor : float
        Voxel size of the downsampling, ``× Tr`` (0 disables downsampling).
    normal_radius_factor, feature_radius_factor : float
        Normal and FPFH support radii, ``× Tr``.
    normal_max_nn, feature_max_nn : int
        Maximum neighbours of the hybrid searches.
    ransac_distance_factor : float
        RANSAC inlier distance (and the distance checker), ``× Tr``.
    edge_length_ratio : float
        ``CorrespondenceCheckerBasedOnEdgeLength`` similarity (0.9, Open3D's tutorial).
    ransac_n : int
        Correspondences per hypothesis.
    max_iteration : int
        RANSAC iterations (``RANSACConvergenceCriteria``).
    confidence : float
        RANSAC early-exit confidence.
    mutual_filter : bool
        Keep only mutual FPFH matches.
    refine : {"plane", "point", "none"}
        ICP refinement on the full-resolution clouds.
    refine_gate_factor : float
        Refinement ICP gate, ``× Tr``.
    refine_max_iter : int
        Refinement ICP iterations.
    seed : int
        Seed of Open3D's RNG (``open3d.utility.random.seed``); recorded in ``info["seed"]``.
        Open3D evaluates RANSAC hypotheses on several threads, so two runs with the same seed
        can still differ when the threads are scheduled differently (seen under load).
    covariance : bool
        Compute the twist covariance (module docstring).
    min_points, degeneracy_ratio
        As :class:`Open3DICP`.
    """

    name = "o3d-fpfh-ransac"

    def __init__(
        self,
        *,
        voxel_factor: float = 1.5,
        normal_radius_factor: float = 5.0,
        normal_max_nn: int = 30,
        feature_radius_factor: float = 10.0,
        feature_max_nn: int = 100,
        ransac_distance_factor: float = 2.25,
        edge_length_ratio: float = 0.9,
        ransac_n: int = 3,
        max_iteration: int = 100_000,
        confidence: float = 0.999,
        mutual_filter: bool = False,
        refine: Literal["plane", "point", "none"] = "plane",
        refine_gate_factor: float = 2.0,
        refine_max_iter: int = 30,
        seed: int = 0,
        covariance: bool = True,
        min_points: int = 10,
        degeneracy_ratio: float = 1e-9,
    ) -> None:
        self._o3d = require("open3d", self.name)
        self.voxel_factor = _positive("voxel_factor", voxel_factor, allow_zero=True)
        self.normal_radius_factor = _positive("normal_radius_factor", normal_radius_factor)
        self.normal_max_nn = int(normal_max_nn)
        self.feature_radius_factor = _positive("feature_radius_factor", feature_radius_factor)
        self.feature_max_nn = int(feature_max_nn)
        self.ransac_distance_factor = _positive("ransac_distance_factor", ransac_distance_factor)
        if not 0 < float(edge_length_ratio) < 1:
            raise ConfigError(f"edge_length_ratio must be in (0, 1), got {edge_length_ratio}")
        self.edge_length_ratio = float(edge_length_ratio)
        if int(ransac_n) < 3:
            raise ConfigError(f"ransac_n must be >= 3, got {ransac_n}")
        self.ransac_n = int(ransac_n)
        if int(max_iteration) < 1:
            raise ConfigError(f"max_iteration must be >= 1, got {max_iteration}")
        self.max_iteration = int(max_iteration)
        if not 0 < float(confidence) <= 1:
            raise ConfigError(f"confidence must be in (0, 1], got {confidence}")
        self.confidence = float(confidence)
        self.mutual_filter = bool(mutual_filter)
        if refine not in ("plane", "point", "none"):
            raise ConfigError(f"refine must be 'plane', 'point' or 'none', got {refine!r}")
        self.refine = refine
        self.refine_gate_factor = _positive("refine_gate_factor", refine_gate_factor)
        self.refine_max_iter = int(refine_max_iter)
        self.seed = int(seed)
        self.covariance = bool(covariance)
        self.min_points = max(3, int(min_points))
        self.degeneracy_ratio = float(degeneracy_ratio)

    def _features(self, pcd: Any, tr: float, timings: dict) -> tuple[Any, Any]:
        o3d = self._o3d
        t0 = time.perf_counter()
        v = self.voxel_factor * tr
        down = pcd.voxel_down_sample(v) if v > 0 else pcd
        timings["downsample"] = timings.get("downsample", 0.0) + time.perf_counter() - t0
        t0 = time.perf_counter()
        _o3d_normals(o3d, down, self.normal_radius_factor * tr, self.normal_max_nn)
        timings["normals"] = timings.get("normals", 0.0) + time.perf_counter() - t0
        t0 = time.perf_counter()
        feat = o3d.pipelines.registration.compute_fpfh_feature(
            down,
            o3d.geometry.KDTreeSearchParamHybrid(
                radius=self.feature_radius_factor * tr, max_nn=self.feature_max_nn
            ),
        )
        timings["describe"] = timings.get("describe", 0.0) + time.perf_counter() - t0
        return down, feat

    def _run(
        self, src: PreparedCloud, tgt: PreparedCloud, T0: np.ndarray, timings: dict, info: dict
    ) -> RegistrationResult:
        o3d = self._o3d
        reg = o3d.pipelines.registration
        tr = src.resolution
        ps, pt = _o3d_cloud(o3d, src.points), _o3d_cloud(o3d, tgt.points)
        ds, fs = self._features(ps, tr, timings)
        dt, ft = self._features(pt, tr, timings)
        n_ds, n_dt = len(ds.points), len(dt.points)
        dist = self.ransac_distance_factor * tr
        info.update(
            seed=self.seed,
            voxel_size=self.voxel_factor * tr,
            n_down_source=n_ds,
            n_down_target=n_dt,
            ransac_distance=dist,
            init_ignored=True,
        )
        if n_ds < 3 or n_dt < 3:
            return _flag(
                "degenerate",
                f"too few points after downsampling ({n_ds}, {n_dt})",
                np.eye(4),
                timings,
                info,
            )
        t0 = time.perf_counter()
        o3d.utility.random.seed(self.seed)
        res = reg.registration_ransac_based_on_feature_matching(
            ds,
            dt,
            fs,
            ft,
            self.mutual_filter,
            dist,
            reg.TransformationEstimationPointToPoint(False),
            self.ransac_n,
            [
                reg.CorrespondenceCheckerBasedOnEdgeLength(self.edge_length_ratio),
                reg.CorrespondenceCheckerBasedOnDistance(dist),
            ],
            reg.RANSACConvergenceCriteria(self.max_iteration, self.confidence),
        )
        timings["ransac"] = time.perf_counter() - t0
        T = np.array(res.transformation)
        n_ransac = len(np.asarray(res.correspondence_set))
        info.update(ransac_fitness=float(res.fitness), ransac_inliers=n_ransac, T_ransac=T.copy())
        if n_ransac < 3:
            return _flag(
                "failed", "RANSAC found no consistent hypothesis", np.eye(4), timings, info
            )
        gate = self.refine_gate_factor * tr
        normals = None
        converged = True
        if self.refine != "none":
            t0 = time.perf_counter()
            if self.refine == "plane":
                _o3d_normals(o3d, pt, self.normal_radius_factor * tr, self.normal_max_nn)
                normals = np.asarray(pt.normals)
                est = reg.TransformationEstimationPointToPlane()
            else:
                est = reg.TransformationEstimationPointToPoint(False)
            ref = reg.registration_icp(
                ps, pt, gate, T, est, reg.ICPConvergenceCriteria(max_iteration=self.refine_max_iter)
            )
            T = np.array(ref.transformation)
            timings["refine"] = time.perf_counter() - t0
        else:
            gate = dist
        return self._finish(
            T,
            src.points,
            tgt,
            gate,
            src.radius,
            converged=converged,
            timings=timings,
            info=info,
            normals=normals,
            n_correspondences=n_ds,
            compute_covariance=self.covariance,
        )


# --------------------------------------------------------------------------- KISS-ICP


@dataclass
class KissFrame:
    """A validated cloud and its content hash: the prepared form of :class:`KissICPRegistration`.

    Attributes
    ----------
    cloud : PreparedCloud
        Validated finite points, KD-tree and resolution.
    key : str
        Hash of the float64 points (detects consecutive calls).
    max_range : float
        Largest point range from the sensor origin (m).
    """

    cloud: PreparedCloud
    key: str
    max_range: float = field(default=float("nan"))


class KissICPRegistration(_ExternalBase):
    """KISS-ICP fed frame by frame (see the module docstring for the statefulness rules).

    Lengths derived when the pipeline is (re)built from the target frame ``k`` (``Tr`` = its
    resolution): ``mapping.voxel_size = voxel_factor · Tr`` (KISS-ICP voxelises the source at
    1.5 × and the map at 0.5 × this size and searches correspondences in the 27 neighbouring
    voxels, so the voxel must exceed the expected point displacement between frames);
    ``data.max_range = range_margin ·`` the largest point range of the target;
    ``data.min_range = min_range``; ``adaptive_threshold.initial_threshold =
    initial_threshold_factor · voxel`` and ``min_motion_th = min_motion_factor · voxel`` (KISS-ICP's
    defaults are 2 and 0.1 of its 1 m voxel); ``registration.convergence_criterion =
    convergence_factor · voxel``. KISS-ICP does not report convergence: ``converged`` is always
    True and the quality shows in ``fitness`` / ``inlier_rmse`` (gate ``3σ``).

    Parameters
    ----------
    voxel_factor : float
        Voxel size in multiples of ``Tr`` (default 1).
    voxel_size : float, optional
        Absolute voxel size in metres (overrides ``voxel_factor``).
    range_margin : float
        ``max_range`` = this × the target's largest range (default 1.5). A source with a point
        beyond ``0.95 · max_range`` triggers a rebuild (the preprocessor would drop it).
    max_range : float, optional
        Absolute ``max_range`` in metres (overrides ``range_margin``).
    min_range : float
        Points closer than this are dropped (m).
    initial_threshold_factor, min_motion_factor : float
        Adaptive-threshold parameters in multiples of the voxel size.
    fixed_threshold : float, optional
        Fixed correspondence threshold σ in metres (disables the adaptive threshold).
    max_points_per_voxel : int
        Map density (KISS-ICP default 20).
    max_iterations : int
        ICP iterations per frame (KISS-ICP default 500).
    convergence_factor : float
        Convergence criterion on the update norm, × voxel size.
    stateful : bool
        Keep the pipeline alive across consecutive calls (default True).
    dense_points : int or None
        A target scan with more points builds the pipeline with KISS-ICP's own voxel rule
        ``max_range / 100`` instead of ``voxel_factor · Tr`` (``voxel_size`` overrides both;
        None: always ``Tr``-based).
    num_threads : int
        Threads of the KISS-ICP core (default 1; 0 = all).
    min_points : int
        Clouds with fewer finite points are ``degenerate``.
    degeneracy_ratio : float
        As :class:`Open3DICP`.
    """

    name = "kiss-icp"

    def __init__(
        self,
        *,
        voxel_factor: float = 1.0,
        voxel_size: float | None = None,
        range_margin: float = 1.5,
        max_range: float | None = None,
        min_range: float = 0.0,
        initial_threshold_factor: float = 2.0,
        min_motion_factor: float = 0.1,
        fixed_threshold: float | None = None,
        max_points_per_voxel: int = 20,
        max_iterations: int = 500,
        convergence_factor: float = 1e-4,
        stateful: bool = True,
        dense_points: int | None = DENSE_POINTS,
        num_threads: int = 1,
        min_points: int = 6,
        degeneracy_ratio: float = 1e-9,
    ) -> None:
        self._kiss_mod = require("kiss_icp", self.name)
        self._kiss_core = require("kiss_icp.kiss_icp", self.name)
        self._kiss_cfg = require("kiss_icp.config", self.name)
        self.voxel_factor = _positive("voxel_factor", voxel_factor)
        self.voxel_size = None if voxel_size is None else _positive("voxel_size", voxel_size)
        self.range_margin = _positive("range_margin", range_margin)
        if self.range_margin <= 1:
            raise ConfigError(f"range_margin must be > 1, got {range_margin}")
        self.max_range = None if max_range is None else _positive("max_range", max_range)
        self.min_range = _positive("min_range", min_range, allow_zero=True)
        self.initial_threshold_factor = _positive(
            "initial_threshold_factor", initial_threshold_factor
        )
        self.min_motion_factor = _positive("min_motion_factor", min_motion_factor)
        self.fixed_threshold = (
            None if fixed_threshold is None else _positive("fixed_threshold", fixed_threshold)
        )
        self.max_points_per_voxel = int(max_points_per_voxel)
        if int(max_iterations) < 1:
            raise ConfigError(f"max_iterations must be >= 1, got {max_iterations}")
        self.max_iterations = int(max_iterations)
        self.convergence_factor = _positive("convergence_factor", convergence_factor)
        self.stateful = bool(stateful)
        self.dense_points = _dense_points(dense_points)
        self.num_threads = int(num_threads)
        self.min_points = max(3, int(min_points))
        self.degeneracy_ratio = float(degeneracy_ratio)
        self._pipeline: Any = None
        self._last_key: str | None = None
        self._config: dict[str, float] = {}
        self._settings = "sparse"
        self.n_rebuilds = 0

    # ------------------------------------------------------------------ prepared path
    def prepare(self, points: np.ndarray) -> KissFrame:
        """Validate a cloud and hash it (cheap; the pipeline state lives in this object)."""
        cloud = self._prepare(points, "cloud")
        rng = (
            float(np.linalg.norm(cloud.points, axis=1).max()) if cloud.points.size else float("nan")
        )
        return KissFrame(cloud, _fingerprint(cloud.points), rng)

    def register(
        self, source: np.ndarray, target: np.ndarray, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register ``source`` (scan ``k+1``) onto ``target`` (scan ``k``); see the class doc."""
        return self.register_prepared(self.prepare(source), self.prepare(target), init=init)

    def register_prepared(
        self, source: KissFrame, target: KissFrame, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register two prepared frames (``prepare``); consecutive calls reuse the pipeline."""
        timings: dict[str, float] = {}
        info: dict[str, Any] = {"method": self.name}
        given_init = init is not None
        v = self._validate(source.cloud, target.cloud, init, timings, info)
        if isinstance(v, RegistrationResult):
            self._reset()
            return v
        _, _, T0 = v
        try:
            return self._run_frames(source, target, T0 if given_init else None, timings, info)
        except Exception as e:
            log.warning("%s raised %s: %s", self.name, type(e).__name__, e)
            self._reset()
            return _flag("failed", f"{type(e).__name__}: {e}", T0, timings, info)

    def reset(self) -> None:
        """Forget the pipeline; the next call rebuilds it."""
        self._reset()

    def _reset(self) -> None:
        self._pipeline = None
        self._last_key = None

    def _build(self, target: KissFrame) -> None:
        cfgm = self._kiss_cfg
        sub = importlib.import_module("kiss_icp.config.config")
        tr = target.cloud.resolution
        max_range = self.max_range or self.range_margin * target.max_range
        dense = _is_dense(target.cloud.points.shape[0], self.dense_points)
        if self.voxel_size:
            voxel = self.voxel_size
        else:  # KISS-ICP's own rule on dense scans (its default: no voxel_size given)
            voxel = max_range / 100.0 if dense else self.voxel_factor * tr
        conf = cfgm.KISSConfig(
            data=sub.DataConfig(max_range=max_range, min_range=self.min_range, deskew=False),
            mapping=sub.MappingConfig(
                voxel_size=voxel, max_points_per_voxel=self.max_points_per_voxel
            ),
            registration=sub.RegistrationConfig(
                max_num_iterations=self.max_iterations,
                convergence_criterion=self.convergence_factor * voxel,
                max_num_threads=self.num_threads,
            ),
            adaptive_threshold=sub.AdaptiveThresholdConfig(
                fixed_threshold=self.fixed_threshold,
                initial_threshold=self.initial_threshold_factor * voxel,
                min_motion_th=self.min_motion_factor * voxel,
            ),
        )
        self._pipeline = self._kiss_core.KissICP(conf)
        self._pipeline.register_frame(np.ascontiguousarray(target.cloud.points), np.zeros(0))
        self._last_key = target.key
        self._config = {"voxel_size": float(voxel), "max_range": float(max_range)}
        self._settings = "dense" if dense and not self.voxel_size else "sparse"
        self.n_rebuilds += 1

    def _run_frames(
        self,
        source: KissFrame,
        target: KissFrame,
        init: np.ndarray | None,
        timings: dict,
        info: dict,
    ) -> RegistrationResult:
        t0 = time.perf_counter()
        consecutive = self.stateful and self._pipeline is not None and self._last_key == target.key
        if consecutive and source.max_range > 0.95 * self._config["max_range"]:
            consecutive = False
            info["rebuild_reason"] = "source beyond the configured max_range"
        if not consecutive:
            self._build(target)
        timings["build"] = time.perf_counter() - t0
        kiss = self._pipeline
        t0 = time.perf_counter()
        sigma = float(kiss.adaptive_threshold.get_threshold())
        if init is not None:
            kiss.last_delta = np.array(init, dtype=np.float64)
        predicted = np.array(kiss.last_delta, dtype=np.float64)
        kiss.register_frame(np.ascontiguousarray(source.cloud.points), np.zeros(0))
        self._last_key = source.key if self.stateful else None
        T = np.array(kiss.last_delta, dtype=np.float64)
        timings["register"] = time.perf_counter() - t0
        info.update(
            self._config,
            settings=self._settings,
            reused_pipeline=consecutive,
            n_rebuilds=self.n_rebuilds,
            sigma=sigma,
            prediction=predicted,
            init_given=init is not None,
        )
        if not self.stateful:
            self._pipeline = None
        gate = 3.0 * sigma
        return self._finish(
            T,
            source.cloud.points,
            target.cloud,
            gate,
            source.cloud.radius,
            converged=True,
            timings=timings,
            info=info,
            fallback=predicted,
        )


# --------------------------------------------------------------------------- small_gicp

_SG_TYPES = {"gicp": "GICP", "icp": "ICP", "plane_icp": "PLANE_ICP", "vgicp": "VGICP"}
_GRID_LIMIT = 1_000_000.0  # small_gicp discretises coordinates to 21-bit ints (±1 048 576)


class SmallGICPRegistration(_ExternalBase):
    """small_gicp registration (GICP by default) with scale-aware parameters.

    ``downsampling_resolution = downsampling_factor · Tr`` (0 → no downsampling; raised to
    ``max|coordinate| / 10⁶`` when smaller, because small_gicp drops points whose voxel index
    leaves its 21-bit range — recorded in ``info["downsampling_clamped"]``);
    ``max_correspondence_distance = gate_factor · Tr``; VGICP voxel ``voxel_factor · Tr``;
    ``translation_epsilon = translation_tol_factor · Tr``; ``rotation_epsilon`` = 0.1° (small_gicp's
    default) or ``translation_epsilon / radius`` when smaller. On a dense source (more than
    ``dense_points`` points, no absolute downsampling/gate given) the downsampling is
    ``max range / 400`` and the gate ``4 ×`` it (small_gicp's 0.25 m / 1 m at 100 m range,
    **[interpretation]**), and ``Tr`` is that of the downsampled source.

    **Covariance** from small_gicp's Hessian ``H`` (6×6 over a RIGHT perturbation
    ``[φ, ρ]``, rotation first), converted to relnav's left ``[ρ, φ]`` twist by
    :func:`twist_covariance_from_hessian`. ``covariance="scaled"`` (default,
    **[interpretation]**) multiplies ``H⁻¹`` by the a-posteriori variance factor
    ``2·error / (m − 6)`` (``m`` = 3 per inlier for ICP/GICP/VGICP, 1 for PLANE_ICP):
    small_gicp's GICP covariances are normalised (eigenvalues 1e-3, 1, 1), so the raw ``H⁻¹``
    has no metric scale. ``covariance="hessian"`` returns the raw converted ``H⁻¹``;
    ``"none"`` skips it. ``info["H"]`` keeps the raw Hessian.

    Parameters
    ----------
    registration_type : {"gicp", "icp", "plane_icp", "vgicp"}
        small_gicp's registration type.
    downsampling_factor : float
        Voxel downsampling, ``× Tr`` (default 1).
    downsampling_resolution : float, optional
        Absolute downsampling voxel in metres (overrides the factor; 0 disables).
    gate_factor : float
        Correspondence gate, ``× Tr`` (default 5).
    max_correspondence_distance : float, optional
        Absolute gate in metres (overrides ``gate_factor``).
    voxel_factor : float
        VGICP voxel resolution, ``× Tr``.
    num_neighbors : int
        Neighbours for the covariance / normal estimation (small_gicp default 10).
    max_iterations : int
        Optimiser iterations (small_gicp default 20).
    translation_tol_factor : float
        Convergence on the translation update, ``× Tr``.
    covariance : {"scaled", "hessian", "none"}
        See above.
    dense_points : int or None
        Source size above which the range-based (dense) settings apply; None: never.
    num_threads : int
        small_gicp threads (default 1).
    min_points, degeneracy_ratio
        As :class:`Open3DICP` (the ratio is computed from ``H``).
    """

    def __init__(
        self,
        registration_type: str = "gicp",
        *,
        downsampling_factor: float = 1.0,
        downsampling_resolution: float | None = None,
        gate_factor: float = 5.0,
        max_correspondence_distance: float | None = None,
        voxel_factor: float = 3.0,
        num_neighbors: int = 10,
        max_iterations: int = 20,
        translation_tol_factor: float = 0.01,
        covariance: Literal["scaled", "hessian", "none"] = "scaled",
        dense_points: int | None = DENSE_POINTS,
        num_threads: int = 1,
        min_points: int = 6,
        degeneracy_ratio: float = 1e-9,
    ) -> None:
        key = str(registration_type).strip().lower()
        if key not in _SG_TYPES:
            raise ConfigError(
                f"small-gicp registration type must be one of {', '.join(_SG_TYPES)}, "
                f"got {registration_type!r}"
            )
        self.registration_type = key
        self.name = "small-gicp" if key == "gicp" else f"small-gicp:{key}"
        self._sg = require("small_gicp", self.name)
        self.downsampling_factor = _positive(
            "downsampling_factor", downsampling_factor, allow_zero=True
        )
        self.downsampling_resolution = (
            None
            if downsampling_resolution is None
            else _positive("downsampling_resolution", downsampling_resolution, allow_zero=True)
        )
        self.gate_factor = _positive("gate_factor", gate_factor)
        self.max_correspondence_distance = (
            None
            if max_correspondence_distance is None
            else _positive("max_correspondence_distance", max_correspondence_distance)
        )
        self.voxel_factor = _positive("voxel_factor", voxel_factor)
        if int(num_neighbors) < 5:
            raise ConfigError(f"num_neighbors must be >= 5, got {num_neighbors}")
        self.num_neighbors = int(num_neighbors)
        if int(max_iterations) < 1:
            raise ConfigError(f"max_iterations must be >= 1, got {max_iterations}")
        self.max_iterations = int(max_iterations)
        self.translation_tol_factor = _positive("translation_tol_factor", translation_tol_factor)
        if covariance not in ("scaled", "hessian", "none"):
            raise ConfigError(
                f"covariance must be 'scaled', 'hessian' or 'none', got {covariance!r}"
            )
        self.covariance = covariance
        self.dense_points = _dense_points(dense_points)
        self.num_threads = max(1, int(num_threads))
        self.min_points = max(3, int(min_points))
        self.degeneracy_ratio = float(degeneracy_ratio)

    def _cloud(self, points: np.ndarray, res: float) -> tuple[Any, Any]:
        sg = self._sg
        if res > 0:
            return sg.preprocess_points(
                np.ascontiguousarray(points),
                downsampling_resolution=res,
                num_neighbors=self.num_neighbors,
                num_threads=self.num_threads,
            )
        cloud = sg.PointCloud(np.ascontiguousarray(points))
        tree = sg.KdTree(cloud, num_threads=self.num_threads)
        sg.estimate_normals_covariances(
            cloud, tree, num_neighbors=self.num_neighbors, num_threads=self.num_threads
        )
        return cloud, tree

    def _run(
        self, src: PreparedCloud, tgt: PreparedCloud, T0: np.ndarray, timings: dict, info: dict
    ) -> RegistrationResult:
        sg = self._sg
        tr = src.resolution
        res = (
            self.downsampling_resolution
            if self.downsampling_resolution is not None
            else self.downsampling_factor * tr
        )
        dense = self.downsampling_resolution is None and _is_dense(
            src.points.shape[0], self.dense_points
        )
        dense_gate = None
        if dense:  # small_gicp's own outdoor settings, scaled to the scan's range
            reach = max(_max_range(src.points), _max_range(tgt.points))
            res = reach / 400.0
            dense_gate = 4.0 * res
        info["settings"] = "dense" if dense else "sparse"
        clamped = False
        if res > 0:
            extent = max(float(np.abs(src.points).max()), float(np.abs(tgt.points).max()))
            floor = extent / _GRID_LIMIT
            if res < floor:
                res, clamped = floor, True
                log.info("small-gicp: downsampling resolution raised to %.3g m (21-bit grid)", res)
        gate = self.max_correspondence_distance or dense_gate or self.gate_factor * tr
        if dense:
            tr = max(tr, res)  # the aligned clouds have the downsampled spacing
        ttol = self.translation_tol_factor * tr
        rtol = min(math.radians(0.1), ttol / max(src.radius, 1e-12))
        t0 = time.perf_counter()
        s_cloud, _ = self._cloud(src.points, res)
        t_cloud, t_tree = self._cloud(tgt.points, res)
        timings["preprocess"] = time.perf_counter() - t0
        n_s, n_t = int(s_cloud.size()), int(t_cloud.size())
        info.update(
            registration_type=self.registration_type,
            downsampling_resolution=res,
            downsampling_clamped=clamped,
            n_down_source=n_s,
            n_down_target=n_t,
        )
        if n_s < self.min_points or n_t < self.min_points:
            return _flag(
                "degenerate", f"too few points after downsampling ({n_s}, {n_t})", T0, timings, info
            )
        t0 = time.perf_counter()
        common = {
            "init_T_target_source": T0,
            "max_correspondence_distance": gate,
            "num_threads": self.num_threads,
            "max_iterations": self.max_iterations,
            "rotation_epsilon": rtol,
            "translation_epsilon": ttol,
        }
        if self.registration_type == "vgicp":
            vox = self.voxel_factor * tr
            vmap = sg.GaussianVoxelMap(vox)
            vmap.insert(t_cloud)
            info["voxel_resolution"] = vox
            res_sg = sg.align(vmap, s_cloud, **common)
        else:
            res_sg = sg.align(
                t_cloud,
                s_cloud,
                t_tree,
                registration_type=_SG_TYPES[self.registration_type],
                **common,
            )
        timings["align"] = time.perf_counter() - t0
        T = np.array(res_sg.T_target_source, dtype=np.float64)
        H = np.array(res_sg.H, dtype=np.float64)
        n_in = int(res_sg.num_inliers)
        info.update(
            H=H,
            b=np.array(res_sg.b, dtype=np.float64).reshape(-1),
            error=float(res_sg.error),
            iterations=int(res_sg.iterations),
            sg_num_inliers=n_in,
        )
        cov = None
        if self.covariance != "none":
            cov = twist_covariance_from_hessian(H, T)
            if cov is not None and self.covariance == "scaled":
                m = n_in * (1 if self.registration_type == "plane_icp" else 3)
                cov = cov * (2.0 * float(res_sg.error) / (m - 6)) if m > 6 else None
        result = self._finish(
            T,
            np.asarray(s_cloud.points())[:, :3],
            tgt,
            gate,
            src.radius,
            converged=bool(res_sg.converged),
            timings=timings,
            info=info,
            covariance=cov,
            compute_covariance=False,
            fallback=T0,
        )
        # degeneracy indicator from small_gicp's own Hessian: right perturbation [φ, ρ] in the
        # source frame → [ρ, φ], about the source centroid
        perm = np.r_[3:6, 0:3]
        if np.isfinite(H).all() and n_in > 0:
            ratio = information_degeneracy(
                H[np.ix_(perm, perm)], src.points.mean(axis=0), src.radius
            )
            result.info["degeneracy_ratio"] = ratio
            if result.status == "ok" and ratio < self.degeneracy_ratio:
                result.status = "degenerate"
                result.message = f"geometry does not fix 6 DoF (λmin/λmax of H = {ratio:.2e})"
        return result


# --------------------------------------------------------------------------- registry


def _no_spec(prefix: str, spec: str | None) -> None:
    if spec:
        raise ConfigError(f"method {prefix!r} takes no ':' spec, got {spec!r}")


@register_method(
    "o3d-fpfh-ransac",
    "Open3D: voxel downsampling, FPFH, RANSAC on feature matches (seeded), point-to-plane ICP",
    extra="baselines",
    examples=["o3d-fpfh-ransac"],
)
def _make_o3d_fpfh(spec: str | None, **options: Any) -> Open3DFPFHRansac:
    _no_spec("o3d-fpfh-ransac", spec)
    return Open3DFPFHRansac(**options)


@register_method(
    "o3d-icp-point",
    "Open3D point-to-point ICP from the initial guess",
    extra="baselines",
    examples=["o3d-icp-point"],
)
def _make_o3d_point(spec: str | None, **options: Any) -> Open3DICP:
    _no_spec("o3d-icp-point", spec)
    return Open3DICP("point", **options)


@register_method(
    "o3d-icp-plane",
    "Open3D point-to-plane ICP from the initial guess",
    extra="baselines",
    examples=["o3d-icp-plane"],
)
def _make_o3d_plane(spec: str | None, **options: Any) -> Open3DICP:
    _no_spec("o3d-icp-plane", spec)
    return Open3DICP("plane", **options)


@register_method(
    "kiss-icp",
    "KISS-ICP odometry (local voxel map, adaptive threshold); voxel = Tr (sparse scans) or "
    "max_range/100, KISS-ICP's own rule (scans > 5000 points)",
    extra="baselines",
    examples=["kiss-icp"],
)
def _make_kiss(spec: str | None, **options: Any) -> KissICPRegistration:
    _no_spec("kiss-icp", spec)
    return KissICPRegistration(**options)


@register_method(
    "small-gicp",
    "small_gicp align (GICP; spec icp|plane_icp|vgicp), covariance from H; downsampling Tr "
    "(sparse scans) or range/400, gate 4x (small_gicp's 0.25/1 m at 100 m; scans > 5000 points)",
    extra="baselines",
    examples=["small-gicp", "small-gicp:vgicp", "small-gicp:plane_icp"],
)
def _make_small_gicp(spec: str | None, **options: Any) -> SmallGICPRegistration:
    return SmallGICPRegistration(spec or "gicp", **options)
