"""The navigator's non-planarity gain (``nonplanar_gain``): less information from map patches that
are not planes, so that the directions only they constrain come from the motion model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nav_scenarios import flash_orbit
from relnav.errors import ConfigError
from relnav.geometry.se3 import log_se3
from relnav.navigation import Navigator, VoxelMap
from relnav.navigation.gicp import left_information, solve_scan_to_map
from relnav.navigation.voxel_map import plane_information
from relnav.pipeline import run_sequence
from relnav.sim.scenario import simulate


def _normal_variance(info: np.ndarray, n: np.ndarray) -> float:
    """``λ₀ + σ_n²`` of a patch from its information ``n nᵀ/(λ₀ + σ_n²) + (I − n nᵀ)/σ_p²``."""
    return 1.0 / float(n @ info @ n)


def test_gain_leaves_a_plane_alone_and_inflates_an_edge(rng):
    """A planar neighbourhood keeps its information; one straddling a right-angled edge gets the
    variance ``λ₀ (1 + γ λ₀/λ₁) + σ_n²`` along its normal."""
    sp, sn, gamma = 0.3, 0.01, 100.0
    plane = np.c_[rng.uniform(-1, 1, (10, 2)), np.zeros(10)]
    nb = np.arange(10)[None]
    i0, _ = plane_information(plane, nb, sp, sn)
    i1, _ = plane_information(plane, nb, sp, sn, nonplanar_gain=gamma)
    np.testing.assert_allclose(i1, i0, rtol=1e-12)

    # five points on the floor z = 0 (x < 0), five on the wall x = 0 (z > 0)
    u = rng.uniform(0.1, 1.0, (5, 2))
    edge = np.vstack([np.c_[-u[:, 0], u[:, 1], np.zeros(5)], np.c_[np.zeros(5), u[:, 1], u[:, 0]]])
    e0, n0 = plane_information(edge, nb, sp, sn)
    e1, n1 = plane_information(edge, nb, sp, sn, nonplanar_gain=gamma)
    np.testing.assert_allclose(n1, n0)
    lam = np.linalg.eigvalsh(np.cov(edge.T, bias=True))
    assert lam[0] / lam[1] > 0.01  # not a plane
    np.testing.assert_allclose(_normal_variance(e0[0], n0[0]), lam[0] + sn**2, rtol=1e-9)
    expected = lam[0] * (1 + gamma * lam[0] / lam[1]) + sn**2
    np.testing.assert_allclose(_normal_variance(e1[0], n1[0]), expected, rtol=1e-9)
    # along the surface nothing changes
    t = np.cross(n0[0], [0.0, 1.0, 0.0])
    t /= np.linalg.norm(t)
    assert float(t @ e1[0] @ t) == pytest.approx(1.0 / sp**2, rel=1e-9)


def _rot_z(a: float) -> np.ndarray:
    T = np.eye(4)
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    return T


def _can(radius: float = 3.0, half_height: float = 2.0, s: float = 0.4) -> tuple[np.ndarray, float]:
    """The visible side of a can (axis z): its wall and its flat lid sampled on a fixed angular
    pattern of spacing ``s``; returns the points and the pattern's angular step (rad)."""
    n_th = int(2 * math.pi * radius / s)
    th = np.arange(n_th) * 2 * math.pi / n_th
    th = th[(th > 0.3) & (th < 2.5)]
    TH, Z = np.meshgrid(th, np.arange(-half_height, half_height + 1e-9, s))
    parts = [np.c_[radius * np.cos(TH.ravel()), radius * np.sin(TH.ravel()), Z.ravel()]]
    for r in np.arange(s, radius, s):
        m = max(int(2 * math.pi * r / s), 6)
        t = np.arange(m) * 2 * math.pi / m
        t = t[(t > 0.3) & (t < 2.5)]
        parts.append(np.c_[r * np.cos(t), r * np.sin(t), np.full(len(t), half_height)])
    return np.vstack(parts), 2 * math.pi / n_th


def test_gain_leaves_an_aliased_axis_rotation_more_to_the_motion_model():
    """A fixed pixel pattern on a body of revolution: the sensor turned by 0.4 of the pattern's
    step about the can's axis, and the new scan repeats the old one point for point. The model's
    prediction is the true pose (1σ 1°); the map's samples pull the registration back towards
    "no motion". The gain weakens the rim's fake information about that rotation, so the
    registered rotation stays nearer the prediction, the more so the larger the gain."""
    P, step = _can()
    s = 0.4
    T_true = _rot_z(0.4 * step)
    Lam = left_information(T_true, np.diag([0.05**2] * 3 + [math.radians(1.0) ** 2] * 3))
    rot, info = [], []
    for gamma in (0.0, 100.0, 1000.0):
        vm = VoxelMap(0.3 * s, noise_floor=0.03 * s, inplane_sigma=3 * s, nonplanar_gain=gamma)
        vm.insert(P, 0)
        fit = solve_scan_to_map(P, vm, T_true, T_true, Lam, 1.0, 3.0, 30, 1e-6, 1e-7)
        rot.append(float(log_se3(fit.T)[5]))
        info.append(float(fit.H[5, 5]))
    true = 0.4 * step
    assert 0 < rot[0] < rot[1] < rot[2] < true, np.degrees(rot)
    assert info[0] > info[1] > info[2] > 0, info
    # plain: the registration takes 70 % of the true rotation away; γ = 1000: about half
    assert rot[0] < 0.4 * true and rot[2] > 0.5 * true, np.degrees(rot)


def test_navigator_passes_the_gain_to_its_map_and_checks_it(tmp_path):
    """``nonplanar_gain`` reaches the map; a negative one is one ConfigError line; on a short
    sparse orbit of an asteroid (smooth, nearly planar patches) the gain barely changes the
    steps."""
    with pytest.raises(ConfigError, match="nonplanar_gain"):
        Navigator(**{"map.nonplanar_gain": -1.0})
    sc = flash_orbit("nav-nonplanar", max_frames=8)
    simulate(sc, tmp_path / "seq")
    from relnav.io.sequences import ScanSequence

    seq = ScanSequence(tmp_path / "seq")
    nav = Navigator(initial_pose=seq.gt_poses[0], **{"map.nonplanar_gain": 100.0})
    for scan in seq:
        nav.register_frame(scan)
    assert nav.map is not None and nav.map.nonplanar_gain == 100.0
    off = run_sequence(seq, "relnav")
    on = run_sequence(seq, "relnav", **{"map.nonplanar_gain": 100.0})
    d = [np.linalg.norm(a[:3, 3] - b[:3, 3]) for a, b in zip(off.poses, on.poses, strict=True)]
    assert max(d) < 0.1, d  # measured 0.03 m
