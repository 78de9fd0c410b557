"""Speed of relnav.matching: NN matching, GCC, RANSAC (50 000 iterations), CLGV.

Run: ``.venv/bin/python benchmarks/speed/bench_matching.py`` (prints figures; nothing is asserted).
Each figure is the best of ``--repeat`` runs after a warm-up call (numba JIT / cache load).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from relnav.geometry import mean_resolution, random_transform, transform_points
from relnav.matching import (
    Correspondences,
    clgv_select,
    geometric_consistency_grouping,
    match_descriptors,
    ransac_search,
)


def best_of(fn: Callable[[], object], repeat: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def problem(seed: int, n_corr: int, outlier_frac: float = 0.5):
    rng = np.random.default_rng(seed)
    n_pts = max(3000, 2 * n_corr)
    tgt = rng.uniform(-1.0, 1.0, (n_pts, 3))
    T = random_transform(rng, max_translation=0.5)
    src = transform_points(np.linalg.inv(T), tgt)
    tr = mean_resolution(src)
    src = src + rng.normal(0.0, 0.1 * tr, src.shape)
    si = rng.choice(n_pts, n_corr, replace=False)
    ti = si.copy()
    w = rng.random(n_corr) < outlier_frac
    ti[w] = rng.integers(0, n_pts, w.sum())
    return src, tgt, Correspondences(si, ti, rng.random(n_corr)), tr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(0)

    print("NN matching (exact, float32 matrix product, tau = 1)")
    for k, dim in [(500, 33), (1000, 352), (3000, 135)]:
        a = rng.gamma(0.5, size=(k, dim)).astype(np.float32)
        b = rng.gamma(0.5, size=(k, dim)).astype(np.float32)
        t = best_of(lambda a=a, b=b: match_descriptors(a, b), args.repeat)
        tm = best_of(lambda a=a, b=b: match_descriptors(a, b, mutual=True), args.repeat)
        print(f"  {k:5d} x {k:5d}, D={dim:3d}: {t * 1e3:8.2f} ms   (mutual {tm * 1e3:8.2f} ms)")

    print("GCC (bitset + numba), 50 % outliers, eps = 2 Tr, random descriptor order")
    for n in (200, 500, 880, 2000, 5000):
        src, tgt, corr, tr = problem(1, n)
        for bug in (False, True):
            t = best_of(
                lambda src=src, tgt=tgt, corr=corr, tr=tr, bug=bug: geometric_consistency_grouping(
                    src, tgt, corr, epsilon=2 * tr, pcl_bug=bug
                ),
                args.repeat,
            )
            label = " (pcl_bug)" if bug else ""
            print(f"  n = {n:5d}{label:10s}: {t * 1e3:8.2f} ms")

    print("RANSAC, 50 000 fixed iterations, 50 % outliers")
    for n in (100, 500, 880, 2000):
        src, tgt, corr, tr = problem(2, n)
        t = best_of(
            lambda src=src, tgt=tgt, corr=corr, tr=tr: ransac_search(
                src, tgt, corr, threshold=2 * tr
            ),
            max(1, args.repeat // 2),
        )
        r = ransac_search(src, tgt, corr, threshold=2 * tr, adaptive=True)
        ta = best_of(
            lambda src=src, tgt=tgt, corr=corr, tr=tr: ransac_search(
                src, tgt, corr, threshold=2 * tr, adaptive=True
            ),
            args.repeat,
        )
        print(
            f"  n = {n:5d}: {t * 1e3:8.1f} ms   (adaptive: {r.n_iterations} it, {ta * 1e3:6.2f} ms)"
        )

    print("CLGV (k = 10, 1000 hypotheses)")
    for n in (200, 500, 880):
        src, tgt, corr, tr = problem(3, n)
        t = best_of(
            lambda src=src, tgt=tgt, corr=corr, tr=tr: clgv_select(src, tgt, corr, epsilon=2 * tr),
            args.repeat,
        )
        print(f"  n = {n:5d}: {t * 1e3:8.2f} ms")


if __name__ == "__main__":
    main()
