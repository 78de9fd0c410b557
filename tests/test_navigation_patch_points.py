"""Where a plane patch's residuals are measured from: the voxel mean or the fitted plane.

``map.patch_point="plane"`` (the default) moves each voxel mean along its patch's normal toward
the plane through its neighbours' centroid
(:attr:`relnav.navigation.voxel_map.VoxelMap.patch_points`); the registration then measures a
scan point's offset from there (``solve_scan_to_map``), except the point-to-point refinement on
repeated points, which keeps the means.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from relnav.navigation import Navigator, VoxelMap
from relnav.navigation.gicp import left_information, solve_scan_to_map


def _noisy_plane(rng: np.random.Generator, n: int = 4000, noise: float = 0.05) -> np.ndarray:
    """Points of the plane z = 0 over 4 m × 4 m, with ``noise`` (m) along z."""
    P = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), np.zeros(n)])
    P[:, 2] += rng.normal(0.0, noise, n)
    return P


def _map(points: np.ndarray, patch_point: str, reach: float = np.inf) -> VoxelMap:
    m = VoxelMap(
        0.1, noise_floor=0.01, k_neighbors=10, patch_point=patch_point, patch_point_reach=reach
    )
    m.insert(points, 0)
    return m


def test_plane_patch_points_move_toward_the_fitted_plane_by_the_weighted_share() -> None:
    """Each mean moves along its normal by ``d / (1 + w)`` toward the plane through its 10
    nearest map points' centroid (``d``: its distance from that plane, ``w``: its observations),
    and the points end closer to the true surface than the noisy means."""
    P = _noisy_plane(np.random.default_rng(3))
    mean_map, plane_map = _map(P, "mean"), _map(P, "plane")
    np.testing.assert_array_equal(mean_map.patch_points, mean_map.means)
    M, Q, n = plane_map.means, plane_map.patch_points, plane_map.normals
    np.testing.assert_allclose(M, mean_map.means)
    shift = Q - M
    np.testing.assert_allclose(np.cross(shift, n), 0.0, atol=1e-12)  # along the normal only
    _, nb = cKDTree(M).query(M, k=10)
    d = np.einsum("ij,ij->i", n, M - M[nb].mean(axis=1))
    w = np.maximum(plane_map.weights, 1.0)
    np.testing.assert_allclose(np.einsum("ij,ij->i", shift, n), -d / (1.0 + w), atol=1e-9)
    rms_mean = float(np.sqrt(np.mean(M[:, 2] ** 2)))
    rms_plane = float(np.sqrt(np.mean(Q[:, 2] ** 2)))
    assert rms_plane < 0.85 * rms_mean


def test_a_neighbourhood_wider_than_the_reach_keeps_its_mean() -> None:
    """10 neighbours of a 0.1 m voxel map reach about 0.2 m: a reach of 0.05 m keeps every
    mean, 0.5 m moves every one."""
    P = _noisy_plane(np.random.default_rng(6))
    narrow, wide = _map(P, "plane", reach=0.05), _map(P, "plane", reach=0.5)
    np.testing.assert_array_equal(narrow.patch_points, narrow.means)
    assert np.all(np.abs(np.einsum("ij,ij->i", wide.patch_points - wide.means, wide.normals)) > 0)


def test_patch_points_follow_the_map_after_an_update_and_an_eviction() -> None:
    rng = np.random.default_rng(4)
    m = VoxelMap(0.1, noise_floor=0.01, patch_point="plane", max_voxels=1500)
    m.insert(_noisy_plane(rng, 2000), 0)
    assert m.patch_points.shape == (len(m), 3)
    m.insert(_noisy_plane(rng, 2000), 1)  # evicts down to 1500 voxels
    assert len(m) == 1500 and m.patch_points.shape == (1500, 3)
    np.testing.assert_allclose(np.cross(m.patch_points - m.means, m.normals), 0.0, atol=1e-12)


def test_unknown_patch_point_is_refused() -> None:
    with pytest.raises(ValueError, match="patch_point"):
        VoxelMap(0.1, patch_point="centroid")
    with pytest.raises(ValueError, match="patch_point_reach"):
        VoxelMap(0.1, patch_point_reach=-1.0)


@pytest.mark.parametrize("patch_point", ["mean", "plane"])
@pytest.mark.parametrize("from_means", [False, True])
def test_the_solver_measures_residuals_from_the_patch_points(
    patch_point: str, from_means: bool
) -> None:
    rng = np.random.default_rng(5)
    m = _map(_noisy_plane(rng), patch_point)
    scan = _noisy_plane(rng, 300)
    T = np.eye(4)
    fit = solve_scan_to_map(
        scan,
        m,
        T,
        T,
        left_information(T, np.eye(6) * 1e-6),  # held at the start by the prior
        0.5,
        3.0,
        1,
        1e-9,
        1e-9,
        from_means=from_means,
    )
    ok = fit.idx >= 0
    ref = m.means if from_means or patch_point == "mean" else m.patch_points
    X = scan @ fit.T[:3, :3].T + fit.T[:3, 3]
    e = X[ok] - ref[fit.idx[ok]]
    d2 = np.einsum("ni,nij,nj->n", e, m.information[fit.idx[ok]], e)
    np.testing.assert_allclose(fit.d2[ok], d2, rtol=1e-9, atol=1e-12)


def test_the_navigator_builds_its_map_with_the_option() -> None:
    assert Navigator().config.map.patch_point == "plane"  # the default since session 32
    nav = Navigator(**{"map.patch_point": "mean", "map.patch_point_reach": 2.0})
    nav.solver.spacing0 = 0.25  # the first scan's point spacing, m
    assert nav.solver.map_options()["patch_point"] == "mean"
    assert nav.solver.map_options()["patch_point_reach"] == 0.5
