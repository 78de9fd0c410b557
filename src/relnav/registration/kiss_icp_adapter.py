"""KISS-ICP as the relnav method ``kiss-icp`` (see :mod:`relnav.registration.external`)."""

from __future__ import annotations

import importlib
import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from relnav.errors import ConfigError
from relnav.registration.base import register_fixed
from relnav.registration.external_base import (
    DENSE_POINTS,
    _dense_points,
    _ExternalBase,
    _fingerprint,
    _flag,
    _is_dense,
    _positive,
    require,
)
from relnav.registration.icp import PreparedCloud
from relnav.registration.result import RegistrationResult

log = logging.getLogger(__name__)


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


register_fixed(
    KissICPRegistration,
    {
        "kiss-icp": (
            "KISS-ICP odometry (local voxel map, adaptive threshold); voxel = Tr (sparse scans) "
            "or max_range/100, KISS-ICP's own rule (scans > 5000 points)",
            {},
        )
    },
    extra="baselines",
)
