"""Array aliases, the :class:`Scan` container and the frame/rotation conventions.

Conventions (decided once, see ``docs/DESIGN.md`` §3):

* Points are ``float64`` arrays of shape ``(N, 3)`` in metres.
* Descriptors are ``float32`` arrays of shape ``(K, D)``.
* Poses are ``4x4`` homogeneous matrices. ``T_a_b`` maps coordinates in frame ``b`` to frame
  ``a``: ``p_a = T_a_b @ p_b``.
* Registration returns ``T_target_source`` (``target ≈ T @ source``).
* Odometry: source = current scan ``k+1``, target = previous scan ``k``; the step is
  ``T_k_k1`` and ``T_world_sensor[k+1] = T_world_sensor[k] @ T_k_k1``.
* Quaternions are ``(x, y, z, w)`` (SciPy order); TUM files are ``t x y z qx qy qz qw``.
* Angles are radians inside the code, degrees in reports and CLI output.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["Descriptors", "Points", "Pose", "Scan"]

Points = npt.NDArray[np.float64]
"""``(N, 3)`` float64 point coordinates in metres."""

Pose = npt.NDArray[np.float64]
"""``(4, 4)`` float64 homogeneous rigid transform."""

Descriptors = npt.NDArray[np.float32]
"""``(K, D)`` float32 local descriptors."""


@dataclass
class Scan:
    """One scan of one sensor.

    Attributes
    ----------
    points : (N, 3) float64
        Points in the sensor frame, metres.
    time : float
        Scan time in seconds.
    timestamps : (N,) float64, optional
        Per-point times in seconds.
    intensity : (N,) float64, optional
        Per-point return intensity.
    normals : (N, 3) float64, optional
        Per-point unit normals in the sensor frame.
    sensor : dict
        Free-form sensor metadata (name, model, ...).
    """

    points: Points
    time: float = 0.0
    timestamps: np.ndarray | None = None
    intensity: np.ndarray | None = None
    normals: np.ndarray | None = None
    sensor: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.points = np.asarray(self.points, dtype=np.float64).reshape(-1, 3)

    def __len__(self) -> int:
        return int(self.points.shape[0])
