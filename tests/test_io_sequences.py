"""relnav.io.sequences: folder round trip, laziness, second sensor, metadata, bad folders."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

import relnav.io.sequences as seqmod
from relnav.errors import ConfigError, InputError
from relnav.geometry import random_transform
from relnav.io import (
    ScanSequence,
    SequenceWriter,
    read_tum,
    sequence_layout,
    write_points,
    write_sequence,
    write_tum,
)
from relnav.scan import Scan


@pytest.fixture
def data(rng: np.random.Generator) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    scans = [rng.normal(size=(int(rng.integers(5, 40)), 3)) for _ in range(6)]
    times = 10.0 + 0.1 * np.arange(6) + rng.uniform(0, 1e-3, size=6)
    poses = np.stack([random_transform(rng, 20.0) for _ in range(6)])
    return scans, times, poses


def test_write_and_read_back(tmp_path: Path, data: tuple) -> None:
    scans, times, poses = data
    meta = {"name": "flash", "fov_deg": np.float64(30.0), "res": np.array([64, 64])}
    scenario = {"seed": 7, "version": "0.1"}
    out = write_sequence(
        tmp_path / "seq", scans, times, gt_poses=poses, sensor_meta=meta, scenario=scenario
    )
    assert (out / "scans" / "000000.ply").is_file() and (out / "timestamps.txt").is_file()
    seq = ScanSequence(out)
    assert len(seq) == 6 and seq.sensor == "" and seq.folder == out
    np.testing.assert_array_equal(seq.timestamps, times)
    np.testing.assert_allclose(seq.gt_poses, poses, rtol=0, atol=1e-9)
    assert seq.sensor_meta == {"name": "flash", "fov_deg": 30.0, "res": [64, 64]}
    assert seq.scenario == scenario
    for i, scan in enumerate(seq):
        np.testing.assert_array_equal(scan.points, scans[i])
        assert scan.time == times[i] and scan.sensor["name"] == "flash"
    last = seq[-1]
    np.testing.assert_array_equal(last.points, scans[-1])
    assert last.time == times[-1]
    with pytest.raises(IndexError):
        seq[6]
    with pytest.raises(IndexError):
        seq[-7]
    assert ScanSequence.sensors(out) == [""]


@pytest.mark.parametrize("fmt", ["npy", "pcd", "xyz", "bin"])
def test_other_formats(tmp_path: Path, data: tuple, fmt: str) -> None:
    scans, times, _ = data
    write_sequence(tmp_path / fmt, scans, times, fmt=fmt)
    seq = ScanSequence(tmp_path / fmt)
    assert seq.files[0].name == f"000000.{fmt}"
    tol = 1e-5 if fmt in ("pcd", "bin") else 0.0
    np.testing.assert_allclose(seq[3].points, scans[3], rtol=0, atol=tol)
    assert seq.gt_poses is None and seq.sensor_meta == {} and seq.scenario is None


def test_scan_sequence_is_lazy(
    tmp_path: Path, data: tuple, monkeypatch: pytest.MonkeyPatch
) -> None:
    scans, times, poses = data
    write_sequence(tmp_path / "s", scans, times, gt_poses=poses)
    calls: list[Path] = []
    real = seqmod.read_scan

    def counting(path: Path, *args: object, **kw: object) -> Scan:
        calls.append(Path(path))
        return real(path, *args, **kw)

    monkeypatch.setattr(seqmod, "read_scan", counting)
    seq = ScanSequence(tmp_path / "s")
    _ = len(seq), seq.timestamps, seq.gt_poses, seq.sensor_meta
    assert calls == []
    s = seq[4]
    assert [c.name for c in calls] == ["000004.ply"] and len(s) == len(scans[4])
    it = iter(seq)
    next(it)
    assert len(calls) == 2  # iteration reads one scan per step


def test_second_sensor(tmp_path: Path, data: tuple, rng: np.random.Generator) -> None:
    scans, times, poses = data
    folder = tmp_path / "two"
    write_sequence(folder, scans, times, gt_poses=poses, sensor_meta={"name": "lidar"})
    k_scans = [rng.normal(size=(10, 3)) for _ in range(4)]
    k_times = 10.0 + 0.15 * np.arange(4)
    with SequenceWriter(folder, sensor="kinect", fmt="npy", sensor_meta={"name": "kinect"}) as w:
        for pts, t in zip(k_scans, k_times, strict=True):
            w.add(pts, t)
    assert (folder / "scans_kinect" / "000003.npy").is_file()
    assert (folder / "sensor_kinect.yaml").is_file() and (
        folder / "timestamps_kinect.txt"
    ).is_file()
    assert not (folder / "gt_T_target_sensor_kinect.tum").exists()
    assert ScanSequence.sensors(folder) == ["", "kinect"]
    kin = ScanSequence(folder, sensor="kinect")
    assert len(kin) == 4 and kin.sensor == "kinect"
    assert kin.sensor_meta == {"name": "kinect"} and kin.gt_poses is None
    np.testing.assert_array_equal(kin.timestamps, k_times)
    np.testing.assert_array_equal(kin[1].points, k_scans[1])
    prim = ScanSequence(folder)
    assert len(prim) == 6 and prim.sensor_meta == {"name": "lidar"}
    assert prim.gt_poses is not None


def test_user_folder_without_metadata(tmp_path: Path, rng: np.random.Generator) -> None:
    d = tmp_path / "mine" / "scans"
    names = ["scan10.xyz", "scan2.xyz", "scan1.XYZ", "notes.md"]
    for k, name in enumerate(names):
        if name.endswith("md"):
            (d / name).write_text("not a scan")
        else:
            write_points(d / name, np.full((3, 3), float(k)))
    seq = ScanSequence(tmp_path / "mine")
    assert [f.name for f in seq.files] == ["scan1.XYZ", "scan2.xyz", "scan10.xyz"]  # natural
    np.testing.assert_array_equal(seq.timestamps, [0.0, 1.0, 2.0])
    assert seq[2].time == 2.0 and seq[2].points[0, 0] == 0.0
    assert seq.gt_poses is None and seq.scenario is None


def test_times_fall_back_to_gt_file(tmp_path: Path, rng: np.random.Generator) -> None:
    write_sequence(tmp_path / "q", [rng.normal(size=(4, 3))] * 3, None)
    (tmp_path / "q" / "timestamps.txt").unlink()
    write_tum(
        tmp_path / "q" / "gt_T_target_sensor.tum", [5.0, 6.0, 7.5], np.tile(np.eye(4), (3, 1, 1))
    )
    seq = ScanSequence(tmp_path / "q")
    np.testing.assert_array_equal(seq.timestamps, [5.0, 6.0, 7.5])
    assert seq[-1].time == 7.5


def test_gt_row_mismatch_raises(tmp_path: Path, data: tuple) -> None:
    scans, times, poses = data
    write_sequence(tmp_path / "m", scans, times, gt_poses=poses)
    write_tum(tmp_path / "m" / "gt_T_target_sensor.tum", times[:4], poses[:4])
    seq = ScanSequence(tmp_path / "m")
    assert len(seq[0]) > 0  # still usable without GT
    with pytest.raises(InputError, match="4 poses for 6 scans"):
        _ = seq.gt_poses


def test_bad_folders(tmp_path: Path, data: tuple) -> None:
    with pytest.raises(InputError, match="no such sequence folder"):
        ScanSequence(tmp_path / "absent")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="missing scans folder"):
        ScanSequence(tmp_path / "empty")
    scans, times, _ = data
    write_sequence(tmp_path / "t", scans, times)
    (tmp_path / "t" / "timestamps.txt").write_text("0\n1\n")
    with pytest.raises(InputError, match=r"timestamps\.txt: 2 timestamps for 6 scans"):
        ScanSequence(tmp_path / "t")
    (tmp_path / "t" / "timestamps.txt").write_text("0\nabc\n")
    with pytest.raises(InputError, match=r"timestamps\.txt: line 2"):
        ScanSequence(tmp_path / "t")
    with pytest.raises(InputError, match=r"missing scans folder.*sensors present"):
        ScanSequence(tmp_path / "t", sensor="kinect")
    with pytest.raises(InputError, match="invalid sensor name"):
        ScanSequence(tmp_path / "t", sensor="../x")


def test_writer_gt_only_when_every_frame_has_pose(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="relnav.io"):
        with SequenceWriter(tmp_path / "p") as w:
            w.add(np.zeros((2, 3)), 0.0, np.eye(4))
            w.add(np.zeros((2, 3)), 1.0)
    assert not (tmp_path / "p" / "gt_T_target_sensor.tum").exists()
    assert "only 1 of 2 frames" in caplog.text


def test_writer_accepts_scans_and_keeps_attributes(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    pts = rng.normal(size=(8, 3))
    scan = Scan(pts, time=3.25, intensity=np.arange(8.0), timestamps=3.25 + np.arange(8) * 1e-3)
    with SequenceWriter(tmp_path / "w") as w:
        w.add(scan, T_target_sensor=np.eye(4))
        assert w.n_frames == 1
        w.close(scenario={"seed": 3})
    back = ScanSequence(tmp_path / "w")[0]
    assert back.time == 3.25
    np.testing.assert_array_equal(back.intensity, np.arange(8.0))
    np.testing.assert_array_equal(back.timestamps, scan.timestamps)
    t, P = read_tum(tmp_path / "w" / "gt_T_target_sensor.tum")
    np.testing.assert_array_equal(P[0], np.eye(4))
    np.testing.assert_array_equal(t, [3.25])
    with pytest.raises(InputError, match="closed"):
        w.add(pts, 4.0)


def test_writer_refuses_to_mix_with_old_scans(tmp_path: Path, data: tuple) -> None:
    scans, times, poses = data
    write_sequence(tmp_path / "o", scans, times, gt_poses=poses)
    with pytest.raises(InputError, match="overwrite=True"):
        SequenceWriter(tmp_path / "o")
    write_sequence(tmp_path / "o", scans[:2], times[:2], overwrite=True)
    seq = ScanSequence(tmp_path / "o")
    assert len(seq) == 2 and seq.gt_poses is None  # stale GT removed too


def test_writer_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="unknown scan format"):
        SequenceWriter(tmp_path / "f", fmt="e57")
    with SequenceWriter(tmp_path / "g") as w:
        with pytest.raises(InputError, match="frame 0"):
            w.add(np.zeros((2, 3)), float("nan"))
        with pytest.raises(InputError, match=r"\(4, 4\)"):
            w.add(np.zeros((2, 3)), 0.0, np.eye(3))
    with pytest.raises(InputError, match="2 timestamps for 3 scans"):
        write_sequence(tmp_path / "h", [np.zeros((1, 3))] * 3, [0.0, 1.0])


def test_sequence_writes_are_byte_identical(tmp_path: Path, data: tuple) -> None:
    scans, times, poses = data
    for name in ("a", "b"):
        write_sequence(
            tmp_path / name, scans, times, gt_poses=poses, sensor_meta={"m": 1}, scenario={"s": 2}
        )
    files_a = sorted(
        p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file()
    )
    files_b = sorted(
        p.relative_to(tmp_path / "b") for p in (tmp_path / "b").rglob("*") if p.is_file()
    )
    assert files_a == files_b and len(files_a) == 6 + 4
    for rel in files_a:
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()


def test_layout_paths(tmp_path: Path) -> None:
    lay = sequence_layout(tmp_path, "kinect")
    assert lay.scans_dir.name == "scans_kinect"
    assert lay.gt.name == "gt_T_target_sensor_kinect.tum"
    assert lay.sensor_yaml.name == "sensor_kinect.yaml"
    assert lay.timestamps.name == "timestamps_kinect.txt"
    assert sequence_layout(tmp_path).scans_dir.name == "scans"


def test_convert_sequence_streams_scans(tmp_path: Path, data: tuple) -> None:
    scans, times, poses = data
    src = ScanSequence(write_sequence(tmp_path / "src", scans, times, gt_poses=poses))
    out = write_sequence(tmp_path / "dst", src, None, gt_poses=src.gt_poses, fmt="npy")
    dst = ScanSequence(out)
    assert [f.suffix for f in dst.files] == [".npy"] * 6
    np.testing.assert_array_equal(dst.timestamps, times)  # taken from each Scan
    np.testing.assert_array_equal(dst[5].points, scans[5])
    np.testing.assert_allclose(dst.gt_poses, poses, rtol=0, atol=1e-9)
