"""SHOT and the SHOT LRF (+ the grid radius search they use)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from relnav.errors import ConfigError, InputError
from relnav.features import compute, get_descriptor
from relnav.features.shot import (
    _SPEC_FROM_PCL,
    SHOT_DIM,
    _accumulate_pcl,
    _accumulate_product,
    _volume_pcl,
    shot,
)
from relnav.geometry import estimate_normals, mean_resolution, random_transform, transform_points
from relnav.geometry.lrf import _shot_lrf_full, radius_search, shot_lrf


def bumpy_sphere(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    rad = 1.0 + 0.15 * np.sin(3.0 * u[:, 0]) * np.cos(2.0 * u[:, 1]) + 0.05 * u[:, 2] ** 3
    return u * rad[:, None] * np.array([1.6, 1.0, 0.7])


@pytest.fixture(scope="module")
def scene() -> tuple[np.ndarray, np.ndarray, float]:
    P = bumpy_sphere(400, seed=3)
    N = estimate_normals(P, k=15, viewpoint=np.zeros(3))
    N = -N  # outward (the viewpoint is inside)
    return P, N, 10.0 * mean_resolution(P)


def test_registry_entry() -> None:
    spec = get_descriptor("shot")
    assert (spec.dim, spec.radius_factor, spec.needs_normals) == (352, 20.0, True)


def test_radius_search_matches_kdtree(scene) -> None:
    P, _, r = scene
    Q = P[::7] + 0.01
    off, idx, d2 = radius_search(P, Q, r)
    ref = cKDTree(P).query_ball_point(Q, r)
    for k in range(Q.shape[0]):
        row = idx[off[k] : off[k + 1]]
        assert sorted(row.tolist()) == sorted(ref[k])
        np.testing.assert_allclose(d2[off[k] : off[k + 1]], ((P[row] - Q[k]) ** 2).sum(1))
    off_s, _, d2_s = radius_search(P, Q, r, sort=True)
    assert np.array_equal(off_s, off)
    for k in range(Q.shape[0]):
        assert np.all(np.diff(d2_s[off_s[k] : off_s[k + 1]]) >= 0)
    # a query far outside the cloud's bounding box
    off2, idx2, _ = radius_search(P, np.array([[100.0, 0.0, 0.0]]), r)
    assert off2[-1] == 0 and idx2.size == 0


def test_shot_lrf_is_orthonormal_and_matches_tree_path(scene) -> None:
    P, _, r = scene
    kp = np.arange(P.shape[0])
    L = shot_lrf(P, kp, r)
    assert L.shape == (P.shape[0], 3, 3)
    assert not np.isnan(L).any()
    np.testing.assert_allclose(
        L @ L.transpose(0, 2, 1), np.broadcast_to(np.eye(3), L.shape), atol=1e-12
    )
    np.testing.assert_allclose(np.linalg.det(L), 1.0, atol=1e-12)
    np.testing.assert_allclose(shot_lrf(P, kp, r, tree=cKDTree(P)), L, atol=1e-12)


def test_shot_lrf_rotation_equivariance(scene) -> None:
    P, _, r = scene
    kp = np.arange(P.shape[0])
    T = random_transform(np.random.default_rng(4), max_translation=3.0)
    L1, ties1 = _shot_lrf_full(P, kp, r)
    L2, ties2 = _shot_lrf_full(transform_points(T, P), kp, r)
    assert np.array_equal(ties1, ties2)
    ok = ~ties1.any(axis=1)
    assert ok.mean() > 0.8
    # LRF rows rotate with the cloud: L2 = L1 Rᵀ
    np.testing.assert_allclose(L2[ok], L1[ok] @ T[:3, :3].T, atol=1e-10)


def test_shot_lrf_needs_five_neighbours_besides_the_keypoint() -> None:
    rng = np.random.default_rng(0)
    P = rng.normal(scale=0.05, size=(6, 3))
    assert not np.isnan(shot_lrf(P, np.array([0]), 1.0)).any()  # 5 neighbours
    assert np.isnan(shot_lrf(P[:5], np.array([0]), 1.0)).all()  # 4 neighbours
    # duplicates of the keypoint do not count
    Pd = np.vstack([P[:5], P[:1]])
    assert np.isnan(shot_lrf(Pd, np.array([0]), 1.0)).all()


@pytest.mark.parametrize("interp", ["pcl", "product"])
def test_rigid_motion_invariance(scene, interp: str) -> None:
    P, N, r = scene
    kp = np.arange(P.shape[0])
    T = random_transform(np.random.default_rng(9), max_translation=3.0)
    A = compute("shot", P, radius=r, normals=N, interp=interp)
    B = compute("shot", transform_points(T, P), radius=r, normals=N @ T[:3, :3].T, interp=interp)
    _, ties = _shot_lrf_full(P, kp, r)
    ok = ~ties.any(axis=1)  # LRF sign decided by a majority (no tie-break)
    assert ok.mean() > 0.8
    # measured: identical in float32; tolerance 1e-6 covers rounding of the LRF (~1e-14)
    np.testing.assert_allclose(A[ok], B[ok], atol=1e-6)


@pytest.mark.parametrize("interp", ["pcl", "product"])
def test_unit_l2_norm_and_nonnegative(scene, interp: str) -> None:
    P, N, r = scene
    D = shot(P, np.arange(P.shape[0]), radius=r, normals=N, interp=interp)
    assert D.shape == (P.shape[0], SHOT_DIM) and D.dtype == np.float32
    assert not np.isnan(D).any()
    np.testing.assert_allclose(np.linalg.norm(D, axis=1), 1.0, atol=1e-5)
    assert (D >= -1e-7).all()


def test_interpolation_variants_differ(scene) -> None:
    P, N, r = scene
    kp = np.arange(0, P.shape[0], 10)
    a = shot(P, kp, radius=r, normals=N)
    b = shot(P, kp, radius=r, normals=N, interp="product")
    assert np.abs(a - b).max() > 1e-2


def test_planar_patch_puts_all_mass_in_the_extreme_cosine_bin() -> None:
    rng = np.random.default_rng(1)
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 15), np.linspace(-1, 1, 15)), -1).reshape(-1, 2)
    P = np.column_stack([g + rng.uniform(-0.02, 0.02, g.shape), np.zeros(len(g))])
    N = np.tile([0.0, 0.0, 1.0], (len(P), 1))
    kp = np.arange(len(P))
    r = 0.5
    D = shot(P, kp, radius=r, normals=N, layout="pcl").reshape(len(P), 32, 11)
    zsign = shot_lrf(P, kp, r)[:, 2, 2]
    ok = ~np.isnan(D[:, 0, 0])
    assert ok.sum() > 100
    for k in np.flatnonzero(ok):
        slot = 10 if zsign[k] > 0 else 0  # cos θ = n·z_LRF = ±1
        mass = (D[k] ** 2).sum(axis=0)
        assert mass[slot] > 1.0 - 1e-6


def test_layouts_are_column_permutations(scene) -> None:
    P, N, r = scene
    kp = np.arange(0, P.shape[0], 13)
    spec = shot(P, kp, radius=r, normals=N)
    pcl = shot(P, kp, radius=r, normals=N, layout="pcl")
    assert np.array_equal(spec, pcl[:, _SPEC_FROM_PCL])
    # spec index ((a·2 + e)·2 + s)·11 + c ↔ PCL ((a·2 + s)·2 + e)·11 + c
    a, e, s, c = 5, 1, 0, 7
    assert _SPEC_FROM_PCL[((a * 2 + e) * 2 + s) * 11 + c] == ((a * 2 + s) * 2 + e) * 11 + c


def test_pcl_interpolation_known_answer() -> None:
    """One neighbour, hand-derived from ALGORITHMS §A.2 (PCL additive interpolation)."""
    r = 1.0
    d, phi, incl = 0.6 * r, np.deg2rad(30.0), np.deg2rad(80.0)
    x, y, z = d * np.sin(incl) * np.cos(phi), d * np.sin(incl) * np.sin(phi), d * np.cos(incl)
    desc, sel = _volume_pcl(x, y, z, d, r / 2)
    assert (sel, desc) == (4, 4 * 4 + 1 * 2 + 1)  # sector 4 (22.5° centre), outer, upper
    h = np.zeros(352)
    _accumulate_pcl(h, desc, sel, 10.0, x, y, z, d, r)  # cos θ = 1 → bin_pos 10
    dr = (0.6 - 0.75) / 0.5  # −0.3
    de = (80.0 - 45.0) / 90.0
    da = (30.0 - 22.5) / 45.0
    expected = np.zeros(352)
    expected[19 * 11 + 10] = 1.0 + (1 + dr) + (1 - de) + (1 - da)
    expected[17 * 11 + 10] = -dr  # inner shell
    expected[18 * 11 + 10] = de  # lower half
    expected[23 * 11 + 10] = da  # next sector
    np.testing.assert_allclose(h, expected, atol=1e-12)
    hp = np.zeros(352)
    _accumulate_product(hp, desc, sel, 10.0, x, y, z, d, r)
    assert hp.sum() == pytest.approx(1.0)  # unit mass per neighbour
    assert hp.argmax() == 19 * 11 + 10


@pytest.mark.parametrize("n", [1, 2, 4, 5])
def test_tiny_clouds_give_nan_rows(n: int) -> None:
    P = np.random.default_rng(n).normal(size=(n, 3))
    D = compute("shot", P, radius=100.0, normals=np.tile([0.0, 0.0, 1.0], (n, 1)))
    assert D.shape == (n, 352)
    assert np.isnan(D).all()  # ≤ 4 neighbours besides each keypoint


def test_degenerate_inputs_do_not_raise(scene) -> None:
    dup = np.zeros((10, 3))
    assert np.isnan(compute("shot", dup, radius=1.0, normals=np.tile([0, 0, 1.0], (10, 1)))).all()
    line = np.outer(np.linspace(0.0, 1.0, 30), [1.0, 2.0, 3.0])
    L = compute("shot", line, radius=0.5, normals=np.tile([0, 0, 1.0], (30, 1)))
    ok = ~np.isnan(L[:, 0])
    assert np.isfinite(L[ok]).all()
    np.testing.assert_allclose(np.linalg.norm(L[ok], axis=1), 1.0, atol=1e-5)
    # NaN normals are skipped; all-NaN normals → NaN rows
    P, N, r = scene
    Nn = N.copy()
    Nn[::3] = np.nan
    D = shot(P, np.arange(50), radius=r, normals=Nn)
    assert np.isfinite(D).all()
    assert np.isnan(shot(P, np.arange(5), radius=r, normals=np.full_like(N, np.nan))).all()


def test_bad_arguments(scene) -> None:
    P, N, r = scene
    with pytest.raises(ConfigError):
        shot(P, np.arange(3), radius=r, normals=N, interp="cubic")
    with pytest.raises(ConfigError):
        shot(P, np.arange(3), radius=r, normals=N, layout="weird")
    with pytest.raises(ConfigError):
        compute("shot", P, radius=r, normals=N, bins=12)
    with pytest.raises(InputError):
        shot(P, np.arange(3), radius=r, normals=None)
    with pytest.raises(InputError):
        shot(P, np.arange(3), radius=r, normals=N[:5])
    # a separate LRF radius is accepted
    D = shot(P, np.arange(20), radius=r, normals=N, lrf_radius=0.7 * r)
    assert np.isfinite(D).all()
