"""Time per frame of every registered method on the same frames, plus Open3D / small_gicp ICP.

Usage::

    .venv/bin/python benchmarks/speed/bench_registration.py [--points 500 3000] [--frames 6]
        [--target voyager] [--threads 1] [--repeat 3] [--only icp-point icp-plane ...]
        [--iterations 30] [--skip-methods]

Frames: a simulated sequence (paper 1's surface-sampling sensor with hidden-point removal,
``surface-hpr``) around a procedural target; the sensor circles the target by ``--step-deg``
(2°) per frame about the target centre, plus a 1 %-of-size translation, at 3× the target size.
Each method registers frame ``k+1`` (source) onto frame ``k`` (target) from the identity.

Part 1 — every family of :func:`relnav.registration.available_methods` (first example string;
families whose optional dependency is missing are listed as skipped): median ms per frame
(minimum of ``--repeat`` runs per pair, after a warm-up call whose extra time is reported as
compile/load overhead), mean rotation error (deg) and mean RMS displacement error of the source
points (% of the target size) against the ground truth, frames with status ``ok``.

Part 2 — our ICP against the references on the same pairs and the same settings: Open3D's
``registration_icp`` point-to-point / point-to-plane (same gate = our default ``10·Tr``, same
target normals, ``--iterations`` iterations forced with ``relative_fitness = relative_rmse = 0``)
against ours with ``open3d_compatible=True`` (also reports the largest transform difference),
and small_gicp ``align`` (``ICP`` / ``PLANE_ICP``, same gate and iteration count, convergence
epsilons 0, no downsampling). Ratios are ours / reference (< 1: ours faster). Open3D and
small_gicp are imported lazily; ``--threads`` sets ``OMP_NUM_THREADS`` before Open3D is imported
and small_gicp's ``num_threads`` (ours is single-threaded).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from typing import Any

import numpy as np

from relnav.geometry.normals import estimate_normals
from relnav.geometry.rotations import rotation_angle
from relnav.geometry.se3 import exp_se3, from_rt, invert, transform_points


def look_at(pos: np.ndarray) -> np.ndarray:
    """Sensor pose ``T_target_sensor`` at ``pos`` looking at the target origin (x forward)."""
    x = -pos / np.linalg.norm(pos)
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    return from_rt(np.column_stack([x, y, np.cross(x, y)]), pos)


def make_frames(target: str, n_points: int, n_frames: int, step_deg: float, seed: int):
    """Scans (sensor frame) and ground-truth poses ``T_target_sensor`` of a short orbit."""
    from relnav.sim.sensors import make_sensor
    from relnav.sim.targets import get_target

    rng = np.random.default_rng(seed)
    tg = get_target(target)
    sensor = make_sensor("surface-hpr", n_points=n_points)
    T = look_at(np.array([3.0 * tg.extent, 0.3 * tg.extent, 0.8 * tg.extent]))
    poses, scans = [], []
    for _ in range(n_frames):
        poses.append(T)
        scans.append(sensor.scan(tg, T, rng))
        xi = np.zeros(6)
        xi[:3] = 0.01 * tg.extent * rng.normal(size=3) / np.sqrt(3.0)
        xi[3:] = np.deg2rad(step_deg) * np.array([0.2, 0.3, 1.0]) / np.linalg.norm([0.2, 0.3, 1.0])
        T = exp_se3(xi) @ T  # about the target centre
    return scans, poses, tg.extent


def pair_errors(gt: np.ndarray, T: np.ndarray, src: np.ndarray) -> tuple[float, float]:
    d = transform_points(T, src) - transform_points(gt, src)
    rot = float(np.rad2deg(rotation_angle((invert(gt) @ T)[:3, :3])))
    return rot, float(np.sqrt((d**2).sum(axis=1).mean()))


def timed(fn, repeat: int) -> tuple[float, Any]:
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def bench_methods(pairs, extent: float, repeat: int, only: list[str] | None) -> None:
    from relnav.errors import RelnavError
    from relnav.registration import available_methods, get_registration

    head = ["ms/frame", "compile s", "rot °", "err %", "ok"]
    print(f"\n{'method':32s} {head[0]:>9s} {head[1]:>9s} {head[2]:>7s} {head[3]:>7s} {head[4]:>5s}")
    for family, meta in available_methods().items():
        spec = meta["examples"][0]
        if only and family not in only and spec not in only:
            continue
        try:
            reg = get_registration(spec)
            src, tgt, _ = pairs[0]
            t0 = time.perf_counter()
            reg.register(src, tgt)
            warm = time.perf_counter() - t0
        except (ImportError, RelnavError) as e:
            print(f"{spec:32s} skipped ({type(e).__name__}: {e})")
            continue
        times, rots, errs, n_ok = [], [], [], 0
        for src, tgt, gt in pairs:
            reg = get_registration(spec)  # fresh state (stateful adapters)
            dt, res = timed(lambda reg=reg, s=src, t=tgt: reg.register(s, t), repeat)
            times.append(dt)
            r, e = pair_errors(gt, res.T_target_source, src)
            rots.append(r)
            errs.append(100.0 * e / extent)
            n_ok += res.ok
        med = statistics.median(times)
        print(
            f"{spec:32s} {1e3 * med:9.2f} {max(warm - med, 0.0):9.2f} {np.mean(rots):7.3f} "
            f"{np.mean(errs):7.3f} {n_ok:>2d}/{len(pairs)}"
        )


def bench_references(pairs, repeat: int, iterations: int, threads: int) -> None:
    from relnav.geometry.neighbors import mean_resolution
    from relnav.registration import get_registration

    try:
        import open3d as o3d
    except ImportError:
        o3d = None
    try:
        import small_gicp
    except ImportError:
        small_gicp = None
    rows: dict[str, list[float]] = {}
    max_diff: dict[str, float] = {"point": 0.0, "plane": 0.0}
    for src, tgt, _ in pairs:
        gate = 10.0 * mean_resolution(src)  # our scale-aware default gate
        normals = estimate_normals(tgt, k=10)
        for kind in ("point", "plane"):
            ours_reg = get_registration(
                f"icp-{kind}",
                open3d_compatible=True,
                max_correspondence_distance=gate,
                max_iter=iterations,
                relative_fitness=0.0,
                relative_rmse=0.0,
            )
            tn = normals if kind == "plane" else None
            t_ours, r_ours = timed(
                lambda r=ours_reg, s=src, t=tgt, n=tn: r.register(s, t, target_normals=n), repeat
            )
            rows.setdefault(f"ours icp-{kind} (open3d_compatible)", []).append(t_ours)
            if o3d is not None:
                reg_mod = o3d.pipelines.registration
                ps = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src))
                pt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tgt))
                pt.normals = o3d.utility.Vector3dVector(normals)
                est = (
                    reg_mod.TransformationEstimationPointToPoint()
                    if kind == "point"
                    else reg_mod.TransformationEstimationPointToPlane()
                )
                crit = reg_mod.ICPConvergenceCriteria(
                    relative_fitness=0.0, relative_rmse=0.0, max_iteration=iterations
                )
                icp_fn = reg_mod.registration_icp
                t_o3d, r_o3d = timed(
                    lambda ps=ps, pt=pt, g=gate, est=est, crit=crit, f=icp_fn: f(
                        ps, pt, g, np.eye(4), est, crit
                    ),
                    repeat,
                )
                rows.setdefault(f"Open3D ICP {kind}", []).append(t_o3d)
                diff = np.abs(np.asarray(r_o3d.transformation) - r_ours.T_target_source).max()
                max_diff[kind] = max(max_diff[kind], float(diff))
            if small_gicp is not None:
                kind_sg = "ICP" if kind == "point" else "PLANE_ICP"
                pc_t = small_gicp.PointCloud(tgt)
                if kind == "plane":  # its own normals (k = 10), not timed, as ours / Open3D's
                    small_gicp.estimate_normals(pc_t, num_neighbors=10, num_threads=threads)

                def run_sg(s=src, pc_t=pc_t, g=gate, k=kind_sg):
                    tree = small_gicp.KdTree(pc_t, num_threads=threads)
                    return small_gicp.align(
                        pc_t,
                        small_gicp.PointCloud(s),
                        tree,
                        registration_type=k,
                        max_correspondence_distance=g,
                        num_threads=threads,
                        max_iterations=iterations,
                        rotation_epsilon=0.0,
                        translation_epsilon=0.0,
                    )

                t_sg, _ = timed(run_sg, repeat)
                rows.setdefault(f"small_gicp {kind_sg}", []).append(t_sg)
    med = {k: statistics.median(v) for k, v in rows.items()}
    print(f"\n{iterations} iterations each, same gate (10·Tr), same target normals:")
    for k, v in med.items():
        print(f"  {k:40s} {1e3 * v:9.3f} ms/frame")
    for kind in ("point", "plane"):
        ours = med[f"ours icp-{kind} (open3d_compatible)"]
        if o3d is not None:
            ref = med[f"Open3D ICP {kind}"]
            print(
                f"  ratio ours/Open3D icp-{kind}: {ours / ref:5.2f}   "
                f"(max |ΔT| = {max_diff[kind]:.1e})"
            )
        sg = med.get(f"small_gicp {'ICP' if kind == 'point' else 'PLANE_ICP'}")
        if sg is not None:
            print(f"  ratio ours/small_gicp icp-{kind}: {ours / sg:5.2f}")
    if o3d is None:
        print("  (open3d not installed: Open3D rows skipped)")
    if small_gicp is None:
        print("  (small_gicp not installed: small_gicp rows skipped)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, nargs="+", default=[500, 3000])
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--target", default="voyager")
    ap.add_argument("--step-deg", type=float, default=2.0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--iterations", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--skip-methods", action="store_true", help="only the reference comparison")
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", str(args.threads))
    print(
        f"target {args.target}, {args.frames} frames, step {args.step_deg}°, seed {args.seed}, "
        f"threads for Open3D/small_gicp: {os.environ['OMP_NUM_THREADS']}/{args.threads} "
        "(ours: 1)"
    )
    for n in args.points:
        scans, poses, extent = make_frames(args.target, n, args.frames, args.step_deg, args.seed)
        pairs = [
            (scans[k + 1], scans[k], invert(poses[k]) @ poses[k + 1]) for k in range(len(scans) - 1)
        ]
        sizes = [len(s) for s in scans]
        print(f"\n=== surface-hpr n_points={n}: {min(sizes)}–{max(sizes)} points per scan ===")
        if not args.skip_methods:
            bench_methods(pairs, extent, args.repeat, args.only)
        bench_references(pairs, args.repeat, args.iterations, args.threads)


if __name__ == "__main__":
    main()
