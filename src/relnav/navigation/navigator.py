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
   (``prior.sigma_first_t``, ``prior.sigma_first_r_deg``).
2. **Register** the scan onto the map from the prediction, the prediction's information inside
   the least squares: directions the scan cannot fix (a symmetric target about its axis, one
   flat panel) stay with the model instead of drifting. When the scan's points repeat the
   previous scan's surface points (not merely its rays), the answer is refined point to point
   (``solver.repeat_refine``).
3. **Judge** the step from evidence only: too few scan points near the model, an overlap below
   ``solver.min_overlap``, a degenerate scan information (``solver.min_degeneracy``), or a
   correction inconsistent with the motion model (χ² beyond ``solver.chi2_gate``) unless a second
   registration under the weak prior fits the scan as well (``solver.recover_rms_ratio``; then the
   filter is widened) → ``failed``/``degenerate``: the pose keeps the prediction and the map is not
   updated. A scan with too few points within the model's gate (after a burn, say) is registered
   under the weak prior too (``solver.recover_unmatched``; with the measured attitude the prior
   keeps its rotation). An accepted step whose covariance gives it a probability above
   ``integrity.flag_probability`` of an error beyond ``integrity.flag_limit_t`` /
   ``integrity.flag_limit_r_deg`` is ``flagged``: a label only, the step is used as an ``ok`` one.
4. **Update** the filter with the registered pose and the scan's own information (scaled by
   the observed residual) and the map with the scan; the fixed-lag smoother
   (``prior.smooth_lag``) gives :meth:`Navigator.finalize` its trajectory.

Parameters are scale-free (multiples of the first scan's point spacing ``s₀``) and were chosen
on the navigation suite (``benchmarks/nav/nav_suite.py``), then frozen.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np

from relnav.geometry.lie import log_se3
from relnav.geometry.se3 import invert
from relnav.navigation.attitude_input import AttitudeInput, aided_prediction
from relnav.navigation.gicp import left_information
from relnav.navigation.integrity import (
    ambiguity,
    disagreement,
    exceedance_probability,
    step_sigmas,
)
from relnav.navigation.motion import ConstantVelocityFilter
from relnav.navigation.multistart import kept_answer, rotated_starts
from relnav.navigation.options import (
    NavigatorConfig,
    in_map,
    loop_closer_options,
    navigator_config,
)
from relnav.navigation.orbit import OrbitCorrection, correct_azimuth
from relnav.navigation.pose_graph import LoopCloser
from relnav.navigation.relocalize import Relocalizer
from relnav.navigation.repeated import RepeatedPoints
from relnav.navigation.revisit_check import RevisitCheck
from relnav.navigation.solver import MapSolver, median, point_spacing, rms_radius
from relnav.navigation.startup import StartupCorrection, StartupWindow
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


class Navigator:
    """Frame-to-model navigator with the :class:`~relnav.odometry.Odometry` interface.

    Parameters
    ----------
    initial_pose : (4, 4) float64, optional
        ``T_target_sensor`` of the first frame (identity by default).
    attitude : AttitudeInput, optional
        The chaser's measured attitude: the rotation of each step's prior (:mod:`.attitude_input`).
    **options
        Options of :class:`NavigatorConfig`: ``section={"key": value}``, ``**{"section.key":
        value}``, or a flat name of the last release (deprecated;
        :func:`~relnav.navigation.options.navigator_config`).
    """

    name = "relnav"
    #: what a run may ask besides ``register_frame`` (:mod:`relnav.odometry.tracker`)
    capabilities = frozenset({"skip_frame", "smoother", "final_report"})

    def __init__(
        self,
        *,
        initial_pose: np.ndarray | None = None,
        attitude: AttitudeInput | None = None,
        **options: Any,
    ) -> None:
        self.config = navigator_config(options, where="method 'relnav'")
        self.attitude = attitude
        self.pose = np.eye(4) if initial_pose is None else np.array(initial_pose, dtype=float)
        self.repeats = RepeatedPoints(self.config.solver)
        self.solver = MapSolver(self.config, self.repeats)  # holds the map
        self.motion: ConstantVelocityFilter | None = None
        self.n_frames = 0
        self._online: list[np.ndarray] = []
        self._times: list[float] = []  # each online pose's time, s
        self._last_dt = 1.0
        self._f0 = 0
        self._rescaled = False
        self._initial_pose = self.pose.copy()
        self._boot: list[tuple[np.ndarray, float, int, np.ndarray]] | None = (
            [] if self.config.startup.bootstrap_frames > 0 else None
        )
        self._boot_velocity: tuple[np.ndarray, np.ndarray] | None = None
        self.loop_closer: LoopCloser | None = None
        self.revisits: RevisitCheck | None = None
        self.relocalizer = self._new_relocalizer()
        self.startup = StartupWindow(self.config)
        self._prefix: list[np.ndarray] = []  # the start-up window's corrected earlier poses
        self.symmetry: SymmetryAxis | None = None
        self._sym_count = 0
        self.orbit: OrbitCorrection | None = None  # set by finalize() with orbit.mean_motion
        # before the map: the first sighting (centroid and line of sight, target frame; time;
        # attitude) and each later scan's time, position and whether its bearing was used
        self._sighting: tuple[np.ndarray, np.ndarray, float, np.ndarray] | None = None
        self._premap: list[tuple[float, np.ndarray, bool]] = []

    @property
    def map(self) -> VoxelMap | None:
        """The model of the target (target frame), None before the first usable frame."""
        return self.solver.map

    @property
    def spacing0(self) -> float:
        """The first usable scan's point spacing ``s₀`` (m), NaN before it."""
        return self.solver.spacing0

    def _new_relocalizer(self) -> Relocalizer | None:
        c = self.config
        return (
            Relocalizer(c.reloc, self.solver, self._initial_pose[:3, 3])
            if c.reloc.enabled
            else None
        )

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
        self.repeats.set_scan(P, self.n_frames)
        P, _ = reduce_to_budget(P, self.config.map.max_points, seed=[0, self.n_frames])
        K = self.config.startup.bootstrap_frames
        if self._boot is not None:
            self._boot.append((P, t, n_raw, self.repeats.full_scan))
        out = self._track(P, t, n_raw, t_start)
        self._startup_step(P, t, out)
        out = self._observe_loops(P, out)
        if self._boot is not None and len(self._boot) > K and self._rescaled:
            out = self._bootstrap(out)
        return out

    def _bootstrap(self, last: OdometryStep) -> OdometryStep:
        """Track the buffered first frames again, starting with the velocity they revealed.

        **[interpretation]** The first step has no motion prior: on sparse or near-symmetric scans
        it can settle short of the true motion, and the map and the velocity inherit the error.
        After ``startup.bootstrap_frames`` frames the filter knows the velocity; the navigator is
        reset to the first frame and the same scans are tracked again from that velocity (with its
        covariance, inflated 4×), once. The online steps already returned are not changed;
        :meth:`finalize` returns the second pass's poses.
        """
        assert self.motion is not None and self._boot is not None
        frames, self._boot = self._boot, None
        v = self.motion.velocity.copy()
        P_vv = 4.0 * self.motion.P[6:, 6:].copy()
        self.motion = None
        self.pose = self._initial_pose.copy()
        self.n_frames, self._online, self._times, self._rescaled = 0, [], [], False
        self._boot_velocity = (v, P_vv)
        self.loop_closer, self.revisits = None, None
        self.symmetry, self._sym_count = None, 0
        self._sighting, self._premap = None, []
        self.repeats = RepeatedPoints(self.config.solver)
        self.solver = MapSolver(self.config, self.repeats)  # no map: the first frame builds it
        self.relocalizer = self._new_relocalizer()
        out = last
        for P, t, n_raw, full in frames:
            self.repeats.set_scan(full, self.n_frames)  # the repeated-point refinement's scan
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
                self.motion.per_second(dt)
            if self._boot_velocity is not None:  # second pass of the first frames
                v, P_vv = self._boot_velocity
                self.motion.reset(velocity=v, velocity_covariance=P_vv)
            elif self.config.startup.premap_range:  # the range rate before the map, if any
                start = self._premap_velocity(self.motion.P[6:, 6:])
                if start is not None:
                    self.motion.reset(velocity=start[0], velocity_covariance=start[1])
            self._rescaled = True
            self.motion.start_smoothing(self.config.prior.smooth_lag)
        if np.isfinite(t - self.motion.t) and t > self.motion.t:
            self._last_dt = t - self.motion.t
        # the jitter is learned from the map's jitter_after_frames-th frame, unless it is measured
        learn = self._settled(self.config.prior.jitter_after_frames) and self.attitude is None
        self.motion.jitter_rate = self.config.prior.jitter_rate if learn else 0.0
        T_pred, P_pp = self.motion.predict(t)
        aided = None
        if self.attitude is not None:  # the chaser's measured rotation over the step
            aided = aided_prediction(self.motion, self.attitude, t)
            T_pred, P_pp = aided or (T_pred, P_pp)
        ranges = np.linalg.norm(P, axis=1)
        rng = median(ranges)  # the scan's median range, m
        self.repeats.observe_rays(P, self.spacing0, ranges, rng)
        try:
            result = self._register(P, T_pred, P_pp, rng, timings, aided=aided is not None)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as e:
            log.warning("frame %d: registration raised %s: %s", self.n_frames, type(e).__name__, e)
            result = RegistrationResult(
                T_target_source=T_pred, status="failed", message=f"{type(e).__name__}: {e}"
            )
        if self.relocalizer is not None:
            try:
                result = self.relocalizer.check(P, T_pred, result, timings, self.n_frames)
            except (np.linalg.LinAlgError, ValueError, FloatingPointError) as e:
                # never lose a frame to the relocaliser: the step keeps its own judgement
                log.warning(
                    "frame %d: relocalisation raised %s: %s", self.n_frames, type(e).__name__, e
                )
        if result.info.get("relocalised"):
            self._reset_for_relocalisation()
        used_prior = result.status != "ok"
        keep_fit = result.status == "degenerate" and bool(result.info.get("keep_fit"))
        if keep_fit:  # an unstable step keeps its better-fitting answer; the map is not updated
            self.motion.update(result.T_target_source, result.info["information"])
            self.pose = self.motion.pose.copy()
        elif result.status == "ok":
            if result.info.get("recovered"):
                st, sr = self.solver.first_sigma
                if result.info.get("rotation_kept"):  # the measured rotation was not in doubt
                    sr = 0.0
                self.motion.widen(np.array([st] * 3 + [sr] * 3))
            self.motion.update(result.T_target_source, result.info["information"])
            if self.config.prior.adaptive_noise:
                self.motion.adapt(result.info["chi2_motion"])
            self.pose = self.motion.pose.copy()
            # two answers apart but within the flag limits: the pose is kept, the map is not
            # fed a scan that may sit at the other answer
            if not result.info.get("stability_apart"):
                ts = time.perf_counter()
                Pm = even_subset(P, self.config.map.max_map_points)
                self.map.insert(Pm @ self.pose[:3, :3].T + self.pose[:3, 3], self.n_frames)
                result.info["merged"] = True  # in the map, whatever label integrity adds
                self.repeats.remember(self.repeats.full_scan, self.pose)
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

    def _startup_step(self, P: np.ndarray | None, t: float, out: OdometryStep) -> None:
        """The start-up window's turn (:class:`~relnav.navigation.startup.StartupWindow`):
        record the frame just tracked and apply its correction when one is due; the time it
        takes is added to the frame's."""
        if not self.startup.open or self.map is None:
            return
        assert self.motion is not None
        ts = time.perf_counter()
        age = self.n_frames - self._f0
        correction = self.startup.observe(
            self.n_frames - 1, t, self.pose, P, out, age, self.solver, self.motion
        )
        if correction is not None:
            self._apply_startup(correction)
        out.time_s += time.perf_counter() - ts

    def _apply_startup(self, correction: StartupCorrection) -> None:
        """Make the start-up window's corrected poses the navigator's: the map rebuilt from
        them, the filter going on from the last one (the smoother restarted there), the last
        scan remembered at its new pose and the earlier poses kept for :meth:`finalize`."""
        assert self.motion is not None
        new_map = self.solver.new_map()
        for Pm, T, frame in correction.map_frames:
            new_map.insert(Pm @ T[:3, :3].T + T[:3, 3], frame)
        self.solver.map = new_map
        self.motion.reset(
            correction.pose, correction.velocity, smooth_lag=self.config.prior.smooth_lag
        )
        self.pose = self.motion.pose.copy()
        self.repeats.remember(self.repeats.full_scan, self.pose)
        self._prefix = correction.earlier_poses
        if self.relocalizer is not None:
            self.relocalizer.map_changed()

    def _reset_for_relocalisation(self) -> None:
        """Reset the motion filter before it takes a relocalised pose: the pose's covariance
        is widened by the first frame's (the filter then takes the verified pose as it is) and
        the velocity's as ``reloc.velocity`` says: ``keep`` (kept, 1σ widened by 10 × the white
        acceleration), ``zero`` (restarted: zero, the first frame's 1σ) or ``widen`` (kept,
        the first frame's 1σ, as a recovered step)."""
        c, m = self.config, self.motion
        assert m is not None
        st, sr = self.solver.first_sigma
        first = np.array([st] * 3 + [sr] * 3)
        sv = 10.0 * m.sigma_acc if c.reloc.velocity == "keep" else first / max(self._last_dt, 1e-9)
        zero = np.zeros(6) if c.reloc.velocity == "zero" else None
        m.reset(velocity=zero, widen=first, widen_velocity=sv)

    def _update_symmetry(self) -> None:
        """Test the map for an axis of rotational symmetry every ``symmetry.every`` accepted
        frames (``symmetry.max_ratio > 0``; :mod:`relnav.navigation.symmetry`)."""
        c = self.config
        if c.symmetry.max_ratio <= 0 or self.map is None:
            return
        self._sym_count += 1
        if self._sym_count % max(c.symmetry.every, 1):
            return
        found = symmetry_axis(
            self.map.means,
            self.map.normals,
            max_ratio=c.symmetry.max_ratio,
            min_arc_deg=c.symmetry.min_arc_deg,
            max_axial_fraction=c.symmetry.max_axial,
            irls=c.symmetry.irls,
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
        ``degenerate``, one whose probability of an error beyond ``integrity.flag_limit_t`` /
        ``integrity.flag_limit_r_deg`` exceeds ``integrity.flag_probability`` becomes ``flagged``
        (the status only: the pose, the filter and the map were updated as for an ``ok`` step)."""
        c = self.config
        s_t, s_r = step_sigmas(C)
        s_r = math.degrees(s_r)
        result.info.update(step_sigma_t=s_t, step_sigma_r_deg=s_r, step_covariance=C.copy())
        if result.status != "ok":
            return
        pl_t, pl_r = c.integrity.protection_k * s_t, c.integrity.protection_k * s_r
        over = []
        if c.integrity.alert_limit_t > 0 and pl_t > c.integrity.alert_limit_t:
            over.append(f"translation {pl_t:.3g} m > {c.integrity.alert_limit_t:g} m")
        if c.integrity.alert_limit_r_deg > 0 and pl_r > c.integrity.alert_limit_r_deg:
            over.append(f"rotation {pl_r:.3g}° > {c.integrity.alert_limit_r_deg:g}°")
        if over:
            result.status = "degenerate"
            result.message = "protection level over the alert limit: " + ", ".join(over)
            return
        if c.integrity.flag_probability > 0:
            lim_t, lim_r = c.integrity.flag_limit_t, c.integrity.flag_limit_r_deg
            p = exceedance_probability(C, lim_t, math.radians(lim_r))
            result.info["exceed_probability"] = p
            if p > c.integrity.flag_probability:
                result.status = "flagged"
                result.message = (
                    f"step error beyond {lim_t:g} m or {lim_r:g}° with "
                    f"probability {p:.2f} (> {c.integrity.flag_probability:g}) under its covariance"
                )
                return
        why = disagreement(result, c) if self._settled() else ""
        if why:
            result.status, result.message = "flagged", why

    def _settled(self, frames: int | None = None) -> bool:
        """Whether the motion model has seen ``frames`` frames of the map (default
        ``integrity.flag_after_frames``): before, its corrections are it learning the velocity
        (no disagreement flag; the jitter is learned from ``prior.jitter_after_frames``)."""
        if frames is None:
            frames = self.config.integrity.flag_after_frames
        return self.n_frames - self._f0 >= frames

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
        self._startup_step(None, t, out)
        return self._observe_loops(None, out)

    def _observe_loops(self, P: np.ndarray | None, out: OdometryStep) -> OdometryStep:
        """Record the frame for the pose graph (``loops.enabled``) and the revisit test
        (``loops.revisit_alarm_chi2``): its scan and its step's covariance; while the revisit alarm
        stands an ``ok`` step is ``flagged``. The time it takes is added to the frame's."""
        c = self.config
        if not (c.loops.enabled or c.loops.revisit_alarm_chi2 > 0) or self.map is None:
            return out
        ts = time.perf_counter()
        if self.loop_closer is None:
            self.loop_closer = LoopCloser(
                self.map.voxel_size,
                self.solver.map_options(),
                **loop_closer_options(c),
                fallback_sigma=self.solver.first_sigma,
            )
            if c.loops.revisit_alarm_chi2 > 0:
                self.revisits = RevisitCheck(self.loop_closer, c.loops.revisit_alarm_chi2)
        cov = out.result.info.get("step_covariance") if out.result is not None else None
        Pm = None if P is None else even_subset(P, c.map.max_map_points)
        if c.loops.enabled:
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

    def _follow_range(self, P: np.ndarray, t: float) -> float | None:
        """Before the map: place the sensor where the scan's centroid says the target is.

        **[interpretation]** (``startup.premap_range``) A few points cannot be registered, but
        their centroid's range is measured to centimetres while the target is far. The first
        scan with a point fixes the sighting: its centroid in the target frame (from the given
        pose) and the line of sight to it. Each later scan before the map then sets the sensor
        on that line at its own centroid's range, the attitude unchanged: what a centroid
        cannot tell without the chaser's attitude (a turn about the target) stays as it was.
        With the attitude input covering the scans, the sensor is turned by the measured
        rotation since the sighting and placed so that the whole centroid, bearing and range,
        sits on the sighted point. When the map starts, the motion model's velocity starts at
        the rate fitted to these positions (:meth:`_premap_velocity`). Returns the range (m)
        when the sensor was placed, None for the sighting itself or a degenerate centroid.
        """
        c_s = P.mean(0)
        r = float(np.linalg.norm(c_s))
        if not np.isfinite(r) or r <= 0:
            return None
        if self._sighting is None:
            R = self.pose[:3, :3].copy()
            self._sighting = (R @ c_s + self.pose[:3, 3], R @ (c_s / r), t, R)
            return None
        c_target, u, t0, R0 = self._sighting
        dR = self.attitude.step(t0, t) if self.attitude is not None else None
        if dR is not None:  # the chaser's attitude: the whole bearing
            self.pose[:3, :3] = R0 @ dR
            self.pose[:3, 3] = c_target - self.pose[:3, :3] @ c_s
        else:
            self.pose[:3, 3] = c_target - u * r
        self._premap.append((t, self.pose[:3, 3].copy(), dR is not None))
        return r

    def _premap_velocity(self, P_vv: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The body velocity (per second) of the positions before the map — a line fitted to
        them over time — and its covariance: the fit's spread plus 20 % of the speed in the
        directions the positions measured (the line of sight, or every direction with the
        attitude input), the model's own ``P_vv`` (6×6, per second²) in the others; None with
        fewer than three positions."""
        if self._sighting is None or len(self._premap) < 3:
            return None
        t = np.array([p[0] for p in self._premap])
        X = np.array([p[1] for p in self._premap])
        dt = t - t.mean()
        if not np.sum(dt**2) > 0:
            return None
        A = np.c_[dt, np.ones_like(dt)]
        slope = np.linalg.lstsq(A, X, rcond=None)[0]
        E = X - A @ slope
        S = (E.T @ E) / max(len(t) - 2, 1) / float(np.sum(dt**2))  # the rate's covariance
        R = self.pose[:3, :3]
        v = np.zeros(6)
        v[:3] = R.T @ slope[0]
        C = R.T @ S @ R + (0.2 * float(np.linalg.norm(slope[0]))) ** 2 * np.eye(3)
        P = np.array(P_vv, dtype=float)
        if all(p[2] for p in self._premap):  # every direction measured
            P[:3, :3] = C
            P[:3, 3:] = 0.0
        else:  # the line of sight only
            u = R.T @ self._sighting[1]
            uu, across = np.outer(u, u), np.eye(3) - np.outer(u, u)
            P[:3, :3] = across @ P[:3, :3] @ across + float(u @ C @ u) * uu
            P[:3, 3:] = across @ P[:3, 3:]
        P[3:, :3] = P[:3, 3:].T
        return v, P

    def _first(self, P: np.ndarray, t: float, n_raw: int, t_start: float) -> OdometryStep:
        c = self.config
        need = max(c.solver.min_points, c.startup.map_min_points, 3)
        if len(P) < need:
            # no map yet: keep the initial pose (or follow the range), wait for a usable scan
            res = RegistrationResult(
                status="failed", message=f"only {len(P)} finite points (< {need}): no map started"
            )
            if c.startup.premap_range and len(P):
                r = self._follow_range(P, t)
                if r is not None:  # the step stays failed: not registered, only placed
                    res.info["premap_range_m"] = r
            return OdometryStep(
                self.pose.copy(),
                np.eye(4),
                res,
                True,
                "failed",
                n_raw,
                time.perf_counter() - t_start,
            )
        if c.startup.premap_range and self._sighting is not None:
            self._follow_range(P, t)  # the map starts where this scan says
        self.solver.spacing0 = point_spacing(P)
        self.solver.map = self.solver.new_map()
        Pm = even_subset(P, c.map.max_map_points)
        self.solver.map.insert(Pm @ self.pose[:3, :3].T + self.pose[:3, 3], self.n_frames)
        self.repeats.remember(self.repeats.full_scan, self.pose)
        ranges = np.linalg.norm(P, axis=1)
        self.repeats.observe_rays(P, self.spacing0, ranges, median(ranges))
        st0 = c.prior.sigma_first_t * max(rms_radius(P), self.spacing0)
        sr0 = math.radians(c.prior.sigma_first_r_deg)
        sa_t = c.prior.sigma_acc_t * self.spacing0
        sa_r = math.radians(c.prior.sigma_acc_r_deg)
        # velocities per second need a frame period: the first one is not known yet, so the
        # filter is set up per frame period (1 s) and rescaled at the second frame.
        self.motion = ConstantVelocityFilter(
            self.pose,
            t,
            np.array([st0] * 3 + [sr0] * 3),
            np.array([sa_t] * 3 + [sa_r] * 3),
            jitter_max=math.radians(c.prior.jitter_max_deg) ** 2,
            jitter_scan_margin=c.prior.jitter_scan_margin,
        )
        self._rescaled = False
        self._f0 = self.n_frames
        self.solver.first_sigma = (st0, sr0)
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
        self,
        P: np.ndarray,
        T_pred: np.ndarray,
        P_pp: np.ndarray,
        rng: float,
        timings: dict,
        aided: bool = False,
    ) -> RegistrationResult:
        """Register the scan ``P`` onto the map from the prediction ``(T_pred, P_pp)`` and judge
        it (``rng``: the scan's median range, m; ``aided``: the prediction's rotation is the
        chaser's measured attitude)."""
        c = self.config
        assert self.map is not None
        info: dict[str, Any] = {"method": self.name}
        if len(P) < c.solver.min_points:
            return RegistrationResult(
                T_target_source=T_pred,
                status="failed",
                message=f"only {len(P)} finite points (< {c.solver.min_points})",
                timings=timings,
                info=info,
            )
        ts = time.perf_counter()
        radius = max(rms_radius(P), self.spacing0)
        sigma = np.sqrt(np.maximum(np.diag(P_pp), 0.0))
        Lam = left_information(T_pred, P_pp)
        v = self.map.voxel_size
        motion = 3.0 * (float(np.linalg.norm(sigma[:3])) + float(np.linalg.norm(sigma[3:])) * rng)
        gate = float(max(motion, 2.0 * v))
        timings["prepare"] = time.perf_counter() - ts
        ts = time.perf_counter()
        sym = self.symmetry.twist if self.symmetry is not None else None
        Lam_fit = stiffen_prior(Lam, sym, c.symmetry.gain) if sym is not None else Lam
        solver = self.solver
        sj = math.sqrt(self.motion.jitter_var) if self.symmetry is None else 0.0  # flat axis
        jittering = sj >= math.radians(c.prior.jitter_start_min_deg)
        if c.prior.jitter_starts > 0 and jittering:
            starts = rotated_starts(T_pred, sj, c.prior.jitter_starts)  # other minima
            answers = solver.solve_starts(P, T_pred, Lam, gate, rng, radius, Lam_fit, starts)
            fit = kept_answer(answers, c.prior.jitter_choice)
            if len(answers) > 1 and c.integrity.ambiguity_rms > 0:
                info.update(ambiguity(fit, answers, c))
        else:
            fit = solver.solve(P, T_pred, Lam, gate, rng, radius, Lam_fit=Lam_fit)
        recovered = False
        disagree = fit["chi2"] > c.solver.chi2_gate and fit["usable"]
        retry = c.solver.recover_unmatched
        unmatched = not fit["usable"] and (
            retry == "always" or (retry == "with_attitude" and aided)
        )
        if disagree or unmatched:
            # the model and the scan disagree (or the scan is not within the model's gate at
            # all): is the model wrong (a manoeuvre, an over-confident velocity) or the
            # registration? Register again under the first frame's weak prior; keep that answer
            # only if the scan supports it as well (when nothing matched, if it is usable).
            # When nothing matched and the rotation is measured, only the translation is in
            # doubt: the prior keeps the measured rotation's covariance.
            keep = unmatched and aided
            weak = solver.weak_prior(T_pred, P_pp[3:, 3:] if keep else None)
            gate_w = float(max(gate, 3.0 * solver.first_sigma[0]))
            alt = solver.solve(P, T_pred, weak, gate_w, rng, radius, primary=False)
            if (
                alt["usable"]
                and alt["cond"] >= c.solver.min_degeneracy
                and (unmatched or alt["rms"] <= c.solver.recover_rms_ratio * fit["rms"])
            ):
                fit, recovered = alt, True
                Lam = weak
                info["rotation_kept"] = keep
        timings["register"] = time.perf_counter() - ts
        unstable = False
        if (
            c.integrity.stability_check
            and fit["usable"]
            and (c.integrity.stability_when == "always" or jittering)
        ):
            ts = time.perf_counter()
            Lam_s = Lam if recovered else Lam_fit
            fit, unstable = solver.stability(P, fit, T_pred, Lam_s, gate, rng, radius, info)
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
        elif fit["n_pairs"] < c.solver.min_points:
            status, message = (
                "failed",
                f"{fit['n_pairs']} scan points near the model (< {c.solver.min_points})",
            )
        elif fit["overlap"] < c.solver.min_overlap:
            status, message = (
                "failed",
                f"overlap {fit['overlap']:.2f} with the model (< {c.solver.min_overlap})",
            )
        elif fit["cond"] < c.solver.min_degeneracy:
            status, message = (
                "degenerate",
                f"the scan constrains too few directions (eigenvalue ratio {fit['cond']:.1e})",
            )
        elif fit["chi2"] > c.solver.chi2_gate and not recovered:
            status, message = (
                "failed",
                f"correction inconsistent with the motion model (χ² {fit['chi2']:.1f} > "
                f"{c.solver.chi2_gate}) and not confirmed under a weak prior",
            )
        elif unstable:
            status, message = (
                "degenerate",
                f"unstable registration: a second start {info['stability_start_sigma']:.1f}σ "
                f"along the weakest direction ends {info['stability_distance']:.1f}σ away "
                f"(> {c.integrity.stability_gate})",
            )
            info["keep_fit"] = c.integrity.stability_pose == "fit"
        return solver.fit_result(fit, T, H, Lam, status, message, timings, info)

    def finalize(self) -> np.ndarray:
        """Poses of every frame so far, smoothed when ``prior.smooth_lag > 0``: ``(N, 4, 4)``.

        Frames before the map started keep their pose; each later frame's pose is the
        fixed-lag smoother's (it used up to ``prior.smooth_lag`` later frames), then, with
        ``loops.enabled``, corrected by the keyframes' pose graph
        (:meth:`relnav.navigation.pose_graph.LoopCloser.correct`).
        """
        online = list(self._online)
        pre = self._prefix
        if self.motion is None or not self._rescaled:
            poses = np.stack(online) if online else np.zeros((0, 4, 4))
        elif self.config.prior.smooth_lag <= 0:
            poses = np.stack(online[: self._f0] + pre + online[self._f0 + len(pre) :])
        else:
            sm = self.motion.finish_smoothing()
            poses = np.stack(online[: self._f0] + pre + list(sm))
            if len(poses) != len(online):  # defensive: never a trajectory of another length
                log.warning("smoother returned %d poses for %d frames", len(poses), len(online))
                poses = np.stack(online)
        if self.config.loops.enabled and self.loop_closer is not None and len(poses):
            corrected = self.loop_closer.correct(poses, first_frame=self._f0)
            if corrected.shape == poses.shape and np.all(np.isfinite(corrected)):
                poses = corrected
            else:
                log.warning("pose graph gave a non-finite trajectory: not applied")
        if self.config.orbit.mean_motion > 0 and self.map is not None and len(poses):
            poses = self._orbit_azimuth(poses)
        return poses

    def final_report(self) -> dict[str, Any]:
        """What the navigator decided once per run, for the run's record (``run.json``): the
        orbit test's verdict when ``orbit.mean_motion`` was given (:class:`OrbitCorrection`),
        the start-up's multi-view refinements and re-anchoring (accepted or not, why) and the
        revisits tested (:meth:`RevisitCheck.summary`)."""
        out: dict[str, Any] = {}
        if self.orbit is not None:
            out["orbit"] = self.orbit.as_dict()
        if self.startup.refinements:
            out["start_up"] = [dict(r) for r in self.startup.refinements]
        if self.revisits is not None and self.revisits.checks:
            out["revisits"] = self.revisits.summary()
        if self.attitude is not None:
            out["attitude_input"] = self.attitude.describe()
        return out

    def _orbit_azimuth(self, poses: np.ndarray) -> np.ndarray:
        """The azimuth about a body of revolution's axis from the target's free relative orbit
        (``orbit.mean_motion``; :mod:`relnav.navigation.orbit`), recorded in :attr:`orbit`."""
        c = self.config
        assert self.map is not None
        try:
            corrected, self.orbit = correct_azimuth(
                poses,
                np.asarray(self._times, dtype=np.float64),
                self.map.means,
                self.map.normals,
                c.orbit.mean_motion,
                max_symmetry_ratio=c.orbit.max_symmetry,
                max_misfit=c.orbit.max_misfit,
                min_excess=c.orbit.min_excess,
            )
        except (np.linalg.LinAlgError, ValueError) as e:
            log.warning("orbit azimuth: %s: %s (poses unchanged)", type(e).__name__, e)
            return poses
        log.info("orbit azimuth: %s", self.orbit.reason)
        return corrected
