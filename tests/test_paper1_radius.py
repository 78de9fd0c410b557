"""Paper 1's radius rule: one support radius, from the new scan's resolution, for both scans."""

from __future__ import annotations

import numpy as np
import pytest

import relnav.matching.nn as nn_module
from relnav.odometry import Odometry
from relnav.odometry.presets import METHOD_PRESETS
from relnav.pipeline import resolve_method


def _scans() -> tuple[np.ndarray, np.ndarray, int]:
    """Two consecutive scans (same sensor pose) sharing a surface patch whose neighbourhood is
    identical in both; the second scan also sees a denser patch far away, so its mean
    resolution ``Tr`` (and the radius ``80·Tr``) differs. Returns the scans and the index, in
    both, of a model point at the centre of the shared patch."""
    rng = np.random.default_rng(3)
    g = np.arange(-10, 11) * 0.05
    x, y = np.meshgrid(g, g)
    patch = np.c_[x.ravel(), y.ravel(), 0.1 * np.sin(3 * x.ravel()) * np.cos(2 * y.ravel())]
    patch += rng.normal(scale=0.002, size=patch.shape)
    centre = int(np.argmin(np.linalg.norm(patch[:, :2], axis=1)))
    far = rng.uniform(-0.2, 0.2, size=(300, 3)) + np.array([500.0, 0.0, 0.0])
    return patch, np.vstack([patch, far]), centre


def _matched_descriptors(monkeypatch, **options) -> tuple[np.ndarray, np.ndarray]:
    """The descriptors the pair's NN matching receives (source = 2nd scan, target = 1st)."""
    seen: list[tuple[np.ndarray, np.ndarray]] = []
    real = nn_module.match_descriptors

    def spy(src, tgt, **kw):
        seen.append((np.array(src), np.array(tgt)))
        return real(src, tgt, **kw)

    monkeypatch.setattr(nn_module, "match_descriptors", spy)
    first, second, _ = _scans()
    odo = Odometry("feature:hods+gcc+svd", step_check="off", **options)
    odo.register_frame(first)
    odo.register_frame(second)
    assert len(seen) == 1
    return seen[0]


def test_consecutive_hods_descriptors_of_one_point_use_one_radius(monkeypatch):
    _, _, centre = _scans()
    src, tgt = _matched_descriptors(monkeypatch)  # the default: paper 1's rule
    assert np.isfinite(src[centre]).all()
    # the same model point, the same neighbourhood, one radius: the same descriptor
    np.testing.assert_allclose(src[centre], tgt[centre], atol=1e-6)
    # relnav's per-scan radius describes the same point differently (the rule matters here)
    src_own, tgt_own = _matched_descriptors(monkeypatch, radius_from="own")
    assert np.abs(src_own[centre] - tgt_own[centre]).max() > 1e-3


@pytest.mark.parametrize("name", ["paper1", "paper1-svd"])
def test_paper_presets_use_the_papers_radius_rule(name):
    method, options, _ = resolve_method(name)
    assert options.get("radius_from", "source") == "source"
    odo = Odometry(method, **options)
    assert odo.registration.radius_from == "source"
    assert odo.registration.match_from == "target"
    assert odo.motion_prior == "identity"  # §3.3.7: no usable cluster -> the initialisation


def test_extended_and_competitor_presets():
    assert METHOD_PRESETS["extended"].options["radius_from"] == "own"
    method, options, _ = resolve_method("paper1-icp-point")
    odo = Odometry(method, **options)
    assert odo.registration.thresholds == "paper"
    assert odo.motion_prior == "identity"


@pytest.mark.parametrize(("match_from", "bound"), [("target", 30), ("source", 50)])
def test_matching_direction(match_from, bound):
    """Paper 1 eq. 5 matches every feature of P_k (target) to its nearest in P_{k+1}: at most
    one correspondence per target point; ``match_from="source"`` the other way round."""
    from relnav.registration.feature import FeatureRegistration

    rng = np.random.default_rng(1)
    target = rng.normal(size=(30, 3))
    source = np.vstack([target, rng.normal(size=(20, 3))])
    reg = FeatureRegistration("hods", "none", "svd", tau=np.inf, match_from=match_from)
    res = reg.register(source, target)
    assert res.n_correspondences == bound
