"""SE(3) exponential, logarithm, inverse and adjoint in numba (navigator filter, smoother and GICP;
pose graphs).

Same maps as :func:`relnav.geometry.se3.exp_se3` / :func:`~relnav.geometry.se3.log_se3` (twist
``[ρ, φ]``, ``|φ| ≤ π``), without SciPy's ``Rotation`` objects: the filter calls them a few
times per frame and the smoother a few times per frame and window step, where the object
overhead dominated.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from relnav.geometry.icp_kernels import rodrigues_nb

__all__ = ["exp_se3", "log_se3"]


@njit(cache=True)
def rot_log_nb(R: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Rotation vector of ``R`` (``|w| ≤ π``).

    The angle is ``atan2(s, c)`` (accurate near 0 and π, unlike ``acos``); the axis comes from
    the skew part of ``R`` below 170°, and above from its symmetric part, ``k kᵀ = (S − c I) /
    (1 − c)`` with ``S = (R + Rᵀ)/2``, signed by the skew part.
    """
    w = np.empty(3)
    w[0] = R[2, 1] - R[1, 2]
    w[1] = R[0, 2] - R[2, 0]
    w[2] = R[1, 0] - R[0, 1]
    s = 0.5 * math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    c = min(1.0, max(-1.0, 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)))
    th = math.atan2(s, c)
    if c > -0.985:  # below ~170°
        f = 0.5 if s < 1e-15 else 0.5 * th / s
        for i in range(3):
            w[i] *= f
        return w
    a = 0
    for i in range(1, 3):
        if R[i, i] > R[a, a]:
            a = i
    k = np.empty(3)
    ka = math.sqrt(max((R[a, a] - c) / (1.0 - c), 0.0))
    for i in range(3):
        k[i] = ka if i == a else 0.5 * (R[a, i] + R[i, a]) / ((1.0 - c) * ka)
    if k[0] * w[0] + k[1] * w[1] + k[2] * w[2] < 0.0:
        for i in range(3):
            k[i] = -k[i]
    n = math.sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2])
    for i in range(3):
        w[i] = th * k[i] / n
    return w


@njit(cache=True)
def _hat2(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:  # pragma: no cover - numba
    K = np.zeros((3, 3))
    K[0, 1], K[0, 2], K[1, 2] = -p[2], p[1], -p[0]
    K[1, 0], K[2, 0], K[2, 1] = p[2], -p[1], p[0]
    return K, K @ K, math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])


@njit(cache=True)
def exp_se3_nb(xi: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    phi = xi[3:].copy()
    K, K2, th = _hat2(phi)
    if th < 1e-8:
        J = np.eye(3) + 0.5 * K + K2 / 6.0
    else:
        J = np.eye(3) + (1.0 - math.cos(th)) / th**2 * K + (th - math.sin(th)) / th**3 * K2
    T = np.eye(4)
    T[:3, :3] = rodrigues_nb(phi)
    T[:3, 3] = J @ xi[:3].copy()
    return T


@njit(cache=True)
def log_se3_nb(T: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    phi = rot_log_nb(np.ascontiguousarray(T[:3, :3]))
    K, K2, th = _hat2(phi)
    if th < 1e-8:
        Ji = np.eye(3) - 0.5 * K + K2 / 12.0
    else:
        half = th / 2.0
        Ji = np.eye(3) - 0.5 * K + (1.0 - half / math.tan(half)) / th**2 * K2
    out = np.empty(6)
    out[:3] = Ji @ np.ascontiguousarray(T[:3, 3])
    out[3:] = phi
    return out


@njit(cache=True)
def invert_nb(T: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Inverse of a rigid transform ``T`` (4×4)."""
    out = np.eye(4)
    for i in range(3):
        for j in range(3):
            out[i, j] = T[j, i]
        out[i, 3] = -(T[0, i] * T[0, 3] + T[1, i] * T[1, 3] + T[2, i] * T[2, 3])
    return out


@njit(cache=True)
def adjoint_nb(T: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Adjoint ``[[R, [t]×R], [0, R]]`` (6×6) of ``T`` (twists ``[ρ, φ]``)."""
    t0, t1, t2 = T[0, 3], T[1, 3], T[2, 3]
    A = np.zeros((6, 6))
    for j in range(3):
        r0, r1, r2 = T[0, j], T[1, j], T[2, j]
        A[0, j] = A[3, 3 + j] = r0
        A[1, j] = A[4, 3 + j] = r1
        A[2, j] = A[5, 3 + j] = r2
        A[0, 3 + j] = t1 * r2 - t2 * r1  # [t]× R, column j: t × R[:, j]
        A[1, 3 + j] = t2 * r0 - t0 * r2
        A[2, 3 + j] = t0 * r1 - t1 * r0
    return A


def exp_se3(xi: np.ndarray) -> np.ndarray:
    """``4x4`` transform of the twist ``xi = [ρ (m), φ (rad)]`` (6,)."""
    return exp_se3_nb(np.ascontiguousarray(xi, dtype=np.float64).reshape(6))


def log_se3(T: np.ndarray) -> np.ndarray:
    """Twist ``[ρ, φ]`` (6,) of a ``4x4`` rigid transform, ``|φ| ≤ π``."""
    return log_se3_nb(np.ascontiguousarray(T, dtype=np.float64))
