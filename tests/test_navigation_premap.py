"""Before the map: a far approach whose first scans have too few points to register
(``startup.premap_range``): the pose follows the target's range along the first line of sight
(its whole bearing with the chaser's attitude input), and the motion model starts at that rate."""

from __future__ import annotations

import numpy as np
import pytest

from nav_scenarios import flash, flash_orbit
from relnav.io.sequences import ScanSequence
from relnav.navigation.navigator import Navigator
from relnav.pipeline import run_sequence
from relnav.sim.scenario import simulate


@pytest.fixture(scope="module")
def approach(tmp_path_factory):
    """A V-bar approach from 110 m to 40 m (10 s frames) to a 10 m asteroid seen by a 24×24
    flash LIDAR: 4 points per scan over the first 17 frames, then 8–30."""
    out = tmp_path_factory.mktemp("approach") / "seq"
    simulate(
        {
            "name": "approach",
            "seed": 5,
            "frames": 40,
            "dt": 10.0,
            "format": "npy",
            "target": {"name": "asteroid", "scale_to": 10.0},
            "sensors": [flash(24)],
            "trajectory": {"kind": "vbar", "params": {"start": -110.0, "stop": -40.0}},
        },
        out,
    )
    return ScanSequence(out)


def _sparse_frames(seq: ScanSequence) -> int:
    n = np.array([len(seq[i].points) for i in range(len(seq))])
    return int(np.argmax(n >= 6))


def test_the_pose_follows_the_range_before_the_map(approach):
    first_map = _sparse_frames(approach)
    assert first_map >= 10  # the scenario has the sparse start it is about
    off = run_sequence(approach, "relnav", **{"startup.premap_range": False})
    on = run_sequence(approach, "relnav")  # on by default
    e_off = np.linalg.norm(off.online_poses[:, :3, 3] - approach.gt_poses[:, :3, 3], axis=1)
    e_on = np.linalg.norm(on.online_poses[:, :3, 3] - approach.gt_poses[:, :3, 3], axis=1)
    pre = slice(1, first_map)
    assert np.all(e_on[pre] < 1.0)  # 0.2-0.5 m measured: the range of 4 points' centroid
    assert np.all(e_off[pre][4:] > 5.0)  # the pose stays where it started: 1.75 m per frame
    # the steps before the map are still not registered: failed, with the range recorded
    steps = on.steps[1:first_map]
    assert all(s.status == "failed" for s in steps)
    assert all(s.result.info["premap_range_m"] > 40.0 for s in steps)


def test_the_motion_model_starts_at_the_range_rate(approach):
    """Once the map starts, the velocity along the line of sight is the ranges' rate, known to
    their fit (the registrations of 8-point scans then pull it less)."""
    first_map = _sparse_frames(approach)
    gt = approach.gt_poses
    v_true = (gt[first_map + 1][:3, 3] - gt[first_map][:3, 3]) / 10.0  # target frame, m/s
    u = v_true / np.linalg.norm(v_true)
    along, sd = {}, {}
    for premap in (False, True):
        nav = Navigator(initial_pose=gt[0], **{"startup.premap_range": premap})
        for i in range(first_map + 2):  # the map starts; the next frame sets the velocity
            nav.register_frame(approach[i])
        assert nav.motion is not None
        R = nav.pose[:3, :3]
        along[premap] = float(u @ R @ nav.motion.velocity[:3])
        sd[premap] = float(np.sqrt(u @ R @ nav.motion.P[6:9, 6:9] @ R.T @ u))
    assert abs(along[True] / np.linalg.norm(v_true) - 1.0) < 0.15  # 0.184 vs 0.179 m/s
    assert sd[True] < 0.5 * sd[False]  # 0.066 vs 0.26 m/s measured


def test_nothing_changes_when_the_first_scans_can_be_registered(tmp_path):
    simulate(flash_orbit("premap-off", max_frames=12), tmp_path / "seq")
    seq = ScanSequence(tmp_path / "seq")
    off = run_sequence(seq, "relnav", **{"startup.premap_range": False})
    on = run_sequence(seq, "relnav")
    np.testing.assert_array_equal(off.poses, on.poses)
    np.testing.assert_array_equal(off.online_poses, on.online_poses)


def test_with_the_attitude_input_the_whole_bearing_places_the_sensor(tmp_path):
    """On a helical approach the first frames turn about the target: a range cannot see that,
    the centroid's bearing under the measured attitude does."""
    from relnav.navigation.attitude_input import AttitudeInput

    out = tmp_path / "helix"
    simulate(
        {
            "name": "helix",
            "seed": 6,
            "frames": 40,
            "dt": 15.0,
            "format": "npy",
            "target": {"name": "asteroid", "scale_to": 10.0},
            "pointing": {"attitude_sigma_deg": 0.01},
            "sensors": [flash(24)],
            "trajectory": {
                "kind": "helical-approach",
                "params": {
                    "radius_start": 100.0,
                    "radius_end": 50.0,
                    "height_start": 10.0,
                    "height_end": 5.0,
                    "turns": 0.3,
                },
            },
        },
        out,
    )
    seq = ScanSequence(out)
    first_map = _sparse_frames(seq)
    assert first_map >= 10
    att = AttitudeInput.from_tum(out / "chaser_attitude.tum", 0.01)
    errors = {}
    for label, extra in (("range", {}), ("bearing", {"attitude": att})):
        run = run_sequence(seq, "relnav", **{"startup.premap_range": True, **extra})
        e = np.linalg.norm(run.online_poses[:, :3, 3] - seq.gt_poses[:, :3, 3], axis=1)
        errors[label] = e[1 : first_map + 1].max()
    assert errors["bearing"] < 5.0  # 3.4 m measured
    assert errors["range"] > 20.0  # 63 m: the turn about the target is not seen


def test_the_map_can_wait_for_denser_scans(approach):
    """``startup.map_min_points``: scans sparser than it are placed by their range, and the map
    starts at the first scan that has that many points."""
    n = np.array([len(approach[i].points) for i in range(len(approach))])
    start = int(np.argmax(n >= 12))
    assert start > _sparse_frames(approach)  # the option changes where the map starts
    run = run_sequence(approach, "relnav", **{"startup.map_min_points": 12})
    assert run.steps[start].status == "first"
    before = run.steps[1:start]
    assert all(s.status == "failed" for s in before)
    assert all(s.result.info["premap_range_m"] > 40.0 for s in before)
    e = np.linalg.norm(run.online_poses[:, :3, 3] - approach.gt_poses[:, :3, 3], axis=1)
    assert np.all(e[1 : start + 1] < 1.5)  # 0.82 m measured: a straight approach, the range
    # places the sensor; registering the 8-point scans instead drags the track sideways
    early = run_sequence(approach, "relnav")
    e0 = np.linalg.norm(early.online_poses[:, :3, 3] - approach.gt_poses[:, :3, 3], axis=1)
    assert e0[start] > 3.0  # 4.9 m measured
