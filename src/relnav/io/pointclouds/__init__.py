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

Layout: this package's ``__init__`` is the dispatcher (extension → format module) and public API;
one module per format family (:mod:`.ply`, :mod:`.pcd`, :mod:`.text`, :mod:`.arrays` for NPY and
KITTI ``.bin``, :mod:`.las`), with shared field recognition in :mod:`._common`.

Writers are deterministic: the same input gives byte-identical files (no dates, no random ids).
Text formats print the shortest decimal that round-trips (Python ``repr``), so float64 values are
recovered exactly.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from relnav.errors import InputError
from relnav.io.pointclouds._common import (
    ABSURD_COORDINATE,
    SANE_COORDINATE,
    _check_coordinates,
    _Cloud,
)
from relnav.io.pointclouds.arrays import _read_bin, _read_npy, _write_bin, _write_npy
from relnav.io.pointclouds.las import _read_las, _write_las
from relnav.io.pointclouds.pcd import _lzf_decompress_nb as _lzf_decompress_nb  # numba, old path
from relnav.io.pointclouds.pcd import _read_pcd, _write_pcd, lzf_decompress
from relnav.io.pointclouds.ply import _read_ply, _write_ply
from relnav.io.pointclouds.text import _TEXT_EXTENSIONS, _read_text, _write_text
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


_MAGIC = {
    b"ply\n": "PLY",
    b"ply\r": "PLY",
    b"# .PCD": "PCD",
    b"VERSION": "PCD",
    b"\x93NUMPY": "NPY",
    b"LASF": "LAS/LAZ",
}


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
    # misread bytes may hold signalling NaNs: their casts to float64 are NaNs like any other
    # (dropped with a logged warning by _finalize), not a RuntimeWarning on the terminal
    with np.errstate(invalid="ignore"):
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


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------


# --------------------------------------------------------------------------------------------
# PCD
# --------------------------------------------------------------------------------------------


# --------------------------------------------------------------------------------------------
# text (XYZ / TXT / CSV)
# --------------------------------------------------------------------------------------------


# --------------------------------------------------------------------------------------------
# NPY and KITTI .bin
# --------------------------------------------------------------------------------------------


# --------------------------------------------------------------------------------------------
# LAS / LAZ
# --------------------------------------------------------------------------------------------
