"""Unit dual quaternions and the Cayley transform (ALGORITHMS.md §G.6)."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import InputError
from relnav.geometry.dualquat import (
    cayley,
    cayley_inverse,
    cayley_mean,
    dq_canonical,
    dq_conjugate,
    dq_from_matrix,
    dq_from_rt,
    dq_identity,
    dq_inverse,
    dq_multiply,
    dq_normalize,
    dq_to_matrix,
    dq_to_rt,
    dq_transform_points,
    quat_cayley,
    quat_cayley_inverse,
    quat_cayley_mean,
)
from relnav.geometry.rotations import matrix_to_quat, quat_multiply, rotvec_to_matrix
from relnav.geometry.se3 import random_transform, transform_points


def _random_dqs(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    T = np.stack([random_transform(rng, max_translation=5.0) for _ in range(n)])
    return T, dq_from_matrix(T)


def test_matrix_round_trip_and_composition(rng: np.random.Generator) -> None:
    T, A = _random_dqs(rng, 50)
    np.testing.assert_allclose(dq_to_matrix(A), T, atol=1e-12)
    # composition follows matrix order, inverse is the conjugate for unit dq
    T2, B = _random_dqs(rng, 50)
    np.testing.assert_allclose(dq_to_matrix(dq_multiply(A, B)), T @ T2, atol=1e-12)
    np.testing.assert_allclose(
        dq_multiply(A, dq_conjugate(A)), np.tile(dq_identity(), (50, 1)), atol=1e-12
    )
    np.testing.assert_allclose(dq_inverse(A), dq_conjugate(A), atol=1e-12)
    pts = rng.normal(size=(20, 3))
    np.testing.assert_allclose(
        dq_transform_points(A[0], pts), transform_points(T[0], pts), atol=1e-12
    )


def test_dual_part_is_half_t_q() -> None:
    q = matrix_to_quat(rotvec_to_matrix([0.3, -0.2, 0.5]))
    t = np.array([1.0, -2.0, 0.5])
    a = dq_from_rt(q, t)
    expected = 0.5 * quat_multiply(np.r_[t, 0.0], q)
    np.testing.assert_allclose(a[4:], expected, atol=1e-15)
    q2, t2 = dq_to_rt(-a)  # the same pose with the other sign
    np.testing.assert_allclose(q2, q, atol=1e-15)
    np.testing.assert_allclose(t2, t, atol=1e-14)


def test_cayley_round_trip_and_purity(rng: np.random.Generator) -> None:
    _, A = _random_dqs(rng, 200)
    A[::3] *= -1.0  # both hemispheres in the input
    B = cayley(A)
    np.testing.assert_allclose(cayley_inverse(B), dq_canonical(A), atol=1e-12)
    # the literal dual-quaternion expression equals the closed form and is a pure dual quaternion
    full = cayley(A, full=True)
    np.testing.assert_allclose(full[:, [3, 7]], 0.0, atol=1e-12)
    np.testing.assert_allclose(full[:, [0, 1, 2, 4, 5, 6]], B, atol=1e-12)
    np.testing.assert_allclose(cayley_inverse(B, general=True), cayley_inverse(B), atol=1e-12)
    # inverse Cayley of any twist is a unit dual quaternion (|q| = 1, q·q_d = 0)
    Bs = rng.normal(size=(100, 6))
    Q = cayley_inverse(Bs)
    np.testing.assert_allclose(np.linalg.norm(Q[:, :4], axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(Q[:, :4] * Q[:, 4:], axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(cayley(Q, hemisphere=False), Bs, atol=1e-9)


def test_cayley_real_part_is_tan_quarter_angle() -> None:
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    for phi in (0.1, 1.0, 2.5, np.pi):
        a = dq_from_rt(matrix_to_quat(rotvec_to_matrix(phi * axis)), [0.3, 0.1, -0.2])
        np.testing.assert_allclose(cayley(a)[:3], np.tan(phi / 4.0) * axis, atol=1e-12)
        np.testing.assert_allclose(quat_cayley(a[:4]), cayley(a)[:3], atol=1e-15)
        np.testing.assert_allclose(
            quat_cayley_inverse(cayley(a)[:3]), dq_canonical(a)[:4], atol=1e-12
        )


def test_cayley_small_angle_limit() -> None:
    phi = np.array([2e-4, -1e-4, 3e-4])
    t = np.array([1e-3, -2e-3, 5e-4])
    a = dq_from_rt(matrix_to_quat(rotvec_to_matrix(phi)), t)
    B = cayley(a)
    np.testing.assert_allclose(4.0 * B[:3], phi, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(4.0 * B[3:], t, rtol=1e-3, atol=1e-9)
    np.testing.assert_allclose(cayley(dq_identity()), 0.0, atol=0)


def test_hemisphere_handling_at_full_turn() -> None:
    minus_one = -dq_identity()  # q = -1: rotation by 2π, the Cayley singularity
    with np.errstate(all="ignore"):
        assert not np.all(np.isfinite(cayley(minus_one, hemisphere=False)))
    np.testing.assert_allclose(cayley(minus_one), 0.0, atol=0)  # same pose as the identity
    # a rotation by π maps to |B_r| = 1, finite, and back
    a = dq_from_rt([1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    B = cayley(a)
    assert np.isfinite(B).all()
    assert np.linalg.norm(B[:3]) == pytest.approx(1.0)
    np.testing.assert_allclose(dq_to_matrix(cayley_inverse(B)), dq_to_matrix(a), atol=1e-12)


def test_cayley_mean_recovers_centre_of_symmetric_set(rng: np.random.Generator) -> None:
    T0, c = _random_dqs(rng, 1)
    c = c[0]
    d = rng.normal(scale=0.05, size=(5, 6))
    twists = np.vstack([d, -d])  # symmetric in Cayley coordinates about c
    X = dq_multiply(c, cayley_inverse(twists))
    m, it, ok = cayley_mean(X)  # from X[0], as in the UKF (close to the mean)
    assert ok and it <= 10
    np.testing.assert_allclose(dq_to_matrix(m), T0[0], atol=1e-9)
    m, it, ok = cayley_mean(X, init=dq_identity(), max_iter=50)  # from far away
    assert ok
    np.testing.assert_allclose(dq_to_matrix(m), T0[0], atol=1e-9)
    # negative weights (UKF W0 < 0) are allowed as long as they sum to 1
    w = np.r_[-4.0, np.full(10, 0.5)]
    m2, _, ok2 = cayley_mean(np.vstack([c, X]), w)
    assert ok2
    np.testing.assert_allclose(dq_to_matrix(m2), T0[0], atol=1e-9)
    # the rotation part alone gives the same rotation
    qm, _, _ = quat_cayley_mean(X[:, :4], init=[0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(qm, dq_canonical(m)[:4], atol=1e-9)


def test_normalize_and_bad_input(rng: np.random.Generator) -> None:
    _, A = _random_dqs(rng, 3)
    noisy = 1.7 * A + 1e-3 * rng.normal(size=A.shape)
    N = dq_normalize(noisy)
    np.testing.assert_allclose(np.linalg.norm(N[:, :4], axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.sum(N[:, :4] * N[:, 4:], axis=1), 0.0, atol=1e-14)
    with pytest.raises(InputError):
        dq_multiply(np.zeros(7), np.zeros(8))
    with pytest.raises(InputError):
        cayley_inverse(np.zeros(5))
    with pytest.raises(InputError):
        dq_normalize(np.zeros(8))
    with pytest.raises(InputError):
        cayley_mean(np.zeros((0, 8)))
