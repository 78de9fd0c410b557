"""relnav.io.pointclouds: round trips, hand-written PCD fixtures (incl. LZF), Open3D cross-check,
bad input, NaN handling, empty clouds, byte-identical writes."""

from __future__ import annotations

import logging
import struct
from pathlib import Path

import numpy as np
import pytest

from relnav.errors import InputError
from relnav.io import (
    POINT_WRITE_EXTENSIONS,
    lzf_decompress,
    read_points,
    read_scan,
    write_points,
    write_scan,
)
from relnav.scan import Scan

# Largest coordinate error allowed per format for |x| <= ~40 m (precision of the stored type).
F32 = 40.0 * 2.0**-23  # float32 relative precision at 40 m
TOL = {
    ".ply": 0.0,
    ".pcd": F32,
    ".xyz": 0.0,
    ".txt": 0.0,
    ".csv": 0.0,
    ".npy": 0.0,
    ".bin": F32,
    ".las": 0.5e-6,  # half the 1 µm LAS scale chosen for this extent
    ".laz": 0.5e-6,
}


@pytest.fixture
def cloud(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    pts = rng.normal(scale=10.0, size=(200, 3))
    inten = rng.uniform(0.0, 1.0, size=200)
    return pts, inten


# ---------------------------------------------------------------------------------------------
# tiny LZF compressor (test oracle for the decompressor; liblzf stream format)
# ---------------------------------------------------------------------------------------------


def lzf_compress(data: bytes) -> bytes:
    """Greedy LZF: 3-byte hash table, literal runs of <= 32, back references of <= 264 bytes."""
    out = bytearray()
    lit = bytearray()
    table: dict[bytes, int] = {}
    i, n = 0, len(data)

    def flush() -> None:
        while lit:
            chunk = lit[:32]
            out.append(len(chunk) - 1)
            out.extend(chunk)
            del lit[:32]

    while i < n:
        key = data[i : i + 3]
        ref = table.get(key) if len(key) == 3 else None
        if len(key) == 3:
            table[key] = i
        if ref is not None and i - ref - 1 < 8192:
            m = 0
            while i + m < n and m < 264 and data[ref + m] == data[i + m]:
                m += 1
            if m >= 3:
                flush()
                off = i - ref - 1
                ln = m - 2
                if ln < 7:
                    out.append((ln << 5) | (off >> 8))
                else:
                    out.append((7 << 5) | (off >> 8))
                    out.append(ln - 7)
                out.append(off & 0xFF)
                i += m
                continue
        lit.append(data[i])
        i += 1
    flush()
    return bytes(out)


def test_lzf_decompress_matches_compressor(rng: np.random.Generator) -> None:
    pieces = [
        b"",
        b"a",
        b"abcabcabcabcabcabcabc" * 20,  # long overlapping back references
        bytes(rng.integers(0, 256, size=3000, dtype=np.uint8)),  # mostly literals
        np.repeat(rng.normal(size=50).astype("<f4"), 20).tobytes(),
    ]
    for raw in pieces:
        comp = lzf_compress(raw)
        assert lzf_decompress(comp, len(raw)) == raw
    comp = lzf_compress(pieces[2])
    assert len(comp) < len(pieces[2]) // 5  # the oracle really used back references


def test_lzf_rejects_malformed_streams() -> None:
    with pytest.raises(ValueError):
        lzf_decompress(bytes([5, 1, 2]), 6)  # literal run longer than the stream
    with pytest.raises(ValueError):
        lzf_decompress(bytes([0, 65, 0x20, 0x05]), 4)  # reference before the start
    with pytest.raises(ValueError):
        lzf_decompress(lzf_compress(b"abcdef"), 7)  # wrong expected size


# ---------------------------------------------------------------------------------------------
# round trips
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("ext", POINT_WRITE_EXTENSIONS)
@pytest.mark.parametrize("binary", [True, False])
def test_round_trip_points_and_intensity(
    tmp_path: Path, cloud: tuple[np.ndarray, np.ndarray], ext: str, binary: bool
) -> None:
    pts, inten = cloud
    f = tmp_path / f"c{ext}"
    assert write_points(f, pts, intensity=inten, binary=binary) == f
    scan = read_scan(f, time=2.5)
    assert scan.points.dtype == np.float64 and scan.points.shape == pts.shape
    assert scan.time == 2.5
    np.testing.assert_allclose(scan.points, pts, rtol=0, atol=TOL[ext])
    assert scan.intensity is not None
    itol = 0.0 if ext in (".ply", ".xyz", ".txt", ".csv", ".npy", ".las", ".laz") else 1e-7
    np.testing.assert_allclose(scan.intensity, inten, rtol=0, atol=itol)
    np.testing.assert_array_equal(read_points(f), scan.points)


@pytest.mark.parametrize("ext", [".ply", ".pcd", ".las"])
def test_per_point_timestamps_round_trip(
    tmp_path: Path, rng: np.random.Generator, ext: str
) -> None:
    pts = rng.normal(size=(30, 3))
    t = 1e3 + np.sort(rng.uniform(0, 0.1, size=30))
    scan = Scan(pts, timestamps=t, intensity=np.arange(30.0))
    f = write_scan(tmp_path / f"s{ext}", scan)
    back = read_scan(f)
    assert back.timestamps is not None
    np.testing.assert_array_equal(back.timestamps, t)  # float64 in all three formats
    np.testing.assert_array_equal(back.intensity, np.arange(30.0))


def test_ply_float32_option_and_pcd_float64_option(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    pts = rng.normal(size=(20, 3))
    write_points(tmp_path / "a.ply", pts, double=False)
    write_points(tmp_path / "a.pcd", pts, double=True)
    np.testing.assert_array_equal(read_points(tmp_path / "a.ply"), pts.astype(np.float32))
    np.testing.assert_array_equal(read_points(tmp_path / "a.pcd"), pts)
    assert b"SIZE 8 8 8" in (tmp_path / "a.pcd").read_bytes()[:200]


def test_las_float_intensity_kept_exactly_and_integer_intensity_standard(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    laspy = pytest.importorskip("laspy")
    pts = rng.normal(size=(10, 3))
    write_points(tmp_path / "i.las", pts, intensity=np.arange(10.0) * 100)
    las = laspy.read(tmp_path / "i.las")
    np.testing.assert_array_equal(np.asarray(las.intensity), np.arange(10) * 100)
    assert "intensity_f64" not in set(las.point_format.dimension_names)
    f = rng.uniform(size=10)
    write_points(tmp_path / "f.las", pts, intensity=f)
    np.testing.assert_array_equal(read_scan(tmp_path / "f.las").intensity, f)


@pytest.mark.parametrize("ext", POINT_WRITE_EXTENSIONS)
def test_empty_cloud_round_trip(tmp_path: Path, ext: str) -> None:
    f = write_points(tmp_path / f"e{ext}", np.empty((0, 3)))
    out = read_points(f)
    assert out.shape == (0, 3) and out.dtype == np.float64


@pytest.mark.parametrize("ext", POINT_WRITE_EXTENSIONS)
def test_writes_are_byte_identical(
    tmp_path: Path, cloud: tuple[np.ndarray, np.ndarray], ext: str
) -> None:
    pts, inten = cloud
    a = write_points(tmp_path / f"a{ext}", pts, intensity=inten)
    b = write_points(tmp_path / f"b{ext}", pts.copy(), intensity=inten.copy())
    assert a.read_bytes() == b.read_bytes()


def test_extension_is_case_insensitive(tmp_path: Path, rng: np.random.Generator) -> None:
    pts = rng.normal(size=(5, 3))
    f = write_points(tmp_path / "UP.PLY", pts)
    np.testing.assert_array_equal(read_points(f), pts)


# ---------------------------------------------------------------------------------------------
# hand-written PCD fixtures
# ---------------------------------------------------------------------------------------------

PCD_PTS = np.array([[1.0, 2.0, 3.0], [-4.5, 0.25, 6.0], [0.0, -1.0, 1e3]])
PCD_I = np.array([10.0, 20.0, 30.0])


def _pcd_header(data: str, *, extra_field: bool = True) -> bytes:
    # x y z (float32), a padding/extra field "rgb" (uint32), intensity (float64), a COUNT-2 field
    return (
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\n"
        "FIELDS x y z rgb intensity pair\n"
        "SIZE 4 4 4 4 8 2\n"
        "TYPE F F F U F I\n"
        "COUNT 1 1 1 1 1 2\n"
        "WIDTH 3\n"
        "HEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\n"
        "POINTS 3\n"
        f"DATA {data}\n"
    ).encode("ascii")


def _pcd_records() -> np.ndarray:
    dt = np.dtype(
        [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4"), ("i", "<f8"), ("p", "<i2", (2,))]
    )
    rec = np.zeros(3, dtype=dt)
    rec["x"], rec["y"], rec["z"] = PCD_PTS.T
    rec["rgb"] = [0xFF0000, 0x00FF00, 0x0000FF]
    rec["i"] = PCD_I
    rec["p"] = [[1, 2], [3, 4], [5, 6]]
    return rec


def test_pcd_ascii_fixture(tmp_path: Path) -> None:
    body = "".join(
        f"{x} {y} {z} {c} {i} 7 8\n"
        for (x, y, z), c, i in zip(PCD_PTS, [1, 2, 3], PCD_I, strict=True)
    )
    f = tmp_path / "a.pcd"
    f.write_bytes(_pcd_header("ascii") + body.encode())
    s = read_scan(f)
    np.testing.assert_array_equal(s.points, PCD_PTS)
    np.testing.assert_array_equal(s.intensity, PCD_I)


def test_pcd_binary_fixture(tmp_path: Path) -> None:
    f = tmp_path / "b.pcd"
    f.write_bytes(_pcd_header("binary") + _pcd_records().tobytes())
    s = read_scan(f)
    np.testing.assert_array_equal(s.points, PCD_PTS)
    np.testing.assert_array_equal(s.intensity, PCD_I)


@pytest.mark.parametrize("literal_only", [True, False])
def test_pcd_binary_compressed_fixture(tmp_path: Path, literal_only: bool) -> None:
    rec = _pcd_records()
    # binary_compressed stores the fields one after the other (structure of arrays)
    soa = b"".join(np.ascontiguousarray(rec[name]).tobytes() for name in rec.dtype.names)
    assert len(soa) == rec.nbytes
    if literal_only:
        comp = b"".join(
            bytes([len(soa[k : k + 32]) - 1]) + soa[k : k + 32] for k in range(0, len(soa), 32)
        )
    else:
        comp = lzf_compress(soa)
    f = tmp_path / "c.pcd"
    f.write_bytes(_pcd_header("binary_compressed") + struct.pack("<II", len(comp), len(soa)) + comp)
    s = read_scan(f)
    np.testing.assert_array_equal(s.points, PCD_PTS)
    np.testing.assert_array_equal(s.intensity, PCD_I)


def test_pcd_organised_cloud_with_nans_drops_them(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    pts = np.array([[1, 2, 3], [np.nan, np.nan, np.nan], [4, 5, 6], [7, 8, np.inf]], dtype="<f4")
    head = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        "WIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA binary\n"
    )
    f = tmp_path / "org.pcd"
    f.write_bytes(head.encode() + pts.tobytes())
    with caplog.at_level(logging.WARNING, logger="relnav.io"):
        out = read_points(f)
    np.testing.assert_array_equal(out, [[1, 2, 3], [4, 5, 6]])
    assert "dropped 2 of 4" in caplog.text and "org.pcd" in caplog.text


# ---------------------------------------------------------------------------------------------
# text files
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("plain.xyz", "1 2 3\n4 5 6\n"),
        ("tabs.txt", "1\t2\t3\n4\t5\t6\n"),
        ("comma.csv", "X,Y,Z\n1,2,3\n4, 5, 6\n"),
        ("semi.csv", "x;y;z;r;g;b\n1;2;3;9;9;9\n4;5;6;9;9;9\n"),
        ("cc.txt", "//X Y Z Nx Ny Nz\n1 2 3 0 0 1\n4 5 6 0 1 0\n"),
        ("twoheaders.txt", "exported by tool\nx y z\n1 2 3\n# a comment\n4 5 6\n"),
        ("reordered.csv", "intensity,z,y,x\n7,3,2,1\n8,6,5,4\n"),
    ],
)
def test_text_variants(tmp_path: Path, name: str, text: str) -> None:
    f = tmp_path / name
    f.write_text(text)
    np.testing.assert_array_equal(read_points(f), [[1, 2, 3], [4, 5, 6]])


def test_text_named_and_positional_intensity(tmp_path: Path) -> None:
    (tmp_path / "a.csv").write_text("intensity,z,y,x\n7,3,2,1\n8,6,5,4\n")
    np.testing.assert_array_equal(read_scan(tmp_path / "a.csv").intensity, [7, 8])
    (tmp_path / "b.xyz").write_text("1 2 3 0.5\n4 5 6 0.25\n")
    np.testing.assert_array_equal(read_scan(tmp_path / "b.xyz").intensity, [0.5, 0.25])
    (tmp_path / "c.xyz").write_text("1 2 3 0 0 1\n")
    assert read_scan(tmp_path / "c.xyz").intensity is None


def test_text_normals_read_from_named_columns(tmp_path: Path) -> None:
    (tmp_path / "n.txt").write_text("//X Y Z Nx Ny Nz\n1 2 3 0 0 1\n")
    np.testing.assert_array_equal(read_scan(tmp_path / "n.txt").normals, [[0, 0, 1]])


# ---------------------------------------------------------------------------------------------
# NaN rows, NPY variants
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("ext", [".ply", ".pcd", ".xyz", ".npy"])
def test_nan_rows_dropped_on_read_with_count(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, ext: str
) -> None:
    pts = np.array([[1.0, 2, 3], [np.nan, 0, 0], [4, 5, 6], [0, np.inf, 0], [7, 8, 9]])
    inten = np.array([1.0, 2, 3, 4, 5])
    f = tmp_path / f"n{ext}"
    if ext == ".npy":
        np.save(f, np.column_stack([pts, inten]))
    elif ext == ".xyz":
        f.write_text("1 2 3 1\nnan 0 0 2\n4 5 6 3\n0 inf 0 4\n7 8 9 5\n")
    else:
        from relnav.io.pointclouds import _write_pcd, _write_ply  # bypass writer's own NaN filter

        (_write_ply if ext == ".ply" else _write_pcd)(f, pts, inten, None, True, True)
    with caplog.at_level(logging.WARNING, logger="relnav.io"):
        s = read_scan(f)
    np.testing.assert_array_equal(s.points, pts[[0, 2, 4]])
    np.testing.assert_array_equal(s.intensity, inten[[0, 2, 4]])
    assert "dropped 2 of 5" in caplog.text


def test_nan_rows_dropped_on_write(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    pts = np.array([[1.0, 2, 3], [np.nan, 0, 0]])
    with caplog.at_level(logging.WARNING, logger="relnav.io"):
        write_points(tmp_path / "w.ply", pts, intensity=np.array([5.0, 6.0]))
    assert "dropped 1 of 2" in caplog.text
    s = read_scan(tmp_path / "w.ply")
    np.testing.assert_array_equal(s.points, [[1, 2, 3]])
    np.testing.assert_array_equal(s.intensity, [5.0])


def test_npy_wide_and_structured(tmp_path: Path, rng: np.random.Generator) -> None:
    a = rng.normal(size=(8, 6))
    np.save(tmp_path / "w.npy", a)
    s = read_scan(tmp_path / "w.npy")
    np.testing.assert_array_equal(s.points, a[:, :3])
    assert s.intensity is None
    rec = np.zeros(4, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4")])
    rec["x"], rec["intensity"] = [1, 2, 3, 4], [9, 8, 7, 6]
    np.save(tmp_path / "s.npy", rec)
    s = read_scan(tmp_path / "s.npy")
    np.testing.assert_array_equal(s.points[:, 0], [1, 2, 3, 4])
    np.testing.assert_array_equal(s.intensity, [9, 8, 7, 6])


# ---------------------------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------------------------


def test_missing_file_and_unknown_extension(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"nope\.ply: no such file"):
        read_points(tmp_path / "nope.ply")
    (tmp_path / "cloud.e57").write_bytes(b"x")
    with pytest.raises(InputError, match=r"cloud\.e57.*unknown point-cloud extension"):
        read_points(tmp_path / "cloud.e57")
    with pytest.raises(InputError, match=r"out\.e57"):
        write_points(tmp_path / "out.e57", np.zeros((1, 3)))


@pytest.mark.parametrize("ext", [".ply", ".pcd", ".npy", ".las", ".laz"])
def test_truncated_files_raise(tmp_path: Path, rng: np.random.Generator, ext: str) -> None:
    f = write_points(tmp_path / f"full{ext}", rng.normal(size=(100, 3)), intensity=np.ones(100))
    raw = f.read_bytes()
    g = tmp_path / f"truncated{ext}"
    g.write_bytes(raw[: len(raw) * 2 // 3])
    with pytest.raises(InputError, match=rf"truncated\{ext}"):
        read_points(g)


def test_truncated_pcd_compressed_and_ascii(tmp_path: Path) -> None:
    comp = lzf_compress(b"\x00" * 36)
    f = tmp_path / "tc.pcd"
    head = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nPOINTS 3\nDATA binary_compressed\n"
    f.write_bytes(head.encode() + struct.pack("<II", len(comp) + 10, 36) + comp)
    with pytest.raises(InputError, match=r"tc\.pcd: truncated"):
        read_points(f)
    f.write_bytes(head.encode() + struct.pack("<II", len(comp), 35) + comp)
    with pytest.raises(InputError, match=r"tc\.pcd.*uncompressed size"):
        read_points(f)
    g = tmp_path / "ta.pcd"
    g.write_text(
        "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nPOINTS 3\nDATA ascii\n1 2 3\n4 5 6\n"
    )
    with pytest.raises(InputError, match=r"ta\.pcd: truncated"):
        read_points(g)


@pytest.mark.parametrize(
    ("name", "content", "msg"),
    [
        ("junk.ply", b"this is not a ply file\n", "corrupt"),
        ("junk.pcd", b"hello world\n", "not a PCD"),
        (
            "noxyz.pcd",
            b"FIELDS a b c\nSIZE 4 4 4\nTYPE F F F\nPOINTS 0\nDATA ascii\n",
            "no x, y, z",
        ),
        ("badtype.pcd", b"FIELDS x y z\nSIZE 3 4 4\nTYPE F F F\nPOINTS 0\nDATA ascii\n", "TYPE"),
        ("nodata.pcd", b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\n", "no DATA"),
        ("binary.xyz", bytes(range(256)), "not a text"),
        ("words.txt", b"hello there\ngeneral kenobi\n", "no numeric"),
        ("ragged.csv", b"1,2,3\n4,5\n", "corrupt text"),
        ("odd.bin", b"\x00" * 20, "multiple of 16"),
        ("junk.npy", b"\x93NUMPY garbage", "corrupt"),
        ("junk.las", b"LASF" + b"\x00" * 50, "corrupt"),
    ],
)
def test_corrupt_files_raise_naming_file(
    tmp_path: Path, name: str, content: bytes, msg: str
) -> None:
    f = tmp_path / name
    f.write_bytes(content)
    with pytest.raises(InputError, match=msg) as ei:
        read_points(f)
    assert name in str(ei.value)


def test_wrong_shapes(tmp_path: Path) -> None:
    np.save(tmp_path / "flat.npy", np.zeros(9))
    with pytest.raises(InputError, match=r"flat\.npy.*shape \(9,\)"):
        read_points(tmp_path / "flat.npy")
    np.save(tmp_path / "two.npy", np.zeros((4, 2)))
    with pytest.raises(InputError, match=r"two\.npy"):
        read_points(tmp_path / "two.npy")
    with pytest.raises(InputError, match=r"o\.ply.*\(N, 3\)"):
        write_points(tmp_path / "o.ply", np.zeros((4, 2)))
    with pytest.raises(InputError, match=r"o\.ply.*intensity"):
        write_points(tmp_path / "o.ply", np.zeros((4, 3)), intensity=np.zeros(3))


def test_ply_mesh_without_xyz_raises(tmp_path: Path) -> None:
    f = tmp_path / "uv.ply"
    f.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float u\nend_header\n1\n")
    with pytest.raises(InputError, match=r"uv\.ply.*x, y, z"):
        read_points(f)


# ---------------------------------------------------------------------------------------------
# Open3D cross-check
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("ext", [".pcd", ".ply"])
@pytest.mark.parametrize(("ascii_", "compressed"), [(False, False), (True, False), (False, True)])
def test_open3d_files_read_by_us(
    tmp_path: Path, rng: np.random.Generator, ext: str, ascii_: bool, compressed: bool
) -> None:
    o3d = pytest.importorskip("open3d")
    pts = rng.normal(scale=5.0, size=(300, 3))
    f = tmp_path / f"o3d{ext}"
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    assert o3d.io.write_point_cloud(str(f), pc, write_ascii=ascii_, compressed=compressed)
    if ext == ".pcd" and compressed:
        assert b"DATA binary_compressed" in f.read_bytes()[:400]
    ref = np.asarray(o3d.io.read_point_cloud(str(f)).points)  # Open3D's own reading
    np.testing.assert_allclose(read_points(f), ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(read_points(f), pts, rtol=0, atol=1e-3 if ascii_ else 5 * F32)


@pytest.mark.parametrize("ext", [".pcd", ".ply"])
@pytest.mark.parametrize("binary", [True, False])
def test_our_files_read_by_open3d(
    tmp_path: Path, rng: np.random.Generator, ext: str, binary: bool
) -> None:
    o3d = pytest.importorskip("open3d")
    pts = rng.normal(scale=5.0, size=(300, 3))
    f = write_points(tmp_path / f"ours{ext}", pts, intensity=rng.uniform(size=300), binary=binary)
    got = np.asarray(o3d.io.read_point_cloud(str(f)).points)
    assert got.shape == pts.shape
    np.testing.assert_allclose(got, read_points(f), rtol=0, atol=5 * F32)


def test_pcd_empty_header_without_final_newline(tmp_path: Path) -> None:
    f = tmp_path / "e.pcd"
    f.write_bytes(
        b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 0\nPOINTS 0\nDATA binary"
    )
    assert read_points(f).shape == (0, 3)
