"""Sparse ICP (sicp-point, sicp-plane): shrink operator, known answers, robustness, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.geometry.rotations import rotation_angle
from relnav.geometry.se3 import exp_se3, from_rt, invert, transform_points
from relnav.registration import PreparedRegistration, available_methods, get_registration
from relnav.registration.sparse_icp import SparseICP, shrink

SICP_METHODS = ["sicp-point", "sicp-plane"]


def bumpy_surface(n: int, rng: np.random.Generator, size: float = 1.0) -> np.ndarray:
    """Random samples of a non-symmetric bumpy surface patch (``size`` m across)."""
    xy = rng.uniform(-0.5, 0.5, (n, 2))
    centres = np.array([[0.2, 0.1], [-0.25, 0.3], [0.05, -0.3], [-0.3, -0.2]])
    heights = np.array([0.15, -0.1, 0.12, 0.08])
    z = 0.1 * xy[:, 0] ** 2
    for c, h in zip(centres, heights, strict=True):
        z += h * np.exp(-np.sum((xy - c) ** 2, axis=1) / 0.02)
    return size * np.column_stack([xy, z])


def motion(rng: np.random.Generator, rot_deg: float, trans: float) -> np.ndarray:
    xi = rng.normal(size=6)
    xi[:3] *= trans / np.linalg.norm(xi[:3])
    xi[3:] *= np.deg2rad(rot_deg) / np.linalg.norm(xi[3:])
    return exp_se3(xi)


def errors(gt: np.ndarray, T: np.ndarray, pts: np.ndarray) -> tuple[float, float]:
    """Rotation error (deg) and RMS displacement of ``pts`` (m)."""
    d = transform_points(T, pts) - transform_points(gt, pts)
    rot = float(np.rad2deg(rotation_angle((invert(gt) @ T)[:3, :3])))
    return rot, float(np.sqrt((d**2).sum(axis=1).mean()))


def look_at(pos: np.ndarray) -> np.ndarray:
    x = -pos / np.linalg.norm(pos)
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    return from_rt(np.column_stack([x, y, np.cross(x, y)]), pos)


@pytest.fixture(scope="module")
def surface_pair():
    rng = np.random.default_rng(7)
    tgt = bumpy_surface(1500, rng)
    gt = motion(rng, 3.0, 0.03)
    src = transform_points(invert(gt), bumpy_surface(1500, rng))
    return src, tgt, gt


# --------------------------------------------------------------------------- shrink operator


@pytest.mark.parametrize("mu", [1.0, 10.0, 100.0])
@pytest.mark.parametrize("p", [0.5, 0.8, 1.0])
def test_shrink_minimises_the_lp_proximal_objective(mu, p):
    """``shrink`` ≈ argmin |z|^p + μ/2 (z − h)² (brute force on a fine grid)."""
    hs = np.linspace(0.01, 3.0, 40)
    z = shrink(hs, mu, p)
    grid = np.linspace(0.0, 3.0, 60001)
    for h, zz in zip(hs, z, strict=True):
        f = np.abs(grid) ** p + mu / 2 * (grid - h) ** 2
        fz = abs(zz) ** p + mu / 2 * (zz - h) ** 2
        assert fz - f.min() < 1e-4 * max(1.0, f.min())
        assert 0.0 <= zz <= h  # shrinks towards 0, never past it


def test_shrink_known_values():
    # p = 1: soft thresholding, z = max(0, 1 − 1/(μ|h|)) h
    h = np.array([[0.05, 0.0, 0.0], [0.3, 0.4, 0.0]])
    z = shrink(h, 10.0, 1.0)
    np.testing.assert_allclose(z[0], 0.0)
    np.testing.assert_allclose(z[1], (1 - 1 / (10 * 0.5)) * h[1])
    # p = 0.5, μ = 10: threshold h_a = B_a + (p/μ) B_a^(p−1) with B_a = 0.1^(2/3)
    ba = 0.1 ** (2 / 3)
    ha = ba + 0.05 * ba**-0.5
    assert shrink(np.array([ha * 0.999]), 10.0, 0.5)[0] == 0.0
    assert shrink(np.array([ha * 1.001]), 10.0, 0.5)[0] > 0.0


# --------------------------------------------------------------------------- known answers


def test_registry_and_protocol():
    methods = available_methods()
    for m in SICP_METHODS:
        assert m in methods
        reg = get_registration(m)
        assert isinstance(reg, PreparedRegistration)
        assert (reg.p, reg.mu, reg.max_icp) == (0.5, 10.0, 20)  # paper 1 / Langlois
    assert get_registration("sicp-plane:paper").thresholds == "paper"
    from relnav.errors import ConfigError

    with pytest.raises(ConfigError):
        SparseICP("point", p=1.5)
    with pytest.raises(ConfigError):
        get_registration("sicp-point:bogus")


@pytest.mark.parametrize("method", SICP_METHODS)
def test_exact_recovery_same_points(method):
    rng = np.random.default_rng(3)
    tgt = bumpy_surface(800, rng)
    gt = motion(rng, 3.0, 0.03)
    src = transform_points(invert(gt), tgt[rng.permutation(800)[:640]])
    res = get_registration(method, max_icp=100).register(src, tgt)
    assert res.ok and res.converged, res.message
    rot, disp = errors(gt, res.T_target_source, src)
    assert rot < 1e-3 and disp < 1e-5, (rot, disp)
    assert res.fitness == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("method", "tol_deg", "tol_m"), [("sicp-point", 0.6, 0.01), ("sicp-plane", 0.1, 0.002)]
)
def test_recovers_small_motion_independent_sampling(method, tol_deg, tol_m, surface_pair):
    src, tgt, gt = surface_pair
    res = get_registration(method).register(src, tgt)
    assert res.ok, res.message
    rot, disp = errors(gt, res.T_target_source, src)
    assert rot < tol_deg and disp < tol_m, (rot, disp)  # from 3° / ≈ 0.037 m
    assert res.covariance is not None and res.covariance.shape == (6, 6)
    assert set(res.timings) >= {"prepare", "nn", "solve"}


@pytest.mark.parametrize("seed", [0, 1])
def test_recovers_small_motion_on_satellite_scans(seed):
    sim_targets = pytest.importorskip("relnav.sim.targets")
    sim_sensors = pytest.importorskip("relnav.sim.sensors")
    rng = np.random.default_rng(seed)
    tg = sim_targets.get_target("voyager")
    sensor = sim_sensors.make_sensor("surface-hpr")
    d = rng.normal(size=3)
    T1 = look_at(d / np.linalg.norm(d) * 3.0 * tg.extent)
    T2 = motion(rng, 4.0, 0.04 * tg.extent) @ T1  # sensor moves about the target centre
    tgt, src = sensor.scan(tg, T1, rng), sensor.scan(tg, T2, rng)
    gt = invert(T1) @ T2
    for method in SICP_METHODS:
        res = get_registration(method).register(src, tgt)
        assert res.ok, (method, res.message)
        rot, disp = errors(gt, res.T_target_source, src)
        assert rot < 1.0 and disp < 0.01 * tg.extent, (method, rot, disp / tg.extent)


def test_sparse_norm_resists_outliers(surface_pair):
    """ℓ0.5 keeps its accuracy with 30 % gross outliers in the source (no gate, no rule)."""
    src, tgt, gt = surface_pair
    rng = np.random.default_rng(11)
    outliers = rng.uniform(-0.5, 0.5, (450, 3)) * [1.0, 1.0, 0.6] + [0.0, 0.0, 0.35]
    src_o = np.vstack([src, outliers])
    res = get_registration("sicp-plane").register(src_o, tgt)
    assert res.ok
    rot, disp = errors(gt, res.T_target_source, src)
    assert rot < 0.2 and disp < 0.003, (rot, disp)
    assert res.n_inliers < 1500 + 0.1 * 450 < res.n_correspondences == 1950


def test_scale_invariance_of_default_normalisation(surface_pair):
    src, tgt, _ = surface_pair
    for method in SICP_METHODS:
        a = get_registration(method).register(src, tgt)
        b = get_registration(method).register(300.0 * src, 300.0 * tgt)
        np.testing.assert_allclose(b.T_target_source[:3, :3], a.T_target_source[:3, :3], atol=1e-8)
        np.testing.assert_allclose(
            b.T_target_source[:3, 3], 300.0 * a.T_target_source[:3, 3], rtol=1e-6, atol=1e-8
        )
    paper = get_registration("sicp-point:paper").register(src, tgt)
    assert paper.info["scale"] == 1.0 and paper.info["inlier_distance"] == 0.01


def test_penalty_mode_and_identity(surface_pair):
    _, tgt, _ = surface_pair
    for method in SICP_METHODS:
        res = get_registration(method, use_penalty=True).register(tgt, tgt)
        assert res.ok
        np.testing.assert_allclose(res.T_target_source, np.eye(4), atol=1e-9)


# --------------------------------------------------------------------------- bad input

_GOOD = np.random.default_rng(9).normal(size=(200, 3))
_LINE = np.outer(np.linspace(0, 1, 50), [1.0, 2.0, 3.0])
BAD_CASES = {
    "empty": (np.zeros((0, 3)), _GOOD, None),
    "two points": (_GOOD[:2], _GOOD, None),
    "coincident": (np.ones((50, 3)), _GOOD, None),
    "collinear": (_LINE, _GOOD, None),
    "all nan": (np.full((50, 3), np.nan), _GOOD, None),
    "target empty": (_GOOD, np.zeros((0, 3)), None),
    "wrong shape": (_GOOD[:, :2], _GOOD, None),
    "nan init": (_GOOD, _GOOD, np.full((4, 4), np.nan)),
}


@pytest.mark.parametrize("method", SICP_METHODS)
@pytest.mark.parametrize("case", list(BAD_CASES))
def test_bad_input_is_flagged_not_raised(method, case):
    src, tgt, init = BAD_CASES[case]
    res = get_registration(method).register(src, tgt, init=init)
    assert res.status in ("degenerate", "failed") and res.message
    assert np.isfinite(res.T_target_source).all()


def test_gate_without_neighbours_fails():
    res = get_registration("sicp-point", max_correspondence_distance=0.1).register(
        _GOOD + 100.0, _GOOD
    )
    assert res.status == "failed" and "nearest neighbours" in res.message


def test_partial_nan_points_are_dropped(surface_pair):
    src, tgt, _ = surface_pair
    dirty = src.copy()
    dirty[::100] = np.nan
    a = get_registration("sicp-plane").register(dirty, tgt)
    b = get_registration("sicp-plane").register(src[np.isfinite(dirty).all(axis=1)], tgt)
    assert a.ok and a.info["n_dropped_source"] == 15
    np.testing.assert_allclose(a.T_target_source, b.T_target_source, atol=1e-12)
