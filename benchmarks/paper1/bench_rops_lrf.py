"""CPU time of RoPS per frame with its two frames: local mesh (default) vs points.

For the first ``--frames`` scans of each sequence (``relnav simulate PRESET --out DIR``), describes
every point (the feature pipeline's default keypoints) with radius ``20·Tr`` (RoPS's registered
factor) and prints the median **process CPU time** per frame (numba single-threaded; CPU time is
used because the machine may be shared, which inflates wall-clock times), the frame-computation
share and the ratio local_mesh / points. Compilation is excluded (one warm-up call).

Run: ``python benchmarks/paper1/bench_rops_lrf.py SEQ_DIR [SEQ_DIR ...] [--frames 10]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from relnav.features.rops import rops
from relnav.geometry import mean_resolution
from relnav.geometry.lrf import _rops_lrf_csr, _support_csr
from relnav.io.pointclouds import read_points


def cpu_ms(fn) -> float:
    t = time.process_time()
    fn()
    return 1e3 * (time.process_time() - t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seqs", nargs="+", type=Path)
    ap.add_argument("--frames", type=int, default=10)
    args = ap.parse_args()
    warm = np.random.default_rng(0).random((50, 3))
    for lrf in ("points", "local_mesh"):
        rops(warm, np.arange(5), radius=0.5, lrf=lrf)
    print("| sequence | points/frame | RoPS points (ms) | RoPS local_mesh (ms) | ratio "
          "| of which frame: points / local_mesh (ms) |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for seq in args.seqs:
        scans = sorted((seq / "scans").glob("*"))[: args.frames]
        res = {"points": [], "local_mesh": []}
        frame = {"points": [], "local_mesh": []}
        sizes = []
        for f in scans:
            P = read_points(f)
            kp = np.arange(len(P))
            r = 20.0 * mean_resolution(P)
            sizes.append(len(P))
            flat, off = _support_csr(P, kp, r)
            for lrf in res:
                res[lrf].append(cpu_ms(lambda: rops(P, kp, radius=r, lrf=lrf)))  # noqa: B023
                frame[lrf].append(
                    cpu_ms(lambda: _rops_lrf_csr(P, kp, flat, off, r, None, 1e-10, lrf))  # noqa: B023
                )
        a = np.median(res["points"])
        b = np.median(res["local_mesh"])
        print(
            f"| {seq.name} | {np.median(sizes):.0f} | {a:.1f} | {b:.1f} | {b / a:.2f} "
            f"| {np.median(frame['points']):.1f} / {np.median(frame['local_mesh']):.1f} |"
        )


if __name__ == "__main__":
    main()
