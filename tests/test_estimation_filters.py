"""The four recursive filters and the SVD reference: oracles, accuracy, options, literal modes."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are

from relnav.estimation import get_estimator
from relnav.estimation._recursive import adaptive_factors, identity_state, measurement_matrix
from relnav.estimation.sdre import sdre_gain, sdre_xi
from relnav.geometry.rotations import rotation_angle, rotvec_to_matrix
from relnav.geometry.se3 import from_rt, random_transform, transform_points
from relnav.matching.correspondences import Correspondences

FILTERS = ["kalman", "hinf", "alphabeta", "sdre"]
ALL = [*FILTERS, "svd"]
EXACT_OPTS = {
    "kalman": {"p0": 1e6},
    "hinf": {"p0": 1e6},
    "alphabeta": {"center": True, "n_passes": 500},
    "sdre": {"center": True, "n_passes": 500, "sigma_w_sdre": 0.5},
    "svd": {},
}


def _errors(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    dR = T_est[:3, :3].T @ T_true[:3, :3]
    return float(np.rad2deg(rotation_angle(dR))), float(
        np.linalg.norm(T_est[:3, 3] - T_true[:3, 3])
    )


def _realistic(seed: int, n: int = 50, angle_deg: float = 2.0, trans_m: float = 0.05):
    """Target ±1 m around 10 m on boresight; small inter-frame motion; d ~ U(0.05, 0.3)."""
    rng = np.random.default_rng(seed)
    src = rng.uniform(-1.0, 1.0, (n, 3)) + np.array([10.0, 0.0, 0.0])
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    T = from_rt(rotvec_to_matrix(np.deg2rad(angle_deg) * axis), trans_m * direction)
    corr = Correspondences(np.arange(n), np.arange(n), rng.uniform(0.05, 0.3, n))
    return src, transform_points(T, src), corr, T


# --------------------------------------------------------------------------------------------
# NumPy references of §D.2/§D.4 with dense H (oracles for the numba kernels)
# --------------------------------------------------------------------------------------------


def _ref_kalman(a, b, m, sv, sw, p0, literal, joseph=True):
    x, P = identity_state(), p0 * np.eye(12)
    for u in range(len(a)):
        H = measurement_matrix(a[u], m[u] if literal else 1.0)
        V = m[u] * sv**2 * np.eye(3)
        if not literal:
            P = P + sw**2 * np.eye(12)
        S = H @ P @ H.T + V
        K = P @ H.T @ np.linalg.inv(S)
        x = x + K @ (b[u] - H @ x)
        if literal:
            P = P + sw**2 * np.eye(12) - P @ H.T @ np.linalg.inv(S) @ H @ P
        elif joseph:
            IKH = np.eye(12) - K @ H
            P = IKH @ P @ IKH.T + K @ V @ K.T
        else:
            P = P - K @ S @ K.T
    return x, P


def _ref_hinf(a, b, m, sv, sw, p0, theta, dt, literal):
    """Simon's printed form (eqs. 13–16) with the explicit L inverse."""
    x, P = identity_state(), p0 * np.eye(12)
    Q = dt * np.eye(12)
    for u in range(len(a)):
        H = measurement_matrix(a[u], m[u] if literal else 1.0)
        Vi = np.eye(3) / (m[u] * sv**2)
        L = np.linalg.inv(np.eye(12) - theta * Q @ P + H.T @ Vi @ H @ P)
        K = P @ L @ H.T @ Vi
        x = x + K @ (b[u] - H @ x)
        P = P @ L + sw**2 * np.eye(12)
    return x, P


def _ref_nlms(a, b, alpha, beta, dt, v0=0.0):
    x, v = identity_state(), np.full(12, v0)
    for u in range(len(a)):
        H = measurement_matrix(a[u])
        xm = x + dt * v
        r = np.linalg.pinv(H) @ (b[u] - H @ xm)
        x = xm + alpha[u] * r
        v = v + beta[u] / dt * r
    return x


@pytest.fixture
def sorted_problem():
    """Small problem whose correspondences are already in processing order."""
    rng = np.random.default_rng(3)
    n = 25
    src = rng.uniform(-1.0, 1.0, (n, 3)) + np.array([4.0, 0.5, -0.5])
    T = from_rt(rotvec_to_matrix(np.deg2rad([3.0, -4.0, 2.0])), [0.1, -0.05, 0.08])
    tgt = transform_points(T, src) + 0.002 * rng.normal(size=(n, 3))
    d = np.sort(rng.uniform(0.02, 0.4, n))
    corr = Correspondences(np.arange(n), np.arange(n), d)
    return src, tgt, corr


@pytest.mark.parametrize(
    ("name", "opts"),
    [
        ("kalman", {}),
        ("kalman", {"joseph": False, "p0": 10.0}),
        ("kalman", {"paper_literal": True}),
        ("kalman", {"paper_literal": True, "adaptive": "per_match", "sigma_w": 0.05}),
        ("hinf", {}),
        ("hinf", {"theta": 5.0, "dt": 1e-3, "p0": 2.0}),
        ("hinf", {"paper_literal": True, "adaptive": "per_match"}),
        ("alphabeta", {}),
        ("alphabeta", {"alpha": 1.2, "beta": 0.3, "dt": 0.5}),
        ("sdre", {"sigma_w_sdre": 0.5}),
    ],
)
def test_kernels_match_dense_numpy_reference(name, opts, sorted_problem):
    src, tgt, corr = sorted_problem
    a, b = tgt[corr.tgt_idx], src[corr.src_idx]  # a ∈ P_k (target) builds H, ψ = b ∈ P_{k+1}
    nlms = {"average": False, "normalise": "sample"}
    single = {"n_passes": 1} | (nlms if name in ("alphabeta", "sdre") else {})
    est = get_estimator(name, **{"center": False, **single, **opts})  # raw-coordinate kernels
    m = adaptive_factors(corr.distance, est.adaptive, scale=est.m_scale, m_min=est.m_min)
    lit = est.paper_literal
    if name == "kalman":
        x_ref, _ = _ref_kalman(a, b, m, est.sigma_v, est.sigma_w, est.p0, lit, est.joseph)
    elif name == "hinf":
        x_ref, _ = _ref_hinf(a, b, m, est.sigma_v, est.sigma_w, est.p0, est.theta, est.dt, lit)
    elif name == "alphabeta":
        x_ref = _ref_nlms(a, b, est.alpha / (1 + m), est.beta / (1 + m), est.dt)
    else:
        _, g = est.gains(m)
        x_ref = _ref_nlms(a, b, g, np.zeros_like(g), 1.0)
    e = est.estimate(src, tgt, corr)
    assert e.status == "ok"
    assert e.info.get("theta_halvings", 0) == 0
    np.testing.assert_allclose(e.info["x_raw"], x_ref, rtol=1e-8, atol=1e-10)


def test_kalman_covariance_matches_reference_P(sorted_problem):
    """The mapped covariance is J P Jᵀ of the reference P (same P as the dense Joseph form)."""
    from relnav.estimation._recursive import state_covariance_to_twist

    src, tgt, corr = sorted_problem
    a, b = tgt[corr.tgt_idx], src[corr.src_idx]
    m = adaptive_factors(corr.distance, "per_match")
    x_ref, P_ref = _ref_kalman(a, b, m, 1.0, 5e-3, 1.0, False)
    kal = get_estimator("kalman", center=False, n_passes=1, projection="frobenius")
    e = kal.estimate(src, tgt, corr)
    np.testing.assert_allclose(
        e.covariance, state_covariance_to_twist(x_ref, P_ref), rtol=1e-6, atol=1e-9
    )


# --------------------------------------------------------------------------------------------
# accuracy
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ALL)
def test_exact_recovery_of_random_rigid_transform(name):
    """≥ 20 exact correspondences, uniformly random rotation: < 0.1° and < 1 mm.

    Options (EXACT_OPTS): Kalman/H∞ p0 = 1e6 (removes the prior's pull to the identity);
    αβ/SDRE centred data + up to 500 sweeps (NLMS needs several sweeps; SDRE also σ_w_sdre = 0.5).
    """
    for seed in range(5):
        rng = np.random.default_rng(100 + seed)
        n = 20
        src = rng.uniform(-1.0, 1.0, (n, 3)) + np.array([10.0, 0.0, 0.0])
        T = random_transform(rng, max_translation=1.0)
        corr = Correspondences(np.arange(n), np.arange(n), rng.uniform(0.05, 0.3, n))
        est = get_estimator(name, **EXACT_OPTS[name]).estimate(src, transform_points(T, src), corr)
        assert est.status == "ok" and est.converged and est.n_used == n
        rot, trans = _errors(est.T_target_source, T)
        assert rot < 0.1, (seed, rot)
        assert trans < 1e-3, (seed, trans)
        assert est.info["rmse"] < 1e-3


# Tolerances reached with Paper 1's defaults (single pass from the identity) on a 2° / 5 cm
# inter-frame motion, 50 correspondences on a 2 m target 10 m ahead, 10 seeds (max over seeds):
#   kalman, hinf: rotation error ≤ 0.27°, translation error ≤ 4.8 cm — the prior P0 = I with
#       σ_v = 1 regularises the 12-state towards the identity; rotation and translation columns
#       are strongly correlated at 10 m range, so almost none of the translation is recovered.
#   alphabeta:    rotation error ≤ 1.8° (mean ≈ 1.2°), translation ≤ 5.2 cm — one NLMS sweep of
#       50 updates with α ≈ 0.5/(1+M) on badly conditioned (uncentred) data.
#   sdre:         stays within 0.01° of the identity — the DARE gain with σ_w = 5e-3 is ≈ 2e-5.
DEFAULT_TOLERANCE = {
    "kalman": (0.3, 0.05),
    "hinf": (0.3, 0.05),
    "alphabeta": (1.9, 0.055),
}


@pytest.mark.parametrize("name", FILTERS)
def test_paper_gains_in_raw_coordinates_on_small_realistic_motion(name):
    """Paper 1's gains on raw sensor-frame coordinates (``center=False``, SDRE σ_w = 5e-3)."""
    rot_err, trans_err = [], []
    for seed in range(10):
        src, tgt, corr, T = _realistic(seed)
        raw = {"center": False, "n_passes": 1} | ({"sigma_w_sdre": 5e-3} if name == "sdre" else {})
        raw |= {"average": False, "normalise": "sample"} if name in ("alphabeta", "sdre") else {}
        est = get_estimator(name, **raw).estimate(src, tgt, corr)
        assert est.status == "ok"
        r, t = _errors(est.T_target_source, T)
        rot_err.append(r)
        trans_err.append(t)
    rot_err, trans_err = np.array(rot_err), np.array(trans_err)
    if name == "sdre":
        assert np.all(np.abs(rot_err - 2.0) < 0.01)  # essentially the identity
        return
    rot_tol, trans_tol = DEFAULT_TOLERANCE[name]
    assert rot_err.max() < rot_tol
    assert trans_err.max() < trans_tol
    assert rot_err.mean() < (0.2 if name in ("kalman", "hinf") else 1.4)  # better than identity


def test_paper_defaults_improve_with_more_correspondences():
    """Kalman: the pull towards the prior shrinks as |Ω| grows (Paper 1's cardinality remark)."""
    errs = []
    for n in (50, 500):
        src, tgt, corr, T = _realistic(0, n=n)
        kalman = get_estimator("kalman", center=False, n_passes=1)
        errs.append(_errors(kalman.estimate(src, tgt, corr).T_target_source, T))
    assert errs[1][0] < 0.5 * errs[0][0]
    assert errs[1][1] < errs[0][1]


@pytest.mark.parametrize("name", ALL)
def test_output_is_a_proper_rotation_with_noise_and_outliers(name):
    rng = np.random.default_rng(5)
    src, tgt, corr, _ = _realistic(1, n=60)
    tgt = tgt + 0.01 * rng.normal(size=tgt.shape)
    tgt[:10] = rng.uniform(-1, 1, (10, 3)) + np.array([10.0, 0.0, 0.0])  # gross outliers
    for opts in ({}, {"paper_literal": True} if name != "svd" else {"weights": "inverse"}):
        est = get_estimator(name, **opts).estimate(src, tgt, corr)
        if est.status != "ok":
            continue
        R = est.T_target_source[:3, :3]
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-10)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-10)
        np.testing.assert_array_equal(est.T_target_source[3], [0.0, 0.0, 0.0, 1.0])


def test_svd_inverse_weights_downweight_bad_matches():
    rng = np.random.default_rng(9)
    src, tgt, _, T = _realistic(2, n=40)
    d = np.full(40, 0.05)
    d[:5] = 5.0  # five poor matches …
    tgt = tgt.copy()
    tgt[:5] += rng.normal(scale=0.3, size=(5, 3))  # … that are also wrong
    corr = Correspondences(np.arange(40), np.arange(40), d)
    plain = _errors(get_estimator("svd").estimate(src, tgt, corr).T_target_source, T)
    weighted = _errors(
        get_estimator("svd", weights="inverse").estimate(src, tgt, corr).T_target_source, T
    )
    assert weighted[0] < 0.1 * plain[0] and weighted[1] < 0.1 * plain[1]


# --------------------------------------------------------------------------------------------
# filter-specific behaviour
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("a", "b", "q", "r"),
    [(5e-3, 1.0, 5e-3, 1.0), (5e-3, 3.0, 5e-3, 1.0), (0.5, 0.2, 0.5, 1.0), (0.9, 2.0, 0.1, 0.3)],
)
def test_sdre_closed_form_matches_solve_discrete_are(a, b, q, r):
    eye = np.eye(12)
    X = solve_discrete_are(a * eye, b * eye, q * eye, r * eye)
    xi = float(sdre_xi(a, b, q, r))
    np.testing.assert_allclose(X, xi * eye, rtol=1e-9, atol=1e-14)
    # the scalar gain equals (BᵀXB + R)⁻¹ BᵀXA
    G = np.linalg.solve(b * b * X + r * eye, b * X * a)
    np.testing.assert_allclose(G, float(sdre_gain(np.asarray(xi), a, np.asarray(b), r)) * eye)


def test_sdre_printed_riccati_has_zero_solution():
    """Eq. 26 as printed (no +Q): ξ = 0 for σ_w < 1, and the root r(a²−1)/b² otherwise."""
    for a, b, r in [(5e-3, 2.0, 1.0), (1.5, 2.0, 0.5)]:
        xi = float(sdre_xi(a, b, a, r, include_q=False))
        resid = a * a * xi - xi - a * a * b * b * xi * xi / (b * b * xi + r)
        assert abs(resid) < 1e-12 and xi >= 0
    assert float(sdre_xi(5e-3, 2.0, 5e-3, 1.0, include_q=False)) == 0.0


def test_sdre_gain_dependence_on_adaptive_factor():
    """B = M I (eq. 26 as printed, ``m_role="input"``): g(M) = Mξa/(M²ξ + r) vanishes for
    M → 0 and M → ∞ (peak near M ≈ 1 for σ_w_sdre = 0.5), so the best matches are ignored.
    R = M σ_v² I (default ``m_role="noise"``, the common setting's V): g decreases with M."""
    m = np.array([1e-3, 0.1, 1.0, 10.0, 100.0])
    _, g = get_estimator("sdre", sigma_w_sdre=0.5, m_role="input").gains(m)
    assert g[2] > 0.1 and g[0] < 1e-3 and g[4] < 1e-2
    _, g = get_estimator("sdre", sigma_w_sdre=0.5).gains(m)
    assert np.all(np.diff(g) < 0) and g[0] > 0.4
    _, g_paper = get_estimator("sdre", sigma_w_sdre=5e-3, m_role="input").gains(np.array([1.0]))
    assert 1e-5 < g_paper[0] < 1e-4  # Paper 1's σ_w = 5e-3: tiny gain


def test_hinf_existence_condition_halves_theta(caplog):
    src, tgt, corr, _ = _realistic(3)
    with caplog.at_level(logging.WARNING, logger="relnav.estimation.hinf"):
        est = get_estimator("hinf", theta=1e5, dt=1.0).estimate(src, tgt, corr)
    assert est.status == "ok"
    assert est.info["theta_halvings"] > 0
    assert any("existence condition" in r.getMessage() for r in caplog.records)
    assert np.isfinite(est.covariance).all()
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="relnav.estimation.hinf"):
        default = get_estimator("hinf").estimate(src, tgt, corr)
    assert default.info["theta_halvings"] == 0
    assert not caplog.records


def test_hinf_is_nearly_kalman_at_paper_values():
    src, tgt, corr, _ = _realistic(4)
    h = get_estimator("hinf").estimate(src, tgt, corr).T_target_source
    k = get_estimator("kalman").estimate(src, tgt, corr).T_target_source
    assert np.rad2deg(rotation_angle(h[:3, :3].T @ k[:3, :3])) < 1e-3
    assert np.linalg.norm(h[:3, 3] - k[:3, 3]) < 1e-4


def test_refit_t_is_consistent_with_projected_rotation():
    src, tgt, corr, _ = _realistic(5)
    est = get_estimator("kalman", refit_t=True).estimate(src, tgt, corr)
    # T_source_target = inverse; its t must equal mean(b − R a)
    Tst = np.linalg.inv(est.T_target_source)
    a, b = tgt[corr.tgt_idx], src[corr.src_idx]
    np.testing.assert_allclose(Tst[:3, 3], (b - a @ Tst[:3, :3].T).mean(axis=0), atol=1e-12)


def test_multi_pass_and_converged_flag():
    src, tgt, corr, T = _realistic(6)
    capped = get_estimator("alphabeta", n_passes=3, tol=0.0).estimate(src, tgt, corr)
    assert capped.info["passes"] == 3 and not capped.converged
    full = get_estimator("alphabeta", n_passes=500, center=True).estimate(src, tgt, corr)
    assert full.converged and full.info["passes"] < 500
    assert _errors(full.T_target_source, T)[0] < _errors(capped.T_target_source, T)[0]
    single = get_estimator("alphabeta", n_passes=1).estimate(src, tgt, corr)
    assert single.converged and single.info["passes"] == 1  # 1 sweep = Paper 1, complete
    default = get_estimator("alphabeta").estimate(src, tgt, corr)  # converges by default
    assert default.converged and default.info["converged"] and 1 < default.info["passes"] < 200


@pytest.mark.parametrize("name", FILTERS)
def test_warm_start_keeps_previous_estimate(name):
    src, tgt, corr, T = _realistic(7)
    opts = {"sigma_w_sdre": 0.5} if name == "sdre" else {}
    est = get_estimator(name, warm_start=True, n_passes=1, **opts)  # one sweep: not converged
    first = est.estimate(src, tgt, corr)
    second = est.estimate(src, tgt, corr)
    assert _errors(second.T_target_source, T)[0] < _errors(first.T_target_source, T)[0]
    est.reset()
    np.testing.assert_array_equal(
        est.estimate(src, tgt, corr).T_target_source, first.T_target_source
    )
    # a degenerate pair does not overwrite the stored state
    est.reset()
    est.estimate(src, tgt, corr)
    est.estimate(src, tgt, corr.subset(np.arange(2)))
    np.testing.assert_array_equal(
        est.estimate(src, tgt, corr).T_target_source, second.T_target_source
    )


def test_cold_start_does_not_carry_state():
    src, tgt, corr, _ = _realistic(8)
    est = get_estimator("alphabeta")
    first = est.estimate(src, tgt, corr)
    np.testing.assert_array_equal(
        est.estimate(src, tgt, corr).T_target_source, first.T_target_source
    )


# --------------------------------------------------------------------------------------------
# paper-literal modes (§D.2)
# --------------------------------------------------------------------------------------------


def test_sdre_literal_keeps_initialisation():
    src, tgt, corr, _ = _realistic(0)
    est = get_estimator("sdre", paper_literal=True).estimate(src, tgt, corr)
    assert est.status == "ok"
    np.testing.assert_array_equal(est.info["x_raw"], identity_state())
    np.testing.assert_allclose(est.T_target_source, np.eye(4), atol=1e-15)


def test_alphabeta_literal_ignores_the_measurements():
    src, tgt, corr, _ = _realistic(0)
    src2, tgt2, _, _ = _realistic(1)  # other points, same descriptor distances
    lit = get_estimator("alphabeta", paper_literal=True, adaptive="per_match")
    e1 = lit.estimate(src, tgt, corr)
    e2 = lit.estimate(src2, tgt2, corr)
    assert e1.info["x_raw"] == e2.info["x_raw"]
    # eq. 11 as printed (M = 10·Σd ≈ 90 ≫ 4): the printed recursion diverges → flagged
    diverged = get_estimator("alphabeta", paper_literal=True).estimate(src, tgt, corr)
    assert diverged.status == "failed"
    np.testing.assert_array_equal(diverged.T_target_source, np.eye(4))


def test_alphabeta_literal_printed_recursion_by_hand():
    """Eqs. 22–25 for one component, two steps, β = M = 2, V₀ = 1."""
    src, tgt, _, _ = _realistic(0, n=6)
    corr = Correspondences(np.arange(6), np.arange(6), np.full(6, 0.2))  # M_u = 2
    alpha, dt = 1e-6, 1e-5
    xk, v = 1.0, 1.0
    xs = []
    for _ in range(6):
        xp = xk
        xk = xp + v * dt
        r = xp - xk
        xk = xk + alpha * r
        v = v - 2.0 / dt * xk
        xs.append(xk)
    e = get_estimator("alphabeta", paper_literal=True, adaptive="per_match").estimate(
        src, tgt, corr
    )
    assert e.info["x_raw"][0] == pytest.approx(xs[-1], rel=1e-12)


@pytest.mark.parametrize("name", ["kalman", "hinf"])
def test_kalman_hinf_literal_shrink_towards_model_scale(name):
    """Printed H = M·H_u: with M = 10·Σd ≫ 1 the state fits ψ = M(R a + t), i.e. R̂ ≈ R/M."""
    src, tgt, corr, _ = _realistic(0)
    e = get_estimator(name, paper_literal=True).estimate(src, tgt, corr)
    assert e.status == "ok"
    x = np.asarray(e.info["x_raw"])
    m_sum = 10.0 * corr.distance.sum()  # ≈ 94
    # ‖R̂‖_F ≈ ‖R‖_F / M = √3 / M (the SO(3) projection is scale-free, so R is still usable)
    assert 0.8 * np.sqrt(3) < np.linalg.norm(x[:9]) * m_sum < 1.2 * np.sqrt(3)


# Coherent defaults (centred points; SDRE σ_w = 0.5), same problems as above, worst of 10 seeds
# (measured: kalman/hinf ≤ 0.232°, ≤ 3.4 cm; alphabeta ≤ 0.92°, sdre ≤ 0.88°, ≤ 26 cm — one NLMS
# sweep of 50 updates recovers ≈ 65 % of the rotation; the residual rotation error, lever-armed
# by the 10 m range through t = b̄ − R̂ā, dominates the translation error).
COHERENT_TOLERANCE = {
    "kalman": (0.25, 0.035),
    "hinf": (0.25, 0.035),
    "alphabeta": (1.0, 0.27),
    "sdre": (1.0, 0.27),
}


@pytest.mark.parametrize("name", FILTERS)
def test_coherent_defaults_on_small_realistic_motion(name):
    rot_err, trans_err = [], []
    for seed in range(10):
        src, tgt, corr, T = _realistic(seed)
        est = get_estimator(name).estimate(src, tgt, corr)
        assert est.status == "ok"
        r, t = _errors(est.T_target_source, T)
        rot_err.append(r)
        trans_err.append(t)
    rot_tol, trans_tol = COHERENT_TOLERANCE[name]
    assert max(rot_err) < rot_tol
    assert max(trans_err) < trans_tol
    assert np.mean(rot_err) < 0.5 * 2.0  # recovers more than half of the 2° rotation
