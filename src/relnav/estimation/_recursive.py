"""Shared machinery of Paper 1's recursive estimators (ALGORITHMS §D.1–D.5).

Everything the four filters (``kalman``, ``hinf``, ``alphabeta``, ``sdre``) have in common lives
here: input checks, the processing order, the adaptive factor ``M_u``, the measurement matrix
``H_u``, small numba helpers for the 12-state updates, the degeneracy test, the SO(3) output
projection, the covariance mapping, and the base class :class:`RecursiveEstimator`.

Frame convention (converted in exactly one place, :func:`filter_to_target_source`)
------------------------------------------------------------------------------------
Paper 1's filter estimates ``x = [r11 r12 r13 r21 r22 r23 r31 r32 r33 tx ty tz]`` with
``p_{k+1} = R p_k + t`` (eq. 2). In odometry the *target* is the previous scan ``P_k`` and the
*source* the current scan ``P_{k+1}``, so for correspondence ``u`` the filter uses
``a_u = tgt_pts[tgt_idx[u]]`` (a point of ``P_k``) to build ``H_u`` and the measurement is
``ψ_u = b_u = src_pts[src_idx[u]]`` (a point of ``P_{k+1}``). The filter's own output is therefore
``T_source_target`` (``= T_{k+1,k}``); the estimators return its inverse ``T_target_source``.

Layout: this module holds the base class :class:`RecursiveEstimator` and re-exports the pieces,
each in its own module: :mod:`._state` (state ↔ transform, ``H_u``), :mod:`._prepare`
(correspondences, degeneracy, ``M_u``), :mod:`._covariance`, :mod:`._kernels` (numba 12-state
helpers) and :mod:`._nlms` (the NLMS-type sweep).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from relnav.errors import ConfigError
from relnav.estimation._covariance import residual_covariance, state_covariance_to_twist
from relnav.estimation._kernels import _cholesky as _cholesky
from relnav.estimation._kernels import _h_apply as _h_apply
from relnav.estimation._kernels import _ht_apply as _ht_apply
from relnav.estimation._kernels import _inv3 as _inv3
from relnav.estimation._kernels import _p_ht as _p_ht
from relnav.estimation._kernels import _spd_inverse as _spd_inverse
from relnav.estimation._nlms import _nlms_kernel as _nlms_kernel
from relnav.estimation._nlms import nlms_options as nlms_options
from relnav.estimation._nlms import run_nlms
from relnav.estimation._prepare import (
    AdaptiveMode,
    Prepared,
    adaptive_factors,
    check_geometry,
    prepare_correspondences,
)
from relnav.estimation._state import (
    filter_to_target_source,
    identity_state,
    measurement_matrix,
    project_state,
    state_to_transform,
    transform_to_state,
)
from relnav.estimation.base import Estimate, EstimateStatus
from relnav.geometry.se3 import transform_points
from relnav.matching.correspondences import Correspondences

__all__ = [
    "AdaptiveMode",
    "Prepared",
    "RecursiveEstimator",
    "adaptive_factors",
    "check_geometry",
    "filter_to_target_source",
    "identity_state",
    "measurement_matrix",
    "prepare_correspondences",
    "project_state",
    "run_nlms",
    "residual_covariance",
    "state_covariance_to_twist",
    "state_to_transform",
    "transform_to_state",
]

log = logging.getLogger(__name__)

DEFAULT_MAX_PASSES = 200
"""Cap on the sweeps over Ω of the coherent filters (they stop earlier when converged)."""

CovarianceMode = Literal["filter", "residual", "none"]

# ---------------------------------------------------------------------------------------------
# State <-> transform
# ---------------------------------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# Correspondence preparation, adaptive factor and degeneracy
# ---------------------------------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# Covariances
# ---------------------------------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# numba helpers for the 12-state updates (H_u = hs·[I₃ ⊗ aᵀ, I₃])
# ---------------------------------------------------------------------------------------------


# ---------------------------------------------------------------------------------------------
# Base class
# ---------------------------------------------------------------------------------------------


def _check_positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    v = float(value)
    ok = (v >= 0.0) if allow_zero else (v > 0.0)
    if not (np.isfinite(v) and ok):
        raise ConfigError(f"{name} must be {'≥' if allow_zero else '>'} 0, got {value!r}")
    return v


@dataclass
class _RunOutput:
    """What a filter kernel run returns to the base class."""

    x: np.ndarray
    P: np.ndarray | None
    passes: int
    last_sweep_step: float
    info: dict[str, Any]


class RecursiveEstimator:
    """Base of the four recursive estimators (common options and the estimate pipeline).

    Parameters (keyword-only, shared by all filters)
    ------------------------------------------------
    paper_literal : bool
        Use the equations as printed in Paper 1 (§D.2) instead of the coherent reading (§D.3–D.5).
    adaptive : {"per_match", "sum", "none"} or None
        Adaptive factor ``M`` (§D.3). None → ``"per_match"`` (coherent) or ``"sum"`` (literal,
        eq. 11 as printed).
    m_scale, m_min : float
        ``M_u = max(m_scale·d_u, m_min)`` (Paper 1: 10; clamp 1e-3).
    refit_t : bool
        Replace the filter's translation by ``mean(b − R a)`` after projection (§D.5).
    projection : {"data", "frobenius"}, optional
        How the 3×3 block ``R̂`` becomes a rotation (:func:`project_state`). ``"data"`` (default
        of the coherent filters, **[interpretation]**): ``R = polar(R̂ C)`` with ``C`` the
        scatter of the used target points weighted by ``1/M_u``, and ``t`` chosen so that the
        projected transform predicts the filter's point at the weighted centroid.
        ``"frobenius"`` (default with ``paper_literal=True``): ``R = polar(R̂)``, ``t`` keeps the
        filter's prediction at the unweighted centroid. Without centring (``center=False``,
        e.g. ``paper_literal=True``) ``t = x[9:12]`` as the filter has it.
        Why: the filters estimate an affine map; a converged filter is the (``1/M_u``-weighted)
        affine least-squares fit, whose Frobenius projection is NOT the rigid least-squares fit
        when the points are spread anisotropically, and whose raw ``t`` carries the affine
        block's error ``(R̂ − R) ā`` (ā tens of metres away in odometry) and depends on the
        coordinate origin. Measured on sim-voyager (fixed noiseless model cloud, 60 frames,
        the same SHOT + GCC correspondences, ``benchmarks/paper1_estimators_same_corr.py``):
        affine fit + Frobenius projection T_error 5.3 %, + consistent ``t`` 3.6 %, + data
        projection 0.59 % (= Kabsch weighted by ``1/M_u``; unweighted Kabsch 1.07 %).
    warm_start : bool
        Start from the previous successful pair's estimate instead of the identity (§D.3
        alternative). The estimator object keeps that state; :meth:`reset` clears it.
    n_passes : int, optional
        Maximum number of sweeps over Ω. Default: 200 for the coherent filters (iterate until
        converged, the paper's "number of iterations for each filter"), 1 with
        ``paper_literal=True``. Sweeps stop as soon as the state changes by at most ``tol``
        (2-norm) over a whole sweep; ``converged`` and ``info["passes"]`` report it.
    tol : float
        Sweep-change tolerance (default 1e-9; state in centred coordinates: rotation block
        dimensionless, translation in metres).
    min_correspondences : int
        Fewer → ``status="degenerate"`` (default 4, §D.3).
    collinear_tol, coplanar_tol : float
        Relative singular-value thresholds of :func:`check_geometry`.
    covariance : {"filter", "residual", "none"}
        ``filter``: map the 12×12 state covariance (Kalman, H∞ only);
        ``residual``: Gauss–Newton covariance from the post-fit residuals.
    center : bool, optional
        Run the filter on centred points ``a − ā``, ``b − b̄`` and map back with
        ``t = t_c + b̄ − R̂ ā`` (``R̂`` the raw 3×3 block, before projection; ``P`` mapped by the
        same linear map). **[interpretation]** Default: ``True`` for the coherent filters,
        ``False`` with ``paper_literal=True``. Paper 1 writes the filters on raw coordinates;
        there, the conditioning depends on where the target is in the sensor frame: with the
        target tens of metres away, one sweep of αβ/SDRE barely leaves the identity and
        Kalman/H∞'s prior couples rotation and translation (on ``sim-voyager`` every
        filter's trajectory stays at the first pose, T_error ≈ 100 %). Centring is the same model
        ``p_{k+1} = R p_k + t`` in translated coordinates, so the estimate no longer depends on
        the target's position. ``center=False`` reproduces the raw-coordinate behaviour.
    divergence_limit : float
        ``status="failed"`` when ``max|x[:9]| > divergence_limit`` or
        ``max|x[9:]| > divergence_limit·(1 + max|a|, |b|)`` (diverged filter; relevant for the
        literal αβ). Default 1e3.
    """

    name = "recursive"
    _has_state_covariance = False
    _default_covariance: CovarianceMode = "residual"

    def __init__(
        self,
        *,
        paper_literal: bool = False,
        adaptive: AdaptiveMode | None = None,
        m_scale: float = 10.0,
        m_min: float = 1e-3,
        refit_t: bool = False,
        projection: Literal["data", "frobenius"] | None = None,
        warm_start: bool = False,
        n_passes: int | None = None,
        tol: float = 1e-9,
        min_correspondences: int = 4,
        collinear_tol: float = 1e-3,
        coplanar_tol: float = 1e-3,
        covariance: CovarianceMode | None = None,
        center: bool | None = None,
        divergence_limit: float = 1e3,
    ) -> None:
        if adaptive is None:
            adaptive = "sum" if paper_literal else "per_match"
        if adaptive not in ("per_match", "sum", "none"):
            raise ConfigError(f"adaptive must be 'per_match', 'sum' or 'none', got {adaptive!r}")
        cov = self._default_covariance if covariance is None else covariance
        if cov not in ("filter", "residual", "none"):
            raise ConfigError(f"covariance must be 'filter', 'residual' or 'none', got {cov!r}")
        if cov == "filter" and not self._has_state_covariance:
            raise ConfigError(f"estimator {self.name!r} has no state covariance; use 'residual'")
        if n_passes is None:
            n_passes = 1 if paper_literal else DEFAULT_MAX_PASSES
        if isinstance(n_passes, bool) or int(n_passes) != n_passes or n_passes < 1:
            raise ConfigError(f"n_passes must be an integer ≥ 1, got {n_passes!r}")
        if projection is None:
            projection = "frobenius" if paper_literal else "data"
        if projection not in ("data", "frobenius"):
            raise ConfigError(f"projection must be 'data' or 'frobenius', got {projection!r}")
        if int(min_correspondences) != min_correspondences or min_correspondences < 1:
            raise ConfigError(f"min_correspondences must be ≥ 1, got {min_correspondences!r}")
        self.paper_literal = bool(paper_literal)
        self.adaptive: AdaptiveMode = adaptive
        self.m_scale = _check_positive("m_scale", m_scale)
        self.m_min = _check_positive("m_min", m_min)
        self.refit_t = bool(refit_t)
        self.projection = projection
        self.warm_start = bool(warm_start)
        self.n_passes = int(n_passes)
        self.tol = _check_positive("tol", tol, allow_zero=True)
        self.min_correspondences = int(min_correspondences)
        self.collinear_tol = _check_positive("collinear_tol", collinear_tol, allow_zero=True)
        self.coplanar_tol = _check_positive("coplanar_tol", coplanar_tol, allow_zero=True)
        self.covariance_mode: CovarianceMode = cov
        self.center = (not self.paper_literal) if center is None else bool(center)
        self.divergence_limit = _check_positive("divergence_limit", divergence_limit)
        self._prev_state: np.ndarray | None = None

    # -- to be implemented by the filters ------------------------------------------------------

    def _run(self, x0: np.ndarray, a: np.ndarray, b: np.ndarray, m: np.ndarray) -> _RunOutput:
        raise NotImplementedError

    def _options(self) -> dict[str, Any]:
        return {}

    def _measurement_variance(self, m: np.ndarray) -> np.ndarray | None:
        """Per-match measurement variance ``M_u σ_v²`` (m²) of the filter model, if it has one."""
        sigma_v = getattr(self, "sigma_v", None)
        return None if sigma_v is None else m * sigma_v**2

    # -- public --------------------------------------------------------------------------------

    def reset(self) -> None:
        """Forget the warm-start state."""
        self._prev_state = None

    def options(self) -> dict[str, Any]:
        """All options of this estimator (for logging/reproducibility)."""
        base = {
            "paper_literal": self.paper_literal,
            "adaptive": self.adaptive,
            "m_scale": self.m_scale,
            "m_min": self.m_min,
            "refit_t": self.refit_t,
            "projection": self.projection,
            "warm_start": self.warm_start,
            "n_passes": self.n_passes,
            "tol": self.tol,
            "min_correspondences": self.min_correspondences,
            "collinear_tol": self.collinear_tol,
            "coplanar_tol": self.coplanar_tol,
            "covariance": self.covariance_mode,
            "center": self.center,
            "divergence_limit": self.divergence_limit,
        }
        base.update(self._options())
        return base

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.options().items())
        return f"{type(self).__name__}({opts})"

    def estimate(self, src_pts: np.ndarray, tgt_pts: np.ndarray, corr: Correspondences) -> Estimate:
        """Estimate ``T_target_source`` (``target ≈ T @ source``) from correspondences.

        Parameters
        ----------
        src_pts : (N, 3) float64
            Source cloud (odometry: current scan ``P_{k+1}``), metres.
        tgt_pts : (M, 3) float64
            Target cloud (odometry: previous scan ``P_k``), metres.
        corr : Correspondences
            ``src_idx`` into ``src_pts``, ``tgt_idx`` into ``tgt_pts``, ``distance`` =
            descriptor distance (drives ``M_u``).

        Returns
        -------
        Estimate
            ``T_target_source`` (identity unless ``status == "ok"``), twist covariance (see
            ``covariance`` option), ``n_used``, ``status``, ``converged`` and ``info`` with
            ``rmse`` (m, on the used correspondences), ``x_raw`` (12-state before projection,
            filter frame ``T_source_target``), ``orthogonality_error`` (‖R̂ − R‖_F), ``passes``.

        Raises
        ------
        InputError
            Malformed arrays or out-of-range indices. Data problems (too few / degenerate /
            non-finite correspondences) never raise: they give ``status`` ``"degenerate"`` or
            ``"failed"`` with the identity.
        """
        prep, problem = prepare_correspondences(src_pts, tgt_pts, corr)
        if prep is None:
            return self._flagged(problem, len(corr))
        n = prep.a.shape[0]
        geo_kw = {
            "min_count": self.min_correspondences,
            "collinear_tol": self.collinear_tol,
            "coplanar_tol": self.coplanar_tol,
        }
        reason = check_geometry(prep.a, **geo_kw)
        if not reason:
            reason = check_geometry(prep.b, **geo_kw)
        if reason:
            return self._flagged("degenerate: " + reason, n)
        m = adaptive_factors(prep.d, self.adaptive, scale=self.m_scale, m_min=self.m_min)
        x0 = self._prev_state.copy() if (self.warm_start and self._prev_state is not None) else None
        if x0 is None:
            x0 = identity_state()
        a_mean = prep.a.mean(axis=0)
        b_mean = prep.b.mean(axis=0)
        if self.center:
            x0 = x0.copy()
            x0[9:12] += x0[:9].reshape(3, 3) @ a_mean - b_mean  # t_c = t − b̄ + R ā
            out = self._run(
                x0, np.ascontiguousarray(prep.a - a_mean), np.ascontiguousarray(prep.b - b_mean), m
            )
            out.x[9:12] += b_mean - out.x[:9].reshape(3, 3) @ a_mean
            if out.P is not None:
                G = np.eye(12)
                for i in range(3):
                    G[9 + i, 3 * i : 3 * i + 3] = -a_mean
                out.P = G @ out.P @ G.T
        else:
            out = self._run(x0, prep.a, prep.b, m)
        x = out.x
        if not np.isfinite(x).all() or (out.P is not None and not np.isfinite(out.P).all()):
            return self._flagged("failed: filter state became non-finite", n, info=out.info)
        extent = 1.0 + max(float(np.abs(prep.a).max()), float(np.abs(prep.b).max()))
        lim = self.divergence_limit
        if np.abs(x[:9]).max() > lim or np.abs(x[9:]).max() > lim * extent:
            info = dict(out.info, x_raw=x.tolist())
            return self._flagged("failed: filter state diverged", n, info=info)
        metric = a_ref = None
        a_w = a_mean
        if self.projection == "data":
            w = 1.0 / m
            a_w = (w[:, None] * prep.a).sum(axis=0) / w.sum()
            ac = prep.a - a_w
            metric = (w[:, None] * ac).T @ ac
        if self.center:
            a_ref = a_w  # t consistent with the projected R (origin-invariant)
        R, t = project_state(
            x, refit_t=self.refit_t, a_mean=a_mean, b_mean=b_mean, metric=metric, a_ref=a_ref
        )
        T = filter_to_target_source(R, t)
        res = transform_points(T, prep.b) - prep.a
        rmse = float(np.sqrt(np.mean(np.sum(res * res, axis=1))))
        cov: np.ndarray | None = None
        if self.covariance_mode == "filter" and out.P is not None:
            b_cov = None
            var = self._measurement_variance(m)
            if self.refit_t and var is not None:
                b_cov = float(var.sum()) / n**2 * np.eye(3)  # Cov(b̄) under V_u = var_u I₃
            cov = state_covariance_to_twist(
                x,
                out.P,
                refit_t=self.refit_t,
                a_mean=a_mean,
                b_mean=b_mean,
                b_mean_cov=b_cov,
                metric=metric,
                a_ref=a_ref,
            )
        elif self.covariance_mode == "residual":
            cov = residual_covariance(T, prep.b, prep.a)
        if self.warm_start:
            self._prev_state = np.concatenate([R.reshape(9), t])
        converged = self.n_passes == 1 or out.last_sweep_step <= self.tol
        info: dict[str, Any] = {
            "estimator": self.name,
            "paper_literal": self.paper_literal,
            "adaptive": self.adaptive,
            "rmse": rmse,
            "x_raw": x.tolist(),
            "orthogonality_error": float(np.linalg.norm(x[:9].reshape(3, 3) - R)),
            "passes": out.passes,
            "converged": bool(converged),
            "last_sweep_step": out.last_sweep_step,
            "m_mean": float(m.mean()),
        }
        info.update(out.info)
        return Estimate(
            T_target_source=T,
            covariance=cov,
            n_used=n,
            status="ok",
            converged=bool(converged),
            info=info,
        )

    def _flagged(self, problem: str, n: int, info: dict[str, Any] | None = None) -> Estimate:
        status: EstimateStatus = "failed" if problem.startswith("failed") else "degenerate"
        msg = problem.split(": ", 1)[1] if ": " in problem else problem
        log.debug("%s: %s (%s)", self.name, status, msg)
        full = {"estimator": self.name, "message": msg}
        if info:
            full.update(info)
        full["n_correspondences"] = n
        return Estimate(
            T_target_source=np.eye(4),
            covariance=None,
            n_used=0,
            status=status,
            converged=False,
            info=full,
        )


# ---------------------------------------------------------------------------------------------
# Shared NLMS-type kernel (coherent αβ and SDRE)
# ---------------------------------------------------------------------------------------------
