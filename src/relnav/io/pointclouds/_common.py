"""Shared by the point-cloud format modules: the reader's record (:class:`_Cloud`), recognition of
named per-point fields (intensity, time, normals), the coordinate sanity limits and the exact
text formatting of floats.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from relnav.errors import InputError

logger = logging.getLogger("relnav.io")

__all__ = [
    "ABSURD_COORDINATE",
    "SANE_COORDINATE",
]


ABSURD_COORDINATE = 1.0e9
"""|coordinate| (m) above which a file is rejected as misread (25x the geostationary radius;
float32 garbage is typically ~1e20-1e38)."""

SANE_COORDINATE = 1.0e5
"""|coordinate| (m) above which a scan is accepted with a warning (no LIDAR ranges 100 km)."""


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


@dataclass
class _Cloud:
    """Internal result of a format reader (before NaN filtering)."""

    points: np.ndarray
    intensity: np.ndarray | None = None
    timestamps: np.ndarray | None = None
    normals: np.ndarray | None = None


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
