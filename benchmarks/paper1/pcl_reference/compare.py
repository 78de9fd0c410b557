"""Per-keypoint correlation of relnav's descriptors with PCL 1.13's (the committed fixture).

Run: ``python benchmarks/paper1/pcl_reference/compare.py
[--fixture tests/data/pcl/pcl_reference.npz]
[--other OTHER.npz]`` — prints, per cloud and descriptor, the median and 5th percentile of the
Pearson correlation over the keypoints finite on both sides. The default RoPS is compared with
both PCL references: ``rops_local`` (PCL on the same local triangles, like for like) and ``rops``
(PCL on its greedy-projection mesh). ``--other`` (a fixture regenerated with other
greedy-projection settings) adds PCL's RoPS on that mesh against PCL's RoPS on the fixture's mesh.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from relnav.features.fpfh import fpfh
from relnav.features.rops import rops
from relnav.features.shot import shot
from relnav.features.trisi import spin

FIXTURE = Path(__file__).resolve().parents[3] / "tests" / "data" / "pcl" / "pcl_reference.npz"


def corr(a: np.ndarray, b: np.ndarray) -> str:
    """Median (5th percentile, rows) of the per-row Pearson correlation."""
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    x = a[ok].astype(np.float64)
    y = b[ok].astype(np.float64)
    x -= x.mean(axis=1, keepdims=True)
    y -= y.mean(axis=1, keepdims=True)
    c = (x * y).sum(axis=1) / np.sqrt((x * x).sum(axis=1) * (y * y).sum(axis=1))
    return f"{np.median(c):.4f} (p5 {np.percentile(c, 5):.4f}, n={ok.sum()})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fixture", type=Path, default=FIXTURE)
    ap.add_argument("--other", type=Path)
    args = ap.parse_args()
    Z = np.load(args.fixture)
    O = np.load(args.other) if args.other else None
    for c in ("voyager", "asteroid"):
        P = Z[f"{c}/points"].astype(np.float64)
        N = Z[f"{c}/normals"].astype(np.float64)
        kp = Z[f"{c}/keypoints"].astype(np.int64)
        r = float(Z[f"{c}/radius"])
        T = Z[f"{c}/triangles"]
        default = rops(P, kp, radius=r)
        rows = [
            ("spin layout=pcl", spin(P, kp, radius=r, normals=N, layout="pcl"), "spin"),
            ("RoPS on PCL's mesh", rops(P, kp, radius=r, triangles=T), "rops"),
            ("RoPS default vs PCL, same local mesh", default, "rops_local"),
            ("RoPS default vs PCL's greedy mesh", default, "rops"),
            ("RoPS lrf=points vs greedy mesh", rops(P, kp, radius=r, lrf="points"), "rops"),
            ("FPFH", fpfh(P, kp, radius=r, normals=N), "fpfh"),
            ("SHOT layout=pcl", shot(P, kp, radius=r, normals=N, layout="pcl"), "shot"),
        ]
        for name, D, key in rows:
            print(f"{c:9s} {name:37s} {corr(D, Z[f'{c}/{key}'])}")
        if O is not None:
            print(f"{c:9s} {'PCL RoPS, other mesh':37s} {corr(O[f'{c}/rops'], Z[f'{c}/rops'])}")


if __name__ == "__main__":
    main()
