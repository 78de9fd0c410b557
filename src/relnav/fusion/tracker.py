"""Paper 2's tracking chain: per-frame pose observations → twistor UKF (or quaternion EKF).

:class:`Tracker` runs a filter over a sequence of per-frame observations (observed centroid
position and attitude of the target in the sensor frame). Frames without an observation (a
missing scan from one of the sensors, a registration flagged as failed, a NaN observation) are
**predicted through**: the filter propagates its state and covariance and the step is flagged.
:func:`track_sequence` builds the observations from a two-sensor sequence folder and runs it.

Frames
------
``s`` = primary sensor (camera) frame (x forward, y left, z up); ``b`` = target body frame of
the observer. The estimate is ``T_s_b`` (position ``d`` = origin of ``b`` in ``s``, attitude
``R_s_b``), velocity ``ḋ`` in ``s`` and body rates ``ω`` in ``b``. Observers built on a model
of the target (Paper 2's contour model, or the registration chain here) define ``b`` as the
model frame fixed to the target at the first observed frame, so ``b`` differs from the
simulator's mesh frame by a constant transform. Ground truth (sequence folders):
``T_s_target = inv(T_target_s)`` per frame; ``gt_alignment="mean"`` (default) right-multiplies
it by the constant ``T_target_b`` that best matches the estimate (rotation: chordal mean of
``R_gt⁻¹ R_est``; translation: mean of ``R_gtᵀ (d_est − d_gt)``), ``"first"`` takes it from the
first estimated frame, ``"none"`` compares the mesh frame directly. Truth velocity and body
rates come from finite differences of the aligned truth.

Euler angles are extrinsic ``xyz`` (roll about x, pitch about y, yaw about z; ``R = Rz Ry Rx``)
of ``R_s_b``, unwrapped over time (a spinning target's yaw keeps growing). Attitude errors are
the body-axis rotation vector of ``R_gtᵀ R_est`` (degrees in reports).
"""

from __future__ import annotations

import copy
import csv
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Protocol

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from relnav.errors import ConfigError, InputError, RelnavError
from relnav.fusion.dynamics import ClohessyWiltshire, mean_motion
from relnav.fusion.ekf import QuaternionEKF
from relnav.fusion.ukf import PAPER2_RATE_HZ, PoseFilter, TwistorUKF, quat_delta
from relnav.geometry.dualquat import _qmul
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
_QCONJ = np.array([-1.0, -1.0, -1.0, 1.0])


# --------------------------------------------------------------------------------------------
# data containers
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Observation:
    """One per-frame observation of the target.

    Attributes
    ----------
    position : (3,) ndarray
        Target reference point (centroid) in the sensor frame, m.
    quat_xyzw : (4,) ndarray
        Attitude ``R_sensor_body``.
    quality : float
        Observer's quality score (e.g. registration fitness, 1 = best).
    R : (6, 6) ndarray, optional
        Covariance of ``[δp (m), δθ (rad)]``; default: the filter's.
    drift : (6, 6) ndarray, optional
        Growth of the observer's own slowly varying error since its previous observation
        (same coordinates), for ``TwistorUKF(observer_bias=True)``.
    """

    position: np.ndarray
    quat_xyzw: np.ndarray
    quality: float = 1.0
    R: np.ndarray | None = None
    drift: np.ndarray | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.position, dtype=np.float64)
        q = np.asarray(self.quat_xyzw, dtype=np.float64)
        if p.shape != (3,) or q.shape != (4,):
            raise InputError(
                f"observation needs position (3,) and quat_xyzw (4,), got {p.shape}, {q.shape}"
            )
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "quat_xyzw", q)


def _euler_unwrapped(quats: np.ndarray) -> np.ndarray:
    """Extrinsic xyz Euler angles ``(K, 3)`` rad of quaternions ``(K, 4)``, unwrapped in time
    (rows with NaN stay NaN)."""
    out = np.full((len(quats), 3), np.nan)
    ok = np.all(np.isfinite(quats), axis=1)
    if np.any(ok):
        e = Rotation.from_quat(quats[ok]).as_euler("xyz")
        out[ok] = np.unwrap(e, axis=0)
    return out


def _body_rates(times: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """Body rates ``(K, 3)`` rad/s by finite differences of attitudes (forward; last backward)."""
    K = len(times)
    w = np.full((K, 3), np.nan)
    if K < 2:
        return w
    dq = _qmul(quats[:-1] * _QCONJ, quats[1:])
    dq = np.where(dq[:, 3:4] < 0, -dq, dq)
    dt = np.diff(times)
    with np.errstate(divide="ignore", invalid="ignore"):
        rates = Rotation.from_quat(dq).as_rotvec() / dt[:, None]
    w[:-1] = rates
    w[-1] = rates[-1]
    return w


def _velocities(times: np.ndarray, pos: np.ndarray) -> np.ndarray:
    if len(times) < 2:
        return np.zeros_like(pos)
    return np.gradient(pos, times, axis=0)


@dataclass
class TrackTruth:
    """Ground truth on the tracker's time steps (same frames as the estimate).

    Attributes
    ----------
    position (K, 3) m, velocity (K, 3) m/s, quat (K, 4) xyzw, omega (K, 3) rad/s (body).
    """

    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    omega: np.ndarray

    @property
    def euler(self) -> np.ndarray:
        """Extrinsic xyz Euler angles ``(K, 3)``, rad, unwrapped."""
        return _euler_unwrapped(self.quat)

    @classmethod
    def from_poses(cls, times: np.ndarray, T_s_b: np.ndarray) -> TrackTruth:
        """Truth from poses ``T_sensor_body`` ``(K, 4, 4)``; velocity and body rates by finite
        differences."""
        times = np.asarray(times, dtype=np.float64)
        quats = Rotation.from_matrix(T_s_b[:, :3, :3]).as_quat()
        quats = np.where(quats[:, 3:4] < 0, -quats, quats)
        pos = T_s_b[:, :3, 3].copy()
        return cls(pos, _velocities(times, pos), quats, _body_rates(times, quats))


@dataclass
class TrackResult:
    """Per-step output of :class:`Tracker`.

    Attributes
    ----------
    time : (K,) float64
        Step times, s.
    position, velocity : (K, 3)
        m and m/s, sensor frame (NaN before initialization).
    quat : (K, 4)
        Attitude ``R_sensor_body`` (xyzw).
    omega : (K, 3)
        Body rates, rad/s.
    covariance : (K, 12, 12)
        Covariance of ``[δd, δv, δθ, δω]`` after each step.
    status : list[str]
        ``"init"``, ``"update"``, ``"predict"`` (no observation), ``"waiting"`` (before the
        first observation) or ``"flagged: <reason>"`` (observation rejected or bad time step;
        the filter predicted through).
    nis : (K,)
        Normalized innovation squared of accepted/gated updates (NaN otherwise).
    observed : (K, 7)
        Observed position and quaternion (NaN where none).
    filter : str
        ``"ukf"`` or ``"ekf"``.
    settings : dict
        Filter configuration.
    truth : TrackTruth, optional
        Ground truth on the same steps.
    meta : dict
        Free-form metadata (sequence folder, observer, seed, alignment...).
    noise_scale : (K,), optional
        Measurement-covariance scale ``λ`` used per step (``Tracker(noise_scale=...)``).
    """

    time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    omega: np.ndarray
    covariance: np.ndarray
    status: list[str]
    nis: np.ndarray
    observed: np.ndarray
    filter: str
    settings: dict[str, Any] = field(default_factory=dict)
    truth: TrackTruth | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    noise_scale: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.time)

    @property
    def euler(self) -> np.ndarray:
        """Extrinsic xyz Euler angles (roll, pitch, yaw) ``(K, 3)``, rad, unwrapped."""
        return _euler_unwrapped(self.quat)

    def sigma(self) -> dict[str, np.ndarray]:
        """1σ per step: ``position`` (m), ``velocity`` (m/s), ``attitude`` (rad, body axes),
        ``omega`` (rad/s), each ``(K, 3)``."""
        d = np.sqrt(np.clip(np.diagonal(self.covariance, axis1=1, axis2=2), 0.0, None))
        return {
            "position": d[:, 0:3],
            "velocity": d[:, 3:6],
            "attitude": d[:, 6:9],
            "omega": d[:, 9:12],
        }

    @property
    def n_flagged(self) -> int:
        """Steps whose observation was rejected (``flagged: ...``)."""
        return sum(s.startswith("flagged") for s in self.status)

    @property
    def n_predicted(self) -> int:
        """Steps without a usable observation (predicted through, flagged or not)."""
        return sum(s == "predict" or s.startswith("flagged") for s in self.status)

    def errors(self) -> dict[str, np.ndarray]:
        """Estimate minus truth per step: ``position`` (m), ``velocity`` (m/s), ``attitude``
        (rad, body rotation vector of ``R_gtᵀ R_est``), ``euler`` (rad, wrapped difference),
        ``omega`` (rad/s); each ``(K, 3)``.

        Raises
        ------
        EstimationError
            No ground truth.
        """
        from relnav.errors import EstimationError

        if self.truth is None:
            raise EstimationError("this track has no ground truth")
        t = self.truth
        att = np.full((len(self), 3), np.nan)
        ok = np.all(np.isfinite(self.quat), axis=1)
        if np.any(ok):
            dq = _qmul(t.quat[ok] * _QCONJ, self.quat[ok])
            dq = np.where(dq[:, 3:4] < 0, -dq, dq)
            att[ok] = Rotation.from_quat(dq).as_rotvec()
        de = self.euler - t.euler
        de = (de + np.pi) % (2.0 * np.pi) - np.pi
        return {
            "position": self.position - t.position,
            "velocity": self.velocity - t.velocity,
            "attitude": att,
            "euler": de,
            "omega": self.omega - t.omega,
        }

    def nees(self) -> np.ndarray:
        """NEES per step over the 12 physical components (NaN without an estimate)."""
        e = self.errors()
        err = -np.concatenate([e["position"], e["velocity"], e["attitude"], e["omega"]], axis=1)
        out = np.full(len(self), np.nan)
        for k in range(len(self)):
            if np.all(np.isfinite(err[k])) and np.all(np.isfinite(self.covariance[k])):
                out[k] = float(err[k] @ np.linalg.solve(self.covariance[k], err[k]))
        return out

    def consistency(self, probability: float = 0.95) -> dict[str, Any]:
        """Mean NIS over the updates and mean NEES over the estimated steps (after the
        initializing one), each with the two-sided ``probability`` band of the mean of that
        many independent χ² values (``χ²_{m·n}/n``; m = 6 for NIS, 12 for NEES).

        Returns
        -------
        dict
            ``{"nis": {"mean", "n", "dof", "band"}, "nees": {...} or None}``.
        """
        a = (1.0 - probability) / 2.0

        def block(x: np.ndarray, dof: int) -> dict[str, Any] | None:
            x = x[np.isfinite(x)]
            if x.size == 0:
                return None
            n = int(x.size)
            band = [float(chi2.ppf(a, dof * n) / n), float(chi2.ppf(1.0 - a, dof * n) / n)]
            return {"mean": float(x.mean()), "n": n, "dof": dof, "band": band}

        upd = np.array([st == "update" for st in self.status])
        out: dict[str, Any] = {"nis": block(np.where(upd, self.nis, np.nan), 6), "nees": None}
        if self.truth is not None:
            ne = self.nees()
            est = np.array([st not in ("init", "waiting") for st in self.status])
            out["nees"] = block(np.where(est, ne, np.nan), 12)
        return out

    def summary(self, skip: int | float = 0.2) -> dict[str, dict[str, list[float]]]:
        """RMS and max absolute error per axis after convergence.

        Parameters
        ----------
        skip : int or float
            Steps to ignore at the start (an int) or a fraction of the steps (a float < 1).

        Returns
        -------
        dict
            ``{quantity: {"rms": [x, y, z], "max": [x, y, z]}}`` with ``position`` (m),
            ``velocity`` (m/s), ``attitude`` and ``euler`` (deg), ``omega`` (deg/s).
        """
        n0 = round(skip * len(self)) if isinstance(skip, float) and skip < 1 else int(skip)
        out: dict[str, dict[str, list[float]]] = {}
        for key, e in self.errors().items():
            e = e[n0:]
            e = e[np.all(np.isfinite(e), axis=1)]
            if key in ("attitude", "euler", "omega"):
                e = np.degrees(e)
            if len(e) == 0:
                out[key] = {"rms": [math.nan] * 3, "max": [math.nan] * 3}
                continue
            out[key] = {
                "rms": np.sqrt(np.mean(e**2, axis=0)).tolist(),
                "max": np.max(np.abs(e), axis=0).tolist(),
            }
        return out

    def to_csv(self, path: str | Path) -> Path:
        """Write one row per step: estimate, 1σ, observation, and truth/errors when present.

        Angles in degrees (Euler angles extrinsic xyz), rates in deg/s, lengths in metres.
        """
        path = Path(path)
        sig = self.sigma()
        eul = np.degrees(self.euler)
        cols: dict[str, np.ndarray] = {}
        xyz = ("x", "y", "z")

        def put(prefix: str, arr: np.ndarray, names: Sequence[str] = xyz) -> None:
            for i, n in enumerate(names):
                cols[f"{prefix}{n}"] = arr[:, i]

        put("p", self.position)
        put("v", self.velocity)
        put("", eul, ("roll", "pitch", "yaw"))
        put("w", np.degrees(self.omega))
        put("q", self.quat, ("x", "y", "z", "w"))
        put("sigma_p", sig["position"])
        put("sigma_v", sig["velocity"])
        put("sigma_att_", np.degrees(sig["attitude"]))
        put("sigma_w", np.degrees(sig["omega"]))
        put("obs_p", self.observed[:, :3])
        put("obs_q", self.observed[:, 3:], ("x", "y", "z", "w"))
        if self.truth is not None:
            t = self.truth
            put("true_p", t.position)
            put("true_v", t.velocity)
            put("true_", np.degrees(t.euler), ("roll", "pitch", "yaw"))
            put("true_w", np.degrees(t.omega))
            e = self.errors()
            put("err_p", e["position"])
            put("err_v", e["velocity"])
            put("err_att_", np.degrees(e["attitude"]))
            put("err_w", np.degrees(e["omega"]))
            cols["nees"] = self.nees()
        if self.noise_scale is not None:
            cols["noise_scale"] = np.asarray(self.noise_scale, dtype=np.float64)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["time", "status", "nis", *cols])
            for k in range(len(self)):
                w.writerow(
                    [repr(float(self.time[k])), self.status[k], f"{self.nis[k]:.6g}"]
                    + [f"{cols[c][k]:.9g}" for c in cols]
                )
        return path


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
    init : {"first", "prior"}
        ``"first"``: initialize position and attitude from the first usable observation (steps
        before it are ``"waiting"``); ``"prior"``: start from the filter's initial state
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
        init: Literal["first", "prior"] = "first",
        noise_scale: Literal["fixed", "innovation"] = "fixed",
        **filter_options: Any,
    ) -> None:
        if n_mean_motion is not None and orbit_radius_m is not None:
            raise ConfigError("give n_mean_motion or orbit_radius_m, not both")
        n = 0.0 if n_mean_motion is None else float(n_mean_motion)
        if orbit_radius_m is not None:
            n = mean_motion(orbit_radius_m)
        if init not in ("first", "prior"):
            raise ConfigError(f"init must be 'first' or 'prior', got {init!r}")
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
            return "init", math.nan
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
        if self.noise_scale == "innovation":
            R0 = f.R if R is None else np.asarray(R, dtype=np.float64)
            probe = copy.deepcopy(f).update(obs.position, obs.quat_xyzw, R=R0)
            if probe.meas_cov.size and np.all(np.isfinite(probe.innovation)):
                A = probe.innovation_cov - probe.meas_cov
                self._innov.append((probe.innovation, A, probe.meas_cov))
            self.lam = self._match_scale()
            R = R0 * self.lam
        info = f.update(obs.position, obs.quat_xyzw, R=R)
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
            if progress is not None:
                progress(k + 1, K)
        assert self.filter is not None
        return rec.result(t, self.filter_name, self.filter.settings(), truth, dict(meta or {}))


# --------------------------------------------------------------------------------------------
# simulated observations (tests, benchmarks, demos)
# --------------------------------------------------------------------------------------------


def simulate_observations(
    n_steps: int = 100,
    dt: float = 4.5,
    *,
    omega_deg_s: Sequence[float] = (0.0, 0.0, 5.0),
    position0: Sequence[float] = (3.0, 0.0, 0.0),
    velocity0: Sequence[float] = (0.0, 0.0, 0.0),
    quat0: Sequence[float] = (0.0, 0.0, 0.0, 1.0),
    n_mean_motion: float = 0.0,
    lvlh_axes: str | np.ndarray | None = None,
    sigma_position: float = 0.01,
    sigma_attitude_deg: float = 1.0,
    missing: Sequence[int] = (),
    offset: Sequence[float] = (0.0, 0.0, 0.0),
    seed: int | np.random.Generator | None = 0,
) -> tuple[np.ndarray, list[Observation | None], TrackTruth]:
    """Observations of a target spinning at a constant body rate, with CW relative translation.

    Truth: ``q_{k+1} = q_k ⊗ q_Δ(ω dt)``, ``(d, ḋ)`` by the exact CW transition; observations
    ``D = d + N(0, σ_p² I)``, ``Q = q ⊗ exp(N(0, σ_θ² I))`` (body-frame noise).

    Parameters
    ----------
    n_steps, dt : int, float
        Number of steps and period (s). Defaults: 100 frames at 4.5 s (22.5° per frame at 5°/s,
        Paper 2's semi-physical run).
    omega_deg_s : (3,)
        Body rate, deg/s (Paper 2: ``(0, 0, 5)``).
    position0, velocity0, quat0 : array_like
        Initial relative state (sensor frame).
    n_mean_motion, lvlh_axes : float, str
        CW dynamics of the truth.
    sigma_position, sigma_attitude_deg : float
        Measurement noise 1σ (m, deg).
    missing : sequence of int
        Steps without an observation (``None``).
    offset : (3,) array_like
        Body-frame offset (m) of the observed reference point from the rotation centre: the
        observed position is ``d + R c`` (it circles the spin axis). Truth is the point of
        the spin axis nearest the reference point, ``d + R c_∥`` with ``c_∥`` the component
        of ``c`` along ``ω`` (the component the observations can resolve).
    seed : int or Generator
        Noise seed.

    Returns
    -------
    times : (K,) ndarray
    observations : list of Observation or None
    truth : TrackTruth
    """
    if int(n_steps) < 1 or not dt > 0:
        raise InputError(f"need n_steps >= 1 and dt > 0, got {n_steps}, {dt}")
    rng = np.random.default_rng(seed)
    K = int(n_steps)
    w = np.radians(np.asarray(omega_deg_s, dtype=np.float64).reshape(3))
    cw = ClohessyWiltshire(n_mean_motion, lvlh_axes=lvlh_axes)
    q = np.asarray(quat0, dtype=np.float64).reshape(4)
    q = q / np.linalg.norm(q)
    d = np.asarray(position0, dtype=np.float64).reshape(3)
    v = np.asarray(velocity0, dtype=np.float64).reshape(3)
    times = np.arange(K) * float(dt)
    P = np.zeros((K, 3))
    V = np.zeros((K, 3))
    Qs = np.zeros((K, 4))
    qd = quat_delta(w, dt)
    for k in range(K):
        P[k], V[k], Qs[k] = d, v, (q if q[3] >= 0 else -q)
        q = _qmul(q, qd)
        q = q / np.linalg.norm(q)
        d, v = cw.propagate(d, v, dt)
    noise_p = rng.normal(size=(K, 3)) * sigma_position
    noise_q = Rotation.from_rotvec(rng.normal(size=(K, 3)) * math.radians(sigma_attitude_deg))
    zq = _qmul(Qs, noise_q.as_quat())
    c = np.asarray(offset, dtype=np.float64).reshape(3)
    Rk = quat_to_matrix(Qs)
    ref = P + Rk @ c
    nw = float(np.linalg.norm(w))
    if nw > 0.0 and np.any(c != 0.0):
        u = w / nw
        P = P + Rk @ (u * float(u @ c))  # constant: R_k u = R_0 u for a body-fixed rate
    miss = {int(i) for i in missing}
    obs: list[Observation | None] = [
        None if k in miss else Observation(ref[k] + noise_p[k], zq[k]) for k in range(K)
    ]
    truth = TrackTruth(P, V, Qs, np.tile(w, (K, 1)))
    return times, obs, truth


# --------------------------------------------------------------------------------------------
# observers (scans → observations)
# --------------------------------------------------------------------------------------------


class Observer(Protocol):
    """Turns the scans of one frame into an :class:`Observation`.

    ``observe(k, scans, prior)``: ``scans`` maps sensor names (``""`` = primary camera) to
    ``(N, 3)`` points in that sensor's frame; ``prior`` is the predicted ``T_s_b`` or ``None``.
    Return ``None`` (or raise :class:`relnav.errors.RelnavError`) when no usable observation
    can be made — the tracker then predicts through and flags the step.
    """

    name: str

    def observe(
        self, k: int, scans: dict[str, np.ndarray], prior: np.ndarray | None
    ) -> Observation | None: ...


def _subsample(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    if n <= 0 or len(points) <= n:
        return points
    return points[np.sort(rng.choice(len(points), n, replace=False))]


class RegistrationObserver:
    """Observations from a frame-to-frame registration chain on one sensor's scans.

    **[interpretation]** Stand-in for Paper 2's contour-model observation when
    :mod:`relnav.fusion.reconstruction` is not used: the body frame ``b`` is the sensor frame
    at the first observed frame, with its origin at that scan's centroid ``c₀``
    (``T_s_b(0) = [I, c₀]``). Each later scan (source) is registered onto the previous good
    scan (target), initialized from the filter's prediction, and
    ``T_s_b(k) = T_{prev←k}⁻¹ T_s_b(prev)``. A registration whose status is not ``ok`` gives no
    observation. Quality = registration fitness.

    Parameters
    ----------
    method : str
        Registration method string (:func:`relnav.registration.get_registration`).
    sensor : str
        Which scan to use (``""`` = primary).
    max_points : int
        Random subsample per scan (seeded), 0 = all points.
    seed : int
        Subsampling seed.
    **options
        Passed to the registration factory.
    """

    def __init__(
        self,
        method: str = "icp-point",
        *,
        sensor: str = "",
        max_points: int = 4000,
        seed: int = 0,
        **options: Any,
    ) -> None:
        from relnav.registration import get_registration

        self.method = method
        self.reg = get_registration(method, **options)
        self.sensor = sensor
        self.max_points = int(max_points)
        self.rng = np.random.default_rng(seed)
        self.name = f"registration:{method}"
        self.n_failed = 0
        self._prev_pts: np.ndarray | None = None
        self._prev_T: np.ndarray | None = None

    def observe(
        self, k: int, scans: dict[str, np.ndarray], prior: np.ndarray | None
    ) -> Observation | None:
        pts = scans.get(self.sensor)
        if pts is None or len(pts) < 10:
            raise InputError(f"frame {k}: too few points from sensor {self.sensor or 'primary'}")
        pts = _subsample(np.asarray(pts, dtype=np.float64), self.max_points, self.rng)
        if self._prev_pts is None or self._prev_T is None:
            T = np.eye(4)
            T[:3, 3] = pts.mean(axis=0)
            self._prev_pts, self._prev_T = pts, T
            return Observation(T[:3, 3], np.array([0.0, 0.0, 0.0, 1.0]), 1.0)
        init = None if prior is None else self._prev_T @ invert(prior)
        res = self.reg.register(pts, self._prev_pts, init=init)
        if not res.ok:
            self.n_failed += 1
            raise InputError(f"frame {k}: registration {res.status}: {res.message}")
        T = invert(res.T_target_source) @ self._prev_T
        T[:3, :3] = project_to_so3(T[:3, :3])
        self._prev_pts, self._prev_T = pts, T
        q = Rotation.from_matrix(T[:3, :3]).as_quat()
        return Observation(T[:3, 3].copy(), q, float(res.fitness))

    @property
    def stats(self) -> dict[str, Any]:
        """Counters for the result metadata."""
        return {"registration_failed": self.n_failed}


class ContourObserver:
    """Paper 2's chain: CGA cross-source registration (LIDAR → camera), plane clustering and the
    contour model's per-frame observation (:func:`relnav.fusion.cross_source.
    cross_source_register`, :func:`relnav.fusion.clustering.cluster_and_project`,
    :class:`relnav.fusion.reconstruction.ContourModel`).

    The body frame is the contour model's ``B`` (axes of the camera frame at the first observed
    frame, origin at that frame's fused centroid) — the same convention as
    :class:`RegistrationObserver`. The filter's prediction is passed to the model as the
    registration start (``T_model_frame = T_M_B · T_s_b⁻¹`` with ``T_M_B = [I, b]``). Frames
    whose cross-source registration fails are tracked on the camera cloud alone
    (``fallback_camera_only=True``) or give no observation; a model rejection (quality 0) gives
    no observation. Needs the camera scan in every frame.

    Parameters
    ----------
    lidar : str
        Second-sensor name.
    m : int
        Samples of the CGA registration (paper 2: 15).
    seed : int
        Seed of the registration and the model (frame ``k`` uses ``seed + k``).
    fallback_camera_only : bool
        See above.
    cluster_options, model_options : dict, optional
        Passed to ``cluster_and_project`` and ``ContourModel``.
    """

    def __init__(
        self,
        *,
        lidar: str = "lidar",
        m: int = 15,
        seed: int = 0,
        fallback_camera_only: bool = True,
        cluster_options: dict[str, Any] | None = None,
        model_options: dict[str, Any] | None = None,
    ) -> None:
        from relnav.fusion.clustering import cluster_and_project
        from relnav.fusion.cross_source import cross_source_register
        from relnav.fusion.reconstruction import ContourModel

        self._register = cross_source_register
        self._cluster = cluster_and_project
        self.model = ContourModel(seed=seed, **(model_options or {}))
        self.cluster_options = dict(cluster_options or {})
        self.lidar = lidar
        self.m = int(m)
        self.seed = int(seed)
        self.fallback_camera_only = bool(fallback_camera_only)
        self.name = "contour"
        self.n_fusion_failed = 0
        self._last_R: np.ndarray | None = None

    @property
    def stats(self) -> dict[str, Any]:
        """Counters for the result metadata."""
        hist = self.model.history
        return {
            "fusion_failed": self.n_fusion_failed,
            "model_rejected": sum(not h.get("accepted", True) for h in hist),
            "model_points": int(self.model.points.shape[0]),
        }

    def observe(
        self, k: int, scans: dict[str, np.ndarray], prior: np.ndarray | None
    ) -> Observation | None:
        from relnav.geometry.se3 import transform_points

        cam = scans.get("")
        lid = scans.get(self.lidar)
        if cam is None or len(cam) == 0:
            raise InputError(f"frame {k}: no camera points")
        cloud = cam
        why = ""
        if lid is None or len(lid) == 0:
            why = f"no {self.lidar} scan"
        else:
            res = self._register(cam, lid, m=self.m, seed=self.seed + k)
            if res.ok:
                lid_c = transform_points(res.T_target_source, lid)
                cloud = self._cluster(cam, lid_c, **self.cluster_options).fused_points
            else:
                why = f"cross-source registration {res.status}: {res.message}"
        if why:
            self.n_fusion_failed += 1
            if not self.fallback_camera_only:
                raise InputError(f"frame {k}: {why}")
            log.info("frame %d: %s; using the camera cloud alone", k, why)
        init = None
        b = self.model.body_origin
        if prior is not None and b is not None:
            T_M_B = np.eye(4)
            T_M_B[:3, 3] = b
            init = T_M_B @ invert(prior)
        position, quat, quality = self.model.observe(cloud, init=init)
        if quality <= 0.0:
            reason = self.model.history[-1].get("reason", "rejected") if self.model.history else ""
            raise InputError(f"frame {k}: contour model: {reason}")
        R = self.model.last_covariance  # None → the filter's fixed noise
        # [interpretation] the frame merged last carries its pose error into the model, which
        # the following registrations inherit: that is the observer's drift since then
        drift, self._last_R = self._last_R, R
        return Observation(np.asarray(position), np.asarray(quat), float(quality), R=R, drift=drift)


def _default_observer(second: str | None, seed: int) -> Observer:
    if second is not None:
        try:
            return ContourObserver(lidar=second, seed=seed)
        except (ImportError, TypeError) as e:  # I1's modules absent or a different API
            log.info("contour-model observer unavailable (%s); using the registration chain", e)
    return RegistrationObserver(seed=seed)


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
    else:
        raise ConfigError(
            "gt_alignment must be 'mean', 'first', 'first-rotation' or 'none', got " + repr(how)
        )
    return T_gt @ A, A


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
    gt_alignment: Literal["mean", "first", "first-rotation", "none"] = "mean",
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
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
    gt_alignment : {"mean", "first", "first-rotation", "none"}
        How truth is expressed in the estimate's body frame (module docstring).
        ``"first-rotation"``: rotation from the first estimated frame (exact for the contour
        and registration observers, whose body axes are by definition the sensor axes at
        their first observation and which initialize the filter there), translation the mean
        offset.
    seed : int
        Seed of the observer's random choices (recorded in ``meta``).
    progress : callable, optional
        ``progress(done, total)``.
    **tracker_options
        Passed to :class:`Tracker` (``n_mean_motion``, ``orbit_radius_m``, ``q``, ``r`` …).
        With the UKF and the contour observer, ``centre_offset`` and ``observer_bias`` default
        to ``True`` (:class:`relnav.fusion.ukf.TwistorUKF`): its reference point is the first
        frame's centroid, which circles the spin axis, and its model drifts.

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
        obs_impl: Observer = _default_observer(second, seed)
    elif isinstance(observer, str):
        if observer == "contour":
            if second is None:
                raise InputError("the contour observer needs a second sensor (scans_<name>/)")
            obs_impl = ContourObserver(lidar=second, seed=seed)
        elif observer.startswith("registration"):
            _, _, method = observer.partition(":")
            obs_impl = RegistrationObserver(method or "icp-point", seed=seed)
        else:
            raise ConfigError(
                f"unknown observer {observer!r}: 'contour' or 'registration[:method]'"
            )
    else:
        obs_impl = observer

    if str(filter).lower() == "ukf" and isinstance(obs_impl, ContourObserver):
        # the contour model's reference point circles the spin axis and the model drifts
        tracker_options.setdefault("centre_offset", True)
        tracker_options.setdefault("observer_bias", True)
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
