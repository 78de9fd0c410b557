"""Trajectory files: TUM (``t x y z qx qy qz qw``) and KITTI (12 numbers, row-major ``3x4``).

Poses are ``(N, 4, 4)`` float64 homogeneous transforms ``T_a_b`` (what frames ``a``/``b`` are is
the caller's business: a sequence's ground truth is ``T_target_sensor``). Quaternions are
``(x, y, z, w)``, normalised on read. Values are written with Python ``repr`` (the shortest
decimal that round-trips), so a write/read cycle gives back the same float64 numbers, up to the
quaternion's own conversion error (~1e-15).

Lines that are blank or start with ``#`` are skipped on reading; separators may be whitespace or
commas. A malformed line raises :class:`relnav.errors.InputError` giving the file and line number.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np

from relnav.errors import InputError
from relnav.geometry.rotations import matrix_to_quat, quat_to_matrix
from relnav.io.text import read_text_file

__all__ = ["read_kitti", "read_trajectory", "read_tum", "write_kitti", "write_tum"]

logger = logging.getLogger("relnav.io")

_SPLIT = re.compile(r"[\s,]+")


def _numeric_rows(p: Path, width: int, what: str) -> tuple[np.ndarray, list[int]]:
    """Parse every non-comment line of ``p`` into ``width`` finite floats."""
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    text = read_text_file(p, what=what)
    rows: list[list[float]] = []
    linenos: list[int] = []
    for no, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        toks = [t for t in _SPLIT.split(s) if t]
        if len(toks) != width:
            raise InputError(
                f"{p}: line {no}: expected {width} numbers ({what}), got {len(toks)}: {s[:60]!r}"
            )
        try:
            vals = [float(t) for t in toks]
        except ValueError:
            raise InputError(f"{p}: line {no}: non-numeric value in {s[:60]!r}") from None
        if not all(np.isfinite(vals)):
            raise InputError(f"{p}: line {no}: NaN or infinite value in {s[:60]!r}")
        rows.append(vals)
        linenos.append(no)
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, width)
    return arr, linenos


def _as_poses(poses: np.ndarray, what: str) -> np.ndarray:
    """Validate ``(N, 4, 4)`` (or ``(N, 3, 4)``) finite poses; return ``(N, 4, 4)``."""
    try:
        P = np.asarray(poses, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"{what}: poses are not numeric ({e})") from None
    if P.ndim != 3 or P.shape[1:] not in ((4, 4), (3, 4)):
        raise InputError(f"{what}: poses must have shape (N, 4, 4) or (N, 3, 4), got {P.shape}")
    if not np.isfinite(P).all():
        bad = int(np.flatnonzero(~np.isfinite(P).reshape(P.shape[0], -1).all(axis=1))[0])
        raise InputError(f"{what}: pose {bad} has NaN or infinite entries")
    if P.shape[1] == 3:
        full = np.zeros((P.shape[0], 4, 4))
        full[:, :3, :] = P
        full[:, 3, 3] = 1.0
        P = full
    return P


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory file.

    Parameters
    ----------
    path : str or Path
        Text file, one pose per line: ``t x y z qx qy qz qw`` (seconds, metres, unit
        quaternion ``xyzw``).

    Returns
    -------
    timestamps : (N,) float64
        Seconds.
    poses : (N, 4, 4) float64
        Homogeneous transforms; the quaternion is normalised before conversion.

    Raises
    ------
    InputError
        Missing file, a line without exactly 8 finite numbers, or a zero quaternion
        (the message gives the line number).
    """
    p = Path(path)
    rows, linenos = _numeric_rows(p, 8, "t x y z qx qy qz qw")
    q = rows[:, 4:8]
    norm = np.linalg.norm(q, axis=1)
    if rows.shape[0] and (bad := np.flatnonzero(norm < 1e-12)).size:
        raise InputError(f"{p}: line {linenos[int(bad[0])]}: zero-length quaternion")
    poses = np.tile(np.eye(4), (rows.shape[0], 1, 1))
    if rows.shape[0]:
        poses[:, :3, :3] = quat_to_matrix(q / norm[:, None])
        poses[:, :3, 3] = rows[:, 1:4]
    return rows[:, 0].copy(), poses


def write_tum(path: str | Path, timestamps: np.ndarray, poses: np.ndarray) -> Path:
    """Write a TUM trajectory file ``t x y z qx qy qz qw`` (one pose per line).

    Parameters
    ----------
    path : str or Path
        Output file; parent folders are created.
    timestamps : (N,) array_like
        Seconds.
    poses : (N, 4, 4) array_like
        Homogeneous transforms; the rotation block is converted to a unit quaternion ``xyzw``
        with ``w >= 0`` (nearest rotation if it is not exactly orthonormal).

    Returns
    -------
    Path
        The path written.
    """
    p = Path(path)
    P = _as_poses(poses, str(p))
    try:
        t = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as e:
        raise InputError(f"{p}: timestamps are not numeric ({e})") from None
    if t.shape[0] != P.shape[0]:
        raise InputError(f"{p}: {t.shape[0]} timestamps for {P.shape[0]} poses")
    if not np.isfinite(t).all():
        raise InputError(f"{p}: timestamps contain NaN or infinite values")
    lines = []
    if P.shape[0]:
        q = matrix_to_quat(P[:, :3, :3]).reshape(-1, 4)
        table = np.column_stack([t, P[:, :3, 3], q]).tolist()
        lines = [" ".join(map(repr, r)) + "\n" for r in table]
    from relnav.atomic import atomic_write_text

    atomic_write_text(p, "".join(lines), encoding="ascii")  # a killed writer leaves no half file
    return p


def read_kitti(path: str | Path) -> np.ndarray:
    """Read a KITTI pose file (12 numbers per line: the row-major top ``3x4`` of each pose).

    Returns
    -------
    (N, 4, 4) float64
        Homogeneous transforms, exactly as stored (no re-orthonormalisation).

    Raises
    ------
    InputError
        Missing file or a line without exactly 12 finite numbers (with its line number).
    """
    p = Path(path)
    rows, _ = _numeric_rows(p, 12, "row-major 3x4 pose")
    poses = np.tile(np.eye(4), (rows.shape[0], 1, 1))
    poses[:, :3, :] = rows.reshape(-1, 3, 4)
    return poses


def write_kitti(path: str | Path, poses: np.ndarray) -> Path:
    """Write a KITTI pose file: the top ``3x4`` of each ``(N, 4, 4)`` pose, row-major, per line."""
    p = Path(path)
    P = _as_poses(poses, str(p))
    rows = P[:, :3, :].reshape(-1, 12).tolist()
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text("".join(" ".join(map(repr, r)) + "\n" for r in rows), encoding="ascii")
    return p


def _first_row_width(p: Path) -> int:
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    for line in read_text_file(p, what="trajectory").splitlines():
        s = line.strip()
        if s and not s.startswith("#"):
            return len([t for t in _SPLIT.split(s) if t])
    return 0


def read_trajectory(path: str | Path) -> tuple[np.ndarray | None, np.ndarray, str]:
    """Read a TUM or a KITTI trajectory, telling them apart by the numbers per line.

    A KITTI file has no times; they come from a ``times.txt`` in the same folder when it has one
    time per pose (the KITTI odometry layout, and what ``relnav odometry --format kitti``
    writes), else they are ``None``.

    Returns
    -------
    timestamps : (N,) float64 or None
        Seconds.
    poses : (N, 4, 4) float64
    fmt : {"tum", "kitti"}

    Raises
    ------
    InputError
        Missing file, or lines with neither 8 (TUM) nor 12 (KITTI) numbers.
    """
    p = Path(path)
    width = _first_row_width(p)
    if width == 12:
        poses = read_kitti(p)
        times = None
        tf = p.parent / "times.txt"
        if tf.is_file():
            t, _ = _numeric_rows(tf, 1, "time in seconds")
            if len(t) == len(poses):
                times = t[:, 0].copy()
            else:
                logger.warning("%s: %d times for %d poses, ignored", tf, len(t), len(poses))
        return times, poses, "kitti"
    if width in (8, 0):
        t, poses = read_tum(p)
        return t, poses, "tum"
    raise InputError(
        f"{p}: {width} numbers per line: expected 8 (TUM: t x y z qx qy qz qw) "
        "or 12 (KITTI: row-major 3x4 pose)"
    )
