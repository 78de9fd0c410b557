"""relnav.geometry.eigen: the plain-loop linear algebra of the navigator's kernels against NumPy."""

from __future__ import annotations

import numpy as np

from relnav.geometry.eigen import (
    block,
    inverse,
    matmul,
    matmul_t,
    matmul_tn,
    pinv_sym,
    sym_eigvals,
    symmetrize,
)


def test_products_and_blocks_match_numpy() -> None:
    rng = np.random.default_rng(0)
    A, B, C = rng.normal(size=(12, 6)), rng.normal(size=(6, 12)), rng.normal(size=(12, 6))
    np.testing.assert_allclose(matmul(A, B), A @ B, atol=1e-12)
    np.testing.assert_allclose(matmul_t(A, C), A @ C.T, atol=1e-12)
    np.testing.assert_allclose(matmul_tn(A, C), A.T @ C, atol=1e-12)
    S = rng.normal(size=(7, 7))
    np.testing.assert_array_equal(symmetrize(S), 0.5 * (S + S.T))
    np.testing.assert_array_equal(block(A, 2, 9, 1, 4), A[2:9, 1:4])


def test_inverse_matches_numpy_and_reports_singular_matrices() -> None:
    rng = np.random.default_rng(1)
    for n in (3, 6, 12):
        A = rng.normal(size=(n, n)) + n * np.eye(n)
        X, ok = inverse(A)
        assert ok
        np.testing.assert_allclose(X, np.linalg.inv(A), rtol=1e-10, atol=1e-12)
    A = rng.normal(size=(6, 6))
    A[3] = 2.0 * A[1]  # exactly dependent rows: a zero pivot
    A[3] -= 2.0 * A[1]
    X, ok = inverse(A)
    assert not ok and not X.any()
    _, ok = inverse(np.full((4, 4), np.nan))
    assert not ok


def test_symmetric_eigenvalues_and_pseudo_inverse_match_numpy() -> None:
    rng = np.random.default_rng(2)
    for n in (3, 6):
        M = rng.normal(size=(n, n))
        S = M @ M.T
        np.testing.assert_allclose(sym_eigvals(S), np.linalg.eigvalsh(S), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(pinv_sym(S), np.linalg.pinv(S), rtol=1e-8, atol=1e-10)
    # rank 4 of 6: the pseudo-inverse drops the null space as NumPy's does
    M = rng.normal(size=(6, 4))
    S = M @ M.T
    np.testing.assert_allclose(pinv_sym(S), np.linalg.pinv(S), rtol=1e-6, atol=1e-8)
    np.testing.assert_array_equal(pinv_sym(np.zeros((6, 6))), np.zeros((6, 6)))
