"""Step checks of pairwise odometry (relnav.odometry.step_check): issue 11, item 9."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.errors import ConfigError
from relnav.geometry import invert, transform_points
from relnav.geometry.se3 import exp_se3
from relnav.odometry import Odometry, run_sequence
from relnav.odometry.step_check import StepChecker, resolve_step_check
from relnav.registration import RegistrationResult, get_registration
from relnav.scan import Scan


def _bumpy_cloud(rng, n=500):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = 1.0 + 0.2 * np.sin(3 * d[:, 0]) * np.cos(2 * d[:, 1]) + 0.15 * d[:, 2] ** 2
    return d * r[:, None] * 2.0 + np.array([8.0, 0.0, 0.0])


class _Fixed:
    """A registration that always answers the same step (right or wrong)."""

    name = "fixed"

    def __init__(self, T):
        self.T = np.asarray(T, dtype=float)
        self.calls = 0

    def register(self, source, target, *, init=None):
        self.calls += 1
        return RegistrationResult(T_target_source=self.T.copy(), status="ok", fitness=1.0)


class _Consistent(_Fixed):
    """Answers ``T`` for the pair (source, target) and ``T⁻¹`` for (target, source)."""

    def __init__(self, T, source):
        super().__init__(T)
        self.source = source

    def register(self, source, target, *, init=None):
        self.calls += 1
        T = self.T if np.array_equal(source, self.source) else invert(self.T)
        return RegistrationResult(T_target_source=T, status="ok", fitness=1.0)


def test_resolve_modes():
    assert resolve_step_check("auto", "icp-point") == "full"
    assert resolve_step_check("auto", "icp-plane") == "backward"
    assert resolve_step_check("auto", "sicp-point") == "referee"
    assert resolve_step_check("auto", "feature:hods+gcc+alphabeta") == "referee"
    assert resolve_step_check("auto", "feature:hods+gcc+svd", {"refine": "icp-plane"}) == "backward"
    assert resolve_step_check("auto", "kiss-icp") == "off"
    assert resolve_step_check(True, object()) == "off"  # objects may be stateful
    assert resolve_step_check("full", object()) == "full"
    assert resolve_step_check(False, "icp-point") == "off"
    with pytest.raises(ConfigError, match="step_check must be one of"):
        resolve_step_check("sometimes", "icp-point")


@pytest.mark.parametrize(
    "bad",
    [{"step_check": "maybe"}, {"step_tolerance_m": -1}, {"step_tolerance_deg": "abc"}],
)
def test_bad_options_are_config_errors(bad):
    with pytest.raises(ConfigError):
        Odometry("icp-point", **bad)


def _pair(rng, T):
    target = _bumpy_cloud(rng)
    source = transform_points(invert(T), target)  # target = T @ source
    return source, target


def test_right_step_stays_ok_and_wrong_step_is_flagged(rng):
    T = exp_se3([0.05, -0.03, 0.02, 0.01, -0.02, 0.03])
    source, target = _pair(rng, T)
    # the right answer: both checks agree with it
    reg = _Consistent(T, source)
    odo = Odometry(reg, step_check="full")
    odo.register_frame(target)
    out = odo.register_frame(source)
    assert out.status == "ok", out.result.message
    assert reg.calls == 2  # forward, then backward
    sc = out.result.info["step_check"]
    assert sc["referee_t"] < 0.05 and sc["loop_t"] < 1e-9
    # a wrong answer (1 m off) from a method that also answers it backwards
    wrong = exp_se3([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]) @ T
    odo = Odometry(_Fixed(wrong), step_check="referee")
    odo.register_frame(target)
    out = odo.register_frame(source)
    assert out.status == "flagged"
    assert "point-to-plane ICP" in out.result.message
    assert not out.used_prior  # kept in the chain, not trusted
    np.testing.assert_allclose(out.step, wrong)


def test_inconsistent_backward_registration_is_flagged(rng):
    T = exp_se3([0.05, -0.03, 0.02, 0.01, -0.02, 0.03])
    source, target = _pair(rng, T)
    odo = Odometry(_Fixed(T), step_check="backward")  # backward answers T again, not T⁻¹
    odo.register_frame(target)
    out = odo.register_frame(source)
    assert out.status == "flagged"
    assert "forward–backward loop" in out.result.message


def test_off_leaves_method_untouched(rng):
    T = exp_se3([1.0, 0, 0, 0, 0, 0])
    source, target = _pair(rng, T)
    reg = _Fixed(exp_se3([0.0, 0.0, 0.0, 0.0, 0.0, 0.3]))
    odo = Odometry(reg)  # auto: off for an object
    odo.register_frame(target)
    assert odo.register_frame(source).status == "ok"
    assert reg.calls == 1


def test_icp_point_stopped_short_is_flagged_and_converged_is_not(rng):
    """icp-point with 2 iterations stops short of a 1.5 m step; with the default it converges."""
    T = exp_se3([1.5, 0.0, 0.0, 0.0, 0.0, 0.1])
    source, target = _pair(rng, T)
    for max_iter, expect in ((2, "flagged"), (20, "ok")):
        odo = Odometry(get_registration("icp-point", max_iter=max_iter), step_check="full")
        odo.register_frame(target)
        out = odo.register_frame(source)
        assert out.status == expect, (max_iter, out.result.message)


def test_run_counts_flagged_steps_and_diagnostics_give_the_reason(rng, tmp_path):
    T = exp_se3([0.05, 0.0, 0.0, 0.0, 0.0, 0.02])
    wrong = exp_se3([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]) @ T
    clouds = [_bumpy_cloud(rng)]
    for _ in range(3):
        clouds.append(transform_points(invert(T), clouds[-1]))
    seq = [Scan(c, time=float(i)) for i, c in enumerate(clouds)]
    run = run_sequence(seq, _Fixed(wrong), initial_pose=None, step_check="referee", out=tmp_path)
    assert run.n_flagged == 3
    assert run.options["step_check"] == "referee"
    assert run.flagged.tolist() == [False, True, True, True]
    rows = run.diagnostics()
    assert [r["status"] for r in rows] == ["first", "flagged", "flagged", "flagged"]
    assert all("step not trusted" in r["message"] for r in rows[1:])
    text = (tmp_path / "diagnostics.csv").read_text()
    assert text.count(",flagged,") == 3


def test_checker_rejects_bad_factors():
    with pytest.raises(ConfigError):
        StepChecker(_Fixed(np.eye(4)), "full", referee_factor=0.0)
    with pytest.raises(ConfigError):
        StepChecker(_Fixed(np.eye(4)), "sometimes")  # type: ignore[arg-type]
