"""Trajectories and pointing: shapes, lengths, closure, CW against an ODE integrator."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from relnav.errors import ConfigError, InputError
from relnav.sim import trajectories as tr


def test_forward_backward_length_and_turnaround():
    p = tr.forward_backward(41, start=(-6.0, 0.0, 0.0), end=(-2.3, 0.0, 0.0))
    assert p.shape == (41, 3)
    np.testing.assert_allclose(p[0], p[-1])
    np.testing.assert_allclose(p[20], [-2.3, 0.0, 0.0])
    assert tr.path_length(p) == pytest.approx(2 * 3.7, rel=1e-12)
    # constant speed
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    np.testing.assert_allclose(steps, steps[0], rtol=1e-9)


@pytest.mark.parametrize("sagitta", [-1.5, 0.7, 3.0, 6.0])
def test_curved_arc_closed_form_length(sagitta):
    a, b = np.array([-3.0, -2.5, 0.5]), np.array([-3.0, 2.5, 0.5])
    p = tr.curved_forward_backward(2001, start=a, end=b, sagitta=sagitta)
    c = np.linalg.norm(b - a)
    R = (c * c / 4 + sagitta**2) / (2 * abs(sagitta))
    theta = 4 * np.arctan(2 * abs(sagitta) / c)
    assert tr.path_length(p) == pytest.approx(2 * R * theta, rel=1e-5)
    np.testing.assert_allclose(p[0], a, atol=1e-12)
    np.testing.assert_allclose(p[1000], b, atol=1e-9)
    # all points at the same distance from the arc centre, in the z = 0.5 plane
    np.testing.assert_allclose(p[:, 2], 0.5, atol=1e-12)
    mid = p[500]  # apex: distance |sagitta| from the chord midpoint
    assert np.linalg.norm(mid - (a + b) / 2) == pytest.approx(abs(sagitta), rel=1e-6)
    # negative sagitta bulges to the right of travel (+y about z) = +x (towards the origin)
    assert np.sign(mid[0] - a[0]) == (1.0 if sagitta < 0 else -1.0)


def test_ellipse_of_inspection_closed_and_perimeter():
    p = tr.ellipse_of_inspection(4001, semi_major=60.0, semi_minor=30.0, tilt_deg=20.0)
    np.testing.assert_allclose(p[0], p[-1], atol=1e-9)
    a, b = 60.0, 30.0
    ramanujan = np.pi * (3 * (a + b) - np.sqrt((3 * a + b) * (a + 3 * b)))
    assert tr.path_length(p) == pytest.approx(ramanujan, rel=1e-4)
    # centred on the target, planar
    np.testing.assert_allclose(p[:-1].mean(axis=0), 0.0, atol=1e-6)
    centred = p - p.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    assert sv[2] < 1e-9 * sv[0]


def test_elliptic_orbit_loops_scale_length():
    one = tr.elliptic_orbit(2001, semi_major=50.0, semi_minor=25.0, loops=1.0)
    two5 = tr.elliptic_orbit(5001, semi_major=50.0, semi_minor=25.0, loops=2.5)
    assert tr.path_length(two5) == pytest.approx(2.5 * tr.path_length(one), rel=1e-4)
    # after 2.5 loops the chaser is on the opposite side
    np.testing.assert_allclose(two5[-1], -two5[0], atol=1e-9)


def test_helix_geometry():
    p = tr.helical_approach(
        361, radius_start=40, radius_end=20, height_start=30, height_end=0, turns=1.0
    )
    rho = np.hypot(p[:, 0], p[:, 1])
    np.testing.assert_allclose(rho[[0, -1]], [40, 20])
    np.testing.assert_allclose(p[[0, -1], 2], [30, 0])
    # one full turn: start and end directions coincide
    np.testing.assert_allclose(p[0, :2] / 40, p[-1, :2] / 20, atol=1e-12)
    # length between a flat spiral and the bound with the height change added
    flat = 2 * np.pi * 30
    assert flat < tr.path_length(p) < np.hypot(flat + 20, 30)


def test_vbar_rbar():
    v = tr.vbar_approach(10, start=-50, stop=-5)
    np.testing.assert_allclose(v[:, [0, 2]], 0)
    np.testing.assert_allclose(v[[0, -1], 1], [-50, -5])
    r = tr.rbar_approach(10, start=-50, stop=-5, profile="exponential")
    np.testing.assert_allclose(r[:, 1:], 0)
    ratios = r[1:, 0] / r[:-1, 0]
    np.testing.assert_allclose(ratios, ratios[0])
    assert tr.path_length(r) == pytest.approx(45.0)
    with pytest.raises(InputError, match="profile"):
        tr.vbar_approach(5, profile="bogus")


def _cw_ode(n):
    def f(_t, s):
        x, _y, z, vx, vy, vz = s
        return [vx, vy, vz, 2 * n * vy + 3 * n * n * x, -2 * n * vx, -n * n * z]

    return f


def test_cw_closed_form_matches_ode():
    n = tr.mean_motion(6_778_137.0)
    assert n == pytest.approx(1.131e-3, rel=1e-3)
    s0 = np.array([20.0, -10.0, 5.0, 0.01, -0.03, 0.02])
    t = np.linspace(0, 4000.0, 41)
    closed = tr.cw_propagate(t, s0, n=n)
    sol = solve_ivp(_cw_ode(n), (0, t[-1]), s0, t_eval=t, rtol=1e-12, atol=1e-12, method="DOP853")
    np.testing.assert_allclose(closed, sol.y.T, atol=1e-6)
    # semigroup property of the STM
    np.testing.assert_allclose(
        tr.cw_stm(n, 700.0) @ tr.cw_stm(n, 300.0), tr.cw_stm(n, 1000.0), atol=1e-9
    )


def test_cw_zero_mean_motion_is_straight_line():
    s0 = np.array([1.0, 2.0, 3.0, 0.1, -0.2, 0.05])
    t = np.linspace(0, 100, 11)
    p = tr.clohessy_wiltshire(t, state0=s0, mean_motion_rad_s=0.0)
    np.testing.assert_allclose(p, s0[:3] + t[:, None] * s0[3:], atol=1e-12)
    # tiny n: closed form tends to the straight line
    p2 = tr.clohessy_wiltshire(t, state0=s0, mean_motion_rad_s=1e-9)
    np.testing.assert_allclose(p2, p, atol=1e-6)


def test_cw_burns_change_the_velocity_at_their_time():
    s0 = np.array([0.0, -50.0, 0.0, 0.0, 0.1, 0.0])
    t = np.arange(0.0, 101.0, 10.0)
    dv = np.array([0.02, 0.1, -0.03])
    p = tr.clohessy_wiltshire(t, state0=s0, mean_motion_rad_s=0.0, burns=[[45.0, *dv]])
    straight = s0[:3] + t[:, None] * s0[3:]
    np.testing.assert_allclose(p[t <= 45], straight[t <= 45], atol=1e-12)
    late = t > 45
    np.testing.assert_allclose(p[late], straight[late] + (t[late, None] - 45.0) * dv, atol=1e-12)
    # in orbit: after the burn the path is the CW solution from the state the burn left
    n = tr.mean_motion(6_778_137.0)
    s1 = np.array([20.0, 0.0, 10.0, 0.0, -2 * n * 20.0, 0.0])
    q = tr.clohessy_wiltshire(t, state0=s1, burns=[[45.0, *dv]])
    after = tr.cw_stm(n, 45.0) @ s1 + np.r_[0.0, 0.0, 0.0, dv]
    np.testing.assert_allclose(q[late], tr.cw_propagate(t[late] - 45.0, after, n=n)[:, :3])
    np.testing.assert_allclose(q[~late], tr.clohessy_wiltshire(t, state0=s1)[~late])


def test_cw_burns_are_checked():
    with pytest.raises(ConfigError, match="a burn is"):
        tr.make_trajectory("cw", 3, 10.0, {"burns": [[5.0, 0.1]]})
    with pytest.raises(ConfigError, match="a burn is"):
        tr.make_trajectory("cw", 3, 10.0, {"burns": [[-1.0, 0.0, 0.1, 0.0]]})
    with pytest.raises(ConfigError, match="a burn is"):
        tr.make_trajectory("cw", 3, 10.0, {"burns": [[5.0, np.nan, 0.1, 0.0]]})
    with pytest.raises(ConfigError, match="a burn is"):
        tr.make_trajectory("cw", 3, 10.0, {"burns": [["soon", 0.0, 0.1, 0.0]]})


def test_cw_bounded_ellipse_default_is_periodic():
    n = tr.mean_motion(6_778_137.0)
    period = 2 * np.pi / n
    x0 = 20.0
    s0 = [x0, 0.0, 0.0, 0.0, -2 * n * x0, 0.0]
    p = tr.clohessy_wiltshire(np.array([0.0, period]), state0=s0)
    np.testing.assert_allclose(p[1], p[0], atol=1e-6)


def test_make_trajectory_dispatch_and_errors():
    t, p = tr.make_trajectory("elliptic-orbit", 5, 2.0, {"loops": 1.0})
    np.testing.assert_allclose(t, [0, 2, 4, 6, 8])
    assert p.shape == (5, 3)
    t, p = tr.make_trajectory("cw", 3, 10.0, {"mean_motion_rad_s": 0.0})
    assert p.shape == (3, 3)
    with pytest.raises(ConfigError, match="unknown trajectory kind"):
        tr.make_trajectory("spiral-of-doom", 5, 1.0)
    with pytest.raises(ConfigError, match="unknown parameter"):
        tr.make_trajectory("helical-approach", 5, 1.0, {"radius": 3})
    with pytest.raises(ConfigError, match="semi-axes"):
        tr.make_trajectory("elliptic-orbit", 5, 1.0, {"semi_major": -1.0})
    assert "cw" in tr.trajectory_kinds()


def test_look_at_boresight_hits_target():
    rng = np.random.default_rng(1)
    p = rng.uniform(-50, 50, size=(200, 3))
    target = np.array([1.0, -2.0, 0.5])
    R = tr.look_at(p, target=target)
    np.testing.assert_allclose(
        np.einsum("nij,nkj->nik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    d = target - p
    np.testing.assert_allclose(R[:, :, 0], d / np.linalg.norm(d, axis=1)[:, None], atol=1e-12)
    # z (sensor up) has a non-negative component along world up; y is horizontal
    assert np.all(R[:, 2, 2] >= 0)
    np.testing.assert_allclose(R[:, 2, 1], 0, atol=1e-12)
    # the target expressed in the sensor frame lies on +x
    T = tr.pointing_poses(p, target=target)
    tgt_s = np.einsum("nji,nj->ni", T[:, :3, :3], target - T[:, :3, 3])
    np.testing.assert_allclose(tgt_s[:, 1:], 0, atol=1e-9)
    assert np.all(tgt_s[:, 0] > 0)


def test_look_at_degenerate_up():
    R = tr.look_at(np.array([[0.0, 0.0, 10.0], [0.0, 0.0, -3.0]]))
    np.testing.assert_allclose(R[0, :, 0], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(R[1, :, 0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0)
    with pytest.raises(InputError, match="coincides"):
        tr.look_at(np.zeros((1, 3)))


def test_pointing_jitter_seeded():
    p = tr.elliptic_orbit(20, loops=1.0)
    a = tr.pointing_poses(p, jitter_deg=0.5, seed=3)
    b = tr.pointing_poses(p, jitter_deg=0.5, seed=3)
    c = tr.pointing_poses(p, jitter_deg=0.5, seed=4)
    clean = tr.pointing_poses(p)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    np.testing.assert_allclose(a[:, :3, 3], p)
    ang = np.degrees(
        np.arccos(np.clip((np.einsum("nji,nji->n", clean[:, :3, :3], a[:, :3, :3]) - 1) / 2, -1, 1))
    )
    assert 0 < ang.mean() < 2.0  # ≈ 0.5° · sqrt(8/π) ≈ 0.8°
    with pytest.raises(InputError):
        tr.pointing_poses(p, jitter_deg=-1)
