"""Open any supported input as a scan sequence: :func:`open_sequence`.

Accepted inputs (checked in this order):

- a recording: ``.bag`` (ROS 1), ``.mcap``, ``.db3`` or a ROS 2 bag folder → :class:`BagSequence`
  (``topic`` selects the ``PointCloud2`` topic);
- a relnav sequence folder (``scans/`` …, DESIGN §5) → :class:`relnav.io.ScanSequence`;
- a KITTI odometry sequence folder (``velodyne/*.bin``, ``times.txt``, optional ``calib.txt``
  and ground truth ``poses/NN.txt``, ``poses.txt`` or ``../../poses/NN.txt``) →
  :class:`FileSequence`;
- any plain folder of point-cloud files (sorted by natural name order, times ``0, 1, 2, …``
  unless a ``timestamps.txt`` or ``times.txt`` sits next to them) → :class:`FileSequence`.

Every returned object has ``len``, ``seq[i]`` (a :class:`~relnav.scan.Scan`), ``timestamps``,
``gt_poses`` (or ``None``), ``source_files`` and ``describe()``.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from relnav.errors import InputError
from relnav.io.bags import BagSequence, is_recording
from relnav.io.pointclouds import POINT_READ_EXTENSIONS, read_scan
from relnav.io.sequences import _check_increasing, _natural_key, _read_timestamps
from relnav.io.text import read_text_file
from relnav.io.trajectories import read_kitti
from relnav.scan import Scan

__all__ = [
    "UNITS_FACTOR",
    "UNITS_FACTOR_GT",
    "FileSequence",
    "content_hash",
    "open_sequence",
    "read_kitti_calib_tr",
    "units_warning",
]

logger = logging.getLogger("relnav.io")


class FileSequence:
    """Scans from a list of point-cloud files, with times and optional ground truth.

    Parameters
    ----------
    files : sequence of Path
        Scan files in order.
    times : (N,) float64, optional
        Scan times, seconds (default ``0, 1, 2, …``).
    gt_poses : (N, 4, 4) float64, optional
        Ground truth ``T_world_sensor`` per scan.
    kind : str
        ``"folder"`` or ``"kitti"`` (recorded in ``run.json``).
    folder : Path
        The folder the files came from.
    extra_sources : sequence of Path
        Other files that define the sequence (times, poses, calibration).
    """

    def __init__(
        self,
        files: Sequence[Path],
        *,
        times: np.ndarray | None = None,
        gt_poses: np.ndarray | None = None,
        kind: str = "folder",
        folder: Path | None = None,
        extra_sources: Sequence[Path] = (),
    ) -> None:
        self._files = list(files)
        n = len(self._files)
        self._times = np.arange(n, dtype=np.float64) if times is None else np.asarray(times)
        if self._times.shape != (n,):
            raise InputError(f"{folder}: {self._times.size} times for {n} scans")
        if gt_poses is not None and len(gt_poses) != n:
            raise InputError(f"{folder}: {len(gt_poses)} ground-truth poses for {n} scans")
        self._gt = gt_poses
        self._kind = kind
        self._folder = folder if folder is not None else (self._files[0].parent if n else Path())
        self._extra = list(extra_sources)
        self._times_assumed = times is None

    @property
    def times_assumed(self) -> bool:
        """True when no file gave the scan times: they are ``0, 1, 2, …`` s (or what
        :meth:`set_time_spacing` set)."""
        return self._times_assumed

    def set_time_spacing(self, dt: float) -> None:
        """Scan times ``0, dt, 2·dt, …`` (seconds) for a folder without a times file."""
        if not self._times_assumed:
            raise InputError(f"{self._folder}: the scans have times of their own (--dt/--rate)")
        self._times = np.arange(len(self._files), dtype=np.float64) * float(dt)

    @property
    def folder(self) -> Path:
        """The folder the scans came from."""
        return self._folder

    @property
    def files(self) -> list[Path]:
        """Scan files in order."""
        return list(self._files)

    @property
    def timestamps(self) -> np.ndarray:
        """``(N,)`` scan times, seconds."""
        return self._times.copy()

    @property
    def gt_poses(self) -> np.ndarray | None:
        """``(N, 4, 4)`` ground truth or ``None``."""
        return None if self._gt is None else self._gt.copy()

    @property
    def source_files(self) -> list[Path]:
        """Files whose content defines this sequence."""
        return [*self._files, *self._extra]

    def describe(self) -> dict[str, Any]:
        """What ``run.json`` records about the input."""
        return {"kind": self._kind, "path": str(self._folder)}

    def __len__(self) -> int:
        return len(self._files)

    def __getitem__(self, i: int) -> Scan:
        n = len(self._files)
        k = int(i) + n if i < 0 else int(i)
        if not 0 <= k < n:
            raise IndexError(f"scan index {i} out of range for {n} scans")
        return read_scan(self._files[k], time=float(self._times[k]))

    def __iter__(self) -> Iterator[Scan]:
        for i in range(len(self)):
            yield self[i]

    def __repr__(self) -> str:
        return f"FileSequence({str(self._folder)!r}, kind={self._kind!r}, n={len(self)})"


def _point_files(d: Path) -> list[Path]:
    files = [q for q in d.iterdir() if q.is_file() and q.suffix.lower() in POINT_READ_EXTENSIONS]
    # a folder of scans never holds the trajectory/time text files relnav itself reads
    skip = {"times.txt", "timestamps.txt", "poses.txt", "calib.txt"}
    files = [q for q in files if q.name not in skip and not q.name.startswith("gt_")]
    return sorted(files, key=lambda q: (_natural_key(q.name), q.name))


def read_kitti_calib_tr(path: Path) -> np.ndarray | None:
    """The ``Tr`` line of a KITTI ``calib.txt`` (velodyne → camera 0) as a 4×4, or ``None``."""
    for line in read_text_file(path, what="KITTI calibration").splitlines():
        key, _, rest = line.partition(":")
        if key.strip() == "Tr":
            try:
                vals = [float(x) for x in rest.split()]
            except ValueError:
                raise InputError(f"{path}: Tr line is not numeric") from None
            if len(vals) != 12:
                raise InputError(f"{path}: Tr has {len(vals)} numbers, expected 12")
            T = np.eye(4)
            T[:3, :] = np.reshape(vals, (3, 4))
            return T
    return None


def _kitti_sequence(folder: Path) -> FileSequence:
    """A KITTI odometry sequence folder.

    The ground truth (``poses/NN.txt``) is the pose of camera 0 in the first camera frame; with
    a ``calib.txt`` ``Tr`` (velodyne → camera 0) it is converted to the velodyne's pose in the
    first velodyne frame, ``Tr⁻¹ · P_k · Tr`` **[interpretation]**, so it compares directly with
    LIDAR odometry that starts at the identity (without ``calib.txt`` the poses are used as
    they are).
    """
    velo = folder / "velodyne"
    files = sorted(velo.glob("*.bin"), key=lambda q: (_natural_key(q.name), q.name))
    if not files:
        raise InputError(f"{velo}: no .bin scans")
    extra: list[Path] = []
    times = None
    if (folder / "times.txt").is_file():
        times = _read_timestamps(folder / "times.txt")
        extra.append(folder / "times.txt")
        if len(times) != len(files):
            raise InputError(f"{folder / 'times.txt'}: {len(times)} times for {len(files)} scans")
        _check_increasing(times, folder / "times.txt")
    name = folder.name
    candidates = [
        folder / "poses" / f"{name}.txt",
        folder / "poses.txt",
        folder.parent.parent / "poses" / f"{name}.txt",
    ]
    if (folder / "poses").is_dir():
        only = sorted((folder / "poses").glob("*.txt"))
        if len(only) == 1:
            candidates.append(only[0])
    gt = None
    for c in candidates:
        if c.is_file():
            gt = read_kitti(c)
            extra.append(c)
            calib = folder / "calib.txt"
            if calib.is_file() and (Tr := read_kitti_calib_tr(calib)) is not None:
                from relnav.geometry.se3 import invert

                gt = invert(Tr)[None] @ gt @ Tr[None]
                extra.append(calib)
            if len(gt) != len(files):
                raise InputError(f"{c}: {len(gt)} poses for {len(files)} scans in {velo}")
            break
    return FileSequence(
        files, times=times, gt_poses=gt, kind="kitti", folder=folder, extra_sources=extra
    )


def _plain_folder(folder: Path) -> FileSequence:
    files = _point_files(folder)
    if not files:
        exts = ", ".join(sorted(POINT_READ_EXTENSIONS))
        raise InputError(f"{folder}: no scans (expected scans/, velodyne/, or point files: {exts})")
    times = None
    extra: list[Path] = []
    for name in ("timestamps.txt", "times.txt"):
        if (folder / name).is_file():
            times = _read_timestamps(folder / name)
            extra.append(folder / name)
            if len(times) != len(files):
                raise InputError(f"{folder / name}: {len(times)} times for {len(files)} scans")
            _check_increasing(times, folder / name)
            break
    return FileSequence(files, times=times, kind="folder", folder=folder, extra_sources=extra)


def open_sequence(path: str | Path, *, sensor: str | None = None, topic: str | None = None) -> Any:
    """Open a recording, a relnav sequence folder, a KITTI folder or a plain folder of scans.

    Parameters
    ----------
    path : str or Path
        See the module docstring.
    sensor : str, optional
        Second sensor of a relnav sequence folder (``scans_<name>/``).
    topic : str, optional
        ``PointCloud2`` topic of a recording.

    Raises
    ------
    InputError
        Missing path, nothing recognisable, or an option that does not fit the input
        (``--topic`` for a folder, ``--sensor`` for a recording).
    """
    from relnav.io.sequences import ScanSequence

    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such file or folder")
    if is_recording(p):
        if sensor:
            raise InputError(f"{p}: --sensor is for sequence folders; use --topic for a recording")
        return BagSequence(p, topic=topic)
    if topic:
        raise InputError(f"{p}: --topic is for recordings (.bag, .mcap, .db3), not a folder")
    if p.is_file():
        raise InputError(f"{p}: not a recording (.bag, .mcap, .db3) nor a folder of scans")
    if sensor or (p / "scans").is_dir():
        return ScanSequence(p, sensor=sensor)
    if (p / "velodyne").is_dir():
        return _kitti_sequence(p)
    return _plain_folder(p)


def sequence_sources(seq: Any) -> list[Path]:
    """Files that define ``seq`` (scans, times, ground truth), for :func:`content_hash`."""
    if hasattr(seq, "source_files"):
        return list(seq.source_files)
    files = list(getattr(seq, "files", []))
    lay = getattr(seq, "layout", None)
    if lay is not None:
        files += [q for q in (lay.timestamps, lay.gt, lay.sensor_yaml) if q.is_file()]
    return files


def sequence_description(seq: Any) -> dict[str, Any]:
    """``{"kind", "path", ...}`` of any sequence :func:`open_sequence` returns."""
    if hasattr(seq, "describe"):
        return seq.describe()
    d: dict[str, Any] = {"kind": "sequence", "path": str(getattr(seq, "folder", ""))}
    if getattr(seq, "sensor", ""):
        d["sensor"] = seq.sensor
    return d


def content_hash(paths: Sequence[Path], root: Path | None = None) -> str:
    """SHA-256 over the names (relative to ``root``) and bytes of ``paths``, in order.

    Returns ``"sha256:<hex>"``; two runs on the same inputs record the same hash.
    """
    h = hashlib.sha256()
    for q in paths:
        name = str(q.relative_to(root)) if root is not None and q.is_relative_to(root) else q.name
        h.update(name.encode() + b"\0")
        with q.open("rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    return "sha256:" + h.hexdigest()


UNITS_FACTOR = 1000.0
"""A scan extending this many times beyond the sensor's range (or the target's size, when no
ground truth gives the distance) is taken as written in other units (millimetres, not metres)."""
UNITS_FACTOR_GT = 100.0
"""The same against the ground truth's largest sensor-to-target distance (a scan cannot reach
much beyond the target it sees)."""


def _scene_lengths(seq: Any) -> list[tuple[float, float, str]]:
    """``(length m, factor, what)`` a scan of ``seq`` should stay within ``factor`` times of:
    the sensor's range, the ground truth's farthest sensor-to-target distance, or else the
    target's size, where known."""
    out: list[tuple[float, float, str]] = []
    meta = getattr(seq, "sensor_meta", None) or {}
    try:
        r = float(meta.get("max_range", np.inf))
    except (TypeError, ValueError):
        r = np.inf
    if np.isfinite(r) and r > 0:
        out.append((r, UNITS_FACTOR, "the sensor's range"))
    try:
        gt = getattr(seq, "gt_poses", None)
    except InputError:
        gt = None
    if gt is not None and len(gt):
        d = float(np.max(np.linalg.norm(np.asarray(gt)[:, :3, 3], axis=1)))
        if np.isfinite(d) and d > 0:
            out.append((d, UNITS_FACTOR_GT, "the ground truth's largest distance to the target"))
            return out
    try:
        sc = getattr(seq, "scenario", None) or {}
        size = float((sc.get("target") or {}).get("scale_to") or 0.0)
    except (AttributeError, TypeError, ValueError, InputError):
        size = 0.0
    if np.isfinite(size) and size > 0:
        out.append((size, UNITS_FACTOR, "the target's size"))
    return out


def units_warning(seq: Any, points: np.ndarray) -> str | None:
    """A warning when ``points`` (a scan of ``seq``, ``(N, 3)`` m) reach far beyond a length
    the sequence knows (:data:`UNITS_FACTOR` x the sensor's range or the target's size,
    :data:`UNITS_FACTOR_GT` x the ground truth's distance): the scans are likely in
    millimetres. ``None`` otherwise, or when the sequence knows no length."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not len(pts):
        return None
    extent = float(np.max(np.linalg.norm(pts, axis=1)))
    for ref, factor, what in _scene_lengths(seq):
        if extent >= factor * ref:
            return (
                f"the first scan reaches {extent:.4g} m, {extent / ref:.0f}x {what} "
                f"({ref:.4g} m): are the scans in millimetres? relnav reads metres"
            )
    return None
