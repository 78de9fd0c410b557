"""``relnav odometry``: run frame-to-frame odometry over a sequence, a recording or a folder."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from relnav.cli._common import console, parse_options, progress_bar
from relnav.pipeline.outputs import STATE_MAX_FRAMES, PoseFormat


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
        help="OUTPUT pose format (the input's layout is detected): tum: estimate.tum; kitti: "
        "also estimate_kitti.txt (3x4 poses) and times.txt.",
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
    initial_pose: str = typer.Option(
        None,
        "--initial-pose",
        help="Start pose: gt (the ground truth's first pose; default when there is ground "
        "truth), identity (default otherwise), or a FILE with a 4x4 / 3x4 matrix (16 / 12 "
        "numbers) or a TUM/KITTI trajectory (its first pose). Printed and kept in run.json.",
    ),
    rate: float = typer.Option(
        None, "--rate", help="Scan rate, Hz, for a folder without times (default 1 Hz)."
    ),
    dt: float = typer.Option(
        None, "--dt", help="Scan spacing, s, for a folder without times (default 1 s)."
    ),
    attitude: Path = typer.Option(
        None,
        "--attitude",
        help="The chaser's measured inertial attitude (TUM file of R_W_sensor: star tracker, "
        "IMU; position columns ignored): the navigator's rotation prior for each step "
        "(method relnav; a target whose own rotation per frame is small).",
    ),
    attitude_sigma_deg: float = typer.Option(
        0.01, "--attitude-sigma-deg", help="1σ per axis of each --attitude sample, degrees."
    ),
) -> None:
    """Estimate the sensor trajectory; writes estimate.tum, diagnostics.csv and run.json.

    With ground truth (a sequence folder's gt_T_target_sensor.tum, KITTI poses/NN.txt) also
    metrics.json and errors.png.

    Examples: [bold]relnav odometry seq/ --method extended --out runs/ext[/],
    [bold]relnav odometry drive.bag --topic /points --method icp-point --out runs/bag[/],
    [bold]relnav odometry kitti/sequences/00 --method kiss-icp --format kitti --out runs/00[/]
    """
    from relnav.errors import ConfigError, InputError
    from relnav.io.outputs import RunFolder, output_error
    from relnav.io.sources import open_sequence
    from relnav.odometry.options import check_max_frames
    from relnav.pipeline import OdometryPipeline

    max_frames = check_max_frames(max_frames)
    opts = parse_options(option)
    prior = opts.pop("motion_prior", None)
    if prior is not None and motion_prior is not None and prior != motion_prior:
        raise ConfigError(
            f"--motion-prior {motion_prior} and -O motion_prior={prior} disagree; give one"
        )
    pose_option = opts.pop("initial_pose", None)
    if initial_pose is not None and pose_option is not None:
        raise ConfigError("--initial-pose and -O initial_pose both given; give one")
    spacing = time_spacing(rate, dt)
    # a preset's own motion prior (paper1-icp-point: identity) unless the user gave one
    pipe = OdometryPipeline(method, opts, motion_prior=motion_prior or prior)
    name, preset = pipe.method, pipe.preset
    if attitude is not None:
        if not pipe.is_navigator:
            raise ConfigError(f"--attitude needs the navigator (method relnav), not {name!r}")
        from relnav.navigation.attitude_input import AttitudeInput

        pipe.options["attitude"] = AttitudeInput.from_tum(attitude, attitude_sigma_deg)
    seq = open_sequence(seq_dir, sensor=sensor, topic=topic)
    if len(seq) == 0:
        raise InputError(f"{seq_dir}: no scan files to run odometry on")
    n = len(seq) if max_frames is None else min(len(seq), max_frames)
    apply_time_spacing(seq, spacing)
    if initial_pose is not None:
        start, start_text = start_pose(initial_pose, seq, from_file=True)
    else:
        start, start_text = start_pose(pose_option, seq)
    console.print(f"start pose: {start_text}", highlight=False)
    warn_units(seq)
    live = None
    if viz or rrd is not None:
        from relnav.eval.rerun_export import LiveViewer

        live = LiveViewer(
            f"odometry {preset or name}",
            rrd=rrd,
            gt_poses=seq.gt_poses,
            fallback_rrd=Path(out) / "live.rrd",
        )
    from relnav.navigation.state import check_state_options

    if state is None:
        state = pipe.is_navigator and n <= STATE_MAX_FRAMES
    if state and not pipe.is_navigator:
        raise ConfigError("--state needs the navigator (method relnav)")
    state_opts = parse_options(state_option, flag="--state-option")
    if state_opts and not state:
        raise ConfigError("--state-option needs the full state (method relnav, --state)")
    check_state_options(state_opts)  # before the run, not after it
    if pipe.is_navigator and n > STATE_MAX_FRAMES and not state:
        console.print(
            f"[yellow]{n} frames: the full relative state is skipped to keep memory flat "
            "(--state writes it)[/]"
        )
    with RunFolder(out, protect=getattr(seq, "source_files", [])) as folder:
        try:
            summary = _run_into(
                folder,
                seq,
                pipe,
                start=start,
                n=n,
                live=live,
                state=bool(state),
                state_opts=state_opts,
                max_frames=max_frames,
                strict=strict,
                fmt=fmt,
            )
        except OSError as e:
            raise output_error(e, out) from None
        _report(Path(out), folder, summary)  # under the lock: the folder is finished


def _run_into(
    folder: Any,
    seq: Any,
    pipe: Any,
    *,
    start: Any,
    n: int,
    live: Any,
    state: bool,
    state_opts: dict[str, Any],
    max_frames: int | None,
    strict: bool,
    fmt: PoseFormat,
) -> dict[str, Any]:
    """The run (:class:`relnav.pipeline.OdometryPipeline` ``pipe``) and its outputs, in ``folder``
    (held by :class:`relnav.io.outputs.RunFolder`); returns ``status``, ``interrupted`` and
    ``failed`` for :func:`_report`."""
    from rich.table import Table

    out = folder.folder
    with progress_bar() as bar:
        task = bar.add_task(pipe.label, total=n)

        def step(i: int, s: Any) -> None:
            bar.advance(task)
            if live is not None:
                live.log_frame(i, seq[i].points, s.pose)

        result = pipe.run(
            seq,
            out=out,  # streamed: memory stays flat; the state keeps its compact records
            initial_pose=start,
            max_frames=max_frames,
            progress=step,
            strict=strict,
            on_interrupt="stop",  # Ctrl-C: the frames estimated are written, run.json says so
            state=state,
        )
    run = result.run
    interrupted, all_failed, status = result.interrupted, result.failed, result.status
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
    m = pipe.write(
        result,
        seq,
        out,
        command="odometry",
        fmt=fmt,
        extra_outputs=live_file,
        state_options=state_opts,
    )
    if interrupted or all_failed:
        return {"status": status, "interrupted": interrupted, "failed": all_failed}
    table = Table(title=f"odometry — {pipe.label}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("frames", str(len(run.poses)))
    table.add_row("flagged (not ok)", str(run.n_flagged))
    table.add_row("median time per frame (ms)", f"{run.median_time_ms:.1f}")
    for key in ("e_T_avg", "e_T_max", "drift", "T_error_pct", "e_R_avg", "e_R_max", "e_RT"):
        if key in m:
            table.add_row(key, f"{m[key]:.4g}")
    for key in ("e_T_avg", "T_error_pct", "e_R_avg"):  # a smoother's run: its online poses too
        if key in m.get("causal", {}):
            table.add_row(f"{key} (causal: estimate_causal.tum)", f"{m['causal'][key]:.4g}")
    if (alarms := m.get("state", {}).get("innovation_alarm_frames")) is not None:
        table.add_row("state: innovation alarm (frames)", str(alarms))
    console.print(table)
    if alarms:
        console.print(
            f"[yellow]state: on {alarms} frames the relative state's dynamics could not follow "
            "its last five innovations (windowed NIS test at 0.999): the navigator's map may be "
            "sliding there (state.csv, column innovation_alarm)[/]",
            highlight=False,
        )
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
    return {"status": status, "interrupted": None, "failed": None}


def _report(out: Path, folder: Any, summary: dict[str, Any]) -> None:
    """Finish the folder (drop the previous run's other outputs, the .incomplete marker) and
    print what was written; one line and a non-zero exit after Ctrl-C or when every frame
    failed."""
    from relnav.errors import EstimationError
    from relnav.io.runinfo import read_run_info

    written = list((read_run_info(out) or {}).get("outputs", []))
    removed = folder.finish(written)
    if removed:
        console.print(
            f"removed the previous run's {', '.join(sorted(removed))} (not written by this run)",
            highlight=False,
        )
    if summary["interrupted"]:
        k, n = summary["interrupted"]["at_frame"], summary["interrupted"]["of"]
        console.print(
            f"[yellow]interrupted at frame {k} of {n}: the {k} frames estimated are in {out}/ "
            "(run.json status: interrupted)[/]",
            highlight=False,
        )
        raise typer.Exit(130)
    if summary["failed"]:
        raise EstimationError(
            f"every frame failed (first: {summary['failed']}); diagnostics in "
            f"{out}/diagnostics.csv, run.json status: failed"
        )
    console.print(f"wrote {out}/: {', '.join(sorted(written))}", highlight=False)


def time_spacing(rate: float | None, dt: float | None) -> float | None:
    """Scan spacing (s) from ``--rate`` (Hz) or ``--dt`` (s); ConfigError for both, or a value
    that is not positive and finite."""
    import math

    from relnav.errors import ConfigError

    if rate is not None and dt is not None:
        raise ConfigError("--rate and --dt both given; give one")
    for flag, v in (("--rate", rate), ("--dt", dt)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ConfigError(f"{flag} must be a positive number, got {v}")
    if rate is not None:
        return 1.0 / rate
    return dt


def apply_time_spacing(seq: Any, spacing: float | None) -> None:
    """Set a folder's scan spacing, or warn that 1 s is assumed when it has no times."""
    from relnav.errors import ConfigError

    assumed = bool(getattr(seq, "times_assumed", False))
    if spacing is not None:
        if not assumed:
            raise ConfigError(
                "--rate/--dt are for folders without times; this input has its own scan times"
            )
        seq.set_time_spacing(spacing)
    elif assumed:
        console.print(
            "[yellow]no scan times (no timestamps.txt/times.txt): assuming 1 s between scans; "
            "--rate HZ or --dt S sets the spacing[/]",
            highlight=False,
        )


def start_pose(value: Any, seq: Any, *, from_file: bool = False) -> tuple[Any, str]:
    """The start pose given to the run (``"gt"``, ``None`` = identity, or a 4x4) and the line
    printed about it. ``value``: ``None`` (gt when there is ground truth, else identity),
    ``"gt"``, ``"identity"``, what ``-O initial_pose`` parsed to, or (``from_file``, the
    ``--initial-pose`` option) a file name."""
    import numpy as np

    from relnav.errors import ConfigError
    from relnav.odometry.options import parse_initial_pose

    has_gt = getattr(seq, "gt_poses", None) is not None
    if value is None:
        value = "gt" if has_gt else "identity"
    if from_file and isinstance(value, str) and value.strip().lower() not in ("gt", "identity"):
        T = parse_initial_pose(_pose_file(Path(value)))
        return T, f"from {value} (--initial-pose)"
    parsed = parse_initial_pose(value)
    if isinstance(parsed, str):
        if not has_gt:
            raise ConfigError("--initial-pose gt: this input has no ground truth")
        return parsed, "the ground truth's first pose (--initial-pose gt)"
    if parsed is None:
        why = "" if has_gt else " (no ground truth; --initial-pose FILE sets one)"
        return None, f"identity{why}"
    return np.asarray(parsed), "given by -O initial_pose"


def _pose_file(p: Path) -> Any:
    """16 or 12 numbers (a 4x4 or 3x4 matrix, row-major) or a trajectory's first pose."""
    import numpy as np

    from relnav.errors import ConfigError, InputError
    from relnav.io.text import read_text_file
    from relnav.io.trajectories import read_trajectory

    if not p.is_file():
        raise ConfigError(
            f"--initial-pose {p}: not gt, identity nor a file (a 4x4 matrix or a trajectory)"
        )
    tokens = read_text_file(p, what="pose").replace(",", " ").split()
    tokens = [t for t in tokens if not t.startswith("#")]
    if len(tokens) in (12, 16):
        try:
            return [float(t) for t in tokens]
        except ValueError:
            pass
    try:
        _, poses, _ = read_trajectory(p)
    except InputError as e:
        raise ConfigError(f"--initial-pose {p}: neither a matrix nor a trajectory ({e})") from None
    if not len(poses):
        raise ConfigError(f"--initial-pose {p}: the trajectory is empty")
    return np.asarray(poses[0])


def warn_units(seq: Any) -> None:
    """Print a units hint when the first scan extends far beyond the scene (see
    :func:`relnav.io.sources.units_warning`)."""
    from relnav.errors import InputError
    from relnav.io.sources import units_warning

    try:
        scan = seq[0]
    except InputError:
        return  # the run flags it
    if (msg := units_warning(seq, scan.points)) is not None:
        console.print(f"[yellow]warning: {msg}[/]", highlight=False)


def register(app: typer.Typer) -> None:
    """Register ``relnav odometry``."""
    app.command("odometry")(odometry)
