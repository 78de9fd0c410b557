"""Dense mode of the odometry (issue 13): feature pipelines on budget-reduced scans describe a
keypoint subset and are refined by point-to-plane ICP (the step check's referee); scans within
the budget are untouched."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError
from relnav.geometry import transform_points
from relnav.geometry.rotations import rotation_angle
from relnav.geometry.se3 import exp_se3
from relnav.odometry import Odometry, run_sequence
from relnav.odometry.budget import DEFAULT_BUDGET_TARGET
from relnav.odometry.odometry import DEFAULT_DENSE_KEYPOINTS
from relnav.registration.feature import FeatureRegistration
from relnav.registration.result import RegistrationResult


def _surface(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` fresh surface samples of a procedural satellite (~10 m) 20 m in front of the
    sensor (asymmetric: all six degrees of freedom fixed)."""
    import trimesh

    from relnav.sim.targets import procedural_target

    mesh = procedural_target("envisat").mesh
    P, _ = trimesh.sample.sample_surface(mesh, n, seed=int(rng.integers(2**31)))
    return np.asarray(P, dtype=np.float64) * 0.4 + [20.0, 0.0, 0.0]


def _frames(rng: np.random.Generator, n: int, k: int) -> tuple[list[np.ndarray], list]:
    """``k`` scans of one fixed scene after small known motions (fresh samples per frame)."""
    poses = [np.eye(4)]
    for _ in range(k - 1):
        step = exp_se3(np.r_[rng.uniform(-0.05, 0.05, 3), rng.uniform(-0.01, 0.01, 3)])
        poses.append(poses[-1] @ step)
    scans = [transform_points(np.linalg.inv(T), _surface(rng, n)) for T in poses]
    return scans, poses


def _step_error(poses: list, k: int, step: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation (deg) error of the step ``k-1 → k``."""
    err = np.linalg.inv(np.linalg.inv(poses[k - 1]) @ poses[k]) @ step
    return float(np.linalg.norm(err[:3, 3])), float(np.degrees(rotation_angle(err[:3, :3])))


@pytest.mark.parametrize("method", ["feature:hods+gcc+svd", "feature:hods+gcc+alphabeta"])
def test_scans_within_the_budget_are_bit_for_bit_untouched(rng, method):
    scans, _ = _frames(rng, 900, 4)
    auto = run_sequence(scans, method, initial_pose=np.eye(4), point_budget=1000)
    off = run_sequence(scans, method, initial_pose=np.eye(4), point_budget=1000, dense_refine="off")
    assert np.array_equal(auto.poses, off.poses)
    for a, b in zip(auto.steps, off.steps, strict=True):
        assert a.status == b.status
        if a.result is not None:
            assert np.array_equal(a.result.T_target_source, b.result.T_target_source)
            for key in ("refine_status", "dense_refine", "dense_keypoints"):
                assert key not in a.result.info
            assert "refine" not in a.result.timings
            assert not a.result.info["step_check"].get("referee_shared", False)


def test_dense_scans_are_described_at_a_subset_and_refined(rng):
    scans, poses = _frames(rng, 8000, 3)
    run = run_sequence(scans, "feature:hods+gcc+svd", initial_pose=np.eye(4))
    starts = []
    for k in (1, 2):
        s = run.steps[k]
        info = s.result.info
        assert s.n_used == DEFAULT_BUDGET_TARGET
        assert info["dense_keypoints"] == DEFAULT_DENSE_KEYPOINTS
        assert info["refine_status"] == "ok" and "refine" in s.result.timings
        rec = info["dense_refine"]
        assert rec["method"] == "icp-plane" and rec["status"] == "ok"
        starts.append(rec["start"])
        # the step check judged the coarse step with the refinement's ICP (not run twice)
        check = info["step_check"]
        assert check["referee_shared"] and check["referee_t"] == pytest.approx(rec["t"])
        doubtful = rec["rot_deg"] > 5.0 or rec["t"] > 0.5  # the default step tolerance
        assert s.status == ("flagged" if doubtful else "ok")
        assert check["flagged"] == doubtful
        if not doubtful:
            assert rec["start"] == "coarse"
        # the refined step replaced the coarse one, and is accurate
        assert not np.array_equal(s.step, rec["T_coarse"])
        t_err, r_err = _step_error(poses, k, s.step)
        assert t_err < 0.05 and r_err < 0.5
    assert "coarse" in starts


def test_dense_mode_options():
    assert Odometry("feature:hods+gcc+alphabeta").dense_refine
    assert not Odometry("feature:hods+gcc+alphabeta", refine="icp-plane").dense_refine
    assert not Odometry("icp-point").dense_refine
    assert Odometry("icp-point", dense_refine="on").dense_refine
    assert Odometry("feature:hods", dense_keypoints=None).dense_keypoints is None
    with pytest.raises(ConfigError, match="dense_refine"):
        Odometry("feature:hods", dense_refine="maybe")
    with pytest.raises(ConfigError, match="dense_keypoints"):
        Odometry("feature:hods", dense_keypoints=10)


def test_feature_prepare_with_given_keypoints_skips_non_finite_points(rng):
    P = _surface(rng, 400)
    P[5] = np.nan
    reg = FeatureRegistration("hods", "gcc", "svd")
    cf = reg.prepare(P, keypoints=np.array([3, 5, 7, 399]))
    # point 5 is dropped; 7 and 399 move down by one in the finite cloud
    assert np.array_equal(cf.keypoints, [3, 6, 398])
    assert cf.descriptors.shape == (3, reg.descriptor_spec.dim)
    np.testing.assert_array_equal(cf.points[cf.keypoints], P[[3, 7, 399]])
    with pytest.raises(ConfigError, match="keypoints"):
        reg.prepare(P, keypoints=np.array([400]))


class _WrongOnce:
    """A registration whose second step is off by 60° (status ``ok``): a bad coarse step."""

    name = "wrong-once"

    def __init__(self, truth: list[np.ndarray]) -> None:
        self.truth = truth
        self.calls = 0

    def register(
        self, source: np.ndarray, target: np.ndarray, *, init: np.ndarray | None = None
    ) -> RegistrationResult:
        self.calls += 1
        T = self.truth[self.calls].copy()
        if self.calls == 2:
            T = exp_se3(np.r_[0.0, 0.0, 0.0, 0.0, 0.0, np.radians(60.0)]) @ T
        return RegistrationResult(T_target_source=T, status="ok")


@pytest.mark.parametrize("step_check", ["referee", "off"])
def test_a_bad_coarse_step_on_dense_scans_is_flagged_not_made_ok(rng, step_check):
    scans, poses = _frames(rng, 8000, 3)
    truth = [np.eye(4)] + [np.linalg.inv(poses[k - 1]) @ poses[k] for k in (1, 2)]
    odo = Odometry(_WrongOnce(truth), dense_refine="on", step_check=step_check, point_budget=5000)
    steps = [odo.register_frame(s) for s in scans]
    assert steps[1].status == "ok" and steps[1].result.info["dense_refine"]["start"] == "coarse"
    bad = steps[2]
    assert bad.status == "flagged" and "not trusted" in bad.result.message
    rec = bad.result.info["dense_refine"]
    assert rec["status"] != "ok" or rec["rot_deg"] > 5.0  # the ICP moved the coarse step
    # the second start at the motion prior found the true step (kept, but flagged)
    assert rec["start"] == "prior" and rec["prior_fitness"] > rec.get("fitness", 0.0)
    t_err, r_err = _step_error(poses, 2, bad.step)
    assert t_err < 0.05 and r_err < 0.5
