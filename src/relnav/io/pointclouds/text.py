"""Text point clouds (``.xyz``, ``.txt``, ``.csv``): optional header row naming the columns,
whitespace/comma/semicolon separators, exact float round trip.
"""

from __future__ import annotations

import io as _io
import re
import warnings
from pathlib import Path

import numpy as np

from relnav.errors import InputError
from relnav.io.pointclouds._common import _Cloud, _fmt_rows, _pick_fields, _Roles, logger

_TEXT_EXTENSIONS = (".xyz", ".txt", ".csv")
_MAX_HEADER_LINES = 50


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
