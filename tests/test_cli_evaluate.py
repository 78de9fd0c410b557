"""Smoke tests of ``relnav evaluate`` (Typer CliRunner + one subprocess for the error line)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from relnav.errors import EstimationError, InputError, RelnavError
from relnav.eval.metrics import METRIC_KEYS

try:  # helper A's reader; a plain NumPy stand-in while it is not there yet
    import relnav.io.trajectories  # noqa: F401
except ImportError:  # pragma: no cover - only before relnav.io.trajectories exists

    def _read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
        d = np.loadtxt(path, comments="#", ndmin=2)
        P = np.repeat(np.eye(4)[None], len(d), axis=0)
        P[:, :3, 3] = d[:, 1:4]
        P[:, :3, :3] = Rotation.from_quat(d[:, 4:8]).as_matrix()
        return d[:, 0], P

    _mod = types.ModuleType("relnav.io.trajectories")
    _mod.read_tum = _read_tum  # type: ignore[attr-defined]
    sys.modules["relnav.io.trajectories"] = _mod

from relnav.cli.main import app

runner = CliRunner()


def _write_tum(path: Path, t: np.ndarray, xyz: np.ndarray, rotvec: np.ndarray) -> Path:
    q = Rotation.from_rotvec(rotvec).as_quat()
    np.savetxt(path, np.column_stack([t, xyz, q]), fmt="%.9f", header="t x y z qx qy qz qw")
    return path


@pytest.fixture
def tum_pair(tmp_path: Path) -> tuple[Path, Path]:
    n = 20
    t = 0.1 * np.arange(n)
    xyz = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)])
    rv = np.zeros((n, 3))
    gt = _write_tum(tmp_path / "gt.tum", t, xyz, rv)
    est_xyz = xyz + np.array([0.0, 0.1, 0.0])
    est_rv = rv + np.array([0.0, 0.0, np.radians(2.0)])
    est = _write_tum(tmp_path / "est.tum", t + 0.002, est_xyz, est_rv)
    return est, gt


def test_evaluate_prints_table_and_writes_json(tum_pair: tuple[Path, Path], tmp_path: Path) -> None:
    est, gt = tum_pair
    out = tmp_path / "out" / "metrics.json"
    res = runner.invoke(app, ["evaluate", str(est), str(gt), "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert "e_T_avg" in res.output and "matched 20 of 20" in res.output
    doc = json.loads(out.read_text())
    for key in (*METRIC_KEYS, "n_matched", "n_est", "n_gt", "align", "est_file", "units"):
        assert key in doc, key
    assert doc["e_T_avg"] == pytest.approx(0.1, abs=1e-8)
    assert doc["e_R_avg"] == pytest.approx(2.0, abs=1e-6)
    assert doc["T_error_pct"] == pytest.approx(100 * 0.1 / 19, abs=1e-7)
    assert doc["time_ms"] is None  # unknown here: JSON null, not NaN
    assert doc["units"]["e_R_avg"] == "deg"


def test_evaluate_options_and_plots(tum_pair: tuple[Path, Path], tmp_path: Path) -> None:
    est, gt = tum_pair
    out = tmp_path / "m.json"
    res = runner.invoke(
        app,
        [
            "evaluate",
            str(est),
            str(gt),
            "--json",
            str(out),
            "--align",
            "first",
            "--delta",
            "2",
            "--plot-dir",
            str(tmp_path / "plots"),
        ],
    )
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert doc["align"] == "first" and doc["rpe_delta"] == 2
    # aligning the first poses removes the 2° yaw, so the 19 m straight path swings sideways:
    # |Rz(−2°) (k, 0, 0) − (k, 0, 0)| = 2 k sin 1°, largest at k = 19
    assert doc["e_R_max"] < 1e-6
    assert doc["e_T_max"] == pytest.approx(2 * 19 * np.sin(np.radians(1.0)), abs=1e-6)
    for name in ("trajectories.png", "errors.png"):
        assert (tmp_path / "plots" / name).stat().st_size > 5000


def test_evaluate_too_few_matches_is_an_estimation_error(
    tum_pair: tuple[Path, Path], tmp_path: Path
) -> None:
    est, gt = tum_pair
    res = runner.invoke(app, ["evaluate", str(est), str(gt), "--max-diff", "0.001"])
    assert res.exit_code != 0
    assert isinstance(res.exception, EstimationError)
    assert "only 0 of 20" in str(res.exception)


def test_evaluate_bad_files_are_input_errors(tum_pair: tuple[Path, Path], tmp_path: Path) -> None:
    est, gt = tum_pair
    res = runner.invoke(app, ["evaluate", str(tmp_path / "missing.tum"), str(gt)])
    assert res.exit_code != 0 and isinstance(res.exception, InputError)
    bad = tmp_path / "bad.tum"
    bad.write_text("0.0 1 2 3\nnot a pose\n")
    res = runner.invoke(app, ["evaluate", str(est), str(bad)])
    assert res.exit_code != 0 and isinstance(res.exception, RelnavError)


def test_console_script_prints_one_error_line(tmp_path: Path) -> None:
    gt = _write_tum(tmp_path / "gt.tum", np.arange(3.0), np.zeros((3, 3)), np.zeros((3, 3)))
    code = "import sys; from relnav.cli.main import main; sys.argv[0] = 'relnav'; main()"
    # rich wraps at 80 columns when stderr is not a terminal; widen it so the long tmp path
    # stays on the one line that main() prints
    env = {**os.environ, "COLUMNS": "400"}
    proc = subprocess.run(
        [sys.executable, "-c", code, "evaluate", str(tmp_path / "nope.tum"), str(gt)],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert proc.returncode == 1
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "error:" in lines[0] and "nope.tum" in lines[0], proc.stderr
