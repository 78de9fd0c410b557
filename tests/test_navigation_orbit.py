"""The azimuth about a body of revolution from a free relative orbit (relnav.navigation.orbit)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relnav.geometry.rotations import rotvec_to_matrix
from relnav.navigation.orbit import correct_azimuth, orbit_turns

N_LEO = 2 * math.pi / 5553.6  # rad/s


def _body_of_revolution(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A capsule-like cone frustum about z with its base cap: points and unit normals."""
    n = 3000
    z = rng.uniform(0.0, 3.0, n)
    th = rng.uniform(0.0, 2 * np.pi, n)
    r = 2.5 - 0.5 * z
    side = np.column_stack([r * np.cos(th), r * np.sin(th), z - 1.0])
    n_side = np.column_stack([np.cos(th), np.sin(th), np.full(n, 0.5)])
    m = n // 3
    rc = 2.5 * np.sqrt(rng.uniform(0, 1, m))
    tc = rng.uniform(0.0, 2 * np.pi, m)
    cap = np.column_stack([rc * np.cos(tc), rc * np.sin(tc), np.full(m, -1.0)])
    n_cap = np.tile([0.0, 0.0, -1.0], (m, 1))
    N = np.vstack([n_side, n_cap])
    return np.vstack([side, cap]), N / np.linalg.norm(N, axis=1, keepdims=True)


def _box() -> tuple[np.ndarray, np.ndarray]:
    """Surface samples of a 4 × 2 × 1.5 m box and their normals."""
    rng = np.random.default_rng(3)
    half = np.array([2.0, 1.0, 0.75])
    P = rng.uniform(-1, 1, (3000, 3)) * half
    face = rng.integers(0, 3, 3000)
    sign = np.sign(rng.uniform(-1, 1, 3000))
    P[np.arange(3000), face] = sign * half[face]
    N = np.zeros_like(P)
    N[np.arange(3000), face] = sign
    return P, N


def _looking_at_origin(p: np.ndarray) -> np.ndarray:
    """``T_target_sensor`` at ``p`` with the optical axis (sensor z) towards the origin."""
    zc = -p / np.linalg.norm(p)
    up = np.array([0.0, 0.0, 1.0]) if abs(zc[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    xc = np.cross(up, zc)
    xc /= np.linalg.norm(xc)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([xc, np.cross(zc, xc), zc])
    T[:3, 3] = p
    return T


def _trajectory(A, B, frames: int = 120, helical: bool = False):
    """Poses and times of a free orbit ``A cos nt + B sin nt`` (one orbit), or of a helix."""
    t = np.linspace(0.0, 5553.6, frames)
    ph = N_LEO * t
    P = np.outer(np.cos(ph), A) + np.outer(np.sin(ph), B)
    if helical:  # closing in and climbing at constant rates: no free orbit
        P *= np.linspace(1.0, 0.5, frames)[:, None]
        P[:, 2] += np.linspace(0.0, 30.0, frames)
    return np.stack([_looking_at_origin(p) for p in P]), t


def _lagging(T: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """The navigator's failure on a body of revolution: its azimuth about z lags the truth at
    a constant rate (``fraction`` of a turn per orbit, a biased azimuth rate), plus 2 cm of
    position noise."""
    out = T.copy()
    for i in range(len(T)):
        lag = 2 * np.pi * fraction * i / (len(T) - 1)
        R = rotvec_to_matrix(np.array([0.0, 0.0, -lag]))
        out[i, :3, :3] = R @ T[i, :3, :3]
        out[i, :3, 3] = R @ T[i, :3, 3] + (rng.normal(0, 0.02, 3) if i else 0.0)
    return out


def _position_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.linalg.norm(a[:, :3, 3] - b[:, :3, 3], axis=1)))


@pytest.mark.parametrize(
    "A, B",
    [
        ((35.0, 0.0, 10.0), (0.0, 60.0, -8.0)),  # an inclined inspection ellipse
        ((40.0, 0.0, 0.0), (0.0, 0.3, 45.0)),  # passes 0.3 m from the axis
    ],
)
def test_lagging_azimuth_is_taken_from_the_orbit(A, B):
    rng = np.random.default_rng(0)
    pts, nrm = _body_of_revolution(rng)
    truth, t = _trajectory(np.array(A), np.array(B))
    est = _lagging(truth, 0.25, rng)
    assert _position_error(est, truth) > 10.0
    out, info = correct_azimuth(est, t, pts, nrm, N_LEO)
    assert info.applied, info.reason
    assert abs(float(info.axis[2])) > 0.99
    assert info.excess > 10.0
    # the positions come back to within a few noise levels, and the attitude with them (a
    # rotation about the axis), also where the path passes the axis and its azimuth is
    # undefined (2 cm there would turn it by degrees)
    assert _position_error(out, truth) < 0.3
    R_err = np.einsum("nji,njk->nik", out[:, :3, :3], truth[:, :3, :3])
    ang = np.degrees(np.arccos(np.clip((np.trace(R_err, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert np.max(ang) < 1.0


@pytest.mark.parametrize(
    "target, lag, helical, n_factor, reason",
    [
        ("revolution", 0.0, False, 1.0, "agrees"),  # the registered azimuth is right
        ("revolution", 0.25, True, 1.0, "not a free orbit"),  # a helical approach
        ("revolution", 0.25, False, 1.2, "not a free orbit"),  # another orbit's mean motion
        ("box", 0.25, False, 1.0, "no body of revolution"),
    ],
)
def test_left_alone(target, lag, helical, n_factor, reason):
    rng = np.random.default_rng(2)
    pts, nrm = _body_of_revolution(rng) if target == "revolution" else _box()
    A, B = np.array([35.0, 0.0, 10.0]), np.array([0.0, 60.0, -8.0])
    truth, t = _trajectory(A, B, helical=helical)
    est = _lagging(truth, lag, rng)
    out, info = correct_azimuth(est, t, pts, nrm, n_factor * N_LEO)
    assert not info.applied and reason in info.reason
    np.testing.assert_array_equal(out, est)


def test_bad_input():
    rng = np.random.default_rng(5)
    pts, nrm = _body_of_revolution(rng)
    truth, t = _trajectory(np.array([35.0, 0.0, 10.0]), np.array([0.0, 60.0, -8.0]))
    with pytest.raises(ValueError, match="mean_motion"):
        correct_azimuth(truth, t, pts, nrm, 0.0)
    with pytest.raises(ValueError, match="times"):
        correct_azimuth(truth, t[:-1], pts, nrm, N_LEO)
    out, info = correct_azimuth(truth[:5], t[:5], pts, nrm, N_LEO)
    assert not info.applied and "too few frames" in info.reason
    np.testing.assert_array_equal(out, truth[:5])
    bad = truth.copy()
    bad[3, 0, 3] = np.nan  # a non-finite pose: left alone, never a crash
    out, info = correct_azimuth(bad, t, pts, nrm, N_LEO)
    assert not info.applied
    np.testing.assert_array_equal(np.isnan(out), np.isnan(bad))
    _, info = correct_azimuth(truth, t, np.zeros((3, 3)), np.zeros((3, 3)), N_LEO)
    assert not info.applied and "no axis" in info.reason


@pytest.mark.parametrize(
    "bad",
    [
        {"orbit.mean_motion": -1e-3},
        {"orbit.mean_motion": float("nan")},
        {"orbit.mean_motion": float("inf")},
        {"orbit.min_excess": float("inf")},
        {"orbit.max_symmetry": 0.0},
        {"orbit.max_misfit": -0.1},
        {"orbit.min_excess": 0.5},
    ],
)
def test_bad_orbit_options_are_one_config_error(bad) -> None:
    from relnav.errors import ConfigError
    from relnav.navigation import Navigator

    with pytest.raises(ConfigError, match=next(iter(bad)).replace(".", r"\.")):
        Navigator(**bad)


def test_navigator_records_its_verdict():
    """With the orbit given, ``finalize`` runs the test and the run records its verdict
    (``run.json``'s options); the poses have one per frame whatever it says."""
    from relnav.pipeline import run_sequence
    from relnav.scan import Scan

    rng = np.random.default_rng(6)
    pts, _ = _body_of_revolution(rng)
    truth, t = _trajectory(np.array([35.0, 0.0, 10.0]), np.array([0.0, 60.0, -8.0]), frames=12)
    scans = []
    for T, tk in zip(truth, t, strict=True):
        Tinv = np.linalg.inv(T)
        P = pts[rng.choice(len(pts), 800, replace=False)] @ Tinv[:3, :3].T + Tinv[:3, 3]
        scans.append(Scan(points=P[P[:, 2] > 0], time=float(tk)))  # roughly what faces it
    run = run_sequence(
        scans, "relnav", initial_pose=truth[0], **{"orbit.mean_motion": N_LEO, "startup.window": 0}
    )
    assert run.poses.shape == (12, 4, 4) and np.all(np.isfinite(run.poses))
    verdict = run.options["finalize"]["orbit"]
    assert verdict["reason"] and isinstance(verdict["applied"], bool)
    off = run_sequence(scans, "relnav", initial_pose=truth[0], **{"startup.window": 0})
    assert "finalize" not in off.options


def test_a_skipped_frame_keeps_times_and_poses_aligned():
    """An unreadable scan (``skip_frame``) still gets a time, so the orbit test sees one time
    per pose (and does not crash) whatever frames were lost."""
    from relnav.navigation import Navigator
    from relnav.scan import Scan

    rng = np.random.default_rng(7)
    pts, _ = _body_of_revolution(rng)
    truth, t = _trajectory(np.array([35.0, 0.0, 10.0]), np.array([0.0, 60.0, -8.0]), frames=12)
    nav = Navigator(initial_pose=truth[0], **{"orbit.mean_motion": N_LEO, "startup.window": 0})
    for k, (T, tk) in enumerate(zip(truth, t, strict=True)):
        if k in (0, 5):  # before the first scan and in the middle
            nav.skip_frame("unreadable")
        Tinv = np.linalg.inv(T)
        P = pts[rng.choice(len(pts), 800, replace=False)] @ Tinv[:3, :3].T + Tinv[:3, 3]
        nav.register_frame(Scan(points=P[P[:, 2] > 0], time=float(tk)))
    poses = nav.finalize()
    assert len(poses) == len(nav._times) == 14
    assert np.all(np.isfinite(poses)) and nav.orbit is not None


def test_orbit_report_rebuilds_the_applied_turns():
    """An applied correction's report carries the centre and the per-frame turns, and
    orbit_turns rebuilds from it the transforms that took the poses to the corrected ones; no
    turns for a correction that was not applied."""
    rng = np.random.default_rng(0)
    pts, nrm = _body_of_revolution(rng)
    truth, t = _trajectory(np.array([35.0, 0.0, 10.0]), np.array([0.0, 60.0, -8.0]))
    est = _lagging(truth, 0.25, rng)
    out, info = correct_azimuth(est, t, pts, nrm, N_LEO)
    assert info.applied, info.reason
    G = orbit_turns(info.as_dict())
    assert G is not None and G.shape == (len(est), 4, 4)
    np.testing.assert_allclose(G @ est, out, atol=1e-9)
    _, kept = correct_azimuth(truth, t, pts, nrm, N_LEO)
    assert not kept.applied and orbit_turns(kept.as_dict()) is None
    assert "correction_deg" not in kept.as_dict()


def test_relative_state_observes_the_orbit_corrected_azimuth(rng):
    """relative_state turns each frame by the run's recorded orbit correction (pose and
    information, StateRecord.turned) before the filter, unless orbit_azimuth=False; the
    information is turned as a left perturbation is (Ad_G)."""
    from types import SimpleNamespace

    from relnav.geometry.se3 import adjoint, invert
    from relnav.navigation.state import StateRecord, relative_state

    poses = []
    for k in range(6):
        T = np.eye(4)
        T[:3, :3] = rotvec_to_matrix([0.0, 0.0, 0.02 * k])
        T[:3, 3] = [40.0, 2.0 * k, 1.0]
        poses.append(T)
    A = rng.normal(size=(6, 6))
    H = A @ A.T + np.eye(6)
    frames = [StateRecord("first", poses[0], H, None)] + [
        StateRecord("ok", T, H, 1e-4 * np.eye(6)) for T in poses[1:]
    ]
    angles = [0.0, 5.0, 10.0, 15.0, 20.0, 25.0]
    report = {"applied": True, "axis": [0.0, 0.0, 1.0], "center": [1.0, 0.0, 0.0],
              "correction_deg": angles, "misfit_m": 0.04, "scale_m": 40.0}  # fmt: skip
    run = SimpleNamespace(
        steps=frames,
        timestamps=np.arange(6.0),
        method="relnav",
        options={"finalize": {"orbit": report}},
    )
    res = relative_state(run)
    plain = relative_state(run, orbit_azimuth=False)
    G = orbit_turns(report)
    for k in range(6):
        np.testing.assert_allclose(res.observed[k, :3], invert(G[k] @ poses[k])[:3, 3], atol=1e-9)
        np.testing.assert_allclose(plain.observed[k, :3], invert(poses[k])[:3, 3], atol=1e-9)
    turned = frames[3].turned(G[3])
    Ad = adjoint(G[3])
    np.testing.assert_allclose(
        np.linalg.inv(turned.information), Ad @ np.linalg.inv(H) @ Ad.T, rtol=1e-9, atol=1e-12
    )
    np.testing.assert_array_equal(turned.step_covariance, frames[3].step_covariance)
    # the orbit's azimuth (about z through the centre) is known to misfit / scale = 1 mrad:
    # the filter's frames carry it in their information and their step covariance
    u = np.array([0.0, -1.0, 0.0, 0.0, 0.0, 1.0])  # [c × a, a]
    pinned = turned.pinned(u, 1e-3)
    var = u @ np.linalg.inv(pinned.information) @ u
    assert var <= 1e-6 < u @ np.linalg.inv(turned.information) @ u
    ub = adjoint(invert(turned.pose)) @ u
    assert ub @ pinned.step_covariance @ ub <= 1e-6 < ub @ turned.step_covariance @ ub
    assert np.linalg.eigvalsh(pinned.step_covariance).min() > -1e-15
