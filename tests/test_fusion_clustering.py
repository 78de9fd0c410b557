"""Paper 2's plane clustering: shape factors, plane/line growing, LIDAR projection (§G.4)."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError, InputError
from relnav.fusion.clustering import (
    EDGE,
    LINEAR,
    PLANAR,
    cluster_and_project,
    shape_factors,
)


def _grid(u: np.ndarray, v: np.ndarray, origin, e1, e2) -> np.ndarray:
    uu, vv = np.meshgrid(u, v)
    return np.asarray(origin) + uu.reshape(-1, 1) * e1 + vv.reshape(-1, 1) * e2


def _box_faces(rng: np.random.Generator, step: float = 0.01, noise: float = 0.0005):
    """Three visible faces of a 0.6 x 0.5 x 0.4 m box with corner at the origin (camera)."""
    ex, ey, ez = np.eye(3)
    a = np.arange(step / 2, 0.6, step)
    b = np.arange(step / 2, 0.5, step)
    c = np.arange(step / 2, 0.4, step)
    faces = [
        _grid(a, b, (0, 0, 0), ex, ey),  # z = 0, normal z
        _grid(a, c, (0, 0, 0), ex, ez),  # y = 0, normal y
        _grid(b, c, (0, 0, 0), ey, ez),  # x = 0, normal x
    ]
    P = np.vstack(faces)
    return P + rng.normal(scale=noise, size=P.shape)


def test_shape_factors_sum_and_labels(rng: np.random.Generator) -> None:
    ex, ey, _ = np.eye(3)
    g = np.arange(0.0, 0.3, 0.01)
    plane = _grid(g, g, (0, 0, 0), ex, ey) + 1e-4 * rng.normal(size=(g.size**2, 3))
    sf = shape_factors(plane, k=20)
    np.testing.assert_allclose(sf.F_L + sf.F_H + sf.F_S, 1.0, atol=1e-12)
    inner = np.all((plane[:, :2] > 0.035) & (plane[:, :2] < 0.255), axis=1)
    assert np.mean(sf.labels[inner] == PLANAR) > 0.99  # (random samples look edge-like)
    border = (plane[:, 1] < 0.005) & (plane[:, 0] > 0.05) & (plane[:, 0] < 0.25)
    assert np.mean(sf.labels[border] == EDGE) > 0.8  # a plane's border is "edge", not planar
    np.testing.assert_allclose(np.abs(sf.normals[:, 2]), 1.0, atol=1e-2)
    line = np.c_[np.linspace(0, 1, 400), 1e-4 * rng.normal(size=(400, 2))]
    sf = shape_factors(line, k=20)
    assert np.mean(sf.labels == LINEAR) > 0.95
    np.testing.assert_allclose(np.abs(sf.directions[:, 0]), 1.0, atol=1e-2)
    assert shape_factors(np.zeros((2, 3))).labels.tolist() == [0, 0]


def test_planes_found_and_lidar_projected(rng: np.random.Generator) -> None:
    cam = _box_faces(rng)
    # LIDAR: points on the three faces with 5 mm noise + 20 far outliers
    m = 300
    on = np.zeros((m, 3))
    which = rng.integers(0, 3, m)
    on[:, 0] = rng.uniform(0.05, 0.45, m)
    on[:, 1] = rng.uniform(0.05, 0.35, m)
    on[:, 2] = rng.uniform(0.05, 0.35, m)
    for f in range(3):
        on[which == (2 - f), f] = 0.0  # f-th coordinate zero on face 2-f
    true_axis = np.array([2, 1, 0])[which]  # coordinate that is zero
    lid = on + rng.normal(scale=0.005, size=on.shape)
    out = rng.uniform(-0.3, 0.3, (20, 3)) + np.array([0.3, 0.3, 0.8])
    L = np.vstack([lid, out])
    res = cluster_and_project(cam, L, delta=0.03)
    fused, kept, planes, _lines = res
    assert len(planes) >= 3
    normals = np.abs(np.array([p.normal for p in planes[:3]]))
    assert np.all(np.sort(normals.max(axis=1)) > 0.999)
    assert kept[:m].mean() > 0.9
    assert not kept[m:].any()  # far outliers removed
    np.testing.assert_array_equal(fused.shape, (cam.shape[0] + kept.sum(), 3))
    # kept points lie on their true face after projection (the camera's plane fit)
    k = np.flatnonzero(kept[:m])
    resid = res.projected[k, true_axis[k]]
    assert np.max(np.abs(resid)) < 0.002
    # and projection removed the LIDAR noise component normal to the face
    assert np.std(resid) < 0.2 * np.std(lid[k, true_axis[k]])
    assert res.info["n_planes"] == len(planes) and res.delta == 0.03
    assert np.all(res.segment[~kept] == -1)
    # planes are CGA vectors n + d e∞
    v = planes[0].cga()
    np.testing.assert_allclose(v[:3], planes[0].normal)
    assert v[3] == v[4] == pytest.approx(planes[0].d)


def test_lines_and_parallel_plane_delta(rng: np.random.Generator) -> None:
    # a 4 cm thick panel (two parallel 0.5 x 0.5 planes) and a rod along y
    ex, ey, _ = np.eye(3)
    g = np.arange(0.005, 0.5, 0.01)
    top = _grid(g, g, (0, 0, 0.04), ex, ey)
    bottom = _grid(g, g, (0, 0, 0.0), ex, ey)
    rod = np.c_[np.full(300, 1.0), np.linspace(0, 0.6, 300), np.full(300, 0.5)]
    cam = np.vstack([top, bottom, rod]) + rng.normal(scale=2e-4, size=(2 * g.size**2 + 300, 3))
    lid = np.vstack(
        [
            np.c_[rng.uniform(0.1, 0.4, (50, 2)), np.full(50, 0.043)],
            np.c_[np.full(20, 1.004), rng.uniform(0.1, 0.5, 20), np.full(20, 0.497)],
        ]
    )
    res = cluster_and_project(cam, lid, plane_dist=0.005)
    assert len(res.planes) == 2 and len(res.lines) >= 1
    assert res.delta == pytest.approx(0.08, abs=2e-3)  # 2 x 4 cm
    line = res.lines[0]
    assert abs(line.direction[1]) > 0.999
    assert res.kept_mask.all()
    np.testing.assert_allclose(res.projected[:50, 2], 0.04, atol=1e-3)
    np.testing.assert_allclose(res.projected[50:, [0, 2]], [[1.0, 0.5]] * 20, atol=1e-3)
    r2 = cluster_and_project(cam, lid, plane_dist=0.005, delta="resolution")
    assert r2.delta == pytest.approx(2 * r2.info["resolution_camera"])


def test_edge_cases(rng: np.random.Generator) -> None:
    cam = _box_faces(rng, step=0.02)
    res = cluster_and_project(cam, np.zeros((0, 3)))
    assert res.kept_mask.shape == (0,) and res.fused_points.shape == cam.shape
    res = cluster_and_project(cam[:5], rng.normal(size=(10, 3)))
    assert not res.kept_mask.any() and res.info["reason"]
    with pytest.raises(InputError):
        cluster_and_project(cam, np.zeros((4, 2)))
    with pytest.raises(InputError):
        cluster_and_project(np.full((30, 3), np.nan), np.zeros((4, 3)))
    with pytest.raises(ConfigError):
        cluster_and_project(cam, cam[:10], sigma_deg=0)
    with pytest.raises(ConfigError):
        cluster_and_project(cam, cam[:10], delta="bogus")  # type: ignore[arg-type]
