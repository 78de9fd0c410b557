"""τ-gated exact NN descriptor matching against a brute-force (scipy cdist) oracle."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from relnav.errors import ConfigError, InputError
from relnav.matching import Correspondences, match_descriptors, normalize_descriptors


def _oracle(src, tgt, tau, mutual=False):
    """Brute force in float64: (src_row, tgt_row, distance, margin to the runner-up)."""
    a = src / np.linalg.norm(src, axis=1, keepdims=True)
    b = tgt / np.linalg.norm(tgt, axis=1, keepdims=True)
    sv = np.flatnonzero(np.isfinite(a).all(axis=1))
    tv = np.flatnonzero(np.isfinite(b).all(axis=1))
    D = cdist(a[sv], b[tv])
    j = np.argmin(D, axis=1)
    d = D[np.arange(len(sv)), j]
    srt = np.sort(D, axis=1)
    margin = srt[:, 1] - srt[:, 0] if D.shape[1] > 1 else np.full(len(sv), np.inf)
    keep = d < tau
    if mutual:
        i_back = np.argmin(D, axis=0)
        keep &= i_back[j] == np.arange(len(sv))
    return sv[keep], tv[j[keep]], d[keep], margin[keep]


def _hist_desc(rng, k, dim=33):
    """Non-negative, histogram-like descriptors with some structure (shared prototypes)."""
    protos = rng.gamma(0.5, size=(8, dim))
    lab = rng.integers(0, 8, k)
    return (protos[lab] + 0.3 * rng.gamma(0.5, size=(k, dim))).astype(np.float32)


def test_normalize_rows_unit_nan_and_zero():
    F = np.array([[3.0, 4.0], [0.0, 0.0], [np.nan, 1.0], [1.0, np.inf], [0.0, 2.0]])
    N = normalize_descriptors(F)
    assert N.dtype == np.float32
    np.testing.assert_allclose(N[0], [0.6, 0.8], atol=1e-7)
    np.testing.assert_allclose(N[4], [0.0, 1.0])
    assert np.isnan(N[1:4]).all()
    big = normalize_descriptors(np.array([[1e200, 1e200], [3, 4]]))  # |F|² overflows float64
    np.testing.assert_allclose(big[0], [2**-0.5, 2**-0.5], rtol=1e-6)
    ints = normalize_descriptors(np.array([[0, 5]]))
    np.testing.assert_allclose(ints, [[0.0, 1.0]])
    with pytest.raises(InputError):
        normalize_descriptors(np.ones(5))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_nn_equals_brute_force_without_gate(seed):
    rng = np.random.default_rng(seed)
    src, tgt = _hist_desc(rng, 120), _hist_desc(rng, 150)
    corr = match_descriptors(src, tgt, tau=np.inf)
    si, ti, d, margin = _oracle(src.astype(np.float64), tgt.astype(np.float64), np.inf)
    np.testing.assert_array_equal(corr.src_idx, si)  # every valid source row, in order
    clear = margin > 1e-5  # float32 similarity cannot separate closer runner-ups
    assert clear.mean() > 0.9
    np.testing.assert_array_equal(corr.tgt_idx[clear], ti[clear])
    np.testing.assert_allclose(corr.distance, d, atol=1e-6)
    assert corr.distance.dtype == np.float64


def test_nn_tau_gate_is_strict_and_exact():
    rng = np.random.default_rng(5)
    src, tgt = _hist_desc(rng, 200), _hist_desc(rng, 180)
    full = match_descriptors(src, tgt, tau=np.inf)
    tau = float(np.median(full.distance))
    gated = match_descriptors(src, tgt, tau=tau)
    si, _, _, _ = _oracle(src.astype(np.float64), tgt.astype(np.float64), tau)
    assert 0 < len(gated) < len(full)
    assert np.all(gated.distance < tau)
    # same accepted set, up to pairs within rounding of the gate
    far = np.abs(full.distance - tau) > 1e-6
    expect = set(full.src_idx[far & (full.distance < tau)])
    got = set(gated.src_idx) & set(full.src_idx[far])
    assert got == expect
    assert set(si) & set(full.src_idx[far]) == expect
    # paper default tau = 1 on non-negative unit vectors: only pairs with cosine > 0.5
    cos = 1.0 - 0.5 * full.distance**2
    one = match_descriptors(src, tgt)
    assert set(one.src_idx) == set(full.src_idx[cos > 0.5])


def test_nn_mutual_check_against_brute_force():
    rng = np.random.default_rng(7)
    src, tgt = _hist_desc(rng, 90), _hist_desc(rng, 110)
    corr = match_descriptors(src, tgt, tau=np.inf, mutual=True)
    si, ti, _, _ = _oracle(src.astype(np.float64), tgt.astype(np.float64), np.inf, mutual=True)
    assert 0 < len(corr) < 90
    # allow disagreement only through float32 near-ties: compare as sets with small slack
    a = set(zip(corr.src_idx.tolist(), corr.tgt_idx.tolist(), strict=True))
    b = set(zip(si.tolist(), ti.tolist(), strict=True))
    assert len(a ^ b) <= 2
    # mutual pairs are one-to-one
    assert len(np.unique(corr.tgt_idx)) == len(corr)


def test_nn_nan_rows_skipped_and_keypoint_maps():
    rng = np.random.default_rng(3)
    src, tgt = _hist_desc(rng, 40), _hist_desc(rng, 30)
    src[[2, 5]] = np.nan
    src[7] = 0.0  # zero descriptor: invalid
    tgt[[0, 11]] = np.nan
    src_kp = rng.permutation(1000)[:40]
    tgt_kp = rng.permutation(500)[:30]
    corr = match_descriptors(src, tgt, tau=np.inf, src_keypoints=src_kp, tgt_keypoints=tgt_kp)
    plain = match_descriptors(src, tgt, tau=np.inf)
    valid_rows = np.setdiff1d(np.arange(40), [2, 5, 7])
    np.testing.assert_array_equal(plain.src_idx, valid_rows)
    assert not np.isin(plain.tgt_idx, [0, 11]).any()
    np.testing.assert_array_equal(corr.src_idx, src_kp[plain.src_idx])
    np.testing.assert_array_equal(corr.tgt_idx, tgt_kp[plain.tgt_idx])


def test_nn_chunked_equals_unchunked():
    rng = np.random.default_rng(11)
    src, tgt = _hist_desc(rng, 257), _hist_desc(rng, 97)
    a = match_descriptors(src, tgt, tau=0.8, mutual=True)
    b = match_descriptors(src, tgt, tau=0.8, mutual=True, chunk_bytes=4 * 97 * 10)  # 10 rows
    np.testing.assert_array_equal(a.src_idx, b.src_idx)
    np.testing.assert_array_equal(a.tgt_idx, b.tgt_idx)
    np.testing.assert_array_equal(a.distance, b.distance)


def test_nn_identical_descriptors_give_zero_distance():
    rng = np.random.default_rng(1)
    d = rng.random((50, 352)).astype(np.float32)
    corr = match_descriptors(d, d[::-1].copy())
    np.testing.assert_array_equal(corr.tgt_idx, 49 - np.arange(50))
    assert corr.distance.max() < 1e-6  # float64 recomputation, no float32 cancellation


def test_nn_empty_and_all_invalid():
    rng = np.random.default_rng(0)
    d = _hist_desc(rng, 10)
    assert len(match_descriptors(np.zeros((0, 33), np.float32), d)) == 0
    assert len(match_descriptors(d, np.zeros((0, 33), np.float32))) == 0
    assert len(match_descriptors(np.full((4, 33), np.nan), d)) == 0
    assert isinstance(match_descriptors(d, d), Correspondences)


def test_nn_bad_input():
    d = np.ones((4, 3), np.float32)
    with pytest.raises(InputError, match="dimensions"):
        match_descriptors(d, np.ones((4, 5), np.float32))
    with pytest.raises(InputError, match="src_keypoints"):
        match_descriptors(d, d, src_keypoints=np.arange(3))
    with pytest.raises(ConfigError, match="tau"):
        match_descriptors(d, d, tau=0.0)
    with pytest.raises(ConfigError, match="tau"):
        match_descriptors(d, d, tau=float("nan"))
