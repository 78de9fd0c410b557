"""``relnav demo``: simulate → estimate → evaluate → plot on a built-in scenario, no data needed."""

from __future__ import annotations

from pathlib import Path

import typer

from relnav.cli._common import console, progress_bar

DEMO_PRESET = "sim-voyager"
DEMO_FRAMES = 60
DEMO_METHODS = ("relnav", "paper1", "icp-point")
"""relnav's navigator, paper 1's pipeline as published, plain ICP (``--method extended`` adds
paper 1's descriptors with relnav's extensions)."""
DEMO_PEER = "kiss-icp"
"""The best peer of the navigation suite, added to the demo when ``[baselines]`` is installed."""


def default_methods() -> list[str]:
    """:data:`DEMO_METHODS`, plus :data:`DEMO_PEER` when its package is importable."""
    import importlib.util

    peer = [DEMO_PEER] if importlib.util.find_spec("kiss_icp") is not None else []
    return [*DEMO_METHODS, *peer]


TABLE_KEYS = (
    ("e_T_avg", "m"),
    ("e_T_max", "m"),
    ("drift", "m"),
    ("T_error_pct", "%"),
    ("e_R_avg", "deg"),
    ("e_R_max", "deg"),
    ("e_RT", "m²+deg²"),
    ("rpe_trans_rmse", "m"),
    ("rpe_rot_rmse", "deg"),
    ("time_ms", "ms"),
)
"""Rows of the demo table (``relnav evaluate --metrics`` defines each key)."""


def short_labels(methods: list[str], width: int = 10) -> dict[str, str]:
    """Column labels that fit an 80-column table: the name itself when it is at most ``width``
    characters (presets, ``icp-point``), else a letter ``A``, ``B``, … (explained in a legend)."""
    out: dict[str, str] = {}
    letters = iter("ABCDEFGHIJKLMNOPQRSTUVWXYZ")
    for m in methods:
        out[m] = m if len(m) <= width else next(letters)
    return out


def run_folder_name(method: str) -> str:
    """A file-system-safe folder name for a method string or preset."""
    import re

    return re.sub(r"[^A-Za-z0-9_.-]+", "_", method).strip("_") or "method"


def demo(
    out: Path = typer.Option(Path("relnav-demo"), "--out", "-o", help="Output folder."),
    preset: str = typer.Option(DEMO_PRESET, "--preset", help="Scenario preset to simulate."),
    frames: int = typer.Option(
        DEMO_FRAMES, "--frames", help="Frames (the first N of the preset, at its own rate)."
    ),
    seed: int = typer.Option(0, "--seed", help="Simulation seed."),
    method: list[str] = typer.Option(
        None,
        "--method",
        "-m",
        help="Methods or presets to compare (`relnav methods`); default: relnav, paper1, "
        "icp-point, and kiss-icp when [baselines] is installed.",
    ),
) -> None:
    """Run the whole chain on a built-in scenario (procedural target, ~60 frames).

    Writes OUT/sequence/, one folder per method OUT/runs/<method>/ (estimate.tum,
    diagnostics.csv, metrics.json, errors.png, run.json), and OUT/metrics.json,
    OUT/trajectory.png, OUT/errors.png and OUT/run.json for all methods together.
    """
    import json
    import time

    from rich.table import Table

    from relnav.cli.evaluate import json_safe
    from relnav.cli.odometry import write_run_outputs
    from relnav.eval.metrics import match_trajectories
    from relnav.eval.plots import plot_errors, plot_trajectories
    from relnav.io.runinfo import run_info, write_run_info
    from relnav.io.sequences import ScanSequence
    from relnav.odometry import run_sequence
    from relnav.odometry.presets import resolve_method
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    method = list(method) if method else default_methods()
    resolved = {m: resolve_method(m) for m in method}  # unknown names fail before any work
    labels = short_labels(list(method))
    out.mkdir(parents=True, exist_ok=True)
    seq_dir = out / "sequence"
    scenario = get_preset(preset, max_frames=frames, seed=seed)
    timings: dict[str, float] = {}
    with progress_bar() as bar:
        task = bar.add_task(f"simulate {preset}", total=min(frames, scenario.frames))
        t0 = time.perf_counter()
        simulate(scenario, seq_dir, progress=lambda *a: bar.advance(task), overwrite=True)
        timings["simulate_s"] = time.perf_counter() - t0
        seq = ScanSequence(seq_dir)
        runs = {}
        for m in method:
            name, options, _ = resolved[m]
            task = bar.add_task(m, total=len(seq))
            runs[m] = run_sequence(
                seq, name, progress=lambda i, s, t=task: bar.advance(t), **options
            )

    metrics: dict[str, dict] = {}
    folders: dict[str, str] = {}
    for m, run in runs.items():
        folder = out / "runs" / run_folder_name(m)
        metrics[m] = write_run_outputs(
            folder, run, seq, command="demo", preset=resolved[m][2], seed=seed
        )
        folders[m] = str(folder.relative_to(out))
    (out / "metrics.json").write_text(
        json.dumps(
            {
                "preset": preset,
                "frames": frames,
                "seed": seed,
                "folders": folders,
                "methods": {m: json_safe(v) for m, v in metrics.items()},
            },
            indent=2,
        )
    )
    title = f"relnav demo — {preset}, {len(seq)} frames, seed {seed}"
    plot_trajectories(
        out / "trajectory.png", seq.gt_poses, {m: r.poses for m, r in runs.items()}, title=title
    )
    matched = {
        m: match_trajectories(r.timestamps, r.poses, seq.timestamps, seq.gt_poses)
        for m, r in runs.items()
    }
    first = next(iter(matched.values()))
    plot_errors(
        out / "errors.png",
        first.gt_poses,
        {m: mt.est_poses for m, mt in matched.items()},
        times=first.times,
        title=f"{title}: error with respect to the ground truth",
    )
    write_run_info(
        out,
        run_info(
            command="demo",
            method=None,
            options={
                m: {"method": resolved[m][0], "preset": resolved[m][2], "options": resolved[m][1]}
                for m in method
            },
            sequence=seq,
            seed=seed,
            timings=timings,
            outputs=["metrics.json", "trajectory.png", "errors.png", "run.json", *folders.values()],
            extra={"scenario_preset": preset},
        ),
    )

    table = Table(title=f"relnav demo — {preset} ({len(seq)} frames, seed {seed})")
    table.add_column("metric")
    table.add_column("unit")
    for m in runs:
        table.add_column(labels[m], justify="right")
    for key, unit in TABLE_KEYS:
        table.add_row(key, unit, *(f"{metrics[m][key]:.4g}" for m in runs))
    table.add_row("flagged", "frames", *(str(metrics[m]["flagged_frames"]) for m in runs))
    console.print(table)
    for m in runs:
        legend = f"{labels[m]} = {m}" if labels[m] != m else m
        console.print(f"  {legend}: {folders[m]}/", highlight=False)
    console.print(
        "  time_ms = median per frame; `relnav evaluate --metrics` defines every metric",
        highlight=False,
    )
    console.print(
        f"wrote {out / 'metrics.json'}, {out / 'trajectory.png'}, {out / 'errors.png'}, "
        f"{out / 'run.json'}",
        highlight=False,
    )


def register(app: typer.Typer) -> None:
    """Register ``relnav demo``."""
    app.command("demo")(demo)
