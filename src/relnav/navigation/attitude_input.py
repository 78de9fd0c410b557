"""The chaser's measured attitude as the navigator's rotation prior (optional input).

A chaser knows its own inertial attitude (star tracker, gyros) far better than a LIDAR step can
tell it. Between two scans at ``t₀`` and ``t₁`` the measured attitudes ``R_W_sensor`` give the
sensor's rotation over the step, ``ΔR = R(t₀)ᵀ R(t₁)`` (sensor frame). While the target's
attitude is inertially fixed over the step (a static or slowly rotating target), the step of
``T_target_sensor`` has that same rotation, whatever the chaser's attitude control does
between frames (jitter, thruster firings): the constant-velocity model cannot predict those.

:func:`aided_prediction` turns ``ΔR`` into a rotation measurement of the motion filter's
predicted pose, ``R_meas = R_prev ΔR`` (``R_prev`` the filter's pose of the previous frame),
with noise ``2σ² I₃`` (two independent attitude samples of 1σ ``σ`` per axis) plus the previous
pose's own rotation covariance **[interpretation: the previous pose is treated as independent
of the prediction, which over-states the noise slightly; conservative]**. The registration then
starts from, and is regularised by, the aided prediction.

Limitation: a tumbling target rotates in the inertial frame; its rotation over a step is not in
``ΔR``. Give the input only when the target's rotation per frame is below ``σ`` (or accept the
bias).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from relnav.errors import InputError
from relnav.navigation.motion import ConstantVelocityFilter

__all__ = ["AttitudeInput", "aided_prediction"]


@dataclass(frozen=True)
class AttitudeInput:
    """Measured inertial attitudes of the sensor.

    Attributes
    ----------
    times : (N,) float64
        Strictly increasing sample times, s (the scans' clock).
    rotations : (N, 3, 3) float64
        ``R_W_sensor`` at those times.
    sigma_deg : float
        1σ per axis of each attitude sample, degrees (> 0).
    source : str
        Where the samples came from (a file name), for the run's record.
    """

    times: np.ndarray = field(repr=False)
    rotations: np.ndarray = field(repr=False)
    sigma_deg: float
    source: str = ""

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=np.float64).reshape(-1)
        R = np.asarray(self.rotations, dtype=np.float64).reshape(-1, 3, 3)
        if len(t) != len(R) or len(t) < 2:
            raise InputError(f"attitude input: {len(t)} times for {len(R)} rotations (>= 2)")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(R))):
            raise InputError("attitude input: non-finite times or rotations")
        if np.any(np.diff(t) <= 0):
            raise InputError("attitude input: times must increase strictly")
        if not (math.isfinite(self.sigma_deg) and self.sigma_deg > 0):
            raise InputError(f"attitude input: sigma_deg must be > 0, got {self.sigma_deg}")
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "rotations", R)

    @classmethod
    def from_tum(cls, path: str | Path, sigma_deg: float) -> AttitudeInput:
        """Read a TUM file (``t x y z qx qy qz qw``; the position columns are ignored)."""
        from relnav.io.trajectories import read_tum

        t, T = read_tum(path)
        return cls(t, T[:, :3, :3], float(sigma_deg), source=Path(path).name)

    def at(self, t: float) -> np.ndarray | None:
        """``R_W_sensor`` at ``t`` (s), interpolated on the geodesic between the two nearest
        samples; ``None`` outside the samples' span (no extrapolation)."""
        from relnav.geometry.rotations import matrix_to_rotvec, rotvec_to_matrix

        tt = self.times
        if not (tt[0] <= t <= tt[-1]):
            return None
        i = int(np.clip(np.searchsorted(tt, t, side="right") - 1, 0, len(tt) - 2))
        a = (t - tt[i]) / (tt[i + 1] - tt[i])
        R0, R1 = self.rotations[i], self.rotations[i + 1]
        w = np.asarray(matrix_to_rotvec(R0.T @ R1), dtype=np.float64).reshape(3)
        return R0 @ np.asarray(rotvec_to_matrix(a * w)).reshape(3, 3)

    def step(self, t0: float, t1: float) -> np.ndarray | None:
        """The sensor's rotation from ``t0`` to ``t1``, ``R(t₀)ᵀ R(t₁)`` (sensor frame), or
        ``None`` when either time is outside the samples."""
        R0, R1 = self.at(t0), self.at(t1)
        return None if R0 is None or R1 is None else R0.T @ R1

    def describe(self) -> dict[str, object]:
        """For ``run.json``."""
        return {
            "source": self.source,
            "samples": len(self.times),
            "sigma_deg": self.sigma_deg,
            "span_s": [float(self.times[0]), float(self.times[-1])],
        }


def aided_prediction(
    motion: ConstantVelocityFilter, attitude: AttitudeInput, t: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """Update the motion filter's prediction at ``t`` with the attitude input's step rotation.

    ``motion`` is the navigator's :class:`~relnav.navigation.motion.ConstantVelocityFilter`
    after ``predict(t)``. Returns the aided prediction ``(T_pred, P_pp)`` (as ``predict``
    returns them) or ``None`` when the input does not cover the step.
    """
    dR = attitude.step(motion.t, t)
    if dR is None:
        return None
    R_meas = motion.pose[:3, :3] @ dR
    s2 = math.radians(attitude.sigma_deg) ** 2
    return motion.observe_rotation(R_meas, 2.0 * s2 * np.eye(3) + motion.P[3:6, 3:6])
