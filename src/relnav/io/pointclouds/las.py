"""LAS/LAZ point clouds (laspy): scaled integer coordinates, ``gps_time``, intensity (``uint16``
or an exact ``float64`` extra dimension), reproducible headers.
"""

from __future__ import annotations

import datetime as _dt
from pathlib import Path

import numpy as np

from relnav.errors import InputError
from relnav.io.pointclouds._common import _Cloud

_LAS_FLOAT_INTENSITY = "intensity_f64"
_LAS_FIXED_DATE = _dt.date(2000, 1, 1)


LAZ_MAX_EXPANSION = 1000
"""A LAZ file may claim at most this many times its size in point records (or
:data:`LAZ_MIN_BUDGET` bytes, whichever is larger). **[interpretation]** Real scans compress
3-10x; a file claiming more is refused before the decompressor allocates the records."""
LAZ_MIN_BUDGET = 64 << 20
"""Bytes of point records a LAZ file may always claim, whatever its size (a constant cloud
compresses over 1000x)."""
_VLR_HEADER = 54
_EVLR_HEADER = 60


def _check_las_header(p: Path) -> None:
    """Check the LAS/LAZ public header block against the file size before laspy (and its LAZ
    decompressor) see it: header size, point data offset, VLR/EVLR counts and the point
    count times the record length. InputError naming the first inconsistency."""
    import struct

    size = p.stat().st_size
    with p.open("rb") as f:
        head = f.read(375)
    if len(head) < 227:
        raise InputError(f"{p}: truncated LAS/LAZ header ({len(head)} bytes, at least 227)")
    minor = head[25]
    header_size, offset, n_vlrs = struct.unpack_from("<HII", head, 94)
    fmt_byte, rec_len, n_legacy = struct.unpack_from("<BHI", head, 104)
    if not 227 <= header_size <= min(size, 65535):
        raise InputError(f"{p}: LAS header size {header_size} is impossible for this file")
    if not header_size <= offset <= size:
        raise InputError(
            f"{p}: LAS point data offset {offset} is outside the file ({size} bytes, header "
            f"{header_size})"
        )
    if n_vlrs * _VLR_HEADER > offset - header_size:
        raise InputError(
            f"{p}: LAS header claims {n_vlrs} VLRs, but only {offset - header_size} bytes "
            "separate the header from the points"
        )
    n_points = n_legacy
    if minor >= 4 and len(head) >= 255:
        start_evlr, n_evlrs, n_points64 = struct.unpack_from("<QIQ", head, 235)
        n_points = max(n_points, n_points64)
        if n_evlrs and (start_evlr > size or n_evlrs * _EVLR_HEADER > size - start_evlr):
            raise InputError(f"{p}: LAS header claims {n_evlrs} EVLRs the file cannot hold")
    if rec_len == 0 and n_points:
        raise InputError(f"{p}: LAS point record length is 0")
    need = n_points * rec_len
    compressed = bool(fmt_byte & 0xC0)
    if compressed:
        budget = max(LAZ_MIN_BUDGET, LAZ_MAX_EXPANSION * size)
        if need > budget:
            raise InputError(
                f"{p}: LAZ header claims {n_points} points ({need} bytes) from a {size}-byte "
                f"file (more than {LAZ_MAX_EXPANSION}x): corrupt header"
            )
    elif need > size - offset:
        raise InputError(
            f"{p}: truncated LAS file: header claims {n_points} points of {rec_len} bytes "
            f"({need} bytes), the file holds {size - offset} after the header"
        )


def _read_las(p: Path) -> _Cloud:
    import laspy

    _check_las_header(p)
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
