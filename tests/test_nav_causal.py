"""The navigator's causal output: the pose it had at each frame's time, beside the smoothed one,
and the simulator's attitude jitter that makes the motion non-smooth."""

from __future__ import annotations

import numpy as np
import pytest

from nav_scenarios import flash_orbit
from relnav.errors import InputError
from relnav.io.sequences import ScanSequence
from relnav.io.trajectories import read_tum
from relnav.odometry import run_sequence
from relnav.sim.scenario import Scenario, scenario_poses, simulate
from relnav.sim.trajectories import pointing_poses


@pytest.fixture(scope="module")
def short_orbit(tmp_path_factory):
    out = tmp_path_factory.mktemp("causal") / "seq"
    simulate(flash_orbit("causal", max_frames=14), out)
    return ScanSequence(out)


def test_causal_poses_are_the_online_steps_and_are_written_beside_the_smoothed(
    short_orbit, tmp_path
):
    run = run_sequence(short_orbit, "relnav", out=tmp_path / "run")
    online = np.stack([s.pose for s in run.steps])
    np.testing.assert_array_equal(run.causal_poses, online)
    np.testing.assert_array_equal(run.online_poses, online)
    # the smoother moved at least one pose: the two trajectories are different files
    assert not np.array_equal(run.poses, run.causal_poses)
    t_s, smoothed = read_tum(run.paths["estimate"])
    t_c, causal = read_tum(run.paths["estimate_causal"])
    np.testing.assert_array_equal(t_s, t_c)
    np.testing.assert_allclose(causal, online, atol=1e-9)
    np.testing.assert_allclose(smoothed, run.poses, atol=1e-9)


def test_a_prefix_of_the_causal_trajectory_does_not_depend_on_later_frames(short_orbit):
    """Causal: the poses of frames 0..k are the same whether the run stops at k or goes on
    (the smoothed trajectory is not: it looks ahead)."""
    long = run_sequence(short_orbit, "relnav", max_frames=14)
    short = run_sequence(short_orbit, "relnav", max_frames=10)
    np.testing.assert_array_equal(long.causal_poses[:10], short.causal_poses)


def test_pairwise_methods_have_no_separate_causal_trajectory(short_orbit):
    run = run_sequence(short_orbit, "icp-point", max_frames=4)
    assert run.causal_poses is None
    np.testing.assert_array_equal(run.online_poses, run.poses)


def _angles_deg(T):
    from relnav.geometry.rotations import rotation_angle

    return np.array([np.degrees(rotation_angle(R)) for R in T[:, :3, :3]])


def test_white_and_random_walk_attitude_jitter_per_axis():
    p = np.column_stack([np.linspace(-60, -40, 2000), np.zeros(2000), np.full(2000, 5.0)])
    base = pointing_poses(p)
    white = pointing_poses(p, jitter_deg=(0.0, 0.0, 2.0), seed=3)
    d = np.einsum("nji,njk->nik", base[:, :3, :3], white[:, :3, :3])  # R_look⁻¹ R
    rv = np.stack([d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0], d[:, 1, 0] - d[:, 0, 1]], 1)
    rv = np.degrees(rv / 2)
    assert np.allclose(rv[:, :2], 0.0, atol=1e-9)  # only the sensor's z axis jitters
    assert 1.9 < np.std(rv[:, 2]) < 2.1
    walk = pointing_poses(p, jitter_deg=0.5, jitter_kind="random-walk", seed=3)
    dw = np.einsum("nji,njk->nik", base[:, :3, :3], walk[:, :3, :3])
    a = _angles_deg(np.pad(dw, ((0, 0), (0, 1), (0, 1))))
    # a random walk wanders (its late attitude error far above one step's), white jitter not
    assert np.median(a[-200:]) > 5 * 0.5 * np.sqrt(3)
    aw = _angles_deg(np.pad(d, ((0, 0), (0, 1), (0, 1))))
    assert np.median(aw[-200:]) < 4.0
    with pytest.raises(InputError):
        pointing_poses(p, jitter_deg=(1.0, -1.0, 0.0))
    with pytest.raises(InputError):
        pointing_poses(p, jitter_deg=1.0, jitter_kind="pink")


def test_scenario_jitter_is_in_the_ground_truth_and_seeded():
    sc = Scenario.model_validate(
        {**flash_orbit("j", frames=20), "pointing": {"jitter_deg": [1.0, 0.5, 0.25]}}
    )
    _, T1, _ = scenario_poses(sc)
    _, T2, _ = scenario_poses(sc)
    np.testing.assert_array_equal(T1, T2)
    calm = Scenario.model_validate(flash_orbit("j", frames=20))
    _, T0, _ = scenario_poses(calm)
    assert np.allclose(T1[:, :3, 3], T0[:, :3, 3])
    assert not np.allclose(T1[:, :3, :3], T0[:, :3, :3])
