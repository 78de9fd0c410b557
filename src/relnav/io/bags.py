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

import hashlib
import itertools
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


_PF_SIZES = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 8: 8}

MAX_POINT_STEP = 1 << 16
"""Largest ``point_step`` accepted, bytes (real sensors use 16-64; PCL's biggest types ~1.4 kB)."""


def _int(msg: Any, name: str, where: str) -> int:
    try:
        v = int(getattr(msg, name))
    except (AttributeError, TypeError, ValueError, OverflowError):
        raise InputError(f"{where}: PointCloud2 has no integer {name}") from None
    if v < 0:
        raise InputError(f"{where}: PointCloud2 {name} = {v} is negative")
    return v


def pointcloud2_layout(msg: Any, *, where: str = "PointCloud2") -> dict[str, Any]:
    """Check a ``PointCloud2`` message's layout against its data, before touching the data.

    Checks: ``x``, ``y``, ``z`` fields present with a known datatype, a non-negative offset, a
    count that is a small positive integer (``0`` read as ``1``) and an extent within
    ``point_step`` (and not overlapping each other); ``row_step ≥ width·point_step`` (``0`` is
    read as ``width·point_step``); ``data`` long enough for ``height`` rows.

    Returns
    -------
    dict
        ``height``, ``width``, ``point_step``, ``row_step`` (int) and ``dtype`` (the x/y/z
        record of one point).

    Raises
    ------
    InputError
        Naming ``where`` and the first inconsistency.
    """
    try:
        fields = {str(f.name): f for f in msg.fields}
    except (AttributeError, TypeError):
        raise InputError(f"{where}: PointCloud2 has no field list") from None
    missing = [n for n in "xyz" if n not in fields]
    if missing:
        raise InputError(
            f"{where}: PointCloud2 has no field(s) {', '.join(missing)} "
            f"(fields: {', '.join(fields) or 'none'})"
        )
    height, width = _int(msg, "height", where), _int(msg, "width", where)
    step, row_step = _int(msg, "point_step", where), _int(msg, "row_step", where)
    if step > MAX_POINT_STEP:
        raise InputError(f"{where}: PointCloud2 point_step {step} > {MAX_POINT_STEP} bytes")
    endian = ">" if getattr(msg, "is_bigendian", False) else "<"
    names, formats, offsets, spans = [], [], [], []
    for n in "xyz":
        f = fields[n]
        dtype_id, offset, count = (getattr(f, k, None) for k in ("datatype", "offset", "count"))
        if dtype_id not in _PF_TYPES:
            raise InputError(f"{where}: field {n!r} has unknown PointField datatype {dtype_id}")
        try:
            offset, count = int(offset), int(count if count is not None else 1)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{where}: field {n!r} has a non-integer offset or count") from None
        count = max(count, 1)
        end = offset + _PF_SIZES[dtype_id] * count
        if offset < 0 or count > MAX_POINT_STEP or end > step:
            raise InputError(
                f"{where}: field {n!r} (offset {offset}, count {count}, "
                f"{_PF_SIZES[dtype_id]}-byte values) does not fit point_step {step}"
            )
        names.append(n)
        formats.append(endian + _PF_TYPES[dtype_id])
        offsets.append(offset)
        spans.append((offset, offset + _PF_SIZES[dtype_id]))
    spans.sort()
    if any(a[1] > b[0] for a, b in itertools.pairwise(spans)):
        raise InputError(f"{where}: PointCloud2 fields x, y, z overlap (offsets {offsets})")
    row = row_step or width * step
    if row < width * step:
        raise InputError(
            f"{where}: PointCloud2 row_step {row} < width {width} × point_step {step}: rows overlap"
        )
    try:
        size = len(msg.data)
    except TypeError:
        raise InputError(f"{where}: PointCloud2 has no data buffer") from None
    need = (height - 1) * row + width * step if height and width else 0
    if size < need:
        raise InputError(
            f"{where}: PointCloud2 data has {size} bytes, too few for "
            f"{height}×{width} points of {step} bytes (row_step {row}: {need} bytes)"
        )
    dt = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    return {"height": height, "width": width, "point_step": step, "row_step": row, "dtype": dt}


def decode_pointcloud2(msg: Any, *, where: str = "PointCloud2") -> np.ndarray:
    """Decode the ``x, y, z`` fields of a ``sensor_msgs/PointCloud2`` message.

    The layout is checked first (:func:`pointcloud2_layout`); the data are then read in place
    (memory: the ``(N, 3)`` result).

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
        An inconsistent layout (see :func:`pointcloud2_layout`), or coordinates beyond
        :data:`relnav.io.pointclouds.ABSURD_COORDINATE` (bytes misread).
    """
    from relnav.io.pointclouds._common import _check_coordinates

    lay = pointcloud2_layout(msg, where=where)
    height, width = lay["height"], lay["width"]
    if height * width == 0:
        return np.zeros((0, 3))
    raw = msg.data
    if isinstance(raw, bytes | bytearray | memoryview):
        data = np.frombuffer(raw, dtype=np.uint8)
    else:  # rosbags gives a uint8 array; a list of ints works too
        data = np.ascontiguousarray(raw, dtype=np.uint8).reshape(-1)
    rec = np.ndarray(
        (height, width),
        dtype=lay["dtype"],
        buffer=data,
        strides=(lay["row_step"], lay["point_step"]),
    )
    pts = np.empty((height * width, 3))
    with np.errstate(all="ignore"):  # misread bytes: NaN/inf dropped, absurd values refused
        for j, c in enumerate("xyz"):
            pts[:, j] = rec[c].reshape(-1)
    ok = _check_coordinates(Path(where), pts)
    return pts[ok] if not ok.all() else pts


def _deserialize(reader: Any, raw: Any, con: Any, *, where: str) -> Any:
    """A message of the recording; InputError when its bytes do not deserialise."""
    try:
        return reader.deserialize(raw, con.msgtype)
    except Exception as e:  # rosbags raises its own types, struct.error, ValueError...
        raise InputError(f"{where}: cannot deserialise ({type(e).__name__}: {e})") from None


def _frame_id(msg: Any) -> str:
    return str(getattr(getattr(msg, "header", None), "frame_id", ""))


def _checked_stamps(
    path: Path, topic: str, stamps: list[tuple[float, int]], digests: list[bytes]
) -> list[tuple[float, int]]:
    """Sorted ``(stamp, message index)``: an exact duplicate message (same stamp, same bytes) is
    dropped with a warning; two different messages with one stamp, or a non-finite stamp, are
    an InputError (as equal times in a sequence folder)."""
    out: list[tuple[float, int]] = []
    dropped = 0
    for t, k in sorted(stamps):
        if not np.isfinite(t):
            raise InputError(f"{path} {topic}: message {k} has a non-finite header stamp")
        if out and t == out[-1][0]:
            if digests[k] == digests[out[-1][1]]:
                dropped += 1
                continue
            raise InputError(
                f"{path} {topic}: messages {out[-1][1]} and {k} have the same header stamp "
                f"{t!r} s but different content: scan times must increase"
            )
        out.append((t, k))
    if dropped:
        logger.warning(
            "%s %s: dropped %d duplicated message(s) (same stamp and bytes)", path, topic, dropped
        )
    return out


def _warn_frame_ids(path: Path, topic: str, frames: list[str | None]) -> None:
    """Warn when the messages of one topic name several frames (odometry assumes one sensor)."""
    named = [f for f in frames if f is not None]
    distinct = sorted(set(named))
    if len(distinct) > 1:
        counts = ", ".join(f"{f or '(empty)'} ×{named.count(f)}" for f in distinct[:5])
        logger.warning(
            "%s %s: messages name %d different frame_ids (%s): odometry treats them as one sensor",
            path,
            topic,
            len(distinct),
            counts,
        )


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
                stamps, frames, digests = [], [], []
                for k, (con, t_ns, raw) in enumerate(r.messages(connections=cons)):
                    try:
                        msg = _deserialize(r, raw, con, where=f"{self._path} {topic} #{k}")
                    except InputError:  # kept: its frame is flagged when read
                        msg = None
                    stamps.append((_stamp_seconds(msg, t_ns), k))
                    frames.append(_frame_id(msg) if msg is not None else None)
                    digests.append(hashlib.blake2b(bytes(raw), digest_size=16).digest())
        except InputError:
            raise
        except Exception as e:  # rosbags raises its own error types per format
            raise InputError(
                f"{self._path}: cannot read recording ({type(e).__name__}: {e})"
            ) from None
        stamps = _checked_stamps(self._path, topic, stamps, digests)
        _warn_frame_ids(self._path, topic, frames)
        self._times = np.array([s for s, _ in stamps], dtype=np.float64)
        self._order = [k for _, k in stamps]  # sorted position → message index in the bag
        self._pos_of = {k: i for i, k in enumerate(self._order)}
        self._iter: Iterator[tuple[int, Scan | InputError]] | None = None
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

    def _stream(self) -> Iterator[tuple[int, Scan | InputError]]:
        """Every message of the topic as a scan, or the error that message raised: one bad
        message never ends the stream."""
        r = self._ctx
        cons = [c for c in r.connections if c.topic == self._topic]
        for k, (con, t_ns, raw) in enumerate(r.messages(connections=cons)):
            if k not in self._pos_of:  # a dropped duplicate
                continue
            where = f"{self._path} {self._topic} #{k}"
            try:
                msg = _deserialize(r, raw, con, where=where)
                pts = decode_pointcloud2(msg, where=where)
            except InputError as e:
                yield k, e
                continue
            frame = _frame_id(msg)
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
        try:
            for k, scan in self._iter:
                self._next_msg = k + 1
                if k == want:
                    if isinstance(scan, InputError):
                        raise scan
                    self._last = (k, scan)
                    return scan
        except InputError:
            raise
        except Exception as e:  # the recording itself broke mid-stream: reopened next time
            self._close()
            raise InputError(
                f"{self._path}: cannot read message {want} of {self._topic} "
                f"({type(e).__name__}: {e})"
            ) from None
        self._close()  # pragma: no cover - init counted the messages
        raise InputError(f"{self._path}: message {want} of {self._topic} is missing")

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
