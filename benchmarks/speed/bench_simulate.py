"""Time the simulation of a preset on one core (default: 250-frame sim-voyager).

Usage::

    python benchmarks/speed/bench_simulate.py [--preset sim-voyager] [--frames 250] [--repeat 3]

One warm-up run (numba JIT, target construction caches) precedes the timed runs. The process
is pinned to one CPU and BLAS/numba thread pools are limited to one thread. Prints the wall
time per run and the per-stage split reported by :func:`relnav.sim.scenario.simulate`
(setup = target + trajectory + attitude + sensors, scan = sensor simulation, write = files).
Target: < 10 s for 250 frames of sim-voyager.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="sim-voyager")
    ap.add_argument("--frames", type=int, default=250)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    if hasattr(os, "sched_setaffinity"):
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})

    from relnav.sim.presets import get_preset
    from relnav.sim.scenario import simulate

    sc = get_preset(args.preset, frames=args.frames, seed=args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        simulate(sc, Path(tmp) / "warmup")
        print(f"warm-up: {time.perf_counter() - t0:.2f} s (includes JIT and imports)")
        totals = []
        for r in range(args.repeat):
            t0 = time.perf_counter()
            summary = simulate(sc, Path(tmp) / f"run{r}")
            wall = time.perf_counter() - t0
            totals.append(wall)
            t = summary.timings
            s = summary.sensors[0]
            print(
                f"run {r}: {wall:.2f} s wall | setup {t['setup']:.2f} s, scan {t['scan']:.2f} s, "
                f"write {t['write']:.2f} s | {1e3 * wall / sc.frames:.1f} ms/frame | "
                f"mean {s.mean_points:.1f} pts/scan"
            )
    print(
        f"{args.preset}, {sc.frames} frames, 1 core: median {statistics.median(totals):.2f} s "
        f"(target < 10 s)"
    )


if __name__ == "__main__":
    main()
