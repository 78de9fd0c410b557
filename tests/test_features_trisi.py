"""TriSI and spin images: known answers, oracles, invariance, normalisation, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError, InputError
from relnav.features import compute, get_descriptor
from relnav.features.trisi import spin, spin_grid, trisi
from relnav.geometry import (
    estimate_normals,
    mean_resolution,
    random_transform,
    transform_points,
)
from relnav.geometry.lrf import rops_lrf

# Tolerances (one place): see tests/test_features_rops.py for the reasoning. Spin-image values
# are float32 in [0, 1]; with a well-defined LRF (margins ≥ MARGIN) transformed clouds give the
# same images up to float32 rounding.
DESC_ATOL = 1e-6
MARGIN = 1e-3


def bumpy_surface(seed: int, n: int = 500) -> np.ndarray:
    """Generic non-planar height field z = f(x, y) on [-1, 1]², placed 5 m ahead, (n, 3)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1.0, 1.0, (n, 2))
    z = np.zeros(n)
    for _ in range(6):
        c = rng.uniform(-1, 1, 2)
        z += rng.uniform(-0.3, 0.3) * np.exp(-np.sum((xy - c) ** 2, axis=1) / 0.15)
    z += 0.1 * xy[:, 0] ** 2 - 0.05 * xy[:, 0] * xy[:, 1]
    return np.c_[xy, z] + np.array([5.0, 0.0, 0.0])


def lrf_margin(P: np.ndarray, i: int, r: float) -> float:
    """Definedness margin of the RoPS point LRF (relative eigen gaps and sign sums)."""
    V = P[np.linalg.norm(P - P[i], axis=1) <= r] - P[i]
    d = np.linalg.norm(V, axis=1)
    w = (r - d) ** 2
    lam, E = np.linalg.eigh(np.einsum("n,ni,nj->ij", w, V, V))
    m = (w[:, None] * V).sum(0)
    s = (w * d).sum()
    gap = min(lam[2] - lam[1], lam[1] - lam[0]) / lam[2]
    return float(min(gap, abs(m @ E[:, 2]) / s, abs(m @ E[:, 0]) / s))


@pytest.fixture(scope="module")
def surface() -> tuple[np.ndarray, float]:
    P = bumpy_surface(11)
    return P, 8.0 * mean_resolution(P)


def test_registry_entries() -> None:
    t, s = get_descriptor("trisi"), get_descriptor("spin")
    assert (t.dim, t.radius_factor, t.needs_normals) == (675, 20.0, False)
    assert (s.dim, s.needs_normals) == (225, True)


def test_grids() -> None:
    g = spin_grid(1.5)
    assert (g.na, g.nb, g.size) == (15, 15, 225)
    assert g.a0 == pytest.approx(0.05) and g.b0 == pytest.approx(-1.5 + 0.1)
    p = spin_grid(1.0, layout="pcl", width=8)
    assert (p.na, p.nb, p.size) == (9, 17, 153)
    with pytest.raises(ConfigError):
        spin_grid(1.0, layout="nope")


def _star(r: float, alphas: list[float], betas: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """Keypoint at the origin with normal +z and support points at given (α, β)."""
    ang = np.linspace(0, 2 * np.pi, len(alphas), endpoint=False)
    pts = [np.zeros(3)]
    pts += [[a * np.cos(t), a * np.sin(t), b] for a, b, t in zip(alphas, betas, ang, strict=True)]
    P = np.array(pts, dtype=float)
    N = np.tile([0.0, 0.0, 1.0], (len(P), 1))
    assert (np.linalg.norm(P, axis=1) <= r).all()
    return P, N


def test_spin_known_answer_cell_centres() -> None:
    r = 1.5  # cells: α 0.1 wide (centres 0.05 + 0.1 j), β 0.2 wide (centres -1.4 + 0.2 i)
    alphas = [0.05 + 0.1 * 3, 0.05 + 0.1 * 7, 0.05 + 0.1 * 7, 0.05 + 0.1 * 10]
    betas = [-1.4 + 0.2 * 7, -1.4 + 0.2 * 2, -1.4 + 0.2 * 9, -1.4 + 0.2 * 7]
    P, N = _star(r, alphas, betas)
    img = spin(P, np.array([0]), radius=r, normals=N)[0].reshape(15, 15)  # [β, α]
    expected = np.zeros((15, 15))
    # keypoint itself: α = 0 (half a cell below the first centre, clamped → cell 0), β = 0
    # (exactly the centre of β cell 7)
    expected[7, 0] = 1 / 5
    for a, b in zip(alphas, betas, strict=True):
        expected[round((b + 1.4) / 0.2), round((a - 0.05) / 0.1)] += 1 / 5
    np.testing.assert_allclose(img, expected, atol=1e-6)


def test_spin_bilinear_split_and_nearest() -> None:
    r = 1.5
    # α 70 % of the way from the centre of cell 2 to cell 3; β 25 % from cell 4 to cell 5.
    alphas = [0.32] * 4
    betas = [-1.4 + 0.2 * 4.25] * 4
    P, N = _star(r, alphas, betas)
    img = spin(P, np.array([0]), radius=r, normals=N)[0].reshape(15, 15)
    assert img[7, 0] == pytest.approx(0.2, abs=1e-6)
    np.testing.assert_allclose(
        img[4:6, 2:4], 0.8 * np.array([[0.75 * 0.3, 0.75 * 0.7], [0.25 * 0.3, 0.25 * 0.7]]), 1e-5
    )
    assert img.sum() == pytest.approx(1.0, abs=1e-6)
    near = spin(P, np.array([0]), radius=r, normals=N, interpolation="nearest")[0]
    near = near.reshape(15, 15)
    assert near[4, 3] == pytest.approx(0.8, abs=1e-6)
    assert near.sum() == pytest.approx(1.0, abs=1e-6)


def test_spin_pcl_layout_nodes() -> None:
    # PCL: node spacing r/(w√2) = 0.1, α nodes 0..0.8, β nodes -0.8..0.8, cylinder α, |β| < 0.8
    r = 0.8 * np.sqrt(2.0)
    g = spin_grid(r, layout="pcl", width=8)
    assert g.da == pytest.approx(0.1) and g.b0 == pytest.approx(-0.8) and g.pcl
    # last two points are inside the sphere but outside the cylinder: dropped
    P, N = _star(r, [0.2, 0.25, 0.5, 0.4, 0.85, 0.1], [0.0, 0.3, -0.5, 0.15, 0.0, 0.9])
    img = spin(P, np.array([0]), radius=r, normals=N, layout="pcl", width=8)[0]
    assert img.shape == (153,)
    img = img.reshape(9, 17)  # α-major as PCL
    assert img[0, 8] == pytest.approx(0.0, abs=1e-6)  # the keypoint itself is skipped
    assert img[2, 8] == pytest.approx(0.25, abs=1e-6)  # (α=0.2, β=0) exactly on a node
    np.testing.assert_allclose(img[2:4, 11], [0.125, 0.125], atol=1e-6)  # α=0.25 split in half
    np.testing.assert_allclose(img[5, 3], 0.25, atol=1e-6)  # (α=0.5, β=-0.5)
    assert img.sum() == pytest.approx(1.0, abs=1e-6)
    # support angle: PCL keeps opposite normals (|cos|), the "guo" layout does not
    N2 = N.copy()
    N2[1] *= -1.0
    flip = spin(P, np.array([0]), radius=r, normals=N2, layout="pcl", support_angle_deg=10.0)
    np.testing.assert_allclose(flip[0], img.ravel(), atol=1e-6)
    guo = spin(P, np.array([0]), radius=r, normals=N2, support_angle_deg=10.0)[0]
    assert np.isfinite(guo).all() and not np.allclose(
        guo, spin(P, np.array([0]), radius=r, normals=N, support_angle_deg=10.0)[0]
    )


def test_trisi_blocks_equal_spin_around_lrf_axes(surface) -> None:
    P, r = surface
    kp = np.array([3, 77, 200, 401])
    for lrf in ("points", "local_mesh"):
        T = trisi(P, kp, radius=r, lrf=lrf).reshape(len(kp), 3, 225)
        L = rops_lrf(P, kp, r, lrf=lrf)
        for a in range(3):
            axes = np.full_like(P, np.nan)
            axes[kp] = L[:, a]
            np.testing.assert_allclose(T[:, a], spin(P, kp, radius=r, normals=axes), atol=1e-7)
    # default: the point-based frame (ALGORITHMS §A.5)
    np.testing.assert_array_equal(trisi(P, kp, radius=r), trisi(P, kp, radius=r, lrf="points"))


def test_trisi_shape_and_unit_blocks(surface) -> None:
    P, r = surface
    D = compute("trisi", P, radius=r)
    assert D.shape == (len(P), 675) and D.dtype == np.float32
    ok = np.isfinite(D).all(axis=1)
    assert ok.sum() > 0.9 * len(P)
    assert np.isnan(D[~ok]).all()
    blocks = D[ok].reshape(-1, 3, 225)
    assert (blocks >= 0).all()
    np.testing.assert_allclose(blocks.sum(axis=2), 1.0, rtol=1e-5)


def test_trisi_rigid_motion_invariance(surface) -> None:
    P, r = surface
    kp = np.arange(0, len(P), 2)
    good = np.array([lrf_margin(P, i, r) >= MARGIN for i in kp])
    assert good.sum() > 0.5 * kp.size
    D0 = compute("trisi", P, radius=r, keypoints=kp)
    for seed in (4, 9):
        T = random_transform(np.random.default_rng(seed), max_translation=3.0)
        D1 = compute("trisi", transform_points(T, P), radius=r, keypoints=kp)
        np.testing.assert_allclose(D1[good], D0[good], atol=DESC_ATOL)


def test_spin_rigid_motion_invariance_and_unit_sum(surface) -> None:
    P, r = surface
    N = estimate_normals(P, radius=r)
    assert np.isfinite(N).all()
    D0 = compute("spin", P, radius=r, normals=N)
    assert D0.shape == (len(P), 225)
    assert np.isfinite(D0).all()
    np.testing.assert_allclose(D0.sum(axis=1), 1.0, rtol=1e-5)
    T = random_transform(np.random.default_rng(2), max_translation=3.0)
    D1 = compute("spin", transform_points(T, P), radius=r, normals=N @ T[:3, :3].T)
    np.testing.assert_allclose(D1, D0, atol=DESC_ATOL)
    # flipping the normal mirrors β: the image is flipped upside down
    Df = spin(P, np.arange(10), radius=r, normals=-N)
    np.testing.assert_allclose(
        Df.reshape(10, 15, 15), D0[:10].reshape(10, 15, 15)[:, ::-1], atol=1e-6
    )


def test_spin_support_angle_filter(surface) -> None:
    P, r = surface
    N = estimate_normals(P, radius=r)
    assert np.isfinite(N).all()
    kp = np.arange(0, len(P), 25)
    D = spin(P, kp, radius=r, normals=N, support_angle_deg=20.0)
    np.testing.assert_allclose(D.sum(axis=1), 1.0, rtol=1e-5)
    # with a permissive angle the filter is a no-op
    np.testing.assert_allclose(
        spin(P, kp, radius=r, normals=N, support_angle_deg=180.0),
        spin(P, kp, radius=r, normals=N),
        atol=1e-7,
    )
    assert not np.allclose(D, spin(P, kp, radius=r, normals=N))


@pytest.mark.parametrize(
    "cloud",
    [
        np.zeros((1, 3)),
        np.array([[0.0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]]),
        np.array([[0.0, 0, 0], [0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.01]]),  # 4 points
        np.tile([[1.0, 2.0, 3.0]], (12, 1)),  # duplicates
        np.c_[np.linspace(0, 0.1, 20), np.linspace(0, 0.05, 20), np.zeros(20)] + 4.0,  # line
    ],
    ids=["1pt", "3pt", "4pt", "duplicates", "collinear"],
)
def test_degenerate_input(cloud: np.ndarray) -> None:
    D = compute("trisi", cloud, radius=0.5)
    assert D.shape == (len(cloud), 675) and np.isnan(D).all()
    # spin images only need a normal: NaN below 5 support points or for a non-finite normal,
    # otherwise a valid unit-sum image (never an exception)
    S = compute("spin", cloud, radius=0.5, normals=np.tile([0.0, 0.0, 1.0], (len(cloud), 1)))
    if len(cloud) < 5:
        assert np.isnan(S).all()
    else:
        np.testing.assert_allclose(S.sum(axis=1), 1.0, rtol=1e-5)
    S = compute("spin", cloud, radius=0.5, normals=np.full((len(cloud), 3), np.nan))
    assert np.isnan(S).all()
    compute("spin", cloud, radius=0.5)  # estimated normals: must not raise


def test_bad_arguments(surface) -> None:
    P, r = surface
    with pytest.raises(InputError):
        spin(P, np.array([0]), radius=r, normals=None)
    with pytest.raises(InputError):
        spin(P, np.array([0]), radius=r, normals=np.zeros((3, 3)))
    with pytest.raises(InputError):
        trisi(P, np.array([0]), radius=0.0)
    with pytest.raises(ConfigError):
        trisi(P, np.array([0]), radius=r, interpolation="cubic")
    with pytest.raises(ConfigError):
        trisi(P, np.array([0]), radius=r, lrf="mesh")
    assert trisi(P, np.zeros(0, dtype=np.int64), radius=r).shape == (0, 675)
