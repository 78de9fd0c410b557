"""``relnav export``: a simulated sequence written as a ROS 2 bag and as a KITTI folder reads
back with relnav's own readers (same points to float32, same times) and runs through
``relnav odometry``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from relnav.cli.main import app
from relnav.errors import InputError
from relnav.io.export import export_kitti, export_rosbag2
from relnav.io.sources import open_sequence
from relnav.io.trajectories import read_kitti

pytest.importorskip("rosbags")

runner = CliRunner()
N_FRAMES = 5


@pytest.fixture(scope="module")
def sim_seq(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short simulated sequence; its third scan emptied to exercise a no-return frame."""
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    out = tmp_path_factory.mktemp("sim") / "seq"
    simulate(get_preset("sim-voyager", max_frames=N_FRAMES, seed=5), out)
    return out


def _same_scans(a: object, b: object) -> None:
    assert len(a) == len(b) == N_FRAMES  # type: ignore[arg-type]
    np.testing.assert_allclose(b.timestamps, a.timestamps, rtol=0, atol=1e-9)  # type: ignore[attr-defined]
    for i in range(N_FRAMES):
        want = a[i].points.astype(np.float32)  # type: ignore[index]
        got = b[i].points  # type: ignore[index]
        assert got.shape == want.shape and len(got) > 0
        np.testing.assert_array_equal(got.astype(np.float32), want)


@pytest.mark.parametrize("fmt", ["rosbag2", "kitti"])
def test_export_round_trips_and_runs_odometry(sim_seq: Path, tmp_path: Path, fmt: str) -> None:
    out = tmp_path / f"seq_{fmt}"
    r = runner.invoke(app, ["export", str(sim_seq), "--as", fmt, "--out", str(out)])
    assert r.exit_code == 0, r.output
    src = open_sequence(sim_seq)
    back = open_sequence(out)
    _same_scans(src, back)
    if fmt == "kitti":
        assert back.describe()["kind"] == "kitti"
        assert sorted(p.name for p in (out / "velodyne").iterdir())[0] == "000000.bin"
        np.testing.assert_allclose(read_kitti(out / "poses.txt"), src.gt_poses, atol=1e-12)
    else:
        assert back.describe()["kind"] == "recording" and back.topic == "/points"
        assert not list(tmp_path.glob(".*.tmp"))  # the temporary folder was renamed
    # again without --overwrite: one clear error, the export left as it was
    r = runner.invoke(app, ["export", str(sim_seq), "--as", fmt, "--out", str(out)])
    assert r.exit_code == 1 and "already exists" in str(r.exception or r.output)
    run = tmp_path / "run"
    r = runner.invoke(app, ["odometry", str(out), "--method", "icp-point", "--out", str(run)])
    assert r.exit_code == 0, r.output
    info = json.loads((run / "run.json").read_text())
    assert info["sequence"]["kind"] == ("kitti" if fmt == "kitti" else "recording")
    assert info["sequence"]["frames"] == N_FRAMES
    est = np.loadtxt(run / "estimate.tum")
    assert est.shape == (N_FRAMES, 8)
    np.testing.assert_allclose(est[:, 0], src.timestamps, atol=1e-6)

    # relnav view: a KITTI folder with poses.txt draws; a recording (no ground truth) is one line
    png = tmp_path / "view.png"
    r = runner.invoke(app, ["view", str(out), "--out", str(png), "--frames", "2"])
    if fmt == "kitti":
        assert r.exit_code == 0, r.output
        assert png.stat().st_size > 0
    else:
        assert r.exit_code == 1 and "no ground truth" in str(r.exception or r.output)


def test_export_empty_scan_and_mcap(sim_seq: Path, tmp_path: Path) -> None:
    """A scan with no point survives both formats as an empty scan; MCAP storage too."""

    class WithEmpty:
        def __init__(self, seq: object) -> None:
            self.seq = seq
            self.timestamps = seq.timestamps  # type: ignore[attr-defined]
            self.gt_poses = seq.gt_poses  # type: ignore[attr-defined]

        def __len__(self) -> int:
            return len(self.seq)  # type: ignore[arg-type]

        def __getitem__(self, i: int) -> object:
            s = self.seq[i]  # type: ignore[index]
            if i == 2:
                s.points = np.zeros((0, 3))
                s.intensity = None
            return s

    seq = WithEmpty(open_sequence(sim_seq))
    bag = export_rosbag2(seq, tmp_path / "b", storage="mcap", topic="/lidar/points")
    kit = export_kitti(seq, tmp_path / "k")
    assert list(bag.glob("*.mcap"))
    for back in (open_sequence(bag, topic="/lidar/points"), open_sequence(kit)):
        assert len(back) == N_FRAMES
        assert back[2].points.shape == (0, 3)
        assert len(back[3].points) == len(seq[3].points)


def test_export_bad_input(sim_seq: Path, tmp_path: Path) -> None:
    seq = open_sequence(sim_seq)
    with pytest.raises(Exception, match="topic"):
        export_rosbag2(seq, tmp_path / "b", topic="points")
    with pytest.raises(Exception, match="storage"):
        export_rosbag2(seq, tmp_path / "b", storage="zip")

    class Backwards:
        timestamps = np.array([1.0, 0.5])
        gt_poses = None

        def __len__(self) -> int:
            return 2

    with pytest.raises(InputError, match="increasing"):
        export_kitti(Backwards(), tmp_path / "k")
    assert not (tmp_path / "k").exists()
    r = runner.invoke(app, ["export", str(sim_seq), "--as", "las", "--out", str(tmp_path / "x")])
    assert r.exit_code != 0
