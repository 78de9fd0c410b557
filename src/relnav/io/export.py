"""Recordings out: a scan sequence written as a ROS 2 bag or as a KITTI odometry folder.

:func:`export_sequence` takes anything :func:`relnav.io.open_sequence` opens (a simulated
sequence folder, a plain folder, a KITTI folder, a recording) and writes

- ``"rosbag2"``: a ROS 2 bag folder (``metadata.yaml`` + one ``.db3``; ``storage="mcap"`` for
  one ``.mcap``) with one ``sensor_msgs/msg/PointCloud2`` message per scan on ``topic``:
  fields ``x, y, z, intensity`` float32 (16-byte points, little-endian, ``height = 1``), the
  scan time as ``header.stamp`` **and** as the record time, ``header.frame_id = frame_id``.
  A scan with no point is a message with ``width = 0`` (relnav reads it back as an empty scan).
  Written with the ``rosbags`` library (extra ``[ros]``), no ROS installation needed.
- ``"kitti"``: the KITTI odometry layout, ``velodyne/NNNNNN.bin`` (float32 ``x y z
  reflectance``, reflectance 0 when the scan has none), ``times.txt`` (one time per scan, s,
  written with every digit) and, when the sequence has ground truth, ``poses.txt`` (KITTI
  pose format: the row-major top 3×4 of each ``T_world_sensor``, as the sequence gives it: for
  a simulated sequence the sensor's pose in the target frame, not re-based on the first pose).

Both keep the points to float32 (what the formats hold) and the times (the bag to the
nanosecond of ``builtin_interfaces/Time``); :mod:`relnav.io.bags` and
:func:`relnav.io.open_sequence` read them back. The output is written into a temporary sibling
folder and renamed when complete, so an interrupted export leaves no half-written recording
under the final name.
"""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from relnav.atomic import temp_name
from relnav.errors import ConfigError, InputError

__all__ = ["EXPORT_FORMATS", "export_kitti", "export_rosbag2", "export_sequence"]

logger = logging.getLogger("relnav.io")

EXPORT_FORMATS = ("rosbag2", "kitti")
"""Formats :func:`export_sequence` writes."""

Progress = Callable[[int, int], None]


def _stamp_ns(t: float) -> int:
    """A scan time, s, as integer nanoseconds (ROS ``builtin_interfaces/Time``)."""
    return round(float(t) * 1e9)


def _check_out(out: Path, overwrite: bool) -> None:
    if out.exists():
        if not overwrite:
            raise InputError(f"{out}: already exists (--overwrite replaces it)")
        if not out.is_dir():
            raise InputError(f"{out}: exists and is not a folder")


def _finish(tmp: Path, out: Path) -> Path:
    """Move the completed temporary folder ``tmp`` to ``out`` (replacing an old ``out``)."""
    if out.exists():
        shutil.rmtree(out)
    os.replace(tmp, out)
    return out


def _tmp_dir(out: Path) -> Path:
    tmp = temp_name(out)  # the project's temporary sibling (relnav.atomic)
    if tmp.exists():
        shutil.rmtree(tmp)
    out.parent.mkdir(parents=True, exist_ok=True)
    return tmp


def _scan_arrays(seq: Any, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) float32 and intensity (N,) float32 (zeros when absent) of scan ``i``."""
    scan = seq[i]
    pts = np.asarray(scan.points, dtype=np.float32).reshape(-1, 3)
    inten = getattr(scan, "intensity", None)
    if inten is None:
        inten = np.zeros(len(pts), dtype=np.float32)
    return pts, np.asarray(inten, dtype=np.float32).reshape(-1)


def _pointcloud2(ts: Any, pts: np.ndarray, inten: np.ndarray, t: float, frame_id: str) -> Any:
    """A ``sensor_msgs/msg/PointCloud2`` with float32 x, y, z, intensity (16-byte points)."""
    PC2 = ts.types["sensor_msgs/msg/PointCloud2"]
    PF = ts.types["sensor_msgs/msg/PointField"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    rec = np.zeros((len(pts), 4), dtype="<f4")
    rec[:, :3] = pts
    rec[:, 3] = inten
    ns = _stamp_ns(t)
    sec, nsec = divmod(ns, 1_000_000_000)
    return PC2(
        header=Header(stamp=Time(sec=int(sec), nanosec=int(nsec)), frame_id=frame_id),
        height=1,
        width=len(pts),
        fields=[
            PF(name=n, offset=4 * k, datatype=7, count=1)
            for k, n in enumerate(("x", "y", "z", "intensity"))
        ],
        is_bigendian=False,
        point_step=16,
        row_step=16 * len(pts),
        data=np.frombuffer(rec.tobytes(), dtype=np.uint8).copy(),
        is_dense=True,
    )


def export_rosbag2(
    seq: Any,
    out: str | Path,
    *,
    topic: str = "/points",
    frame_id: str = "lidar",
    storage: str = "sqlite3",
    overwrite: bool = False,
    progress: Progress | None = None,
) -> Path:
    """Write ``seq`` as a ROS 2 bag folder (one ``PointCloud2`` per scan on ``topic``).

    Parameters
    ----------
    seq : sequence
        Anything :func:`relnav.io.open_sequence` returns (``len``, ``seq[i].points`` (N, 3) m in
        the sensor frame, ``timestamps`` (N,) s).
    out : str or Path
        The bag folder to create.
    topic, frame_id : str
        Topic name (starts with ``/``) and ``header.frame_id``.
    storage : {"sqlite3", "mcap"}
        ROS 2 storage plugin.
    overwrite : bool
        Replace an existing ``out``.
    progress : callable, optional
        ``progress(done, total)`` after each scan.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    ConfigError
        ``rosbags`` missing, a bad topic or storage.
    InputError
        ``out`` exists, times that do not increase, an unreadable scan.
    """
    try:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise ConfigError(
            "writing ROS 2 bags needs the optional dependency rosbags: pip install 'relnav[ros]'"
        ) from None
    if not topic.startswith("/") or len(topic) < 2 or any(c.isspace() for c in topic):
        raise ConfigError(f"topic must be a ROS name starting with '/', got {topic!r}")
    plugins = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
    if storage not in plugins:
        raise ConfigError(f"storage must be one of {', '.join(plugins)}, got {storage!r}")
    out = Path(out)
    _check_out(out, overwrite)
    times = _checked_times(seq)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    tmp = _tmp_dir(out)
    n = len(seq)
    try:
        with Writer(tmp, version=9, storage_plugin=plugins[storage]) as w:
            con = w.add_connection(topic, "sensor_msgs/msg/PointCloud2", typestore=ts)
            for i in range(n):
                pts, inten = _scan_arrays(seq, i)
                msg = _pointcloud2(ts, pts, inten, float(times[i]), frame_id)
                w.write(con, _stamp_ns(times[i]), ts.serialize_cdr(msg, msg.__msgtype__))
                if progress is not None:
                    progress(i + 1, n)
        # rosbags names the storage file after the folder: rename it after the final name
        for f in list(tmp.iterdir()):
            if f.name.startswith(tmp.name):
                f.rename(tmp / (out.name + f.name[len(tmp.name) :]))
        meta = tmp / "metadata.yaml"
        meta.write_text(meta.read_text().replace(tmp.name, out.name))
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    logger.info("wrote %d scans to the ROS 2 bag %s (topic %s)", n, out, topic)
    return _finish(tmp, out)


def export_kitti(
    seq: Any, out: str | Path, *, overwrite: bool = False, progress: Progress | None = None
) -> Path:
    """Write ``seq`` as a KITTI odometry folder: ``velodyne/*.bin``, ``times.txt``, ``poses.txt``.

    Parameters
    ----------
    seq : sequence
        As for :func:`export_rosbag2`; ``seq.gt_poses`` (N, 4, 4) or ``None``.
    out : str or Path
        The folder to create (``relnav odometry OUT`` reads it).
    overwrite : bool
        Replace an existing ``out``.
    progress : callable, optional
        ``progress(done, total)`` after each scan.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    InputError
        ``out`` exists, times that do not increase, an unreadable scan.
    """
    from relnav.io.trajectories import write_kitti

    out = Path(out)
    _check_out(out, overwrite)
    times = _checked_times(seq)
    gt = getattr(seq, "gt_poses", None)
    tmp = _tmp_dir(out)
    n = len(seq)
    try:
        velo = tmp / "velodyne"
        velo.mkdir(parents=True)
        width = max(6, len(str(max(n - 1, 0))))
        for i in range(n):
            pts, inten = _scan_arrays(seq, i)
            rec = np.zeros((len(pts), 4), dtype="<f4")
            rec[:, :3] = pts
            rec[:, 3] = inten
            (velo / f"{i:0{width}d}.bin").write_bytes(rec.tobytes())
            if progress is not None:
                progress(i + 1, n)
        (tmp / "times.txt").write_text("".join(f"{float(t)!r}\n" for t in times))
        if gt is not None:
            write_kitti(tmp / "poses.txt", np.asarray(gt))
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    logger.info("wrote %d scans to the KITTI folder %s", n, out)
    return _finish(tmp, out)


def _checked_times(seq: Any) -> np.ndarray:
    times = np.asarray(seq.timestamps, dtype=np.float64)
    if len(times) != len(seq):
        raise InputError(f"{len(times)} times for {len(seq)} scans")
    if len(seq) == 0:
        raise InputError("the sequence has no scans: nothing to export")
    if not np.isfinite(times).all() or np.any(np.diff(times) <= 0):
        raise InputError("scan times must be finite and increasing to export a recording")
    return times


def export_sequence(seq: Any, out: str | Path, fmt: str, **kwargs: Any) -> Path:
    """Write ``seq`` as ``fmt`` (one of :data:`EXPORT_FORMATS`); see :func:`export_rosbag2`
    and :func:`export_kitti` for the keyword arguments."""
    key = str(fmt).lower()
    if key == "rosbag2":
        return export_rosbag2(seq, out, **kwargs)
    if key == "kitti":
        kwargs = {k: v for k, v in kwargs.items() if k in ("overwrite", "progress")}
        return export_kitti(seq, out, **kwargs)
    raise ConfigError(f"unknown export format {fmt!r}; expected one of {', '.join(EXPORT_FORMATS)}")
