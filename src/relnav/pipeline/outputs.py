"""The run folder of an odometry run: estimate, diagnostics, metrics, figures, state, run.json.

:func:`write_run_outputs` writes what ``relnav odometry`` and ``relnav demo`` leave in a run
folder (:class:`relnav.pipeline.OdometryPipeline` calls it): ``estimate.tum`` (a smoother's run
also ``estimate_causal.tum``, the poses each frame had when it was estimated),
``diagnostics.csv``, with ground truth ``metrics.json`` and ``errors.png``, for the navigator the
relative state (:func:`write_state_outputs`: ``state.csv``, ``state.png``,
``state_errors.png``), and ``run.json`` (the run's record, :mod:`relnav.io.runinfo`).
"""

from __future__ import annotations

import math
from enum import StrEnum
from pathlib import Path
from typing import Any

__all__ = [
    "STATE_MAX_FRAMES",
    "PoseFormat",
    "json_safe",
    "navigator_run",
    "write_run_outputs",
    "write_state_outputs",
]


class PoseFormat(StrEnum):
    """Trajectory file format of the estimate."""

    tum = "tum"
    kitti = "kitti"


def json_safe(res: dict[str, Any]) -> dict[str, Any]:
    """NaN/inf → None (top-level values) so the JSON is standard."""
    return {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in res.items()
    }


STATE_MAX_FRAMES = 5000
"""Runs longer than this write the full state only on request (``--state``): it keeps about
1.7 kB per frame in memory."""


def navigator_run(run: Any) -> bool:
    """Whether ``run`` (an :class:`relnav.odometry.OdometryRun`) is the navigator's: its method
    is a registered tracker built by :class:`relnav.navigation.Navigator` (or a subclass), whose
    run folder has the revisit counts and the relative state."""
    from relnav.pipeline.registry import builds_navigator, tracker_entry

    return builds_navigator(tracker_entry(run.method) if isinstance(run.method, str) else None)


def _block_means(values: Any) -> dict[str, float | None]:
    """Mean of each column of ``values`` ``(K, 4)`` over its finite steps, by block name."""
    import numpy as np

    from relnav.filtering.track_result import STATE_BLOCKS

    out: dict[str, float | None] = {}
    for name, col in zip(STATE_BLOCKS, values.T, strict=True):
        col = col[np.isfinite(col)]
        out[name] = float(np.mean(col)) if len(col) else None
    return out


def write_state_outputs(
    out: Path,
    run: Any,
    gt: Any,
    metrics: dict[str, Any],
    steps: Any = None,
    options: dict[str, Any] | None = None,
) -> list[str]:
    """The navigator's full relative state (twistor UKF on its poses): ``state.csv``,
    ``state.png`` and, with ground truth, ``state_errors.png`` (errors with ±3σ); adds the
    state's error summary and NEES to ``metrics`` (key ``state``). ``options`` go to
    :func:`relnav.navigation.state.relative_state` (``angular_acceleration``, ``drift`` …)."""
    import numpy as np

    from relnav.eval.track_plots import plot_track, plot_track_errors
    from relnav.navigation.state import nees_band, relative_state, state_options

    result = relative_state(run, steps=steps, gt_poses=gt, **state_options(options or {}))
    result.to_csv(out / "state.csv")
    names = ["state.csv", plot_track(result, out / "state.png").name]
    if gt is not None:
        names.append(plot_track_errors(result, out / "state_errors.png").name)
        k0 = round(0.3 * len(result))
        nees = result.nees()[k0:]
        nees = nees[np.isfinite(nees)]
        summary = result.summary(skip=0.3)
        metrics["state"] = {
            # frames whose last innovations the state's dynamics cannot follow (state.csv)
            "innovation_alarm_frames": int(np.sum(result.innovation_alarm())),
            "skip_fraction": 0.3,
            "omega_rms_deg_s": summary["omega"]["rms"],
            "omega_max_deg_s": summary["omega"]["max"],
            "omega_sensor_rms_deg_s": summary["omega_sensor"]["rms"],
            "omega_sensor_max_deg_s": summary["omega_sensor"]["max"],
            "attitude_rms_deg": summary["attitude"]["rms"],
            "position_rms_m": summary["position"]["rms"],
            "velocity_rms_m_s": summary["velocity"]["rms"],
            "nees_mean": float(np.mean(nees)) if len(nees) else None,
            "nees_band_95": list(nees_band(len(nees))) if len(nees) else None,
            # each 3-dim block alone and given the other nine (3 when consistent)
            "nees_blocks_mean": _block_means(result.nees_blocks()[k0:]),
            "nees_given_rest_mean": _block_means(result.nees_conditional()[k0:]),
        }
    return names


def write_run_outputs(
    out: Path,
    run: Any,
    seq: Any,
    *,
    command: str,
    preset: str | None,
    fmt: PoseFormat = PoseFormat.tum,
    seed: int | None = None,
    timings: dict[str, float] | None = None,
    errors_plot: bool = True,
    extra_outputs: list[str] | None = None,
    state_steps: Any = None,
    state_options: dict[str, Any] | None = None,
    status: str = "complete",
) -> dict[str, Any]:
    """Write a run folder: estimate (TUM, and KITTI on request), diagnostics, metrics, run.json.

    ``status`` goes to ``run.json`` (``complete``, ``interrupted``: Ctrl-C, the frames
    estimated until then; ``failed``: every frame failed).

    With ground truth in ``seq``, ``metrics.json`` holds every metric plus the processing time
    and flag count, and ``errors.png`` the errors over time. Returns the metrics (``{}``
    without ground truth).
    """
    import json

    from relnav.eval.metrics import evaluate_trajectories
    from relnav.io.runinfo import run_info, write_run_info

    paths = run.write(out)
    outputs = [paths["estimate"].name, paths["diagnostics"].name]
    if "estimate_causal" in paths:  # a smoother's run: the online poses beside the smoothed
        outputs.append(paths["estimate_causal"].name)
    if fmt == PoseFormat.kitti:
        import numpy as np

        from relnav.io.trajectories import write_kitti

        write_kitti(out / "estimate_kitti.txt", run.poses)
        np.savetxt(out / "times.txt", run.timestamps, fmt="%.9f")
        outputs += ["estimate_kitti.txt", "times.txt"]
    metrics: dict[str, Any] = {}
    navigator = navigator_run(run)
    gt = getattr(seq, "gt_poses", None)  # a plain list of scans has none
    n = len(run.poses)
    if gt is not None and n >= 2:
        metrics = evaluate_trajectories(run.timestamps, run.poses, seq.timestamps[:n], gt[:n])
        metrics.update(
            time_ms=run.median_time_ms,
            time_ms_mean=run.mean_time_ms,
            flagged_frames=run.n_flagged,
            method=run.method,
            preset=preset,
        )
        outputs.append("metrics.json")
        if run.causal_poses is not None:  # the online poses, as a real-time loop had them
            causal = evaluate_trajectories(
                run.timestamps, run.causal_poses, seq.timestamps[:n], gt[:n]
            )
            metrics["causal"] = {
                k: v for k, v in causal.items() if isinstance(v, int | float) and k in metrics
            }
            metrics["causal"].pop("time_ms", None)  # the run's, not the trajectory's
        if navigator:  # the navigator's revisit test: revisits tested, failed
            revisits = run.options.get("finalize", {}).get("revisits") or []
            metrics.update(
                revisit_tests=len(revisits), revisit_alarms=sum(r["alarm"] for r in revisits)
            )
        if errors_plot:
            from relnav.eval.metrics import match_trajectories
            from relnav.eval.plots import plot_errors

            m = match_trajectories(run.timestamps, run.poses, seq.timestamps[:n], gt[:n])
            label = preset or run.method
            plot_errors(
                out / "errors.png",
                m.gt_poses,
                {label: m.est_poses},
                times=m.times,
                title=f"{label}: error with respect to the ground truth",
                step_sigmas=(
                    {label: run.step_sigma[m.idx_est]} if run.step_sigma is not None else None
                ),
            )
            outputs.append("errors.png")
    frames = state_steps if state_steps is not None else run.steps
    if navigator and len(frames) >= 3:
        gt_n = gt[:n] if gt is not None else None
        outputs += write_state_outputs(out, run, gt_n, metrics, steps=frames, options=state_options)
    if metrics:  # once, with the state's figures when there are some
        from relnav.atomic import atomic_write_text

        atomic_write_text(out / "metrics.json", json.dumps(json_safe(metrics), indent=2) + "\n")
    if seed is None:  # a simulated sequence records its scenario's seed
        scenario = getattr(seq, "scenario", None)
        seed = scenario.get("seed") if isinstance(scenario, dict) else None
    doc = run_info(
        command=command,
        run=run,
        preset=preset,
        sequence=seq,
        seed=seed,
        timings=timings,
        outputs=[*outputs, *(extra_outputs or []), "run.json"],
        extra={"status": status},
    )
    write_run_info(out, doc)
    return metrics
