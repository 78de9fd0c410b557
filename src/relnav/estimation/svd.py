"""Non-recursive reference estimator: Kabsch/Umeyama (SVD) on all correspondences.

``T_target_source = argmin Σ_u w_u ‖R b_u + t − a_u‖²`` with ``b_u = src_pts[src_idx[u]]`` and
``a_u = tgt_pts[tgt_idx[u]]`` (no frame inversion needed: the source is mapped onto the target
directly). Weights: ``"none"`` (default) or ``"inverse"`` ``w_u = 1 / max(m_scale·d_u, m_min)``,
i.e. the inverse of the recursive filters' adaptive noise scale ``M_u`` (§D.3).

Degeneracy: fewer than ``min_correspondences`` (default 3) or collinear points →
``"degenerate"``; coplanar points fix a rigid transform and are accepted unless
``reject_coplanar=True`` (which applies the same test as the recursive filters).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.estimation._recursive import (
    _check_positive,
    residual_covariance,
)
from relnav.estimation.base import Estimate, options_repr, register_estimator
from relnav.estimation.prepared import usable_correspondences
from relnav.geometry.se3 import umeyama
from relnav.matching.correspondences import Correspondences

__all__ = ["SVDEstimator"]


@register_estimator("svd", "Kabsch/Umeyama SVD on all correspondences (reference)")
class SVDEstimator:
    """Kabsch/Umeyama reference estimator.

    Parameters
    ----------
    weights : {"none", "inverse"}
        Per-correspondence weights (see module docstring).
    m_scale, m_min : float
        ``M_u = max(m_scale·d_u, m_min)`` for ``weights="inverse"``.
    min_correspondences : int
        Default 3.
    collinear_tol, coplanar_tol : float
        Relative singular-value thresholds (see
        :func:`~relnav.estimation._recursive.check_geometry`).
    reject_coplanar : bool
        Flag coplanar correspondences as degenerate too (default False).
    covariance : {"residual", "none"}
        ``residual`` (default): Gauss–Newton twist covariance (left perturbation, target frame)
        from the post-fit residuals; zero for exact correspondences.
    """

    name = "svd"

    def __init__(
        self,
        *,
        weights: Literal["none", "inverse"] = "none",
        m_scale: float = 10.0,
        m_min: float = 1e-3,
        min_correspondences: int = 3,
        collinear_tol: float = 1e-3,
        coplanar_tol: float = 1e-3,
        reject_coplanar: bool = False,
        covariance: Literal["residual", "none"] = "residual",
    ) -> None:
        if weights not in ("none", "inverse"):
            raise ConfigError(f"svd: weights must be 'none' or 'inverse', got {weights!r}")
        if covariance not in ("residual", "none"):
            raise ConfigError(f"svd: covariance must be 'residual' or 'none', got {covariance!r}")
        if int(min_correspondences) != min_correspondences or min_correspondences < 3:
            raise ConfigError(f"svd: min_correspondences must be ≥ 3, got {min_correspondences!r}")
        self.weights = weights
        self.m_scale = _check_positive("m_scale", m_scale)
        self.m_min = _check_positive("m_min", m_min)
        self.min_correspondences = int(min_correspondences)
        self.collinear_tol = _check_positive("collinear_tol", collinear_tol, allow_zero=True)
        self.coplanar_tol = _check_positive("coplanar_tol", coplanar_tol, allow_zero=True)
        self.reject_coplanar = bool(reject_coplanar)
        self.covariance_mode = covariance

    def options(self) -> dict[str, Any]:
        """All options (for logging/reproducibility)."""
        return {
            "weights": self.weights,
            "m_scale": self.m_scale,
            "m_min": self.m_min,
            "min_correspondences": self.min_correspondences,
            "collinear_tol": self.collinear_tol,
            "coplanar_tol": self.coplanar_tol,
            "reject_coplanar": self.reject_coplanar,
            "covariance": self.covariance_mode,
        }

    def __repr__(self) -> str:
        return options_repr(self)

    def estimate(self, src_pts: np.ndarray, tgt_pts: np.ndarray, corr: Correspondences) -> Estimate:
        """Kabsch/Umeyama ``T_target_source`` (``target ≈ T @ source``).

        Parameters and return as :meth:`RecursiveEstimator.estimate
        <relnav.estimation._recursive.RecursiveEstimator.estimate>`; ``info`` has ``rmse`` (m)
        and, when weighted, ``weights``. Data problems never raise (flagged status, identity).
        """
        prep, flagged = usable_correspondences(
            self, src_pts, tgt_pts, corr, self.coplanar_tol if self.reject_coplanar else None
        )
        if flagged is not None:
            return flagged
        n = prep.a.shape[0]
        w = None
        if self.weights == "inverse":
            w = 1.0 / np.maximum(self.m_scale * prep.d, self.m_min)
        T, rmse = umeyama(prep.b, prep.a, w)
        cov = residual_covariance(T, prep.b, prep.a) if self.covariance_mode == "residual" else None
        return Estimate(
            T_target_source=T,
            covariance=cov,
            n_used=n,
            status="ok",
            converged=True,
            info={"estimator": self.name, "rmse": rmse, "weights": self.weights},
        )
