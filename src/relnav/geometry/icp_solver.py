"""ICP on prepared clouds: point-to-point, point-to-plane and X84 (ALGORITHMS §C.1–C.3).

The registration methods ``icp-point``, ``icp-plane`` and ``icp-x84``
(:mod:`relnav.registration.icp`) and the ``icp`` estimator of
:mod:`relnav.estimation.icp_refine` run this solver; it lives below both so that neither imports
the other.

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

**Implementation.** The whole loop runs in one numba function (``icp_kernels._icp_loop``) over
a numba KD-tree (:class:`relnav.geometry.kdtree.KDTree`, exact NN, queries transformed on the
fly); the rigid fit uses Horn's quaternion method (the same least-squares minimiser as
Arun/Umeyama SVD with the reflection guard) and small symmetric eigenproblems use Jacobi
rotations (:mod:`relnav.geometry.eigen`), so no LAPACK call is compiled (cold numba
compilation stays a few seconds; the cache makes later imports instant).
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
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.geometry.icp_kernels import (
    _icp_loop,
    _plane_system,
    information_ratio,
    point_information,
    reject_outliers,
)
from relnav.geometry.prepared_cloud import PreparedCloud, check_init, prepare_cloud
from relnav.geometry.registration_result import RegistrationResult

__all__ = [
    "PAPER_GATE",
    "PAPER_ROTATION_TOL",
    "PAPER_TRANSLATION_TOL",
    "ICPSolver",
]

log = logging.getLogger(__name__)

PAPER_GATE = 0.01
"""Paper 1's correspondence gate (m, [interpretation] of the unit)."""
PAPER_TRANSLATION_TOL = 0.01
"""Paper 1's translation-change stop threshold (m)."""
PAPER_ROTATION_TOL = 0.009
"""Paper 1's rotation-change stop threshold (rad, [interpretation] of the unit)."""

Thresholds = Literal["scale", "paper"]


def failed_result(
    status: str, message: str, T: np.ndarray, timings: dict, info: dict
) -> RegistrationResult:
    """A non-``ok`` result at ``T`` (shared by the ICP family)."""
    log.debug("registration %s: %s", status, message)
    return RegistrationResult(
        T_target_source=T.copy(), status=status, message=message, timings=timings, info=info
    )


def total_time(t: dict[str, float]) -> float:
    return float(sum(t.values()))


def register_clouds(
    method: Any,
    source: np.ndarray,
    target: np.ndarray,
    *,
    init: np.ndarray | None,
    target_normals: np.ndarray | None,
    resolution: bool,
) -> RegistrationResult:
    """``register`` of the ICP family on raw clouds: prepare the source (no normals; ``Tr``
    when ``resolution``) and the target (``method.prepare``), register the prepared pair and
    count the target's preparation in ``timings["prepare"]``."""
    src = prepare_cloud(source, min_points=method.min_points, resolution=resolution, name="source")
    tgt = method.prepare(target, normals=target_normals, name="target")
    result = method.register_prepared(src, tgt, init=init)
    result.timings["prepare"] = result.timings.get("prepare", 0.0) + total_time(tgt.timings)
    return result


def start_pair(
    source: PreparedCloud,
    target: PreparedCloud,
    init: Any,
    head: dict[str, Any],
    tail: dict[str, Any] | None = None,
) -> tuple[np.ndarray, dict[str, float], dict[str, Any], RegistrationResult | None]:
    """Common start of ``register_prepared`` for methods on prepared clouds.

    Returns the checked initial guess ``T0``, ``timings`` (the source's preparation), ``info``
    (``head``, the cloud sizes, ``tail``) and, when the guess or a cloud is unusable, the
    ``failed``/``degenerate`` result to return instead of registering.
    """
    timings: dict[str, float] = {"prepare": total_time(source.timings)}
    info: dict[str, Any] = {
        **head,
        "n_source": int(source.points.shape[0]),
        "n_target": int(target.points.shape[0]),
        "n_dropped_source": source.n_dropped,
        "n_dropped_target": target.n_dropped,
        **(tail or {}),
    }
    T0, msg = check_init(init)
    if T0 is None:
        return np.eye(4), timings, info, failed_result("failed", msg, np.eye(4), timings, info)
    for cloud, nm in ((source, "source"), (target, "target")):
        if not cloud.ok:
            m = cloud.message if cloud.message.startswith(nm) else f"{nm}: {cloud.message}"
            return T0, timings, info, failed_result(cloud.status, m, T0, timings, info)
    return T0, timings, info, None


def with_normals(target: PreparedCloud, *, min_points: int, normal_k: int) -> PreparedCloud:
    """``target`` with PCA normals (``normal_k`` neighbours), recomputed only when absent."""
    if target.normals is not None:
        return target
    return prepare_cloud(
        target.points,
        min_points=min_points,
        normals="pca",
        normal_k=normal_k,
        resolution=False,
        name="target",
    )


class ICPSolver:
    """Paper 1's ICP (point-to-point, point-to-plane, X84); see the module docstring.

    Returns :class:`~relnav.geometry.registration_result.RegistrationResult` (the registration
    method is :class:`relnav.registration.icp.ICP`).

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
        return register_clouds(
            self,
            source,
            target,
            init=init,
            target_normals=target_normals,
            resolution=self._needs_resolution,
        )

    def register_prepared(
        self, source: PreparedCloud, target: PreparedCloud, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        """Register two prepared clouds (see :meth:`prepare`); source timings are counted."""
        head = {
            "variant": self.variant,
            "thresholds": self.thresholds,
            "open3d_compatible": self.open3d_compatible,
            "outlier_rule": self.rule,
        }
        T0, timings, info, failed = start_pair(source, target, init, head, {"n_iterations": 0})
        if failed is not None:
            return failed
        if self.variant == "plane":
            target = with_normals(target, min_points=self.min_points, normal_k=self.normal_k)
        if self._needs_resolution and not np.isfinite(source.resolution):
            source = prepare_cloud(source.points, min_points=self.min_points, name="source")
        gate, ttol, rtol = self._resolve_thresholds(source)
        info.update(
            gate=gate, translation_tol=ttol, rotation_tol=rtol, resolution=source.resolution
        )
        if not (gate > 0):
            return failed_result("degenerate", f"invalid gate {gate} m", T0, timings, info)
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
            return failed_result("failed", msg, T0, timings, info)
        if code == 2:
            return failed_result(
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
            A, r2 = point_information(X, target.points, si, ti)
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
