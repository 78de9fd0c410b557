"""HoD / HoD-S: exact == brute force, pmf properties, invariance, fast modes, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError
from relnav.features import compute, get_descriptor
from relnav.features.hod import hod_histograms as _hod_histograms
from relnav.features.hod import visit_order
from relnav.geometry import mean_resolution, random_transform, transform_points


def bumpy_sphere(n: int, seed: int) -> np.ndarray:
    """``n`` points on a bumpy ellipsoid (no symmetries, no exact ties), metres."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    rad = 1.0 + 0.15 * np.sin(3.0 * u[:, 0]) * np.cos(2.0 * u[:, 1]) + 0.05 * u[:, 2] ** 3
    return u * rad[:, None] * np.array([1.6, 1.0, 0.7])


def hod_histograms(*args, **kwargs):
    """The all-pairs reading (ALGORITHMS §A.1) that most tests below exercise."""
    kwargs.setdefault("pairs", "all")
    return _hod_histograms(*args, **kwargs)


def brute_hod(P: np.ndarray, kp: np.ndarray, r: float, fine: bool, norm: str = "2r") -> np.ndarray:
    """Independent NumPy reference: all pairs of each support, binned as documented."""
    out = np.full((kp.size, 240 if fine else 40), np.nan)
    for k, i in enumerate(kp):
        S = P[((P - P[i]) ** 2).sum(axis=1) <= r * r]
        n = len(S)
        if n < 5:
            continue
        D = np.sqrt(((S[:, None] - S[None]) ** 2).sum(-1))[np.triu_indices(n, 1)]
        scale = 2 * r if norm == "2r" else D.max()
        if not scale > 0:
            continue
        f = np.minimum((D / scale * 200).astype(np.int64), 199)
        out[k, :40] = np.bincount(f // 5, minlength=40) / D.size
        if fine:
            out[k, 40:] = np.bincount(f, minlength=200) / D.size
    return out.astype(np.float32)


@pytest.fixture(scope="module")
def cloud() -> np.ndarray:
    return bumpy_sphere(300, seed=7)


def test_registry_entries() -> None:
    for name, dim in (("hod", 240), ("hods", 40)):
        spec = get_descriptor(name)
        assert spec.dim == dim
        assert spec.radius_factor == 80.0
        assert not spec.needs_normals


@pytest.mark.parametrize("fine", [False, True])
@pytest.mark.parametrize("r_factor", [3.0, 12.0])
def test_exact_mode_equals_brute_force(cloud: np.ndarray, fine: bool, r_factor: float) -> None:
    r = r_factor * mean_resolution(cloud)
    kp = np.arange(cloud.shape[0])
    got = hod_histograms(cloud, kp, radius=r, fine=fine)
    ref = brute_hod(cloud, kp, r, fine)
    assert got.dtype == np.float32
    assert np.array_equal(got, ref, equal_nan=True)  # integer counts → bit-identical
    if r_factor == 3.0:  # small radius: some supports are below MIN_SUPPORT
        assert np.isnan(got[:, 0]).any() and (~np.isnan(got[:, 0])).any()


def test_result_independent_of_keypoint_order_and_subset(cloud: np.ndarray) -> None:
    r = 10.0 * mean_resolution(cloud)
    kp = np.arange(cloud.shape[0])
    full = hod_histograms(cloud, kp, radius=r)
    perm = np.random.default_rng(3).permutation(kp)
    assert np.array_equal(hod_histograms(cloud, perm, radius=r), full[perm], equal_nan=True)
    sub = perm[:37]
    assert np.array_equal(hod_histograms(cloud, sub, radius=r), full[sub], equal_nan=True)


def test_visit_order_is_a_permutation(cloud: np.ndarray) -> None:
    o = visit_order(cloud)
    assert np.array_equal(np.sort(o), np.arange(cloud.shape[0]))
    # a greedy tour is much shorter than the index order
    step = np.linalg.norm(np.diff(cloud[o], axis=0), axis=1).sum()
    rnd = np.linalg.norm(np.diff(cloud, axis=0), axis=1).sum()
    assert step < 0.3 * rnd


@pytest.mark.parametrize("name", ["hod", "hods"])
def test_pmf_blocks_sum_to_one(cloud: np.ndarray, name: str) -> None:
    D = compute(name, cloud, radius=80.0 * mean_resolution(cloud))
    assert D.shape == (cloud.shape[0], get_descriptor(name).dim)
    assert not np.isnan(D).any()
    assert (D >= 0).all()
    np.testing.assert_allclose(D[:, :40].sum(axis=1), 1.0, atol=1e-5)
    if name == "hod":
        np.testing.assert_allclose(D[:, 40:].sum(axis=1), 1.0, atol=1e-5)
        # coarse bin c is the sum of fine bins 5c..5c+4
        np.testing.assert_allclose(D[:, :40], D[:, 40:].reshape(-1, 40, 5).sum(-1), atol=1e-6)


@pytest.mark.parametrize("name", ["hod", "hods"])
@pytest.mark.parametrize("mode", ["exact", "fast"])
def test_rigid_motion_invariance(cloud: np.ndarray, name: str, mode: str) -> None:
    r = 20.0 * mean_resolution(cloud)
    T = random_transform(np.random.default_rng(11), max_translation=5.0)
    A = compute(name, cloud, radius=r, mode=mode)
    B = compute(name, transform_points(T, cloud), radius=r, mode=mode)
    # Distances change only by rounding (~1e-16 relative); a pair switching bins would move
    # 1/npairs ≈ 1e-4 of mass — not expected on this random cloud, so a tight tolerance.
    np.testing.assert_allclose(A, B, atol=1e-6)


def test_support_size_rule() -> None:
    # a cluster of 5 points within r of each other + 4 far away cluster + one isolated point
    rng = np.random.default_rng(2)
    a = rng.normal(scale=0.01, size=(5, 3))
    b = rng.normal(scale=0.01, size=(4, 3)) + 10.0
    c = np.array([[-10.0, 0.0, 0.0]])
    P = np.vstack([a, b, c])
    D = hod_histograms(P, np.arange(10), radius=0.2)
    assert not np.isnan(D[:5]).any()
    assert np.isnan(D[5:]).all()


@pytest.mark.parametrize("fine", [False, True])
def test_max_normalization_matches_brute_force(cloud: np.ndarray, fine: bool) -> None:
    r = 6.0 * mean_resolution(cloud)
    kp = np.arange(0, cloud.shape[0], 3)
    got = hod_histograms(cloud, kp, radius=r, fine=fine, normalization="max")
    ref = brute_hod(cloud, kp, r, fine, norm="max")
    assert np.array_equal(got, ref, equal_nan=True)
    # scale invariance of the max normalisation
    got2 = hod_histograms(3.0 * cloud, kp, radius=3.0 * r, fine=fine, normalization="max")
    np.testing.assert_allclose(got, got2, atol=1e-6)


@pytest.mark.parametrize(("fine", "bound"), [(False, 0.01), (True, 0.02)])
def test_fast_anchors_close_to_exact(fine: bool, bound: float) -> None:
    # Measured on this cloud: mean L1 0.0044 (HoD-S) / 0.0089 (HoD) at the default spacing
    # (benchmark satellite, 880 pts: 0.009 / 0.019). Bounds are ~2.3x the measured values.
    P = bumpy_sphere(700, seed=5)
    r = 40.0 * mean_resolution(P)
    kp = np.arange(P.shape[0])
    exact = hod_histograms(P, kp, radius=r, fine=fine)
    fast = hod_histograms(P, kp, radius=r, fine=fine, mode="fast")
    assert np.array_equal(np.isnan(fast[:, 0]), np.isnan(exact[:, 0]))
    l1 = np.abs(fast - exact).sum(axis=1)
    assert l1.mean() < bound
    np.testing.assert_allclose(fast[:, :40].sum(axis=1), 1.0, atol=1e-5)
    # deterministic
    assert np.array_equal(fast, hod_histograms(P, kp, radius=r, fine=fine, mode="fast"))
    # denser anchors → closer to exact
    dense = hod_histograms(P, kp, radius=r, fine=fine, mode="fast", anchor_spacing=0.03)
    assert np.abs(dense - exact).sum(axis=1).mean() < l1.mean()


def test_fast_subsample_seeded_and_exact_when_supports_small(cloud: np.ndarray) -> None:
    r = 20.0 * mean_resolution(cloud)
    kp = np.arange(cloud.shape[0])
    opts = {"mode": "fast", "fast_method": "subsample", "n_max": 60}
    a = hod_histograms(cloud, kp, radius=r, seed=1, **opts)
    b = hod_histograms(cloud, kp, radius=r, seed=1, **opts)
    c = hod_histograms(cloud, kp, radius=r, seed=2, **opts)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    exact = hod_histograms(cloud, kp, radius=r)
    assert np.array_equal(np.isnan(a[:, 0]), np.isnan(exact[:, 0]))
    assert 0.0 < np.abs(a - exact).sum(axis=1).mean() < 1.0
    # n_max larger than every support → the exact result
    big = hod_histograms(cloud, kp, radius=r, mode="fast", fast_method="subsample", n_max=10**6)
    assert np.array_equal(big, exact, equal_nan=True)


@pytest.mark.parametrize("n", [1, 2, 4])
@pytest.mark.parametrize("name", ["hod", "hods"])
def test_tiny_clouds_give_nan_rows(n: int, name: str) -> None:
    P = np.random.default_rng(n).normal(size=(n, 3))
    for mode in ("exact", "fast"):
        D = compute(name, P, radius=100.0, mode=mode)
        assert D.shape == (n, get_descriptor(name).dim)
        assert np.isnan(D).all()


def test_duplicates_and_collinear_points() -> None:
    dup = np.zeros((8, 3))
    D = hod_histograms(dup, np.arange(8), radius=1.0)
    assert np.all(D[:, 0] == 1.0) and np.all(D[:, 40] == 1.0)  # all distances 0 → bin 0
    assert np.isnan(hod_histograms(dup, np.arange(8), radius=1.0, normalization="max")).all()
    line = np.outer(np.linspace(0.0, 1.0, 20), [1.0, 2.0, 3.0])
    for mode in ("exact", "fast"):
        L = hod_histograms(line, np.arange(20), radius=1.0, mode=mode)
        assert np.isfinite(L).all()
        np.testing.assert_allclose(L[:, :40].sum(axis=1), 1.0, atol=1e-5)


def test_bad_options_raise_config_error(cloud: np.ndarray) -> None:
    with pytest.raises(ConfigError):
        compute("hods", cloud, radius=1.0, mode="fastest")
    with pytest.raises(ConfigError):
        compute("hods", cloud, radius=1.0, normalization="median")
    with pytest.raises(ConfigError):
        compute("hods", cloud, radius=1.0, bins=12)
    with pytest.raises(ConfigError):
        compute("hod", cloud, radius=1.0, mode="fast", fast_method="pairs")


def brute_hod_keypoint(P: np.ndarray, kp: np.ndarray, r: float, fine: bool) -> np.ndarray:
    """pmf of ‖q − p‖ / r over the support of each keypoint (keypoint excluded), plain NumPy."""
    nf = 200
    out = np.full((kp.size, 40 + (nf if fine else 0)), np.nan, dtype=np.float32)
    for row, k in enumerate(kp):
        d = np.linalg.norm(P - P[k], axis=1)
        inside = np.flatnonzero(d <= r)
        if inside.size < 5:
            continue
        others = inside[inside != k]
        b = np.minimum((d[others] / r * nf).astype(int), nf - 1)
        h = np.bincount(b, minlength=nf)
        out[row, :40] = h.reshape(40, 5).sum(axis=1) / others.size
        if fine:
            out[row, 40:] = h / others.size
    return out


@pytest.mark.parametrize("fine", [False, True])
def test_keypoint_pairs_equal_brute_force(cloud: np.ndarray, fine: bool) -> None:
    r = 3.0 * mean_resolution(cloud)
    kp = np.arange(cloud.shape[0])
    got = _hod_histograms(cloud, kp, radius=r, fine=fine)  # pairs="keypoint" is the default
    np.testing.assert_allclose(got, brute_hod_keypoint(cloud, kp, r, fine), atol=1e-6)


def test_keypoint_pairs_discriminate_where_all_pairs_do_not(rng: np.random.Generator) -> None:
    """At r = 80·Tr on a small compact cloud every all-pairs histogram is the same (the support is
    the whole cloud); the keypoint-centred ones still differ from point to point."""
    d = rng.normal(size=(300, 3))
    P = d / np.linalg.norm(d, axis=1, keepdims=True) * np.array([3.0, 2.0, 1.0])
    r = 80.0 * mean_resolution(P)
    kp = np.arange(P.shape[0])
    all_pairs = _hod_histograms(P, kp, radius=r, fine=False, pairs="all")
    keypoint = _hod_histograms(P, kp, radius=r, fine=False, pairs="keypoint")
    assert np.ptp(all_pairs, axis=0).max() < 1e-6
    assert np.ptp(keypoint, axis=0).max() > 0.05
