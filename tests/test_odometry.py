"""Odometry chaining, the motion prior, and bad-input robustness of the feature pipeline."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.geometry import invert, random_transform, rotation_angle, transform_points
from relnav.geometry.se3 import exp_se3
from relnav.odometry import Odometry, run_sequence
from relnav.registration import RegistrationResult, get_registration
from relnav.scan import Scan


class _Oracle:
    """A fake registration returning known steps (or failing on chosen frames)."""

    name = "oracle"

    def __init__(self, steps, fail_at=()):
        self.steps = steps
        self.fail_at = set(fail_at)
        self.k = 0

    def register(self, source, target, *, init=None):
        self.k += 1
        if self.k in self.fail_at:
            return RegistrationResult(status="degenerate", message="test")
        return RegistrationResult(T_target_source=self.steps[self.k], status="ok")


_SCENE = np.random.default_rng(0).uniform(-10.0, 10.0, (10, 3))
"""Dummy scan for the oracle (its ~15 m reach allows the test steps; see the scene bound)."""


def test_chaining_follows_design_convention(rng):
    steps = [np.eye(4)] + [random_transform(rng, 0.5) for _ in range(5)]
    T0 = random_transform(rng)
    odo = Odometry(_Oracle(steps), initial_pose=T0)
    expected = T0.copy()
    for k in range(6):
        out = odo.register_frame(_SCENE)
        if k:
            expected = expected @ steps[k]
        np.testing.assert_allclose(out.pose, expected, atol=1e-12)


def test_failed_frame_keeps_constant_velocity_prior(rng):
    step = exp_se3([0.1, 0, 0, 0, 0, 0.05])
    steps = [np.eye(4)] + [step] * 5
    odo = Odometry(_Oracle(steps, fail_at={3}))
    outs = [odo.register_frame(_SCENE) for _ in range(6)]
    assert [o.status for o in outs] == ["first", "ok", "ok", "degenerate", "ok", "ok"]
    assert outs[3].used_prior
    np.testing.assert_allclose(outs[3].step, step, atol=1e-12)
    np.testing.assert_allclose(outs[-1].pose, np.linalg.matrix_power(step, 5), atol=1e-12)
    odo_id = Odometry(_Oracle(steps, fail_at={3}), motion_prior="identity")
    outs = [odo_id.register_frame(_SCENE) for _ in range(6)]
    np.testing.assert_allclose(outs[3].step, np.eye(4))


def _bumpy_cloud(rng, n=400):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = 1.0 + 0.15 * np.sin(3 * d[:, 0]) * np.cos(2 * d[:, 1]) + 0.1 * d[:, 2] ** 2
    return d * r[:, None] * 2.0 + np.array([8.0, 0.0, 0.0])


@pytest.mark.parametrize("method", ["feature:hods+gcc+svd", "feature:shot+gcc+svd"])
def test_feature_registration_recovers_small_motion(rng, method):
    target = _bumpy_cloud(rng)
    T = exp_se3([0.05, -0.03, 0.02, 0.01, -0.02, 0.03])  # T_target_source
    source = transform_points(invert(T), target)
    res = get_registration(method).register(source, target)
    assert res.status == "ok", res.message
    assert res.n_inliers >= 20
    err = invert(T) @ res.T_target_source
    assert np.degrees(rotation_angle(err[:3, :3])) < 1.0
    assert np.linalg.norm(err[:3, 3]) < 0.05
    for stage in ("describe", "match", "group", "estimate"):
        assert stage in res.timings


def test_alphabeta_raw_and_centred(rng):
    """αβ with paper 1's gains, one NLMS sweep: on raw sensor-frame points 8 m away
    (``center=False``) it recovers only part of the motion (but moves towards the truth); on
    centred points (the default) it recovers it."""
    target = _bumpy_cloud(rng)
    T = exp_se3([0.05, -0.03, 0.02, 0.01, -0.02, 0.03])
    source = transform_points(invert(T), target)
    motion = np.degrees(rotation_angle(T[:3, :3]))
    raw = get_registration(
        "feature:hods+gcc+alphabeta", estimator_options={"center": False}
    ).register(source, target)
    err = np.degrees(rotation_angle((invert(T) @ raw.T_target_source)[:3, :3]))
    assert raw.status == "ok"
    assert err < motion
    centred = get_registration("feature:hods+gcc+alphabeta").register(source, target)
    err_c = np.degrees(rotation_angle((invert(T) @ centred.T_target_source)[:3, :3]))
    assert err_c < 0.5


def test_refinement_and_motion_gate(rng):
    target = _bumpy_cloud(rng)
    T = exp_se3([0.05, -0.03, 0.02, 0.01, -0.02, 0.03])
    source = transform_points(invert(T), target)
    res = get_registration("feature:hods+gcc+svd", refine="icp-plane").register(source, target)
    assert res.status == "ok" and "refine" in res.timings
    err = invert(T) @ res.T_target_source
    assert np.degrees(rotation_angle(err[:3, :3])) < 0.1
    # a 1-degree gate rejects the ~2-degree step (identity prior), a 10-degree gate keeps it
    for gate, expect in ((1.0, "failed"), (10.0, "ok")):
        odo = Odometry("feature:hods+gcc+svd", gate_rotation_deg=gate)
        odo.register_frame(target)
        out = odo.register_frame(source)
        assert out.status == expect
        assert out.used_prior == (expect == "failed")


BAD_SCANS = {
    "empty": np.zeros((0, 3)),
    "one": np.array([[1.0, 2.0, 3.0]]),
    "three": np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]),
    "identical": np.ones((50, 3)),
    "collinear": np.column_stack([np.linspace(0, 1, 60), np.zeros(60), np.zeros(60)]),
    "nan": np.full((30, 3), np.nan),
}


def test_bad_scans_are_flagged_and_run_completes(rng):
    good = _bumpy_cloud(rng)
    scans = [Scan(good, time=0.0)]
    for i, bad in enumerate(BAD_SCANS.values(), start=1):
        scans.append(Scan(bad, time=float(2 * i - 1)))
        scans.append(Scan(good, time=float(2 * i)))
    run = run_sequence(scans, "feature:hods+gcc+alphabeta", initial_pose=None)
    assert len(run.poses) == len(scans)
    assert np.isfinite(run.poses).all()
    statuses = [s.status for s in run.steps]
    # every bad frame is flagged, and so is the good frame right after it (nothing to match)
    for i in range(1, len(scans), 2):
        assert statuses[i] in ("degenerate", "failed"), (i, statuses[i])
        assert run.steps[i].used_prior
    rows = run.diagnostics()
    assert [r["status"] for r in rows] == statuses
    assert all(r["used_prior"] == int(s.used_prior) for r, s in zip(rows, run.steps, strict=True))


def test_run_writes_estimate_and_diagnostics(tmp_path, rng):
    good = _bumpy_cloud(rng)
    scans = [Scan(good, time=0.1 * i) for i in range(3)]
    run = run_sequence(scans, "feature:hods+gcc+svd")
    paths = run.write(tmp_path)
    lines = paths["estimate"].read_text().strip().splitlines()
    assert len(lines) == 3
    header = paths["diagnostics"].read_text().splitlines()[0].split(",")
    for col in ("n_points", "n_correspondences", "n_inliers", "status", "t_describe_ms"):
        assert col in header
