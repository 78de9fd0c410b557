"""Pose graph of relnav's navigator: synthetic rings with drift, robust loop edges, the navigator
with ``loop_closure`` on a short simulated sequence with revisits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav_scenarios import flash_orbit
from relnav.errors import ConfigError
from relnav.geometry.se3 import exp_se3, invert, log_se3
from relnav.navigation import Navigator
from relnav.navigation.pose_graph import (
    PoseGraph,
    compose_step_covariances,
    interpolate_corrections,
)
from relnav.sim.scenario import simulate


def _ring(n: int, radius: float = 50.0) -> np.ndarray:
    """``n`` poses on a circle around the origin, each sensor looking at the centre."""
    poses = []
    for k in range(n):
        a = 2 * math.pi * k / n
        T = exp_se3(np.array([0.0, 0.0, 0.0, 0.0, a, 0.0]))
        T[:3, 3] = radius * np.array([math.sin(a), 0.0, math.cos(a)])
        poses.append(T)
    return np.stack(poses)


def _drifted_chain(truth: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, list]:
    """Odometry steps with a bias (drift) and noise; the chained poses and the steps."""
    bias = np.array([0.02, 0.0, 0.01, 0.0, math.radians(0.3), math.radians(0.1)])
    steps, chain = [], [truth[0].copy()]
    for k in range(1, len(truth)):
        S = invert(truth[k - 1]) @ truth[k]
        noise = rng.normal(0.0, [0.005] * 3 + [math.radians(0.02)] * 3)
        S = S @ exp_se3(bias + noise)
        steps.append(S)
        chain.append(chain[-1] @ S)
    return np.stack(chain), steps


def _ape(P: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((P[:, :3, 3] - truth[:, :3, 3]) ** 2, axis=1))))


def _ring_graph(chain: np.ndarray, steps: list) -> PoseGraph:
    odo_info = np.diag([1 / 0.03**2] * 3 + [1 / math.radians(0.4) ** 2] * 3)
    g = PoseGraph()
    for T in chain:
        g.add_node(T)
    for k, S in enumerate(steps):
        g.add_edge(k, k + 1, S, odo_info)
    return g


LOOP_INFO = np.diag([1 / 0.02**2] * 3 + [1 / math.radians(0.05) ** 2] * 3)


def test_one_correct_loop_edge_removes_most_of_the_drift(rng):
    truth = _ring(36)
    chain, steps = _drifted_chain(truth, rng)
    g = _ring_graph(chain, steps)
    g.add_edge(0, 35, invert(truth[0]) @ truth[35], LOOP_INFO, robust=True)
    res = g.optimize()
    before, after = _ape(chain, truth), _ape(res.poses, truth)
    assert before > 3.0  # the drift is large: metres over the ring
    assert after < 0.25 * before
    np.testing.assert_allclose(res.poses[0], chain[0])  # the gauge node stays
    assert res.weights[-1] > 0.5  # the correct loop edge keeps its weight


def test_a_wrong_loop_edge_is_down_weighted(rng):
    truth = _ring(36)
    chain, steps = _drifted_chain(truth, rng)
    g = _ring_graph(chain, steps)
    g.add_edge(0, 35, invert(truth[0]) @ truth[35], LOOP_INFO, robust=True)
    # a revisit that never happened: frame 18 (opposite side) "seen" 5 m and 20° off the truth
    wrong = invert(truth[0]) @ truth[18] @ exp_se3(np.array([5.0, 0, 0, 0, math.radians(20), 0]))
    g.add_edge(0, 18, wrong, LOOP_INFO, robust=True)
    res = g.optimize()
    assert res.weights[-1] < 0.01
    assert res.weights[-2] > 0.5
    assert _ape(res.poses, truth) < 0.3 * _ape(chain, truth)


def test_composed_covariance_matches_monte_carlo(rng):
    steps = [exp_se3(rng.normal(0, [1, 1, 1, 0.3, 0.3, 0.3])) for _ in range(3)]
    covs = []
    for _ in range(3):
        A = rng.normal(0, 0.02, (6, 6))
        covs.append(A @ A.T + 1e-5 * np.eye(6))
    C = compose_step_covariances(steps, covs)
    Z = steps[0] @ steps[1] @ steps[2]
    samples = []
    for _ in range(4000):
        Zs = np.eye(4)
        for S, Cs in zip(steps, covs, strict=True):
            Zs = Zs @ S @ exp_se3(rng.multivariate_normal(np.zeros(6), Cs))
        samples.append(log_se3(invert(Z) @ Zs))
    C_mc = np.cov(np.array(samples).T)
    # sampling error of a 4 000-sample covariance is a few per cent; first-order propagation
    np.testing.assert_allclose(np.diag(C), np.diag(C_mc), rtol=0.1)


def test_interpolated_corrections_reach_the_keyframes_and_blend_between(rng):
    poses = np.stack([exp_se3(rng.normal(0, 1, 6)) for _ in range(11)])
    frames = np.array([0, 5, 10])
    before = poses[frames]
    D = exp_se3(np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.1]))
    after = np.stack([before[0], D @ before[1], D @ before[2]])
    out = interpolate_corrections(poses, frames, before, after)
    np.testing.assert_allclose(out[frames], after, atol=1e-12)
    np.testing.assert_allclose(out[7], D @ poses[7], atol=1e-12)  # between equal corrections
    half = exp_se3(0.6 * log_se3(D))  # frame 3: 3/5 of the way from I to D
    np.testing.assert_allclose(out[3], half @ poses[3], atol=1e-12)


def test_pose_graph_rejects_bad_edges():
    g = PoseGraph()
    g.add_node(np.eye(4))
    with pytest.raises(ValueError):
        g.add_edge(0, 1, np.eye(4), np.eye(6))
    g.add_node(np.eye(4))
    with pytest.raises(ValueError):
        g.add_edge(0, 1, np.eye(4), np.full((6, 6), np.nan))


@pytest.fixture(scope="module")
def loop_seq(tmp_path_factory):
    """90 frames of a 64×64 flash LIDAR on 2.5 loops of an ellipse around an asteroid (revisits
    every 36 frames)."""
    out = tmp_path_factory.mktemp("nav-loop") / "seq"
    sc = flash_orbit("nav-loop-test", seed=5, frames=90, dt=155.0)
    simulate(sc, out)
    from relnav.io.sequences import ScanSequence

    return ScanSequence(out)


def _track(seq, **options):
    """Run the navigator frame by frame; (navigator, online poses, final poses)."""
    nav = Navigator(initial_pose=seq.gt_poses[0], **options)
    online = np.stack([nav.register_frame(seq[i]).pose for i in range(len(seq))])
    return nav, online, nav.finalize()


def test_navigator_with_loop_closure_keeps_one_finite_pose_per_frame(loop_seq):
    opts = {"loops.keyframe_every": 3, "loops.min_separation": 6}
    _, online_off, final_off = _track(loop_seq, **opts)
    nav, online_on, final_on = _track(loop_seq, **{"loops.enabled": True}, **opts)
    assert final_on.shape == final_off.shape == (len(loop_seq), 4, 4)
    assert np.all(np.isfinite(final_on))
    # revisits were found and registered, and the graph moved the trajectory
    assert nav.loop_closer is not None
    assert sum(e.accepted for e in nav.loop_closer.loops) >= 3
    assert not np.allclose(final_on, final_off)
    # the online per-frame poses are untouched: only finalize() applies the pose graph
    np.testing.assert_array_equal(online_on, online_off)
    # the corrected trajectory stays a trajectory: no jump beyond the largest true step
    gt = loop_seq.gt_poses
    true_step = np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1).max()
    est_step = np.linalg.norm(np.diff(final_on[:, :3, 3], axis=0), axis=1)
    assert est_step.max() < 1.5 * true_step


@pytest.mark.parametrize(
    ("options", "needle"),
    [
        ({"loops.keyframe_every": 0}, "must be >= 1"),
        ({"loops.min_overlap": 1.5}, "must be >= 0 and <= 1"),
        ({"loops.enabled": "maybe"}, "loops.enabled='maybe'"),
        ({"loops.kernal": 5.0}, "did you mean 'loops.kernel'"),
    ],
)
def test_bad_loop_option_is_a_config_error(options, needle):
    with pytest.raises(ConfigError, match=needle):
        Navigator(**options)
