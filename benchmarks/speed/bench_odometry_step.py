"""Time of one full odometry step of paper 1's method at paper 1's cloud sizes.

For clouds of ≈150, 440, 880 and 3 100 points (the presets sim-bennu, sim-helical, real-fb and
sim-eoi), times ``feature:hods+gcc+alphabeta`` on consecutive frame pairs the way odometry runs it
(with ``radius_from="own"`` the previous scan's descriptors are reused, so one step = describe
the new scan + match + group + estimate; with paper 1's rule ``radius_from="source"``, the
default, the previous scan is described again at the new scan's radius) on the window of
consecutive frames whose mean size is closest to the paper's, with one BLAS thread, for the
HoD-S readings/modes:

* ``keypoint`` — keypoint-centred pairs (relnav's default reading),
* ``all/exact`` — all point pairs, exact incremental histograms,
* ``all/fast`` — all point pairs, fast (anchor) approximation,

and prints the median ms per step beside paper 1's reported time for HoD-S/αβ (41, 112, 518,
27 954 ms) as a ratio, plus the accuracy of each variant (median rotation / translation error
of the step against the ground truth over the pairs, with ``svd`` so the filter's gain does not
hide descriptor differences; a flagged step counts as the identity, so its error equals the true
step, column ``step°``). numba compilation is excluded (one warm-up step).

Run: ``python benchmarks/speed/bench_odometry_step.py [--pairs 15]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from relnav._threads import limit_blas_threads
from relnav.geometry import invert, rotation_angle
from relnav.io.sequences import ScanSequence
from relnav.registration.feature import FeatureRegistration
from relnav.sim.presets import get_preset
from relnav.sim.scenario import simulate

SIZES = [
    ("sim-bennu", 150, 41.0),
    ("sim-helical", 440, 112.0),
    ("real-fb", 880, 518.0),
    ("sim-eoi", 3100, 27954.0),
]
VARIANTS = {
    "keypoint": {"pairs": "keypoint"},
    "all/exact": {"pairs": "all", "mode": "exact"},
    "all/fast": {"pairs": "all", "mode": "fast"},
}


def window(seq: ScanSequence, target_points: int, n_pairs: int) -> int:
    """First frame of the ``n_pairs + 1`` frames whose mean size is closest to the target."""
    counts = np.array([len(seq[k]) for k in range(len(seq))], dtype=float)
    means = np.convolve(counts, np.ones(n_pairs + 1) / (n_pairs + 1), mode="valid")
    return int(np.argmin(np.abs(means - target_points)))


def step_stats(
    seq: ScanSequence,
    start: int,
    estimator: str,
    options: dict,
    n_pairs: int,
    radius_from: str = "source",
):
    reg = FeatureRegistration(
        "hods", "gcc", estimator, descriptor_options=options, radius_from=radius_from
    )
    gt = seq.gt_poses
    prev = reg.prepare(seq[start].points)
    reg.register_prepared(reg.prepare(seq[start + 1].points), prev)  # warm-up (numba)
    times, rot, trans, npts, flagged, step = [], [], [], [], 0, []
    for k in range(start, min(start + n_pairs, len(seq) - 1)):
        pts = seq[k + 1].points
        t0 = time.perf_counter()
        cur = reg.prepare(pts)
        res = reg.register_prepared(cur, prev)
        times.append(time.perf_counter() - t0)
        T_true = invert(gt[k]) @ gt[k + 1]
        step.append(np.degrees(rotation_angle(T_true[:3, :3])))
        flagged += res.status != "ok"
        E = invert(T_true) @ res.T_target_source
        rot.append(np.degrees(rotation_angle(E[:3, :3])))
        trans.append(np.linalg.norm(E[:3, 3]))
        npts.append(len(pts))
        prev = cur
    return (
        1000 * np.median(times),
        np.median(rot),
        np.median(trans),
        np.mean(npts),
        flagged,
        np.median(step),
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=15)
    ap.add_argument(
        "--radius-from",
        nargs="+",
        default=["source", "own"],
        choices=["source", "own"],
        help="radius rules to time (source: paper 1's, the default; own: relnav's reuse)",
    )
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--presets", nargs="+", default=[s[0] for s in SIZES])
    args = ap.parse_args()
    print(
        f"{'preset':12} {'pts':>6} {'variant':10} {'radius':7} {'ms/step':>9} {'paper ms':>9} "
        f"{'× faster':>9} {'rot° (svd)':>10} {'t m (svd)':>10}"
    )
    with tempfile.TemporaryDirectory() as tmp, limit_blas_threads(1):
        for preset, target_points, paper_ms in SIZES:
            if preset not in args.presets:
                continue
            d = Path(tmp) / preset
            simulate(get_preset(preset), d)
            seq = ScanSequence(d)
            k0 = window(seq, target_points, args.pairs)
            for name in args.variants:
                opts = VARIANTS[name]
                for rf in args.radius_from:
                    ms, _, _, n, _, _ = step_stats(seq, k0, "alphabeta", opts, args.pairs, rf)
                    _, rot, tr, _, flagged, step = step_stats(seq, k0, "svd", opts, args.pairs, rf)
                    print(
                        f"{preset:12} {n:6.0f} {name:10} {rf:7} {ms:9.1f} {paper_ms:9.0f} "
                        f"{paper_ms / ms:9.1f} {rot:10.2f} {tr:10.3f} {flagged:8d} {step:6.2f}",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
