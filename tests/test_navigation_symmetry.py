"""Rotational symmetry of the navigator's map (relnav.navigation.symmetry) and its use."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from relnav.navigation.navigator import Navigator
from relnav.navigation.symmetry import marginalise_direction, stiffen_prior, symmetry_axis

# the robust test (3 reweighted passes): the suite's near-symmetric maps score 1e-3 to 6e-3,
# the irregular ones 5e-2 to 2e-1
RATIO = 0.0025
IRLS = 3


def _pca_normals(P: np.ndarray, k: int = 10) -> np.ndarray:
    """Normals from the k nearest neighbours' covariance, as the map estimates them."""
    _, idx = cKDTree(P).query(P, k=k)
    Q = P[idx] - P[idx].mean(1, keepdims=True)
    _, vec = np.linalg.eigh(np.einsum("nki,nkj->nij", Q, Q))
    return vec[:, :, 0]


def _capsule(n: int, rng: np.random.Generator, arc_deg: float = 360.0) -> np.ndarray:
    """A capsule-like body of revolution about z (cone frustum on a shallow cap), m."""
    z = rng.uniform(0.0, 3.0, n)
    th = rng.uniform(0.0, np.radians(arc_deg), n)
    r = 2.5 - 0.5 * z  # frustum, radius 2.5 → 1.0 m
    side = np.column_stack([r * np.cos(th), r * np.sin(th), z])
    m = n // 3
    rc = 2.5 * np.sqrt(rng.uniform(0, 1, m))
    tc = rng.uniform(0.0, np.radians(arc_deg), m)
    cap = np.column_stack([rc * np.cos(tc), rc * np.sin(tc), -0.1 * (1 - (rc / 2.5) ** 2)])
    return np.vstack([side, cap]) + rng.normal(0, 0.005, (n + m, 3))


def _box(n: int, rng: np.random.Generator) -> np.ndarray:
    """Surface samples of a 3 × 2 × 1.5 m box."""
    half = np.array([1.5, 1.0, 0.75])
    P = rng.uniform(-1, 1, (n, 3)) * half
    face = rng.integers(0, 3, n)
    P[np.arange(n), face] = np.sign(rng.uniform(-1, 1, n)) * half[face]
    return P + rng.normal(0, 0.005, P.shape)


def _blob(n: int, rng: np.random.Generator) -> np.ndarray:
    """An irregular asteroid-like body: an elongated ellipsoid with low-order bumps, m."""
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    r = 1 + 0.25 * v[:, 0] * v[:, 1] + 0.2 * v[:, 2] ** 2 - 0.15 * v[:, 0] ** 3
    return v * r[:, None] * np.array([3.0, 1.8, 1.2]) + rng.normal(0, 0.005, (n, 3))


def _pose(rng: np.random.Generator) -> np.ndarray:
    """A random rigid transform (the test must not depend on the map's frame)."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, rng.uniform(-5, 5, 3)
    return T


def test_body_of_revolution_is_symmetric_and_its_axis_found():
    rng = np.random.default_rng(0)
    T = _pose(rng)
    P = _capsule(3000, rng) @ T[:3, :3].T + T[:3, 3]
    s = symmetry_axis(P, _pca_normals(P), max_ratio=RATIO, min_arc_deg=180.0, irls=IRLS)
    assert s is not None
    axis = T[:3, 2]  # the body's z axis in the map frame
    assert abs(float(s.axis @ axis)) > 0.999
    # the axis passes through the body's axis line (distance of T's origin to it)
    d = (T[:3, 3] - s.center) - float((T[:3, 3] - s.center) @ s.axis) * s.axis
    assert np.linalg.norm(d) < 0.02
    assert s.ratio < 0.2 * RATIO and s.arc_deg == 360.0
    np.testing.assert_allclose(s.twist[3:], s.axis)
    np.testing.assert_allclose(s.twist[:3], np.cross(s.center, s.axis), atol=1e-12)


def test_box_and_blob_are_not_symmetric():
    rng = np.random.default_rng(1)
    for P in (_box(3000, rng), _blob(3000, rng)):
        N = _pca_normals(P)
        assert symmetry_axis(P, N, max_ratio=RATIO, min_arc_deg=180.0, irls=IRLS) is None
        # and not by a small margin: the best rotation moves the surface along its normals
        s = symmetry_axis(
            P, N, max_ratio=np.inf, min_arc_deg=0.0, max_axial_fraction=1.0, irls=IRLS
        )
        assert s is not None and s.ratio > 5 * RATIO


def test_plain_least_squares_orders_them_too():
    """Without reweighting the rims' poor normals raise the capsule's ratio, but it stays
    below the irregular bodies'."""
    rng = np.random.default_rng(5)
    P = _capsule(6000, rng)
    cap = symmetry_axis(P, _pca_normals(P), max_ratio=np.inf, min_arc_deg=0.0)
    assert cap is not None and cap.ratio < 0.01
    rng = np.random.default_rng(1)
    for Q in (_box(3000, rng), _blob(3000, rng)):
        s = symmetry_axis(Q, _pca_normals(Q), max_ratio=np.inf, min_arc_deg=0.0)
        assert s is not None and s.ratio > 1.5 * cap.ratio


def test_partial_map_and_plate_are_not_declared_symmetric():
    rng = np.random.default_rng(2)
    P = _capsule(3000, rng, arc_deg=90.0)  # a quarter of the body seen so far
    assert symmetry_axis(P, _pca_normals(P), max_ratio=RATIO, min_arc_deg=180.0, irls=IRLS) is None
    plate = np.column_stack([rng.uniform(-2, 2, (2000, 2)), rng.normal(0, 0.003, 2000)])
    assert (
        symmetry_axis(plate, _pca_normals(plate), max_ratio=RATIO, min_arc_deg=180.0, irls=IRLS)
        is None
    )


def test_marginalised_and_stiffened_along_the_symmetric_rotation():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    H = A @ A.T + 6 * np.eye(6)
    u = rng.normal(size=6)
    Hm = marginalise_direction(H, u)
    np.testing.assert_allclose(Hm @ u, 0.0, atol=1e-9 * np.abs(H).max())
    assert np.all(np.linalg.eigvalsh(Hm) > -1e-9)
    # a direction H-orthogonal to u keeps its information
    v = rng.normal(size=6)
    v -= u * float(u @ H @ v) / float(u @ H @ u)
    assert abs(float(v @ Hm @ v) - float(v @ H @ v)) < 1e-9 * float(v @ H @ v)
    Ls = stiffen_prior(H, u, 99.0)
    assert np.isclose(float(u @ Ls @ u), 100.0 * float(u @ H @ u))


def test_navigator_hands_the_symmetric_rotation_to_the_motion_model():
    """Scans of a body of revolution spinning about its axis: the navigator finds the axis
    and the scan's information passed to the filter has nothing along that rotation."""
    rng = np.random.default_rng(4)
    body = _capsule(2500, rng)
    body[:, 2] -= 1.0
    nav = Navigator(
        **{
            "symmetry.max_ratio": RATIO,
            "symmetry.irls": IRLS,
            "symmetry.every": 1,
            "startup.bootstrap_frames": 0,
        }
    )
    seen = []
    for k in range(8):
        c, s = np.cos(np.radians(2.0 * k)), np.sin(np.radians(2.0 * k))
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        # the sensor 20 m along x, looking at the body's side; the body turns about z
        P = body @ Rz.T + np.array([0.0, 0.0, 20.0])
        out = nav.register_frame(P + rng.normal(0, 0.003, P.shape))
        if out.result is not None and "symmetry_axis" in out.result.info:
            seen.append(out.result.info)
    assert nav.symmetry is not None
    assert abs(float(nav.symmetry.axis @ nav.pose[:3, 2])) > 0.99
    assert seen
    for info in seen:
        H, u = info["information"], info["symmetry_twist"]
        assert abs(float(u @ H @ u)) < 1e-8 * np.trace(H)


@pytest.mark.parametrize(
    "bad",
    [
        {"symmetry.max_ratio": -1.0},
        {"symmetry.max_axial": 1.5},
        {"symmetry.every": 0},
        {"symmetry.min_arc_deg": 400.0},
    ],
)
def test_bad_symmetry_options_are_one_config_error(bad) -> None:
    from relnav.errors import ConfigError
    from relnav.navigation import Navigator

    with pytest.raises(ConfigError, match=next(iter(bad)).replace(".", r"\.")):
        Navigator(**bad)
