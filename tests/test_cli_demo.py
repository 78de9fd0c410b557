"""`relnav demo` end to end on a few frames: files written, metrics for every method."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from relnav.cli.main import app


def test_demo_writes_outputs(tmp_path):
    out = tmp_path / "demo"
    res = CliRunner().invoke(app, ["demo", "--out", str(out), "--frames", "6"])
    assert res.exit_code == 0, res.output
    for name in ("estimate.tum", "diagnostics.csv", "metrics.json", "trajectory.png"):
        assert (out / name).is_file(), name
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["methods"]) == {
        "feature:hods+gcc+alphabeta",
        "feature:hods+gcc+svd",
        "icp-point",
        "extended",
    }
    for m in metrics["methods"].values():
        assert m["n_frames"] == 6
        assert m["e_RT"] >= 0
    assert len((out / "estimate.tum").read_text().splitlines()) == 6
