"""Covariances of Paper 1's estimators: the 12-state filter covariance mapped to a 6-DoF twist
covariance, and the residual-based covariance used when a filter has none.
"""

from __future__ import annotations

import logging

import numpy as np

from relnav.estimation._state import _polar, state_to_transform
from relnav.geometry.rotations import hat
from relnav.geometry.se3 import invert, transform_points

__all__ = [
    "residual_covariance",
    "state_covariance_to_twist",
]

log = logging.getLogger(__name__)


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
