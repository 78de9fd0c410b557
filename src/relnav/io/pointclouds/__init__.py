"""Point-cloud files: read and write PLY, PCD, XYZ/TXT/CSV, NPY, KITTI ``.bin`` and LAS/LAZ.

The format is chosen from the file extension (case-insensitive). Every reader returns points as
``(N, 3)`` float64 in the file's own frame (for a sequence folder: the sensor frame), metres.

Extra per-point fields are recognised by name where the format has names (PLY, PCD, headed
text, structured ``.npy``, LAS): intensity (``intensity``, ``i``, ``reflectance``,
``scalar_intensity``...), per-point time (``timestamp``, ``time``, ``t``...) and normals
(``nx ny nz`` or ``normal_x normal_y normal_z``). Formats without names follow a fixed rule:
**[interpretation]** a headerless text file or an ``(N, 4)`` ``.npy`` with exactly four columns
carries intensity in the fourth column; KITTI ``.bin`` is always ``x y z reflectance`` float32.

Rows whose coordinates are NaN or infinite are dropped with a warning on the ``relnav.io`` logger
(organised clouds mark missing returns that way). An empty cloud is valid and reads back as
``(0, 3)``.

Every problem with a file raises :class:`relnav.errors.InputError` naming the file: missing
file, unknown extension, truncated or corrupt content, wrong shape, no ``x``/``y``/``z``, a
binary body whose length disagrees with the header (PLY, PCD, KITTI ``.bin``), a file of another
format behind the extension, or coordinates beyond :data:`ABSURD_COORDINATE` (the signature of
bytes read with the wrong type). **[interpretation]** Coordinates beyond
:data:`SANE_COORDINATE` are accepted with a warning.

Writers are deterministic: the same input gives byte-identical files (no dates, no random ids).
Text formats print the shortest decimal that round-trips (Python ``repr``), so float64 values are
recovered exactly.
"""

from __future__ import annotations

import datetime as _dt
import io as _io
import logging
import re
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from relnav.errors import InputError
from relnav.scan import Scan

__all__ = [
    "ABSURD_COORDINATE",
    "POINT_READ_EXTENSIONS",
    "SANE_COORDINATE",
    "POINT_WRITE_EXTENSIONS",
    "lzf_decompress",
    "read_points",
    "read_scan",
    "write_points",
    "write_scan",
]

logger = logging.getLogger("relnav.io")

POINT_READ_EXTENSIONS: tuple[str, ...] = (
    ".ply",
    ".pcd",
    ".xyz",
    ".txt",
    ".csv",
    ".npy",
    ".bin",
    ".las",
    ".laz",
)
"""Extensions :func:`read_points` understands (lower case)."""

POINT_WRITE_EXTENSIONS: tuple[str, ...] = POINT_READ_EXTENSIONS
"""Extensions :func:`write_points` can write (lower case)."""

ABSURD_COORDINATE = 1.0e9
"""|coordinate| (m) above which a file is rejected as misread (25x the geostationary radius;
float32 garbage is typically ~1e20-1e38)."""

SANE_COORDINATE = 1.0e5
"""|coordinate| (m) above which a scan is accepted with a warning (no LIDAR ranges 100 km)."""

_MAGIC = {
    b"ply\n": "PLY",
    b"ply\r": "PLY",
    b"# .PCD": "PCD",
    b"VERSION": "PCD",
    b"\x93NUMPY": "NPY",
    b"LASF": "LAS/LAZ",
}

# Field names recognised for the optional per-point attributes (compared in lower case).
_INTENSITY_NAMES = (
    "intensity",
    "scalar_intensity",
    "i",
    "reflectance",
    "scalar_reflectance",
    "remission",
    "intensity_f64",
)
_TIME_NAMES = ("timestamp", "timestamps", "time", "t", "scalar_time", "gps_time")
_NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"))

_TEXT_EXTENSIONS = (".xyz", ".txt", ".csv")
_MAX_HEADER_LINES = 50
_LAS_FLOAT_INTENSITY = "intensity_f64"
_LAS_FIXED_DATE = _dt.date(2000, 1, 1)


@dataclass
class _Cloud:
    """Internal result of a format reader (before NaN filtering)."""

    points: np.ndarray
    intensity: np.ndarray | None = None
    timestamps: np.ndarray | None = None
    normals: np.ndarray | None = None


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------


def read_points(path: str | Path) -> np.ndarray:
    """Read the points of a point-cloud file.

    Parameters
    ----------
    path : str or Path
        ``.ply``, ``.pcd``, ``.xyz``, ``.txt``, ``.csv``, ``.npy``, ``.bin`` (KITTI),
        ``.las`` or ``.laz`` (extension case-insensitive).

    Returns
    -------
    (N, 3) float64
        Points in the file's frame, metres; non-finite rows removed.

    Raises
    ------
    InputError
        Missing file, unknown extension, corrupt/truncated content, no x/y/z.
    """
    return _read_any(path).points


def read_scan(path: str | Path, time: float = 0.0, *, sensor: dict | None = None) -> Scan:
    """Read a point-cloud file as a :class:`relnav.scan.Scan`.

    Parameters
    ----------
    path : str or Path
        Any file :func:`read_points` accepts.
    time : float
        Scan time in seconds, stored in ``Scan.time``.
    sensor : dict, optional
        Sensor metadata stored in ``Scan.sensor``.

    Returns
    -------
    Scan
        Points ``(N, 3)`` plus ``intensity``, per-point ``timestamps`` and ``normals`` when the
        file has them (rows aligned with the kept points).
    """
    c = _read_any(path)
    return Scan(
        points=c.points,
        time=float(time),
        timestamps=c.timestamps,
        intensity=c.intensity,
        normals=c.normals,
        sensor=dict(sensor) if sensor else {},
    )


def write_points(
    path: str | Path,
    points: np.ndarray,
    *,
    intensity: np.ndarray | None = None,
    timestamps: np.ndarray | None = None,
    binary: bool = True,
    double: bool | None = None,
) -> Path:
    """Write points (and optional per-point intensity/time) to a file chosen by its extension.

    Parameters
    ----------
    path : str or Path
        Output file; parent folders are created. Extensions: ``.ply`` (plyfile, binary
        little-endian float64 or ASCII), ``.pcd`` (float64 fields, ``DATA binary`` or
        ``ascii``), ``.xyz``/``.txt`` (space separated, no header), ``.csv`` (comma separated,
        header ``x,y,z[,intensity]``), ``.npy`` (``(N, 3)`` or ``(N, 4)`` with intensity),
        ``.bin`` (KITTI float32 ``x y z intensity``, intensity 0 when absent), ``.las``/``.laz``.
    points : (N, 3) array_like
        Coordinates in metres. Non-finite rows are dropped with a warning.
    intensity : (N,) array_like, optional
        Per-point intensity.
    timestamps : (N,) array_like, optional
        Per-point times in seconds; stored by PLY, PCD (field ``timestamp``) and LAS
        (``gps_time``), ignored (with a debug message) by the other formats.
    binary : bool
        Binary or ASCII encoding for PLY and PCD; ignored by the other formats.
    double : bool, optional
        Store float64 (``True``) or float32 (``False``) fields in PLY and PCD. Default: float64
        for PLY, float32 for PCD. **[interpretation]** PCD defaults to float32 (``SIZE 4``), the
        de-facto standard of PCL's point types: Open3D 0.20 reads binary ``SIZE 8`` fields as
        zeros. Ignored by the other formats (text and ``.npy`` are exact, ``.bin`` is float32).

    Returns
    -------
    Path
        The path written.

    Notes
    -----
    LAS headers get a fixed creation date (2000-01-01) so that files are reproducible.
    LAS stores integers: the scale is the finest of 1 µm, 10 µm, ... 1 cm that covers the extent
    around an offset at the cloud's rounded centre, so coordinates come back within half a scale
    step. **[interpretation]** Intensity is written to the standard ``uint16`` field when it is
    integer-valued in ``[0, 65535]``; otherwise it is also stored exactly in an extra ``float64``
    dimension ``intensity_f64`` that :func:`read_points` prefers.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in POINT_WRITE_EXTENSIONS:
        raise InputError(
            f"{p}: cannot write point-cloud extension {p.suffix!r}; "
            f"supported: {', '.join(POINT_WRITE_EXTENSIONS)}"
        )
    pts, inten, times = _validate_for_write(p, points, intensity, timestamps)
    p.parent.mkdir(parents=True, exist_ok=True)
    if ext == ".ply":
        _write_ply(p, pts, inten, times, binary, True if double is None else double)
    elif ext == ".pcd":
        _write_pcd(p, pts, inten, times, binary, False if double is None else double)
    elif ext in _TEXT_EXTENSIONS:
        _write_text(p, pts, inten, times)
    elif ext == ".npy":
        _write_npy(p, pts, inten, times)
    elif ext == ".bin":
        _write_bin(p, pts, inten, times)
    else:
        _write_las(p, pts, inten, times)
    return p


def write_scan(path: str | Path, scan: Scan, *, binary: bool = True) -> Path:
    """Write a :class:`Scan`'s points, intensity and per-point times (see :func:`write_points`)."""
    return write_points(
        path, scan.points, intensity=scan.intensity, timestamps=scan.timestamps, binary=binary
    )


# --------------------------------------------------------------------------------------------
# shared helpers
# --------------------------------------------------------------------------------------------


def _read_any(path: str | Path) -> _Cloud:
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in POINT_READ_EXTENSIONS:
        raise InputError(
            f"{p}: unknown point-cloud extension {p.suffix!r}; "
            f"supported: {', '.join(POINT_READ_EXTENSIONS)}"
        )
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    _check_magic(p, ext)
    if ext == ".ply":
        c = _read_ply(p)
    elif ext == ".pcd":
        c = _read_pcd(p)
    elif ext in _TEXT_EXTENSIONS:
        c = _read_text(p)
    elif ext == ".npy":
        c = _read_npy(p)
    elif ext == ".bin":
        c = _read_bin(p)
    else:
        c = _read_las(p)
    return _finalize(p, c)


def _check_magic(p: Path, ext: str) -> None:
    """InputError when the file starts with another format's signature (e.g. a PLY renamed
    ``.bin``): its bytes would otherwise be read as points."""
    with p.open("rb") as f:
        head = f.read(8)
    for magic, fmt in _MAGIC.items():
        if head.startswith(magic):
            expected = {"PLY": ".ply", "PCD": ".pcd", "NPY": ".npy", "LAS/LAZ": (".las", ".laz")}
            if ext not in expected[fmt]:
                raise InputError(f"{p}: this is a {fmt} file, not a {ext} file (rename it)")
            return
    if ext in (".ply", ".npy", ".las", ".laz"):
        want = {".ply": "PLY", ".npy": "NPY", ".las": "LAS/LAZ", ".laz": "LAS/LAZ"}[ext]
        raise InputError(f"{p}: not a {want} file (no {want} signature at the start)")


def _finalize(p: Path, c: _Cloud) -> _Cloud:
    """Cast to float64, check shapes, drop rows with non-finite coordinates."""
    pts = np.ascontiguousarray(c.points, dtype=np.float64).reshape(-1, 3)
    n = pts.shape[0]

    def _col(a: np.ndarray | None, width: int | None = None) -> np.ndarray | None:
        if a is None:
            return None
        a = np.asarray(a, dtype=np.float64)
        a = a.reshape(n, width) if width else a.reshape(n)
        return a

    inten = _col(c.intensity)
    times = _col(c.timestamps)
    normals = _col(c.normals, 3)
    ok = _check_coordinates(p, pts)
    n_bad = int(n - np.count_nonzero(ok))
    if n_bad:
        logger.warning("%s: dropped %d of %d points with NaN/inf coordinates", p, n_bad, n)
        pts = pts[ok]
        inten = inten[ok] if inten is not None else None
        times = times[ok] if times is not None else None
        normals = normals[ok] if normals is not None else None
    return _Cloud(pts, inten, times, normals)


def _check_coordinates(p: Path, pts: np.ndarray) -> np.ndarray:
    """Rows of ``pts`` that are finite; raise on absurd coordinates (a misread file), warn on
    large ones (units?)."""
    ok = np.isfinite(pts).all(axis=1)
    if len(pts):
        big = float(np.max(np.abs(np.where(ok[:, None], pts, 0.0))))
        if big > ABSURD_COORDINATE:
            raise InputError(
                f"{p}: coordinates up to {big:.3g} m (limit {ABSURD_COORDINATE:.0e} m): the data "
                "are misread (wrong extension, SIZE/TYPE or byte order?)"
            )
        if big > SANE_COORDINATE:
            logger.warning(
                "%s: coordinates up to %.3g m, beyond %.0e m: check the units",
                p,
                big,
                SANE_COORDINATE,
            )
    return ok


def _validate_for_write(
    p: Path,
    points: np.ndarray,
    intensity: np.ndarray | None,
    timestamps: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"{p}: points are not numeric ({e})") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"{p}: points must have shape (N, 3), got {pts.shape}")
    n = pts.shape[0]
    extras = []
    for name, a in (("intensity", intensity), ("timestamps", timestamps)):
        if a is None:
            extras.append(None)
            continue
        try:
            a = np.asarray(a, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise InputError(f"{p}: {name} is not numeric ({e})") from None
        if a.shape != (n,):
            raise InputError(f"{p}: {name} must have shape ({n},), got {a.shape}")
        extras.append(a)
    ok = _check_coordinates(p, pts)
    n_bad = int(n - np.count_nonzero(ok))
    if n_bad:
        logger.warning("%s: dropped %d of %d points with NaN/inf coordinates", p, n_bad, n)
        pts = pts[ok]
        extras = [a[ok] if a is not None else None for a in extras]
    return np.ascontiguousarray(pts), extras[0], extras[1]


@dataclass
class _Roles:
    """Which named fields hold the coordinates and the optional per-point attributes."""

    xyz: list[str] | None = None
    intensity: str | None = None
    time: str | None = None
    normals: list[str] | None = None

    def used(self) -> set[str]:
        """Every field name referenced."""
        out = set(self.xyz or []) | set(self.normals or [])
        return out | {n for n in (self.intensity, self.time) if n is not None}

    def build(self, get: Callable[[str], np.ndarray]) -> _Cloud:
        """Assemble a cloud from ``get(field_name) -> (N,) array`` (``xyz`` must be set)."""
        assert self.xyz is not None

        def stack(names: list[str]) -> np.ndarray:
            return np.column_stack([np.asarray(get(n), dtype=np.float64) for n in names])

        c = _Cloud(stack(self.xyz).reshape(-1, 3))
        if self.intensity is not None:
            c.intensity = np.asarray(get(self.intensity), dtype=np.float64)
        if self.time is not None:
            c.timestamps = np.asarray(get(self.time), dtype=np.float64)
        if self.normals is not None:
            c.normals = stack(self.normals).reshape(-1, 3)
        return c


def _pick_fields(names: list[str]) -> _Roles:
    """Recognise the roles of field names (case-insensitive; first occurrence wins)."""
    low = [str(n).strip().lower() for n in names]
    pos = {n: i for i, n in reversed(list(enumerate(low)))}
    roles = _Roles()
    if all(k in pos for k in ("x", "y", "z")):
        roles.xyz = [names[pos[k]] for k in ("x", "y", "z")]
    roles.intensity = next((names[pos[c]] for c in _INTENSITY_NAMES if c in pos), None)
    roles.time = next((names[pos[c]] for c in _TIME_NAMES if c in pos), None)
    trio = next((t for t in _NORMAL_NAMES if all(k in pos for k in t)), None)
    if trio is not None:
        roles.normals = [names[pos[k]] for k in trio]
    return roles


def _fmt_rows(cols: list[np.ndarray], sep: str, *, single: bool = False) -> str:
    """Rows of floats printed with the shortest decimal that round-trips, newline terminated.

    With ``single``, columns that hold float32-representable values are printed with the
    shortest decimal that round-trips *in float32* (e.g. ``0.1`` rather than
    ``0.10000000149011612``).
    """
    if not cols or cols[0].shape[0] == 0:
        return ""
    if single:
        fmt_cols = []
        for c in cols:
            c = np.asarray(c, dtype=np.float64)
            c32 = c.astype(np.float32)
            if np.array_equal(c32.astype(np.float64), c, equal_nan=True):
                fmt_cols.append([str(v) for v in c32])  # NumPy prints float32 shortest
            else:
                fmt_cols.append([repr(v) for v in c.tolist()])
        return "".join(sep.join(r) + "\n" for r in zip(*fmt_cols, strict=True))
    rows = np.column_stack(cols).tolist()
    return "".join(sep.join(map(repr, r)) + "\n" for r in rows)


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------


def _read_ply(p: Path) -> _Cloud:
    from plyfile import PlyData

    try:
        with p.open("rb") as f:
            ply = PlyData.read(f, mmap="c")  # memory-mapped: ~500x faster than mmap=False
    except Exception as e:  # plyfile raises many types on bad input
        raise InputError(f"{p}: corrupt or truncated PLY file ({type(e).__name__}: {e})") from None
    _check_ply_size(p, ply)
    elements = list(ply.elements)
    el = next((e for e in elements if e.name == "vertex"), None)
    if el is None or _pick_fields([q.name for q in el.properties]).xyz is None:
        el = next((e for e in elements if _pick_fields([q.name for q in e.properties]).xyz), None)
    if el is None:
        raise InputError(f"{p}: PLY file has no element with x, y, z properties")
    names = [q.name for q in el.properties]
    roles = _pick_fields(names)
    data = el.data
    try:  # np.array copies, so nothing keeps the memory map alive
        return roles.build(lambda n: np.array(data[n], dtype=np.float64, copy=True))
    except (TypeError, ValueError) as e:
        raise InputError(f"{p}: PLY x/y/z properties are not numeric scalars ({e})") from None


def _check_ply_size(p: Path, ply: object) -> None:
    """InputError when a binary PLY with fixed-size rows has more bytes than its header
    declares (the counts or types in the header are wrong)."""
    from plyfile import PlyListProperty

    if getattr(ply, "text", True):
        return
    elements = list(ply.elements)  # type: ignore[attr-defined]
    if any(isinstance(q, PlyListProperty) for e in elements for q in e.properties):
        return
    with p.open("rb") as f:
        head = f.read(1 << 16)
    i = head.find(b"end_header")
    j = head.find(b"\n", i) if i >= 0 else -1
    if j < 0:
        return
    body = sum(e.count * e.dtype(ply.byte_order).itemsize for e in elements)  # type: ignore[attr-defined]
    size = p.stat().st_size
    if size > j + 1 + body:
        raise InputError(
            f"{p}: binary PLY has {size - j - 1} data bytes but its header declares {body}: "
            "element counts or property types are wrong"
        )


def _write_ply(
    p: Path,
    pts: np.ndarray,
    inten: np.ndarray | None,
    times: np.ndarray | None,
    binary: bool,
    double: bool,
) -> None:
    from plyfile import PlyData, PlyElement

    f = "<f8" if double else "<f4"
    fields = [("x", f), ("y", f), ("z", f)]
    if inten is not None:
        fields.append(("intensity", f))
    if times is not None:
        fields.append(("timestamp", "<f8"))  # times need float64 whatever the coordinates
    arr = np.empty(pts.shape[0], dtype=fields)
    arr["x"], arr["y"], arr["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    if inten is not None:
        arr["intensity"] = inten
    if times is not None:
        arr["timestamp"] = times
    el = PlyElement.describe(arr, "vertex")
    PlyData([el], text=not binary, byte_order="<").write(str(p))


# --------------------------------------------------------------------------------------------
# PCD
# --------------------------------------------------------------------------------------------

_PCD_TYPES = {
    ("F", 2): "<f2",
    ("F", 4): "<f4",
    ("F", 8): "<f8",
    ("I", 1): "<i1",
    ("I", 2): "<i2",
    ("I", 4): "<i4",
    ("I", 8): "<i8",
    ("U", 1): "<u1",
    ("U", 2): "<u2",
    ("U", 4): "<u4",
    ("U", 8): "<u8",
}


@njit(cache=True)
def _lzf_decompress_nb(src: np.ndarray, out: np.ndarray) -> int:  # pragma: no cover - numba
    """LZF decode ``src`` into ``out``; bytes written, or ``-1`` on a malformed stream."""
    ip = 0
    op = 0
    n_in = src.size
    n_out = out.size
    while ip < n_in:
        ctrl = np.int64(src[ip])
        ip += 1
        if ctrl < 32:  # literal run of ctrl + 1 bytes
            length = ctrl + 1
            if ip + length > n_in or op + length > n_out:
                return -1
            for k in range(length):
                out[op + k] = src[ip + k]
            ip += length
            op += length
        else:  # back reference
            length = ctrl >> 5
            if length == 7:
                if ip >= n_in:
                    return -1
                length += np.int64(src[ip])
                ip += 1
            if ip >= n_in:
                return -1
            ref = op - ((ctrl & 0x1F) << 8) - 1 - np.int64(src[ip])
            ip += 1
            length += 2
            if ref < 0 or op + length > n_out:
                return -1
            for k in range(length):  # byte by byte: the regions may overlap
                out[op + k] = out[ref + k]
            op += length
    return op


def lzf_decompress(data: bytes | np.ndarray, out_size: int) -> bytes:
    """Decompress an LZF stream (liblzf format, as in PCL's ``binary_compressed`` PCD).

    Parameters
    ----------
    data : bytes
        Compressed stream.
    out_size : int
        Expected decompressed size in bytes.

    Returns
    -------
    bytes
        Exactly ``out_size`` bytes.

    Raises
    ------
    ValueError
        Malformed stream or a decompressed size different from ``out_size``.
    """
    src = np.frombuffer(bytes(data), dtype=np.uint8)
    out = np.empty(int(out_size), dtype=np.uint8)
    if src.size == 0:
        if out_size == 0:
            return b""
        raise ValueError("empty LZF stream")
    n = _lzf_decompress_nb(src, out)
    if n < 0:
        raise ValueError("malformed LZF stream")
    if n != out_size:
        raise ValueError(f"LZF stream decompressed to {n} bytes, expected {out_size}")
    return out.tobytes()


def _parse_pcd_header(p: Path, raw: bytes) -> tuple[dict[str, list[str]], int]:
    """Header keys → tokens, and the byte offset where the data starts."""
    header: dict[str, list[str]] = {}
    pos = 0
    limit = min(len(raw), 1 << 20)
    while True:
        nl = raw.find(b"\n", pos, limit)
        if nl < 0 and raw[pos:limit].strip().upper().startswith(b"DATA"):
            nl = limit  # a last header line without its newline (empty cloud)
        if nl < 0:
            if "FIELDS" in header or "VERSION" in header:
                raise InputError(f"{p}: truncated PCD header (no DATA line)")
            raise InputError(f"{p}: not a PCD file (no header found)")
        try:
            line = raw[pos:nl].decode("ascii").strip()
        except UnicodeDecodeError:
            raise InputError(f"{p}: not a PCD file (binary bytes in the header)") from None
        pos = nl + 1
        if not line or line.startswith("#"):
            continue
        toks = line.split()
        key = toks[0].upper()
        if key not in (
            "VERSION",
            "FIELDS",
            "COLUMNS",
            "SIZE",
            "TYPE",
            "COUNT",
            "WIDTH",
            "HEIGHT",
            "VIEWPOINT",
            "POINTS",
            "DATA",
        ):
            raise InputError(f"{p}: not a PCD file (unexpected header line {line[:40]!r})")
        header["FIELDS" if key == "COLUMNS" else key] = toks[1:]
        if key == "DATA":
            return header, pos


def _read_pcd(p: Path) -> _Cloud:
    raw = p.read_bytes()
    header, start = _parse_pcd_header(p, raw)
    fields = header.get("FIELDS")
    if not fields:
        raise InputError(f"{p}: PCD header has no FIELDS line")
    nf = len(fields)
    try:
        sizes = [int(s) for s in header.get("SIZE", [])]
        types = [t.upper() for t in header.get("TYPE", [])]
        counts = [int(c) for c in header.get("COUNT", ["1"] * nf)]
        width = int(header["WIDTH"][0]) if "WIDTH" in header else None
        height = int(header["HEIGHT"][0]) if "HEIGHT" in header else 1
        npts = int(header["POINTS"][0]) if "POINTS" in header else None
    except (ValueError, IndexError):
        raise InputError(f"{p}: malformed PCD header (SIZE/COUNT/WIDTH/HEIGHT/POINTS)") from None
    if len(sizes) != nf or len(types) != nf or len(counts) != nf:
        raise InputError(
            f"{p}: PCD header FIELDS/SIZE/TYPE/COUNT lengths differ "
            f"({nf}/{len(sizes)}/{len(types)}/{len(counts)})"
        )
    if npts is None:
        if width is None:
            raise InputError(f"{p}: PCD header has neither POINTS nor WIDTH")
        npts = width * height
    if width is not None and width * height != npts:
        raise InputError(f"{p}: PCD WIDTH*HEIGHT = {width * height} but POINTS = {npts}")
    if npts < 0 or any(c < 1 for c in counts):
        raise InputError(f"{p}: PCD header has a negative POINTS or a COUNT below 1")
    bases = []
    for f, s, t in zip(fields, sizes, types, strict=True):
        if (t, s) not in _PCD_TYPES:
            raise InputError(f"{p}: PCD field {f!r} has unsupported TYPE {t} SIZE {s}")
        bases.append(_PCD_TYPES[(t, s)])
    roles = _pick_fields(fields)
    if roles.xyz is None:
        raise InputError(f"{p}: PCD file has no x, y, z fields (FIELDS {' '.join(fields)})")
    mode = (header.get("DATA") or [""])[0].lower()
    body = raw[start:]
    wanted = roles.used()

    cols: dict[str, np.ndarray] = {}
    if mode == "ascii":
        ncols = sum(counts)
        text = body.decode("ascii", errors="replace")
        starts = np.cumsum([0, *counts[:-1]])
        use = {f: int(starts[i]) for i, f in enumerate(fields) if f in wanted}
        if npts == 0:
            cols = {f: np.empty(0) for f in use}
        else:
            try:
                with warnings.catch_warnings(action="error", category=UserWarning):
                    table = np.loadtxt(_io.StringIO(text), dtype=np.float64, ndmin=2)
            except (ValueError, UserWarning) as e:
                raise InputError(f"{p}: corrupt PCD ascii data ({e})") from None
            if table.shape[0] < npts:
                raise InputError(
                    f"{p}: truncated PCD ascii data: {table.shape[0]} rows, POINTS = {npts}"
                )
            if table.shape[1] != ncols:
                raise InputError(
                    f"{p}: PCD ascii rows have {table.shape[1]} values, header says {ncols}"
                )
            if table.shape[0] > npts:
                logger.warning(
                    "%s: PCD ascii data has %d rows but POINTS = %d: reading the first %d",
                    p,
                    table.shape[0],
                    npts,
                    npts,
                )
            cols = {f: table[:npts, i] for f, i in use.items()}
    elif mode in ("binary", "binary_compressed"):
        names = [f if f not in fields[:i] else f"__dup{i}" for i, f in enumerate(fields)]
        dt = np.dtype(
            [
                (n, b) if c == 1 else (n, b, (c,))
                for n, b, c in zip(names, bases, counts, strict=True)
            ]
        )
        need = npts * dt.itemsize
        if mode == "binary":
            if len(body) < need:
                raise InputError(
                    f"{p}: truncated PCD binary data: {len(body)} bytes, expected {need}"
                )
            if len(body) > need:
                raise InputError(
                    f"{p}: PCD binary data has {len(body)} bytes but the header (POINTS "
                    f"{npts}, SIZE/COUNT: {dt.itemsize} bytes per point) needs {need}: "
                    "POINTS or SIZE/TYPE is wrong"
                )
            rec = np.frombuffer(body, dtype=dt, count=npts)
            for f in wanted:
                a = rec[f]
                cols[f] = a[:, 0] if a.ndim == 2 else a
        elif npts == 0:
            cols = {f: np.empty(0) for f in wanted}
        else:
            if len(body) < 8:
                raise InputError(f"{p}: truncated PCD binary_compressed data (no size words)")
            csize, usize = (int(v) for v in np.frombuffer(body[:8], dtype="<u4"))
            if usize != need:
                raise InputError(
                    f"{p}: PCD binary_compressed uncompressed size {usize} != expected {need}"
                )
            if len(body) < 8 + csize:
                raise InputError(
                    f"{p}: truncated PCD binary_compressed data: "
                    f"{len(body) - 8} of {csize} compressed bytes"
                )
            try:
                dec = lzf_decompress(body[8 : 8 + csize], usize)
            except ValueError as e:
                raise InputError(f"{p}: corrupt PCD binary_compressed data ({e})") from None
            off = 0  # field-major (structure of arrays) layout
            for f, b, c in zip(fields, bases, counts, strict=True):
                nbytes = npts * np.dtype(b).itemsize * c
                if f in wanted and f not in cols:
                    a = np.frombuffer(dec, dtype=b, count=npts * c, offset=off).reshape(npts, c)
                    cols[f] = a[:, 0]
                off += nbytes
    else:
        raise InputError(f"{p}: unsupported PCD DATA type {mode!r}")

    return roles.build(cols.__getitem__)


def _write_pcd(
    p: Path,
    pts: np.ndarray,
    inten: np.ndarray | None,
    times: np.ndarray | None,
    binary: bool,
    double: bool,
) -> None:
    f = "<f8" if double else "<f4"
    names = ["x", "y", "z"]
    cols = [pts[:, 0], pts[:, 1], pts[:, 2]]
    dts = [f, f, f]
    if inten is not None:
        names.append("intensity")
        cols.append(inten)
        dts.append(f)
    if times is not None:
        names.append("timestamp")
        cols.append(times)
        dts.append("<f8")  # times need float64 whatever the coordinates
    n = pts.shape[0]
    k = len(names)
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\n"
        f"FIELDS {' '.join(names)}\n"
        f"SIZE {' '.join(d[-1] for d in dts)}\n"
        f"TYPE {' '.join(['F'] * k)}\n"
        f"COUNT {' '.join(['1'] * k)}\n"
        f"WIDTH {n}\n"
        "HEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\n"
        f"POINTS {n}\n"
        f"DATA {'binary' if binary else 'ascii'}\n"
    )
    if binary:
        rec = np.empty(n, dtype=[(nm, d) for nm, d in zip(names, dts, strict=True)])
        for nm, c in zip(names, cols, strict=True):
            rec[nm] = c
        p.write_bytes(header.encode("ascii") + rec.tobytes())
    else:
        # ASCII: values rounded to the field precision first, so binary and ASCII agree
        cols = [np.asarray(c, dtype=d).astype(np.float64) for c, d in zip(cols, dts, strict=True)]
        p.write_text(header + _fmt_rows(cols, " ", single=not double), encoding="ascii")


# --------------------------------------------------------------------------------------------
# text (XYZ / TXT / CSV)
# --------------------------------------------------------------------------------------------

_SPLIT = re.compile(r"[\s,;]+")


def _is_float(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _read_text(p: Path) -> _Cloud:
    raw = p.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{p}: not a text point file (undecodable bytes)") from None
    if "\x00" in text:
        raise InputError(f"{p}: not a text point file (contains NUL bytes)")
    lines = text.splitlines()
    header: list[str] | None = None
    first = None
    n_header = 0
    for i, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        is_comment = s.startswith(("#", "//"))
        body = s.lstrip("#/").strip() if is_comment else s
        toks = [t.strip("\"'") for t in _SPLIT.split(body) if t]
        if not is_comment and len(toks) >= 3 and all(_is_float(t) for t in toks[:3]):
            first = i
            break
        if toks:
            header = toks
        n_header += 0 if is_comment else 1
        if n_header > _MAX_HEADER_LINES:
            raise InputError(f"{p}: no numeric x y z rows after {_MAX_HEADER_LINES} header lines")
    if first is None:
        if n_header and not (header and _pick_fields(header).xyz):  # prose, not a header
            raise InputError(f"{p}: no numeric x y z rows found")
        return _Cloud(np.empty((0, 3)))  # empty file or header only: an empty cloud
    data_line = lines[first]
    delim = ";" if ";" in data_line else ("," if "," in data_line else None)
    ntok = len([t for t in _SPLIT.split(data_line.strip()) if t])
    roles = _pick_fields(header) if header and len(header) == ntok else _Roles()
    if roles.xyz is not None and header is not None:
        idx = {n: j for j, n in reversed(list(enumerate(header)))}
    else:  # positional: x y z [intensity when exactly four columns]
        header = [f"c{j}" for j in range(ntok)]
        idx = {n: j for j, n in enumerate(header)}
        roles = _Roles(xyz=header[:3], intensity=header[3] if ntok == 4 else None)
    usecols = sorted({idx[n] for n in roles.used()})
    try:
        with warnings.catch_warnings(action="error", category=UserWarning):
            table = np.loadtxt(
                _io.StringIO("\n".join(lines[first:])),
                dtype=np.float64,
                delimiter=delim,
                comments=["#", "//"],
                usecols=usecols,
                ndmin=2,
            )
    except (ValueError, UserWarning) as e:
        raise InputError(
            f"{p}: corrupt text point data ({e}; data rows start at line {first + 1})"
        ) from None
    col = {c: j for j, c in enumerate(usecols)}
    return roles.build(lambda n: table[:, col[idx[n]]])


def _write_text(
    p: Path, pts: np.ndarray, inten: np.ndarray | None, times: np.ndarray | None
) -> None:
    cols = [pts[:, 0], pts[:, 1], pts[:, 2]]
    if inten is not None:
        cols.append(inten)
    if times is not None:
        logger.debug("%s: per-point timestamps are not stored in text files", p)
    if p.suffix.lower() == ".csv":
        head = "x,y,z,intensity\n" if inten is not None else "x,y,z\n"
        p.write_text(head + _fmt_rows(cols, ","), encoding="ascii")
    else:
        p.write_text(_fmt_rows(cols, " "), encoding="ascii")


# --------------------------------------------------------------------------------------------
# NPY and KITTI .bin
# --------------------------------------------------------------------------------------------


def _read_npy(p: Path) -> _Cloud:
    try:
        arr = np.load(p, allow_pickle=False)
    except Exception as e:  # ValueError, EOFError, OSError on corrupt/truncated/object arrays
        raise InputError(
            f"{p}: corrupt or unreadable .npy file ({type(e).__name__}: {e})"
        ) from None
    if not isinstance(arr, np.ndarray):
        raise InputError(f"{p}: expected a single array, got {type(arr).__name__}")
    if arr.dtype.names:
        roles = _pick_fields(list(arr.dtype.names))
        if roles.xyz is None:
            raise InputError(f"{p}: structured array without x, y, z fields {arr.dtype.names}")
        flat = arr.reshape(-1)
        try:
            return roles.build(lambda n: flat[n])
        except (TypeError, ValueError) as e:
            raise InputError(f"{p}: x/y/z fields are not numeric ({e})") from None
    if arr.ndim != 2 or arr.shape[1] < 3:
        raise InputError(f"{p}: expected an (N, 3) or (N, >=3) array, got shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise InputError(f"{p}: expected a numeric array, got dtype {arr.dtype}")
    c = _Cloud(arr[:, :3])
    if arr.shape[1] == 4:
        c.intensity = arr[:, 3]
    return c


def _write_npy(
    p: Path, pts: np.ndarray, inten: np.ndarray | None, times: np.ndarray | None
) -> None:
    if times is not None:
        logger.debug("%s: per-point timestamps are not stored in .npy files", p)
    arr = pts if inten is None else np.column_stack([pts, inten])
    np.save(p, np.ascontiguousarray(arr, dtype=np.float64), allow_pickle=False)


def _read_bin(p: Path) -> _Cloud:
    size = p.stat().st_size
    if size % 16:
        raise InputError(
            f"{p}: size {size} bytes is not a multiple of 16 "
            "(KITTI .bin is float32 x, y, z, reflectance per point)"
        )
    arr = np.fromfile(p, dtype="<f4").reshape(-1, 4)
    return _Cloud(arr[:, :3], intensity=arr[:, 3])


def _write_bin(
    p: Path, pts: np.ndarray, inten: np.ndarray | None, times: np.ndarray | None
) -> None:
    if times is not None:
        logger.debug("%s: per-point timestamps are not stored in KITTI .bin files", p)
    arr = np.zeros((pts.shape[0], 4), dtype="<f4")
    arr[:, :3] = pts
    if inten is not None:
        arr[:, 3] = inten
    p.write_bytes(arr.tobytes())


# --------------------------------------------------------------------------------------------
# LAS / LAZ
# --------------------------------------------------------------------------------------------


def _read_las(p: Path) -> _Cloud:
    import laspy

    try:
        las = laspy.read(p)
        pts = np.column_stack(
            [np.asarray(las.x, np.float64), np.asarray(las.y, np.float64), np.asarray(las.z)]
        )
        dims = set(las.point_format.dimension_names)
        if _LAS_FLOAT_INTENSITY in dims:
            inten = np.asarray(las[_LAS_FLOAT_INTENSITY], dtype=np.float64)
        else:
            inten = np.asarray(las.intensity, dtype=np.float64)
        times = np.asarray(las.gps_time, dtype=np.float64) if "gps_time" in dims else None
    except Exception as e:  # laspy raises LaspyException, ValueError, OSError...
        raise InputError(
            f"{p}: corrupt or truncated LAS/LAZ file ({type(e).__name__}: {e})"
        ) from None
    return _Cloud(pts.reshape(-1, 3), intensity=inten, timestamps=times)


def _las_scale_offset(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis offset (rounded centre) and the finest scale in 1e-6..1e-2 m that fits int32."""
    if pts.shape[0] == 0:
        return np.zeros(3), np.full(3, 1e-6)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    offset = np.round((lo + hi) / 2.0)
    half = np.maximum(np.abs(hi - offset), np.abs(lo - offset))
    scale = np.empty(3)
    for a in range(3):
        for s in (1e-6, 1e-5, 1e-4, 1e-3, 1e-2):
            if half[a] / s < 2**31 - 2:
                scale[a] = s
                break
        else:
            raise InputError(f"coordinates span too far ({half[a]:.3g} m) for a LAS file")
    return offset, scale


def _write_las(
    p: Path, pts: np.ndarray, inten: np.ndarray | None, times: np.ndarray | None
) -> None:
    import laspy

    header = laspy.LasHeader(point_format=1 if times is not None else 0, version="1.2")
    header.creation_date = _LAS_FIXED_DATE  # deterministic bytes (laspy defaults to today)
    try:
        header.offsets, header.scales = _las_scale_offset(pts)
    except InputError as e:
        raise InputError(f"{p}: {e}") from None
    float_intensity = inten is not None and not (
        np.all(inten == np.round(inten))
        and inten.min(initial=0) >= 0
        and inten.max(initial=0) <= 65535
    )
    if float_intensity:
        header.add_extra_dim(laspy.ExtraBytesParams(name=_LAS_FLOAT_INTENSITY, type=np.float64))
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    if inten is not None:
        if float_intensity:
            las[_LAS_FLOAT_INTENSITY] = inten
            lo, hi = float(inten.min(initial=0.0)), float(inten.max(initial=0.0))
            span = hi - lo if hi > lo else 1.0
            las.intensity = np.round((inten - lo) / span * 65535).astype(np.uint16)
        else:
            las.intensity = inten.astype(np.uint16)
    if times is not None:
        las.gps_time = times
    try:
        las.write(str(p))
    except Exception as e:
        raise InputError(f"{p}: could not write LAS/LAZ ({type(e).__name__}: {e})") from None
