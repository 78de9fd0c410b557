"""Scenarios: validation errors, exact ground truth, determinism, presets."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from relnav.errors import ConfigError, InputError
from relnav.io.sequences import ScanSequence
from relnav.sim.presets import PAPER_MEAN_POINTS, available_presets, get_preset
from relnav.sim.scenario import (
    Scenario,
    apply_overrides,
    load_scenario,
    scenario_poses,
    simulate,
)
from relnav.sim.targets import get_target
from relnav.sim.trajectories import make_trajectory, path_length


def _small(**kw) -> dict:
    d = {
        "name": "t",
        "seed": 3,
        "frames": 4,
        "dt": 20.0,
        "target": {"name": "iridium"},
        "sensors": [{"preset": "goldeneye", "overrides": {"range_sigma": 0.05}}],
        "trajectory": {
            "kind": "cw",
            "params": {"state0": [15.0, 0.0, 5.0, 0.0, -0.0339, 0.0]},
        },
        "attitude": {"kind": "tumble", "inertia": [2, 3, 4], "omega0_deg_s": [1, -2, 3]},
    }
    d.update(kw)
    return d


# ------------------------------------------------------------------ validation errors


def test_unknown_key_is_config_error():
    with pytest.raises(ConfigError, match=r"trajectory\.wobble: unknown key"):
        load_scenario(apply_overrides(_small(), {"trajectory.wobble": 1}))
    with pytest.raises(ConfigError, match="colour: unknown key"):
        load_scenario(_small(colour="red"))


def test_negative_range_and_bad_numbers():
    bad = apply_overrides(_small(), {"sensors.0.overrides.max_range": -5})
    with pytest.raises(ConfigError, match=r"sensors\.0 \(goldeneye\).*range"):
        load_scenario(bad)
    with pytest.raises(ConfigError, match="frames"):
        load_scenario(_small(frames=0))
    with pytest.raises(ConfigError, match="dt"):
        load_scenario(_small(dt=-1.0))
    with pytest.raises(ConfigError, match="jitter_deg"):
        load_scenario(_small(pointing={"jitter_deg": -1}))
    with pytest.raises(ConfigError, match="unknown sensor"):
        load_scenario(_small(sensors=[{"preset": "lidar9000"}]))
    with pytest.raises(ConfigError, match="unique"):
        load_scenario(_small(sensors=[{"preset": "vlp16"}, {"preset": "vlp16"}]))


def test_unknown_trajectory_kind_and_param():
    with pytest.raises(ConfigError, match="unknown trajectory kind 'zigzag'"):
        load_scenario(_small(trajectory={"kind": "zigzag"}))
    with pytest.raises(ConfigError, match=r"unknown parameter.*radius"):
        load_scenario(_small(trajectory={"kind": "helical-approach", "params": {"radius": 3}}))
    with pytest.raises(ConfigError, match="triangle"):
        load_scenario(_small(attitude={"kind": "tumble", "inertia": [1, 1, 9]}))


def test_missing_mesh(tmp_path):
    with pytest.raises(InputError, match="mesh file not found"):
        load_scenario(_small(target={"path": str(tmp_path / "nope.ply")}))
    with pytest.raises(ConfigError, match="not both"):
        load_scenario(_small(target={"name": "iridium", "path": "x.ply"}))


def test_sensor_that_sees_nothing(tmp_path):
    sc = _small(sensors=[{"preset": "vlp16", "overrides": {"max_range": 5.0}}])
    with pytest.raises(InputError, match="sensor vlp16 saw nothing of the target in any of the 4"):
        simulate(sc, tmp_path / "seq")


def test_existing_output_needs_overwrite(tmp_path):
    sc = _small(frames=1)
    simulate(sc, tmp_path / "s")
    with pytest.raises(InputError, match="overwrite"):
        simulate(sc, tmp_path / "s")
    simulate(sc, tmp_path / "s", overwrite=True)


# ------------------------------------------------------------------ ground truth


def _closest_dist(mesh: trimesh.Trimesh, pts: np.ndarray) -> np.ndarray:
    _, d, _ = trimesh.proximity.closest_point(mesh, pts)
    return d


@pytest.mark.parametrize(
    ("sensor", "overrides"),
    [
        ("goldeneye", {"range_sigma": 0.0}),
        ("vlp16", {"range_sigma": 0.0}),
        ("surface-hpr", {"noise_sigma": 0.0, "n_points": 300}),
    ],
)
def test_ground_truth_is_exact(tmp_path, sensor, overrides):
    d = _small(
        frames=3,
        sensors=[{"preset": sensor, "overrides": overrides}],
        trajectory={
            "kind": "cw",
            "params": {"state0": [12.0, 0.0, 4.0, 0.0, -0.0271, 0.0]},
        },
        pointing={"jitter_deg": 1.0},
        target={"name": "iridium", "com_offset": [0.1, -0.2, 0.3]},
    )
    simulate(d, tmp_path / "seq")
    seq = ScanSequence(tmp_path / "seq")
    gt = seq.gt_poses
    mesh = get_target("iridium").mesh
    rng = np.random.default_rng(0)
    for k in range(len(seq)):
        p = seq[k].points
        assert len(p) > 50
        p = p[rng.choice(len(p), min(len(p), 150), replace=False)]
        p_t = p @ gt[k][:3, :3].T + gt[k][:3, 3]
        assert _closest_dist(mesh, p_t).max() < 1e-6
    # chained relative poses reproduce the absolute ones
    steps = [np.linalg.inv(gt[i]) @ gt[i + 1] for i in range(len(gt) - 1)]
    T = gt[0].copy()
    for i, S in enumerate(steps):
        T = T @ S
        np.testing.assert_allclose(T, gt[i + 1], atol=1e-9)


def test_ground_truth_composition_matches_world_poses(tmp_path):
    d = _small(
        frames=3, sensors=[{"preset": "goldeneye", "rpy_deg": [0, 5, 0], "offset_m": [0, 0.3, 0]}]
    )
    sc = load_scenario(d)
    simulate(sc, tmp_path / "seq")
    gt = ScanSequence(tmp_path / "seq").gt_poses
    _, T_W_rig, T_W_target = scenario_poses(sc)
    T_W_sensor = T_W_rig @ sc.sensors[0].T_rig_sensor
    np.testing.assert_allclose(T_W_target @ gt, T_W_sensor, atol=1e-9)
    # tumbling target: rotation part of T_W_target changes between frames
    assert not np.allclose(T_W_target[0], T_W_target[-1])


def test_target_rotates_about_its_centre_of_mass():
    c = np.array([0.4, -0.3, 0.2])
    sc = load_scenario(_small(target={"name": "iridium", "com_offset": c.tolist()}))
    _, _, T_W_target = scenario_poses(sc)
    # the centre of mass sits at the W origin in every frame
    np.testing.assert_allclose(T_W_target[:, :3, :3] @ c + T_W_target[:, :3, 3], 0, atol=1e-12)


def test_attitude_phase_enters_the_same_motion_later():
    """``attitude.phase_s``: frame k of the shifted scenario is the unshifted law at
    ``t_k + phase_s`` (tumble: the same integration, not a restart from ω0)."""
    att = {"kind": "tumble", "inertia": [1.0, 2.0, 3.0], "omega0_deg_s": [2.0, 0.5, 4.0]}
    base = load_scenario(_small(attitude=att))
    later = load_scenario(_small(attitude={**att, "phase_s": 7.0}))
    t = np.array([0.0, 1.5, 3.0])
    np.testing.assert_allclose(later.attitude.rotations(t), base.attitude.rotations(t + 7.0))
    assert not np.allclose(later.attitude.rotations(t), base.attitude.rotations(t))
    for bad in (-1.0, float("inf"), float("nan")):
        with pytest.raises(ConfigError, match="phase_s"):
            load_scenario(_small(attitude={**att, "phase_s": bad}))


def test_two_sensor_ground_truth_exact(tmp_path):
    sc = get_preset("li-rotating", frames=2, distance=2.0, axis="x")
    d = apply_overrides(
        sc.model_dump(mode="json"),
        {
            "sensors.0.overrides": {"sigma_coeff": 0.0, "quantize": False},
            "sensors.1.overrides": {"range_sigma": 0.0},
        },
    )
    simulate(d, tmp_path / "li")
    mesh = get_target("iridium", scale_to=sc.target.scale_to).mesh
    rng = np.random.default_rng(1)
    for sensor in (None, "lidar"):
        seq = ScanSequence(tmp_path / "li", sensor=sensor)
        for k in range(len(seq)):
            p = seq[k].points
            p = p[rng.choice(len(p), 150, replace=False)]
            g = seq.gt_poses[k]
            assert _closest_dist(mesh, p @ g[:3, :3].T + g[:3, 3]).max() < 1e-6


def test_noisy_points_near_the_mesh(tmp_path):
    simulate(_small(frames=2), tmp_path / "seq")
    seq = ScanSequence(tmp_path / "seq")
    gt = seq.gt_poses
    mesh = get_target("iridium").mesh
    p = seq[1].points[:300]
    d = _closest_dist(mesh, p @ gt[1][:3, :3].T + gt[1][:3, 3])
    assert 0.01 < d.mean() < 0.1  # 5 cm range noise


# ------------------------------------------------------------------ determinism, files


def _files(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_same_seed_byte_identical(tmp_path):
    d = _small(frames=3, pointing={"jitter_deg": 0.5})
    simulate(d, tmp_path / "a")
    simulate(d, tmp_path / "b")
    fa, fb = _files(tmp_path / "a"), _files(tmp_path / "b")
    assert fa.keys() == fb.keys()
    assert all(fa[k] == fb[k] for k in fa)
    simulate({**d, "seed": 4}, tmp_path / "c")
    fc = _files(tmp_path / "c")
    scans = [k for k in fa if str(k).startswith("scans")]
    assert scans and all(fa[k] != fc[k] for k in scans)


def test_scenario_yaml_round_trip_and_summary(tmp_path):
    d = _small(frames=3)
    summary = simulate(d, tmp_path / "seq")
    again = load_scenario(tmp_path / "seq" / "scenario.yaml")
    assert again.relnav_version
    sc = load_scenario(d)
    assert again.model_dump(exclude={"relnav_version", "trajectory"}) == sc.model_dump(
        exclude={"relnav_version", "trajectory"}
    )
    assert again.trajectory.params["semi_major_axis"] == 6_778_137.0  # defaults resolved
    s = summary.sensors[0]
    assert s.frames == 3 and s.folder == "scans" and s.min_points <= s.mean_points <= s.max_points
    _, pos = make_trajectory("cw", 3, 20.0, sc.trajectory.params)
    assert s.path_length_m == pytest.approx(path_length(pos))
    assert (tmp_path / "seq" / "sensor.yaml").is_file()
    np.testing.assert_allclose(ScanSequence(tmp_path / "seq").timestamps, [0, 20, 40])


def test_apply_overrides():
    d = apply_overrides(_small(), {"trajectory.params.state0": "[1, 2, 3, 0, 0, 0]", "seed": "9"})
    assert d["seed"] == 9 and d["trajectory"]["params"]["state0"] == [1, 2, 3, 0, 0, 0]
    d = apply_overrides(_small(), {"sensors.0.overrides.range_sigma": "0"})
    assert d["sensors"][0]["overrides"]["range_sigma"] == 0
    with pytest.raises(ConfigError, match="index"):
        apply_overrides(_small(), {"sensors.5.name": "x"})


# ------------------------------------------------------------------ presets


def test_all_presets_build():
    for name in available_presets():
        sc = get_preset(name, frames=5)
        assert isinstance(sc, Scenario) and sc.frames == 5 and sc.name == name
    with pytest.raises(ConfigError, match="unknown preset"):
        get_preset("sim-pluto")
    with pytest.raises(ConfigError, match="unknown option"):
        get_preset("sim-orion", distance=3)
    with pytest.raises(ConfigError, match="distance"):
        get_preset("li-rotating", distance=-1)


@pytest.mark.parametrize(
    ("name", "length"),
    [
        ("real-fb", 7.4),
        ("real-curved", 12.4),
        ("sim-eoi", 290.0),
        ("sim-helical", 206.0),
        ("sim-voyager", 788.0),
        ("sim-orion", 788.0),
        ("sim-bennu", 788.0),
    ],
)
def test_preset_path_lengths(name, length):
    sc = get_preset(name)
    _, pos = make_trajectory(sc.trajectory.kind, sc.frames, sc.dt, sc.trajectory.params)
    assert path_length(pos) == pytest.approx(length, rel=0.01)


def test_li_rotating_two_sensor_folders(tmp_path):
    sc = get_preset("li-rotating", frames=2, distance=2.4, axis="y")
    assert sc.attitude.axis == "y" and sc.trajectory.params["position"][0] == -2.4
    summary = simulate(sc, tmp_path / "li")
    assert [s.folder for s in summary.sensors] == ["scans", "scans_lidar"]
    kin, lid = ScanSequence(tmp_path / "li"), ScanSequence(tmp_path / "li", sensor="lidar")
    assert len(kin) == len(lid) == 2
    assert len(kin[0]) > 5 * len(lid[0]) > 0  # dense depth camera, sparse LIDAR
    np.testing.assert_allclose(kin.timestamps, [0.0, 4.5])
    # fixed mounting between the two sensors in every frame
    rel = np.linalg.inv(kin.gt_poses) @ lid.gt_poses
    expected = np.linalg.inv(sc.sensors[0].T_rig_sensor) @ sc.sensors[1].T_rig_sensor
    np.testing.assert_allclose(rel, np.broadcast_to(expected, rel.shape), atol=1e-9)
    # 22.5° of target rotation between frames, about the target's y axis in W
    step = np.linalg.inv(kin.gt_poses[0]) @ kin.gt_poses[1]
    ang = np.degrees(np.arccos((np.trace(step[:3, :3]) - 1) / 2))
    assert ang == pytest.approx(22.5, abs=1e-6)


@pytest.mark.parametrize(
    ("name", "frames"),
    [
        ("real-fb", 31),
        ("real-curved", 41),
        ("sim-helical", 30),
        ("sim-voyager", 50),
        ("sim-orion", 25),
        ("sim-bennu", 25),
    ],
)
def test_preset_point_counts_in_band(tmp_path, name, frames):
    summary = simulate(get_preset(name, frames=frames), tmp_path / name)
    mean = summary.sensors[0].mean_points
    assert abs(mean / PAPER_MEAN_POINTS[name] - 1) < 0.25


def test_preset_point_counts_in_band_resampled(tmp_path):
    sc = get_preset("sim-voyager", frames=50, model_cloud="resample")
    summary = simulate(sc, tmp_path / "resampled")
    mean = summary.sensors[0].mean_points
    assert abs(mean / PAPER_MEAN_POINTS["sim-voyager"] - 1) < 0.25


def test_target_mesh_swap(shared_targets):
    mesh = shared_targets / "voyager.ply"
    if not mesh.is_file():
        pytest.skip("voyager.ply not present")
    sc = get_preset("sim-voyager", frames=3, target_mesh=str(mesh))
    assert sc.target.path == str(mesh) and sc.target.name is None and sc.target.scale_to is None
    sc = get_preset("sim-bennu", frames=3, target_mesh=str(mesh))
    assert sc.target.scale_to == 10.0  # the preset's scale is kept
    sc = get_preset("sim-bennu", frames=3, target_mesh=str(mesh), scale_to=None)
    assert sc.target.scale_to is None
