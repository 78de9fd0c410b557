"""relnav.pipeline: the run folder, the tracker registry and declared capabilities (issue 43)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from relnav.errors import ConfigError
from relnav.geometry import invert, transform_points
from relnav.geometry.se3 import exp_se3
from relnav.io.sequences import ScanSequence, write_sequence
from relnav.navigation import Navigator
from relnav.odometry import OdometryStep
from relnav.odometry import run_sequence as odometry_run_sequence
from relnav.odometry.tracker import capabilities_of
from relnav.pipeline import (
    OdometryPipeline,
    available_trackers,
    register_tracker,
    resolve_method,
    run_pipeline,
    run_sequence,
    tracker_entry,
    unregister_tracker,
)
from relnav.registration import RegistrationResult

TIMING = {"t_frame_ms", "t_other_ms"}


@pytest.fixture
def moving_cloud(rng, tmp_path):
    """8 frames of one cloud seen from known poses (scan k = T_k^-1 · model), with ground truth."""
    model = rng.uniform(-2.0, 2.0, (400, 3)) + np.array([6.0, 0.0, 0.0])
    poses = [np.eye(4)]
    for _ in range(7):
        poses.append(poses[-1] @ exp_se3(np.r_[rng.normal(0, 0.03, 3), rng.normal(0, 0.01, 3)]))
    scans = [transform_points(invert(T), model) for T in poses]
    return write_sequence(
        tmp_path / "seq", scans, np.arange(8.0), gt_poses=np.stack(poses), fmt="ply"
    )


class _Replay:
    """A toy tracker: each frame's pose from a table it was given (no registration)."""

    capabilities = frozenset({"final_report"})

    def __init__(self, *, initial_pose=None, poses=None, status="ok"):
        self.poses = np.asarray(poses)
        self.status = status
        self.k = 0

    def register_frame(self, scan):
        T = self.poses[self.k]
        self.k += 1
        res = RegistrationResult(T_target_source=np.eye(4), status=self.status, message="toy")
        first = self.k == 1
        return OdometryStep(
            T.copy(),
            np.eye(4),
            None if first else res,
            False,
            "first" if first else self.status,
            len(scan.points),
            0.0,
        )

    def final_report(self):
        return {"frames": self.k}


def _rows(path):
    with path.open(newline="") as f:
        return [{k: v for k, v in r.items() if k not in TIMING} for r in csv.DictReader(f)]


def test_navigator_is_registered_with_its_declared_capabilities():
    entry = tracker_entry("relnav")
    assert entry is not None and entry.factory is Navigator
    assert (
        entry.capabilities == Navigator.capabilities == {"skip_frame", "smoother", "final_report"}
    )
    assert tracker_entry("RELNAV") is entry and "relnav" in available_trackers()
    assert resolve_method("relnav") == ("relnav", {}, None)
    name, opts, preset = resolve_method("relnav-tumbling")
    assert (name, preset) == ("relnav", "relnav-tumbling") and opts


def test_odometry_layer_does_not_know_tracker_names(moving_cloud):
    """The odometry layer runs what it is handed: a tracker's name is resolved one layer up."""
    seq = ScanSequence(moving_cloud)
    with pytest.raises(ConfigError, match=r"relnav\.pipeline"):
        odometry_run_sequence(seq, "relnav")
    run = odometry_run_sequence(seq, tracker_entry("relnav"), max_frames=3)
    assert run.method == "relnav" and len(run.poses) == 3


def test_registry_refuses_bad_registrations():
    with pytest.raises(ConfigError, match="registration method family"):
        register_tracker("icp-point", _Replay)
    with pytest.raises(ConfigError, match="already registered"):
        register_tracker("relnav", Navigator)
    with pytest.raises(ConfigError, match="contradict"):
        register_tracker("h43-replay", _Replay, capabilities={"smoother"})
    with pytest.raises(ConfigError, match="unknown capabilities"):
        register_tracker("h43-replay", object, capabilities={"teleport"})
    with pytest.raises(ConfigError, match="one word"):
        register_tracker("a:b", _Replay)
    assert tracker_entry("h43-replay") is None


def test_declared_capability_without_its_method_is_refused():
    class _Liar(_Replay):
        capabilities = frozenset({"smoother"})  # but no finalize()

    with pytest.raises(ConfigError, match="finalize"):
        capabilities_of(_Liar(poses=np.eye(4)[None]))
    assert capabilities_of(object()) == frozenset()  # the bare protocol: register_frame only


def test_a_registered_tracker_runs_like_a_method_and_only_its_capabilities_are_used(
    moving_cloud, tmp_path
):
    seq = ScanSequence(moving_cloud)
    gt = np.asarray(seq.gt_poses)
    register_tracker("h43-replay", _Replay, description="test")
    try:
        res = run_pipeline(seq, "h43-replay", options={"poses": gt}, out=tmp_path / "run")
    finally:
        unregister_tracker("h43-replay")
    assert res.status == "complete" and res.method == "h43-replay"
    assert res.run.options["finalize"] == {"frames": 8}  # declared: asked for
    assert res.run.causal_poses is None  # no smoother declared: finalize never asked
    assert res.run.options["step_check"] == "off"
    assert res.metrics["ape_trans_rmse"] == pytest.approx(0.0, abs=1e-9)
    written = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert written["ape_trans_rmse"] == res.metrics["ape_trans_rmse"]
    assert set(res.outputs) >= {"estimate.tum", "diagnostics.csv", "metrics.json", "run.json"}
    assert not (tmp_path / "run" / "state.csv").exists()  # not the navigator


def test_every_frame_failed_is_a_failed_status(moving_cloud):
    seq = ScanSequence(moving_cloud)
    register_tracker("h43-fail", _Replay)
    try:
        pipe = OdometryPipeline("h43-fail", {"poses": np.asarray(seq.gt_poses), "status": "failed"})
        res = pipe.run(seq, stream=False)
    finally:
        unregister_tracker("h43-fail")
    assert res.run.status_counts() == {"first": 1, "failed": 7}
    assert res.status == "failed" and res.failed == "toy"
    ok = OdometryPipeline("icp-point").run(seq, stream=False)
    assert ok.status == "complete" and ok.failed is None


def test_interrupt_keeps_the_frames_estimated(moving_cloud, tmp_path):
    seq = ScanSequence(moving_cloud)

    def stop(i, step):
        if i == 3:
            raise KeyboardInterrupt

    res = OdometryPipeline("icp-point").run(
        seq, out=tmp_path / "run", progress=stop, on_interrupt="stop"
    )
    assert res.status == "interrupted" and res.interrupted == {"at_frame": 4, "of": 8}
    assert len(res.run.poses) == 4


def test_navigator_run_folder_streamed_equals_in_memory(moving_cloud, tmp_path):
    """The CLI's path (streamed, compact state records) and the demo's (in memory, steps) write
    the same estimate, causal estimate, diagnostics and metrics."""
    seq = ScanSequence(moving_cloud)
    pipe = OdometryPipeline("relnav")
    a = pipe.run(seq, out=tmp_path / "a", state=True)
    pipe.write(a, seq, command="test")
    b = pipe.run(seq, stream=False)
    pipe.write(b, seq, tmp_path / "b", command="test")
    for name in ("estimate.tum", "estimate_causal.tum"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert _rows(tmp_path / "a" / "diagnostics.csv") == _rows(tmp_path / "b" / "diagnostics.csv")
    drop = {"time_ms", "time_ms_mean"}
    ma = {k: v for k, v in a.metrics.items() if k not in drop}
    mb = {k: v for k, v in b.metrics.items() if k not in drop}
    assert ma == mb and "state" in ma and "causal" in ma
    assert {"state.csv", "estimate_causal.tum"} <= set(a.outputs) & set(b.outputs)
    info = json.loads((tmp_path / "a" / "run.json").read_text())
    assert info["command"] == "test" and info["status"] == "complete"


def test_pipeline_run_sequence_equals_the_odometry_layer_for_a_method_string(moving_cloud):
    seq = ScanSequence(moving_cloud)
    a = run_sequence(seq, "icp-point", max_frames=4)
    b = odometry_run_sequence(seq, "icp-point", max_frames=4)
    np.testing.assert_array_equal(a.poses, b.poses)


def test_any_form_of_method_runs_and_bad_ones_are_refused(moving_cloud, tmp_path):
    from relnav.errors import InputError
    from relnav.registration import get_registration

    seq = ScanSequence(moving_cloud)
    gt = np.asarray(seq.gt_poses)
    by_class = run_pipeline(seq, _Replay, options={"poses": gt}, out=tmp_path / "cls")
    assert by_class.method == "Replay" and by_class.run.options["finalize"] == {"frames": 8}
    by_object = run_pipeline(seq, get_registration("icp-point"), out=tmp_path / "obj")
    by_name = run_pipeline(seq, "icp-point", out=tmp_path / "name")
    np.testing.assert_array_equal(by_object.run.poses, by_name.run.poses)
    with pytest.raises(ConfigError, match="instance"):
        OdometryPipeline(_Replay(poses=gt))
    with pytest.raises(ConfigError, match="got int"):
        OdometryPipeline(3)
    with pytest.raises(InputError, match="no scans"):
        OdometryPipeline("icp-point").run([])
    plain = run_pipeline([s.points for s in seq][:4], "icp-point", out=tmp_path / "plain")
    assert plain.status == "complete" and plain.metrics == {}  # no ground truth: no metrics
    assert "metrics.json" not in plain.outputs and "estimate.tum" in plain.outputs


def test_the_cli_starts_without_the_registry():
    """``relnav --help`` and every command's start stay cheap: the CLI imports the pipeline's
    outputs module, not its registry (which imports the navigator and paper 2's methods)."""
    import subprocess
    import sys

    code = (
        "import sys, relnav.cli.main; "
        "print(sorted(m for m in ('relnav.pipeline.registry', 'relnav.navigation.navigator') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
