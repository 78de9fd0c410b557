"""Keypoint selectors (all, voxel, FPS, ISS, random) and voxel downsampling."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from relnav.errors import ConfigError, InputError
from relnav.features.keypoints import (
    farthest_point_sampling,
    iss_keypoints,
    select_keypoints,
    voxel_downsample,
)
from relnav.geometry import mean_resolution

log = logging.getLogger(__name__)


def cube_surface(n: int = 1500, seed: int = 1) -> np.ndarray:
    """Points sampled (seeded) on the surface of a unit cube centred at the origin."""
    P, _ = trimesh.sample.sample_surface(trimesh.creation.box(extents=[1, 1, 1]), n, seed=seed)
    return np.asarray(P, dtype=np.float64)


def dist_to_cube_edges(P: np.ndarray) -> np.ndarray:
    """Distance of points on the unit cube's surface to the nearest edge."""
    gaps = np.sort(0.5 - np.abs(P), axis=1)  # distances to the three nearest face planes
    return gaps[:, 1]


@pytest.fixture(scope="module")
def blob() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.normal(size=(800, 3)) * [1.0, 0.5, 0.2] + [3.0, 0.0, 0.0]


def test_all(blob) -> None:
    idx = select_keypoints(blob)
    assert idx.dtype == np.int64
    np.testing.assert_array_equal(idx, np.arange(len(blob)))


def test_voxel_one_point_per_voxel_nearest_centroid(blob) -> None:
    v = 0.4
    idx = select_keypoints(blob, "voxel", voxel_size=v)
    keys = np.floor(blob / v).astype(np.int64)
    occupied = {tuple(k) for k in keys}
    chosen = [tuple(k) for k in keys[idx]]
    assert len(set(chosen)) == len(chosen) == len(occupied)  # ≤ 1 per voxel, every voxel once
    assert np.all(np.diff(idx) > 0)
    for i in idx[:50]:  # oracle: brute force nearest point to the voxel centroid
        members = np.flatnonzero((keys == keys[i]).all(axis=1))
        c = blob[members].mean(axis=0)
        assert i == members[np.argmin(np.linalg.norm(blob[members] - c, axis=1))]


def test_voxel_downsample_centroids(blob) -> None:
    v = 0.5
    C = voxel_downsample(blob, v)
    keys = np.floor(blob / v).astype(np.int64)
    uk = np.unique(keys, axis=0)
    assert C.shape == (len(uk), 3)
    for j in range(0, len(uk), 7):
        np.testing.assert_allclose(C[j], blob[(keys == uk[j]).all(axis=1)].mean(0), atol=1e-12)
    # a cloud already at one point per voxel is unchanged (up to order)
    G = (np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) * v
    np.testing.assert_allclose(np.sort(voxel_downsample(G, v), axis=0), np.sort(G, axis=0))


def test_fps_distinct_deterministic_and_covers_better_than_random(blob) -> None:
    n = 60
    f = select_keypoints(blob, "fps", n=n, seed=3)
    assert f.shape == (n,) and len(np.unique(f)) == n
    np.testing.assert_array_equal(f, farthest_point_sampling(blob, n, seed=3))
    assert f[0] != select_keypoints(blob, "fps", n=n, seed=4)[0]

    def covering_radius(idx: np.ndarray) -> float:
        return float(cKDTree(blob[idx]).query(blob)[0].max())

    r_fps = covering_radius(f)
    r_rand = [covering_radius(select_keypoints(blob, "random", n=n, seed=s)) for s in range(5)]
    log.info("covering radius: fps %.3f, random %s", r_fps, np.round(r_rand, 3))
    assert r_fps < min(r_rand)
    # greedy property: each new point is the farthest from those already chosen
    for s in (1, 10, 40):
        d = cKDTree(blob[f[:s]]).query(blob)[0]
        assert np.linalg.norm(blob[f[s]] - blob[f[:s]], axis=1).min() == pytest.approx(d.max())


def test_fps_on_duplicates_and_oversized_n() -> None:
    P = np.repeat(np.array([[0.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]]), 4, axis=0)
    idx = farthest_point_sampling(P, 12, seed=0)
    assert len(np.unique(idx)) == 12
    assert len(np.unique(P[idx[:3]], axis=0)) == 3  # the three distinct sites come first
    assert farthest_point_sampling(P, 50).shape == (12,)


def test_random_distinct_sorted_seeded(blob) -> None:
    a = select_keypoints(blob, "random", n=100, seed=7)
    assert len(np.unique(a)) == 100 and np.all(np.diff(a) > 0)
    np.testing.assert_array_equal(a, select_keypoints(blob, "random", n=100, seed=7))
    assert not np.array_equal(a, select_keypoints(blob, "random", n=100, seed=8))


def test_iss_cube_keypoints_lie_on_edges() -> None:
    P = cube_surface()
    tr = mean_resolution(P)
    idx = select_keypoints(P, "iss")
    assert idx.size >= 8
    d = dist_to_cube_edges(P[idx]) / tr
    log.info(
        "ISS on cube: %d keypoints, edge distance / Tr: median %.2f max %.2f",
        idx.size,
        np.median(d),
        d.max(),
    )
    # flat faces have no saliency, so every keypoint sees an edge within the salient radius
    assert d.max() <= 6.0
    assert np.median(d) <= 2.0
    # and the keypoints are spread over the cube, not clumped
    assert len({tuple(np.sign(p).astype(int)) for p in P[idx]}) >= 6


def test_iss_matches_open3d() -> None:
    o3d = pytest.importorskip("open3d")
    P = cube_surface(seed=2)
    tr = mean_resolution(P)
    P = P + np.random.default_rng(3).normal(0.0, 0.05 * tr, P.shape)  # break exact planarity
    sr, nr = 6 * tr, 4 * tr
    ours = iss_keypoints(P, salient_radius=sr, non_max_radius=nr)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    theirs = np.asarray(
        o3d.geometry.keypoint.compute_iss_keypoints(pc, salient_radius=sr, non_max_radius=nr).points
    )
    dist, ti = cKDTree(P).query(theirs)
    assert dist.max() == 0.0
    a, b = set(ours.tolist()), set(ti.tolist())
    jaccard = len(a & b) / max(len(a | b), 1)
    log.info(
        "ISS vs Open3D: ours %d, open3d %d, common %d, jaccard %.3f",
        len(a),
        len(b),
        len(a & b),
        jaccard,
    )
    assert jaccard >= 0.9


def test_iss_planar_patch_has_no_keypoints_and_bad_params() -> None:
    g = np.linspace(0, 1, 25)
    P = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    P = np.c_[P, np.zeros(len(P))] @ np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    assert iss_keypoints(P).size == 0
    with pytest.raises(ConfigError):
        iss_keypoints(P, salient_radius=-1.0, non_max_radius=1.0)
    assert iss_keypoints(np.zeros((0, 3))).size == 0
    assert iss_keypoints(np.zeros((1, 3))).size == 0


def test_bad_input() -> None:
    P = np.random.default_rng(0).normal(size=(20, 3))
    with pytest.raises(ConfigError):
        select_keypoints(P, "harris")
    with pytest.raises(ConfigError):
        select_keypoints(P, "voxel")
    with pytest.raises(ConfigError):
        select_keypoints(P, "voxel", voxel_size=0.0)
    with pytest.raises(ConfigError):
        select_keypoints(P, "fps")
    with pytest.raises(ConfigError):
        select_keypoints(P, "random", n=-1)
    with pytest.raises(ConfigError):
        select_keypoints(P, "fps", n=3, gamma_21=0.9)
    with pytest.raises(InputError):
        select_keypoints(np.full((3, 3), np.nan), "all")
    with pytest.raises(InputError):
        select_keypoints(P[:, :2], "all")
    for m, kw in (
        ("all", {}),
        ("voxel", {"voxel_size": 1.0}),
        ("fps", {"n": 5}),
        ("random", {"n": 5}),
        ("iss", {}),
    ):
        assert select_keypoints(np.zeros((0, 3)), m, **kw).shape == (0,)
