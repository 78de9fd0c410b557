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
