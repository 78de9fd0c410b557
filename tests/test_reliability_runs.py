"""Issue 11, lost work and silently wrong steps: unreadable scans (item 14), streamed outputs
(item 16), the scene bound on accepted steps (item 7), the benchmark lock (item 15) and
SIGKILL fault injection (done-when)."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from relnav.cli.main import app
from relnav.errors import InputError
from relnav.geometry import invert, transform_points
from relnav.geometry.se3 import exp_se3, kabsch
from relnav.io.locks import FolderLock
from relnav.io.sequences import ScanSequence, write_sequence
from relnav.odometry import Odometry
from relnav.pipeline import run_sequence
from relnav.registration import RegistrationResult

runner = CliRunner()


class _Exact:
    """Kabsch on index-aligned clouds: the exact step when the scans are one cloud moved."""

    name = "exact"

    def register(self, source, target, *, init=None):
        return RegistrationResult(T_target_source=kabsch(source, target), status="ok")


@pytest.fixture
def moving_cloud(rng, tmp_path):
    """A 10-frame sequence of one cloud seen from known poses (scan k = T_k^-1 · model)."""
    model = rng.uniform(-2.0, 2.0, (60, 3)) + np.array([6.0, 0.0, 0.0])
    poses = [np.eye(4)]
    for _ in range(9):
        poses.append(poses[-1] @ exp_se3(np.r_[rng.normal(0, 0.05, 3), rng.normal(0, 0.02, 3)]))
    scans = [transform_points(invert(T), model) for T in poses]
    folder = write_sequence(
        tmp_path / "seq", scans, np.arange(10.0), gt_poses=np.stack(poses), fmt="ply"
    )
    return folder, np.stack(poses)


@pytest.mark.parametrize("bad", [4, 9])
def test_unreadable_scan_flags_frame_and_run_goes_on(moving_cloud, bad):  # item 14
    folder, poses = moving_cloud
    f = ScanSequence(folder).files[bad]
    f.write_bytes(f.read_bytes()[:100])  # truncated
    run = run_sequence(ScanSequence(folder), _Exact())
    status = [s.status for s in run.steps]
    assert status[bad] == "failed" and "unreadable scan" in run.steps[bad].result.message
    assert len(run.poses) == 10
    # the next frame is registered onto the last readable one: back on the true pose
    ok = [k for k in range(1, 10) if k != bad]
    assert all(status[k] == "ok" for k in ok)
    np.testing.assert_allclose(run.poses[ok], poses[ok], atol=1e-9)
    with pytest.raises(InputError):
        run_sequence(ScanSequence(folder), _Exact(), strict=True)


def test_unreadable_scan_cli_writes_everything_strict_aborts(moving_cloud, tmp_path):
    folder, _ = moving_cloud
    f = ScanSequence(folder).files[3]
    f.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 50\n")
    out = tmp_path / "o"
    r = runner.invoke(app, ["odometry", str(folder), "-m", "icp-point", "--out", str(out)])
    assert r.exit_code == 0, r.output
    rows = list(csv.DictReader((out / "diagnostics.csv").open()))
    assert len(rows) == 10 and rows[3]["status"] == "failed"
    assert "unreadable scan" in rows[3]["message"]
    assert (out / "metrics.json").is_file()
    out2 = tmp_path / "strict"
    r = runner.invoke(
        app, ["odometry", str(folder), "-m", "icp-point", "--strict", "--out", str(out2)]
    )
    assert isinstance(r.exception, InputError)
    assert not (out2 / "estimate.tum").exists()
    assert not list(out2.glob(".*.tmp"))


def test_ply_renamed_bin_in_a_sequence_is_flagged_not_ok(moving_cloud):  # item 7
    """The issue's case: icp-point used to mark this frame ok with a 1.45e34 m jump."""
    folder, poses = moving_cloud
    seq = ScanSequence(folder)
    f = seq.files[3]
    f.rename(f.with_suffix(".bin"))
    run = run_sequence(ScanSequence(folder), _Exact())
    assert run.steps[3].status == "failed" and "PLY file" in run.steps[3].result.message
    assert np.abs(run.poses[:, :3, 3]).max() < 10.0
    np.testing.assert_allclose(run.poses[4:], poses[4:], atol=1e-9)


def test_absurd_scan_array_is_never_registered(rng):
    scan = rng.uniform(-5.0, 5.0, (100, 3))
    odo = Odometry(_Exact())
    odo.register_frame(scan)
    step = odo.register_frame(scan * 1e35)
    assert step.status == "failed" and "misread" in step.result.message
    assert odo.register_frame(scan).status == "ok"


def test_streamed_run_equals_in_memory_run(moving_cloud, tmp_path):  # item 16
    folder, _ = moving_cloud
    seq = ScanSequence(folder)
    mem = run_sequence(seq, "icp-point")
    paths = mem.write(tmp_path / "mem")
    streamed = run_sequence(seq, "icp-point", out=tmp_path / "st", keep_steps=False)
    assert streamed.steps == [] and streamed.n_flagged == mem.n_flagged
    assert (tmp_path / "st" / "estimate.tum").read_bytes() == paths["estimate"].read_bytes()
    a = list(csv.DictReader(paths["diagnostics"].open()))
    b = list(csv.DictReader((tmp_path / "st" / "diagnostics.csv").open()))
    drop = lambda r: {k: v for k, v in r.items() if not k.startswith("t_")}  # noqa: E731
    assert [drop(r) for r in a] == [drop(r) for r in b]
    assert not list((tmp_path / "st").glob(".*"))


def test_streamed_run_keeps_the_steps_sigma(moving_cloud, tmp_path):
    """errors.png's σ envelope: a streamed run (the CLI's, no steps kept) still has each
    step's 1σ, equal to the steps' own."""
    folder, _ = moving_cloud
    seq = ScanSequence(folder)
    mem = run_sequence(seq, "relnav")
    streamed = run_sequence(seq, "relnav", out=tmp_path / "st", keep_steps=False)
    own = [s.result.info.get("step_sigma_t", np.nan) if s.result else np.nan for s in mem.steps]
    assert streamed.step_sigma is not None and streamed.step_sigma.shape == (len(seq), 2)
    np.testing.assert_array_equal(streamed.step_sigma[:, 0], own)
    assert np.isnan(streamed.step_sigma[0]).all() and np.isfinite(streamed.step_sigma[1:]).any()
    assert run_sequence(seq, "icp-point").step_sigma is None  # no step covariance: none


class _Fixed:
    name = "fixed"

    def __init__(self, T):
        self.T = T

    def register(self, source, target, *, init=None):
        return RegistrationResult(T_target_source=self.T, status="ok", inlier_rmse=0.0)


def test_step_beyond_the_scene_is_not_ok(rng):  # item 7: "bound every accepted step"
    scan = rng.uniform(-5.0, 5.0, (100, 3))  # reach ~8.7 m
    far = np.eye(4)
    far[0, 3] = 1.45e34
    odo = Odometry(_Fixed(far))
    odo.register_frame(scan)
    step = odo.register_frame(scan)
    assert (
        step.status == "failed" and step.used_prior and "could not overlap" in step.result.message
    )
    np.testing.assert_array_equal(step.pose, np.eye(4))
    bad = np.full((4, 4), np.nan)
    odo = Odometry(_Fixed(bad))
    odo.register_frame(scan)
    step = odo.register_frame(scan)
    assert step.status == "failed" and np.isfinite(step.pose).all()
    near = np.eye(4)
    near[0, 3] = 3.0
    odo = Odometry(_Fixed(near))
    odo.register_frame(scan)
    assert odo.register_frame(scan).status == "ok"


# ------------------------------------------------------------------ benchmark lock (item 15)

GRID = {
    "name": "lock",
    "scenarios": [{"preset": "sim-voyager", "max_frames": 3}],
    "methods": ["icp-point", "icp-x84"],
    "seeds": [0, 1],
    "warmup_frames": 0,
}


def test_folder_lock_times_out_with_holder(tmp_path):
    with FolderLock(tmp_path, what="relnav benchmark"):
        with pytest.raises(InputError, match=f"pid {os.getpid()}"):
            FolderLock(tmp_path, timeout=0.3, what="relnav benchmark").acquire()
    with FolderLock(tmp_path, timeout=0):  # released
        pass


def _bench_cmd(grid: Path, out: Path) -> list[str]:
    code = "from relnav.cli.main import main; main()"
    return [
        sys.executable,
        "-c",
        code,
        "benchmark",
        str(grid),
        "--out",
        str(out),
        "--workers",
        "0",
        "--no-report",
    ]


def _env() -> dict[str, str]:
    src = str(Path(__file__).resolve().parents[1] / "src")
    return {**os.environ, "PYTHONPATH": src + os.pathsep + os.environ.get("PYTHONPATH", "")}


def test_two_benchmarks_on_one_folder_run_each_job_once(tmp_path):
    grid = tmp_path / "grid.yaml"
    grid.write_text(yaml.safe_dump(GRID))
    out = tmp_path / "bench"
    procs = [
        subprocess.Popen(
            _bench_cmd(grid, out),
            env=_env(),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    for p in procs:
        _, err = p.communicate(timeout=600)
        assert p.returncode == 0, err
    runs = [json.loads(x) for x in (out / "runs.jsonl").read_text().splitlines()]
    assert len(runs) == 2
    assert sum(r["n_ok"] + r["n_failed"] for r in runs) == 4  # each job ran exactly once
    assert sorted(r["n_skipped"] for r in runs) == [0, 4]


# ------------------------------------------------------------------ fault injection


def _complete_tum(p: Path, n: int) -> bool:
    lines = p.read_text().splitlines()
    return len(lines) == n and all(len(x.split()) == 8 for x in lines)


def _wait_for(cond, timeout: float = 300.0) -> None:
    t0 = time.monotonic()
    while not cond():
        assert time.monotonic() - t0 < timeout, "the run never reached the kill point"
        time.sleep(0.02)


def _lines(folder: Path, pattern: str) -> int:
    return sum(len(f.read_bytes().splitlines()) for f in folder.glob(pattern))


def test_sigkill_odometry_then_rerun(tmp_path):
    n = 200
    seq = tmp_path / "seq"
    r = runner.invoke(app, ["simulate", "sim-voyager", "--max-frames", str(n), "--out", str(seq)])
    assert r.exit_code == 0, r.output
    out = tmp_path / "o"
    code = "from relnav.cli.main import main; main()"
    cmd = [sys.executable, "-c", code, "odometry", str(seq), "-m", "icp-point", "--out", str(out)]
    kill_rows = np.random.default_rng(11).integers(1, n - 1, 3)  # seeded kill points (frames)
    for k, at in enumerate(kill_rows):
        p = subprocess.Popen(cmd, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        # kill while the estimate is being streamed, after `at` frames
        _wait_for(
            lambda p=p, at=at: (
                _lines(out, f".estimate.tum.{p.pid}.tmp") >= at or p.poll() is not None
            )
        )
        p.send_signal(signal.SIGKILL)
        p.wait()
        # whatever the kill point: a trusted file is complete, never half-written
        if k == 0:
            assert not (out / "estimate.tum").exists() and not (out / "diagnostics.csv").exists()
        for f in (out / "estimate.tum", out / "diagnostics.csv"):
            if f.exists():
                assert _complete_tum(f, n) or len(f.read_text().splitlines()) == n + 1
    done = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert _complete_tum(out / "estimate.tum", n)
    assert len(list(csv.DictReader((out / "diagnostics.csv").open()))) == n
    assert not list(out.glob(".*.tmp"))  # stale temporaries of killed runs removed


def test_sigkill_benchmark_then_rerun_loses_nothing(tmp_path):
    from relnav.bench.store import ResultsStore

    n = 30
    grid = tmp_path / "grid.yaml"
    scen = [{"preset": "sim-voyager", "max_frames": n}]
    grid.write_text(yaml.safe_dump({**GRID, "scenarios": scen}))
    out = tmp_path / "bench"
    rng = np.random.default_rng(5)
    seen: dict[str, str] = {}

    def n_rows() -> int:
        if not (out / "results.sqlite").is_file():
            return 0
        try:
            with ResultsStore(out / "results.sqlite", readonly=True) as st:
                return len(st)
        except Exception:  # store being created
            return 0

    for _ in range(3):
        before = n_rows()
        p = subprocess.Popen(
            _bench_cmd(grid, out), env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        at = min(before + int(rng.integers(0, 2)), 3)  # seeded kill point: jobs stored
        _wait_for(lambda p=p, at=at: n_rows() >= at or p.poll() is not None)
        time.sleep(float(rng.uniform(0.0, 0.5)))  # ... plus a random part of the next job
        p.send_signal(signal.SIGKILL)
        p.wait()
        if (out / "results.sqlite").is_file():
            with ResultsStore(out / "results.sqlite", readonly=True) as st:
                rows = st.rows()
            for r in rows:  # a finished job stays finished, with the same result
                assert seen.setdefault(r["job_id"], r["finished_at"]) == r["finished_at"]
                assert _complete_tum(out / r["estimate_path"], n)
    done = subprocess.run(
        _bench_cmd(grid, out), env=_env(), capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr
    with ResultsStore(out / "results.sqlite", readonly=True) as st:
        rows = st.rows()
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows)
    for r in rows:
        assert seen.get(r["job_id"], r["finished_at"]) == r["finished_at"]  # not redone
        assert _complete_tum(out / r["estimate_path"], n)
    last = json.loads((out / "runs.jsonl").read_text().splitlines()[-1])
    assert last["n_skipped"] == len(seen)
