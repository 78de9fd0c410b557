"""PLY point clouds (plyfile): binary little-endian or ASCII, float64 or float32 fields, optional
intensity, per-point time and normals. Used through :func:`relnav.io.pointclouds.read_points` /
:func:`~relnav.io.pointclouds.write_points`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relnav.errors import InputError
from relnav.io.pointclouds._common import _Cloud, _pick_fields


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
