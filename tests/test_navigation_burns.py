"""A burn the motion model does not predict, with the chaser's attitude input: the measured
attitude makes the prior tight, the pair gate narrow, and the scan after the burn finds no pair
in it. ``solver.recover_unmatched`` registers such a scan again under the weak prior."""

from __future__ import annotations

import numpy as np
import pytest

from nav_scenarios import attitude_errors_deg, flash
from relnav.io.sequences import ScanSequence
from relnav.navigation.attitude_input import AttitudeInput
from relnav.pipeline import run_sequence
from relnav.sim.scenario import simulate

BURN_FRAME = 10  # the first frame after the burn (at 95 s, frames every 10 s)


@pytest.fixture(scope="module")
def burn(tmp_path_factory):
    """A V-bar hold 50 m behind a 10 m procedural Envisat (96×96 flash LIDAR, ~50 points per
    scan), then a 0.3 m/s burn towards it: 1.5 m off the model's prediction at the next frame."""
    out = tmp_path_factory.mktemp("burn") / "seq"
    simulate(
        {
            "name": "burn",
            "seed": 7,
            "frames": 16,
            "dt": 10.0,
            "format": "npy",
            "target": {"name": "envisat", "scale_to": 10.0},
            "pointing": {"attitude_sigma_deg": 0.01},
            "sensors": [flash(96)],
            "trajectory": {
                "kind": "cw",
                "params": {"state0": [0, -50, 0, 0, 0, 0], "burns": [[95.0, 0, 0.3, 0]]},
            },
        },
        out,
    )
    return ScanSequence(out), AttitudeInput.from_tum(out / "chaser_attitude.tum", 0.01)


def _run(burn, recover: str):
    seq, attitude = burn
    # the relocaliser off: the option alone decides what happens to the scan after the burn
    opts = {"solver.recover_unmatched": recover, "reloc.enabled": False}
    run = run_sequence(seq, "relnav", attitude=attitude, **opts)
    error = np.linalg.norm(run.online_poses[:, :3, 3] - seq.gt_poses[:, :3, 3], axis=1)
    return run, error


def test_without_the_retry_the_track_coasts_away_after_the_burn(burn):
    run, error = _run(burn, recover="never")
    assert error[BURN_FRAME - 1] < 0.1  # tracked before the burn
    after = run.steps[BURN_FRAME]
    assert after.status == "failed" and "near the model" in after.result.message
    assert error[-1] > 10.0  # 16.5 m measured: every later scan is farther from the prediction


def test_the_retry_registers_the_scan_and_keeps_the_measured_rotation(burn):
    """On by default: the scan is registered under the weak prior in translation, the measured
    attitude's covariance in rotation, and the filter is widened in translation only."""
    run, error = _run(burn, recover="with_attitude")
    after = run.steps[BURN_FRAME]
    assert after.result.info["recovered"] and after.result.info["rotation_kept"]
    assert after.status != "ok"  # a step the model's prior rejected is never plain ok
    assert error[BURN_FRAME:].max() < 1.0  # 0.04-0.41 m measured
    seq, _ = burn
    turn = attitude_errors_deg(run.online_poses, seq.gt_poses)
    assert turn[BURN_FRAME:].max() < 0.5  # 0.03-0.06° measured; 4-5° with a rotation widened


def test_without_the_attitude_the_retry_is_under_the_whole_weak_prior(burn):
    seq, _ = burn
    run = run_sequence(seq, "relnav", **{"reloc.enabled": False})
    again = [s for s in run.steps[1:] if s.result is not None and s.result.info.get("recovered")]
    assert again  # the burn's scan (here its answer disagreed with the model: χ² beyond the gate)
    assert not any(s.result.info["rotation_kept"] for s in again)
