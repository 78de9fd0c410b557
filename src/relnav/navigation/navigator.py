"""relnav's own navigator (method ``relnav``): frame-to-model tracking of a space target.

Each scan is registered to a model of the target accumulated in the target frame from the
previous scans (:class:`~relnav.navigation.voxel_map.VoxelMap`: a fine voxel map whose points carry
plane-like information from their map neighbours), by robust generalised ICP with the motion
model's prediction inside the least squares (:func:`~relnav.navigation.gicp.solve_scan_to_map`).
A static target and a tumbling one are the same problem in the target frame: the estimated pose
is ``T_target_sensor``.

Per frame ``k``:

1. **Predict** with the constant-velocity error-state filter of pose and body velocity
   (:class:`~relnav.navigation.motion.ConstantVelocityFilter`); its pose covariance ``P_pp``
   is the prior's. Before the first velocity is known, the prior is weak
   (``sigma_first_t``, ``sigma_first_r_deg``).
2. **Register** the scan onto the map from the prediction, the prediction's information inside
   the least squares: directions the scan cannot fix (a symmetric target about its axis, one
   flat panel) stay with the model instead of drifting. When the scan's points repeat the
   previous scan's surface points (not merely its rays), the answer is refined point to point
   (``repeat_refine``).
3. **Judge** the step from evidence only: too few scan points near the model, an overlap below
   ``min_overlap``, a degenerate scan information (``min_degeneracy``), or a correction
   inconsistent with the motion model (χ² beyond ``chi2_gate``) unless a second registration
   under the weak prior fits the scan as well (``recover_rms_ratio``; then the filter is
   widened) → ``failed``/``degenerate``: the pose keeps the prediction and the map is not
   updated. An accepted step whose covariance gives it a probability above
   ``flag_probability`` of an error beyond ``flag_limit_t`` / ``flag_limit_r_deg`` is
   ``flagged``: a label only, the step is used as an ``ok`` one.
4. **Update** the filter with the registered pose and the scan's own information (scaled by
   the observed residual) and the map with the scan; the fixed-lag smoother
   (``smooth_lag``) gives :meth:`Navigator.finalize` its trajectory.

Parameters are scale-free (multiples of the first scan's point spacing ``s₀``) and were chosen
on the navigation suite (``benchmarks/nav_suite.py``), then frozen.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from relnav.geometry.lie import exp_se3, log_se3
from relnav.geometry.se3 import invert
from relnav.navigation import multiview as mv
from relnav.navigation.attitude_input import AttitudeInput, aided_prediction
from relnav.navigation.gicp import (
    ScanToMapFit,
    degeneracy,
    left_information,
    normal_information,
    solve_scan_to_map,
    variance_factor,
)
from relnav.navigation.integrity import disagreement, exceedance_probability
from relnav.navigation.motion import ConstantVelocityFilter
from relnav.navigation.multistart import rotated_starts
from relnav.navigation.options import NavigatorConfig, in_map, loop_closer_options
from relnav.navigation.orbit import OrbitCorrection, correct_azimuth
from relnav.navigation.pose_graph import LoopCloser
from relnav.navigation.relocalize import Relocalizer
from relnav.navigation.repeated import RepeatedPoints
from relnav.navigation.revisit_check import RevisitCheck
from relnav.navigation.symmetry import (
    SymmetryAxis,
    marginalise_direction,
    stiffen_prior,
    symmetry_axis,
)
from relnav.navigation.voxel_map import VoxelMap, even_subset
from relnav.odometry.budget import reduce_to_budget
from relnav.odometry.odometry import OdometryStep
from relnav.registration.result import RegistrationResult
from relnav.scan import Scan

__all__ = ["Navigator", "NavigatorConfig", "exceedance_probability"]

log = logging.getLogger(__name__)


def _rms_radius(P: np.ndarray) -> float:
    """RMS distance of the points from their centroid (m): the scan's lever arm."""
    return float(np.sqrt(np.mean(np.sum((P - P.mean(0)) ** 2, axis=1))))


def _spacing(P: np.ndarray) -> float:
    """Median nearest-neighbour distance of a cloud (m)."""
    d, _ = cKDTree(P).query(P, k=2)
    s = float(np.median(d[:, 1]))
    return s if s > 0 else float(np.mean(d[:, 1]))


class Navigator:
    """Frame-to-model navigator with the :class:`~relnav.odometry.Odometry` interface.

    Parameters
    ----------
    initial_pose : (4, 4) float64, optional
        ``T_target_sensor`` of the first frame (identity by default).
    attitude : AttitudeInput, optional
        The chaser's measured attitude: the rotation of each step's prior (:mod:`.attitude_input`).
    **options
        Fields of :class:`NavigatorConfig`.
    """

    name = "relnav"

    def __init__(
        self,
        *,
        initial_pose: np.ndarray | None = None,
        attitude: AttitudeInput | None = None,
        **options: Any,
    ) -> None:
        from relnav.config import check_options

        options = check_options(NavigatorConfig, options, where="method 'relnav'")
        self.config = NavigatorConfig(**options)
        self.attitude = attitude
        self.pose = np.eye(4) if initial_pose is None else np.array(initial_pose, dtype=float)
        self.map: VoxelMap | None = None
        self.full_scan = np.zeros((0, 3))  # the frame's finite points before the point budget
        self.repeats = RepeatedPoints(self)
        self.motion: ConstantVelocityFilter | None = None
        self.spacing0 = float("nan")
        self.n_frames = 0
        self._online: list[np.ndarray] = []
        self._times: list[float] = []  # each online pose's time, s
        self._last_dt = 1.0
        self._f0 = 0
        self._rescaled = False
        self._initial_pose = self.pose.copy()
        self._boot: list[tuple[np.ndarray, float, int, np.ndarray]] | None = (
            [] if self.config.bootstrap_frames > 0 else None
        )
        self._boot_velocity: tuple[np.ndarray, np.ndarray] | None = None
        self.loop_closer: LoopCloser | None = None
        self.revisits: RevisitCheck | None = None
        self.relocalizer = Relocalizer(self) if self.config.relocalise else None
        c = self.config
        mv.check_window_options(c)
        self._win: list[mv.WindowFrame] | None = (
            [] if c.init_window > 0 or c.reanchor_frame > 0 else None
        )
        self._win_due = sorted({c.init_window, c.init_repeat, c.reanchor_frame} - {0})
        self._prefix: list[np.ndarray] = []
        self.refinements: list[dict[str, Any]] = []
        self.symmetry: SymmetryAxis | None = None
        self._sym_count = 0
        self.orbit: OrbitCorrection | None = None  # set by finalize() with orbit_mean_motion

    # ------------------------------------------------------------------ main entry
    def register_frame(self, scan: Scan | np.ndarray) -> OdometryStep:
        """Track one scan; returns the pose ``T_target_sensor`` and the step's status."""
        t_start = time.perf_counter()
        if isinstance(scan, Scan):
            P, t = scan.points, float(scan.time)
        else:
            P, t = np.asarray(scan, dtype=np.float64).reshape(-1, 3), float(self.n_frames)
        P = np.asarray(P, dtype=np.float64).reshape(-1, 3)
        n_raw = len(P)
        P = P[np.all(np.isfinite(P), axis=1)]
        self.full_scan = P
        P, _ = reduce_to_budget(P, self.config.max_points, seed=[0, self.n_frames])
        K = self.config.bootstrap_frames
        if self._boot is not None:
            self._boot.append((P, t, n_raw, self.full_scan))
        out = self._track(P, t, n_raw, t_start)
        mv.window_step(self, P, t, out)
        out = self._observe_loops(P, out)
        if self._boot is not None and len(self._boot) > K and self._rescaled:
            out = self._bootstrap(out)
        return out

    def _bootstrap(self, last: OdometryStep) -> OdometryStep:
        """Track the buffered first frames again, starting with the velocity they revealed.

        **[interpretation]** The first step has no motion prior: on sparse or near-symmetric
        scans it can settle short of the true motion, and the map and the velocity inherit the
        error. After ``bootstrap_frames`` frames the filter knows the velocity; the navigator is
        reset to the first frame and the same scans are tracked again from that velocity (with
        its covariance, inflated 4×), once. The online steps already returned are not changed;
        :meth:`finalize` returns the second pass's poses.
        """
        assert self.motion is not None and self._boot is not None
        frames, self._boot = self._boot, None
        v = self.motion.velocity.copy()
        P_vv = 4.0 * self.motion.P[6:, 6:].copy()
        self.map, self.motion = None, None
        self.pose = self._initial_pose.copy()
        self.n_frames, self._online, self._times, self._rescaled = 0, [], [], False
        self._boot_velocity = (v, P_vv)
        self.loop_closer, self.revisits = None, None
        self.symmetry, self._sym_count = None, 0
        self.repeats = RepeatedPoints(self)
        if self.relocalizer is not None:
            self.relocalizer = Relocalizer(self)
        out = last
        for P, t, n_raw, full in frames:
            self.full_scan = full  # the frame's own scan for the repeated-point refinement
            out = self._observe_loops(P, self._track(P, t, n_raw, time.perf_counter()))
        self._boot_velocity = None
        return OdometryStep(
            out.pose,
            out.step,
            out.result,
            out.used_prior,
            out.status,
            out.n_points,
            last.time_s + out.time_s,
        )

    def _track(self, P: np.ndarray, t: float, n_raw: int, t_start: float) -> OdometryStep:
        timings: dict[str, float] = {}
        if self.map is None:  # first usable frame builds the map
            out = self._first(P, t, n_raw, t_start)
            self.n_frames += 1
            self._online.append(out.pose.copy())
            self._times.append(t)
            return out

        assert self.motion is not None
        prev_pose = self.pose.copy()
        if not self._rescaled:  # per-frame sigmas → per second, with the first frame period
            dt = t - self.motion.t
            if np.isfinite(dt) and dt > 0:
                self.motion.P[6:, 6:] /= dt**2
                self.motion.sigma_acc = self.motion.sigma_acc / dt
            if self._boot_velocity is not None:  # second pass of the first frames
                self.motion.velocity = self._boot_velocity[0].copy()
                self.motion.P[6:, 6:] = self._boot_velocity[1]
            self._rescaled = True
            self.motion.start_smoothing(self.config.smooth_lag)
        if np.isfinite(t - self.motion.t) and t > self.motion.t:
            self._last_dt = t - self.motion.t
        learn = self._settled() and self.attitude is None  # jitter: unless it is measured
        self.motion.jitter_rate = self.config.jitter_rate if learn else 0.0
        T_pred, P_pp = self.motion.predict(t)
        if self.attitude is not None:  # the chaser's measured rotation over the step
            T_pred, P_pp = aided_prediction(self.motion, self.attitude, t) or (T_pred, P_pp)
        self.repeats.observe_rays(P)
        try:
            result = self._register(P, T_pred, P_pp, timings)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as e:
            log.warning("frame %d: registration raised %s: %s", self.n_frames, type(e).__name__, e)
            result = RegistrationResult(
                T_target_source=T_pred, status="failed", message=f"{type(e).__name__}: {e}"
            )
        if self.relocalizer is not None:
            try:
                result = self.relocalizer.check(P, T_pred, result, timings)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError) as e:
                # never lose a frame to the relocaliser: the step keeps its own judgement
                log.warning(
                    "frame %d: relocalisation raised %s: %s", self.n_frames, type(e).__name__, e
                )
        used_prior = result.status != "ok"
        keep_fit = result.status == "degenerate" and bool(result.info.get("keep_fit"))
        if keep_fit:  # an unstable step keeps its better-fitting answer; the map is not updated
            self.motion.update(result.T_target_source, result.info["information"])
            self.pose = self.motion.pose.copy()
        elif result.status == "ok":
            if result.info.get("recovered"):
                st, sr = self._first_sigma
                self.motion.widen(np.array([st] * 3 + [sr] * 3))
            self.motion.update(result.T_target_source, result.info["information"])
            if self.config.adaptive_noise:
                self.motion.adapt(result.info["chi2_motion"])
            self.pose = self.motion.pose.copy()
            ts = time.perf_counter()
            Pm = even_subset(P, self.config.max_map_points)
            self.map.insert(Pm @ self.pose[:3, :3].T + self.pose[:3, 3], self.n_frames)
            result.info["merged"] = True  # in the map, whatever label the integrity check adds
            self.repeats.remember(self.full_scan, self.pose, self.n_frames)
            self._update_symmetry()
            timings["map"] = time.perf_counter() - ts
        else:
            self.motion.skip()
            self.pose = self.motion.pose.copy()
        if self.motion.step_covariance is not None:
            self._judge_integrity(result, self.motion.step_covariance)
        step = invert(prev_pose) @ self.pose
        self.n_frames += 1
        self._online.append(self.pose.copy())
        self._times.append(t)
        return OdometryStep(
            self.pose.copy(),
            step,
            result,
            used_prior,
            result.status,
            n_raw,
            time.perf_counter() - t_start,
        )

    def _update_symmetry(self) -> None:
        """Test the map for an axis of rotational symmetry every ``symmetry_every`` accepted
        frames (``symmetry_max_ratio > 0``; :mod:`relnav.navigation.symmetry`)."""
        c = self.config
        if c.symmetry_max_ratio <= 0 or self.map is None:
            return
        self._sym_count += 1
        if self._sym_count % max(c.symmetry_every, 1):
            return
        found = symmetry_axis(
            self.map.means,
            self.map.normals,
            max_ratio=c.symmetry_max_ratio,
            min_arc_deg=c.symmetry_min_arc_deg,
            max_axial_fraction=c.symmetry_max_axial,
            irls=c.symmetry_irls,
        )
        if (found is None) != (self.symmetry is None):
            log.info(
                "frame %d: %s",
                self.n_frames,
                "no symmetry axis"
                if found is None
                else f"symmetry axis {np.round(found.axis, 3)} (ratio {found.ratio:.2e}, "
                f"{found.arc_deg:.0f}° of arc)",
            )
        self.symmetry = found

    def _judge_integrity(self, result: RegistrationResult, C: np.ndarray) -> None:
        """Record the step's 1σ (largest translation/rotation axis of its covariance ``C``,
        body frame); an ``ok`` step whose protection level exceeds an alert limit becomes
        ``degenerate``, one whose probability of an error beyond ``flag_limit_t`` /
        ``flag_limit_r_deg`` exceeds ``flag_probability`` becomes ``flagged`` (the status
        only: the pose, the filter and the map were updated as for an ``ok`` step)."""
        c = self.config
        s_t = math.sqrt(max(float(np.linalg.eigvalsh(C[:3, :3])[-1]), 0.0))
        s_r = math.degrees(math.sqrt(max(float(np.linalg.eigvalsh(C[3:, 3:])[-1]), 0.0)))
        result.info.update(step_sigma_t=s_t, step_sigma_r_deg=s_r, step_covariance=C.copy())
        if result.status != "ok":
            return
        pl_t, pl_r = c.protection_k * s_t, c.protection_k * s_r
        over = []
        if c.alert_limit_t > 0 and pl_t > c.alert_limit_t:
            over.append(f"translation {pl_t:.3g} m > {c.alert_limit_t:g} m")
        if c.alert_limit_r_deg > 0 and pl_r > c.alert_limit_r_deg:
            over.append(f"rotation {pl_r:.3g}° > {c.alert_limit_r_deg:g}°")
        if over:
            result.status = "degenerate"
            result.message = "protection level over the alert limit: " + ", ".join(over)
            return
        if c.flag_probability > 0:
            p = exceedance_probability(C, c.flag_limit_t, math.radians(c.flag_limit_r_deg))
            result.info["exceed_probability"] = p
            if p > c.flag_probability:
                result.status = "flagged"
                result.message = (
                    f"step error beyond {c.flag_limit_t:g} m or {c.flag_limit_r_deg:g}° with "
                    f"probability {p:.2f} (> {c.flag_probability:g}) under its covariance"
                )
                return
        why = disagreement(result, c) if self._settled() else ""
        if why:
            result.status, result.message = "flagged", why

    def _settled(self) -> bool:
        """Whether the motion model has seen ``flag_after_frames`` frames of the map: before,
        its corrections are it learning the velocity (no jitter learned, no disagreement flag)."""
        return self.n_frames - self._f0 >= self.config.flag_after_frames

    def skip_frame(self, reason: str) -> OdometryStep:
        """Flag a frame whose scan could not be read: status ``failed``, pose predicted by the
        motion model one frame period ahead (the map is not touched)."""
        t0 = time.perf_counter()
        prev = self.pose.copy()
        self._boot = None  # a gap among the first frames: no second pass
        if self.motion is not None and self._rescaled:
            self.motion.predict(self.motion.t + self._last_dt)
            self.motion.skip()
            self.pose = self.motion.pose.copy()
        log.warning("frame %d: skipped (%s)", self.n_frames, reason)
        self.n_frames += 1
        self._online.append(self.pose.copy())
        if self.motion is not None and self._rescaled:
            self._times.append(self.motion.t)
        else:
            self._times.append(self._times[-1] + self._last_dt if self._times else 0.0)
        res = RegistrationResult(T_target_source=self.pose.copy(), status="failed", message=reason)
        if self.motion is not None and self.motion.step_covariance is not None:
            res.info["step_covariance"] = self.motion.step_covariance.copy()
        out = OdometryStep(
            self.pose.copy(),
            invert(prev) @ self.pose,
            res,
            True,
            "failed",
            0,
            time.perf_counter() - t0,
        )
        t = self.motion.t if self.motion is not None else float(self.n_frames - 1)
        mv.window_step(self, None, t, out)
        return self._observe_loops(None, out)

    def _map_options(self) -> dict[str, Any]:
        """The navigator's patch and weighting parameters of a :class:`VoxelMap` (metres from
        the multiples of ``s₀``), shared by its map and the pose graph's keyframe maps."""
        c, s0 = self.config, self.spacing0
        return {
            "max_weight": c.max_voxel_weight,
            "noise_floor": c.noise_floor * s0,
            "inplane_sigma": c.inplane_sigma * s0,
            "k_neighbors": c.k_neighbors,
            "nonplanar_gain": c.nonplanar_gain,
            "surface": c.surface,
            "curvature_sigma": c.curvature_sigma,
            "quadric_reach": c.quadric_reach * s0,
        }

    def _new_map(self) -> VoxelMap:
        """An empty map with the navigator's parameters (voxel ``voxel_factor · s₀``)."""
        c = self.config
        return VoxelMap(
            c.voxel_factor * self.spacing0, max_voxels=c.max_voxels, **self._map_options()
        )

    def _observe_loops(self, P: np.ndarray | None, out: OdometryStep) -> OdometryStep:
        """Record the frame for the pose graph (``loop_closure``) and the revisit test
        (``revisit_alarm_chi2``): its scan and its step's covariance; while the revisit alarm
        stands an ``ok`` step is ``flagged``. The time it takes is added to the frame's."""
        c = self.config
        if not (c.loop_closure or c.revisit_alarm_chi2 > 0) or self.map is None:
            return out
        ts = time.perf_counter()
        if self.loop_closer is None:
            self.loop_closer = LoopCloser(
                self.map.voxel_size,
                self._map_options(),
                **loop_closer_options(c),
                fallback_sigma=self._first_sigma,
            )
            if c.revisit_alarm_chi2 > 0:
                self.revisits = RevisitCheck(self.loop_closer, c.revisit_alarm_chi2)
        cov = out.result.info.get("step_covariance") if out.result is not None else None
        Pm = None if P is None else even_subset(P, c.max_map_points)
        if c.loop_closure:
            P_pose = self.motion.P[:6, :6] if self.motion is not None else None
            self.loop_closer.observe(self.n_frames - 1, in_map(out), Pm, cov, P_pose)
        if self.revisits is not None:
            edge = self.revisits.observe(self.n_frames - 1, in_map(out), Pm, cov, self._pose_of)
            self.revisits.label(out, edge)
        out.time_s += time.perf_counter() - ts
        return out

    def _pose_of(self, f: int) -> np.ndarray:
        """Frame ``f``'s online pose (the start-up's refined one where it was refined)."""
        i = f - self._f0
        return self._prefix[i] if 0 <= i < len(self._prefix) else self._online[f]

    def _first(self, P: np.ndarray, t: float, n_raw: int, t_start: float) -> OdometryStep:
        c = self.config
        if len(P) < max(c.min_points, 3):
            # no map yet: keep the initial pose, wait for a usable scan
            res = RegistrationResult(
                status="failed", message=f"only {len(P)} finite points: no map started"
            )
            return OdometryStep(
                self.pose.copy(),
                np.eye(4),
                res,
                True,
                "failed",
                n_raw,
                time.perf_counter() - t_start,
            )
        self.spacing0 = _spacing(P)
        self.map = self._new_map()
        Pm = even_subset(P, c.max_map_points)
        self.map.insert(Pm @ self.pose[:3, :3].T + self.pose[:3, 3], self.n_frames)
        self.repeats.remember(self.full_scan, self.pose, self.n_frames)
        self.repeats.observe_rays(P)
        st0 = c.sigma_first_t * max(_rms_radius(P), self.spacing0)
        sr0 = math.radians(c.sigma_first_r_deg)
        sa_t = c.sigma_acc_t * self.spacing0
        sa_r = math.radians(c.sigma_acc_r_deg)
        # velocities per second need a frame period: the first one is not known yet, so the
        # filter is set up per frame period (1 s) and rescaled at the second frame.
        self.motion = ConstantVelocityFilter(
            self.pose,
            t,
            np.array([st0] * 3 + [sr0] * 3),
            np.array([sa_t] * 3 + [sa_r] * 3),
            jitter_max=math.radians(c.jitter_max_deg) ** 2,
            jitter_scan_margin=c.jitter_scan_margin,
        )
        self._rescaled = False
        self._f0 = self.n_frames
        self._first_sigma = (st0, sr0)
        return OdometryStep(
            self.pose.copy(),
            np.eye(4),
            None,
            False,
            "first",
            n_raw,
            time.perf_counter() - t_start,
        )

    def _register(
        self, P: np.ndarray, T_pred: np.ndarray, P_pp: np.ndarray, timings: dict
    ) -> RegistrationResult:
        c = self.config
        assert self.map is not None
        info: dict[str, Any] = {"method": self.name}
        if len(P) < c.min_points:
            return RegistrationResult(
                T_target_source=T_pred,
                status="failed",
                message=f"only {len(P)} finite points (< {c.min_points})",
                timings=timings,
                info=info,
            )
        ts = time.perf_counter()
        rng = float(np.median(np.linalg.norm(P, axis=1)))
        radius = max(_rms_radius(P), self.spacing0)
        sigma = np.sqrt(np.maximum(np.diag(P_pp), 0.0))
        Lam = left_information(T_pred, P_pp)
        v = self.map.voxel_size
        motion = 3.0 * (float(np.linalg.norm(sigma[:3])) + float(np.linalg.norm(sigma[3:])) * rng)
        gate = float(max(motion, 2.0 * v))
        timings["prepare"] = time.perf_counter() - ts
        ts = time.perf_counter()
        sym = self.symmetry.twist if self.symmetry is not None else None
        Lam_fit = stiffen_prior(Lam, sym, c.symmetry_gain) if sym is not None else Lam
        fit = self._solve(P, T_pred, Lam, gate, rng, radius, Lam_fit=Lam_fit)
        sj = math.sqrt(self.motion.jitter_var) if self.symmetry is None else 0.0  # flat axis
        if fit["usable"] and c.jitter_starts > 0 and sj >= math.radians(c.jitter_start_min_deg):
            for T0 in rotated_starts(T_pred, sj, c.jitter_starts):  # other minima in the jitter
                alt = self._solve(P, T_pred, Lam, gate, rng, radius, False, Lam_fit, start=T0)
                fit = alt if alt["usable"] and alt["rms"] < fit["rms"] else fit
        recovered = False
        if fit["chi2"] > c.chi2_gate and fit["usable"]:
            # the model and the scan disagree: is the model wrong (a manoeuvre, an
            # over-confident velocity) or the registration? Register again under the first
            # frame's weak prior; keep that answer only if the scan supports it as well.
            weak = self._weak_prior(T_pred)
            gate_w = float(max(gate, 3.0 * self._first_sigma[0]))
            alt = self._solve(P, T_pred, weak, gate_w, rng, radius, primary=False)
            if (
                alt["usable"]
                and alt["cond"] >= c.min_degeneracy
                and (alt["rms"] <= c.recover_rms_ratio * fit["rms"])
            ):
                fit, recovered = alt, True
                Lam = weak
        timings["register"] = time.perf_counter() - ts
        unstable = False
        if c.stability_check and fit["usable"]:
            ts = time.perf_counter()
            Lam_s = Lam if recovered else Lam_fit
            fit, unstable = self._stability(P, fit, T_pred, Lam_s, gate, rng, radius, info)
            timings["stability"] = time.perf_counter() - ts
        T, H = fit["T"], fit["H"] / fit["var_factor"]
        if sym is not None:  # the symmetric rotation is the motion model's
            H = marginalise_direction(H, sym)
            info["symmetry_axis"] = self.symmetry.axis.copy()  # type: ignore[union-attr]
            info["symmetry_ratio"] = self.symmetry.ratio  # type: ignore[union-attr]
            info["symmetry_twist"] = sym.copy()
            # the registration's correction along the symmetric rotation, in prior σ
            q = float(sym @ Lam @ sym)
            xi = log_se3(T @ invert(T_pred))
            info["symmetry_shift_sigma"] = float(sym @ Lam @ xi) / math.sqrt(q) if q > 0 else 0.0
        info["information"] = H
        info["prior_information"] = Lam
        info["prediction"] = T_pred
        info.update(
            iterations=fit["iterations"],
            overlap=fit["overlap"],
            chi2_motion=fit["chi2"],
            degeneracy=fit["cond"],
            gate=gate,
            sigma_t=float(sigma[0]),
            sigma_r_deg=float(math.degrees(sigma[3])),
            map_voxels=len(self.map),
            robust_rms_sigma=fit["rms"],
            variance_factor=fit["var_factor"],
            recovered=recovered,
            repeat_fraction=fit["repeat_fraction"],
            repeated_points=fit["repeated"],
            same_rays=self.repeats.ray_fraction,
            jitter_sigma_deg=math.degrees(math.sqrt(self.motion.jitter_var)),
        )
        status = "ok"
        message = ""
        if not (np.all(np.isfinite(T)) and np.all(np.isfinite(H))):
            status, message = "failed", "non-finite registration"
        elif fit["n_pairs"] < c.min_points:
            status, message = (
                "failed",
                f"{fit['n_pairs']} scan points near the model (< {c.min_points})",
            )
        elif fit["overlap"] < c.min_overlap:
            status, message = (
                "failed",
                f"overlap {fit['overlap']:.2f} with the model (< {c.min_overlap})",
            )
        elif fit["cond"] < c.min_degeneracy:
            status, message = (
                "degenerate",
                f"the scan constrains too few directions (eigenvalue ratio {fit['cond']:.1e})",
            )
        elif fit["chi2"] > c.chi2_gate and not recovered:
            status, message = (
                "failed",
                f"correction inconsistent with the motion model (χ² {fit['chi2']:.1f} > "
                f"{c.chi2_gate}) and not confirmed under a weak prior",
            )
        elif unstable:
            status, message = (
                "degenerate",
                f"unstable registration: a second start {info['stability_start_sigma']:.1f}σ "
                f"along the weakest direction ends {info['stability_distance']:.1f}σ away "
                f"(> {c.stability_gate})",
            )
            info["keep_fit"] = c.stability_pose == "fit"
        return self.fit_result(fit, T, H, Lam, status, message, timings, info)

    def fit_result(
        self,
        fit: dict[str, Any],
        T: np.ndarray,
        H: np.ndarray,
        prior: np.ndarray,
        status: str,
        message: str,
        timings: dict[str, float],
        info: dict[str, Any],
    ) -> RegistrationResult:
        """The step's :class:`RegistrationResult` from a registration ``fit`` (:meth:`_solve`):
        pose ``T``, covariance ``(H + prior)⁻¹`` of the scan's information ``H`` and the
        prior's (left twist, target frame; ``None`` when singular)."""
        try:
            cov = np.linalg.inv(H + prior)
        except np.linalg.LinAlgError:
            cov = None
        return RegistrationResult(
            T_target_source=T,
            covariance=cov,
            fitness=fit["fitness"],
            inlier_rmse=fit["rms"],
            n_correspondences=int(fit["n_pairs"]),
            n_inliers=int(fit["n_inliers"]),
            converged=fit["iterations"] < self.config.max_iter,
            status=status,  # type: ignore[arg-type]
            timings=timings,
            message=message,
            info=info,
        )

    def _stability(
        self,
        P: np.ndarray,
        fit: dict[str, Any],
        T_pred: np.ndarray,
        Lam: np.ndarray,
        gate: float,
        rng: float,
        radius: float,
        info: dict[str, Any],
    ) -> tuple[dict[str, Any], bool]:
        """Register ``P`` again from the answer ``fit`` displaced along its weakest direction.

        **[interpretation]** A step whose answer depends on where the solver starts is not
        determined by the scan. The weakest direction is the smallest eigenvector of the
        answer's information ``H / σ̂² + Λ`` (left twist, target frame) with rotations scaled
        by the lever arm ``radius`` (m); the start is displaced by ``stability_k`` σ along it,
        at most ``stability_cap`` map voxels (metres of translation, or of arc at ``radius``).
        The second answer goes through the same point-to-point refinement on repeated points
        as the first. The answers' distance is measured in the same information (σ). Returns the
        better-fitting answer (lower robust RMS, the first on ties) and whether the distance
        exceeds ``stability_gate``.
        """
        c = self.config
        assert self.map is not None
        H_post = fit["H"] / fit["var_factor"] + Lam
        H_post = 0.5 * (H_post + H_post.T)
        sc = np.array([1.0, 1.0, 1.0, radius, radius, radius])  # y = sc * ξ, metres
        Hs = H_post / sc[:, None] / sc[None, :]
        ev, U = np.linalg.eigh(Hs)
        if not np.all(np.isfinite(ev)) or ev[0] <= 0:
            return fit, False
        sig_w = 1.0 / math.sqrt(float(ev[0]))
        shift = min(c.stability_k * sig_w, c.stability_cap * self.map.voxel_size)
        xi0 = U[:, 0] * shift / sc
        T0 = exp_se3(xi0) @ fit["T"]
        T_c = exp_se3(xi0) @ T_pred if c.stability_mode == "prior" else T_pred
        alt = self.register_on_map(
            P, self.map.information, T0, T_c, Lam, gate, rng, kernel_scale=c.stability_kernel
        )
        # the same pipeline as the first answer: refined point to point on repeated points
        alt, _, _ = self.repeats.apply(P, alt, T_c, Lam, gate, rng, False)
        d = log_se3(alt.T @ invert(fit["T"]))
        dist = math.sqrt(max(float(d @ H_post @ d), 0.0))
        rms_alt = alt.rms
        info.update(
            stability_distance=dist,
            stability_start_sigma=shift / sig_w,
            stability_start=shift,
            stability_follow=dist / max(math.sqrt(float(xi0 @ H_post @ xi0)), 1e-300),
            stability_shift=d.copy(),
            stability_rms=rms_alt,
        )
        unstable = dist > c.stability_gate
        if unstable and rms_alt < fit["rms"]:
            fit = dict(fit, T=alt.T, rms=rms_alt)
        return fit, unstable

    def _weak_prior(self, T_pred: np.ndarray) -> np.ndarray:
        """Information (left, target frame) of the first frame's weak motion prior."""
        st, sr = self._first_sigma
        return left_information(T_pred, np.diag([st**2] * 3 + [sr**2] * 3))

    def register_on_map(
        self,
        P: np.ndarray,
        info: np.ndarray,
        T0: np.ndarray,
        T_pred: np.ndarray,
        Lam: np.ndarray,
        gate: float,
        rng: float,
        kernel_scale: float = 1.0,
        voxel_map: VoxelMap | None = None,
    ) -> ScanToMapFit:
        """Robust GICP of the scan ``P`` (sensor frame, m) onto the map's points with the
        per-point information ``info`` ``(M, 3, 3)``, from ``T0``, under the prior ``(T_pred,
        Lam)`` (left twist information, target frame); ``gate`` the pair gate (m), ``rng`` the
        scan's median range (m, for the rotation tolerance); ``voxel_map`` another map than
        the navigator's (its information is then ``info``). The solver's options come from the
        configuration (:func:`~relnav.navigation.gicp.solve_scan_to_map`)."""
        c = self.config
        target = self.map if voxel_map is None else voxel_map
        assert target is not None
        v = target.voxel_size
        return solve_scan_to_map(
            P,
            target,
            np.ascontiguousarray(T0),
            np.ascontiguousarray(T_pred),
            np.ascontiguousarray(Lam),
            gate,
            float(c.kernel) * kernel_scale,
            int(c.max_iter),
            c.tolerance * v,
            c.tolerance * v / max(rng, 1.0),
            c0=float(c.kernel_start) * kernel_scale,
            decay=float(c.kernel_decay),
            information=info,
        )

    def _solve(
        self,
        P: np.ndarray,
        T_pred: np.ndarray,
        Lam: np.ndarray,
        gate: float,
        rng: float,
        radius: float,
        primary: bool = True,
        Lam_fit: np.ndarray | None = None,
        voxel_map: VoxelMap | None = None,
        start: np.ndarray | None = None,
    ) -> dict[str, Any]:
        """One registration onto the map and its quality figures (``rng``: the scan's median
        range, ``radius``: its lever arm, both m; ``primary``: the frame's first registration,
        under the motion model's prior). With ``repeat_refine`` the answer is refined point to
        point when the scan repeats the previous scan's surface points
        (:mod:`relnav.navigation.repeated`). ``Lam_fit``: the prior's information inside the
        solver when it differs from ``Lam`` (the χ² against the motion model uses ``Lam``);
        ``voxel_map``: register onto that map instead of the navigator's."""
        c = self.config
        target = self.map if voxel_map is None else voxel_map
        assert target is not None
        Lf = Lam if Lam_fit is None else Lam_fit
        T0 = T_pred if start is None else start
        fit = self.register_on_map(
            P, target.information, T0, T_pred, Lf, gate, rng, voxel_map=target
        )
        repeat_frac, repeated = float("nan"), False
        if voxel_map is None:  # the repeated-points test compares with the navigator's map
            fit, repeat_frac, repeated = self.repeats.apply(P, fit, T_pred, Lf, gate, rng, primary)
        n = len(P)
        if c.information == "normal":
            H_cov = normal_information(
                P,
                fit.T,
                fit.idx,
                fit.d2,
                target.normals,
                target.information,
                target.inplane_sigma**2,
                float(c.kernel) ** 2,
            )
        else:
            H_cov = fit.H
        has = fit.d2 >= 0
        inl = has & (fit.d2 < 9.0)
        xi = log_se3(fit.T @ invert(T_pred))
        rms = fit.rms if fit.sw > 0 else float("nan")
        return {
            "T": fit.T,
            "H": H_cov,
            "n_pairs": fit.n_pairs,
            "iterations": fit.iterations,
            "overlap": float(has.sum()) / n,
            "fitness": float(inl.sum()) / n,
            "n_inliers": int(inl.sum()),
            "chi2": float(xi @ Lam @ xi),
            "cond": degeneracy(H_cov, radius),
            "rms": rms,
            "var_factor": variance_factor(rms),
            "usable": bool(fit.n_pairs >= c.min_points and has.sum() >= c.min_overlap * n),
            "repeat_fraction": repeat_frac,
            "repeated": repeated,
        }

    def finalize(self) -> np.ndarray:
        """Poses of every frame so far, smoothed when ``smooth_lag > 0``: ``(N, 4, 4)``.

        Frames before the map started keep their pose; each later frame's pose is the
        fixed-lag smoother's (it used up to ``smooth_lag`` later frames), then, with
        ``loop_closure``, corrected by the keyframes' pose graph
        (:meth:`relnav.navigation.pose_graph.LoopCloser.correct`).
        """
        online = list(self._online)
        pre = self._prefix
        if self.motion is None or not self._rescaled:
            poses = np.stack(online) if online else np.zeros((0, 4, 4))
        elif self.config.smooth_lag <= 0:
            poses = np.stack(online[: self._f0] + pre + online[self._f0 + len(pre) :])
        else:
            sm = self.motion.finish_smoothing()
            poses = np.stack(online[: self._f0] + pre + list(sm))
            if len(poses) != len(online):  # defensive: never a trajectory of another length
                log.warning("smoother returned %d poses for %d frames", len(poses), len(online))
                poses = np.stack(online)
        if self.config.loop_closure and self.loop_closer is not None and len(poses):
            corrected = self.loop_closer.correct(poses, first_frame=self._f0)
            if corrected.shape == poses.shape and np.all(np.isfinite(corrected)):
                poses = corrected
            else:
                log.warning("pose graph gave a non-finite trajectory: not applied")
        if self.config.orbit_mean_motion > 0 and self.map is not None and len(poses):
            poses = self._orbit_azimuth(poses)
        return poses

    def final_report(self) -> dict[str, Any]:
        """What the navigator decided once per run, for the run's record (``run.json``): the
        orbit test's verdict when ``orbit_mean_motion`` was given (:class:`OrbitCorrection`),
        the start-up's multi-view refinements and re-anchoring (accepted or not, why) and the
        revisits tested (:meth:`RevisitCheck.summary`)."""
        out: dict[str, Any] = {}
        if self.orbit is not None:
            out["orbit"] = self.orbit.as_dict()
        if self.refinements:
            out["start_up"] = [dict(r) for r in self.refinements]
        if self.revisits is not None and self.revisits.checks:
            out["revisits"] = self.revisits.summary()
        if self.attitude is not None:
            out["attitude_input"] = self.attitude.describe()
        return out

    def _orbit_azimuth(self, poses: np.ndarray) -> np.ndarray:
        """The azimuth about a body of revolution's axis from the target's free relative orbit
        (``orbit_mean_motion``; :mod:`relnav.navigation.orbit`), recorded in :attr:`orbit`."""
        c = self.config
        assert self.map is not None
        try:
            corrected, self.orbit = correct_azimuth(
                poses,
                np.asarray(self._times, dtype=np.float64),
                self.map.means,
                self.map.normals,
                c.orbit_mean_motion,
                max_symmetry_ratio=c.orbit_max_symmetry,
                max_misfit=c.orbit_max_misfit,
                min_excess=c.orbit_min_excess,
            )
        except (np.linalg.LinAlgError, ValueError) as e:
            log.warning("orbit azimuth: %s: %s (poses unchanged)", type(e).__name__, e)
            return poses
        log.info("orbit azimuth: %s", self.orbit.reason)
        return corrected
