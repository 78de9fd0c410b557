"""Sequence folders (DESIGN §5): read lazily with :class:`ScanSequence`, write with
:class:`SequenceWriter` / :func:`write_sequence`.

Layout (only ``scans/`` is required)::

    SEQ/scans/000000.ply ...          primary sensor scans (any supported point format)
    SEQ/timestamps.txt                one float per line, seconds
    SEQ/gt_T_target_sensor.tum        ground truth T_target_sensor per scan (TUM)
    SEQ/sensor.yaml                   sensor metadata
    SEQ/scenario.yaml                 resolved scenario (seed, package version)
    SEQ/scans_<name>/ ... SEQ/timestamps_<name>.txt, SEQ/gt_T_target_sensor_<name>.tum,
    SEQ/sensor_<name>.yaml            a second sensor ``<name>`` (paper 2)

Scan points are in the sensor frame. **[interpretation]** Scan files are ordered by *natural*
name order (``scan2`` before ``scan10``), identical to plain sorting for zero-padded names; files
with other extensions in ``scans/`` are ignored with a warning, hidden files (``.name``: the
temporary names of scans being written) silently. Scan times must increase strictly. When
``timestamps.txt`` is absent the scan times come from the ground-truth TUM file if it has one
row per scan, else they are ``0, 1, 2, ...``.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from relnav.atomic import atomic_write_text
from relnav.config import dump_yaml, load_yaml
from relnav.errors import ConfigError, InputError
from relnav.io.pointclouds import POINT_READ_EXTENSIONS, POINT_WRITE_EXTENSIONS, read_scan
from relnav.io.pointclouds import write_points as _write_points
from relnav.io.text import read_text_file
from relnav.io.trajectories import read_tum, write_tum
from relnav.scan import Scan

__all__ = [
    "ScanSequence",
    "SequenceLayout",
    "SequenceWriter",
    "sequence_layout",
    "write_sequence",
]

logger = logging.getLogger("relnav.io")

_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


@dataclass(frozen=True)
class SequenceLayout:
    """Paths of one sensor's files in a sequence folder.

    Attributes
    ----------
    folder : Path
        The sequence folder.
    sensor : str
        ``""`` for the primary sensor, else the second sensor's name.
    scans_dir, timestamps, gt, sensor_yaml, scenario_yaml : Path
        ``scans[_name]/``, ``timestamps[_name].txt``, ``gt_T_target_sensor[_name].tum``,
        ``sensor[_name].yaml`` and the shared ``scenario.yaml``.
    """

    folder: Path
    sensor: str
    scans_dir: Path
    timestamps: Path
    gt: Path
    sensor_yaml: Path
    scenario_yaml: Path


def _check_sensor(sensor: str | None) -> str:
    name = sensor or ""
    if name and not _NAME_RE.match(name):
        raise InputError(
            f"invalid sensor name {name!r}: use letters, digits, '_', '-' or '.' "
            "(it becomes part of folder names)"
        )
    return name


def sequence_layout(folder: str | Path, sensor: str | None = None) -> SequenceLayout:
    """Paths of the files of ``sensor`` (``None``/``""`` = primary) in sequence ``folder``."""
    f = Path(folder)
    name = _check_sensor(sensor)
    sfx = f"_{name}" if name else ""
    return SequenceLayout(
        folder=f,
        sensor=name,
        scans_dir=f / f"scans{sfx}",
        timestamps=f / f"timestamps{sfx}.txt",
        gt=f / f"gt_T_target_sensor{sfx}.tum",
        sensor_yaml=f / f"sensor{sfx}.yaml",
        scenario_yaml=f / "scenario.yaml",
    )


def _natural_key(name: str) -> list[Any]:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _scan_files(d: Path) -> list[Path]:
    files = [
        q
        for q in d.iterdir()
        if q.is_file() and q.suffix.lower() in POINT_READ_EXTENSIONS and not q.name.startswith(".")
    ]
    return sorted(files, key=lambda q: (_natural_key(q.name), q.name))


def _read_yaml(p: Path) -> dict[str, Any]:
    try:
        return load_yaml(p)
    except ConfigError as e:
        raise InputError(str(e)) from None


def _read_timestamps(p: Path) -> np.ndarray:
    vals: list[float] = []
    for no, line in enumerate(read_text_file(p, what="timestamps").splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        try:
            v = float(s.split()[0].rstrip(","))
        except ValueError:
            raise InputError(f"{p}: line {no}: not a number: {s[:40]!r}") from None
        if not np.isfinite(v):
            raise InputError(f"{p}: line {no}: NaN or infinite timestamp")
        vals.append(v)
    return np.asarray(vals, dtype=np.float64)


def _check_increasing(t: np.ndarray, source: Path) -> None:
    """InputError naming the first scan time that is not after the previous one."""
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        kind = "duplicate" if t[k] == t[k - 1] else "decreasing"
        raise InputError(
            f"{source}: scan times must increase: {kind} time {float(t[k])!r} s at scan {k} "
            f"(previous {float(t[k - 1])!r} s; {bad.size} such scans)"
        )


def _warn_ignored(d: Path, n: int) -> None:
    """Warn about files of ``d`` that are not scans (unsupported extensions) or no scans."""
    other = sorted(
        q.suffix.lower() or q.name
        for q in d.iterdir()
        if q.is_file()
        and q.suffix.lower() not in POINT_READ_EXTENSIONS
        and not q.name.startswith(".")
    )
    if other:
        kinds = ", ".join(sorted(set(other)))
        logger.warning(
            "%s: ignoring %d files that are not scans (%s); scan extensions: %s",
            d,
            len(other),
            kinds,
            " ".join(POINT_READ_EXTENSIONS),
        )
    if n == 0:
        logger.warning("%s: no scan files found", d)


def _to_builtin(x: Any) -> Any:
    """Recursively turn NumPy scalars/arrays, tuples and Paths into YAML-safe builtins."""
    if isinstance(x, dict):
        return {str(k): _to_builtin(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_to_builtin(v) for v in x]
    if isinstance(x, np.ndarray):
        return _to_builtin(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, Path):
        return str(x)
    return x


class ScanSequence:
    """Lazy reader of one sensor's scans in a sequence folder.

    Parameters
    ----------
    folder : str or Path
        Sequence folder (see the module docstring for the layout).
    sensor : str, optional
        ``None`` for the primary sensor (``scans/``), or a name such as ``"kinect"`` for
        ``scans_kinect/``.

    Notes
    -----
    Only file names, ``timestamps[_name].txt`` and ``sensor[_name].yaml`` are read on
    construction; a scan file is read by each ``seq[i]`` (nothing is cached, so memory stays
    flat over long sequences) and the ground truth on first access to :attr:`gt_poses`.

    Examples
    --------
    >>> seq = ScanSequence("out/seq")  # doctest: +SKIP
    >>> scan = seq[0]; scan.points.shape, scan.time  # doctest: +SKIP
    """

    def __init__(self, folder: str | Path, sensor: str | None = None) -> None:
        self._layout = sequence_layout(folder, sensor)
        lay = self._layout
        if not lay.folder.is_dir():
            raise InputError(f"{lay.folder}: no such sequence folder")
        if not lay.scans_dir.is_dir():
            avail = ScanSequence.sensors(lay.folder)
            hint = f"; sensors present: {avail}" if avail else ""
            raise InputError(f"{lay.scans_dir}: missing scans folder{hint}")
        self._files = _scan_files(lay.scans_dir)
        n = len(self._files)
        _warn_ignored(lay.scans_dir, n)
        self._meta = _read_yaml(lay.sensor_yaml) if lay.sensor_yaml.is_file() else {}
        self._gt: np.ndarray | None = None
        self._gt_loaded = False
        self._times: np.ndarray | None = None
        if lay.timestamps.is_file():
            t = _read_timestamps(lay.timestamps)
            if t.shape[0] != n:
                raise InputError(
                    f"{lay.timestamps}: {t.shape[0]} timestamps for {n} scans in {lay.scans_dir}"
                )
            _check_increasing(t, lay.timestamps)
            self._times = t
        self._times_from_file = self._times is not None
        self._times_assumed = False

    # --- metadata --------------------------------------------------------------------------

    @property
    def folder(self) -> Path:
        """The sequence folder."""
        return self._layout.folder

    @property
    def sensor(self) -> str:
        """Sensor name, ``""`` for the primary sensor."""
        return self._layout.sensor

    @property
    def layout(self) -> SequenceLayout:
        """Paths of this sensor's files."""
        return self._layout

    @property
    def files(self) -> list[Path]:
        """Scan files in reading order."""
        return list(self._files)

    @property
    def timestamps(self) -> np.ndarray:
        """Scan times ``(N,)``, seconds (``timestamps.txt``, else the GT file, else ``i``)."""
        return self._scan_times().copy()

    def _scan_times(self) -> np.ndarray:
        if self._times is None:
            n = len(self._files)
            times = np.arange(n, dtype=np.float64)
            self._times_assumed = True
            if self._layout.gt.is_file():
                try:
                    t, _ = read_tum(self._layout.gt)
                except InputError as e:
                    logger.warning("ignoring ground-truth times: %s", e)
                else:
                    if t.shape[0] == n:
                        _check_increasing(t, self._layout.gt)
                        times, self._times_assumed = t, False
            self._times = times
            self._times_from_file = False
        return self._times

    @property
    def times_assumed(self) -> bool:
        """True when no file gives the scan times (neither ``timestamps.txt`` nor the ground
        truth): they are ``0, 1, 2, …`` s, or what :meth:`set_time_spacing` set."""
        self._scan_times()
        return self._times_assumed

    def set_time_spacing(self, dt: float) -> None:
        """Scan times ``0, dt, 2·dt, …`` (seconds) for a sequence without times of its own."""
        if not self.times_assumed:
            raise InputError(f"{self.folder}: the scans have times of their own (--dt/--rate)")
        self._times = np.arange(len(self._files), dtype=np.float64) * float(dt)

    @property
    def gt_poses(self) -> np.ndarray | None:
        """Ground truth ``T_target_sensor`` per scan ``(N, 4, 4)``, or ``None`` without a GT file.

        Raises
        ------
        InputError
            The GT file is malformed or its row count differs from the number of scans.
        """
        if not self._gt_loaded:
            gt_path = self._layout.gt
            if gt_path.is_file():
                t, poses = read_tum(gt_path)
                n = len(self._files)
                if poses.shape[0] != n:
                    raise InputError(f"{gt_path}: {poses.shape[0]} poses for {n} scans")
                if self._times_from_file and n and np.max(np.abs(t - self._times)) > 1e-6:
                    logger.warning(
                        "%s: ground-truth times differ from %s by up to %.3g s",
                        gt_path,
                        self._layout.timestamps.name,
                        float(np.max(np.abs(t - self._times))),
                    )
                self._gt = poses
            self._gt_loaded = True
        return None if self._gt is None else self._gt.copy()

    @property
    def sensor_meta(self) -> dict[str, Any]:
        """Sensor metadata from ``sensor[_name].yaml`` (``{}`` when absent)."""
        return dict(self._meta)

    @property
    def scenario(self) -> dict[str, Any] | None:
        """The resolved scenario from ``scenario.yaml``, or ``None`` when absent."""
        p = self._layout.scenario_yaml
        return _read_yaml(p) if p.is_file() else None

    @staticmethod
    def sensors(folder: str | Path) -> list[str]:
        """Sensors present in ``folder``: ``""`` for ``scans/`` then the ``<name>`` of each
        ``scans_<name>/`` (sorted)."""
        f = Path(folder)
        if not f.is_dir():
            raise InputError(f"{f}: no such sequence folder")
        out = [""] if (f / "scans").is_dir() else []
        names = sorted(
            d.name[len("scans_") :]
            for d in f.iterdir()
            if d.is_dir() and d.name.startswith("scans_") and len(d.name) > len("scans_")
        )
        return out + names

    # --- sequence protocol -----------------------------------------------------------------

    def __len__(self) -> int:
        return len(self._files)

    def __getitem__(self, i: int) -> Scan:
        if isinstance(i, bool) or not isinstance(i, int | np.integer):
            raise TypeError(f"ScanSequence indices must be integers, not {type(i).__name__}")
        n = len(self._files)
        k = int(i) + n if i < 0 else int(i)
        if not 0 <= k < n:
            raise IndexError(f"scan index {i} out of range for {n} scans")
        return read_scan(self._files[k], time=float(self._scan_times()[k]), sensor=self._meta)

    def __iter__(self) -> Iterator[Scan]:
        times = self._scan_times()
        for k, f in enumerate(self._files):
            yield read_scan(f, time=float(times[k]), sensor=self._meta)

    def __repr__(self) -> str:
        s = f", sensor={self.sensor!r}" if self.sensor else ""
        return f"ScanSequence({str(self.folder)!r}{s}, n={len(self)})"


class SequenceWriter:
    """Stream scans of one sensor into a sequence folder.

    Parameters
    ----------
    folder : str or Path
        Sequence folder (created if needed).
    sensor : str, optional
        ``None`` for the primary sensor (``scans/``), else the name of a second sensor.
    fmt : str
        Scan file format: an extension from :data:`relnav.io.POINT_WRITE_EXTENSIONS`
        without the dot (``"ply"``, ``"npy"``...).
    sensor_meta : dict, optional
        Written to ``sensor[_name].yaml`` on :meth:`close`.
    binary : bool
        Binary or ASCII PLY/PCD.
    overwrite : bool
        **[interpretation]** An existing non-empty ``scans[_name]/`` is an error unless this is
        true; then its scan files and this sensor's timestamps/GT files are deleted first, so a
        shorter rerun cannot leave stale frames behind.

    Examples
    --------
    >>> with SequenceWriter("out/seq", sensor_meta={"model": "flash"}) as w:  # doctest: +SKIP
    ...     w.add(points, time=0.0, T_target_sensor=T)
    ...     w.close(scenario={"seed": 1})
    """

    def __init__(
        self,
        folder: str | Path,
        *,
        sensor: str | None = None,
        fmt: str = "ply",
        sensor_meta: dict[str, Any] | None = None,
        binary: bool = True,
        overwrite: bool = False,
    ) -> None:
        ext = "." + str(fmt).lower().lstrip(".")
        if ext not in POINT_WRITE_EXTENSIONS:
            raise ConfigError(
                f"unknown scan format {fmt!r}; choose one of "
                f"{', '.join(e[1:] for e in POINT_WRITE_EXTENSIONS)}"
            )
        self._layout = sequence_layout(folder, sensor)
        lay = self._layout
        if lay.scans_dir.is_dir():
            old = _scan_files(lay.scans_dir)
            if old and not overwrite:
                raise InputError(
                    f"{lay.scans_dir}: already holds {len(old)} scan files "
                    "(pass overwrite=True, or --overwrite on the command line, to replace them)"
                )
            for q in old:
                q.unlink()
            if old:
                for q in (lay.timestamps, lay.gt):
                    q.unlink(missing_ok=True)
                logger.info("%s: removed %d old scan files", lay.scans_dir, len(old))
        lay.scans_dir.mkdir(parents=True, exist_ok=True)
        self._ext = ext
        self._binary = binary
        self._meta = None if sensor_meta is None else _to_builtin(dict(sensor_meta))
        self._times: list[float] = []
        self._poses: list[np.ndarray | None] = []
        self._closed = False

    @property
    def folder(self) -> Path:
        """The sequence folder."""
        return self._layout.folder

    @property
    def sensor(self) -> str:
        """Sensor name, ``""`` for the primary sensor."""
        return self._layout.sensor

    @property
    def n_frames(self) -> int:
        """Number of scans added so far."""
        return len(self._times)

    def add(
        self,
        points: np.ndarray | Scan,
        time: float | None = None,
        T_target_sensor: np.ndarray | None = None,
        *,
        intensity: np.ndarray | None = None,
    ) -> Path:
        """Write one scan now, as ``scans[_name]/{i:06d}.{fmt}``.

        Parameters
        ----------
        points : (N, 3) array_like or Scan
            Points in the sensor frame, metres. A :class:`Scan` also gives its intensity,
            per-point timestamps and (when ``time`` is ``None``) its time.
        time : float, optional
            Scan time in seconds; default the scan's time, or the frame index for an array.
        T_target_sensor : (4, 4) array_like, optional
            Ground-truth pose of the sensor in the target frame at ``time``.
        intensity : (N,) array_like, optional
            Per-point intensity (overrides a Scan's).

        Returns
        -------
        Path
            The scan file written.
        """
        if self._closed:
            raise InputError(f"{self._layout.scans_dir}: SequenceWriter is closed")
        per_point_t = None
        if isinstance(points, Scan):
            if time is None:
                time = points.time
            if intensity is None:
                intensity = points.intensity
            per_point_t = points.timestamps
            points = points.points
        k = len(self._times)
        t = float(k) if time is None else float(time)
        if not np.isfinite(t):
            raise InputError(f"frame {k}: scan time is NaN or infinite")
        if self._times and t <= self._times[-1]:
            logger.warning(
                "frame %d: time %.9g s is not after the previous %.9g s", k, t, self._times[-1]
            )
        pose = None
        if T_target_sensor is not None:
            pose = np.asarray(T_target_sensor, dtype=np.float64)
            if pose.shape != (4, 4) or not np.isfinite(pose).all():
                raise InputError(f"frame {k}: T_target_sensor must be a finite (4, 4) matrix")
        path = self._layout.scans_dir / f"{k:06d}{self._ext}"
        tmp = path.with_name(f".{k:06d}.{os.getpid()}.tmp{self._ext}")  # hidden: not a scan
        try:
            _write_points(
                tmp, points, intensity=intensity, timestamps=per_point_t, binary=self._binary
            )
            os.replace(tmp, path)  # a killed writer never leaves a half-written scan
        finally:
            tmp.unlink(missing_ok=True)
        self._times.append(t)
        self._poses.append(pose)
        return path

    def close(self, scenario: dict[str, Any] | None = None) -> None:
        """Write timestamps, ground truth (only when every frame had a pose), sensor and
        scenario YAML. Calling it again only (re)writes ``scenario`` if given."""
        lay = self._layout
        if scenario is not None:
            dump_yaml(_to_builtin(dict(scenario)), lay.scenario_yaml)
        if self._closed:
            return
        self._closed = True
        atomic_write_text(lay.timestamps, "".join(f"{t!r}\n" for t in self._times), "ascii")
        have = [q is not None for q in self._poses]
        if self._poses and all(have):
            write_tum(lay.gt, np.asarray(self._times), np.stack(self._poses))  # type: ignore[arg-type]
        elif any(have):
            logger.warning(
                "%s: only %d of %d frames have a ground-truth pose; no GT file written",
                lay.folder,
                sum(have),
                len(have),
            )
        if self._meta is not None:
            dump_yaml(self._meta, lay.sensor_yaml)
        logger.info("%s: wrote %d scans", lay.scans_dir, len(self._times))

    def __enter__(self) -> SequenceWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def write_sequence(
    folder: str | Path,
    scans: Iterable[np.ndarray | Scan],
    timestamps: Sequence[float] | np.ndarray | None,
    *,
    gt_poses: np.ndarray | Sequence[np.ndarray] | None = None,
    sensor_meta: dict[str, Any] | None = None,
    scenario: dict[str, Any] | None = None,
    sensor: str | None = None,
    fmt: str = "ply",
    binary: bool = True,
    overwrite: bool = False,
) -> Path:
    """Write a whole sequence at once (see :class:`SequenceWriter`).

    Parameters
    ----------
    folder : str or Path
        Sequence folder.
    scans : iterable of (N_i, 3) arrays or Scans
        Points in the sensor frame; consumed one at a time (a :class:`ScanSequence` works,
        e.g. to convert a folder to another format).
    timestamps : (M,) array_like or None
        Scan times in seconds; ``None`` uses each Scan's time (or the index).
    gt_poses : (M, 4, 4) array_like, optional
        Ground truth ``T_target_sensor`` per scan.
    sensor_meta, scenario, sensor, fmt, binary, overwrite
        As for :class:`SequenceWriter`.

    Returns
    -------
    Path
        The sequence folder.
    """
    n_expected = len(scans) if hasattr(scans, "__len__") else None  # type: ignore[arg-type]
    for name, arr in (("timestamps", timestamps), ("ground-truth poses", gt_poses)):
        if arr is not None and n_expected is not None and len(arr) != n_expected:
            raise InputError(f"{folder}: {len(arr)} {name} for {n_expected} scans")
    with SequenceWriter(
        folder,
        sensor=sensor,
        fmt=fmt,
        sensor_meta=sensor_meta,
        binary=binary,
        overwrite=overwrite,
    ) as w:
        for k, s in enumerate(scans):  # streamed: a ScanSequence is read one scan at a time
            if (timestamps is not None and k >= len(timestamps)) or (
                gt_poses is not None and k >= len(gt_poses)
            ):
                raise InputError(f"{folder}: more scans than timestamps/ground-truth poses")
            w.add(
                s,
                None if timestamps is None else float(timestamps[k]),
                None if gt_poses is None else gt_poses[k],
            )
        for name, arr in (("timestamps", timestamps), ("ground-truth poses", gt_poses)):
            if arr is not None and len(arr) != w.n_frames:
                raise InputError(f"{folder}: {len(arr)} {name} for {w.n_frames} scans")
        w.close(scenario=scenario)
    return Path(folder)
