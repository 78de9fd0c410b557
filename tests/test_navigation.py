"""relnav's navigator: map, motion filter, tracking accuracy on a short sparse orbit, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav_scenarios import FLASH_64, flash_orbit
from relnav.geometry.se3 import adjoint, exp_se3, invert, log_se3
from relnav.navigation import Navigator, VoxelMap
from relnav.navigation.motion import ConstantVelocityFilter
from relnav.pipeline import run_sequence
from relnav.sim.scenario import simulate


@pytest.fixture(scope="module")
def orbit_seq(tmp_path_factory):
    """30 frames of a 64×64 flash LIDAR (2 cm noise) on an ellipse around an asteroid at ~50 m."""
    out = tmp_path_factory.mktemp("nav") / "seq"
    sc = flash_orbit("nav-test", max_frames=30)
    simulate(sc, out)
    from relnav.io.sequences import ScanSequence

    return ScanSequence(out)


def _step_errors(est, gt):
    et, er = [], []
    for k in range(1, len(est)):
        e = invert(invert(gt[k - 1]) @ gt[k]) @ (invert(est[k - 1]) @ est[k])
        et.append(np.linalg.norm(e[:3, 3]))
        er.append(math.degrees(math.acos(np.clip((np.trace(e[:3, :3]) - 1) / 2, -1, 1))))
    return np.array(et), np.array(er)


def test_navigator_tracks_sparse_orbit_better_than_pairwise_icp(orbit_seq):
    gt = orbit_seq.gt_poses
    nav = run_sequence(orbit_seq, "relnav")
    icp = run_sequence(orbit_seq, "icp-plane")
    et_nav, _ = _step_errors(nav.poses, gt)
    et_icp, _ = _step_errors(icp.poses, gt)
    steps = np.linalg.norm([(invert(gt[k - 1]) @ gt[k])[:3, 3] for k in range(1, len(gt))], axis=1)
    # a per-step error well below the step itself (≈ 3 m) and below pairwise ICP's on these frames
    assert np.sqrt(np.mean(et_nav**2)) < 0.15 * np.mean(steps)
    assert np.sqrt(np.mean(et_nav**2)) < np.sqrt(np.mean(et_icp**2))
    final = np.linalg.norm((invert(gt[-1]) @ nav.poses[-1])[:3, 3])
    assert final < 2.0
    assert all(s.status in ("first", "ok") for s in nav.steps)


def test_navigator_is_deterministic(orbit_seq):
    a = run_sequence(orbit_seq, "relnav", max_frames=8)
    b = run_sequence(orbit_seq, "relnav", max_frames=8)
    np.testing.assert_array_equal(a.poses, b.poses)


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros((0, 3)),
        np.full((40, 3), np.nan),
        np.ones((40, 3)),  # 40 coincident points
        np.c_[np.linspace(0, 5, 40), np.zeros(40), np.zeros(40)] + [50, 0, 0],  # collinear
    ],
    ids=["empty", "nan", "coincident", "collinear"],
)
def test_bad_scan_is_flagged_and_tracking_continues(orbit_seq, bad):
    nav = Navigator(initial_pose=orbit_seq.gt_poses[0])
    statuses = []
    for k in range(6):
        pts = bad if k == 3 else orbit_seq[k].points
        step = nav.register_frame(pts)
        statuses.append(step.status)
        assert np.all(np.isfinite(step.pose))
    assert statuses[3] in ("failed", "degenerate")
    assert statuses[4] == "ok" and statuses[5] == "ok"
    err = np.linalg.norm((invert(orbit_seq.gt_poses[5]) @ nav.pose)[:3, 3])
    assert err < 2.0


@pytest.mark.parametrize(
    ("options", "needle"),
    [
        ({"map.voxel_factr": 0.3}, "did you mean 'map.voxel_factor'"),
        ({"solver.kernel": "abc"}, "solver.kernel='abc'"),
        ({"solver.max_iter": 0}, "must be >= 1"),
        ({"solver.max_iter": 2.5}, "fractional"),
        ({"solver.min_overlap": 1.5}, "must be >= 0 and <= 1"),
        ({"prior.sigma_acc_t": float("nan")}, "NaN"),
        ({"solver": {"kernel": -1.0}}, "solver.kernel=-1.0 out of range"),
        ({"startup": {"windw": 4}}, "did you mean 'startup.window'"),  # -O startup.windw=4
    ],
)
def test_bad_option_is_a_config_error(options, needle):
    from relnav.errors import ConfigError

    with pytest.raises(ConfigError, match="method 'relnav'") as e:
        Navigator(**options)
    assert needle in str(e.value)


def test_voxel_map_bounds_and_forgets(rng):
    m = VoxelMap(0.5, max_weight=4.0, max_voxels=50)
    plane = np.c_[rng.uniform(0, 2, (200, 2)), np.zeros(200)]
    for f in range(3):
        m.insert(plane, frame=f)
    assert len(m) <= 16 + 1  # 4×4 voxels on a 2 m square
    assert np.all(m.weights <= 4.0 + 1e-9)
    # normals of a plane are ±z; the information is strong along z, weak in the plane
    assert np.all(np.abs(np.abs(m.normals[:, 2]) - 1.0) < 1e-6)
    assert np.all(m.information[:, 2, 2] > 100 * m.information[:, 0, 0])
    m.insert(rng.uniform(10, 30, (500, 3)), frame=3)
    assert len(m) <= 50
    assert m.last_seen.max() == 3


def test_constant_velocity_filter_learns_velocity_and_ignores_unseen_directions():
    v_true = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.02])
    f = ConstantVelocityFilter(np.eye(4), 0.0, np.full(6, 5.0), np.full(6, 1e-3))
    T = np.eye(4)
    H = np.diag([1e4, 1e4, 1e4, 1e4, 1e4, 1e4])
    for k in range(1, 6):
        T = T @ exp_se3(v_true)
        f.predict(float(k))
        Ad = adjoint(T)
        f.update(T, np.linalg.inv(Ad).T @ H @ np.linalg.inv(Ad))
    np.testing.assert_allclose(f.velocity, v_true, atol=1e-3)
    # a measurement blind along body x: the pose keeps the model's x motion
    T_pred, _ = f.predict(6.0)
    Hb = np.diag([0.0, 1e4, 1e4, 1e4, 1e4, 1e4])
    Ad = adjoint(T_pred)
    f.update(T_pred, np.linalg.inv(Ad).T @ Hb @ np.linalg.inv(Ad))
    np.testing.assert_allclose(log_se3(invert(T) @ f.pose), v_true, atol=1e-6)


@pytest.fixture(scope="module")
def tumble_run(tmp_path_factory):
    """A 64×64 flash LIDAR on a hold point 50 m from a satellite spinning 1°/s about a tilted
    axis, 60 frames at 2 s, and the navigator's run on it."""
    out = tmp_path_factory.mktemp("tumble") / "seq"
    sc = {
        "name": "nav-tumble-test",
        "seed": 1,
        "frames": 60,
        "dt": 2.0,
        "format": "npy",
        "target": {"name": "envisat", "scale_to": 16.0},
        "sensors": [dict(FLASH_64)],
        "trajectory": {"kind": "static", "params": {"position": (-50.0, 0.0, 5.0)}},
        "attitude": {
            "kind": "spin",
            "axis": (0.35, 0.25, 0.90),
            "rate_deg_s": 1.0,
            "initial_rpy_deg": (10.0, 20.0, 0.0),
        },
    }
    simulate(sc, out)
    from relnav.io.sequences import ScanSequence

    seq = ScanSequence(out)
    return seq, run_sequence(seq, "relnav")


@pytest.mark.parametrize("process_noise", ["poses", "physics"])
def test_relative_state_recovers_the_spin_rate(tumble_run, process_noise):
    from relnav.navigation.state import relative_state

    seq, run = tumble_run
    res = relative_state(run, gt_poses=seq.gt_poses, process_noise=process_noise)
    k0 = len(res) // 3
    err = np.degrees(np.linalg.norm(res.errors()["omega"][k0:], axis=1))
    rate = np.degrees(np.linalg.norm(res.truth.omega[k0:], axis=1))
    assert np.allclose(rate, 1.0, atol=0.05)  # the truth is the 1°/s spin
    assert np.median(err) < 0.1 and np.max(err) < 0.2  # a tenth of the rate, typically
    sig = np.degrees(res.sigma()["omega"][k0:])
    assert np.all(np.isfinite(sig)) and np.all(sig > 0)


def test_pose_noise_from_second_differences(rng):
    from types import SimpleNamespace

    from relnav.navigation.state import pose_noise

    v = np.array([1.0, 0.2, 0.0, 0.0, 0.0, 0.03])
    for frame in ("sensor", "target"):
        steps, T = [], np.eye(4)
        for _ in range(400):
            T = T @ exp_se3(v)
            e = exp_se3(np.r_[rng.normal(0, 0.05, 3), rng.normal(0, 0.002, 3)])
            # sensor: a right twist (sensor axes); target: a left twist (the target's own
            # position and attitude)
            noisy = T @ e if frame == "sensor" else e @ T
            steps.append(SimpleNamespace(pose=noisy, status="ok"))
        nt, nr = pose_noise(steps, frame=frame)
        assert 0.035 < nt < 0.07
        assert 0.0014 < nr < 0.0028


def test_unreadable_scan_is_flagged_and_the_navigator_goes_on(orbit_seq, tmp_path):
    import shutil

    from relnav.io.sequences import ScanSequence

    folder = tmp_path / "seq"
    shutil.copytree(orbit_seq.folder, folder)
    seq = ScanSequence(folder)
    bad = seq.files[5]
    bad.write_bytes(bad.read_bytes()[:40])  # truncated
    run = run_sequence(ScanSequence(folder), "relnav", max_frames=12)
    status = [s.status for s in run.steps]
    assert status[5] == "failed" and "unreadable scan" in run.steps[5].result.message
    assert all(s == "ok" for k, s in enumerate(status[1:], 1) if k != 5)
    err = np.linalg.norm((invert(orbit_seq.gt_poses[11]) @ run.poses[11])[:3, 3])
    assert err < 2.0


def test_fixed_lag_smoother_reduces_the_error_of_noisy_poses(rng):
    v = np.array([1.0, 0.0, 0.1, 0.0, 0.0, 0.02])
    f = ConstantVelocityFilter(np.eye(4), 0.0, np.full(6, 2.0), np.full(6, 1e-3))
    f.start_smoothing(5)
    truth, filtered = [np.eye(4)], [np.eye(4)]
    H = np.diag([1 / 0.05**2] * 3 + [1 / 0.002**2] * 3)  # body-frame information of a pose
    T = np.eye(4)
    for k in range(1, 60):
        T = T @ exp_se3(v)
        meas = T @ exp_se3(np.r_[rng.normal(0, 0.05, 3), rng.normal(0, 0.002, 3)])
        f.predict(float(k))
        Ad_inv = np.linalg.inv(adjoint(meas))
        # the filter takes the measurement's own information: the pose itself is the MAP here
        T_pred = f._pred[0]
        P_pp = f._pred[1][:6, :6]
        y = log_se3(invert(T_pred) @ meas)
        T_map = T_pred @ exp_se3(np.linalg.solve(np.linalg.inv(P_pp) + H, H @ y))
        f.update(T_map, Ad_inv.T @ H @ Ad_inv)
        truth.append(T.copy())
        filtered.append(f.pose.copy())
    smoothed = f.finish_smoothing()
    assert len(smoothed) == 60

    def err(P):
        return np.sqrt(
            np.mean([np.sum((p[:3, 3] - t[:3, 3]) ** 2) for p, t in zip(P, truth, strict=True)])
        )

    assert err(smoothed) < 0.8 * err(filtered)


def test_bootstrap_second_pass_keeps_one_pose_per_frame(orbit_seq):
    run = run_sequence(
        orbit_seq, "relnav", max_frames=12, **{"startup.window": 0, "startup.bootstrap_frames": 4}
    )
    assert run.poses.shape == (12, 4, 4) and np.all(np.isfinite(run.poses))
    assert all(s.status in ("first", "ok") for s in run.steps)
    err = np.linalg.norm((invert(orbit_seq.gt_poses[11]) @ run.poses[11])[:3, 3])
    assert err < 2.0


def test_numba_se3_maps_equal_the_reference(rng):
    from relnav.geometry import lie
    from relnav.geometry import se3 as ref

    angles = [0.0, 1e-12, 1e-6, 0.5, 2.0, 2.99, np.pi - 1e-4, np.pi - 1e-7, np.pi]
    for ang in angles + list(rng.uniform(0, np.pi, 50)):
        ax = rng.normal(size=3)
        xi = np.r_[rng.normal(0, 5, 3), ang * ax / np.linalg.norm(ax)]
        T = ref.exp_se3(xi)
        np.testing.assert_allclose(lie.exp_se3(xi), T, atol=1e-12)
        np.testing.assert_allclose(ref.exp_se3(lie.log_se3(T)), T, atol=1e-6)
        if ang < np.pi - 1e-3:  # away from π the twist itself is unique
            np.testing.assert_allclose(lie.log_se3(T), ref.log_se3(T), atol=1e-9)


def test_step_covariance_is_consistent_with_the_step_errors():
    """The filter's step covariance (stochastic clone of the previous pose) against Monte Carlo
    step errors: the NEES of one step per independent run lies in its 95 % χ² band."""
    from scipy.stats import chi2

    v = np.array([0.5, 0.0, 0.1, 0.0, 0.01, 0.02])
    sig = np.array([0.05] * 3 + [0.004] * 3)
    H = np.diag(1 / sig**2)  # body-frame information of a pose measurement
    runs, nees = 150, []
    for seed in range(runs):
        rng = np.random.default_rng(seed)
        f = ConstantVelocityFilter(np.eye(4), 0.0, np.full(6, 2.0), np.full(6, 1e-6))
        T = np.eye(4)
        prev_est, prev_true = np.eye(4), np.eye(4)
        for k in range(1, 16):
            T = T @ exp_se3(v)
            meas = T @ exp_se3(rng.normal(0, sig))
            f.predict(float(k))
            T_pred, P_pp = f._pred[0], f._pred[1][:6, :6]
            y = log_se3(invert(T_pred) @ meas)
            T_map = T_pred @ exp_se3(np.linalg.solve(np.linalg.inv(P_pp) + H, H @ y))
            Ad_inv = np.linalg.inv(adjoint(T_map))
            f.update(T_map, Ad_inv.T @ H @ Ad_inv)
            if k < 15:
                prev_est, prev_true = f.pose.copy(), T.copy()
        S_est = invert(prev_est) @ f.pose
        e = log_se3(invert(S_est) @ (invert(prev_true) @ T))
        nees.append(float(e @ np.linalg.solve(f.step_covariance, e)))
    lo, hi = chi2.ppf([0.025, 0.975], 6 * runs) / runs
    assert lo < np.mean(nees) < hi, (np.mean(nees), lo, hi)


@pytest.fixture(scope="module")
def monitored_runs(orbit_seq):
    """12 frames (the multi-view start included) without integrity monitoring and with an alert
    limit below every protection level."""
    free = run_sequence(orbit_seq, "relnav", max_frames=12)
    tight = run_sequence(orbit_seq, "relnav", max_frames=12, **{"integrity.alert_limit_t": 1e-6})
    return free, tight


def test_alert_limit_flags_steps_without_changing_poses(monitored_runs):
    """Integrity monitoring only labels steps: the poses are those of the unmonitored run, every
    step records its 1σ, and a limit below every protection level flags every registered step."""
    free, tight = monitored_runs
    assert free.steps[-1].result.info.get("merged")
    np.testing.assert_array_equal(free.poses, tight.poses)
    assert all(s.result.info["step_sigma_t"] > 0 for s in free.steps[1:])
    assert all(s.status in ("first", "ok") for s in free.steps)
    assert all(s.status == "degenerate" for s in tight.steps[1:])
    assert all("protection level" in s.result.message for s in tight.steps[1:])
    assert not any(s.used_prior for s in tight.steps[1:])


def test_relabelled_merged_frames_still_observe_the_relative_state(monitored_runs):
    """A step relabelled ``degenerate`` by an alert limit went into the map all the same
    (``in_map``): the relative state takes it as an observation, so the state is that of the
    unmonitored run."""
    from relnav.navigation.options import in_map
    from relnav.navigation.state import StateRecord, relative_state

    free, tight = monitored_runs
    assert all(in_map(s) and StateRecord.from_step(s).merged for s in tight.steps)
    a, b = relative_state(free), relative_state(tight)
    np.testing.assert_allclose(b.position, a.position)
    np.testing.assert_allclose(b.omega, a.omega)


def test_step_flags_label_steps_without_changing_poses(orbit_seq):
    """``flag_probability``: a step whose covariance puts its error beyond the flag limits with
    a higher probability is ``flagged`` (a label: poses identical to an unflagged run); on the
    well-observed orbit at the suite's limits (0.5 m, 5°) no step is flagged."""
    off = run_sequence(orbit_seq, "relnav", max_frames=10, **{"integrity.flag_probability": 0.0})
    default = run_sequence(orbit_seq, "relnav", max_frames=10)
    tight = run_sequence(orbit_seq, "relnav", max_frames=10, **{"integrity.flag_limit_t": 1e-6})
    np.testing.assert_array_equal(off.poses, default.poses)
    np.testing.assert_array_equal(off.poses, tight.poses)
    assert all(s.status in ("first", "ok") for s in default.steps)
    # the first two steps (weak start-up prior: 1σ ≈ 0.26 m) 0.06, then below 0.01
    assert all(s.result.info["exceed_probability"] < 0.2 for s in default.steps[1:])
    assert all(s.result.info["exceed_probability"] < 0.02 for s in default.steps[4:])
    assert "exceed_probability" not in off.steps[1].result.info
    assert all(s.status == "flagged" for s in tight.steps[1:])
    assert all(s.result.info["exceed_probability"] == 1.0 for s in tight.steps[1:])
    assert all("probability" in s.result.message for s in tight.steps[1:])
    assert not any(s.used_prior for s in tight.steps[1:])
    assert tight.n_flagged == 9


def test_exceedance_probability_matches_closed_forms():
    """One uncertain axis: P(|N(0, σ²)| > L) = 2Φ(−L/σ), within the draws' standard error; both
    limits at once: the union of independent events; certain and non-finite extremes."""
    from scipy.stats import norm

    from relnav.navigation.navigator import exceedance_probability

    for sigma in (0.2, 0.5, 1.0):
        C = np.diag([sigma**2, 0, 0, 0, 0, 0])
        p = exceedance_probability(C, 0.5, math.radians(5))
        assert abs(p - 2 * norm.sf(0.5 / sigma)) < 0.03, (sigma, p)
    C = np.diag([0.5**2, 0, 0, math.radians(5) ** 2, 0, 0])
    q = 2 * norm.sf(1.0)
    assert abs(exceedance_probability(C, 0.5, math.radians(5)) - (1 - (1 - q) ** 2)) < 0.03
    assert exceedance_probability(np.zeros((6, 6)), 0.5, 0.1) == 0.0
    assert exceedance_probability(1e6 * np.eye(6), 0.5, 0.1) == 1.0
    assert exceedance_probability(np.full((6, 6), np.nan), 0.5, 0.1) == 1.0


def test_exceedance_probability_counts_the_fixed_draws_exactly(rng):
    """The compiled count and the no-draw shortcut (a bound that no draw can pass) give the
    fraction of the fixed draws ``e = B z`` beyond either limit, draw for draw, on correlated
    covariances from far inside to far beyond the limits."""
    from relnav.navigation.integrity import _unit_normals, exceedance_probability

    Z = _unit_normals()
    lt, lr = 0.5, math.radians(5)
    shortcut = 0
    for scale in (1e-3, 0.02, 0.1, 0.3, 1.0):
        for _ in range(20):
            A = rng.standard_normal((6, 6)) * scale
            C = A @ A.T
            w, U = np.linalg.eigh(C)
            e = Z @ (U * np.sqrt(np.maximum(w, 0.0))).T
            beyond = (np.sum(e[:, :3] ** 2, axis=1) > lt**2) | (
                np.sum(e[:, 3:] ** 2, axis=1) > lr**2
            )
            p = exceedance_probability(C, lt, lr)
            assert abs(p - beyond.mean()) <= 2 / len(Z)  # at most a draw on a limit's edge
            shortcut += p == 0.0
    assert shortcut >= 20  # the smallest covariances take the shortcut, and it says 0


def test_exceedance_probability_counts_only_draws_that_can_pass_a_limit(rng):
    """Counting only the draws long enough to pass a limit by the eigenvalue bound gives the
    same count as counting every draw, draw for draw, on covariances whose 1σ ellipsoid spans
    the limits (where the bound prunes some draws and keeps others)."""
    from relnav.navigation.integrity import (
        _draws_by_norm,
        _draws_that_can_exceed,
        _exceed_count,
        _unit_normals,
    )

    Z_all = np.ascontiguousarray(_unit_normals().T)
    Zt, z2 = _draws_by_norm()
    lt2, lr2 = 0.5**2, math.radians(5) ** 2
    pruned = 0
    for scale in np.geomspace(0.03, 0.5, 40):
        A = rng.standard_normal((6, 6)) * scale
        A[3:] *= math.radians(5) / 0.5  # rotations at the same share of their limit
        w, U = np.linalg.eigh(A @ A.T)
        B = np.ascontiguousarray(U * np.sqrt(np.maximum(w, 0.0)))
        n = _draws_that_can_exceed(B, z2, lt2, lr2)
        every = _exceed_count(Z_all, B, lt2, lr2, Z_all.shape[1])
        assert _exceed_count(Zt, B, lt2, lr2, n) == every
        pruned += 0 < n < len(z2)
    assert pruned >= 10  # the comparison covered partly pruned counts, not only all or none


def test_normal_information_drops_the_in_plane_pull(rng):
    """On a flat patch the normals fix only z, roll and pitch: the normal-only information has
    no translation along the plane and no rotation about its normal, the solver's has."""
    from relnav.navigation.gicp import normal_information

    P = np.c_[rng.uniform(-5, 5, (200, 2)), np.zeros(200)]
    n = np.tile([0.0, 0.0, 1.0], (200, 1))
    sn2, sp2 = 0.01**2, 0.3**2
    nn = n[:, :, None] * n[:, None, :]
    Om = nn / sn2 + (np.eye(3) - nn) / sp2
    H = normal_information(P, np.eye(4), np.arange(200), np.zeros(200), n, Om, sp2, 9.0)
    free = [0, 1, 5]  # x, y translation and rotation about z
    assert np.allclose(H[np.ix_(free, free)], 0.0, atol=1e-6)
    fixed = [2, 3, 4]
    assert np.all(np.linalg.eigvalsh(H[np.ix_(fixed, fixed)]) > 1e3)


def test_degeneracy_and_variance_factor_of_a_registration(rng):
    """The lever-arm-normalised eigenvalue ratio is 1 for information that weighs metres and
    radians alike at that lever arm and 0 with a free direction; the variance factor only scales
    information down, and is 1 without pairs."""
    from relnav.navigation.gicp import degeneracy, variance_factor

    r = 40.0
    H = np.diag([1.0, 1.0, 1.0, r**2, r**2, r**2])
    assert degeneracy(H, r) == pytest.approx(1.0)
    assert degeneracy(H, 1.0) == pytest.approx(1.0 / r**2)
    H[5, 5] = 0.0  # rotation about z unconstrained
    assert degeneracy(H, r) == 0.0
    assert degeneracy(np.zeros((6, 6)), r) == 0.0
    assert variance_factor(0.5) == 1.0
    assert variance_factor(2.0) == pytest.approx(4.0)
    assert variance_factor(float("nan")) == variance_factor(float("inf")) == 1.0


def test_robust_cost_saturates_at_the_kernel_and_counts_unpaired_points_there():
    """Geman–McClure on squared Mahalanobis distances: 0 at a perfect pair, ``c²/2`` at
    ``d = c``, towards ``c²`` far out, and ``c²`` for a point without a pair."""
    from relnav.navigation.gicp import robust_cost

    c = 3.0
    assert robust_cost(np.array([0.0]), c) == 0.0
    assert robust_cost(np.array([9.0]), c) == pytest.approx(4.5)
    assert robust_cost(np.array([1e12]), c) == pytest.approx(9.0)
    assert robust_cost(np.array([-1.0, -1.0]), c) == pytest.approx(18.0)
    assert robust_cost(np.array([0.0, 1.0, 9.0, -1.0]), c) == pytest.approx(0.9 + 4.5 + 9.0)
    assert robust_cost(np.array([]), c) == 0.0


def test_drift_covariance_maps_the_step_to_the_observation(rng):
    """A step error is a body twist of ``T_target_sensor``; the observation is the target's
    position in the sensor frame and its attitude in target axes."""
    from relnav.geometry.rotations import random_rotation
    from relnav.navigation.state import StateRecord, drift_covariance

    T = np.eye(4)
    T[:3, :3] = random_rotation(rng)
    T[:3, 3] = rng.normal(0, 30, 3)
    A = rng.normal(size=(6, 6))
    C = A @ A.T
    Ct, Cr = np.zeros((6, 6)), np.zeros((6, 6))
    Ct[:3, :3], Cr[3:, 3:] = C[:3, :3], C[3:, 3:]
    # a body translation of the sensor moves the target by the same vector in the sensor frame
    Dt = drift_covariance(Ct, T)
    np.testing.assert_allclose(Dt[:3, :3], C[:3, :3], atol=1e-9)
    np.testing.assert_allclose(Dt[3:, :], 0.0, atol=1e-9)
    # a body rotation φ of the sensor is R_ts φ in target axes (and swings the target by the
    # lever arm in the sensor frame)
    R = T[:3, :3]
    Dr = drift_covariance(Cr, T)
    np.testing.assert_allclose(Dr[3:, 3:], R @ C[3:, 3:] @ R.T, atol=1e-9)
    assert np.allclose(drift_covariance(C, T), drift_covariance(C, T).T)
    # the navigator's steps carry their covariance into the compact records
    from types import SimpleNamespace

    res = SimpleNamespace(info={"information": np.eye(6), "step_covariance": C})
    rec = StateRecord.from_step(SimpleNamespace(status="ok", pose=T, result=res))
    np.testing.assert_array_equal(rec.step_covariance, C)


def test_map_drift_shares_follow_the_map_running_mean():
    """Frame k merged into a map of n frames moves it by 1/min(n, memory) of its error; frames
    the navigator did not merge do not count (a ``flagged`` one was merged)."""
    from types import SimpleNamespace

    from relnav.navigation.state import map_drift_shares

    status = ["first", "ok", "flagged", "failed", "ok"] + ["ok"] * 10
    steps = [SimpleNamespace(status=s) for s in status]
    g = map_drift_shares(steps, memory=5.0)
    np.testing.assert_allclose(g[:6], [1.0, 1.0, 1 / 2, 1 / 3, 1 / 3, 1 / 4])
    np.testing.assert_allclose(g[7:], 1 / 5)  # saturated at the memory
    assert np.all(map_drift_shares(steps, memory=1.0) == 1.0)  # memory 1: the whole step


def test_split_rotation_drift_keeps_both_parts_covariances(rng):
    """The map's share of a step's rotation (with its lever arm) and the white rest: both
    positive semi-definite, summing to the step; a translation alone stays with the map."""
    from relnav.navigation.state import split_rotation_drift

    A = rng.normal(size=(6, 6))
    Q = A @ A.T
    for share in (1.0, 0.3, 0.05):
        bias, white = split_rotation_drift(Q, share)
        np.testing.assert_allclose(bias + white, Q, atol=1e-12)
        assert np.linalg.eigvalsh(bias).min() > -1e-9
        assert np.linalg.eigvalsh(white).min() > -1e-9
        # the rotation block is split by the share
        np.testing.assert_allclose(bias[3:, 3:], share * Q[3:, 3:], atol=1e-9)
    np.testing.assert_allclose(split_rotation_drift(Q, 1.0)[1], 0.0, atol=1e-12)
    Qt = np.zeros((6, 6))
    Qt[:3, :3] = Q[:3, :3]
    np.testing.assert_allclose(split_rotation_drift(Qt, 0.1)[0], Qt, atol=1e-12)


def test_relative_state_map_drift_on_a_short_run(tumble_run):
    """drift="map": the bias takes the map's share of each step's rotation, the rest goes to
    the observation's white noise; the rate is still recovered and the option is checked."""
    from relnav.errors import ConfigError
    from relnav.navigation.state import StateRecord, relative_state

    seq, run = tumble_run
    steps = [StateRecord.from_step(s) for s in run.steps]
    full = relative_state(run, steps=steps, gt_poses=seq.gt_poses)
    mapd = relative_state(run, steps=steps, gt_poses=seq.gt_poses, drift="map")
    k0 = len(mapd) // 3
    err = np.degrees(np.linalg.norm(mapd.errors()["omega"][k0:], axis=1))
    assert np.median(err) < 0.1 and np.max(err) < 0.2
    # less freedom for the bias's rotation: the attitude's covariance at the end is smaller
    assert np.trace(mapd.covariance[-1][6:9, 6:9]) < np.trace(full.covariance[-1][6:9, 6:9])
    # memory 1 is the whole step: the default model
    one = relative_state(run, steps=steps, gt_poses=seq.gt_poses, drift="map", map_memory=1.0)
    np.testing.assert_allclose(one.covariance[-1], full.covariance[-1], rtol=1e-6, atol=1e-15)
    with pytest.raises(ConfigError):
        relative_state(run, steps=steps, drift="share")
    with pytest.raises(ConfigError):
        relative_state(run, steps=steps, drift="map", map_memory=0.5)


def test_nearest_map_point_search_reuses_neighbours_exactly(rng):
    """The solver's nearest-map-point search skips a point whose neighbour provably did not
    change: over a converging sequence of poses its answers equal fresh searches and brute
    force (main and recent trees, the gate)."""
    from relnav.navigation.gicp import _nearest, _new_cache

    m = VoxelMap(0.05)
    surf = rng.normal(size=(3000, 3))
    surf /= np.linalg.norm(surf, axis=1)[:, None]
    m.insert(surf[:2700], frame=0)
    _ = m.means  # main tree over the first points
    m.insert(surf[2700:] * 1.01, frame=1)  # the recent tree
    trees = m.search_trees
    main, recent = trees[0], trees[4]
    assert len(main) > 1000 and len(recent) > 100
    P = surf[::7] * 1.02 + rng.normal(scale=0.01, size=surf[::7].shape)
    gate = 0.08
    cache = _new_cache(len(P))
    xi = np.r_[0.05, -0.03, 0.02, 0.03, 0.01, -0.02]
    for k in range(12):
        T = exp_se3(xi * 0.5**k)
        X, idx = _nearest(P, T, trees, gate, cache)
        _, fresh = _nearest(P, T, trees, gate, _new_cache(len(P)))
        np.testing.assert_array_equal(idx, fresh)
        # brute force over the trees' points: main first, a recent point only if closer
        d_main = np.linalg.norm(X[:, None] - main[None], axis=2)
        d_rec = np.linalg.norm(X[:, None] - recent[None], axis=2)
        jm, jr = d_main.argmin(1), d_rec.argmin(1)
        dm, dr = d_main.min(1), d_rec.min(1)
        ref = np.where(dm < gate, trees[1][jm], -1)
        ref = np.where((dr < gate) & (dr < dm), trees[8][trees[5][jr]], ref)
        np.testing.assert_array_equal(idx, ref)
    assert (cache[3] >= 0).mean() > 0.5  # most points have a neighbour to reuse


def test_relative_state_adaptive_bank_on_a_principal_axis_spin(tumble_run):
    """angular_acceleration="adaptive": on a spin about a fixed axis (ω̇ = 0) the likelihood
    moves the bank towards the members with less angular acceleration than the torque-free
    bound, and the rate is still recovered."""
    from relnav.errors import ConfigError
    from relnav.navigation.state import TORQUE_FREE_SHARES, relative_state

    seq, run = tumble_run
    res = relative_state(run, gt_poses=seq.gt_poses, angular_acceleration="adaptive")
    P = res.model_probability
    assert P.shape == (len(res), len(TORQUE_FREE_SHARES))
    np.testing.assert_allclose(P.sum(axis=1), 1.0)
    assert P[-1, 0] < 0.5  # the bound alone is not the most probable model at the end
    k0 = len(res) // 3
    err = np.degrees(np.linalg.norm(res.errors()["omega"][k0:], axis=1))
    assert np.median(err) < 0.1 and np.max(err) < 0.2
    # no bank without the physics noise: one filter
    one = relative_state(run, process_noise="poses", angular_acceleration="adaptive")
    assert one.model_probability is None
    with pytest.raises(ConfigError):
        relative_state(run, angular_acceleration="fast")
    with pytest.raises(ConfigError):
        relative_state(run, angular_acceleration=-1.0)


def test_relative_state_bank_shares_floor_and_presets(tumble_run):
    """torque_free_shares and bank_floor shape the adaptive bank; a preset expands to its
    options with the caller's winning; bad values and unknown presets are refused."""
    from relnav.errors import ConfigError
    from relnav.navigation.state import (
        STATE_PRESETS,
        check_state_options,
        relative_state,
        state_options,
    )

    seq, run = tumble_run
    res = relative_state(
        run, angular_acceleration="adaptive", torque_free_shares=(1.0, 0.01), bank_floor=0.0
    )
    assert res.model_probability.shape == (len(res), 2)
    assert res.settings["bank"] == ["torque-free bound × 1", "torque-free bound × 0.01"]
    assert res.settings["floor"] == 0.0
    hold = state_options({"preset": "hold-point", "bank_floor": 1e-4})
    assert hold == {**STATE_PRESETS["hold-point"], "bank_floor": 1e-4}
    assert state_options({"drift": "map"}) == {"drift": "map"}
    res = relative_state(run, gt_poses=seq.gt_poses, **state_options({"preset": "hold-point"}))
    assert res.model_probability.shape[1] == 4 and res.settings["floor"] == 1e-5
    assert res.settings["centre_offset"] and res.settings["gate_probability"] == 0.999
    # rigid_body: a spin about a fixed axis reveals no inertia, the first pass stands
    assert res.meta["inertia_identified"] is False and res.settings["inertia"] is None
    k0 = len(res) // 3
    err = np.degrees(np.linalg.norm(res.errors()["omega"][k0:], axis=1))
    assert np.median(err) < 0.1 and np.max(err) < 0.2
    check_state_options({"preset": "hold-point"})
    for bad in (
        {"preset": "orbit"},
        {"torque_free_shares": ()},
        {"torque_free_shares": (1.0, -0.1)},
        {"torque_free_shares": "fast"},
        {"bank_floor": 0.5},
        {"bank_floor": "low"},
        {"rigid_body": True, "filter": "ekf"},
        {"rigid_body": True, "process_noise": "poses"},
    ):
        with pytest.raises(ConfigError):
            check_state_options({"angular_acceleration": "adaptive", **bad})


def test_scale_drift_scales_translation_and_rotation_apart(rng):
    """scale_drift: the translation and rotation variances by their scales, the lever-arm
    correlation by the root of their product; positive semi-definite; scales 1 change nothing."""
    from relnav.navigation.state import scale_drift

    A = rng.normal(size=(6, 6))
    Q = A @ A.T
    S = scale_drift(Q, 0.25, 4.0)
    np.testing.assert_allclose(S[:3, :3], 0.25 * Q[:3, :3])
    np.testing.assert_allclose(S[3:, 3:], 4.0 * Q[3:, 3:])
    np.testing.assert_allclose(S[:3, 3:], Q[:3, 3:])  # √(0.25 · 4) = 1
    assert np.linalg.eigvalsh(S).min() > -1e-9
    np.testing.assert_allclose(scale_drift(Q, 1.0, 1.0), Q)
    np.testing.assert_allclose(scale_drift(Q, 0.0, 0.0), 0.0)


def test_relative_state_noise_scales_on_a_short_run(tumble_run):
    """drift_scale / drift_rotation_scale / measurement_scale: 1 is the default model; a
    smaller drift leaves the bias less freedom (smaller attitude covariance); a smaller
    measurement covariance raises the likelihood of the innovations when the drift explains
    them; bad values are refused."""
    from relnav.errors import ConfigError
    from relnav.navigation.state import StateRecord, relative_state
    from relnav.navigation.state.noise_fit import fit_noise_scales

    seq, run = tumble_run
    steps = [StateRecord.from_step(s) for s in run.steps]
    base = relative_state(run, steps=steps, gt_poses=seq.gt_poses)
    ones = relative_state(
        run,
        steps=steps,
        gt_poses=seq.gt_poses,
        drift_scale=1.0,
        drift_rotation_scale=1.0,
        measurement_scale=1.0,
    )
    np.testing.assert_array_equal(ones.covariance[-1], base.covariance[-1])
    less = relative_state(run, steps=steps, gt_poses=seq.gt_poses, drift_scale=0.1)
    rot = relative_state(run, steps=steps, gt_poses=seq.gt_poses, drift_rotation_scale=0.1)
    for res in (less, rot):
        assert np.trace(res.covariance[-1][6:9, 6:9]) < np.trace(base.covariance[-1][6:9, 6:9])
        k0 = len(res) // 3
        err = np.degrees(np.linalg.norm(res.errors()["omega"][k0:], axis=1))
        assert np.median(err) < 0.1  # the rate is still recovered
    # the measurement scale multiplies the scans' covariances: the innovations change
    half = relative_state(run, steps=steps, measurement_scale=0.5)
    assert np.nansum(half.log_likelihood) != pytest.approx(np.nansum(base.log_likelihood))
    for bad in (
        {"drift_scale": -1.0},
        {"drift_rotation_scale": np.nan},
        {"measurement_scale": 0.0},
    ):
        with pytest.raises(ConfigError):
            relative_state(run, steps=steps, **bad)
    # truth-free identification: the fitted scale is no less likely than the start
    fit = fit_noise_scales([run], names=["measurement_scale"], max_evaluations=8)
    assert set(fit["scales"]) == {"measurement_scale"}
    assert fit["log_likelihood"] >= fit["start_log_likelihood"]
    assert 1e-3 <= fit["scales"]["measurement_scale"] <= 1e3
    with pytest.raises(ConfigError):
        fit_noise_scales([run], names=["drift_scale"], start=[0.0])


def test_startup_bias_sums_the_start_up_steps(rng):
    """startup_bias: the first update takes the sum of the start-up frames' drift (merged
    frames after the first, non-merged ones skipped), block diagonal and positive
    semi-definite; no frames, no covariance."""
    from relnav.navigation.state import StateRecord, drift_covariance, startup_bias

    frames = [StateRecord("first", np.eye(4))]
    for k in range(6):
        A = rng.normal(size=(6, 6)) * 1e-2
        pose = exp_se3(rng.normal(size=6) * 0.3)
        frames.append(StateRecord("failed" if k == 2 else "ok", pose, None, A @ A.T))
    start_up, C = startup_bias(frames, 3)
    assert start_up == [1, 2, 4]
    expected = sum(drift_covariance(frames[k].step_covariance, frames[k].pose) for k in (1, 2, 4))
    np.testing.assert_allclose(C[3:, 3:], expected[3:, 3:], atol=1e-15)
    # the translation blocks summed in target axes, given in the first update's sensor axes
    in_target = sum(
        frames[k].pose[:3, :3]
        @ drift_covariance(frames[k].step_covariance, frames[k].pose)[:3, :3]
        @ frames[k].pose[:3, :3].T
        for k in (1, 2, 4)
    )
    R_st = frames[1].pose[:3, :3].T
    np.testing.assert_allclose(C[:3, :3], R_st @ in_target @ R_st.T, atol=1e-15)
    assert np.trace(C[:3, :3]) == pytest.approx(np.trace(expected[:3, :3]))
    np.testing.assert_array_equal(C[:3, 3:], 0.0)
    assert np.linalg.eigvalsh(C).min() > -1e-15
    # the map's share of the rotation (drift="map") lowers the rotation block
    shared, C_map = startup_bias(frames, 3, np.full(len(frames), 0.5))
    assert shared == start_up and np.trace(C_map[3:, 3:]) < np.trace(C[3:, 3:])
    none, C0 = startup_bias(frames, 0)
    assert none == [] and not C0.any()


def test_relative_state_initial_bias_on_a_short_run(tumble_run):
    """initial_bias=N: the map's offset is uncertain from the first update on (larger attitude
    covariance there than the default's), the rate is still recovered; 0 is the default;
    bad values are refused."""
    from relnav.errors import ConfigError
    from relnav.navigation.state import StateRecord, relative_state

    seq, run = tumble_run
    steps = [StateRecord.from_step(s) for s in run.steps]
    base = relative_state(run, steps=steps, gt_poses=seq.gt_poses)
    zero = relative_state(run, steps=steps, gt_poses=seq.gt_poses, initial_bias=0)
    np.testing.assert_array_equal(zero.covariance[-1], base.covariance[-1])
    start = relative_state(run, steps=steps, gt_poses=seq.gt_poses, initial_bias=5.0)
    k1 = base.status.index("update")  # the first update
    att = slice(6, 9)
    assert np.trace(start.covariance[k1][att, att]) > np.trace(base.covariance[k1][att, att])
    k0 = len(start) // 3
    err = np.degrees(np.linalg.norm(start.errors()["omega"][k0:], axis=1))
    assert np.median(err) < 0.1 and np.max(err) < 0.2
    for bad in (-1, 2.5, True, "startup"):
        with pytest.raises(ConfigError):
            relative_state(run, steps=steps, initial_bias=bad)


def test_map_offset_rotation_is_the_start_up_drifts_largest_axis(rng):
    """map_offset_rotation: the start-up steps' rotation covariances summed, kept along their
    largest axis (rank one, its variance the largest eigenvalue); none without start-up."""
    from relnav.navigation.state import StateRecord, drift_covariance, map_offset_rotation

    frames = [StateRecord("first", np.eye(4))]
    for _ in range(6):
        A = rng.normal(size=(6, 6))
        frames.append(StateRecord("ok", np.eye(4), None, A @ A.T))
    C = map_offset_rotation(frames, 4)
    S = sum(drift_covariance(f.step_covariance, f.pose)[3:, 3:] for f in frames[1:5])
    w, V = np.linalg.eigh(S)
    np.testing.assert_allclose(C, w[-1] * np.outer(V[:, -1], V[:, -1]), atol=1e-12)
    assert np.linalg.matrix_rank(C, tol=1e-12 * w[-1]) == 1
    assert not map_offset_rotation(frames, 0).any()


def test_relative_state_offset_drift_on_a_short_run(tumble_run):
    """drift="offset": the map's rotation offset widens the attitude covariance along the
    start-up's weakest axis at every estimated step, the rate is still recovered, the body
    offset and the Gauss–Markov wander reach the UKF's settings; the options are checked."""
    from relnav.errors import ConfigError
    from relnav.navigation.state import StateRecord, map_offset_rotation, relative_state

    seq, run = tumble_run
    steps = [StateRecord.from_step(s) for s in run.steps]
    res = relative_state(run, steps=steps, gt_poses=seq.gt_poses, drift="offset")
    assert res.settings["centre_offset"] and res.settings["observer_bias"]
    period = float(np.median(np.diff(run.timestamps)))
    np.testing.assert_allclose(res.settings["bias_correlation_time"], [50 * period, 10 * period])
    C = map_offset_rotation(steps, 10)
    u = np.linalg.eigh(C)[1][:, -1]
    live = [k for k in range(len(res)) if np.all(np.isfinite(res.covariance[k]))]
    assert live
    for k in live:
        assert u @ res.covariance[k][6:9, 6:9] @ u >= u @ C @ u * (1 - 1e-9)
        assert np.linalg.eigvalsh(res.covariance[k]).min() > -1e-12
    k0 = len(res) // 3
    err = np.degrees(np.linalg.norm(res.errors()["omega"][k0:], axis=1))
    assert np.median(err) < 0.1 and np.max(err) < 0.2
    no_offset = relative_state(run, steps=steps, drift="offset", offset_frames=0)
    assert no_offset.settings["centre_offset"]
    for bad in (
        {"filter": "ekf"},
        {"offset_frames": -1},
        {"offset_frames": 2.5},
        {"wander_frames": 0.0},
        {"wander_rotation_frames": -3.0},
        {"initial_bias": 5},
    ):
        with pytest.raises(ConfigError):
            relative_state(run, steps=steps, drift="offset", **bad)


def test_flat_option_names_of_the_last_release_still_work_with_a_warning():
    """``-O init_window=4`` (the flat name of the last release) is ``startup.window=4``, with a
    deprecation message naming the new name; a dotted key and a nested mapping are the same."""
    from relnav.navigation.options import navigator_config

    with pytest.warns(FutureWarning) as caught:
        legacy = navigator_config({"init_window": 4, "orbit_mean_motion": 1e-3})
    said = [str(w.message) for w in caught]
    assert any("'init_window' is now 'startup.window'" in m for m in said)
    assert any("'orbit_mean_motion' is now 'orbit.mean_motion'" in m for m in said)
    dotted = navigator_config({"startup.window": 4, "orbit.mean_motion": 1e-3})
    nested = navigator_config({"startup": {"window": 4}, "orbit": {"mean_motion": 1e-3}})
    assert legacy == dotted == nested
    assert dotted.startup.window == 4 and dotted.reloc == navigator_config().reloc


def test_relnav_methods_lists_every_navigator_option_with_its_range():
    """``relnav methods`` shows each ``section.key`` of the navigator with its default, range
    and one line (the same fields the options are validated with)."""
    from rich.console import Console

    from relnav.cli.methods import navigator_options_table
    from relnav.navigation.options import SECTIONS

    console = Console(width=250, record=True)
    console.print(navigator_options_table())
    text = console.export_text()
    n_fields = sum(len(m.model_fields) for m in SECTIONS.values())
    rows = [line for line in text.splitlines() if line.startswith("│ ") and "." in line[:30]]
    assert len(rows) == n_fields
    row = next(line for line in rows if "solver.min_overlap" in line)
    assert ">= 0 and <= 1" in row and "0.3" in row


def test_cli_says_a_flat_option_name_is_deprecated_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from relnav.cli.main import app
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    seq = tmp_path / "seq"
    simulate(get_preset("sim-voyager", max_frames=4, seed=1), seq)
    args = ["odometry", str(seq), "--no-state", "-O", "init_window=0", "--out", str(tmp_path / "r")]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert "warning: method 'relnav': option 'init_window' is now 'startup.window'" in text
    assert "options.py" not in text  # the message, not a source location
