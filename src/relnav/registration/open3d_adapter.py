"""Open3D's point-to-point / point-to-plane ICP and FPFH + RANSAC (+ ICP) as relnav
methods ``o3d-icp-point``, ``o3d-icp-plane``, ``o3d-fpfh-ransac`` (see
:mod:`relnav.registration.external`)."""

from __future__ import annotations

import logging
import time
from types import ModuleType
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.geometry.rotations import rotation_angle
from relnav.registration.base import register_fixed
from relnav.registration.external_base import (
    _ExternalBase,
    _flag,
    _positive,
    require,
)
from relnav.registration.icp import PreparedCloud
from relnav.registration.result import RegistrationResult

log = logging.getLogger(__name__)


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


register_fixed(
    Open3DFPFHRansac,
    {
        "o3d-fpfh-ransac": (
            "Open3D: voxel downsampling, FPFH, RANSAC on feature matches (seeded), "
            "point-to-plane ICP",
            {},
        )
    },
    extra="baselines",
)
register_fixed(
    Open3DICP,
    {
        "o3d-icp-point": ("Open3D point-to-point ICP from the initial guess", {"variant": "point"}),
        "o3d-icp-plane": ("Open3D point-to-plane ICP from the initial guess", {"variant": "plane"}),
    },
    extra="baselines",
)
