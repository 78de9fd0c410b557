"""Array point clouds: NumPy ``.npy`` (plain ``(N, 3|4)`` or structured with named fields) and KITTI
``.bin`` (float32 ``x y z reflectance``).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from relnav.errors import InputError
from relnav.io.pointclouds._common import _Cloud, _pick_fields, logger


def _read_npy(p: Path) -> _Cloud:
    try:
        with warnings.catch_warnings():  # a corrupt header is parsed as a Python literal
            warnings.simplefilter("ignore", SyntaxWarning)
            warnings.simplefilter("ignore", DeprecationWarning)
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
