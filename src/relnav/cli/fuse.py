"""``relnav fuse``: cross-source fusion of one depth-camera scan and one LIDAR scan (paper 2)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from relnav.cli._common import console
from relnav.errors import InputError

_OUTPUTS = ("fused.ply", "lidar_in_camera.ply", "T_camera_lidar.txt", "result.json")


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(float(x)) else None


def fuse(
    camera_scan: Path = typer.Argument(..., help="Dense depth-camera cloud (any point format)."),
    lidar_scan: Path = typer.Argument(..., help="Sparse LIDAR cloud (any point format)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    m: int = typer.Option(15, "--m", min=3, help="Samples retained (paper 2: 15)."),
    seed: int = typer.Option(0, "--seed", help="Seed (recorded in result.json)."),
    method: str = typer.Option(
        "cga-sphere", "--method", help="cga-sphere (paper 2) or cbd (baseline)."
    ),
    cluster: bool = typer.Option(
        True, "--cluster/--no-cluster", help="Snap LIDAR points onto camera planes (§G.4)."
    ),
    force: bool = typer.Option(False, "--force", help="Overwrite existing outputs in --out."),
) -> None:
    """Register LIDAR_SCAN onto CAMERA_SCAN and write the fused cloud.

    Writes fused.ply (camera points + registered LIDAR points, snapped onto the camera's
    planes/lines unless --no-cluster), lidar_in_camera.ply, T_camera_lidar.txt (4x4,
    p_camera = T @ p_lidar) and result.json (RMSE in metres, timings in seconds).

    Exit code 2 when the registration is flagged (degenerate/failed); the files are still
    written (identity transform).

    Example: [bold]relnav fuse kinect/000000.ply lidar/000000.ply --out fused/ --m 15[/]
    """
    import time

    import numpy as np
    from rich.table import Table

    from relnav import __version__
    from relnav.fusion.cbd import CBDRegistration
    from relnav.fusion.clustering import cluster_and_project
    from relnav.fusion.cross_source import CrossSourceRegistration
    from relnav.geometry.rotations import rotation_angle
    from relnav.io.pointclouds import read_points, write_points

    for p, what in ((camera_scan, "camera"), (lidar_scan, "LIDAR")):
        if not p.is_file():
            raise InputError(f"{p}: no such {what} scan file")
    existing = [n for n in _OUTPUTS if (out / n).exists()]
    if existing and not force:
        raise InputError(f"{out}: would overwrite {', '.join(existing)} (use --force)")
    name = method.strip().lower()
    if name == "cga-sphere":
        reg = CrossSourceRegistration(m=m, seed=seed)
    elif name == "cbd":
        reg = CBDRegistration(seed=seed)
    else:
        raise InputError(f"--method must be 'cga-sphere' or 'cbd', got {method!r}")
    t0 = time.perf_counter()
    cam = read_points(camera_scan)
    lid = read_points(lidar_scan)
    t_read = time.perf_counter() - t0
    res = reg.register(lid, cam)
    T = res.T_target_source
    lid_c = lid @ T[:3, :3].T + T[:3, 3]
    timings = {"read": t_read, **{f"register.{k}": v for k, v in res.timings.items()}}
    n_kept = int(lid.shape[0])
    if res.ok and cluster:
        t1 = time.perf_counter()
        cl = cluster_and_project(cam, lid_c)
        timings["cluster"] = time.perf_counter() - t1
        fused = cl.fused_points
        n_kept = int(cl.kept_mask.sum())
        cl_info = {
            "planes": len(cl.planes),
            "lines": len(cl.lines),
            "delta_m": _num(cl.delta),
            "kept": n_kept,
        }
    else:
        fused = np.vstack([cam, lid_c]) if res.ok else cam
        cl_info = None
    out.mkdir(parents=True, exist_ok=True)
    write_points(out / "fused.ply", fused)
    write_points(out / "lidar_in_camera.ply", lid_c)
    np.savetxt(out / "T_camera_lidar.txt", T, fmt="%.12g")
    rot_deg = math.degrees(float(rotation_angle(T[:3, :3])))
    doc = {
        "camera_scan": str(camera_scan),
        "lidar_scan": str(lidar_scan),
        "method": name,
        "m": m,
        "seed": seed,
        "status": res.status,
        "message": res.message,
        "T_camera_lidar": T.tolist(),
        "rotation_deg": rot_deg,
        "translation_m": T[:3, 3].tolist(),
        "rmse_m": _num(res.inlier_rmse),
        "fitness": res.fitness,
        "n_camera": int(cam.shape[0]),
        "n_lidar": int(lid.shape[0]),
        "samples_retained": res.n_inliers,
        "samples_tried": res.n_correspondences,
        "n_fused": int(fused.shape[0]),
        "clustering": cl_info,
        "timings_s": timings,
        "relnav_version": __version__,
    }
    (out / "result.json").write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")

    table = Table(title=f"relnav fuse ({name}): {lidar_scan.name} → {camera_scan.name}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("status", res.status + (f" ({res.message})" if res.message else ""))
    table.add_row("points camera / LIDAR", f"{cam.shape[0]} / {lid.shape[0]}")
    rmse = "—" if not math.isfinite(res.inlier_rmse) else f"{res.inlier_rmse:.4f} m"
    table.add_row("RMSE", rmse)
    table.add_row("fitness", f"{res.fitness:.3f}")
    table.add_row("samples retained / tried", f"{res.n_inliers} / {res.n_correspondences}")
    table.add_row("rotation", f"{rot_deg:.3f} deg")
    table.add_row("translation", " ".join(f"{v:+.4f}" for v in T[:3, 3]) + " m")
    if cl_info is not None:
        table.add_row("planes / lines", f"{cl_info['planes']} / {cl_info['lines']}")
        table.add_row("LIDAR points kept", f"{n_kept} of {lid.shape[0]}")
    for k, v in timings.items():
        table.add_row(f"time {k}", f"{v:.3f} s")
    console.print(table)
    console.print(f"wrote {', '.join(_OUTPUTS)} to {out}", highlight=False)
    if not res.ok:
        raise typer.Exit(code=2)


def register(app: typer.Typer) -> None:
    """Register ``relnav fuse``."""
    app.command("fuse")(fuse)
