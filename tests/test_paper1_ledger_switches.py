"""The deviation ledger's switches for choices paper 1 leaves open (docs/paper1-deviations.md,
rows 1, 4 and 7): each changes exactly the one thing it names."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from relnav.errors import ConfigError
from relnav.geometry.normals import estimate_normals
from relnav.matching.nn import match_descriptors
from relnav.registration.feature import FeatureRegistration


def _brute_force(A, B, tau, mutual):
    D = np.linalg.norm(A[:, None, :] - B[None, :, :], axis=2)
    j = np.argmin(D, axis=1)
    keep = D[np.arange(len(A)), j] < tau
    if mutual:
        keep &= np.argmin(D, axis=0)[j] == np.arange(len(A))
    i = np.flatnonzero(keep)
    return i, j[i]


@pytest.mark.parametrize("mutual", [False, True])
def test_raw_matching_is_the_nearest_neighbour_of_the_unscaled_descriptors(rng, mutual):
    """``normalize=False``: nearest neighbour and τ on the raw L2 distance (here with rows of
    very different norms, where unit scaling would pick other neighbours)."""
    A = rng.uniform(0, 1, (40, 8)) * rng.uniform(0.2, 5.0, (40, 1))
    B = rng.uniform(0, 1, (50, 8)) * rng.uniform(0.2, 5.0, (50, 1))
    A[3] = np.nan  # an invalid row is skipped
    for tau in (0.8, 1.5, np.inf):
        c = match_descriptors(A, B, tau=tau, mutual=mutual, normalize=False)
        ok = np.isfinite(A).all(axis=1)
        i, j = _brute_force(A[ok], B, tau, mutual)
        assert np.array_equal(c.src_idx, np.flatnonzero(ok)[i]) and np.array_equal(c.tgt_idx, j)
        assert np.allclose(c.distance, np.linalg.norm(A[c.src_idx] - B[c.tgt_idx], axis=1))
    unit = match_descriptors(A, B, tau=np.inf, normalize=True)
    raw = match_descriptors(A, B, tau=np.inf, normalize=False)
    assert not np.array_equal(unit.tgt_idx, raw.tgt_idx)


def test_median_resolution_sets_the_radius_and_the_gcc_tolerance_base(rng):
    P = np.r_[rng.normal(size=(150, 3)), rng.normal(size=(50, 3)) * 0.1]  # uneven spacing
    d = cKDTree(P).query(P, k=2)[0][:, 1]
    mean = FeatureRegistration("hods").prepare(P)
    med = FeatureRegistration("hods", resolution="median").prepare(P)
    assert mean.resolution == pytest.approx(np.mean(d))
    assert med.resolution == pytest.approx(np.median(d))
    assert med.radius == pytest.approx(80 * np.median(d))  # HoD-S: 80·Tr


def test_normal_k_estimates_the_normals_from_the_k_nearest_points(rng):
    P = rng.normal(size=(120, 3)) * [3.0, 3.0, 0.3]
    knn = FeatureRegistration("shot", normal_k=10).prepare(P)
    assert np.allclose(knn.normals, estimate_normals(P, k=10), equal_nan=True)
    by_radius = FeatureRegistration("shot").prepare(P)
    assert not np.allclose(by_radius.normals, knn.normals, equal_nan=True)


def test_bad_switches_are_config_errors():
    with pytest.raises(ConfigError):
        FeatureRegistration("hods", resolution="mode")
    with pytest.raises(ConfigError):
        FeatureRegistration("shot", normal_k=2)


def test_every_ledger_switch_of_the_grid_is_in_the_ledger_and_its_report():
    """A switch run by the full-length grid has a row in docs/paper1-deviations.md and a line
    in the report's ledger table."""
    import importlib.util
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    labels = re.findall(
        r'label: "(ledger:[a-z0-9-]+)"', (root / "configs/paper1-full-length.yaml").read_text()
    )
    assert len(labels) >= 15
    ledger = (root / "docs/paper1-deviations.md").read_text()
    spec = importlib.util.spec_from_file_location(
        "paper1_full_length_report", root / "benchmarks/paper1/paper1_full_length_report.py"
    )
    report = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(report)
    for label in labels:
        assert label in ledger, label
        assert label in report.LEDGER, label
