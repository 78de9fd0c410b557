"""Validation of the odometry-level options (motion prior, gates, initial pose, frame limit).

Every option is checked once, before the first frame, with the accepted values in the message
(:class:`relnav.errors.ConfigError`); the registration method checks its own options
(:func:`relnav.config.check_options` via :func:`relnav.registration.get_registration`).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field

from relnav.config import StrictModel, validate
from relnav.errors import ConfigError

__all__ = [
    "ODOMETRY_KEYS",
    "OdometryOptions",
    "check_max_frames",
    "check_odometry_options",
    "parse_initial_pose",
]

ODOMETRY_KEYS = (
    "motion_prior",
    "gate_rotation_deg",
    "gate_translation",
    "initial_pose",
    "step_check",
    "step_tolerance_m",
    "step_tolerance_deg",
)
"""Options handled by the odometry itself rather than by the registration method."""


class OdometryOptions(StrictModel):
    """Options of :class:`relnav.odometry.Odometry` itself.

    Attributes
    ----------
    motion_prior : {"constant_velocity", "identity"}
        Step kept by flagged frames.
    gate_rotation_deg : float, optional
        Innovation gate on the rotation, degrees, in ``(0, 180]``.
    gate_translation : float, optional
        Innovation gate on the translation, metres, ``> 0``.
    """

    motion_prior: Literal["constant_velocity", "identity"] = "constant_velocity"
    gate_rotation_deg: float | None = Field(default=None, gt=0, le=180, allow_inf_nan=False)
    gate_translation: float | None = Field(default=None, gt=0, allow_inf_nan=False)


def check_max_frames(max_frames: Any) -> int | None:
    """``None`` or a non-negative integer; :class:`ConfigError` otherwise."""
    if max_frames is None:
        return None
    if isinstance(max_frames, bool) or not isinstance(max_frames, int | np.integer):
        raise ConfigError(f"max_frames must be an integer >= 0, got {max_frames!r}")
    if max_frames < 0:
        raise ConfigError(f"max_frames must be >= 0, got {max_frames}")
    return int(max_frames)


def parse_initial_pose(value: Any) -> np.ndarray | str | None:
    """Check an initial pose: ``"gt"``, ``"identity"``/``None``, or a rigid ``T_world_sensor``.

    Parameters
    ----------
    value : str, None or array_like
        ``"gt"`` (the ground truth's first pose when there is one), ``"identity"`` or
        ``None``, or 16 (4x4) or 12 (3x4, last row ``0 0 0 1`` implied) numbers, row-major.

    Returns
    -------
    "gt", None or (4, 4) float64

    Raises
    ------
    ConfigError
        Anything else, a non-finite matrix, or a rotation block that is not a rotation.
    """
    if value is None:
        return None
    if isinstance(value, str):
        v = value.strip().lower()
        if v in ("gt", "identity"):
            return "gt" if v == "gt" else None
        raise ConfigError(
            f"initial_pose must be 'gt', 'identity' or 16 numbers (row-major 4x4), got {value!r}"
        )
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"initial_pose is not numeric: {value!r}") from None
    if a.size == 12:
        a = np.vstack([a.reshape(3, 4), [0.0, 0.0, 0.0, 1.0]])
    if a.size != 16:
        raise ConfigError(f"initial_pose needs 16 (4x4) or 12 (3x4) numbers, got {a.size}")
    T = a.reshape(4, 4)
    if not np.isfinite(T).all():
        raise ConfigError("initial_pose has NaN or infinite entries")
    R = T[:3, :3]
    if (
        np.abs(R.T @ R - np.eye(3)).max() > 1e-6
        or np.linalg.det(R) <= 0
        or np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-12
    ):
        raise ConfigError("initial_pose is not a rigid transform (R orthonormal, det +1, 0 0 0 1)")
    return T


def check_odometry_options(options: dict[str, Any]) -> OdometryOptions:
    """Validate the odometry-level options (:class:`OdometryOptions`), ConfigError if bad."""
    return validate(OdometryOptions, options, "odometry options")
