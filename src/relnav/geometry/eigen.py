"""Small symmetric eigenproblems in numba (no LAPACK call compiled)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["jacobi_eigh", "solve_spd6"]


@njit(cache=True)
def jacobi_eigh(A_in: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Eigen-decomposition of a small symmetric matrix by cyclic Jacobi rotations.

    Returns ``(w, V)`` with ``A = V diag(w) Vᵀ`` (unsorted). Plain loops, no LAPACK: numba
    compiles it in a fraction of the time ``np.linalg`` needs, and it is exact to rounding.
    """
    n = A_in.shape[0]
    A = A_in.copy()
    V = np.eye(n)
    for _sweep in range(60):
        off = 0.0
        scale = 0.0
        for p in range(n):
            scale += A[p, p] * A[p, p]
            for q in range(p + 1, n):
                off += A[p, q] * A[p, q]
        if off <= 1e-32 * scale or off == 0.0:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = A[p, q]
                if apq == 0.0:
                    continue
                theta = (A[q, q] - A[p, p]) / (2.0 * apq)
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                sn = t * c
                for k in range(n):
                    akp = A[k, p]
                    akq = A[k, q]
                    A[k, p] = c * akp - sn * akq
                    A[k, q] = sn * akp + c * akq
                for k in range(n):
                    apk = A[p, k]
                    aqk = A[q, k]
                    A[p, k] = c * apk - sn * aqk
                    A[q, k] = sn * apk + c * aqk
                for k in range(n):
                    vkp = V[k, p]
                    vkq = V[k, q]
                    V[k, p] = c * vkp - sn * vkq
                    V[k, q] = sn * vkp + c * vkq
    w = np.empty(n)
    for p in range(n):
        w[p] = A[p, p]
    return w, V


@njit(cache=True)
def solve_spd6(A: np.ndarray, b: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Solve the symmetric positive definite system ``A x = b`` (6×6, e.g. normal equations of a
    pose) by Cholesky with a tiny ridge; a non-positive pivot is replaced by 1e-300."""
    n = 6
    L = np.zeros((n, n))
    ridge = 1e-12 * (abs(A[0, 0]) + abs(A[3, 3]) + 1.0)
    for i in range(n):
        for j in range(i + 1):
            s = A[i, j] + (ridge if i == j else 0.0)
            for k in range(j):
                s -= L[i, k] * L[j, k]
            if i == j:
                L[i, i] = math.sqrt(s) if s > 0.0 else 1e-300
            else:
                L[i, j] = s / L[j, j]
    y = np.zeros(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    x = np.zeros(n)
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    return x
