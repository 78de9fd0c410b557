"""Does relnav's numba KD-tree beat scipy's cKDTree and pykdtree inside the ICP loop? (not a test)

Run:  python benchmarks/speed/bench_kdtree.py [--reps 30]

Issue 14 keeps :mod:`relnav.geometry.kdtree` only if it is faster where ICP uses it. Each ICP
iteration transforms the source by the current estimate and looks up the nearest target point of
every source point within the gate (:func:`relnav.geometry.kdtree.kd_query`, called from the
fused numba loop). Measured here on pairs of simulated scans (VLP-16 and HDL-64 of the
procedural Envisat, 15 m; the HPR sampler at 4000 points), single thread, median over ``--reps``:

* **query**: the transform + nearest neighbour within the gate of one iteration —
  numba ``kd_query`` vs ``cKDTree.query(X, distance_upper_bound=gate, workers=1)`` vs
  ``pykdtree`` (``OMP_NUM_THREADS=1``), the transform done in NumPy for the last two;
* **build**: the tree of the target cloud (once per scan in odometry);
* both together for one 20-iteration ``icp-point`` call (one build + 20 queries).

Prints the times and the ratios other / numba (> 1: the numba tree is faster). The neighbours
are checked to be the same (indices, distances to 1e-12) before anything is timed.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # pykdtree: one thread, like the other two

import argparse
import time
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from relnav.geometry.kdtree import KDTree, kd_query
from relnav.geometry.neighbors import mean_resolution
from relnav.geometry.se3 import exp_se3
from relnav.sim.sensors import make_sensor
from relnav.sim.targets import procedural_target


def median_time(f, reps: int) -> float:
    f()  # warm-up (numba compilation, caches)
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def scans(sensor: str, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Target scan, source scan (a small motion later) and the ground-truth T_target_source."""
    target = procedural_target("envisat")
    s = make_sensor(sensor, n_points=4000) if sensor == "surface-hpr" else make_sensor(sensor)
    T1 = np.eye(4)
    T1[:3, 3] = [-15.0, 0.3, 0.2]
    T2 = exp_se3(np.array([0.1, -0.05, 0.03, 0.01, -0.02, 0.015])) @ T1
    rng = np.random.default_rng(seed)
    A = s.scan(target, T1, rng)
    B = s.scan(target, T2, rng)
    return A, B, np.linalg.inv(T1) @ T2


def measure(A: np.ndarray, B: np.ndarray, T: np.ndarray, reps: int, py_tree: Any) -> list[float]:
    """Median seconds: query numba, cKDTree, pykdtree; build numba, cKDTree, pykdtree."""
    gate = 10.0 * mean_resolution(B)
    tree = KDTree(A)
    ck = cKDTree(A)
    X = B @ T[:3, :3].T + T[:3, 3]
    _, i_nb, d_nb = kd_query(tree._Pp, tree._perm, tree._dim, tree._val, B, T, gate, False)
    d_ck, _ = ck.query(X, k=1, distance_upper_bound=gate, workers=1)
    hit = i_nb >= 0
    assert np.array_equal(hit, np.isfinite(d_ck)), "numba and cKDTree disagree on the gate"
    assert np.allclose(d_nb[hit], d_ck[hit], rtol=0, atol=1e-12)
    out = [
        median_time(
            lambda: kd_query(tree._Pp, tree._perm, tree._dim, tree._val, B, T, gate, False),
            reps,
        ),
        median_time(
            lambda: ck.query(B @ T[:3, :3].T + T[:3, 3], k=1, distance_upper_bound=gate, workers=1),
            reps,
        ),
        float("nan"),
        median_time(lambda: KDTree(A), reps),
        median_time(lambda: cKDTree(A), reps),
        float("nan"),
    ]
    if py_tree is not None:
        pk = py_tree(A, leafsize=16)
        d_pk, _ = pk.query(X, k=1, distance_upper_bound=gate)
        assert np.allclose(d_pk[hit], d_nb[hit], rtol=0, atol=1e-9)
        out[2] = median_time(
            lambda: pk.query(B @ T[:3, :3].T + T[:3, 3], k=1, distance_upper_bound=gate), reps
        )
        out[5] = median_time(lambda: py_tree(A, leafsize=16), reps)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=30)
    args = ap.parse_args()
    try:
        from pykdtree.kdtree import KDTree as PyKDTree
    except ImportError:  # optional
        PyKDTree = None
    print(
        f"{'cloud':<12} {'N':>6} | query: {'numba':>8} {'cKDTree':>8} {'ratio':>6} "
        f"{'pykdtree':>8} {'ratio':>6} | build: {'numba':>8} {'cKDTree':>8} {'ratio':>6} "
        f"{'pykdtree':>8} {'ratio':>6}   (ms)"
    )
    for sensor in ("vlp16", "hdl64", "surface-hpr"):
        A, B, T = scans(sensor, 0)
        qn, qc, qp, bn, bc, bp = (1e3 * x for x in measure(A, B, T, args.reps, PyKDTree))
        print(
            f"{sensor:<12} {A.shape[0]:>6} |        {qn:>8.3f} {qc:>8.3f} {qc / qn:>6.2f} "
            f"{qp:>8.3f} {qp / qn:>6.2f} |        {bn:>8.3f} {bc:>8.3f} {bc / bn:>6.2f} "
            f"{bp:>8.3f} {bp / bn:>6.2f}"
        )
        n = 20  # icp-point's iterations: one build, n queries
        tn, tc, tp = bn + n * qn, bc + n * qc, bp + n * qp
        print(
            f"{'':<12} {'':>6} | one {n}-iteration ICP's tree work: numba {tn:.2f} ms, cKDTree "
            f"{tc:.2f} ms ({tc / tn:.2f}x), pykdtree {tp:.2f} ms ({tp / tn:.2f}x)"
        )
    print("ratio = other / numba: > 1 means relnav's numba KD-tree is faster")


if __name__ == "__main__":
    main()
