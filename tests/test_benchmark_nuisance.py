"""Nuisance post-processing of scans (robustness benchmark): known answers and determinism."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError, InputError
from relnav.sim.nuisance import NuisanceSpec, apply_nuisance, nuisance_rng


@pytest.fixture
def cloud(rng: np.random.Generator) -> np.ndarray:
    # a 2 m blob 20 m in front of the sensor (x forward)
    return rng.normal(size=(2000, 3)) * 0.5 + np.array([20.0, 0.0, 0.0])


def test_identity_is_a_copy(cloud, rng):
    spec = NuisanceSpec()
    assert spec.is_identity and spec.label == "clean" and spec.key == "clean"
    out = apply_nuisance(cloud, spec, rng)
    assert out is not cloud and np.array_equal(out, cloud)


def test_keep_fraction_takes_a_subset(cloud, rng):
    out = apply_nuisance(cloud, NuisanceSpec(keep_fraction=0.25), rng)
    assert len(out) == 500
    # every kept point is an original point
    assert np.isin(out.view([("", float)] * 3), cloud.view([("", float)] * 3)).all()


def test_halfspace_removes_one_side(cloud, rng):
    out = apply_nuisance(cloud, NuisanceSpec(occlusion="halfspace", occlusion_fraction=0.3), rng)
    assert abs(len(out) - 1400) <= 2
    # the removed points are separable by a plane: their convex hull misses the kept ones
    removed = cloud[~np.isin(cloud[:, 0], out[:, 0])]
    centre_gap = removed.mean(axis=0) - out.mean(axis=0)
    u = centre_gap / np.linalg.norm(centre_gap)
    assert (removed @ u).min() > np.quantile(out @ u, 0.5)


def test_cone_removes_an_angular_patch(cloud, rng):
    out = apply_nuisance(cloud, NuisanceSpec(occlusion="cone", occlusion_fraction=0.2), rng)
    assert len(out) == 1600
    out2 = apply_nuisance(
        cloud,
        NuisanceSpec(occlusion="cone", occlusion_half_angle_deg=0.5),
        nuisance_rng(0, NuisanceSpec(occlusion="cone", occlusion_half_angle_deg=0.5), 0),
    )
    assert 0 < len(cloud) - len(out2) < len(cloud)


def test_range_noise_is_along_the_ray(cloud, rng):
    sigma = 0.05
    out = apply_nuisance(cloud, NuisanceSpec(range_sigma_m=sigma), rng)
    assert out.shape == cloud.shape
    d_in = cloud / np.linalg.norm(cloud, axis=1, keepdims=True)
    d_out = out / np.linalg.norm(out, axis=1, keepdims=True)
    assert np.allclose(d_in, d_out, atol=1e-12)  # direction unchanged
    dr = np.linalg.norm(out, axis=1) - np.linalg.norm(cloud, axis=1)
    assert abs(dr.std() - sigma) < 0.1 * sigma and abs(dr.mean()) < 4 * sigma / np.sqrt(2000)


def test_outliers_in_the_enlarged_box(cloud, rng):
    out = apply_nuisance(cloud, NuisanceSpec(outlier_fraction=0.1), rng)
    assert len(out) == 2200
    assert np.array_equal(out[:2000], cloud)
    lo, hi = cloud.min(axis=0), cloud.max(axis=0)
    c, half = (lo + hi) / 2, 0.6 * (hi - lo)
    extra = out[2000:]
    assert (np.abs(extra - c) <= half + 1e-12).all()
    assert (np.abs(extra - c) > 0.5 * (hi - lo)).any()  # some fall outside the original box


def test_deterministic_per_seed_and_frame(cloud):
    spec = NuisanceSpec(range_sigma_m=0.01, outlier_fraction=0.05, keep_fraction=0.8)
    a = apply_nuisance(cloud, spec, nuisance_rng(3, spec, 7))
    b = apply_nuisance(cloud, spec, nuisance_rng(3, spec, 7))
    c = apply_nuisance(cloud, spec, nuisance_rng(4, spec, 7))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_bad_specs_and_points():
    with pytest.raises(ConfigError, match="keep_fraction"):
        NuisanceSpec.parse({"keep_fraction": 0.0})
    with pytest.raises(ConfigError, match="occlusion"):
        NuisanceSpec.parse({"occlusion_fraction": 0.2})  # no occlusion kind
    with pytest.raises(ConfigError, match="unknown key"):
        NuisanceSpec.parse({"range_sigma": 0.1})
    with pytest.raises(InputError, match="shape"):
        apply_nuisance(np.zeros((4, 2)), NuisanceSpec(), np.random.default_rng(0))
    with pytest.raises(InputError, match="non-finite"):
        apply_nuisance(np.full((4, 3), np.nan), NuisanceSpec(), np.random.default_rng(0))


def test_labels_and_keys():
    a = NuisanceSpec(range_sigma_m=0.02)
    assert a.label == "range_sigma_m=0.02" and a.active() == {"range_sigma_m": 0.02}
    assert a.key == NuisanceSpec.parse({"range_sigma_m": 0.02}).key != "clean"
    assert NuisanceSpec(range_sigma_m=0.03).key != a.key
