"""Grouper registry: names, tolerance from the resolution, options, edge cases."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError, InputError
from relnav.geometry import random_transform, transform_points
from relnav.matching import (
    Correspondences,
    available_groupers,
    geometric_consistency_grouping,
    get_grouper,
    ransac_correspondences,
)

GROUPERS = ["gcc", "ransac", "clgv"]


def _problem(seed, n_corr=120, noise=0.002):
    rng = np.random.default_rng(seed)
    tgt = rng.uniform(-1.0, 1.0, (500, 3))
    T = random_transform(rng, max_translation=0.5)
    src = transform_points(np.linalg.inv(T), tgt) + rng.normal(0.0, noise, (500, 3))
    si = rng.choice(500, n_corr, replace=False)
    ti = si.copy()
    w = rng.random(n_corr) < 0.5
    ti[w] = rng.integers(0, 500, w.sum())
    return src, tgt, Correspondences(si, ti, rng.random(n_corr)), ti != si


def test_registry_names_and_descriptions():
    groupers = available_groupers()
    assert set(groupers) == {"gcc", "ransac", "clgv", "none"}
    assert all(isinstance(d, str) and d for d in groupers.values())
    for name in groupers:
        assert get_grouper(name).name == name


def test_unknown_name_and_bad_options_are_config_errors():
    with pytest.raises(ConfigError, match="available"):
        get_grouper("hough")
    with pytest.raises(ConfigError, match="bad options"):
        get_grouper("gcc", gc_size=1.0)
    with pytest.raises(ConfigError):
        get_grouper("gcc", epsilon=-0.1)
    with pytest.raises(ConfigError):
        get_grouper("ransac", epsilon_factor=0.0)
    with pytest.raises(ConfigError):
        get_grouper("ransac", max_iter=0)  # validated at construction, not first use
    with pytest.raises(ConfigError):
        get_grouper("clgv", keep_ratio=2.0)
    with pytest.raises(ConfigError):
        get_grouper("gcc", min_cluster_size=-1)


def test_gcc_grouper_uses_two_resolutions_by_default():
    src, tgt, corr, _ = _problem(0)
    tr = 0.01
    g = get_grouper("gcc")
    out = g.select(src, tgt, corr, resolution=tr)
    ref, clusters = geometric_consistency_grouping(src, tgt, corr, epsilon=2.0 * tr)
    np.testing.assert_array_equal(out.src_idx, ref.src_idx)
    assert g.info["epsilon"] == pytest.approx(0.02)
    assert g.info["n_clusters"] == len(clusters)
    # absolute epsilon wins over the resolution
    g2 = get_grouper("gcc", epsilon=0.02)
    out2 = g2.select(src, tgt, corr, resolution=123.0)
    np.testing.assert_array_equal(out2.src_idx, ref.src_idx)
    g3 = get_grouper("gcc", epsilon_factor=4.0)
    g3.select(src, tgt, corr, resolution=tr)
    assert g3.info["epsilon"] == pytest.approx(0.04)


def test_ransac_grouper_matches_function_and_records_seed():
    src, tgt, corr, _ = _problem(1)
    g = get_grouper("ransac", max_iter=2000, seed=5)
    out = g.select(src, tgt, corr, resolution=0.01)
    ref, T = ransac_correspondences(src, tgt, corr, threshold=0.02, max_iter=2000, seed=5)
    np.testing.assert_array_equal(out.src_idx, ref.src_idx)
    np.testing.assert_allclose(g.info["T_target_source"], T)
    assert g.info["seed"] == 5 and g.info["n_iterations"] == 2000


@pytest.mark.parametrize("name", GROUPERS)
def test_groupers_reject_most_outliers(name):
    src, tgt, corr, wrong = _problem(2, n_corr=200)
    opts = {"max_iter": 2000} if name == "ransac" else {}
    out = get_grouper(name, **opts).select(src, tgt, corr, resolution=0.01)
    chosen = set(zip(out.src_idx.tolist(), out.tgt_idx.tolist(), strict=True))
    pairs = zip(corr.src_idx.tolist(), corr.tgt_idx.tolist(), strict=True)
    kept = np.array([p in chosen for p in pairs])
    assert np.count_nonzero(kept & wrong) <= 0.1 * np.count_nonzero(wrong)
    assert np.count_nonzero(kept & ~wrong) >= 0.5 * np.count_nonzero(~wrong)


def test_none_grouper_is_identity():
    src, tgt, corr, _ = _problem(3)
    assert get_grouper("none").select(src, tgt, corr, resolution=0.01) is corr


@pytest.mark.parametrize("name", GROUPERS)
@pytest.mark.parametrize("n", [0, 1, 2, 3])
def test_too_few_correspondences_give_empty(name, n):
    pts = np.random.default_rng(0).random((6, 3))
    corr = Correspondences(np.arange(n), np.arange(n), np.zeros(n))
    opts = {"max_iter": 100} if name == "ransac" else {}
    assert len(get_grouper(name, **opts).select(pts, pts, corr, resolution=0.05)) == 0


@pytest.mark.parametrize("name", [*GROUPERS, "none"])
def test_degenerate_clouds_do_not_raise(name):
    corr = Correspondences(np.arange(15), np.arange(15), np.linspace(0, 1, 15))
    same = np.zeros((15, 3))
    line = np.outer(np.linspace(0, 1, 15), [0.0, 0.0, 1.0])
    opts = {"max_iter": 200} if name == "ransac" else {}
    g = get_grouper(name, **opts)
    for pts in (same, line):
        out = g.select(pts, pts, corr, resolution=0.05)
        assert isinstance(out, Correspondences)
        if name in ("ransac", "clgv"):
            assert len(out) == 0  # no rigid transform is determined


def test_missing_resolution_is_input_error():
    src, tgt, corr, _ = _problem(4)
    for bad in (None, 0.0, float("nan"), -1.0):
        with pytest.raises(InputError, match="resolution"):
            get_grouper("gcc").select(src, tgt, corr, resolution=bad)
    out = get_grouper("gcc", epsilon=0.02).select(src, tgt, corr, resolution=None)
    assert len(out) > 0
