"""Clohessy–Wiltshire dynamics (ALGORITHMS.md §G.5)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from relnav.errors import ConfigError, InputError
from relnav.filtering.dynamics import (
    MU_EARTH,
    ClohessyWiltshire,
    axis_permutation,
    cw_matrix,
    cw_stm,
    mean_motion,
)

N_LEO = mean_motion(6_778_137.0)


def _cw_rhs(n: float):  # type: ignore[no-untyped-def]
    def f(_t: float, s: np.ndarray) -> np.ndarray:
        x, _y, z, vx, vy, vz = s
        return np.array([vx, vy, vz, 2 * n * vy + 3 * n * n * x, -2 * n * vx, -n * n * z])

    return f


def test_leo_mean_motion() -> None:
    assert N_LEO == pytest.approx(1.131e-3, rel=1e-3)
    assert mean_motion(42_164_000.0) == pytest.approx(2 * math.pi / 86_164.1, rel=1e-4)
    with pytest.raises(InputError):
        mean_motion(-1.0)


@pytest.mark.parametrize("dt", [0.5, 4.5, 60.0, 1000.0, 5554.0])
def test_stm_matches_numerical_integration(dt: float, rng: np.random.Generator) -> None:
    s0 = np.r_[rng.normal(scale=50.0, size=3), rng.normal(scale=0.1, size=3)]
    sol = solve_ivp(_cw_rhs(N_LEO), (0.0, dt), s0, method="DOP853", rtol=1e-13, atol=1e-13)
    s1 = cw_stm(N_LEO, dt) @ s0
    scale = 1.0 + np.abs(s0).max()
    np.testing.assert_allclose(s1, sol.y[:, -1], atol=1e-9 * scale, rtol=0)
    # and the matrix exponential of the continuous system
    np.testing.assert_allclose(cw_stm(N_LEO, dt), expm(cw_matrix(N_LEO) * dt), atol=1e-9)


def test_stm_semigroup_and_inverse() -> None:
    a, b = 37.0, 910.0
    np.testing.assert_allclose(cw_stm(N_LEO, a + b), cw_stm(N_LEO, a) @ cw_stm(N_LEO, b), atol=1e-9)
    np.testing.assert_allclose(cw_stm(N_LEO, -a) @ cw_stm(N_LEO, a), np.eye(6), atol=1e-10)


def test_zero_n_limit_is_double_integrator() -> None:
    di = np.eye(6)
    di[:3, 3:] = 4.5 * np.eye(3)
    np.testing.assert_array_equal(cw_stm(0.0, 4.5), di)
    # below n·dt = 1e-8 the double integrator is used (error O(n·dt²)); above it the
    # cancellation-free closed form is exact to rounding
    for n in (1e-12, 1e-9):
        np.testing.assert_allclose(cw_stm(n, 4.5), expm(cw_matrix(n) * 4.5), atol=1e-8 * 4.5)
    for n in (3e-9, 1e-7, 1e-5):
        np.testing.assert_allclose(cw_stm(n, 4.5), expm(cw_matrix(n) * 4.5), atol=1e-13)
        np.testing.assert_allclose(cw_stm(n, 4.5), di, atol=1e-3)


def test_physics_known_answers() -> None:
    # along-track offset with zero velocity is an equilibrium; cross-track oscillates with n
    P = 2 * math.pi / N_LEO
    s = cw_stm(N_LEO, 1234.0) @ np.array([0.0, 100.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(s, [0, 100, 0, 0, 0, 0], atol=1e-12)
    s = cw_stm(N_LEO, P) @ np.array([0.0, 0.0, 10.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(s[[2, 5]], [10.0, 0.0], atol=1e-9)
    # radial offset: along-track drift of −3/2·n·x0 per unit time on average
    s = cw_stm(N_LEO, P) @ np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert s[1] == pytest.approx(6 * (0 - 2 * math.pi), rel=1e-9)  # 6(sin nT − nT)


def test_axis_permutation_and_sensor_frame_model(rng: np.random.Generator) -> None:
    M = axis_permutation("z,x,y")  # LVLH x = sensor z, y = sensor x, z = sensor y
    np.testing.assert_array_equal(M, [[0, 0, 1], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_array_equal(axis_permutation("-zx-y"), [[0, 0, -1], [1, 0, 0], [0, -1, 0]])
    np.testing.assert_array_equal(axis_permutation(None), np.eye(3))
    cw = ClohessyWiltshire(N_LEO, lvlh_axes="z,x,y")
    p, v = rng.normal(size=3), rng.normal(scale=0.01, size=3)
    p1, v1 = cw.propagate(p, v, 300.0)
    s_l = cw_stm(N_LEO, 300.0) @ np.r_[M @ p, M @ v]
    np.testing.assert_allclose(p1, M.T @ s_l[:3], atol=1e-12)
    np.testing.assert_allclose(v1, M.T @ s_l[3:], atol=1e-12)
    # batch propagation
    P1, _ = cw.propagate(np.tile(p, (4, 1)), np.tile(v, (4, 1)), 300.0)
    np.testing.assert_allclose(P1, np.tile(p1, (4, 1)), atol=1e-12)
    for bad in ("x,x,y", "x,y", "q,y,z", "-x,y,z"):  # repeated, short, unknown, reflection
        with pytest.raises(ConfigError):
            axis_permutation(bad)
    with pytest.raises(ConfigError):
        axis_permutation(np.diag([1.0, 1.0, 2.0]))


def test_euler_model_is_one_euler_step() -> None:
    cw = ClohessyWiltshire(N_LEO, model="euler")
    np.testing.assert_allclose(cw.stm(10.0), np.eye(6) + 10.0 * cw_matrix(N_LEO), atol=0)
    assert not np.allclose(cw.stm(100.0), ClohessyWiltshire(N_LEO).stm(100.0), atol=1e-6)
    with pytest.raises(ConfigError):
        ClohessyWiltshire(0.0, model="rk4")  # type: ignore[arg-type]
    with pytest.raises(InputError):
        cw_stm(-1e-3, 1.0)
    with pytest.raises(InputError):
        cw_stm(N_LEO, float("nan"))
    assert MU_EARTH == pytest.approx(3.986004418e14)
