"""``relnav fuse``: cross-source fusion of one depth-camera scan and one LIDAR scan (paper 2)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import typer

from relnav.cli._common import console
from relnav.errors import InputError

_OUTPUTS = ("fused.ply", "lidar_in_camera.ply", "T_camera_lidar.txt", "result.json")


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(float(x)) else None


def fuse_sequence(
    seq_dir: Path,
    out: Path,
    *,
    reg_factory: Any,
    second_sensor: str = "auto",
    max_frames: int | None = None,
    force: bool = False,
) -> dict[str, Any]:
    """Register every LIDAR scan of a sequence onto the camera scan of the same time.

    The sequence's primary sensor (``scans/``) is the camera, ``scans_<name>/`` the LIDAR. The
    ground truth of the two sensors gives the true ``T_camera_lidar = T_tc⁻¹ T_tl`` per frame,
    so every frame gets a rotation error (geodesic, degrees) and a translation error (metres).
    Frames are paired by timestamp (nearest, within 1 ms).

    Writes ``OUT/fuse.csv`` (one row per pair), ``OUT/fuse.json`` (summary, settings) and
    ``OUT/fuse_errors.png``; returns the summary.
    """
    import csv
    import time

    import numpy as np

    from relnav.eval.metrics import associate
    from relnav.geometry.rotations import rotation_angle
    from relnav.geometry.se3 import invert
    from relnav.io.sequences import ScanSequence

    cam = ScanSequence(seq_dir)
    names = [n for n in ScanSequence.sensors(seq_dir) if n]
    if second_sensor == "auto":
        if len(names) != 1:
            raise InputError(
                f"{seq_dir}: give --second-sensor (second sensors: {', '.join(names) or 'none'})"
            )
        second_sensor = names[0]
    lid = ScanSequence(seq_dir, sensor=second_sensor)
    existing = [n for n in ("fuse.csv", "fuse.json") if (out / n).exists()]
    if existing and not force:
        raise InputError(f"{out}: would overwrite {', '.join(existing)} (use --force)")
    i_cam, i_lid = associate(lid.timestamps, cam.timestamps, max_diff=1e-3)
    pairs = list(zip(i_lid.tolist(), i_cam.tolist(), strict=True))
    if not pairs:
        raise InputError(f"{seq_dir}: no camera and {second_sensor} scans share a timestamp")
    if max_frames is not None:
        pairs = pairs[: int(max_frames)]
    G_c, G_l = cam.gt_poses, lid.gt_poses
    rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    for k, (il, ic) in enumerate(pairs):
        reg = reg_factory()
        t1 = time.perf_counter()
        res = reg.register(lid[il].points, cam[ic].points)
        dt = time.perf_counter() - t1
        T = res.T_target_source
        row: dict[str, Any] = {
            "pair": k,
            "time": float(cam.timestamps[ic]),
            "camera_frame": ic,
            "lidar_frame": il,
            "status": res.status,
            "rmse_m": res.inlier_rmse,
            "time_s": dt,
            "rot_err_deg": float("nan"),
            "trans_err_m": float("nan"),
        }
        if G_c is not None and G_l is not None:
            T_true = invert(G_c[ic]) @ G_l[il]
            E = invert(T_true) @ T
            row["rot_err_deg"] = math.degrees(float(rotation_angle(E[:3, :3])))
            row["trans_err_m"] = float(np.linalg.norm(T[:3, 3] - T_true[:3, 3]))
        rows.append(row)
    total = time.perf_counter() - t0
    out.mkdir(parents=True, exist_ok=True)
    with (out / "fuse.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    ok = [r for r in rows if r["status"] == "ok"]

    def _stats(key: str) -> dict[str, float | None]:
        v = np.array([r[key] for r in ok], dtype=float)
        v = v[np.isfinite(v)]
        if not v.size:
            return {"median": None, "min": None, "max": None, "rmse": None}
        return {
            "median": float(np.median(v)),
            "min": float(v.min()),
            "max": float(v.max()),
            "rmse": float(np.sqrt(np.mean(v**2))),
        }

    summary = {
        "sequence": str(seq_dir),
        "camera": "scans",
        "lidar": f"scans_{second_sensor}",
        "pairs": len(rows),
        "ok": len(ok),
        "flagged": len(rows) - len(ok),
        "rotation_error_deg": _stats("rot_err_deg"),
        "translation_error_m": _stats("trans_err_m"),
        "has_ground_truth": G_c is not None and G_l is not None,
        "total_s": total,
    }
    _plot_fuse(out / "fuse_errors.png", rows, title=f"relnav fuse — {seq_dir.name}")
    return summary


def _plot_fuse(path: Path, rows: list[dict[str, Any]], *, title: str) -> Path:
    """Rotation and translation error of every pair (flagged pairs marked)."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 5.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax_r, ax_t = fig.subplots(2, 1, sharex=True)
    k = np.array([r["pair"] for r in rows])
    ok = np.array([r["status"] == "ok" for r in rows])
    for ax, key, lab in (
        (ax_r, "rot_err_deg", "rotation error [deg]"),
        (ax_t, "trans_err_m", "translation error [m]"),
    ):
        v = np.array([r[key] for r in rows], dtype=float)
        ax.plot(k[ok], v[ok], "o-", color="tab:blue", ms=4, lw=1.2, label="ok")
        if (~ok).any():
            ax.plot(k[~ok], v[~ok], "x", color="tab:red", ms=7, label="flagged (identity)")
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    ax_t.set_xlabel("pair (camera scan, LIDAR scan of the same time)")
    ax_t.xaxis.get_major_locator().set_params(integer=True)
    ax_r.legend(fontsize="small")
    fig.suptitle(title + ": T_camera_lidar against the ground truth")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


def fuse(
    camera_scan: Path = typer.Argument(
        ...,
        help="Dense depth-camera cloud (any point format), or a sequence folder "
        "(scans/ = camera, scans_<name>/ = LIDAR) to fuse every frame against its ground truth.",
    ),
    lidar_scan: Path | None = typer.Argument(
        None, help="Sparse LIDAR cloud (any point format); omit for a sequence folder."
    ),
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
    second_sensor: str = typer.Option(
        "auto", "--second-sensor", help="Sequence mode: the LIDAR's name (scans_<name>/)."
    ),
    max_frames: int | None = typer.Option(
        None, "--max-frames", min=1, help="Sequence mode: only the first N pairs."
    ),
) -> None:
    """Register LIDAR_SCAN onto CAMERA_SCAN and write the fused cloud.

    Writes fused.ply (camera points + registered LIDAR points, snapped onto the camera's
    planes/lines unless --no-cluster), lidar_in_camera.ply, T_camera_lidar.txt (4x4,
    p_camera = T @ p_lidar) and result.json (RMSE in metres, timings in seconds).

    Exit code 2 when the registration is flagged (degenerate/failed); the files are still
    written (identity transform).

    With a sequence folder instead of two files, every LIDAR scan is registered onto the
    camera scan of the same time and compared with the ground truth: fuse.csv (per pair:
    rotation error in degrees, translation error in metres, status), fuse.json (summary) and
    fuse_errors.png.

    Examples: [bold]relnav fuse kinect/000000.ply lidar/000000.ply --out fused/ --m 15[/],
    [bold]relnav fuse seq/ --out fused/[/]
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

    name = method.strip().lower()
    if name not in ("cga-sphere", "cbd"):
        raise InputError(f"--method must be 'cga-sphere' or 'cbd', got {method!r}")

    def make() -> Any:
        return (
            CrossSourceRegistration(m=m, seed=seed)
            if name == "cga-sphere"
            else (CBDRegistration(seed=seed))
        )

    if camera_scan.is_dir() and lidar_scan is None:
        summary = fuse_sequence(
            camera_scan,
            out,
            reg_factory=make,
            second_sensor=second_sensor,
            max_frames=max_frames,
            force=force,
        )
        summary.update(method=name, m=m, seed=seed, relnav_version=__version__)
        (out / "fuse.json").write_text(
            json.dumps(summary, indent=2, allow_nan=False, default=_num) + "\n"
        )
        from relnav.io.runinfo import run_info, write_run_info
        from relnav.io.sequences import ScanSequence

        write_run_info(
            out,
            run_info(
                command="fuse",
                method=name,
                options={"m": m, "cluster": cluster, "second_sensor": second_sensor},
                sequence=ScanSequence(camera_scan),
                seed=seed,
                timings={"total_s": summary["total_s"]},
                outputs=["fuse.csv", "fuse.json", "fuse_errors.png", "run.json"],
                extra={"flags": {"pairs": summary["pairs"], "flagged": summary["flagged"]}},
            ),
        )
        table = Table(title=f"relnav fuse ({name}) over {camera_scan}: {summary['pairs']} pairs")
        table.add_column("quantity")
        table.add_column("median", justify="right")
        table.add_column("min", justify="right")
        table.add_column("max", justify="right")
        for key, unit in (("rotation_error_deg", "deg"), ("translation_error_m", "m")):
            st = summary[key]
            table.add_row(
                f"{key} ({unit})",
                *("—" if st[s] is None else f"{st[s]:.4g}" for s in ("median", "min", "max")),
            )
        table.add_row("flagged pairs", str(summary["flagged"]), "", "")
        console.print(table)
        if summary["flagged"]:
            console.print(
                f"[yellow]flagged[/]: {summary['flagged']} of {summary['pairs']} pairs did not "
                "register (degenerate or failed): their transform is the identity, not an "
                "estimate (marked x in fuse_errors.png)",
                highlight=False,
            )
        console.print(f"wrote fuse.csv, fuse.json, fuse_errors.png to {out}", highlight=False)
        return
    if lidar_scan is None:
        raise InputError("give CAMERA_SCAN and LIDAR_SCAN files, or one sequence folder")
    for p, what in ((camera_scan, "camera"), (lidar_scan, "LIDAR")):
        if not p.is_file():
            raise InputError(f"{p}: no such {what} scan file")
    existing = [n for n in _OUTPUTS if (out / n).exists()]
    if existing and not force:
        raise InputError(f"{out}: would overwrite {', '.join(existing)} (use --force)")
    reg = make()
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
