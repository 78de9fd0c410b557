"""Recordings in: ROS 1 bags, ROS 2 bags (sqlite3 ``.db3``) and MCAP files, read with ``rosbags``.

:class:`BagSequence` exposes the ``sensor_msgs/PointCloud2`` messages of one topic as a sequence
of :class:`~relnav.scan.Scan` (points in the message's frame, metres), like
:class:`relnav.io.ScanSequence`: ``len(seq)``, ``seq[i]``, ``seq.timestamps``, ``seq.gt_poses``
(always ``None``: a recording has no ground truth). No ROS installation is needed; the reader
is the optional dependency ``rosbags`` (extra ``[ros]``).

Scan times are the messages' ``header.stamp`` (seconds), not the time the bag recorded them
**[interpretation]** (the stamp is the acquisition time; the record time includes transport
latency); messages are ordered by that stamp. Points with a non-finite coordinate are dropped.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from relnav.errors import ConfigError, InputError
from relnav.scan import Scan

__all__ = ["BAG_SUFFIXES", "BagSequence", "decode_pointcloud2", "is_recording"]

logger = logging.getLogger("relnav.io")

BAG_SUFFIXES = (".bag", ".mcap", ".db3")
"""File suffixes read as recordings (a ROS 2 bag folder with ``metadata.yaml`` is one too)."""

POINTCLOUD2_TYPES = ("sensor_msgs/msg/PointCloud2", "sensor_msgs/PointCloud2")

# sensor_msgs/PointField datatypes → NumPy type
_PF_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def is_recording(path: str | Path) -> bool:
    """True for a ``.bag``/``.mcap``/``.db3`` file or a ROS 2 bag folder (``metadata.yaml``)."""
    p = Path(path)
    if p.is_file():
        return p.suffix.lower() in BAG_SUFFIXES
    return p.is_dir() and (p / "metadata.yaml").is_file()


def decode_pointcloud2(msg: Any, *, where: str = "PointCloud2") -> np.ndarray:
    """Decode the ``x, y, z`` fields of a ``sensor_msgs/PointCloud2`` message.

    Parameters
    ----------
    msg : PointCloud2
        A deserialised message (attributes ``fields``, ``point_step``, ``row_step``, ``height``,
        ``width``, ``is_bigendian``, ``data``); the ``x``, ``y``, ``z`` fields may have any
        offsets and any numeric datatype, the point may carry other fields and padding.
    where : str
        Used in error messages (e.g. ``"file.bag /points #3"``).

    Returns
    -------
    (N, 3) float64
        Finite points, metres, in the message's ``header.frame_id`` frame.

    Raises
    ------
    InputError
        A missing ``x``/``y``/``z`` field, an unknown datatype or a data buffer too short.
    """
    fields = {f.name: f for f in msg.fields}
    missing = [n for n in "xyz" if n not in fields]
    if missing:
        raise InputError(
            f"{where}: PointCloud2 has no field(s) {', '.join(missing)} "
            f"(fields: {', '.join(fields) or 'none'})"
        )
    endian = ">" if msg.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for n in "xyz":
        f = fields[n]
        if f.datatype not in _PF_TYPES:
            raise InputError(f"{where}: field {n!r} has unknown PointField datatype {f.datatype}")
        names.append(n)
        formats.append(endian + _PF_TYPES[f.datatype])
        offsets.append(int(f.offset))
    step = int(msg.point_step)
    height, width = int(msg.height), int(msg.width)
    n_pts = height * width
    if n_pts == 0:
        return np.zeros((0, 3))
    dt = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    data = np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), dtype=np.uint8)
    row = int(msg.row_step) or width * step
    if data.size < (height - 1) * row + width * step or max(offsets) + 1 > step:
        raise InputError(
            f"{where}: PointCloud2 data has {data.size} bytes, too few for "
            f"{height}×{width} points of {step} bytes (row_step {row})"
        )
    rows = [
        np.frombuffer(data[r * row : r * row + width * step].tobytes(), dtype=dt)
        for r in range(height)
    ]
    rec = np.concatenate(rows) if len(rows) > 1 else rows[0]
    pts = np.column_stack([rec["x"], rec["y"], rec["z"]]).astype(np.float64)
    ok = np.isfinite(pts).all(axis=1)
    return pts[ok] if not ok.all() else pts


def _stamp_seconds(msg: Any, fallback_ns: int) -> float:
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        return fallback_ns * 1e-9
    sec = getattr(stamp, "sec", getattr(stamp, "secs", 0))
    nsec = getattr(stamp, "nanosec", getattr(stamp, "nsecs", 0))
    return float(sec) + 1e-9 * float(nsec)


class BagSequence:
    """The ``PointCloud2`` messages of one topic of a recording, as a sequence of scans.

    Parameters
    ----------
    path : str or Path
        ``.bag`` (ROS 1), ``.mcap``, ``.db3`` or a ROS 2 bag folder.
    topic : str, optional
        Topic to read; may be omitted when the recording has exactly one PointCloud2 topic.

    Notes
    -----
    Construction reads every message of the topic once to collect the header stamps; scans
    are then decoded on access. Sequential access (``seq[0]``, ``seq[1]``, … as odometry does)
    streams through the recording once; random access reopens it.
    """

    def __init__(self, path: str | Path, topic: str | None = None) -> None:
        try:
            from rosbags.highlevel import AnyReader
        except ImportError:
            raise ConfigError(
                "reading ROS bags and MCAP files needs the optional dependency rosbags: "
                "pip install 'relnav[ros]'"
            ) from None
        self._path = Path(path)
        if not self._path.exists():
            raise InputError(f"{self._path}: no such recording")
        self._reader_cls = AnyReader
        try:
            with AnyReader([self._path]) as r:
                clouds = sorted({c.topic for c in r.connections if c.msgtype in POINTCLOUD2_TYPES})
                if topic is None:
                    if len(clouds) != 1:
                        which = ", ".join(clouds) if clouds else "none"
                        raise InputError(
                            f"{self._path}: give --topic (PointCloud2 topics: {which})"
                        )
                    topic = clouds[0]
                if topic not in clouds:
                    all_topics = ", ".join(sorted({c.topic for c in r.connections})) or "none"
                    raise InputError(
                        f"{self._path}: no PointCloud2 topic {topic!r} "
                        f"(PointCloud2 topics: {', '.join(clouds) or 'none'}; all: {all_topics})"
                    )
                self._topic = topic
                cons = [c for c in r.connections if c.topic == topic]
                stamps = []
                for k, (con, t_ns, raw) in enumerate(r.messages(connections=cons)):
                    stamps.append((_stamp_seconds(r.deserialize(raw, con.msgtype), t_ns), k))
        except InputError:
            raise
        except Exception as e:  # rosbags raises its own error types per format
            raise InputError(
                f"{self._path}: cannot read recording ({type(e).__name__}: {e})"
            ) from None
        stamps.sort()
        self._times = np.array([s for s, _ in stamps], dtype=np.float64)
        self._order = [k for _, k in stamps]  # sorted position → message index in the bag
        self._pos_of = {k: i for i, k in enumerate(self._order)}
        self._iter: Iterator[tuple[int, Scan]] | None = None
        self._ctx: Any = None
        self._next_msg = 0
        self._last: tuple[int, Scan] | None = None  # the scan odometry and a viewer both ask for
        if not len(self._times):
            logger.warning("%s: topic %s has no messages", self._path, topic)

    # --- metadata --------------------------------------------------------------------------

    @property
    def path(self) -> Path:
        """The recording."""
        return self._path

    @property
    def topic(self) -> str:
        """The PointCloud2 topic read."""
        return self._topic

    @property
    def timestamps(self) -> np.ndarray:
        """``(N,)`` header stamps, seconds, ascending."""
        return self._times.copy()

    @property
    def gt_poses(self) -> None:
        """Recordings carry no ground truth."""
        return None

    @property
    def source_files(self) -> list[Path]:
        """Files whose content defines this sequence (for the run's content hash)."""
        if self._path.is_dir():
            return sorted(q for q in self._path.iterdir() if q.is_file())
        return [self._path]

    def describe(self) -> dict[str, Any]:
        """What ``run.json`` records about the input."""
        return {"kind": "recording", "path": str(self._path), "topic": self._topic}

    # --- access ----------------------------------------------------------------------------

    def _close(self) -> None:
        if self._ctx is not None:
            self._ctx.__exit__(None, None, None)
        self._ctx, self._iter = None, None

    def _stream(self) -> Iterator[tuple[int, Scan]]:
        r = self._ctx
        cons = [c for c in r.connections if c.topic == self._topic]
        for k, (con, t_ns, raw) in enumerate(r.messages(connections=cons)):
            msg = r.deserialize(raw, con.msgtype)
            pts = decode_pointcloud2(msg, where=f"{self._path} {self._topic} #{k}")
            frame = str(getattr(getattr(msg, "header", None), "frame_id", ""))
            yield k, Scan(pts, time=_stamp_seconds(msg, t_ns), sensor={"frame_id": frame})

    def __len__(self) -> int:
        return len(self._times)

    def __getitem__(self, i: int) -> Scan:
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"scan {i} out of range for {n} scans")
        want = self._order[i % n]
        if self._last is not None and self._last[0] == want:
            return self._last[1]
        if self._iter is None or want < self._next_msg:
            self._close()
            self._ctx = self._reader_cls([self._path])
            self._ctx.__enter__()
            self._iter = self._stream()
            self._next_msg = 0
        for k, scan in self._iter:
            self._next_msg = k + 1
            if k == want:
                self._last = (k, scan)
                return scan
        raise InputError(
            f"{self._path}: message {want} of {self._topic} vanished"
        )  # pragma: no cover

    def __iter__(self) -> Iterator[Scan]:
        for i in range(len(self)):
            yield self[i]

    def __del__(self) -> None:
        try:
            self._close()
        except Exception:  # pragma: no cover - interpreter shutdown
            pass

    def __repr__(self) -> str:
        return f"BagSequence({str(self._path)!r}, topic={self._topic!r}, {len(self)} scans)"
