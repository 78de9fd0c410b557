"""Paper 2's tracking chain: per-frame pose observations → twistor UKF (or quaternion EKF).

:class:`Tracker` runs a filter over a sequence of per-frame observations (observed centroid
position and attitude of the target in the sensor frame). Frames without an observation (a
missing scan from one of the sensors, a registration flagged as failed, a NaN observation) are
**predicted through**: the filter propagates its state and covariance and the step is flagged.
:func:`track_sequence` builds the observations from a two-sensor sequence folder and runs it.
Observations and observers live in :mod:`relnav.fusion.observers`, the output containers in
:mod:`relnav.fusion.track_result` (both re-exported here).

Frames
------
``s`` = primary sensor (camera) frame (x forward, y left, z up); ``b`` = target body frame of
the observer. The estimate is ``T_s_b`` (position ``d`` = origin of ``b`` in ``s``, attitude
``R_s_b``), velocity ``ḋ`` in ``s`` and body rates ``ω`` in ``b``. Observers built on a model
of the target (Paper 2's contour model, or the registration chain here) define ``b`` as the
model frame fixed to the target at the first observed frame, so ``b`` differs from the
simulator's mesh frame by a constant transform. Ground truth (sequence folders):
``T_s_target = inv(T_target_s)`` per frame; ``gt_alignment="mean"`` right-multiplies it by the
constant ``T_target_b`` that best matches the estimate (rotation: chordal mean of
``R_gt⁻¹ R_est``; translation: mean of ``R_gtᵀ (d_est − d_gt)``), ``"first"`` takes it from the
first estimated frame, ``"none"`` compares the mesh frame directly. A filter that estimates the
rotation centre (``centre_offset``) is compared with the rotation centre: ``"centre"`` keeps
only the axial part of that mean translation (the default ``"auto"`` picks it for such a
filter, ``"mean"`` otherwise). Truth velocity and body rates come from finite differences of
the aligned truth.

Euler angles are extrinsic ``xyz`` (roll about x, pitch about y, yaw about z; ``R = Rz Ry Rx``)
of ``R_s_b``, unwrapped over time (a spinning target's yaw keeps growing). Attitude errors are
the body-axis rotation vector of ``R_gtᵀ R_est`` (degrees in reports).
"""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError, InputError, RelnavError
from relnav.fusion.dynamics import mean_motion
from relnav.fusion.ekf import QuaternionEKF
from relnav.fusion.observer_noise import (
    CALIBRATION_FILTER_OPTIONS,
    ObserverNoise,
    calibrated_noise,
)
from relnav.fusion.observers import (
    ContourObserver,
    Observation,
    Observer,
    RegistrationObserver,
    _default_observer,
    simulate_observations,
)
from relnav.fusion.pose_filter import PAPER2_RATE_HZ, PoseFilter
from relnav.fusion.track_result import TrackResult, TrackTruth, _body_rates
from relnav.fusion.ukf import TwistorUKF
from relnav.geometry.rotations import project_to_so3, quat_to_matrix
from relnav.geometry.se3 import invert

__all__ = [
    "Observation",
    "Observer",
    "RegistrationObserver",
    "Tracker",
    "TrackResult",
    "TrackTruth",
    "make_filter",
    "simulate_observations",
    "track_sequence",
]

log = logging.getLogger(__name__)

FilterName = Literal["ukf", "ekf"]


# --------------------------------------------------------------------------------------------
# the tracker
# --------------------------------------------------------------------------------------------


class _TrackLog:
    """Accumulates per-step filter outputs into :class:`TrackResult` arrays."""

    def __init__(self, K: int) -> None:
        self.pos = np.full((K, 3), np.nan)
        self.vel = np.full((K, 3), np.nan)
        self.quat = np.full((K, 4), np.nan)
        self.om = np.full((K, 3), np.nan)
        self.cov = np.full((K, 12, 12), np.nan)
        self.nis = np.full(K, np.nan)
        self.loglik = np.full(K, np.nan)
        self.obs = np.full((K, 7), np.nan)
        self.lam = np.full(K, np.nan)
        self.status: list[str] = []

    def record(
        self, k: int, f: PoseFilter | None, live: bool, status: str, nis: float, o: Any
    ) -> None:
        self.status.append(status)
        self.nis[k] = nis
        if o is not None:
            self.obs[k] = np.r_[o.position, o.quat_xyzw]
        if live and f is not None:
            self.pos[k], self.vel[k], self.quat[k], self.om[k] = (
                f.position,
                f.velocity,
                f.quaternion,
                f.omega,
            )
            self.cov[k] = f.physical_covariance()

    def result(
        self,
        times: np.ndarray,
        name: str,
        settings: dict[str, Any],
        truth: TrackTruth | None,
        meta: dict[str, Any],
    ) -> TrackResult:
        n_flag = sum(s.startswith("flagged") for s in self.status)
        if n_flag:
            log.info("%d of %d steps flagged (predicted through)", n_flag, len(self.status))
        return TrackResult(
            time=times,
            position=self.pos,
            velocity=self.vel,
            quat=self.quat,
            omega=self.om,
            covariance=self.cov,
            status=self.status,
            nis=self.nis,
            observed=self.obs,
            filter=name,
            settings=settings,
            truth=truth,
            meta=meta,
            noise_scale=self.lam,
            log_likelihood=self.loglik,
        )


def make_filter(name: FilterName | str = "ukf", **options: Any) -> PoseFilter:
    """Build ``"ukf"`` (:class:`TwistorUKF`) or ``"ekf"`` (:class:`QuaternionEKF`).

    Raises
    ------
    ConfigError
        Unknown filter or options.
    """
    key = str(name).lower()
    classes: dict[str, type[PoseFilter]] = {"ukf": TwistorUKF, "ekf": QuaternionEKF}
    if key not in classes:
        raise ConfigError(f"unknown filter {name!r}; choose 'ukf' or 'ekf'")
    try:
        return classes[key](**options)
    except TypeError as e:
        raise ConfigError(f"bad option for filter {key!r}: {e}") from None


class Tracker:
    """Run a pose filter over per-frame observations, predicting through missing ones.

    Parameters
    ----------
    filter : {"ukf", "ekf"}
        Twistor UKF (Paper 2) or the quaternion EKF baseline.
    n_mean_motion : float, optional
        CW mean motion, rad/s (default 0, Paper 2's lab set-up).
    orbit_radius_m : float, optional
        Alternative to ``n_mean_motion``: circular-orbit radius (m, from Earth's centre).
    dt : float, optional
        Nominal step for the process noise (default: median step of the run, else 1/0.22 s).
    omega0 : (3,) array_like, optional
        Initial body rate, rad/s (default zero; Paper 2 Table 3 uses ``(0, 0, 5)°/s``).
    velocity0 : (3,) array_like, optional
        Initial velocity, m/s (default zero).
    min_quality : float
        Observations with ``quality`` below this are rejected (flagged).
    init : {"first", "rate", "prior"}
        ``"first"``: initialize position and attitude from the first usable observation (steps
        before it are ``"waiting"``); ``"rate"`` **[interpretation, not in Paper 2]**: as
        ``"first"``, then at the second usable observation the filter starts again from the
        first one with the attitude change between them as its body rate, ``log(q₀⁻¹ q₁)/Δt``
        (the shortest rotation: a target turning less than 180° between them), and takes the
        second as its first update — for a target whose rate is unknown (no ``omega0``): a
        zero initial rate reads the first turns of a reference point circling the spin axis as
        velocity; ``"prior"``: start from the filter's initial state
        (``position0``/``quat0`` in ``filter_options``).
    noise_scale : {"fixed", "innovation"}
        ``"fixed"``: each update uses the observation's covariance (or the filter's ``r``) as
        is. ``"innovation"`` **[interpretation]**: covariance matching on the innovations seen
        so far — before each update the measurement covariance is multiplied by the scalar
        ``λ ≥ 1`` that makes the mean NIS of the updates so far, this one included
        (re-evaluated with ``S_j = H P_j Hᵀ + λ R_j``), equal to the measurement dimension;
        ``λ = 1`` without an innovation. Only the measurements up to the current one
        are used (causal, no ground truth); ``λ`` per step is in
        :attr:`TrackResult.noise_scale`.
    **filter_options
        Passed to the filter (``q``, ``r``, ``p0``, ``alpha``, ``kappa``, ``lvlh_axes``,
        ``translation_model``, ``jacobian``, ``gate_probability`` …).

    Examples
    --------
    >>> times, obs, truth = simulate_observations(n_steps=30, seed=0)
    >>> result = Tracker("ukf").run(times, obs, truth=truth)
    >>> result.summary()["attitude"]["rms"]  # doctest: +SKIP
    """

    def __init__(
        self,
        filter: FilterName | str = "ukf",
        *,
        n_mean_motion: float | None = None,
        orbit_radius_m: float | None = None,
        dt: float | None = None,
        omega0: Any = None,
        velocity0: Any = None,
        min_quality: float = 0.0,
        init: Literal["first", "rate", "prior"] = "first",
        noise_scale: Literal["fixed", "innovation"] = "fixed",
        **filter_options: Any,
    ) -> None:
        if n_mean_motion is not None and orbit_radius_m is not None:
            raise ConfigError("give n_mean_motion or orbit_radius_m, not both")
        n = 0.0 if n_mean_motion is None else float(n_mean_motion)
        if orbit_radius_m is not None:
            n = mean_motion(orbit_radius_m)
        if init not in ("first", "rate", "prior"):
            raise ConfigError(f"init must be 'first', 'rate' or 'prior', got {init!r}")
        if init == "rate" and omega0 is not None:
            raise ConfigError("init='rate' estimates the initial rate: give no omega0")
        self.filter_name = str(filter).lower()
        self.n_mean_motion = n
        self.dt = dt
        self.omega0 = None if omega0 is None else np.asarray(omega0, dtype=np.float64)
        self.velocity0 = None if velocity0 is None else np.asarray(velocity0, dtype=np.float64)
        self.min_quality = float(min_quality)
        self.init = init
        if noise_scale not in ("fixed", "innovation"):
            raise ConfigError(f"noise_scale must be 'fixed' or 'innovation', got {noise_scale!r}")
        self.noise_scale = noise_scale
        self.lam = 1.0
        self.log_likelihood = math.nan  # of the last step's update (NaN without one)
        self._innov: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.filter_options = dict(filter_options)
        make_filter(self.filter_name, n_mean_motion=n, **self._opts(1.0))  # validate early
        self.filter: PoseFilter | None = None
        self._t: float | None = None
        self._initialized = False

    def _opts(self, dt: float) -> dict[str, Any]:
        opts = dict(self.filter_options)
        opts.setdefault("dt", dt)
        if self.omega0 is not None:
            opts.setdefault("omega0", self.omega0)
        if self.velocity0 is not None:
            opts.setdefault("velocity0", self.velocity0)
        return opts

    def reset(self, dt: float | None = None) -> None:
        """Build a fresh filter (nominal step ``dt``)."""
        step = self.dt or dt or 1.0 / PAPER2_RATE_HZ
        self.filter = make_filter(
            self.filter_name, n_mean_motion=self.n_mean_motion, **self._opts(step)
        )
        self._t = None
        self._initialized = self.init == "prior"
        self._first: tuple[float, Observation] | None = None  # init="rate": held observation
        self.lam = 1.0
        self._innov = []

    def _match_scale(self) -> float:
        """``λ ≥ 1`` with mean ``νᵀ(A + λR)⁻¹ν`` over the past updates = their dimension."""
        if not self._innov:
            return 1.0
        m = float(np.mean([nu.size for nu, _, _ in self._innov]))

        def mean_nis(lam: float) -> float:
            return float(
                np.mean([nu @ np.linalg.solve(A + lam * R, nu) for nu, A, R in self._innov])
            )

        if mean_nis(1.0) <= m:
            return 1.0
        lo, hi = 0.0, math.log(1e6)
        if mean_nis(math.exp(hi)) > m:
            return math.exp(hi)
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if mean_nis(math.exp(mid)) > m:
                lo = mid
            else:
                hi = mid
        return math.exp(hi)

    def _usable(self, obs: Observation | None) -> str:
        """``""`` if ``obs`` can be used, else the reason."""
        if obs is None:
            return "none"
        if not (np.all(np.isfinite(obs.position)) and np.all(np.isfinite(obs.quat_xyzw))):
            return "non-finite observation"
        if float(np.linalg.norm(obs.quat_xyzw)) < 1e-9:
            return "zero quaternion"
        if not math.isfinite(obs.quality) or obs.quality < self.min_quality:
            return f"quality {obs.quality:.3g} below {self.min_quality:.3g}"
        return ""

    def step(self, t: float, obs: Observation | None) -> tuple[str, float]:
        """Advance to time ``t`` (s) and use ``obs`` if any.

        Returns
        -------
        status : str
            See :class:`TrackResult`.
        nis : float
            NIS of the update (NaN if none).
        """
        if self.filter is None:
            self.reset()
        f = self.filter
        assert f is not None
        self.log_likelihood = math.nan  # set again by an update
        t = float(t)
        reason = self._usable(obs)
        if not self._initialized:
            if reason:
                self._t = t if math.isfinite(t) else self._t
                return ("waiting" if reason == "none" else f"flagged: {reason}"), math.nan
            assert obs is not None
            f.initialize(
                obs.position,
                obs.quat_xyzw,
                velocity=self.velocity0,
                omega=self.omega0,
            )
            self._initialized = True
            self._t = t
            self._first = (t, obs) if self.init == "rate" else None
            return "init", math.nan
        if self._first is not None and not reason and math.isfinite(t) and t > self._first[0]:
            # init="rate": start again from the first observation, with the rate the second shows
            assert obs is not None
            t0, o0 = self._first
            f.initialize(
                o0.position,
                o0.quat_xyzw,
                velocity=self.velocity0,
                omega=_body_rates(np.array([t0, t]), np.stack([o0.quat_xyzw, obs.quat_xyzw]))[0],
            )
            self._t, self._first = t0, None
        if not math.isfinite(t) or (self._t is not None and t < self._t):
            return f"flagged: time {t!r} not after {self._t!r}", math.nan
        if self._t is not None:
            f.predict(t - self._t)
        self._t = t
        if reason == "none":
            return "predict", math.nan
        if reason:
            return f"flagged: {reason}", math.nan
        assert obs is not None
        R = obs.R
        if obs.drift is not None and hasattr(f, "add_observer_drift"):
            f.add_observer_drift(obs.drift)
        if obs.offset_drift is not None and hasattr(f, "add_offset_drift"):
            f.add_offset_drift(obs.offset_drift)
        if obs.sources is not None and hasattr(f, "set_merge_sources"):
            f.set_merge_sources(obs.frame, obs.sources)
        if self.noise_scale == "innovation":
            R0 = f.R if R is None else np.asarray(R, dtype=np.float64)
            probe = copy.deepcopy(f).update(obs.position, obs.quat_xyzw, R=R0)
            if probe.meas_cov.size and np.all(np.isfinite(probe.innovation)):
                A = probe.innovation_cov - probe.meas_cov
                self._innov.append((probe.innovation, A, probe.meas_cov))
            self.lam = self._match_scale()
            R = R0 * self.lam
        info = f.update(obs.position, obs.quat_xyzw, R=R)
        self.log_likelihood = info.log_likelihood
        if not info.accepted:
            return f"flagged: {info.message}", info.nis
        return "update", info.nis

    def run(
        self,
        times: Sequence[float] | np.ndarray,
        observations: Sequence[Observation | None],
        *,
        truth: TrackTruth | None = None,
        progress: Callable[[int, int], None] | None = None,
        meta: dict[str, Any] | None = None,
    ) -> TrackResult:
        """Run the filter over a whole sequence (a fresh filter).

        Parameters
        ----------
        times : (K,) array_like
            Step times, s (non-decreasing; a step going back in time is flagged and skipped).
        observations : sequence of Observation or None
            One per step; ``None`` = no observation (predicted through).
        truth : TrackTruth, optional
            Attached to the result.
        progress : callable, optional
            ``progress(done, total)`` after each step.
        meta : dict, optional
            Stored in the result.

        Raises
        ------
        InputError
            ``times`` and ``observations`` differ in length, or ``truth`` does.
        """
        t = np.asarray(times, dtype=np.float64).reshape(-1)
        K = len(t)
        if len(observations) != K:
            raise InputError(f"{len(observations)} observations for {K} time steps")
        if truth is not None and len(truth.position) != K:
            raise InputError(f"ground truth has {len(truth.position)} steps for {K} time steps")
        finite = t[np.isfinite(t)]
        steps = np.diff(finite)
        steps = steps[steps > 0]
        self.reset(float(np.median(steps)) if len(steps) else None)
        rec = _TrackLog(K)
        for k in range(K):
            o = observations[k]
            st, ni = self.step(t[k], o)
            rec.record(k, self.filter, self._initialized, st, ni, o)
            rec.lam[k] = self.lam
            rec.loglik[k] = self.log_likelihood
            if progress is not None:
                progress(k + 1, K)
        assert self.filter is not None
        return rec.result(t, self.filter_name, self.filter.settings(), truth, dict(meta or {}))


def _observer_noise(
    value: ObserverNoise | Literal["reported"] | str | Path | None, rate_known: bool
) -> ObserverNoise | Literal["reported"]:
    """``track_sequence``'s ``observer_noise`` as the contour observer takes it (``None`` and
    ``"calibrated"``: :func:`relnav.fusion.observer_noise.calibrated_noise` of the loop)."""
    if value is None or (isinstance(value, str) and value == "calibrated"):
        return calibrated_noise(rate_known)
    if isinstance(value, ObserverNoise):
        return value
    if isinstance(value, str) and value == "reported":
        return "reported"
    if isinstance(value, str | Path):
        return ObserverNoise.load(value)
    raise ConfigError(
        f"observer_noise: expected a model, 'calibrated', 'reported' or a path, got {value!r}"
    )


def _align_truth(
    T_gt: np.ndarray, est_pos: np.ndarray, est_quat: np.ndarray, how: str
) -> tuple[np.ndarray, np.ndarray]:
    """Right-multiply truth poses ``(K, 4, 4)`` by a constant ``T_target_b``; returns the
    aligned poses and the alignment."""
    A = np.eye(4)
    ok = np.all(np.isfinite(est_pos), axis=1) & np.all(np.isfinite(est_quat), axis=1)
    if how == "none" or not np.any(ok):
        return T_gt.copy(), A
    R_est = quat_to_matrix(est_quat[ok])
    R_gt = T_gt[ok, :3, :3]
    rel_R = np.swapaxes(R_gt, 1, 2) @ R_est
    rel_t = np.einsum("kji,kj->ki", R_gt, est_pos[ok] - T_gt[ok, :3, 3])
    if how == "first":
        A[:3, :3] = project_to_so3(rel_R[0])
        A[:3, 3] = rel_t[0]
    elif how == "mean":
        A[:3, :3] = project_to_so3(rel_R.sum(axis=0))
        A[:3, 3] = rel_t.mean(axis=0)
    elif how == "first-rotation":
        A[:3, :3] = project_to_so3(rel_R[0])
        A[:3, 3] = rel_t.mean(axis=0)
    elif how == "centre":
        A[:3, :3] = project_to_so3(rel_R[0])
        u = _spin_axis(T_gt[:, :3, :3])
        m = rel_t.mean(axis=0)
        A[:3, 3] = m if u is None else u * float(u @ m)
    else:
        raise ConfigError(
            "gt_alignment must be 'auto', 'mean', 'first', 'first-rotation', 'centre' or "
            "'none', got " + repr(how)
        )
    return T_gt @ A, A


def _spin_axis(R_gt: np.ndarray) -> np.ndarray | None:
    """Unit spin axis ``(3,)`` of truth attitudes ``R_s_target`` ``(K, 3, 3)`` in target axes:
    the principal direction of the frame-to-frame rotation vectors ``log(R_kᵀ R_k+1)``
    (``None`` when the target does not turn)."""
    from scipy.spatial.transform import Rotation

    if len(R_gt) < 2:
        return None
    inc = Rotation.from_matrix(np.swapaxes(R_gt[:-1], 1, 2) @ R_gt[1:]).as_rotvec()
    inc = inc[np.all(np.isfinite(inc), axis=1)]
    if len(inc) == 0 or float(np.max(np.linalg.norm(inc, axis=1))) < 1e-9:
        return None
    return np.linalg.eigh(inc.T @ inc)[1][:, -1]


def _associate(t_primary: np.ndarray, t_other: np.ndarray) -> np.ndarray:
    """Index into ``t_other`` of the scan nearest each primary time within half a frame period
    (−1 when none)."""
    out = np.full(len(t_primary), -1, dtype=np.int64)
    if len(t_other) == 0 or len(t_primary) == 0:
        return out
    steps = np.diff(t_primary)
    steps = steps[steps > 0]
    tol = 0.5 * float(np.median(steps)) if len(steps) else 1e-3
    order = np.argsort(t_other)
    ts = t_other[order]
    j = (
        np.clip(np.searchsorted(ts, t_primary), 1, len(ts) - 1)
        if len(ts) > 1
        else np.zeros(len(t_primary), dtype=np.int64)
    )
    for i, tp in enumerate(t_primary):
        cands = [j[i]] if len(ts) == 1 else [j[i] - 1, j[i]]
        best = min(cands, key=lambda c: abs(ts[c] - tp))
        if abs(ts[best] - tp) <= tol:
            out[i] = order[best]
    return out


def track_sequence(
    seq_dir: str | Path,
    *,
    filter: FilterName | str = "ukf",
    observer: Observer | str | None = None,
    second_sensor: str | None = "auto",
    max_frames: int | None = None,
    require_all_sensors: bool = True,
    gt_alignment: Literal["auto", "mean", "first", "first-rotation", "centre", "none"] = "auto",
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    observer_noise: ObserverNoise | Literal["reported"] | str | Path | None = None,
    **tracker_options: Any,
) -> TrackResult:
    """Track the target over a sequence folder (primary camera + optional second sensor).

    Parameters
    ----------
    seq_dir : str or Path
        Sequence folder (``scans/`` = camera; ``scans_<name>/`` = second sensor).
    filter : {"ukf", "ekf"}
    observer : Observer, {"contour", "registration"} or None
        ``None``: the contour-model chain when :mod:`relnav.fusion.reconstruction` is
        available and a second sensor exists, else :class:`RegistrationObserver`.
    second_sensor : str or None
        Name of the second sensor; ``"auto"`` = the first ``scans_<name>/`` found; ``None`` =
        camera only.
    max_frames : int, optional
        Use the first N camera frames.
    require_all_sensors : bool
        A frame where any used sensor has no scan (no scan within half a frame period, or an
        empty scan) gets no observation (predicted through, ``"flagged: missing scan"``).
    gt_alignment : {"auto", "mean", "first", "first-rotation", "centre", "none"}
        How truth is expressed in the estimate's body frame (module docstring).
        ``"first-rotation"``: rotation from the first estimated frame (exact for the contour
        and registration observers, whose body axes are by definition the sensor axes at
        their first observation and which initialize the filter there), translation the mean
        offset. ``"centre"``: the same rotation; the truth point is the target's rotation
        centre (its frame origin) moved along the spin axis only, by the mean offset's axial
        component — the point a ``centre_offset`` filter estimates (its position along the
        axis is unobservable), so that an error of the estimated centre across the axis is
        counted, not aligned away. ``"auto"`` (default): ``"centre"`` when the filter
        estimates a centre offset, else ``"mean"``.
    seed : int
        Seed of the observer's random choices (recorded in ``meta``).
    progress : callable, optional
        ``progress(done, total)``.
    observer_noise : ObserverNoise, "calibrated", "reported" or path, optional
        The contour observer's noise (:class:`ContourObserver` ``noise``): ``None`` or
        ``"calibrated"`` = :func:`relnav.fusion.observer_noise.calibrated_noise` (the model
        calibrated with ``omega0`` given, or the one without when it is not), a path =
        a JSON model (:meth:`ObserverNoise.save`). Only with the contour observer built here.
    **tracker_options
        Passed to :class:`Tracker` (``n_mean_motion``, ``orbit_radius_m``, ``q``, ``r`` …).
        With the UKF and the contour observer, ``centre_offset`` and ``observer_bias`` default
        to ``True`` (:class:`relnav.fusion.ukf.TwistorUKF`): its reference point is the first
        frame's centroid, which circles the spin axis, and its model drifts; with a calibrated
        noise model (not ``"reported"``) also the options it was calibrated with,
        ``bias_frame="body"`` and ``robust_dof=8``. Without ``omega0`` (an unknown rate)
        ``init`` defaults to ``"rate"``: the initial rate from the first two observations.
        With ``merge_slots`` > 0 the merge states replace the bias (``observer_bias`` then
        defaults to ``False``).

    Returns
    -------
    TrackResult
        With ``truth`` when the primary sensor has a ground-truth file.

    Raises
    ------
    InputError
        Missing folder / scans; unknown second sensor.
    """
    from relnav.io.sequences import ScanSequence

    if observer_noise is not None and observer is not None and observer != "contour":
        if not isinstance(observer, ContourObserver):
            raise ConfigError("observer_noise is an option of the contour observer")
    noise = _observer_noise(observer_noise, tracker_options.get("omega0") is not None)
    folder = Path(seq_dir)
    cam = ScanSequence(folder)
    if len(cam) == 0:
        raise InputError(f"{folder}: no camera scans")
    others = [s for s in ScanSequence.sensors(folder) if s]
    second: str | None
    if second_sensor == "auto":
        second = others[0] if others else None
    else:
        second = second_sensor
        if second is not None and second not in others:
            raise InputError(f"{folder}: no scans_{second}/ (sensors present: {others})")
    sec = ScanSequence(folder, sensor=second) if second else None
    n = len(cam) if max_frames is None else max(0, min(len(cam), int(max_frames)))
    times = cam.timestamps[:n]
    assoc = _associate(times, sec.timestamps) if sec is not None else None

    if observer is None:
        obs_impl: Observer = _default_observer(second, seed, noise)
    elif isinstance(observer, str):
        if observer == "contour":
            if second is None:
                raise InputError("the contour observer needs a second sensor (scans_<name>/)")
            obs_impl = ContourObserver(lidar=second, seed=seed, noise=noise)
        elif observer.startswith("registration"):
            _, _, method = observer.partition(":")
            obs_impl = RegistrationObserver(method or "icp-point", seed=seed)
        else:
            raise ConfigError(
                f"unknown observer {observer!r}: 'contour' or 'registration[:method]'"
            )
    else:
        obs_impl = observer
    if observer_noise is not None and not isinstance(obs_impl, ContourObserver):
        raise ConfigError("observer_noise is an option of the contour observer")

    if str(filter).lower() == "ukf" and isinstance(obs_impl, ContourObserver):
        # the contour model's reference point circles the spin axis and the model drifts
        tracker_options.setdefault("centre_offset", True)
        if not tracker_options.get("merge_slots"):  # the merge states replace the bias
            tracker_options.setdefault("observer_bias", True)
            if obs_impl.noise != "reported":  # the filter its noise was calibrated with
                for key, value in CALIBRATION_FILTER_OPTIONS.items():
                    tracker_options.setdefault(key, value)
    if tracker_options.get("omega0") is None and tracker_options.get("init") is None:
        tracker_options["init"] = "rate"  # an unknown rate: from the first two attitudes
    tracker = Tracker(filter, **tracker_options)
    steps = np.diff(times)
    steps = steps[steps > 0]
    tracker.reset(float(np.median(steps)) if len(steps) else None)
    f = tracker.filter
    assert f is not None
    rec = _TrackLog(n)
    for k in range(n):
        scans: dict[str, np.ndarray] = {"": cam[k].points}
        missing = len(scans[""]) == 0
        if sec is not None and assoc is not None and second is not None:
            j = int(assoc[k])
            if j >= 0:
                scans[second] = sec[j].points
                missing = missing or len(scans[second]) == 0
            else:
                missing = True
        o: Observation | None = None
        msg = ""
        if missing and require_all_sensors:
            msg = "missing scan"
        else:
            prior = None
            if tracker._initialized and tracker._t is not None:
                prior = _predicted_pose(f, float(times[k]) - tracker._t)
            try:
                o = obs_impl.observe(k, scans, prior)
                if o is None:
                    msg = "no observation"
            except RelnavError as e:
                msg = str(e)
        st, ni = tracker.step(float(times[k]), o)
        if msg and st in ("predict", "waiting"):
            st = f"flagged: {msg}"
        rec.record(k, f, tracker._initialized, st, ni, o)
        rec.lam[k] = tracker.lam
        if progress is not None:
            progress(k + 1, n)

    truth = None
    gt = cam.gt_poses
    meta: dict[str, Any] = {
        "sequence": str(folder),
        "observer": getattr(obs_impl, "name", type(obs_impl).__name__),
        "second_sensor": second,
        "seed": seed,
        "gt_alignment": gt_alignment,
        "observer_stats": dict(getattr(obs_impl, "stats", {}) or {}),
    }
    if isinstance(obs_impl, ContourObserver):  # the noise the observations carried
        n_ = obs_impl.noise
        meta["observer_noise"] = n_ if isinstance(n_, str) else n_.to_dict()
    if gt_alignment == "auto":
        gt_alignment = "centre" if getattr(f, "centre_offset", False) else "mean"
        meta["gt_alignment"] = gt_alignment
    if gt is not None:
        T_s_target = invert(gt[:n])
        T_aligned, A = _align_truth(T_s_target, rec.pos, rec.quat, gt_alignment)
        truth = TrackTruth.from_poses(times, T_aligned)
        meta["T_target_body"] = A.tolist()
    return rec.result(times, tracker.filter_name, f.settings(), truth, meta)


def _predicted_pose(f: PoseFilter, dt: float) -> np.ndarray:
    """``T_s_b`` of the observer's body frame (origin = the reference point) predicted ``dt``
    seconds ahead (mean only, the filter is not changed)."""
    T = np.eye(4)
    p, q = f.predicted_reference(dt)
    T[:3, :3] = quat_to_matrix(q)
    T[:3, 3] = p
    return T
