"""Export a sequence (and estimates) to a Rerun recording (``.rrd``), extra ``[viz]``.

Open the file with the Rerun viewer (``rerun FILE.rrd``): each scan is shown in the target
frame at its ground-truth pose (or the sensor frame when there is none), with the ground-truth
and estimated sensor trajectories, on a ``frame`` timeline.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relnav.errors import ConfigError

__all__ = ["export_rrd"]


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
) -> Path:
    """Write ``seq_dir``'s scans and trajectories to the Rerun recording ``out``.

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
    return out
