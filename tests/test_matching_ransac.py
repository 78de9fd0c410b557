"""RANSAC and CLGV on correspondences: known-motion recovery with 50 % outliers, seeding."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError
from relnav.geometry import kabsch, random_transform, rotation_angle, transform_points
from relnav.matching import (
    Correspondences,
    clgv_select,
    clgv_vote,
    ransac_correspondences,
    ransac_search,
)
from relnav.matching.ransac import BATCH, _kabsch_triangle, sample_triplets

NOISE = 0.002  # m, on the source points
THETA = 0.02  # m, inlier threshold / epsilon (≈ 10 σ)


def _problem(seed, n_corr=200, outlier_frac=0.5, n_pts=1000):
    """Target cloud, source = T_src_tgt · target + noise; half the pairings wrong."""
    rng = np.random.default_rng(seed)
    tgt = rng.uniform(-1.0, 1.0, (n_pts, 3))
    T_target_source = random_transform(rng, max_translation=0.5)
    src = transform_points(np.linalg.inv(T_target_source), tgt)
    src = src + rng.normal(0.0, NOISE, src.shape)
    src_idx = rng.choice(n_pts, n_corr, replace=False)
    tgt_idx = src_idx.copy()
    w = rng.random(n_corr) < outlier_frac
    tgt_idx[w] = rng.integers(0, n_pts, w.sum())
    corr = Correspondences(src_idx, tgt_idx, rng.random(n_corr))
    return src, tgt, corr, tgt_idx != src_idx, T_target_source


def _pose_errors(T_est, T_true):
    dR = T_est[:3, :3] @ T_true[:3, :3].T
    return np.degrees(rotation_angle(dR)), np.linalg.norm(T_est[:3, 3] - T_true[:3, 3])


def _kept_mask(corr, sel):
    chosen = set(zip(sel.src_idx.tolist(), sel.tgt_idx.tolist(), strict=True))
    pairs = zip(corr.src_idx.tolist(), corr.tgt_idx.tolist(), strict=True)
    return np.array([p in chosen for p in pairs])


def test_sample_triplets_distinct_and_uniform():
    rng = np.random.default_rng(0)
    t = sample_triplets(rng, 7, 70_000)
    assert t.min() == 0 and t.max() == 6
    assert np.all((t[:, 0] != t[:, 1]) & (t[:, 0] != t[:, 2]) & (t[:, 1] != t[:, 2]))
    freq = np.bincount(t.ravel(), minlength=7) / t.size
    np.testing.assert_allclose(freq, 1 / 7, atol=0.01)
    assert np.all(np.sort(sample_triplets(rng, 3, 50), axis=1) == [0, 1, 2])


def test_closed_form_triangle_kabsch_equals_svd_kabsch():
    rng = np.random.default_rng(8)
    R, t = np.empty((3, 3)), np.empty(3)
    for i in range(300):
        s = rng.normal(size=(3, 3))
        if i % 3 == 0:  # rigid + noise
            m = transform_points(random_transform(rng), s) + rng.normal(0, 0.05, (3, 3))
        elif i % 3 == 1:  # unrelated triangles
            m = rng.normal(size=(3, 3))
        else:  # mirror images: the optimum flips the plane normal
            m = transform_points(random_transform(rng), s * [1.0, 1.0, -1.0])
        _kabsch_triangle(s, m, 0, 1, 2, R, t)
        T = kabsch(s, m)
        np.testing.assert_allclose(R, T[:3, :3], atol=1e-9)
        np.testing.assert_allclose(t, T[:3, 3], atol=1e-9)
        assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ransac_recovers_transform_with_half_outliers(seed):
    src, tgt, corr, wrong, T_true = _problem(seed)
    inliers, T = ransac_correspondences(src, tgt, corr, threshold=THETA, seed=seed)
    rot_deg, trans_m = _pose_errors(T, T_true)
    assert rot_deg < 0.3 and trans_m < 0.005
    kept = _kept_mask(corr, inliers)
    assert np.count_nonzero(kept & wrong) <= 0.02 * np.count_nonzero(wrong)
    assert np.count_nonzero(kept & ~wrong) >= 0.98 * np.count_nonzero(~wrong)


def test_ransac_equals_plain_numpy_reference():
    """Same samples (same seed), SVD Kabsch + full inlier counts, first best hypothesis."""
    src, tgt, corr, _, _ = _problem(6, n_corr=120, outlier_frac=0.6)
    n_it = 500
    assert n_it <= BATCH  # a single batch: the reference draws the same samples
    samples = sample_triplets(np.random.default_rng(21), len(corr), n_it)
    s, m = src[corr.src_idx], tgt[corr.tgt_idx]
    counts = []
    for smp in samples:
        a, b = s[smp], m[smp]
        area = min(
            0.5 * np.linalg.norm(np.cross(a[1] - a[0], a[2] - a[0])),
            0.5 * np.linalg.norm(np.cross(b[1] - b[0], b[2] - b[0])),
        )
        if area < 1e-6:
            counts.append(-1)
            continue
        T = kabsch(a, b)
        counts.append(int(np.sum(np.linalg.norm(transform_points(T, s) - m, axis=1) < THETA)))
    best = samples[int(np.argmax(counts))]
    T0 = kabsch(s[best], m[best])
    mask = np.linalg.norm(transform_points(T0, s) - m, axis=1) < THETA
    r = ransac_search(src, tgt, corr, threshold=THETA, max_iter=n_it, seed=21)
    assert r.success and counts.count(max(counts)) > 1  # the tie-break is exercised
    np.testing.assert_array_equal(r.inlier_mask, mask)
    np.testing.assert_allclose(r.T_target_source, kabsch(s[mask], m[mask]), atol=1e-12)
    assert r.best_count == max(counts)


def test_ransac_same_seed_same_result_and_recorded():
    src, tgt, corr, _, _ = _problem(3, outlier_frac=0.7)
    a = ransac_search(src, tgt, corr, threshold=THETA, max_iter=3000, seed=17)
    b = ransac_search(src, tgt, corr, threshold=THETA, max_iter=3000, seed=17)
    np.testing.assert_array_equal(a.inlier_mask, b.inlier_mask)
    np.testing.assert_array_equal(a.T_target_source, b.T_target_source)
    assert a.seed == 17 and a.n_iterations == 3000 and a.success


def test_ransac_adaptive_stops_early_and_still_recovers():
    src, tgt, corr, _, T_true = _problem(4)
    r = ransac_search(src, tgt, corr, threshold=THETA, adaptive=True, seed=0)
    assert r.success
    # w ≈ 0.5 → log(0.01) / log(1 − 0.125) ≈ 35 hypotheses
    assert r.n_iterations < 200
    assert r.n_iterations >= r.info["adaptive_target"] - 1
    rot_deg, trans_m = _pose_errors(r.T_target_source, T_true)
    assert rot_deg < 0.3 and trans_m < 0.005


def test_ransac_failure_cases_return_empty_identity():
    pts = np.random.default_rng(0).random((10, 3))
    for n in range(4):  # 0–3 correspondences: nothing can be verified
        corr = Correspondences(np.arange(n), np.arange(n), np.zeros(n))
        inl, T = ransac_correspondences(pts, pts, corr, threshold=0.1, max_iter=100)
        assert len(inl) == 0 and np.array_equal(T, np.eye(4))
    corr = Correspondences(np.arange(10), np.arange(10), np.zeros(10))
    same = np.ones((10, 3))
    r = ransac_search(same, same, corr, threshold=0.1, max_iter=500)
    assert not r.success and len(r.inliers) == 0 and r.n_degenerate == 500
    line = np.outer(np.linspace(0, 1, 10), [1.0, -2.0, 0.5])
    inl, T = ransac_correspondences(line, line, corr, threshold=0.1, max_iter=500)
    assert len(inl) == 0 and np.array_equal(T, np.eye(4))


def test_ransac_bad_options():
    src, tgt, corr, _, _ = _problem(0, n_corr=20)
    with pytest.raises(ConfigError):
        ransac_correspondences(src, tgt, corr, threshold=-1.0)
    with pytest.raises(ConfigError):
        ransac_correspondences(src, tgt, corr, threshold=0.1, max_iter=0)
    with pytest.raises(ConfigError):
        ransac_correspondences(src, tgt, corr, threshold=0.1, confidence=1.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clgv_keeps_mostly_inliers(seed):
    src, tgt, corr, wrong, _ = _problem(seed, n_corr=300)
    r = clgv_vote(src, tgt, corr, epsilon=THETA, seed=seed)
    kept = _kept_mask(corr, r.selected)
    assert np.count_nonzero(kept & wrong) <= 0.05 * kept.sum()  # precision ≥ 95 %
    # Recall is limited by the noisy k=10 local vote (≈ binomial(10, 0.5) among inliers)
    # against keep_ratio · max score (measured 0.68–0.91 at keep_ratio = 0.5).
    assert np.count_nonzero(kept & ~wrong) >= 0.6 * np.count_nonzero(~wrong)
    loose = clgv_select(src, tgt, corr, epsilon=THETA, seed=seed, keep_ratio=0.3)
    kept = _kept_mask(corr, loose)
    assert np.count_nonzero(kept & wrong) <= 0.05 * kept.sum()
    assert np.count_nonzero(kept & ~wrong) >= 0.85 * np.count_nonzero(~wrong)
    # each vote separates the classes on its own
    assert r.local_score[~wrong].mean() > 3 * r.local_score[wrong].mean()
    assert r.global_score[~wrong].mean() > 0.9 > 0.1 > r.global_score[wrong].mean()
    assert r.seed == seed and r.n_valid_hypotheses > 0


def test_clgv_seeded_and_select_matches_vote():
    src, tgt, corr, _, _ = _problem(5, n_corr=150)
    a = clgv_select(src, tgt, corr, epsilon=THETA, seed=3)
    b = clgv_select(src, tgt, corr, epsilon=THETA, seed=3)
    c = clgv_vote(src, tgt, corr, epsilon=THETA, seed=3).selected
    for x in (b, c):
        np.testing.assert_array_equal(a.src_idx, x.src_idx)
        np.testing.assert_array_equal(a.tgt_idx, x.tgt_idx)


def test_clgv_failure_cases_no_exception():
    pts = np.random.default_rng(0).random((12, 3))
    for n in range(4):
        corr = Correspondences(np.arange(n), np.arange(n), np.zeros(n))
        assert len(clgv_select(pts, pts, corr, epsilon=0.1)) == 0
    corr = Correspondences(np.arange(12), np.arange(12), np.zeros(12))
    same = np.ones((12, 3))
    r = clgv_vote(same, same, corr, epsilon=0.1, n_hypotheses=50)
    assert len(r.selected) == 0 and "degenerate" in r.info["message"]
    line = np.outer(np.linspace(0, 1, 12), [1.0, 2.0, 3.0])
    assert len(clgv_select(line, line, corr, epsilon=0.1, n_hypotheses=50)) == 0
    with pytest.raises(ConfigError):
        clgv_select(pts, pts, corr, epsilon=0.1, keep_ratio=0.0)
