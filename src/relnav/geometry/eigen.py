"""Small dense linear algebra in numba without LAPACK: symmetric eigenproblems, inverses and the
products of the navigator's 4×4–12×12 matrices.

Plain loops: numba compiles them several times faster than ``np.linalg`` calls and ``@`` on
arrays (a first ``relnav demo`` compiles every kernel), and they are exact to rounding.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "block",
    "inverse",
    "jacobi_eigh",
    "matmul",
    "matmul_t",
    "matmul_tn",
    "pinv_sym",
    "solve_spd6",
    "sym_eigvals",
    "symmetrize",
]


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


@njit(cache=True)
def matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """``A @ B`` (2-D, C-contiguous)."""
    n, k, m = A.shape[0], A.shape[1], B.shape[1]
    out = np.zeros((n, m))
    for i in range(n):
        for p in range(k):
            a = A[i, p]
            for j in range(m):
                out[i, j] += a * B[p, j]
    return out


@njit(cache=True)
def matmul_t(A: np.ndarray, B: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """``A @ B.T`` (2-D, C-contiguous)."""
    n, k, m = A.shape[0], A.shape[1], B.shape[0]
    out = np.zeros((n, m))
    for i in range(n):
        for j in range(m):
            s = 0.0
            for p in range(k):
                s += A[i, p] * B[j, p]
            out[i, j] = s
    return out


@njit(cache=True)
def matmul_tn(A: np.ndarray, B: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """``A.T @ B`` (2-D, C-contiguous)."""
    k, n, m = A.shape[0], A.shape[1], B.shape[1]
    out = np.zeros((n, m))
    for p in range(k):
        for i in range(n):
            a = A[p, i]
            for j in range(m):
                out[i, j] += a * B[p, j]
    return out


@njit(cache=True)
def symmetrize(A: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """``(A + Aᵀ) / 2`` of a square matrix."""
    n = A.shape[0]
    out = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.5 * (A[i, j] + A[j, i])
    return out


@njit(cache=True)
def block(A: np.ndarray, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:  # pragma: no cover
    """The contiguous copy of ``A[r0:r1, c0:c1]``."""
    out = np.empty((r1 - r0, c1 - c0))
    for i in range(r0, r1):
        for j in range(c0, c1):
            out[i - r0, j - c0] = A[i, j]
    return out


@njit(cache=True)
def inverse(A_in: np.ndarray) -> tuple[np.ndarray, bool]:  # pragma: no cover - numba
    """``A⁻¹`` of a small square matrix by Gauss–Jordan elimination with partial pivoting, and
    whether it exists: ``False`` (and zeros) when a pivot is exactly zero, where
    ``np.linalg.inv`` raises ``LinAlgError``."""
    n = A_in.shape[0]
    A = A_in.copy()
    X = np.eye(n)
    for c in range(n):
        piv = c
        for r in range(c + 1, n):
            if abs(A[r, c]) > abs(A[piv, c]):
                piv = r
        if A[piv, c] == 0.0 or not math.isfinite(A[piv, c]):
            return np.zeros((n, n)), False
        if piv != c:
            for j in range(n):
                A[c, j], A[piv, j] = A[piv, j], A[c, j]
                X[c, j], X[piv, j] = X[piv, j], X[c, j]
        d = 1.0 / A[c, c]
        for j in range(n):
            A[c, j] *= d
            X[c, j] *= d
        for r in range(n):
            if r != c:
                f = A[r, c]
                if f != 0.0:
                    for j in range(n):
                        A[r, j] -= f * A[c, j]
                        X[r, j] -= f * X[c, j]
    return X, True


@njit(cache=True)
def sym_eigvals(A: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Eigenvalues of a small symmetric matrix, ascending (:func:`jacobi_eigh`)."""
    w, _ = jacobi_eigh(A)
    for i in range(1, len(w)):  # insertion sort: n ≤ 12
        x = w[i]
        j = i - 1
        while j >= 0 and w[j] > x:
            w[j + 1] = w[j]
            j -= 1
        w[j + 1] = x
    return w


@njit(cache=True)
def pinv_sym(A: np.ndarray, rcond: float = 1e-15) -> np.ndarray:  # pragma: no cover - numba
    """Pseudo-inverse of a symmetric matrix: ``V diag(1/w) Vᵀ`` over the eigenvalues with
    ``|w| > rcond · max |w|`` (``np.linalg.pinv``'s rule, its singular values being ``|w|``)."""
    w, V = jacobi_eigh(A)
    n = len(w)
    big = 0.0
    for i in range(n):
        big = max(big, abs(w[i]))
    out = np.zeros((n, n))
    for k in range(n):
        if abs(w[k]) > rcond * big:
            inv = 1.0 / w[k]
            for i in range(n):
                a = V[i, k] * inv
                for j in range(n):
                    out[i, j] += a * V[j, k]
    return out
