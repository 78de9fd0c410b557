"""Speed of the simulated sensors (prints figures; not a test).

Run:  .venv/bin/python benchmarks/speed/bench_sensors.py [--frames 30]

Measures, per frame (median and 90th percentile over poses around the target):

* one 128×128 flash-LIDAR frame (GoldenEye preset) of a 40 000-face mesh
  (``../shared/data/targets/eros.ply`` scaled to 30 m; fallback: procedural asteroid with
  81 920 faces), target filling most of the 45° field of view — goal < 20 ms;
* the raw ray cast of the same rays with our :class:`RayCaster` and with Open3D's
  ``RaycastingScene`` (same rays, same run) and the ratio ours / Open3D;
* a VLP-16 frame of the procedural Envisat, a HPR (surface-sampler) frame at ~200–3000
  visible points, and a full-resolution Kinect frame.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from relnav.geometry import from_rt
from relnav.sim.sensors import make_sensor
from relnav.sim.targets import Target, load_target, procedural_target

EROS = Path(__file__).resolve().parents[3] / "shared" / "data" / "targets" / "eros.ply"


def look_at(position: np.ndarray) -> np.ndarray:
    x = -position / np.linalg.norm(position)
    up = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    y = np.cross(up, x)
    y /= np.linalg.norm(y)
    return from_rt(np.column_stack([x, y, np.cross(x, y)]), position)


def poses(n: int, distance: float, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return [look_at(distance * u) for u in v]


def timed(f, reps: list) -> tuple[float, float, list]:
    out, ts = [], []
    for a in reps:
        t0 = time.perf_counter()
        out.append(f(a))
        ts.append(time.perf_counter() - t0)
    ms = 1e3 * np.asarray(ts)
    return float(np.median(ms)), float(np.percentile(ms, 90)), out


def row(label: str, med: float, p90: float, extra: str = "") -> None:
    print(f"{label:<48s} {med:9.2f} {p90:9.2f}  {extra}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=30)
    args = ap.parse_args()
    n = args.frames

    if EROS.is_file():
        big = load_target(EROS, scale_to=30.0)
        label = f"eros.ply ({len(big.mesh.faces)} faces, 30 m)"
    else:
        big = procedural_target("asteroid", subdivisions=6, scale_to=30.0)
        label = f"procedural asteroid ({len(big.mesh.faces)} faces, 30 m)"
    print(f"mesh: {label}")
    print(f"{'case':<48s} {'median ms':>9s} {'p90 ms':>9s}  notes")

    flash = make_sensor("goldeneye")
    rng = np.random.default_rng(0)
    P = poses(n, 45.0)
    flash.scan(big, P[0], rng)  # warm-up: numba JIT (cached) + Embree BVH
    med, p90, pts = timed(lambda T: flash.scan(big, T, rng), P)
    row(
        "flash 128x128 frame (scan, incl. noise)",
        med,
        p90,
        f"{np.mean([len(p) for p in pts]):.0f} pts",
    )

    # raw casts of all 16384 rays: ours vs Open3D on identical rays
    dirs = flash.ray_directions()
    rc = big.raycaster
    rays = []
    for T in P:
        d = dirs @ T[:3, :3].T
        rays.append((np.ascontiguousarray(np.broadcast_to(T[:3, 3], d.shape)), d))
    rc.cast(*rays[0])
    med_ours, p90_ours, _ = timed(lambda od: rc.cast(*od), rays)
    row(f"RayCaster.cast {len(dirs)} rays ({rc.backend})", med_ours, p90_ours)
    try:
        import open3d as o3d

        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor(np.asarray(big.mesh.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(big.mesh.faces, dtype=np.uint32)),
        )
        o3d_rays = [o3d.core.Tensor(np.hstack(od).astype(np.float32)) for od in rays]
        scene.cast_rays(o3d_rays[0])
        med_o3d, p90_o3d, res = timed(lambda r: scene.cast_rays(r)["t_hit"].numpy(), o3d_rays)
        row("Open3D RaycastingScene.cast_rays (same rays)", med_o3d, p90_o3d)
        ours_r = rc.cast(*rays[0])[0]
        same = np.isfinite(ours_r) == np.isfinite(res[0])
        both = np.isfinite(ours_r) & np.isfinite(res[0])
        dr = np.abs(ours_r[both] - res[0][both])
        print(
            f"ratio ours/Open3D: raw cast {med_ours / med_o3d:.2f}, full flash frame "
            f"{med / med_o3d:.2f}; hit agreement {same.mean():.4f}, "
            f"max |Δrange| {dr.max():.2e} m (Open3D float32)"
        )
    except ImportError:
        print("open3d not installed: no comparison")

    env: Target = procedural_target("envisat")
    vlp = make_sensor("vlp16")
    P30 = poses(n, 30.0, seed=1)
    vlp.scan(env, P30[0], rng)
    med, p90, pts = timed(lambda T: vlp.scan(env, T, rng), P30)
    row("VLP-16 frame, Envisat at 30 m", med, p90, f"{np.mean([len(p) for p in pts]):.0f} pts")

    for k in (200, 1000, 3000):
        hpr = make_sensor("surface-hpr", n_points=k)
        t0 = time.perf_counter()
        ns = hpr.surface_samples_for(env)
        cal = 1e3 * (time.perf_counter() - t0)
        med, p90, pts = timed(lambda T, s=hpr: s.scan(env, T, rng), P30)
        row(
            f"HPR frame, n_points={k}",
            med,
            p90,
            f"{np.mean([len(p) for p in pts]):.0f} pts from {ns} samples "
            f"(one-off calibration {cal:.0f} ms)",
        )

    kin = make_sensor("kinect1")
    cap = procedural_target("capsule")
    P4 = poses(max(5, n // 3), 4.5, seed=2)
    kin.scan(cap, P4[0], rng)
    med, p90, pts = timed(lambda T: kin.scan(cap, T, rng), P4)
    row(
        "Kinect 640x480 frame, capsule at 4.5 m",
        med,
        p90,
        f"{np.mean([len(p) for p in pts]):.0f} pts",
    )


if __name__ == "__main__":
    main()
