"""Issue 41 (reliability, second campaign): recordings, archives and text encodings.

Each test names the case of the issue it covers.
"""

from __future__ import annotations

import logging
import struct
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from relnav.errors import ConfigError, InputError, RelnavError
from relnav.io.bags import BagSequence, decode_pointcloud2
from relnav.io.pointclouds import read_points, write_points
from relnav.io.sources import open_sequence

pytest.importorskip("rosbags")
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS1_NOETIC)


def pc2(
    points: np.ndarray,
    stamp: float,
    *,
    frame: str = "lidar",
    names: str = "xyz",
    step: int | None = None,
    row_step: int | None = None,
    height: int = 1,
    width: int | None = None,
    offsets: tuple[int, ...] | None = None,
    counts: tuple[int, ...] | None = None,
    data: bytes | None = None,
):  # type: ignore[no-untyped-def]
    """A float32 PointCloud2 (ROS 1 types) whose layout fields can be overridden."""
    PC2 = TS.types["sensor_msgs/msg/PointCloud2"]
    PF = TS.types["sensor_msgs/msg/PointField"]
    Header = TS.types["std_msgs/msg/Header"]
    Time = TS.types["builtin_interfaces/msg/Time"]
    pts = np.asarray(points, dtype="<f4").reshape(-1, len(names))
    offsets = offsets or tuple(4 * i for i in range(len(names)))
    counts = counts or (1,) * len(names)
    fields = [
        PF(name=n, offset=o, datatype=7, count=c)
        for n, o, c in zip(names, offsets, counts, strict=True)
    ]
    step = 12 if step is None else step
    width = len(pts) // height if width is None else width
    raw = pts.tobytes() if data is None else data
    sec = int(np.floor(stamp))
    return PC2(
        header=Header(
            seq=0, stamp=Time(sec=sec, nanosec=round((stamp - sec) * 1e9)), frame_id=frame
        ),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=False,
        point_step=step,
        row_step=width * step if row_step is None else row_step,
        data=np.frombuffer(raw, dtype=np.uint8).copy(),
        is_dense=False,
    )


def write_bag(path: Path, msgs: list) -> Path:  # type: ignore[type-arg]
    from rosbags.rosbag1 import Writer

    with Writer(path) as w:
        con = w.add_connection("/points", "sensor_msgs/msg/PointCloud2", typestore=TS)
        for k, m in enumerate(msgs):
            w.write(con, 10**9 * (k + 1), TS.serialize_ros1(m, m.__msgtype__))
    return path


def cloud(k: int, n: int = 50) -> np.ndarray:
    return np.random.default_rng(k).uniform(-1, 1, (n, 3)) + np.array([5.0, 0.0, 0.0])


# --- recordings ---------------------------------------------------------------------------


def test_one_bad_message_does_not_kill_the_stream(tmp_path):  # case 1
    msgs = [pc2(cloud(k), float(k)) for k in range(8)]
    msgs[4] = pc2(cloud(4)[:, :2], 4.0, names="xy", step=8)  # no z field
    seq = BagSequence(write_bag(tmp_path / "a.bag", msgs))
    assert len(seq) == 8
    for k in range(8):
        if k == 4:
            with pytest.raises(InputError, match="no field"):
                seq[k]
        else:  # every later message still decodes
            np.testing.assert_allclose(seq[k].points, cloud(k).astype("f4"), rtol=0, atol=0)


def test_overlapping_rows_are_refused_before_any_allocation(tmp_path):  # case 2
    m = pc2(np.zeros((1, 3)), 0.0, step=12, width=8192, height=98305, row_step=1)
    with pytest.raises(InputError, match="rows overlap"):
        decode_pointcloud2(m)
    # a bag of them: the frame is flagged by the reader, not a MemoryError
    seq = BagSequence(
        write_bag(
            tmp_path / "b.bag",
            [
                pc2(cloud(0), 0.0),
                pc2(np.zeros((1, 3)), 1.0, step=12, width=8192, height=98305, row_step=1),
            ],
        )
    )
    with pytest.raises(InputError, match="rows overlap"):
        seq[1]


@pytest.mark.parametrize(
    ("kw", "needle"),
    [
        ({"offsets": (0, 4, 12)}, "does not fit point_step"),  # z ends beyond point_step
        ({"offsets": (0, 4, -8)}, "does not fit point_step"),  # negative offset
        ({"counts": (1, 1, 2**40)}, "does not fit point_step"),  # count beyond a C int
        ({"offsets": (0, 2, 8)}, "overlap"),  # x and y overlap
        ({"step": 2**20}, "point_step"),
    ],
)
def test_bad_field_layouts_are_input_errors(kw, needle):  # case 3
    m = pc2(cloud(0), 0.0, **kw)
    with pytest.raises(InputError, match=needle):
        decode_pointcloud2(m)


def test_short_data_is_an_input_error():  # case 3 (total size vs data length)
    m = pc2(cloud(0), 0.0, data=cloud(0).astype("<f4").tobytes()[:-1])
    with pytest.raises(InputError, match="too few"):
        decode_pointcloud2(m)


def test_equal_stamps_refused_duplicates_dropped_frame_ids_warned(tmp_path, caplog):  # case 4
    same = [pc2(cloud(k), 5.0) for k in range(12)]
    with pytest.raises(InputError, match="same header stamp"):
        BagSequence(write_bag(tmp_path / "same.bag", same))
    dup = [pc2(cloud(k), float(k)) for k in range(4)]
    dup.insert(2, dup[1])
    alt = [pc2(cloud(k), float(k), frame="a" if k % 2 else "b") for k in range(4)]
    with caplog.at_level(logging.WARNING, logger="relnav.io"):
        seq = BagSequence(write_bag(tmp_path / "dup.bag", dup))
        assert len(seq) == 4
        np.testing.assert_array_equal(seq.timestamps, [0.0, 1.0, 2.0, 3.0])
        np.testing.assert_array_equal(seq[2].points, cloud(2).astype("f4"))
        assert "duplicated message" in caplog.text
        BagSequence(write_bag(tmp_path / "alt.bag", alt))
        assert "2 different frame_ids" in caplog.text


def test_misread_bytes_leak_no_numpy_warning():  # case 5
    raw = np.full(300, 0xFF, dtype=np.uint8).tobytes()  # NaN patterns as float32
    m = pc2(np.zeros((25, 3)), 0.0, data=raw)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pts = decode_pointcloud2(m)
    assert pts.shape == (0, 3)
    absurd = np.full((25, 3), 3e30, dtype="<f4").tobytes()
    with pytest.raises(InputError, match="misread"):
        decode_pointcloud2(pc2(np.zeros((25, 3)), 0.0, data=absurd))


def test_decode_accepts_duck_typed_messages():
    f = SimpleNamespace
    m = f(
        fields=[f(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")],
        height=1,
        width=2,
        point_step=12,
        row_step=24,
        is_bigendian=False,
        data=np.arange(6, dtype="<f4").tobytes(),
    )
    np.testing.assert_array_equal(decode_pointcloud2(m), [[0, 1, 2], [3, 4, 5]])


# --- text encodings -----------------------------------------------------------------------

BAD_UTF8 = b"0.0\n1.0\n\xff\xfe\x00 2.0\n"


def _plain(tmp_path: Path, n: int = 4) -> Path:
    d = tmp_path / "plain"
    d.mkdir()
    for k in range(n):
        write_points(d / f"{k:03d}.ply", cloud(k))
    return d


@pytest.mark.parametrize("name", ["timestamps.txt", "times.txt"])
def test_undecodable_times_name_file_and_offset(tmp_path, name):  # text encodings
    d = _plain(tmp_path)
    (d / name).write_bytes(BAD_UTF8)
    with pytest.raises(InputError, match=rf"{name}.*byte offset 8"):
        open_sequence(d)


def test_undecodable_sensor_yaml_kitti_calib_and_tum(tmp_path, rng):  # text encodings
    from relnav.io.sequences import ScanSequence, write_sequence
    from relnav.io.trajectories import read_tum

    seq = write_sequence(tmp_path / "seq", [cloud(k) for k in range(3)], np.arange(3.0))
    (seq / "sensor.yaml").write_bytes(b"name: \xc3\x28\n")
    with pytest.raises(InputError, match=r"sensor.yaml.*byte offset 6"):
        ScanSequence(seq)
    kitti = tmp_path / "kitti" / "00"
    (kitti / "velodyne").mkdir(parents=True)
    for k in range(2):
        cloud(k).astype("<f4").tofile(kitti / "velodyne" / f"{k:06d}.bin")
    (kitti / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 2)
    (kitti / "calib.txt").write_bytes(b"P0: 1 2 3\nTr: \x80\n")
    with pytest.raises(InputError, match=r"calib.txt.*byte offset 14"):
        open_sequence(kitti)
    (tmp_path / "gt.tum").write_bytes(b"0 0 0 0 0 0 0 1\n\xe9\n")
    with pytest.raises(InputError, match=r"gt.tum.*byte offset 16"):
        read_tum(tmp_path / "gt.tum")


def test_undecodable_scenario_and_grid_yaml(tmp_path):  # text encodings
    from relnav.bench.grid import load_grid
    from relnav.sim.scenario import load_scenario

    p = tmp_path / "bad.yaml"
    p.write_bytes(b"name: caf\xe9\n")
    with pytest.raises(ConfigError, match=r"bad.yaml.*byte offset 9"):
        load_scenario(p)
    with pytest.raises(ConfigError, match=r"bad.yaml.*byte offset 9"):
        load_grid(p)


@pytest.mark.parametrize(("times", "kind"), [("0 1 1 2", "duplicate"), ("3 2 1 0", "decreasing")])
def test_plain_folder_times_must_increase(tmp_path, times, kind):  # plain folders, case 14
    d = _plain(tmp_path)
    (d / "times.txt").write_text("\n".join(times.split()) + "\n")
    with pytest.raises(InputError, match=kind) as e:
        open_sequence(d)
    assert "np.float64" not in str(e.value)
    assert "1.0 s at scan 2" in str(e.value) or "2.0 s at scan 1" in str(e.value)


def test_errors_are_relnav_errors():
    assert issubclass(InputError, RelnavError)
    assert struct.calcsize("<f") == 4  # the layouts above assume 4-byte float32


# --- archives and headers -----------------------------------------------------------------


def _patched(src: Path, dst: Path, offset: int, fmt: str, value: int) -> Path:
    raw = bytearray(src.read_bytes())
    struct.pack_into(fmt, raw, offset, value)
    dst.write_bytes(bytes(raw))
    return dst


@pytest.mark.parametrize("ext", [".laz", ".las"])
def test_las_laz_huge_point_count_is_refused_before_laspy(tmp_path, ext):  # case 6
    src = write_points(tmp_path / f"ok{ext}", cloud(0, 200))
    np.testing.assert_allclose(read_points(src), cloud(0, 200), atol=1e-5)
    bad = _patched(src, tmp_path / f"bad{ext}", 107, "<I", 1_923_080_680)  # 38 GB of records
    with pytest.raises(InputError, match=r"claims 1923080680 points|truncated LAS"):
        read_points(bad)


def test_las_claiming_a_billion_vlrs_is_refused(tmp_path):  # case 7
    src = write_points(tmp_path / "ok.las", cloud(0, 20))
    bad = _patched(src, tmp_path / "bad.las", 100, "<I", 1_400_000_000)
    with pytest.raises(InputError, match="1400000000 VLRs"):
        read_points(bad)


def _lzf_bomb(n_refs: int) -> bytes:
    """A valid LZF stream of ``12 + 264·n_refs`` zero bytes: a literal byte, back references
    of 264 bytes each, and an 11-byte literal."""
    return b"\x00\x00" + b"\xe0\xff\x00" * n_refs + b"\x0a" + b"\x00" * 11


def test_pcd_lzf_bomb_is_refused_before_decompressing(tmp_path, monkeypatch):  # case 8
    import relnav.io.pointclouds.pcd as pcd

    n_refs = 36_000  # 108 kB of LZF -> 9.5 MB of x y z float32
    stream = _lzf_bomb(n_refs)
    usize = 12 + 264 * n_refs
    n = usize // 12
    assert len(pcd.lzf_decompress(stream, usize)) == usize  # a real, decodable stream
    header = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA binary_compressed\n"
    ).encode()
    body = struct.pack("<II", len(stream), n * 12) + stream
    p = tmp_path / "bomb.pcd"
    p.write_bytes(header + body)
    monkeypatch.setattr(pcd, "LZF_MIN_BUDGET", 0)  # as if the file claimed more than 64 MiB
    with pytest.raises(InputError, match=r"claims \d+ bytes from"):
        read_points(p)


def test_pcd_huge_count_is_an_input_error(tmp_path):  # case 9
    p = tmp_path / "count.pcd"
    p.write_bytes(
        b"VERSION 0.7\nFIELDS x y z w\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 99999999999\n"
        b"WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary\n" + b"\0" * 16
    )
    with pytest.raises(InputError, match="COUNT 99999999999"):
        read_points(p)


def test_odometry_over_a_bag_flags_only_the_bad_message(tmp_path):  # case 1, end to end
    from relnav.odometry import run_sequence

    base = cloud(0, 200)
    msgs = [pc2(base + np.array([0.02 * k, 0.0, 0.0]), float(k)) for k in range(8)]
    msgs[4] = pc2(base[:, :2], 4.0, names="xy", step=8)  # no z field
    seq = BagSequence(write_bag(tmp_path / "a.bag", msgs))
    run = run_sequence(seq, "icp-point", initial_pose="identity")
    rows = run.diagnostics()
    unreadable = [int(r["frame"]) for r in rows if "unreadable scan" in str(r["message"])]
    assert unreadable == [4]
    assert len(run.poses) == 8 and np.isfinite(run.poses).all()


def test_a_recording_broken_mid_stream_is_an_input_error(tmp_path, monkeypatch):  # case 1
    seq = BagSequence(write_bag(tmp_path / "a.bag", [pc2(cloud(k), float(k)) for k in range(5)]))
    real = BagSequence._stream

    def broken(self):  # type: ignore[no-untyped-def]
        for k, scan in real(self):
            if k == 2:
                raise ValueError("chunk CRC mismatch")
            yield k, scan

    monkeypatch.setattr(BagSequence, "_stream", broken)
    np.testing.assert_array_equal(seq[1].points, cloud(1).astype("f4"))
    with pytest.raises(InputError, match=r"cannot read message 2 .*CRC"):
        seq[2]
    np.testing.assert_array_equal(seq[0].points, cloud(0).astype("f4"))  # reopened
