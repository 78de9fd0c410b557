"""Known-answer, invariance and evo-oracle tests of relnav.eval.metrics (+ plots smoke tests)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from relnav.errors import EstimationError, InputError
from relnav.eval.metrics import (
    METRIC_DOCS,
    METRIC_KEYS,
    STAT_NAMES,
    align_trajectory,
    associate,
    compute_metrics,
    evaluate_trajectories,
    match_trajectories,
    metric_units,
    pose_errors,
    relative_pose_errors,
)
from relnav.geometry.se3 import exp_se3, from_rt, random_transform

TOL = 1e-12


def line_traj(n: int = 11, step: float = 1.0) -> np.ndarray:
    """Straight line along x, identity attitude: T_k = [I, (k*step, 0, 0)]."""
    P = np.repeat(np.eye(4)[None], n, axis=0)
    P[:, 0, 3] = step * np.arange(n)
    return P


def smooth_traj(rng: np.random.Generator, n: int = 40) -> np.ndarray:
    """A curved, tumbling trajectory built from random small twists."""
    P = [np.eye(4)]
    for _ in range(n - 1):
        xi = np.concatenate([rng.normal(0.3, 0.1, 3), rng.normal(0.0, 0.05, 3)])
        P.append(P[-1] @ exp_se3(xi))
    return np.stack(P)


def perturb(rng: np.random.Generator, P: np.ndarray, sig_t: float, sig_r: float) -> np.ndarray:
    out = P.copy()
    for k in range(len(P)):
        xi = np.concatenate([rng.normal(0, sig_t, 3), rng.normal(0, sig_r, 3)])
        out[k] = P[k] @ exp_se3(xi)
    return out


# ------------------------------------------------------------------------------------------
# known answers
# ------------------------------------------------------------------------------------------


def test_identical_trajectories_give_zero_everywhere(rng: np.random.Generator) -> None:
    P = smooth_traj(rng)
    m = compute_metrics(P, P.copy())
    for key in METRIC_KEYS:
        assert key in m
    zero_keys = [k for k in METRIC_KEYS if k.startswith(("e_", "ape_", "rpe_t", "rpe_r", "drift"))]
    for k in [*zero_keys, "T_error_pct"]:
        assert abs(m[k]) < 1e-9, (k, m[k])
    assert m["n_frames"] == len(P)
    assert np.isnan(m["time_ms"]) and np.isnan(m["duration_s"])


def test_constant_offset_gives_known_translation_errors() -> None:
    gt = line_traj(11)
    est = gt.copy()
    est[:, 1, 3] += 0.1
    m = compute_metrics(est, gt)
    for k in ("e_T_avg", "e_T_max", "drift", "e_y_max", "e_y_avg", "ape_trans_rmse"):
        assert m[k] == pytest.approx(0.1, abs=TOL), k
    for k in ("e_x_max", "e_x_avg", "e_z_max", "e_z_avg", "e_R_avg", "e_R_max"):
        assert m[k] == pytest.approx(0.0, abs=TOL), k
    assert m["path_length"] == pytest.approx(10.0, abs=TOL)
    assert m["T_error_pct"] == pytest.approx(1.0, abs=1e-10)
    # a constant world-frame offset with fixed attitude leaves every relative motion exact
    assert m["rpe_trans_rmse"] == pytest.approx(0.0, abs=TOL)
    assert m["e_RT"] == pytest.approx(0.0, abs=TOL)


def test_per_axis_errors() -> None:
    gt = line_traj(6)
    est = gt.copy()
    est[:, :3, 3] -= np.array([0.1, -0.2, 0.3])  # Δ = t_gt − t_est = (0.1, −0.2, 0.3)
    est[3, :3, 3] -= np.array([0.5, 0.0, 0.0])  # one frame with a larger x error
    m = compute_metrics(est, gt)
    assert m["e_x_max"] == pytest.approx(0.6, abs=TOL)
    assert m["e_x_avg"] == pytest.approx((5 * 0.1 + 0.6) / 6, abs=TOL)
    assert m["e_y_max"] == pytest.approx(0.2, abs=TOL)
    assert m["e_y_avg"] == pytest.approx(0.2, abs=TOL)
    assert m["e_z_max"] == pytest.approx(0.3, abs=TOL)
    assert m["e_z_avg"] == pytest.approx(0.3, abs=TOL)
    n_small, n_big = np.sqrt(0.14), np.sqrt(0.36 + 0.04 + 0.09)
    assert m["e_T_max"] == pytest.approx(n_big, abs=TOL)
    assert m["e_T_avg"] == pytest.approx(np.sqrt((5 * n_small**2 + n_big**2) / 6), abs=TOL)
    pe = pose_errors(est, gt)
    np.testing.assert_allclose(pe.delta[0], [0.1, -0.2, 0.3], atol=TOL)


def test_drift_and_translation_error_percentage() -> None:
    gt = line_traj(11)  # 10 m
    est = gt.copy()
    est[:, 2, 3] = 0.05 * np.arange(11)  # error grows linearly to 0.5 m at the end
    m = compute_metrics(est, gt)
    assert m["drift"] == pytest.approx(0.5, abs=TOL)
    assert m["T_error_pct"] == pytest.approx(5.0, abs=1e-10)
    assert m["e_T_max"] == pytest.approx(0.5, abs=TOL)
    assert m["e_z_avg"] == pytest.approx(0.25, abs=TOL)
    assert m["e_T_avg"] == pytest.approx(np.sqrt(np.mean((0.05 * np.arange(11)) ** 2)), abs=TOL)
    # every step has the same 0.05 m vertical error
    assert m["rpe_trans_rmse"] == pytest.approx(0.05, abs=TOL)
    assert m["e_RT_trans"] == pytest.approx(0.05**2, abs=TOL)


def test_constant_yaw_error_of_two_degrees() -> None:
    gt = line_traj(11)
    est = gt.copy()
    est[:, :3, :3] = Rotation.from_euler("z", 2.0, degrees=True).as_matrix()
    m = compute_metrics(est, gt)
    assert m["e_R_avg"] == pytest.approx(2.0, abs=1e-10)
    assert m["e_R_max"] == pytest.approx(2.0, abs=1e-10)
    assert m["ape_rot_rmse_deg"] == pytest.approx(2.0, abs=1e-10)
    assert m["e_T_avg"] == pytest.approx(0.0, abs=TOL)
    # the 1 m step is seen rotated by 2° in the estimate's body frame: |R(−2°) d − d| = 2 sin 1°
    assert m["rpe_trans_rmse"] == pytest.approx(2 * np.sin(np.radians(1.0)), abs=TOL)
    assert m["rpe_rot_rmse_deg"] == pytest.approx(0.0, abs=1e-9)
    # legacy signed Euler reading: mean(0,0,0) − mean(0,0,2) = −2/3
    assert m["e_R_euler_avg"] == pytest.approx(2 / 3, abs=1e-10)
    assert m["e_R_euler_max"] == pytest.approx(-2 / 3, abs=1e-10)
    legacy = compute_metrics(est, gt, rotation_error="euler_mean_diff")
    assert legacy["e_R_avg"] == pytest.approx(2 / 3, abs=1e-10)
    assert legacy["e_R_max"] == pytest.approx(-2 / 3, abs=1e-10)
    assert legacy["ape_rot_rmse_deg"] == pytest.approx(2.0, abs=1e-10)


def test_e_rt_combines_rpe_components_and_unit_option(rng: np.random.Generator) -> None:
    gt = smooth_traj(rng, 30)
    est = perturb(rng, gt, 0.02, 0.01)
    m = compute_metrics(est, gt)
    assert m["e_RT"] == pytest.approx(m["rpe_trans_rmse"] ** 2 + m["rpe_rot_rmse_deg"] ** 2)
    assert m["e_RT"] == pytest.approx(m["e_RT_trans"] + m["e_RT_rot"])
    mr = compute_metrics(est, gt, e_rt_rot_unit="rad")
    assert mr["e_RT_rot"] == pytest.approx(m["e_RT_rot"] * np.radians(1.0) ** 2)
    assert mr["e_RT_trans"] == m["e_RT_trans"]
    # e^RT stays consecutive-frame when the RPE delta changes
    m3 = compute_metrics(est, gt, delta=3)
    assert m3["e_RT"] == m["e_RT"] and m3["rpe_delta"] == 3.0
    assert m3["rpe_trans_rmse"] != pytest.approx(m["rpe_trans_rmse"])
    assert metric_units("rad")["e_RT_rot"] == "rad²"


def test_rotation_angle_near_pi_and_tiny() -> None:
    gt = line_traj(3)
    for ang in (1e-7, 179.9999):
        est = gt.copy()
        est[:, :3, :3] = Rotation.from_rotvec(
            np.radians(ang) * np.array([0.0, 0.6, 0.8])
        ).as_matrix()
        assert compute_metrics(est, gt)["e_R_max"] == pytest.approx(ang, rel=1e-7)


def test_metrics_invariant_to_a_common_change_of_world_frame(rng: np.random.Generator) -> None:
    gt = smooth_traj(rng, 25)
    est = perturb(rng, gt, 0.05, 0.02)
    T = random_transform(rng, 5.0)
    a = compute_metrics(est, gt)
    b = compute_metrics(T @ est, T @ gt)
    for k in ("e_T_avg", "e_T_max", "drift", "e_R_avg", "e_RT", "rpe_trans_rmse", "path_length"):
        assert b[k] == pytest.approx(a[k], rel=1e-9, abs=1e-12), k


def test_timing_and_duration() -> None:
    gt = line_traj(4)
    m = compute_metrics(
        gt, gt, times=np.array([1.0, 1.1, 1.2, 1.5]), frame_time_s=[0.1, 0.2, 0.3, 0.4]
    )
    assert m["time_ms"] == pytest.approx(250.0)
    assert m["duration_s"] == pytest.approx(0.5)
    assert compute_metrics(gt, gt, frame_time_s=0.02)["time_ms"] == pytest.approx(20.0)


def test_zero_path_length_gives_nan_percentage() -> None:
    gt = np.repeat(np.eye(4)[None], 3, axis=0)
    est = gt.copy()
    est[:, 0, 3] = 0.1
    m = compute_metrics(est, gt)
    assert np.isnan(m["T_error_pct"]) and m["drift"] == pytest.approx(0.1)


@pytest.mark.parametrize(
    ("est", "gt", "match"),
    [
        (np.zeros((3, 4, 4)), line_traj(3), "not a rigid transform"),
        (line_traj(3), line_traj(4), "differ in length"),
        (line_traj(1), line_traj(1), "at least 2"),
        (line_traj(3)[:, :3], line_traj(3), "shape"),
    ],
)
def test_bad_poses_raise_input_error(est: np.ndarray, gt: np.ndarray, match: str) -> None:
    with pytest.raises(InputError, match=match):
        compute_metrics(est, gt)


def test_bad_options_raise_input_error() -> None:
    P = line_traj(3)
    nanP = P.copy()
    nanP[1, 0, 3] = np.nan
    with pytest.raises(InputError, match="pose 1"):
        compute_metrics(nanP, P)
    with pytest.raises(InputError, match="delta"):
        compute_metrics(P, P, delta=3)
    with pytest.raises(InputError, match="delta"):
        compute_metrics(P, P, delta=0)
    with pytest.raises(InputError, match="rotation_error"):
        compute_metrics(P, P, rotation_error="quat")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="frame_time_s"):
        compute_metrics(P, P, frame_time_s=[1.0, 2.0])
    with pytest.raises(InputError, match="times"):
        compute_metrics(P, P, times=[0.0, 1.0])


# ------------------------------------------------------------------------------------------
# association and alignment
# ------------------------------------------------------------------------------------------


def test_associate_shifted_and_missing_timestamps() -> None:
    t_gt = np.arange(10) * 0.1
    t_est = np.delete(t_gt, [2, 7]) + 0.004  # two frames missing, 4 ms late
    ie, ig = associate(t_est, t_gt, max_diff=0.01)
    np.testing.assert_array_equal(ie, np.arange(8))
    np.testing.assert_array_equal(ig, [0, 1, 3, 4, 5, 6, 8, 9])
    # the same with the lateness removed by the offset and a tight window
    _ie2, ig2 = associate(t_est, t_gt, max_diff=1e-9, offset=-0.004)
    np.testing.assert_array_equal(ig2, ig)
    # too tight without the offset: nothing matches
    assert associate(t_est, t_gt, max_diff=0.001)[0].size == 0


def test_associate_is_one_to_one_and_order_independent(rng: np.random.Generator) -> None:
    t_gt = np.array([0.0, 1.0, 2.0])
    t_est = np.array([0.995, 1.002, 2.0])  # two estimates compete for gt 1.0
    ie, ig = associate(t_est, t_gt, max_diff=0.01)
    np.testing.assert_array_equal(ie, [1, 2])  # the closer one (2 ms) wins
    np.testing.assert_array_equal(ig, [1, 2])
    # unsorted inputs give the same pairs
    pe, pg = rng.permutation(3), rng.permutation(3)
    ie3, ig3 = associate(t_est[pe], t_gt[pg], max_diff=0.01)
    pairs = {(int(pe[i]), int(pg[j])) for i, j in zip(ie3, ig3, strict=True)}
    assert pairs == {(1, 1), (2, 2)}


def test_associate_rejects_bad_input() -> None:
    with pytest.raises(InputError, match="max_diff"):
        associate([0.0], [0.0], max_diff=-1.0)
    with pytest.raises(InputError, match="non-finite"):
        associate([np.nan], [0.0])
    assert associate([], [0.0])[0].size == 0


def test_too_few_matches_raise_estimation_error_with_counts() -> None:
    P = line_traj(5)
    t_gt = np.arange(5.0)
    t_est = np.array([0.0, 10.0, 11.0, 12.0, 13.0])
    with pytest.raises(EstimationError, match=r"only 1 of 5 estimated poses matched"):
        evaluate_trajectories(t_est, P, t_gt, P, max_diff=0.01)
    with pytest.raises(EstimationError, match=r"only 0 of 5"):
        evaluate_trajectories(t_est + 100, P, t_gt, P)
    with pytest.raises(InputError, match="stamps"):
        evaluate_trajectories(t_gt[:4], P, t_gt, P)


def test_evaluate_with_alignment_recovers_zero_error(rng: np.random.Generator) -> None:
    gt = smooth_traj(rng, 20)
    T = random_transform(rng, 3.0)
    est = T @ gt  # the same motion expressed in another world frame
    t = np.linspace(0.0, 2.0, 20)
    raw = evaluate_trajectories(t, est, t, gt)
    assert raw["e_T_avg"] > 0.1
    # relative errors do not care about the world frame
    assert raw["rpe_trans_rmse"] < 1e-9 and raw["e_RT"] < 1e-12
    for align in ("first", "se3", "sim3"):
        m = evaluate_trajectories(t, est, t, gt, align=align)
        assert m["e_T_max"] < 1e-9 and m["e_R_max"] < 1e-6, align
        assert m["align"] == align and m["n_matched"] == 20
    _aligned, T_al = align_trajectory(est, gt, "se3")
    np.testing.assert_allclose(T_al @ T, np.eye(4), atol=1e-9)
    with pytest.raises(InputError, match="alignment"):
        align_trajectory(est, gt, "affine")  # type: ignore[arg-type]


def test_evaluate_subsets_frame_times_by_matches() -> None:
    P = line_traj(4)
    t = np.arange(4.0)
    m = evaluate_trajectories(t, P, t[:3], P[:3], frame_time_s=np.array([0.1, 0.1, 0.1, 10.0]))
    assert m["n_matched"] == 3 and m["n_est"] == 4 and m["n_gt"] == 3
    assert m["time_ms"] == pytest.approx(100.0)
    mt = match_trajectories(t, P, t[:3], P[:3])
    np.testing.assert_array_equal(mt.idx_gt, [0, 1, 2])


# ------------------------------------------------------------------------------------------
# evo oracle (same TUM files)
# ------------------------------------------------------------------------------------------


def _write_tum(path: Path, t: np.ndarray, P: np.ndarray) -> None:
    q = Rotation.from_matrix(P[:, :3, :3]).as_quat()  # x y z w
    np.savetxt(path, np.column_stack([t, P[:, :3, 3], q]), fmt="%.9f", header="t x y z qx qy qz qw")


def _read_tum(path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        from relnav.io.trajectories import read_tum
    except ImportError:  # helper A's reader not there yet: plain NumPy
        d = np.loadtxt(path, comments="#", ndmin=2)
        P = np.repeat(np.eye(4)[None], len(d), axis=0)
        P[:, :3, 3] = d[:, 1:4]
        P[:, :3, :3] = Rotation.from_quat(d[:, 4:8]).as_matrix()
        return d[:, 0], P
    return read_tum(path)


@pytest.mark.parametrize(("delta", "all_pairs"), [(1, False), (3, False), (3, True)])
def test_rpe_and_ape_equal_evo_on_the_same_tum_files(
    tmp_path: Path, rng: np.random.Generator, delta: int, all_pairs: bool
) -> None:
    evo_metrics = pytest.importorskip("evo.core.metrics")
    from evo.tools import file_interface

    gt = smooth_traj(rng, 60)
    est = perturb(rng, gt, 0.03, 0.02)
    t = 100.0 + 0.1 * np.arange(60)
    _write_tum(tmp_path / "gt.tum", t, gt)
    _write_tum(tmp_path / "est.tum", t, est)
    traj_ref = file_interface.read_tum_trajectory_file(str(tmp_path / "gt.tum"))
    traj_est = file_interface.read_tum_trajectory_file(str(tmp_path / "est.tum"))
    t_e, P_e = _read_tum(tmp_path / "est.tum")
    t_g, P_g = _read_tum(tmp_path / "gt.tum")
    ours = evaluate_trajectories(t_e, P_e, t_g, P_g, delta=delta, rpe_all_pairs=all_pairs)

    def evo_rmse(metric: object) -> float:
        metric.process_data((traj_ref, traj_est))  # type: ignore[attr-defined]
        return float(metric.get_statistic(evo_metrics.StatisticsType.rmse))  # type: ignore[attr-defined]

    PR, U = evo_metrics.PoseRelation, evo_metrics.Unit
    rpe_t = evo_rmse(evo_metrics.RPE(PR.translation_part, delta, U.frames, all_pairs=all_pairs))
    rpe_r = evo_rmse(evo_metrics.RPE(PR.rotation_angle_deg, delta, U.frames, all_pairs=all_pairs))
    ape_t = evo_rmse(evo_metrics.APE(PR.translation_part))
    ape_r = evo_rmse(evo_metrics.APE(PR.rotation_angle_deg))
    assert ours["rpe_trans_rmse"] == pytest.approx(rpe_t, abs=1e-9)
    assert ours["rpe_rot_rmse_deg"] == pytest.approx(rpe_r, abs=1e-9)
    assert ours["ape_trans_rmse"] == pytest.approx(ape_t, abs=1e-9)
    assert ours["ape_rot_rmse_deg"] == pytest.approx(ape_r, abs=1e-9)
    assert ours["e_T_avg"] == pytest.approx(ape_t, abs=1e-9)
    assert rpe_t > 1e-3 and ape_r > 0.1  # non-trivial errors were compared

    # SE(3) Umeyama alignment agrees with evo's align()
    traj_est.align(traj_ref, correct_scale=False)
    ape_t_aligned = evo_rmse(evo_metrics.APE(PR.translation_part))
    ours_se3 = evaluate_trajectories(t_e, P_e, t_g, P_g, align="se3")
    assert ours_se3["ape_trans_rmse"] == pytest.approx(ape_t_aligned, abs=1e-9)


def test_relative_pose_errors_shapes() -> None:
    P = line_traj(5)
    tr, rot = relative_pose_errors(P, P, delta=2)
    assert tr.shape == rot.shape == (2,)  # pairs (0, 2), (2, 4) as in evo
    tr, rot = relative_pose_errors(P, P, delta=2, all_pairs=True)
    assert tr.shape == rot.shape == (3,)
    with pytest.raises(InputError):
        relative_pose_errors(P, P, delta=5)


# ------------------------------------------------------------------------------------------
# plots (smoke)
# ------------------------------------------------------------------------------------------


def test_plots_write_png_files(tmp_path: Path, rng: np.random.Generator) -> None:
    import matplotlib

    from relnav.eval.plots import plot_errors, plot_trajectories

    backend = matplotlib.get_backend()
    gt = smooth_traj(rng, 15)
    est = {"noisy": perturb(rng, gt, 0.05, 0.01), "offset": gt @ from_rt(t=[0.1, 0.0, 0.0])}
    p1 = plot_trajectories(tmp_path / "sub" / "traj.png", gt, est, title="test")
    p2 = plot_errors(tmp_path / "err.png", gt, est, times=np.linspace(0, 1.4, 15))
    for p in (p1, p2):
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    assert matplotlib.get_backend() == backend  # no global backend switch
    with pytest.raises(InputError, match="associate them first"):
        plot_errors(tmp_path / "bad.png", gt, {"short": gt[:5]})
    with pytest.raises(InputError, match="PNG"):
        plot_trajectories(tmp_path / "x.pdf", gt, est)


@pytest.mark.parametrize(
    ("delta", "unit", "all_pairs"),
    [(2, "frames", False), (1.5, "m", False), (1.5, "m", True), (4.0, "deg", False)],
)
@pytest.mark.parametrize("align", ["none", "sim3"])
def test_every_evo_statistic_delta_unit_and_sim3_equal_evo(
    tmp_path: Path, rng: np.random.Generator, delta: float, unit: str, all_pairs: bool, align: str
) -> None:
    """All seven statistics under evo's names, RPE delta in m/deg, sim3 (scale) alignment."""
    evo_metrics = pytest.importorskip("evo.core.metrics")
    from evo.tools import file_interface

    gt = smooth_traj(rng, 50)
    est = perturb(rng, gt, 0.03, 0.02)
    est[:, :3, 3] *= 0.8  # a scale error only sim3 can remove
    t = 10.0 + 0.1 * np.arange(50)
    _write_tum(tmp_path / "gt.tum", t, gt)
    _write_tum(tmp_path / "est.tum", t, est)
    ref = file_interface.read_tum_trajectory_file(str(tmp_path / "gt.tum"))
    traj = file_interface.read_tum_trajectory_file(str(tmp_path / "est.tum"))
    if align == "sim3":
        traj.align(ref, correct_scale=True)
    t_e, P_e = _read_tum(tmp_path / "est.tum")
    t_g, P_g = _read_tum(tmp_path / "gt.tum")
    ours = evaluate_trajectories(
        t_e, P_e, t_g, P_g, align=align, delta=delta, delta_unit=unit, rpe_all_pairs=all_pairs
    )
    PR, U = evo_metrics.PoseRelation, evo_metrics.Unit
    evo_unit = {"frames": U.frames, "m": U.meters, "deg": U.degrees}[unit]
    for key, metric in (
        ("ape_trans", evo_metrics.APE(PR.translation_part)),
        ("ape_rot", evo_metrics.APE(PR.rotation_angle_deg)),
        ("rpe_trans", evo_metrics.RPE(PR.translation_part, delta, evo_unit, all_pairs=all_pairs)),
        ("rpe_rot", evo_metrics.RPE(PR.rotation_angle_deg, delta, evo_unit, all_pairs=all_pairs)),
    ):
        metric.process_data((ref, traj))
        stats = metric.get_all_statistics()
        assert set(stats) == set(STAT_NAMES)
        for stat, value in stats.items():
            assert ours[f"{key}_{stat}"] == pytest.approx(value, rel=1e-9, abs=1e-9), (key, stat)
    # deprecated aliases still present and equal
    assert ours["rpe_rot_rmse_deg"] == ours["rpe_rot_rmse"]
    if align == "sim3":
        assert ours["align_scale"] == pytest.approx(1.25, rel=0.05)
        assert ours["ape_trans_rmse"] < 0.2  # the 20 % scale error is gone


def test_metric_docs_name_every_key_once(rng: np.random.Generator) -> None:
    gt = smooth_traj(rng, 10)
    m = compute_metrics(perturb(rng, gt, 0.01, 0.01), gt)
    assert set(m) == set(METRIC_DOCS)
    assert m["e_T_avg"] == m["ape_trans_rmse"] and m["e_T_max"] == m["ape_trans_max"]
    assert m["e_R_euler_peak"] == m["e_R_euler_max"]
    assert METRIC_DOCS["e_R_euler_max"][1] == "deprecated"
