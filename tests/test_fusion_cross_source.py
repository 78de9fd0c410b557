"""Paper 2's CGA cross-source registration, the CBD baseline and ``relnav fuse``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from relnav.errors import ConfigError
from relnav.fusion.cbd import CBDRegistration, sphere_fit_curvature
from relnav.fusion.cross_source import (
    CrossSourceRegistration,
    SphereMatches,
    cross_source_register,
    fps_from_centroid,
    motor_from_matches,
)
from relnav.geometry.rotations import rotation_angle
from relnav.geometry.se3 import invert, kabsch, random_transform, transform_points


def _satellite() -> trimesh.Trimesh:
    """Asymmetric box-with-panels target (~1.6 m)."""
    tm = trimesh.transformations.translation_matrix
    parts = [
        trimesh.creation.box((1.0, 0.8, 0.6)),
        trimesh.creation.box((0.02, 1.2, 0.4), transform=tm((0.2, 1.0, 0.0))),
        trimesh.creation.box((0.3, 0.2, 0.25), transform=tm((0.25, -0.2, 0.42))),
    ]
    return trimesh.util.concatenate(parts)


def _pair(seed: int, n_cam: int = 6000, n_lid: int = 600):
    """Camera cloud (camera frame), LIDAR cloud (LIDAR frame), true T_camera_lidar."""
    rng = np.random.default_rng(seed)
    mesh = _satellite()
    cam = trimesh.sample.sample_surface(mesh, n_cam, seed=seed)[0]
    cam = cam + rng.normal(scale=0.002, size=cam.shape)
    lid_c = trimesh.sample.sample_surface(mesh, n_lid, seed=seed + 100)[0]
    lid_c = lid_c + rng.normal(scale=0.005, size=lid_c.shape)
    T = random_transform(rng, 1.0)
    return cam, transform_points(invert(T), lid_c), T, lid_c


def _errors(T_est: np.ndarray, T_true: np.ndarray, lid: np.ndarray) -> tuple[float, float]:
    rot = float(np.degrees(rotation_angle(T_est[:3, :3].T @ T_true[:3, :3])))
    d = transform_points(T_est, lid) - transform_points(T_true, lid)
    return rot, float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


# --------------------------------------------------------------------------------------------


def test_fps_from_centroid_order(rng: np.random.Generator) -> None:
    P = rng.normal(size=(300, 3))
    idx = fps_from_centroid(P, 20)
    assert idx.shape == (20,) and len(set(idx.tolist())) == 20
    c = P.mean(axis=0)
    assert idx[0] == np.argmax(np.linalg.norm(P - c, axis=1))
    # every next sample is the farthest from the centroid and the previous samples
    for s in range(1, 20):
        chosen = np.vstack([c, P[idx[:s]]])
        dmin = np.min(np.linalg.norm(P[:, None] - chosen[None], axis=2), axis=1)
        dmin[idx[:s]] = -1
        assert idx[s] == np.argmax(dmin)
    assert fps_from_centroid(P, 0).size == 0
    assert fps_from_centroid(P[:5], 10).size == 5


def test_motor_from_exact_pairs_recovers_transform(rng: np.random.Generator) -> None:
    """Point / sphere-centre pairs: the CGA motor is the rigid motion (1e-6) and equals Kabsch."""
    for _ in range(3):
        T = random_transform(rng, 2.0)  # T_camera_lidar
        lid = rng.normal(size=(15, 3))
        centres = transform_points(T, lid)
        m = SphereMatches(
            lidar_points=lid,
            centres=centres,
            radii=rng.uniform(0.0, 0.1, 15),
            circle=np.zeros(15, bool),
            quads=np.zeros((15, 4, 3)),
            sample_index=np.arange(15),
        )
        T_est, motor, info = motor_from_matches(m)
        np.testing.assert_allclose(T_est, T, atol=1e-6)
        assert info["sample_rmse"] < 1e-9 and motor.shape == (8,)
        noisy = SphereMatches(
            lid, centres + rng.normal(scale=0.02, size=centres.shape), m.radii, m.circle,
            m.quads, m.sample_index,
        )  # fmt: skip
        T_est, _, _ = motor_from_matches(noisy)
        np.testing.assert_allclose(T_est, kabsch(lid, noisy.centres), atol=1e-9)


@pytest.mark.parametrize("seed", [1, 3])
def test_global_registration_synthetic(seed: int) -> None:
    """Full-surface clouds at 10:1 density, arbitrary relative rotation (rotation invariance)."""
    cam, lid, T, _ = _pair(seed)
    res = cross_source_register(cam, lid, m=15, seed=seed)
    assert res.ok, res.message
    rot, gt = _errors(res.T_target_source, T, lid)
    assert rot < 6.0
    assert gt < 0.08
    assert res.n_inliers == 15
    assert 0 < res.inlier_rmse < 0.05 and res.fitness > 0.9
    assert res.info["seed"] == seed and len(res.info["matches"]) == 15
    assert res.info["n_hypotheses"] > 0 and "rival_score" in res.info


def test_determinism_and_registry() -> None:
    from relnav.registration import get_registration

    cam, lid, _, _ = _pair(3)
    a = cross_source_register(cam, lid, seed=5)
    b = get_registration("cga-sphere", seed=5).register(lid, cam)
    np.testing.assert_array_equal(a.T_target_source, b.T_target_source)
    with pytest.raises(ConfigError):
        get_registration("cga-sphere:foo")
    with pytest.raises(ConfigError):
        CrossSourceRegistration(m=2)
    with pytest.raises(ConfigError):
        CrossSourceRegistration(coplanar="nope")  # type: ignore[arg-type]


def test_init_rotation_skips_search_and_max_rotation() -> None:
    cam, lid, T, _ = _pair(4)
    res = cross_source_register(cam, lid, init=T)
    assert res.ok and res.info["n_hypotheses"] == 0
    rot, gt = _errors(res.T_target_source, T, lid)
    assert rot < 6.0 and gt < 0.08
    res2 = cross_source_register(cam, lid, init=T, max_rotation_deg=20.0)
    assert res2.ok and res2.info["n_hypotheses"] > 0
    assert _errors(res2.T_target_source, T, lid)[0] < 6.0


def test_bad_inputs_are_flagged(rng: np.random.Generator) -> None:
    cam, lid, _, _ = _pair(2)
    cases = {
        "empty camera": (np.zeros((0, 3)), lid),
        "empty lidar": (cam, np.zeros((0, 3))),
        "fewer than m": (cam, lid[:10]),
        "wrong shape": (cam, lid[:, :2]),
        "coplanar": (
            np.c_[rng.uniform(-1, 1, (3000, 2)), np.zeros(3000)],
            np.c_[rng.uniform(-1, 1, (300, 2)), np.zeros(300)],
        ),
    }
    for what, (c, li) in cases.items():
        res = cross_source_register(c, li, m=15)
        assert res.status in ("degenerate", "failed"), what
        assert res.message, what
        np.testing.assert_array_equal(res.T_target_source, np.eye(4))
    # no overlap: the LIDAR saw a different object (a thin rod bundle) -> flagged
    rod = np.c_[rng.uniform(-0.03, 0.03, (400, 2)), rng.uniform(-1.5, 1.5, 400)]
    res = cross_source_register(cam, rod, m=15)
    assert res.status in ("degenerate", "failed")
    # non-finite rows are dropped, not fatal
    lid_nan = np.vstack([lid, [[np.nan, 0, 0]]])
    res = cross_source_register(cam, lid_nan, seed=2)
    assert res.ok and res.info["dropped_nonfinite_lidar"] == 1
    assert cross_source_register(cam, lid, init=np.zeros((3, 3))).status == "failed"


def test_li_rotating_frames(tmp_path: Path) -> None:
    """Simulated Kinect + HDL-64 (paper 2 preset): RMSE comparable to paper 2 (0.01–0.06 m)."""
    presets = pytest.importorskip("relnav.sim.presets")
    from relnav.io.sequences import ScanSequence
    from relnav.sim.scenario import simulate

    sc = presets.get_preset("li-rotating", distance=3.0, axis="z", frames=2, seed=1)
    simulate(sc, tmp_path / "seq")
    cam = ScanSequence(tmp_path / "seq")
    lid = ScanSequence(tmp_path / "seq", sensor="lidar")
    for k in range(len(cam)):
        T_true = invert(cam.gt_poses[k]) @ lid.gt_poses[k]
        res = cross_source_register(cam[k].points, lid[k].points, m=15, seed=0)
        assert res.ok, res.message
        rot, gt = _errors(res.T_target_source, T_true, lid[k].points)
        assert gt < 0.05, (k, gt)
        assert rot < 6.0, (k, rot)
        assert res.inlier_rmse < 0.03


# --------------------------------------------------------------------------------------------
# CBD baseline
# --------------------------------------------------------------------------------------------


def test_sphere_fit_curvature_known_sphere(rng: np.random.Generator) -> None:
    u = rng.normal(size=(2000, 3))
    P = 0.5 * u / np.linalg.norm(u, axis=1, keepdims=True) + [1.0, -2.0, 0.5]
    curv, centres, radii = sphere_fit_curvature(P, k=20)
    # exact up to the 1e-9 relative ridge of the normal equations
    np.testing.assert_allclose(np.median(radii), 0.5, rtol=1e-5)
    np.testing.assert_allclose(np.median(curv), 2.0, rtol=1e-5)
    np.testing.assert_allclose(np.median(centres, axis=0), [1.0, -2.0, 0.5], atol=1e-5)
    plane = np.c_[rng.uniform(size=(500, 2)), np.zeros(500)]
    assert np.all(sphere_fit_curvature(plane, k=20)[0] < 1e-3)


def test_cbd_synthetic_known_answer() -> None:
    from relnav.registration import get_registration

    cam, lid, T, _ = _pair(3)
    res = get_registration("cbd", seed=3).register(lid, cam)
    assert res.ok, res.message
    rot, gt = _errors(res.T_target_source, T, lid)
    assert rot < 8.0 and gt < 0.1
    assert res.info["seed"] == 3
    bad = CBDRegistration().register(np.zeros((5, 3)), cam)
    assert bad.status == "degenerate"


# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------


def test_cli_fuse(tmp_path: Path) -> None:
    import typer
    from typer.testing import CliRunner

    from relnav.cli import fuse
    from relnav.io.pointclouds import write_points

    cam, lid, T, _ = _pair(3)
    write_points(tmp_path / "cam.ply", cam)
    write_points(tmp_path / "lid.npy", lid)
    app = typer.Typer()
    fuse.register(app)
    app.command("noop")(lambda: None)  # keep the sub-command name with a single command
    out = tmp_path / "out"
    args = ["fuse", str(tmp_path / "cam.ply"), str(tmp_path / "lid.npy"), "--out", str(out)]
    r = CliRunner().invoke(app, [*args, "--m", "15", "--seed", "3"])
    assert r.exit_code == 0, r.output
    doc = json.loads((out / "result.json").read_text())
    assert doc["status"] == "ok" and doc["seed"] == 3 and doc["rmse_m"] < 0.05
    T_file = np.loadtxt(out / "T_camera_lidar.txt")
    assert _errors(T_file, T, lid)[1] < 0.08
    assert (out / "fused.ply").is_file()
    # refuses to overwrite without --force
    r = CliRunner().invoke(app, args)
    assert r.exit_code != 0
    r = CliRunner().invoke(app, [*args, "--force", "--no-cluster", "--method", "cbd"])
    assert r.exit_code == 0, r.output
