"""Point budget (issue 13): reduction of dense scans, unchanged results below the budget,
the peers' dense settings and the dense sensor presets."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError
from relnav.features.keypoints import voxel_downsample
from relnav.geometry import transform_points
from relnav.geometry.se3 import exp_se3
from relnav.odometry import Odometry, run_sequence
from relnav.odometry.budget import (
    DEFAULT_BUDGET_TARGET,
    DEFAULT_POINT_BUDGET,
    LOW_FRACTION,
    reduce_to_budget,
)
from relnav.odometry.runner import DIAGNOSTIC_COLUMNS, diagnostic_row


def _surface(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` fresh surface samples of a procedural satellite (~10 m) 20 m in front of the
    sensor (an asymmetric scene that fixes all six degrees of freedom)."""
    import trimesh

    from relnav.sim.targets import procedural_target

    mesh = procedural_target("envisat").mesh
    P, _ = trimesh.sample.sample_surface(mesh, n, seed=int(rng.integers(2**31)))
    return np.asarray(P, dtype=np.float64) * 0.4 + [20.0, 0.0, 0.0]


def _frames(rng: np.random.Generator, n: int, k: int) -> tuple[list[np.ndarray], list]:
    """``k`` scans of one surface seen after small known motions (fresh samples per frame)."""
    steps = [np.eye(4)] + [
        exp_se3(np.r_[rng.uniform(-0.05, 0.05, 3), rng.uniform(-0.002, 0.002, 3)])
        for _ in range(k - 1)
    ]
    poses = [np.eye(4)]
    for s in steps[1:]:
        poses.append(poses[-1] @ s)
    scans = []
    for T in poses:  # the scene is fixed in the world; the scan is in the sensor frame
        scans.append(transform_points(np.linalg.inv(T), _surface(rng, n)))
    return scans, poses


# --------------------------------------------------------------------------- reduce_to_budget


def test_at_or_below_budget_the_same_array_is_returned(rng):
    P = _surface(rng, 500)
    for budget in (500, 501, None):
        out, red = reduce_to_budget(P, budget, target=200)
        assert out is P and not red.reduced and red.n_out == 500


def test_random_reduction_is_seeded_and_keeps_scan_points_in_order(rng):
    P = _surface(rng, 20_000)
    a, ra = reduce_to_budget(P, 5000, target=3000, seed=[0, 1])
    b, _ = reduce_to_budget(P, 5000, target=3000, seed=[0, 1])
    c, _ = reduce_to_budget(P, 5000, target=3000, seed=[0, 2])
    assert a.shape == (3000, 3) and ra.reduced and ra.sampler == "random"
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    where = {row.tobytes(): i for i, row in enumerate(P)}
    idx = np.array([where[row.tobytes()] for row in a])  # KeyError if not a scan point
    assert np.all(np.diff(idx) > 0)  # distinct, in scan order


@pytest.mark.parametrize("n", [6000, 60_000])
def test_voxel_reduction_stays_within_target_and_matches_voxel_downsample(rng, n):
    P = _surface(rng, n) - [25.0, 3.0, 1.0]  # negative coordinates too
    out, red = reduce_to_budget(P, 5000, target=2000, sampler="voxel")
    assert red.sampler == "voxel" and red.voxel > 0
    assert LOW_FRACTION * 2000 <= out.shape[0] <= 2000
    ref = voxel_downsample(P, red.voxel)  # same cells, ordered differently
    key = np.lexsort(out.T[::-1])
    np.testing.assert_allclose(out[key], ref[np.lexsort(ref.T[::-1])], atol=1e-12)


def test_voxel_groups_agree_with_row_wise_unique(rng):
    P = rng.uniform(-7.0, 5.0, (3000, 3))
    v = 0.8
    got = voxel_downsample(P, v)
    keys = np.floor(P / v).astype(np.int64)
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    want = np.stack([np.bincount(inv, weights=P[:, a]) for a in range(3)], 1)
    want /= np.bincount(inv)[:, None]
    np.testing.assert_array_equal(got, want)


def test_non_finite_rows_are_dropped_when_reducing(rng):
    P = _surface(rng, 8000)
    P[::7] = np.nan
    out, red = reduce_to_budget(P, 5000, target=3000)
    assert np.isfinite(out).all() and red.n_out == 3000 and red.n_in == 8000


def test_bad_budget_options_are_config_errors():
    with pytest.raises(ConfigError, match="point_budget"):
        Odometry("icp-point", point_budget=10)
    with pytest.raises(ConfigError, match="point_budget"):
        Odometry("icp-point", point_budget="lots")
    with pytest.raises(ConfigError, match="budget_sampler"):
        Odometry("icp-point", budget_sampler="grid")
    with pytest.raises(ConfigError, match="budget_target"):
        Odometry("icp-point", budget_target=2.5)


# --------------------------------------------------------------------------- odometry


def test_native_methods_get_the_budget_and_peers_do_not():
    assert Odometry("icp-point").point_budget == DEFAULT_POINT_BUDGET
    assert Odometry("feature:hods+gcc+svd").budget_target == DEFAULT_BUDGET_TARGET
    assert Odometry("icp-point", point_budget=None).point_budget is None
    assert Odometry("icp-point", point_budget="None").point_budget is None  # -O on the CLI
    pytest.importorskip("kiss_icp")
    assert Odometry("kiss-icp").point_budget is None


@pytest.mark.parametrize("method", ["feature:hods+gcc+svd", "icp-point"])
def test_below_the_budget_results_are_bit_for_bit_unchanged(rng, method):
    scans, _ = _frames(rng, 900, 4)
    with_budget = run_sequence(scans, method, initial_pose=np.eye(4), point_budget=1000)
    literal = run_sequence(scans, method, initial_pose=np.eye(4), point_budget=None)
    assert np.array_equal(with_budget.poses, literal.poses)
    for a, b in zip(with_budget.steps, literal.steps, strict=True):
        assert a.n_used == a.n_points == 900 and a.budget_voxel == 0.0
        if a.result is not None:
            assert "point_budget" not in a.result.info
            assert np.array_equal(a.result.T_target_source, b.result.T_target_source)


def test_dense_scans_are_reduced_and_recorded(rng):
    scans, poses = _frames(rng, 30_000, 3)
    run = run_sequence(scans, "icp-plane", initial_pose=np.eye(4), budget_seed=7)
    for k, s in enumerate(run.steps):
        assert s.n_points == 30_000 and s.n_used == DEFAULT_BUDGET_TARGET
        if k:
            info = s.result.info["point_budget"]
            assert info["n_in"] == 30_000 and info["n_out"] == DEFAULT_BUDGET_TARGET
            assert info["sampler"] == "random" and info["seed"] == [7, k]
            assert "budget" in s.result.timings
    row = diagnostic_row(1, 0.1, run.steps[1])
    assert list(row) == list(DIAGNOSTIC_COLUMNS)
    assert row["n_points"] == 30_000 and row["n_used"] == DEFAULT_BUDGET_TARGET
    # the reduced clouds still register: step errors below the 3000-point spacing (~0.14 m)
    for k in range(1, 3):
        err = np.linalg.inv(np.linalg.inv(poses[k - 1]) @ poses[k]) @ run.steps[k].step
        assert run.steps[k].status == "ok" and np.linalg.norm(err[:3, 3]) < 0.1


def test_a_300k_point_scan_goes_through_the_feature_pipeline(rng):
    scans, _ = _frames(rng, 300_000, 2)
    odo = Odometry("feature:hods+gcc+svd")
    odo.register_frame(scans[0])
    s = odo.register_frame(scans[1])
    assert s.n_points == 300_000 and s.n_used == DEFAULT_BUDGET_TARGET
    assert s.result is not None and s.result.n_correspondences <= DEFAULT_BUDGET_TARGET


# --------------------------------------------------------------------------- peers, presets


def test_kiss_icp_uses_its_own_voxel_rule_on_dense_scans(rng):
    ext = pytest.importorskip("relnav.registration.external")
    pytest.importorskip("kiss_icp")
    scans, _ = _frames(rng, 25_000, 2)
    dense = ext.KissICPRegistration().register(scans[1], scans[0])
    assert dense.info["settings"] == "dense"
    assert dense.info["voxel_size"] == pytest.approx(dense.info["max_range"] / 100.0)
    sparse = ext.KissICPRegistration().register(scans[1][::20], scans[0][::20])
    assert sparse.info["settings"] == "sparse"
    assert sparse.info["voxel_size"] < dense.info["voxel_size"] / 2
    off = ext.KissICPRegistration(dense_points=None).register(scans[1], scans[0])
    assert off.info["settings"] == "sparse"


def test_small_gicp_downsamples_dense_scans_by_range(rng):
    ext = pytest.importorskip("relnav.registration.external")
    pytest.importorskip("small_gicp")
    scans, _ = _frames(rng, 25_000, 2)
    r = ext.SmallGICPRegistration().register(scans[1], scans[0])
    reach = max(np.linalg.norm(s, axis=1).max() for s in scans)
    assert r.info["settings"] == "dense"
    assert r.info["downsampling_resolution"] == pytest.approx(reach / 400.0)
    assert r.info["n_down_source"] < 25_000
    with pytest.raises(ConfigError, match="dense_points"):
        ext.SmallGICPRegistration(dense_points=0)


def test_dense_presets():
    from relnav.sim.presets import available_presets, get_preset
    from relnav.sim.sensors import make_sensor

    assert {"dense-flash", "dense-kinect", "dense-hdl64"} <= set(available_presets())
    s = make_sensor("flash256")
    assert (s.rows, s.cols) == (256, 256)
    sc = get_preset("dense-flash", resolution="64", frames=3)
    assert sc.sensors[0].overrides == {"rows": 64, "cols": 64}
    for bad in (4, 100.5, "x"):
        with pytest.raises(ConfigError, match="resolution"):
            get_preset("dense-flash", resolution=bad)
