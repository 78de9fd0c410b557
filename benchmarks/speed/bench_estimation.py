"""Speed and accuracy of the estimators (Paper 1 §D filters + SVD). Prints figures; asserts nothing.

Usage: ``.venv/bin/python benchmarks/speed/bench_estimation.py [n_correspondences]``
"""

from __future__ import annotations

import sys
import time

import numpy as np

from relnav.estimation import get_estimator
from relnav.estimation._recursive import adaptive_factors, identity_state, prepare_correspondences
from relnav.geometry.rotations import rotation_angle, rotvec_to_matrix
from relnav.geometry.se3 import from_rt, transform_points
from relnav.matching.correspondences import Correspondences


def problem(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    src = rng.uniform(-1.0, 1.0, (n, 3)) + np.array([10.0, 0.0, 0.0])
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    d = rng.normal(size=3)
    T = from_rt(rotvec_to_matrix(np.deg2rad(2.0) * axis), 0.05 * d / np.linalg.norm(d))
    corr = Correspondences(np.arange(n), np.arange(n), rng.uniform(0.05, 0.3, n))
    return src, transform_points(T, src), corr, T


def best_of(f, repeat: int = 7, number: int = 5) -> float:
    f()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            f()
        times.append((time.perf_counter() - t0) / number)
    return min(times)


def kernel_time(name: str, src, tgt, corr) -> float:
    from relnav.estimation._recursive import _nlms_kernel
    from relnav.estimation.hinf import _hinf_kernel
    from relnav.estimation.kalman import _kalman_kernel

    prep, _ = prepare_correspondences(src, tgt, corr)
    m = adaptive_factors(prep.d, "per_match")
    a, b = prep.a, prep.b
    if name == "kalman":
        return best_of(
            lambda: _kalman_kernel(
                identity_state(), np.eye(12), a, b, m, 1.0, 2.5e-5, 1, 0.0, False, 1.0, False, True
            )
        )
    if name == "hinf":
        return best_of(
            lambda: _hinf_kernel(
                identity_state(), np.eye(12), a, b, m, 1.0, 2.5e-5, 1e-6, 1, 0.0, False, 1.0, False
            )
        )
    g = 0.5 / (1 + m)
    return best_of(
        lambda: _nlms_kernel(
            identity_state(), np.zeros(12), a, b, g, 0 * g, np.ones_like(m), 1.0, 1, 0.0, False
        )
    )


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 500
    src, tgt, corr, T = problem(n)
    print(f"{n} correspondences, 2°/5 cm motion, 2 m target at 10 m")
    print(f"{'estimator':<34}{'kernel ms':>10}{'total ms':>10}{'rot err °':>11}{'trans err m':>13}")
    configs = [
        ("kalman", {}),
        ("hinf", {}),
        ("alphabeta", {}),
        ("sdre", {}),
        ("sdre", {"sigma_w_sdre": 0.5}),
        ("alphabeta", {"center": True}),
        ("kalman", {"p0": 1e6}),
        ("alphabeta", {"center": True, "n_passes": 500}),
        ("svd", {}),
    ]
    for name, opts in configs:
        est = get_estimator(name, **opts)
        total = best_of(lambda est=est: est.estimate(src, tgt, corr))
        kern = kernel_time(name, src, tgt, corr) if name != "svd" and not opts else float("nan")
        e = est.estimate(src, tgt, corr)
        rot = np.rad2deg(rotation_angle(e.T_target_source[:3, :3].T @ T[:3, :3]))
        trans = np.linalg.norm(e.T_target_source[:3, 3] - T[:3, 3])
        label = name + (" " + ",".join(f"{k}={v}" for k, v in opts.items()) if opts else "")
        print(f"{label:<34}{kern * 1e3:>10.3f}{total * 1e3:>10.3f}{rot:>11.4f}{trans:>13.5f}")


if __name__ == "__main__":
    main()
