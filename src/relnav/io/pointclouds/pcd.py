"""PCL PCD point clouds: header parsing, ``ascii``/``binary``/``binary_compressed`` (LZF, numba
decoder) bodies, float32 or float64 fields. Used through :func:`relnav.io.pointclouds.read_points`
/ :func:`~relnav.io.pointclouds.write_points`.
"""

from __future__ import annotations

import io as _io
import warnings
from pathlib import Path

import numpy as np
from numba import njit

from relnav.errors import InputError
from relnav.io.pointclouds._common import _Cloud, _fmt_rows, _pick_fields, logger

__all__ = [
    "lzf_decompress",
]


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


PCD_MAX_COUNT = 1 << 16
"""Largest PCD field COUNT accepted (PCL's largest descriptor, SHOT colour, has 1 344)."""
LZF_RATIO_LIMIT = 88
"""LZF cannot expand beyond this: a 3-byte back reference yields at most 264 bytes."""
LZF_MAX_EXPANSION = 32
"""**[interpretation]** A ``binary_compressed`` PCD may claim at most this many times its file
size decompressed (or :data:`LZF_MIN_BUDGET` bytes); real point data compress 1.2-4x with LZF,
a larger claim is a decompression bomb."""
LZF_MIN_BUDGET = 64 << 20
"""Decompressed bytes a ``binary_compressed`` PCD may always claim, whatever its size."""


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
    if any(c > PCD_MAX_COUNT for c in counts) or any(s > 8 for s in sizes):
        raise InputError(
            f"{p}: PCD header COUNT {max(counts)} or SIZE {max(sizes)} beyond any real field "
            f"(COUNT up to {PCD_MAX_COUNT}, SIZE up to 8)"
        )
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
            budget = max(LZF_MIN_BUDGET, LZF_MAX_EXPANSION * len(raw))
            if usize > min(budget, LZF_RATIO_LIMIT * csize + 8):
                raise InputError(
                    f"{p}: PCD binary_compressed claims {usize} bytes from {csize} compressed "
                    f"bytes (a {len(raw)}-byte file): more than this reader accepts "
                    f"({LZF_MAX_EXPANSION}x the file, or LZF's own limit {LZF_RATIO_LIMIT}x)"
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
