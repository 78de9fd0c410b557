"""Time per frame of relnav's navigator alone on suite sequences, and whether its poses changed.

Runs ``run_sequence(seq, 'relnav')`` ``--repeats`` times per sequence (the scans are read once,
into memory, so file reading is not timed; a warm-up run on a few frames compiles numba first)
and prints the median over the runs of the median ms per frame, with the spread of the runs.
``--save FILE`` writes every sequence's final poses (``.npz``); ``--compare FILE`` prints the
largest pose difference from such a file (translation m, rotation entries), so that a speed
change can be checked for unchanged results before the suite is run. ``--kiss`` also times
KISS-ICP (``run_sequence(seq, 'kiss-icp')``) in the same conditions and prints the ratio.

    python benchmarks/speed/bench_navigator.py --only asteroid-helical-128,voyager-ellipse-128 \\
        --repeats 3 --save /tmp/before.npz
    python benchmarks/speed/bench_navigator.py --only asteroid-helical-128 --compare /tmp/before.npz

Timings are of a shared machine: compare before/after in the same conditions.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from relnav.io.sequences import ScanSequence
from relnav.pipeline import run_sequence


class _InMemory:
    """A sequence's scans read once (``__getitem__``/``__len__``/``gt_poses`` of the original)."""

    def __init__(self, seq: ScanSequence) -> None:
        self.scans = [seq[i] for i in range(len(seq))]
        self.gt_poses = seq.gt_poses
        self.timestamps = seq.timestamps

    def __len__(self) -> int:
        return len(self.scans)

    def __getitem__(self, i: int) -> Any:
        return self.scans[i]


def time_method(seq: _InMemory, method: str, repeats: int, **options: Any) -> dict[str, Any]:
    """Median ms per frame of each of ``repeats`` runs, the poses of the last run, wall s."""
    run_sequence(seq, method, max_frames=min(5, len(seq)), **options)  # compile / warm up
    ms, walls, poses = [], [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        run = run_sequence(seq, method, **options)
        walls.append(time.perf_counter() - t0)
        ms.append(float(run.median_time_ms))
        poses = run.poses
    return {"ms": ms, "wall": walls, "poses": poses}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("/work/nav"), help="nav_suite.py's --out")
    p.add_argument("--only", default="asteroid-helical-128,voyager-ellipse-128")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--save", type=Path, default=None, help="write the poses (.npz)")
    p.add_argument("--compare", type=Path, default=None, help="compare with saved poses")
    p.add_argument("--kiss", action="store_true", help="time KISS-ICP too")
    p.add_argument("-O", dest="options", action="append", default=[], help="relnav key=value")
    a = p.parse_args(argv)
    opts = dict(o.split("=", 1) for o in a.options)
    saved: dict[str, np.ndarray] = {}
    ref = dict(np.load(a.compare)) if a.compare else {}
    for name in [s for s in a.only.split(",") if s]:
        seq = _InMemory(ScanSequence(a.out / "sequences" / name))
        r = time_method(seq, "relnav", a.repeats, **opts)
        saved[name] = r["poses"]
        line = (
            f"{name:22s} relnav  median {statistics.median(r['ms']):7.2f} ms/frame  "
            f"runs {' '.join(f'{m:.2f}' for m in r['ms'])}  "
            f"wall {statistics.median(r['wall']):6.2f} s"
        )
        if a.kiss:
            k = time_method(seq, "kiss-icp", a.repeats)
            km = statistics.median(k["ms"])
            line += f"  kiss-icp {km:6.2f} ms  ratio {statistics.median(r['ms']) / km:5.2f}"
        if name in ref:
            d = r["poses"] - ref[name]
            dt, dr = np.abs(d[:, :3, 3]).max(), np.abs(d[:, :3, :3]).max()
            line += f"  Δt max {dt:.1e} m  ΔR max {dr:.1e}"
        print(line, flush=True)
    if a.save:
        np.savez(a.save, **saved)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
