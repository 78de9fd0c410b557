"""``relnav view``: a picture of a sequence — scans in the target frame and the sensor path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer

from relnav.cli._common import console
from relnav.errors import InputError


def render_sequence(
    folder: Path,
    out: Path,
    *,
    frames: int = 6,
    sensor: str | None = None,
    max_points: int = 20000,
    seed: int = 0,
) -> Path:
    """Plot ``frames`` evenly spaced scans of ``folder`` in the target frame plus the sensor path.

    Each scan is mapped with its ground truth ``T_target_sensor``; the ground-truth sensor
    positions are drawn as a line (start marked). Scans are subsampled (seeded) to
    ``max_points`` in total for drawing only.

    Raises
    ------
    InputError
        Missing folder, no scans, or no ground truth.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from relnav.geometry.se3 import transform_points
    from relnav.io.sources import open_sequence

    seq = open_sequence(folder, sensor=sensor or None)
    n = len(seq)
    if n == 0:
        raise InputError(f"{folder}: no scans to view")
    gt = getattr(seq, "gt_poses", None)
    if gt is None:
        raise InputError(
            f"{folder}: no ground truth (a recording or a plain folder has none); relnav view "
            "draws scans in the target frame, with the ground truth's poses"
        )
    k = max(1, min(int(frames), n))
    idx = np.unique(np.round(np.linspace(0, n - 1, k)).astype(int))
    rng = np.random.default_rng(seed)
    per = max(1, max_points // len(idx))

    clouds: list[tuple[int, np.ndarray]] = []
    for i in idx:
        pts = seq[int(i)].points
        if len(pts) > per:
            pts = pts[rng.choice(len(pts), per, replace=False)]
        if len(pts):
            clouds.append((int(i), transform_points(gt[i], pts)))
    path = gt[:, :3, 3]

    fig = plt.figure(figsize=(15, 7))
    cmap = plt.get_cmap("viridis")
    sensor_name = getattr(seq, "sensor", None)
    name = f" ({sensor_name})" if sensor_name else ""
    for panel, with_path in ((1, True), (2, False)):
        ax = fig.add_subplot(1, 2, panel, projection="3d")
        for j, (i, p_t) in enumerate(clouds):
            ax.scatter(
                p_t[:, 0],
                p_t[:, 1],
                p_t[:, 2],
                s=1.5 if with_path else 2.5,
                color=cmap(j / max(len(clouds) - 1, 1)),
                label=f"scan {i}",
                depthshade=False,
            )
        bounds = [c for _, c in clouds]
        if with_path:
            ax.plot(path[:, 0], path[:, 1], path[:, 2], "k-", lw=1.0, label="sensor (GT)")
            ax.scatter(*path[0], color="red", s=20, marker="o", label="start")
            ax.scatter(*path[idx, :].T, color="k", s=10, marker="^")
            bounds.append(path)
            ax.set_title(f"{Path(folder).name}{name}: sensor path and {len(clouds)} of {n} scans")
        else:
            ax.set_title("scans in the target frame (ground truth)")
        P = np.vstack(bounds) if bounds else np.zeros((1, 3))
        lo, hi = P.min(axis=0), P.max(axis=0)
        c, r = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2, 1e-6)
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[1] - r, c[1] + r)
        ax.set_zlim(c[2] - r, c[2] + r)
        ax.set_box_aspect((1, 1, 1))
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        if with_path:
            leg = ax.legend(loc="upper left", fontsize=7, markerscale=3)
            for h, t in zip(leg.legend_handles, leg.get_texts(), strict=True):
                if t.get_text() == "start" and hasattr(h, "set_sizes"):
                    h.set_sizes([25.0])  # markerscale is for the tiny scan dots only
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out


def view(
    folder: Path = typer.Argument(
        ..., help="Sequence folder (scans/ + ground truth), or any input relnav reads."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output image (.png, .pdf, .svg)."),
    frames: int = typer.Option(6, "--frames", "-k", min=1, help="Number of scans to draw."),
    sensor: str | None = typer.Option(
        None, "--sensor", help="Second sensor's name (scans_<name>/); default the primary."
    ),
    rrd: Path | None = typer.Option(
        None, "--rrd", help="Also write every scan to a Rerun recording (extra \\[viz])."
    ),
    estimate: list[Path] | None = typer.Option(
        None, "--estimate", help="Estimated TUM trajectory to add to the .rrd (repeatable)."
    ),
    live: bool = typer.Option(
        False,
        "--live",
        help="Stream every scan to the Rerun viewer (extra \\[viz]); headless: writes OUT.rrd.",
    ),
) -> None:
    """Draw a few scans mapped into the target frame with the ground truth, and the sensor path.

    Example: [bold]relnav view seq --out seq.png --frames 8 --rrd seq.rrd[/]
    """
    render_sequence(folder, out, frames=frames, sensor=sensor)
    console.print(f"wrote {out}")
    if rrd is not None or live:
        from relnav.eval.rerun_export import export_rrd
        from relnav.io.trajectories import read_tum

        est = {p.stem: read_tum(p)[1] for p in estimate or []}
        target = rrd if rrd is not None else out.with_suffix(".rrd")
        written = export_rrd(folder, target, estimates=est, sensor=sensor, live=live)
        console.print(f"wrote {written}" if written else "streamed to the Rerun viewer")


def register(app: typer.Typer) -> None:
    """Register ``relnav view`` on ``app``."""
    app.command("view")(view)
