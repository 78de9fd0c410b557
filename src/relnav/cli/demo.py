"""``relnav demo``: simulate → estimate → evaluate → plot on a built-in scenario, no data needed."""

from __future__ import annotations

from pathlib import Path

import typer

from relnav.cli._common import console, progress_bar

DEMO_PRESET = "sim-voyager"
DEMO_FRAMES = 60
DEMO_METHODS = ("feature:hods+gcc+alphabeta", "feature:hods+gcc+svd", "icp-point", "extended")
EXTENDED = (
    "feature:hods+gcc+svd",
    {
        "grouper_options": {"seeds": "all"},
        "refine": "icp-plane",
        "gate_rotation_deg": 15.0,
    },
)
"""``extended`` in ``--method``: paper 1's HoD-S pipeline with relnav's extensions — GCC seeded
from every correspondence, SVD, point-to-plane ICP refinement and a 15° innovation gate."""
TABLE_KEYS = (
    ("e_T_avg", "m"),
    ("e_T_max", "m"),
    ("drift", "m"),
    ("T_error_pct", "%"),
    ("e_R_avg", "deg"),
    ("e_R_max", "deg"),
    ("e_RT", ""),
    ("rpe_trans_rmse", "m"),
    ("rpe_rot_rmse_deg", "deg"),
    ("time_ms", "ms/frame (median)"),
)


def demo(
    out: Path = typer.Option(Path("relnav-demo"), "--out", "-o", help="Output folder."),
    preset: str = typer.Option(DEMO_PRESET, "--preset", help="Scenario preset to simulate."),
    frames: int = typer.Option(
        DEMO_FRAMES, "--frames", help="Frames (the first N of the preset, at its own rate)."
    ),
    seed: int = typer.Option(0, "--seed", help="Simulation seed."),
    method: list[str] = typer.Option(
        list(DEMO_METHODS),
        "--method",
        "-m",
        help="Methods to compare (first = main); 'extended' = HoD-S with relnav's extensions.",
    ),
) -> None:
    """Run the whole chain on a built-in scenario (procedural target, ~60 frames).

    Writes sequence/, estimate.tum (first method), estimate_<method>.tum, metrics.json,
    diagnostics.csv and trajectory.png to --out.
    """
    import json

    from rich.table import Table

    from relnav.eval.metrics import evaluate_trajectories
    from relnav.eval.plots import plot_trajectories
    from relnav.io.sequences import ScanSequence
    from relnav.odometry import run_sequence
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    out.mkdir(parents=True, exist_ok=True)
    seq_dir = out / "sequence"
    scenario = get_preset(preset, max_frames=frames, seed=seed)
    with progress_bar() as bar:
        task = bar.add_task(f"simulate {preset}", total=min(frames, scenario.frames))
        simulate(scenario, seq_dir, progress=lambda *a: bar.advance(task), overwrite=True)
        seq = ScanSequence(seq_dir)
        runs = {}
        for m in method:
            task = bar.add_task(m, total=len(seq))
            name, options = EXTENDED if m == "extended" else (m, {})
            runs[m] = run_sequence(
                seq, name, progress=lambda i, s, t=task: bar.advance(t), **options
            )

    metrics: dict[str, dict] = {}
    for i, (m, run) in enumerate(runs.items()):
        res = evaluate_trajectories(run.timestamps, run.poses, seq.timestamps, seq.gt_poses)
        res["time_ms"] = run.median_time_ms
        res["time_ms_mean"] = run.mean_time_ms
        res["flagged_frames"] = run.n_flagged
        metrics[m] = res
        if i == 0:
            run.write(out)
        else:
            from relnav.io.trajectories import write_tum

            safe = m.replace(":", "_").replace("+", "_")
            write_tum(out / f"estimate_{safe}.tum", run.timestamps, run.poses)
    (out / "metrics.json").write_text(
        json.dumps({"preset": preset, "frames": frames, "seed": seed, "methods": metrics}, indent=2)
    )
    plot_trajectories(
        out / "trajectory.png",
        seq.gt_poses,
        {m: r.poses for m, r in runs.items()},
        title=f"relnav demo — {preset}, {len(seq)} frames",
    )

    table = Table(title=f"relnav demo — {preset} ({len(seq)} frames, seed {seed})")
    table.add_column("metric")
    table.add_column("unit")
    for m in runs:
        table.add_column(m, justify="right")
    for key, unit in TABLE_KEYS:
        table.add_row(key, unit, *(f"{metrics[m][key]:.4g}" for m in runs))
    table.add_row("flagged frames", "", *(str(metrics[m]["flagged_frames"]) for m in runs))
    console.print(table)
    console.print(f"wrote {out / 'estimate.tum'}, {out / 'metrics.json'}, {out / 'trajectory.png'}")


def register(app: typer.Typer) -> None:
    """Register ``relnav demo``."""
    app.command("demo")(demo)
