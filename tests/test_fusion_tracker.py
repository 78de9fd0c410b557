"""Tracker: predict-through of missing/bad observations, sequence folders, ``relnav track``."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from relnav.errors import ConfigError, InputError
from relnav.filtering.tracker import Observation, Tracker
from relnav.filtering.ukf import ProcessNoise
from relnav.fusion.observers import simulate_observations
from relnav.fusion.tracker import track_sequence
from relnav.geometry.rotations import euler_to_matrix
from relnav.geometry.se3 import from_rt, invert, transform_points

Q_RIGID = ProcessNoise(position=1e-6, velocity=1e-7, attitude=1e-6, omega=1e-7)


@pytest.mark.parametrize("filt", ["ukf", "ekf"])
def test_missing_observations_are_predicted_through(filt: str) -> None:
    gap = list(range(20, 26))
    times, obs, truth = simulate_observations(50, 4.5, missing=gap, seed=4)
    res = Tracker(filt, q=Q_RIGID).run(times, obs, truth=truth)
    assert [res.status[k] for k in gap] == ["predict"] * len(gap)
    assert res.n_predicted == len(gap) and res.n_flagged == 0
    sig = res.sigma()["attitude"][:, 2]
    assert np.all(np.diff(sig[19:26]) > 0)  # uncertainty grows while predicting
    assert sig[27] < sig[25]  # and shrinks with the next update
    err = res.errors()["attitude"]
    sig_all = res.sigma()["attitude"]
    # predicting through 6 frames (135° of spin): errors stay within the filter's 3σ
    assert np.all(np.abs(err[gap]) < 3 * sig_all[gap])
    assert np.degrees(np.abs(err[gap])).max() < 1.5
    assert np.degrees(np.abs(err[40:])).max() < 1.5
    # the consistency samples: NIS at the updates, NEES at every step after the first
    assert res.updated.sum() == 50 - 1 - len(gap) and not res.updated[gap].any()
    assert res.estimated.sum() == 49 and not res.estimated[0] and res.estimated[gap].all()


def test_nan_observation_is_flagged_and_equals_prediction() -> None:
    times, obs, _ = simulate_observations(30, 4.5, seed=5)
    bad = list(obs)
    bad[10] = Observation(np.array([np.nan, 0.0, 3.0]), np.array([0.0, 0.0, 0.0, 1.0]))
    none = list(obs)
    none[10] = None
    r_bad = Tracker("ukf").run(times, bad)
    r_none = Tracker("ukf").run(times, none)
    assert r_bad.status[10] == "flagged: non-finite observation"
    assert r_bad.n_flagged == 1
    assert all(s == "update" for s in r_bad.status[11:])
    np.testing.assert_array_equal(r_bad.quat, r_none.quat)
    np.testing.assert_array_equal(r_bad.covariance, r_none.covariance)


def test_bad_times_quality_and_waiting() -> None:
    times, obs, truth = simulate_observations(20, 4.5, seed=6)
    obs = list(obs)
    obs[0] = obs[1] = None
    obs[5] = Observation(obs[5].position, obs[5].quat_xyzw, quality=0.1)
    times = times.copy()
    times[8] = times[7] - 1.0  # goes back in time
    res = Tracker("ukf", min_quality=0.5).run(times, obs, truth=truth)
    assert res.status[:3] == ["waiting", "waiting", "init"]
    assert np.isnan(res.position[:2]).all() and np.isfinite(res.position[2]).all()
    assert res.status[5].startswith("flagged: quality")
    assert res.status[8].startswith("flagged: time")
    assert res.status[9] == "update"
    assert res.n_flagged == 2
    # a waiting step's NaN rows are skipped by the summary
    assert np.isfinite(res.summary(skip=0)["attitude"]["rms"]).all()


def test_run_input_errors() -> None:
    times, obs, _ = simulate_observations(5, 4.5, seed=0)
    with pytest.raises(InputError):
        Tracker("ukf").run(times[:4], obs)
    with pytest.raises(ConfigError):
        Tracker("pf")
    with pytest.raises(ConfigError):
        Tracker("ukf", n_mean_motion=1e-3, orbit_radius_m=7e6)
    with pytest.raises(ConfigError):
        Tracker("ukf", not_an_option=1)
    with pytest.raises(InputError):
        Observation(np.zeros(2), np.zeros(4))


def test_track_result_csv_and_summary(tmp_path: Path) -> None:
    times, obs, truth = simulate_observations(25, 4.5, seed=8)
    res = Tracker("ekf", q=Q_RIGID).run(times, obs, truth=truth)
    p = res.to_csv(tmp_path / "t.csv")
    rows = list(csv.DictReader(p.open()))
    assert len(rows) == 25
    for key in ("px", "vx", "yaw", "wz", "sigma_att_z", "sigma_wz", "true_yaw", "err_att_z"):
        assert key in rows[0]
    # yaw grows 22.5° per frame (unwrapped), ω in deg/s
    yaw = np.array([float(r["true_yaw"]) for r in rows])
    np.testing.assert_allclose(np.diff(yaw), 22.5, atol=1e-9)
    assert float(rows[-1]["wz"]) == pytest.approx(5.0, abs=0.1)
    s = res.summary()
    assert set(s) == {"position", "velocity", "attitude", "euler", "omega", "omega_sensor"}
    # small attitude errors: Euler-angle differences ≈ body-axis errors
    np.testing.assert_allclose(s["euler"]["rms"], s["attitude"]["rms"], atol=0.05)


# --------------------------------------------------------------------------------------------
# sequence folders
# --------------------------------------------------------------------------------------------


def _box_surface(rng: np.random.Generator, n: int, size: tuple[float, float, float]) -> np.ndarray:
    """Points on the surface of a box with a panel (asymmetric), centred at the origin."""
    pts = rng.uniform(-0.5, 0.5, size=(n, 3)) * size
    face = rng.integers(0, 3, n)
    sign = rng.choice([-0.5, 0.5], n)
    pts[np.arange(n), face] = sign * np.asarray(size)[face]
    panel = np.c_[rng.uniform(0.3, 0.9, n // 4), rng.uniform(-0.1, 0.1, n // 4), np.zeros(n // 4)]
    panel[:, 0] += size[0] / 2
    return np.vstack([pts, panel])


def _write_spin_sequence(folder: Path, frames: int = 10, drop_lidar: int | None = 6) -> None:
    from relnav.io.sequences import write_sequence

    rng = np.random.default_rng(0)
    body = _box_surface(rng, 1500, (0.6, 0.4, 0.3))
    # spin about the centroid: the observers' reference point (first scan's centroid) is then
    # on the spin axis, where Paper 2's translational model (CW, no rotation coupling) holds
    body -= body.mean(axis=0)
    T_W_cam = from_rt(None, [-3.0, 0.0, 0.0])  # camera 3 m behind the target, looking +x
    T_cam_lidar = from_rt(euler_to_matrix([0.0, 0.0, 0.05]), [0.0, -0.2, 0.0])
    times = np.arange(frames) * 4.5
    cam_scans, lid_scans, gt_c, gt_l = [], [], [], []
    for t in times:
        T_W_target = from_rt(euler_to_matrix([0.0, 0.0, math.radians(5.0 * t)]), None)
        T_target_cam = invert(T_W_target) @ T_W_cam
        pts_cam = transform_points(invert(T_target_cam), body)  # whole surface: exact ICP
        cam_scans.append(pts_cam + rng.normal(scale=1e-3, size=pts_cam.shape))
        T_target_lidar = T_target_cam @ T_cam_lidar
        lid = transform_points(invert(T_target_lidar), body[::5])
        lid_scans.append(lid)
        gt_c.append(T_target_cam)
        gt_l.append(T_target_lidar)
    write_sequence(folder, cam_scans, times, gt_poses=np.array(gt_c), fmt="npy")
    keep = [k for k in range(frames) if k != drop_lidar]
    write_sequence(
        folder,
        [lid_scans[k] for k in keep],
        times[keep],
        gt_poses=np.array(gt_l)[keep],
        sensor="lidar",
        fmt="npy",
    )


def test_track_sequence_registration_observer(tmp_path: Path) -> None:
    _write_spin_sequence(tmp_path / "seq", frames=10, drop_lidar=6)
    res = track_sequence(
        tmp_path / "seq",
        filter="ukf",
        observer="registration",
        omega0=np.radians([0.0, 0.0, 5.0]),  # Paper 2 Table 3 initial rate
        q=Q_RIGID,
        r={"position": 0.005, "attitude": math.radians(0.5)},
    )
    assert res.status[6] == "flagged: missing scan"  # no LIDAR scan for frame 6
    assert res.n_flagged == 1
    assert res.meta["second_sensor"] == "lidar" and res.truth is not None
    s = res.summary(skip=3)
    assert np.all(np.array(s["attitude"]["max"]) < 1.0), s["attitude"]
    assert np.all(np.array(s["omega"]["max"]) < 0.2), s["omega"]
    assert np.all(np.array(s["position"]["max"]) < 0.02), s["position"]
    # camera only: the missing LIDAR scan no longer matters
    res2 = track_sequence(tmp_path / "seq", observer="registration", second_sensor=None, q=Q_RIGID)
    assert res2.n_flagged == 0


def test_track_sequence_keeps_an_explicit_init(tmp_path: Path) -> None:
    """Without ``omega0`` the rate is taken from the first two observations by default
    (``init="rate"``), but a caller's ``init="first"`` is kept (the filter starts at the
    first frame at rest and learns the rate from the updates)."""
    _write_spin_sequence(tmp_path / "seq", frames=4, drop_lidar=None)
    default = track_sequence(
        tmp_path / "seq", observer="registration", second_sensor=None, q=Q_RIGID
    )
    first = track_sequence(
        tmp_path / "seq", observer="registration", second_sensor=None, q=Q_RIGID, init="first"
    )
    # the spin is 5 deg/s about z: "rate" has it at the second frame, "first" still lags
    assert abs(math.degrees(default.omega[1, 2]) - 5.0) < 0.5
    assert math.degrees(first.omega[1, 2]) < 4.0


def test_track_sequence_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError):
        track_sequence(tmp_path / "nothing")
    _write_spin_sequence(tmp_path / "seq", frames=3, drop_lidar=None)
    with pytest.raises(InputError):
        track_sequence(tmp_path / "seq", second_sensor="kinect2")
    with pytest.raises(ConfigError):
        track_sequence(tmp_path / "seq", observer="magic")


def test_cli_track_smoke(tmp_path: Path) -> None:
    import typer
    from typer.testing import CliRunner

    from relnav.cli import track as track_cmd

    _write_spin_sequence(tmp_path / "seq", frames=6, drop_lidar=None)
    app = typer.Typer()
    track_cmd.register(app)
    app.command("noop")(lambda: None)  # keep "track" as a sub-command
    out = tmp_path / "out"
    args = ["track", str(tmp_path / "seq"), "--out", str(out), "--filter", "ekf"]
    args += ["--observer", "registration", "--omega0", "0,0,5", "-O", "q.attitude=1e-5"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    for name in ("track.csv", "track.json", "track.png", "track_errors.png"):
        assert (out / name).is_file(), name
    rows = list(csv.DictReader((out / "track.csv").open()))
    assert len(rows) == 6 and "sigma_wz" in rows[0] and "nees" in rows[0]
    info = json.loads((out / "track.json").read_text())
    lo, hi = info["consistency"]["nees"]["band"]
    assert info["consistency"]["nis"]["dof"] == 6 and lo < 12 < hi
    assert "mean NIS" in r.output
    bad = CliRunner().invoke(
        app, ["track", str(tmp_path / "seq"), "--out", str(out), "--omega0", "1,2"]
    )
    assert bad.exit_code != 0


@pytest.mark.slow
def test_track_li_rotating_end_to_end(tmp_path: Path) -> None:
    """Simulated Paper 2 lab set-up (Kinect + HDL-64, target spinning 5°/s about z, 22.5° per
    frame), through the default observer (I1's contour model when present)."""
    pytest.importorskip("relnav.sim.presets")
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    simulate(get_preset("li-rotating", frames=6, seed=1), tmp_path / "seq")
    # the reference point itself (not the rotation centre, which 6 frames = 135° of spin do not
    # yet pin down) and no observer-drift state: the chain's raw accuracy
    res = track_sequence(
        tmp_path / "seq",
        filter="ukf",
        omega0=np.radians([0.0, 0.0, 5.0]),
        centre_offset=False,
        observer_bias=False,
    )
    assert np.isfinite(res.consistency()["nis"]["mean"])
    print("\nobserver:", res.meta["observer"], res.meta["observer_stats"], res.status)
    print({k: np.round(v["max"], 4).tolist() for k, v in res.summary(skip=2).items()})
    assert res.n_flagged == 0
    s = res.summary(skip=2)
    assert np.all(np.array(s["attitude"]["max"]) < 2.0), s["attitude"]
    assert np.all(np.array(s["position"]["max"]) < 0.05), s["position"]
    assert abs(math.degrees(res.omega[-1, 2]) - 5.0) < 0.5


def test_rate_error_in_sensor_axes_ignores_a_constant_body_frame_offset(tmp_path):
    """errors()["omega_sensor"]: an estimate whose body axes are the true ones turned by a
    constant ε (an uncooperative target's map) has the body-axis rate error ω − R_εᵀ ω, but the
    same rate vector in the sensor's axes: no error there."""
    from relnav.filtering.track_result import TrackResult, TrackTruth

    K = 30
    t = np.arange(K, dtype=float) * 2.0
    w_true = np.radians([0.3, 0.4, 1.2])
    R_true = [Rotation.from_rotvec(w_true * tk) for tk in t]
    R_eps = Rotation.from_rotvec(np.radians([0.0, 0.0, 10.0]))
    quat_est = np.stack([(R * R_eps).as_quat() for R in R_true])
    omega_est = np.tile(R_eps.inv().apply(w_true), (K, 1))  # the same spin in turned axes
    truth = TrackTruth(np.zeros((K, 3)), np.zeros((K, 3)), np.stack([R.as_quat() for R in R_true]),
                       np.tile(w_true, (K, 1)))  # fmt: skip
    res = TrackResult(
        time=t, position=np.zeros((K, 3)), velocity=np.zeros((K, 3)), quat=quat_est,
        omega=omega_est, covariance=np.tile(np.eye(12), (K, 1, 1)), status=["update"] * K,
        nis=np.ones(K), observed=np.full((K, 7), np.nan), filter="ukf", settings={},
        truth=truth,
    )  # fmt: skip
    e = res.errors()
    np.testing.assert_allclose(e["omega_sensor"], 0.0, atol=1e-12)
    body = np.degrees(np.linalg.norm(e["omega"], axis=1))
    np.testing.assert_allclose(body, np.degrees(np.linalg.norm(w_true - omega_est[0])))
    assert body[0] > 0.08  # |ω_xy| · 2 sin 5° = 0.087 deg/s
    assert "err_wsx" in res.to_csv(tmp_path / "state.csv").read_text().splitlines()[0]


def _nis_track(nis: np.ndarray):
    from relnav.filtering.track_result import TrackResult

    K = len(nis)
    return TrackResult(
        time=np.arange(K, dtype=float), position=np.zeros((K, 3)), velocity=np.zeros((K, 3)),
        quat=np.tile([0.0, 0.0, 0.0, 1.0], (K, 1)), omega=np.zeros((K, 3)),
        covariance=np.tile(np.eye(12), (K, 1, 1)), status=["update"] * K, nis=nis,
        observed=np.full((K, 7), np.nan), filter="ukf", settings={},
    )  # fmt: skip


def test_innovation_alarm_catches_a_run_of_large_innovations(tmp_path):
    """A consistent filter's NIS (χ²₆) rarely raises the windowed alarm; a stretch of
    innovations 4× too large does, from within one window of its start, and the alarm ends one
    window after it; a gap of unobserved steps (NaN) raises none."""
    rng = np.random.default_rng(5)
    nis = rng.chisquare(6, 2000)
    quiet = _nis_track(nis).innovation_alarm()
    assert quiet.mean() < 0.005
    bad = nis.copy()
    bad[1000:1030] *= 4.0
    bad[1100:1110] = np.nan
    alarm = _nis_track(bad).innovation_alarm(window=5)
    assert alarm[1004:1030].mean() > 0.9
    assert not alarm[1035:1100].any() and not alarm[1100:1110].any()
    with pytest.raises(ValueError):
        _nis_track(nis).innovation_alarm(window=0)
    header = _nis_track(bad).to_csv(tmp_path / "s.csv").read_text().splitlines()[0]
    assert header.endswith("innovation_alarm")
