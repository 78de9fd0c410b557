"""Issue 41: every reader and ``decode_pointcloud2`` under mutated input (hypothesis).

Property: a reader either returns finite ``(N, 3)`` float64 points (or its documented type)
or raises the project's error (:class:`relnav.errors.RelnavError`) — never another exception,
never more than a bounded amount of memory for the file's size (tracemalloc peak), never a
hang (a generous alarm as a guard, not a timing assertion).

Examples: ``RELNAV_FUZZ=local`` for the long run (``RELNAV_FUZZ_EXAMPLES`` per reader,
default 300); the default ``ci`` profile runs a few hundred in total, derandomised (the same
examples every run). Inputs that crashed a reader are kept in ``tests/data/fuzz_corpus`` and
replayed by :func:`test_regression_corpus`.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import tracemalloc
import warnings
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from relnav.errors import RelnavError

CORPUS = Path(__file__).parent / "data" / "fuzz_corpus"

settings.register_profile(
    "relnav-fuzz-ci",
    max_examples=20,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
settings.register_profile(
    "relnav-fuzz-local",
    max_examples=int(os.environ.get("RELNAV_FUZZ_EXAMPLES", "300")),
    derandomize=False,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
PROFILE = settings.get_profile(
    "relnav-fuzz-local" if os.environ.get("RELNAV_FUZZ") == "local" else "relnav-fuzz-ci"
)

MEMORY_FLOOR = 16 << 20
"""Bytes any read may take whatever the file's size (the largest peak seen over 6 000 examples
was 2.7 MB, a scenario YAML; LAZ files are decompressed in a child process)."""
MEMORY_PER_BYTE = 200
"""Bytes per file byte a read may take beyond the floor."""
HANG_GUARD_S = 60
"""A read taking longer than this is a hang (the slowest seen reads take milliseconds)."""

STATS: Counter[tuple[str, str]] = Counter()
"""(reader, outcome) -> examples; written to ``$RELNAV_FUZZ_STATS`` (JSON) when set."""
PEAKS: dict[str, int] = {}
"""reader -> largest traced memory peak of one read, bytes (written with the stats)."""


@pytest.fixture(scope="module", autouse=True)
def _stats() -> Iterator[None]:
    yield
    if target := os.environ.get("RELNAV_FUZZ_STATS"):
        rows: dict[str, int] = {f"{r} {o}": n for (r, o), n in sorted(STATS.items())}
        rows.update({f"{r} peak_bytes": n for r, n in sorted(PEAKS.items())})
        Path(target).write_text(json.dumps(rows, indent=1) + "\n")


# --- seeds --------------------------------------------------------------------------------


def _cloud(n: int = 40) -> np.ndarray:
    return np.random.default_rng(7).uniform(-3.0, 3.0, (n, 3)) + np.array([20.0, 0.0, 0.0])


def _seed_files(folder: Path) -> dict[str, list[bytes]]:
    """Valid files of every point format (several variants each), as bytes."""
    from relnav.io.pointclouds import write_points

    pts = _cloud()
    inten = np.linspace(0.0, 1.0, len(pts))
    times = np.linspace(0.0, 0.1, len(pts))
    seeds: dict[str, list[bytes]] = {}
    variants: list[tuple[str, dict[str, Any]]] = [
        (".ply", {"binary": True}),
        (".ply", {"binary": False}),
        (".pcd", {"binary": True}),
        (".pcd", {"binary": False}),
        (".xyz", {}),
        (".txt", {}),
        (".csv", {}),
        (".npy", {}),
        (".bin", {}),
        (".las", {}),
        (".laz", {}),
    ]
    for k, (ext, kw) in enumerate(variants):
        p = folder / f"seed{k}{ext}"
        extra = {} if ext == ".bin" else {"intensity": inten}
        if ext in (".ply", ".pcd", ".las", ".laz"):
            extra["timestamps"] = times
        write_points(p, pts, **extra, **kw)
        seeds.setdefault(ext, []).append(p.read_bytes())
    seeds[".pcd"].append(_compressed_pcd(pts))
    return seeds


def _compressed_pcd(pts: np.ndarray) -> bytes:
    """A ``binary_compressed`` PCD (field-major float32 x, y, z; LZF literal runs)."""
    n = len(pts)
    raw = np.concatenate([pts[:, j].astype("<f4") for j in range(3)]).tobytes()
    stream = b"".join(
        bytes([len(raw[i : i + 32]) - 1]) + raw[i : i + 32] for i in range(0, len(raw), 32)
    )
    header = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary_compressed\n"
    ).encode()
    return header + np.array([len(stream), len(raw)], dtype="<u4").tobytes() + stream


TEXT_SEEDS = {
    "timestamps": b"# t\n0.0\n0.1\n0.2\n0.30000001\n",
    "tum": b"# t x y z qx qy qz qw\n0 1 2 3 0 0 0 1\n1 1.5 2 3 0 0 0.0998 0.995\n",
    "kitti": b"1 0 0 1 0 1 0 2 0 0 1 3\n1 0 0 1.5 0 1 0 2 0 0 1 3\n",
    "calib": b"P0: 7 0 6 0 0 7 1 0 0 0 1 0\nTr: 1 0 0 0.1 0 1 0 0.2 0 0 1 0.3\n",
    "yaml": b"name: test\nframes: 10\ntarget:\n  name: voyager\nsensors:\n- preset: goldeneye\n",
}


# --- mutation -----------------------------------------------------------------------------

_INTERESTING = [0, 1, 0x7F, 0x80, 0xFF, 0x7FFF, 0xFFFF, 2**31 - 1, 2**31, 2**32 - 1, 10**9]


@st.composite
def mutated(draw: st.DrawFn, seeds: list[bytes]) -> bytes:
    """A seed with 1-6 mutations: byte flips and sets, interesting integers written over 1-8
    bytes, ASCII digits inserted (numbers in text headers), truncation, insertion, deletion,
    block duplication. Positions favour the first 512 bytes (headers)."""
    data = bytearray(draw(st.sampled_from(seeds)))
    for _ in range(draw(st.integers(1, 6))):
        n = len(data)
        hi = max(n - 1, 0)
        pos = draw(st.one_of(st.integers(0, min(hi, 511)), st.integers(0, hi)))
        op = draw(
            st.sampled_from(["flip", "set", "int", "digits", "trunc", "insert", "delete", "dup"])
        )
        if op == "flip" and n:
            data[pos] ^= 1 << draw(st.integers(0, 7))
        elif op == "set" and n:
            data[pos] = draw(st.integers(0, 255))
        elif op == "int" and n:
            width = draw(st.sampled_from([1, 2, 4, 8]))
            v = draw(st.one_of(st.sampled_from(_INTERESTING), st.integers(0, 2**64 - 1)))
            raw = (v % 256**width).to_bytes(width, draw(st.sampled_from(["little", "big"])))
            data[pos : pos + width] = raw
        elif op == "digits":
            data[pos:pos] = draw(st.text("0123456789-.e", min_size=1, max_size=12)).encode()
        elif op == "trunc":
            del data[pos:]
        elif op == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=64))
        elif op == "delete":
            del data[pos : pos + draw(st.integers(1, 64))]
        elif op == "dup" and n:
            data[pos:pos] = data[pos : pos + draw(st.integers(1, 256))]
    return bytes(data)


class _Hang(Exception):
    pass


@contextlib.contextmanager
def bounded(size: int, name: str = "") -> Iterator[None]:
    """Measure the tracemalloc peak of the block against the file's size; alarm on a hang;
    any Python warning raised in the block fails the example."""

    def _alarm(signum: int, frame: Any) -> None:
        raise _Hang(f"no answer after {HANG_GUARD_S} s")

    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(HANG_GUARD_S)
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no warning leaks to the terminal (case 5)
            yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        peak = tracemalloc.get_traced_memory()[1] - base
        PEAKS[name] = max(PEAKS.get(name, 0), peak)
        assert peak <= MEMORY_FLOOR + MEMORY_PER_BYTE * size, (
            f"{peak} bytes for a {size}-byte input"
        )


@pytest.fixture(scope="module")
def traced() -> Iterator[None]:
    tracemalloc.start()
    yield
    tracemalloc.stop()


def check_points(pts: Any) -> None:
    assert isinstance(pts, np.ndarray) and pts.dtype == np.float64
    assert pts.ndim == 2 and pts.shape[1] == 3
    assert np.isfinite(pts).all()


def run_reader(path: Path, data: bytes, read: Callable[[Path], Any], name: str) -> Any:
    """Write ``data`` to ``path`` and read it: the result, or None on a RelnavError."""
    path.write_bytes(data)
    with bounded(len(data), name):
        try:
            out = read(path)
        except RelnavError as e:
            assert str(e), "an error with an empty message"
            STATS[(name, type(e).__name__)] += 1
            return None
    STATS[(name, "read")] += 1
    return out


# --- point-cloud readers ------------------------------------------------------------------

POINT_EXTS = [".ply", ".pcd", ".xyz", ".txt", ".csv", ".npy", ".bin", ".las", ".laz"]


@pytest.fixture(scope="module")
def point_seeds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[bytes]]:
    return _seed_files(tmp_path_factory.mktemp("seeds"))


@pytest.mark.parametrize("ext", POINT_EXTS)
def test_point_readers_fuzz(ext, point_seeds, tmp_path, traced):
    from relnav.io.pointclouds import read_points

    seeds = point_seeds[ext]
    for s in seeds:  # the seeds themselves read
        check_points(read_points(_write(tmp_path / f"seed{ext}", s)))

    @PROFILE
    @given(data=mutated(seeds))
    def fuzz(data: bytes) -> None:
        pts = run_reader(tmp_path / f"case{ext}", data, read_points, ext)
        if pts is not None:
            check_points(pts)

    fuzz()


def _write(p: Path, data: bytes) -> Path:
    p.write_bytes(data)
    return p


# --- text readers -------------------------------------------------------------------------


def _timestamps(p: Path) -> np.ndarray:
    from relnav.io.sequences import _read_timestamps

    return _read_timestamps(p)


def _tum(p: Path) -> np.ndarray:
    from relnav.io.trajectories import read_tum

    t, poses = read_tum(p)
    assert poses.shape == (len(t), 4, 4) and np.isfinite(poses).all()
    return t


def _kitti(p: Path) -> np.ndarray:
    from relnav.io.trajectories import read_kitti

    poses = read_kitti(p)
    assert poses.ndim == 3 and poses.shape[1:] == (4, 4) and np.isfinite(poses).all()
    return poses


def _calib(p: Path) -> Any:
    from relnav.io.sources import read_kitti_calib_tr

    T = read_kitti_calib_tr(p)
    assert T is None or (T.shape == (4, 4) and np.isfinite(T).all())
    return T


def _yaml(p: Path) -> Any:
    from relnav.config import load_yaml

    d = load_yaml(p)
    assert isinstance(d, dict)
    return d


TEXT_READERS: dict[str, Callable[[Path], Any]] = {
    "timestamps": _timestamps,
    "tum": _tum,
    "kitti": _kitti,
    "calib": _calib,
    "yaml": _yaml,
}


@pytest.mark.parametrize("kind", list(TEXT_READERS))
def test_text_readers_fuzz(kind, tmp_path, traced):
    read = TEXT_READERS[kind]
    read(_write(tmp_path / "seed.txt", TEXT_SEEDS[kind]))

    @PROFILE
    @given(data=mutated([TEXT_SEEDS[kind]]))
    def fuzz(data: bytes) -> None:
        out = run_reader(tmp_path / "case.txt", data, read, kind)
        if kind == "timestamps" and out is not None:
            assert out.dtype == np.float64 and np.isfinite(out).all()

    fuzz()


def test_scenario_and_grid_yaml_fuzz(tmp_path, traced):
    """Mutated YAML through the scenario and grid loaders: a scenario/grid or a RelnavError."""
    from relnav.bench.grid import load_grid
    from relnav.sim.scenario import load_scenario

    configs = Path(__file__).parents[1] / "configs"
    seeds = [TEXT_SEEDS["yaml"]]
    for name in ("nav/voyager-ellipse-128.yaml", "paper1-fidelity-quick.yaml"):
        if (configs / name).is_file():  # a scenario and a grid
            seeds.append((configs / name).read_bytes())

    @PROFILE
    @given(data=mutated(seeds), which=st.sampled_from([load_scenario, load_grid]))
    def fuzz(data: bytes, which: Callable[[Path], Any]) -> None:
        run_reader(tmp_path / "case.yaml", data, which, which.__name__)

    fuzz()


# --- PointCloud2 --------------------------------------------------------------------------

_BIG = st.one_of(st.integers(-(2**40), 2**40), st.sampled_from(_INTERESTING))


_PF_SIZE = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 8: 8}


@st.composite
def pointcloud2(draw: st.DrawFn) -> SimpleNamespace:
    """A valid message (x, y, z of random types at random places, padding, row padding), then
    0-3 of its layout attributes replaced by random or absurd values."""
    types = [draw(st.sampled_from(sorted(_PF_SIZE))) for _ in range(3)]
    order = draw(st.permutations([0, 1, 2]))
    offsets, at = [0, 0, 0], 0
    for j in order:
        at += draw(st.integers(0, 4))
        offsets[j] = at
        at += _PF_SIZE[types[j]]
    step = at + draw(st.integers(0, 8))
    width, height = draw(st.integers(0, 40)), draw(st.integers(0, 3))
    row = width * step + draw(st.integers(0, 8))
    fields = [
        SimpleNamespace(name=n, offset=offsets[j], datatype=types[j], count=1)
        for j, n in enumerate("xyz")
    ]
    nbytes = row * height
    data = draw(st.binary(min_size=nbytes, max_size=nbytes)) if nbytes <= 4096 else b""
    msg = SimpleNamespace(
        fields=fields,
        height=height,
        width=width,
        point_step=step,
        row_step=row,
        is_bigendian=draw(st.booleans()),
        data=data,
    )
    for _ in range(draw(st.integers(0, 3))):
        what = draw(st.sampled_from(["height", "width", "point_step", "row_step", "field", "data"]))
        if what == "field":
            f = draw(st.sampled_from(msg.fields))
            attr = draw(st.sampled_from(["offset", "datatype", "count", "name"]))
            value = draw(st.sampled_from("xyzi")) if attr == "name" else draw(_BIG)
            setattr(f, attr, value)
        elif what == "data":
            msg.data = draw(st.binary(min_size=0, max_size=4096))
        else:
            setattr(msg, what, draw(_BIG))
    msg.data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    return msg


def test_decode_pointcloud2_fuzz(traced):
    from relnav.io.bags import decode_pointcloud2

    @PROFILE.__class__(PROFILE, max_examples=PROFILE.max_examples * 5)
    @given(msg=pointcloud2())
    def fuzz(msg: SimpleNamespace) -> None:
        with bounded(len(msg.data) + 4096, "PointCloud2"):
            try:
                pts = decode_pointcloud2(msg)
            except RelnavError:
                STATS[("PointCloud2", "InputError")] += 1
                return
        STATS[("PointCloud2", "read")] += 1
        check_points(pts)

    fuzz()


# --- regression corpus --------------------------------------------------------------------


def _corpus_reader(p: Path) -> Callable[[Path], Any]:
    from relnav.io.pointclouds import read_points

    kind = p.name.split("__")[0]
    if kind in TEXT_READERS:
        return TEXT_READERS[kind]
    return read_points


@pytest.mark.parametrize(
    "path", sorted(CORPUS.glob("*")) if CORPUS.is_dir() else [], ids=lambda p: p.name
)
def test_regression_corpus(path, traced):
    """Inputs that crashed, hung or exhausted memory before (issue 41): now a RelnavError or
    finite points."""
    data = path.read_bytes()
    with bounded(len(data)):
        try:
            out = _corpus_reader(path)(path)
        except RelnavError:
            return
    if isinstance(out, np.ndarray) and out.ndim == 2 and out.shape[1:] == (3,):
        check_points(out)


def test_corpus_is_small():
    total = sum(p.stat().st_size for p in CORPUS.glob("*")) if CORPUS.is_dir() else 0
    assert total < 200_000


def test_bounded_detects_a_leak(traced):
    """The memory guard itself fails when a read takes far more than the bound."""
    with pytest.raises(AssertionError, match="bytes for a 10-byte input"), bounded(10):
        big = np.ones(MEMORY_FLOOR // 8 + 4096 * 1024)
        del big
    assert io.BytesIO  # the module's imports stay used
