"""Multiplicative quaternion EKF — the baseline of Paper 2 (ALGORITHMS.md §G.7).

Standard MEKF (Lefferts, Markley, Shuster 1982) in the form of Kang et al. (2021), Paper 2's
reference [57], on the same state and measurement as :class:`relnav.filtering.ukf.TwistorUKF`:
nominal ``d, ḋ`` (sensor frame), ``q`` (``R_sensor_body``, xyzw), ``ω`` (body, rad/s).

* Error state (12): ``[δd, δḋ, δθ, δω]`` with ``q_true = q ⊗ [½δθ, 1]`` (body-frame attitude
  error). ALGORITHMS.md orders it ``[δθ, δω, δr, δv]``; the order here matches the UKF's
  physical components (only the layout of :attr:`covariance` differs).
* Predict: ``q ← q ⊗ q_Δ(ωΔt)``; ``ω`` constant **[interpretation: Kang et al. also estimate
  inertia ratios with Euler's equations; the lab target spins at a constant rate]**;
  translation by the CW transition (or Euler, as the UKF). Error dynamics
  ``δθ̇ = −[ω×]δθ + δω``. ``jacobian="first-order"`` (default, as §G.7): ``F = I + Δt A``;
  ``jacobian="exact"``: ``F_θθ = exp(−[ω×]Δt)``, ``F_θω = ∫₀^Δt exp(−[ω×]s) ds`` and the CW
  transition matrix for translation. ``P ← F P Fᵀ + Q``.
* Update: residual ``[D − d, 2·vec(q⁻¹ ⊗ Q)]`` (sign fixed so ``w ≥ 0``),
  ``H = [[I, 0, 0, 0], [0, 0, I, 0]]``, standard gain, reset ``q ← q ⊗ [½δθ, 1]`` normalized.
  ``covariance_update="joseph"`` (default) or ``"standard"``. No covariance reset Jacobian
  (standard MEKF practice).

References
----------
Lefferts, Markley, Shuster, *Kalman filtering for spacecraft attitude estimation*, J. Guidance
5(5), 1982. Paper 2 ref. [57] (Kang et al. 2021).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.filtering.dynamics import TranslationModel
from relnav.filtering.noise import InitialUncertainty, MeasurementNoise, ProcessNoise
from relnav.filtering.pose_filter import (
    PAPER2_RATE_HZ,
    PoseFilter,
    UpdateInfo,
    _sym,
    canon_q,
    quat_delta,
)
from relnav.geometry.dualquat import qmul
from relnav.geometry.rotations import hat, rotvec_to_matrix

__all__ = ["QuaternionEKF"]

Jacobian = Literal["first-order", "exact"]


def _gamma(w: np.ndarray, dt: float) -> np.ndarray:
    """``∫₀^dt exp(−[ω×]s) ds`` (3, 3)."""
    W = hat(w)
    a = float(np.linalg.norm(w))
    if a * dt < 1e-8:
        return dt * np.eye(3) - 0.5 * dt * dt * W
    return (
        dt * np.eye(3)
        - (1.0 - math.cos(a * dt)) / a**2 * W
        + (a * dt - math.sin(a * dt)) / a**3 * (W @ W)
    )


class QuaternionEKF(PoseFilter):
    """Multiplicative quaternion EKF with CW translation (the same API as ``TwistorUKF``).

    Parameters
    ----------
    n_mean_motion, dt, q, r, p0, position0, velocity0, quat0, omega0, translation_model,
    lvlh_axes, gate_probability, gate_patience
        As for :class:`relnav.filtering.ukf.TwistorUKF`.
    jacobian : {"first-order", "exact"}
        Discretization of the error dynamics (module docstring).
    covariance_update : {"joseph", "standard"}

    Examples
    --------
    >>> ekf = QuaternionEKF(dt=4.5, omega0=[0, 0, np.radians(5)])
    >>> ekf.predict()
    >>> ekf.covariance.shape
    (12, 12)
    """

    name = "ekf"
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
        jacobian: Jacobian = "first-order",
        covariance_update: Literal["joseph", "standard"] = "joseph",
        gate_probability: float | None = None,
        gate_patience: int | None = None,
    ) -> None:
        if jacobian not in ("first-order", "exact"):
            raise ConfigError(f"jacobian must be 'first-order' or 'exact', got {jacobian!r}")
        if covariance_update not in ("standard", "joseph"):
            raise ConfigError(
                f"covariance_update must be 'standard' or 'joseph', got {covariance_update!r}"
            )
        self.jacobian: Jacobian = jacobian
        self.covariance_update = covariance_update
        super().__init__(
            n_mean_motion,
            dt,
            q,
            r,
            p0=p0,
            position0=position0,
            velocity0=velocity0,
            quat0=quat0,
            omega0=omega0,
            translation_model=translation_model,
            lvlh_axes=lvlh_axes,
            gate_probability=gate_probability,
            gate_patience=gate_patience,
        )

    def transition_jacobian(self, dt: float) -> np.ndarray:
        """Error-state transition ``F`` ``(12, 12)`` for a step of ``dt`` at the current ``ω``."""
        F = np.eye(12)
        w = self._w
        if self.jacobian == "first-order":
            F[0:6, 0:6] = np.eye(6) + dt * self.dynamics.A()
            F[6:9, 6:9] = np.eye(3) - dt * hat(w)
            F[6:9, 9:12] = dt * np.eye(3)
        else:
            F[0:6, 0:6] = self.dynamics.stm(dt)
            F[6:9, 6:9] = rotvec_to_matrix(w * dt).T
            F[6:9, 9:12] = _gamma(w, dt)
        return F

    def _predict(self, dt: float) -> None:
        F = self.transition_jacobian(dt)  # at the prior ω (constant over the step)
        self._q = canon_q(qmul(self._q, quat_delta(self._w, dt)))
        self._d, self._v = self.dynamics.propagate(self._d, self._v, dt)
        self._P = _sym(F @ self._P @ F.T + np.diag(self._phys_process_var(dt)))

    def _update(self, p: np.ndarray, q_meas: np.ndarray, R: np.ndarray) -> UpdateInfo:
        dq = canon_q(qmul(self._q * np.array([-1.0, -1.0, -1.0, 1.0]), q_meas))
        nu = np.concatenate([p - self._d, 2.0 * dq[:3]])
        H = np.zeros((6, 12))
        H[0:3, 0:3] = np.eye(3)
        H[3:6, 6:9] = np.eye(3)
        P = self._P
        S = _sym(H @ P @ H.T + R)
        nis = float(nu @ np.linalg.solve(S, nu))
        reason = self._gate(nis, 6)
        if reason:
            return UpdateInfo(False, nis, nu, reason, S, R)
        K = np.linalg.solve(S, H @ P).T
        dx = K @ nu
        if self.covariance_update == "joseph":
            IKH = np.eye(12) - K @ H
            P = IKH @ P @ IKH.T + K @ R @ K.T
        else:
            P = P - K @ S @ K.T
        self._d = self._d + dx[0:3]
        self._v = self._v + dx[3:6]
        dth = dx[6:9]
        self._q = canon_q(qmul(self._q, np.r_[0.5 * dth, 1.0]))
        self._w = self._w + dx[9:12]
        self._P = _sym(P)
        return UpdateInfo(True, nis, nu, "", S, R)

    def settings(self) -> dict[str, Any]:
        """Configuration as plain values."""
        out = super().settings()
        out.update(jacobian=self.jacobian, covariance_update=self.covariance_update)
        return out
