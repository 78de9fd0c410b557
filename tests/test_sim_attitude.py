"""Target attitude: spin closed form, torque-free tumbling conservation laws."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError, InputError
from relnav.geometry.rotations import random_rotation, rotvec_to_matrix
from relnav.sim import attitude as att


def test_static():
    R0 = random_rotation(1)
    R = att.static(np.arange(4.0), R0)
    assert R.shape == (4, 3, 3)
    np.testing.assert_allclose(R, np.broadcast_to(R0, (4, 3, 3)))


@pytest.mark.parametrize("axis", ["x", "y", "z", (1.0, 1.0, 0.0)])
def test_spin_closed_form(axis):
    t = np.arange(16) * 4.5
    R = att.spin(t, axis=axis, rate_deg_s=5.0)
    a = np.array({"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}.get(axis, axis), float)
    a /= np.linalg.norm(a)
    # 16 frames at 22.5° steps (Paper 2)
    steps = np.einsum("nji,njk->nik", R[:-1], R[1:])
    for S in steps:
        np.testing.assert_allclose(S, rotvec_to_matrix(np.deg2rad(22.5) * a), atol=1e-12)
        np.testing.assert_allclose(S @ a, a, atol=1e-12)


def test_tumble_principal_axis_equals_spin():
    t = np.linspace(0, 60, 13)
    R0 = random_rotation(7)
    Rt = att.tumble(t, inertia=(3.0, 2.0, 1.0), omega0_deg_s=(0.0, 0.0, 6.0), R0=R0)
    # body z-axis spin = spin about the world axis R0 e_z
    Rs = att.spin(t, axis=R0[:, 2], rate_deg_s=6.0, R0=R0)
    np.testing.assert_allclose(Rt, Rs, atol=1e-9)


def test_tumble_conserves_energy_and_momentum():
    J = np.array([[4.0, 0.3, -0.2], [0.3, 6.0, 0.1], [-0.2, 0.1, 7.0]])
    t = np.linspace(0, 300, 61)
    R, w = att.tumble(t, inertia=J, omega0_deg_s=(3.0, -2.0, 4.0), return_omega=True)
    assert R.shape == (61, 3, 3) and w.shape == (61, 3)
    np.testing.assert_allclose(
        np.einsum("nij,nkj->nik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
    E = att.rotational_energy(w, J)
    np.testing.assert_allclose(E, E[0], rtol=1e-8)
    L = att.angular_momentum_world(R, w, J)
    np.testing.assert_allclose(np.linalg.norm(w @ J.T, axis=1), np.linalg.norm(L[0]), rtol=1e-8)
    # stronger: the world-frame angular momentum vector is constant
    np.testing.assert_allclose(L, np.broadcast_to(L[0], L.shape), atol=1e-8 * np.linalg.norm(L[0]))
    # and the body really tumbles (intermediate-axis-like motion, not a plain spin)
    assert np.ptp(w[:, 0]) > 1e-3


def test_tumble_unsorted_times_and_zero():
    t = np.array([10.0, 0.0, 5.0])
    R = att.tumble(t, inertia=(1, 2, 3), omega0_deg_s=(1, 2, 3))
    Rs = att.tumble(np.sort(t), inertia=(1, 2, 3), omega0_deg_s=(1, 2, 3))
    np.testing.assert_allclose(R[[1, 2, 0]], Rs, atol=1e-12)
    np.testing.assert_allclose(R[1], np.eye(3), atol=1e-15)


def test_bad_inputs():
    with pytest.raises(InputError, match="triangle"):
        att.tumble([0, 1], inertia=(1, 1, 5))
    with pytest.raises(InputError, match="positive definite"):
        att.tumble([0, 1], inertia=(-1, 2, 2))
    with pytest.raises(InputError, match="axis"):
        att.spin([0, 1], axis="w")
    with pytest.raises(ConfigError, match="unknown attitude kind"):
        att.make_attitude("wobble", [0, 1])
    with pytest.raises(ConfigError, match="tumble"):
        att.make_attitude("tumble", [0, 1], inertia=(0, 0, 0))
