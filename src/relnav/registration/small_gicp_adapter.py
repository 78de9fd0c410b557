"""small_gicp as the relnav method ``small-gicp`` (see :mod:`relnav.registration.external`)."""

from __future__ import annotations

import logging
import math
import time
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.registration.base import register_method
from relnav.registration.external_base import (
    DENSE_POINTS,
    _dense_points,
    _ExternalBase,
    _flag,
    _is_dense,
    _max_range,
    _positive,
    information_degeneracy,
    require,
    twist_covariance_from_hessian,
)
from relnav.registration.icp import PreparedCloud
from relnav.registration.result import RegistrationResult

log = logging.getLogger(__name__)


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


@register_method(
    "small-gicp",
    "small_gicp align (GICP; spec icp|plane_icp|vgicp), covariance from H; downsampling Tr "
    "(sparse scans) or range/400, gate 4x (small_gicp's 0.25/1 m at 100 m; scans > 5000 points)",
    extra="baselines",
    examples=["small-gicp", "small-gicp:vgicp", "small-gicp:plane_icp"],
)
def _make_small_gicp(spec: str | None, **options: Any) -> SmallGICPRegistration:
    return SmallGICPRegistration(spec or "gicp", **options)
