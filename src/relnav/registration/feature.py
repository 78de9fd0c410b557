"""Paper 1's method as one registration: descriptors → NN matching → grouping → estimator.

Method strings: ``feature:<descriptor>+<grouper>+<estimator>``, e.g.
``feature:hods+gcc+alphabeta``, ``feature:shot+ransac+kalman``, ``feature:fpfh+gcc+svd``.

Pipeline for a pair (source = scan ``k+1``, target = scan ``k``), ALGORITHMS §0:

1. Resolution ``Tr`` = mean nearest-neighbour distance; support radius ``r = factor · Tr``
   (20 for SHOT/FPFH/RoPS/TriSI/spin, 80 for HoD/HoD-S).
2. Keypoints: every point (paper default) or a subsample (``keypoints="voxel"|"fps"|"iss"``).
3. Normals (only for descriptors that need them): PCA, radius ``normal_radius_factor · Tr``,
   oriented towards the sensor (origin of the scan frame).
4. Descriptors of both clouds; exact NN matching on unit-normalised descriptors with gate ``τ``:
   every descriptor of ``P_k`` (the target) to its nearest in ``P_{k+1}`` (paper 1 eq. 5,
   ``match_from="target"``, default), or every source descriptor to its nearest in the target
   (``match_from="source"``, relnav's former default).
5. Grouping (GCC with ``ε = 2·Tr`` by default) → correspondences Ω.
6. Estimator (recursive filter or SVD) → ``T_target_source``.
7. Optional (a relnav extension, off by default): ``refine="icp-plane"`` (any registration
   method string) refines the estimate on the full clouds, starting from it; a refinement
   that is not ``ok`` leaves the feature estimate in place.

**Radius: paper 1's rule by default.** Paper 1 computes ``Tr`` on ``P_{k+1}`` (the source) and
uses that one support radius for *both* clouds. That is the default (``radius_from="source"``):
the target is described again at the source's radius (its resolution, keypoints and normals are
reused), so the previous scan's descriptors cannot be reused as they are and a step describes
two clouds. ``radius_from="own"`` (relnav's option, used by the ``extended`` preset) gives each
cloud its own ``Tr`` and reuses the previous scan's descriptors; it is cheaper but the radius
then changes between consecutive scans (``Tr`` moves by 1-2.5 % per frame, up to ~10 %), and
HoD/HoD-S, which divide distances by the radius, describe the same point differently
(docs/paper1-deviations.md).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.features import compute as compute_descriptors
from relnav.features import get_descriptor
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.normals import estimate_normals
from relnav.geometry.se3 import transform_points
from relnav.registration.base import register_method
from relnav.registration.result import RegistrationResult

__all__ = ["CloudFeatures", "FeatureRegistration"]

log = logging.getLogger(__name__)


@dataclass
class CloudFeatures:
    """Per-cloud data of the feature pipeline (reusable across pairs).

    Attributes
    ----------
    points : (N, 3) float64
        Finite points of the cloud (scan frame, m).
    resolution : float
        Mean resolution ``Tr`` (m); NaN for fewer than 2 distinct points.
    radius : float
        Support radius used for the descriptors (m).
    keypoints : (K,) int64
        Indices of the described points.
    descriptors : (K, D) float32
        Descriptors (NaN rows invalid).
    timings : dict[str, float]
        Seconds spent per stage while preparing this cloud.
    normals : (N, 3) float64 or None
        Normals of ``points`` (only for descriptors that need them).
    """

    points: np.ndarray
    resolution: float
    radius: float
    keypoints: np.ndarray
    descriptors: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)
    normals: np.ndarray | None = None


class FeatureRegistration:
    """Descriptor-based registration (paper 1, §2).

    Parameters
    ----------
    descriptor : str
        Registered descriptor name (``hod``, ``hods``, ``shot``, ``fpfh``, ``rops``, ``trisi``,
        ``spin``).
    grouper : str
        ``gcc`` (default), ``ransac``, ``clgv`` or ``none``.
    estimator : str
        ``alphabeta``, ``kalman``, ``hinf``, ``sdre`` or ``svd``.
    radius_factor : float, optional
        Support radius in multiples of ``Tr``; the descriptor's default when omitted.
    normal_radius_factor : float
        Normal-estimation radius in multiples of ``Tr`` (ALGORITHMS §A: 5, [interpretation]).
    normal_k : int, optional
        Estimate the normals from the ``normal_k`` nearest points instead of that radius (PCL's
        correspondence-grouping tutorial: 10); the paper is silent (ledger row 4).
    resolution : {"mean", "median"}
        ``Tr``: the mean (default, the usual definition) or the median distance of each point
        to its nearest distinct neighbour; the paper does not define it (ledger row 1).
    keypoints : {"all", "voxel", "fps", "iss", "random"}
        Keypoint selection (paper 1: ``all``).
    keypoint_options : dict, optional
        Passed to :func:`relnav.features.keypoints.select_keypoints`.
    tau : float
        Descriptor-distance gate of the NN matching (paper 1: 1.0).
    unit_descriptors : bool
        Scale the descriptors to unit L2 norm before matching (default: relnav's reading of
        τ = 1, ledger row 7); ``False``: τ on the raw descriptors' distance.
    mutual : bool
        Keep only mutual nearest neighbours.
    match_from : {"target", "source"}
        Direction of the NN matching: ``target`` (default, paper 1 eq. 5: each feature of
        ``P_k`` to its nearest feature of ``P_{k+1}``) or ``source`` (each feature of
        ``P_{k+1}`` to its nearest of ``P_k``).
    radius_from : {"source", "own"}
        ``source`` (default, paper 1): both clouds are described with the radius from the
        source's resolution; ``own``: each cloud with its own (relnav's option, reuses the
        previous scan's descriptors). See the module docstring.
    min_points : int
        Clouds with fewer finite points are ``degenerate``.
    descriptor_options, grouper_options, estimator_options : dict, optional
        Passed to the descriptor function, the grouper and the estimator.
    refine : str, optional
        Registration method run after the estimator, initialised with its result (e.g.
        ``"icp-plane"``); ``refine_options`` are passed to it.
    """

    def __init__(
        self,
        descriptor: str = "hods",
        grouper: str = "gcc",
        estimator: str = "alphabeta",
        *,
        radius_factor: float | None = None,
        normal_radius_factor: float = 5.0,
        normal_k: int | None = None,
        resolution: Literal["mean", "median"] = "mean",
        keypoints: str = "all",
        keypoint_options: dict[str, Any] | None = None,
        tau: float = 1.0,
        unit_descriptors: bool = True,
        mutual: bool = False,
        radius_from: Literal["own", "source"] = "source",
        match_from: Literal["target", "source"] = "target",
        min_points: int = 5,
        descriptor_options: dict[str, Any] | None = None,
        grouper_options: dict[str, Any] | None = None,
        estimator_options: dict[str, Any] | None = None,
        refine: str | None = None,
        refine_options: dict[str, Any] | None = None,
    ) -> None:
        from relnav.estimation import get_estimator
        from relnav.matching.grouping import get_grouper

        self.descriptor_spec = get_descriptor(descriptor)
        self.grouper = get_grouper(grouper, **(grouper_options or {}))
        self.estimator = get_estimator(estimator, **(estimator_options or {}))
        if radius_from not in ("own", "source"):
            raise ConfigError(f"radius_from must be 'own' or 'source', got {radius_from!r}")
        self.radius_factor = float(radius_factor or self.descriptor_spec.radius_factor)
        self.normal_radius_factor = float(normal_radius_factor)
        if normal_k is not None and int(normal_k) < 3:
            raise ConfigError(f"normal_k must be at least 3, got {normal_k!r}")
        self.normal_k = None if normal_k is None else int(normal_k)
        if resolution not in ("mean", "median"):
            raise ConfigError(f"resolution must be 'mean' or 'median', got {resolution!r}")
        self.resolution = resolution
        self.unit_descriptors = bool(unit_descriptors)
        self.keypoint_method = keypoints
        self.keypoint_options = dict(keypoint_options or {})
        self.tau = float(tau)
        self.mutual = bool(mutual)
        self.radius_from = radius_from
        if match_from not in ("target", "source"):
            raise ConfigError(f"match_from must be 'target' or 'source', got {match_from!r}")
        self.match_from = match_from
        self.min_points = int(min_points)
        self.descriptor_options = dict(descriptor_options or {})
        if self.descriptor_options:
            self._dry_run_descriptor()
        self.refiner = None
        if refine:
            from relnav.registration.base import get_registration

            self.refiner = get_registration(refine, **(refine_options or {}))
        self.name = f"feature:{descriptor}+{grouper}+{estimator}"

    def _dry_run_descriptor(self) -> None:
        """Describe a tiny fixed cloud once so that bad ``descriptor_options`` fail at start
        (:class:`ConfigError`) instead of flagging every frame."""
        rng = np.random.default_rng(0)
        P = rng.normal(size=(32, 3))
        normals = estimate_normals(P, radius=1.0) if self.descriptor_spec.needs_normals else None
        try:
            compute_descriptors(
                self.descriptor_spec.name,
                P,
                radius=1.0,
                keypoints=np.arange(4),
                normals=normals,
                **self.descriptor_options,
            )
        except Exception as e:  # any failure here is the options' fault
            raise ConfigError(
                f"feature: bad descriptor_options for {self.descriptor_spec.name!r}: "
                f"{type(e).__name__}: {e}"
            ) from None

    # ------------------------------------------------------------------ per-cloud work
    def prepare(
        self,
        points: np.ndarray,
        *,
        radius: float | None = None,
        keypoints: np.ndarray | None = None,
    ) -> CloudFeatures:
        """Resolution, keypoints, normals and descriptors of one cloud.

        ``radius`` (m) overrides ``radius_factor · Tr``. ``keypoints`` ((K,) int, indices into
        ``points``) overrides the keypoint selection: only those points are described (indices
        of non-finite points dropped), their neighbourhoods still use the whole cloud (the
        odometry's dense mode, :class:`relnav.odometry.Odometry` ``dense_keypoints``).
        """
        timings: dict[str, float] = {}
        t0 = time.perf_counter()
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        finite = np.isfinite(P).all(axis=1)
        if keypoints is not None:
            keypoints = np.asarray(keypoints, dtype=np.int64).reshape(-1)
            if keypoints.size and (keypoints.min() < 0 or keypoints.max() >= P.shape[0]):
                raise ConfigError(f"keypoints must index the {P.shape[0]} points")
            if not finite.all():
                new_index = np.cumsum(finite) - 1
                keypoints = new_index[keypoints[finite[keypoints]]]
        P = P[finite]
        tr = mean_resolution(P, statistic=self.resolution) if P.shape[0] >= 2 else float("nan")
        timings["resolution"] = time.perf_counter() - t0
        if P.shape[0] < self.min_points or not np.isfinite(tr) or tr <= 0:
            empty = np.zeros((0, self.descriptor_spec.dim), np.float32)
            return CloudFeatures(P, tr, float("nan"), np.zeros(0, np.int64), empty, timings)
        r = float(radius) if radius is not None else self.radius_factor * tr
        t0 = time.perf_counter()
        if keypoints is not None:
            kp = keypoints
        elif self.keypoint_method == "all":
            kp = np.arange(P.shape[0], dtype=np.int64)
        else:
            from relnav.features.keypoints import select_keypoints

            opts = dict(self.keypoint_options)
            if self.keypoint_method == "voxel":
                opts.setdefault("voxel_size", 2.0 * tr)
            kp = select_keypoints(P, self.keypoint_method, **opts)
        timings["keypoints"] = time.perf_counter() - t0
        normals = None
        if self.descriptor_spec.needs_normals:
            t0 = time.perf_counter()
            normals = (
                estimate_normals(P, k=self.normal_k)
                if self.normal_k is not None
                else estimate_normals(P, radius=self.normal_radius_factor * tr)
            )
            timings["normals"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        desc = compute_descriptors(
            self.descriptor_spec.name,
            P,
            radius=r,
            keypoints=kp,
            normals=normals,
            **self.descriptor_options,
        )
        timings["describe"] = time.perf_counter() - t0
        return CloudFeatures(P, tr, r, kp, desc, timings, normals)

    def describe_at(self, cloud: CloudFeatures, radius: float) -> CloudFeatures:
        """``cloud`` described again with support ``radius`` (m), reusing its resolution,
        keypoints and normals (paper 1's one radius for both clouds of a pair)."""
        if cloud.keypoints.size == 0 or cloud.points.shape[0] < self.min_points:
            return cloud
        t0 = time.perf_counter()
        desc = compute_descriptors(
            self.descriptor_spec.name,
            cloud.points,
            radius=float(radius),
            keypoints=cloud.keypoints,
            normals=cloud.normals,
            **self.descriptor_options,
        )
        timings = {"describe_target": time.perf_counter() - t0}
        return CloudFeatures(
            cloud.points,
            cloud.resolution,
            float(radius),
            cloud.keypoints,
            desc,
            timings,
            cloud.normals,
        )

    # ------------------------------------------------------------------ pair work
    def register(
        self, source: np.ndarray, target: np.ndarray, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register ``source`` onto ``target`` (``init`` is ignored: the method is global)."""
        src = self.prepare(source)
        radius = src.radius if self.radius_from == "source" else None
        return self.register_prepared(src, self.prepare(target, radius=radius), init=init)

    def register_prepared(
        self, source: CloudFeatures, target: CloudFeatures, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register two prepared clouds; the source's timings are counted in the result."""
        from relnav.matching.correspondences import Correspondences
        from relnav.matching.nn import match_descriptors

        timings = dict(source.timings)
        if (
            self.radius_from == "source"
            and np.isfinite(source.radius)
            and target.radius != source.radius
        ):
            target = self.describe_at(target, source.radius)
            dt = target.timings["describe_target"]
            timings["describe"] = timings.get("describe", 0.0) + dt
        n_src, n_tgt = source.points.shape[0], target.points.shape[0]
        info: dict[str, Any] = {"n_source": n_src, "n_target": n_tgt}
        if n_src == 0 or n_tgt == 0:
            return RegistrationResult(
                status="failed", message="empty cloud", timings=timings, info=info
            )
        if source.keypoints.size == 0 or target.keypoints.size == 0:
            return RegistrationResult(
                status="degenerate",
                message=f"too few distinct points (source {n_src}, target {n_tgt})",
                timings=timings,
                info=info,
            )
        t0 = time.perf_counter()
        backward = self.match_from == "target"  # paper 1 eq. 5: each feature of P_k to P_{k+1}
        a, b = (target, source) if backward else (source, target)
        corr = match_descriptors(
            a.descriptors,
            b.descriptors,
            tau=self.tau,
            mutual=self.mutual,
            normalize=self.unit_descriptors,
            src_keypoints=a.keypoints,
            tgt_keypoints=b.keypoints,
        )
        if backward:  # as source → target pairs
            corr = Correspondences(corr.tgt_idx, corr.src_idx, corr.distance)
        timings["match"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        grouped = self.grouper.select(
            source.points, target.points, corr, resolution=source.resolution
        )
        timings["group"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        est = self.estimator.estimate(source.points, target.points, grouped)
        timings["estimate"] = time.perf_counter() - t0
        info.update(est.info)
        info["n_grouped"] = len(grouped)
        message = "" if est.status == "ok" else str(est.info.get("message", est.status))
        T, cov = est.T_target_source, est.covariance
        if self.refiner is not None and est.status == "ok":
            t0 = time.perf_counter()
            ref = self.refiner.register(source.points, target.points, init=T)
            timings["refine"] = time.perf_counter() - t0
            info["refine_status"] = ref.status
            if ref.status == "ok":
                T, cov = ref.T_target_source, ref.covariance
        rmse = float("nan")
        if len(grouped) and est.status == "ok":
            moved = transform_points(T, source.points[grouped.src_idx])
            res = np.linalg.norm(moved - target.points[grouped.tgt_idx], axis=1)
            rmse = float(np.sqrt(np.mean(res**2)))
        return RegistrationResult(
            T_target_source=T,
            covariance=cov,
            fitness=len(grouped) / max(len(corr), 1),
            inlier_rmse=rmse,
            n_correspondences=len(corr),
            n_inliers=len(grouped),
            converged=est.converged,
            status=est.status,
            timings=timings,
            message=message,
            info=info,
        )


def _parse_spec(spec: str | None) -> tuple[str, str, str]:
    if not spec:
        return "hods", "gcc", "alphabeta"
    parts = [p.strip().lower() for p in spec.split("+")]
    if len(parts) == 1:
        return parts[0], "gcc", "alphabeta"
    if len(parts) == 3:
        return parts[0], parts[1], parts[2]
    raise ConfigError(
        f"feature method spec {spec!r} must be 'descriptor+grouper+estimator' "
        "(e.g. feature:hods+gcc+alphabeta)"
    )


@register_method(
    "feature",
    "Paper 1: local descriptors → NN matching (τ) → grouping → adaptive recursive filter",
    examples=[
        "feature:hods+gcc+alphabeta",
        "feature:shot+gcc+kalman",
        "feature:fpfh+ransac+svd",
    ],
)
def _make_feature(spec: str | None, **options: Any) -> FeatureRegistration:
    d, g, e = _parse_spec(spec)
    _check_nested_options(d, g, e, options)
    return FeatureRegistration(d, g, e, **options)


def _check_nested_options(d: str, g: str, e: str, options: dict[str, Any]) -> None:
    """Check ``descriptor_/grouper_/estimator_options`` before anything runs (ConfigError)."""
    import inspect

    from relnav.config import check_options
    from relnav.estimation.base import estimator_factory
    from relnav.matching.grouping import grouper_factory

    own = set(inspect.signature(FeatureRegistration.__init__).parameters) - {"self"}
    for key, name, factory_of in (
        ("estimator_options", e, estimator_factory),
        ("grouper_options", g, grouper_factory),
        ("descriptor_options", d, None),
    ):
        sub = options.get(key)
        if sub is None:
            continue
        if not isinstance(sub, dict):
            raise ConfigError(f"feature: {key} must be a mapping of key=value, got {sub!r}")
        misplaced = sorted(set(sub) & own - {"descriptor", "grouper", "estimator"})
        if misplaced:
            raise ConfigError(
                f"feature: {key}.{misplaced[0]} is an option of the feature method itself "
                f"(use -O {misplaced[0]}=...)"
            )
        factory = factory_of(name) if factory_of is not None else None
        if factory is not None:
            check_options(factory, sub, where=f"feature {key} ({name})")
