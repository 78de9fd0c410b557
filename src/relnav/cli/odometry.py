"""``relnav odometry``: run frame-to-frame odometry over a sequence folder."""

from __future__ import annotations

from pathlib import Path

import typer

from relnav.cli._common import console, parse_options, progress_bar


def odometry(
    seq_dir: Path = typer.Argument(..., help="Sequence folder (scans/, optional gt TUM file)."),
    method: str = typer.Option(
        "feature:hods+gcc+alphabeta", "--method", "-m", help="Method string (`relnav methods`)."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    sensor: str = typer.Option(None, "--sensor", help="Second-sensor name (scans_<name>/)."),
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
        "gate_rotation_deg, gate_translation.",
    ),
    strict: bool = typer.Option(
        False, "--strict", help="Abort on an unreadable scan (default: flag the frame, go on)."
    ),
) -> None:
    """Estimate the sensor trajectory of a sequence; writes estimate.tum and diagnostics.csv.

    Example: [bold]relnav odometry seq/ --method feature:shot+gcc+kalman --out runs/shot[/]
    """
    import json

    from rich.table import Table

    from relnav.errors import ConfigError, InputError
    from relnav.io.atomic import atomic_write_text
    from relnav.io.sequences import ScanSequence
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
    seq = ScanSequence(seq_dir, sensor=sensor)
    if len(seq) == 0:
        raise InputError(f"{seq.layout.scans_dir}: no scan files to run odometry on")
    n = len(seq) if max_frames is None else min(len(seq), max_frames)
    with progress_bar() as bar:
        task = bar.add_task(method, total=n)
        run = run_sequence(
            seq,
            method,
            initial_pose=initial_pose,
            motion_prior=motion_prior,  # type: ignore[arg-type]
            max_frames=max_frames,
            progress=lambda i, step: bar.advance(task),
            out=out,
            keep_steps=False,
            strict=strict,
            **opts,
        )
    paths = run.paths
    table = Table(title=f"odometry — {method}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("frames", str(len(run.poses)))
    table.add_row("flagged (kept the motion prior)", str(run.n_flagged))
    table.add_row("mean time per frame (ms)", f"{run.mean_time_ms:.1f}")
    note = ""
    if seq.gt_poses is not None and n < 2:
        note = f"evaluation needs at least two frames ({n} estimated): metrics skipped"
    elif seq.gt_poses is not None:
        from relnav.eval.metrics import evaluate_trajectories

        m = evaluate_trajectories(run.timestamps, run.poses, seq.timestamps[:n], seq.gt_poses[:n])
        m["time_ms"] = run.mean_time_ms
        atomic_write_text(Path(out) / "metrics.json", json.dumps(m, indent=2))
        for key in ("e_T_avg", "e_T_max", "drift", "T_error_pct", "e_R_avg", "e_R_max", "e_RT"):
            table.add_row(key, f"{m[key]:.4g}")
    console.print(table)
    if note:
        console.print(f"[yellow]{note}[/]")
    console.print(f"wrote {paths['estimate']} and {paths['diagnostics']}")


def register(app: typer.Typer) -> None:
    """Register ``relnav odometry``."""
    app.command("odometry")(odometry)
