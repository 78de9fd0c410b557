"""Run odometry over a whole sequence: :func:`run_sequence` and :class:`OdometryRun`."""

from __future__ import annotations

import contextlib
import csv
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from relnav._threads import limit_blas_threads
from relnav.errors import ConfigError, InputError
from relnav.odometry.odometry import MotionPrior, Odometry, OdometryStep
from relnav.odometry.tracker import TrackerEntry, capabilities_of
from relnav.registration.base import Registration
from relnav.scan import Scan

__all__ = [
    "DIAGNOSTIC_COLUMNS",
    "DIAGNOSTIC_STAGES",
    "OdometryRun",
    "diagnostic_row",
    "make_tracker",
    "run_sequence",
]

log = logging.getLogger(__name__)

DIAGNOSTIC_STAGES = ("resolution", "keypoints", "normals", "describe", "match", "group", "estimate")
"""Stage timings always present (ms, 0 when a method has no such stage) in ``diagnostics.csv``."""


@dataclass
class OdometryRun:
    """The output of :func:`run_sequence`.

    Attributes
    ----------
    method : str
        Method string.
    timestamps : (N,) float64
        Scan times, seconds.
    poses : (N, 4, 4) float64
        Estimated ``T_world_sensor`` (world = the ground truth's frame when the run started
        from the ground truth's first pose, i.e. the target frame for simulated sequences).
        Methods with a smoother (``relnav``) give their smoothed trajectory here; the online
        per-frame poses are :attr:`causal_poses`.
    steps : list[OdometryStep]
        Per-frame details (empty when the run streamed to disk with ``keep_steps=False``).
    options : dict
        The options the run used (method options, motion prior, initial pose source).
    used_prior : (N,) bool
        Frames that kept the motion prior.
    flagged : (N,) bool
        Frames whose status is neither ``first`` nor ``ok`` (``flagged`` steps are kept in the
        chain but not trusted; ``degenerate``/``failed`` ones kept the motion prior).
    frame_time_s : (N,) float64
        Wall-clock seconds per frame.
    paths : dict[str, Path]
        Files already written by a streamed run (``estimate``, ``diagnostics``; with a
        smoother also ``estimate_causal``).
    causal_poses : (N, 4, 4) float64, optional
        The pose the tracker returned at each frame's time, from that frame and the ones before
        only (what a real-time loop has); ``None`` when it equals :attr:`poses` (no smoother).
    """

    method: str
    timestamps: np.ndarray
    poses: np.ndarray
    steps: list[OdometryStep] = field(repr=False, default_factory=list)
    options: dict[str, Any] = field(default_factory=dict)
    used_prior: np.ndarray | None = field(repr=False, default=None)
    flagged: np.ndarray | None = field(repr=False, default=None)
    frame_time_s: np.ndarray | None = field(repr=False, default=None)
    paths: dict[str, Path] = field(default_factory=dict)
    causal_poses: np.ndarray | None = field(repr=False, default=None)
    #: each frame's step 1σ (N, 2) [translation m, rotation deg] (NaN where a step has none),
    #: or None when no step has one (trackers without a step covariance)
    step_sigma: np.ndarray | None = field(repr=False, default=None)

    @property
    def online_poses(self) -> np.ndarray:
        """The causal trajectory ``(N, 4, 4)``: :attr:`causal_poses`, or :attr:`poses` when
        the tracker has no smoother."""
        return self.poses if self.causal_poses is None else self.causal_poses

    @property
    def n_flagged(self) -> int:
        """Frames whose registration was not ``ok`` (flagged, or kept the motion prior)."""
        if self.flagged is not None:
            return int(np.count_nonzero(self.flagged))
        if self.steps:
            return sum(s.status not in ("ok", "first") for s in self.steps)
        return int(np.count_nonzero(self.used_prior)) if self.used_prior is not None else 0

    def _times(self) -> list[float]:
        if self.frame_time_s is not None:
            return [float(t) for t in self.frame_time_s[1:]]
        return [s.time_s for s in self.steps[1:]]

    @property
    def mean_time_ms(self) -> float:
        """Mean wall-clock time per registered frame (first frame excluded), ms."""
        times = self._times()
        return 1000.0 * float(np.mean(times)) if times else float("nan")

    @property
    def median_time_ms(self) -> float:
        """Median wall-clock time per registered frame, ms (robust to one-off JIT compilation)."""
        times = self._times()
        return 1000.0 * float(np.median(times)) if times else float("nan")

    def status_counts(self) -> dict[str, int]:
        """Frames per status; a streamed run reads its diagnostics file row by row (memory
        stays flat however long the run)."""
        from collections import Counter

        if not self.steps and "diagnostics" in self.paths and len(self.timestamps):
            with self.paths["diagnostics"].open(newline="") as f:
                return dict(Counter(str(r.get("status", "")) for r in csv.DictReader(f)))
        return dict(Counter(str(s.status) for s in self.steps))

    def diagnostics(self) -> list[dict[str, Any]]:
        """One row per frame: points, correspondences, inliers, status, stage times (ms)."""
        if not self.steps and "diagnostics" in self.paths and len(self.timestamps):
            with self.paths["diagnostics"].open(newline="") as f:
                return list(csv.DictReader(f))
        return [
            diagnostic_row(i, t, s)
            for i, (t, s) in enumerate(zip(self.timestamps, self.steps, strict=True))
        ]

    def write(self, out_dir: str | Path) -> dict[str, Path]:
        """Write ``estimate.tum`` and ``diagnostics.csv`` into ``out_dir`` (atomically: a
        temporary name, then a rename); returns the paths."""
        out = Path(out_dir)
        if self.paths and all(p.parent.resolve() == out.resolve() for p in self.paths.values()):
            return dict(self.paths)  # streamed there already
        rows = self.diagnostics()
        with _RunWriter(out) as w:
            for t, T, row in zip(self.timestamps, self.poses, rows, strict=True):
                w.add(float(t), T, row)
        paths = dict(w.paths)
        if self.causal_poses is not None:
            from relnav.io.trajectories import write_tum

            paths["estimate_causal"] = out / "estimate_causal.tum"
            write_tum(paths["estimate_causal"], self.timestamps, self.causal_poses)
        return paths


def diagnostic_row(i: int, t: float, s: OdometryStep) -> dict[str, Any]:
    """The ``diagnostics.csv`` row of frame ``i`` (time ``t``, s) from its step."""
    r = s.result
    row: dict[str, Any] = {
        "frame": i,
        "time": float(t),
        "n_points": s.n_points,
        "n_used": s.n_points if s.n_used is None else s.n_used,
        "budget_voxel_m": s.budget_voxel,
        "n_correspondences": r.n_correspondences if r else 0,
        "n_inliers": r.n_inliers if r else 0,
        "status": s.status,
        "used_prior": int(s.used_prior),
        "fitness": round(r.fitness, 6) if r else "",
        "inlier_rmse": r.inlier_rmse if r else "",
    }
    timings = r.timings if r else {}
    for stage in DIAGNOSTIC_STAGES:
        row[f"t_{stage}_ms"] = 1000.0 * timings.get(stage, 0.0)
    extra = sorted(set(timings) - set(DIAGNOSTIC_STAGES))
    row["t_other_ms"] = 1000.0 * sum(timings[k] for k in extra)
    row["t_frame_ms"] = 1000.0 * s.time_s
    info = r.info if r else {}
    row["step_sigma_t_m"] = info.get("step_sigma_t", "")
    row["step_sigma_r_deg"] = info.get("step_sigma_r_deg", "")
    row["message"] = r.message if r else ""
    return row


DIAGNOSTIC_COLUMNS = (
    "frame",
    "time",
    "n_points",
    "n_used",
    "budget_voxel_m",
    "n_correspondences",
    "n_inliers",
    "status",
    "used_prior",
    "fitness",
    "inlier_rmse",
    *(f"t_{stage}_ms" for stage in DIAGNOSTIC_STAGES),
    "t_other_ms",
    "t_frame_ms",
    "step_sigma_t_m",
    "step_sigma_r_deg",
    "message",
)
"""Columns of ``diagnostics.csv``, in order."""


class _RunWriter:
    """Stream ``estimate.tum`` and ``diagnostics.csv`` rows to temporary files as frames come
    (memory stays flat), renamed to their final names by :meth:`close` (a killed run leaves
    no file a later run trusts)."""

    def __init__(self, out_dir: str | Path) -> None:
        from relnav.atomic import remove_stale_temps, temp_name

        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self.paths = {
            "estimate": self.out / "estimate.tum",
            "diagnostics": self.out / "diagnostics.csv",
        }
        for p in self.paths.values():
            remove_stale_temps(p)
        self._tmp = {k: temp_name(p) for k, p in self.paths.items()}
        self._est = self._tmp["estimate"].open("w", encoding="ascii")
        try:
            self._diag = self._tmp["diagnostics"].open("w", newline="")
        except BaseException:
            self._est.close()
            self._tmp["estimate"].unlink(missing_ok=True)
            raise
        self._csv = csv.DictWriter(self._diag, fieldnames=list(DIAGNOSTIC_COLUMNS))
        self._csv.writeheader()

    def add(self, t: float, pose: np.ndarray, row: dict[str, Any]) -> None:
        """Append one frame (time s, ``T_world_sensor``, diagnostics row) and flush."""
        from relnav.geometry.rotations import matrix_to_quat

        q = matrix_to_quat(np.asarray(pose, dtype=np.float64)[:3, :3]).reshape(4)
        vals = [float(t), *np.asarray(pose, dtype=np.float64)[:3, 3].tolist(), *q.tolist()]
        with self._naming("estimate"):
            self._est.write(" ".join(map(repr, vals)) + "\n")
            self._est.flush()
        with self._naming("diagnostics"):
            self._csv.writerow(row)
            self._diag.flush()

    @contextlib.contextmanager
    def _naming(self, key: str) -> Iterator[None]:
        """An OSError without a file name (a failed write or flush: full disk) names the file
        being written (its final name)."""
        try:
            yield
        except OSError as e:
            if e.filename is None:
                e.filename = str(self.paths[key])
            raise

    def close(self) -> None:
        """Fsync and rename the files to their final names (on a failure, e.g. a full disk:
        the temporary files are deleted and the error raised)."""
        try:
            for key, f in (("estimate", self._est), ("diagnostics", self._diag)):
                with self._naming(key):
                    f.flush()
                    os.fsync(f.fileno())
                    f.close()
            for k, p in self.paths.items():
                os.replace(self._tmp[k], p)
        except BaseException:
            self.abort()
            raise

    def abort(self) -> None:
        """Close and delete the temporary files; never raises (it runs while another error,
        e.g. a full disk, is being reported)."""
        for f in (self._est, self._diag):
            try:
                f.close()
            except OSError:  # the buffered rows could not be flushed (full disk)
                pass
        for tmp in self._tmp.values():
            try:
                tmp.unlink(missing_ok=True)
            except OSError:  # pragma: no cover - a folder gone read-only meanwhile
                log.warning("could not remove %s", tmp)

    def __enter__(self) -> _RunWriter:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def make_tracker(
    method: str | Registration | TrackerEntry,
    *,
    initial_pose: np.ndarray | None = None,
    motion_prior: MotionPrior = "constant_velocity",
    **method_options: Any,
) -> Any:
    """The per-frame tracker for ``method``: a registered tracker or pairwise :class:`Odometry`.

    Parameters
    ----------
    method : str, Registration or TrackerEntry
        A registration method string or object (pairwise :class:`Odometry`), or a registered
        tracker (:func:`relnav.pipeline.registry.tracker_entry`; method names such as
        ``relnav`` are resolved to one by :mod:`relnav.pipeline`).
    initial_pose : (4, 4) float64, optional
        ``T_world_sensor`` of the first frame (identity by default).
    motion_prior : {"constant_velocity", "identity"}
        :class:`Odometry`'s prior (a registered tracker has its own motion model).
    **method_options
        Passed to the registration factory, :class:`Odometry` or the tracker's factory.

    Returns
    -------
    Tracker
        ``register_frame(scan) -> OdometryStep``, with its declared capabilities.

    Raises
    ------
    ConfigError
        Unknown method or bad options.
    """
    if isinstance(method, TrackerEntry):
        return method.build(initial_pose=initial_pose, **method_options)
    if isinstance(method, str):
        from relnav.registration import available_methods

        if method.partition(":")[0].strip().lower() not in available_methods():
            raise ConfigError(
                f"unknown registration method {method!r}: registered trackers (e.g. the "
                "navigator, 'relnav') and presets run through relnav.pipeline "
                "(run_sequence, OdometryPipeline); `relnav methods` lists every name"
            )
    return Odometry(method, initial_pose=initial_pose, motion_prior=motion_prior, **method_options)


def run_sequence(
    sequence: Sequence[Scan],
    method: str | Registration | TrackerEntry = "feature:hods+gcc+alphabeta",
    *,
    initial_pose: np.ndarray | str | None = "gt",
    motion_prior: MotionPrior = "constant_velocity",
    max_frames: int | None = None,
    progress: Callable[[int, OdometryStep], None] | None = None,
    blas_threads: int | None = 1,
    out: str | Path | None = None,
    keep_steps: bool = True,
    strict: bool = False,
    on_interrupt: str = "raise",
    **method_options: Any,
) -> OdometryRun:
    """Run frame-to-frame odometry over ``sequence``.

    Every option is validated before the first frame (:class:`relnav.errors.ConfigError`).

    Parameters
    ----------
    sequence : sequence of Scan
        E.g. a :class:`relnav.io.ScanSequence`; its ``gt_poses`` (if any) give the initial pose.
    method : str, Registration or TrackerEntry
        Registration method (``relnav methods`` lists them), or a registered tracker
        (:func:`relnav.pipeline.run_sequence` takes its name, e.g. ``relnav``).
    initial_pose : (4, 4) array, "gt", "identity" or None
        ``"gt"``: the ground truth's first pose when the sequence has one, else the identity.
    motion_prior : {"constant_velocity", "identity"}
        Step kept by frames whose registration is degenerate or failed.
    max_frames : int, optional
        Stop after this many frames (>= 0).
    progress : callable, optional
        Called as ``progress(i, step)`` after each frame (the CLI draws its progress bar with it).
    blas_threads : int or None
        BLAS threads during the run (default 1: small per-frame linear algebra is slower
        multi-threaded; see :mod:`relnav._threads`). ``None`` leaves the setting alone.
    out : str or Path, optional
        Stream ``estimate.tum`` and ``diagnostics.csv`` into this folder as frames come
        (temporary names, renamed when the run ends).
    keep_steps : bool
        Keep every :class:`OdometryStep` in memory (``False`` with ``out`` keeps memory flat
        over long runs: only poses, times and flags stay).
    strict : bool
        An unreadable scan (:class:`relnav.errors.InputError`) aborts the run. By default the
        frame is flagged ``failed`` with the reason and the run goes on.
    on_interrupt : {"raise", "stop"}
        On ``KeyboardInterrupt`` (Ctrl-C) during the frames: ``"raise"`` deletes the streamed
        files and re-raises; ``"stop"`` ends the run at the last estimated frame and returns it
        (``options["interrupted"]`` = ``{"at_frame", "of"}``; the smoother is not run).
    **method_options
        Passed to the registration factory; ``gate_rotation_deg``/``gate_translation`` and
        ``step_check``/``step_tolerance_m``/``step_tolerance_deg`` go to :class:`Odometry`.

    Returns
    -------
    OdometryRun
    """
    from relnav.odometry.options import check_max_frames, parse_initial_pose

    max_frames = check_max_frames(max_frames)
    initial_pose = parse_initial_pose(initial_pose)
    if on_interrupt not in ("raise", "stop"):
        raise ConfigError(f"on_interrupt must be 'raise' or 'stop', got {on_interrupt!r}")
    n = len(sequence) if max_frames is None else min(len(sequence), max_frames)
    if isinstance(initial_pose, str):
        gt = getattr(sequence, "gt_poses", None)
        T0 = np.asarray(gt[0], dtype=float) if (gt is not None and len(gt)) else None
        init_source = "gt" if T0 is not None else "identity"
    else:
        T0 = initial_pose
        init_source = "given" if T0 is not None else "identity"
    odo = make_tracker(method, initial_pose=T0, motion_prior=motion_prior, **method_options)
    caps = capabilities_of(odo)
    steps: list[OdometryStep] = []
    times = np.zeros(n)
    poses = np.zeros((n, 4, 4))
    used_prior = np.zeros(n, dtype=bool)
    flagged = np.zeros(n, dtype=bool)
    frame_time = np.zeros(n)
    sigma = np.full((n, 2), np.nan)
    writer = _RunWriter(out) if out is not None else None
    interrupted: int | None = None
    done = 0  # frames estimated and streamed
    try:
        with limit_blas_threads(blas_threads):
            for i in range(n):
                try:
                    scan = sequence[i]
                except InputError as e:
                    if strict or "skip_frame" not in caps:
                        raise
                    times[i] = _scan_time(sequence, i, times[i - 1] if i else 0.0)
                    step = odo.skip_frame(f"unreadable scan: {e}")
                else:
                    times[i] = scan.time if isinstance(scan, Scan) else float(i)
                    step = odo.register_frame(scan)
                poses[i] = step.pose
                used_prior[i] = step.used_prior
                flagged[i] = step.status not in ("ok", "first")
                frame_time[i] = step.time_s
                info = step.result.info if step.result is not None else {}
                sigma[i] = info.get("step_sigma_t", np.nan), info.get("step_sigma_r_deg", np.nan)
                if keep_steps:
                    steps.append(step)
                if writer is not None:
                    writer.add(times[i], step.pose, diagnostic_row(i, times[i], step))
                done = i + 1
                if progress is not None:
                    progress(i, step)
    except KeyboardInterrupt:
        if on_interrupt != "stop":
            if writer is not None:
                writer.abort()
            raise
        # the frames estimated and streamed are kept; a frame half done is dropped
        interrupted = k = done
        log.info("interrupted at frame %d of %d: keeping the %d frames estimated", k, n, k)
        if keep_steps:
            del steps[k:]
        times, poses, used_prior = times[:k], poses[:k], used_prior[:k]
        flagged, frame_time, sigma = flagged[:k], frame_time[:k], sigma[:k]
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    causal: np.ndarray | None = None
    if "smoother" in caps and n and interrupted is None:  # e.g. the navigator's smoother
        final = np.asarray(odo.finalize(), dtype=float)
        if final.shape == poses.shape and np.all(np.isfinite(final)):
            poses, causal = final, poses
    paths: dict[str, Path] = {}
    if writer is not None:
        writer.close()
        paths = dict(writer.paths)
        if causal is not None:  # the streamed rows were the online poses: kept beside
            from relnav.io.trajectories import write_tum

            os.replace(paths["estimate"], writer.out / "estimate_causal.tum")
            paths["estimate_causal"] = writer.out / "estimate_causal.tum"
            write_tum(paths["estimate"], times, poses)
    if isinstance(method, str | TrackerEntry):
        name = method if isinstance(method, str) else method.name
    else:
        name = getattr(method, "name", type(method).__name__)
    checker = odo.step_checker if "step_check" in caps else None
    meta: dict[str, Any] = {
        "motion_prior": motion_prior,
        "initial_pose": init_source,
        "method_options": method_options,
        "step_check": checker.mode if checker is not None else "off",
    }
    # what the tracker decided at the end
    if "final_report" in caps and n and interrupted is None and (report := odo.final_report()):
        meta["finalize"] = report
    if interrupted is not None:
        meta["interrupted"] = {"at_frame": interrupted, "of": n}
    run = OdometryRun(
        name,
        times,
        poses,
        steps,
        meta,
        used_prior=used_prior,
        flagged=flagged,
        frame_time_s=frame_time,
        paths=paths,
        causal_poses=causal,
        step_sigma=sigma if np.isfinite(sigma).any() else None,
    )
    if run.n_flagged:
        log.info(
            "%d of %d frames flagged (%d kept the motion prior)",
            run.n_flagged,
            n,
            int(np.count_nonzero(used_prior)),
        )
    return run


def _scan_time(sequence: Sequence[Scan], i: int, previous: float) -> float:
    """Time of scan ``i`` without reading it (its file may be unreadable), seconds."""
    stamps = getattr(sequence, "timestamps", None)
    try:
        return float(stamps[i]) if stamps is not None else float(i)
    except (IndexError, TypeError, ValueError):
        return previous
