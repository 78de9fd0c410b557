"""``relnav odometry``: run frame-to-frame odometry over a sequence, a recording or a folder."""

from __future__ import annotations

import time
from enum import StrEnum
from pathlib import Path
from typing import Any

import typer

from relnav.cli._common import console, parse_options, progress_bar


class PoseFormat(StrEnum):
    """Trajectory file format of the estimate."""

    tum = "tum"
    kitti = "kitti"


def prepare_method(
    method: str, option: list[str] | dict[str, Any] | None
) -> tuple[str, dict[str, Any], str | None]:
    """Expand a preset and check the method and its options before any frame is read.

    ``option`` is the ``-O key=value`` list or the dict already parsed from it.

    Returns ``(method string, options, preset name or None)``; raises
    :class:`~relnav.errors.ConfigError` (with "did you mean") for an unknown name or bad options.
    """
    from relnav.odometry.presets import resolve_method
    from relnav.odometry.runner import make_tracker

    parsed = option if isinstance(option, dict) else parse_options(option)
    name, opts, preset = resolve_method(method, parsed)
    make_tracker(name, **opts)  # builds the method: bad options fail here, not after frame 0
    return name, opts, preset


STATE_MAX_FRAMES = 5000
"""Runs longer than this write the full state only on request (``--state``): it keeps about
1.7 kB per frame in memory."""


def _block_means(values: Any) -> dict[str, float | None]:
    """Mean of each column of ``values`` ``(K, 4)`` over its finite steps, by block name."""
    import numpy as np

    from relnav.fusion.track_result import STATE_BLOCKS

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

    from relnav.cli.track import plot_track, plot_track_errors
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
) -> dict[str, Any]:
    """Write a run folder: estimate (TUM, and KITTI on request), diagnostics, metrics, run.json.

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
    gt = seq.gt_poses
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
            metrics["causal"] = {k: v for k, v in causal.items() if isinstance(v, int | float)}
        if run.method == "relnav":  # the navigator's revisit test: revisits tested, failed
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
            )
            outputs.append("errors.png")
    frames = state_steps if state_steps is not None else run.steps
    if run.method == "relnav" and len(frames) >= 3:
        gt_n = gt[:n] if gt is not None else None
        outputs += write_state_outputs(out, run, gt_n, metrics, steps=frames, options=state_options)
    if metrics:  # once, with the state's figures when there are some
        from relnav.atomic import atomic_write_text
        from relnav.cli.evaluate import json_safe

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
    )
    write_run_info(out, doc)
    return metrics


def odometry(
    seq_dir: Path = typer.Argument(
        ...,
        help="Sequence folder (scans/), KITTI folder (velodyne/), plain folder of scans, or a "
        "recording (.bag, .mcap, .db3, ROS 2 bag folder).",
    ),
    method: str = typer.Option(
        "relnav",
        "--method",
        "-m",
        help="Method string or preset name (`relnav methods` lists both).",
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    sensor: str = typer.Option(None, "--sensor", help="Second-sensor name (scans_<name>/)."),
    topic: str = typer.Option(
        None, "--topic", help="PointCloud2 topic of a recording (needed if it has several)."
    ),
    max_frames: int = typer.Option(None, "--max-frames", help="Stop after N frames (N >= 0)."),
    motion_prior: str = typer.Option(
        None, "--motion-prior", help="constant_velocity (default) | identity"
    ),
    option: list[str] = typer.Option(
        None,
        "--option",
        "-O",
        help="Method option key=value (repeatable; dots nest: estimator_options.alpha=0.3). "
        "Odometry options: motion_prior, initial_pose (gt | identity | 16 numbers), "
        "gate_rotation_deg, gate_translation, step_check (auto | off | referee | backward | "
        "full), step_tolerance_m, step_tolerance_deg, point_budget (None = every point), "
        "budget_target, budget_sampler (random | voxel), budget_seed, dense_refine (auto | on | "
        "off), dense_keypoints (None = every point of a reduced scan).",
    ),
    strict: bool = typer.Option(
        False, "--strict", help="Abort on an unreadable scan (default: flag the frame, go on)."
    ),
    fmt: PoseFormat = typer.Option(
        PoseFormat.tum,
        "--format",
        help="tum: estimate.tum; kitti: also estimate_kitti.txt (3x4 poses) and times.txt.",
    ),
    viz: bool = typer.Option(
        False, "--viz", help="Stream scans and trajectories to the Rerun viewer (extra \\[viz])."
    ),
    state: bool = typer.Option(
        None,
        "--state/--no-state",
        help="Write the navigator's full relative state (state.csv, state.png, "
        f"state_errors.png); default: on for relnav up to {STATE_MAX_FRAMES} frames.",
    ),
    state_option: list[str] = typer.Option(
        None,
        "--state-option",
        "-S",
        help="relative_state option key=value for the full state (repeatable), e.g. "
        "preset=hold-point (the chaser holds station beside a spinning or tumbling target), "
        "angular_acceleration=adaptive, drift=offset, n_mean_motion=0.0011, acceleration=1e-4.",
    ),
    rrd: Path = typer.Option(
        None,
        "--rrd",
        help="Save the live stream to this .rrd (implies --viz; headless default OUT/live.rrd).",
    ),
) -> None:
    """Estimate the sensor trajectory; writes estimate.tum, diagnostics.csv and run.json.

    With ground truth (a sequence folder's gt_T_target_sensor.tum, KITTI poses/NN.txt) also
    metrics.json and errors.png.

    Examples: [bold]relnav odometry seq/ --method extended --out runs/ext[/],
    [bold]relnav odometry drive.bag --topic /points --method icp-point --out runs/bag[/],
    [bold]relnav odometry kitti/sequences/00 --method kiss-icp --format kitti --out runs/00[/]
    """
    from rich.table import Table

    from relnav.errors import ConfigError, InputError
    from relnav.io.sources import open_sequence
    from relnav.odometry import run_sequence
    from relnav.odometry.options import check_max_frames

    max_frames = check_max_frames(max_frames)
    opts = parse_options(option)
    prior = opts.pop("motion_prior", None)
    if prior is not None and motion_prior is not None and prior != motion_prior:
        raise ConfigError(
            f"--motion-prior {motion_prior} and -O motion_prior={prior} disagree; give one"
        )
    motion_prior = motion_prior or prior or "constant_velocity"
    initial_pose = opts.pop("initial_pose", "gt")
    name, opts, preset = prepare_method(method, opts)
    seq = open_sequence(seq_dir, sensor=sensor, topic=topic)
    if len(seq) == 0:
        raise InputError(f"{seq_dir}: no scan files to run odometry on")
    n = len(seq) if max_frames is None else min(len(seq), max_frames)
    live = None
    if viz or rrd is not None:
        from relnav.eval.rerun_export import LiveViewer

        live = LiveViewer(
            f"odometry {preset or name}",
            rrd=rrd,
            gt_poses=seq.gt_poses,
            fallback_rrd=Path(out) / "live.rrd",
        )
    from relnav.navigation.state import StateRecord, check_state_options

    if state is None:
        state = name == "relnav" and n <= STATE_MAX_FRAMES
    if state and name != "relnav":
        raise ConfigError("--state needs the navigator (method relnav)")
    state_opts = parse_options(state_option, flag="--state-option")
    if state_opts and not state:
        raise ConfigError("--state-option needs the full state (method relnav, --state)")
    check_state_options(state_opts)  # before the run, not after it
    records: list[Any] | None = [] if state else None
    if name == "relnav" and n > STATE_MAX_FRAMES and not state:
        console.print(
            f"[yellow]{n} frames: the full relative state is skipped to keep memory flat "
            "(--state writes it)[/]"
        )
    t0 = time.perf_counter()
    with progress_bar() as bar:
        task = bar.add_task(preset or name, total=n)

        def step(i: int, s: Any) -> None:
            bar.advance(task)
            if live is not None:
                live.log_frame(i, seq[i].points, s.pose)
            if records is not None:
                records.append(StateRecord.from_step(s))

        run = run_sequence(
            seq,
            name,
            initial_pose=initial_pose,
            motion_prior=motion_prior,  # type: ignore[arg-type]
            max_frames=max_frames,
            progress=step,
            out=out,
            keep_steps=False,  # memory stays flat; the state keeps its compact records
            strict=strict,
            **opts,
        )
    wall = time.perf_counter() - t0
    out = Path(out)
    if live is not None:
        live.close()
        if live.path is not None:
            console.print(
                f"streamed to {live.path} (open with: rerun {live.path})", highlight=False
            )
    live_file = []
    if live is not None and live.path is not None:
        live_file = [
            str(live.path.relative_to(out)) if live.path.is_relative_to(out) else str(live.path)
        ]
    m = write_run_outputs(
        out,
        run,
        seq,
        command="odometry",
        preset=preset,
        fmt=fmt,
        timings={"wall_s": wall},
        extra_outputs=live_file,
        state_steps=records if records is not None else [],
        state_options=state_opts,
    )
    table = Table(title=f"odometry — {preset or name}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("frames", str(len(run.poses)))
    table.add_row("flagged (not ok)", str(run.n_flagged))
    table.add_row("median time per frame (ms)", f"{run.median_time_ms:.1f}")
    for key in ("e_T_avg", "e_T_max", "drift", "T_error_pct", "e_R_avg", "e_R_max", "e_RT"):
        if key in m:
            table.add_row(key, f"{m[key]:.4g}")
    if (alarms := m.get("state", {}).get("innovation_alarm_frames")) is not None:
        table.add_row("state: innovation alarm (frames)", str(alarms))
    console.print(table)
    orbit = run.options.get("finalize", {}).get("orbit")
    if orbit is not None:
        console.print(f"orbit model: {orbit['reason']}", highlight=False)
    revisits = run.options.get("finalize", {}).get("revisits") or []
    if alarmed := [r for r in revisits if r["alarm"]]:
        r = alarmed[0]
        console.print(
            f"[yellow]map inconsistent: frame {r['new_frame']} revisits frame {r['old_frame']} "
            f"and disagrees with the tracked chain (χ² {r['chi2']:.1f}); {len(alarmed)} of the "
            f"{len(revisits)} revisits tested failed and the ok steps after a failed one are "
            "flagged (docs/navigator.md)[/]",
            highlight=False,
        )
    if seq.gt_poses is not None and n < 2:
        console.print(
            f"[yellow]evaluation needs at least two frames ({n} estimated): metrics skipped[/]"
        )
    written = sorted(p.name for p in out.iterdir() if p.is_file())
    console.print(f"wrote {out}/: {', '.join(written)}", highlight=False)


def register(app: typer.Typer) -> None:
    """Register ``relnav odometry``."""
    app.command("odometry")(odometry)
