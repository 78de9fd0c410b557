"""Stateful frame-to-frame odometry (:class:`Odometry`).

Convention (DESIGN §3): the current scan ``k+1`` (source) is registered onto the previous scan
``k`` (target); the step is ``T_k_k1 = T_target_source`` and the pose chain is
``T_world_sensor[k+1] = T_world_sensor[k] @ T_k_k1``. Paper 1's ``R*`` (maps ``P_k → P_{k+1}``)
is the inverse of this step; the estimators convert in one place, nowhere else.

A frame whose registration is ``degenerate`` or ``failed`` (or raises) is never dropped: it keeps
the **motion prior** (the last accepted step — constant velocity — by default, or the identity)
and is flagged in :class:`OdometryStep`. Never ``ok``: a non-finite or non-rigid step, a step
translated farther than the two scans reach (they could not overlap), a scan with coordinates
beyond :data:`relnav.io.pointclouds.ABSURD_COORDINATE` (misread bytes) or an unreadable scan
(:meth:`Odometry.skip_frame`); after such a scan the next one is registered onto the last
usable scan.

An ``ok`` step of a pairwise method is then re-examined without ground truth
(:mod:`relnav.odometry.step_check`: a point-to-plane referee started at the step and a
forward–backward registration); a step they disagree with is ``flagged`` — kept in the chain,
not trusted.

**Dense mode (beyond paper 1; only for scans reduced by the point budget).** For a feature
pipeline (``feature:...``, ``dense_refine="auto"``), a scan reduced by the point budget
(:mod:`relnav.odometry.budget`, 3 000 points) is described at a seeded random 1 000 of its points
(``dense_keypoints``; their neighbourhoods use all 3 000), and the pipeline's step is a *coarse*
estimate refined by relnav's point-to-plane ICP on the two reduced scans, started at it (coarse
to fine). That ICP is the step check's referee (:mod:`relnav.odometry.step_check`), run once:
the check judges the COARSE step against it exactly as before (a coarse step the ICP moves by
more than the step tolerance, or from which it fails, is ``flagged``). A doubtful coarse step
(moved by more than the tolerance, or the ICP failed from it) gets a second ICP started at the
motion prior, and the candidate with the higher fitness is kept; a step refined from the prior
is always ``flagged``. The refined step replaces the coarse one when an ICP is ``ok``.
``result.info`` records ``refine_status``, ``dense_refine`` (the ICP's move, fitness, start
``"coarse"`` or ``"prior"``, the coarse ``T_coarse``) and ``dense_keypoints``;
``result.timings["refine"]`` its cost. Scans at or below the budget never see any of it, so
paper 1's pipeline and numbers are untouched (the same poses, bit for bit).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.geometry.rotations import rotation_angle
from relnav.geometry.se3 import invert
from relnav.io.pointclouds import ABSURD_COORDINATE
from relnav.odometry.budget import (
    DEFAULT_BUDGET_TARGET,
    DEFAULT_POINT_BUDGET,
    SAMPLERS,
    check_point_budget,
    reduce_to_budget,
)
from relnav.registration.base import PreparedRegistration, Registration, get_registration
from relnav.registration.result import RegistrationResult
from relnav.scan import Scan

__all__ = ["DEFAULT_DENSE_KEYPOINTS", "MotionPrior", "Odometry", "OdometryStep"]

log = logging.getLogger(__name__)

DEFAULT_DENSE_KEYPOINTS = 1000
"""Points a feature pipeline describes in a budget-reduced scan in dense mode."""

MotionPrior = Literal["constant_velocity", "identity"]


@dataclass
class OdometryStep:
    """Outcome of one :meth:`Odometry.register_frame` call.

    Attributes
    ----------
    pose : (4, 4) float64
        ``T_world_sensor`` of this frame.
    step : (4, 4) float64
        ``T_prev_curr`` applied to reach it (identity for the first frame).
    result : RegistrationResult or None
        The registration (None for the first frame).
    used_prior : bool
        True when the step is the motion prior because the registration was not ``ok``.
    status : str
        ``"first"``, ``"ok"``, ``"flagged"`` (registered, kept, but not trusted: see
        :mod:`relnav.odometry.step_check`), ``"degenerate"`` or ``"failed"``.
    n_points : int
        Points in the scan.
    time_s : float
        Wall-clock seconds spent on this frame (preparation + registration).
    n_used : int or None
        Points passed to the registration after the point budget (None: not recorded).
    budget_voxel : float
        Voxel (m) of the point-budget reduction; 0 when the scan was within the budget.
    """

    pose: np.ndarray
    step: np.ndarray
    result: RegistrationResult | None
    used_prior: bool
    status: str
    n_points: int
    time_s: float
    n_used: int | None = None
    budget_voxel: float = 0.0


class Odometry:
    """Frame-to-frame odometry with any registration method.

    Parameters
    ----------
    method : str or Registration
        A method string (``"feature:hods+gcc+alphabeta"``) or a registration object.
    initial_pose : (4, 4) float64, optional
        ``T_world_sensor`` of the first frame (identity by default).
    motion_prior : {"constant_velocity", "identity"}
        Step used for frames whose registration is not ``ok``, and the initial guess given to
        the registration.
    gate_rotation_deg, gate_translation : float, optional
        Innovation gate (a relnav extension, off by default as in paper 1): a registered step
        whose rotation differs from the motion prior's by more than ``gate_rotation_deg``
        degrees, or whose translation differs by more than ``gate_translation`` metres, is
        rejected (status ``failed``) and the prior is used instead. It protects the chain from
        the occasional wrong registration of a smooth trajectory; it also rejects genuine
        manoeuvres larger than the gate.
    step_check : {"auto", "off", "referee", "backward", "full"} or bool
        Re-examine every ``ok`` step without ground truth and flag the doubtful ones
        (:mod:`relnav.odometry.step_check`; ``auto``: forward–backward and a point-to-plane
        referee for point-to-point ICP, forward–backward for point-to-plane ICP and for feature
        pipelines refined by ICP, the referee for other feature pipelines, off for other
        methods and for registration objects).
    step_tolerance_m, step_tolerance_deg : float
        Accuracy a step must have to stay ``ok`` (m, degrees; default 0.5 m, 5°).
    point_budget : int, None or "auto"
        Largest scan passed to the method: above it the scan is voxel-downsampled
        (:func:`relnav.odometry.budget.reduce_to_budget`; voxel and counts in the step and in
        ``result.info["point_budget"]``); at or below it the scan is passed unchanged.
        ``"auto"`` (default): :data:`~relnav.odometry.budget.DEFAULT_POINT_BUDGET` for
        relnav-native methods, none for the peers (``[baselines]`` methods, which downsample
        with their own settings) and for registration objects. ``None``: no budget (paper 1's
        literal "describe every vertex" at any density).
    budget_target : int or None
        Size a scan above the budget is reduced to (default 3 000, capped at the budget;
        None: the budget itself). See :mod:`relnav.odometry.budget` for why it is smaller than
        the budget.
    budget_sampler : {"random", "voxel"}
        How a scan above the budget is reduced (:mod:`relnav.odometry.budget`: a seeded random
        subset by default, measured better than voxel centroids).
    budget_seed : int
        Seed of the random reduction; frame ``k`` draws with ``default_rng([budget_seed, k])``.
    dense_refine : {"auto", "on", "off"} or bool
        Refine a step between two budget-reduced scans by point-to-plane ICP on those scans,
        started at the method's step (see the module docstring; a relnav extension beyond
        paper 1, never applied to scans within the budget). ``"auto"`` (default): on for
        feature pipelines (``feature:...``) without their own ``refine`` option, off for other
        methods and for registration objects; ``"on"``: any method.
    dense_keypoints : int or None
        With the dense refinement on, a feature pipeline that describes every point
        (``keypoints="all"``) describes only a seeded random ``dense_keypoints`` points of a
        budget-reduced scan (default :data:`DEFAULT_DENSE_KEYPOINTS`; their neighbourhoods
        still use the whole reduced scan, and the refinement uses every point of it).
        ``None``: describe every point of the reduced scan.
    **method_options
        Options for :func:`relnav.registration.get_registration` when ``method`` is a string.
    """

    #: what a run may ask besides ``register_frame`` (:mod:`relnav.odometry.tracker`)
    capabilities = frozenset({"skip_frame", "step_check"})

    def __init__(
        self,
        method: str | Registration,
        *,
        initial_pose: np.ndarray | None = None,
        motion_prior: MotionPrior = "constant_velocity",
        gate_rotation_deg: float | None = None,
        gate_translation: float | None = None,
        step_check: str | bool = "auto",
        step_tolerance_m: float = 0.5,
        step_tolerance_deg: float = 5.0,
        point_budget: int | str | None = "auto",
        budget_target: int | None = DEFAULT_BUDGET_TARGET,
        budget_sampler: str = "random",
        budget_seed: int = 0,
        dense_refine: str | bool = "auto",
        dense_keypoints: int | None = DEFAULT_DENSE_KEYPOINTS,
        **method_options: Any,
    ) -> None:
        from relnav.odometry.options import check_odometry_options, parse_initial_pose
        from relnav.odometry.step_check import StepChecker, make_referee, resolve_step_check

        opts = check_odometry_options(
            {
                "motion_prior": motion_prior,
                "gate_rotation_deg": gate_rotation_deg,
                "gate_translation": gate_translation,
            }
        )
        T0 = parse_initial_pose(initial_pose)
        if isinstance(T0, str):
            raise ConfigError("Odometry: initial_pose must be a (4, 4) matrix or None")
        self.registration = (
            get_registration(method, **method_options) if isinstance(method, str) else method
        )
        check = resolve_step_check(step_check, method, method_options)
        tolerance_m = _number("step_tolerance_m", step_tolerance_m)
        tolerance_deg = _number("step_tolerance_deg", step_tolerance_deg)
        self._tolerance_m = tolerance_m
        self._tolerance_rad = float(np.radians(tolerance_deg))
        self.step_checker: StepChecker | None = (
            None
            if check == "off"
            else StepChecker(
                self.registration,
                check,  # type: ignore[arg-type]
                tolerance_m=tolerance_m,
                tolerance_deg=tolerance_deg,
            )
        )
        self.point_budget = _resolve_budget(point_budget, method)
        self.budget_target = _optional_count(budget_target, "budget_target")
        if budget_sampler not in SAMPLERS:
            raise ConfigError(
                f"budget_sampler must be one of {', '.join(SAMPLERS)}, got {budget_sampler!r}"
            )
        self.budget_sampler = budget_sampler
        if isinstance(budget_seed, bool) or not isinstance(budget_seed, int | np.integer):
            raise ConfigError(f"budget_seed must be an integer, got {budget_seed!r}")
        self.budget_seed = int(budget_seed)
        self.dense_refine = _resolve_dense_refine(dense_refine, method, method_options)
        self.dense_keypoints = _optional_count(dense_keypoints, "dense_keypoints")
        self._refiner: Any = None
        if self.dense_refine:
            if self.step_checker is not None and self.step_checker.uses_referee:
                self._refiner = self.step_checker.referee  # one ICP: refinement and referee
            else:
                self._refiner = make_referee()
        self.motion_prior: MotionPrior = opts.motion_prior
        g_rot, g_t = opts.gate_rotation_deg, opts.gate_translation
        self.gate_rotation = None if g_rot is None else float(np.radians(g_rot))
        self.gate_translation = g_t
        self.pose = np.eye(4) if T0 is None else np.array(T0, dtype=float)
        self.last_step = np.eye(4)
        self._prev_points: np.ndarray | None = None
        self._prev_prepared: Any = None
        self._prev_referee: Any = None
        self._prev_refine_cloud: Any = None
        self._prev_reach = 0.0
        self._anchor_pose = self.pose.copy()
        self._gap = 0
        self.n_frames = 0

    @property
    def prior_step(self) -> np.ndarray:
        """The step the motion prior predicts for the next frame."""
        return self.last_step.copy() if self.motion_prior == "constant_velocity" else np.eye(4)

    def _prior_over(self, n_steps: int) -> np.ndarray:
        """The motion prior over ``n_steps`` frames (``prior_step ** n_steps``)."""
        return np.linalg.matrix_power(self.prior_step, max(int(n_steps), 1))

    def register_frame(self, scan: Scan | np.ndarray) -> OdometryStep:
        """Register a new scan onto the previous one and advance the pose chain.

        After frames skipped with :meth:`skip_frame`, the scan is registered onto the last
        usable scan (initial guess: the motion prior over the gap) and the pose chain restarts
        from that scan's pose.
        """
        points = scan.points if isinstance(scan, Scan) else np.asarray(scan, dtype=np.float64)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        reach = _reach(points)
        if reach > ABSURD_COORDINATE:  # misread bytes, not a scene: never registered
            return self.skip_frame(
                f"scan coordinates up to {reach:.3g} m (limit {ABSURD_COORDINATE:.0e} m): "
                "misread data?"
            )
        t0 = time.perf_counter()
        n_raw = len(points)
        points, budget = reduce_to_budget(
            points,
            self.point_budget,
            target=self.budget_target,
            sampler=self.budget_sampler,
            seed=[self.budget_seed, self.n_frames],
        )
        prepared = None
        prepare_error = ""
        dense_kp = self._dense_keypoints(points) if budget.reduced else None
        if isinstance(self.registration, PreparedRegistration):
            try:
                if dense_kp is not None:  # a FeatureRegistration (see _dense_keypoints)
                    prepare: Any = self.registration.prepare
                    prepared = prepare(points, keypoints=dense_kp)
                else:
                    prepared = self.registration.prepare(points)
            except Exception as e:  # a bad scan must not stop the run
                log.warning("frame %d: preparation failed: %s", self.n_frames, e)
                prepare_error = f"{type(e).__name__}: {e}"
        referee = None
        if self.step_checker is not None and not prepare_error:
            referee = self.step_checker.prepare(points)
        refine_cloud = None  # the dense refinement's per-scan data (reduced scans only)
        if self._refiner is not None and budget.reduced and not prepare_error:
            if referee is not None:
                refine_cloud = referee
            else:
                from relnav.odometry.step_check import prepare_referee

                refine_cloud = prepare_referee(self._refiner, points)
        if self.n_frames == 0:
            out = OdometryStep(
                self.pose.copy(),
                np.eye(4),
                None,
                False,
                "first",
                n_raw,
                time.perf_counter() - t0,
                len(points),
                budget.voxel,
            )
        else:
            gap = self._gap + 1  # frames between the previous usable scan and this one
            prior = self._prior_over(gap)
            if self._prev_points is None:
                result = RegistrationResult(status="failed", message="no usable previous scan")
            else:
                result = self._register(points, prepared, prepare_error, prior)
            if budget.reduced:
                result.info["point_budget"] = {
                    "budget": self.point_budget,
                    "target": self.budget_target,
                    "n_in": budget.n_in,
                    "n_out": budget.n_out,
                    "voxel": budget.voxel,
                    "sampler": budget.sampler,
                    "seed": [self.budget_seed, self.n_frames],
                }
                result.timings["budget"] = budget.time_s
                if dense_kp is not None:
                    result.info["dense_keypoints"] = int(dense_kp.size)
            if result.status == "ok":
                self._check_plausible(result, reach)
            if result.status == "ok":
                self._apply_gate(result, prior)
            refined = adopted = None
            if result.status == "ok" and budget.reduced and self._refiner is not None:
                refined, adopted = self._refine(result, refine_cloud, referee is None, prior)
            if result.status == "ok" and self.step_checker is not None:
                self.step_checker.judge(
                    result,
                    source=points,
                    target=self._prev_points,  # type: ignore[arg-type]
                    source_prepared=prepared,
                    target_prepared=self._prev_prepared,
                    source_referee=referee,
                    target_referee=self._prev_referee,
                    referee_result=refined,
                )
            if adopted is not None and result.status in ("ok", "flagged"):
                result.T_target_source = adopted.T_target_source.copy()
                result.covariance = adopted.covariance
                if adopted is not refined and result.status == "ok":  # no check flagged it
                    result.status = "flagged"  # type: ignore[assignment]
                    result.message = (
                        "step not trusted: the method's step was doubtful; refined from the "
                        "motion prior instead"
                    )
            used_prior = result.status not in ("ok", "flagged")
            if used_prior:
                step = self.prior_step
                log.info(
                    "frame %d: registration %s (%s); using the %s motion prior",
                    self.n_frames,
                    result.status,
                    result.message,
                    self.motion_prior,
                )
                self.pose = self.pose @ step
            elif gap == 1:
                step = result.T_target_source
                self.last_step = step.copy()
                self.pose = self.pose @ step
            else:  # registered across a gap: restart the chain from the last usable scan
                new_pose = self._anchor_pose @ result.T_target_source
                step = invert(self.pose) @ new_pose
                self.pose = new_pose
            out = OdometryStep(
                self.pose.copy(),
                step.copy(),
                result,
                used_prior,
                result.status,
                n_raw,
                time.perf_counter() - t0,
                len(points),
                budget.voxel,
            )
        self._prev_points = points
        self._prev_prepared = prepared
        self._prev_referee = referee
        self._prev_refine_cloud = refine_cloud
        self._prev_reach = reach
        self._anchor_pose = self.pose.copy()
        self._gap = 0
        self.n_frames += 1
        return out

    def skip_frame(self, reason: str) -> OdometryStep:
        """Flag a frame whose scan could not be read: status ``failed``, pose from the motion
        prior; the next scan is registered onto the last usable one."""
        t0 = time.perf_counter()
        result = RegistrationResult(status="failed", message=reason)
        if self.n_frames == 0:
            step = np.eye(4)
            self._prev_points = None
        else:
            step = self.prior_step
            self.pose = self.pose @ step
        if self._prev_points is None:  # nothing usable yet: the next scan starts the chain
            self._anchor_pose = self.pose.copy()
        else:
            self._gap += 1
        log.warning("frame %d: skipped (%s)", self.n_frames, reason)
        self.n_frames += 1
        return OdometryStep(
            self.pose.copy(), step.copy(), result, True, "failed", 0, time.perf_counter() - t0
        )

    def _check_plausible(self, result: RegistrationResult, reach: float) -> None:
        """Reject (in place) an ``ok`` step that no scene allows: non-finite or non-rigid, or
        translated farther than the two scans reach (then they cannot overlap at all).

        Points are in the sensor frame, within ``reach`` (m) of it, so ``target = T source``
        with any overlap needs ``|t| <= reach_source + reach_target``.
        """
        T = np.asarray(result.T_target_source, dtype=np.float64)
        R = T[:3, :3]
        if (
            T.shape != (4, 4)
            or not np.isfinite(T).all()
            or np.abs(R.T @ R - np.eye(3)).max() > 1e-6
            or np.linalg.det(R) <= 0
        ):
            result.status = "failed"
            result.message = "registration returned a non-finite or non-rigid transform"
            return
        bound = reach + self._prev_reach
        t = float(np.linalg.norm(T[:3, 3]))
        if not t <= bound:
            result.status = "failed"
            result.message = (
                f"step translation {t:.3g} m exceeds what the scans allow ({bound:.3g} m: "
                "they could not overlap)"
            )

    def _apply_gate(self, result: RegistrationResult, prior: np.ndarray) -> None:
        """Reject (in place) a step too far from the motion prior."""
        if self.gate_rotation is None and self.gate_translation is None:
            return
        d = invert(prior) @ result.T_target_source
        d_rot = rotation_angle(d[:3, :3])
        d_t = float(np.linalg.norm(result.T_target_source[:3, 3] - prior[:3, 3]))
        if (self.gate_rotation is not None and d_rot > self.gate_rotation) or (
            self.gate_translation is not None and d_t > self.gate_translation
        ):
            result.status = "failed"
            result.message = (
                f"step rejected by the motion gate (Δrot {np.degrees(d_rot):.1f}°, "
                f"Δt {d_t:.3g} m from the prior)"
            )
            result.info["gated"] = True

    def _dense_keypoints(self, points: np.ndarray) -> np.ndarray | None:
        """The points a feature pipeline describes in a budget-reduced scan: a seeded random
        ``dense_keypoints`` of them (``default_rng([budget_seed, k, 1])`` for frame ``k``,
        sorted), or None (describe as the method says: dense mode off, not a feature pipeline
        with ``keypoints="all"``, or the scan is not larger)."""
        from relnav.registration.feature import FeatureRegistration

        K = self.dense_keypoints
        reg = self.registration
        if (
            K is None
            or not self.dense_refine
            or not isinstance(reg, FeatureRegistration)
            or reg.keypoint_method != "all"
            or len(points) <= K
        ):
            return None
        rng = np.random.default_rng([self.budget_seed, self.n_frames, 1])
        return np.sort(rng.choice(len(points), size=K, replace=False)).astype(np.int64)

    def _refine(
        self, result: RegistrationResult, cloud: Any, count_prepare: bool, prior: np.ndarray
    ) -> tuple[RegistrationResult | None, RegistrationResult | None]:
        """The dense refinement of an ``ok`` step between two budget-reduced scans.

        Point-to-plane ICP started at the method's (coarse) step. When it fails from there or
        moves the step by more than the step tolerance (the coarse step is doubtful: the step
        check will flag it), the same ICP is also started at the motion ``prior`` and the
        candidate with the higher fitness (inliers / source points; ties: lower inlier RMSE)
        is kept. Records ``info["refine_status"]``, ``info["dense_refine"]`` and
        ``timings["refine"]`` (s; with the current scan's ICP preparation when
        ``count_prepare``, i.e. when the step check does not count it).

        Returns
        -------
        judged : RegistrationResult or None
            The ICP started at the coarse step (the step check's referee); None when one of
            the scans has no refinement data.
        adopted : RegistrationResult or None
            The refinement to adopt (``ok``), or None (keep the coarse step).
        """
        from relnav.odometry.step_check import step_difference

        prev = self._prev_refine_cloud
        if cloud is None or prev is None:
            result.info["refine_status"] = "skipped"
            result.info["dense_refine"] = {"message": "no refinement data for one of the scans"}
            return None, None
        t0 = time.perf_counter()
        T = np.asarray(result.T_target_source, dtype=np.float64)
        ref = self._run_refiner(cloud, prev, T)
        record: dict[str, Any] = {"method": self._refiner.name, "status": ref.status}
        adopted = ref if ref.status == "ok" else None
        doubtful = True
        if ref.status == "ok":
            d_rot, d_t = step_difference(T, ref.T_target_source)
            record.update(rot_deg=float(np.degrees(d_rot)), t=d_t, fitness=ref.fitness)
            doubtful = d_rot > self._tolerance_rad or d_t > self._tolerance_m
        else:
            record["message"] = ref.message
        record["start"] = "coarse"
        if doubtful:  # a second start at the motion prior
            alt = self._run_refiner(cloud, prev, prior)
            record["prior_status"] = alt.status
            if alt.status == "ok":
                record["prior_fitness"] = alt.fitness
                if adopted is None or (alt.fitness, -alt.inlier_rmse) > (
                    adopted.fitness,
                    -adopted.inlier_rmse,
                ):
                    adopted = alt
                    record["start"] = "prior"
        record["T_coarse"] = T.copy()
        dt = time.perf_counter() - t0 + (cloud.time_s if count_prepare else 0.0)
        result.timings["refine"] = result.timings.get("refine", 0.0) + dt
        result.info["refine_status"] = "ok" if adopted is not None else ref.status
        result.info["dense_refine"] = record
        return ref, adopted

    def _run_refiner(self, cloud: Any, prev: Any, init: np.ndarray) -> RegistrationResult:
        """The refinement ICP from ``init``; a raised error becomes a ``failed`` result."""
        try:
            return self._refiner.register_prepared(cloud.cloud, prev.cloud, init=init)
        except Exception as e:  # the refinement must never stop the run
            log.warning(
                "frame %d: dense refinement raised %s: %s", self.n_frames, type(e).__name__, e
            )
            return RegistrationResult(status="failed", message=f"{type(e).__name__}: {e}")

    def _register(
        self, points: np.ndarray, prepared: Any, prepare_error: str, prior: np.ndarray
    ) -> RegistrationResult:
        if prepare_error:
            return RegistrationResult(status="failed", message=prepare_error)
        try:
            if prepared is not None and self._prev_prepared is not None:
                return self.registration.register_prepared(  # type: ignore[union-attr]
                    prepared, self._prev_prepared, init=prior
                )
            if prepared is None and isinstance(self.registration, PreparedRegistration):
                return RegistrationResult(status="failed", message="previous frame unusable")
            return self.registration.register(points, self._prev_points, init=prior)
        except Exception as e:  # never let one frame stop the run; flag it
            log.warning("frame %d: registration raised %s: %s", self.n_frames, type(e).__name__, e)
            return RegistrationResult(status="failed", message=f"{type(e).__name__}: {e}")


def _optional_count(value: Any, name: str) -> int | None:
    """:func:`check_point_budget` of ``value``; the command line's ``None``/``null`` is None."""
    return check_point_budget(
        None if str(value).strip().lower() in ("none", "null") else value, name
    )


def _number(name: str, value: Any) -> float:
    """A positive finite number, or :class:`ConfigError` naming the option."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a positive number, got {value!r}") from None
    if isinstance(value, bool) or not (np.isfinite(v) and v > 0):
        raise ConfigError(f"{name} must be a positive number, got {value!r}")
    return v


def _resolve_budget(budget: int | str | None, method: str | Registration) -> int | None:
    """The point budget for ``method`` (see :class:`Odometry`); ConfigError if invalid."""
    if isinstance(budget, str) and budget.strip().lower() in ("none", "null"):
        return None  # the command line's -O point_budget=None
    if isinstance(budget, str):
        if budget.strip().lower() != "auto":
            raise ConfigError(f"point_budget must be an integer, None or 'auto', got {budget!r}")
        if not isinstance(method, str):
            return None
        from relnav.registration.base import available_methods

        meta = available_methods().get(method.partition(":")[0].strip().lower())
        return DEFAULT_POINT_BUDGET if meta is not None and meta["extra"] is None else None
    return check_point_budget(budget)


def _resolve_dense_refine(
    mode: str | bool, method: str | Registration, options: dict[str, Any]
) -> bool:
    """Whether the dense refinement runs (see :class:`Odometry`); ConfigError if invalid."""
    if isinstance(mode, bool):
        return mode
    m = str(mode).strip().lower()
    if m in ("on", "true", "yes"):
        return True
    if m in ("off", "false", "no", "none"):
        return False
    if m != "auto":
        raise ConfigError(f"dense_refine must be 'auto', 'on' or 'off', got {mode!r}")
    if not isinstance(method, str):
        return False
    family = method.strip().lower().partition(":")[0]
    return family == "feature" and not options.get("refine")


def _reach(points: np.ndarray) -> float:
    """Largest distance (m) of a finite point from the sensor; 0 for no finite point."""
    if points.size == 0:
        return 0.0
    n = np.sqrt(np.einsum("ij,ij->i", points, points))
    n = n[np.isfinite(n)]
    return float(n.max()) if n.size else 0.0
