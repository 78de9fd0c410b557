"""Recordings, KITTI folders and plain folders in, end to end through ``relnav odometry``.

Every input is written by the test itself: ROS 1 / ROS 2 (sqlite3) / MCAP bags with
``sensor_msgs/PointCloud2`` (via ``rosbags``' writers), a KITTI odometry folder and a plain folder
of scans, all holding the same simulated scans, so the estimates must agree exactly.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from relnav.cli.main import app
from relnav.errors import InputError, RelnavError
from relnav.geometry.se3 import invert
from relnav.io.bags import BagSequence, decode_pointcloud2
from relnav.io.sources import open_sequence
from relnav.io.trajectories import read_kitti, read_tum, write_kitti

rosbags = pytest.importorskip("rosbags")
from rosbags.typesys import Stores, get_typestore  # noqa: E402

runner = CliRunner()
N_FRAMES = 6
METHOD = "icp-point"


@pytest.fixture(scope="module")
def sim_seq(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short simulated sequence (scans in the sensor frame + ground truth)."""
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    out = tmp_path_factory.mktemp("sim") / "seq"
    simulate(get_preset("sim-voyager", max_frames=N_FRAMES, seed=3), out)
    return out


def _scans(seq_dir: Path) -> tuple[list[np.ndarray], np.ndarray]:
    from relnav.io.sequences import ScanSequence

    seq = ScanSequence(seq_dir)
    return [s.points for s in seq], seq.timestamps


def _pointcloud2(ts, points: np.ndarray, stamp: float, *, layout: str):  # type: ignore[no-untyped-def]
    """A PointCloud2 with x, y, z at unusual offsets/types: float64 with an intensity field in
    between and trailing padding ("f8"), or float32 in z, y, x order over two rows ("f4")."""
    PC2 = ts.types["sensor_msgs/msg/PointCloud2"]
    PF = ts.types["sensor_msgs/msg/PointField"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    n = len(points)
    if layout == "f8":
        dt = np.dtype(
            {
                "names": ["x", "i", "y", "z"],
                "formats": ["<f8", "<f4", "<f8", "<f8"],
                "offsets": [0, 8, 12, 20],
                "itemsize": 32,
            }
        )
        fields = [
            PF(name="x", offset=0, datatype=8, count=1),
            PF(name="intensity", offset=8, datatype=7, count=1),
            PF(name="y", offset=12, datatype=8, count=1),
            PF(name="z", offset=20, datatype=8, count=1),
        ]
        height, width = 1, n
    else:
        dt = np.dtype(
            {"names": ["z", "y", "x"], "formats": ["<f4"] * 3, "offsets": [0, 4, 8], "itemsize": 16}
        )
        fields = [
            PF(name=c, offset=o, datatype=7, count=1) for c, o in (("z", 0), ("y", 4), ("x", 8))
        ]
        if n % 2:
            points = np.vstack([points, [[np.nan, np.nan, np.nan]]])  # a NaN point, dropped
        height, width = 2, len(points) // 2
    rec = np.zeros(len(points), dtype=dt)
    for c in "xyz":
        rec[c] = points[:, "xyz".index(c)]
    data = rec.tobytes()
    row_step = width * dt.itemsize
    if layout == "f4":  # rows padded with 8 bytes
        rows = [data[r * row_step : (r + 1) * row_step] + b"\0" * 8 for r in range(height)]
        data, row_step = b"".join(rows), row_step + 8
    sec = int(np.floor(stamp))
    t = Time(sec=sec, nanosec=round((stamp - sec) * 1e9))
    ros1 = "seq" in Header.__dataclass_fields__
    header = Header(seq=0, stamp=t, frame_id="l") if ros1 else Header(stamp=t, frame_id="l")
    return PC2(
        header=header,
        height=height,
        width=width,
        fields=fields,
        is_bigendian=False,
        point_step=dt.itemsize,
        row_step=row_step,
        data=np.frombuffer(data, dtype=np.uint8).copy(),
        is_dense=False,
    )


def _write_bag(
    path: Path, kind: str, scans: list[np.ndarray], times: np.ndarray, layout: str
) -> Path:
    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        ts = get_typestore(Stores.ROS1_NOETIC)
        with Writer(path) as w:
            con = w.add_connection("/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
            w.add_connection("/other", "std_msgs/msg/String", typestore=ts)
            for k, (p, t) in enumerate(zip(scans, times, strict=True)):
                msg = _pointcloud2(ts, p, t, layout=layout)
                # record time deliberately later than the stamp: relnav must use the stamp
                w.write(con, int((t + 0.5) * 1e9) + k, ts.serialize_ros1(msg, msg.__msgtype__))
        return path
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = get_typestore(Stores.ROS2_HUMBLE)
    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w:
        con = w.add_connection("/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
        for p, t in zip(scans, times, strict=True):
            msg = _pointcloud2(ts, p, t, layout=layout)
            w.write(con, int((t + 0.5) * 1e9), ts.serialize_cdr(msg, msg.__msgtype__))
    if kind == "mcap":
        return next(path.glob("*.mcap"))  # the bare .mcap file
    return path  # the ROS 2 bag folder (metadata.yaml + .db3)


def _plain_folder(sim_seq: Path, dest: Path) -> Path:
    dest.mkdir()
    for f in sorted((sim_seq / "scans").iterdir()):
        shutil.copy(f, dest / f.name)
    shutil.copy(sim_seq / "timestamps.txt", dest / "timestamps.txt")
    return dest


def _fails(args: list[str], *needles: str) -> None:
    """The command stops with a RelnavError (one line from ``relnav``) naming ``needles``."""
    res = runner.invoke(app, args)
    assert res.exit_code != 0
    assert isinstance(res.exception, RelnavError), res.exception
    for n in needles:
        assert n in str(res.exception), (n, str(res.exception))


def _run(args: list[str]) -> str:
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    return res.output


def test_decode_pointcloud2_any_offsets_and_types() -> None:
    ts = get_typestore(Stores.ROS2_HUMBLE)
    pts = np.random.default_rng(0).normal(size=(7, 3))
    got = decode_pointcloud2(_pointcloud2(ts, pts, 1.0, layout="f8"))
    np.testing.assert_array_equal(got, pts)
    got = decode_pointcloud2(_pointcloud2(ts, pts, 1.0, layout="f4"))  # 2 rows, padded, 1 NaN
    np.testing.assert_array_equal(got, pts.astype(np.float32).astype(np.float64))
    msg = _pointcloud2(ts, pts, 1.0, layout="f8")
    msg.fields = [f for f in msg.fields if f.name != "z"]
    with pytest.raises(InputError, match="no field"):
        decode_pointcloud2(msg)


@pytest.mark.parametrize("kind", ["ros1", "ros2", "mcap"])
def test_odometry_on_a_recording_equals_the_plain_folder(
    sim_seq: Path, tmp_path: Path, kind: str
) -> None:
    scans, times = _scans(sim_seq)
    suffix = {"ros1": ".bag", "ros2": "", "mcap": ""}[kind]
    rec = _write_bag(tmp_path / f"rec{suffix}", kind, scans, times, layout="f8")
    folder = _plain_folder(sim_seq, tmp_path / "plain")

    _run(["odometry", str(rec), "--topic", "/points", "-m", METHOD, "--out", str(tmp_path / "b")])
    _run(["odometry", str(folder), "-m", METHOD, "--out", str(tmp_path / "f")])
    t_b, P_b = read_tum(tmp_path / "b" / "estimate.tum")
    _, P_f = read_tum(tmp_path / "f" / "estimate.tum")
    np.testing.assert_allclose(t_b, times, atol=1e-9)  # header stamps, not record times
    np.testing.assert_allclose(P_b, P_f, atol=1e-9)  # float64 fields: the very same points
    info = json.loads((tmp_path / "b" / "run.json").read_text())
    assert info["sequence"]["kind"] == "recording" and info["sequence"]["topic"] == "/points"
    assert info["sequence"]["frames"] == N_FRAMES
    assert info["sequence"]["content_hash"].startswith("sha256:")


def test_recording_float32_rows_and_topic_errors(sim_seq: Path, tmp_path: Path) -> None:
    scans, times = _scans(sim_seq)
    rec = _write_bag(tmp_path / "r.bag", "ros1", scans, times, layout="f4")
    seq = BagSequence(rec, topic="/points")
    assert len(seq) == N_FRAMES
    np.testing.assert_allclose(seq[2].points, scans[2], atol=1e-5)
    np.testing.assert_allclose(seq[0].points, scans[0], atol=1e-5)  # random access reopens
    # one PointCloud2 topic: --topic may be omitted
    assert len(open_sequence(rec)) == N_FRAMES
    _fails(["odometry", str(rec), "--topic", "/nope", "--out", str(tmp_path)], "/nope", "/points")
    _fails(["odometry", str(tmp_path / "missing.bag"), "--out", str(tmp_path)], "no such")


def test_kitti_layout_in_and_kitti_poses_out(sim_seq: Path, tmp_path: Path) -> None:
    """velodyne/*.bin + times.txt + calib.txt + poses/NN.txt; --format kitti; evaluate KITTI."""
    from relnav.io.sequences import ScanSequence

    src = ScanSequence(sim_seq)
    scans, times = _scans(sim_seq)
    G = src.gt_poses
    G = invert(G[0])[None] @ G  # velodyne poses in the first velodyne frame
    kitti = tmp_path / "dataset" / "sequences" / "04"
    (kitti / "velodyne").mkdir(parents=True)
    for k, p in enumerate(scans):
        rec = np.column_stack([p, np.ones(len(p))]).astype(np.float32)
        rec.tofile(kitti / "velodyne" / f"{k:06d}.bin")
    np.savetxt(kitti / "times.txt", times, fmt="%.6e")
    Tr = np.eye(4)
    Tr[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]  # velodyne → camera axes, as KITTI
    Tr[:3, 3] = [0.27, -0.08, -0.06]
    (kitti / "calib.txt").write_text(
        "P0: "
        + " ".join(["0"] * 12)
        + "\nTr: "
        + " ".join(map(repr, Tr[:3].ravel().tolist()))
        + "\n"
    )
    (tmp_path / "dataset" / "poses").mkdir()
    write_kitti(tmp_path / "dataset" / "poses" / "04.txt", Tr[None] @ G @ invert(Tr)[None])

    seq = open_sequence(kitti)
    np.testing.assert_allclose(seq.gt_poses, G, atol=1e-9)  # camera → velodyne frame
    np.testing.assert_allclose(seq.timestamps, times, rtol=1e-6)

    out = tmp_path / "run"
    _run(["odometry", str(kitti), "-m", METHOD, "--format", "kitti", "--out", str(out)])
    est = read_kitti(out / "estimate_kitti.txt")
    assert est.shape == (N_FRAMES, 4, 4)
    m = json.loads((out / "metrics.json").read_text())
    assert m["n_frames"] == N_FRAMES and m["e_T_avg"] < 1.0  # tracked in the velodyne frame
    info = json.loads((out / "run.json").read_text())
    assert info["sequence"]["kind"] == "kitti"
    assert "estimate_kitti.txt" in info["outputs"]

    # evaluate reads KITTI poses (times from the times.txt written next to the estimate)
    write_kitti(tmp_path / "gt_velo.txt", G)
    doc = tmp_path / "eval.json"
    _run(
        [
            "evaluate",
            str(out / "estimate_kitti.txt"),
            str(tmp_path / "gt_velo.txt"),
            "--json",
            str(doc),
        ]
    )
    e = json.loads(doc.read_text())
    assert e["est_format"] == "kitti" and e["gt_format"] == "kitti"
    assert e["n_matched"] == N_FRAMES
    assert e["e_T_avg"] == pytest.approx(m["e_T_avg"], abs=1e-6)


def test_plain_folder_of_scans_and_bad_folders(sim_seq: Path, tmp_path: Path) -> None:
    folder = _plain_folder(sim_seq, tmp_path / "own")
    seq = open_sequence(folder)
    assert len(seq) == N_FRAMES and seq.gt_poses is None
    np.testing.assert_allclose(seq.timestamps, _scans(sim_seq)[1])
    empty = tmp_path / "empty"
    empty.mkdir()
    _fails(["odometry", str(empty), "--out", str(tmp_path / "o")], "no scans")
    _fails(["odometry", str(folder), "--topic", "/x", "--out", str(tmp_path)], "--topic is for")


def test_recording_without_rosbags_names_the_extra(tmp_path, monkeypatch):
    import sys

    from relnav.errors import ConfigError

    (tmp_path / "x.bag").write_bytes(b"#ROSBAG V2.0\n")
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
    with pytest.raises(ConfigError, match=r"relnav\[ros\]"):
        BagSequence(tmp_path / "x.bag")


@pytest.mark.parametrize("name", ["bad.bag", "bad.mcap", "bad.db3"])
def test_corrupt_recording_is_one_clear_error(tmp_path, name):
    (tmp_path / name).write_bytes(b"not a recording at all" * 10)
    _fails(
        ["odometry", str(tmp_path / name), "-m", METHOD, "--out", str(tmp_path / "o")],
        name,
        "cannot read recording",
    )
