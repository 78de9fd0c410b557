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


def _check_las_header(p: Path) -> int:
    """Check the LAS/LAZ public header block against the file size before laspy (and its LAZ
    decompressor) see it: header size, point data offset, VLR/EVLR counts and the point
    count times the record length. InputError naming the first inconsistency; returns the
    bytes of point records the file claims."""
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
        _check_laszip_vlr(p, header_size, n_vlrs, rec_len, budget)
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
    return need


_LASZIP_USER = b"laszip encoded"
_LASZIP_RECORD = 22204
_LASZIP_VARIABLE_CHUNKS = 0xFFFFFFFF


def _check_laszip_vlr(p: Path, header_size: int, n_vlrs: int, rec_len: int, budget: int) -> None:
    """The LAZ decompressor's own description (the ``laszip encoded`` VLR): its items must
    add up to the point record length and a chunk of points must fit the memory budget (the
    decompressor allocates whole chunks; a corrupt chunk size aborts the process)."""
    import struct

    with p.open("rb") as f:
        f.seek(header_size)
        vlrs = f.read(min(n_vlrs * (_VLR_HEADER + 65535), 1 << 22))
    pos = 0
    for _ in range(n_vlrs):
        if pos + _VLR_HEADER > len(vlrs):
            raise InputError(f"{p}: truncated LAS VLRs")
        user = vlrs[pos + 2 : pos + 18].rstrip(b"\0")
        record, length = struct.unpack_from("<HH", vlrs, pos + 18)
        data = vlrs[pos + _VLR_HEADER : pos + _VLR_HEADER + length]
        pos += _VLR_HEADER + length
        if user != _LASZIP_USER or record != _LASZIP_RECORD:
            continue
        if len(data) < 34:
            raise InputError(f"{p}: truncated laszip VLR ({len(data)} bytes)")
        chunk = struct.unpack_from("<I", data, 12)[0]
        n_items = struct.unpack_from("<H", data, 32)[0]
        if len(data) < 34 + 6 * n_items:
            raise InputError(f"{p}: laszip VLR lists {n_items} items it does not hold")
        sizes = [struct.unpack_from("<H", data, 34 + 6 * k + 2)[0] for k in range(n_items)]
        if sum(sizes) != rec_len:
            raise InputError(
                f"{p}: laszip items add up to {sum(sizes)} bytes, the point record has {rec_len}"
            )
        if chunk != _LASZIP_VARIABLE_CHUNKS and chunk * rec_len > budget:
            raise InputError(f"{p}: laszip chunk size {chunk} points is corrupt")
        return
    raise InputError(f"{p}: compressed LAS (LAZ) without its laszip VLR")


LAZ_DECODE_TIMEOUT_S = 600.0
"""A LAZ file whose decompression takes longer than this is abandoned (a hang guard)."""


def _read_las(p: Path) -> _Cloud:
    need = _check_las_header(p)
    with p.open("rb") as f:
        f.seek(104)
        compressed = bool(f.read(1)[0] & 0xC0)
    if compressed:
        return _read_laz_isolated(p, need)
    return _read_las_here(p)


def _read_las_here(p: Path) -> _Cloud:
    import laspy

    try:
        # the sequential decompressor: the parallel one trusts the chunk table, and a corrupt
        # table makes it allocate without bound
        backend = getattr(laspy.LazBackend, "Lazrs", None)
        las = laspy.read(p, laz_backend=backend) if backend is not None else laspy.read(p)
        pts = np.column_stack(
            [np.asarray(las.x, np.float64), np.asarray(las.y, np.float64), np.asarray(las.z)]
        )
        dims = set(las.point_format.dimension_names)
        if _LAS_FLOAT_INTENSITY in dims:
            inten = np.asarray(las[_LAS_FLOAT_INTENSITY], dtype=np.float64)
        else:
            inten = np.asarray(las.intensity, dtype=np.float64)
        times = np.asarray(las.gps_time, dtype=np.float64) if "gps_time" in dims else None
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as e:  # laspy: LaspyException, ValueError...; lazrs: PanicException
        raise InputError(
            f"{p}: corrupt or truncated LAS/LAZ file ({type(e).__name__}: {e})"
        ) from None
    return _Cloud(pts.reshape(-1, 3), intensity=inten, timestamps=times)


def _read_laz_isolated(p: Path, need: int) -> _Cloud:
    """Decompress a LAZ file in a child process (``forkserver``) with a bounded address space.

    The LAZ decompressor (lazrs, Rust) aborts the whole process when a corrupt chunk table
    makes it allocate tens of GB, a failure no check of the header can rule out; in a child,
    it ends as one :class:`InputError` (with the decompressor's own message) and the run goes
    on. **[interpretation]** The cost is a fork per file (~10-50 ms).
    """
    import multiprocessing as mp
    import tempfile

    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(["relnav.io.pointclouds.las", "laspy", "lazrs"])  # imported once
    recv, send = ctx.Pipe(duplex=False)
    limit = 4 * max(LAZ_MIN_BUDGET, need) + (1 << 30)
    with tempfile.NamedTemporaryFile(prefix="relnav-laz-", suffix=".err") as err:
        proc = ctx.Process(target=_laz_child, args=(str(p), send, err.name, limit), daemon=True)
        proc.start()
        send.close()
        try:
            if not recv.poll(LAZ_DECODE_TIMEOUT_S):
                raise InputError(
                    f"{p}: LAZ decompression gave no answer in {LAZ_DECODE_TIMEOUT_S:.0f} s"
                )
            msg = recv.recv()
        except (EOFError, OSError):  # the child died (abort, memory limit)
            proc.join(5.0)
            first = _first_line(Path(err.name))
            raise InputError(
                f"{p}: corrupt LAZ file: the decompressor failed"
                f"{f' ({first})' if first else ''} (exit {proc.exitcode})"
            ) from None
        finally:
            recv.close()
            if proc.is_alive():
                proc.kill()
            proc.join(5.0)
    if msg[0] == "error":
        raise InputError(msg[1])
    _, pts, inten, times = msg
    return _Cloud(pts, intensity=inten, timestamps=times)


def _first_line(path: Path) -> str:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""
    lines = [x.strip() for x in text.splitlines() if x.strip()]
    return lines[0][:200] if lines else ""


def _laz_child(path: str, send: object, err_path: str, limit: int) -> None:  # pragma: no cover
    """Child of :func:`_read_laz_isolated`: stderr to ``err_path``, address space capped."""
    import os
    import resource

    fd = os.open(err_path, os.O_WRONLY | os.O_APPEND)
    os.dup2(fd, 2)
    os.environ["RUST_BACKTRACE"] = "0"
    try:
        with open("/proc/self/statm") as f:
            vsz = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        resource.setrlimit(resource.RLIMIT_AS, (vsz + limit, vsz + limit))
    except (OSError, ValueError):
        pass
    try:
        c = _read_las_here(Path(path))
        msg: tuple = ("ok", c.points, c.intensity, c.timestamps)
    except InputError as e:
        msg = ("error", str(e))
    except MemoryError:
        msg = ("error", f"{path}: corrupt LAZ file: the decompressor ran out of memory")
    send.send(msg)  # type: ignore[attr-defined]
    send.close()  # type: ignore[attr-defined]


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
