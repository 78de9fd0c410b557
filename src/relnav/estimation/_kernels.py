"""Small numba kernels for the 12-state updates of Paper 1's filters (``H_u = hs·[I₃ ⊗ aᵀ, I₃]``
products, 3×3 inverse, Cholesky and SPD inverse), allocation-free.
"""

from __future__ import annotations

import logging

import numpy as np
from numba import njit

log = logging.getLogger(__name__)


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
