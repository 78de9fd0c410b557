"""Export a sequence (and estimates) to a Rerun recording (``.rrd``), extra ``[viz]``.

Open the file with the Rerun viewer (``rerun FILE.rrd``): each scan is shown in the target
frame at its ground-truth pose (or the sensor frame when there is none), with the ground-truth
and estimated sensor trajectories, on a ``frame`` timeline.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relnav.errors import ConfigError

__all__ = ["LiveViewer", "export_rrd"]


def _rerun():
    try:
        import rerun as rr
    except ImportError:
        raise ConfigError(
            "writing .rrd files needs the optional dependency rerun-sdk: pip install 'relnav[viz]'"
        ) from None
    return rr


def _set_frame(rr, k: int) -> None:
    if hasattr(rr, "set_time"):  # rerun >= 0.23
        rr.set_time("frame", sequence=k)
    else:  # pragma: no cover - older rerun
        rr.set_time_sequence("frame", k)


def export_rrd(
    seq_dir: str | Path,
    out: str | Path,
    *,
    estimates: dict[str, np.ndarray] | None = None,
    sensor: str | None = None,
    max_frames: int | None = None,
    live: bool = False,
) -> Path | None:
    """Write ``seq_dir``'s scans and trajectories to the Rerun recording ``out``.

    With ``live=True`` they are streamed to a spawned Rerun viewer instead; on a machine
    without a display (or without the viewer) the recording is written to ``out`` as usual.
    Returns the file written, or ``None`` when streamed to a viewer.

    Parameters
    ----------
    seq_dir : path
        Sequence folder (:class:`relnav.io.ScanSequence`).
    out : path
        ``.rrd`` file to write.
    estimates : dict[str, (N, 4, 4)], optional
        Estimated ``T_target_sensor`` trajectories by name, drawn beside the ground truth.
    sensor : str, optional
        Second sensor's name (``scans_<name>/``).
    max_frames : int, optional
        Export only the first frames.
    live : bool
        Stream to a viewer (``relnav view SEQ --live``).
    """
    from relnav.geometry.se3 import transform_points
    from relnav.io.sequences import ScanSequence

    rr = _rerun()
    seq = ScanSequence(seq_dir, sensor=sensor)
    n = len(seq) if max_frames is None else min(len(seq), max_frames)
    gt = seq.gt_poses
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rr.init("relnav", spawn=False)
    streamed = False
    if live and _has_display():
        try:
            rr.spawn()
            streamed = True
        except Exception as e:  # no viewer binary
            import logging

            logging.getLogger(__name__).warning(
                "cannot spawn the Rerun viewer (%s): writing %s", e, out
            )
    if not streamed:
        rr.save(str(out))
    if gt is not None:
        rr.log("trajectory/ground_truth", rr.LineStrips3D([gt[:n, :3, 3]]), static=True)
    for name, poses in (estimates or {}).items():
        rr.log(f"trajectory/{name}", rr.LineStrips3D([np.asarray(poses)[:n, :3, 3]]), static=True)
    for k in range(n):
        _set_frame(rr, k)
        pts = seq[k].points
        if gt is not None:
            pts = transform_points(gt[k], pts)
            rr.log("sensor", rr.Points3D(gt[k : k + 1, :3, 3], radii=0.05))
        rr.log("scan", rr.Points3D(pts, radii=0.01))
    rr.disconnect()
    return None if streamed else out


def _has_display() -> bool:
    """False on a Linux machine without X11/Wayland (a server, CI)."""
    import os
    import sys

    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class LiveViewer:
    """Stream odometry to the Rerun viewer as frames are computed (``relnav odometry --viz``).

    Each frame logs the scan in the world frame at its *estimated* pose, the estimated
    trajectory so far and the sensor position; every ``model_every`` frames, the model of the
    target accumulated from the registered scans (one point per voxel of ``model_voxel`` metres,
    default: half the first scan's median spacing) as ``world/model``; the ground truth (when
    known) is logged once.
    With ``rrd`` the stream goes to that file (headless machines; open it later with
    ``rerun FILE.rrd``); otherwise a viewer is spawned, and when that is impossible (no
    display, no viewer binary) the stream falls back to ``fallback_rrd``.

    Parameters
    ----------
    name : str
        Recording name.
    rrd : Path, optional
        Write to this ``.rrd`` instead of a live viewer.
    gt_poses : (N, 4, 4) float64, optional
        Ground truth ``T_world_sensor``.
    fallback_rrd : Path, optional
        Where to write when no viewer can be spawned.
    max_points : int
        Scans are subsampled (every k-th point) to at most this many points for display.
    model_every : int
        Frames between two logs of the accumulated model (0: no model).
    model_voxel : float, optional
        Voxel of the displayed model, metres.
    """

    def __init__(
        self,
        name: str,
        *,
        rrd: str | Path | None = None,
        gt_poses: np.ndarray | None = None,
        fallback_rrd: str | Path | None = None,
        max_points: int = 20000,
        model_every: int = 10,
        model_voxel: float | None = None,
    ) -> None:
        import logging

        rr = _rerun()
        self._rr = rr
        self.path: Path | None = None
        rr.init(f"relnav/{name}", spawn=False)
        headless = not _has_display()
        if rrd is None and not headless:
            try:
                rr.spawn()
            except Exception as e:  # no viewer binary, no display
                logging.getLogger(__name__).warning("cannot spawn the Rerun viewer: %s", e)
                rrd = fallback_rrd
        elif rrd is None:
            rrd = fallback_rrd
        if rrd is not None:
            self.path = Path(rrd)
            self.path.parent.mkdir(parents=True, exist_ok=True)
            rr.save(str(self.path))
        self._max_points = int(max_points)
        self._track: list[np.ndarray] = []
        self._model_every = int(model_every)
        self._model_voxel = model_voxel
        self._model: dict[tuple[int, int, int], np.ndarray] = {}
        if gt_poses is not None:
            rr.log("world/ground_truth", rr.LineStrips3D([gt_poses[:, :3, 3]]), static=True)

    def log_frame(self, k: int, points: np.ndarray | None, pose: np.ndarray) -> None:
        """Log frame ``k``: ``points`` (sensor frame, (N, 3)) at the estimated ``pose``."""
        from relnav.geometry.se3 import transform_points

        rr = self._rr
        _set_frame(rr, k)
        self._track.append(np.asarray(pose)[:3, 3].copy())
        rr.log("world/estimate", rr.LineStrips3D([np.asarray(self._track)]))
        rr.log("world/sensor", rr.Points3D(np.asarray(pose)[None, :3, 3], radii=0.05))
        if points is not None and len(points):
            step = max(1, len(points) // self._max_points)
            world = transform_points(pose, points[::step])
            rr.log("world/scan", rr.Points3D(world, radii=0.01))
            if self._model_every > 0:
                self._accumulate(world)
        if self._model_every > 0 and self._model and k % self._model_every == 0:
            rr.log("world/model", rr.Points3D(np.stack(list(self._model.values())), radii=0.02))

    def _accumulate(self, world: np.ndarray) -> None:
        """Keep the first point of every model voxel (display only)."""
        world = world[np.all(np.isfinite(world), axis=1)]
        if not len(world):
            return
        if self._model_voxel is None:
            from relnav.geometry.neighbors import mean_resolution

            res = mean_resolution(world) if len(world) > 1 else 0.0
            self._model_voxel = 0.5 * res if np.isfinite(res) and res > 0 else 0.05
        keys = np.floor(world / self._model_voxel).astype(np.int64)
        for key, p in zip(map(tuple, keys.tolist()), world, strict=True):
            self._model.setdefault(key, p)

    def close(self) -> None:
        """Flush and disconnect."""
        self._rr.disconnect()
