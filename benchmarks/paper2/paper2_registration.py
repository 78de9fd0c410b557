"""Paper 2's registration experiment (§3.1.1, Fig. 6; §4, Fig. 15) on simulated li-rotating data.

Grid: 6 distances (1.2, 2, 3, 4, 5, 6 m) × rotation about x, y, z × 16 frames at 22.5°
(``relnav.sim.presets`` ``li-rotating``: Kinect v1 + HDL-64, target scaled to the Kinect's field
at each distance). Methods: ``cga-sphere`` (paper 2, m = 15), ``cbd`` (paper 2's CBD baseline,
our interpretation) and ``icp-point`` (relnav's point-to-point ICP started from the centroid
alignment, identity rotation — **[interpretation]**: ICP needs a start; FMR, paper 2's deep
baseline, is out of scope). Then RMSE and time of ``cga-sphere`` vs ``m ∈ {5, 10, 15, 20, 30}``.

Error measures per frame pair (ground truth ``T_camera_lidar = inv(T_target_cam) T_target_lidar``):

* ``rmse_gt`` — RMS over the LIDAR points of ``‖T_est p − T_gt p‖`` (m): the registration error
  (the main measure; paper 2 does not define its RMSE);
* ``rmse_nn`` — RMS distance of the registered LIDAR points to the nearest camera point, over the
  LIDAR points that truly overlap the camera cloud (GT-registered point within 3 cm of a camera
  point) (m): the fusion residual, floor = sensor noise;
* ``rot_err_deg``, ``trans_err_m``, ``status``, ``time_s``.

Writes ``registration.csv``, ``m_sweep.csv``, ``summary.txt`` and ``fig6_rmse_vs_angle.png``,
``fig6d_rmse_vs_distance.png``, ``fig15_m_sweep.png`` into ``--out``; simulated sequences are
kept in ``--out/sequences`` and reused.

    .venv/bin/python benchmarks/paper2/paper2_registration.py --out results/paper2 [--frames 16]
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

DISTANCES = (1.2, 2.0, 3.0, 4.0, 5.0, 6.0)
AXES = ("x", "y", "z")
M_VALUES = (5, 10, 15, 20, 30)


def _sequence(root: Path, d: float, axis: str, frames: int) -> Path:
    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    seq = root / f"li_{axis}_{d:g}_{frames}"
    if not (seq / "scans_lidar").is_dir():
        sc = get_preset("li-rotating", distance=d, axis=axis, frames=frames)
        simulate(sc.model_copy(update={"format": "npy"}), seq, overwrite=True)
    return seq


def _errors(
    T: np.ndarray, T_gt: np.ndarray, L: np.ndarray, tree_c: Any, overlap: np.ndarray
) -> dict[str, float]:
    from relnav.geometry.rotations import rotation_angle

    Le = L @ T[:3, :3].T + T[:3, 3]
    Lg = L @ T_gt[:3, :3].T + T_gt[:3, 3]
    d, _ = tree_c.query(Le[overlap]) if overlap.any() else (np.zeros(0), None)
    return {
        "rmse_gt": float(np.sqrt(np.mean(np.sum((Le - Lg) ** 2, axis=1)))),
        "rmse_nn": float(np.sqrt(np.mean(d**2))) if d.size else float("nan"),
        "rot_err_deg": float(np.degrees(rotation_angle(T[:3, :3].T @ T_gt[:3, :3]))),
        "trans_err_m": float(np.linalg.norm(T[:3, 3] - T_gt[:3, 3])),
    }


def _methods(seed: int) -> dict[str, Any]:
    from relnav.fusion.cbd import CBDRegistration
    from relnav.fusion.cross_source import CrossSourceRegistration
    from relnav.registration import get_registration

    return {
        "cga-sphere": CrossSourceRegistration(m=15, seed=seed),
        "cbd": CBDRegistration(seed=seed),
        "icp-point": get_registration("icp-point"),
    }


def run(a: argparse.Namespace) -> None:
    from scipy.spatial import cKDTree

    from relnav.fusion.cross_source import CrossSourceRegistration
    from relnav.geometry.se3 import from_rt, invert
    from relnav.io.sequences import ScanSequence

    out: Path = a.out
    out.mkdir(parents=True, exist_ok=True)
    seq_root = out / "sequences"
    methods = {k: v for k, v in _methods(a.seed).items() if k in a.methods}
    rows: list[dict[str, Any]] = []
    sweep: list[dict[str, Any]] = []
    t_all = time.perf_counter()
    for d in a.distances:
        for axis in a.axes:
            seq = _sequence(seq_root, d, axis, a.frames)
            cam = ScanSequence(seq)
            lid = ScanSequence(seq, sensor="lidar")
            for k in range(len(cam)):
                C, L = cam[k].points, lid[k].points
                T_gt = invert(cam.gt_poses[k]) @ lid.gt_poses[k]
                tree_c = cKDTree(C)
                dg, _ = tree_c.query(L @ T_gt[:3, :3].T + T_gt[:3, 3])
                overlap = dg < 0.03
                base = {
                    "distance_m": d,
                    "axis": axis,
                    "frame": k,
                    "angle_deg": 22.5 * k,
                    "n_camera": C.shape[0],
                    "n_lidar": L.shape[0],
                    "overlap": float(overlap.mean()),
                }
                for name, reg in methods.items():
                    init = None
                    if name == "icp-point":
                        init = from_rt(np.eye(3), C.mean(axis=0) - L.mean(axis=0))
                    t0 = time.perf_counter()
                    res = reg.register(L, C, init=init)
                    dt = time.perf_counter() - t0
                    rows.append(
                        {
                            **base,
                            "method": name,
                            "status": res.status,
                            "time_s": dt,
                            **_errors(res.T_target_source, T_gt, L, tree_c, overlap),
                        }
                    )
                for m in a.m_values:
                    reg = CrossSourceRegistration(m=m, seed=a.seed)
                    t0 = time.perf_counter()
                    res = reg.register(L, C)
                    dt = time.perf_counter() - t0
                    sweep.append(
                        {
                            **base,
                            "m": m,
                            "status": res.status,
                            "retained": res.n_inliers,
                            "time_s": dt,
                            **_errors(res.T_target_source, T_gt, L, tree_c, overlap),
                        }
                    )
            print(f"done d={d:g} m axis={axis} ({time.perf_counter() - t_all:.0f} s)", flush=True)
    _write_csv(out / "registration.csv", rows)
    _write_csv(out / "m_sweep.csv", sweep)
    summary = _summary(rows, sweep, a)
    (out / "summary.txt").write_text(summary)
    print(summary)
    _plots(out, rows, sweep, a)
    print(f"wrote {out}/registration.csv, m_sweep.csv, summary.txt and 3 figures")


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    if not rows:
        return
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def _agg(rows: list[dict[str, Any]], key: str, **sel: Any) -> tuple[float, float, int]:
    v = [r[key] for r in rows if all(r[k] == x for k, x in sel.items())]
    v = [x for x in v if isinstance(x, float | int) and math.isfinite(x)]
    if not v:
        return float("nan"), float("nan"), 0
    return float(np.median(v)), float(np.mean(v)), len(v)


def _summary(rows: list[dict[str, Any]], sweep: list[dict[str, Any]], a: Any) -> str:
    lines = ["paper 2 registration experiment (li-rotating), median / mean over frames", ""]
    lines.append("rmse_gt (m) by distance:")
    hdr = "method        " + " ".join(f"{d:>13g}" for d in a.distances) + "     all (med/mean)"
    lines.append(hdr)
    for name in a.methods:
        cells = []
        for d in a.distances:
            med, mean, _ = _agg(rows, "rmse_gt", method=name, distance_m=d)
            cells.append(f"{med:6.4f}/{mean:6.4f}")
        med, mean, n = _agg(rows, "rmse_gt", method=name)
        ok = sum(r["status"] == "ok" for r in rows if r["method"] == name)
        lines.append(f"{name:<13} " + " ".join(cells) + f"   {med:6.4f}/{mean:6.4f} (ok {ok}/{n})")
    lines += ["", "rmse_nn (m, fusion residual over the true overlap) by distance:"]
    for name in a.methods:
        cells = [
            f"{_agg(rows, 'rmse_nn', method=name, distance_m=d)[0]:13.4f}" for d in a.distances
        ]
        lines.append(f"{name:<13} " + " ".join(cells))
    lines += ["", "median rotation error (deg) / median time (s):"]
    for name in a.methods:
        lines.append(
            f"{name:<13} rot {_agg(rows, 'rot_err_deg', method=name)[0]:.2f} deg, "
            f"time {_agg(rows, 'time_s', method=name)[0]:.3f} s"
        )
    lines += ["", "by axis (rmse_gt median, m):"]
    for name in a.methods:
        cells = [f"{ax}: {_agg(rows, 'rmse_gt', method=name, axis=ax)[0]:.4f}" for ax in a.axes]
        lines.append(f"{name:<13} " + ", ".join(cells))
    if sweep:
        lines += ["", "cga-sphere vs m: rmse_gt median / mean (m), time median (s), ok"]
        for m in a.m_values:
            med, mean, n = _agg(sweep, "rmse_gt", m=m)
            ok = sum(r["status"] == "ok" for r in sweep if r["m"] == m)
            t = _agg(sweep, "time_s", m=m)[0]
            lines.append(f"m={m:<3} {med:.4f} / {mean:.4f}   {t:.3f} s   ok {ok}/{n}")
    return "\n".join(lines) + "\n"


def _plots(out: Path, rows: list[dict[str, Any]], sweep: list[dict[str, Any]], a: Any) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    angles = sorted({r["angle_deg"] for r in rows})
    fig, axs = plt.subplots(1, len(a.axes), figsize=(5 * len(a.axes), 4), squeeze=False)
    for ax, axis in zip(axs[0], a.axes, strict=True):
        for name in a.methods:
            y = [_agg(rows, "rmse_gt", method=name, axis=axis, angle_deg=g)[0] for g in angles]
            ax.plot(angles, y, marker="o", label=name)
        ax.set_title(f"rotation about {axis} (median over distances)")
        ax.set_xlabel("attitude angle (deg)")
        ax.set_ylabel("RMSE vs ground truth (m)")
        ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(out / "fig6_rmse_vs_angle.png", dpi=120)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    for name in a.methods:
        y = [_agg(rows, "rmse_gt", method=name, distance_m=d)[0] for d in a.distances]
        ax.plot(a.distances, y, marker="o", label=name)
    ax.set_xlabel("distance (m)")
    ax.set_ylabel("median RMSE vs ground truth (m)")
    ax.set_yscale("log")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "fig6d_rmse_vs_distance.png", dpi=120)
    plt.close(fig)

    if sweep:
        fig, ax = plt.subplots(figsize=(6, 4))
        ms = list(a.m_values)
        ax.plot(ms, [_agg(sweep, "rmse_gt", m=m)[0] for m in ms], "o-", label="median RMSE")
        ax.set_xlabel("m (retained samples)")
        ax.set_ylabel("RMSE vs ground truth (m)")
        ax2 = ax.twinx()
        ax2.plot(ms, [_agg(sweep, "time_s", m=m)[0] for m in ms], "s--", color="C1", label="time")
        ax2.set_ylabel("median time (s)")
        ax.grid(True, alpha=0.3)
        fig.legend(loc="upper center")
        fig.tight_layout()
        fig.savefig(out / "fig15_m_sweep.png", dpi=120)
        plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="output folder")
    ap.add_argument("--frames", type=int, default=16, help="frames per sequence (22.5° steps)")
    ap.add_argument("--distances", type=float, nargs="+", default=list(DISTANCES))
    ap.add_argument("--axes", nargs="+", default=list(AXES), choices=AXES)
    ap.add_argument(
        "--methods",
        nargs="+",
        default=["cga-sphere", "cbd", "icp-point"],
        choices=["cga-sphere", "cbd", "icp-point"],
    )
    ap.add_argument("--m-values", type=int, nargs="*", default=list(M_VALUES))
    ap.add_argument("--seed", type=int, default=0)
    run(ap.parse_args())


if __name__ == "__main__":
    main()
