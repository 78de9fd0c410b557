"""Conformal geometric algebra helpers: closed forms, kingdon definitions, clifford oracle."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import InputError
from relnav.geometry import cga
from relnav.geometry.rotations import random_rotation
from relnav.geometry.se3 import kabsch

TOL = 1e-9


def _rand_rt(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    return random_rotation(rng), rng.normal(size=3) * 2.0


# --------------------------------------------------------------------------------------------
# NumPy closed forms
# --------------------------------------------------------------------------------------------


def test_null_vectors_and_embedding(rng: np.random.Generator) -> None:
    assert cga.inner(cga.EINF, cga.EINF) == 0.0
    assert cga.inner(cga.E0, cga.E0) == 0.0
    assert cga.inner(cga.EINF, cga.E0) == -1.0
    x = rng.normal(size=(50, 3)) * 3
    X = cga.up(x)
    np.testing.assert_allclose(cga.inner(X, X), 0.0, atol=1e-12)
    np.testing.assert_allclose(cga.down(X), x, atol=1e-12)
    np.testing.assert_allclose(cga.down(7.5 * X), x, atol=1e-12)  # scale invariant
    np.testing.assert_allclose(cga.inner(X, cga.EINF), -1.0)


def test_table1_inner_products_match_vector_forms(rng: np.random.Generator) -> None:
    a, b, c2 = rng.normal(size=(3, 40, 3))
    r1, r2 = rng.uniform(0.1, 2.0, size=(2, 40))
    n = rng.normal(size=(40, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = rng.normal(size=40)
    A, B = cga.up(a), cga.up(b)
    S1, S2 = cga.sphere_vectors(a, r1), cga.sphere_vectors(c2, r2)
    Pi = cga.plane_vectors(n, d)
    np.testing.assert_allclose(cga.inner(A, B), cga.point_point_inner(a, b), atol=TOL)
    np.testing.assert_allclose(cga.inner(A, B), -0.5 * np.sum((a - b) ** 2, 1), atol=TOL)
    np.testing.assert_allclose(cga.inner(B, S1), cga.point_sphere_inner(b, a, r1), atol=TOL)
    np.testing.assert_allclose(cga.inner(A, Pi), cga.point_plane_inner(a, n, d), atol=TOL)
    np.testing.assert_allclose(cga.inner(S1, S2), cga.sphere_sphere_inner(a, r1, c2, r2), atol=TOL)
    np.testing.assert_allclose(cga.inner(Pi, S2), cga.plane_sphere_inner(n, d, c2), atol=TOL)
    # a point on the sphere has zero inner product; inside > 0
    u = rng.normal(size=(40, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    np.testing.assert_allclose(cga.inner(cga.up(a + r1[:, None] * u), S1), 0.0, atol=1e-9)
    assert np.all(cga.inner(cga.up(a + 0.5 * r1[:, None] * u), S1) > 0)
    # plane angle
    np.testing.assert_allclose(cga.plane_angle([0, 0, 1.0], [0, 1.0, 1.0]), np.pi / 4)
    c, r2s = cga.sphere_params(3.0 * S1)
    np.testing.assert_allclose(c, a, atol=TOL)
    np.testing.assert_allclose(r2s, r1**2, atol=TOL)


def test_spheres_through_points(rng: np.random.Generator) -> None:
    centre = rng.normal(size=(30, 3))
    radius = rng.uniform(0.2, 3.0, 30)
    u = rng.normal(size=(30, 4, 3))
    u /= np.linalg.norm(u, axis=2, keepdims=True)
    quads = centre[:, None, :] + radius[:, None, None] * u
    fit = cga.spheres_through_points(quads)
    assert fit.valid.all() and not fit.circle.any()
    np.testing.assert_allclose(fit.centres, centre, atol=1e-8)
    np.testing.assert_allclose(fit.radii, radius, atol=1e-8)
    # coplanar: a circle through 4 points of a circle
    ang = rng.uniform(0, 2 * np.pi, 4)
    circ = np.stack([np.cos(ang), np.sin(ang), np.zeros(4)], 1) * 2.0 + [1.0, 2.0, 3.0]
    c, r, is_circle = cga.sphere_through_points(*circ)
    assert is_circle
    np.testing.assert_allclose(c, [1.0, 2.0, 3.0], atol=1e-9)
    assert r == pytest.approx(2.0)
    fit = cga.spheres_through_points(circ)
    np.testing.assert_allclose(np.abs(fit.normals[0]), [0, 0, 1], atol=1e-9)
    # collinear: no sphere, no circle
    line = np.outer(np.arange(4.0), [1.0, 1.0, 0.0])
    assert not cga.spheres_through_points(line).valid[0]
    with pytest.raises(InputError):
        cga.sphere_through_points(*line)
    with pytest.raises(InputError):
        cga.spheres_through_points(np.zeros((2, 3, 3)))


def test_dense_product_identities(rng: np.random.Generator) -> None:
    e = np.eye(32)
    einf = e[8] + e[16]
    e0 = 0.5 * (e[16] - e[8])
    assert np.allclose(cga.gp(einf, einf), 0.0)
    assert np.allclose(cga.gp(e0, e0), 0.0)
    sym = 0.5 * (cga.gp(einf, e0) + cga.gp(e0, einf))
    assert sym[0] == pytest.approx(-1.0)
    A, B, C = rng.normal(size=(3, 32))
    np.testing.assert_allclose(cga.gp(cga.gp(A, B), C), cga.gp(A, cga.gp(B, C)), atol=1e-10)
    # reverse of a product
    np.testing.assert_allclose(
        cga.reverse(cga.gp(A, B)), cga.gp(cga.reverse(B), cga.reverse(A)), atol=1e-10
    )


def test_motor_roundtrip_and_sandwich(rng: np.random.Generator) -> None:
    for _ in range(5):
        R, t = _rand_rt(rng)
        m = cga.motor_from_rt(R, t)
        R2, t2 = cga.motor_to_rt(m)
        np.testing.assert_allclose(R2, R, atol=TOL)
        np.testing.assert_allclose(t2, t, atol=TOL)
        Md = cga.motor_to_dense(m)
        MMr = cga.gp(Md, cga.reverse(Md))
        np.testing.assert_allclose(MMr, np.eye(32)[0], atol=1e-12)  # M M~ = 1
        x = rng.normal(size=3)
        Xd = np.zeros(32)
        Xd[[1, 2, 4, 8, 16]] = cga.up(x)
        Y = cga.gp(cga.gp(Md, Xd), cga.reverse(Md))
        y5 = Y[[1, 2, 4, 8, 16]]
        np.testing.assert_allclose(cga.down(y5), R @ x + t, atol=TOL)
        np.testing.assert_allclose(cga.motor_apply(m, x[None]), (R @ x + t)[None], atol=TOL)
    # rotor <-> quaternion convention: +90 deg about z is [w, -z, y, -x]
    r = cga.rotor_from_quat([0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    np.testing.assert_allclose(r, [np.cos(np.pi / 4), -np.sin(np.pi / 4), 0, 0])
    R, _ = cga.motor_to_rt(np.r_[r, 0, 0, 0, 0])
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_estimate_motor_exact_points_and_kabsch(rng: np.random.Generator) -> None:
    R, t = _rand_rt(rng)
    x = rng.normal(size=(12, 3))
    y = x @ R.T + t
    m, info = cga.estimate_motor(cga.up(x), cga.up(y))
    R2, t2 = cga.motor_to_rt(m)
    np.testing.assert_allclose(R2, R, atol=TOL)
    np.testing.assert_allclose(t2, t, atol=TOL)
    assert info["gap"] > 0
    # spheres (any radii) with noisy centres: equals Kabsch / weighted Kabsch on the centres
    yn = y + rng.normal(scale=0.05, size=y.shape)
    w = rng.uniform(0.5, 2.0, 12)
    for weights in (None, w):
        S = cga.sphere_vectors(x, rng.uniform(0.0, 0.5, 12))
        m, _ = cga.estimate_motor(S, cga.up(yn), weights)
        R3, t3 = cga.motor_to_rt(m)
        K = kabsch(x, yn, weights)
        np.testing.assert_allclose(R3, K[:3, :3], atol=1e-9)
        np.testing.assert_allclose(t3, K[:3, 3], atol=1e-9)
    # reflected data still gives a proper rotation
    m, _ = cga.estimate_motor(cga.up(x), cga.up(x * [1, 1, -1]))
    assert np.linalg.det(cga.motor_to_rt(m)[0]) == pytest.approx(1.0)
    with pytest.raises(InputError):
        cga.estimate_motor(cga.up(x[:2]), cga.up(y[:2]))


# --------------------------------------------------------------------------------------------
# kingdon definitions
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def kingdon_ok() -> None:
    pytest.importorskip("kingdon")


def test_kingdon_definitions_agree(kingdon_ok: None, rng: np.random.Generator) -> None:
    B = cga.basis()
    assert cga.mv_to_dense(B.einf * B.einf) == pytest.approx(np.zeros(32))
    assert cga.mv_to_dense(B.einf | B.eo)[0] == pytest.approx(-1.0)
    x = rng.normal(size=3)
    d = cga.mv_to_dense(cga.up_mv(x))
    np.testing.assert_allclose(d[[1, 2, 4, 8, 16]], cga.up(x), atol=TOL)
    P = rng.normal(size=(4, 3))
    c, r2 = cga.sphere_from_dual_mv(cga.sphere_dual_mv(*P))
    c2, r, _ = cga.sphere_through_points(*P)
    np.testing.assert_allclose(c, c2, atol=1e-8)
    assert r2 == pytest.approx(r**2, rel=1e-8)
    R, t = _rand_rt(rng)
    m = cga.motor_from_rt(R, t)
    M = cga.motor_mv(m)
    Y = cga.mv_to_dense(M * cga.up_mv(x) * ~M)
    np.testing.assert_allclose(cga.down(Y[[1, 2, 4, 8, 16]]), R @ x + t, atol=TOL)
    alg = cga.algebra()
    A, Bm = rng.normal(size=(2, 32))
    ka = alg.multivector(values=list(A), keys=tuple(range(32)))
    kb = alg.multivector(values=list(Bm), keys=tuple(range(32)))
    np.testing.assert_allclose(cga.mv_to_dense(ka * kb), cga.gp(A, Bm), atol=1e-10)


# --------------------------------------------------------------------------------------------
# clifford oracle
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def g3c():
    pytest.importorskip("clifford")
    import clifford.g3c as g3c

    return g3c


def _perm(g3c) -> np.ndarray:
    """clifford value index of each bitmap."""
    perm = np.zeros(32, dtype=np.int64)
    for i, tup in enumerate(g3c.layout.bladeTupList):
        perm[sum(1 << (k - 1) for k in tup)] = i
    return perm


def _to_cf(g3c, dense: np.ndarray):
    v = np.zeros(32)
    v[_perm(g3c)] = dense
    return g3c.layout.MultiVector(v)


def _from_cf(g3c, mv) -> np.ndarray:
    return np.asarray(mv.value)[_perm(g3c)]


def test_clifford_oracle(g3c, rng: np.random.Generator) -> None:
    # conventions
    np.testing.assert_allclose(_from_cf(g3c, g3c.einf)[[8, 16]], [1.0, 1.0])
    np.testing.assert_allclose(_from_cf(g3c, g3c.eo)[[8, 16]], [-0.5, 0.5])
    # geometric product on random multivectors
    for _ in range(3):
        A, B = rng.normal(size=(2, 32))
        cf = _from_cf(g3c, _to_cf(g3c, A) * _to_cf(g3c, B))
        np.testing.assert_allclose(cga.gp(A, B), cf, atol=1e-9)
    e1, e2, e3 = (g3c.blades[k] for k in ("e1", "e2", "e3"))
    for _ in range(5):
        a, b = rng.normal(size=(2, 3)) * 2
        Xa = g3c.up(a[0] * e1 + a[1] * e2 + a[2] * e3)
        Xb = g3c.up(b[0] * e1 + b[1] * e2 + b[2] * e3)
        np.testing.assert_allclose(_from_cf(g3c, Xa)[[1, 2, 4, 8, 16]], cga.up(a), atol=TOL)
        assert float((Xa | Xb)[()]) == pytest.approx(float(cga.point_point_inner(a, b)), abs=TOL)
        rho = rng.uniform(0.1, 1.0)
        S = Xb - 0.5 * rho**2 * g3c.einf
        assert float((Xa | S)[()]) == pytest.approx(
            float(cga.point_sphere_inner(a, b, rho)), abs=TOL
        )
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        d = rng.normal()
        Pi = n[0] * e1 + n[1] * e2 + n[2] * e3 + d * g3c.einf
        assert float((Xa | Pi)[()]) == pytest.approx(float(cga.point_plane_inner(a, n, d)), abs=TOL)
    # sphere through 4 points: clifford's dual of X1^X2^X3^X4
    P = rng.normal(size=(4, 3))
    Xs = [g3c.up(p[0] * e1 + p[1] * e2 + p[2] * e3) for p in P]
    S = (Xs[0] ^ Xs[1] ^ Xs[2] ^ Xs[3]).dual()
    c, r2 = cga.sphere_params(_from_cf(g3c, S)[[1, 2, 4, 8, 16]])
    c2, r, _ = cga.sphere_through_points(*P)
    np.testing.assert_allclose(c, c2, atol=1e-9)
    assert float(r2) == pytest.approx(r**2, rel=1e-9)
    # motor sandwich
    R, t = _rand_rt(rng)
    M = _to_cf(g3c, cga.motor_to_dense(cga.motor_from_rt(R, t)))
    x = rng.normal(size=3)
    Y = M * g3c.up(x[0] * e1 + x[1] * e2 + x[2] * e3) * ~M
    y = _from_cf(g3c, Y)[[1, 2, 4, 8, 16]]
    np.testing.assert_allclose(cga.down(y), R @ x + t, atol=TOL)
