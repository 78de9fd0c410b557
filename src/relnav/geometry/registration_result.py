"""The :class:`RegistrationResult` every registration method returns.

It lives here, below ``estimation`` and ``registration``, because the ICP solver
(:mod:`relnav.geometry.icp_solver`) returns it to both; :mod:`relnav.registration.result` is
its public import path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

__all__ = ["RegistrationResult", "RegistrationStatus"]

RegistrationStatus = Literal["ok", "flagged", "degenerate", "failed"]


@dataclass
class RegistrationResult:
    """Result of registering a source cloud onto a target cloud.

    Attributes
    ----------
    T_target_source : (4, 4) float64
        ``target ≈ T @ source``. Identity (or the initial guess) when ``status != "ok"``.
    covariance : (6, 6) float64 or None
        Covariance of the twist ``[rho (m), phi (rad)]`` when the method provides one.
    fitness : float
        Fraction of source points/correspondences that are inliers after alignment, in [0, 1].
    inlier_rmse : float
        RMS distance of the inliers after alignment, metres (NaN when unknown).
    n_correspondences : int
        Putative correspondences (before grouping / outlier rejection).
    n_inliers : int
        Correspondences used for the final estimate.
    converged : bool
        The method's own convergence flag.
    status : {"ok", "flagged", "degenerate", "failed"}
        ``flagged``: an estimate was produced but a check found it doubtful (set by
        :mod:`relnav.odometry.step_check`; methods themselves do not return it);
        ``degenerate``: geometry or correspondences cannot fix 6 DoF (too few, collinear,
        coplanar); ``failed``: the method ran but produced no usable estimate (or raised).
    timings : dict[str, float]
        Seconds per stage (e.g. ``{"normals": .., "describe": .., "match": .., "group": ..,
        "estimate": ..}``).
    message : str
        Human-readable reason for a non-``ok`` status.
    info : dict
        Method-specific extras (e.g. correspondence counts per stage).
    """

    T_target_source: np.ndarray = field(default_factory=lambda: np.eye(4))
    covariance: np.ndarray | None = None
    fitness: float = 0.0
    inlier_rmse: float = float("nan")
    n_correspondences: int = 0
    n_inliers: int = 0
    converged: bool = False
    status: RegistrationStatus = "ok"
    timings: dict[str, float] = field(default_factory=dict)
    message: str = ""
    info: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """``status == "ok"``."""
        return self.status == "ok"

    @property
    def total_time(self) -> float:
        """Sum of the stage timings, seconds."""
        return float(sum(self.timings.values()))
