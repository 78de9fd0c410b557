"""Ray casting, hidden point removal, noise models and the simulated sensors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
import yaml

from relnav.errors import ConfigError, InputError
from relnav.geometry import from_rt, transform_points
from relnav.sim.hpr import hidden_point_removal
from relnav.sim.noise import (
    KINECT_RAW_A,
    kinect_depth,
    kinect_depth_to_raw,
    kinect_raw_to_depth,
)
from relnav.sim.raycast import RayCaster
from relnav.sim.sensors import (
    DepthCamera,
    FlashLidar,
    ScanningLidar,
    SurfaceSampler,
    available_sensors,
    make_sensor,
    sensor_from_dict,
)
from relnav.sim.targets import Target, procedural_target

# --------------------------------------------------------------------------- helpers


def look_at(position, at=(0.0, 0.0, 0.0)) -> np.ndarray:
    """T_target_sensor of a sensor at ``position`` whose +x points at ``at`` (z roughly up)."""
    p = np.asarray(position, dtype=float)
    x = np.asarray(at, dtype=float) - p
    x /= np.linalg.norm(x)
    up = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    y = np.cross(up, x)
    y /= np.linalg.norm(y)
    return from_rt(np.column_stack([x, y, np.cross(x, y)]), p)


def plane_target(size: float = 40.0, tilt_deg: float = 0.0) -> Target:
    """Square plane through the origin with normal +x (optionally tilted about z)."""
    m = trimesh.Trimesh(
        vertices=[[0, -1, -1], [0, 1, -1], [0, 1, 1], [0, -1, 1]],
        faces=[[0, 1, 2], [0, 2, 3]],
    )
    m.apply_scale(size / 2)
    m = m.subdivide().subdivide()
    if tilt_deg:
        m.apply_transform(
            trimesh.transformations.rotation_matrix(math.radians(tilt_deg), [0, 0, 1])
        )
    return Target(name="plane", mesh=m, source="test:plane")


def on_mesh_distance(target: Target, pts_sensor: np.ndarray, T: np.ndarray) -> np.ndarray:
    pts_t = transform_points(T, pts_sensor)
    if len(pts_t) > 3000:  # closest_point is slow; a seeded subset is enough
        pts_t = pts_t[np.random.default_rng(0).choice(len(pts_t), 3000, replace=False)]
    _, dist, _ = trimesh.proximity.closest_point(target.mesh, pts_t)
    return dist


NOISELESS = {
    "vlp16": dict(range_sigma=0.0),
    "hdl64": dict(range_sigma=0.0),
    "rs32": dict(range_sigma=0.0),
    "goldeneye": dict(range_sigma=0.0),
    "dragoneye": dict(range_sigma=0.0),
    "kinect1": dict(sigma_coeff=0.0, quantize=False, decimation=4),
    "surface-hpr": dict(noise_sigma=0.0, n_points=300),
}


@pytest.fixture(scope="module")
def envisat() -> Target:
    return procedural_target("envisat")


@pytest.fixture(scope="module")
def capsule() -> Target:
    return procedural_target("capsule")


# --------------------------------------------------------------------------- ray casting


def test_raycaster_known_answer_and_miss() -> None:
    rc = RayCaster(trimesh.creation.box(extents=(1.0, 1.0, 1.0)))
    o = np.array([[-5.0, 0.1, 0.2], [-5.0, 3.0, 0.0], [0.0, 0.0, 7.0]])
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -2.0]])  # last not unit
    r, f = rc.cast(o, d)
    assert r[0] == pytest.approx(4.5, abs=1e-12) and f[0] >= 0
    assert np.isinf(r[1]) and f[1] == -1
    assert r[2] == pytest.approx(6.5, abs=1e-12)
    assert r.dtype == np.float64 and f.dtype == np.int64
    assert rc.face_normals.shape == (12, 3)
    np.testing.assert_allclose(np.linalg.norm(rc.face_normals, axis=1), 1.0)
    with pytest.raises(InputError):
        rc.cast(o, d[:2])
    with pytest.raises(InputError):
        rc.cast(o, np.zeros((3, 3)))


def test_raycaster_exact_at_vertices_and_edges() -> None:
    """Rays aimed exactly at mesh vertices (worst case for float32 Embree) hit them in float64."""
    t = procedural_target("asteroid", subdivisions=4, seed=3)
    V = t.mesh.vertices
    origin = np.array([1500.0, 200.0, -100.0])
    # vertices on the near side, seen head-on enough
    n = t.mesh.vertex_normals
    front = np.flatnonzero(
        ((origin - V) * n).sum(axis=1) > 0.3 * np.linalg.norm(origin - V, axis=1)
    )
    sel = front[:400]
    d = V[sel] - origin
    expected = np.linalg.norm(d, axis=1)
    r, _f = t.raycaster.cast(np.broadcast_to(origin, d.shape), d / expected[:, None])
    # a few may be occluded by a nearer bump; all others must land on the vertex
    close = np.abs(r - expected) < 1e-6
    assert close.mean() > 0.95
    pts = origin + d / expected[:, None] * r[:, None]
    _, dist, _ = trimesh.proximity.closest_point(t.mesh, pts)
    assert dist.max() < 1e-6


def test_raycaster_triangle_backend_agrees_with_embree() -> None:
    t = procedural_target("asteroid", subdivisions=3, seed=0, scale_to=50.0)
    rng = np.random.default_rng(0)
    o = rng.normal(size=(500, 3)) * 10 + [0.0, 0.0, 100.0]
    d = rng.normal(size=(500, 3)) * 0.15 + [0.0, 0.0, -1.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r1, _f1 = RayCaster(t.mesh).cast(o, d)
    r2, _f2 = RayCaster(t.mesh, backend="triangle").cast(o, d)
    assert np.isfinite(r1).sum() > 100
    np.testing.assert_array_equal(np.isfinite(r1), np.isfinite(r2))
    np.testing.assert_allclose(r1[np.isfinite(r1)], r2[np.isfinite(r2)], atol=1e-9)


# --------------------------------------------------------------------------- HPR


def fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5**0.5) * i
    return np.column_stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)])


def test_hpr_sphere_keeps_the_visible_cap() -> None:
    P = fibonacci_sphere(3000)
    d = 10.0
    vis = hidden_point_removal(P, [d, 0.0, 0.0])
    cap = np.flatnonzero(P[:, 0] >= 1.0 / d)  # geometrically visible from (d, 0, 0)
    assert np.isin(cap, vis).all()  # every visible point kept
    assert (P[vis, 0] > 0.0).all()  # nothing from the far hemisphere
    assert len(vis) <= 1.1 * len(cap)  # only a thin band near the horizon in excess
    assert np.all(np.diff(vis) > 0)


def test_hpr_matches_open3d() -> None:
    o3d = pytest.importorskip("open3d")
    rng = np.random.default_rng(2)
    P = fibonacci_sphere(1500) * [1.0, 0.6, 0.3] + rng.normal(scale=0.01, size=(1500, 3))
    C = np.array([0.5, 3.0, 1.0])
    ours = hidden_point_removal(P, C, radius_factor=100.0)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    R = 100.0 * np.linalg.norm(P - C, axis=1).max()
    _, idx = pc.hidden_point_removal(C, R)
    assert set(ours.tolist()) == set(idx)


def test_hpr_degenerate_inputs() -> None:
    assert hidden_point_removal(np.zeros((0, 3)), np.zeros(3)).size == 0
    three = np.eye(3)
    np.testing.assert_array_equal(hidden_point_removal(three, [5.0, 5.0, 5.0]), [0, 1, 2])
    # a point at the viewpoint is dropped; a planar cloud does not crash
    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2)
    planar = np.column_stack([g, np.zeros(len(g))])
    vis = hidden_point_removal(np.vstack([planar, [[1.0, 1.0, 3.0]]]), [1.0, 1.0, 3.0])
    assert 25 not in vis
    with pytest.raises(InputError):
        hidden_point_removal(planar, [0.0, 0.0, 1.0], radius_factor=1.0)
    with pytest.raises(InputError):
        hidden_point_removal(planar[:, :2], [0.0, 0.0, 1.0])
    assert np.array_equal(
        hidden_point_removal(planar, [2.0, 2.0, 5.0], gamma=2.0),
        hidden_point_removal(planar, [2.0, 2.0, 5.0], radius_factor=100.0),
    )


# --------------------------------------------------------------------------- noise models


def test_kinect_raw_map_and_quantisation_step() -> None:
    z = np.array([0.8, 1.0, 2.0, 3.0, 4.5, 6.0])
    np.testing.assert_allclose(kinect_raw_to_depth(kinect_depth_to_raw(z)), z, rtol=1e-12)
    raw = np.rint(kinect_depth_to_raw(z))
    z0, z1 = kinect_raw_to_depth(raw), kinect_raw_to_depth(raw + 1)
    np.testing.assert_allclose(z1 - z0, -KINECT_RAW_A * z0 * z1, rtol=1e-9)  # exact identity
    step = z1 - z0
    np.testing.assert_allclose(step, -KINECT_RAW_A * z**2, rtol=0.04)  # ≈ 0.00307 Z^2
    q = kinect_depth(z, np.random.default_rng(0), sigma_coeff=0.0, quantize=True)
    assert np.all(np.abs(q - z) <= 0.5 * step * 1.05)


# --------------------------------------------------------------------------- every sensor


@pytest.mark.parametrize("preset", list(NOISELESS))
def test_noiseless_scans_lie_on_the_mesh(preset: str, envisat: Target, capsule: Target) -> None:
    sensor = make_sensor(preset, **NOISELESS[preset])
    if preset == "kinect1":
        target, T = capsule, look_at([4.5, 1.0, 1.5])
    else:
        target, T = envisat, look_at([35.0, -20.0, 12.0], at=(1.0, 0.5, 0.0))
    pts = sensor.scan(target, T, np.random.default_rng(1))
    assert pts.dtype == np.float64 and pts.ndim == 2 and pts.shape[1] == 3
    assert len(pts) > 50
    assert on_mesh_distance(target, pts, T).max() < 1e-6
    assert (np.linalg.norm(pts, axis=1) <= sensor.max_range + 1e-9).all()


def test_noiseless_far_large_target_stays_exact() -> None:
    """Float32 Embree + float64 refinement: 500 m asteroid seen from 1.5 km."""
    t = procedural_target("asteroid", seed=5, craters=10)
    T = look_at([1200.0, -700.0, 500.0])
    s = make_sensor("goldeneye", range_sigma=0.0, rows=64, cols=64)
    pts = s.scan(t, T, np.random.default_rng(0))
    assert len(pts) > 300
    assert on_mesh_distance(t, pts, T).max() < 1e-6


@pytest.mark.parametrize("preset", available_sensors())
def test_seeded_determinism(preset: str, envisat: Target, capsule: Target) -> None:
    over = {"decimation": 4} if preset == "kinect1" else {}
    if preset in ("vlp16", "goldeneye", "surface-hpr"):
        over["dropout"] = 0.1
    sensor = make_sensor(preset, **over)
    target, T = (
        (capsule, look_at([4.0, 0.5, 1.0]))
        if preset == "kinect1"
        else (
            envisat,
            look_at([30.0, 15.0, 8.0]),
        )
    )
    a = sensor.scan(target, T, np.random.default_rng(42))
    b = sensor.scan(target, T, np.random.default_rng(42))
    c = sensor.scan(target, T, np.random.default_rng(43))
    assert len(a) > 0
    assert a.tobytes() == b.tobytes()
    assert a.shape != c.shape or not np.array_equal(a, c)


@pytest.mark.parametrize("preset", available_sensors())
def test_to_dict_yaml_roundtrip(preset: str) -> None:
    s = make_sensor(preset)
    d = s.to_dict()
    assert d["kind"] == s.kind and d["name"] == preset
    back = sensor_from_dict(yaml.safe_load(yaml.safe_dump(d)))
    assert back == s and back.to_dict() == d
    assert type(back) is type(s)
    assert s.max_range > 0


def test_looking_away_returns_no_points(envisat: Target, capsule: Target) -> None:
    behind = look_at([40.0, 0.0, 0.0], at=(80.0, 0.0, 0.0))
    for preset in ("goldeneye", "dragoneye"):
        pts = make_sensor(preset).scan(envisat, behind, np.random.default_rng(0))
        assert pts.shape == (0, 3) and pts.dtype == np.float64
    k = make_sensor("kinect1", decimation=4)
    assert k.scan(capsule, look_at([4.0, 0, 0], at=(8.0, 0, 0)), 0).shape == (0, 3)
    # target straight above a VLP-16 (outside ±15°) and beyond range
    above = from_rt(np.eye(3), [0.0, 0.0, -40.0])
    assert make_sensor("vlp16").scan(envisat, above, 0).shape == (0, 3)
    far = look_at([0.0, 5000.0, 0.0])
    assert make_sensor("hdl64").scan(envisat, far, 0).shape == (0, 3)
    s = make_sensor("surface-hpr", fov_h_deg=30.0, fov_v_deg=30.0)
    assert s.scan(envisat, behind, np.random.default_rng(0)).shape == (0, 3)


# --------------------------------------------------------------------------- sensor specifics


def test_range_noise_and_dropout_statistics_on_a_plane() -> None:
    plane = plane_target(60.0)
    T = look_at([20.0, 0.0, 0.0])  # head-on
    s = FlashLidar("f", rows=100, cols=100, fov_h_deg=40, fov_v_deg=40, range_sigma=0.05)
    ret = s.scan_detailed(plane, T, np.random.default_rng(3))
    assert len(ret.points) == 10_000  # plane fills the FOV
    res = np.linalg.norm(ret.points, axis=1) - ret.true_range
    assert np.std(res) == pytest.approx(0.05, rel=0.05)
    assert abs(np.mean(res)) < 4 * 0.05 / 100
    # noise is along the ray: points stay on their pixel ray
    u = ret.points / np.linalg.norm(ret.points, axis=1, keepdims=True)
    np.testing.assert_allclose(u, s.ray_directions()[ret.ray_index], atol=1e-12)
    s2 = FlashLidar("f", rows=100, cols=100, fov_h_deg=40, fov_v_deg=40, dropout=0.3)
    n = len(s2.scan(plane, T, np.random.default_rng(4)))
    assert abs(n / 10_000 - 0.7) < 4 * math.sqrt(0.21 / 10_000)


def test_scanning_lidar_beam_geometry_and_frame() -> None:
    plane = plane_target(200.0)
    # plane (normal +x in target) seen from +x: the sensor is 30 m away looking at it
    T = look_at([30.0, 0.0, 0.0])
    s = make_sensor("vlp16", range_sigma=0.0)
    ret = s.scan_detailed(plane, T, 0)
    p = ret.points
    el = np.degrees(np.arcsin(p[:, 2] / np.linalg.norm(p, axis=1)))
    nearest = np.abs(el[:, None] - np.array(s.elevations_deg)[None, :]).min(axis=1)
    assert nearest.max() < 1e-9
    az = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
    k = (az + 180.0) / 0.2
    assert np.abs(k - np.round(k)).max() < 1e-6
    assert (p[:, 0] > 0).all()  # target in front (+x)
    assert len(np.unique(np.round(el, 6))) == 16
    # a target on the left (+y of the sensor) gives azimuths near +90°
    T_left = from_rt(np.eye(3), [0.0, -40.0, 0.0])  # sensor at -40 y: target at +y
    left = s.scan(procedural_target("capsule"), T_left, 0)
    assert len(left) > 0
    assert np.abs(np.degrees(np.arctan2(left[:, 1], left[:, 0])) - 90.0).max() < 5.0


def test_scanning_lidar_auto_fov_equals_full_scan(envisat: Target) -> None:
    T = look_at([25.0, 20.0, 5.0])
    full = make_sensor("rs32").scan(envisat, T, np.random.default_rng(9))
    auto = make_sensor("rs32", azimuth_fov_deg="auto").scan(envisat, T, np.random.default_rng(9))
    assert full.tobytes() == auto.tobytes()
    narrow = make_sensor("rs32", azimuth_fov_deg=(-5.0, 5.0)).scan(envisat, T, 9)
    az = np.degrees(np.arctan2(narrow[:, 1], narrow[:, 0]))
    assert 0 < len(narrow) < len(full) and np.abs(az).max() <= 5.0 + 1e-9


def test_grazing_incidence_rejected() -> None:
    plane = plane_target(200.0, tilt_deg=0.0)
    # sensor 1 m off the plane, looking along it: most rays hit at > 80 deg incidence
    T = look_at([1.0, -50.0, 0.0], at=(1.0, 50.0, 0.0))
    T = T @ from_rt(trimesh.transformations.rotation_matrix(0.3, [0, 0, 1])[:3, :3])
    s85 = FlashLidar("f", rows=60, cols=60, fov_h_deg=60, fov_v_deg=60, max_incidence_deg=85)
    s90 = FlashLidar("f", rows=60, cols=60, fov_h_deg=60, fov_v_deg=60, max_incidence_deg=90)
    a = s85.scan_detailed(plane, T, 0)
    b = s90.scan_detailed(plane, T, 0)
    assert len(a.points) < len(b.points)
    assert np.degrees(a.incidence).max() <= 85.0 + 1e-9
    assert np.degrees(b.incidence).max() > 85.0


def test_depth_camera_depth_noise_quantisation_and_rays() -> None:
    plane = plane_target(20.0, tilt_deg=40.0)  # depths vary across the image
    T = look_at([3.0, 0.0, 0.0])
    clean = DepthCamera("k", decimation=4, sigma_coeff=0.0, quantize=False)
    quant = DepthCamera("k", decimation=4, sigma_coeff=0.0, quantize=True)
    noisy = DepthCamera("k", decimation=4, sigma_coeff=1.43e-3, quantize=False)
    c = clean.scan_detailed(plane, T, 0)
    q = quant.scan_detailed(plane, T, 0)
    n = noisy.scan_detailed(plane, T, np.random.default_rng(5))
    assert len(c.points) == 160 * 120
    np.testing.assert_array_equal(c.ray_index, q.ray_index)
    # points lie on their pixel rays with x = depth
    d = clean.ray_directions()[q.ray_index]
    np.testing.assert_allclose(q.points, d * (q.points[:, :1] / d[:, :1]), atol=1e-12)
    # quantisation: discrete depth levels spaced by ~0.00307 Z^2, error within half a step
    z = c.points[:, 0]
    levels = np.unique(np.round(q.points[:, 0], 9))
    gaps = np.diff(levels)
    mid = 0.5 * (levels[1:] + levels[:-1])
    np.testing.assert_allclose(gaps, -KINECT_RAW_A * mid**2, rtol=0.02)
    assert np.all(np.abs(q.points[:, 0] - z) <= 0.5 * 0.00307 * z**2 * 1.05 + 1e-12)
    # axial noise sigma = 1.43e-3 Z^2
    rel = (n.points[:, 0] - c.points[:, 0]) / (1.43e-3 * c.points[:, 0] ** 2)
    assert np.std(rel) == pytest.approx(1.0, rel=0.05)
    # depth gate along +x (not slant range)
    assert z.min() >= 0.8 and z.max() <= 6.0


def test_depth_camera_projector_shadows() -> None:
    wall = plane_target(10.0)
    post = trimesh.creation.box(extents=(0.1, 0.1, 3.0))
    post.apply_translation([0.8, 0.0, 0.0])
    t = Target("wall+post", trimesh.util.concatenate([wall.mesh, post]), "test")
    T = look_at([2.5, 0.0, 0.0])
    a = DepthCamera("k", decimation=4, sigma_coeff=0, quantize=False).scan_detailed(t, T, 0)
    b = DepthCamera("k", decimation=4, sigma_coeff=0, quantize=False, shadows=True)
    b = b.scan_detailed(t, T, 0)
    assert 0 < len(a.points) - len(b.points) < 0.2 * len(a.points)
    assert set(b.ray_index.tolist()) <= set(a.ray_index.tolist())


def test_surface_sampler_counts_and_crops(envisat: Target) -> None:
    s = make_sensor("surface-hpr", n_points=300)
    rng = np.random.default_rng(11)
    counts = []
    for _ in range(8):
        v = rng.normal(size=3)
        T = look_at(v / np.linalg.norm(v) * 40.0)
        counts.append(len(s.scan(envisat, T, rng)))
    assert 0.6 * 300 < np.mean(counts) < 1.4 * 300
    fixed = make_sensor("surface-hpr", n_surface=1000, noise_sigma=0.01)
    T = look_at([30.0, 10.0, 5.0])
    ret = fixed.scan_detailed(envisat, T, np.random.default_rng(0))
    assert 0 < len(ret.points) < 1000
    res = np.linalg.norm(ret.points, axis=1) - ret.true_range
    assert 0.005 < np.std(res) < 0.02
    near = make_sensor("surface-hpr", n_surface=1000, max_range=32.0, fov_h_deg=10, fov_v_deg=10)
    p = near.scan(envisat, T, np.random.default_rng(0))
    assert (np.linalg.norm(p, axis=1) <= 32.0).all()
    assert (np.abs(p[:, 1] / p[:, 0]) <= math.tan(math.radians(5)) + 1e-12).all()


def test_bad_parameters_raise_config_error() -> None:
    bad = [
        lambda: make_sensor("nosuch"),
        lambda: make_sensor("vlp16", min_range=-1.0),
        lambda: make_sensor("vlp16", min_range=50.0, max_range=10.0),
        lambda: make_sensor("vlp16", max_range=0.0),
        lambda: make_sensor("vlp16", colour="red"),
        lambda: make_sensor("vlp16", azimuth_step_deg=0.0),
        lambda: make_sensor("vlp16", azimuth_fov_deg=(10.0, -10.0)),
        lambda: make_sensor("vlp16", azimuth_fov_deg="wide"),
        lambda: make_sensor("vlp16", elevations_deg=[]),
        lambda: make_sensor("vlp16", range_sigma=-0.1),
        lambda: make_sensor("goldeneye", dropout=1.0),
        lambda: make_sensor("goldeneye", rows=0),
        lambda: make_sensor("goldeneye", fov_h_deg=180.0),
        lambda: make_sensor("kinect1", decimation=0),
        lambda: make_sensor("surface-hpr", hpr_radius_factor=0.5),
        lambda: ScanningLidar("x", [0.0], 0.2, max_incidence_deg=120.0),
        lambda: SurfaceSampler("x", n_points=0),
        lambda: sensor_from_dict({"kind": "radar"}),
        lambda: sensor_from_dict({"kind": "flash_lidar"}),
    ]
    for f in bad:
        with pytest.raises(ConfigError):
            f()
    assert sensor_from_dict({"preset": "vlp16", "range_sigma": 0.0}).range_sigma == 0.0


def test_bad_scan_inputs_raise_input_error(envisat: Target) -> None:
    s = make_sensor("goldeneye")
    with pytest.raises(InputError):
        s.scan(envisat, np.eye(3), np.random.default_rng(0))
    with pytest.raises(InputError):
        s.scan(envisat, np.diag([1.0, 1.0, -1.0, 1.0]), np.random.default_rng(0))
    with pytest.raises(InputError, match="rng"):
        s.scan(envisat, look_at([40.0, 0, 0]), None)  # type: ignore[arg-type]
