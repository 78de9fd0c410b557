"""SE(3): homogeneous transforms, exp/log maps, application to points, Kabsch/Umeyama.

All transforms are ``4x4`` float64 matrices ``T = [[R, t], [0, 1]]``; ``T_a_b`` maps coordinates
in frame ``b`` to frame ``a``. Twists are ordered ``xi = [rho (3), phi (3)]`` (translation part
first, rotation vector second, as in Barfoot's *State Estimation for Robotics*).
"""

from __future__ import annotations

import numpy as np

from relnav.errors import InputError
from relnav.geometry.lie import invert_nb
from relnav.geometry.rotations import hat, matrix_to_rotvec, rotvec_to_matrix

__all__ = [
    "adjoint",
    "compose",
    "exp_se3",
    "from_rt",
    "invert",
    "kabsch",
    "log_se3",
    "random_transform",
    "relative",
    "transform_points",
    "umeyama",
]


def from_rt(R: np.ndarray | None = None, t: np.ndarray | None = None) -> np.ndarray:
    """Build a ``4x4`` transform from a rotation ``(3, 3)`` and a translation ``(3,)``."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if t is not None:
        T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def compose(*Ts: np.ndarray) -> np.ndarray:
    """Product ``T1 @ T2 @ ...`` of transforms (left to right)."""
    out = np.eye(4)
    for T in Ts:
        out = out @ T
    return out


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transform(s) ``T`` (``(4, 4)`` or ``(N, 4, 4)``), exact for SE(3)."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape == (4, 4):  # one transform: the compiled inverse, the same numbers
        return invert_nb(np.ascontiguousarray(T))
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    Rt = np.swapaxes(R, -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    out[..., 3, 3] = 1.0
    return out


def relative(T_w_a: np.ndarray, T_w_b: np.ndarray) -> np.ndarray:
    """``T_a_b = T_w_a⁻¹ T_w_b`` (works on stacks)."""
    return invert(T_w_a) @ T_w_b


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply ``T (4, 4)`` to points ``(N, 3)``: returns ``R p + t``."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return P @ T[:3, :3].T + T[:3, 3]


def _left_jacobian(phi: np.ndarray) -> np.ndarray:
    theta = float(np.linalg.norm(phi))
    K = hat(phi)
    if theta < 1e-8:
        return np.eye(3) + 0.5 * K + K @ K / 6.0
    return (
        np.eye(3)
        + (1.0 - np.cos(theta)) / theta**2 * K
        + (theta - np.sin(theta)) / theta**3 * K @ K
    )


def _left_jacobian_inv(phi: np.ndarray) -> np.ndarray:
    theta = float(np.linalg.norm(phi))
    K = hat(phi)
    if theta < 1e-8:
        return np.eye(3) - 0.5 * K + K @ K / 12.0
    half = theta / 2.0
    cot = half / np.tan(half)
    return np.eye(3) - 0.5 * K + (1.0 - cot) / theta**2 * K @ K


def exp_se3(xi: np.ndarray) -> np.ndarray:
    """Exponential map of a twist ``xi = [rho, phi]`` (6,) to a ``4x4`` transform."""
    xi = np.asarray(xi, dtype=np.float64).reshape(6)
    rho, phi = xi[:3], xi[3:]
    return from_rt(rotvec_to_matrix(phi), _left_jacobian(phi) @ rho)


def log_se3(T: np.ndarray) -> np.ndarray:
    """Logarithm of a ``4x4`` rigid transform: twist ``[rho, phi]`` (6,), ``|phi| <= π``."""
    T = np.asarray(T, dtype=np.float64)
    phi = matrix_to_rotvec(T[:3, :3])
    rho = _left_jacobian_inv(phi) @ T[:3, 3]
    return np.concatenate([rho, phi])


def adjoint(T: np.ndarray) -> np.ndarray:
    """Adjoint ``(6, 6)`` of ``T`` for twists ordered ``[ρ, φ]``: ``T exp(ξ) = exp(Ad_T ξ) T``,
    i.e. ``[[R, [t]×R], [0, R]]``."""
    R, t = T[:3, :3], T[:3, 3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[:3, 3:] = hat(t) @ R
    A[3:, 3:] = R
    return A


def random_transform(
    rng: np.random.Generator | int | None = None, max_translation: float = 1.0
) -> np.ndarray:
    """Random rigid transform: uniform rotation, translation uniform in ``±max_translation`` m."""
    from relnav.geometry.rotations import random_rotation

    rng = np.random.default_rng(rng)
    return from_rt(random_rotation(rng), rng.uniform(-max_translation, max_translation, 3))


def umeyama(
    src: np.ndarray,
    dst: np.ndarray,
    weights: np.ndarray | None = None,
    *,
    with_scale: bool = False,
) -> tuple[np.ndarray, float]:
    """Least-squares similarity/rigid transform mapping ``src`` onto ``dst`` (Umeyama 1991).

    Parameters
    ----------
    src, dst : (N, 3) float64
        Corresponding points; ``dst ≈ s R src + t``.
    weights : (N,) float64, optional
        Non-negative per-pair weights.
    with_scale : bool
        Estimate a scale ``s`` too (otherwise ``s = 1``, i.e. Kabsch/Arun).

    Returns
    -------
    T : (4, 4) float64
        ``T_dst_src`` (rotation scaled by ``s`` when ``with_scale``).
    rmse : float
        Root mean squared residual after alignment, metres.

    Raises
    ------
    InputError
        Fewer than 3 pairs, mismatched shapes or non-finite values.
    """
    src = np.asarray(src, dtype=np.float64).reshape(-1, 3)
    dst = np.asarray(dst, dtype=np.float64).reshape(-1, 3)
    if src.shape != dst.shape:
        raise InputError(f"umeyama: shapes differ {src.shape} vs {dst.shape}")
    if src.shape[0] < 3:
        raise InputError(f"umeyama: need at least 3 point pairs, got {src.shape[0]}")
    if not (np.isfinite(src).all() and np.isfinite(dst).all()):
        raise InputError("umeyama: non-finite coordinates")
    w = np.ones(src.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64)
    wsum = w.sum()
    if not wsum > 0:
        raise InputError("umeyama: weights sum to zero")
    w = w / wsum
    mu_s = w @ src
    mu_d = w @ dst
    xs = src - mu_s
    xd = dst - mu_d
    H = (xs * w[:, None]).T @ xd  # sum w (s - mu_s)(d - mu_d)^T
    U, S, Vt = np.linalg.svd(H)
    D = np.eye(3)
    if np.linalg.det(Vt.T @ U.T) < 0:
        D[2, 2] = -1.0
    R = Vt.T @ D @ U.T
    s = 1.0
    if with_scale:
        var_s = float(w @ (xs**2).sum(axis=1))
        s = float(np.trace(np.diag(S) @ D) / var_s) if var_s > 0 else 1.0
    t = mu_d - s * R @ mu_s
    T = from_rt(s * R, t)
    res = dst - (src @ (s * R).T + t)
    rmse = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    return T, rmse


def kabsch(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Rigid transform ``T_dst_src`` (4x4) minimising ``Σ w |R src + t − dst|²`` (no scale)."""
    return umeyama(src, dst, weights)[0]
