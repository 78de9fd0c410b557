"""Re-anchoring of the navigator's start-up (``reanchor_frame``,
:mod:`relnav.navigation.startup.anchor`): the gauge error it removes on a tumbling target,
its refusal without evidence, the target-frame turn handed to the relative state, and option
checking."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from nav_scenarios import FLASH_64, attitude_errors_deg
from relnav.errors import ConfigError
from relnav.geometry.lie import exp_se3
from relnav.geometry.rotations import rotation_angle
from relnav.io.sequences import ScanSequence
from relnav.navigation import Navigator
from relnav.navigation.state import StateRecord, relative_state
from relnav.navigation.state import relative as state_module
from relnav.navigation.state import rigid_body as rigid_body_module
from relnav.pipeline import resolve_method, run_sequence
from relnav.sim.scenario import simulate

FRAMES = 30


def _hold_point(name: str, seed: int, attitude: dict) -> dict:
    """A 64×64 flash LIDAR (2 cm noise) holding 40 m from a 12 m satellite, 2 s frames."""
    return {
        "name": name,
        "seed": seed,
        "frames": FRAMES,
        "dt": 2.0,
        "format": "npy",
        "target": {"name": "voyager", "scale_to": 12.3},
        "sensors": [dict(FLASH_64)],
        "trajectory": {"kind": "static", "params": {"position": (-40.0, 5.0, -6.0)}},
        "attitude": attitude,
    }


TUMBLE = {
    "kind": "tumble",
    "inertia": (4000.0, 7000.0, 9000.0),
    "omega0_deg_s": (0.6, -0.9, 0.5),
    "initial_rpy_deg": (15.0, 40.0, -20.0),
}


@pytest.fixture(scope="module")
def tumble_seq(tmp_path_factory):
    """The satellite tumbling at ~1.2°/s (2.4° per frame)."""
    out = tmp_path_factory.mktemp("anchor") / "tumble"
    simulate(_hold_point("anchor-tumble", 3, TUMBLE), out)
    return ScanSequence(out)


@pytest.fixture(scope="module")
def still_seq(tmp_path_factory):
    """The same view of a still satellite: nothing for a re-anchoring to correct."""
    out = tmp_path_factory.mktemp("anchor") / "still"
    simulate(_hold_point("anchor-still", 5, {"kind": "static"}), out)
    return ScanSequence(out)


def _reanchor_record(seq: ScanSequence, **options) -> tuple[dict, object]:
    nav = Navigator(initial_pose=seq.gt_poses[0], **options)
    steps = [nav.register_frame(seq[k]) for k in range(len(seq))]
    records = [r for r in nav.startup.refinements if r.get("kind") == "reanchor"]
    assert len(records) == 1
    return records[0], steps


def test_reanchoring_removes_the_start_up_turn_of_a_tumbling_target(tumble_seq):
    """The start-up's error is a turn of the whole map; the first scan on the later map finds
    it: the attitude error of the frames after the re-anchoring falls below half."""
    gt = tumble_seq.gt_poses
    plain = run_sequence(tumble_seq, "relnav", **{"map.surface": "quadric"})
    anchored = run_sequence(
        tumble_seq, "relnav", **{"map.surface": "quadric", "startup.reanchor_frame": 20}
    )
    before = attitude_errors_deg(plain.poses, gt)[20:].mean()
    after = attitude_errors_deg(anchored.poses, gt)[20:].mean()
    assert before > 3.0  # the start-up error the option is for
    assert after < 0.5 * before
    np.testing.assert_allclose(anchored.poses[0], gt[0])  # the anchor stays


def test_reanchoring_records_the_turn_for_the_relative_state(tumble_seq):
    rec, steps = _reanchor_record(
        tumble_seq, **{"map.surface": "quadric", "startup.reanchor_frame": 20}
    )
    assert rec["accepted"] and rec["chi2"] <= 22.46 and rec["gain_chi2"] > 22.46
    assert rec["rms"] < rec["rms_before"]
    turned = [k for k, s in enumerate(steps) if s.result and "gauge_turn" in s.result.info]
    assert turned == [19]  # the window's 20th frame
    G = steps[19].result.info["gauge_turn"]
    assert G.shape == (4, 4) and np.allclose(G[3], [0, 0, 0, 1])
    angle = math.degrees(rotation_angle(G[:3, :3]))
    assert abs(angle - rec["rotation_deg"]) < 1e-6 and angle > 1.0


def test_reanchoring_is_refused_without_a_better_fit(still_seq):
    """A still target: the first scan fits the later map where it is, so nothing is turned."""
    rec, steps = _reanchor_record(still_seq, **{"startup.reanchor_frame": 20})
    assert not rec["accepted"]
    assert rec["reason"] in ("no better fit", "inconsistent with the start-up")
    assert all("gauge_turn" not in (s.result.info if s.result else {}) for s in steps)


def test_gauge_turn_moves_the_earlier_frames_into_the_later_target_frame():
    """``relative_state`` sees one target frame: the frames before a turn are turned by it."""
    G = exp_se3(np.array([0.1, -0.2, 0.3, 0.02, -0.01, 0.03]))
    poses = [exp_se3(np.array([k, 0.0, 0.0, 0.0, 0.0, 0.01 * k])) for k in range(4)]
    H = np.eye(6)
    frames = [StateRecord("ok", T, H) for T in poses]
    frames[2] = StateRecord("ok", poses[2], H, gauge_turn=G)
    out = state_module._gauge_turned(frames)
    for k in (0, 1):
        np.testing.assert_allclose(out[k].pose, G @ poses[k])
        assert not np.allclose(out[k].information, H)  # the information turns with the pose
    for k in (2, 3):
        np.testing.assert_allclose(out[k].pose, poses[k])


@pytest.mark.parametrize(
    "options",
    [
        {"startup.reanchor_frame": 5},  # < reanchor_skip + 2
        {"startup.reanchor_frame": 10},  # the multi-view window's frame
        {"startup.reanchor_frame": 20, "startup.reanchor_skip": 0},
        {"startup.reanchor_frame": 20, "startup.window": 0, "startup.bootstrap_frames": 3},
    ],
)
def test_reanchor_options_are_checked(options):
    with pytest.raises(ConfigError):
        Navigator(**options)


def test_relnav_tumbling_preset_expands_to_the_navigator():
    method, options, preset = resolve_method("relnav-tumbling", {"startup": {"reanchor_frame": 25}})
    assert method == "relnav" and preset == "relnav-tumbling"
    assert options == {"map": {"surface": "quadric"}, "startup": {"reanchor_frame": 25}}


@pytest.mark.parametrize("refine", [False, True])
def test_rigid_body_second_pass_that_fails_keeps_the_first(monkeypatch, refine):
    """Euler's equations with a wild inertia fit can diverge: the first pass stands, and the
    run's meta says why (for each fit, the rates' and the attitudes')."""
    calls = {"n": 0}
    real_run = state_module.Tracker.run

    def failing_second_pass(self, *a, **k):
        calls["n"] += 1
        if calls["n"] > 1:
            raise ValueError("Found zero norm quaternions in `quat`.")
        return real_run(self, *a, **k)

    fit = SimpleNamespace(
        inertia=np.diag([1.0, 2.0, 3.0]), principal=np.array([1.0, 2.0, 3.0]), residual=1e-4
    )
    monkeypatch.setattr(state_module.Tracker, "run", failing_second_pass)
    monkeypatch.setattr(rigid_body_module, "fit_inertia", lambda *a, **k: fit)
    monkeypatch.setattr(rigid_body_module, "refine_inertia", lambda *a, **k: fit)
    w = 0.02  # rad/s about z
    frames = [
        StateRecord("first" if k == 0 else "ok", exp_se3(np.r_[0, 0, 0, 0, 0, w * k]), np.eye(6))
        for k in range(30)
    ]
    run = SimpleNamespace(steps=frames, timestamps=np.arange(30.0), method="relnav")
    res = relative_state(run, rigid_body=True, inertia_refine=refine)
    assert calls["n"] == 3 if refine else 2
    assert res.meta["inertia_rejected"].count("zero norm") == (2 if refine else 1)
    assert "inertia_source" not in res.meta
    assert np.all(np.isfinite(res.omega))


def test_run_record_says_what_the_start_up_decided(tumble_seq):
    """``run.json``'s ``finalize`` lists the multi-view refinement and the re-anchoring."""
    run = run_sequence(
        tumble_seq, "relnav", **{"map.surface": "quadric", "startup.reanchor_frame": 20}
    )
    kinds = [r["kind"] for r in run.options["finalize"]["start_up"]]
    assert kinds == ["multi-view", "reanchor"]
    assert run.options["finalize"]["start_up"][1]["accepted"] is True
