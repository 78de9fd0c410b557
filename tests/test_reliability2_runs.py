"""Issue 41 (reliability, second campaign): output folders, faults and the first hour of
``relnav odometry`` (start pose, missing times, every frame failed, Ctrl-C).

Fault tests: SIGKILL of a running ``relnav odometry`` at several moments, a read-only folder
and a full disk (small tmpfs mounts where the machine allows them, skipped with the reason
elsewhere; the same paths also through a deterministic ``OSError``).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from relnav.cli.main import app
from relnav.errors import ConfigError, EstimationError, OutputError
from relnav.io.locks import FolderLock
from relnav.io.outputs import INCOMPLETE_MARKER
from relnav.io.pointclouds import write_points
from relnav.io.runinfo import read_run_info

runner = CliRunner()
N = 12
METHOD = "icp-point"


@pytest.fixture(scope="module")
def seq(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short simulated sequence with ground truth."""
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    out = tmp_path_factory.mktemp("sim") / "seq"
    simulate(get_preset("sim-voyager", max_frames=N, seed=5), out)
    return out


@pytest.fixture(scope="module")
def plain(seq: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same scans as a plain folder: no times, no ground truth."""
    d = tmp_path_factory.mktemp("plain") / "scans"
    d.mkdir()
    for f in sorted((seq / "scans").iterdir()):
        (d / f.name).write_bytes(f.read_bytes())
    return d


def odo(src: Path, out: Path, *args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(
        app, ["odometry", str(src), "-m", METHOD, "--out", str(out), *args], env={"COLUMNS": "200"}
    )


def one_line_error(r, kind: type) -> str:  # type: ignore[no-untyped-def]
    assert isinstance(r.exception, kind), (r.output, r.exception)
    msg = str(r.exception)
    assert "\n" not in msg and "Traceback" not in r.output
    return msg


# --- output folders -----------------------------------------------------------------------


def test_rerun_without_ground_truth_removes_the_old_metrics(seq, plain, tmp_path):  # case 10
    out = tmp_path / "o"
    assert odo(seq, out).exit_code == 0
    assert (out / "metrics.json").is_file() and (out / "errors.png").is_file()
    (out / "notes.txt").write_text("mine")  # not a run output: never touched
    r = odo(plain, out)
    assert r.exit_code == 0, r.output
    assert not (out / "metrics.json").exists() and not (out / "errors.png").exists()
    assert "removed the previous run's errors.png, metrics.json" in r.output
    listed = r.output.split("wrote ")[-1]
    assert "metrics.json" not in listed and "errors.png" not in listed
    assert (out / "notes.txt").read_text() == "mine"
    info = read_run_info(out)
    assert info["status"] == "complete"
    assert sorted(info["outputs"]) == sorted(
        p.name for p in out.iterdir() if p.name in info["outputs"]
    )


def test_second_run_into_a_locked_folder_is_refused(seq, tmp_path):  # case 11
    out = tmp_path / "o"
    with FolderLock(out, timeout=0, what="odometry run"):  # another run holds the folder
        r = odo(seq, out)
    msg = one_line_error(r, OutputError)
    assert str(out) in msg and f"pid {os.getpid()}" in msg
    assert not (out / "estimate.tum").exists() and not (out / "run.json").exists()
    assert odo(seq, out).exit_code == 0  # released: the next run goes


def test_two_runs_at_once_never_mix(seq, tmp_path):  # case 11, two real processes
    out = tmp_path / "o"
    cmd = [sys.executable, "-c", "from relnav.cli.main import main; main()", "odometry"]
    cmd += [str(seq), "-m", METHOD, "--out", str(out)]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)]
    t0 = time.monotonic()
    while not (out / ".lock").exists() and procs[0].poll() is None:
        assert time.monotonic() - t0 < 120, "the first run never took the folder"
        time.sleep(0.02)
    procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    results = [(p.wait(timeout=300), *p.communicate()) for p in procs]
    codes = sorted(code for code, _, _ in results)
    if codes == [0, 0]:  # the first finished before the second started: sequential, fine
        return
    assert codes == [0, 1], results
    refused = next(err for code, _, err in results if code == 1)
    assert "another odometry run" in refused and "Traceback" not in refused
    info = read_run_info(out)
    assert info["status"] == "complete" and not (out / INCOMPLETE_MARKER).exists()


def test_read_only_folder_is_one_line(seq, tmp_path, monkeypatch):  # case 12 (deterministic)
    import relnav.odometry.runner as runner_mod

    def refuse(self, *a, **k):  # type: ignore[no-untyped-def]
        raise OSError(errno.EROFS, "Read-only file system", str(self._tmp["estimate"]))

    monkeypatch.setattr(runner_mod._RunWriter, "add", refuse)
    out = tmp_path / "o"
    msg = one_line_error(odo(seq, out), OutputError)
    assert msg == f"{out / 'estimate.tum'}: cannot write: Read-only file system"
    assert not list(out.glob(".*.tmp"))  # the streamed temporaries were removed
    assert (out / INCOMPLETE_MARKER).exists()  # the next run knows


def test_full_disk_is_one_line_and_the_next_run_knows(seq, tmp_path, monkeypatch):  # case 12
    import relnav.eval.plots as plots

    real = plots.FigureCanvasAgg.print_png

    def full(self, f, *a, **k):  # type: ignore[no-untyped-def]
        raise OSError(errno.ENOSPC, "No space left on device")

    out = tmp_path / "o"
    monkeypatch.setattr(plots.FigureCanvasAgg, "print_png", full)
    msg = one_line_error(odo(seq, out), OutputError)
    assert msg.startswith(f"{out / 'errors.png'}: cannot write: No space left on device"), msg
    assert not list(out.glob(".*.tmp")) and not (out / "run.json").exists()
    assert (out / INCOMPLETE_MARKER).exists()
    monkeypatch.setattr(plots.FigureCanvasAgg, "print_png", real)
    r = odo(seq, out)
    assert r.exit_code == 0, r.output
    assert "did not finish" in r.output.replace("\n", " ")
    assert read_run_info(out)["status"] == "complete"
    assert not (out / INCOMPLETE_MARKER).exists()


@contextlib.contextmanager
def tmpfs(path: Path, options: str) -> Iterator[Path]:
    """A tmpfs at ``path`` (skip the test when mounting is not permitted here)."""
    path.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)],
        capture_output=True,
        text=True,
    )
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({r.stderr.strip() or r.returncode})")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


def _remount(path: Path, options: str) -> None:
    subprocess.run(["mount", "-o", f"remount,{options}", str(path)], check=True)


@pytest.mark.skipif(sys.platform != "linux", reason="tmpfs mounts are Linux-only")
@pytest.mark.parametrize("size", ["12k", "40k"])
def test_full_tmpfs_then_room_again(seq, tmp_path, size):  # case 12 (a real full disk)
    with tmpfs(tmp_path / "disk", f"size={size}") as disk:
        out = disk / "o"
        msg = one_line_error(odo(seq, out), OutputError)
        assert "No space left on device" in msg and msg.startswith(f"{out}/"), msg
        left = sorted(p.name for p in out.iterdir()) if out.exists() else []
        assert not [n for n in left if n.endswith(".tmp")], left
        if "run.json" in left:  # a complete folder, or one marked incomplete
            assert INCOMPLETE_MARKER in left
        _remount(disk, "size=8m")
        r = odo(seq, out)
        assert r.exit_code == 0, r.output
        if INCOMPLETE_MARKER in left:
            assert "did not finish" in r.output.replace("\n", " ")
        assert read_run_info(out)["status"] == "complete"


@pytest.mark.skipif(sys.platform != "linux", reason="tmpfs mounts are Linux-only")
def test_read_only_mount_is_one_line(seq, tmp_path):  # case 12 (a real read-only folder)
    with tmpfs(tmp_path / "ro", "ro,size=64k") as ro:
        msg = one_line_error(odo(seq, ro / "o"), OutputError)
        assert msg.startswith(f"{ro / 'o'}") and "Read-only file system" in msg


def _env() -> dict[str, str]:
    return {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}


def test_sigkill_at_any_moment_leaves_a_folder_the_next_run_recognises(tmp_path):
    """Kill ``relnav odometry`` while it streams frames and while it writes its last files:
    the folder is either complete (``run.json`` last, no marker) or marked incomplete, and
    the next run says so and replaces it."""
    n = 80
    src = tmp_path / "seq"
    r = runner.invoke(app, ["simulate", "sim-voyager", "--max-frames", str(n), "--out", str(src)])
    assert r.exit_code == 0, r.output
    out = tmp_path / "o"
    cmd = [sys.executable, "-c", "from relnav.cli.main import main; main()", "odometry"]
    cmd += [str(src), "-m", METHOD, "--out", str(out)]

    def streaming(p: subprocess.Popen) -> bool:  # type: ignore[type-arg]
        tmp = out / f".estimate.tum.{p.pid}.tmp"
        return tmp.is_file() and len(tmp.read_bytes().splitlines()) >= n // 3

    def finishing(p: subprocess.Popen) -> bool:  # type: ignore[type-arg]
        return (out / "estimate.tum").is_file()  # outputs being written after the frames

    for moment in (streaming, finishing):
        (out / "estimate.tum").unlink(missing_ok=True)
        p = subprocess.Popen(cmd, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        t0 = time.monotonic()
        while not moment(p) and p.poll() is None:
            assert time.monotonic() - t0 < 300, "the run never reached the kill point"
            time.sleep(0.005)
        alive = p.poll() is None
        p.send_signal(signal.SIGKILL)
        p.wait()
        info = read_run_info(out)
        complete = (
            info is not None
            and info.get("status") == "complete"
            and not (out / INCOMPLETE_MARKER).exists()
            and all((out / f).is_file() for f in info["outputs"])
        )
        assert complete or (out / INCOMPLETE_MARKER).exists()
        if moment is streaming and alive:  # killed among the frames: never complete
            assert not complete
        if not complete:
            done = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=600)
            assert done.returncode == 0, done.stderr
            assert "did not finish" in (done.stdout + done.stderr).replace("\n", " ")
            assert read_run_info(out)["status"] == "complete"
            assert not (out / INCOMPLETE_MARKER).exists() and not list(out.glob(".*.tmp"))
            assert len((out / "estimate.tum").read_text().splitlines()) == n


# --- the first hour -----------------------------------------------------------------------


def test_ctrl_c_saves_what_was_estimated(seq, tmp_path, monkeypatch):
    from relnav.odometry.odometry import Odometry

    real = Odometry.register_frame
    calls = {"n": 0}

    def interrupted_at_5(self, scan):  # type: ignore[no-untyped-def]
        calls["n"] += 1
        if calls["n"] == 6:
            raise KeyboardInterrupt
        return real(self, scan)

    monkeypatch.setattr(Odometry, "register_frame", interrupted_at_5)
    out = tmp_path / "o"
    r = odo(seq, out)
    assert r.exit_code == 130, r.output
    text = " ".join(r.output.split())
    assert text.count("interrupted at frame 5 of 12") == 1, r.output
    info = read_run_info(out)
    assert info["status"] == "interrupted" and info["options"]["interrupted"]["at_frame"] == 5
    assert len((out / "estimate.tum").read_text().splitlines()) == 5
    assert info["flags"]["frames"] == 5
    assert not (out / INCOMPLETE_MARKER).exists()  # a finished (interrupted) folder


def test_every_frame_failed_exits_non_zero(seq, tmp_path):
    out = tmp_path / "o"
    r = odo(seq, out, "-O", "gate_rotation_deg=1e-9", "-O", "gate_translation=1e-9")
    msg = one_line_error(r, EstimationError)
    assert msg.startswith("every frame failed") and r.exit_code == 1
    assert read_run_info(out)["status"] == "failed"
    assert (out / "diagnostics.csv").is_file()  # the reasons are kept


def test_start_pose_is_printed_and_recorded(seq, plain, tmp_path):
    r = odo(seq, tmp_path / "a")
    assert "start pose: the ground truth's first pose (--initial-pose gt)" in r.output
    assert read_run_info(tmp_path / "a")["options"]["initial_pose"] == "gt"
    r = odo(plain, tmp_path / "b")
    assert "start pose: identity (no ground truth" in r.output
    assert read_run_info(tmp_path / "b")["options"]["initial_pose"] == "identity"
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 3.0]
    pose = tmp_path / "T0.txt"
    pose.write_text("\n".join(" ".join(map(str, row)) for row in T) + "\n")
    r = odo(plain, tmp_path / "c", "--initial-pose", str(pose))
    assert r.exit_code == 0, r.output
    assert f"start pose: from {pose}" in r.output.replace("\n", "")
    first = np.array((tmp_path / "c" / "estimate.tum").read_text().split()[1:4], dtype=float)
    np.testing.assert_allclose(first, [1.0, 2.0, 3.0])
    assert read_run_info(tmp_path / "c")["options"]["initial_pose"] == "given"
    r = odo(plain, tmp_path / "d", "--initial-pose", "gt")
    assert "no ground truth" in one_line_error(r, ConfigError)
    r = odo(plain, tmp_path / "e", "--initial-pose", str(tmp_path / "missing.txt"))
    assert "not gt, identity nor a file" in one_line_error(r, ConfigError)


def test_missing_times_warn_and_rate_dt_set_them(seq, plain, tmp_path):
    r = odo(plain, tmp_path / "a", "--max-frames", "3")
    assert "assuming 1 s between scans" in r.output.replace("\n", " ")
    r = odo(plain, tmp_path / "b", "--max-frames", "3", "--rate", "10")
    assert r.exit_code == 0 and "assuming" not in r.output
    t = np.loadtxt(tmp_path / "b" / "estimate.tum")[:, 0]
    np.testing.assert_allclose(t, [0.0, 0.1, 0.2])
    r = odo(plain, tmp_path / "c", "--max-frames", "3", "--dt", "0.5")
    np.testing.assert_allclose(np.loadtxt(tmp_path / "c" / "estimate.tum")[:, 0], [0, 0.5, 1.0])
    assert "own scan times" in one_line_error(odo(seq, tmp_path / "d", "--dt", "0.5"), ConfigError)
    msg = one_line_error(odo(plain, tmp_path / "e", "--rate", "10", "--dt", "1"), ConfigError)
    assert "give one" in msg
    assert "positive" in one_line_error(odo(plain, tmp_path / "f", "--rate", "-1"), ConfigError)


def test_scans_in_millimetres_get_a_units_hint(seq, tmp_path):  # case 13 (units)
    from relnav.io.sequences import ScanSequence

    mm = tmp_path / "mm"
    (mm / "scans").mkdir(parents=True)
    for name in ("timestamps.txt", "gt_T_target_sensor.tum", "sensor.yaml"):
        (mm / name).write_bytes((seq / name).read_bytes())
    s = ScanSequence(seq)
    for f, scan in zip(s.files, s, strict=True):
        write_points(mm / "scans" / f.name, scan.points * 1000.0)
    r = odo(mm, tmp_path / "o", "--max-frames", "3")
    assert "are the scans in millimetres?" in r.output.replace("\n", " ")
    r = odo(seq, tmp_path / "m", "--max-frames", "3")
    assert "are the scans in" not in r.output  # metres: no hint


def test_marker_json_survives_garbage(tmp_path):
    from relnav.io.outputs import RunFolder

    out = tmp_path / "o"
    out.mkdir()
    (out / INCOMPLETE_MARKER).write_bytes(b"\xff\x00")
    (out / "estimate.tum").write_text("0 0 0 0 0 0 0 1\n")
    with RunFolder(out) as folder:
        assert folder.was_incomplete and "estimate.tum" in folder.removed
        assert json.loads((out / INCOMPLETE_MARKER).read_text())["pid"] == os.getpid()
        folder.finish([])
    assert not (out / INCOMPLETE_MARKER).exists()
