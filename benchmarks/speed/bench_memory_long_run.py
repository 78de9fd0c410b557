"""Peak memory of ``relnav odometry`` on a short and a long run (issue 11, item 16).

Usage::

    python benchmarks/speed/bench_memory_long_run.py [--preset sim-bennu] [--frames 2000 20000]
        [--method icp-point] [--workdir /tmp/relnav-mem]

Simulates the longest run once (``--frames max --max-frames N`` keeps the per-frame motion of
every run identical: the short run is a prefix of the long one), then runs
``relnav odometry --max-frames N`` in a fresh process per length and reads its peak resident
set size (``wait4`` ``ru_maxrss``). Long runs must stay flat: the streamed CLI keeps only the
poses (128 B/frame) and flags, so the long/short ratio should be close to 1 (target: within
10 %). Not a test: it takes minutes for 20 000 frames.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path


def _peak_rss_mb(cmd: list[str]) -> tuple[float, float, int]:
    """Run ``cmd``; its peak RSS (MB), wall time (s) and exit code."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode:
        sys.stderr.write(p.stderr.read().decode() if p.stderr else "")
    return usage.ru_maxrss / 1024.0, time.perf_counter() - t0, p.returncode


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="sim-bennu")
    ap.add_argument("--frames", type=int, nargs="+", default=[2000, 20000])
    ap.add_argument("--method", action="append", default=None)
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/relnav-mem"))
    args = ap.parse_args()
    methods = args.method or ["icp-point"]
    relnav = [sys.executable, "-c", "from relnav.cli.main import main; main()"]
    n_max = max(args.frames)
    seq = args.workdir / f"{args.preset}-{n_max}"
    if not (seq / "timestamps.txt").is_file():
        t0 = time.perf_counter()
        subprocess.run(
            [
                *relnav,
                "simulate",
                args.preset,
                "--frames",
                str(n_max),
                "--out",
                str(seq),
                "--overwrite",
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        print(f"simulated {n_max} frames of {args.preset} in {time.perf_counter() - t0:.0f} s")
    print(f"{'method':28s} {'frames':>7s} {'peak RSS MB':>12s} {'wall s':>8s}")
    for method in methods:
        peaks = {}
        for n in sorted(args.frames):
            out = args.workdir / f"run-{method.replace(':', '_')}-{n}"
            cmd = [
                *relnav,
                "odometry",
                str(seq),
                "-m",
                method,
                "--max-frames",
                str(n),
                "--out",
                str(out),
            ]
            mb, wall, rc = _peak_rss_mb(cmd)
            peaks[n] = mb
            print(f"{method:28s} {n:7d} {mb:12.1f} {wall:8.1f}" + ("" if rc == 0 else f" rc={rc}"))
        lo, hi = min(args.frames), max(args.frames)
        print(f"{method}: peak RSS {hi} / {lo} frames = {peaks[hi] / peaks[lo]:.3f}")


if __name__ == "__main__":
    main()
