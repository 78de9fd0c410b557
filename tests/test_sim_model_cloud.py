"""Paper 1's data generation: one model cloud per target, HPR per pose (``model_cloud``)."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError
from relnav.geometry import from_rt
from relnav.sim import model_cloud as mcmod
from relnav.sim.model_cloud import fibonacci_sphere, model_cloud_for, voxel_representatives
from relnav.sim.presets import get_preset
from relnav.sim.scenario import _build_sensor
from relnav.sim.sensors import make_sensor, sensor_from_dict
from relnav.sim.targets import Target, procedural_target


@pytest.fixture(scope="module")
def voyager() -> Target:
    return procedural_target("voyager")


def _look_at(p) -> np.ndarray:
    p = np.asarray(p, dtype=float)
    x = -p / np.linalg.norm(p)
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    return from_rt(np.column_stack([x, y, np.cross(x, y)]), p)


def _orbit_poses(n: int = 2, step_deg: float = 2.0, r: float = 40.0) -> list[np.ndarray]:
    a = np.radians(step_deg) * np.arange(n)
    return [_look_at([r * np.cos(t), r * np.sin(t), 8.0]) for t in a]


def _sensor(**kw):
    return make_sensor("surface-hpr", n_points=200, model_views=200, model_resolution=48, **kw)


def test_fibonacci_sphere_unit_and_spread() -> None:
    d = fibonacci_sphere(800)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert np.abs(d.mean(axis=0)).max() < 0.01  # no preferred direction


def test_random_thinning_is_nested_and_calibrated(voyager: Target) -> None:
    kw = dict(n_views=100, resolution=32, thinning="random", seed=1)
    small = model_cloud_for(voyager, size=300, **kw).points
    big = model_cloud_for(voyager, size=600, **kw).points
    rows = {r.tobytes() for r in big}
    assert small.shape == (300, 3) and all(r.tobytes() in rows for r in small)
    s = _sensor(model_cloud="fixed")
    mc = s.model_cloud_of(voyager)
    assert mc.thinning == "random" and mc.points.shape[0] > 200
    # calibrated at 3 bounding radii (HPR keeps fewer points from farther away)
    r = 3.0 * voyager.bounding_sphere[1]
    poses = _orbit_poses(4, 90.0, r=r)
    counts = [len(s.scan(voyager, T, np.random.default_rng(0))) for T in poses]
    assert 0.6 * 200 < np.mean(counts) < 1.4 * 200


def test_voxel_representatives_one_sample_per_voxel() -> None:
    rng = np.random.default_rng(3)
    P = rng.uniform(0.0, 1.0, (5000, 3))
    idx = voxel_representatives(P, 0.25)
    assert idx.size == 64 and np.all(np.diff(idx) > 0)
    cells = np.floor((P[idx] - P.min(axis=0)) / 0.25).astype(int)
    assert len({tuple(c) for c in cells}) == 64


@pytest.mark.parametrize("thinning", ["random", "voxel"])
def test_consecutive_noiseless_scans_share_points_of_one_cloud(voyager: Target, thinning) -> None:
    s = _sensor(model_cloud="fixed", model_thinning=thinning)
    mc = s.model_cloud_of(voyager)
    T0, T1 = _orbit_poses()
    a = s.scan(voyager, T0, np.random.default_rng(0))
    b = s.scan(voyager, T1, np.random.default_rng(1))
    # every point of a scan is, bit for bit, a model point seen from that pose
    for T, scan in ((T0, a), (T1, b)):
        R, t = T[:3, :3], T[:3, 3]
        model_s = (mc.points - t) @ R
        rows = {r.tobytes() for r in model_s}
        assert all(p.tobytes() in rows for p in scan)
    # and consecutive scans share most of their model points (same cloud, nearby poses)
    back_a = a @ T0[:3, :3].T + T0[:3, 3]
    back_b = b @ T1[:3, :3].T + T1[:3, 3]
    ia = np.argmin(((back_a[:, None] - mc.points[None]) ** 2).sum(-1), axis=1)
    ib = np.argmin(((back_b[:, None] - mc.points[None]) ** 2).sum(-1), axis=1)
    np.testing.assert_allclose(mc.points[ia], back_a, atol=1e-9)
    shared = np.intersect1d(ia, ib).size
    assert shared > 0.7 * min(len(a), len(b))


def test_resample_option_restores_fresh_samples(voyager: Target) -> None:
    s = _sensor(model_cloud="resample")
    T0, T1 = _orbit_poses()
    a = s.scan(voyager, T0, np.random.default_rng(0))
    b = s.scan(voyager, T1, np.random.default_rng(1))
    back_a = a @ T0[:3, :3].T + T0[:3, 3]
    back_b = b @ T1[:3, :3].T + T1[:3, 3]
    d = np.sqrt(((back_a[:, None] - back_b[None]) ** 2).sum(-1)).min(axis=1)
    assert (d < 1e-9).sum() == 0  # no point repeats
    assert len(a) > 50 and len(b) > 50


def test_model_cloud_deterministic_by_seed(voyager: Target) -> None:
    kw = dict(n_views=100, resolution=32, thinning="random", size=500)
    a = model_cloud_for(voyager, seed=5, **kw).points.copy()
    mcmod._CACHE.clear()
    mcmod._RAW.clear()
    b = model_cloud_for(voyager, seed=5, **kw).points
    c = model_cloud_for(voyager, seed=6, **kw).points
    np.testing.assert_array_equal(a, b)
    assert a.shape != c.shape or not np.array_equal(a, c)
    # same seed, same scans: the noise comes from the frame rng only
    s1 = _sensor(model_cloud="fixed", noise_sigma=0.01, model_seed=2)
    s2 = sensor_from_dict(s1.to_dict())
    T = _orbit_poses(1)[0]
    np.testing.assert_array_equal(
        s1.scan(voyager, T, np.random.default_rng(9)), s2.scan(voyager, T, np.random.default_rng(9))
    )


def test_presets_default_to_fixed_and_option_restores_resample() -> None:
    for name in ("sim-eoi", "sim-helical", "sim-voyager", "sim-orion", "sim-bennu"):
        fixed = _build_sensor(get_preset(name, frames=3).sensors[0])
        res = _build_sensor(get_preset(name, frames=3, model_cloud="resample").sensors[0])
        assert fixed.model_cloud == "fixed" and res.model_cloud == "resample"
    with pytest.raises(ConfigError, match="model_cloud"):
        get_preset("sim-voyager", model_cloud="sometimes")
    with pytest.raises(ConfigError, match="unknown option"):
        get_preset("real-fb", model_cloud="fixed")


def test_bad_model_cloud_parameters() -> None:
    for kw in (
        dict(model_cloud="both"),
        dict(model_views=0),
        dict(model_resolution=1),
        dict(model_voxel=-0.1),
        dict(model_voxel=0.0),
        dict(model_thinning="octree"),
        dict(model_size=0),
        dict(model_seed=-1),
    ):
        with pytest.raises(ConfigError):
            make_sensor("surface-hpr", **kw)
