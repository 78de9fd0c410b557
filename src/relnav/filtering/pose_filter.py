"""Common base of Paper 2's pose filters (:class:`PoseFilter`): state (``d, ḋ, q, ω`` in the sensor
frame ``s`` / body frame ``b``), CW propagation settings, accessors, NIS/NEES and the update record
(:class:`UpdateInfo`), with the small quaternion helpers both filters use.

Implemented by :class:`relnav.filtering.ukf.TwistorUKF` and
:class:`relnav.filtering.ekf.QuaternionEKF`; conventions in :mod:`relnav.filtering.ukf`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from relnav.errors import ConfigError, InputError
from relnav.filtering.dynamics import ClohessyWiltshire, TranslationModel
from relnav.filtering.noise import InitialUncertainty, MeasurementNoise, ProcessNoise, _coerce
from relnav.geometry.dualquat import (
    qmul,
)
from relnav.geometry.rotations import quat_to_matrix

__all__ = ["PAPER2_RATE_HZ", "PoseFilter", "UpdateInfo", "quat_delta"]

log = logging.getLogger(__name__)


PAPER2_RATE_HZ = 0.22
"""Paper 2 Table 3 sensor acquisition frequency, Hz."""


@dataclass(frozen=True)
class UpdateInfo:
    """Outcome of one measurement update.

    Attributes
    ----------
    accepted : bool
        The measurement was applied.
    nis : float
        Normalized innovation squared ``νᵀ P_zz⁻¹ ν`` (NaN when not computed).
    innovation : ndarray
        Innovation in the filter's measurement coordinates (empty when rejected early).
    message : str
        Reason for a rejection.
    innovation_cov : ndarray
        ``S = H P Hᵀ + R`` in the same coordinates (empty when rejected early).
    meas_cov : ndarray
        The ``R`` part of ``S`` (empty when rejected early).
    """

    accepted: bool
    nis: float = float("nan")
    innovation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    message: str = ""
    innovation_cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    meas_cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def log_likelihood(self) -> float:
        """Gaussian log-likelihood of the innovation, ``−½ (νᵀ S⁻¹ ν + log det 2πS)`` (NaN when
        no innovation was computed): what a bank of filters weighs its members by."""
        nu, S = self.innovation, self.innovation_cov
        if nu.size == 0 or S.shape != (nu.size, nu.size) or not np.all(np.isfinite(nu)):
            return float("nan")
        sign, logdet = np.linalg.slogdet(2.0 * np.pi * S)
        if sign <= 0:
            return float("nan")
        return float(-0.5 * (nu @ np.linalg.solve(S, nu) + logdet))


def quat_delta(omega: np.ndarray, dt: float) -> np.ndarray:
    """``q_Δ = [ω/|ω| sin(½|ω|Δt), cos(½|ω|Δt)]`` (xyzw, Paper 2 eq. 31) of rate(s) ``(..., 3)``.

    Body rates in rad/s, ``dt`` in s; exact for a constant rate over the step.
    """
    th = np.asarray(omega, dtype=np.float64) * float(dt)
    a = np.linalg.norm(th, axis=-1, keepdims=True)
    half = 0.5 * a
    # sin(a/2)/a with its series near 0
    k = np.where(a < 1e-8, 0.5 - a * a / 48.0, np.sin(half) / np.where(a < 1e-8, 1.0, a))
    return np.concatenate([k * th, np.cos(half)], axis=-1)


def canon_q(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def _rotvec_between(q: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """Body-frame rotation vector of ``q⁻¹ ⊗ q_true`` (rad)."""
    dq = qmul(q * np.array([-1.0, -1.0, -1.0, 1.0]), q_true)
    return Rotation.from_quat(canon_q(dq)).as_rotvec()


def _sym(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + P.T)


def _sqrt_psd(M: np.ndarray) -> np.ndarray:
    """A square root ``S`` with ``S Sᵀ = M`` (Cholesky, jitter, eigen-clipping fallback)."""
    M = _sym(M)
    try:
        return np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        pass
    scale = max(float(np.trace(M)) / M.shape[0], 1e-300)
    jitter = 1e-12 * scale
    for _ in range(4):
        try:
            return np.linalg.cholesky(M + jitter * np.eye(M.shape[0]))
        except np.linalg.LinAlgError:
            jitter *= 100.0
    w, V = np.linalg.eigh(M)
    log.warning("covariance not positive definite (min eigenvalue %.3g); clipping", w.min())
    w = np.clip(w, 1e-12 * max(w.max(), 1e-300), None)
    return V * np.sqrt(w)


def _check_vec(x: Any, n: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (n,):
        raise InputError(f"{name} must have shape ({n},), got {a.shape}")
    return a


# --------------------------------------------------------------------------------------------
# common base
# --------------------------------------------------------------------------------------------


class PoseFilter:
    """Common state handling of :class:`TwistorUKF` and :class:`relnav.filtering.ekf.QuaternionEKF`.

    Nominal state: ``position`` ``d`` (m, sensor frame), ``velocity`` (m/s), ``quaternion``
    (xyzw, ``R_sensor_body``, ``w ≥ 0``), ``omega`` (rad/s, body frame). Subclasses implement
    ``_predict``, ``_update`` and the native covariance layout.
    """

    name = "base"
    dim = 12

    def __init__(
        self,
        n_mean_motion: float = 0.0,
        dt: float = 1.0 / PAPER2_RATE_HZ,
        q: ProcessNoise | Mapping[str, float] | None = None,
        r: MeasurementNoise | Mapping[str, float] | np.ndarray | None = None,
        *,
        p0: InitialUncertainty | Mapping[str, float] | None = None,
        position0: Any = None,
        velocity0: Any = None,
        quat0: Any = None,
        omega0: Any = None,
        translation_model: TranslationModel = "cw",
        lvlh_axes: str | np.ndarray | None = None,
        gate_probability: float | None = None,
        gate_patience: int | None = None,
    ) -> None:
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise ConfigError(f"nominal time step dt must be > 0 s, got {dt!r}")
        self.dt = dt
        self.dynamics = ClohessyWiltshire(
            n_mean_motion, lvlh_axes=lvlh_axes, model=translation_model
        )
        self.q_noise: ProcessNoise = _coerce(ProcessNoise, q, "q")
        self.R = self._measurement_cov(r)
        self.p0: InitialUncertainty = _coerce(InitialUncertainty, p0, "p0")
        if gate_probability is not None and not (0.0 < float(gate_probability) < 1.0):
            raise ConfigError(f"gate_probability must be in (0, 1), got {gate_probability!r}")
        self.gate_probability = None if gate_probability is None else float(gate_probability)
        if gate_patience is not None and not (
            isinstance(gate_patience, int | np.integer) and gate_patience >= 1
        ):
            raise ConfigError(f"gate_patience must be an integer >= 1, got {gate_patience!r}")
        self.gate_patience = None if gate_patience is None else int(gate_patience)
        self._gated_run = 0  # consecutive observations refused by the gate
        self._d = np.zeros(3)
        self._v = np.zeros(3)
        self._q = np.array([0.0, 0.0, 0.0, 1.0])
        self._w = np.zeros(3)
        self._P = np.eye(self.dim)
        self.initialize(
            position=np.zeros(3) if position0 is None else position0,
            quat=np.array([0.0, 0.0, 0.0, 1.0]) if quat0 is None else quat0,
            velocity=velocity0,
            omega=omega0,
        )

    # --- configuration helpers ---------------------------------------------------------------

    @staticmethod
    def _measurement_cov(r: Any) -> np.ndarray:
        if isinstance(r, np.ndarray | list | tuple) and not isinstance(r, Mapping):
            R = np.asarray(r, dtype=np.float64)
            if R.shape == (6,):
                R = np.diag(R)
            if R.shape != (6, 6) or not np.all(np.isfinite(R)):
                raise ConfigError(f"r must be a finite (6, 6) covariance, got shape {R.shape}")
            if np.linalg.eigvalsh(_sym(R)).min() <= 0.0:
                raise ConfigError("r must be positive definite")
            return _sym(R)
        R = _coerce(MeasurementNoise, r, "r").covariance()
        if np.any(np.diag(R) <= 0.0):
            raise ConfigError("measurement noise must be > 0 for position and attitude")
        return R

    def _phys_process_var(self, dt: float) -> np.ndarray:
        """Physical process variances ``(12,)`` ``[d, v, θ, ω]`` for a step of ``dt`` s: the
        random walks of :class:`ProcessNoise` and its accelerations held over the step."""
        qn = self.q_noise
        dt = abs(dt)
        s = dt / self.dt
        var = s * np.repeat(np.array([qn.position, qn.velocity, qn.attitude, qn.omega]) ** 2, 3)
        alpha = qn.angular_acceleration
        if qn.torque_free:
            # the estimated rate only: its covariance in the bound would feed back on itself
            alpha += qn.torque_free_share * float(self._w @ self._w) / math.sqrt(3.0)
        a = qn.acceleration
        held = np.array([0.5 * a * dt * dt, a * dt, 0.5 * alpha * dt * dt, alpha * dt])
        return var + np.repeat(held**2, 3)

    # --- state ------------------------------------------------------------------------------

    def initialize(
        self,
        position: Any,
        quat: Any,
        velocity: Any = None,
        omega: Any = None,
        p0: InitialUncertainty | Mapping[str, float] | None = None,
    ) -> None:
        """(Re)set the state and covariance.

        Parameters
        ----------
        position : (3,) array_like
            m, sensor frame.
        quat : (4,) array_like
            ``R_sensor_body`` (xyzw), normalized here.
        velocity, omega : (3,) array_like, optional
            m/s and rad/s (body); default zero.
        p0 : InitialUncertainty or dict, optional
            Initial 1σ (default: the constructor's).
        """
        d = _check_vec(position, 3, "position")
        q = _check_vec(quat, 4, "quat")
        v = np.zeros(3) if velocity is None else _check_vec(velocity, 3, "velocity")
        w = np.zeros(3) if omega is None else _check_vec(omega, 3, "omega")
        nq = float(np.linalg.norm(q))
        if not (np.all(np.isfinite(np.r_[d, q, v, w])) and nq > 0.0):
            raise InputError("initial state must be finite with a non-zero quaternion")
        if p0 is not None:
            self.p0 = _coerce(InitialUncertainty, p0, "p0")
        self._d, self._v, self._q, self._w = d.copy(), v.copy(), canon_q(q), w.copy()
        s = self.p0
        phys = np.repeat(np.array([s.position, s.velocity, s.attitude, s.omega]) ** 2, 3)
        self._P = self._native_from_phys_var(phys)
        self._on_reset()

    def _on_reset(self) -> None:
        """Hook: drop cached sigma points etc."""

    def _native_from_phys_var(self, phys_var: np.ndarray) -> np.ndarray:
        """Diagonal native covariance from physical variances ``[d, v, θ, ω]`` (12,)."""
        return np.diag(phys_var)

    @property
    def position(self) -> np.ndarray:
        """Target reference point in the sensor frame ``(3,)``, m."""
        return self._d.copy()

    @property
    def reference_position(self) -> np.ndarray:
        """The observed reference point in the sensor frame ``(3,)``, m (= ``position`` unless
        the filter estimates a centre offset)."""
        return self._d.copy()

    def predicted_reference(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Mean reference point ``(3,)`` and attitude ``(4,)`` xyzw predicted ``dt`` s ahead
        (the filter is not changed)."""
        dt = max(float(dt), 0.0)
        q = canon_q(qmul(self._q, quat_delta(self._w, dt)))
        return self.dynamics.propagate(self._d, self._v, dt)[0], q

    @property
    def velocity(self) -> np.ndarray:
        """Its velocity ``(3,)``, m/s (sensor frame)."""
        return self._v.copy()

    @property
    def quaternion(self) -> np.ndarray:
        """Attitude ``R_sensor_body`` as a unit quaternion ``(4,)`` xyzw, ``w ≥ 0``."""
        return self._q.copy()

    @property
    def omega(self) -> np.ndarray:
        """Body angular rate ``(3,)``, rad/s."""
        return self._w.copy()

    @property
    def covariance(self) -> np.ndarray:
        """Native error-state covariance (``dim × dim``)."""
        return self._P.copy()

    def pose_matrix(self) -> np.ndarray:
        """``T_sensor_body`` ``(4, 4)`` of the current estimate."""
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(self._q)
        T[:3, 3] = self._d
        return T

    def _phys_jacobian(self) -> np.ndarray:
        """``(12, dim)`` map from native error coordinates to ``[δd, δv, δθ, δω]``."""
        return np.eye(12)

    def physical_covariance(self) -> np.ndarray:
        """``(12, 12)`` covariance of ``[δd (m), δv (m/s), δθ (rad, body), δω (rad/s)]``."""
        J = self._phys_jacobian()
        return _sym(J @ self._P @ J.T)

    def state_sigma(self) -> dict[str, np.ndarray]:
        """1σ bounds: ``{"position" (m), "velocity" (m/s), "attitude" (rad), "omega" (rad/s)}``."""
        s = np.sqrt(np.clip(np.diag(self.physical_covariance()), 0.0, None))
        return {"position": s[:3], "velocity": s[3:6], "attitude": s[6:9], "omega": s[9:12]}

    def error_vector(self, position: Any, velocity: Any, quat_xyzw: Any, omega: Any) -> np.ndarray:
        """True minus estimated state ``(12,)`` ``[δd, δv, δθ, δω]`` (``δθ``: body rotation
        vector of ``q⁻¹ ⊗ q_true``)."""
        p = _check_vec(position, 3, "position")
        v = _check_vec(velocity, 3, "velocity")
        qt = _check_vec(quat_xyzw, 4, "quat_xyzw")
        w = _check_vec(omega, 3, "omega")
        return np.concatenate([p - self._d, v - self._v, _rotvec_between(self._q, qt), w - self._w])

    def nees(self, position: Any, velocity: Any, quat_xyzw: Any, omega: Any) -> float:
        """Normalized estimation error squared over the 12 physical components (χ²₁₂ if
        consistent)."""
        e = self.error_vector(position, velocity, quat_xyzw, omega)
        P = self.physical_covariance()
        return float(e @ np.linalg.solve(P, e))

    # --- steps ------------------------------------------------------------------------------

    def predict(self, dt: float | None = None) -> None:
        """Propagate the state and covariance by ``dt`` seconds (default: the nominal ``dt``).

        Raises
        ------
        InputError
            ``dt`` negative or not finite.
        """
        step = self.dt if dt is None else float(dt)
        if not math.isfinite(step) or step < 0.0:
            raise InputError(f"prediction step must be finite and >= 0 s, got {dt!r}")
        if step == 0.0:
            return
        self._predict(step)

    def update(
        self, position: Any, quat_xyzw: Any, R: np.ndarray | MeasurementNoise | None = None
    ) -> UpdateInfo:
        """Measurement update with an observed centroid position and attitude.

        Parameters
        ----------
        position : (3,) array_like
            Observed reference point in the sensor frame, m.
        quat_xyzw : (4,) array_like
            Observed attitude ``R_sensor_body`` (any sign, normalized here).
        R : (6, 6) array_like or MeasurementNoise, optional
            Covariance of ``[δp (m), δθ (rad)]`` for this measurement (default: the filter's).

        Returns
        -------
        UpdateInfo
            ``accepted=False`` (state unchanged) for a NaN/infinite observation or covariance, a
            zero quaternion, or an innovation failing the ``gate_probability`` χ² gate.

        Raises
        ------
        InputError
            Wrong shapes.
        """
        p = _check_vec(position, 3, "position")
        q = _check_vec(quat_xyzw, 4, "quat_xyzw")
        if R is None:
            Rm = self.R
        elif isinstance(R, MeasurementNoise):
            Rm = R.covariance()
        else:
            Rm = np.asarray(R, dtype=np.float64)
            if Rm.shape != (6, 6):
                raise InputError(f"R must have shape (6, 6), got {Rm.shape}")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
            return UpdateInfo(False, message="non-finite observation")
        if not np.all(np.isfinite(Rm)):
            return UpdateInfo(False, message="non-finite measurement covariance")
        nq = float(np.linalg.norm(q))
        if nq < 1e-9:
            return UpdateInfo(False, message="zero quaternion")
        try:
            info = self._update(p, q / nq, _sym(Rm))
            gated = not info.accepted and info.message.startswith("gated")
            self._gated_run = self._gated_run + 1 if gated else 0
            if gated and self.gate_patience and self._gated_run >= self.gate_patience:
                info = self._reacquire(p, q / nq, _sym(Rm), info)
            return info
        except np.linalg.LinAlgError as e:
            return UpdateInfo(False, message=f"singular innovation covariance ({e})")

    def _reacquire(
        self, p: np.ndarray, q: np.ndarray, R: np.ndarray, gated: UpdateInfo
    ) -> UpdateInfo:
        """**[interpretation]** ``gate_patience`` observations in a row refused by the gate
        mean that the filter, not the observations, has gone wrong (a gate is for isolated
        outliers; without this a diverged filter refuses every later observation and coasts
        for good). Its covariance is widened by ``2 · NIS / χ²`` (the observation then sits
        inside the gate) and the observation is used; until an observation passes the gate
        by itself, each one refused is taken so."""
        assert self.gate_probability is not None
        limit = float(chi2.ppf(self.gate_probability, gated.innovation.size))
        self._widen(2.0 * gated.nis / limit)
        info = self._update(p, q, R)
        if info.accepted:  # the run goes on until an observation passes the gate by itself
            info = replace(info, message=f"re-acquired after {self._gated_run} gated")
        return info

    def _widen(self, factor: float) -> None:
        """Scale the state covariance by ``factor`` (> 1)."""
        self._P = _sym(self._P * float(factor))

    def _gate(self, nis: float, m: int) -> str:
        if not math.isfinite(nis):
            return "non-finite innovation"
        if self.gate_probability is not None and nis > chi2.ppf(self.gate_probability, m):
            return f"gated (NIS {nis:.3g} > χ²_{m}({self.gate_probability}))"
        return ""

    def _predict(self, dt: float) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _update(
        self, p: np.ndarray, q: np.ndarray, R: np.ndarray
    ) -> UpdateInfo:  # pragma: no cover
        raise NotImplementedError

    def settings(self) -> dict[str, Any]:
        """The filter's configuration as plain values (for result metadata)."""
        return {
            "filter": self.name,
            "n_mean_motion": self.dynamics.n,
            "dt": self.dt,
            "translation_model": self.dynamics.model,
            "lvlh_axes": self.dynamics.M.tolist(),
            "q": asdict(self.q_noise),
            "r": np.sqrt(np.diag(self.R)).tolist(),
            "p0": asdict(self.p0),
            "gate_probability": self.gate_probability,
            "gate_patience": self.gate_patience,
        }

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(position={np.round(self._d, 4).tolist()}, "
            f"quat={np.round(self._q, 4).tolist()}, omega={np.round(self._w, 5).tolist()})"
        )
