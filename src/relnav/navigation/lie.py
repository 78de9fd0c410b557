"""SE(3) exponential and logarithm in numba for the navigator's per-frame filter and smoother.

Same maps as :func:`relnav.geometry.se3.exp_se3` / :func:`~relnav.geometry.se3.log_se3` (twist
``[ρ, φ]``, ``|φ| ≤ π``), without SciPy's ``Rotation`` objects: the filter calls them a few
times per frame and the smoother a few times per frame and window step, where the object
overhead dominated.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from relnav.geometry.icp_kernels import _rodrigues_nb
from relnav.navigation.gicp import _rot_log

__all__ = ["exp_se3", "log_se3"]


@njit(cache=True)
def _hat2(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:  # pragma: no cover - numba
    K = np.zeros((3, 3))
    K[0, 1], K[0, 2], K[1, 2] = -p[2], p[1], -p[0]
    K[1, 0], K[2, 0], K[2, 1] = p[2], -p[1], p[0]
    return K, K @ K, math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])


@njit(cache=True)
def _exp(xi: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    phi = xi[3:].copy()
    K, K2, th = _hat2(phi)
    if th < 1e-8:
        J = np.eye(3) + 0.5 * K + K2 / 6.0
    else:
        J = np.eye(3) + (1.0 - math.cos(th)) / th**2 * K + (th - math.sin(th)) / th**3 * K2
    T = np.eye(4)
    T[:3, :3] = _rodrigues_nb(phi)
    T[:3, 3] = J @ xi[:3].copy()
    return T


@njit(cache=True)
def _log(T: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    phi = _rot_log(np.ascontiguousarray(T[:3, :3]))
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


def exp_se3(xi: np.ndarray) -> np.ndarray:
    """``4x4`` transform of the twist ``xi = [ρ (m), φ (rad)]`` (6,)."""
    return _exp(np.ascontiguousarray(xi, dtype=np.float64).reshape(6))


def log_se3(T: np.ndarray) -> np.ndarray:
    """Twist ``[ρ, φ]`` (6,) of a ``4x4`` rigid transform, ``|φ| ≤ π``."""
    return _log(np.ascontiguousarray(T, dtype=np.float64))
