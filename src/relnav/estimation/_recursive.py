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
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numba import njit

from relnav.errors import ConfigError, InputError
from relnav.estimation.base import Estimate, options_repr
from relnav.estimation.prepared import (
    Prepared,
    check_geometry,
    flagged_estimate,
    prepare_correspondences,
    usable_correspondences,
)
from relnav.geometry.rotations import hat
from relnav.geometry.se3 import from_rt, invert, transform_points
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

AdaptiveMode = Literal["per_match", "sum", "none"]
CovarianceMode = Literal["filter", "residual", "none"]

# ---------------------------------------------------------------------------------------------
# State <-> transform
# ---------------------------------------------------------------------------------------------


def identity_state() -> np.ndarray:
    """``x₀ = vec(I₃) ⊕ 0₃`` (12,), Paper 1's initialisation."""
    x = np.zeros(12)
    x[[0, 4, 8]] = 1.0
    return x


def transform_to_state(T: np.ndarray) -> np.ndarray:
    """12-state ``[R row-major (9), t (3)]`` of a ``4x4`` transform (filter frame)."""
    T = np.asarray(T, dtype=np.float64)
    return np.concatenate([T[:3, :3].reshape(9), T[:3, 3]])


def measurement_matrix(a: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """``H_u`` (3, 12) of §D.3 for a target point ``a`` (3,): ``H_u x = R a + t``.

    ``scale`` multiplies the whole matrix (``M`` in the printed eq. 10; 1 in the coherent
    interpretation).
    """
    a = np.asarray(a, dtype=np.float64).reshape(3)
    H = np.zeros((3, 12))
    for i in range(3):
        H[i, 3 * i : 3 * i + 3] = a
        H[i, 9 + i] = 1.0
    return scale * H


def _polar(M: np.ndarray) -> np.ndarray:
    """Nearest proper rotation(s) ``U diag(1, 1, det(U Vᵀ)) Vᵀ`` of (..., 3, 3) matrices."""
    U, _, Vt = np.linalg.svd(M)
    d = np.where(np.linalg.det(U @ Vt) >= 0, 1.0, -1.0)
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def project_state(
    x: np.ndarray,
    *,
    refit_t: bool = False,
    a_mean: np.ndarray | None = None,
    b_mean: np.ndarray | None = None,
    metric: np.ndarray | None = None,
    a_ref: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Output projection of §D.5: a rotation from ``R̂ = reshape(x[:9], 3, 3)`` and ``t``.

    Parameters
    ----------
    x : (12,) float64
        Raw filter state (filter frame, maps ``P_k`` → ``P_{k+1}``).
    refit_t : bool
        If True, ``t = mean(b) − R mean(a)`` (= ``mean_u(b_u − R a_u)``) instead of ``x[9:12]``
        **[interpretation, §D.5]**; needs ``a_mean`` and ``b_mean``.
    a_mean, b_mean : (3,) float64
        Centroids of the used target (``P_k``) and source (``P_{k+1}``) points, metres.
    metric : (3, 3) float64, optional
        ``None``: Frobenius projection ``R = polar(R̂)`` (Paper 1's reading). Else the
        (weighted) scatter ``C = Σ w_u (a_u − ā)(a_u − ā)ᵀ`` of the used target points: ``R =
        polar(R̂ C) = argmin_R Σ_u w_u ‖(R̂ − R)(a_u − ā)‖²``, the rotation whose predictions of
        the measurements are closest to the filter's **[interpretation]**.
    a_ref : (3,) float64, optional
        If given (and not ``refit_t``), ``t = x[9:12] + (R̂ − R) a_ref``: the projected transform
        predicts the same point as the filter at ``a_ref`` (the used points' centroid), which
        makes ``t`` independent of the coordinate origin. ``None``: ``t = x[9:12]``.

    Returns
    -------
    R : (3, 3) proper rotation (det +1).
    t : (3,) translation, metres.
    """
    M = np.asarray(x[:9], dtype=np.float64).reshape(3, 3)
    R = _polar(M if metric is None else M @ metric)
    if refit_t:
        if a_mean is None or b_mean is None:
            raise InputError("project_state: refit_t needs a_mean and b_mean")
        t = np.asarray(b_mean, dtype=np.float64) - R @ np.asarray(a_mean, dtype=np.float64)
    elif a_ref is not None:
        t = np.asarray(x[9:12], dtype=np.float64) + (M - R) @ np.asarray(a_ref, dtype=np.float64)
    else:
        t = np.asarray(x[9:12], dtype=np.float64).copy()
    return R, t


def filter_to_target_source(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """THE one place where the filter frame is converted to the estimator convention.

    The filter estimates ``T_source_target = [R | t]`` (``b = R a + t``, ``a`` ∈ target ``P_k``,
    ``b`` ∈ source ``P_{k+1}``); estimators return ``T_target_source = T_source_target⁻¹``.
    """
    return invert(from_rt(R, t))


def state_to_transform(
    x: np.ndarray,
    *,
    refit_t: bool = False,
    a_mean: np.ndarray | None = None,
    b_mean: np.ndarray | None = None,
    metric: np.ndarray | None = None,
    a_ref: np.ndarray | None = None,
) -> np.ndarray:
    """``T_target_source`` (4, 4) of a raw filter state ``x`` (projection + inversion)."""
    R, t = project_state(
        x, refit_t=refit_t, a_mean=a_mean, b_mean=b_mean, metric=metric, a_ref=a_ref
    )
    return filter_to_target_source(R, t)


# ---------------------------------------------------------------------------------------------
def adaptive_factors(
    d: np.ndarray, mode: AdaptiveMode, *, scale: float = 10.0, m_min: float = 1e-3
) -> np.ndarray:
    """Adaptive factor ``M_u`` per correspondence (eq. 11, §D.3).

    ``per_match`` (default, **[interpretation]**): ``M_u = scale·d_u``; ``sum`` (eq. 11 read
    literally): ``M = scale·Σ d_u`` for every match; ``none``: ``M = 1``. The first two are
    clamped to ``≥ m_min``.
    """
    d = np.asarray(d, dtype=np.float64)
    if mode == "per_match":
        m = scale * d
    elif mode == "sum":
        m = np.full(d.shape, scale * float(d.sum()))
    elif mode == "none":
        return np.ones(d.shape)
    else:  # pragma: no cover - validated in the constructor
        raise ConfigError(f"adaptive must be 'per_match', 'sum' or 'none', got {mode!r}")
    return np.maximum(m, m_min)


# ---------------------------------------------------------------------------------------------
# Covariances
# ---------------------------------------------------------------------------------------------


def _vee_first_order(dT: np.ndarray) -> np.ndarray:
    """First-order twist ``[ρ, φ]`` of transforms close to identity, ``(..., 4, 4) -> (..., 6)``."""
    R = dT[..., :3, :3]
    w = 0.5 * np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        axis=-1,
    )
    return np.concatenate([dT[..., :3, 3], w], axis=-1)


def state_covariance_to_twist(
    x: np.ndarray,
    P: np.ndarray,
    *,
    refit_t: bool = False,
    a_mean: np.ndarray | None = None,
    b_mean: np.ndarray | None = None,
    b_mean_cov: np.ndarray | None = None,
    metric: np.ndarray | None = None,
    a_ref: np.ndarray | None = None,
    rel_step: float = 1e-6,
) -> np.ndarray:
    """Map the 12×12 state covariance to the 6×6 twist covariance of ``T_target_source``.

    The map ``x ↦ T_target_source(x)`` (SO(3) projection of §D.5 with ``metric`` and
    ``a_ref`` as in :func:`project_state`, optional ``refit_t``, then inversion) is linearised
    **numerically** by central differences (step
    ``rel_step·max(1, |x_i|)``) with the **left** perturbation convention
    ``T = exp(δξ^) T̂`` , ``δξ = [ρ (m), φ (rad)]`` expressed in the target frame:
    ``J[:, i] = (vee(T(x+h e_i) T̂⁻¹) − vee(T(x−h e_i) T̂⁻¹)) / 2h`` (``vee`` to first order,
    exact for the derivative). Returns ``J P Jᵀ`` (symmetrised).

    The projection discards the non-rotational (stretch) directions of ``x[:9]``, so those parts
    of ``P`` do not appear in the result. With ``refit_t`` (``t = b̄ − R ā``) the rotation
    uncertainty is propagated into ``t``; ``b_mean_cov`` (3×3, covariance of ``b̄`` in the source
    frame) adds the noise of the refit itself, ``Rᵀ Σ_b̄ R`` on the ``ρ`` block (the correlation
    between ``b̄`` and ``R`` is neglected — it vanishes for a centred least-squares fit).
    """
    x = np.asarray(x, dtype=np.float64)
    T_hat = state_to_transform(
        x, refit_t=refit_t, a_mean=a_mean, b_mean=b_mean, metric=metric, a_ref=a_ref
    )
    F_hat = invert(T_hat)  # T_source_target
    h = rel_step * np.maximum(1.0, np.abs(x))
    X = np.repeat(x[None, :], 24, axis=0)
    idx = np.arange(12)
    X[idx, idx] += h
    X[12 + idx, idx] -= h
    # batch projection
    M = X[:, :9].reshape(24, 3, 3)
    R = _polar(M if metric is None else M @ np.asarray(metric, dtype=np.float64))
    if refit_t:
        t = np.asarray(b_mean)[None, :] - R @ np.asarray(a_mean)
    elif a_ref is not None:
        t = X[:, 9:12] + (M - R) @ np.asarray(a_ref, dtype=np.float64)
    else:
        t = X[:, 9:12]
    F = np.zeros((24, 4, 4))
    F[:, :3, :3] = R
    F[:, :3, 3] = t
    F[:, 3, 3] = 1.0
    dT = invert(F) @ F_hat  # T(x') T̂⁻¹ = F(x')⁻¹ F̂
    xi = _vee_first_order(dT)
    J = ((xi[:12] - xi[12:]) / (2.0 * h[:, None])).T  # (6, 12)
    C = J @ P @ J.T
    if refit_t and b_mean_cov is not None:
        R_hat = F_hat[:3, :3]
        C[:3, :3] += R_hat.T @ np.asarray(b_mean_cov, dtype=np.float64) @ R_hat
    return 0.5 * (C + C.T)


def residual_covariance(
    T_target_source: np.ndarray, src_used: np.ndarray, tgt_used: np.ndarray
) -> np.ndarray | None:
    """Gauss–Newton twist covariance of ``T_target_source`` from point residuals.

    Model ``a_i = exp(δξ^) T̂ b_i + e_i`` (left perturbation, target frame), Jacobian
    ``J_i = [I₃, −[T̂ b_i]×]``, isotropic noise ``σ² = Σ‖e_i‖² / (3n − 6)`` estimated from the
    residuals: ``C = σ² (Σ J_iᵀ J_i)⁻¹``. Exact correspondences give ``C = 0`` (honest: no
    residual). Returns None when ``n ≤ 2`` or the normal matrix is singular.
    """
    n = src_used.shape[0]
    if n <= 2:
        return None
    q = transform_points(T_target_source, src_used)
    e = tgt_used - q
    dof = max(3 * n - 6, 1)
    sigma2 = float(np.sum(e * e)) / dof
    qs = q.sum(axis=0)
    A = np.zeros((6, 6))
    A[:3, :3] = n * np.eye(3)
    A[:3, 3:] = -hat(qs)
    A[3:, :3] = hat(qs)
    A[3:, 3:] = np.sum(q * q) * np.eye(3) - q.T @ q  # Σ [q]×ᵀ[q]× = Σ (|q|² I − q qᵀ)
    if not np.isfinite(A).all():
        return None
    lam, V = np.linalg.eigh(A)
    if not lam[0] > 1e-14 * lam[-1]:
        return None
    C = (V / lam) @ V.T * sigma2
    return 0.5 * (C + C.T)


# ---------------------------------------------------------------------------------------------
# numba helpers for the 12-state updates (H_u = hs·[I₃ ⊗ aᵀ, I₃])
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def _h_apply(x: np.ndarray, a: np.ndarray, hs: float, out: np.ndarray) -> None:
    """``out = H x`` (3,) with ``H = hs·[I₃ ⊗ aᵀ, I₃]``."""
    for i in range(3):
        out[i] = hs * (x[3 * i] * a[0] + x[3 * i + 1] * a[1] + x[3 * i + 2] * a[2] + x[9 + i])


@njit(cache=True)
def _ht_apply(e: np.ndarray, a: np.ndarray, hs: float, out: np.ndarray) -> None:
    """``out = Hᵀ e`` (12,)."""
    for i in range(3):
        for j in range(3):
            out[3 * i + j] = hs * a[j] * e[i]
        out[9 + i] = hs * e[i]


@njit(cache=True)
def _p_ht(P: np.ndarray, a: np.ndarray, hs: float, out: np.ndarray) -> None:
    """``out = P Hᵀ`` (12, 3) for a (12, 12) matrix ``P`` (any, not only symmetric)."""
    for r in range(12):
        for i in range(3):
            out[r, i] = hs * (
                P[r, 3 * i] * a[0] + P[r, 3 * i + 1] * a[1] + P[r, 3 * i + 2] * a[2] + P[r, 9 + i]
            )


@njit(cache=True)
def _inv3(S: np.ndarray, out: np.ndarray) -> bool:
    """Inverse of a 3×3 matrix by cofactors; False if (near) singular."""
    c00 = S[1, 1] * S[2, 2] - S[1, 2] * S[2, 1]
    c01 = S[1, 2] * S[2, 0] - S[1, 0] * S[2, 2]
    c02 = S[1, 0] * S[2, 1] - S[1, 1] * S[2, 0]
    det = S[0, 0] * c00 + S[0, 1] * c01 + S[0, 2] * c02
    if not (abs(det) > 1e-300):
        return False
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[1, 0] = c01 * inv
    out[2, 0] = c02 * inv
    out[0, 1] = (S[0, 2] * S[2, 1] - S[0, 1] * S[2, 2]) * inv
    out[1, 1] = (S[0, 0] * S[2, 2] - S[0, 2] * S[2, 0]) * inv
    out[2, 1] = (S[0, 1] * S[2, 0] - S[0, 0] * S[2, 1]) * inv
    out[0, 2] = (S[0, 1] * S[1, 2] - S[0, 2] * S[1, 1]) * inv
    out[1, 2] = (S[0, 2] * S[1, 0] - S[0, 0] * S[1, 2]) * inv
    out[2, 2] = (S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]) * inv
    return True


@njit(cache=True)
def _cholesky(A: np.ndarray, L: np.ndarray) -> bool:
    """Lower Cholesky factor of a symmetric matrix; False if not positive definite."""
    n = A.shape[0]
    for i in range(n):
        for j in range(i + 1):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                if not (s > 0.0):
                    return False
                L[i, i] = np.sqrt(s)
            else:
                L[i, j] = s / L[j, j]
        for j in range(i + 1, n):
            L[i, j] = 0.0
    return True


@njit(cache=True)
def _spd_inverse(A: np.ndarray, L: np.ndarray, out: np.ndarray, Linv: np.ndarray) -> bool:
    """Inverse of a symmetric positive-definite matrix via Cholesky; False if not SPD.

    ``L`` and ``Linv`` are (n, n) workspaces (``Linv`` receives ``L⁻¹``, lower triangular).
    """
    n = A.shape[0]
    if not _cholesky(A, L):
        return False
    # Linv = L⁻¹ (lower), then out = Linvᵀ Linv
    for i in range(n):
        for j in range(i + 1, n):
            Linv[i, j] = 0.0
    for i in range(n):
        Linv[i, i] = 1.0 / L[i, i]
        for j in range(i):
            s = 0.0
            for k in range(j, i):
                s -= L[i, k] * Linv[k, j]
            Linv[i, j] = s / L[i, i]
    for i in range(n):
        for j in range(i + 1):
            s = 0.0
            for k in range(i, n):
                s += Linv[k, i] * Linv[k, j]
            out[i, j] = s
            out[j, i] = s
    return True


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
        the same SHOT + GCC correspondences, ``benchmarks/paper1/paper1_estimators_same_corr.py``):
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
        return options_repr(self)

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
        prep, flagged = usable_correspondences(self, src_pts, tgt_pts, corr, self.coplanar_tol)
        if flagged is not None:
            return flagged
        n = prep.a.shape[0]
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
        return flagged_estimate(self.name, problem, n, info)


# ---------------------------------------------------------------------------------------------
# Shared NLMS-type kernel (coherent αβ and SDRE)
# ---------------------------------------------------------------------------------------------


def nlms_options(
    name: str, paper_literal: bool, average: bool | None, normalise: str | None
) -> tuple[bool, str]:
    """Resolve the ``average`` and ``normalise`` options of the NLMS filters (αβ, SDRE).

    Defaults: the coherent reading averages the sweeps and normalises over the set;
    ``paper_literal`` keeps one sweep's last iterate and the per-sample normaliser.
    """
    avg = (not paper_literal) if average is None else bool(average)
    if normalise is None:
        normalise = "sample" if paper_literal else "set"
    if normalise not in ("set", "sample"):
        raise ConfigError(f"{name}: normalise must be 'set' or 'sample', got {normalise!r}")
    return avg, normalise


def run_nlms(
    x: np.ndarray,
    v: np.ndarray,
    A: np.ndarray,
    B: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    hs: np.ndarray,
    dt: float,
    n_passes: int,
    tol: float,
    average: bool,
    normalise: str,
) -> tuple[int, float]:
    """The NLMS-type sweeps of αβ and SDRE, in place on ``x`` (12,) and ``v`` (12,).

    ``normalise="sample"``: the per-sample NLMS step ``H_u⁺ e = H_uᵀ e / (hs_u² (‖a_u‖² + 1))``.
    ``"set"`` **[interpretation]**: the same update in coordinates whitened by the used points'
    scatter ``C = L Lᵀ`` (``ã = L⁻¹ a``, rotation block ``R̂ L``), with ONE normaliser for the
    whole set, ``max_u ‖ã_u‖² + 1``. Every update is still a contraction for ``α_u < 2``, but the
    sweeps' fixed point weights each match by its gain ``α_u`` only — the per-sample normaliser
    also weights it by ``1/(‖a_u‖² + 1)``, i.e. it discounts the points far from the centroid,
    which carry the rotation — and whitening makes every direction converge at the same rate.
    """
    if normalise == "sample" or A.shape[0] < 4:
        return _nlms_kernel(x, v, A, B, alpha, beta, hs, dt, n_passes, tol, average, 0.0)
    C = A.T @ A / A.shape[0]
    lam, V = np.linalg.eigh(C)
    if not lam[0] > 1e-12 * max(lam[-1], 1e-300):
        return _nlms_kernel(x, v, A, B, alpha, beta, hs, dt, n_passes, tol, average, 0.0)
    L = V * np.sqrt(lam)  # C = L Lᵀ
    Li = (V / np.sqrt(lam)).T  # L⁻¹
    Aw = np.ascontiguousarray(A @ Li.T)
    G = np.eye(12)  # x_w = G x : rotation rows R̂ → R̂ L
    Gi = np.eye(12)
    for i in range(3):
        G[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = L.T
        Gi[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = Li.T
    xw = G @ x
    vw = G @ v
    den = float((hs.max() ** 2) * ((Aw * Aw).sum(axis=1).max() + 1.0))
    passes, step = _nlms_kernel(xw, vw, Aw, B, alpha, beta, hs, dt, n_passes, tol, average, den)
    x[:] = Gi @ xw
    v[:] = Gi @ vw
    return passes, step


@njit(cache=True)
def _nlms_kernel(
    x: np.ndarray,
    v: np.ndarray,
    A: np.ndarray,
    B: np.ndarray,
    alpha: np.ndarray,
    beta: np.ndarray,
    hs: np.ndarray,
    dt: float,
    n_passes: int,
    tol: float,
    average: bool,
    den_set: float = 0.0,
) -> tuple[int, float]:
    """In place: ``x⁻ = x + dt v; r = H⁺(ψ − H x⁻); x = x⁻ + α_u r; v += (β_u/dt) r``.

    ``H = hs_u·[I₃ ⊗ aᵀ, I₃]`` so ``H⁺ = [I₃ ⊗ a, I₃]ᵀ / (hs_u (‖a‖² + 1))`` (minimum-norm
    state-space residual); ``den_set > 0`` replaces the per-sample normaliser
    ``hs_u² (‖a_u‖² + 1)`` by that constant. With ``average`` the sweep's output is the mean of
    its ``n`` iterates (the filter itself continues from its last iterate) and convergence is
    tested on that mean. Returns (passes run, 2-norm of the output's change over the last
    pass); ``x`` holds the output.
    """
    n = A.shape[0]
    hx = np.empty(3)
    e = np.empty(3)
    r = np.empty(12)
    xs = np.empty(12)
    xo = x.copy()
    xsum = np.empty(12)
    step = 0.0
    passes = 0
    for _p in range(n_passes):
        passes += 1
        xs[:] = xo
        xsum[:] = 0.0
        for u in range(n):
            a = A[u]
            h = hs[u]
            for k in range(12):
                x[k] += dt * v[k]
            _h_apply(x, a, h, hx)
            for i in range(3):
                e[i] = B[u, i] - hx[i]
            if den_set > 0.0:
                den = den_set
            else:
                den = h * h * (a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + 1.0)
            _ht_apply(e, a, h, r)
            for k in range(12):
                r[k] /= den
                x[k] += alpha[u] * r[k]
                v[k] += beta[u] / dt * r[k]
                xsum[k] += x[k]
        for k in range(12):
            xo[k] = xsum[k] / n if average else x[k]
        step = 0.0
        for k in range(12):
            step += (xo[k] - xs[k]) ** 2
        step = np.sqrt(step)
        if step <= tol:
            break
    x[:] = xo
    return passes, step
