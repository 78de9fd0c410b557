"""Stateful frame-to-frame odometry (:class:`Odometry`).

Convention (DESIGN §3): the current scan ``k+1`` (source) is registered onto the previous scan
``k`` (target); the step is ``T_k_k1 = T_target_source`` and the pose chain is
``T_world_sensor[k+1] = T_world_sensor[k] @ T_k_k1``. Paper 1's ``R*`` (maps ``P_k → P_{k+1}``)
is the inverse of this step; the estimators convert in one place, nowhere else.

A frame whose registration is ``degenerate`` or ``failed`` (or raises) is never dropped: it keeps
the **motion prior** (the last accepted step — constant velocity — by default, or the identity)
and is flagged in :class:`OdometryStep`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from relnav.errors import RelnavError
from relnav.geometry.rotations import rotation_angle
from relnav.geometry.se3 import invert
from relnav.registration.base import PreparedRegistration, Registration, get_registration
from relnav.registration.result import RegistrationResult
from relnav.types import Scan

__all__ = ["MotionPrior", "Odometry", "OdometryStep"]

log = logging.getLogger(__name__)

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
        ``"first"``, ``"ok"``, ``"degenerate"`` or ``"failed"``.
    n_points : int
        Points in the scan.
    time_s : float
        Wall-clock seconds spent on this frame (preparation + registration).
    """

    pose: np.ndarray
    step: np.ndarray
    result: RegistrationResult | None
    used_prior: bool
    status: str
    n_points: int
    time_s: float


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
    **method_options
        Options for :func:`relnav.registration.get_registration` when ``method`` is a string.
    """

    def __init__(
        self,
        method: str | Registration,
        *,
        initial_pose: np.ndarray | None = None,
        motion_prior: MotionPrior = "constant_velocity",
        gate_rotation_deg: float | None = None,
        gate_translation: float | None = None,
        **method_options: Any,
    ) -> None:
        self.registration = (
            get_registration(method, **method_options) if isinstance(method, str) else method
        )
        if motion_prior not in ("constant_velocity", "identity"):
            raise RelnavError(f"unknown motion prior {motion_prior!r}")
        self.motion_prior: MotionPrior = motion_prior
        self.gate_rotation = None if gate_rotation_deg is None else np.radians(gate_rotation_deg)
        self.gate_translation = gate_translation
        self.pose = np.eye(4) if initial_pose is None else np.array(initial_pose, dtype=float)
        self.last_step = np.eye(4)
        self._prev_points: np.ndarray | None = None
        self._prev_prepared: Any = None
        self.n_frames = 0

    @property
    def prior_step(self) -> np.ndarray:
        """The step the motion prior predicts for the next frame."""
        return self.last_step.copy() if self.motion_prior == "constant_velocity" else np.eye(4)

    def register_frame(self, scan: Scan | np.ndarray) -> OdometryStep:
        """Register a new scan onto the previous one and advance the pose chain."""
        points = scan.points if isinstance(scan, Scan) else np.asarray(scan, dtype=np.float64)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        t0 = time.perf_counter()
        prepared = None
        prepare_error = ""
        if isinstance(self.registration, PreparedRegistration):
            try:
                prepared = self.registration.prepare(points)
            except Exception as e:  # a bad scan must not stop the run
                log.warning("frame %d: preparation failed: %s", self.n_frames, e)
                prepare_error = f"{type(e).__name__}: {e}"
        if self.n_frames == 0:
            out = OdometryStep(
                self.pose.copy(),
                np.eye(4),
                None,
                False,
                "first",
                len(points),
                time.perf_counter() - t0,
            )
        else:
            result = self._register(points, prepared, prepare_error)
            if result.status == "ok":
                self._apply_gate(result)
            used_prior = result.status != "ok"
            step = self.prior_step if used_prior else result.T_target_source
            if used_prior:
                log.info(
                    "frame %d: registration %s (%s); using the %s motion prior",
                    self.n_frames,
                    result.status,
                    result.message,
                    self.motion_prior,
                )
            else:
                self.last_step = step.copy()
            self.pose = self.pose @ step
            out = OdometryStep(
                self.pose.copy(),
                step.copy(),
                result,
                used_prior,
                result.status,
                len(points),
                time.perf_counter() - t0,
            )
        self._prev_points = points
        self._prev_prepared = prepared
        self.n_frames += 1
        return out

    def _apply_gate(self, result: RegistrationResult) -> None:
        """Reject (in place) a step too far from the motion prior."""
        if self.gate_rotation is None and self.gate_translation is None:
            return
        d = invert(self.prior_step) @ result.T_target_source
        d_rot = rotation_angle(d[:3, :3])
        d_t = float(np.linalg.norm(result.T_target_source[:3, 3] - self.prior_step[:3, 3]))
        if (self.gate_rotation is not None and d_rot > self.gate_rotation) or (
            self.gate_translation is not None and d_t > self.gate_translation
        ):
            result.status = "failed"
            result.message = (
                f"step rejected by the motion gate (Δrot {np.degrees(d_rot):.1f}°, "
                f"Δt {d_t:.3g} m from the prior)"
            )
            result.info["gated"] = True

    def _register(
        self, points: np.ndarray, prepared: Any, prepare_error: str
    ) -> RegistrationResult:
        if prepare_error:
            return RegistrationResult(status="failed", message=prepare_error)
        try:
            if prepared is not None and self._prev_prepared is not None:
                return self.registration.register_prepared(  # type: ignore[union-attr]
                    prepared, self._prev_prepared, init=self.prior_step
                )
            if prepared is None and isinstance(self.registration, PreparedRegistration):
                return RegistrationResult(status="failed", message="previous frame unusable")
            return self.registration.register(points, self._prev_points, init=self.prior_step)
        except Exception as e:  # never let one frame stop the run; flag it
            log.warning("frame %d: registration raised %s: %s", self.n_frames, type(e).__name__, e)
            return RegistrationResult(status="failed", message=f"{type(e).__name__}: {e}")
