"""The optional Rerun export (extra [viz]): skipped when rerun-sdk is not installed."""

from __future__ import annotations

import numpy as np
import pytest

from relnav.io.sequences import write_sequence


def test_export_rrd_writes_a_recording(tmp_path, rng):
    pytest.importorskip("rerun")
    from relnav.eval.rerun_export import export_rrd

    scans = [rng.normal(size=(50, 3)) for _ in range(3)]
    poses = np.stack([np.eye(4)] * 3)
    write_sequence(tmp_path / "seq", scans, [0.0, 1.0, 2.0], gt_poses=poses)
    out = export_rrd(tmp_path / "seq", tmp_path / "seq.rrd", estimates={"est": poses})
    data = out.read_bytes()
    assert data[:3] == b"RRF"  # Rerun's file magic
    assert len(data) > 1000


def test_export_rrd_without_rerun_names_the_extra(tmp_path, monkeypatch):
    import sys

    from relnav.errors import ConfigError
    from relnav.eval.rerun_export import export_rrd

    monkeypatch.setitem(sys.modules, "rerun", None)
    with pytest.raises(ConfigError, match=r"relnav\[viz\]"):
        export_rrd(tmp_path, tmp_path / "x.rrd")


def test_odometry_viz_streams_to_an_rrd_when_headless(tmp_path, rng, monkeypatch):
    """`relnav odometry --viz` without a display writes OUT/live.rrd; --rrd picks the file."""
    pytest.importorskip("rerun")
    import json

    from typer.testing import CliRunner

    from relnav.cli.main import app

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    base = rng.normal(size=(300, 3))
    scans = [base + np.array([0.05 * k, 0.0, 0.0]) for k in range(4)]
    write_sequence(tmp_path / "seq", scans, [0.0, 1.0, 2.0, 3.0])
    out = tmp_path / "run"
    res = CliRunner().invoke(
        app, ["odometry", str(tmp_path / "seq"), "-m", "icp-point", "-o", str(out), "--viz"]
    )
    assert res.exit_code == 0, res.output
    data = (out / "live.rrd").read_bytes()
    assert data[:3] == b"RRF" and b"world/scan" in data and b"world/estimate" in data
    assert b"world/model" in data  # the model accumulated from the registered scans
    assert "live.rrd" in json.loads((out / "run.json").read_text())["outputs"]
    res = CliRunner().invoke(
        app,
        [
            "odometry",
            str(tmp_path / "seq"),
            "-m",
            "icp-point",
            "-o",
            str(out),
            "--rrd",
            str(tmp_path / "x.rrd"),
        ],
    )
    assert res.exit_code == 0, res.output
    assert (tmp_path / "x.rrd").read_bytes()[:3] == b"RRF"


def test_view_live_without_a_display_writes_the_recording(tmp_path, rng, monkeypatch):
    pytest.importorskip("rerun")
    from typer.testing import CliRunner

    from relnav.cli.main import app

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    scans = [rng.normal(size=(50, 3)) for _ in range(3)]
    write_sequence(tmp_path / "seq", scans, [0.0, 1.0, 2.0], gt_poses=np.stack([np.eye(4)] * 3))
    res = CliRunner().invoke(
        app, ["view", str(tmp_path / "seq"), "--out", str(tmp_path / "v.png"), "--live"]
    )
    assert res.exit_code == 0, res.output
    assert (tmp_path / "v.rrd").read_bytes()[:3] == b"RRF"
