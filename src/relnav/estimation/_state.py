"""Paper 1's 12-number filter state ``x = [r11 … r33, tx ty tz]`` and transforms: identity state,
state ↔ transform, the measurement matrix ``H_u``, the SO(3) output projection and the one
place where the filter's ``T_source_target`` becomes ``T_target_source``
(:func:`filter_to_target_source`). Frame convention in :mod:`relnav.estimation._recursive`.
"""

from __future__ import annotations

import logging

import numpy as np

from relnav.errors import InputError
from relnav.geometry.se3 import from_rt, invert

__all__ = [
    "filter_to_target_source",
    "identity_state",
    "measurement_matrix",
    "project_state",
    "state_to_transform",
    "transform_to_state",
]

log = logging.getLogger(__name__)


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
