"""The navigator's online revisit test (:mod:`relnav.navigation.revisit_check`): the chain
covariance from running sums, the revisit candidate, the χ² alarm on a consistent and on a
drifting trajectory, and the navigator's flags while the alarm stands."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from nav_scenarios import flash_orbit
from relnav.errors import ConfigError
from relnav.geometry.se3 import adjoint, exp_se3, invert
from relnav.navigation import Navigator
from relnav.navigation.pose_graph import LoopCloser, compose_step_covariances, revisit_candidate
from relnav.navigation.revisit_check import RevisitCheck, chain_covariance
from relnav.sim.scenario import simulate


def _random_cov(rng: np.random.Generator) -> np.ndarray:
    A = rng.normal(size=(6, 6)) * np.array([0.05] * 3 + [0.002] * 3)
    return A @ A.T + 1e-6 * np.eye(6)


def test_chain_covariance_from_running_sums_equals_composed_steps(rng):
    poses = [exp_se3(rng.normal(size=6))]
    covs = [np.zeros((6, 6))]
    for _ in range(12):
        poses.append(poses[-1] @ exp_se3(rng.normal(0.0, [1.0] * 3 + [0.2] * 3)))
        covs.append(_random_cov(rng))
    sums, S = [], np.zeros((6, 6))
    for T, C in zip(poses, covs, strict=True):
        A = adjoint(T)
        S = S + A @ C @ A.T
        sums.append(S)
    j, k = 3, 11
    steps = [invert(poses[f - 1]) @ poses[f] for f in range(j + 1, k + 1)]
    expected = compose_step_covariances(steps, covs[j + 1 : k + 1])
    np.testing.assert_allclose(chain_covariance(sums[j], sums[k], poses[k]), expected, atol=1e-12)


def _looking_at_origin(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    z = -p / np.linalg.norm(p)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = p
    return T


def test_revisit_candidate_is_the_nearest_old_keyframe_viewing_the_same_side():
    angles = np.radians(np.arange(0, 720, 30.0))  # two loops, 12 keyframes each
    poses = [_looking_at_origin(50.0 * np.array([math.cos(a), math.sin(a), 0.1])) for a in angles]
    positions = np.array([T[:3, 3] for T in poses])
    centroids = np.zeros_like(positions)  # every submap is centred on the target
    # the newest keyframe (loop 2, 330°) revisits loop 1's 330° keyframe, 12 keyframes older
    assert revisit_candidate(positions, centroids, 10, 0.15, math.radians(15)) == 11
    # a separation of 13 keyframes: index 11 (12 older) is too recent, and nothing else is near
    assert revisit_candidate(positions, centroids, 13, 0.15, math.radians(15)) is None
    # the view must match: the same place looking the other way (its submap behind it)
    away = centroids.copy()
    away[-1] = 2.0 * positions[-1]
    assert revisit_candidate(positions, away, 10, 0.15, math.radians(15)) is None
    # the place must match: moved 20 m away, nothing is near
    far = positions.copy()
    far[-1] *= 1.4
    assert revisit_candidate(far, centroids, 10, 0.15, math.radians(15)) is None
    # too few keyframes
    assert revisit_candidate(positions[:5], centroids[:5], 10, 0.15, math.radians(15)) is None


def _target(rng: np.random.Generator) -> np.ndarray:
    """Points on an asymmetric body: a 10×6×4 m box, a 3 m mast and a 6×3 m panel (m)."""
    half = np.array([5.0, 3.0, 2.0])
    box = rng.uniform(-1.0, 1.0, size=(3000, 3)) * half
    rows, axis = np.arange(len(box)), rng.integers(0, 3, len(box))
    box[rows, axis] = np.sign(box[rows, axis]) * half[axis]  # onto one of the six faces
    mast = np.column_stack([np.zeros(300), np.zeros(300), rng.uniform(2.0, 5.0, 300)])
    panel = np.column_stack(
        [rng.uniform(5.0, 11.0, 600), rng.uniform(-1.5, 1.5, 600), np.zeros(600)]
    )
    return np.vstack([box, mast, panel])


def _scans(points: np.ndarray, poses: list[np.ndarray], rng: np.random.Generator) -> list:
    """The target's points within 60° of each sensor's line of sight, sensor frame, 2 cm noise."""
    out = []
    for T in poses:
        P = (points - T[:3, 3]) @ T[:3, :3]
        keep = P[:, 2] > 0
        out.append(P[keep] + rng.normal(0.0, 0.02, size=(int(keep.sum()), 3)))
    return out


def _run_check(poses_seen: list[np.ndarray], scans: list, alarm: float) -> RevisitCheck:
    closer = LoopCloser(1.0, {"noise_floor": 0.02}, every=4, window=3, min_separation=6)
    check = RevisitCheck(closer, alarm)
    C = np.diag([0.05**2] * 3 + [math.radians(0.1) ** 2] * 3)
    for f, P in enumerate(scans):
        check.observe(f, True, P, None if f == 0 else C, lambda g: poses_seen[g])
    return check


@pytest.fixture(scope="module")
def circling():
    """Two loops of 36 frames at 45 m around the asymmetric body: true poses and scans."""
    rng = np.random.default_rng(11)
    angles = np.radians(np.arange(0, 720, 10.0))
    poses = [_looking_at_origin(45.0 * np.array([math.cos(a), math.sin(a), 0.3])) for a in angles]
    return poses, _scans(_target(rng), poses, rng)


def test_a_consistent_trajectory_passes_its_revisits(circling):
    poses, scans = circling
    check = _run_check(poses, scans, 16.81)
    assert len(check.checks) >= 3  # the second loop revisits the first
    assert all(e.supported for e in check.checks)
    assert max(e.chi2 for e in check.checks) < 16.81
    assert check.alarm is None and check.describe_alarm() == ""


def test_a_drifting_map_raises_the_alarm_with_its_disagreement(circling):
    poses, scans = circling
    # the navigator's poses turn away from the truth by 0.25° per frame about the target:
    # locally every step is nearly right, but a revisit 36 frames later is 9° off the chain
    drifted = [
        exp_se3(np.array([0, 0, 0, 0, 0, math.radians(0.25 * f)])) @ T for f, T in enumerate(poses)
    ]
    check = _run_check(drifted, scans, 16.81)
    assert any(e.supported and e.chi2 > 16.81 for e in check.checks)
    assert check.alarm is not None
    old, new, chi2, _, gap_deg = check.alarm
    assert new - old >= 24 and chi2 > 16.81
    # the registered disagreement is the drift between the two frames: 0.25° per frame
    assert gap_deg == pytest.approx(0.25 * (new - old), rel=0.2)
    assert "map inconsistent since frame" in check.describe_alarm()


def test_a_revisit_without_evidence_neither_raises_nor_clears_the_alarm(circling):
    poses, _ = circling
    rng = np.random.default_rng(5)
    # a flat plate: the registration cannot fix the slide and turn in its plane (degenerate),
    # so the drift's disagreement is not evidence
    plate = np.column_stack([rng.uniform(-8, 8, 4000), rng.uniform(-8, 8, 4000), np.zeros(4000)])
    drifted = [
        exp_se3(np.array([0, 0, 0, 0, 0, math.radians(0.25 * f)])) @ T for f, T in enumerate(poses)
    ]
    check = _run_check(drifted, _scans(plate, poses, rng), 16.81)
    assert check.checks and not any(e.supported for e in check.checks)
    assert check.alarm is None


@pytest.fixture(scope="module")
def loop_dir(tmp_path_factory):
    """90 frames of a 64×64 flash LIDAR on 2.5 loops of an ellipse around an asteroid (revisits
    every 36 frames)."""
    out = tmp_path_factory.mktemp("nav-revisit") / "seq"
    simulate(flash_orbit("nav-revisit-test", seed=5, frames=90, dt=155.0), out)
    return out


@pytest.fixture(scope="module")
def loop_seq(loop_dir):
    from relnav.io.sequences import ScanSequence

    return ScanSequence(loop_dir)


def _statuses(seq, **options) -> tuple[Navigator, list]:
    """The navigator's steps after the first frame (which has no registration)."""
    nav = Navigator(initial_pose=seq.gt_poses[0], **options)
    return nav, [nav.register_frame(seq[i]) for i in range(len(seq))][1:]


def test_navigator_flags_its_steps_while_the_revisit_alarm_stands(loop_seq):
    opts = {"loops.keyframe_every": 3, "loops.min_separation": 6}
    nav, steps = _statuses(loop_seq, **opts)
    tested = [k for k, s in enumerate(steps) if "revisit_chi2" in s.result.info]
    assert tested, "the orbit's revisits were tested"
    assert nav.revisits is not None and len(nav.revisits.checks) == len(tested)
    record = nav.final_report()["revisits"]  # the run's record (run.json)
    assert len(record) == len(tested) and not any(r["alarm"] for r in record)
    assert all(r["new_frame"] - r["old_frame"] >= 6 * 3 for r in record)
    assert all(
        s.result.info["revisit_chi2"] < 16.81 for s in steps if "revisit_chi2" in s.result.info
    )
    assert not any(s.result.message.startswith("map inconsistent") for s in steps)
    # the same run with a zero-size test (every supported revisit "fails"): the poses are the
    # same, and from the first such revisit on every ok step is flagged with the reason
    _, alarmed = _statuses(loop_seq, **{"loops.revisit_alarm_chi2": 1e-9}, **opts)
    np.testing.assert_array_equal([s.pose for s in alarmed], [s.pose for s in steps])
    first = next(k for k, s in enumerate(alarmed) if s.result.info.get("revisit_alarm"))
    assert "map inconsistent" in alarmed[first].result.message
    assert first == tested[0]
    assert all(s.status != "ok" for s in alarmed[first:])
    # off: no test at all
    _, off = _statuses(loop_seq, **{"loops.revisit_alarm_chi2": 0}, **opts)
    assert not any("revisit_chi2" in s.result.info for s in off)
    assert [s.status for s in off] == [s.status for s in steps]


def test_negative_alarm_threshold_is_a_config_error():
    with pytest.raises(ConfigError, match="revisit_alarm_chi2"):
        Navigator(**{"loops.revisit_alarm_chi2": -1.0})


def test_odometry_reports_the_revisit_alarm(loop_dir, tmp_path):
    from typer.testing import CliRunner

    from relnav.cli.main import app

    args = ["odometry", str(loop_dir), "--no-state", "-O", "loops.keyframe_every=3"]
    args += ["-O", "loops.min_separation=6"]
    res = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "ok")])
    assert res.exit_code == 0, res.output
    m = json.loads((tmp_path / "ok" / "metrics.json").read_text())
    assert m["revisit_tests"] > 0 and m["revisit_alarms"] == 0
    assert "map inconsistent" not in res.output
    # a zero-size test: every supported revisit fails, the run says so and flags the rest
    res = CliRunner().invoke(
        app, [*args, "-O", "loops.revisit_alarm_chi2=1e-9", "--out", str(tmp_path / "alarm")]
    )
    assert res.exit_code == 0, res.output
    m = json.loads((tmp_path / "alarm" / "metrics.json").read_text())
    assert m["revisit_alarms"] > 0 and m["flagged_frames"] > 0
    assert "map inconsistent" in res.output
    record = json.loads((tmp_path / "alarm" / "run.json").read_text())
    assert any(r["alarm"] for r in record["options"]["finalize"]["revisits"])
    diagnostics = (tmp_path / "alarm" / "diagnostics.csv").read_text()
    assert "map inconsistent since frame" in diagnostics
