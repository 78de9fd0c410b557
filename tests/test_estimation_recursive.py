"""Shared machinery of the estimators: conventions, ordering, degeneracy, covariance, registry."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError, InputError
from relnav.estimation import available_estimators, get_estimator
from relnav.estimation._recursive import (
    adaptive_factors,
    check_geometry,
    filter_to_target_source,
    identity_state,
    measurement_matrix,
    project_state,
    residual_covariance,
    state_covariance_to_twist,
    state_to_transform,
    transform_to_state,
)
from relnav.geometry.rotations import rotation_angle, rotvec_to_matrix
from relnav.geometry.se3 import (
    exp_se3,
    from_rt,
    invert,
    log_se3,
    random_transform,
    transform_points,
)
from relnav.matching.correspondences import Correspondences

FILTERS = ["kalman", "hinf", "alphabeta", "sdre"]
ALL = [*FILTERS, "svd"]
# options with which every estimator solves exact correspondences to < 0.1 deg / 1 mm
EXACT_OPTS = {
    "kalman": {"p0": 1e6},
    "hinf": {"p0": 1e6},
    "alphabeta": {"center": True, "n_passes": 500},
    "sdre": {"center": True, "n_passes": 500, "sigma_w_sdre": 0.5},
    "svd": {},
}


def _pair(rng: np.random.Generator, n: int = 30, T: np.ndarray | None = None):
    """Source points 10 m ahead on boresight, target = T·source, exact correspondences."""
    src = rng.uniform(-1.0, 1.0, (n, 3)) + np.array([10.0, 0.0, 0.0])
    if T is None:
        T = random_transform(rng, max_translation=1.0)
    tgt = transform_points(T, src)
    corr = Correspondences(np.arange(n), np.arange(n), rng.uniform(0.05, 0.3, n))
    return src, tgt, corr, T


def _errors(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    dR = T_est[:3, :3].T @ T_true[:3, :3]
    return float(np.rad2deg(rotation_angle(dR))), float(
        np.linalg.norm(T_est[:3, 3] - T_true[:3, 3])
    )


# --------------------------------------------------------------------------------------------
# conventions
# --------------------------------------------------------------------------------------------


def test_measurement_matrix_maps_state_to_R_a_plus_t(rng):
    T = random_transform(rng)
    x = transform_to_state(T)
    a = rng.normal(size=3)
    H = measurement_matrix(a)
    assert H.shape == (3, 12)
    np.testing.assert_allclose(H @ x, T[:3, :3] @ a + T[:3, 3], atol=1e-12)
    np.testing.assert_allclose(H @ H.T, (a @ a + 1.0) * np.eye(3), atol=1e-12)
    np.testing.assert_allclose(measurement_matrix(a, 3.0), 3.0 * H)


def test_identity_state_and_projection_roundtrip(rng):
    np.testing.assert_array_equal(state_to_transform(identity_state()), np.eye(4))
    T = random_transform(rng)
    x = transform_to_state(T)
    # the filter state is T_source_target; the estimator returns its inverse
    np.testing.assert_allclose(state_to_transform(x), invert(T), atol=1e-12)
    np.testing.assert_allclose(filter_to_target_source(T[:3, :3], T[:3, 3]), invert(T), atol=1e-12)


def test_projection_returns_proper_rotation_even_for_reflections(rng):
    for _ in range(20):
        M = rng.normal(size=(3, 3))
        M[:, 0] *= -1 if np.linalg.det(M) > 0 else 1  # force det < 0
        assert np.linalg.det(M) < 0
        R, _ = project_state(np.concatenate([M.reshape(9), np.zeros(3)]))
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    # nearest rotation of a slightly perturbed rotation is close to it
    R0 = rotvec_to_matrix(np.array([0.3, -0.2, 0.5]))
    R, _ = project_state(np.concatenate([(R0 + 1e-4 * rng.normal(size=(3, 3))).ravel(), [0, 0, 0]]))
    assert rotation_angle(R.T @ R0) < 1e-3


def test_refit_t_formula(rng):
    R0 = rotvec_to_matrix(np.array([0.1, 0.2, -0.1]))
    x = np.concatenate([R0.ravel(), [5.0, 5.0, 5.0]])
    a_mean, b_mean = rng.normal(size=3), rng.normal(size=3)
    _, t = project_state(x, refit_t=True, a_mean=a_mean, b_mean=b_mean)
    np.testing.assert_allclose(t, b_mean - R0 @ a_mean, atol=1e-12)


@pytest.mark.parametrize("name", ALL)
def test_inverse_convention_target_equals_T_source(name, rng):
    """target = T·source → every estimator returns T (not T⁻¹)."""
    T = from_rt(rotvec_to_matrix(np.deg2rad([1.0, -2.0, 1.5])), [0.03, -0.04, 0.02])
    src, tgt, corr, _ = _pair(rng, n=40, T=T)
    est = get_estimator(name, **EXACT_OPTS[name]).estimate(src, tgt, corr)
    assert est.status == "ok"
    rot, trans = _errors(est.T_target_source, T)
    assert rot < 0.01 and trans < 1e-4
    # and clearly not the inverse
    rot_inv, _ = _errors(est.T_target_source, invert(T))
    assert rot_inv > 2.0
    if name != "svd":
        # the raw filter state is T_source_target = T⁻¹ (Paper 1's R*, P_k → P_{k+1})
        x = np.asarray(est.info["x_raw"])
        np.testing.assert_allclose(x[:9].reshape(3, 3), T[:3, :3].T, atol=1e-4)


# --------------------------------------------------------------------------------------------
# adaptive factor, ordering
# --------------------------------------------------------------------------------------------


def test_adaptive_factors_modes():
    d = np.array([0.0, 0.05, 0.2])
    np.testing.assert_allclose(adaptive_factors(d, "per_match"), [1e-3, 0.5, 2.0])
    np.testing.assert_allclose(adaptive_factors(d, "sum"), [2.5, 2.5, 2.5])
    np.testing.assert_allclose(adaptive_factors(d, "none"), [1.0, 1.0, 1.0])
    np.testing.assert_allclose(
        adaptive_factors(d, "per_match", scale=1.0, m_min=0.1), [0.1, 0.1, 0.2]
    )


@pytest.mark.parametrize("name", FILTERS)
def test_shuffled_equal_distances_are_deterministic(name, rng):
    src, tgt, _, _ = _pair(rng, n=40, T=random_transform(rng, max_translation=0.1))
    n = 40
    d = np.repeat([0.1, 0.2], n // 2)  # many exact ties
    base = Correspondences(np.arange(n), np.arange(n), d)
    est0 = get_estimator(name).estimate(src, tgt, base)
    for seed in range(3):
        perm = np.random.default_rng(seed).permutation(n)
        est = get_estimator(name).estimate(src, tgt, base.subset(perm))
        np.testing.assert_array_equal(est.T_target_source, est0.T_target_source)
        assert est.info["x_raw"] == est0.info["x_raw"]


@pytest.mark.parametrize("name", FILTERS)
def test_processing_order_is_ascending_distance(name, rng):
    """Feeding the correspondences pre-sorted or reversed gives the same result (order = sorted)."""
    src, tgt, _, _ = _pair(rng, n=30, T=random_transform(rng, max_translation=0.1))
    d = rng.uniform(0.0, 0.5, 30)
    corr = Correspondences(np.arange(30), np.arange(30), d)
    order = np.argsort(d)
    e1 = get_estimator(name).estimate(src, tgt, corr)
    e2 = get_estimator(name).estimate(src, tgt, corr.subset(order[::-1]))
    np.testing.assert_array_equal(e1.T_target_source, e2.T_target_source)
    # … but processing order matters for a recursive filter: a different order differs
    e3 = get_estimator(name, adaptive="none").estimate(src, tgt, corr)
    corr_rev = Correspondences(np.arange(30), np.arange(30), d.max() - d)
    e4 = get_estimator(name, adaptive="none").estimate(src, tgt, corr_rev)
    assert not np.array_equal(e3.T_target_source, e4.T_target_source)


# --------------------------------------------------------------------------------------------
# degeneracy and bad input
# --------------------------------------------------------------------------------------------


def test_check_geometry_thresholds(rng):
    P = rng.normal(size=(50, 3))
    assert check_geometry(P) == ""
    assert "correspondences" in check_geometry(P[:3])
    line = np.outer(np.linspace(0, 1, 20), [1.0, 2.0, 3.0]) + 5.0
    assert "collinear" in check_geometry(line)
    plane = P.copy()
    plane[:, 2] = 0.0
    assert "coplanar" in check_geometry(plane)
    assert check_geometry(plane, coplanar_tol=None) == ""
    assert "coincide" in check_geometry(np.ones((10, 3)) * 7.0)
    # tolerance is relative: a slightly thick plane (σ3/σ1 ≈ 1e-2) is accepted
    plane[:, 2] = 1e-2 * rng.normal(size=50)
    assert check_geometry(plane) == ""


def _assert_flagged(est, status):
    assert est.status == status
    np.testing.assert_array_equal(est.T_target_source, np.eye(4))
    assert est.covariance is None
    assert est.converged is False
    assert est.n_used == 0
    assert est.info["message"]


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("n", [0, 1, 2, 3])
def test_too_few_correspondences(name, n, rng):
    src, tgt, _, _ = _pair(rng, n=10)
    corr = Correspondences(np.arange(n), np.arange(n), np.full(n, 0.1))
    est = get_estimator(name).estimate(src, tgt, corr)
    if name == "svd" and n == 3:
        assert est.status == "ok"  # Kabsch needs only 3 non-collinear pairs
    else:
        _assert_flagged(est, "degenerate")


@pytest.mark.parametrize("name", ALL)
def test_collinear_and_duplicate_points_are_degenerate(name, rng):
    T = random_transform(rng, max_translation=0.1)
    line = np.outer(np.linspace(-1, 1, 25), [0.3, 1.0, -0.2]) + np.array([10.0, 0.0, 0.0])
    corr = Correspondences(np.arange(25), np.arange(25), np.full(25, 0.1))
    _assert_flagged(
        get_estimator(name).estimate(line, transform_points(T, line), corr), "degenerate"
    )
    # the same pair repeated many times
    src, tgt, _, _ = _pair(rng, n=10, T=T)
    dup = Correspondences(np.full(12, 4), np.full(12, 4), np.full(12, 0.1))
    _assert_flagged(get_estimator(name).estimate(src, tgt, dup), "degenerate")


@pytest.mark.parametrize("name", ALL)
def test_coplanar_points(name, rng):
    T = from_rt(rotvec_to_matrix(np.deg2rad([2.0, 1.0, -1.0])), [0.05, 0.0, -0.02])
    src = np.column_stack([np.full(30, 10.0), rng.uniform(-1, 1, (30, 2))])  # plane x = 10
    corr = Correspondences(np.arange(30), np.arange(30), np.full(30, 0.1))
    est = get_estimator(name).estimate(src, transform_points(T, src), corr)
    if name == "svd":
        assert est.status == "ok"  # rigid transform fixed by coplanar points
        rot, trans = _errors(est.T_target_source, T)
        assert rot < 1e-5 and trans < 1e-9
        est = get_estimator("svd", reject_coplanar=True).estimate(
            src, transform_points(T, src), corr
        )
    _assert_flagged(est, "degenerate")


@pytest.mark.parametrize("name", ALL)
def test_non_finite_input_fails_cleanly(name, rng):
    src, tgt, corr, _ = _pair(rng, n=20)
    bad = src.copy()
    bad[3] = np.nan
    _assert_flagged(get_estimator(name).estimate(bad, tgt, corr), "failed")
    bad_t = tgt.copy()
    bad_t[5, 1] = np.inf
    _assert_flagged(get_estimator(name).estimate(src, bad_t, corr), "failed")
    d = corr.distance.copy()
    d[0] = np.nan
    bad_c = Correspondences(corr.src_idx, corr.tgt_idx, d)
    _assert_flagged(get_estimator(name).estimate(src, tgt, bad_c), "failed")
    # a NaN point that no correspondence uses does not matter
    extra = np.vstack([src, [np.nan, np.nan, np.nan]])
    assert get_estimator(name).estimate(extra, tgt, corr).status == "ok"


@pytest.mark.parametrize("name", ALL)
def test_malformed_arrays_raise_input_error(name, rng):
    src, tgt, corr, _ = _pair(rng, n=10)
    est = get_estimator(name)
    with pytest.raises(InputError, match="src_pts"):
        est.estimate(src[:, :2], tgt, corr)
    with pytest.raises(InputError, match="tgt_idx"):
        est.estimate(src, tgt[:5], corr)
    with pytest.raises(InputError, match="src_idx"):
        est.estimate(src[:5], tgt, corr)


def test_registry_and_config_errors():
    names = available_estimators()
    assert set(ALL) <= set(names)
    with pytest.raises(ConfigError, match="unknown estimator"):
        get_estimator("nope")
    with pytest.raises(ConfigError, match="bad options"):
        get_estimator("kalman", not_an_option=1)
    with pytest.raises(ConfigError, match="sigma_v"):
        get_estimator("kalman", sigma_v=-1.0)
    with pytest.raises(ConfigError, match="adaptive"):
        get_estimator("hinf", adaptive="mean")
    with pytest.raises(ConfigError, match="n_passes"):
        get_estimator("alphabeta", n_passes=0)
    with pytest.raises(ConfigError, match="state covariance"):
        get_estimator("sdre", covariance="filter")
    with pytest.raises(ConfigError, match="beta"):
        get_estimator("alphabeta", paper_literal=True, beta=0.5)
    with pytest.raises(ConfigError, match="weights"):
        get_estimator("svd", weights="bogus")
    assert "KalmanEstimator(" in repr(get_estimator("kalman"))


# --------------------------------------------------------------------------------------------
# covariance
# --------------------------------------------------------------------------------------------


def test_state_covariance_jacobian_against_finite_log(rng):
    """J P Jᵀ with the first-order vee equals the Jacobian built from the exact SE(3) log."""
    T = random_transform(rng, max_translation=0.5)
    x = transform_to_state(invert(T)) + 1e-3 * rng.normal(size=12)  # slightly non-rigid state
    T_hat = state_to_transform(x)
    J = np.zeros((6, 12))
    h = 1e-5
    for i in range(12):
        e = np.zeros(12)
        e[i] = h
        J[:, i] = (
            log_se3(state_to_transform(x + e) @ invert(T_hat))
            - log_se3(state_to_transform(x - e) @ invert(T_hat))
        ) / (2 * h)
    A = rng.normal(size=(12, 12))
    P = A @ A.T
    C = state_covariance_to_twist(x, P)
    np.testing.assert_allclose(C, J @ P @ J.T, rtol=1e-5, atol=1e-9)
    assert np.all(np.linalg.eigvalsh(C) > -1e-12)


@pytest.mark.parametrize("opts", [{}, {"refit_t": True}, {"center": True}])
def test_kalman_covariance_is_consistent_monte_carlo(opts):
    """Kalman (p0 large, σ_v = true noise, σ_w = 0): predicted twist covariance ≈ empirical.

    Left perturbation: T_true = exp(δ) T_est ⇒ δ = log(T_true T_est⁻¹).
    """
    rng = np.random.default_rng(7)
    n, sigma = 40, 0.01
    src0 = rng.uniform(-1.0, 1.0, (n, 3)) + np.array([6.0, 0.0, 0.0])
    T = from_rt(rotvec_to_matrix(np.deg2rad([3.0, -2.0, 1.0])), [0.1, 0.05, -0.02])
    tgt0 = transform_points(T, src0)
    corr = Correspondences(np.arange(n), np.arange(n), np.full(n, 0.1))
    est = get_estimator("kalman", p0=1e8, sigma_v=sigma, sigma_w=0.0, adaptive="none", **opts)
    errs, covs = [], []
    for _ in range(300):
        src = src0 + sigma * rng.normal(size=src0.shape)  # noise on the measurement ψ = b
        e = est.estimate(src, tgt0, corr)
        errs.append(log_se3(T @ invert(e.T_target_source)))
        covs.append(e.covariance)
    errs = np.array(errs)
    C_emp = np.cov(errs.T)
    C_pred = np.mean(covs, axis=0)
    # per-axis variance ratio within sampling error of 300 trials (±~25 %)
    ratio = np.diag(C_emp) / np.diag(C_pred)
    assert np.all((ratio > 0.7) & (ratio < 1.4)), ratio
    # whitened errors: mean NEES ≈ 6
    W = np.linalg.inv(C_pred)
    nees = np.einsum("ij,jk,ik->i", errs, W, errs)
    assert 4.8 < nees.mean() < 7.2


def test_residual_covariance_monte_carlo():
    rng = np.random.default_rng(11)
    n, sigma = 40, 0.01
    src0 = rng.uniform(-1.0, 1.0, (n, 3)) + np.array([6.0, 0.0, 0.0])
    T = exp_se3(np.array([0.1, 0.05, -0.02, 0.05, -0.03, 0.02]))
    tgt0 = transform_points(T, src0)
    corr = Correspondences(np.arange(n), np.arange(n), np.full(n, 0.1))
    svd = get_estimator("svd")
    errs, covs = [], []
    for _ in range(300):
        tgt = tgt0 + sigma * rng.normal(size=tgt0.shape)
        e = svd.estimate(src0, tgt, corr)
        errs.append(log_se3(T @ invert(e.T_target_source)))
        covs.append(e.covariance)
    ratio = np.diag(np.cov(np.array(errs).T)) / np.diag(np.mean(covs, axis=0))
    assert np.all((ratio > 0.7) & (ratio < 1.4)), ratio
    # exact data → zero covariance; too few points → None
    e = svd.estimate(src0, tgt0, corr)
    np.testing.assert_allclose(e.covariance, 0.0, atol=1e-20)
    assert residual_covariance(np.eye(4), src0[:2], tgt0[:2]) is None


@pytest.mark.parametrize("name", ALL)
def test_covariance_shape_and_psd(name, rng):
    src, tgt, corr, _ = _pair(rng, n=30, T=random_transform(rng, max_translation=0.1))
    tgt = tgt + 0.005 * rng.normal(size=tgt.shape)
    est = get_estimator(name).estimate(src, tgt, corr)
    assert est.covariance is not None and est.covariance.shape == (6, 6)
    np.testing.assert_allclose(est.covariance, est.covariance.T, atol=1e-15)
    assert np.linalg.eigvalsh(est.covariance).min() > -1e-12
    if name != "svd":
        none = get_estimator(name, covariance="none").estimate(src, tgt, corr)
        assert none.covariance is None
