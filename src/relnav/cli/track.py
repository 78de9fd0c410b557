"""``relnav track``: Paper 2's tracking (twistor UKF or quaternion EKF) over a sequence folder.

Writes ``OUT/target_pose.tum`` (the target's pose ``T_sensor_body``; ``target_pose_gt.tum``
with ground truth), ``OUT/track.csv`` (per step: position, velocity, Euler angles, angular
velocity with 1σ, the observation and, with ground truth, truth and errors),
``OUT/track.png`` (estimate vs truth, Paper 2 Figs. 8/13), ``OUT/track_errors.png`` (errors
with ±3σ bounds, Fig. 14) and ``OUT/track.json`` (settings, summary, and ``consistency``: mean
NIS over the updates and, with ground truth, mean NEES, each with the 95 % χ² band of such a
mean). ``track.csv`` carries ``nis`` per update and ``nees`` per step (with ground truth).
"""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
import typer

from relnav.cli._common import consistency_meaning, console, parse_options, progress_bar
from relnav.eval.track_plots import plot_track, plot_track_errors


class FilterChoice(StrEnum):
    """Filter to run."""

    ukf = "ukf"
    ekf = "ekf"


def write_track_tum(result: Any, out: Path) -> list[Path]:
    """The target's pose ``T_sensor_body`` per step as TUM: ``target_pose.tum`` (estimate,
    steps before initialisation left out) and ``target_pose_gt.tum`` (truth, when known), so
    ``relnav evaluate``, ``relnav compare`` and evo read them."""
    from relnav.geometry.rotations import quat_to_matrix
    from relnav.io.trajectories import write_tum

    def poses(pos: np.ndarray, quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ok = np.isfinite(pos).all(axis=1) & np.isfinite(quat).all(axis=1)
        T = np.tile(np.eye(4), (int(ok.sum()), 1, 1))
        q = quat[ok] / np.linalg.norm(quat[ok], axis=1, keepdims=True)
        T[:, :3, :3] = quat_to_matrix(q)
        T[:, :3, 3] = pos[ok]
        return np.asarray(result.time)[ok], T

    written = [write_tum(out / "target_pose.tum", *poses(result.position, result.quat))]
    if result.truth is not None:
        tr = result.truth
        written.append(write_tum(out / "target_pose_gt.tum", *poses(tr.position, tr.quat)))
    return written


def track(
    seq_dir: Path = typer.Argument(..., help="Sequence folder (scans/ = camera, scans_<name>/)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    filter: FilterChoice = typer.Option(FilterChoice.ukf, "--filter", "-f", help="ukf | ekf"),
    observer: str = typer.Option(
        None,
        "--observer",
        help="contour | registration[:METHOD] (default: contour model when available).",
    ),
    second_sensor: str = typer.Option(
        "auto", "--second-sensor", help="Second sensor name, 'auto' or 'none'."
    ),
    n_mean_motion: float = typer.Option(
        None, "--n-mean-motion", help="CW mean motion, rad/s (default 0: force-free)."
    ),
    orbit_radius: float = typer.Option(
        None, "--orbit-radius", help="Circular orbit radius (m, from Earth's centre) → n."
    ),
    omega0_deg: str = typer.Option(
        None, "--omega0", help="Initial body rate 'wx,wy,wz' in deg/s (Paper 2: 0,0,5)."
    ),
    max_frames: int = typer.Option(None, "--max-frames", help="Use the first N frames."),
    gt_alignment: str = typer.Option(
        "auto",
        "--gt-alignment",
        help="Truth in the estimate's body frame: auto | mean | first | first-rotation | "
        "centre | none (auto: centre for a filter estimating the rotation centre, else mean).",
    ),
    seed: int = typer.Option(0, "--seed", help="Observer seed."),
    option: list[str] = typer.Option(
        None,
        "--option",
        "-O",
        help="Filter option key=value (repeatable), e.g. -O q.attitude=1e-4 -O kappa=0.",
    ),
    observer_noise: str = typer.Option(
        None,
        "--observer-noise",
        help="Contour observer's noise: calibrated (default; Paper 2's simulation, one model "
        "with --omega0 and one without) | reported "
        "(its jackknife covariance) | FILE.json (relnav.fusion.observer_noise.ObserverNoise).",
    ),
    plots: bool = typer.Option(True, "--plots/--no-plots", help="Write the PNG figures."),
) -> None:
    """Estimate the target's relative position, velocity, attitude and angular velocity.

    Example: [bold]relnav track seq/ --out runs/track --filter ukf --omega0 0,0,5[/]
    """
    from rich.table import Table

    from relnav.errors import InputError
    from relnav.fusion.tracker import track_sequence

    opts: dict[str, Any] = parse_options(option)
    if n_mean_motion is not None:
        opts["n_mean_motion"] = n_mean_motion
    if orbit_radius is not None:
        opts["orbit_radius_m"] = orbit_radius
    if omega0_deg is not None:
        try:
            w = [float(x) for x in omega0_deg.split(",")]
        except ValueError:
            raise InputError(f"--omega0 must be 'wx,wy,wz' in deg/s, got {omega0_deg!r}") from None
        if len(w) != 3:
            raise InputError(f"--omega0 needs three values, got {omega0_deg!r}")
        opts["omega0"] = np.radians(w)
    second = None if second_sensor.lower() == "none" else second_sensor
    out = Path(out)
    with progress_bar() as bar:
        task = bar.add_task(f"track ({filter.value})", total=None)
        result = track_sequence(
            seq_dir,
            filter=filter.value,
            observer=observer,
            second_sensor=second,
            max_frames=max_frames,
            gt_alignment=gt_alignment,  # type: ignore[arg-type]
            seed=seed,
            progress=lambda i, n: bar.update(task, completed=i, total=n),
            observer_noise=observer_noise,
            **opts,
        )
    out.mkdir(parents=True, exist_ok=True)
    csv_path = result.to_csv(out / "track.csv")
    written = [csv_path]
    summary = result.summary() if result.truth is not None else None
    info = {
        "filter": result.filter,
        "settings": result.settings,
        "meta": result.meta,
        "frames": len(result),
        "updates": int(result.updated.sum()),
        "flagged": result.n_flagged,
        "summary_after_20pct": summary,
        "consistency": result.consistency(),
    }
    (out / "track.json").write_text(json.dumps(info, indent=2, default=str))
    written.append(out / "track.json")
    written += write_track_tum(result, out)
    if plots:
        written.append(plot_track(result, out / "track.png"))
        if result.truth is not None:
            written.append(plot_track_errors(result, out / "track_errors.png"))

    table = Table(title=f"track — {result.filter.upper()} ({result.meta.get('observer')})")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("frames", str(len(result)))
    table.add_row("updates", str(info["updates"]))
    table.add_row("flagged (predicted through)", str(result.n_flagged))
    last = ~np.isnan(result.position[:, 0])
    if np.any(last):
        k = int(np.flatnonzero(last)[-1])
        table.add_row("final ω (deg/s)", ", ".join(f"{x:.3f}" for x in np.degrees(result.omega[k])))
    for key, label in (("nis", "mean NIS (6 dof)"), ("nees", "mean NEES (12 dof)")):
        c = info["consistency"].get(key)
        if c is not None:
            lo, hi = c["band"]
            flag = "" if lo <= c["mean"] <= hi else " (outside)"
            table.add_row(f"{label}, 95 % band", f"{c['mean']:.3g} [{lo:.2f}, {hi:.2f}]{flag}")
    if summary is not None:
        for key, unit in (
            ("position", "m"),
            ("velocity", "m/s"),
            ("attitude", "deg"),
            ("omega", "deg/s"),
        ):
            rms = summary[key]["rms"]
            table.add_row(f"RMS {key} error x,y,z ({unit})", ", ".join(f"{x:.4g}" for x in rms))
    console.print(table)
    if result.n_flagged:
        console.print(
            f"[yellow]flagged[/]: {result.n_flagged} of {len(result)} frames had no usable "
            "measurement (registration flagged or missing); the filter predicted through them",
            highlight=False,
        )
    for key, label in (("nis", "NIS"), ("nees", "NEES")):
        c = info["consistency"].get(key)
        if c is not None and (note := consistency_meaning(label, c["mean"], c["band"])):
            console.print(f"[yellow]alarm[/]: {note}", highlight=False)
    from relnav.io.runinfo import run_info, write_run_info
    from relnav.io.sequences import ScanSequence

    written.append(
        write_run_info(
            out,
            run_info(
                command="track",
                method=f"{result.filter}:{result.meta.get('observer')}",
                options={
                    "filter_options": opts,
                    "gt_alignment": result.meta.get("gt_alignment", gt_alignment),
                    "second_sensor": second_sensor,
                    "max_frames": max_frames,
                    "observer_noise": observer_noise,
                },
                sequence=ScanSequence(seq_dir),
                seed=seed,
                outputs=[p.name for p in written] + ["run.json"],
                extra={"flags": {"frames": len(result), "flagged": int(result.n_flagged)}},
            ),
        )
    )
    console.print("wrote " + ", ".join(str(p) for p in written))


def register(app: typer.Typer) -> None:
    """Register ``relnav track``."""
    app.command("track")(track)
