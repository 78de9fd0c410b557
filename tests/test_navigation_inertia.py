"""A tumbling target's inertia from its body rates (relnav.navigation.state.inertia) and the UKF's
torque-free prediction (TwistorUKF(inertia=…))."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from relnav.errors import ConfigError, InputError
from relnav.filtering.ukf import TwistorUKF, euler_rates
from relnav.navigation.state.inertia import InertiaFit, fit_inertia, rate_sweep_deg, refine_inertia


def _tumble(J: np.ndarray, w0: np.ndarray, t: np.ndarray) -> np.ndarray:
    sol = solve_ivp(
        lambda _, w: np.linalg.solve(J, np.cross(J @ w, w)),
        (t[0], t[-1]),
        w0,
        t_eval=t,
        rtol=1e-10,
        atol=1e-13,
    )
    return sol.y.T


def _body_inertia(rng) -> np.ndarray:
    R = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
    return R @ np.diag([0.3, 1.8, 2.0]) @ R.T


def test_euler_rates_is_the_torque_free_motion(rng):
    J = _body_inertia(rng)
    w0 = np.radians([0.4, 0.9, 1.2])
    t = np.array([0.0, 7.0])
    ref = _tumble(J, w0, t)[-1]
    out = euler_rates(w0[None], J, 7.0)[0]
    np.testing.assert_allclose(out, ref, atol=1e-9)
    # angular momentum and energy are kept; a sphere does not turn the rate
    assert np.linalg.norm(J @ out) == pytest.approx(np.linalg.norm(J @ w0), rel=1e-9)
    assert out @ J @ out == pytest.approx(w0 @ J @ w0, rel=1e-9)
    np.testing.assert_allclose(euler_rates(w0[None], np.eye(3), 7.0)[0], w0)
    # one inertia per rate: the same motions
    both = euler_rates(np.stack([w0, 2.0 * w0]), np.stack([J, np.eye(3)]), 7.0)
    np.testing.assert_allclose(both, [out, 2.0 * w0], atol=1e-12)


def test_fit_inertia_recovers_the_shape_of_a_tumble(rng):
    J = _body_inertia(rng)
    t = np.arange(0.0, 400.0, 2.0)
    w = _tumble(J, np.radians([0.3, 0.4, 1.2]), t)
    fit = fit_inertia(t, w + rng.normal(scale=np.radians(0.005), size=w.shape))
    assert fit is not None and fit.sweep_deg > 10.0
    true = J / np.linalg.det(J) ** (1.0 / 3.0)
    np.testing.assert_allclose(fit.principal, np.linalg.eigvalsh(true), rtol=0.05)
    assert np.linalg.det(fit.inertia) == pytest.approx(1.0)
    assert 0.0 < fit.residual < np.radians(0.002)
    # a spin about a principal axis does not reveal it; NaN rows are skipped
    axis = np.linalg.eigh(J)[1][:, 0]
    spin = np.tile(np.radians(1.0) * axis, (len(t), 1))
    assert rate_sweep_deg(spin) < 1e-6 and fit_inertia(t, spin) is None
    w_nan = w.copy()
    w_nan[::7] = np.nan
    assert fit_inertia(t, w_nan) is not None
    with pytest.raises(InputError):
        fit_inertia(t, w[:, :2])
    with pytest.raises(InputError):
        fit_inertia(t, w, window_s=0.0)


def _attitudes(w: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Body attitudes ``R_sensor_body`` (xyzw) of a sensor holding an inertial attitude, turned
    by the mean rate of each step (as the UKF does)."""
    R = [Rotation.identity()]
    for k in range(1, len(t)):
        R.append(R[-1] * Rotation.from_rotvec(0.5 * (w[k - 1] + w[k]) * (t[k] - t[k - 1])))
    return np.stack([r.as_quat() for r in R])


def test_refine_inertia_reads_the_shape_from_the_attitudes(rng):
    """A rate fit whose smallest moment is 29 % off (a lagging filter's) is brought back to the
    tumble's shape by the attitudes; observation outliers do not pull it away."""
    J = _body_inertia(rng)
    true = np.linalg.eigvalsh(J / np.linalg.det(J) ** (1.0 / 3.0))
    t = np.arange(0.0, 380.0, 2.0)
    w = _tumble(J, np.radians([0.3, 0.4, 1.2]), t)
    q = _attitudes(w, t)
    noise = Rotation.from_rotvec(rng.normal(scale=np.radians(0.3), size=(len(t), 3)))
    observed = (Rotation.from_quat(q) * noise).as_quat()
    observed[::17] = (Rotation.from_quat(q[::17]) * Rotation.from_rotvec([0.2, 0.0, 0.0])).as_quat()
    observed[5::9] = np.nan
    lam, V = np.linalg.eigh(J)
    biased = (V * (lam * [0.6, 1.0, 1.0])) @ V.T
    start = InertiaFit(biased / np.linalg.det(biased) ** (1.0 / 3.0), 1e-5, 90.0)
    assert abs(start.principal[0] / true[0] - 1.0) > 0.25
    rates = w + rng.normal(scale=np.radians(0.01), size=w.shape)
    fit = refine_inertia(start, t, observed, q, rates)
    assert fit is not None
    np.testing.assert_allclose(fit.principal, true, rtol=0.03)
    assert np.linalg.det(fit.inertia) == pytest.approx(1.0)
    assert 0.0 < fit.residual < np.radians(0.002)
    # too few observed attitudes: no refinement; shapes are checked
    few = np.full_like(observed, np.nan)
    few[:11] = observed[:11]
    assert refine_inertia(start, t, few, q, rates) is None
    unset = rates.copy()
    unset[0] = np.nan
    assert refine_inertia(start, t, observed, q, unset) is None
    with pytest.raises(InputError):
        refine_inertia(start, t, observed[:, :3], q, rates)
    with pytest.raises(InputError):
        refine_inertia(start, t, observed, q[:-1], rates)


def test_ukf_inertia_option_turns_the_rate_and_is_checked(rng):
    J = _body_inertia(rng)
    w0 = np.radians([0.3, 0.4, 1.2])
    tight = {"omega": 1e-7}  # the sigma points' spread would move the mean of a nonlinear step
    ukf = TwistorUKF(dt=2.0, omega0=w0, inertia=5.0 * J, p0=tight)  # any scale
    ukf.predict(20.0)
    np.testing.assert_allclose(ukf.omega, _tumble(J, w0, np.array([0.0, 20.0]))[-1], atol=1e-8)
    assert np.linalg.det(np.asarray(ukf.settings()["inertia"])) == pytest.approx(1.0)
    still = TwistorUKF(dt=2.0, omega0=w0, p0=tight)
    still.predict(20.0)
    np.testing.assert_allclose(still.omega, w0)
    assert still.settings()["inertia"] is None
    for bad in (np.eye(2), -np.eye(3), np.array([[1.0, 0.5, 0], [0, 1, 0], [0, 0, 1]]), "big"):
        with pytest.raises(ConfigError):
            TwistorUKF(inertia=bad)


def test_relative_state_rigid_body_identifies_a_tumbling_targets_inertia(rng):
    """relative_state(rigid_body=True) on noisy poses of a torque-free tumble seen from a
    holding sensor: the second pass knows the inertia's shape and its rate error is smaller
    than the first pass's."""
    from types import SimpleNamespace

    from relnav.navigation.state import StateRecord, relative_state

    J = np.diag([0.3, 1.8, 2.0])
    t = np.arange(0.0, 400.0, 2.0)
    w = _tumble(J, np.radians([0.3, 0.4, 1.2]), t)
    R_wb = [np.eye(3)]
    for k in range(1, len(t)):  # the body's attitude, turned by the mean rate of each step
        dR = Rotation.from_rotvec(0.5 * (w[k - 1] + w[k]) * (t[k] - t[k - 1])).as_matrix()
        R_wb.append(R_wb[-1] @ dR)
    sensor = np.array([-50.0, 0.0, 5.0])
    sig_p, sig_r = 0.01, np.radians(0.05)
    frames, truth = [], []
    for k, R in enumerate(R_wb):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R.T, R.T @ sensor
        truth.append(T)
        noisy = T.copy()
        noisy[:3, :3] = (
            T[:3, :3] @ Rotation.from_rotvec(rng.normal(scale=sig_r, size=3)).as_matrix()
        )
        noisy[:3, 3] += rng.normal(scale=sig_p, size=3)
        H = np.diag([sig_p**-2] * 3 + [sig_r**-2] * 3)
        frames.append(StateRecord("first" if k == 0 else "ok", noisy, H, np.eye(6) * 1e-8))
    run = SimpleNamespace(steps=frames, timestamps=t, method="relnav")
    gt = np.stack(truth)
    first = relative_state(run, gt_poses=gt)
    rigid = relative_state(run, gt_poses=gt, rigid_body=True)
    assert rigid.meta["inertia_identified"]
    true = np.diag(J) / np.prod(np.diag(J)) ** (1.0 / 3.0)
    np.testing.assert_allclose(rigid.meta["principal_inertia"], true, rtol=0.1)
    assert rigid.settings["inertia"] is not None
    k0 = len(t) // 3

    def rate_rms(res) -> float:
        return float(np.sqrt(np.mean(np.sum(res.errors()["omega"][k0:] ** 2, axis=1))))

    assert rate_rms(rigid) < 0.5 * rate_rms(first)


def test_rigid_body_pass_keeps_the_likelier_second_pass(monkeypatch):
    """Of the passes with the rates' and the attitudes' inertia, the one whose innovations are
    the likelier over the steps both have one is kept; without refinement, the rates' pass."""
    from types import SimpleNamespace

    from relnav.navigation.state import rigid_body

    rates_fit = InertiaFit(np.diag([0.5, 1.0, 2.0]), 1e-5, 30.0)
    attitudes_fit = InertiaFit(np.diag([0.4, 1.25, 2.0]), 2e-5, 30.0)
    monkeypatch.setattr(rigid_body, "fit_inertia", lambda *a, **k: rates_fit)
    monkeypatch.setattr(rigid_body, "refine_inertia", lambda *a, **k: attitudes_fit)
    K = 6
    first = SimpleNamespace(
        time=np.arange(K, dtype=float),
        omega=np.zeros((K, 3)),
        quat=np.tile([0.0, 0.0, 0.0, 1.0], (K, 1)),
        observed=np.zeros((K, 7)),
    )
    # the attitudes' pass is likelier on the common steps; the rates' pass lacks step 5,
    # where the attitudes' pass is very unlikely (not counted)
    ll = {
        id(rates_fit): np.array([np.nan, -3.0, -3.0, -3.0, -3.0, np.nan]),
        id(attitudes_fit): np.array([np.nan, -2.0, -2.0, -2.0, -2.0, -100.0]),
    }

    def run_pass(fit):
        return SimpleNamespace(
            omega=np.zeros((K, 3)), quat=first.quat, log_likelihood=ll[id(fit)], fit=fit
        )

    kept, meta = rigid_body.rigid_body_pass(first, run_pass, skip=1)
    assert kept.fit is attitudes_fit and meta["inertia_source"] == "attitudes"
    assert meta["inertia_log_likelihood"] == {"rates": -12.0, "attitudes": -8.0}
    np.testing.assert_allclose(meta["principal_inertia"], attitudes_fit.principal)
    ll[id(attitudes_fit)][1] = -10.0
    kept, meta = rigid_body.rigid_body_pass(first, run_pass, skip=1)
    assert kept.fit is rates_fit and meta["inertia_source"] == "rates"
    kept, meta = rigid_body.rigid_body_pass(first, run_pass, skip=1, refine=False)
    assert kept.fit is rates_fit and "inertia_log_likelihood" not in meta
