"""The navigator's compiled per-frame kernels against their NumPy definitions.

Session 29 moved the motion filter, the map's insert, the step's integrity figures and a few scan
figures into numba. Each test here writes the quantity as plain NumPy (the formulas the navigator
used before) and checks the kernel against it: to rounding where the order of the arithmetic
changed, exactly where it did not (the map's counts and sums, the medians).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from relnav.geometry.lie import adjoint_nb, exp_se3, invert_nb, log_se3
from relnav.geometry.rotations import random_rotation
from relnav.geometry.se3 import adjoint, invert
from relnav.navigation.gicp import degeneracy, left_information, motion_chi2
from relnav.navigation.integrity import exceedance_probability, step_sigmas
from relnav.navigation.motion import ConstantVelocityFilter
from relnav.navigation.options import SolverOptions
from relnav.navigation.repeated import RepeatedPoints
from relnav.navigation.solver import median, rms_radius
from relnav.navigation.voxel_map import VoxelMap


def _pose(rng: np.random.Generator, scale: float = 20.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = random_rotation(rng)
    T[:3, 3] = rng.uniform(-scale, scale, 3)
    return T


def _spd(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    A = rng.normal(size=(n, n)) * scale
    return A @ A.T + 1e-3 * scale**2 * np.eye(n)


def test_invert_and_adjoint_match_the_numpy_ones() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        T = _pose(rng)
        np.testing.assert_allclose(invert_nb(T), invert(T), atol=1e-12)
        np.testing.assert_allclose(adjoint_nb(T), adjoint(T), atol=1e-12)


def _reference_predict(f: ConstantVelocityFilter, t: float) -> tuple[np.ndarray, np.ndarray]:
    """The filter's prediction in NumPy (the module doc's formulas)."""
    dt = t - f.t
    step = exp_se3(f.velocity * dt)
    F = np.eye(12)
    F[:6, :6] = adjoint(invert(step))
    F[:6, 6:] = dt * np.eye(6)
    Q = np.zeros((12, 12))
    sa2 = f.q_scale * f.sigma_acc**2
    Q[6:, 6:] = np.diag(sa2)
    Q[:6, :6] = np.diag(sa2 * dt**2) / 3.0
    P = F @ f.P @ F.T + Q
    P[3:6, 3:6] += f.jitter_var * np.eye(3)
    return f.pose @ step, 0.5 * (P + P.T)


def _filter(rng: np.random.Generator) -> ConstantVelocityFilter:
    f = ConstantVelocityFilter(_pose(rng), 0.0, np.full(6, 0.2), np.array([0.05] * 3 + [0.01] * 3))
    f.velocity = rng.normal(size=6) * np.array([1, 1, 1, 0.05, 0.05, 0.05])
    f.P = _spd(rng, 12, 0.05)
    f.jitter_var = 1e-5
    return f


def test_prediction_matches_its_definition() -> None:
    rng = np.random.default_rng(1)
    for _ in range(10):
        f = _filter(rng)
        T_ref, P_ref = _reference_predict(f, 2.0)
        T, P_pp = f.predict(2.0)
        np.testing.assert_allclose(T, T_ref, atol=1e-10)
        np.testing.assert_allclose(P_pp, P_ref[:6, :6], rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(f._pred[1], P_ref, rtol=1e-10, atol=1e-14)


def test_update_matches_its_definition() -> None:
    """The velocity by Gaussian conditioning and ``P − P_{:,p} G P_{p,:}`` with
    ``G = H (P_pp H + I)⁻¹``, ``H`` the scan's left information moved to the body frame, and the
    step's covariance from the clone."""
    rng = np.random.default_rng(2)
    for _ in range(10):
        f = _filter(rng)
        prev_pose = f.pose.copy()
        P0 = f.P.copy()
        T_pred, _ = f.predict(1.0)
        P = f._pred[1]
        F = f._F
        T_star = T_pred @ exp_se3(rng.normal(size=6) * 0.01)
        H_left = _spd(rng, 6, 30.0)
        v0 = f.velocity.copy()
        f.update(T_star, H_left)
        Ad = adjoint(T_star)
        H = Ad.T @ H_left @ Ad
        y = log_se3(invert(T_pred) @ T_star)
        v_ref = v0 + P[6:, :6] @ np.linalg.solve(P[:6, :6], y)
        G = H @ np.linalg.inv(P[:6, :6] @ H + np.eye(6))
        P_post = P - P[:, :6] @ G @ P[:6, :]
        # the posterior is a difference of terms of P's size: rounding relative to that size
        tol = 1e-10 * float(np.abs(P).max())
        np.testing.assert_allclose(f.velocity, v_ref, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(f.P, 0.5 * (P_post + P_post.T), rtol=0, atol=tol)
        C = F @ P0[:, :6]
        C_post = C - P[:, :6] @ G @ C[:6, :]
        A = adjoint(invert(invert(prev_pose) @ T_star))
        X = C_post[:6, :] @ A.T
        S = P_post[:6, :6] + A @ P0[:6, :6] @ A.T - X - X.T
        np.testing.assert_allclose(f.step_covariance, 0.5 * (S + S.T), rtol=0, atol=tol)


def test_a_singular_update_keeps_the_prediction() -> None:
    """``P_pp`` singular (the numpy solve would raise): the velocity and the covariance stay."""
    rng = np.random.default_rng(3)
    f = _filter(rng)
    T_pred, _ = f.predict(1.0)
    P_pred = f._pred[1].copy()
    P_pred[:6, :] = 0.0
    P_pred[:, :6] = 0.0
    f._pred = (T_pred, P_pred, f._pred[2])
    v0 = f.velocity.copy()
    f.update(T_pred, np.eye(6))
    np.testing.assert_array_equal(f.velocity, v0)
    np.testing.assert_allclose(f.P, P_pred)


def _reference_insert(
    vm: dict[int, list[float]], points: np.ndarray, voxel: float, max_weight: float
) -> None:
    """The voxel map's running sums in plain Python: per cell (in point order) the count and
    the sum, the old ones scaled down when the weight would pass ``max_weight``."""
    cells: dict[tuple[int, ...], list[float]] = {}
    for p in points:
        key = tuple(np.floor(p / voxel).astype(np.int64))
        c = cells.setdefault(key, [0.0, 0.0, 0.0, 0.0])
        c[0] += 1.0
        for d in range(3):
            c[1 + d] += p[d]
    for key, (w_add, *s_add) in cells.items():
        w_old, *s_old = vm.get(key, [0.0, 0.0, 0.0, 0.0])
        scale = 1.0
        if w_old + w_add > max_weight:
            scale = max(max_weight - w_add, 0.0) / max(w_old, 1e-12)
        w_new = w_old * scale + w_add
        cap = min(1.0, max_weight / max(w_new, 1e-12))
        vm[key] = [w_new * cap] + [(s_old[d] * scale + s_add[d]) * cap for d in range(3)]


def test_map_insert_matches_the_running_sums_exactly() -> None:
    rng = np.random.default_rng(4)
    voxel, max_weight = 0.5, 5.0
    vm = VoxelMap(voxel, max_weight=max_weight)
    ref: dict[tuple[int, ...], list[float]] = {}
    for frame in range(8):
        P = rng.uniform(-3, 3, (200, 3))
        vm.insert(P, frame)
        _reference_insert(ref, P, voxel, max_weight)
    keys = np.floor(vm.means / voxel).astype(np.int64)
    assert len(vm) == len(ref)
    for k, w, mu in zip(map(tuple, keys), vm.weights, vm.means, strict=True):
        w_ref, *s_ref = ref[k]
        assert w == w_ref  # bit for bit: the same additions in the same order
        np.testing.assert_array_equal(mu, np.array(s_ref) / w_ref)
    # the sorted index finds every voxel
    codes = vm._codes
    assert np.all(np.diff(codes) > 0) and len(codes) == len(vm)


def test_median_is_numpys() -> None:
    rng = np.random.default_rng(5)
    for n in (1, 2, 3, 10, 11, 301):
        x = rng.normal(size=n)
        assert median(x) == float(np.median(x))
    assert np.isnan(median(np.zeros(0)))


def test_rms_radius_is_the_rms_distance_from_the_centroid() -> None:
    rng = np.random.default_rng(6)
    P = rng.normal(size=(500, 3)) * [3.0, 1.0, 0.2] + 40.0
    ref = float(np.sqrt(np.mean(np.sum((P - P.mean(0)) ** 2, axis=1))))
    assert rms_radius(P) == pytest.approx(ref, rel=1e-12)
    assert np.isnan(rms_radius(np.zeros((0, 3))))


def test_integrity_figures_match_their_definitions() -> None:
    rng = np.random.default_rng(7)
    for _ in range(10):
        C = _spd(rng, 6, 0.1)
        s_t, s_r = step_sigmas(C)
        assert s_t == pytest.approx(np.sqrt(np.linalg.eigvalsh(C[:3, :3])[-1]), rel=1e-12)
        assert s_r == pytest.approx(np.sqrt(np.linalg.eigvalsh(C[3:, 3:])[-1]), rel=1e-12)
        H, r = _spd(rng, 6, 10.0), 3.0
        sc = 1.0 / np.array([1, 1, 1, r, r, r])
        ev = np.linalg.eigvalsh(H * sc[:, None] * sc[None, :])
        assert degeneracy(H, r) == pytest.approx(ev[0] / ev[-1], rel=1e-9)
        T, T_pred, Lam = _pose(rng), _pose(rng), _spd(rng, 6)
        xi = log_se3(T @ invert(T_pred))
        assert motion_chi2(T, T_pred, Lam) == pytest.approx(xi @ Lam @ xi, rel=1e-10)
        Ad = adjoint(T)
        S = Ad @ C @ Ad.T
        np.testing.assert_allclose(
            left_information(T, C), np.linalg.pinv(0.5 * (S + S.T)), rtol=1e-8, atol=1e-8
        )
    bad = np.full((6, 6), np.nan)
    assert all(np.isnan(step_sigmas(bad)))
    assert degeneracy(bad, 1.0) == 0.0
    assert exceedance_probability(bad, 0.5, 0.1) == 1.0


def _reference_evidence(
    Q: np.ndarray, T_prev: np.ndarray, P: np.ndarray, T: np.ndarray, sig: float, s0: float
) -> float:
    """:meth:`RepeatedPoints.evidence` on SciPy's KD-tree (its implementation before session 29)."""
    tree = cKDTree(Q @ T_prev[:3, :3].T + T_prev[:3, 3])
    X = P @ T[:3, :3].T + T[:3, 3]
    d, j = tree.query(X, k=min(4, tree.n), distance_upper_bound=s0)
    ok = np.isfinite(d)
    D = tree.data[np.where(ok, j, 0)] - X[:, None, :]
    ray = X - T[:3, 3]
    ray /= np.linalg.norm(ray, axis=1)[:, None]
    along = np.einsum("nkj,nj->nk", D, ray)
    across2 = np.einsum("nkj,nkj->nk", D, D) - along**2
    return float(np.count_nonzero((ok & (across2 < sig**2)).any(axis=1))) / len(P)


def test_repeated_point_evidence_matches_scipys_search() -> None:
    rng = np.random.default_rng(8)
    Q = rng.normal(size=(400, 3)) * 2.0 + [0.0, 0.0, 30.0]
    T_prev = np.eye(4)
    T = _pose(rng, 0.0)
    T[:3, :3] = np.eye(3)
    T[:3, 3] = [0.02, -0.01, 0.0]
    # half the new scan repeats the previous points (seen from the moved pose), half is fresh
    P = np.vstack([Q[:200] - T[:3, 3], rng.normal(size=(200, 3)) * 2.0 + [0.0, 0.0, 30.0]])
    P[:200] += rng.normal(size=(200, 3)) * 0.002
    rp = RepeatedPoints(SolverOptions())
    rp.remember(Q, T_prev)
    s0, sig = 0.2, 0.02
    got = rp.evidence(P, T, sig, s0)
    assert got == _reference_evidence(Q, T_prev, P, T, sig, s0)
    assert 0.4 <= got <= 0.6  # the repeated half, not the fresh one


def test_map_insert_drops_points_beyond_the_cell_range() -> None:
    """Cells beyond ±2²⁰ per axis (and non-finite points) cannot be packed: they are dropped, the
    others inserted as usual."""
    vm = VoxelMap(0.5)
    P = np.array([[0.1, 0.2, 0.3], [1e9, 0.0, 0.0], [np.nan, 0.0, 0.0], [-0.7, 0.2, 0.3]])
    vm.insert(P, 0)
    assert len(vm) == 2
    np.testing.assert_allclose(np.sort(vm.means[:, 0]), [-0.7, 0.1])
    vm.insert(np.array([[2e9, 0.0, 0.0]]), 1)  # nothing left to insert: unchanged
    assert len(vm) == 2
