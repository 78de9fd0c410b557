"""The full relative state from LIDAR alone: navigator poses → paper 2's twistor UKF.

The navigator (:class:`~relnav.navigation.navigator.Navigator`) gives per frame the pose
``T_target_sensor`` and the scan's own information ``H`` about it (no motion prior inside, so the
measurements are independent across frames). :func:`relative_state` turns them into paper 2's
observations (the target's origin and attitude in the sensor frame, ``T_sensor_target``, with the
covariance ``H⁻¹`` mapped to ``[δp (sensor frame), δθ (target axes)]``) and runs
:class:`relnav.filtering.tracker.Tracker` (twistor UKF, Clohessy–Wiltshire translation with mean
motion ``n``; ``n = 0`` is a free double integrator). The result holds the target's position and
velocity in the sensor frame, its attitude and its body rates, with covariances, per frame.

Frames: the body rates ``ω`` are those of the target relative to the sensor frame, in target
axes; for a chaser holding an inertial attitude they are the target's inertial rates.
Directions the scan did not constrain get a large variance (the UKF predicts through them);
frames the navigator rejected (``failed``, ``degenerate``) are predicted through (status
``predict``); a ``flagged`` step (``flag_probability`` of
:class:`~relnav.navigation.options.NavigatorConfig`)
is observed like an ``ok`` one, its covariance already saying how little it is determined.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace
from types import SimpleNamespace
from typing import Any

import numpy as np

from relnav.errors import ConfigError
from relnav.filtering.multiple_model import mix_tracks
from relnav.filtering.track_result import TrackResult, TrackTruth
from relnav.filtering.tracker import Observation, Tracker
from relnav.geometry.rotations import hat, matrix_to_quat
from relnav.geometry.se3 import adjoint, invert
from relnav.navigation.options import in_map
from relnav.navigation.orbit import orbit_turns
from relnav.navigation.state.inertia import InertiaFit
from relnav.navigation.state.rigid_body import rigid_body_pass

__all__ = [
    "TORQUE_FREE_SHARES",
    "StateRecord",
    "check_state_options",
    "drift_covariance",
    "map_drift_shares",
    "split_rotation_drift",
    "map_offset_rotation",
    "measurement_covariance",
    "STATE_PRESETS",
    "startup_bias",
    "state_options",
    "nees_band",
    "pose_noise",
    "relative_state",
    "scale_drift",
    "with_map_rotation_offset",
]

log = logging.getLogger(__name__)

_UNSEEN_VAR = 1e6  # variance (m², rad²) given to directions the scan did not constrain
# relative_state(angular_acceleration="adaptive"): shares of the torque-free bound in the bank
TORQUE_FREE_SHARES = (1.0, 0.1, 0.01)
# relative_state(rigid_body=True): first-pass frames left out of the inertia fit (converging)
RIGID_BODY_SKIP_FRAMES = 10

STATE_PRESETS: dict[str, dict[str, Any]] = {
    "hold-point": {
        "drift": "offset",
        "acceleration": 1e-6,
        "angular_acceleration": "adaptive",
        "torque_free_shares": (1.0, 0.1, 0.01, 0.001),
        "bank_floor": 1e-5,
        "gate_probability": 0.999,
        "gate_patience": 5,
        "rigid_body": True,
        "wander_frames": 100.0,
    },
}
"""Named sets of :func:`relative_state` options (:func:`state_options`, ``-S preset=NAME``).

``"hold-point"`` **[measured, chosen on envisat-tumble-64's 20 noise seeds]**: the chaser holds
its station beside a spinning or tumbling target (the relative acceleration its guidance does
not know is ~1e-6 m/s², not the 1e-4 of the Clohessy–Wiltshire terms of a free flight), the
navigator's error as a map offset plus a wander (``drift="offset"``), a bank of four
angular-acceleration levels down to 1/1000 of the torque-free bound whose members take over
slowly (probability floor 1e-5), a χ² gate at 0.999, and a tumbling target's inertia
identified from a first pass (``rigid_body``, designed on aura-tumble-64; a spin keeps the
first pass). ``wander_frames`` 100 (the translation wander's correlation time, frames; the
option's default is 50) **[measured, session 17, on envisat-tumble-64 and aura-tumble-64 with
the ``relnav-tumbling`` navigator]**: 12-dim NEES 11.5 and 12.5, inside the band, against 19.4
and 19.9 with 50 (the position over-confident). ``gate_patience`` 5 **[interpretation]**: the
gate is for isolated outliers (envisat-tumble-64 seed 14's three-frame swing); five refusals in
a row mean the filter has diverged, and it re-acquires (found on eros-tumble-64 seed 9, where
the gate refused 190 of 200 observations and the rate stayed 1.35°/s off; 0.021°/s with it).
Its rate and NEES on the tumbling sequences, and
on those made after it was frozen: ``docs/results/nav/state_hold_point.md``. Knowledge of the
mission phase, not a default: on a helical approach the offset model follows the navigator's
attitude drift.
"""


def _observation_jacobian(T_target_sensor: np.ndarray) -> np.ndarray:
    """Left twist of ``T_target_sensor`` → ``[δp (sensor frame), δθ (target axes)]``."""
    J = np.zeros((6, 6))
    J[:3, :3] = invert(T_target_sensor)[:3, :3]
    J[3:, 3:] = np.eye(3)
    return J


def drift_covariance(C_step_body: np.ndarray, T_target_sensor: np.ndarray) -> np.ndarray:
    """A step's covariance (body frame of ``T_target_sensor``) in the observation's coordinates.

    **[interpretation]** The navigator's pose error relative to the truth is its map's error,
    which moves by at most one step's error per frame: paper 2's observer-bias state
    (``TwistorUKF(observer_bias=True)``) takes it as the growth of a slowly varying bias, so that
    the UKF does not read the navigator's drift as target motion.
    """
    Ad = adjoint(T_target_sensor)
    J = _observation_jacobian(T_target_sensor)
    C = J @ Ad @ np.asarray(C_step_body) @ Ad.T @ J.T
    return 0.5 * (C + C.T)


def scale_drift(Q: np.ndarray, translation: float, rotation: float) -> np.ndarray:
    """``D Q D`` with ``D = diag(√translation · I₃, √rotation · I₃)``: a drift covariance
    ``[δp (m), δθ (rad)]`` ``(6, 6)`` with its translation and rotation variances scaled (their
    correlation, the lever arm, by ``√(translation · rotation)``); positive semi-definite when
    ``Q`` is."""
    D = np.sqrt(np.r_[[float(translation)] * 3, [float(rotation)] * 3])
    return D[:, None] * np.asarray(Q, dtype=float) * D[None, :]


def measurement_covariance(H_left: np.ndarray, T_target_sensor: np.ndarray) -> np.ndarray:
    """Covariance of ``[δp (m, sensor frame), δθ (rad, target axes)]`` of ``T_sensor_target``.

    ``H_left`` is the information of a left perturbation of ``T_target_sensor`` (target frame,
    twist ``[ρ, φ]``). Since ``exp(δ) T_ts`` inverts to ``T_st exp(−δ)``, the position of the
    target in the sensor frame moves by ``R_st ρ`` and its attitude by ``φ`` in target axes.
    Unconstrained directions (eigenvalues of ``H`` below 1e-9 of the largest) get a variance of
    1e6.
    """
    H = 0.5 * (H_left + H_left.T)
    w, V = np.linalg.eigh(H)
    top = max(float(w[-1]), 1e-300)
    inv_w = np.where(w > 1e-9 * top, 1.0 / np.maximum(w, 1e-300), _UNSEEN_VAR)
    C = (V * inv_w) @ V.T
    J = _observation_jacobian(T_target_sensor)
    C = J @ C @ J.T
    return 0.5 * (C + C.T)


@dataclass(frozen=True)
class StateRecord:
    """What :func:`relative_state` needs of one navigator frame (about 700 bytes).

    Attributes
    ----------
    status : str
        The frame's status (``"ok"``, ``"first"``, ``"failed"`` …).
    pose : (4, 4) float64
        Online ``T_target_sensor``.
    information : (6, 6) float64 or None
        The scan's own information about the pose (left twist, target frame).
    step_covariance : (6, 6) float64 or None
        Covariance of the step that led to this pose (body frame, right twist ``[ρ, φ]``).
    merged : bool or None
        Whether the scan went into the map (:func:`~relnav.navigation.options.in_map`; None:
        as its status says).
    gauge_turn : (4, 4) float64 or None
        The turn ``G`` of the navigator's target frame made at this frame (re-anchoring,
        :mod:`relnav.navigation.startup.anchor`): the earlier frames' poses are ``G T`` in the frame
        of this one's.
    """

    status: str
    pose: np.ndarray
    information: np.ndarray | None = None
    step_covariance: np.ndarray | None = None
    merged: bool | None = None
    gauge_turn: np.ndarray | None = None

    def turned(self, G: np.ndarray) -> StateRecord:
        """The frame with its pose turned in the target frame, ``T' = G T`` (``G`` ``(4, 4)``):
        a left perturbation ``δ`` of ``T`` is ``Ad_G δ`` of ``T'``, so the information becomes
        ``Ad_G⁻ᵀ H Ad_G⁻¹``; the step covariance (body frame) is unchanged."""
        H = None
        if self.information is not None:
            A = np.linalg.inv(adjoint(np.asarray(G, dtype=float)))
            H = A.T @ np.asarray(self.information) @ A
        pose = np.asarray(G, dtype=float) @ self.pose
        return replace(self, pose=pose, information=H)

    def pinned(self, u: np.ndarray, sigma: float) -> StateRecord:
        """The frame with one direction of its pose known to ``sigma``: ``u`` ``(6,)`` a left
        twist of the pose (target frame, ``[ρ (m), φ (rad)]``), ``sigma`` its 1σ along ``u``
        (units of a unit multiple of ``u``). The information gains ``u uᵀ / σ²`` and the step
        covariance is conditioned on the same knowledge in the body frame
        (``u_b = Ad(T⁻¹) u``: ``(C⁻¹ + u_b u_bᵀ / σ²)⁻¹``, in covariance form)."""
        u = np.asarray(u, dtype=float)
        w = 1.0 / float(sigma) ** 2
        H = None if self.information is None else np.asarray(self.information) + w * np.outer(u, u)
        C = self.step_covariance
        if C is not None:
            C = np.asarray(C, dtype=float)
            ub = adjoint(invert(self.pose)) @ u
            Cu = C @ ub
            C = C - np.outer(Cu, Cu) / (float(ub @ Cu) + 1.0 / w)
            C = 0.5 * (C + C.T)
        return replace(self, information=H, step_covariance=C)

    @classmethod
    def from_step(cls, step: Any) -> StateRecord:
        """From an :class:`relnav.odometry.OdometryStep` of the navigator."""
        info = {} if step.result is None else step.result.info
        return cls(
            str(step.status),
            np.array(step.pose, dtype=float),
            info.get("information"),
            info.get("step_covariance"),
            in_map(step),
            info.get("gauge_turn"),
        )


def relative_state(
    run: Any,
    *,
    steps: Sequence[Any] | None = None,
    gt_poses: np.ndarray | None = None,
    n_mean_motion: float = 0.0,
    filter: str = "ukf",
    process_noise: str = "physics",
    acceleration: float = 1e-4,
    angular_acceleration: float | str | None = None,
    drift: str = "step",
    map_memory: float = 20.0,
    offset_frames: int = 10,
    wander_frames: float = 50.0,
    wander_rotation_frames: float = 10.0,
    drift_scale: float = 1.0,
    drift_rotation_scale: float = 1.0,
    measurement_scale: float = 1.0,
    initial_bias: int = 0,
    orbit_azimuth: bool = True,
    torque_free_shares: Sequence[float] = TORQUE_FREE_SHARES,
    bank_floor: float = 1e-3,
    rigid_body: bool = False,
    inertia_refine: bool = True,
    **tracker_options: Any,
) -> TrackResult:
    """Estimate the target's relative state from a navigator run.

    Parameters
    ----------
    run : relnav.odometry.OdometryRun
        A run of method ``relnav`` (its steps carry the scans' information matrices).
    steps : sequence of StateRecord or OdometryStep, optional
        The frames (default ``run.steps``); a streamed run (``keep_steps=False``) passes the
        compact records it kept.
    gt_poses : (N, 4, 4) float64, optional
        Ground-truth ``T_target_sensor`` per frame (attached as the truth).
    n_mean_motion : float
        Clohessy–Wiltshire mean motion of the target's orbit, rad/s (0: free motion).
    filter : {"ukf", "ekf"}
        Paper 2's twistor UKF (default) or the quaternion EKF.
    process_noise : {"physics", "poses"}
        ``"physics"`` (default) **[interpretation]**: no random walks; the target's position
        and attitude move only through their rates, which change by the accelerations below
        held over each step (:class:`relnav.filtering.noise.ProcessNoise`), and the poses' white
        noise added to each scan's covariance is measured in the observations' coordinates
        (``pose_noise(frame="target")``). ``"poses"`` (the former default): per frame period
        the state may move by one step of the poses' white noise (:func:`pose_noise`, sensor
        axes), its rates by one such step per period. **[measured]** ``"physics"`` lowers the
        position error on 12 of the 16 other suite sequences and the attitude error on 13,
        and envisat-tumble-64's rate error (20 noise seeds, max 0.188 → 0.172 deg/s), but
        orion-inclined-64 gets worse (``docs/results/nav/state_process_noise.md``). The
        torque-free bound holds for a chaser holding an inertial attitude, not for the rate
        relative to a slewing sensor.
    acceleration : float
        With ``process_noise="physics"``: 1σ of the unmodelled relative acceleration, m/s²
        (default 1e-4, the order of the Clohessy–Wiltshire terms ``3n²r`` a free model leaves
        out at a 50 m hold point in low orbit, 1.8e-4).
    angular_acceleration : float, "adaptive" or None
        With ``process_noise="physics"``: 1σ of the target's angular acceleration, rad/s², when
        known. ``None`` (default): the bound of a torque-free rigid body, ``|ω̂|²/√3`` from the
        filter's own rate (``ProcessNoise.torque_free``; valid for a chaser holding an inertial
        attitude). ``"adaptive"`` **[interpretation]**: a bank of three filters taking 1, 1/10
        and 1/100 of that bound, mixed by the likelihood of their innovations
        (:func:`relnav.filtering.multiple_model.mix_tracks`, probability floor 1e-3), so that the
        data tell a target spinning about a principal axis (``ω̇ = 0``) from a tumbling one
        (one filter, as ``None``, with ``process_noise="poses"`` or a caller's ``q``). Not
        the default: over 20 noise seeds it brings envisat-tumble-64's worst rate error after
        convergence from 0.172 to 0.060 deg/s, but the held-out aura-tumble-64's 95th
        percentile goes 0.074 → 0.181 deg/s (max 0.123 → 0.201) and orion-inclined-64,
        sim-helical and asteroid-helical-128 get worse (a member whose rate lags the truth
        keeps the higher likelihood while the observer bias absorbs its attitude error;
        ``docs/navigator.md``, "Full relative state on a tumbling target").
    torque_free_shares : sequence of float
        With ``angular_acceleration="adaptive"``: the bank's shares of the torque-free bound
        (each > 0; default 1, 1/10 and 1/100).
    bank_floor : float
        With ``angular_acceleration="adaptive"``: the bank's probability floor
        (:func:`relnav.filtering.multiple_model.model_probabilities`; default 1e-3, in
        ``[0, 1/M)``): how fast a dormant member can take over.
    rigid_body : bool
        **[interpretation]** (UKF only) Identify a tumbling target's inertia from the
        estimated rates (:func:`relnav.navigation.state.inertia.fit_inertia`, after the first
        ``RIGID_BODY_SKIP_FRAMES`` frames) and run the filter again with the rate turned by
        Euler's torque-free equations (``TwistorUKF(inertia=J)``) and, as its angular
        acceleration, the fit's RMS miss (one filter, no bank); on a spin, whose rate does not
        sweep in the body, the first pass stands. ``meta`` records
        ``inertia_identified`` and ``principal_inertia`` (ascending, ``det = 1``). The second
        pass uses the whole run's rates: a smoothed identification, not a causal filter.
        For a sensor holding an inertial attitude; default False.
    inertia_refine : bool
        With ``rigid_body``: also refine the inertia on the first pass's attitudes and keep
        the second pass whose innovations are the likelier
        (:func:`relnav.navigation.state.rigid_body.rigid_body_pass`; ``meta["inertia_source"]``;
        default True).
    drift : {"step", "map"}
        How much of each step's covariance (:func:`drift_covariance`) the observer bias takes.
        ``"step"`` (default): all of it, every frame. ``"map"`` **[interpretation]**: the
        step's rotation (with the swing of the target's position it causes) by the share a
        running-mean map absorbs (:func:`map_drift_shares`: ``1/min(n, map_memory)`` for the
        frame merged into a map of ``n`` frames), the rest of it as the observation's white
        noise (:func:`split_rotation_drift`); the step's own translation stays a random walk of
        the bias. Measured against the truth (envisat-tumble-64), the map's rotation error is
        set in the first ~10 frames (the weak first prior) and then stays within ±0.3°, while
        its translation error in target axes jumps by 0.3 m for 50–90 frames at some views and
        comes back (not white, not the map). Not the default: the NEES stays far below its
        band and the held-out rate error gets worse (``docs/results/nav/state_drift.md``).
        ``"offset"`` **[interpretation]** (UKF only): the navigator's error as what it was
        measured to be on the tumbling sequences, a map offset set during the start-up plus a
        stationary wander around it (:func:`map_offset_rotation`,
        ``docs/results/nav/state_offset.md``). The first ``offset_frames`` merged steps' drift
        builds the offset: its translation moves the map origin on the target (the UKF's
        body-frame offset ``c``, ``centre_offset=True`` without the axis pseudo-measurement,
        grown frame by frame, then constant), its rotation, which a constant-rate spin cannot
        reveal, stays outside the filter and is added to the covariance of the attitude and
        the rates of every frame's output (rank one, along the start-up's least-constrained
        rotation). Later steps' drift drives a Gauss–Markov observer bias with correlation
        times ``wander_frames`` (translation) and ``wander_rotation_frames`` (rotation).
        Part of the ``"hold-point"`` preset (:data:`STATE_PRESETS`).
        Not the default: it takes the observations' attitude as the map's, so where the
        navigator's attitude drifts during a helical approach the state follows it
        (iridium-helical-64 13.9 → 25.1°, voyager-helical-64 14.8 → 25.1°), where the
        random-walk bias corrected ~10° of it.
    map_memory : float
        With ``drift="map"``: the frames after which a map voxel's running mean forgets
        geometrically (the navigator's ``max_voxel_weight``, default 20).
    offset_frames : int
        With ``drift="offset"``: the start-up steps whose drift is the map's offset (default
        10, unscaled by ``drift_scale``).
    wander_frames, wander_rotation_frames : float
        With ``drift="offset"``: correlation times, in frame periods, of the translation and
        rotation wander around the map's offset (defaults 50 and 10, chosen on
        envisat-tumble-64's 20 noise seeds; ``inf``: a random walk).
    drift_scale, drift_rotation_scale : float
        Scales (≥ 0, default 1) of the drift the observer bias takes each frame
        (:func:`scale_drift`): its translation variance by ``drift_scale``, its rotation
        variance by ``drift_scale · drift_rotation_scale``.
    measurement_scale : float
        Scale (> 0, default 1) of each observation's covariance (the scan's ``H⁻¹`` with the
        poses' white noise). **[measured]** No setting of the three scales, fitted to the
        innovations' likelihood without the truth
        (:func:`relnav.navigation.state.noise_fit.fit_noise_scales`) or to the
        truth's NEES, brings every block of the NEES near 3 (less drift raises the position
        and velocity blocks, but the attitude block faster), and the fitted scales make
        iridium-helical-64's attitude worse (13.9 → 22.7°;
        ``docs/results/nav/state_noise_scales.md``).
    initial_bias : int
        Start-up frames whose drift is the map's initial offset (default 0: none, the bias
        starts at zero covariance at the first frame and grows frame by frame). With ``N > 0``
        the observer bias takes at the first update the sum of the first ``N`` merged frames'
        step covariances (translation and rotation blocks, their correlation dropped, not
        scaled by ``drift_scale``; :func:`startup_bias`), those frames add no drift of their
        own and the later ones the scaled drift. Not the default: the rate block stays below
        1 whatever the start-up, and envisat-tumble-64's and iridium-helical-64's attitude get
        worse (1.06 → 2.36°, 13.9 → 17.1°; ``docs/results/nav/state_initial_bias.md``).
    orbit_azimuth : bool
        **[interpretation]** When the navigator's run took the azimuth about a body of
        revolution's axis from the target's orbit (``run.options["finalize"]["orbit"]``,
        :func:`relnav.navigation.orbit.correct_azimuth`), turn each frame's online pose and
        information by that frame's correction (:meth:`StateRecord.turned`) before the filter
        (default True), so that the state agrees with the run's trajectory, and condition its
        information and step covariance on the orbit's azimuth, known to the orbit's
        radius/height misfit over the sensor's median distance (:meth:`StateRecord.pinned`).
        Measured (one run each, after 30 % of the frames, ``docs/results/nav/orbit.md``):
        attitude error sim-orion-resample 49.0 → 1.3°, orion-inclined-64 27.4 → 5.3°,
        sim-bennu-resample 3.4 → 0.65°, the held-out orion-tilt60-64 24.2 → 7.6°.
    **tracker_options
        Passed to :class:`relnav.filtering.tracker.Tracker` (``q`` replaces the process noise above,
        ``p0``, ``omega0``, ``gate_probability`` …). With the
        UKF, ``observer_bias`` defaults to True: each step's covariance
        (:func:`drift_covariance`) feeds the bias state, in the target's axes
        (``bias_frame="body"``).

    Returns
    -------
    relnav.filtering.tracker.TrackResult
    """
    if drift not in ("step", "map", "offset"):
        raise ConfigError(f"drift must be 'step', 'map' or 'offset', got {drift!r}")
    offset_mode = drift == "offset"
    if offset_mode:
        offset_frames = _check_offset_options(
            filter, offset_frames, wander_frames, wander_rotation_frames
        )
    if not (np.isfinite(map_memory) and map_memory >= 1.0):
        raise ConfigError(f"map_memory must be >= 1 frame, got {map_memory!r}")
    scales = {
        "drift_scale": drift_scale,
        "drift_rotation_scale": drift_rotation_scale,
        "measurement_scale": measurement_scale,
    }
    for label, value in scales.items():
        if not (isinstance(value, int | float) and np.isfinite(value) and value >= 0.0):
            raise ConfigError(f"{label} must be a finite number >= 0, got {value!r}")
    if not measurement_scale > 0.0:
        raise ConfigError(f"measurement_scale must be > 0, got {measurement_scale!r}")
    initial_bias = _frame_count(initial_bias, "initial_bias")
    if offset_mode and initial_bias:
        raise ConfigError("initial_bias and drift='offset' are alternatives (see offset_frames)")
    if process_noise not in ("physics", "poses"):
        raise ConfigError(f"process_noise must be 'physics' or 'poses', got {process_noise!r}")
    alpha = angular_acceleration
    if isinstance(alpha, str) and alpha != "adaptive":
        raise ConfigError(f"angular_acceleration: a number, None or 'adaptive', not {alpha!r}")
    if rigid_body and (filter != "ukf" or process_noise != "physics" or "q" in tracker_options):
        raise ConfigError("rigid_body needs the UKF with the physics process noise (no q)")
    # the bank varies the physics noise's angular acceleration: not with a caller's q
    adaptive = alpha == "adaptive" and process_noise == "physics" and "q" not in tracker_options
    try:
        bank_shares = tuple(float(x) for x in np.atleast_1d(torque_free_shares))
    except (TypeError, ValueError):
        bank_shares = ()
    if not bank_shares or not all(np.isfinite(x) and x > 0.0 for x in bank_shares):
        raise ConfigError(f"torque_free_shares must be numbers > 0, got {torque_free_shares!r}")
    n_bank = len(bank_shares)
    if not (isinstance(bank_floor, int | float) and 0.0 <= bank_floor < 1.0 / n_bank):
        raise ConfigError(f"bank_floor must be in [0, 1/{n_bank}), got {bank_floor!r}")
    if alpha is not None and not isinstance(alpha, str):
        alpha = float(alpha)  # type: ignore[arg-type]
        if not (np.isfinite(alpha) and alpha >= 0.0):
            raise ConfigError(f"angular_acceleration must be >= 0 rad/s², got {alpha}")
    frames = [
        s if isinstance(s, StateRecord) else StateRecord.from_step(s)
        for s in (run.steps if steps is None else steps)
    ]
    frames = _gauge_turned(frames)
    if orbit_azimuth:
        frames = _orbit_turned(run, frames)
    noise = pose_noise(frames, frame="target" if process_noise == "physics" else "sensor")
    shares = map_drift_shares(frames, map_memory) if drift == "map" else np.ones(len(frames))
    start_up, P_start = startup_bias(frames, initial_bias, shares)
    first_update = start_up[0] if start_up else -1
    offset_steps = set(_start_up_steps(frames, offset_frames)) if offset_mode else set()
    observations: list[Observation | None] = []
    for index, (step, share) in enumerate(zip(frames, shares, strict=True)):
        H = step.information
        if not in_map(step):
            observations.append(None)
            continue
        T_st = invert(step.pose)
        R = None if H is None else measurement_covariance(np.asarray(H), step.pose)
        if R is not None:
            R = R + np.diag([noise[0] ** 2] * 3 + [noise[1] ** 2] * 3)
        Q = offset = None
        if step.step_covariance is not None:
            Q = drift_covariance(step.step_covariance, step.pose)
            if share < 1.0 and R is not None:
                Q, white = split_rotation_drift(Q, share)
                R = R + white  # the scan's rotation error relative to its map: white
            if index in offset_steps:
                # drift="offset": the start-up moves the map origin on the target (its rotation
                # is added to the output, map_offset_rotation), no wander of its own
                offset, Q = Q[:3, :3], None
            else:
                Q = scale_drift(Q, drift_scale, drift_scale * drift_rotation_scale)
        if index in start_up:
            # the start-up frames' drift is the map's initial offset, given at the first update
            Q = P_start if index == first_update else None
        if R is not None:
            R = float(measurement_scale) * R
        T_q = matrix_to_quat(T_st[:3, :3])
        observations.append(Observation(T_st[:3, 3], T_q, R=R, drift=Q, offset_drift=offset))
    truth = None
    if gt_poses is not None:
        T_st_gt = np.stack([invert(T) for T in np.asarray(gt_poses)[: len(frames)]])
        truth = TrackTruth.from_poses(np.asarray(run.timestamps, dtype=float), T_st_gt)
    if "q" not in tracker_options and process_noise == "poses":
        # [interpretation] process noise per frame period from the poses' own white noise: the
        # state may move by one noise step per frame, its rates by one noise step per period
        dt = _frame_period(run.timestamps)
        nt, nr = max(noise[0], 1e-4), max(noise[1], 1e-5)
        tracker_options["q"] = {
            "position": nt,
            "velocity": nt / dt,
            "attitude": nr,
            "omega": nr / dt,
        }
    elif "q" not in tracker_options:
        # the physics a user can state: the target's reference point and attitude move only
        # through their rates, which change by the accelerations held over each step
        tracker_options["q"] = {
            "position": 0.0,
            "velocity": 0.0,
            "attitude": 0.0,
            "omega": 0.0,
            "acceleration": float(acceleration),
            "angular_acceleration": 0.0 if adaptive else float(alpha or 0.0),  # type: ignore[arg-type]
            "torque_free": adaptive or alpha is None,
        }
    if filter == "ukf":
        # the navigator's slowly varying map drift is a bias of its observations, not target
        # motion: paper 2's observer-bias state absorbs it (see drift_covariance)
        tracker_options.setdefault("observer_bias", True)
        # the map's error is a body-fixed offset of its origin: seen from the sensor it turns
        # with the target (measured: envisat-tumble-64, 20 seeds, position NEES 10.8 → 3.1)
        tracker_options.setdefault("bias_frame", "body")
    if offset_mode:
        # the map origin's offset on the target, grown by the start-up frames from zero (the
        # first frame anchors the map), and the wander around the offset
        period = _frame_period(run.timestamps)
        tracker_options.setdefault("centre_offset", True)
        tracker_options.setdefault("axis_sigma", np.inf)
        tracker_options.setdefault("p0", {"offset": 1e-4})
        tracker_options.setdefault(
            "bias_correlation_time",
            (float(wander_frames) * period, float(wander_rotation_frames) * period),
        )
    meta: dict[str, Any] = {"method": run.method}

    def track(options: dict[str, Any], bank_of_levels: bool) -> TrackResult:
        if not bank_of_levels:
            tracker = Tracker(filter, n_mean_motion=n_mean_motion, **options)
            return tracker.run(run.timestamps, observations, truth=truth, meta=meta)
        bank = []
        for share in bank_shares:
            opts = {**options, "q": {**options["q"], "torque_free_share": share}}
            tracker = Tracker(filter, n_mean_motion=n_mean_motion, **opts)
            bank.append(tracker.run(run.timestamps, observations, truth=truth, meta=meta))
        labels = [f"torque-free bound × {share:g}" for share in bank_shares]
        return mix_tracks(bank, labels, floor=bank_floor)

    result = track(tracker_options, adaptive)
    if rigid_body:
        # the rates and attitudes of a first pass tell a tumbling target's inertia; a second
        # pass turns the rate by Euler's equations (a spin reveals none: the first pass stands)
        def second_pass(fit: InertiaFit) -> TrackResult:
            # the torque-free model's own miss is the angular acceleration it leaves out
            q2 = {**tracker_options["q"], "angular_acceleration": fit.residual}
            q2["torque_free"] = False
            return track({**tracker_options, "q": q2, "inertia": fit.inertia}, False)

        skip = min(RIGID_BODY_SKIP_FRAMES, len(result) // 2)
        result, found = rigid_body_pass(result, second_pass, skip=skip, refine=inertia_refine)
        meta.update(found)
        result.meta.update(meta)
    if offset_mode:
        result = with_map_rotation_offset(result, map_offset_rotation(frames, offset_frames))
    return result


def startup_bias(
    steps: Sequence[Any], n_frames: int, shares: np.ndarray | None = None
) -> tuple[list[int], np.ndarray]:
    """The start-up frames and the observer bias's covariance at the first update.

    **[interpretation]** The navigator's map takes its rotation offset from the first frames
    merged into it (the weak first prior; on envisat-tumble-64 it is set in ~10 frames and
    then stays within ±0.3°, ``docs/results/nav/state_drift.md``); afterwards that offset is
    not observable (a constant rotation offset of a constant-rate motion is another constant-
    rate motion). The drift of the start-up frames (the ``n_frames`` merged frames after the
    first one that carry a step covariance) is therefore taken as one offset of the map,
    present from the first update on, instead of a random walk growing over those frames: the
    sum of their step covariances (:func:`drift_covariance`, the map's share with
    ``drift="map"``, not scaled by ``drift_scale``; the translation blocks summed in the
    target's axes), with the correlation between its translation and rotation blocks (one
    step's lever arm) dropped, since the offset of a map merged from several views is not one
    registration's. Built from the scans' own
    covariances only (no ground truth); a causal filter would have it after ``n_frames``
    frames.

    Parameters
    ----------
    steps : sequence
        Frames with ``status``, ``pose`` (``T_target_sensor``) and ``step_covariance``
        (:class:`StateRecord`).
    n_frames : int
        Number of start-up frames (0: none).
    shares : (N,) array_like, optional
        The map's share of each step's rotation (:func:`map_drift_shares`); default 1.

    Returns
    -------
    start_up : list of int
        Indices of the start-up frames (the first is the first update, which takes the
        covariance).
    covariance : (6, 6) float64
        ``[δp (m, sensor frame of the first update), δθ (rad, target axes)]`` of the offset,
        block diagonal.
    """
    merged = [k for k, s in enumerate(steps) if in_map(s)]
    start_up = _start_up_steps(steps, n_frames)
    C = np.zeros((6, 6))
    if not start_up:
        return start_up, C
    for k in start_up:
        Q = drift_covariance(steps[k].step_covariance, steps[k].pose)
        if shares is not None and shares[k] < 1.0:
            Q, _ = split_rotation_drift(Q, float(shares[k]))
        R_ts = np.asarray(steps[k].pose)[:3, :3]  # the translation block to target axes
        C[:3, :3] += R_ts @ Q[:3, :3] @ R_ts.T
        C[3:, 3:] += Q[3:, 3:]
    if merged[1] != start_up[0]:
        start_up = [merged[1], *start_up]  # the first update takes it (its own step: none)
    R_st = np.asarray(steps[start_up[0]].pose)[:3, :3].T  # … and to the first update's sensor
    C[:3, :3] = R_st @ C[:3, :3] @ R_st.T
    return start_up, 0.5 * (C + C.T)


def _gauge_turned(frames: list[StateRecord]) -> list[StateRecord]:
    """``frames`` with each one before a navigator's turn of its target frame (``gauge_turn``)
    turned by it, so that all are in the last frame's target frame: what a causal filter
    restarted on its buffer at the turn would see."""
    out = list(frames)
    for k, f in enumerate(frames):
        if f.gauge_turn is not None:
            G = np.asarray(f.gauge_turn, dtype=float)
            out[:k] = [g.turned(G) for g in out[:k]]
    return out


def _orbit_turned(run: Any, frames: list[StateRecord]) -> list[StateRecord]:
    """``frames`` turned by the run's orbit correction, if one was applied (else as given)."""
    options = getattr(run, "options", None) or {}
    report = options.get("finalize", {}).get("orbit") if isinstance(options, dict) else None
    G = None if not isinstance(report, dict) else orbit_turns(report)
    if G is None:
        return frames
    if len(G) != len(frames):
        log.warning("orbit correction of %d frames for %d: not applied", len(G), len(frames))
        return frames
    # the orbit gives the azimuth about the axis through its centre to its misfit over the
    # sensor's distance (rad): each frame's scan information and step are conditioned on it
    a = np.asarray(report["axis"], dtype=float)
    u = np.concatenate([np.cross(np.asarray(report["center"], dtype=float), a), a])
    sigma = max(float(report["misfit_m"]) / max(float(report["scale_m"]), 1e-9), 1e-4)
    return [f.turned(g).pinned(u, sigma) for f, g in zip(frames, G, strict=True)]


def _start_up_steps(steps: Sequence[Any], n_frames: int) -> list[int]:
    """Indices of the first ``n_frames`` merged frames after the first that carry a step
    covariance (the navigator's start-up, whose drift sets its map's offset)."""
    merged = [k for k, s in enumerate(steps) if in_map(s)]
    later = [k for k in merged[1:] if steps[k].step_covariance is not None]
    return later[: int(n_frames)] if n_frames > 0 else []


def _frame_count(value: Any, label: str) -> int:
    """A number of frames >= 0 (a command line's whole float accepted), else ConfigError."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise ConfigError(f"{label} must be a number of frames >= 0, got {value!r}")
    return value


def _frame_period(timestamps: Any) -> float:
    """Median frame period, s (1 when it cannot be told)."""
    t = np.asarray(timestamps, dtype=float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    return dt if np.isfinite(dt) and dt > 0 else 1.0


def _check_offset_options(filter: str, n_frames: Any, *frames: Any) -> int:
    """Check the options of ``drift="offset"``; returns ``offset_frames`` as an int."""
    if filter != "ukf":
        raise ConfigError("drift='offset' needs the UKF (its body offset and observer bias)")
    n_frames = _frame_count(n_frames, "offset_frames")
    for value in frames:
        if not (isinstance(value, int | float) and float(value) > 0.0):
            raise ConfigError(f"wander correlation times must be > 0 frames, got {value!r}")
    return n_frames


def map_offset_rotation(steps: Sequence[Any], n_frames: int) -> np.ndarray:
    """Covariance ``(3, 3)`` (rad², target axes) of the rotation offset of the navigator's map.

    **[interpretation, measured]** The sum of the rotation blocks of the first ``n_frames``
    merged steps' covariances (:func:`drift_covariance`), kept along its largest axis only.
    On envisat-tumble-64's 20 noise seeds the map's rotation offset relative to the target
    (mean over the frames after the first 30) lies along that axis: its squared size over the
    variance is 0.62 there, 0.05 and 0.09 along the other two (aura-tumble-64: 0.30 against
    0.08 and 0.09). Each later scan registers against the first scan's surfaces as well,
    which holds the well-constrained directions; the least-constrained one keeps what the
    start-up gave it.

    Parameters
    ----------
    steps : sequence
        Frames with ``status``, ``pose`` and ``step_covariance`` (:class:`StateRecord`).
    n_frames : int
        Start-up frames (0: no offset).
    """
    C = np.zeros((3, 3))
    for k in _start_up_steps(steps, n_frames):
        C += drift_covariance(steps[k].step_covariance, steps[k].pose)[3:, 3:]
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    return max(float(w[-1]), 0.0) * np.outer(V[:, -1], V[:, -1])


def with_map_rotation_offset(result: TrackResult, C_offset: np.ndarray) -> TrackResult:
    """``result`` with a constant rotation offset of the observations' frame added to its
    covariances.

    The estimate is the attitude of the map's frame, ``R_s_b ε`` for the target's ``R_s_b``
    and an unknown constant ``ε`` (covariance ``C_offset`` ``(3, 3)``, rad², body axes); its
    body rates are the target's turned by ``ε``. So the attitude error takes ``δθ = ε`` and the
    rate error ``δω = [ω̂]× ε`` (``ω̂`` the estimated rate): ``P + J C Jᵀ`` with
    ``J = [0; 0; I; [ω̂]×]`` in ``[δd, δv, δθ, δω]``. Steps without an estimate are unchanged.
    """
    P = np.array(result.covariance, dtype=float, copy=True)
    for k in range(len(P)):
        if np.all(np.isfinite(P[k])) and np.all(np.isfinite(result.omega[k])):
            J = np.zeros((12, 3))
            J[6:9] = np.eye(3)
            J[9:12] = hat(np.asarray(result.omega[k], dtype=float))
            P[k] = P[k] + J @ C_offset @ J.T
    return replace(result, covariance=P)


def state_options(options: dict[str, Any]) -> dict[str, Any]:
    """:func:`relative_state` options with a ``preset`` name (:data:`STATE_PRESETS`) replaced
    by its options; the caller's other options win over the preset's.

    Raises
    ------
    ConfigError
        An unknown preset.
    """
    out = dict(options)
    name = out.pop("preset", None)
    if name is None:
        return out
    if name not in STATE_PRESETS:
        raise ConfigError(f"unknown state preset {name!r} (known: {sorted(STATE_PRESETS)})")
    return {**STATE_PRESETS[name], **out}


def check_state_options(options: dict[str, Any]) -> None:
    """Raise :class:`~relnav.errors.ConfigError` for options :func:`relative_state` would
    refuse (unknown names, bad values) by running it on two still frames: what a command line
    checks before a long run rather than after it."""
    if {"run", "steps", "gt_poses"} & set(options):
        raise ConfigError("run, steps and gt_poses are not options of the relative state")
    options = state_options(options)
    frames = [StateRecord("first", np.eye(4)), StateRecord("ok", np.eye(4))]
    still = SimpleNamespace(steps=frames, timestamps=[0.0, 1.0], method="relnav")
    relative_state(still, **options)


def split_rotation_drift(Q: np.ndarray, share: float) -> tuple[np.ndarray, np.ndarray]:
    """Split a step's covariance into the map's share of its rotation and a white remainder.

    ``Q`` ``(6, 6)`` is in the observation's coordinates ``[δp (m), δθ (rad)]``
    (:func:`drift_covariance`): a rotation error of the step also swings the target's position
    (the lever arm), ``δp = A δθ + u`` with ``A = Q_pθ Q_θθ⁺`` and ``u`` the translation error of
    its own. The rotation ``δθ`` goes to the map (the observer bias) by ``share``, the rest of
    it, with its lever arm, is white: ``W = (1 − share) M Q_θθ Mᵀ`` with ``M = [A; I]``. The
    translation's own error ``u`` stays with the bias. Both parts are positive semi-definite
    and sum to ``Q``.

    Returns
    -------
    bias, white : (6, 6) float64
    """
    Q = 0.5 * (np.asarray(Q, dtype=float) + np.asarray(Q, dtype=float).T)
    A = Q[:3, 3:] @ np.linalg.pinv(Q[3:, 3:], hermitian=True)
    M = np.vstack([A, np.eye(3)])
    W = (1.0 - float(share)) * (M @ Q[3:, 3:] @ M.T)
    W = 0.5 * (W + W.T)
    return Q - W, W


def map_drift_shares(steps: Sequence[Any], memory: float = 20.0) -> np.ndarray:
    """Share of each frame's step error that the navigator's map absorbs, ``(N,)``.

    **[interpretation]** A map voxel keeps the running mean of the points merged into it, its
    weight saturating at ``memory`` frames. A frame merged into a map built from ``n`` frames
    with an error ``w`` relative to it moves the mean by ``w / min(n, memory)``: the first
    frames set the map's offset, later ones move it by a small share. ``n`` counts the frames
    merged before this one (``ok`` or ``first``; at least 1).

    Parameters
    ----------
    steps : sequence
        Frames with ``status``.
    memory : float
        Frames after which a voxel forgets geometrically (``max_voxel_weight``).

    Returns
    -------
    (N,) float64
        ``1 / min(n, memory)`` per frame, in (0, 1].
    """
    merged = np.cumsum([in_map(s) for s in steps])
    n = np.maximum(np.concatenate([[0], merged[:-1]]), 1).astype(float)
    return 1.0 / np.minimum(n, float(memory))


def pose_noise(steps: Sequence[Any], frame: str = "sensor") -> tuple[float, float]:
    """White noise of the navigator's poses (1σ: m, rad), from their second differences.

    For smooth motion the second difference of the steps is dominated by the pose noise, whose
    variance it multiplies by 6 (weights 1, −2, 1). A robust (MAD) scale per component,
    averaged over the axes **[interpretation: no ground truth involved; true accelerations
    count as noise, which is conservative]**. Frames the navigator flagged are left out.

    Parameters
    ----------
    steps : sequence
        Frames with ``pose`` (``T_target_sensor``) and ``status``.
    frame : {"sensor", "target"}
        Coordinates of the noise. ``"sensor"`` (default): the right steps
        ``Δ_k = T_{k-1}⁻¹ T_k`` and ``log(Δ_{k-1}⁻¹ Δ_k)``, the sensor's own noise in its axes.
        ``"target"``: the left steps ``Λ_k = T_k T_{k-1}⁻¹`` and ``log(Λ_k Λ_{k-1}⁻¹)``, the
        noise of a left twist ``T = exp(δ) T_true``, i.e. of the target's position and
        attitude as the observations of :func:`relative_state` see them. A rotation about the
        target seen in sensor axes adds itself times the range as translation: on
        envisat-tumble-64 (20 noise seeds, 50 m) the translation is 0.051 m in sensor axes and
        0.0075 m in the target's (truth-based MAD there: 0.0072 m). For a target spinning at a
        constant rate before a chaser at a hold point both kinds of steps are constant.
    """
    from relnav.geometry.lie import log_se3

    if frame not in ("sensor", "target"):
        raise ConfigError(f"frame must be 'sensor' or 'target', got {frame!r}")
    poses = [s.pose for s in steps]
    ok = [in_map(s) for s in steps]
    d2 = []
    for k in range(2, len(poses)):
        if ok[k] and ok[k - 1] and ok[k - 2]:
            if frame == "sensor":
                a = invert(poses[k - 2]) @ poses[k - 1]
                b = invert(poses[k - 1]) @ poses[k]
                d2.append(log_se3(invert(a) @ b))
            else:
                a = poses[k - 1] @ invert(poses[k - 2])
                b = poses[k] @ invert(poses[k - 1])
                d2.append(log_se3(b @ invert(a)))
    if len(d2) < 3:
        return 0.0, 0.0
    D = np.asarray(d2)
    mad = 1.4826 * np.median(np.abs(D - np.median(D, axis=0)), axis=0) / np.sqrt(6.0)
    return float(np.sqrt(np.mean(mad[:3] ** 2))), float(np.sqrt(np.mean(mad[3:] ** 2)))


def nees_band(n_steps: int, dof: int = 12, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided band of the **mean** NEES over ``n_steps`` consistent steps (χ² / n_steps)."""
    from scipy.stats import chi2

    a = (1.0 - probability) / 2.0
    k = dof * n_steps
    return float(chi2.ppf(a, k) / n_steps), float(chi2.ppf(1.0 - a, k) / n_steps)
