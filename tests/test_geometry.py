"""Property tests of the geometry core (SE(3), rotations, Kabsch, resolution, normals)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from relnav.errors import InputError
from relnav.geometry import (
    exp_se3,
    invert,
    kabsch,
    log_se3,
    matrix_to_quat,
    mean_resolution,
    project_to_so3,
    quat_multiply,
    quat_to_matrix,
    random_transform,
    rotation_angle,
    transform_points,
    umeyama,
)
from relnav.geometry.normals import estimate_normals

seeds = st.integers(min_value=0, max_value=2**32 - 1)


@given(seeds)
@settings(max_examples=60, deadline=None)
def test_exp_log_roundtrip(seed):
    T = random_transform(seed, max_translation=5.0)
    np.testing.assert_allclose(exp_se3(log_se3(T)), T, atol=1e-9)


@given(seeds)
@settings(max_examples=60, deadline=None)
def test_log_exp_roundtrip_small(seed):
    rng = np.random.default_rng(seed)
    xi = np.concatenate([rng.uniform(-3, 3, 3), rng.uniform(-1, 1, 3) * 0.9])
    np.testing.assert_allclose(log_se3(exp_se3(xi)), xi, atol=1e-9)


@given(seeds)
@settings(max_examples=60, deadline=None)
def test_inverse(seed):
    T = random_transform(seed)
    np.testing.assert_allclose(T @ invert(T), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(invert(invert(T)), T, atol=1e-12)


@given(seeds)
@settings(max_examples=60, deadline=None)
def test_kabsch_recovers_transform_exactly(seed):
    rng = np.random.default_rng(seed)
    T = random_transform(rng, max_translation=10.0)
    src = rng.normal(size=(20, 3))
    dst = transform_points(T, src)
    np.testing.assert_allclose(kabsch(src, dst), T, atol=1e-9)


def test_umeyama_scale(rng):
    T = random_transform(rng)
    src = rng.normal(size=(50, 3))
    dst = 2.5 * (src @ T[:3, :3].T) + T[:3, 3]
    Ts, rmse = umeyama(src, dst, with_scale=True)
    assert rmse < 1e-9
    np.testing.assert_allclose(np.linalg.det(Ts[:3, :3]) ** (1 / 3), 2.5, rtol=1e-9)


def test_kabsch_never_reflects(rng):
    src = rng.normal(size=(30, 3))
    dst = src * np.array([1.0, 1.0, -1.0])  # a pure reflection
    R = kabsch(src, dst)[:3, :3]
    assert np.linalg.det(R) > 0.999


def test_kabsch_bad_input():
    with pytest.raises(InputError):
        kabsch(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(InputError):
        kabsch(np.full((5, 3), np.nan), np.zeros((5, 3)))


@given(seeds)
@settings(max_examples=40, deadline=None)
def test_quaternion_roundtrip_and_product(seed):
    rng = np.random.default_rng(seed)
    R1, R2 = random_transform(rng)[:3, :3], random_transform(rng)[:3, :3]
    q1, q2 = matrix_to_quat(R1), matrix_to_quat(R2)
    assert q1[3] >= 0
    np.testing.assert_allclose(quat_to_matrix(q1), R1, atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(q1, q2)), R1 @ R2, atol=1e-12)


def test_project_to_so3_and_angle(rng):
    R = random_transform(rng)[:3, :3]
    noisy = R + 1e-3 * rng.normal(size=(3, 3))
    P = project_to_so3(noisy)
    np.testing.assert_allclose(P @ P.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(P) == pytest.approx(1.0)
    assert rotation_angle(P.T @ R) < 2e-3


def test_mean_resolution_grid():
    g = np.stack(np.meshgrid(np.arange(10), np.arange(10), [0.0]), -1).reshape(-1, 3) * 0.05
    assert mean_resolution(g) == pytest.approx(0.05)
    # duplicates do not collapse the resolution
    assert mean_resolution(np.vstack([g, g])) == pytest.approx(0.05)
    assert np.isnan(mean_resolution(np.zeros((1, 3))))


def test_normals_of_plane_point_to_viewpoint(rng):
    pts = np.column_stack([rng.uniform(-1, 1, 500), rng.uniform(-1, 1, 500), np.full(500, 5.0)])
    n = estimate_normals(pts, k=12)
    np.testing.assert_allclose(np.abs(n[:, 2]), 1.0, atol=1e-9)
    assert (n[:, 2] < 0).all()  # oriented towards the origin (sensor)
    n_r = estimate_normals(pts, radius=0.2)
    np.testing.assert_allclose(n_r[:, 2], -1.0, atol=1e-9)


def test_hat_batch_is_hat_of_each_vector() -> None:
    from relnav.geometry.rotations import hat, hat_batch

    rng = np.random.default_rng(3)
    v, u = rng.normal(size=(6, 3)), rng.normal(size=3)
    K = hat_batch(v)
    assert K.shape == (6, 3, 3)
    np.testing.assert_allclose(K @ u, np.cross(v, u), atol=1e-12)
    for k in range(6):
        np.testing.assert_array_equal(K[k], hat(v[k]))
