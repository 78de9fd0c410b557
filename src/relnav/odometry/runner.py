"""Run odometry over a whole sequence: :func:`run_sequence` and :class:`OdometryRun`."""

from __future__ import annotations

import csv
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from relnav._threads import limit_blas_threads
from relnav.odometry.odometry import MotionPrior, Odometry, OdometryStep
from relnav.registration.base import Registration
from relnav.types import Scan

__all__ = ["DIAGNOSTIC_STAGES", "NAVIGATOR_METHOD", "OdometryRun", "make_tracker", "run_sequence"]

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
        per-frame poses stay in ``steps[k].pose``.
    steps : list[OdometryStep]
        Per-frame details.
    options : dict
        The options the run used (method options, motion prior, initial pose source).
    """

    method: str
    timestamps: np.ndarray
    poses: np.ndarray
    steps: list[OdometryStep] = field(repr=False, default_factory=list)
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def n_flagged(self) -> int:
        """Frames whose registration was not ``ok`` (they kept the motion prior)."""
        return sum(s.used_prior for s in self.steps)

    @property
    def mean_time_ms(self) -> float:
        """Mean wall-clock time per registered frame (first frame excluded), ms."""
        times = [s.time_s for s in self.steps[1:]]
        return 1000.0 * float(np.mean(times)) if times else float("nan")

    @property
    def median_time_ms(self) -> float:
        """Median wall-clock time per registered frame, ms (robust to one-off JIT compilation)."""
        times = [s.time_s for s in self.steps[1:]]
        return 1000.0 * float(np.median(times)) if times else float("nan")

    def diagnostics(self) -> list[dict[str, Any]]:
        """One row per frame: points, correspondences, inliers, status, stage times (ms)."""
        rows = []
        for i, (t, s) in enumerate(zip(self.timestamps, self.steps, strict=True)):
            r = s.result
            row: dict[str, Any] = {
                "frame": i,
                "time": float(t),
                "n_points": s.n_points,
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
            row["message"] = r.message if r else ""
            rows.append(row)
        return rows

    def write(self, out_dir: str | Path) -> dict[str, Path]:
        """Write ``estimate.tum`` and ``diagnostics.csv`` into ``out_dir``; returns the paths."""
        from relnav.io.trajectories import write_tum

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        est = out / "estimate.tum"
        write_tum(est, self.timestamps, self.poses)
        diag = out / "diagnostics.csv"
        rows = self.diagnostics()
        with diag.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["frame"])
            w.writeheader()
            w.writerows(rows)
        return {"estimate": est, "diagnostics": diag}


NAVIGATOR_METHOD = "relnav"
"""The method string of relnav's own frame-to-model navigator (:mod:`relnav.navigation`)."""


def make_tracker(
    method: str | Registration,
    *,
    initial_pose: np.ndarray | None = None,
    motion_prior: MotionPrior = "constant_velocity",
    **method_options: Any,
) -> Any:
    """The per-frame tracker for ``method``: relnav's navigator or pairwise :class:`Odometry`.

    Both have ``register_frame(scan) -> OdometryStep``.
    """
    if isinstance(method, str) and method.strip().lower() == NAVIGATOR_METHOD:
        from relnav.navigation import Navigator

        return Navigator(initial_pose=initial_pose, **method_options)
    return Odometry(method, initial_pose=initial_pose, motion_prior=motion_prior, **method_options)


def run_sequence(
    sequence: Sequence[Scan],
    method: str | Registration = "feature:hods+gcc+alphabeta",
    *,
    initial_pose: np.ndarray | str | None = "gt",
    motion_prior: MotionPrior = "constant_velocity",
    max_frames: int | None = None,
    progress: Callable[[int, OdometryStep], None] | None = None,
    blas_threads: int | None = 1,
    **method_options: Any,
) -> OdometryRun:
    """Run frame-to-frame odometry over ``sequence``.

    Parameters
    ----------
    sequence : sequence of Scan
        E.g. a :class:`relnav.io.ScanSequence`; its ``gt_poses`` (if any) give the initial pose.
    method : str or Registration
        Registration method (``relnav methods`` lists them).
    initial_pose : (4, 4) array, "gt" or None
        ``"gt"``: the ground truth's first pose when the sequence has one, else the identity.
    motion_prior : {"constant_velocity", "identity"}
        Step kept by frames whose registration is degenerate or failed.
    max_frames : int, optional
        Stop after this many frames.
    progress : callable, optional
        Called as ``progress(i, step)`` after each frame (the CLI draws its progress bar with it).
    blas_threads : int or None
        BLAS threads during the run (default 1: small per-frame linear algebra is slower
        multi-threaded; see :mod:`relnav._threads`). ``None`` leaves the setting alone.
    **method_options
        Passed to the registration factory.

    Returns
    -------
    OdometryRun
    """
    n = len(sequence) if max_frames is None else min(len(sequence), int(max_frames))
    gt = getattr(sequence, "gt_poses", None)
    if isinstance(initial_pose, str):
        T0 = np.asarray(gt[0], dtype=float) if (initial_pose == "gt" and gt is not None) else None
        init_source = "gt" if T0 is not None else "identity"
    else:
        T0 = None if initial_pose is None else np.asarray(initial_pose, dtype=float)
        init_source = "given" if T0 is not None else "identity"
    odo = make_tracker(method, initial_pose=T0, motion_prior=motion_prior, **method_options)
    steps: list[OdometryStep] = []
    times = np.zeros(n)
    with limit_blas_threads(blas_threads):
        for i in range(n):
            scan = sequence[i]
            times[i] = scan.time if isinstance(scan, Scan) else float(i)
            step = odo.register_frame(scan)
            steps.append(step)
            if progress is not None:
                progress(i, step)
    poses = np.stack([s.pose for s in steps]) if steps else np.zeros((0, 4, 4))
    finalize = getattr(odo, "finalize", None)
    if callable(finalize) and steps:  # e.g. the navigator's fixed-lag smoother
        smoothed = np.asarray(finalize(), dtype=float)
        if smoothed.shape == poses.shape and np.all(np.isfinite(smoothed)):
            poses = smoothed
    name = method if isinstance(method, str) else getattr(method, "name", type(method).__name__)
    run = OdometryRun(
        name,
        times,
        poses,
        steps,
        {
            "motion_prior": motion_prior,
            "initial_pose": init_source,
            "method_options": method_options,
        },
    )
    if run.n_flagged:
        log.info("%d of %d frames kept the motion prior", run.n_flagged, n)
    return run
