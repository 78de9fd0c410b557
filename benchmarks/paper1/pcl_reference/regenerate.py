"""Regenerate ``tests/data/pcl/pcl_reference.npz``: PCL 1.13 descriptors on relnav clouds.

Usage (needs Debian's ``libpcl-dev`` and cmake; the tests do NOT need PCL)::

    benchmarks/paper1/pcl_reference/build.sh            # builds build/pcl_reference
    python benchmarks/paper1/pcl_reference/regenerate.py [--out tests/data/pcl/pcl_reference.npz]
    python benchmarks/paper1/pcl_reference/compare.py    # relnav vs the fixture, per descriptor

(``--gp3-mu 4 --gp3-radius-factor 10 --out /tmp/mu4.npz`` writes PCL's outputs on a denser greedy
mesh; ``compare.py --other /tmp/mu4.npz`` then correlates PCL's RoPS on the two meshes.)

For each cloud (procedural ``voyager`` and ``asteroid`` targets, seed 0) ``N_POINTS`` area-weighted
uniform surface samples are drawn (``np.random.default_rng(SEED)``) with their exact face normals,
rounded to float32 (both sides then read the same numbers). The support radius is
``RADIUS_FACTOR`` × the mean resolution; ``N_KEYPOINTS`` keypoints are drawn without replacement.
The C++ program (``pcl_reference.cpp``) computes on these points:

* ``SpinImageEstimation`` (image width 8, support-angle cosine 0 = disabled, min neighbours 0),
  rotation axis = input normal;
* ``GreedyProjectionTriangulation`` of the whole cloud (search radius ``GP3_RADIUS_FACTOR`` ×
  resolution, mu 2.5, 100 neighbours, PCL-tutorial angles) and ``ROPSEstimation`` on that mesh
  (5 bins, 3 rotations, support radius = radius);
* ``FPFHEstimation`` and ``SHOTEstimation`` (radius, normals as given);
* ``ROPSEstimation`` at each keypoint alone (``setIndices`` with that keypoint, the search
  surface still the whole cloud) with ``setTriangles`` = that keypoint's local triangles, the
  mesh relnav's default RoPS builds its frame from (``relnav.geometry.lrf.rops_local_mesh`` on the
  float32 points as float64, default ``max_edge`` = 3·Tr): the like-for-like reference of the
  default ``rops``.

The npz holds, per cloud ``c``: ``c/points``, ``c/normals`` (N, 3) float32, ``c/keypoints`` (K,)
int32, ``c/radius``, ``c/triangles`` (M, 3) int32 (PCL's mesh), ``c/spin`` (K, 153),
``c/rops`` (K, 135), ``c/fpfh`` (K, 33), ``c/shot`` (K, 352) float32 (NaN where PCL gives NaN),
``c/rops_local`` (K, 135) float32 (PCL's RoPS on the local triangles; NaN for a keypoint without
any) and those triangles as CSR ``c/rops_local_offsets`` (K + 1,) and ``c/rops_local_triangles``
(M, 3) int32 (keypoint ``k``'s are rows ``offsets[k]:offsets[k + 1]``).
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from relnav.geometry import mean_resolution
from relnav.geometry.lrf import rops_local_mesh
from relnav.sim.sensors import SurfaceSampler
from relnav.sim.targets import procedural_target

HERE = Path(__file__).resolve().parent
CLOUDS = ("voyager", "asteroid")
SEED = 16
N_POINTS = 1500
N_KEYPOINTS = 150
RADIUS_FACTOR = 10.0
GP3_RADIUS_FACTOR = 6.0
SPIN_WIDTH = 8
GP3_MU = 2.5


def make_cloud(
    name: str, seed: int = SEED, gp3_mu: float = GP3_MU, gp3_rf: float = GP3_RADIUS_FACTOR
) -> dict[str, np.ndarray]:
    """Surface samples, normals, keypoints and radius of one fixture cloud (float32 points)."""
    target = procedural_target(name, seed=0)
    rng = np.random.default_rng(seed)
    sampler = SurfaceSampler.__new__(SurfaceSampler)  # only its (static) sampling tables
    pts, f = SurfaceSampler.sample_surface(sampler, target, N_POINTS, rng)
    normals = SurfaceSampler._sampling_tables(target)[4][f]
    pts = pts.astype(np.float32)
    normals = normals.astype(np.float32)
    res = mean_resolution(pts.astype(np.float64))
    kp = np.sort(rng.choice(N_POINTS, size=N_KEYPOINTS, replace=False)).astype(np.int32)
    radius = np.float32(RADIUS_FACTOR * res)
    # the local meshes exactly as the default rops(points, kp, radius=radius) builds them
    tri_off, tris = rops_local_mesh(pts.astype(np.float64), kp, float(radius))
    return {
        "points": pts,
        "normals": normals,
        "keypoints": kp,
        "radius": radius,
        "gp3_radius": np.float32(gp3_rf * res),
        "gp3_mu": np.float32(gp3_mu),
        "rops_local_offsets": tri_off.astype(np.int32),
        "rops_local_triangles": tris.astype(np.int32),
    }


def run_pcl(exe: Path, cloud: dict[str, np.ndarray], work: Path) -> dict[str, np.ndarray]:
    """Write the binary input, run the C++ program, read its binary output."""
    inp = work / "in.bin"
    out = work / "out.bin"
    n = cloud["points"].shape[0]
    k = cloud["keypoints"].shape[0]
    with open(inp, "wb") as fh:
        np.array([n, k, SPIN_WIDTH], dtype=np.int32).tofile(fh)
        np.array([cloud["radius"], cloud["gp3_radius"], cloud["gp3_mu"]], dtype=np.float32).tofile(
            fh
        )
        np.hstack([cloud["points"], cloud["normals"]]).astype(np.float32).tofile(fh)
        cloud["keypoints"].astype(np.int32).tofile(fh)
        np.array([cloud["rops_local_triangles"].shape[0]], dtype=np.int32).tofile(fh)
        cloud["rops_local_offsets"].astype(np.int32).tofile(fh)
        cloud["rops_local_triangles"].astype(np.int32).tofile(fh)
    subprocess.run([str(exe), str(inp), str(out)], check=True)
    raw = out.read_bytes()
    res: dict[str, np.ndarray] = {}
    pos = 0
    for name in ("spin", "rops", "fpfh", "shot", "triangles", "rops_local"):
        rows, cols = np.frombuffer(raw, dtype=np.int32, count=2, offset=pos)
        pos += 8
        dt = np.int32 if name == "triangles" else np.float32
        a = np.frombuffer(raw, dtype=dt, count=int(rows) * int(cols), offset=pos)
        pos += a.nbytes
        res[name] = a.reshape(int(rows), int(cols)).copy()
    if pos != len(raw):
        raise RuntimeError(f"unexpected output size {len(raw)} (read {pos})")
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--exe", type=Path, default=HERE / "build" / "pcl_reference")
    ap.add_argument(
        "--out", type=Path, default=HERE.parents[2] / "tests" / "data" / "pcl" / "pcl_reference.npz"
    )
    ap.add_argument("--gp3-mu", type=float, default=GP3_MU, help="greedy projection mu")
    ap.add_argument(
        "--gp3-radius-factor", type=float, default=GP3_RADIUS_FACTOR, help="search radius / Tr"
    )
    args = ap.parse_args()
    arrays: dict[str, np.ndarray] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in CLOUDS:
            cloud = make_cloud(name, gp3_mu=args.gp3_mu, gp3_rf=args.gp3_radius_factor)
            res = run_pcl(args.exe, cloud, Path(tmp))
            for key, val in {**cloud, **res}.items():
                arrays[f"{name}/{key}"] = np.asarray(val)
            print(
                f"{name}: {cloud['points'].shape[0]} points, "
                f"radius {float(cloud['radius']):.4g} m, "
                f"{res['triangles'].shape[0]} PCL triangles, "
                f"{cloud['rops_local_triangles'].shape[0]} local triangles"
            )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.out, **arrays)
    print(f"wrote {args.out} ({args.out.stat().st_size / 1024:.0f} kB)")


if __name__ == "__main__":
    main()
